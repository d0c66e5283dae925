//! `verisplat convert`: any readable scene format to PLY, .splat, SPZ, PlayCanvas compressed
//! PLY, SOG or glTF (.glb, .gltf).

use super::common::{check_output_file, FilterArgs};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use verisplat::core::console::note;
use verisplat::io::scene::write::{convert as convert_scene, ConvertOptions, OutputFormat};

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat convert scene.ply scene.spz
  verisplat convert scene.ply scene.sog                 # PlayCanvas SOG bundle
  verisplat convert scene.ply scene_sog/meta.json       # unbundled SOG: textures beside meta.json
  verisplat convert scene.ply scene.compressed.ply      # PlayCanvas / SuperSplat compressed PLY
  verisplat convert scene.ply scene.glb                 # glTF 2.0, KHR_gaussian_splatting (.gltf: JSON + .bin)
  verisplat convert model_dir/ small.splat --min-opacity 0.05 --max-scale 0.5
  verisplat convert scene.spz cropped.ply --crop -1,-1,-1,1,1,1 --sh-degree 1
  verisplat convert scene.ply power.ply --kernel power   # render power.ply with that kernel
  verisplat convert scene.ply for_playcanvas.spz --spz-axes raw   # splat-transform's axes")]
pub(crate) struct ConvertArgs {
    /// Input scene: PLY, compressed PLY, .splat, .spz, SOG (.sog or directory), glTF (.glb,
    /// .gltf) or a model directory.
    pub(crate) input: PathBuf,
    /// Output file: .ply (INRIA, lossless), .splat (DC colour only), .spz (SPZ v3, gzip),
    /// .compressed.ply (PlayCanvas compressed PLY), .sog (PlayCanvas SOG bundle),
    /// DIR/meta.json (an unbundled SOG, its WebP textures beside meta.json), .glb (glTF
    /// binary, KHR_gaussian_splatting) or .gltf (glTF JSON, its buffer in a .bin beside it).
    pub(crate) output: PathBuf,
    #[command(flatten)]
    pub(crate) filter: FilterArgs,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) overwrite: bool,
    #[command(flatten)]
    pub(crate) transform: super::transform::TransformArgs,
    /// Record this alpha falloff in the output (gaussian or power; a PLY header comment,
    /// which `render` follows) [default: the input's].
    #[arg(long, value_name = "gaussian|power")]
    pub(crate) kernel: Option<verisplat::cpu::SplatKernel>,
    /// Attach feature channels from an N x K NumPy array (float32 or float16; written as
    /// feat_* PLY properties; other formats drop them with a note).
    #[arg(long, value_name = "FILE.npy")]
    pub(crate) features: Option<PathBuf>,
    /// Axes of the SPZ input and of the SPZ output, whichever are SPZ: spec (the SPZ spec's
    /// RUB: Niantic's spz library, Scaniverse) or raw (PLY axes as they are: PlayCanvas
    /// splat-transform). To change a file's axes, convert it to PLY with one and back with
    /// the other.
    #[arg(long, value_name = "spec|raw", default_value_t = verisplat::io::scene::spz::SpzAxes::Spec)]
    pub(crate) spz_axes: verisplat::io::scene::spz::SpzAxes,
}

pub(crate) fn convert(args: &ConvertArgs) -> Result<()> {
    // Name, folder and existing-file problems are reported before the input is read.
    OutputFormat::from_path(&args.output)?;
    check_output_file(&args.output, args.overwrite)?;
    let options = ConvertOptions {
        transform: args.transform.transform()?,
        filter: args.filter.filter()?,
        overwrite: args.overwrite,
        kernel: args.kernel,
        features: args.features.clone(),
        spz_axes: args.spz_axes,
    };
    let r = convert_scene(&args.input, &args.output, &options)?;
    if r.output_format == OutputFormat::Spz {
        note!(
            "note: {} is written in {}; tools that read SPZ in the other axes show it upside down (for those: --spz-axes {})",
            args.output.display(),
            options.spz_axes.describe(),
            options.spz_axes.other()
        );
    }
    if let Some(t) = &options.transform {
        note!("transformed: {} by {t}", super::plural(r.read, "Gaussian"));
    }
    note!(
        "converted {} ({}, {}) -> {} ({}, {}, SH degree {}, {} bytes)",
        args.input.display(),
        r.input_format,
        super::plural(r.read, "Gaussian"),
        args.output.display(),
        r.output_format,
        super::plural(r.written, "Gaussian"),
        r.sh_degree,
        r.bytes
    );
    if let Some(from) = r.sh_dropped_from {
        note!(
            "note: {} stores no SH bands beyond the DC colour; the scene's SH degree {from} was reduced to {}",
            r.output_format,
            r.sh_degree
        );
    }
    if r.written == 0 && r.read > 0 {
        note!(
            "note: the filters removed all {} Gaussians; {} holds an empty scene",
            r.read,
            args.output.display()
        );
    }
    if r.antialiased_flag_lost {
        note!(
            "note: {} records that the scene was trained with antialiasing; {} cannot record that, so render the output with --antialiased",
            args.input.display(),
            r.output_format
        );
    }
    if r.features_dropped > 0 {
        note!(
            "note: {} stores no feature channels; the {} of {} were dropped (PLY keeps them as feat_*)",
            r.output_format,
            super::plural(r.features_dropped, "channel"),
            args.input.display()
        );
    }
    if let Some(rules) = r.rules_lost {
        note!(
            "note: {} records that the scene was trained with {rules}'s rules; {} cannot record that, so render the output with --rules {rules}",
            args.input.display(),
            r.output_format
        );
    }
    if r.mip_filter_mark_lost {
        note!(
            "note: {} records that Mip-Splatting's 3D filter is folded into its scales and opacities; {} holds the same Gaussians but cannot record that",
            args.input.display(),
            r.output_format
        );
    }
    if let Some(kernel) = r.kernel_lost {
        note!(
            "note: {} records that the scene is made for the {kernel} kernel; {} cannot record that, so render the output with --kernel {kernel}",
            args.input.display(),
            r.output_format
        );
    }
    Ok(())
}
