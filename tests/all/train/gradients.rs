//! The differentiable rasterizer's CPU reference (`cpu::backward`, f64) against central
//! finite differences of its own forward pass, parameter group by parameter group: SH
//! degrees 0-3, both kernels, direct (feature) channels, backgrounds, depth and alpha
//! gradients, a Gaussian cut by the T < 1e-4 stop and one skipped at alpha < 1/255. Its
//! forward is checked against the f32 CPU renderer, so both follow the same rules.
//!
//! Tolerance: the loss is smooth at the tested points (a decision flipping within +-h
//! would show as an O(1) error, not a small one), and central
//! differences in f64 with h = 1e-6 have truncation error ~h^2 |f'''| and rounding error
//! ~1e-16 |L| / h ~ 1e-10 relative: a relative L2 error of 1e-6 per group leaves four
//! orders of margin and would catch any wrong term (those are O(1) relative).

use crate::common::Rng;
use glam::Vec3;
use verisplat::core::camera::Camera;
use verisplat::core::model::grad::{
    relative_l2, ColorParams, PixelGrads, SplatParams, GRAD_GROUPS,
};
use verisplat::cpu::backward::{backward, forward, Image64};
use verisplat::cpu::{RenderOptions, SplatKernel};

/// A 48x40 camera looking at the origin from about 3 units away.
pub fn grad_camera() -> Camera {
    Camera::look_at(
        "grad",
        48,
        40,
        0.9,
        Vec3::new(0.4, -0.3, -3.0),
        Vec3::ZERO,
        Vec3::new(0.0, -1.0, 0.0),
    )
}

/// `n` random Gaussians in view with SH colours of `degree`, or `channels` direct values
/// ([`verisplat::core::gen::random_splat_params`], which `verisplat doctor` uses too).
pub fn grad_scene(n: usize, seed: u64, colors: Option<u32>, channels: usize) -> SplatParams<f32> {
    verisplat::core::gen::random_splat_params(n, seed, colors, channels)
}

/// Random pixel gradients for a frame of `channels`.
pub fn pixel_grads(cam: &Camera, channels: usize, seed: u64, depth: bool) -> PixelGrads<f64> {
    let mut rng = Rng(seed);
    let px = (cam.width * cam.height) as usize;
    PixelGrads {
        color: (0..px * channels)
            .map(|_| rng.range(-1.0, 1.0) as f64)
            .collect(),
        alpha: (0..px).map(|_| rng.range(-1.0, 1.0) as f64).collect(),
        depth: if depth {
            (0..px).map(|_| 0.3 * rng.range(-1.0, 1.0) as f64).collect()
        } else {
            Vec::new()
        },
    }
}

fn loss(img: &Image64, g: &PixelGrads<f64>) -> f64 {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    dot(&img.color, &g.color) + dot(&img.alpha, &g.alpha) + dot(&img.depth, &g.depth)
}

/// Mutable access to scalar `k` of parameter group `group`.
fn scalar<'a>(p: &'a mut SplatParams<f64>, group: &str, k: usize) -> &'a mut f64 {
    match group {
        "means" => &mut p.means[k / 3][k % 3],
        "quats" => &mut p.quats[k / 4][k % 4],
        "scales" => &mut p.scales[k / 3][k % 3],
        "opacities" => &mut p.opacities[k],
        "colors" => match &mut p.colors {
            ColorParams::Sh { coeffs, .. } => &mut coeffs[k],
            ColorParams::Direct { values, .. } => &mut values[k],
        },
        _ => unreachable!("no group {group}"),
    }
}

/// Central differences of the loss for every scalar of every parameter group.
pub fn finite_differences(
    p: &SplatParams<f64>,
    cam: &Camera,
    opts: &RenderOptions,
    bg: &[f64],
    g: &PixelGrads<f64>,
) -> Vec<(&'static str, Vec<f64>)> {
    finite_differences_of(p, g, &|q| forward(q, cam, opts, bg).unwrap())
}

/// Central differences of the loss of the frames `render` makes.
fn finite_differences_of(
    p: &SplatParams<f64>,
    g: &PixelGrads<f64>,
    render: &dyn Fn(&SplatParams<f64>) -> Image64,
) -> Vec<(&'static str, Vec<f64>)> {
    let h = 1e-6;
    let n = p.len();
    let stride = p.color_stride();
    let groups: [(&str, usize); 5] = [
        ("means", n * 3),
        ("quats", n * 4),
        ("scales", n * 3),
        ("opacities", n),
        ("colors", n * stride),
    ];
    groups
        .iter()
        .map(|&(group, count)| {
            let fd = (0..count)
                .map(|k| {
                    let mut plus = p.clone();
                    *scalar(&mut plus, group, k) += h;
                    let mut minus = p.clone();
                    *scalar(&mut minus, group, k) -= h;
                    (loss(&render(&plus), g) - loss(&render(&minus), g)) / (2.0 * h)
                })
                .collect();
            (group, fd)
        })
        .collect()
}

/// Checks the reference backward against finite differences, group by group, and that the
/// gradients are not trivially zero.
fn check(p32: &SplatParams<f32>, opts: &RenderOptions, bg: &[f64], depth: bool, seed: u64) {
    check_on(&grad_camera(), p32, opts, bg, depth, seed);
}

/// [`check`] from `cam`.
pub(crate) fn check_on(
    cam: &Camera,
    p32: &SplatParams<f32>,
    opts: &RenderOptions,
    bg: &[f64],
    depth: bool,
    seed: u64,
) {
    let cam = cam.clone();
    let p = p32.to_f64();
    let g = pixel_grads(&cam, p.channels(), seed, depth);
    let grads = backward(&p, &cam, opts, bg, &g).unwrap();
    for (group, fd) in finite_differences(&p, &cam, opts, bg, &g) {
        let analytic = grads.group(group);
        let err = relative_l2(&analytic, &fd);
        let norm = fd.iter().map(|x| x * x).sum::<f64>().sqrt();
        eprintln!("{group}: relative L2 error {err:.2e}, |fd| {norm:.3e}");
        assert!(
            norm > 1e-3,
            "{group}: the finite differences are ~0 ({norm}); the scene tests nothing"
        );
        assert!(
            err < 1e-6,
            "{group}: relative L2 error {err:e} against finite differences\nanalytic {analytic:?}\nfd       {fd:?}"
        );
    }
}

#[test]
fn reference_backward_matches_finite_differences_for_sh_degrees_0_to_3() {
    for degree in 0..=3u32 {
        let p = grad_scene(8, 100 + degree as u64, Some(degree), 3);
        let opts = RenderOptions::default();
        check(&p, &opts, &[0.2, 0.5, 0.9], true, 7 + degree as u64);
    }
}

#[test]
fn reference_backward_matches_finite_differences_with_the_power_kernel() {
    let p = grad_scene(8, 200, Some(1), 3);
    let opts = RenderOptions {
        kernel: SplatKernel::Power,
        ..Default::default()
    };
    check(&p, &opts, &[0.0, 0.3, 0.0], true, 21);
}

#[test]
fn reference_backward_matches_finite_differences_for_feature_channels() {
    let p = grad_scene(7, 300, None, 5);
    check(
        &p,
        &RenderOptions::default(),
        &[0.1, 0.0, -0.2, 0.3, 0.0],
        false,
        31,
    );
    let opts = RenderOptions {
        kernel: SplatKernel::Power,
        ..Default::default()
    };
    check(&p, &opts, &[0.0; 5], true, 32);
}

#[test]
fn reference_backward_matches_finite_differences_with_options() {
    // A scale modifier and an SH degree below the stored one.
    let p = grad_scene(8, 400, Some(3), 3);
    let opts = RenderOptions {
        scale_modifier: 0.8,
        sh_degree: Some(2),
        ..Default::default()
    };
    check(&p, &opts, &[1.0, 1.0, 1.0], true, 41);
    // The antialiased opacity compensation (gsplat's rasterize_mode="antialiased").
    let opts = RenderOptions {
        antialiased: true,
        ..Default::default()
    };
    check(&p, &opts, &[0.2, 0.1, 0.0], true, 42);
}

/// A stack of near-opaque Gaussians stops pixels at T < 1e-4 (the Gaussians behind are
/// cut there), and a faint one (opacity below 1/255) is skipped everywhere: its gradient is
/// exactly zero, as are its finite differences.
#[test]
fn reference_backward_handles_the_transmittance_stop_and_the_alpha_skip() {
    let cam = grad_camera();
    let mut p = grad_scene(6, 500, Some(1), 3);
    let mut stack = |z: f32, o: f32, s: f32| {
        p.means.push([0.05, 0.02, z]);
        p.quats.push([1.0, 0.1, 0.0, 0.0]);
        p.scales.push([s, s * 0.9, s]);
        p.opacities.push(o);
        if let ColorParams::Sh { coeffs, .. } = &mut p.colors {
            coeffs.extend([
                0.8, -0.3, 0.4, 0.1, 0.2, -0.1, 0.0, 0.1, 0.2, -0.2, 0.1, 0.0,
            ]);
        }
    };
    for (k, z) in [-1.2f32, -1.1, -1.0, -0.9].iter().enumerate() {
        stack(*z, 0.985 - 0.01 * k as f32, 0.35);
    }
    stack(-1.3, 0.003, 0.4); // below 1/255 everywhere
    let faint = p.len() - 1;
    let p64 = p.to_f64();
    let opts = RenderOptions::default();
    // The stop happens: some pixels end with T in [1e-4 / (1 - 0.99), ...): alpha above
    // 1 - 1e-2 after three or four of the stacked Gaussians, and the last one is cut.
    let img = forward(&p64, &cam, &opts, &[0.0; 3]).unwrap();
    let stopped = img.alpha.iter().filter(|&&a| 1.0 - a < 1e-3).count();
    assert!(stopped > 10, "only {stopped} pixels end near T = 1e-4");
    let g = pixel_grads(&cam, 3, 51, true);
    let grads = backward(&p64, &cam, &opts, &[0.0, 0.0, 0.0], &g).unwrap();
    assert_eq!(grads.opacities[faint], 0.0);
    assert_eq!(grads.means[faint], [0.0; 3]);
    check(&p, &opts, &[0.0, 0.0, 0.0], true, 51);
}

/// Gaussians whose centres lie outside the guard band (|x/z| > 1.3 tan(fov/2)), large
/// enough to reach into the frame: their Jacobian uses the clamped position, whose
/// derivative moves from x to z.
/// A few random Gaussians and two whose centres lie outside the guard band of `cam`
/// (|x/z| > 1.3 tan(fov/2)), large enough to reach into the frame.
pub(crate) fn guard_band_scene(cam: &Camera) -> SplatParams<f32> {
    let mut p = grad_scene(4, 1000, Some(1), 3);
    let lim_x = 1.3 * cam.tan_half_fov_x();
    let lim_y = 1.3 * cam.tan_half_fov_y();
    // At different depths: equal depths would make their order, and the loss, jump under
    // a perturbation.
    let beyond = [
        Vec3::new(1.25 * lim_x * 3.0, 0.1, 3.0),
        Vec3::new(-0.2, -1.3 * lim_y * 3.4, 3.4),
    ];
    push_large_gaussians(&mut p, cam, beyond);
    p
}

/// Adds to `p` a large Gaussian (SH degree 1) at each camera-space point of `cam` in
/// `centres`.
pub(crate) fn push_large_gaussians<const N: usize>(
    p: &mut SplatParams<f32>,
    cam: &Camera,
    centres: [Vec3; N],
) {
    let to_world = |v: Vec3| cam.rotation.transpose() * (v - cam.translation);
    for (k, v) in centres.into_iter().enumerate() {
        p.means.push(to_world(v).to_array());
        p.quats.push([1.0, 0.2 * k as f32, 0.1, -0.1]);
        p.scales.push([0.9, 0.7, 0.5]);
        p.opacities.push(0.8);
        if let ColorParams::Sh { coeffs, .. } = &mut p.colors {
            coeffs.extend([
                0.6, 0.2, -0.1, 0.1, 0.0, 0.2, -0.1, 0.1, 0.0, 0.2, 0.1, -0.2,
            ]);
        }
    }
}

/// Outside the guard band the Jacobian uses the clamped position, whose derivative moves
/// from x to z.
#[test]
fn reference_backward_matches_finite_differences_at_the_guard_band() {
    let cam = grad_camera();
    let p = guard_band_scene(&cam);
    // Both reach the frame: their gradients are not zero.
    let g = pixel_grads(&cam, 3, 101, true);
    let grads = backward(&p.to_f64(), &cam, &RenderOptions::default(), &[0.0; 3], &g).unwrap();
    let n = p.len();
    for i in [n - 2, n - 1] {
        assert!(
            grads.means[i].iter().any(|&x| x != 0.0),
            "Gaussian {i} reaches no pixel"
        );
    }
    check(&p, &RenderOptions::default(), &[0.0; 3], true, 101);
}

/// The neural shader (`render --shader`): features blended, then an MLP per pixel (tanh,
/// relu, sigmoid; features, view direction and alpha in), composited over a background.
/// Its reference backward against finite differences, for the Gaussians and the MLP.
/// A random neural shader of `k` feature channels (and, with `extra`, the view direction
/// and alpha as inputs): tanh, relu and sigmoid layers of `hidden` and 6 outputs.
fn random_mlp(k: usize, extra: bool, hidden: usize, seed: u64) -> verisplat::fields::mlp::Mlp {
    use verisplat::fields::mlp::{Activation, Layer, Mlp, MlpInput};
    let mut rng = Rng(seed);
    let mut layer = |inputs: usize, outputs: usize, activation| Layer {
        inputs,
        outputs,
        weight: (0..inputs * outputs)
            .map(|_| rng.range(-0.8, 0.8))
            .collect(),
        bias: (0..outputs).map(|_| rng.range(-0.3, 0.3)).collect(),
        activation,
    };
    let (inputs, width) = match extra {
        true => (
            vec![MlpInput::Features, MlpInput::ViewDir, MlpInput::Alpha],
            k + 4,
        ),
        false => (vec![MlpInput::Features], k),
    };
    Mlp {
        inputs,
        layers: vec![
            layer(width, hidden, Activation::Tanh),
            layer(hidden, 6, Activation::Relu),
            layer(6, 3, Activation::Sigmoid),
        ],
    }
}

#[test]
fn reference_backward_of_a_shaded_frame_matches_finite_differences() {
    use verisplat::cpu::backward::{backward_shaded, forward_shaded, MlpParams};
    let cam = grad_camera();
    let k = 4;
    let p = grad_scene(8, 1300, None, k).to_f64();
    let mlp = random_mlp(k, true, 8, 1301);
    let w = MlpParams::of(&mlp);
    let opts = RenderOptions::default();
    let bg = [0.2, 0.1, 0.4];
    // The f64 shaded frame is the f32 renderer's (`cpu::render_features` + `mlp::shade`).
    let p32 = grad_scene(8, 1300, None, k);
    let frame = verisplat::cpu::render_features(&p32.to_activated(), &cam, &opts);
    let shaded = verisplat::fields::mlp::shade(
        &mlp,
        &cam,
        &frame.features,
        k,
        &frame.alpha,
        [0.2, 0.1, 0.4],
    );
    let img = forward_shaded(&p, &cam, &opts, &mlp, &w, bg).unwrap();
    let worst = shaded
        .iter()
        .flatten()
        .zip(&img.color)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-4,
        "the f64 shaded frame differs from the renderer's by {worst}"
    );
    let g = pixel_grads(&cam, 3, 131, true);
    let (grads, g_mlp) = backward_shaded(&p, &cam, &opts, &mlp, &w, bg, &g).unwrap();
    for (group, fd) in finite_differences_of(&p, &g, &|q| {
        forward_shaded(q, &cam, &opts, &mlp, &w, bg).unwrap()
    }) {
        let err = relative_l2(&grads.group(group), &fd);
        eprintln!("shaded {group}: relative L2 error {err:.2e}");
        assert!(err < 1e-6, "{group}: relative L2 error {err:e}");
    }
    // The MLP's weights and biases, layer by layer.
    let h = 1e-6;
    let loss_with =
        |w: &MlpParams<f64>| loss(&forward_shaded(&p, &cam, &opts, &mlp, w, bg).unwrap(), &g);
    for l in 0..mlp.layers.len() {
        for (name, analytic, count) in [
            ("weights", &g_mlp.weights[l], w.weights[l].len()),
            ("biases", &g_mlp.biases[l], w.biases[l].len()),
        ] {
            let fd: Vec<f64> = (0..count)
                .map(|j| {
                    let (mut plus, mut minus) = (w.clone(), w.clone());
                    let (a, b) = match name {
                        "weights" => (&mut plus.weights[l][j], &mut minus.weights[l][j]),
                        _ => (&mut plus.biases[l][j], &mut minus.biases[l][j]),
                    };
                    *a += h;
                    *b -= h;
                    (loss_with(&plus) - loss_with(&minus)) / (2.0 * h)
                })
                .collect();
            let err = relative_l2(analytic, &fd);
            eprintln!("shaded layer {l} {name}: relative L2 error {err:.2e}");
            assert!(
                fd.iter().any(|&x| x != 0.0),
                "layer {l} {name}: zero gradient"
            );
            assert!(err < 1e-6, "layer {l} {name}: relative L2 error {err:e}");
        }
    }
}

/// The largest difference of any colour channel or alpha between the f32 renderer's
/// frame and the f64 reference's (3 channels).
pub(crate) fn largest_difference(frame: &verisplat::core::frame::Frame, img: &Image64) -> f64 {
    let mut worst = 0.0f64;
    for (i, c) in frame.color.iter().enumerate() {
        for (ch, v) in c.iter().enumerate() {
            worst = worst.max((*v as f64 - img.color[i * 3 + ch]).abs());
        }
        worst = worst.max((frame.alpha[i] as f64 - img.alpha[i]).abs());
    }
    worst
}

/// The f64 reference follows the f32 renderer's rules: same image up to rounding.
#[test]
fn reference_forward_equals_the_cpu_renderer() {
    let cam = grad_camera();
    let p = grad_scene(30, 600, Some(3), 3);
    let opts = RenderOptions {
        background: [0.1, 0.2, 0.3],
        ..Default::default()
    };
    let frame = verisplat::cpu::render(&p.to_activated(), &cam, &opts);
    let img = forward(&p.to_f64(), &cam, &opts, &[0.1, 0.2, 0.3]).unwrap();
    let worst = largest_difference(&frame, &img);
    assert!(worst < 1e-4, "largest difference {worst}");
    assert!(
        img.alpha.iter().filter(|&&a| a > 0.5).count() > 100,
        "the frame is mostly empty"
    );
}

/// Every group the comparisons walk is covered by `SplatGrads::group`.
#[test]
fn every_gradient_group_has_values() {
    let p = grad_scene(3, 700, Some(0), 3).to_f64();
    let cam = grad_camera();
    let g = pixel_grads(&cam, 3, 71, false);
    let grads = backward(&p, &cam, &RenderOptions::default(), &[0.0; 3], &g).unwrap();
    for group in GRAD_GROUPS {
        assert!(!grads.group(group).is_empty(), "{group}");
    }
}

// ---- The Vulkan backward pass against the reference -------------------------------------
//
// Tolerance: relative L2 error <= 1e-3 per parameter group, the figure. The device
// computes in f32 (about 1e-7 relative per operation) and undoes each pixel's transmittance
// by division, as gsplat does; over the ~10-50 Gaussians a pixel composites and the sums
// over pixels that errors reach ~1e-5 relative. A pixel where f32 and f64 decide the 1/255
// skip differently (alpha within ~1e-7 of it) shifts its gradients by about the skipped
// alpha, 0.4 %, on one pixel of thousands. Any wrong term is an O(1) error.

use crate::common::gpu::{assert_validation_clean, new_renderer};
use verisplat::render::backward::differentiable::{Accumulation, DiffRasterizer};
use verisplat::render::forward::blend::BlendKernel;

pub(crate) fn to_f32(g: &PixelGrads<f64>) -> PixelGrads<f32> {
    let f = |v: &Vec<f64>| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    PixelGrads {
        color: f(&g.color),
        alpha: f(&g.alpha),
        depth: f(&g.depth),
    }
}

/// GPU gradients and the reference's for one scene; returns the GPU's.
pub(crate) fn gpu_against_reference(
    r: &mut DiffRasterizer,
    p: &SplatParams<f32>,
    cam: &Camera,
    opts: &RenderOptions,
    seed: u64,
) -> verisplat::core::model::grad::SplatGrads<f32> {
    let mut bg: Vec<f64> = opts.background.iter().map(|&b| b as f64).collect();
    bg.resize(p.channels(), 0.0);
    let g = pixel_grads(cam, p.channels(), seed, true);
    let (_, token) = r.forward(p, cam, opts).unwrap();
    let gpu = r.backward(p, cam, opts, token, &to_f32(&g)).unwrap();
    let cpu = backward(&p.to_f64(), cam, opts, &bg, &g).unwrap();
    for group in GRAD_GROUPS {
        let (a, b) = (gpu.group(group), cpu.group(group));
        eprintln!("GPU {group}: relative L2 error {:.2e}", relative_l2(&a, &b));
    }
    for group in GRAD_GROUPS {
        let (a, b) = (gpu.group(group), cpu.group(group));
        let err = relative_l2(&a, &b);
        assert!(
            b.iter().any(|&x| x != 0.0),
            "{group}: the reference gradient is zero; the scene tests nothing"
        );
        assert!(
            err <= 1e-3,
            "{group}: relative L2 error {err:e} against the reference"
        );
    }
    assert_validation_clean(r.renderer());
    gpu
}

/// A rasterizer whose backward passes also read the projected quantities' gradients
/// back (`SplatGrads::screen`, compared with the reference's like every group).
pub(crate) fn diff_rasterizer(kernel: Option<BlendKernel>) -> DiffRasterizer {
    let mut r = DiffRasterizer::with_renderer(new_renderer(kernel));
    r.renderer().set_screen_grads(true).unwrap();
    r
}

pub(crate) fn gpu_camera() -> Camera {
    Camera::look_at(
        "grad-gpu",
        72,
        56,
        0.9,
        Vec3::new(0.4, -0.3, -3.0),
        Vec3::ZERO,
        Vec3::new(0.0, -1.0, 0.0),
    )
}

#[test]
fn gpu_backward_matches_the_reference_for_sh_degrees_and_kernels() {
    let cam = gpu_camera();
    // The device's own blend (8-pixel bins on lavapipe) and the shared kernel (16-pixel).
    for blend in [None, Some(BlendKernel::Shared)] {
        let mut r = diff_rasterizer(blend);
        for degree in 0..=3u32 {
            let p = grad_scene(60, 800 + degree as u64, Some(degree), 3);
            let opts = RenderOptions {
                background: [0.2, 0.4, 0.1],
                ..Default::default()
            };
            gpu_against_reference(&mut r, &p, &cam, &opts, 80 + degree as u64);
        }
        let p = grad_scene(60, 810, Some(2), 3);
        let opts = RenderOptions {
            kernel: SplatKernel::Power,
            scale_modifier: 0.9,
            sh_degree: Some(1),
            ..Default::default()
        };
        gpu_against_reference(&mut r, &p, &cam, &opts, 90);
        let p = guard_band_scene(&cam);
        gpu_against_reference(&mut r, &p, &cam, &RenderOptions::default(), 91);
        let p = grad_scene(60, 811, Some(3), 3);
        let opts = RenderOptions {
            antialiased: true,
            background: [0.1, 0.1, 0.3],
            ..Default::default()
        };
        gpu_against_reference(&mut r, &p, &cam, &opts, 92);
        // The reproducible mode's blends (the portable exp, unfused arithmetic; its own
        // pipelines) differentiate as the reference does too.
        for kernel in SplatKernel::ALL {
            let opts = RenderOptions {
                kernel,
                reproducible: true,
                ..Default::default()
            };
            gpu_against_reference(&mut r, &p, &cam, &opts, 93);
        }
    }
}

/// N-D feature channels (direct values, no background) on the device: 1 to 16 channels,
/// both blend layouts and both kernels, against the reference.
#[test]
fn gpu_backward_matches_the_reference_for_feature_channels() {
    let cam = gpu_camera();
    for blend in [None, Some(BlendKernel::Shared)] {
        let mut r = diff_rasterizer(blend);
        for (k, kernel) in [
            (1, SplatKernel::Gaussian),
            (5, SplatKernel::Power),
            (8, SplatKernel::Gaussian),
            (16, SplatKernel::Gaussian),
        ] {
            let p = grad_scene(50, 1100 + k as u64, None, k);
            let opts = RenderOptions {
                kernel,
                ..Default::default()
            };
            let gpu = gpu_against_reference(&mut r, &p, &cam, &opts, 110 + k as u64);
            assert_eq!(gpu.colors.len(), 50 * k);
        }
        // More channels than the device differentiates: a clear error.
        let p = grad_scene(5, 1200, None, 17);
        let e = r.forward(&p, &cam, &RenderOptions::default()).unwrap_err();
        assert!(e.to_string().contains("at most 16"), "{e}");
    }
}

/// Direct RGB values (negative ones included) over a background on the device: blended as
/// given, never clamped, as the reference and gsplat do; image and gradients equal the
/// reference's.
#[test]
fn gpu_direct_rgb_is_not_clamped_and_matches_the_reference() {
    let cam = gpu_camera();
    let mut r = diff_rasterizer(None);
    let p = grad_scene(60, 1300, None, 3);
    let ColorParams::Direct { values, .. } = &p.colors else {
        unreachable!("direct values were asked for")
    };
    assert!(values.iter().filter(|&&v| v < -0.2).count() > 20);
    let opts = RenderOptions {
        background: [0.2, 0.4, 0.1],
        ..Default::default()
    };
    let (frame, _) = r.forward(&p, &cam, &opts).unwrap();
    let img = forward(&p.to_f64(), &cam, &opts, &[0.2, 0.4, 0.1]).unwrap();
    assert_eq!(frame.feature_count, 3);
    let worst = frame
        .features
        .iter()
        .zip(&img.color)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-4, "largest difference {worst}");
    assert!(
        img.color.iter().filter(|&&c| c < -0.05).count() > 50,
        "the reference frame has no negative colours: the scene tests nothing"
    );
    gpu_against_reference(&mut r, &p, &cam, &opts, 130);
}

/// The deterministic accumulation gives bit-identical gradients run after run, also when
/// the backward pass renders its frame again, and the same bits whether it adds its 64-bit
/// fixed-point values with 64-bit atomics or as 32-bit halves with a carry (a device
/// without `shaderBufferInt64Atomics`); the float-atomic fast mode and its
/// compare-and-swap fallback agree with it to rounding.
#[test]
fn gpu_backward_is_deterministic_and_the_fast_modes_agree() {
    let cam = gpu_camera();
    let mut r = diff_rasterizer(None);
    let p = grad_scene(50000, 900, Some(1), 3);
    let opts = RenderOptions::default();
    let g = to_f32(&pixel_grads(&cam, 3, 91, true));
    let (_, token) = r.forward(&p, &cam, &opts).unwrap();
    let first = r.backward(&p, &cam, &opts, token, &g).unwrap();
    let second = r.backward(&p, &cam, &opts, token, &g).unwrap();
    // Another frame in between: the backward renders the first one again.
    let other = grad_scene(40, 901, Some(3), 3);
    r.forward(&other, &cam, &opts).unwrap();
    let third = r.backward(&p, &cam, &opts, token, &g).unwrap();
    let bits = |s: &verisplat::core::model::grad::SplatGrads<f32>| -> Vec<u64> {
        GRAD_GROUPS
            .iter()
            .flat_map(|gr| s.group(gr))
            .map(|x| x.to_bits())
            .collect()
    };
    assert_eq!(bits(&first), bits(&second));
    assert_eq!(bits(&first), bits(&third));
    let ctx32 = verisplat::gpu::GpuContext::new(&verisplat::gpu::ContextOptions {
        validation: true,
        emulate: verisplat::gpu::emulate::Emulation::parse("no-int64-atomics").unwrap(),
        ..Default::default()
    })
    .unwrap();
    assert!(!ctx32.info().int64_atomics);
    let mut r32 = DiffRasterizer::new(ctx32).unwrap();
    r32.renderer().set_screen_grads(true).unwrap();
    let (_, token32) = r32.forward(&p, &cam, &opts).unwrap();
    let halves = r32.backward(&p, &cam, &opts, token32, &g).unwrap();
    eprintln!(
        "64-bit atomics on the first device: {}",
        r.renderer().ctx().info().int64_atomics
    );
    assert_eq!(bits(&first), bits(&halves));
    assert_validation_clean(r32.renderer());
    for mode in [Accumulation::FloatAtomics, Accumulation::CompareAndSwap] {
        if mode == Accumulation::FloatAtomics && !r.renderer().ctx().info().float_atomic_add {
            eprintln!("no float atomics on this device: the fast mode is refused");
            continue;
        }
        r.renderer().set_gradient_accumulation(mode).unwrap();
        let fast = r.backward(&p, &cam, &opts, token, &g).unwrap();
        for group in GRAD_GROUPS {
            let err = relative_l2(&fast.group(group), &first.group(group));
            assert!(err < 1e-5, "{}: {group} differs by {err:e}", mode.name());
        }
    }
    assert_validation_clean(r.renderer());
}

/// A frame shaded by a neural shader on the device: its backward pass (the shader's, then
/// the feature blend's) against the reference's, for the Gaussians and every layer of the
/// network; bit-identical run after run. Shaders with and without the view direction and
/// alpha as inputs, 4 and 8 channels, both kernels and blend layouts, and a frame of more
/// chunks than partial sums (several dispatches of the shader's backward pass).
#[test]
fn gpu_backward_of_a_shaded_frame_matches_the_reference() {
    use verisplat::cpu::backward::{backward_shaded, forward_shaded, MlpParams};
    let big = Camera::look_at(
        "grad-gpu-big",
        160,
        120,
        0.9,
        Vec3::new(0.4, -0.3, -3.0),
        Vec3::ZERO,
        Vec3::new(0.0, -1.0, 0.0),
    );
    for (blend, k, extra, kernel, cam) in [
        (None, 4, true, SplatKernel::Gaussian, gpu_camera()),
        (
            Some(BlendKernel::Shared),
            8,
            false,
            SplatKernel::Power,
            gpu_camera(),
        ),
        (None, 8, true, SplatKernel::Gaussian, big),
    ] {
        let mut r = diff_rasterizer(blend);
        let p = grad_scene(40, 1400 + k as u64, None, k);
        let mlp = random_mlp(k, extra, 16, 1401 + k as u64);
        let opts = RenderOptions {
            kernel,
            background: [0.2, 0.1, 0.4],
            ..Default::default()
        };
        let bg = opts.background.map(|b| b as f64);
        let w = MlpParams::of(&mlp);
        r.set_shader(Some(&mlp)).unwrap();
        let (frame, token) = r.forward(&p, &cam, &opts).unwrap();
        let img = forward_shaded(&p.to_f64(), &cam, &opts, &mlp, &w, bg).unwrap();
        let worst = frame
            .color
            .iter()
            .flatten()
            .zip(&img.color)
            .map(|(a, b)| (*a as f64 - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-4, "the shaded frame differs by {worst}");
        let g = pixel_grads(&cam, 3, 1402, true);
        let (gpu, gpu_mlp) = r
            .backward_shaded(&p, &cam, &opts, token, &to_f32(&g))
            .unwrap();
        let (cpu, cpu_mlp) = backward_shaded(&p.to_f64(), &cam, &opts, &mlp, &w, bg, &g).unwrap();
        let label = format!("{k} channels, {kernel:?}, {}x{}", cam.width, cam.height);
        for group in GRAD_GROUPS {
            let (a, b) = (gpu.group(group), cpu.group(group));
            let err = relative_l2(&a, &b);
            eprintln!("shaded GPU {label} {group}: relative L2 error {err:.2e}");
            assert!(b.iter().any(|&x| x != 0.0), "{group}: zero reference");
            assert!(err <= 1e-3, "{label} {group}: relative L2 error {err:e}");
        }
        for l in 0..mlp.layers.len() {
            for (name, a, b) in [
                ("weights", &gpu_mlp.weights[l], &cpu_mlp.weights[l]),
                ("biases", &gpu_mlp.biases[l], &cpu_mlp.biases[l]),
            ] {
                let a: Vec<f64> = a.iter().map(|&x| x as f64).collect();
                let err = relative_l2(&a, b);
                eprintln!("shaded GPU {label} layer {l} {name}: relative L2 error {err:.2e}");
                assert!(
                    b.iter().any(|&x| x != 0.0),
                    "layer {l} {name}: zero reference"
                );
                assert!(
                    err <= 1e-3,
                    "{label} layer {l} {name}: relative L2 error {err:e}"
                );
            }
        }
        // Bit-identical again, also after another frame (the backward renders it again).
        let again = r
            .backward_shaded(&p, &cam, &opts, token, &to_f32(&g))
            .unwrap();
        r.forward(&grad_scene(20, 1499, None, k), &cam, &opts)
            .unwrap();
        let third = r
            .backward_shaded(&p, &cam, &opts, token, &to_f32(&g))
            .unwrap();
        let bits = |(s, m): &(
            verisplat::core::model::grad::SplatGrads<f32>,
            MlpParams<f32>,
        )| {
            let mut v: Vec<u32> = GRAD_GROUPS
                .iter()
                .flat_map(|gr| s.group(gr))
                .map(|x| (x as f32).to_bits())
                .collect();
            v.extend(
                m.weights
                    .iter()
                    .chain(&m.biases)
                    .flatten()
                    .map(|x| x.to_bits()),
            );
            v
        };
        let first = (gpu, gpu_mlp);
        assert_eq!(bits(&first), bits(&again), "{label}: not deterministic");
        assert_eq!(bits(&first), bits(&third), "{label}: not deterministic");
        // A shaded frame's plain backward is refused; without the shader it is a features
        // frame again.
        let e = r.backward(&p, &cam, &opts, token, &to_f32(&g)).unwrap_err();
        assert!(e.to_string().contains("backward_shaded"), "{e}");
        assert_validation_clean(r.renderer());
    }
}
