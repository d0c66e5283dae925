#version 460
// Radix sort epilogue for odd pass counts: copies the result from the scratch
// ping-pong buffers back into the caller's key/value buffers.
#define WG_SIZE_SPEC_ID SORT_SPEC_WG
#include "common.glsl"
#include "sort_spec.glsl"

layout(std430, binding = SORT_COPY_META) readonly buffer Meta { uint meta[]; };
#if SORT_TEXEL_IO
layout(binding = SORT_COPY_KEYS_IN) uniform usamplerBuffer keys_in;
layout(binding = SORT_COPY_VALUES_IN) uniform usamplerBuffer values_in;
layout(binding = SORT_COPY_KEYS_OUT, r32ui) uniform writeonly uimageBuffer keys_out;
layout(binding = SORT_COPY_VALUES_OUT, r32ui) uniform writeonly uimageBuffer values_out;
#define COPY(i) \
    imageStore(keys_out, int(i), texelFetch(keys_in, int(i))); \
    imageStore(values_out, int(i), texelFetch(values_in, int(i)))
#else
layout(std430, binding = SORT_COPY_KEYS_IN) readonly buffer KeysIn { SORT_KEY keys_in[]; };
layout(std430, binding = SORT_COPY_VALUES_IN) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = SORT_COPY_KEYS_OUT) writeonly buffer KeysOut { SORT_KEY keys_out[]; };
layout(std430, binding = SORT_COPY_VALUES_OUT) writeonly buffer ValuesOut { uint values_out[]; };
#define COPY(i) \
    keys_out[i] = keys_in[i]; \
    values_out[i] = values_in[i]
#endif

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
            COPY(i);
        }
    }
}
