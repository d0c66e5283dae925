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

use super::data::{Dataset, View};
use super::device::{DeviceModel, McmcStep, Step, StepPipelines};
use super::loss::{GpuLoss, LossValue};
use super::model::noise_key;
use super::model::{position_lr, Model, Settings};
use crate::camera::Camera;
use crate::gen::Rng;
use crate::gpu::sync::{barrier, Access};
use crate::model::grad::PixelGrads;
use crate::model::RenderOptions;
use crate::render::backward::DeviceFeatures;
use crate::render::differentiable::DiffRasterizer;
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
    pub shader: Option<crate::mlp::Mlp>,
    /// The alpha falloff trained with (recorded in the PLY).
    pub kernel: crate::model::SplatKernel,
    /// Iterations after which a checkpoint (`chkpntN.safetensors`) is written.
    pub checkpoint_iterations: Vec<u32>,
    /// Continue from this checkpoint (of the same data set and settings).
    pub resume: Option<super::checkpoint::Checkpoint>,
    /// Set (Ctrl-C, SIGTERM): write a checkpoint after the current iteration and stop.
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Step on the host (upload the Gaussians and read their gradients back every
    /// iteration) even where the device could: for comparisons.
    pub host_optimizer: bool,
}

impl Default for TrainOptions {
    /// The original's settings and `vksplat train`'s defaults: SH degree 3, black
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
            kernel: crate::model::SplatKernel::default(),
            checkpoint_iterations: Vec::new(),
            resume: None,
            cancel: None,
            host_optimizer: false,
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
        )
    }
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
    /// Mean FLIP (`vksplat eval`'s, the default observer).
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
    Write(#[from] crate::fsutil::WriteError),
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

fn write(
    path: &Path,
    bytes: &[u8],
    overwrite: bool,
    written: &mut Vec<PathBuf>,
) -> Result<(), TrainError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| TrainError::Other(format!("{}: cannot create: {e}", dir.display())))?;
    }
    crate::fsutil::write_bytes_atomically(path, overwrite, bytes)?;
    written.push(path.to_path_buf());
    Ok(())
}

/// The image's name without its extension (the original's `image_name`).
fn stem(name: &str) -> &str {
    name.rsplit_once('.').map_or(name, |(s, _)| s)
}

/// The points as the original's `input.ply` (x y z nx ny nz red green blue).
fn points_ply(points: &[crate::camera::colmap::Point3D]) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.len()
    )
    .into_bytes();
    for p in points {
        for v in p.position {
            out.extend((v as f32).to_le_bytes());
        }
        out.extend([0u8; 12]);
        out.extend(p.color);
    }
    out
}

/// Renders `views` and compares them with their photos.
fn evaluate(
    rast: &mut DiffRasterizer,
    model: &Model,
    views: &[&View],
    opts: &RenderOptions,
    iteration: u32,
    split: &str,
) -> Result<Evaluation, TrainError> {
    let params = model.params();
    rast.set_shader(model.shader.as_ref())?;
    let (mut psnr, mut ssim, mut l1, mut flip) = (0.0, 0.0, 0.0, 0.0);
    for v in views {
        let (frame, _) = rast.forward(&params, &v.camera, opts)?;
        let img: Vec<f32> = frame
            .color
            .iter()
            .flatten()
            .map(|c| c.clamp(0.0, 1.0))
            .collect();
        let gt: Vec<f32> = v.image.iter().flatten().copied().collect();
        let (w, h) = (v.camera.width as usize, v.camera.height as usize);
        psnr += crate::metrics::psnr(&gt, &img, 1.0);
        ssim += crate::metrics::ssim(&gt, &img, w, h, 3);
        flip += crate::metrics::flip(&gt, &img, w, h, crate::metrics::flip_default_ppd());
        l1 += img
            .iter()
            .zip(&gt)
            .map(|(a, b)| (a - b).abs() as f64)
            .sum::<f64>()
            / img.len() as f64;
    }
    let n = views.len().max(1) as f64;
    Ok(Evaluation {
        iteration,
        split: split.to_string(),
        views: views.len(),
        psnr: psnr / n,
        ssim: ssim / n,
        l1: l1 / n,
        flip: flip / n,
    })
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
    if opts.sh_degree > 3 {
        return Err(TrainError::Other(format!(
            "--sh-degree must be 0..3, not {}",
            opts.sh_degree
        )));
    }
    if s.iterations == 0 {
        return Err(TrainError::Other("--iterations must be at least 1".into()));
    }
    let mut rng = Rng(opts.seed);
    let mut written = Vec::new();
    let fingerprint = opts.fingerprint(data);
    // A resumed run replaces the files of the run it continues.
    let overwrite = opts.overwrite || opts.resume.is_some();
    // The original's start: points3D, or random points around the cameras' centre.
    let mut model = match &data.points {
        Some(points) => {
            write(
                &out.join("input.ply"),
                &points_ply(points),
                overwrite,
                &mut written,
            )?;
            Model::from_points(points, opts.sh_degree)
        }
        None => {
            let (centre, half) = data.random_box.unwrap_or_else(|| {
                let (mean, extent) = super::data::cameras_centre_and_extent(&data.train);
                (mean.to_array(), extent)
            });
            note(format!(
                "{} has no points: starting from {} random Gaussians in the cube of half side {half:.3} around ({:.3}, {:.3}, {:.3})",
                data.source.display(),
                opts.random_points,
                centre[0],
                centre[1],
                centre[2]
            ));
            Model::random(opts.random_points, centre, half, opts.sh_degree, &mut rng)
        }
    };
    model.scene.kernel = opts.kernel;
    if let Some(mlp) = &opts.shader {
        model = model.with_features(mlp.clone(), &mut rng);
    }
    let mut first = 1;
    let mut order: Vec<usize> = Vec::new();
    if let Some(c) = &opts.resume {
        if c.fingerprint != fingerprint {
            return Err(TrainError::Other(
                "the checkpoint belongs to another data set or other settings; resume with the ones it was written with".into(),
            ));
        }
        if c.iteration >= s.iterations {
            return Err(TrainError::Other(format!(
                "the checkpoint is at iteration {}, not before --iterations {}",
                c.iteration, s.iterations
            )));
        }
        model = c.model.clone();
        rng = Rng(c.rng);
        order = c.order.clone();
        first = c.iteration + 1;
        note(format!(
            "resuming after iteration {} ({} Gaussians)",
            c.iteration,
            model.len()
        ));
    }
    // cameras.json: the test cameras, then the training ones (the original's order), at
    // the photos' own size.
    let all: Vec<(usize, Camera)> = data
        .test
        .iter()
        .chain(&data.train)
        .enumerate()
        .map(|(i, v)| {
            let mut c = v.camera.clone();
            c.name = stem(&c.name).to_string();
            (i, c)
        })
        .collect();
    let json = crate::camera::inria::to_json(&all).map_err(|e| TrainError::Other(e.to_string()))?;
    write(
        &out.join("cameras.json"),
        json.as_bytes(),
        overwrite,
        &mut written,
    )?;
    let cfg = format!(
        "Namespace(sh_degree={}, source_path='{}', model_path='{}', images='images', resolution=-1, white_background={}, data_device='cuda', eval={})",
        opts.sh_degree,
        data.source.display(),
        out.display(),
        if opts.white_background { "True" } else { "False" },
        if data.test.is_empty() { "False" } else { "True" },
    );
    write(
        &out.join("cfg_args"),
        cfg.as_bytes(),
        overwrite,
        &mut written,
    )?;
    let bg = if opts.white_background {
        [1.0; 3]
    } else {
        [0.0; 3]
    };
    let render_opts = RenderOptions {
        background: bg,
        kernel: opts.kernel,
        ..Default::default()
    };
    let mut evaluations = Vec::new();
    let start = std::time::Instant::now();
    let mut peak = 0u64;
    let checkpoint = |it: u32,
                      model: &Model,
                      rng: &Rng,
                      order: &[usize],
                      written: &mut Vec<PathBuf>,
                      overwrite: bool| {
        let c = super::checkpoint::Checkpoint {
            iteration: it,
            rng: rng.0,
            order: order.to_vec(),
            model: model.clone(),
            fingerprint: fingerprint.clone(),
        };
        let path = out.join(format!("chkpnt{it}.safetensors"));
        write(&path, &c.to_bytes(), overwrite, written).map(|()| path)
    };
    // The state on the device, unless the caller asks for the host optimiser.
    let device_path = !opts.host_optimizer;
    let mut pipelines: Option<StepPipelines> = None;
    let mut stage_sums = StageSums::default();
    let mut dev: Option<DeviceModel> = None;
    for it in first..=s.iterations {
        if it % s.sh_increase_interval == 0 && model.active_sh_degree < opts.sh_degree {
            model.active_sh_degree += 1;
        }
        if order.is_empty() {
            // A fresh random order of the training views (Fisher-Yates).
            order = (0..data.train.len()).collect();
            for i in (1..order.len()).rev() {
                order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
            }
        }
        let view = &data.train[order.pop().expect("refilled above")];
        let cam = &view.camera;
        // The original's densification (statistics, clone/split/prune, opacity resets) or
        // the MCMC strategy's refinement (relocation and growth).
        let mcmc = s.mcmc.as_ref();
        let until = mcmc.map_or(s.densify_until_iter, |m| m.refine_until);
        let in_densify = it < until;
        let densify_now =
            in_densify && it > s.densify_from_iter && it % s.densification_interval == 0;
        let reset_now = mcmc.is_none() && in_densify && it % s.opacity_reset_interval == 0;
        let lr_now = position_lr(s, data.extent, it);
        let n_now = model.len().max(1);
        let mcmc_step = mcmc.map(|m| McmcStep {
            noise_scale: m.noise_lr * lr_now,
            key: noise_key(opts.seed, it),
            opacity_reg: m.opacity_reg / n_now as f32,
            scale_reg: m.scale_reg / (3 * n_now) as f32,
        });
        let value;
        if device_path {
            if dev.is_none() {
                if pipelines.is_none() {
                    pipelines = Some(StepPipelines::new(rast.renderer().ctx())?);
                }
                dev = Some(DeviceModel::new(
                    rast.renderer(),
                    pipelines.as_ref().expect("made above"),
                    &model,
                    s.clip_grad.is_some(),
                )?);
            }
            let d = dev.as_ref().expect("made above");
            let it_opts = RenderOptions {
                sh_degree: Some(model.active_sh_degree),
                ..render_opts
            };
            let renderer = rast.renderer();
            match (&d.features, d.shader()) {
                (Some(features), Some(shader)) => {
                    renderer.render_shaded_on_device(&d.scene, features, shader, cam, &it_opts)?
                }
                _ => renderer.render_on_device(&d.scene, cam, &it_opts)?,
            }
            if renderer.forward_state()?.last_contributor.is_none() {
                return Err(TrainError::Other(format!(
                    "the {}x{} view {} of {} Gaussians is too large to render in one piece, which training needs; use a lower --resolution",
                    cam.width, cam.height, cam.name, model.len()
                )));
            }
            loss.stage_target(renderer.ctx(), &view.image)?;
            let step = Step {
                stats: in_densify && mcmc.is_none(),
                adam: (!densify_now).then(|| model.advance_steps(reset_now)),
                skip_opacity: reset_now,
                position_lr: lr_now,
                size: (cam.width, cam.height),
                mcmc: mcmc_step,
            };
            let (w, h, lambda) = (cam.width, cam.height, s.lambda_dssim);
            let features = match (d.feature_values(), d.shader()) {
                (Some((values, channels)), Some(shader)) => Some(DeviceFeatures {
                    values,
                    channels,
                    shader,
                    cam,
                    background: bg,
                }),
                _ => None,
            };
            let mut norm_buffer = None;
            stage_sums.add(renderer.timings().stages());
            renderer.backward_on_device(
                &d.scene,
                (w, h),
                features,
                &mut |ctx, cmd, image, grad| loss.record_image(ctx, cmd, image, grad, w, h, lambda),
                &mut |ctx, cmd, grads| {
                    barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
                    norm_buffer = d.record_step(ctx, cmd, grads, &step, s)?;
                    Ok(())
                },
            )?;
            stage_sums.add(rast.renderer().backward_timings());
            let ctx = rast.renderer().ctx();
            value = loss.read_value(ctx)?;
            if let Some(b) = norm_buffer {
                // The squared norm of the whole gradient, clipped against (one float).
                let sq: Vec<[f32; 4]> = b.read(ctx, 1)?;
                let norm = sq[0][0].sqrt();
                if !norm.is_finite() && value.total.is_finite() {
                    return Err(TrainError::Other(format!(
                        "training diverged at iteration {it}: the gradient's norm is {norm}; the last model saved is the last good one"
                    )));
                }
            }
        } else {
            let params = model.params();
            rast.set_shader(model.shader.as_ref())?;
            let (frame, token) = rast.forward(&params, cam, &render_opts)?;
            stage_sums.add(rast.renderer().timings().stages());
            let (v, grad) = loss.compute(
                rast.renderer().ctx(),
                &frame.color,
                &view.image,
                cam.width,
                cam.height,
                s.lambda_dssim,
            )?;
            value = v;
            if value.total.is_finite() {
                let pixel_grads = PixelGrads {
                    color: grad.iter().flatten().copied().collect(),
                    alpha: Vec::new(),
                    depth: Vec::new(),
                };
                let (grads, shader_grads) = if model.shader.is_some() {
                    let (g, m) =
                        rast.backward_shaded(&params, cam, &render_opts, token, &pixel_grads)?;
                    (g, Some(m))
                } else {
                    (
                        rast.backward(&params, cam, &render_opts, token, &pixel_grads)?,
                        None,
                    )
                };
                stage_sums.add(rast.renderer().backward_timings());
                if in_densify && mcmc.is_none() {
                    let radii: Vec<f32> = rast
                        .projected()?
                        .iter()
                        .map(|sp| sp.color_radius[3])
                        .collect();
                    model.add_stats(&grads, &radii, cam.width, cam.height);
                }
                if !densify_now {
                    let norm = model.step(&grads, shader_grads.as_ref(), lr_now, s, reset_now);
                    if !norm.is_finite() {
                        return Err(TrainError::Other(format!(
                            "training diverged at iteration {it}: the gradient's norm is {norm}; the last model saved is the last good one"
                        )));
                    }
                    if let Some(m) = mcmc_step {
                        model.add_noise(m.noise_scale, m.key);
                    }
                }
            }
        }
        if !value.total.is_finite() {
            return Err(TrainError::Other(format!(
                "training diverged at iteration {it}: the loss is {} ({} Gaussians); the last model saved is the last good one",
                value.total,
                model.len()
            )));
        }
        // What the host does on the model: the device's state comes down first, and goes
        // up again (rebuilt) at the next iteration when it changed.
        let evaluate_now = opts.test_iterations.contains(&it) || it == s.iterations;
        let checkpoint_now = opts.checkpoint_iterations.contains(&it);
        let save_now = opts.save_iterations.contains(&it) || it == s.iterations;
        let cancelled = opts
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::SeqCst));
        if let Some(d) = &dev {
            if densify_now || reset_now || evaluate_now || checkpoint_now || save_now || cancelled {
                d.download(rast.renderer().ctx(), &mut model)?;
            }
            if densify_now || reset_now {
                dev = None;
            }
        }
        if let (true, Some(m)) = (densify_now, mcmc) {
            // 3dgs-mcmc's order: relocate and grow, the step (skipped: the parameters are
            // new), the noise.
            model.mcmc_refine(m.cap_max, &mut rng);
            if let Some(ms) = mcmc_step {
                model.add_noise(ms.noise_scale, ms.key);
            }
        } else if densify_now {
            let screen = (it > s.opacity_reset_interval).then_some(20.0);
            model.densify_and_prune(s, data.extent, screen, &mut rng);
            if model.is_empty() {
                return Err(TrainError::Other(format!(
                    "every Gaussian was pruned at iteration {it}; the scene is empty (check the photos and cameras)"
                )));
            }
        }
        if reset_now {
            model.reset_opacity();
        }
        if it % 10 == 1 {
            peak = peak.max(rast.renderer().ctx().live_allocations().1);
        }
        progress(Progress {
            iteration: it,
            iterations: s.iterations,
            loss: value,
            gaussians: model.len(),
        });
        if evaluate_now {
            let (views, split): (Vec<&View>, &str) = if data.test.is_empty() {
                (
                    data.train
                        .iter()
                        .step_by((data.train.len() / 5).max(1))
                        .take(5)
                        .collect(),
                    "train",
                )
            } else {
                (data.test.iter().collect(), "test")
            };
            let e = evaluate(rast, &model, &views, &render_opts, it, split)?;
            note(format!(
                "[ITER {it}] evaluating {split} ({} views): L1 {:.5} PSNR {:.2} dB SSIM {:.4} FLIP {:.4}; {} Gaussians",
                e.views,
                e.l1,
                e.psnr,
                e.ssim,
                e.flip,
                model.len()
            ));
            evaluations.push(e);
        }
        if checkpoint_now {
            let path = checkpoint(it, &model, &rng, &order, &mut written, overwrite)?;
            note(format!("[ITER {it}] checkpoint {}", path.display()));
        }
        if cancelled && it < s.iterations {
            let path = checkpoint(it, &model, &rng, &order, &mut written, true)?;
            return Err(TrainError::Interrupted {
                message: format!(
                    "interrupted after iteration {it}; wrote {}; continue with the same command and --resume {}",
                    path.display(),
                    path.display()
                ),
            });
        }
        if save_now {
            let path = out
                .join("point_cloud")
                .join(format!("iteration_{it}"))
                .join("point_cloud.ply");
            let bytes = crate::scene::ply::to_bytes(
                &model.scene,
                crate::scene::ply::PlyEncoding::BinaryLittleEndian,
            );
            write(&path, &bytes, overwrite, &mut written)?;
            if let Some(mlp) = &model.shader {
                let shader_path = path.with_file_name("shader.safetensors");
                write(&shader_path, &mlp.to_safetensors(), overwrite, &mut written)?;
            }
            note(format!(
                "[ITER {it}] saved {} ({} Gaussians)",
                path.display(),
                model.len()
            ));
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    Ok(TrainReport {
        iterations: s.iterations,
        gaussians: model.len(),
        evaluations,
        written,
        iterations_per_second: (s.iterations + 1 - first) as f64 / seconds.max(1e-9),
        device_bytes_peak: peak,
        on_device: device_path,
        stage_ms: stage_sums
            .0
            .into_iter()
            .map(|(n, ms)| (n, ms / f64::from((s.iterations + 1 - first).max(1))))
            .collect(),
    })
}
