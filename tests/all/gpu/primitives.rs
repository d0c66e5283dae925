//! GPU prefix sum and radix sort against CPU references, on whatever Vulkan device is
//! available (lavapipe in CI), with validation on: any validation message fails.

use verisplat::core::gen::{tile_depth_keys, Rng};
use verisplat::gpu::buffer::BufferView;
use verisplat::gpu::buffer::{GpuBuffer, MemoryKind};
use verisplat::gpu::scan::{Scan, ScanPush, SCAN_BLOCK};
use verisplat::gpu::shader::compile_glsl;
use verisplat::gpu::sort::{
    Count, RadixSort, SortConfig, SortJob, SortPassPush, SortSetupPush, SortTexels,
    DEFAULT_SORT_CONFIG, SORT_CONFIG_32,
};
use verisplat::gpu::sync::{barrier, Access};
use verisplat::gpu::{ContextOptions, GpuContext, GpuTimer};

fn context() -> GpuContext {
    let ctx = GpuContext::new(&ContextOptions {
        device: None,
        validation: true,
        ..Default::default()
    })
    .expect("create Vulkan context with validation");
    eprintln!("device: {}", ctx.info());
    ctx
}

fn assert_no_validation_messages(ctx: &GpuContext) {
    let messages = ctx.validation_messages();
    assert!(
        messages.is_empty(),
        "validation messages:\n{}",
        messages.join("\n")
    );
}

#[test]
fn push_constant_layouts_are_pinned() {
    use std::mem::{offset_of, size_of};
    assert_eq!(size_of::<ScanPush>(), 16);
    assert_eq!(offset_of!(ScanPush, n), 0);
    assert_eq!(offset_of!(ScanPush, write_total), 4);
    assert_eq!(offset_of!(ScanPush, total_index), 8);
    assert_eq!(size_of::<SortSetupPush>(), 16);
    assert_eq!(offset_of!(SortSetupPush, host_n), 0);
    assert_eq!(offset_of!(SortSetupPush, count_index), 4);
    assert_eq!(offset_of!(SortSetupPush, max_n), 8);
    assert_eq!(offset_of!(SortSetupPush, max_groups_x), 12);
    assert_eq!(size_of::<SortPassPush>(), 16);
    assert_eq!(offset_of!(SortPassPush, shift), 0);
    assert_eq!(offset_of!(SortPassPush, bits), 4);
    assert_eq!(offset_of!(SortPassPush, hist_stride), 8);
}

#[test]
fn shader_compile_error_names_file_and_line() {
    let broken = "#version 460\nlayout(local_size_x = 1) in;\nvoid main() { int x = ; }\n";
    let err = compile_glsl("broken", broken, &[]).expect_err("broken GLSL must not compile");
    let text = err.to_string();
    assert!(text.contains("glsl/broken.comp:3"), "message was: {text}");
}

#[test]
fn unknown_device_is_a_clear_error() {
    let result = GpuContext::new(&ContextOptions {
        device: Some("no-such-device-xyz".into()),
        validation: false,
        ..Default::default()
    });
    let err = result.err().expect("an unknown device name must fail");
    let text = err.to_string();
    assert!(
        text.contains("no-such-device-xyz") && text.contains("#0"),
        "{text}"
    );
}

#[test]
fn context_reports_device_and_no_validation_messages() {
    let ctx = context();
    assert!(ctx.validation_enabled());
    assert!(ctx.info().subgroup_size >= 1);
    assert!(ctx.info().max_workgroup_count[0] >= 65535);
    let buffer = GpuBuffer::from_slice(&ctx, "roundtrip", &[1u32, 2, 3, 4, 5]).expect("upload");
    assert_eq!(
        buffer.read::<u32>(&ctx, 5).expect("read"),
        vec![1, 2, 3, 4, 5]
    );
    let host = GpuBuffer::new(&ctx, "host", 16, MemoryKind::Readback).expect("readback buffer");
    assert_eq!(host.size(), 16);
    drop(host);
    drop(buffer);
    assert_no_validation_messages(&ctx);
    // Leaked objects would be reported while the device and instance are destroyed.
    let log = ctx.validation_log();
    let sort = RadixSort::new(&ctx).expect("sort pipelines");
    let mut timer = GpuTimer::new(&ctx, "timer", 2).expect("timer");
    ctx.submit_and_wait("timer smoke test", |cmd| {
        timer.reset(&ctx, cmd);
        timer.stage(&ctx, cmd, "nothing", |_| Ok(()))
    })
    .expect("submit");
    let times = timer.read(&ctx).expect("timestamps");
    assert_eq!(times.len(), 1);
    assert!(times[0].1 >= 0.0);
    drop((sort, timer));
    drop(ctx);
    let messages = log.lock().map(|m| m.clone()).unwrap_or_default();
    assert!(
        messages.is_empty(),
        "teardown messages:\n{}",
        messages.join("\n")
    );
}

fn gpu_scan(ctx: &GpuContext, scan: &Scan, data: &[u32], in_place: bool) -> (Vec<u32>, u32) {
    let n = data.len() as u32;
    let input = GpuBuffer::new(ctx, "scan input", 4 * u64::from(n), MemoryKind::Device)
        .expect("input buffer");
    input.upload(ctx, data).expect("upload");
    let output = GpuBuffer::new(ctx, "scan output", 4 * u64::from(n), MemoryKind::Device)
        .expect("output buffer");
    let total = GpuBuffer::from_slice(ctx, "scan total", &[0xDEAD_BEEFu32; 4]).expect("total");
    let scratch = GpuBuffer::new(
        ctx,
        "scan scratch",
        Scan::scratch_size(n),
        MemoryKind::Device,
    )
    .expect("scratch");
    let out = if in_place { &input } else { &output };
    ctx.submit_and_wait("scan test", |cmd| {
        scan.record(
            ctx,
            cmd,
            input.whole(),
            out.whole(),
            (&total, 8),
            scratch.whole(),
            n,
        )?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
        Ok(())
    })
    .expect("scan");
    let result = out.read::<u32>(ctx, data.len()).expect("read scan");
    let totals = total.read::<u32>(ctx, 4).expect("read total");
    assert_eq!(totals[0], 0xDEAD_BEEF, "scan wrote outside its total slot");
    (result, totals[2])
}

#[test]
fn prefix_sum_matches_cpu() {
    let ctx = context();
    let scan = Scan::new(&ctx).expect("scan pipelines");
    let b = SCAN_BLOCK as usize;
    let mut sizes = vec![
        0,
        1,
        2,
        3,
        1000,
        12345,
        b - 1,
        b,
        b + 1,
        2 * b - 1,
        2 * b,
        2 * b + 1,
    ];
    sizes.extend([b * b - 1, b * b, b * b + 1, (1 << 20) + 3]);
    let mut rng = Rng(7);
    for (i, &n) in sizes.iter().enumerate() {
        // Small values keep totals below 2^32 even for the 16M-element case.
        let data: Vec<u32> = (0..n).map(|_| rng.next_u32() % 200).collect();
        let mut expected = Vec::with_capacity(n);
        let mut sum = 0u32;
        for &x in &data {
            expected.push(sum);
            sum = sum.wrapping_add(x);
        }
        let (result, total) = gpu_scan(&ctx, &scan, &data, i % 2 == 1);
        assert!(result == expected, "scan mismatch for n = {n}");
        assert_eq!(total, sum, "total mismatch for n = {n}");
    }
    assert_no_validation_messages(&ctx);
}

#[derive(Clone, Copy, Debug)]
enum Mode {
    Host,
    /// Count in a device buffer; the buffers have room for `capacity` elements.
    Device {
        capacity: usize,
    },
    /// Device count `overstate` larger than the capacity (= the number of keys): the
    /// sort must clamp it.
    DeviceOverstated {
        overstate: u32,
    },
}

fn mask_of(key_bits: u32) -> u64 {
    if key_bits >= 64 {
        u64::MAX
    } else {
        (1u64 << key_bits) - 1
    }
}

/// Key words of one key as the sort stores it: `[lo, hi]` for 64-bit keys, `[lo]` (the
/// key's low 32 bits) for 32-bit ones.
fn pack_keys(keys: &[u64], words: u32) -> Vec<u32> {
    keys.iter()
        .flat_map(|&k| {
            [k as u32, (k >> 32) as u32]
                .into_iter()
                .take(words as usize)
        })
        .collect()
}

/// Sorts `keys`/`values` on the GPU and checks against a CPU stable sort, including
/// that elements past the count are untouched. A 32-bit sort sees the keys' low words.
fn check_sort(
    ctx: &GpuContext,
    sort: &RadixSort,
    keys: &[u64],
    key_bits: u32,
    mode: Mode,
    what: &str,
) {
    let n = keys.len();
    let capacity = match mode {
        Mode::Host => n,
        Mode::Device { capacity } => capacity.max(n),
        Mode::DeviceOverstated { .. } => n,
    };
    let device_count = match mode {
        Mode::DeviceOverstated { overstate } => n as u32 + overstate,
        _ => n as u32,
    };
    let mut rng = Rng(n as u64 ^ 0x5eed);
    let words = sort.config().key_words;
    let width_mask = mask_of(32 * words);
    let mut all_keys: Vec<u64> = keys.iter().map(|&k| k & width_mask).collect();
    all_keys.extend((n..capacity).map(|_| rng.next_u64() & width_mask));
    let values: Vec<u32> = (0..capacity as u32).collect();
    let packed = pack_keys(&all_keys, words);
    let key_buf = GpuBuffer::new(
        ctx,
        "keys",
        4 * u64::from(words) * capacity.max(1) as u64,
        MemoryKind::Device,
    )
    .expect("keys");
    key_buf.upload(ctx, &packed).expect("upload keys");
    let value_buf =
        GpuBuffer::new(ctx, "values", 4 * capacity as u64, MemoryKind::Device).expect("values");
    value_buf.upload(ctx, &values).expect("upload values");
    let count_buf =
        GpuBuffer::from_slice(ctx, "count", &[0u32, 0, device_count, 0]).expect("count");
    let scratch = GpuBuffer::new(
        ctx,
        "sort scratch",
        sort.scratch_size_for(capacity as u32),
        MemoryKind::Device,
    )
    .expect("scratch");
    let count = match mode {
        Mode::Host => Count::Host(n as u32),
        Mode::Device { .. } | Mode::DeviceOverstated { .. } => Count::Device {
            buffer: &count_buf,
            offset: 8,
            max_n: capacity as u32,
        },
    };
    // A texel-I/O sort reads and writes through R32_UINT views of the same bytes.
    let view = |b: &GpuBuffer, (offset, size): (u64, u64)| {
        BufferView::new(ctx, b, ash::vk::Format::R32_UINT, offset, size.max(4)).expect("view")
    };
    let views = sort.config().texel_io.then(|| {
        let [k, v] = RadixSort::scratch_pair_ranges(&sort.config(), capacity as u32);
        [
            view(&key_buf, (0, key_buf.size())),
            view(&value_buf, (0, value_buf.size())),
            view(&scratch, k),
            view(&scratch, v),
        ]
    });
    ctx.submit_and_wait("sort test", |cmd| {
        match &views {
            Some([k, v, sk, sv]) => {
                let texels = SortTexels {
                    keys: k.handle(),
                    values: v.handle(),
                    scratch_keys: sk.handle(),
                    scratch_values: sv.handle(),
                };
                let job = SortJob::new(&key_buf, &value_buf, &scratch, count, key_bits)
                    .texels(Some(&texels));
                sort.record(ctx, cmd, &job)?
            }
            None => {
                let job = SortJob::new(&key_buf, &value_buf, &scratch, count, key_bits);
                sort.record(ctx, cmd, &job)?
            }
        }
        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
        Ok(())
    })
    .expect("sort");
    let got_keys: Vec<u32> = key_buf
        .read(ctx, capacity * words as usize)
        .expect("read keys");
    let got_values: Vec<u32> = value_buf.read(ctx, capacity).expect("read values");

    let mask = mask_of(key_bits);
    let mut expected: Vec<(u64, u32)> = all_keys[..n].iter().copied().zip(0u32..).collect();
    expected.sort_by_key(|&(k, _)| k & mask);
    let w = words as usize;
    for (i, &(k, v)) in expected.iter().enumerate() {
        let got = got_keys[i * w..(i + 1) * w]
            .iter()
            .rev()
            .fold(0u64, |acc, &word| (acc << 32) | u64::from(word));
        assert!(
            got == k && got_values[i] == v,
            "{what}: n = {n}, key_bits = {key_bits}, {mode:?}: element {i} is ({got:#x}, {}), \
             expected ({k:#x}, {v})",
            got_values[i]
        );
    }
    assert!(
        got_keys[n * w..] == packed[n * w..],
        "{what}: keys past the count changed"
    );
    assert!(
        got_values[n..] == values[n..],
        "{what}: values past the count changed"
    );
}

fn patterns(rng: &mut Rng, n: usize) -> Vec<(&'static str, Vec<u64>)> {
    let random: Vec<u64> = (0..n).map(|_| rng.next_u64()).collect();
    let mut sorted = random.clone();
    sorted.sort_unstable();
    let reversed: Vec<u64> = sorted.iter().rev().copied().collect();
    vec![
        ("random", random),
        ("all equal", vec![0x1234_5678_9abc_def0; n]),
        ("sorted", sorted),
        ("reverse sorted", reversed),
        ("tile|depth", tile_depth_keys(rng, n)),
    ]
}

#[test]
fn radix_sort_matches_cpu_stable_sort() {
    let ctx = context();
    let sort = RadixSort::new(&ctx).expect("sort pipelines");
    let c = sort.config();
    let block = (c.workgroup_size * c.items_per_thread) as usize;
    let mut rng = Rng(42);
    let sizes = [
        0,
        1,
        2,
        3,
        1000,
        block - 1,
        block,
        block + 1,
        2 * block - 1,
        2 * block + 1,
        12345,
    ];
    for &n in &sizes {
        for (what, keys) in patterns(&mut rng, n) {
            for key_bits in [16, 33, 44, 64] {
                check_sort(&ctx, &sort, &keys, key_bits, Mode::Host, what);
            }
            check_sort(
                &ctx,
                &sort,
                &keys,
                44,
                Mode::Device {
                    capacity: n + n / 3 + 5,
                },
                what,
            );
        }
    }
    assert_no_validation_messages(&ctx);
}

/// The 32-bit key variants (the renderer's depth order and pair sort: through storage
/// buffers, and through texel views on CPU devices) against a CPU stable sort: every
/// pattern and block boundary, host and device counts, a 2^20-element sort, and a bit
/// range past the key refused.
#[test]
fn radix_sort_of_32_bit_keys_matches_cpu_stable_sort() {
    let ctx = context();
    for texel_io in [false, true] {
        let config = SortConfig {
            texel_io,
            ..SORT_CONFIG_32
        };
        let sort = RadixSort::with_config(&ctx, config).expect("sort pipelines");
        check_32_bit_sort(&ctx, &sort);
    }
    let refused = SortConfig {
        texel_io: true,
        ..DEFAULT_SORT_CONFIG
    };
    assert!(
        RadixSort::with_config(&ctx, refused).is_err(),
        "texel I/O needs 32-bit keys"
    );
    assert_no_validation_messages(&ctx);
}

fn check_32_bit_sort(ctx: &GpuContext, sort: &RadixSort) {
    let c = sort.config();
    assert_eq!(c.key_words, 1);
    let block = (c.workgroup_size * c.items_per_thread) as usize;
    let mut rng = Rng(4242);
    for n in [0, 1, 3, block - 1, block, block + 1, 2 * block + 1, 12345] {
        for (what, keys) in patterns(&mut rng, n) {
            for key_bits in [12, 17, 32] {
                check_sort(ctx, sort, &keys, key_bits, Mode::Host, what);
            }
            let device = Mode::Device {
                capacity: n + n / 3 + 5,
            };
            check_sort(ctx, sort, &keys, 32, device, what);
        }
    }
    let n = (1 << 20) + 3;
    let random: Vec<u64> = (0..n).map(|_| rng.next_u64()).collect();
    let device = Mode::Device { capacity: n + 77 };
    check_sort(ctx, sort, &random, 32, device, "random large");
    check_sort(ctx, sort, &random, 14, Mode::Host, "random large, 14 bits");
    // Bits past the key are refused (by the storage-buffer variant; the texel variant
    // refuses any call without its views first).
    let (a, b, c) = (dummy(ctx), dummy(ctx), dummy(ctx));
    let e = sort.record(
        ctx,
        vk_null_cmd(),
        &SortJob::new(&a, &b, &c, Count::Host(1), 0).bits(0..33),
    );
    let text = e.expect_err("refused").to_string();
    let expected = if sort.config().texel_io {
        "texel"
    } else {
        "0..33 are not a range inside the 32-bit key"
    };
    assert!(text.contains(expected), "{text}");
}

#[test]
fn radix_sort_large_and_device_count() {
    let ctx = context();
    let sort = RadixSort::new(&ctx).expect("sort pipelines");
    let mut rng = Rng(9);
    let n = (1 << 20) + 3;
    let keys = tile_depth_keys(&mut rng, n);
    check_sort(&ctx, &sort, &keys, 44, Mode::Host, "tile|depth large");
    let random: Vec<u64> = (0..n).map(|_| rng.next_u64()).collect();
    check_sort(
        &ctx,
        &sort,
        &random,
        33,
        Mode::Device { capacity: n + 5000 },
        "random large",
    );
    // Device count of zero with a non-zero capacity.
    check_sort(
        &ctx,
        &sort,
        &[],
        44,
        Mode::Device { capacity: 5000 },
        "empty device count",
    );
    // A device count larger than the capacity is clamped to the capacity.
    let keys: Vec<u64> = (0..3000).map(|_| rng.next_u64()).collect();
    check_sort(
        &ctx,
        &sort,
        &keys,
        64,
        Mode::Device { capacity: 3000 },
        "exact capacity",
    );
    let overstated = Mode::DeviceOverstated {
        overstate: 1_000_000,
    };
    check_sort(&ctx, &sort, &keys, 64, overstated, "count above capacity");
    assert_no_validation_messages(&ctx);
}

/// The 2D dispatch grid (used past maxComputeWorkGroupCount[0] workgroups), forced with
/// a tiny pretend limit so small inputs need several rows of workgroups.
#[test]
fn two_dimensional_dispatch_grid() {
    let ctx = context();
    let scan = Scan::new(&ctx).expect("scan").with_dispatch_limit(3);
    let mut rng = Rng(11);
    for n in [SCAN_BLOCK as usize * 7 + 5, SCAN_BLOCK as usize * 9] {
        let data: Vec<u32> = (0..n).map(|_| rng.next_u32() % 1000).collect();
        let mut expected = Vec::with_capacity(n);
        let mut sum = 0u32;
        for &x in &data {
            expected.push(sum);
            sum += x;
        }
        let (result, total) = gpu_scan(&ctx, &scan, &data, false);
        assert!(result == expected, "2D-grid scan mismatch for n = {n}");
        assert_eq!(total, sum);
    }
    let sort = RadixSort::new(&ctx).expect("sort").with_dispatch_limit(4);
    let c = sort.config();
    let n = (c.workgroup_size * c.items_per_thread) as usize * 10 + 17;
    let keys = tile_depth_keys(&mut rng, n);
    check_sort(&ctx, &sort, &keys, 44, Mode::Host, "2D grid, host count");
    let capacity = n + 9000;
    check_sort(
        &ctx,
        &sort,
        &keys,
        33,
        Mode::Device { capacity },
        "2D grid, device count",
    );
    assert_no_validation_messages(&ctx);
}

#[test]
fn radix_sort_other_configs() {
    let ctx = context();
    let mut rng = Rng(3);
    let odd = SortConfig {
        radix_bits: 5,
        workgroup_size: 64,
        items_per_thread: 7,
        ..DEFAULT_SORT_CONFIG
    };
    for config in [
        SortConfig {
            radix_bits: 4,
            workgroup_size: 256,
            items_per_thread: 16,
            ..DEFAULT_SORT_CONFIG
        },
        odd,
        SortConfig {
            key_words: 1,
            ..odd
        },
    ] {
        let sort = RadixSort::with_config(&ctx, config).expect("sort pipelines");
        let key_bits = if config.key_words == 1 { 32 } else { 44 };
        for n in [0, 1, 1023, 1024, 1025, 20000] {
            for (what, keys) in patterns(&mut rng, n) {
                check_sort(&ctx, &sort, &keys, key_bits, Mode::Host, what);
                check_sort(
                    &ctx,
                    &sort,
                    &keys,
                    13,
                    Mode::Device { capacity: n + 100 },
                    what,
                );
            }
        }
    }
    assert_no_validation_messages(&ctx);
}

#[test]
fn radix_sort_of_a_bit_range_keeps_lower_bits_in_arrival_order() {
    // Pairs already in (depth, index) order sorted by the tile bits 32..44 only must come
    // out exactly as a stable sort by the tile alone (depth order kept within each tile).
    let ctx = context();
    let sort = RadixSort::new(&ctx).expect("sort");
    let mut rng = Rng(77);
    for (n, bits) in [
        (0usize, 32..44),
        (1, 32..44),
        (4095, 32..44),
        (4097, 32..49),
        (100_003, 32..44),
        (70_001, 32..49),
        (5000, 36..61),
    ] {
        let mut keys: Vec<u64> = tile_depth_keys(&mut rng, n);
        if bits.end > 44 {
            // Bin ids past 16 bits (a 4K frame of 8-pixel bins has 129,600).
            for k in &mut keys {
                let hi = (*k >> 32) * 37 % 129_600;
                *k = (hi << 32) | (*k & 0xFFFF_FFFF);
            }
        }
        let packed: Vec<[u32; 2]> = keys.iter().map(|&k| [k as u32, (k >> 32) as u32]).collect();
        let values: Vec<u32> = (0..n as u32).collect();
        let cap = n.max(1);
        let key_buf =
            GpuBuffer::new(&ctx, "keys", 8 * cap as u64, MemoryKind::Device).expect("keys");
        key_buf.upload(&ctx, &packed).expect("upload");
        let value_buf =
            GpuBuffer::new(&ctx, "values", 4 * cap as u64, MemoryKind::Device).expect("values");
        value_buf.upload(&ctx, &values).expect("upload");
        let scratch = GpuBuffer::new(
            &ctx,
            "scratch",
            sort.scratch_size_for(cap as u32),
            MemoryKind::Device,
        )
        .expect("scratch");
        ctx.submit_and_wait("bit range sort", |cmd| {
            let job = SortJob::new(&key_buf, &value_buf, &scratch, Count::Host(n as u32), 0)
                .bits(bits.clone());
            sort.record(&ctx, cmd, &job)?;
            verisplat::gpu::sync::barrier(
                &ctx,
                cmd,
                verisplat::gpu::Access::ComputeWrite,
                verisplat::gpu::Access::TransferRead,
            );
            Ok(())
        })
        .expect("sort");
        let got_keys: Vec<[u32; 2]> = key_buf.read(&ctx, n).expect("read");
        let got_values: Vec<u32> = value_buf.read(&ctx, n).expect("read");
        let mut expected: Vec<(u64, u32)> =
            keys.iter().copied().zip(values.iter().copied()).collect();
        let mask = (1u64 << (bits.end - bits.start)) - 1;
        expected.sort_by_key(|&(k, _)| (k >> bits.start) & mask);
        let want_keys: Vec<[u32; 2]> = expected
            .iter()
            .map(|&(k, _)| [k as u32, (k >> 32) as u32])
            .collect();
        let want_values: Vec<u32> = expected.iter().map(|&(_, v)| v).collect();
        assert_eq!(got_keys, want_keys, "n = {n}, bits {bits:?}");
        assert_eq!(got_values, want_values, "n = {n}, bits {bits:?}");
    }
    let (a, b, c) = (dummy(&ctx), dummy(&ctx), dummy(&ctx));
    let e = sort.record(
        &ctx,
        vk_null_cmd(),
        &SortJob::new(&a, &b, &c, Count::Host(1), 0).bits(40..70),
    );
    assert!(e.is_err_and(|e| e.to_string().contains("40..70")));
    assert_no_validation_messages(&ctx);
}

fn vk_null_cmd() -> ash::vk::CommandBuffer {
    ash::vk::CommandBuffer::null()
}

fn dummy(ctx: &GpuContext) -> GpuBuffer {
    GpuBuffer::new(ctx, "dummy", 64, MemoryKind::Device).expect("dummy")
}
