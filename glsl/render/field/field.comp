#version 460
// Field renders (render --mode field-slice | field-integral | field-max): the fitted field
// f(x) = sum_i o_i feat_i G_i(x) itself, a plain sum (no blending, no sort), four channels
// per dispatch. The CPU reference's field renders have every formula.
//
// One invocation per pixel of a PIXEL_WG_X x PIXEL_WG_Y (16x8) tile (WG_SIZE 128, within
// every device's limit;
// pixel = local index). The
// Gaussians are read in chunks of CHUNK: each of the first CHUNK invocations tests one
// against the tile's frustum (its support's bounding sphere against the four side planes;
// for a slice also against the plane), a workgroup scan compacts the survivors into shared
// memory in index order, and every pixel sums them in that order, so a pixel's sum has the
// same order on every device.
//
// FIELD_MODE 0 slice: the field where the pixel's ray meets the plane (NaN: misses).
//            1 integral: int_0^inf f(o + t d) dt in closed form per Gaussian.
//            2 max: each channel's maximum over params.mode.x samples at the centres of
//              equal segments of the ray's chord through the field's box (NaN: misses).
#ifndef FIELD_MODE
#define FIELD_MODE 0
#endif
#ifndef SPLAT_KERNEL
#define SPLAT_KERNEL 0u
#endif
#define WG_SIZE (PIXEL_WG_X * PIXEL_WG_Y)
#define TILE_W PIXEL_WG_X
#define TILE_H PIXEL_WG_Y
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

#define CHUNK WG_SIZE
layout(std430, binding = FIELD_PARAMS) readonly buffer ParamsBuf { FieldParams params; };
layout(std430, binding = FIELD_GAUSSIANS) readonly buffer GaussianBuf { FieldGaussian gaussians[]; };
// o_i feat_i, this group's four channels: features[i * groups + group].
layout(std430, binding = FIELD_FEATURES) readonly buffer FeatureBuf { vec4 features[]; };
// This group's four channels per pixel: out_field[group * pixels + pixel].
layout(std430, binding = FIELD_OUTPUT) buffer OutBuf { vec4 out_field[]; };
// A pass: channel group, the Gaussians [first, first + count), and whether to add to the
// output (every pass of a slice or an integral but the first) rather than write it.
// llvmpipe ends an invocation whose loops run past 65,535 iterations in all, silently,
// before it writes: the host keeps each pass below that and finds such a pixel by the
// pattern it filled the output with.
layout(push_constant) uniform FieldBlock { FieldPush push; };

shared vec4 s_mean[CHUNK];
shared vec4 s_a0[CHUNK];
shared vec4 s_a1[CHUNK];
shared vec4 s_feat[CHUNK];
shared uint wg_count;

float form(vec4 a0, vec4 a1, vec3 v, vec3 w) {
    return v.x * (a0.x * w.x + a0.y * w.y + a0.z * w.z)
         + v.y * (a0.y * w.x + a0.w * w.y + a1.x * w.z)
         + v.z * (a0.z * w.x + a1.x * w.y + a1.y * w.z);
}

float field_kernel(float d2, float cutoff) {
    if (!(d2 <= cutoff)) return 0.0;
    return SPLAT_KERNEL == SPLAT_KERNEL_POWER ? max(0.0, 1.0 - d2 / 9.0) : exp(-0.5 * d2);
}

// Abramowitz and Stegun 7.1.26 (absolute error below 1.5e-7), as cpu::field::erf.
float erf_as(float x) {
    float t = 1.0 / (1.0 + 0.3275911 * abs(x));
    float y = 1.0 - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t
        + 0.254829592) * t * exp(-x * x);
    return x < 0.0 ? -y : y;
}

float nonzero(float v) {
    return abs(v) < 1e-20 ? (v < 0.0 ? -1e-20 : 1e-20) : v;
}

void main() {
    uint li = gl_LocalInvocationIndex;
    uvec2 tile = gl_WorkGroupID.xy;
    uvec2 pix = tile * uvec2(TILE_W, TILE_H) + uvec2(li % TILE_W, li / TILE_W);
    uint width = params.size.x, height = params.size.y, n = params.size.z;
    bool inside = pix.x < width && pix.y < height;
    float cutoff = params.origin.w;
    mat3 rows = mat3(params.w2c[0].xyz, params.w2c[1].xyz, params.w2c[2].xyz); // columns = rows of R
    vec3 trans = vec3(params.w2c[0].w, params.w2c[1].w, params.w2c[2].w);
    vec4 f = params.focal;
    vec3 o = params.origin.xyz;
    // The pixel's unit ray: R^T (x, y, 1).
    vec3 dc = vec3((float(pix.x) + 0.5 - f.z) / f.x, (float(pix.y) + 0.5 - f.w) / f.y, 1.0);
    vec3 d = normalize(rows * dc);

    // The tile's frustum, as x / z and y / z ranges of camera space.
    vec2 lo = (vec2(tile * uvec2(TILE_W, TILE_H)) - f.zw) / f.xy;
    vec2 hi = (vec2(min(tile * uvec2(TILE_W, TILE_H) + uvec2(TILE_W, TILE_H), uvec2(width, height))) - f.zw) / f.xy;

    bool valid = inside;
    vec4 acc = vec4(0.0);
#if FIELD_MODE == 0
    vec3 pn = params.plane_normal.xyz;
    float den = dot(pn, d);
    float t_hit = dot(pn, params.plane_point.xyz - o) / den;
    valid = valid && den != 0.0 && t_hit > 0.0 && !isinf(t_hit);
    vec3 x = o + t_hit * d;
#elif FIELD_MODE == 2
    uint samples = params.mode.x;
    vec3 inv = vec3(1.0) / vec3(nonzero(d.x), nonzero(d.y), nonzero(d.z));
    vec3 t1 = (params.bounds_min.xyz - o) * inv;
    vec3 t2 = (params.bounds_max.xyz - o) * inv;
    vec3 tmin = min(t1, t2), tmax = max(t1, t2);
    float t_in = max(0.0, max(tmin.x, max(tmin.y, tmin.z)));
    float t_out = min(tmax.x, min(tmax.y, tmax.z));
    valid = valid && t_in < t_out;
    float dt = (t_out - t_in) / float(samples);
    vec4 sums[MAX_FIELD_SAMPLES];
    for (uint j = 0u; j < samples; j++) sums[j] = vec4(0.0);
#endif

    uint end = push.first + push.count;
    for (uint base = push.first; base < end; base += CHUNK) {
        uint g = base + li;
        bool keep = false;
        FieldGaussian gd;
        if (li < CHUNK && g < end) {
            gd = gaussians[g];
            float r = gd.mean_radius.w;
            vec3 p = gd.mean_radius.xyz * rows + trans; // camera space
            // The support's sphere against the four half-spaces x >= lo.x z, x <= hi.x z,
            // y >= lo.y z, y <= hi.y z (whose intersection is the tile's frustum, z >= 0).
            keep = p.x - lo.x * p.z >= -r * sqrt(1.0 + lo.x * lo.x)
                && hi.x * p.z - p.x >= -r * sqrt(1.0 + hi.x * hi.x)
                && p.y - lo.y * p.z >= -r * sqrt(1.0 + lo.y * lo.y)
                && hi.y * p.z - p.y >= -r * sqrt(1.0 + hi.y * hi.y);
#if FIELD_MODE == 0
            keep = keep && abs(dot(params.plane_normal.xyz, gd.mean_radius.xyz - params.plane_point.xyz)) <= r;
#endif
        }
        uint slot = workgroup_exclusive_scan(keep ? 1u : 0u);
        // The last invocation's exclusive sum plus its own flag is the count.
        if (keep) {
            s_mean[slot] = gd.mean_radius;
            s_a0[slot] = gd.a0;
            s_a1[slot] = gd.a1;
            s_feat[slot] = features[g * params.size.w + push.group];
        }
        if (li == WG_SIZE - 1u) wg_count = slot + (keep ? 1u : 0u);
        barrier();
        uint count = wg_count;
        for (uint j = 0u; j < count && valid; j++) {
            vec3 mu = s_mean[j].xyz;
            vec4 a0 = s_a0[j], a1 = s_a1[j];
#if FIELD_MODE == 0
            vec3 e = x - mu;
            acc += field_kernel(form(a0, a1, e, e), cutoff) * s_feat[j];
#else
            vec3 u = o - mu;
            float a = max(form(a0, a1, d, d), 1e-30);
            float t0 = -form(a0, a1, d, u) / a;
            vec3 w = u + t0 * d;
            float m = form(a0, a1, w, w);
            if (m >= cutoff) continue;
            float half_len = sqrt((cutoff - m) / a);
#if FIELD_MODE == 1
            float s_lo = max(t0 - half_len, 0.0) - t0;
            float s_hi = half_len;
            if (s_hi <= s_lo) continue;
            float v;
            if (SPLAT_KERNEL == SPLAT_KERNEL_POWER) {
                v = (1.0 - m / 9.0) * (s_hi - s_lo) - a * (s_hi * s_hi * s_hi - s_lo * s_lo * s_lo) / 27.0;
            } else {
                float c = sqrt(0.5 * a);
                v = exp(-0.5 * m) * sqrt(3.14159265358979 / (2.0 * a)) * (erf_as(c * s_hi) - erf_as(c * s_lo));
            }
            acc += v * s_feat[j];
#else
            // The samples that may lie in [t0 - half, t0 + half] (cpu::field::sample_span).
            float first = floor((t0 - half_len - t_in) / dt - 0.5) - 1.0;
            float last = ceil((t0 + half_len - t_in) / dt - 0.5) + 2.0;
            uint j0 = uint(clamp(first, 0.0, float(samples)));
            uint j1 = uint(clamp(last, 0.0, float(samples)));
            for (uint s = j0; s < j1; s++) {
                float t = t_in + (float(s) + 0.5) * dt;
                sums[s] += field_kernel(m + a * (t - t0) * (t - t0), cutoff) * s_feat[j];
            }
#endif
#endif
        }
        barrier();
    }
#if FIELD_MODE == 2
    if (valid) {
        acc = sums[0];
        for (uint s = 1u; s < samples; s++) acc = max(acc, sums[s]);
    }
#endif
    if (!inside) return;
    float nan_value = uintBitsToFloat(0x7fc00000u);
    uint at = push.group * width * height + pix.y * width + pix.x;
    vec4 value = valid ? acc : vec4(nan_value);
    out_field[at] = push.accumulate != 0u ? out_field[at] + value : value;
}
