//! `vksplat train`: the original 3DGS training on the differentiable rasterizer
//! ([`vksplat::train`]).

use super::common::{fail_on_validation_messages, GpuArgs};
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use vksplat::train::model::Settings;
use vksplat::{note, outln};

#[derive(Args)]
#[command(after_help = "Examples:
  vksplat train data/garden -o models/garden --eval -r 4
  vksplat train data/lego -o models/lego --white-background --iterations 7000")]
pub(crate) struct TrainArgs {
    /// A COLMAP data set: images/ and sparse/0/ (text or binary; points3D starts the
    /// Gaussians).
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
    /// Photo scale: 1, 2, 4 or 8 divide the size, another number is a width in pixels.
    #[arg(short = 'r', long, default_value_t = 1)]
    pub(crate) resolution: u32,
    /// Largest SH degree (0-3).
    #[arg(long, visible_alias = "sh_degree", default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub(crate) sh_degree: u32,
    /// White background (synthetic data sets).
    #[arg(long, visible_alias = "white_background")]
    pub(crate) white_background: bool,
    /// Iterations after which the model is saved (the last one always is).
    #[arg(long, visible_alias = "save_iterations", value_delimiter = ',', default_values_t = [7000u32, 30000])]
    pub(crate) save_iterations: Vec<u32>,
    /// Iterations after which the test views are evaluated (PSNR, SSIM, L1).
    #[arg(long, visible_alias = "test_iterations", value_delimiter = ',', default_values_t = [7000u32, 30000])]
    pub(crate) test_iterations: Vec<u32>,
    /// Seed of the view order, the random start and the split samples.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Random Gaussians when the data set has no points3D.
    #[arg(long, default_value_t = 100_000)]
    pub(crate) random_points: usize,
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
    /// ... until this one ...
    #[arg(long, visible_alias = "densify_until_iter", default_value_t = 15_000)]
    pub(crate) densify_until_iter: u32,
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
    /// Replace the model directory's files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) gpu: GpuArgs,
}

pub(crate) fn train(args: &TrainArgs) -> Result<()> {
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
    if !(0.0..=1.0).contains(&args.lambda_dssim) {
        bail!(
            "--lambda-dssim must be in [0, 1], not {}",
            args.lambda_dssim
        );
    }
    if args.densification_interval == 0 || args.opacity_reset_interval == 0 {
        bail!("--densification-interval and --opacity-reset-interval must be at least 1");
    }
    if !args.dataset.is_dir() {
        bail!(
            "{}: is not a directory (a COLMAP data set: images/ and sparse/0/)",
            args.dataset.display()
        );
    }
    let data = vksplat::train::data::load_colmap(
        &args.dataset,
        vksplat::train::data::Resolution(args.resolution),
        args.eval,
    )?;
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
    }
    let settings = Settings {
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
        densify_until_iter: args.densify_until_iter,
        densify_grad_threshold: args.densify_grad_threshold,
        opacity_reset_interval: args.opacity_reset_interval,
        ..Settings::default()
    };
    let opts = vksplat::train::run::TrainOptions {
        settings,
        sh_degree: args.sh_degree,
        white_background: args.white_background,
        save_iterations: args.save_iterations.clone(),
        test_iterations: args.test_iterations.clone(),
        seed: args.seed,
        random_points: args.random_points,
        overwrite: args.overwrite,
    };
    let ctx = args.gpu.context()?;
    let mut loss = vksplat::train::loss::GpuLoss::new(&ctx)?;
    let mut rast = vksplat::render::differentiable::DiffRasterizer::new(ctx)?;
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let bar = indicatif::ProgressBar::new(u64::from(args.iterations));
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40.cyan/blue} {pos}/{len} {per_sec} ETA {eta}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    };
    let quiet = args.quiet;
    let report = vksplat::train::run::train(
        &data,
        &args.output,
        &opts,
        &mut rast,
        &mut loss,
        &mut |p| {
            if p.iteration % 10 == 0 || p.iteration == p.iterations {
                bar.set_message(format!(
                    "loss {:.4}  L1 {:.4}  SSIM {:.3}  {} Gaussians",
                    p.loss.total, p.loss.l1, p.loss.ssim, p.gaussians
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
    .map_err(|e| anyhow::anyhow!("{}: {e}", args.output.display()))?;
    bar.finish_and_clear();
    fail_on_validation_messages(rast.renderer().ctx())?;
    let last = report.evaluations.last();
    outln!(
        "trained {} iterations at {:.1} it/s: {} Gaussians{} -> {}",
        report.iterations,
        report.iterations_per_second,
        report.gaussians,
        last.map_or(String::new(), |e| format!(
            "; {} PSNR {:.2} dB, SSIM {:.4}",
            e.split, e.psnr, e.ssim
        )),
        args.output.display()
    );
    Ok(())
}
