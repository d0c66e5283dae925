#version 460
// Radix sort pass step 3: stable scatter. Invocation t owns the SORT_ITEMS consecutive
// elements starting at t * SORT_ITEMS of its block. Its output slot for digit d is
// (block's offset for d) + (d-elements in earlier subgroups) + (d-elements in earlier
// invocations of its subgroup) + (d-elements it has already written), so elements
// with equal digits keep their input order.
#define WG_SIZE SORT_WG
#include "common.glsl"

layout(push_constant) uniform Push {
    uint shift;
    uint bits;
    uint hist_stride;
    uint pad;
} pc;

layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer KeysIn { uvec2 keys_in[]; };
layout(std430, binding = 2) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = 3) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 4) writeonly buffer KeysOut { uvec2 keys_out[]; };
layout(std430, binding = 5) writeonly buffer ValuesOut { uint values_out[]; };

#define SORT_KEYS keys_in
#include "sort_common.glsl"

// subgroup_counts[digit * SORT_MAX_SUBGROUPS + subgroup]: totals, then (after the
// scan) the subgroup's first output slot for that digit.
shared uint subgroup_counts[SORT_RADIX * SORT_MAX_SUBGROUPS];

void main() {
    uint block = linear_group_id();
    if (block >= meta[META_BLOCKS]) {
        return;
    }
    uint n = meta[META_N];
    uint t = gl_LocalInvocationID.x;
    uint mask = (1u << pc.bits) - 1u;
    uint begin = block * SORT_BLOCK + t * SORT_ITEMS;
    uint block_offset = t < SORT_RADIX ? offsets[t * pc.hist_stride + block] : 0u;

    uint packed[SORT_PACKED_WORDS];
    count_digits(begin, n, mask, packed);

    uint next_slot[SORT_RADIX];
    for (uint d = 0; d < SORT_RADIX; ++d) {
        uint c = unpack_count(packed, d);
        next_slot[d] = subgroupExclusiveAdd(c);
        uint total = subgroupAdd(c);
        if (subgroupElect()) {
            subgroup_counts[d * SORT_MAX_SUBGROUPS + gl_SubgroupID] = total;
        }
    }
    barrier();
    if (t < SORT_RADIX) {
        uint run = block_offset;
        for (uint s = 0; s < gl_NumSubgroups; ++s) {
            uint idx = t * SORT_MAX_SUBGROUPS + s;
            uint c = subgroup_counts[idx];
            subgroup_counts[idx] = run;
            run += c;
        }
    }
    barrier();
    for (uint d = 0; d < SORT_RADIX; ++d) {
        next_slot[d] += subgroup_counts[d * SORT_MAX_SUBGROUPS + gl_SubgroupID];
    }

    for (uint k = 0; k < SORT_ITEMS; ++k) {
        uint i = begin + k;
        if (i < n) {
            uvec2 key = keys_in[i];
            uint digit = key_digit(key, pc.shift, mask);
            uint dst = 0;
            // Select chain instead of a dynamically indexed array: stays in registers.
            for (uint d = 0; d < SORT_RADIX; ++d) {
                if (digit == d) {
                    dst = next_slot[d];
                    next_slot[d] = dst + 1u;
                }
            }
            keys_out[dst] = key;
            values_out[dst] = values_in[i];
        }
    }
}
