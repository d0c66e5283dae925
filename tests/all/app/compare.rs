//! `verisplat compare` and `verisplat eval` through the binary: GPU vs CPU reference on every
//! real scene, a perturbed blend failing, image comparisons, evaluation against photos
//! made here (CPU reference renders with seeded noise), and trained model directories.

use crate::common;
use crate::common::cli::{s, stderr, stdout, verisplat, verisplat_env};
use crate::common::gpu::{MIN_PSNR, MIN_WITHIN};

use serde_json::Value;
use std::path::{Path, PathBuf};

use verisplat::core::camera::Camera;
use verisplat::io::metrics;

/// Runs a command that must succeed and returns its stdout.
fn succeeds(args: &[&str]) -> String {
    let o = verisplat(args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    stdout(&o)
}

/// Runs a command that must fail: returns its one-line error, checking there was no panic
/// and no output file.
fn fails(args: &[&str], out: &Path) -> String {
    let o = verisplat(args);
    let e = stderr(&o);
    assert!(!o.status.success(), "{args:?} must fail");
    assert!(!e.contains("panicked"), "{args:?} panicked: {e}");
    let last = e.trim_end().lines().last().unwrap_or("");
    assert!(last.starts_with("error: "), "{args:?}: {e}");
    assert!(!out.exists(), "{args:?} left an output file");
    last.to_string()
}

fn read_json(p: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
}

/// The real scenes of `tests/all/io/real_scenes.rs` with their camera file (or the default
/// camera).
const REAL_SCENES: [(&str, Option<&str>); 6] = [
    (
        "playbot_lod6_1873_sh2.ply",
        Some("playbot_orbit_cameras.synthetic.json"),
    ),
    (
        "playbot_lod3_31k_sh2.ply",
        Some("playbot_orbit_cameras.synthetic.json"),
    ),
    (
        "playbot_lod2_125k_sh2.ply",
        Some("playbot_orbit_cameras.synthetic.json"),
    ),
    (
        "playbot_lod1_250k_sh1.ply",
        Some("playbot_orbit_cameras.synthetic.json"),
    ),
    (
        "plant_113k_sh0.ply",
        Some("plant_orbit_cameras.synthetic.json"),
    ),
    ("train3_sh3.ply", None),
];

#[test]
fn compare_passes_on_every_real_scene_with_the_defaults() {
    let dir = tempfile::tempdir().unwrap();
    for (k, (scene, cams)) in REAL_SCENES.iter().enumerate() {
        let scene_path = common::shared_data().join(scene);
        let report = dir.path().join(format!("r{k}"));
        let cams_path = cams.map(|c| common::shared_data().join(c));
        // Two cameras of the first scene, one of the others, at 320x180: lavapipe and the
        // CPU reference are slow, and the full-resolution agreement is
        // tests/all/render/frames.rs'.
        let mut args = vec![
            "compare",
            s(&scene_path),
            "--width",
            "320",
            "-o",
            s(&report),
        ];
        if let Some(c) = &cams_path {
            args.extend([
                "--cameras",
                s(c),
                "--camera",
                if k == 0 { "3,17" } else { "3" },
            ]);
        }
        let out = succeeds(&args);
        assert!(out.contains("all pass"), "{scene}: {out}");
        let json = read_json(&report.join("report.json"));
        assert_eq!(json["pass"], true, "{scene}");
        let frames = json["frames"].as_array().unwrap();
        assert_eq!(frames.len(), if k == 0 { 2 } else { 1 }, "{scene}");
        for f in frames {
            // null is an infinite PSNR (identical planes).
            for plane in ["color", "alpha"] {
                let psnr = f[plane]["psnr"].as_f64().unwrap_or(f64::INFINITY);
                assert!(psnr >= MIN_PSNR, "{scene} {plane}: {f}");
                assert!(
                    f[plane]["within"].as_f64().unwrap() >= MIN_WITHIN,
                    "{scene}: {f}"
                );
            }
            // FLIP is reported (not gated): near 0 for frames this close.
            let flip = f["flip"].as_f64().unwrap();
            assert!((0.0..0.01).contains(&flip), "{scene}: FLIP {flip}");
            let diff = report.join(f["diff"].as_str().unwrap());
            let img = image::open(&diff).unwrap();
            // The heat map plus its colour bar.
            assert_eq!(
                (img.width(), img.height()),
                (320, 180 + verisplat::io::diff_image::BAR_HEIGHT),
                "{scene}"
            );
        }
        let csv = std::fs::read_to_string(report.join("report.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + frames.len(), "{csv}");
    }
}

#[test]
fn a_perturbed_blend_fails_with_exit_1_naming_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("rep");
    let scene = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let cams = common::shared_data().join("playbot_orbit_cameras.synthetic.json");
    let args = [
        "compare",
        s(&scene),
        "--cameras",
        s(&cams),
        "--camera",
        "3,7",
        "--width",
        "160",
        "-o",
        s(&report),
    ];
    // 0.01 on red alone: MSE 1e-4 / 3 over the colour samples, PSNR 44.8 dB < 55.
    let o = verisplat_env(&args, &[(verisplat_perturb_env(), "0.01")]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(!e.contains("panicked"), "{e}");
    assert!(
        e.contains("2 of 2 frame(s) fail")
            && e.contains("frame 3 (\"playbot_orbit_003\"")
            && e.contains("frame 7 (\"playbot_orbit_007\"")
            && e.contains("colour PSNR"),
        "{e}"
    );
    assert!(stdout(&o).contains("FAIL"));
    // The reports are still written, saying which frames failed.
    let json = read_json(&report.join("report.json"));
    assert_eq!(json["pass"], false);
    assert_eq!(json["failed_frames"], serde_json::json!([3, 7]));
    // The perturbation shows in FLIP too (reported, not gated).
    assert!(json["frames"][0]["flip"].as_f64().unwrap() > 0.0);
    let psnr = json["frames"][0]["color"]["psnr"].as_f64().unwrap();
    let want = 10.0 * (3.0f64 / 1e-4).log10();
    // Pixels whose red is already clamped at 1 cannot move, so the PSNR is a little above
    // the closed form; it is far below the threshold either way.
    assert!(psnr >= want - 0.01 && psnr < 50.0, "{psnr} vs {want}");
    // The same frames without the perturbation pass, with another blend kernel too.
    let mut again = args.to_vec();
    again.extend(["--overwrite", "--blend-kernel", "shared"]);
    let out = succeeds(&again);
    assert!(
        out.contains("blend kernel shared") && out.contains("all pass"),
        "{out}"
    );
    assert_eq!(
        read_json(&report.join("report.json"))["blend_kernel"],
        "shared"
    );
}

fn verisplat_perturb_env() -> &'static str {
    "VERISPLAT_TEST_PERTURB_RED"
}

/// Renders the demo scene on the CPU at 64x36 into `path` (PNG or EXR).
fn demo_render(path: &Path, extra: &[&str]) {
    let mut args = vec![
        "render",
        "--demo",
        "--cpu",
        "--width",
        "64",
        "-o",
        s(path),
        "-q",
    ];
    args.extend(extra);
    succeeds(&args);
}

/// `--reproducible`: every value of every frame is the CPU reference's (0 differing in
/// report.json and the closing line); without it lavapipe's exp makes some differ.
#[test]
fn compare_reproducible_reports_every_value_the_references_bits() {
    let dir = tempfile::tempdir().unwrap();
    for (flag, exact) in [(Some("--reproducible"), true), (None, false)] {
        let report = dir.path().join(format!("r{exact}"));
        let mut args = vec![
            "compare",
            "--demo",
            "--orbit",
            "2",
            "--width",
            "320",
            "-o",
            s(&report),
        ];
        args.extend(flag);
        let out = succeeds(&args);
        let json = read_json(&report.join("report.json"));
        let differing: u64 = json["frames"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|f| f["differing_values"].as_array().unwrap().clone())
            .map(|v| v.as_u64().unwrap())
            .sum();
        if exact {
            assert_eq!(differing, 0, "{out}");
            assert!(out.contains("every value the reference's bits"), "{out}");
        } else {
            assert!(differing > 0, "{out}");
            let said = format!("{differing} of 576000 values differ from the reference's bits");
            assert!(out.contains(&said), "{out}");
        }
    }
}

#[test]
fn two_images_compare_by_channel_with_clear_errors_for_mismatches() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.exr");
    demo_render(&a, &[]);
    let pa = verisplat::io::image_file::read_image(&a).unwrap();
    assert_eq!(pa.names(), ["R", "G", "B", "A", "Z"]);
    // Identical images: infinite PSNR, written as null in the JSON and "inf" in the table.
    let rep = dir.path().join("rep");
    let out = succeeds(&["compare", s(&a), s(&a), "-o", s(&rep)]);
    assert!(out.contains("inf") && out.contains("pass"), "{out}");
    let json = read_json(&rep.join("report.json"));
    assert!(json["groups"][0]["psnr"].is_null(), "{json}");
    assert_eq!(json["groups"][0]["ssim"], 1.0);
    assert_eq!(json["groups"][0]["flip"], 0.0);

    // A NumPy dump of the same image with seeded noise on the colour.
    let mut rng = common::Rng(7);
    let names = ["R", "G", "B", "A", "Z"];
    let mut samples = pa.interleave(&names).unwrap();
    for px in samples.chunks_mut(5) {
        for v in &mut px[..3] {
            *v += 0.02 * rng.normal();
        }
    }
    let b = dir.path().join("b.npy");
    let (w, h) = (pa.width as usize, pa.height as usize);
    std::fs::write(
        &b,
        verisplat::io::image_file::npy_bytes(&[h, w, 5], &samples),
    )
    .unwrap();
    let diff = dir.path().join("diff.png");
    let o = verisplat(&[
        "compare",
        s(&a),
        s(&b),
        "--diff",
        s(&diff),
        "-o",
        s(&rep),
        "--overwrite",
    ]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "noise must fail the gate: {}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("colour PSNR"), "{}", stderr(&o));
    let json = read_json(&rep.join("report.json"));
    let clamp = |v: Vec<f32>| v.into_iter().map(|x| x.clamp(0.0, 1.0)).collect::<Vec<_>>();
    let (ra, rb) = (
        clamp(pa.interleave(&["R", "G", "B"]).unwrap()),
        clamp(samples.chunks(5).flat_map(|p| p[..3].to_vec()).collect()),
    );
    let own = metrics::psnr(&ra, &rb, 1.0);
    let got = json["groups"][0]["psnr"].as_f64().unwrap();
    assert!((got - own).abs() < 0.01, "{got} vs {own}");
    assert_eq!(json["groups"][1]["group"], "alpha");
    assert!(json["groups"][1]["psnr"].is_null(), "alpha is unchanged");
    assert_eq!(json["groups"][2]["group"], "depth");
    let img = image::open(&diff).unwrap();
    assert_eq!(
        (img.width(), img.height()),
        (64, 36 + verisplat::io::diff_image::BAR_HEIGHT)
    );

    // Channel and size mismatches.
    let rgb = dir.path().join("rgb.npy");
    let rgb_samples: Vec<f32> = samples.chunks(5).flat_map(|p| p[..3].to_vec()).collect();
    std::fs::write(
        &rgb,
        verisplat::io::image_file::npy_bytes(&[h, w, 3], &rgb_samples),
    )
    .unwrap();
    let e = fails(&["compare", s(&a), s(&rgb)], Path::new("/nonexistent"));
    assert!(
        e.contains("different channels") && e.contains("R, G, B, A, Z") && e.contains("--channels"),
        "{e}"
    );
    let o = verisplat(&[
        "compare",
        s(&a),
        s(&rgb),
        "--channels",
        "R,G,B",
        "--min-psnr",
        "20",
        "--min-within",
        "0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let small = dir.path().join("small.png");
    succeeds(&[
        "render",
        "--demo",
        "--cpu",
        "--width",
        "32",
        "-o",
        s(&small),
        "-q",
    ]);
    let e = fails(&["compare", s(&a), s(&small)], Path::new("/nonexistent"));
    assert!(e.contains("64x36") && e.contains("32x18"), "{e}");
    let e = fails(
        &["compare", s(&a), "/nonexistent/b.png"],
        Path::new("/nonexistent"),
    );
    assert!(e.contains("/nonexistent/b.png"), "{e}");
}

#[test]
fn png_8_and_16_bit_agree_within_one_8bit_step() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    demo_render(&a, &[]);
    demo_render(&b, &["--png16"]);
    let out = succeeds(&["compare", s(&a), s(&b), "--min-psnr", "40"]);
    // 8-bit rounding is at most half a step from the 16-bit value.
    assert!(out.contains("100.000"), "{out}");
}

/// A trained-model directory made here: the PLAYBOT LOD6 scene as iteration 30000, the
/// 3-Gaussian train3 scene as iteration 7000, and a cameras.json of `n` orbit cameras
/// named view_000, view_001, ... at 96x54.
fn model_dir(root: &Path, n: usize) -> (PathBuf, Vec<Camera>) {
    let model = root.join("model");
    for (it, file) in [
        (30000, "playbot_lod6_1873_sh2.ply"),
        (7000, "train3_sh3.ply"),
    ] {
        let d = model.join(format!("point_cloud/iteration_{it}"));
        std::fs::create_dir_all(&d).unwrap();
        std::fs::copy(common::shared_data().join(file), d.join("point_cloud.ply")).unwrap();
    }
    let text =
        std::fs::read_to_string(common::shared_data().join("playbot_orbit_cameras.synthetic.json"))
            .unwrap();
    let mut entries: Vec<Value> = serde_json::from_str(&text).unwrap();
    entries.truncate(n);
    for (i, e) in entries.iter_mut().enumerate() {
        // 1280x720 to 96x54: focal lengths scale by 0.075.
        e["img_name"] = format!("view_{i:03}").into();
        e["width"] = 96.into();
        e["height"] = 54.into();
        e["fx"] = (e["fx"].as_f64().unwrap() * 0.075).into();
        e["fy"] = (e["fy"].as_f64().unwrap() * 0.075).into();
    }
    let path = model.join("cameras.json");
    std::fs::write(&path, serde_json::to_string(&entries).unwrap()).unwrap();
    let cams = verisplat::io::camera::load_cameras_json(&path).unwrap();
    (model, cams)
}

/// The CPU reference render of `cam` (at `w x h`) with seeded Gaussian noise, quantised to
/// 8 bits: the "photo" of that camera, as `H x W x 3` values in [0, 1].
fn noisy_photo(cam: &Camera, w: u32, h: u32, seed: u64) -> Vec<f32> {
    let scene =
        verisplat::io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply"))
            .unwrap()
            .activated();
    let cam = cam.with_resolution(w, h).unwrap();
    let frame = verisplat::cpu::render(&scene, &cam, &Default::default());
    let mut rng = common::Rng(seed);
    metrics::clamped_color(&frame)
        .into_iter()
        .map(|v| verisplat::io::output::to_u8(v + 0.03 * rng.normal()) as f32 / 255.0)
        .collect()
}

/// Writes, for each of `cams` (96x54), the CPU reference's render of the model's scene
/// (its clamped colour, changed by `photo(camera, colour)`) as the camera's photo in
/// `DIR/images`, and runs `eval --cpu` of `model` on them: its output and report.
fn eval_rendered_photos(
    dir: &Path,
    model: &Path,
    cams: &[Camera],
    photo: impl Fn(&Camera, Vec<f32>) -> Vec<f32>,
) -> (std::process::Output, Value) {
    let scene =
        verisplat::io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply"))
            .unwrap()
            .activated();
    let images = dir.join("images");
    std::fs::create_dir_all(&images).unwrap();
    for cam in cams {
        let frame = verisplat::cpu::render(&scene, cam, &Default::default());
        let rgb = photo(cam, metrics::clamped_color(&frame));
        write_png(&images.join(format!("{}.png", cam.name)), 96, 54, &rgb);
    }
    let rep = dir.join("rep");
    let o = verisplat(&[
        "eval",
        s(model),
        "--images",
        s(&images),
        "-o",
        s(&rep),
        "--cpu",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json = read_json(&rep.join("report.json"));
    (o, json)
}

/// A photo of the model taken at another exposure and white balance scores low in plain
/// PSNR and high in the colour-corrected PSNR beside it (gsplat's `cc_psnr`), which `eval`
/// labels and writes to both reports.
#[test]
fn eval_reports_the_colour_corrected_psnr_beside_the_plain_one() {
    let dir = tempfile::tempdir().unwrap();
    let (model, cams) = model_dir(dir.path(), 9);
    let (o, json) = eval_rendered_photos(dir.path(), &model, &cams, |_, rgb| {
        rgb.into_iter()
            .enumerate()
            .map(|(i, v)| [0.7 * v + 0.2, 0.9 * v + 0.05, 0.6 * v + 0.1][i % 3])
            .collect()
    });
    assert!(stdout(&o).contains("PSNR cc"), "{}", stdout(&o));
    let r = &json["results"][0];
    let (psnr, cc) = (r["psnr"].as_f64().unwrap(), r["psnr_cc"].as_f64().unwrap());
    assert!(psnr < 25.0 && cc > 40.0, "{r}");
    assert!(json["mean"]["psnr_cc"].as_f64().unwrap() > 40.0, "{json}");
    let csv = std::fs::read_to_string(dir.path().join("rep/report.csv")).unwrap();
    assert!(
        csv.starts_with("frame,camera,photo,width,height,psnr,ssim,flip,psnr_cc\n"),
        "{csv}"
    );
}

/// A fisheye camera's photo is scored inside its image circle only, as it is trained: a
/// border of any colour past the lens's field of view changes nothing, and eval says so.
#[test]
fn eval_scores_a_fisheye_photo_inside_its_image_circle() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = model_dir(dir.path(), 9);
    // Through an equidistant fisheye of 2 x 0.5 rad: at fx about 80 its circle is about
    // 40 pixels in radius, so the 96x54 image's left, right and corners are outside.
    let path = model.join("cameras.json");
    let mut entries: Vec<Value> =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    for e in &mut entries {
        e["lens"] = serde_json::json!({"kind": "fisheye", "k": [0, 0, 0, 0], "max_theta": 0.5});
    }
    std::fs::write(&path, serde_json::to_string(&entries).unwrap()).unwrap();
    let cams = verisplat::io::camera::load_cameras_json(&path).unwrap();
    let (o, json) = eval_rendered_photos(dir.path(), &model, &cams, |cam, rgb| {
        let circle = verisplat::train::masks::image_circle(cam).expect("pixels past the circle");
        rgb.into_iter()
            .enumerate()
            .map(|(i, v)| if circle[i / 3] { v } else { 1.0 })
            .collect()
    });
    assert!(
        stdout(&o).contains("scored only the pixels inside the image circle of 2 fisheye photo(s)"),
        "{}",
        stdout(&o)
    );
    for r in json["results"].as_array().unwrap() {
        assert_eq!(r["image_circle"], true, "{r}");
        // The white border is not scored: the render and the photo are the same pixels.
        assert!(
            r["psnr"].is_null() || r["psnr"].as_f64().unwrap() > 60.0,
            "{r}"
        );
    }
}

fn write_png(path: &Path, w: u32, h: u32, rgb: &[f32]) {
    let bytes: Vec<u8> = rgb.iter().map(|&v| (v * 255.0).round() as u8).collect();
    image::RgbImage::from_raw(w, h, bytes)
        .unwrap()
        .save(path)
        .unwrap();
}

/// What eval computes for a photo, done here with the metrics module: the CPU reference
/// render quantised to 8 bits against the photo.
fn own_psnr(cam: &Camera, w: u32, h: u32, photo: &[f32]) -> f64 {
    let scene =
        verisplat::io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply"))
            .unwrap()
            .activated();
    let frame = verisplat::cpu::render(
        &scene,
        &cam.with_resolution(w, h).unwrap(),
        &Default::default(),
    );
    let render: Vec<f32> = metrics::clamped_color(&frame)
        .into_iter()
        .map(|v| verisplat::io::output::to_u8(v) as f32 / 255.0)
        .collect();
    metrics::psnr(photo, &render, 1.0)
}

#[test]
fn eval_reports_per_image_psnr_of_the_test_split() {
    let dir = tempfile::tempdir().unwrap();
    let (model, cams) = model_dir(dir.path(), 17);
    let images = dir.path().join("images");
    std::fs::create_dir_all(&images).unwrap();
    let mut own = Vec::new();
    for (i, cam) in cams.iter().enumerate() {
        let photo = noisy_photo(cam, 96, 54, i as u64 + 1);
        write_png(&images.join(format!("{}.png", cam.name)), 96, 54, &photo);
        own.push(own_psnr(cam, 96, 54, &photo));
    }
    let rep = dir.path().join("rep");
    let o = verisplat(&["eval", s(&model), "--images", s(&images), "-o", s(&rep)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("note: using the model's cameras"),
        "{}",
        stderr(&o)
    );
    let json = read_json(&rep.join("report.json"));
    let results = json["results"].as_array().unwrap();
    let frames: Vec<u64> = results
        .iter()
        .map(|r| r["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(frames, [0, 8, 16], "--split test is the llffhold rule");
    for r in results {
        let k = r["frame"].as_u64().unwrap() as usize;
        let psnr = r["psnr"].as_f64().unwrap();
        // The GPU render may round a handful of 8-bit values differently from the CPU
        // reference (they agree to ~100 dB); against noise at ~30 dB that moves the PSNR by
        // far less than the 0.01 dB the test allows.
        assert!(
            (psnr - own[k]).abs() < 0.01,
            "frame {k}: {psnr} vs {}",
            own[k]
        );
        assert!((20.0..45.0).contains(&psnr), "{psnr}");
        let (ssim, flip) = (r["ssim"].as_f64().unwrap(), r["flip"].as_f64().unwrap());
        assert!(ssim > 0.0 && ssim < 1.0 && flip > 0.0 && flip < 1.0, "{r}");
        // The colour fit can keep the render as it is, so it never scores lower; here it
        // gains what the noise's clipping at black biased (about 1 dB).
        let cc = r["psnr_cc"].as_f64().unwrap();
        assert!(cc >= psnr - 1e-6 && cc < psnr + 3.0, "{r}");
    }
    let mean = json["mean"]["psnr"].as_f64().unwrap();
    let want = (own[0] + own[8] + own[16]) / 3.0;
    assert!((mean - want).abs() < 0.01, "{mean} vs {want}");
    let csv = std::fs::read_to_string(rep.join("report.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 + 1, "{csv}");
    assert!(csv.lines().last().unwrap().starts_with("mean,"), "{csv}");

    // The train split is the other 14 cameras; --cpu renders with the reference, so the
    // PSNR is exactly the test's own.
    let o = verisplat(&[
        "eval",
        s(&model),
        "--images",
        s(&images),
        "-o",
        s(&rep),
        "--overwrite",
        "--split",
        "train",
        "--cpu",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json = read_json(&rep.join("report.json"));
    let results = json["results"].as_array().unwrap();
    assert_eq!(results.len(), 14);
    for r in results {
        let k = r["frame"].as_u64().unwrap() as usize;
        assert!(k % 8 != 0);
        assert!((r["psnr"].as_f64().unwrap() - own[k]).abs() < 1e-9);
    }
}

#[test]
fn eval_renders_at_the_size_of_downscaled_photos_and_names_problems() {
    let dir = tempfile::tempdir().unwrap();
    let (model, cams) = model_dir(dir.path(), 9);
    let images = dir.path().join("images_2");
    std::fs::create_dir_all(&images).unwrap();
    // Photos downscaled by 2 (as images_2 of a data set): 48x27.
    let mut own = Vec::new();
    for (i, cam) in cams.iter().enumerate() {
        let photo = noisy_photo(cam, 48, 27, 100 + i as u64);
        write_png(&images.join(format!("{}.png", cam.name)), 48, 27, &photo);
        own.push(own_psnr(cam, 48, 27, &photo));
    }
    let rep = dir.path().join("rep");
    let o = verisplat(&[
        "eval",
        s(&model),
        "--images",
        s(&images),
        "-o",
        s(&rep),
        "--cpu",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json = read_json(&rep.join("report.json"));
    let results = json["results"].as_array().unwrap();
    assert_eq!(results.len(), 2, "cameras 0 and 8");
    for r in results {
        assert_eq!(
            (r["width"].as_u64(), r["height"].as_u64()),
            (Some(48), Some(27))
        );
        let k = r["frame"].as_u64().unwrap() as usize;
        assert!((r["psnr"].as_f64().unwrap() - own[k]).abs() < 1e-9);
    }

    // A missing photo names the camera and the path looked for, unless --skip-missing.
    std::fs::remove_file(images.join("view_008.png")).unwrap();
    let out = dir.path().join("rep2");
    let e = fails(
        &[
            "eval",
            s(&model),
            "--images",
            s(&images),
            "-o",
            s(&out),
            "--cpu",
        ],
        &out,
    );
    assert!(
        e.contains("camera 8 (\"view_008\")")
            && e.contains(&format!("{}.{{png,jpg", images.join("view_008").display()))
            && e.contains("--skip-missing"),
        "{e}"
    );
    let o = verisplat(&[
        "eval",
        s(&model),
        "--images",
        s(&images),
        "-o",
        s(&out),
        "--cpu",
        "--skip-missing",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json = read_json(&out.join("report.json"));
    assert_eq!(json["results"].as_array().unwrap().len(), 1);
    assert_eq!(json["skipped"], serde_json::json!(["view_008"]));

    // A photo of another shape is an error naming both sizes.
    write_png(
        &images.join("view_008.png"),
        40,
        40,
        &vec![0.5; 40 * 40 * 3],
    );
    let out = dir.path().join("rep3");
    let e = fails(
        &[
            "eval",
            s(&model),
            "--images",
            s(&images),
            "-o",
            s(&out),
            "--cpu",
        ],
        &out,
    );
    assert!(
        e.contains("96x54") && e.contains("40x40") && e.contains("view_008"),
        "{e}"
    );
}

#[test]
fn model_directories_cameras_and_iterations() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = model_dir(dir.path(), 9);
    // The model's cameras.json is picked up by render (9 frames, named after it).
    let frames = dir.path().join("frames");
    let o = verisplat(&[
        "render",
        s(&model),
        "--cpu",
        "-q",
        "-o",
        &format!("{}/{{name}}.png", frames.display()),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("note: using the model's cameras"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read_dir(&frames).unwrap().count(), 9);
    assert!(frames.join("view_004.png").is_file());
    assert_eq!(
        image::open(frames.join("view_004.png")).unwrap().width(),
        96
    );
    // ... and by bench and compare.
    let o = verisplat(&[
        "bench",
        s(&model),
        "--cpu",
        "--frames",
        "1",
        "--warmup",
        "0",
    ]);
    assert!(
        o.status.success() && stderr(&o).contains("note: using the model's cameras"),
        "{}",
        stderr(&o)
    );
    let rep = dir.path().join("rep");
    let out = succeeds(&["compare", s(&model), "--camera", "0", "-o", s(&rep)]);
    assert!(out.contains("view_000"), "{out}");

    // --iteration picks point_cloud/iteration_N; the default is the largest.
    let info = succeeds(&["info", s(&model)]);
    assert!(
        info.contains("iteration_30000") && info.contains("1873"),
        "{info}"
    );
    let info = succeeds(&["info", s(&model), "--iteration", "7000"]);
    assert!(
        info.contains("iteration_7000") && info.contains("gaussians   3"),
        "{info}"
    );
    let one = dir.path().join("one.png");
    let o = verisplat(&[
        "render",
        s(&model),
        "--iteration",
        "7000",
        "--camera",
        "0",
        "--cpu",
        "-o",
        s(&one),
    ]);
    assert!(
        o.status.success() && stderr(&o).contains("iteration_7000"),
        "{}",
        stderr(&o)
    );
    // A missing iteration lists the ones there are.
    let e = fails(
        &[
            "render",
            s(&model),
            "--iteration",
            "5000",
            "--cpu",
            "-o",
            s(&dir.path().join("x.png")),
        ],
        &dir.path().join("x.png"),
    );
    assert!(
        e.contains("iteration_5000") && e.contains("7000, 30000"),
        "{e}"
    );
    let scene = common::shared_data().join("train3_sh3.ply");
    let e = fails(
        &["info", s(&scene), "--iteration", "7000"],
        Path::new("/nonexistent"),
    );
    assert!(e.contains("not a trained model directory"), "{e}");

    // --cameras MODEL_DIR reads that directory's cameras.json.
    let frames2 = dir.path().join("frames2");
    let o = verisplat(&[
        "render",
        s(&common::shared_data().join("playbot_lod6_1873_sh2.ply")),
        "--cameras",
        s(&model),
        "--camera",
        "view_002",
        "--cpu",
        "-o",
        &format!("{}/{{name}}.png", frames2.display()),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(frames2.join("view_002.png").is_file());

    // Without cameras.json the default camera is used, with a note.
    std::fs::remove_file(model.join("cameras.json")).unwrap();
    let two = dir.path().join("two.png");
    let o = verisplat(&["render", s(&model), "--cpu", "--width", "64", "-o", s(&two)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("has no cameras.json; using the default camera"),
        "{}",
        stderr(&o)
    );
    // eval then needs --cameras.
    let e = fails(
        &[
            "eval",
            s(&model),
            "--images",
            s(dir.path()),
            "-o",
            s(&dir.path().join("r")),
        ],
        &dir.path().join("r"),
    );
    assert!(e.contains("--cameras"), "{e}");
}

/// `--scale-modifier` (the reference's scaling_modifier) is checked against the reference
/// like any frame, changes the image, and is refused where it means nothing.
#[test]
fn scale_modifier_renders_match_the_reference_and_change_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let out = succeeds(&[
        "compare",
        "--demo",
        "--width",
        "200",
        "--scale-modifier",
        "0.6",
        "-o",
        s(&dir.path().join("rep")),
    ]);
    assert!(out.contains("all pass"), "{out}");
    let plain = dir.path().join("plain.png");
    let small = dir.path().join("small.png");
    succeeds(&["render", "--demo", "--width", "200", "-o", s(&plain)]);
    succeeds(&[
        "render",
        "--demo",
        "--width",
        "200",
        "--scale-modifier",
        "0.6",
        "-o",
        s(&small),
    ]);
    let (a, b) = (
        image::open(&plain).unwrap().to_rgb8(),
        image::open(&small).unwrap().to_rgb8(),
    );
    let changed = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(changed > 1000, "only {changed} pixels changed");
    let never = dir.path().join("never.png");
    for bad in ["0", "-1", "nan"] {
        let o = verisplat(&["render", "--demo", "--scale-modifier", bad, "-o", s(&never)]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{bad}: {e}");
        assert!(
            e.contains("--scale-modifier") && !e.contains("panicked"),
            "{e}"
        );
        assert!(!never.exists());
    }
    let e = fails(
        &["compare", s(&plain), s(&small), "--scale-modifier", "2"],
        &never,
    );
    assert!(e.contains("--scale-modifier"), "{e}");
}
