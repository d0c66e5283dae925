//! Fitting Gaussians with feature channels to field samples (`verisplat fit`).

use crate::arrays::{check_finite, floats, rows};
use crate::errors::{guarded, value_err};
use crate::scene::PyScene;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use verisplat::core::scene;

/// The counts and options `fit` takes before it reads anything else: channels, the
/// held-out share, enough samples (unless `force`), steps and the gradient clip.
fn check_sizes(
    n: usize,
    k: usize,
    holdout: f32,
    steps: usize,
    clip_grad: f32,
    force: bool,
) -> PyResult<()> {
    if k == 0 || k > scene::MAX_FEATURES {
        return Err(value_err(format!(
            "values: {k} channels; a Gaussian carries 1 to {} features",
            scene::MAX_FEATURES
        )));
    }
    if !(0.0..=0.9).contains(&holdout) {
        return Err(value_err(format!(
            "holdout must be between 0 and 0.9, got {holdout}"
        )));
    }
    if !force {
        // The command line's rule (`verisplat fit --force`), in the function's words.
        verisplat::fields::fit::check_enough(n, holdout).map_err(|m| {
            value_err(format!(
                "points {}",
                m.replace("--holdout ", "holdout=")
                    .replace("--force", "force=True")
            ))
        })?;
    }
    if steps == 0 || clip_grad.is_nan() || clip_grad < 0.0 {
        return Err(value_err(
            "steps must be at least 1 and clip_grad 0 or more",
        ));
    }
    Ok(())
}

/// Fits Gaussians with feature channels to field samples, as `verisplat fit` does: `points`
/// `n x 3` and `values` `n x k` float32 bytes. Returns the scene and a report: the held-out
/// errors, the counts, what was chosen from the data (`notes`) and `warnings` (a fit no
/// better than predicting 0).
#[pyfunction]
#[pyo3(signature = (points, values, n, k, gaussians=None, max_gaussians=None, steps=1500, kernel="gaussian", holdout=0.1, seed=1, bounds=None, magnitude_channel=0, db=false, clip_grad=0.0, times=None, force=false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit<'py>(
    py: Python<'py>,
    points: &[u8],
    values: &[u8],
    n: usize,
    k: usize,
    gaussians: Option<usize>,
    max_gaussians: Option<usize>,
    steps: usize,
    kernel: &str,
    holdout: f32,
    seed: u64,
    bounds: Option<[f32; 6]>,
    magnitude_channel: usize,
    db: bool,
    clip_grad: f32,
    times: Option<&[u8]>,
    force: bool,
) -> PyResult<(PyScene, Bound<'py, PyDict>)> {
    use verisplat::fields::fit::{self, FieldData, FitConfig, Layout};
    let points = floats(points, "points", n * 3)?;
    let values = floats(values, "values", n * k)?;
    check_finite("points", &points, 3)?;
    check_finite("values", &values, k.max(1))?;
    let kernel: verisplat::cpu::SplatKernel = kernel.parse().map_err(value_err)?;
    check_sizes(n, k, holdout, steps, clip_grad, force)?;
    let positions: Vec<[f32; 3]> = rows(&points);
    let times = times.map(|t| floats(t, "times", n)).transpose()?;
    if let Some(t) = &times {
        check_finite("times", t, 1)?;
    }
    let mut data = FieldData {
        bounds: fit::model::point_bounds(&positions),
        time_column: times.as_ref().map(|_| 3),
        times,
        positions,
        values,
        k,
        layout: Layout::SamplesNpy,
        bounds_source: "the samples' extent".into(),
    };
    if let Some(b) = bounds {
        fit::check_bounds(b).map_err(|m| value_err(format!("bounds: {m}")))?;
        if let Some(i) = data
            .positions
            .iter()
            .position(|p| (0..3).any(|a| p[a] < b[a] || p[a] > b[a + 3]))
        {
            return Err(value_err(format!(
                "points: point {i} lies outside the bounds"
            )));
        }
        data.bounds = b;
        data.bounds_source = "bounds".into();
    }
    fit::check_fittable(&data).map_err(|m| value_err(format!("points and values: {m}")))?;
    if magnitude_channel >= k {
        return Err(value_err(format!(
            "magnitude_channel {magnitude_channel} is not one of the {k} channels"
        )));
    }
    if !db {
        fit::check_magnitude(&data, magnitude_channel).map_err(|m| {
            value_err(format!(
                "values: {}",
                m.replace("pass --db", "pass db=True")
            ))
        })?;
    }
    let (auto_initial, auto_max) = fit::default_counts(n);
    let initial =
        gaussians.unwrap_or_else(|| auto_initial.min(max_gaussians.unwrap_or(usize::MAX)));
    let max_gaussians = max_gaussians.unwrap_or(auto_max.max(initial));
    if initial == 0 || initial > max_gaussians {
        return Err(value_err(format!(
            "gaussians ({initial}) must be between 1 and max_gaussians ({max_gaussians})"
        )));
    }
    let cfg = FitConfig {
        kernel,
        initial,
        max_gaussians,
        steps,
        holdout,
        seed,
        magnitude_channel,
        db,
        clip_grad,
        ..FitConfig::default()
    };
    let outcome =
        py.detach(|| guarded(|| fit::fit(&data, &cfg, &mut |_| {}).map_err(value_err)))?;
    let raw = fit::to_scene(&outcome, kernel, magnitude_channel);
    let act = raw.activated();
    let report = PyDict::new(py);
    let h = outcome.holdout.as_ref();
    report.set_item("holdout_relative_l2", h.map(|h| h.relative_l2))?;
    report.set_item(
        "holdout_relative_l2_per_channel",
        h.map(|h| h.per_channel.clone()),
    )?;
    report.set_item(
        "holdout_magnitude_db_rms",
        h.and_then(|h| h.magnitude_db_rms),
    )?;
    report.set_item("gaussians_initial", initial)?;
    report.set_item("gaussians_max", max_gaussians)?;
    report.set_item("gaussians", outcome.model.len())?;
    report.set_item("value_scale", outcome.value_scale)?;
    report.set_item("fit_bounds", outcome.fit_bounds.to_vec())?;
    report.set_item("notes", outcome.notes.clone())?;
    report.set_item("time_range", outcome.time_range)?;
    let warnings: Vec<String> = h
        .filter(|h| h.relative_l2.is_nan() || h.relative_l2 >= 1.0)
        .map(|h| {
            format!(
                "the held-out relative L2 error is {:.3}: this fit is no better than predicting 0 everywhere (error 1)",
                h.relative_l2
            )
        })
        .into_iter()
        .collect();
    report.set_item("warnings", warnings)?;
    Ok((
        PyScene::new(raw, act, format!("fitted to {n} samples")),
        report,
    ))
}
