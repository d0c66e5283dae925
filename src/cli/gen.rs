//! `verisplat gen`: a seeded synthetic scene, written in the format its name asks for; or,
//! with `--rf`, a synthetic RF field on a dense grid (`.npy`) for `verisplat fit`.

use super::common::check_output_file;
use super::values;
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use verisplat::core::console::note;
use verisplat::fields::rf::{MovingSource, RfData, RfField};
use verisplat::io::scene::write::{write_scene, OutputFormat};

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat gen 1e6 -o synthetic_1m.ply
  verisplat gen 100000 --seed 7 --sh-degree 3 -o s.spz
  verisplat gen --rf dipole dipole.npy            (64 x 64 x 64 x 4, plus dipole.npy.json)
  verisplat gen --rf two-ray tworay.npy --size 32
  verisplat gen --rf moving-source moving.npy     (16^3 points x 9 times: 36864 x 5, plus moving.npy.json)
  verisplat gen --rf moving-source moving.csv --size 12 --times 5

With --rf the field is written as a float32 .npy of shape N x N x N x 4 (points spread over
the field's bounds like numpy.linspace), with a sidecar OUT.npy.json holding the bounds and
channel names; `verisplat fit OUT.npy` reads the bounds from it. moving-source is a Gaussian blob
(sigma 0.5) whose centre moves from (-1, 0, 0) at t = 0 to (1, 0, 0) at t = 1, sampled on
the grid at --times times: samples x, y, z, t, magnitude as a float32 .npy (N x 5, its
sidecar naming column 3 the time) or a .csv with the header x,y,z,t,magnitude; `verisplat fit`
fits them in space and time.")]
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
    /// radiation), two-ray (a transmitter above a ground plane) or moving-source (a blob
    /// moving in time: samples with a time column).
    #[arg(long, value_name = "dipole|two-ray|moving-source")]
    pub(crate) rf: Option<RfData>,
    /// Grid points per axis of an --rf field [default: 64; 16 for moving-source].
    #[arg(long, value_name = "N", value_parser = values::int_in(2usize, 512), requires = "rf")]
    pub(crate) size: Option<usize>,
    /// --rf moving-source: times sampled, equally spaced over 0..1 (both ends) [default: 9].
    #[arg(long, value_name = "F", value_parser = values::int_in(2usize, 1000), requires = "rf")]
    pub(crate) times: Option<usize>,
    /// Output file, its format chosen by the name as `convert` chooses it: .ply (INRIA),
    /// .compressed.ply, .splat, .spz, .sog, DIR/meta.json (an unbundled SOG), .glb or
    /// .gltf (with its .bin); .npy with --rf.
    #[arg(short, long)]
    pub(crate) output: Option<PathBuf>,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub(crate) overwrite: bool,
}

pub(crate) fn gen(args: &GenArgs) -> Result<()> {
    match args.rf {
        Some(RfData::Grid(field)) => return gen_rf(args, field),
        Some(RfData::MovingSource) => return gen_moving_source(args),
        None => {}
    }
    let Some(count) = &args.count else {
        bail!("gen needs the number of Gaussians (e.g. `verisplat gen 1e5 -o scene.ply`), or --rf dipole|two-ray|moving-source OUT.npy");
    };
    let count = verisplat::app::bench::parse_count(count)
        .map_err(|m| anyhow::anyhow!("invalid value for N: {m}"))?;
    let Some(output) = &args.output else {
        bail!("gen needs an output file: -o scene.ply (or .compressed.ply, .splat, .spz, .sog, .glb, .gltf)");
    };
    let format = OutputFormat::from_path(output)?;
    check_output_file(output, args.overwrite)?;
    let scene = verisplat::core::gen::synthetic_scene(count, args.seed, args.sh_degree);
    // As `convert` writes it: a .gltf with its .bin beside it, DIR/meta.json unbundled.
    write_scene(&scene, output, format, args.overwrite)?;
    note!(
        "wrote {} synthetic Gaussians (seed {}, SH degree {}) to {} ({format})",
        scene.len(),
        args.seed,
        args.sh_degree.min(format.max_sh_degree()),
        output.display()
    );
    Ok(())
}

/// The output of `gen --rf`: `OUT` or `-o OUT`, once.
fn rf_output(args: &GenArgs, field: RfData) -> Result<PathBuf> {
    Ok(match (&args.count, &args.output) {
        (Some(_), Some(_)) => bail!("give the output .npy once: as OUT.npy or as -o OUT.npy"),
        (Some(p), None) => PathBuf::from(p),
        (None, Some(p)) => p.clone(),
        (None, None) => bail!("gen --rf needs an output file: verisplat gen --rf {field} OUT.npy"),
    })
}

/// `gen --rf moving-source`: the samples in space and time, `.npy` (with a sidecar) or
/// `.csv`.
fn gen_moving_source(args: &GenArgs) -> Result<()> {
    let out = rf_output(args, RfData::MovingSource)?;
    let ext = out
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if ext != "npy" && ext != "csv" {
        bail!(
            "{}: gen --rf moving-source writes samples as a NumPy array or a CSV file; name the output .npy or .csv",
            out.display()
        );
    }
    let (n, times) = (args.size.unwrap_or(16), args.times.unwrap_or(9));
    let rows = MovingSource::samples(n, times);
    let count = n * n * n * times;
    check_output_file(&out, args.overwrite)?;
    let sidecar = verisplat::fields::rf::sidecar_path(&out);
    if ext == "npy" {
        check_output_file(&sidecar, args.overwrite)?;
        let bytes = verisplat::io::image_file::npy_bytes(&[count, 5], &rows);
        verisplat::io::output::write_bytes_atomically(&out, args.overwrite, &bytes)?;
        verisplat::io::output::write_bytes_atomically(
            &sidecar,
            args.overwrite,
            MovingSource::sidecar_json(n, times).as_bytes(),
        )?;
    } else {
        let mut text = MovingSource::COLUMNS.join(",") + "\n";
        for r in rows.chunks_exact(5) {
            let line: Vec<String> = r.iter().map(|v| format!("{v:?}")).collect();
            text.push_str(&line.join(","));
            text.push('\n');
        }
        verisplat::io::output::write_bytes_atomically(&out, args.overwrite, text.as_bytes())?;
    }
    note!(
        "wrote the moving source (centre (-1 + 2 t, 0, 0), sigma {}), {count} samples x, y, z, t, magnitude ({n}^3 points at {times} times over 0..1), to {}{}",
        MovingSource::SIGMA,
        out.display(),
        if ext == "npy" {
            format!(" and its columns to {}", sidecar.display())
        } else {
            String::new()
        }
    );
    print_fit_flags(MovingSource::BOUNDS, " --time-column 3");
    Ok(())
}

/// Prints the `fit` flags that read the generated data as generated: `--bounds`, then
/// `extra`.
fn print_fit_flags(b: [f32; 6], extra: &str) {
    verisplat::core::console::outln!(
        "--bounds {},{},{},{},{},{}{extra}",
        b[0],
        b[1],
        b[2],
        b[3],
        b[4],
        b[5]
    );
}

fn gen_rf(args: &GenArgs, field: RfField) -> Result<()> {
    if args.times.is_some() {
        bail!("--times applies to --rf moving-source; {field} is a static field");
    }
    let out = rf_output(args, RfData::Grid(field))?;
    let is_npy = out
        .extension()
        .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case("npy"));
    if !is_npy {
        bail!(
            "{}: gen --rf writes a NumPy array; name the output .npy",
            out.display()
        );
    }
    let sidecar = verisplat::fields::rf::sidecar_path(&out);
    check_output_file(&out, args.overwrite)?;
    check_output_file(&sidecar, args.overwrite)?;
    let size = args.size.unwrap_or(64);
    let grid = verisplat::fields::rf::generate(field, size);
    let bytes = verisplat::io::image_file::npy_bytes(&grid.shape(), &grid.data);
    verisplat::io::output::write_bytes_atomically(&out, args.overwrite, &bytes)?;
    verisplat::io::output::write_bytes_atomically(
        &sidecar,
        args.overwrite,
        verisplat::fields::rf::sidecar_json(&grid).as_bytes(),
    )?;
    let b = grid.bounds;
    note!(
        "wrote the {field} field, {n} x {n} x {n} x 4 ({}), to {} and its bounds to {}",
        field.channels().join(", "),
        out.display(),
        sidecar.display(),
        n = size
    );
    print_fit_flags(b, "");
    Ok(())
}
