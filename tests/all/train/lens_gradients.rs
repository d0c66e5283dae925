//! The backward pass through every lens (issue 49): the f64 reference's chain rule
//! through the unscented transform's sigma points (`cpu::backward`'s `lens` module)
//! against central differences of its own forward pass, and its forward against the f32
//! CPU renderer, for a distorted (OPENCV) lens, fisheyes (one seeing past 90 degrees),
//! the orthographic lens and whole-sphere panoramas (one wrapping, with Gaussians across
//! its seam). The tolerance is `gradients.rs`'s: relative L2 error < 1e-6 per group.

use super::gradients::{check_on, grad_camera, grad_scene};
use crate::common::through_lens as through;
use glam::Vec3;
use verisplat::core::camera::{Camera, Lens};
use verisplat::core::model::Rules;
use verisplat::cpu::backward::forward;
use verisplat::cpu::RenderOptions;

/// A `width` x `height` camera at `eye` looking at the origin.
fn camera_at(width: u32, height: u32, eye: Vec3) -> Camera {
    Camera::look_at(
        "grad-lens",
        width,
        height,
        0.9,
        eye,
        Vec3::ZERO,
        Vec3::new(0.0, -1.0, 0.0),
    )
}

/// The cameras the gradients are checked from: each lens kind, from outside the scene
/// and from inside it (where a fisheye sees Gaussians past 90 degrees and a panorama
/// has them all around, across its seam and near its poles).
pub(crate) fn lens_cameras() -> Vec<(&'static str, Camera)> {
    let outside = grad_camera();
    let inside = camera_at(48, 40, Vec3::new(0.1, -0.05, -0.15));
    let distorted = Lens::RadialTangential {
        radial: [-0.2, 0.05, -0.01, 0.02, 0.0, 0.0],
        tangential: [0.003, -0.002],
    };
    vec![
        (
            "opencv",
            Camera {
                lens: distorted,
                ..outside.clone()
            },
        ),
        (
            "fisheye 120",
            through(
                &camera_at(48, 40, Vec3::new(0.3, -0.2, -1.6)),
                "fisheye:fov=120",
                1.6,
            ),
        ),
        (
            "fisheye 200 inside",
            through(&inside, "fisheye:fov=200", 0.7),
        ),
        (
            "distorted fisheye inside",
            Camera {
                lens: Lens::Fisheye {
                    k: [0.05, -0.01, 0.002, 0.001],
                    max_theta: 80f64.to_radians(),
                },
                ..through(&inside, "fisheye:fov=160", 0.7)
            },
        ),
        ("ortho", through(&outside, "ortho", 3.0)),
        (
            "whole sphere, wrapping",
            through(
                &camera_at(64, 32, Vec3::new(0.05, 0.02, 0.1)),
                "equirect",
                1.0,
            ),
        ),
        (
            "window across the seam",
            // Looking away from the scene, which is behind: across the seam.
            through(
                &Camera::look_at(
                    "grad-lens",
                    40,
                    32,
                    0.9,
                    Vec3::new(0.05, 0.02, -1.0),
                    Vec3::new(0.0, 0.0, -3.0),
                    Vec3::new(0.0, -1.0, 0.0),
                ),
                "equirect:lon=120..240,lat=50..-50",
                1.0,
            ),
        ),
    ]
}

#[test]
fn reference_backward_through_every_lens_matches_finite_differences() {
    for (k, (name, cam)) in lens_cameras().into_iter().enumerate() {
        eprintln!("{name}:");
        let p = grad_scene(10, 800 + k as u64, Some(1), 3);
        if name == "fisheye 200 inside" {
            let behind = p
                .means
                .iter()
                .filter(|m| (cam.rotation * Vec3::from(**m) + cam.translation).z < 0.0)
                .count();
            assert!(behind > 0, "no Gaussian past 90 degrees");
        }
        check_on(
            &cam,
            &p,
            &RenderOptions::default(),
            &[0.1, 0.2, 0.3],
            true,
            80 + k as u64,
        );
    }
}

#[test]
fn reference_backward_through_lenses_matches_finite_differences_under_gsplat_rules_antialiased() {
    for (k, (name, cam)) in lens_cameras().into_iter().enumerate().step_by(2) {
        eprintln!("{name}:");
        let p = grad_scene(8, 900 + k as u64, Some(2), 3);
        let opts = RenderOptions {
            rules: Rules::Gsplat,
            antialiased: true,
            ..Default::default()
        };
        check_on(&cam, &p, &opts, &[0.0; 3], true, 90 + k as u64);
    }
}

/// The f64 reference draws every lens as the f32 CPU renderer does.
#[test]
fn reference_forward_through_every_lens_equals_the_cpu_renderer() {
    for (k, (name, cam)) in lens_cameras().into_iter().enumerate() {
        let p = grad_scene(30, 950 + k as u64, Some(3), 3);
        let opts = RenderOptions {
            background: [0.1, 0.2, 0.3],
            ..Default::default()
        };
        let frame = verisplat::cpu::render(&p.to_activated(), &cam, &opts);
        let img = forward(&p.to_f64(), &cam, &opts, &[0.1, 0.2, 0.3]).unwrap();
        let worst = super::gradients::largest_difference(&frame, &img);
        let covered = img.alpha.iter().filter(|&&a| a > 0.5).count();
        eprintln!("{name}: largest difference {worst:.1e}, {covered} pixels covered");
        assert!(worst < 1e-4, "{name}: largest difference {worst}");
        assert!(
            covered * 10 > img.alpha.len(),
            "{name}: the frame is mostly empty"
        );
    }
}

// ---- The Vulkan backward pass through every lens against the reference ------------------
//
// `gradients.rs`'s tolerance: relative L2 error <= 1e-3 per parameter group. The device
// takes the sigma points' pixel offsets in f32 without cancellation (`lens_offset`), as
// its forward pass does, and their Jacobians (`lens_jacobian`) directly.

/// The GPU's gradients through every lens against the reference's, for SH colours and
/// both kernels.
#[test]
fn gpu_backward_through_every_lens_matches_the_reference() {
    use super::gradients::{diff_rasterizer, gpu_against_reference};
    use verisplat::render::forward::blend::BlendKernel;
    let mut r = diff_rasterizer(None);
    for (k, (name, cam)) in lens_cameras().into_iter().enumerate() {
        eprintln!("{name}:");
        let p = grad_scene(40, 1000 + k as u64, Some(3), 3);
        let first =
            gpu_against_reference(&mut r, &p, &cam, &RenderOptions::default(), 100 + k as u64);
        // Deterministic: the same bits run to run.
        let again =
            gpu_against_reference(&mut r, &p, &cam, &RenderOptions::default(), 100 + k as u64);
        for group in verisplat::core::model::grad::GRAD_GROUPS {
            let bits = |g: &verisplat::core::model::grad::SplatGrads<f32>| {
                g.group(group)
                    .iter()
                    .map(|x| x.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(
                bits(&first),
                bits(&again),
                "{name}: {group} changed run to run"
            );
        }
    }
    // The shared blend kernel (16-pixel bins), antialiased under gsplat's rules.
    let mut r = diff_rasterizer(Some(BlendKernel::Shared));
    for (k, (name, cam)) in lens_cameras().into_iter().enumerate().skip(1).step_by(2) {
        eprintln!("{name}, shared kernel, gsplat's rules, antialiased:");
        let p = grad_scene(30, 1100 + k as u64, Some(1), 3);
        let opts = RenderOptions {
            rules: Rules::Gsplat,
            antialiased: true,
            background: [0.2, 0.1, 0.0],
            ..Default::default()
        };
        gpu_against_reference(&mut r, &p, &cam, &opts, 110 + k as u64);
    }
}
