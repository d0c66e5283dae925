#version 460
// Feature blend: after the colour blend, composites four feature channels of every splat
// (one group of a scene's K channels; dispatched once per group, without sorting again)
// front to back over the same bin lists, with exactly the colour rules (same alpha,
// transmittance, skip and stop; background 0). One invocation per pixel, 16x8 per
// workgroup (128 invocations, within every device's limit), each reading its own bin's list, so it works with 8- and 16-pixel bins.
// TEXEL_FETCH (CPU devices, as the texel blend kernel): splats, values and features are
// read through texel-buffer views, which lavapipe compiles to gathers instead of per-lane
// scalar loops.
#ifndef SPLAT_KERNEL
#define SPLAT_KERNEL 0u
#endif
#ifndef TEXEL_FETCH
#define TEXEL_FETCH 0
#endif
// SURFACE = 1, the surface pass (core::model::surface, cpu::surface): the one group's
// channels per Gaussian are its axis (n, n . mean) in world space, flipped per Gaussian to
// face the camera (n . mean - n . centre > 0 gives -n) and blended into .xyz; .w is the
// median depth, the depth of the Gaussian that takes the pixel's transmittance from
// above 0.5 to 0.5 or below (0 while none has). Chunks resume it like the channels.
#ifndef SURFACE
#define SURFACE 0
#endif
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"

layout(local_size_x = PIXEL_WG_X, local_size_y = PIXEL_WG_Y) in;

layout(std430, binding = BLEND_FEATURES_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
#if !TEXEL_FETCH
layout(std430, binding = BLEND_FEATURES_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = BLEND_FEATURES_VALUES) readonly buffer ValueBuf { uint values[]; };
#else
layout(binding = BLEND_FEATURES_SPLATS) uniform samplerBuffer splat_texels;   // 3 rgba32f texels per splat
layout(binding = BLEND_FEATURES_VALUES) uniform usamplerBuffer value_texels;
#endif
layout(std430, binding = BLEND_FEATURES_RANGES) readonly buffer RangeBuf { uvec2 ranges[]; };
// This group's four channels per Gaussian (zero-padded past K).
#if !TEXEL_FETCH
layout(std430, binding = BLEND_FEATURES_FEATURES) readonly buffer FeatureBuf { vec4 features[]; };
#else
layout(binding = BLEND_FEATURES_FEATURES) uniform samplerBuffer feature_texels;
#endif
// This group's four channels per pixel, row-major.
layout(std430, binding = BLEND_FEATURES_OUTPUT) buffer OutBuf { vec4 out_features[]; };
layout(std430, binding = BLEND_FEATURES_COUNTERS) buffer CounterBuf { Counters counters; };
// A frame keyed in depth-ordered chunks runs this before each chunk's colour blend: every
// chunk but the first resumes each pixel's channels from the output and its transmittance
// and stop from the colour image's between-chunk state (colour = (C, T), T negated once
// the pixel is done; glsl/render/forward/blend.comp), which at that point is the state the previous
// chunk left. Compositing is sequential per pixel, so the channels equal one pass bit for
// bit. A frame in one piece is resume 0.
layout(binding = BLEND_FEATURES_COLOR_STATE, rgba32f) uniform readonly image2D color_state;
layout(push_constant) uniform FeatureBlendBlock { FeatureBlendPush chunk; };

void main() {
    uvec2 pix = gl_GlobalInvocationID.xy;
    if (pix.x >= params.image.x || pix.y >= params.image.y) return;
    vec2 pixf = vec2(pix);
    uvec2 bin = pix / params.bins.x;
    uvec2 range = ranges[bin.y * params.bins.y + bin.x];
    float T = 1.0;
    vec4 F = vec4(0.0);
    bool done = false;
    uint o = pix.y * params.image.x + pix.x;
    if (chunk.resume != 0u) {
        float state = imageLoad(color_state, ivec2(pix)).a;
        T = abs(state);
        done = state < 0.0;
        F = out_features[o];
    }
    float alpha_max = params.rules.y, t_stop = params.rules.z;
#if SURFACE
    vec3 centre = params.cam_pos.xyz;
#endif
    uint k = range.x;
    // The colour blend's composite(), with features in place of colour and no depth.
    for (; k < range.y && !done; k++) {
#if !TEXEL_FETCH
        uint g = values[k];
        vec4 mob = splats[g].mean_opacity_bound;
        vec4 conic_depth = splats[g].conic_depth;
        vec4 feature = features[g];
#else
        int g = int(texelFetch(value_texels, int(k)).x);
        vec4 mob = texelFetch(splat_texels, g * 3);
        vec4 conic_depth = texelFetch(splat_texels, g * 3 + 1);
        vec4 feature = texelFetch(feature_texels, g);
#endif
        vec3 conic = conic_depth.xyz;
        vec2 d = wrapped_mean(mob.xy, pix.x / TILE_SIZE * TILE_SIZE, params.modes.z, params.image.x) - pixf;
        float power = splat_power(conic, d);
        float alpha = min(alpha_max, kernel_falloff(SPLAT_KERNEL, mob.z, min(power, 0.0)));
        bool take = power <= 0.0 && alpha >= ALPHA_MIN;
        float test_t = T * (1.0 - alpha);
        bool stop = take && test_t < t_stop;
        bool add = take && !stop;
#if SURFACE
        // facing_normal: the sums in this order, no fused multiply-add.
        precise float nc = feature.x * centre.x + feature.y * centre.y + feature.z * centre.z;
        precise float facing = feature.w - nc;
        vec3 n = facing > 0.0 ? -feature.xyz : feature.xyz;
        float w = add ? alpha * T : 0.0;
        if (REPRODUCIBLE) {
            precise vec3 f = F.xyz + n * w;
            F.xyz = f;
        } else {
            F.xyz += n * w;
        }
        F.w = add && T > 0.5 && test_t <= 0.5 ? conic_depth.w : F.w;
#else
        float w = add ? alpha * T : 0.0;
        if (REPRODUCIBLE) {
            precise vec4 f = F + feature * w;
            F = f;
        } else {
            F += feature * w;
        }
#endif
        T = add ? test_t : T;
        done = stop;
    }
    // Cut off before the end of the list (see LOOP_REPORT).
    if (k < range.y && !done) {
        REPORT_LOOP(counters.max_list_loop, range.y - range.x + 16u);
    }
    out_features[o] = F;
}
