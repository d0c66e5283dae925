//! Camera files carry their lens (issue 49, "every command and camera source"): a COLMAP
//! fisheye or distorted model, a nerfstudio fisheye or equirectangular path, a
//! transforms.json with a `camera_model` and an exported cameras.json render through their
//! lens, exactly as `render --lens` draws the same camera; `info` names each camera's
//! lens; the exports keep it, and COLMAP's refuses what it has no model for.

use crate::common::cli::{stderr, stdout, verisplat_in};
use std::path::Path;
use verisplat::core::camera::{Lens, LensSpec};
use verisplat::io;
use verisplat::io::camera::PathTiming;

/// The demo scene from (0, -0.5, -1.5), looking along +z with -y up: the camera whose
/// rotation is the identity and translation (0, 0.5, 1.5).
const LOOK_AT: &str = "0,-0.5,-1.5,0,-0.5,0,0,-1,0";

/// Runs `verisplat render --demo --cpu ARGS` in `dir`, which must succeed.
fn render(dir: &Path, args: &[&str]) {
    let mut all = vec!["render", "--demo", "--cpu", "-q"];
    all.extend_from_slice(args);
    let o = verisplat_in(dir, &all);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

fn pixels(path: &Path) -> Vec<u8> {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgba8()
        .into_raw()
}

/// A COLMAP text model in `dir/name` of one camera of `model` line `camera` (after the
/// id) at the identity rotation and translation (0, 0.5, 3): LOOK_AT's pose.
fn colmap(dir: &Path, name: &str, camera: &str) {
    let d = dir.join(name);
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(d.join("cameras.txt"), format!("1 {camera}\n")).unwrap();
    std::fs::write(d.join("images.txt"), "1 1 0 0 0 0 0.5 1.5 1 cam.png\n\n").unwrap();
}

#[test]
fn camera_files_render_through_their_lens_as_render_lens_draws_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The reference: a 360-degree equidistant fisheye (the lens a COLMAP OPENCV_FISHEYE
    // camera with zero coefficients is), exported as a cameras.json too.
    render(
        dir,
        &[
            "--look-at",
            LOOK_AT,
            "--lens",
            "fisheye:fov=360",
            "--width",
            "96",
            "--height",
            "64",
            "-o",
            "lens.png",
            "--export-cameras",
            "cams.json",
        ],
    );
    let want = pixels(&dir.join("lens.png"));
    let lit = want.chunks(4).filter(|p| p[..3] != [0, 0, 0]).count();
    assert!(lit > 150, "{lit} lit pixels");
    // Its focal length: the 180 degrees off the axis at the shorter side's edge.
    let f = (32.0 / std::f64::consts::PI) as f32;
    colmap(
        dir,
        "fisheye",
        &format!("OPENCV_FISHEYE 96 64 {f} {f} 48 32 0 0 0 0"),
    );
    colmap(dir, "pinhole", &format!("PINHOLE 96 64 {f} {f} 48 32"));
    std::fs::write(
        dir.join("transforms.json"),
        format!(
            r#"{{"w": 96, "h": 64, "fl_x": {f}, "fl_y": {f}, "cx": 48, "cy": 32,
                "camera_model": "OPENCV_FISHEYE", "k1": 0, "k2": 0, "k3": 0, "k4": 0,
                "frames": [{{"file_path": "images/cam.png", "transform_matrix":
                    [[1, 0, 0, 0], [0, -1, 0, -0.5], [0, 0, -1, -1.5], [0, 0, 0, 1]]}}]}}"#
        ),
    )
    .unwrap();
    for (cameras, out) in [
        ("fisheye", "colmap.png"),
        ("cams.json", "json.png"),
        ("transforms.json", "transforms.png"),
        ("pinhole", "pinhole.png"),
    ] {
        render(dir, &["--cameras", cameras, "-o", out]);
    }
    assert!(
        pixels(&dir.join("colmap.png")) == want,
        "the COLMAP fisheye"
    );
    assert!(
        pixels(&dir.join("json.png")) == want,
        "the exported cameras.json"
    );
    assert!(
        pixels(&dir.join("transforms.png")) == want,
        "the transforms.json"
    );
    // The pinhole of the same intrinsics sees something else: the lens was used.
    assert!(pixels(&dir.join("pinhole.png")) != want);

    // nerfstudio: the equirectangular path is the whole sphere of --lens equirect, and
    // the fisheye path's fov gives the perspective camera's focal length.
    render(
        dir,
        &[
            "--look-at",
            LOOK_AT,
            "--lens",
            "equirect",
            "--width",
            "128",
            "--height",
            "64",
            "-o",
            "equirect.png",
        ],
    );
    let gl = "[1,0,0,0, 0,-1,0,-0.5, 0,0,-1,-1.5, 0,0,0,1]";
    for (kind, fov) in [("equirectangular", 90.0), ("fisheye", 90.0)] {
        std::fs::write(
            dir.join(format!("{kind}.json")),
            format!(
                r#"{{"camera_type": "{kind}", "render_width": 128, "render_height": 64,
                    "camera_path": [{{"camera_to_world": {gl}, "fov": {fov}}}]}}"#
            ),
        )
        .unwrap();
        render(
            dir,
            &[
                "--cameras",
                &format!("{kind}.json"),
                "-o",
                &format!("ns_{kind}.png"),
            ],
        );
    }
    assert!(pixels(&dir.join("ns_equirectangular.png")) == pixels(&dir.join("equirect.png")));
    let f = (64.0 / (2.0 * 45f64.to_radians().tan())) as f32;
    colmap(
        dir,
        "ns_equivalent",
        &format!("OPENCV_FISHEYE 128 64 {f} {f} 64 32 0 0 0 0"),
    );
    render(dir, &["--cameras", "ns_equivalent", "-o", "ns_colmap.png"]);
    assert!(pixels(&dir.join("ns_fisheye.png")) == pixels(&dir.join("ns_colmap.png")));
    let (cams, _) =
        io::camera::load_camera_file(&dir.join("fisheye.json"), &PathTiming::default()).unwrap();
    assert_eq!(
        cams[0].lens,
        Lens::Fisheye {
            k: [0.0; 4],
            max_theta: std::f64::consts::PI
        }
    );
}

#[test]
fn info_names_each_cameras_lens() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("model");
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(
        d.join("cameras.txt"),
        "1 PINHOLE 64 48 50 50 32 24\n\
         2 OPENCV 64 48 50 50 32 24 -0.1 0.01 0 0\n\
         3 OPENCV_FISHEYE 64 48 20 20 32 24 0 0 0 0\n\
         4 FULL_OPENCV 64 48 50 50 32 24 -0.1 0.01 0 0 0.001 0 0 0\n",
    )
    .unwrap();
    std::fs::write(
        d.join("images.txt"),
        "1 1 0 0 0 0 0 3 1 a.png\n\n\
         2 1 0 0 0 0 0 3 2 b.png\n\n\
         3 1 0 0 0 0 0 3 3 c.png\n\n\
         4 1 0 0 0 0 0 3 3 d.png\n\n\
         5 1 0 0 0 0 0 3 4 e.png\n\n",
    )
    .unwrap();
    let o = verisplat_in(tmp.path(), &["info", "model"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(
        text.contains(
            "lens        pinhole (1), distorted (OPENCV) (1), fisheye (2), distorted (FULL_OPENCV) (1)"
        ),
        "{text}"
    );
    let o = verisplat_in(tmp.path(), &["info", "model", "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        json["lenses"],
        serde_json::json!([
            "pinhole",
            "distorted (OPENCV)",
            "fisheye",
            "fisheye",
            "distorted (FULL_OPENCV)"
        ])
    );
}

#[test]
fn exports_keep_the_lens_and_colmap_refuses_what_it_has_no_model_for() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    fn generated<'a>(lens: &'a str, export: &[&'a str]) -> Vec<&'a str> {
        let mut args = vec![
            "--look-at",
            LOOK_AT,
            "--lens",
            lens,
            "--width",
            "48",
            "--height",
            "32",
        ];
        args.extend_from_slice(export);
        args
    }
    // --export-cameras: every lens reads back as it was.
    for (i, lens) in [
        "fisheye:fov=200",
        "equirect:lon=-90..90,lat=45..-45",
        "ortho:width=2.5",
    ]
    .into_iter()
    .enumerate()
    {
        let file = format!("cams_{i}.json");
        render(
            dir,
            &generated(
                lens,
                &["-o", &format!("x_{i}.png"), "--export-cameras", &file],
            ),
        );
        let (cams, _) =
            io::camera::load_camera_file(&dir.join(&file), &PathTiming::default()).unwrap();
        assert_eq!(
            cams[0].lens,
            lens.parse::<LensSpec>().unwrap().lens(),
            "{lens}"
        );
    }
    // --export-colmap: a fisheye becomes OPENCV_FISHEYE, and the data set's model renders
    // its own images back.
    render(
        dir,
        &generated("fisheye:fov=360", &["--export-colmap", "data"]),
    );
    let cameras = std::fs::read_to_string(dir.join("data/sparse/0/cameras.txt")).unwrap();
    assert!(
        cameras.contains("1 OPENCV_FISHEYE 48 32 5.092958 5.092958 24 16 0 0 0 0"),
        "{cameras}"
    );
    render(dir, &["--cameras", "data/sparse/0", "-o", "back.png"]);
    assert!(pixels(&dir.join("back.png")) == pixels(&dir.join("data/images/look_at.png")));
    // A distorted COLMAP camera is written back as the model that holds it.
    colmap(
        dir,
        "opencv",
        "OPENCV 48 32 40 41 24 16 -0.2 0.03 0.001 -0.002",
    );
    render(dir, &["--cameras", "opencv", "--export-colmap", "data2"]);
    let cameras = std::fs::read_to_string(dir.join("data2/sparse/0/cameras.txt")).unwrap();
    assert!(
        cameras.contains("1 OPENCV 48 32 40 41 24 16 -0.2 0.03 0.001 -0.002"),
        "{cameras}"
    );
    colmap(
        dir,
        "full",
        "FULL_OPENCV 48 32 40 41 24 16 -0.2 0.03 0.001 -0.002 0.004 0.1 0 0",
    );
    render(dir, &["--cameras", "full", "--export-colmap", "data3"]);
    let (cams, _) = io::camera::colmap::load_colmap_model(&dir.join("data3")).unwrap();
    assert_eq!(
        cams[0].lens,
        Lens::RadialTangential {
            radial: [-0.2, 0.03, 0.004, 0.1, 0.0, 0.0],
            tangential: [0.001, -0.002]
        }
    );
    // COLMAP has no orthographic or equirectangular model: refused, nothing written.
    for lens in ["ortho", "equirect"] {
        let mut args = vec!["render", "--demo", "--cpu"];
        args.extend(generated(lens, &["--export-colmap", "refused"]));
        let o = verisplat_in(dir, &args);
        let e = stderr(&o);
        assert!(
            !o.status.success() && e.contains("lens, which COLMAP has no camera model for"),
            "{lens}: {e}"
        );
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(!dir.join("refused").exists(), "{lens}");
    }
}
