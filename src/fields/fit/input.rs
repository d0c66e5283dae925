//! The field samples `fit` reads: a dense grid `.npy` (its points spread over bounds
//! given or from its sidecar) or scattered samples (`.npy` or `.csv`, with an optional
//! time column), checked value by value, and the bounds and time columns they come with.

use super::columns::Columns;
pub use super::columns::TimeColumn;
use super::model;
use crate::core::scene::MAX_FEATURES;
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
/// takes `bounds`, else those of its sidecar `PATH.json` ([`crate::fields::rf::sidecar_path`]);
/// scattered samples carry their positions and take no bounds. `time` says which column of
/// scattered samples is their time ([`TimeColumn`]); a time column holding one value for
/// every sample is refused (a static field needs none).
pub fn load(
    path: &Path,
    bounds: Option<[f32; 6]>,
    time: &TimeColumn,
) -> Result<FieldData, InputError> {
    Ok(load_with_columns(path, bounds, time)?.0)
}

/// [`load`], and for scattered samples which column plays which role ([`Columns`]: by
/// name from a CSV header, else x, y, z first).
pub fn load_with_columns(
    path: &Path,
    bounds: Option<[f32; 6]>,
    time: &TimeColumn,
) -> Result<(FieldData, Option<Columns>), InputError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let bytes = std::fs::read(path).map_err(|e| bad(path, format!("cannot read: {e}")))?;
    let (data, columns) = match ext.as_str() {
        "npy" => load_npy(&bytes, path, bounds, time)?,
        "csv" => {
            let (data, columns) = load_csv(&bytes, path, time)?;
            (with_bounds(data, bounds, path)?, Some(columns))
        }
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
    Ok((data, columns))
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
    let side = crate::fields::rf::sidecar_path(npy);
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
) -> Result<(FieldData, Option<Columns>), InputError> {
    let array = crate::core::npy::parse_npy_array(bytes, path).map_err(|e| {
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
                    let side = crate::fields::rf::sidecar_path(path);
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
                let px = crate::fields::rf::grid_coordinate(bounds[0], bounds[3], i, x);
                for j in 0..y {
                    let py = crate::fields::rf::grid_coordinate(bounds[1], bounds[4], j, y);
                    for l in 0..z {
                        let pz = crate::fields::rf::grid_coordinate(bounds[2], bounds[5], l, z);
                        positions.push([px, py, pz]);
                    }
                }
            }
            let data = FieldData {
                positions,
                times: None,
                time_column: None,
                values: array.data,
                k: c,
                bounds,
                layout: Layout::Grid([x, y, z, c]),
                bounds_source: source,
            };
            Ok((data, None))
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
            let (time_column, time_from) = match time {
                TimeColumn::Auto => {
                    let c = sidecar_time_column(path)?;
                    let from = format!("the sidecar {}", crate::fields::rf::sidecar_path(path).display());
                    (c, c.map(|_| from))
                }
                TimeColumn::Index(c) => (Some(*c), Some(format!("--time-column {c}"))),
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
            let columns = Columns::positional(cols, time_column, time_from);
            let data = samples(array.data, cols, Layout::SamplesNpy, &columns);
            Ok((with_bounds(data, bounds, path)?, Some(columns)))
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

/// Scattered samples from rows of `cols` values, the columns read in the roles `columns`
/// gives them.
fn samples(rows: Vec<f32>, cols: usize, layout: Layout, columns: &Columns) -> FieldData {
    let k = columns.values.len();
    let n = rows.len() / cols;
    let mut positions = Vec::with_capacity(n);
    let mut values = Vec::with_capacity(n * k);
    let mut times = Vec::with_capacity(if columns.time.is_some() { n } else { 0 });
    for row in rows.chunks_exact(cols) {
        positions.push(columns.xyz.map(|c| row[c]));
        values.extend(columns.values.iter().map(|&c| row[c]));
        if let Some(c) = columns.time {
            times.push(row[c]);
        }
    }
    FieldData {
        bounds: model::point_bounds(&positions),
        times: columns.time.map(|_| times),
        time_column: columns.time,
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

fn load_csv(
    bytes: &[u8],
    path: &Path,
    time: &TimeColumn,
) -> Result<(FieldData, Columns), InputError> {
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
    let columns = match &header {
        Some(names) => Columns::from_header(names, time).map_err(|m| bad(path, m))?,
        None => {
            let c = match time {
                TimeColumn::Auto => None,
                TimeColumn::Index(c) => Some(*c),
                TimeColumn::Name(name) => return Err(bad(
                    path,
                    format!("--time-column {name}: it has no header row to name columns; give the time's column number (x, y, z are 0 to 2, e.g. --time-column 3)"),
                )),
            };
            if let Some(c) = c {
                check_time_column(c, cols, path)?;
            }
            Columns::positional(cols, c, c.map(|c| format!("--time-column {c}")))
        }
    };
    let data = samples(rows, cols, Layout::SamplesCsv, &columns);
    Ok((data, columns))
}
