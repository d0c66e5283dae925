//! Every real INRIA scene in `../shared/data/` loads and renders a recognisable image, and
//! the orbit cameras.json beside them follows the documented convention.

use crate::common;
use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;

/// Camera `index` of an orbit file of the shared scenes at 320x180; the file holds the 24
/// cameras of its orbit.
fn orbit_camera(name: &str, index: usize) -> Camera {
    assert_eq!(common::orbit_cameras(name).len(), 24);
    common::orbit(name, index, 320, 180)
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
        let s = io::scene::load(&common::shared_data().join(file)).unwrap();
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
