//! Benchmarks: per-stage timing reports (GPU timestamps or CPU wall clock), scaling sweeps,
//! CSV/JSON output and SVG plots. Used by `vksplat bench`; warm-up frames are discarded and
//! every figure is measured.

use crate::camera::Camera;
use crate::cpu::{self, Projected};
use crate::gpu::GpuResult;
use crate::model::{ActivatedScene, RenderOptions};
use crate::render::GpuRenderer;
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
}

/// Version of the JSON layout written by [`to_json`]; raised when a field changes meaning
/// or disappears.
pub const JSON_SCHEMA_VERSION: u32 = 1;

/// The camera a benchmark times and where it comes from.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchCamera {
    /// The camera, at the benchmarked resolution.
    pub camera: Camera,
    /// Its index in the camera file, if it comes from one.
    pub index: Option<usize>,
    /// Where it comes from: the camera file described (`path (format, N cameras)`), or
    /// `the default camera` (framing the scene).
    pub source: String,
}

/// Which camera was timed, as reported.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CameraReport {
    /// The camera's name (`img_name` of a cameras.json, `default` for the default camera).
    pub name: String,
    /// Its index in the camera file (`null` for the default camera).
    pub index: Option<usize>,
    /// The camera file described (`path (format, N cameras)`), or `the default camera`.
    pub source: String,
}

impl BenchCamera {
    fn report(&self) -> CameraReport {
        CameraReport {
            name: self.camera.name.clone(),
            index: self.index,
            source: self.source.clone(),
        }
    }

    /// `"name" (index 3 of cameras.json)` or `"default" (default camera)`.
    pub fn describe(&self) -> String {
        describe_camera(&self.report())
    }
}

fn describe_camera(c: &CameraReport) -> String {
    match c.index {
        Some(i) => format!("\"{}\" (camera {i} of {})", c.name, c.source),
        None => format!("\"{}\" ({})", c.name, c.source),
    }
}

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
    /// Blend kernel as `VKSPLAT_BLEND` names it (`shared`, `texel:2`; GPU only).
    pub blend_kernel: Option<String>,
    /// The alpha falloff rendered (`gaussian` or `power`, `--kernel`).
    pub kernel: String,
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
        out += &format!(
            "{:<12} {:>9} {:>9} {:>9} {:>9}\n",
            "stage", "min ms", "median", "p95", "max"
        );
        let frame_label = if self.renderer == "gpu" {
            "frame (GPU)"
        } else {
            "frame"
        };
        let rows = self
            .stages
            .iter()
            .map(|s| (s.name.as_str(), s.ms))
            .chain([(frame_label, self.frame_ms), ("wall clock", self.wall_ms)]);
        for (name, s) in rows {
            out += &format!(
                "{name:<12} {:>9.3} {:>9.3} {:>9.3} {:>9.3}\n",
                s.min, s.median, s.p95, s.max
            );
        }
        out += &format!(
            "frames/s (median wall clock) {:.2}\nvisible Gaussians {}, tile pairs {}, key bits {}\nsort {:.3e} keys/s, blend {} pixel-Gaussian evaluations, {:.3e}/s\n",
            self.fps, self.visible, self.pairs, self.key_bits, self.sort_keys_per_s, self.blend_evaluations, self.blend_evaluations_per_s
        );
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

/// Appends one frame's stage times to per-stage sample lists (created on first use).
fn push_stage_samples<'a>(
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
fn stage_reports(samples: Vec<(String, Vec<f64>)>) -> Vec<StageReport> {
    samples
        .into_iter()
        .map(|(name, v)| StageReport {
            name,
            ms: Stat::of(&v),
        })
        .collect()
}

fn per_second(count: u64, ms: f64) -> f64 {
    if ms > 0.0 {
        count as f64 / (ms / 1e3)
    } else {
        0.0
    }
}

/// Benchmarks the GPU renderer: `warmup` discarded frames, then `frames` measured ones,
/// then one untimed frame whose intermediates give the blend's evaluation count.
pub fn bench_gpu(
    renderer: &mut GpuRenderer,
    scene: &ActivatedScene,
    name: &str,
    camera: &BenchCamera,
    opts: &RenderOptions,
    frames: usize,
    warmup: usize,
) -> GpuResult<BenchReport> {
    let cam = &camera.camera;
    let gpu_scene = renderer.upload(scene)?;
    // A scene with feature channels is benchmarked with its feature blend.
    let gpu_features = if scene.feature_count > 0 {
        Some(renderer.upload_features(scene)?)
    } else {
        None
    };
    let mut stage_samples: Vec<(String, Vec<f64>)> = Vec::new();
    let (mut frame, mut wall) = (Vec::new(), Vec::new());
    let mut peak = 0u64;
    for i in 0..warmup + frames {
        let t = std::time::Instant::now();
        match &gpu_features {
            Some(f) => std::hint::black_box(renderer.render_features(&gpu_scene, f, cam, opts)?),
            None => std::hint::black_box(renderer.render(&gpu_scene, cam, opts)?),
        };
        let elapsed = t.elapsed().as_secs_f64() * 1e3;
        peak = peak.max(renderer.ctx().live_allocations().1);
        if i < warmup {
            continue;
        }
        wall.push(elapsed);
        let tm = renderer.timings();
        frame.push(tm.total);
        push_stage_samples(&mut stage_samples, tm.stages());
    }
    let stats = renderer.stats().clone();
    // Counted from one more frame's lists, which a frame in chunks does not keep.
    let evaluations = if stats.chunks > 1 {
        0
    } else {
        let (_, inter) = renderer.render_with_intermediates(&gpu_scene, cam, opts)?;
        let projected: Vec<Projected> = inter
            .splats
            .iter()
            .map(|s| Projected {
                mean2d: [s.mean_opacity_bound[0], s.mean_opacity_bound[1]],
                opacity: s.mean_opacity_bound[2],
                conic: [s.conic_depth[0], s.conic_depth[1], s.conic_depth[2]],
                ..Default::default()
            })
            .collect();
        let (bins_x, size) = (inter.bins.0, inter.bin_size);
        cpu::count_evaluations(&projected, cam, opts.kernel, |x, y| {
            let [a, b] = inter.ranges[((y / size) * bins_x + x / size) as usize];
            &inter.values[a as usize..b as usize]
        })
    };
    let info = renderer.ctx().info();
    let stages = stage_reports(stage_samples);
    let wall_ms = Stat::of(&wall);
    let mut report = BenchReport {
        scene: name.to_string(),
        gaussians: scene.len() as u64,
        camera: camera.report(),
        width: cam.width,
        height: cam.height,
        renderer: "gpu".into(),
        device: info.name.clone(),
        driver: info.driver.clone(),
        vulkan: info.api_version.clone(),
        blend_kernel: Some(renderer.blend_kernel().to_string()),
        kernel: opts.kernel.to_string(),
        feature_channels: scene.feature_count,
        compact: gpu_scene.is_compact(),
        frames,
        warmup,
        stages,
        frame_ms: Stat::of(&frame),
        wall_ms,
        fps: per_second(1, wall_ms.median),
        visible: u64::from(stats.visible),
        pairs: stats.pairs,
        key_bits: stats.key_bits,
        chunks: stats.chunks,
        device_bytes_peak: peak,
        device_bytes_per_gaussian: peak as f64 / scene.len().max(1) as f64,
        sort_keys_per_s: 0.0,
        blend_evaluations: evaluations,
        blend_evaluations_per_s: 0.0,
    };
    report.sort_keys_per_s = per_second(report.pairs, report.median("sort"));
    report.blend_evaluations_per_s = per_second(evaluations, report.median("blend"));
    Ok(report)
}

/// Benchmarks the CPU reference renderer (wall clock per phase).
pub fn bench_cpu(
    scene: &ActivatedScene,
    name: &str,
    camera: &BenchCamera,
    opts: &RenderOptions,
    frames: usize,
    warmup: usize,
) -> BenchReport {
    let cam = &camera.camera;
    let mut stage_samples: Vec<(String, Vec<f64>)> = Vec::new();
    let (mut frame, mut wall) = (Vec::new(), Vec::new());
    let mut pairs = 0;
    for i in 0..warmup + frames {
        let t = std::time::Instant::now();
        let (_, tm) = if scene.feature_count > 0 {
            cpu::render_features_timed(scene, cam, opts)
        } else {
            cpu::render_timed(scene, cam, opts)
        };
        let elapsed = t.elapsed().as_secs_f64() * 1e3;
        if i < warmup {
            continue;
        }
        pairs = tm.pairs;
        wall.push(elapsed);
        frame.push(tm.total);
        push_stage_samples(&mut stage_samples, tm.stages());
    }
    let projected = cpu::preprocess(scene, cam, opts);
    let (keys, values) = cpu::tile_keys(&projected, cam);
    let (sorted_keys, sorted_values) = cpu::sort_pairs(&keys, &values);
    let (tx, ty) = cam.tile_grid();
    let ranges = cpu::tile_ranges(&sorted_keys, (tx * ty) as usize);
    let evaluations = cpu::count_evaluations(&projected, cam, opts.kernel, |x, y| {
        let [a, b] = ranges[((y / 16) * tx + x / 16) as usize];
        &sorted_values[a as usize..b as usize]
    });
    let visible = projected.iter().filter(|p| p.tiles_touched() > 0).count() as u64;
    let stages = stage_reports(stage_samples);
    let wall_ms = Stat::of(&wall);
    let mut report = BenchReport {
        scene: name.to_string(),
        gaussians: scene.len() as u64,
        camera: camera.report(),
        width: cam.width,
        height: cam.height,
        renderer: "cpu".into(),
        device: format!("CPU reference ({} threads)", rayon::current_num_threads()),
        driver: "-".into(),
        vulkan: "-".into(),
        blend_kernel: None,
        kernel: opts.kernel.to_string(),
        feature_channels: scene.feature_count,
        compact: false,
        frames,
        warmup,
        stages,
        frame_ms: Stat::of(&frame),
        wall_ms,
        fps: per_second(1, wall_ms.median),
        visible,
        pairs,
        key_bits: crate::render::key_bits(tx * ty),
        chunks: 1,
        device_bytes_peak: 0,
        device_bytes_per_gaussian: 0.0,
        sort_keys_per_s: 0.0,
        blend_evaluations: evaluations,
        blend_evaluations_per_s: 0.0,
    };
    report.sort_keys_per_s = per_second(report.pairs, report.median("sort"));
    report.blend_evaluations_per_s = per_second(evaluations, report.median("blend"));
    report
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
        "scene,gaussians,width,height,renderer,stage,min_ms,median_ms,p95_ms,max_ms,pairs,visible,sort_keys_per_s,blend_evaluations_per_s,device_bytes_peak\n",
    );
    for r in reports {
        let rows = r
            .stages
            .iter()
            .map(|s| (s.name.as_str(), s.ms))
            .chain([("frame", r.frame_ms), ("wall", r.wall_ms)]);
        for (stage, s) in rows {
            out += &format!(
                "{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{},{},{:.1},{:.1},{}\n",
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

/// Parses a resolution: `720p`, `1080p`, `1440p`, `4k` or `WxH`.
pub fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "720p" => Ok((1280, 720)),
        "1080p" => Ok((1920, 1080)),
        "1440p" => Ok((2560, 1440)),
        "4k" | "2160p" => Ok((3840, 2160)),
        other => {
            let (w, h) = other.split_once('x').ok_or_else(|| {
                format!("unknown resolution {s:?}; use 720p, 1080p, 1440p, 4k or WxH")
            })?;
            let parse = |v: &str| {
                v.parse::<u32>().map_err(|_| {
                    format!("unknown resolution {s:?}; use 720p, 1080p, 1440p, 4k or WxH")
                })
            };
            Ok((parse(w)?, parse(h)?))
        }
    }
}

/// Parses a Gaussian count such as `1e5`, `250000` or `2.5e5`.
pub fn parse_count(s: &str) -> Result<usize, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of Gaussians"))?;
    if !(1.0..=1e9).contains(&v) || v.fract() != 0.0 {
        return Err(format!(
            "{s:?} is not a whole number of Gaussians between 1 and 1e9"
        ));
    }
    Ok(v as usize)
}

/// Stage and series colours: Tableau 10 without its yellow, readable on white and told
/// apart by most colour-blind readers.
const PALETTE: [(u8, u8, u8); 9] = [
    (78, 121, 167),
    (242, 142, 43),
    (225, 87, 89),
    (118, 183, 178),
    (89, 161, 79),
    (176, 122, 161),
    (255, 157, 167),
    (156, 117, 95),
    (186, 176, 172),
];

fn palette(k: usize) -> plotters::style::RGBColor {
    let (r, g, b) = PALETTE[k % PALETTE.len()];
    plotters::style::RGBColor(r, g, b)
}

fn draw_err(e: impl std::fmt::Display) -> String {
    format!("cannot draw the plot: {e}")
}

/// `1k`, `250k`, `1M`, `2.5M`: a Gaussian count for an axis label.
fn count_label(v: f64) -> String {
    let (scaled, unit) = if v >= 1e6 {
        (v / 1e6, "M")
    } else if v >= 1e3 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    let text = format!("{scaled:.2}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    format!("{text}{unit}")
}

/// Three significant digits at most: `0.058`, `0.23`, `2.07`, `8.29`, `33.2`.
fn value_label(v: f64) -> String {
    if v <= 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.log10().floor() as i32).clamp(0, 6) as usize;
    let text = format!("{v:.digits$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// Tick values for a logarithmic axis over `[lo, hi]`: 1, 2, 5 times powers of ten, or
/// denser steps (1, 1.5, 2, 3, 5, 7) when that gives fewer than three ticks.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
        return Vec::new();
    }
    let mut ticks = Vec::new();
    for mantissas in [&[1.0, 2.0, 5.0][..], &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0][..]] {
        ticks.clear();
        let mut decade = 10f64.powi(lo.log10().floor() as i32);
        while decade <= hi {
            for m in mantissas {
                let t = decade * m;
                if t >= lo * (1.0 - 1e-9) && t <= hi * (1.0 + 1e-9) {
                    ticks.push(t);
                }
            }
            decade *= 10.0;
        }
        if ticks.len() >= 3 {
            break;
        }
    }
    ticks
}

/// One sweep axis: the reports along it, one series per value of the other axis.
struct SeriesGroup<'a> {
    /// Series label (`1280x720` or `10k Gaussians`) and its points, sorted by `x`.
    series: Vec<(String, Vec<(f64, &'a BenchReport)>)>,
}

impl<'a> SeriesGroup<'a> {
    fn x_values(&self) -> Vec<f64> {
        let mut xs: Vec<f64> = self
            .series
            .iter()
            .flat_map(|(_, pts)| pts.iter().map(|p| p.0))
            .collect();
        xs.sort_by(|a, b| a.total_cmp(b));
        xs.dedup();
        xs
    }
}

/// Groups `reports` into series: `key` names the series a report belongs to (the value
/// of the other axis) and `x` places it along this axis.
fn group<'a, K: PartialOrd + Copy>(
    reports: &'a [BenchReport],
    key: impl Fn(&BenchReport) -> K,
    label: impl Fn(&BenchReport) -> String,
    x: impl Fn(&BenchReport) -> f64,
) -> SeriesGroup<'a> {
    let mut keys: Vec<K> = Vec::new();
    for r in reports {
        if !keys.iter().any(|k| *k == key(r)) {
            keys.push(key(r));
        }
    }
    keys.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let series = keys
        .into_iter()
        .map(|k| {
            let mut pts: Vec<(f64, &BenchReport)> = reports
                .iter()
                .filter(|r| key(r) == k)
                .map(|r| (x(r), r))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let name = pts.first().map(|p| label(p.1)).unwrap_or_default();
            (name, pts)
        })
        .collect();
    SeriesGroup { series }
}

type Area<'b> =
    plotters::drawing::DrawingArea<plotters::prelude::SVGBackend<'b>, plotters::coord::Shift>;

/// How a legend entry is drawn.
enum Swatch {
    /// A filled square (a stacked stage).
    Fill,
    /// A line with a dot (a series).
    Line,
    /// A dashed black line (the whole frame).
    Dashed,
}

/// Draws a legend into its own area, so it never covers data.
fn draw_legend(
    area: &Area,
    title: &str,
    entries: &[(String, plotters::style::RGBColor, Swatch)],
) -> Result<(), String> {
    use plotters::prelude::*;
    let font = ("sans-serif", 14).into_font();
    area.draw(&Text::new(
        title.to_string(),
        (6, 8),
        font.clone().style(FontStyle::Bold),
    ))
    .map_err(draw_err)?;
    for (i, (label, colour, swatch)) in entries.iter().enumerate() {
        let y = 34 + 22 * i as i32;
        match swatch {
            Swatch::Fill => area
                .draw(&Rectangle::new([(8, y), (24, y + 14)], colour.filled()))
                .map_err(draw_err)?,
            Swatch::Line => {
                area.draw(&PathElement::new(
                    vec![(6, y + 7), (26, y + 7)],
                    colour.stroke_width(2),
                ))
                .map_err(draw_err)?;
                area.draw(&Circle::new((16, y + 7), 3, colour.filled()))
                    .map_err(draw_err)?;
            }
            Swatch::Dashed => {
                for x in [6, 13, 20] {
                    area.draw(&PathElement::new(
                        vec![(x, y + 7), (x + 5, y + 7)],
                        BLACK.stroke_width(2),
                    ))
                    .map_err(draw_err)?;
                }
            }
        }
        area.draw(&Text::new(label.clone(), (32, y), font.clone()))
            .map_err(draw_err)?;
    }
    Ok(())
}

/// Frame time (median) against `x` on log axes, one line per series; the legend goes in
/// `legend`.
fn draw_overview(
    area: &Area,
    legend: &Area,
    title: &str,
    xlabel: &str,
    legend_title: &str,
    group: &SeriesGroup,
    x_label: &dyn Fn(&f64) -> String,
) -> Result<(), String> {
    use plotters::prelude::*;
    let xs = group.x_values();
    let (xmin, xmax) = (xs[0], xs[xs.len() - 1]);
    let ys: Vec<f64> = group
        .series
        .iter()
        .flat_map(|(_, pts)| pts.iter().map(|p| p.1.frame_ms.median))
        .filter(|v| *v > 0.0)
        .collect();
    let ymin = ys.iter().copied().fold(f64::INFINITY, f64::min).min(1e3);
    let ymax = ys.iter().copied().fold(0.0, f64::max).max(1e-3);
    let (ylo, yhi) = (ymin / 1.3, ymax * 1.3);
    let mut yticks = log_ticks(ylo, yhi);
    if yticks.len() < 2 {
        yticks = ys.clone();
    }
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(
            (xmin / 1.15..xmax * 1.15)
                .log_scale()
                .with_key_points(xs.clone()),
            (ylo..yhi).log_scale().with_key_points(yticks),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(format!("{xlabel} (log)"))
        .y_desc("frame ms (median, log)")
        .x_label_formatter(x_label)
        .y_label_formatter(&|v| value_label(*v))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(draw_err)?;
    let mut entries = Vec::new();
    for (k, (name, pts)) in group.series.iter().enumerate() {
        let colour = palette(k);
        let line: Vec<(f64, f64)> = pts
            .iter()
            .map(|(x, r)| (*x, r.frame_ms.median.max(ylo)))
            .collect();
        chart
            .draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))
            .map_err(draw_err)?;
        chart
            .draw_series(line.into_iter().map(|p| Circle::new(p, 4, colour.filled())))
            .map_err(draw_err)?;
        entries.push((name.clone(), colour, Swatch::Line));
    }
    draw_legend(legend, legend_title, &entries)
}

/// The median stage times of one series stacked as filled areas against `x`, with the
/// whole frame's median as a dashed line over them.
fn draw_stacked(
    area: &Area,
    title: &str,
    xlabel: &str,
    stages: &[String],
    pts: &[(f64, &BenchReport)],
    x_label: &dyn Fn(&f64) -> String,
) -> Result<(), String> {
    use plotters::prelude::*;
    if pts.len() < 2 {
        area.titled(
            &format!("{title}: one point, nothing to plot"),
            ("sans-serif", 15),
        )
        .map_err(draw_err)?;
        return Ok(());
    }
    let xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
    let (xmin, xmax) = (xs[0], xs[xs.len() - 1]);
    let ymax = pts
        .iter()
        .map(|(_, r)| {
            r.frame_ms
                .median
                .max(r.stages.iter().map(|s| s.ms.median).sum())
        })
        .fold(0.0, f64::max)
        * 1.08;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (xmin..xmax).log_scale().with_key_points(xs.clone()),
            0.0..ymax.max(1e-3),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(format!("{xlabel} (log)"))
        .y_desc("ms (median, stacked)")
        .x_label_formatter(x_label)
        .y_labels(6)
        .y_label_formatter(&|v| value_label(*v))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(draw_err)?;
    let mut lower = vec![0.0; pts.len()];
    for (k, name) in stages.iter().enumerate() {
        let upper: Vec<f64> = pts
            .iter()
            .zip(&lower)
            .map(|((_, r), lo)| lo + r.median(name))
            .collect();
        let mut outline: Vec<(f64, f64)> = xs.iter().copied().zip(upper.iter().copied()).collect();
        outline.extend(xs.iter().copied().zip(lower.iter().copied()).rev());
        let colour = palette(k);
        chart
            .draw_series(std::iter::once(Polygon::new(
                outline,
                colour.mix(0.9).filled(),
            )))
            .map_err(draw_err)?;
        chart
            .draw_series(LineSeries::new(
                xs.iter().copied().zip(upper.iter().copied()),
                colour.stroke_width(1),
            ))
            .map_err(draw_err)?;
        lower = upper;
    }
    // The whole frame (the stages plus the barriers between them), dashed.
    let frame: Vec<(f64, f64)> = pts.iter().map(|(x, r)| (*x, r.frame_ms.median)).collect();
    chart
        .draw_series(DashedLineSeries::new(frame, 6, 4, BLACK.stroke_width(2)))
        .map_err(draw_err)?;
    Ok(())
}

/// The median of each stage of one report as bars.
fn draw_breakdown(area: &Area, report: &BenchReport) -> Result<(), String> {
    use plotters::prelude::*;
    let ymax = report
        .stages
        .iter()
        .map(|s| s.ms.median)
        .fold(0.0, f64::max)
        * 1.1;
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "stages at {} Gaussians, {}x{}",
                count_label(report.gaussians as f64),
                report.width,
                report.height
            ),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (0..report.stages.len()).into_segmented(),
            0.0..ymax.max(1e-3),
        )
        .map_err(draw_err)?;
    let names: Vec<String> = report.stages.iter().map(|s| s.name.clone()).collect();
    chart
        .configure_mesh()
        .x_labels(names.len())
        .x_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) => names.get(*i).cloned().unwrap_or_default(),
            _ => String::new(),
        })
        .y_desc("ms (median)")
        .y_label_formatter(&|v| value_label(*v))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(draw_err)?;
    chart
        .draw_series(report.stages.iter().enumerate().map(|(i, s)| {
            Rectangle::new(
                [
                    (SegmentValue::Exact(i), 0.0),
                    (SegmentValue::Exact(i + 1), s.ms.median),
                ],
                palette(i).filled(),
            )
        }))
        .map_err(draw_err)?;
    Ok(())
}

/// An SVG of a sweep. Top row: the frame time against Gaussians (one line per
/// resolution) and against megapixels (one line per Gaussian count), on log axes, and the
/// per-stage breakdown of the largest point. Then, for every resolution, the stage times
/// stacked as filled areas against Gaussians, and for every Gaussian count, against
/// megapixels, each with the whole frame dashed over them. Legends sit beside the plots,
/// never on the data; ticks are at the measured values.
pub fn plot_sweep(reports: &[BenchReport]) -> Result<String, String> {
    use plotters::prelude::*;
    let largest = reports
        .iter()
        .max_by_key(|r| (r.gaussians, r.width as u64 * r.height as u64))
        .ok_or_else(|| draw_err("no reports"))?;
    let stages: Vec<String> = largest.stages.iter().map(|s| s.name.clone()).collect();
    let megapixels = |r: &BenchReport| r.width as f64 * r.height as f64 / 1e6;
    let resolution = |r: &BenchReport| format!("{}x{}", r.width, r.height);
    let by_gaussians = group(
        reports,
        |r| (r.width as u64 * r.height as u64, r.width),
        resolution,
        |r| r.gaussians as f64,
    );
    let by_pixels = group(
        reports,
        |r| r.gaussians,
        |r| format!("{} Gaussians", count_label(r.gaussians as f64)),
        megapixels,
    );
    let vary_gaussians = by_gaussians.x_values().len() > 1;
    let vary_pixels = by_pixels.x_values().len() > 1;
    let count_ticks = |v: &f64| count_label(*v);
    let mp_ticks = |v: &f64| value_label(*v);

    let legend_w = 190u32;
    let row_h = 420u32;
    let stacked_rows: Vec<(&SeriesGroup, &str)> = [
        (vary_gaussians, &by_gaussians, "Gaussians"),
        (vary_pixels, &by_pixels, "megapixels"),
    ]
    .into_iter()
    .filter(|(vary, _, _)| *vary)
    .map(|(_, g, label)| (g, label))
    .collect();
    let columns = stacked_rows
        .iter()
        .map(|(g, _)| g.series.len())
        .max()
        .unwrap_or(1)
        .max(2);
    let width = (legend_w + 360 * columns as u32).max(1500);
    let height = row_h * (1 + stacked_rows.len() as u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let (top, mut rest) = root.split_vertically(row_h);
        // Top row: overviews and the breakdown, each overview with its legend beside it.
        let overviews = [vary_gaussians, vary_pixels].iter().filter(|v| **v).count();
        let panel_w = width / (overviews as u32 + 1);
        let mut area = top;
        if vary_gaussians {
            let (panel, next) = area.split_horizontally(panel_w);
            let (plot, legend) = panel.split_horizontally(panel_w - 130);
            draw_overview(
                &plot,
                &legend.margin(40, 0, 0, 0),
                "frame time vs Gaussians",
                "Gaussians",
                "resolution",
                &by_gaussians,
                &count_ticks,
            )?;
            area = next;
        }
        if vary_pixels {
            let (panel, next) = area.split_horizontally(panel_w);
            let (plot, legend) = panel.split_horizontally(panel_w - 130);
            draw_overview(
                &plot,
                &legend.margin(40, 0, 0, 0),
                "frame time vs megapixels",
                "megapixels",
                "Gaussians",
                &by_pixels,
                &mp_ticks,
            )?;
            area = next;
        }
        draw_breakdown(&area, largest)?;
        // Stacked rows, one panel per series, and the stage legend in the right column.
        if !stacked_rows.is_empty() {
            let (plots, legend) = rest.split_horizontally(width - legend_w);
            let mut entries: Vec<(String, RGBColor, Swatch)> = stages
                .iter()
                .enumerate()
                .map(|(k, s)| (s.clone(), palette(k), Swatch::Fill))
                .collect();
            entries.reverse(); // top of the stack first
            entries.push(("whole frame".into(), BLACK, Swatch::Dashed));
            draw_legend(&legend.margin(40, 0, 0, 0), "stages", &entries)?;
            rest = plots;
        }
        let mut rows = rest
            .split_evenly((stacked_rows.len().max(1), 1))
            .into_iter();
        for (g, xlabel) in &stacked_rows {
            let Some(row) = rows.next() else { break };
            let panels = row.split_evenly((1, columns));
            for ((name, pts), panel) in g.series.iter().zip(&panels) {
                let (title, ticks): (String, &dyn Fn(&f64) -> String) = if *xlabel == "Gaussians" {
                    (format!("stages vs Gaussians at {name}"), &count_ticks)
                } else {
                    (format!("stages vs megapixels, {name}"), &mp_ticks)
                };
                draw_stacked(panel, &title, xlabel, &stages, pts, ticks)?;
            }
        }
        root.present().map_err(draw_err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_labels_are_short_and_exact_enough() {
        assert_eq!(count_label(300.0), "300");
        assert_eq!(count_label(1000.0), "1k");
        assert_eq!(count_label(1200.0), "1.2k");
        assert_eq!(count_label(250_000.0), "250k");
        assert_eq!(count_label(2.5e6), "2.5M");
        assert_eq!(value_label(0.003072), "0.00307");
        assert_eq!(value_label(0.9216), "0.922");
        assert_eq!(value_label(8.2944), "8.29");
        assert_eq!(value_label(100.0), "100");
        assert_eq!(value_label(0.0), "0");
    }

    #[test]
    fn log_ticks_give_at_least_three_values_inside_the_range() {
        assert_eq!(log_ticks(0.9, 60.0), [1.0, 2.0, 5.0, 10.0, 20.0, 50.0]);
        // Less than a decade: denser steps.
        assert_eq!(log_ticks(68.0, 330.0), [70.0, 100.0, 150.0, 200.0, 300.0]);
        assert!(log_ticks(0.0, 1.0).is_empty());
    }
}

/// Forward and backward timings of the differentiable rasterizer on one camera
/// (`vksplat bench --backward`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BackwardReport {
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
    /// Device name.
    pub device: String,
    /// Driver name and version.
    pub driver: String,
    /// The alpha falloff (`gaussian` or `power`).
    pub kernel: String,
    /// How per-pair gradients are summed (`deterministic`, `float-atomics`, `cas`).
    pub accumulation: String,
    /// Feature channels differentiated instead of the colour (0: the SH colour).
    pub feature_channels: usize,
    /// The neural shader the feature channels were shaded with, as its layer widths
    /// (e.g. "8-64-64-3"); its backward pass is the `shade_bwd` stage.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shader: Option<String>,
    /// Measured iterations (forward + backward each).
    pub iterations: usize,
    /// Discarded warm-up iterations.
    pub warmup: usize,
    /// Forward stages (device timestamps), in pipeline order.
    pub forward_stages: Vec<StageReport>,
    /// Forward frame, first timestamp to last, ms.
    pub forward_ms: Stat,
    /// Backward stages (device timestamps), in order.
    pub backward_stages: Vec<StageReport>,
    /// Backward pass, first timestamp to last, ms.
    pub backward_ms: Stat,
    /// Median backward over median forward.
    pub backward_over_forward: f64,
    /// Wall clock of a whole iteration (upload of the pixel gradients and read-back of the
    /// Gaussians' included), ms.
    pub iteration_wall_ms: Stat,
    /// (bin, Gaussian) pairs of the frame.
    pub pairs: u64,
    /// Device memory held at the peak (scene, frame and backward buffers), bytes.
    pub device_bytes_peak: u64,
    /// `device_bytes_peak` per Gaussian.
    pub device_bytes_per_gaussian: f64,
    /// Of which the backward pass's own buffers, bytes.
    pub backward_device_bytes: u64,
}

/// Times `iterations` forward + backward passes of `scene` from `camera` (after `warmup`
/// more) with fixed pseudo-random pixel gradients (those of an L1 loss have the same
/// cost: the pass's work does not depend on the values).
#[allow(clippy::too_many_arguments)]
pub fn bench_backward(
    renderer: &mut GpuRenderer,
    scene: &ActivatedScene,
    name: &str,
    camera: &BenchCamera,
    opts: &RenderOptions,
    shader: Option<&crate::mlp::Mlp>,
    iterations: usize,
    warmup: usize,
) -> GpuResult<BackwardReport> {
    use crate::model::grad::PixelGrads;
    let cam = &camera.camera;
    renderer.set_save_forward_state(true);
    let gpu_scene = renderer.upload(scene)?;
    // A scene with feature channels differentiates those (blended without a background).
    let k = scene.feature_count;
    let gpu_features = if k > 0 {
        Some(renderer.upload_features(scene)?)
    } else {
        None
    };
    let features = (k > 0).then_some((scene.features.as_slice(), k));
    // A shader turns the channels into colour: the pixels' gradients are the colour's.
    let gpu_shader = match (shader, &gpu_features) {
        (Some(m), Some(_)) => Some(crate::render::shade::GpuShader::new(renderer.ctx(), m)?),
        (Some(_), None) => {
            return Err(crate::gpu::GpuError::InvalidArgument(
                "a shader shades feature channels, and the scene has none".into(),
            ))
        }
        (None, _) => None,
    };
    let channels = if k > 0 && gpu_shader.is_none() { k } else { 3 };
    let pixels = (cam.width * cam.height) as usize;
    let mut rng = crate::gen::Rng(7);
    let scale = 1.0 / pixels as f32;
    let grads = PixelGrads {
        color: (0..pixels * channels)
            .map(|_| scale * rng.range(-1.0, 1.0))
            .collect(),
        alpha: (0..pixels).map(|_| scale * rng.range(-1.0, 1.0)).collect(),
        depth: Vec::new(),
    };
    let (mut fwd_samples, mut bwd_samples) = (Vec::new(), Vec::new());
    let (mut fwd, mut bwd, mut wall) = (Vec::new(), Vec::new(), Vec::new());
    let mut peak = 0u64;
    for i in 0..warmup + iterations {
        let t = std::time::Instant::now();
        match (&gpu_features, &gpu_shader, features) {
            (Some(f), Some(s), Some(values)) => {
                let frame = renderer.render_shaded(&gpu_scene, f, s, cam, opts)?;
                std::hint::black_box(renderer.backward_shaded(
                    &gpu_scene,
                    values,
                    s,
                    cam,
                    opts.background,
                    &frame,
                    &grads,
                )?);
            }
            (Some(f), _, _) => {
                let frame = renderer.render_features(&gpu_scene, f, cam, opts)?;
                std::hint::black_box(
                    renderer.backward_with_features(&gpu_scene, features, &frame, &grads)?,
                );
            }
            _ => {
                let frame = renderer.render(&gpu_scene, cam, opts)?;
                std::hint::black_box(renderer.backward(&gpu_scene, &frame, &grads)?);
            }
        }
        let elapsed = t.elapsed().as_secs_f64() * 1e3;
        peak = peak.max(renderer.ctx().live_allocations().1);
        if i < warmup {
            continue;
        }
        wall.push(elapsed);
        fwd.push(renderer.timings().total);
        push_stage_samples(&mut fwd_samples, renderer.timings().stages());
        bwd.push(renderer.backward_total_ms());
        let stages = renderer.backward_timings();
        push_stage_samples(
            &mut bwd_samples,
            stages.iter().map(|(s, ms)| (s.as_str(), *ms)),
        );
    }
    renderer.set_save_forward_state(false);
    let info = renderer.ctx().info();
    let (forward_ms, backward_ms) = (Stat::of(&fwd), Stat::of(&bwd));
    Ok(BackwardReport {
        scene: name.to_string(),
        gaussians: scene.len() as u64,
        camera: camera.report(),
        width: cam.width,
        height: cam.height,
        device: info.name.clone(),
        driver: info.driver.clone(),
        kernel: opts.kernel.to_string(),
        accumulation: renderer.gradient_accumulation().name().to_string(),
        feature_channels: k,
        shader: shader.map(|m| {
            let mut widths = vec![m.layers[0].inputs.to_string()];
            widths.extend(m.layers.iter().map(|l| l.outputs.to_string()));
            widths.join("-")
        }),
        iterations,
        warmup,
        forward_stages: stage_reports(fwd_samples),
        forward_ms,
        backward_stages: stage_reports(bwd_samples),
        backward_ms,
        backward_over_forward: if forward_ms.median > 0.0 {
            backward_ms.median / forward_ms.median
        } else {
            0.0
        },
        iteration_wall_ms: Stat::of(&wall),
        pairs: renderer.stats().pairs,
        device_bytes_peak: peak,
        device_bytes_per_gaussian: peak as f64 / scene.len().max(1) as f64,
        backward_device_bytes: renderer.backward_device_bytes(),
    })
}

impl BackwardReport {
    /// The report as text: both passes' stages (median and p95) and the ratio.
    pub fn to_text(&self) -> String {
        use std::fmt::Write;
        let mut t = String::new();
        let _ = writeln!(
            t,
            "{}: {} Gaussians, {}x{}, {} ({}), kernel {}, accumulation {}, {}, {} iterations",
            self.scene,
            self.gaussians,
            self.width,
            self.height,
            self.device,
            self.driver,
            self.kernel,
            self.accumulation,
            match (self.feature_channels, &self.shader) {
                (0, _) => "SH colour".to_string(),
                (k, None) => format!("{k} feature channels"),
                (k, Some(s)) => format!("{k} feature channels shaded by an MLP {s}"),
            },
            self.iterations
        );
        let _ = writeln!(t, "  {:<16} {:>10} {:>10}", "stage", "median ms", "p95 ms");
        for (pass, stages, total) in [
            ("forward", &self.forward_stages, &self.forward_ms),
            ("backward", &self.backward_stages, &self.backward_ms),
        ] {
            for s in stages {
                let _ = writeln!(
                    t,
                    "  {:<16} {:>10.2} {:>10.2}",
                    s.name, s.ms.median, s.ms.p95
                );
            }
            let _ = writeln!(
                t,
                "  {:<16} {:>10.2} {:>10.2}",
                format!("{pass} total"),
                total.median,
                total.p95
            );
        }
        let _ = writeln!(
            t,
            "  backward / forward: {:.2}x; iteration wall clock {:.1} ms (median)",
            self.backward_over_forward, self.iteration_wall_ms.median
        );
        let _ = write!(
            t,
            "  {} pairs; device memory {:.1} MB at the peak ({:.0} bytes per Gaussian), of which backward {:.1} MB",
            self.pairs,
            self.device_bytes_peak as f64 / 1e6,
            self.device_bytes_per_gaussian,
            self.backward_device_bytes as f64 / 1e6
        );
        t
    }
}

/// Backward reports as JSON: `{"schema_version": 1, "backward_runs": [...]}`.
pub fn backward_to_json(reports: &[BackwardReport]) -> String {
    #[derive(Serialize)]
    struct Document<'a> {
        schema_version: u32,
        backward_runs: &'a [BackwardReport],
    }
    let doc = Document {
        schema_version: JSON_SCHEMA_VERSION,
        backward_runs: reports,
    };
    serde_json::to_string_pretty(&doc).unwrap_or_default()
}
