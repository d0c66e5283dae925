//! The training loss `L = 0.8 L1 + 0.2 (1 - SSIM)` (`verisplat::train::loss`): the f64
//! reference's gradient against central finite differences, its SSIM against the eval
//! metric, and the device's loss and gradient against the reference, bit-identical run
//! after run.
//!
//! Tolerances: the loss is smooth away from x == y (random images never meet it) and
//! central differences in f64 with h = 1e-6 are accurate to ~1e-9 relative, so 1e-6
//! catches any wrong term. The device works in f32 (moments E[x^2] - mx^2 cancel digits):
//! 1e-3 relative L2 for the gradient, as the backward pass's other checks.

use crate::common::{gpu::assert_validation_clean, Rng};
use verisplat::core::model::grad::relative_l2;
use verisplat::train::loss::{loss_reference, loss_reference_masked, GpuLoss, LAMBDA_DSSIM};

fn image(width: usize, height: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng(seed);
    // Smooth structure plus noise, as rendered and photographed images have.
    (0..width * height * 3)
        .map(|i| {
            let (p, c) = (i / 3, i % 3);
            let (x, y) = ((p % width) as f32, (p / width) as f32);
            let v =
                0.5 + 0.3 * ((0.3 * x + c as f32).sin() * (0.2 * y).cos()) + rng.range(-0.15, 0.15);
            v.clamp(0.0, 1.0) as f64
        })
        .collect()
}

#[test]
fn reference_loss_gradient_matches_finite_differences() {
    let (w, h) = (19, 14);
    let (x, y) = (image(w, h, 1), image(w, h, 2));
    let lambda = LAMBDA_DSSIM as f64;
    let (value, grad) = loss_reference(&x, &y, w, h, 3, lambda);
    // Its SSIM is the eval metric's (symmetric in its images).
    let f32s = |v: &[f64]| v.iter().map(|&a| a as f32).collect::<Vec<f32>>();
    let metric = verisplat::io::metrics::ssim(&f32s(&y), &f32s(&x), w, h, 3);
    assert!(
        (value.ssim - metric).abs() < 1e-6,
        "{} vs {metric}",
        value.ssim
    );
    assert!(
        (value.total - ((1.0 - lambda) * value.l1 + lambda * (1.0 - value.ssim))).abs() < 1e-15
    );
    // Every value's derivative (corners, edges and the inside all differ: zero padding).
    let step = 1e-6;
    let fd: Vec<f64> = (0..x.len())
        .map(|i| {
            let (mut plus, mut minus) = (x.clone(), x.clone());
            plus[i] += step;
            minus[i] -= step;
            let lp = loss_reference(&plus, &y, w, h, 3, lambda).0.total;
            let lm = loss_reference(&minus, &y, w, h, 3, lambda).0.total;
            (lp - lm) / (2.0 * step)
        })
        .collect();
    let err = relative_l2(&grad, &fd);
    eprintln!("loss gradient: relative L2 error {err:.2e} against finite differences");
    assert!(err < 1e-6, "relative L2 error {err:e}");
    // The SSIM part alone (lambda = 1) too, where L1 does not dominate.
    let (_, g1) = loss_reference(&x, &y, w, h, 3, 1.0);
    let fd1: Vec<f64> = (0..x.len())
        .step_by(7)
        .map(|i| {
            let (mut plus, mut minus) = (x.clone(), x.clone());
            plus[i] += step;
            minus[i] -= step;
            let lp = loss_reference(&plus, &y, w, h, 3, 1.0).0.total;
            let lm = loss_reference(&minus, &y, w, h, 3, 1.0).0.total;
            (lp - lm) / (2.0 * step)
        })
        .collect();
    let g1s: Vec<f64> = (0..x.len()).step_by(7).map(|i| g1[i]).collect();
    let err = relative_l2(&g1s, &fd1);
    assert!(err < 1e-6, "D-SSIM: relative L2 error {err:e}");
}

#[test]
fn device_loss_equals_the_reference_and_is_deterministic() {
    let r = crate::common::gpu::renderer();
    let ctx = r.ctx();
    let mut loss = GpuLoss::new(ctx).unwrap();
    // The window through storage buffers and through texel views (CPU devices' default).
    let mut buffers = GpuLoss::with_texel_fetch(ctx, false).unwrap();
    let mut texels = GpuLoss::with_texel_fetch(ctx, true).unwrap();
    // Odd sizes below and above the window, and one of several reduction rounds.
    for (w, h) in [(7, 5), (37, 23), (300, 160)] {
        let (x, y) = (image(w, h, 10 + w as u64), image(w, h, 20 + h as u64));
        // The reference on the f32 values the device sees.
        let ((gx, x32), (gy, y32)) = (device_rgb(&x), device_rgb(&y));
        let (want, want_grad) = loss_reference(&x32, &y32, w, h, 3, LAMBDA_DSSIM as f64);
        let (got, grad) = loss
            .compute(ctx, &gx, &gy, w as u32, h as u32, LAMBDA_DSSIM)
            .unwrap();
        eprintln!("{w}x{h}: device {got:?}, reference {want:?}");
        assert!(
            (got.l1 - want.l1).abs() <= 1e-5 * want.l1,
            "l1 {} vs {}",
            got.l1,
            want.l1
        );
        assert!(
            (got.ssim - want.ssim).abs() <= 1e-5,
            "ssim {} vs {}",
            got.ssim,
            want.ssim
        );
        assert!(
            (got.mse - want.mse).abs() <= 1e-5 * want.mse,
            "mse {} vs {}",
            got.mse,
            want.mse
        );
        let g: Vec<f64> = grad.iter().flatten().map(|&v| v as f64).collect();
        let err = relative_l2(&g, &want_grad);
        eprintln!("{w}x{h}: gradient relative L2 error {err:.2e}");
        assert!(err <= 1e-3, "{w}x{h}: relative L2 error {err:e}");
        let (again, grad2) = loss
            .compute(ctx, &gx, &gy, w as u32, h as u32, LAMBDA_DSSIM)
            .unwrap();
        assert_eq!(again.total.to_bits(), got.total.to_bits());
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&grad2), bits(&grad));
        for l in [&mut buffers, &mut texels] {
            let (v, g) = l
                .compute(ctx, &gx, &gy, w as u32, h as u32, LAMBDA_DSSIM)
                .unwrap();
            assert_eq!(v.total.to_bits(), got.total.to_bits());
            assert_eq!(bits(&g), bits(&grad), "{w}x{h}: buffers and texel views");
        }
    }
    // Mismatched sizes: an error, not a crash.
    let e = loss
        .compute(ctx, &[[0.0; 3]; 4], &[[0.0; 3]; 6], 2, 2, LAMBDA_DSSIM)
        .unwrap_err();
    assert!(e.to_string().contains("pixels"), "{e}");
    assert_validation_clean(&r);
}

/// A mask (one flag per pixel; a band and scattered pixels masked): the f64 reference's
/// gradient is the finite differences' of its loss, zero at every masked pixel (whose
/// values change nothing), and the device's loss and gradient equal the reference's with
/// the tolerances above; a mask keeping every pixel gives the unmasked bits.
#[test]
fn a_masked_loss_ignores_its_masked_pixels_on_the_device_as_in_the_reference() {
    let (w, h) = (23, 17);
    let (x, y) = (image(w, h, 5), image(w, h, 6));
    let keep: Vec<bool> = (0..w * h).map(|p| !((p % w) < 7 || p % 11 == 0)).collect();
    let lambda = LAMBDA_DSSIM as f64;
    let masked = |x: &[f64]| loss_reference_masked(x, &y, Some(&keep), w, h, 3, lambda);
    let (value, grad) = masked(&x);
    let step = 1e-6;
    let fd: Vec<f64> = (0..x.len())
        .map(|i| {
            let (mut plus, mut minus) = (x.clone(), x.clone());
            plus[i] += step;
            minus[i] -= step;
            (masked(&plus).0.total - masked(&minus).0.total) / (2.0 * step)
        })
        .collect();
    let err = relative_l2(&grad, &fd);
    eprintln!("masked loss gradient: relative L2 error {err:.2e} against finite differences");
    assert!(err < 1e-6, "relative L2 error {err:e}");
    for (i, g) in grad.iter().enumerate() {
        if !keep[i / 3] {
            assert_eq!(*g, 0.0, "value {i} is masked");
        }
    }
    // The masked pixels' values change nothing.
    let mut other = x.clone();
    for (i, v) in other.iter_mut().enumerate() {
        if !keep[i / 3] {
            *v = 1.0 - *v;
        }
    }
    assert_eq!(masked(&other).0, value);
    // L1 is the mean over the kept pixels.
    let kept = keep.iter().filter(|&&k| k).count();
    let l1: f64 = (0..x.len())
        .filter(|i| keep[i / 3])
        .map(|i| (x[i] - y[i]).abs())
        .sum::<f64>()
        / (3 * kept) as f64;
    assert!((value.l1 - l1).abs() < 1e-12, "{} vs {l1}", value.l1);
    // The device.
    let r = crate::common::gpu::renderer();
    let ctx = r.ctx();
    let mut loss = GpuLoss::new(ctx).unwrap();
    let ((gx, x32), (gy, y32)) = (device_rgb(&x), device_rgb(&y));
    let (want, want_grad) = loss_reference_masked(&x32, &y32, Some(&keep), w, h, 3, lambda);
    let (got, g) = loss
        .compute_masked(ctx, &gx, &gy, Some(&keep), w as u32, h as u32, LAMBDA_DSSIM)
        .unwrap();
    eprintln!("masked: device {got:?}, reference {want:?}");
    assert!((got.l1 - want.l1).abs() <= 1e-5 * want.l1);
    assert!((got.ssim - want.ssim).abs() <= 1e-5);
    assert!((got.mse - want.mse).abs() <= 1e-5 * want.mse);
    let g64: Vec<f64> = g.iter().flatten().map(|&v| v as f64).collect();
    let err = relative_l2(&g64, &want_grad);
    eprintln!("masked: device gradient relative L2 error {err:.2e}");
    assert!(err <= 1e-3, "relative L2 error {err:e}");
    assert!(g.iter().zip(&keep).all(|(v, &k)| k || v == &[0.0; 3]));
    let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    // The window through storage buffers and through texel views: the same bits.
    for texel in [false, true] {
        let mut other = GpuLoss::with_texel_fetch(ctx, texel).unwrap();
        let (v, g2) = other
            .compute_masked(ctx, &gx, &gy, Some(&keep), w as u32, h as u32, LAMBDA_DSSIM)
            .unwrap();
        assert_eq!(v.total.to_bits(), got.total.to_bits());
        assert_eq!(bits(&g2), bits(&g), "texel views {texel}");
    }
    // Every pixel kept: the unmasked loss's bits.
    let all = vec![true; w * h];
    let (a, ga) = loss
        .compute(ctx, &gx, &gy, w as u32, h as u32, LAMBDA_DSSIM)
        .unwrap();
    let (b, gb) = loss
        .compute_masked(ctx, &gx, &gy, Some(&all), w as u32, h as u32, LAMBDA_DSSIM)
        .unwrap();
    assert_eq!(a.total.to_bits(), b.total.to_bits());
    assert_eq!(bits(&ga), bits(&gb));
    assert_validation_clean(&r);
}

/// An image of f64 values as the device's f32 pixels, and those f32 values in f64 (what
/// the reference is given, so that it sees what the device sees).
fn device_rgb(v: &[f64]) -> (Vec<[f32; 3]>, Vec<f64>) {
    let px: Vec<[f32; 3]> = v
        .chunks_exact(3)
        .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
        .collect();
    let back = px.iter().flatten().map(|&v| v as f64).collect();
    (px, back)
}
