//! The f64 reference of a shaded frame and its backward pass.
//!
//! A shaded frame (`render --shader`): the Gaussians' direct feature channels are blended
//! (no background), then per pixel the MLP turns the features (with the view direction and
//! alpha, as its inputs list) into a colour `c`, and the pixel is
//! `alpha * c + (1 - alpha) * background` (`crate::fields::mlp::shade`). Its backward pass
//! runs the MLP's per pixel, then the blend's with the feature gradients it produced.

use super::*;

pub use crate::fields::mlp::MlpParams;
use crate::fields::mlp::{Activation, Mlp, MlpInput};

/// Value and derivative of an activation at `x`.
fn activation64(a: Activation, x: f64) -> (f64, f64) {
    match a {
        Activation::Relu => (x.max(0.0), if x > 0.0 { 1.0 } else { 0.0 }),
        Activation::Sigmoid => {
            let s = 1.0 / (1.0 + (-x).exp());
            (s, s * (1.0 - s))
        }
        Activation::Tanh => {
            let t = x.tanh();
            (t, 1.0 - t * t)
        }
        Activation::None => (x, 1.0),
    }
}

/// The MLP on `x`: each layer's input and its activations' derivatives, and the output.
fn mlp_forward64(
    mlp: &Mlp,
    w: &MlpParams<f64>,
    x: &[f64],
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<f64>) {
    let mut inputs = Vec::with_capacity(mlp.layers.len());
    let mut derivs = Vec::with_capacity(mlp.layers.len());
    let mut cur = x.to_vec();
    for (i, l) in mlp.layers.iter().enumerate() {
        let mut next = Vec::with_capacity(l.outputs);
        let mut d = Vec::with_capacity(l.outputs);
        for o in 0..l.outputs {
            let row = &w.weights[i][o * l.inputs..(o + 1) * l.inputs];
            let z = w.biases[i][o] + row.iter().zip(&cur).map(|(a, b)| a * b).sum::<f64>();
            let (v, dv) = activation64(l.activation, z);
            next.push(v);
            d.push(dv);
        }
        inputs.push(std::mem::replace(&mut cur, next));
        derivs.push(d);
    }
    (inputs, derivs, cur)
}

/// Back through the MLP: adds the parameters' gradients to `g` and returns dL/d(input).
fn mlp_backward64(
    mlp: &Mlp,
    w: &MlpParams<f64>,
    inputs: &[Vec<f64>],
    derivs: &[Vec<f64>],
    g_out: &[f64],
    g: &mut MlpParams<f64>,
) -> Vec<f64> {
    let mut g_cur = g_out.to_vec();
    for (i, l) in mlp.layers.iter().enumerate().rev() {
        let mut g_in = vec![0.0; l.inputs];
        for o in 0..l.outputs {
            let gz = g_cur[o] * derivs[i][o];
            g.biases[i][o] += gz;
            for j in 0..l.inputs {
                g.weights[i][o * l.inputs + j] += gz * inputs[i][j];
                g_in[j] += gz * w.weights[i][o * l.inputs + j];
            }
        }
        g_cur = g_in;
    }
    g_cur
}

/// The MLP's input vector of one pixel (`Mlp::input_vector` in f64).
fn mlp_input64(mlp: &Mlp, features: &[f64], view_dir: [f32; 3], alpha: f64) -> Vec<f64> {
    let mut x = Vec::new();
    for i in &mlp.inputs {
        match i {
            MlpInput::Features => x.extend_from_slice(features),
            MlpInput::ViewDir => x.extend(view_dir.iter().map(|&v| v as f64)),
            MlpInput::Alpha => x.push(alpha),
        }
    }
    x
}

fn check_shaded(p: &SplatParams<f64>, mlp: &Mlp) -> Result<usize, String> {
    match &p.colors {
        ColorParams::Direct { channels, .. } => {
            mlp.check_channels(*channels)?;
            Ok(*channels)
        }
        ColorParams::Sh { .. } => {
            Err("a shaded frame blends direct feature channels, not SH".into())
        }
    }
}

/// A frame shaded by `mlp` (with the parameters `w`), in f64: colour (3 channels,
/// `alpha * mlp + (1 - alpha) * background`), alpha and depth.
pub fn forward_shaded(
    p: &SplatParams<f64>,
    cam: &Camera,
    opts: &RenderOptions,
    mlp: &Mlp,
    w: &MlpParams<f64>,
    background: [f64; 3],
) -> Result<Image64, String> {
    let k = check_shaded(p, mlp)?;
    let feats = forward(p, cam, opts, &vec![0.0; k])?;
    let width = cam.width as usize;
    let mut color = vec![0.0; feats.alpha.len() * 3];
    for (i, &a) in feats.alpha.iter().enumerate() {
        let dir = crate::fields::mlp::view_dir(cam, (i % width) as u32, (i / width) as u32);
        let x = mlp_input64(mlp, &feats.color[i * k..(i + 1) * k], dir, a);
        let (_, _, c) = mlp_forward64(mlp, w, &x);
        for ch in 0..3 {
            color[i * 3 + ch] = a * c[ch] + (1.0 - a) * background[ch];
        }
    }
    Ok(Image64 {
        width: cam.width,
        height: cam.height,
        channels: 3,
        color,
        alpha: feats.alpha,
        depth: feats.depth,
    })
}

/// The backward pass of [`forward_shaded`]: the Gaussians' gradients (their `colors` are
/// dL/d feature values) and the MLP's.
pub fn backward_shaded(
    p: &SplatParams<f64>,
    cam: &Camera,
    opts: &RenderOptions,
    mlp: &Mlp,
    w: &MlpParams<f64>,
    background: [f64; 3],
    grads: &PixelGrads<f64>,
) -> Result<(SplatGrads<f64>, MlpParams<f64>), String> {
    let k = check_shaded(p, mlp)?;
    let feats = forward(p, cam, opts, &vec![0.0; k])?;
    let pixels = feats.alpha.len();
    let width = cam.width as usize;
    let mut g_mlp = w.zeros_like();
    let mut g_feat = vec![0.0; pixels * k];
    let mut g_alpha: Vec<f64> = if grads.alpha.is_empty() {
        vec![0.0; pixels]
    } else {
        grads.alpha.clone()
    };
    if !grads.color.is_empty() {
        for i in 0..pixels {
            let a = feats.alpha[i];
            let dir = crate::fields::mlp::view_dir(cam, (i % width) as u32, (i / width) as u32);
            let x = mlp_input64(mlp, &feats.color[i * k..(i + 1) * k], dir, a);
            let (inputs, derivs, c) = mlp_forward64(mlp, w, &x);
            let gy = &grads.color[i * 3..i * 3 + 3];
            // colour = a c + (1 - a) background.
            let g_c: Vec<f64> = gy.iter().map(|g| a * g).collect();
            g_alpha[i] += (0..3)
                .map(|ch| gy[ch] * (c[ch] - background[ch]))
                .sum::<f64>();
            let g_x = mlp_backward64(mlp, w, &inputs, &derivs, &g_c, &mut g_mlp);
            // Split dL/d(input) by the inputs' order; the view direction has no parameter.
            let mut at = 0;
            for input in &mlp.inputs {
                match input {
                    MlpInput::Features => {
                        g_feat[i * k..(i + 1) * k].copy_from_slice(&g_x[at..at + k]);
                        at += k;
                    }
                    MlpInput::ViewDir => at += 3,
                    MlpInput::Alpha => {
                        g_alpha[i] += g_x[at];
                        at += 1;
                    }
                }
            }
        }
    }
    let blend_grads = PixelGrads {
        color: g_feat,
        alpha: g_alpha,
        depth: grads.depth.clone(),
    };
    let g = backward(p, cam, opts, &vec![0.0; k], &blend_grads)?;
    Ok((g, g_mlp))
}
