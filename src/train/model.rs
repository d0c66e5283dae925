//! The Gaussians being trained, in the original's parameterisation (a [`Scene`]: centres,
//! log scales, unnormalised quaternions, opacity logits, SH coefficients up to the
//! maximum degree), its Adam optimiser with the original per-group learning rates, and the
//! original's adaptive density control (clone, split, prune, opacity reset). Rules of the
//! original `gaussian_model.py` and `train.py`; where they are stated in numbers, the
//! numbers are theirs ([`Settings::default`]).

use crate::camera::colmap::Point3D;
use crate::gen::Rng;
use crate::model::grad::{ColorParams, SplatGrads, SplatParams};
use crate::model::sh::SH_C0;
use crate::scene::{sigmoid, Scene};

/// The original's optimisation and densification settings (`arguments/__init__.py`).
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Iterations in all.
    pub iterations: u32,
    /// Centre learning rate at the start and the end (times the scene extent), decayed
    /// exponentially over `position_lr_max_steps`.
    pub position_lr_init: f32,
    /// See `position_lr_init`.
    pub position_lr_final: f32,
    /// Steps of the centres' decay.
    pub position_lr_max_steps: u32,
    /// SH DC learning rate (the rest: a twentieth of it).
    pub feature_lr: f32,
    /// Opacity learning rate.
    pub opacity_lr: f32,
    /// Log-scale learning rate.
    pub scaling_lr: f32,
    /// Quaternion learning rate.
    pub rotation_lr: f32,
    /// Below `percent_dense * extent` a densified Gaussian is cloned, above it split.
    pub percent_dense: f32,
    /// Weight of D-SSIM in the loss.
    pub lambda_dssim: f32,
    /// Densify every this many iterations ...
    pub densification_interval: u32,
    /// ... from this iteration ...
    pub densify_from_iter: u32,
    /// ... until this one.
    pub densify_until_iter: u32,
    /// Average 2D-mean gradient (NDC units, as the original's) above which a Gaussian is
    /// densified.
    pub densify_grad_threshold: f32,
    /// Opacities are reset to at most 0.01 every this many iterations.
    pub opacity_reset_interval: u32,
    /// The SH degree in use rises by one every this many iterations.
    pub sh_increase_interval: u32,
    /// Learning rate of the neural shader's weights (feature splats).
    pub shader_lr: f32,
    /// Largest L2 norm of the whole gradient (all parameters, the shader's too); above it
    /// the gradient is scaled down to it. `None`: no clipping (the original's default).
    pub clip_grad: Option<f32>,
    /// The MCMC strategy (3DGS as Markov chain Monte Carlo, Kheradmand et al. 2024)
    /// instead of the original's densification; `None`: the original's.
    pub mcmc: Option<Mcmc>,
}

/// The MCMC strategy's settings (the names and defaults of `ubc-vision/3dgs-mcmc`): every
/// `densification_interval` iterations from `densify_from_iter` to `refine_until`, the
/// dead Gaussians (opacity <= 0.005) are moved onto live ones drawn by opacity and the
/// count grows by 5 % up to `cap_max`, each draw sharing its source's opacity and scale so
/// the rendered image stays the same; after every step the centres get noise shaped by
/// each Gaussian's covariance, strong where it is transparent; the loss gains
/// `opacity_reg * mean(opacity) + scale_reg * mean(scale)`. No opacity reset.
#[derive(Clone, Debug, PartialEq)]
pub struct Mcmc {
    /// The most Gaussians.
    pub cap_max: usize,
    /// Noise scale, times the centres' learning rate.
    pub noise_lr: f32,
    /// Weight of the mean opacity in the loss.
    pub opacity_reg: f32,
    /// Weight of the mean scale in the loss.
    pub scale_reg: f32,
    /// Relocation and growth stop at this iteration.
    pub refine_until: u32,
}

impl Default for Mcmc {
    fn default() -> Self {
        Mcmc {
            cap_max: 1_000_000,
            noise_lr: 5e5,
            opacity_reg: 0.01,
            scale_reg: 0.01,
            refine_until: 25_000,
        }
    }
}

/// The counter-based random numbers of the MCMC noise, the same on the host and the
/// device (`glsl/train_step.comp`): a PCG hash.
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

impl Default for Settings {
    fn default() -> Self {
        Settings {
            iterations: 30_000,
            position_lr_init: 0.00016,
            position_lr_final: 0.0000016,
            position_lr_max_steps: 30_000,
            feature_lr: 0.0025,
            opacity_lr: 0.025,
            scaling_lr: 0.005,
            rotation_lr: 0.001,
            percent_dense: 0.01,
            lambda_dssim: 0.2,
            densification_interval: 100,
            densify_from_iter: 500,
            densify_until_iter: 15_000,
            densify_grad_threshold: 0.0002,
            opacity_reset_interval: 3000,
            sh_increase_interval: 1000,
            shader_lr: 0.001,
            clip_grad: None,
            mcmc: None,
        }
    }
}

fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// Adam's betas (torch.optim.Adam's defaults, as the original uses them).
const ADAM_BETAS: (f32, f32) = (0.9, 0.999);

/// Adam's bias corrections at step `t` (1-based): `1 - b1^t` and `sqrt(1 - b2^t)`.
pub(super) fn adam_corrections(t: u32) -> (f32, f32) {
    (
        1.0 - ADAM_BETAS.0.powi(t as i32),
        (1.0 - ADAM_BETAS.1.powi(t as i32)).sqrt(),
    )
}

/// Adam's moments of one parameter array.
#[derive(Clone, Debug, Default)]
struct Moments {
    m: Vec<f32>,
    v: Vec<f32>,
}

impl Moments {
    fn zeros(n: usize) -> Self {
        Moments {
            m: vec![0.0; n],
            v: vec![0.0; n],
        }
    }

    /// torch.optim.Adam's step (betas 0.9, 0.999, eps 1e-15 as the original sets it) with
    /// `lr(i)` per value, at step `t` (1-based).
    fn step(&mut self, params: &mut [f32], grads: &[f32], t: u32, lr: impl Fn(usize) -> f32) {
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

    fn keep(&mut self, stride: usize, keep: &[bool]) {
        for a in [&mut self.m, &mut self.v] {
            *a = a
                .chunks_exact(stride)
                .zip(keep)
                .filter(|(_, k)| **k)
                .flat_map(|(c, _)| c.iter().copied())
                .collect();
        }
    }

    fn grow(&mut self, values: usize) {
        self.m.resize(self.m.len() + values, 0.0);
        self.v.resize(self.v.len() + values, 0.0);
    }
}

/// A checkpoint's scalars (counts, degrees, step counts) by name.
pub(crate) type Scalars = serde_json::Map<String, serde_json::Value>;

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
    pub shader: Option<crate::mlp::Mlp>,
    shader_moments: Moments,
    /// Per Gaussian: the sum of its 2D-mean gradient norms (NDC) and how many views saw it.
    grad_accum: Vec<f32>,
    denom: Vec<u32>,
    max_radii: Vec<f32>,
}

/// The mean squared distance to the three nearest other points (the original's
/// `distCUDA2`), through a uniform grid.
pub fn mean_sq_dist3(points: &[[f32; 3]]) -> Vec<f32> {
    use std::collections::HashMap;
    let n = points.len();
    if n < 2 {
        return vec![0.01; n];
    }
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let volume: f32 = (0..3).map(|a| (hi[a] - lo[a]).max(1e-6)).product();
    let cell = (volume / n as f32).cbrt().max(1e-6) * 2.0;
    let key = |p: &[f32; 3]| [0, 1, 2].map(|a| ((p[a] - lo[a]) / cell).floor() as i32);
    let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i as u32);
    }
    use rayon::prelude::*;
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let k = key(p);
            let mut best = [f32::MAX; 3];
            let mut r = 1i32;
            loop {
                for dx in -r..=r {
                    for dy in -r..=r {
                        for dz in -r..=r {
                            // Only the shell of this radius (the inside was searched).
                            if r > 1 && dx.abs() < r && dy.abs() < r && dz.abs() < r {
                                continue;
                            }
                            if let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                                for &j in list {
                                    if j as usize == i {
                                        continue;
                                    }
                                    let q = points[j as usize];
                                    let d = (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f32>();
                                    if d < best[2] {
                                        best[2] = d;
                                        best.sort_by(|a, b| a.total_cmp(b));
                                    }
                                }
                            }
                        }
                    }
                }
                // Done once three are found within the searched cube's inner radius.
                let reach = (r as f32 * cell).powi(2);
                if (best[2] < f32::MAX && best[2] <= reach) || r > 64 {
                    break;
                }
                r += 1;
            }
            let found: Vec<f32> = best.iter().copied().filter(|d| *d < f32::MAX).collect();
            (found.iter().sum::<f32>() / found.len().max(1) as f32).max(1e-7)
        })
        .collect()
}

impl Model {
    /// Gaussians at `points` (the original's `create_from_pcd`): SH DC from the colour,
    /// isotropic scales of the root mean squared distance to the 3 nearest points,
    /// identity rotations, opacity 0.1.
    pub fn from_points(points: &[Point3D], max_sh_degree: u32) -> Self {
        let mut scene = Scene::empty(max_sh_degree);
        let positions: Vec<[f32; 3]> = points
            .iter()
            .map(|p| p.position.map(|v| v as f32))
            .collect();
        let d2 = mean_sq_dist3(&positions);
        let stride = scene.sh_stride();
        for (i, p) in points.iter().enumerate() {
            scene.positions.push(positions[i]);
            let s = d2[i].sqrt().ln();
            scene.log_scales.push([s; 3]);
            scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
            scene.opacity_logits.push(logit(0.1));
            let mut sh = vec![0.0; stride];
            for (v, c) in sh.iter_mut().zip(p.color) {
                *v = (c as f32 / 255.0 - 0.5) / SH_C0;
            }
            scene.sh.extend(sh);
        }
        Self::of(scene)
    }

    /// `count` random Gaussians in the cube of half side `half` around `centre`, random
    /// colours (the original's start for data sets without points).
    pub fn random(
        count: usize,
        centre: [f32; 3],
        half: f32,
        max_sh_degree: u32,
        rng: &mut Rng,
    ) -> Self {
        let points: Vec<Point3D> = (0..count)
            .map(|_| Point3D {
                position: [0, 1, 2].map(|a| (centre[a] + rng.range(-half, half)) as f64),
                color: [0, 1, 2].map(|_| (rng.unit() * 255.0) as u8),
            })
            .collect();
        Self::from_points(&points, max_sh_degree)
    }

    fn of(scene: Scene) -> Self {
        let n = scene.len();
        let stride = scene.sh_stride();
        Model {
            moments: [
                Moments::zeros(n * 3),
                Moments::zeros(n * 3),
                Moments::zeros(n * 4),
                Moments::zeros(n),
                Moments::zeros(n * stride),
                Moments::zeros(n * scene.feature_count),
            ],
            active_sh_degree: 0,
            steps: [0; 7],
            shader: None,
            shader_moments: Moments::default(),
            scene,
            grad_accum: vec![0.0; n],
            denom: vec![0; n],
            max_radii: vec![0.0; n],
        }
    }

    /// Learns `k` feature channels per Gaussian (started at small seeded values) and the
    /// neural shader `mlp`, which turns them into colour, instead of SH colour.
    pub fn with_features(mut self, mlp: crate::mlp::Mlp, rng: &mut Rng) -> Self {
        let k = mlp.feature_channels();
        let n = self.len();
        self.scene.feature_count = k;
        self.scene.features = (0..n * k).map(|_| rng.range(-0.1, 0.1)).collect();
        self.moments[5] = Moments::zeros(n * k);
        let params: usize = mlp.layers.iter().map(|l| (l.inputs + 1) * l.outputs).sum();
        self.shader_moments = Moments::zeros(params);
        self.shader = Some(mlp);
        self
    }

    /// The whole state as named arrays and scalars (a checkpoint's content).
    pub(crate) fn state(&self) -> (Vec<(String, Vec<f32>)>, Scalars) {
        let s = &self.scene;
        let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let mut arrays = vec![
            ("positions".to_string(), flat(&s.positions)),
            ("log_scales".to_string(), flat(&s.log_scales)),
            (
                "rotations".to_string(),
                s.rotations.iter().flatten().copied().collect(),
            ),
            ("opacity_logits".to_string(), s.opacity_logits.clone()),
            ("sh".to_string(), s.sh.clone()),
            ("features".to_string(), s.features.clone()),
            ("grad_accum".to_string(), self.grad_accum.clone()),
            (
                "denom".to_string(),
                self.denom.iter().map(|&d| d as f32).collect(),
            ),
            ("max_radii".to_string(), self.max_radii.clone()),
            ("shader_m".to_string(), self.shader_moments.m.clone()),
            ("shader_v".to_string(), self.shader_moments.v.clone()),
        ];
        for (g, m) in self.moments.iter().enumerate() {
            arrays.push((format!("m{g}"), m.m.clone()));
            arrays.push((format!("v{g}"), m.v.clone()));
        }
        let mut meta = serde_json::Map::new();
        meta.insert("gaussians".into(), serde_json::json!(s.len()));
        meta.insert("sh_degree".into(), serde_json::json!(s.sh_degree));
        meta.insert("feature_count".into(), serde_json::json!(s.feature_count));
        meta.insert("kernel".into(), serde_json::json!(s.kernel.to_string()));
        meta.insert(
            "active_sh_degree".into(),
            serde_json::json!(self.active_sh_degree),
        );
        meta.insert("steps".into(), serde_json::json!(self.steps));
        (arrays, meta)
    }

    /// The model of [`Self::state`]'s arrays and scalars.
    pub(crate) fn from_state(
        mut arrays: std::collections::HashMap<String, Vec<f32>>,
        meta: &serde_json::Map<String, serde_json::Value>,
        shader: Option<crate::mlp::Mlp>,
    ) -> Result<Self, String> {
        let num = |k: &str| {
            meta.get(k)
                .and_then(|v| v.as_u64())
                .ok_or(format!("has no {k}"))
        };
        let n = num("gaussians")? as usize;
        let sh_degree = num("sh_degree")? as u32;
        if sh_degree > 3 {
            return Err(format!("has SH degree {sh_degree}"));
        }
        let k = num("feature_count")? as usize;
        let mut take = |name: &str, len: usize| -> Result<Vec<f32>, String> {
            let v = arrays.remove(name).ok_or(format!("has no {name}"))?;
            if v.len() != len {
                return Err(format!("{name} holds {} values, not {len}", v.len()));
            }
            Ok(v)
        };
        let mut scene = Scene::empty(sh_degree);
        let stride = scene.sh_stride();
        let rows3 = |v: Vec<f32>| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        scene.positions = rows3(take("positions", n * 3)?);
        scene.log_scales = rows3(take("log_scales", n * 3)?);
        scene.rotations = take("rotations", n * 4)?
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        scene.opacity_logits = take("opacity_logits", n)?;
        scene.sh = take("sh", n * stride)?;
        scene.feature_count = k;
        scene.features = take("features", n * k)?;
        scene.kernel = meta
            .get("kernel")
            .and_then(|v| v.as_str())
            .and_then(|s| s.parse().ok())
            .ok_or("has no kernel")?;
        let mut model = Model::of(scene);
        model.grad_accum = take("grad_accum", n)?;
        model.denom = take("denom", n)?.iter().map(|&d| d as u32).collect();
        model.max_radii = take("max_radii", n)?;
        for (g, width) in [3, 3, 4, 1, stride, k].into_iter().enumerate() {
            model.moments[g] = Moments {
                m: take(&format!("m{g}"), n * width)?,
                v: take(&format!("v{g}"), n * width)?,
            };
        }
        let params = shader.as_ref().map_or(0, |m| {
            m.layers.iter().map(|l| (l.inputs + 1) * l.outputs).sum()
        });
        model.shader_moments = Moments {
            m: take("shader_m", params)?,
            v: take("shader_v", params)?,
        };
        model.shader = shader;
        model.active_sh_degree = num("active_sh_degree")? as u32;
        let steps = meta
            .get("steps")
            .and_then(|v| v.as_array())
            .filter(|a| a.len() == 7)
            .ok_or("has no step counts")?;
        for (t, v) in model.steps.iter_mut().zip(steps) {
            *t = v.as_u64().ok_or("has a bad step count")? as u32;
        }
        Ok(model)
    }

    /// Floats of one Gaussian's record on the device ([`super::device`]): centre (3), log
    /// scales (3), quaternion (4), opacity logit, then its colour: SH coefficients up to
    /// the largest degree, or the feature channels of feature splats.
    pub(super) fn record_floats(&self) -> usize {
        11 + self.colour_floats()
    }

    /// Colour values per Gaussian that training learns: SH coefficients, or feature
    /// channels when a shader turns them into colour.
    pub(super) fn colour_floats(&self) -> usize {
        if self.shader.is_some() {
            self.scene.feature_count
        } else {
            self.scene.sh_stride()
        }
    }

    /// The colour's moments group: SH (4) or features (5).
    fn colour_group(&self) -> usize {
        if self.shader.is_some() {
            5
        } else {
            4
        }
    }

    /// The neural shader's weights and biases (flattened as `Mlp::gpu_words` orders
    /// them) and their Adam moments, for the device.
    pub(super) fn device_shader_state(&self) -> Option<[Vec<f32>; 3]> {
        let mlp = self.shader.as_ref()?;
        Some([
            mlp.flat_params(),
            self.shader_moments.m.clone(),
            self.shader_moments.v.clone(),
        ])
    }

    /// Takes [`Self::device_shader_state`]'s arrays back.
    pub(super) fn set_device_shader_state(&mut self, state: [Vec<f32>; 3]) {
        let [flat, m, v] = state;
        if let Some(mlp) = self.shader.as_mut() {
            mlp.set_flat_params(&flat);
            self.shader_moments = Moments { m, v };
        }
    }

    /// The parameters, Adam's moments (in the records' layout) and the densification
    /// statistics (sum of 2D-mean gradient norms, views seen, largest radius, 0) as the
    /// device holds them.
    pub(super) fn device_state(&self) -> [Vec<f32>; 4] {
        let s = &self.scene;
        let (n, r, c) = (self.len(), self.record_floats(), self.colour_floats());
        let colour = self.colour_group();
        let mut out = [
            vec![0f32; n * r],
            vec![0f32; n * r],
            vec![0f32; n * r],
            vec![0f32; n * 4],
        ];
        for (g, width, offset) in [(0, 3, 0), (1, 3, 3), (2, 4, 6), (3, 1, 10), (colour, c, 11)] {
            let params: Vec<f32> = match g {
                0 => s.positions.iter().flatten().copied().collect(),
                1 => s.log_scales.iter().flatten().copied().collect(),
                2 => s.rotations.iter().flatten().copied().collect(),
                3 => s.opacity_logits.clone(),
                4 => s.sh.clone(),
                _ => s.features.clone(),
            };
            for (a, src) in [&params, &self.moments[g].m, &self.moments[g].v]
                .into_iter()
                .enumerate()
            {
                for i in 0..n {
                    out[a][i * r + offset..i * r + offset + width]
                        .copy_from_slice(&src[i * width..(i + 1) * width]);
                }
            }
        }
        for i in 0..n {
            out[3][i * 4..i * 4 + 4].copy_from_slice(&[
                self.grad_accum[i],
                self.denom[i] as f32,
                self.max_radii[i],
                0.0,
            ]);
        }
        out
    }

    /// Takes the state of [`Self::device_state`]'s layout back (same Gaussians).
    pub(super) fn set_device_state(&mut self, state: [Vec<f32>; 4]) {
        let n = self.len();
        let r = self.record_floats();
        let c = self.colour_floats();
        let colour = self.colour_group();
        let [params, m, v, stats] = state;
        let rows = |src: &[f32], offset: usize, width: usize| -> Vec<f32> {
            (0..n)
                .flat_map(|i| src[i * r + offset..i * r + offset + width].iter().copied())
                .collect()
        };
        let s = &mut self.scene;
        let p3 = rows(&params, 0, 3);
        s.positions = p3.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let l3 = rows(&params, 3, 3);
        s.log_scales = l3.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let q4 = rows(&params, 6, 4);
        s.rotations = q4
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        s.opacity_logits = rows(&params, 10, 1);
        if colour == 4 {
            s.sh = rows(&params, 11, c);
        } else {
            s.features = rows(&params, 11, c);
        }
        for (g, width, offset) in [(0, 3, 0), (1, 3, 3), (2, 4, 6), (3, 1, 10), (colour, c, 11)] {
            self.moments[g] = Moments {
                m: rows(&m, offset, width),
                v: rows(&v, offset, width),
            };
        }
        self.grad_accum = (0..n).map(|i| stats[i * 4]).collect();
        self.denom = (0..n).map(|i| stats[i * 4 + 1] as u32).collect();
        self.max_radii = (0..n).map(|i| stats[i * 4 + 2]).collect();
    }

    /// Counts one Adam step of every group (not the opacities' when `skip_opacity`), as
    /// [`Self::step`] does, and returns the counts.
    pub(super) fn advance_steps(&mut self, skip_opacity: bool) -> [u32; 7] {
        for (g, t) in self.steps.iter_mut().enumerate() {
            if !(skip_opacity && g == 3) {
                *t += 1;
            }
        }
        self.steps
    }

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
        let k = crate::model::sh_coeffs_for_degree(self.active_sh_degree) * 3;
        SplatParams {
            means: s.positions.clone(),
            quats: s.rotations.clone(),
            scales: s.log_scales.iter().map(|l| l.map(f32::exp)).collect(),
            opacities: s.opacity_logits.iter().map(|&o| sigmoid(o)).collect(),
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

    /// One Adam step with the gradients of the activated parameters (`grads`, as the
    /// rasterizer returns them for [`Self::params`]) and, for feature splats, the shader's
    /// (`shader_grads`), the centres' learning rate `position_lr`; `skip_opacity` leaves
    /// the opacities (just reset) alone. With `settings.clip_grad`, the whole gradient of
    /// the stored parameters is scaled to at most that L2 norm first. Returns the norm
    /// before clipping.
    pub fn step(
        &mut self,
        grads: &SplatGrads<f32>,
        shader_grads: Option<&crate::mlp::MlpParams<f32>>,
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
            let k = crate::model::sh_coeffs_for_degree(self.active_sh_degree) * 3;
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

    /// The original's `reset_opacity`: every opacity to at most 0.01, its Adam state zero.
    pub fn reset_opacity(&mut self) {
        let cap = logit(0.01);
        for o in &mut self.scene.opacity_logits {
            *o = o.min(cap);
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
    fn push_copy(&mut self, i: usize, at: Option<([f32; 3], [f32; 3])>) {
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
    let r = crate::fit::model::rotation(q.map(|v| v / n));
    // t = S S R^T v, then R t.
    let rt = [0, 1, 2].map(|a| r[0][a] * v[0] + r[1][a] * v[1] + r[2][a] * v[2]);
    let t = [0, 1, 2].map(|a| s[a] * s[a] * rt[a]);
    [0, 1, 2].map(|a| r[a][0] * t[0] + r[a][1] * t[1] + r[a][2] * t[2])
}

/// The centres' learning rate at `step` (the original's `get_expon_lr_func`, no delay).
pub fn position_lr(settings: &Settings, extent: f32, step: u32) -> f32 {
    let t = (step as f32 / settings.position_lr_max_steps.max(1) as f32).clamp(0.0, 1.0);
    let (a, b) = (
        settings.position_lr_init * extent,
        settings.position_lr_final * extent,
    );
    (a.ln() * (1.0 - t) + b.ln() * t).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

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
