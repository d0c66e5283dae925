// Spherical harmonics and the rotation matrix, shared by preprocess.comp (forward) and
// preprocess_bwd.comp (backward). The includer declares `sh_texels`, the SH coefficients
// as RGBA32F texels (coefficient-major, colour channel innermost, each Gaussian's floats
// padded to whole texels: the host's sh_texel_stride).
#ifndef SH_COMMON_GLSL
#define SH_COMMON_GLSL

const float SH_C0 = 0.28209479177387814;
const float SH_C1 = 0.4886025119029199;
const float SH_C2[5] = float[](1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                               -1.0925484305920792, 0.5462742152960396);
const float SH_C3[7] = float[](-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                               0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                               -0.5900435899266435);

// Float `idx` of the SH texels. `base` is a multiple of 4 and `k` a constant in every call
// below, so after inlining the component index is a constant.
float sh_float(uint idx) {
    return texelFetch(sh_texels, int(idx >> 2u))[idx & 3u];
}

vec3 coeff(uint base, uint k) {
    return vec3(sh_float(base + 3u * k), sh_float(base + 3u * k + 1u), sh_float(base + 3u * k + 2u));
}

vec3 eval_sh(uint base, uint degree, vec3 dir) {
    // precise: the terms in the order written, as the CPU reference adds them.
    precise vec3 result = SH_C0 * coeff(base, 0u);
    if (degree > 0u) {
        float x = dir.x, y = dir.y, z = dir.z;
        result = result - SH_C1 * y * coeff(base, 1u) + SH_C1 * z * coeff(base, 2u) - SH_C1 * x * coeff(base, 3u);
        if (degree > 1u) {
            precise float xx = x * x, yy = y * y, zz = z * z;
            precise float xy = x * y, yz = y * z, xz = x * z;
            result = result + SH_C2[0] * xy * coeff(base, 4u) + SH_C2[1] * yz * coeff(base, 5u)
                + SH_C2[2] * (2.0 * zz - xx - yy) * coeff(base, 6u) + SH_C2[3] * xz * coeff(base, 7u)
                + SH_C2[4] * (xx - yy) * coeff(base, 8u);
            if (degree > 2u) {
                result = result + SH_C3[0] * y * (3.0 * xx - yy) * coeff(base, 9u)
                    + SH_C3[1] * xy * z * coeff(base, 10u)
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * coeff(base, 11u)
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * coeff(base, 12u)
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * coeff(base, 13u)
                    + SH_C3[5] * z * (xx - yy) * coeff(base, 14u)
                    + SH_C3[6] * x * (xx - 3.0 * yy) * coeff(base, 15u);
            }
        }
    }
    return max(result + 0.5, vec3(0.0));
}

// M v and A B with the columns added in order, 0, 1 then 2, as the CPU reference (glam)
// adds them: GLSL's own products add them in an order the compiler picks (SPIR-V to NIR
// adds the last column first), which changes the last bits.
vec3 mat_vec(mat3 m, vec3 v) {
    precise vec3 r = m[0] * v.x + m[1] * v.y + m[2] * v.z;
    return r;
}

mat3 mat_mat(mat3 a, mat3 b) {
    return mat3(mat_vec(a, b[0]), mat_vec(a, b[1]), mat_vec(a, b[2]));
}

// v / |v| as the CPU reference (glam's normalize) computes it: v times the reciprocal of
// the square root, each correctly rounded. (GLSL's normalize may take an approximate
// reciprocal square root: llvmpipe's differs in the last bits.)
vec3 unit(vec3 v) {
    precise float len = sqrt(dot(v, v));
    precise vec3 r = v * (1.0 / len);
    return r;
}

// Rotation matrix of a unit quaternion (w, x, y, z), as columns.
mat3 quat_to_mat3(vec4 q) {
    float r = q.x, x = q.y, y = q.z, z = q.w;
    return mat3(
        vec3(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + r * z), 2.0 * (x * z - r * y)),
        vec3(2.0 * (x * y - r * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + r * x)),
        vec3(2.0 * (x * z + r * y), 2.0 * (y * z - r * x), 1.0 - 2.0 * (x * x + y * y)));
}

#endif
