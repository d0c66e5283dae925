#version 460
// Radix sort set-up: reads the element count (from the host or a device buffer),
// clamps it to the capacity, and writes it plus the indirect dispatch grid for the
// per-block passes into the sort's meta words.
#define WG_SIZE 1
#include "common.glsl"
#include "sort_spec.glsl"

// count_index 0xFFFFFFFF: use host_n.
layout(push_constant) uniform SortSetupBlock { SortSetupPush pc; };

layout(std430, binding = SORT_SETUP_COUNT) readonly buffer Count { uint counts[]; };
layout(std430, binding = SORT_SETUP_META) writeonly buffer Meta { uint meta[]; };

void main() {
    uint n = pc.count_index == 0xFFFFFFFFu ? pc.host_n : counts[pc.count_index];
    n = min(n, pc.max_n);
    uint blocks = (n + (SORT_BLOCK - 1u)) / SORT_BLOCK;
    uint x = min(blocks, pc.max_groups_x);
    uint y = x == 0u ? 0u : (blocks + x - 1u) / x;
    meta[META_N] = n;
    meta[META_BLOCKS] = blocks;
    meta[META_DISPATCH + 0] = x;
    meta[META_DISPATCH + 1] = y;
    meta[META_DISPATCH + 2] = 1u;
}
