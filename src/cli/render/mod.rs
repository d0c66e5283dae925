//! `verisplat render`: one camera or a camera path to PNG/EXR files, or to a video.
//!
//! [`render`] runs the command's phases in order; the rooms below hold them: the
//! arguments (`args`), the scene and its time (`scene`, `time`), where the frames go
//! (`outputs`), the splat renderers (`splat`), the field renders (`field`), the COLMAP
//! export (`colmap`), videos through ffmpeg (`video`) and stopping on Ctrl-C
//! (`interrupt`).

mod args;
mod colmap;
mod field;
mod interrupt;
mod outputs;
mod scene;
mod splat;
mod time;
mod video;

pub(crate) use args::RenderArgs;
pub(crate) use interrupt::{interrupt_flag, Interrupted};

use crate::cli::common::{camera_path, draws_pinholes_only, refuse_lens};
use crate::cli::plural;
use anyhow::{bail, Result};
use outputs::Outputs;
use splat::Job;
use std::path::Path;
use verisplat::app::sequence::{Plan, Summary};
use verisplat::core::console::note;
use verisplat::io::output::RenderMode;

pub(crate) fn render(args: &RenderArgs) -> Result<()> {
    if args.cpu {
        args::check_cpu_options(args)?;
    }
    let shard = crate::cli::common::shard(args.shard.as_deref())?;
    let video = video::checked(args)?;
    let outputs = Outputs::checked(args, shard, video.is_some())?;
    let scene::Loaded {
        scene,
        name,
        time,
        field_mode,
        render_features,
        shader,
    } = scene::load(args)?;
    // The default camera frames the Gaussians of every time, so a scene looks the same
    // from --time T as from the frame of --time-range at T.
    if field_mode.is_some() {
        refuse_lens(&args.path, &draws_pinholes_only("a field render"))?;
    }
    let mut path = camera_path(&args.view, &video::path_args(args)?, &args.scene, &scene)?;
    let (scene, animation) = scene::at_time(args, time, scene, &mut path)?;
    if let Some(file) = &args.export_cameras {
        if outputs.exports_cameras {
            outputs::export_cameras(file, &path.cameras, args)?;
        }
    }
    if let Some(frames) = &args.frames {
        frames.check(path.len).map_err(anyhow::Error::msg)?;
    }
    if let Some(dir) = &args.export_colmap {
        if animation.is_some() {
            bail!("--export-colmap writes a data set of one scene; give one --time instead of --time-range");
        }
        return colmap::export_colmap(args, dir, &scene, &name, &path.cameras, shader.as_ref());
    }
    let (output_name, plan, started) = if let Some(out) = &video {
        let frames = video::frames(args, out, &path.cameras)?;
        let started = video::start(args, out, &frames)?;
        let plan = Plan {
            frames,
            skipped: 0,
            removed_temporaries: 0,
        };
        (out.path.clone(), plan, Some(started))
    } else {
        let (output_name, pattern) = outputs.pattern(args, &path.cameras)?;
        let Some(frames) =
            outputs::planned_frames(args, shard, &path.cameras, &pattern, &outputs.opts)?
        else {
            return Ok(());
        };
        if args.verify {
            return outputs::verify(&frames);
        }
        let Some(plan) = outputs::prepare(args, frames)? else {
            return Ok(());
        };
        (output_name, plan, None)
    };
    let opts = scene::render_options(args, &scene, &name);
    let mut run_opts = outputs::run_options(args);
    if let Some(s) = &started {
        run_opts.sink = Some(s.writer.clone());
    }
    let act = scene.activated();
    let job = Job {
        args,
        scene: &act,
        animation: animation.as_ref(),
        frames: &plan.frames,
        opts: &opts,
        run_opts: &run_opts,
        features: render_features,
        shader: shader.as_ref(),
    };
    let (summary, how) = render_frames(&job, field_mode)?;
    if let Some(s) = &started {
        if summary.interrupted {
            s.writer.abort();
            return Err(Interrupted(format!(
                "interrupted after {} of {}; no video written (its temporary file is removed)",
                summary.written,
                plural(plan.frames.len(), "frame")
            ))
            .into());
        }
        s.writer.finish()?;
    }
    if summary.interrupted {
        return Err(Interrupted(format!(
            "interrupted after {} of {}; every file written is complete; run the same command with --skip-existing to finish",
            summary.written,
            plural(plan.frames.len(), "frame")
        ))
        .into());
    }
    let mut what = describe_frames(&plan, &summary, &path.source, &output_name);
    if let Some(s) = &started {
        what = format!("{what} ({})", s.description);
    }
    note!(
        "rendered {name} ({}) {what} {how} in {:.2} s: {:.2} frames/s; rendering {:.2} s, encoding {:.2} s on {}",
        plural(scene.len(), "Gaussian"),
        summary.wall_s,
        summary.frames_per_s(),
        summary.render_s,
        summary.encode_s,
        match (&started, args.encode_threads) {
            (Some(_), _) => "the rendering thread, ffmpeg encoding meanwhile".to_string(),
            (None, 0) => "the rendering thread".to_string(),
            (None, n) => format!("{}, overlapped", plural(n, "thread")),
        }
    );
    if summary.appeared > 0 {
        note!(
            "kept {} that another run wrote meanwhile",
            plural(summary.appeared, "file")
        );
    }
    Ok(())
}

/// Renders the job's frames with the renderer the options choose: the field renders
/// (`field_mode`), several devices (`--devices`), the CPU reference (`--cpu`) or the
/// device; the summary and how it rendered (`on <device>`, for the closing line).
fn render_frames(job: &Job, field_mode: Option<RenderMode>) -> Result<(Summary, String)> {
    let args = job.args;
    Ok(if let Some(mode) = field_mode {
        if args.devices.is_some() {
            bail!("--devices spreads colour and feature renders over devices; the field modes render on one (drop --devices)");
        }
        field::render(
            args,
            job.scene,
            job.animation,
            job.opts.kernel,
            mode,
            job.frames,
            job.run_opts,
            job.shader,
        )?
    } else if let (Some(_), Some(_)) = (&args.devices, &job.animation) {
        bail!("--devices spreads a path over devices; an animation (--time-range) renders on one (drop --devices)");
    } else if let Some(devices) = &args.devices {
        splat::render_on_devices(job, devices)?
    } else if args.cpu {
        splat::render_cpu(job)?
    } else {
        splat::render_gpu(job, args.gpu.context()?)?
    })
}

/// What was rendered, for the closing line: one frame from its camera to its file, or
/// the frames of the path (and those skipped) to the output.
fn describe_frames(plan: &Plan, summary: &Summary, source: &str, output_name: &Path) -> String {
    let first = &plan.frames[0];
    // A video's frames have no files of their own.
    if plan.frames.len() == 1 && plan.skipped == 0 && !first.files.is_empty() {
        let from = if source == "the default camera" {
            "from the default camera".to_string()
        } else {
            format!("from camera \"{}\" of {}", first.camera.name, source)
        };
        format!(
            "{from} at {}x{} -> {}",
            first.camera.width,
            first.camera.height,
            first.files[0].path.display()
        )
    } else {
        format!(
            "{} of {} at {}x{}{} -> {}",
            plural(summary.written, "frame"),
            source,
            first.camera.width,
            first.camera.height,
            if plan.skipped > 0 {
                format!(" ({} skipped: already written)", plan.skipped)
            } else {
                String::new()
            },
            output_name.display()
        )
    }
}
