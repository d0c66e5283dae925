//! Malformed-input suite: a table of small hand-made bad (or odd but usable) files for every
//! scene and camera format, each with what must happen.
//!
//! The files are generated here (the table below is the source of truth) into a temporary
//! `malformed/<case>/` directory. Each case is checked twice:
//! * through the library (`io::scene::load`, `io::camera::load_camera_file`): an error is one
//!   sentence that names the file and contains the expected fragment; a usable file decodes
//!   to the stated number of Gaussians and renders correctly on the CPU reference;
//! * through the `verisplat` binary (with `VERISPLAT_VALIDATE=1`, under a timeout): a bad file
//!   gives one `error:` line with the same fragment, a non-zero exit, no panic and nothing
//!   in the output folder (no partial or temporary file); a usable one renders a PNG.
//!
//! Policy for values (the PLY loader's, applied to every format): a NaN or infinite value
//! in any attribute a Gaussian is rendered from (position, scale, rotation, opacity, SH)
//! is an error naming the Gaussian and the property: such values come from a diverged
//! training run and dropping them silently would hide that. Values the renderer does not
//! read (PLY normals, unknown extra properties) are ignored whatever they hold. Denormal
//! values, zero and negative log scales (a scale that underflows to 0 renders as the
//! 0.3-pixel dilation) and 0 Gaussians (the background) are valid. A `.splat` stores linear
//! scales, so a zero or negative scale there has no log scale and is an error.
//!
//! Truncation sweeps cut small valid files of every format at many offsets.

mod cameras;
mod case;
mod compressed_ply;
mod ply;
mod sog;
mod splat;
mod spz;

use crate::common;
use cameras::{colmap_bin, inria_json, keyframes, nerfstudio, C2W, IDENTITY, KEY0, KEY1, PINHOLE};
use case::{scene_case, Case, Expect, Kind};
use compressed_ply::{cply, good_bounds};
use sog::{good_sog_meta, sog_zip};
use spz::spz_v4;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use verisplat::core::camera::Camera;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;
use verisplat::io::camera::PathTiming;
use verisplat::io::scene::compressed_ply::CHUNK_PROPS;

/// The longest a CLI run on a tiny file may take before it counts as a hang.
const CLI_TIMEOUT: Duration = Duration::from_secs(120);
/// Renders of usable cases are this small: the checks are about values, not detail.
const W: u32 = 64;
const H: u32 = 48;

// ---------------------------------------------------------------------------------------
// The table.

/// The table: every case, in the order they are checked.
fn cases() -> Vec<Case> {
    let mut v = Vec::new();
    v.extend(ply::ply_structure_cases());
    v.extend(ply::ply_value_cases());
    v.extend(ply::ply_usable_cases());
    v.extend(splat::splat_cases());
    v.extend(spz::spz_cases());
    v.extend(compressed_ply::compressed_ply_cases());
    v.extend(sog::sog_zip_cases());
    v.extend(sog::sog_dir_cases());
    v.extend(content_detection_cases());
    v.extend(cameras::inria_camera_cases());
    v.extend(cameras::nerfstudio_camera_cases());
    v.extend(cameras::keyframe_path_cases());
    v.extend(cameras::colmap_text_cases());
    v.extend(cameras::colmap_binary_cases());
    // A COLMAP model that is fine renders.
    v.push(cameras::colmap_ok());
    v
}

/// The table's cases for content detection.
fn content_detection_cases() -> Vec<Case> {
    use Expect::Error;
    vec![
        scene_case(
            "unknown_bytes",
            "s.bin",
            b"GIF89a\x01\x00".to_vec(),
            Error("is not a recognised scene format"),
        ),
        scene_case(
            "meta_json_alone",
            "meta.json",
            b"{\"version\": 2}".to_vec(),
            Error("has a SOG meta.json that is not valid"),
        ),
    ]
}

// ---------------------------------------------------------------------------------------
// Checks.

fn write_case(root: &Path, case: &Case) -> PathBuf {
    let dir = root.join(case.name);
    for (name, bytes) in &case.files {
        let p = dir.join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, bytes).unwrap();
    }
    dir.join(case.arg)
}

/// A camera looking at the origin from `(0, 0, -3)`, `W`x`H`.
fn test_camera() -> Camera {
    Camera::look_at(
        "t",
        W,
        H,
        50f32.to_radians(),
        glam::Vec3::new(0.0, 0.0, -3.0),
        glam::Vec3::ZERO,
        glam::Vec3::NEG_Y,
    )
}

/// A usable scene renders with finite values: the background for no Gaussians, otherwise
/// colour at the image centre where the splat(s) sit.
fn check_render(name: &str, s: &Scene) {
    let bg = [0.25, 0.5, 0.75];
    let frame = cpu::render(
        &s.activated(),
        &test_camera(),
        &RenderOptions {
            background: bg,
            ..Default::default()
        },
    );
    assert!(
        frame
            .color
            .iter()
            .flatten()
            .chain(&frame.alpha)
            .chain(&frame.depth)
            .all(|v| v.is_finite()),
        "{name}: non-finite pixels"
    );
    if s.is_empty() {
        assert!(
            frame.color.iter().all(|c| *c == bg),
            "{name}: not the background"
        );
        assert!(frame.alpha.iter().all(|&a| a == 0.0), "{name}: alpha");
    } else {
        let centre = (H / 2 * W + W / 2) as usize;
        assert!(
            frame.alpha[centre] > 0.3,
            "{name}: centre alpha {}",
            frame.alpha[centre]
        );
    }
}

/// An error must be one sentence that names the file and contains the fragment.
fn check_message(name: &str, msg: &str, file: &Path, fragment: &str) {
    assert!(!msg.contains('\n'), "{name}: more than one line: {msg}");
    let dir = file.parent().unwrap().to_string_lossy().into_owned();
    assert!(
        msg.contains(&dir) || msg.contains(&*file.to_string_lossy()),
        "{name}: does not name the file: {msg}"
    );
    assert!(
        msg.contains(fragment),
        "{name}: expected \"{fragment}\" in: {msg}"
    );
}

fn library_check(case: &Case, path: &Path) {
    let name = case.name;
    match case.kind {
        Kind::Scene => match (io::scene::load(path), &case.expect) {
            (Err(e), Expect::Error(frag)) => check_message(name, &e.to_string(), path, frag),
            (Ok(s), Expect::Renders(n)) => {
                assert_eq!(s.len(), *n, "{name}");
                s.check_consistent().unwrap();
                check_render(name, &s);
            }
            (Ok(s), Expect::Error(frag)) => {
                panic!("{name}: loaded {} Gaussians, expected \"{frag}\"", s.len())
            }
            (Err(e), Expect::Renders(_)) => panic!("{name}: {e}"),
        },
        Kind::Cameras => match (
            io::camera::load_camera_file(path, &PathTiming::default()),
            &case.expect,
        ) {
            (Err(e), Expect::Error(frag)) => check_message(name, &e.to_string(), path, frag),
            (Ok((cams, _)), Expect::Renders(n)) => {
                assert_eq!(cams.len(), *n, "{name}");
                for c in &cams {
                    c.validate().unwrap();
                }
            }
            (Ok((cams, _)), Expect::Error(frag)) => {
                panic!("{name}: loaded {} cameras, expected \"{frag}\"", cams.len())
            }
            (Err(e), Expect::Renders(_)) => panic!("{name}: {e}"),
        },
    }
}

/// Runs the binary with a timeout; returns (success, stderr).
fn run_cli(args: &[&std::ffi::OsStr], stderr_file: &Path) -> (bool, String) {
    let err = std::fs::File::create(stderr_file).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_verisplat"))
        .args(args)
        .env("VERISPLAT_VALIDATE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > CLI_TIMEOUT {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("verisplat {args:?} hung (killed after {CLI_TIMEOUT:?})");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (
        status.success(),
        std::fs::read_to_string(stderr_file).unwrap(),
    )
}

/// Renders through the CLI: a bad file fails cleanly with nothing written, a usable one
/// writes its frames.
fn cli_check(case_name: &str, kind: Kind, path: &Path, expect: &Expect, work: &Path) {
    let out_dir = work.join(format!("{case_name}.out"));
    std::fs::create_dir_all(&out_dir).unwrap();
    let (w, h) = (W.to_string(), H.to_string());
    let mut args: Vec<&std::ffi::OsStr> = vec!["render".as_ref()];
    match kind {
        Kind::Scene => args.push(path.as_os_str()),
        Kind::Cameras => args.extend(["--demo".as_ref(), "--cameras".as_ref(), path.as_os_str()]),
    }
    let out = out_dir.join("frame_{:05}.png");
    args.extend([
        "--cpu".as_ref(),
        "-q".as_ref(),
        "--width".as_ref(),
        w.as_ref(),
        "--height".as_ref(),
        h.as_ref(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    let (ok, stderr) = run_cli(&args, &work.join(format!("{case_name}.stderr")));
    assert!(
        !stderr.contains("panicked"),
        "{case_name}: the CLI panicked: {stderr}"
    );
    let written: Vec<_> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    match expect {
        Expect::Error(frag) => {
            assert!(!ok, "{case_name}: the CLI succeeded on a bad file");
            assert!(stderr.starts_with("error: "), "{case_name}: {stderr}");
            assert_eq!(
                stderr.trim_end().lines().count(),
                1,
                "{case_name}: one line: {stderr}"
            );
            assert!(
                stderr.contains(frag),
                "{case_name}: expected \"{frag}\" in: {stderr}"
            );
            assert!(
                written.is_empty(),
                "{case_name}: the failed run left {written:?}"
            );
        }
        Expect::Renders(n) => {
            assert!(ok, "{case_name}: {stderr}");
            let frames = if kind == Kind::Cameras { *n } else { 1 };
            assert_eq!(written.len(), frames, "{case_name}: wrote {written:?}");
            for f in &written {
                let img = image::open(out_dir.join(f)).unwrap();
                assert_eq!((img.width(), img.height()), (W, H), "{case_name}");
            }
        }
    }
}

#[test]
fn every_malformed_case_fails_clearly_or_renders_through_the_library() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("malformed");
    let cases = cases();
    let mut names = std::collections::HashSet::new();
    for case in &cases {
        assert!(names.insert(case.name), "duplicate case {}", case.name);
        let path = write_case(&root, case);
        library_check(case, &path);
    }
}

#[test]
fn every_malformed_case_fails_clearly_or_renders_through_the_cli() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("malformed");
    let work = tmp.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    for case in &cases() {
        let path = write_case(&root, case);
        cli_check(case.name, case.kind, &path, &case.expect, &work);
    }
}

// ---------------------------------------------------------------------------------------
// Truncation sweeps.

/// Small valid files of every scene format, with the loader's name for them.
fn valid_scene_files() -> Vec<(&'static str, Vec<u8>)> {
    let s = common::random_scene(5, 3, 11);
    let s0 = common::random_scene(3, 0, 12);
    vec![
        (
            "t.ply",
            io::scene::ply::to_bytes(&s, io::scene::ply::PlyEncoding::BinaryLittleEndian),
        ),
        (
            "t_be.ply",
            io::scene::ply::to_bytes(&s0, io::scene::ply::PlyEncoding::BinaryBigEndian),
        ),
        (
            "t_ascii.ply",
            io::scene::ply::to_bytes(&s0, io::scene::ply::PlyEncoding::Ascii),
        ),
        ("t.splat", io::scene::splat::to_bytes(&s)),
        ("t.spz", io::scene::spz::to_bytes_v3(&s).unwrap()),
        ("t_v4.spz", spz_v4(3, 3, 32, 0)),
        (
            "t.compressed.ply",
            cply("1", "3", &CHUNK_PROPS, "uint", good_bounds(), 3),
        ),
        ("t.sog", sog_zip(&good_sog_meta(), None)),
    ]
}

/// Fragments a truncated file's error may contain: each says the file is cut short or
/// is no longer recognisable as its format.
const TRUNCATION_FRAGMENTS: [&str; 10] = [
    "truncated",
    "is empty (0 bytes)",
    "header lies",
    "not a recognised scene format",
    "not a multiple of the 32-byte",
    "not a readable zip",
    "corrupt",
    "no end_header",
    "does not start with the SPZ magic",
    "non-numeric value",
];

fn truncation_ok(name: &str, cut: usize) -> bool {
    // A .splat cut at a record boundary is a valid, shorter .splat (and empty is empty).
    name.ends_with(".splat") && cut % 32 == 0
}

#[test]
fn truncated_scene_files_fail_clearly_at_every_offset() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, bytes) in valid_scene_files() {
        let full = tmp.path().join(name);
        std::fs::write(&full, &bytes).unwrap();
        io::scene::load(&full).unwrap_or_else(|e| panic!("the uncut {name} must load: {e}"));
        for cut in 0..bytes.len() {
            let path = tmp.path().join(format!("cut_{cut}_{name}"));
            std::fs::write(&path, &bytes[..cut]).unwrap();
            match io::scene::load(&path) {
                Ok(s) => assert!(
                    truncation_ok(name, cut),
                    "{name} cut at {cut} loaded {} Gaussians",
                    s.len()
                ),
                Err(e) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains(&*path.to_string_lossy()) && !msg.contains('\n'),
                        "{msg}"
                    );
                    assert!(
                        TRUNCATION_FRAGMENTS.iter().any(|f| msg.contains(f)),
                        "{name} cut at {cut}: unexpected message: {msg}"
                    );
                }
            }
            std::fs::remove_file(&path).unwrap();
        }
    }
}

#[test]
fn truncated_camera_files_fail_clearly_at_every_offset() {
    let json = [
        ("cameras.json", inria_json(64, "50", IDENTITY)),
        ("camera_path.json", nerfstudio("perspective", C2W, "50")),
        (
            "path.json",
            keyframes(1, ",\"frames\":2", &format!("{KEY0},{KEY1}")),
        ),
    ];
    let tmp = tempfile::tempdir().unwrap();
    for (name, text) in &json {
        for cut in 0..text.len() {
            let path = tmp.path().join(format!("cut_{cut}_{name}"));
            std::fs::write(&path, &text.as_bytes()[..cut]).unwrap();
            let e = io::camera::load_camera_file(&path, &PathTiming::default())
                .expect_err(&format!("{name} cut at {cut}"));
            let msg = e.to_string();
            assert!(
                msg.contains(&*path.to_string_lossy()) && !msg.contains('\n'),
                "{msg}"
            );
            assert!(
                msg.contains("not valid JSON") || msg.contains("EOF"),
                "{name} cut at {cut}: {msg}"
            );
        }
    }
    // COLMAP binary: cut either file anywhere.
    let (c, i) = colmap_bin(1, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
    for which in 0..2 {
        let full = if which == 0 { &c } else { &i };
        for cut in 0..full.len() {
            let dir = tmp.path().join(format!("bin_{which}_{cut}"));
            std::fs::create_dir_all(&dir).unwrap();
            let (cc, ii) = if which == 0 {
                (&c[..cut], &i[..])
            } else {
                (&c[..], &i[..cut])
            };
            std::fs::write(dir.join("cameras.bin"), cc).unwrap();
            std::fs::write(dir.join("images.bin"), ii).unwrap();
            let e = io::camera::load_camera_file(&dir, &PathTiming::default())
                .expect_err(&format!("COLMAP binary file {which} cut at {cut}"));
            let msg = e.to_string();
            assert!(
                msg.contains("truncated") || msg.contains("claims"),
                "file {which} cut at {cut}: {msg}"
            );
        }
    }
}

#[test]
fn truncated_scene_files_fail_cleanly_through_the_cli() {
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    for (name, bytes) in valid_scene_files() {
        let len = bytes.len();
        let mut cuts = vec![0, 1, 3, 7, 16, len / 3, len / 2, len - 1];
        cuts.sort();
        cuts.dedup();
        for cut in cuts {
            if truncation_ok(name, cut) {
                continue;
            }
            let case = format!("cut_{cut}_{name}");
            let path = tmp.path().join(&case);
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let msg = io::scene::load(&path).expect_err(&case).to_string();
            let frag = TRUNCATION_FRAGMENTS
                .iter()
                .find(|f| msg.contains(*f))
                .unwrap();
            cli_check(&case, Kind::Scene, &path, &Expect::Error(frag), &work);
        }
    }
}
