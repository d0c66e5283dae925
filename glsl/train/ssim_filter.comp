#version 460
// Training loss: one axis of SSIM's separable 11-tap Gaussian window (sigma 1.5) over
// `groups` vec4s per pixel, zero outside the image (PyTorch conv2d with padding 5, as the
// original's ssim). The window is symmetric, so the same pass is also its adjoint.
//
// One invocation filters a run of RUN consecutive pixels along the axis, from RUN + 10
// source values held in registers: 2.25 loads per output instead of 11. Each output is
// still the sum over the taps in order, left (top) to right (bottom), of tap * value, with
// the values outside the image 0 (adding +0 to a sum that is never -0 changes no bit), so
// the result is that of the 11-load loop bit for bit.
// TEXEL_FETCH (CPU devices): the source is read through an RGBA32F texel view, which
// llvmpipe gathers in one vector load where a storage-buffer load is a per-lane scalar loop.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "loss_common.glsl"

layout(push_constant) uniform FilterBlock { ImageRowsPush p; };

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

// Outputs per invocation (gpu::shader_set::SSIM_FILTER_RUN, a define from the host).
#define RUN SSIM_FILTER_RUN

void main() {
    uint w = p.size.x, h = p.size.y, groups = p.size.z;
    bool along_x = p.size.w == 0u;
    uint len = along_x ? w : h;
    uint runs = (len + RUN - 1u) / RUN;
    // Invocation i: along x, run i % runs of row i / runs; along y, column i % w of the
    // rows' run i / w (neighbouring invocations read neighbouring columns).
    uint i = pixel_index();
    if (i >= runs * (along_x ? h : w)) return;
    uint other = along_x ? i / runs : i % w;
    int at0 = int((along_x ? i % runs : i / w) * RUN);
    // Pixel index of position c along the axis.
    uint step = along_x ? 1u : w;
    uint base = along_x ? other * w : other;
    for (uint g = 0u; g < groups; g++) {
        vec4 win[RUN + 10];
        [[unroll]] for (int t = 0; t < RUN + 10; t++) {
            int c = at0 + t - 5;
            bool inside = c >= 0 && c < int(len);
            win[t] = SRC((base + uint(clamp(c, 0, int(len) - 1)) * step) * groups + g);
            win[t] = inside ? win[t] : vec4(0.0);
        }
        [[unroll]] for (int j = 0; j < RUN; j++) {
            precise vec4 acc = vec4(0.0);
            [[unroll]] for (int k = 0; k < 11; k++) acc += p.rows[k >> 2][k & 3] * win[j + k];
            if (at0 + j < int(len)) dst[(base + uint(at0 + j) * step) * groups + g] = acc;
        }
    }
}
