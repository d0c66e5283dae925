#version 460
// Radix sort pass step 3: stable scatter. An element's output slot is
// (block's offset for its digit, from the scanned histogram)
// + (equal digits in earlier subgroups' chunks) + (its rank within its subgroup's
// chunk, from count_row), so equal digits keep their input order.
#define WG_SIZE_SPEC_ID SORT_SPEC_WG
#include "common.glsl"
#include "sort_spec.glsl"

layout(push_constant) uniform SortPassBlock { SortPassPush pc; };

layout(std430, binding = SORT_SCATTER_META) readonly buffer Meta { uint meta[]; };
layout(std430, binding = SORT_SCATTER_OFFSETS) readonly buffer Offsets { uint offsets[]; };
#if SORT_TEXEL_IO
// 32-bit keys and values through R32UI texel views (see sort_histogram.comp): texel fetches
// and imageStore are straight per-lane code on llvmpipe, storage-buffer accesses are not.
layout(binding = SORT_SCATTER_KEYS_IN) uniform usamplerBuffer keys_in;
layout(binding = SORT_SCATTER_VALUES_IN) uniform usamplerBuffer values_in;
layout(binding = SORT_SCATTER_KEYS_OUT, r32ui) uniform writeonly uimageBuffer keys_out;
layout(binding = SORT_SCATTER_VALUES_OUT, r32ui) uniform writeonly uimageBuffer values_out;
#define LOAD_KEY(i) texelFetch(keys_in, int(i)).x
#define LOAD_VALUE(i) texelFetch(values_in, int(i)).x
#define STORE_PAIR(dst, key, value) \
    imageStore(keys_out, int(dst), uvec4(key)); \
    imageStore(values_out, int(dst), uvec4(value))
#else
layout(std430, binding = SORT_SCATTER_KEYS_IN) readonly buffer KeysIn { SORT_KEY keys_in[]; };
layout(std430, binding = SORT_SCATTER_VALUES_IN) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = SORT_SCATTER_KEYS_OUT) writeonly buffer KeysOut { SORT_KEY keys_out[]; };
layout(std430, binding = SORT_SCATTER_VALUES_OUT) writeonly buffer ValuesOut { uint values_out[]; };
#define LOAD_KEY(i) keys_in[i]
#define LOAD_VALUE(i) values_in[i]
#define STORE_PAIR(dst, key, value) \
    keys_out[dst] = key; \
    values_out[dst] = value
#endif
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
        keys[row] = valid ? LOAD_KEY(i) : SORT_KEY(0u);
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
            STORE_PAIR(dst, keys[row], LOAD_VALUE(i));
        }
    }
}
