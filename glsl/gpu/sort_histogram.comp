#version 460
// Radix sort pass step 1: per-block digit histogram, written digit-major
// (hist[digit * hist_stride + block]) so one exclusive scan of the table yields every
// (digit, block) output offset in stable order.
#define WG_SIZE_SPEC_ID SORT_SPEC_WG
#include "common.glsl"
#include "sort_spec.glsl"

layout(push_constant) uniform SortPassBlock { SortPassPush pc; };

layout(std430, binding = SORT_HISTOGRAM_META) readonly buffer Meta { uint meta[]; };
#if SORT_TEXEL_IO
// 32-bit keys read through an R32UI texel view: llvmpipe turns texel fetches into straight
// per-lane loads, storage-buffer loads into a guarded loop per component.
layout(binding = SORT_HISTOGRAM_KEYS) uniform usamplerBuffer keys_tex;
#define LOAD_KEY(i) texelFetch(keys_tex, int(i)).x
#else
layout(std430, binding = SORT_HISTOGRAM_KEYS) readonly buffer Keys { SORT_KEY keys[]; };
#define LOAD_KEY(i) keys[i]
#endif
layout(std430, binding = SORT_HISTOGRAM_HIST) writeonly buffer Hist { uint hist[]; };

#include "sort_common.glsl"

void main() {
    uint block = linear_group_id();
    if (block >= meta[META_BLOCKS]) {
        return;
    }
    uint n = meta[META_N];
    uint mask = (1u << pc.bits) - 1u;
    clear_subgroup_counts();
    for (uint row = 0; row < SORT_ITEMS; ++row) {
        uint i = sort_element_index(block, row);
        bool valid = i < n;
        if (valid) {
            // Order does not matter here, so shared atomics (cheaper than the
            // ballot-based ranking the scatter needs) into per-subgroup counters.
            uint digit = key_digit(LOAD_KEY(i), pc.shift, mask);
            atomicAdd(subgroup_counts[gl_SubgroupID * SORT_RADIX + digit], 1u);
        }
    }
    barrier();
    for (uint d = gl_LocalInvocationID.x; d < SORT_RADIX; d += SORT_WG) {
        uint sum = 0;
        for (uint s = 0; s < gl_NumSubgroups; ++s) {
            sum += subgroup_counts[s * SORT_RADIX + d];
        }
        hist[d * pc.hist_stride + block] = sum;
    }
}
