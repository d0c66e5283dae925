//! `verisplat doctor`: lists every Vulkan device and runs the self-check
//! ([`verisplat::app::doctor`]) on the usable ones; and the hidden `verisplat gpu-report`, which
//! turns a GPU bundle run's results into one markdown report.

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;
use verisplat::app::doctor::{self, DeviceRun};
use verisplat::core::console::{note, outln};
use verisplat::gpu::devices::{self, DeviceSummary};

#[derive(Args)]
#[command(after_help = "\
Run it on every new GPU or driver: each check compares a GPU building block with its CPU \
reference (subgroup size, the demo scene's render, the radix sort, the prefix sum, the \
backward pass) and prints its figure and PASS or FAIL. Exit status: 0 when every check on \
every checked device passes, 1 otherwise.

Examples:
  verisplat doctor
  verisplat doctor --device 1 --json doctor.json
  verisplat doctor --validate -q")]
pub(crate) struct DoctorArgs {
    /// Check only this device: index or part of its name (default: every usable device).
    #[arg(long, value_name = "N|NAME")]
    device: Option<String>,
    /// Write a machine-readable report (devices, and every check with its figure,
    /// threshold and result) to FILE, replacing it; "-" writes it to standard output
    /// (the text then goes to standard error).
    #[arg(long, value_name = "FILE|-")]
    json: Option<PathBuf>,
    /// Enable the Khronos validation layer (also VERISPLAT_VALIDATE=1): any message fails.
    #[arg(long)]
    validate: bool,
    /// Run only these checks (comma-separated: subgroups, sort64, sort32, scan, render,
    /// backward, validation; subgroups always runs, as the device opens).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    checks: Option<Vec<String>>,
    /// Print only warnings, failures and the verdict.
    #[arg(short, long)]
    quiet: bool,
}

/// The JSON report.
#[derive(Serialize)]
struct Report<'a> {
    schema_version: u32,
    verisplat_version: &'static str,
    devices: &'a [DeviceSummary],
    runs: &'a [DeviceRun],
    passed: bool,
}

fn describe(d: &DeviceSummary) -> Vec<String> {
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    let heaps: Vec<String> = d
        .heaps
        .iter()
        .map(|h| {
            format!(
                "{:.0} MiB{}{}",
                mib(h.size),
                if h.device_local { " device-local" } else { "" },
                h.budget
                    .map(|b| format!(" (budget {:.0} MiB)", mib(b)))
                    .unwrap_or_default()
            )
        })
        .collect();
    let yes = |b: bool| if b { "yes" } else { "no" };
    vec![
        format!(
            "#{} {} ({}): {}",
            d.index,
            d.name,
            d.device_type,
            if d.usable {
                "usable".to_string()
            } else {
                format!("NOT usable: lacks {}", d.missing.join(", "))
            }
        ),
        format!(
            "    driver {} {}, Vulkan {}",
            d.driver_name, d.driver_info, d.api_version
        ),
        format!(
            "    subgroup {} (min {}, max {}), operations: {}",
            d.subgroup_size,
            d.min_subgroup_size,
            d.max_subgroup_size,
            d.subgroup_operations.join(" ")
        ),
        format!(
            "    compute: shared memory {} B, workgroup invocations {}, workgroup count {:?}, storage buffer range {} B",
            d.max_shared_memory,
            d.max_workgroup_invocations,
            d.max_workgroup_count,
            d.max_storage_buffer_range
        ),
        format!(
            "    timestamps: {} ns per tick, {} valid bits; atomics: float32 add {}, int64 {}",
            d.timestamp_period_ns,
            d.timestamp_valid_bits,
            yes(d.float32_atomic_add),
            yes(d.int64_atomics)
        ),
        format!(
            "    memory heaps: {}{}",
            heaps.join(", "),
            if d.memory_budget_ext {
                ""
            } else {
                " (no VK_EXT_memory_budget)"
            }
        ),
    ]
}

pub(crate) fn doctor(args: &DoctorArgs) -> Result<()> {
    let json_to_stdout = args.json.as_deref() == Some(std::path::Path::new("-"));
    // The text goes to standard error when the JSON takes standard output.
    let say = |line: &str| {
        if json_to_stdout {
            note!("{line}");
        } else {
            outln!("{line}");
        }
    };
    let validation = args.validate || verisplat::core::former_name::env_flag("VERISPLAT_VALIDATE");
    if let Some(unknown) = args
        .checks
        .iter()
        .flatten()
        .find(|c| !doctor::CHECKS.contains(&c.as_str()))
    {
        bail!(
            "--checks: there is no check '{unknown}'; the checks are {}",
            doctor::CHECKS.join(", ")
        );
    }
    let list = devices::enumerate().context("listing the Vulkan devices")?;
    if !args.quiet {
        say(&format!("Vulkan devices ({}):", list.len()));
        for d in &list {
            for line in describe(d) {
                say(&format!("  {line}"));
            }
        }
    }
    let chosen: Vec<usize> = match &args.device {
        Some(choice) => {
            let names: Vec<String> = list.iter().map(|d| d.name.clone()).collect();
            match verisplat::gpu::context::select_device(choice, &names) {
                Some(i) => vec![i],
                None => bail!(
                    "no device matches --device {choice}; available: {}",
                    list.iter()
                        .map(|d| format!("#{} {}", d.index, d.name))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        }
        None => list.iter().filter(|d| d.usable).map(|d| d.index).collect(),
    };
    if chosen.is_empty() {
        bail!(
            "no usable Vulkan device (verisplat needs Vulkan 1.3 with a compute queue, push \
             descriptors, synchronization2 and maintenance4): {}",
            if list.is_empty() {
                "the Vulkan loader reports no devices (is a driver installed? VK_DRIVER_FILES \
                 may point at its ICD JSON)"
                    .to_string()
            } else {
                list.iter()
                    .map(|d| format!("#{} {} lacks {}", d.index, d.name, d.missing.join(", ")))
                    .collect::<Vec<_>>()
                    .join("; ")
            }
        );
    }
    let mut runs = Vec::new();
    for index in chosen {
        let name = list.get(index).map_or("?", |d| d.name.as_str());
        if !args.quiet {
            say(&format!("self-check on #{index} {name}:"));
        }
        let run = doctor::self_check(index, validation, args.checks.as_deref(), |check| {
            for (i, line) in check.lines().iter().enumerate() {
                // With -q: only failures and warnings.
                if !args.quiet || !check.passed || i > 0 {
                    say(line);
                }
            }
        });
        say(&run.verdict());
        runs.push(run);
    }
    let passed = runs.iter().all(|r| r.passed);
    if let Some(path) = &args.json {
        let report = Report {
            schema_version: 1,
            verisplat_version: env!("CARGO_PKG_VERSION"),
            devices: &list,
            runs: &runs,
            passed,
        };
        let text = serde_json::to_string_pretty(&report)? + "\n";
        if json_to_stdout {
            verisplat::core::console::out!("{text}");
        } else {
            std::fs::write(path, text)
                .with_context(|| format!("{}: cannot write the report", path.display()))?;
        }
    }
    if !passed {
        let failed: Vec<&str> = runs
            .iter()
            .filter(|r| !r.passed)
            .map(|r| r.device.as_str())
            .collect();
        bail!(
            "the self-check failed on {} (see the FAIL lines above)",
            failed.join(", ")
        );
    }
    Ok(())
}

#[derive(Args)]
pub(crate) struct GpuReportArgs {
    /// The results folder a GPU bundle's run.sh wrote (doctor.json, steps.tsv, bench and
    /// compare reports, train.txt).
    results: PathBuf,
    /// The markdown file to write (default: standard output); replaced if it exists.
    #[arg(short, long, value_name = "FILE.md")]
    output: Option<PathBuf>,
}

/// Writes the markdown report of a bundle run's results.
pub(crate) fn gpu_report(args: &GpuReportArgs) -> Result<()> {
    if !args.results.is_dir() {
        bail!("{}: not a folder of results", args.results.display());
    }
    let md = doctor::report::markdown(&args.results);
    match &args.output {
        Some(path) => std::fs::write(path, md)
            .with_context(|| format!("{}: cannot write the report", path.display()))?,
        None => verisplat::core::console::out!("{md}"),
    }
    Ok(())
}
