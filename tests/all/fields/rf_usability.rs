//! What a new user of the RF fields hit (issue 39): colour-bar labels drawn as written,
//! CSV headers that name the coordinates in any order (and a note for a time column
//! spelled almost right), too few samples refused unless forced, `--look-at`, and the
//! field examples' sizes. (The Slurm examples are tools/slurm_test.sh's.)

use crate::common::cli::{fails, ok, s, stderr};
use crate::common::{self, Rng};
use std::path::Path;

/// A field PLY of 30 Gaussians with 2 channels in `dir`.
fn field_ply(dir: &Path) -> std::path::PathBuf {
    let mut scene = common::random_scene(30, 0, 39);
    for v in scene.log_scales.iter_mut().flatten() {
        *v += 1.5;
    }
    let mut rng = Rng(39);
    let feats = (0..60).map(|_| rng.range(0.0, 1.0)).collect();
    scene.set_features(2, feats).unwrap();
    let path = dir.join("rf_field.ply");
    let bytes = verisplat::io::scene::ply::to_bytes(
        &scene,
        verisplat::io::scene::ply::PlyEncoding::BinaryLittleEndian,
    );
    std::fs::write(&path, bytes).unwrap();
    path
}

/// A CPU slice render of the field through z = 0.
const SLICE: [&str; 5] = [
    "--cpu",
    "--mode",
    "field-slice",
    "--slice-plane",
    "0,0,0,0,0,1",
];

/// Item 1: `mW` is not drawn as `MW`, nor `V/m` as `V/M`; a character the font cannot draw
/// is refused, naming it.
#[test]
fn colour_bar_labels_keep_their_case_and_refuse_what_the_font_cannot_draw() {
    let dir = tempfile::tempdir().unwrap();
    let ply = field_ply(dir.path());
    let render_at = |units: &str, name: &str, width: &str, range: &str| {
        let out = dir
            .path()
            .join(format!("bar_{}_{width}.png", units.len() + name.len() * 7));
        let _ = std::fs::remove_file(&out);
        let base = ["render", s(&ply)];
        ok(&[
            &base[..],
            &SLICE,
            &[
                "--width",
                width,
                "--height",
                "40",
                "--range",
                range,
                "--colorbar",
                "--units",
                units,
                "--channel-name",
                name,
                "-o",
                s(&out),
                "-q",
            ],
        ]
        .concat());
        image::open(&out).unwrap().to_rgb8()
    };
    let render = |units: &str, name: &str| render_at(units, name, "480", "0,1");
    let h = 40;
    let bar = |img: &image::RgbImage| -> Vec<u8> {
        let mut v = Vec::new();
        for y in h..img.height() {
            for x in 0..img.width() {
                v.extend(img.get_pixel(x, y).0);
            }
        }
        v
    };
    let milli = render("mW", "power");
    let mega = render("MW", "power");
    assert_eq!(
        milli.dimensions(),
        (480, h + verisplat::io::diff_image::BAR_HEIGHT)
    );
    assert_ne!(bar(&milli), bar(&mega), "mW and MW drew the same label");
    assert_ne!(bar(&render("V/m", "power")), bar(&render("V/M", "power")));
    assert_ne!(bar(&render("V/m", "e")), bar(&render("V/m", "E")));
    render("dBµV/m", "|E| at 20 °C");
    // A long label between long end labels at 320 wide (the walkthrough's side view): drawn
    // between them (at the font's single size), not left out.
    let narrow = |units: &str| bar(&render_at(units, "magnitude µ", "320", "0,0.5979"));
    assert_ne!(
        narrow("mW"),
        narrow("MW"),
        "the narrow bar left its label out"
    );
    let out = dir.path().join("refused.png");
    for (flag, label, c) in [
        ("--units", "Vж", "'ж' (U+0436)"),
        ("--channel-name", "Φ", "'Φ'"),
    ] {
        let base = ["render", s(&ply)];
        let e = fails(
            &[
                &base[..],
                &SLICE,
                &[
                    "--width",
                    "64",
                    "--colorbar",
                    flag,
                    label,
                    "-o",
                    s(&out),
                    "-q",
                ],
            ]
            .concat(),
            &out,
        );
        assert!(
            e.contains(flag) && e.contains(c) && e.contains("cannot draw"),
            "{e}"
        );
    }
}

/// Rows `x, y, z, v` of a smooth field at 400 random points, `v` written where `order`
/// says (`order` lists the columns by role: 'x', 'y', 'z', 'v', or 'n' for noise).
fn csv_rows(order: &str) -> String {
    let mut rng = Rng(7);
    let mut text = String::new();
    for _ in 0..400 {
        let p = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ];
        let v = (-(p[0] * p[0] + (p[1] - 0.3).powi(2) + p[2] * p[2]) * 2.0).exp();
        let noise = rng.range(0.0, 1.0);
        let cells: Vec<String> = order
            .chars()
            .map(|c| match c {
                'x' => p[0].to_string(),
                'y' => p[1].to_string(),
                'z' => p[2].to_string(),
                'v' => v.to_string(),
                _ => noise.to_string(),
            })
            .collect();
        text += &cells.join(",");
        text.push('\n');
    }
    text
}

fn fit_args<'a>(csv: &'a str, out: &'a str) -> Vec<&'a str> {
    vec!["fit", csv, "-o", out, "--gaussians", "10", "--steps", "20"]
}

/// Items 2 and 6: a header's x, y, z in any order are found by name (the same fit as in
/// x, y, z order), the summary says which column plays which role (and "1 channel");
/// headers without x, y or z are errors naming the columns.
#[test]
fn csv_headers_name_the_coordinates_in_any_order() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    std::fs::write(p("xyz.csv"), format!("x,y,z,power\n{}", csv_rows("xyzv"))).unwrap();
    std::fs::write(p("pxyz.csv"), format!("power,x,y,z\n{}", csv_rows("vxyz"))).unwrap();
    std::fs::write(
        p("zyx.csv"),
        format!("Z (m),power,y,x [m]\n{}", csv_rows("zvyx")),
    )
    .unwrap();
    ok(&fit_args(s(&p("xyz.csv")), s(&p("xyz.ply"))));
    let o = ok(&fit_args(s(&p("pxyz.csv")), s(&p("pxyz.ply"))));
    let e = stderr(&o);
    assert!(
        e.contains("x = column 1 \"x\"") && e.contains("feat_0 = column 0 \"power\""),
        "{e}"
    );
    assert!(
        e.contains("400 samples of 1 channel from") && !e.contains("1 channels"),
        "{e}"
    );
    ok(&fit_args(s(&p("zyx.csv")), s(&p("zyx.ply"))));
    let bytes = std::fs::read(p("xyz.ply")).unwrap();
    assert!(
        std::fs::read(p("pxyz.ply")).unwrap() == bytes,
        "power,x,y,z fit otherwise"
    );
    assert!(
        std::fs::read(p("zyx.ply")).unwrap() == bytes,
        "z,power,y,x fit otherwise"
    );
    let out = p("o.ply");
    for (name, header, says) in [
        ("zz.csv", "x,y,zz,power", "names no z column"),
        ("abc.csv", "a,b,c,power", "names no x, y or z column"),
        ("twice.csv", "x,y,z,X", "names x in columns 0 and 3"),
    ] {
        std::fs::write(p(name), format!("{header}\n{}", csv_rows("xyzv"))).unwrap();
        let e = fails(&["fit", s(&p(name)), "-o", s(&out), "-q"], &out);
        assert!(e.contains(name) && e.contains(says), "{name}: {e}");
        if name != "twice.csv" {
            assert!(e.contains(&header.replace(',', ", ")), "{name}: {e}");
        }
    }
}

/// Item 3: a column spelled almost `time` is read as a value, and a note says so (also
/// with -q); the summary says there is no time.
#[test]
fn a_time_column_spelled_almost_right_gets_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("tme.csv");
    std::fs::write(&csv, format!("x,y,z,tme,power\n{}", csv_rows("xyznv"))).unwrap();
    let out = dir.path().join("tme.ply");
    let o = ok(&[fit_args(s(&csv), s(&out)), vec!["-q"]].concat());
    let e = stderr(&o);
    assert!(
        e.contains("column 3 \"tme\" is read as a value (feat_0), not as the time")
            && e.contains("--time-column 3"),
        "{e}"
    );
    let o = ok(&[fit_args(s(&csv), s(&out)), vec!["--overwrite"]].concat());
    assert!(
        stderr(&o).contains("no time, feat_0 = column 3 \"tme\""),
        "{}",
        stderr(&o)
    );
    // Spelled right, it is the time.
    std::fs::write(&csv, format!("x,y,z,time,power\n{}", csv_rows("xyznv"))).unwrap();
    let o = ok(&[fit_args(s(&csv), s(&out)), vec!["--overwrite"]].concat());
    assert!(
        stderr(&o).contains("time = column 3 \"time\""),
        "{}",
        stderr(&o)
    );
}

/// Item 4: three samples (2 to train on, 1 held out) are refused with how many are
/// needed, unless forced.
#[test]
fn too_few_samples_are_refused_unless_forced() {
    assert_eq!(verisplat::fields::fit::min_samples(0.1), 45);
    assert_eq!(verisplat::fields::fit::min_samples(0.0), 20);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("three.csv");
    std::fs::write(&csv, "x,y,z,v\n0,0,0,1\n1,0,0,2\n0,1,0,3\n").unwrap();
    let out = dir.path().join("three.ply");
    let e = fails(&["fit", s(&csv), "-o", s(&out), "-q"], &out);
    assert!(
        e.contains("three.csv")
            && e.contains("holds 3 samples")
            && e.contains("at least 45 (40 to fit and 5 held out")
            && e.contains("--force"),
        "{e}"
    );
    let e = fails(
        &["fit", s(&csv), "-o", s(&out), "-q", "--holdout", "0"],
        &out,
    );
    assert!(e.contains("at least 20 to fit"), "{e}");
    ok(&[
        "fit",
        s(&csv),
        "-o",
        s(&out),
        "-q",
        "--force",
        "--steps",
        "5",
    ]);
    assert!(out.exists());
    // 44 samples are refused, 45 taken.
    let rows: Vec<String> = csv_rows("xyzv").lines().map(String::from).collect();
    let some = dir.path().join("some.csv");
    let out = dir.path().join("some.ply");
    std::fs::write(&some, rows[..44].join("\n")).unwrap();
    let e = fails(&["fit", s(&some), "-o", s(&out), "-q"], &out);
    assert!(e.contains("holds 44 samples"), "{e}");
    std::fs::write(&some, rows[..45].join("\n")).unwrap();
    ok(&["fit", s(&some), "-o", s(&out), "-q", "--steps", "5"]);
}

/// Item 6: `--look-at` places one camera at the eye looking at the target, up as given;
/// exported and read back it renders the same picture.
#[test]
fn look_at_is_one_camera_from_an_eye_to_a_target() {
    let dir = tempfile::tempdir().unwrap();
    let ply = field_ply(dir.path());
    let p = |n: &str| dir.path().join(n);
    let (cam_json, look_png, file_png) = (p("cam.json"), p("look.png"), p("file.png"));
    let view = "4,0,0,0,0,0,0,0,1";
    let common_args = [
        "--cpu",
        "--mode",
        "field-slice",
        "--slice-plane",
        "0,0,0,1,0,0",
        "--width",
        "64",
        "--height",
        "48",
        "-q",
    ];
    let mut a = vec![
        "render",
        s(&ply),
        "--look-at",
        view,
        "--export-cameras",
        s(&cam_json),
        "-o",
        s(&look_png),
    ];
    a.extend(common_args);
    ok(&a);
    let (cams, _) =
        verisplat::io::camera::load_camera_file(&p("cam.json"), &Default::default()).unwrap();
    assert_eq!(cams.len(), 1);
    let c = &cams[0];
    assert!(
        (c.position() - glam::Vec3::new(4.0, 0.0, 0.0)).length() < 1e-5,
        "{}",
        c.position()
    );
    // Rows of the world-to-camera rotation: right, down, forward.
    let forward = c.rotation.row(2);
    let down = c.rotation.row(1);
    assert!((forward - glam::Vec3::NEG_X).length() < 1e-5, "{forward}");
    assert!((down - glam::Vec3::NEG_Z).length() < 1e-5, "{down}");
    assert_eq!((c.width, c.height), (64, 48));
    let mut a = vec![
        "render",
        s(&ply),
        "--cameras",
        s(&cam_json),
        "-o",
        s(&file_png),
    ];
    a.extend(common_args);
    ok(&a);
    assert!(std::fs::read(p("look.png")).unwrap() == std::fs::read(p("file.png")).unwrap());
    let out = p("bad.png");
    for (value, says) in [
        (
            "1,1,1,1,1,1,0,0,1",
            "the eye and the target are the same point",
        ),
        ("0,0,4,0,0,0,0,0,1", "along the line of sight"),
        ("4,0,0,0,0,0", "9 numbers"),
    ] {
        let o = common::cli::verisplat(&["render", s(&ply), "--look-at", value, "-o", s(&out)]);
        let e = stderr(&o);
        assert!(
            !o.status.success() && e.contains(says) && !out.exists(),
            "{value}: {e}"
        );
    }
    let o = common::cli::verisplat(&[
        "render",
        s(&ply),
        "--look-at",
        view,
        "--orbit",
        "3",
        "-o",
        s(&out),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("cannot be used with"),
        "{}",
        stderr(&o)
    );
}

/// Item 6: the field renders of the RF walkthrough say their size (`--width`): at the
/// default 1280x720 a maximum took 74 s on a busy 2-core CPU device.
#[test]
fn the_walkthrough_field_renders_state_their_width() {
    let page =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/rf-fields.md"))
            .unwrap();
    let renders: Vec<&str> = page
        .lines()
        .filter(|l| l.starts_with("verisplat render") && l.contains("--mode field-max"))
        .collect();
    assert!(!renders.is_empty());
    for line in renders {
        assert!(line.contains("--width"), "{line}");
    }
}
