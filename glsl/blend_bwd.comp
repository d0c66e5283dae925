#version 460
// Blend backward: one workgroup per bin, one invocation per pixel. Walks the bin's sorted
// pairs back to front from the last pair any of its pixels composited (the forward's saved
// last contributor; no re-sort, no re-render), undoing each pixel's transmittance from the
// saved final T, and writes per pair the bin's sum of the pixels' gradients with respect
// to the pair's Gaussian: 2D mean (2), conic (3), opacity, colour (3), depth, and the sum of
// |dL/d mean2d| per axis (gsplat's absgrad). Mirrors the pixel loop of cpu::backward.
//
// Determinism: a pixel's contribution is summed over the workgroup in a fixed order (a
// subgroup sum, then the subgroups in index order), and each pair's sum is written to the
// pair's own slot: no float atomics. grad_accumulate.comp then adds the pairs of each
// Gaussian in fixed point, where the order of additions cannot change the result. The
// largest |sum| of each field is kept (an order-independent max) to choose that fixed point.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_vote : require
#include "splat_common.glsl"

#ifndef BIN
#define BIN 16u
#endif
#ifndef SPLAT_KERNEL
#define SPLAT_KERNEL 0u
#endif
// Gradient fields per pair (GRAD_FIELDS, src/gpu/shader_set.rs).
#define F GRAD_FIELDS
// Pairs staged in shared memory at a time.
#define BATCH 16u

layout(local_size_x = BIN, local_size_y = BIN) in;
// At least the number of subgroups of a BIN x BIN workgroup (the host passes it from the
// device's minimum subgroup size).
layout(constant_id = GRAD_SPEC_MAX_SUBGROUPS) const uint MAX_SUBGROUPS = 32u;

layout(std430, binding = BLEND_BWD_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
layout(std430, binding = BLEND_BWD_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = BLEND_BWD_VALUES) readonly buffer ValueBuf { uint values[]; };
layout(std430, binding = BLEND_BWD_RANGES) readonly buffer RangeBuf { uvec2 ranges[]; };
// Per pixel: one past the last composited pair, and the final transmittance's bits.
layout(std430, binding = BLEND_BWD_LAST) readonly buffer LastBuf { uvec2 last_state[]; };
// Per pixel: dL/d colour (rgb, with the background) and dL/d alpha, the latter including
// what the alpha-normalised depth passes on to it (src/render/backward.rs).
layout(std430, binding = BLEND_BWD_GRAD_COLOR) readonly buffer GradColorBuf { vec4 grad_color[]; };
// Per pixel: dL/d (sum of depth * weight), i.e. dL/d depth / alpha.
layout(std430, binding = BLEND_BWD_GRAD_DEPTH) readonly buffer GradDepthBuf { float grad_depth[]; };
layout(std430, binding = BLEND_BWD_PAIR_GRADS) writeonly buffer PairGradBuf { float pair_grads[]; };
// Largest |pair sum| per field, as float bits (non-negative floats order like their bits).
layout(std430, binding = BLEND_BWD_MAXIMA) buffer MaximaBuf { uint maxima[]; };

shared vec4 s_mean_opacity[BATCH];  // mean2d.xy, opacity, depth
shared vec4 s_conic[BATCH];
shared vec4 s_color[BATCH];
shared float s_part[BATCH * MAX_SUBGROUPS * F];
shared uint s_last;
shared uint s_max[F];

void main() {
    uvec2 bin = gl_WorkGroupID.xy;
    uvec2 pix = bin * BIN + gl_LocalInvocationID.xy;
    bool inside = pix.x < params.image.x && pix.y < params.image.y;
    vec2 pixf = vec2(pix);
    uvec2 range = ranges[bin.y * params.bins.y + bin.x];
    uint last = 0u;
    float T = 1.0;
    vec4 g_ca = vec4(0.0);
    float g_dacc = 0.0;
    if (inside) {
        uint p = pix.y * params.image.x + pix.x;
        uvec2 state = last_state[p];
        last = state.x;
        T = uintBitsToFloat(state.y);
        g_ca = grad_color[p];
        g_dacc = grad_depth[p];
    }
    float t_final = T;
    vec3 behind = t_final * params.background.rgb;
    float behind_depth = 0.0;
    uint li = gl_LocalInvocationIndex;
    if (li == 0u) s_last = 0u;
    if (li < F) s_max[li] = 0u;
    barrier();
    if (last != 0u) atomicMax(s_last, last);
    barrier();
    // One past the last pair any pixel of the bin composited; the pairs after it receive 0.
    uint end = max(s_last, range.x);
    for (uint k = end + li; k < range.y; k += BIN * BIN) {
        for (uint f = 0u; f < F; f++) pair_grads[k * F + f] = 0.0;
    }
    uint batch_end = end;
    while (batch_end > range.x) {
        uint count = min(BATCH, batch_end - range.x);
        if (li < count) {
            Splat s = splats[values[batch_end - 1u - li]];
            s_mean_opacity[li] = vec4(s.mean_opacity_bound.xyz, s.conic_depth.w);
            s_conic[li] = s.conic_depth;
            s_color[li] = s.color_radius;
        }
        barrier();
        for (uint j = 0u; j < count; j++) {
            uint k = batch_end - 1u - j;
            float c[F];
            for (uint f = 0u; f < F; f++) c[f] = 0.0;
            bool used = k < last;
            if (used) {
                vec4 mo = s_mean_opacity[j];
                vec3 conic = s_conic[j].xyz;
                vec3 col = s_color[j].rgb;
                // The forward's alpha and skip rule (blend.comp, composite).
                vec2 d = mo.xy - pixf;
                float power = -0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) - conic.y * d.x * d.y;
                float unclamped = kernel_falloff(SPLAT_KERNEL, mo.z, min(power, 0.0));
                float alpha = min(ALPHA_MAX, unclamped);
                if (power <= 0.0 && alpha >= ALPHA_MIN) {
                    float one_minus = 1.0 - alpha;
                    float t_i = T / one_minus;  // transmittance in front of this Gaussian
                    float w = alpha * t_i;
                    vec3 g_col = g_ca.rgb * w;
                    float g_a = dot(g_ca.rgb, col * t_i - behind / one_minus)
                        + g_dacc * (mo.w * t_i - behind_depth / one_minus)
                        + g_ca.a * t_final / one_minus;
                    behind += col * w;
                    behind_depth += mo.w * w;
                    T = t_i;
                    if (unclamped < ALPHA_MAX) {
                        // d alpha / d opacity and d alpha / d power (a constant branch).
                        bool power_kernel = SPLAT_KERNEL == SPLAT_KERNEL_POWER;
                        float da_do = power_kernel ? 1.0 + 2.0 * power / 9.0 : exp(power);
                        float da_dp = power_kernel ? mo.z * (2.0 / 9.0) : unclamped;
                        float gp = g_a * da_dp;
                        c[0] = gp * -(conic.x * d.x + conic.y * d.y);
                        c[1] = gp * -(conic.z * d.y + conic.y * d.x);
                        c[2] = gp * (-0.5 * d.x * d.x);
                        c[3] = gp * (-d.x * d.y);
                        c[4] = gp * (-0.5 * d.y * d.y);
                        c[5] = g_a * da_do;
                        c[10] = abs(c[0]);
                        c[11] = abs(c[1]);
                    }
                    c[6] = g_col.r;
                    c[7] = g_col.g;
                    c[8] = g_col.b;
                    c[9] = g_dacc * w;
                }
            }
            // The subgroup's sum (skipped where none of its pixels composited the pair).
            uint slot = (j * MAX_SUBGROUPS + gl_SubgroupID) * F;
            if (subgroupAny(used)) {
                for (uint f = 0u; f < F; f++) {
                    float s = subgroupAdd(c[f]);
                    if (subgroupElect()) s_part[slot + f] = s;
                }
            } else if (subgroupElect()) {
                for (uint f = 0u; f < F; f++) s_part[slot + f] = 0.0;
            }
        }
        barrier();
        // The workgroup's sum per pair and field: subgroups in index order.
        for (uint t = li; t < count * F; t += BIN * BIN) {
            uint j = t / F, f = t % F;
            float s = 0.0;
            for (uint sg = 0u; sg < gl_NumSubgroups; sg++) s += s_part[(j * MAX_SUBGROUPS + sg) * F + f];
            pair_grads[(batch_end - 1u - j) * F + f] = s;
            if (s != 0.0) atomicMax(s_max[f], floatBitsToUint(abs(s)));
        }
        batch_end -= count;
        barrier();
    }
    barrier();
    if (li < F && s_max[li] != 0u) atomicMax(maxima[li], s_max[li]);
}
