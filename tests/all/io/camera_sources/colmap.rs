//! COLMAP models: the text fixture, text and binary round trips of poses, the camera
//! models accepted, and malformed, truncated or lying files.

use super::{
    assert_front_view, assert_mat_close, assert_same_camera, assert_vec_close, assorted_cameras,
    fixtures, front_camera, load, load_err, project, write,
};
use glam::{DQuat, Vec2, Vec3};
use std::path::Path;
use verisplat::core::camera::{self, Camera, CameraError, Lens};
use verisplat::core::file_error::FileError;
use verisplat::io;
use verisplat::io::camera::CameraFormat;

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

/// `Lens::RadialTangential` with radial `k` (k1..k6) and tangential `p`.
fn brown(k: [f64; 6], p: [f64; 2]) -> Lens {
    Lens::RadialTangential {
        radial: k,
        tangential: p,
    }
}

/// The equidistant fisheye `k1..k4`, imaging as far as its polynomial grows.
fn fisheye(k: [f64; 4]) -> Lens {
    Lens::Fisheye {
        k,
        max_theta: camera::lens::fisheye_max_theta(&k),
    }
}

#[test]
fn colmap_models_carry_their_lens_and_unmappable_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let images = "1 1 0 0 0 0 0 5 1 a.png\n\n";
    let z = 0.0;
    let cases: Vec<(&str, Result<Lens, &str>)> = vec![
        ("SIMPLE_PINHOLE 640 480 500 320 240", Ok(Lens::Pinhole)),
        ("SIMPLE_RADIAL 640 480 500 320 240 0", Ok(Lens::Pinhole)),
        ("RADIAL 640 480 500 320 240 0 0", Ok(Lens::Pinhole)),
        ("OPENCV 640 480 500 500 320 240 0 0 0 0", Ok(Lens::Pinhole)),
        (
            "FULL_OPENCV 640 480 500 500 320 240 0 0 0 0 0 0 0 0",
            Ok(Lens::Pinhole),
        ),
        ("FOV 640 480 500 500 320 240 0", Ok(Lens::Pinhole)),
        (
            "SIMPLE_RADIAL 640 480 500 320 240 0.01",
            Ok(brown([0.01, z, z, z, z, z], [z, z])),
        ),
        (
            "RADIAL 640 480 500 320 240 0.01 -0.002",
            Ok(brown([0.01, -0.002, z, z, z, z], [z, z])),
        ),
        (
            "OPENCV 640 480 500 500 320 240 -0.2 0.05 0.001 -0.0005",
            Ok(brown([-0.2, 0.05, z, z, z, z], [0.001, -0.0005])),
        ),
        (
            "FULL_OPENCV 640 480 500 500 320 240 0.1 -0.03 0.001 0.002 0.01 0.05 0.003 0.0004",
            Ok(brown(
                [0.1, -0.03, 0.01, 0.05, 0.003, 0.0004],
                [0.001, 0.002],
            )),
        ),
        (
            "OPENCV_FISHEYE 640 480 500 500 320 240 0 0 0 0",
            Ok(fisheye([z; 4])),
        ),
        (
            "OPENCV_FISHEYE 640 480 500 500 320 240 0.05 -0.01 0.002 -0.0003",
            Ok(fisheye([0.05, -0.01, 0.002, -0.0003])),
        ),
        (
            "SIMPLE_RADIAL_FISHEYE 640 480 500 320 240 -0.2",
            Ok(fisheye([-0.2, z, z, z])),
        ),
        (
            "RADIAL_FISHEYE 640 480 500 320 240 0.02 0.001",
            Ok(fisheye([0.02, 0.001, z, z])),
        ),
        (
            "FOV 640 480 500 500 320 240 0.9",
            Err("the FOV model is not supported"),
        ),
        (
            "THIN_PRISM_FISHEYE 640 480 500 500 320 240 0 0 0 0 0 0 0 0",
            Err("the THIN_PRISM_FISHEYE model is not supported"),
        ),
        (
            "RAD_TAN_THIN_PRISM_FISHEYE 640 480 500 500 320 240 0 0 0 0 0 0 0 0 0 0 0 0",
            Err("the RAD_TAN_THIN_PRISM_FISHEYE model is not supported"),
        ),
        (
            "OPENCV 640 480 500 500 320 240 nan 0 0 0",
            Err("non-finite distortion parameter"),
        ),
        ("WEIRD 640 480 500", Err("unknown camera model \"WEIRD\"")),
        (
            "PINHOLE 640 480 500 500 320",
            Err("PINHOLE takes 4 parameters, the line has 3"),
        ),
        (
            "PINHOLE 640 480 nan 500 320 240",
            Err("non-finite or non-positive intrinsics"),
        ),
        (
            "PINHOLE 640 480 -500 500 320 240",
            Err("non-finite or non-positive intrinsics"),
        ),
        (
            "PINHOLE 0 480 500 500 320 240",
            Err("resolution 0x480 is not usable"),
        ),
        ("PINHOLE 99999999999 480 500 500 320 240", Err("not usable")),
    ];
    for (line, want) in cases {
        write(dir.path(), "cameras.txt", format!("1 {line}\n"));
        write(dir.path(), "images.txt", images);
        match want {
            Ok(lens) => {
                let mut c = load(dir.path()).0.remove(0);
                assert_eq!(c.lens, lens, "{line}");
                // The pose and the pinhole part as the model writes them.
                assert_eq!((c.fx, c.fy, c.cx, c.cy), (500.0, 500.0, 320.0, 240.0));
                c.lens = Lens::Pinhole;
                c.name = line.into();
                assert_front_view(&c);
                // The trainer's reading: the pinhole part, the distortion beside it.
                let (cams, _) =
                    io::camera::colmap::load_colmap_model_distorted(dir.path()).unwrap();
                assert_eq!(cams[0].0.lens, Lens::Pinhole, "{line}");
                assert_eq!(cams[0].1.is_some(), lens != Lens::Pinhole, "{line}");
            }
            Err(msg) => {
                let e = load_err(dir.path());
                assert!(e.contains(msg) && e.contains("camera 1"), "{line}: {e}");
                assert!(e.contains("cameras.txt"), "{e}");
            }
        }
    }
    // Binary: an unknown model id and a refused model, both naming the camera; a
    // distorted model read with its lens.
    for (model, params, want) in [
        (99, vec![], Err("unknown camera model id 99")),
        (
            10,
            vec![
                500.0, 500.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            ],
            Err("the THIN_PRISM_FISHEYE model is not supported"),
        ),
        (
            2,
            vec![500.0, 320.0, 240.0, 0.2],
            Ok(brown([0.2, z, z, z, z, z], [z, z])),
        ),
        (
            5,
            vec![500.0, 500.0, 320.0, 240.0, 0.1, 0.0, 0.0, 0.0],
            Ok(fisheye([0.1, z, z, z])),
        ),
    ] {
        let mut c = 1u64.to_le_bytes().to_vec();
        bin_camera(&mut c, 3, model, 640, 480, &params);
        let mut im = 1u64.to_le_bytes().to_vec();
        bin_image(&mut im, 1, [1.0, 0.0, 0.0, 0.0], [0.0; 3], 3, "a", 0);
        let d = tempfile::tempdir().unwrap();
        write(d.path(), "cameras.bin", c);
        write(d.path(), "images.bin", im);
        match want {
            Ok(lens) => assert_eq!(load(d.path()).0[0].lens, lens),
            Err(msg) => {
                let e = load_err(d.path());
                assert!(e.contains(msg) && e.contains("camera 3"), "{e}");
            }
        }
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
        io::camera::colmap::parse_colmap_binary(&c, path, &im, path)
            .unwrap()
            .len(),
        3
    );
    for cut in 0..c.len() {
        let r = io::camera::colmap::parse_colmap_binary(&c[..cut], path, &im, path);
        assert!(
            matches!(r, Err(CameraError::File(FileError::Invalid { .. }))),
            "cameras.bin cut at {cut}"
        );
    }
    for cut in 0..im.len() {
        let r = io::camera::colmap::parse_colmap_binary(&c, path, &im[..cut], path);
        assert!(
            matches!(r, Err(CameraError::File(FileError::Invalid { .. }))),
            "images.bin cut at {cut}"
        );
    }
    let mut longer = im.clone();
    longer.push(0);
    let e = io::camera::colmap::parse_colmap_binary(&c, path, &longer, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("unexpected bytes"), "{e}");

    // Counts that lie: huge image/camera counts and a huge 2D point count.
    let mut lie = im.clone();
    lie[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = io::camera::colmap::parse_colmap_binary(&c, path, &lie, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("claims 18446744073709551615 images"), "{e}");
    let mut lie = c.clone();
    lie[..8].copy_from_slice(&1_000_000u64.to_le_bytes());
    let e = io::camera::colmap::parse_colmap_binary(&lie, path, &im, path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("claims 1000000 cameras"), "{e}");
    for points in [u64::MAX, u64::MAX / 24 + 1, 1 << 40] {
        let mut im = 1u64.to_le_bytes().to_vec();
        bin_image(&mut im, 1, [1.0, 0.0, 0.0, 0.0], [0.0; 3], 1, "a", 0);
        let n = im.len();
        im[n - 8..].copy_from_slice(&points.to_le_bytes());
        let e = io::camera::colmap::parse_colmap_binary(&c, path, &im, path)
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
    let e = io::camera::colmap::parse_colmap_binary(&c, path, &im, path)
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
        let e = io::camera::colmap::parse_colmap_binary(&c, path, &im, path)
            .unwrap_err()
            .to_string();
        assert!(e.contains(msg), "{msg}: {e}");
    }
}
