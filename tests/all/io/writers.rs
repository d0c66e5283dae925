//! The PlayCanvas compressed-PLY and SOG writers: the shared scenes round-trip through each
//! writer and the reader within the format's quantisation, render close to the source,
//! give the same bytes every time, and refuse what they cannot write.

use crate::common;
use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::core::model::{Rules, SplatKernel};
use verisplat::core::scene::{self, sigmoid, Scene};
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;

use verisplat::io::scene::write::{self, ConvertError, ConvertOptions, OutputFormat};
use verisplat::io::scene::{quantize, SceneFormat};

const SH_C0: f32 = 0.282_094_8;
/// Rounding of f32 arithmetic on values of order 1..10.
const F32_SLACK: f32 = 1e-5;

/// `scene` written in `format` and read back, and the format the reader saw.
fn round_trip(scene: &Scene, format: OutputFormat) -> (Scene, SceneFormat) {
    let bytes = write::to_bytes(scene, format).unwrap();
    io::scene::parse_bytes(&bytes, std::path::Path::new("written")).unwrap()
}

/// The source scene in the writers' order (Morton), to compare with the decoded one.
fn in_written_order(s: &Scene) -> Scene {
    s.select(&quantize::morton_order(&s.positions), s.sh_degree)
}

/// The largest difference between two quaternions, normalised, up to sign.
fn rotation_error(a: [f32; 4], b: [f32; 4]) -> f32 {
    let (a, b) = (scene::normalize_quat(a), scene::normalize_quat(b));
    let diff = |s: f32| (0..4).map(|k| (a[k] - s * b[k]).abs()).fold(0f32, f32::max);
    diff(1.0).min(diff(-1.0))
}

/// The extent of each of the three values `f(i)` over each 256-Gaussian chunk, per
/// Gaussian (the compressed PLY's chunk bounds are its members' extremes).
fn chunk_extents(n: usize, f: impl Fn(usize) -> [f32; 3]) -> Vec<[f32; 3]> {
    let mut out = Vec::with_capacity(n);
    for start in (0..n).step_by(256) {
        let end = (start + 256).min(n);
        let ext: [f32; 3] = std::array::from_fn(|a| {
            let v = (start..end).map(|i| f(i)[a]);
            v.clone().fold(f32::NEG_INFINITY, f32::max) - v.fold(f32::INFINITY, f32::min)
        });
        out.extend(std::iter::repeat(ext).take(end - start));
    }
    out
}

/// Opacity error bound of both formats: half an 8-bit step, a whole one where the byte was
/// kept within 1..=254.
fn opacity_bound(p: f32) -> f32 {
    if (1.5 / 255.0..=253.5 / 255.0).contains(&p) {
        0.5 / 255.0 + 1e-6
    } else {
        1.0 / 255.0 + 1e-6
    }
}

/// The compressed PLY decodes every Gaussian within half a quantisation step: positions
/// and log scales 11-10-11 bits over the chunk's box, DC colours a byte over the chunk's
/// colour range, SH a byte of 1/32 over [-4, 4] (half a step, 1/64, inside; a whole step
/// in the end bytes, which decode to -4 and 4), quaternion components 10 bits over
/// [-sqrt(1/2), sqrt(1/2)] (half step 6.9e-4; the rebuilt largest about threefold).
#[allow(clippy::needless_range_loop)] // a, the axis, indexes five arrays alike
fn check_compressed_ply(name: &str, src: &Scene, got: &Scene) {
    let n = src.len();
    let stride = src.sh_stride();
    let half = |ext: [f32; 3], a: usize| ext[a] / if a == 1 { 2046.0 } else { 4094.0 };
    let pos_ext = chunk_extents(n, |i| src.positions[i]);
    let scale_ext = chunk_extents(n, |i| src.log_scales[i]);
    let colour_ext = chunk_extents(n, |i| {
        std::array::from_fn(|c| 0.5 + SH_C0 * src.sh[i * stride + c])
    });
    let mut worst = [0f32; 6];
    for i in 0..n {
        for a in 0..3 {
            let e = (src.positions[i][a] - got.positions[i][a]).abs();
            let b = half(pos_ext[i], a) + 1e-6;
            assert!(e <= b, "{name} Gaussian {i} position {a}: {e} > {b}");
            worst[0] = worst[0].max(e / b);
            let e = (src.log_scales[i][a] - got.log_scales[i][a]).abs();
            let b = half(scale_ext[i], a) + F32_SLACK;
            assert!(e <= b, "{name} Gaussian {i} log scale {a}: {e} > {b}");
            worst[1] = worst[1].max(e / b);
            let e = (src.sh[i * stride + a] - got.sh[i * stride + a]).abs();
            let b = colour_ext[i][a] / 510.0 / SH_C0 + F32_SLACK;
            assert!(e <= b, "{name} Gaussian {i} f_dc_{a}: {e} > {b}");
            worst[2] = worst[2].max(e / b);
        }
        let e = rotation_error(src.rotations[i], got.rotations[i]);
        assert!(e <= 3e-3, "{name} Gaussian {i} rotation: {e}");
        worst[3] = worst[3].max(e / 3e-3);
        let p = sigmoid(src.opacity_logits[i]);
        let e = (p - sigmoid(got.opacity_logits[i])).abs();
        assert!(e <= opacity_bound(p), "{name} Gaussian {i} opacity: {e}");
        worst[4] = worst[4].max(e / opacity_bound(p));
        for j in 3..stride {
            let v = src.sh[i * stride + j];
            let e = (v.clamp(-4.0, 4.0) - got.sh[i * stride + j]).abs();
            let b = if v.abs() < 3.95 {
                1.0 / 64.0
            } else {
                1.0 / 32.0
            } + F32_SLACK;
            assert!(e <= b, "{name} Gaussian {i} SH {j}: {v} -> {e} > {b}");
            worst[5] = worst[5].max(e / b);
        }
    }
    println!("{name} compressed PLY: worst error / bound (position, log scale, dc, rotation, opacity, sh) {worst:.3?}");
}

/// The value of `book` (ascending) nearest `v`.
fn nearest(book: &[f32], v: f32) -> f32 {
    book.iter()
        .copied()
        .min_by(|a, b| (a - v).abs().total_cmp(&(b - v).abs()))
        .unwrap()
}

/// The distinct values of `v`, ascending.
fn distinct(v: impl Iterator<Item = f32>) -> Vec<f32> {
    let mut d: Vec<f32> = v.collect();
    d.sort_by(f32::total_cmp);
    d.dedup();
    d
}

/// The SOG decodes positions within half a 16-bit step of their log transform (times
/// `|p| + 1` back in linear units), log scales and DC terms to the codebook entry nearest
/// the source's (the entries decoded are the codebook's, so a nearer unused entry would
/// show), quaternion components within half a byte step over [-sqrt(1/2), sqrt(1/2)]
/// (2.8e-3; the rebuilt largest about threefold). Returns the RMS error of the higher SH
/// bands (the palette's).
#[allow(clippy::needless_range_loop)] // a, the axis, indexes several arrays alike
fn check_sog(name: &str, src: &Scene, got: &Scene) -> f64 {
    let n = src.len();
    let stride = src.sh_stride();
    let log = |v: f32| v.signum() * v.abs().ln_1p();
    let range: [f32; 3] = std::array::from_fn(|a| {
        let v = src.positions.iter().map(|p| log(p[a]));
        v.clone().fold(f32::NEG_INFINITY, f32::max) - v.fold(f32::INFINITY, f32::min)
    });
    let scale_book = distinct(got.log_scales.iter().flatten().copied());
    let dc_book = distinct((0..n).flat_map(|i| got.sh[i * stride..i * stride + 3].to_vec()));
    assert!(scale_book.len() <= 256 && dc_book.len() <= 256, "{name}");
    for i in 0..n {
        for a in 0..3 {
            let p = src.positions[i][a];
            let e = (p - got.positions[i][a]).abs();
            let b = (p.abs() + 1.0) * range[a] / 131_070.0 * 1.001 + 1e-6;
            assert!(e <= b, "{name} Gaussian {i} position {a}: {e} > {b}");
            // Nearest up to a tie (a value halfway between two entries).
            let v = src.log_scales[i][a];
            let (e, best) = (
                (got.log_scales[i][a] - v).abs(),
                (nearest(&scale_book, v) - v).abs(),
            );
            assert!(
                e <= best + 1e-6,
                "{name} Gaussian {i} log scale {a} ({v}): {e} > {best}"
            );
            let v = src.sh[i * stride + a];
            let (e, best) = (
                (got.sh[i * stride + a] - v).abs(),
                (nearest(&dc_book, v) - v).abs(),
            );
            assert!(
                e <= best + 1e-6,
                "{name} Gaussian {i} f_dc_{a} ({v}): {e} > {best}"
            );
        }
        let e = rotation_error(src.rotations[i], got.rotations[i]);
        assert!(e <= 1e-2, "{name} Gaussian {i} rotation: {e}");
        let p = sigmoid(src.opacity_logits[i]);
        let e = (p - sigmoid(got.opacity_logits[i])).abs();
        assert!(e <= opacity_bound(p), "{name} Gaussian {i} opacity: {e}");
    }
    let (mut sq, mut count) = (0f64, 0usize);
    for i in 0..n {
        for j in 3..stride {
            sq += f64::from(src.sh[i * stride + j] - got.sh[i * stride + j]).powi(2);
            count += 1;
        }
    }
    (sq / count.max(1) as f64).sqrt()
}

/// The shared scenes of SH degree 0 to 3 and a camera that frames each.
fn scenes() -> Vec<(&'static str, Scene, Camera)> {
    let playbot = common::orbit(common::PLAYBOT_ORBIT, 0, 320, 180);
    let plant = common::orbit("plant_orbit_cameras.synthetic.json", 0, 320, 180);
    let train = common::shared_scene("train3_sh3.ply");
    let train_cam = camera::default_camera(&train.positions, 320, 180);
    vec![
        (
            "playbot_lod3_31k_sh2",
            common::shared_scene("playbot_lod3_31k_sh2.ply"),
            playbot,
        ),
        ("train3_sh3", train, train_cam),
        (
            "plant_113k_sh0",
            common::shared_scene("plant_113k_sh0.ply"),
            plant,
        ),
    ]
}

/// PSNR of CPU reference renders of `b` against `a`.
fn render_psnr(a: &Scene, b: &Scene, cam: &Camera) -> f64 {
    let opts = RenderOptions::default();
    let fa = cpu::render(&a.activated(), cam, &opts);
    let fb = cpu::render(&b.activated(), cam, &opts);
    common::gpu::compare(&fb, &fa).psnr
}

#[test]
fn writers_round_trip_the_shared_scenes_within_their_quantisation() {
    // PSNR of 320x180 CPU renders of the read-back scene against the source, measured
    // (printed): compressed PLY playbot 57.96 dB, train3 93.09 dB, plant 73.25 dB; SOG
    // playbot 90.65 dB (its PLY was decoded from a SOG, so its codebooks and palette come
    // back almost exactly), train3 85.61 dB, plant 76.28 dB. Each threshold is 3 dB under
    // the measurement.
    let thresholds = [
        ("playbot_lod3_31k_sh2", 54.9, 87.6),
        ("train3_sh3", 90.0, 82.6),
        ("plant_113k_sh0", 70.2, 73.2),
    ];
    for ((name, src, cam), (tname, cply_min, sog_min)) in scenes().into_iter().zip(thresholds) {
        assert_eq!(name, tname);
        let ordered = in_written_order(&src);
        let (c, format) = round_trip(&src, OutputFormat::CompressedPly);
        assert_eq!(format, SceneFormat::CompressedPly);
        assert_eq!((c.len(), c.sh_degree), (src.len(), src.sh_degree), "{name}");
        check_compressed_ply(name, &ordered, &c);
        let (s, format) = round_trip(&src, OutputFormat::Sog);
        assert_eq!(
            format,
            SceneFormat::Sog {
                version: 2,
                bundled: true
            }
        );
        assert_eq!((s.len(), s.sh_degree), (src.len(), src.sh_degree), "{name}");
        let sh_rms = check_sog(name, &ordered, &s);
        let psnr_c = render_psnr(&src, &c, &cam);
        let psnr_s = render_psnr(&src, &s, &cam);
        println!(
            "{name}: compressed PLY {psnr_c:.2} dB (threshold {cply_min}), SOG {psnr_s:.2} dB (threshold {sog_min}), SOG SH rest RMS error {sh_rms:.5}"
        );
        assert!(psnr_c >= cply_min, "{name} compressed PLY: {psnr_c:.2} dB");
        assert!(psnr_s >= sog_min, "{name} SOG: {psnr_s:.2} dB");
    }
}

#[test]
fn writers_give_the_same_bytes_and_keep_the_flags() {
    let mut s = common::shared_scene("playbot_lod6_1873_sh2.ply");
    for format in [OutputFormat::CompressedPly, OutputFormat::Sog] {
        let a = write::to_bytes(&s, format).unwrap();
        let b = write::to_bytes(&s.clone(), format).unwrap();
        assert!(a == b, "{format}: two writes differ");
    }
    // Antialiasing survives both; the kernel and rules only the compressed PLY (header
    // comments), and convert says so for SOG.
    s.antialiased = true;
    s.kernel = SplatKernel::Power;
    s.rules = Rules::Gsplat;
    let (c, _) = round_trip(&s, OutputFormat::CompressedPly);
    assert!(c.antialiased);
    assert_eq!((c.kernel, c.rules), (SplatKernel::Power, Rules::Gsplat));
    let (g, _) = round_trip(&s, OutputFormat::Sog);
    assert!(g.antialiased);
    assert!(OutputFormat::Sog.records_antialiasing());
    assert!(!OutputFormat::Sog.records_kernel_and_rules());
    assert!(OutputFormat::CompressedPly.records_kernel_and_rules());
}

#[test]
fn convert_writes_sog_bundles_and_directories_without_overwriting() {
    let dir = tempfile::tempdir().unwrap();
    let src = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let source = io::scene::load(&src).unwrap();
    let opts = ConvertOptions::default();
    for (out, format) in [
        (
            dir.path().join("a.compressed.ply"),
            OutputFormat::CompressedPly,
        ),
        (dir.path().join("a.sog"), OutputFormat::Sog),
        (dir.path().join("sog_dir/meta.json"), OutputFormat::Sog),
    ] {
        assert_eq!(OutputFormat::from_path(&out).unwrap(), format);
        let r = write::convert(&src, &out, &opts).unwrap();
        assert_eq!((r.written, r.sh_degree, r.output_format), (1873, 2, format));
        assert!(!r.antialiased_flag_lost);
        // Read back through the loader, directory or file.
        let back = io::scene::load(&out).unwrap();
        assert_eq!(back.len(), source.len());
        // An existing output is refused and left as it was, then replaced on request.
        let before = std::fs::read(&out).unwrap();
        let e = write::convert(&src, &out, &opts).unwrap_err();
        assert!(e.to_string().contains("already exists"), "{e}");
        assert_eq!(std::fs::read(&out).unwrap(), before);
        let again = ConvertOptions {
            overwrite: true,
            ..Default::default()
        };
        write::convert(&src, &out, &again).unwrap();
        assert_eq!(
            std::fs::read(&out).unwrap(),
            before,
            "{format}: not deterministic"
        );
    }
    // The directory's textures are outputs too: one left there is not overwritten.
    let other = dir.path().join("other/meta.json");
    std::fs::create_dir_all(other.parent().unwrap()).unwrap();
    std::fs::write(dir.path().join("other/quats.webp"), b"keep").unwrap();
    let e = write::convert(&src, &other, &opts).unwrap_err();
    assert!(
        matches!(e, ConvertError::Write(_)) && e.to_string().contains("quats.webp"),
        "{e}"
    );
    assert!(!other.exists());
    assert_eq!(
        std::fs::read(dir.path().join("other/quats.webp")).unwrap(),
        b"keep"
    );
}

#[test]
fn writers_refuse_empty_and_time_varying_scenes_clearly() {
    let empty = Scene::empty(2);
    for format in [OutputFormat::CompressedPly, OutputFormat::Sog] {
        let e = write::to_bytes(&empty, format).unwrap_err();
        assert!(e.contains("holds no Gaussians"), "{format}: {e}");
    }
    let mut timed = common::shared_scene("train3_sh3.ply");
    timed.time = Some(vec![[0.0, 0.0]; timed.len()]);
    for format in [OutputFormat::CompressedPly, OutputFormat::Sog] {
        let e = write::to_bytes(&timed, format).unwrap_err();
        assert!(e.contains("time-varying"), "{format}: {e}");
    }
    // Through convert: the filters removing everything is named, and no file is left.
    let dir = tempfile::tempdir().unwrap();
    let src = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let out = dir.path().join("none.sog");
    let opts = ConvertOptions {
        filter: scene::filter::SceneFilter {
            min_opacity: Some(1.0),
            ..Default::default()
        },
        ..Default::default()
    };
    let e = write::convert(&src, &out, &opts).unwrap_err().to_string();
    assert!(
        e.contains("none.sog") && e.contains("the filters removed all 1873 Gaussians"),
        "{e}"
    );
    assert!(!out.exists());
    // A scene with a NaN is named, not written as garbage.
    let mut bad = common::shared_scene("train3_sh3.ply");
    bad.positions[1][0] = f32::NAN;
    for format in [OutputFormat::CompressedPly, OutputFormat::Sog] {
        let e = write::to_bytes(&bad, format).unwrap_err();
        assert!(
            e.contains("Gaussian 1 has a non-finite value"),
            "{format}: {e}"
        );
    }
}
