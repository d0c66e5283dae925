#version 460
// Training loss: per pixel and channel the SSIM value from the local moments and its
// derivatives with respect to them (metrics::ssim_with_gradient's rules), and the pixel's
// sums over R, G, B of |x - y|, of SSIM and of (x - y)^2, which loss_reduce.comp adds up.
// A masked pixel (target w 1) adds nothing: no sums, no derivative maps, and its image is
// the target's.
#extension GL_GOOGLE_include_directive : require
#include "loss_common.glsl"

layout(push_constant) uniform SizeBlock { SizePush p; };

// E[x], E[y], E[x^2], E[y^2], E[xy] per pixel (vec4s, rgb).
layout(std430, binding = SSIM_MAP_MOMENTS) readonly buffer MomentBuf { vec4 moments[]; };
layout(std430, binding = SSIM_MAP_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = SSIM_MAP_TARGET) readonly buffer TargetBuf { vec4 target[]; };
// dS/dE[x], dS/dE[x^2], dS/dE[xy] per pixel (vec4s, rgb).
layout(std430, binding = SSIM_MAP_MAPS) writeonly buffer MapBuf { vec4 maps[]; };
// Per pixel: sum of |x - y| and sum of SSIM over the channels.
layout(std430, binding = SSIM_MAP_SUMS) writeonly buffer SumBuf { vec4 sums[]; };

const float C1 = 0.01 * 0.01;
const float C2 = 0.03 * 0.03;

void main() {
    uint i = pixel_index();
    if (i >= p.size.x * p.size.y) return;
    vec3 mx = moments[5u * i + 0u].rgb;
    vec3 my = moments[5u * i + 1u].rgb;
    vec3 exx = moments[5u * i + 2u].rgb;
    vec3 eyy = moments[5u * i + 3u].rgb;
    vec3 exy = moments[5u * i + 4u].rgb;
    precise vec3 a1 = 2.0 * mx * my + C1;
    precise vec3 a2 = 2.0 * (exy - mx * my) + C2;
    precise vec3 b1 = mx * mx + my * my + C1;
    precise vec3 b2 = (exx - mx * mx) + (eyy - my * my) + C2;
    precise vec3 d = b1 * b2;
    precise vec3 s = a1 * a2 / d;
    if (target[i].w != 0.0) {
        maps[3u * i + 0u] = vec4(0.0);
        maps[3u * i + 1u] = vec4(0.0);
        maps[3u * i + 2u] = vec4(0.0);
        sums[i] = vec4(0.0);
        return;
    }
    maps[3u * i + 0u] = vec4(2.0 * my * a2 / d - 2.0 * mx * s / b1 + 2.0 * mx * s / b2 - 2.0 * my * a1 / d, 0.0);
    maps[3u * i + 1u] = vec4(-s / b2, 0.0);
    maps[3u * i + 2u] = vec4(2.0 * a1 / d, 0.0);
    vec3 diff = image[i].rgb - target[i].rgb;
    vec3 l1 = abs(diff);
    precise vec3 sq = diff * diff;
    sums[i] = vec4(l1.r + l1.g + l1.b, s.r + s.g + s.b, sq.r + sq.g + sq.b, 0.0);
}
