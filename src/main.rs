//! The `verisplat` command line. Each subcommand lives in its own file under `src/cli/`.

mod cli;

use clap::{Parser, Subcommand};
use std::process::ExitCode;
use verisplat::core::console::note;

#[derive(Parser)]
#[command(
    name = "verisplat",
    version,
    about = "3D Gaussian Splatting renderer (Vulkan compute + exact CPU reference)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
// Negative numbers are values, not flags (`--orbit-elevation -10`): every subcommand
// allows them.
enum Command {
    /// Render a scene to PNG or EXR images (one frame or a camera path), or to an MP4, WebM or GIF video (ffmpeg).
    #[command(allow_negative_numbers = true)]
    Render(cli::render::RenderArgs),
    /// Print a scene's size, bounds and parameter statistics (or what a camera file holds).
    #[command(allow_negative_numbers = true)]
    Info(cli::info::InfoArgs),
    /// Render the same camera repeatedly and report per-stage GPU times.
    #[command(allow_negative_numbers = true)]
    Bench(cli::bench::BenchArgs),
    /// Write a synthetic scene (seeded) in any format convert writes, or a synthetic RF field (--rf) as .npy.
    #[command(allow_negative_numbers = true)]
    Gen(cli::gen::GenArgs),
    /// Fit Gaussians with feature channels to field samples (a grid .npy, or samples .npy/.csv).
    #[command(allow_negative_numbers = true)]
    Fit(cli::fit::FitArgs),
    /// Convert a scene (any readable format) to .ply, .compressed.ply, .splat, .spz, .sog, .glb or .gltf, chosen by OUT's name.
    #[command(allow_negative_numbers = true)]
    Convert(cli::convert::ConvertArgs),
    /// Compare a scene's GPU renders with the CPU reference, or two images (PSNR, SSIM, errors).
    #[command(allow_negative_numbers = true)]
    Compare(cli::compare::CompareArgs),
    /// Render a model's cameras and compare them with the photos (PSNR, SSIM, FLIP).
    #[command(allow_negative_numbers = true)]
    Eval(cli::eval::EvalArgs),
    /// Train 3DGS from photos (a COLMAP data set), as the original train.py.
    #[command(allow_negative_numbers = true)]
    Train(cli::train::TrainArgs),
    /// Serve an interactive viewer of a scene to a browser (orbit, fly, filters, cameras, keyframes).
    #[command(allow_negative_numbers = true)]
    View(cli::view::ViewArgs),
    /// List the Vulkan devices and self-check each usable one against the CPU reference.
    Doctor(cli::doctor::DoctorArgs),
    /// Make the markdown report of a GPU bundle run's results folder (tools/gpu_bundle.sh).
    #[command(hide = true)]
    GpuReport(cli::doctor::GpuReportArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Render(args) => cli::render::render(args),
        Command::Info(arg) => cli::info::info(arg),
        Command::Bench(args) => cli::bench::bench(args),
        Command::Gen(args) => cli::gen::gen(args),
        Command::Fit(args) => cli::fit::fit(args),
        Command::Convert(args) => cli::convert::convert(args),
        Command::Compare(args) => cli::compare::compare(args),
        Command::Eval(args) => cli::eval::eval(args),
        Command::Train(args) => cli::train::train(args),
        Command::View(args) => cli::view::view(args),
        Command::Doctor(args) => cli::doctor::doctor(args),
        Command::GpuReport(args) => cli::doctor::gpu_report(args),
    };
    // A closed pipe (`verisplat info scene.ply | head`) is not an error; any other failure to
    // write the command's output is.
    let result = result.and_then(|()| match verisplat::core::console::stdout_error() {
        Some(e) => Err(anyhow::anyhow!("writing to standard output failed: {e}")),
        None => Ok(()),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => match e.downcast_ref::<cli::render::Interrupted>() {
            Some(stopped) => {
                note!("{stopped}");
                ExitCode::from(130)
            }
            None => {
                note!("error: {}", verisplat::core::console::error_sentence(&e));
                ExitCode::FAILURE
            }
        },
    }
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
