//! `verisplat bench`: per-stage GPU (or CPU reference) timings of one camera, and sweeps.

use super::common::{
    camera_path, check_output_file, fail_on_validation_messages, load_scene, CameraArgs,
    FilterArgs, GpuArgs, KernelArg, PathArgs, SceneArg,
};
use super::values;
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use verisplat::app::bench::BenchCamera;
use verisplat::core::console::{note, out, outln};
use verisplat::core::scene::filter::SceneFilter;
use verisplat::core::scene::Scene;
use verisplat::io::output;
use verisplat::render::GpuRenderer;

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat bench scene.ply --frames 20
  verisplat bench scene.ply --cameras cameras.json --camera 5 --width 1920 --json b.json
  verisplat bench --sweep gaussians=1e4,1e5,1e6 --sweep resolution=720p,1080p --plot sweep.svg
  verisplat bench scene.ply --cpu
  verisplat bench --sweep gaussians=1e5,1e6,1e7 --json b.json --shard slurm   # b.shard-I-of-N.json")]
pub(crate) struct BenchArgs {
    /// Scene: any supported format or a model directory; not needed with
    /// --sweep gaussians=...
    pub(crate) scene: Option<PathBuf>,
    /// Use the built-in demo scene.
    #[arg(long, conflicts_with = "scene")]
    pub(crate) demo: bool,
    /// Iteration of a trained model directory: point_cloud/iteration_N (default: the largest).
    #[arg(long, value_name = "N", conflicts_with = "demo")]
    pub(crate) iteration: Option<u64>,
    #[command(flatten)]
    pub(crate) spz: super::common::SpzAxesArg,
    #[command(flatten)]
    pub(crate) view: CameraArgs,
    #[command(flatten)]
    pub(crate) path: PathArgs,
    #[command(flatten)]
    pub(crate) filter: FilterArgs,
    /// Multiply every Gaussian's scales by M before projecting (the reference rasterizer's
    /// scaling_modifier; < 1 shrinks the splats, > 1 grows them).
    #[arg(long, value_name = "M", default_value_t = 1.0, value_parser = values::positive_f32)]
    pub(crate) scale_modifier: f32,
    #[command(flatten)]
    pub(crate) kernel: KernelArg,
    /// Sweep: `gaussians=1e4,1e5,...` (synthetic scenes from `verisplat gen`) and/or
    /// `resolution=720p,1080p,4k,WxH`; repeat the flag for both (all combinations run).
    #[arg(long, value_name = "AXIS=V1,V2,...")]
    pub(crate) sweep: Vec<String>,
    /// Run shard I of N (0-based) of the sweep's points (a contiguous block, in the order
    /// Gaussian counts, then resolutions); `slurm` reads SLURM_ARRAY_TASK_ID,
    /// SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_MIN. Report files get .shard-I-of-N
    /// before their extension.
    #[arg(long, value_name = "I/N|slurm", requires = "sweep")]
    pub(crate) shard: Option<String>,
    /// Merge the JSON reports of a sharded sweep (the files `--json X --shard I/N` wrote,
    /// X.shard-I-of-N.json, every shard once) into one report in `--json` (the points in
    /// the sweep's order, as one process writes them); runs nothing.
    #[arg(long, value_name = "SHARD.json", num_args = 1.., requires = "json", conflicts_with_all = ["sweep", "scene", "demo", "shard", "csv", "plot"])]
    pub(crate) merge: Vec<PathBuf>,
    /// Seed of the synthetic scenes of a Gaussians sweep.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Write the report as JSON: {"schema_version": 1, "runs": [...]}, one run per point
    /// of a sweep, each naming the timed camera.
    #[arg(long, value_name = "FILE")]
    pub(crate) json: Option<PathBuf>,
    /// Write the report(s) as CSV (one row per stage).
    #[arg(long, value_name = "FILE")]
    pub(crate) csv: Option<PathBuf>,
    /// Write an SVG plot of the sweep: frame time per resolution and per Gaussian count,
    /// the stage times of every series as stacked areas, and a stage breakdown.
    #[arg(long, value_name = "FILE.svg")]
    pub(crate) plot: Option<PathBuf>,
    /// Replace output files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Measured frames.
    #[arg(long, default_value_t = 10, value_parser = values::int_in(1usize, 100_000))]
    pub(crate) frames: usize,
    /// Discarded warm-up frames.
    #[arg(long, default_value_t = 2, value_parser = values::int_in(0usize, 100_000))]
    pub(crate) warmup: usize,
    /// Print no report on stdout (write it with --json/--csv).
    #[arg(long, short)]
    pub(crate) quiet: bool,
    /// Benchmark the CPU reference renderer instead (wall clock).
    #[arg(long)]
    pub(crate) cpu: bool,
    /// Upload the scene in compact form (SH, scales and rotations as fp16), as `render --compact`.
    #[arg(long, conflicts_with = "cpu")]
    pub(crate) compact: bool,
    /// Attach feature channels (an N x K NumPy array, as `render --features`); a scene with
    /// feature channels (these, or its PLY feat_*) is benchmarked with its feature blend,
    /// reported as the `features` stage.
    #[arg(long, value_name = "FILE.npy")]
    pub(crate) features: Option<PathBuf>,
    /// Time the differentiable rasterizer: each iteration renders the frame with its
    /// forward state saved and runs the backward pass (pixel gradients to Gaussian
    /// gradients), timing both passes' stages; reports device bytes per Gaussian. A scene
    /// with feature channels (--features, at most 16) differentiates those instead of its
    /// colour.
    #[arg(long, conflicts_with_all = ["cpu", "compact", "csv", "plot"])]
    pub(crate) backward: bool,
    /// How the backward pass sums gradients: deterministic (fixed point, bit-identical run
    /// to run), float-atomics (faster, not reproducible) or cas (float adds by
    /// compare-and-swap, for devices without float atomics).
    #[arg(
        long,
        value_name = "MODE",
        default_value = "deterministic",
        requires = "backward"
    )]
    pub(crate) accumulation: verisplat::render::backward::grad_accumulate::Accumulation,
    /// With --backward: shade the feature channels with this neural shader (as `render
    /// --shader`) and differentiate it too: its backward pass is the `shade_bwd` stage.
    #[arg(long, value_name = "FILE.safetensors", requires = "backward")]
    pub(crate) shader: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// The camera a benchmark times: the one `--camera` selects of the path (`--orbit`,
/// `--cameras` or the default camera), or its first.
pub(crate) fn choose_camera(
    view: &CameraArgs,
    path: &PathArgs,
    scene_arg: &SceneArg,
    scene: &Scene,
) -> Result<BenchCamera> {
    let camera = view.camera.is_some();
    let path = camera_path(view, path, scene_arg, scene)?;
    let timed = |(k, cam): &(usize, verisplat::core::camera::Camera)| BenchCamera {
        camera: cam.clone(),
        // The default camera is no camera of a file.
        index: (path.source != "the default camera").then_some(*k),
        source: path.source.clone(),
    };
    match path.cameras.as_slice() {
        [one] => Ok(timed(one)),
        [first, ..] if !camera => {
            note!(
                "timing camera {} (\"{}\") of {}; pick another with --camera",
                first.0,
                first.1.name,
                path.source
            );
            Ok(timed(first))
        }
        many => bail!(
            "--camera selects {} of {}; bench times one camera",
            super::plural(many.len(), "camera"),
            path.source
        ),
    }
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
                    counts.push(verisplat::app::bench::parse_count(v).map_err(anyhow::Error::msg)?)
                }
                "resolution" => resolutions
                    .push(verisplat::app::bench::parse_resolution(v).map_err(anyhow::Error::msg)?),
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

/// A point's report, or (in a sweep of `points` > 1) `None` with a note when the point is
/// beyond the device's limits or the input, so the other points still produce theirs.
fn kept_in_sweep<T>(
    report: verisplat::gpu::GpuResult<T>,
    points: usize,
    name: &str,
    cam: &verisplat::core::camera::Camera,
) -> Result<Option<T>> {
    use verisplat::gpu::GpuError;
    match report {
        Ok(report) => Ok(Some(report)),
        Err(
            e @ (GpuError::DeviceLimit { .. } | GpuError::Input(_) | GpuError::InvalidArgument(_)),
        ) if points > 1 => {
            note!("skipped {name} at {}x{}: {e}", cam.width, cam.height);
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}

/// `bench --merge`: the shards' JSON reports as one.
fn merge(args: &BenchArgs) -> Result<()> {
    let out = args
        .json
        .as_ref()
        .expect("clap requires --json with --merge");
    check_output_file(out, args.overwrite)?;
    let mut parts: Vec<(verisplat::app::shard::Shard, serde_json::Value, &PathBuf)> = Vec::new();
    for path in &args.merge {
        let name = path.file_stem().and_then(|n| n.to_str()).unwrap_or("");
        let shard = name
            .rsplit_once('.')
            .and_then(|(_, tag)| verisplat::app::shard::Shard::parse_tag(tag))
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: not a shard's report (its name must end in .shard-I-of-N.json, as bench --json --shard writes it)",
                    path.display()
                )
            })?;
        let text = std::fs::read(path)
            .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", path.display()))?;
        let doc: serde_json::Value = serde_json::from_slice(&text)
            .map_err(|e| anyhow::anyhow!("{}: is not a bench JSON report: {e}", path.display()))?;
        if let Some((other, _, p)) = parts.iter().find(|(s, _, _)| s.index == shard.index) {
            bail!(
                "{} and {}: both are {other}; merge the reports of one run",
                p.display(),
                path.display()
            );
        }
        parts.push((shard, doc, path));
    }
    let count = parts[0].0.count;
    if let Some((s, _, p)) = parts.iter().find(|(s, _, _)| s.count != count) {
        bail!("{}: is {s}, the others are of {count} shards", p.display());
    }
    let missing: Vec<String> = (0..count)
        .filter(|i| !parts.iter().any(|(s, _, _)| s.index == *i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        bail!(
            "shard(s) {} of {count} are missing; pass every shard's report",
            missing.join(", ")
        );
    }
    parts.sort_by_key(|(s, _, _)| s.index);
    let version = &parts[0].1["schema_version"];
    let key = if parts[0].1.get("backward_runs").is_some() {
        "backward_runs"
    } else {
        "runs"
    };
    let mut runs = Vec::new();
    for (_, doc, path) in &parts {
        if &doc["schema_version"] != version {
            bail!(
                "{}: another report version than the first shard's",
                path.display()
            );
        }
        let list = doc[key].as_array().ok_or_else(|| {
            anyhow::anyhow!(
                "{}: has no {key} list (all shards must be of one kind of bench)",
                path.display()
            )
        })?;
        runs.extend(list.iter().cloned());
    }
    let mut doc = serde_json::Map::new();
    doc.insert("schema_version".into(), version.clone());
    doc.insert(key.into(), serde_json::Value::Array(runs));
    let text = serde_json::to_string_pretty(&serde_json::Value::Object(doc))? + "\n";
    output::write_bytes_atomically(out, args.overwrite, text.as_bytes())?;
    if !args.quiet {
        note!(
            "merged {} shards ({} points) into {}",
            count,
            parts
                .iter()
                .map(|(_, d, _)| d[key].as_array().map_or(0, |a| a.len()))
                .sum::<usize>(),
            out.display()
        );
    }
    Ok(())
}

pub(crate) fn bench(args: &BenchArgs) -> Result<()> {
    if !args.merge.is_empty() {
        return merge(args);
    }
    let shard = super::common::shard(args.shard.as_deref())?;
    let files = ReportFiles::checked(args, shard)?;
    let filter = args.filter.filter()?;
    let Sweeps {
        counts,
        resolutions,
    } = parse_sweeps(&args.sweep)?;
    let scene_arg = SceneArg {
        scene: args.scene.clone(),
        demo: args.demo,
        iteration: args.iteration,
        spz: args.spz,
    };
    let (file_scene, shader) = load_file_scene(args, &scene_arg, &filter, counts.is_empty())?;
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
    let mut renderer = bench_renderer(args)?;
    let points = counts.len() * resolutions.len();
    let Some(mine) = shard_points(shard, points) else {
        return Ok(());
    };
    let mut runs = Runs {
        points,
        forward: Vec::new(),
        backward: Vec::new(),
    };
    for (c, count) in counts.iter().enumerate() {
        let point = |r: usize| c * resolutions.len() + r;
        if !(0..resolutions.len()).any(|r| mine.contains(&point(r))) {
            continue;
        }
        let (scene, name) = point_scene(args, *count, &file_scene, &filter)?;
        let act = scene.activated();
        let kernel = args.kernel.resolve(&scene, &name);
        let rules = args.kernel.resolve_rules(&scene, &name);
        for (r, res) in resolutions.iter().enumerate() {
            if !mine.contains(&point(r)) {
                continue;
            }
            let timed = point_camera(args, *res, *count, &scene_arg, &scene)?;
            let point = Point {
                scene: &act,
                name: &name,
                timed: &timed,
                kernel,
                rules,
                shader: shader.as_ref(),
            };
            runs.bench(args, renderer.as_mut(), &point)?;
        }
    }
    if args.backward {
        return write_backward_reports(args, renderer.as_ref(), &files, &runs.backward);
    }
    write_reports(args, renderer.as_ref(), &files, points, &runs.forward)
}

/// The report files of a run (a shard writes its own), checked (and their folders
/// created) before the benchmark runs.
struct ReportFiles {
    json: Option<PathBuf>,
    csv: Option<PathBuf>,
    plot: Option<PathBuf>,
}

impl ReportFiles {
    fn checked(
        args: &BenchArgs,
        shard: Option<verisplat::app::shard::Shard>,
    ) -> Result<ReportFiles> {
        // A shard writes its own report files.
        let shard_file = |path: &Option<PathBuf>| -> Option<PathBuf> {
            let path = path.as_ref()?;
            Some(shard.map_or_else(|| path.clone(), |s| s.file_name(path)))
        };
        let (json, csv, plot) = (
            shard_file(&args.json),
            shard_file(&args.csv),
            shard_file(&args.plot),
        );
        // Report files are checked (and their folders created) before the benchmark runs.
        for path in [&json, &csv, &plot].into_iter().flatten() {
            check_output_file(path, args.overwrite)?;
        }
        Ok(ReportFiles { json, csv, plot })
    }
}

/// A scene and its name.
type NamedScene = (Scene, String);

/// The scene file (or demo) a run without a Gaussians sweep times, with its features
/// attached and filters applied, and the neural shader of `--shader`; `None` for a
/// Gaussians sweep (`no_count_sweep` false), which generates its own scenes.
fn load_file_scene(
    args: &BenchArgs,
    scene_arg: &SceneArg,
    filter: &SceneFilter,
    no_count_sweep: bool,
) -> Result<(Option<NamedScene>, Option<verisplat::fields::mlp::Mlp>)> {
    if (args.features.is_some() || args.shader.is_some()) && !no_count_sweep {
        bail!("--features and --shader apply to a scene file; a Gaussians sweep generates its own scenes");
    }
    let mut shader = None;
    let file_scene = if no_count_sweep {
        let (mut scene, name) = load_scene(scene_arg)?;
        super::common::refuse_time_varying(&scene, &name, "bench")?;
        if let Some(file) = &args.features {
            verisplat::core::scene::features::attach_npy(&mut scene, file)?;
        }
        if let Some(path) = &args.shader {
            let mlp = verisplat::fields::mlp::Mlp::load(path)?;
            mlp.check_channels(scene.feature_count)
                .map_err(|e| anyhow::anyhow!("{}: {e} ({name})", path.display()))?;
            shader = Some(mlp);
        }
        if filter.is_identity_for(&scene) {
            Some((scene, name))
        } else {
            let kept = filter.apply(&scene);
            note!(
                "filters keep {} of {} Gaussians (SH degree {})",
                kept.len(),
                scene.len(),
                kept.sh_degree
            );
            Some((kept, name))
        }
    } else {
        if args.scene.is_some() || args.demo {
            bail!("a Gaussians sweep generates its own scenes; drop the scene argument or the gaussians sweep");
        }
        None
    };
    Ok((file_scene, shader))
}

/// The GPU renderer (`None` with `--cpu`), set up as the options ask.
fn bench_renderer(args: &BenchArgs) -> Result<Option<GpuRenderer>> {
    Ok(if args.cpu {
        None
    } else {
        let mut renderer = GpuRenderer::new(args.gpu.context()?)?;
        renderer.set_compact(args.compact);
        if args.backward {
            renderer.set_gradient_accumulation(args.accumulation)?;
        }
        Some(renderer)
    })
}

/// The points of the sweep this process runs (all of them without `--shard`), announced
/// for a shard; `None` when a shard has none.
fn shard_points(
    shard: Option<verisplat::app::shard::Shard>,
    points: usize,
) -> Option<std::ops::Range<usize>> {
    let mine = shard.map_or(0..points, |s| s.range(points));
    if let Some(s) = shard {
        if mine.is_empty() {
            note!("{s}: no points (the sweep has {points}, fewer than the shards); nothing to run");
            return None;
        }
        note!(
            "{s}: points {}..={} of the sweep's {points}",
            mine.start,
            mine.end - 1
        );
    }
    Some(mine)
}

/// The scene of a sweep's Gaussian count (a synthetic one, filtered), or the file scene.
fn point_scene(
    args: &BenchArgs,
    count: Option<usize>,
    file_scene: &Option<NamedScene>,
    filter: &SceneFilter,
) -> Result<(Scene, String)> {
    // --sh-degree caps a file scene's degree and sets the synthetic scenes' degree.
    let synthetic_sh_degree = args.filter.sh_degree.unwrap_or(2);
    Ok(match (count, file_scene) {
        (Some(n), _) => (
            filter.apply(&verisplat::core::gen::synthetic_scene(
                n,
                args.seed,
                synthetic_sh_degree,
            )),
            format!(
                "synthetic {n} (seed {}, SH {synthetic_sh_degree})",
                args.seed
            ),
        ),
        (None, Some((s, name))) => (s.clone(), name.clone()),
        (None, None) => bail!("no scene"),
    })
}

/// The camera timed at a point of the sweep (its resolution replacing the view's size),
/// checked.
fn point_camera(
    args: &BenchArgs,
    res: Option<(u32, u32)>,
    count: Option<usize>,
    scene_arg: &SceneArg,
    scene: &Scene,
) -> Result<BenchCamera> {
    // A resolution of the sweep replaces --width/--height/--scale.
    let mut view = args.view.clone();
    if let Some((w, h)) = res {
        (view.width, view.height, view.scale) = (Some(w), Some(h), None);
    }
    // Synthetic scenes are no model directory.
    let source = match count {
        Some(_) => SceneArg {
            scene: None,
            demo: false,
            iteration: None,
            spz: Default::default(),
        },
        None => scene_arg.clone(),
    };
    let timed = choose_camera(&view, &args.path, &source, scene)?;
    timed.camera.validate()?;
    Ok(timed)
}

/// One point of the sweep: what is timed.
struct Point<'a> {
    scene: &'a verisplat::core::model::ActivatedScene,
    name: &'a str,
    timed: &'a BenchCamera,
    kernel: verisplat::cpu::SplatKernel,
    rules: verisplat::cpu::Rules,
    shader: Option<&'a verisplat::fields::mlp::Mlp>,
}

/// The reports of the points run so far (of `points` in the sweep).
struct Runs {
    points: usize,
    forward: Vec<verisplat::app::bench::BenchReport>,
    backward: Vec<verisplat::app::bench::BackwardReport>,
}

impl Runs {
    /// Benchmarks one point (forward, or with `--backward` forward and backward), prints
    /// its report and keeps it.
    fn bench(
        &mut self,
        args: &BenchArgs,
        renderer: Option<&mut GpuRenderer>,
        point: &Point,
    ) -> Result<()> {
        let Point {
            scene: act,
            name,
            timed,
            kernel,
            rules,
            shader,
        } = *point;
        let cam = &timed.camera;
        let opts = verisplat::cpu::RenderOptions {
            scale_modifier: args.scale_modifier,
            kernel,
            rules,
            reproducible: args.kernel.reproducible,
            ..Default::default()
        };
        let points = self.points;
        let mut renderer = renderer;
        if let (true, Some(r)) = (args.backward, renderer.as_deref_mut()) {
            let report = verisplat::app::bench::bench_backward(
                r,
                act,
                name,
                timed,
                &opts,
                shader,
                args.frames,
                args.warmup,
            );
            if let Some(report) = kept_in_sweep(report, points, name, cam)? {
                if !args.quiet {
                    outln!("{}", report.to_text());
                }
                self.backward.push(report);
            }
            return Ok(());
        }
        let report = match renderer {
            Some(r) => verisplat::app::bench::bench_gpu(
                r,
                act,
                name,
                timed,
                &opts,
                args.frames,
                args.warmup,
            ),
            None => Ok(verisplat::app::bench::bench_cpu(
                act,
                name,
                timed,
                &opts,
                args.frames,
                args.warmup,
            )),
        };
        if let Some(report) = kept_in_sweep(report, points, name, cam)? {
            if !args.quiet {
                outln!("{}", report.to_text());
            }
            self.forward.push(report);
        }
        Ok(())
    }
}

/// The end of a `--backward` run: its validation check and JSON report.
fn write_backward_reports(
    args: &BenchArgs,
    renderer: Option<&GpuRenderer>,
    files: &ReportFiles,
    backward_reports: &[verisplat::app::bench::BackwardReport],
) -> Result<()> {
    if backward_reports.is_empty() {
        bail!("every point of the sweep exceeded the device's limits (see above)");
    }
    if let Some(r) = renderer {
        fail_on_validation_messages(r.ctx())?;
    }
    if let Some(path) = &files.json {
        let text = verisplat::app::bench::backward_to_json(backward_reports);
        output::write_bytes_atomically(path, args.overwrite, text.as_bytes())?;
    }
    Ok(())
}

/// The end of a forward run: the sweep's summary, the validation check and the report
/// files (JSON, CSV, SVG plot).
fn write_reports(
    args: &BenchArgs,
    renderer: Option<&GpuRenderer>,
    files: &ReportFiles,
    points: usize,
    reports: &[verisplat::app::bench::BenchReport],
) -> Result<()> {
    if points > 1 && !args.quiet {
        outln!("sweep summary (medians):");
        out!("{}", verisplat::app::bench::summary_table(reports));
    }
    if reports.is_empty() {
        bail!("every point of the sweep exceeded the device's limits (see above)");
    }
    if let Some(r) = renderer {
        fail_on_validation_messages(r.ctx())?;
    }
    let write_text = |path: &PathBuf, text: String| -> Result<()> {
        output::write_bytes_atomically(path, args.overwrite, text.as_bytes())?;
        Ok(())
    };
    if let Some(path) = &files.json {
        write_text(path, verisplat::app::bench::to_json(reports))?;
    }
    if let Some(path) = &files.csv {
        write_text(path, verisplat::app::bench::to_csv(reports))?;
    }
    if let Some(path) = &files.plot {
        let svg = verisplat::app::bench::plot_sweep(reports).map_err(anyhow::Error::msg)?;
        write_text(path, svg)?;
    }
    Ok(())
}
