//! Keyframe paths: front views, timing, exact round trips at the keyframes, smooth
//! interpolation between them, and malformed keyframe files.

use super::{
    assert_front_view, assert_mat_close, assert_same_camera, assert_vec_close, assorted_cameras,
    fixtures, front_camera, load, load_err, project, write,
};
use glam::{Mat3, Vec2, Vec3};
use std::path::Path;
use verisplat::core::camera::{orbit, Camera, CameraError, OrbitParams};
use verisplat::io::camera::{
    keyframes_to_json, load_camera_file, CameraFormat, KeyframePath, PathTiming,
};

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
