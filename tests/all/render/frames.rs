//! Whole frames on the GPU (lavapipe, validation on) against the CPU reference, and the
//! renderer's invariants.
//!
//! Thresholds (from the project's targets; `common::gpu::Thresholds::FRAME`): PSNR >= 55
//! dB on colour clamped to [0, 1], at least 99.9 % of 8-bit pixels within 1/255, alpha
//! PSNR >= 55 dB. Depth is compared where both alphas exceed 0.5 (it is normalised by
//! alpha): at least 99.9 % of those pixels within 1e-3 relative, none beyond 2 %. The tail
//! exists because a pixel whose transmittance lands within rounding of the 1e-4 stop may
//! add one more Gaussian on one side only; its weight is below 1e-4 but its depth can be
//! tens of times the pixel's mean depth (seen in inside-the-scene views).

use crate::common;
use crate::common::gpu::{
    assert_validation_clean, check_frame, compare, move_towards, new_renderer, renderer, Thresholds,
};
use crate::common::{orbit, shared_scene};
use glam::Vec3;
use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions};

use verisplat::render::{FrameRequest, Readback, Rendered};

#[test]
fn playbot_lods_match_from_orbit_close_and_inside() {
    let mut r = renderer();
    let target = Vec3::new(0.0, -0.5, 0.0);
    let cams = "playbot_orbit_cameras.synthetic.json";
    for (file, w, h) in [
        ("playbot_lod6_1873_sh2.ply", 640, 360),
        ("playbot_lod3_31k_sh2.ply", 640, 360),
        ("playbot_lod2_125k_sh2.ply", 1280, 720),
        ("playbot_lod1_250k_sh1.ply", 480, 270),
    ] {
        let s = shared_scene(file).activated();
        let wide = orbit(cams, 5, w, h);
        check_frame(
            &mut r,
            &format!("{file} orbit 5"),
            &s,
            &wide,
            &RenderOptions::default(),
        );
        if w <= 640 {
            let close = move_towards(&wide, target, 0.25, "close-up");
            check_frame(
                &mut r,
                &format!("{file} close-up"),
                &s,
                &close,
                &RenderOptions {
                    background: [1.0, 1.0, 1.0],
                    ..Default::default()
                },
            );
            let far = move_towards(&orbit(cams, 17, w, h), target, 3.0, "wide");
            check_frame(
                &mut r,
                &format!("{file} wide"),
                &s,
                &far,
                &RenderOptions::default(),
            );
            let inside = Camera::look_at(
                "inside",
                w,
                h,
                1.4,
                Vec3::new(0.1, -0.6, -0.1),
                Vec3::new(0.0, -0.2, 1.0),
                Vec3::NEG_Y,
            );
            check_frame(
                &mut r,
                &format!("{file} inside"),
                &s,
                &inside,
                &RenderOptions {
                    background: [0.2, 0.3, 0.4],
                    ..Default::default()
                },
            );
        }
    }
}

#[test]
fn plant_and_train_match() {
    let mut r = renderer();
    let plant = shared_scene("plant_113k_sh0.ply").activated();
    check_frame(
        &mut r,
        "plant orbit 0",
        &plant,
        &orbit("plant_orbit_cameras.synthetic.json", 0, 640, 360),
        &RenderOptions::default(),
    );
    let close = move_towards(
        &orbit("plant_orbit_cameras.synthetic.json", 9, 480, 360),
        Vec3::ZERO,
        0.3,
        "close-up",
    );
    check_frame(
        &mut r,
        "plant close-up",
        &plant,
        &close,
        &RenderOptions::default(),
    );
    let train = shared_scene("train3_sh3.ply").activated();
    check_frame(
        &mut r,
        "train3 default",
        &train,
        &camera::default_camera(&train.positions, 320, 240),
        &RenderOptions::default(),
    );
    let demo = verisplat::io::demo::demo_scene().activated();
    check_frame(
        &mut r,
        "demo default",
        &demo,
        &camera::default_camera(&demo.positions, 1280, 720),
        &RenderOptions::default(),
    );
}

#[test]
fn antialiased_mode_matches_the_reference() {
    let mut r = renderer();
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 3, 480, 270);
    let opts = RenderOptions {
        antialiased: true,
        ..Default::default()
    };
    check_frame(&mut r, "antialiased", &s, &cam, &opts);
    // And it is not the plain render: compensation lowers the opacity of small splats.
    let gs = r.upload(&s).unwrap();
    let aa = r
        .render(&FrameRequest::new(&gs, &cam, &opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    let plain = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    let lowered = (0..aa.alpha.len())
        .filter(|&i| aa.alpha[i] + 1e-3 < plain.alpha[i])
        .count();
    assert!(
        lowered > aa.alpha.len() / 100,
        "only {lowered} pixels changed"
    );
}

/// The power-function kernel (`--kernel power`) against the CPU reference on every real
/// scene, from orbit, close-up, wide and inside cameras, with the same thresholds as the
/// Gaussian kernel; and it is not the Gaussian render.
#[test]
fn power_kernel_matches_the_reference_on_real_scenes() {
    let mut r = renderer();
    let power = |background: [f32; 3]| RenderOptions {
        background,
        kernel: cpu::SplatKernel::Power,
        ..Default::default()
    };
    let target = Vec3::new(0.0, -0.5, 0.0);
    let cams = "playbot_orbit_cameras.synthetic.json";
    for (file, w, h) in [
        ("playbot_lod6_1873_sh2.ply", 640, 360),
        ("playbot_lod3_31k_sh2.ply", 640, 360),
        ("playbot_lod2_125k_sh2.ply", 1280, 720),
        ("playbot_lod1_250k_sh1.ply", 480, 270),
    ] {
        let s = shared_scene(file).activated();
        let wide = orbit(cams, 7, w, h);
        check_frame(
            &mut r,
            &format!("{file} power orbit 7"),
            &s,
            &wide,
            &power([0.0; 3]),
        );
        if w <= 640 {
            let close = move_towards(&wide, target, 0.25, "close-up");
            check_frame(
                &mut r,
                &format!("{file} power close-up"),
                &s,
                &close,
                &power([1.0; 3]),
            );
            let inside = Camera::look_at(
                "inside",
                w,
                h,
                1.4,
                Vec3::new(0.1, -0.6, -0.1),
                Vec3::new(0.0, -0.2, 1.0),
                Vec3::NEG_Y,
            );
            check_frame(
                &mut r,
                &format!("{file} power inside"),
                &s,
                &inside,
                &power([0.2, 0.3, 0.4]),
            );
        }
    }
    let plant = shared_scene("plant_113k_sh0.ply").activated();
    let plant_cam = orbit("plant_orbit_cameras.synthetic.json", 0, 640, 360);
    check_frame(&mut r, "plant power", &plant, &plant_cam, &power([0.0; 3]));
    let train = shared_scene("train3_sh3.ply").activated();
    let train_cam = camera::default_camera(&train.positions, 320, 240);
    check_frame(&mut r, "train3 power", &train, &train_cam, &power([0.0; 3]));
    // With the per-frame options too (scale modifier, antialiasing, filters).
    let opts = RenderOptions {
        scale_modifier: 1.3,
        antialiased: true,
        min_opacity: Some(0.05),
        ..power([0.0; 3])
    };
    check_frame(&mut r, "plant power, options", &plant, &plant_cam, &opts);
    // Not the Gaussian render.
    let gs = r.upload(&plant).unwrap();
    let p = r
        .render(&FrameRequest::new(&gs, &plant_cam, &power([0.0; 3])))
        .and_then(Rendered::into_frame)
        .unwrap();
    let g = r
        .render(&FrameRequest::new(
            &gs,
            &plant_cam,
            &RenderOptions::default(),
        ))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(compare(&p, &g).psnr < 40.0);
    assert_validation_clean(&r);
}

/// Every blend variant with the power kernel gives the same image, matching the
/// reference; switching kernels frame to frame on one renderer gives each kernel's frame.
#[test]
fn every_blend_kernel_matches_the_reference_with_the_power_kernel() {
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 11, 400, 300);
    let power = RenderOptions {
        kernel: cpu::SplatKernel::Power,
        ..Default::default()
    };
    let mut frames = Vec::new();
    for kernel in verisplat::render::forward::blend::BlendKernel::all() {
        let Some(mut r) = common::gpu::renderer_if_it_fits(kernel) else {
            continue;
        };
        check_frame(&mut r, &format!("power {kernel:?}"), &s, &cam, &power);
        let gs = r.upload(&s).unwrap();
        let p = r
            .render(&FrameRequest::new(&gs, &cam, &power))
            .and_then(Rendered::into_frame)
            .unwrap();
        let g = r
            .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
            .and_then(Rendered::into_frame)
            .unwrap();
        assert_eq!(
            r.render(&FrameRequest::new(&gs, &cam, &power))
                .and_then(Rendered::into_frame)
                .unwrap(),
            p,
            "{kernel:?}: power again"
        );
        assert_ne!(g, p);
        // The RGBA8 readback (the viewer's) packs the same frame.
        let packed = r
            .render(&FrameRequest::new(&gs, &cam, &power).readback(Readback::Rgba8))
            .and_then(Rendered::into_rgba8)
            .unwrap();
        let want: Vec<u8> = p
            .color
            .iter()
            .flat_map(|c| c.map(verisplat::io::output::to_u8).into_iter().chain([255]))
            .collect();
        assert!(packed.rgba == want, "{kernel:?}: rgba8 readback");
        assert_validation_clean(&r);
        frames.push(p);
    }
    for f in &frames[1..] {
        assert_eq!(f, &frames[0]);
    }
}

#[test]
fn every_blend_kernel_matches_the_reference() {
    // The GPU kernel (one pixel per thread, shared memory) and the CPU-device kernels
    // (texel fetches, strips of pixels per invocation) all run here, whatever the device.
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 11, 400, 300);
    let mut frames = Vec::new();
    for kernel in verisplat::render::forward::blend::BlendKernel::all() {
        let Some(mut r) = common::gpu::renderer_if_it_fits(kernel) else {
            continue;
        };
        assert_eq!(r.blend_kernel(), kernel);
        check_frame(
            &mut r,
            &format!("{kernel:?}"),
            &s,
            &cam,
            &RenderOptions::default(),
        );
        let gs = r.upload(&s).unwrap();
        frames.push(
            r.render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
                .and_then(Rendered::into_frame)
                .unwrap(),
        );
    }
    // Same arithmetic per pixel in every variant.
    for f in &frames[1..] {
        assert_eq!(f, &frames[0]);
    }
}

#[test]
fn gaussians_outside_the_view_change_no_pixel() {
    let mut r = renderer();
    let base = shared_scene("playbot_lod6_1873_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 0, 320, 180);
    let opts = RenderOptions::default();
    let gs = r.upload(&base.activated()).unwrap();
    let reference = r
        .render(&FrameRequest::new(&gs, &cam, &opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    let visible = r.stats().visible;
    let mut more = base.clone();
    let eye = cam.position();
    let back = cam.rotation.transpose() * Vec3::new(0.0, 0.0, -1.0);
    let right = cam.rotation.transpose() * Vec3::X;
    for k in 0..50 {
        let k = k as f32;
        // Behind the camera, far to the side, and beyond the near plane's reach.
        common::push_gaussian(
            &mut more,
            (eye + back * (1.0 + k * 0.1)).into(),
            0.05,
            0.9,
            [1.0, 0.0, 0.0],
        );
        common::push_gaussian(
            &mut more,
            (eye + right * (50.0 + k)).into(),
            0.05,
            0.9,
            [0.0, 1.0, 0.0],
        );
        common::push_gaussian(
            &mut more,
            (eye + (cam.rotation.transpose() * Vec3::Z) * 0.1).into(),
            0.01,
            0.9,
            [0.0, 0.0, 1.0],
        );
    }
    let gs = r.upload(&more.activated()).unwrap();
    let with_more = r
        .render(&FrameRequest::new(&gs, &cam, &opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(
        with_more, reference,
        "invisible Gaussians changed the image"
    );
    assert_eq!(
        r.stats().visible,
        visible,
        "none of the added Gaussians is visible"
    );
    assert_validation_clean(&r);
}

#[test]
fn empty_scene_renders_the_background_and_renders_are_deterministic() {
    let mut r = renderer();
    let empty = Scene::empty(2).activated();
    let cam = camera::default_camera(&[], 100, 70);
    let gs = r.upload(&empty).unwrap();
    let f = r
        .render(&FrameRequest::new(
            &gs,
            &cam,
            &RenderOptions {
                background: [0.25, 0.5, 0.75],
                ..Default::default()
            },
        ))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(f.color.iter().all(|c| *c == [0.25, 0.5, 0.75]));
    assert!(f.alpha.iter().all(|&a| a == 0.0) && f.depth.iter().all(|&d| d == 0.0));
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 8, 500, 280);
    let gs = r.upload(&s).unwrap();
    let a = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    let b = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(a
        .color
        .iter()
        .flatten()
        .zip(b.color.iter().flatten())
        .all(|(x, y)| x.to_bits() == y.to_bits()));
    assert_eq!(a, b);
    assert_validation_clean(&r);
}

#[test]
fn key_buffers_grow_when_a_frame_needs_more_pairs() {
    // 64 Gaussians that each cover the whole 1280x720 frame: 64 pairs per bin (3,600
    // 16-pixel or 14,400 8-pixel bins), more than the initial capacity, so the frame is
    // recorded again with larger buffers.
    let mut s = Scene::empty(0);
    for k in 0..64 {
        common::push_gaussian(
            &mut s,
            [0.01 * k as f32, 0.0, 3.0 + 0.01 * k as f32],
            4.0,
            0.05,
            [0.5, 0.2, 0.1],
        );
    }
    let act = s.activated();
    let cam = common::axis_camera(50.0)
        .with_resolution(1280, 720)
        .unwrap();
    let mut r = new_renderer(None);
    let gs = r.upload(&act).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(r.stats().regrows, 1);
    let (bx, by) = verisplat::render::bin_grid(r.blend_kernel().bin_size(), 1280, 720);
    assert_eq!(
        r.stats().pairs,
        64 * u64::from(bx * by),
        "every Gaussian covers every bin"
    );
    let c = cpu::render(&act, &cam, &RenderOptions::default());
    let cmp = compare(&g, &c);
    assert!(cmp.meets(&Thresholds::COLOUR), "{cmp:?}");
    // The next frame fits without regrowing.
    r.render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(r.stats().regrows, 0);
    assert_validation_clean(&r);
}

#[test]
fn teardown_leaves_no_allocation_and_no_validation_message() {
    let mut r = new_renderer(None);
    let log = r.ctx().validation_log();
    let s = shared_scene("playbot_lod6_1873_sh2.ply").activated();
    let gs = r.upload(&s).unwrap();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 3, 200, 120);
    r.render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(r.ctx().live_allocations().0 > 0);
    drop(gs);
    let ctx = r.into_context();
    assert_eq!(
        ctx.live_allocations(),
        (0, 0),
        "gpu-allocator still holds allocations"
    );
    drop(ctx);
    // vkDestroyDevice reports any object still alive through the validation layer.
    let messages = log.lock().unwrap().clone();
    assert!(
        messages.is_empty(),
        "teardown messages:\n{}",
        messages.join("\n")
    );
}

#[test]
fn a_scene_beyond_one_storage_binding_renders_in_preprocess_windows() {
    let mut r = renderer();
    // 48 bytes of position, scale, rotation and opacity per Gaussian (and 48 per splat):
    // past the device's maxStorageBufferRange (128 MiB on lavapipe: 2,796,203
    // Gaussians), so preprocess runs in two windows. Every 997th Gaussian is in view, at
    // its own place with its own colour and opacity, from both windows; the rest are
    // behind the camera. A window bound at the wrong offset would move or recolour them.
    let range = u64::from(r.ctx().info().max_storage_buffer_range);
    let n = (range / 48 + 200_000) as usize;
    assert!(
        n < 30_000_000,
        "this test is sized for lavapipe-like limits (range {range})"
    );
    let mut s = Scene::empty(0);
    s.positions = (0..n)
        .map(|i| {
            let k = (i / 997) as f32;
            let (x, y) = ((k % 60.0 - 30.0) * 0.05, ((k / 60.0).floor() - 24.0) * 0.05);
            [
                x,
                y,
                if i % 997 == 0 {
                    5.0 + (k % 7.0) * 0.1
                } else {
                    -5.0
                },
            ]
        })
        .collect();
    s.log_scales = vec![[-4.0; 3]; n];
    s.rotations = vec![[1.0, 0.0, 0.0, 0.0]; n];
    s.opacity_logits = (0..n).map(|i| (i % 5) as f32 - 1.0).collect();
    s.sh = (0..n * 3)
        .map(|i| ((i * 37) % 101) as f32 / 50.0 - 1.0)
        .collect();
    let s = s.activated();
    let cam = Camera::look_at("front", 200, 160, 0.9, Vec3::ZERO, Vec3::Z, Vec3::NEG_Y);
    let gs = r.upload(&s).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    let c = cpu::render(&s, &cam, &RenderOptions::default());
    let cmp = compare(&g, &c);
    eprintln!("{n} Gaussians: {cmp:?}, {:?}", r.stats());
    assert!(r.stats().visible > 2500, "{:?}", r.stats());
    assert!(cmp.meets(&Thresholds::COLOUR), "{cmp:?}");
    assert_validation_clean(&r);
    drop(r);
}

#[test]
fn sh3_coefficients_beyond_one_storage_binding_render_through_the_texel_buffer() {
    let mut r = renderer();
    // SH degree 3 is 192 bytes of coefficients per Gaussian: more than 699,050 Gaussians
    // exceed one storage binding on lavapipe (128 MiB). SH is read through a texel buffer,
    // so such a scene renders, and it matches the reference.
    let range = u64::from(r.ctx().info().max_storage_buffer_range);
    let n = (range / 192 + 1000) as usize;
    assert!(
        n < 3_000_000,
        "sized for lavapipe-like limits (range {range})"
    );
    let mut s = verisplat::core::gen::synthetic_scene(n, 7, 3);
    // The generator's SH bands above DC are small; make the view-dependent part visible.
    let stride = s.sh_stride();
    for (i, v) in s.sh.iter_mut().enumerate() {
        if i % stride >= 3 {
            *v = ((i * 2_654_435_761) % 1000) as f32 / 1000.0 - 0.5;
        }
    }
    assert!(s.sh.len() as u64 * 4 > range);
    let act = s.activated();
    let cam = camera::default_camera(&act.positions, 240, 135);
    check_frame(
        &mut r,
        "SH3 beyond one binding",
        &act,
        &cam,
        &RenderOptions::default(),
    );
}

#[test]
fn texel_kernel_falls_back_to_16_pixel_bins_past_its_pair_limit() {
    // 1,200 Gaussians covering the whole 1280x720 frame: 1,200 x 14,400 8-pixel bins is
    // more pairs than the texel kernel keys by 8-pixel bins (SMALL_BIN_MAX_PAIRS, 2^24;
    // past it the sort costs more than the shorter lists save), 1,200 x 3,600 16-pixel bins
    // is not, so the frame is keyed by 16-pixel bins.
    let mut s = Scene::empty(0);
    for k in 0..1200 {
        let f = k as f32;
        common::push_gaussian(
            &mut s,
            [0.001 * f, -0.0005 * f, 3.0 + 0.002 * f],
            4.0,
            0.05,
            [0.2, 0.5, 0.8],
        );
    }
    let act = s.activated();
    let cam = common::axis_camera(50.0)
        .with_resolution(1280, 720)
        .unwrap();
    let mut r = new_renderer(Some(
        verisplat::render::forward::blend::BlendKernel::Texel { strip: 2 },
    ));
    let limit = u64::from(verisplat::render::SMALL_BIN_MAX_PAIRS);
    assert!((1200 * 3_600..1200 * 14_400).contains(&limit));
    let gs = r.upload(&act).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(r.stats().bin_size, 16);
    assert_eq!(r.stats().pairs, 1200 * 3600);
    assert!(r.stats().regrows >= 1, "the first frame tried 8-pixel bins");
    let c = cpu::render(&act, &cam, &RenderOptions::default());
    let cmp = compare(&g, &c);
    assert!(cmp.meets(&Thresholds::COLOUR), "{cmp:?}");
    // The next frame of the same size starts with 16-pixel bins (no attempt dropped), and
    // gives the same image.
    let again = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!((r.stats().bin_size, r.stats().regrows), (16, 0));
    assert!(common::frame_bits(&again) == common::frame_bits(&g));
    // Another size starts with the kernel's 8-pixel bins again (and keeps them: its pairs
    // fit under the limit).
    let small = cam.with_resolution(320, 180).unwrap();
    r.render(&FrameRequest::new(&gs, &small, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!((r.stats().bin_size, r.stats().regrows), (8, 0));
    assert_validation_clean(&r);
}

#[test]
fn lavapipe_loop_limit_means_larger_bins_or_a_clear_refusal() {
    // llvmpipe ends all loops of a shader invocation after 65,535 iterations in total.
    // (1) At 3840x2160 a Gaussian covering the frame spans 129,600 8-pixel bins: the
    //     frame falls back to 16-pixel bins (32,400) and still matches the reference.
    let mut s = Scene::empty(0);
    for k in 0..3 {
        let f = k as f32;
        common::push_gaussian(
            &mut s,
            [0.01 * f, 0.0, 3.0 + 0.1 * f],
            4.0,
            0.2,
            [0.9, 0.4, 0.1],
        );
    }
    let act = s.activated();
    let cam = common::axis_camera(50.0)
        .with_resolution(3840, 2160)
        .unwrap();
    let mut r = new_renderer(Some(
        verisplat::render::forward::blend::BlendKernel::Texel { strip: 2 },
    ));
    let limited = r.ctx().info().name.contains("llvmpipe");
    let gs = r.upload(&act).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    if limited {
        assert_eq!(r.stats().bin_size, 16, "fell back to 16-pixel bins");
    }
    let c = cpu::render(&act, &cam, &RenderOptions::default());
    let cmp = compare(&g, &c);
    assert!(cmp.meets(&Thresholds::COLOUR), "{cmp:?}");

    // (2) 70,000 Gaussians piled on one pixel: the far pixels of their bin never finish,
    //     so the blend would need 70,000 iterations there. On llvmpipe that is refused.
    let mut s = Scene::empty(0);
    for k in 0..70_000 {
        common::push_gaussian(
            &mut s,
            [-0.6, -0.6, 3.0 + 1e-5 * k as f32],
            0.01,
            0.9,
            [1.0, 1.0, 1.0],
        );
    }
    let act = s.activated();
    let cam = common::axis_camera(50.0);
    let gs = r.upload(&act).unwrap();
    match r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
    {
        Err(e) if limited => {
            let e = e.to_string();
            assert!(
                e.contains("65535") && e.contains("Gaussians in one bin") && e.contains("llvmpipe"),
                "{e}"
            );
        }
        Err(e) => panic!("only llvmpipe has a loop limit: {e}"),
        Ok(frame) => {
            assert!(!limited, "llvmpipe must refuse a frame it cannot finish");
            let c = cpu::render(&act, &cam, &RenderOptions::default());
            assert!(compare(&frame, &c).meets(&Thresholds::PSNR));
        }
    }
    assert_validation_clean(&r);
}

/// The per-frame options the viewer's sliders drive (scale modifier, max-scale and
/// min-opacity filters, SH degree) match the reference on the GPU, and a filter applied per
/// frame renders exactly what a scene filtered on load renders, on both renderers.
#[test]
fn per_frame_options_match_the_reference_and_the_load_filters() {
    let mut r = renderer();
    let scene = shared_scene("playbot_lod3_31k_sh2.ply");
    let s = scene.activated();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 3, 480, 270);
    // A threshold inside the scene's range of largest scales (its median).
    let mut largest: Vec<f32> = s.scales.iter().map(|v| v[0].max(v[1]).max(v[2])).collect();
    largest.sort_by(f32::total_cmp);
    let median_scale = largest[largest.len() / 2];
    for (label, opts) in [
        (
            "scale modifier 0.5",
            RenderOptions {
                scale_modifier: 0.5,
                ..Default::default()
            },
        ),
        (
            "scale modifier 1.7",
            RenderOptions {
                scale_modifier: 1.7,
                ..Default::default()
            },
        ),
        (
            "max scale at the median",
            RenderOptions {
                max_scale: Some(median_scale),
                ..Default::default()
            },
        ),
        (
            "min opacity 0.5, sh degree 0",
            RenderOptions {
                min_opacity: Some(0.5),
                sh_degree: Some(0),
                ..Default::default()
            },
        ),
    ] {
        check_frame(&mut r, label, &s, &cam, &opts);
    }

    // Per-frame filters == filters on load, bit for bit, GPU and CPU.
    let filter = verisplat::core::scene::filter::SceneFilter {
        max_scale: Some(median_scale),
        min_opacity: Some(0.3),
        sh_degree: Some(1),
        crop: None,
    };
    let filtered = filter.apply(&scene).activated();
    assert!(filtered.len() < s.len() && !filtered.is_empty());
    let per_frame = RenderOptions {
        max_scale: filter.max_scale,
        min_opacity: filter.min_opacity,
        sh_degree: filter.sh_degree,
        ..Default::default()
    };
    let cpu_loaded = cpu::render(&filtered, &cam, &RenderOptions::default());
    let cpu_frame = cpu::render(&s, &cam, &per_frame);
    assert!(
        cpu_loaded == cpu_frame,
        "CPU: per-frame filters differ from load filters"
    );
    let full = r.upload(&s).unwrap();
    let part = r.upload(&filtered).unwrap();
    let gpu_loaded = r
        .render(&FrameRequest::new(&part, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    let gpu_frame = r
        .render(&FrameRequest::new(&full, &cam, &per_frame))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(
        gpu_loaded == gpu_frame,
        "GPU: per-frame filters differ from load filters"
    );
    // And the filters do something.
    let plain = r
        .render(&FrameRequest::new(&full, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(plain != gpu_frame);
    // Bad values are refused, not rendered.
    for bad in [
        RenderOptions {
            scale_modifier: 0.0,
            ..Default::default()
        },
        RenderOptions {
            max_scale: Some(f32::NAN),
            ..Default::default()
        },
        RenderOptions {
            min_opacity: Some(1.5),
            ..Default::default()
        },
    ] {
        let e = r
            .render(&FrameRequest::new(&full, &cam, &bad))
            .and_then(Rendered::into_frame)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scale") || e.contains("opacity"), "{e}");
    }
    assert_validation_clean(&r);
}

/// The RGBA8 readback (packed on the device) equals the 8-bit quantisation of the float
/// frame that PNG files are written from, bit for bit, and reads back 4 bytes per pixel.
#[test]
fn rgba8_readback_equals_the_quantised_float_frame() {
    let mut r = renderer();
    let s = shared_scene("playbot_lod2_125k_sh2.ply").activated();
    for (k, (w, h), bg) in [
        (5, (640, 360), [0.0, 0.0, 0.0]),
        (9, (333, 217), [1.0, 1.0, 1.0]),
        (2, (1280, 720), [0.25, 0.5, 0.75]),
    ] {
        let cam = orbit("playbot_orbit_cameras.synthetic.json", k, w, h);
        let opts = RenderOptions {
            background: bg,
            ..Default::default()
        };
        let gs = r.upload(&s).unwrap();
        let float = r
            .render(&FrameRequest::new(&gs, &cam, &opts))
            .and_then(Rendered::into_frame)
            .unwrap();
        let packed = r
            .render(&FrameRequest::new(&gs, &cam, &opts).readback(Readback::Rgba8))
            .and_then(Rendered::into_rgba8)
            .unwrap();
        assert_eq!((packed.width, packed.height), (w, h));
        assert_eq!(packed.rgba.len(), (w * h * 4) as usize);
        let want: Vec<u8> = float
            .color
            .iter()
            .flat_map(|c| {
                [
                    verisplat::io::output::to_u8(c[0]),
                    verisplat::io::output::to_u8(c[1]),
                    verisplat::io::output::to_u8(c[2]),
                    255,
                ]
            })
            .collect();
        let diff = (0..want.len()).find(|&i| want[i] != packed.rgba[i]);
        assert!(
            diff.is_none(),
            "camera {k} at {w}x{h}: byte {:?} differs",
            diff.map(|i| (i, want[i], packed.rgba[i]))
        );
        // Frames alternate freely between the two readbacks.
        let again = r
            .render(&FrameRequest::new(&gs, &cam, &opts))
            .and_then(Rendered::into_frame)
            .unwrap();
        assert!(again == float);
    }
    assert_validation_clean(&r);
}

/// The viewer's previews (frames while the camera moves) draw the most important
/// Gaussians, uploaded once most important first: a preview of `k` equals a render of
/// exactly the `k` most important (its prefix), one of the scene's count or more draws
/// the whole scene, the view at rest draws the whole scene, and `set_preview(0)`
/// previews with the whole scene.
#[test]
fn viewer_previews_draw_the_most_important_gaussians() {
    use verisplat::app::view::source::{
        GpuSource, ViewSettings, ViewSource, DEFAULT_PREVIEW_GAUSSIANS,
    };
    let scene = shared_scene("playbot_lod2_125k_sh2.ply");
    // The ranking: every kept Gaussian weighs at least as much as every dropped one.
    let weight = |i: usize| {
        let mut s = scene.log_scales[i];
        s.sort_by(f32::total_cmp);
        verisplat::core::scene::sigmoid(scene.opacity_logits[i]) * (s[1] + s[2]).exp()
    };
    let keep = scene.most_important(1000);
    assert_eq!(keep.len(), 1000);
    assert!(keep.windows(2).all(|w| w[0] < w[1]), "kept in scene order");
    let lightest_kept = keep
        .iter()
        .map(|&i| weight(i))
        .fold(f32::INFINITY, f32::min);
    let heaviest_dropped = (0..scene.len())
        .filter(|i| keep.binary_search(i).is_err())
        .map(weight)
        .fold(0.0, f32::max);
    assert!(lightest_kept >= heaviest_dropped);
    assert_eq!(scene.most_important(usize::MAX).len(), scene.len());
    // Ranked: heaviest first, and its first k are the k most important.
    let ranked = scene.ranked_by_importance(30_000);
    assert!(ranked.windows(2).all(|w| weight(w[0]) >= weight(w[1])));
    let mut first = ranked[..1000].to_vec();
    first.sort_unstable();
    assert_eq!(first, keep);

    let cam = orbit("playbot_orbit_cameras.synthetic.json", 4, 320, 180);
    let settings = ViewSettings::default();
    let mut src = GpuSource::new(&scene, None, false, DEFAULT_PREVIEW_GAUSSIANS).unwrap();
    // The subset holds the whole scene, most important first (the scene is smaller).
    assert_eq!(
        src.preview_subset() as usize,
        DEFAULT_PREVIEW_GAUSSIANS.min(scene.len())
    );
    let full = src.render(&cam, &settings).unwrap();
    assert_eq!(full.gaussians as usize, scene.len());
    let mut r = renderer();
    for k in [1000, 24_576] {
        let preview = src.render_preview(&cam, &settings, k).unwrap();
        assert_eq!(preview.gaussians, k);
        assert!(full.rgba8 != preview.rgba8);
        // The preview is the render of the k most important, bit for bit.
        let subset = scene
            .select(&scene.ranked_by_importance(k as usize), scene.sh_degree)
            .activated();
        let gs = r.upload(&subset).unwrap();
        let want = r
            .render(
                &FrameRequest::new(&gs, &cam, &RenderOptions::default()).readback(Readback::Rgba8),
            )
            .and_then(Rendered::into_rgba8)
            .unwrap();
        assert!(
            want.rgba == preview.rgba8,
            "the preview of {k} is not their render"
        );
    }
    // Asking for the scene's count (or more) draws the whole scene; past the subset's
    // size short of it, the subset.
    let whole = src.render_preview(&cam, &settings, 125_000).unwrap();
    assert_eq!(whole.gaussians as usize, scene.len());
    assert!(whole.rgba8 == full.rgba8);
    let most = src.render_preview(&cam, &settings, 124_000).unwrap();
    assert_eq!(
        most.gaussians as usize,
        DEFAULT_PREVIEW_GAUSSIANS.min(124_000)
    );
    // Off: previews draw everything.
    src.set_preview(&scene, 0).unwrap();
    assert_eq!(src.preview_subset(), 0);
    assert!(src.render_preview(&cam, &settings, 1000).unwrap().rgba8 == full.rgba8);
    assert_validation_clean(src.renderer());
    assert_validation_clean(&r);
}
