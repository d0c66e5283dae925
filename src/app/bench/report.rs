//! The forward benchmark's report ([`BenchReport`]) and its forms: a text table, the JSON
//! document, the CSV rows and the one-line-per-run summary of a sweep.

use super::camera::{describe_camera, CameraReport};
use super::{PairStats, StageReport, Stat, JSON_SCHEMA_VERSION};
use serde::Serialize;

/// A benchmark of one scene and camera.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchReport {
    /// Scene name.
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: u64,
    /// The camera that was timed.
    pub camera: CameraReport,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `gpu` (the Vulkan pipeline) or `cpu` (the CPU reference renderer).
    pub renderer: String,
    /// Device name (the CPU reference reports its thread count).
    pub device: String,
    /// Driver name and version.
    pub driver: String,
    /// Vulkan version of the device.
    pub vulkan: String,
    /// Blend kernel as `VERISPLAT_BLEND` names it (`shared`, `texel:2`; GPU only).
    pub blend_kernel: Option<String>,
    /// The alpha falloff rendered (`gaussian` or `power`, `--kernel`).
    pub kernel: String,
    /// Rendered in the reproducible mode (`--reproducible`; docs/reproducibility.md).
    pub reproducible: bool,
    /// Feature channels blended per frame (the `features` stage), 0 for colour only.
    pub feature_channels: usize,
    /// The scene was uploaded compact (SH, scales and rotations as fp16; `--compact`).
    pub compact: bool,
    /// Measured frames.
    pub frames: usize,
    /// Discarded warm-up frames.
    pub warmup: usize,
    /// Per stage, in pipeline order.
    pub stages: Vec<StageReport>,
    /// First timestamp to last (GPU) or the whole render (CPU), ms.
    pub frame_ms: Stat,
    /// Wall clock per frame, ms.
    pub wall_ms: Stat,
    /// Frames per second at the median wall clock.
    pub fps: f64,
    /// Gaussians touching at least one tile.
    pub visible: u64,
    /// (tile, Gaussian) pairs sorted.
    pub pairs: u64,
    /// Key bits that order the pairs (32 depth bits + tile bits).
    pub key_bits: u32,
    /// Peak device bytes held by the renderer (scene + per-frame buffers), GPU only.
    pub device_bytes_peak: u64,
    /// `device_bytes_peak` per Gaussian.
    pub device_bytes_per_gaussian: f64,
    /// Pairs sorted per second at the median sort time.
    pub sort_keys_per_s: f64,
    /// Depth-ordered chunks each frame was keyed and blended in (1: at once; GPU only).
    pub chunks: u32,
    /// Pixel-Gaussian evaluations of one frame's blend (per pixel, the Gaussians of its
    /// tile's list up to the one that finished it); 0 when not counted (a frame in
    /// chunks, whose lists are not kept).
    pub blend_evaluations: u64,
    /// `blend_evaluations` per second at the median blend time.
    pub blend_evaluations_per_s: f64,
    /// How one frame's pairs fall per bin and how many of them can draw; absent when not
    /// counted (a frame in chunks, whose lists are not kept).
    pub pair_stats: Option<PairStats>,
}

impl BenchReport {
    /// Median of a stage by name (0 when absent).
    pub fn median(&self, stage: &str) -> f64 {
        self.stages
            .iter()
            .find(|s| s.name == stage)
            .map_or(0.0, |s| s.ms.median)
    }

    /// A human-readable table.
    pub fn to_text(&self) -> String {
        let renderer = if self.renderer == "gpu" {
            format!(
                "Vulkan pipeline on {}, driver {}, Vulkan {}{}",
                self.device,
                self.driver,
                self.vulkan,
                self.blend_kernel
                    .as_ref()
                    .map_or(String::new(), |k| format!(", blend kernel {k}"))
            )
        } else {
            self.device.clone()
        };
        let mut renderer = if self.kernel == "gaussian" {
            renderer
        } else {
            format!("{renderer}, {} kernel", self.kernel)
        };
        if self.reproducible {
            renderer += ", reproducible mode";
        }
        if self.feature_channels > 0 {
            renderer += &format!(", {} feature channels blended", self.feature_channels);
        }
        let mut out = format!(
            "scene {}: {} Gaussians\ncamera {} at {}x{}\nrenderer: {renderer}\n",
            self.scene,
            self.gaussians,
            describe_camera(&self.camera),
            self.width,
            self.height,
        );
        let traffic = self.stages.iter().any(|s| s.bytes.is_some());
        out += &format!(
            "{:<12} {:>9} {:>9} {:>9} {:>9}{}\n",
            "stage",
            "min ms",
            "median",
            "p95",
            "max",
            if traffic {
                format!(" {:>10} {:>8}", "MB moved", "GB/s")
            } else {
                String::new()
            }
        );
        let frame_label = if self.renderer == "gpu" {
            "frame (GPU)"
        } else {
            "frame"
        };
        let rows = self
            .stages
            .iter()
            .map(|s| (s.name.as_str(), s.ms, moved(s)))
            .chain([
                (frame_label, self.frame_ms, String::new()),
                ("wall clock", self.wall_ms, String::new()),
            ]);
        for (name, s, moved) in rows {
            out += &format!(
                "{name:<12} {:>9.3} {:>9.3} {:>9.3} {:>9.3}{moved}\n",
                s.min, s.median, s.p95, s.max
            );
        }
        if traffic {
            out += "MB moved: the bytes each stage's shaders read and write in device memory, counted from the frame's counts (caches not modelled); GB/s at the median\n";
        }
        out += &format!(
            "frames/s (median wall clock) {:.2}\nvisible Gaussians {}, tile pairs {}, key bits {}\nsort {:.3e} keys/s, blend {} pixel-Gaussian evaluations, {:.3e}/s\n",
            self.fps, self.visible, self.pairs, self.key_bits, self.sort_keys_per_s, self.blend_evaluations, self.blend_evaluations_per_s
        );
        if let Some(p) = &self.pair_stats {
            out += &format!(
                "pairs: {:.2} per visible Gaussian; per {s}x{s} bin ({} bins) max {}, p99 {}; {} can draw (some pixel centre gets alpha >= 1/255), {:.3}x sorted per drawing pair\n",
                p.per_visible,
                p.bins,
                p.per_bin_max,
                p.per_bin_p99,
                p.drawing,
                self.pairs as f64 / p.drawing.max(1) as f64,
                s = p.bin_size,
            );
        }
        if self.chunks > 1 {
            out += &format!(
                "frame keyed and blended in {} depth-ordered chunks (blend evaluations not counted)\n",
                self.chunks
            );
        }
        if self.renderer == "gpu" {
            out += &format!(
                "device memory: peak {} B ({:.1} B per Gaussian){}\n",
                self.device_bytes_peak,
                self.device_bytes_per_gaussian,
                if self.compact {
                    ", compact scene (fp16 SH, scales, rotations)"
                } else {
                    ""
                }
            );
        }
        out
    }
}

/// A stage's MB moved and GB/s columns (blank without a model).
fn moved(s: &StageReport) -> String {
    match (s.bytes, s.gb_per_s()) {
        (Some(b), Some(rate)) => format!(" {:>10.2} {:>8.2}", b.total() as f64 / 1e6, rate),
        (Some(b), None) => format!(" {:>10.2} {:>8}", b.total() as f64 / 1e6, "-"),
        _ => String::new(),
    }
}

/// The JSON of a benchmark run, one layout for one report and for a sweep:
/// `{"schema_version": 1, "runs": [report, ...]}`, each report as [`BenchReport`]
/// serialises (times in ms as `{min, median, p95, max}`, the camera as [`CameraReport`]).
pub fn to_json(reports: &[BenchReport]) -> String {
    #[derive(Serialize)]
    struct Document<'a> {
        schema_version: u32,
        runs: &'a [BenchReport],
    }
    let doc = Document {
        schema_version: JSON_SCHEMA_VERSION,
        runs: reports,
    };
    // Serialising plain data to a string cannot fail.
    serde_json::to_string_pretty(&doc).unwrap_or_default() + "\n"
}

/// One line per report: Gaussians, resolution, median frame and wall-clock times,
/// frames/s, the sort and blend medians and the pairs sorted; for the end of a sweep.
pub fn summary_table(reports: &[BenchReport]) -> String {
    let mut out = format!(
        "{:>11} {:>11} {:>10} {:>10} {:>9} {:>9} {:>9} {:>12}\n",
        "Gaussians",
        "resolution",
        "frame ms",
        "wall ms",
        "frames/s",
        "sort ms",
        "blend ms",
        "tile pairs"
    );
    for r in reports {
        out += &format!(
            "{:>11} {:>11} {:>10.3} {:>10.3} {:>9.2} {:>9.3} {:>9.3} {:>12}\n",
            r.gaussians,
            format!("{}x{}", r.width, r.height),
            r.frame_ms.median,
            r.wall_ms.median,
            r.fps,
            r.median("sort"),
            r.median("blend"),
            r.pairs
        );
    }
    out
}

/// CSV of reports: one row per (report, stage) plus `frame` and `wall` rows.
pub fn to_csv(reports: &[BenchReport]) -> String {
    let mut out = String::from(
        "scene,gaussians,width,height,renderer,stage,min_ms,median_ms,p95_ms,max_ms,pairs,visible,sort_keys_per_s,blend_evaluations_per_s,device_bytes_peak,bytes_read,bytes_written\n",
    );
    for r in reports {
        let rows = r
            .stages
            .iter()
            .map(|s| (s.name.as_str(), s.ms, s.bytes))
            .chain([("frame", r.frame_ms, None), ("wall", r.wall_ms, None)]);
        for (stage, s, bytes) in rows {
            let (read, written) = bytes.map_or((String::new(), String::new()), |b| {
                (b.read.to_string(), b.written.to_string())
            });
            out += &format!(
                "{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{},{},{:.1},{:.1},{},{read},{written}\n",
                r.scene.replace(',', ";"),
                r.gaussians,
                r.width,
                r.height,
                r.renderer,
                stage,
                s.min,
                s.median,
                s.p95,
                s.max,
                r.pairs,
                r.visible,
                r.sort_keys_per_s,
                r.blend_evaluations_per_s,
                r.device_bytes_peak
            );
        }
    }
    out
}
