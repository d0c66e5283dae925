//! The MCMC strategy (3DGS as Markov chain Monte Carlo): the counter-based noise shared
//! with the device, the relocation's opacity and scale, the noise on the centres, and the
//! refinement (relocate the dead, grow by 5 %).

use super::{logit, Model};
use crate::core::gen::Rng;
use crate::core::scene::sigmoid;

/// The counter-based random numbers of the MCMC noise, the same on the host and the
/// device (`glsl/train/train_step.comp`): a PCG hash.
pub fn pcg_hash(x: u32) -> u32 {
    let state = x.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// The key of one run's iteration: the seed and the iteration hashed together.
pub fn noise_key(seed: u64, iteration: u32) -> u32 {
    pcg_hash(pcg_hash((seed as u32) ^ pcg_hash((seed >> 32) as u32)) ^ iteration)
}

/// A standard normal sample for (key, Gaussian `i`, axis `a`): Box-Muller of two hashed
/// uniforms in (0, 1].
pub fn noise_normal(key: u32, i: u32, a: u32) -> f32 {
    let h = pcg_hash(key ^ pcg_hash(i.wrapping_mul(4).wrapping_add(a)));
    let h2 = pcg_hash(h ^ 0x9e37_79b9);
    let u1 = ((h >> 8) + 1) as f32 / 16_777_216.0;
    let u2 = ((h2 >> 8) + 1) as f32 / 16_777_216.0;
    let r = (-2.0 * u1.ln()).sqrt();
    r * (std::f32::consts::TAU * u2).cos()
}

/// The MCMC relocation's opacity and scale factor of a Gaussian of opacity `o` shared by
/// `n` (itself and its copies): `1 - (1 - o)^(1/n)` and `o / sum_{i=1..n} sum_{k<i}
/// C(i-1, k) (-1)^k o'^(k+1) / sqrt(k+1)` (the paper's eq. 9; `n` at most 51).
pub fn relocation(o: f32, n: u32) -> (f32, f32) {
    let n = n.clamp(1, 51);
    let (o64, nf) = (f64::from(o), f64::from(n));
    let new_o = 1.0 - (1.0 - o64).powf(1.0 / nf);
    let mut denom = 0.0;
    for i in 1..=n {
        let mut binom = 1.0f64;
        for k in 0..i {
            if k > 0 {
                binom = binom * f64::from(i - k) / f64::from(k);
            }
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            denom += binom * sign * new_o.powi(k as i32 + 1) / f64::from(k + 1).sqrt();
        }
    }
    (new_o as f32, (o64 / denom) as f32)
}

impl Model {
    /// The MCMC noise (after a step): each centre moves by `scale * sigmoid(-100 (opacity -
    /// 0.005)) * Sigma n`, `n` standard normal ([`noise_normal`] of `key`), `Sigma` the
    /// Gaussian's covariance (R S S R^T).
    pub fn add_noise(&mut self, scale: f32, key: u32) {
        let s = &mut self.scene;
        for i in 0..s.positions.len() {
            let q = s.rotations[i];
            let sc = s.log_scales[i].map(f32::exp);
            let o = sigmoid(s.opacity_logits[i]);
            let gate = 1.0 / (1.0 + (-100.0 * ((1.0 - o) - 0.995)).exp());
            let noise = [0, 1, 2].map(|a| noise_normal(key, i as u32, a) * gate * scale);
            let d = covariance_times(q, sc, noise);
            for (p, d) in s.positions[i].iter_mut().zip(d) {
                *p += d;
            }
        }
    }

    /// The MCMC strategy's refinement: the dead (opacity <= 0.005) moved onto live ones
    /// drawn by opacity, then 5 % more Gaussians (at most `cap_max`) drawn by opacity from
    /// all; each drawn Gaussian and its copies share its opacity and scale
    /// ([`relocation`]); the drawn ones' Adam moments restart at zero, the copies' too.
    /// Returns (relocated, added).
    pub fn mcmc_refine(&mut self, cap_max: usize, rng: &mut Rng) -> (usize, usize) {
        let n = self.len();
        let opacity: Vec<f32> = self
            .scene
            .opacity_logits
            .iter()
            .map(|&o| sigmoid(o))
            .collect();
        let dead: Vec<usize> = (0..n).filter(|&i| opacity[i] <= 0.005).collect();
        let alive: Vec<usize> = (0..n).filter(|&i| opacity[i] > 0.005).collect();
        let mut relocated = 0;
        if !dead.is_empty() && !alive.is_empty() {
            let sampled = sample_by(&alive, &opacity, dead.len(), rng);
            self.share(&sampled, &opacity);
            for (&d, &src) in dead.iter().zip(&sampled) {
                self.copy_params(src, d);
            }
            relocated = dead.len();
        }
        let n = self.len();
        let target = cap_max.min((1.05 * n as f64) as usize);
        let add = target.saturating_sub(n);
        if add > 0 && n > 0 {
            let opacity: Vec<f32> = self
                .scene
                .opacity_logits
                .iter()
                .map(|&o| sigmoid(o))
                .collect();
            let all: Vec<usize> = (0..n).collect();
            let sampled = sample_by(&all, &opacity, add, rng);
            self.share(&sampled, &opacity);
            for &src in &sampled {
                self.push_copy(src, None);
            }
        }
        (relocated, add)
    }

    /// Gives each drawn Gaussian the opacity and scale it shares with its copies (drawn
    /// `c` times: `c + 1` Gaussians), and zeroes its Adam moments.
    fn share(&mut self, sampled: &[usize], opacity: &[f32]) {
        let mut counts = std::collections::BTreeMap::new();
        for &i in sampled {
            *counts.entry(i).or_insert(0u32) += 1;
        }
        let eps = f32::EPSILON;
        let stride = self.scene.sh_stride();
        let k = self.scene.feature_count;
        for (&i, &c) in &counts {
            let (o, factor) = relocation(opacity[i], c + 1);
            let o = o.clamp(0.005, 1.0 - eps);
            self.scene.opacity_logits[i] = logit(o);
            let sc = self.scene.log_scales[i].map(|l| (factor * l.exp()).ln());
            self.scene.log_scales[i] = sc;
            for (m, width) in self.moments.iter_mut().zip([3, 3, 4, 1, stride, k]) {
                for v in [&mut m.m, &mut m.v] {
                    if !v.is_empty() {
                        v[i * width..(i + 1) * width].fill(0.0);
                    }
                }
            }
        }
    }

    /// Gaussian `dst` takes `src`'s parameters (its moments stay, as the original's).
    fn copy_params(&mut self, src: usize, dst: usize) {
        let s = &mut self.scene;
        s.positions[dst] = s.positions[src];
        s.log_scales[dst] = s.log_scales[src];
        s.rotations[dst] = s.rotations[src];
        s.opacity_logits[dst] = s.opacity_logits[src];
        let stride = s.sh_stride();
        s.sh.copy_within(src * stride..(src + 1) * stride, dst * stride);
        let k = s.feature_count;
        s.features.copy_within(src * k..(src + 1) * k, dst * k);
    }
}

/// `count` draws with replacement from `from`, each with probability proportional to its
/// `weight` (a seeded inverse-CDF draw).
fn sample_by(from: &[usize], weight: &[f32], count: usize, rng: &mut Rng) -> Vec<usize> {
    let mut cdf = Vec::with_capacity(from.len());
    let mut total = 0.0f64;
    for &i in from {
        total += f64::from(weight[i].max(0.0));
        cdf.push(total);
    }
    (0..count)
        .map(|_| {
            let u = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * total;
            let j = cdf.partition_point(|&c| c <= u).min(from.len() - 1);
            from[j]
        })
        .collect()
}

/// `Sigma v` for the covariance `R S S R^T` of a Gaussian (quaternion `q`, w first, scales
/// `s`), in f32 as the device computes it.
fn covariance_times(q: [f32; 4], s: [f32; 3], v: [f32; 3]) -> [f32; 3] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let r = crate::core::model::field::rotation(q.map(|v| v / n));
    // t = S S R^T v, then R t.
    let rt = [0, 1, 2].map(|a| r[0][a] * v[0] + r[1][a] * v[1] + r[2][a] * v[2]);
    let t = [0, 1, 2].map(|a| s[a] * s[a] * rt[a]);
    [0, 1, 2].map(|a| r[a][0] * t[0] + r[a][1] * t[1] + r[a][2] * t[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::camera::colmap::Point3D;

    /// The MCMC relocation keeps what a pixel sees: `n` copies of the new opacity
    /// composite to the old one (`1 - (1 - o')^n = o`), one copy changes nothing, and the
    /// scale factor is the paper's (0.952 for o = 0.5, n = 2, worked by hand).
    #[test]
    fn relocation_keeps_the_opacity_a_pixel_sees() {
        for &o in &[0.01f32, 0.3, 0.5, 0.9, 0.99] {
            let (same, factor) = relocation(o, 1);
            assert!(
                (same - o).abs() < 1e-6 && (factor - 1.0).abs() < 1e-5,
                "{o}"
            );
            for n in [2u32, 3, 7, 51] {
                let (o2, f) = relocation(o, n);
                let seen = 1.0 - (1.0 - f64::from(o2)).powi(n as i32);
                assert!((seen - f64::from(o)).abs() < 1e-5, "o {o} n {n}: {seen}");
                assert!(f > 0.0 && f.is_finite(), "o {o} n {n}: {f}");
            }
        }
        let (o2, f) = relocation(0.5, 2);
        assert!((o2 - 0.292_893).abs() < 1e-5, "{o2}");
        assert!((f - 0.952_18).abs() < 1e-4, "{f}");
    }

    /// The noise's normals are standard normal (mean 0, variance 1 within the sampling
    /// error of 300,000 draws), and differ by key, Gaussian and axis.
    #[test]
    fn noise_normals_are_standard_normal() {
        let key = noise_key(7, 123);
        let draws: Vec<f64> = (0..100_000u32)
            .flat_map(|i| (0..3).map(move |a| f64::from(noise_normal(key, i, a))))
            .collect();
        let n = draws.len() as f64;
        let mean = draws.iter().sum::<f64>() / n;
        let var = draws.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.02, "variance {var}");
        assert_ne!(noise_normal(key, 0, 0), noise_normal(key, 0, 1));
        assert_ne!(noise_normal(key, 0, 0), noise_normal(key, 1, 0));
        assert_ne!(
            noise_normal(key, 0, 0),
            noise_normal(noise_key(7, 124), 0, 0)
        );
    }

    /// MCMC refinement: the dead are moved onto live ones, 5 % more are added, never past
    /// the cap, the arrays (and Adam's) stay one per Gaussian, and the same seed gives
    /// the same result.
    #[test]
    fn mcmc_refine_relocates_and_grows_to_the_cap() {
        let points: Vec<Point3D> = (0..200)
            .map(|i| Point3D {
                position: [i as f64 * 0.01, (i % 7) as f64 * 0.1, 0.0],
                color: [100, 150, 200],
            })
            .collect();
        let mut model = Model::from_points(&points, 1);
        for (i, o) in model.scene.opacity_logits.iter_mut().enumerate() {
            *o = logit(if i % 4 == 0 {
                0.001
            } else {
                0.2 + 0.003 * i as f32
            });
        }
        let mut a = model.clone();
        let (relocated, added) = a.mcmc_refine(205, &mut Rng(3));
        assert_eq!(relocated, 50);
        assert_eq!(added, 5, "5 % of 200 is 10, but the cap is 205");
        assert_eq!(a.len(), 205);
        assert!(a
            .scene
            .opacity_logits
            .iter()
            .all(|&o| sigmoid(o) >= 0.005 - 1e-6));
        let [p, m, v, stats] = a.device_state();
        assert_eq!(p.len(), 205 * a.record_floats());
        assert_eq!((m.len(), v.len(), stats.len()), (p.len(), p.len(), 205 * 4));
        let mut b = model.clone();
        b.mcmc_refine(205, &mut Rng(3));
        assert_eq!(a.scene.positions, b.scene.positions);
        assert_eq!(a.scene.opacity_logits, b.scene.opacity_logits);
        let (_, grown) = model.mcmc_refine(10_000, &mut Rng(3));
        assert_eq!(grown, 10);
    }
}
