//! The `vksplat` command line. Each subcommand lives in its own file under `src/cli/`.

mod cli;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

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
    Render(cli::render::RenderArgs),
    /// Print a scene's size, bounds and parameter statistics.
    Info(cli::common::SceneArg),
    /// Render the same camera repeatedly and report per-stage GPU times.
    Bench(cli::bench::BenchArgs),
    /// Write a synthetic scene (seeded) as an INRIA PLY, for scaling benchmarks.
    Gen(cli::gen::GenArgs),
    /// Convert a scene (any readable format) to .ply, .splat or .spz, chosen by OUT's extension.
    Convert(cli::convert::ConvertArgs),
    /// Compare a scene's GPU renders with the CPU reference, or two images (PSNR, SSIM, errors).
    Compare(cli::compare::CompareArgs),
    /// Render a model's cameras and compare them with the photos (PSNR, SSIM, FLIP).
    Eval(cli::eval::EvalArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Render(args) => cli::render::render(args),
        Command::Info(arg) => cli::info::info(arg),
        Command::Bench(args) => cli::bench::bench(args),
        Command::Gen(args) => cli::gen::gen(args),
        Command::Convert(args) => cli::convert::convert(args),
        Command::Compare(args) => cli::compare::compare(args),
        Command::Eval(args) => cli::eval::eval(args),
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
