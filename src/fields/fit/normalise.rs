//! What `fit` does around the optimisation: inputs no field can be fitted to are
//! refused, the values made linear (complex magnitude and phase to I and Q, dB to power)
//! and divided by their largest magnitude, the times mapped to 0..1 and a flat scan given
//! a thickness; after the fit the features and temporal parameters are mapped back.

use super::input::{check_times, FieldData};
use super::model::FEAT;
use super::run::{fit_normalised, holdout_count};
use super::{FitConfig, FitOutcome, Progress};

/// The default Gaussian counts for `samples` samples: one Gaussian per 20 samples at the
/// start and at most one per 5, within 8..=1000 and the start..=4000 (the 64^3 grid gets
/// 1000 -> 4000).
pub fn default_counts(samples: usize) -> (usize, usize) {
    let initial = (samples / 20).clamp(8, 1000);
    let max = (samples / 5).clamp(initial, 4000);
    (initial, max)
}

/// The box the fit keeps its Gaussians in, and a note when it differs from the data's:
/// an axis along which the samples do not spread (below 1e-3 of the largest side: a scan
/// on a plane or a line) gets the spacing the initial Gaussians have along the other axes
/// as its thickness, centred on the samples.
pub fn fit_bounds(bounds: [f32; 6], initial: usize) -> ([f32; 6], Option<String>) {
    let ext = [0, 1, 2].map(|a| f64::from(bounds[a + 3] - bounds[a]).max(0.0));
    let largest = ext.iter().fold(0f64, |m, &e| m.max(e));
    let flat: Vec<usize> = (0..3).filter(|&a| ext[a] < 1e-3 * largest).collect();
    if flat.is_empty() || flat.len() == 3 {
        return (bounds, None);
    }
    let dims = 3 - flat.len();
    let measure: f64 = (0..3)
        .filter(|a| !flat.contains(a))
        .map(|a| ext[a])
        .product();
    let thickness = (measure / initial.max(1) as f64).powf(1.0 / dims as f64);
    let mut b = bounds;
    for &a in &flat {
        let mid = 0.5 * (f64::from(bounds[a]) + f64::from(bounds[a + 3]));
        b[a] = (mid - 0.5 * thickness) as f32;
        b[a + 3] = (mid + 0.5 * thickness) as f32;
    }
    let axes: Vec<&str> = flat.iter().map(|&a| ["x", "y", "z"][a]).collect();
    let shape = if dims == 2 { "a plane" } else { "a line" };
    (
        b,
        Some(format!(
            "the samples lie on {shape} (no spread along {}); the Gaussians get a thickness of {thickness:.4} there (the spacing of the initial Gaussians; --bounds sets it)",
            axes.join(" and ")
        )),
    )
}

/// Refuses a magnitude channel `m` without a positive value (dB, most likely), unless the
/// fit takes it as dB ([`FitConfig::db`]).
pub fn check_magnitude(data: &FieldData, m: usize) -> Result<(), String> {
    let mags = data.values.iter().skip(m).step_by(data.k.max(1));
    if mags.clone().all(|v| *v <= 0.0) {
        let lowest = mags.clone().fold(f32::INFINITY, |a, &v| a.min(v));
        let highest = mags.fold(f32::NEG_INFINITY, |a, &v| a.max(v));
        return Err(format!(
            "the magnitude channel {m} has no positive value ({lowest} to {highest}); if it is in dB (e.g. dBm), pass --db to fit it as linear power, or choose another --magnitude-channel"
        ));
    }
    Ok(())
}

/// Refuses inputs no field can be fitted to: one sample, every sample at one point, or
/// every value 0 or not finite.
pub fn check_fittable(data: &FieldData) -> Result<(), String> {
    let n = data.len();
    if n < 2 {
        return Err(format!(
            "holds {n} sample; a field needs samples spread over a line, a plane or a volume"
        ));
    }
    let p0 = data.positions[0];
    if data.positions.iter().all(|p| *p == p0) {
        return Err(format!(
            "all {n} samples lie at one point ({}, {}, {}); a field needs samples spread over a line, a plane or a volume",
            p0[0], p0[1], p0[2]
        ));
    }
    if data.values.iter().all(|v| *v == 0.0) {
        return Err("every value is 0; there is no field to fit".into());
    }
    if let Some(t) = &data.times {
        if t.len() != n {
            return Err(format!("{} times for {n} samples", t.len()));
        }
        check_times(t)?;
    }
    Ok(())
}

/// The fewest samples a fit trains on unless forced (`fit --force`).
pub const MIN_TRAIN_SAMPLES: usize = 20;
/// The fewest samples it holds out to measure the error (with a hold-out share above 0)
/// unless forced.
pub const MIN_HOLDOUT_SAMPLES: usize = 5;

/// The fewest samples that leave [`MIN_TRAIN_SAMPLES`] to train on and, with a hold-out
/// share above 0, [`MIN_HOLDOUT_SAMPLES`] held out.
pub fn min_samples(holdout: f32) -> usize {
    (MIN_TRAIN_SAMPLES..)
        .find(|&n| {
            let held = holdout_count(n, holdout);
            n - held >= MIN_TRAIN_SAMPLES && (holdout <= 0.0 || held >= MIN_HOLDOUT_SAMPLES)
        })
        .unwrap_or(usize::MAX)
}

/// Refuses `n` samples too few to fit and to measure the fit on held-out samples, saying
/// how many it needs.
pub fn check_enough(n: usize, holdout: f32) -> Result<(), String> {
    let need = min_samples(holdout);
    if n >= need {
        return Ok(());
    }
    let held = holdout_count(need, holdout);
    let split = if held > 0 {
        format!(
            "with --holdout {holdout}, at least {need} ({} to fit and {held} held out to measure the error)",
            need - held
        )
    } else {
        format!("at least {need} to fit")
    };
    Err(format!(
        "holds {n} samples, too few to fit a field and measure it: it needs {split}; give more samples, or --force to fit these anyway"
    ))
}

/// Fits Gaussians to `data`. Deterministic for a given configuration (any thread count).
///
/// The values are divided by their largest absolute value first (and the fitted features
/// multiplied back), so the result does not depend on their unit; a flat scan (samples on
/// a plane or a line) is given a thickness ([`fit_bounds`]); inputs no field can be fitted
/// to are refused ([`check_fittable`]). With [`FitConfig::db`] the magnitude channel is
/// fitted as linear power.
pub fn fit(
    data: &FieldData,
    cfg: &FitConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<FitOutcome, String> {
    check_fittable(data)?;
    let k = data.k;
    if cfg.magnitude_channel >= k {
        return Err(format!(
            "--magnitude-channel {} is not a channel of the data, which has {k} (0 to {})",
            cfg.magnitude_channel,
            k - 1
        ));
    }
    let m = cfg.magnitude_channel;
    let values = linear_values(data, cfg)?;
    let scale = values.iter().fold(0f64, |a, &v| a.max(f64::from(v).abs()));
    let (lo, hi) = values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let (bounds, note) = fit_bounds(data.bounds, cfg.initial);
    // Times mapped to 0..1, so nothing depends on their unit or origin either.
    let time_range = data.times.as_ref().map(|t| {
        t.iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            })
    });
    let (t0, span) = time_range.map_or((0.0, 1.0), |(a, b)| {
        (f64::from(a), f64::from(b) - f64::from(a))
    });
    let normalised = FieldData {
        times: data.times.as_ref().map(|t| {
            t.iter()
                .map(|&v| ((f64::from(v) - t0) / span) as f32)
                .collect()
        }),
        time_column: data.time_column,
        positions: data.positions.clone(),
        values: values
            .iter()
            .map(|&v| (f64::from(v) / scale) as f32)
            .collect(),
        k,
        bounds,
        layout: data.layout.clone(),
        bounds_source: data.bounds_source.clone(),
    };
    let mut out = fit_normalised(&normalised, cfg, progress).map_err(|e| {
        format!(
            "{e} (the values range from {lo:e} to {hi:e}; they are fitted divided by {scale:e})"
        )
    })?;
    map_back(&mut out, k, scale, (t0, span));
    out.time_range = time_range;
    out.final_loss.0 *= scale * scale;
    let mags = values.iter().skip(m).step_by(k);
    out.magnitude_range = mags.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
        (a.min(v), b.max(v))
    });
    out.value_scale = scale;
    out.fit_bounds = bounds;
    out.notes.extend(note);
    Ok(out)
}

/// The values as they are fitted: with `--complex`, magnitude and phase as I and Q; with
/// `--db`, the magnitude channel as linear power (refused beyond single precision);
/// otherwise a magnitude channel without a positive value is refused.
fn linear_values(data: &FieldData, cfg: &FitConfig) -> Result<Vec<f32>, String> {
    let k = data.k;
    let m = cfg.magnitude_channel;
    let mut values = data.values.clone();
    if let Some((mc, pc)) = cfg.complex {
        if mc == pc || mc >= k || pc >= k {
            return Err(format!(
                "--complex {mc},{pc} needs two different channels of the {k} (0 to {})",
                k - 1
            ));
        }
        if cfg.db {
            return Err("--complex and --db do not go together: give the magnitude linear".into());
        }
        if let Some(v) = values.iter().skip(mc).step_by(k).find(|v| **v < 0.0) {
            return Err(format!(
                "--complex {mc},{pc}: channel {mc} is a magnitude but holds {v}; give I and Q as two plain channels instead"
            ));
        }
        for row in values.chunks_exact_mut(k) {
            let (mag, phase) = (f64::from(row[mc]), f64::from(row[pc]));
            row[mc] = (mag * phase.cos()) as f32;
            row[pc] = (mag * phase.sin()) as f32;
        }
    }
    if cfg.db {
        for v in values.iter_mut().skip(m).step_by(k) {
            *v = 10f64.powf(f64::from(*v) / 10.0) as f32;
        }
        if let Some(v) = values.iter().skip(m).step_by(k).find(|v| !v.is_finite()) {
            return Err(format!(
                "channel {m} in dB gives a linear power of {v}, beyond single precision; are these dB?"
            ));
        }
    } else if cfg.complex.is_none() {
        check_magnitude(data, m)?;
    }
    Ok(values)
}

/// Maps the fitted features back to the data's unit (times `scale`) and the temporal
/// means and log scales back from 0..1 to the samples' times (`t0` and `span`).
fn map_back(out: &mut FitOutcome, k: usize, scale: f64, (t0, span): (f64, f64)) {
    let stride = out.model.stride();
    let t_at = out.model.time.then(|| out.model.time_offset());
    for g in out.model.params.chunks_exact_mut(stride) {
        for f in &mut g[FEAT..FEAT + k] {
            *f = (f64::from(*f) * scale) as f32;
        }
        if let Some(t) = t_at {
            g[t] = (t0 + f64::from(g[t]) * span) as f32;
            g[t + 1] = (f64::from(g[t + 1]) + span.ln()) as f32;
        }
    }
}
