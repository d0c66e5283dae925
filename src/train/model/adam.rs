//! Adam as the original runs it (torch.optim.Adam, eps 1e-15): the moments of one
//! parameter array, and the model's step over every parameter group with the original's
//! learning rates and optional gradient-norm clipping.

use super::{Model, Settings};
use crate::core::model::grad::SplatGrads;
use crate::core::scene::sigmoid;

/// Adam's betas (torch.optim.Adam's defaults, as the original uses them).
const ADAM_BETAS: (f32, f32) = (0.9, 0.999);

/// Adam's bias corrections at step `t` (1-based): `1 - b1^t` and `sqrt(1 - b2^t)`.
pub(in crate::train) fn adam_corrections(t: u32) -> (f32, f32) {
    (
        1.0 - ADAM_BETAS.0.powi(t as i32),
        (1.0 - ADAM_BETAS.1.powi(t as i32)).sqrt(),
    )
}

/// Adam's moments of one parameter array.
#[derive(Clone, Debug, Default)]
pub(in crate::train) struct Moments {
    pub(in crate::train) m: Vec<f32>,
    pub(in crate::train) v: Vec<f32>,
}

impl Moments {
    pub(super) fn zeros(n: usize) -> Self {
        Moments {
            m: vec![0.0; n],
            v: vec![0.0; n],
        }
    }

    /// torch.optim.Adam's step (betas 0.9, 0.999, eps 1e-15 as the original sets it) with
    /// `lr(i)` per value, at step `t` (1-based).
    pub(in crate::train) fn step(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        t: u32,
        lr: impl Fn(usize) -> f32,
    ) {
        let (b1, b2, eps) = (ADAM_BETAS.0, ADAM_BETAS.1, 1e-15f32);
        let (c1, c2) = adam_corrections(t);
        for (i, ((p, g), (m, v))) in params
            .iter_mut()
            .zip(grads)
            .zip(self.m.iter_mut().zip(self.v.iter_mut()))
            .enumerate()
        {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= lr(i) / c1 * *m / (v.sqrt() / c2 + eps);
        }
    }

    pub(super) fn keep(&mut self, stride: usize, keep: &[bool]) {
        for a in [&mut self.m, &mut self.v] {
            *a = a
                .chunks_exact(stride)
                .zip(keep)
                .filter(|(_, k)| **k)
                .flat_map(|(c, _)| c.iter().copied())
                .collect();
        }
    }

    pub(super) fn grow(&mut self, values: usize) {
        self.m.resize(self.m.len() + values, 0.0);
        self.v.resize(self.v.len() + values, 0.0);
    }
}

impl Model {
    /// Counts one Adam step of every group (not the opacities' when `skip_opacity`), as
    /// [`Self::step`] does, and returns the counts.
    pub(in crate::train) fn advance_steps(&mut self, skip_opacity: bool) -> [u32; 7] {
        for (g, t) in self.steps.iter_mut().enumerate() {
            if !(skip_opacity && g == 3) {
                *t += 1;
            }
        }
        self.steps
    }

    /// One Adam step with the gradients of the activated parameters (`grads`, as the
    /// rasterizer returns them for [`Self::params`]) and, for feature splats, the shader's
    /// (`shader_grads`), the centres' learning rate `position_lr`; `skip_opacity` leaves
    /// the opacities (just reset) alone. With `settings.clip_grad`, the whole gradient of
    /// the stored parameters is scaled to at most that L2 norm first. Returns the norm
    /// before clipping.
    pub fn step(
        &mut self,
        grads: &SplatGrads<f32>,
        shader_grads: Option<&crate::fields::mlp::MlpParams<f32>>,
        position_lr: f32,
        settings: &Settings,
        skip_opacity: bool,
    ) -> f32 {
        let n = self.len();
        let t = self.advance_steps(skip_opacity);
        let s = &mut self.scene;
        let flat3 = |v: &[[f32; 3]]| -> Vec<f32> { v.iter().flatten().copied().collect() };
        // Chain rule to the stored parameters: scales = exp(log), opacity = sigmoid(logit).
        let mut g_pos = flat3(&grads.means);
        let mut g_log: Vec<f32> = grads
            .scales
            .iter()
            .zip(&s.log_scales)
            .flat_map(|(g, l)| [0, 1, 2].map(|a| g[a] * l[a].exp()))
            .collect();
        let mut g_rot: Vec<f32> = grads.quats.iter().flatten().copied().collect();
        let mut g_logit: Vec<f32> = grads
            .opacities
            .iter()
            .zip(&s.opacity_logits)
            .map(|(g, &o)| {
                let p = sigmoid(o);
                g * p * (1.0 - p)
            })
            .collect();
        if let Some(filters) = &self.mip_filters {
            // Through Mip-Splatting's filter: the renders saw sqrt(s^2 + f^2) and the
            // opacity times the filter's factor.
            for (i, &f) in filters.iter().enumerate() {
                let sc = s.log_scales[i].map(f32::exp);
                let p = sigmoid(s.opacity_logits[i]);
                let (filtered, factor) = super::mip::filtered(sc, f);
                let g_op = grads.opacities[i];
                let g =
                    super::mip::log_scale_grads(grads.scales[i], g_op, p * factor, sc, f, filtered);
                g_log[i * 3..i * 3 + 3].copy_from_slice(&g);
                g_logit[i] = g_op * factor * p * (1.0 - p);
            }
        }
        if let Some(mc) = &settings.mcmc {
            // The regularisers' gradients: mean opacity over n, mean scale over 3n.
            let (ro, rs) = (mc.opacity_reg / n as f32, mc.scale_reg / (3 * n) as f32);
            for (g, &o) in g_logit.iter_mut().zip(&s.opacity_logits) {
                let p = sigmoid(o);
                *g += ro * p * (1.0 - p);
            }
            for (g, l) in g_log.iter_mut().zip(s.log_scales.iter().flatten()) {
                *g += rs * l.exp();
            }
        }
        let stride = s.sh_stride();
        let mut g_sh = vec![0.0; n * stride];
        let mut g_feat = Vec::new();
        if self.shader.is_some() {
            g_feat = grads.colors.clone();
        } else {
            let k = crate::core::model::sh_coeffs_for_degree(self.active_sh_degree) * 3;
            for i in 0..n {
                g_sh[i * stride..i * stride + k].copy_from_slice(&grads.colors[i * k..(i + 1) * k]);
            }
        }
        let mut g_mlp: Vec<f32> = shader_grads.map_or_else(Vec::new, |m| {
            m.weights
                .iter()
                .zip(&m.biases)
                .flat_map(|(w, b)| w.iter().chain(b).copied())
                .collect()
        });
        let mut groups: [&mut Vec<f32>; 7] = [
            &mut g_pos,
            &mut g_log,
            &mut g_rot,
            &mut g_logit,
            &mut g_sh,
            &mut g_feat,
            &mut g_mlp,
        ];
        let norm = groups
            .iter()
            .map(|g| g.iter().map(|v| (*v as f64).powi(2)).sum::<f64>())
            .sum::<f64>()
            .sqrt() as f32;
        if let Some(max) = settings.clip_grad {
            if norm > max && norm.is_finite() {
                let scale = max / norm;
                for g in groups.iter_mut() {
                    for v in g.iter_mut() {
                        *v *= scale;
                    }
                }
            }
        }
        let mut pos = flat3(&s.positions);
        self.moments[0].step(&mut pos, &g_pos, t[0], |_| position_lr);
        for (p, c) in s.positions.iter_mut().zip(pos.chunks_exact(3)) {
            *p = [c[0], c[1], c[2]];
        }
        let mut ls = flat3(&s.log_scales);
        self.moments[1].step(&mut ls, &g_log, t[1], |_| settings.scaling_lr);
        for (p, c) in s.log_scales.iter_mut().zip(ls.chunks_exact(3)) {
            *p = [c[0], c[1], c[2]];
        }
        let mut q: Vec<f32> = s.rotations.iter().flatten().copied().collect();
        self.moments[2].step(&mut q, &g_rot, t[2], |_| settings.rotation_lr);
        for (p, c) in s.rotations.iter_mut().zip(q.chunks_exact(4)) {
            *p = [c[0], c[1], c[2], c[3]];
        }
        if !skip_opacity {
            self.moments[3].step(&mut s.opacity_logits, &g_logit, t[3], |_| {
                settings.opacity_lr
            });
        }
        if let Some(mlp) = self.shader.as_mut() {
            self.moments[5].step(&mut s.features, &g_feat, t[5], |_| settings.feature_lr);
            let mut flat = mlp.flat_params();
            self.shader_moments
                .step(&mut flat, &g_mlp, t[6], |_| settings.shader_lr);
            mlp.set_flat_params(&flat);
        } else {
            let (dc, rest) = (settings.feature_lr, settings.feature_lr / 20.0);
            self.moments[4].step(&mut s.sh, &g_sh, t[4], |i| {
                if i % stride < 3 {
                    dc
                } else {
                    rest
                }
            });
        }
        norm
    }
}
