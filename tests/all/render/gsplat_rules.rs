//! gsplat's rules (`--rules gsplat`, `model::Rules::Gsplat`: near plane 0.01, alpha clamp
//! 0.999, the per-axis opacity-aware 3.33-sigma box, the guard band that follows the
//! principal point, the inclusive 1e-4 stop and the antialiased ratio's floor of 0) on the
//! device against the CPU reference: the near plane and the clamp, whole frames at every
//! blend variant, and feature channels. The reference under them is checked against what
//! the rules mean in `reference::gsplat_rules`; gradients and training under them are
//! `train::gsplat_rules`.

use crate::common;
use crate::common::gpu::{assert_validation_clean, check_frame, compare, move_towards, renderer};
use crate::common::{gsplat, off_centre, orbit, shared_scene, PLAYBOT_ORBIT};
use glam::Vec3;
use verisplat::core::camera::Camera;
use verisplat::core::scene::ActivatedScene;
use verisplat::cpu::{self, RenderOptions, Rules, SplatKernel};
use verisplat::render::{FrameRequest, Rendered};

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

fn centre_alpha(frame: &verisplat::core::frame::Frame, cam: &Camera) -> f32 {
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
        let g = r
            .render(&FrameRequest::new(&gs, cam, o))
            .and_then(Rendered::into_frame)
            .unwrap();
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

/// Whole frames under gsplat's rules on the device against the reference: orbit, close-up
/// and inside views (where the near plane matters), an off-centre principal point, the
/// antialiased mode with the power kernel, every blend variant; and they are not the
/// original's frames.
#[test]
fn gsplat_rules_match_the_reference_on_real_scenes() {
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let wide = orbit(PLAYBOT_ORBIT, 3, 480, 270);
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
            let g = r
                .render(&FrameRequest::new(&gs, cam, &plain))
                .and_then(Rendered::into_frame)
                .unwrap();
            let o = r
                .render(&FrameRequest::new(
                    &gs,
                    cam,
                    &RenderOptions {
                        rules: Rules::Original,
                        ..plain.clone()
                    },
                ))
                .and_then(Rendered::into_frame)
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
    let cases = super::features::TWO_SCENES_BOTH_KERNELS;
    super::features::check_gpu_cases_with(&mut r, &cases, Rules::Gsplat);
}
