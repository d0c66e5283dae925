//! The original's adaptive density control: clone the small and split the large
//! Gaussians with large view-space gradients, prune the transparent and the too large,
//! and reset the opacities.

use super::adam::Moments;
use super::{logit, Model, Settings};
use crate::core::gen::Rng;
use crate::core::scene::Scene;

impl Model {
    /// The original's `reset_opacity`: every opacity to at most 0.01, its Adam state zero.
    pub fn reset_opacity(&mut self) {
        let cap = logit(0.01);
        match &self.mip_filters {
            None => {
                for o in &mut self.scene.opacity_logits {
                    *o = o.min(cap);
                }
            }
            // With Mip-Splatting's filter the opacity the renders see is capped (its
            // `reset_opacity`): min(sigmoid(o) * factor, 0.01) / factor.
            Some(filters) => {
                let s = &mut self.scene;
                for ((o, l), &f) in s.opacity_logits.iter_mut().zip(&s.log_scales).zip(filters) {
                    let (_, factor) = super::mip::filtered(l.map(f32::exp), f);
                    let seen = crate::core::scene::sigmoid(*o) * factor;
                    if seen > 0.01 {
                        *o = logit(0.01 / factor);
                    }
                }
            }
        }
        self.moments[3] = Moments::zeros(self.len());
    }

    /// The original's `densify_and_prune`: clone the small and split the large Gaussians
    /// whose average 2D-mean gradient reaches the threshold, then prune the transparent
    /// (opacity < 0.005) and, with `max_screen_size`, the too large. Returns (cloned,
    /// split, pruned).
    pub fn densify_and_prune(
        &mut self,
        settings: &Settings,
        extent: f32,
        max_screen_size: Option<f32>,
        rng: &mut Rng,
    ) -> (usize, usize, usize) {
        let n = self.len();
        let grads: Vec<f32> = (0..n)
            .map(|i| {
                if self.denom[i] > 0 {
                    self.grad_accum[i] / self.denom[i] as f32
                } else {
                    0.0
                }
            })
            .collect();
        let max_scale = |s: &Scene, i: usize| {
            s.log_scales[i]
                .iter()
                .fold(f32::MIN, |a, &b| a.max(b))
                .exp()
        };
        let threshold = settings.densify_grad_threshold;
        let limit = settings.percent_dense * extent;
        // Clone: copies of the small ones.
        let clone: Vec<usize> = (0..n)
            .filter(|&i| grads[i] >= threshold && max_scale(&self.scene, i) <= limit)
            .collect();
        for &i in &clone {
            self.push_copy(i, None);
        }
        // Split (among the originals; clones have zero gradient): two samples each.
        let split: Vec<usize> = (0..n)
            .filter(|&i| grads[i] >= threshold && max_scale(&self.scene, i) > limit)
            .collect();
        for &i in &split {
            let s = self.scene.log_scales[i].map(f32::exp);
            let q = self.scene.rotations[i];
            let rot =
                glam::Mat3::from_quat(glam::Quat::from_xyzw(q[1], q[2], q[3], q[0]).normalize());
            for _ in 0..2 {
                let sample = glam::Vec3::new(
                    rng.normal() * s[0],
                    rng.normal() * s[1],
                    rng.normal() * s[2],
                );
                let p = glam::Vec3::from(self.scene.positions[i]) + rot * sample;
                let log = s.map(|v| (v / (0.8 * 2.0)).ln());
                self.push_copy(i, Some((p.to_array(), log)));
            }
        }
        // Prune: the split originals, the transparent and the too large.
        let total = self.len();
        let min_opacity = logit(0.005);
        let mut keep = vec![true; total];
        for &i in &split {
            keep[i] = false;
        }
        for (i, k) in keep.iter_mut().enumerate() {
            if self.scene.opacity_logits[i] < min_opacity {
                *k = false;
            }
            if let Some(max) = max_screen_size {
                let big_screen = i < n && self.max_radii[i] > max;
                if big_screen || max_scale(&self.scene, i) > 0.1 * extent {
                    *k = false;
                }
            }
        }
        let pruned = keep.iter().filter(|k| !**k).count() - split.len();
        self.keep(&keep);
        let m = self.len();
        self.grad_accum = vec![0.0; m];
        self.denom = vec![0; m];
        self.max_radii = vec![0.0; m];
        (clone.len(), split.len(), pruned)
    }

    /// Appends a copy of Gaussian `i` (at another place and scale when given), with zero
    /// Adam moments (the original's `densification_postfix`).
    pub(super) fn push_copy(&mut self, i: usize, at: Option<([f32; 3], [f32; 3])>) {
        let s = &mut self.scene;
        let stride = s.sh_stride();
        let (p, l) = at.unwrap_or((s.positions[i], s.log_scales[i]));
        s.positions.push(p);
        s.log_scales.push(l);
        s.rotations.push(s.rotations[i]);
        s.opacity_logits.push(s.opacity_logits[i]);
        let sh: Vec<f32> = s.sh[i * stride..(i + 1) * stride].to_vec();
        s.sh.extend(sh);
        let k = s.feature_count;
        let f: Vec<f32> = s.features[i * k..(i + 1) * k].to_vec();
        s.features.extend(f);
        for (m, width) in self.moments.iter_mut().zip([3, 3, 4, 1, stride, k]) {
            m.grow(width);
        }
        self.grad_accum.push(0.0);
        self.denom.push(0);
        self.max_radii.push(0.0);
    }

    fn keep(&mut self, keep: &[bool]) {
        fn filter<T: Copy>(v: &mut Vec<T>, keep: &[bool]) {
            let mut k = keep.iter();
            v.retain(|_| *k.next().expect("one flag per Gaussian"));
        }
        let s = &mut self.scene;
        let stride = s.sh_stride();
        filter(&mut s.positions, keep);
        filter(&mut s.log_scales, keep);
        filter(&mut s.rotations, keep);
        filter(&mut s.opacity_logits, keep);
        let rows = |v: &[f32], width: usize| -> Vec<f32> {
            if width == 0 {
                return Vec::new();
            }
            v.chunks_exact(width)
                .zip(keep)
                .filter(|(_, k)| **k)
                .flat_map(|(c, _)| c.iter().copied())
                .collect()
        };
        s.sh = rows(&s.sh, stride);
        let k = s.feature_count;
        s.features = rows(&s.features, k);
        for (m, width) in self.moments.iter_mut().zip([3, 3, 4, 1, stride, k]) {
            if width > 0 {
                m.keep(width, keep);
            }
        }
    }
}
