//! Discrete-GPU semantics forced on lavapipe through `ContextOptions::emulate` (never the
//! environment: the tests share one process): device-local memory that is not
//! host-visible, host memory that is not coherent (flushes and invalidates in
//! `nonCoherentAtomSize` units, which the validation layer checks), timestamps of few
//! valid bits, and small maxStorageBufferRange and maxComputeWorkGroupCount. Each path
//! must render what the CPU reference renders (the thresholds of `render/frames.rs`: a PSNR
//! of at least 55 dB, 99.9 % of 8-bit pixels within 1/255, an alpha PSNR of 55 dB), and
//! where the emulation changes no arithmetic (memory, timestamps, dispatch layout) the
//! frame and every intermediate buffer must equal the plain device's bit for bit.

use std::time::Instant;
use verisplat::render::{FrameRequest, Readback, Rendered};

use crate::common;
use crate::common::cli::{ok, s, stderr, verisplat_env};
use crate::common::gpu::{assert_validation_clean, check_against_reference, renderer};
use crate::common::{orbit, PLAYBOT_ORBIT};
use verisplat::core::camera::Camera;
use verisplat::core::frame::Frame;
use verisplat::core::scene::ActivatedScene;
use verisplat::cpu::RenderOptions;
use verisplat::gpu::emulate::Emulation;
use verisplat::gpu::sync::{barrier, Access};
use verisplat::gpu::timing::Untimed;
use verisplat::gpu::{
    limits, ContextOptions, GpuBuffer, GpuContext, GpuError, GpuTimer, MemoryKind,
};
use verisplat::io;

use verisplat::render::{GpuRenderer, Intermediates, SplitLimits};

fn context(emulate: &str) -> GpuContext {
    GpuContext::new(&ContextOptions {
        validation: true,
        emulate: Emulation::parse(emulate).expect("an emulation list"),
        ..Default::default()
    })
    .expect("a Vulkan device (lavapipe) with the validation layer")
}

fn emulated_renderer(emulate: &str) -> GpuRenderer {
    GpuRenderer::new(context(emulate)).expect("pipelines build")
}

fn lod3() -> ActivatedScene {
    io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply"))
        .unwrap()
        .activated()
}

/// The frame and its intermediates on the plain (shared) renderer.
fn plain_frame(s: &ActivatedScene, cam: &Camera) -> (Frame, Intermediates) {
    let mut r = renderer();
    let gs = r.upload(s).unwrap();
    let out = r
        .render(
            &FrameRequest::new(&gs, cam, &RenderOptions::default())
                .readback(Readback::Intermediates),
        )
        .and_then(Rendered::into_intermediates)
        .unwrap();
    assert_validation_clean(&r);
    out
}

fn assert_same_bits(label: &str, a: &Frame, b: &Frame) {
    let (x, y) = (common::frame_bits(a), common::frame_bits(b));
    let differing = x.iter().zip(&y).filter(|(p, q)| p != q).count();
    assert_eq!(
        differing, 0,
        "{label}: {differing} values differ from the plain device"
    );
}

/// The depth order, scan, sorted pairs and ranges equal the plain device's exactly.
fn assert_same_intermediates(label: &str, a: &Intermediates, b: &Intermediates) {
    assert_eq!(a.counters.pairs(), b.counters.pairs(), "{label}: pairs");
    assert_eq!(a.counters.visible, b.counters.visible, "{label}: visible");
    assert_eq!(a.order, b.order, "{label}: depth order");
    assert_eq!(a.offsets, b.offsets, "{label}: scanned offsets");
    assert_eq!(a.keys, b.keys, "{label}: sorted keys");
    assert_eq!(a.values, b.values, "{label}: sorted values");
    assert_eq!(a.ranges, b.ranges, "{label}: bin ranges");
    assert!(
        a.keys.windows(2).all(|w| w[0] <= w[1]),
        "{label}: keys sorted"
    );
}

#[test]
fn discrete_memory_renders_match_the_reference_and_the_plain_device() {
    let mut r = emulated_renderer("discrete");
    let info = r.ctx().info();
    assert!(info.emulation.device_local_not_host_visible && info.emulation.non_coherent);
    assert!(info.non_coherent_atom_size >= 1);
    // One place decides: device buffers are not mappable, host buffers sync by hand.
    let device = GpuBuffer::new(r.ctx(), "device", 256, MemoryKind::Device).unwrap();
    assert!(!device.memory_plan().mappable);
    let e = device.mapped().unwrap_err().to_string();
    assert!(
        e.contains("not host-visible") && e.contains("staging"),
        "{e}"
    );
    for kind in [MemoryKind::Upload, MemoryKind::Readback] {
        let b = GpuBuffer::new(r.ctx(), "host", 100, kind).unwrap();
        let plan = b.memory_plan();
        assert!(plan.mappable && plan.explicit_sync, "{kind:?}: {plan:?}");
        assert_eq!(plan.atom, info.non_coherent_atom_size);
    }
    drop(device);

    let s = lod3();
    let cam = orbit(PLAYBOT_ORBIT, 5, 320, 180);
    let gs = r.upload(&s).unwrap();
    let (g, inter) = r
        .render(
            &FrameRequest::new(&gs, &cam, &RenderOptions::default())
                .readback(Readback::Intermediates),
        )
        .and_then(Rendered::into_intermediates)
        .unwrap();
    check_against_reference("discrete memory", &g, &s, &cam);
    let (plain, plain_inter) = plain_frame(&s, &cam);
    assert_same_bits("discrete memory", &g, &plain);
    assert_same_intermediates("discrete memory", &inter, &plain_inter);
    // The 8-bit frame reads a range of the read-back buffer (invalidated in atoms).
    let packed = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()).readback(Readback::Rgba8))
        .and_then(Rendered::into_rgba8)
        .unwrap();
    let plain_packed = {
        let mut p = renderer();
        let pgs = p.upload(&s).unwrap();
        p.render(
            &FrameRequest::new(&pgs, &cam, &RenderOptions::default()).readback(Readback::Rgba8),
        )
        .and_then(Rendered::into_rgba8)
        .unwrap()
    };
    assert_eq!(packed.rgba, plain_packed.rgba, "8-bit frames");
    // A frame in depth-ordered chunks reads the scanned offsets back to plan them.
    r.set_split_limits(SplitLimits {
        window: 0,
        chunk_pairs: 20_000,
    });
    let chunked = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(r.stats().chunks > 1, "{:?}", r.stats());
    assert_same_bits("discrete memory, in chunks", &chunked, &plain);
    assert_validation_clean(&r);
}

#[test]
fn mapped_ranges_are_flushed_and_invalidated_in_whole_atoms() {
    let ctx = context("non-coherent");
    let atom = ctx.info().non_coherent_atom_size;
    // Odd sizes, sub-allocated next to each other in one memory block.
    for (i, len) in [1usize, 3, 63, 64, 65, 1000, 4099].into_iter().enumerate() {
        let bytes: Vec<u8> = (0..len).map(|k| (k * 31 + i * 7) as u8).collect();
        let mut upload = GpuBuffer::new(
            &ctx,
            &format!("upload {len}"),
            len as u64,
            MemoryKind::Upload,
        )
        .unwrap();
        let readback = GpuBuffer::new(
            &ctx,
            &format!("readback {len}"),
            len as u64,
            MemoryKind::Readback,
        )
        .unwrap();
        assert!(upload.memory_plan().explicit_sync && readback.memory_plan().explicit_sync);
        upload.write_mapped(&bytes).unwrap();
        assert_eq!(upload.host_syncs(), (1, 0), "a write is flushed once");
        ctx.submit_and_wait("copy", |cmd| {
            barrier(&ctx, cmd, Access::HostWrite, Access::TransferRead);
            let region = [ash::vk::BufferCopy::default().size(len as u64)];
            // SAFETY: both buffers are alive and hold `len` bytes.
            unsafe {
                ctx.device()
                    .cmd_copy_buffer(cmd, upload.handle(), readback.handle(), &region)
            };
            barrier(&ctx, cmd, Access::TransferWrite, Access::HostRead);
            Ok(())
        })
        .unwrap();
        // (Buffers hold at least 4 bytes.)
        assert_eq!(&readback.mapped().unwrap()[..len], &bytes[..]);
        // Unaligned pieces: each invalidated on its own, rounded out to atoms.
        for (start, n) in [(0, 1), (len / 3, (len / 2).max(1)), (len - 1, 1)] {
            assert_eq!(
                readback.mapped_range(start as u64, n as u64).unwrap(),
                &bytes[start..start + n]
            );
        }
        assert_eq!(readback.host_syncs(), (0, 4));
        // Staged uploads and reads of device buffers round-trip exactly.
        let words: Vec<u32> = (0..len as u32)
            .map(|k| k.wrapping_mul(2_654_435_761))
            .collect();
        let device = GpuBuffer::from_slice(&ctx, "device words", &words).unwrap();
        assert_eq!(device.read::<u32>(&ctx, len).unwrap(), words);
    }
    assert!(atom.is_power_of_two());
    let messages = ctx.validation_messages();
    assert!(messages.is_empty(), "validation:\n{}", messages.join("\n"));
    // On lavapipe's coherent memory without the emulation nothing is synced by hand.
    let plain = context("");
    let mut b = GpuBuffer::new(&plain, "plain", 100, MemoryKind::Upload).unwrap();
    b.write_mapped(&[1, 2, 3]).unwrap();
    assert!(!b.memory_plan().explicit_sync && b.host_syncs() == (0, 0));
    // A device buffer there is host-visible (and so mappable) memory.
    let d = GpuBuffer::new(&plain, "plain device", 16, MemoryKind::Device).unwrap();
    assert!(d.memory_plan().mappable);
}

/// Renders `frames` frames of `s` and checks each one's stage times against the host's
/// clock; returns the frames' totals.
fn timed_frames(r: &mut GpuRenderer, s: &ActivatedScene, cam: &Camera, frames: usize) -> Vec<f64> {
    let gs = r.upload(s).unwrap();
    let mut totals = Vec::new();
    for _ in 0..frames {
        let start = Instant::now();
        r.render(&FrameRequest::new(&gs, cam, &RenderOptions::default()))
            .and_then(Rendered::into_frame)
            .unwrap();
        let wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let t = r.timings().clone();
        let stages: f64 = t.stages().iter().map(|(_, ms)| *ms).sum();
        for (name, ms) in t.stages() {
            assert!(ms >= 0.0 && ms.is_finite(), "{name}: {ms} ms");
        }
        // Stages run one after another inside the span, the span inside the call.
        assert!(t.total > 0.0, "{t:?}");
        assert!(stages <= t.total * 1.001 + 1e-3, "{stages} > {t:?}");
        assert!(
            t.total <= wall_ms,
            "{} ms of timestamps in {wall_ms} ms",
            t.total
        );
        totals.push(t.total);
    }
    totals
}

#[test]
fn timestamps_of_36_bits_wrap_mid_frame_and_stay_plausible() {
    let mut r = emulated_renderer("timestamp-bits=36");
    assert_eq!(r.ctx().info().timestamp_valid_bits, 36);
    let s = lod3();
    let cam = orbit(PLAYBOT_ORBIT, 2, 256, 144);
    let totals = timed_frames(&mut r, &s, &cam, 4);
    eprintln!("frame spans with 36-bit timestamps: {totals:?} ms");
    // The timer on its own: the emulated counter wraps in the middle of the reading, and
    // the durations come out as on a 64-bit counter.
    let ctx = r.ctx();
    let buf = GpuBuffer::new(ctx, "filled", 64 << 20, MemoryKind::Device).unwrap();
    let mut timer = GpuTimer::new(ctx, "wrap test", 3).unwrap();
    let start = Instant::now();
    ctx.submit_and_wait("timed fills", |cmd| {
        timer.reset(ctx, cmd);
        for name in ["fill a", "fill b", "fill c"] {
            timer.stage(ctx, cmd, name, |cmd| {
                buf.fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 7);
                barrier(ctx, cmd, Access::TransferWrite, Access::TransferWrite);
                Ok(())
            })?;
        }
        Ok(())
    })
    .unwrap();
    let wall_ms = start.elapsed().as_secs_f64() * 1e3;
    let reading = timer
        .read_checked(ctx)
        .unwrap()
        .expect("36 bits measure a fill");
    assert!(reading.wrapped, "the emulated counter wraps mid-reading");
    let sum: f64 = reading.stages.iter().map(|(_, ms)| ms).sum();
    eprintln!("{reading:?}, host {wall_ms:.3} ms");
    assert!(reading
        .stages
        .iter()
        .all(|(_, ms)| *ms > 0.0 && *ms < wall_ms));
    assert!(sum <= reading.span_ms * 1.001 + 1e-3 && reading.span_ms <= wall_ms);
    assert_eq!(timer.span_ms(ctx).unwrap(), reading.span_ms);
    assert_validation_clean(&r);
}

#[test]
fn timestamps_of_8_bits_are_refused_not_misreported() {
    // A raw 1 ns counter of 8 bits wraps every 256 ns: any stage is longer, so no
    // duration can be told apart from a shorter one.
    let mut r = emulated_renderer("timestamp-bits=8");
    let s = lod3();
    let cam = orbit(PLAYBOT_ORBIT, 2, 256, 144);
    let gs = r.upload(&s).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    check_against_reference("8-bit timestamps", &g, &s, &cam);
    let t = r.timings();
    assert!(
        t.total == 0.0 && t.stages().iter().all(|(_, ms)| *ms == 0.0),
        "untimed, not wrong: {t:?}"
    );
    let ctx = r.ctx();
    let mut timer = GpuTimer::new(ctx, "8 bits", 1).unwrap();
    ctx.submit_and_wait("timed", |cmd| {
        timer.reset(ctx, cmd);
        timer.stage(ctx, cmd, "nothing much", |_| Ok(()))
    })
    .unwrap();
    match timer.read_checked(ctx).unwrap() {
        Err(Untimed::WrapTooShort { bits, wrap_ms, .. }) => {
            assert_eq!(bits, 8);
            assert!((wrap_ms - 256e-6 * f64::from(ctx.info().timestamp_period_ns)).abs() < 1e-12);
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert!(timer.read(ctx).unwrap().is_empty() && timer.span_ms(ctx).unwrap() == 0.0);
    assert_validation_clean(&r);
}

#[test]
fn a_workgroup_count_of_64_lays_dispatches_out_in_two_dimensions() {
    let mut r = emulated_renderer("max-workgroup-count=64");
    let info = r.ctx().info();
    assert_eq!(info.max_workgroup_count[0], 64);
    assert_eq!(limits::dispatch_groups(info, "t", 64).unwrap(), [64, 1, 1]);
    assert_eq!(limits::dispatch_groups(info, "t", 65).unwrap(), [64, 2, 1]);
    let too_many = u64::from(info.max_workgroup_count[1]) * 64 + 1;
    match limits::dispatch_groups(info, "a test", too_many) {
        Err(GpuError::DeviceLimit { limit, .. }) => assert_eq!(limit, "maxComputeWorkGroupCount"),
        other => panic!("{other:?}"),
    }
    assert!(limits::check_dispatch(info, "t", [65, 1, 1]).is_err());
    // 31k Gaussians: 122 preprocess workgroups and more for the sorts' passes, each laid
    // out as rows of 64.
    let s = lod3();
    let cam = orbit(PLAYBOT_ORBIT, 5, 320, 180);
    let gs = r.upload(&s).unwrap();
    let (g, inter) = r
        .render(
            &FrameRequest::new(&gs, &cam, &RenderOptions::default())
                .readback(Readback::Intermediates),
        )
        .and_then(Rendered::into_intermediates)
        .unwrap();
    check_against_reference("64 workgroups", &g, &s, &cam);
    let (plain, plain_inter) = plain_frame(&s, &cam);
    assert_same_bits("64 workgroups", &g, &plain);
    assert_same_intermediates("64 workgroups", &inter, &plain_inter);
    assert_validation_clean(&r);
}

#[test]
fn a_small_storage_binding_splits_the_frame_or_refuses_it() {
    // 256 KiB per binding: 5,376 Gaussians per preprocess window and 65,536 pairs per
    // key buffer, so the 31k-Gaussian frame (about 150k pairs at 960x540) is
    // preprocessed in windows and rendered in depth-ordered chunks, bit for bit the
    // plain device's frame.
    let mut r = emulated_renderer("max-storage-buffer-range=256K");
    assert_eq!(r.ctx().info().max_storage_buffer_range, 256 << 10);
    let s = lod3();
    let cam = orbit(PLAYBOT_ORBIT, 5, 960, 540);
    let gs = r.upload(&s).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
        .and_then(Rendered::into_frame)
        .unwrap();
    eprintln!("256 KiB bindings: {:?}", r.stats());
    assert!(r.stats().chunks > 1, "{:?}", r.stats());
    check_against_reference("256 KiB bindings", &g, &s, &cam);
    let (plain, _) = plain_frame(&s, &cam);
    assert_same_bits("256 KiB bindings", &g, &plain);
    assert_validation_clean(&r);
    drop(r);
    // 64 KiB: one array of 31k words does not fit one binding; refused, clearly.
    let mut r = emulated_renderer("max-storage-buffer-range=64K");
    let e = r.upload(&s).and_then(|gs| {
        r.render(&FrameRequest::new(&gs, &cam, &RenderOptions::default()))
            .and_then(Rendered::into_frame)
            .map(|_| ())
    });
    match e {
        Err(GpuError::DeviceLimit {
            limit,
            needed,
            max,
            message,
        }) => {
            assert_eq!(limit, "maxStorageBufferRange");
            assert!(needed > max && max == 64 << 10, "{needed} {max}");
            assert!(message.contains("maxStorageBufferRange"), "{message}");
        }
        other => panic!("expected a DeviceLimit refusal, got {:?}", other.err()),
    }
    assert_validation_clean(&r);
}

#[test]
fn cli_render_on_an_emulated_discrete_device_matches_the_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let (gpu, cpu) = (dir.path().join("gpu.exr"), dir.path().join("cpu.exr"));
    let args = |out: &std::path::Path, cpu: bool| {
        let mut a = vec!["render", "--demo", "--width", "320", "-o"];
        a.push(s(out));
        if cpu {
            a.push("--cpu");
        }
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let gpu_args = args(&gpu, false);
    let o = verisplat_env(
        &gpu_args.iter().map(String::as_str).collect::<Vec<_>>(),
        &[("VERISPLAT_EMULATE", "discrete")],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let cpu_args = args(&cpu, true);
    ok(&cpu_args.iter().map(String::as_str).collect::<Vec<_>>());
    ok(&["compare", s(&cpu), s(&gpu), "--min-psnr", "55"]);
}
