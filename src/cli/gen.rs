//! `vksplat gen`: a seeded synthetic scene, written in the format its name asks for; or,
//! with `--rf`, a synthetic RF field on a dense grid (`.npy`) for `vksplat fit`.

use super::common::check_output_file;
use super::values;
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use vksplat::note;
use vksplat::rf::RfField;
use vksplat::scene::write::{to_bytes, OutputFormat};

#[derive(Args)]
#[command(after_help = "Examples:
  vksplat gen 1e6 -o synthetic_1m.ply
  vksplat gen 100000 --seed 7 --sh-degree 3 -o s.spz
  vksplat gen --rf dipole dipole.npy            (64 x 64 x 64 x 4, plus dipole.npy.json)
  vksplat gen --rf two-ray tworay.npy --size 32

With --rf the field is written as a float32 .npy of shape N x N x N x 4 (points spread over
the field's bounds like numpy.linspace), with a sidecar OUT.npy.json holding the bounds and
channel names; `vksplat fit OUT.npy` reads the bounds from it.")]
pub(crate) struct GenArgs {
    /// Number of Gaussians (e.g. 100000 or 1e5); with --rf, the output .npy instead.
    #[arg(value_name = "N | OUT.npy")]
    pub(crate) count: Option<String>,
    /// Random seed.
    #[arg(long, default_value_t = 1, conflicts_with = "rf")]
    pub(crate) seed: u64,
    /// SH degree (0..=3).
    #[arg(long, value_name = "D", default_value_t = 2, value_parser = values::int_in(0u32, 3), conflicts_with = "rf")]
    pub(crate) sh_degree: u32,
    /// Write a synthetic RF field instead of a scene: dipole (a half-wave dipole's
    /// radiation) or two-ray (a transmitter above a ground plane).
    #[arg(long, value_name = "dipole|two-ray")]
    pub(crate) rf: Option<RfField>,
    /// Grid points per axis of an --rf field.
    #[arg(long, value_name = "N", default_value_t = 64, value_parser = values::int_in(2usize, 512), requires = "rf")]
    pub(crate) size: usize,
    /// Output file: .ply (INRIA), .splat or .spz, chosen by the extension; .npy with --rf.
    #[arg(short, long)]
    pub(crate) output: Option<PathBuf>,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) overwrite: bool,
}

pub(crate) fn gen(args: &GenArgs) -> Result<()> {
    if let Some(field) = args.rf {
        return gen_rf(args, field);
    }
    let Some(count) = &args.count else {
        bail!("gen needs the number of Gaussians (e.g. `vksplat gen 1e5 -o scene.ply`), or --rf dipole|two-ray OUT.npy");
    };
    let count = vksplat::bench::parse_count(count)
        .map_err(|m| anyhow::anyhow!("invalid value for N: {m}"))?;
    let Some(output) = &args.output else {
        bail!("gen needs an output file: -o scene.ply|scene.splat|scene.spz");
    };
    let format = OutputFormat::from_path(output)?;
    check_output_file(output, args.overwrite)?;
    let scene = vksplat::gen::synthetic_scene(count, args.seed, args.sh_degree);
    let bytes = to_bytes(&scene, format).map_err(|message| {
        anyhow::anyhow!(
            "{}: cannot be written as {format}: {message}",
            output.display()
        )
    })?;
    vksplat::output::write_bytes_atomically(output, args.overwrite, &bytes)?;
    note!(
        "wrote {} synthetic Gaussians (seed {}, SH degree {}) to {} ({format})",
        scene.len(),
        args.seed,
        args.sh_degree.min(format.max_sh_degree()),
        output.display()
    );
    Ok(())
}

fn gen_rf(args: &GenArgs, field: RfField) -> Result<()> {
    let out = match (&args.count, &args.output) {
        (Some(_), Some(_)) => bail!("give the output .npy once: as OUT.npy or as -o OUT.npy"),
        (Some(p), None) => PathBuf::from(p),
        (None, Some(p)) => p.clone(),
        (None, None) => bail!("gen --rf needs an output file: vksplat gen --rf {field} OUT.npy"),
    };
    let is_npy = out
        .extension()
        .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case("npy"));
    if !is_npy {
        bail!(
            "{}: gen --rf writes a NumPy array; name the output .npy",
            out.display()
        );
    }
    let sidecar = vksplat::rf::sidecar_path(&out);
    check_output_file(&out, args.overwrite)?;
    check_output_file(&sidecar, args.overwrite)?;
    let grid = vksplat::rf::generate(field, args.size);
    let bytes = vksplat::image_file::npy_bytes(&grid.shape(), &grid.data);
    vksplat::output::write_bytes_atomically(&out, args.overwrite, &bytes)?;
    vksplat::output::write_bytes_atomically(
        &sidecar,
        args.overwrite,
        vksplat::rf::sidecar_json(&grid).as_bytes(),
    )?;
    let b = grid.bounds;
    note!(
        "wrote the {field} field, {n} x {n} x {n} x 4 ({}), to {} and its bounds to {}",
        field.channels().join(", "),
        out.display(),
        sidecar.display(),
        n = args.size
    );
    vksplat::outln!(
        "--bounds {},{},{},{},{},{}",
        b[0],
        b[1],
        b[2],
        b[3],
        b[4],
        b[5]
    );
    Ok(())
}
