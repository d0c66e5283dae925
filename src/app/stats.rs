//! Scene statistics for `verisplat info`: what a user checks before choosing filters.

use crate::core::camera::{bulk_bounds, BulkBounds};
use crate::core::scene::Scene;

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

/// Everything `verisplat info` prints.
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
    /// Log-binned histogram of the largest activated scale of each Gaussian.
    pub max_scale_histogram: Histogram,
    /// Log-binned histogram of the activated opacities.
    pub opacity_histogram: Histogram,
}

/// A histogram over bins whose edges follow the 1-2-5 series (0.001, 0.002, 0.005,
/// 0.01, ...), so a user can read off `--max-scale` / `--min-opacity` thresholds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Histogram {
    /// Bin edges, increasing; bin `i` is `[edges[i], edges[i + 1])`.
    pub edges: Vec<f64>,
    /// Values per bin (`edges.len() - 1` entries).
    pub counts: Vec<usize>,
    /// Values that are zero, negative or not finite (outside every bin).
    pub outside: usize,
    /// All values.
    pub total: usize,
}

/// The 1-2-5 series value of step `k` (`k = 0` is 1, `k = 1` is 2, `k = 3` is 10, ...).
fn series(k: i64) -> f64 {
    let decade = k.div_euclid(3);
    [1.0, 2.0, 5.0][k.rem_euclid(3) as usize] * 10f64.powi(decade as i32)
}

/// Largest series step whose value is <= v (v > 0, finite).
fn series_floor(v: f64) -> i64 {
    let mut k = (v.log10().floor() as i64) * 3;
    while series(k + 1) <= v {
        k += 1;
    }
    while series(k) > v {
        k -= 1;
    }
    k
}

impl Histogram {
    /// Bins positive finite `values` on the 1-2-5 series.
    pub fn log_binned(values: impl Iterator<Item = f64>) -> Histogram {
        let values: Vec<f64> = values.collect();
        let positive = values.iter().copied().filter(|v| v.is_finite() && *v > 0.0);
        let (lo, hi) = positive.fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
        let mut h = Histogram {
            total: values.len(),
            ..Default::default()
        };
        if lo > hi {
            h.outside = values.len();
            return h;
        }
        let (k0, k1) = (series_floor(lo), series_floor(hi) + 1);
        h.edges = (k0..=k1).map(series).collect();
        h.counts = vec![0; h.edges.len() - 1];
        for v in values {
            if v.is_finite() && v > 0.0 {
                let last = h.counts.len() - 1;
                let k = (series_floor(v) - k0) as usize;
                h.counts[k.min(last)] += 1;
            } else {
                h.outside += 1;
            }
        }
        h
    }
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
        max_scale_histogram: Histogram::log_binned(
            act.scales.iter().map(|s| s[0].max(s[1]).max(s[2]) as f64),
        ),
        opacity_histogram: Histogram::log_binned(act.opacities.iter().map(|&v| v as f64)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_histogram_bins_on_the_1_2_5_series() {
        let h =
            Histogram::log_binned([0.0011, 0.0015, 0.0021, 0.7, 1.0, 0.0, f64::NAN].into_iter());
        assert_eq!(h.edges.first().copied(), Some(0.001));
        assert!((h.edges.last().unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(h.counts.iter().sum::<usize>(), 5);
        assert_eq!(h.outside, 2);
        assert_eq!(h.total, 7);
        assert_eq!(h.counts[0], 2); // [0.001, 0.002)
        assert_eq!(h.counts[1], 1); // [0.002, 0.005)
        assert_eq!(*h.counts.last().unwrap(), 1); // [1, 2)
        for w in h.edges.windows(2) {
            assert!(w[0] < w[1]);
        }
        assert!(Histogram::log_binned(std::iter::empty()).counts.is_empty());
    }
}
