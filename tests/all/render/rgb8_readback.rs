//! "Read back what the output needs": a run whose every output is 8-bit colour (RGB PNGs,
//! a video) reads back only the colour packed to 8-bit RGBA on the device, and writes the
//! same bytes as the float readback quantised on the host: PNG files byte for byte, and
//! the frames a video's encoder is fed. Which outputs take the 8-bit readback
//! (`sequence::reads_rgb8_only`), and that an 8-bit frame refuses the files that need floats.
//! Lavapipe with the validation layer on (any message fails).

use crate::common;
use crate::common::cli::{s, stderr, verisplat_env};
use crate::common::gpu::{assert_validation_clean, new_renderer};
use crate::common::{orbit_path, PLAYBOT_ORBIT};
use std::path::Path;
use std::sync::{Arc, Mutex};
use verisplat::app::sequence::{
    self, Existing, FramePlan, FrameSink, OutputPattern, ProgressStyle, RunOptions,
};
use verisplat::core::camera::Camera;
use verisplat::core::frame::{FramePixels, Rgba8Frame};
use verisplat::core::scene::Scene;
use verisplat::cpu::RenderOptions;
use verisplat::io;
use verisplat::io::output::{self, OutputError, OutputOptions, RenderMode};

use verisplat::render::frame::path::GpuPath;
use verisplat::render::{GpuRenderer, GpuScene};

/// Every file of a directory with its bytes, by name.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut f: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            (name, std::fs::read(e.path()).unwrap())
        })
        .collect();
    f.sort();
    f
}

/// The plan of `cams` written to `dir/{}.<ext>` with `opts`.
fn plan(cams: &[Camera], dir: &Path, ext: &str, opts: &OutputOptions) -> Vec<FramePlan> {
    let pattern = OutputPattern::parse(&dir.join(format!("{{}}.{ext}")), "png").unwrap();
    let cams: Vec<(usize, Camera)> = cams.iter().cloned().enumerate().collect();
    sequence::plan(&cams, &pattern, None, opts, Existing::Refuse)
        .unwrap()
        .frames
}

/// Runs `frames` through `run_pipelined` on the device, two frames in flight, reading
/// back 8-bit colour (`rgb8`) or floats, with `sink` taking the frames when given.
fn run(
    r: &mut GpuRenderer,
    gs: &GpuScene,
    opts: &RenderOptions,
    frames: &[FramePlan],
    rgb8: bool,
    sink: Option<Arc<dyn FrameSink>>,
) {
    let mut source = GpuPath::new(r, gs, opts, 2).rgb8(rgb8);
    let summary = sequence::run_pipelined(
        frames,
        &mut source,
        &RunOptions {
            frames_in_flight: 2,
            progress: ProgressStyle::Quiet,
            sink,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.written, frames.len());
}

/// Bright and dark Gaussians over a grey background: colours above 1 and below 0 (the
/// clamps of the quantisation), at an odd size (partial workgroups at the edges).
fn clamped_scene() -> Scene {
    let mut s = Scene::empty(0);
    for k in 0..40 {
        let t = k as f32 / 40.0;
        common::push_gaussian(
            &mut s,
            [0.8 * (t * 13.0).sin(), 0.6 * (t * 7.0).cos(), 3.0 + t],
            0.15 + 0.2 * t,
            0.3 + 0.6 * t,
            [3.0 * t, 1.5 - 2.5 * t, 0.5],
        );
    }
    s
}

/// The test scenes with a path each: the shared PLAYBOT (LOD3) on its orbit over a
/// coloured background, and [`clamped_scene`] from the axis camera, both at odd sizes.
fn scenes() -> Vec<(Scene, Vec<Camera>, RenderOptions)> {
    let playbot = io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply")).unwrap();
    let axis = common::axis_camera(60.0).with_resolution(97, 61).unwrap();
    let mut moved = axis.clone();
    moved.translation = glam::Vec3::new(0.2, -0.1, 0.5);
    vec![
        (
            playbot,
            orbit_path(PLAYBOT_ORBIT, 4, 161, 121),
            RenderOptions {
                background: [0.25, 0.5, 0.75],
                ..Default::default()
            },
        ),
        (
            clamped_scene(),
            vec![axis, moved],
            RenderOptions {
                background: [0.5, 0.5, 0.5],
                ..Default::default()
            },
        ),
    ]
}

#[test]
fn rgb_pngs_read_back_as_8_bit_colour_equal_those_of_the_float_readback() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = new_renderer(None);
    for (k, (scene, cams, opts)) in scenes().into_iter().enumerate() {
        let gs = r.upload(&scene.activated()).unwrap();
        let (float_dir, rgb8_dir) = (
            dir.path().join(format!("float{k}")),
            dir.path().join(format!("rgb8{k}")),
        );
        for (out, rgb8) in [(&float_dir, false), (&rgb8_dir, true)] {
            std::fs::create_dir(out).unwrap();
            let frames = plan(&cams, out, "png", &OutputOptions::default());
            assert!(sequence::reads_rgb8_only(&frames));
            run(&mut r, &gs, &opts, &frames, rgb8, None);
        }
        let (a, b) = (files(&float_dir), files(&rgb8_dir));
        assert_eq!(a.len(), cams.len());
        assert_eq!(
            a.iter().map(|f| &f.0).collect::<Vec<_>>(),
            b.iter().map(|f| &f.0).collect::<Vec<_>>()
        );
        for ((name, x), (_, y)) in a.iter().zip(&b) {
            assert!(x == y, "scene {k}: {name} differs between the readbacks");
        }
    }
    assert_validation_clean(&r);
}

/// A sink that keeps the 8-bit RGB of each frame it takes: what the video writer feeds
/// ffmpeg ([`output::rgb8`]).
#[derive(Debug, Default)]
struct Captured(Mutex<Vec<Fed>>);

/// One frame a [`Captured`] sink took.
#[derive(Debug)]
struct Fed {
    size: (u32, u32),
    rgb: Vec<u8>,
    /// It came packed from the device.
    packed: bool,
}

impl FrameSink for Captured {
    fn write(&self, frame: &FramePixels) -> Result<(), OutputError> {
        self.0.lock().unwrap().push(Fed {
            size: frame.size(),
            rgb: output::rgb8(frame),
            packed: matches!(frame, FramePixels::Rgba8(_)),
        });
        Ok(())
    }
}

#[test]
fn a_video_is_fed_the_same_8_bit_frames_by_both_readbacks() {
    let mut r = new_renderer(None);
    for (scene, cams, opts) in scenes() {
        let gs = r.upload(&scene.activated()).unwrap();
        // A video's frames have no files of their own.
        let frames: Vec<FramePlan> = cams
            .iter()
            .enumerate()
            .map(|(index, c)| FramePlan {
                index,
                camera: c.clone(),
                files: Vec::new(),
            })
            .collect();
        assert!(sequence::reads_rgb8_only(&frames));
        let mut fed = Vec::new();
        for rgb8 in [false, true] {
            let sink = Arc::new(Captured::default());
            run(&mut r, &gs, &opts, &frames, rgb8, Some(sink.clone()));
            let got = std::mem::take(&mut *sink.0.lock().unwrap());
            assert!(
                got.iter().all(|f| f.packed == rgb8),
                "the sink gets what was read back"
            );
            fed.push(got);
        }
        assert_eq!(fed[0].len(), cams.len());
        for (k, (a, b)) in fed[0].iter().zip(&fed[1]).enumerate() {
            assert_eq!(a.size, b.size);
            assert_eq!(a.rgb.len(), (a.size.0 * a.size.1 * 3) as usize);
            assert!(a.rgb == b.rgb, "frame {k} fed to the encoder differs");
        }
    }
    assert_validation_clean(&r);
}

#[test]
fn only_runs_whose_every_output_is_8_bit_colour_read_back_8_bits() {
    let cams = orbit_path(PLAYBOT_ORBIT, 2, 32, 24);
    let dir = Path::new("unwritten");
    let with = |mode: Option<RenderMode>, png16: bool| OutputOptions {
        mode,
        png16,
        ..Default::default()
    };
    let eight_bit =
        |ext: &str, opts: OutputOptions| sequence::reads_rgb8_only(&plan(&cams, dir, ext, &opts));
    assert!(eight_bit("png", with(None, false)));
    assert!(eight_bit("png", with(Some(RenderMode::Rgb), false)));
    // 16 bits, straight colour and alpha, alpha, depth, colour with its depth beside it,
    // floats, features.
    assert!(!eight_bit("png", with(None, true)));
    assert!(!eight_bit("png", with(Some(RenderMode::Rgba), false)));
    assert!(!eight_bit("png", with(Some(RenderMode::Alpha), false)));
    assert!(!eight_bit("png", with(Some(RenderMode::Depth), false)));
    assert!(!eight_bit("png", with(Some(RenderMode::RgbDepth), false)));
    assert!(!eight_bit("png", with(Some(RenderMode::Normal), false)));
    assert!(!eight_bit("exr", with(None, false)));
    assert!(!eight_bit("exr", with(Some(RenderMode::Rgb), false)));
    assert!(!eight_bit("npy", with(Some(RenderMode::Features), false)));
    // One file that needs floats makes the whole run read back floats.
    let mut mixed = plan(&cams, dir, "png", &OutputOptions::default());
    mixed[1].files = plan(&cams, dir, "exr", &OutputOptions::default())[1]
        .files
        .clone();
    assert!(!sequence::reads_rgb8_only(&mixed));
}

#[test]
fn an_8_bit_frame_refuses_a_file_that_needs_floats() {
    let dir = tempfile::tempdir().unwrap();
    let frame = FramePixels::Rgba8(Rgba8Frame {
        width: 2,
        height: 1,
        rgba: vec![1, 2, 3, 255, 4, 5, 6, 255],
    });
    for (name, opts) in [
        ("a.exr", OutputOptions::default()),
        (
            "b.png",
            OutputOptions {
                png16: true,
                ..Default::default()
            },
        ),
        (
            "c.png",
            OutputOptions {
                mode: Some(RenderMode::Alpha),
                ..Default::default()
            },
        ),
    ] {
        let path = dir.path().join(name);
        let spec = &output::plan_files(&path, None, &opts).unwrap()[0];
        let e = output::write_pixels(&frame, spec, false).unwrap_err();
        assert!(matches!(e, OutputError::NeedsFloat(_)), "{e}");
        assert!(e.to_string().contains(name), "{e}");
        assert!(!path.exists());
    }
    // The colour it holds, as an 8-bit RGB PNG.
    let path = dir.path().join("d.png");
    let spec = &output::plan_files(&path, None, &OutputOptions::default()).unwrap()[0];
    output::write_pixels(&frame, spec, false).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!(img.as_raw(), &vec![1, 2, 3, 4, 5, 6]);
}

/// `verisplat render` of a path to PNGs: the 8-bit readback (said by `--timings`) writes
/// the bytes that `VERISPLAT_READBACK=float` does; a bad value of the variable is refused.
#[test]
fn render_writes_the_same_pngs_with_either_readback() {
    let dir = tempfile::tempdir().unwrap();
    let data = common::shared_data();
    let ply = data.join("playbot_lod3_31k_sh2.ply");
    let cameras = data.join(PLAYBOT_ORBIT);
    let render = |out: &Path, env: &[(&str, &str)]| {
        let o = verisplat_env(
            &[
                "render",
                s(&ply),
                "--cameras",
                s(&cameras),
                "--frames",
                "0..3",
                "--width",
                "161",
                "--height",
                "91",
                "--background",
                "0.1,0.2,0.3",
                "--timings",
                "-o",
                &format!("{}/f_{{:02}}.png", out.display()),
            ],
            env,
        );
        (o.status.success(), stderr(&o))
    };
    let (float_dir, rgb8_dir) = (dir.path().join("float"), dir.path().join("rgb8"));
    let (ok, e) = render(&rgb8_dir, &[]);
    assert!(ok, "{e}");
    assert!(
        e.contains("readback: 8-bit colour packed on the device"),
        "{e}"
    );
    let (ok, e) = render(&float_dir, &[("VERISPLAT_READBACK", "float")]);
    assert!(ok, "{e}");
    assert!(e.contains("readback: float colour"), "{e}");
    let (a, b) = (files(&float_dir), files(&rgb8_dir));
    assert_eq!(a.len(), 3);
    assert!(a == b, "the PNGs differ between the readbacks");
    let (ok, e) = render(&dir.path().join("bad"), &[("VERISPLAT_READBACK", "half")]);
    assert!(
        !ok && e.starts_with("error: ") && e.contains("VERISPLAT_READBACK"),
        "{e}"
    );
    assert_eq!(e.trim_end().lines().count(), 1, "one sentence: {e}");
}
