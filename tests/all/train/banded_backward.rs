//! The backward pass of frames whose buffers exceed one storage binding (issue 61, item 4):
//! under an emulated small maxStorageBufferRange the pairs' gradient records, the pixels'
//! gradients and the forward's last contributors are split into bands
//! (`render::frame::bands`), and the gradients equal the unsplit pass's on the plain
//! device bit for bit, in both blend layouts, for SH colour and for feature channels. A
//! frame no band fits is refused with the binding's sentence.

use super::gradients::{grad_scene, pixel_grads, to_f32};
use crate::common::gpu::assert_validation_clean;
use glam::Vec3;
use verisplat::core::camera::Camera;
use verisplat::core::model::grad::{SplatGrads, SplatParams, GRAD_GROUPS};
use verisplat::cpu::RenderOptions;
use verisplat::gpu::emulate::Emulation;
use verisplat::gpu::{ContextOptions, GpuContext, GpuError};
use verisplat::render::backward::differentiable::DiffRasterizer;
use verisplat::render::forward::blend::BlendKernel;
use verisplat::render::GpuRenderer;

/// A rasterizer on lavapipe under `emulate` ("" for the plain device) with `kernel`'s blend
/// (None: the device's own), reading the projected quantities' gradients back too.
fn rasterizer(emulate: &str, kernel: Option<BlendKernel>) -> DiffRasterizer {
    let ctx = GpuContext::new(&ContextOptions {
        validation: true,
        emulate: Emulation::parse(emulate).expect("an emulation list"),
        ..Default::default()
    })
    .expect("a Vulkan device (lavapipe) with the validation layer");
    let kernel = kernel.filter(|k| k.fits(ctx.info()));
    let renderer = match kernel {
        Some(k) => GpuRenderer::with_blend_kernel(ctx, k),
        None => GpuRenderer::new(ctx),
    }
    .expect("pipelines build");
    let mut r = DiffRasterizer::with_renderer(renderer);
    r.renderer().set_screen_grads(true).unwrap();
    r
}

/// 128x200: 16-byte colour gradients make 2 KiB rows and the last contributors 1 KiB rows.
fn camera() -> Camera {
    Camera::look_at(
        "banded",
        128,
        200,
        0.9,
        Vec3::new(0.4, -0.3, -3.0),
        Vec3::ZERO,
        Vec3::new(0.0, -1.0, 0.0),
    )
}

fn bits(g: &SplatGrads<f32>) -> Vec<u64> {
    GRAD_GROUPS
        .iter()
        .flat_map(|group| g.group(group))
        .chain(g.screen.iter().flatten().map(|&x| f64::from(x)))
        .map(f64::to_bits)
        .collect()
}

/// The frame's pixels and the gradients of `p` on `r`.
fn frame_and_grads(
    r: &mut DiffRasterizer,
    p: &SplatParams<f32>,
    cam: &Camera,
    opts: &RenderOptions,
    seed: u64,
) -> Result<(Vec<u32>, SplatGrads<f32>), GpuError> {
    let g = to_f32(&pixel_grads(cam, p.channels(), seed, true));
    let (frame, token) = r.forward(p, cam, opts)?;
    let grads = r.backward(p, cam, opts, token, &g)?;
    let pixels = frame
        .features
        .iter()
        .chain(&frame.alpha)
        .chain(&frame.depth)
        .map(|x| x.to_bits())
        .collect();
    Ok((pixels, grads))
}

#[test]
fn the_backward_in_bands_equals_the_backward_in_one_piece_bit_for_bit() {
    let cam = camera();
    let opts = RenderOptions {
        background: [0.2, 0.4, 0.1],
        ..Default::default()
    };
    for kernel in [None, Some(BlendKernel::Shared)] {
        let mut plain = rasterizer("", kernel);
        // 128 KiB bindings: 2,688 pair records of 48 bytes a band, 64 rows of colour
        // gradients a band (4 bands), and the forward's last contributors in 2 bands; the
        // forward's key buffers hold 16,384 pairs, so the frame stays in one piece.
        let mut small = rasterizer("max-storage-buffer-range=128K", kernel);
        // 1 MiB: 8 feature channels (80-byte records) in bands of 13,056 pairs. (Their
        // pixel gradients take 32 bytes a pixel, as the forward's feature images do, which
        // it binds whole: a feature frame the forward draws needs no pixel bands.)
        let mut features = rasterizer("max-storage-buffer-range=1M", kernel);
        let sh = grad_scene(200, 6100, Some(3), 3);
        let direct = grad_scene(1000, 6101, None, 8);
        let plain_opts = RenderOptions::default();
        for (name, r, p, opts, want_row_bands) in [
            ("SH colour at 128 KiB", &mut small, &sh, &opts, 4),
            (
                "8 feature channels at 1 MiB",
                &mut features,
                &direct,
                &plain_opts,
                1,
            ),
        ] {
            let (want_pixels, want) = frame_and_grads(&mut plain, p, &cam, opts, 61).unwrap();
            assert_eq!(plain.renderer().backward_bands(), (1, 1), "{name}");
            let (pairs, bin) = (
                plain.renderer().stats().pairs,
                plain.renderer().stats().bin_size,
            );
            let (pixels, got) = frame_and_grads(r, p, &cam, opts, 61).unwrap();
            // The same lists (a frame whose keys outgrow the binding goes to larger bins).
            assert_eq!(r.renderer().stats().pairs, pairs, "{name}");
            assert_eq!(r.renderer().stats().bin_size, bin, "{name}");
            let (row_bands, pair_bands) = r.renderer().backward_bands();
            eprintln!(
                "{name} ({kernel:?}): {pairs} pairs, {row_bands} pixel bands, {pair_bands} pair bands"
            );
            assert_eq!(row_bands, want_row_bands, "{name}");
            assert!(pair_bands >= 2, "{name}: {pair_bands} pair bands");
            assert!(
                r.renderer().stats().chunks <= 1,
                "{name}: the forward went in chunks"
            );
            assert!(pixels == want_pixels, "{name}: the frames differ");
            let (a, b) = (bits(&got), bits(&want));
            assert!(a.iter().any(|&x| x != 0), "{name}: all gradients are zero");
            let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
            assert!(
                a.len() == b.len() && differ == 0,
                "{name}: {differ} of {} gradient values differ from one piece's",
                a.len()
            );
            assert_validation_clean(r.renderer());
        }
        // 64 KiB: 64 rows of colour gradients (128 KiB) fit no binding: refused with the
        // binding's sentence.
        let mut tiny = rasterizer("max-storage-buffer-range=64K", kernel);
        let few = grad_scene(20, 6102, Some(3), 3);
        let e = frame_and_grads(&mut tiny, &few, &cam, &opts, 61).unwrap_err();
        let text = e.to_string();
        assert!(
            matches!(e, GpuError::DeviceLimit { .. })
                && text
                    .contains("pixel colour gradients (64 rows of 128 pixels) needs 131072 bytes"),
            "{text}"
        );
        assert_validation_clean(tiny.renderer());
    }
}
