#version 460
// Test kernel for the exact 64-bit counting of preprocess (WORKGROUP_COUNT64 in
// splat_common.glsl): every invocation contributes a pseudo-random term below 2^20, and
// the total, far beyond 2^32, must come out exact. Used by the tests only.
#extension GL_GOOGLE_include_directive : require
#define WORKGROUP_COUNT64
#include "splat_common.glsl"

layout(local_size_x = LINEAR_WG) in;

layout(std430, binding = COUNT64_TEST_COUNT) buffer CountBuf { uint lo; uint hi; uint seed; };

void main() {
    uint i = linear_group_id() * LINEAR_WG + gl_LocalInvocationIndex;
    uint h = (i ^ seed) * 2654435761u;
    h ^= h >> 15;
    uint value = h & 0xFFFFFu;
    uint sum = workgroup_sum_u32(value);
    if (gl_LocalInvocationIndex == 0u) {
        ATOMIC_ADD_U64(lo, hi, sum);
    }
}
