//! Camera sources: every file format loads to the expected world-to-camera pose and
//! intrinsics, the orbit and keyframe paths behave, selection specs work, and malformed
//! inputs give clear errors instead of panics.

use crate::common;
use glam::{DMat3, DQuat, Mat3, Vec2, Vec3};
use std::path::{Path, PathBuf};
use vksplat::camera::{
    self, default_camera, keyframes_to_json, load_camera_file, orbit, select_cameras, Camera,
    CameraError, CameraFormat, KeyframePath, OrbitParams, PathTiming,
};

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

// ---------------------------------------------------------------- COLMAP

/// `cameras` with id i + 1 as PINHOLE and images named by camera name, as COLMAP text.
fn colmap_text(cams: &[Camera]) -> (String, String) {
    let mut c = String::from("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let mut im = String::from("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    for (i, cam) in cams.iter().enumerate() {
        c += &format!(
            "{} PINHOLE {} {} {} {} {} {}\n",
            i + 1,
            cam.width,
            cam.height,
            cam.fx,
            cam.fy,
            cam.cx,
            cam.cy
        );
        let q = DQuat::from_mat3(&cam.rotation.as_dmat3());
        let t = cam.translation;
        im += &format!(
            "{} {} {} {} {} {} {} {} {} {}\n1.0 2.0 -1\n",
            i + 1,
            q.w,
            q.x,
            q.y,
            q.z,
            t.x as f64,
            t.y as f64,
            t.z as f64,
            i + 1,
            cam.name
        );
    }
    (c, im)
}

/// COLMAP binary camera record: id, model id, width, height (u64), f64 params.
fn bin_camera(out: &mut Vec<u8>, id: u32, model: i32, w: u64, h: u64, params: &[f64]) {
    out.extend(id.to_le_bytes());
    out.extend(model.to_le_bytes());
    out.extend(w.to_le_bytes());
    out.extend(h.to_le_bytes());
    for p in params {
        out.extend(p.to_le_bytes());
    }
}

/// COLMAP binary image record with `points` 2D points.
fn bin_image(
    out: &mut Vec<u8>,
    id: u32,
    q: [f64; 4],
    t: [f64; 3],
    cam: u32,
    name: &str,
    points: u64,
) {
    out.extend(id.to_le_bytes());
    for v in q.iter().chain(&t) {
        out.extend(v.to_le_bytes());
    }
    out.extend(cam.to_le_bytes());
    out.extend(name.as_bytes());
    out.push(0);
    out.extend(points.to_le_bytes());
    for k in 0..points {
        out.extend((k as f64 * 1.5).to_le_bytes());
        out.extend(2.5f64.to_le_bytes());
        out.extend((k as i64 - 1).to_le_bytes());
    }
}

/// `cams` as COLMAP's binary `cameras.bin` and `images.bin` (one PINHOLE camera each).
fn colmap_bin(cams: &[Camera]) -> (Vec<u8>, Vec<u8>) {
    let mut c = (cams.len() as u64).to_le_bytes().to_vec();
    let mut im = (cams.len() as u64).to_le_bytes().to_vec();
    for (i, cam) in cams.iter().enumerate() {
        let id = i as u32 + 1;
        bin_camera(
            &mut c,
            id,
            1,
            cam.width as u64,
            cam.height as u64,
            &[cam.fx as f64, cam.fy as f64, cam.cx as f64, cam.cy as f64],
        );
        let q = DQuat::from_mat3(&cam.rotation.as_dmat3());
        let t = cam.translation.as_dvec3();
        bin_image(
            &mut im,
            id,
            [q.w, q.x, q.y, q.z],
            t.to_array(),
            id,
            &cam.name,
            i as u64 % 3,
        );
    }
    (c, im)
}

#[test]
fn colmap_text_fixture() {
    let dir = fixtures().join("colmap_text");
    let (cams, format) = load(&dir);
    assert_eq!(format, CameraFormat::ColmapText);
    // Sorted by name: "front.png" before "side.png" although listed after it.
    let names: Vec<&str> = cams.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["front.png", "side.png"]);
    assert_same_camera(&cams[0], &front_camera(), 1e-6);
    assert_front_view(&cams[0]);
    // SIMPLE_PINHOLE keeps its off-centre principal point as written.
    let side = &cams[1];
    assert_eq!(
        (side.width, side.height, side.fx, side.fy, side.cx, side.cy),
        (320, 240, 250.0, 250.0, 150.5, 110.25)
    );
    let expected_side = Camera::look_at(
        "x",
        320,
        240,
        1.0,
        Vec3::new(-5.0, 0.0, 0.0),
        Vec3::ZERO,
        Vec3::NEG_Y,
    );
    assert_mat_close(side.rotation, expected_side.rotation, 1e-6, "side");
    assert_vec_close(side.translation, expected_side.translation, 1e-5, "side");
    let (o, _) = project(side, Vec3::ZERO);
    assert!((o - Vec2::new(150.5, 110.25)).length() < 1e-3, "{o}");
    assert!(
        project(side, Vec3::NEG_Z).0.x > 150.5 + 1.0,
        "-z is to the right from -x"
    );
    assert!(project(side, Vec3::NEG_Y).0.y < 110.25 - 1.0);

    // The same model found from the file path, and under sparse/0.
    assert_eq!(load(&dir.join("images.txt")).0, cams);
    assert_eq!(load(&dir.join("cameras.txt")).0, cams);
    let tmp = tempfile::tempdir().unwrap();
    for f in ["cameras.txt", "images.txt"] {
        write(
            tmp.path(),
            &format!("sparse/0/{f}"),
            std::fs::read(dir.join(f)).unwrap(),
        );
    }
    assert_eq!(load(tmp.path()), (cams, CameraFormat::ColmapText));
}

#[test]
fn colmap_text_and_binary_round_trip_poses() {
    let cams = assorted_cameras(12);
    let mut sorted = cams.clone();
    sorted.sort_by(|a, b| a.name.cmp(&b.name));
    let dir = tempfile::tempdir().unwrap();
    let (c, im) = colmap_text(&cams);
    write(dir.path(), "txt/cameras.txt", c);
    write(dir.path(), "txt/images.txt", im);
    let (c, im) = colmap_bin(&cams);
    write(dir.path(), "bin/sparse/0/cameras.bin", c);
    let images_bin = write(dir.path(), "bin/sparse/0/images.bin", im);
    for (path, format) in [
        (dir.path().join("txt"), CameraFormat::ColmapText),
        (dir.path().join("bin"), CameraFormat::ColmapBinary),
        (images_bin, CameraFormat::ColmapBinary),
    ] {
        let (loaded, f) = load(&path);
        assert_eq!(f, format, "{}", path.display());
        assert_eq!(loaded.len(), sorted.len());
        for (a, b) in loaded.iter().zip(&sorted) {
            assert_eq!(a.name, b.name);
            assert_same_camera(a, b, 1e-6);
        }
    }
}

#[test]
fn colmap_binary_front_camera() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = 1u64.to_le_bytes().to_vec();
    bin_camera(&mut c, 4, 1, 640, 480, &[500.0, 500.0, 320.0, 240.0]);
    let mut im = 1u64.to_le_bytes().to_vec();
    bin_image(
        &mut im,
        9,
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 5.0],
        4,
        "front.png",
        5,
    );
    write(dir.path(), "cameras.bin", c);
    write(dir.path(), "images.bin", im);
    let (cams, format) = load(dir.path());
    assert_eq!(format, CameraFormat::ColmapBinary);
    assert_same_camera(&cams[0], &front_camera(), 1e-7);
    assert_front_view(&cams[0]);
}

#[test]
fn colmap_models_with_zero_distortion_are_accepted_others_refused() {
    let dir = tempfile::tempdir().unwrap();
    let images = "1 1 0 0 0 0 0 5 1 a.png\n\n";
    let cases = [
        ("SIMPLE_RADIAL 640 480 500 320 240 0", None),
        ("RADIAL 640 480 500 320 240 0 0", None),
        ("OPENCV 640 480 500 500 320 240 0 0 0 0", None),
        ("FULL_OPENCV 640 480 500 500 320 240 0 0 0 0 0 0 0 0", None),
        (
            "SIMPLE_RADIAL 640 480 500 320 240 0.01",
            Some("SIMPLE_RADIAL model with non-zero distortion"),
        ),
        (
            "OPENCV 640 480 500 500 320 240 0 0 0.001 0",
            Some("OPENCV model with non-zero distortion"),
        ),
        (
            "OPENCV_FISHEYE 640 480 500 500 320 240 0 0 0 0",
            Some("OPENCV_FISHEYE model, a fisheye"),
        ),
        ("WEIRD 640 480 500", Some("unknown camera model \"WEIRD\"")),
        (
            "PINHOLE 640 480 500 500 320",
            Some("PINHOLE takes 4 parameters, the line has 3"),
        ),
        (
            "PINHOLE 640 480 nan 500 320 240",
            Some("non-finite or non-positive intrinsics"),
        ),
        (
            "PINHOLE 640 480 -500 500 320 240",
            Some("non-finite or non-positive intrinsics"),
        ),
        (
            "PINHOLE 0 480 500 500 320 240",
            Some("resolution 0x480 is not usable"),
        ),
        (
            "PINHOLE 99999999999 480 500 500 320 240",
            Some("not usable"),
        ),
    ];
    for (line, want) in cases {
        write(dir.path(), "cameras.txt", format!("1 {line}\n"));
        write(dir.path(), "images.txt", images);
        match want {
            None => assert_front_view(&{
                let mut c = load(dir.path()).0.remove(0);
                c.name = line.into();
                c
            }),
            Some(msg) => {
                let e = load_err(dir.path());
                assert!(e.contains(msg) && e.contains("camera 1"), "{line}: {e}");
                assert!(e.contains("cameras.txt"), "{e}");
            }
        }
    }
    // Binary: an unknown model id and a refused model, both naming the camera.
    for (model, params, msg) in [
        (99, vec![], "unknown camera model id 99"),
        (
            2,
            vec![500.0, 320.0, 240.0, 0.2],
            "SIMPLE_RADIAL model with non-zero",
        ),
    ] {
        let mut c = 1u64.to_le_bytes().to_vec();
        bin_camera(&mut c, 3, model, 640, 480, &params);
        let mut im = 1u64.to_le_bytes().to_vec();
        bin_image(&mut im, 1, [1.0, 0.0, 0.0, 0.0], [0.0; 3], 3, "a", 0);
        let d = tempfile::tempdir().unwrap();
        write(d.path(), "cameras.bin", c);
        write(d.path(), "images.bin", im);
        let e = load_err(d.path());
        assert!(e.contains(msg) && e.contains("camera 3"), "{e}");
    }
}

#[test]
fn colmap_malformed_text() {
    let cameras = "1 PINHOLE 640 480 500 500 320 240\n";
    let cases = [
        ("1 0 0 0 0 0 0 5 1 a.png\n\n", "zero length"),
        (
            "1 nan 0 0 0 0 0 5 1 a.png\n\n",
            "zero length or is not finite",
        ),
        ("1 1 0 0 0 0 nan 5 1 a.png\n\n", "translation"),
        ("1 1 0 0 0 0 0 5 2 a.png\n\n", "refers to camera 2"),
        ("1 1 0 0 0 0 0 5\n", "expected IMAGE_ID"),
        ("1 1 0 zero 0 0 0 5 1 a.png\n", "\"zero\" is not a number"),
        ("-1 1 0 0 0 0 0 5 1 a.png\n", "image id \"-1\""),
        ("# nothing\n", "no cameras"),
    ];
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "cameras.txt", cameras);
    for (images, msg) in cases {
        write(dir.path(), "images.txt", images);
        let e = load_err(dir.path());
        assert!(e.contains(msg), "{images:?}: {e}");
    }
    write(dir.path(), "images.txt", "1 1 0 0 0 0 0 5 1 a.png\n\n");
    write(
        dir.path(),
        "cameras.txt",
        "1 PINHOLE 640 480 500 500 320 240\n1 PINHOLE 640 480 500 500 320 240\n",
    );
    assert!(load_err(dir.path()).contains("appears twice"));
    write(dir.path(), "cameras.txt", [0xff, 0xfe, 0x00]);
    assert!(load_err(dir.path()).contains("not UTF-8"));
    // A directory without a model says what it looked for.
    let empty = tempfile::tempdir().unwrap();
    let e = load_err(empty.path());
    assert!(
        e.contains("not a COLMAP sparse model") && e.contains("sparse/0"),
        "{e}"
    );
}

#[test]
fn colmap_truncated_and_lying_binaries_never_panic() {
    let cams = assorted_cameras(3);
    let (c, im) = colmap_bin(&cams);
    let path = Path::new("model");
    // The whole files parse; every strict prefix, and every extension, is an error.
    assert_eq!(
        camera::colmap::parse_colmap_binary(&c, path, &im, path)
            .unwrap()
            .len(),
        3
    );
    for cut in 0..c.len() {
        let r = camera::colmap::parse_colmap_binary(&c[..cut], path, &im, path);
        assert!(
            matches!(r, Err(CameraError::Invalid { .. })),
            "cameras.bin cut at {cut}"
        );
    }
    for cut in 0..im.len() {
        let r = camera::colmap::parse_colmap_binary(&c, path, &im[..cut], path);
        assert!(
            matches!(r, Err(CameraError::Invalid { .. })),
            "images.bin cut at {cut}"
        );
    }
    let mut longer = im.clone();
    longer.push(0);
    let e = camera::colmap::parse_colmap_binary(&c, path, &longer, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("unexpected bytes"), "{e}");

    // Counts that lie: huge image/camera counts and a huge 2D point count.
    let mut lie = im.clone();
    lie[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = camera::colmap::parse_colmap_binary(&c, path, &lie, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("claims 18446744073709551615 images"), "{e}");
    let mut lie = c.clone();
    lie[..8].copy_from_slice(&1_000_000u64.to_le_bytes());
    let e = camera::colmap::parse_colmap_binary(&lie, path, &im, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("claims 1000000 cameras"), "{e}");
    for points in [u64::MAX, u64::MAX / 24 + 1, 1 << 40] {
        let mut im = 1u64.to_le_bytes().to_vec();
        bin_image(&mut im, 1, [1.0, 0.0, 0.0, 0.0], [0.0; 3], 1, "a", 0);
        let n = im.len();
        im[n - 8..].copy_from_slice(&points.to_le_bytes());
        let e = camera::colmap::parse_colmap_binary(&c, path, &im, path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("2D points"), "{e}");
    }
    // No NUL after the name.
    let mut im = 1u64.to_le_bytes().to_vec();
    im.extend(1u32.to_le_bytes());
    im.extend([0u8; 56]);
    im.extend(1u32.to_le_bytes());
    im.extend(b"no terminator at all, just letters");
    let e = camera::colmap::parse_colmap_binary(&c, path, &im, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("NUL") || e.contains("claims"), "{e}");

    // Non-finite and zero-length values in an otherwise well-formed file.
    let one_cam = |params: [f64; 4]| {
        let mut c = 1u64.to_le_bytes().to_vec();
        bin_camera(&mut c, 1, 1, 64, 48, &params);
        c
    };
    let one_image = |q: [f64; 4], t: [f64; 3]| {
        let mut im = 1u64.to_le_bytes().to_vec();
        bin_image(&mut im, 1, q, t, 1, "a", 1);
        im
    };
    let good_cam = one_cam([50.0, 50.0, 32.0, 24.0]);
    let good_q = [1.0, 0.0, 0.0, 0.0];
    for (c, im, msg) in [
        (
            one_cam([f64::NAN, 50.0, 32.0, 24.0]),
            one_image(good_q, [0.0; 3]),
            "non-finite",
        ),
        (
            one_cam([50.0, 50.0, f64::INFINITY, 24.0]),
            one_image(good_q, [0.0; 3]),
            "non-finite",
        ),
        (
            good_cam.clone(),
            one_image([0.0; 4], [0.0; 3]),
            "zero length",
        ),
        (
            good_cam.clone(),
            one_image([f64::NAN, 0.0, 0.0, 0.0], [0.0; 3]),
            "not finite",
        ),
        (
            good_cam.clone(),
            one_image(good_q, [0.0, f64::NAN, 0.0]),
            "translation",
        ),
        (
            good_cam.clone(),
            one_image([1e300, 1e300, 0.0, 0.0], [0.0; 3]),
            "not finite",
        ),
    ] {
        let e = camera::colmap::parse_colmap_binary(&c, path, &im, path)
            .unwrap_err()
            .to_string();
        assert!(e.contains(msg), "{msg}: {e}");
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
                r#", "camera_type": "fisheye""#,
                &format!(r#"{{"camera_to_world": {m}, "fov": 50}}"#),
            ),
            "camera_type \"fisheye\" is not supported",
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

    let scene = vksplat::demo_scene();
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

// ---------------------------------------------------------------- keyframes

#[test]
fn keyframes_front_views() {
    let dir = tempfile::tempdir().unwrap();
    let text = r#"{"version": 1, "width": 640, "height": 480, "keyframes": [
        {"time": 0, "position": [0, 0, -5], "look_at": [0, 0, 0], "vfov": 51.28201164861056}]}"#;
    let (cams, format) = load(&write(dir.path(), "k.json", text));
    assert_eq!((format, cams.len()), (CameraFormat::Keyframes, 1));
    assert_eq!(cams[0].name, "frame_00000");
    assert_same_camera(&cams[0], &front_camera(), 1e-6);
    assert_front_view(&cams[0]);

    // The rotation form (camera-to-world quaternion): start and end views exact.
    let (cams, _) = load_camera_file(
        &fixtures().join("keyframes_rotation.json"),
        &PathTiming {
            frames: Some(9),
            fps: None,
        },
    )
    .unwrap();
    assert_eq!(cams.len(), 9);
    assert_same_camera(&cams[0], &front_camera(), 1e-6);
    assert_front_view(&cams[0]);
    let side = Camera::look_at(
        "side",
        640,
        480,
        1.0,
        Vec3::new(-5.0, 0.0, 0.0),
        Vec3::ZERO,
        Vec3::NEG_Y,
    );
    assert_mat_close(cams[8].rotation, side.rotation, 1e-6, "last");
    assert_vec_close(cams[8].translation, side.translation, 1e-5, "last");
}

#[test]
fn keyframe_timing() {
    let path = fixtures().join("keyframes_example.json");
    let frames = |t: PathTiming| load_camera_file(&path, &t).unwrap().0;
    let file = frames(PathTiming::default());
    assert_eq!(file.len(), 120, "the file's own frame count");
    let by_fps = frames(PathTiming {
        frames: None,
        fps: Some(10.0),
    });
    assert_eq!(by_fps.len(), 41, "4 s at 10 fps, both ends included");
    let by_count = frames(PathTiming {
        frames: Some(7),
        fps: Some(10.0),
    });
    assert_eq!(by_count.len(), 7, "frames wins over fps");
    let text = std::fs::read_to_string(&path).unwrap();
    let kp = KeyframePath::parse(&text, &path).unwrap();
    // First and last frames sit exactly on the first and last keyframes.
    for cams in [&file, &by_count] {
        let first = kp.sample(0.0, "k0".into());
        let last = kp.sample(4.0, "k2".into());
        assert_eq!(
            (cams[0].rotation, cams[0].translation),
            (first.rotation, first.translation)
        );
        let n = cams.len() - 1;
        assert_eq!(
            (cams[n].rotation, cams[n].translation),
            (last.rotation, last.translation)
        );
    }
    // With look_at keyframes every frame looks at the interpolated target, so a target
    // shared by all keyframes stays on the principal point between them too.
    let shared = text.replace("[0.0, -0.8, 0.0]", "[0.0, -0.5, 0.0]");
    let cams = KeyframePath::parse(&shared, &path)
        .unwrap()
        .cameras(&PathTiming::default())
        .unwrap();
    for c in &cams {
        let (p, _) = project(c, Vec3::new(0.0, -0.5, 0.0));
        assert!(
            (p - Vec2::new(640.0, 360.0)).length() < 1e-3,
            "{}: {p}",
            c.name
        );
    }
    // The field of view goes linearly from 50 to 35 degrees over the last segment.
    let vfov = |c: &Camera| (2.0 * (c.height as f32 / (2.0 * c.fy)).atan()).to_degrees();
    assert!((vfov(&by_fps[15]) - 50.0).abs() < 1e-3);
    assert!((vfov(&by_fps[40]) - 35.0).abs() < 1e-3);
    assert!((vfov(&by_fps[30]) - (50.0 - 15.0 * 1.5 / 2.5)).abs() < 1e-3);
}

#[test]
fn keyframe_round_trip_is_exact_at_keyframes() {
    let mut cams = assorted_cameras(7);
    cams.extend(
        orbit(
            &[],
            &OrbitParams {
                frames: 5,
                centre: Some(Vec3::ZERO),
                radius: Some(3.0),
                width: 320,
                height: 240,
                ..Default::default()
            },
        )
        .unwrap(),
    );
    let times: Vec<f64> = (0..cams.len())
        .map(|i| i as f64 * 0.75 + (i * i) as f64 * 0.1)
        .collect();
    let json = keyframes_to_json(&cams, &times, 24.0).unwrap();
    let path = Path::new("round_trip.json");
    let kp = KeyframePath::parse(&json, path).unwrap();
    for (c, &t) in cams.iter().zip(&times) {
        let back = kp.sample(t, c.name.clone());
        assert_mat_close(back.rotation, c.rotation, 1e-6, &c.name);
        assert_vec_close(back.translation, c.translation, 2e-6, &c.name);
        assert!(
            (back.fy - c.fy).abs() < 1e-6 * c.fy,
            "{}: fy {} vs {}",
            c.name,
            back.fy,
            c.fy
        );
        assert_eq!((back.cx, back.cy), (c.cx, c.cy));
    }
    // Loaded as a file, the path spans the keyframes at 24 fps.
    let dir = tempfile::tempdir().unwrap();
    let (frames, format) = load(&write(dir.path(), "k.json", &json));
    assert_eq!(format, CameraFormat::Keyframes);
    let span = times[times.len() - 1] - times[0];
    assert_eq!(frames.len(), (span * 24.0 + 1e-9).floor() as usize + 1);
    assert_same_camera(&frames[0], &cams[0], 1e-6);

    // The writer refuses what a keyframe path cannot hold.
    assert!(keyframes_to_json(&[], &[], 24.0).is_err());
    assert!(keyframes_to_json(&cams[..2], &[0.0], 24.0).is_err());
    assert!(keyframes_to_json(&cams[..2], &[1.0, 1.0], 24.0).is_err());
    assert!(keyframes_to_json(&cams[..1], &[f64::NAN], 24.0).is_err());
    assert!(keyframes_to_json(&cams[..1], &[0.0], 0.0).is_err());
    let mut other = cams[1].clone();
    other.width = 100;
    let e = keyframes_to_json(&[cams[0].clone(), other], &[0.0, 1.0], 24.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("one resolution"), "{e}");
}

#[test]
fn keyframe_interpolation_is_smooth() {
    // Keyframes on a wobbly ring with uneven spacing in time, mixing look_at and rotation.
    let ring = orbit(
        &[],
        &OrbitParams {
            frames: 8,
            centre: Some(Vec3::ZERO),
            radius: Some(4.0),
            width: 320,
            height: 240,
            ..Default::default()
        },
    )
    .unwrap();
    let times = [0.0, 0.5, 1.5, 2.0, 3.5, 4.0, 4.2, 6.0];
    let mut json: serde_json::Value =
        serde_json::from_str(&keyframes_to_json(&ring, &times, 60.0).unwrap()).unwrap();
    for (i, k) in json["keyframes"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .enumerate()
        .filter(|(i, _)| i % 3 == 1)
    {
        let obj = k.as_object_mut().unwrap();
        obj.remove("rotation");
        obj.insert(
            "look_at".into(),
            serde_json::json!([0.0, 0.2 * i as f64, 0.0]),
        );
    }
    let kp = KeyframePath::parse(&json.to_string(), Path::new("ring.json")).unwrap();
    let cams = kp.cameras(&PathTiming::default()).unwrap();
    assert_eq!(cams.len(), 361);
    // The fastest the ring moves between keys is one chord (3.06 units) in 0.2 s; the
    // spline may overshoot that speed a little but never jumps.
    let max_speed = 3.1 / 0.2;
    let mut prev: Option<&Camera> = None;
    for c in &cams {
        let r = c.rotation;
        assert!(
            (r * r.transpose()).abs_diff_eq(Mat3::IDENTITY, 1e-5),
            "{}: not orthonormal",
            c.name
        );
        assert!(
            (r.determinant() - 1.0).abs() < 1e-5,
            "{}: det {}",
            c.name,
            r.determinant()
        );
        if let Some(p) = prev {
            let step = (c.position() - p.position()).length();
            assert!(
                step < 2.0 * max_speed / 60.0,
                "{}: position jumps by {step}",
                c.name
            );
            let relative = (p.rotation * c.rotation.transpose()).to_cols_array();
            let turn = relative[0] + relative[4] + relative[8];
            let angle = ((turn - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees();
            assert!(
                angle < 10.0,
                "{}: turns by {angle} degrees in one frame",
                c.name
            );
        }
        prev = Some(c);
    }
}

#[test]
fn keyframes_malformed() {
    let k = |time: &str, rest: &str| {
        format!(r#"{{"time": {time}, "position": [0, 0, -5], {rest}, "vfov": 50}}"#)
    };
    let file = |keys: &[String]| {
        format!(
            r#"{{"version": 1, "width": 64, "height": 48, "keyframes": [{}]}}"#,
            keys.join(",")
        )
    };
    let look = r#""look_at": [0, 0, 0]"#;
    let cases = [
        (file(&[k("0", look), k("0", look)]), "strictly increasing"),
        (file(&[k("1", look), k("0.5", look)]), "strictly increasing"),
        (
            file(&[k("0", r#""rotation": [0, 0, 0, 0]"#)]),
            "zero length",
        ),
        (
            file(&[k("0", r#""rotation": [1, 0, 0]"#)]),
            "not a keyframe path",
        ),
        (
            file(&[k("0", r#""look_at": [0, 0, -5]"#)]),
            "look_at is the camera position",
        ),
        (
            file(&[k("0", r#""look_at": [0, -3, -5]"#)]),
            "straight along up",
        ),
        (
            file(&[k("0", r#""look_at": [0, 0, 0], "rotation": [1, 0, 0, 0]"#)]),
            "not both",
        ),
        (
            file(&[k("0", r#""up": [0, -1, 0]"#)]),
            "needs look_at or rotation",
        ),
        (
            file(&[k("0", r#""rotation": [1, 0, 0, 0], "up": [0, -1, 0]"#)]),
            "up only goes with look_at",
        ),
        (
            file(&[k("0", r#""look_at": [0, 0, 0], "up": [0, 0, 0]"#)]),
            "up non-zero",
        ),
        (
            file(&[k("0", r#""lookat": [0, 0, 0]"#)]),
            "unknown field `lookat`",
        ),
        (file(&[k("NaN", look)]), "not valid JSON"),
        (file(&[]), "has no keyframes"),
        (
            file(&[k("0", look)]).replace("\"version\": 1", "\"version\": 2"),
            "version 2 is not supported",
        ),
        (
            file(&[k("0", look)]).replace("\"width\": 64", "\"width\": 0"),
            "not usable",
        ),
        (
            file(&[k("0", look)]).replace("\"version\": 1,", "\"version\": 1, \"fps\": -3,"),
            "fps -3",
        ),
        (
            file(&[k("0", look)]).replace("\"version\": 1,", "\"version\": 1, \"frames\": 0,"),
            "frames 0",
        ),
        (
            file(&[k("0", look)]).replace("\"vfov\": 50", "\"vfov\": 180"),
            "vfov 180",
        ),
        (file(&[k("0", look), k("1e9", look)]), "more than"),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (text, msg) in cases {
        let e = load_err(&write(dir.path(), "k.json", &text));
        assert!(e.contains(msg), "{text}\n  -> {e}");
    }
    // Timing overrides are checked too.
    let p = write(dir.path(), "k.json", file(&[k("0", look), k("1", look)]));
    for t in [
        PathTiming {
            frames: Some(0),
            fps: None,
        },
        PathTiming {
            frames: None,
            fps: Some(f32::NAN),
        },
    ] {
        assert!(
            matches!(load_camera_file(&p, &t), Err(CameraError::BadParameter(_))),
            "{t:?}"
        );
    }
}

// ---------------------------------------------------------------- detection, selection

#[test]
fn format_detection_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8], &str); 6] = [
        (
            "a.json",
            b"{\"foo\": 1}",
            "neither \"camera_path\" (nerfstudio) nor \"keyframes\"",
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
        camera::detect_camera_format(&fixtures().join("keyframes_example.json")).unwrap(),
        CameraFormat::Keyframes
    );
    assert_eq!(
        camera::detect_camera_format(&fixtures().join("colmap_text")).unwrap(),
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
