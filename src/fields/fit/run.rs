//! The optimisation on normalised data (values of largest magnitude 1, times in 0..1):
//! the seeded hold-out split and the training samples binned into batches, the initial
//! Gaussians, the learning rates and parameter ranges, and the steps with their density
//! control; [`super::evaluate`] scores the result.

use super::evaluate::{final_loss, holdout_error};
use super::input::FieldData;
use super::model::{self, CellGrid, LossConfig, Model, Points, FEAT, LOGIT, ROT, SCALE};
use super::optim::{self, Adam, DensityStep};
use super::{FitConfig, FitOutcome, Progress};
use crate::core::gen::Rng;
use crate::core::model::SplatKernel;

/// The loss weight of each sample (see the module docs): from `|value|` of `channel`, or
/// with `complex` `(I, Q)` from the magnitude `|I + iQ|`.
pub fn weights(data: &FieldData, channel: usize, complex: Option<(usize, usize)>) -> Vec<f32> {
    let k = data.k;
    let magnitude = |n: usize| match complex {
        Some((i, q)) => data.values[n * k + i].hypot(data.values[n * k + q]),
        None => data.values[n * k + channel].abs(),
    };
    let max = (0..data.len()).map(magnitude).fold(0f32, f32::max);
    (0..data.len())
        .map(|n| {
            if max > 0.0 {
                0.1 + 0.9 * magnitude(n) / max
            } else {
                1.0
            }
        })
        .collect()
}

/// The samples as the optimisation takes them.
struct Samples {
    /// The loss weight of every sample ([`weights`]).
    w_all: Vec<f32>,
    /// The samples trained on (indices into the data), in the shuffled order.
    train_idx: Vec<usize>,
    /// How many were held out.
    n_hold: usize,
    /// The cells the samples are binned into.
    grid: CellGrid,
    /// The training samples in mini-batches, binned.
    batches: Vec<Points>,
    /// The held-out samples, binned.
    holdout: Points,
}

/// The box of the data: its sides, volume and diagonal.
struct Extent {
    ext: [f32; 3],
    volume: f64,
    diag: f32,
}

/// How many of `n` samples the share `holdout` holds out (at least 1 and at most `n - 1`
/// of 2 or more, where the share is above 0).
pub fn holdout_count(n: usize, holdout: f32) -> usize {
    if holdout > 0.0 && n >= 2 {
        ((n as f64 * f64::from(holdout)).round() as usize).clamp(1, n - 1)
    } else {
        0
    }
}

/// A seeded shuffle (Fisher-Yates) of the samples, the first share held out, and the
/// rest in batches, binned into cells about the size of the Gaussians at the largest
/// count.
fn split_samples(data: &FieldData, cfg: &FitConfig, extent: &Extent, rng: &mut Rng) -> Samples {
    let k = data.k;
    let n = data.len();
    let w_all = weights(data, cfg.magnitude_channel, cfg.complex);
    // Seeded shuffle (Fisher-Yates), the first share held out.
    let mut idx: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        idx.swap(i, j);
    }
    let n_hold = holdout_count(n, cfg.holdout);
    let (hold_idx, train_idx) = idx.split_at(n_hold);
    let times = data.times.as_deref();
    let gather = |ids: &[usize]| -> (Vec<[f32; 3]>, Vec<f32>, Vec<f32>, Vec<f32>) {
        (
            ids.iter().map(|&i| data.positions[i]).collect(),
            ids.iter()
                .flat_map(|&i| &data.values[i * k..(i + 1) * k])
                .copied()
                .collect(),
            ids.iter().map(|&i| w_all[i]).collect(),
            times.map_or_else(Vec::new, |t| ids.iter().map(|&i| t[i]).collect()),
        )
    };
    let volume = extent.volume;
    // Cells about the size of the Gaussians at the largest count, but no more than four
    // per sample of a batch (each batch keeps a start index per cell).
    let batch = cfg.batch.max(1);
    let final_scale = 0.5 * (volume / cfg.max_gaussians as f64).cbrt() as f32;
    let sparse_limit = (volume / (4.0 * batch as f64)).cbrt() as f32;
    let grid = CellGrid::with_side(data.bounds, final_scale.max(sparse_limit));
    let n_batches = train_idx.len().div_ceil(batch).max(1);
    let batches: Vec<Points> = (0..n_batches)
        .map(|b| {
            let (a, z) = (
                b * train_idx.len() / n_batches,
                (b + 1) * train_idx.len() / n_batches,
            );
            let (p, v, w, t) = gather(&train_idx[a..z]);
            Points::binned(&grid, &p, &v, &w, &t, k)
        })
        .collect();
    let holdout = {
        let (p, v, w, t) = gather(hold_idx);
        Points::binned(&grid, &p, &v, &w, &t, k)
    };
    Samples {
        train_idx: train_idx.to_vec(),
        w_all,
        n_hold,
        grid,
        batches,
        holdout,
    }
}

/// The initial Gaussians: centres drawn from the training samples with probability
/// proportional to their weight, isotropic, features so that the overlapping Gaussians
/// add up to the sample's values. With time (0..1 here), as if in `layers = N^(1/4)`
/// layers over time, N / layers Gaussians each in space, temporal scale half a layer's
/// spacing.
fn initial_gaussians(
    data: &FieldData,
    cfg: &FitConfig,
    volume: f64,
    samples: &Samples,
    rng: &mut Rng,
) -> Model {
    let k = data.k;
    let times = data.times.as_deref();
    let (train_idx, w_all) = (&samples.train_idx, &samples.w_all);
    let layers = if times.is_some() {
        (cfg.initial as f64).powf(0.25).round().max(1.0)
    } else {
        1.0
    };
    let s0 = 0.5 * (volume * layers / cfg.initial as f64).cbrt() as f32;
    let st0 = (0.5 / layers) as f32;
    let kernel_integral = match cfg.kernel {
        SplatKernel::Gaussian => 15.75f32, // (2 pi)^(3/2)
        SplatKernel::Power => 45.24,       // 4 pi * 3.6
    };
    // Temporal overlap: `layers` per unit time, each integrating to sqrt(2 pi) s_t.
    let time_overlap = if times.is_some() {
        (layers as f32 * 2.5066 * st0).max(1.0)
    } else {
        1.0
    };
    let overlap = (cfg.initial as f32 / layers as f32 / volume as f32
        * kernel_integral
        * s0
        * s0
        * s0
        * time_overlap)
        .max(1.0);
    let mut cdf = Vec::with_capacity(train_idx.len());
    let mut acc = 0f64;
    for &i in train_idx {
        acc += f64::from(w_all[i]);
        cdf.push(acc);
    }
    let mut mdl = if times.is_some() {
        Model::with_time(k)
    } else {
        Model::new(k)
    };
    for _ in 0..cfg.initial {
        let u = f64::from(rng.unit()) * acc;
        let pick = cdf.partition_point(|&c| c <= u).min(train_idx.len() - 1);
        let i = train_idx[pick];
        let p = data.positions[i];
        for v in p {
            mdl.params.push(v + rng.range(-0.5, 0.5) * s0);
        }
        mdl.params.extend_from_slice(&[s0.ln(); 3]);
        mdl.params.extend_from_slice(&[1.0, 0.0, 0.0, 0.0]);
        mdl.params.push(0.0);
        for c in 0..k {
            mdl.params.push(data.values[i * k + c] / (0.5 * overlap));
        }
        if let Some(t) = times {
            mdl.params
                .push((t[i] + rng.range(-0.5, 0.5) * st0).clamp(0.0, 1.0));
            mdl.params.push(st0.ln());
        }
    }
    mdl
}

/// How a step moves the parameters: the loss, the learning rates at the start, and the
/// ranges each parameter is kept in.
struct StepRules {
    loss_cfg: LossConfig,
    /// Per parameter of a Gaussian, before the decay.
    base_lr: Vec<f32>,
    min_log_scale: f32,
    max_log_scale: f32,
    /// Temporal log scales' range.
    min_log_st: f32,
    max_log_st: f32,
    /// Where a Gaussian's temporal mean is (a time-varying model).
    t_at: Option<usize>,
    /// A unit of time against the largest side, in the density control's choice of axis.
    time_to_space: f32,
}

impl StepRules {
    fn new(data: &FieldData, cfg: &FitConfig, extent: &Extent, mdl: &Model) -> Self {
        let k = data.k;
        let (ext, diag) = (extent.ext, extent.diag);
        let y_max = data
            .values
            .iter()
            .fold(0f32, |m, v| m.max(v.abs()))
            .max(1e-12);
        let loss_cfg = LossConfig {
            kernel: cfg.kernel,
            scale_reg: cfg.scale_reg,
            reg_length: diag,
        };
        let stride = mdl.stride();
        let base_lr: Vec<f32> = (0..stride)
            .map(|j| match j {
                0..=2 => cfg.lr_position * diag,
                SCALE..=5 => cfg.lr_scale,
                ROT..=9 => cfg.lr_rotation,
                LOGIT => cfg.lr_opacity,
                j if j < FEAT + k => cfg.lr_feature * y_max,
                // The temporal mean and log scale (time in 0..1).
                j if j == FEAT + k => cfg.lr_time,
                _ => cfg.lr_scale,
            })
            .collect();
        let min_log_scale = (1e-3 * diag).ln();
        let max_log_scale = (0.5 * diag).ln();
        // Temporal scales from 1e-3 of the time span to 10 spans (all but constant over it).
        let (min_log_st, max_log_st) = (1e-3f32.ln(), 10f32.ln());
        let t_at = mdl.time.then(|| mdl.time_offset());
        // A unit of time compares to the largest side in the density control's choice of axis.
        let time_to_space = ext.iter().fold(0f32, |m, &e| m.max(e)).ln();
        StepRules {
            loss_cfg,
            base_lr,
            min_log_scale,
            max_log_scale,
            min_log_st,
            max_log_st,
            t_at,
            time_to_space,
        }
    }

    /// Keeps the parameters in range: quaternions unit, scales between 1e-3 and 0.5 of
    /// the diagonal, centres inside the `bounds`.
    fn clamp(&self, mdl: &mut Model, bounds: [f32; 6]) {
        let stride = mdl.stride();
        for g in mdl.params.chunks_exact_mut(stride) {
            let q = &mut g[ROT..ROT + 4];
            let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            if norm > 1e-12 && norm.is_finite() {
                q.iter_mut().for_each(|v| *v /= norm);
            } else {
                q.copy_from_slice(&[1.0, 0.0, 0.0, 0.0]);
            }
            for j in 0..3 {
                g[SCALE + j] = g[SCALE + j].clamp(self.min_log_scale, self.max_log_scale);
                g[j] = g[j].clamp(bounds[j], bounds[j + 3]);
            }
            g[LOGIT] = g[LOGIT].clamp(-12.0, 12.0);
            if let Some(t) = self.t_at {
                g[t] = g[t].clamp(0.0, 1.0);
                g[t + 1] = g[t + 1].clamp(self.min_log_st, self.max_log_st);
            }
        }
    }
}

/// The optimisation's state from step to step.
struct Optimisation {
    mdl: Model,
    adam: Adam,
    /// Per Gaussian: its densification score since the last density step.
    score: Vec<f32>,
    history: Vec<DensityStep>,
    /// Steps whose gradient was clipped.
    clipped_steps: usize,
}

impl Optimisation {
    /// Step `step` (1-based) on `points`: the loss and its gradient (refused when not
    /// finite), clipped with `--clip-grad`, the scores added, Adam with the decayed
    /// learning rates, the parameters kept in range. Returns the batch's loss.
    fn step(
        &mut self,
        cfg: &FitConfig,
        rules: &StepRules,
        grid: &CellGrid,
        points: &Points,
        bounds: [f32; 6],
        step: usize,
    ) -> Result<f64, String> {
        let mut lg = model::loss_and_grad(&self.mdl, &rules.loss_cfg, grid, points);
        if !lg.total().is_finite() || lg.grad.iter().any(|g| !g.is_finite()) {
            return Err(format!(
                "the optimisation diverged at step {step} (a non-finite loss or gradient); --clip-grad or a lower --steps may help"
            ));
        }
        if cfg.clip_grad > 0.0 {
            let norm = lg
                .grad
                .iter()
                .map(|g| f64::from(*g).powi(2))
                .sum::<f64>()
                .sqrt();
            if norm > f64::from(cfg.clip_grad) {
                let f = (f64::from(cfg.clip_grad) / norm) as f32;
                lg.grad.iter_mut().for_each(|g| *g *= f);
                self.clipped_steps += 1;
            }
        }
        for (s, v) in self.score.iter_mut().zip(&lg.score) {
            *s += v;
        }
        let t = (step - 1) as f32 / cfg.steps.max(2).saturating_sub(1) as f32;
        let decay = cfg.lr_final_fraction.powf(t);
        let lr: Vec<f32> = rules.base_lr.iter().map(|l| l * decay).collect();
        self.adam.step(&mut self.mdl.params, &lg.grad, &lr);
        rules.clamp(&mut self.mdl, bounds);
        Ok(lg.total())
    }

    /// The density control after step `step`: prune the transparent, then clone and split
    /// the highest-scoring within the growth budget, and start the scores again.
    fn density_step(&mut self, cfg: &FitConfig, rules: &StepRules, step: usize) {
        let mdl = &mut self.mdl;
        let before = mdl.len();
        let pruned = optim::prune(mdl, &mut self.adam, &mut self.score, cfg.min_opacity);
        let room = cfg.max_gaussians.saturating_sub(mdl.len());
        let budget = room.min((mdl.len() as f32 * cfg.grow_fraction).ceil() as usize);
        let (cloned, split) = optim::densify(
            mdl,
            &mut self.adam,
            &self.score,
            budget,
            rules.time_to_space,
        );
        self.score = vec![0.0; mdl.len()];
        self.history.push(DensityStep {
            step,
            before,
            pruned,
            cloned,
            split,
            after: mdl.len(),
        });
    }

    /// A last prune, so no Gaussian below --min-opacity is written.
    fn last_prune(&mut self, cfg: &FitConfig) {
        let mdl = &mut self.mdl;
        let before = mdl.len();
        let pruned = optim::prune(mdl, &mut self.adam, &mut self.score, cfg.min_opacity);
        self.history.push(DensityStep {
            step: cfg.steps,
            before,
            pruned,
            after: mdl.len(),
            ..Default::default()
        });
    }
}

/// Fits Gaussians to normalised `data` ([`super::fit`] normalises them and maps the
/// result back).
pub(super) fn fit_normalised(
    data: &FieldData,
    cfg: &FitConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitOutcome, String> {
    let k = data.k;
    if cfg.initial == 0 || cfg.initial > cfg.max_gaussians {
        return Err(format!(
            "--gaussians {} must be between 1 and --max-gaussians ({})",
            cfg.initial, cfg.max_gaussians
        ));
    }
    let mut rng = Rng(cfg.seed ^ 0xF17_5EED_0000_0000);
    let n = data.len();
    let ext = model::extents(data.bounds);
    let extent = Extent {
        ext,
        volume: f64::from(ext[0]) * f64::from(ext[1]) * f64::from(ext[2]),
        diag: (ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]).sqrt(),
    };
    let samples = split_samples(data, cfg, &extent, &mut rng);
    let mdl = initial_gaussians(data, cfg, extent.volume, &samples, &mut rng);
    let rules = StepRules::new(data, cfg, &extent, &mdl);
    let mut opt = Optimisation {
        adam: Adam::new(mdl.params.len()),
        score: vec![0f32; mdl.len()],
        mdl,
        history: Vec::new(),
        clipped_steps: 0,
    };
    let densify_until = (cfg.steps as f64 * f64::from(cfg.densify_until)) as usize;
    let n_batches = samples.batches.len();
    for step in 1..=cfg.steps {
        let points = &samples.batches[(step - 1) % n_batches];
        let loss = opt.step(cfg, &rules, &samples.grid, points, data.bounds, step)?;
        if cfg.densify_every > 0
            && step % cfg.densify_every == 0
            && step <= densify_until
            && step < cfg.steps
        {
            opt.density_step(cfg, &rules, step);
        }
        progress(Progress {
            step,
            loss,
            gaussians: opt.mdl.len(),
        });
    }
    opt.last_prune(cfg);
    let Optimisation {
        mdl,
        history,
        clipped_steps,
        ..
    } = opt;
    let grid = &samples.grid;
    let final_loss = final_loss(&mdl, cfg, &rules.loss_cfg, grid, &samples.batches);
    let holdout_error = holdout_error(&mdl, cfg, grid, &samples.holdout);
    let m = cfg.magnitude_channel;
    let range = (0..n)
        .map(|i| data.values[i * k + m])
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    Ok(FitOutcome {
        model: mdl,
        history,
        train_samples: samples.train_idx.len(),
        holdout_samples: samples.n_hold,
        final_loss,
        holdout: holdout_error,
        magnitude_range: range,
        value_scale: 1.0,
        fit_bounds: data.bounds,
        notes: Vec::new(),
        clipped_steps,
        time_range: None,
    })
}
