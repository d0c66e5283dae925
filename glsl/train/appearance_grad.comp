#version 460
#extension GL_GOOGLE_include_directive : require
// Training appearance (`--appearance affine`): the backward of c' = A c + b. With g the
// loss's gradient with respect to c' (in GRAD), the pixel's gradient becomes A^T g (in
// place, for the backward pass) and the transform's 12 gradients are sums over pixels:
// dL/dA[r][j] = g[r] c[j], dL/db[r] = g[r], that is row r of [A | b] gets g[r] (c, 1).
// Workgroup w sums pixels [w * APPEARANCE_SPAN, (w + 1) * APPEARANCE_SPAN): invocation t
// its APPEARANCE_ITEMS pixels t, t + APPEARANCE_WG, ..., then a fixed-shape tree in shared
// memory (no subgroup operations, no atomics), so the partial sums are the same bits at
// every subgroup size; the host adds the workgroups' partials in f64, in order.

layout(local_size_x = APPEARANCE_WG) in;

#include "interface.glsl"

layout(push_constant) uniform AffineBlock { ImageRowsPush p; };

layout(std430, binding = APPEARANCE_GRAD_IMAGE) readonly buffer ImageBuf { vec4 image[]; };
layout(std430, binding = APPEARANCE_GRAD_GRAD) buffer GradBuf { vec4 grad[]; };
layout(std430, binding = APPEARANCE_GRAD_PARTIALS) writeonly buffer PartialBuf { vec4 partials[]; };

shared vec4 rows[3][APPEARANCE_WG];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint base = gl_WorkGroupID.x * APPEARANCE_SPAN;
    uint n = p.size.x * p.size.y;
    precise vec4 acc0 = vec4(0.0);
    precise vec4 acc1 = vec4(0.0);
    precise vec4 acc2 = vec4(0.0);
    for (uint k = 0u; k < APPEARANCE_ITEMS; k++) {
        uint i = base + k * APPEARANCE_WG + t;
        if (i < n) {
            vec4 gv = grad[i];
            vec3 g = gv.rgb;
            vec4 c1 = vec4(image[i].rgb, 1.0);
            acc0 += g.r * c1;
            acc1 += g.g * c1;
            acc2 += g.b * c1;
            // A^T g: column j of A dotted with g.
            precise vec3 back = vec3(
                p.rows[0].x * g.r + p.rows[1].x * g.g + p.rows[2].x * g.b,
                p.rows[0].y * g.r + p.rows[1].y * g.g + p.rows[2].y * g.b,
                p.rows[0].z * g.r + p.rows[1].z * g.g + p.rows[2].z * g.b);
            grad[i] = vec4(back, gv.w);
        }
    }
    rows[0][t] = acc0;
    rows[1][t] = acc1;
    rows[2][t] = acc2;
    barrier();
    for (uint half_ = APPEARANCE_WG / 2u; half_ > 0u; half_ >>= 1) {
        if (t < half_) {
            rows[0][t] = rows[0][t] + rows[0][t + half_];
            rows[1][t] = rows[1][t] + rows[1][t + half_];
            rows[2][t] = rows[2][t] + rows[2][t + half_];
        }
        barrier();
    }
    if (t < 3u) partials[3u * gl_WorkGroupID.x + t] = rows[t][0];
}
