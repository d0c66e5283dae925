//! gsplat's rules (`--rules gsplat`, `model::Rules::Gsplat`): near plane 0.01, alpha clamp
//! 0.999, the per-axis opacity-aware 3.33-sigma box, the guard band that follows the
//! principal point, the inclusive 1e-4 stop and the antialiased ratio's floor of 0.
//!
//! The CPU reference under them is checked against what the rules mean (every tail kept:
//! the frame equals a blend of every Gaussian at every pixel; the near plane; the clamp),
//! the device against the reference (frames at every blend variant, feature channels,
//! gradients), the reference's gradients against finite differences, and the CLI records
//! them in a trained model and renders with them.

use crate::common;
use crate::common::gpu::{assert_validation_clean, compare, move_towards, renderer};
use crate::gpu_frames::{check_frame, load, orbit};
use crate::gradients::{
    check_on, diff_rasterizer, gpu_against_reference, gpu_camera, grad_scene, push_large_gaussians,
};
use glam::Vec3;
use verisplat::camera::Camera;
use verisplat::cpu::{self, RenderOptions, Rules, SplatKernel};
use verisplat::model::grad::SplatParams;
use verisplat::scene::ActivatedScene;

fn gsplat(opts: RenderOptions) -> RenderOptions {
    RenderOptions {
        rules: Rules::Gsplat,
        ..opts
    }
}

/// Pixel (x, y) blended from every projected Gaussian, front to back, without tiles.
fn dense_pixel(
    p: &[cpu::Projected],
    order: &[u32],
    x: u32,
    y: u32,
    opts: &RenderOptions,
) -> [f32; 4] {
    let r = cpu::blend_pixel(p, order, x as f32, y as f32, opts.kernel, opts.rules);
    let t = r.transmittance;
    let b = opts.background;
    [
        r.color[0] + t * b[0],
        r.color[1] + t * b[1],
        r.color[2] + t * b[2],
        1.0 - t,
    ]
}

/// Under gsplat's rules no tail of a splat is cut at a tile edge: the reference frame equals,
/// bit for bit at every pixel, the blend of every visible Gaussian in depth order (the box
/// holds every pixel where alpha >= 1/255). The original's 3-sigma disc cuts the tails of
/// opaque splats, so there the two differ.
#[test]
fn gsplat_rules_keep_every_tail_the_original_cuts() {
    let s = load("playbot_lod6_1873_sh2.ply").activated();
    let wide = orbit("playbot_orbit_cameras.synthetic.json", 4, 160, 120);
    let close = move_towards(&wide, Vec3::new(0.0, -0.5, 0.0), 0.4, "closer");
    let mut cut = [0usize; 2];
    for cam in [&wide, &close] {
        for (k, rules) in Rules::ALL.into_iter().enumerate() {
            let opts = RenderOptions {
                rules,
                background: [0.1, 0.2, 0.3],
                ..Default::default()
            };
            let frame = cpu::render(&s, cam, &opts);
            let p = cpu::preprocess(&s, cam, &opts);
            let mut order: Vec<u32> = (0..p.len() as u32)
                .filter(|&i| p[i as usize].radius > 0)
                .collect();
            order.sort_by(|&a, &b| p[a as usize].depth.total_cmp(&p[b as usize].depth));
            for y in 0..cam.height {
                for x in 0..cam.width {
                    let i = (y * cam.width + x) as usize;
                    let got = [
                        frame.color[i][0],
                        frame.color[i][1],
                        frame.color[i][2],
                        frame.alpha[i],
                    ];
                    if got != dense_pixel(&p, &order, x, y, &opts) {
                        cut[k] += 1;
                    }
                }
            }
        }
    }
    eprintln!(
        "pixels that differ from the dense blend: original {}, gsplat {}",
        cut[0], cut[1]
    );
    assert_eq!(cut[1], 0, "gsplat's rules cut a tail");
    assert!(
        cut[0] > 0,
        "the original's disc cuts nothing here; the test shows nothing"
    );
}

/// One splat of `opacity` and axis scale `scale` at view depth `z` on the optical axis of
/// a camera at the origin looking down +z, red.
fn one_splat(z: f32, scale: f32, opacity: f32) -> (ActivatedScene, Camera) {
    let s = ActivatedScene {
        sh_degree: 0,
        positions: vec![[0.0, 0.0, z]],
        scales: vec![[scale; 3]],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]],
        opacities: vec![opacity],
        sh: vec![1.5, -1.7, -1.7],
        ..Default::default()
    };
    let cam = Camera::look_at("axis", 64, 48, 0.9, Vec3::ZERO, Vec3::Z, Vec3::NEG_Y);
    (s, cam)
}

fn centre_alpha(frame: &verisplat::frame::Frame, cam: &Camera) -> f32 {
    frame.alpha[(cam.height / 2 * cam.width + cam.width / 2) as usize]
}

/// gsplat's near plane (0.01 unless given) and its alpha clamp (0.999), on the CPU and on
/// the device alike.
#[test]
fn gsplats_near_plane_and_alpha_clamp() {
    let mut r = renderer();
    let both = |r: &mut verisplat::render::GpuRenderer,
                s: &ActivatedScene,
                cam: &Camera,
                o: &RenderOptions| {
        let c = cpu::render(s, cam, o);
        let gs = r.upload(s).unwrap();
        let g = r.render(&gs, cam, o).unwrap();
        (centre_alpha(&c, cam), centre_alpha(&g, cam))
    };
    // At depth 0.1: behind the original's plane (0.2), in front of gsplat's (0.01).
    let (s, cam) = one_splat(0.1, 0.002, 0.9);
    let (c, g) = both(&mut r, &s, &cam, &RenderOptions::default());
    assert_eq!((c, g), (0.0, 0.0), "the original culls at 0.2");
    let (c, g) = both(&mut r, &s, &cam, &gsplat(RenderOptions::default()));
    assert!(
        c > 0.5 && (c - g).abs() < 1e-5,
        "gsplat's rules show it: {c} {g}"
    );
    let near = gsplat(RenderOptions {
        near_plane: Some(0.15),
        ..Default::default()
    });
    assert_eq!(
        both(&mut r, &s, &cam, &near),
        (0.0, 0.0),
        "a given near plane culls"
    );
    let (s, cam) = one_splat(0.009, 0.0002, 0.9);
    assert_eq!(
        both(&mut r, &s, &cam, &gsplat(RenderOptions::default())),
        (0.0, 0.0)
    );
    // An opaque splat: alpha at its centre is the clamp.
    let (s, cam) = one_splat(2.0, 3.0, 1.0);
    for (opts, clamp) in [
        (RenderOptions::default(), 0.99),
        (gsplat(RenderOptions::default()), 0.999),
    ] {
        let (c, g) = both(&mut r, &s, &cam, &opts);
        assert!(
            (c - clamp).abs() < 1e-6 && (g - clamp).abs() < 1e-6,
            "{c} {g} vs {clamp}"
        );
    }
    assert!(RenderOptions {
        near_plane: Some(0.0),
        ..Default::default()
    }
    .validate()
    .is_err());
    assert_validation_clean(&r);
}

/// A camera whose principal point is off centre, where gsplat's guard band differs from the
/// original's.
fn off_centre(cam: &Camera, dx: f32, dy: f32) -> Camera {
    let mut c = cam.clone();
    c.cx += dx;
    c.cy += dy;
    c.name = format!("{} off centre", cam.name);
    c
}

/// Whole frames under gsplat's rules on the device against the reference: orbit, close-up
/// and inside views (where the near plane matters), an off-centre principal point, the
/// antialiased mode with the power kernel, every blend variant; and they are not the
/// original's frames.
#[test]
fn gsplat_rules_match_the_reference_on_real_scenes() {
    let s = load("playbot_lod3_31k_sh2.ply").activated();
    let wide = orbit("playbot_orbit_cameras.synthetic.json", 3, 480, 270);
    let close = move_towards(&wide, Vec3::new(0.0, -0.5, 0.0), 0.25, "close-up");
    let inside = Camera::look_at(
        "inside",
        320,
        180,
        1.4,
        Vec3::new(0.1, -0.6, -0.1),
        Vec3::new(0.0, -0.2, 1.0),
        Vec3::NEG_Y,
    );
    let shifted = off_centre(&wide, 70.0, -40.0);
    {
        let mut r = renderer();
        let plain = gsplat(RenderOptions {
            background: [0.2, 0.3, 0.4],
            ..Default::default()
        });
        for cam in [&wide, &close, &inside, &shifted] {
            check_frame(&mut r, &format!("gsplat {}", cam.name), &s, cam, &plain);
        }
        let aa = gsplat(RenderOptions {
            antialiased: true,
            kernel: SplatKernel::Power,
            ..Default::default()
        });
        check_frame(&mut r, "gsplat antialiased power", &s, &close, &aa);
        let gs = r.upload(&s).unwrap();
        for cam in [&inside, &shifted] {
            let g = r.render(&gs, cam, &plain).unwrap();
            let o = r
                .render(
                    &gs,
                    cam,
                    &RenderOptions {
                        rules: Rules::Original,
                        ..plain.clone()
                    },
                )
                .unwrap();
            eprintln!("{}: gsplat vs original {:?}", cam.name, compare(&g, &o));
            assert!(
                g.alpha != o.alpha,
                "{}: the rules change nothing here",
                cam.name
            );
        }
    }
    for kernel in verisplat::render::forward::blend::BlendKernel::all() {
        if let Some(mut r) = common::gpu::renderer_if_it_fits(kernel) {
            check_frame(
                &mut r,
                &format!("gsplat {kernel:?}"),
                &s,
                &close,
                &gsplat(RenderOptions::default()),
            );
        }
    }
}

/// Feature channels blend under gsplat's clamp and stop, on the device as in the reference.
#[test]
fn gsplat_rules_blend_feature_channels_like_the_reference() {
    let mut r = renderer();
    let cases = crate::features::TWO_SCENES_BOTH_KERNELS;
    crate::features::check_gpu_cases_with(&mut r, &cases, Rules::Gsplat);
}

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
    let cam = crate::gradients::grad_camera();
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
    crate::train::make_dataset(&data, 8, 48, 36);
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
    let (scene, _) = verisplat::scene::load_with_format(&ply).unwrap();
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
