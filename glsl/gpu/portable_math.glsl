// Arithmetic that gives the same bits on every device (docs/reproducibility.md): what the
// Vulkan specification only bounds in ulps (exp), written with the operations it rounds
// correctly (+, -, x, `precise`, so no compiler fuses them) and exact ones (floor,
// exponent bits). The twin of core::math::exp, operation for operation; its constants are
// the same bits (checked there), its accuracy is measured there (within 2 ulp).
#ifndef PORTABLE_MATH_GLSL
#define PORTABLE_MATH_GLSL

// e^x: x = n ln 2 + r with n = floor(x log2 e + 1/2) (ln 2 in two parts), e^r by its Taylor
// polynomial of degree 7, times 2^n from the exponent bits. 0 below -87 (the results stay
// normal floats, so denormal handling changes nothing), +inf above 88.
float portable_exp(float x) {
    precise float t = x * 1.44269504 + 0.5;
    float n = floor(t);
    precise float r = (x - n * 0.693145752) - n * 1.42860677e-6;
    precise float p = ((((((0.000198412701 * r + 0.00138888892) * r + 0.00833333377) * r
                        + 0.0416666679) * r + 0.166666672) * r + 0.5) * r + 1.0) * r + 1.0;
    precise float e = p * uintBitsToFloat(uint(int(n) + 127) << 23u);
    return x < -87.0 ? 0.0 : (x > 88.0 ? uintBitsToFloat(0x7F800000u) : e);
}

#endif
