//! The CPU reference renderer against closed-form values of the reference rules.

use crate::common;
use crate::common::{axis_camera, push_gaussian};
use glam::Vec3;
use verisplat::core::frame::Frame;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, sh, RenderOptions};

fn render(s: &Scene, background: [f32; 3]) -> Frame {
    cpu::render(
        &s.activated(),
        &axis_camera(50.0),
        &RenderOptions {
            background,
            ..Default::default()
        },
    )
}

#[test]
fn single_isotropic_gaussian_gives_the_analytic_alpha() {
    let (z, scale, rgb) = (5.0f32, 0.2f32, [0.6f32, 0.3, 0.9]);
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [0.0, 0.0, z], scale, 0.8, rgb);
    let opacity = s.activated().opacities[0] as f64;
    let bg = [0.1f32, 0.2, 0.3];
    let f = render(&s, bg);
    // Facing the camera on the axis: variance (f s / z)^2 + 0.3 = 4.3 px^2, centre (32, 32).
    let var = (50.0f64 * scale as f64 / z as f64).powi(2) + 0.3;
    let mut checked = 0;
    for (px, py) in [
        (32, 32),
        (33, 32),
        (32, 34),
        (35, 30),
        (37, 32),
        (29, 36),
        (32, 38),
        (20, 20),
    ] {
        let d2 = ((px - 32) * (px - 32) + (py - 32) * (py - 32)) as f64;
        let mut alpha = (opacity * (-0.5 * d2 / var).exp()).min(0.99);
        if alpha < 1.0 / 255.0 {
            alpha = 0.0;
        }
        let i = f.index(px as u32, py as u32);
        assert!(
            (f.alpha[i] as f64 - alpha).abs() < 2e-6,
            "pixel ({px},{py}): {} vs {alpha}",
            f.alpha[i]
        );
        for c in 0..3 {
            let want = rgb[c] as f64 * alpha + (1.0 - alpha) * bg[c] as f64;
            assert!(
                (f.color[i][c] as f64 - want).abs() < 2e-6,
                "pixel ({px},{py}) channel {c}"
            );
        }
        let want_depth = if alpha > 0.0 { z as f64 } else { 0.0 };
        assert!(
            (f.depth[i] as f64 - want_depth).abs() < 1e-4,
            "depth at ({px},{py}): {}",
            f.depth[i]
        );
        checked += (alpha > 0.0) as usize;
    }
    assert!(
        checked >= 6,
        "the chosen pixels must mostly be inside the splat"
    );
    // (32, 38) is 6 px away: 0.8 exp(-36 / 8.6) = 0.012 > 1/255, still inside the 7 px radius.
    assert!(f.alpha[f.index(32, 38)] > 0.01);
}

#[test]
fn two_gaussians_blend_front_to_back_regardless_of_file_order() {
    let mut front_first = Scene::empty(0);
    push_gaussian(&mut front_first, [0.0, 0.0, 3.0], 0.1, 0.5, [1.0, 0.0, 0.0]);
    push_gaussian(&mut front_first, [0.0, 0.0, 6.0], 0.2, 0.7, [0.0, 1.0, 0.0]);
    let mut back_first = Scene::empty(0);
    push_gaussian(&mut back_first, [0.0, 0.0, 6.0], 0.2, 0.7, [0.0, 1.0, 0.0]);
    push_gaussian(&mut back_first, [0.0, 0.0, 3.0], 0.1, 0.5, [1.0, 0.0, 0.0]);
    let a = render(&front_first, [0.0; 3]);
    let b = render(&back_first, [0.0; 3]);
    assert_eq!(a, b, "file order must not matter when depths differ");
    let act = front_first.activated();
    let (o1, o2) = (act.opacities[0], act.opacities[1]);
    let i = a.index(32, 32);
    assert!((a.color[i][0] - o1).abs() < 1e-6);
    assert!((a.color[i][1] - o2 * (1.0 - o1)).abs() < 1e-6);
    let w = o1 + o2 * (1.0 - o1);
    assert!((a.depth[i] - (3.0 * o1 + 6.0 * o2 * (1.0 - o1)) / w).abs() < 1e-5);
}

#[test]
fn equal_depths_keep_index_order() {
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [0.0, 0.0, 4.0], 0.1, 0.6, [1.0, 0.0, 0.0]);
    push_gaussian(&mut s, [0.0, 0.0, 4.0], 0.1, 0.6, [0.0, 0.0, 1.0]);
    let f = render(&s, [0.0; 3]);
    let c = f.color[f.index(32, 32)];
    assert!(
        c[0] > c[2] * 2.0,
        "the first Gaussian in the file is in front: {c:?}"
    );
    s.positions.swap(0, 1);
    s.sh.swap(0, 3);
    s.sh.swap(2, 5);
    let f = render(&s, [0.0; 3]);
    let c = f.color[f.index(32, 32)];
    assert!(c[2] > c[0] * 2.0, "after swapping, blue is in front: {c:?}");
}

#[test]
fn alpha_is_clamped_at_0_99() {
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [0.0, 0.0, 4.0], 0.1, 0.9995, [1.0, 1.0, 1.0]);
    let f = render(&s, [0.0; 3]);
    let i = f.index(32, 32);
    let want = 1.0 - (1.0 - 0.99f32);
    assert_eq!(
        f.alpha[i], want,
        "opacity 0.9995 at the centre is clamped to 0.99"
    );
    assert!((f.color[i][0] - 0.99).abs() < 1e-6);
}

#[test]
fn contributions_below_one_255th_are_skipped() {
    for (opacity, contributes) in [(0.0039f32, false), (0.0040, true)] {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, 4.0], 0.1, opacity, [1.0, 1.0, 1.0]);
        let f = render(&s, [0.25; 3]);
        let i = f.index(32, 32);
        if contributes {
            assert!((f.alpha[i] - opacity).abs() < 1e-7);
            assert!(f.color[i][0] > 0.25);
        } else {
            assert_eq!(f.alpha[i], 0.0, "alpha {opacity} < 1/255 must be skipped");
            assert_eq!(f.color[i], [0.25; 3]);
            assert_eq!(f.depth[i], 0.0);
        }
    }
}

#[test]
fn compositing_stops_before_transmittance_drops_below_1e_4() {
    // Opacity 0.98 three times: T = 0.02, 0.0004, then 0.000008 < 1e-4, so the third
    // (blue) Gaussian is not added and the pixel keeps T = 0.0004.
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [0.0, 0.0, 2.0], 0.05, 0.98, [1.0, 0.0, 0.0]);
    push_gaussian(&mut s, [0.0, 0.0, 3.0], 0.05, 0.98, [1.0, 0.0, 0.0]);
    push_gaussian(&mut s, [0.0, 0.0, 4.0], 0.05, 0.98, [0.0, 0.0, 1.0]);
    let f = render(&s, [0.0, 0.0, 0.0]);
    let i = f.index(32, 32);
    let o = s.activated().opacities[0];
    let t = (1.0 - o) * (1.0 - o);
    assert_eq!(
        f.color[i][2], 0.0,
        "the Gaussian that would take T below 1e-4 is not added"
    );
    assert!((f.alpha[i] - (1.0 - t)).abs() < 1e-7);
    assert!((f.color[i][0] - (o + o * (1.0 - o))).abs() < 1e-6);
    assert!((f.depth[i] - (2.0 * o + 3.0 * o * (1.0 - o)) / (1.0 - t)).abs() < 1e-5);
    // Without the stop rule the blue term would be o * t = 0.00039, well above f32 noise.
    assert!(o * t > 1e-4);
}

/// A Gaussian on the optical axis with the given SH coefficients for red (green and
/// blue use the same, scaled), seen along +z.
fn axis_colour(deg: u32, coeffs: &[f32]) -> f32 {
    let mut s = Scene::empty(deg);
    push_gaussian(&mut s, [0.0, 0.0, 5.0], 0.3, 0.9995, [0.5; 3]);
    for (k, &v) in coeffs.iter().enumerate() {
        s.sh[k * 3] = v;
    }
    let f = render(&s, [0.0; 3]);
    f.color[f.index(32, 32)][0] / 0.99
}

#[test]
fn sh_colours_match_hand_computed_values_on_the_axis() {
    // Seen along +z: band 1 reduces to C1 sh2, band 2 to 2 C2[2] sh6, band 3 to 2 C3[3] sh12.
    let mut coeffs = [0.0f32; 16];
    for (k, v) in coeffs.iter_mut().enumerate() {
        *v = 0.05 * (k as f32 + 1.0) * if k % 2 == 0 { 1.0 } else { -1.0 };
    }
    let base = 0.5 + sh::SH_C0 * coeffs[0];
    let b1 = sh::SH_C1 * coeffs[2];
    let b2 = 2.0 * sh::SH_C2[2] * coeffs[6];
    let b3 = 2.0 * sh::SH_C3[3] * coeffs[12];
    for (deg, want) in [
        (1, base + b1),
        (2, base + b1 + b2),
        (3, base + b1 + b2 + b3),
    ] {
        let got = axis_colour(deg, &coeffs[..(deg as usize + 1).pow(2)]);
        assert!((got - want).abs() < 1e-5, "degree {deg}: {got} vs {want}");
    }
}

#[test]
fn sh_evaluation_along_the_axes() {
    let coeffs: Vec<f32> = (0..16)
        .flat_map(|k| [0.1 * k as f32 - 0.7, 0.2, -0.05 * k as f32])
        .collect();
    let c = |k: usize| Vec3::new(coeffs[k * 3], coeffs[k * 3 + 1], coeffs[k * 3 + 2]);
    let dc = sh::SH_C0 * c(0) + Vec3::splat(0.5);
    let x = dc - sh::SH_C1 * c(3) - sh::SH_C2[2] * c(6) + sh::SH_C2[4] * c(8)
        - sh::SH_C3[4] * c(13)
        + sh::SH_C3[6] * c(15);
    let y = dc
        - sh::SH_C1 * c(1)
        - sh::SH_C2[2] * c(6)
        - sh::SH_C2[4] * c(8)
        - sh::SH_C3[0] * c(9)
        - sh::SH_C3[2] * c(11);
    let z = dc + sh::SH_C1 * c(2) + 2.0 * sh::SH_C2[2] * c(6) + 2.0 * sh::SH_C3[3] * c(12);
    for (dir, want) in [(Vec3::X, x), (Vec3::Y, y), (Vec3::Z, z)] {
        let got = sh::eval_sh(3, &coeffs, dir);
        for ch in 0..3 {
            assert!(
                (got[ch] - want[ch].max(0.0)).abs() < 1e-6,
                "{dir}: {got:?} vs {want}"
            );
        }
    }
    // Clamped below at zero, not above.
    let mut dark = [0.0f32; 3];
    dark[0] = -10.0;
    dark[1] = 10.0;
    let got = sh::eval_sh(0, &dark, Vec3::Z);
    assert_eq!(got[0], 0.0);
    assert!((got[1] - (0.5 + 10.0 * sh::SH_C0)).abs() < 1e-6 && got[1] > 1.0);
}

#[test]
fn gaussians_at_or_behind_the_near_plane_change_nothing() {
    let mut base = Scene::empty(0);
    push_gaussian(&mut base, [0.0, 0.0, 4.0], 0.3, 0.7, [0.2, 0.4, 0.6]);
    let reference = render(&base, [0.0; 3]);
    for z in [0.2f32, 0.15, -1.0] {
        let mut s = base.clone();
        push_gaussian(&mut s, [0.0, 0.0, z], 0.05, 0.9, [1.0, 1.0, 1.0]);
        assert_eq!(render(&s, [0.0; 3]), reference, "z = {z} must be culled");
    }
    let mut s = base.clone();
    push_gaussian(&mut s, [0.0, 0.0, 0.25], 0.05, 0.9, [1.0, 1.0, 1.0]);
    assert_ne!(
        render(&s, [0.0; 3]),
        reference,
        "z = 0.25 is in front of the near plane and must show"
    );
}

#[test]
fn empty_scene_renders_the_background() {
    let f = render(&Scene::empty(3), [0.25, 0.5, 1.0]);
    assert!(f.color.iter().all(|c| *c == [0.25, 0.5, 1.0]));
    assert!(f.alpha.iter().all(|&a| a == 0.0));
    assert!(f.depth.iter().all(|&d| d == 0.0));
}

#[test]
fn tile_rectangles_follow_get_rect() {
    // Centre (100.5, 3.2), radius 7 on a 10x5 grid: x tiles [5, 7), y tiles [0, 1).
    let (lo, hi) = cpu::tile_rect([100.5, 3.2], 7.0, (10, 5));
    assert_eq!((lo, hi), ([5, 0], [7, 1]));
    // Left of the image: (-20 + 7 + 15) / 16 = 0.125 truncates to 0: zero tiles.
    let (lo, hi) = cpu::tile_rect([-20.0, 40.0], 7.0, (10, 5));
    assert_eq!(lo[0], 0);
    assert_eq!(hi[0], 0);
}

#[test]
fn keys_are_emitted_in_index_order_and_sorted_stably() {
    let s = common::random_scene(300, 1, 77);
    let mut s = s;
    for p in &mut s.positions {
        p[2] += 3.0;
    }
    let cam = axis_camera(40.0);
    let projected = cpu::preprocess(
        &s.activated(),
        &cam,
        &RenderOptions {
            sh_degree: Some(1),
            ..Default::default()
        },
    );
    let (keys, values) = cpu::tile_keys(&projected, &cam);
    assert_eq!(
        keys.len(),
        projected
            .iter()
            .map(|p| p.tiles_touched() as usize)
            .sum::<usize>()
    );
    assert!(
        values.windows(2).all(|w| w[0] <= w[1]),
        "emitted in Gaussian index order"
    );
    let (sk, sv) = cpu::sort_pairs(&keys, &values);
    for w in sk.iter().zip(&sv).collect::<Vec<_>>().windows(2) {
        assert!(w[0].0 < w[1].0 || (w[0].0 == w[1].0 && w[0].1 < w[1].1));
    }
    let ranges = cpu::tile_ranges(&sk, 16);
    let total: u32 = ranges.iter().map(|r| r[1] - r[0]).sum();
    assert_eq!(total as usize, sk.len());
}

#[test]
fn antialiased_mode_scales_opacity_by_the_dilation_compensation() {
    // Isotropic Gaussian facing the camera: the 2D covariance is v I with v = (f s / z)^2,
    // so det_before / det_after = (v / (v + 0.3))^2 and the compensation is v / (v + 0.3).
    for (scale, z) in [(0.2f32, 5.0f32), (0.01, 5.0), (0.0001, 5.0)] {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, z], scale, 0.8, [1.0, 1.0, 1.0]);
        let opacity = s.activated().opacities[0] as f64;
        let opts = RenderOptions {
            antialiased: true,
            ..Default::default()
        };
        let f = cpu::render(&s.activated(), &axis_camera(50.0), &opts);
        let v = (50.0f64 * scale as f64 / z as f64).powi(2);
        let factor = (v / (v + 0.3)).max(0.000025f64.sqrt());
        let want = (opacity * factor).min(0.99);
        let want = if want < 1.0 / 255.0 { 0.0 } else { want };
        let got = f.alpha[f.index(32, 32)] as f64;
        assert!(
            (got - want).abs() < 1e-5,
            "scale {scale}: alpha {got} vs {want}"
        );
        // Off by default: the plain render is the uncompensated opacity.
        let plain = render(&s, [0.0; 3]);
        assert!((plain.alpha[plain.index(32, 32)] as f64 - opacity.min(0.99)).abs() < 1e-5);
    }
}

fn power_options(background: [f32; 3]) -> RenderOptions {
    RenderOptions {
        background,
        kernel: cpu::SplatKernel::Power,
        ..Default::default()
    }
}

/// The power kernel's alpha, `opacity * max(0, 1 - d2 / 9)`, in f32 from the projected
/// conic exactly as the rules say, then through the 0.99 clamp and the 1/255 skip; as the
/// frame stores it (`1 - T` with `T = 1 - alpha`).
fn power_alpha_f32(p: &cpu::Projected, px: f32, py: f32) -> f32 {
    let (dx, dy) = (p.mean2d[0] - px, p.mean2d[1] - py);
    let [a, b, c] = p.conic;
    let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
    let d2 = -2.0 * power;
    let alpha = (p.opacity * (1.0 - d2 / 9.0).max(0.0)).min(0.99);
    if power > 0.0 || alpha < 1.0 / 255.0 {
        0.0
    } else {
        1.0 - (1.0 - alpha)
    }
}

#[test]
fn power_kernel_gives_opacity_times_one_minus_d2_over_9() {
    // Facing the camera on the axis: variance (f s / z)^2 + 0.3 = 4.3 px^2, centre (32, 32);
    // the support ends at d2 = 9, i.e. 3 sqrt(4.3) = 6.22 px from the centre.
    let (z, scale, rgb) = (5.0f32, 0.2f32, [0.6f32, 0.3, 0.9]);
    let bg = [0.1f32, 0.2, 0.3];
    let var = (50.0f64 * scale as f64 / z as f64).powi(2) + 0.3;
    for opacity in [0.8f32, 0.05, 0.999] {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, z], scale, opacity, rgb);
        let act = s.activated();
        let o = act.opacities[0] as f64;
        let f = cpu::render(&act, &axis_camera(50.0), &power_options(bg));
        let p = cpu::preprocess(&act, &axis_camera(50.0), &power_options(bg))[0];
        let (mut inside, mut outside) = (0, 0);
        for (dx, dy) in [
            (0, 0),
            (1, 0),
            (0, 2),
            (3, -2),
            (5, 0),
            (0, 6),
            (-6, -1),
            (6, 2),
            (4, 5),
            (0, 7),
            (-9, 3),
        ] {
            let (px, py) = (32 + dx, 32 + dy);
            let d2 = f64::from(dx * dx + dy * dy) / var;
            let mut alpha = (o * (1.0 - d2 / 9.0).max(0.0)).min(0.99);
            if alpha < 1.0 / 255.0 {
                alpha = 0.0;
            }
            let i = f.index(px as u32, py as u32);
            assert!(
                (f.alpha[i] as f64 - alpha).abs() < 2e-6,
                "opacity {opacity}, pixel ({px},{py}), d2 {d2}: {} vs {alpha}",
                f.alpha[i]
            );
            // Bit for bit the formula in f32 on the projected conic.
            assert_eq!(
                f.alpha[i].to_bits(),
                power_alpha_f32(&p, px as f32, py as f32).to_bits(),
                "opacity {opacity}, pixel ({px},{py})"
            );
            if d2 > 9.0 {
                assert_eq!(f.alpha[i], 0.0, "outside the support at d2 {d2}");
                assert_eq!(f.color[i], bg);
                outside += 1;
            } else if alpha > 0.0 {
                inside += 1;
            }
            for c in 0..3 {
                let want = rgb[c] as f64 * alpha + (1.0 - alpha) * bg[c] as f64;
                assert!(
                    (f.color[i][c] as f64 - want).abs() < 2e-6,
                    "pixel ({px},{py}) channel {c}"
                );
            }
        }
        assert!(
            inside >= 5 && outside == 4,
            "{inside} inside, {outside} outside"
        );
    }
    // 6 px out (d2 = 8.37): 0.8 gives 0.8 * 0.070 = 0.056, but 0.05 gives 0.0035 < 1/255.
    let at = |opacity: f32, dx: u32| {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.0, 0.0, z], scale, opacity, rgb);
        let f = cpu::render(&s.activated(), &axis_camera(50.0), &power_options(bg));
        f.alpha[f.index(32 + dx, 32)]
    };
    assert!(at(0.8, 6) > 0.05);
    assert_eq!(at(0.05, 6), 0.0);
    assert!(at(0.05, 5) > 0.01);
    // The 0.99 clamp, and the Gaussian kernel differs (exp(-d2/2) > 1 - d2/9 nowhere
    // but the centre).
    assert_eq!(at(0.999, 0), 1.0 - (1.0 - 0.99f32));
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [0.0, 0.0, z], scale, 0.8, rgb);
    let g = render(&s, bg);
    let pw = cpu::render(&s.activated(), &axis_camera(50.0), &power_options(bg));
    assert!(g.alpha[g.index(35, 32)] < pw.alpha[pw.index(35, 32)]);
}

#[test]
fn power_kernel_blends_two_splats_front_to_back() {
    // Two splats on the axis, the nearer one listed second: pixel (32, 32) gets
    // a1 + a2 (1 - a1) alpha and c1 a1 + c2 a2 (1 - a1) colour, a_i = o_i (1 - d2_i / 9).
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [0.0, 0.0, 6.0], 0.3, 0.7, [0.0, 0.0, 1.0]);
    push_gaussian(&mut s, [0.0, 0.0, 3.0], 0.05, 0.6, [1.0, 0.0, 0.0]);
    let act = s.activated();
    let cam = axis_camera(50.0);
    let f = cpu::render(&act, &cam, &power_options([0.0; 3]));
    // (34, 33): d^2 = 5 px^2 from both centres.
    let var = |scale: f64, z: f64| (50.0 * scale / z).powi(2) + 0.3;
    let a = |o: f32, v: f64| f64::from(o) * (1.0 - 5.0 / v / 9.0);
    let (far, near) = (
        a(act.opacities[0], var(0.3, 6.0)),
        a(act.opacities[1], var(0.05, 3.0)),
    );
    assert!(
        far > 0.1 && near > 0.1,
        "both inside their support: {far} {near}"
    );
    let i = f.index(34, 33);
    let alpha = near + far * (1.0 - near);
    assert!(
        (f.alpha[i] as f64 - alpha).abs() < 2e-6,
        "{} vs {alpha}",
        f.alpha[i]
    );
    assert!((f.color[i][0] as f64 - near).abs() < 2e-6);
    assert!((f.color[i][2] as f64 - far * (1.0 - near)).abs() < 2e-6);
    let depth = (3.0 * near + 6.0 * far * (1.0 - near)) / alpha;
    assert!((f.depth[i] as f64 - depth).abs() < 1e-4);
}

/// Random projected splats (centre, conic of a rotated ellipse, opacity) around a 64x64
/// pixel window.
fn random_splats(n: usize, seed: u64) -> Vec<cpu::Projected> {
    let mut rng = common::Rng(seed);
    (0..n)
        .map(|_| {
            let (l1, l2) = (rng.range(0.3, 150.0), rng.range(0.3, 150.0));
            let t = rng.range(0.0, std::f32::consts::PI);
            let (c, s) = (t.cos(), t.sin());
            // Covariance R diag(l1, l2) R^T, conic its inverse.
            let (a, b, d) = (
                c * c * l1 + s * s * l2,
                c * s * (l1 - l2),
                s * s * l1 + c * c * l2,
            );
            let det = a * d - b * b;
            cpu::Projected {
                mean2d: [rng.range(-30.0, 94.0), rng.range(-30.0, 94.0)],
                conic: [d / det, -b / det, a / det],
                opacity: rng.range(0.0, 1.0).powi(3),
                radius: 1,
                ..Default::default()
            }
        })
        .collect()
}

/// The tile test is exact for each kernel: a tile it rejects gets alpha < 1/255 at every
/// pixel under that kernel (brute force), for 16- and 8-pixel bins. The bound is the
/// kernel's own: the power kernel's rejects tiles the Gaussian bound keeps, and would be
/// wrong for the Gaussian kernel.
#[test]
fn tile_culling_is_exact_for_each_kernel() {
    use cpu::SplatKernel::{Gaussian, Power};
    let splats = random_splats(1000, 7);
    for size in [16u32, 8] {
        let tiles = 64 / size;
        let (mut power_only, mut wrong_for_gaussian, mut kept_empty, mut kept) = (0, 0, 0, 0);
        for (i, p) in splats.iter().enumerate() {
            for ty in 0..tiles {
                for tx in 0..tiles {
                    let tile = [tx, ty];
                    for kernel in [Gaussian, Power] {
                        let receives =
                            cpu::tile_receives(p.mean2d, p.conic, p.opacity, kernel, tile, size);
                        let best = cpu::max_alpha_in_tile(p, kernel, tile, size, 64, 64);
                        assert!(
                            receives || best < 1.0 / 255.0,
                            "splat {i} {p:?}, {size}-pixel tile {tile:?}: rejected by the {kernel} test but reaches alpha {best}"
                        );
                        if receives {
                            kept += 1;
                            kept_empty += usize::from(best < 1.0 / 255.0);
                        }
                    }
                    let power = cpu::tile_receives(p.mean2d, p.conic, p.opacity, Power, tile, size);
                    let gauss =
                        cpu::tile_receives(p.mean2d, p.conic, p.opacity, Gaussian, tile, size);
                    if gauss && !power {
                        power_only += 1;
                        let best = cpu::max_alpha_in_tile(p, Gaussian, tile, size, 64, 64);
                        wrong_for_gaussian += usize::from(best >= 1.0 / 255.0);
                    }
                }
            }
        }
        eprintln!(
            "{size}-pixel tiles: kept {kept} (of which {kept_empty} receive nothing at a pixel), \
             {power_only} culled by the power bound only, {wrong_for_gaussian} of them lit by the Gaussian"
        );
        assert!(power_only > 50, "the power bound is tighter: {power_only}");
        assert!(
            wrong_for_gaussian * 2 > power_only,
            "{wrong_for_gaussian} of {power_only}"
        );
        // Tight: the continuous-square test keeps few tiles whose pixels all stay below 1/255.
        assert!(kept_empty * 20 < kept, "{kept_empty} of {kept}");
    }
}

/// A CPU render whose (tile, splat) pairs are culled with `tile_receives` of the kernel is
/// bit for bit the plain reference render (which keeps the whole rectangle), on a real
/// scene from an orbit and a close-up, for both kernels.
#[test]
fn tile_culled_render_equals_the_reference_render_bit_for_bit() {
    let scene = verisplat::io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply"))
        .unwrap()
        .activated();
    let cams = verisplat::io::camera::load_cameras_json(
        &common::shared_data().join("playbot_orbit_cameras.synthetic.json"),
    )
    .unwrap();
    let orbit = cams[2].with_resolution(480, 270).unwrap();
    let close = common::gpu::move_towards(&orbit, Vec3::new(0.0, -0.5, 0.0), 0.3, "close-up");
    for cam in [&orbit, &close] {
        for kernel in cpu::SplatKernel::ALL {
            let opts = RenderOptions {
                background: [0.2, 0.3, 0.4],
                kernel,
                ..Default::default()
            };
            let plain = cpu::render(&scene, cam, &opts);
            let projected = cpu::preprocess(&scene, cam, &opts);
            let (keys, values) = cpu::tile_keys(&projected, cam);
            let (tx, ty) = cam.tile_grid();
            let (keys, values): (Vec<u64>, Vec<u32>) = keys
                .iter()
                .zip(&values)
                .filter(|(k, v)| {
                    let tile = (*k >> 32) as u32;
                    let p = &projected[**v as usize];
                    cpu::tile_receives(
                        p.mean2d,
                        p.conic,
                        p.opacity,
                        kernel,
                        [tile % tx, tile / tx],
                        16,
                    )
                })
                .map(|(k, v)| (*k, *v))
                .unzip();
            let (sk, sv) = cpu::sort_pairs(&keys, &values);
            let ranges = cpu::tile_ranges(&sk, (tx * ty) as usize);
            let culled = cpu::blend(
                &projected,
                &sv,
                &ranges,
                cam,
                opts.background,
                kernel,
                opts.rules,
            );
            let all: usize = projected.iter().map(|p| p.tiles_touched() as usize).sum();
            eprintln!("{} {kernel}: {} of {all} pairs kept", cam.name, sk.len());
            assert!(sk.len() < all, "some pairs are culled");
            assert!(
                common::frame_bits(&culled) == common::frame_bits(&plain),
                "{} {kernel}",
                cam.name
            );
        }
    }
}
