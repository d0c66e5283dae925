#version 460
// Preprocess backward: one invocation per Gaussian reads its accumulated gradients with
// respect to the projected quantities (2D mean, conic, opacity, colour, depth; fixed point,
// grad_common.glsl) and applies the chain rule through the forward's preprocess: EWA
// projection with the 0.3 dilation and the guard-band clamp, the covariance from the
// normalised quaternion and scales (times the scale modifier), and the SH colour with its
// view direction's dependence on the mean and the clamp at 0 after +0.5. Writes dL/d mean,
// opacity, quaternion (the normalised one the device holds; the host applies the
// normalisation's Jacobian), scales and SH coefficients. Mirrors cpu::backward's
// project_backward line by line (in f32).
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "splat_common.glsl"
#include "grad_common.glsl"
#ifndef FLOAT_ATOMICS
#define FLOAT_ATOMICS 0
#endif
// 1: the variant for frames through a lens other than the pinhole (the unscented
// transform's chain rule, lens.glsl); 0: the pinhole's EWA alone.
#ifndef LENSES
#define LENSES 0
#endif

// 256 invocations where the device allows them (faster on lavapipe), else 128: the host's
// choice (gpu::workgroup::wide_linear_workgroup), as a specialization constant.
layout(local_size_x = LINEAR_WG, local_size_x_id = WIDE_WG_SPEC) in;

layout(std430, binding = PREPROCESS_BWD_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
layout(std430, binding = PREPROCESS_BWD_GAUSSIANS) readonly buffer GaussianBuf { Gaussian gaussians[]; };
layout(binding = PREPROCESS_BWD_SH) uniform samplerBuffer sh_texels;
layout(std430, binding = PREPROCESS_BWD_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = PREPROCESS_BWD_MAXIMA) readonly buffer MaximaBuf { uint maxima[]; };
// Two fields' (lo, hi) sums per uvec4: a Gaussian's 4 * pc.vecs fields are whole uvec4s.
layout(std430, binding = PREPROCESS_BWD_ACC) readonly buffer AccBuf { uvec4 acc[]; };
// Per Gaussian: its GaussianGrad.
layout(std430, binding = PREPROCESS_BWD_GRADS) writeonly buffer GradBuf { GaussianGrad grads[]; };
// dL/d SH coefficient, in the SH texels' layout (a vec4 per texel: on CPU devices each
// storage access costs a loop over the lanes, whatever its width).
layout(std430, binding = PREPROCESS_BWD_SH_GRADS) writeonly buffer ShGradBuf { vec4 sh_grads[]; };
// dL/d feature channel (direct values), 4 per group: `pc.vecs - 3` groups.
layout(std430, binding = PREPROCESS_BWD_FEATURE_GRADS) writeonly buffer FeatGradBuf { vec4 feature_grads[]; };
layout(push_constant) uniform GradBlock { GradPush pc; };

#include "sh_common.glsl"
#if LENSES
#include "lens.glsl"
#endif

// Texels of the most SH coefficients (degree 3: 16 per channel, 48 floats).
#define SH_TEXELS 12u

// The float sum of field f from its (lo, hi) fixed-point pair.
float field_value(uvec2 v, uint f) {
#if FLOAT_ATOMICS
    return uintBitsToFloat(v.x);
#else
    if (v == uvec2(0u)) return 0.0;
    return from_fixed(v, grad_shift(maxima[f], pc.bits));
#endif
}

// Fields f and f + 1 (f even) of Gaussian g: one load for two fields.
vec2 field_pair(uint g, uint f) {
    uvec4 v = acc[(g * 4u * pc.vecs + f) / 2u];
    return vec2(field_value(v.xy, f), field_value(v.zw, f + 1u));
}

// SH basis Y_k(dir) and its gradient (cpu::backward::sh_basis, sh_basis_grad).
void sh_basis(uint degree, vec3 d, out float b[16], out vec3 gb[16]) {
    for (uint k = 0u; k < 16u; k++) { b[k] = 0.0; gb[k] = vec3(0.0); }
    float x = d.x, y = d.y, z = d.z;
    b[0] = SH_C0;
    if (degree > 0u) {
        b[1] = -SH_C1 * y; gb[1] = vec3(0.0, -SH_C1, 0.0);
        b[2] = SH_C1 * z;  gb[2] = vec3(0.0, 0.0, SH_C1);
        b[3] = -SH_C1 * x; gb[3] = vec3(-SH_C1, 0.0, 0.0);
    }
    if (degree > 1u) {
        float xx = x * x, yy = y * y, zz = z * z;
        b[4] = SH_C2[0] * x * y;               gb[4] = SH_C2[0] * vec3(y, x, 0.0);
        b[5] = SH_C2[1] * y * z;               gb[5] = SH_C2[1] * vec3(0.0, z, y);
        b[6] = SH_C2[2] * (2.0 * zz - xx - yy); gb[6] = SH_C2[2] * vec3(-2.0 * x, -2.0 * y, 4.0 * z);
        b[7] = SH_C2[3] * x * z;               gb[7] = SH_C2[3] * vec3(z, 0.0, x);
        b[8] = SH_C2[4] * (xx - yy);           gb[8] = SH_C2[4] * vec3(2.0 * x, -2.0 * y, 0.0);
        if (degree > 2u) {
            b[9] = SH_C3[0] * y * (3.0 * xx - yy);
            gb[9] = SH_C3[0] * vec3(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
            b[10] = SH_C3[1] * x * y * z;
            gb[10] = SH_C3[1] * vec3(y * z, x * z, x * y);
            b[11] = SH_C3[2] * y * (4.0 * zz - xx - yy);
            gb[11] = SH_C3[2] * vec3(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
            b[12] = SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
            gb[12] = SH_C3[3] * vec3(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
            b[13] = SH_C3[4] * x * (4.0 * zz - xx - yy);
            gb[13] = SH_C3[4] * vec3(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
            b[14] = SH_C3[5] * z * (xx - yy);
            gb[14] = SH_C3[5] * vec3(2.0 * x * z, -2.0 * y * z, xx - yy);
            b[15] = SH_C3[6] * x * (xx - 3.0 * yy);
            gb[15] = SH_C3[6] * vec3(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
        }
    }
}

// Antialiased: the blended opacity is opacity * sqrt(max(r, min_ratio)) (the rules' floor,
// FrameParams.rules.w),
// r = det(cov2d) / det(cov2d + dilation) (cpu::backward::compensation), of the dilated
// 2D covariance abc. Adds the compensation's gradient to g_a, g_b, g_c; returns
// dL/d(opacity) from dL/d(blended opacity) `g_blended`.
float compensation_grads(vec3 abc, float g_blended, float opacity,
                         inout float g_a, inout float g_b, inout float g_c) {
    float a = abc.x, b = abc.y, c = abc.z;
    float det = a * c - b * b;
    float det0 = (a - COV2D_DILATION) * (c - COV2D_DILATION) - b * b;
    float r = det0 / det;
    float min_ratio = params.rules.w;
    float comp = sqrt(max(min_ratio, r));
    if (r > min_ratio) {
        float k = g_blended * opacity * 0.5 / comp / (det * det);
        g_a += k * ((c - COV2D_DILATION) * det - det0 * c);
        g_c += k * ((a - COV2D_DILATION) * det - det0 * a);
        g_b += k * (2.0 * b * det0 - 2.0 * b * det);
    }
    return g_blended * comp;
}

void main() {
    uint i = linear_group_id() * gl_WorkGroupSize.x + gl_LocalInvocationIndex;
    if (i >= pc.count) return;
    uint stride = ((params.counts.z * 3u + 3u) / 4u) * 4u;
    GaussianGrad out_g;
    out_g.mean_opacity = vec4(0.0);
    out_g.quat = vec4(0.0);
    out_g.scale = vec4(0.0);
    out_g.mean2d_abs = vec4(0.0);
    uint texels = stride / 4u;
    uint groups = pc.vecs - 3u;
    bool visible = splats[i].color_radius.w > 0.0;
    // Direct feature channels: their sums are their gradients.
    for (uint gi = 0u; gi < groups; gi++) {
        uint f = 12u + 4u * gi;
        feature_grads[i * groups + gi] = visible ? vec4(field_pair(i, f), field_pair(i, f + 2u)) : vec4(0.0);
    }
    if (!visible) {
        grads[i] = out_g;
        for (uint q = 0u; q < texels; q++) sh_grads[i * texels + q] = vec4(0.0);
        return;
    }
    vec2 f01 = field_pair(i, 0u), f23 = field_pair(i, 2u), f45 = field_pair(i, 4u);
    vec2 f67 = field_pair(i, 6u), f89 = field_pair(i, 8u), f1011 = field_pair(i, 10u);
    vec2 g_mean2d = f01;
    vec3 g_conic = vec3(f23, f45.x);
    float g_opacity = f45.y;
    vec3 g_color = vec3(f67, f89.x);
    float g_depth = f89.y;
    out_g.mean2d_abs = vec4(g_mean2d, f1011);
    out_g.mean_opacity.w = g_opacity;

    Gaussian g = gaussians[i];
    vec3 mean = g.pos_opacity.xyz;
    mat3 w_t = mat3(params.w2c_row0.xyz, params.w2c_row1.xyz, params.w2c_row2.xyz);  // W^T
    vec3 v = vec3(dot(params.w2c_row0.xyz, mean) + params.w2c_row0.w,
                  dot(params.w2c_row1.xyz, mean) + params.w2c_row1.w,
                  dot(params.w2c_row2.xyz, mean) + params.w2c_row2.w);
    float sm = params.filters.x;
    vec3 s = sm * g.scale.xyz;
    mat3 rot = quat_to_mat3(g.rotation);
    mat3 m = rot * mat3(s.x, 0.0, 0.0, 0.0, s.y, 0.0, 0.0, 0.0, s.z);
    mat3 cov3d = m * transpose(m);
#if LENSES
    // Through the lens (cpu::backward's lens module): the covariance as the forward's
    // unscented transform made it, the conic's and the compensation's chain rule as the
    // pinhole's, then the sigma points' back to the camera-space mean and axes W M.
    vec3 g_mean;
    mat3 g_m;
    {
        mat3 axes = transpose(w_t) * m;
        vec2 mean_px;
        vec3 cov;
        lens_unscented(v, axes, mean_px, cov);
        float a = cov.x + COV2D_DILATION;
        float b = cov.y;
        float c = cov.z + COV2D_DILATION;
        float det = a * c - b * b;
        float det2 = det * det;
        float g_a = g_conic.x * (-c * c / det2) + g_conic.y * (b * c / det2) + g_conic.z * (1.0 / det - a * c / det2);
        float g_c = g_conic.x * (1.0 / det - a * c / det2) + g_conic.y * (b * a / det2) + g_conic.z * (-a * a / det2);
        float g_b = g_conic.x * (2.0 * b * c / det2) + g_conic.y * (-1.0 / det - 2.0 * b * b / det2)
            + g_conic.z * (2.0 * a * b / det2);
        if (params.cam_pos.w != 0.0) {
            out_g.mean_opacity.w = compensation_grads(vec3(a, b, c), g_opacity, g.pos_opacity.w, g_a, g_b, g_c);
        }
        vec3 g_v;
        mat3 g_axes;
        lens_unscented_backward(v, axes, g_mean2d, vec3(g_a, g_b, g_c), g_v, g_axes);
        // The depth: the distance from the camera for the lenses that see behind their
        // image plane, else z (as preprocess).
        uint lens = params.modes.y;
        bool by_distance = lens == LENS_FISHEYE || lens == LENS_EQUIRECTANGULAR;
        g_v += g_depth * (by_distance ? v / length(v) : vec3(0.0, 0.0, 1.0));
        g_mean = w_t * g_v;
        // axes = W M: dL/dM = W^T dL/d axes.
        g_m = w_t * g_axes;
    }
#else
    float fx = params.focal.x, fy = params.focal.y;
    vec4 lim = params.limits;
    float z = v.z;
    float tx = clamp(v.x / z, -lim.x, lim.y) * z;
    float ty = clamp(v.y / z, -lim.z, lim.w) * z;
    vec3 j0 = vec3(fx / z, 0.0, -(fx * tx) / (z * z));
    vec3 j1 = vec3(0.0, fy / z, -(fy * ty) / (z * z));
    vec3 t0 = w_t * j0;
    vec3 t1 = w_t * j1;
    vec3 s0 = cov3d * t0;
    vec3 s1 = cov3d * t1;
    float a = dot(t0, s0) + COV2D_DILATION;
    float b = dot(t0, s1);
    float c = dot(t1, s1) + COV2D_DILATION;
    float det = a * c - b * b;
    float det2 = det * det;
    // conic (A, B, C) = (c, -b, a) / det.
    float g_a = g_conic.x * (-c * c / det2) + g_conic.y * (b * c / det2) + g_conic.z * (1.0 / det - a * c / det2);
    float g_c = g_conic.x * (1.0 / det - a * c / det2) + g_conic.y * (b * a / det2) + g_conic.z * (-a * a / det2);
    float g_b = g_conic.x * (2.0 * b * c / det2) + g_conic.y * (-1.0 / det - 2.0 * b * b / det2)
        + g_conic.z * (2.0 * a * b / det2);
    if (params.cam_pos.w != 0.0) {
        out_g.mean_opacity.w = compensation_grads(vec3(a, b, c), g_opacity, g.pos_opacity.w, g_a, g_b, g_c);
    }
    // a = t0' S t0, b = t0' S t1, c = t1' S t1 (S symmetric).
    mat3 g_cov = mat3(g_a * t0 * t0.x + g_b * t0 * t1.x + g_c * t1 * t1.x,
                      g_a * t0 * t0.y + g_b * t0 * t1.y + g_c * t1 * t1.y,
                      g_a * t0 * t0.z + g_b * t0 * t1.z + g_c * t1 * t1.z);
    vec3 g_t0 = 2.0 * g_a * s0 + g_b * s1;
    vec3 g_t1 = 2.0 * g_c * s1 + g_b * s0;
    // t_k = W^T j_k, so dL/dj_k = W dL/dt_k; transpose(w_t) is W.
    vec3 g_j0 = transpose(w_t) * g_t0;
    vec3 g_j1 = transpose(w_t) * g_t1;
    vec3 g_v = vec3(0.0);
    float z2 = z * z, z3 = z2 * z;
    g_v.z += g_j0.x * (-fx / z2) + g_j0.z * (2.0 * fx * tx / z3);
    g_v.z += g_j1.y * (-fy / z2) + g_j1.z * (2.0 * fy * ty / z3);
    float g_tx = g_j0.z * (-fx / z2);
    float g_ty = g_j1.z * (-fy / z2);
    // tx = clamp(x / z, -lim, lim) z: x passes where unclamped, z carries the bound where clamped.
    float ux = v.x / z, uy = v.y / z;
    if (ux >= -lim.x && ux <= lim.y) g_v.x += g_tx; else g_v.z += g_tx * tx / z;
    if (uy >= -lim.z && uy <= lim.w) g_v.y += g_ty; else g_v.z += g_ty * ty / z;
    // mean2d = f * v.xy / z + c - 0.5; depth = z.
    g_v.x += g_mean2d.x * fx / z;
    g_v.y += g_mean2d.y * fy / z;
    g_v.z -= (g_mean2d.x * fx * v.x + g_mean2d.y * fy * v.y) / z2;
    g_v.z += g_depth;
    vec3 g_mean = w_t * g_v;
    // Sigma = M M^T with M = R S.
    mat3 g_m = (g_cov + transpose(g_cov)) * m;
#endif
    out_g.scale = vec4(dot(rot[0], g_m[0]) * sm, dot(rot[1], g_m[1]) * sm, dot(rot[2], g_m[2]) * sm, 0.0);
    mat3 g_rot = mat3(g_m[0] * s.x, g_m[1] * s.y, g_m[2] * s.z);
    // gr(row, col) = g_rot[col][row].
    float qr = g.rotation.x, qx = g.rotation.y, qy = g.rotation.z, qz = g.rotation.w;
    float r10 = g_rot[0][1], r01 = g_rot[1][0], r02 = g_rot[2][0], r20 = g_rot[0][2];
    float r21 = g_rot[1][2], r12 = g_rot[2][1], r00 = g_rot[0][0], r11 = g_rot[1][1], r22 = g_rot[2][2];
    out_g.quat = 2.0 * vec4(
        qz * (r10 - r01) + qy * (r02 - r20) + qx * (r21 - r12),
        qy * (r10 + r01) + qz * (r20 + r02) + qr * (r21 - r12) - 2.0 * qx * (r11 + r22),
        qx * (r10 + r01) + qr * (r02 - r20) + qz * (r21 + r12) - 2.0 * qy * (r00 + r22),
        qr * (r10 - r01) + qx * (r20 + r02) + qy * (r21 + r12) - 2.0 * qz * (r00 + r11));
    // SH colour = max(sum_k sh_k Y_k(dir) + 0.5, 0), dir = normalize(mean - camera centre).
    vec3 u = mean - params.cam_pos.xyz;
    float len = length(u);
    vec3 dir = u / len;
    uint degree = params.counts.y;
    uint used = (degree + 1u) * (degree + 1u);
    float basis[16];
    vec3 basis_grad[16];
    sh_basis(degree, dir, basis, basis_grad);
    // The used coefficients' texels, each fetched once (unrolled: constant indices).
    vec4 sh[SH_TEXELS];
    [[unroll]] for (uint q = 0u; q < SH_TEXELS; q++) {
        sh[q] = 4u * q < 3u * used ? texelFetch(sh_texels, int(i * texels + q)) : vec4(0.0);
    }
#define SH_COEFF(k) vec3(sh[(3u * (k)) / 4u][(3u * (k)) % 4u], sh[(3u * (k) + 1u) / 4u][(3u * (k) + 1u) % 4u], \
                         sh[(3u * (k) + 2u) / 4u][(3u * (k) + 2u) % 4u])
    vec3 raw = vec3(0.0);
    [[unroll]] for (uint k = 0u; k < 16u; k++) {
        if (k < used) raw += SH_COEFF(k) * basis[k];
    }
    vec3 g_raw = vec3(raw.x + 0.5 < 0.0 ? 0.0 : g_color.x,
                      raw.y + 0.5 < 0.0 ? 0.0 : g_color.y,
                      raw.z + 0.5 < 0.0 ? 0.0 : g_color.z);
    vec3 g_dir = vec3(0.0);
    [[unroll]] for (uint k = 0u; k < 16u; k++) {
        if (k < used) g_dir += basis_grad[k] * dot(SH_COEFF(k), g_raw);
    }
    // dL/d coefficient k, channel c = basis[k] * g_raw[c], at float 3k + c; 0 past the used.
    [[unroll]] for (uint q = 0u; q < SH_TEXELS; q++) {
        vec4 t = vec4(0.0);
        [[unroll]] for (uint c = 0u; c < 4u; c++) {
            uint k = (4u * q + c) / 3u;
            if (k < used) t[c] = (basis[k] * g_raw)[(4u * q + c) % 3u];
        }
        if (q < texels) sh_grads[i * texels + q] = t;
    }
    for (uint q = SH_TEXELS; q < texels; q++) sh_grads[i * texels + q] = vec4(0.0);
    g_mean += (g_dir - dir * dot(dir, g_dir)) / len;
    out_g.mean_opacity.xyz = g_mean;
    grads[i] = out_g;
}
