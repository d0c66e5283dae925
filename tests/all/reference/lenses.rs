//! The CPU reference through lenses other than the pinhole (issue 49, its first part): a
//! Gaussian is drawn where the lens's exact map puts it, with the spread the unscented
//! transform gives, including where a pinhole sees nothing; and the renderers that do
//! not draw a lens yet say so instead of drawing a pinhole.

use crate::common::{axis_camera, push_gaussian};
use glam::Vec3;
use std::f64::consts::{FRAC_PI_2, PI};
use verisplat::core::camera::{Camera, Lens};
use verisplat::core::frame::Frame;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions};

fn render(s: &Scene, cam: &Camera) -> Frame {
    cpu::render(&s.activated(), cam, &RenderOptions::default())
}

/// The pixel (as the renderers index it) where `lens` puts camera-space point `p`.
fn pixel_of(cam: &Camera, p: [f32; 3]) -> (u32, u32) {
    let px = cam
        .lens
        .project(&cam.intrinsics(), Vec3::from(p).as_dvec3())
        .expect("the lens images the point");
    ((px.x - 0.5).round() as u32, (px.y - 0.5).round() as u32)
}

fn with_lens(lens: Lens, f: f32, size: u32) -> Camera {
    Camera {
        width: size,
        height: size,
        cx: size as f32 / 2.0,
        cy: size as f32 / 2.0,
        lens,
        ..axis_camera(f)
    }
}

#[test]
fn a_fisheye_draws_a_gaussian_behind_its_image_plane_where_its_map_puts_it() {
    // 100 degrees from the axis, behind the plane z = 0, to the right and a little up.
    let t = 100f32.to_radians();
    let p = [3.0 * t.sin() * 0.9, -3.0 * t.sin() * 0.3, 3.0 * t.cos()];
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, p, 0.05, 0.9, [1.0, 0.5, 0.2]);
    let fisheye = with_lens(
        Lens::Fisheye {
            k: [0.0; 4],
            max_theta: 110f64.to_radians(),
        },
        40.0,
        160,
    );
    let frame = render(&s, &fisheye);
    let (x, y) = pixel_of(&fisheye, p);
    let peak = frame.alpha[frame.index(x, y)];
    assert!(peak > 0.5, "alpha {peak} at ({x}, {y})");
    // Its footprint is small and around that pixel: nothing lit 10 pixels away.
    let lit: Vec<(u32, u32)> = (0..160)
        .flat_map(|j| (0..160).map(move |i| (i, j)))
        .filter(|&(i, j)| frame.alpha[frame.index(i, j)] > 0.0)
        .collect();
    assert!(!lit.is_empty());
    for (i, j) in &lit {
        assert!(i.abs_diff(x) < 10 && j.abs_diff(y) < 10, "({i}, {j}) lit");
    }
    // A pinhole of the same focal length sees nothing of it.
    let pinhole = with_lens(Lens::Pinhole, 40.0, 160);
    assert!(render(&s, &pinhole).alpha.iter().all(|&a| a == 0.0));
}

#[test]
fn an_equirectangular_camera_sees_every_direction() {
    let dirs = [
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 0.0, -1.0],
        [0.6, -0.8, 0.0],
        [0.0, 0.8, 0.6],
    ];
    let mut s = Scene::empty(0);
    for d in dirs {
        push_gaussian(&mut s, d.map(|v| 4.0 * v), 0.15, 0.9, [0.9, 0.9, 0.9]);
    }
    let cam = Camera {
        width: 256,
        height: 128,
        lens: Lens::FULL_SPHERE,
        ..axis_camera(1.0)
    };
    let frame = render(&s, &cam);
    for d in dirs {
        let p = d.map(|v| 4.0 * v);
        let (x, y) = pixel_of(&cam, p);
        // Straight behind lands on the seam, the right edge: its left neighbour is lit.
        let x = x.min(cam.width - 1);
        let a = frame.alpha[frame.index(x, y)];
        assert!(a > 0.5, "{d:?}: alpha {a} at ({x}, {y})");
    }
    // The image between them is empty: most of the sphere holds no Gaussian.
    let empty = frame.alpha.iter().filter(|&&a| a == 0.0).count();
    assert!(empty > frame.alpha.len() * 3 / 4, "{empty} empty pixels");
}

#[test]
fn a_gaussian_across_the_seam_is_drawn_on_both_sides_where_the_image_wraps() {
    // Straight behind the camera, on the seam of a full-sphere image, a little to its left
    // as the camera looks (its mean on the left edge).
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, [-0.05, 0.0, -4.0], 0.15, 0.9, [0.9, 0.9, 0.9]);
    let cam = |width: u32| Camera {
        width,
        height: 128,
        lens: Lens::FULL_SPHERE,
        ..axis_camera(1.0)
    };
    // 256 is whole tiles, 250 is not (its last tile partly empty): the image wraps at
    // both, and both edges see the same Gaussian the same way, mirrored about the seam
    // through its centre.
    for width in [256, 250] {
        let wide = cam(width);
        assert!(wide.lens.wraps());
        let frame = render(&s, &wide);
        let row = 64;
        let (left, right) = (
            frame.alpha[frame.index(0, row)],
            frame.alpha[frame.index(width - 1, row)],
        );
        assert!(left > 0.3 && right > 0.3, "{width}: edges {left} {right}");
        let px = wide
            .lens
            .project(&wide.intrinsics(), glam::DVec3::new(-0.05, 0.0, -4.0))
            .unwrap();
        assert!(px.x < 6.0, "{px}");
        // Pixel centres i + 0.5: the alpha falls off with the distance across the seam.
        let w = width as f64;
        let across = |x: u32| ((x as f64 + 0.5 - px.x + w / 2.0).rem_euclid(w) - w / 2.0).abs();
        for i in 0..12u32 {
            let x = (i + width - 6) % width;
            let next = (x + 1) % width;
            let (d, dn) = (across(x), across(next));
            let (a, an) = (
                frame.alpha[frame.index(x, row)],
                frame.alpha[frame.index(next, row)],
            );
            assert!(
                (d < dn) == (a > an) || (a - an).abs() < 1e-6,
                "{width}: ({x}: {a} at {d}) ({next}: {an} at {dn})"
            );
        }
    }
}

#[test]
fn an_orthographic_gaussian_keeps_its_size_at_any_distance() {
    let footprint = |z: f32| {
        let mut s = Scene::empty(0);
        push_gaussian(&mut s, [0.2, -0.1, z], 0.1, 0.9, [1.0; 3]);
        let cam = with_lens(Lens::Orthographic, 40.0, 64);
        let f = render(&s, &cam);
        let (x, y) = pixel_of(&cam, [0.2, -0.1, z]);
        (
            f.alpha.iter().filter(|&&a| a > 0.05).count(),
            f.alpha[f.index(x, y)],
        )
    };
    let (near, near_peak) = footprint(2.0);
    let (far, far_peak) = footprint(20.0);
    // sd 0.1 units at 40 px per unit: 4 px, a footprint of about pi (2.4 sd)^2.
    assert!(near > 100 && near < 400, "{near} pixels");
    assert_eq!(near, far);
    assert!(
        near_peak > 0.85 && near_peak == far_peak,
        "{near_peak} {far_peak}"
    );
}

#[test]
fn a_distorted_camera_draws_where_its_distortion_puts_a_gaussian() {
    let p = [1.2f32, 0.8, 3.0];
    let mut s = Scene::empty(0);
    push_gaussian(&mut s, p, 0.02, 0.9, [1.0; 3]);
    let lens = Lens::RadialTangential {
        radial: [-0.3, 0.08, 0.0, 0.0, 0.0, 0.0],
        tangential: [0.002, -0.001],
    };
    let cam = with_lens(lens, 60.0, 96);
    let frame = render(&s, &cam);
    let (x, y) = pixel_of(&cam, p);
    assert!(frame.alpha[frame.index(x, y)] > 0.5);
    // Barrel distortion pulls it towards the centre from where a pinhole draws it.
    let pin = with_lens(Lens::Pinhole, 60.0, 96);
    let (px, py) = pixel_of(&pin, p);
    assert!(x < px && y < py, "({x}, {y}) vs the pinhole's ({px}, {py})");
}

#[test]
fn a_lens_with_impossible_parameters_is_refused_by_name() {
    let mut cam = with_lens(
        Lens::Fisheye {
            k: [0.0; 4],
            max_theta: 4.0,
        },
        40.0,
        64,
    );
    let e = cam.validate().unwrap_err().to_string();
    assert!(e.contains("field of view") && e.contains("axis"), "{e}");
    cam.lens = Lens::Equirectangular {
        longitude: [0.0, 0.0],
        latitude: [FRAC_PI_2, -FRAC_PI_2],
    };
    assert!(cam
        .validate()
        .unwrap_err()
        .to_string()
        .contains("longitude"));
    cam.lens = Lens::Equirectangular {
        longitude: [-PI, PI],
        latitude: [2.0, -1.0],
    };
    assert!(cam
        .validate()
        .unwrap_err()
        .to_string()
        .contains("latitudes"));
}

#[test]
fn render_takes_a_lens_for_generated_cameras_and_refuses_what_cannot_draw_it() {
    use crate::common::cli::{stderr, verisplat_in};
    let dir = tempfile::tempdir().unwrap();
    let scene = crate::common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let scene = scene.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "render", scene, "--orbit", "1", "--width", "96", "--height", "64",
        ];
        args.extend_from_slice(extra);
        verisplat_in(dir.path(), &args)
    };
    // The CPU reference draws the fisheye; its 200 degrees show the scene smaller than
    // the pinhole's 50 from the same place.
    let lit = |lens: &str| {
        let o = run(&["--cpu", "--lens", lens, "-o", "lens.png"]);
        assert!(o.status.success(), "{lens}: {}", stderr(&o));
        let img = image::open(dir.path().join("lens.png")).unwrap().to_rgb8();
        std::fs::remove_file(dir.path().join("lens.png")).unwrap();
        img.pixels().filter(|p| p.0 != [0, 0, 0]).count()
    };
    let (fisheye, pinhole) = (lit("fisheye:fov=200"), lit("pinhole"));
    assert!(fisheye > 20 && pinhole > 4 * fisheye, "{fisheye} {pinhole}");
    // The GPU renderer draws it too (tests/all/render/lenses.rs checks it against the
    // reference); an export COLMAP cannot hold is refused before writing anything.
    let o = run(&["--lens", "fisheye:fov=200", "-o", "gpu.png"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("gpu.png").exists());
    for (extra, says) in [
        (
            &["--cpu", "--lens", "equirect", "--export-colmap", "data"][..],
            "which COLMAP has no camera model for",
        ),
        (
            &["--cpu", "--lens", "fisheye:fov=400", "-o", "x.png"][..],
            "at most 360",
        ),
    ] {
        let o = run(extra);
        assert!(
            !o.status.success() && stderr(&o).contains(says),
            "{extra:?}: {}",
            stderr(&o)
        );
    }
    assert!(!dir.path().join("x.png").exists() && !dir.path().join("data").exists());
}

#[test]
fn an_equirectangular_window_defaults_to_its_angles_ratio() {
    // Issue 59: the whole sphere came out 1280x720 by default and 1000x563 with --width
    // 1000 alone, stretched in any 360-degree viewer.
    use crate::common::cli::{stderr, verisplat_in};
    let dir = tempfile::tempdir().unwrap();
    let scene = crate::common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let size = |extra: &[&str]| {
        let mut args = vec![
            "render",
            scene.to_str().unwrap(),
            "--cpu",
            "-o",
            "pano.png",
            "--overwrite",
        ];
        args.extend_from_slice(extra);
        let o = verisplat_in(dir.path(), &args);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        image::image_dimensions(dir.path().join("pano.png")).unwrap()
    };
    assert_eq!(size(&["--lens", "equirect", "--width", "200"]), (200, 100));
    assert_eq!(
        size(&["--lens", "equirect", "--width", "1001", "--height", "20"]),
        (1001, 20)
    );
    assert_eq!(size(&["--lens", "equirect", "--height", "51"]), (102, 51));
    assert_eq!(
        size(&[
            "--lens",
            "equirect:lon=-60..60,lat=30..-30",
            "--width",
            "300"
        ]),
        (300, 150)
    );
    assert_eq!(
        size(&["--lens", "equirect:lon=0..90,lat=45..-45", "--height", "64"]),
        (64, 64)
    );
    // Other lenses keep 16:9.
    assert_eq!(size(&["--lens", "fisheye", "--width", "160"]), (160, 90));
    assert_eq!(size(&["--width", "160"]), (160, 90));
}
