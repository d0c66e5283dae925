//! `vksplat render`: one camera or a camera path to PNG/EXR files.

use super::common::{
    camera_path, fail_on_validation_messages, load_scene, parse_background, parse_depth_range,
    CameraArgs, FilterArgs, GpuArgs, PathArgs, SceneArg,
};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use vksplat::camera::Camera;
use vksplat::output;
use vksplat::render::GpuRenderer;
use vksplat::sequence::{Existing, FrameRange, OutputPattern, ProgressStyle};

#[derive(Args)]
pub(crate) struct RenderArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArg,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    #[command(flatten)]
    pub(crate) path: PathArgs,
    /// Output: a file (.png or .exr), a pattern with {} / {:05} (frame number) or {name}
    /// (camera name), e.g. out/frame_{:05}.exr, or a directory (out/ gives
    /// out/frame_00000.png, ...).
    #[arg(short, long, value_name = "OUT", default_value = "render.png")]
    pub(crate) output: PathBuf,
    /// What to write: rgb, alpha, depth or rgb+depth [default: rgb for PNG, rgb+depth
    /// (R, G, B, A, Z) for EXR]. Depth PNGs are colour-mapped for looking at.
    #[arg(long, value_name = "MODE")]
    pub(crate) mode: Option<output::RenderMode>,
    /// Frames of the path to render: 100..200 (end exclusive), 100..=199, 100.., ..50 or 7.
    /// File names keep the frame's number in the whole path, so split runs give the files
    /// of one run.
    #[arg(long, value_name = "RANGE")]
    pub(crate) frames: Option<FrameRange>,
    /// Resume: skip frames whose files exist (write only the missing files of a frame).
    #[arg(long, conflicts_with = "overwrite")]
    pub(crate) skip_existing: bool,
    /// Replace output files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Image format of a directory output: png or exr.
    #[arg(long, value_name = "EXT", default_value = "png", value_parser = ["png", "exr"])]
    pub(crate) format: String,
    /// Write 16-bit PNG (colour and alpha) instead of 8-bit.
    #[arg(long)]
    pub(crate) png16: bool,
    /// Write EXR channels as 16-bit half floats instead of 32-bit floats.
    #[arg(long)]
    pub(crate) exr_half: bool,
    /// Depth range NEAR,FAR of colour-mapped depth PNGs (default: each frame's 1st-99th
    /// percentile; fix it for a steady video).
    #[arg(long, value_name = "NEAR,FAR", value_parser = parse_depth_range)]
    pub(crate) depth_range: Option<[f32; 2]>,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white").
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = parse_background)]
    pub(crate) background: [f32; 3],
    #[command(flatten)]
    pub(crate) filter: FilterArgs,
    /// Opacity compensation for scenes trained with antialiasing (mip) settings:
    /// opacity * sqrt(max(2.5e-5, det_before / det_after)) of the 0.3 dilation. On by
    /// default when the file records antialiased training (SPZ flag, SOG meta.json).
    #[arg(long)]
    pub(crate) antialiased: bool,
    /// Render without the compensation even when the file records antialiased training.
    #[arg(long, conflicts_with = "antialiased")]
    pub(crate) no_antialiased: bool,
    /// Render with the CPU reference renderer instead of the Vulkan pipeline.
    #[arg(long)]
    pub(crate) cpu: bool,
    /// Print the GPU time of each pipeline stage (timestamp queries; the mean over the
    /// frames of a path).
    #[arg(long)]
    pub(crate) timings: bool,
    /// Threads that encode and write images while the next frame renders (0: encode on
    /// the rendering thread).
    #[arg(long, value_name = "N", default_value_t = vksplat::sequence::default_encode_threads())]
    pub(crate) encode_threads: usize,
    /// No progress display (the summary is still printed).
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

pub(crate) fn render(args: &RenderArgs) -> Result<()> {
    let pattern = OutputPattern::parse(&args.output, &args.format).map_err(anyhow::Error::msg)?;
    let out_opts = output::OutputOptions {
        mode: args.mode,
        png16: args.png16,
        exr_half: args.exr_half,
        depth_range: args.depth_range,
    };
    // Fail on a bad file name before loading anything.
    output::plan_files(&pattern.path(0, "x"), &out_opts)?;
    let filter = args.filter.filter()?;
    let (scene, name) = load_scene(&args.scene)?;
    let total = scene.len();
    let scene = if filter.is_identity_for(&scene) {
        scene
    } else {
        let kept = filter.apply(&scene);
        eprintln!(
            "filters keep {} of {total} Gaussians (SH degree {})",
            kept.len(),
            kept.sh_degree
        );
        kept
    };
    let (cams, source) = camera_path(&args.view, &args.path, &args.scene, &scene)?;
    for (_, c) in &cams {
        c.validate()?;
    }
    let existing = if args.overwrite {
        Existing::Overwrite
    } else if args.skip_existing {
        Existing::Skip
    } else {
        Existing::Refuse
    };
    let plan = vksplat::sequence::plan(&cams, &pattern, args.frames, &out_opts, existing)?;
    if plan.removed_temporaries > 0 {
        eprintln!(
            "removed {} temporary file(s) left by an interrupted run",
            plan.removed_temporaries
        );
    }
    if plan.frames.is_empty() {
        eprintln!(
            "all {} frame(s) already exist; nothing to render",
            plan.skipped
        );
        return Ok(());
    }
    let antialiased = args.antialiased || (scene.antialiased && !args.no_antialiased);
    if scene.antialiased && !args.antialiased && !args.no_antialiased {
        eprintln!(
            "note: {name} records that it was trained with antialiasing; rendering with its opacity compensation (--no-antialiased turns it off)"
        );
    }
    let opts = vksplat::cpu::RenderOptions {
        background: args.background,
        antialiased,
    };
    let run_opts = vksplat::sequence::RunOptions {
        overwrite: args.overwrite,
        encode_threads: args.encode_threads,
        queue_depth: args.encode_threads.max(1) + 1,
        progress: if args.quiet {
            ProgressStyle::Quiet
        } else {
            ProgressStyle::Auto
        },
    };
    let act = scene.activated();
    let (summary, how) = if args.cpu {
        let mut render = |cam: &Camera| Ok(vksplat::cpu::render(&act, cam, &opts));
        let s = vksplat::sequence::run(&plan.frames, &mut render, &run_opts)?;
        (s, "on the CPU".to_string())
    } else {
        render_gpu(args, &act, &plan.frames, &opts, &run_opts)?
    };
    let first = &plan.frames[0];
    let what = if plan.frames.len() == 1 && plan.skipped == 0 {
        format!(
            "from camera \"{}\" of {source} at {}x{} -> {}",
            first.camera.name,
            first.camera.width,
            first.camera.height,
            first.files[0].path.display()
        )
    } else {
        format!(
            "{} frame(s) of {source} at {}x{}{} -> {}",
            summary.written,
            first.camera.width,
            first.camera.height,
            if plan.skipped > 0 {
                format!(" ({} skipped: already written)", plan.skipped)
            } else {
                String::new()
            },
            args.output.display()
        )
    };
    eprintln!(
        "rendered {name} ({} Gaussians) {what} {how} in {:.2} s: {:.2} frames/s; rendering {:.2} s, encoding {:.2} s on {}",
        scene.len(),
        summary.wall_s,
        summary.frames_per_s(),
        summary.render_s,
        summary.encode_s,
        match args.encode_threads {
            0 => "the rendering thread".to_string(),
            n => format!("{n} thread(s), overlapped"),
        }
    );
    Ok(())
}

pub(crate) fn render_gpu(
    args: &RenderArgs,
    scene: &vksplat::scene::ActivatedScene,
    frames: &[vksplat::sequence::FramePlan],
    opts: &vksplat::cpu::RenderOptions,
    run_opts: &vksplat::sequence::RunOptions,
) -> Result<(vksplat::sequence::Summary, String)> {
    let t0 = std::time::Instant::now();
    let ctx = args.gpu.context()?;
    if args.gpu.verbose {
        eprintln!("device: {}", ctx.info());
    }
    let t1 = std::time::Instant::now();
    let mut renderer = GpuRenderer::new(ctx)?;
    if args.gpu.verbose {
        eprintln!(
            "start-up: device {:.0} ms, shaders and pipelines {:.0} ms",
            (t1 - t0).as_secs_f64() * 1e3,
            t1.elapsed().as_secs_f64() * 1e3
        );
    }
    let gpu_scene = renderer.upload(scene)?;
    let mut stage_sums: Vec<(&'static str, f64)> = Vec::new();
    let mut frame_sum = 0.0;
    let mut last_stats = None;
    let mut render = |cam: &Camera| -> Result<vksplat::frame::Frame> {
        let frame = renderer.render(&gpu_scene, cam, opts)?;
        let t = renderer.timings();
        if stage_sums.is_empty() {
            stage_sums = t.stages().iter().map(|(s, _)| (*s, 0.0)).collect();
        }
        for (sum, (_, ms)) in stage_sums.iter_mut().zip(t.stages()) {
            sum.1 += ms;
        }
        frame_sum += t.total;
        last_stats = Some(renderer.stats().clone());
        Ok(frame)
    };
    let summary = vksplat::sequence::run(frames, &mut render, run_opts);
    let n = frames.len().max(1) as f64;
    if args.timings && !stage_sums.is_empty() {
        eprintln!("{:<12} {:>10}", "stage", "GPU ms");
        for (stage, ms) in &stage_sums {
            eprintln!("{stage:<12} {:>10.3}", ms / n);
        }
        eprintln!("{:<12} {:>10.3}", "frame", frame_sum / n);
        if let Some(st) = &last_stats {
            eprintln!(
                "visible Gaussians {}, tile pairs {}, key bits {} (last frame)",
                st.visible, st.pairs, st.key_bits
            );
        }
    }
    if args.gpu.verbose {
        eprintln!(
            "device memory: scene {} bytes, per-frame buffers {} bytes",
            gpu_scene.device_bytes(),
            renderer.frame_device_bytes()
        );
    }
    let summary = summary?;
    fail_on_validation_messages(renderer.ctx())?;
    let device = renderer.ctx().info().name.clone();
    Ok((summary, format!("on {device}")))
}
