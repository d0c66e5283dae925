//! The kernel of the additive Gaussian field `fit` optimises and the field renders draw
//! (`fit::model`, `cpu::field`): its support, its value and derivative, and the rotation
//! of a Gaussian's quaternion.

use super::SplatKernel;

/// `d2` beyond which the Gaussian kernel is taken as 0 (4 sigma).
pub const GAUSSIAN_CUTOFF: f32 = 16.0;
/// `d2` where the power kernel ends (3 sigma).
pub const POWER_CUTOFF: f32 = 9.0;

/// The support of `kernel`: `d2` above this contributes nothing.
pub fn cutoff(kernel: SplatKernel) -> f32 {
    match kernel {
        SplatKernel::Gaussian => GAUSSIAN_CUTOFF,
        SplatKernel::Power => POWER_CUTOFF,
    }
}

/// The kernel at `d2` (within the cutoff) and its derivative with respect to `d2`.
#[inline]
pub fn kernel_value(kernel: SplatKernel, d2: f32) -> (f32, f32) {
    match kernel {
        SplatKernel::Gaussian => {
            let g = (-0.5 * d2).exp();
            (g, -0.5 * g)
        }
        SplatKernel::Power => {
            let g = 1.0 - d2 / 9.0;
            if g > 0.0 {
                (g, -1.0 / 9.0)
            } else {
                (0.0, 0.0)
            }
        }
    }
}

/// Rotation matrix (rows) of a normalised quaternion `w, x, y, z` (the renderers'
/// `quat_to_mat3`).
pub fn rotation(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}
