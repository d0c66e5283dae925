//! Rendering: checking a render request, the Vulkan `Renderer` class (which keeps the
//! last scene uploaded) and the CPU reference renderer.

use crate::arrays::byte_array;
use crate::cameras::{to_camera, CamTuple};
use crate::device::{check_validation, open_context};
use crate::errors::{guarded, py_err, value_err};
use crate::scene::PyScene;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyDict};
use std::sync::Mutex;
use verisplat::core::camera::Camera;
use verisplat::core::frame::Frame;
use verisplat::core::model::surface::{surface_planes, NormalSpace};
use verisplat::cpu::RenderOptions;
use verisplat::render::{FrameRequest, Rendered};
use verisplat::render::{GpuRenderer, GpuScene};

/// The planes a render returns: colour `B x H x W x 3`, alpha and depth `B x H x W`,
/// features `B x H x W x K`, each as `f32` bytes, `None` where not asked for.
type Planes<'py> = (
    Option<Bound<'py, PyByteArray>>,
    Option<Bound<'py, PyByteArray>>,
    Option<Bound<'py, PyByteArray>>,
    Option<Bound<'py, PyByteArray>>,
);

/// What a render returns and how.
struct Want {
    rgb: bool,
    alpha: bool,
    depth: bool,
    features: bool,
    /// The surface pass (normals in this space and the median depth), returned in the
    /// features plane as four channels per pixel: the unit normal and the median depth.
    surface: Option<NormalSpace>,
}

/// Per-frame options as the Python side passes them: background, SH degree, scale
/// modifier, max scale, min opacity, antialiased (None: the scene's flag), kernel (None:
/// the scene's), rules (None: the scene's), near plane (None: the rules' default) and the
/// reproducible mode.
type OptTuple = (
    [f32; 3],
    Option<u32>,
    f32,
    Option<f32>,
    Option<f32>,
    Option<bool>,
    Option<String>,
    Option<String>,
    Option<f32>,
    bool,
);

/// The planes wanted: rgb, alpha, depth, features, and the surface pass's normal space
/// (`"camera"` or `"world"`; None: no surface pass).
type WantTuple = (bool, bool, bool, bool, Option<String>);

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
    let (
        background,
        sh_degree,
        scale_modifier,
        max_scale,
        min_opacity,
        antialiased,
        kernel,
        rules,
        near_plane,
        reproducible,
    ) = options;
    if let Some(d) = sh_degree {
        if d > 3 {
            return Err(value_err(format!("sh_degree must be 0 to 3, got {d}")));
        }
    }
    let kernel = match kernel {
        Some(k) => k
            .parse::<verisplat::cpu::SplatKernel>()
            .map_err(value_err)?,
        None => scene.raw.kernel,
    };
    let rules = match rules {
        Some(r) => r.parse::<verisplat::cpu::Rules>().map_err(value_err)?,
        None => scene.raw.rules,
    };
    let opts = RenderOptions {
        background,
        antialiased: antialiased.unwrap_or(scene.raw.antialiased),
        scale_modifier,
        max_scale,
        min_opacity,
        sh_degree,
        kernel,
        rules,
        near_plane,
        reproducible,
    };
    opts.validate().map_err(value_err)?;
    let (rgb, alpha, depth, features, surface) = want;
    let surface = surface
        .map(|s| s.parse::<NormalSpace>().map_err(value_err))
        .transpose()?;
    if features && surface.is_some() {
        return Err(value_err(
            "mode 'features' and the surface pass (normal, median-depth) are separate renders; ask for one",
        ));
    }
    check_features(scene, features)?;
    Ok(Request {
        opts,
        cams: self::cameras(cameras)?,
        want: Want {
            rgb,
            alpha,
            depth,
            features,
            surface,
        },
    })
}

/// A surface frame's features turned into what the Python side reads: per pixel the unit
/// normal in `space` (0 where alpha is 0) and the median depth (0 where the
/// transmittance never reaches 0.5).
fn finish_surface(mut frame: Frame, cam: &Camera, space: NormalSpace) -> Frame {
    let camera = (space == NormalSpace::Camera).then_some(cam);
    let planes = surface_planes(&frame.features, &frame.alpha, camera);
    frame.features = planes
        .normals
        .iter()
        .zip(&planes.median_depth)
        .flat_map(|(n, &d)| [n[0], n[1], n[2], d])
        .collect();
    frame
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
    let features = (want.features || want.surface.is_some())
        .then(|| byte_array(py, &gather(&|f| &f.features)));
    (rgb, alpha, depth, features)
}

/// State behind a renderer's lock. The uploaded scene is declared first so it is freed
/// before the renderer (and its device).
struct RendererState {
    features: Option<(u64, verisplat::render::GpuFeatures)>,
    /// The surface pass's axes of the last scene that rendered one.
    surface: Option<(u64, verisplat::render::GpuFeatures)>,
    scene: Option<(u64, GpuScene)>,
    gpu: GpuRenderer,
    uploads: u64,
    frames: u64,
    timings: Vec<(&'static str, f64)>,
}

/// The Vulkan renderer: pipelines and per-frame buffers, and the last scene uploaded.
#[pyclass(module = "verisplat._native", name = "Renderer", frozen)]
pub(crate) struct PyRenderer {
    state: Mutex<RendererState>,
    device: String,
    validation: bool,
}

#[pymethods]
impl PyRenderer {
    /// Opens `device` (index or part of its name; default: discrete, then integrated,
    /// then CPU; also VERISPLAT_DEVICE). VERISPLAT_VALIDATE=1 turns the validation layer on,
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
                        surface: None,
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
        let surface = want.surface;
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
                if surface.is_some() && st.surface.as_ref().map(|(id, _)| *id) != Some(scene.id) {
                    st.surface = None;
                    let uploaded = st
                        .gpu
                        .upload_surface(&scene.act)
                        .map_err(|e| py_err(e.into()))?;
                    st.surface = Some((scene.id, uploaded));
                }
                let gpu_scene = &st.scene.as_ref().expect("uploaded above").1;
                let mut frames = Vec::with_capacity(cams.len());
                for cam in &cams {
                    let frame = match (&st.features, features, &st.surface, surface) {
                        (_, _, Some((_, f)), Some(space)) => st
                            .gpu
                            .render(&FrameRequest::new(gpu_scene, cam, &opts).features(f))
                            .and_then(Rendered::into_frame)
                            .map(|frame| finish_surface(frame, cam, space)),
                        (Some((_, f)), true, _, _) => st
                            .gpu
                            .render(&FrameRequest::new(gpu_scene, cam, &opts).features(f))
                            .and_then(Rendered::into_frame),
                        _ => st
                            .gpu
                            .render(&FrameRequest::new(gpu_scene, cam, &opts))
                            .and_then(Rendered::into_frame),
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
pub(crate) fn render_cpu<'py>(
    py: Python<'py>,
    scene: &PyScene,
    cameras: Vec<CamTuple>,
    options: OptTuple,
    want: WantTuple,
) -> PyResult<Planes<'py>> {
    let Request { opts, cams, want } = request(scene, &cameras, options, want)?;
    let features = want.features;
    let surface = want.surface;
    let frames = py.detach(|| {
        guarded(|| {
            Ok(cams
                .iter()
                .map(|cam| {
                    if let Some(space) = surface {
                        let frame = verisplat::cpu::surface::render_surface(&scene.act, cam, &opts);
                        finish_surface(frame, cam, space)
                    } else if features {
                        verisplat::cpu::render_features(&scene.act, cam, &opts)
                    } else {
                        verisplat::cpu::render(&scene.act, cam, &opts)
                    }
                })
                .collect::<Vec<_>>())
        })
    })?;
    Ok(planes(py, &frames, &want))
}
