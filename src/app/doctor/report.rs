//! One markdown report from the results folder of a GPU bundle run (`tools/bundle/run.sh`):
//! the device, what `doctor` said, GPU-vs-CPU comparisons, forward and backward benches
//! and training, with every step's outcome. Made by the `verisplat` binary itself because
//! the target machine may have no Python.
//!
//! The folder holds what `run.sh` wrote: `info.txt` (`key: value` lines), `steps.tsv`
//! (step, status, seconds, command; tab-separated), `doctor.json`, `compare_<name>/report.json`,
//! `forward_<name>.json` and `backward_<name>.json` (`verisplat bench --json`), and
//! `train.txt` (`verisplat train --timings` output). Anything missing is reported as missing.

use std::fmt::Write as _;
use std::path::Path;

use serde_json::Value;

fn read_json(path: &Path) -> Option<Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

fn num(v: &Value, path: &[&str]) -> Option<f64> {
    path.iter().try_fold(v, |v, k| v.get(k))?.as_f64()
}

fn text<'a>(v: &'a Value, key: &str) -> &'a str {
    v.get(key).and_then(Value::as_str).unwrap_or("?")
}

fn fmt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        Some(x) if x.is_infinite() => "inf".into(),
        _ => "–".into(),
    }
}

/// Thousands separators: 125000 -> 125,000.
fn grouped(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    out
}

fn mib(bytes: f64) -> String {
    if bytes >= (1u64 << 30) as f64 {
        format!("{:.1} GiB", bytes / (1u64 << 30) as f64)
    } else {
        format!("{:.0} MiB", bytes / (1u64 << 20) as f64)
    }
}

/// Files in `dir` named `<prefix>*<suffix>`, sorted.
fn files(dir: &Path, prefix: &str, suffix: &str) -> Vec<std::path::PathBuf> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(prefix) && n.ends_with(suffix))
        })
        .collect();
    out.sort();
    out
}

fn scene_name(v: &Value) -> String {
    let s = text(v, "scene");
    Path::new(s)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or(s)
        .to_string()
}

/// The markdown report of the results in `dir`.
pub fn markdown(dir: &Path) -> String {
    let mut md = String::new();
    let doctor = read_json(&dir.join("doctor.json"));
    let run = doctor
        .as_ref()
        .and_then(|d| d.get("runs"))
        .and_then(|r| r.get(0));
    let device = run.map_or("unknown device".to_string(), |r| {
        text(r, "device").to_string()
    });
    let _ = writeln!(md, "# verisplat on {device}\n");
    if let Ok(info) = std::fs::read_to_string(dir.join("info.txt")) {
        for line in info.lines().filter(|l| !l.trim().is_empty()) {
            let _ = writeln!(md, "- {line}");
        }
    }
    if let Some(r) = run {
        let _ = writeln!(md, "- driver: {}", text(r, "driver"));
    }
    md.push('\n');
    doctor_section(&mut md, doctor.as_ref());
    compare_section(&mut md, dir);
    bench_section(&mut md, dir);
    train_section(&mut md, dir);
    steps_section(&mut md, dir);
    md
}

fn doctor_section(md: &mut String, doctor: Option<&Value>) {
    let _ = writeln!(md, "## Doctor (`verisplat doctor`)\n");
    let Some(d) = doctor else {
        let _ = writeln!(
            md,
            "No doctor report (doctor.json is missing: see the steps).\n"
        );
        return;
    };
    if let Some(devices) = d.get("devices").and_then(Value::as_array) {
        let _ = writeln!(
            md,
            "| # | device | type | driver | Vulkan | subgroup (min-max) | shared memory | max invocations | storage buffer range | float atomics | int64 atomics | device-local memory | usable |"
        );
        let _ = writeln!(md, "|--:|---|---|---|---|---|--:|--:|--:|---|---|--:|---|");
        for dev in devices {
            let local: f64 = dev
                .get("heaps")
                .and_then(Value::as_array)
                .map(|h| {
                    h.iter()
                        .filter(|h| h.get("device_local") == Some(&Value::Bool(true)))
                        .filter_map(|h| num(h, &["size"]))
                        .sum()
                })
                .unwrap_or(0.0);
            let yes = |k: &str| {
                if dev.get(k) == Some(&Value::Bool(true)) {
                    "yes"
                } else {
                    "no"
                }
            };
            let missing = dev
                .get("missing")
                .and_then(Value::as_array)
                .map(|m| {
                    m.iter()
                        .filter_map(Value::as_str)
                        .collect::<Vec<_>>()
                        .join(", ")
                })
                .unwrap_or_default();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} {} | {} | {} ({}-{}) | {} B | {} | {} B | {} | {} | {} | {} |",
                fmt(num(dev, &["index"]), 0),
                text(dev, "name"),
                text(dev, "device_type"),
                text(dev, "driver_name"),
                text(dev, "driver_info"),
                text(dev, "api_version"),
                fmt(num(dev, &["subgroup_size"]), 0),
                fmt(num(dev, &["min_subgroup_size"]), 0),
                fmt(num(dev, &["max_subgroup_size"]), 0),
                fmt(num(dev, &["max_shared_memory"]), 0),
                fmt(num(dev, &["max_workgroup_invocations"]), 0),
                fmt(num(dev, &["max_storage_buffer_range"]), 0),
                yes("float32_atomic_add"),
                yes("int64_atomics"),
                mib(local),
                if missing.is_empty() {
                    "yes".to_string()
                } else {
                    format!("no: lacks {missing}")
                }
            );
        }
        md.push('\n');
    }
    for run in d
        .get("runs")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        let _ = writeln!(
            md,
            "Self-check on #{} {} (subgroup {} measured, {} reported):\n",
            fmt(num(run, &["device_index"]), 0),
            text(run, "device"),
            fmt(num(run, &["subgroup_size"]), 0),
            fmt(num(run, &["reported_subgroup_size"]), 0)
        );
        let _ = writeln!(md, "| check | what | figure | threshold | result |");
        let _ = writeln!(md, "|---|---|---|---|---|");
        for c in run
            .get("checks")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            let passed = c.get("passed") == Some(&Value::Bool(true));
            let warning = c
                .get("warning")
                .and_then(Value::as_str)
                .map(|w| format!(" (WARN: {w})"))
                .unwrap_or_default();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {}{} |",
                text(c, "name"),
                text(c, "what"),
                text(c, "figure").replace('|', "/"),
                text(c, "threshold"),
                if passed { "PASS" } else { "**FAIL**" },
                warning
            );
        }
        md.push('\n');
        // Whether the device reproduces the CPU reference bit for bit (the render check's
        // note), as a line of its own.
        for note in run
            .get("checks")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
            .filter_map(|c| c.get("note").and_then(Value::as_str))
        {
            let _ = writeln!(md, "{}\n", note.replace('|', "/"));
        }
    }
    let passed = d.get("passed") == Some(&Value::Bool(true));
    let _ = writeln!(
        md,
        "**Doctor: {}.**\n",
        if passed {
            "every check passed"
        } else {
            "a check FAILED (the figures below are not to be trusted)"
        }
    );
}

fn compare_section(md: &mut String, dir: &Path) {
    let mut reports: Vec<_> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("compare_"))
        })
        .map(|p| p.join("report.json"))
        .collect();
    reports.sort();
    if reports.is_empty() {
        return;
    }
    let _ = writeln!(md, "## GPU vs CPU reference (`verisplat compare`)\n");
    let _ = writeln!(
        md,
        "| scene | frames | resolution | lowest colour dB | lowest SSIM | lowest within 1/255 % | lowest alpha dB | blend kernel | result |"
    );
    let _ = writeln!(md, "|---|--:|---|--:|--:|--:|--:|---|---|");
    for path in reports {
        let Some(r) = read_json(&path) else {
            let name = path
                .parent()
                .and_then(|p| p.file_name())
                .and_then(|n| n.to_str())
                .unwrap_or("?")
                .trim_start_matches("compare_")
                .to_string();
            let _ = writeln!(md, "| {name} | – | – | – | – | – | – | – | no report |");
            continue;
        };
        let frames: Vec<&Value> = r
            .get("frames")
            .and_then(Value::as_array)
            .map(|f| f.iter().collect())
            .unwrap_or_default();
        let lowest = |p: &[&str]| {
            frames
                .iter()
                .filter_map(|f| num(f, p))
                .fold(None, |a: Option<f64>, x| Some(a.map_or(x, |a| a.min(x))))
        };
        let res = frames.first().map_or("–".to_string(), |f| {
            format!(
                "{}x{}",
                fmt(num(f, &["width"]), 0),
                fmt(num(f, &["height"]), 0)
            )
        });
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            scene_name(&r),
            frames.len(),
            res,
            fmt(lowest(&["color", "psnr"]), 2),
            fmt(lowest(&["ssim"]), 5),
            fmt(lowest(&["color", "within"]).map(|w| w * 100.0), 3),
            fmt(lowest(&["alpha", "psnr"]), 2),
            text(&r, "blend_kernel"),
            if r.get("pass") == Some(&Value::Bool(true)) {
                "pass"
            } else {
                "**FAIL**"
            }
        );
    }
    md.push('\n');
}

fn bench_section(md: &mut String, dir: &Path) {
    let forward: Vec<Value> = files(dir, "forward_", ".json")
        .iter()
        .filter_map(|p| read_json(p))
        .flat_map(|v| {
            v.get("runs")
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default()
        })
        .collect();
    let backward: Vec<Value> = files(dir, "backward_", ".json")
        .iter()
        .filter_map(|p| read_json(p))
        .flat_map(|v| {
            v.get("backward_runs")
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default()
        })
        .collect();
    if forward.is_empty() && backward.is_empty() {
        return;
    }
    let _ = writeln!(md, "## Forward and backward passes (`verisplat bench`)\n");
    let _ = writeln!(
        md,
        "| scene | Gaussians | resolution | forward ms | frames/s | forward ms (saving state) | backward ms | backward / forward | blend_bwd ms | device bytes / Gaussian (training) |"
    );
    let _ = writeln!(md, "|---|--:|---|--:|--:|--:|--:|--:|--:|--:|");
    let key = |r: &Value| {
        (
            text(r, "scene").to_string(),
            num(r, &["gaussians"]).unwrap_or(0.0) as u64,
            num(r, &["width"]).unwrap_or(0.0) as u64,
            num(r, &["height"]).unwrap_or(0.0) as u64,
        )
    };
    let mut rows: Vec<(String, u64, u64, u64)> = forward.iter().chain(&backward).map(key).collect();
    rows.dedup();
    let mut seen = std::collections::HashSet::new();
    rows.retain(|k| seen.insert(k.clone()));
    for k in rows {
        let f = forward.iter().find(|r| key(r) == k);
        let b = backward.iter().find(|r| key(r) == k);
        let blend_bwd = b.and_then(|b| {
            b.get("backward_stages")?
                .as_array()?
                .iter()
                .find(|s| s.get("name").and_then(Value::as_str) == Some("blend_bwd"))
                .and_then(|s| num(s, &["median"]))
        });
        let name = Path::new(&k.0)
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or(&k.0)
            .to_string();
        let _ = writeln!(
            md,
            "| {} | {} | {}x{} | {} | {} | {} | {} | {} | {} | {} |",
            name,
            grouped(k.1),
            k.2,
            k.3,
            fmt(f.and_then(|f| num(f, &["frame_ms", "median"])), 2),
            fmt(f.and_then(|f| num(f, &["fps"])), 1),
            fmt(b.and_then(|b| num(b, &["forward_ms", "median"])), 2),
            fmt(b.and_then(|b| num(b, &["backward_ms", "median"])), 2),
            fmt(b.and_then(|b| num(b, &["backward_over_forward"])), 2),
            fmt(blend_bwd, 2),
            fmt(b.and_then(|b| num(b, &["device_bytes_per_gaussian"])), 0),
        );
    }
    let frames = forward
        .first()
        .and_then(|r| num(r, &["frames"]))
        .map(|f| format!("{f:.0}"))
        .unwrap_or_else(|| "–".into());
    let _ = writeln!(
        md,
        "\nMedians of device timestamps over {frames} measured frames (warm-up discarded).\n"
    );
    pairs_table(md, &forward);
    traffic_table(md, &forward);
}

/// The forward stages' device memory traffic (`bytes` of each stage in `verisplat bench
/// --json`) and the bandwidth it makes at the stage's median time.
fn traffic_table(md: &mut String, forward: &[Value]) {
    // The stages `bench` counts the bytes of: every forward stage but the feature blend
    // and the shader.
    use crate::render::Stage;
    let stages: Vec<&str> = Stage::FORWARD
        .into_iter()
        .filter(|s| !matches!(s, Stage::Features | Stage::Shade))
        .map(Stage::name)
        .collect();
    let stage = |r: &Value, name: &str| -> Option<(f64, f64)> {
        let s = r
            .get("stages")?
            .as_array()?
            .iter()
            .find(|s| s.get("name").and_then(Value::as_str) == Some(name))?;
        let bytes = num(s, &["bytes", "read"])? + num(s, &["bytes", "written"])?;
        Some((bytes, num(s, &["median"])?))
    };
    let counted: Vec<&Value> = forward
        .iter()
        .filter(|r| stages.iter().any(|n| stage(r, n).is_some()))
        .collect();
    if counted.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "| scene | Gaussians | resolution | {} |",
        stages.join(" | ")
    );
    let _ = writeln!(md, "|---|--:|---|{}", "--:|".repeat(stages.len()));
    for r in counted {
        let cells: Vec<String> = stages
            .iter()
            .map(|n| match stage(r, n) {
                Some((bytes, ms)) if ms > 0.0 => {
                    format!(
                        "{:.1} MB, {:.0} GB/s",
                        bytes / 1e6,
                        bytes / (ms * 1e-3) / 1e9
                    )
                }
                Some((bytes, _)) => format!("{:.1} MB", bytes / 1e6),
                None => "–".into(),
            })
            .collect();
        let _ = writeln!(
            md,
            "| {} | {} | {}x{} | {} |",
            scene_name(r),
            grouped(num(r, &["gaussians"]).unwrap_or(0.0) as u64),
            fmt(num(r, &["width"]), 0),
            fmt(num(r, &["height"]), 0),
            cells.join(" | ")
        );
    }
    let _ = writeln!(
        md,
        "\nBytes each stage's shaders read and write in device memory per frame, counted from the frame's counts and records (caches not modelled), and that over the stage's median time: the bandwidth it reached at least.\n"
    );
}

/// The forward frames' pairs (`pair_stats` of `verisplat bench --json`): how many are
/// sorted, how many of them can draw, and how they fall per bin.
fn pairs_table(md: &mut String, forward: &[Value]) {
    let counted: Vec<&Value> = forward
        .iter()
        .filter(|r| r.get("pair_stats").is_some_and(|p| !p.is_null()))
        .collect();
    if counted.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "| scene | Gaussians | resolution | pairs sorted | per visible Gaussian | sorted / can draw | bin | pairs per bin: max | p99 |"
    );
    let _ = writeln!(md, "|---|--:|---|--:|--:|--:|--:|--:|--:|");
    for r in counted {
        let p = &r["pair_stats"];
        let pairs = num(r, &["pairs"]);
        let drawing = num(p, &["drawing"]);
        let ratio = pairs.zip(drawing).map(|(a, b)| a / b.max(1.0));
        let _ = writeln!(
            md,
            "| {} | {} | {}x{} | {} | {} | {} | {} px | {} | {} |",
            scene_name(r),
            grouped(num(r, &["gaussians"]).unwrap_or(0.0) as u64),
            fmt(num(r, &["width"]), 0),
            fmt(num(r, &["height"]), 0),
            grouped(pairs.unwrap_or(0.0) as u64),
            fmt(num(p, &["per_visible"]), 2),
            fmt(ratio, 3),
            fmt(num(p, &["bin_size"]), 0),
            grouped(num(p, &["per_bin_max"]).unwrap_or(0.0) as u64),
            grouped(num(p, &["per_bin_p99"]).unwrap_or(0.0) as u64),
        );
    }
    let _ = writeln!(
        md,
        "\nA pair can draw when some pixel centre of its bin gets alpha >= 1/255 from the Gaussian (counted on the host from one frame's lists; frames in chunks are not counted).\n"
    );
}

fn train_section(md: &mut String, dir: &Path) {
    let Ok(out) = std::fs::read_to_string(dir.join("train.txt")) else {
        return;
    };
    let _ = writeln!(md, "## Training (`verisplat train --timings`)\n");
    if let Some(line) = out.lines().find(|l| l.starts_with("trained ")) {
        let _ = writeln!(md, "{line}\n");
    }
    let _ = writeln!(md, "```");
    for line in out
        .lines()
        .filter(|l| !l.contains('\r'))
        .skip_while(|l| !l.starts_with("trained ") && !l.starts_with("error"))
    {
        let _ = writeln!(md, "{line}");
    }
    let _ = writeln!(md, "```\n");
}

fn steps_section(md: &mut String, dir: &Path) {
    let Ok(steps) = std::fs::read_to_string(dir.join("steps.tsv")) else {
        return;
    };
    let _ = writeln!(md, "## Steps\n");
    let _ = writeln!(md, "| step | result | seconds | command |");
    let _ = writeln!(md, "|---|---|--:|---|");
    let mut failed = 0;
    for line in steps.lines().filter(|l| !l.is_empty()) {
        let mut f = line.splitn(4, '\t');
        let (name, status, secs, cmd) = (
            f.next().unwrap_or("?"),
            f.next().unwrap_or("?"),
            f.next().unwrap_or("?"),
            f.next().unwrap_or(""),
        );
        if status != "ok" {
            failed += 1;
        }
        let status = if status == "ok" {
            "ok".to_string()
        } else {
            format!("**{status}**")
        };
        let _ = writeln!(
            md,
            "| {name} | {status} | {secs} | `{}` |",
            cmd.replace('|', "\\|")
        );
    }
    let _ = writeln!(
        md,
        "\n{}\n",
        if failed == 0 {
            "Every step succeeded.".to_string()
        } else {
            format!("{failed} step(s) failed: their logs are in the results folder.")
        }
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thousands_are_grouped() {
        assert_eq!(grouped(0), "0");
        assert_eq!(grouped(999), "999");
        assert_eq!(grouped(1000), "1,000");
        assert_eq!(grouped(10_000_000), "10,000,000");
    }

    #[test]
    fn an_empty_folder_makes_a_report_that_says_what_is_missing() {
        let dir = std::env::temp_dir().join(format!("verisplat-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let md = markdown(&dir);
        assert!(md.contains("doctor.json is missing"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
