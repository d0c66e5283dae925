//! The `vksplat` command line.

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use vksplat::camera::{self, Camera};
use vksplat::gpu::{ContextOptions, GpuContext};
use vksplat::output::{self, ImageFormat};
use vksplat::render::GpuRenderer;
use vksplat::scene::{self, Scene};

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
    /// INRIA cameras.json to take the camera from.
    #[arg(long, value_name = "FILE")]
    cameras: Option<PathBuf>,
    /// Camera of --cameras: list index or img_name (default 0).
    #[arg(long, value_name = "N|NAME", requires = "cameras")]
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
}

impl GpuArgs {
    /// The Vulkan context these flags ask for.
    fn context(&self) -> Result<GpuContext> {
        Ok(GpuContext::new(&ContextOptions {
            device: self.device.clone(),
            validation: self.validate,
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
    /// Output image (.png or .exr; EXR holds R, G, B, A and depth Z).
    #[arg(short, long, value_name = "OUT", default_value = "render.png")]
    output: PathBuf,
    /// Background colour, linear R,G,B in [0, 1] (or "black" / "white").
    #[arg(long, value_name = "R,G,B", default_value = "0,0,0", value_parser = parse_background)]
    background: [f32; 3],
    /// Render with the CPU reference renderer instead of the Vulkan pipeline.
    #[arg(long)]
    cpu: bool,
    /// Print the GPU time of each pipeline stage (timestamp queries).
    #[arg(long)]
    timings: bool,
    #[command(flatten)]
    gpu: GpuArgs,
    /// Write 16-bit PNG instead of 8-bit.
    #[arg(long)]
    png16: bool,
    /// Replace the output file if it exists.
    #[arg(long)]
    overwrite: bool,
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
            let cams = camera::load_cameras_json(path)?;
            if cams.is_empty() {
                bail!("{}: holds no cameras", path.display());
            }
            camera::select_camera(&cams, args.camera.as_deref().unwrap_or("0"), path)?
        }
        None => camera::default_camera(&scene.positions, 1280, 720),
    };
    Ok(cam.resized(args.width, args.height, args.scale)?)
}

fn render(args: &RenderArgs) -> Result<()> {
    let format = ImageFormat::from_path(&args.output, args.png16)?;
    if !args.overwrite && args.output.exists() {
        return Err(output::OutputError::Exists(args.output.clone()).into());
    }
    let (scene, name) = load_scene(&args.scene)?;
    let cam = choose_camera(&args.view, &scene)?;
    cam.validate()?;
    let opts = vksplat::cpu::RenderOptions {
        background: args.background,
    };
    let start = std::time::Instant::now();
    let (frame, how) = if args.cpu {
        (
            vksplat::cpu::render(&scene.activated(), &cam, &opts),
            "on the CPU".to_string(),
        )
    } else {
        render_gpu(args, &scene, &cam, &opts)?
    };
    let elapsed = start.elapsed();
    output::write_frame(&frame, &args.output, format, args.overwrite)?;
    eprintln!(
        "rendered {name} ({} Gaussians) from camera \"{}\" at {}x{} {how} in {:.1} ms -> {}",
        scene.len(),
        cam.name,
        cam.width,
        cam.height,
        elapsed.as_secs_f64() * 1e3,
        args.output.display()
    );
    Ok(())
}

fn render_gpu(
    args: &RenderArgs,
    scene: &Scene,
    cam: &Camera,
    opts: &vksplat::cpu::RenderOptions,
) -> Result<(vksplat::frame::Frame, String)> {
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
    let gpu_scene = renderer.upload(&scene.activated())?;
    let frame = renderer.render(&gpu_scene, cam, opts)?;
    if args.timings {
        let t = renderer.timings();
        eprintln!("{:<12} {:>10}", "stage", "GPU ms");
        for (stage, ms) in t.stages() {
            eprintln!("{stage:<12} {ms:>10.3}");
        }
        eprintln!("{:<12} {:>10.3}", "frame", t.total);
        let st = renderer.stats();
        eprintln!(
            "visible Gaussians {}, tile pairs {}, key bits {}",
            st.visible, st.pairs, st.key_bits
        );
    }
    if args.gpu.verbose {
        eprintln!(
            "device memory: scene {} bytes, per-frame buffers {} bytes",
            gpu_scene.device_bytes(),
            renderer.frame_device_bytes()
        );
    }
    fail_on_validation_messages(renderer.ctx())?;
    let device = renderer.ctx().info().name.clone();
    Ok((frame, format!("on {device}")))
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
    Ok(())
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
