//! `verisplat fit`: Gaussians with feature channels fitted to field samples (RF fields).
//!
//! Inputs ([`load`]): a dense grid `.npy` (`X x Y x Z x C`, its points spread over
//! `--bounds` like `numpy.linspace` on each axis, see [`crate::fields::rf`]) or scattered samples
//! (`.npy` or `.csv`, `N x (3 + C)`: x, y, z, then C values). The C values are the features
//! (K = C). Scattered samples may carry a time in one more column ([`TimeColumn`]): the
//! field is then fitted in space and time (see [`model`]). The model, loss and gradients are in [`model`]; Adam and the density control in
//! [`optim`]; [`fit`] runs the optimisation.
//!
//! Loss weights: `w_n = 0.1 + 0.9 |y_nm| / max_n |y_nm|` (m the magnitude channel), so the
//! strong part of the field counts ten times as much as where it vanishes, which still
//! counts. Held-out error: `sqrt(sum |f - y|^2 / sum |y|^2)` over every channel of the
//! held-out samples, unweighted.
//!
//! The rooms: the inputs ([`input`]), what `fit` does around the optimisation
//! (refusals, normalisation, the result mapped back: [`normalise`]), the optimisation
//! ([`run`]) and its scores at the end ([`evaluate`]).

pub mod columns;
pub mod evaluate;
pub mod input;
pub mod model;
pub mod normalise;
pub mod optim;
pub mod run;

pub use columns::Columns;
pub use input::{
    check_bounds, check_times, load, load_with_columns, parse_bounds, FieldData, InputError,
    Layout, TimeColumn,
};
pub use normalise::{
    check_enough, check_fittable, check_magnitude, default_counts, fit, fit_bounds, min_samples,
    MIN_HOLDOUT_SAMPLES, MIN_TRAIN_SAMPLES,
};
pub use run::{holdout_count, weights};

use crate::core::model::SplatKernel;
use crate::core::scene::Scene;
use model::{Model, LOGIT, ROT, SCALE};
use optim::DensityStep;

/// The fitting options.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FitConfig {
    /// Kernel of the Gaussians.
    #[serde(serialize_with = "kernel_name")]
    pub kernel: SplatKernel,
    /// Gaussians at the start.
    pub initial: usize,
    /// Never more than this many.
    pub max_gaussians: usize,
    /// Optimisation steps.
    pub steps: usize,
    /// Density control every this many steps (0: never).
    pub densify_every: usize,
    /// Density control stops after this fraction of the steps.
    pub densify_until: f32,
    /// Each density step adds at most this fraction of the current count.
    pub grow_fraction: f32,
    /// Prune Gaussians whose opacity falls below this.
    pub min_opacity: f32,
    /// The channel that weights the loss.
    pub magnitude_channel: usize,
    /// Fraction of the samples held out.
    pub holdout: f32,
    /// Seed of every random choice.
    pub seed: u64,
    /// Training samples per step (a mini-batch; all when fewer).
    pub batch: usize,
    /// Weight of the scale regulariser.
    pub scale_reg: f32,
    /// Learning rate of the positions, in units of the data's diagonal.
    pub lr_position: f32,
    /// Learning rate of the log scales.
    pub lr_scale: f32,
    /// Learning rate of the quaternions.
    pub lr_rotation: f32,
    /// Learning rate of the opacity logits.
    pub lr_opacity: f32,
    /// Learning rate of the features, in units of the data's largest absolute value.
    pub lr_feature: f32,
    /// Every learning rate falls exponentially to this fraction at the last step.
    pub lr_final_fraction: f32,
    /// The magnitude channel holds decibels (`10 log10` of a power): it is fitted as the
    /// linear power `10^(v / 10)` and the held-out error is also reported in dB.
    pub db: bool,
    /// Clip the gradient's norm (over every parameter, on the normalised values) to this
    /// before each Adam step (0: no clipping).
    pub clip_grad: f32,
    /// Learning rate of the temporal means, in units of the samples' time span.
    pub lr_time: f32,
    /// Channels `(M, P)` hold one complex value as magnitude and phase (radians): they are
    /// fitted as `I = M cos P` and `Q = M sin P` (which channels M and P of the output then
    /// hold), so the Gaussians add up coherently; the weights come from M.
    pub complex: Option<(usize, usize)>,
}

fn kernel_name<S: serde::Serializer>(k: &SplatKernel, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(k.name())
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            kernel: SplatKernel::Gaussian,
            initial: 1000,
            max_gaussians: 4000,
            steps: 1500,
            densify_every: 100,
            densify_until: 0.75,
            grow_fraction: 0.25,
            min_opacity: 0.005,
            magnitude_channel: 0,
            holdout: 0.1,
            seed: 1,
            batch: 16384,
            scale_reg: 0.01,
            lr_position: 1e-3,
            lr_scale: 0.01,
            lr_rotation: 0.01,
            lr_opacity: 0.05,
            lr_feature: 0.02,
            lr_final_fraction: 0.1,
            db: false,
            clip_grad: 0.0,
            complex: None,
            lr_time: 2e-3,
        }
    }
}

/// Held-out errors.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HoldoutError {
    /// `sqrt(sum |f - y|^2 / sum |y|^2)` over all channels.
    pub relative_l2: f64,
    /// The same per channel.
    pub per_channel: Vec<f64>,
    /// With [`FitConfig::db`]: the RMS error of the magnitude channel in dB (the fitted
    /// power and the data each floored 40 dB below the data's peak).
    pub magnitude_db_rms: Option<f64>,
}

/// A progress report after a step.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Steps done.
    pub step: usize,
    /// The batch's loss (data term plus regulariser) at that step.
    pub loss: f64,
    /// Gaussians now.
    pub gaussians: usize,
}

/// What [`fit`] produced.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// The fitted Gaussians.
    pub model: Model,
    /// Every density-control step, the final prune last.
    pub history: Vec<DensityStep>,
    /// Samples trained on.
    pub train_samples: usize,
    /// Samples held out.
    pub holdout_samples: usize,
    /// Loss on all training samples at the end (data term, regulariser).
    pub final_loss: (f64, f64),
    /// Held-out error (none without held-out samples).
    pub holdout: Option<HoldoutError>,
    /// Min and max of the magnitude channel in the data (for the colormap).
    pub magnitude_range: (f32, f32),
    /// The values were divided by this (their largest absolute value) for the fit and the
    /// features multiplied back, so nothing depends on their unit.
    pub value_scale: f64,
    /// The box the Gaussians were kept in: the data's, with flat axes given a thickness.
    pub fit_bounds: [f32; 6],
    /// What was chosen from the data (thickness of a flat scan), one sentence each.
    pub notes: Vec<String>,
    /// Steps whose gradient norm was clipped (`--clip-grad`).
    pub clipped_steps: usize,
    /// A time-varying fit: the samples' times ran from the first to the second (they were
    /// fitted mapped to 0..1, and the temporal means and scales mapped back).
    pub time_range: Option<(f32, f32)>,
}

/// The fitted Gaussians as a scene: features `feat_*`, colour (`f_dc`) from the turbo
/// colormap of the fitted magnitude channel at each centre (the data's range of that
/// channel mapped to 0..1), SH degree 0, the kernel recorded.
pub fn to_scene(outcome: &FitOutcome, kernel: SplatKernel, magnitude_channel: usize) -> Scene {
    let mdl = &outcome.model;
    let k = mdl.k;
    let centres: Vec<[f32; 3]> = (0..mdl.len())
        .map(|i| {
            let g = mdl.gaussian(i);
            [g[0], g[1], g[2]]
        })
        .collect();
    // A time-varying Gaussian is coloured by the field at its centre at its temporal mean.
    let f = match mdl.time {
        false => model::evaluate(mdl, kernel, &centres),
        true => {
            let taus: Vec<f32> = (0..mdl.len())
                .map(|i| mdl.gaussian(i)[mdl.time_offset()])
                .collect();
            model::evaluate_at(mdl, kernel, &centres, Some(&taus)).unwrap_or_default()
        }
    };
    let (lo, hi) = outcome.magnitude_range;
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut scene = Scene::empty(0);
    scene.kernel = kernel;
    if mdl.time {
        scene.time = Some(Vec::with_capacity(mdl.len()));
    }
    for (i, &c) in centres.iter().enumerate() {
        let g = mdl.gaussian(i);
        scene.positions.push(c);
        scene
            .log_scales
            .push([g[SCALE], g[SCALE + 1], g[SCALE + 2]]);
        scene
            .rotations
            .push([g[ROT], g[ROT + 1], g[ROT + 2], g[ROT + 3]]);
        scene.opacity_logits.push(g[LOGIT]);
        let t = (f[i * k + magnitude_channel] - lo) / span;
        let rgb = crate::io::output::turbo(t);
        for v in rgb {
            scene.sh.push((v - 0.5) / crate::core::model::sh::SH_C0);
        }
        scene.features.extend_from_slice(mdl.features(i));
        if let Some(t) = scene.time.as_mut() {
            let at = mdl.time_offset();
            t.push([g[at], g[at + 1]]);
        }
    }
    scene.feature_count = k;
    scene
}

#[cfg(test)]
mod tests;
