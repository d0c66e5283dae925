//! Synthetic scenes for scaling benchmarks: `n` Gaussians from a fixed seed, shaped like
//! trained scenes rather than uniform noise. About 80 % are flat splats on a few surfaces
//! (a ground patch and spheres, scales shrinking with density, mostly opaque), 15 % are
//! small fuzzy Gaussians around those surfaces (low opacity), and 5 % are large, sparse,
//! faint background Gaussians on a distant shell. World up is -y, like INRIA scenes.

use crate::core::model::sh::SH_C0;
use crate::core::model::sh_coeffs_for_degree;
use crate::core::scene::Scene;
use glam::{Quat, Vec3};

/// SplitMix64: small, fast, reproducible across platforms.
#[derive(Clone, Debug)]
pub struct Rng(pub u64);

impl Rng {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Next 32 random bits (the high half of [`Rng::next_u64`]).
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f32 {
        let u = self.unit().max(1e-7);
        let v = self.unit();
        (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
    }
    /// Uniform direction on the unit sphere.
    pub fn direction(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// A surface the splats lie on.
enum Surface {
    /// The ground patch y = 0, |x|, |z| <= 1 (normal -y, pointing up).
    Ground,
    /// A sphere.
    Sphere { centre: Vec3, radius: f32 },
}

/// `n` sort keys shaped like the renderer's tile|depth pairs of a 1280x720 frame: the high
/// word a tile id of 3,600 (mostly runs of neighbouring tiles, one in eight anywhere), the
/// low word the f32 bits of a depth in [0.2, 50). For sort tests and benchmarks.
pub fn tile_depth_keys(rng: &mut Rng, n: usize) -> Vec<u64> {
    (0..n)
        .map(|i| {
            let cluster = (i / 97) as u32 * 37 % 3600;
            let tile = if rng.next_u32() % 8 == 0 {
                rng.next_u32() % 3600
            } else {
                (cluster + rng.next_u32() % 5) % 3600
            };
            let depth = rng.range(0.2, 50.0);
            (u64::from(tile) << 32) | u64::from(depth.to_bits())
        })
        .collect()
}

/// Generates `n` Gaussians with SH degree `sh_degree` from `seed`.
pub fn synthetic_scene(n: usize, seed: u64, sh_degree: u32) -> Scene {
    let mut rng = Rng(seed ^ 0x5CE1_E5EE_D000_0000);
    let mut surfaces = vec![(Surface::Ground, 4.0f32, Vec3::new(0.45, 0.40, 0.32))];
    for _ in 0..6 {
        let radius = rng.range(0.15, 0.45);
        let centre = Vec3::new(
            rng.range(-0.7, 0.7),
            -radius - rng.range(0.0, 0.6),
            rng.range(-0.7, 0.7),
        );
        let colour = Vec3::new(
            rng.range(0.1, 0.9),
            rng.range(0.1, 0.9),
            rng.range(0.1, 0.9),
        );
        surfaces.push((
            Surface::Sphere { centre, radius },
            4.0 * std::f32::consts::PI * radius * radius,
            colour,
        ));
    }
    let total_area: f32 = surfaces.iter().map(|s| s.1).sum();
    let n_surface = (n as f32 * 0.8) as usize;
    // Typical spacing of surface splats; their tangent scale follows it.
    let spacing = (total_area / n_surface.max(1) as f32).sqrt();
    let k = sh_coeffs_for_degree(sh_degree);
    let mut scene = Scene::empty(sh_degree);
    scene.positions.reserve(n);
    for i in 0..n {
        let kind = if i < n_surface {
            0
        } else if i < n_surface + (n as f32 * 0.15) as usize {
            1
        } else {
            2
        };
        // Pick a surface proportionally to its area.
        let mut pick = rng.range(0.0, total_area);
        let mut s = &surfaces[0];
        for candidate in &surfaces {
            s = candidate;
            if pick < candidate.1 {
                break;
            }
            pick -= candidate.1;
        }
        let (point, normal) = match s.0 {
            Surface::Ground => (
                Vec3::new(rng.range(-1.0, 1.0), 0.0, rng.range(-1.0, 1.0)),
                Vec3::NEG_Y,
            ),
            Surface::Sphere { centre, radius } => {
                let d = rng.direction();
                (centre + d * radius, d)
            }
        };
        let (position, log_scales, rotation, logit, colour) = match kind {
            0 => {
                let tangent = (spacing * 0.8).ln() + 0.4 * rng.normal();
                let flat = tangent + (0.12f32).ln() + 0.3 * rng.normal();
                let align = Quat::from_rotation_arc(Vec3::Z, normal);
                let twist = Quat::from_rotation_z(rng.range(0.0, std::f32::consts::TAU));
                let logit = if rng.unit() < 0.7 {
                    4.0 + rng.normal()
                } else {
                    -1.0 + 1.5 * rng.normal()
                };
                let colour = s.2 + Vec3::new(rng.normal(), rng.normal(), rng.normal()) * 0.08;
                (
                    point,
                    [tangent, tangent + 0.3 * rng.normal(), flat],
                    align * twist,
                    logit,
                    colour,
                )
            }
            1 => {
                let p = point + rng.direction() * spacing * 3.0 * rng.unit();
                let sc = (spacing * 1.5).ln() + 0.5 * rng.normal();
                let q = Quat::from_rotation_arc(Vec3::Z, rng.direction());
                (
                    p,
                    [sc, sc + 0.3 * rng.normal(), sc + 0.3 * rng.normal()],
                    q,
                    -2.0 + rng.normal(),
                    s.2,
                )
            }
            _ => {
                let p = rng.direction() * rng.range(4.0, 8.0);
                let sc = (0.3f32).ln() + 0.5 * rng.normal();
                let q = Quat::from_rotation_arc(Vec3::Z, rng.direction());
                let sky = Vec3::new(0.35, 0.45, 0.6) + Vec3::splat(0.1 * rng.normal());
                (
                    p,
                    [sc, sc + 0.4 * rng.normal(), sc + 0.4 * rng.normal()],
                    q,
                    -2.5 + rng.normal(),
                    sky,
                )
            }
        };
        scene.positions.push(position.into());
        scene.log_scales.push(log_scales);
        scene
            .rotations
            .push([rotation.w, rotation.x, rotation.y, rotation.z]);
        scene.opacity_logits.push(logit);
        for c in 0..3 {
            scene.sh.push((colour[c] - 0.5) / SH_C0);
        }
        for _ in 1..k {
            for _ in 0..3 {
                scene.sh.push(0.05 * rng.normal());
            }
        }
    }
    scene
}

/// `n` random Gaussians in front of a camera at distance 3 or so (centres within
/// +-0.8 x +-0.6 x +-0.5, unnormalised quaternions, scales 0.03-0.3, opacities 0.2-0.95)
/// with SH colours of `colors` degree, or `channels` random direct values: the scenes the
/// gradient tests and `verisplat doctor`'s backward check differentiate.
pub fn random_splat_params(
    n: usize,
    seed: u64,
    colors: Option<u32>,
    channels: usize,
) -> crate::core::model::grad::SplatParams<f32> {
    use crate::core::model::grad::{ColorParams, SplatParams};
    let mut rng = Rng(seed);
    let mut p = SplatParams {
        means: Vec::new(),
        quats: Vec::new(),
        scales: Vec::new(),
        opacities: Vec::new(),
        colors: ColorParams::Direct {
            channels,
            values: Vec::new(),
        },
    };
    for _ in 0..n {
        p.means.push([
            rng.range(-0.8, 0.8),
            rng.range(-0.6, 0.6),
            rng.range(-0.5, 0.5),
        ]);
        // Unnormalised, with a length away from 1, to test the normalisation's gradient.
        let len = rng.range(0.5, 2.0);
        p.quats.push([
            len * rng.range(0.3, 1.0),
            len * rng.range(-1.0, 1.0),
            len * rng.range(-1.0, 1.0),
            len * rng.range(-1.0, 1.0),
        ]);
        p.scales.push([
            rng.range(0.05, 0.3),
            rng.range(0.05, 0.3),
            rng.range(0.03, 0.2),
        ]);
        p.opacities.push(rng.range(0.2, 0.95));
    }
    p.colors = match colors {
        Some(degree) => {
            let k = ((degree + 1) * (degree + 1)) as usize;
            let mut coeffs = Vec::new();
            for _ in 0..n {
                // A DC term that keeps most colours above the clamp, higher bands smaller.
                for j in 0..k {
                    for _ in 0..3 {
                        coeffs.push(if j == 0 {
                            rng.range(-0.5, 1.5)
                        } else {
                            rng.range(-0.4, 0.4)
                        });
                    }
                }
            }
            ColorParams::Sh { degree, coeffs }
        }
        None => ColorParams::Direct {
            channels,
            values: (0..n * channels).map(|_| rng.range(-1.0, 1.0)).collect(),
        },
    };
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_consistent_and_shaped_like_a_scene() {
        let a = synthetic_scene(5000, 7, 2);
        assert_eq!(a, synthetic_scene(5000, 7, 2), "same seed, same scene");
        assert_ne!(a, synthetic_scene(5000, 8, 2));
        a.check_consistent().unwrap();
        assert_eq!(a.len(), 5000);
        assert!(a
            .positions
            .iter()
            .flatten()
            .chain(a.log_scales.iter().flatten())
            .all(|v| v.is_finite()));
        let act = a.activated();
        // Dense surfaces plus a faint, large background.
        let far = a
            .positions
            .iter()
            .filter(|p| Vec3::from(**p).length() > 3.5)
            .count();
        assert!((200..=300).contains(&far), "background share: {far}");
        let opaque = act.opacities.iter().filter(|&&o| o > 0.9).count();
        assert!(opaque > 2000 && opaque < 4000, "opaque share: {opaque}");
        let max_scale = |i: usize| act.scales[i].iter().fold(0f32, |m, &v| m.max(v));
        let near_mean = (0..4000).map(max_scale).sum::<f32>() / 4000.0;
        let far_mean = (4750..5000).map(max_scale).sum::<f32>() / 250.0;
        assert!(
            far_mean > 5.0 * near_mean,
            "background Gaussians are larger: {far_mean} vs {near_mean}"
        );
    }
}
