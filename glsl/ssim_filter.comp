#version 460
// Training loss: one axis of SSIM's separable 11-tap Gaussian window (sigma 1.5) over
// `groups` vec4s per pixel, zero outside the image (PyTorch conv2d with padding 5, as the
// original's ssim). The window is symmetric, so the same pass is also its adjoint.
// TEXEL_FETCH (CPU devices): the source is read through an RGBA32F texel view, which
// llvmpipe gathers in one vector load where a storage-buffer load in the tap loop is a
// per-lane scalar loop.
#extension GL_GOOGLE_include_directive : require
#include "loss_common.glsl"

layout(push_constant) uniform Params {
    uvec4 size;     // width, height, vec4s per pixel, axis (0: x, 1: y)
    vec4 taps[3];   // the 11 normalised taps (metrics::ssim's, in f32)
} p;

#ifndef TEXEL_FETCH
#define TEXEL_FETCH 0
#endif
#if TEXEL_FETCH
layout(binding = SSIM_FILTER_SRC) uniform samplerBuffer src_texels;
#define SRC(j) texelFetch(src_texels, int(j))
#else
layout(std430, binding = SSIM_FILTER_SRC) readonly buffer SrcBuf { vec4 src[]; };
#define SRC(j) src[j]
#endif
layout(std430, binding = SSIM_FILTER_DST) writeonly buffer DstBuf { vec4 dst[]; };

void main() {
    uint i = pixel_index();
    uint w = p.size.x, h = p.size.y, groups = p.size.z;
    if (i >= w * h) return;
    int x = int(i % w), y = int(i / w);
    bool along_x = p.size.w == 0u;
    int len = int(along_x ? w : h);
    int at = along_x ? x : y;
    for (uint g = 0u; g < groups; g++) {
        precise vec4 acc = vec4(0.0);
        for (int k = 0; k < 11; k++) {
            int c = at + k - 5;
            if (c < 0 || c >= len) continue;
            uint j = along_x ? uint(y) * w + uint(c) : uint(c) * w + uint(x);
            acc += p.taps[k >> 2][k & 3] * SRC(j * groups + g);
        }
        dst[i * groups + g] = acc;
    }
}
