#version 460
// Training loss, stage 1: per pixel the five quantities whose local
// means SSIM compares, for R, G and B: x, y, x^2, y^2, xy (x the rendered image, y the
// target), as five vec4s (rgb, w unused). A masked pixel (target w 1) reads the target
// for the image: the loss sees no difference there.
#extension GL_GOOGLE_include_directive : require
#include "loss_common.glsl"

layout(push_constant) uniform SizeBlock { SizePush p; };

layout(std430, binding = SSIM_PREPARE_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = SSIM_PREPARE_TARGET) readonly buffer TargetBuf { vec4 target[]; };
layout(std430, binding = SSIM_PREPARE_PLANES) writeonly buffer PlaneBuf { vec4 planes[]; };

void main() {
    uint i = pixel_index();
    if (i >= p.size.x * p.size.y) return;
    vec3 y = target[i].rgb;
    vec3 x = target[i].w != 0.0 ? y : image[i].rgb;
    planes[5u * i + 0u] = vec4(x, 0.0);
    planes[5u * i + 1u] = vec4(y, 0.0);
    planes[5u * i + 2u] = vec4(x * x, 0.0);
    planes[5u * i + 3u] = vec4(y * y, 0.0);
    planes[5u * i + 4u] = vec4(x * y, 0.0);
}
