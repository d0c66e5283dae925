//! Scenes: the `Scene` class (its arrays, field, times, saving and filtering) and the
//! ways to make one: loading a file, the demo scene and scenes from arrays.

use crate::arrays::{byte_array, check_finite, floats, rows};
use crate::errors::{guarded, py_err, value_err};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use verisplat::core::scene::{self, ActivatedScene, Scene};
use verisplat::io;

static NEXT_SCENE_ID: AtomicU64 = AtomicU64::new(1);

/// A scene: the trainer's parameters as stored and the activated arrays the renderers
/// read. Immutable, so a renderer can keep its upload for as long as it sees the same id.
#[pyclass(module = "verisplat._native", name = "Scene", frozen)]
pub(crate) struct PyScene {
    pub(crate) raw: Scene,
    pub(crate) act: ActivatedScene,
    pub(crate) id: u64,
    pub(crate) source: String,
}

impl PyScene {
    pub(crate) fn new(raw: Scene, act: ActivatedScene, source: String) -> Self {
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
        let model = verisplat::fields::fit::model::Model::from_scene(&self.raw);
        let kernel = self.raw.kernel;
        let f = py.detach(|| {
            guarded(|| {
                verisplat::fields::fit::model::evaluate_at(
                    &model,
                    kernel,
                    &positions,
                    times.as_deref(),
                )
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

    /// The rasterizer's rules the file records ("original" unless a PLY says `gsplat`).
    #[getter]
    fn rules(&self) -> &'static str {
        self.raw.rules.name()
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

    /// Writes the scene in the format `path`'s name says (.ply, .splat, .spz,
    /// .compressed.ply, .sog, or DIR/meta.json for an unbundled SOG's files), atomically; an existing file is refused unless `overwrite`. `spz_axes` ("spec" or
    /// "raw") is the frame of an SPZ output (`spz::SpzAxes`).
    #[pyo3(signature = (path, overwrite=false, spz_axes="spec"))]
    fn save(&self, py: Python<'_>, path: PathBuf, overwrite: bool, spz_axes: &str) -> PyResult<()> {
        let axes: io::scene::spz::SpzAxes = spz_axes.parse().map_err(value_err)?;
        py.detach(|| {
            guarded(|| {
                let format = io::scene::write::OutputFormat::from_path(&path)
                    .map_err(|e| py_err(e.into()))?;
                if format == io::scene::write::OutputFormat::Sog
                    && axes == io::scene::spz::SpzAxes::Spec
                {
                    // A SOG bundle, or an unbundled SOG's several files.
                    return match io::scene::write::write_scene(&self.raw, &path, format, overwrite)
                    {
                        Ok(_) => Ok(()),
                        Err(io::scene::write::ConvertError::Encode { message, .. }) => {
                            Err(value_err(format!("{}: {message}", path.display())))
                        }
                        // The write error itself, so an existing file is FileExistsError.
                        Err(io::scene::write::ConvertError::Write(e)) => Err(py_err(e.into())),
                        Err(e) => Err(py_err(e.into())),
                    };
                }
                let bytes = match (format, axes) {
                    (io::scene::write::OutputFormat::Spz, axes) => {
                        io::scene::spz::to_bytes_v3_with_axes(&self.raw, axes)
                    }
                    (_, io::scene::spz::SpzAxes::Raw) => {
                        Err("is not an .spz file: spz_axes=\"raw\" applies to SPZ only".to_string())
                    }
                    (format, _) => io::scene::write::to_bytes(&self.raw, format),
                }
                .map_err(|m| value_err(format!("{}: {m}", path.display())))?;
                verisplat::io::output::write_bytes_atomically(&path, overwrite, &bytes)
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
/// (`iteration` picks point_cloud/iteration_N; default the largest); an SPZ file in
/// `spz_axes` ("spec" or "raw", `spz::SpzAxes`).
#[pyfunction]
#[pyo3(signature = (path, iteration=None, spz_axes="spec"))]
pub(crate) fn load(
    py: Python<'_>,
    path: PathBuf,
    iteration: Option<u64>,
    spz_axes: &str,
) -> PyResult<PyScene> {
    let axes: io::scene::spz::SpzAxes = spz_axes.parse().map_err(value_err)?;
    py.detach(|| {
        guarded(|| {
            let resolved =
                io::scene::resolve_scene_path_at(&path, iteration).map_err(|e| py_err(e.into()))?;
            let (raw, _) =
                io::scene::detect::load_with_axes(&resolved, axes).map_err(|e| py_err(e.into()))?;
            let act = raw.activated();
            Ok(PyScene::new(raw, act, resolved.display().to_string()))
        })
    })
}

/// The built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0).
#[pyfunction]
pub(crate) fn demo() -> PyScene {
    let raw = verisplat::io::demo::demo_scene();
    let act = raw.activated();
    PyScene::new(raw, act, "built-in demo scene (PLAYBOT)".into())
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
pub(crate) fn scene_from_arrays(
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
