//! Every real INRIA scene in `../shared/data/` loads and renders a recognisable image.

use crate::common;
use verisplat::camera::{self, Camera};
use verisplat::cpu::{self, RenderOptions};
use verisplat::scene;

fn orbit_camera(name: &str, index: usize) -> Camera {
    let path = common::shared_data().join(name);
    let cams = camera::load_cameras_json(&path).unwrap();
    assert_eq!(cams.len(), 24);
    cams[index].with_resolution(320, 180).unwrap()
}

#[test]
fn real_scenes_load_and_render() {
    let cases = [
        (
            "playbot_lod6_1873_sh2.ply",
            1873,
            2,
            Some("playbot_orbit_cameras.synthetic.json"),
        ),
        (
            "playbot_lod3_31k_sh2.ply",
            31_000,
            2,
            Some("playbot_orbit_cameras.synthetic.json"),
        ),
        (
            "playbot_lod2_125k_sh2.ply",
            125_000,
            2,
            Some("playbot_orbit_cameras.synthetic.json"),
        ),
        (
            "playbot_lod1_250k_sh1.ply",
            250_000,
            1,
            Some("playbot_orbit_cameras.synthetic.json"),
        ),
        (
            "plant_113k_sh0.ply",
            113_648,
            0,
            Some("plant_orbit_cameras.synthetic.json"),
        ),
        ("train3_sh3.ply", 3, 3, None),
    ];
    for (file, count, deg, cams) in cases {
        let s = scene::load(&common::shared_data().join(file)).unwrap();
        assert_eq!((s.len(), s.sh_degree), (count, deg), "{file}");
        let cam = match cams {
            Some(c) => orbit_camera(c, 3),
            None => camera::default_camera(&s.positions, 320, 180),
        };
        let f = cpu::render(&s.activated(), &cam, &RenderOptions::default());
        let covered = f.alpha.iter().filter(|&&a| a > 0.5).count() as f64 / f.alpha.len() as f64;
        assert!(f.color.iter().flatten().all(|v| v.is_finite()), "{file}");
        if count > 1000 {
            // Each object fills a clear part of the frame from its suggested orbit.
            assert!((0.03..0.9).contains(&covered), "{file}: covered {covered}");
        } else {
            assert!(f.alpha.iter().any(|&a| a > 0.0), "{file}: nothing visible");
        }
    }
}

#[test]
fn default_camera_frames_the_bulk_despite_outliers() {
    let mut s = scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply")).unwrap();
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

#[test]
fn cameras_json_matches_the_documented_convention() {
    let cam = orbit_camera("playbot_orbit_cameras.synthetic.json", 0);
    // Camera 0 sits at (0, -1.7, -3.2) looking at the robot near (0, -0.5, 0).
    assert!((cam.position() - glam::Vec3::new(0.0, -1.7, -3.2)).length() < 1e-5);
    let target = cam.rotation * glam::Vec3::new(0.0, -0.5, 0.0) + cam.translation;
    assert!(
        target.z > 0.0 && (target.x / target.z).abs() < 0.01 && (target.y / target.z).abs() < 0.01
    );
    // Resolution override rescales the focal length.
    assert!((cam.fx - 772.0225 / 4.0).abs() < 1e-3);
}
