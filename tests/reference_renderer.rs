//! The CPU reference renderer against closed-form values of the reference rules.

mod common;

use common::{axis_camera, push_gaussian};
use glam::Vec3;
use vksplat::cpu::{self, sh, RenderOptions};
use vksplat::frame::Frame;
use vksplat::scene::Scene;

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
