#version 460
// Blend: one workgroup per 16x16 tile, compositing the tile's sorted Gaussians front to back
// with the reference rules and the alpha falloff of SPLAT_KERNEL. Two variants of the same
// arithmetic, chosen per device:
//  - STRIP == 1 (GPUs): one invocation per pixel; Gaussians are fetched into shared memory
//    in batches of 256, and the workgroup stops once every pixel of the tile is finished.
//  - STRIP > 1 (CPU devices such as lavapipe, where every loop-indexed memory load is a
//    per-lane scalar loop): one invocation per STRIP pixels of a row, reading each Gaussian
//    once for all of them; an invocation stops once all its pixels are finished.
#ifndef STRIP
#define STRIP 1
#endif
#ifndef TEXEL_FETCH
#define TEXEL_FETCH 0
#endif
// The alpha falloff (SPLAT_KERNEL_GAUSSIAN or SPLAT_KERNEL_POWER), fixed per pipeline:
// llvmpipe would evaluate both sides of a runtime branch on it.
#ifndef SPLAT_KERNEL
#define SPLAT_KERNEL 0u
#endif
// SAVE_LAST = 1 (frames whose forward state a backward pass reads) also writes, per pixel,
// one past the sorted-pair index of the last Gaussian composited into it (0: none) and the
// bits of its final transmittance (exact: 1 - alpha would lose its low bits).
#ifndef SAVE_LAST
#define SAVE_LAST 0
#endif
#define CHUNK_W min(4u, TILE_SIZE / STRIP)
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "splat_common.glsl"

layout(local_size_x = TILE_SIZE / STRIP, local_size_y = TILE_SIZE) in;

layout(std430, binding = BLEND_PARAMS) readonly buffer ParamsBuf { FrameParams params; };
#if !TEXEL_FETCH
layout(std430, binding = BLEND_SPLATS) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = BLEND_VALUES) readonly buffer ValueBuf { uint values[]; };
#else
// Texel-buffer views of the same splats (3 rgba32f texels each) and sorted values: on CPU
// implementations texel fetches compile to straight-line gathers, unlike buffer loads.
layout(binding = BLEND_SPLATS) uniform samplerBuffer splat_texels;
layout(binding = BLEND_VALUES) uniform usamplerBuffer value_texels;
#endif
layout(std430, binding = BLEND_RANGES) readonly buffer RangeBuf { uvec2 ranges[]; };
layout(binding = BLEND_COLOR, rgba32f) uniform image2D out_color;  // rgb + T * background, alpha = 1 - T
layout(binding = BLEND_DEPTH, r32f) uniform image2D out_depth;     // alpha-normalised depth
layout(std430, binding = BLEND_COUNTERS) buffer CounterBuf { Counters counters; };
#if SAVE_LAST
layout(std430, binding = BLEND_LAST) writeonly buffer LastBuf { uvec2 last_state[]; };
#endif
// A frame keyed in depth-ordered chunks (the host's split of a large frame) is blended once per chunk:
// every chunk but the first resumes each pixel from the state the previous one left in
// the images, and every chunk but the last leaves that state instead of the final pixel.
// Compositing is sequential per pixel, so the result equals one pass bit for bit. A frame
// in one piece is (resume 0, last 1). A frame in one piece whose last contributors exceed
// one storage binding is blended in bands of tile rows (first_tile_row on), each binding
// its rows of last_state: the same pixels, each written once.
layout(push_constant) uniform BlendBlock { BlendPush chunk; };

// Composites one Gaussian into one pixel's state (the reference's per-pixel rule),
// written without branches: SIMD implementations execute both sides of a divergent branch
// anyway, so selects are cheaper than masked control flow. Identical results.
// Returns whether the Gaussian was composited (for SAVE_LAST). The rules' alpha clamp and
// stop (FrameParams.rules.yz), read once per invocation by main().
float alpha_max;
float t_stop;
bool composite(vec4 mean_opacity_depth, vec3 conic, vec3 color, vec2 pixf,
               inout float T, inout vec3 C, inout float D, inout bool done) {
    vec2 d = mean_opacity_depth.xy - pixf;
    float power = splat_power(conic, d);
    float alpha = min(alpha_max, kernel_falloff(SPLAT_KERNEL, mean_opacity_depth.z, min(power, 0.0)));
    bool take = !done && power <= 0.0 && alpha >= ALPHA_MIN;
    float test_t = T * (1.0 - alpha);
    bool stop = take && test_t < t_stop;
    bool add = take && !stop;
    float w = add ? alpha * T : 0.0;
    if (REPRODUCIBLE) {
        // Unfused, as the CPU reference adds them.
        precise vec3 c = C + color * w;
        precise float dw = D + mean_opacity_depth.w * w;
        C = c;
        D = dw;
    } else {
        C += color * w;
        D += mean_opacity_depth.w * w;
    }
    T = add ? test_t : T;
    done = done || stop;
    return add;
}

// One past the pair index of the pixel's last composited Gaussian and the pixel's final
// transmittance (a frame in one piece).
void write_last(uvec2 pix, uint last, float T) {
#if SAVE_LAST
    if (pix.x < params.image.x && pix.y < params.image.y) {
        // The binding starts at the band's first pixel row.
        uint row = pix.y - chunk.first_tile_row * TILE_SIZE;
        last_state[row * params.image.x + pix.x] = uvec2(last, floatBitsToUint(T));
    }
#endif
}

// The state between chunks: colour = (C, T), with T negated once the pixel is done (T
// stays above the stop > 0, so the sign carries the flag exactly); depth = D.
void load_pixel(uvec2 pix, inout float T, inout vec3 C, inout float D, inout bool done) {
    if (chunk.resume != 0u && pix.x < params.image.x && pix.y < params.image.y) {
        vec4 state = imageLoad(out_color, ivec2(pix));
        C = state.rgb;
        T = abs(state.a);
        done = state.a < 0.0;
        D = imageLoad(out_depth, ivec2(pix)).x;
    }
}

void write_pixel(uvec2 pix, float T, vec3 C, float D, bool done) {
    if (pix.x < params.image.x && pix.y < params.image.y) {
        if (chunk.last == 0u) {
            imageStore(out_color, ivec2(pix), vec4(C, done ? -T : T));
            imageStore(out_depth, ivec2(pix), vec4(D));
            return;
        }
        float a = 1.0 - T;
        imageStore(out_color, ivec2(pix), vec4(C + T * params.background.rgb, a));
        imageStore(out_depth, ivec2(pix), vec4(a > 0.0 ? D / a : 0.0));
    }
}

#if !TEXEL_FETCH
shared vec4 s_mean_opacity[TILE_PIXELS];  // mean2d.xy, opacity, depth
shared vec4 s_conic[TILE_PIXELS];         // A, B, C
shared vec4 s_color[TILE_PIXELS];
shared uint s_done;

void main() {
    alpha_max = params.rules.y;
    t_stop = params.rules.z;
    uvec2 tile = gl_WorkGroupID.xy + uvec2(0u, chunk.first_tile_row);
    uint tile_id = tile.y * params.bins.y + tile.x;  // this kernel runs with 16-pixel bins
    uvec2 pix = tile * TILE_SIZE + gl_LocalInvocationID.xy;
    bool inside = pix.x < params.image.x && pix.y < params.image.y;
    vec2 pixf = vec2(pix);
    bool done = !inside;
    float T = 1.0;
    vec3 C = vec3(0.0);
    float D = 0.0;
    uint last = 0u;
    load_pixel(pix, T, C, D, done);
    uvec2 range = ranges[tile_id];
    uint n = range.y - range.x;
    if (gl_LocalInvocationIndex == 0u) {
        REPORT_LOOP(counters.max_list_loop, n + n / TILE_PIXELS + 16u);
    }
    for (uint batch = 0u; batch < n; batch += TILE_PIXELS) {
        // Stop when every pixel of the tile is done (uniform: all threads read one count).
        if (gl_LocalInvocationIndex == 0u) s_done = 0u;
        barrier();
        if (done) atomicAdd(s_done, 1u);
        barrier();
        if (s_done == TILE_PIXELS) break;
        uint k = batch + gl_LocalInvocationIndex;
        if (k < n) {
            Splat s = splats[values[range.x + k]];
            vec2 mean = wrapped_mean(s.mean_opacity_bound.xy, tile.x * TILE_SIZE, params.modes.z, params.image.x);
            s_mean_opacity[gl_LocalInvocationIndex] = vec4(mean, s.mean_opacity_bound.z, s.conic_depth.w);
            s_conic[gl_LocalInvocationIndex] = s.conic_depth;
            s_color[gl_LocalInvocationIndex] = s.color_radius;
        }
        barrier();
        uint count = min(TILE_PIXELS, n - batch);
        for (uint j = 0u; !done && j < count; j++) {
            if (composite(s_mean_opacity[j], s_conic[j].xyz, s_color[j].rgb, pixf, T, C, D, done)) {
                last = SAVE_LAST != 0 ? range.x + batch + j + 1u : 0u;
            }
        }
        barrier();
    }
    write_pixel(pix, T, C, D, done);
    write_last(pix, last, T);
}
#else
void main() {
    alpha_max = params.rules.y;
    t_stop = params.rules.z;
    uvec2 tile = spread_workgroup() + uvec2(0u, chunk.first_tile_row);
    // Each run of 8 consecutive invocations (what lavapipe executes as one SIMD vector)
    // covers a compact block of CHUNK_W strips by 8 / CHUNK_W rows instead of one long row:
    // neighbouring pixels see the same Gaussians and finish together (measured: 8x2 pixel
    // blocks blend about 10 % faster than 16x1 rows). Only a layout choice: correct for any
    // subgroup size.
    uint li = gl_LocalInvocationIndex;
    uint chunk = li / 8u, lane = li % 8u;
    uint chunks_x = (TILE_SIZE / STRIP) / CHUNK_W;
    uvec2 strip_xy = uvec2((chunk % chunks_x) * CHUNK_W + lane % CHUNK_W,
                           (chunk / chunks_x) * (8u / CHUNK_W) + lane / CHUNK_W);
    uvec2 pix0 = tile * TILE_SIZE + uvec2(strip_xy.x * STRIP, strip_xy.y);
    float T[STRIP];
    vec3 C[STRIP];
    float D[STRIP];
    bool done[STRIP];
    uint last[STRIP];
    [[unroll]] for (uint p = 0u; p < STRIP; p++) {
        last[p] = 0u;
        T[p] = 1.0;
        C[p] = vec3(0.0);
        D[p] = 0.0;
        done[p] = pix0.x + p >= params.image.x || pix0.y >= params.image.y;
        load_pixel(pix0 + uvec2(p, 0u), T[p], C[p], D[p], done[p]);
    }
    // This invocation's pixels lie in one bin (strips never cross a bin); pixels past the
    // image edge have no bin.
    uvec2 bin = pix0 / params.bins.x;
    uvec2 range = pix0.y < params.image.y && pix0.x < params.image.x
        ? ranges[bin.y * params.bins.y + bin.x] : uvec2(0u);
    uint k = range.x;
    bool all_done = false;
    for (; k < range.y; k++) {
        all_done = true;
        [[unroll]] for (uint p = 0u; p < STRIP; p++) all_done = all_done && done[p];
        if (all_done) break;
        int g = int(texelFetch(value_texels, int(k)).x) * 3;
        vec4 mob = texelFetch(splat_texels, g);
        vec4 cd = texelFetch(splat_texels, g + 1);
        vec3 color = texelFetch(splat_texels, g + 2).rgb;
        vec2 mean = wrapped_mean(mob.xy, pix0.x / TILE_SIZE * TILE_SIZE, params.modes.z, params.image.x);
        vec4 mo = vec4(mean, mob.z, cd.w);
        [[unroll]] for (uint p = 0u; p < STRIP; p++) {
            if (composite(mo, cd.xyz, color, vec2(pix0) + vec2(float(p), 0.0), T[p], C[p], D[p], done[p])) {
                last[p] = SAVE_LAST != 0 ? k + 1u : 0u;
            }
        }
    }
    // Cut off before the end of the list with pixels still unfinished (see LOOP_REPORT).
    if (k < range.y && !all_done) {
        REPORT_LOOP(counters.max_list_loop, range.y - range.x + 16u);
    }
    [[unroll]] for (uint p = 0u; p < STRIP; p++) {
        write_pixel(pix0 + uvec2(p, 0u), T[p], C[p], D[p], done[p]);
        write_last(pix0 + uvec2(p, 0u), last[p], T[p]);
    }
}
#endif
