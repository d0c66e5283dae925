//! Images and metrics: reading image files, the metrics of `verisplat compare`, PNG
//! encoding and writing image files.

use crate::arrays::{byte_array, floats, rows};
use crate::errors::{guarded, py_err, value_err};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict};
use std::path::{Path, PathBuf};
use verisplat::core::frame::Frame;
use verisplat::io::metrics::{self, PlaneKind};

/// Reads an image (PNG 8/16-bit, JPEG, WebP, OpenEXR, .npy): width, height, channel names
/// and the samples interleaved per pixel as f32 bytes (8/16-bit scaled to [0, 1]).
#[pyfunction]
pub(crate) fn read_image<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(u32, u32, Vec<String>, Bound<'py, PyByteArray>)> {
    let planes = py.detach(|| {
        guarded(|| verisplat::io::image_file::read_image(&path).map_err(|e| py_err(e.into())))
    })?;
    let names: Vec<String> = planes.channels.iter().map(|c| c.name.clone()).collect();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let samples = planes.interleave(&refs).unwrap_or_default();
    Ok((planes.width, planes.height, names, byte_array(py, &samples)))
}

/// The metrics of `verisplat compare A B` for one plane: `kind` is "color", "alpha" or
/// "data".
#[pyfunction]
pub(crate) fn compare<'py>(
    py: Python<'py>,
    reference: &[u8],
    test: &[u8],
    width: usize,
    height: usize,
    channels: usize,
    kind: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let kind = match kind {
        "color" | "colour" => PlaneKind::Colour,
        "alpha" => PlaneKind::Alpha,
        "data" => PlaneKind::Data,
        other => {
            return Err(value_err(format!(
                "kind must be \"color\", \"alpha\" or \"data\", got {other:?}"
            )))
        }
    };
    let count = width * height * channels;
    let mut a = floats(reference, "reference", count)?;
    let mut b = floats(test, "test", count)?;
    let m = py.detach(|| {
        guarded(|| {
            Ok(metrics::plane_metrics(
                &mut a, &mut b, width, height, channels, kind,
            ))
        })
    })?;
    let d = PyDict::new(py);
    d.set_item("psnr", m.stats.psnr)?;
    d.set_item("ssim", m.ssim)?;
    d.set_item("flip", m.flip)?;
    d.set_item("max_abs", m.stats.max_abs)?;
    d.set_item("mean_abs", m.stats.mean_abs)?;
    d.set_item("within", m.stats.within)?;
    d.set_item("peak", m.stats.peak)?;
    Ok(d)
}

/// PNG bytes of an `H x W x 3` float colour image (8-bit, as `verisplat render` writes).
#[pyfunction]
pub(crate) fn encode_png<'py>(
    py: Python<'py>,
    rgb: &[u8],
    width: u32,
    height: u32,
) -> PyResult<Bound<'py, PyBytes>> {
    let n = width as usize * height as usize;
    let color = rows(&floats(rgb, "rgb", n * 3)?);
    let frame = Frame {
        width,
        height,
        color,
        alpha: vec![0.0; n],
        depth: vec![0.0; n],
        feature_count: 0,
        features: Vec::new(),
    };
    let mut out = Vec::new();
    verisplat::io::output::encode_png(&frame, false, &mut out, Path::new("<memory>"))
        .map_err(|e| py_err(e.into()))?;
    Ok(PyBytes::new(py, &out))
}

/// Writes an image file as `verisplat render` does (by extension: `.png` 8-bit, or 16-bit
/// with `png16`; `.exr` R, G, B, A, Z as 32-bit floats), atomically; an existing file is
/// refused unless `overwrite`.
#[pyfunction]
#[pyo3(signature = (path, rgb, alpha, depth, width, height, png16, overwrite))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn save_image(
    path: PathBuf,
    rgb: &[u8],
    alpha: Option<&[u8]>,
    depth: Option<&[u8]>,
    width: u32,
    height: u32,
    png16: bool,
    overwrite: bool,
) -> PyResult<()> {
    guarded(|| {
        let n = width as usize * height as usize;
        let alpha = match alpha {
            Some(a) => floats(a, "alpha", n)?,
            None => vec![1.0; n],
        };
        let depth = match depth {
            Some(d) => floats(d, "depth", n)?,
            None => vec![f32::INFINITY; n],
        };
        let frame = Frame {
            width,
            height,
            color: rows(&floats(rgb, "rgb", n * 3)?),
            alpha,
            depth,
            feature_count: 0,
            features: Vec::new(),
        };
        let format = verisplat::io::output::ImageFormat::from_path(&path, png16)
            .map_err(|e| py_err(e.into()))?;
        verisplat::io::output::write_frame(&frame, &path, format, overwrite)
            .map_err(|e| py_err(e.into()))
    })
}
