//! Camera sources: every file format loads to the expected world-to-camera pose and
//! intrinsics, the orbit and keyframe paths behave, selection specs work, and malformed
//! inputs give clear errors instead of panics.

mod colmap;
mod keyframes;
mod lenses;

use crate::common;
use glam::{DMat3, Mat3, Vec2, Vec3};
use std::path::{Path, PathBuf};
use verisplat::core::camera::{self, default_camera, orbit, select_cameras, Camera, OrbitParams};
use verisplat::io;
use verisplat::io::camera::{load_camera_file, CameraFormat, PathTiming};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/cameras")
}

/// Continuous image coordinates of a world point (pixel centres at +0.5, so the
/// principal point `(cx, cy)` is where the optical axis lands) and its depth.
fn project(cam: &Camera, p: Vec3) -> (Vec2, f32) {
    let v = cam.rotation * p + cam.translation;
    (
        Vec2::new(cam.fx * v.x / v.z + cam.cx, cam.fy * v.y / v.z + cam.cy),
        v.z,
    )
}

/// A camera at (0, 0, -5) looking at the origin with -y up: the origin lands on the
/// image centre, +x world on the right half, -y world ("up") on the upper half.
fn assert_front_view(cam: &Camera) {
    let what = &cam.name;
    assert!(
        (cam.position() - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-5,
        "{what}: {}",
        cam.position()
    );
    let (o, z) = project(cam, Vec3::ZERO);
    assert!(z > 0.0, "{what}: origin behind the camera");
    let centre = Vec2::new(cam.width as f32 / 2.0, cam.height as f32 / 2.0);
    assert!(
        (o - centre).length() < 1e-3,
        "{what}: origin at {o}, centre {centre}"
    );
    let (px, _) = project(cam, Vec3::X);
    assert!(
        px.x > centre.x + 1.0 && (px.y - centre.y).abs() < 1e-3,
        "{what}: +x at {px}"
    );
    let (up, _) = project(cam, Vec3::NEG_Y);
    assert!(
        up.y < centre.y - 1.0 && (up.x - centre.x).abs() < 1e-3,
        "{what}: -y at {up}"
    );
}

fn assert_mat_close(a: Mat3, b: Mat3, tol: f32, what: &str) {
    assert!(a.abs_diff_eq(b, tol), "{what}: rotation\n{a}\nvs\n{b}");
}

fn assert_vec_close(a: Vec3, b: Vec3, tol: f32, what: &str) {
    assert!(a.abs_diff_eq(b, tol), "{what}: {a} vs {b}");
}

/// Same pose and intrinsics within `tol` (names may differ).
fn assert_same_camera(a: &Camera, b: &Camera, tol: f32) {
    let what = format!("{} vs {}", a.name, b.name);
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}");
    assert_mat_close(a.rotation, b.rotation, tol, &what);
    assert_vec_close(a.translation, b.translation, tol * 10.0, &what);
    for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
        assert!(
            (x - y).abs() <= 1e-3 * x.abs().max(1.0),
            "{what}: intrinsics {x} vs {y}"
        );
    }
}

fn load(path: &Path) -> (Vec<Camera>, CameraFormat) {
    load_camera_file(path, &PathTiming::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn load_err(path: &Path) -> String {
    match load_camera_file(path, &PathTiming::default()) {
        Ok((cams, f)) => panic!(
            "{} loaded as {f} with {} cameras",
            path.display(),
            cams.len()
        ),
        Err(e) => e.to_string(),
    }
}

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    if let Some(parent) = p.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(&p, bytes).unwrap();
    p
}

/// 640x480, f = 500: the front camera every format describes.
fn front_camera() -> Camera {
    Camera {
        name: "front".into(),
        width: 640,
        height: 480,
        fx: 500.0,
        fy: 500.0,
        cx: 320.0,
        cy: 240.0,
        rotation: Mat3::IDENTITY,
        translation: Vec3::new(0.0, 0.0, 5.0),
        lens: verisplat::core::camera::Lens::Pinhole,
    }
}

/// Varied look-at cameras (all with -y up, positions a few units from the origin).
fn assorted_cameras(n: usize) -> Vec<Camera> {
    let mut rng = common::Rng(7);
    (0..n)
        .map(|i| {
            let eye = Vec3::new(
                rng.range(-4.0, 4.0),
                rng.range(-3.0, 1.0),
                rng.range(-6.0, -2.0),
            );
            let target = Vec3::new(
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
            );
            Camera::look_at(
                &format!("cam{i}"),
                320,
                240,
                rng.range(0.5, 1.2),
                eye,
                target,
                Vec3::NEG_Y,
            )
        })
        .collect()
}

// ---------------------------------------------------------------- INRIA cameras.json

#[test]
fn inria_json_front_camera() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "cameras.json",
        r#"[{"id": 0, "img_name": "front", "width": 640, "height": 480, "position": [0, 0, -5],
             "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 500, "fy": 500}]"#,
    );
    let (cams, format) = load(&p);
    assert_eq!(format, CameraFormat::InriaJson);
    assert_eq!(cams.len(), 1);
    assert_same_camera(&cams[0], &front_camera(), 1e-6);
    assert_front_view(&cams[0]);
}

#[test]
fn inria_json_malformed() {
    let entry = |rotation: &str, fx: &str| {
        format!(
            r#"[{{"id": 0, "img_name": "a", "width": 64, "height": 48, "position": [0, 0, -5],
                 "rotation": {rotation}, "fx": {fx}, "fy": 50}}]"#
        )
    };
    let eye = "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]";
    let cases = [
        (
            entry("[[0, 0, 0], [0, 0, 0], [0, 0, 0]]", "50"),
            "not a rotation matrix",
        ),
        (entry("[[1, 0], [0, 1]]", "50"), "not an INRIA cameras.json"),
        (entry(eye, "0"), "non-positive intrinsics"),
        (entry(eye, "NaN"), "not valid JSON"),
        (entry(eye, "1e999"), "not valid JSON"),
        (
            entry(eye, "50").replace("\"width\": 64", "\"width\": 0"),
            "not usable",
        ),
        (r#"[{"id": 0}]"#.to_string(), "missing field"),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (text, msg) in cases {
        let e = load_err(&write(dir.path(), "cameras.json", &text));
        assert!(
            e.contains(msg) && e.contains("cameras.json"),
            "{text}\n  -> {e}"
        );
    }
}

#[test]
fn inria_json_rotation_columns_are_camera_axes() {
    // The synthetic orbit files: stored rows are the camera-to-world rotation, so its
    // columns are the camera axes; every camera of the ring looks at the bulk centre.
    let path = common::shared_data().join("playbot_orbit_cameras.synthetic.json");
    assert!(path.is_file(), "{} is missing", path.display());
    let (cams, format) = load(&path);
    assert_eq!((format, cams.len()), (CameraFormat::InriaJson, 24));
    for c in &cams {
        let (p, z) = project(c, Vec3::new(0.0, -0.5, 0.0));
        assert!(
            z > 0.0 && (p - Vec2::new(640.0, 360.0)).length() < 0.5,
            "{}: {p}",
            c.name
        );
    }
}

// ---------------------------------------------------------------- nerfstudio

#[test]
fn nerfstudio_front_camera() {
    let (cams, format) = load(&fixtures().join("nerfstudio_camera_path.json"));
    assert_eq!(format, CameraFormat::NerfstudioPath);
    assert_eq!(cams.len(), 1);
    assert_eq!(cams[0].name, "path_00000");
    assert_same_camera(&cams[0], &front_camera(), 1e-6);
    assert_front_view(&cams[0]);
}

#[test]
fn nerfstudio_opengl_axes_convert_for_any_pose() {
    // An OpenGL camera-to-world (x right, y up, z back) built from each look-at camera
    // loads back to the same OpenCV world-to-camera pose.
    let cams = assorted_cameras(6);
    let entries: Vec<String> = cams
        .iter()
        .map(|c| {
            let c2w = c.rotation.transpose().as_dmat3();
            let gl = DMat3::from_cols(c2w.x_axis, -c2w.y_axis, -c2w.z_axis);
            let p = c.position().as_dvec3();
            let m = [
                gl.x_axis.x,
                gl.y_axis.x,
                gl.z_axis.x,
                p.x,
                gl.x_axis.y,
                gl.y_axis.y,
                gl.z_axis.y,
                p.y,
                gl.x_axis.z,
                gl.y_axis.z,
                gl.z_axis.z,
                p.z,
                0.0,
                0.0,
                0.0,
                1.0,
            ];
            let fov = (2.0 * (c.height as f64 / (2.0 * c.fy as f64)).atan()).to_degrees();
            format!(r#"{{"camera_to_world": {m:?}, "fov": {fov}, "aspect": 1.333}}"#)
        })
        .collect();
    let text = format!(
        r#"{{"render_width": 320, "render_height": 240, "fps": 30, "seconds": 1, "camera_path": [{}]}}"#,
        entries.join(",")
    );
    let dir = tempfile::tempdir().unwrap();
    let (loaded, _) = load(&write(dir.path(), "path.json", text));
    for (a, b) in loaded.iter().zip(&cams) {
        assert_same_camera(a, b, 1e-6);
    }
}

#[test]
fn nerfstudio_malformed() {
    let m = "[1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, -5, 0, 0, 0, 1]";
    let file = |extra: &str, entry: &str| {
        format!(r#"{{"render_width": 64, "render_height": 48{extra}, "camera_path": [{entry}]}}"#)
    };
    let cases = [
        (
            file(
                r#", "camera_type": "orthophoto""#,
                &format!(r#"{{"camera_to_world": {m}, "fov": 50}}"#),
            ),
            "camera_type \"orthophoto\" is not supported; it must be \"perspective\", \"fisheye\" or \"equirectangular\"",
        ),
        (
            file("", r#"{"camera_to_world": [1, 0, 0], "fov": 50}"#),
            "has 3 numbers",
        ),
        (
            file(
                "",
                r#"{"camera_to_world": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1], "fov": 50}"#,
            ),
            "not a rigid transform",
        ),
        (
            file("", &format!(r#"{{"camera_to_world": {m}}}"#)),
            "has no \"fov\"",
        ),
        (
            file("", &format!(r#"{{"camera_to_world": {m}, "fov": 0}}"#)),
            "fov 0 degrees",
        ),
        (
            file("", &format!(r#"{{"camera_to_world": {m}, "fov": NaN}}"#)),
            "not valid JSON",
        ),
        (
            file("", &format!(r#"{{"camera_to_world": {m}, "fov": 1e999}}"#)),
            "not valid JSON",
        ),
        (file("", ""), "no cameras"),
        (
            r#"{"camera_path": []}"#.to_string(),
            "missing field `render_width`",
        ),
        (
            r#"{"render_width": 0, "render_height": 48, "camera_path": []}"#.to_string(),
            "not usable",
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (text, msg) in cases {
        let e = load_err(&write(dir.path(), "p.json", &text));
        assert!(e.contains(msg), "{text}: {e}");
    }
    // Default fov from the file when an entry has none.
    let text = file(
        r#", "default_fov": 51.28201164861056"#,
        &format!(r#"{{"camera_to_world": {m}}}"#),
    );
    let (cams, _) = load(&write(dir.path(), "p.json", text));
    assert!((cams[0].fy - 50.0).abs() < 1e-3);
}

// ---------------------------------------------------------------- orbit

#[test]
fn orbit_front_view_and_invariants() {
    let front = OrbitParams {
        frames: 4,
        centre: Some(Vec3::ZERO),
        radius: Some(5.0),
        elevation_deg: 0.0,
        vfov_deg: 51.282_01,
        width: 640,
        height: 480,
        ..Default::default()
    };
    let cams = orbit(&[], &front).unwrap();
    assert_same_camera(&cams[0], &front_camera(), 1e-6);
    assert_front_view(&cams[0]);
    // A quarter turn later the camera is on the +x side (azimuth grows towards +x).
    assert!(
        (cams[1].position() - Vec3::new(5.0, 0.0, 0.0)).length() < 1e-5,
        "{}",
        cams[1].position()
    );

    let scene = verisplat::io::demo::demo_scene();
    let p = OrbitParams {
        frames: 36,
        start_deg: 0.0,
        ..Default::default()
    };
    let cams = orbit(&scene.positions, &p).unwrap();
    assert_eq!(cams.len(), 36);
    let b = camera::bulk_bounds(&scene.positions);
    let radius0 = (cams[0].position() - b.box_centre()).length();
    let up = Vec3::NEG_Y;
    for (k, c) in cams.iter().enumerate() {
        assert_eq!(c.name, format!("orbit_{k:05}"));
        c.validate().unwrap();
        let (pc, z) = project(c, b.box_centre());
        assert!(
            z > 0.0 && (pc - Vec2::new(c.cx, c.cy)).length() < 1e-3,
            "frame {k}: centre at {pc}"
        );
        let d = c.position() - b.box_centre();
        assert!(
            (d.length() - radius0).abs() < 1e-4 * radius0,
            "frame {k}: radius {}",
            d.length()
        );
        let elevation = (d.normalize().dot(up)).asin().to_degrees();
        assert!(
            (elevation - 20.0).abs() < 1e-3,
            "frame {k}: elevation {elevation}"
        );
        // Evenly spaced: 10 degrees between neighbours, and the last does not repeat the first.
        let next = cams[(k + 1) % cams.len()].position() - b.box_centre();
        let step = d
            .normalize()
            .dot(next.normalize())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        let expected = 2.0
            * (20f32.to_radians().cos() * 5f32.to_radians().sin())
                .asin()
                .to_degrees();
        assert!(
            (step - expected).abs() < 1e-2,
            "frame {k}: step {step} vs {expected}"
        );
    }
    let default = default_camera(&scene.positions, 1280, 720);
    assert_eq!(
        Camera {
            name: "default".into(),
            ..cams[0].clone()
        },
        default
    );
}

// ---------------------------------------------------------------- detection, selection

#[test]
fn format_detection_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8], &str); 6] = [
        (
            "a.json",
            b"{\"foo\": 1}",
            "no \"camera_path\" (nerfstudio), \"keyframes\" (keyframe path) or \"frames\" list",
        ),
        ("b.json", b"\"just a string\"", "not a camera file"),
        ("c.json", b"[1, 2]", "not an INRIA cameras.json"),
        ("d.json", b"[{\"id\": 0", "not valid JSON"),
        ("e.txt", b"not json at all", "not valid JSON"),
        ("f.bin", &[0xff, 0x00, 0x13], "not UTF-8"),
    ];
    for (name, bytes, msg) in cases {
        let e = load_err(&write(dir.path(), name, bytes));
        assert!(e.contains(msg) && e.contains(name), "{name}: {e}");
    }
    assert!(load_err(&dir.path().join("missing.json")).contains("cannot read"));
    assert!(load_err(&write(dir.path(), "empty.json", "[]")).contains("no cameras"));
    assert_eq!(
        io::camera::detect_camera_format(&fixtures().join("keyframes_example.json")).unwrap(),
        CameraFormat::Keyframes
    );
    assert_eq!(
        io::camera::detect_camera_format(&fixtures().join("colmap_text")).unwrap(),
        CameraFormat::ColmapText
    );
    assert_eq!(
        CameraFormat::ColmapBinary.to_string(),
        "COLMAP sparse model (binary)"
    );
}

#[test]
fn selection_on_loaded_cameras() {
    let dir = fixtures().join("colmap_text");
    let (cams, _) = load(&dir);
    let pick = |spec: &str| {
        select_cameras(&cams, spec, &dir).map(|v| v.into_iter().map(|c| c.name).collect::<Vec<_>>())
    };
    assert_eq!(pick("all").unwrap(), ["front.png", "side.png"]);
    assert_eq!(pick("1,0").unwrap(), ["side.png", "front.png"]);
    assert_eq!(pick("0..=1").unwrap(), ["front.png", "side.png"]);
    assert_eq!(pick("side, front.png").unwrap(), ["side.png", "front.png"]);
    let e = pick("0..3").unwrap_err().to_string();
    assert!(
        e.contains("reaches past the last camera")
            && e.contains("0..=1")
            && e.contains("colmap_text"),
        "{e}"
    );
    let e = pick("back").unwrap_err().to_string();
    assert!(
        e.contains("no camera named \"back\"") && e.contains("front.png"),
        "{e}"
    );
}
