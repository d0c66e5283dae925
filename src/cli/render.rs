//! `vksplat render`: one camera or a camera path to PNG/EXR files.

use super::common::{
    camera_path, check_output_dir, fail_on_validation_messages, load_scene, CameraArgs, FilterArgs,
    GpuArgs, KernelArg, PathArgs, SceneArg,
};
use super::{plural, values};
use anyhow::{bail, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use vksplat::camera::Camera;
use vksplat::output::{self, FileContent};
use vksplat::render::path::GpuPath;
use vksplat::render::GpuRenderer;
use vksplat::sequence::{Existing, FrameSelection, OutputPattern, ProgressStyle, Summary};
use vksplat::{note, outln};

/// Output of a single frame when `-o` is not given.
const DEFAULT_OUTPUT: &str = "render.png";
/// Output of a path of several frames when `-o` is not given.
const DEFAULT_SEQUENCE_OUTPUT: &str = "render/frame_{:05}.png";

#[derive(Args)]
#[command(after_help = "Examples:
  vksplat render scene.ply -o view.png
  vksplat render scene.ply --orbit 120 -o orbit/frame_{:05}.exr
  vksplat render model_dir/ --cameras cameras.json --camera 0,8,16 -o renders/{name}.png
  vksplat render scene.spz --cameras path.json --frames 100..200 -o out/ --format exr
  vksplat render scene.ply --orbit 120 -o orbit/f_%04d.png --skip-existing   # resume
  vksplat render scene.ply --orbit 1200 -o orbit/ --shard slurm   # a task of sbatch --array=0-7
  vksplat render scene.ply --orbit 1200 -o orbit/ --verify        # after the array: all there?
  vksplat render scene.ply --orbit 48 --width 320 --height 240 --export-colmap data/   # a data set to train on
  vksplat render moving.ply --time 0.5 --mode field-slice --slice-plane 0,0,0,0,0,1 -o t05.png
  vksplat render moving.ply --time-range 0,1 --time-frames 30 --mode field-max -o anim/frame_%04d.png

A time-varying scene (t_mean, t_scale per Gaussian, what `fit --time-column` writes) is
rendered at a time: --time T, or --time-range T0,T1 for an animation; without either it is
refused (there is no default time).")]
pub(crate) struct RenderArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArg,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    #[command(flatten)]
    pub(crate) path: PathArgs,
    /// Output: a file (.png or .exr), a pattern with {} / {:05} / %05d / ##### (frame
    /// number) or {name} (camera name), e.g. out/frame_{:05}.exr, or a directory (out/
    /// gives out/frame_00000.png, ...) [default: render.png for one frame,
    /// render/frame_{:05}.png for several].
    #[arg(short, long, value_name = "OUT")]
    pub(crate) output: Option<PathBuf>,
    /// What to write: rgb, rgba, alpha, depth, rgb+depth, features, field-slice,
    /// field-integral or field-max [default: rgb for PNG, rgb+depth (R, G, B, A, Z) for
    /// EXR]. rgba: PNG with a transparent background (straight colour; EXR as rgb). Depth
    /// PNGs are colour-mapped for looking at. features: the scene's feature channels
    /// blended like colour over 0, as EXR (feat.0 ... feat.K-1, A, Z) or .npy (H x W x K
    /// float32). field-*: the fitted field itself (the sum over Gaussians `fit` models) on
    /// the --slice-plane, integrated along each ray, or its maximum along each ray; EXR and
    /// .npy as features, PNG the --channel through a colour map (or --shader).
    #[arg(long, value_name = "MODE")]
    pub(crate) mode: Option<output::RenderMode>,
    /// Feature channels for the scene's Gaussians: an N x K NumPy array (float32 or
    /// float16, N the scene's Gaussian count, K 1..64), replacing any feat_* of the file.
    #[arg(long, value_name = "FILE.npy")]
    pub(crate) features: Option<PathBuf>,
    /// Neural shader: a per-pixel MLP (safetensors with a vksplat_mlp description; README
    /// "Neural shader") applied to the blended feature channels (and optionally the view
    /// direction and alpha). The colour written is alpha * MLP + (1 - alpha) * background.
    #[arg(long, value_name = "FILE.safetensors")]
    pub(crate) shader: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) field: Box<super::render_field::FieldArgs>,
    /// Frames of the path to render, numbered in the whole path (before --camera): 7,
    /// 0,3,7, 100..200 (end exclusive), 100..=199, 100.. or ..50. File names keep the
    /// frame's number, so split runs give the files of one run.
    #[arg(long, value_name = "SPEC")]
    pub(crate) frames: Option<FrameSelection>,
    /// A time-varying scene (t_mean, t_scale per Gaussian: `fit --time-column`) at time T:
    /// each Gaussian's opacity times exp(-((T - t_mean) / t_scale)^2 / 2) (0 beyond 4
    /// temporal scales), in every mode. Such a scene needs --time or --time-range.
    #[arg(long, value_name = "T", value_parser = values::any_f32, allow_hyphen_values = true, conflicts_with = "time_range")]
    pub(crate) time: Option<f32>,
    /// An animation of a time-varying scene: frame k of N at time T0 + (T1 - T0) k / (N - 1),
    /// N the path's frames (--orbit N, a camera file) or, for one camera, --time-frames N.
    #[arg(long, value_name = "T0,T1", value_parser = values::time_range, allow_hyphen_values = true)]
    pub(crate) time_range: Option<[f32; 2]>,
    /// --time-range from one camera: N frames of it, one per time.
    #[arg(long, value_name = "N", value_parser = values::int_in(1usize, 1_000_000), requires = "time_range")]
    pub(crate) time_frames: Option<usize>,
    /// Resume: skip frames whose files exist (write only the missing files of a frame).
    #[arg(long, conflicts_with = "overwrite")]
    pub(crate) skip_existing: bool,
    /// Render shard I of N (0-based) of the selected frames, a contiguous block of them, so
    /// N processes together render each frame once; `slurm` reads SLURM_ARRAY_TASK_ID,
    /// SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_MIN (a task of sbatch --array).
    #[arg(long, value_name = "I/N|slurm")]
    pub(crate) shard: Option<String>,
    /// Render nothing: check that every file of the selected frames (of the shard, with
    /// --shard) exists, decodes and has its camera's size; list the others and fail if any.
    #[arg(long, conflicts_with_all = ["overwrite", "skip_existing", "export_cameras"])]
    pub(crate) verify: bool,
    /// Spread the frames over several Vulkan devices of this machine, one renderer each:
    /// `all` (every usable device of the default device's type) or a list of indices or
    /// names, `0,1,3` (a device named twice gets two renderers).
    #[arg(long, value_name = "all|N,N,..", conflicts_with_all = ["cpu", "device"])]
    pub(crate) devices: Option<String>,
    /// Replace output files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Image format of a directory output (-o out/): png or exr [default: png].
    #[arg(long, value_name = "EXT", value_parser = ["png", "exr"])]
    pub(crate) format: Option<String>,
    /// Write 16-bit PNG (colour and alpha) instead of 8-bit.
    #[arg(long)]
    pub(crate) png16: bool,
    /// Write EXR R, G, B, A as 16-bit half floats instead of 32-bit floats (Z stays
    /// 32-bit).
    #[arg(long)]
    pub(crate) exr_half: bool,
    /// Keep the background in EXR R, G, B (the reference's image, as PNG shows it). By
    /// default EXR colour is premultiplied over transparent black, ready to composite.
    #[arg(long)]
    pub(crate) exr_background: bool,
    /// Also write the rendered cameras (after --camera and resizing) as an INRIA
    /// cameras.json, which --cameras reads back.
    #[arg(long, value_name = "FILE.json")]
    pub(crate) export_cameras: Option<PathBuf>,
    /// Instead of -o: write the selected frames as a COLMAP data set in DIR, for training
    /// (or testing a trainer) on a known scene: DIR/images/NAME.png as rendered (colour
    /// over --background), DIR/sparse/0/{cameras,images,points3D}.txt with the cameras
    /// (PINHOLE) and every Nth Gaussian centre and its DC colour as the points (N chosen
    /// so that at most 100,000 are written; said).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["output", "verify", "shard", "devices", "mode", "skip_existing", "export_cameras"])]
    pub(crate) export_colmap: Option<PathBuf>,
    /// Depth range NEAR,FAR of colour-mapped depth PNGs (default: each frame's 1st-99th
    /// percentile; fix it for a steady video).
    #[arg(long, value_name = "NEAR,FAR", value_parser = values::depth_range, allow_hyphen_values = true)]
    pub(crate) depth_range: Option<[f32; 2]>,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white").
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = values::background, allow_hyphen_values = true)]
    pub(crate) background: [f32; 3],
    #[command(flatten)]
    pub(crate) filter: FilterArgs,
    /// Multiply every Gaussian's scales by M before projecting (the reference rasterizer's
    /// scaling_modifier; < 1 shrinks the splats, > 1 grows them).
    #[arg(long, value_name = "M", default_value_t = 1.0, value_parser = values::positive_f32)]
    pub(crate) scale_modifier: f32,
    // Boxed: keeps the Render variant of main's Command enum small.
    #[command(flatten)]
    pub(crate) transform: Box<super::transform::TransformArgs>,
    /// Opacity compensation for scenes trained with antialiasing (mip) settings:
    /// opacity * sqrt(max(2.5e-5, det_before / det_after)) of the 0.3 dilation. On by
    /// default when the file records antialiased training (SPZ flag, SOG meta.json).
    #[arg(long)]
    pub(crate) antialiased: bool,
    /// Render without the compensation even when the file records antialiased training.
    #[arg(long, conflicts_with = "antialiased")]
    pub(crate) no_antialiased: bool,
    #[command(flatten)]
    pub(crate) kernel: KernelArg,
    /// Render with the CPU reference renderer instead of the Vulkan pipeline.
    #[arg(long)]
    pub(crate) cpu: bool,
    /// Print the time of each pipeline stage: GPU timestamps, or with --cpu the wall
    /// clock of the CPU reference's phases (the mean over the frames of a path).
    #[arg(long)]
    pub(crate) timings: bool,
    /// Threads that encode and write images while the next frame renders (0: encode on
    /// the rendering thread; at most 64).
    #[arg(long, value_name = "N", default_value_t = vksplat::sequence::default_encode_threads(), value_parser = values::int_in(0usize, 64))]
    pub(crate) encode_threads: usize,
    /// Frames of a path in flight on the device: 2 records and submits frame n+1 before
    /// frame n is read back and encoded (two sets of per-frame buffers); 1 renders one
    /// frame at a time. The files are the same either way [default: 2].
    #[arg(long, value_name = "N", value_parser = values::int_in(1usize, 2))]
    pub(crate) frames_in_flight: Option<usize>,
    /// Compact device copy of the scene: SH coefficients, axis scales and rotations as fp16
    /// (centres and opacities stay f32): 16 bytes per Gaussian fewer, plus 2 per SH float
    /// (112 in all at SH degree 3). Not exact: frames carry fp16's rounding of those values.
    #[arg(long)]
    pub(crate) compact: bool,
    /// No progress display (the summary is still printed).
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// The render was stopped by Ctrl-C or SIGTERM; `main` prints the message without
/// "error:" and exits with status 130.
#[derive(Debug)]
pub(crate) struct Interrupted(pub(crate) String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// A flag set by the first Ctrl-C or SIGTERM, so a path stops after the frames in hand
/// are written completely; a second signal ends the process at once.
pub(crate) fn interrupt_flag() -> Arc<AtomicBool> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [SIGINT, SIGTERM] {
        // Registered first, so it sees the flag as the previous signal left it.
        let _ = signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&flag));
        let _ = signal_hook::flag::register(signal, Arc::clone(&flag));
    }
    flag
}

/// Refuses output options that the chosen output would silently ignore.
fn check_output_options(
    args: &RenderArgs,
    output: &Path,
    pattern: &OutputPattern,
    opts: &output::OutputOptions,
) -> Result<()> {
    if args.format.is_some() && !vksplat::sequence::names_directory(output) {
        bail!(
            "--format sets the image format of a directory output (-o out/); {} names its format by its extension",
            output.display()
        );
    }
    let files = output::plan_files(&pattern.path(0, "x"), None, opts)?;
    let writes = |pred: fn(&FileContent) -> bool| files.iter().any(|f| pred(&f.content));
    if args.png16
        && !writes(|c| {
            matches!(
                c,
                FileContent::PngColor { .. }
                    | FileContent::PngRgba { .. }
                    | FileContent::PngAlpha { .. }
            )
        })
    {
        bail!(
            "--png16 applies to PNG colour and alpha files; {} writes none (EXR is float, depth PNGs are colour-mapped 8-bit)",
            output.display()
        );
    }
    if args.exr_half
        && !writes(|c| matches!(c, FileContent::Exr(_) | FileContent::ExrFeatures { .. }))
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
    if args.depth_range.is_some() && !writes(|c| matches!(c, FileContent::PngDepth { .. })) {
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
fn export_cameras(path: &Path, cams: &[(usize, Camera)], args: &RenderArgs) -> Result<()> {
    let json = vksplat::camera::inria::to_json(cams)?;
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

/// Refuses Vulkan-only options with `--cpu`.
fn check_cpu_options(args: &RenderArgs) -> Result<()> {
    let g = &args.gpu;
    let gpu_only = [
        ("--device", g.device.is_some()),
        ("--memory-limit", g.memory_limit.is_some()),
        ("--validate", g.validate),
        ("--frames-in-flight", args.frames_in_flight.is_some()),
        ("--compact", args.compact),
    ];
    if let Some((flag, _)) = gpu_only.iter().find(|(_, set)| *set) {
        bail!("{flag} applies to the Vulkan pipeline; --cpu renders with the CPU reference");
    }
    Ok(())
}

pub(crate) fn render(args: &RenderArgs) -> Result<()> {
    if args.cpu {
        check_cpu_options(args)?;
    }
    let shard = super::common::shard(args.shard.as_deref())?;
    let out_opts = output::OutputOptions {
        mode: args.mode,
        png16: args.png16,
        exr_half: args.exr_half,
        depth_range: args.depth_range,
        background: args.background,
        exr_background: args.exr_background,
    };
    let format = args.format.as_deref().unwrap_or("png");
    // Shards never write the same file: the first one writes the whole path's cameras.
    let exports_cameras = shard.map_or(true, |s| s.index == 0);
    if let Some(path) = &args.export_cameras {
        if !args.skip_existing && exports_cameras {
            super::common::check_output_file(path, args.overwrite)?;
        }
    }
    // Bad names and unwritable folders are reported before anything is loaded.
    let explicit = match &args.output {
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
    let filter = args.filter.filter()?;
    let transform = args.transform.transform()?;
    let (mut scene, name) = load_scene(&args.scene)?;
    if let Some(file) = &args.features {
        vksplat::scene::features::attach_npy(&mut scene, file)?;
    }
    let time = time_choice(args, &scene, &name)?;
    let field_mode = args.mode.filter(|m| m.is_field());
    super::render_field::check_options(args, field_mode)?;
    if field_mode.is_some() && scene.feature_count == 0 {
        bail!("--mode {} renders the fitted field, its feature channels, but {name} has none; fit one with `vksplat fit` or give channels with --features FILE.npy", super::render_field::mode_name(field_mode));
    }
    let render_features = args.mode == Some(output::RenderMode::Features);
    if render_features && scene.feature_count == 0 {
        bail!("--mode features needs feature channels, but {name} has none; give them as feat_* PLY properties or with --features FILE.npy");
    }
    let shader = match &args.shader {
        Some(path) => {
            if render_features {
                bail!("--shader writes the shaded colour and --mode features the feature channels; choose one");
            }
            if field_mode.is_some() && !super::render_field::writes_png(args) {
                bail!("--shader colours a field render's PNG; EXR and .npy outputs hold the channels themselves");
            }
            let mlp = vksplat::mlp::Mlp::load(path)?;
            mlp.check_channels(scene.feature_count)
                .map_err(|e| anyhow::anyhow!("{}: {e} ({name})", path.display()))?;
            Some(mlp)
        }
        None => None,
    };
    let scene = super::transform::apply(transform.as_ref(), scene)?;
    let total = scene.len();
    let scene = if filter.is_identity_for(&scene) {
        scene
    } else {
        let kept = filter.apply(&scene);
        note!(
            "filters keep {} of {total} Gaussians (SH degree {})",
            kept.len(),
            kept.sh_degree
        );
        kept
    };
    // The default camera frames the Gaussians of every time, so a scene looks the same
    // from --time T as from the frame of --time-range at T.
    let mut path = camera_path(&args.view, &args.path, &args.scene, &scene)?;
    let mut animation = None;
    let scene = match time {
        TimeChoice::Static => scene,
        TimeChoice::At(t) => {
            let at = scene.at_time(t);
            note!(
                "at time {t}: {} of {} contribute (within 4 temporal scales)",
                at.len(),
                plural(scene.len(), "Gaussian")
            );
            at
        }
        TimeChoice::Range(range) => {
            animation = Some(Animation::new(args, range, &mut path, scene.clone())?);
            scene
        }
    };
    if let Some(file) = &args.export_cameras {
        if exports_cameras {
            export_cameras(file, &path.cameras, args)?;
        }
    }
    if let Some(frames) = &args.frames {
        frames.check(path.len).map_err(anyhow::Error::msg)?;
    }
    if let Some(dir) = &args.export_colmap {
        if animation.is_some() {
            bail!("--export-colmap writes a data set of one scene; give one --time instead of --time-range");
        }
        return export_colmap(args, dir, &scene, &name, &path.cameras, shader.as_ref());
    }
    let selected = path
        .cameras
        .iter()
        .filter(|(k, _)| args.frames.as_ref().map_or(true, |f| f.contains(*k)))
        .count();
    let (output_name, pattern) = match explicit {
        Some(p) => p,
        None => {
            let out = PathBuf::from(if selected > 1 {
                DEFAULT_SEQUENCE_OUTPUT
            } else {
                DEFAULT_OUTPUT
            });
            let pattern = OutputPattern::parse(&out, format).map_err(anyhow::Error::msg)?;
            check_output_options(args, &out, &pattern, &out_opts)?;
            if selected > 1 {
                note!(
                    "no -o given: writing {} frames to {}",
                    selected,
                    out.display()
                );
            }
            (out, pattern)
        }
    };
    let existing = if args.overwrite {
        Existing::Overwrite
    } else if args.skip_existing {
        Existing::Skip
    } else {
        Existing::Refuse
    };
    // Every shard plans the whole selection, so shards that would write the same file
    // are refused by each of them; then it keeps its block.
    let frames =
        vksplat::sequence::plan_frames(&path.cameras, &pattern, args.frames.as_ref(), &out_opts)?;
    let frames = match shard {
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
                    return Ok(());
                }
            }
            mine
        }
        None => frames,
    };
    if args.verify {
        return verify(&frames);
    }
    let plan = vksplat::sequence::prepare(frames, existing)?;
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
        return Ok(());
    }
    let antialiased = args.antialiased || (scene.antialiased && !args.no_antialiased);
    if scene.antialiased && !args.antialiased && !args.no_antialiased {
        note!(
            "note: {name} records that it was trained with antialiasing; rendering with its opacity compensation (--no-antialiased turns it off)"
        );
    }
    let opts = vksplat::cpu::RenderOptions {
        background: args.background,
        antialiased,
        scale_modifier: args.scale_modifier,
        kernel: args.kernel.resolve(&scene, &name),
        ..Default::default()
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
        skip_existing: args.skip_existing,
        cancel: Some(interrupt_flag()),
        frames_in_flight: args.frames_in_flight.unwrap_or(2),
    };
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
    let (summary, how) = if let Some(mode) = field_mode {
        if args.devices.is_some() {
            bail!("--devices spreads colour and feature renders over devices; the field modes render on one (drop --devices)");
        }
        super::render_field::render(
            args,
            &act,
            animation.as_ref(),
            opts.kernel,
            mode,
            &plan.frames,
            &run_opts,
            shader.as_ref(),
        )?
    } else if let (Some(_), Some(_)) = (&args.devices, &animation) {
        bail!("--devices spreads a path over devices; an animation (--time-range) renders on one (drop --devices)");
    } else if let Some(devices) = &args.devices {
        render_on_devices(&job, devices)?
    } else if args.cpu {
        render_cpu(&job)?
    } else {
        render_gpu(&job, args.gpu.context()?)?
    };
    if summary.interrupted {
        return Err(Interrupted(format!(
            "interrupted after {} of {}; every file written is complete; run the same command with --skip-existing to finish",
            summary.written,
            plural(plan.frames.len(), "frame")
        ))
        .into());
    }
    let first = &plan.frames[0];
    let what = if plan.frames.len() == 1 && plan.skipped == 0 {
        let from = if path.source == "the default camera" {
            "from the default camera".to_string()
        } else {
            format!("from camera \"{}\" of {}", first.camera.name, path.source)
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
            path.source,
            first.camera.width,
            first.camera.height,
            if plan.skipped > 0 {
                format!(" ({} skipped: already written)", plan.skipped)
            } else {
                String::new()
            },
            output_name.display()
        )
    };
    note!(
        "rendered {name} ({}) {what} {how} in {:.2} s: {:.2} frames/s; rendering {:.2} s, encoding {:.2} s on {}",
        plural(scene.len(), "Gaussian"),
        summary.wall_s,
        summary.frames_per_s(),
        summary.render_s,
        summary.encode_s,
        match args.encode_threads {
            0 => "the rendering thread".to_string(),
            n => format!("{}, overlapped", plural(n, "thread")),
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

/// How `--time` and `--time-range` apply to the scene.
enum TimeChoice {
    /// A static scene.
    Static,
    /// One time (`--time`).
    At(f32),
    /// An animation (`--time-range T0,T1`).
    Range([f32; 2]),
}

/// Checks `--time` / `--time-range` against the scene: a time-varying scene needs one, a
/// static one takes neither.
fn time_choice(args: &RenderArgs, scene: &vksplat::scene::Scene, name: &str) -> Result<TimeChoice> {
    let flag = if args.time.is_some() {
        "--time"
    } else {
        "--time-range"
    };
    match (scene.time_range(), args.time, args.time_range) {
        (None, None, None) => Ok(TimeChoice::Static),
        (None, _, _) if scene.time.is_some() => Ok(TimeChoice::Static), // time-varying but empty
        (None, _, _) => bail!(
            "{flag} applies to a time-varying scene (t_mean, t_scale per Gaussian, as `vksplat fit --time-column` writes), but {name} is static; drop {flag}"
        ),
        (Some((lo, hi)), None, None) => bail!(
            "{name} is time-varying (its Gaussians' temporal means run from {lo} to {hi}); render it at a time with --time T, or as an animation with --time-range {lo},{hi} --time-frames N"
        ),
        (Some(_), Some(t), _) => Ok(TimeChoice::At(t)),
        (Some(_), None, Some(r)) => Ok(TimeChoice::Range(r)),
    }
}

/// `--time-range`: the time-varying scene (transformed and filtered) and the time of each
/// frame of the path; frame `k` of `n` shows the scene at `t0 + (t1 - t0) k / (n - 1)`.
pub(crate) struct Animation {
    scene: vksplat::scene::Scene,
    range: [f32; 2],
    frames: usize,
}

impl Animation {
    /// The animation over `path`'s frames, or over `--time-frames N` copies of its one
    /// camera (which then become the path).
    fn new(
        args: &RenderArgs,
        range: [f32; 2],
        path: &mut super::common::CameraPath,
        scene: vksplat::scene::Scene,
    ) -> Result<Animation> {
        let frames = match (args.time_frames, path.cameras.len()) {
            (Some(n), 1) => {
                let cam = path.cameras[0].1.clone();
                path.cameras = (0..n).map(|k| (k, cam.clone())).collect();
                path.len = n;
                path.source = format!("{} at {}", path.source, plural(n, "time"));
                n
            }
            (Some(n), m) if path.len != n || m != path.len => bail!(
                "--time-frames {n} repeats one camera, but the path has {}; drop --time-frames to spread --time-range over the path's frames",
                plural(path.len, "frame")
            ),
            (_, 1) if path.len == 1 => bail!(
                "--time-range {},{} from one camera needs the number of frames: --time-frames N",
                range[0],
                range[1]
            ),
            _ => path.len,
        };
        if args.frames_in_flight.is_some() {
            bail!("--frames-in-flight does not apply to --time-range: each frame uploads the scene at its time and renders on its own");
        }
        Ok(Animation {
            scene,
            range,
            frames,
        })
    }

    /// The time of frame `index`.
    pub(crate) fn time(&self, index: usize) -> f32 {
        if self.frames <= 1 {
            return self.range[0];
        }
        let f = index as f64 / (self.frames - 1) as f64;
        (f64::from(self.range[0]) + f * (f64::from(self.range[1]) - f64::from(self.range[0])))
            as f32
    }

    /// The scene as frame `index` shows it ([`vksplat::scene::Scene::at_time`]), activated.
    pub(crate) fn scene(&self, index: usize) -> vksplat::scene::ActivatedScene {
        self.scene.at_time(self.time(index)).activated()
    }
}

/// What each renderer of `render` gets: the command's arguments, the scene, the frames to
/// render and how to render and write them.
#[derive(Clone, Copy)]
struct Job<'a> {
    args: &'a RenderArgs,
    scene: &'a vksplat::scene::ActivatedScene,
    /// `--time-range`: each frame's scene (then `scene` is unused).
    animation: Option<&'a Animation>,
    frames: &'a [vksplat::sequence::FramePlan],
    opts: &'a vksplat::cpu::RenderOptions,
    run_opts: &'a vksplat::sequence::RunOptions,
    /// Render the feature channels (`--mode features`, or for `shader`).
    features: bool,
    shader: Option<&'a vksplat::mlp::Mlp>,
}

/// Sums of per-stage times over the frames of a path, printed by `--timings`.
#[derive(Default)]
struct StageSums {
    stages: Vec<(&'static str, f64)>,
    total: f64,
    frames: usize,
}

impl StageSums {
    fn add(&mut self, stages: &[(&'static str, f64)], total: f64) {
        if self.stages.is_empty() {
            self.stages = stages.iter().map(|(s, _)| (*s, 0.0)).collect();
        }
        for (sum, (_, ms)) in self.stages.iter_mut().zip(stages) {
            sum.1 += ms;
        }
        self.total += total;
        self.frames += 1;
    }

    /// The mean of each stage, as a table on stderr.
    fn print(&self, unit: &str) {
        if self.frames == 0 {
            return;
        }
        let n = self.frames as f64;
        note!("{:<12} {:>10}", "stage", unit);
        for (stage, ms) in &self.stages {
            note!("{stage:<12} {:>10.3}", ms / n);
        }
        note!("{:<12} {:>10.3}", "frame", self.total / n);
    }
}

fn render_cpu(job: &Job) -> Result<(Summary, String)> {
    let (scene, opts, shader) = (job.scene, job.opts, job.shader);
    if job.args.gpu.verbose {
        note!(
            "renderer: the CPU reference on {}",
            plural(rayon::current_num_threads(), "thread")
        );
    }
    let mut sums = StageSums::default();
    let mut pairs = 0;
    let mut render = |p: &vksplat::sequence::FramePlan| {
        let cam = &p.camera;
        let at_time = job.animation.map(|a| a.scene(p.index));
        let scene = at_time.as_ref().unwrap_or(scene);
        let (mut frame, t) = if job.features || shader.is_some() {
            vksplat::cpu::render_features_timed(scene, cam, opts)
        } else {
            vksplat::cpu::render_timed(scene, cam, opts)
        };
        let mut stages = t.stages().to_vec();
        let mut total = t.total;
        if let Some(mlp) = shader {
            let start = std::time::Instant::now();
            frame.color = vksplat::mlp::shade(
                mlp,
                cam,
                &frame.features,
                frame.feature_count,
                &frame.alpha,
                opts.background,
            );
            let ms = start.elapsed().as_secs_f64() * 1e3;
            stages.push(("shade", ms));
            total += ms;
            frame.features.clear();
            frame.feature_count = 0;
        }
        sums.add(&stages, total);
        pairs = t.pairs;
        Ok(frame)
    };
    let summary = vksplat::sequence::run_each(job.frames, &mut render, job.run_opts);
    if job.args.timings {
        sums.print("CPU ms");
        note!("tile pairs {pairs} (last frame)");
    }
    Ok((summary?, "on the CPU".to_string()))
}

/// Points3D written by `--export-colmap` at most.
const EXPORT_COLMAP_POINTS: usize = 100_000;

/// `--export-colmap DIR`: the selected cameras rendered (on the device, or the CPU
/// reference with --cpu or --shader) into a COLMAP data set.
fn export_colmap(
    args: &RenderArgs,
    dir: &Path,
    scene: &vksplat::scene::Scene,
    name: &str,
    cameras: &[(usize, Camera)],
    shader: Option<&vksplat::mlp::Mlp>,
) -> Result<()> {
    let cams: Vec<Camera> = cameras
        .iter()
        .filter(|(k, _)| args.frames.as_ref().map_or(true, |f| f.contains(*k)))
        .map(|(_, c)| c.clone())
        .collect();
    if cams.is_empty() {
        bail!("--export-colmap: no cameras selected");
    }
    let stride = scene.len().div_ceil(EXPORT_COLMAP_POINTS).max(1);
    let opts = vksplat::cpu::RenderOptions {
        background: args.background,
        scale_modifier: args.scale_modifier,
        kernel: args.kernel.resolve(scene, name),
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(cams.len() as u64)
    };
    let act = scene.activated();
    // The device renders unless --cpu or a shader (shaded on the CPU) asks otherwise.
    let mut gpu = if args.cpu || shader.is_some() {
        None
    } else {
        let renderer = GpuRenderer::new(args.gpu.context()?)?;
        let gpu_scene = renderer.upload(&act)?;
        Some((renderer, gpu_scene))
    };
    let how = if gpu.is_some() {
        "on the device"
    } else {
        "with the CPU reference"
    };
    vksplat::train::data::write_dataset(dir, scene, &cams, stride, args.overwrite, &mut |cam| {
        bar.inc(1);
        match (&mut gpu, shader) {
            (Some((renderer, gpu_scene)), _) => renderer
                .render(gpu_scene, cam, &opts)
                .map_err(|e| e.to_string()),
            (None, Some(mlp)) => {
                let mut frame = vksplat::cpu::render_features(&act, cam, &opts);
                frame.color = vksplat::mlp::shade(
                    mlp,
                    cam,
                    &frame.features,
                    scene.feature_count,
                    &frame.alpha,
                    opts.background,
                );
                Ok(frame)
            }
            (None, None) => Ok(vksplat::cpu::render(&act, cam, &opts)),
        }
    })?;
    if let Some((renderer, gpu_scene)) = gpu {
        drop(gpu_scene);
        fail_on_validation_messages(renderer.ctx())?;
    }
    bar.finish_and_clear();
    outln!(
        "wrote a COLMAP data set of {name}: {} rendered {how} at {}x{} and {} ({}) in {:.2} s -> {}",
        plural(cams.len(), "image"),
        cams[0].width,
        cams[0].height,
        plural(scene.len().div_ceil(stride), "point"),
        if stride == 1 {
            "every Gaussian centre".to_string()
        } else {
            format!("one Gaussian centre in {stride}")
        },
        t.elapsed().as_secs_f64(),
        dir.display()
    );
    Ok(())
}

/// `--verify`: lists the frames whose files are missing, unreadable or of the wrong size
/// on stdout, and fails when there are any.
fn verify(frames: &[vksplat::sequence::FramePlan]) -> Result<()> {
    let files: usize = frames.iter().map(|f| f.files.len()).sum();
    let problems = vksplat::sequence::verify(frames);
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

/// `--devices`: one renderer per device, each on its own thread with a contiguous block
/// of the frames (the split of `--shard`); the progress is each block's summary.
fn render_on_devices(job: &Job, devices: &str) -> Result<(Summary, String)> {
    let Job { args, frames, .. } = *job;
    let chosen: Vec<String> = if devices.trim() == "all" {
        args.gpu
            .context()?
            .info()
            .same_kind_devices
            .iter()
            .map(|i| i.to_string())
            .collect()
    } else {
        devices
            .split(',')
            .map(|d| d.trim().to_string())
            .filter(|d| !d.is_empty())
            .collect()
    };
    if chosen.is_empty() {
        bail!("--devices {devices:?}: expected all or a list of device indices or names, e.g. 0,1");
    }
    let t0 = std::time::Instant::now();
    let workers = chosen.len().min(frames.len());
    let run_opts = vksplat::sequence::RunOptions {
        progress: ProgressStyle::Quiet,
        ..job.run_opts.clone()
    };
    let results: Vec<Result<(Summary, String)>> = std::thread::scope(|s| {
        let handles: Vec<_> = chosen[..workers]
            .iter()
            .enumerate()
            .map(|(w, device)| {
                let block = vksplat::shard::Shard {
                    index: w,
                    count: workers,
                }
                .range(frames.len());
                let run_opts = &run_opts;
                s.spawn(move || {
                    let ctx = args.gpu.context_on(Some(device))?;
                    let block = &frames[block];
                    let part = Job {
                        frames: block,
                        run_opts,
                        ..*job
                    };
                    let (summary, how) = render_gpu(&part, ctx)?;
                    note!(
                        "device {device}: {} {how} (frames {}..={})",
                        plural(summary.written, "frame"),
                        block[0].index,
                        block[block.len() - 1].index
                    );
                    Ok((summary, how))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("a device's render thread panicked")))
            })
            .collect()
    });
    let mut total = Summary::default();
    let mut names = Vec::new();
    for r in results {
        let (s, how) = r?;
        total.written += s.written;
        total.render_s += s.render_s;
        total.encode_s += s.encode_s;
        total.appeared += s.appeared;
        total.interrupted |= s.interrupted;
        names.push(how);
    }
    total.wall_s = t0.elapsed().as_secs_f64();
    names.dedup();
    Ok((
        total,
        format!("{} ({})", names.join(", "), plural(workers, "renderer")),
    ))
}

fn render_gpu(job: &Job, ctx: vksplat::gpu::GpuContext) -> Result<(Summary, String)> {
    let Job {
        args,
        scene,
        animation,
        frames,
        opts,
        run_opts,
        features,
        shader,
    } = *job;
    let t0 = std::time::Instant::now();
    if args.gpu.verbose {
        note!("device: {}", ctx.info());
        note!(
            "memory budget: {} bytes ({})",
            ctx.info().memory_budget,
            ctx.info().budget_source.describe()
        );
    }
    let mut renderer = GpuRenderer::new(ctx)?;
    renderer.set_compact(args.compact);
    if args.gpu.verbose {
        note!(
            "start-up: device {:.0} ms (pipelines are built when a frame first needs them)",
            t0.elapsed().as_secs_f64() * 1e3
        );
    }
    let gpu_shader = match shader {
        Some(m) => Some(vksplat::render::shade::GpuShader::new(renderer.ctx(), m)?),
        None => None,
    };
    let mut sums = StageSums::default();
    let mut last_stats = None;
    if let Some(anim) = animation {
        // Each frame its own scene: uploaded, rendered, dropped.
        let mut device_bytes = 0;
        let summary = vksplat::sequence::run_each(
            frames,
            &mut |p| {
                let at_time = anim.scene(p.index);
                let gpu_scene = renderer.upload(&at_time)?;
                device_bytes = gpu_scene.device_bytes();
                let frame = if features || shader.is_some() {
                    let f = renderer.upload_features(&at_time)?;
                    match &gpu_shader {
                        Some(s) => renderer.render_shaded(&gpu_scene, &f, s, &p.camera, opts)?,
                        None => renderer.render_features(&gpu_scene, &f, &p.camera, opts)?,
                    }
                } else {
                    renderer.render(&gpu_scene, &p.camera, opts)?
                };
                sums.add(&renderer.timings().stages(), renderer.timings().total);
                Ok(frame)
            },
            run_opts,
        );
        if args.timings {
            sums.print("GPU ms");
        }
        if args.gpu.verbose {
            note!("device memory: scene {device_bytes} bytes (the last frame's)");
        }
        let summary = summary?;
        fail_on_validation_messages(renderer.ctx())?;
        let device = renderer.ctx().info().name.clone();
        return Ok((summary, format!("on {device}")));
    }
    let gpu_scene = renderer.upload(scene)?;
    let gpu_features = if features || shader.is_some() {
        Some(renderer.upload_features(scene)?)
    } else {
        None
    };
    let summary = {
        let mut source = GpuPath::new(&mut renderer, &gpu_scene, opts, run_opts.frames_in_flight)
            .on_frame(|t, stats| {
                sums.add(&t.stages(), t.total);
                last_stats = Some(stats.clone());
            });
        if let Some(f) = &gpu_features {
            source = source.with_features(f, gpu_shader.as_ref());
        }
        vksplat::sequence::run_pipelined(frames, &mut source, run_opts)
    };
    if args.timings {
        sums.print("GPU ms");
        if let Some(st) = &last_stats {
            note!(
                "visible Gaussians {}, tile pairs {}, key bits {} (last frame)",
                st.visible,
                st.pairs,
                st.key_bits
            );
        }
    }
    if args.gpu.verbose {
        let (pipelines, ms) = renderer.pipelines_built();
        note!("pipelines: {pipelines} stages built in {ms:.0} ms");
        note!(
            "device memory: scene {} bytes, per-frame buffers {} bytes ({})",
            gpu_scene.device_bytes(),
            renderer.frame_device_bytes(),
            match renderer.frame_sets() {
                1 => "one frame in flight".to_string(),
                n => format!("{n} frames in flight, a set each"),
            }
        );
    }
    let summary = summary?;
    fail_on_validation_messages(renderer.ctx())?;
    let device = renderer.ctx().info().name.clone();
    Ok((summary, format!("on {device}")))
}
