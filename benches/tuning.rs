//! Timings behind two tuning choices, on lavapipe or any Vulkan device. No assertions: the
//! figures are for choosing and for BENCHMARKS.md.
//!
//! - `store_paths`: what lavapipe's per-lane memory operations cost by path (storage
//!   buffer vs texel buffer loads and scatters, and the blend's output path: `imageStore`
//!   of a vec4 into a 2D image vs a texel buffer), on 2^22 elements; the median-low of 4
//!   runs per case. Why the sort and the blend read and write through texel views.
//! - `sort_and_scan`: the 2^20-pair radix sort (44 key bits, tile|depth keys) and the
//!   2^20-element prefix sum, 8 runs of which the first 2 are discarded; median, min and
//!   max. `VERISPLAT_SORT_CONFIG=radix_bits,workgroup_size,items` overrides the sort's tuning;
//!   `VERISPLAT_SORT_PROFILE=1` adds the per-stage totals of 3 timed sorts.
//!
//! `cargo bench --bench tuning` runs both; `cargo bench --bench tuning -- store_paths` (or
//! `sort_and_scan`) one of them. Under `cargo test` (no `--bench` argument) each runs once
//! at a small size, as a smoke test.

use ash::vk;
use verisplat::core::gen::{tile_depth_keys, Rng};
use verisplat::gpu::shader::{compile_glsl, BindingKind, Resource};
use verisplat::gpu::sort::{SortConfig, SortJob};
use verisplat::gpu::sync::{barrier, Access};
use verisplat::gpu::{
    BufferView, ComputePipeline, ContextOptions, Count, GpuBuffer, GpuContext, GpuImage, GpuTimer,
    MemoryKind, RadixSort, Scan,
};

const HEAD: &str = "#version 460\nlayout(local_size_x = 256) in;\n";

/// Each memory path on `n` elements (a multiple of 65,536), `runs` runs per case (at
/// least 2); prints the second fastest.
fn store_paths(ctx: &GpuContext, n: u32, runs: usize) {
    let perm: Vec<u32> = (0..n).map(|i| (i.wrapping_mul(2654435761)) % n).collect();
    let src: Vec<u32> = (0..n).collect();
    let perm_buf = GpuBuffer::from_slice(ctx, "perm", &perm).unwrap();
    let src_buf = GpuBuffer::from_slice(ctx, "src", &src).unwrap();
    let dst_buf = GpuBuffer::new(ctx, "dst", 16 * u64::from(n), MemoryKind::Device).unwrap();
    let u32_view =
        |b: &GpuBuffer, bytes| BufferView::new(ctx, b, vk::Format::R32_UINT, 0, bytes).unwrap();
    let v4_view = |b: &GpuBuffer| {
        BufferView::new(ctx, b, vk::Format::R32G32B32A32_SFLOAT, 0, b.size()).unwrap()
    };
    let src_view = u32_view(&src_buf, src_buf.size());
    let perm_view = u32_view(&perm_buf, perm_buf.size());
    let dst_view = u32_view(&dst_buf, 4 * u64::from(n));
    let dst_v4 = v4_view(&dst_buf);
    // The blend's output path: imageStore of a vec4 into a 2D image vs a texel buffer.
    let (w, h) = (2048u32, n / 2048);
    let image = GpuImage::new(ctx, "image", w, h, vk::Format::R32G32B32A32_SFLOAT).unwrap();
    let ssbo = [
        Resource::Buffer(src_buf.whole()),
        Resource::Buffer(perm_buf.whole()),
        Resource::Buffer(dst_buf.whole()),
    ];
    let texel = |dst: &BufferView| {
        [
            Resource::TexelBuffer(src_view.handle()),
            Resource::TexelBuffer(perm_view.handle()),
            Resource::TexelBuffer(dst.handle()),
        ]
    };
    use BindingKind::*;
    let cases: Vec<(&str, &str, Vec<BindingKind>, Vec<Resource>)> = vec![
        ("ssbo load/ssbo scatter u32", "layout(std430, binding=0) readonly buffer A { uint a[]; }; layout(std430, binding=1) readonly buffer P { uint p[]; }; layout(std430, binding=2) writeonly buffer D { uint d[]; };\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; d[p[i]] = a[i]; }", vec![StorageBuffer, StorageBuffer, StorageBuffer], ssbo.to_vec()),
        ("texel load/imageStore scatter u32", "layout(binding=0) uniform usamplerBuffer a; layout(binding=1) uniform usamplerBuffer p; layout(binding=2, r32ui) uniform writeonly uimageBuffer d;\nvoid main() { int i = int(gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u); imageStore(d, int(texelFetch(p, i).x), texelFetch(a, i)); }", vec![UniformTexelBuffer, UniformTexelBuffer, StorageTexelBuffer], texel(&dst_view).to_vec()),
        ("ssbo load/ssbo store vec4 (contiguous)", "layout(std430, binding=0) readonly buffer A { uint a[]; }; layout(std430, binding=1) readonly buffer P { uint p[]; }; layout(std430, binding=2) writeonly buffer D { vec4 d[]; };\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; d[i] = vec4(float(a[i]), 1.0, 2.0, float(p[i])); }", vec![StorageBuffer, StorageBuffer, StorageBuffer], ssbo.to_vec()),
        ("texel load/imageStore vec4 (contiguous)", "layout(binding=0) uniform usamplerBuffer a; layout(binding=1) uniform usamplerBuffer p; layout(binding=2, rgba32f) uniform writeonly imageBuffer d;\nvoid main() { int i = int(gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u); imageStore(d, i, vec4(float(texelFetch(a, i).x), 1.0, 2.0, float(texelFetch(p, i).x))); }", vec![UniformTexelBuffer, UniformTexelBuffer, StorageTexelBuffer], texel(&dst_v4).to_vec()),
        ("imageStore vec4 into image2D", "layout(binding=0, rgba32f) uniform writeonly image2D d;\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; imageStore(d, ivec2(i % 2048u, i / 2048u), vec4(float(i), 1.0, 2.0, 3.0)); }", vec![StorageImage], vec![Resource::Image { view: image.view(), layout: vk::ImageLayout::GENERAL }]),
        ("imageStore vec4 into imageBuffer", "layout(binding=0, rgba32f) uniform writeonly imageBuffer d;\nvoid main() { uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * 65536u; imageStore(d, int(i), vec4(float(i), 1.0, 2.0, 3.0)); }", vec![StorageTexelBuffer], vec![Resource::TexelBuffer(dst_v4.handle())]),
    ];
    let mut timer = GpuTimer::new(ctx, "t", 8).unwrap();
    for (name, body, kinds, res) in cases {
        let spirv = compile_glsl(name, &format!("{HEAD}{body}"), &[]).unwrap();
        let p = ComputePipeline::new(
            ctx,
            "case",
            &spirv,
            &kinds,
            &verisplat::core::shader_interface::NO_PUSH_CONSTANTS,
        )
        .unwrap();
        let mut ms = Vec::new();
        for _ in 0..runs {
            ctx.submit_and_wait("mb", |cmd| {
                image.transition_to_general(ctx, cmd);
                timer.reset(ctx, cmd);
                timer.stage(ctx, cmd, "x", |cmd| {
                    p.dispatch_resources(ctx, cmd, &res, &[], [256, n / 65536, 1])
                })
            })
            .unwrap();
            ms.push(timer.span_ms(ctx).unwrap());
        }
        ms.sort_by(f64::total_cmp);
        println!(
            "{name:45} {:.2} ms for {n} elements ({:.1} ns each)",
            ms[1],
            ms[1] * 1e6 / f64::from(n)
        );
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The sort of `n` pairs (44 key bits) and the scan of `n` elements, `iterations` runs of
/// which the first 2 are discarded.
fn sort_and_scan(ctx: &GpuContext, n: u32, iterations: usize) {
    let config = std::env::var("VERISPLAT_SORT_CONFIG").ok().and_then(|s| {
        let v: Vec<u32> = s.split(',').filter_map(|x| x.trim().parse().ok()).collect();
        (v.len() == 3).then(|| SortConfig {
            radix_bits: v[0],
            workgroup_size: v[1],
            items_per_thread: v[2],
            key_words: 2,
            texel_io: false,
        })
    });
    let sort = match config {
        Some(c) => RadixSort::with_config(ctx, c),
        None => RadixSort::new(ctx),
    }
    .expect("sort");
    let scan = Scan::new(ctx).expect("scan");
    let mut rng = Rng(1);
    let keys: Vec<[u32; 2]> = tile_depth_keys(&mut rng, n as usize)
        .iter()
        .map(|&k| [k as u32, (k >> 32) as u32])
        .collect();
    let values: Vec<u32> = (0..n).collect();
    let key_buf = GpuBuffer::from_slice(ctx, "keys", &keys).expect("keys");
    let value_buf = GpuBuffer::from_slice(ctx, "values", &values).expect("values");
    let scratch = GpuBuffer::new(ctx, "scratch", sort.scratch_size_for(n), MemoryKind::Device)
        .expect("scratch");
    let counts: Vec<u32> = (0..n).map(|_| rng.next_u32() % 64).collect();
    let scan_buf = GpuBuffer::from_slice(ctx, "scan data", &counts).expect("scan data");
    let scan_out =
        GpuBuffer::new(ctx, "scan out", 4 * u64::from(n), MemoryKind::Device).expect("out");
    let scan_scratch = GpuBuffer::new(
        ctx,
        "scan scratch",
        Scan::scratch_size(n),
        MemoryKind::Device,
    )
    .expect("s");
    let mut timer = GpuTimer::new(ctx, "bench timer", 4).expect("timer");
    if std::env::var_os("VERISPLAT_SORT_PROFILE").is_some() {
        let mut stage_timer = GpuTimer::new(ctx, "profile timer", 64).expect("timer");
        for _ in 0..3 {
            key_buf.upload(ctx, &keys).expect("reset keys");
            ctx.submit_and_wait("profile", |cmd| {
                stage_timer.reset(ctx, cmd);
                let job = SortJob::new(&key_buf, &value_buf, &scratch, Count::Host(n), 44);
                sort.record_timed(ctx, cmd, &job, &mut stage_timer)
            })
            .expect("profile run");
        }
        let mut totals: Vec<(String, f64)> = Vec::new();
        for (name, ms) in stage_timer.read(ctx).expect("timestamps") {
            match totals.iter_mut().find(|(n, _)| *n == name) {
                Some(entry) => entry.1 += ms,
                None => totals.push((name, ms)),
            }
        }
        println!("per-stage totals over all passes: {totals:?}");
    }
    let (mut sort_ms, mut scan_ms) = (Vec::new(), Vec::new());
    for iteration in 0..iterations {
        key_buf.upload(ctx, &keys).expect("reset keys");
        let start = std::time::Instant::now();
        ctx.submit_and_wait("bench", |cmd| {
            timer.reset(ctx, cmd);
            timer.stage(ctx, cmd, "sort", |cmd| {
                let job = SortJob::new(&key_buf, &value_buf, &scratch, Count::Host(n), 44);
                sort.record(ctx, cmd, &job)
            })?;
            barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeReadWrite);
            timer.stage(ctx, cmd, "scan", |cmd| {
                scan.record(
                    ctx,
                    cmd,
                    scan_buf.whole(),
                    scan_out.whole(),
                    (&scratch, 20),
                    scan_scratch.whole(),
                    n,
                )
            })
        })
        .expect("bench run");
        let wall = start.elapsed().as_secs_f64() * 1e3;
        let times = timer.read(ctx).expect("timestamps");
        println!("iteration {iteration}: {times:?} (wall {wall:.1} ms)");
        if iteration >= 2 {
            sort_ms.push(times[0].1);
            scan_ms.push(times[1].1);
        }
    }
    println!(
        "config {:?}: sort {n} pairs x 44 bits median {:.2} ms (min {:.2}, max {:.2}); \
         scan {n} median {:.3} ms",
        sort.config(),
        median(sort_ms.clone()),
        sort_ms.iter().copied().fold(f64::MAX, f64::min),
        sort_ms.iter().copied().fold(0.0, f64::max),
        median(scan_ms)
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let full = args.iter().any(|a| a == "--bench");
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let wanted =
        |name: &str| filters.is_empty() || filters.iter().any(|f| name.contains(f.as_str()));
    let ctx = GpuContext::new(&ContextOptions::default()).expect("a Vulkan device");
    println!("device: {}", ctx.info());
    if wanted("store_paths") {
        println!("## store_paths");
        let (n, runs) = if full { (1 << 22, 4) } else { (1 << 16, 2) };
        store_paths(&ctx, n, runs);
    }
    if wanted("sort_and_scan") {
        println!("## sort_and_scan");
        let (n, iterations) = if full { (1 << 20, 8) } else { (1 << 14, 3) };
        sort_and_scan(&ctx, n, iterations);
    }
}
