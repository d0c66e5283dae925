//! The forward benchmarks: the Vulkan renderer ([`bench_gpu`], device timestamps per stage)
//! and the CPU reference renderer ([`bench_cpu`], wall clock per phase).

use super::camera::BenchCamera;
use super::pairs::{pair_stats, BinLists};
use super::report::BenchReport;
use super::{per_second, push_stage_samples, stage_reports, Stat};
use crate::core::model::{ActivatedScene, RenderOptions};
use crate::cpu::{self, Projected};
use crate::gpu::GpuResult;
use crate::render::GpuRenderer;
use crate::render::{frame_traffic, Readback};
use crate::render::{FrameRequest, Rendered};

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
            Some(f) => std::hint::black_box(
                renderer
                    .render(&FrameRequest::new(&gpu_scene, cam, opts).features(f))
                    .and_then(Rendered::into_frame)?,
            ),
            None => std::hint::black_box(
                renderer
                    .render(&FrameRequest::new(&gpu_scene, cam, opts))
                    .and_then(Rendered::into_frame)?,
            ),
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
    let (evaluations, pair_stats) = if stats.chunks > 1 {
        (0, None)
    } else {
        let (_, inter) = renderer
            .render(&FrameRequest::new(&gpu_scene, cam, opts).readback(Readback::Intermediates))
            .and_then(Rendered::into_intermediates)?;
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
        let evaluations =
            cpu::count_evaluations(&projected, cam, opts.kernel, opts.rules, |x, y| {
                let [a, b] = inter.ranges[((y / size) * bins_x + x / size) as usize];
                &inter.values[a as usize..b as usize]
            });
        let lists = BinLists {
            size,
            bins_x,
            ranges: &inter.ranges,
            values: &inter.values,
        };
        let visible = u64::from(stats.visible);
        let pairs = pair_stats(&projected, cam, opts.kernel, opts.rules, &lists, visible);
        (evaluations, Some(pairs))
    };
    let info = renderer.ctx().info();
    let mut stages = stage_reports(stage_samples);
    let traffic = frame_traffic(&gpu_scene, cam, opts, &stats, Readback::Float, false);
    for stage in stages.iter_mut() {
        stage.bytes = traffic
            .iter()
            .find(|(s, _)| s.name() == stage.name)
            .map(|&(_, t)| t);
    }
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
        blend_kernel: Some(renderer.blend_kernel_for(opts).to_string()),
        kernel: opts.kernel.to_string(),
        reproducible: opts.reproducible,
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
        pair_stats,
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
    let evaluations = cpu::count_evaluations(&projected, cam, opts.kernel, opts.rules, |x, y| {
        let [a, b] = ranges[((y / 16) * tx + x / 16) as usize];
        &sorted_values[a as usize..b as usize]
    });
    let visible = projected.iter().filter(|p| p.tiles_touched() > 0).count() as u64;
    let lists = BinLists {
        size: cpu::TILE_SIZE,
        bins_x: tx,
        ranges: &ranges,
        values: &sorted_values,
    };
    let pairs_of_frame = pair_stats(&projected, cam, opts.kernel, opts.rules, &lists, visible);
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
        reproducible: opts.reproducible,
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
        pair_stats: Some(pairs_of_frame),
    };
    report.sort_keys_per_s = per_second(report.pairs, report.median("sort"));
    report.blend_evaluations_per_s = per_second(evaluations, report.median("blend"));
    report
}
