//! Scene statistics for `vksplat info`: what a user checks before choosing filters.

use crate::camera::{bulk_bounds, BulkBounds};
use crate::scene::Scene;

/// min / max / mean / standard deviation of one quantity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Arithmetic mean.
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
}

impl Summary {
    /// Summarises `values` (NaN-free). Empty input gives zeros.
    pub fn of(values: impl Iterator<Item = f64>) -> Summary {
        let (mut n, mut mean, mut m2) = (0u64, 0.0f64, 0.0f64);
        let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values {
            n += 1;
            let d = v - mean;
            mean += d / n as f64;
            m2 += d * (v - mean);
            min = min.min(v);
            max = max.max(v);
        }
        if n == 0 {
            return Summary {
                min: 0.0,
                max: 0.0,
                mean: 0.0,
                std: 0.0,
            };
        }
        Summary {
            min,
            max,
            mean,
            std: (m2 / n as f64).sqrt(),
        }
    }
}

/// Everything `vksplat info` prints.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneStats {
    /// Number of Gaussians.
    pub count: usize,
    /// SH degree.
    pub sh_degree: u32,
    /// Axis-aligned bounds of all centres (min, max).
    pub bounds: Option<([f32; 3], [f32; 3])>,
    /// Robust bounds of the bulk.
    pub bulk: BulkBounds,
    /// Stored scale values (natural log), all axes pooled.
    pub log_scale: Summary,
    /// Activated scales `exp(s)`, all axes pooled.
    pub scale: Summary,
    /// Largest activated scale of each Gaussian.
    pub max_scale: Summary,
    /// Stored opacity logits.
    pub opacity_logit: Summary,
    /// Activated opacities.
    pub opacity: Summary,
}

/// Computes the statistics of a scene.
pub fn scene_stats(scene: &Scene) -> SceneStats {
    let act = scene.activated();
    let bounds = (!scene.is_empty()).then(|| {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &scene.positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    });
    SceneStats {
        count: scene.len(),
        sh_degree: scene.sh_degree,
        bounds,
        bulk: bulk_bounds(&scene.positions),
        log_scale: Summary::of(scene.log_scales.iter().flatten().map(|&v| v as f64)),
        scale: Summary::of(act.scales.iter().flatten().map(|&v| v as f64)),
        max_scale: Summary::of(act.scales.iter().map(|s| s[0].max(s[1]).max(s[2]) as f64)),
        opacity_logit: Summary::of(scene.opacity_logits.iter().map(|&v| v as f64)),
        opacity: Summary::of(act.opacities.iter().map(|&v| v as f64)),
    }
}
