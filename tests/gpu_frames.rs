//! Whole frames on the GPU (lavapipe, validation on) against the CPU reference.

mod common;

use vksplat::camera::{self, Camera};
use vksplat::cpu::{self, RenderOptions};
use vksplat::frame::Frame;
use vksplat::gpu::{ContextOptions, GpuContext};
use vksplat::render::GpuRenderer;
use vksplat::scene::{self, Scene};

fn renderer() -> GpuRenderer {
    let ctx = GpuContext::new(&ContextOptions {
        validation: true,
        ..Default::default()
    })
    .expect("a Vulkan device (lavapipe) is available");
    GpuRenderer::new(ctx).expect("pipelines build")
}

fn assert_no_validation_messages(r: &GpuRenderer) {
    let msgs = r.ctx().validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
}

/// PSNR over float colour (clamped to [0, 1] like a displayed image) and the share of
/// 8-bit pixels within 1/255.
fn compare(gpu: &Frame, cpu: &Frame) -> (f64, f64) {
    let mut se = 0.0f64;
    let mut within = 0usize;
    for (g, c) in gpu.color.iter().zip(&cpu.color) {
        let mut ok = true;
        for ch in 0..3 {
            let d = g[ch].clamp(0.0, 1.0) as f64 - c[ch].clamp(0.0, 1.0) as f64;
            se += d * d;
            let (g8, c8) = (
                vksplat::output::to_u8(g[ch]) as i32,
                vksplat::output::to_u8(c[ch]) as i32,
            );
            ok &= (g8 - c8).abs() <= 1;
        }
        within += ok as usize;
    }
    let mse = se / (gpu.color.len() * 3) as f64;
    let psnr = if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / mse).log10()
    };
    (psnr, within as f64 / gpu.color.len() as f64)
}

#[test]
fn demo_scene_matches_the_cpu_reference() {
    let mut r = renderer();
    let s = vksplat::demo_scene();
    let act = s.activated();
    let cam = camera::default_camera(&s.positions, 640, 360);
    let opts = RenderOptions {
        background: [0.1, 0.2, 0.3],
    };
    let gs = r.upload(&act).unwrap();
    let g = r.render(&gs, &cam, &opts).unwrap();
    let c = cpu::render(&act, &cam, &opts);
    let (psnr, within) = compare(&g, &c);
    eprintln!(
        "demo: psnr {psnr:.2} dB, within {:.5}, timings {:?}, stats {:?}",
        within,
        r.timings(),
        r.stats()
    );
    assert!(
        psnr >= 55.0 && within >= 0.999,
        "psnr {psnr}, within {within}"
    );
    assert_no_validation_messages(&r);
}
