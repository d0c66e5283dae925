//! What a real capture brings out in `train` and `render`: outputs at an iteration where
//! the schedule also changes the model, the iteration lists as train.py spells them,
//! progress in a log, cameras picked by name, and an orbit of a model whose world is not
//! y-down.

use crate::common::dataset::make_dataset;
use crate::common::{self, cli::verisplat};
use std::path::Path;
use verisplat::core::camera::orbit::{orbit, OrbitParams};

fn text(out: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// The largest opacity of the model saved at `iteration`.
fn max_opacity(model: &Path, iteration: u32) -> f32 {
    let ply = model.join(format!("point_cloud/iteration_{iteration}/point_cloud.ply"));
    let scene = verisplat::io::scene::load_with_format(&ply)
        .expect("the saved model")
        .0;
    scene
        .opacity_logits
        .iter()
        .map(|&l| verisplat::core::scene::sigmoid(l))
        .fold(0.0, f32::max)
}

/// The original saves and evaluates before it densifies or resets the opacities, so the
/// model saved at an opacity-reset iteration is the trained one, not the reset one; its
/// checkpoint is the state after the iteration (what a resumed run continues from, bit
/// for bit). Without a terminal, progress comes as plain lines.
#[test]
fn a_save_at_an_opacity_reset_is_the_model_before_the_reset() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    make_dataset(&data, 10, 48, 36);
    let run = |out: &str, extra: &[&str]| {
        let model = dir.path().join(out);
        let mut args = vec![
            "train",
            data.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--eval",
            "--iterations",
            "60",
            "--save-iterations",
            "40,60",
            "--test-iterations",
            "40,60",
            "--densify-from-iter",
            "500",
            "--densify-until-iter",
            "1000",
            "--opacity-reset-interval",
            "40",
            "--sh-degree",
            "0",
        ];
        args.extend(extra);
        let out = verisplat(&args);
        assert!(out.status.success(), "{}", text(&out));
        (text(&out), model)
    };
    let (log, a) = run("a", &["--checkpoint-iterations", "40"]);
    // The start is 0.1; a reset would leave every opacity at 0.01 or below.
    let saved = max_opacity(&a, 40);
    assert!(
        saved > 0.05,
        "the model saved at 40 is the reset one: {saved}"
    );
    // The evaluation at 40 is of the trained model too: not far below the one at 60.
    let psnr = |it: u32| -> f64 {
        let tag = format!("[ITER {it}] evaluating test");
        let line = log.lines().find(|l| l.contains(&tag)).expect(&tag);
        line.split("PSNR ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!(psnr(40) > psnr(60) - 3.0, "{log}");
    // Progress as lines: every 5 % of 60 iterations is every third one.
    let lines = log.lines().filter(|l| l.starts_with("iteration ")).count();
    assert!(lines >= 20, "{lines} progress lines:\n{log}");
    assert!(log.contains("iteration 60/60 (100 %)"), "{log}");
    // The checkpoint at 40 holds the reset state, so resuming from it gives the same bytes.
    let chk = a.join("chkpnt40.safetensors");
    let (_, b) = run("b", &["--resume", chk.to_str().unwrap(), "-q"]);
    let ply = "point_cloud/iteration_60/point_cloud.ply";
    assert!(
        std::fs::read(a.join(ply)).unwrap() == std::fs::read(b.join(ply)).unwrap(),
        "the run resumed from the checkpoint at the reset differs"
    );
}

/// A trained model directory whose cameras (named 0001, 0002, ...) circle (1, 2, 3) with
/// z up, holding the shared LOD6 scene.
fn z_up_model(dir: &Path) -> std::path::PathBuf {
    let model = dir.join("model");
    let iteration = model.join("point_cloud/iteration_7");
    std::fs::create_dir_all(&iteration).unwrap();
    std::fs::copy(
        common::shared_data().join("playbot_lod6_1873_sh2.ply"),
        iteration.join("point_cloud.ply"),
    )
    .unwrap();
    let params = OrbitParams {
        frames: 12,
        up: glam::Vec3::Z,
        centre: Some(glam::Vec3::new(1.0, 2.0, 3.0)),
        radius: Some(5.0),
        elevation_deg: 30.0,
        width: 40,
        height: 30,
        ..Default::default()
    };
    let cams: Vec<(usize, verisplat::core::camera::Camera)> = orbit(&[], &params)
        .unwrap()
        .into_iter()
        .enumerate()
        .map(|(i, mut c)| {
            c.name = format!("{:04}", i + 1);
            (i, c)
        })
        .collect();
    std::fs::write(
        model.join("cameras.json"),
        verisplat::io::camera::inria::to_json(&cams).unwrap(),
    )
    .unwrap();
    model
}

/// `--camera 0002` picks the camera named 0002 (index 1), `#2` index 2, and the summary
/// says which was picked; `--orbit` of a model takes its up and centre from the model's
/// cameras unless told otherwise.
#[test]
fn cameras_by_name_and_an_orbit_in_the_model_s_frame() {
    let dir = tempfile::tempdir().unwrap();
    let model = z_up_model(dir.path());
    let m = model.to_str().unwrap();
    let exported = |args: &[&str], name: &str| {
        let json = dir.path().join(format!("{name}.json"));
        let out_dir = format!("{}/", dir.path().join(name).display());
        let mut all = vec!["render", m];
        all.extend(args);
        all.extend(["-o", &out_dir, "--export-cameras"]);
        all.push(json.to_str().unwrap());
        let out = verisplat(&all);
        assert!(out.status.success(), "{}", text(&out));
        let cams = verisplat::io::camera::inria::load_cameras_json(&json).unwrap();
        (cams, text(&out))
    };
    let (cams, log) = exported(&["--camera", "0002"], "by_name");
    assert_eq!(cams.len(), 1);
    assert_eq!(cams[0].name, "0002");
    assert!(log.contains("--camera 0002: \"0002\" (index 1)"), "{log}");
    let (cams, _) = exported(&["--camera", "#2"], "by_index");
    assert_eq!(cams[0].name, "0003");
    // The orbit: z up around (1, 2, 3), from the model's cameras, with a note.
    let (cams, log) = exported(
        &["--orbit", "6", "--width", "40", "--height", "30"],
        "orbit",
    );
    assert!(log.contains("from the model's 12 cameras"), "{log}");
    let (up, centre) = verisplat::core::camera::up_and_centre_of(&cams);
    assert!(up.unwrap().abs_diff_eq(glam::Vec3::Z, 1e-3), "{up:?}");
    assert!(
        centre
            .unwrap()
            .abs_diff_eq(glam::Vec3::new(1.0, 2.0, 3.0), 1e-2),
        "{centre:?}"
    );
    // Asked for, -y and the scene's centre win.
    let (cams, _) = exported(
        &[
            "--orbit",
            "6",
            "--width",
            "40",
            "--height",
            "30",
            "--orbit-up",
            "0,-1,0",
        ],
        "orbit_y",
    );
    let (up, _) = verisplat::core::camera::up_and_centre_of(&cams);
    assert!(up.unwrap().abs_diff_eq(glam::Vec3::NEG_Y, 1e-3), "{up:?}");
}

/// The data set the training tests make reads back: cameras, points, the held-out split
/// and the downscaled photos.
#[test]
fn a_colmap_text_model_reads_back_as_written() {
    let dir = tempfile::tempdir().unwrap();
    make_dataset(dir.path(), 5, 40, 30);
    let (cams, _) = verisplat::io::camera::colmap::load_colmap_model(dir.path()).unwrap();
    assert_eq!(cams.len(), 5);
    let points = verisplat::io::camera::colmap::load_colmap_points(dir.path())
        .unwrap()
        .unwrap();
    assert_eq!(points.len(), 1873_usize.div_ceil(2));
    let data = verisplat::train::data::load_colmap(
        dir.path(),
        verisplat::train::data::Resolution(2),
        true,
    )
    .unwrap();
    // Every 8th (the first of 5) is held out; photos halved with the cameras.
    assert_eq!((data.train.len(), data.test.len()), (4, 1));
    let v = &data.train[0];
    assert_eq!((v.camera.width, v.camera.height), (20, 15));
    assert_eq!(v.image.len(), 20 * 15);
    assert!(data.extent > 0.0);
}

/// The iteration lists take the original train.py's spelling, `--test-iterations 2 4`
/// (space-separated, as `--help` shows the default), as well as `2,4` (issue 59, item 8).
#[test]
fn iteration_lists_are_space_or_comma_separated() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    make_dataset(&data, 4, 32, 24);
    let train = |model: &Path, lists: &[&str]| {
        let mut args = vec![
            "train",
            data.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--eval",
            "--iterations",
            "4",
            "--sh-degree",
            "0",
        ];
        args.extend_from_slice(lists);
        let o = verisplat(&args);
        let log = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(o.status.success(), "{args:?}: {log}");
        log
    };
    let spaces: &[&str] = &[
        "--test-iterations",
        "2",
        "3",
        "--save-iterations",
        "2",
        "3",
        "--checkpoint-iterations",
        "1",
        "3",
    ];
    let commas: &[&str] = &[
        "--test-iterations",
        "2,3",
        "--save-iterations",
        "2,3",
        "--checkpoint-iterations",
        "1,3",
    ];
    for (name, lists) in [("spaces", spaces), ("commas", commas)] {
        let model = dir.path().join(name);
        let log = train(&model, lists);
        for it in [2, 3] {
            assert!(
                log.contains(&format!("[ITER {it}] evaluating test")),
                "{name}: no evaluation at {it}: {log}"
            );
            let ply = model.join(format!("point_cloud/iteration_{it}/point_cloud.ply"));
            assert!(ply.is_file(), "{name}: {} missing", ply.display());
        }
        for it in [1, 3] {
            let chk = model.join(format!("chkpnt{it}.safetensors"));
            assert!(chk.is_file(), "{name}: {} missing", chk.display());
        }
    }
}
