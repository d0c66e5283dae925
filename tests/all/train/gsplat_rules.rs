//! Gradients and training under gsplat's rules (`--rules gsplat`,
//! `model::Rules::Gsplat`): the f64 reference's backward against finite differences and
//! the device's against the reference (an off-centre camera with Gaussians beyond its
//! asymmetric guard band among them), and `train --rules gsplat` recording the rules in its
//! model, which `render` then follows. Frames under them are `render::gsplat_rules`.

use super::gradients::{
    check_on, diff_rasterizer, gpu_against_reference, gpu_camera, grad_camera, grad_scene,
    push_large_gaussians,
};
use crate::common;
use crate::common::{gsplat, off_centre};
use glam::Vec3;
use verisplat::core::camera::Camera;
use verisplat::core::model::grad::SplatParams;
use verisplat::cpu::{self, RenderOptions, Rules, SplatKernel};

/// Two Gaussians whose centres lie beyond the sides of gsplat's guard band of an
/// off-centre camera (left of -(cx/fx + 0.3 tan), below (H - cy)/fy + 0.3 tan), large
/// enough to reach into the frame, among random ones.
fn off_centre_band_scene(cam: &Camera) -> SplatParams<f32> {
    let mut p = grad_scene(5, 1200, Some(1), 3);
    let [xn, _, _, yp] = cpu::clamp_limits(cam, Rules::Gsplat);
    // (Placed where no pixel's alpha lies within a step of 1/255: a Gaussian crossing the
    // skip there would make the loss jump.)
    let beyond = [
        Vec3::new(-1.2 * xn * 3.0, 0.1, 3.0),
        Vec3::new(-0.2, 1.2 * yp * 3.4, 3.4),
    ];
    push_large_gaussians(&mut p, cam, beyond);
    p
}

/// The f64 reference's gradients under gsplat's rules against central differences: SH,
/// the power kernel, the antialiased compensation (floor 0), an off-centre camera with
/// Gaussians beyond its asymmetric guard band.
#[test]
fn reference_backward_matches_finite_differences_under_gsplats_rules() {
    let cam = grad_camera();
    let p = grad_scene(8, 1100, Some(2), 3);
    check_on(
        &cam,
        &p,
        &gsplat(RenderOptions::default()),
        &[0.2, 0.1, 0.0],
        true,
        111,
    );
    let opts = gsplat(RenderOptions {
        antialiased: true,
        kernel: SplatKernel::Power,
        ..Default::default()
    });
    check_on(&cam, &p, &opts, &[0.0; 3], true, 112);
    let shifted = off_centre(&cam, 9.0, -7.0);
    let p = off_centre_band_scene(&shifted);
    check_on(
        &shifted,
        &p,
        &gsplat(RenderOptions::default()),
        &[0.0; 3],
        true,
        113,
    );
}

/// The device's backward under gsplat's rules against the reference, every group (the
/// projected quantities' too), at both blend layouts.
#[test]
fn gpu_backward_matches_the_reference_under_gsplats_rules() {
    let cam = gpu_camera();
    let shifted = off_centre(&cam, 12.0, -9.0);
    for blend in [
        None,
        Some(verisplat::render::forward::blend::BlendKernel::Shared),
    ] {
        let mut r = diff_rasterizer(blend);
        let p = grad_scene(60, 1300, Some(3), 3);
        let plain = gsplat(RenderOptions {
            background: [0.2, 0.4, 0.1],
            ..Default::default()
        });
        gpu_against_reference(&mut r, &p, &cam, &plain, 130);
        let aa = gsplat(RenderOptions {
            antialiased: true,
            ..Default::default()
        });
        gpu_against_reference(&mut r, &p, &cam, &aa, 131);
        let p = off_centre_band_scene(&shifted);
        gpu_against_reference(&mut r, &p, &shifted, &gsplat(RenderOptions::default()), 132);
    }
}

/// `train --rules gsplat` records the rules in the model it writes; `render` and `eval`
/// use them (with a note) unless `--rules` says otherwise; `convert` to a format that
/// cannot record them says so.
#[test]
fn a_model_trained_with_gsplats_rules_records_and_renders_with_them() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::dataset::make_dataset(&data, 8, 48, 36);
    let model = dir.path().join("model");
    let run = |args: &[&str]| {
        let out = common::cli::verisplat(args);
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(out.status.success(), "{args:?}: {err}");
        err
    };
    let (d, m) = (data.to_str().unwrap(), model.to_str().unwrap());
    run(&[
        "train",
        d,
        "-o",
        m,
        "--iterations",
        "60",
        "--rules",
        "gsplat",
        "--sh-degree",
        "0",
        "-q",
    ]);
    let ply = model.join("point_cloud/iteration_60/point_cloud.ply");
    let (scene, _) = verisplat::io::scene::load_with_format(&ply).unwrap();
    assert_eq!(scene.rules, Rules::Gsplat);
    let head = std::fs::read(&ply).unwrap();
    let head = String::from_utf8_lossy(&head[..400]);
    assert!(head.contains("comment verisplat rules gsplat"), "{head}");
    let png = dir.path().join("a.png");
    let p = ply.to_str().unwrap();
    let err = run(&[
        "render",
        p,
        "-o",
        png.to_str().unwrap(),
        "--width",
        "48",
        "--height",
        "36",
    ]);
    assert!(err.contains("gsplat's rules"), "{err}");
    let orig = dir.path().join("b.png");
    let err = run(&[
        "render",
        p,
        "-o",
        orig.to_str().unwrap(),
        "--width",
        "48",
        "--height",
        "36",
        "--rules",
        "original",
    ]);
    assert!(!err.contains("gsplat's rules"), "{err}");
    let splat = dir.path().join("c.splat");
    let err = run(&["convert", p, splat.to_str().unwrap()]);
    assert!(err.contains("--rules gsplat"), "{err}");
    // A model trained with the original's records nothing.
    let model2 = dir.path().join("model2");
    run(&[
        "train",
        d,
        "-o",
        model2.to_str().unwrap(),
        "--iterations",
        "20",
        "--sh-degree",
        "0",
        "-q",
    ]);
    let ply2 = model2.join("point_cloud/iteration_20/point_cloud.ply");
    assert!(!String::from_utf8_lossy(&std::fs::read(ply2).unwrap()).contains("verisplat rules"));
}
