#version 460
// Prefix sum of at most SCAN_BLOCK elements in one workgroup (the top level of the
// multi-level scan); also writes the grand total. Input and output may alias.
#define WG_SIZE SCAN_WG
#include "common.glsl"

layout(push_constant) uniform ScanBlock { ScanPush pc; };

layout(std430, binding = SCAN_BLOCK_DATA_IN) buffer Input { uint data_in[]; };
layout(std430, binding = SCAN_BLOCK_DATA_OUT) buffer Output { uint data_out[]; };
layout(std430, binding = SCAN_BLOCK_TOTALS) buffer Total { uint totals[]; };

void main() {
    uint begin = gl_LocalInvocationID.x * SCAN_ITEMS;
    uint local_prefix[SCAN_ITEMS];
    uint sum = 0;
    for (uint k = 0; k < SCAN_ITEMS; ++k) {
        uint i = begin + k;
        uint x = i < pc.n ? data_in[i] : 0u;
        local_prefix[k] = sum;
        sum += x;
    }
    uint prefix = workgroup_exclusive_scan(sum);
    for (uint k = 0; k < SCAN_ITEMS; ++k) {
        uint i = begin + k;
        if (i < pc.n) {
            data_out[i] = prefix + local_prefix[k];
        }
    }
    if (gl_LocalInvocationID.x == WG_SIZE - 1 && pc.write_total != 0u) {
        totals[pc.total_index] = prefix + sum;
    }
}
