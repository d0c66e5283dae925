//! `vksplat gen`: a seeded synthetic scene, written in the format its name asks for.

use super::common::check_output_file;
use super::values;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use vksplat::note;
use vksplat::scene::write::{to_bytes, OutputFormat};

#[derive(Args)]
#[command(after_help = "Examples:
  vksplat gen 1e6 -o synthetic_1m.ply
  vksplat gen 100000 --seed 7 --sh-degree 3 -o s.spz")]
pub(crate) struct GenArgs {
    /// Number of Gaussians (e.g. 100000 or 1e5).
    #[arg(value_parser = vksplat::bench::parse_count)]
    pub(crate) count: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// SH degree (0..=3).
    #[arg(long, value_name = "D", default_value_t = 2, value_parser = values::int_in(0u32, 3))]
    pub(crate) sh_degree: u32,
    /// Output file: .ply (INRIA), .splat or .spz, chosen by the extension.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) overwrite: bool,
}

pub(crate) fn gen(args: &GenArgs) -> Result<()> {
    let format = OutputFormat::from_path(&args.output)?;
    check_output_file(&args.output, args.overwrite)?;
    let scene = vksplat::gen::synthetic_scene(args.count, args.seed, args.sh_degree);
    let bytes = to_bytes(&scene, format).map_err(|message| {
        anyhow::anyhow!(
            "{}: cannot be written as {format}: {message}",
            args.output.display()
        )
    })?;
    vksplat::output::write_bytes_atomically(&args.output, args.overwrite, &bytes)?;
    note!(
        "wrote {} synthetic Gaussians (seed {}, SH degree {}) to {} ({format})",
        scene.len(),
        args.seed,
        args.sh_degree.min(format.max_sh_degree()),
        args.output.display()
    );
    Ok(())
}
