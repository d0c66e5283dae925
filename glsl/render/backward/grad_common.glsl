// Fixed-point accumulation of gradients, shared by grad_accumulate.comp (which adds) and
// preprocess_bwd.comp (which reads the sums back).
//
// A Gaussian's gradient is the sum of its pairs' partial sums (blend_bwd.comp). Float
// atomics would add them in whatever order the hardware runs the pairs, and float
// addition is not associative, so the result would change from run to run. Instead every
// partial is converted to a 64-bit two's-complement integer with a power-of-two scale and
// added with integer atomics, which are associative: the sum is exact and independent of
// the order. The scale of field f is 2^s with s = 62 - e - bits, where 2^e bounds the
// largest |partial| of the field (maxima[f]) and 2^bits the number of pairs a Gaussian can
// have (the bins of the frame): no sum can overflow, and the resolution is 2^-(62 - bits)
// of the largest partial (2^-48 for a 1280x720 frame of 8x8 bins), far below f32's 2^-24.
// The 64-bit integers are (lo, hi) pairs of u32: added with one 64-bit atomic where the
// device has them (grad_accumulate.comp's INT64_ATOMICS), else with 32-bit atomics and an
// explicit carry, so no 64-bit atomics are needed.
#ifndef GRAD_COMMON_GLSL
#define GRAD_COMMON_GLSL

// Scale exponent of a field whose largest |partial| has the float bits `max_bits`.
int grad_shift(uint max_bits, uint bits) {
    int e;
    frexp(uintBitsToFloat(max_bits), e);  // |partial| < 2^e
    return clamp(62 - int(bits) - e, -200, 250);
}

// x * 2^s without forming 2^s itself (which may be out of range when x is tiny).
float scale_pow2(float x, int s) {
    int h = s / 2;
    return ldexp(ldexp(x, h), s - h);
}

// floor(x) of an integer-valued float |x| < 2^63 as a two's-complement (lo, hi) pair.
uvec2 to_fixed(float x) {
    x = floor(x);
    if (abs(x) < 2147483648.0) {
        int v = int(x);
        return uvec2(uint(v), v < 0 ? 0xFFFFFFFFu : 0u);
    }
    // |x| >= 2^31: x is a multiple of 2^8, so x mod 2^32 has at most 24 significant bits
    // and both parts are exact.
    float h = floor(x * (1.0 / 4294967296.0));
    float l = x - h * 4294967296.0;
    return uvec2(uint(l), uint(int(h)));
}

// The float nearest the (lo, hi) pair, times 2^-s.
float from_fixed(uvec2 v, int s) {
    int hi = int(v.y);
    float x;
    if ((hi == 0 && v.x < 0x80000000u) || (hi == -1 && v.x >= 0x80000000u)) {
        x = float(int(v.x));  // fits 32 bits: exact conversion, no cancellation
    } else {
        x = float(hi) * 4294967296.0 + float(v.x);
    }
    return scale_pow2(x, -s);
}
#endif
