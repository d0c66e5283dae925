//! The kernel of the additive Gaussian field `fit` optimises and the field renders draw
//! (`fit::model`, `cpu::field`): its support, its value and derivative, and the rotation
//! of a Gaussian's quaternion.

use super::{ActivatedScene, SplatKernel};
use crate::core::frame::Frame;

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
    // The columns of the transpose are the rows.
    crate::core::quat::quat_to_mat3(q)
        .transpose()
        .to_cols_array_2d()
}

// What the field renders of both renderers share (the CPU reference's `cpu::field` and
// the device's `render::field`): the modes, the Gaussians as they read them, the kernel
// in f64 and the frame of channels.

pub use crate::core::rules::MAX_FIELD_SAMPLES;

/// What a field render shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FieldMode {
    /// The field on the plane through `point` with normal `normal`.
    Slice {
        /// A point of the plane.
        point: [f32; 3],
        /// Its normal (any length but 0).
        normal: [f32; 3],
    },
    /// The line integral of the field along each ray.
    Integral,
    /// The maximum of the field along each ray, over `samples` points.
    Max {
        /// Points along the chord (1..=[`MAX_FIELD_SAMPLES`]).
        samples: u32,
    },
}

impl FieldMode {
    /// The number the device selects the mode with (`FIELD_MODE`).
    pub fn shader_id(&self) -> u32 {
        match self {
            FieldMode::Slice { .. } => 0,
            FieldMode::Integral => 1,
            FieldMode::Max { .. } => 2,
        }
    }
}

/// `d2` where `kernel`'s field support ends ([`cutoff`]).
pub fn field_cutoff(kernel: SplatKernel) -> f64 {
    f64::from(cutoff(kernel))
}

/// The kernel's value at `d2` (0 beyond the cutoff).
pub fn field_kernel(kernel: SplatKernel, d2: f64) -> f64 {
    // NaN (and anything past the cutoff) is outside the support.
    if d2.is_nan() || d2 > field_cutoff(kernel) {
        return 0.0;
    }
    match kernel {
        SplatKernel::Gaussian => (-0.5 * d2).exp(),
        SplatKernel::Power => (1.0 - d2 / 9.0).max(0.0),
    }
}

/// The Gaussians as the field renders read them: centre, inverse covariance, the radius of
/// the bounding sphere of the support, and `o_i feat_i`.
#[derive(Clone, Debug)]
pub struct FieldGaussians {
    /// Channels.
    pub k: usize,
    /// The falloff.
    pub kernel: SplatKernel,
    /// Centres.
    pub means: Vec<[f64; 3]>,
    /// `A = R S^-2 R^T`: xx, xy, xz, yy, yz, zz.
    pub inv_cov: Vec<[f64; 6]>,
    /// `sqrt(cutoff) * max scale`: the support lies inside this sphere.
    pub radius: Vec<f64>,
    /// `o_i feat_i`, `k` per Gaussian.
    pub weights: Vec<f64>,
    /// The union of the support boxes, `[min xyz, max xyz]` (empty: min > max).
    pub bounds: [f64; 6],
}

impl FieldGaussians {
    /// The field of `scene` (which must carry feature channels) with `kernel`.
    pub fn new(scene: &ActivatedScene, kernel: SplatKernel) -> FieldGaussians {
        let k = scene.feature_count;
        let n = scene.len();
        let reach = field_cutoff(kernel).sqrt();
        let mut g = FieldGaussians {
            k,
            kernel,
            means: Vec::with_capacity(n),
            inv_cov: Vec::with_capacity(n),
            radius: Vec::with_capacity(n),
            weights: Vec::with_capacity(n * k),
            bounds: [
                f64::INFINITY,
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ],
        };
        for i in 0..n {
            let mean = scene.positions[i].map(f64::from);
            let s = scene.scales[i].map(f64::from);
            let q = scene.rotations[i];
            let r = rotation(q).map(|row| row.map(f64::from));
            let inv_s2 = s.map(|v| 1.0 / (v * v));
            let a = |x: usize, y: usize| (0..3).map(|j| r[x][j] * inv_s2[j] * r[y][j]).sum();
            g.inv_cov
                .push([a(0, 0), a(0, 1), a(0, 2), a(1, 1), a(1, 2), a(2, 2)]);
            // The support box: half-extent along axis x is reach * sqrt(Sigma_xx).
            for ax in 0..3 {
                let var: f64 = (0..3).map(|j| (r[ax][j] * s[j]).powi(2)).sum();
                let h = reach * var.sqrt();
                g.bounds[ax] = g.bounds[ax].min(mean[ax] - h);
                g.bounds[ax + 3] = g.bounds[ax + 3].max(mean[ax] + h);
            }
            g.radius.push(reach * s[0].max(s[1]).max(s[2]));
            g.means.push(mean);
            let o = f64::from(scene.opacities[i]);
            g.weights.extend(
                scene.features[i * k..(i + 1) * k]
                    .iter()
                    .map(|&f| o * f64::from(f)),
            );
        }
        g
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True without Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// `v^T A_i w`.
    fn form(&self, i: usize, v: [f64; 3], w: [f64; 3]) -> f64 {
        let [xx, xy, xz, yy, yz, zz] = self.inv_cov[i];
        v[0] * (xx * w[0] + xy * w[1] + xz * w[2])
            + v[1] * (xy * w[0] + yy * w[1] + yz * w[2])
            + v[2] * (xz * w[0] + yz * w[1] + zz * w[2])
    }

    /// The field at `x`: `k` channels (the sum over every Gaussian).
    pub fn evaluate(&self, x: [f64; 3]) -> Vec<f64> {
        let mut out = vec![0.0; self.k];
        for i in 0..self.len() {
            let e = sub(x, self.means[i]);
            let g = field_kernel(self.kernel, self.form(i, e, e));
            if g > 0.0 {
                for (o, w) in out.iter_mut().zip(&self.weights[i * self.k..]) {
                    *o += g * w;
                }
            }
        }
        out
    }

    /// Gaussian `i` along the unit ray `o + t d`: `(a, t0, m)` with
    /// `d2(t) = m + a (t - t0)^2`; `m` from the closest point itself, not `c - b^2 / a`,
    /// which cancels far from the Gaussian.
    pub fn along_ray(&self, i: usize, o: [f64; 3], d: [f64; 3]) -> (f64, f64, f64) {
        let u = sub(o, self.means[i]);
        let a = self.form(i, d, d).max(1e-300);
        let t0 = -self.form(i, d, u) / a;
        let w = [u[0] + t0 * d[0], u[1] + t0 * d[1], u[2] + t0 * d[2]];
        (a, t0, self.form(i, w, w))
    }
}

/// A frame of `k` field channels per pixel: alpha 1 where channel 0 is a number, 0 where
/// it is NaN (empty).
pub fn frame_from_channels(w: u32, h: u32, k: usize, features: Vec<f32>) -> Frame {
    let mut frame = Frame::background(w, h, [0.0; 3]);
    for (a, px) in frame.alpha.iter_mut().zip(features.chunks_exact(k.max(1))) {
        *a = if px[0].is_nan() { 0.0 } else { 1.0 };
    }
    frame.feature_count = k;
    frame.features = features;
    frame
}

/// `a - b`.
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
