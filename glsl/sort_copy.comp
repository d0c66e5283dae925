#version 460
// Radix sort epilogue for odd pass counts: copies the result from the scratch
// ping-pong buffers back into the caller's key/value buffers.
#define WG_SIZE SORT_WG
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer KeysIn { SORT_KEY keys_in[]; };
layout(std430, binding = 2) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = 3) writeonly buffer KeysOut { SORT_KEY keys_out[]; };
layout(std430, binding = 4) writeonly buffer ValuesOut { uint values_out[]; };

void main() {
    uint block = linear_group_id();
    if (block >= meta[META_BLOCKS]) {
        return;
    }
    uint n = meta[META_N];
    uint base = block * SORT_BLOCK + gl_LocalInvocationID.x;
    for (uint k = 0; k < SORT_ITEMS; ++k) {
        uint i = base + k * SORT_WG;
        if (i < n) {
            keys_out[i] = keys_in[i];
            values_out[i] = values_in[i];
        }
    }
}
