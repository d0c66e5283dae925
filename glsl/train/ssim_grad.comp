#version 460
// Training loss: dL/d(rendered pixel) of L = (1 - lambda) L1 + lambda (1 - SSIM), from the
// filtered derivative maps: dSSIM/dx = (F[dS/dmx] + 2 x F[dS/dExx] + y F[dS/dExy]) / n.
// A masked pixel (target w 1) gets no gradient (its image is the target's to the loss).
#extension GL_GOOGLE_include_directive : require
#include "loss_common.glsl"

layout(push_constant) uniform LossGradBlock { LossGradPush p; };

layout(std430, binding = SSIM_GRAD_FILTERED) readonly buffer FilteredBuf { vec4 filtered[]; };
layout(std430, binding = SSIM_GRAD_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = SSIM_GRAD_TARGET) readonly buffer TargetBuf { vec4 target[]; };
layout(std430, binding = SSIM_GRAD_GRAD) writeonly buffer GradBuf { vec4 grad[]; };

void main() {
    uint i = pixel_index();
    if (i >= p.size.x * p.size.y) return;
    if (target[i].w != 0.0) {
        grad[i] = vec4(0.0);
        return;
    }
    vec3 x = image[i].rgb;
    vec3 y = target[i].rgb;
    precise vec3 ds = filtered[3u * i + 0u].rgb + 2.0 * x * filtered[3u * i + 1u].rgb
        + y * filtered[3u * i + 2u].rgb;
    grad[i] = vec4(p.scale.x * sign(x - y) - p.scale.y * ds, 0.0);
}
