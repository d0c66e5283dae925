//! Real spherical harmonics up to degree 3, evaluated exactly as the reference does.

// The constants keep the reference source's digits; they round to f32 exactly as its
// `const float` declarations do.
#![allow(clippy::excessive_precision)]

use glam::Vec3;

/// Band 0 constant.
pub const SH_C0: f32 = 0.282_094_791_773_878_14;
/// Band 1 constant.
pub const SH_C1: f32 = 0.488_602_511_902_919_9;
/// Band 2 constants.
pub const SH_C2: [f32; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Band 3 constants.
pub const SH_C3: [f32; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Colour of one Gaussian seen along unit direction `dir` (mean minus camera centre,
/// normalised): the SH sum to `degree`, plus 0.5, clamped below at 0 (not above).
/// `sh` holds the Gaussian's coefficients, channel innermost (`sh[k * 3 + c]`).
pub fn eval_sh(degree: u32, sh: &[f32], dir: Vec3) -> [f32; 3] {
    let c = |k: usize| Vec3::new(sh[k * 3], sh[k * 3 + 1], sh[k * 3 + 2]);
    let mut result = SH_C0 * c(0);
    if degree > 0 {
        let (x, y, z) = (dir.x, dir.y, dir.z);
        result = result - SH_C1 * y * c(1) + SH_C1 * z * c(2) - SH_C1 * x * c(3);
        if degree > 1 {
            let (xx, yy, zz) = (x * x, y * y, z * z);
            let (xy, yz, xz) = (x * y, y * z, x * z);
            result = result
                + SH_C2[0] * xy * c(4)
                + SH_C2[1] * yz * c(5)
                + SH_C2[2] * (2.0 * zz - xx - yy) * c(6)
                + SH_C2[3] * xz * c(7)
                + SH_C2[4] * (xx - yy) * c(8);
            if degree > 2 {
                result = result
                    + SH_C3[0] * y * (3.0 * xx - yy) * c(9)
                    + SH_C3[1] * xy * z * c(10)
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * c(11)
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * c(12)
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * c(13)
                    + SH_C3[5] * z * (xx - yy) * c(14)
                    + SH_C3[6] * x * (xx - 3.0 * yy) * c(15);
            }
        }
    }
    result += Vec3::splat(0.5);
    [result.x.max(0.0), result.y.max(0.0), result.z.max(0.0)]
}
