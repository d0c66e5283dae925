//! Camera paths with two frames in flight (`render --frames-in-flight 2`, the default):
//! frame n+1 is recorded and submitted before frame n is read back. The files equal those
//! of one frame at a time and of frames rendered on their own, also when a frame in the
//! middle of the path needs far more tile/Gaussian pairs than the frames before it (its
//! buffers regrow while the other frame is in flight); pipelined frames match the CPU
//! reference; an error mid-path names its frame and leaves only complete files.
//! Lavapipe with the validation layer on (any message fails).

use crate::common;
use crate::common::cli::{ok_stderr, s, verisplat};
use crate::common::gpu::{assert_validation_clean, compare, new_renderer, Thresholds};
use crate::common::{orbit_path, PLAYBOT_ORBIT};
use std::collections::BTreeMap;
use std::path::Path;
use verisplat::app::sequence::{
    self, Existing, FrameSource, OutputPattern, ProgressStyle, RunOptions,
};
use verisplat::core::camera::Camera;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;

use verisplat::io::output::{self, OutputOptions};

use verisplat::render::frame::path::GpuPath;
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};

/// Every file of a directory with its bytes, by name.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect()
}

fn assert_same_files(a: &Path, b: &Path, frames: usize) {
    let (fa, fb) = (files(a), files(b));
    assert_eq!(fa.len(), frames, "{}", a.display());
    assert_eq!(
        fa.keys().collect::<Vec<_>>(),
        fb.keys().collect::<Vec<_>>(),
        "{} vs {}",
        a.display(),
        b.display()
    );
    for (name, bytes) in &fa {
        assert!(
            bytes == &fb[name],
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

#[test]
fn two_frames_in_flight_write_the_files_of_one_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::shared_data().join("playbot_lod3_31k_sh2.ply");
    for ext in ["png", "exr"] {
        for depth in ["1", "2"] {
            let out = dir.path().join(format!("{ext}{depth}"));
            let e = ok_stderr(&[
                "render",
                s(&scene),
                "--orbit",
                "6",
                "--width",
                "160",
                "-o",
                s(&out.join(format!("{{:02}}.{ext}"))),
                "--frames-in-flight",
                depth,
                "-q",
                "-v",
            ]);
            // Two frames in flight hold two sets of per-frame buffers, and say so.
            let memory = e
                .lines()
                .find(|l| l.starts_with("device memory:"))
                .unwrap_or_else(|| panic!("no memory line in {e}"));
            let want = if depth == "2" {
                "(2 frames in flight, a set each)"
            } else {
                "(one frame in flight)"
            };
            assert!(memory.ends_with(want), "{memory}");
        }
        assert_same_files(
            &dir.path().join(format!("{ext}1")),
            &dir.path().join(format!("{ext}2")),
            6,
        );
    }
    // The option is the Vulkan pipeline's.
    let o = verisplat(&[
        "render",
        "--demo",
        "--cpu",
        "--frames-in-flight",
        "2",
        "-o",
        s(&dir.path().join("cpu.png")),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("--frames-in-flight applies to the Vulkan pipeline"),
        "{e}"
    );
    let o = verisplat(&["render", "--demo", "--frames-in-flight", "3"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("must be between 1 and 2"),
        "{e}"
    );
}

/// 600 large, faint Gaussians in front of the camera at the origin: seen from close by,
/// each covers the whole 320x180 frame (hundreds of thousands of pairs, beyond the initial
/// key capacity); seen from 300 units back, a few bins.
fn crowd() -> Scene {
    let mut s = Scene::empty(0);
    for k in 0..600 {
        let t = k as f32 / 600.0;
        common::push_gaussian(
            &mut s,
            [0.3 * (t * 17.0).sin(), 0.2 * (t * 11.0).cos(), 3.0 + t],
            4.0,
            0.02,
            [t, 0.5 - 0.4 * t, 0.2 + 0.6 * t],
        );
    }
    s
}

fn crowd_path() -> Vec<(usize, Camera)> {
    let near = common::axis_camera(300.0)
        .with_resolution(320, 180)
        .unwrap();
    let mut far = near.clone();
    far.translation = glam::Vec3::new(0.0, 0.0, 300.0);
    // Frames 2 and 3 need far more pairs than 0 and 1: frame 2 regrows while frame 3 is
    // in flight with buffers sized before the regrow, so frame 3 regrows as well.
    [&far, &far, &near, &near, &far, &near]
        .into_iter()
        .enumerate()
        .map(|(k, c)| {
            let mut c = c.clone();
            c.name = format!("c{k}");
            (k, c)
        })
        .collect()
}

/// Renders `cams` with `run_pipelined` into `dir` as `ext` files, `depth` frames in
/// flight; returns each frame's regrow count.
fn run_path(
    r: &mut GpuRenderer,
    gs: &verisplat::render::GpuScene,
    cams: &[(usize, Camera)],
    dir: &Path,
    ext: &str,
    depth: usize,
) -> Vec<u32> {
    let pattern = OutputPattern::parse(&dir.join(format!("{{}}.{ext}")), "png").unwrap();
    let plan = sequence::plan(
        cams,
        &pattern,
        None,
        &OutputOptions::default(),
        Existing::Refuse,
    )
    .unwrap();
    let mut regrows = Vec::new();
    let opts = RenderOptions::default();
    let mut source = GpuPath::new(r, gs, &opts, depth).on_frame(|_, st| regrows.push(st.regrows));
    let summary = sequence::run_pipelined(
        &plan.frames,
        &mut source,
        &RunOptions {
            frames_in_flight: depth,
            progress: ProgressStyle::Quiet,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.written, cams.len());
    drop(source);
    regrows
}

#[test]
fn a_frame_that_regrows_while_another_is_in_flight_gives_the_same_files() {
    let act = crowd().activated();
    let cams = crowd_path();
    let dir = tempfile::tempdir().unwrap();
    let mut regrows = BTreeMap::new();
    for depth in [1, 2] {
        // A fresh renderer per run: the key buffers start at their initial size.
        let mut r = new_renderer(None);
        let gs = r.upload(&act).unwrap();
        for ext in ["png", "exr"] {
            let out = dir.path().join(format!("{ext}{depth}"));
            std::fs::create_dir(&out).unwrap();
            let g = run_path(&mut r, &gs, &cams, &out, ext, depth);
            regrows.insert((depth, ext), g);
        }
        assert_eq!(r.frame_sets(), depth);
        assert_eq!(r.frames_in_flight(), 0);
        assert_validation_clean(&r);
    }
    // Pipelined: frame 2 regrows, and frame 3, submitted before frame 2's regrow, too;
    // afterwards both sets are large enough.
    let piped = &regrows[&(2, "png")];
    assert!(piped[2] >= 1 && piped[3] >= 1, "{piped:?}");
    assert_eq!(piped[5], 0, "{piped:?}");
    assert!(regrows[&(1, "png")][2] >= 1, "{regrows:?}");
    for ext in ["png", "exr"] {
        assert_same_files(
            &dir.path().join(format!("{ext}1")),
            &dir.path().join(format!("{ext}2")),
            cams.len(),
        );
    }
    // Each frame rendered on its own, by a renderer that has not seen the others.
    let single = dir.path().join("single");
    std::fs::create_dir(&single).unwrap();
    for (k, cam) in &cams {
        let mut r = new_renderer(None);
        let gs = r.upload(&act).unwrap();
        let frame = r
            .render(&FrameRequest::new(&gs, cam, &RenderOptions::default()))
            .and_then(Rendered::into_frame)
            .unwrap();
        for ext in ["png", "exr"] {
            let path = single.join(format!("{k}.{ext}"));
            for spec in output::plan_files(&path, Some(cam), &OutputOptions::default()).unwrap() {
                output::write_file(&frame, &spec, false).unwrap();
            }
            let piped = std::fs::read(dir.path().join(format!("{ext}2/{k}.{ext}"))).unwrap();
            assert!(std::fs::read(&path).unwrap() == piped, "frame {k} {ext}");
        }
        assert_validation_clean(&r);
    }
}

#[test]
fn pipelined_frames_match_the_cpu_reference() {
    let act = io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply"))
        .unwrap()
        .activated();
    let cams = orbit_path(PLAYBOT_ORBIT, 5, 160, 90);
    let opts = RenderOptions::default();
    let mut r = new_renderer(None);
    let gs = r.upload(&act).unwrap();
    let mut frames = Vec::new();
    let mut timings = Vec::new();
    {
        let mut path = GpuPath::new(&mut r, &gs, &opts, 2).on_frame(|t, _| timings.push(t.clone()));
        // Two in flight at every step: frame k+1 is submitted before frame k finishes.
        path.submit(&cams[0]).unwrap();
        for cam in &cams[1..] {
            path.submit(cam).unwrap();
            assert!(
                path.submit(cam).is_err(),
                "a third frame in flight is refused"
            );
            frames.push(path.finish().unwrap().into_float().unwrap());
        }
        frames.push(path.finish().unwrap().into_float().unwrap());
        assert!(path.finish().is_err(), "nothing left in flight");
    }
    assert_eq!(r.frame_sets(), 2);
    for (k, (g, cam)) in frames.iter().zip(&cams).enumerate() {
        let c = cpu::render(&act, cam, &opts);
        let cmp = compare(g, &c);
        assert!(cmp.meets(&Thresholds::COLOUR), "frame {k}: {cmp:?}");
        // Each frame read its own timestamps.
        let t = &timings[k];
        assert!(
            t.total > 0.0 && t.blend > 0.0 && t.total >= t.blend,
            "frame {k}: {t:?}"
        );
    }
    // The single-frame API still works after pipelined frames, and agrees bit for bit.
    let again = r
        .render(&FrameRequest::new(&gs, &cams[2], &opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(again, frames[2]);
    assert_validation_clean(&r);
}

/// Pipelined feature frames equal the unpipelined ones (each frame its own feature
/// images).
#[test]
fn pipelined_feature_frames_equal_unpipelined_ones() {
    let mut s = io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply")).unwrap();
    let n = s.len();
    let values: Vec<f32> = (0..n * 5)
        .map(|i| ((i * 37) % 101) as f32 / 50.0 - 1.0)
        .collect();
    s.set_features(5, values).unwrap();
    let act = s.activated();
    let cams = orbit_path(PLAYBOT_ORBIT, 3, 96, 54);
    let opts = RenderOptions::default();
    let mut r = new_renderer(None);
    let gs = r.upload(&act).unwrap();
    let gf = r.upload_features(&act).unwrap();
    let single: Vec<_> = cams
        .iter()
        .map(|c| {
            r.render(&FrameRequest::new(&gs, c, &opts).features(&gf))
                .and_then(Rendered::into_frame)
                .unwrap()
        })
        .collect();
    let mut piped = Vec::new();
    {
        let mut path = GpuPath::new(&mut r, &gs, &opts, 2).with_features(&gf, None);
        path.submit(&cams[0]).unwrap();
        for cam in &cams[1..] {
            path.submit(cam).unwrap();
            piped.push(path.finish().unwrap().into_float().unwrap());
        }
        piped.push(path.finish().unwrap().into_float().unwrap());
    }
    for (k, (a, b)) in single.iter().zip(&piped).enumerate() {
        assert_eq!(a.feature_count, 5);
        assert!(a == b, "frame {k}");
        let c = cpu::render_features(&act, &cams[k], &opts);
        let cmp = compare(b, &c);
        assert!(cmp.meets(&Thresholds::COLOUR), "frame {k}: {cmp:?}");
    }
    assert_validation_clean(&r);
}

/// A frame that fails mid-path, while the next frame is in flight: the error names it,
/// the frames before it are complete on disk, and nothing else is (no frame after it, no
/// temporary file). Frame 3 needs far more pairs than the frames before it, and the key
/// buffers it would regrow to exceed --memory-limit, so it fails when it is finished,
/// with frame 4 in flight.
#[test]
fn an_error_mid_path_names_its_frame_and_leaves_only_complete_files() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("crowd.ply");
    std::fs::write(
        &ply,
        io::scene::ply::to_bytes(&crowd(), io::scene::ply::PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    let path = crowd_path();
    let (far, near) = (&path[0].1, &path[2].1);
    let cams: Vec<(usize, Camera)> = [far, far, far, near, far, far]
        .into_iter()
        .cloned()
        .enumerate()
        .collect();
    let json = dir.path().join("cams.json");
    std::fs::write(&json, io::camera::inria::to_json(&cams).unwrap()).unwrap();
    for depth in ["1", "2"] {
        let out = dir.path().join(format!("out{depth}"));
        let o = verisplat(&[
            "render",
            s(&ply),
            "--cameras",
            s(&json),
            "-o",
            s(&out.join("{}.exr")),
            "--memory-limit",
            "12M",
            "--frames-in-flight",
            depth,
            "--encode-threads",
            "1",
        ]);
        let last = common::cli::failure_last_line(&o);
        assert!(
            last.starts_with("error: frame 3: out of device memory")
                && last.contains("3 frame(s) written before it are complete"),
            "depth {depth}: {last}"
        );
        let names: Vec<String> = files(&out).into_keys().collect();
        assert_eq!(names, ["0.exr", "1.exr", "2.exr"], "depth {depth}");
        for n in &names {
            exr::prelude::read_all_data_from_file(out.join(n)).unwrap();
        }
    }
    assert_same_files(&dir.path().join("out1"), &dir.path().join("out2"), 3);
}
