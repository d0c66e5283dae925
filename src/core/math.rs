//! Arithmetic that gives the same bits on every device: functions the Vulkan
//! specification only bounds in ulps (exp among them), written with the operations it
//! does round correctly (+, -, x) and exact ones (`floor`, exponent bits), in the same
//! order as their GLSL twins (`glsl/gpu/portable_math.glsl`, whose operations are
//! `precise` so that no compiler fuses them). The CPU reference uses them always; the
//! shaders in the reproducible mode ([`crate::core::model::RenderOptions::reproducible`]).
//! docs/reproducibility.md.

/// log2(e), rounded to f32 (bits 0x3FB8AA3B; the test checks every constant's bits).
const LOG2E: f32 = std::f32::consts::LOG2_E;
/// The high part of ln 2: 16 significant bits, so `n * LN2_HI` is exact for every
/// |n| < 2^8.
const LN2_HI: f32 = 0.693_145_75;
/// ln 2 - LN2_HI, rounded.
const LN2_LO: f32 = 1.428_606_8e-6;
/// 1/k! for k = 3..7, rounded to f32.
const C3: f32 = 0.166_666_67;
const C4: f32 = 0.041_666_668;
const C5: f32 = 0.008_333_334;
const C6: f32 = 0.001_388_888_9;
const C7: f32 = 0.000_198_412_7;
/// Below this [`exp`] returns 0: e^-87 = 1.6e-38 is the smallest result it computes, a
/// normal float, so no device's handling of denormals can change a bit.
pub const EXP_MIN_ARG: f32 = -87.0;
/// Above this [`exp`] returns +inf (e^88 = 1.7e38 is its largest finite result).
pub const EXP_MAX_ARG: f32 = 88.0;

/// e^x from +, -, x, `floor` and exponent bits, the same operations in the same order as
/// `portable_exp` in `glsl/gpu/portable_math.glsl`: x = n ln 2 + r with n the floor of
/// x log2(e) + 1/2 (ln 2 in two parts, Cody and Waite), e^r by its Taylor polynomial of
/// degree 7 (|r| <= 0.35), times 2^n built from the exponent bits. Within 2 ulp of the
/// exact value on [-87, 88] (the test measures 1.18 ulp at most); 0 below -87, +inf above
/// 88, NaN for NaN.
pub fn exp(x: f32) -> f32 {
    if x.is_nan() {
        return x;
    }
    if x < EXP_MIN_ARG {
        return 0.0;
    }
    if x > EXP_MAX_ARG {
        return f32::INFINITY;
    }
    let n = (x * LOG2E + 0.5).floor();
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = ((((((C7 * r + C6) * r + C5) * r + C4) * r + C3) * r + 0.5) * r + 1.0) * r + 1.0;
    // n is in [-126, 127] here: 2^n is a normal float.
    let scale = f32::from_bits(((n as i32 + 127) as u32) << 23);
    p * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The GLSL twin's literals, in the order `portable_exp` uses them, are these
    /// constants' bits (glslc and Rust both round decimals correctly).
    #[test]
    fn the_glsl_twin_uses_the_same_constants() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/glsl/gpu/portable_math.glsl");
        let src = std::fs::read_to_string(path).unwrap();
        let body = &src[src.find("float portable_exp(").unwrap()..];
        let body = &body[..body.find("return").unwrap()];
        let literals: Vec<f32> = body
            .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-'))
            .filter(|t| t.contains('.'))
            .map(|t| t.parse().unwrap())
            .collect();
        let want = [
            LOG2E, 0.5, LN2_HI, LN2_LO, C7, C6, C5, C4, C3, 0.5, 1.0, 1.0,
        ];
        assert_eq!(
            literals.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            want.map(f32::to_bits),
            "{literals:?}"
        );
        assert_eq!(LN2_HI.to_bits() & 0xFF, 0, "n * LN2_HI must be exact");
        let bits = [LOG2E, LN2_HI, LN2_LO, C3, C4, C5, C6, C7].map(f32::to_bits);
        assert_eq!(
            bits,
            [
                0x3FB8AA3B, 0x3F317200, 0x35BFBE8E, 0x3E2AAAAB, 0x3D2AAAAB, 0x3C088889, 0x3AB60B61,
                0x39500D01
            ]
        );
    }

    /// Distance in ulps (of the f32 grid at the exact value) between `got` and `exact`.
    fn ulps(got: f32, exact: f64) -> f64 {
        let e = exact as f32;
        let ulp = f64::from(f32::from_bits(e.to_bits() + 1)) - f64::from(e);
        (f64::from(got) - exact).abs() / ulp
    }

    /// Every 997th f32 in [-87, 88] (about 2 million values): within 2 ulp of f64's exp, and
    /// the edges as documented.
    #[test]
    fn exp_is_within_two_ulp_of_f64() {
        let mut worst = (0.0f64, 0.0f32);
        let mut check = |x: f32| {
            let u = ulps(exp(x), f64::from(x).exp());
            if u > worst.0 {
                worst = (u, x);
            }
        };
        // Negative half: from -0 down to -87 (bits increase with magnitude).
        let (neg0, neg_end) = ((-0.0f32).to_bits(), EXP_MIN_ARG.to_bits());
        (neg0..=neg_end)
            .step_by(997)
            .for_each(|b| check(f32::from_bits(b)));
        (0u32..=EXP_MAX_ARG.to_bits())
            .step_by(997)
            .for_each(|b| check(f32::from_bits(b)));
        [EXP_MIN_ARG, EXP_MAX_ARG, -0.5, -5.5, 1.0]
            .into_iter()
            .for_each(&mut check);
        eprintln!("worst: exp({}) is {:.3} ulp off", worst.1, worst.0);
        assert!(worst.0 <= 2.0, "exp({}) is {} ulp off", worst.1, worst.0);
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-87.5), 0.0);
        assert_eq!(exp(-f32::INFINITY), 0.0);
        assert_eq!(exp(88.5), f32::INFINITY);
        assert!(exp(f32::NAN).is_nan());
    }
}
