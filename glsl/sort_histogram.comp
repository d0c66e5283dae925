#version 460
// Radix sort pass step 1: per-block digit histogram, written digit-major
// (hist[digit * hist_stride + block]) so one exclusive scan of the table yields every
// (digit, block) output offset in stable order.
#define WG_SIZE SORT_WG
#include "common.glsl"

layout(push_constant) uniform Push {
    uint shift;
    uint bits;
    uint hist_stride;
    uint pad;
} pc;

layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Keys { uvec2 keys[]; };
layout(std430, binding = 2) writeonly buffer Hist { uint hist[]; };

// counts[digit * SORT_WG + thread]: each thread counts its own items in its own column.
shared uint counts[SORT_RADIX * SORT_WG];

void main() {
    uint block = linear_group_id();
    if (block >= meta[META_BLOCKS]) {
        return;
    }
    uint n = meta[META_N];
    uint t = gl_LocalInvocationID.x;
    for (uint d = 0; d < SORT_RADIX; ++d) {
        counts[d * SORT_WG + t] = 0u;
    }
    uint mask = (1u << pc.bits) - 1u;
    uint begin = block * SORT_BLOCK + t * SORT_ITEMS;
    uint end = min(begin + SORT_ITEMS, n);
    for (uint i = begin; i < end; ++i) {
        uint slot = key_digit(keys[i], pc.shift, mask) * SORT_WG + t;
        counts[slot] += 1u;
    }
    barrier();
    for (uint d = t; d < SORT_RADIX; d += SORT_WG) {
        uint sum = 0;
        for (uint j = 0; j < SORT_WG; ++j) {
            sum += counts[d * SORT_WG + j];
        }
        hist[d * pc.hist_stride + block] = sum;
    }
}
