//! Feature channels: blended with the colour rules against closed forms (CPU reference),
//! the GPU feature blend against the CPU reference on real scenes, and the loaders.
//!
//! GPU vs CPU tolerance: PSNR >= 55 dB per channel, the peak being the channel's largest
//! absolute CPU value (the features are not in [0, 1]); as for colour, the only
//! differences are f32 rounding in preprocess and a pixel whose transmittance lands within
//! rounding of the 1e-4 stop.

mod common;

use common::{axis_camera, push_gaussian};
use vksplat::camera::{self, Camera};
use vksplat::cpu::{self, RenderOptions, SplatKernel};
use vksplat::scene::{self, Scene};

/// Random features in [-2, 3) for every Gaussian.
fn random_features(s: &mut Scene, k: usize, seed: u64) {
    let mut rng = common::Rng(seed);
    let v = (0..s.len() * k).map(|_| rng.range(-2.0, 3.0)).collect();
    s.set_features(k, v).unwrap();
}

#[test]
fn one_and_two_splats_blend_features_like_colour() {
    // One splat on the axis at (32, 32), variance 4.3 px^2: the features at a pixel are
    // alpha * f (background 0), alpha as the colour blend's, for both kernels.
    let var = (50.0f64 * 0.2 / 5.0).powi(2) + 0.3;
    for kernel in SplatKernel::ALL {
        let opts = RenderOptions {
            kernel,
            ..Default::default()
        };
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, 5.0], 0.2, 0.8, [0.5; 3]);
        let f = [1.5f32, -0.25, 4.0];
        s.set_features(3, f.to_vec()).unwrap();
        let act = s.activated();
        let o = f64::from(act.opacities[0]);
        let (frame, feats) = cpu::render_features(&act, &axis_camera(50.0), &opts);
        for (dx, dy) in [(0i32, 0i32), (1, 2), (3, -2), (5, 0), (0, 7), (10, 10)] {
            let d2 = f64::from(dx * dx + dy * dy) / var;
            let a = match kernel {
                SplatKernel::Gaussian => o * (-0.5 * d2).exp(),
                SplatKernel::Power => o * (1.0 - d2 / 9.0).max(0.0),
            }
            .min(0.99);
            let a = if a < 1.0 / 255.0 { 0.0 } else { a };
            let i = frame.index((32 + dx) as u32, (32 + dy) as u32);
            assert!((f64::from(frame.alpha[i]) - a).abs() < 2e-6);
            for c in 0..3 {
                let want = a * f64::from(f[c]);
                let got = f64::from(feats[i * 3 + c]);
                assert!(
                    (got - want).abs() < 1e-5,
                    "{kernel} ({dx},{dy}) channel {c}: {got} vs {want}"
                );
            }
        }
        // Two splats, the nearer listed second: f = a1 f1 + a2 (1 - a1) f2 at the centre.
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, 6.0], 0.3, 0.7, [0.5; 3]);
        push_gaussian(&mut s, [0.0, 0.0, 3.0], 0.05, 0.6, [0.5; 3]);
        s.set_features(2, vec![10.0, -1.0, 2.0, 0.5]).unwrap();
        let act = s.activated();
        let (frame, feats) = cpu::render_features(&act, &axis_camera(50.0), &opts);
        let i = frame.index(32, 32);
        let (far, near) = (f64::from(act.opacities[0]), f64::from(act.opacities[1]));
        for (c, (f_far, f_near)) in [(10.0, 2.0), (-1.0, 0.5)].into_iter().enumerate() {
            let want = near * f_near + far * (1.0 - near) * f_far;
            let got = f64::from(feats[i * 2 + c]);
            assert!(
                (got - want).abs() < 1e-5,
                "{kernel} two splats: {got} vs {want}"
            );
        }
        // Background 0 for features, whatever the colour background.
        let opts_bg = RenderOptions {
            background: [1.0, 1.0, 1.0],
            ..opts.clone()
        };
        let (frame, feats) = cpu::render_features(&act, &axis_camera(50.0), &opts_bg);
        let corner = frame.index(0, 0);
        assert_eq!(frame.alpha[corner], 0.0);
        assert_eq!(&feats[corner * 2..corner * 2 + 2], &[0.0, 0.0]);
    }
}

/// The feature blend stops with the colour: channel 0 set to the colour's red gives the
/// colour image's red (background 0), bit for bit, on a real scene.
#[test]
fn a_feature_equal_to_the_colour_gives_the_colour_image() {
    let mut s = scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply")).unwrap();
    s.sh_degree = 0;
    let s = s.select(&(0..s.len()).collect::<Vec<_>>(), 0);
    let cam = orbit(3, 320, 180);
    let act = s.activated();
    let projected = cpu::preprocess(&act, &cam, &RenderOptions::default());
    let red: Vec<f32> = projected.iter().map(|p| p.color[0]).collect();
    let mut with = s.clone();
    with.set_features(1, red).unwrap();
    let (frame, feats) = cpu::render_features(&with.activated(), &cam, &RenderOptions::default());
    assert_eq!(feats.len(), frame.color.len());
    for (i, (f, c)) in feats.iter().zip(&frame.color).enumerate() {
        assert_eq!(f.to_bits(), c[0].to_bits(), "pixel {i}");
    }
}

fn orbit(i: usize, w: u32, h: u32) -> Camera {
    let cams = camera::load_cameras_json(
        &common::shared_data().join("playbot_orbit_cameras.synthetic.json"),
    )
    .unwrap();
    cams[i].with_resolution(w, h).unwrap()
}

/// PSNR of one channel of `k`, the peak being the channel's largest absolute CPU value.
fn channel_psnr(gpu: &[f32], cpu: &[f32], k: usize, c: usize) -> f64 {
    let (mut se, mut peak, mut n) = (0.0f64, 0.0f64, 0usize);
    for (g, r) in gpu.chunks_exact(k).zip(cpu.chunks_exact(k)) {
        let d = f64::from(g[c]) - f64::from(r[c]);
        se += d * d;
        peak = peak.max(f64::from(r[c]).abs());
        n += 1;
    }
    let mse = se / n as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (peak.max(1e-6).powi(2) / mse).log10()
    }
}

#[test]
fn gpu_feature_blend_matches_the_reference_for_every_channel_count() {
    let mut r = common::gpu::renderer();
    let cases = [
        (
            "playbot_lod3_31k_sh2.ply",
            1,
            3,
            640,
            360,
            SplatKernel::Gaussian,
        ),
        (
            "playbot_lod3_31k_sh2.ply",
            3,
            7,
            480,
            270,
            SplatKernel::Power,
        ),
        (
            "playbot_lod6_1873_sh2.ply",
            4,
            11,
            640,
            360,
            SplatKernel::Gaussian,
        ),
        ("plant_113k_sh0.ply", 5, 0, 400, 300, SplatKernel::Gaussian),
        (
            "playbot_lod2_125k_sh2.ply",
            17,
            5,
            320,
            180,
            SplatKernel::Power,
        ),
        (
            "playbot_lod6_1873_sh2.ply",
            64,
            2,
            256,
            144,
            SplatKernel::Gaussian,
        ),
    ];
    for (file, k, cam_index, w, h, kernel) in cases {
        let mut s = scene::load(&common::shared_data().join(file)).unwrap();
        random_features(&mut s, k, k as u64);
        let act = s.activated();
        let cam = if file.starts_with("plant") {
            camera::load_cameras_json(
                &common::shared_data().join("plant_orbit_cameras.synthetic.json"),
            )
            .unwrap()[cam_index]
                .with_resolution(w, h)
                .unwrap()
        } else {
            orbit(cam_index, w, h)
        };
        let opts = RenderOptions {
            kernel,
            background: [0.3, 0.3, 0.3],
            ..Default::default()
        };
        let gs = r.upload(&act).unwrap();
        let gf = r.upload_features(&act).unwrap();
        let (gframe, gfeat) = r.render_features(&gs, &gf, &cam, &opts).unwrap();
        assert!(r.timings().features > 0.0, "the features stage is timed");
        assert!(r.timings().stages().iter().any(|(n, _)| *n == "features"));
        let (cframe, cfeat) = cpu::render_features(&act, &cam, &opts);
        assert_eq!(gfeat.len(), (w * h) as usize * k);
        // The colour frame is the plain render's.
        assert_eq!(gframe, r.render(&gs, &cam, &opts).unwrap());
        let m = vksplat::metrics::compare_frames(&cframe, &gframe);
        assert!(m.color.psnr >= 55.0, "{file} colour {}", m.color.psnr);
        let worst = (0..k)
            .map(|c| channel_psnr(&gfeat, &cfeat, k, c))
            .fold(f64::INFINITY, f64::min);
        eprintln!("{file} K={k} {kernel}: lowest channel PSNR {worst:.1} dB");
        assert!(worst >= 55.0, "{file} K={k}: channel PSNR {worst}");
        let nonzero = cfeat.iter().filter(|v| **v != 0.0).count();
        assert!(nonzero > cfeat.len() / 100, "{file}: the features show");
    }
    common::gpu::assert_validation_clean(&r);
}
