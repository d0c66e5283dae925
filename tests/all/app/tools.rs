//! The scripts of `tools/` that drive the binary for a user: `tools/fisheye_dataset.py`
//! centres its rigs where `render --orbit` looks, and a failure is one sentence and a
//! non-zero exit, never a Python traceback (issue 59, items 6 and 12).

use crate::common::{self, cli::bin};
use std::path::Path;
use std::process::{Command, Output};

/// Runs `tools/fisheye_dataset.py` with `args` and this build's binary.
fn fisheye_dataset(args: &[&str]) -> Output {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/fisheye_dataset.py");
    Command::new("python3")
        .arg(script)
        .args(args)
        .args(["--verisplat", bin()])
        .env("VERISPLAT_VALIDATE", "1")
        .output()
        .expect("python3 runs tools/fisheye_dataset.py")
}

/// Its standard error, checked to be one `error:` sentence of a failed run.
fn one_sentence(o: &Output) -> String {
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "must fail: {e}");
    assert!(!e.contains("Traceback"), "a traceback: {e}");
    assert!(e.starts_with("error: "), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "one sentence: {e}");
    e
}

#[test]
fn fisheye_rigs_look_at_the_orbits_centre_and_fail_in_one_sentence() {
    let scene_path = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let scene = verisplat::io::scene::load(&scene_path).unwrap();
    let bulk = verisplat::core::camera::bulk_bounds(&scene.positions);
    let centre = bulk.box_centre();
    // The check means something only where the median is elsewhere.
    assert!(
        centre.distance(bulk.centre) > 1e-3,
        "{centre} {}",
        bulk.centre
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fish");
    let args = [
        scene_path.to_str().unwrap(),
        out.to_str().unwrap(),
        "--width",
        "32",
        "--height",
        "24",
        "--rings",
        "20:3",
    ];
    let o = fisheye_dataset(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rig: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("rig.json")).unwrap()).unwrap();
    let rig = rig.as_array().unwrap();
    assert_eq!(rig.len(), 3);
    let f32s = |v: &serde_json::Value| -> Vec<f32> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect()
    };
    for cam in rig {
        // Each camera's optical axis (the rotation's third column) passes through the
        // centre the orbits look at.
        let eye = glam::Vec3::from_slice(&f32s(&cam["position"]));
        let rows: Vec<Vec<f32>> = cam["rotation"]
            .as_array()
            .unwrap()
            .iter()
            .map(f32s)
            .collect();
        let forward = glam::Vec3::new(rows[0][2], rows[1][2], rows[2][2]);
        let to_centre = centre - eye;
        let off_axis = (to_centre - forward * to_centre.dot(forward)).length();
        assert!(off_axis < 1e-5 * to_centre.length(), "{cam}: {off_axis}");
    }
    assert!(out.join("images/fish_000.png").is_file());
    // Into the same folder again, without --overwrite: one sentence.
    let e = one_sentence(&fisheye_dataset(&args));
    assert!(
        e.contains("already exists") && e.contains("--overwrite"),
        "{e}"
    );
    // verisplat's own sentence (a scene it cannot read) is the script's.
    let missing = dir.path().join("missing.ply");
    let e = one_sentence(&fisheye_dataset(&[
        missing.to_str().unwrap(),
        dir.path().join("other").to_str().unwrap(),
    ]));
    assert!(e.contains("missing.ply"), "{e}");
}
