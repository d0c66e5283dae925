//! Differentiable rasterization on a Vulkan device: the `Rasterizer` class (forward and
//! backward passes for torch) and the conversions of Gaussians, options and gradients
//! it shares with the CPU reference passes.

use crate::arrays::{byte_array, floats, rows};
use crate::cameras::{to_camera, CamTuple};
use crate::device::{check_validation, open_context};
use crate::errors::{guarded, py_err, value_err};
use crate::shader::shader_of;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyDict};
use std::sync::Mutex;
use verisplat::core::model::grad::{ColorParams, PixelGrads, SplatGrads, SplatParams};
use verisplat::cpu::RenderOptions;
use verisplat::fields::mlp::{Mlp, MlpParams};
use verisplat::render::backward::differentiable::{Accumulation, DiffRasterizer};

/// The channels of the image a forward pass returns: 3 when shaded.
pub(crate) fn image_channels(p: &SplatParams<f32>, shader: &Option<Mlp>) -> PyResult<usize> {
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

pub(crate) fn shader_grads_into<'py, T: bytemuck::Pod>(
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

/// Gaussians as they cross for a gradient: N, then means, quats, scales, opacities and
/// colours as f32 bytes; `sh_degree` Some for SH coefficients `N x (d+1)^2 x 3`, None for
/// `channels` direct values per Gaussian.
pub(crate) type ParamsTuple<'a> = (
    usize,
    &'a [u8],
    &'a [u8],
    &'a [u8],
    &'a [u8],
    &'a [u8],
    Option<u32>,
    usize,
);

pub(crate) fn splat_params(t: &ParamsTuple) -> PyResult<SplatParams<f32>> {
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

/// The rasterizer's rules as the Python side names them (`"original"`, `"gsplat"`) and
/// the near plane (None: the rules' default).
pub(crate) type RulesArg<'a> = (&'a str, Option<f32>);

/// What every differentiable entry point reads from its arguments: the Gaussians, the
/// camera, the shader, the image's channels and the render options.
pub(crate) struct DiffInputs {
    pub(crate) p: SplatParams<f32>,
    pub(crate) cam: verisplat::core::camera::Camera,
    pub(crate) shader: Option<Mlp>,
    pub(crate) channels: usize,
    pub(crate) opts: RenderOptions,
}

/// Checks and converts the arguments every differentiable entry point takes.
pub(crate) fn diff_inputs(
    params: &ParamsTuple,
    camera: &CamTuple,
    shader: Option<&[u8]>,
    background: &[f32],
    kernel: &str,
    antialiased: bool,
    rules: RulesArg,
) -> PyResult<DiffInputs> {
    let p = splat_params(params)?;
    let cam = to_camera(camera)?;
    let shader = shader_of(shader)?;
    let channels = image_channels(&p, &shader)?;
    let opts = diff_options(background, kernel, antialiased, channels, rules)?;
    Ok(DiffInputs {
        p,
        cam,
        shader,
        channels,
        opts,
    })
}

fn diff_options(
    background: &[f32],
    kernel: &str,
    antialiased: bool,
    channels: usize,
    (rules, near_plane): RulesArg,
) -> PyResult<RenderOptions> {
    let kernel = kernel.parse().map_err(|e: String| value_err(e))?;
    let rules = rules.parse().map_err(|e: String| value_err(e))?;
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
    let opts = RenderOptions {
        background: bg,
        kernel,
        antialiased,
        rules,
        near_plane,
        ..Default::default()
    };
    opts.validate().map_err(value_err)?;
    Ok(opts)
}

pub(crate) fn pixel_grads(
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

pub(crate) fn grads_dict<'py, T: bytemuck::Pod>(
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
    d.set_item("screen", byte_array(py, &g.screen))?;
    Ok(d)
}

/// The differentiable rasterizer on a Vulkan device: a forward pass that keeps its state
/// and the backward pass that reads it.
#[pyclass(module = "verisplat._native", name = "Rasterizer", frozen)]
pub(crate) struct PyRasterizer {
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

    /// The last frame's sorted pairs, and the bands its backward pass was split into to
    /// fit the device's storage bindings (1 each for a pass in one piece).
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        if let Ok(mut st) = self.state.lock() {
            let r = st.renderer();
            d.set_item("pairs", r.stats().pairs)?;
            let (rows, pairs) = r.backward_bands();
            d.set_item("backward_pixel_bands", rows)?;
            d.set_item("backward_pair_bands", pairs)?;
        }
        Ok(d)
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

    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (params, camera, background, kernel, shader=None, antialiased=false, rules="original", near_plane=None, reproducible=false))]
    fn forward<'py>(
        &self,
        py: Python<'py>,
        params: ParamsTuple,
        camera: CamTuple,
        background: Vec<f32>,
        kernel: &str,
        shader: Option<&[u8]>,
        antialiased: bool,
        rules: &str,
        near_plane: Option<f32>,
        reproducible: bool,
    ) -> PyResult<ForwardOut<'py>> {
        let DiffInputs {
            p,
            cam,
            shader,
            mut opts,
            ..
        } = diff_inputs(
            &params,
            &camera,
            shader,
            &background,
            kernel,
            antialiased,
            (rules, near_plane),
        )?;
        opts.reproducible = reproducible;
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
    #[pyo3(signature = (params, camera, background, kernel, token, grad_color=None, grad_alpha=None, grad_depth=None, shader=None, screen=false, antialiased=false, rules="original", near_plane=None, reproducible=false))]
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
        screen: bool,
        antialiased: bool,
        rules: &str,
        near_plane: Option<f32>,
        reproducible: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let DiffInputs {
            p,
            cam,
            shader,
            channels,
            mut opts,
        } = diff_inputs(
            &params,
            &camera,
            shader,
            &background,
            kernel,
            antialiased,
            (rules, near_plane),
        )?;
        opts.reproducible = reproducible;
        let pixels = cam.width as usize * cam.height as usize;
        let g = pixel_grads(grad_color, grad_alpha, grad_depth, pixels, channels)?;
        let (grads, shader_grads) = py.detach(|| {
            guarded(|| {
                let mut st = self.state.lock().map_err(|_| {
                    PyRuntimeError::new_err("the rasterizer failed earlier; create a new one")
                })?;
                st.set_shader(shader.as_ref())
                    .map_err(|e| py_err(e.into()))?;
                st.renderer()
                    .set_screen_grads(screen)
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
