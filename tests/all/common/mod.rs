//! Helpers shared by the integration tests: hand-built scenes and cameras.
#![allow(dead_code)]

pub mod cli;
pub mod gpu;

use glam::{Mat3, Vec3};
use std::path::PathBuf;
use verisplat::camera::Camera;
use verisplat::scene::Scene;

/// `../shared/data`, the read-only real scenes. They are always there (in CI too), so a
/// test that needs them fails without them instead of skipping.
pub fn shared_data() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    assert!(
        dir.is_dir(),
        "{} is missing: the tests need the read-only real scenes there",
        dir.display()
    );
    dir
}

/// The documentation a user reads, as paths relative to the repository: README.md, then
/// every docs/*.md in name order (the pages whose options and examples tests check).
pub fn doc_pages() -> Vec<String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut docs: Vec<String> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    docs.sort();
    let mut all = vec!["README.md".to_string()];
    all.extend(docs);
    all
}

/// Inverse sigmoid, to store a wanted opacity.
pub fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

pub use verisplat::gen::Rng;

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
    let c0 = verisplat::cpu::sh::SH_C0;
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

/// The bits of a frame's colour, alpha and depth, in that order: equal bits mean a
/// bit-identical frame (NaN-safe, unlike comparing the floats).
pub fn frame_bits(f: &verisplat::frame::Frame) -> Vec<u32> {
    f.color
        .iter()
        .flatten()
        .chain(&f.alpha)
        .chain(&f.depth)
        .map(|v| v.to_bits())
        .collect()
}

/// An `H x W x K` float32 `.npy` image (what `render` writes for features and fields) as
/// (W, H, K, values).
pub fn npy_image(path: &std::path::Path) -> (usize, usize, usize, Vec<f32>) {
    let a = verisplat::image_file::parse_npy_array(&std::fs::read(path).unwrap(), path).unwrap();
    (a.shape[1], a.shape[0], a.shape[2], a.data)
}
