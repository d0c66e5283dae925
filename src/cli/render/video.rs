//! `render -o out.mp4` (or `.webm`, `.gif`): the frames of a path streamed to the system
//! ffmpeg as one video ([`verisplat::io::video`]). Everything a video cannot honour is
//! refused, and ffmpeg looked for, before the scene is loaded.

use super::args::RenderArgs;
use crate::cli::common::{check_output_file, PathArgs};
use crate::cli::plural;
use anyhow::{bail, Result};
use std::path::PathBuf;
use std::sync::Arc;
use verisplat::app::sequence::{FramePlan, OutputPattern};
use verisplat::core::camera::Camera;
use verisplat::core::console::note;
use verisplat::io;
use verisplat::io::camera::CameraFormat;
use verisplat::io::output::RenderMode;
use verisplat::io::video::{self, VideoFormat, VideoOptions, VideoWriter};

/// Frame rate of a video when neither `--fps` nor a keyframe path gives one.
pub(super) const DEFAULT_FPS: f64 = 30.0;

/// The video `-o` names, checked.
pub(super) struct VideoOut {
    pub(super) path: PathBuf,
    pub(super) format: VideoFormat,
    ffmpeg: PathBuf,
}

/// The format of the video `-o` names (`.mp4`, `.webm`, `.gif`), if it names one.
pub(super) fn video_format(args: &RenderArgs) -> Option<VideoFormat> {
    let out = args.output.as_deref()?;
    if verisplat::app::sequence::names_directory(out) {
        return None;
    }
    VideoFormat::from_path(out)
}

/// The video `-o` names, with its options checked, the output refused if it exists
/// (without `--overwrite`) and ffmpeg found with the format's encoder; `None` for image
/// outputs, which refuse `--quality`.
pub(super) fn checked(args: &RenderArgs) -> Result<Option<VideoOut>> {
    let Some(format) = video_format(args) else {
        if args.quality.is_some() {
            bail!("--quality sets the quality of a video (-o out.mp4 or out.webm); image outputs have none (see --png16, --exr-half)");
        }
        return Ok(None);
    };
    let out = args.output.clone().unwrap_or_default();
    let shown = out.display();
    if args.mode.is_some_and(|m| m != RenderMode::Rgb) {
        bail!(
            "{shown}: a video holds colour (--mode rgb, the default); write the other modes as an image sequence (-o frames/frame_%04d.png or .exr)"
        );
    }
    let refused = [
        ("--png16", args.png16, "its frames are 8-bit"),
        ("--exr-half", args.exr_half, "it is not EXR"),
        ("--exr-background", args.exr_background, "it is not EXR"),
        (
            "--depth-range",
            args.depth_range.is_some(),
            "it holds colour",
        ),
        (
            "--skip-existing",
            args.skip_existing,
            "a video is one file, written whole or not at all",
        ),
        (
            "--shard",
            args.shard.is_some(),
            "a video is one file; render the shards as images and encode them with ffmpeg",
        ),
        (
            "--devices",
            args.devices.is_some(),
            "a video's frames are encoded in order on one device",
        ),
        ("--verify", args.verify, "it checks image sequences"),
        (
            "--format",
            args.format.is_some(),
            "its extension names its format",
        ),
    ];
    if let Some((flag, _, why)) = refused.iter().find(|(_, set, _)| *set) {
        bail!("{flag} does not apply to a video ({shown}): {why}");
    }
    let pattern = OutputPattern::parse(&out, "png").map_err(anyhow::Error::msg)?;
    if pattern.is_sequence() {
        bail!("{shown}: a video is one file; drop the frame-number or {{name}} placeholder");
    }
    match (format.crf_range(), args.quality) {
        (None, Some(_)) => bail!(
            "--quality sets the CRF of an MP4 or WebM; a GIF's quality is its 256-colour palette, made from the whole clip (drop --quality)"
        ),
        (Some((lo, hi, _)), Some(q)) if q < lo || q > hi => bail!(
            "--quality {q}: {}'s CRF is between {lo} (best) and {hi}",
            format.with_article()
        ),
        _ => {}
    }
    check_output_file(&out, args.overwrite)?;
    let ffmpeg = video::check_ffmpeg(&out, format).map_err(anyhow::Error::msg)?;
    Ok(Some(VideoOut {
        path: out,
        format,
        ffmpeg,
    }))
}

/// Whether `--fps` samples the path: only a keyframe path's (`--cameras`), which a
/// video then plays in real time. For other paths of a video `--fps` is the video's rate
/// alone, so it is taken out of the path's arguments.
pub(super) fn path_args(args: &RenderArgs) -> Result<PathArgs> {
    let mut p = args.path.clone();
    if video_format(args).is_some() && keyframe_fps(args)?.is_none() {
        p.fps = None;
    }
    Ok(p)
}

/// The frame rate a keyframe path given with `--cameras` has (its file's), if it is one.
fn keyframe_fps(args: &RenderArgs) -> Result<Option<f64>> {
    let Some(file) = &args.view.cameras else {
        return Ok(None);
    };
    if io::camera::detect_camera_format(file)? != CameraFormat::Keyframes {
        return Ok(None);
    }
    let text = std::fs::read_to_string(file)
        .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", file.display()))?;
    Ok(Some(io::camera::KeyframePath::parse(&text, file)?.fps))
}

/// The video's frame rate: `--fps`, else a keyframe path's own, else [`DEFAULT_FPS`].
fn frame_rate(args: &RenderArgs) -> Result<f64> {
    Ok(match args.path.fps {
        Some(fps) => f64::from(fps),
        None => keyframe_fps(args)?.unwrap_or(DEFAULT_FPS),
    })
}

/// The frames of the video: the selected cameras in path order (no files: they go to
/// the encoder), all of one size.
pub(super) fn frames(
    args: &RenderArgs,
    out: &VideoOut,
    cameras: &[(usize, Camera)],
) -> Result<Vec<FramePlan>> {
    let frames: Vec<FramePlan> = cameras
        .iter()
        .filter(|(k, _)| args.frames.as_ref().map_or(true, |f| f.contains(*k)))
        .map(|(k, cam)| FramePlan {
            index: *k,
            camera: cam.clone(),
            files: Vec::new(),
        })
        .collect();
    let Some(first) = frames.first() else {
        bail!(
            "no frames to render: --frames selects none of the {} chosen",
            plural(cameras.len(), "frame")
        );
    };
    let size = (first.camera.width, first.camera.height);
    if let Some(other) = frames
        .iter()
        .find(|f| (f.camera.width, f.camera.height) != size)
    {
        bail!(
            "{}: frame {} is {}x{} but frame {} is {}x{}; a video's frames have one size (give --width and --height)",
            out.path.display(),
            other.index,
            other.camera.width,
            other.camera.height,
            first.index,
            size.0,
            size.1
        );
    }
    Ok(frames)
}

/// A started video and how it is encoded, for the closing line.
pub(super) struct Started {
    pub(super) writer: Arc<VideoWriter>,
    pub(super) description: String,
}

/// Starts ffmpeg for the frames (removing the temporaries a killed run left of this
/// output first).
pub(super) fn start(args: &RenderArgs, out: &VideoOut, frames: &[FramePlan]) -> Result<Started> {
    let removed = verisplat::app::sequence::remove_stale_temporaries_of(&out.path);
    if removed > 0 {
        note!("removed {removed} temporary file(s) left by an interrupted run");
    }
    let (width, height) = (frames[0].camera.width, frames[0].camera.height);
    let opts = VideoOptions {
        format: out.format,
        fps: frame_rate(args)?,
        crf: args.quality,
        pad_colour: args.background,
        overwrite: args.overwrite,
    };
    let writer = VideoWriter::start(&out.ffmpeg, &out.path, width, height, &opts)?;
    let quality = match out.format.crf_range() {
        Some((_, _, default)) => format!(", CRF {}", args.quality.unwrap_or(default)),
        None => String::new(),
    };
    let padded = if out.format == VideoFormat::Mp4 && (width % 2 == 1 || height % 2 == 1) {
        format!(
            ", padded to {}x{} with the background (H.264 needs even sizes)",
            width + width % 2,
            height + height % 2
        )
    } else {
        String::new()
    };
    Ok(Started {
        writer: Arc::new(writer),
        description: format!(
            "{}, {} fps{quality}{padded}",
            out.format.describe(),
            opts.fps
        ),
    })
}
