//! Neural shaders as safetensors bytes: parsing them, building one from its layers,
//! reading a shader file and listing a shader's layers.

use crate::arrays::floats;
use crate::errors::value_err;
use pyo3::prelude::*;
use pyo3::types::PyByteArray;
use std::path::PathBuf;
use verisplat::fields::mlp::Mlp;

/// A layer crossing to or from Python: outputs, inputs, weight and bias as f32 bytes,
/// activation.
type LayerTuple = (usize, usize, Vec<u8>, Vec<u8>, String);
/// A network's inputs and layers.
type ShaderLayers = (Vec<String>, Vec<LayerTuple>);

/// A neural shader given as safetensors bytes (`Shader.to_bytes()`).
pub(crate) fn shader_of(bytes: Option<&[u8]>) -> PyResult<Option<Mlp>> {
    bytes
        .map(|b| Mlp::parse(b, None).map_err(|e| value_err(format!("shader: {e}"))))
        .transpose()
}

/// A network built from its layers (weight `outputs x inputs` and bias as f32 bytes, and
/// the activation) and inputs, checked as a shader file is: its safetensors bytes.
#[pyfunction]
pub(crate) fn shader_from_layers<'py>(
    py: Python<'py>,
    inputs: Vec<String>,
    layers: Vec<LayerTuple>,
) -> PyResult<Bound<'py, PyByteArray>> {
    let mut parsed = Vec::new();
    for n in &inputs {
        parsed.push(verisplat::fields::mlp::MlpInput::parse(n).ok_or_else(|| {
            value_err(format!(
                "inputs: unknown input {n:?}; inputs are \"features\", \"view_dir\" and \"alpha\""
            ))
        })?);
    }
    let mut out = Vec::new();
    for (i, (outputs, ins, w, b, act)) in layers.iter().enumerate() {
        let activation = verisplat::fields::mlp::Activation::parse(act).ok_or_else(|| {
            value_err(format!(
                "layer {i}: unknown activation {act:?}; use relu, sigmoid, tanh or none"
            ))
        })?;
        out.push(verisplat::fields::mlp::Layer {
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
pub(crate) fn shader_file<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<Bound<'py, PyByteArray>> {
    let mlp = Mlp::load(&path).map_err(|e| value_err(e.to_string()))?;
    Ok(PyByteArray::new(py, &mlp.to_safetensors()))
}

/// The inputs and layers of shader bytes.
#[pyfunction]
pub(crate) fn shader_layers(bytes: &[u8]) -> PyResult<ShaderLayers> {
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
