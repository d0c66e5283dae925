//! Rendering camera paths to image sequences with the `verisplat` binary: split runs equal
//! one run, an interrupted run resumes to the same files and never leaves a truncated
//! frame, outputs read back equal to the in-memory render, render modes and filters.

use crate::common;
use crate::common::cli::{command, ok_stderr, s, verisplat};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};
use verisplat::core::scene::filter::SceneFilter;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;
use verisplat::io::scene::ply;

/// Every file of a directory (recursively) with its bytes, by relative path.
fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_path_buf();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Asserts two planes are equal, reporting the first difference (not the whole plane).
fn same(label: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{label}: lengths");
    if let Some(i) = (0..got.len()).find(|&i| got[i].to_bits() != want[i].to_bits()) {
        panic!("{label}: sample {i} is {} instead of {}", got[i], want[i]);
    }
}

/// Decodes an image file completely (PNG with `image`, EXR with `exr`): a truncated file
/// fails.
fn decodes(path: &Path) -> Result<(), String> {
    if path.extension().is_some_and(|e| e == "exr") {
        exr::prelude::read_all_data_from_file(path)
            .map(|_| ())
            .map_err(|e| e.to_string())
    } else {
        image::open(path).map(|_| ()).map_err(|e| e.to_string())
    }
}

#[test]
fn a_path_split_into_frame_ranges_equals_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    let split = dir.path().join("split");
    let common = [
        "render",
        "--demo",
        "--orbit",
        "10",
        "--width",
        "160",
        "--mode",
        "rgb+depth",
    ];
    let run = |out: &Path, extra: &[&str]| {
        let pattern = out.join("f_{:04}.png");
        let mut args = common.to_vec();
        args.extend(["-o", s(&pattern)]);
        args.extend(extra);
        ok_stderr(&args)
    };
    run(&whole, &[]);
    run(&split, &["--frames", "0..4"]);
    run(&split, &["--frames", "4..=6"]);
    run(&split, &["--frames", "7.."]);
    let (a, b) = (files(&whole), files(&split));
    assert_eq!(a.len(), 20, "10 colour and 10 depth PNGs: {:?}", a.keys());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, v) in &a {
        assert!(b[k] == *v, "{} differs between the runs", k.display());
    }
    // The same holds for EXR, and for the CPU renderer.
    let whole = dir.path().join("whole_exr");
    let split = dir.path().join("split_exr");
    let exr = |out: &Path, extra: &[&str]| {
        let pattern = out.join("{name}.exr");
        let mut args = vec!["render", "--demo", "--orbit", "4", "--width", "96", "--cpu"];
        args.extend(["-o", s(&pattern)]);
        args.extend(extra);
        ok_stderr(&args)
    };
    exr(&whole, &[]);
    exr(&split, &["--frames", "..2"]);
    exr(&split, &["--frames", "2..", "--encode-threads", "0"]);
    assert_eq!(files(&whole), files(&split));
    assert!(whole.join("orbit_00003.exr").exists());
}

#[test]
fn a_killed_run_resumes_to_the_files_of_an_uninterrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::shared_data().join("playbot_lod3_31k_sh2.ply");
    let args = |out: &Path| -> Vec<String> {
        [
            "render",
            s(&scene),
            "--orbit",
            "40",
            "--width",
            "480",
            "--mode",
            "rgb+depth",
            "-o",
            s(&out.join("frame_{:03}.exr")),
            "--exr-half",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let reference = dir.path().join("reference");
    let o = command().args(args(&reference)).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let resumed = dir.path().join("resumed");
    let mut child = command()
        .args(args(&resumed))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Watch the folder while it runs: every frame file that exists decodes completely.
    let start = Instant::now();
    let mut checked = 0;
    loop {
        let done: Vec<PathBuf> = std::fs::read_dir(&resumed)
            .map(|d| {
                d.flatten()
                    .map(|e| e.path())
                    .filter(|p| p.extension().is_some_and(|e| e == "exr"))
                    .collect()
            })
            .unwrap_or_default();
        for p in &done {
            decodes(p).unwrap_or_else(|e| panic!("{} is not a complete image: {e}", p.display()));
            checked += 1;
        }
        if done.len() >= 8 {
            break;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before it could be interrupted"
        );
        assert!(start.elapsed() < Duration::from_secs(120), "no progress");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(checked > 0);
    let partial = files(&resumed);
    let frames = partial
        .keys()
        .filter(|k| !k.to_string_lossy().starts_with('.'))
        .count();
    assert!(frames < 40, "killed too late: {frames} frames");
    for k in partial
        .keys()
        .filter(|k| !k.to_string_lossy().starts_with('.'))
    {
        decodes(&resumed.join(k)).unwrap_or_else(|e| panic!("{}: {e}", k.display()));
    }
    // Without --skip-existing the run refuses to touch the existing frames.
    let o = command().args(args(&resumed)).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--skip-existing"));
    // Resume.
    let mut resume = args(&resumed);
    resume.push("--skip-existing".into());
    let o = command().args(&resume).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert!(e.contains("skipped"), "{e}");
    // Same files, byte for byte, and no temporary file left behind.
    assert_eq!(files(&reference), files(&resumed));
}

#[test]
fn exr_and_png16_hold_the_in_memory_render() {
    let dir = tempfile::tempdir().unwrap();
    let scene = verisplat::io::demo::demo_scene();
    // The CLI makes the default camera at the requested size (it frames the scene for
    // that aspect ratio), not a 1280x720 camera scaled down.
    let (w, h) = verisplat::core::camera::resized_dims((1280, 720), Some(200), None, None).unwrap();
    let cam = verisplat::core::camera::default_camera(&scene.positions, w, h);
    let frame = cpu::render(
        &scene.activated(),
        &cam,
        &RenderOptions {
            background: [0.1, 0.2, 0.3],
            ..Default::default()
        },
    );
    let exr_path = dir.path().join("f.exr");
    let half_path = dir.path().join("h.exr");
    let png_path = dir.path().join("f.png");
    let alpha_path = dir.path().join("a.png");
    let base = [
        "render",
        "--demo",
        "--cpu",
        "--width",
        "200",
        "--background",
        "0.1,0.2,0.3",
    ];
    let with = |extra: &[&str]| {
        let mut a = base.to_vec();
        a.extend(extra);
        ok_stderr(&a);
    };
    with(&["-o", s(&exr_path)]);
    with(&["-o", s(&half_path), "--exr-half", "--mode", "rgb"]);
    with(&["-o", s(&png_path), "--png16"]);
    with(&["-o", s(&alpha_path), "--mode", "alpha", "--png16"]);

    use exr::prelude::*;
    let read = |p: &Path| {
        read_all_flat_layers_from_file(p)
            .unwrap()
            .layer_data
            .remove(0)
            .channel_data
            .list
    };
    let chans = read(&exr_path);
    let names: Vec<String> = chans.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["A", "B", "G", "R", "Z"]);
    let plane =
        |c: &AnyChannel<FlatSamples>| -> Vec<f32> { c.sample_data.values_as_f32().collect() };
    // EXR colour is premultiplied (the background term removed); Z is +inf where empty.
    let premultiplied = verisplat::io::output::premultiplied_color(&frame, [0.1, 0.2, 0.3]);
    let colour = |ch: usize| -> Vec<f32> { premultiplied.iter().map(|p| p[ch]).collect() };
    let z: Vec<f32> = (frame.depth.iter().zip(&frame.alpha))
        .map(|(&d, &a)| if a > 0.0 { d } else { f32::INFINITY })
        .collect();
    same("A", &plane(&chans[0]), &frame.alpha);
    same("B", &plane(&chans[1]), &colour(2));
    same("G", &plane(&chans[2]), &colour(1));
    same("R", &plane(&chans[3]), &colour(0));
    same("Z", &plane(&chans[4]), &z);
    // Half floats: R, G, B, A only (mode rgb), each the f16 rounding of the value.
    let chans = read(&half_path);
    let names: Vec<String> = chans.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["A", "B", "G", "R"]);
    assert!(matches!(chans[3].sample_data, FlatSamples::F16(_)));
    let want: Vec<f32> = colour(0)
        .into_iter()
        .map(|v| f16::from_f32(v).to_f32())
        .collect();
    same("half R", &plane(&chans[3]), &want);
    // 16-bit PNG: exactly the quantised colour; the alpha PNG is grey.
    let png = image::open(&png_path).unwrap().to_rgb16();
    for (i, p) in png.pixels().enumerate() {
        let want = frame.color[i].map(verisplat::io::output::to_u16);
        assert_eq!(p.0, want, "pixel {i}");
    }
    let alpha = image::open(&alpha_path).unwrap();
    assert_eq!(alpha.color(), image::ColorType::L16);
    let alpha = alpha.to_luma16();
    for (i, p) in alpha.pixels().enumerate() {
        assert_eq!(p.0[0], verisplat::io::output::to_u16(frame.alpha[i]));
    }
}

#[test]
fn depth_modes_write_depth() {
    let dir = tempfile::tempdir().unwrap();
    let exr_path = dir.path().join("d.exr");
    let png_path = dir.path().join("d.png");
    let base = ["render", "--demo", "--width", "160", "--mode", "depth"];
    let mut a = base.to_vec();
    a.extend(["-o", s(&exr_path)]);
    ok_stderr(&a);
    let mut a = base.to_vec();
    a.extend(["-o", s(&png_path)]);
    ok_stderr(&a);
    let layer = exr::prelude::read_all_flat_layers_from_file(&exr_path)
        .unwrap()
        .layer_data
        .remove(0);
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    assert_eq!(names, ["Z"]);
    let z: Vec<f32> = layer.channel_data.list[0]
        .sample_data
        .values_as_f32()
        .collect();
    // Empty pixels hold +inf ("no surface"), covered ones their depth.
    let covered: Vec<f32> = z.iter().copied().filter(|&d| d.is_finite()).collect();
    assert!(covered.len() > z.len() / 20);
    assert!(z.iter().all(|&d| d.is_finite() || d == f32::INFINITY) && z[0] == f32::INFINITY);
    // The demo camera stands a few units from the robot.
    assert!(covered.iter().all(|&d| d > 0.2 && d < 20.0));
    // The colour-mapped PNG: black where nothing is, colours elsewhere.
    let img = image::open(&png_path).unwrap().to_rgb8();
    assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
    let coloured = img.pixels().filter(|p| p.0 != [0, 0, 0]).count();
    assert!(coloured > (img.width() * img.height()) as usize / 20);
}

#[test]
fn max_scale_filter_equals_a_prefiltered_scene() {
    let dir = tempfile::tempdir().unwrap();
    let src = common::shared_data().join("playbot_lod3_31k_sh2.ply");
    let scene = io::scene::load(&src).unwrap();
    // A threshold in the middle of the distribution removes a real share.
    let mut largest: Vec<f32> = scene
        .log_scales
        .iter()
        .map(|s| s[0].max(s[1]).max(s[2]).exp())
        .collect();
    largest.sort_by(|a, b| a.total_cmp(b));
    let threshold = largest[largest.len() * 3 / 4];
    let filter = SceneFilter {
        max_scale: Some(threshold),
        ..Default::default()
    };
    let kept = filter.apply(&scene);
    let above = largest.iter().filter(|&&v| v > threshold).count();
    assert_eq!(kept.len(), scene.len() - above);
    assert!(above > 1000);
    let pre = dir.path().join("prefiltered.ply");
    std::fs::write(
        &pre,
        ply::to_bytes(&kept, ply::PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    let cams = common::shared_data().join("playbot_orbit_cameras.synthetic.json");
    let render = |scene: &Path, out: &Path, extra: &[&str]| {
        let mut a = vec![
            "render",
            s(scene),
            "--cameras",
            s(&cams),
            "--camera",
            "0..3",
            "--width",
            "320",
            "-o",
            s(out),
        ];
        a.extend(extra);
        ok_stderr(&a)
    };
    let t = threshold.to_string();
    let e = render(
        &src,
        &dir.path().join("filtered/{}.png"),
        &["--max-scale", &t],
    );
    assert!(
        e.contains(&format!("filters keep {} of {}", kept.len(), scene.len())),
        "{e}"
    );
    render(&pre, &dir.path().join("pre/{}.png"), &[]);
    let (a, b) = (
        files(&dir.path().join("filtered")),
        files(&dir.path().join("pre")),
    );
    assert_eq!(a.len(), 3);
    assert_eq!(a, b);
    // And the filter changes the picture.
    render(&src, &dir.path().join("all/{}.png"), &[]);
    assert_ne!(files(&dir.path().join("all")), a);
}

#[test]
fn sequence_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.png");
    let fails = |args: &[&str]| -> String {
        let o = verisplat(args);
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "{args:?} must fail");
        assert!(!e.contains("panicked"), "{e}");
        assert!(e.starts_with("error: "), "{e}");
        e
    };
    let e = fails(&["render", "--demo", "--orbit", "3", "-o", s(&one)]);
    assert!(e.contains("3 frames") && e.contains("pattern"), "{e}");
    assert!(!one.exists());
    let e = fails(&["render", "--demo", "--orbit", "3", "-o", "x/{bad}.png"]);
    assert!(e.contains("placeholder"), "{e}");
    let e = fails(&[
        "render",
        "--demo",
        "--orbit",
        "3",
        "--frames",
        "5..9",
        "-o",
        s(&dir.path().join("{}.png")),
    ]);
    assert!(e.contains("past the end"), "{e}");
    let e = fails(&["render", "--demo", "--frames", "9..2", "-o", "{}.png"]);
    assert!(e.contains("empty"), "{e}");
    let e = fails(&[
        "render",
        "--demo",
        "--orbit",
        "3",
        "-o",
        s(&dir.path().join("same.png")),
        "--camera",
        "0,0",
    ]);
    assert!(e.contains("same") || e.contains("pattern"), "{e}");
}

#[test]
fn progress_lines_and_summary_without_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let e = ok_stderr(&[
        "render",
        "--demo",
        "--orbit",
        "10",
        "--width",
        "64",
        "-o",
        s(&dir.path().join("p/{:02}.png")),
    ]);
    assert!(e.contains("10/10 frames (100 %)"), "{e}");
    assert!(e.contains("frames/s") && e.contains("ETA"), "{e}");
    assert!(e.contains("rendered") && e.contains("10 frames"), "{e}");
    let q = ok_stderr(&[
        "render",
        "--demo",
        "--orbit",
        "10",
        "--width",
        "64",
        "-q",
        "-o",
        s(&dir.path().join("q/{:02}.png")),
    ]);
    assert!(!q.contains("ETA"), "{q}");
}

#[test]
fn every_camera_file_format_renders_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cameras");
    for (source, frames) in [
        (fixtures.join("colmap_text"), None),
        (fixtures.join("nerfstudio_camera_path.json"), None),
        (fixtures.join("keyframes_example.json"), Some("12")),
        (
            common::shared_data().join("playbot_orbit_cameras.synthetic.json"),
            None,
        ),
    ] {
        let name = source.file_stem().unwrap().to_string_lossy().into_owned();
        let out = dir.path().join(&name);
        let out_dir = format!("{}/", out.display());
        let mut args = vec![
            "render",
            "--demo",
            "--cameras",
            s(&source),
            "--width",
            "48",
            "-o",
            &out_dir,
        ];
        if let Some(n) = frames {
            args.extend(["--path-frames", n]);
        }
        let e = ok_stderr(&args);
        let written = files(&out);
        assert!(!written.is_empty(), "{name}: {e}");
        if let Some(n) = frames {
            assert_eq!(written.len(), n.parse::<usize>().unwrap(), "{name}");
        }
        for k in written.keys() {
            decodes(&out.join(k)).unwrap();
        }
    }
}

/// A device lost in the middle of a path (simulated: the renderer fails at frame 3 with
/// VK_ERROR_DEVICE_LOST) stops the run with one error naming the frame, and every frame
/// finished before it is complete on disk, with and without encoder threads.
#[test]
fn a_device_lost_mid_path_stops_cleanly_with_finished_frames_intact() {
    use verisplat::app::sequence::{self, Existing, OutputPattern, ProgressStyle, RunOptions};
    let scene = verisplat::io::demo::demo_scene();
    let act = scene.activated();
    let cams: Vec<(usize, verisplat::core::camera::Camera)> = verisplat::core::camera::orbit(
        &scene.positions,
        &verisplat::core::camera::OrbitParams {
            frames: 6,
            width: 64,
            height: 36,
            ..Default::default()
        },
    )
    .unwrap()
    .into_iter()
    .enumerate()
    .collect();
    for threads in [0, 2] {
        let dir = tempfile::tempdir().unwrap();
        let pattern = OutputPattern::parse(&dir.path().join("{}.exr"), "png").unwrap();
        let plan = sequence::plan(
            &cams,
            &pattern,
            None,
            &verisplat::io::output::OutputOptions::default(),
            Existing::Refuse,
        )
        .unwrap();
        let mut k = 0;
        let mut render =
            |cam: &verisplat::core::camera::Camera| -> anyhow::Result<verisplat::core::frame::Frame> {
                k += 1;
                if k == 4 {
                    return Err(verisplat::gpu::GpuError::Vk {
                        call: "vkQueueSubmit",
                        result: ash::vk::Result::ERROR_DEVICE_LOST,
                    }
                    .into());
                }
                Ok(cpu::render(&act, cam, &RenderOptions::default()))
            };
        let e = sequence::run(
            &plan.frames,
            &mut render,
            &RunOptions {
                encode_threads: threads,
                progress: ProgressStyle::Quiet,
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with(
                "frame 3: Vulkan call vkQueueSubmit failed: ERROR_DEVICE_LOST (the device was lost"
            ) && e.ends_with("(3 frame(s) written before it are complete)"),
            "{e}"
        );
        let written = files(dir.path());
        let names: Vec<String> = written.keys().map(|k| k.display().to_string()).collect();
        assert_eq!(names, ["0.exr", "1.exr", "2.exr"], "threads {threads}");
        for n in &names {
            decodes(&dir.path().join(n)).unwrap();
        }
    }
}
