//! The Gaussians a run starts from: at the data set's points (the original's
//! `create_from_pcd`, scales from [`mean_sq_dist3`]) or random in a cube, optionally with
//! learned feature channels and a neural shader.

use super::adam::Moments;
use super::{logit, Model};
use crate::core::gen::Rng;
use crate::core::model::sh::SH_C0;
use crate::core::scene::Scene;
use crate::io::camera::colmap::Point3D;

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
        Self::from_points(&random_points(count, centre, half, rng), max_sh_degree)
    }

    pub(super) fn of(scene: Scene) -> Self {
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
            mip_filters: None,
        }
    }

    /// Learns `k` feature channels per Gaussian (started at small seeded values) and the
    /// neural shader `mlp`, which turns them into colour, instead of SH colour.
    pub fn with_features(mut self, mlp: crate::fields::mlp::Mlp, rng: &mut Rng) -> Self {
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
}

/// `count` random points in the cube of half side `half` around `centre` with random
/// colours: the original's start for data sets without points (which it also writes as
/// the model's `input.ply`).
pub fn random_points(count: usize, centre: [f32; 3], half: f32, rng: &mut Rng) -> Vec<Point3D> {
    (0..count)
        .map(|_| Point3D {
            position: [0, 1, 2].map(|a| (centre[a] + rng.range(-half, half)) as f64),
            color: [0, 1, 2].map(|_| (rng.unit() * 255.0) as u8),
        })
        .collect()
}
