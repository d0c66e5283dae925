//! Benchmarks: per-stage timing reports (GPU timestamps or CPU wall clock), scaling sweeps,
//! CSV/JSON output and SVG plots. Used by `verisplat bench`; warm-up frames are discarded and
//! every figure is measured.
//!
//! This module holds the timing summaries shared by every benchmark ([`Stat`],
//! [`StageReport`]); the rooms below it hold the camera being timed (`camera`), the
//! forward benchmarks (`forward`), the statistics of a frame's pairs (`pairs`) and their report with its text, JSON and CSV forms
//! (`report`), the backward benchmark (`backward`), the command line's value parsers
//! (`parse`) and the SVG plots of a sweep (`plot`).

mod backward;
mod camera;
mod forward;
mod pairs;
mod parse;
mod plot;
mod report;

pub use backward::{backward_to_json, bench_backward, BackwardReport};
pub use camera::{BenchCamera, CameraReport};
pub use forward::{bench_cpu, bench_gpu};
pub use pairs::PairStats;
pub use parse::{parse_count, parse_resolution};
pub use plot::plot_sweep;
pub use report::{summary_table, to_csv, to_json, BenchReport};

use crate::gpu::Traffic;
use serde::Serialize;

/// min / median / p95 / max of a series of samples, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Stat {
    /// Smallest sample.
    pub min: f64,
    /// Median sample.
    pub median: f64,
    /// 95th percentile (nearest rank).
    pub p95: f64,
    /// Largest sample.
    pub max: f64,
}

impl Stat {
    /// Summarises samples (at least one).
    pub fn of(samples: &[f64]) -> Stat {
        let mut v = samples.to_vec();
        v.sort_by(|a, b| a.total_cmp(b));
        if v.is_empty() {
            return Stat::default();
        }
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Stat {
            min: v[0],
            median: at(0.5),
            p95: at(0.95),
            max: v[v.len() - 1],
        }
    }
}

/// One stage's timing.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StageReport {
    /// Stage name (`preprocess`, `order`, `scan`, `keys`, `sort`, `ranges`, `blend`,
    /// `readback` on the GPU; `preprocess`, `keys`, `sort`, `ranges`, `blend` on the CPU).
    pub name: String,
    /// Milliseconds.
    #[serde(flatten)]
    pub ms: Stat,
    /// Device memory the stage reads and writes in one frame, counted from the frame's
    /// counts and the records its shaders load and store
    /// ([`crate::render::frame_traffic`]); absent where there is no model (the CPU
    /// reference, the feature blend, the shader, the backward pass).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bytes: Option<Traffic>,
}

impl StageReport {
    /// The bandwidth the stage reached at least: its bytes over its median time, in GB/s
    /// (10^9 bytes a second).
    pub fn gb_per_s(&self) -> Option<f64> {
        let bytes = self.bytes?.total() as f64;
        (self.ms.median > 0.0).then(|| bytes / (self.ms.median * 1e-3) / 1e9)
    }
}

/// Version of the JSON layout written by [`to_json`]; raised when a field changes meaning
/// or disappears.
pub const JSON_SCHEMA_VERSION: u32 = 1;

/// Appends one frame's stage times to per-stage sample lists (created on first use).
pub(crate) fn push_stage_samples<'a>(
    samples: &mut Vec<(String, Vec<f64>)>,
    stages: impl IntoIterator<Item = (&'a str, f64)>,
) {
    for (k, (stage, ms)) in stages.into_iter().enumerate() {
        if samples.len() <= k {
            samples.push((stage.to_string(), Vec::new()));
        }
        samples[k].1.push(ms);
    }
}

/// Summarises per-stage sample lists.
pub(crate) fn stage_reports(samples: Vec<(String, Vec<f64>)>) -> Vec<StageReport> {
    samples
        .into_iter()
        .map(|(name, v)| StageReport {
            name,
            ms: Stat::of(&v),
            bytes: None,
        })
        .collect()
}

pub(crate) fn per_second(count: u64, ms: f64) -> f64 {
    if ms > 0.0 {
        count as f64 / (ms / 1e3)
    } else {
        0.0
    }
}
