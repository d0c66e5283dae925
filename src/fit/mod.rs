//! `vksplat fit`: Gaussians with feature channels fitted to field samples (RF fields).
//!
//! Inputs ([`load`]): a dense grid `.npy` (`X x Y x Z x C`, its points spread over
//! `--bounds` like `numpy.linspace` on each axis, see [`crate::rf`]) or scattered samples
//! (`.npy` or `.csv`, `N x (3 + C)`: x, y, z, then C values). The C values are the features
//! (K = C). Scattered samples may carry a time in one more column ([`TimeColumn`]): the
//! field is then fitted in space and time (see [`model`]). The model, loss and gradients are in [`model`]; Adam and the density control in
//! [`optim`]; [`fit`] runs the optimisation.
//!
//! Loss weights: `w_n = 0.1 + 0.9 |y_nm| / max_n |y_nm|` (m the magnitude channel), so the
//! strong part of the field counts ten times as much as where it vanishes, which still
//! counts. Held-out error: `sqrt(sum |f - y|^2 / sum |y|^2)` over every channel of the
//! held-out samples, unweighted.

pub mod model;
pub mod optim;

use crate::gen::Rng;
use crate::model::SplatKernel;
use crate::scene::{Scene, MAX_FEATURES};
use model::{CellGrid, LossConfig, Model, Points, FEAT, LOGIT, ROT, SCALE};
use optim::{Adam, DensityStep};
use std::path::{Path, PathBuf};

/// A malformed input: the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct InputError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

fn bad(path: &Path, message: impl Into<String>) -> InputError {
    InputError {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// How the samples were given.
#[derive(Clone, Debug, PartialEq)]
pub enum Layout {
    /// A dense grid of this shape `[X, Y, Z, C]`.
    Grid([usize; 4]),
    /// Scattered samples from a `.npy`.
    SamplesNpy,
    /// Scattered samples from a `.csv`.
    SamplesCsv,
}

/// Which column of scattered samples holds their time (`fit --time-column`).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum TimeColumn {
    /// A CSV header's `t` or `time` column, or the `time_column` of a `.npy`'s sidecar
    /// (`gen --rf moving-source` writes one); else none.
    #[default]
    Auto,
    /// This column (0-based among all columns; x, y, z are 0 to 2).
    Index(usize),
    /// The column a CSV header names so.
    Name(String),
}

impl std::str::FromStr for TimeColumn {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        if s.is_empty() {
            return Err(
                "expected a column number (0-based, e.g. 3) or a CSV header's name (e.g. t)".into(),
            );
        }
        Ok(match s.parse::<usize>() {
            Ok(i) => TimeColumn::Index(i),
            Err(_) => TimeColumn::Name(s.to_string()),
        })
    }
}

/// Field samples: positions and `k` values each.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldData {
    /// Sample positions.
    pub positions: Vec<[f32; 3]>,
    /// Sample times (a time-varying field), one per sample.
    pub times: Option<Vec<f32>>,
    /// The input's column that held the times.
    pub time_column: Option<usize>,
    /// `k` values per sample.
    pub values: Vec<f32>,
    /// Channels per sample.
    pub k: usize,
    /// The box the samples fill, `[xmin, ymin, zmin, xmax, ymax, zmax]`.
    pub bounds: [f32; 6],
    /// How they were given.
    pub layout: Layout,
    /// Where the bounds came from: `--bounds`, a sidecar file, or the samples.
    pub bounds_source: String,
}

impl FieldData {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    /// True without samples.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// Parses `xmin,ymin,zmin,xmax,ymax,zmax` (six finite numbers, each min below its max).
pub fn parse_bounds(s: &str) -> Result<[f32; 6], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 6 {
        return Err(format!(
            "expected 6 numbers xmin,ymin,zmin,xmax,ymax,zmax, got {} in \"{s}\"",
            parts.len()
        ));
    }
    let mut b = [0f32; 6];
    for (v, p) in b.iter_mut().zip(&parts) {
        *v = p
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("\"{p}\" is not a finite number"))?;
    }
    check_bounds(b)?;
    Ok(b)
}

/// Each min below its max (and no NaN).
pub fn check_bounds(b: [f32; 6]) -> Result<(), String> {
    for (a, name) in ["x", "y", "z"].iter().enumerate() {
        if b[a].is_nan() || b[a + 3].is_nan() || b[a] >= b[a + 3] {
            return Err(format!(
                "{name}min ({}) must be below {name}max ({})",
                b[a],
                b[a + 3]
            ));
        }
    }
    Ok(())
}

/// Reads the bounds from the sidecar JSON `gen --rf` writes (`"bounds": [6 numbers]`).
fn sidecar_bounds(path: &Path) -> Result<[f32; 6], InputError> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, format!("cannot read: {e}")))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(path, format!("is not valid JSON: {e}")))?;
    let b: Vec<f32> = value
        .get("bounds")
        .and_then(|b| b.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_f64())
                .map(|v| v as f32)
                .collect()
        })
        .unwrap_or_default();
    let b: [f32; 6] = b
        .try_into()
        .map_err(|_| bad(path, "has no \"bounds\" of 6 numbers"))?;
    check_bounds(b).map_err(|m| bad(path, format!("\"bounds\": {m}")))?;
    Ok(b)
}

/// Loads field samples from `path` (`.npy` grid or samples, or `.csv` samples). A grid
/// takes `bounds`, else those of its sidecar `PATH.json` ([`crate::rf::sidecar_path`]);
/// scattered samples carry their positions and take no bounds. `time` says which column of
/// scattered samples is their time ([`TimeColumn`]); a time column holding one value for
/// every sample is refused (a static field needs none).
pub fn load(
    path: &Path,
    bounds: Option<[f32; 6]>,
    time: &TimeColumn,
) -> Result<FieldData, InputError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let bytes = std::fs::read(path).map_err(|e| bad(path, format!("cannot read: {e}")))?;
    let data = match ext.as_str() {
        "npy" => load_npy(&bytes, path, bounds, time)?,
        "csv" => with_bounds(load_csv(&bytes, path, time)?, bounds, path)?,
        _ => {
            return Err(bad(
                path,
                "has an unknown input format; fit reads a .npy (grid X x Y x Z x C, or samples N x (3 + C)) or a .csv (N rows of x, y, z and C values)",
            ))
        }
    };
    if data.k > MAX_FEATURES {
        return Err(bad(
            path,
            format!(
                "has {} value channels; a Gaussian carries at most {MAX_FEATURES} features",
                data.k
            ),
        ));
    }
    if let (Some(t), Some(c)) = (&data.times, data.time_column) {
        check_times(t).map_err(|m| bad(path, format!("column {c} (time): {m}")))?;
    }
    Ok(data)
}

/// Refuses times no time-varying field can be fitted to: one value for every sample.
pub fn check_times(times: &[f32]) -> Result<(), String> {
    if let Some(i) = times.iter().position(|v| !v.is_finite()) {
        return Err(format!(
            "sample {i} has the time {}, not a finite number",
            times[i]
        ));
    }
    if let Some(&t0) = times.first() {
        if times.iter().all(|&t| t == t0) {
            return Err(format!(
                "every sample has the time {t0}; a field at one time is static: drop the time column (or --time-column) and fit it without time"
            ));
        }
    }
    Ok(())
}

/// The `time_column` a `.npy`'s sidecar names (`gen --rf moving-source` writes one).
fn sidecar_time_column(npy: &Path) -> Result<Option<usize>, InputError> {
    let side = crate::rf::sidecar_path(npy);
    let Ok(text) = std::fs::read_to_string(&side) else {
        return Ok(None);
    };
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(&side, format!("is not valid JSON: {e}")))?;
    match value.get("time_column") {
        None | Some(serde_json::Value::Null) => Ok(None),
        Some(v) => v.as_u64().map(|c| Some(c as usize)).ok_or_else(|| {
            bad(
                &side,
                format!("\"time_column\" is {v}, not a column number"),
            )
        }),
    }
}

/// Checks that column `c` of `cols` can be the time: not x, y or z, and a value left.
fn check_time_column(c: usize, cols: usize, path: &Path) -> Result<(), InputError> {
    if c < 3 {
        return Err(bad(
            path,
            format!("--time-column {c} is {} (columns 0 to 2 are x, y, z); the time is a column after them", ["x", "y", "z"][c]),
        ));
    }
    if c >= cols {
        return Err(bad(
            path,
            format!(
                "--time-column {c}: the samples have {cols} columns (0 to {})",
                cols - 1
            ),
        ));
    }
    if cols < 5 {
        return Err(bad(
            path,
            format!(
                "has {cols} columns; samples with a time are x, y, z, t and at least one value"
            ),
        ));
    }
    Ok(())
}

fn load_npy(
    bytes: &[u8],
    path: &Path,
    bounds: Option<[f32; 6]>,
    time: &TimeColumn,
) -> Result<FieldData, InputError> {
    let array = crate::image_file::parse_npy_array(bytes, path).map_err(|e| {
        let m = e.to_string();
        let prefix = format!("{}: ", path.display());
        bad(path, m.strip_prefix(&prefix).unwrap_or(&m))
    })?;
    let first_bad = |data: &[f32]| data.iter().position(|v| !v.is_finite());
    match array.shape[..] {
        [x, y, z, c] => {
            if *time != TimeColumn::Auto {
                return Err(bad(
                    path,
                    format!("is a dense grid ({x} x {y} x {z} x {c}), which has no time column; give time-varying fields as samples N x (4 + C): x, y, z, t and the values"),
                ));
            }
            if x * y * z * c == 0 {
                return Err(bad(
                    path,
                    format!("is an empty grid (shape {:?}); a grid needs at least one point and one channel", array.shape),
                ));
            }
            if let Some(at) = first_bad(&array.data) {
                let (p, ch) = (at / c, at % c);
                return Err(bad(
                    path,
                    format!(
                        "has a non-finite value ({}) at grid point [{}, {}, {}], channel {ch}",
                        array.data[at],
                        p / (y * z),
                        p / z % y,
                        p % z
                    ),
                ));
            }
            let (bounds, source) = match bounds {
                Some(b) => (b, "--bounds".to_string()),
                None => {
                    let side = crate::rf::sidecar_path(path);
                    if !side.exists() {
                        return Err(bad(
                            path,
                            format!(
                                "is a dense grid ({x} x {y} x {z} x {c}) and needs its extent: give --bounds xmin,ymin,zmin,xmax,ymax,zmax (there is no sidecar {} beside it)",
                                side.display()
                            ),
                        ));
                    }
                    (sidecar_bounds(&side)?, side.display().to_string())
                }
            };
            let mut positions = Vec::with_capacity(x * y * z);
            for i in 0..x {
                let px = crate::rf::grid_coordinate(bounds[0], bounds[3], i, x);
                for j in 0..y {
                    let py = crate::rf::grid_coordinate(bounds[1], bounds[4], j, y);
                    for l in 0..z {
                        let pz = crate::rf::grid_coordinate(bounds[2], bounds[5], l, z);
                        positions.push([px, py, pz]);
                    }
                }
            }
            Ok(FieldData {
                positions,
                times: None,
                time_column: None,
                values: array.data,
                k: c,
                bounds,
                layout: Layout::Grid([x, y, z, c]),
                bounds_source: source,
            })
        }
        [n, cols] => {
            if cols < 4 {
                return Err(bad(
                    path,
                    format!("has {cols} columns; samples are N x (3 + C): x, y, z and at least one value"),
                ));
            }
            if n == 0 {
                return Err(bad(path, "holds no samples (0 rows)"));
            }
            let time_column = match time {
                TimeColumn::Auto => sidecar_time_column(path)?,
                TimeColumn::Index(c) => Some(*c),
                TimeColumn::Name(name) => {
                    return Err(bad(
                        path,
                        format!("--time-column {name}: a .npy has no column names; give the time's column number (x, y, z are 0 to 2, e.g. --time-column 3)"),
                    ))
                }
            };
            if let Some(c) = time_column {
                check_time_column(c, cols, path)?;
            }
            if let Some(at) = first_bad(&array.data) {
                return Err(bad(
                    path,
                    format!(
                        "has a non-finite value ({}) at sample {}, column {}{}",
                        array.data[at],
                        at / cols,
                        at % cols,
                        if Some(at % cols) == time_column { " (the time)" } else { "" }
                    ),
                ));
            }
            with_bounds(
                samples(array.data, cols, Layout::SamplesNpy, time_column),
                bounds,
                path,
            )
        }
        _ => Err(bad(
            path,
            format!(
                "has shape {:?}; fit reads a dense grid X x Y x Z x C (4-D) or samples N x (3 + C) (2-D)",
                array.shape
            ),
        )),
    }
}

/// Scattered samples from rows of `cols` values (x, y, z, values; column `time_column`,
/// if any, the time).
fn samples(rows: Vec<f32>, cols: usize, layout: Layout, time_column: Option<usize>) -> FieldData {
    let k = cols - 3 - usize::from(time_column.is_some());
    let n = rows.len() / cols;
    let mut positions = Vec::with_capacity(n);
    let mut values = Vec::with_capacity(n * k);
    let mut times = Vec::with_capacity(if time_column.is_some() { n } else { 0 });
    for row in rows.chunks_exact(cols) {
        positions.push([row[0], row[1], row[2]]);
        for (c, v) in row.iter().enumerate().skip(3) {
            if Some(c) == time_column {
                times.push(*v);
            } else {
                values.push(*v);
            }
        }
    }
    FieldData {
        bounds: model::point_bounds(&positions),
        times: time_column.map(|_| times),
        time_column,
        positions,
        values,
        k,
        layout,
        bounds_source: "the samples' extent".into(),
    }
}

/// Scattered samples inside `bounds` (`--bounds`: the region they were taken in, which
/// also gives flat scans their thickness); every sample must lie inside.
fn with_bounds(
    mut data: FieldData,
    bounds: Option<[f32; 6]>,
    path: &Path,
) -> Result<FieldData, InputError> {
    let Some(b) = bounds else {
        return Ok(data);
    };
    if let Some(i) = data
        .positions
        .iter()
        .position(|p| (0..3).any(|a| p[a] < b[a] || p[a] > b[a + 3]))
    {
        let p = data.positions[i];
        return Err(bad(
            path,
            format!(
                "sample {i} at ({}, {}, {}) lies outside --bounds {},{},{},{},{},{}",
                p[0], p[1], p[2], b[0], b[1], b[2], b[3], b[4], b[5]
            ),
        ));
    }
    data.bounds = b;
    data.bounds_source = "--bounds".into();
    Ok(data)
}

fn load_csv(bytes: &[u8], path: &Path, time: &TimeColumn) -> Result<FieldData, InputError> {
    let text =
        std::str::from_utf8(bytes).map_err(|_| bad(path, "is not a text (UTF-8) CSV file"))?;
    let mut rows = Vec::new();
    // (line number, columns) of the row that set the width (a header or the first row).
    let mut width: Option<(usize, usize)> = None;
    let mut header: Option<Vec<String>> = None;
    let mut seen_row = false;
    for (i, line) in text.lines().enumerate() {
        let lineno = i + 1;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = t.split(',').map(str::trim).collect();
        let parsed: Vec<Option<f32>> = fields.iter().map(|f| f.parse::<f32>().ok()).collect();
        if !seen_row && width.is_none() && parsed.iter().any(Option::is_none) {
            // A header row (column names).
            width = Some((lineno, fields.len()));
            header = Some(fields.iter().map(|f| f.to_string()).collect());
            continue;
        }
        seen_row = true;
        if let Some((at, w)) = width {
            if fields.len() != w {
                return Err(bad(
                    path,
                    format!(
                        "line {lineno} has {} values where line {at} has {w}; every row needs x, y, z and the same number of values",
                        fields.len()
                    ),
                ));
            }
        } else {
            width = Some((lineno, fields.len()));
        }
        for (c, (f, v)) in fields.iter().zip(&parsed).enumerate() {
            match v {
                None => {
                    return Err(bad(
                        path,
                        format!("line {lineno}, column {}: \"{f}\" is not a number", c + 1),
                    ))
                }
                Some(v) if !v.is_finite() => {
                    return Err(bad(
                        path,
                        format!("line {lineno}, column {}: {f} is not a finite value", c + 1),
                    ))
                }
                Some(v) => rows.push(*v),
            }
        }
    }
    let cols = width.map_or(0, |w| w.1);
    if !seen_row {
        return Err(bad(path, "holds no samples (no data rows)"));
    }
    if cols < 4 {
        return Err(bad(
            path,
            format!("has {cols} columns; samples are rows of x, y, z and at least one value"),
        ));
    }
    let named = |want: &dyn Fn(&str) -> bool| {
        header
            .as_ref()
            .and_then(|h| h.iter().position(|n| want(n.trim_matches('"'))))
    };
    let time_column = match time {
        TimeColumn::Auto => named(&|n| n.eq_ignore_ascii_case("t") || n.eq_ignore_ascii_case("time")),
        TimeColumn::Index(c) => Some(*c),
        TimeColumn::Name(name) => Some(named(&|n| n == name).ok_or_else(|| {
            bad(
                path,
                match &header {
                    Some(h) => format!(
                        "--time-column {name}: its header names no such column (it has {})",
                        h.join(", ")
                    ),
                    None => format!(
                        "--time-column {name}: it has no header row to name columns; give the time's column number (x, y, z are 0 to 2, e.g. --time-column 3)"
                    ),
                },
            )
        })?),
    };
    if let Some(c) = time_column {
        check_time_column(c, cols, path)?;
    }
    Ok(samples(rows, cols, Layout::SamplesCsv, time_column))
}

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

fn fit_normalised(
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
    let w_all = weights(data, cfg.magnitude_channel, cfg.complex);
    // Seeded shuffle (Fisher-Yates), the first share held out.
    let mut idx: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        idx.swap(i, j);
    }
    let n_hold = if cfg.holdout > 0.0 && n >= 2 {
        ((n as f64 * f64::from(cfg.holdout)).round() as usize).clamp(1, n - 1)
    } else {
        0
    };
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
    let ext = model::extents(data.bounds);
    let volume = f64::from(ext[0]) * f64::from(ext[1]) * f64::from(ext[2]);
    let diag = (ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]).sqrt();
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
    let y_max = data
        .values
        .iter()
        .fold(0f32, |m, v| m.max(v.abs()))
        .max(1e-12);

    // Initialisation: centres drawn from the training samples with probability
    // proportional to their weight, isotropic, features so that the overlapping
    // Gaussians add up to the sample's values. With time (0..1 here), as if in
    // `layers = N^(1/4)` layers over time, N / layers Gaussians each in space, temporal
    // scale half a layer's spacing.
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
    let mut adam = Adam::new(mdl.params.len());
    let mut score = vec![0f32; mdl.len()];
    let mut history = Vec::new();
    let densify_until = (cfg.steps as f64 * f64::from(cfg.densify_until)) as usize;
    let mut clipped_steps = 0;
    for step in 1..=cfg.steps {
        let points = &batches[(step - 1) % n_batches];
        let mut lg = model::loss_and_grad(&mdl, &loss_cfg, &grid, points);
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
                clipped_steps += 1;
            }
        }
        for (s, v) in score.iter_mut().zip(&lg.score) {
            *s += v;
        }
        let t = (step - 1) as f32 / cfg.steps.max(2).saturating_sub(1) as f32;
        let decay = cfg.lr_final_fraction.powf(t);
        let lr: Vec<f32> = base_lr.iter().map(|l| l * decay).collect();
        adam.step(&mut mdl.params, &lg.grad, &lr);
        // Keep the parameters in range: quaternions unit, scales between 1e-3 and 0.5 of
        // the diagonal, centres inside the bounds.
        for g in mdl.params.chunks_exact_mut(stride) {
            let q = &mut g[ROT..ROT + 4];
            let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            if norm > 1e-12 && norm.is_finite() {
                q.iter_mut().for_each(|v| *v /= norm);
            } else {
                q.copy_from_slice(&[1.0, 0.0, 0.0, 0.0]);
            }
            for j in 0..3 {
                g[SCALE + j] = g[SCALE + j].clamp(min_log_scale, max_log_scale);
                g[j] = g[j].clamp(data.bounds[j], data.bounds[j + 3]);
            }
            g[LOGIT] = g[LOGIT].clamp(-12.0, 12.0);
            if let Some(t) = t_at {
                g[t] = g[t].clamp(0.0, 1.0);
                g[t + 1] = g[t + 1].clamp(min_log_st, max_log_st);
            }
        }
        if cfg.densify_every > 0
            && step % cfg.densify_every == 0
            && step <= densify_until
            && step < cfg.steps
        {
            let before = mdl.len();
            let pruned = optim::prune(&mut mdl, &mut adam, &mut score, cfg.min_opacity);
            let room = cfg.max_gaussians.saturating_sub(mdl.len());
            let budget = room.min((mdl.len() as f32 * cfg.grow_fraction).ceil() as usize);
            let (cloned, split) =
                optim::densify(&mut mdl, &mut adam, &score, budget, time_to_space);
            score = vec![0.0; mdl.len()];
            history.push(DensityStep {
                step,
                before,
                pruned,
                cloned,
                split,
                after: mdl.len(),
            });
        }
        progress(Progress {
            step,
            loss: lg.total(),
            gaussians: mdl.len(),
        });
    }
    // A last prune, so no Gaussian below --min-opacity is written.
    let before = mdl.len();
    let pruned = optim::prune(&mut mdl, &mut adam, &mut score, cfg.min_opacity);
    history.push(DensityStep {
        step: cfg.steps,
        before,
        pruned,
        after: mdl.len(),
        ..Default::default()
    });
    // Loss over all training samples.
    let (mut num, mut den) = (0f64, 0f64);
    for points in &batches {
        let f = model::forward(&mdl, cfg.kernel, &grid, points);
        let sum_w: f64 = points.weights.iter().map(|&w| f64::from(w)).sum();
        num += model::data_loss(&f, points, k) * sum_w;
        den += sum_w;
    }
    let reg_only = model::regulariser(&mdl, &loss_cfg, None);
    let holdout_error = (!holdout.is_empty()).then(|| {
        let f = model::forward(&mdl, cfg.kernel, &grid, &holdout);
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
    });
    let m = cfg.magnitude_channel;
    let range = (0..n)
        .map(|i| data.values[i * k + m])
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    Ok(FitOutcome {
        model: mdl,
        history,
        train_samples: train_idx.len(),
        holdout_samples: n_hold,
        final_loss: (num / den.max(1e-300), reg_only),
        holdout: holdout_error,
        magnitude_range: range,
        value_scale: 1.0,
        fit_bounds: data.bounds,
        notes: Vec::new(),
        clipped_steps,
        time_range: None,
    })
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
        let rgb = crate::output::turbo(t);
        for v in rgb {
            scene.sh.push((v - 0.5) / crate::model::sh::SH_C0);
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
