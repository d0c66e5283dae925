//! The Gaussians being trained, in the original's parameterisation (a [`Scene`]: centres,
//! log scales, unnormalised quaternions, opacity logits, SH coefficients up to the
//! maximum degree), its Adam optimiser with the original per-group learning rates, and the
//! original's adaptive density control (clone, split, prune, opacity reset). Rules of the
//! original `gaussian_model.py` and `train.py`; where they are stated in numbers, the
//! numbers are theirs ([`Settings::default`]).
//!
//! Here: the [`Model`] and what the rasterizer takes from it. Its rooms: the settings and
//! the centres' learning-rate schedule ([`settings`]), the starting Gaussians ([`init`]),
//! Adam ([`adam`]), the state as checkpoints and the device hold it ([`state`]), the
//! original's densification ([`densify`]) and the MCMC strategy's ([`mcmc`]).

pub mod adam;
pub mod densify;
pub mod init;
pub mod mcmc;
pub mod mip;
pub mod settings;
pub mod state;

pub(super) use adam::adam_corrections;
pub(super) use adam::Moments;
pub use init::{mean_sq_dist3, random_points};
pub use mcmc::{noise_key, noise_normal, pcg_hash, relocation};
pub use settings::{position_lr, Mcmc, Settings};

use crate::core::model::grad::{ColorParams, SplatGrads, SplatParams};
use crate::core::scene::{sigmoid, Scene};

/// The logit (inverse sigmoid) of the probability `p`.
fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// The Gaussians, their optimiser state and their densification statistics.
#[derive(Clone, Debug)]
pub struct Model {
    /// The parameters, SH up to the maximum degree.
    pub scene: Scene,
    /// The SH degree the renders use now.
    pub active_sh_degree: u32,
    moments: [Moments; 6],
    /// Adam steps taken per group (torch keeps the count through densification).
    steps: [u32; 7],
    /// A neural shader learned with the feature channels (`scene.features`), and its
    /// moments (weights and biases flattened as `Mlp::gpu_words` orders them).
    pub shader: Option<crate::fields::mlp::Mlp>,
    shader_moments: Moments,
    /// Per Gaussian: the sum of its 2D-mean gradient norms (NDC) and how many views saw it.
    grad_accum: Vec<f32>,
    denom: Vec<u32>,
    max_radii: Vec<f32>,
    /// Mip-Splatting's 3D filter per Gaussian ([`mip`], `train --mip-filter`): the
    /// renders see each Gaussian convolved with it; `None` without the option.
    pub mip_filters: Option<Vec<f32>>,
}

impl Model {
    /// Gaussians in the model.
    pub fn len(&self) -> usize {
        self.scene.len()
    }

    /// True without Gaussians.
    pub fn is_empty(&self) -> bool {
        self.scene.len() == 0
    }

    /// The parameters as the rasterizer takes them (activated; SH of the active degree).
    pub fn params(&self) -> SplatParams<f32> {
        let s = &self.scene;
        let stride = s.sh_stride();
        let k = crate::core::model::sh_coeffs_for_degree(self.active_sh_degree) * 3;
        let mut scales: Vec<[f32; 3]> = s.log_scales.iter().map(|l| l.map(f32::exp)).collect();
        let mut opacities: Vec<f32> = s.opacity_logits.iter().map(|&o| sigmoid(o)).collect();
        if let Some(filters) = &self.mip_filters {
            for ((sc, o), &f) in scales.iter_mut().zip(opacities.iter_mut()).zip(filters) {
                let (filtered, factor) = mip::filtered(*sc, f);
                *sc = filtered;
                *o *= factor;
            }
        }
        SplatParams {
            means: s.positions.clone(),
            quats: s.rotations.clone(),
            scales,
            opacities,
            colors: if self.shader.is_some() {
                ColorParams::Direct {
                    channels: s.feature_count,
                    values: s.features.clone(),
                }
            } else {
                ColorParams::Sh {
                    degree: self.active_sh_degree,
                    coeffs: s
                        .sh
                        .chunks_exact(stride)
                        .flat_map(|c| c[..k].iter().copied())
                        .collect(),
                }
            },
        }
    }

    /// Records a view's densification statistics: per Gaussian seen (`radii > 0`) the norm
    /// of its 2D-mean gradient in NDC (pixels times half the image size, as the original's
    /// screen-space gradient) and its largest screen radius.
    pub fn add_stats(&mut self, grads: &SplatGrads<f32>, radii: &[f32], width: u32, height: u32) {
        let (hw, hh) = (width as f32 / 2.0, height as f32 / 2.0);
        for (i, &r) in radii.iter().enumerate().take(self.len()) {
            if r > 0.0 {
                let g = grads.means2d[i];
                self.grad_accum[i] += ((g[0] * hw).powi(2) + (g[1] * hh).powi(2)).sqrt();
                self.denom[i] += 1;
                self.max_radii[i] = self.max_radii[i].max(r);
            }
        }
    }
}
