#version 460
// Gradient accumulation: one invocation per sorted pair adds the pair's partial sums
// (blend_bwd.comp) to its Gaussian's fixed-point accumulators (grad_common.glsl), in any
// order with the same result. With FLOAT_ATOMICS = 1 (the opt-in fast mode) it adds the
// floats with atomicAdd instead (VK_EXT_shader_atomic_float), or with a compare-and-swap
// loop where the device lacks it (CAS_FALLBACK = 1): faster, not reproducible.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"
#include "grad_common.glsl"
#ifndef FLOAT_ATOMICS
#define FLOAT_ATOMICS 0
#endif
#ifndef CAS_FALLBACK
#define CAS_FALLBACK 0
#endif
#if FLOAT_ATOMICS && !CAS_FALLBACK
#extension GL_EXT_shader_atomic_float : require
#endif
#define F GRAD_FIELDS

layout(local_size_x = 256) in;

layout(std430, binding = GRAD_ACCUMULATE_VALUES) readonly buffer ValueBuf { uint values[]; };
layout(std430, binding = GRAD_ACCUMULATE_PAIR_GRADS) readonly buffer PairGradBuf { float pair_grads[]; };
layout(std430, binding = GRAD_ACCUMULATE_MAXIMA) readonly buffer MaximaBuf { uint maxima[]; };
// Two words per Gaussian and field: (lo, hi) of the fixed-point sum, or the float sum and
// an unused word.
#if FLOAT_ATOMICS && !CAS_FALLBACK
layout(std430, binding = GRAD_ACCUMULATE_ACC) buffer AccBuf { float acc[]; };
#else
layout(std430, binding = GRAD_ACCUMULATE_ACC) buffer AccBuf { uint acc[]; };
#endif
// count: sorted pairs; bits: log2 of the most pairs one Gaussian can have, rounded up.
layout(push_constant) uniform Push { uint count; uint bits; } pc;

void main() {
    uint k = linear_group_id() * 256u + gl_LocalInvocationIndex;
    if (k >= pc.count) return;
    uint g = values[k];
    for (uint f = 0u; f < F; f++) {
        float v = pair_grads[k * F + f];
        if (v == 0.0) continue;
#if FLOAT_ATOMICS && !CAS_FALLBACK
        atomicAdd(acc[(g * F + f) * 2u], v);
#elif FLOAT_ATOMICS
        uint i = (g * F + f) * 2u;
        uint old = acc[i];
        for (;;) {
            uint seen = atomicCompSwap(acc[i], old, floatBitsToUint(uintBitsToFloat(old) + v));
            if (seen == old) break;
            old = seen;
        }
#else
        uvec2 x = to_fixed(scale_pow2(v, grad_shift(maxima[f], pc.bits)));
        uint i = (g * F + f) * 2u;
        uint old = atomicAdd(acc[i], x.x);
        uint carry = old + x.x < old ? 1u : 0u;
        if (x.y + carry != 0u) atomicAdd(acc[i + 1u], x.y + carry);
#endif
    }
}
