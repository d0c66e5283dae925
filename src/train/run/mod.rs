//! The training loop of the original method on the differentiable rasterizer: per
//! iteration one training view, forward, the loss and its gradient on the device
//! ([`super::loss::GpuLoss`]), backward, the densification statistics, and an Adam step
//! ([`super::model`]); SH degree up every 1000 iterations, densification from 500 to
//! 15000 every 100, opacity reset every 3000; the model directory as the original writes
//! it.
//!
//! The parameters, Adam's state and the densification statistics stay on the device
//! ([`super::device`]): an iteration renders, computes the loss and its gradient, runs the
//! backward pass and steps Adam without a Gaussian crossing to the host; only the loss's
//! sums (16 bytes) are read back. The state comes down for what the host does every few
//! hundred iterations (densification, opacity reset, evaluation, checkpoints, saving).
//! Feature splats (their channels and the neural shader's weights) and gradient clipping
//! too. [`TrainOptions::host_optimizer`] steps on the host instead
//! ([`super::model::Model::step`], through the rasterizer's upload/read-back API), for
//! comparisons. Same rules either way.
//!
//! The loop ([`train`]) goes through each iteration's phases in turn, carrying its state
//! from one to the next: the view and what the schedule asks for (`schedule`), the step
//! on the device or the host (`step`), the host's changes to the model: densification,
//! MCMC refinement, opacity reset (`densify`), the evaluation (`evaluate`) and the files
//! (`output`); a run starts from the data set's points or a checkpoint (`start`).

mod densify;
mod evaluate;
mod output;
mod schedule;
mod start;
mod step;

use super::data::Dataset;
use super::device::DeviceModel;
use super::loss::{GpuLoss, LossValue};
use super::model::{Model, Settings};
use crate::core::gen::Rng;
use crate::core::model::RenderOptions;
use crate::render::backward::differentiable::DiffRasterizer;
use schedule::{Due, Plan};
use std::cell::OnceCell;
use std::path::{Path, PathBuf};

/// What a training run is asked to do.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Optimisation and densification settings.
    pub settings: Settings,
    /// Largest SH degree (0-3).
    pub sh_degree: u32,
    /// White instead of black background.
    pub white_background: bool,
    /// Iterations after which the model is saved (the last one always is).
    pub save_iterations: Vec<u32>,
    /// Iterations after which the test views (or, without them, up to five training
    /// views) are evaluated.
    pub test_iterations: Vec<u32>,
    /// Seed of the view order, the random start and the split samples.
    pub seed: u64,
    /// Random Gaussians when the data set has no points.
    pub random_points: usize,
    /// Replace the iterations' files that exist.
    pub overwrite: bool,
    /// Feature splats: the neural shader to start from; the Gaussians then learn its
    /// feature channels (instead of SH colour) and the shader its weights, jointly.
    pub shader: Option<crate::fields::mlp::Mlp>,
    /// The alpha falloff trained with (recorded in the PLY).
    pub kernel: crate::core::model::SplatKernel,
    /// The rasterizer's rules (`--rules`), recorded in the model.
    pub rules: crate::core::model::Rules,
    /// The reproducible mode (`--reproducible`, [`RenderOptions::reproducible`]): the
    /// blends and their backward take the CPU reference's exp and unfused arithmetic.
    pub reproducible: bool,
    /// Iterations after which a checkpoint (`chkpntN.safetensors`) is written.
    pub checkpoint_iterations: Vec<u32>,
    /// Continue from this checkpoint (of the same data set and settings).
    pub resume: Option<super::checkpoint::Checkpoint>,
    /// Set (Ctrl-C, SIGTERM): write a checkpoint after the current iteration and stop.
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Step on the host (upload the Gaussians and read their gradients back every
    /// iteration) even where the device could: for comparisons.
    pub host_optimizer: bool,
    /// Keep the training photos on the device, each uploaded once, when they take at most
    /// a quarter of its memory budget (the default); false: upload each photo every time
    /// it is trained on. The same bits either way (`VERISPLAT_TRAIN_PHOTOS=host` in
    /// `verisplat train`, for comparisons).
    pub photos_on_device: bool,
    /// The `-r` the photos were loaded at, for `cfg_args` (`None`: not given, written as
    /// the original's -1).
    pub resolution: Option<u32>,
    /// Mip-Splatting's 3D filter (`--mip-filter`, [`crate::train::model::mip`]), folded
    /// into the saved scales and opacities.
    pub mip_filter: bool,
    /// Per-photo appearance (`--appearance`, [`crate::train::appearance`]): none, or an
    /// affine colour transform per training photo learnt with the scene.
    pub appearance: crate::train::appearance::AppearanceSettings,
}

impl Default for TrainOptions {
    /// The original's settings and `verisplat train`'s defaults: SH degree 3, black
    /// background, seed 0, 100,000 random Gaussians without points, nothing saved before
    /// the last iteration, the state on the device.
    fn default() -> Self {
        TrainOptions {
            settings: Settings::default(),
            sh_degree: 3,
            white_background: false,
            save_iterations: Vec::new(),
            test_iterations: Vec::new(),
            seed: 0,
            random_points: 100_000,
            overwrite: false,
            shader: None,
            kernel: crate::core::model::SplatKernel::default(),
            rules: crate::core::model::Rules::default(),
            reproducible: false,
            checkpoint_iterations: Vec::new(),
            resume: None,
            cancel: None,
            host_optimizer: false,
            photos_on_device: true,
            resolution: None,
            mip_filter: false,
            appearance: Default::default(),
        }
    }
}

impl TrainOptions {
    /// What a checkpoint must match to be resumed: the data set's views and the settings
    /// that shape the run (not the output or evaluation choices).
    fn fingerprint(&self, data: &Dataset) -> String {
        format!(
            "{:?}|sh {}|white {}|seed {}|points {}|kernel {}|shader {}|train {:?}",
            Settings {
                iterations: 0,
                ..self.settings.clone()
            },
            self.sh_degree,
            self.white_background,
            self.seed,
            self.random_points,
            self.kernel,
            self.shader.as_ref().map_or(0, |m| m.layers.len()),
            data.train
                .iter()
                .map(|v| (&v.camera.name, v.camera.width, v.camera.height))
                .collect::<Vec<_>>()
        ) + match self.rules {
            // The original's leave the fingerprints of earlier checkpoints as they were.
            crate::core::model::Rules::Original => "",
            crate::core::model::Rules::Gsplat => "|rules gsplat",
        } + if self.mip_filter { "|mip-filter" } else { "" }
            + if self.reproducible {
                "|reproducible"
            } else {
                ""
            }
            + &appearance_fingerprint(&self.appearance)
            + &lens_fingerprint(data)
            + &mask_fingerprint(data)
    }
}

/// The training views' masks when one has a mask (a masked run resumes only from a
/// checkpoint of the same masks): a 64-bit FNV-1a hash of every view's flags; empty
/// otherwise, so that the fingerprints of unmasked data sets stay those of earlier
/// checkpoints.
fn mask_fingerprint(data: &Dataset) -> String {
    if data.train.iter().all(|v| v.mask.is_none()) {
        return String::new();
    }
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    for v in &data.train {
        let flags = v.mask.iter().flatten().map(|&k| u8::from(k) + 1);
        for byte in flags.chain([0]) {
            hash = (hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    format!("|masks {hash:016x}")
}

/// The per-photo appearance's settings when one is learnt (a run with one resumes only
/// from a checkpoint of the same); empty without, so that the fingerprints of earlier
/// checkpoints stay as they were.
fn appearance_fingerprint(a: &crate::train::appearance::AppearanceSettings) -> String {
    match a.mode {
        crate::train::appearance::AppearanceMode::None => String::new(),
        mode => format!(
            "|appearance {mode} lr {:?} reg {:?} from {}",
            a.lr, a.reg, a.from
        ),
    }
}

/// The training cameras' lenses when one is not the pinhole (a run through a lens resumes
/// only from a checkpoint of the same lenses); empty otherwise, so that the fingerprints of
/// pinhole data sets, and of undistorted ones, stay those of earlier checkpoints.
fn lens_fingerprint(data: &Dataset) -> String {
    if data.train.iter().all(|v| v.camera.lens.is_pinhole()) {
        return String::new();
    }
    let lenses: Vec<_> = data.train.iter().map(|v| &v.camera.lens).collect();
    format!("|lenses {lenses:?}")
}

/// Evaluation of a set of views.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Evaluation {
    /// Iteration.
    pub iteration: u32,
    /// "test" or "train".
    pub split: String,
    /// Views evaluated.
    pub views: usize,
    /// Mean PSNR (dB) of the clamped renders.
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
    /// Mean L1.
    pub l1: f64,
    /// Mean FLIP (`verisplat eval`'s, the default observer).
    pub flip: f64,
}

/// What a finished run reports.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TrainReport {
    /// Iterations run.
    pub iterations: u32,
    /// Gaussians at the end.
    pub gaussians: usize,
    /// Evaluations at the test iterations.
    pub evaluations: Vec<Evaluation>,
    /// Files written.
    pub written: Vec<PathBuf>,
    /// Iterations per second of the whole loop (wall clock).
    pub iterations_per_second: f64,
    /// Device memory at the peak (sampled every 10 iterations), bytes.
    pub device_bytes_peak: u64,
    /// Whether the iterations kept the state on the device ([`super::device`]).
    pub on_device: bool,
    /// Mean milliseconds per iteration of each device stage (GPU timestamps): the
    /// forward pass's, then the loss, the backward pass's and the step (with the state on
    /// the device; the host optimiser's loss and step are not device stages).
    pub stage_ms: Vec<(String, f64)>,
    /// Mean milliseconds per iteration of the host's wall clock in each part of the loop
    /// (`step`, `model changes`, `outputs`, `checkpoints`, and `other`: the rest).
    pub host_ms: Vec<(String, f64)>,
    /// Mean per iteration of the step's device calls: command buffers submitted and the
    /// host's milliseconds recording, submitting and waiting for them
    /// ([`crate::gpu::host_time`]); the step's other time is the host's own work.
    pub step_device_calls: crate::gpu::HostTime,
}

/// Sums of per-stage milliseconds, in the order the stages first appear.
#[derive(Default)]
struct StageSums(Vec<(String, f64)>);

impl StageSums {
    fn add<S: AsRef<str>>(&mut self, stages: impl IntoIterator<Item = (S, f64)>) {
        for (name, ms) in stages {
            let name = name.as_ref();
            match self.0.iter_mut().find(|(n, _)| n == name) {
                Some((_, sum)) => *sum += ms,
                None => self.0.push((name.to_string(), ms)),
            }
        }
    }
}

/// One iteration's figures, for a progress display.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Iteration (1-based).
    pub iteration: u32,
    /// Of.
    pub iterations: u32,
    /// The loss.
    pub loss: LossValue,
    /// Gaussians now.
    pub gaussians: usize,
}

/// A training error.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The device.
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    /// Writing the model.
    #[error(transparent)]
    Write(#[from] crate::core::fsutil::WriteError),
    /// Stopped by a signal after writing a checkpoint.
    #[error("{message}")]
    Interrupted {
        /// What happened and how to resume.
        message: String,
    },
    /// Anything else, one sentence.
    #[error("{0}")]
    Other(String),
}

/// What a run keeps fixed: its inputs and what follows from them.
struct Job<'a> {
    data: &'a Dataset,
    /// The model directory.
    out: &'a Path,
    opts: &'a TrainOptions,
    /// What a checkpoint must match to be resumed ([`TrainOptions::fingerprint`]).
    fingerprint: String,
    /// Replace existing files: asked for, or a resumed run replacing its own.
    overwrite: bool,
    /// The background and kernel every render uses.
    render_opts: RenderOptions,
}

impl<'a> Job<'a> {
    fn new(data: &'a Dataset, out: &'a Path, opts: &'a TrainOptions) -> Self {
        let bg = if opts.white_background {
            [1.0; 3]
        } else {
            [0.0; 3]
        };
        Job {
            data,
            out,
            opts,
            fingerprint: opts.fingerprint(data),
            // A resumed run replaces the files of the run it continues.
            overwrite: opts.overwrite || opts.resume.is_some(),
            render_opts: RenderOptions {
                background: bg,
                kernel: opts.kernel,
                rules: opts.rules,
                reproducible: opts.reproducible,
                ..Default::default()
            },
        }
    }

    /// Mip-Splatting's 3D filter of centres `positions` from the training cameras.
    fn mip_filters(&self, positions: &[[f32; 3]]) -> Vec<f32> {
        let cams: Vec<_> = self.data.train.iter().map(|v| &v.camera).collect();
        crate::train::model::mip::filters(positions, &cams)
    }
}

/// What the loop carries from one iteration to the next.
struct Run<'p> {
    model: Model,
    rng: Rng,
    /// The training views still to come in this round, last first.
    order: Vec<usize>,
    /// The first iteration to run (after a resumed checkpoint's).
    first: u32,
    /// The model on the device (none on the host path, or after the host changed it).
    dev: Option<DeviceModel<'p>>,
    written: Vec<PathBuf>,
    evaluations: Vec<Evaluation>,
    /// Device memory at the peak so far, bytes.
    peak: u64,
    stage_sums: StageSums,
    /// The training photos' appearance transforms (`--appearance affine`).
    appearance: Option<crate::train::appearance::Appearances>,
}

/// Refuses options no run can start with.
fn check_options(opts: &TrainOptions) -> Result<(), TrainError> {
    if opts.sh_degree > 3 {
        return Err(TrainError::Other(format!(
            "--sh-degree must be 0..3, not {}",
            opts.sh_degree
        )));
    }
    if opts.settings.iterations == 0 {
        return Err(TrainError::Other("--iterations must be at least 1".into()));
    }
    Ok(())
}

/// Trains on `data` and writes the model directory `out`. `progress` sees every
/// iteration; `note` the one-line messages (evaluations, densification).
pub fn train(
    data: &Dataset,
    out: &Path,
    opts: &TrainOptions,
    rast: &mut DiffRasterizer,
    loss: &mut GpuLoss,
    progress: &mut dyn FnMut(Progress),
    note: &mut dyn FnMut(String),
) -> Result<TrainReport, TrainError> {
    let s = &opts.settings;
    check_options(opts)?;
    let job = Job::new(data, out, opts);
    // The step's pipelines, built at the first iteration on the device (once per run).
    let pipelines = OnceCell::new();
    let mut run = Run::start(&job, note)?;
    output::write_cameras_and_cfg(&job, &mut run.written)?;
    let start = std::time::Instant::now();
    // The host's wall clock in each part of the loop, and the step's device calls.
    let mut host = StageSums::default();
    let mut calls = crate::gpu::HostTime::default();
    // Adds the time since `t` to part `name` and restarts `t`.
    let lap = |host: &mut StageSums, name: &str, t: &mut std::time::Instant| {
        host.add([(name, t.elapsed().as_secs_f64() * 1e3)]);
        *t = std::time::Instant::now();
    };
    // The state on the device, unless the caller asks for the host optimiser.
    let device_path = !opts.host_optimizer;
    // The photos on the device too, each uploaded once, when they take at most a quarter
    // of the device's memory budget (and none kept from a run before, whatever the path).
    {
        let ctx = rast.renderer().ctx();
        let wanted = device_path && opts.photos_on_device;
        let pixels: Vec<u64> = data.train.iter().map(|v| v.image.len() as u64).collect();
        let max = if wanted {
            ctx.info().memory_budget / 4
        } else {
            0
        };
        let kept = loss.keep_photos(ctx, &pixels, max)?;
        if wanted && !kept {
            note(format!(
                "the {} training photos take more than a quarter of the device's memory budget: each is uploaded when it is trained on",
                pixels.len()
            ));
        }
    }
    for it in run.first..=s.iterations {
        let mut t = std::time::Instant::now();
        let (photo, view) = run.next_view(&job, it);
        let plan = Plan::at(&job, it, run.model.len());
        let due = Due::at(&job, it);
        // The original's order: the evaluation and the save at an iteration see the model
        // before its step, densification and opacity reset (and the last iteration's step
        // and changes are in no output); a checkpoint (what a resumed run continues from)
        // sees the model after them.
        if due.evaluate || due.save {
            run.bring_down_for_outputs(rast)?;
            if due.evaluate {
                run.evaluate(&job, rast, it, note)?;
            }
            if due.save {
                run.save(&job, it, note)?;
            }
        }
        lap(&mut host, "outputs", &mut t);
        let before = rast.renderer().ctx().host_time();
        let value = if device_path {
            run.device_step(&job, &pipelines, rast, loss, (photo, view), &plan)?
        } else {
            run.host_step(&job, rast, loss, (photo, view), &plan)?
        };
        calls += rast.renderer().ctx().host_time().since(&before);
        lap(&mut host, "step", &mut t);
        if !value.total.is_finite() {
            return Err(TrainError::Other(format!(
                "training diverged at iteration {it}: the loss is {} ({} Gaussians); the last model saved is the last good one",
                value.total,
                run.model.len()
            )));
        }
        run.bring_down(rast, &plan, &due)?;
        if it < s.iterations {
            run.change_model(&job, &plan)?;
        }
        lap(&mut host, "model changes", &mut t);
        if it % 10 == 1 {
            run.peak = run.peak.max(rast.renderer().ctx().live_allocations().1);
        }
        progress(Progress {
            iteration: it,
            iterations: s.iterations,
            loss: value,
            gaussians: run.model.len(),
        });
        lap(&mut host, "other", &mut t);
        if due.checkpoint {
            let path = run.checkpoint(&job, it, job.overwrite)?;
            note(format!("[ITER {it}] checkpoint {}", path.display()));
        }
        lap(&mut host, "checkpoints", &mut t);
        if due.cancelled && it < s.iterations {
            let path = run.checkpoint(&job, it, true)?;
            return Err(TrainError::Interrupted {
                message: format!(
                    "interrupted after iteration {it}; wrote {}; continue with the same command and --resume {}",
                    path.display(),
                    path.display()
                ),
            });
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let first = run.first;
    let iterations = (s.iterations + 1 - first).max(1);
    Ok(TrainReport {
        iterations: s.iterations,
        gaussians: run.model.len(),
        evaluations: run.evaluations,
        written: run.written,
        iterations_per_second: (s.iterations + 1 - first) as f64 / seconds.max(1e-9),
        device_bytes_peak: run.peak,
        on_device: device_path,
        stage_ms: run
            .stage_sums
            .0
            .into_iter()
            .map(|(n, ms)| (n, ms / f64::from(iterations)))
            .collect(),
        host_ms: host
            .0
            .into_iter()
            .map(|(n, ms)| (n, ms / f64::from(iterations)))
            .collect(),
        step_device_calls: calls.per(u64::from(iterations)),
    })
}
