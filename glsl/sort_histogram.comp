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

#define SORT_KEYS keys
#include "sort_common.glsl"

// Per-subgroup digit totals: subgroup_counts[digit * SORT_MAX_SUBGROUPS + subgroup].
shared uint subgroup_counts[SORT_RADIX * SORT_MAX_SUBGROUPS];

void main() {
    uint block = linear_group_id();
    if (block >= meta[META_BLOCKS]) {
        return;
    }
    uint n = meta[META_N];
    uint mask = (1u << pc.bits) - 1u;
    uint begin = block * SORT_BLOCK + gl_LocalInvocationID.x * SORT_ITEMS;

    // Each invocation counts its consecutive items in registers.
    uint packed[SORT_PACKED_WORDS];
    count_digits(begin, n, mask, packed);

    for (uint d = 0; d < SORT_RADIX; ++d) {
        uint total = subgroupAdd(unpack_count(packed, d));
        if (subgroupElect()) {
            subgroup_counts[d * SORT_MAX_SUBGROUPS + gl_SubgroupID] = total;
        }
    }
    barrier();
    uint t = gl_LocalInvocationID.x;
    if (t < SORT_RADIX) {
        uint sum = 0;
        for (uint s = 0; s < gl_NumSubgroups; ++s) {
            sum += subgroup_counts[t * SORT_MAX_SUBGROUPS + s];
        }
        hist[t * pc.hist_stride + block] = sum;
    }
}
