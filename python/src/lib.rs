//! `vksplat._native`: the Rust side of the Python package.
//!
//! The public API is the Python package `vksplat` (python/vksplat/__init__.py), which
//! turns numpy arrays into the little-endian `f32` bytes this module takes and wraps the
//! bytes it returns as arrays. Arrays cross as bytes so the module needs nothing beyond
//! the stable ABI (one wheel for every CPython >= 3.9). Everything long-running releases
//! the GIL; every error becomes a Python exception carrying the sentence the command line
//! prints; a panic is caught and raised as `RuntimeError`, never unwound into Python.

use glam::{Mat3, Vec3};
use pyo3::exceptions::{PyFileExistsError, PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use vksplat::camera::{self, Camera};
use vksplat::cpu::RenderOptions;
use vksplat::frame::Frame;
use vksplat::gpu::{ContextOptions, GpuContext, GpuError};
use vksplat::metrics::{self, PlaneKind};
use vksplat::render::{GpuRenderer, GpuScene};
use vksplat::scene::{self, ActivatedScene, Scene};

/// A camera as it crosses the boundary: name, width, height, `[fx, fy, cx, cy]` and the
/// world-to-camera matrix, row-major 4x4 (OpenCV axes).
type CamTuple = (String, u32, u32, [f32; 4], [f32; 16]);

/// The planes a render returns: colour `B x H x W x 3`, alpha and depth `B x H x W`,
/// features `B x H x W x K`, each as `f32` bytes, `None` where not asked for.
type Planes<'py> = (
    Option<Bound<'py, PyByteArray>>,
    Option<Bound<'py, PyByteArray>>,
    Option<Bound<'py, PyByteArray>>,
    Option<Bound<'py, PyByteArray>>,
);

// ---------------------------------------------------------------------------------------
// Errors

/// An error as a Python exception: a missing file is `FileNotFoundError`, an output that
/// exists (without `overwrite`) `FileExistsError`, a device
/// failure `RuntimeError`, anything else (bad input) `ValueError`; the message is the
/// command line's sentence.
fn py_err(e: anyhow::Error) -> PyErr {
    let sentence = vksplat::console::error_sentence(&e);
    for cause in e.chain() {
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            if io.kind() == std::io::ErrorKind::NotFound {
                return PyFileNotFoundError::new_err(sentence);
            }
        }
        if let Some(vksplat::output::OutputError::Exists(_)) = cause.downcast_ref() {
            return PyFileExistsError::new_err(sentence);
        }
        if let Some(vksplat::fsutil::WriteError::Exists(_)) = cause.downcast_ref() {
            return PyFileExistsError::new_err(sentence);
        }
        if cause.downcast_ref::<GpuError>().is_some() {
            return PyRuntimeError::new_err(sentence);
        }
    }
    PyValueError::new_err(sentence)
}

fn value_err(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// Runs `f`, turning a panic into `RuntimeError` so none unwinds into Python.
fn guarded<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in vksplat (please report it): {what}"
            )))
        }
    }
}

// ---------------------------------------------------------------------------------------
// Byte helpers

fn floats(bytes: &[u8], what: &str, count: usize) -> PyResult<Vec<f32>> {
    if bytes.len() != count * 4 {
        return Err(value_err(format!(
            "{what}: expected {count} float32 values, got {} bytes",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

fn rows<const N: usize>(v: &[f32]) -> Vec<[f32; N]> {
    v.chunks_exact(N)
        .map(|c| std::array::from_fn(|i| c[i]))
        .collect()
}

fn byte_array<'py, T: bytemuck::Pod>(py: Python<'py>, v: &[T]) -> Bound<'py, PyByteArray> {
    PyByteArray::new(py, bytemuck::cast_slice(v))
}

// ---------------------------------------------------------------------------------------
// Cameras

fn to_camera(t: &CamTuple) -> PyResult<Camera> {
    let (name, width, height, k, m) = t;
    // Row-major [R t; 0 1]: glam takes columns, so R's rows become the transpose's columns.
    let rotation = Mat3::from_cols_array(&[m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]]);
    let cam = Camera {
        name: name.clone(),
        width: *width,
        height: *height,
        fx: k[0],
        fy: k[1],
        cx: k[2],
        cy: k[3],
        rotation,
        translation: Vec3::new(m[3], m[7], m[11]),
    };
    cam.validate()
        .map_err(|e| value_err(format!("camera \"{name}\": {e}")))?;
    Ok(cam)
}

fn from_camera(c: &Camera) -> CamTuple {
    let r = c.rotation.transpose().to_cols_array(); // rows of R
    let t = c.translation;
    (
        c.name.clone(),
        c.width,
        c.height,
        [c.fx, c.fy, c.cx, c.cy],
        [
            r[0], r[1], r[2], t.x, r[3], r[4], r[5], t.y, r[6], r[7], r[8], t.z, 0.0, 0.0, 0.0, 1.0,
        ],
    )
}

/// Every camera of a camera file (INRIA cameras.json, COLMAP model, nerfstudio path,
/// vksplat keyframes; a trained model directory stands for its cameras.json).
#[pyfunction]
#[pyo3(signature = (path, frames=None, fps=None))]
fn load_cameras(
    py: Python<'_>,
    path: PathBuf,
    frames: Option<usize>,
    fps: Option<f32>,
) -> PyResult<Vec<CamTuple>> {
    py.detach(|| {
        guarded(|| {
            let timing = camera::PathTiming { frames, fps };
            let (cams, _) =
                camera::load_camera_file(&path, &timing).map_err(|e| py_err(e.into()))?;
            Ok(cams.iter().map(from_camera).collect())
        })
    })
}

/// Writes cameras as an INRIA cameras.json (read back by `load_cameras` and the CLI's
/// `--cameras`), atomically.
#[pyfunction]
#[pyo3(signature = (path, cameras, overwrite=false))]
fn save_cameras(path: PathBuf, cameras: Vec<CamTuple>, overwrite: bool) -> PyResult<()> {
    guarded(|| {
        let cams = cameras
            .iter()
            .map(to_camera)
            .collect::<PyResult<Vec<_>>>()?;
        let numbered: Vec<(usize, Camera)> = cams.into_iter().enumerate().collect();
        let text = camera::inria::to_json(&numbered).map_err(|e| py_err(e.into()))?;
        vksplat::output::write_bytes_atomically(&path, overwrite, text.as_bytes())
            .map_err(|e| py_err(e.into()))
    })
}

/// A turntable orbit around the scene's bulk (see `vksplat render --orbit`).
#[pyfunction]
#[pyo3(signature = (scene, frames, width, height, vfov, elevation, start, up, centre=None, radius=None))]
#[allow(clippy::too_many_arguments)]
fn orbit(
    scene: &PyScene,
    frames: usize,
    width: u32,
    height: u32,
    vfov: f32,
    elevation: f32,
    start: f32,
    up: [f32; 3],
    centre: Option<[f32; 3]>,
    radius: Option<f32>,
) -> PyResult<Vec<CamTuple>> {
    guarded(|| {
        let params = camera::OrbitParams {
            frames,
            centre: centre.map(Vec3::from),
            radius,
            elevation_deg: elevation,
            up: Vec3::from(up),
            start_deg: start,
            vfov_deg: vfov,
            width,
            height,
        };
        let cams = camera::orbit(&scene.raw.positions, &params).map_err(|e| py_err(e.into()))?;
        Ok(cams.iter().map(from_camera).collect())
    })
}

/// The camera `vksplat render` uses when given none.
#[pyfunction]
fn default_camera(scene: &PyScene, width: u32, height: u32) -> PyResult<CamTuple> {
    guarded(|| {
        camera::check_resolution(width, height).map_err(|e| py_err(e.into()))?;
        Ok(from_camera(&camera::default_camera(
            &scene.raw.positions,
            width,
            height,
        )))
    })
}

/// A camera at `eye` looking at `target`, `up` the world's up, vertical field of view in
/// degrees.
#[pyfunction]
#[pyo3(signature = (eye, target, up, width, height, vfov, name=String::new()))]
fn look_at(
    eye: [f32; 3],
    target: [f32; 3],
    up: [f32; 3],
    width: u32,
    height: u32,
    vfov: f32,
    name: String,
) -> PyResult<CamTuple> {
    guarded(|| {
        camera::check_resolution(width, height).map_err(|e| py_err(e.into()))?;
        if !(vfov > 0.0 && vfov < 180.0) {
            return Err(value_err(format!(
                "the vertical field of view must be between 0 and 180 degrees, got {vfov}"
            )));
        }
        let cam = Camera::look_at(
            &name,
            width,
            height,
            vfov.to_radians(),
            Vec3::from(eye),
            Vec3::from(target),
            Vec3::from(up),
        );
        cam.validate().map_err(|e| py_err(e.into()))?;
        Ok(from_camera(&cam))
    })
}

/// The centre of the scene's robust bounding box (2nd-98th percentile per axis), what
/// the default camera and orbits look at.
#[pyfunction]
fn bulk_centre(scene: &PyScene) -> [f32; 3] {
    camera::bulk_bounds(&scene.raw.positions)
        .box_centre()
        .to_array()
}

// ---------------------------------------------------------------------------------------
// Scenes

static NEXT_SCENE_ID: AtomicU64 = AtomicU64::new(1);

/// A scene: the trainer's parameters as stored and the activated arrays the renderers
/// read. Immutable, so a renderer can keep its upload for as long as it sees the same id.
#[pyclass(module = "vksplat._native", name = "Scene", frozen)]
struct PyScene {
    raw: Scene,
    act: ActivatedScene,
    id: u64,
    source: String,
}

impl PyScene {
    fn new(raw: Scene, act: ActivatedScene, source: String) -> Self {
        PyScene {
            raw,
            act,
            id: NEXT_SCENE_ID.fetch_add(1, Ordering::Relaxed),
            source,
        }
    }
}

#[pymethods]
impl PyScene {
    /// Number of Gaussians.
    fn __len__(&self) -> usize {
        self.raw.len()
    }

    /// SH degree, 0..=3.
    #[getter]
    fn sh_degree(&self) -> u32 {
        self.raw.sh_degree
    }

    /// Whether the file records antialiased training.
    #[getter]
    fn antialiased(&self) -> bool {
        self.raw.antialiased
    }

    /// Feature channels per Gaussian (0 without features).
    #[getter]
    fn feature_count(&self) -> usize {
        self.raw.feature_count
    }

    /// The field the Gaussians hold, `sum_i o_i feat_i G_i(x)` (the sum `fit` fits), at `n`
    /// points (`n x 3` float32 bytes), for a time-varying scene at `times` (`n` float32
    /// bytes): `n x K` float32 bytes.
    #[pyo3(signature = (points, n, times=None))]
    fn evaluate_field<'py>(
        &self,
        py: Python<'py>,
        points: &[u8],
        n: usize,
        times: Option<&[u8]>,
    ) -> PyResult<Bound<'py, PyByteArray>> {
        if self.raw.feature_count == 0 {
            return Err(value_err(format!(
                "{} has no feature channels, so it holds no field",
                self.source
            )));
        }
        let p = floats(points, "points", n * 3)?;
        check_finite("points", &p, 3)?;
        let positions: Vec<[f32; 3]> = rows(&p);
        let times = times.map(|t| floats(t, "times", n)).transpose()?;
        let model = vksplat::fit::model::Model::from_scene(&self.raw);
        let kernel = self.raw.kernel;
        let f = py.detach(|| {
            guarded(|| {
                vksplat::fit::model::evaluate_at(&model, kernel, &positions, times.as_deref())
                    .map_err(|m| value_err(format!("{}: {m}", self.source)))
            })
        })?;
        Ok(byte_array(py, &f))
    }

    /// A time-varying scene's temporal means' range `(min, max)`; None for a static one.
    #[getter]
    fn time_range(&self) -> Option<(f32, f32)> {
        self.raw.time_range()
    }

    /// The static scene a time-varying one is at time `t` (each Gaussian's opacity times
    /// its temporal factor, as `render --time` renders it).
    fn at_time(&self, t: f32) -> PyResult<PyScene> {
        if self.raw.time.is_none() {
            return Err(value_err(format!(
                "{} is static (no t_mean, t_scale); it has no time to choose",
                self.source
            )));
        }
        if !t.is_finite() {
            return Err(value_err(format!("t must be a finite number, got {t}")));
        }
        let raw = self.raw.at_time(t);
        let act = raw.activated();
        Ok(PyScene::new(
            raw,
            act,
            format!("{} at t = {t}", self.source),
        ))
    }

    /// The falloff the file records ("gaussian" unless a PLY says `power`).
    #[getter]
    fn kernel(&self) -> &'static str {
        self.raw.kernel.name()
    }

    /// Where the scene came from.
    #[getter]
    fn source(&self) -> &str {
        &self.source
    }

    /// A number unique to this scene object.
    #[getter]
    fn id(&self) -> u64 {
        self.id
    }

    /// One array as little-endian f32 bytes: means, quats, scales, opacities, sh (the
    /// activated values the renderers read) or log_scales, raw_quats, opacity_logits (the
    /// trainer's parameters).
    fn array<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyBytes>> {
        let bytes: &[u8] = match name {
            "means" => bytemuck::cast_slice(&self.act.positions),
            "quats" => bytemuck::cast_slice(&self.act.rotations),
            "scales" => bytemuck::cast_slice(&self.act.scales),
            "opacities" => bytemuck::cast_slice(&self.act.opacities),
            "sh" => bytemuck::cast_slice(&self.act.sh),
            "log_scales" => bytemuck::cast_slice(&self.raw.log_scales),
            "raw_quats" => bytemuck::cast_slice(&self.raw.rotations),
            "opacity_logits" => bytemuck::cast_slice(&self.raw.opacity_logits),
            "features" => bytemuck::cast_slice(&self.act.features),
            other => return Err(value_err(format!("no array called {other:?}"))),
        };
        Ok(PyBytes::new(py, bytes))
    }

    /// Writes the scene in the format `path`'s extension names (.ply, .splat, .spz),
    /// atomically; an existing file is refused unless `overwrite`.
    #[pyo3(signature = (path, overwrite=false))]
    fn save(&self, py: Python<'_>, path: PathBuf, overwrite: bool) -> PyResult<()> {
        py.detach(|| {
            guarded(|| {
                let format =
                    scene::write::OutputFormat::from_path(&path).map_err(|e| py_err(e.into()))?;
                let bytes = scene::write::to_bytes(&self.raw, format)
                    .map_err(|m| value_err(format!("{}: {m}", path.display())))?;
                vksplat::output::write_bytes_atomically(&path, overwrite, &bytes)
                    .map_err(|e| py_err(e.into()))
            })
        })
    }

    /// The Gaussians whose largest scale is at most `max_scale` and whose opacity is at
    /// least `min_opacity`, with SH bands up to `sh_degree` (as the CLI's filters).
    #[pyo3(signature = (max_scale=None, min_opacity=None, sh_degree=None))]
    fn filtered(
        &self,
        max_scale: Option<f32>,
        min_opacity: Option<f32>,
        sh_degree: Option<u32>,
    ) -> PyResult<PyScene> {
        guarded(|| {
            let f = scene::filter::SceneFilter {
                max_scale,
                min_opacity,
                crop: None,
                sh_degree,
            };
            f.validate().map_err(value_err)?;
            let raw = f.apply(&self.raw);
            let act = raw.activated();
            Ok(PyScene::new(raw, act, self.source.clone()))
        })
    }
}

/// Loads a scene from any supported file, a SOG directory or a trained model directory
/// (`iteration` picks point_cloud/iteration_N; default the largest).
#[pyfunction]
#[pyo3(signature = (path, iteration=None))]
fn load(py: Python<'_>, path: PathBuf, iteration: Option<u64>) -> PyResult<PyScene> {
    py.detach(|| {
        guarded(|| {
            let resolved =
                scene::resolve_scene_path_at(&path, iteration).map_err(|e| py_err(e.into()))?;
            let raw = scene::load(&resolved).map_err(|e| py_err(e.into()))?;
            let act = raw.activated();
            Ok(PyScene::new(raw, act, resolved.display().to_string()))
        })
    })
}

/// Fits Gaussians with feature channels to field samples, as `vksplat fit` does: `points`
/// `n x 3` and `values` `n x k` float32 bytes. Returns the scene and a report: the held-out
/// errors, the counts, what was chosen from the data (`notes`) and `warnings` (a fit no
/// better than predicting 0).
#[pyfunction]
#[pyo3(signature = (points, values, n, k, gaussians=None, max_gaussians=None, steps=1500, kernel="gaussian", holdout=0.1, seed=1, bounds=None, magnitude_channel=0, db=false, clip_grad=0.0, times=None))]
#[allow(clippy::too_many_arguments)]
fn fit<'py>(
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
) -> PyResult<(PyScene, Bound<'py, PyDict>)> {
    use vksplat::fit::{self, FieldData, FitConfig, Layout};
    let points = floats(points, "points", n * 3)?;
    let values = floats(values, "values", n * k)?;
    check_finite("points", &points, 3)?;
    check_finite("values", &values, k.max(1))?;
    let kernel: vksplat::cpu::SplatKernel = kernel.parse().map_err(value_err)?;
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
    if steps == 0 || clip_grad.is_nan() || clip_grad < 0.0 {
        return Err(value_err(
            "steps must be at least 1 and clip_grad 0 or more",
        ));
    }
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

/// The built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0).
#[pyfunction]
fn demo() -> PyScene {
    let raw = vksplat::demo_scene();
    let act = raw.activated();
    PyScene::new(raw, act, "built-in demo scene (PLAYBOT)".into())
}

fn check_finite(name: &str, v: &[f32], per: usize) -> PyResult<()> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(value_err(format!(
            "{name}[{}] is {}; every value must be finite",
            i / per.max(1),
            v[i]
        )));
    }
    Ok(())
}

fn sh_degree_of(coeffs: usize) -> PyResult<u32> {
    match coeffs {
        1 => Ok(0),
        4 => Ok(1),
        9 => Ok(2),
        16 => Ok(3),
        k => Err(value_err(format!(
            "sh has {k} coefficients per channel; it must have 1, 4, 9 or 16 (SH degree 0 to 3)"
        ))),
    }
}

/// Checks a quaternion array: finite and non-zero.
fn check_quats(quats: &[[f32; 4]]) -> PyResult<()> {
    if let Some(i) = quats
        .iter()
        .position(|q| q.iter().map(|v| v * v).sum::<f32>() < 1e-30)
    {
        return Err(value_err(format!(
            "quats[{i}] is {:?}, a zero quaternion has no rotation",
            quats[i]
        )));
    }
    Ok(())
}

/// A scene from arrays, `activated` (scales, opacities in [0, 1], any non-zero
/// quaternions) or raw (log scales, opacity logits, quaternions as the trainer stores
/// them). Shapes were checked by the Python side; values are checked here.
#[pyfunction]
#[pyo3(signature = (n, sh_coeffs, means, quats, scales, opacities, sh, activated, antialiased=false, feature_count=0, features=None))]
#[allow(clippy::too_many_arguments)]
fn scene_from_arrays(
    n: usize,
    sh_coeffs: usize,
    means: &[u8],
    quats: &[u8],
    scales: &[u8],
    opacities: &[u8],
    sh: &[u8],
    activated: bool,
    antialiased: bool,
    feature_count: usize,
    features: Option<&[u8]>,
) -> PyResult<PyScene> {
    guarded(|| {
        let sh_degree = sh_degree_of(sh_coeffs)?;
        let features = match features {
            Some(b) => {
                let f = floats(b, "features", n * feature_count)?;
                check_finite("features", &f, feature_count)?;
                f
            }
            None => Vec::new(),
        };
        let means = floats(means, "means", n * 3)?;
        let quats = floats(quats, "quats", n * 4)?;
        let scales = floats(scales, "scales", n * 3)?;
        let opacities = floats(opacities, "opacities", n)?;
        let sh = floats(sh, "sh", n * sh_coeffs * 3)?;
        let (scale_name, opacity_name) = if activated {
            ("scales", "opacities")
        } else {
            ("log_scales", "opacity_logits")
        };
        check_finite("means", &means, 3)?;
        check_finite("quats", &quats, 4)?;
        check_finite(scale_name, &scales, 3)?;
        check_finite(opacity_name, &opacities, 1)?;
        check_finite("sh", &sh, sh_coeffs * 3)?;
        let quats: Vec<[f32; 4]> = rows(&quats);
        check_quats(&quats)?;
        let mut raw = Scene::empty(sh_degree);
        raw.positions = rows(&means);
        raw.sh = sh.clone();
        raw.antialiased = antialiased;
        if feature_count > 0 {
            raw.set_features(feature_count, features.clone())
                .map_err(value_err)?;
        }
        let act = if activated {
            if let Some(i) = scales.iter().position(|&s| s <= 0.0) {
                return Err(value_err(format!(
                    "scales[{}] is {}; activated scales must be positive (pass log scales with activated=False)",
                    i / 3,
                    scales[i]
                )));
            }
            if let Some(i) = opacities.iter().position(|o| !(0.0..=1.0).contains(o)) {
                return Err(value_err(format!(
                    "opacities[{i}] is {}; activated opacities must be in [0, 1] (pass logits with activated=False)",
                    opacities[i]
                )));
            }
            let scales: Vec<[f32; 3]> = rows(&scales);
            raw.log_scales = scales.iter().map(|s| s.map(f32::ln)).collect();
            // Logits of 0 and 1 are infinite: clamp to the nearest representable
            // probabilities so that the stored parameters stay finite.
            raw.opacity_logits = opacities
                .iter()
                .map(|&p| {
                    let p = p.clamp(f32::MIN_POSITIVE, 1.0 - f32::EPSILON / 2.0);
                    (p / (1.0 - p)).ln()
                })
                .collect();
            // Unit quaternions are used as given, so a loaded scene's arrays give back the
            // same scene bit for bit; others are normalised as the trainer does.
            let unit: Vec<[f32; 4]> = quats
                .iter()
                .map(|q| {
                    let n2: f32 = q.iter().map(|v| v * v).sum();
                    if (n2 - 1.0).abs() <= 4.0 * f32::EPSILON {
                        *q
                    } else {
                        scene::normalize_quat(*q)
                    }
                })
                .collect();
            raw.rotations = quats;
            ActivatedScene {
                sh_degree,
                positions: raw.positions.clone(),
                scales,
                rotations: unit,
                opacities,
                sh,
                feature_count: raw.feature_count,
                features,
            }
        } else {
            raw.log_scales = rows(&scales);
            raw.rotations = quats;
            raw.opacity_logits = opacities;
            let act = raw.activated();
            if let Some(i) = act
                .scales
                .iter()
                .position(|s| s.iter().any(|v| !v.is_finite()))
            {
                return Err(value_err(format!(
                    "log_scales[{i}] is {:?}; its exponential overflows",
                    raw.log_scales[i]
                )));
            }
            act
        };
        Ok(PyScene::new(raw, act, "arrays".into()))
    })
}

// ---------------------------------------------------------------------------------------
// Rendering

/// What a render returns and how.
struct Want {
    rgb: bool,
    alpha: bool,
    depth: bool,
    features: bool,
}

/// Per-frame options as the Python side passes them: background, SH degree, scale
/// modifier, max scale, min opacity, antialiased (None: the scene's flag), kernel (None:
/// the scene's).
type OptTuple = (
    [f32; 3],
    Option<u32>,
    f32,
    Option<f32>,
    Option<f32>,
    Option<bool>,
    Option<String>,
);

/// The planes wanted: rgb, alpha, depth, features.
type WantTuple = (bool, bool, bool, bool);

/// A checked render request.
struct Request {
    opts: RenderOptions,
    cams: Vec<Camera>,
    want: Want,
}

/// Checks the options, the cameras and the planes asked for.
fn request(
    scene: &PyScene,
    cameras: &[CamTuple],
    options: OptTuple,
    want: WantTuple,
) -> PyResult<Request> {
    let (background, sh_degree, scale_modifier, max_scale, min_opacity, antialiased, kernel) =
        options;
    if let Some(d) = sh_degree {
        if d > 3 {
            return Err(value_err(format!("sh_degree must be 0 to 3, got {d}")));
        }
    }
    let kernel = match kernel {
        Some(k) => k.parse::<vksplat::cpu::SplatKernel>().map_err(value_err)?,
        None => scene.raw.kernel,
    };
    let opts = RenderOptions {
        background,
        antialiased: antialiased.unwrap_or(scene.raw.antialiased),
        scale_modifier,
        max_scale,
        min_opacity,
        sh_degree,
        kernel,
    };
    opts.validate().map_err(value_err)?;
    let (rgb, alpha, depth, features) = want;
    check_features(scene, features)?;
    Ok(Request {
        opts,
        cams: self::cameras(cameras)?,
        want: Want {
            rgb,
            alpha,
            depth,
            features,
        },
    })
}

fn cameras(cams: &[CamTuple]) -> PyResult<Vec<Camera>> {
    let cams = cams.iter().map(to_camera).collect::<PyResult<Vec<_>>>()?;
    if let Some(first) = cams.first() {
        if let Some(other) = cams
            .iter()
            .find(|c| (c.width, c.height) != (first.width, first.height))
        {
            return Err(value_err(format!(
                "a batch renders cameras of one size: \"{}\" is {}x{} and \"{}\" is {}x{}",
                first.name, first.width, first.height, other.name, other.width, other.height
            )));
        }
    } else {
        return Err(value_err("no camera to render"));
    }
    Ok(cams)
}

/// Refuses a features render of a scene without features, and any render of a
/// time-varying scene (render `scene.at_time(t)`).
fn check_features(scene: &PyScene, features: bool) -> PyResult<()> {
    if let Some((lo, hi)) = scene.raw.time_range() {
        return Err(value_err(format!(
            "{} is time-varying (its Gaussians' temporal means run from {lo} to {hi}); render it at a time: scene.at_time(t)",
            scene.source
        )));
    }
    if features && scene.raw.feature_count == 0 {
        return Err(value_err(format!(
            "mode 'features' needs feature channels, but {} has none (Scene.from_arrays(features=...), or feat_* PLY properties)",
            scene.source
        )));
    }
    Ok(())
}

/// Concatenates the wanted planes of the frames.
fn planes<'py>(py: Python<'py>, frames: &[Frame], want: &Want) -> Planes<'py> {
    let gather = |f: &dyn Fn(&Frame) -> &[f32]| -> Vec<f32> {
        frames.iter().flat_map(|fr| f(fr).iter().copied()).collect()
    };
    let rgb = want
        .rgb
        .then(|| byte_array(py, &gather(&|f| bytemuck::cast_slice(&f.color))));
    let alpha = want.alpha.then(|| byte_array(py, &gather(&|f| &f.alpha)));
    let depth = want.depth.then(|| byte_array(py, &gather(&|f| &f.depth)));
    let features = want
        .features
        .then(|| byte_array(py, &gather(&|f| &f.features)));
    (rgb, alpha, depth, features)
}

/// State behind a renderer's lock. The uploaded scene is declared first so it is freed
/// before the renderer (and its device).
struct RendererState {
    features: Option<(u64, vksplat::render::GpuFeatures)>,
    scene: Option<(u64, GpuScene)>,
    gpu: GpuRenderer,
    uploads: u64,
    frames: u64,
    timings: Vec<(&'static str, f64)>,
}

/// Opens `device` (VKSPLAT_VALIDATE=1 also turns the validation layer on): the context,
/// the device's name and whether the validation layer is on.
fn open_context(device: Option<String>, validation: bool) -> PyResult<(GpuContext, String, bool)> {
    let ctx = GpuContext::new(&ContextOptions {
        device,
        validation,
        memory_limit: None,
        ..Default::default()
    })
    .map_err(|e| py_err(e.into()))?;
    let name = ctx.info().name.clone();
    let validation = ctx.validation_enabled();
    Ok((ctx, name, validation))
}

/// With the validation layer on, any message it printed fails the call.
fn check_validation(ctx: &GpuContext, on: bool) -> PyResult<()> {
    if on {
        let messages = ctx.validation_messages();
        if !messages.is_empty() {
            return Err(PyRuntimeError::new_err(format!(
                "the Vulkan validation layer reported {} message(s): {}",
                messages.len(),
                messages.join(" | ")
            )));
        }
    }
    Ok(())
}

/// The Vulkan renderer: pipelines and per-frame buffers, and the last scene uploaded.
#[pyclass(module = "vksplat._native", name = "Renderer", frozen)]
struct PyRenderer {
    state: Mutex<RendererState>,
    device: String,
    validation: bool,
}

#[pymethods]
impl PyRenderer {
    /// Opens `device` (index or part of its name; default: discrete, then integrated,
    /// then CPU; also VKSPLAT_DEVICE). VKSPLAT_VALIDATE=1 turns the validation layer on,
    /// and any message it prints fails the render.
    #[new]
    #[pyo3(signature = (device=None))]
    fn new(py: Python<'_>, device: Option<String>) -> PyResult<Self> {
        py.detach(|| {
            guarded(|| {
                let (ctx, name, validation) = open_context(device, false)?;
                let gpu = GpuRenderer::new(ctx).map_err(|e| py_err(e.into()))?;
                Ok(PyRenderer {
                    state: Mutex::new(RendererState {
                        features: None,
                        scene: None,
                        gpu,
                        uploads: 0,
                        frames: 0,
                        timings: Vec::new(),
                    }),
                    device: name,
                    validation,
                })
            })
        })
    }

    /// The device's name.
    #[getter]
    fn device(&self) -> &str {
        &self.device
    }

    /// Renders `cameras` (all of one size) of `scene`; returns the wanted planes of all
    /// frames, concatenated. The scene is uploaded only when it is not the last one.
    fn render<'py>(
        &self,
        py: Python<'py>,
        scene: &PyScene,
        cameras: Vec<CamTuple>,
        options: OptTuple,
        want: WantTuple,
    ) -> PyResult<Planes<'py>> {
        let Request { opts, cams, want } = request(scene, &cameras, options, want)?;
        let features = want.features;
        let frames = py.detach(|| {
            guarded(|| {
                let mut guard = self.state.lock().map_err(|_| {
                    PyRuntimeError::new_err("the renderer failed earlier; create a new one")
                })?;
                let st = &mut *guard;
                if st.scene.as_ref().map(|(id, _)| *id) != Some(scene.id) {
                    st.scene = None; // free the old upload first
                    let uploaded = st.gpu.upload(&scene.act).map_err(|e| py_err(e.into()))?;
                    st.scene = Some((scene.id, uploaded));
                    st.uploads += 1;
                }
                if features && st.features.as_ref().map(|(id, _)| *id) != Some(scene.id) {
                    st.features = None;
                    let uploaded = st
                        .gpu
                        .upload_features(&scene.act)
                        .map_err(|e| py_err(e.into()))?;
                    st.features = Some((scene.id, uploaded));
                }
                let gpu_scene = &st.scene.as_ref().expect("uploaded above").1;
                let mut frames = Vec::with_capacity(cams.len());
                for cam in &cams {
                    let frame = match (&st.features, features) {
                        (Some((_, f)), true) => st.gpu.render_features(gpu_scene, f, cam, &opts),
                        _ => st.gpu.render(gpu_scene, cam, &opts),
                    };
                    frames.push(frame.map_err(|e| py_err(e.into()))?);
                    st.frames += 1;
                }
                st.timings = st.gpu.timings().stages().to_vec();
                check_validation(st.gpu.ctx(), self.validation)?;
                Ok(frames)
            })
        })?;
        Ok(planes(py, &frames, &want))
    }

    /// GPU milliseconds of each stage of the last frame, in pipeline order.
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        if let Ok(st) = self.state.lock() {
            for (name, ms) in &st.timings {
                d.set_item(*name, *ms)?;
            }
        }
        Ok(d)
    }

    /// Counters: scene uploads, frames rendered, device bytes of the uploaded scene and of
    /// the per-frame buffers.
    #[getter]
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        if let Ok(st) = self.state.lock() {
            d.set_item("uploads", st.uploads)?;
            d.set_item("frames", st.frames)?;
            d.set_item(
                "scene_bytes",
                st.scene.as_ref().map_or(0, |(_, s)| s.device_bytes()),
            )?;
            d.set_item("frame_bytes", st.gpu.frame_device_bytes())?;
        }
        Ok(d)
    }
}

/// Renders on the CPU reference renderer (rayon threads); same arguments as
/// `Renderer.render`.
#[pyfunction]
fn render_cpu<'py>(
    py: Python<'py>,
    scene: &PyScene,
    cameras: Vec<CamTuple>,
    options: OptTuple,
    want: WantTuple,
) -> PyResult<Planes<'py>> {
    let Request { opts, cams, want } = request(scene, &cameras, options, want)?;
    let features = want.features;
    let frames = py.detach(|| {
        guarded(|| {
            Ok(cams
                .iter()
                .map(|cam| {
                    if features {
                        vksplat::cpu::render_features(&scene.act, cam, &opts)
                    } else {
                        vksplat::cpu::render(&scene.act, cam, &opts)
                    }
                })
                .collect::<Vec<_>>())
        })
    })?;
    Ok(planes(py, &frames, &want))
}

// ---------------------------------------------------------------------------------------
// Images and metrics

/// Reads an image (PNG 8/16-bit, JPEG, WebP, OpenEXR, .npy): width, height, channel names
/// and the samples interleaved per pixel as f32 bytes (8/16-bit scaled to [0, 1]).
#[pyfunction]
fn read_image<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(u32, u32, Vec<String>, Bound<'py, PyByteArray>)> {
    let planes = py.detach(|| {
        guarded(|| vksplat::image_file::read_image(&path).map_err(|e| py_err(e.into())))
    })?;
    let names: Vec<String> = planes.channels.iter().map(|c| c.name.clone()).collect();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let samples = planes.interleave(&refs).unwrap_or_default();
    Ok((planes.width, planes.height, names, byte_array(py, &samples)))
}

/// The metrics of `vksplat compare A B` for one plane: `kind` is "color", "alpha" or
/// "data".
#[pyfunction]
fn compare<'py>(
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

/// PNG bytes of an `H x W x 3` float colour image (8-bit, as `vksplat render` writes).
#[pyfunction]
fn encode_png<'py>(
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
    vksplat::output::encode_png(&frame, false, &mut out, Path::new("<memory>"))
        .map_err(|e| py_err(e.into()))?;
    Ok(PyBytes::new(py, &out))
}

/// Writes an image file as `vksplat render` does (by extension: `.png` 8-bit, or 16-bit
/// with `png16`; `.exr` R, G, B, A, Z as 32-bit floats), atomically; an existing file is
/// refused unless `overwrite`.
#[pyfunction]
#[pyo3(signature = (path, rgb, alpha, depth, width, height, png16, overwrite))]
#[allow(clippy::too_many_arguments)]
fn save_image(
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
        let format =
            vksplat::output::ImageFormat::from_path(&path, png16).map_err(|e| py_err(e.into()))?;
        vksplat::output::write_frame(&frame, &path, format, overwrite).map_err(|e| py_err(e.into()))
    })
}

// ---------------------------------------------------------------------------------------
// Differentiable rasterization

use vksplat::mlp::{Mlp, MlpParams};
use vksplat::model::grad::{ColorParams, PixelGrads, SplatGrads, SplatParams};
use vksplat::render::differentiable::{Accumulation, DiffRasterizer};

/// A layer crossing to or from Python: outputs, inputs, weight and bias as f32 bytes,
/// activation.
type LayerTuple = (usize, usize, Vec<u8>, Vec<u8>, String);
/// A network's inputs and layers.
type ShaderLayers = (Vec<String>, Vec<LayerTuple>);

/// A neural shader given as safetensors bytes (`Shader.to_bytes()`).
fn shader_of(bytes: Option<&[u8]>) -> PyResult<Option<Mlp>> {
    bytes
        .map(|b| Mlp::parse(b, None).map_err(|e| value_err(format!("shader: {e}"))))
        .transpose()
}

/// The channels of the image a forward pass returns: 3 when shaded.
fn image_channels(p: &SplatParams<f32>, shader: &Option<Mlp>) -> PyResult<usize> {
    match shader {
        Some(mlp) => {
            if !matches!(p.colors, ColorParams::Direct { .. }) {
                return Err(value_err(
                    "colors: a shader reads direct feature values (N, K), not SH coefficients",
                ));
            }
            mlp.check_channels(p.channels())
                .map_err(|e| value_err(format!("colors: {e}")))?;
            Ok(3)
        }
        None => Ok(p.channels()),
    }
}

fn shader_grads_into<'py, T: bytemuck::Pod>(
    py: Python<'py>,
    d: &Bound<'py, PyDict>,
    g: &MlpParams<T>,
) -> PyResult<()> {
    let list = |v: &Vec<Vec<T>>| -> Vec<Bound<'py, PyByteArray>> {
        v.iter().map(|x| byte_array(py, x)).collect()
    };
    d.set_item("shader_weights", list(&g.weights))?;
    d.set_item("shader_biases", list(&g.biases))?;
    Ok(())
}

/// A network built from its layers (weight `outputs x inputs` and bias as f32 bytes, and
/// the activation) and inputs, checked as a shader file is: its safetensors bytes.
#[pyfunction]
fn shader_from_layers<'py>(
    py: Python<'py>,
    inputs: Vec<String>,
    layers: Vec<LayerTuple>,
) -> PyResult<Bound<'py, PyByteArray>> {
    let mut parsed = Vec::new();
    for n in &inputs {
        parsed.push(vksplat::mlp::MlpInput::parse(n).ok_or_else(|| {
            value_err(format!(
                "inputs: unknown input {n:?}; inputs are \"features\", \"view_dir\" and \"alpha\""
            ))
        })?);
    }
    let mut out = Vec::new();
    for (i, (outputs, ins, w, b, act)) in layers.iter().enumerate() {
        let activation = vksplat::mlp::Activation::parse(act).ok_or_else(|| {
            value_err(format!(
                "layer {i}: unknown activation {act:?}; use relu, sigmoid, tanh or none"
            ))
        })?;
        out.push(vksplat::mlp::Layer {
            inputs: *ins,
            outputs: *outputs,
            weight: floats(w, &format!("layer {i} weight"), outputs * ins)?,
            bias: floats(b, &format!("layer {i} bias"), *outputs)?,
            activation,
        });
    }
    let mlp = Mlp {
        inputs: parsed,
        layers: out,
    };
    // The file's checks: layer count, widths, chaining, 3 outputs, finite weights.
    let bytes = mlp.to_safetensors();
    Mlp::parse(&bytes, None).map_err(|e| value_err(format!("shader: {e}")))?;
    Ok(PyByteArray::new(py, &bytes))
}

/// A shader file (`render --shader`'s, with its sidecar .json if any) as safetensors bytes
/// with the description inside.
#[pyfunction]
fn shader_file<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyByteArray>> {
    let mlp = Mlp::load(&path).map_err(|e| value_err(e.to_string()))?;
    Ok(PyByteArray::new(py, &mlp.to_safetensors()))
}

/// The inputs and layers of shader bytes.
#[pyfunction]
fn shader_layers(bytes: &[u8]) -> PyResult<ShaderLayers> {
    let mlp = Mlp::parse(bytes, None).map_err(|e| value_err(format!("shader: {e}")))?;
    let inputs = mlp.inputs.iter().map(|i| i.name().to_string()).collect();
    let layers = mlp
        .layers
        .iter()
        .map(|l| {
            (
                l.outputs,
                l.inputs,
                bytemuck::cast_slice(&l.weight).to_vec(),
                bytemuck::cast_slice(&l.bias).to_vec(),
                l.activation.name().to_string(),
            )
        })
        .collect();
    Ok((inputs, layers))
}

/// Gaussians as they cross for a gradient: N, then means, quats, scales, opacities and
/// colours as f32 bytes; `sh_degree` Some for SH coefficients `N x (d+1)^2 x 3`, None for
/// `channels` direct values per Gaussian.
type ParamsTuple<'a> = (
    usize,
    &'a [u8],
    &'a [u8],
    &'a [u8],
    &'a [u8],
    &'a [u8],
    Option<u32>,
    usize,
);

fn splat_params(t: &ParamsTuple) -> PyResult<SplatParams<f32>> {
    let (n, means, quats, scales, opacities, colors, sh_degree, channels) = *t;
    let colors = match sh_degree {
        Some(d) if d <= 3 => ColorParams::Sh {
            degree: d,
            coeffs: floats(colors, "colors", n * ((d + 1) * (d + 1)) as usize * 3)?,
        },
        Some(d) => return Err(value_err(format!("sh_degree must be 0..3, got {d}"))),
        None => ColorParams::Direct {
            channels,
            values: floats(colors, "colors", n * channels)?,
        },
    };
    let p = SplatParams {
        means: rows(&floats(means, "means", n * 3)?),
        quats: rows(&floats(quats, "quats", n * 4)?),
        scales: rows(&floats(scales, "scales", n * 3)?),
        opacities: floats(opacities, "opacities", n)?,
        colors,
    };
    p.validate().map_err(value_err)?;
    Ok(p)
}

fn diff_options(background: &[f32], kernel: &str, channels: usize) -> PyResult<RenderOptions> {
    let kernel = kernel.parse().map_err(|e: String| value_err(e))?;
    if !background.is_empty() && background.len() != channels {
        return Err(value_err(format!(
            "backgrounds must have {channels} values per camera, got {}",
            background.len()
        )));
    }
    let mut bg = [0f32; 3];
    if channels == 3 && background.len() == 3 {
        bg.copy_from_slice(background);
    }
    Ok(RenderOptions {
        background: bg,
        kernel,
        ..Default::default()
    })
}

fn pixel_grads(
    grad_color: Option<&[u8]>,
    grad_alpha: Option<&[u8]>,
    grad_depth: Option<&[u8]>,
    pixels: usize,
    channels: usize,
) -> PyResult<PixelGrads<f32>> {
    let f = |b: Option<&[u8]>, what: &str, count: usize| -> PyResult<Vec<f32>> {
        b.map_or(Ok(Vec::new()), |b| floats(b, what, count))
    };
    Ok(PixelGrads {
        color: f(grad_color, "grad_colors", pixels * channels)?,
        alpha: f(grad_alpha, "grad_alphas", pixels)?,
        depth: f(grad_depth, "grad_depths", pixels)?,
    })
}

fn grads_dict<'py, T: bytemuck::Pod>(
    py: Python<'py>,
    g: &SplatGrads<T>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("means", byte_array(py, &g.means))?;
    d.set_item("quats", byte_array(py, &g.quats))?;
    d.set_item("scales", byte_array(py, &g.scales))?;
    d.set_item("opacities", byte_array(py, &g.opacities))?;
    d.set_item("colors", byte_array(py, &g.colors))?;
    d.set_item("means2d", byte_array(py, &g.means2d))?;
    d.set_item("absgrad", byte_array(py, &g.absgrad))?;
    Ok(d)
}

/// The differentiable rasterizer on a Vulkan device: a forward pass that keeps its state
/// and the backward pass that reads it.
#[pyclass(module = "vksplat._native", name = "Rasterizer", frozen)]
struct PyRasterizer {
    state: Mutex<DiffRasterizer>,
    device: String,
    validation: bool,
}

/// What `Rasterizer.forward` returns: colour (`H x W x 3`, or `H x W x D` for D direct
/// channels other than 3), alpha, depth, the token of
/// the pass, and per Gaussian the projection (12 floats: mean2d x y, opacity, -, conic
/// A B C, depth, colour r g b, radius).
type ForwardOut<'py> = (
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
    u64,
    Bound<'py, PyByteArray>,
);

#[pymethods]
impl PyRasterizer {
    #[new]
    #[pyo3(signature = (device=None, validation=false))]
    fn new(py: Python<'_>, device: Option<String>, validation: bool) -> PyResult<Self> {
        py.detach(|| {
            guarded(|| {
                let (ctx, name, validation) = open_context(device, validation)?;
                let r = DiffRasterizer::new(ctx).map_err(|e| py_err(e.into()))?;
                Ok(PyRasterizer {
                    state: Mutex::new(r),
                    device: name,
                    validation,
                })
            })
        })
    }

    /// The device's name.
    #[getter]
    fn device(&self) -> &str {
        &self.device
    }

    /// `deterministic` (default), `float-atomics` or `cas`.
    fn set_accumulation(&self, mode: &str) -> PyResult<()> {
        let mode: Accumulation = mode.parse().map_err(|e: String| value_err(e))?;
        let mut st = self.state.lock().map_err(|_| {
            PyRuntimeError::new_err("the rasterizer failed earlier; create a new one")
        })?;
        st.renderer()
            .set_gradient_accumulation(mode)
            .map_err(|e| py_err(e.into()))
    }

    /// Device milliseconds of the last forward and backward passes' stages.
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        if let Ok(mut st) = self.state.lock() {
            let r = st.renderer();
            for (name, ms) in r.timings().stages() {
                d.set_item(format!("forward/{name}"), ms)?;
            }
            for (name, ms) in r.backward_timings() {
                d.set_item(format!("backward/{name}"), ms)?;
            }
        }
        Ok(d)
    }

    #[pyo3(signature = (params, camera, background, kernel, shader=None))]
    fn forward<'py>(
        &self,
        py: Python<'py>,
        params: ParamsTuple,
        camera: CamTuple,
        background: Vec<f32>,
        kernel: &str,
        shader: Option<&[u8]>,
    ) -> PyResult<ForwardOut<'py>> {
        let p = splat_params(&params)?;
        let cam = to_camera(&camera)?;
        let shader = shader_of(shader)?;
        let opts = diff_options(&background, kernel, image_channels(&p, &shader)?)?;
        let (frame, token, projected) = py.detach(|| {
            guarded(|| {
                let mut st = self.state.lock().map_err(|_| {
                    PyRuntimeError::new_err("the rasterizer failed earlier; create a new one")
                })?;
                st.set_shader(shader.as_ref())
                    .map_err(|e| py_err(e.into()))?;
                let (frame, token) = st.forward(&p, &cam, &opts).map_err(|e| py_err(e.into()))?;
                let projected = st.projected().map_err(|e| py_err(e.into()))?;
                check_validation(st.renderer().ctx(), self.validation)?;
                Ok((frame, token, projected))
            })
        })?;
        // Direct channels other than RGB come back as the frame's feature channels.
        let color = if frame.feature_count > 0 {
            byte_array(py, &frame.features)
        } else {
            byte_array(py, &frame.color)
        };
        Ok((
            color,
            byte_array(py, &frame.alpha),
            byte_array(py, &frame.depth),
            token,
            byte_array(py, &projected),
        ))
    }

    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (params, camera, background, kernel, token, grad_color=None, grad_alpha=None, grad_depth=None, shader=None))]
    fn backward<'py>(
        &self,
        py: Python<'py>,
        params: ParamsTuple,
        camera: CamTuple,
        background: Vec<f32>,
        kernel: &str,
        token: u64,
        grad_color: Option<&[u8]>,
        grad_alpha: Option<&[u8]>,
        grad_depth: Option<&[u8]>,
        shader: Option<&[u8]>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let p = splat_params(&params)?;
        let cam = to_camera(&camera)?;
        let shader = shader_of(shader)?;
        let channels = image_channels(&p, &shader)?;
        let opts = diff_options(&background, kernel, channels)?;
        let pixels = cam.width as usize * cam.height as usize;
        let g = pixel_grads(grad_color, grad_alpha, grad_depth, pixels, channels)?;
        let (grads, shader_grads) = py.detach(|| {
            guarded(|| {
                let mut st = self.state.lock().map_err(|_| {
                    PyRuntimeError::new_err("the rasterizer failed earlier; create a new one")
                })?;
                st.set_shader(shader.as_ref())
                    .map_err(|e| py_err(e.into()))?;
                let out = if shader.is_some() {
                    st.backward_shaded(&p, &cam, &opts, token, &g)
                        .map(|(g, m)| (g, Some(m)))
                } else {
                    st.backward(&p, &cam, &opts, token, &g).map(|g| (g, None))
                }
                .map_err(|e| py_err(e.into()))?;
                check_validation(st.renderer().ctx(), self.validation)?;
                Ok(out)
            })
        })?;
        let d = grads_dict(py, &grads)?;
        if let Some(m) = &shader_grads {
            shader_grads_into(py, &d, m)?;
        }
        Ok(d)
    }
}

/// The f64 CPU reference forward pass: colour (`H x W x D`, or 3 shaded), alpha and
/// depth as f64 bytes.
#[pyfunction]
#[pyo3(signature = (params, camera, background, kernel, shader=None))]
fn reference_forward<'py>(
    py: Python<'py>,
    params: ParamsTuple,
    camera: CamTuple,
    background: Vec<f32>,
    kernel: &str,
    shader: Option<&[u8]>,
) -> PyResult<(
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
)> {
    let p = splat_params(&params)?;
    let cam = to_camera(&camera)?;
    let shader = shader_of(shader)?;
    let channels = image_channels(&p, &shader)?;
    let opts = diff_options(&background, kernel, channels)?;
    let bg = reference_background(&background, channels);
    let img = py.detach(|| {
        guarded(|| {
            let p = p.to_f64();
            match &shader {
                Some(mlp) => {
                    let bg3 = [bg[0], bg[1], bg[2]];
                    vksplat::cpu::backward::forward_shaded(
                        &p,
                        &cam,
                        &opts,
                        mlp,
                        &MlpParams::of(mlp),
                        bg3,
                    )
                }
                None => vksplat::cpu::backward::forward(&p, &cam, &opts, &bg),
            }
            .map_err(value_err)
        })
    })?;
    Ok((
        byte_array(py, &img.color),
        byte_array(py, &img.alpha),
        byte_array(py, &img.depth),
    ))
}

fn reference_background(background: &[f32], channels: usize) -> Vec<f64> {
    if background.is_empty() {
        vec![0.0; channels]
    } else {
        background.iter().map(|&b| b as f64).collect()
    }
}

/// The f64 CPU reference backward pass: gradients as f64 bytes.
#[pyfunction]
#[pyo3(signature = (params, camera, background, kernel, grad_color=None, grad_alpha=None, grad_depth=None, shader=None))]
#[allow(clippy::too_many_arguments)]
fn reference_backward<'py>(
    py: Python<'py>,
    params: ParamsTuple,
    camera: CamTuple,
    background: Vec<f32>,
    kernel: &str,
    grad_color: Option<&[u8]>,
    grad_alpha: Option<&[u8]>,
    grad_depth: Option<&[u8]>,
    shader: Option<&[u8]>,
) -> PyResult<Bound<'py, PyDict>> {
    let p = splat_params(&params)?;
    let cam = to_camera(&camera)?;
    let shader = shader_of(shader)?;
    let channels = image_channels(&p, &shader)?;
    let opts = diff_options(&background, kernel, channels)?;
    let bg = reference_background(&background, channels);
    let pixels = cam.width as usize * cam.height as usize;
    let g = pixel_grads(grad_color, grad_alpha, grad_depth, pixels, channels)?;
    let g64 = PixelGrads {
        color: g.color.iter().map(|&x| x as f64).collect(),
        alpha: g.alpha.iter().map(|&x| x as f64).collect(),
        depth: g.depth.iter().map(|&x| x as f64).collect(),
    };
    let (grads, shader_grads) = py.detach(|| {
        guarded(|| {
            let p = p.to_f64();
            match &shader {
                Some(mlp) => {
                    let bg3 = [bg[0], bg[1], bg[2]];
                    let w = MlpParams::of(mlp);
                    vksplat::cpu::backward::backward_shaded(&p, &cam, &opts, mlp, &w, bg3, &g64)
                        .map(|(g, m)| (g, Some(m)))
                }
                None => {
                    vksplat::cpu::backward::backward(&p, &cam, &opts, &bg, &g64).map(|g| (g, None))
                }
            }
            .map_err(value_err)
        })
    })?;
    let d = grads_dict(py, &grads)?;
    if let Some(m) = &shader_grads {
        shader_grads_into(py, &d, m)?;
    }
    Ok(d)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<PyRenderer>()?;
    m.add_class::<PyRasterizer>()?;
    m.add_function(wrap_pyfunction!(reference_forward, m)?)?;
    m.add_function(wrap_pyfunction!(reference_backward, m)?)?;
    m.add_function(wrap_pyfunction!(shader_from_layers, m)?)?;
    m.add_function(wrap_pyfunction!(shader_file, m)?)?;
    m.add_function(wrap_pyfunction!(shader_layers, m)?)?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(demo, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(scene_from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(load_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(save_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(orbit, m)?)?;
    m.add_function(wrap_pyfunction!(default_camera, m)?)?;
    m.add_function(wrap_pyfunction!(look_at, m)?)?;
    m.add_function(wrap_pyfunction!(bulk_centre, m)?)?;
    m.add_function(wrap_pyfunction!(render_cpu, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(encode_png, m)?)?;
    m.add_function(wrap_pyfunction!(save_image, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
