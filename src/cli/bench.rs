//! `vksplat bench`: per-stage GPU (or CPU reference) timings of one camera, and sweeps.

use super::common::{
    fail_on_validation_messages, load_scene, model_cameras, CameraArgs, GpuArgs, SceneArg,
};
use anyhow::{bail, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use vksplat::camera::{self, Camera};
use vksplat::output;
use vksplat::render::GpuRenderer;
use vksplat::scene::Scene;

#[derive(Args)]
pub(crate) struct BenchArgs {
    /// Scene (.ply or model directory); not needed with --sweep gaussians=...
    pub(crate) scene: Option<PathBuf>,
    /// Use the built-in demo scene.
    #[arg(long, conflicts_with = "scene")]
    pub(crate) demo: bool,
    /// Iteration of a trained model directory: point_cloud/iteration_N (default: the largest).
    #[arg(long, value_name = "N", conflicts_with = "demo")]
    pub(crate) iteration: Option<u64>,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    /// Sweep: `gaussians=1e4,1e5,...` (synthetic scenes from `vksplat gen`) and/or
    /// `resolution=720p,1080p,4k,WxH`; repeat the flag for both (all combinations run).
    #[arg(long, value_name = "AXIS=V1,V2,...")]
    pub(crate) sweep: Vec<String>,
    /// Seed of the synthetic scenes of a Gaussians sweep.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// SH degree of the synthetic scenes of a Gaussians sweep.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub(crate) sh_degree: u32,
    /// Write the report(s) as JSON.
    #[arg(long, value_name = "FILE")]
    pub(crate) json: Option<PathBuf>,
    /// Write the report(s) as CSV (one row per stage).
    #[arg(long, value_name = "FILE")]
    pub(crate) csv: Option<PathBuf>,
    /// Write an SVG plot of the sweep (stacked stage times and a stage breakdown).
    #[arg(long, value_name = "FILE.svg")]
    pub(crate) plot: Option<PathBuf>,
    /// Replace output files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Measured frames.
    #[arg(long, default_value_t = 10)]
    pub(crate) frames: usize,
    /// Discarded warm-up frames.
    #[arg(long, default_value_t = 2)]
    pub(crate) warmup: usize,
    /// Benchmark the CPU reference renderer instead (wall clock).
    #[arg(long)]
    pub(crate) cpu: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// The camera to time: one of `cameras` (`--cameras`, or a model directory's own), or the
/// default camera.
pub(crate) fn choose_camera(
    args: &CameraArgs,
    cameras: Option<&Path>,
    scene: &Scene,
) -> Result<Camera> {
    let cam = match cameras {
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

/// The sweep axes of `bench`: Gaussian counts and resolutions (either may be empty).
pub(crate) struct Sweeps {
    pub(crate) counts: Vec<usize>,
    pub(crate) resolutions: Vec<(u32, u32)>,
}

pub(crate) fn parse_sweeps(sweeps: &[String]) -> Result<Sweeps> {
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

pub(crate) fn bench(args: &BenchArgs) -> Result<()> {
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
    let scene_arg = SceneArg {
        scene: args.scene.clone(),
        demo: args.demo,
        iteration: args.iteration,
    };
    let cameras = match &args.view.cameras {
        Some(file) => Some(file.clone()),
        None if counts.is_empty() => model_cameras(&scene_arg),
        None => None,
    };
    let file_scene = if counts.is_empty() {
        Some(load_scene(&scene_arg)?)
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
                Some((w, h)) if count.is_some() || cameras.is_none() => {
                    camera::default_camera(&scene.positions, *w, *h)
                }
                Some((w, h)) => choose_camera(&args.view, cameras.as_deref(), &scene)?
                    .with_resolution(*w, *h)?,
                None => choose_camera(&args.view, cameras.as_deref(), &scene)?,
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
