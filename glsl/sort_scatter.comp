#version 460
// Radix sort pass step 3: stable scatter. Thread t owns the SORT_ITEMS consecutive
// elements starting at t * SORT_ITEMS of its block; a digit-major exclusive scan of the
// per-thread counts gives each (digit, thread) its first output slot, and each thread
// then walks its elements in order, so equal digits keep their input order.
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

shared uint counts[SORT_RADIX * SORT_WG];
// Global output offset of each digit for this block minus the digit's local start.
shared uint digit_base[SORT_RADIX];

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
    for (uint d = t; d < SORT_RADIX; d += SORT_WG) {
        digit_base[d] = offsets[d * pc.hist_stride + block];
    }
    uint mask = (1u << pc.bits) - 1u;
    uint begin = block * SORT_BLOCK + t * SORT_ITEMS;
    uint end = min(begin + SORT_ITEMS, n);
    for (uint i = begin; i < end; ++i) {
        uint slot = key_digit(keys_in[i], pc.shift, mask) * SORT_WG + t;
        counts[slot] += 1u;
    }
    barrier();

    // Exclusive scan of counts in digit-major order: thread t scans the SORT_RADIX
    // entries starting at t * SORT_RADIX, then the per-thread sums are scanned.
    uint first = t * SORT_RADIX;
    uint sum = 0;
    for (uint k = 0; k < SORT_RADIX; ++k) {
        uint c = counts[first + k];
        counts[first + k] = sum;
        sum += c;
    }
    uint prefix = workgroup_exclusive_scan(sum);
    for (uint k = 0; k < SORT_RADIX; ++k) {
        uint idx = first + k;
        uint local_offset = counts[idx] + prefix;
        counts[idx] = local_offset;
        if (idx % SORT_WG == 0u) {
            // Start of digit idx / SORT_WG within the block (wraps back when added).
            digit_base[idx / SORT_WG] -= local_offset;
        }
    }
    barrier();

    for (uint i = begin; i < end; ++i) {
        uvec2 key = keys_in[i];
        uint digit = key_digit(key, pc.shift, mask);
        uint slot = digit * SORT_WG + t;
        uint rank = counts[slot];
        counts[slot] = rank + 1u;
        uint dst = digit_base[digit] + rank;
        keys_out[dst] = key;
        values_out[dst] = values_in[i];
    }
}
