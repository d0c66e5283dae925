//! The `verisplat` binary: the README's demo command, `info`, and one clear error (non-zero
//! exit, no panic, no output file) for each bad input.

use crate::common;
use crate::common::cli::{fails, stderr, verisplat};

use std::path::{Path, PathBuf};
use std::process::Command;
use verisplat::io::scene::ply;

#[test]
fn demo_render_writes_a_picture_of_the_robot() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.png");
    let o = verisplat(&["render", "--demo", "-o", out.to_str().unwrap(), "--cpu"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1280, 720));
    // The default camera frames the object: a good share of pixels is covered, the
    // border is background.
    let covered = img.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count();
    let share = covered as f64 / (1280.0 * 720.0);
    assert!((0.05..0.8).contains(&share), "covered share {share}");
    assert!(img.get_pixel(0, 0).0 == [0, 0, 0] && img.get_pixel(1279, 719).0 == [0, 0, 0]);
    // Running it again does not overwrite without --overwrite.
    let e = fails(
        &["render", "--demo", "-o", out.to_str().unwrap(), "--cpu"],
        Path::new("/nonexistent"),
    );
    assert!(
        e.contains("already exists") && e.contains("--overwrite"),
        "{e}"
    );
    let o = verisplat(&[
        "render",
        "--demo",
        "-o",
        out.to_str().unwrap(),
        "--cpu",
        "--overwrite",
        "--width",
        "320",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(image::open(&out).unwrap().width(), 320);
    assert_eq!(image::open(&out).unwrap().height(), 180);
}

#[test]
fn exr_render_with_background_and_scale() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d.exr");
    let o = verisplat(&[
        "render",
        "--demo",
        "--cpu",
        "-o",
        out.to_str().unwrap(),
        "--scale",
        "0.25",
        "--background",
        "1,1,1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
    assert_eq!(img.layer_data[0].size.width(), 320);
    assert_eq!(img.layer_data[0].channel_data.list.len(), 5);
    // OpenEXR's own tool (installed by tools/setup.sh) reads the file and its channels.
    let header = Command::new("exrheader")
        .arg(&out)
        .output()
        .expect("exrheader is installed by tools/setup.sh");
    let text = String::from_utf8_lossy(&header.stdout);
    assert!(header.status.success(), "{text}");
    for ch in [
        "A, 32-bit floating-point",
        "B, 32-bit",
        "G, 32-bit",
        "R, 32-bit",
        "Z, 32-bit",
    ] {
        assert!(text.contains(ch), "exrheader lacks {ch:?}:\n{text}");
    }
}

#[test]
fn info_prints_the_statistics() {
    let o = verisplat(&["info", "--demo"]);
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    for needle in [
        "gaussians   1873",
        "sh degree   2",
        "bounds",
        "max scale per Gaussian",
        "opacity logit (stored)",
        "log scale (stored)",
    ] {
        assert!(s.contains(needle), "missing {needle:?} in\n{s}");
    }
}

fn write_scene(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn bad_inputs_give_one_clear_error_each() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = out.to_str().unwrap();
    let good = ply::to_bytes(
        &common::random_scene(20, 1, 4),
        ply::PlyEncoding::BinaryLittleEndian,
    );
    let scene = write_scene(dir.path(), "good.ply", &good);
    let s = scene.to_str().unwrap();
    let truncated = write_scene(dir.path(), "cut.ply", &good[..good.len() - 10]);
    let mut nan_scene = common::random_scene(5, 0, 4);
    nan_scene.positions[3][0] = f32::NAN;
    let nan = write_scene(
        dir.path(),
        "nan.ply",
        &ply::to_bytes(&nan_scene, ply::PlyEncoding::BinaryLittleEndian),
    );
    let cams = write_scene(dir.path(), "cameras.json", br#"[{"id": 0, "img_name": "a", "width": 64, "height": 48, "position": [0,0,-3], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 50, "fy": 50}]"#);
    let broken_cams = write_scene(dir.path(), "broken.json", b"{ not json");
    let c = cams.to_str().unwrap();
    let jpg = dir.path().join("x.jpg");

    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["render", "/nonexistent/x.ply", "-o", o],
            vec!["/nonexistent/x.ply", "cannot read"],
        ),
        (
            vec!["render", truncated.to_str().unwrap(), "-o", o],
            vec!["cut.ply", "truncated"],
        ),
        (
            vec!["render", nan.to_str().unwrap(), "-o", o],
            vec!["nan.ply", "vertex 3", "non-finite"],
        ),
        (
            vec![
                "render",
                s,
                "--cameras",
                broken_cams.to_str().unwrap(),
                "-o",
                o,
            ],
            vec!["broken.json", "cameras.json"],
        ),
        (
            vec![
                "render",
                s,
                "--cameras",
                "/nonexistent/cameras.json",
                "-o",
                o,
            ],
            vec!["/nonexistent/cameras.json", "cannot read"],
        ),
        (
            vec!["render", s, "--cameras", c, "--camera", "5", "-o", o],
            vec![
                "cameras.json",
                "index 5 is out of range",
                "there is 1 camera (only 0)",
            ],
        ),
        (
            vec!["render", s, "--cameras", c, "--camera", "nope", "-o", o],
            vec!["no camera named \"nope\""],
        ),
        (
            vec!["render", s, "--scale", "1000", "-o", o],
            vec!["--scale", "16384"],
        ),
        (
            vec!["render", s, "-o", jpg.to_str().unwrap()],
            vec![
                "x.jpg",
                "unknown output format",
                ".png",
                ".exr",
                ".mp4",
                ".webm",
                ".gif",
            ],
        ),
        (
            vec!["info", truncated.to_str().unwrap()],
            vec!["cut.ply", "truncated"],
        ),
    ];
    for (args, needles) in cases {
        let mut args = args.clone();
        args.push("--cpu");
        if args[0] == "info" {
            args.pop();
        }
        let e = fails(&args, &out);
        for n in needles {
            assert!(e.contains(n), "{args:?}: expected {n:?} in {e}");
        }
    }
    // Flag errors from clap (range errors are checked while parsing) also exit non-zero
    // without a panic, naming the option and the range.
    for (args, needle) in [
        (vec!["--background", "1,2"], "R,G,B"),
        (vec!["--width", "0"], "between 1 and 16384"),
        (
            vec!["--width", "100000", "--height", "10"],
            "between 1 and 16384",
        ),
        (vec!["--scale", "0"], "--scale"),
    ] {
        let mut all = vec!["render", s, "-o", o];
        all.extend(args);
        let bad = verisplat(&all);
        assert!(
            !bad.status.success() && stderr(&bad).contains(needle),
            "{all:?}"
        );
        assert!(!stderr(&bad).contains("panicked"));
    }
    assert!(!out.exists());
}

#[test]
fn cameras_json_camera_selected_by_name_renders() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cam.png");
    let data = common::shared_data();
    let o = verisplat(&[
        "render",
        data.join("playbot_lod6_1873_sh2.ply").to_str().unwrap(),
        "--cameras",
        data.join("playbot_orbit_cameras.synthetic.json")
            .to_str()
            .unwrap(),
        "--camera",
        "playbot_orbit_006",
        "--scale",
        "0.25",
        "--cpu",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("playbot_orbit_006"));
    assert_eq!(image::open(&out).unwrap().width(), 320);
}

#[test]
fn gpu_is_the_default_and_matches_cpu_output() {
    let dir = tempfile::tempdir().unwrap();
    let gpu = dir.path().join("gpu.png");
    let cpu = dir.path().join("cpu.png");
    let o = verisplat(&[
        "render",
        "--demo",
        "--width",
        "480",
        "-o",
        gpu.to_str().unwrap(),
        "--timings",
        "--validate",
        "-v",
    ]);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    for needle in [
        "device: #",
        "preprocess",
        "scan",
        "keys",
        "sort",
        "ranges",
        "blend",
        "readback",
        "frame",
        "tile pairs",
        "device memory",
    ] {
        assert!(e.contains(needle), "missing {needle:?} in\n{e}");
    }
    assert!(!e.contains("on the CPU"), "{e}");
    let o = verisplat(&[
        "render",
        "--demo",
        "--width",
        "480",
        "-o",
        cpu.to_str().unwrap(),
        "--cpu",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (g, c) = (
        image::open(&gpu).unwrap().to_rgb8(),
        image::open(&cpu).unwrap().to_rgb8(),
    );
    assert_eq!(g.dimensions(), c.dimensions());
    let close = g
        .pixels()
        .zip(c.pixels())
        .filter(|(a, b)| {
            a.0.iter()
                .zip(b.0)
                .all(|(x, y)| (*x as i32 - y as i32).abs() <= 1)
        })
        .count();
    assert!(
        close as f64 >= 0.999 * (480.0 * 270.0),
        "{close} pixels within 1/255"
    );
    // A device that does not exist is one clear error.
    let o = verisplat(&[
        "render",
        "--demo",
        "-o",
        dir.path().join("x.png").to_str().unwrap(),
        "--device",
        "no-such-gpu",
    ]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("no-such-gpu") && !e.contains("panicked"),
        "{e}"
    );
    assert!(!dir.path().join("x.png").exists());
}

#[test]
fn bench_reports_every_stage() {
    let o = verisplat(&[
        "bench", "--demo", "--width", "320", "--frames", "3", "--warmup", "1",
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    for stage in [
        "preprocess",
        "order",
        "scan",
        "keys",
        "sort",
        "ranges",
        "blend",
        "readback",
        "frame (GPU)",
        "wall clock",
    ] {
        let line = out
            .lines()
            .find(|l| l.starts_with(stage))
            .unwrap_or_else(|| panic!("no {stage} line in\n{out}"));
        let median: f64 = line
            .split_whitespace()
            .rev()
            .nth(2)
            .and_then(|v| v.parse().ok())
            .unwrap();
        assert!(median >= 0.0 && median.is_finite(), "{line}");
    }
    let frame_line = out.lines().find(|l| l.starts_with("frame (GPU)")).unwrap();
    let frame_median: f64 = frame_line
        .split_whitespace()
        .rev()
        .nth(2)
        .unwrap()
        .parse()
        .unwrap();
    assert!(frame_median > 0.0, "{frame_line}");
    assert!(
        out.contains("tile pairs") && out.contains("B per Gaussian"),
        "{out}"
    );
    let o = verisplat(&["bench", "--demo", "--frames", "2", "--cpu"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && out.contains("CPU reference"), "{out}");
    // The reference sorts every tile of each rectangle, so it names pairs that cannot draw.
    let sorted_per_drawing = out
        .split("can draw (some pixel centre gets alpha >= 1/255), ")
        .nth(1)
        .and_then(|s| s.split('x').next())
        .and_then(|s| s.parse::<f64>().ok());
    assert!(sorted_per_drawing.is_some_and(|r| r > 1.05), "{out}");
    let o = verisplat(&["bench", "--demo", "--frames", "0"]);
    assert!(!o.status.success() && stderr(&o).contains("--frames"));
}

/// `bench --backward` times both passes, stage by stage, and reports their ratio and the
/// memory per Gaussian; refused with --cpu.
#[test]
fn bench_backward_reports_both_passes() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("backward.json");
    let o = verisplat(&[
        "bench",
        "--demo",
        "--width",
        "128",
        "--height",
        "96",
        "--frames",
        "2",
        "--warmup",
        "1",
        "--backward",
        "--accumulation",
        "cas",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = crate::common::cli::stdout(&o);
    for stage in [
        "blend",
        "blend_bwd",
        "accumulate",
        "preprocess_bwd",
        "backward / forward",
    ] {
        assert!(text.contains(stage), "{stage} missing from:\n{text}");
    }
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let run = &doc["backward_runs"][0];
    assert_eq!(run["accumulation"], "cas");
    assert_eq!(run["feature_channels"], 0);
    let names: Vec<&str> = run["backward_stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["blend_bwd", "accumulate", "preprocess_bwd"]);
    assert!(run["backward_ms"]["median"].as_f64().unwrap() > 0.0);
    assert!(run["backward_over_forward"].as_f64().unwrap() > 0.0);
    assert!(run["device_bytes_per_gaussian"].as_f64().unwrap() > 0.0);
    assert_eq!(run["backward_bands"], serde_json::json!([1, 1]));
    assert!(!text.contains("bands of pixel rows"), "{text}");
    let refused = verisplat(&["bench", "--demo", "--backward", "--cpu"]);
    assert!(!refused.status.success());
    // Storage bindings of 256 KiB: 4 KiB rows of colour gradients in bands of 64 rows (3
    // for 192), and 11k pair records of 48 bytes in bands of 5,440 (3); said in the report.
    let split = dir.path().join("split.json");
    let args = [
        "bench",
        "--demo",
        "--width",
        "256",
        "--height",
        "192",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--backward",
        "--json",
        split.to_str().unwrap(),
    ];
    let o = crate::common::cli::verisplat_env(
        &args,
        &[("VERISPLAT_EMULATE", "max-storage-buffer-range=256K")],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = crate::common::cli::stdout(&o);
    assert!(
        text.contains("backward in 3 bands of pixel rows and 3 of pairs"),
        "{text}"
    );
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&split).unwrap()).unwrap();
    assert_eq!(
        doc["backward_runs"][0]["backward_bands"],
        serde_json::json!([3, 3])
    );
}

/// Bytes per stage (issue 60, item 3) of a `bench --demo` report, tied to the records the
/// shaders load and store.
fn assert_stage_bytes(report: &serde_json::Value) {
    let stages = report["stages"].as_array().unwrap();
    let bytes = |name: &str, k: &str| {
        let s = stages.iter().find(|s| s["name"] == name).unwrap();
        s["bytes"][k].as_u64().unwrap_or_else(|| panic!("{s}"))
    };
    for s in stages {
        let name = s["name"].as_str().unwrap();
        assert!(bytes(name, "read") > 0 && bytes(name, "written") > 0, "{s}");
    }
    let n = report["gaussians"].as_u64().unwrap();
    let (visible, pairs) = (
        report["visible"].as_u64().unwrap(),
        report["pairs"].as_u64().unwrap(),
    );
    let pixels = report["width"].as_u64().unwrap() * report["height"].as_u64().unwrap();
    // Preprocess: each 48-byte record, and the degree-2 SH (27 floats in 7 texels) of each
    // keyed Gaussian; out, per Gaussian, its 48-byte splat and six words, and the counters.
    assert_eq!(bytes("preprocess", "read"), n * 48 + visible * 7 * 16);
    assert_eq!(bytes("preprocess", "written"), n * 72 + 48);
    // Keys: a pair is 8 bytes out; blend: each pair's index and splat in, colour and depth
    // out; readback: the two images copied, and the counters.
    assert_eq!(bytes("keys", "written"), pairs * 8);
    assert!(bytes("blend", "read") > pairs * 52);
    assert_eq!(bytes("blend", "written"), pixels * 20);
    assert_eq!(bytes("readback", "read"), pixels * 20 + 48);
}

#[test]
fn bench_json_reports_every_stage_and_a_sweep_writes_csv_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("report.json");
    let o = verisplat(&[
        "bench",
        "--demo",
        "--width",
        "256",
        "--frames",
        "2",
        "--warmup",
        "1",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(doc["schema_version"], 1);
    let report = &doc["runs"][0];
    let stages = report["stages"].as_array().unwrap();
    let names: Vec<&str> = stages.iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "preprocess",
            "order",
            "scan",
            "keys",
            "sort",
            "ranges",
            "blend",
            "readback"
        ]
    );
    for s in stages {
        for k in ["min", "median", "p95", "max"] {
            assert!(s[k].as_f64().unwrap() > 0.0, "{s}");
        }
        assert!(
            s["min"].as_f64() <= s["median"].as_f64() && s["median"].as_f64() <= s["max"].as_f64()
        );
    }
    assert_stage_bytes(report);
    for k in [
        "fps",
        "sort_keys_per_s",
        "blend_evaluations_per_s",
        "device_bytes_per_gaussian",
    ] {
        assert!(report[k].as_f64().unwrap() > 0.0, "{k} in {report}");
    }
    assert_eq!(report["gaussians"], 1873);
    assert_eq!(report["renderer"], "gpu");
    assert!(
        report["device"].as_str().unwrap().len() > 3
            && report["vulkan"].as_str().unwrap().starts_with('1')
    );
    assert!(report["pairs"].as_u64().unwrap() > 1000 && report["visible"].as_u64().unwrap() > 100);
    // Only pairs that can draw are sorted (issue 60): the host's own count of the pairs of
    // which some pixel centre of the bin gets alpha >= 1/255 is within 1 % of the pairs
    // sorted (the device's test is conservative: it never drops a drawing pair).
    let p = &report["pair_stats"];
    let pairs = report["pairs"].as_u64().unwrap();
    let drawing = p["drawing"].as_u64().unwrap();
    assert!(
        drawing <= pairs && drawing as f64 >= 0.99 * pairs as f64,
        "{p}"
    );
    let (max, p99) = (
        p["per_bin_max"].as_u64().unwrap(),
        p["per_bin_p99"].as_u64().unwrap(),
    );
    assert!(max >= p99 && p99 > 0 && max < pairs, "{p}");
    let per_visible = pairs as f64 / report["visible"].as_f64().unwrap();
    assert!(
        (p["per_visible"].as_f64().unwrap() - per_visible).abs() < 1e-9,
        "{p}"
    );
    // The stage times add up to about the frame (timestamps bracket each stage; the
    // barriers between stages take the rest). Medians are taken per stage, so under a
    // loaded machine (tests run in parallel) their sum can stray from the frame's median.
    let sum: f64 = stages.iter().map(|s| s["median"].as_f64().unwrap()).sum();
    let frame = report["frame_ms"]["median"].as_f64().unwrap();
    assert!(
        sum <= frame * 1.6 && sum >= frame * 0.3,
        "stages {sum} ms vs frame {frame} ms"
    );
    // Existing outputs are not overwritten unasked.
    let o = verisplat(&[
        "bench",
        "--demo",
        "--frames",
        "1",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains("--overwrite"));

    let (csv, svg) = (dir.path().join("sweep.csv"), dir.path().join("sweep.svg"));
    let o = verisplat(&[
        "bench",
        "--sweep",
        "gaussians=500,2e3",
        "--sweep",
        "resolution=160x90",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--csv",
        csv.to_str().unwrap(),
        "--plot",
        svg.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert!(rows[0].starts_with("scene,gaussians,width,height,renderer,stage,min_ms,median_ms"));
    assert_eq!(
        rows.len(),
        1 + 2 * 10,
        "two points x (8 stages + frame + wall)"
    );
    assert!(
        rows.iter().any(|r| r.contains(",500,160,90,gpu,blend,"))
            && rows.iter().any(|r| r.contains(",2000,160,90,gpu,sort,"))
    );
    let plot = std::fs::read_to_string(&svg).unwrap();
    assert!(
        plot.starts_with("<svg") && plot.contains("time vs Gaussians") && plot.contains("blend")
    );
    assert!(std::fs::read_dir(dir.path()).unwrap().all(|e| !e
        .unwrap()
        .file_name()
        .to_string_lossy()
        .ends_with(".tmp")));
    // Bad sweeps are one clear error.
    let o = verisplat(&["bench", "--sweep", "colours=3"]);
    assert!(!o.status.success() && stderr(&o).contains("unknown axis"));
    let o = verisplat(&["bench", "--sweep", "gaussians=lots"]);
    assert!(!o.status.success() && stderr(&o).contains("not a number of Gaussians"));
}

#[test]
fn gen_writes_a_loadable_synthetic_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("synthetic.ply");
    let o = verisplat(&[
        "gen",
        "2e3",
        "--seed",
        "5",
        "--sh-degree",
        "1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = verisplat::io::scene::load(&out).unwrap();
    assert_eq!((s.len(), s.sh_degree), (2000, 1));
    assert_eq!(s, verisplat::core::gen::synthetic_scene(2000, 5, 1));
    let o = verisplat(&["gen", "10", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("already exists"));
}

#[test]
fn info_prints_log_binned_histograms_that_count_every_gaussian() {
    let o = verisplat(&["info", "--demo"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    for title in ["largest scale per Gaussian", "opacity (after the sigmoid)"] {
        let section: Vec<&str> = out
            .split(title)
            .nth(1)
            .unwrap_or_else(|| panic!("no {title} histogram in:\n{out}"))
            .lines()
            .skip(1)
            .take_while(|l| l.trim_start().starts_with('['))
            .collect();
        assert!(section.len() >= 2, "{title}: {section:?}");
        let counts: usize = section
            .iter()
            .map(|l| {
                l.split(')')
                    .nth(1)
                    .unwrap()
                    .split_whitespace()
                    .next()
                    .unwrap()
                    .parse::<usize>()
                    .unwrap()
            })
            .sum();
        assert_eq!(counts, 1873, "{title}");
    }
}

/// `bench --reproducible` says the mode in its table and in each run of the JSON report.
#[test]
fn bench_names_the_reproducible_mode() {
    let dir = tempfile::tempdir().unwrap();
    let bench_json = dir.path().join("bench.json");
    let args = [
        "bench", "--demo", "--width", "160", "--frames", "1", "--warmup", "0",
    ];
    let o = common::cli::ok(
        &[
            &args[..],
            &["--reproducible", "--json", common::cli::s(&bench_json)],
        ]
        .concat(),
    );
    assert!(
        common::cli::stdout(&o).contains("reproducible mode"),
        "{}",
        common::cli::stdout(&o)
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&bench_json).unwrap()).unwrap();
    let runs = json["runs"].as_array().expect("runs");
    assert!(
        !runs.is_empty() && runs.iter().all(|r| r["reproducible"] == true),
        "{json}"
    );
    assert!(!common::cli::stdout(&common::cli::ok(&args)).contains("reproducible mode"));
}

/// `--kernel power` on render, bench and compare; a PLY that records the kernel (header
/// `comment verisplat kernel power`, written by `convert --kernel`) renders with it, with a
/// note, unless `--kernel` overrides; `info` prints it; `convert` keeps it in PLY and says
/// when a format cannot; a bad kernel name is one clear error.
#[test]
fn kernel_flag_and_the_ply_kernel_comment() {
    use common::cli::{ok, s, stdout};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let power = d.join("power.ply");
    ok(&["convert", s(&plain), s(&power), "--kernel", "power"]);
    let bytes = std::fs::read(&power).unwrap();
    let header = String::from_utf8_lossy(&bytes[..400]);
    assert!(
        header.contains("\ncomment verisplat kernel power\n"),
        "{header}"
    );
    assert_eq!(
        verisplat::io::scene::load(&power).unwrap().kernel,
        verisplat::cpu::SplatKernel::Power
    );
    // A Gaussian scene's PLY stays as the trainer writes it (no comment).
    let back = d.join("back.ply");
    ok(&["convert", s(&power), s(&back), "--kernel", "gaussian"]);
    assert!(!String::from_utf8_lossy(&std::fs::read(&back).unwrap()[..400]).contains("comment"));
    // PLY to PLY keeps it; .splat cannot record it and says so.
    let kept = d.join("kept.ply");
    ok(&["convert", s(&power), s(&kept)]);
    assert_eq!(std::fs::read(&kept).unwrap(), bytes);
    let o = ok(&["convert", s(&power), s(&d.join("p.splat"))]);
    assert!(stderr(&o).contains("--kernel power"), "{}", stderr(&o));

    let info = stdout(&ok(&["info", s(&power)]));
    assert!(info.contains("kernel      power"), "{info}");
    assert!(stdout(&ok(&["info", s(&plain)])).contains("kernel      gaussian"));
    let json: serde_json::Value =
        serde_json::from_str(&stdout(&ok(&["info", s(&power), "--json"]))).unwrap();
    assert_eq!(json["kernel"], "power");

    // render: the file's kernel with a note; --kernel overrides; GPU and CPU alike.
    let render = |scene: &Path, out: &str, extra: &[&str]| -> String {
        let mut args = vec!["render", s(scene), "--width", "160", "-o"];
        let out = d.join(out);
        args.push(s(&out));
        args.extend_from_slice(extra);
        stderr(&ok(&args))
    };
    let e = render(&power, "file.png", &["--cpu"]);
    assert!(e.contains("records the power kernel"), "{e}");
    render(&plain, "flag.png", &["--cpu", "--kernel", "power"]);
    render(&power, "override.png", &["--cpu", "--kernel", "gaussian"]);
    render(&plain, "gaussian.png", &["--cpu"]);
    render(&power, "gpu.exr", &[]);
    render(&power, "cpu.exr", &["--cpu"]);
    let read = |n: &str| std::fs::read(d.join(n)).unwrap();
    assert_eq!(read("file.png"), read("flag.png"));
    assert_eq!(read("override.png"), read("gaussian.png"));
    assert_ne!(read("file.png"), read("gaussian.png"));
    ok(&[
        "compare",
        s(&d.join("cpu.exr")),
        s(&d.join("gpu.exr")),
        "--min-psnr",
        "55",
    ]);

    // compare and bench take the flag and report it.
    let report = d.join("report");
    ok(&[
        "compare",
        s(&plain),
        "--kernel",
        "power",
        "--width",
        "160",
        "-o",
        s(&report),
    ]);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("report.json")).unwrap())
            .unwrap();
    assert_eq!(json["kernel"], "power");
    assert_eq!(json["pass"], true);
    let o = ok(&[
        "bench",
        s(&power),
        "--width",
        "160",
        "--frames",
        "1",
        "--warmup",
        "0",
    ]);
    assert!(stdout(&o).contains("power kernel"), "{}", stdout(&o));
    assert!(!stdout(&o).contains("reproducible mode"), "{}", stdout(&o));
    // The table's bytes per stage and the bandwidth they make at the median.
    let text = stdout(&o);
    let blend = text.lines().find(|l| l.starts_with("blend ")).unwrap();
    assert!(
        text.contains("MB moved") && text.contains("GB/s") && blend.split_whitespace().count() == 7,
        "{text}"
    );

    // Bad names: the flag, and the header comment (one sentence naming the line).
    let o = verisplat(&[
        "render",
        "--demo",
        "--kernel",
        "cubic",
        "-o",
        s(&d.join("x.png")),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("use gaussian or power"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("x.png").exists());
    let mut bad = bytes.clone();
    let at = header.find("kernel power").unwrap() + "kernel ".len();
    bad[at..at + 5].copy_from_slice(b"cubic");
    let bad_ply = write_scene(d, "bad.ply", &bad);
    let e = fails(
        &["render", s(&bad_ply), "-o", s(&d.join("y.png"))],
        &d.join("y.png"),
    );
    assert!(
        e.contains("header line 3") && e.contains("unknown kernel \"cubic\""),
        "{e}"
    );
}
