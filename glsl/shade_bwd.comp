#version 460
// The neural shader's backward pass (src/render/shade_bwd.rs): from dL/d(shaded colour)
// and dL/d(alpha) per pixel to dL/d(feature channels) and dL/d(alpha) per pixel, which the
// feature blend's backward (blend_bwd) takes, and to the network's weight and bias
// gradients. The rules of cpu::backward::backward_shaded.
//
// A workgroup takes a chunk of 64 consecutive pixels, one per invocation. Each invocation
// evaluates the network on its pixel as shade.comp does (the same operations in the same
// order), keeping every layer's input in the workgroup's scratch region, then walks the
// layers back. The parameters' gradients are summed over the chunk's pixels in pixel
// order by the invocation that owns each parameter (every 64th) and added to the
// workgroup's partial sums; a dispatch covers as many chunks as there are partial slots,
// the next dispatch adds the next chunks to the same slots, and mlp_grad_reduce.comp sums
// the slots in order. No atomics: the gradients are the same bits run after run.
#extension GL_GOOGLE_include_directive : require

#define PIXELS 64u

layout(local_size_x = 64) in;

// 128 bytes of push constants (src/render/shade_bwd.rs ShadeBwdPush).
layout(push_constant) uniform ShadeBwdParams {
    uvec4 size;        // width, height, K, groups of four channels
    uvec4 code;        // input code (Mlp::input_code), layers, plane stride in vec4s, first chunk
    uvec4 shape;       // scratch floats per workgroup, activations per pixel, parameters, widest layer
    vec4 intrinsics;   // fx, fy, cx, cy
    vec4 rot0;         // rows of the world-to-camera rotation
    vec4 rot1;
    vec4 rot2;
    vec4 background;
} p;

layout(binding = SHADE_BWD_WORDS) uniform usamplerBuffer words_view;
#include "mlp_common.glsl"
// The forward's feature planes: group g's vec4 of pixel i at g * plane stride + i.
layout(std430, binding = SHADE_BWD_FEATURES) readonly buffer FeatureBuf { vec4 features[]; };
// The frame's alpha (1 - T) per pixel.
layout(std430, binding = SHADE_BWD_ALPHA) readonly buffer AlphaBuf { float alphas[]; };
// In: dL/d(shaded rgb) and dL/d alpha per pixel; out: dL/d alpha with the shader's part
// added, and rgb 0 (the blend's colour is not what the shader read: only the features are).
layout(std430, binding = SHADE_BWD_GRAD_COLOR) buffer GradColorBuf { vec4 grad_color[]; };
// Out: dL/d(feature channels), pixel-major, groups of four.
layout(std430, binding = SHADE_BWD_GRAD_FEATURES) writeonly buffer GradFeatureBuf { vec4 grad_features[]; };
// Per workgroup: the activations (value j of invocation t at j * 64 + t), then two
// gradient rows of the widest layer, each value 64 apart.
layout(std430, binding = SHADE_BWD_SCRATCH) coherent buffer ScratchBuf { float scratch[]; };
// Per partial slot (workgroup) the parameters' sums, in the words' float layout.
layout(std430, binding = SHADE_BWD_PARTIALS) buffer PartialBuf { float partials[]; };

uint sbase;

uint act_at(uint j, uint t) { return sbase + j * PIXELS + t; }
uint grad_at(uint r, uint i, uint t) { return sbase + (p.shape.y + r * p.shape.w + i) * PIXELS + t; }

// The invocations' scratch writes, visible to the workgroup.
void sync() {
    memoryBarrierBuffer();
    barrier();
}

void main() {
    uint t = gl_LocalInvocationID.x;
    uint wg = gl_WorkGroupID.x;
    sbase = wg * p.shape.x;
    uint index = (p.code.w + wg) * PIXELS + t;
    bool live = index < p.size.x * p.size.y;
    uvec2 pix = uvec2(index % p.size.x, index / p.size.x);
    float alpha = live ? alphas[index] : 0.0;

    // The first layer's inputs (zeros past the image: their gradients are 0).
    uint n = 0u;
    uint slots = (p.code.x >> 4) & 3u;
    for (uint s = 0u; s < slots; s++) {
        uint id = (p.code.x >> (8u + 2u * s)) & 3u;
        if (id == 0u) {
            for (uint k = 0u; k < p.size.z; k++) {
                scratch[act_at(n++, t)] = live ? features[(k >> 2) * p.code.z + index][k & 3u] : 0.0;
            }
        } else if (id == 1u) {
            vec3 w = mlp_view_dir(pix, p.intrinsics, p.rot0, p.rot1, p.rot2);
            scratch[act_at(n++, t)] = w.x;
            scratch[act_at(n++, t)] = w.y;
            scratch[act_at(n++, t)] = w.z;
        } else {
            scratch[act_at(n++, t)] = alpha;
        }
    }

    // Forward, as shade.comp: each layer's outputs follow its inputs.
    uint at = 0u;
    for (uint l = 0u; l < p.code.y; l++) {
        uvec4 h = layer_header(l);
        uint ins = h.x, outs = h.y, kind = h.z, base = h.w;
        for (uint o = 0u; o < outs; o++) {
            precise float acc = weight(base + outs * ins + o);
            for (uint i = 0u; i < ins; i++) {
                acc += weight(base + o * ins + i) * scratch[act_at(at + i, t)];
            }
            scratch[act_at(at + ins + o, t)] = activate(kind, acc);
        }
        at += ins;
    }
    vec3 c = vec3(scratch[act_at(at, t)], scratch[act_at(at + 1u, t)], scratch[act_at(at + 2u, t)]);

    // colour = alpha c + (1 - alpha) background.
    vec4 g = live ? grad_color[index] : vec4(0.0);
    precise float g_alpha = g.r * (c.r - p.background.r);
    g_alpha += g.g * (c.g - p.background.g);
    g_alpha += g.b * (c.b - p.background.b);
    uint cur = 0u;
    scratch[grad_at(cur, 0u, t)] = alpha * g.r;
    scratch[grad_at(cur, 1u, t)] = alpha * g.g;
    scratch[grad_at(cur, 2u, t)] = alpha * g.b;

    // Back through the layers, last first.
    for (uint li = p.code.y; li > 0u; li--) {
        uvec4 h = layer_header(li - 1u);
        uint ins = h.x, outs = h.y, kind = h.z, base = h.w;
        at -= ins;
        for (uint o = 0u; o < outs; o++) {
            float y = scratch[act_at(at + ins + o, t)];
            scratch[grad_at(cur, o, t)] *= activate_grad(kind, y);
        }
        for (uint j = 0u; j < ins; j++) {
            precise float acc = 0.0;
            for (uint o = 0u; o < outs; o++) {
                acc += scratch[grad_at(cur, o, t)] * weight(base + o * ins + j);
            }
            scratch[grad_at(1u - cur, j, t)] = acc;
        }
        sync();
        // dL/dW[o][j] = sum over pixels of dL/dz[o] x[j], dL/db[o] = sum of dL/dz[o]:
        // invocation t sums parameters t, t + 64, ... over the chunk's pixels in order.
        uint weights = outs * ins;
        for (uint q = t; q < weights + outs; q += PIXELS) {
            precise float sum = 0.0;
            if (q < weights) {
                uint o = q / ins, j = q % ins;
                for (uint u = 0u; u < PIXELS; u++) {
                    sum += scratch[grad_at(cur, o, u)] * scratch[act_at(at + j, u)];
                }
            } else {
                for (uint u = 0u; u < PIXELS; u++) {
                    sum += scratch[grad_at(cur, q - weights, u)];
                }
            }
            uint slot = wg * p.shape.z + base + q;
            partials[slot] = partials[slot] + sum;
        }
        // Every invocation has read this layer's rows before the next overwrites them.
        sync();
        cur = 1u - cur;
    }
    if (!live) return;

    // dL/d(the first layer's inputs): the features' to the feature blend, alpha's added.
    n = 0u;
    for (uint s = 0u; s < slots; s++) {
        uint id = (p.code.x >> (8u + 2u * s)) & 3u;
        if (id == 0u) {
            for (uint gi = 0u; gi < p.size.w; gi++) {
                vec4 v = vec4(0.0);
                for (uint c4 = 0u; c4 < 4u; c4++) {
                    uint k = 4u * gi + c4;
                    if (k < p.size.z) v[c4] = scratch[grad_at(cur, n + k, t)];
                }
                grad_features[index * p.size.w + gi] = v;
            }
            n += p.size.z;
        } else if (id == 1u) {
            n += 3u;  // the view direction has no parameter
        } else {
            g_alpha += scratch[grad_at(cur, n, t)];
            n += 1u;
        }
    }
    grad_color[index] = vec4(0.0, 0.0, 0.0, g.a + g_alpha);
}
