//! Where `verisplat render` writes: the output name pattern (given, or the default for one
//! frame or a path), the checks of the output options against it, the frames of a shard,
//! the plan on disk (`--skip-existing`, `--overwrite`), `--export-cameras` and `--verify`.

use super::args::RenderArgs;
use super::interrupt::interrupt_flag;
use crate::cli::common::check_output_dir;
use crate::cli::plural;
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};
use verisplat::app::sequence::{
    Existing, FramePlan, OutputPattern, Plan, ProgressStyle, RunOptions,
};
use verisplat::core::camera::Camera;
use verisplat::core::console::{note, outln};
use verisplat::io::output::{self, FileContent};

/// Output of a single frame when `-o` is not given.
pub(super) const DEFAULT_OUTPUT: &str = "render.png";
/// Output of a path of several frames when `-o` is not given.
pub(super) const DEFAULT_SEQUENCE_OUTPUT: &str = "render/frame_{:05}.png";

/// Refuses output options that the chosen output would silently ignore.
pub(super) fn check_output_options(
    args: &RenderArgs,
    output: &Path,
    pattern: &OutputPattern,
    opts: &output::OutputOptions,
) -> Result<()> {
    if args.format.is_some() && !verisplat::app::sequence::names_directory(output) {
        bail!(
            "--format sets the image format of a directory output (-o out/); {} names its format by its extension",
            output.display()
        );
    }
    let files = output::plan_files(&pattern.path(0, "x"), None, opts).map_err(|e| match e {
        // The library's sentence names the image formats; render writes videos too.
        output::OutputError::UnknownFormat(_) => anyhow::anyhow!(
            "{}: unknown output format; render writes .png or .exr images (.npy with --mode features), or an .mp4, .webm or .gif video (through ffmpeg)",
            output.display()
        ),
        e => e.into(),
    })?;
    let writes = |pred: fn(&FileContent) -> bool| files.iter().any(|f| pred(&f.content));
    if args.png16
        && !writes(|c| {
            matches!(
                c,
                FileContent::PngColor { .. }
                    | FileContent::PngRgba { .. }
                    | FileContent::PngAlpha { .. }
                    | FileContent::PngNormal { .. }
            )
        })
    {
        bail!(
            "--png16 applies to PNG colour and alpha files; {} writes none (EXR is float, depth PNGs are colour-mapped 8-bit)",
            output.display()
        );
    }
    if args.exr_half
        && !writes(|c| {
            matches!(
                c,
                FileContent::Exr(_)
                    | FileContent::ExrFeatures { .. }
                    | FileContent::ExrNormal { .. }
            )
        })
    {
        bail!(
            "--exr-half applies to EXR output; {} is not an EXR file",
            output.display()
        );
    }
    if args.exr_background && args.mode == Some(output::RenderMode::Features) {
        bail!("--exr-background does not apply to --mode features: features are blended over 0, without a background");
    }
    if args.exr_background && !writes(|c| matches!(c, FileContent::Exr(_))) {
        bail!(
            "--exr-background applies to EXR output; {} is not an EXR file",
            output.display()
        );
    }
    if args.normal_space.is_some() && args.mode != Some(output::RenderMode::Normal) {
        bail!("--normal-space sets the space of --mode normal's normals; add --mode normal");
    }
    if args.depth_range.is_some()
        && !writes(|c| {
            matches!(
                c,
                FileContent::PngDepth { .. } | FileContent::PngMedianDepth { .. }
            )
        })
    {
        bail!(
            "--depth-range sets the colour map of depth PNGs; {} writes none (use --mode depth or rgb+depth with a .png output; EXR stores depth as it is)",
            output.display()
        );
    }
    Ok(())
}

/// Writes the camera path as an INRIA cameras.json (the whole path, whatever --frames
/// renders of it, so every part of a split run writes the same file). With
/// --skip-existing an identical file is left as it is.
pub(super) fn export_cameras(
    path: &Path,
    cams: &[(usize, Camera)],
    args: &RenderArgs,
) -> Result<()> {
    let json = verisplat::io::camera::inria::to_json(cams)?;
    if !args.overwrite && args.skip_existing && path.exists() {
        if std::fs::read(path).ok().as_deref() == Some(json.as_bytes()) {
            return Ok(());
        }
        bail!(
            "{}: already exists and holds other cameras; pass --overwrite to replace it",
            path.display()
        );
    }
    output::write_bytes_atomically(path, args.overwrite, json.as_bytes())?;
    Ok(())
}

/// `--verify`: lists the frames whose files are missing, unreadable or of the wrong size
/// on stdout, and fails when there are any.
pub(super) fn verify(frames: &[verisplat::app::sequence::FramePlan]) -> Result<()> {
    let files: usize = frames.iter().map(|f| f.files.len()).sum();
    let problems = verisplat::app::sequence::verify(frames);
    for p in &problems {
        outln!("frame {}: {}: {}", p.frame, p.path.display(), p.reason);
    }
    if problems.is_empty() {
        note!(
            "verified {} ({}): all present and readable",
            plural(frames.len(), "frame"),
            plural(files, "file")
        );
        return Ok(());
    }
    let bad_frames = {
        let mut f: Vec<usize> = problems.iter().map(|p| p.frame).collect();
        f.dedup();
        f.len()
    };
    let missing = problems.iter().filter(|p| p.reason == "missing").count();
    bail!(
        "{bad_frames} of {} incomplete: {missing} file(s) missing, {} unreadable or of the wrong size (listed above); delete unreadable ones and rerun the same command (or array) with --skip-existing",
        plural(frames.len(), "frame"),
        problems.len() - missing
    )
}

/// The output options and the output named by `-o`, checked before anything is loaded.
pub(super) struct Outputs<'a> {
    /// What each frame writes (`--mode`, `--png16`, ...).
    pub(super) opts: output::OutputOptions,
    /// The image format of a directory output (`--format`, PNG by default).
    format: &'a str,
    /// This run writes `--export-cameras` (a shard's run only when it is the first).
    pub(super) exports_cameras: bool,
    /// `-o` and its pattern (`None`: the default, chosen once the path is known).
    explicit: Option<(PathBuf, OutputPattern)>,
}

impl Outputs<'_> {
    /// Checks the output options and names: bad names and unwritable folders are reported
    /// before anything is loaded. A `video` output (checked by `super::video`) has no
    /// image names.
    pub(super) fn checked(
        args: &RenderArgs,
        shard: Option<verisplat::app::shard::Shard>,
        video: bool,
    ) -> Result<Outputs<'_>> {
        let out_opts = output::OutputOptions {
            mode: args.mode,
            png16: args.png16,
            exr_half: args.exr_half,
            depth_range: args.depth_range,
            background: args.background,
            exr_background: args.exr_background,
            normal_space: args.normal_space.unwrap_or_default(),
        };
        let format = args.format.as_deref().unwrap_or("png");
        // Shards never write the same file: the first one writes the whole path's cameras.
        let exports_cameras = shard.map_or(true, |s| s.index == 0);
        if let Some(path) = &args.export_cameras {
            if !args.skip_existing && exports_cameras {
                crate::cli::common::check_output_file(path, args.overwrite)?;
            }
        }
        // Bad names and unwritable folders are reported before anything is loaded.
        let explicit = match &args.output {
            Some(_) if video => None,
            Some(out) => {
                let pattern = OutputPattern::parse(out, format).map_err(anyhow::Error::msg)?;
                check_output_options(args, out, &pattern, &out_opts)?;
                let first = pattern.path(0, "x");
                check_output_dir(
                    first
                        .parent()
                        .filter(|d| !d.as_os_str().is_empty())
                        .unwrap_or(Path::new(".")),
                )?;
                Some((out.clone(), pattern))
            }
            None => {
                check_output_dir(Path::new("."))?;
                None
            }
        };
        Ok(Outputs {
            opts: out_opts,
            format,
            exports_cameras,
            explicit,
        })
    }

    /// The output and its pattern: `-o`, or without it the default for the number of
    /// frames `cameras` and `--frames` select (announced for a path).
    pub(super) fn pattern(
        &self,
        args: &RenderArgs,
        cameras: &[(usize, Camera)],
    ) -> Result<(PathBuf, OutputPattern)> {
        let selected = cameras
            .iter()
            .filter(|(k, _)| args.frames.as_ref().map_or(true, |f| f.contains(*k)))
            .count();
        Ok(match &self.explicit {
            Some(p) => p.clone(),
            None => {
                let out = PathBuf::from(if selected > 1 {
                    DEFAULT_SEQUENCE_OUTPUT
                } else {
                    DEFAULT_OUTPUT
                });
                let pattern =
                    OutputPattern::parse(&out, self.format).map_err(anyhow::Error::msg)?;
                check_output_options(args, &out, &pattern, &self.opts)?;
                if selected > 1 {
                    note!(
                        "no -o given: writing {} frames to {}",
                        selected,
                        out.display()
                    );
                }
                (out, pattern)
            }
        })
    }
}

/// The frames this run renders: the selection's, or a shard's block of them (`None`,
/// announced, when a shard has none).
pub(super) fn planned_frames(
    args: &RenderArgs,
    shard: Option<verisplat::app::shard::Shard>,
    cameras: &[(usize, Camera)],
    pattern: &OutputPattern,
    out_opts: &output::OutputOptions,
) -> Result<Option<Vec<FramePlan>>> {
    // Every shard plans the whole selection, so shards that would write the same file
    // are refused by each of them; then it keeps its block.
    let frames =
        verisplat::app::sequence::plan_frames(cameras, pattern, args.frames.as_ref(), out_opts)?;
    Ok(Some(match shard {
        Some(shard) => {
            let all = frames.len();
            let mine = shard.take(frames);
            match (mine.first(), mine.last()) {
                (Some(a), Some(b)) => note!(
                    "{shard}: {} of the {all} selected, frames {}..={}",
                    plural(mine.len(), "frame"),
                    a.index,
                    b.index
                ),
                _ => {
                    note!("{shard}: no frames (the selection has {all}, fewer than the shards); nothing to render");
                    return Ok(None);
                }
            }
            mine
        }
        None => frames,
    }))
}

/// Readies the frames on disk as `--overwrite` / `--skip-existing` ask (announcing the
/// temporaries removed); `None`, announced, when every frame is there already.
pub(super) fn prepare(args: &RenderArgs, frames: Vec<FramePlan>) -> Result<Option<Plan>> {
    let existing = if args.overwrite {
        Existing::Overwrite
    } else if args.skip_existing {
        Existing::Skip
    } else {
        Existing::Refuse
    };
    let plan = verisplat::app::sequence::prepare(frames, existing)?;
    if plan.removed_temporaries > 0 {
        note!(
            "removed {} temporary file(s) left by an interrupted run",
            plan.removed_temporaries
        );
    }
    if plan.frames.is_empty() {
        note!(
            "all {} already exist; nothing to render",
            plural(plan.skipped, "frame")
        );
        return Ok(None);
    }
    Ok(Some(plan))
}

/// How the frames are written: the encoders, the progress display, resuming, the
/// Ctrl-C flag and the frames in flight.
pub(super) fn run_options(args: &RenderArgs) -> RunOptions {
    RunOptions {
        overwrite: args.overwrite,
        encode_threads: args.encode_threads,
        queue_depth: args.encode_threads.max(1) + 1,
        progress: if args.quiet {
            ProgressStyle::Quiet
        } else {
            ProgressStyle::Auto
        },
        skip_existing: args.skip_existing,
        cancel: Some(interrupt_flag()),
        frames_in_flight: args.frames_in_flight.unwrap_or(2),
        sink: None,
    }
}
