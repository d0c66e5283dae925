#version 460
// Radix sort pass step 3: stable scatter. An element's output slot is
// (block's offset for its digit, from the scanned histogram)
// + (equal digits in earlier subgroups' chunks) + (its rank within its subgroup's
// chunk, from count_row), so equal digits keep their input order.
#define WG_SIZE SORT_WG
#include "common.glsl"

layout(push_constant) uniform Push {
    uint shift;
    uint bits;
    uint hist_stride;
    uint pad;
} pc;

layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer KeysIn { SORT_KEY keys_in[]; };
layout(std430, binding = 2) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = 3) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 4) writeonly buffer KeysOut { SORT_KEY keys_out[]; };
layout(std430, binding = 5) writeonly buffer ValuesOut { uint values_out[]; };

#define SORT_KEYS keys_in
#include "sort_common.glsl"

void main() {
    uint block = linear_group_id();
    if (block >= meta[META_BLOCKS]) {
        return;
    }
    uint n = meta[META_N];
    uint mask = (1u << pc.bits) - 1u;
    clear_subgroup_counts();
    SORT_KEY keys[SORT_ITEMS];
    uint ranks[SORT_ITEMS];
    for (uint row = 0; row < SORT_ITEMS; ++row) {
        uint i = sort_element_index(block, row);
        bool valid = i < n;
        keys[row] = valid ? keys_in[i] : SORT_KEY(0u);
        ranks[row] = count_row(key_digit(keys[row], pc.shift, mask), valid);
    }
    barrier();
    // Per digit: turn subgroup counts into each subgroup's first output slot.
    for (uint d = gl_LocalInvocationID.x; d < SORT_RADIX; d += SORT_WG) {
        uint run = offsets[d * pc.hist_stride + block];
        for (uint s = 0; s < gl_NumSubgroups; ++s) {
            uint slot = s * SORT_RADIX + d;
            uint c = subgroup_counts[slot];
            subgroup_counts[slot] = run;
            run += c;
        }
    }
    barrier();
    for (uint row = 0; row < SORT_ITEMS; ++row) {
        uint i = sort_element_index(block, row);
        if (i < n) {
            uint digit = key_digit(keys[row], pc.shift, mask);
            uint dst = subgroup_counts[gl_SubgroupID * SORT_RADIX + digit] + ranks[row];
            keys_out[dst] = keys[row];
            values_out[dst] = values_in[i];
        }
    }
}
