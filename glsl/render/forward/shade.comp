#version 460
// Neural shader: a per-pixel MLP over the blended feature image (the MLP's file format
// documents the evaluation order, which the CPU reference shares). Reads the feature
// channels (K, in groups of four), optionally the pixel's view direction and alpha, runs
// the layers, and writes alpha * mlp + (1 - alpha) * background into the colour image
// (alpha is kept). One invocation per pixel.
#extension GL_GOOGLE_include_directive : require
#include "interface.glsl"

// PIXEL_WG_X x PIXEL_WG_Y (16 x 8) pixels: 128 invocations, within every device's limit.
layout(local_size_x = PIXEL_WG_X, local_size_y = PIXEL_WG_Y) in;

layout(push_constant) uniform ShadeBlock { ShadePush p; };

// 4 * MAX_LAYERS header words (inputs, outputs, activation, float offset), then the
// weights and biases as float bits.
// Read through a texel view (R32_UINT).
layout(binding = SHADE_WORDS) uniform usamplerBuffer words_view;
#include "mlp_common.glsl"
// Feature planes: group g's vec4 of pixel i at g * plane stride + i.
layout(std430, binding = SHADE_FEATURES) readonly buffer FeatureBuf { vec4 features[]; };
layout(binding = SHADE_COLOR, rgba32f) uniform image2D color;  // rgb + T * background, alpha = 1 - T

void main() {
    uvec2 pix = gl_GlobalInvocationID.xy;
    if (pix.x >= p.size.x || pix.y >= p.size.y) return;
    uint index = pix.y * p.size.x + pix.x;
    vec4 c = imageLoad(color, ivec2(pix));
    float alpha = c.a;

    // Two halves: the current layer's inputs and its outputs, swapped after each layer.
    float act[2 * MAX_WIDTH];
    uint n = 0u;
    uint slots = (p.code.x >> 4) & 3u;
    for (uint s = 0u; s < slots; s++) {
        uint id = (p.code.x >> (8u + 2u * s)) & 3u;
        if (id == 0u) {
            for (uint k = 0u; k < p.size.z; k++) {
                act[n++] = features[(k >> 2) * p.code.z + index][k & 3u];
            }
        } else if (id == 1u) {
            vec3 w = mlp_view_dir(pix, p.intrinsics, p.rot[0], p.rot[1], p.rot[2]);
            act[n++] = w.x;
            act[n++] = w.y;
            act[n++] = w.z;
        } else {
            act[n++] = alpha;
        }
    }

    uint cur = 0u;
    for (uint l = 0u; l < p.code.y; l++) {
        uvec4 h = layer_header(l);
        uint ins = h.x, outs = h.y, kind = h.z, base = h.w;
        uint next = MAX_WIDTH - cur;
        for (uint o = 0u; o < outs; o++) {
            // Bias first, then the products in input order: the CPU reference's order.
            precise float acc = weight(base + outs * ins + o);
            for (uint i = 0u; i < ins; i++) {
                acc += weight(base + o * ins + i) * act[cur + i];
            }
            act[next + o] = activate(kind, acc);
        }
        cur = next;
    }
    float t = 1.0 - alpha;
    vec3 rgb = alpha * vec3(act[cur], act[cur + 1u], act[cur + 2u]) + t * p.background.rgb;
    imageStore(color, ivec2(pix), vec4(rgb, alpha));
}
