//! Feature channels: blended with the colour rules against closed forms (CPU reference),
//! the GPU feature blend against the CPU reference on real scenes, and the loaders.
//!
//! GPU vs CPU tolerance: PSNR >= 55 dB per channel, the peak being the channel's largest
//! absolute CPU value (the features are not in [0, 1]); as for colour, the only
//! differences are f32 rounding in preprocess and a pixel whose transmittance lands within
//! rounding of the 1e-4 stop.

use crate::common;
use crate::common::gpu::MIN_PSNR;
use crate::common::{axis_camera, orbit, push_gaussian, PLAYBOT_ORBIT};
use std::path::Path;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions, SplatKernel};
use verisplat::io;

use verisplat::render::{FrameRequest, Rendered};

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
        let frame = cpu::render_features(&act, &axis_camera(50.0), &opts);
        let feats = &frame.features;
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
        let frame = cpu::render_features(&act, &axis_camera(50.0), &opts);
        let (feats, i) = (&frame.features, frame.index(32, 32));
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
        let frame = cpu::render_features(&act, &axis_camera(50.0), &opts_bg);
        let feats = &frame.features;
        let corner = frame.index(0, 0);
        assert_eq!(frame.alpha[corner], 0.0);
        assert_eq!(&feats[corner * 2..corner * 2 + 2], &[0.0, 0.0]);
    }
}

/// The feature blend stops with the colour: channel 0 set to the colour's red gives the
/// colour image's red (background 0), bit for bit, on a real scene.
#[test]
fn a_feature_equal_to_the_colour_gives_the_colour_image() {
    let mut s = io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply")).unwrap();
    s.sh_degree = 0;
    let s = s.select(&(0..s.len()).collect::<Vec<_>>(), 0);
    let cam = orbit(PLAYBOT_ORBIT, 3, 320, 180);
    let act = s.activated();
    let projected = cpu::preprocess(&act, &cam, &RenderOptions::default());
    let red: Vec<f32> = projected.iter().map(|p| p.color[0]).collect();
    let mut with = s.clone();
    with.set_features(1, red).unwrap();
    let frame = cpu::render_features(&with.activated(), &cam, &RenderOptions::default());
    let feats = &frame.features;
    assert_eq!(feats.len(), frame.color.len());
    for (i, (f, c)) in feats.iter().zip(&frame.color).enumerate() {
        assert_eq!(f.to_bits(), c[0].to_bits(), "pixel {i}");
    }
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
    check_gpu_cases(
        &mut r,
        &[
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
        ],
    );
}

/// The storage-buffer variant (GPUs; lavapipe uses texel fetches) on 16-pixel bins.
#[test]
fn gpu_feature_blend_storage_buffer_variant_matches_the_reference() {
    let mut r =
        common::gpu::new_renderer(Some(verisplat::render::forward::blend::BlendKernel::Shared));
    check_gpu_cases(&mut r, &TWO_SCENES_BOTH_KERNELS);
}

/// Two scenes, one per kernel, at two channel counts (the storage-buffer variant's cases,
/// and gsplat's rules' in `render::gsplat_rules`).
pub(crate) const TWO_SCENES_BOTH_KERNELS: [Case; 2] = [
    (
        "playbot_lod3_31k_sh2.ply",
        5,
        3,
        320,
        180,
        SplatKernel::Gaussian,
    ),
    (
        "playbot_lod6_1873_sh2.ply",
        17,
        11,
        256,
        144,
        SplatKernel::Power,
    ),
];

/// Scene file, K, orbit camera, width, height, kernel.
pub(crate) type Case = (&'static str, usize, usize, u32, u32, SplatKernel);

fn check_gpu_cases(r: &mut verisplat::render::GpuRenderer, cases: &[Case]) {
    check_gpu_cases_with(r, cases, verisplat::cpu::Rules::Original);
}

/// [`check_gpu_cases`] under `rules`.
pub(crate) fn check_gpu_cases_with(
    r: &mut verisplat::render::GpuRenderer,
    cases: &[Case],
    rules: verisplat::cpu::Rules,
) {
    for &(file, k, cam_index, w, h, kernel) in cases {
        let mut s = io::scene::load(&common::shared_data().join(file)).unwrap();
        random_features(&mut s, k, k as u64);
        let act = s.activated();
        let cam = if file.starts_with("plant") {
            orbit("plant_orbit_cameras.synthetic.json", cam_index, w, h)
        } else {
            orbit(PLAYBOT_ORBIT, cam_index, w, h)
        };
        let opts = RenderOptions {
            kernel,
            rules,
            background: [0.3, 0.3, 0.3],
            ..Default::default()
        };
        let gs = r.upload(&act).unwrap();
        let gf = r.upload_features(&act).unwrap();
        let mut gframe = r
            .render(&FrameRequest::new(&gs, &cam, &opts).features(&gf))
            .and_then(Rendered::into_frame)
            .unwrap();
        let gfeat = std::mem::take(&mut gframe.features);
        assert_eq!(gframe.feature_count, k);
        gframe.feature_count = 0;
        assert!(r.timings().features > 0.0, "the features stage is timed");
        assert!(r.timings().stages().iter().any(|(n, _)| *n == "features"));
        let cframe = cpu::render_features(&act, &cam, &opts);
        let cfeat = &cframe.features;
        assert_eq!(gfeat.len(), (w * h) as usize * k);
        // The colour frame is the plain render's.
        assert_eq!(
            gframe,
            r.render(&FrameRequest::new(&gs, &cam, &opts))
                .and_then(Rendered::into_frame)
                .unwrap()
        );
        let m = verisplat::io::metrics::compare_frames(&cframe, &gframe);
        assert!(m.color.psnr >= MIN_PSNR, "{file} colour {}", m.color.psnr);
        let worst = (0..k)
            .map(|c| channel_psnr(&gfeat, cfeat, k, c))
            .fold(f64::INFINITY, f64::min);
        eprintln!("{file} K={k} {kernel}: lowest channel PSNR {worst:.1} dB");
        assert!(worst >= MIN_PSNR, "{file} K={k}: channel PSNR {worst}");
        let nonzero = cfeat.iter().filter(|v| **v != 0.0).count();
        assert!(nonzero > cfeat.len() / 100, "{file}: the features show");
    }
    common::gpu::assert_validation_clean(r);
}

/// A float16 `.npy` of `shape` (NumPy's `<f2`).
fn npy_f16(shape: &[usize], values: &[f32]) -> Vec<u8> {
    let f32_file = verisplat::io::image_file::npy_bytes(shape, values);
    let data_at = f32_file.len() - values.len() * 4;
    let mut out = f32_file[..data_at].to_vec();
    let at = out.windows(3).position(|w| w == b"<f4").unwrap();
    out[at + 2] = b'2';
    for v in values {
        out.extend_from_slice(&exr::prelude::f16::from_f32(*v).to_bits().to_le_bytes());
    }
    out
}

/// PLY `feat_*` are read and written back (convert keeps them in PLY, drops them with a
/// note elsewhere); `--features` attaches float32 or float16 N x K arrays; `info` reports
/// K and per-channel statistics; `render --mode features` writes EXR (feat.0 ..., A, Z) and
/// .npy (H x W x K) on the GPU and the CPU, which agree.
#[test]
fn features_through_the_cli() {
    use common::cli::{ok, s, stderr, stdout};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let n = io::scene::load(&plain).unwrap().len();
    let k = 6;
    let mut rng = common::Rng(5);
    let values: Vec<f32> = (0..n * k).map(|_| rng.range(-1.0, 2.0)).collect();
    let f32_file = d.join("f32.npy");
    std::fs::write(
        &f32_file,
        verisplat::io::image_file::npy_bytes(&[n, k], &values),
    )
    .unwrap();
    let f16_file = d.join("f16.npy");
    std::fs::write(&f16_file, npy_f16(&[n, k], &values)).unwrap();

    // PLY round trip through convert --features.
    let with = d.join("with.ply");
    ok(&["convert", s(&plain), s(&with), "--features", s(&f32_file)]);
    let loaded = io::scene::load(&with).unwrap();
    assert_eq!(loaded.feature_count, k);
    assert_eq!(loaded.features, values);
    let again = d.join("again.ply");
    ok(&["convert", s(&with), s(&again)]);
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(&with).unwrap()
    );
    let o = ok(&["convert", s(&with), s(&d.join("x.spz"))]);
    assert!(
        stderr(&o).contains("stores no feature channels"),
        "{}",
        stderr(&o)
    );
    // float16 features load to the float16 values.
    let mut h = io::scene::load(&plain).unwrap();
    verisplat::core::scene::features::attach_npy(&mut h, &f16_file).unwrap();
    assert_eq!(h.feature_count, k);
    for (a, b) in h.features.iter().zip(&values) {
        assert!((a - b).abs() <= 2e-3, "{a} vs {b}");
    }

    let info = stdout(&ok(&["info", s(&with)]));
    assert!(
        info.contains("features    6 channels per Gaussian"),
        "{info}"
    );
    assert!(info.contains("feat_5"), "{info}");
    let json: serde_json::Value = serde_json::from_str(&stdout(&ok(&[
        "info",
        s(&plain),
        "--features",
        s(&f16_file),
        "--json",
    ])))
    .unwrap();
    assert_eq!(json["feature_channels"], 6);
    let mean0 = values.iter().step_by(k).map(|v| f64::from(*v)).sum::<f64>() / n as f64;
    assert!((json["features"][0]["mean"].as_f64().unwrap() - mean0).abs() < 1e-3);

    // Render features on the GPU and the CPU, as EXR and .npy.
    let render = |scene: &Path, out: &str, extra: &[&str]| {
        let out = d.join(out);
        let mut args = vec![
            "render",
            s(scene),
            "--mode",
            "features",
            "--width",
            "200",
            "-o",
            s(&out),
        ];
        args.extend_from_slice(extra);
        let o = ok(&args);
        assert!(out.exists(), "{}", stderr(&o));
    };
    render(&with, "gpu.exr", &["--timings"]);
    render(&with, "gpu.npy", &[]);
    render(&with, "cpu.npy", &["--cpu"]);
    render(&plain, "flag.npy", &["--cpu", "--features", s(&f32_file)]);
    let read_npy = |name: &str| {
        verisplat::io::image_file::parse_npy_array(
            &std::fs::read(d.join(name)).unwrap(),
            Path::new(name),
        )
        .unwrap()
    };
    let (g, c) = (read_npy("gpu.npy"), read_npy("cpu.npy"));
    assert_eq!(g.shape, vec![113, 200, k]);
    assert_eq!(c.shape, g.shape);
    assert_eq!(read_npy("flag.npy"), c);
    for ch in 0..k {
        let psnr = channel_psnr(&g.data, &c.data, k, ch);
        assert!(psnr >= MIN_PSNR, "channel {ch}: {psnr}");
    }
    let exr = verisplat::io::image_file::read_image(&d.join("gpu.exr")).unwrap();
    let mut names: Vec<&str> = exr.names();
    names.sort();
    assert_eq!(
        names,
        ["A", "Z", "feat.0", "feat.1", "feat.2", "feat.3", "feat.4", "feat.5"]
    );
    let f3 = &exr.channel("feat.3").unwrap().values;
    assert!(f3
        .iter()
        .zip(g.data.iter().skip(3).step_by(k))
        .all(|(a, b)| a == b));
}

/// Malformed feature inputs: one clear sentence naming the file, and no output file.
#[test]
fn malformed_feature_inputs_give_one_clear_error_and_no_output() {
    use common::cli::{fails, s};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let n = io::scene::load(&plain).unwrap().len();
    let write = |name: &str, bytes: Vec<u8>| {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let mut nan = vec![0.5f32; n * 3];
    nan[3 * 10 + 1] = f32::NAN;
    let mut inf = vec![0.5f32; n * 2];
    inf[n] = f32::INFINITY;
    let cases = [
        (
            write(
                "short.npy",
                verisplat::io::image_file::npy_bytes(&[n - 1, 3], &vec![0.0; (n - 1) * 3]),
            ),
            format!(
                "has {} rows of features, but the scene has {n} Gaussians",
                n - 1
            ),
        ),
        (
            write(
                "nan.npy",
                verisplat::io::image_file::npy_bytes(&[n, 3], &nan),
            ),
            "non-finite feature (NaN) at row 10, channel 1".to_string(),
        ),
        (
            write("inf.npy", npy_f16(&[n, 2], &inf)),
            format!(
                "non-finite feature (inf) at row {}, channel {}",
                n / 2,
                n % 2
            ),
        ),
        (
            write(
                "cube.npy",
                verisplat::io::image_file::npy_bytes(&[n, 2, 2], &vec![0.0; n * 4]),
            ),
            "features are an N x K array".to_string(),
        ),
        (
            write(
                "wide.npy",
                verisplat::io::image_file::npy_bytes(&[n, 65], &vec![0.0; n * 65]),
            ),
            "1 to 64 are supported".to_string(),
        ),
        (
            write(
                "empty.npy",
                verisplat::io::image_file::npy_bytes(&[n, 0], &[]),
            ),
            "1 to 64 are supported".to_string(),
        ),
        (
            write("text.npy", b"not numpy".to_vec()),
            "is not a NumPy .npy file".to_string(),
        ),
    ];
    for (file, want) in &cases {
        for out in ["out.exr", "out.npy"] {
            let out = d.join(out);
            let e = fails(
                &[
                    "render",
                    s(&plain),
                    "--mode",
                    "features",
                    "--features",
                    s(file),
                    "-o",
                    s(&out),
                ],
                &out,
            );
            assert!(e.contains(s(file)) && e.contains(want.as_str()), "{e}");
        }
        let out = d.join("out.ply");
        let e = fails(
            &["convert", s(&plain), s(&out), "--features", s(file)],
            &out,
        );
        assert!(e.contains(want.as_str()), "{e}");
    }
    // Features mode without features, with a PNG, and .npy without the mode.
    let out = d.join("o.exr");
    let e = fails(
        &["render", s(&plain), "--mode", "features", "-o", s(&out)],
        &out,
    );
    assert!(e.contains("needs feature channels"), "{e}");
    let good = write(
        "good.npy",
        verisplat::io::image_file::npy_bytes(&[n, 1], &vec![1.0; n]),
    );
    let out = d.join("o.png");
    let e = fails(
        &[
            "render",
            s(&plain),
            "--mode",
            "features",
            "--features",
            s(&good),
            "-o",
            s(&out),
        ],
        &out,
    );
    assert!(e.contains(".exr or .npy"), "{e}");
    let out = d.join("o.npy");
    let e = fails(&["render", s(&plain), "-o", s(&out)], &out);
    assert!(e.contains("--mode features"), "{e}");
    // A PLY with a gap in its feat_* properties or more than 64 of them.
    let mut sc = io::scene::load(&plain).unwrap();
    sc.set_features(2, vec![0.0; n * 2]).unwrap();
    let bytes = io::scene::ply::to_bytes(&sc, io::scene::ply::PlyEncoding::BinaryLittleEndian);
    let header_end = bytes.windows(10).position(|w| w == b"end_header").unwrap();
    let mut gap = bytes.clone();
    let at = gap[..header_end]
        .windows(6)
        .position(|w| w == b"feat_1")
        .unwrap();
    gap[at + 5] = b'7';
    let gap = write("gap.ply", gap);
    let out = d.join("g.png");
    let e = fails(&["render", s(&gap), "-o", s(&out)], &out);
    assert!(e.contains("\"feat_1\""), "{e}");
}

/// `feat_*` survive a PLY round trip in every encoding, the filters and transforms keep
/// each Gaussian's features with it, and `select` carries them.
#[test]
fn ply_features_round_trip_and_follow_the_gaussians() {
    use verisplat::io::scene::ply::{parse, to_bytes, PlyEncoding};
    let mut s = common::random_scene(50, 1, 9);
    random_features(&mut s, 9, 3);
    for enc in [
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
        PlyEncoding::Ascii,
    ] {
        let back = parse(&to_bytes(&s, enc), Path::new("f.ply")).unwrap();
        assert_eq!(back, s, "{enc:?}");
    }
    let picked = s.select(&[7, 3, 40], 0);
    assert_eq!(picked.feature_count, 9);
    assert_eq!(&picked.features[9..18], &s.features[27..36]);
    let filter = verisplat::core::scene::filter::SceneFilter {
        min_opacity: Some(0.5),
        ..Default::default()
    };
    let kept = filter.apply(&s);
    assert!(kept.len() < s.len() && !kept.is_empty());
    for (j, p) in kept.positions.iter().enumerate() {
        let i = s.positions.iter().position(|q| q == p).unwrap();
        assert_eq!(
            kept.features[j * 9..(j + 1) * 9],
            s.features[i * 9..(i + 1) * 9]
        );
    }
    assert!(s.set_features(65, vec![0.0; 50 * 65]).is_err());
    assert!(s.set_features(2, vec![0.0; 99]).is_err());
}
