//! Rendering the frames of a path as splats: on one device, spread over several
//! (`--devices`), or with the CPU reference (`--cpu`), with the per-stage timings of
//! `--timings`.

use super::args::RenderArgs;
use super::time::Animation;
use crate::cli::common::fail_on_validation_messages;
use crate::cli::plural;
use anyhow::{bail, Result};
use verisplat::app::sequence::{ProgressStyle, Summary};
use verisplat::core::console::note;
use verisplat::render::forward::shade::GpuShader;
use verisplat::render::frame::path::GpuPath;
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};

/// What each renderer of `render` gets: the command's arguments, the scene, the frames to
/// render and how to render and write them.
#[derive(Clone, Copy)]
pub(super) struct Job<'a> {
    pub(super) args: &'a RenderArgs,
    pub(super) scene: &'a verisplat::core::scene::ActivatedScene,
    /// `--time-range`: each frame's scene (then `scene` is unused).
    pub(super) animation: Option<&'a Animation>,
    pub(super) frames: &'a [verisplat::app::sequence::FramePlan],
    pub(super) opts: &'a verisplat::cpu::RenderOptions,
    pub(super) run_opts: &'a verisplat::app::sequence::RunOptions,
    /// Render the feature channels (`--mode features`, or for `shader`).
    pub(super) features: bool,
    pub(super) shader: Option<&'a verisplat::fields::mlp::Mlp>,
}

/// `--mode normal` or `median-depth`: the frames are rendered with the surface pass
/// (`core::model::surface`).
fn surface(job: &Job) -> bool {
    job.args.mode.is_some_and(|m| m.is_surface())
}

/// The variable that makes `render` read back floats even where every output is 8-bit
/// colour (`VERISPLAT_READBACK=float`): the files are the same bytes either way, which
/// the tests check with it, and benchmarks compare the two readbacks with it.
pub(super) const READBACK_ENV: &str = "VERISPLAT_READBACK";

/// Whether the device path reads back only the colour, packed to 8-bit RGBA on the
/// device: when every output of the run is 8-bit RGB colour
/// ([`verisplat::app::sequence::reads_rgb8_only`]: RGB PNGs, a video) and the frames blend
/// no features (a shader's or a surface pass's frames read back floats), unless
/// [`READBACK_ENV`] asks for floats. Anything else (EXR, 16-bit or RGBA PNG, depth,
/// alpha, features, normals, .npy) reads back the float planes.
fn reads_rgb8(job: &Job, features: bool) -> Result<bool> {
    match verisplat::core::former_name::env_var(READBACK_ENV).as_deref() {
        None | Some("") | Some("auto") => {}
        Some("float") => return Ok(false),
        Some(other) => bail!("{READBACK_ENV}={other:?}: expected float or auto"),
    }
    Ok(!features && verisplat::app::sequence::reads_rgb8_only(job.frames))
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

pub(super) fn render_cpu(job: &Job) -> Result<(Summary, String)> {
    let (scene, opts, shader) = (job.scene, job.opts, job.shader);
    if job.args.gpu.verbose {
        note!(
            "renderer: the CPU reference on {}",
            plural(rayon::current_num_threads(), "thread")
        );
    }
    let mut sums = StageSums::default();
    let mut pairs = 0;
    let mut render = |p: &verisplat::app::sequence::FramePlan| {
        let cam = &p.camera;
        let at_time = job.animation.map(|a| a.scene(p.index));
        let scene = at_time.as_ref().unwrap_or(scene);
        let (mut frame, t) = if surface(job) {
            let start = std::time::Instant::now();
            let frame = verisplat::cpu::surface::render_surface(scene, cam, opts);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let t = verisplat::cpu::CpuTimings {
                total: ms,
                ..Default::default()
            };
            (frame, t)
        } else if job.features || shader.is_some() {
            verisplat::cpu::render_features_timed(scene, cam, opts)
        } else {
            verisplat::cpu::render_timed(scene, cam, opts)
        };
        let mut stages = t.stages().to_vec();
        let mut total = t.total;
        if let Some(mlp) = shader {
            let start = std::time::Instant::now();
            frame.color = verisplat::fields::mlp::shade(
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
    let summary = verisplat::app::sequence::run_each(job.frames, &mut render, job.run_opts);
    if job.args.timings {
        sums.print("CPU ms");
        note!("tile pairs {pairs} (last frame)");
    }
    Ok((summary?, "on the CPU".to_string()))
}

/// `--devices`: one renderer per device, each on its own thread with a contiguous block
/// of the frames (the split of `--shard`); the progress is each block's summary.
pub(super) fn render_on_devices(job: &Job, devices: &str) -> Result<(Summary, String)> {
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
    let run_opts = verisplat::app::sequence::RunOptions {
        progress: ProgressStyle::Quiet,
        ..job.run_opts.clone()
    };
    let results: Vec<Result<(Summary, String)>> = std::thread::scope(|s| {
        let handles: Vec<_> = chosen[..workers]
            .iter()
            .enumerate()
            .map(|(w, device)| {
                let block = verisplat::app::shard::Shard {
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

/// The device path: one renderer on `ctx`, the frames of a path in flight
/// ([`render_path`]) or of an animation one by one ([`render_animation`]).
pub(super) fn render_gpu(job: &Job, ctx: verisplat::gpu::GpuContext) -> Result<(Summary, String)> {
    let args = job.args;
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
    let gpu_shader = match job.shader {
        Some(m) => Some(GpuShader::new(renderer.ctx(), m)?),
        None => None,
    };
    let summary = match job.animation {
        Some(anim) => render_animation(job, anim, &mut renderer, gpu_shader.as_ref())?,
        None => render_path(job, &mut renderer, gpu_shader.as_ref())?,
    };
    fail_on_validation_messages(renderer.ctx())?;
    let device = renderer.ctx().info().name.clone();
    Ok((summary, format!("on {device}")))
}

/// `--time-range` on the device: each frame its own scene, uploaded, rendered (read back
/// as floats), dropped.
fn render_animation(
    job: &Job,
    anim: &Animation,
    renderer: &mut GpuRenderer,
    gpu_shader: Option<&GpuShader>,
) -> Result<Summary> {
    let Job {
        args,
        frames,
        opts,
        run_opts,
        features,
        shader,
        ..
    } = *job;
    let mut sums = StageSums::default();
    let mut device_bytes = 0;
    let summary = verisplat::app::sequence::run_each(
        frames,
        &mut |p| {
            let at_time = anim.scene(p.index);
            let gpu_scene = renderer.upload(&at_time)?;
            device_bytes = gpu_scene.device_bytes();
            let request = FrameRequest::new(&gpu_scene, &p.camera, opts);
            let frame = if surface(job) {
                let f = renderer.upload_surface(&at_time)?;
                renderer.render(&request.features(&f))
            } else if features || shader.is_some() {
                let f = renderer.upload_features(&at_time)?;
                renderer.render(&request.features(&f).shader(gpu_shader))
            } else {
                renderer.render(&request)
            }
            .and_then(Rendered::into_frame)?;
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
    Ok(summary?)
}

/// The frames of a path of one scene on the device, up to `--frames-in-flight` at once,
/// read back as 8-bit colour or as floats ([`reads_rgb8`]).
fn render_path(
    job: &Job,
    renderer: &mut GpuRenderer,
    gpu_shader: Option<&GpuShader>,
) -> Result<Summary> {
    let Job {
        args,
        scene,
        frames,
        opts,
        run_opts,
        features,
        shader,
        ..
    } = *job;
    let gpu_scene = renderer.upload(scene)?;
    let gpu_features = if surface(job) {
        Some(renderer.upload_surface(scene)?)
    } else if features || shader.is_some() {
        Some(renderer.upload_features(scene)?)
    } else {
        None
    };
    let rgb8 = reads_rgb8(job, gpu_features.is_some())?;
    if args.gpu.verbose || args.timings {
        note!(
            "readback: {}",
            if rgb8 {
                "8-bit colour packed on the device (4 bytes a pixel)"
            } else {
                "float colour, alpha and depth (20 bytes a pixel)"
            }
        );
    }
    let mut sums = StageSums::default();
    let mut last_stats = None;
    let summary = {
        let mut source = GpuPath::new(renderer, &gpu_scene, opts, run_opts.frames_in_flight)
            .rgb8(rgb8)
            .on_frame(|t, stats| {
                sums.add(&t.stages(), t.total);
                last_stats = Some(stats.clone());
            });
        if let Some(f) = &gpu_features {
            source = source.with_features(f, gpu_shader);
        }
        verisplat::app::sequence::run_pipelined(frames, &mut source, run_opts)
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
    Ok(summary?)
}
