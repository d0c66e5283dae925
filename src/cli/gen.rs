//! `vksplat gen`: a seeded synthetic scene.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use vksplat::output;

#[derive(Args)]
pub(crate) struct GenArgs {
    /// Number of Gaussians (e.g. 100000 or 1e5).
    #[arg(value_parser = vksplat::bench::parse_count)]
    pub(crate) count: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// SH degree (0..=3).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub(crate) sh_degree: u32,
    /// Output .ply file.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) overwrite: bool,
}

pub(crate) fn gen(args: &GenArgs) -> Result<()> {
    let scene = vksplat::gen::synthetic_scene(args.count, args.seed, args.sh_degree);
    let bytes =
        vksplat::scene::ply::to_bytes(&scene, vksplat::scene::ply::PlyEncoding::BinaryLittleEndian);
    output::write_bytes_atomically(&args.output, args.overwrite, &bytes)?;
    eprintln!(
        "wrote {} synthetic Gaussians (seed {}, SH degree {}) to {}",
        scene.len(),
        args.seed,
        args.sh_degree,
        args.output.display()
    );
    Ok(())
}
