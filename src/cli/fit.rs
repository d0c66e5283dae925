//! `verisplat fit`: Gaussians with feature channels fitted to RF field samples.

use super::common::check_output_file;
use super::values;
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;
use verisplat::core::console::{note, outln};
use verisplat::cpu::SplatKernel;
use verisplat::fields::fit::{Columns, FieldData, FitConfig, FitOutcome, Layout};

#[derive(Args)]
#[command(after_help = "Examples:
  verisplat gen --rf dipole dipole.npy
  verisplat fit dipole.npy -o dipole.ply --report dipole_fit.json
  verisplat fit samples.csv -o field.ply --gaussians 500 --max-gaussians 2000 --kernel power
  verisplat gen --rf moving-source moving.npy
  verisplat fit moving.npy -o moving.ply      (x, y, z, t, value: --time-column 3 from moving.npy.json)

Inputs: a dense grid .npy (X x Y x Z x C, points spread over --bounds like numpy.linspace,
or over the bounds of the sidecar FILE.npy.json that `gen --rf` writes), or scattered
samples (.npy or .csv, N x (3 + C): x, y, z, then C values; a CSV may hold # comments and
start with a header row, whose x, y, z (and t or time) columns are found by name in any
order, the notes saying which column plays which role). The C values become the Gaussians'
features feat_0..feat_{C-1}. Fewer than 45 samples (20 to fit, 5 held out at the default
--holdout 0.1) need --force.
Samples with a time (one more column, --time-column; a CSV header's t or time column is
found by itself) are fitted in space and time: each Gaussian gets a temporal mean and scale
(t_mean, t_scale in the PLY); render them with `verisplat render --time T`.")]
pub(crate) struct FitArgs {
    /// Field samples: a grid .npy (X x Y x Z x C) or samples .npy / .csv (N x (3 + C)).
    pub(crate) input: PathBuf,
    /// Output PLY (features as feat_*, colours from the turbo colormap of the magnitude).
    #[arg(short, long, value_name = "OUT.ply")]
    pub(crate) output: PathBuf,
    /// Extent of a grid input [default: from the sidecar INPUT.json that gen --rf writes, e.g. dipole.npy.json].
    /// Scattered samples: the region they were taken in (every sample inside it; a scan on a
    /// plane or a line gets its thickness from it).
    #[arg(long, value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", value_parser = verisplat::fields::fit::parse_bounds, allow_hyphen_values = true)]
    pub(crate) bounds: Option<[f32; 6]>,
    /// Scattered samples: the column holding each sample's time (0-based, after x, y, z: e.g.
    /// 3 for rows x, y, z, t, values...), or a CSV header's name for it; the field is then
    /// fitted in space and time [default: a CSV header's t or time column, or the
    /// time_column of the sidecar INPUT.json that gen --rf moving-source writes; else none].
    #[arg(long, value_name = "C|NAME")]
    pub(crate) time_column: Option<verisplat::fields::fit::TimeColumn>,
    /// Gaussians at the start [default: one per 20 samples, 8 to 1000].
    #[arg(long, value_name = "N", value_parser = values::int_in(1usize, 10_000_000))]
    pub(crate) gaussians: Option<usize>,
    /// Density control never goes beyond this many Gaussians [default: one per 5 samples,
    /// at least --gaussians, at most 4000].
    #[arg(long, value_name = "M", value_parser = values::int_in(1usize, 10_000_000))]
    pub(crate) max_gaussians: Option<usize>,
    /// The magnitude channel is in dB (10 log10 of a power, e.g. dBm): fit it as the linear
    /// power 10^(v/10) (the PLY holds that power) and also report the held-out error in dB.
    #[arg(long)]
    pub(crate) db: bool,
    /// Clip the gradient's norm to this before each Adam step (the values are normalised
    /// to a largest magnitude of 1 first; 0: no clipping).
    #[arg(long, value_name = "G", default_value_t = 0.0, value_parser = non_negative)]
    pub(crate) clip_grad: f32,
    /// Channels M,P hold one complex value as magnitude and phase (radians): fit it as
    /// I = M cos P and Q = M sin P (channels M and P of the PLY then hold I and Q), so the
    /// Gaussians add up coherently; render with --complex M,P to see |f| and its phase.
    #[arg(long, value_name = "M,P", value_parser = channel_pair)]
    pub(crate) complex: Option<(usize, usize)>,
    /// Optimisation steps (one mini-batch each).
    #[arg(long, value_name = "S", default_value_t = FitConfig::default().steps, value_parser = values::int_in(1usize, 10_000_000))]
    pub(crate) steps: usize,
    /// Prune and densify every M steps, during the first three quarters of the steps (0: never).
    #[arg(long, value_name = "M", default_value_t = 100)]
    pub(crate) densify_every: usize,
    /// Prune Gaussians whose opacity falls below this (also once at the end).
    #[arg(long, value_name = "O", default_value_t = 0.005, value_parser = values::unit_f32)]
    pub(crate) min_opacity: f32,
    /// The channel that weights the loss (weight 0.1 + 0.9 |value| / max |value|).
    #[arg(long, value_name = "C", default_value_t = 0)]
    pub(crate) magnitude_channel: usize,
    /// Fraction of the samples held out to measure the error (0 to 0.9).
    #[arg(long, value_name = "F", default_value_t = 0.1, value_parser = holdout)]
    pub(crate) holdout: f32,
    /// Training samples per step.
    #[arg(long, value_name = "B", default_value_t = FitConfig::default().batch, value_parser = values::int_in(1usize, 1 << 30))]
    pub(crate) batch: usize,
    /// Weight of the scale regulariser (mean over Gaussians of sum_j (scale_j / diagonal)^2).
    #[arg(long, value_name = "W", default_value_t = FitConfig::default().scale_reg, value_parser = non_negative)]
    pub(crate) scale_reg: f32,
    /// Random seed (initialisation, hold-out and batches).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Falloff of the Gaussians: gaussian (exp(-d2/2), truncated at d2 = 16) or power (max(0, 1 - d2/9)).
    #[arg(long, value_name = "gaussian|power", default_value = "gaussian")]
    pub(crate) kernel: SplatKernel,
    /// Also write a JSON report (inputs, parameters, losses, held-out error, counts, time).
    #[arg(long, value_name = "FILE.json")]
    pub(crate) report: Option<PathBuf>,
    /// Fit samples too few to fit and hold out (fewer than 20 to fit on, or, with
    /// --holdout above 0, fewer than 5 held out), which is refused otherwise.
    #[arg(long)]
    pub(crate) force: bool,
    /// Replace output files that exist.
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

fn holdout(s: &str) -> Result<f32, String> {
    let v = values::unit_f32(s)?;
    if v <= 0.9 {
        Ok(v)
    } else {
        Err(format!("must be between 0 and 0.9, got {v}"))
    }
}

/// `A,B`: two different channel numbers.
pub(crate) fn channel_pair(s: &str) -> Result<(usize, usize), String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let pair = match parts[..] {
        [a, b] => a.parse::<usize>().ok().zip(b.parse::<usize>().ok()),
        _ => None,
    };
    match pair {
        Some((a, b)) if a != b => Ok((a, b)),
        Some(_) => Err(format!("the two channels must differ, got \"{s}\"")),
        None => Err(format!("expected two channel numbers A,B, got \"{s}\"")),
    }
}

fn non_negative(s: &str) -> Result<f32, String> {
    let v = values::any_f32(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("must be 0 or more, got {v}"))
    }
}

pub(crate) fn fit(args: &FitArgs) -> Result<()> {
    let started = Instant::now();
    check_paths(args)?;
    let (data, columns, magnitude_channel) = load_input(args)?;
    let cfg = config(args, &data, magnitude_channel)?;
    let layout = describe(args, &data, columns.as_ref(), &cfg);
    let bar = progress_bar(args.quiet, cfg.steps);
    let outcome = verisplat::fields::fit::fit(&data, &cfg, &mut |p| {
        if p.step % 10 == 0 || p.step == cfg.steps {
            bar.set_message(format!("loss {:.3e}  {} Gaussians", p.loss, p.gaussians));
            bar.set_position(p.step as u64);
        }
    })
    .map_err(|m| anyhow::anyhow!("{}: {m}", args.input.display()))?;
    bar.finish_and_clear();
    for n in &outcome.notes {
        note!("note: {n}");
    }
    let warnings = warnings(&outcome);
    let scene = verisplat::fields::fit::to_scene(&outcome, cfg.kernel, cfg.magnitude_channel);
    let bytes = verisplat::io::scene::ply::to_bytes(
        &scene,
        verisplat::io::scene::ply::PlyEncoding::BinaryLittleEndian,
    );
    verisplat::io::output::write_bytes_atomically(&args.output, args.overwrite, &bytes)?;
    let seconds = started.elapsed().as_secs_f64();
    let input = Input {
        data: &data,
        columns: columns.as_ref(),
        layout: &layout,
    };
    write_report(args, &input, &cfg, &outcome, &warnings, seconds)?;
    print_summary(args, &cfg, &outcome, &warnings, seconds);
    Ok(())
}

/// Refuses outputs that are not a PLY, that are the input or each other, or that exist
/// (without `--overwrite`), and a start above the most Gaussians.
fn check_paths(args: &FitArgs) -> Result<()> {
    let ext = args
        .output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if ext.as_deref() != Some("ply") {
        bail!(
            "{}: fit writes a PLY (feat_* properties); name the output .ply",
            args.output.display()
        );
    }
    if args.output == args.input || args.report.as_ref() == Some(&args.input) {
        bail!(
            "{}: is the input file; choose another output",
            args.input.display()
        );
    }
    if args.report.as_ref() == Some(&args.output) {
        bail!("{}: is both the PLY and the report", args.output.display());
    }
    check_output_file(&args.output, args.overwrite)?;
    if let Some(r) = &args.report {
        check_output_file(r, args.overwrite)?;
    }
    if let (Some(g), Some(m)) = (args.gaussians, args.max_gaussians) {
        if g > m {
            bail!("--gaussians {g} is above --max-gaussians {m}");
        }
    }
    Ok(())
}

/// Loads the samples and refuses what no field can be fitted to or the options do not
/// fit (channels it does not have, a magnitude channel without a positive value).
/// Returns them, the roles of their columns and the channel that weights the loss.
fn load_input(args: &FitArgs) -> Result<(FieldData, Option<Columns>, usize)> {
    let (data, columns) = verisplat::fields::fit::load_with_columns(
        &args.input,
        args.bounds,
        &args.time_column.clone().unwrap_or_default(),
    )?;
    for n in columns.iter().flat_map(|c| &c.notes) {
        note!("note: {}: {n}", args.input.display());
    }
    verisplat::fields::fit::check_fittable(&data)
        .map_err(|m| anyhow::anyhow!("{}: {m}", args.input.display()))?;
    if args.magnitude_channel >= data.k {
        bail!(
            "{}: --magnitude-channel {} is not one of its channels (it has {}: 0 to {})",
            args.input.display(),
            args.magnitude_channel,
            data.k,
            data.k - 1
        );
    }
    if let Some((m, p)) = args.complex {
        if args.db {
            bail!("--complex and --db do not go together: give the magnitude linear");
        }
        if m.max(p) >= data.k {
            bail!(
                "{}: --complex {m},{p} names a channel it does not have (it has {}: 0 to {})",
                args.input.display(),
                data.k,
                data.k - 1
            );
        }
    }
    let magnitude_channel = args.complex.map_or(args.magnitude_channel, |(m, _)| m);
    if !args.db {
        verisplat::fields::fit::check_magnitude(&data, magnitude_channel)
            .map_err(|m| anyhow::anyhow!("{}: {m}", args.input.display()))?;
    }
    if !args.force {
        verisplat::fields::fit::check_enough(data.len(), args.holdout)
            .map_err(|m| anyhow::anyhow!("{}: {m}", args.input.display()))?;
    }
    Ok((data, columns, magnitude_channel))
}

/// The fitting options: the Gaussian counts (chosen from the samples' count unless given,
/// and noted) and the arguments.
fn config(args: &FitArgs, data: &FieldData, magnitude_channel: usize) -> Result<FitConfig> {
    let (auto_initial, auto_max) = verisplat::fields::fit::default_counts(data.len());
    let initial = args
        .gaussians
        .unwrap_or_else(|| auto_initial.min(args.max_gaussians.unwrap_or(usize::MAX)));
    let max_gaussians = args.max_gaussians.unwrap_or(auto_max.max(initial));
    if initial > max_gaussians {
        bail!("--gaussians {initial} is above --max-gaussians {max_gaussians}");
    }
    if (args.gaussians.is_none() || args.max_gaussians.is_none()) && !args.quiet {
        note!(
            "chose --gaussians {initial} --max-gaussians {max_gaussians} for {} samples (one Gaussian per 20 samples at the start, at most one per 5; give either to choose)",
            data.len()
        );
    }
    Ok(FitConfig {
        kernel: args.kernel,
        initial,
        max_gaussians,
        db: args.db,
        clip_grad: args.clip_grad,
        steps: args.steps,
        densify_every: args.densify_every,
        min_opacity: args.min_opacity,
        magnitude_channel,
        complex: args.complex,
        holdout: args.holdout,
        seed: args.seed,
        batch: args.batch,
        scale_reg: args.scale_reg,
        ..FitConfig::default()
    })
}

/// How the samples were given (for the report), noted with what is fitted to them and
/// which column plays which role.
fn describe(
    args: &FitArgs,
    data: &FieldData,
    columns: Option<&Columns>,
    cfg: &FitConfig,
) -> String {
    let layout = match &data.layout {
        Layout::Grid(s) => format!("grid {} x {} x {} x {}", s[0], s[1], s[2], s[3]),
        Layout::SamplesNpy => "samples (.npy)".into(),
        Layout::SamplesCsv => "samples (.csv)".into(),
    };
    let time = match (&data.times, data.time_column) {
        (Some(t), Some(c)) => {
            let (lo, hi) = t
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            format!(", with times from {lo} to {hi} (column {c})")
        }
        _ => String::new(),
    };
    if !args.quiet {
        note!(
            "fitting {} Gaussians (at most {}, {} kernel) to {} of {}{time} from {} ({layout})",
            cfg.initial,
            cfg.max_gaussians,
            cfg.kernel,
            super::plural(data.len(), "sample"),
            super::plural(data.k, "channel"),
            args.input.display()
        );
        if let Some(c) = columns {
            note!("columns of {}: {}", args.input.display(), c.describe());
        }
    }
    layout
}

/// The progress bar (hidden with `--quiet`).
fn progress_bar(quiet: bool, steps: usize) -> indicatif::ProgressBar {
    if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let bar = indicatif::ProgressBar::new(steps as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40.cyan/blue} step {pos}/{len}  ETA {eta}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    }
}

/// A fit no better than predicting 0 everywhere, one sentence.
fn warnings(outcome: &FitOutcome) -> Vec<String> {
    let mut warnings = Vec::new();
    if let Some(h) = outcome
        .holdout
        .as_ref()
        .filter(|h| h.relative_l2.is_nan() || h.relative_l2 >= 1.0)
    {
        warnings.push(format!(
            "the held-out relative L2 error is {:.3}: this fit is no better than predicting 0 everywhere (error 1); do not use it. More samples, more --steps or other --gaussians may help",
            h.relative_l2
        ));
    }
    warnings
}

/// The JSON report (`--report`): the input, the options, the losses and errors, the
/// density control's history, the time taken.
/// The input as the report describes it.
struct Input<'a> {
    data: &'a FieldData,
    columns: Option<&'a Columns>,
    layout: &'a str,
}

fn write_report(
    args: &FitArgs,
    input: &Input,
    cfg: &FitConfig,
    outcome: &FitOutcome,
    warnings: &[String],
    seconds: f64,
) -> Result<()> {
    let Some(report) = &args.report else {
        return Ok(());
    };
    let grown: usize = outcome.history.iter().map(|h| h.cloned + h.split).sum();
    let pruned: usize = outcome.history.iter().map(|h| h.pruned).sum();
    let (data, layout) = (input.data, input.layout);
    let value = serde_json::json!({
        "input": args.input.display().to_string(),
        "layout": layout,
        "columns": input.columns,
        "samples": data.len(),
        "channels": data.k,
        "bounds": data.bounds,
        "bounds_from": data.bounds_source,
        "time_column": data.time_column,
        "time_range": outcome.time_range.map(|(a, b)| [a, b]),
        "output": args.output.display().to_string(),
        "parameters": cfg,
        "train_samples": outcome.train_samples,
        "holdout_samples": outcome.holdout_samples,
        "final_loss": {
            "data": outcome.final_loss.0,
            "scale_regulariser": outcome.final_loss.1,
            "total": outcome.final_loss.0 + outcome.final_loss.1,
            "on": "all training samples",
        },
        "holdout_relative_l2": outcome.holdout.as_ref().map(|h| h.relative_l2),
        "holdout_magnitude_db_rms": outcome.holdout.as_ref().and_then(|h| h.magnitude_db_rms),
        "value_scale": outcome.value_scale,
        "fit_bounds": outcome.fit_bounds,
        "notes": outcome.notes,
        "warnings": warnings,
        "clipped_steps": outcome.clipped_steps,
        "holdout_relative_l2_per_channel": outcome.holdout.as_ref().map(|h| h.per_channel.clone()),
        "gaussians": {
            "initial": cfg.initial,
            "final": outcome.model.len(),
            "pruned": pruned,
            "added": grown,
        },
        "density_control": outcome.history,
        "seconds": seconds,
        "threads": rayon::current_num_threads(),
    });
    let text = serde_json::to_string_pretty(&value)? + "\n";
    verisplat::io::output::write_bytes_atomically(report, args.overwrite, text.as_bytes())?;
    Ok(())
}

/// The summary line (Gaussians, samples, steps, loss, held-out error), the warnings and
/// what was written.
fn print_summary(
    args: &FitArgs,
    cfg: &FitConfig,
    outcome: &FitOutcome,
    warnings: &[String],
    seconds: f64,
) {
    let grown: usize = outcome.history.iter().map(|h| h.cloned + h.split).sum();
    let pruned: usize = outcome.history.iter().map(|h| h.pruned).sum();
    let error = match &outcome.holdout {
        Some(h) => format!(
            "held-out relative L2 error {:.4} ({} samples; per channel {}){}",
            h.relative_l2,
            outcome.holdout_samples,
            h.per_channel
                .iter()
                .map(|e| format!("{e:.3}"))
                .collect::<Vec<_>>()
                .join(", "),
            h.magnitude_db_rms
                .map(|d| format!("; magnitude RMS error {d:.2} dB"))
                .unwrap_or_default()
        ),
        None => "no held-out samples (--holdout 0)".into(),
    };
    outln!(
        "fitted {} Gaussians ({} initial, {grown} added, {pruned} pruned) to {} samples in {} steps, {seconds:.1} s; training loss {:.4e}; {error}",
        outcome.model.len(),
        cfg.initial,
        outcome.train_samples,
        cfg.steps,
        outcome.final_loss.0 + outcome.final_loss.1,
    );
    for w in warnings {
        note!("warning: {w}");
    }
    if !args.quiet {
        note!("wrote {}", args.output.display());
        if let Some(r) = &args.report {
            note!("wrote {}", r.display());
        }
    }
}
