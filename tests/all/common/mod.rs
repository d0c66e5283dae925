//! Helpers shared by the integration tests: the shared scenes and their orbit cameras,
//! hand-built scenes and cameras. `cli` runs the binary, `gpu` holds the shared renderer
//! and the GPU-vs-CPU thresholds, `dataset` makes training data sets, `viewer` drives
//! `verisplat view`.
#![allow(dead_code)]

pub mod cli;
pub mod dataset;
pub mod gpu;
pub mod viewer;

use glam::{Mat3, Vec3};
use std::path::PathBuf;
use verisplat::core::camera::Camera;
use verisplat::core::scene::Scene;
use verisplat::cpu::{RenderOptions, Rules};
use verisplat::io;

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

/// A scene of `../shared/data` (see [`shared_data`]), loaded.
pub fn shared_scene(name: &str) -> Scene {
    io::scene::load(&shared_data().join(name)).unwrap()
}

/// The 24 cameras of the shared PLAYBOT orbit (an INRIA cameras.json in `../shared/data`).
pub const PLAYBOT_ORBIT: &str = "playbot_orbit_cameras.synthetic.json";

/// The cameras of an orbit file of `../shared/data` (an INRIA cameras.json, e.g.
/// [`PLAYBOT_ORBIT`] or `plant_orbit_cameras.synthetic.json`) at the file's resolution.
pub fn orbit_cameras(file: &str) -> Vec<Camera> {
    io::camera::load_cameras_json(&shared_data().join(file)).unwrap()
}

/// Camera `i` of the orbit file `file` of `../shared/data` at `w x h` (the same view:
/// `Camera::with_resolution` scales focal lengths and principal point).
pub fn orbit(file: &str, i: usize, w: u32, h: u32) -> Camera {
    orbit_cameras(file)[i].with_resolution(w, h).unwrap()
}

/// The first `frames` cameras of the orbit file `file` at `w x h`: a camera path.
pub fn orbit_path(file: &str, frames: usize, w: u32, h: u32) -> Vec<Camera> {
    orbit_cameras(file)
        .iter()
        .take(frames)
        .map(|c| c.with_resolution(w, h).unwrap())
        .collect()
}

/// `opts` under gsplat's rules (`Rules::Gsplat`).
pub fn gsplat(opts: RenderOptions) -> RenderOptions {
    RenderOptions {
        rules: Rules::Gsplat,
        ..opts
    }
}

/// A camera whose principal point is off centre by `(dx, dy)` pixels, where gsplat's guard
/// band differs from the original's.
pub fn off_centre(cam: &Camera, dx: f32, dy: f32) -> Camera {
    let mut c = cam.clone();
    c.cx += dx;
    c.cy += dy;
    c.name = format!("{} off centre", cam.name);
    c
}

/// `cam` through the lens `spec` names (`--lens`'s form), with the focal lengths and
/// principal point it gives a camera `distance` from what it looks at.
pub fn through_lens(cam: &Camera, spec: &str, distance: f64) -> Camera {
    let spec: verisplat::core::camera::LensSpec = spec.parse().unwrap();
    let (lens, fx, fy, cx, cy) = spec.apply(cam.width, cam.height, cam.fx as f64, distance);
    Camera {
        lens,
        fx: fx as f32,
        fy: fy as f32,
        cx: cx as f32,
        cy: cy as f32,
        ..cam.clone()
    }
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

pub use verisplat::core::gen::Rng;

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
        lens: verisplat::core::camera::Lens::Pinhole,
    }
}

/// The bits of a frame's colour, alpha and depth, in that order: equal bits mean a
/// bit-identical frame (NaN-safe, unlike comparing the floats).
pub fn frame_bits(f: &verisplat::core::frame::Frame) -> Vec<u32> {
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
    let a =
        verisplat::io::image_file::parse_npy_array(&std::fs::read(path).unwrap(), path).unwrap();
    (a.shape[1], a.shape[0], a.shape[2], a.data)
}
