//! The command line as a new user meets it (issue 16): one test per defect found by trying
//! every command, so each stays fixed. Renders use the CPU reference at small sizes (fast
//! and device-independent) unless the item is about the GPU path.

use crate::common::cli::{bin, fails, ok, s, stderr, stdout, verisplat, verisplat_in};

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A clap usage error: non-zero exit, no panic, the message contains `needle`.
fn usage_error(args: &[&str], needle: &str) {
    let o = verisplat(args);
    let e = stderr(&o);
    assert!(!o.status.success(), "{args:?} must fail");
    assert!(!e.contains("panicked"), "{args:?} panicked: {e}");
    assert!(e.contains(needle), "{args:?}: {e}");
}

/// An INRIA cameras.json with a camera named after its photo and one without `img_name`.
fn cameras_json(dir: &Path) -> PathBuf {
    let cam = |id: u32, name: Option<&str>, z: f32| {
        let name = name.map_or(String::new(), |n| format!("\"img_name\": \"{n}\", "));
        format!(
            "{{\"id\": {id}, {name}\"width\": 64, \"height\": 48, \"position\": [0, 0, {z}], \"rotation\": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], \"fx\": 60, \"fy\": 60}}"
        )
    };
    let path = dir.join("cams.json");
    std::fs::write(
        &path,
        format!(
            "[{}, {}]",
            cam(0, Some("front.png"), -4.0),
            cam(5, None, -5.0)
        ),
    )
    .unwrap();
    path
}

/// Item 1: a closed stdout ends the command quietly, for every command that prints.
#[test]
fn closed_stdout_is_not_a_panic() {
    // The reader is gone before the writer starts, so the first write hits a closed pipe.
    for args in [
        "info --demo",
        "info --demo --json",
        "bench --demo --cpu --frames 1 --warmup 0 --width 32",
    ] {
        let o = Command::new("bash")
            .arg("-c")
            .arg(format!(
                "set -o pipefail; (sleep 0.3; exec \"$0\" {args}) | true"
            ))
            .arg(bin())
            .output()
            .unwrap();
        let e = stderr(&o);
        assert!(!e.contains("panicked"), "{args}: {e}");
        assert!(o.status.success(), "{args}: status {:?}: {e}", o.status);
    }
    // Any other failure to write stdout is an error, not silence.
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full");
    if let Ok(full) = full {
        let o = Command::new(bin())
            .args(["info", "--demo"])
            .stdout(Stdio::from(full))
            .output()
            .unwrap();
        assert!(!o.status.success());
        assert!(stderr(&o).contains("writing to standard output failed"));
    }
}

/// Item 2: negative numbers are values; out-of-range values are range errors.
#[test]
fn negative_numbers_and_range_errors() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = dir.path().join("neg_{}.png");
    let o = ok(&[
        "render",
        "--demo",
        "--cpu",
        "--orbit",
        "2",
        "--orbit-elevation",
        "-10",
        "--orbit-start",
        "-90",
        "--orbit-centre",
        "-0.1,0,0",
        "--orbit-up",
        "0,-1,0",
        "--width",
        "48",
        "-o",
        s(&pattern),
        "-q",
    ]);
    assert!(dir.path().join("neg_0.png").exists() && dir.path().join("neg_1.png").exists());
    assert!(stderr(&o).contains("2 frames"));
    // The US spelling is accepted too.
    ok(&[
        "render",
        "--demo",
        "--cpu",
        "--orbit",
        "1",
        "--orbit-center",
        "-0.1,0,0",
        "--width",
        "32",
        "-o",
        s(&dir.path().join("us.png")),
        "-q",
    ]);
    let out = dir.path().join("r.png");
    for (flag, value, needle) in [
        ("--orbit-radius", "-1", "must be greater than 0"),
        ("--width", "-5", "must be between 1 and 16384"),
        ("--scale", "-2", "must be greater than 0"),
        ("--max-scale", "-0.5", "must be greater than 0"),
        ("--min-opacity", "-0.5", "must be between 0 and 1"),
        ("--vfov", "0", "between 0 and 180"),
        ("--encode-threads", "1000", "between 0 and 64"),
        ("--sh-degree", "-1", "between 0 and 3"),
        ("--background", "2,0,0", "between 0 and 1"),
    ] {
        let mut args = vec!["render", "--demo", "--cpu", "-o", s(&out), flag, value];
        if flag.starts_with("--orbit") {
            args.extend(["--orbit", "2"]);
        }
        usage_error(&args, needle);
        assert!(!out.exists());
    }
    usage_error(
        &[
            "render",
            "--demo",
            "--orbit",
            "2",
            "--orbit-elevation",
            "-95",
        ],
        "between -90 and 90",
    );
}

/// Item 3: a number is a device index and only an index.
#[test]
fn device_number_is_only_an_index() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d.png");
    let e = fails(&["render", "--demo", "--device", "99", "-o", s(&out)], &out);
    assert!(
        e.contains("there is no device #99") && e.contains("available: #0"),
        "{e}"
    );
    let e = fails(
        &["render", "--demo", "--device", "no-such-gpu", "-o", s(&out)],
        &out,
    );
    assert!(e.contains("no device name contains 'no-such-gpu'"), "{e}");
}

/// Item 4: options the chosen output or camera source would ignore are refused.
#[test]
fn ignored_option_combinations_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cams = cameras_json(dir.path());
    let keyframes =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cameras/keyframes_example.json");
    let png = dir.path().join("x.png");
    let exr = dir.path().join("x.exr");
    let cases: Vec<(Vec<&str>, &Path, &str)> = vec![
        (
            vec!["--format", "exr", "-o", s(&png)],
            &png,
            "--format sets the image format of a directory output",
        ),
        (
            vec!["--png16", "-o", s(&exr)],
            &exr,
            "--png16 applies to PNG",
        ),
        (
            vec!["--exr-half", "-o", s(&png)],
            &png,
            "--exr-half applies to EXR",
        ),
        (
            vec!["--depth-range", "1,2", "--mode", "rgb", "-o", s(&png)],
            &png,
            "--depth-range sets the colour map of depth PNGs",
        ),
        (
            vec!["--depth-range", "1,2", "-o", s(&exr)],
            &exr,
            "--depth-range",
        ),
        (
            vec!["--path-frames", "5", "--cameras", s(&cams), "-o", s(&png)],
            &png,
            "is a INRIA cameras.json file",
        ),
        (
            vec!["--fps", "10", "--orbit", "3", "-o", s(&png)],
            &png,
            "an orbit's frame count is --orbit FRAMES",
        ),
        (
            vec!["--fps", "10", "-o", s(&png)],
            &png,
            "--fps set the sampling of a keyframe path",
        ),
        (
            vec![
                "--vfov",
                "40",
                "--cameras",
                keyframes.to_str().unwrap(),
                "-o",
                s(&png),
            ],
            &png,
            "brings its own intrinsics",
        ),
        (
            vec!["--cpu", "--device", "0", "-o", s(&png)],
            &png,
            "--device applies to the Vulkan pipeline",
        ),
        (
            vec!["--cpu", "--memory-limit", "1G", "-o", s(&png)],
            &png,
            "--memory-limit applies to the Vulkan pipeline",
        ),
    ];
    for (extra, out, needle) in cases {
        let mut args = vec!["render", "--demo"];
        args.extend(extra);
        let e = fails(&args, out);
        assert!(e.contains(needle), "{args:?}: {e}");
    }
    // --timings and -v with --cpu print the CPU reference's phases and renderer.
    let o = ok(&[
        "render",
        "--demo",
        "--cpu",
        "--timings",
        "-v",
        "--width",
        "64",
        "-o",
        s(&png),
    ]);
    let e = stderr(&o);
    assert!(e.contains("renderer: the CPU reference"), "{e}");
    for phase in [
        "CPU ms",
        "preprocess",
        "keys",
        "sort",
        "ranges",
        "blend",
        "frame",
    ] {
        assert!(e.contains(phase), "{phase}: {e}");
    }
}

/// Item 5: outputs are checked before any work, and missing folders are created.
#[test]
fn outputs_are_checked_before_the_work_starts() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a_file");
    std::fs::write(&file, b"x").unwrap();
    // A folder that cannot exist (a file is in the way) is reported before the missing
    // scene is even looked at.
    let out = file.join("sub/out.png");
    let e = fails(&["render", "no_such_scene.ply", "-o", s(&out)], &out);
    assert!(e.contains("cannot create the output folder"), "{e}");
    let json = file.join("b.json");
    let e = fails(&["bench", "no_such_scene.ply", "--json", s(&json)], &json);
    assert!(e.contains("cannot create the output folder"), "{e}");
    let e = fails(
        &["convert", "no_such_scene.ply", s(&file.join("c.ply"))],
        &file.join("c.ply"),
    );
    assert!(e.contains("cannot create the output folder"), "{e}");
    // Missing folders of bench reports are created.
    let json = dir.path().join("new/dir/b.json");
    ok(&[
        "bench",
        "--demo",
        "--cpu",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--width",
        "32",
        "-q",
        "--json",
        s(&json),
    ]);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["runs"].as_array().unwrap().len(), 1);
}

/// Item 7: convert and gen say what they drop and write what the name asks for.
#[test]
fn convert_and_gen_are_honest_about_formats() {
    let dir = tempfile::tempdir().unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/playbot_lod6_1873_sh2.ply");
    let splat = dir.path().join("a.splat");
    let o = ok(&["convert", s(&src), s(&splat)]);
    let e = stderr(&o);
    assert!(
        e.contains("SH degree 0") && e.contains("SH degree 2 was reduced to 0"),
        "{e}"
    );
    let empty = dir.path().join("empty.ply");
    let o = ok(&["convert", s(&src), s(&empty), "--min-opacity", "1"]);
    assert!(
        stderr(&o).contains("the filters removed all 1873 Gaussians"),
        "{}",
        stderr(&o)
    );
    // A compressed PLY cannot be empty: a clear error, and no file.
    let cp = dir.path().join("x.compressed.ply");
    let e = fails(&["convert", s(&src), s(&cp), "--min-opacity", "1"], &cp);
    assert!(e.contains("the filters removed all 1873 Gaussians"), "{e}");
    // The input itself, by another spelling of its path, even with --overwrite.
    let copy = dir.path().join("copy.ply");
    std::fs::copy(&src, &copy).unwrap();
    let same = dir.path().join("./copy.ply");
    let o = verisplat(&["convert", s(&copy), s(&same), "--overwrite"]);
    assert!(
        !o.status.success() && stderr(&o).contains("is the input file"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&copy).unwrap(), std::fs::read(&src).unwrap());
    // gen writes the format its name asks for.
    let spz = dir.path().join("g.spz");
    ok(&["gen", "500", "-o", s(&spz)]);
    let o = ok(&["info", s(&spz)]);
    assert!(stdout(&o).contains("format      SPZ"), "{}", stdout(&o));
    let bad = dir.path().join("g.xyz");
    let e = fails(&["gen", "10", "-o", s(&bad)], &bad);
    assert!(e.contains("unknown output format"), "{e}");
}

/// Item 8: output names, one numbering for --camera and --frames, lists and bounds.
#[test]
fn output_names_and_frame_selection() {
    let dir = tempfile::tempdir().unwrap();
    let cams = cameras_json(dir.path());
    let names = dir.path().join("named/{name}.png");
    ok(&[
        "render",
        "--demo",
        "--cpu",
        "--cameras",
        s(&cams),
        "-o",
        s(&names),
        "-q",
    ]);
    let mut files: Vec<String> = std::fs::read_dir(dir.path().join("named"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(files, ["camera_5.png", "front.png"]);
    one_frame_and_frames_of_the_whole_path(dir.path());
    frame_lists_bounds_and_hash_patterns(dir.path(), &cams);
}

/// One frame of an orbit to one file; --frames numbers frames in the whole path, whatever
/// --camera selected.
fn one_frame_and_frames_of_the_whole_path(dir: &Path) {
    // One frame of an orbit to one file.
    let single = dir.join("single.png");
    ok(&[
        "render",
        "--demo",
        "--cpu",
        "--orbit",
        "3",
        "--frames",
        "1",
        "--width",
        "32",
        "-o",
        s(&single),
    ]);
    assert!(single.exists());
    // --frames numbers frames in the whole path, whatever --camera selected.
    let out = dir.join("o_{}.png");
    let e = fails(
        &[
            "render",
            "--demo",
            "--cpu",
            "--orbit",
            "6",
            "--camera",
            "3,5",
            "--frames",
            "1",
            "-o",
            s(&out),
        ],
        &dir.join("o_1.png"),
    );
    assert!(
        e.contains("--frames 1 selects none of the 2 frame(s) chosen (3, 5)"),
        "{e}"
    );
    ok(&[
        "render",
        "--demo",
        "--cpu",
        "--orbit",
        "6",
        "--camera",
        "3,5",
        "--frames",
        "5",
        "--width",
        "32",
        "-o",
        s(&out),
        "-q",
    ]);
    assert!(dir.join("o_5.png").exists() && !dir.join("o_3.png").exists());
}

/// --frames lists, bounds reported in the notation the option reads, and #### patterns.
fn frame_lists_bounds_and_hash_patterns(dir: &Path, cams: &Path) {
    let out = dir.join("o_{}.png");
    // Lists, and bounds reported in the notation the option reads.
    let list = dir.join("l_%02d.png");
    ok(&[
        "render",
        "--demo",
        "--cpu",
        "--orbit",
        "10",
        "--frames",
        "0,2,7..=8",
        "--width",
        "32",
        "-o",
        s(&list),
        "-q",
    ]);
    for k in [0, 2, 7, 8] {
        assert!(dir.join(format!("l_{k:02}.png")).exists(), "{k}");
    }
    assert!(!dir.join("l_01.png").exists());
    let e = fails(
        &[
            "render",
            "--demo",
            "--cpu",
            "--orbit",
            "10",
            "--frames",
            "5..20",
            "-o",
            s(&out),
        ],
        &dir.join("o_19.png"),
    );
    assert!(e.contains("0..=9") && e.contains("use 5.."), "{e}");
    let e = fails(
        &[
            "render",
            "--demo",
            "--cpu",
            "--orbit",
            "10",
            "--camera",
            "5..20",
            "-o",
            s(&out),
        ],
        &dir.join("o_19.png"),
    );
    assert!(e.contains("0..=9") && e.contains("use 5.."), "{e}");
    let e = fails(
        &[
            "render",
            "--demo",
            "--cpu",
            "--cameras",
            s(cams),
            "--camera",
            "7",
            "-o",
            s(&out),
        ],
        &dir.join("o_7.png"),
    );
    assert!(e.contains("(0..=1)"), "{e}");
    // #### patterns.
    let hashes = dir.join("h.####.png");
    ok(&[
        "render",
        "--demo",
        "--cpu",
        "--orbit",
        "2",
        "--width",
        "32",
        "-o",
        s(&hashes),
        "-q",
    ]);
    assert!(dir.join("h.0001.png").exists());
}

/// Item 9: with --skip-existing, a file another run writes meanwhile is kept.
#[test]
fn skip_existing_keeps_a_file_that_appears_during_the_run() {
    use verisplat::app::sequence::{self, Existing, OutputPattern, RunOptions};
    let dir = tempfile::tempdir().unwrap();
    let scene = verisplat::io::demo::demo_scene().activated();
    let cams: Vec<(usize, verisplat::core::camera::Camera)> = verisplat::core::camera::orbit(
        &scene.positions,
        &verisplat::core::camera::OrbitParams {
            frames: 3,
            width: 32,
            height: 24,
            ..Default::default()
        },
    )
    .unwrap()
    .into_iter()
    .enumerate()
    .collect();
    let pattern = OutputPattern::parse(&dir.path().join("f_{}.png"), "png").unwrap();
    let plan = sequence::plan(&cams, &pattern, None, &Default::default(), Existing::Skip).unwrap();
    assert_eq!(plan.frames.len(), 3);
    let late = dir.path().join("f_2.png");
    for threads in [0, 2] {
        std::fs::remove_file(&late).ok();
        let mut rendered = 0;
        let mut render = |cam: &verisplat::core::camera::Camera| {
            rendered += 1;
            if rendered == 1 {
                // Another process of a split run writes frame 2 while this one renders
                // frame 0.
                std::fs::write(&late, b"written by the other run").unwrap();
            }
            Ok(verisplat::cpu::render(&scene, cam, &Default::default()))
        };
        let opts = RunOptions {
            skip_existing: true,
            encode_threads: threads,
            progress: sequence::ProgressStyle::Quiet,
            ..Default::default()
        };
        let summary = sequence::run(&plan.frames, &mut render, &opts).unwrap();
        assert_eq!(summary.appeared, 1, "threads {threads}");
        assert_eq!(std::fs::read(&late).unwrap(), b"written by the other run");
        assert!(dir.path().join("f_1.png").exists());
        for k in 0..2 {
            std::fs::remove_file(dir.path().join(format!("f_{k}.png"))).unwrap();
        }
    }
}

/// Item 12: the small things a new user reads.
#[test]
fn output_polish() {
    let dir = tempfile::tempdir().unwrap();
    // "from the default camera", not "of the default camera"; plurals.
    let o = ok(&[
        "render",
        "--demo",
        "--cpu",
        "--width",
        "32",
        "-o",
        s(&dir.path().join("a.png")),
    ]);
    let e = stderr(&o);
    assert!(e.contains("from the default camera at 32x18"), "{e}");
    assert!(!e.contains(" 1 cameras") && !e.contains(" 1 frames"), "{e}");
    let o = ok(&["info", "--demo"]);
    assert!(
        stdout(&o).contains("(9 coefficients per channel)"),
        "{}",
        stdout(&o)
    );
    // An empty file says so.
    let empty = dir.path().join("empty.ply");
    std::fs::write(&empty, b"").unwrap();
    let e = fails(&["info", s(&empty)], Path::new("/nonexistent"));
    assert!(e.contains("is empty (0 bytes)"), "{e}");
    // info on a camera file describes it.
    let cams = cameras_json(dir.path());
    let o = ok(&["info", s(&cams)]);
    let text = stdout(&o);
    assert!(
        text.contains("is a camera file")
            && text.contains("INRIA cameras.json")
            && text.contains("cameras     2"),
        "{text}"
    );
    // info --json for scripts, with the same numbers as the text.
    let o = ok(&["info", "--demo", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["schema_version"], 1);
    assert_eq!(v["gaussians"], 1873);
    assert_eq!(v["sh_degree"], 2);
    let counts: u64 = v["opacity_histogram"]["counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap())
        .sum::<u64>()
        + v["opacity_histogram"]["outside"].as_u64().unwrap();
    assert_eq!(counts, 1873);
    // A path without -o goes to a pattern, not to one file.
    let o = verisplat_in(
        dir.path(),
        &[
            "render", "--demo", "--cpu", "--orbit", "2", "--width", "32", "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("render/frame_00000.png").exists());
    assert!(dir.path().join("render/frame_00001.png").exists());
}

/// Item 14: Ctrl-C (SIGINT) and SIGTERM stop a path cleanly with a resume hint.
#[test]
fn interrupting_a_path_stops_cleanly() {
    for signal in ["INT", "TERM"] {
        let dir = tempfile::tempdir().unwrap();
        let child = Command::new(bin())
            .args([
                "render",
                "--demo",
                "--cpu",
                "--orbit",
                "400",
                "--width",
                "320",
                "-o",
                s(&dir.path().join("f_{:03}.png")),
                "-q",
            ])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Wait for the first frame on disk, then interrupt.
        let start = Instant::now();
        while !dir.path().join("f_000.png").exists() {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "no frame written"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let killed = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let out = child.wait_with_output().unwrap();
        let e = stderr(&out);
        assert_eq!(out.status.code(), Some(130), "{signal}: {e}");
        assert!(
            e.contains("interrupted after")
                && e.contains("of 400 frames")
                && e.contains("--skip-existing"),
            "{signal}: {e}"
        );
        // Every file left is complete; no temporaries remain.
        let mut written = 0;
        for entry in std::fs::read_dir(dir.path()).unwrap() {
            let p = entry.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            assert!(!name.ends_with(".tmp"), "temporary left: {name}");
            image::open(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
            written += 1;
        }
        assert!((1..400).contains(&written), "{written}");
    }
}

/// README.md and every docs/*.md, one after the other: the documentation an option may
/// be named in.
fn documentation() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    crate::common::doc_pages()
        .iter()
        .map(|p| std::fs::read_to_string(root.join(p)).unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// Item 11: every option the README and docs/ name exists, and every subcommand's help
/// has examples.
#[test]
fn readme_and_help_agree() {
    let readme = documentation();
    let commands = [
        "render", "info", "bench", "gen", "fit", "convert", "compare", "eval", "train", "view",
    ];
    let helps: Vec<String> = commands
        .iter()
        .map(|c| {
            let o = ok(&[c, "--help"]);
            let h = stdout(&o);
            assert!(h.contains("Examples:"), "{c} --help has no examples");
            h
        })
        .collect();
    let all_help = helps.join("\n");
    // Flags of other programs the README and docs/ show (cargo, the test script).
    let foreign = [
        "--release",
        "--all-targets",
        "--bench",
        "--test",
        "--no-fail-fast",
        "--lib",
        "--bins",
        "--ignored",
        "--nocapture",
        // tools/colormap_shader.py in the RF walkthrough.
        "--channel",
        "--range",
        // sbatch in "Rendering on a cluster".
        "--array",
        "--parsable",
        "--dependency",
        "--wrap",
        "--gres",
        "--gpus-per-task",
        // tools/module_graph.py in docs/module-graph.md.
        "--no-tests",
        "--layers",
        "--mermaid",
        "--why",
        "--depth",
        "--src",
        "--bin",
        "--wings",
        "--python",
    ];
    let mut missing = Vec::new();
    for (i, _) in readme.match_indices("--") {
        let flag: String = readme[i..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
            .collect();
        // `---` is Markdown, not an option.
        if flag.len() <= 2 || flag.starts_with("---") || foreign.contains(&flag.as_str()) {
            continue;
        }
        let boundary = |h: &str| {
            h.match_indices(flag.as_str()).any(|(j, _)| {
                !h[j + flag.len()..]
                    .chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_alphanumeric() || c == '-')
            })
        };
        if !boundary(&all_help) && !missing.contains(&flag) {
            missing.push(flag);
        }
    }
    assert!(
        missing.is_empty(),
        "README or docs/ names options no --help knows: {missing:?}"
    );
    // And the other way round: every option of every subcommand is in the README or docs/.
    let mut undocumented = Vec::new();
    for (c, h) in commands.iter().zip(&helps) {
        for line in h.lines() {
            let t = line.trim_start();
            let flag = t
                .split([' ', ',', '='])
                .find(|w| w.starts_with("--"))
                .unwrap_or("");
            // `-o, --output <OUT>`: the README may use either spelling.
            let short = t
                .strip_prefix('-')
                .filter(|r| r.chars().nth(1) == Some(','))
                .map(|r| format!("-{}", &r[..1]));
            let documented = readme.contains(flag)
                || short.is_some_and(|sh| {
                    readme.contains(&format!("{sh} ")) || readme.contains(&format!("{sh}]"))
                });
            if t.starts_with('-') && !flag.is_empty() && flag != "--help" && !documented {
                undocumented.push(format!("{c} {flag}"));
            }
        }
    }
    assert!(
        undocumented.is_empty(),
        "options missing from the README and docs/: {undocumented:?}"
    );
}

/// A camera file where the scene belongs gets the same answer from every command: what
/// it is and how to pass it (`info` describes it; `render` and `view` used to say "is not
/// a recognised scene format").
#[test]
fn a_camera_file_given_as_the_scene_is_named_as_one_by_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let cams = cameras_json(dir.path());
    let out = dir.path().join("out.png");
    for args in [
        vec!["render", s(&cams), "-o", s(&out)],
        vec!["view", s(&cams), "--port", "0"],
        vec!["bench", s(&cams), "--frames", "1"],
    ] {
        let e = fails(&args, Path::new("/nonexistent"));
        assert!(
            e.contains("is a camera file (INRIA cameras.json), not a scene")
                && e.contains(&format!("--cameras {}", cams.display())),
            "{args:?}: {e}"
        );
        assert!(!e.contains("not a recognised scene format"), "{e}");
    }
    assert!(!out.exists());
}
