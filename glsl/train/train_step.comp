#version 460
// Training step on the device: one invocation per Gaussian.
//
// The Gaussians' stored parameters (the original's: centre, log scales, unnormalised
// quaternion, opacity logit, SH coefficients up to the largest degree) live in STATE, one
// record of `pc.counts.y` floats each (a multiple of 4; the colour from float COLOUR_OFFSET,
// Model::record_floats); Adam's moments in M and V, the same layout. The SH part is
// stepped and copied a vec4 at a time (STATE4, M4, V4, SH_GRADS4, SH4 alias the same
// buffers; no float is accessed through both): a CPU device runs each buffer access with a
// per-invocation index as a loop over its lanes, and a vec4 costs what a float does. With
// STEP_STATS it adds the frame's densification statistics (norm of the 2D-mean gradient
// in NDC, views seen, largest screen radius) for every Gaussian the frame drew; with
// STEP_ADAM it takes the chain rule from the backward pass's gradients of the activated
// values (preprocess_bwd's GaussianGrad, SH gradients in texel layout) to the stored
// parameters and one Adam step (torch.optim.Adam: betas 0.9, 0.999, eps 1e-15, the bias
// corrections from the host per group); always it writes the activated record (centre,
// sigmoid opacity, exp scales, normalised quaternion) and the SH texels that the next
// forward pass reads. Feature splats (STEP_FEATURES): the record's colour part holds the K
// feature channels instead of SH, their gradients come from the feature blend's backward
// pass, and they are written both Gaussian-major in groups of four (FEATURES, what the
// backward pass reads) and one buffer per group (FEAT0..3, what the feature blend reads).
// Gradient clipping: a first dispatch (STEP_NORM) writes each Gaussian's squared gradient
// norm (the stored parameters'), which loss_reduce adds up in a fixed order into
// NORM_TOTAL; the step (STEP_CLIP) then scales every gradient by min(1, max / norm), as
// Model::step does. The MCMC strategy (STEP_NOISE): the regularisers' gradients (mean
// opacity, mean scale) join the loss's, and after the step each centre moves by noise
// shaped by its covariance (Model::add_noise; the same hashed normals as the host's).
// Each Gaussian's values are its own: the result does not depend on the order the device
// runs them in. The arithmetic is the host's, operation by operation (the host
// optimiser's Model::step, Model::add_stats and Model::params), `precise` so that no
// compiler fuses it differently.
#extension GL_GOOGLE_include_directive : require
// 256 invocations where the device allows them (faster on lavapipe), else 128: the host's
// choice (gpu::workgroup::wide_linear_workgroup), as a specialization constant.
#define WG_SIZE_SPEC_ID WIDE_WG_SPEC
#include "common.glsl"

layout(std430, binding = TRAIN_STEP_STATE) buffer StateBuf { float state[]; };
layout(std430, binding = TRAIN_STEP_M) buffer MBuf { float moment_m[]; };
layout(std430, binding = TRAIN_STEP_V) buffer VBuf { float moment_v[]; };
layout(std430, binding = TRAIN_STEP_GRADS) readonly buffer GradBuf { GaussianGrad grads[]; };
layout(std430, binding = TRAIN_STEP_SH_GRADS) readonly buffer ShGradBuf { float sh_grads[]; };
layout(std430, binding = TRAIN_STEP_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
// Per Gaussian: (sum of 2D-mean gradient norms, views seen, largest radius, 0).
layout(std430, binding = TRAIN_STEP_STATS) buffer StatsBuf { vec4 stats[]; };
layout(std430, binding = TRAIN_STEP_GAUSSIANS) writeonly buffer GaussianBuf { Gaussian gaussians[]; };
layout(std430, binding = TRAIN_STEP_SH) writeonly buffer ShBuf { float sh_out[]; };
layout(std430, binding = TRAIN_STEP_STATE) buffer State4Buf { vec4 state4[]; };
layout(std430, binding = TRAIN_STEP_M) buffer M4Buf { vec4 moment_m4[]; };
layout(std430, binding = TRAIN_STEP_V) buffer V4Buf { vec4 moment_v4[]; };
layout(std430, binding = TRAIN_STEP_SH_GRADS) readonly buffer ShGrad4Buf { vec4 sh_grads4[]; };
layout(std430, binding = TRAIN_STEP_SH) writeonly buffer Sh4Buf { vec4 sh_out4[]; };
layout(std430, binding = TRAIN_STEP_FEATURE_GRADS) readonly buffer FeatGradBuf { vec4 feature_grads[]; };
layout(std430, binding = TRAIN_STEP_FEATURES) writeonly buffer FeatBuf { vec4 features_out[]; };
layout(std430, binding = TRAIN_STEP_FEAT0) writeonly buffer Feat0Buf { vec4 feat0[]; };
layout(std430, binding = TRAIN_STEP_FEAT1) writeonly buffer Feat1Buf { vec4 feat1[]; };
layout(std430, binding = TRAIN_STEP_FEAT2) writeonly buffer Feat2Buf { vec4 feat2[]; };
layout(std430, binding = TRAIN_STEP_FEAT3) writeonly buffer Feat3Buf { vec4 feat3[]; };
layout(std430, binding = TRAIN_STEP_NORMS) writeonly buffer NormBuf { vec4 norms[]; };
layout(std430, binding = TRAIN_STEP_NORM_TOTAL) readonly buffer NormTotalBuf { vec4 norm_total[]; };

layout(push_constant) uniform StepBlock { StepPush pc; };

// model::pcg_hash, model::noise_normal.
uint pcg_hash(uint x) {
    uint state = x * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

float noise_normal(uint key, uint i, uint a) {
    uint h = pcg_hash(key ^ pcg_hash(i * 4u + a));
    uint h2 = pcg_hash(h ^ 0x9e3779b9u);
    precise float u1 = float((h >> 8u) + 1u) / 16777216.0;
    precise float u2 = float((h2 >> 8u) + 1u) / 16777216.0;
    precise float r = sqrt(-2.0 * log(u1));
    precise float n = r * cos(6.2831853071795864 * u2);
    return n;
}

float sigmoid_of(float x) {
    precise float e = exp(-x);
    precise float s = 1.0 / (1.0 + e);
    return s;
}

// One Adam step of value j of the records (`g` its gradient), learning rate `lr`, bias
// corrections `c1`, `c2`: the host's Moments::step.
void adam(uint j, float g, float lr, float c1, float c2) {
    precise float m = 0.9 * moment_m[j] + (1.0 - 0.9) * g;
    precise float v = 0.999 * moment_v[j] + (1.0 - 0.999) * g * g;
    moment_m[j] = m;
    moment_v[j] = v;
    precise float p = state[j] - lr / c1 * m / (sqrt(v) / c2 + 1e-15);
    state[j] = p;
}

// adam for the values of vec4 j4 of the records (`s` its parameters) where `on` is true,
// each with its own learning rate and bias corrections: the same operations per component;
// the others (padding, a skipped opacity) keep their bits. Returns the parameters.
vec4 adam4(uint j4, vec4 s, vec4 g, vec4 lr, vec4 c1, vec4 c2, bvec4 on) {
    vec4 m0 = moment_m4[j4];
    vec4 v0 = moment_v4[j4];
    precise vec4 m = 0.9 * m0 + (1.0 - 0.9) * g;
    precise vec4 v = 0.999 * v0 + (1.0 - 0.999) * g * g;
    precise vec4 p = s - lr / c1 * m / (sqrt(v) / c2 + 1e-15);
    moment_m4[j4] = mix(m0, m, on);
    moment_v4[j4] = mix(v0, v, on);
    vec4 stepped = mix(s, p, on);
    state4[j4] = stepped;
    return stepped;
}

// The SH coefficients of Gaussian i (record from float `base`): with `adam`, one Adam step
// of each (DC at the first colour rate, the rest at the second; gradients times `scale`),
// then their texels for the next forward pass (0 past the coefficients), a vec4 at a time.
void sh_step(uint i, uint base, bool adam, float scale) {
    uint texel_vecs = pc.counts.w / 4u;
    uint colours = pc.counts.z;
    uint at = (base + COLOUR_OFFSET) / 4u;
    for (uint t = 0u; t < texel_vecs; t++) {
        bvec4 valid = lessThan(uvec4(4u * t) + uvec4(0u, 1u, 2u, 3u), uvec4(colours));
        vec4 p = state4[at + t];
        if (adam) {
            vec4 g = sh_grads4[i * texel_vecs + t] * scale;
            vec4 lr = t == 0u ? vec4(pc.lr_sh.xxx, pc.lr_sh.y) : vec4(pc.lr_sh.y);
            p = adam4(at + t, p, g, lr, vec4(pc.lr_sh.z), vec4(pc.lr_sh.w), valid);
        }
        sh_out4[i * texel_vecs + t] = mix(vec4(0.0), p, valid);
    }
}

// The gradients of Gaussian i's stored parameters: centre, log scales, quaternion, opacity
// logit (the chain rule through exp, q / |q| and the sigmoid); the colour part is read
// where it is used (colour_grad).
struct RawGrad {
    vec3 mean;
    vec3 log_scale;
    vec4 quat;
    float logit;
};

// Mip-Splatting's 3D filter `f` (STEP_MIP) on scales `sizes`: the filtered scales (xyz)
// and the opacity's factor sqrt(det(S^2) / det(S^2 + f^2)) (w);
// train::model::mip::filtered.
vec4 mip_filtered(vec3 sizes, float f) {
    precise float f2 = f * f;
    precise vec3 sq = sizes * sizes;
    precise vec3 after = sq + vec3(f2);
    precise float det1 = sq.x * sq.y * sq.z;
    precise float det2 = after.x * after.y * after.z;
    precise float factor = sqrt(det1 / det2);
    return vec4(sqrt(after), factor);
}

RawGrad raw_grad(uint i, vec4 s0, vec4 s1, vec4 s2) {
    vec3 log_scale = vec3(s0.w, s1.xy);
    GaussianGrad g = grads[i];
    RawGrad r;
    r.mean = g.mean_opacity.xyz;
    for (uint a = 0u; a < 3u; a++) {
        precise float gl = g.scale[a] * exp(log_scale[a]);
        r.log_scale[a] = gl;
    }
    vec4 q = vec4(s1.zw, s2.xy);
    precise float norm = sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    precise vec4 u = q / norm;
    precise float dot_ = g.quat.x * u.x + g.quat.y * u.y + g.quat.z * u.z + g.quat.w * u.w;
    for (uint a = 0u; a < 4u; a++) {
        precise float gq = (g.quat[a] - u[a] * dot_) / norm;
        r.quat[a] = gq;
    }
    float p = sigmoid_of(s2.z);
    precise float go = g.mean_opacity.w * p * (1.0 - p);
    r.logit = go;
    if ((pc.flags_size.x & STEP_MIP) != 0u) {
        // Through the filter (train::model::mip::log_scale_grads).
        float f = s2.w;
        vec3 sizes = vec3(exp(log_scale.x), exp(log_scale.y), exp(log_scale.z));
        vec4 mf = mip_filtered(sizes, f);
        vec3 filtered = mf.xyz;
        float factor = mf.w;
        float g_op = g.mean_opacity.w;
        precise float opacity = p * factor;
        precise float f2 = f * f;
        precise vec3 sq = sizes * sizes;
        precise vec3 gl = g.scale.xyz * (sq / filtered) + vec3(g_op * opacity) * (vec3(f2) / (sq + vec3(f2)));
        r.log_scale = gl;
        precise float gm = g_op * factor * p * (1.0 - p);
        r.logit = gm;
    }
    if ((pc.flags_size.x & STEP_NOISE) != 0u) {
        // MCMC's regularisers, as Model::step adds them.
        precise float ro = go + pc.clip.z * p * (1.0 - p);
        r.logit = ro;
        for (uint a = 0u; a < 3u; a++) {
            precise float rs = r.log_scale[a] + pc.clip.w * exp(log_scale[a]);
            r.log_scale[a] = rs;
        }
    }
    return r;
}

float colour_grad(uint i, uint k, bool features) {
    if (features) return feature_grads[i * pc.flags_size.w + k / 4u][k % 4u];
    return sh_grads[i * pc.counts.w + k];
}

void main() {
    uint i = linear_group_id() * WG_SIZE + gl_LocalInvocationIndex;
    uint count = pc.counts.x;
    if (i >= count) return;
    uint rec = pc.counts.y;
    uint colours = pc.counts.z;
    uint texel_floats = pc.counts.w;
    uint flags = pc.flags_size.x;
    uint groups = pc.flags_size.w;
    bool features = (flags & STEP_FEATURES) != 0u;
    uint base = i * rec;
    // The record's first three vec4s: centre and log scales (s0, s1.xy), quaternion
    // (s1.zw, s2.xy), opacity logit (s2.z), an unused float.
    uint b4 = base / 4u;
    vec4 s0 = state4[b4], s1 = state4[b4 + 1u], s2 = state4[b4 + 2u];
    if ((flags & STEP_NORM) != 0u) {
        RawGrad r = raw_grad(i, s0, s1, s2);
        precise float sq = dot(r.mean, r.mean) + dot(r.log_scale, r.log_scale)
            + dot(r.quat, r.quat) + r.logit * r.logit;
        for (uint k = 0u; k < colours; k++) {
            float g = colour_grad(i, k, features);
            sq += g * g;
        }
        norms[i] = vec4(sq, 0.0, 0.0, 0.0);
        return;
    }
    if ((flags & STEP_STATS) != 0u) {
        float r = splats[i].color_radius.w;
        if (r > 0.0) {
            vec2 g = grads[i].mean2d_abs.xy;
            vec2 half_size = uintBitsToFloat(pc.flags_size.yz);
            precise float gx = g.x * half_size.x;
            precise float gy = g.y * half_size.y;
            precise float norm = sqrt(gx * gx + gy * gy);
            vec4 s = stats[i];
            precise float sum = s.x + norm;
            stats[i] = vec4(sum, s.y + 1.0, max(s.z, r), 0.0);
        }
    }
    // Model::step: with clipping, every gradient times max / norm when the norm (finite)
    // exceeds max.
    float scale = 1.0;
    if ((flags & (STEP_ADAM | STEP_CLIP)) == (STEP_ADAM | STEP_CLIP)) {
        float norm = sqrt(norm_total[0].x);
        if (norm > pc.clip.x && !isinf(norm) && !isnan(norm)) scale = pc.clip.x / norm;
    }
    if ((flags & STEP_ADAM) != 0u) {
        RawGrad r = raw_grad(i, s0, s1, s2);
        // Per float: centre (lr.x), log scale (lr.y), quaternion (lr.z), opacity (lr.w).
        vec4 lr = pc.lr, c1 = pc.c1, c2 = pc.c2;
        bool opacity = (flags & STEP_SKIP_OPACITY) == 0u;
        s0 = adam4(b4, s0, vec4(r.mean, r.log_scale.x) * scale, lr.xxxy, c1.xxxy, c2.xxxy, bvec4(true));
        s1 = adam4(b4 + 1u, s1, vec4(r.log_scale.yz, r.quat.xy) * scale, lr.yyzz, c1.yyzz, c2.yyzz, bvec4(true));
        s2 = adam4(b4 + 2u, s2, vec4(r.quat.zw, r.logit, 0.0) * scale, lr.zzww, c1.zzww, c2.zzww,
            bvec4(true, true, opacity, false));
        // Feature channels at the first colour rate (SH: sh_step below).
        for (uint k = 0u; features && k < colours; k++) {
            adam(base + COLOUR_OFFSET + k, colour_grad(i, k, true) * scale, pc.lr_sh.x, pc.lr_sh.z, pc.lr_sh.w);
        }
        if ((flags & STEP_NOISE) != 0u) {
            // Model::add_noise with the stepped values.
            vec4 q = vec4(s1.zw, s2.xy);
            precise float qn = sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
            float w = q.x / qn, x = q.y / qn, y = q.z / qn, z = q.w / qn;
            vec3 sc = vec3(exp(s0.w), exp(s1.x), exp(s1.y));
            float o = sigmoid_of(s2.z);
            precise float gate = 1.0 / (1.0 + exp(-100.0 * ((1.0 - o) - 0.995)));
            vec3 v;
            for (uint a = 0u; a < 3u; a++) {
                precise float n = noise_normal(pc.noise.x, i, a) * gate * pc.clip.y;
                v[a] = n;
            }
            // rows of R
            vec3 r0 = vec3(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y));
            vec3 r1 = vec3(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x));
            vec3 r2 = vec3(2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y));
            precise vec3 rt = r0 * v.x + r1 * v.y + r2 * v.z;
            precise vec3 t = sc * sc * rt;
            precise vec3 d = vec3(dot(r0, t), dot(r1, t), dot(r2, t));
            precise vec3 moved = s0.xyz + d;
            s0.xyz = moved;
            state4[b4] = s0;
        }
    }
    // The activated record, SH texels and feature channels of the next forward pass.
    vec3 sizes = vec3(exp(s0.w), exp(s1.x), exp(s1.y));
    vec4 q = vec4(s1.zw, s2.xy);
    precise float qn = sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    precise vec4 rot = q / qn;
    float opacity = sigmoid_of(s2.z);
    if ((flags & STEP_MIP) != 0u) {
        vec4 mf = mip_filtered(sizes, s2.w);
        precise float o = opacity * mf.w;
        opacity = o;
        sizes = mf.xyz;
    }
    gaussians[i] = Gaussian(vec4(s0.xyz, opacity), vec4(sizes, 0.0), rot);
    if (!features) {
        sh_step(i, base, (flags & STEP_ADAM) != 0u, scale);
        return;
    }
    for (uint k = 0u; k < texel_floats; k++) sh_out[i * texel_floats + k] = 0.0;
    for (uint g = 0u; g < groups; g++) {
        vec4 v = vec4(0.0);
        for (uint c = 0u; c < 4u; c++) {
            uint k = 4u * g + c;
            if (k < colours) v[c] = state[base + COLOUR_OFFSET + k];
        }
        features_out[i * groups + g] = v;
        if (g == 0u) feat0[i] = v;
        else if (g == 1u) feat1[i] = v;
        else if (g == 2u) feat2[i] = v;
        else feat3[i] = v;
    }
}
