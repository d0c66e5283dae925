#version 460
// The neural shader's backward pass: from dL/d(shaded colour) and dL/d(alpha) per pixel
// to dL/d(feature channels) and dL/d(alpha) per pixel, which the feature blend's backward
// (blend_bwd.comp) takes, and to the network's weight and bias gradients.
//
// A workgroup takes a chunk of PIXELS consecutive pixels, one per invocation. Each
// invocation evaluates the network on its pixel as shade.comp does (the same operations in
// the same order), keeping every layer's input in a private array sized for the network,
// then walks the layers back. Per layer, the chunk's inputs and output gradients are staged
// in the workgroup's scratch region; the parameters' gradients are summed over the chunk's
// pixels in pixel order by the invocation that owns each parameter (every PIXELS-th) and
// added to the workgroup's partial sums; a dispatch covers as many chunks as there are
// partial slots, the next dispatch adds the next chunks to the same slots, and
// mlp_grad_reduce.comp sums the slots in order. No atomics: the gradients are the same
// bits run after run.
#extension GL_GOOGLE_include_directive : require
#include "interface.glsl"

#define PIXELS SHADE_CHUNK_PIXELS

layout(local_size_x = PIXELS) in;

// Sized for the network: the values a pixel's evaluation keeps, and the widest layer.
layout(constant_id = SHADE_SPEC_ACTIVATIONS) const uint ACTIVATIONS = 16u;
layout(constant_id = SHADE_SPEC_WIDEST) const uint WIDEST = 16u;

// shade.comp's constants, then the pass's shape (scratch vec4s per workgroup, 0,
// parameters, 0).
layout(push_constant) uniform ShadeBwdBlock { ShadeBwdPush bwd; };

layout(binding = SHADE_BWD_WORDS) uniform usamplerBuffer words_view;
#include "mlp_common.glsl"
// The forward's feature planes: group g's vec4 of pixel i at g * plane stride + i.
layout(std430, binding = SHADE_BWD_FEATURES) readonly buffer FeatureBuf { vec4 features[]; };
// The frame's colour image per pixel (a copy of it), whose alpha is 1 - T.
layout(std430, binding = SHADE_BWD_ALPHA) readonly buffer AlphaBuf { vec4 pixel_colors[]; };
// In: dL/d(shaded rgb) and dL/d alpha per pixel; out: dL/d alpha with the shader's part
// added, and rgb 0 (the blend's colour is not what the shader read: only the features are).
layout(std430, binding = SHADE_BWD_GRAD_COLOR) buffer GradColorBuf { vec4 grad_color[]; };
// Out: dL/d(feature channels), pixel-major, groups of four.
layout(std430, binding = SHADE_BWD_GRAD_FEATURES) writeonly buffer GradFeatureBuf { vec4 grad_features[]; };
// Per workgroup, one layer at a time, pixel-major in rows of vec4s: each pixel's inputs
// and a 1 (the bias's input), zero-padded to XROW vec4s, then each pixel's outputs'
// gradients, zero-padded to GROW vec4s.
layout(std430, binding = SHADE_BWD_SCRATCH) coherent buffer ScratchBuf { vec4 scratch[]; };
// Per partial slot (workgroup) the parameters' sums, in the words' float layout.
layout(std430, binding = SHADE_BWD_PARTIALS) buffer PartialBuf { float partials[]; };

const uint XROW = (WIDEST + 4u) / 4u;
const uint GROW = (WIDEST + 3u) / 4u;

float act[ACTIVATIONS];
// Two rows of gradients, the current layer's outputs' and its inputs'.
float grad[2u * WIDEST];

// The invocations' scratch writes, visible to the workgroup.
void sync() {
    memoryBarrierBuffer();
    barrier();
}

void main() {
    uint t = gl_LocalInvocationID.x;
    uint wg = gl_WorkGroupID.x;
    uint sbase = wg * bwd.shape.x;
    uint gbase = sbase + PIXELS * XROW;
    uint index = (bwd.shade.code.w + wg) * PIXELS + t;
    bool live = index < bwd.shade.size.x * bwd.shade.size.y;
    uvec2 pix = uvec2(index % bwd.shade.size.x, index / bwd.shade.size.x);
    float alpha = live ? pixel_colors[index].a : 0.0;

    // The first layer's inputs (zeros past the image: their gradients are 0).
    uint n = 0u;
    uint slots = (bwd.shade.code.x >> 4) & 3u;
    for (uint s = 0u; s < slots; s++) {
        uint id = (bwd.shade.code.x >> (8u + 2u * s)) & 3u;
        if (id == 0u) {
            for (uint k = 0u; k < bwd.shade.size.z; k++) {
                act[n++] = live ? features[(k >> 2) * bwd.shade.code.z + index][k & 3u] : 0.0;
            }
        } else if (id == 1u) {
            vec3 w = mlp_view_dir(pix, bwd.shade.intrinsics, bwd.shade.rot[0], bwd.shade.rot[1], bwd.shade.rot[2]);
            act[n++] = w.x;
            act[n++] = w.y;
            act[n++] = w.z;
        } else {
            act[n++] = alpha;
        }
    }

    // Forward, as shade.comp: each layer's outputs follow its inputs.
    uint at = 0u;
    for (uint l = 0u; l < bwd.shade.code.y; l++) {
        uvec4 h = layer_header(l);
        uint ins = h.x, outs = h.y, kind = h.z, base = h.w;
        for (uint o = 0u; o < outs; o++) {
            precise float acc = weight(base + outs * ins + o);
            for (uint i = 0u; i < ins; i++) {
                acc += weight(base + o * ins + i) * act[at + i];
            }
            act[at + ins + o] = activate(kind, acc);
        }
        at += ins;
    }
    vec3 c = vec3(act[at], act[at + 1u], act[at + 2u]);

    // colour = alpha c + (1 - alpha) background.
    vec4 g = live ? grad_color[index] : vec4(0.0);
    precise float g_alpha = g.r * (c.r - bwd.shade.background.r);
    g_alpha += g.g * (c.g - bwd.shade.background.g);
    g_alpha += g.b * (c.b - bwd.shade.background.b);
    uint cur = 0u;
    grad[0] = alpha * g.r;
    grad[1] = alpha * g.g;
    grad[2] = alpha * g.b;

    // Back through the layers, last first.
    for (uint li = bwd.shade.code.y; li > 0u; li--) {
        uvec4 h = layer_header(li - 1u);
        uint ins = h.x, outs = h.y, kind = h.z, base = h.w;
        uint gc = cur * WIDEST, gn = WIDEST - gc;
        at -= ins;
        uint orow = (outs + 3u) / 4u, xrow = (ins + 4u) / 4u;
        for (uint o = 0u; o < 4u * orow; o++) {
            float gz = 0.0;
            if (o < outs) {
                gz = grad[gc + o] * activate_grad(kind, act[at + ins + o]);
                grad[gc + o] = gz;
            }
            scratch[gbase + t * orow + (o >> 2)][o & 3u] = gz;
        }
        for (uint j = ins; j < 4u * xrow; j++) {
            scratch[sbase + t * xrow + (j >> 2)][j & 3u] = j == ins ? 1.0 : 0.0;
        }
        for (uint j = 0u; j < ins; j++) {
            scratch[sbase + t * xrow + (j >> 2)][j & 3u] = act[at + j];
            precise float acc = 0.0;
            for (uint o = 0u; o < outs; o++) {
                acc += grad[gc + o] * weight(base + o * ins + j);
            }
            grad[gn + j] = acc;
        }
        sync();
        // dL/dW[o][j] = sum over pixels of dL/dz[o] x[j], and dL/db[o] = the same with
        // x = 1: blocks of 4 x 4 parameters, invocation t summing blocks t, t + 64, ...
        // over the chunk's pixels in order.
        uint slot0 = wg * bwd.shape.z + base;
        for (uint b = t; b < orow * xrow; b += PIXELS) {
            uint ob = b / xrow, jb = b % xrow;
            precise vec4 s0 = vec4(0.0), s1 = vec4(0.0), s2 = vec4(0.0), s3 = vec4(0.0);
            for (uint u = 0u; u < PIXELS; u++) {
                vec4 x = scratch[sbase + u * xrow + jb];
                vec4 gz = scratch[gbase + u * orow + ob];
                s0 += gz.x * x;
                s1 += gz.y * x;
                s2 += gz.z * x;
                s3 += gz.w * x;
            }
            mat4 sums = mat4(s0, s1, s2, s3);
            for (uint r = 0u; r < 4u; r++) {
                uint o = 4u * ob + r;
                for (uint c4 = 0u; c4 < 4u; c4++) {
                    uint j = 4u * jb + c4;
                    if (o < outs && j <= ins) {
                        uint slot = slot0 + (j < ins ? o * ins + j : outs * ins + o);
                        partials[slot] = partials[slot] + sums[r][c4];
                    }
                }
            }
        }
        // Every invocation has read this layer's rows before the next overwrites them.
        sync();
        cur = 1u - cur;
    }
    if (!live) return;

    // dL/d(the first layer's inputs): the features' to the feature blend, alpha's added.
    uint gi0 = cur * WIDEST;
    n = 0u;
    for (uint s = 0u; s < slots; s++) {
        uint id = (bwd.shade.code.x >> (8u + 2u * s)) & 3u;
        if (id == 0u) {
            for (uint gi = 0u; gi < bwd.shade.size.w; gi++) {
                vec4 v = vec4(0.0);
                for (uint c4 = 0u; c4 < 4u; c4++) {
                    uint k = 4u * gi + c4;
                    if (k < bwd.shade.size.z) v[c4] = grad[gi0 + n + k];
                }
                grad_features[index * bwd.shade.size.w + gi] = v;
            }
            n += bwd.shade.size.z;
        } else if (id == 1u) {
            n += 3u;  // the view direction has no parameter
        } else {
            g_alpha += grad[gi0 + n];
            n += 1u;
        }
    }
    grad_color[index] = vec4(0.0, 0.0, 0.0, g.a + g_alpha);
}
