#version 460
// Prefix sum, level step 1: the sum of each SCAN_BLOCK-element block.
#define WG_SIZE SCAN_WG
#include "common.glsl"

layout(push_constant) uniform ScanBlock { ScanPush pc; };

layout(std430, binding = SCAN_REDUCE_DATA_IN) readonly buffer Input { uint data_in[]; };
layout(std430, binding = SCAN_REDUCE_BLOCK_SUMS) writeonly buffer BlockSums { uint block_sums[]; };

void main() {
    uint block = linear_group_id();
    uint base = block * SCAN_BLOCK;
    if (base >= pc.n) {
        return;
    }
    uint begin = base + gl_LocalInvocationID.x * SCAN_ITEMS;
    uint end = min(begin + SCAN_ITEMS, pc.n);
    uint sum = 0;
    for (uint i = begin; i < end; ++i) {
        sum += data_in[i];
    }
    uint total = workgroup_sum(sum);
    if (gl_LocalInvocationID.x == 0) {
        block_sums[block] = total;
    }
}
