//! The default camera (`camera::default_camera`): it frames a scene's robust box, centred
//! and with a tight margin, as frame 0 of the default orbit, and one stray Gaussian far
//! away does not move it. (They need a scene, the demo's or a shared one, so they live
//! here rather than in `src/core/camera`, which uses no module above it.)

use crate::common;
use glam::Vec3;
use verisplat::core::camera;
use verisplat::core::camera::default_camera;
use verisplat::io;

/// Pixel coordinates and depth of a world point seen by `cam`.
fn project_point(cam: &verisplat::core::camera::Camera, p: Vec3) -> (f32, f32, f32) {
    let v = cam.rotation * p + cam.translation;
    (
        cam.fx * v.x / v.z + cam.cx,
        cam.fy * v.y / v.z + cam.cy,
        v.z,
    )
}

#[test]
fn default_camera_frames_the_whole_robust_box_centred_and_is_orbit_frame_0() {
    let scene = verisplat::io::demo::demo_scene();
    let b = verisplat::core::camera::bulk_bounds(&scene.positions);
    for (w, h) in [(1280, 720), (320, 240), (100, 70), (480, 640)] {
        let default = verisplat::core::camera::default_camera(&scene.positions, w, h);
        let frames = verisplat::core::camera::orbit(
            &scene.positions,
            &verisplat::core::camera::OrbitParams {
                frames: 7,
                width: w,
                height: h,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(frames.len(), 7);
        assert_eq!(frames[0].name, "orbit_00000");
        assert_eq!(
            verisplat::core::camera::Camera {
                name: "default".into(),
                ..frames[0].clone()
            },
            default
        );
        for cam in &frames {
            // The box centre is the image centre.
            let (u, v, _) = project_point(cam, b.box_centre());
            assert!((u - cam.cx).abs() < 1e-2 && (v - cam.cy).abs() < 1e-2);
            // Every corner is inside the image, with the 5% margin, and one corner
            // touches that margin on some frame (the framing is tight, not loose).
            for k in 0..8 {
                let c = Vec3::new(
                    if k & 1 == 0 { b.lo.x } else { b.hi.x },
                    if k & 2 == 0 { b.lo.y } else { b.hi.y },
                    if k & 4 == 0 { b.lo.z } else { b.hi.z },
                );
                let (u, v, z) = project_point(cam, c);
                assert!(z > 0.0, "{w}x{h} {}: corner {k} behind", cam.name);
                let (mu, mv) = (cam.cx - cam.cx / 1.05, cam.cy - cam.cy / 1.05);
                assert!(
                    u >= mu - 0.01 && u <= w as f32 - mu + 0.01,
                    "{w}x{h} {}: corner {k} at u = {u}",
                    cam.name
                );
                assert!(
                    v >= mv - 0.01 && v <= h as f32 - mv + 0.01,
                    "{w}x{h} {}: corner {k} at v = {v}",
                    cam.name
                );
            }
        }
    }
    // An empty scene still gets a valid camera.
    default_camera(&[], 64, 48).validate().unwrap();
}

#[test]
fn default_camera_frames_the_bulk_despite_outliers() {
    let mut s = io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply")).unwrap();
    let before = camera::default_camera(&s.positions, 320, 180);
    // One stray Gaussian far away must not move the framing noticeably.
    s.positions.push([500.0, -800.0, 900.0]);
    let after = camera::default_camera(&s.positions, 320, 180);
    assert!((before.position() - after.position()).length() < 0.05);
    // The centre of the robust box projects to the image centre.
    let b = camera::bulk_bounds(&s.positions);
    let p = after.rotation * b.box_centre() + after.translation;
    let (u, v) = (
        after.fx * p.x / p.z + after.cx,
        after.fy * p.y / p.z + after.cy,
    );
    assert!(
        (u - 160.0).abs() < 1.0 && (v - 90.0).abs() < 1.0,
        "({u}, {v})"
    );
}
