#version 460
// Preprocess: per Gaussian, cull at the near plane, project (a pinhole by the EWA rule,
// every other lens by the unscented transform of lens.glsl), 2D covariance with the 0.3
// dilation, conic, radius, tile rectangle, SH colour, depth and tiles touched. One thread
// per Gaussian; mirrors cpu::preprocess_one line by line. Also writes each Gaussian's depth
// sort key (depth bits), index and tiles touched, for the depth order stage.
#extension GL_GOOGLE_include_directive : require
#define WORKGROUP_COUNT64
#include "splat_common.glsl"

layout(local_size_x = LINEAR_WG) in;

layout(std430, binding = PREPROCESS_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
#ifndef COMPACT_GAUSSIANS
#define COMPACT_GAUSSIANS 0
#endif
#ifndef PREPROCESS_TEXEL_IO
#define PREPROCESS_TEXEL_IO 0
#endif
// Every lens (FrameParams::modes.y), or the pinhole alone: a variant of its own, so that
// a pinhole frame runs exactly the code it ran before lenses (the same floats, bit for
// bit, on every driver).
#ifndef LENSES
#define LENSES 0
#endif
// A compact upload (--compact, GaussianCompact): unpacking is exact.
Gaussian unpack_compact(GaussianCompact c) {
    vec2 sxy = unpackHalf2x16(c.shape.x), szw = unpackHalf2x16(c.shape.y);
    vec2 rxy = unpackHalf2x16(c.shape.z), rz = unpackHalf2x16(c.shape.w);
    Gaussian g;
    g.pos_opacity = c.pos_opacity;
    g.scale = vec4(sxy, szw.x, 0.0);
    g.rotation = vec4(szw.y, rxy, rz.x);
    return g;
}
#if PREPROCESS_TEXEL_IO
// CPU devices: the records through an RGBA32UI texel view and every output written with
// imageStore, all by the global index (the views cover whole buffers, so windows only
// bound the dispatch): llvmpipe turns these into straight per-lane code, storage-buffer
// accesses into a guarded loop per component (the tuning bench measures both).
layout(binding = PREPROCESS_GAUSSIANS) uniform usamplerBuffer gaussian_texels;
#if COMPACT_GAUSSIANS
Gaussian load_gaussian(uint w, uint i) {
    GaussianCompact c;
    c.pos_opacity = uintBitsToFloat(texelFetch(gaussian_texels, int(2u * i)));
    c.shape = texelFetch(gaussian_texels, int(2u * i + 1u));
    return unpack_compact(c);
}
#else
Gaussian load_gaussian(uint w, uint i) {
    Gaussian g;
    g.pos_opacity = uintBitsToFloat(texelFetch(gaussian_texels, int(3u * i)));
    g.scale = uintBitsToFloat(texelFetch(gaussian_texels, int(3u * i + 1u)));
    g.rotation = uintBitsToFloat(texelFetch(gaussian_texels, int(3u * i + 2u)));
    return g;
}
#endif
#elif COMPACT_GAUSSIANS
layout(std430, binding = PREPROCESS_GAUSSIANS) readonly buffer GaussianBuf { GaussianCompact gaussians[]; };
Gaussian load_gaussian(uint w, uint i) { return unpack_compact(gaussians[w]); }
#else
layout(std430, binding = PREPROCESS_GAUSSIANS) readonly buffer GaussianBuf { Gaussian gaussians[]; };
Gaussian load_gaussian(uint w, uint i) { return gaussians[w]; }
#endif
// SH coefficients, coefficient-major with the colour channel innermost, each Gaussian's
// floats padded to whole RGBA32F texels (the host's sh_texel_stride). Read as a
// texel buffer, which addresses far more than one storage binding on some devices.
layout(binding = PREPROCESS_SH) uniform samplerBuffer sh_texels;
layout(std430, binding = PREPROCESS_COUNTERS) buffer CounterBuf { Counters counters; };
// Outputs, per Gaussian: the splat, its tile rectangle, its depth key (depth bits, or ~0
// when culled) and index for the depth sort, which bins of a small rectangle receive it
// (see BIN_MASK_BINS in splat_common) and its tiles touched (gathered into depth order by
// order.comp). Bin masks and tiles touched are indexed globally (4 bytes each: one binding
// holds any scene the SH texels allow), the rest by the index in the window.
#if PREPROCESS_TEXEL_IO
layout(binding = PREPROCESS_SPLATS, rgba32f) uniform writeonly imageBuffer splats_img;
layout(binding = PREPROCESS_RECTS, rg32ui) uniform writeonly uimageBuffer rects_img;
layout(binding = PREPROCESS_DEPTH_KEYS, r32ui) uniform writeonly uimageBuffer depth_keys_img;
layout(binding = PREPROCESS_DEPTH_VALUES, r32ui) uniform writeonly uimageBuffer depth_values_img;
layout(binding = PREPROCESS_BIN_MASKS, r32ui) uniform writeonly uimageBuffer bin_masks_img;
layout(binding = PREPROCESS_TOUCHED, r32ui) uniform writeonly uimageBuffer touched_img;
void store_outputs(uint w, uint i, Splat s, uvec2 rect, uint depth_key, uint mask, uint touched) {
    int t = int(i);
    imageStore(splats_img, 3 * t, s.mean_opacity_bound);
    imageStore(splats_img, 3 * t + 1, s.conic_depth);
    imageStore(splats_img, 3 * t + 2, s.color_radius);
    imageStore(rects_img, t, uvec4(rect, 0u, 0u));
    imageStore(depth_keys_img, t, uvec4(depth_key));
    imageStore(depth_values_img, t, uvec4(i));
    imageStore(bin_masks_img, t, uvec4(mask));
    imageStore(touched_img, t, uvec4(touched));
}
#else
layout(std430, binding = PREPROCESS_SPLATS) writeonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = PREPROCESS_RECTS) writeonly buffer RectBuf { uvec2 rects[]; };
layout(std430, binding = PREPROCESS_DEPTH_KEYS) writeonly buffer DepthKeyBuf { uint depth_keys[]; };
layout(std430, binding = PREPROCESS_DEPTH_VALUES) writeonly buffer DepthValueBuf { uint depth_values[]; };
layout(std430, binding = PREPROCESS_BIN_MASKS) writeonly buffer BinMaskBuf { uint bin_masks[]; };
layout(std430, binding = PREPROCESS_TOUCHED) writeonly buffer TouchedBuf { uint touched_by_index[]; };
void store_outputs(uint w, uint i, Splat s, uvec2 rect, uint depth_key, uint mask, uint touched) {
    splats[w] = s;
    rects[w] = rect;
    depth_keys[w] = depth_key;
    depth_values[w] = i;
    bin_masks[i] = mask;
    touched_by_index[i] = touched;
}
#endif
// The window of Gaussians this dispatch handles: bindings 1, 3, 4, 5 and 7 start at
// Gaussian `first` (one storage binding may not cover a large scene, so the host
// dispatches once per window); the SH texels and the indices written are global (and so
// is every binding of the texel-I/O variant).
layout(push_constant) uniform WindowBlock { WindowPush window; };

#include "sh_common.glsl"
#include "lens.glsl"

// C's truncating float-to-int conversion, clamped to [0, hi].
uint clamp_tile(float v, uint hi) {
    return uint(clamp(int(v), 0, int(hi)));
}

// The tile columns [x, y) of a splat's copy centred at column `x`, `radius_x` pixels to
// either side, on an image `width` pixels and `tiles` tiles across, as the rectangle of
// model::Rules::extent (empty where it culls the copy: gsplat's box off the image).
uvec2 copy_columns(bool gsplat, float x, float radius_x, uint width, uint tiles) {
    if (gsplat) {
        float p = x + 0.5;  // gsplat's pixel centres are at +0.5
        if (p + radius_x <= 0.0 || p - radius_x >= float(width)) return uvec2(0u);
        return uvec2(clamp_tile(floor((p - radius_x) / 16.0), tiles),
                     clamp_tile(ceil((p + radius_x) / 16.0), tiles));
    }
    return uvec2(clamp_tile((x - radius_x) / 16.0, tiles),
                 clamp_tile((x + radius_x + 15.0) / 16.0, tiles));
}

shared uint s_visible;

void main() {
    uint w = linear_group_id() * LINEAR_WG + gl_LocalInvocationIndex;  // index in the window
    uint i = window.first + w;
    uint touched = 0u;
    uint mask = 0u;
    if (gl_LocalInvocationIndex == 0u) s_visible = 0u;
    if (w < window.count) {
        Gaussian g = load_gaussian(w, i);
        vec3 mean = g.pos_opacity.xyz;
        vec3 view = vec3(dot(params.w2c_row0.xyz, mean) + params.w2c_row0.w,
                         dot(params.w2c_row1.xyz, mean) + params.w2c_row1.w,
                         dot(params.w2c_row2.xyz, mean) + params.w2c_row2.w);
        Splat s;
        s.mean_opacity_bound = vec4(0.0);
        s.conic_depth = vec4(0.0);
        s.color_radius = vec4(0.0);
        uvec2 rect = uvec2(0u);
        // Per-frame filters, as cpu::RenderOptions::keeps: `<=` and `>=` are false for NaN,
        // so a NaN scale or opacity is dropped whenever its filter is on.
        float max_scale = params.filters.y, min_opacity = params.filters.z;
        bool kept = (max_scale < 0.0 || max(max(g.scale.x, g.scale.y), g.scale.z) <= max_scale)
            && (min_opacity < 0.0 || g.pos_opacity.w >= min_opacity);
        bool gsplat = params.modes.x == RULES_GSPLAT;
        // The depth sorted by and culled at the near plane, as cpu::preprocess_one: the
        // distance from the camera for the lenses that see behind their image plane,
        // else z.
#if LENSES
        uint lens = params.modes.y;
#else
        // The pinhole variant: the lens is known, and the code is the EWA path alone.
        uint lens = LENS_PINHOLE;
#endif
        bool by_distance = lens == LENS_FISHEYE || lens == LENS_EQUIRECTANGULAR;
        float depth = by_distance ? sqrt(dot(view, view)) : view.z;
        if (kept && depth > params.rules.x) {
            // The reference's scaling_modifier: S = modifier * scale.
            float sm = params.filters.x;
            mat3 m = mat_mat(quat_to_mat3(g.rotation), mat3(sm * g.scale.x, 0.0, 0.0, 0.0, sm * g.scale.y, 0.0, 0.0, 0.0, sm * g.scale.z));
            float fx = params.focal.x, fy = params.focal.y;
            float a, b, c;
            vec2 mean2d;
            bool projected = true;
            // GLSL's mat3(a, b, c) takes columns, so the rows of W as columns give W^T.
            mat3 w_t = mat3(params.w2c_row0.xyz, params.w2c_row1.xyz, params.w2c_row2.xyz);
            if (lens == LENS_PINHOLE) {
                mat3 cov3d = mat_mat(m, transpose(m));
                vec4 lim = params.limits;
                float z = view.z;
                float tx = clamp(view.x / z, -lim.x, lim.y) * z;
                float ty = clamp(view.y / z, -lim.z, lim.w) * z;
                vec3 j0 = vec3(fx / z, 0.0, -(fx * tx) / (z * z));
                vec3 j1 = vec3(0.0, fy / z, -(fy * ty) / (z * z));
                // Rows of T = J W, with W the world-to-camera rotation: t_i = W^T j_i.
                vec3 t0 = mat_vec(w_t, j0);
                vec3 t1 = mat_vec(w_t, j1);
                vec3 s0 = mat_vec(cov3d, t0);
                vec3 s1 = mat_vec(cov3d, t1);
                a = dot(t0, s0);
                b = dot(t0, s1);
                c = dot(t1, s1);
            } else {
                // Through the lens: the unscented transform of the camera-space Gaussian.
                vec2 mean_px;
                vec3 cov;
                projected = lens_unscented(view, transpose(w_t) * m, mean_px, cov);
                a = cov.x;
                b = cov.y;
                c = cov.z;
                mean2d = mean_px - 0.5;
            }
            float det_before = a * c - b * b;
            a += COV2D_DILATION;
            c += COV2D_DILATION;
            float det = a * c - b * b;
            if (projected && (gsplat ? det > 0.0 : det != 0.0)) {
                // Optional antialiasing compensation (cam_pos.w = 1), as cpu::preprocess_one.
                float opacity = g.pos_opacity.w;
                if (params.cam_pos.w != 0.0) {
                    opacity *= sqrt(max(params.rules.w, det_before / det));
                }
                float det_inv = 1.0 / det;
                vec3 conic = vec3(c * det_inv, -b * det_inv, a * det_inv);
                if (lens == LENS_PINHOLE) {
                    float inv_z = 1.0 / view.z;
                    mean2d = vec2(fx * view.x * inv_z + params.focal.z - 0.5,
                                  fy * view.y * inv_z + params.focal.w - 0.5);
                }
                uint gx = params.image.z, gy = params.image.w;
                // Where the rectangle is found: the centre, on an image of `size` pixels
                // and `bins_x` bins across.
                vec2 at = mean2d;
                vec2 size = vec2(params.image.xy);
                uint bins_x = params.bins.y;
#if LENSES
                // An image that wraps around (wrapped_mean): the rectangle in the tiles of
                // three turns of whole tiles side by side, the image the middle one, as
                // model::Rules::wrapped_extent.
                bool wraps = params.modes.z != 0u;
                if (wraps) {
                    at.x += float(gx * TILE_SIZE);
                    size.x = float(3u * gx * TILE_SIZE);
                    gx *= 3u;
                    bins_x = gx * params.bins.w;  // three turns of whole tiles
                }
#endif
                float radius;
                float radius_x;  // along x: the rectangle's half width, for the copies
                uvec2 rmin, rmax;
                // Whether the rules count the splat as seen (its radius, the trainer's and
                // gsplat's visibility): the original's when its tile rectangle is not
                // empty, gsplat's unless below 1/255 or off the image; either way also
                // where no bin receives it, as in those rasterizers.
                bool shown = true;
                if (gsplat) {
                    // model::Rules::extent: a per-axis box of e sigmas, e opacity-aware.
                    float extend = min(GSPLAT_EXTEND, sqrt(2.0 * log(opacity / ALPHA_MIN)));
                    vec2 r = ceil(extend * sqrt(vec2(a, c)));
                    vec2 p = at + 0.5;  // gsplat's pixel centres are at +0.5
                    shown = opacity >= ALPHA_MIN && (r.x > 0.0 || r.y > 0.0)
                        && all(greaterThan(p + r, vec2(0.0))) && all(lessThan(p - r, size));
                    radius = max(r.x, r.y);
                    radius_x = r.x;
                    vec2 lo = floor((p - r) / 16.0), hi = ceil((p + r) / 16.0);
                    rmin = uvec2(clamp_tile(lo.x, gx), clamp_tile(lo.y, gy));
                    rmax = uvec2(clamp_tile(hi.x, gx), clamp_tile(hi.y, gy));
                    if (!shown) rmax = rmin;
                } else {
                    float mid = 0.5 * (a + c);
                    float disc = sqrt(max(mid * mid - det, 0.1));
                    radius = ceil(3.0 * sqrt(max(mid + disc, mid - disc)));
                    radius_x = radius;
                    rmin = uvec2(clamp_tile((at.x - radius) / 16.0, gx),
                                 clamp_tile((at.y - radius) / 16.0, gy));
                    rmax = uvec2(clamp_tile((at.x + radius + 15.0) / 16.0, gx),
                                 clamp_tile((at.y + radius + 15.0) / 16.0, gy));
                }
#if LENSES
                if (wraps) {
                    // A width that is not whole tiles: across the seam, the columns of the
                    // copies one image width to the right (seen in the turn to the left)
                    // and to the left (in the turn to the right).
                    uint tiles = params.image.z;
                    if (params.image.x != tiles * TILE_SIZE && rmax.x > rmin.x && rmax.y > rmin.y) {
                        float w = float(params.image.x);
                        uvec2 right = copy_columns(gsplat, mean2d.x + w, radius_x, params.image.x, tiles);
                        uvec2 left = copy_columns(gsplat, mean2d.x - w, radius_x, params.image.x, tiles);
                        if (right.y > right.x) {
                            rmin.x = min(rmin.x, right.x);
                            rmax.x = max(rmax.x, right.y);
                        }
                        if (left.y > left.x) {
                            rmin.x = min(rmin.x, left.x + 2u * tiles);
                            rmax.x = max(rmax.x, left.y + 2u * tiles);
                        }
                    }
                    // At most one turn wide.
                    rmax.x = min(rmax.x, rmin.x + tiles);
                }
#endif
                // Count the bins of the reference rectangle that receive anything.
                float bound = alpha_bound(opacity, uint(params.filters.w));
                uvec2 bmin = rmin * params.bins.w;
                uvec2 bmax = min(rmax * params.bins.w, uvec2(bins_x, params.bins.z));
                uint by = bmin.y;
                uint bx = bmax.x;
                uint bit = 1u;  // bit of bin (bx, by) in row-major order; 0 past the 32nd
                for (; by < bmax.y; by++) {
                    for (bx = bmin.x; bx < bmax.x; bx++) {
#if LENSES
                        bool receives = wraps
                            ? wrapped_bin_receives(mean2d, conic, bound, uvec2(bx, by), params.bins.x, params.bins.y, params.image.z * params.bins.w, params.image.x)
                            : tile_receives(at, conic, bound, uvec2(bx, by), params.bins.x);
#else
                        bool receives = tile_receives(at, conic, bound, uvec2(bx, by), params.bins.x);
#endif
                        touched += receives ? 1u : 0u;
                        mask |= receives ? bit : 0u;
                        bit <<= 1u;
                    }
                }
                // Cut off (see LOOP_REPORT): both loops must have run to their ends.
                if (by < bmax.y || bx < bmax.x) {
                    REPORT_LOOP(counters.max_bins_loop, (bmax.x - bmin.x + 1u) * (bmax.y - bmin.y) + 16u);
                }
                // The record says what the rules see (the radius); only a splat some bin
                // receives is keyed (its rectangle, for the keys stage).
                if (shown && rmax.x > rmin.x && rmax.y > rmin.y) {
                    vec3 dir = unit(mean - params.cam_pos.xyz);
                    uint stride = ((params.counts.z * 3u + 3u) / 4u) * 4u;
                    vec3 color = eval_sh(i * stride, params.counts.y, dir);
                    s.mean_opacity_bound = vec4(mean2d, opacity, bound);
                    s.conic_depth = vec4(conic, depth);
                    s.color_radius = vec4(color, radius);
                }
                if (touched != 0u) {
                    rect = uvec2(pack_tile(rmin.x, rmin.y), pack_tile(rmax.x, rmax.y));
                }
            }
        }
        // Culled Gaussians sort after every visible one.
        uint depth_key = touched != 0u ? floatBitsToUint(depth) : 0xFFFFFFFFu;
        store_outputs(w, i, s, rect, depth_key, touched != 0u ? mask : 0u, touched);
    }
    // Exact 64-bit total of tiles touched (each term < 2^20 tiles).
    uint sum = workgroup_sum_u32(touched);
    uint visible = subgroupAdd(touched != 0u ? 1u : 0u);
    if (subgroupElect() && visible != 0u) atomicAdd(s_visible, visible);
    barrier();
    if (gl_LocalInvocationIndex == 0u && sum != 0u) {
        ATOMIC_ADD_U64(counters.touched_lo, counters.touched_hi, sum);
        atomicAdd(counters.visible, s_visible);
    }
}
