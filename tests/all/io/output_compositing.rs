//! Outputs for compositing and for other tools: premultiplied EXR with Z and the camera
//! in its header, RGBA PNG, camera paths exported as INRIA cameras.json, and the bench
//! JSON and sweep plot. Each is checked through the binary against the CPU reference
//! rendered in memory (the binary's `--cpu` path is the same code, so most comparisons
//! are exact).

use crate::common::cli::{fails, ok, s};

use std::path::{Path, PathBuf};
use std::process::Command;
use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::core::frame::Frame;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;

use verisplat::io::output;

/// The demo scene's default camera at 200x113, written as a cameras.json for the binary;
/// returns the file and the camera as read back (what the binary renders).
fn demo_camera(dir: &Path) -> (PathBuf, Camera) {
    let scene = verisplat::io::demo::demo_scene();
    let cam = camera::default_camera(&scene.positions, 1280, 720)
        .resized(Some(200), None, None)
        .unwrap();
    let path = dir.join("camera.json");
    std::fs::write(&path, io::camera::inria::to_json(&[(0, cam)]).unwrap()).unwrap();
    let cam = io::camera::load_cameras_json(&path).unwrap().remove(0);
    (path, cam)
}

fn cpu_render(cam: &Camera, background: [f32; 3]) -> Frame {
    cpu::render(
        &verisplat::io::demo::demo_scene().activated(),
        cam,
        &RenderOptions {
            background,
            ..Default::default()
        },
    )
}

/// The layer of an EXR file: its channels by name and its attributes.
fn read_exr(
    path: &Path,
) -> (
    Vec<(String, exr::prelude::FlatSamples)>,
    exr::meta::header::LayerAttributes,
) {
    let mut image = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let layer = image.layer_data.remove(0);
    let channels = layer
        .channel_data
        .list
        .into_iter()
        .map(|c| (c.name.to_string(), c.sample_data))
        .collect();
    (channels, layer.attributes)
}

fn plane(channels: &[(String, exr::prelude::FlatSamples)], name: &str) -> Vec<f32> {
    let (_, samples) = channels
        .iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no channel {name}"));
    samples.values_as_f32().collect()
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn exr_is_premultiplied_with_z_infinite_where_empty_and_the_camera_in_its_header() {
    let dir = tempfile::tempdir().unwrap();
    let (cams, cam) = demo_camera(dir.path());
    let bg = [1.0, 0.5, 0.25];
    let (full, half, baked) = (
        dir.path().join("full.exr"),
        dir.path().join("half.exr"),
        dir.path().join("baked.exr"),
    );
    let base = [
        "render",
        "--demo",
        "--cpu",
        "--cameras",
        s(&cams),
        "--background",
        "1,0.5,0.25",
    ];
    for (out, extra) in [
        (&full, &[][..]),
        (&half, &["--exr-half"][..]),
        (&baked, &["--exr-background"][..]),
    ] {
        let mut args = base.to_vec();
        args.extend(["-o", s(out)]);
        args.extend(extra);
        ok(&args);
    }
    let over_bg = cpu_render(&cam, bg);
    let over_black = cpu_render(&cam, [0.0; 3]);
    let (channels, attributes) = read_exr(&full);
    let names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["A", "B", "G", "R", "Z"]);
    // RGB is the accumulated colour, premultiplied: the render over black, to float
    // rounding of the background's removal (1 - alpha is T to 6e-8, times bg <= 1).
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        let want: Vec<f32> = over_black.color.iter().map(|p| p[c]).collect();
        let d = max_diff(&plane(&channels, name), &want);
        assert!(d <= 1e-6, "{name}: off by {d}");
    }
    assert_eq!(plane(&channels, "A"), over_bg.alpha);
    // Z: the depth where something was rendered, +inf ("no surface") where alpha is 0.
    let z = plane(&channels, "Z");
    let empty = over_bg.alpha.iter().filter(|&&a| a == 0.0).count();
    assert!(
        empty > 100 && z.len() - empty > 1000,
        "{empty} empty pixels"
    );
    for (i, (&zi, &a)) in z.iter().zip(&over_bg.alpha).enumerate() {
        if a == 0.0 {
            assert_eq!(zi, f32::INFINITY, "pixel {i}");
        } else {
            assert_eq!(zi, over_bg.depth[i], "pixel {i}");
        }
    }
    // The camera, as OpenEXR's standard attributes.
    assert_eq!(
        attributes.world_to_camera,
        Some(output::exr_world_to_camera(&cam))
    );
    assert_eq!(
        attributes.world_to_normalized_device,
        Some(output::exr_world_to_ndc(&cam))
    );

    // --exr-half: R, G, B, A in half floats, Z still 32-bit.
    let (channels, _) = read_exr(&half);
    for (name, samples) in &channels {
        let is_f32 = matches!(samples, exr::prelude::FlatSamples::F32(_));
        assert_eq!(is_f32, name == "Z", "channel {name}");
    }
    assert_eq!(plane(&channels, "Z"), z);

    // --exr-background: the reference's image, background included, exactly.
    let (channels, _) = read_exr(&baked);
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        let want: Vec<f32> = over_bg.color.iter().map(|p| p[c]).collect();
        assert_eq!(plane(&channels, name), want, "{name}");
    }
    let e = fails(
        &[
            "render",
            "--demo",
            "--exr-background",
            "-o",
            s(&dir.path().join("x.png")),
        ],
        &dir.path().join("x.png"),
    );
    assert!(e.contains("--exr-background") && e.contains("EXR"), "{e}");

    // OpenEXR's own tool reads the attributes (exrheader: installed by tools/setup.sh).
    let header = Command::new("exrheader").arg(&full).output();
    if let Ok(header) = header {
        let text = String::from_utf8_lossy(&header.stdout);
        assert!(header.status.success(), "{text}");
        for attr in ["worldToCamera (type m44f)", "worldToNDC (type m44f)"] {
            assert!(text.contains(attr), "exrheader lacks {attr:?}:\n{text}");
        }
    }
}

#[test]
fn exr_matrices_map_points_like_the_camera() {
    // An off-centre principal point and unequal focal lengths, so every term shows.
    let mut cam = Camera::look_at(
        "c",
        320,
        200,
        0.9,
        glam::Vec3::new(1.0, -2.0, -4.0),
        glam::Vec3::new(0.2, 0.1, 0.3),
        glam::Vec3::NEG_Y,
    );
    cam.fx *= 1.1;
    cam.cx = 150.0;
    cam.cy = 107.0;
    let to_cam = output::exr_world_to_camera(&cam).map(f64::from);
    let to_ndc = output::exr_world_to_ndc(&cam).map(f64::from);
    // Row vector times row-major matrix, as OpenEXR (Imath) multiplies.
    let mul = |p: [f64; 3], m: &[f64; 16]| -> [f64; 4] {
        let mut out = [0.0; 4];
        for (c, o) in out.iter_mut().enumerate() {
            *o = p[0] * m[c] + p[1] * m[4 + c] + p[2] * m[8 + c] + m[12 + c];
        }
        out
    };
    for p in [[0.0, 0.0, 0.0], [0.5, -0.3, 0.8], [-1.0, 0.7, 2.0]] {
        let opencv = cam.rotation * glam::Vec3::from(p.map(|v| v as f32)) + cam.translation;
        assert!(opencv.z > 1.0);
        // Camera space: x right, y up (OpenCV's y negated), z forward.
        let c = mul(p, &to_cam);
        let want = [opencv.x, -opencv.y, opencv.z];
        for k in 0..3 {
            assert!((c[k] - want[k] as f64).abs() < 1e-5, "{c:?} vs {want:?}");
        }
        assert_eq!(c[3], 1.0);
        // NDC: (0, 0) top-left, (1, 1) bottom-right corner of the image.
        let h = mul(p, &to_ndc);
        let u = (cam.fx * opencv.x / opencv.z + cam.cx) / cam.width as f32;
        let v = (cam.fy * opencv.y / opencv.z + cam.cy) / cam.height as f32;
        assert!(
            (h[0] / h[3] - u as f64).abs() < 1e-5,
            "x {} vs {u}",
            h[0] / h[3]
        );
        assert!(
            (h[1] / h[3] - v as f64).abs() < 1e-5,
            "y {} vs {v}",
            h[1] / h[3]
        );
        let near_z = 1.0 - 0.2 / opencv.z as f64;
        assert!((h[2] / h[3] - near_z).abs() < 1e-5);
    }
}

#[test]
fn rgba_png_holds_straight_colour_over_a_transparent_background() {
    let dir = tempfile::tempdir().unwrap();
    let (cams, cam) = demo_camera(dir.path());
    let bg = [0.2, 0.4, 0.6];
    let over_bg = cpu_render(&cam, bg);
    let over_black = cpu_render(&cam, [0.0; 3]);
    let straight = output::straight_color(&over_bg, bg);
    for sixteen in [false, true] {
        let out = dir.path().join(format!("rgba{sixteen}.png"));
        let mut args = vec![
            "render",
            "--demo",
            "--cpu",
            "--cameras",
            s(&cams),
            "--background",
            "0.2,0.4,0.6",
            "--mode",
            "rgba",
            "-o",
            s(&out),
        ];
        if sixteen {
            args.push("--png16");
        }
        ok(&args);
        let img = image::open(&out).unwrap();
        let (scale, px): (f32, Vec<[u16; 4]>) = if sixteen {
            assert_eq!(img.color(), image::ColorType::Rgba16);
            (65535.0, img.to_rgba16().pixels().map(|p| p.0).collect())
        } else {
            assert_eq!(img.color(), image::ColorType::Rgba8);
            let px = img
                .to_rgba8()
                .pixels()
                .map(|p| p.0.map(u16::from))
                .collect();
            (255.0, px)
        };
        let q = |v: f32| {
            if sixteen {
                output::to_u16(v)
            } else {
                u16::from(output::to_u8(v))
            }
        };
        let mut checked = 0;
        for (i, p) in px.iter().enumerate() {
            let a = over_bg.alpha[i];
            // Alpha is the alpha plane quantised; RGB the straight colour quantised.
            assert_eq!(p[3], q(a), "alpha of pixel {i}");
            assert_eq!(&p[..3], &straight[i].map(q)[..], "colour of pixel {i}");
            if a == 0.0 {
                assert_eq!(*p, [0; 4], "empty pixel {i}");
            }
            // Straight colour times alpha is the render over black (the background is
            // not in it), to the quantisation of colour and alpha (half a step each).
            if a > 0.05 && straight[i].iter().all(|&c| c <= 1.0) {
                for c in 0..3 {
                    let composed = p[c] as f32 / scale * (p[3] as f32 / scale);
                    let err = (composed - over_black.color[i][c]).abs();
                    assert!(err <= 1.01 / scale, "pixel {i} channel {c}: off by {err}");
                }
                checked += 1;
            }
        }
        assert!(checked > 1000, "only {checked} covered pixels checked");
    }
}

#[test]
fn an_exported_orbit_renders_the_same_files_as_the_orbit() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("path/orbit.json");
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let pattern = |d: &Path| d.join("{name}.png").to_str().unwrap().to_string();
    let orbit = [
        "render",
        "--demo",
        "--orbit",
        "4",
        "--orbit-elevation=-15",
        "--width",
        "160",
        "--height",
        "100",
    ];
    let mut args = orbit.to_vec();
    let pa = pattern(&a);
    args.extend(["-o", &pa, "--export-cameras", s(&json)]);
    ok(&args);
    let pb = pattern(&b);
    ok(&["render", "--demo", "--cameras", s(&json), "-o", &pb]);
    // Byte-identical files: the exported cameras read back as the orbit's cameras
    // (rotation, intrinsics and size exactly; the position is written so that the
    // translation read back is the same float).
    let names = |d: &Path| {
        let mut v: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(&a).len(), 4);
    assert_eq!(names(&a), names(&b));
    for n in names(&a) {
        assert!(
            std::fs::read(a.join(&n)).unwrap() == std::fs::read(b.join(&n)).unwrap(),
            "{n:?} differs"
        );
    }
    // The INRIA layout: id, img_name, size, centre, camera-to-world rows, focal lengths.
    let scene = verisplat::io::demo::demo_scene();
    let cams = camera::orbit(
        &scene.positions,
        &camera::OrbitParams {
            frames: 4,
            elevation_deg: -15.0,
            // Generated cameras are made at the requested size (framed for its aspect).
            width: 160,
            height: 100,
            ..Default::default()
        },
    )
    .unwrap();
    let entries: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(entries.len(), 4);
    for (k, (e, cam)) in entries.iter().zip(&cams).enumerate() {
        assert_eq!(e["id"], k);
        assert_eq!(e["img_name"], format!("orbit_{k:05}"));
        assert_eq!(
            (e["width"].as_u64(), e["height"].as_u64()),
            (Some(160), Some(100))
        );
        assert_eq!(e["fx"].as_f64().unwrap() as f32, cam.fx);
        assert_eq!(e["fy"].as_f64().unwrap() as f32, cam.fy);
        assert!(
            e.get("cx").is_none(),
            "centred principal point is not written"
        );
        let c2w = cam.rotation.transpose();
        for r in 0..3 {
            for c in 0..3 {
                assert_eq!(e["rotation"][r][c].as_f64().unwrap() as f32, c2w.row(r)[c]);
            }
        }
        let centre = cam.position();
        for c in 0..3 {
            let d = (e["position"][c].as_f64().unwrap() as f32 - centre[c]).abs();
            assert!(d < 1e-5, "position {c} off by {d}");
        }
    }
    // Existing: refused without --overwrite, before rendering anything.
    let c = dir.path().join("c");
    let pc = pattern(&c);
    let mut args = orbit.to_vec();
    args.extend(["-o", &pc, "--export-cameras", s(&json)]);
    let e = fails(&args, &c);
    assert!(
        e.contains("already exists") && e.contains("--overwrite"),
        "{e}"
    );
    // --camera and the resolution apply; ids keep the frame numbers of the path.
    let picked = dir.path().join("picked.json");
    let mut args = orbit.to_vec();
    args.extend([
        "--camera",
        "1,3",
        "--scale",
        "0.5",
        "-o",
        &pc,
        "--export-cameras",
        s(&picked),
    ]);
    args.retain(|a| !["--width", "160", "--height", "100"].contains(a));
    ok(&args);
    let read = io::camera::load_cameras_json(&picked).unwrap();
    assert_eq!(read.len(), 2);
    assert_eq!((read[0].width, read[0].height), (640, 360));
    assert_eq!(read[1].name, "orbit_00003");
    let entries: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(&picked).unwrap()).unwrap();
    assert_eq!(
        (entries[0]["id"].as_u64(), entries[1]["id"].as_u64()),
        (Some(1), Some(3))
    );
}

#[test]
fn cameras_json_round_trip_keeps_an_off_centre_principal_point() {
    let mut cam = Camera::look_at(
        "IMG_1.jpg",
        333,
        187,
        0.8,
        glam::Vec3::new(3.0, -1.0, -2.0),
        glam::Vec3::ZERO,
        glam::Vec3::NEG_Y,
    );
    cam.cx = 160.25;
    let json = io::camera::inria::to_json(&[(7, cam.clone())]).unwrap();
    let back = io::camera::parse_cameras_json(&json, Path::new("x.json"))
        .unwrap()
        .remove(0);
    assert_eq!(back.cx, 160.25);
    assert_eq!(back.cy, 187.0 / 2.0);
    // Everything but the translation exactly; the translation to double rounding (a
    // component that is exactly 0 comes back as about 1e-16).
    let d = (back.translation - cam.translation).abs().max_element();
    assert!(d < 1e-12, "translation off by {d}");
    assert_eq!(
        Camera {
            translation: cam.translation,
            ..back
        },
        cam
    );
}

#[test]
fn bench_json_has_one_schema_and_names_the_timed_camera() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.json");
    let o = ok(&[
        "bench",
        "--demo",
        "--width",
        "160",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--json",
        s(&one),
    ]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    // Readable names, no Rust debug text.
    assert!(!text.contains('{') && !text.contains("(gpu)"), "{text}");
    assert!(
        text.contains("camera \"default\" (the default camera) at 160x90"),
        "{text}"
    );
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&one).unwrap()).unwrap();
    assert_eq!(doc["schema_version"], 1);
    let runs = doc["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 1);
    let run = &runs[0];
    assert_eq!(run["camera"]["name"], "default");
    assert_eq!(run["camera"]["source"], "the default camera");
    assert!(run["camera"]["index"].is_null());
    assert_eq!(
        (run["width"].as_u64(), run["height"].as_u64()),
        (Some(160), Some(90))
    );
    let kernel = run["blend_kernel"].as_str().unwrap();
    assert!(
        kernel == "shared" || kernel.starts_with("texel:"),
        "{kernel}"
    );
    assert!(kernel
        .parse::<verisplat::render::forward::blend::BlendKernel>()
        .is_ok());

    // A camera of a file: its name, index and the file.
    let (cams, _) = demo_camera(dir.path());
    let from_file = dir.path().join("file.json");
    ok(&[
        "bench",
        "--demo",
        "--cameras",
        s(&cams),
        "--camera",
        "0",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--cpu",
        "--json",
        s(&from_file),
    ]);
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&from_file).unwrap()).unwrap();
    let cam = &doc["runs"][0]["camera"];
    assert_eq!(cam["name"], "default");
    assert_eq!(cam["index"], 0);
    assert!(cam["source"].as_str().unwrap().contains("camera.json"));
    assert_eq!(doc["runs"][0]["renderer"], "cpu");

    // A sweep: the same layout with one run per point, and a summary table at the end.
    let sweep = dir.path().join("sweep.json");
    let o = ok(&[
        "bench",
        "--sweep",
        "gaussians=300,600",
        "--sweep",
        "resolution=64x48,128x96",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--json",
        s(&sweep),
    ]);
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&sweep).unwrap()).unwrap();
    assert_eq!(doc["schema_version"], 1);
    assert_eq!(doc["runs"].as_array().unwrap().len(), 4);
    assert_eq!(doc["runs"][3]["gaussians"], 600);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let table = text.split("sweep summary").nth(1).expect("a summary table");
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| l.contains("x48") || l.contains("x96"))
        .collect();
    assert_eq!(rows.len(), 4, "{table}");
    assert!(
        rows[3].trim_start().starts_with("600") && rows[3].contains("128x96"),
        "{table}"
    );
}

#[test]
fn the_sweep_plot_draws_every_series_as_stacked_areas() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("sweep.svg");
    ok(&[
        "bench",
        "--sweep",
        "gaussians=300,600,1200",
        "--sweep",
        "resolution=64x48,128x96",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--plot",
        s(&svg),
    ]);
    let plot = std::fs::read_to_string(&svg).unwrap();
    // One stacked panel per resolution and per Gaussian count: all six points plotted.
    for title in [
        "stages vs Gaussians at 64x48",
        "stages vs Gaussians at 128x96",
        "stages vs megapixels, 300 Gaussians",
        "stages vs megapixels, 600 Gaussians",
        "stages vs megapixels, 1.2k Gaussians",
        "frame time vs Gaussians",
        "frame time vs megapixels",
    ] {
        assert!(plot.contains(title), "no {title:?}");
    }
    // Filled areas (polygons), one per stage and panel: 8 GPU stages x 5 panels.
    assert!(plot.matches("<polygon").count() >= 40);
    // Ticks at the measured values: 0.003072 and 0.012288 megapixels, 300 to 1.2k.
    let texts: Vec<&str> = plot
        .split("</text>")
        .filter_map(|t| t.rsplit_once('>').map(|(_, text)| text.trim()))
        .collect();
    for tick in ["0.00307", "0.0123", "300", "600", "1.2k"] {
        assert!(texts.contains(&tick), "no tick {tick} in {texts:?}");
    }
    // No yellow on white.
    let upper = plot.to_ascii_uppercase();
    for yellow in ["#FFFF00", "#EDC948", "RGB(255,255,0)"] {
        assert!(!upper.contains(yellow), "{yellow} in the plot");
    }
}
