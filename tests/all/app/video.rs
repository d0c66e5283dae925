//! `render -o out.mp4 / .webm / .gif` through the binary and the system ffmpeg: the
//! videos' codec, size, frame rate and frame count (ffprobe), their frames decoded back
//! against the PNG sequence of the same path, and the failures: ffmpeg missing, ffmpeg
//! failing, an existing output, Ctrl-C, options a video cannot honour. None leaves a file.
//!
//! Tests that need the real ffmpeg skip without it on a developer machine (saying so) and
//! fail in CI (`CI=true`), which installs it (tools/setup.sh).

use crate::common;
use crate::common::cli::{command, s, stderr};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use verisplat::io::image_file::read_image;

/// Whether ffmpeg and ffprobe are on the PATH; without them a test skips (announced),
/// except in CI, where it fails.
fn have_ffmpeg() -> bool {
    let found = |tool: &str| {
        Command::new(tool)
            .arg("-version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    if found("ffmpeg") && found("ffprobe") {
        return true;
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "ffmpeg or ffprobe is missing: tools/setup.sh installs it (CI=true: the video tests must run)"
    );
    eprintln!("skipped: ffmpeg or ffprobe is not on the PATH (tools/setup.sh installs it)");
    false
}

/// The shared scene and orbit the videos show, at an odd size (the MP4 is padded).
const W: u32 = 161;
const H: u32 = 121;
const FRAMES: usize = 6;

/// `render` of the first [`FRAMES`] cameras of the shared PLAYBOT orbit at W x H, 25 fps
/// (a GIF's delays are whole centiseconds: 25 fps is exact), to `out`, plus `extra`.
fn render_args(out: &Path, extra: &[&str]) -> Vec<String> {
    let data = common::shared_data();
    let mut a: Vec<String> = [
        "render",
        s(&data.join("playbot_lod3_31k_sh2.ply")),
        "--cameras",
        s(&data.join(common::PLAYBOT_ORBIT)),
        "--width",
        &W.to_string(),
        "--height",
        &H.to_string(),
        "--frames",
        &format!("0..{FRAMES}"),
        "-o",
        s(out),
        "-q",
    ]
    .iter()
    .map(|x| x.to_string())
    .collect();
    a.extend(extra.iter().map(|x| x.to_string()));
    a
}

/// Runs the binary with `PATH` set to `path` when given.
fn run(args: &[String], path: Option<&str>) -> Output {
    let mut c = command();
    c.args(args);
    if let Some(p) = path {
        c.env("PATH", p);
    }
    c.output().expect("the binary runs")
}

/// Runs a render that must succeed.
fn renders(args: &[String]) {
    let o = run(args, None);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
}

/// Runs a command that must fail with one `error:` sentence; returns it.
fn refused(args: &[String], path: Option<&str>) -> String {
    let o = run(args, path);
    let e = stderr(&o);
    assert!(!o.status.success(), "{args:?} must fail");
    assert!(!e.contains("panicked"), "{e}");
    assert!(e.starts_with("error: "), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "one sentence: {e}");
    e
}

/// The names of the files in `dir`.
fn names(dir: &Path) -> Vec<String> {
    let mut n: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    n.sort();
    n
}

/// ffprobe's codec, width, height, frame rate and decoded frame count of a video.
fn probe(video: &Path) -> (String, u32, u32, String, usize) {
    let o = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=codec_name,width,height,r_frame_rate,nb_read_frames",
            "-of",
            "default=noprint_wrappers=1",
            s(video),
        ])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "ffprobe {}: {}",
        video.display(),
        stderr(&o)
    );
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let field = |k: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{k}=")))
            .unwrap_or_else(|| panic!("no {k} in {text}"))
            .to_string()
    };
    (
        field("codec_name"),
        field("width").parse().unwrap(),
        field("height").parse().unwrap(),
        field("r_frame_rate"),
        field("nb_read_frames").parse().unwrap(),
    )
}

/// Decodes a video's frames to RGB PNGs in `dir` (cropped to W x H: an MP4 is padded),
/// with ffmpeg; their paths in order.
fn decode(video: &Path, dir: &Path) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    let o = Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-nostdin",
            "-i",
            s(video),
            "-vf",
            &format!("format=rgb24,crop={W}:{H}:0:0"),
            s(&dir.join("%03d.png")),
        ])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "decoding {}: {}",
        video.display(),
        stderr(&o)
    );
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    files
}

/// PSNR (dB, peak 1) of the colour of two 8-bit RGB images of one size.
fn psnr(a: &Path, b: &Path) -> f64 {
    let (pa, pb) = (read_image(a).unwrap(), read_image(b).unwrap());
    assert_eq!((pa.width, pa.height), (pb.width, pb.height), "{a:?} {b:?}");
    let rgb = ["R", "G", "B"];
    verisplat::io::metrics::psnr(
        &pa.interleave(&rgb).unwrap(),
        &pb.interleave(&rgb).unwrap(),
        1.0,
    )
}

/// The three formats: their codec, the size ffprobe reports and the least PSNR of a
/// decoded frame against the PNG of it. Measured at 161x121 on the PLAYBOT orbit:
/// MP4 (CRF 18) 35.7-36.7 dB, WebM (CRF 24) 37.5-39.7 dB, GIF 43.9-44.8 dB; a frame
/// against its neighbour in the path 23.5-23.9 dB. yuv420p halves the colour's
/// resolution, which costs most at this small size.
const FORMATS: [(&str, &str, (u32, u32), f64); 3] = [
    ("mp4", "h264", (W + 1, H + 1), 32.0),
    ("webm", "vp9", (W, H), 33.0),
    ("gif", "gif", (W, H), 40.0),
];

#[test]
fn videos_hold_the_frames_of_the_png_sequence() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    renders(&render_args(&seq.join("f_%02d.png"), &[]));
    let pngs: Vec<PathBuf> = (0..FRAMES)
        .map(|k| seq.join(format!("f_{k:02}.png")))
        .collect();
    for (ext, codec, size, least) in FORMATS {
        let video = dir.path().join(format!("path.{ext}"));
        renders(&render_args(&video, &["--fps", "25"]));
        assert_eq!(
            probe(&video),
            (
                codec.to_string(),
                size.0,
                size.1,
                "25/1".to_string(),
                FRAMES
            ),
            "{ext}"
        );
        let decoded = decode(&video, &dir.path().join(format!("decoded_{ext}")));
        assert_eq!(decoded.len(), FRAMES, "{ext}");
        for (k, (got, want)) in decoded.iter().zip(&pngs).enumerate() {
            let same = psnr(got, want);
            assert!(same >= least, "{ext} frame {k}: {same:.2} dB < {least}");
            // In path order: each frame is nearer its own PNG than the next one's.
            let next = psnr(got, &pngs[(k + 1) % FRAMES]);
            assert!(
                next + 5.0 < same,
                "{ext} frame {k}: {same:.2} dB, next {next:.2} dB"
            );
        }
        // Nothing but the video is left beside it (the temporary file is renamed).
        assert!(
            !names(dir.path()).iter().any(|n| n.ends_with(".tmp")),
            "{:?}",
            names(dir.path())
        );
    }
}

/// A video reads back only 8-bit colour (packed on the device, said by `--timings`), and
/// its file is the one that the float readback (`VERISPLAT_READBACK=float`) gives, byte for
/// byte: MP4 and GIF, whose encoders are deterministic. (WebM is not: its muxer writes
/// random segment ids, different from run to run whatever the readback; the frames fed to
/// its encoder are compared by render::rgb8_readback.)
#[test]
fn a_video_is_the_same_file_with_either_readback() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for ext in ["mp4", "gif"] {
        let mut bytes = Vec::new();
        for readback in ["auto", "float"] {
            let video = dir.path().join(format!("{readback}.{ext}"));
            let mut c = command();
            c.args(render_args(&video, &["--timings"]))
                .env("VERISPLAT_READBACK", readback);
            let o = c.output().expect("the binary runs");
            let e = stderr(&o);
            assert!(o.status.success(), "{ext} {readback}: {e}");
            let said = match readback {
                "auto" => "readback: 8-bit colour packed on the device",
                _ => "readback: float colour",
            };
            assert!(e.contains(said), "{ext} {readback}: {e}");
            bytes.push(std::fs::read(&video).unwrap());
        }
        assert!(
            bytes[0] == bytes[1],
            "the {ext} videos differ between the readbacks"
        );
    }
}

#[test]
fn one_camera_gives_a_one_frame_video_and_quality_changes_the_encoding() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.mp4");
    renders(&render_args(&one, &["--camera", "3"]));
    assert_eq!(
        probe(&one),
        ("h264".to_string(), W + 1, H + 1, "30/1".to_string(), 1)
    );
    // A lower CRF keeps more: a larger file, nearer the PNG.
    let (fine, coarse) = (dir.path().join("fine.webm"), dir.path().join("coarse.webm"));
    renders(&render_args(&fine, &["--quality", "10"]));
    renders(&render_args(&coarse, &["--quality", "55"]));
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(
        size(&fine) > size(&coarse),
        "{} {}",
        size(&fine),
        size(&coarse)
    );
}

#[test]
fn an_existing_video_is_refused_without_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.mp4");
    std::fs::write(&out, b"not a video").unwrap();
    let e = refused(&render_args(&out, &[]), None);
    assert!(e.contains("already exists; pass --overwrite"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"not a video");
    if !have_ffmpeg() {
        return;
    }
    renders(&render_args(&out, &["--overwrite"]));
    assert_eq!(probe(&out).0, "h264");
    assert_eq!(names(dir.path()), ["out.mp4"]);
}

#[test]
fn without_ffmpeg_a_video_is_one_sentence_before_anything_renders() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("bin");
    std::fs::create_dir(&empty).unwrap();
    for (ext, what) in [
        ("mp4", "writing an H.264 MP4"),
        ("webm", "writing a VP9 WebM"),
        ("gif", "writing a GIF"),
    ] {
        let out = dir.path().join(format!("out.{ext}"));
        let e = refused(&render_args(&out, &[]), Some(s(&empty)));
        assert!(
            e.contains(what)
                && e.contains("needs ffmpeg, which is not on the PATH")
                && e.contains("sudo apt install ffmpeg")
                && e.contains("tools/setup.sh"),
            "{e}"
        );
        // Before the scene is read: a missing scene gives the same sentence.
        let mut args = render_args(&out, &[]);
        args[1] = s(&dir.path().join("missing.ply")).to_string();
        assert_eq!(refused(&args, Some(s(&empty))), e);
    }
    assert_eq!(names(dir.path()), ["bin"]);
}

/// A stand-in ffmpeg in `dir` that lists the encoders, then writes part of its output
/// file, says why it fails on stderr and exits with status 1.
fn failing_ffmpeg(dir: &Path) {
    use std::os::unix::fs::PermissionsExt;
    let script = dir.join("ffmpeg");
    std::fs::write(
        &script,
        "#!/bin/sh\n\
         case \"$*\" in *-encoders*) echo ' V..... libx264  H.264'; exit 0;; esac\n\
         for last; do :; done\n\
         printf partial > \"$last\"\n\
         head -c 1000 > /dev/null\n\
         echo 'first line of the log' >&2\n\
         echo 'Error: the encoder exploded' >&2\n\
         exit 1\n",
    )
    .unwrap();
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
}

#[test]
fn a_failing_ffmpeg_leaves_no_file_and_its_error_is_shown() {
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    failing_ffmpeg(&bin);
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = out_dir.join("out.mp4");
    let path = format!("{}:{}", s(&bin), std::env::var("PATH").unwrap_or_default());
    let e = refused(&render_args(&out, &[]), Some(&path));
    assert!(
        e.contains("out.mp4: cannot encode: ffmpeg failed")
            && e.contains("first line of the log | Error: the encoder exploded"),
        "{e}"
    );
    // Neither the video nor the partial temporary file is left.
    assert!(names(&out_dir).is_empty(), "{:?}", names(&out_dir));
}

#[test]
fn interrupting_a_video_leaves_no_file() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("long.mp4");
    let data = common::shared_data();
    let child = command()
        .args([
            "render",
            s(&data.join("playbot_lod3_31k_sh2.ply")),
            "--orbit",
            "400",
            "--width",
            "160",
            "--cpu",
            "-o",
            s(&out),
            "-q",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // ffmpeg opens its (temporary) output once it has the first frame (the folder's
    // write probe, `.verisplat-probe.*.tmp`, comes earlier: before Ctrl-C is handled).
    let start = Instant::now();
    while !names(dir.path())
        .iter()
        .any(|n| n.starts_with(".long.mp4.") && n.ends_with(".tmp"))
    {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no temporary file"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(130), "{e}");
    assert!(
        e.contains("interrupted after") && e.contains("of 400 frames; no video written"),
        "{e}"
    );
    assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
}

#[test]
fn options_a_video_cannot_honour_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mp4 = dir.path().join("out.mp4");
    let gif = dir.path().join("out.gif");
    let png = dir.path().join("out_%02d.png");
    let cases: [(&Path, &[&str], &str); 8] = [
        (
            &mp4,
            &["--mode", "depth"],
            "a video holds colour (--mode rgb",
        ),
        (
            &mp4,
            &["--mode", "rgba"],
            "a video holds colour (--mode rgb",
        ),
        (
            &gif,
            &["--quality", "20"],
            "a GIF's quality is its 256-colour palette",
        ),
        (
            &mp4,
            &["--quality", "60"],
            "an H.264 MP4's CRF is between 0 (best) and 51",
        ),
        (
            &mp4,
            &["--skip-existing"],
            "--skip-existing does not apply to a video",
        ),
        (
            &mp4,
            &["--shard", "0/2"],
            "--shard does not apply to a video",
        ),
        (&mp4, &["--png16"], "--png16 does not apply to a video"),
        (&png, &["--quality", "20"], "image outputs have none"),
    ];
    for (out, extra, want) in cases {
        let e = refused(&render_args(out, extra), None);
        assert!(e.contains(want), "{extra:?}: {e}");
    }
    let e = refused(&render_args(&dir.path().join("f_%03d.mp4"), &[]), None);
    assert!(e.contains("a video is one file"), "{e}");
    assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
}
