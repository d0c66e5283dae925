#version 460
// Blend backward: one workgroup per bin (two layouts, see STRIP). Walks the bin's sorted
// pairs back to front from the last pair any of its pixels composited (the forward's saved
// last contributor; no re-sort, no re-render), undoing each pixel's transmittance from the
// saved final T, and writes per pair the bin's sum of the pixels' gradients with respect
// to the pair's Gaussian: 2D mean (2), conic (3), opacity, colour (3), depth, and the sum of
// |dL/d mean2d| per axis (gsplat's absgrad). Mirrors the pixel loop of cpu::backward.
//
// Determinism: a pixel's contribution is summed over the workgroup in a fixed order (per
// layout, below), and each pair's sum is written to the pair's own slot: no float atomics. grad_accumulate.comp then adds the pairs of each
// Gaussian in fixed point, where the order of additions cannot change the result. The
// largest |sum| of each field is kept (an order-independent max) to choose that fixed point.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_EXT_control_flow_attributes : require
#include "splat_common.glsl"
#include "subgroup.glsl"

#ifndef BIN
#define BIN 16u
#endif
#ifndef SPLAT_KERNEL
#define SPLAT_KERNEL 0u
#endif
// Two variants of the same arithmetic, chosen per device like the forward blend's:
//  - STRIP == 1 (GPUs): one invocation per pixel; pairs are staged in shared memory in
//    batches, and each pair's sum is a balanced tree over the bin's pixels, the same at
//    every subgroup size (subgroup_sum, CANONICAL_SUM; without shuffles the driver's
//    subgroup sums, then the subgroups' in index order).
//  - STRIP == BIN (CPU devices, 8-pixel bins): one invocation per row of the bin reads
//    each pair once through texel views for its BIN pixels. A pair's sum adds the rows in
//    row order: where the workgroup is one subgroup (ROWS_SUBGROUP), one subgroup sum
//    (llvmpipe adds the lanes, which are the rows, one after another; no barrier); where
//    subgroups are narrower than the bin (lavapipe at 4 lanes), the rows' sums go through
//    shared memory and are added in the same order, so the gradients are the same bits
//    at every llvmpipe width.
#ifndef STRIP
#define STRIP 1
#endif
// Gradient fields per pair: GRAD_FIELDS (12, a host constant) as three vec4:
// (mean2d.x, mean2d.y, conic A, conic B), (conic C, opacity, colour r, colour g),
// (colour b, depth, |mean2d.x|, |mean2d.y|); then one vec4 per group of four direct
// feature channels (FEATURE_GROUPS > 0: the Gaussians' values blended instead of their
// SH colour, with no background; the colour fields stay 0).
#ifndef FEATURE_GROUPS
#define FEATURE_GROUPS 0
#endif
#define VECS (3u + uint(FEATURE_GROUPS))
// Array size for the feature arrays (GLSL has no empty arrays).
#if FEATURE_GROUPS > 0
#define FG FEATURE_GROUPS
#else
#define FG 1
#endif

#if STRIP == 1
layout(local_size_x = BIN, local_size_y = BIN) in;
#else
// One row of the bin per invocation, a 1D workgroup of BIN (8) invocations: with the
// device's minimum subgroup size >= 8 (ROWS_SUBGROUP below) it is exactly one subgroup.
// (A (1, 8) workgroup is not: llvmpipe forms subgroups along x, one invocation each.)
layout(local_size_x = BIN, local_size_y = 1) in;
#endif

layout(std430, binding = BLEND_BWD_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
#if STRIP == 1
layout(std430, binding = BLEND_BWD_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = BLEND_BWD_VALUES) readonly buffer ValueBuf { uint values[]; };
#else
layout(binding = BLEND_BWD_SPLATS) uniform samplerBuffer splat_texels;
layout(binding = BLEND_BWD_VALUES) uniform usamplerBuffer value_texels;
#endif
layout(std430, binding = BLEND_BWD_RANGES) readonly buffer RangeBuf { uvec2 ranges[]; };
// Per pixel: one past the last composited pair, and the final transmittance's bits.
layout(std430, binding = BLEND_BWD_LAST) readonly buffer LastBuf { uvec2 last_state[]; };
// Per pixel: dL/d colour (rgb, with the background) and dL/d alpha, the latter including
// what the alpha-normalised depth passes on to it (the backward pass's depth rule).
layout(std430, binding = BLEND_BWD_GRAD_COLOR) readonly buffer GradColorBuf { vec4 grad_color[]; };
// Per pixel: dL/d (sum of depth * weight), i.e. dL/d depth / alpha.
layout(std430, binding = BLEND_BWD_GRAD_DEPTH) readonly buffer GradDepthBuf { float grad_depth[]; };
layout(std430, binding = BLEND_BWD_PAIR_GRADS) writeonly buffer PairGradBuf { vec4 pair_grads[]; };
#if FEATURE_GROUPS > 0
// The Gaussians' feature channels (FEATURE_GROUPS vec4 each) and dL/d blended feature
// channel per pixel (FEATURE_GROUPS vec4 each).
layout(std430, binding = BLEND_BWD_FEATURES) readonly buffer FeatureBuf { vec4 features[]; };
layout(std430, binding = BLEND_BWD_GRAD_FEATURES) readonly buffer GradFeatureBuf { vec4 grad_features[]; };
#endif
// Largest |pair sum| per field, as float bits (non-negative floats order like their bits).
layout(std430, binding = BLEND_BWD_MAXIMA) buffer MaximaBuf { uint maxima[]; };
// The band this dispatch covers: the host splits a frame whose per-pair or per-pixel
// buffers exceed one storage binding (render::frame::bands). counts.xy: the pairs
// [lo, hi) whose sums this dispatch writes, to pair_grads[k - lo] (each band its own
// buffer); counts.z: the first bin row dispatched (workgroup row 0); counts.w: the first
// pixel row of the per-pixel buffers as bound. A bin is walked exactly as in one piece
// (from its last composited pair down to lo), so every pair's sum is bit-identical to the
// unsplit pass's. A frame in one piece is (0, pairs, 0, 0).
layout(push_constant) uniform BandBlock { CountsPush band; };

// One pixel's state for the walk back to front.
struct Pixel {
    uint last;       // one past the last pair composited into it
    float T;         // transmittance behind the Gaussian being undone
    float t_final;
    vec4 g_ca;       // dL/d colour, dL/d alpha
    float g_dacc;    // dL/d sum of depth * weight
    vec3 behind;     // colour composited behind (with the background)
    float behind_depth;
    vec4 g_f[FG];    // dL/d feature channel
    vec4 behind_f[FG];  // feature channels composited behind (no background)
};

Pixel load_pixel(uvec2 pix) {
    Pixel p;
    p.last = 0u;
    p.T = 1.0;
    p.g_ca = vec4(0.0);
    p.g_dacc = 0.0;
    for (uint gi = 0u; gi < FG; gi++) {
        p.g_f[gi] = vec4(0.0);
        p.behind_f[gi] = vec4(0.0);
    }
    if (pix.x < params.image.x && pix.y < params.image.y) {
        uint i = (pix.y - band.counts.w) * params.image.x + pix.x;
        uvec2 state = last_state[i];
        p.last = state.x;
        p.T = uintBitsToFloat(state.y);
        p.g_ca = grad_color[i];
        p.g_dacc = grad_depth[i];
#if FEATURE_GROUPS > 0
        for (uint gi = 0u; gi < FEATURE_GROUPS; gi++) p.g_f[gi] = grad_features[i * FEATURE_GROUPS + gi];
#endif
    }
    p.t_final = p.T;
    p.behind = p.T * params.background.rgb;
    p.behind_depth = 0.0;
    return p;
}

// Undoes one Gaussian (mean2d.xy, opacity, depth; conic; colour) at pixel `pixf` and adds
// its gradients to (a0, a1, a2): the pixel loop of cpu::backward, the forward's alpha and
// skip rule (blend.comp, composite).
void pixel_grad(vec4 mo, vec3 conic, vec3 col, vec4 fv[FG], vec2 pixf, inout Pixel px,
                inout vec4 a0, inout vec4 a1, inout vec4 a2, inout vec4 af[FG]) {
    vec2 d = mo.xy - pixf;
    float power = splat_power(conic, d);
    float unclamped = kernel_falloff(SPLAT_KERNEL, mo.z, min(power, 0.0));
    float alpha = min(params.rules.y, unclamped);
    if (power > 0.0 || alpha < ALPHA_MIN) return;
    float one_minus = 1.0 - alpha;
    float t_i = px.T / one_minus;  // transmittance in front of this Gaussian
    float w = alpha * t_i;
    float g_a = dot(px.g_ca.rgb, col * t_i - px.behind / one_minus)
        + px.g_dacc * (mo.w * t_i - px.behind_depth / one_minus)
        + px.g_ca.a * px.t_final / one_minus;
#if FEATURE_GROUPS > 0
    [[unroll]] for (uint gi = 0u; gi < FEATURE_GROUPS; gi++) {
        af[gi] += px.g_f[gi] * w;
        g_a += dot(px.g_f[gi], fv[gi] * t_i - px.behind_f[gi] / one_minus);
        px.behind_f[gi] += fv[gi] * w;
    }
#endif
    px.behind += col * w;
    px.behind_depth += mo.w * w;
    px.T = t_i;
    vec3 g_col = px.g_ca.rgb * w;
    a1.zw += g_col.rg;
    a2.xy += vec2(g_col.b, px.g_dacc * w);
    if (unclamped < params.rules.y) {
        // d alpha / d opacity and d alpha / d power (a constant branch).
        bool power_kernel = SPLAT_KERNEL == SPLAT_KERNEL_POWER;
        float da_do = power_kernel ? 1.0 + 2.0 * power / 9.0 : (REPRODUCIBLE ? portable_exp(power) : exp(power));
        float da_dp = power_kernel ? mo.z * (2.0 / 9.0) : unclamped;
        float gp = g_a * da_dp;
        vec2 gm = gp * -vec2(conic.x * d.x + conic.y * d.y, conic.z * d.y + conic.y * d.x);
        a0 += vec4(gm, gp * (-0.5 * d.x * d.x), gp * (-d.x * d.y));
        a1.xy += vec2(gp * (-0.5 * d.y * d.y), g_a * da_do);
        a2.zw += abs(gm);
    }
}

// Stores pair k's sums in its band's slot (k in [lo, hi)).
void store_pair(uint k, vec4 s0, vec4 s1, vec4 s2, vec4 sf[FG]) {
    k -= band.counts.x;
    pair_grads[VECS * k] = s0;
    pair_grads[VECS * k + 1u] = s1;
    pair_grads[VECS * k + 2u] = s2;
    for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) pair_grads[VECS * k + 3u + gi] = sf[gi];
}

// The Gaussian's feature channels (zeros without features).
void load_features(uint gaussian, out vec4 fv[FG]) {
    for (uint gi = 0u; gi < FG; gi++) fv[gi] = vec4(0.0);
#if FEATURE_GROUPS > 0
    for (uint gi = 0u; gi < FEATURE_GROUPS; gi++) fv[gi] = features[gaussian * FEATURE_GROUPS + gi];
#endif
}

void zero_features(out vec4 a[FG]) {
    for (uint gi = 0u; gi < FG; gi++) a[gi] = vec4(0.0);
}

#if STRIP == 1
#ifndef CANONICAL_SUM
#define CANONICAL_SUM 0
#endif
#if CANONICAL_SUM
#extension GL_KHR_shader_subgroup_shuffle : require
#endif
// A subgroup's sum of v. CANONICAL_SUM (devices with subgroup shuffles): a butterfly, so
// each subgroup of 2^m lanes adds its pixels as a balanced binary tree over their index,
// and the subgroups' sums continue that tree (main): a pair's sum over the bin's pixels is
// then the same tree, so the same bits, at every subgroup size (lanes numbered along the
// workgroup's invocation index, as drivers lay them out). Otherwise the driver's
// subgroupAdd, whose order is its own.
vec4 subgroup_sum(vec4 v) {
#if CANONICAL_SUM
    for (uint d = 1u; d < SUBGROUP_SIZE; d *= 2u) v = v + subgroupShuffleXor(v, d);
    return v;
#else
    return subgroupAdd(v);
#endif
}

// At least the number of subgroups of a BIN x BIN workgroup (the host passes it from the
// device's minimum subgroup size), and the pairs staged at a time: the host picks the
// largest of 16, 8, 4, 2 whose partial sums fit the device's shared memory.
layout(constant_id = GRAD_SPEC_MAX_SUBGROUPS) const uint MAX_SUBGROUPS = 32u;
layout(constant_id = GRAD_SPEC_BATCH) const uint BATCH = 16u;
shared vec4 s_mean_opacity[BATCH];  // mean2d.xy, opacity, depth
shared vec4 s_conic[BATCH];
shared vec4 s_color[BATCH];
shared uint s_gaussian[BATCH];
shared vec4 s_part[BATCH * MAX_SUBGROUPS * VECS];
shared uint s_last;
shared uint s_max[4u * VECS];

void main() {
    uvec2 bin = gl_WorkGroupID.xy + uvec2(0u, band.counts.z);
    uvec2 pix = bin * BIN + gl_LocalInvocationID.xy;
    vec2 pixf = vec2(pix);
    uvec2 range = ranges[bin.y * params.bins.y + bin.x];
    uint lo = band.counts.x, hi = band.counts.y;
    // A bin with no pair in the band (the whole workgroup returns: no barrier is missed).
    if (range.y <= lo || range.x >= hi) return;
    Pixel px = load_pixel(pix);
    uint li = gl_LocalInvocationIndex;
    if (li == 0u) s_last = 0u;
    if (li < 4u * VECS) s_max[li] = 0u;
    barrier();
    if (px.last != 0u) atomicMax(s_last, px.last);
    barrier();
    // One past the last pair any pixel of the bin composited; the pairs after it receive 0.
    uint end = max(s_last, range.x);
    vec4 zf[FG];
    zero_features(zf);
    for (uint k = max(end, lo) + li; k < min(range.y, hi); k += BIN * BIN) {
        store_pair(k, vec4(0.0), vec4(0.0), vec4(0.0), zf);
    }
    // Back to front from the last composited pair (the pairs past hi too, to undo the
    // pixels' state), down to the band's first.
    uint stop = max(range.x, lo);
    uint batch_end = end;
    while (batch_end > stop) {
        uint count = min(BATCH, batch_end - stop);
        if (li < count) {
            uint gaussian = values[batch_end - 1u - li];
            Splat s = splats[gaussian];
            s_gaussian[li] = gaussian;
            // In a panorama that wraps around, the copy the blend drew in this bin's tile.
            vec2 mean = wrapped_mean(s.mean_opacity_bound.xy, bin.x * BIN / TILE_SIZE * TILE_SIZE,
                                     params.modes.z, params.image.x);
            s_mean_opacity[li] = vec4(mean, s.mean_opacity_bound.z, s.conic_depth.w);
            s_conic[li] = s.conic_depth;
            s_color[li] = s.color_radius;
        }
        barrier();
        for (uint j = 0u; j < count; j++) {
            uint k = batch_end - 1u - j;
            vec4 a0 = vec4(0.0), a1 = vec4(0.0), a2 = vec4(0.0);
            vec4 af[FG];
            zero_features(af);
            bool used = k < px.last;
            if (used) {
                vec4 fv[FG];
                load_features(s_gaussian[j], fv);
                pixel_grad(s_mean_opacity[j], s_conic[j].xyz, s_color[j].rgb, fv, pixf, px, a0, a1, a2, af);
            }
            // The subgroup's sum (skipped where none of its pixels composited the pair).
            uint slot = (j * MAX_SUBGROUPS + gl_SubgroupID) * VECS;
            if (subgroupAny(used)) {
                vec4 s0 = subgroup_sum(a0), s1 = subgroup_sum(a1), s2 = subgroup_sum(a2);
                vec4 sf[FG];
                zero_features(sf);
                for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) sf[gi] = subgroup_sum(af[gi]);
                if (subgroupElect()) {
                    s_part[slot] = s0;
                    s_part[slot + 1u] = s1;
                    s_part[slot + 2u] = s2;
                    for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) s_part[slot + 3u + gi] = sf[gi];
                }
            } else if (subgroupElect()) {
                for (uint v = 0u; v < VECS; v++) s_part[slot + v] = vec4(0.0);
            }
        }
        barrier();
        // The workgroup's sum per pair and vec4 from its subgroups' sums.
        for (uint t = li; t < count * VECS; t += BIN * BIN) {
            uint j = t / VECS, v = t % VECS;
#if CANONICAL_SUM
            // The rest of the balanced tree: pairs of neighbouring subgroups' sums, then
            // pairs of those, ..., in place (this invocation owns these slots).
            for (uint w = 1u; w < gl_NumSubgroups; w *= 2u) {
                for (uint sg = 0u; sg + w < gl_NumSubgroups; sg += 2u * w) {
                    uint at = (j * MAX_SUBGROUPS + sg) * VECS + v;
                    s_part[at] = s_part[at] + s_part[at + w * VECS];
                }
            }
            vec4 s = s_part[j * MAX_SUBGROUPS * VECS + v];
#else
            vec4 s = vec4(0.0);
            for (uint sg = 0u; sg < gl_NumSubgroups; sg++) s += s_part[(j * MAX_SUBGROUPS + sg) * VECS + v];
#endif
            uint k = batch_end - 1u - j;
            if (k >= hi) continue;
            pair_grads[VECS * (k - lo) + v] = s;
            for (uint c = 0u; c < 4u; c++) {
                if (s[c] != 0.0) atomicMax(s_max[4u * v + c], floatBitsToUint(abs(s[c])));
            }
        }
        batch_end -= count;
        barrier();
    }
    barrier();
    if (li < 4u * VECS && s_max[li] != 0u) atomicMax(maxima[li], s_max[li]);
}
#else
// Whether the workgroup is one subgroup (the host's choice from the device's smallest
// subgroup size); if not, the rows' sums go through shared memory.
layout(constant_id = GRAD_SPEC_ROWS_SUBGROUP) const bool ROWS_SUBGROUP = true;
// The rows' values of one pair (VECS vec4 each), and their last composited pairs.
shared vec4 s_rows[BIN * VECS];
shared uint s_row_last[BIN];

// The bin's largest `v` (each row's last composited pair).
uint bin_max(uint v) {
    if (ROWS_SUBGROUP) return subgroupMax(v);
    s_row_last[gl_LocalInvocationIndex] = v;
    barrier();
    uint m = 0u;
    for (uint r = 0u; r < BIN; r++) m = max(m, s_row_last[r]);
    return m;
}

// The rows' vec4s of one pair added in row order from 0 (what llvmpipe's subgroupAdd does
// with the lanes, here the rows), by invocation 0. Every invocation calls it (barriers).
void rows_sum(inout vec4 s0, inout vec4 s1, inout vec4 s2, inout vec4 sf[FG]) {
    uint r = gl_LocalInvocationIndex;
    s_rows[r * VECS] = s0;
    s_rows[r * VECS + 1u] = s1;
    s_rows[r * VECS + 2u] = s2;
    for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) s_rows[r * VECS + 3u + gi] = sf[gi];
    barrier();
    if (r == 0u) {
        s0 = vec4(0.0);
        s1 = vec4(0.0);
        s2 = vec4(0.0);
        zero_features(sf);
        for (uint q = 0u; q < BIN; q++) {
            s0 += s_rows[q * VECS];
            s1 += s_rows[q * VECS + 1u];
            s2 += s_rows[q * VECS + 2u];
            for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) sf[gi] += s_rows[q * VECS + 3u + gi];
        }
    }
    barrier();
}

void main() {
    uvec2 bin = spread_workgroup() + uvec2(0u, band.counts.z);
    uvec2 pix0 = bin * BIN + uvec2(0u, gl_LocalInvocationID.x);
    uvec2 range = ranges[bin.y * params.bins.y + bin.x];
    uint lo = band.counts.x, hi = band.counts.y;
    // A bin with no pair in the band.
    if (range.y <= lo || range.x >= hi) return;
    Pixel px[STRIP];
    uint my_last = 0u;
    [[unroll]] for (uint p = 0u; p < STRIP; p++) {
        px[p] = load_pixel(pix0 + uvec2(p, 0u));
        my_last = max(my_last, px[p].last);
    }
    uint end = max(bin_max(my_last), range.x);
    // The one invocation that stores the pairs' sums and the maxima: the elected lane (every
    // lane holds the subgroup sum), or invocation 0, which sums the rows in shared memory.
    bool leader = ROWS_SUBGROUP ? subgroupElect() : gl_LocalInvocationIndex == 0u;
    vec4 zf[FG];
    zero_features(zf);
    // Strided by the workgroup's invocations (BIN), not the subgroup's lanes: a subgroup
    // wider than the workgroup (16 lanes at LP_NATIVE_VECTOR_WIDTH=512) has only BIN of
    // them active, and a stride of its size skipped pairs, leaving an earlier frame's sums.
    for (uint k = max(end, lo) + gl_LocalInvocationIndex; k < min(range.y, hi); k += BIN) {
        store_pair(k, vec4(0.0), vec4(0.0), vec4(0.0), zf);
    }
    vec4 m0 = vec4(0.0), m1 = vec4(0.0), m2 = vec4(0.0);
    vec4 mf[FG];
    zero_features(mf);
    // Back to front from the last composited pair (the pairs past hi too, to undo the
    // pixels' state), down to the band's first.
    for (uint k = end; k > max(range.x, lo);) {
        k--;
        uint gaussian = texelFetch(value_texels, int(k)).x;
        int g = int(gaussian) * 3;
        vec4 fv[FG];
        load_features(gaussian, fv);
        vec4 mob = texelFetch(splat_texels, g);
        vec4 cd = texelFetch(splat_texels, g + 1);
        vec3 col = texelFetch(splat_texels, g + 2).rgb;
        // In a panorama that wraps around, the copy the blend drew in this bin's tile.
        vec2 mean = wrapped_mean(mob.xy, pix0.x / TILE_SIZE * TILE_SIZE, params.modes.z, params.image.x);
        vec4 mo = vec4(mean, mob.z, cd.w);
        vec4 a0 = vec4(0.0), a1 = vec4(0.0), a2 = vec4(0.0);
        vec4 af[FG];
        zero_features(af);
        bool used = false;
        [[unroll]] for (uint p = 0u; p < STRIP; p++) {
            if (k < px[p].last) {
                used = true;
                Pixel q = px[p];
                pixel_grad(mo, cd.xyz, col, fv, vec2(pix0) + vec2(float(p), 0.0), q, a0, a1, a2, af);
                px[p] = q;
            }
        }
        if (k >= hi) continue;  // walked for the pixels' state only (uniform)
        vec4 s0 = vec4(0.0), s1 = vec4(0.0), s2 = vec4(0.0);
        vec4 sf[FG];
        zero_features(sf);
        if (ROWS_SUBGROUP) {
            if (subgroupAny(used)) {
                s0 = subgroupAdd(a0);
                s1 = subgroupAdd(a1);
                s2 = subgroupAdd(a2);
                for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) sf[gi] = subgroupAdd(af[gi]);
            }
        } else {
            // Summed whether or not a row composited the pair (a sum of zeros is the 0
            // the skip gives): the barriers need every invocation.
            rows_sum(a0, a1, a2, af);
            s0 = a0;
            s1 = a1;
            s2 = a2;
            for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) sf[gi] = af[gi];
        }
        if (leader) {
            store_pair(k, s0, s1, s2, sf);
            m0 = max(m0, abs(s0));
            m1 = max(m1, abs(s1));
            m2 = max(m2, abs(s2));
            for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) mf[gi] = max(mf[gi], abs(sf[gi]));
        }
    }
    if (ROWS_SUBGROUP) {
        m0 = subgroupMax(m0);
        m1 = subgroupMax(m1);
        m2 = subgroupMax(m2);
        for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) mf[gi] = subgroupMax(mf[gi]);
    }
    if (leader) {
        for (uint c = 0u; c < 4u; c++) {
            if (m0[c] != 0.0) atomicMax(maxima[c], floatBitsToUint(m0[c]));
            if (m1[c] != 0.0) atomicMax(maxima[4u + c], floatBitsToUint(m1[c]));
            if (m2[c] != 0.0) atomicMax(maxima[8u + c], floatBitsToUint(m2[c]));
            for (uint gi = 0u; gi < uint(FEATURE_GROUPS); gi++) {
                if (mf[gi][c] != 0.0) atomicMax(maxima[12u + 4u * gi + c], floatBitsToUint(mf[gi][c]));
            }
        }
    }
}
#endif
