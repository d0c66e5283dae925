#version 460
#extension GL_GOOGLE_include_directive : require
// The neural shader's parameter gradients (its backward pass): the sum of the
// partial slots that shade_bwd.comp filled, slot after slot, one invocation per parameter.

layout(local_size_x = MLP_REDUCE_WG) in;

#include "interface.glsl"

// Counts: parameters, slots, 0, 0.
layout(push_constant) uniform CountsBlock { CountsPush p; };

layout(std430, binding = MLP_GRAD_REDUCE_PARTIALS) readonly buffer PartialBuf { float partials[]; };
layout(std430, binding = MLP_GRAD_REDUCE_GRADS) writeonly buffer GradBuf { float grads[]; };

void main() {
    uint q = gl_GlobalInvocationID.x;
    if (q >= p.counts.x) return;
    precise float sum = 0.0;
    for (uint s = 0u; s < p.counts.y; s++) sum += partials[s * p.counts.x + q];
    grads[q] = sum;
}
