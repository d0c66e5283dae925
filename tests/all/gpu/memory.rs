//! Long runs: a 1000-frame camera path rendered and written in one process keeps host and
//! device memory flat, and its files equal frames rendered one per process. The test runs
//! itself in a process of its own (the test binary again, filtered to this one test) so
//! that no other test allocates in the process while resident memory is measured.

use crate::common;
use std::path::Path;
use std::process::Command;
use verisplat::app::sequence::{self, Existing, OutputPattern, ProgressStyle, RunOptions};
use verisplat::core::camera;
use verisplat::core::camera::OrbitParams;
use verisplat::cpu::RenderOptions;

use verisplat::io::output::OutputOptions;
use verisplat::render::{FrameRequest, Rendered};

fn resident_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: u64 = statm
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    pages * 4096
}

/// Set for the process the test starts: there it measures.
const CHILD: &str = "VERISPLAT_MEMORY_TEST_CHILD";

#[test]
fn a_thousand_frame_path_keeps_memory_flat_and_matches_one_frame_per_process() {
    if std::env::var_os(CHILD).is_some() {
        thousand_frame_path();
        return;
    }
    // The test's name as the harness knows it: the module path without the crate name.
    let name = concat!(
        module_path!(),
        "::a_thousand_frame_path_keeps_memory_flat_and_matches_one_frame_per_process"
    );
    let name = name.split_once("::").map_or(name, |(_, rest)| rest);
    let o = Command::new(std::env::current_exe().unwrap())
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .output()
        .unwrap();
    let (out, err) = (common::cli::stdout(&o), common::cli::stderr(&o));
    eprintln!("{err}");
    assert!(
        o.status.success(),
        "the test in its own process failed:\n{out}\n{err}"
    );
    assert!(
        out.contains("test result: ok. 1 passed"),
        "the test did not run in its own process:\n{out}"
    );
}

fn thousand_frame_path() {
    let frames: usize = std::env::var("VERISPLAT_MEMORY_TEST_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("long");
    let scene = verisplat::io::demo::demo_scene();
    // The path `verisplat render --demo --orbit N --width 64` renders.
    let cams: Vec<(usize, camera::Camera)> = camera::orbit(
        &scene.positions,
        &OrbitParams {
            frames,
            ..Default::default()
        },
    )
    .unwrap()
    .into_iter()
    .map(|c| c.resized(Some(64), None, None).unwrap())
    .enumerate()
    .collect();
    let pattern = OutputPattern::parse(&out.join("{:04}.png"), "png").unwrap();
    let plan = sequence::plan(
        &cams,
        &pattern,
        None,
        &OutputOptions::default(),
        Existing::Refuse,
    )
    .unwrap();
    let mut r = common::gpu::new_renderer(None);
    let gs = r.upload(&scene.activated()).unwrap();
    let mut samples = Vec::new();
    let mut rendered = 0usize;
    let mut render = |cam: &camera::Camera| {
        let f = r
            .render(&FrameRequest::new(&gs, cam, &RenderOptions::default()))
            .and_then(Rendered::into_frame)?;
        rendered += 1;
        if rendered % 100 == 0 {
            samples.push((
                rendered,
                resident_bytes(),
                r.frame_device_bytes(),
                r.ctx().live_allocations(),
            ));
        }
        Ok(f)
    };
    let summary = sequence::run(
        &plan.frames,
        &mut render,
        &RunOptions {
            progress: ProgressStyle::Quiet,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.written, frames);
    eprintln!("(frame, resident bytes, per-frame device bytes, live allocations): {samples:?}");
    let first = samples[0];
    let last = *samples.last().unwrap();
    assert_eq!(last.2, first.2, "device buffers grew");
    assert_eq!(last.3, first.3, "gpu-allocator allocations grew");
    // Allow 2 MiB of allocator and driver noise between frame 100 and the last (measured:
    // tens of KiB; before the frame slot was reused, 10 KiB per frame, i.e. 9 MB here).
    assert!(
        last.1 <= first.1 + 2 * 1024 * 1024,
        "host memory grew from {} to {} bytes",
        first.1,
        last.1
    );
    common::gpu::assert_validation_clean(&r);
    drop(r);

    // Frames rendered one per process are the same files.
    let single = dir.path().join("single");
    let n = frames.to_string();
    for k in [0, frames / 2, frames - 1] {
        let o = Command::new(env!("CARGO_BIN_EXE_verisplat"))
            .args(["render", "--demo", "--orbit", &n, "--width", "64", "-q"])
            .args(["--frames", &k.to_string(), "-o"])
            .arg(single.join("{:04}.png"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let name = format!("{k:04}.png");
        let a = std::fs::read(out.join(&name)).unwrap();
        let b = std::fs::read(single.join(&name)).unwrap();
        assert!(
            a == b,
            "frame {k} differs between the long run and its own process"
        );
    }
    assert!(Path::new(&out.join(format!("{:04}.png", frames - 1))).exists());
}
