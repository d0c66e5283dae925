//! Mip-Splatting's 3D smoothing filter (Yu et al., CVPR 2024; `train --mip-filter`): each
//! Gaussian is convolved with an isotropic 3D Gaussian as wide as the finest sampling any
//! training camera gives it, so that it never shrinks below what the photos could resolve
//! and renders without aliasing when seen from nearer or farther than the photos were
//! taken. The rules are the reference code's (`compute_3D_filter`,
//! `get_scaling_with_3D_filter`, `get_opacity_with_3D_filter`):
//! - a Gaussian's filter, a standard deviation in world units, is `sqrt(0.2) * d / f`:
//!   `d` the smallest depth of its centre in a training camera that sees it (depth above
//!   0.2, its pixel within 15 % of the image's size outside the image; through a lens,
//!   its pixel by the lens), `f` the largest focal length (x) of the training cameras; a
//!   Gaussian no camera sees takes the largest `d` of those seen;
//! - the scales render as `sqrt(s^2 + filter^2)`, and the opacity times `sqrt(det(S^2) /
//!   det(S^2 + filter^2))` (the filtered Gaussian's peak, so its integral is unchanged);
//! - the filter is computed at the start, after every densification and, after the last
//!   one, every 100 iterations but the last 100 (as `train.py` of Mip-Splatting does).
//!
//! The saved scene has the filter folded into its scales and opacities
//! ([`fold`]): every renderer and peer viewer shows the filtered scene.

use crate::core::camera::Camera;
use glam::DVec3;

/// The filter's variance in pixels at the finest sampling (the reference's 0.2).
pub const FILTER_VARIANCE_PX: f64 = 0.2;

/// The most iterations between two computations of the filter after densification ends.
pub const RECOMPUTE_INTERVAL: u32 = 100;

/// Each centre's filter (a standard deviation, world units) from the training cameras
/// `cameras` (module docs).
pub fn filters(positions: &[[f32; 3]], cameras: &[&Camera]) -> Vec<f32> {
    let focal = cameras
        .iter()
        .map(|c| f64::from(c.fx))
        .fold(0.0f64, f64::max);
    let mut nearest: Vec<Option<f64>> = vec![None; positions.len()];
    for cam in cameras {
        let (w, h) = (f64::from(cam.width), f64::from(cam.height));
        let r = cam.rotation.as_dmat3();
        let t = cam.translation.as_dvec3();
        let k = cam.intrinsics();
        for (p, near) in positions.iter().zip(nearest.iter_mut()) {
            let c = r * DVec3::new(p[0].into(), p[1].into(), p[2].into()) + t;
            if c.z <= 0.2 {
                continue;
            }
            let Some(px) = cam.lens.project(&k, c) else {
                continue;
            };
            let inside =
                px.x >= -0.15 * w && px.x <= 1.15 * w && px.y >= -0.15 * h && px.y <= 1.15 * h;
            if inside && near.map_or(true, |d| c.z < d) {
                *near = Some(c.z);
            }
        }
    }
    let unseen = nearest.iter().flatten().copied().fold(0.0f64, f64::max);
    let scale = FILTER_VARIANCE_PX.sqrt() / focal.max(f64::MIN_POSITIVE);
    nearest
        .iter()
        .map(|d| (d.unwrap_or(unseen) * scale) as f32)
        .collect()
}

/// The filtered scales and the opacity's factor `sqrt(det(S^2) / det(S^2 + f^2))` of a
/// Gaussian with scales `s` and filter `f`, in the operations the device's training step
/// repeats (`glsl/train/train_step.comp`, `mip_filtered`).
pub fn filtered(s: [f32; 3], f: f32) -> ([f32; 3], f32) {
    let f2 = f * f;
    let sq = s.map(|v| v * v);
    let after = sq.map(|v| v + f2);
    let det1 = sq[0] * sq[1] * sq[2];
    let det2 = after[0] * after[1] * after[2];
    (after.map(f32::sqrt), (det1 / det2).sqrt())
}

/// The gradients of the log scales and of the activated opacity's factor through the
/// filter: from the gradients `g_scale` of the filtered scales and `g_opacity` of the
/// filtered opacity `opacity` (filtered), for scales `s`, filter `f` and the filtered
/// scales `filtered` ([`filtered`]'s, which the caller has made for the opacity). Returns the
/// gradients of the log scales (d filtered scale / d log scale = s^2 / filtered scale;
/// d log(opacity) / d log scale = f^2 / (s^2 + f^2)).
pub fn log_scale_grads(
    g_scale: [f32; 3],
    g_opacity: f32,
    opacity: f32,
    s: [f32; 3],
    f: f32,
    filtered: [f32; 3],
) -> [f32; 3] {
    let f2 = f * f;
    [0, 1, 2].map(|a| {
        let sq = s[a] * s[a];
        g_scale[a] * (sq / filtered[a]) + g_opacity * opacity * (f2 / (sq + f2))
    })
}

/// A saved scene with the filters folded in: log scales of the filtered scales, opacity
/// logits of the filtered opacities, and [`crate::core::scene::Scene::mip_filter`] set so
/// that its files say so.
pub fn fold(scene: &mut crate::core::scene::Scene, filters: &[f32]) {
    scene.mip_filter = true;
    for ((l, o), &f) in scene
        .log_scales
        .iter_mut()
        .zip(scene.opacity_logits.iter_mut())
        .zip(filters)
    {
        let (scales, factor) = filtered(l.map(f32::exp), f);
        *l = scales.map(f32::ln);
        let p = crate::core::scene::sigmoid(*o) * factor;
        *o = (p / (1.0 - p)).ln();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_filter_is_the_finest_sampling_of_the_cameras_that_see_a_centre() {
        // Two cameras on the z axis looking along +z, 2 and 5 units from the origin, focal
        // lengths 100 and 200: the origin's filter is sqrt(0.2) * 2 / 200.
        let cam = |z: f32, f: f32| Camera {
            fx: f,
            fy: f,
            translation: glam::Vec3::new(0.0, 0.0, z),
            ..Camera::look_at(
                "c",
                64,
                64,
                1.0,
                glam::Vec3::ZERO,
                glam::Vec3::Z,
                glam::Vec3::NEG_Y,
            )
        };
        let cams = [cam(2.0, 100.0), cam(5.0, 200.0)];
        // The origin (depths 2 and 5), a point 1 unit off axis at depth 3 (pixel 32 +
        // 100/3 and 32 + 200/6 ~ 65.3: within 15 % outside), one far off axis (unseen).
        let f = filters(
            &[[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [100.0, 0.0, 0.0]],
            &[&cams[0], &cams[1]],
        );
        let k = 0.2f64.sqrt() / 200.0;
        assert!((f[0] as f64 - 2.0 * k).abs() < 1e-9, "{f:?}");
        assert!((f[1] as f64 - 3.0 * k).abs() < 1e-9, "{f:?}");
        assert!((f[2] as f64 - 3.0 * k).abs() < 1e-9, "{f:?}");
    }

    #[test]
    fn filtered_gaussians_keep_their_integral_and_the_gradients_are_the_derivatives() {
        let (s, f) = ([0.01f32, 0.2, 0.05], 0.03f32);
        let (out, factor) = filtered(s, f);
        for a in 0..3 {
            assert!((out[a] - (s[a] * s[a] + f * f).sqrt()).abs() < 1e-7);
        }
        // opacity * prod(scales) is the integral's factor: unchanged by the filter.
        let before = s[0] * s[1] * s[2];
        let after = factor * out[0] * out[1] * out[2];
        assert!((before - after).abs() < 1e-6 * before, "{before} {after}");
        // Central differences in f64 of L = sum(g_scale * filtered) + g_op * p * factor.
        let (g_scale, g_op, p) = ([0.3f64, -1.2, 0.7], 0.9f64, 0.6f64);
        let loss = |l: [f64; 3]| {
            let s = l.map(f64::exp);
            let f2 = (f as f64).powi(2);
            let filt = s.map(|v| (v * v + f2).sqrt());
            let factor = ((s[0] * s[1] * s[2]).powi(2)
                / ((s[0] * s[0] + f2) * (s[1] * s[1] + f2) * (s[2] * s[2] + f2)))
                .sqrt();
            (0..3).map(|a| g_scale[a] * filt[a]).sum::<f64>() + g_op * p * factor
        };
        let l0 = s.map(|v| (v as f64).ln());
        let got = log_scale_grads(
            g_scale.map(|v| v as f32),
            g_op as f32,
            (p as f32) * factor,
            s,
            f,
            out,
        );
        for a in 0..3 {
            let h = 1e-6;
            let (mut up, mut down) = (l0, l0);
            up[a] += h;
            down[a] -= h;
            let fd = (loss(up) - loss(down)) / (2.0 * h);
            assert!(
                (got[a] as f64 - fd).abs() < 1e-4 * fd.abs().max(1e-3),
                "{a}: {} {fd}",
                got[a]
            );
        }
    }

    /// The saved scene (the filter folded in) is the scene the renders saw: its scales and
    /// opacities equal the filtered parameters to f32's rounding through ln/exp and the
    /// logit, and it says it holds the filter.
    #[test]
    fn a_folded_scene_is_what_the_renders_saw() {
        let scene = crate::core::gen::synthetic_scene(200, 5, 1);
        // Each filter half the Gaussian's smallest scale (its smallest axis widens 12 %).
        let filters: Vec<f32> = scene
            .log_scales
            .iter()
            .map(|l| 0.5 * l.map(f32::exp).into_iter().fold(f32::INFINITY, f32::min))
            .collect();
        let mut model = crate::train::model::Model::of(scene.clone());
        model.mip_filters = Some(filters.clone());
        let seen = model.params();
        let mut folded = scene.clone();
        fold(&mut folded, &filters);
        assert!(folded.mip_filter && !scene.mip_filter);
        let saved = crate::train::model::Model::of(folded).params();
        let mut worst = 0.0f32;
        for i in 0..scene.len() {
            for a in 0..3 {
                worst = worst.max((saved.scales[i][a] / seen.scales[i][a] - 1.0).abs());
            }
            worst = worst.max((saved.opacities[i] / seen.opacities[i] - 1.0).abs());
        }
        assert!(worst < 1e-5, "{worst}");
        // The filter did change the scene: every Gaussian's smallest axis grew by 12 %.
        let plain = crate::train::model::Model::of(scene).params();
        for (p, s) in plain.scales.iter().zip(&seen.scales) {
            let min = |v: &[f32; 3]| v.iter().copied().fold(f32::INFINITY, f32::min);
            assert!(
                (min(s) / min(p) - 1.25f32.sqrt()).abs() < 1e-5,
                "{p:?} {s:?}"
            );
        }
    }
}
