//! `vksplat convert`: any readable scene format to PLY, .splat or SPZ.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub(crate) struct ConvertArgs {
    /// Input scene: PLY, compressed PLY, .splat, .spz, SOG (.sog or directory) or a model directory.
    pub(crate) input: PathBuf,
    /// Output file: .ply (INRIA, lossless), .splat or .spz (SPZ v3, gzip).
    pub(crate) output: PathBuf,
    /// Write at most this SH degree (higher bands are dropped).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub(crate) sh_degree: Option<u32>,
    /// Drop Gaussians whose largest axis scale (world units) is above this.
    #[arg(long)]
    pub(crate) max_scale: Option<f32>,
    /// Drop Gaussians whose opacity is below this (0..1).
    #[arg(long)]
    pub(crate) min_opacity: Option<f32>,
    /// Keep only Gaussians whose centre lies in this box.
    #[arg(long, value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", value_parser = vksplat::scene::filter::parse_crop, allow_hyphen_values = true)]
    pub(crate) crop: Option<[[f32; 3]; 2]>,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) overwrite: bool,
    #[command(flatten)]
    pub(crate) transform: super::transform::TransformArgs,
}

pub(crate) fn convert(args: &ConvertArgs) -> Result<()> {
    use vksplat::scene::write::{convert, ConvertOptions};
    let filter = vksplat::scene::filter::SceneFilter {
        max_scale: args.max_scale,
        min_opacity: args.min_opacity,
        crop: args.crop,
        sh_degree: args.sh_degree,
    };
    let options = ConvertOptions {
        transform: args.transform.transform()?,
        filter,
        overwrite: args.overwrite,
    };
    let r = convert(&args.input, &args.output, &options)?;
    if let Some(t) = &options.transform {
        eprintln!("transformed: {} Gaussians by {t}", r.read);
    }
    eprintln!(
        "converted {} ({}, {} Gaussians) -> {} ({}, {} Gaussians, SH degree {}, {} bytes)",
        args.input.display(),
        r.input_format,
        r.read,
        args.output.display(),
        r.output_format,
        r.written,
        r.sh_degree,
        r.bytes
    );
    if r.antialiased_flag_lost {
        eprintln!(
            "note: {} records that the scene was trained with antialiasing; {} cannot record that, so render the output with --antialiased",
            args.input.display(),
            r.output_format
        );
    }
    Ok(())
}
