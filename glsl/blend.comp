#version 460
// Blend: one 16x16 workgroup per tile. The tile's sorted Gaussians are fetched into shared
// memory in batches of 256 and composited front to back with the reference rules; the
// workgroup stops as soon as every pixel of the tile is finished.
#extension GL_GOOGLE_include_directive : require
#include "splat_common.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(std430, binding = 0) readonly buffer ParamsBuf { FrameParams params; };
layout(std430, binding = 1) readonly buffer SplatBuf { Splat splats[]; };
layout(std430, binding = 2) readonly buffer ValueBuf { uint values[]; };
layout(std430, binding = 3) readonly buffer RangeBuf { uvec2 ranges[]; };
layout(binding = 4, rgba32f) uniform writeonly image2D out_color;  // rgb + T * background, alpha = 1 - T
layout(binding = 5, r32f) uniform writeonly image2D out_depth;     // alpha-normalised depth

shared vec4 s_mean_opacity[TILE_PIXELS];  // mean2d.xy, opacity, depth
shared vec4 s_conic[TILE_PIXELS];         // A, B, C
shared vec4 s_color[TILE_PIXELS];
shared uint s_done;

void main() {
    uvec2 tile = gl_WorkGroupID.xy;
    uint tile_id = tile.y * params.image.z + tile.x;
    uvec2 pix = tile * TILE_SIZE + gl_LocalInvocationID.xy;
    bool inside = pix.x < params.image.x && pix.y < params.image.y;
    vec2 pixf = vec2(pix);
    bool done = !inside;
    float T = 1.0;
    vec3 C = vec3(0.0);
    float D = 0.0;
    uvec2 range = ranges[tile_id];
    uint n = range.y - range.x;
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
            s_mean_opacity[gl_LocalInvocationIndex] = vec4(s.mean_depth_opacity.xy, s.mean_depth_opacity.w, s.mean_depth_opacity.z);
            s_conic[gl_LocalInvocationIndex] = s.conic_radius;
            s_color[gl_LocalInvocationIndex] = s.color;
        }
        barrier();
        uint count = min(TILE_PIXELS, n - batch);
        for (uint j = 0u; !done && j < count; j++) {
            vec4 mo = s_mean_opacity[j];
            vec3 con = s_conic[j].xyz;
            vec2 d = mo.xy - pixf;
            float power = -0.5 * (con.x * d.x * d.x + con.z * d.y * d.y) - con.y * d.x * d.y;
            if (power > 0.0) continue;
            float alpha = min(ALPHA_MAX, mo.z * exp(power));
            if (alpha < ALPHA_MIN) continue;
            float test_t = T * (1.0 - alpha);
            if (test_t < T_MIN) {
                done = true;
                break;
            }
            float w = alpha * T;
            C += s_color[j].rgb * w;
            D += mo.w * w;
            T = test_t;
        }
        barrier();
    }
    if (inside) {
        float a = 1.0 - T;
        imageStore(out_color, ivec2(pix), vec4(C + T * params.background.rgb, a));
        imageStore(out_depth, ivec2(pix), vec4(a > 0.0 ? D / a : 0.0));
    }
}
