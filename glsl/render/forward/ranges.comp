#version 460
// Tile ranges: [start, end) of each tile's run in the sorted keys. Tiles without any pair
// keep the zeros the frame cleared them to. Dispatched indirectly over the sorted count.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"

layout(local_size_x = LINEAR_WG) in;

#if RANGES_TEXEL_IO
// CPU devices: the keys through a texel view (straight per-lane loads on llvmpipe).
layout(binding = RANGES_KEYS) uniform usamplerBuffer keys_tex;
#define KEY(i) texelFetch(keys_tex, int(i)).x
#else
layout(std430, binding = RANGES_KEYS) readonly buffer KeyBuf { uint keys[]; };
#define KEY(i) keys[i]
#endif
layout(std430, binding = RANGES_RANGES) writeonly buffer RangeBuf { uvec2 ranges[]; };
layout(std430, binding = RANGES_COUNTERS) readonly buffer CounterBuf { Counters counters; };

void main() {
    uint i = linear_group_id() * LINEAR_WG + gl_LocalInvocationIndex;
    uint n = counters.sort_count;
    if (i >= n) return;
    uint tile = KEY(i);
    if (tile == SENTINEL_TILE) return;
    if (i == 0u || KEY(i - 1u) != tile) ranges[tile].x = i;
    if (i + 1u == n || KEY(i + 1u) != tile) ranges[tile].y = i + 1u;
}
