#version 460
// Gradient accumulation: one invocation per sorted pair adds the pair's partial sums
// (blend_bwd.comp) to its Gaussian's fixed-point accumulators (grad_common.glsl), in any
// order with the same result. With FLOAT_ATOMICS = 1 (the opt-in fast mode) it adds the
// floats with atomicAdd instead (VK_EXT_shader_atomic_float), or with a compare-and-swap
// loop where the device lacks it (CAS_FALLBACK = 1): faster, not reproducible.
// INT64_ATOMICS = 1 (devices with shaderBufferInt64Atomics) adds each fixed-point value
// with one 64-bit atomic, where the fallback adds its two 32-bit halves and a carry: the
// same 64-bit sums, one atomic and no returned value per field (1.35x faster on lavapipe).
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "splat_common.glsl"
#include "grad_common.glsl"
#ifndef FLOAT_ATOMICS
#define FLOAT_ATOMICS 0
#endif
#ifndef CAS_FALLBACK
#define CAS_FALLBACK 0
#endif
#ifndef INT64_ATOMICS
#define INT64_ATOMICS 0
#endif
#if FLOAT_ATOMICS && !CAS_FALLBACK
#extension GL_EXT_shader_atomic_float : require
#endif
#if INT64_ATOMICS
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#endif
// Fields per pair: GRAD_FIELDS (12: 2D mean, conic, opacity, colour, depth, |2D mean|)
// plus 4 per group of feature channels, at most MAX_GRAD_FIELDS; `pc.vecs` vec4s.

// 256 invocations where the device allows them (faster on lavapipe), else 128: the host's
// choice (gpu::workgroup::wide_linear_workgroup), as a specialization constant.
layout(local_size_x = LINEAR_WG, local_size_x_id = WIDE_WG_SPEC) in;

layout(std430, binding = GRAD_ACCUMULATE_VALUES) readonly buffer ValueBuf { uint values[]; };
layout(std430, binding = GRAD_ACCUMULATE_PAIR_GRADS) readonly buffer PairGradBuf { vec4 pair_grads[]; };
layout(std430, binding = GRAD_ACCUMULATE_MAXIMA) readonly buffer MaximaBuf { uint maxima[]; };
// Two words per Gaussian and field: (lo, hi) of the fixed-point sum (one little-endian
// 64-bit word with INT64_ATOMICS), or the float sum and an unused word.
#if FLOAT_ATOMICS && !CAS_FALLBACK
layout(std430, binding = GRAD_ACCUMULATE_ACC) buffer AccBuf { float acc[]; };
#elif INT64_ATOMICS
layout(std430, binding = GRAD_ACCUMULATE_ACC) buffer AccBuf { uint64_t acc[]; };
#else
layout(std430, binding = GRAD_ACCUMULATE_ACC) buffer AccBuf { uint acc[]; };
#endif
// count: sorted pairs; bits: log2 of the most pairs one Gaussian can have, rounded up;
// vecs: vec4s of fields per pair.
layout(push_constant) uniform GradBlock { GradPush pc; };

#if !FLOAT_ATOMICS
// The fixed-point scale 2^s of each field as two power-of-two factors (each in float
// range; multiplying by them is exact), computed once per workgroup.
shared vec2 s_scale[MAX_GRAD_FIELDS];
#endif

void main() {
    uint k = linear_group_id() * gl_WorkGroupSize.x + gl_LocalInvocationIndex;
#if !FLOAT_ATOMICS
    if (gl_LocalInvocationIndex < 4u * pc.vecs) {
        int sh = grad_shift(maxima[gl_LocalInvocationIndex], pc.bits);
        s_scale[gl_LocalInvocationIndex] = vec2(ldexp(1.0, sh / 2), ldexp(1.0, sh - sh / 2));
    }
    barrier();
#endif
    if (k >= pc.count) return;
    uint g = values[k];
    uint fields = 4u * pc.vecs;
    // The pair's partial sums a vec4 at a time; the inner loop is unrolled so its indices
    // are constants (CPU implementations run indexed loads as per-lane loops).
    for (uint vi = 0u; vi < pc.vecs; vi++) {
    vec4 p = pair_grads[pc.vecs * k + vi];
    [[unroll]] for (uint c = 0u; c < 4u; c++) {
        uint f = 4u * vi + c;
        float v = p[c];
        if (v == 0.0) continue;
        uint i = (g * fields + f) * 2u;
#if FLOAT_ATOMICS && !CAS_FALLBACK
        atomicAdd(acc[i], v);
#elif FLOAT_ATOMICS
        uint old = acc[i];
        for (;;) {
            uint seen = atomicCompSwap(acc[i], old, floatBitsToUint(uintBitsToFloat(old) + v));
            if (seen == old) break;
            old = seen;
        }
#else
        vec2 m = s_scale[f];
#if INT64_ATOMICS
        // floor(x) as a 64-bit integer: to_fixed's value (|x| < 2^63, integer-valued).
        atomicAdd(acc[i / 2u], uint64_t(int64_t(floor(v * m.x * m.y))));
#else
        uvec2 x = to_fixed(v * m.x * m.y);
        uint old = atomicAdd(acc[i], x.x);
        uint carry = old + x.x < old ? 1u : 0u;
        if (x.y + carry != 0u) atomicAdd(acc[i + 1u], x.y + carry);
#endif
#endif
    }
    }
}
