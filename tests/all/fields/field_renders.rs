//! Renders of the fitted field (`cpu::field`, `render::field`): the GPU against the f64
//! reference, the reference against the field evaluated directly from the Gaussians
//! (`fit::model::evaluate`, the fit's own sum) at the slice points, by quadrature along
//! the rays and by dense sampling, and all three against closed forms of one Gaussian.
//!
//! Tolerances and why:
//! - GPU vs reference: 2e-5 of the frame's largest absolute value per channel (measured
//!   at most 4.0e-6). The device sums in f32 (relative rounding ~1e-7 per term over up to
//!   a few hundred terms); a point within rounding of a support's edge (d2 = 16, where the
//!   Gaussian is 3.4e-4) could fall either side and cost 3.4e-4 of one term, which these
//!   scenes do not hit.
//! - Reference vs direct evaluation: 1e-5 relative for the slice (f32 evaluation of the
//!   fit's sum); quadrature of the integral with 20,000 midpoints per ray: 2e-6 of the
//!   largest value (measured 4.9e-7); the sampled maximum with 256 samples against 8,192:
//!   within what half a segment can lose at the peak of the narrowest Gaussian (computed
//!   in the test; measured 1.7e-2 of the channel's peak with scales down to 0.03).

use verisplat::core::camera::Camera;
use verisplat::core::scene::Scene;
use verisplat::cpu::field::{self, FieldGaussians, FieldMode};
use verisplat::cpu::SplatKernel;
use verisplat::fields::fit::model::{evaluate, Model};

use crate::common::{self, Rng};

/// A field of `n` overlapping Gaussians in the cube [-1, 1]^3 (the common random scene,
/// scales e^1.5 times larger) with `k` channels in [-1, 2).
fn field_scene(n: usize, k: usize, seed: u64, kernel: SplatKernel) -> Scene {
    let mut s = common::random_scene(n, 0, seed);
    s.kernel = kernel;
    for v in s.log_scales.iter_mut().flatten() {
        *v += 1.5;
    }
    let mut rng = Rng(seed ^ 0xF1E1D);
    let feats = (0..n * k).map(|_| rng.range(-1.0, 2.0)).collect();
    s.set_features(k, feats).unwrap();
    s
}

fn camera(w: u32, h: u32) -> Camera {
    Camera::look_at(
        "field",
        w,
        h,
        50f32.to_radians(),
        glam::Vec3::new(0.7, -1.2, -3.5),
        glam::Vec3::new(0.0, 0.1, 0.0),
        glam::Vec3::NEG_Y,
    )
}

const SLICE: FieldMode = FieldMode::Slice {
    point: [0.1, 0.0, 0.2],
    normal: [0.2, 0.3, 1.0],
};

/// The largest |value| of each channel (NaN skipped).
fn peaks(frame: &verisplat::core::frame::Frame) -> Vec<f32> {
    let k = frame.feature_count;
    (0..k)
        .map(|c| {
            frame.features[c..]
                .iter()
                .step_by(k)
                .filter(|v| !v.is_nan())
                .fold(0f32, |m, v| m.max(v.abs()))
        })
        .collect()
}

#[test]
fn gpu_field_renders_match_the_reference() {
    let r = common::gpu::renderer();
    let ctx = r.ctx();
    for kernel in SplatKernel::ALL {
        // 5 channels: two groups of four, the second padded.
        let scene = field_scene(300, 5, 7, kernel);
        let g = FieldGaussians::new(&scene.activated(), kernel);
        let gpu_field = verisplat::render::field::GpuField::new(ctx, &g).unwrap();
        let mut renderer = verisplat::render::field::FieldRenderer::new(kernel);
        let cam = camera(45, 37);
        for mode in [SLICE, FieldMode::Integral, FieldMode::Max { samples: 96 }] {
            let cpu = field::render_field(&g, &cam, &mode);
            let gpu = renderer.render(ctx, &gpu_field, &cam, &mode).unwrap();
            assert_eq!(gpu.features.len(), cpu.features.len());
            assert_eq!(
                gpu.alpha, cpu.alpha,
                "{kernel:?} {mode:?}: the same pixels are empty"
            );
            let peak = peaks(&cpu);
            let mut worst = 0f32;
            for (i, (a, b)) in gpu.features.iter().zip(&cpu.features).enumerate() {
                if b.is_nan() {
                    assert!(a.is_nan(), "{kernel:?} {mode:?} value {i}: {a} where empty");
                    continue;
                }
                worst = worst.max((a - b).abs() / peak[i % 5]);
            }
            eprintln!(
                "{kernel:?} {mode:?}: largest GPU-reference difference {worst:.2e} of the peak"
            );
            assert!(worst <= 2e-5, "{kernel:?} {mode:?}: {worst}");
            assert!(
                peak.iter().all(|&p| p > 0.1),
                "{mode:?} renders a field: {peak:?}"
            );
        }
    }
    common::gpu::assert_validation_clean(&r);
}

/// The field by the fit's own sum at `points` (f32), `k` each.
fn direct(scene: &Scene, points: &[[f64; 3]]) -> Vec<f32> {
    let p: Vec<[f32; 3]> = points.iter().map(|p| p.map(|v| v as f32)).collect();
    evaluate(&Model::from_scene(scene), scene.kernel, &p)
}

#[test]
fn reference_field_renders_match_the_field_evaluated_from_the_gaussians() {
    let kernel = SplatKernel::Gaussian;
    let scene = field_scene(120, 2, 11, kernel);
    let g = FieldGaussians::new(&scene.activated(), kernel);
    let cam = camera(12, 9);
    let k = 2;
    // Slice: the field at each pixel's plane point.
    let slice = field::render_field(&g, &cam, &SLICE);
    let (mut points, mut pixels) = (Vec::new(), Vec::new());
    for py in 0..cam.height {
        for px in 0..cam.width {
            let (o, d) = field::pixel_ray(&cam, px, py);
            if let FieldMode::Slice { point, normal } = SLICE {
                if let Some(t) = field::slice_hit(o, d, point, normal) {
                    points.push([o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]);
                    pixels.push((py * cam.width + px) as usize);
                }
            }
        }
    }
    assert!(pixels.len() > 50, "most rays meet the plane");
    let f = direct(&scene, &points);
    let peak = peaks(&slice);
    for (n, &p) in pixels.iter().enumerate() {
        for c in 0..k {
            let (a, b) = (slice.features[p * k + c], f[n * k + c]);
            assert!(
                (a - b).abs() <= 1e-5 * peak[c].max(1.0),
                "slice pixel {p} channel {c}: {a} vs {b}"
            );
        }
    }
    // Integral and maximum: midpoint quadrature and dense sampling of the direct sum over
    // each ray's chord through the field's box.
    let integral = field::render_field(&g, &cam, &FieldMode::Integral);
    let max = field::render_field(&g, &cam, &FieldMode::Max { samples: 256 });
    let (ip, mp) = (peaks(&integral), peaks(&max));
    let (mut worst_i, mut worst_m) = (0f64, 0f64);
    for py in (0..cam.height).step_by(2) {
        for px in (0..cam.width).step_by(2) {
            let (o, d) = field::pixel_ray(&cam, px, py);
            let p = (py * cam.width + px) as usize;
            let Some((t_in, t_out)) = field::chord(o, d, g.bounds) else {
                assert!(max.features[p * k].is_nan());
                assert_eq!(integral.features[p * k], 0.0);
                continue;
            };
            let n = 20_000;
            let dt = (t_out - t_in) / n as f64;
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|j| {
                    let t = t_in + (j as f64 + 0.5) * dt;
                    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
                })
                .collect();
            let f = direct(&scene, &pts);
            for c in 0..k {
                let sum: f64 = (0..n).map(|j| f64::from(f[j * k + c])).sum::<f64>() * dt;
                let err = (sum - f64::from(integral.features[p * k + c])).abs() / f64::from(ip[c]);
                worst_i = worst_i.max(err);
                let dense = (0..n)
                    .step_by(n / 8192)
                    .map(|j| f[j * k + c])
                    .fold(f32::MIN, f32::max);
                let err = f64::from((dense - max.features[p * k + c]).abs() / mp[c]);
                worst_m = worst_m.max(err);
            }
        }
    }
    // The sampled maximum lies at most half a segment from a peak: for a peak of the
    // narrowest Gaussian (scale s) that loses at most 1 - exp(-(h / s)^2 / 2) of it, h half
    // the longest chord (the box's diagonal) over 256.
    let b = g.bounds;
    let diag = ((b[3] - b[0]).powi(2) + (b[4] - b[1]).powi(2) + (b[5] - b[2]).powi(2)).sqrt();
    let narrowest = scene
        .log_scales
        .iter()
        .flatten()
        .fold(f64::INFINITY, |m, &v| m.min(f64::from(v).exp()));
    let h = 0.5 * diag / 256.0;
    let bound = 1.0 - (-(h / narrowest).powi(2) / 2.0).exp();
    eprintln!("integral vs quadrature {worst_i:.2e}, maximum (256 samples) vs dense {worst_m:.2e} of the peak (bound {bound:.2e})");
    assert!(worst_i <= 2e-6, "integral vs quadrature: {worst_i}");
    assert!(
        worst_m <= bound,
        "maximum vs dense sampling: {worst_m} > {bound}"
    );
}

#[test]
fn one_gaussian_gives_the_closed_forms() {
    // One isotropic Gaussian of scale s at the origin, opacity o, feature 1, seen along +z
    // from z = -5 through its centre: slice z = 0 gives o exp(-r^2 / 2 s^2); the integral
    // through the centre o s sqrt(2 pi) erf(2 sqrt 2) (truncated at 4 sigma), through an
    // offset b o s sqrt(2 pi) exp(-b^2 / 2 s^2) erf(sqrt((16 - b^2/s^2) / 2)); the maximum o
    // on the axis.
    let (s, o) = (0.3f64, 0.8f64);
    let mut scene = Scene::empty(0);
    common::push_gaussian(&mut scene, [0.0, 0.0, 0.0], s as f32, o as f32, [0.5; 3]);
    scene.set_features(1, vec![1.0]).unwrap();
    let g = FieldGaussians::new(&scene.activated(), SplatKernel::Gaussian);
    let mut cam = common::axis_camera(64.0);
    cam.translation = glam::Vec3::new(0.0, 0.0, 5.0); // centre at z = -5
    let slice = FieldMode::Slice {
        point: [0.0; 3],
        normal: [0.0, 0.0, 1.0],
    };
    let erf = |x: f64| field::erf(x);
    let (sf, inf, mf) = (
        field::render_field(&g, &cam, &slice),
        field::render_field(&g, &cam, &FieldMode::Integral),
        field::render_field(&g, &cam, &FieldMode::Max { samples: 255 }),
    );
    for px in [32u32, 36, 40] {
        let (ro, d) = field::pixel_ray(&cam, px, 32);
        let t = 5.0 / d[2];
        let r = (ro[0] + t * d[0]).hypot(ro[1] + t * d[1]);
        let expect = o * (-r * r / (2.0 * s * s)).exp();
        let got = f64::from(sf.features[sf.index(px, 32)]);
        assert!(
            (got - expect).abs() < 1e-6,
            "slice at r {r}: {got} vs {expect}"
        );
        // Closest approach of the ray to the origin.
        let b = (ro[0].powi(2) + ro[1].powi(2) + ro[2].powi(2)
            - (ro[0] * d[0] + ro[1] * d[1] + ro[2] * d[2]).powi(2))
        .sqrt();
        let q = b * b / (s * s);
        let expect = o
            * s
            * (2.0 * std::f64::consts::PI).sqrt()
            * (-q / 2.0).exp()
            * erf(((16.0 - q) / 2.0).sqrt());
        let got = f64::from(inf.features[inf.index(px, 32)]);
        assert!(
            (got - expect).abs() < 1e-6 * expect.max(1e-3),
            "integral at b {b}: {got} vs {expect}"
        );
        let expect = o * (-q / 2.0).exp();
        let got = f64::from(mf.features[mf.index(px, 32)]);
        // 255 samples over the chord (2.4 long): the peak is at most half a segment away.
        let half = 2.4 / 255.0 / 2.0 / s;
        assert!(
            got <= expect + 1e-6 && got >= expect * (-half * half / 2.0).exp() - 1e-6,
            "maximum at b {b}: {got} vs {expect}"
        );
    }
}

/// The field options: each refused where it does not apply, with one sentence and no file.
#[test]
fn field_options_are_refused_where_they_do_not_apply() {
    use crate::common::cli::{fails, s};
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("f.ply");
    let scene = field_scene(20, 2, 3, SplatKernel::Gaussian);
    std::fs::write(
        &ply,
        verisplat::io::scene::ply::to_bytes(
            &scene,
            verisplat::io::scene::ply::PlyEncoding::BinaryLittleEndian,
        ),
    )
    .unwrap();
    let png = dir.path().join("o.png");
    let npy = dir.path().join("o.npy");
    for (args, out, says) in [
        (
            vec!["--mode", "field-slice"],
            &png,
            "needs the plane: --slice-plane",
        ),
        (
            vec!["--mode", "field-max", "--slice-plane", "0,0,0,0,0,1"],
            &png,
            "--slice-plane applies to --mode field-slice",
        ),
        (
            vec!["--mode", "field-integral", "--max-samples", "9"],
            &png,
            "--max-samples applies to --mode field-max",
        ),
        (
            vec!["--slice-plane", "0,0,0,0,0,1"],
            &png,
            "applies to the field renders",
        ),
        (
            vec!["--mode", "field-max", "--range", "0,1"],
            &npy,
            "--range sets the colour map of a field render's PNG",
        ),
        (
            vec!["--mode", "field-max", "--units", "V/m"],
            &png,
            "add --colorbar",
        ),
        (
            vec!["--mode", "field-max", "--channel", "2"],
            &png,
            "--channel 2 is not a channel of the scene, which has 2",
        ),
        (
            vec!["--mode", "field-max", "--compact"],
            &png,
            "--compact does not apply to --mode field-max",
        ),
    ] {
        let mut a = vec!["render", s(&ply), "-o", s(out)];
        a.extend(args.iter().copied());
        let e = fails(&a, out);
        assert!(e.contains(says), "{args:?}: {e}");
    }
    // Values checked while parsing the command line (clap adds its usage lines).
    for (args, says) in [
        (["--slice-plane", "0,0,0,0,0,0"], "must not be 0,0,0"),
        (["--range", "1,0"], "LO must be below HI"),
    ] {
        let mut a = vec!["render", s(&ply), "-o", s(&png), "--mode", "field-slice"];
        a.extend(args);
        let o = crate::common::cli::verisplat(&a);
        let e = crate::common::cli::stderr(&o);
        assert!(
            !o.status.success() && e.starts_with("error: ") && e.contains(says),
            "{e}"
        );
        assert!(!e.contains("panicked") && !png.exists(), "{e}");
    }
    // A scene without features has no field.
    let bare = dir.path().join("bare.ply");
    let mut plain = scene.clone();
    plain.set_features(0, Vec::new()).unwrap();
    std::fs::write(
        &bare,
        verisplat::io::scene::ply::to_bytes(
            &plain,
            verisplat::io::scene::ply::PlyEncoding::BinaryLittleEndian,
        ),
    )
    .unwrap();
    let e = fails(
        &[
            "render",
            s(&bare),
            "-o",
            s(&npy),
            "--mode",
            "field-integral",
        ],
        &npy,
    );
    assert!(e.contains("has none"), "{e}");
}

/// 40,000 Gaussians on every ray, more than llvmpipe's 65,535 loop iterations per
/// invocation allow in one pass: a slice and an integral are split into passes that add up
/// and still match the reference (1e-5 of the peak: f32 sums of 40,000 terms); a maximum,
/// whose per-sample sums cannot be split, is refused on such a device instead of being
/// returned cut short (elsewhere it matches the reference).
#[test]
fn many_gaussians_on_a_ray_render_in_passes_or_are_refused() {
    let r = common::gpu::renderer();
    let ctx = r.ctx();
    let n = 40_000;
    let mut rng = Rng(9);
    let mut scene = Scene::empty(0);
    for _ in 0..n {
        let p = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ];
        common::push_gaussian(&mut scene, p, 0.5, 0.5, [0.5; 3]);
    }
    scene.set_features(1, vec![1.0; n]).unwrap();
    let g = FieldGaussians::new(&scene.activated(), SplatKernel::Gaussian);
    let gpu_field = verisplat::render::field::GpuField::new(ctx, &g).unwrap();
    let mut renderer = verisplat::render::field::FieldRenderer::new(SplatKernel::Gaussian);
    let cam = camera(8, 6);
    for mode in [SLICE, FieldMode::Integral, FieldMode::Max { samples: 16 }] {
        let gpu = renderer.render(ctx, &gpu_field, &cam, &mode);
        if matches!(mode, FieldMode::Max { .. }) && ctx.info().loop_limited() {
            // Each pixel's ray meets all 40,000 Gaussians, each adding into ~16 samples.
            let Err(e) = gpu else {
                panic!("a cut-off maximum is refused");
            };
            let e = e.to_string();
            assert!(e.contains("65,535") && e.contains("--cpu"), "{e}");
            continue;
        }
        let gpu = gpu.unwrap();
        let cpu = field::render_field(&g, &cam, &mode);
        let peak = peaks(&cpu)[0];
        for (a, b) in gpu.features.iter().zip(&cpu.features) {
            assert!(
                (a - b).abs() <= 1e-5 * peak,
                "{mode:?}: GPU {a} vs reference {b}"
            );
        }
    }
    common::gpu::assert_validation_clean(&r);
}
