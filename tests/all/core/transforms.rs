//! Scene transforms (`src/core/scene/transform.rs`): SH bands transform exactly, transforms
//! compose, a transformed scene seen by the correspondingly transformed camera renders the
//! original image, and a flip twice is the identity. The binary's flags for them are
//! `app::transform_flags`.

use crate::common;
use crate::common::gpu::Thresholds;

use glam::{DMat3, DQuat, DVec3, Mat3, Vec3};

use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::core::scene::transform::SceneTransform;
use verisplat::core::scene::Scene;
use verisplat::cpu::sh::eval_sh;
use verisplat::io;

/// The project's bar for "the same image", 55 dB, on colour and on alpha (these tests do
/// not hold the share of 8-bit pixels within 1/255).
const SAME_IMAGE: Thresholds = Thresholds {
    within: None,
    ..Thresholds::COLOUR_AND_ALPHA
};

fn random_unit(rng: &mut common::Rng) -> DVec3 {
    loop {
        let v = DVec3::new(
            rng.range(-1.0, 1.0) as f64,
            rng.range(-1.0, 1.0) as f64,
            rng.range(-1.0, 1.0) as f64,
        );
        let l = v.length();
        if l > 0.1 && l <= 1.0 {
            return v / l;
        }
    }
}

fn random_rotation(rng: &mut common::Rng) -> SceneTransform {
    let axis = random_unit(rng);
    SceneTransform::rotation(axis.to_array(), rng.range(-180.0, 180.0) as f64).unwrap()
}

/// The SH sum of one channel without the renderer's `+0.5` and clamp at 0: `eval_sh`
/// clamps, so the value is read from whichever of `sh` and `-sh` is not clamped.
fn sh_sum(sh: &[f32], d: Vec3, channel: usize) -> f32 {
    let v = eval_sh(3, sh, d)[channel];
    if v > 0.0 {
        v - 0.5
    } else {
        let neg: Vec<f32> = sh.iter().map(|c| -c).collect();
        0.5 - eval_sh(3, &neg, d)[channel]
    }
}

#[test]
fn sh_of_every_band_transforms_exactly() {
    let mut rng = common::Rng(7);
    let mut transforms: Vec<(String, SceneTransform)> = (0..6)
        .map(|i| (format!("random rotation {i}"), random_rotation(&mut rng)))
        .collect();
    transforms.push((
        "flip y then a rotation".into(),
        SceneTransform::flip_axes(false, true, false).then(&random_rotation(&mut rng)),
    ));
    transforms.push((
        "point reflection".into(),
        SceneTransform::flip_axes(true, true, true),
    ));
    transforms.push((
        "rotation, scale and translation".into(),
        random_rotation(&mut rng)
            .then(&SceneTransform::scaling(3.5).unwrap())
            .then(&SceneTransform::translation([1.0, -2.0, 0.5]).unwrap()),
    ));
    for (name, t) in &transforms {
        let q = t.orthogonal();
        for _ in 0..20 {
            // One Gaussian of degree 3 with random coefficients in [-1, 1] (DC 0, so the
            // sum is all higher bands).
            let mut s = common::random_scene(1, 3, rng.next_u64());
            s.sh[..3].fill(0.0);
            let moved = t.apply(s.clone()).unwrap();
            for _ in 0..20 {
                let d = random_unit(&mut rng);
                let back = (q.transpose() * d).as_vec3();
                for c in 0..3 {
                    let want = sh_sum(&s.sh, back, c);
                    let got = sh_sum(&moved.sh, d.as_vec3(), c);
                    // Both sides are f32 sums of 16 terms, each at most 2.9 |c_k| in size,
                    // and the transformed coefficients are rounded to f32 once: the
                    // rounding error is below 16 * 6e-8 * 2.9 * sum |c_k| ~ 3e-6 sum |c_k|.
                    // A wrong sign or order moves the sum by about the size of a term.
                    let scale: f32 = (0..16).map(|k| s.sh[k * 3 + c].abs()).sum();
                    assert!(
                        (got - want).abs() <= 1e-5 * scale,
                        "{name}: channel {c} at {d}: {got} vs {want} (coefficient sum {scale})"
                    );
                }
            }
        }
    }
}

/// Largest difference between two scenes' fields; quaternions are compared up to sign
/// (`q` and `-q` are the same rotation).
fn max_differences(a: &Scene, b: &Scene) -> (f32, f32, f32, f32) {
    let pos = a
        .positions
        .iter()
        .zip(&b.positions)
        .flat_map(|(p, q)| (0..3).map(move |i| (p[i] - q[i]).abs()))
        .fold(0.0, f32::max);
    let ls = a
        .log_scales
        .iter()
        .zip(&b.log_scales)
        .flat_map(|(p, q)| (0..3).map(move |i| (p[i] - q[i]).abs()))
        .fold(0.0, f32::max);
    let rot = a
        .rotations
        .iter()
        .zip(&b.rotations)
        .map(|(p, q)| {
            let plus = (0..4).map(|i| (p[i] - q[i]).abs()).fold(0.0, f32::max);
            let minus = (0..4).map(|i| (p[i] + q[i]).abs()).fold(0.0, f32::max);
            plus.min(minus)
        })
        .fold(0.0, f32::max);
    let sh =
        a.sh.iter()
            .zip(&b.sh)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f32::max);
    (pos, ls, rot, sh)
}

#[test]
fn transforms_compose() {
    let mut rng = common::Rng(11);
    let scene = common::random_scene(200, 3, 5);
    // Positions lie in [-1, 1]^3 and end up within 10 of the origin; rotations keep the
    // quaternions' norms (<= 2) and the SH coefficients' band norms (<= 2.7). Each path
    // rounds to f32 at most twice, so the fields agree to a few ulps at those sizes:
    // 1e-5 for positions (ulp at 10 is 1e-6), 2e-6 for the rest.
    for case in 0..4 {
        let a = random_rotation(&mut rng);
        let b = random_rotation(&mut rng);
        // Rotating by A then by B is rotating by BA.
        let qa = DQuat::from_mat3(&a.orthogonal());
        let qb = DQuat::from_mat3(&b.orthogonal());
        let (axis, angle) = (qb * qa).to_axis_angle();
        let ba = SceneTransform::rotation(axis.to_array(), angle.to_degrees()).unwrap();
        let stepwise = b.apply(a.apply(scene.clone()).unwrap()).unwrap();
        for (name, t) in [("A.then(B)", a.then(&b)), ("rotation BA", ba)] {
            let (pos, ls, rot, sh) = max_differences(&t.apply(scene.clone()).unwrap(), &stepwise);
            assert!(
                pos <= 1e-5 && ls == 0.0 && rot <= 2e-6 && sh <= 2e-6,
                "case {case}, {name}: position {pos}, log scale {ls}, rotation {rot}, SH {sh}"
            );
        }
        // The same with flips, scales and translations in the chain.
        let x = SceneTransform::flip_axes(case % 2 == 0, true, false)
            .then(&SceneTransform::scaling(2.0).unwrap())
            .then(&a)
            .then(&SceneTransform::translation([0.5, -1.0, 2.0]).unwrap());
        let y = b
            .then(&SceneTransform::scaling(0.75).unwrap())
            .then(&SceneTransform::translation([-3.0, 0.0, 1.0]).unwrap());
        let stepwise = y.apply(x.apply(scene.clone()).unwrap()).unwrap();
        let (pos, ls, rot, sh) =
            max_differences(&x.then(&y).apply(scene.clone()).unwrap(), &stepwise);
        // log scales: ln 2 and ln 0.75 added in two f32 roundings against one.
        assert!(
            pos <= 1e-5 && ls <= 1e-6 && rot <= 2e-6 && sh <= 2e-6,
            "case {case}, chain: position {pos}, log scale {ls}, rotation {rot}, SH {sh}"
        );
        let p = DVec3::new(0.3, -0.7, 1.1);
        assert!((x.then(&y).apply_point(p) - y.apply_point(x.apply_point(p))).length() < 1e-12);
    }
}

#[test]
fn flipping_twice_is_the_identity() {
    let scene = common::random_scene(500, 3, 9);
    for flip in [
        SceneTransform::flip_axes(false, true, false),
        SceneTransform::flip_axes(true, false, true),
    ] {
        assert!(flip.then(&flip).is_identity());
        let twice = flip.apply(flip.apply(scene.clone()).unwrap()).unwrap();
        // Flips only negate and permute values (the matrices hold exactly -1, 0 and 1), so
        // positions, scales and SH come back equal as floats (== treats -0 and +0 alike),
        // and each quaternion comes back as exactly -q: a reflection turns the Gaussian by
        // half a turn, and two half turns are -1 in quaternions, the same rotation.
        assert_eq!(twice.positions, scene.positions);
        assert_eq!(twice.log_scales, scene.log_scales);
        assert_eq!(twice.sh, scene.sh);
        let negated: Vec<[f32; 4]> = scene.rotations.iter().map(|q| q.map(|v| -v)).collect();
        assert_eq!(twice.rotations, negated);
    }
}

/// The camera that sees `t` applied to the scene as `cam` saw the original: view
/// coordinates are the original's times `t.scale()`, so every projection, 2D covariance and
/// SH direction is the same. `W' = W Q^T`, `t' = s t_cam - W Q^T t_scene`. For a
/// reflection `W'` is improper (det -1), which the renderer's arithmetic accepts.
fn transformed_camera(cam: &Camera, t: &SceneTransform) -> Camera {
    let w = cam.rotation.as_dmat3();
    let qt: DMat3 = t.orthogonal().transpose();
    let rotation = w * qt;
    let translation = t.scale() * cam.translation.as_dvec3() - rotation * t.offset();
    Camera {
        rotation: rotation.as_mat3(),
        translation: translation.as_vec3(),
        ..cam.clone()
    }
}

#[test]
fn a_transformed_scene_seen_by_the_transformed_camera_renders_the_same_image() {
    let scene = io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply")).unwrap();
    let cam = camera::orbit(
        &scene.positions,
        &camera::OrbitParams {
            frames: 1,
            ..Default::default()
        },
    )
    .unwrap()
    .remove(0)
    .with_resolution(320, 180)
    .unwrap();
    let opts = verisplat::cpu::RenderOptions::default();
    let original = verisplat::cpu::render(&scene.activated(), &cam, &opts);
    let covered = original.alpha.iter().filter(|&&a| a > 0.5).count();
    assert!(
        covered > original.alpha.len() / 20,
        "the view must show the object ({covered} pixels covered)"
    );
    let depths: Vec<f32> = scene
        .positions
        .iter()
        .map(|p| (cam.rotation * Vec3::from(*p) + cam.translation).z)
        .collect();
    let rot = SceneTransform::rotation([0.3, -1.0, 0.5], 47.0).unwrap();
    let cases = [
        (
            "rotation and translation",
            rot.then(&SceneTransform::translation([2.0, -1.5, 4.0]).unwrap()),
        ),
        (
            "rotation, scale 2.5 and translation",
            rot.then(&SceneTransform::scaling(2.5).unwrap())
                .then(&SceneTransform::translation([-1.0, 0.5, 3.0]).unwrap()),
        ),
        ("scale 0.4", SceneTransform::scaling(0.4).unwrap()),
        (
            "flip y, rotation and translation (mirrored camera)",
            SceneTransform::flip_axes(false, true, false)
                .then(&rot)
                .then(&SceneTransform::translation([0.5, 0.5, -2.0]).unwrap()),
        ),
    ];
    for (name, t) in cases {
        // Scaling the scene scales view depths, and the near plane (0.2) does not scale:
        // the images agree only if no Gaussian crosses it. This camera is far from the
        // object, so the culled set is the same; checked, not assumed.
        let s = t.scale() as f32;
        let crossing = depths
            .iter()
            .filter(|&&z| {
                (z <= verisplat::cpu::NEAR_PLANE) != (z * s <= verisplat::cpu::NEAR_PLANE)
            })
            .count();
        assert_eq!(crossing, 0, "{name}: Gaussians crossing the near plane");
        let moved = t.apply(scene.clone()).unwrap();
        let cam2 = transformed_camera(&cam, &t);
        let frame = verisplat::cpu::render(&moved.activated(), &cam2, &opts);
        // Only rounding differs (positions, quaternions, SH and the camera rounded to f32
        // in another frame), which moves values by ~1e-6 and rarely tips a 1/255 or
        // tile-rectangle decision; 55 dB is the project's bar for "the same image".
        let cmp = common::gpu::compare(&frame, &original);
        assert!(
            cmp.meets(&SAME_IMAGE),
            "{name}: colour PSNR {:.1} dB, alpha PSNR {:.1} dB",
            cmp.psnr,
            cmp.alpha_psnr
        );
        eprintln!(
            "{name}: colour PSNR {:.1} dB, alpha PSNR {:.1} dB",
            cmp.psnr, cmp.alpha_psnr
        );
    }
}

#[test]
fn flip_y_seen_by_a_proper_camera_is_the_mirror_image() {
    // What a user of --flip-y sees: with the camera moved to the mirrored pose (still a
    // proper rotation), the picture is the original upside down, row j in row H-1-j.
    let scene = io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply")).unwrap();
    let cam = camera::orbit(
        &scene.positions,
        &camera::OrbitParams {
            frames: 1,
            ..Default::default()
        },
    )
    .unwrap()
    .remove(0)
    .with_resolution(320, 176)
    .unwrap();
    let opts = verisplat::cpu::RenderOptions::default();
    let original = verisplat::cpu::render(&scene.activated(), &cam, &opts);
    let flip = SceneTransform::flip_axes(false, true, false);
    let mirrored_view = transformed_camera(&cam, &flip);
    let view_flip = Mat3::from_diagonal(Vec3::new(1.0, -1.0, 1.0));
    let cam2 = Camera {
        rotation: view_flip * mirrored_view.rotation,
        translation: view_flip * mirrored_view.translation,
        ..mirrored_view
    };
    assert!(cam2.rotation.determinant() > 0.0);
    let frame = verisplat::cpu::render(&flip.apply(scene).unwrap().activated(), &cam2, &opts);
    let (w, h) = (frame.width, frame.height);
    let mut upside_down = frame.clone();
    for y in 0..h {
        for x in 0..w {
            let (i, j) = (frame.index(x, y), frame.index(x, h - 1 - y));
            upside_down.color[i] = frame.color[j];
            upside_down.alpha[i] = frame.alpha[j];
            upside_down.depth[i] = frame.depth[j];
        }
    }
    // Pixel positions mirror exactly (cy = H/2), but the tile grid is not symmetric at
    // the bottom edge and a Gaussian's 3-sigma tile rectangle may cut off different
    // faint pixels; the same 55 dB bar.
    let cmp = common::gpu::compare(&upside_down, &original);
    eprintln!(
        "mirror: colour PSNR {:.1} dB, alpha PSNR {:.1} dB",
        cmp.psnr, cmp.alpha_psnr
    );
    assert!(
        cmp.meets(&SAME_IMAGE),
        "colour PSNR {:.1} dB, alpha PSNR {:.1} dB",
        cmp.psnr,
        cmp.alpha_psnr
    );
}
