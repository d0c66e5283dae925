#version 460
// Prefix sum, level step 3: scan each block locally and add the block's scanned
// offset. Input and output may alias.
#define WG_SIZE SCAN_WG
#include "common.glsl"

layout(push_constant) uniform ScanBlock { ScanPush pc; };

layout(std430, binding = SCAN_ADD_DATA_IN) buffer Input { uint data_in[]; };
layout(std430, binding = SCAN_ADD_BLOCK_OFFSETS) readonly buffer BlockOffsets { uint block_offsets[]; };
layout(std430, binding = SCAN_ADD_DATA_OUT) buffer Output { uint data_out[]; };

void main() {
    uint block = linear_group_id();
    uint base = block * SCAN_BLOCK;
    if (base >= pc.n) {
        return;
    }
    uint begin = base + gl_LocalInvocationID.x * SCAN_ITEMS;
    uint local_prefix[SCAN_ITEMS];
    uint sum = 0;
    for (uint k = 0; k < SCAN_ITEMS; ++k) {
        uint i = begin + k;
        uint x = i < pc.n ? data_in[i] : 0u;
        local_prefix[k] = sum;
        sum += x;
    }
    uint prefix = workgroup_exclusive_scan(sum) + block_offsets[block];
    for (uint k = 0; k < SCAN_ITEMS; ++k) {
        uint i = begin + k;
        if (i < pc.n) {
            data_out[i] = prefix + local_prefix[k];
        }
    }
}
