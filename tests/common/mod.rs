//! Helpers shared by the integration tests: hand-built scenes and cameras.
#![allow(dead_code)]

pub mod gpu;

use glam::{Mat3, Vec3};
use std::path::PathBuf;
use vksplat::camera::Camera;
use vksplat::scene::Scene;

/// `../shared/data`, the read-only real scenes.
pub fn shared_data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// Inverse sigmoid, to store a wanted opacity.
pub fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// Deterministic pseudo-random numbers (SplitMix64) in [0, 1).
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
}

/// A random scene of `n` Gaussians with SH degree `deg`, every field distinct.
pub fn random_scene(n: usize, deg: u32, seed: u64) -> Scene {
    let mut rng = Rng(seed);
    let mut s = Scene::empty(deg);
    for _ in 0..n {
        s.positions.push([
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ]);
        s.log_scales.push([
            rng.range(-5.0, -2.0),
            rng.range(-5.0, -2.0),
            rng.range(-5.0, -2.0),
        ]);
        s.rotations.push([
            rng.range(0.1, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ]);
        s.opacity_logits.push(rng.range(-3.0, 5.0));
        for _ in 0..s.sh_stride() {
            s.sh.push(rng.range(-1.0, 1.0));
        }
    }
    s
}

/// Appends one Gaussian: centre, isotropic scale, opacity, RGB colour as the SH DC term
/// (higher bands zero).
pub fn push_gaussian(s: &mut Scene, pos: [f32; 3], scale: f32, opacity: f32, rgb: [f32; 3]) {
    s.positions.push(pos);
    s.log_scales.push([scale.ln(); 3]);
    s.rotations.push([1.0, 0.0, 0.0, 0.0]);
    s.opacity_logits.push(logit(opacity));
    let c0 = vksplat::cpu::sh::SH_C0;
    s.sh.extend(rgb.iter().map(|c| (c - 0.5) / c0));
    s.sh.extend(std::iter::repeat(0.0).take(s.sh_stride() - 3));
}

/// A 64x64 camera at the origin looking down +z (identity pose) with focal length `f`
/// and the principal point at (32.5, 32.5), so a point on the axis lands exactly on
/// pixel (32, 32).
pub fn axis_camera(f: f32) -> Camera {
    Camera {
        name: "axis".into(),
        width: 64,
        height: 64,
        fx: f,
        fy: f,
        cx: 32.5,
        cy: 32.5,
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
    }
}
