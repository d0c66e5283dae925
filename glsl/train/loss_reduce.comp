#version 460
#extension GL_GOOGLE_include_directive : require
// Training loss: sums of vec4s in a fixed order (the same bits run after run). Workgroup w
// sums values [w * REDUCE_SPAN, (w + 1) * REDUCE_SPAN) (4096): invocation t its REDUCE_ITEMS
// (32) values t, t + REDUCE_WG (128), ..., then
// a tree in shared memory; the host runs it again on the workgroups' sums down to one.

layout(local_size_x = REDUCE_WG) in;

#include "interface.glsl"

layout(push_constant) uniform CountsBlock { CountsPush p; };  // values

layout(std430, binding = LOSS_REDUCE_VALUES) readonly buffer ValueBuf { vec4 values[]; };
layout(std430, binding = LOSS_REDUCE_SUMS) writeonly buffer SumBuf { vec4 sums[]; };

shared vec4 partial[REDUCE_WG];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint base = gl_WorkGroupID.x * REDUCE_SPAN;
    precise vec4 acc = vec4(0.0);
    for (uint k = 0u; k < REDUCE_ITEMS; k++) {
        uint j = base + k * REDUCE_WG + t;
        if (j < p.counts.x) acc += values[j];
    }
    partial[t] = acc;
    barrier();
    for (uint half_ = REDUCE_WG / 2u; half_ > 0u; half_ >>= 1) {
        if (t < half_) partial[t] = partial[t] + partial[t + half_];
        barrier();
    }
    if (t == 0u) sums[gl_WorkGroupID.x] = partial[0];
}
