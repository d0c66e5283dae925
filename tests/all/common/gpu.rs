//! GPU test helpers: one renderer shared by the tests (pipelines compile once), validation on.
#![allow(dead_code)]

use std::sync::{Mutex, MutexGuard, OnceLock};
use verisplat::camera::Camera;
use verisplat::frame::Frame;
use verisplat::gpu::{ContextOptions, GpuContext};
use verisplat::render::forward::blend::BlendKernel;
use verisplat::render::GpuRenderer;

/// The shared renderer (validation layer on; the blend variant for the device).
pub fn renderer() -> MutexGuard<'static, GpuRenderer> {
    static R: OnceLock<Mutex<GpuRenderer>> = OnceLock::new();
    R.get_or_init(|| Mutex::new(new_renderer(None)))
        .lock()
        .unwrap_or_else(|e| e.into_inner())
}

/// A fresh renderer with validation on and, if given, a fixed blend kernel: one the
/// device's workgroups cannot hold (the shared kernel under `VERISPLAT_EMULATE=spec-limits`)
/// gives way to the device's own, said on stderr, so such a run tests what a device with
/// those limits runs.
pub fn new_renderer(kernel: Option<BlendKernel>) -> GpuRenderer {
    let ctx = GpuContext::new(&ContextOptions {
        validation: true,
        ..Default::default()
    })
    .expect("a Vulkan device (lavapipe) with the validation layer");
    let kernel = kernel.filter(|k| {
        let fits = k.fits(ctx.info());
        if !fits {
            eprintln!(
                "{k} does not fit {}'s workgroup limits: its own kernel runs",
                ctx.info().name
            );
        }
        fits
    });
    match kernel {
        Some(k) => GpuRenderer::with_blend_kernel(ctx, k),
        None => GpuRenderer::new(ctx),
    }
    .expect("pipelines build")
}

/// A fresh renderer with `kernel`, or `None` (said on stderr) when the device's workgroup
/// limits cannot hold it: under `VERISPLAT_EMULATE=spec-limits` (128 invocations) the
/// shared kernel and the 1-pixel texel kernel are refused, as on such a device.
pub fn renderer_if_it_fits(kernel: BlendKernel) -> Option<GpuRenderer> {
    let ctx = GpuContext::new(&ContextOptions {
        validation: true,
        ..Default::default()
    })
    .expect("a Vulkan device (lavapipe) with the validation layer");
    if !kernel.fits(ctx.info()) {
        eprintln!(
            "{kernel} does not fit {}'s workgroup limits: not run",
            ctx.info().name
        );
        return None;
    }
    Some(GpuRenderer::with_blend_kernel(ctx, kernel).expect("pipelines build"))
}

/// Fails on any validation-layer message.
pub fn assert_validation_clean(r: &GpuRenderer) {
    let msgs = r.ctx().validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
}

/// Image comparison figures.
#[derive(Debug)]
pub struct Comparison {
    /// PSNR of colour clamped to [0, 1].
    pub psnr: f64,
    /// Share of pixels whose 8-bit colour is within 1/255 in every channel.
    pub within: f64,
    /// PSNR of alpha.
    pub alpha_psnr: f64,
    /// Largest relative depth difference where both alphas exceed 0.5.
    pub depth_rel: f64,
    /// Share of pixels with both alphas above 0.5 whose depth is within 1e-3 relative.
    pub depth_within: f64,
}

/// Compares a GPU frame with the CPU reference frame: colour and alpha figures from
/// `verisplat::metrics`, plus the relative depth error where both alphas exceed 0.5.
pub fn compare(gpu: &Frame, cpu: &Frame) -> Comparison {
    assert_eq!((gpu.width, gpu.height), (cpu.width, cpu.height));
    let m = verisplat::metrics::compare_frames(cpu, gpu);
    let (mut depth_rel, mut covered, mut depth_ok) = (0.0f64, 0usize, 0usize);
    for i in 0..gpu.alpha.len() {
        if gpu.alpha[i] > 0.5 && cpu.alpha[i] > 0.5 {
            let rel = ((gpu.depth[i] - cpu.depth[i]).abs() / cpu.depth[i].abs().max(1e-6)) as f64;
            depth_rel = depth_rel.max(rel);
            covered += 1;
            depth_ok += (rel <= 1e-3) as usize;
        }
    }
    Comparison {
        psnr: m.color.psnr,
        within: m.color.within,
        alpha_psnr: m.alpha.psnr,
        depth_rel,
        depth_within: if covered == 0 {
            1.0
        } else {
            depth_ok as f64 / covered as f64
        },
    }
}

/// Writes `actual`, `expected` and `diff` PNGs for a failed golden comparison and returns
/// where they went.
pub fn dump_failure(name: &str, gpu: &Frame, cpu: &Frame) -> String {
    let dir = std::env::temp_dir().join("verisplat-test-failures");
    let _ = std::fs::create_dir_all(&dir);
    let mut diff = cpu.clone();
    for i in 0..diff.color.len() {
        for ch in 0..3 {
            diff.color[i][ch] = ((gpu.color[i][ch] - cpu.color[i][ch]).abs() * 10.0).min(1.0);
        }
    }
    use verisplat::output::{write_frame, ImageFormat};
    let _ = write_frame(
        gpu,
        &dir.join(format!("{name}.actual.png")),
        ImageFormat::Png8,
        true,
    );
    let _ = write_frame(
        cpu,
        &dir.join(format!("{name}.expected.png")),
        ImageFormat::Png8,
        true,
    );
    let _ = write_frame(
        &diff,
        &dir.join(format!("{name}.diff.png")),
        ImageFormat::Png8,
        true,
    );
    dir.display().to_string()
}

/// A camera `factor` of the way from the target to the orbit camera `cam` (close-ups
/// for factor < 1), still looking at `target`.
pub fn move_towards(cam: &Camera, target: glam::Vec3, factor: f32, name: &str) -> Camera {
    let eye = target + (cam.position() - target) * factor;
    let vfov = 2.0 * (cam.height as f32 / (2.0 * cam.fy)).atan();
    Camera::look_at(
        name,
        cam.width,
        cam.height,
        vfov,
        eye,
        target,
        glam::Vec3::NEG_Y,
    )
}
