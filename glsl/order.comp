#version 460
// Depth order, second half: after the stable depth sort of (depth bits, tiles touched) keys,
// lay the tiles-touched counts out in depth order for the scan. Keys are then emitted in
// depth order, so the pair sort only needs the tile bits: for equal tiles the stable sort
// keeps depth order, and for equal depths the depth sort kept index order, which is exactly
// the order of a stable sort of the full tile << 32 | depth keys emitted in index order.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"

layout(local_size_x = 256) in;

layout(std430, binding = 0) readonly buffer ParamsBuf { FrameParams params; };
layout(std430, binding = 1) readonly buffer DepthKeyBuf { uvec2 depth_keys[]; };
layout(std430, binding = 2) writeonly buffer TouchedBuf { uint touched_in_order[]; };

void main() {
    uint k = linear_group_id() * 256u + gl_LocalInvocationIndex;
    if (k < params.counts.x) touched_in_order[k] = depth_keys[k].y;
}
