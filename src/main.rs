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
    #[command(flatten)]
    scene: SceneArg,
    #[command(flatten)]
    view: CameraArgs,
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
    let ctx = GpuContext::new(&ContextOptions {
        device: args.gpu.device.clone(),
        validation: args.gpu.validate,
    })?;
    if args.gpu.verbose {
        eprintln!("device: {}", ctx.info());
    }
    let validating = ctx.validation_enabled();
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
    if validating {
        let messages = renderer.ctx().validation_messages();
        if !messages.is_empty() {
            bail!(
                "the Vulkan validation layer reported {} message(s) (printed above)",
                messages.len()
            );
        }
    }
    let device = renderer.ctx().info().name.clone();
    Ok((frame, format!("on {device}")))
}

fn bench(args: &BenchArgs) -> Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let (scene, name) = load_scene(&args.scene)?;
    let cam = choose_camera(&args.view, &scene)?;
    cam.validate()?;
    let opts = vksplat::cpu::RenderOptions::default();
    let act = scene.activated();
    println!(
        "scene {name}: {} Gaussians, {}x{}",
        scene.len(),
        cam.width,
        cam.height
    );
    let mut walls = Vec::new();
    if args.cpu {
        for i in 0..args.warmup + args.frames {
            let t = std::time::Instant::now();
            std::hint::black_box(vksplat::cpu::render(&act, &cam, &opts));
            if i >= args.warmup {
                walls.push(t.elapsed().as_secs_f64() * 1e3);
            }
        }
        println!(
            "device: CPU reference ({} threads)",
            rayon::current_num_threads()
        );
    } else {
        let ctx = GpuContext::new(&ContextOptions {
            device: args.gpu.device.clone(),
            validation: args.gpu.validate,
        })?;
        println!("device: {}", ctx.info());
        let mut renderer = GpuRenderer::new(ctx)?;
        let gpu_scene = renderer.upload(&act)?;
        // (stage name, samples), in pipeline order, then the whole frame.
        let mut stages: Vec<(&str, Vec<f64>)> = Vec::new();
        for i in 0..args.warmup + args.frames {
            let t = std::time::Instant::now();
            std::hint::black_box(renderer.render(&gpu_scene, &cam, &opts)?);
            if i >= args.warmup {
                walls.push(t.elapsed().as_secs_f64() * 1e3);
                let tm = renderer.timings();
                let samples = tm.stages().into_iter().chain([("frame (GPU)", tm.total)]);
                for (k, (name, ms)) in samples.enumerate() {
                    if stages.len() <= k {
                        stages.push((name, Vec::new()));
                    }
                    stages[k].1.push(ms);
                }
            }
        }
        println!(
            "{:<12} {:>9} {:>9} {:>9} {:>9}",
            "stage", "min ms", "median", "p95", "max"
        );
        for (n, v) in &mut stages {
            let s = summary(v);
            println!(
                "{n:<12} {:>9.3} {:>9.3} {:>9.3} {:>9.3}",
                s[0], s[1], s[2], s[3]
            );
        }
        let st = renderer.stats();
        println!(
            "visible Gaussians {}, tile pairs {}, key bits {}",
            st.visible, st.pairs, st.key_bits
        );
        println!(
            "device memory: scene {} B, per-frame {} B ({:.1} B per Gaussian)",
            gpu_scene.device_bytes(),
            renderer.frame_device_bytes(),
            (gpu_scene.device_bytes() + renderer.frame_device_bytes()) as f64
                / scene.len().max(1) as f64
        );
    }
    let s = summary(&mut walls);
    println!(
        "{:<12} {:>9.3} {:>9.3} {:>9.3} {:>9.3}",
        "wall clock", s[0], s[1], s[2], s[3]
    );
    println!("frames/s (median wall clock) {:.2}", 1e3 / s[1]);
    Ok(())
}

/// min, median, p95, max of `v` (sorted in place).
fn summary(v: &mut [f64]) -> [f64; 4] {
    v.sort_by(|a, b| a.total_cmp(b));
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    [v[0], at(0.5), at(0.95), v[v.len() - 1]]
}

fn fmt3(v: [f32; 3]) -> String {
    format!("({:.4}, {:.4}, {:.4})", v[0], v[1], v[2])
}

fn info(arg: &SceneArg) -> Result<()> {
    let (scene, name) = load_scene(arg)?;
    let s = vksplat::stats::scene_stats(&scene);
    println!("scene       {name}");
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
