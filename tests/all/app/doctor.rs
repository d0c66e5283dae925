//! `verisplat doctor`: it passes on this device (lavapipe in CI) with its JSON report saying
//! so, and it fails loudly (non-zero exit, a FAIL line naming the check) when a kernel is
//! broken: the shaders are compiled at run time from a copy of `glsl/` with one line
//! changed (`VERISPLAT_GLSL_DIR`).

use crate::common::cli::{command, s, stderr, stdout};
use std::path::Path;
use std::process::Output;

/// A copy of `glsl/` (its wings' folders) in a temporary directory with `file`'s `from`
/// replaced by `to` (which must occur in it).
fn broken_glsl(file: &str, edits: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let glsl = Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
    let (_, folders) = verisplat::gpu::shader_set::glsl_tree(&glsl).expect("glsl/");
    let mut edited = false;
    for folder in folders {
        let copy = dir
            .path()
            .join(folder.strip_prefix(&glsl).expect("inside glsl/"));
        std::fs::create_dir_all(&copy).expect("a folder of the copy");
        for entry in std::fs::read_dir(&folder).expect("a folder of glsl/") {
            let path = entry.expect("an entry").path();
            if path.is_dir() {
                continue;
            }
            let name = path.file_name().expect("a name");
            let mut text = std::fs::read_to_string(&path).expect("a shader");
            if name == file {
                for (from, to) in edits {
                    assert!(text.contains(from), "{file} no longer contains {from:?}");
                    text = text.replace(from, to);
                }
                edited = true;
            }
            std::fs::write(copy.join(name), text).expect("write the copy");
        }
    }
    assert!(edited, "no {file} under glsl/");
    dir
}

fn doctor(args: &[&str], glsl_dir: Option<&Path>) -> Output {
    let mut c = command();
    c.arg("doctor").args(args);
    if let Some(dir) = glsl_dir {
        c.env("VERISPLAT_GLSL_DIR", dir);
    }
    c.output().expect("the binary runs")
}

#[test]
fn doctor_passes_here_and_its_json_says_so() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let json = dir.path().join("doctor.json");
    let o = doctor(&["--json", s(&json)], None);
    let (out, err) = (stdout(&o), stderr(&o));
    assert!(o.status.success(), "doctor failed:\n{out}\n{err}");
    assert!(out.contains("doctor: all "), "{out}");
    for name in [
        "subgroups",
        "render",
        "sort64",
        "sort32",
        "scan",
        "backward",
    ] {
        assert!(
            out.lines()
                .any(|l| l.trim_start().starts_with(name) && l.ends_with("PASS")),
            "no PASS line for {name}:\n{out}"
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the JSON report"))
            .expect("the report parses");
    assert_eq!(report["passed"], true);
    assert!(!report["devices"].as_array().expect("devices").is_empty());
    let runs = report["runs"].as_array().expect("runs");
    assert!(!runs.is_empty());
    for run in runs {
        let checks = run["checks"].as_array().expect("checks");
        // The validation layer is on (common::cli::command): its check is there too.
        assert!(checks.iter().any(|c| c["name"] == "validation"), "{run}");
        for c in checks {
            assert_eq!(c["passed"], true, "{c}");
            assert!(c["threshold"].is_string() && c["figure"].is_string(), "{c}");
        }
        // The render check says whether the device reproduces the CPU reference bit for
        // bit, and where it first does not when it does not.
        let render = checks
            .iter()
            .find(|c| c["name"] == "render")
            .expect("render");
        let note = render["note"].as_str().expect("the render check's note");
        assert!(
            note.starts_with("bit for bit: yes")
                || (note.starts_with("bit for bit: no, first in ")
                    && (note.contains("preprocess (") || note.contains("in blend;"))),
            "{note}"
        );
        // And whether it does in the reproducible mode.
        assert!(
            note.contains("; with --reproducible: yes")
                || note.contains("; with --reproducible: no, first in "),
            "{note}"
        );
        assert!(out.contains(note), "{out}");
    }
}

/// A failing run: non-zero exit, one error sentence last, and a FAIL line for `check`.
fn assert_fails_naming(o: &Output, check: &str) {
    let (out, err) = (stdout(o), stderr(o));
    assert!(!o.status.success(), "doctor passed:\n{out}\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        out.lines()
            .any(|l| l.trim_start().starts_with(check) && l.ends_with("FAIL")),
        "no FAIL line for {check}:\n{out}"
    );
    assert!(
        out.lines()
            .any(|l| l.starts_with("doctor: ") && l.contains("FAILED") && l.contains(check)),
        "no verdict naming {check}:\n{out}"
    );
    let last = err.trim_end().lines().last().unwrap_or_default();
    assert!(last.starts_with("error: the self-check failed"), "{err}");
}

#[test]
fn doctor_fails_on_a_sort_that_writes_to_the_wrong_slot() {
    // Every pass's element 0 lands on slot 1 (and slot 0 keeps stale data).
    let glsl = broken_glsl(
        "sort_scatter.comp",
        &[
            ("int(dst)", "int(max(dst, 1u))"),
            ("keys_out[dst]", "keys_out[max(dst, 1u)]"),
            ("values_out[dst]", "values_out[max(dst, 1u)]"),
        ],
    );
    // Only the sorts: the run-time compiles of every other kernel would take longer.
    let o = doctor(
        &["--device", "0", "--checks", "sort64,sort32"],
        Some(glsl.path()),
    );
    assert_fails_naming(&o, "sort64");
    assert_fails_naming(&o, "sort32");
}

#[test]
fn doctor_fails_on_a_blend_that_swaps_colour_channels() {
    let glsl = broken_glsl(
        "blend.comp",
        &[(
            "vec4(C + T * params.background.rgb, a)",
            "vec4(C.bgr + T * params.background.rgb, a)",
        )],
    );
    let o = doctor(&["-q", "--checks", "render"], Some(glsl.path()));
    assert_fails_naming(&o, "render");
}

/// `tools/gpu_bundle.sh --bin` packs the binary this suite built (no release build), and
/// the bundle's `run.sh` runs in a clean environment (no cargo or rustc on PATH, a fresh
/// HOME) with `SMOKE=1` (doctor, one comparison, one bench frame), writing a report that
/// names the device and says doctor passed.
#[test]
fn the_gpu_bundle_runs_in_a_clean_environment() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    assert!(
        repo.join("../shared/data/playbot_lod3_31k_sh2.ply")
            .exists(),
        "the shared scenes (../shared/data) are needed to make a bundle"
    );
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let bundle = tmp.path().join("bundle");
    let made = std::process::Command::new("bash")
        .arg(repo.join("tools/gpu_bundle.sh"))
        .arg(&bundle)
        .args(["--bin", crate::common::cli::bin()])
        .output()
        .expect("bash runs");
    assert!(made.status.success(), "gpu_bundle.sh: {}", stderr(&made));
    let bytes: u64 = walk(&bundle);
    assert!(bytes <= 60 << 20, "the bundle is {bytes} bytes");
    let home = tmp.path().join("home");
    std::fs::create_dir_all(&home).expect("a home");
    let report = tmp.path().join("report.md");
    let run = std::process::Command::new("env")
        .args(["-i", "PATH=/usr/bin:/bin", "SMOKE=1"])
        .arg(format!("HOME={}", home.display()))
        .arg(bundle.join("run.sh"))
        .arg(&report)
        .output()
        .expect("run.sh runs");
    let md = std::fs::read_to_string(&report).unwrap_or_default();
    assert!(run.status.success(), "run.sh: {}\n{md}", stderr(&run));
    for needed in [
        "# verisplat on ",
        "**Doctor: every check passed.**",
        "| playbot_lod3_31k_sh2.spz | 1 |",
        "Every step succeeded.",
        // The bench's pairs (issue 60): sorted, per visible Gaussian, how many can draw.
        "| scene | Gaussians | resolution | pairs sorted | per visible Gaussian | sorted / can draw |",
        // Bytes per stage (issue 60, items 3 and 5), and the bandwidth they make.
        "| scene | Gaussians | resolution | preprocess | order | scan | keys | sort | ranges | blend | readback |",
        " GB/s |",
    ] {
        assert!(md.contains(needed), "the report lacks {needed:?}:\n{md}");
    }
}

fn walk(p: &Path) -> u64 {
    match std::fs::read_dir(p) {
        Ok(entries) => entries.flatten().map(|e| walk(&e.path())).sum(),
        Err(_) => std::fs::metadata(p).map_or(0, |m| m.len()),
    }
}
