//! The f64 CPU reference forward and backward passes of the differentiable rasterizer.

use crate::arrays::byte_array;
use crate::cameras::CamTuple;
use crate::differentiable::{
    diff_inputs, grads_dict, pixel_grads, shader_grads_into, DiffInputs, ParamsTuple,
};
use crate::errors::{guarded, value_err};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyDict};
use verisplat::core::model::grad::PixelGrads;
use verisplat::fields::mlp::MlpParams;

/// The f64 CPU reference forward pass: colour (`H x W x D`, or 3 shaded), alpha and
/// depth as f64 bytes.
#[pyfunction]
#[pyo3(signature = (params, camera, background, kernel, shader=None, antialiased=false, rules="original", near_plane=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn reference_forward<'py>(
    py: Python<'py>,
    params: ParamsTuple,
    camera: CamTuple,
    background: Vec<f32>,
    kernel: &str,
    shader: Option<&[u8]>,
    antialiased: bool,
    rules: &str,
    near_plane: Option<f32>,
) -> PyResult<(
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
    Bound<'py, PyByteArray>,
)> {
    let DiffInputs {
        p,
        cam,
        shader,
        channels,
        opts,
    } = diff_inputs(
        &params,
        &camera,
        shader,
        &background,
        kernel,
        antialiased,
        (rules, near_plane),
    )?;
    let bg = reference_background(&background, channels);
    let img = py.detach(|| {
        guarded(|| {
            let p = p.to_f64();
            match &shader {
                Some(mlp) => {
                    let bg3 = [bg[0], bg[1], bg[2]];
                    verisplat::cpu::backward::forward_shaded(
                        &p,
                        &cam,
                        &opts,
                        mlp,
                        &MlpParams::of(mlp),
                        bg3,
                    )
                }
                None => verisplat::cpu::backward::forward(&p, &cam, &opts, &bg),
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
#[pyo3(signature = (params, camera, background, kernel, grad_color=None, grad_alpha=None, grad_depth=None, shader=None, antialiased=false, rules="original", near_plane=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn reference_backward<'py>(
    py: Python<'py>,
    params: ParamsTuple,
    camera: CamTuple,
    background: Vec<f32>,
    kernel: &str,
    grad_color: Option<&[u8]>,
    grad_alpha: Option<&[u8]>,
    grad_depth: Option<&[u8]>,
    shader: Option<&[u8]>,
    antialiased: bool,
    rules: &str,
    near_plane: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let DiffInputs {
        p,
        cam,
        shader,
        channels,
        opts,
    } = diff_inputs(
        &params,
        &camera,
        shader,
        &background,
        kernel,
        antialiased,
        (rules, near_plane),
    )?;
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
                    verisplat::cpu::backward::backward_shaded(&p, &cam, &opts, mlp, &w, bg3, &g64)
                        .map(|(g, m)| (g, Some(m)))
                }
                None => verisplat::cpu::backward::backward(&p, &cam, &opts, &bg, &g64)
                    .map(|g| (g, None)),
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
