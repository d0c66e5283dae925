//! The surface passes (`--mode normal`, `--mode median-depth`; `core::model::surface`):
//! closed forms on generated scenes (a flat Gaussian's normal, the median depth of two
//! overlapping Gaussians), the GPU's `blend_features.comp` (`SURFACE 1`) against the CPU
//! reference (`cpu::surface`) on the shared scenes and through a fisheye and an
//! equirectangular lens, frames in chunks against one piece, and the files written.
//!
//! GPU vs CPU tolerances (measured, then set with margin): the blended normal sums, per
//! channel, PSNR >= 55 dB with peak 1 (the project's frame threshold; the differences are
//! f32 rounding of the splats' conics and alphas, as for colour; measured 108-150 dB).
//! The median depth is a step function of the transmittance: a pixel whose transmittance
//! lands within rounding of 0.5 takes the neighbouring Gaussian's depth, so >= 99.9 % of
//! pixels (the project's `MIN_WITHIN`) must agree within 1e-4 relative; measured 100 %.
//! The colour, alpha and depth of a surface frame equal the plain frame's bit for bit
//! (the pass only adds a dispatch after the colour blend's inputs are made).
//! Run at every lavapipe width by `tools/test.sh`.

use crate::common::gpu::{assert_validation_clean, renderer, MIN_PSNR, MIN_WITHIN};
use crate::common::{axis_camera, logit, orbit, push_gaussian, shared_scene, PLAYBOT_ORBIT};
use glam::Vec3;
use verisplat::core::camera::Camera;
use verisplat::core::frame::Frame;
use verisplat::core::model::surface::{surface_planes, SURFACE_CHANNELS};
use verisplat::core::scene::{ActivatedScene, Scene};
use verisplat::cpu::{self, RenderOptions, SplatKernel};
use verisplat::render::{FrameRequest, GpuRenderer, Rendered, SplitLimits};

/// The GPU's surface frame of `s` from `cam`.
fn gpu_surface(
    r: &mut GpuRenderer,
    s: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
) -> Frame {
    let gs = r.upload(s).unwrap();
    let gf = r.upload_surface(s).unwrap();
    assert!(gf.is_surface() && gf.channels() == SURFACE_CHANNELS);
    r.render(&FrameRequest::new(&gs, cam, opts).features(&gf))
        .and_then(Rendered::into_frame)
        .unwrap()
}

/// One flat Gaussian (scales 0.3, 0.3, 0.001 before `rotation`) at `pos`.
fn flat_gaussian(s: &mut Scene, pos: [f32; 3], rotation: [f32; 4], opacity: f32) {
    push_gaussian(s, pos, 0.3, opacity, [0.5; 3]);
    s.log_scales.pop();
    s.log_scales.push([0.3f32.ln(), 0.3f32.ln(), 0.001f32.ln()]);
    s.rotations.pop();
    s.rotations.push(rotation);
}

#[test]
fn a_flat_gaussian_facing_the_camera_has_normal_minus_z() {
    // Tilted by theta about x, its thin axis is (0, -sin, cos) in world space; seen from
    // the origin it faces away (n . mean = 5 cos > 0), so the pass flips it:
    // (0, sin, -cos). Theta 0 is the disc square to the view: exactly (0, 0, -1).
    let mut r = renderer();
    for theta in [0.0f32, 0.5, -1.0] {
        let mut s = Scene::empty(0);
        let (c, sn) = ((theta / 2.0).cos(), (theta / 2.0).sin());
        flat_gaussian(&mut s, [0.0, 0.0, 5.0], [c, sn, 0.0, 0.0], 0.8);
        let act = s.activated();
        let cam = axis_camera(50.0);
        let want = [0.0, theta.sin(), -theta.cos()];
        let opts = RenderOptions::default();
        for (who, frame) in [
            ("cpu", cpu::surface::render_surface(&act, &cam, &opts)),
            ("gpu", gpu_surface(&mut r, &act, &cam, &opts)),
        ] {
            let i = frame.index(32, 32);
            assert!(frame.alpha[i] > 0.5, "{who}: the centre is covered");
            // Identity camera: camera and world space agree.
            for space in [None, Some(&cam)] {
                let n = surface_planes(&frame.features, &frame.alpha, space).normals[i];
                for (got, want_c) in n.iter().zip(want) {
                    assert!(
                        (got - want_c).abs() < 1e-6,
                        "{who} theta {theta}: {n:?} vs {want:?}"
                    );
                }
            }
            // Nothing hit: normal 0, median depth 0.
            let corner = frame.index(0, 0);
            assert_eq!(frame.alpha[corner], 0.0);
            assert_eq!(&frame.features[corner * 4..corner * 4 + 4], &[0.0; 4]);
        }
        if theta == 0.0 {
            let frame = gpu_surface(&mut r, &act, &cam, &opts);
            let n = surface_planes(&frame.features, &frame.alpha, Some(&cam)).normals;
            assert_eq!(n[frame.index(32, 32)], [0.0, 0.0, -1.0]);
        }
    }
    assert_validation_clean(&r);
}

#[test]
fn the_median_depth_is_the_gaussian_where_transmittance_reaches_one_half() {
    // Two Gaussians on the axis, nearer at z = 3 and farther at z = 6; at the centre pixel
    // each one's alpha is its opacity, so T = (1 - a_near), then (1 - a_near)(1 - a_far).
    let mut r = renderer();
    let cam = axis_camera(50.0);
    for (a_near, a_far) in [(0.6f32, 0.5f32), (0.3, 0.5), (0.2, 0.2), (0.5, 0.9)] {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, 6.0], 0.3, a_far, [0.5; 3]);
        push_gaussian(&mut s, [0.0, 0.0, 3.0], 0.15, a_near, [0.5; 3]);
        let act = s.activated();
        let (near, far) = (act.opacities[1], act.opacities[0]);
        let t1 = 1.0 - near;
        let t2 = t1 * (1.0 - far);
        let want = if t1 <= 0.5 {
            3.0
        } else if t2 <= 0.5 {
            6.0
        } else {
            0.0
        };
        assert!((near - a_near).abs() < 1e-6 && (far - a_far).abs() < 1e-6);
        for kernel in SplatKernel::ALL {
            let opts = RenderOptions {
                kernel,
                ..Default::default()
            };
            for (who, frame) in [
                ("cpu", cpu::surface::render_surface(&act, &cam, &opts)),
                ("gpu", gpu_surface(&mut r, &act, &cam, &opts)),
            ] {
                let i = frame.index(32, 32);
                let got = frame.features[i * 4 + 3];
                assert!(
                    (got - want).abs() < 1e-5,
                    "{who} {kernel} a = ({a_near}, {a_far}): median {got}, want {want}"
                );
                assert!((frame.alpha[i] - (1.0 - t2)).abs() < 1e-6);
            }
        }
    }
    // An opacity just across 0.5 moves the median to the nearer Gaussian.
    for (a_near, want) in [(0.499f32, 6.0f32), (0.501, 3.0)] {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, 6.0], 0.3, 0.9, [0.5; 3]);
        push_gaussian(&mut s, [0.0, 0.0, 3.0], 0.15, 0.5, [0.5; 3]);
        s.opacity_logits[1] = logit(a_near);
        let act = s.activated();
        let frame = gpu_surface(&mut r, &act, &cam, &RenderOptions::default());
        let got = frame.features[frame.index(32, 32) * 4 + 3];
        assert!((got - want).abs() < 1e-5, "a_near {a_near}: {got}");
    }
    assert_validation_clean(&r);
}

/// PSNR of channel `c` of two surface planes, peak 1.
fn channel_psnr(gpu: &[f32], cpu: &[f32], c: usize) -> f64 {
    let (mut se, mut n) = (0.0f64, 0usize);
    for (g, r) in gpu.chunks_exact(4).zip(cpu.chunks_exact(4)) {
        let d = f64::from(g[c]) - f64::from(r[c]);
        se += d * d;
        n += 1;
    }
    if se == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (n as f64 / se).log10()
    }
}

/// Holds the GPU's surface frame of `s` to the CPU reference's (module header), and its
/// colour, alpha and depth to the plain GPU frame's bits; returns the measurements.
fn check_against_reference(
    r: &mut GpuRenderer,
    label: &str,
    s: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
) -> (f64, f64) {
    let g = gpu_surface(r, s, cam, opts);
    let c = cpu::surface::render_surface(s, cam, opts);
    assert_eq!(g.feature_count, SURFACE_CHANNELS);
    assert_eq!(g.features.len(), c.features.len());
    let gs = r.upload(s).unwrap();
    let plain = r
        .render(&FrameRequest::new(&gs, cam, opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(
        crate::common::frame_bits(&g),
        crate::common::frame_bits(&plain),
        "{label}: the surface frame's colour, alpha and depth are the plain frame's"
    );
    let psnr = (0..3)
        .map(|ch| channel_psnr(&g.features, &c.features, ch))
        .fold(f64::INFINITY, f64::min);
    let pixels = g.features.len() / 4;
    let agree = g
        .features
        .chunks_exact(4)
        .zip(c.features.chunks_exact(4))
        .filter(|(a, b)| (a[3] - b[3]).abs() <= 1e-4 * b[3].abs().max(1e-3))
        .count() as f64
        / pixels as f64;
    let hit = c.features.chunks_exact(4).filter(|p| p[3] > 0.0).count();
    eprintln!(
        "{label}: normals {psnr:.1} dB, median depth {:.4} % of pixels agree ({hit} of {pixels} have one)",
        agree * 100.0
    );
    assert!(psnr >= MIN_PSNR, "{label}: normals {psnr:.1} dB");
    assert!(agree >= MIN_WITHIN, "{label}: median depth {agree}");
    assert!(hit > pixels / 100, "{label}: the scene covers the frame");
    // Camera space is world space rotated by the camera.
    let world = surface_planes(&g.features, &g.alpha, None).normals;
    let camera = surface_planes(&g.features, &g.alpha, Some(cam)).normals;
    for (w, n) in world.iter().zip(&camera) {
        let rotated = cam.rotation * Vec3::from(*w);
        assert!((rotated - Vec3::from(*n)).length() < 1e-6);
        let len = Vec3::from(*n).length();
        assert!(
            len == 0.0 || (len - 1.0).abs() < 1e-6,
            "unit normals: {len}"
        );
    }
    (psnr, agree)
}

#[test]
fn gpu_surface_pass_matches_the_reference_on_the_shared_scenes() {
    let mut r = renderer();
    for (file, cam_index, kernel, w, h) in [
        (
            "playbot_lod6_1873_sh2.ply",
            2,
            SplatKernel::Gaussian,
            480,
            270,
        ),
        (
            "playbot_lod3_31k_sh2.ply",
            5,
            SplatKernel::Gaussian,
            480,
            270,
        ),
        ("playbot_lod3_31k_sh2.ply", 9, SplatKernel::Power, 320, 180),
    ] {
        let s = shared_scene(file).activated();
        let cam = orbit(PLAYBOT_ORBIT, cam_index, w, h);
        let opts = RenderOptions {
            kernel,
            background: [0.3, 0.3, 0.3],
            ..Default::default()
        };
        check_against_reference(&mut r, &format!("{file} {kernel}"), &s, &cam, &opts);
    }
    assert_validation_clean(&r);
}

#[test]
fn gpu_surface_pass_matches_the_reference_through_a_fisheye_and_a_panorama() {
    let mut r = renderer();
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let base = orbit(PLAYBOT_ORBIT, 3, 400, 300);
    let distance = (base.position() - Vec3::new(0.0, -0.5, 0.0)).length() as f64;
    for spec in ["fisheye:fov=190", "fisheye:fov=120", "equirect"] {
        let cam = crate::common::through_lens(&base, spec, distance);
        check_against_reference(&mut r, spec, &s, &cam, &RenderOptions::default());
    }
    assert_validation_clean(&r);
}

#[test]
fn gpu_surface_pass_in_chunks_equals_one_piece() {
    let mut r = renderer();
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let cam = orbit(PLAYBOT_ORBIT, 5, 320, 180);
    let opts = RenderOptions::default();
    r.set_split_limits(SplitLimits::default());
    let whole = gpu_surface(&mut r, &s, &cam, &opts);
    r.set_split_limits(SplitLimits {
        window: 1000,
        chunk_pairs: 2000,
    });
    let split = gpu_surface(&mut r, &s, &cam, &opts);
    let chunks = r.stats().chunks;
    r.set_split_limits(SplitLimits::default());
    assert!(chunks > 1, "{chunks} chunks");
    let bits = |f: &Frame| f.features.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(&split),
        bits(&whole),
        "surface planes in {chunks} chunks"
    );
    assert_validation_clean(&r);
}

/// The channels of the EXR file at `path`, by name.
fn exr_channels(path: &std::path::Path) -> Vec<(String, Vec<f32>)> {
    let mut image = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let layer = image.layer_data.remove(0);
    layer
        .channel_data
        .list
        .into_iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect()
}

#[test]
fn surface_files_hold_the_named_channels_and_the_normal_map_colours() {
    use verisplat::core::model::surface::NormalSpace;
    use verisplat::io::output::{self, OutputOptions, RenderMode};
    let s = shared_scene("playbot_lod6_1873_sh2.ply").activated();
    let cam = orbit(PLAYBOT_ORBIT, 2, 96, 64);
    let frame = cpu::surface::render_surface(&s, &cam, &RenderOptions::default());
    let planes = surface_planes(&frame.features, &frame.alpha, Some(&cam));
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, mode: RenderMode, space: NormalSpace| {
        let opts = OutputOptions {
            mode: Some(mode),
            normal_space: space,
            ..Default::default()
        };
        let path = dir.path().join(name);
        let files = output::plan_files(&path, Some(&cam), &opts).unwrap();
        assert_eq!(files.len(), 1, "{name}: one file");
        output::write_file(&frame, &files[0], false).unwrap();
        path
    };
    // EXR: N.x, N.y, N.z, A; the median depth as Z alone, +inf where there is none.
    let n = exr_channels(&write("n.exr", RenderMode::Normal, NormalSpace::Camera));
    let names: Vec<&str> = n.iter().map(|(name, _)| name.as_str()).collect();
    assert_eq!(names, ["A", "N.x", "N.y", "N.z"]);
    for (c, (_, plane)) in n[1..].iter().enumerate() {
        assert!(plane.iter().zip(&planes.normals).all(|(v, p)| *v == p[c]));
    }
    assert_eq!(n[0].1, frame.alpha);
    let m = exr_channels(&write(
        "m.exr",
        RenderMode::MedianDepth,
        NormalSpace::Camera,
    ));
    assert_eq!(m.len(), 1);
    assert_eq!(m[0].0, "Z");
    for (z, d) in m[0].1.iter().zip(&planes.median_depth) {
        assert!(if *d > 0.0 { z == d } else { z.is_infinite() });
    }
    assert!(planes.median_depth.iter().any(|d| *d > 0.0));
    // PNG: 0.5 + 0.5 (x, -y, -z) of camera-space normals, black where alpha is 0.
    let png = image::open(write("n.png", RenderMode::Normal, NormalSpace::Camera))
        .unwrap()
        .to_rgb8();
    let (mut covered, mut facing) = (0, 0);
    for (i, px) in png.pixels().enumerate() {
        let n = planes.normals[i];
        if frame.alpha[i] == 0.0 {
            assert_eq!(px.0, [0, 0, 0]);
            continue;
        }
        covered += 1;
        let want = [n[0], -n[1], -n[2]].map(|v| verisplat::io::output::to_u8(0.5 + 0.5 * v));
        assert_eq!(px.0, want, "pixel {i}");
        facing += usize::from(px.0[2] > 128);
    }
    assert!(
        covered > 100 && facing * 10 > covered * 9,
        "{facing} of {covered} face the camera"
    );
    // Bad requests: a surface mode as .npy, a frame without the pass.
    let opts = OutputOptions {
        mode: Some(RenderMode::Normal),
        ..Default::default()
    };
    assert!(output::plan_files(&dir.path().join("n.npy"), None, &opts).is_err());
    let plain = cpu::render(&s, &cam, &RenderOptions::default());
    let files = output::plan_files(&dir.path().join("p.exr"), Some(&cam), &opts).unwrap();
    let err = output::write_file(&plain, &files[0], false).unwrap_err();
    assert!(err.to_string().contains("surface pass"), "{err}");
    assert!(!dir.path().join("p.exr").exists());
}

#[test]
fn a_compact_surface_frame_is_the_rounded_scenes() {
    // A compact upload draws fp16-rounded scales and rotations, so its axes are the
    // rounded scene's: the surface planes equal the exact upload of the rounded scene's,
    // bit for bit.
    let mut r = renderer();
    let s = shared_scene("playbot_lod3_31k_sh2.ply").activated();
    let cam = orbit(PLAYBOT_ORBIT, 3, 320, 180);
    let opts = RenderOptions::default();
    r.set_compact(true);
    let compact = gpu_surface(&mut r, &s, &cam, &opts);
    r.set_compact(false);
    let rounded = gpu_surface(&mut r, &s.compact_rounded(), &cam, &opts);
    let bits = |f: &Frame| f.features.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert!(
        bits(&compact) == bits(&rounded),
        "compact surface vs rounded scene"
    );
    assert!(bits(&compact) != bits(&gpu_surface(&mut r, &s, &cam, &opts)));
    assert_validation_clean(&r);
}
