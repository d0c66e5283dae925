//! The neural shader: a small per-pixel MLP that turns a rendered feature image (plus,
//! optionally, the pixel's view direction and alpha) into a colour.
//!
//! # File format
//! A [safetensors](https://huggingface.co/docs/safetensors) file, as PyTorch users export
//! one: each layer's weight (`out x in`, as `torch.nn.Linear` stores it) and bias (`out`)
//! are tensors (F32, F16, BF16 or F64), and the metadata entry `verisplat_mlp` holds a JSON
//! object listing the inputs and the layers in order:
//!
//! ```json
//! {"inputs": ["features", "view_dir", "alpha"],
//!  "layers": [{"weight": "0.weight", "bias": "0.bias", "activation": "relu"},
//!             {"weight": "2.weight", "bias": "2.bias", "activation": "sigmoid"}]}
//! ```
//!
//! `inputs` is a list of `features` (the K blended channels), `view_dir` (the unit
//! world-space direction from the camera centre through the pixel centre, 3 values) and
//! `alpha` (the pixel's `1 - T`), concatenated in the order given; `features` must be
//! there. Activations: `relu`, `sigmoid`, `tanh`, `none`. The last layer has 3 outputs:
//! the pixel's (straight) colour `c`; the written colour is `alpha * c + (1 - alpha) *
//! background`, so the background is applied after shading, with alpha.
//! The same information may instead come from a sidecar `FILE.json` beside the file.
//!
//! Evaluation is in f32 in a fixed order (for each output: the bias, then the products
//! in input order), the same on the CPU and in `glsl/render/forward/shade.comp`.

use crate::core::camera::Camera;
use std::path::{Path, PathBuf};

/// Largest width (inputs or outputs) of any layer, what the GPU shader holds per pixel.
pub const MAX_WIDTH: usize = crate::core::shader_interface::MAX_WIDTH as usize;
/// Most layers in one shader.
pub const MAX_LAYERS: usize = crate::core::shader_interface::MAX_LAYERS as usize;
/// The metadata key that describes the network.
pub const METADATA_KEY: &str = "verisplat_mlp";

/// An error in a shader file, naming it.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct MlpError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong, one sentence.
    pub message: String,
}

/// A layer's nonlinearity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// max(0, x).
    Relu,
    /// 1 / (1 + exp(-x)).
    Sigmoid,
    /// tanh(x).
    Tanh,
    /// x.
    None,
}

impl Activation {
    /// The activation a file names (`relu`, `sigmoid`, `tanh`, `none`; `identity` and
    /// `linear` for `none`; any case).
    pub fn parse(s: &str) -> Option<Self> {
        match s.to_ascii_lowercase().as_str() {
            "relu" => Some(Activation::Relu),
            "sigmoid" => Some(Activation::Sigmoid),
            "tanh" => Some(Activation::Tanh),
            "none" | "identity" | "linear" => Some(Activation::None),
            _ => None,
        }
    }

    /// The name a file gives it.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Relu => "relu",
            Activation::Sigmoid => "sigmoid",
            Activation::Tanh => "tanh",
            Activation::None => "none",
        }
    }

    /// The id the GPU shader switches on.
    pub fn shader_id(self) -> u32 {
        match self {
            Activation::None => 0,
            Activation::Relu => 1,
            Activation::Sigmoid => 2,
            Activation::Tanh => 3,
        }
    }

    /// Applies it, in f32 as the shader does.
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Activation::Relu => x.max(0.0),
            Activation::Sigmoid => 1.0 / (1.0 + (-x).exp()),
            Activation::Tanh => x.tanh(),
            Activation::None => x,
        }
    }
}

/// One of the values fed to the first layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MlpInput {
    /// The K feature channels.
    Features,
    /// The unit view direction (3 values, world space).
    ViewDir,
    /// The pixel's alpha.
    Alpha,
}

impl MlpInput {
    /// The input a file names (`features`, `view_dir` or `viewdir`, `alpha`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "features" => Some(MlpInput::Features),
            "view_dir" | "viewdir" => Some(MlpInput::ViewDir),
            "alpha" => Some(MlpInput::Alpha),
            _ => None,
        }
    }

    /// The name a file gives it.
    pub fn name(self) -> &'static str {
        match self {
            MlpInput::Features => "features",
            MlpInput::ViewDir => "view_dir",
            MlpInput::Alpha => "alpha",
        }
    }
}

/// A fully connected layer: `y = act(W x + b)`, `W` row-major `outputs x inputs`.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// Inputs.
    pub inputs: usize,
    /// Outputs.
    pub outputs: usize,
    /// Weights, row-major (`outputs` rows of `inputs`).
    pub weight: Vec<f32>,
    /// Biases.
    pub bias: Vec<f32>,
    /// Nonlinearity.
    pub activation: Activation,
}

/// A neural shader.
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    /// The first layer's inputs, in order.
    pub inputs: Vec<MlpInput>,
    /// The layers, first to last.
    pub layers: Vec<Layer>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Spec {
    inputs: Option<Vec<String>>,
    layers: Vec<LayerSpec>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LayerSpec {
    weight: String,
    bias: Option<String>,
    activation: String,
}

fn to_f32(view: &safetensors::tensor::TensorView, name: &str) -> Result<Vec<f32>, String> {
    use safetensors::Dtype;
    let b = view.data();
    let v: Vec<f32> = match view.dtype() {
        Dtype::F32 => b
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        Dtype::F64 => b
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
            .collect(),
        Dtype::F16 => b
            .chunks_exact(2)
            .map(|c| half_to_f32(u16::from_le_bytes([c[0], c[1]])))
            .collect(),
        Dtype::BF16 => b
            .chunks_exact(2)
            .map(|c| f32::from_bits((u16::from_le_bytes([c[0], c[1]]) as u32) << 16))
            .collect(),
        other => {
            return Err(format!(
                "tensor {name:?} is {other:?}; weights must be F32, F16, BF16 or F64"
            ))
        }
    };
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(format!(
            "tensor {name:?} holds {} at element {i}; weights must be finite",
            v[i]
        ));
    }
    Ok(v)
}

/// IEEE half to f32.
fn half_to_f32(h: u16) -> f32 {
    let sign = ((h >> 15) as u32) << 31;
    let exp = ((h >> 10) & 0x1f) as u32;
    let frac = (h & 0x3ff) as u32;
    let bits = match (exp, frac) {
        (0, 0) => sign,
        (0, f) => {
            // Subnormal: normalise.
            let mut e = 127 - 15 + 1;
            let mut f = f;
            while f & 0x400 == 0 {
                f <<= 1;
                e -= 1;
            }
            sign | (e << 23) | ((f & 0x3ff) << 13)
        }
        (0x1f, f) => sign | 0x7f80_0000 | (f << 13),
        (e, f) => sign | ((e + 127 - 15) << 23) | (f << 13),
    };
    f32::from_bits(bits)
}

impl Mlp {
    /// Reads a shader file (see the module docs).
    pub fn load(path: &Path) -> Result<Mlp, MlpError> {
        let bytes = std::fs::read(path).map_err(|e| MlpError {
            path: path.to_path_buf(),
            message: format!("cannot read: {e}"),
        })?;
        let sidecar = path.with_extension("json");
        let sidecar_text = if sidecar.is_file() && sidecar != path {
            Some(std::fs::read_to_string(&sidecar).map_err(|e| MlpError {
                path: sidecar.clone(),
                message: format!("cannot read: {e}"),
            })?)
        } else {
            None
        };
        Self::parse(&bytes, sidecar_text.as_deref()).map_err(|message| MlpError {
            path: path.to_path_buf(),
            message,
        })
    }

    /// Parses safetensors bytes; `sidecar` is the network description when the file's
    /// metadata has none.
    pub fn parse(bytes: &[u8], sidecar: Option<&str>) -> Result<Mlp, String> {
        let tensors = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| format!("is not a safetensors file: {e}"))?;
        let (_, meta) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| format!("is not a safetensors file: {e}"))?;
        let from_meta = meta.metadata().as_ref().and_then(|m| {
            m.iter()
                .find(|(k, _)| crate::core::former_name::matches_key(k, METADATA_KEY))
                .map(|(_, v)| v.clone())
        });
        let text = match (from_meta, sidecar) {
            (Some(t), _) => t,
            (None, Some(s)) => s.to_string(),
            (None, None) => {
                return Err(format!(
                    "has no {METADATA_KEY:?} metadata entry (nor a sidecar .json) listing the layers and activations; see README \"Neural shader\""
                ))
            }
        };
        let spec: Spec = serde_json::from_str(&text)
            .map_err(|e| format!("its {METADATA_KEY} description is not valid: {e}"))?;
        let input_names = spec.inputs.unwrap_or_else(|| vec!["features".into()]);
        let mut inputs = Vec::new();
        for n in &input_names {
            let i = MlpInput::parse(n).ok_or_else(|| {
                format!("unknown input {n:?}; inputs are \"features\", \"view_dir\" and \"alpha\"")
            })?;
            if inputs.contains(&i) {
                return Err(format!("input {n:?} is listed twice"));
            }
            inputs.push(i);
        }
        if !inputs.contains(&MlpInput::Features) {
            return Err("its inputs must include \"features\"".into());
        }
        if spec.layers.is_empty() {
            return Err("lists no layers".into());
        }
        if spec.layers.len() > MAX_LAYERS {
            return Err(format!(
                "has {} layers; at most {MAX_LAYERS} are supported",
                spec.layers.len()
            ));
        }
        let mut layers: Vec<Layer> = Vec::new();
        for (li, l) in spec.layers.iter().enumerate() {
            let activation = Activation::parse(&l.activation).ok_or_else(|| {
                format!(
                    "layer {li} has unknown activation {:?}; use relu, sigmoid, tanh or none",
                    l.activation
                )
            })?;
            let wv = tensors
                .tensor(&l.weight)
                .map_err(|_| format!("layer {li}: no tensor {:?}", l.weight))?;
            let shape = wv.shape();
            if shape.len() != 2 {
                return Err(format!(
                    "layer {li}: weight {:?} has shape {shape:?}; it must be 2-D (outputs x inputs)",
                    l.weight
                ));
            }
            let (outputs, ins) = (shape[0], shape[1]);
            if outputs == 0 || ins == 0 || outputs > MAX_WIDTH || ins > MAX_WIDTH {
                return Err(format!(
                    "layer {li}: weight {:?} is {outputs} x {ins}; widths must be 1 to {MAX_WIDTH}",
                    l.weight
                ));
            }
            if let Some(prev) = layers.last() {
                if prev.outputs != ins {
                    return Err(format!(
                        "layer {li}: weight {:?} takes {ins} inputs but layer {} gives {} outputs; the shapes do not chain",
                        l.weight,
                        li - 1,
                        prev.outputs
                    ));
                }
            }
            let weight = to_f32(&wv, &l.weight)?;
            let bias = match &l.bias {
                Some(b) => {
                    let bv = tensors
                        .tensor(b)
                        .map_err(|_| format!("layer {li}: no tensor {b:?}"))?;
                    if bv.shape() != [outputs] {
                        return Err(format!(
                            "layer {li}: bias {b:?} has shape {:?}; it must be [{outputs}]",
                            bv.shape()
                        ));
                    }
                    to_f32(&bv, b)?
                }
                None => vec![0.0; outputs],
            };
            layers.push(Layer {
                inputs: ins,
                outputs,
                weight,
                bias,
                activation,
            });
        }
        let last = layers.last().expect("at least one layer");
        if last.outputs != 3 {
            return Err(format!(
                "the last layer gives {} outputs; it must give 3 (R, G, B)",
                last.outputs
            ));
        }
        let mlp = Mlp { inputs, layers };
        let extra = mlp.extra_inputs();
        if mlp.layers[0].inputs <= extra {
            return Err(format!(
                "the first layer takes {} inputs, which leaves no feature channel after the {extra} other inputs",
                mlp.layers[0].inputs
            ));
        }
        Ok(mlp)
    }

    /// The network as a safetensors file that [`Mlp::parse`] (and `render --shader`) reads
    /// back to the same network: layer `i`'s tensors `i.weight` (`outputs x inputs`) and
    /// `i.bias`, F32, and the description in the metadata.
    pub fn to_safetensors(&self) -> Vec<u8> {
        use safetensors::tensor::TensorView;
        let input_names: Vec<&str> = self.inputs.iter().map(|i| i.name()).collect();
        let layers: Vec<serde_json::Value> = self
            .layers
            .iter()
            .enumerate()
            .map(|(i, l)| {
                serde_json::json!({
                    "weight": format!("{i}.weight"),
                    "bias": format!("{i}.bias"),
                    "activation": l.activation.name(),
                })
            })
            .collect();
        let description = serde_json::json!({ "inputs": input_names, "layers": layers });
        let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = self
            .layers
            .iter()
            .enumerate()
            .flat_map(|(i, l)| {
                let le = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
                [
                    (
                        format!("{i}.weight"),
                        vec![l.outputs, l.inputs],
                        le(&l.weight),
                    ),
                    (format!("{i}.bias"), vec![l.outputs], le(&l.bias)),
                ]
            })
            .collect();
        let views = bytes.iter().map(|(name, shape, data)| {
            let view = TensorView::new(safetensors::Dtype::F32, shape.clone(), data)
                .expect("the shape holds the data");
            (name.clone(), view)
        });
        let meta =
            std::collections::HashMap::from([(METADATA_KEY.to_string(), description.to_string())]);
        safetensors::serialize(views, Some(meta)).expect("F32 tensors of matching shapes")
    }

    /// Writes [`Self::to_safetensors`] to `path` (atomically; an existing file only with
    /// `overwrite`).
    pub fn save(
        &self,
        path: &Path,
        overwrite: bool,
    ) -> Result<(), crate::core::fsutil::WriteError> {
        crate::core::fsutil::write_bytes_atomically(path, overwrite, &self.to_safetensors())
    }

    /// Inputs besides the features (view direction 3, alpha 1).
    pub fn extra_inputs(&self) -> usize {
        self.inputs
            .iter()
            .map(|i| match i {
                MlpInput::Features => 0,
                MlpInput::ViewDir => 3,
                MlpInput::Alpha => 1,
            })
            .sum()
    }

    /// The feature channels (K) the network expects.
    pub fn feature_channels(&self) -> usize {
        self.layers[0].inputs - self.extra_inputs()
    }

    /// Checks that a scene's `k` channels are what the network takes.
    pub fn check_channels(&self, k: usize) -> Result<(), String> {
        let want = self.feature_channels();
        if k != want {
            return Err(format!(
                "the shader takes {want} feature channels but the scene has {k}{}",
                if k == 0 {
                    " (add them with --features FILE.npy or feat_* PLY properties)"
                } else {
                    ""
                }
            ));
        }
        Ok(())
    }

    /// The first layer's input vector for one pixel.
    pub fn input_vector(
        &self,
        features: &[f32],
        view_dir: [f32; 3],
        alpha: f32,
        out: &mut Vec<f32>,
    ) {
        out.clear();
        for i in &self.inputs {
            match i {
                MlpInput::Features => out.extend_from_slice(features),
                MlpInput::ViewDir => out.extend_from_slice(&view_dir),
                MlpInput::Alpha => out.push(alpha),
            }
        }
    }

    /// Evaluates the network on `x` (the first layer's inputs), in f32 in the documented
    /// order.
    pub fn eval(&self, x: &[f32]) -> [f32; 3] {
        let mut cur = x.to_vec();
        let mut next = Vec::with_capacity(MAX_WIDTH);
        for l in &self.layers {
            next.clear();
            for o in 0..l.outputs {
                let row = &l.weight[o * l.inputs..(o + 1) * l.inputs];
                let mut acc = l.bias[o];
                for (w, v) in row.iter().zip(&cur) {
                    acc += w * v;
                }
                next.push(l.activation.apply(acc));
            }
            std::mem::swap(&mut cur, &mut next);
        }
        [cur[0], cur[1], cur[2]]
    }

    /// Packs the network for the GPU shader: per layer a header of 4 u32 (inputs,
    /// outputs, activation, offset of its weights in floats from the start of the float
    /// area), then every layer's weights (row-major) followed by its biases. Returned as
    /// u32 words: `4 * MAX_LAYERS` header words, then the floats' bits.
    pub fn gpu_words(&self) -> Vec<u32> {
        let mut header = vec![0u32; 4 * MAX_LAYERS];
        let mut floats: Vec<f32> = Vec::new();
        for (i, l) in self.layers.iter().enumerate() {
            header[i * 4] = l.inputs as u32;
            header[i * 4 + 1] = l.outputs as u32;
            header[i * 4 + 2] = l.activation.shader_id();
            header[i * 4 + 3] = floats.len() as u32;
            floats.extend_from_slice(&l.weight);
            floats.extend_from_slice(&l.bias);
        }
        header.extend(floats.iter().map(|f| f.to_bits()));
        header
    }

    /// The weights and biases in the float layout of [`Self::gpu_words`] (after the
    /// header): per layer the weights (row-major), then the biases.
    pub fn flat_params(&self) -> Vec<f32> {
        self.layers
            .iter()
            .flat_map(|l| l.weight.iter().chain(&l.bias).copied())
            .collect()
    }

    /// Takes the weights and biases of [`Self::flat_params`]'s layout (as many values).
    pub fn set_flat_params(&mut self, flat: &[f32]) {
        let mut at = 0;
        for l in &mut self.layers {
            let (w, b) = (l.weight.len(), l.bias.len());
            l.weight.copy_from_slice(&flat[at..at + w]);
            l.bias.copy_from_slice(&flat[at + w..at + w + b]);
            at += w + b;
        }
    }

    /// Input layout flags for the shader: bit 0 view direction, bit 1 alpha, and the
    /// position of each input (bits 8.. : 2 bits per slot, in order: 0 features,
    /// 1 view_dir, 2 alpha; the count in bits 4..6).
    pub fn input_code(&self) -> u32 {
        let mut code = (self.inputs.len() as u32) << 4;
        for (slot, i) in self.inputs.iter().enumerate() {
            let id = match i {
                MlpInput::Features => 0,
                MlpInput::ViewDir => 1,
                MlpInput::Alpha => 2,
            };
            code |= id << (8 + 2 * slot);
        }
        code
    }
}

/// The neural shader's parameters, or their gradients, per layer: weights (row-major,
/// `outputs x inputs`, as `crate::fields::mlp::Layer`) and biases.
#[derive(Clone, Debug, PartialEq)]
pub struct MlpParams<T> {
    /// Weights per layer.
    pub weights: Vec<Vec<T>>,
    /// Biases per layer.
    pub biases: Vec<Vec<T>>,
}

impl MlpParams<f64> {
    /// The network's weights in f64.
    pub fn of(mlp: &Mlp) -> Self {
        MlpParams {
            weights: mlp
                .layers
                .iter()
                .map(|l| l.weight.iter().map(|&w| w as f64).collect())
                .collect(),
            biases: mlp
                .layers
                .iter()
                .map(|l| l.bias.iter().map(|&b| b as f64).collect())
                .collect(),
        }
    }

    /// Zeros of the same shape.
    pub fn zeros_like(&self) -> Self {
        MlpParams {
            weights: self.weights.iter().map(|w| vec![0.0; w.len()]).collect(),
            biases: self.biases.iter().map(|b| vec![0.0; b.len()]).collect(),
        }
    }
}

impl MlpParams<f32> {
    /// `mlp`'s parameters of the float layout of [`Mlp::gpu_words`] (after the header):
    /// per layer the weights (row-major), then the biases.
    pub fn from_flat(mlp: &Mlp, flat: &[f32]) -> Result<Self, String> {
        let want: usize = mlp.layers.iter().map(|l| (l.inputs + 1) * l.outputs).sum();
        if flat.len() != want {
            return Err(format!(
                "{} values for a network of {want} parameters",
                flat.len()
            ));
        }
        let mut at = 0;
        let mut out = MlpParams {
            weights: Vec::new(),
            biases: Vec::new(),
        };
        for l in &mlp.layers {
            let w = l.inputs * l.outputs;
            out.weights.push(flat[at..at + w].to_vec());
            out.biases.push(flat[at + w..at + w + l.outputs].to_vec());
            at += w + l.outputs;
        }
        Ok(out)
    }
}

/// The unit world-space direction from the camera centre through pixel `(x, y)`: pixel
/// `(i, j)` is evaluated at image position `(i, j)` of the reference's convention, the
/// point `((i + 0.5 - cx) / fx, (j + 0.5 - cy) / fy, 1)` in camera space.
pub fn view_dir(cam: &Camera, x: u32, y: u32) -> [f32; 3] {
    let d = glam::Vec3::new(
        (x as f32 + 0.5 - cam.cx) / cam.fx,
        (y as f32 + 0.5 - cam.cy) / cam.fy,
        1.0,
    );
    let w = cam.rotation.transpose() * d;
    (w / w.length()).to_array()
}

/// Shades a rendered feature image on the CPU: `features` is `width * height * k` floats
/// (pixel-major), `alpha` the frame's alpha; returns the colour,
/// `alpha * mlp(...) + (1 - alpha) * background` per pixel.
pub fn shade(
    mlp: &Mlp,
    cam: &Camera,
    features: &[f32],
    k: usize,
    alpha: &[f32],
    background: [f32; 3],
) -> Vec<[f32; 3]> {
    use rayon::prelude::*;
    let w = cam.width as usize;
    (0..alpha.len())
        .into_par_iter()
        .map_init(Vec::new, |x, p| {
            let dir = view_dir(cam, (p % w) as u32, (p / w) as u32);
            mlp.input_vector(&features[p * k..(p + 1) * k], dir, alpha[p], x);
            let c = mlp.eval(x);
            let a = alpha[p];
            let t = 1.0 - a;
            [
                a * c[0] + t * background[0],
                a * c[1] + t * background[1],
                a * c[2] + t * background[2],
            ]
        })
        .collect()
}
