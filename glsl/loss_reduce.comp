#version 460
#extension GL_GOOGLE_include_directive : require
// Training loss: sums of vec4s in a fixed order (the same bits run after run). Workgroup w
// sums values [w * 4096, (w + 1) * 4096): invocation t its 32 values t, t + 128, ..., then
// a tree in shared memory; the host runs it again on the workgroups' sums down to one.

layout(local_size_x = 128) in;

#include "interface.glsl"

layout(push_constant) uniform CountsBlock { CountsPush p; };  // values

layout(std430, binding = LOSS_REDUCE_VALUES) readonly buffer ValueBuf { vec4 values[]; };
layout(std430, binding = LOSS_REDUCE_SUMS) writeonly buffer SumBuf { vec4 sums[]; };

shared vec4 partial[128];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint base = gl_WorkGroupID.x * 4096u;
    precise vec4 acc = vec4(0.0);
    for (uint k = 0u; k < 32u; k++) {
        uint j = base + k * 128u + t;
        if (j < p.counts.x) acc += values[j];
    }
    partial[t] = acc;
    barrier();
    for (uint half_ = 64u; half_ > 0u; half_ >>= 1) {
        if (t < half_) partial[t] = partial[t] + partial[t + half_];
        barrier();
    }
    if (t == 0u) sums[gl_WorkGroupID.x] = partial[0];
}
