//! The scene model: Gaussians in the parameterisation the original 3DGS trainer stores.
//!
//! [`Scene`] keeps the values exactly as a trained INRIA PLY holds them (log scales,
//! opacity logits, unnormalised quaternions, SH coefficients), so a scene written back
//! to PLY is bit-identical. [`Scene::activated`] applies the reference activations
//! (exp, sigmoid, quaternion normalisation) once, producing the arrays the renderers
//! consume and the GPU upload copies.
//!
//! # Memory layout (structure of arrays, all `f32`, upload-ready)
//! - `positions[i]`: `[x, y, z]` world space.
//! - `log_scales[i]`: `[s0, s1, s2]` natural log of the axis scales.
//! - `rotations[i]`: `[w, x, y, z]` as stored (`rot_0..3`), not normalised.
//! - `opacity_logits[i]`: inverse-sigmoid opacity.
//! - `sh`: `sh_coeffs() * 3` floats per Gaussian, coefficient-major with the colour
//!   channel innermost: coefficient `k` of channel `c` of Gaussian `i` is
//!   `sh[i * sh_stride() + k * 3 + c]`; `k = 0` is the DC term (`f_dc_c`), and
//!   `k >= 1` is `f_rest[c * K + (k - 1)]` of the PLY with `K = sh_coeffs() - 1`.

pub mod features;
pub mod filter;
pub mod transform;

// The activated scene belongs to the splat model the renderers share; re-exported here,
// where it used to live.
pub use crate::core::model::{sh_coeffs_for_degree, ActivatedScene};

use std::path::Path;

/// A set of 3D Gaussians in the trainer's (pre-activation) parameterisation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// SH degree, 0..=3.
    pub sh_degree: u32,
    /// World-space centres.
    pub positions: Vec<[f32; 3]>,
    /// Natural logarithms of the three axis scales.
    pub log_scales: Vec<[f32; 3]>,
    /// Rotation quaternions `(w, x, y, z)`, as stored.
    pub rotations: Vec<[f32; 4]>,
    /// Opacity before the sigmoid.
    pub opacity_logits: Vec<f32>,
    /// SH coefficients, `sh_stride()` floats per Gaussian (see the module docs).
    pub sh: Vec<f32>,
    /// The file records that the scene was trained with antialiasing (the SPZ header's
    /// antialiased flag, SOG's `antialias`): it should be rendered with the opacity
    /// compensation of [`crate::core::model::RenderOptions::antialiased`]. INRIA PLY and `.splat`
    /// cannot record it.
    pub antialiased: bool,
    /// The alpha falloff the scene is made for ([`crate::core::model::SplatKernel`]), as the file
    /// records it (INRIA PLY: a `comment verisplat kernel power` header line); Gaussian when
    /// it records none. `render` uses it unless `--kernel` says otherwise.
    pub kernel: crate::core::model::SplatKernel,
    /// The rasterizer's rules the scene was trained with ([`crate::core::model::Rules`]), as the
    /// file records it (INRIA PLY: a `comment verisplat rules gsplat` header line); the
    /// original's when it records none. `render` uses them unless `--rules` says otherwise.
    pub rules: crate::core::model::Rules,
    /// The scales and opacities hold Mip-Splatting's 3D smoothing filter (`train
    /// --mip-filter` folded it in; INRIA PLY: a `comment verisplat mip-filter 3d` header
    /// line, glTF: `extras.verisplat.mip_filter`). Nothing renders differently: it says
    /// what the file's Gaussians are.
    pub mip_filter: bool,
    /// Feature channels per Gaussian (0 without features, else 1..=[`MAX_FEATURES`]).
    pub feature_count: usize,
    /// `feature_count` floats per Gaussian, Gaussian-major: channel `k` of Gaussian `i` is
    /// `features[i * feature_count + k]` (PLY properties `feat_0 .. feat_{K-1}`, or
    /// `--features FILE.npy`).
    pub features: Vec<f32>,
    /// A time-varying scene (a space-time field `fit --time-column` wrote): per Gaussian
    /// its temporal mean and the natural log of its temporal scale, `[t_mean, t_scale]`
    /// (PLY properties `t_mean`, `t_scale`; `t_scale` is a log like `scale_0..2`). Gaussian
    /// `i` at time `T` is the 3D Gaussian with its opacity times [`temporal_weight`];
    /// [`Scene::at_time`] gives that scene. `None` for a static scene.
    pub time: Option<Vec<[f32; 2]>>,
}

/// `(t - t_mean) / t_scale` squared beyond which a Gaussian's temporal factor is 0: 4
/// temporal sigma, the spatial truncation of the field's Gaussian kernel
/// ([`crate::core::model::field::GAUSSIAN_CUTOFF`]).
pub const TEMPORAL_CUTOFF: f32 = 16.0;

/// The temporal factor of a Gaussian with temporal mean `t_mean` and log temporal scale
/// `t_log_scale` at time `t`: `exp(-0.5 u^2)`, `u = (t - t_mean) / exp(t_log_scale)`, 0
/// where `u^2 > 16` ([`TEMPORAL_CUTOFF`]). The one definition `fit` optimises, the renders
/// at a time apply ([`Scene::at_time`]) and field evaluation uses.
#[inline]
pub fn temporal_weight(t: f32, t_mean: f32, t_log_scale: f32) -> f32 {
    let u = (t - t_mean) * (-t_log_scale).exp();
    let u2 = u * u;
    if u2 <= TEMPORAL_CUTOFF {
        (-0.5 * u2).exp()
    } else {
        0.0
    }
}

/// Most feature channels a Gaussian may carry.
pub const MAX_FEATURES: usize = 64;

/// The logistic sigmoid in f32, as PyTorch evaluates it for the reference.
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

impl Scene {
    /// An empty scene of the given SH degree.
    pub fn empty(sh_degree: u32) -> Self {
        Scene {
            sh_degree,
            ..Default::default()
        }
    }

    /// The Gaussians at `indices` (in that order) with SH bands up to `sh_degree` (at
    /// most the scene's), the flags kept.
    pub fn select(&self, indices: &[usize], sh_degree: u32) -> Scene {
        let mut out = Scene::empty(sh_degree.min(self.sh_degree));
        out.antialiased = self.antialiased;
        out.kernel = self.kernel;
        out.rules = self.rules;
        out.mip_filter = self.mip_filter;
        out.feature_count = self.feature_count;
        out.time = self
            .time
            .as_ref()
            .map(|t| indices.iter().map(|&i| t[i]).collect());
        let in_stride = self.sh_stride();
        let out_stride = out.sh_stride();
        out.positions.reserve(indices.len());
        out.sh.reserve(indices.len() * out_stride);
        for &i in indices {
            out.positions.push(self.positions[i]);
            out.log_scales.push(self.log_scales[i]);
            out.rotations.push(self.rotations[i]);
            out.opacity_logits.push(self.opacity_logits[i]);
            // Coefficient-major, channel innermost: the first `out_stride` floats are
            // exactly the bands 0..=degree.
            out.sh
                .extend_from_slice(&self.sh[i * in_stride..i * in_stride + out_stride]);
            let k = self.feature_count;
            out.features
                .extend_from_slice(&self.features[i * k..(i + 1) * k]);
        }
        out
    }

    /// The indices of the `n` Gaussians that matter most to an image, in scene order:
    /// ranked by opacity times the area of the largest cross-section (the two largest
    /// axis scales), the splats that cover the most of any view. NaN weights rank last,
    /// ties by index.
    pub fn most_important(&self, n: usize) -> Vec<usize> {
        let mut keep = self.ranked_by_importance(n);
        keep.sort_unstable();
        keep
    }

    /// The indices of the `n` Gaussians that matter most (as [`Self::most_important`]),
    /// most important first: the first `k` of them are the `k` most important.
    pub fn ranked_by_importance(&self, n: usize) -> Vec<usize> {
        let weight = |i: usize| {
            let mut s = self.log_scales[i];
            s.sort_by(f32::total_cmp);
            let w = sigmoid(self.opacity_logits[i]) * (s[1] + s[2]).exp();
            if w.is_nan() {
                f32::NEG_INFINITY
            } else {
                w
            }
        };
        let rank = |a: &(f32, usize), b: &(f32, usize)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
        let mut order: Vec<(f32, usize)> = (0..self.len()).map(|i| (weight(i), i)).collect();
        if n < order.len() {
            order.select_nth_unstable_by(n, rank);
            order.truncate(n);
        }
        order.sort_unstable_by(rank);
        order.into_iter().map(|(_, i)| i).collect()
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when the scene holds no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// SH coefficients per colour channel.
    pub fn sh_coeffs(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree)
    }

    /// Floats of SH per Gaussian.
    pub fn sh_stride(&self) -> usize {
        self.sh_coeffs() * 3
    }

    /// Checks that every array has the length the Gaussian count implies.
    pub fn check_consistent(&self) -> Result<(), String> {
        let n = self.len();
        if self.sh_degree > 3 {
            return Err(format!("SH degree {} is above 3", self.sh_degree));
        }
        if self.log_scales.len() != n
            || self.rotations.len() != n
            || self.opacity_logits.len() != n
            || self.sh.len() != n * self.sh_stride()
            || self.features.len() != n * self.feature_count
            || self.time.as_ref().is_some_and(|t| t.len() != n)
        {
            return Err("attribute arrays have inconsistent lengths".into());
        }
        Ok(())
    }

    /// The range of the temporal means `(min, max)` of a time-varying scene (`None` for a
    /// static or an empty one).
    pub fn time_range(&self) -> Option<(f32, f32)> {
        let t = self.time.as_ref()?;
        let lo = t.iter().map(|v| v[0]).fold(f32::INFINITY, f32::min);
        let hi = t.iter().map(|v| v[0]).fold(f32::NEG_INFINITY, f32::max);
        (lo <= hi).then_some((lo, hi))
    }

    /// The static scene a time-varying one is at time `t`: each Gaussian's opacity times its
    /// [`temporal_weight`] (computed in f64 and stored back as a logit, so the activated
    /// opacity is `sigmoid(logit) * weight` to a few f32 ulps), the Gaussians whose weight
    /// is 0 (beyond 4 temporal sigma) left out, `time` cleared. Every renderer (GPU, CPU,
    /// field) takes this scene, so they agree at a time as they do on a static scene. A
    /// static scene comes back as it is.
    pub fn at_time(&self, t: f32) -> Scene {
        let Some(times) = &self.time else {
            return self.clone();
        };
        let weights: Vec<f32> = times
            .iter()
            .map(|v| temporal_weight(t, v[0], v[1]))
            .collect();
        let keep: Vec<usize> = (0..self.len()).filter(|&i| weights[i] > 0.0).collect();
        let mut out = self.select(&keep, self.sh_degree);
        out.time = None;
        for (logit, &i) in out.opacity_logits.iter_mut().zip(&keep) {
            let o = 1.0 / (1.0 + (-f64::from(*logit)).exp());
            let p = o * f64::from(weights[i]);
            // 0 < p <= 1; the clamp keeps p = 1 (an opacity that rounds to 1 in f64) and
            // an underflow finite.
            *logit = (p.ln() - (-p).ln_1p()).clamp(-1e4, 1e4) as f32;
        }
        out
    }

    /// Applies the reference activations: `exp` to scales, sigmoid to opacity and
    /// quaternion normalisation.
    pub fn activated(&self) -> ActivatedScene {
        ActivatedScene {
            sh_degree: self.sh_degree,
            positions: self.positions.clone(),
            scales: self
                .log_scales
                .iter()
                .map(|s| [s[0].exp(), s[1].exp(), s[2].exp()])
                .collect(),
            rotations: self.rotations.iter().map(|q| normalize_quat(*q)).collect(),
            opacities: self.opacity_logits.iter().map(|&o| sigmoid(o)).collect(),
            sh: self.sh.clone(),
            feature_count: self.feature_count,
            features: self.features.clone(),
        }
    }

    /// Attaches `count` feature channels per Gaussian (`features.len()` must be
    /// `len() * count`), replacing any the scene held.
    pub fn set_features(&mut self, count: usize, features: Vec<f32>) -> Result<(), String> {
        if count > MAX_FEATURES || features.len() != self.len() * count {
            return Err(format!(
                "{} feature values do not make {count} channels (at most {MAX_FEATURES}) for each of {} Gaussians",
                features.len(),
                self.len()
            ));
        }
        self.feature_count = count;
        self.features = features;
        Ok(())
    }
}

/// Normalises a quaternion the way `torch.nn.functional.normalize` does (divide by the norm).
pub fn normalize_quat(q: [f32; 4]) -> [f32; 4] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
}

/// Error raised while loading a scene (the readers' one file error).
pub type SceneError = crate::core::file_error::FileError;

/// The opacity logit of an 8-bit alpha, with alpha clamped to `[0.5, 254.5] / 255` so
/// that 0 and 255 (fully transparent / opaque) still give finite logits.
pub(crate) fn logit_from_u8(alpha: u8) -> f32 {
    logit_clamped(alpha as f32 / 255.0)
}

/// Inverse sigmoid of `p`, with `p` clamped to `[0.5/255, 254.5/255]` (half an 8-bit step
/// inside the open interval), so every decoded opacity has a finite logit.
pub(crate) fn logit_clamped(p: f32) -> f32 {
    let p = p.clamp(0.5 / 255.0, 254.5 / 255.0);
    (p / (1.0 - p)).ln()
}

/// The SH DC coefficient whose colour is `rgb` (0..1): `(rgb - 0.5) / C0`.
pub(crate) fn dc_from_color(rgb: f32) -> f32 {
    (rgb - 0.5) / crate::core::model::sh::SH_C0
}

/// The colour (0..1, unclamped) of an SH DC coefficient: `0.5 + C0 * dc`.
pub(crate) fn color_from_dc(dc: f32) -> f32 {
    0.5 + crate::core::model::sh::SH_C0 * dc
}

/// Checks a decoded scene the way the PLY loader checks its values: every value finite and
/// every quaternion of non-zero length. `what` names the format in the message.
pub(crate) fn check_decoded(scene: &Scene, path: &Path, what: &str) -> Result<(), SceneError> {
    scene.check_consistent().map_err(|m| {
        SceneError::invalid(
            path,
            format!("decodes to an inconsistent {what} scene: {m}"),
        )
    })?;
    for i in 0..scene.len() {
        let finite = scene.positions[i].iter().all(|v| v.is_finite())
            && scene.log_scales[i].iter().all(|v| v.is_finite())
            && scene.rotations[i].iter().all(|v| v.is_finite())
            && scene.opacity_logits[i].is_finite();
        if !finite {
            return Err(SceneError::invalid(
                path,
                format!("{what} Gaussian {i} decodes to a non-finite value"),
            ));
        }
        let q = scene.rotations[i];
        if q.iter().map(|v| v * v).sum::<f32>() == 0.0 {
            return Err(SceneError::invalid(
                path,
                format!("{what} Gaussian {i} has a zero-length rotation quaternion"),
            ));
        }
    }
    if let Some(k) = scene.sh.iter().position(|v| !v.is_finite()) {
        return Err(SceneError::invalid(
            path,
            format!(
                "{what} Gaussian {} decodes to a non-finite SH coefficient",
                k / scene.sh_stride().max(1)
            ),
        ));
    }
    Ok(())
}
