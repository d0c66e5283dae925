//! The fit's scores at the end: the loss over every training sample, and the error on the
//! held-out samples (relative L2 over all channels and per channel, and with `--db` the
//! magnitude's RMS error in dB).

use super::model::{self, CellGrid, LossConfig, Model, Points};
use super::{FitConfig, HoldoutError};

/// The loss over all training samples (`batches`): the weighted data term and the
/// regulariser.
pub(super) fn final_loss(
    mdl: &Model,
    cfg: &FitConfig,
    loss_cfg: &LossConfig,
    grid: &CellGrid,
    batches: &[Points],
) -> (f64, f64) {
    let k = mdl.k;
    let (mut num, mut den) = (0f64, 0f64);
    for points in batches {
        let f = model::forward(mdl, cfg.kernel, grid, points);
        let sum_w: f64 = points.weights.iter().map(|&w| f64::from(w)).sum();
        num += model::data_loss(&f, points, k) * sum_w;
        den += sum_w;
    }
    let reg_only = model::regulariser(mdl, loss_cfg, None);
    (num / den.max(1e-300), reg_only)
}

/// The error on the `holdout` samples (none without them), unweighted.
pub(super) fn holdout_error(
    mdl: &Model,
    cfg: &FitConfig,
    grid: &CellGrid,
    holdout: &Points,
) -> Option<HoldoutError> {
    let k = mdl.k;
    (!holdout.is_empty()).then(|| {
        let f = model::forward(mdl, cfg.kernel, grid, holdout);
        let mut num = vec![0f64; k];
        let mut den = vec![0f64; k];
        for (fv, yv) in f.chunks_exact(k).zip(holdout.values.chunks_exact(k)) {
            for c in 0..k {
                num[c] += f64::from(fv[c] - yv[c]).powi(2);
                den[c] += f64::from(yv[c]).powi(2);
            }
        }
        let total = (num.iter().sum::<f64>() / den.iter().sum::<f64>().max(1e-300)).sqrt();
        let m = cfg.magnitude_channel;
        // The values are normalised to a largest magnitude of 1: a floor 40 dB below it.
        let db = |v: f32| 10.0 * f64::from(v).max(1e-4).log10();
        let db_sq: f64 = f
            .chunks_exact(k)
            .zip(holdout.values.chunks_exact(k))
            .map(|(fv, yv)| (db(fv[m]) - db(yv[m])).powi(2))
            .sum();
        HoldoutError {
            relative_l2: total,
            per_channel: (0..k)
                .map(|c| (num[c] / den[c].max(1e-300)).sqrt())
                .collect(),
            magnitude_db_rms: cfg.db.then(|| (db_sq / holdout.len().max(1) as f64).sqrt()),
        }
    })
}
