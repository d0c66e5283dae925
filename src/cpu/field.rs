//! Renders of the fitted field itself (`render --mode field-slice | field-integral |
//! field-max`): the reference, in f64, one pixel at a time over every Gaussian.
//!
//! The field is the one `fit` models ([`crate::fields::fit::model`]): `f(x) = sum_i o_i feat_i
//! G_i(x)`, `G_i` the unnormalised Gaussian `exp(-d2 / 2)` truncated at `d2 <= 16` or the
//! power kernel `max(0, 1 - d2 / 9)`, `d2 = (x - mu_i)^T A_i (x - mu_i)` with
//! `A_i = R_i S_i^-2 R_i^T` (the inverse of the renderers' covariance). It is a plain sum,
//! not alpha-blended. Pixel `(px, py)` looks along the unit ray `o + t d`, `t >= 0`, `o` the
//! camera centre and `d` through the image point `(px + 0.5, py + 0.5)` (the projection of
//! [`crate::cpu::preprocess`], which puts pixel `(i, j)` at `(i, j)` after its `- 0.5`).
//!
//! - **Slice**: `f` where the ray meets the plane (a point and a normal); NaN ("empty")
//!   where it does not (behind the camera or parallel).
//! - **Integral**: `int_0^inf f(o + t d) dt` in world length units, in closed form per
//!   Gaussian: along the ray `d2(t) = m + a (t - t0)^2` (`a = d^T A d`, `t0` the closest
//!   approach, `m` its `d2`), so the truncated Gaussian integrates to
//!   `exp(-m/2) sqrt(pi / 2a) [erf(sqrt(a/2) (hi - t0)) - erf(sqrt(a/2) (lo - t0))]` over
//!   the part `[lo, hi]` of `|t - t0| <= sqrt((16 - m) / a)` with `t >= 0`, and the power
//!   kernel to `(1 - m/9) s - a s^3 / 27` between the same ends (`s = t - t0`). `erf` is
//!   Abramowitz and Stegun 7.1.26 (absolute error below 1.5e-7), here and on the device.
//! - **Maximum**: not closed form for a sum, so sampled: `samples` points at the centres of
//!   equal segments of the ray's chord through the field's box (the union of the
//!   Gaussians' support boxes, [`FieldGaussians::bounds`]), `t >= 0`; each channel's
//!   maximum over them; NaN where the ray misses the box. The points are the same on the
//!   device; the error against the true maximum falls with the segment length (the test
//!   `field_renders::max_converges_with_samples` measures it).

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::SplatKernel;
use rayon::prelude::*;

pub use crate::core::model::field::{
    field_cutoff, field_kernel, frame_from_channels, FieldGaussians, FieldMode, MAX_FIELD_SAMPLES,
};

/// `erf(x)`, Abramowitz and Stegun 7.1.26 (absolute error below 1.5e-7), the device's.
pub fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_429 * t - 1.453_152_027) * t) + 1.421_413_741) * t - 0.284_496_736) * t
            + 0.254_829_592)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

/// `int_lo^hi` of the kernel at `m + a (t - t0)^2` over `t` (already clipped to the
/// support).
pub fn kernel_integral(kernel: SplatKernel, a: f64, m: f64, lo: f64, hi: f64) -> f64 {
    match kernel {
        SplatKernel::Gaussian => {
            let c = (0.5 * a).sqrt();
            (-0.5 * m).exp()
                * (std::f64::consts::PI / (2.0 * a)).sqrt()
                * (erf(c * hi) - erf(c * lo))
        }
        SplatKernel::Power => (1.0 - m / 9.0) * (hi - lo) - a * (hi.powi(3) - lo.powi(3)) / 27.0,
    }
}

/// The unit ray of pixel `(px, py)`: the camera centre and the direction.
pub fn pixel_ray(cam: &Camera, px: u32, py: u32) -> ([f64; 3], [f64; 3]) {
    let dc = [
        (f64::from(px) + 0.5 - f64::from(cam.cx)) / f64::from(cam.fx),
        (f64::from(py) + 0.5 - f64::from(cam.cy)) / f64::from(cam.fy),
        1.0,
    ];
    // World direction R^T dc (R is world-to-camera).
    let r = cam.rotation.to_cols_array_2d(); // r[col][row]
    let mut d = [0.0; 3];
    for (j, dj) in d.iter_mut().enumerate() {
        *dj = (0..3).map(|i| f64::from(r[j][i]) * dc[i]).sum();
    }
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let o = cam.position();
    (
        [f64::from(o.x), f64::from(o.y), f64::from(o.z)],
        d.map(|v| v / len),
    )
}

/// Where the ray meets the plane (`t > 0`), if it does.
pub fn slice_hit(o: [f64; 3], d: [f64; 3], point: [f32; 3], normal: [f32; 3]) -> Option<f64> {
    let n = normal.map(f64::from);
    let den = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
    let num = (0..3)
        .map(|a| n[a] * (f64::from(point[a]) - o[a]))
        .sum::<f64>();
    let t = num / den;
    (den != 0.0 && t.is_finite() && t > 0.0).then_some(t)
}

/// A ray direction component kept away from 0 (so `1 / d` is finite and a ray along a
/// box face gives no `0 * inf`), the device's rule too.
pub fn nonzero(v: f64) -> f64 {
    if v.abs() < 1e-20 {
        if v.is_sign_negative() {
            -1e-20
        } else {
            1e-20
        }
    } else {
        v
    }
}

/// The ray's chord `[t_in, t_out]` (`t >= 0`) through `bounds`, if it meets it.
pub fn chord(o: [f64; 3], d: [f64; 3], bounds: [f64; 6]) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (0f64, f64::INFINITY);
    for a in 0..3 {
        let inv = 1.0 / nonzero(d[a]);
        let t1 = (bounds[a] - o[a]) * inv;
        let t2 = (bounds[a + 3] - o[a]) * inv;
        lo = lo.max(t1.min(t2));
        hi = hi.min(t1.max(t2));
    }
    (lo < hi).then_some((lo, hi))
}

/// The field along one ray under `mode`: `k` values (NaN where empty).
pub fn field_along_ray(g: &FieldGaussians, mode: &FieldMode, o: [f64; 3], d: [f64; 3]) -> Vec<f64> {
    let k = g.k;
    let cutoff = field_cutoff(g.kernel);
    match *mode {
        FieldMode::Slice { point, normal } => match slice_hit(o, d, point, normal) {
            Some(t) => g.evaluate([o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]),
            None => vec![f64::NAN; k],
        },
        FieldMode::Integral => {
            let mut out = vec![0.0; k];
            for i in 0..g.len() {
                let (a, t0, m) = g.along_ray(i, o, d);
                if m >= cutoff {
                    continue;
                }
                let half = ((cutoff - m) / a).sqrt();
                let (lo, hi) = ((t0 - half).max(0.0), t0 + half);
                if hi <= lo {
                    continue;
                }
                let v = kernel_integral(g.kernel, a, m, lo - t0, hi - t0);
                for (c, w) in out.iter_mut().zip(&g.weights[i * k..]) {
                    *c += v * w;
                }
            }
            out
        }
        FieldMode::Max { samples } => {
            let Some((t_in, t_out)) = chord(o, d, g.bounds) else {
                return vec![f64::NAN; k];
            };
            let s = samples.max(1) as usize;
            let step = (t_out - t_in) / s as f64;
            let mut acc = vec![0.0; s * k];
            for i in 0..g.len() {
                let (a, t0, m) = g.along_ray(i, o, d);
                if m >= cutoff {
                    continue;
                }
                let half = ((cutoff - m) / a).sqrt();
                let (first, last) = sample_span(t0 - half, t0 + half, t_in, step, s);
                for j in first..last {
                    let t = t_in + (j as f64 + 0.5) * step;
                    let v = field_kernel(g.kernel, m + a * (t - t0) * (t - t0));
                    if v > 0.0 {
                        for (c, w) in acc[j * k..(j + 1) * k].iter_mut().zip(&g.weights[i * k..]) {
                            *c += v * w;
                        }
                    }
                }
            }
            (0..k)
                .map(|c| {
                    (0..s)
                        .map(|j| acc[j * k + c])
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect()
        }
    }
}

/// The samples `j` (of `s`, at `t_in + (j + 0.5) step`) that may lie in `[lo, hi]`: a
/// range widened by one on each side, so rounding never drops one (the kernel test then
/// decides).
pub fn sample_span(lo: f64, hi: f64, t_in: f64, step: f64, s: usize) -> (usize, usize) {
    let first = ((lo - t_in) / step - 0.5).floor() - 1.0;
    let last = ((hi - t_in) / step - 0.5).ceil() + 2.0;
    let clamp = |v: f64| v.clamp(0.0, s as f64) as usize;
    (clamp(first), clamp(last))
}

/// Renders the field of `g` from `cam` under `mode`: the frame's features hold the `k`
/// channels (NaN where empty), alpha is 1 where there is a value and 0 where empty, depth 0.
pub fn render_field(g: &FieldGaussians, cam: &Camera, mode: &FieldMode) -> Frame {
    let (w, h) = (cam.width, cam.height);
    let k = g.k;
    let rows: Vec<Vec<f32>> = (0..h)
        .into_par_iter()
        .map(|py| {
            let mut row = Vec::with_capacity(w as usize * k);
            for px in 0..w {
                let (o, d) = pixel_ray(cam, px, py);
                row.extend(field_along_ray(g, mode, o, d).iter().map(|&v| v as f32));
            }
            row
        })
        .collect();
    frame_from_channels(w, h, k, rows.concat())
}

/// Appends two channels to a field frame whose channels `i` and `q` are the real and
/// imaginary parts of one complex field: its magnitude `|I + iQ|` and phase
/// `atan2(Q, I)` (radians), channels K and K + 1 (NaN stays NaN).
pub fn append_magnitude_phase(frame: &mut Frame, i: usize, q: usize) {
    let k = frame.feature_count;
    let mut out = Vec::with_capacity(frame.features.len() / k.max(1) * (k + 2));
    for px in frame.features.chunks_exact(k) {
        out.extend_from_slice(px);
        out.push(px[i].hypot(px[q]));
        out.push(px[q].atan2(px[i]));
    }
    frame.features = out;
    frame.feature_count = k + 2;
}
