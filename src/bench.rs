//! Benchmarks: per-stage timing reports (GPU timestamps or CPU wall clock), scaling sweeps,
//! CSV/JSON output and SVG plots. Used by `vksplat bench`; warm-up frames are discarded and
//! every figure is measured.

use crate::camera::Camera;
use crate::cpu::{self, Projected, RenderOptions};
use crate::gpu::GpuResult;
use crate::render::GpuRenderer;
use crate::scene::ActivatedScene;
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

/// A benchmark of one scene and camera.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchReport {
    /// Scene name.
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: u64,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `gpu` or `cpu`.
    pub renderer: String,
    /// Device name (the CPU reference reports its thread count).
    pub device: String,
    /// Driver name and version.
    pub driver: String,
    /// Vulkan version of the device.
    pub vulkan: String,
    /// Blend kernel (GPU only).
    pub blend_kernel: Option<String>,
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
    /// Pixel-Gaussian evaluations of one frame's blend (per pixel, the Gaussians of its
    /// tile's list up to the one that finished it).
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
        let mut out = format!(
            "scene {}: {} Gaussians, {}x{}\ndevice: {} ({}), driver {}, Vulkan {}{}\n",
            self.scene,
            self.gaussians,
            self.width,
            self.height,
            self.device,
            self.renderer,
            self.driver,
            self.vulkan,
            self.blend_kernel
                .as_ref()
                .map_or(String::new(), |k| format!(", blend kernel {k}"))
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
        if self.renderer == "gpu" {
            out += &format!(
                "device memory: peak {} B ({:.1} B per Gaussian)\n",
                self.device_bytes_peak, self.device_bytes_per_gaussian
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
    cam: &Camera,
    frames: usize,
    warmup: usize,
) -> GpuResult<BenchReport> {
    let opts = RenderOptions::default();
    let gpu_scene = renderer.upload(scene)?;
    let mut stage_samples: Vec<(String, Vec<f64>)> = Vec::new();
    let (mut frame, mut wall) = (Vec::new(), Vec::new());
    let mut peak = 0u64;
    for i in 0..warmup + frames {
        let t = std::time::Instant::now();
        std::hint::black_box(renderer.render(&gpu_scene, cam, &opts)?);
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
    let (_, inter) = renderer.render_with_intermediates(&gpu_scene, cam, &opts)?;
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
    let evaluations = cpu::count_evaluations(&projected, cam, |x, y| {
        let [a, b] = inter.ranges[((y / size) * bins_x + x / size) as usize];
        &inter.values[a as usize..b as usize]
    });
    let info = renderer.ctx().info();
    let stages = stage_reports(stage_samples);
    let wall_ms = Stat::of(&wall);
    let mut report = BenchReport {
        scene: name.to_string(),
        gaussians: scene.len() as u64,
        width: cam.width,
        height: cam.height,
        renderer: "gpu".into(),
        device: info.name.clone(),
        driver: info.driver.clone(),
        vulkan: info.api_version.clone(),
        blend_kernel: Some(format!("{:?}", renderer.blend_kernel())),
        frames,
        warmup,
        stages,
        frame_ms: Stat::of(&frame),
        wall_ms,
        fps: per_second(1, wall_ms.median),
        visible: u64::from(stats.visible),
        pairs: stats.pairs,
        key_bits: stats.key_bits,
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
    cam: &Camera,
    frames: usize,
    warmup: usize,
) -> BenchReport {
    let opts = RenderOptions::default();
    let mut stage_samples: Vec<(String, Vec<f64>)> = Vec::new();
    let (mut frame, mut wall) = (Vec::new(), Vec::new());
    let mut pairs = 0;
    for i in 0..warmup + frames {
        let t = std::time::Instant::now();
        let (_, tm) = cpu::render_timed(scene, cam, &opts);
        let elapsed = t.elapsed().as_secs_f64() * 1e3;
        if i < warmup {
            continue;
        }
        pairs = tm.pairs;
        wall.push(elapsed);
        frame.push(tm.total);
        push_stage_samples(&mut stage_samples, tm.stages());
    }
    let projected = cpu::preprocess(scene, cam, scene.sh_degree, false);
    let (keys, values) = cpu::tile_keys(&projected, cam);
    let (sorted_keys, sorted_values) = cpu::sort_pairs(&keys, &values);
    let (tx, ty) = cam.tile_grid();
    let ranges = cpu::tile_ranges(&sorted_keys, (tx * ty) as usize);
    let evaluations = cpu::count_evaluations(&projected, cam, |x, y| {
        let [a, b] = ranges[((y / 16) * tx + x / 16) as usize];
        &sorted_values[a as usize..b as usize]
    });
    let visible = projected.iter().filter(|p| p.tiles_touched() > 0).count() as u64;
    let stages = stage_reports(stage_samples);
    let wall_ms = Stat::of(&wall);
    let mut report = BenchReport {
        scene: name.to_string(),
        gaussians: scene.len() as u64,
        width: cam.width,
        height: cam.height,
        renderer: "cpu".into(),
        device: format!("CPU reference ({} threads)", rayon::current_num_threads()),
        driver: "-".into(),
        vulkan: "-".into(),
        blend_kernel: None,
        frames,
        warmup,
        stages,
        frame_ms: Stat::of(&frame),
        wall_ms,
        fps: per_second(1, wall_ms.median),
        visible,
        pairs,
        key_bits: crate::render::key_bits(tx * ty),
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

/// An SVG with the per-stage medians of a sweep stacked against `x` (one panel per axis
/// that varies: Gaussians and megapixels) and a per-stage breakdown of the last report.
pub fn plot_sweep(reports: &[BenchReport]) -> Result<String, String> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| format!("cannot draw the plot: {e}");
    let mut svg = String::new();
    {
        let stage_names: Vec<String> = reports
            .first()
            .map(|r| r.stages.iter().map(|s| s.name.clone()).collect())
            .unwrap_or_default();
        let root = SVGBackend::with_string(&mut svg, (1500, 500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let panels = root.split_evenly((1, 3));
        let palette = [
            &RED,
            &BLUE,
            &GREEN,
            &MAGENTA,
            &CYAN,
            &BLACK,
            &YELLOW,
            &RGBColor(255, 140, 0),
        ];
        let stacked = |area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
                       title: &str,
                       xlabel: &str,
                       xs: Vec<(f64, &BenchReport)>|
         -> Result<(), String> {
            if xs.len() < 2 {
                area.titled(
                    &format!("{title}: needs two or more points"),
                    ("sans-serif", 16),
                )
                .map_err(|e| err(&e))?;
                return Ok(());
            }
            let xmin = xs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
            let xmax = xs.iter().map(|p| p.0).fold(0.0, f64::max);
            let ymax = xs.iter().map(|p| p.1.frame_ms.median).fold(0.0, f64::max) * 1.1;
            let mut chart = ChartBuilder::on(area)
                .caption(title, ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d((xmin..xmax).log_scale(), 0.0..ymax.max(1e-3))
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .x_desc(xlabel)
                .y_desc("ms (median, stacked)")
                .x_labels(6)
                .x_label_formatter(&|v| {
                    if *v >= 1000.0 {
                        format!("{v:.0e}")
                    } else {
                        format!("{v:.2}")
                    }
                })
                .light_line_style(WHITE)
                .draw()
                .map_err(|e| err(&e))?;
            for (k, name) in stage_names.iter().enumerate() {
                let colour = palette[k % palette.len()];
                let line: Vec<(f64, f64)> = xs
                    .iter()
                    .map(|(x, r)| {
                        (
                            *x,
                            r.stages
                                .iter()
                                .take(k + 1)
                                .map(|s| s.ms.median)
                                .sum::<f64>(),
                        )
                    })
                    .collect();
                chart
                    .draw_series(LineSeries::new(line, colour.stroke_width(2)))
                    .map_err(|e| err(&e))?
                    .label(name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 15, y)], colour.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| err(&e))?;
            Ok(())
        };
        // Panel 1: against Gaussians at the first resolution; panel 2: against pixels at the
        // first Gaussian count.
        let first = reports.first().ok_or_else(|| err(&"no reports"))?;
        let by_n: Vec<(f64, &BenchReport)> = reports
            .iter()
            .filter(|r| (r.width, r.height) == (first.width, first.height))
            .map(|r| (r.gaussians as f64, r))
            .collect();
        let by_px: Vec<(f64, &BenchReport)> = reports
            .iter()
            .filter(|r| r.gaussians == first.gaussians)
            .map(|r| ((r.width as f64 * r.height as f64) / 1e6, r))
            .collect();
        stacked(
            &panels[0],
            &format!("time vs Gaussians at {}x{}", first.width, first.height),
            "Gaussians",
            by_n,
        )?;
        stacked(
            &panels[1],
            &format!("time vs megapixels at {} Gaussians", first.gaussians),
            "megapixels",
            by_px,
        )?;
        // Panel 3: per-stage breakdown of the last (largest) point.
        let last = reports.last().ok_or_else(|| err(&"no reports"))?;
        let ymax = last.stages.iter().map(|s| s.ms.median).fold(0.0, f64::max) * 1.1;
        let mut chart = ChartBuilder::on(&panels[2])
            .caption(
                format!(
                    "stages: {} Gaussians, {}x{}",
                    last.gaussians, last.width, last.height
                ),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((0..last.stages.len()).into_segmented(), 0.0..ymax.max(1e-3))
            .map_err(|e| err(&e))?;
        let names: Vec<String> = last.stages.iter().map(|s| s.name.clone()).collect();
        chart
            .configure_mesh()
            .x_labels(names.len())
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) => names.get(*i).cloned().unwrap_or_default(),
                _ => String::new(),
            })
            .y_desc("ms (median)")
            .light_line_style(WHITE)
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(last.stages.iter().enumerate().map(|(i, s)| {
                let colour = palette[i % palette.len()].filled();
                Rectangle::new(
                    [
                        (SegmentValue::Exact(i), 0.0),
                        (SegmentValue::Exact(i + 1), s.ms.median),
                    ],
                    colour,
                )
            }))
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}
