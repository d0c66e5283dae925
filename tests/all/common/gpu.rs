//! GPU test helpers: one renderer shared by the tests (pipelines compile once), validation on.
#![allow(dead_code)]

use std::sync::{Mutex, MutexGuard, OnceLock};
use verisplat::core::camera::Camera;
use verisplat::core::frame::Frame;
use verisplat::core::scene::ActivatedScene;
use verisplat::cpu::{self, RenderOptions};
use verisplat::gpu::{ContextOptions, GpuContext};
use verisplat::render::forward::blend::BlendKernel;
use verisplat::render::GpuRenderer;
use verisplat::render::{FrameRequest, Rendered};

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

/// The project's GPU-vs-CPU bar: PSNR >= 55 dB (colour clamped to [0, 1]; alpha too where
/// checked).
pub const MIN_PSNR: f64 = 55.0;
/// The project's GPU-vs-CPU bar: at least 99.9 % of 8-bit pixels within 1/255 (and of
/// depths within 1e-3 relative where checked).
pub const MIN_WITHIN: f64 = 0.999;

/// Which figures of a [`Comparison`] a check holds to which bound (`None`: not checked).
/// The constants are the project's thresholds; a check with other bounds states them.
#[derive(Clone, Copy, Debug)]
pub struct Thresholds {
    /// Least colour PSNR, dB.
    pub psnr: f64,
    /// Least share of 8-bit pixels within 1/255.
    pub within: Option<f64>,
    /// Least alpha PSNR, dB.
    pub alpha_psnr: Option<f64>,
    /// Least share of covered pixels whose depth is within 1e-3 relative.
    pub depth_within: Option<f64>,
    /// Largest relative depth difference where both alphas exceed 0.5.
    pub depth_rel: Option<f64>,
}

impl Thresholds {
    /// Colour PSNR >= 55 dB, nothing else.
    pub const PSNR: Thresholds = Thresholds {
        psnr: MIN_PSNR,
        within: None,
        alpha_psnr: None,
        depth_within: None,
        depth_rel: None,
    };
    /// Colour: PSNR >= 55 dB and >= 99.9 % of 8-bit pixels within 1/255.
    pub const COLOUR: Thresholds = Thresholds {
        within: Some(MIN_WITHIN),
        ..Thresholds::PSNR
    };
    /// [`Thresholds::COLOUR`] and an alpha PSNR >= 55 dB.
    pub const COLOUR_AND_ALPHA: Thresholds = Thresholds {
        alpha_psnr: Some(MIN_PSNR),
        ..Thresholds::COLOUR
    };
    /// A whole frame: [`Thresholds::COLOUR_AND_ALPHA`], and depth where both alphas exceed
    /// 0.5: >= 99.9 % of those pixels within 1e-3 relative, none beyond 2 %
    /// (`render::frames` says why a tail exists).
    pub const FRAME: Thresholds = Thresholds {
        depth_within: Some(MIN_WITHIN),
        depth_rel: Some(0.02),
        ..Thresholds::COLOUR_AND_ALPHA
    };
}

/// Compares a GPU frame with the CPU reference frame: colour and alpha figures from
/// `verisplat::io::metrics`, plus the relative depth error where both alphas exceed 0.5.
pub fn compare(gpu: &Frame, cpu: &Frame) -> Comparison {
    assert_eq!((gpu.width, gpu.height), (cpu.width, cpu.height));
    let m = verisplat::io::metrics::compare_frames(cpu, gpu);
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

impl Comparison {
    /// Whether these figures meet every bound of `t`.
    pub fn meets(&self, t: &Thresholds) -> bool {
        let at_least = |v: f64, bound: Option<f64>| bound.map_or(true, |b| v >= b);
        self.psnr >= t.psnr
            && at_least(self.within, t.within)
            && at_least(self.alpha_psnr, t.alpha_psnr)
            && at_least(self.depth_within, t.depth_within)
            && t.depth_rel.map_or(true, |b| self.depth_rel <= b)
    }

    /// Panics with `{label}: {figures} (images in DIR)` unless these figures of `gpu`
    /// against `cpu` meet `t`, having written the frames there ([`dump_failure`]).
    pub fn assert_meets_or_dump(&self, t: &Thresholds, label: &str, gpu: &Frame, cpu: &Frame) {
        if !self.meets(t) {
            let dir = dump_failure(&label.replace(' ', "_"), gpu, cpu);
            panic!("{label}: {self:?} (images in {dir})");
        }
    }
}

/// Holds the GPU frame `g` of `s` from `cam` (default options) to the CPU reference frame
/// with [`Thresholds::COLOUR_AND_ALPHA`] (said on stderr; the images written on failure).
pub fn check_against_reference(label: &str, g: &Frame, s: &ActivatedScene, cam: &Camera) {
    let c = cpu::render(s, cam, &RenderOptions::default());
    let cmp = compare(g, &c);
    eprintln!("{label} vs the CPU reference: {cmp:?}");
    cmp.assert_meets_or_dump(&Thresholds::COLOUR_AND_ALPHA, label, g, &c);
}

/// Renders `s` from `cam` with `opts` on `r` and on the CPU reference and holds the frames
/// to [`Thresholds::FRAME`] (said on stderr with the pair count; the images written on
/// failure); then no validation message.
pub fn check_frame(
    r: &mut GpuRenderer,
    label: &str,
    s: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
) {
    let gs = r.upload(s).unwrap();
    let g = r
        .render(&FrameRequest::new(&gs, cam, opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    let c = cpu::render(s, cam, opts);
    let cmp = compare(&g, &c);
    eprintln!("{label}: {cmp:?}, pairs {}", r.stats().pairs);
    cmp.assert_meets_or_dump(&Thresholds::FRAME, label, &g, &c);
    assert_validation_clean(r);
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
    use verisplat::io::output::{write_frame, ImageFormat};
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
