//! `verisplat train`: the original 3DGS training on the differentiable rasterizer
//! ([`verisplat::train`]).

use super::common::{fail_on_validation_messages, GpuArgs};
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use verisplat::core::console::{note, outln};
use verisplat::train::data::Dataset;
use verisplat::train::model::Settings;
use verisplat::train::run::{TrainOptions, TrainReport};

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat train data/garden -o models/garden --eval -r 4
  verisplat train data/lego -o models/lego --white-background --iterations 7000
  verisplat train data/fisheye -o models/fisheye --eval -r 2          # through the lens
  verisplat train data/fisheye -o models/fisheye-pinhole --undistort  # undistorted photos")]
pub(crate) struct TrainArgs {
    /// A COLMAP data set: images/ and sparse/0/ (text or binary; points3D starts the
    /// Gaussians), or a NeRF-synthetic (transforms_train.json, transforms_test.json) or
    /// nerfstudio (transforms.json) one.
    pub(crate) dataset: PathBuf,
    /// The model directory to write (point_cloud/iteration_N/point_cloud.ply, cameras.json,
    /// cfg_args, input.ply), as the original train.py's --model_path.
    #[arg(
        short = 'o',
        long = "model-path",
        visible_alias = "model_path",
        value_name = "MODEL_DIR"
    )]
    pub(crate) output: PathBuf,
    /// Iterations.
    #[arg(long, default_value_t = 30_000)]
    pub(crate) iterations: u32,
    /// Hold out every 8th image (name order) for evaluation (the original's llffhold).
    #[arg(long)]
    pub(crate) eval: bool,
    /// Photo scale: 1, 2, 4 or 8 divide the size, another number is a width in pixels
    /// [default: 1, the photos' size].
    #[arg(short = 'r', long)]
    pub(crate) resolution: Option<u32>,
    /// Undistort the photos of distorted and fisheye cameras (COLMAP OPENCV, OPENCV_FISHEYE,
    /// ...; transforms.json k1.., p1, p2) to pinhole views at load time, cropped to the
    /// largest rectangle inside the photo (recorded in MODEL_DIR/undistortion.json),
    /// instead of training through the lens on the photos as taken (the default).
    #[arg(long)]
    pub(crate) undistort: bool,
    /// Largest SH degree (0-3).
    #[arg(long, visible_alias = "sh_degree", default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub(crate) sh_degree: u32,
    /// White background (synthetic data sets).
    #[arg(long, visible_alias = "white_background")]
    pub(crate) white_background: bool,
    /// Mip-Splatting's 3D filter: each Gaussian smoothed by the finest sampling the
    /// training cameras give it (renders without aliasing nearer or farther than the
    /// photos); folded into the saved scales and opacities. docs/training.md, "Real
    /// captures".
    #[arg(long)]
    pub(crate) mip_filter: bool,
    /// Per-photo appearance: none, or affine (a 3x3 colour matrix and an offset per
    /// training photo, applied to its render, background included, before the loss and
    /// learnt with the scene, regularised towards the identity: exposure and white
    /// balance that change between photos go there, not into the scene). Renders, the
    /// PLY and evaluations are the scene alone; the transforms are written to
    /// point_cloud/iteration_N/appearance.json. docs/training.md, "Appearance".
    #[arg(long, default_value = "none", value_name = "none|affine")]
    pub(crate) appearance: verisplat::train::appearance::AppearanceMode,
    /// --appearance affine: Adam's learning rate of the transforms [default: 0.002]
    #[arg(long, value_name = "LR")]
    pub(crate) appearance_lr: Option<f32>,
    /// --appearance affine: weight of ||A - I||^2 + ||b||^2 in each photo's loss
    /// [default: 0.1]
    #[arg(long, value_name = "WEIGHT")]
    pub(crate) appearance_reg: Option<f32>,
    /// --appearance affine: the first iteration that applies and learns the transforms
    /// (before it the scene learns alone) [default: 500]
    #[arg(long, value_name = "N")]
    pub(crate) appearance_from: Option<u32>,
    /// What an RGBA photo's alpha does: ignore (dropped), mask (alpha below 0.5 is not
    /// trained on) or background (composited onto the training background) [default:
    /// ignore for a COLMAP data set, background for a transforms one]. Masks in
    /// DATASET/masks/ (or a frame's mask_path) are read whatever this says.
    #[arg(long, value_name = "ignore|mask|background", value_parser = verisplat::train::masks::AlphaMode::parse)]
    pub(crate) alpha_mode: Option<verisplat::train::masks::AlphaMode>,
    /// Iterations after which the model is saved (the last one always is), space- or
    /// comma-separated (7000 30000, as train.py, or 7000,30000).
    #[arg(long, visible_alias = "save_iterations", value_name = "N", num_args = 1.., value_delimiter = ',', default_values_t = [7000u32, 30000])]
    pub(crate) save_iterations: Vec<u32>,
    /// Iterations after which the test views are evaluated (PSNR, SSIM, L1), space- or
    /// comma-separated.
    #[arg(long, visible_alias = "test_iterations", value_name = "N", num_args = 1.., value_delimiter = ',', default_values_t = [7000u32, 30000])]
    pub(crate) test_iterations: Vec<u32>,
    /// Seed of the view order, the random start and the split samples.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Random Gaussians when the data set has no points3D [default: 100,000; 10,000 on a
    /// CPU device]
    #[arg(long)]
    pub(crate) random_points: Option<usize>,
    /// Learning rate of the centres at the start (times the scene extent).
    #[arg(long, visible_alias = "position_lr_init", default_value_t = 0.00016)]
    pub(crate) position_lr_init: f32,
    /// Learning rate of the centres at the end (times the scene extent).
    #[arg(long, visible_alias = "position_lr_final", default_value_t = 0.0000016)]
    pub(crate) position_lr_final: f32,
    /// SH DC learning rate (the other coefficients: a twentieth).
    #[arg(long, visible_alias = "feature_lr", default_value_t = 0.0025)]
    pub(crate) feature_lr: f32,
    /// Opacity learning rate.
    #[arg(long, visible_alias = "opacity_lr", default_value_t = 0.025)]
    pub(crate) opacity_lr: f32,
    /// Log-scale learning rate.
    #[arg(long, visible_alias = "scaling_lr", default_value_t = 0.005)]
    pub(crate) scaling_lr: f32,
    /// Quaternion learning rate.
    #[arg(long, visible_alias = "rotation_lr", default_value_t = 0.001)]
    pub(crate) rotation_lr: f32,
    /// Weight of D-SSIM in the loss.
    #[arg(long, visible_alias = "lambda_dssim", default_value_t = 0.2)]
    pub(crate) lambda_dssim: f32,
    /// Densify from this iteration ...
    #[arg(long, visible_alias = "densify_from_iter", default_value_t = 500)]
    pub(crate) densify_from_iter: u32,
    /// ... until this one ... [default: 15000; 25000 with --strategy mcmc]
    #[arg(long, visible_alias = "densify_until_iter")]
    pub(crate) densify_until_iter: Option<u32>,
    /// ... every this many iterations.
    #[arg(long, visible_alias = "densification_interval", default_value_t = 100)]
    pub(crate) densification_interval: u32,
    /// Average 2D-mean gradient (NDC) above which a Gaussian is cloned or split.
    #[arg(
        long,
        visible_alias = "densify_grad_threshold",
        default_value_t = 0.0002
    )]
    pub(crate) densify_grad_threshold: f32,
    /// Reset opacities every this many iterations.
    #[arg(long, visible_alias = "opacity_reset_interval", default_value_t = 3000)]
    pub(crate) opacity_reset_interval: u32,
    /// Below this fraction of the scene extent a Gaussian is cloned, above it split.
    #[arg(long, visible_alias = "percent_dense", default_value_t = 0.01)]
    pub(crate) percent_dense: f32,
    /// Feature splats: learn K feature channels per Gaussian and a neural shader that turns
    /// them into colour (instead of SH colour), jointly; writes the PLY with feat_* and
    /// shader.safetensors beside it, which `render --shader` reads.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=16))]
    pub(crate) features: Option<u32>,
    /// The neural shader to start from (with --features; its first layer takes K
    /// channels). Default: a fresh K-H-H-3 network (relu, relu, sigmoid).
    #[arg(long, value_name = "FILE.safetensors", requires = "features")]
    pub(crate) shader: Option<PathBuf>,
    /// Hidden width H of a fresh shader.
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u32).range(1..=128))]
    pub(crate) shader_hidden: u32,
    /// Learning rate of the shader's weights.
    #[arg(long, default_value_t = 0.001)]
    pub(crate) shader_lr: f32,
    /// The alpha falloff: gaussian (the original) or power.
    #[arg(long, default_value = "gaussian")]
    pub(crate) kernel: verisplat::core::model::SplatKernel,
    /// The rasterizer's rules: original (the 3DGS rasterizer's) or gsplat (near plane 0.01,
    /// alpha clamp 0.999, a per-axis 3.33-sigma screen box), as gsplat trains. The model
    /// records them, so `render` and `eval` use them too.
    #[arg(long, default_value = "original", value_name = "original|gsplat")]
    pub(crate) rules: verisplat::core::model::Rules,
    /// Train with the reproducible mode's blends (the CPU reference's exp, unfused
    /// arithmetic), as `render --reproducible` draws; costs blend time
    /// (docs/reproducibility.md).
    #[arg(long)]
    pub(crate) reproducible: bool,
    /// How the Gaussians are added and removed: default (the original's densification:
    /// clone, split, prune, opacity resets) or mcmc (3DGS as Markov chain Monte Carlo:
    /// dead Gaussians relocated onto live ones, 5 % growth per refinement up to
    /// --cap-max, noise on the centres, opacity and scale regularisers; the flags of
    /// ubc-vision/3dgs-mcmc).
    #[arg(long, default_value = "default", value_parser = ["default", "mcmc"])]
    pub(crate) strategy: String,
    /// MCMC: the most Gaussians.
    #[arg(long, visible_alias = "cap_max", default_value_t = 1_000_000, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) cap_max: u32,
    /// MCMC: the noise's scale (times the centres' learning rate).
    #[arg(long, visible_alias = "noise_lr", default_value_t = 5e5)]
    pub(crate) noise_lr: f32,
    /// MCMC: weight of the mean opacity in the loss.
    #[arg(long, visible_alias = "opacity_reg", default_value_t = 0.01)]
    pub(crate) opacity_reg: f32,
    /// MCMC: weight of the mean scale in the loss.
    #[arg(long, visible_alias = "scale_reg", default_value_t = 0.01)]
    pub(crate) scale_reg: f32,
    /// Scale the whole gradient down to this L2 norm when it is larger (gradient-norm
    /// clipping; off by default, as the original).
    #[arg(long, value_name = "NORM")]
    pub(crate) clip_grad: Option<f32>,
    /// Iterations after which a checkpoint (MODEL_DIR/chkpntN.safetensors) is written;
    /// Ctrl-C also writes one. Space- or comma-separated.
    #[arg(long, visible_alias = "checkpoint_iterations", value_name = "N", num_args = 1.., value_delimiter = ',')]
    pub(crate) checkpoint_iterations: Vec<u32>,
    /// Continue from a checkpoint, bit for bit as if never stopped (same data set and
    /// settings; the files it writes replace the run's own).
    #[arg(long, value_name = "CHECKPOINT")]
    pub(crate) resume: Option<PathBuf>,
    /// Replace the model directory's files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Print the mean device time per iteration of each stage (GPU timestamps): the
    /// forward pass's, the loss, the backward pass's and the optimiser's step.
    #[arg(long)]
    pub(crate) timings: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

/// A K-H-H-3 network (relu, relu, sigmoid), weights and biases uniform in
/// +-1/sqrt(inputs) as torch.nn.Linear starts them, seeded.
fn fresh_shader(k: usize, hidden: usize, seed: u64) -> verisplat::fields::mlp::Mlp {
    use verisplat::fields::mlp::{Activation, Layer, Mlp, MlpInput};
    let mut rng = verisplat::core::gen::Rng(seed ^ 0x5eed_5ade_0000_0001);
    let mut layer = |inputs: usize, outputs: usize, activation| {
        let bound = 1.0 / (inputs as f32).sqrt();
        Layer {
            inputs,
            outputs,
            weight: (0..inputs * outputs)
                .map(|_| rng.range(-bound, bound))
                .collect(),
            bias: (0..outputs).map(|_| rng.range(-bound, bound)).collect(),
            activation,
        }
    };
    Mlp {
        inputs: vec![MlpInput::Features],
        layers: vec![
            layer(k, hidden, Activation::Relu),
            layer(hidden, hidden, Activation::Relu),
            layer(hidden, 3, Activation::Sigmoid),
        ],
    }
}

pub(crate) fn train(args: &TrainArgs) -> Result<()> {
    check_args(args)?;
    let data = load_dataset(args)?;
    let mut opts = options(args, settings(args))?;
    let ctx = args.gpu.context()?;
    opts.random_points = random_points(args, &data, ctx.info());
    let mut loss = verisplat::train::loss::GpuLoss::new(&ctx)?;
    let mut rast = verisplat::render::backward::differentiable::DiffRasterizer::new(ctx)?;
    let bar = progress_bar(args.quiet, args.iterations);
    let quiet = args.quiet;
    let mut lines = LogLines::new(args.quiet, args.iterations);
    let report = verisplat::train::run::train(
        &data,
        &args.output,
        &opts,
        &mut rast,
        &mut loss,
        &mut |p| {
            lines.iteration(&p);
            if p.iteration % 10 == 0 || p.iteration == p.iterations {
                bar.set_message(format!(
                    "loss {:.4}  PSNR {:.2} dB  L1 {:.4}  SSIM {:.3}  {} Gaussians",
                    p.loss.total,
                    p.loss.psnr(),
                    p.loss.l1,
                    p.loss.ssim,
                    p.gaussians
                ));
                bar.set_position(u64::from(p.iteration));
            }
        },
        &mut |line| {
            if !quiet {
                bar.suspend(|| note!("{line}"));
            }
        },
    )
    .map_err(|e| match e {
        verisplat::train::run::TrainError::Interrupted { message } => {
            anyhow::Error::new(super::render::Interrupted(message))
        }
        // A device that cannot take a lens's backward pass: the other way to train.
        e @ verisplat::train::run::TrainError::Gpu(_)
            if e.to_string().contains(" lens")
                && data.views().any(|v| !v.camera.lens.is_pinhole()) =>
        {
            anyhow::anyhow!(
                "{}: {e} (--undistort trains on pinhole views undistorted from the photos)",
                args.output.display()
            )
        }
        e => anyhow::anyhow!("{}: {e}", args.output.display()),
    })?;
    bar.finish_and_clear();
    fail_on_validation_messages(rast.renderer().ctx())?;
    print_report(args, &report);
    Ok(())
}

/// The random start of a data set without points3D (the original's, INRIA's).
const RANDOM_POINTS: usize = 100_000;
/// The random start on a CPU device (lavapipe), where an iteration from 100,000 takes
/// seconds (BENCHMARKS.md, 2026-11-27); densification adds Gaussians where they help.
const CPU_RANDOM_POINTS: usize = 10_000;

/// `--random-points`, or the default that fits the device: fewer Gaussians on a CPU
/// device, said when the data set has no points (so that the start is random).
fn random_points(args: &TrainArgs, data: &Dataset, info: &verisplat::gpu::DeviceInfo) -> usize {
    if let Some(n) = args.random_points {
        return n;
    }
    if info.device_type != ash::vk::PhysicalDeviceType::CPU {
        return RANDOM_POINTS;
    }
    if data.points.is_none() && args.resume.is_none() && !args.quiet {
        note!(
            "{} is a CPU device: starting from {CPU_RANDOM_POINTS} random Gaussians instead of {RANDOM_POINTS} (--random-points N to choose)",
            info.name
        );
    }
    CPU_RANDOM_POINTS
}

/// Refuses the options no run can use: non-positive learning rates, a D-SSIM weight
/// outside [0, 1], MCMC flags without `--strategy mcmc`, zero intervals, a data set that
/// is not a directory.
fn check_args(args: &TrainArgs) -> Result<()> {
    if args.iterations == 0 {
        bail!("--iterations must be at least 1");
    }
    for (name, v) in [
        ("--position-lr-init", args.position_lr_init),
        ("--position-lr-final", args.position_lr_final),
        ("--feature-lr", args.feature_lr),
        ("--opacity-lr", args.opacity_lr),
        ("--scaling-lr", args.scaling_lr),
        ("--rotation-lr", args.rotation_lr),
        ("--percent-dense", args.percent_dense),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} must be a positive number, not {v}");
        }
    }
    if let Some(c) = args.clip_grad {
        if !(c.is_finite() && c > 0.0) {
            bail!("--clip-grad must be a positive number, not {c}");
        }
    }
    if !(args.shader_lr.is_finite() && args.shader_lr > 0.0) {
        bail!(
            "--shader-lr must be a positive number, not {}",
            args.shader_lr
        );
    }
    if !(0.0..=1.0).contains(&args.lambda_dssim) {
        bail!(
            "--lambda-dssim must be in [0, 1], not {}",
            args.lambda_dssim
        );
    }
    for (name, v) in [
        ("--noise-lr", args.noise_lr),
        ("--opacity-reg", args.opacity_reg),
        ("--scale-reg", args.scale_reg),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{name} must be a number >= 0, not {v}");
        }
    }
    let mcmc = args.strategy == "mcmc";
    if !mcmc {
        for (name, given) in [
            ("--cap-max", args.cap_max != 1_000_000),
            ("--noise-lr", args.noise_lr != 5e5),
            ("--opacity-reg", args.opacity_reg != 0.01),
            ("--scale-reg", args.scale_reg != 0.01),
        ] {
            if given {
                bail!("{name} belongs to --strategy mcmc");
            }
        }
    }
    check_appearance_args(args)?;
    if args.densification_interval == 0 || args.opacity_reset_interval == 0 {
        bail!("--densification-interval and --opacity-reset-interval must be at least 1");
    }
    if !args.dataset.is_dir() {
        bail!(
            "{}: is not a directory (a COLMAP data set: images/ and sparse/0/, or a NeRF-synthetic or nerfstudio one: transforms*.json)",
            args.dataset.display()
        );
    }
    Ok(())
}

/// Refuses the appearance flags without `--appearance affine`, a learning rate that is not
/// positive and a negative weight.
fn check_appearance_args(args: &TrainArgs) -> Result<()> {
    use verisplat::train::appearance::AppearanceMode;
    if args.appearance == AppearanceMode::None {
        for (name, given) in [
            ("--appearance-lr", args.appearance_lr.is_some()),
            ("--appearance-reg", args.appearance_reg.is_some()),
            ("--appearance-from", args.appearance_from.is_some()),
        ] {
            if given {
                bail!("{name} belongs to --appearance affine");
            }
        }
    }
    if let Some(lr) = args.appearance_lr {
        if !(lr.is_finite() && lr > 0.0) {
            bail!("--appearance-lr must be a positive number, not {lr}");
        }
    }
    if let Some(reg) = args.appearance_reg {
        if !(reg.is_finite() && reg >= 0.0) {
            bail!("--appearance-reg must be a number >= 0, not {reg}");
        }
    }
    Ok(())
}

/// Loads the data set (COLMAP, or NeRF-synthetic / nerfstudio transforms) and notes
/// what it holds.
fn load_dataset(args: &TrainArgs) -> Result<Dataset> {
    use verisplat::train::data::{self as sets, LensMode};
    let resolution = sets::Resolution(args.resolution.unwrap_or(1));
    let lenses = if args.undistort {
        LensMode::Undistort
    } else {
        LensMode::Through
    };
    let opts = sets::LoadOptions {
        resolution,
        eval: args.eval,
        lenses,
        background: if args.white_background {
            [1.0; 3]
        } else {
            [0.0; 3]
        },
        alpha: args.alpha_mode,
    };
    let data = sets::load(&args.dataset, &opts)?;
    if !args.quiet {
        note!(
            "{}: {} training and {} test images of {}x{}, {}, scene extent {:.3}",
            args.dataset.display(),
            data.train.len(),
            data.test.len(),
            data.train[0].camera.width,
            data.train[0].camera.height,
            match &data.points {
                Some(p) => format!("{} points", p.len()),
                None => "no points".into(),
            },
            data.extent
        );
        if let Some(note) = mask_note(&data) {
            note!("{note}");
        }
        let through: Vec<String> = match data.lenses {
            LensMode::Through => data
                .lens_counts()
                .iter()
                .map(|(lens, n)| format!("{n} {lens}"))
                .collect(),
            LensMode::Undistort => Vec::new(),
        };
        if !through.is_empty() {
            note!(
                "training through the lens on the photos as taken ({} camera(s); recorded in the model's {}); --undistort trains on pinhole views undistorted from them instead",
                through.join(", "),
                sets::LENS_FILE
            );
        }
        if let Some(u) = data.undistorted.first() {
            note!(
                "undistorted {} photo(s) ({} lens) to pinhole cameras, e.g. {}x{} -> {}x{} (recorded in the model's {})",
                data.undistorted.len(),
                u.distortion.model,
                u.photo.width,
                u.photo.height,
                u.pinhole.width,
                u.pinhole.height,
                verisplat::train::undistort::UNDISTORTION_FILE
            );
            if let Some(note) = upsampling_note(&data.undistorted, resolution) {
                note!("{note}");
            }
        }
    }
    Ok(data)
}

/// How many views are masked and what share of their pixels is ignored; `None` when no
/// view is.
fn mask_note(data: &Dataset) -> Option<String> {
    let masked: Vec<&Vec<bool>> = data.views().filter_map(|v| v.mask.as_ref()).collect();
    if masked.is_empty() {
        return None;
    }
    let total: usize = masked.iter().map(|m| m.len()).sum();
    let ignored: usize = masked
        .iter()
        .map(|m| m.iter().filter(|&&k| !k).count())
        .sum();
    Some(format!(
        "{} of {} views masked ({:.1} % of their pixels ignored by the loss and the densification statistics)",
        masked.len(),
        data.views().count(),
        100.0 * ignored as f64 / total.max(1) as f64
    ))
}

/// A note when the undistorted views (at the training resolution) hold many more pixels
/// than the photos they come from: a wide lens's rim stretched to a pinhole is
/// interpolated, which costs training time and adds no detail.
fn upsampling_note(
    undistorted: &[verisplat::train::undistort::Undistortion],
    resolution: verisplat::train::data::Resolution,
) -> Option<String> {
    let pixels = |(w, h): (u32, u32)| u64::from(w) * u64::from(h);
    let photos: u64 = undistorted
        .iter()
        .map(|u| pixels((u.photo.width, u.photo.height)))
        .sum();
    let views: u64 = undistorted
        .iter()
        .map(|u| pixels(resolution.size(u.pinhole.width, u.pinhole.height)))
        .sum();
    let factor = views as f64 / photos.max(1) as f64;
    (factor >= 2.0).then(|| {
        format!(
            "note: the undistorted views hold {factor:.1}x the photos' pixels (the lens's rim stretched to a pinhole: interpolated, not detail, and slower to train); -r 2, 4 or 8 divides their size, -r WIDTH sets their width"
        )
    })
}

/// The optimisation and densification settings of the arguments.
fn settings(args: &TrainArgs) -> Settings {
    let mcmc = args.strategy == "mcmc";
    Settings {
        iterations: args.iterations,
        position_lr_init: args.position_lr_init,
        position_lr_final: args.position_lr_final,
        feature_lr: args.feature_lr,
        opacity_lr: args.opacity_lr,
        scaling_lr: args.scaling_lr,
        rotation_lr: args.rotation_lr,
        percent_dense: args.percent_dense,
        lambda_dssim: args.lambda_dssim,
        densification_interval: args.densification_interval,
        densify_from_iter: args.densify_from_iter,
        densify_until_iter: args.densify_until_iter.unwrap_or(15_000),
        densify_grad_threshold: args.densify_grad_threshold,
        opacity_reset_interval: args.opacity_reset_interval,
        shader_lr: args.shader_lr,
        clip_grad: args.clip_grad,
        mcmc: mcmc.then(|| verisplat::train::model::Mcmc {
            cap_max: args.cap_max as usize,
            noise_lr: args.noise_lr,
            opacity_reg: args.opacity_reg,
            scale_reg: args.scale_reg,
            refine_until: args.densify_until_iter.unwrap_or(25_000),
        }),
        ..Settings::default()
    }
}

/// What the run is asked to do: `settings`, the shader of feature splats (loaded or
/// fresh), the checkpoint to resume, the outputs; Ctrl-C and SIGTERM stop it.
fn options(args: &TrainArgs, settings: Settings) -> Result<TrainOptions> {
    let shader = match (args.features, &args.shader) {
        (Some(k), Some(path)) => {
            let mlp = verisplat::fields::mlp::Mlp::load(path)?;
            mlp.check_channels(k as usize)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            Some(mlp)
        }
        (Some(k), None) => Some(fresh_shader(
            k as usize,
            args.shader_hidden as usize,
            args.seed,
        )),
        (None, _) => None,
    };
    Ok(TrainOptions {
        settings,
        sh_degree: args.sh_degree,
        white_background: args.white_background,
        save_iterations: args.save_iterations.clone(),
        test_iterations: args.test_iterations.clone(),
        seed: args.seed,
        random_points: args.random_points.unwrap_or(RANDOM_POINTS),
        overwrite: args.overwrite,
        shader,
        kernel: args.kernel,
        rules: args.rules,
        reproducible: args.reproducible,
        checkpoint_iterations: args.checkpoint_iterations.clone(),
        resume: match &args.resume {
            Some(path) => Some(
                verisplat::train::checkpoint::Checkpoint::load(path)
                    .map_err(|m| anyhow::anyhow!("{}: {m}", path.display()))?,
            ),
            None => None,
        },
        cancel: Some(super::render::interrupt_flag()),
        host_optimizer: false,
        photos_on_device: photos_on_device()?,
        resolution: args.resolution,
        mip_filter: args.mip_filter,
        appearance: {
            use verisplat::train::appearance as app;
            app::AppearanceSettings {
                mode: args.appearance,
                lr: args.appearance_lr.unwrap_or(app::DEFAULT_LR),
                reg: args.appearance_reg.unwrap_or(app::DEFAULT_REG),
                from: args.appearance_from.unwrap_or(app::DEFAULT_FROM),
            }
        },
    })
}

/// The progress bar (hidden with `--quiet`).
fn progress_bar(quiet: bool, iterations: u32) -> indicatif::ProgressBar {
    if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let bar = indicatif::ProgressBar::new(u64::from(iterations));
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40.cyan/blue} {pos}/{len} {per_sec} ETA {eta}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    }
}

/// Progress as plain lines where there is no terminal to draw a bar on (a log file, a
/// Slurm job): a line at every 5 % of the iterations and at least every 30 s.
struct LogLines {
    on: bool,
    iterations: u32,
    start: std::time::Instant,
    last_line: std::time::Instant,
    last_step: u32,
    /// The first iteration of this run (after a resumed checkpoint's), for the rate.
    first: Option<u32>,
}

impl LogLines {
    fn new(quiet: bool, iterations: u32) -> Self {
        use std::io::IsTerminal;
        LogLines {
            on: !quiet && !std::io::stderr().is_terminal(),
            iterations,
            start: std::time::Instant::now(),
            last_line: std::time::Instant::now(),
            last_step: 0,
            first: None,
        }
    }

    fn iteration(&mut self, p: &verisplat::train::run::Progress) {
        if !self.on {
            return;
        }
        let first = *self.first.get_or_insert(p.iteration);
        let step = (u64::from(p.iteration) * 20 / u64::from(p.iterations.max(1))) as u32;
        let due = step > self.last_step
            || self.last_line.elapsed() >= std::time::Duration::from_secs(30)
            || p.iteration == p.iterations;
        if !due {
            return;
        }
        self.last_step = step;
        self.last_line = std::time::Instant::now();
        let rate =
            f64::from(p.iteration + 1 - first) / self.start.elapsed().as_secs_f64().max(1e-9);
        note!(
            "iteration {}/{} ({:.0} %): loss {:.4}, PSNR {:.2} dB, {} Gaussians; {rate:.2} it/s, ETA {:.0} s",
            p.iteration,
            self.iterations,
            100.0 * f64::from(p.iteration) / f64::from(self.iterations.max(1)),
            p.loss.total,
            p.loss.psnr(),
            p.gaussians,
            f64::from(self.iterations - p.iteration) / rate.max(1e-9)
        );
    }
}

/// The run's summary line and, with `--timings`, the device time of each stage.
fn print_report(args: &TrainArgs, report: &TrainReport) {
    let last = report.evaluations.last();
    outln!(
        "trained {} iterations at {:.1} it/s: {} Gaussians ({:.0} device bytes per Gaussian at the peak){} -> {}",
        report.iterations,
        report.iterations_per_second,
        report.gaussians,
        report.device_bytes_peak as f64 / report.gaussians.max(1) as f64,
        last.map_or(String::new(), |e| format!(
            "; {} PSNR {:.2} dB, SSIM {:.4}, FLIP {:.4}",
            e.split, e.psnr, e.ssim, e.flip
        )),
        args.output.display()
    );
    if args.timings {
        let gpu: f64 = report.stage_ms.iter().map(|(_, ms)| ms).sum();
        outln!(
            "device time per iteration (mean): {gpu:.2} ms of {:.2} ms wall",
            1000.0 / report.iterations_per_second.max(1e-9)
        );
        for (name, ms) in &report.stage_ms {
            outln!("  {name:<15} {ms:>9.3} ms");
        }
        let host: f64 = report.host_ms.iter().map(|(_, ms)| ms).sum();
        outln!("host time per iteration (mean): {host:.2} ms");
        for (name, ms) in &report.host_ms {
            if name == "step" {
                let c = &report.step_device_calls;
                outln!(
                    "  {name:<15} {ms:>9.3} ms: recording {:.3}, vkQueueSubmit {:.3}, waiting {:.3} ({} submissions), the host's own work {:.3}",
                    c.record_ms,
                    c.submit_ms,
                    c.wait_ms,
                    c.submissions,
                    ms - c.record_ms - c.submit_ms - c.wait_ms
                );
            } else {
                outln!("  {name:<15} {ms:>9.3} ms");
            }
        }
    }
}

/// The variable that makes `train` upload each photo every time it is trained on instead of
/// keeping the photos on the device (`VERISPLAT_TRAIN_PHOTOS=host`): the models are the same
/// bytes either way, which the tests check with it.
const PHOTOS_ENV: &str = "VERISPLAT_TRAIN_PHOTOS";

/// Whether the photos stay on the device ([`PHOTOS_ENV`]).
fn photos_on_device() -> Result<bool> {
    match verisplat::core::former_name::env_var(PHOTOS_ENV).as_deref() {
        None | Some("") | Some("device") => Ok(true),
        Some("host") => Ok(false),
        Some(other) => bail!("{PHOTOS_ENV}={other:?}: expected device or host"),
    }
}
