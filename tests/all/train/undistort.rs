//! Distorted photos (issue 37): a scene rendered through a pinhole camera and distorted
//! synthetically with known coefficients (each photo pixel's ray found by undistorting
//! its position, the pinhole render sampled there, 3x3 samples a pixel) is written as a
//! COLMAP or transforms.json data set. By default (issue 49) it loads as taken, each camera
//! carrying its lens, at `-r` with the intrinsics scaled and the coefficients kept; with
//! `--undistort` ([`LensMode::Undistort`]) loading it must give back the pinhole view over
//! the cropped region, with the photo's focal lengths. Models that cannot be handled are
//! refused by name; zero coefficients load exactly as a pinhole camera; `eval` of a model
//! trained at `-r 2 --undistort` on distorted photos compares with the photos the trainer
//! used. And training through a lens, the default: a fisheye data set trained on as taken.

use crate::common::{self, cli::verisplat};
use std::path::Path;
use verisplat::core::camera::distortion::Distortion;
use verisplat::core::camera::{Camera, Lens};
use verisplat::train::data::{self, LensMode, Resolution};

/// The shared scene (PLAYBOT LOD6, CC BY 4.0), activated.
fn scene() -> verisplat::core::model::ActivatedScene {
    verisplat::io::scene::load_with_format(&common::shared_data().join("playbot_lod6_1873_sh2.ply"))
        .expect("the shared scene")
        .0
        .activated()
}

/// `cam` rendered by the CPU reference at 3x and area-averaged down (what a photo of
/// it is, up to 8-bit quantisation).
fn render(scene: &verisplat::core::model::ActivatedScene, cam: &Camera) -> Vec<[f32; 3]> {
    let big = cam.with_resolution(cam.width * 3, cam.height * 3).unwrap();
    let f = verisplat::cpu::render(scene, &big, &Default::default());
    let c: Vec<[f32; 3]> = f
        .color
        .iter()
        .map(|p| p.map(|v| v.clamp(0.0, 1.0)))
        .collect();
    data::resize(&c, big.width, big.height, cam.width, cam.height)
}

/// The photo that camera `cam` with lens `d` takes of the scene: each pixel the mean of
/// 3x3 rays, each ray's colour bilinearly sampled from a pinhole render 3x as dense with
/// a 1.8x wider field.
fn distorted_photo(
    scene: &verisplat::core::model::ActivatedScene,
    cam: &Camera,
    d: &Distortion,
) -> Vec<[f32; 3]> {
    let (s, m) = (3.0f64, 1.8f64);
    let (bw, bh) = (
        (cam.width as f64 * s * m) as u32,
        (cam.height as f64 * s * m) as u32,
    );
    let wide = Camera {
        width: bw,
        height: bh,
        fx: (cam.fx as f64 * s) as f32,
        fy: (cam.fy as f64 * s) as f32,
        cx: (cam.cx as f64 * s + (m - 1.0) * s * cam.width as f64 / 2.0) as f32,
        cy: (cam.cy as f64 * s + (m - 1.0) * s * cam.height as f64 / 2.0) as f32,
        ..cam.clone()
    };
    let frame = verisplat::cpu::render(scene, &wide, &Default::default());
    let at = |u: f64, v: f64| -> [f32; 3] {
        let u = u.clamp(0.0, bw as f64 - 1.0);
        let v = v.clamp(0.0, bh as f64 - 1.0);
        let (i0, j0) = (u.floor() as usize, v.floor() as usize);
        let (i1, j1) = ((i0 + 1).min(bw as usize - 1), (j0 + 1).min(bh as usize - 1));
        let (a, b) = ((u - i0 as f64) as f32, (v - j0 as f64) as f32);
        let p = |i: usize, j: usize| frame.color[j * bw as usize + i].map(|c| c.clamp(0.0, 1.0));
        let mut out = [0f32; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let top = p(i0, j0)[c] * (1.0 - a) + p(i1, j0)[c] * a;
            let bottom = p(i0, j1)[c] * (1.0 - a) + p(i1, j1)[c] * a;
            *o = top * (1.0 - b) + bottom * b;
        }
        out
    };
    let mut img = Vec::with_capacity((cam.width * cam.height) as usize);
    for j in 0..cam.height {
        for i in 0..cam.width {
            let mut acc = [0f32; 3];
            for sj in 0..3 {
                for si in 0..3 {
                    let u = i as f64 + (si as f64 + 0.5) / 3.0;
                    let v = j as f64 + (sj as f64 + 0.5) / 3.0;
                    let xd = (u - cam.cx as f64) / cam.fx as f64;
                    let yd = (v - cam.cy as f64) / cam.fy as f64;
                    let (x, y) = d.undistort(xd, yd).expect("the photo's rays undistort");
                    let c = at(
                        x * wide.fx as f64 + wide.cx as f64 - 0.5,
                        y * wide.fy as f64 + wide.cy as f64 - 0.5,
                    );
                    for k in 0..3 {
                        acc[k] += c[k] / 9.0;
                    }
                }
            }
            img.push(acc);
        }
    }
    img
}

/// Writes `photo` (of `cam`'s size) as an 8-bit PNG.
fn write_png(path: &Path, cam: &Camera, photo: &[[f32; 3]]) {
    let n = photo.len();
    let frame = verisplat::core::frame::Frame {
        width: cam.width,
        height: cam.height,
        color: photo.to_vec(),
        alpha: vec![1.0; n],
        depth: vec![1.0; n],
        feature_count: 0,
        features: Vec::new(),
    };
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    verisplat::io::output::write_frame(
        &frame,
        path,
        verisplat::io::output::ImageFormat::Png8,
        true,
    )
    .unwrap();
}

/// A COLMAP text data set in `dir` of `cams` (one shared camera of `model` with
/// `params` after the focal length and principal point) and their `photos`.
fn write_colmap(dir: &Path, cams: &[Camera], photos: &[Vec<[f32; 3]>], model: &str, params: &str) {
    for (c, p) in cams.iter().zip(photos) {
        write_png(&dir.join("images").join(&c.name), c, p);
    }
    let c = &cams[0];
    let focal = if model.starts_with("SIMPLE") || model.starts_with("RADIAL") {
        format!("{}", c.fx)
    } else {
        format!("{} {}", c.fx, c.fy)
    };
    let sparse = dir.join("sparse/0");
    std::fs::create_dir_all(&sparse).unwrap();
    std::fs::write(
        sparse.join("cameras.txt"),
        format!(
            "1 {model} {} {} {focal} {} {} {params}\n",
            c.width, c.height, c.cx, c.cy
        ),
    )
    .unwrap();
    // Every image on camera 1.
    let [_, (_, images), _] = verisplat::io::camera::colmap::to_text_model(cams, &[]).unwrap();
    let images: String = images
        .lines()
        .map(|l| {
            let mut f: Vec<&str> = l.split(' ').collect();
            if f.len() >= 10 && !l.starts_with('#') {
                f[8] = "1";
            }
            f.join(" ") + "\n"
        })
        .collect();
    std::fs::write(sparse.join("images.txt"), images).unwrap();
}

/// A nerfstudio `transforms.json` data set in `dir` of `cams` and their `photos`, with
/// the file-level keys `lens` (a JSON object's members, e.g. `"k1": 0.1`).
fn write_transforms(dir: &Path, cams: &[Camera], photos: &[Vec<[f32; 3]>], lens: &str) {
    let mut frames = Vec::new();
    for (c, p) in cams.iter().zip(photos) {
        write_png(&dir.join("images").join(&c.name), c, p);
        // Camera-to-world in OpenGL axes: our x, -y, -z columns and the centre.
        let r = c.rotation.transpose();
        let o = c.position();
        let cols = [r.x_axis, -r.y_axis, -r.z_axis];
        let row = |k: usize| format!("[{}, {}, {}, {}]", cols[0][k], cols[1][k], cols[2][k], o[k]);
        frames.push(format!(
            "{{\"file_path\": \"images/{}\", \"transform_matrix\": [{}, {}, {}, [0, 0, 0, 1]]}}",
            c.name,
            row(0),
            row(1),
            row(2)
        ));
    }
    let c = &cams[0];
    let sep = if lens.is_empty() { "" } else { ", " };
    std::fs::write(
        dir.join("transforms.json"),
        format!(
            "{{\"fl_x\": {}, \"fl_y\": {}, \"cx\": {}, \"cy\": {}, \"w\": {}, \"h\": {}{sep}{lens}, \"frames\": [{}]}}",
            c.fx,
            c.fy,
            c.cx,
            c.cy,
            c.width,
            c.height,
            frames.join(", ")
        ),
    )
    .unwrap();
}

/// `n` orbit cameras of `w x h` around the scene, named `view_NNN.png`, with the
/// principal point a little off centre.
fn cameras(n: usize, w: u32, h: u32) -> Vec<Camera> {
    let positions = verisplat::io::scene::load_with_format(
        &common::shared_data().join("playbot_lod6_1873_sh2.ply"),
    )
    .unwrap()
    .0
    .positions;
    let params = verisplat::core::camera::OrbitParams {
        frames: n,
        width: w,
        height: h,
        elevation_deg: 15.0,
        ..Default::default()
    };
    verisplat::core::camera::orbit(&positions, &params)
        .unwrap()
        .into_iter()
        .enumerate()
        .map(|(i, mut c)| {
            c.name = format!("view_{i:03}.png");
            c.cx += 1.5;
            c.cy -= 1.0;
            c
        })
        .collect()
}

fn psnr(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    verisplat::io::metrics::psnr(&flat(a), &flat(b), 1.0)
}

/// The loaded view of a distorted data set matches a pinhole render of its camera, far
/// better than the photo taken for a pinhole (what loading without the lens gave); the
/// camera keeps the photo's focal lengths and pose. Returns the loaded camera.
fn check_loaded(set: &data::Dataset, cam: &Camera, photo: &[[f32; 3]], what: &str) -> Camera {
    let scene = scene();
    assert_eq!(set.undistorted.len(), 1, "{what}");
    let v = &set.train[0];
    let c = &v.camera;
    assert_eq!((c.fx, c.fy), (cam.fx, cam.fy), "{what}: focal lengths kept");
    assert!(
        c.rotation.abs_diff_eq(cam.rotation, 1e-6),
        "{what}: the pose is kept"
    );
    assert!(
        c.translation.abs_diff_eq(cam.translation, 1e-5),
        "{what}: the pose is kept"
    );
    let truth = render(&scene, c);
    let got = psnr(&v.image, &truth);
    let ignored = psnr(photo, &render(&scene, cam));
    eprintln!(
        "{what}: {}x{} -> {}x{} (cx {} cy {}), PSNR {got:.2} dB undistorted, {ignored:.2} dB with the lens ignored",
        cam.width, cam.height, c.width, c.height, c.cx, c.cy
    );
    assert!(got >= 34.0, "{what}: PSNR {got:.2} dB");
    assert!(got >= ignored + 2.0, "{what}: {got:.2} vs {ignored:.2} dB");
    c.clone()
}

#[test]
fn distorted_colmap_and_transforms_photos_load_as_their_pinhole_views() {
    let scene = scene();
    let cam = cameras(1, 160, 120).remove(0);
    let cases = [
        (
            "OPENCV",
            "-0.25 0.06 0.002 -0.001",
            Distortion::opencv("OPENCV", [-0.25, 0.06, 0.0, 0.0, 0.0, 0.0], [0.002, -0.001]),
            "\"k1\": -0.25, \"k2\": 0.06, \"p1\": 0.002, \"p2\": -0.001",
        ),
        (
            "RADIAL",
            "0.15 -0.01",
            Distortion::opencv("RADIAL", [0.15, -0.01, 0.0, 0.0, 0.0, 0.0], [0.0; 2]),
            "\"k1\": 0.15, \"k2\": -0.01",
        ),
        (
            "OPENCV_FISHEYE",
            "0.03 -0.01 0.002 0",
            Distortion::fisheye("OPENCV_FISHEYE", [0.03, -0.01, 0.002, 0.0]),
            "\"camera_model\": \"OPENCV_FISHEYE\", \"k1\": 0.03, \"k2\": -0.01, \"k3\": 0.002",
        ),
    ];
    for (model, params, lens, keys) in cases {
        let mut c = cam.clone();
        if model == "RADIAL" {
            c.fy = c.fx;
        }
        let photo = distorted_photo(&scene, &c, &lens);
        let dir = tempfile::tempdir().unwrap();
        let colmap = dir.path().join("colmap");
        write_colmap(
            &colmap,
            std::slice::from_ref(&c),
            std::slice::from_ref(&photo),
            model,
            params,
        );
        let set =
            data::load_colmap_with(&colmap, Resolution(1), false, LensMode::Undistort).unwrap();
        let a = check_loaded(&set, &c, &photo, &format!("COLMAP {model}"));
        assert_eq!(set.undistorted[0].distortion, lens);
        // The pinhole size: the inner rectangle of the photo's undistorted border, whose
        // sides (for these lenses) touch an edge's middle or its corners.
        let edge = |u: f64, v: f64| {
            lens.undistort(
                (u - c.cx as f64) / c.fx as f64,
                (v - c.cy as f64) / c.fy as f64,
            )
            .unwrap()
        };
        let (r, b) = (c.width as f64 - 0.5, c.height as f64 - 0.5);
        let side = |u: f64| [c.cy as f64, 0.5, b].map(|v| edge(u, v).0);
        let left = side(0.5).into_iter().fold(f64::MIN, f64::max);
        let right = side(r).into_iter().fold(f64::MAX, f64::min);
        let width = (right - left) * c.fx as f64;
        assert!(
            (a.width as f64 - width).abs() <= 4.0,
            "{model}: width {} vs {width:.1}",
            a.width
        );
        let ts = dir.path().join("transforms");
        write_transforms(
            &ts,
            std::slice::from_ref(&c),
            std::slice::from_ref(&photo),
            keys,
        );
        let set =
            data::load_transforms_with(&ts, Resolution(1), false, [0.0; 3], LensMode::Undistort)
                .unwrap();
        let b = check_loaded(&set, &c, &photo, &format!("transforms.json {model}"));
        assert_eq!(
            (a.width, a.height, a.cx, a.cy),
            (b.width, b.height, b.cx, b.cy),
            "{model}"
        );
    }
}

#[test]
fn zero_coefficients_load_exactly_as_a_pinhole_camera() {
    let scene = scene();
    let cams = cameras(2, 48, 36);
    let photos: Vec<_> = cams.iter().map(|c| render(&scene, c)).collect();
    let dir = tempfile::tempdir().unwrap();
    let load = |name: &str, model: &str, params: &str, lenses: LensMode| {
        let d = dir.path().join(name);
        write_colmap(&d, &cams, &photos, model, params);
        data::load_colmap_with(&d, Resolution(2), false, lenses).unwrap()
    };
    let pinhole = load("pinhole", "PINHOLE", "", LensMode::Through);
    for lenses in [LensMode::Through, LensMode::Undistort] {
        for (name, model, params) in [
            ("opencv", "OPENCV", "0 0 0 0"),
            ("full", "FULL_OPENCV", "0 0 0 0 0 0 0 0"),
        ] {
            let other = load(name, model, params, lenses);
            assert!(other.undistorted.is_empty());
            assert!(other.lens_record().is_none(), "{model}: no lens to record");
            for (a, b) in pinhole.train.iter().zip(&other.train) {
                assert_eq!(a.camera, b.camera, "{model} {lenses:?}");
                assert!(a.image == b.image, "{model} {lenses:?}: the photos differ");
            }
        }
    }
    let ts = |name: &str, lens: &str, lenses: LensMode| {
        let d = dir.path().join(name);
        write_transforms(&d, &cams, &photos, lens);
        data::load_transforms_with(&d, Resolution(1), false, [0.0; 3], lenses).unwrap()
    };
    for lenses in [LensMode::Through, LensMode::Undistort] {
        let (a, b) = (
            ts("ts", "", lenses),
            ts(
                "ts0",
                "\"k1\": 0, \"k2\": 0.0, \"p1\": 0, \"p2\": 0",
                lenses,
            ),
        );
        assert!(b.undistorted.is_empty());
        for (a, b) in a.train.iter().zip(&b.train) {
            assert!(a.camera == b.camera && a.image == b.image);
            assert!(b.camera.lens.is_pinhole());
        }
    }
}

/// By default a distorted data set loads as taken: each camera carries the lens of its
/// model (COLMAP and transforms.json alike), the photos are the files' pixels, nothing is
/// undistorted; at `-r 2` the focal lengths and principal point halve and the lens's
/// coefficients (normalised coordinates) stay. The lenses are what the model directory's
/// `lenses.json` records. An `EQUIRECTANGULAR` transforms.json, which cannot be
/// undistorted, loads as the whole sphere.
#[test]
fn distorted_photos_load_as_taken_with_their_lens_by_default() {
    let scene = scene();
    let cam = cameras(1, 64, 48).remove(0);
    let cases = [
        (
            "OPENCV",
            "-0.25 0.06 0.002 -0.001",
            Distortion::opencv("OPENCV", [-0.25, 0.06, 0.0, 0.0, 0.0, 0.0], [0.002, -0.001]),
            "\"k1\": -0.25, \"k2\": 0.06, \"p1\": 0.002, \"p2\": -0.001",
        ),
        (
            "OPENCV_FISHEYE",
            "0.03 -0.01 0.002 0",
            Distortion::fisheye("OPENCV_FISHEYE", [0.03, -0.01, 0.002, 0.0]),
            "\"camera_model\": \"OPENCV_FISHEYE\", \"k1\": 0.03, \"k2\": -0.01, \"k3\": 0.002",
        ),
    ];
    for (model, params, d, keys) in cases {
        let photo = distorted_photo(&scene, &cam, &d);
        let dir = tempfile::tempdir().unwrap();
        let colmap = dir.path().join("colmap");
        let one = std::slice::from_ref(&cam);
        let photos = std::slice::from_ref(&photo);
        write_colmap(&colmap, one, photos, model, params);
        let ts = dir.path().join("transforms");
        write_transforms(&ts, one, photos, keys);
        let lens = Lens::from_distortion(&d);
        for r in [1, 2] {
            let sets = [
                data::load_colmap(&colmap, Resolution(r), false).unwrap(),
                data::load_transforms(&ts, Resolution(r), false, [0.0; 3]).unwrap(),
            ];
            for set in sets {
                let what = format!("{model} -r {r} {}", set.source.display());
                assert_eq!(set.lenses, LensMode::Through);
                assert!(set.undistorted.is_empty(), "{what}");
                let v = &set.train[0];
                let c = &v.camera;
                assert_eq!(c.lens, lens, "{what}: the camera's lens");
                let s = 1.0 / r as f32;
                assert_eq!(
                    (c.width, c.height),
                    (cam.width / r, cam.height / r),
                    "{what}"
                );
                for (a, b) in [
                    (c.fx, cam.fx),
                    (c.fy, cam.fy),
                    (c.cx, cam.cx),
                    (c.cy, cam.cy),
                ] {
                    assert!(
                        (a - b * s).abs() <= 1e-4 * b.abs(),
                        "{what}: {a} vs {b} / {r}"
                    );
                }
                assert!(c.rotation.abs_diff_eq(cam.rotation, 1e-6), "{what}");
                // The photo as taken (8-bit), area-averaged at -r 2.
                let stored = |p: &[[f32; 3]]| -> Vec<[f32; 3]> {
                    p.iter()
                        .map(|px| px.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() / 255.0))
                        .collect()
                };
                let want = data::resize(&stored(&photo), cam.width, cam.height, c.width, c.height);
                let worst = v
                    .image
                    .iter()
                    .flatten()
                    .zip(want.iter().flatten())
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                assert!(worst < 1e-5, "{what}: the photo differs by {worst}");
                let record: serde_json::Value =
                    serde_json::from_str(&set.lens_record().expect("a lens to record")).unwrap();
                assert_eq!(record["lenses"], "through", "{what}");
                assert_eq!(record["photos"][lens.name()], 1, "{what}: {record}");
            }
        }
        // Undistorting: the record says so, of the lens the photos were taken with.
        let set =
            data::load_colmap_with(&colmap, Resolution(1), false, LensMode::Undistort).unwrap();
        assert!(set.train[0].camera.lens.is_pinhole());
        let record: serde_json::Value = serde_json::from_str(&set.lens_record().unwrap()).unwrap();
        assert_eq!(record["lenses"], "undistort");
        assert_eq!(record["photos"][lens.name()], 1, "{record}");
    }
    // The whole sphere through the lens (no focal length needed), refused undistorting.
    let cams = cameras(1, 64, 32);
    let photos = vec![render(&scene, &cams[0])];
    let dir = tempfile::tempdir().unwrap();
    write_transforms(
        dir.path(),
        &cams,
        &photos,
        "\"camera_model\": \"EQUIRECTANGULAR\"",
    );
    let file = dir.path().join("transforms.json");
    let text = std::fs::read_to_string(&file).unwrap();
    let fl = format!("\"fl_x\": {}, \"fl_y\": {}, ", cams[0].fx, cams[0].fy);
    std::fs::write(&file, text.replace(&fl, "")).unwrap();
    let set = data::load_transforms(dir.path(), Resolution(2), false, [0.0; 3]).unwrap();
    let c = &set.train[0].camera;
    assert_eq!(c.lens, Lens::FULL_SPHERE);
    assert_eq!((c.width, c.height, c.fx, c.fy), (32, 16, 16.0, 16.0));
    let e = data::load_transforms_with(
        dir.path(),
        Resolution(2),
        false,
        [0.0; 3],
        LensMode::Undistort,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("EQUIRECTANGULAR"), "{e}");
}

#[test]
fn lenses_that_cannot_be_undistorted_are_refused_by_name() {
    let scene = scene();
    let cams = cameras(1, 32, 24);
    let photos = vec![render(&scene, &cams[0])];
    let dir = tempfile::tempdir().unwrap();
    for (i, (model, params)) in [
        ("FOV", "0.2"),
        ("THIN_PRISM_FISHEYE", "0 0 0 0 0 0 0 0"),
        ("RAD_TAN_THIN_PRISM_FISHEYE", "0 0 0 0 0 0 0 0 0 0 0 0"),
    ]
    .into_iter()
    .enumerate()
    {
        let d = dir.path().join(format!("c{i}"));
        write_colmap(&d, &cams, &photos, model, params);
        let e = data::load_colmap(&d, Resolution(1), false)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(model) && e.contains("cameras.txt") && e.contains("camera 1"),
            "{e}"
        );
    }
    // Undistorting refuses a lens it has no pinhole view for; these refusals hold through
    // the lens too, but for EQUIRECTANGULAR, which the renderers draw.
    for (i, (lens, says)) in [
        ("\"camera_model\": \"EQUIRECTANGULAR\"", "EQUIRECTANGULAR"),
        ("\"k1\": 0.1, \"k4\": 0.01", "\"k4\""),
        (
            "\"camera_model\": \"OPENCV_FISHEYE\", \"p1\": 0.01",
            "\"p1\"",
        ),
        ("\"k5\": 0.01", "\"k5\""),
        ("\"ftheta_p1\": 0.5", "f-theta"),
        ("\"k1\": \"x\"", "\"k1\" is not a finite number"),
    ]
    .into_iter()
    .enumerate()
    {
        let d = dir.path().join(format!("t{i}"));
        write_transforms(&d, &cams, &photos, lens);
        let e = data::load_transforms_with(&d, Resolution(1), false, [0.0; 3], LensMode::Undistort)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(says) && e.contains("transforms.json"),
            "{lens}: {e}"
        );
        let through = data::load_transforms(&d, Resolution(1), false, [0.0; 3]);
        match through {
            Ok(set) => assert!(
                i == 0 && set.train[0].camera.lens == Lens::FULL_SPHERE,
                "{lens}: loaded"
            ),
            Err(e) => assert!(e.to_string().contains(says), "{lens}: {e}"),
        }
    }
    // A lens given for another size than the photo's.
    let d = dir.path().join("wh");
    write_transforms(&d, &cams, &photos, "\"k1\": 0.1");
    let file = d.join("transforms.json");
    let text = std::fs::read_to_string(&file).unwrap();
    std::fs::write(&file, text.replace("\"w\": 32", "\"w\": 64")).unwrap();
    let e = data::load_transforms(&d, Resolution(1), false, [0.0; 3])
        .unwrap_err()
        .to_string();
    assert!(e.contains("32x24") && e.contains("64x24"), "{e}");
    // The command line says it in one line, without writing a model.
    let d = dir.path().join("t0");
    let model = dir.path().join("model");
    let o = verisplat(&[
        "train",
        d.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
        "--undistort",
        "-q",
    ]);
    let err = common::cli::stderr(&o);
    assert!(
        !o.status.success() && err.contains("EQUIRECTANGULAR"),
        "{err}"
    );
    assert!(!model.exists());
}

/// `train -r 2 --undistort` on distorted photos, then `eval` with no other flag: the photos
/// are undistorted and scaled as the trainer did (`cfg_args` says `resolution=2`,
/// `undistortion.json` how, `lenses.json` that it undistorted), so eval's held-out PSNR is
/// the trainer's; `-r` overrides. The model's cameras are pinholes.
#[test]
fn eval_of_a_model_trained_at_r_2_on_distorted_photos_uses_the_trainers_photos() {
    let scene = scene();
    let lens = Distortion::opencv("OPENCV", [-0.1, 0.01, 0.0, 0.0, 0.0, 0.0], [0.001, 0.0]);
    let cams = cameras(9, 64, 48);
    let photos: Vec<_> = cams
        .iter()
        .map(|c| distorted_photo(&scene, c, &lens))
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("data");
    write_colmap(&set, &cams, &photos, "OPENCV", "-0.1 0.01 0.001 0");
    let model = dir.path().join("model");
    let out = verisplat(&[
        "train",
        set.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
        "-r",
        "2",
        "--eval",
        "--iterations",
        "40",
        "--test-iterations",
        "40",
        "--random-points",
        "2000",
        "--sh-degree",
        "0",
        "--undistort",
        "-q",
    ]);
    let text = common::cli::stdout(&out);
    assert!(out.status.success(), "{}", common::cli::stderr(&out));
    let trained: f64 = text
        .split("PSNR ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .expect("a PSNR in the summary");
    let cfg = std::fs::read_to_string(model.join("cfg_args")).unwrap();
    assert!(cfg.contains("resolution=2,"), "{cfg}");
    assert!(model.join("undistortion.json").is_file());
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join(data::LENS_FILE)).unwrap()).unwrap();
    assert_eq!(record["lenses"], "undistort", "{record}");
    assert_eq!(record["photos"]["distorted"], 9, "{record}");
    let (cams, _) =
        verisplat::io::camera::load_camera_file(&model.join("cameras.json"), &Default::default())
            .unwrap();
    assert!(cams.iter().all(|c| c.lens.is_pinhole()));
    let images = set.join("images");
    let eval = |extra: &[&str], report: &str| -> serde_json::Value {
        let rep = dir.path().join(report);
        let mut args = vec![
            "eval",
            model.to_str().unwrap(),
            "--images",
            images.to_str().unwrap(),
            "--float",
            "-q",
            "-o",
            rep.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = verisplat(&args);
        assert!(o.status.success(), "{}", common::cli::stderr(&o));
        serde_json::from_slice(&std::fs::read(rep.join("report.json")).unwrap()).unwrap()
    };
    let r = eval(&[], "rep");
    let psnr = r["mean"]["psnr"].as_f64().unwrap();
    assert!(
        (psnr - trained).abs() < 0.05,
        "eval {psnr} dB, train {trained} dB"
    );
    let w0 = r["results"][0]["width"].as_u64().unwrap();
    // -r 4 overrides the model's 2: half the size.
    let r4 = eval(&["-r", "4"], "rep4");
    assert_eq!(r4["results"][0]["width"].as_u64().unwrap(), w0 / 2);
}

/// A COLMAP data set of PLAYBOT LOD6 (CC BY 4.0) seen through an equidistant fisheye
/// (`OPENCV_FISHEYE`, k1..k4 = 0): `views` orbit cameras of `w x h` at 1.6 from the
/// centre, 180 degrees across the shorter side, imaging every ray up to 180 degrees from
/// the axis (as COLMAP's fisheye reads back), rendered by the CPU reference (what
/// `tools/fisheye_dataset.py` makes with `render --export-colmap`, small).
fn make_fisheye_dataset(dir: &Path, views: usize, w: u32, h: u32) {
    make_fisheye_dataset_of(dir, views, w, h, 180.0);
}

/// [`make_fisheye_dataset`] with `fov_deg` degrees across the shorter side.
fn make_fisheye_dataset_of(dir: &Path, views: usize, w: u32, h: u32, fov_deg: f32) {
    use verisplat::core::camera::Lens;
    let scene = verisplat::io::scene::load_with_format(
        &common::shared_data().join("playbot_lod6_1873_sh2.ply"),
    )
    .expect("the shared scene")
    .0;
    let f = w.min(h) as f32 / 2.0 / (fov_deg / 2.0).to_radians();
    let cams: Vec<_> = verisplat::core::camera::orbit(
        &scene.positions,
        &verisplat::core::camera::OrbitParams {
            frames: views,
            width: w,
            height: h,
            elevation_deg: 25.0,
            radius: Some(1.6),
            ..Default::default()
        },
    )
    .unwrap()
    .into_iter()
    .enumerate()
    .map(|(i, mut c)| {
        c.name = format!("fish_{i:03}.png");
        (c.fx, c.fy) = (f, f);
        c.lens = Lens::Fisheye {
            k: [0.0; 4],
            max_theta: std::f64::consts::PI,
        };
        c
    })
    .collect();
    verisplat::train::data::write_rendered_dataset(dir, &scene, &cams, None, 2, false).unwrap();
}

/// The test views' L1 and PSNR that `train` notes at iteration `it`.
fn noted_evaluation(log: &str, it: u32) -> (f64, f64) {
    let tag = format!("[ITER {it}] evaluating test");
    let line = log
        .lines()
        .find(|l| l.contains(&tag))
        .unwrap_or_else(|| panic!("no {tag} in {log}"));
    let after = |key: &str| -> f64 {
        line.split(key)
            .nth(1)
            .and_then(|s| s.split_whitespace().next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no {key} in {line}"))
    };
    (after("L1 "), after("PSNR "))
}

/// Training through a lens (issue 49), the default: a fisheye COLMAP data set (180
/// degrees across the shorter side, corners 150 degrees off the axis, which no pinhole
/// view holds) is trained on with its photos as taken, each render and the backward pass
/// through the lens. The held-out L1 falls and the PSNR rises from the start's (to 30 dB in
/// 120 iterations); the model
/// directory's cameras carry the fisheye lens, `lenses.json` says the run went through
/// it, there is no `undistortion.json`, and `eval` (rendering through the lens, the photos
/// as taken) gives the trainer's figure. `--undistort` refuses these photos by name.
#[test]
fn train_through_a_fisheye_lens_learns_and_records_it() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    make_fisheye_dataset(&data, 16, 64, 48);
    let model = dir.path().join("model");
    let out = verisplat(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
        "--eval",
        "--iterations",
        "120",
        "--test-iterations",
        "1,120",
        "--densify-from-iter",
        "60",
        "--densification-interval",
        "30",
        "--sh-degree",
        "1",
    ]);
    let log = format!("{}{}", common::cli::stdout(&out), common::cli::stderr(&out));
    eprintln!("{log}");
    assert!(
        log.contains("training through the lens") && log.contains("16 fisheye"),
        "{log}"
    );
    assert!(out.status.success(), "{log}");
    let (l1_start, psnr_start) = noted_evaluation(&log, 1);
    let (l1_end, psnr_end) = noted_evaluation(&log, 120);
    // Measured: L1 0.0141 -> 0.0061, PSNR 25.75 -> 32.15 dB.
    assert!(
        l1_end < 0.6 * l1_start && psnr_end > psnr_start + 4.0 && psnr_end >= 30.0,
        "held-out L1 {l1_start} -> {l1_end}, PSNR {psnr_start} -> {psnr_end} dB"
    );
    // The model directory records the lens.
    assert!(!model.join("undistortion.json").exists());
    let record: serde_json::Value = serde_json::from_slice(
        &std::fs::read(model.join(verisplat::train::data::LENS_FILE)).unwrap(),
    )
    .unwrap();
    assert_eq!(record["lenses"], "through", "{record}");
    assert_eq!(record["photos"]["fisheye"], 16, "{record}");
    let (cams, _) =
        verisplat::io::camera::load_camera_file(&model.join("cameras.json"), &Default::default())
            .unwrap();
    assert_eq!(cams.len(), 16);
    for c in &cams {
        assert!(
            matches!(c.lens, verisplat::core::camera::Lens::Fisheye { max_theta, .. } if max_theta == std::f64::consts::PI),
            "{}: {:?}",
            c.name,
            c.lens
        );
    }
    // eval renders through the lens and compares with the photos as taken.
    let rep = dir.path().join("rep");
    let eval = verisplat(&[
        "eval",
        model.to_str().unwrap(),
        "--images",
        data.join("images").to_str().unwrap(),
        "--float",
        "-q",
        "-o",
        rep.to_str().unwrap(),
    ]);
    assert!(eval.status.success(), "{}", common::cli::stderr(&eval));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(rep.join("report.json")).unwrap()).unwrap();
    let psnr = report["mean"]["psnr"].as_f64().unwrap();
    assert!(
        (psnr - psnr_end).abs() < 0.05,
        "eval {psnr} dB, train {psnr_end} dB"
    );
    // No pinhole view holds a 180-degree fisheye's photo: --undistort says so by name.
    let refused = verisplat(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        dir.path().join("pinhole").to_str().unwrap(),
        "--undistort",
        "-q",
    ]);
    let err = common::cli::stderr(&refused);
    assert!(
        !refused.status.success()
            && err.contains("OPENCV_FISHEYE")
            && err.contains("no pinhole image"),
        "{err}"
    );
}

/// `--undistort` on fisheye photos (issue 59, item 9): a lens no pinhole view holds is
/// refused naming the model's own coefficients (k1..k4, not the Brown-Conrady slots they
/// are stored in), and a 120-degree fisheye at 160x120, whose pinhole views are 618x194,
/// gets a one-line note that they hold several times the photos' pixels and how to limit
/// them (-r), which -r 2 then silences.
#[test]
fn undistorting_a_fisheye_names_its_coefficients_and_notes_upsampling() {
    let dir = tempfile::tempdir().unwrap();
    let train = |data: &Path, model: &str, extra: &[&str]| {
        let model = dir.path().join(model);
        let mut args = vec![
            "train",
            data.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--undistort",
            "--iterations",
            "1",
            "--sh-degree",
            "0",
        ];
        args.extend_from_slice(extra);
        let o = verisplat(&args);
        (o.status.success(), common::cli::stderr(&o))
    };
    let wide = dir.path().join("wide");
    make_fisheye_dataset_of(&wide, 2, 32, 24, 180.0);
    let (ok, err) = train(&wide, "wide_model", &[]);
    assert!(
        !ok && err.contains("OPENCV_FISHEYE (k1 0, k2 0, k3 0, k4 0) lens distortion")
            && !err.contains("[0.0"),
        "{err}"
    );
    let fish = dir.path().join("fish");
    make_fisheye_dataset_of(&fish, 2, 160, 120, 120.0);
    let (ok, err) = train(&fish, "m1", &[]);
    assert!(ok, "{err}");
    assert!(err.contains("160x120 -> 618x194"), "{err}");
    let note: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("x the photos' pixels"))
        .collect();
    assert_eq!(note.len(), 1, "{err}");
    assert!(
        note[0].contains("6.2x") && note[0].contains("-r 2, 4 or 8"),
        "{}",
        note[0]
    );
    // At -r 2 the views hold 1.6 times the photos' pixels: no note.
    let (ok, err) = train(&fish, "m2", &["-r", "2"]);
    assert!(ok, "{err}");
    assert!(!err.contains("x the photos' pixels"), "{err}");
}
