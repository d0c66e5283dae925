//! Benchmarks of the building blocks on lavapipe or any Vulkan device: radix sort and
//! prefix sum on realistic key distributions at several sizes, the renderer's preprocess
//! and blend stages on synthetic scenes, and the CPU reference. Fixed seeds, warm-up runs
//! discarded, median and spread of GPU timestamps reported.
//!
//! `cargo bench --bench building_blocks` runs the full sizes. Under `cargo test` (no
//! `--bench` argument) it runs one small size of each, as a smoke test.

use std::time::Instant;
use verisplat::core::camera;
use verisplat::core::gen::{synthetic_scene, tile_depth_keys, Rng};
use verisplat::cpu::{self, RenderOptions};
use verisplat::gpu::sort::SortJob;
use verisplat::gpu::sync::{barrier, Access};
use verisplat::gpu::{
    ContextOptions, Count, GpuBuffer, GpuContext, GpuTimer, MemoryKind, RadixSort, Scan,
};
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};

fn stats(mut v: Vec<f64>) -> String {
    v.sort_by(|a, b| a.total_cmp(b));
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    format!(
        "median {:>9.3} ms  min {:>9.3}  p95 {:>9.3}  max {:>9.3}",
        at(0.5),
        v[0],
        at(0.95),
        v[v.len() - 1]
    )
}

fn time_gpu(
    ctx: &GpuContext,
    runs: usize,
    warmup: usize,
    mut record: impl FnMut(ash::vk::CommandBuffer) -> verisplat::gpu::GpuResult<()>,
    reset: impl Fn(),
) -> Vec<f64> {
    let mut timer = GpuTimer::new(ctx, "bench", 4).expect("timer");
    let mut out = Vec::new();
    for i in 0..warmup + runs {
        reset();
        ctx.submit_and_wait("bench", |cmd| {
            timer.reset(ctx, cmd);
            timer.stage(ctx, cmd, "work", &mut record)
        })
        .expect("submit");
        if i >= warmup {
            out.push(timer.read(ctx).expect("timestamps")[0].1);
        }
    }
    out
}

fn main() {
    let full = std::env::args().any(|a| a == "--bench");
    let (sizes, runs, warmup): (&[usize], usize, usize) = if full {
        (&[100_000, 1_000_000, 4_000_000], 7, 2)
    } else {
        (&[50_000], 1, 0)
    };
    let ctx = GpuContext::new(&ContextOptions::default()).expect("a Vulkan device");
    println!("device: {}", ctx.info());

    let sort = RadixSort::new(&ctx).expect("sort");
    let scan = Scan::new(&ctx).expect("scan");
    for &n in sizes {
        let keys: Vec<[u32; 2]> = tile_depth_keys(&mut Rng(42), n)
            .into_iter()
            .map(|k| [k as u32, (k >> 32) as u32])
            .collect();
        let values: Vec<u32> = (0..n as u32).collect();
        let key_buf = GpuBuffer::from_slice(&ctx, "keys", &keys).expect("keys");
        let value_buf = GpuBuffer::from_slice(&ctx, "values", &values).expect("values");
        let scratch = GpuBuffer::new(
            &ctx,
            "scratch",
            RadixSort::scratch_size(n as u32),
            MemoryKind::Device,
        )
        .expect("scratch");
        let reset = || {
            key_buf.upload(&ctx, &keys).expect("reset");
            value_buf.upload(&ctx, &values).expect("reset");
        };
        for (label, bits) in [("44-bit tile|depth", 0..44), ("12 tile bits only", 32..44)] {
            let t = time_gpu(
                &ctx,
                runs,
                warmup,
                |cmd| {
                    let job =
                        SortJob::new(&key_buf, &value_buf, &scratch, Count::Host(n as u32), 0)
                            .bits(bits.clone());
                    sort.record(&ctx, cmd, &job)?;
                    barrier(&ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                    Ok(())
                },
                reset,
            );
            let median = {
                let mut v = t.clone();
                v.sort_by(|a, b| a.total_cmp(b));
                v[v.len() / 2]
            };
            println!(
                "radix sort {n:>9} pairs, {label:<18}: {}  ({:.3e} keys/s)",
                stats(t),
                n as f64 / (median / 1e3)
            );
        }
        let counts: Vec<u32> = {
            let mut rng = Rng(7);
            (0..n).map(|_| (rng.next_u64() % 9) as u32).collect()
        };
        let input = GpuBuffer::from_slice(&ctx, "scan input", &counts).expect("input");
        let output =
            GpuBuffer::new(&ctx, "scan output", 4 * n as u64, MemoryKind::Device).expect("output");
        let total = GpuBuffer::new(&ctx, "total", 4, MemoryKind::Device).expect("total");
        let scan_scratch = GpuBuffer::new(
            &ctx,
            "scan scratch",
            Scan::scratch_size(n as u32).max(16),
            MemoryKind::Device,
        )
        .expect("scratch");
        let t = time_gpu(
            &ctx,
            runs,
            warmup,
            |cmd| {
                scan.record(
                    &ctx,
                    cmd,
                    input.whole(),
                    output.whole(),
                    (&total, 0),
                    scan_scratch.whole(),
                    n as u32,
                )?;
                barrier(&ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                Ok(())
            },
            || (),
        );
        println!("prefix sum {n:>9} u32s{:<21}: {}", "", stats(t));
    }

    // Whole-pipeline stages on synthetic scenes at 1280x720 (and the CPU reference).
    let scene_sizes: &[usize] = if full {
        &[10_000, 100_000, 500_000]
    } else {
        &[5_000]
    };
    let mut renderer = GpuRenderer::new(ctx).expect("renderer");
    for &n in scene_sizes {
        let scene = synthetic_scene(n, 1, 2);
        let act = scene.activated();
        let cam = camera::default_camera(&scene.positions, 1280, 720);
        let gs = renderer.upload(&act).expect("upload");
        let (mut pre, mut blend) = (Vec::new(), Vec::new());
        for i in 0..warmup + runs {
            renderer
                .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
                .and_then(Rendered::into_frame)
                .expect("render");
            if i >= warmup {
                pre.push(renderer.timings().preprocess);
                blend.push(renderer.timings().blend);
            }
        }
        println!(
            "preprocess {n:>9} Gaussians (synthetic, SH 2): {}",
            stats(pre)
        );
        println!(
            "blend      {n:>9} Gaussians, {} pairs: {}",
            renderer.stats().pairs,
            stats(blend)
        );
        let mut cpu_ms = Vec::new();
        for i in 0..warmup.min(1) + runs.min(3) {
            let t = Instant::now();
            std::hint::black_box(cpu::render(&act, &cam, &RenderOptions::default()));
            if i >= warmup.min(1) {
                cpu_ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
        }
        println!(
            "CPU reference {n:>6} Gaussians (wall clock): {}",
            stats(cpu_ms)
        );
    }
}
