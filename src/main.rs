//! The `vksplat` command line.

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use vksplat::camera::{self, Camera};
use vksplat::gpu::{ContextOptions, GpuContext};
use vksplat::output;
use vksplat::render::GpuRenderer;
use vksplat::scene::filter::SceneFilter;
use vksplat::scene::{self, Scene};
use vksplat::sequence::{Existing, FrameRange, OutputPattern, ProgressStyle};

#[derive(Parser)]
#[command(
    name = "vksplat",
    version,
    about = "3D Gaussian Splatting renderer (Vulkan compute + exact CPU reference)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to a PNG or EXR image.
    Render(RenderArgs),
    /// Print a scene's size, bounds and parameter statistics.
    Info(SceneArg),
    /// Render the same camera repeatedly and report per-stage GPU times.
    Bench(BenchArgs),
    /// Write a synthetic scene (seeded) as an INRIA PLY, for scaling benchmarks.
    Gen(GenArgs),
    /// Convert a scene (any readable format) to .ply, .splat or .spz, chosen by OUT's extension.
    Convert(ConvertArgs),
}

#[derive(Args)]
struct ConvertArgs {
    /// Input scene: PLY, compressed PLY, .splat, .spz, SOG (.sog or directory) or a model directory.
    input: PathBuf,
    /// Output file: .ply (INRIA, lossless), .splat or .spz (SPZ v3, gzip).
    output: PathBuf,
    /// Write at most this SH degree (higher bands are dropped).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=3))]
    sh_degree: Option<u32>,
    /// Drop Gaussians whose largest axis scale (world units) is above this.
    #[arg(long)]
    max_scale: Option<f32>,
    /// Drop Gaussians whose opacity is below this (0..1).
    #[arg(long)]
    min_opacity: Option<f32>,
    /// Keep only Gaussians whose centre lies in this box.
    #[arg(long, value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", value_parser = vksplat::scene::filter::parse_crop, allow_hyphen_values = true)]
    crop: Option<[[f32; 3]; 2]>,
    /// Replace the output file if it exists.
    #[arg(long)]
    overwrite: bool,
}

#[derive(Args)]
struct GenArgs {
    /// Number of Gaussians (e.g. 100000 or 1e5).
    #[arg(value_parser = vksplat::bench::parse_count)]
    count: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// SH degree (0..=3).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=3))]
    sh_degree: u32,
    /// Output .ply file.
    #[arg(short, long)]
    output: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    overwrite: bool,
}

/// Where the camera comes from and at which resolution.
#[derive(Args)]
struct CameraArgs {
    /// Camera file: INRIA cameras.json, a COLMAP sparse model (folder, or cameras/images
    /// .txt/.bin), a nerfstudio camera_path.json or a vksplat keyframe JSON (see
    /// docs/cameras.md); the format is detected from the content.
    #[arg(long, value_name = "FILE")]
    cameras: Option<PathBuf>,
    /// Cameras of the path: all, an index, a list 0,3,7, a range 10..20 (end
    /// exclusive) or 10..=20, or img_names [default: all; a single output file needs
    /// exactly one].
    #[arg(long, value_name = "SPEC")]
    camera: Option<String>,
    /// Output width in pixels (alone: keeps the aspect ratio).
    #[arg(long)]
    width: Option<u32>,
    /// Output height in pixels (alone: keeps the aspect ratio).
    #[arg(long)]
    height: Option<u32>,
    /// Scale the camera's resolution (focal lengths scale with it).
    #[arg(long, conflicts_with_all = ["width", "height"])]
    scale: Option<f32>,
}

#[derive(Args)]
struct BenchArgs {
    /// Scene (.ply or model directory); not needed with --sweep gaussians=...
    scene: Option<PathBuf>,
    /// Use the built-in demo scene.
    #[arg(long, conflicts_with = "scene")]
    demo: bool,
    #[command(flatten)]
    view: CameraArgs,
    /// Sweep: `gaussians=1e4,1e5,...` (synthetic scenes from `vksplat gen`) and/or
    /// `resolution=720p,1080p,4k,WxH`; repeat the flag for both (all combinations run).
    #[arg(long, value_name = "AXIS=V1,V2,...")]
    sweep: Vec<String>,
    /// Seed of the synthetic scenes of a Gaussians sweep.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// SH degree of the synthetic scenes of a Gaussians sweep.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=3))]
    sh_degree: u32,
    /// Write the report(s) as JSON.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Write the report(s) as CSV (one row per stage).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Write an SVG plot of the sweep (stacked stage times and a stage breakdown).
    #[arg(long, value_name = "FILE.svg")]
    plot: Option<PathBuf>,
    /// Replace output files that exist.
    #[arg(long)]
    overwrite: bool,
    /// Measured frames.
    #[arg(long, default_value_t = 10)]
    frames: usize,
    /// Discarded warm-up frames.
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    /// Benchmark the CPU reference renderer instead (wall clock).
    #[arg(long)]
    cpu: bool,
    #[command(flatten)]
    gpu: GpuArgs,
}

#[derive(Args)]
struct SceneArg {
    /// Scene: an INRIA .ply, or a trained model directory (uses point_cloud/iteration_<largest>/).
    #[arg(required_unless_present = "demo")]
    scene: Option<PathBuf>,
    /// Use the built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0).
    #[arg(long, conflicts_with = "scene")]
    demo: bool,
}

#[derive(Args)]
struct GpuArgs {
    /// Vulkan device: index or part of its name (default: discrete, then integrated,
    /// then CPU; also VKSPLAT_DEVICE).
    #[arg(long, value_name = "N|NAME")]
    device: Option<String>,
    /// Enable the Khronos validation layer (also VKSPLAT_VALIDATE=1); any message it
    /// prints makes the command fail.
    #[arg(long)]
    validate: bool,
    /// Print the chosen device and memory use.
    #[arg(short, long)]
    verbose: bool,
    /// Device memory the renderer may use, in bytes (K/M/G suffixes; also
    /// VKSPLAT_MEMORY_LIMIT); default: the device-local heap.
    #[arg(long, value_name = "BYTES", value_parser = vksplat::gpu::context::parse_bytes)]
    memory_limit: Option<u64>,
}

impl GpuArgs {
    /// The Vulkan context these flags ask for.
    fn context(&self) -> Result<GpuContext> {
        Ok(GpuContext::new(&ContextOptions {
            device: self.device.clone(),
            validation: self.validate,
            memory_limit: self.memory_limit,
        })?)
    }
}

/// Fails when the validation layer (if enabled) reported anything; the messages were
/// printed as they came.
fn fail_on_validation_messages(ctx: &GpuContext) -> Result<()> {
    let messages = ctx.validation_messages();
    if !messages.is_empty() {
        bail!(
            "the Vulkan validation layer reported {} message(s) (printed above)",
            messages.len()
        );
    }
    Ok(())
}

#[derive(Args)]
struct RenderArgs {
    #[command(flatten)]
    scene: SceneArg,
    #[command(flatten)]
    view: CameraArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Output: a file (.png or .exr), a pattern with {} / {:05} (frame number) or {name}
    /// (camera name), e.g. out/frame_{:05}.exr, or a directory (out/ gives
    /// out/frame_00000.png, ...).
    #[arg(short, long, value_name = "OUT", default_value = "render.png")]
    output: PathBuf,
    /// What to write: rgb, alpha, depth or rgb+depth [default: rgb for PNG, rgb+depth
    /// (R, G, B, A, Z) for EXR]. Depth PNGs are colour-mapped for looking at.
    #[arg(long, value_name = "MODE")]
    mode: Option<output::RenderMode>,
    /// Frames of the path to render: 100..200 (end exclusive), 100..=199, 100.., ..50 or 7.
    /// File names keep the frame's number in the whole path, so split runs give the files
    /// of one run.
    #[arg(long, value_name = "RANGE")]
    frames: Option<FrameRange>,
    /// Resume: skip frames whose files exist (write only the missing files of a frame).
    #[arg(long, conflicts_with = "overwrite")]
    skip_existing: bool,
    /// Replace output files that exist.
    #[arg(long)]
    overwrite: bool,
    /// Image format of a directory output: png or exr.
    #[arg(long, value_name = "EXT", default_value = "png", value_parser = ["png", "exr"])]
    format: String,
    /// Write 16-bit PNG (colour and alpha) instead of 8-bit.
    #[arg(long)]
    png16: bool,
    /// Write EXR channels as 16-bit half floats instead of 32-bit floats.
    #[arg(long)]
    exr_half: bool,
    /// Depth range NEAR,FAR of colour-mapped depth PNGs (default: each frame's 1st-99th
    /// percentile; fix it for a steady video).
    #[arg(long, value_name = "NEAR,FAR", value_parser = parse_depth_range)]
    depth_range: Option<[f32; 2]>,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white").
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = parse_background)]
    background: [f32; 3],
    #[command(flatten)]
    filter: FilterArgs,
    /// Opacity compensation for scenes trained with antialiasing (mip) settings:
    /// opacity * sqrt(max(2.5e-5, det_before / det_after)) of the 0.3 dilation. On by
    /// default when the file records antialiased training (SPZ flag, SOG meta.json).
    #[arg(long)]
    antialiased: bool,
    /// Render without the compensation even when the file records antialiased training.
    #[arg(long, conflicts_with = "antialiased")]
    no_antialiased: bool,
    /// Render with the CPU reference renderer instead of the Vulkan pipeline.
    #[arg(long)]
    cpu: bool,
    /// Print the GPU time of each pipeline stage (timestamp queries; the mean over the
    /// frames of a path).
    #[arg(long)]
    timings: bool,
    /// Threads that encode and write images while the next frame renders (0: encode on
    /// the rendering thread).
    #[arg(long, value_name = "N", default_value_t = vksplat::sequence::default_encode_threads())]
    encode_threads: usize,
    /// No progress display (the summary is still printed).
    #[arg(long, short)]
    quiet: bool,
    #[command(flatten)]
    gpu: GpuArgs,
}

/// Camera paths generated or interpolated by vksplat.
#[derive(Args)]
struct PathArgs {
    /// Render a turntable orbit of FRAMES frames around the scene's bulk (world up -y).
    #[arg(long, value_name = "FRAMES", conflicts_with = "cameras")]
    orbit: Option<usize>,
    /// Orbit centre X,Y,Z (default: the per-axis median of the Gaussians).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, requires = "orbit")]
    orbit_centre: Option<[f32; 3]>,
    /// Orbit radius (default: far enough for the bulk to fit the view).
    #[arg(long, value_name = "R", requires = "orbit")]
    orbit_radius: Option<f32>,
    /// Orbit elevation above the horizon, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 20.0, requires = "orbit")]
    orbit_elevation: f32,
    /// Orbit start angle, degrees (0: the default camera's view, from -z).
    #[arg(long, value_name = "DEG", default_value_t = 0.0, requires = "orbit")]
    orbit_start: f32,
    /// World up axis of the orbit X,Y,Z (INRIA/COLMAP scenes: 0,-1,0).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, default_value = "0,-1,0", requires = "orbit")]
    orbit_up: [f32; 3],
    /// Vertical field of view of generated cameras (orbit, default camera), degrees.
    #[arg(long, value_name = "DEG", default_value_t = camera::DEFAULT_VFOV_DEG)]
    vfov: f32,
    /// Frames per second of a keyframe path (default: the file's).
    #[arg(long, value_name = "FPS")]
    fps: Option<f32>,
    /// Total frames of a keyframe path (default: from its fps and duration).
    #[arg(long, value_name = "N")]
    path_frames: Option<usize>,
}

/// Which Gaussians to render (applied on upload; the file is not changed).
#[derive(Args)]
struct FilterArgs {
    /// Render with at most this SH degree (0..3).
    #[arg(long, value_name = "D", value_parser = clap::value_parser!(u32).range(0..=3))]
    sh_degree: Option<u32>,
    /// Drop Gaussians whose largest scale (world units, after exp) is above S.
    #[arg(long, value_name = "S")]
    max_scale: Option<f32>,
    /// Drop Gaussians whose opacity (after the sigmoid) is below O.
    #[arg(long, value_name = "O")]
    min_opacity: Option<f32>,
    /// Keep only Gaussians whose centre is inside the box XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX.
    #[arg(long, value_name = "BOX", value_parser = vksplat::scene::filter::parse_crop, allow_hyphen_values = true)]
    crop: Option<[[f32; 3]; 2]>,
}

impl FilterArgs {
    fn filter(&self) -> Result<SceneFilter> {
        let f = SceneFilter {
            max_scale: self.max_scale,
            min_opacity: self.min_opacity,
            crop: self.crop,
            sh_degree: self.sh_degree,
        };
        f.validate().map_err(anyhow::Error::msg)?;
        Ok(f)
    }
}

fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected X,Y,Z (three numbers), got \"{s}\""))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!(
            "expected X,Y,Z (three finite numbers), got \"{s}\""
        )),
    }
}

fn parse_depth_range(s: &str) -> Result<[f32; 2], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected NEAR,FAR, got \"{s}\""))?;
    match v[..] {
        [n, f] if n.is_finite() && f.is_finite() && n != f => Ok([n, f]),
        _ => Err(format!(
            "expected NEAR,FAR (two different finite numbers), got \"{s}\""
        )),
    }
}

fn parse_background(s: &str) -> Result<[f32; 3], String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "black" => return Ok([0.0; 3]),
        "white" => return Ok([1.0; 3]),
        _ => {}
    }
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("expected R,G,B (three numbers), got \"{s}\""));
    }
    let mut out = [0f32; 3];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("\"{p}\" is not a finite number"))?;
    }
    Ok(out)
}

fn load_scene(arg: &SceneArg) -> Result<(Scene, String)> {
    if arg.demo {
        return Ok((
            vksplat::demo_scene(),
            "built-in demo scene (PLAYBOT)".into(),
        ));
    }
    let Some(path) = arg.scene.as_deref() else {
        bail!("no scene given; pass a .ply file, a model directory or --demo");
    };
    let resolved = scene::resolve_scene_path(path)?;
    Ok((scene::load(path)?, resolved.display().to_string()))
}

fn choose_camera(args: &CameraArgs, scene: &Scene) -> Result<Camera> {
    let cam = match &args.cameras {
        Some(path) => {
            let (cams, _) = camera::load_camera_file(path, &camera::PathTiming::default())?;
            let spec = args.camera.as_deref().unwrap_or("0");
            let mut picked = camera::select_cameras(&cams, spec, path)?;
            if picked.len() != 1 {
                bail!(
                    "{}: --camera {spec:?} selects {} cameras; bench takes one",
                    path.display(),
                    picked.len()
                );
            }
            picked.remove(0)
        }
        None => camera::default_camera(&scene.positions, 1280, 720),
    };
    Ok(cam.resized(args.width, args.height, args.scale)?)
}

/// The cameras of the path with their frame numbers, at the requested resolution.
/// Also returns a description of the source for the summary.
fn camera_path(args: &RenderArgs, scene: &Scene) -> Result<(Vec<(usize, Camera)>, String)> {
    let view = &args.view;
    let p = &args.path;
    let (all, label, source): (Vec<Camera>, PathBuf, String) = if let Some(frames) = p.orbit {
        let params = camera::OrbitParams {
            frames,
            centre: p.orbit_centre.map(glam::Vec3::from),
            radius: p.orbit_radius,
            elevation_deg: p.orbit_elevation,
            up: glam::Vec3::from(p.orbit_up),
            start_deg: p.orbit_start,
            vfov_deg: p.vfov,
            ..Default::default()
        };
        (
            camera::orbit(&scene.positions, &params)?,
            PathBuf::from("--orbit"),
            format!("an orbit of {frames} frames"),
        )
    } else if let Some(path) = &view.cameras {
        let timing = camera::PathTiming {
            frames: p.path_frames,
            fps: p.fps,
        };
        let (cams, format) = camera::load_camera_file(path, &timing)?;
        let source = format!("{} ({format}, {} cameras)", path.display(), cams.len());
        (cams, path.clone(), source)
    } else {
        let params = camera::OrbitParams {
            frames: 1,
            vfov_deg: p.vfov,
            ..Default::default()
        };
        let mut cams = camera::orbit(&scene.positions, &params)?;
        cams[0].name = "default".into();
        (
            cams,
            PathBuf::from("<default camera>"),
            "the default camera".into(),
        )
    };
    let chosen: Vec<usize> = match &view.camera {
        Some(spec) => camera::select_camera_indices(&all, spec, &label)?,
        // A single output file with several cameras is refused by the plan, naming
        // --camera and patterns.
        None => (0..all.len()).collect(),
    };
    let cams = chosen
        .into_iter()
        .map(|i| Ok((i, all[i].resized(view.width, view.height, view.scale)?)))
        .collect::<Result<Vec<_>>>()?;
    Ok((cams, source))
}

fn render(args: &RenderArgs) -> Result<()> {
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
    let (cams, source) = camera_path(args, &scene)?;
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

fn render_gpu(
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

fn gen(args: &GenArgs) -> Result<()> {
    let scene = vksplat::gen::synthetic_scene(args.count, args.seed, args.sh_degree);
    let bytes =
        vksplat::scene::ply::to_bytes(&scene, vksplat::scene::ply::PlyEncoding::BinaryLittleEndian);
    output::write_bytes_atomically(&args.output, args.overwrite, &bytes)?;
    eprintln!(
        "wrote {} synthetic Gaussians (seed {}, SH degree {}) to {}",
        scene.len(),
        args.seed,
        args.sh_degree,
        args.output.display()
    );
    Ok(())
}

/// The sweep axes of `bench`: Gaussian counts and resolutions (either may be empty).
struct Sweeps {
    counts: Vec<usize>,
    resolutions: Vec<(u32, u32)>,
}

fn parse_sweeps(sweeps: &[String]) -> Result<Sweeps> {
    let (mut counts, mut resolutions) = (Vec::new(), Vec::new());
    for sweep in sweeps {
        let Some((axis, values)) = sweep.split_once('=') else {
            bail!("--sweep {sweep:?}: expected AXIS=V1,V2,... with AXIS gaussians or resolution");
        };
        for v in values.split(',').filter(|v| !v.trim().is_empty()) {
            match axis.trim() {
                "gaussians" => {
                    counts.push(vksplat::bench::parse_count(v).map_err(anyhow::Error::msg)?)
                }
                "resolution" => resolutions
                    .push(vksplat::bench::parse_resolution(v).map_err(anyhow::Error::msg)?),
                other => {
                    bail!("--sweep {sweep:?}: unknown axis {other:?}; use gaussians or resolution")
                }
            }
        }
    }
    Ok(Sweeps {
        counts,
        resolutions,
    })
}

fn bench(args: &BenchArgs) -> Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    for path in [&args.json, &args.csv, &args.plot].into_iter().flatten() {
        if !args.overwrite && path.exists() {
            return Err(output::OutputError::Exists(path.clone()).into());
        }
    }
    let Sweeps {
        counts,
        resolutions,
    } = parse_sweeps(&args.sweep)?;
    let file_scene = if counts.is_empty() {
        Some(load_scene(&SceneArg {
            scene: args.scene.clone(),
            demo: args.demo,
        })?)
    } else {
        if args.scene.is_some() || args.demo {
            bail!("a Gaussians sweep generates its own scenes; drop the scene argument or the gaussians sweep");
        }
        None
    };
    let counts: Vec<Option<usize>> = if counts.is_empty() {
        vec![None]
    } else {
        counts.into_iter().map(Some).collect()
    };
    let resolutions: Vec<Option<(u32, u32)>> = if resolutions.is_empty() {
        vec![None]
    } else {
        resolutions.into_iter().map(Some).collect()
    };
    let mut renderer = if args.cpu {
        None
    } else {
        Some(GpuRenderer::new(args.gpu.context()?)?)
    };
    let points = counts.len() * resolutions.len();
    let mut reports = Vec::new();
    for count in &counts {
        let (scene, name) = match (count, &file_scene) {
            (Some(n), _) => (
                vksplat::gen::synthetic_scene(*n, args.seed, args.sh_degree),
                format!("synthetic {n} (seed {}, SH {})", args.seed, args.sh_degree),
            ),
            (None, Some((s, name))) => (s.clone(), name.clone()),
            (None, None) => bail!("no scene"),
        };
        let act = scene.activated();
        for res in &resolutions {
            let cam = match res {
                Some((w, h)) if count.is_some() || args.view.cameras.is_none() => {
                    camera::default_camera(&scene.positions, *w, *h)
                }
                Some((w, h)) => choose_camera(&args.view, &scene)?.with_resolution(*w, *h)?,
                None => choose_camera(&args.view, &scene)?,
            };
            cam.validate()?;
            let report = match renderer.as_mut() {
                Some(r) => {
                    vksplat::bench::bench_gpu(r, &act, &name, &cam, args.frames, args.warmup)
                }
                None => Ok(vksplat::bench::bench_cpu(
                    &act,
                    &name,
                    &cam,
                    args.frames,
                    args.warmup,
                )),
            };
            match report {
                Ok(report) => {
                    println!("{}", report.to_text());
                    reports.push(report);
                }
                // In a sweep, a point beyond the device's limits is reported and skipped so
                // the other points still produce their results.
                Err(e @ vksplat::gpu::GpuError::InvalidArgument(_)) if points > 1 => {
                    eprintln!("skipped {name} at {}x{}: {e}", cam.width, cam.height);
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
    if reports.is_empty() {
        bail!("every point of the sweep exceeded the device's limits (see above)");
    }
    if let Some(r) = &renderer {
        fail_on_validation_messages(r.ctx())?;
    }
    let write_text = |path: &PathBuf, text: String| -> Result<()> {
        output::write_bytes_atomically(path, args.overwrite, text.as_bytes())?;
        Ok(())
    };
    if let Some(path) = &args.json {
        let json = if reports.len() == 1 {
            serde_json::to_string_pretty(&reports[0])?
        } else {
            serde_json::to_string_pretty(&reports)?
        };
        write_text(path, json)?;
    }
    if let Some(path) = &args.csv {
        write_text(path, vksplat::bench::to_csv(&reports))?;
    }
    if let Some(path) = &args.plot {
        let svg = vksplat::bench::plot_sweep(&reports).map_err(anyhow::Error::msg)?;
        write_text(path, svg)?;
    }
    Ok(())
}

fn fmt3(v: [f32; 3]) -> String {
    format!("({:.4}, {:.4}, {:.4})", v[0], v[1], v[2])
}

fn cmd_convert(args: &ConvertArgs) -> Result<()> {
    use vksplat::scene::write::{convert, ConvertOptions};
    let filter = vksplat::scene::filter::SceneFilter {
        max_scale: args.max_scale,
        min_opacity: args.min_opacity,
        crop: args.crop,
        sh_degree: args.sh_degree,
    };
    let options = ConvertOptions {
        filter,
        overwrite: args.overwrite,
    };
    let r = convert(&args.input, &args.output, &options)?;
    eprintln!(
        "converted {} ({}, {} Gaussians) -> {} ({}, {} Gaussians, SH degree {}, {} bytes)",
        args.input.display(),
        r.input_format,
        r.read,
        args.output.display(),
        r.output_format,
        r.written,
        r.sh_degree,
        r.bytes
    );
    if r.antialiased_flag_lost {
        eprintln!(
            "note: {} records that the scene was trained with antialiasing; {} cannot record that, so render the output with --antialiased",
            args.input.display(),
            r.output_format
        );
    }
    Ok(())
}

fn info(arg: &SceneArg) -> Result<()> {
    let (scene, name, format) = match arg.scene.as_deref() {
        Some(path) if !arg.demo => {
            let (scene, format) = scene::load_with_format(path)?;
            let name = scene::resolve_scene_path(path)?.display().to_string();
            (scene, name, Some(format))
        }
        _ => {
            let (scene, name) = load_scene(arg)?;
            (scene, name, None)
        }
    };
    let s = vksplat::stats::scene_stats(&scene);
    println!("scene       {name}");
    if let Some(format) = format {
        println!("format      {format}");
        if scene.antialiased {
            println!("antialiased yes: the file records antialiased training (rendered with the compensation by default)");
        }
    }
    println!("gaussians   {}", s.count);
    println!(
        "sh degree   {} ({} coefficients per channel)",
        s.sh_degree,
        scene.sh_coeffs()
    );
    if let Some((lo, hi)) = s.bounds {
        println!("bounds      min {}  max {}", fmt3(lo), fmt3(hi));
    }
    println!(
        "bulk        centre {} (per-axis median), radius {:.4} (95% of centres within), 2-98% box {} .. {}",
        fmt3(s.bulk.centre.into()),
        s.bulk.radius,
        fmt3(s.bulk.lo.into()),
        fmt3(s.bulk.hi.into())
    );
    println!();
    println!(
        "{:<28} {:>12} {:>12} {:>12} {:>12}",
        "quantity", "min", "max", "mean", "std"
    );
    for (label, v) in [
        ("scale (exp, all axes)", s.scale),
        ("max scale per Gaussian", s.max_scale),
        ("log scale (stored)", s.log_scale),
        ("opacity (sigmoid)", s.opacity),
        ("opacity logit (stored)", s.opacity_logit),
    ] {
        println!(
            "{label:<28} {:>12.6} {:>12.6} {:>12.6} {:>12.6}",
            v.min, v.max, v.mean, v.std
        );
    }
    print_histogram(
        "largest scale per Gaussian (world units); 'kept' = share kept by --max-scale <bin end>",
        &s.max_scale_histogram,
        true,
    );
    print_histogram(
        "opacity (after the sigmoid); 'kept' = share kept by --min-opacity <bin start>",
        &s.opacity_histogram,
        false,
    );
    Ok(())
}

/// Prints a log-binned histogram as text bars with the share a threshold at each bin
/// edge keeps (below the bin's end for `upper`, from the bin's start otherwise).
fn print_histogram(title: &str, h: &vksplat::stats::Histogram, upper: bool) {
    println!();
    println!("{title}");
    if h.counts.is_empty() {
        println!("  (no positive values)");
        return;
    }
    let peak = h.counts.iter().copied().max().unwrap_or(1).max(1);
    let total = h.total.max(1) as f64;
    let mut below = 0usize;
    let above_all: usize = h.counts.iter().sum();
    for (i, &c) in h.counts.iter().enumerate() {
        let kept = if upper { below + c } else { above_all - below };
        below += c;
        let bar = "#".repeat((c * 40).div_ceil(peak));
        println!(
            "  [{:>9}, {:>9})  {c:>10}  kept {:>6.2} %  {bar}",
            format!("{:.3e}", h.edges[i]),
            format!("{:.3e}", h.edges[i + 1]),
            100.0 * kept as f64 / total,
        );
    }
    if h.outside > 0 {
        println!("  zero, negative or not finite: {}", h.outside);
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Render(args) => render(args),
        Command::Info(arg) => info(arg),
        Command::Bench(args) => bench(args),
        Command::Gen(args) => gen(args),
        Command::Convert(args) => cmd_convert(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_sentence(&e));
            ExitCode::FAILURE
        }
    }
}

/// One sentence: the outermost message with its causes appended.
fn error_sentence(e: &anyhow::Error) -> String {
    let mut s = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !s.contains(&c) {
            s.push_str(": ");
            s.push_str(&c);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// clap checks argument definitions (duplicate names, bad references) only in debug
    /// assertions at parse time; this makes a definition error fail the test suite.
    #[test]
    fn command_line_definition_is_valid() {
        Cli::command().debug_assert();
    }
}
