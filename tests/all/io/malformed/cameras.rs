//! Camera-file cases: builders for INRIA cameras.json, nerfstudio paths, keyframe paths
//! and COLMAP models (text and binary), and their cases.

use super::case::{camera_case, colmap_case, colmap_model_case, Case, Expect, Kind};

// Cameras.

pub(super) fn inria_json(width: i64, fx: &str, rotation: &str) -> String {
    format!(
        r#"[{{"id":0,"img_name":"a","width":{width},"height":48,"position":[0,0,-3],"rotation":{rotation},"fx":{fx},"fy":50}}]"#
    )
}

pub(super) const IDENTITY: &str = "[[1,0,0],[0,1,0],[0,0,1]]";

pub(super) fn nerfstudio(camera_type: &str, c2w: &str, fov: &str) -> String {
    format!(
        r#"{{"camera_type":"{camera_type}","render_width":64,"render_height":48,"camera_path":[{{"camera_to_world":{c2w},"fov":{fov}}}]}}"#
    )
}

pub(super) const C2W: &str = "[1,0,0,0, 0,1,0,0, 0,0,1,3, 0,0,0,1]";

pub(super) fn keyframes(version: u32, frames: &str, keys: &str) -> String {
    format!(r#"{{"version":{version},"width":64,"height":48{frames},"keyframes":[{keys}]}}"#)
}

pub(super) const KEY0: &str = r#"{"time":0,"position":[0,0,-3],"look_at":[0,0,0],"vfov":50}"#;
pub(super) const KEY1: &str = r#"{"time":1,"position":[1,0,-3],"look_at":[0,0,0],"vfov":50}"#;

pub(super) const COLMAP_CAMS: &str = "1 PINHOLE 64 48 50 50 32 24\n";
pub(super) const COLMAP_IMAGES: &str = "1 1 0 0 0 0 0 3 1 a.png\n\n";

/// COLMAP binary files: one camera of `model_id` with `params`, and one image of camera 1
/// with quaternion `q` and `points` claimed 2D points (none stored).
pub(super) fn colmap_bin(
    cam_count: u64,
    model_id: i32,
    params: &[f64],
    q: [f64; 4],
    points: u64,
) -> (Vec<u8>, Vec<u8>) {
    let mut c = Vec::new();
    c.extend_from_slice(&cam_count.to_le_bytes());
    c.extend_from_slice(&1i32.to_le_bytes());
    c.extend_from_slice(&model_id.to_le_bytes());
    c.extend_from_slice(&64u64.to_le_bytes());
    c.extend_from_slice(&48u64.to_le_bytes());
    for p in params {
        c.extend_from_slice(&p.to_le_bytes());
    }
    let mut i = Vec::new();
    i.extend_from_slice(&1u64.to_le_bytes());
    i.extend_from_slice(&1i32.to_le_bytes());
    for v in q.iter().chain(&[0.0, 0.0, 3.0]) {
        i.extend_from_slice(&v.to_le_bytes());
    }
    i.extend_from_slice(&1i32.to_le_bytes());
    i.extend_from_slice(b"a.png\0");
    i.extend_from_slice(&points.to_le_bytes());
    (c, i)
}

pub(super) const PINHOLE: [f64; 4] = [50.0, 50.0, 32.0, 24.0];

/// The table's cases for INRIA cameras.json.
pub(super) fn inria_camera_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    vec![
        camera_case(
            "cams_not_json",
            "cameras.json",
            "[{\"id\": 0,",
            Error("not valid JSON"),
        ),
        camera_case(
            "cams_empty_list",
            "cameras.json",
            "[]",
            Error("holds no cameras (INRIA cameras.json)"),
        ),
        camera_case(
            "cams_missing_fx",
            "cameras.json",
            &inria_json(64, "50", IDENTITY).replace("\"fx\":50,", ""),
            Error("missing field `fx`"),
        ),
        camera_case(
            "cams_zero_width",
            "cameras.json",
            &inria_json(0, "50", IDENTITY),
            Error("resolution 0x48 is not usable"),
        ),
        camera_case(
            "cams_negative_width",
            "cameras.json",
            &inria_json(-64, "50", IDENTITY),
            Error("is not an INRIA cameras.json"),
        ),
        camera_case(
            "cams_huge_width",
            "cameras.json",
            &inria_json(1 << 40, "50", IDENTITY),
            Error("is not an INRIA cameras.json"),
        ),
        camera_case(
            "cams_zero_fx",
            "cameras.json",
            &inria_json(64, "0", IDENTITY),
            Error("non-finite or non-positive intrinsics"),
        ),
        camera_case(
            "cams_fx_overflows",
            "cameras.json",
            &inria_json(64, "1e39", IDENTITY),
            Error("non-finite or non-positive intrinsics"),
        ),
        camera_case(
            "cams_fx_out_of_json_range",
            "cameras.json",
            &inria_json(64, "1e999", IDENTITY),
            Error("not valid JSON"),
        ),
        camera_case(
            "cams_singular_rotation",
            "cameras.json",
            &inria_json(64, "50", "[[1,0,0],[0,1,0],[0,0,0]]"),
            Error("rotation is not a rotation matrix (determinant 0.0000)"),
        ),
        camera_case(
            "cams_denormal_position",
            "cameras.json",
            &inria_json(64, "50", IDENTITY).replace("[0,0,-3]", "[4.9e-324,0,-3]"),
            Renders(1),
        ),
    ]
}

/// The table's cases for nerfstudio camera_path.json.
pub(super) fn nerfstudio_camera_cases() -> Vec<Case> {
    use Expect::Error;
    vec![
        camera_case(
            "ns_fisheye",
            "camera_path.json",
            &nerfstudio("fisheye", C2W, "50"),
            Expect::Renders(1),
        ),
        camera_case(
            "ns_vr180",
            "camera_path.json",
            &nerfstudio("vr180", C2W, "50"),
            Error("camera_type \"vr180\" is not supported; it must be"),
        ),
        camera_case(
            "ns_fifteen_numbers",
            "camera_path.json",
            &nerfstudio("perspective", "[1,0,0,0, 0,1,0,0, 0,0,1,3, 0,0,0]", "50"),
            Error("camera_to_world has 15 numbers"),
        ),
        camera_case(
            "ns_not_rigid",
            "camera_path.json",
            &nerfstudio("perspective", "[2,0,0,0, 0,1,0,0, 0,0,1,3, 0,0,0,1]", "50"),
            Error("is not a rigid transform"),
        ),
        camera_case(
            "ns_zero_fov",
            "camera_path.json",
            &nerfstudio("perspective", C2W, "0"),
            Error("fov 0 degrees must be between 0 and 180"),
        ),
        camera_case(
            "ns_no_fov",
            "camera_path.json",
            &nerfstudio("perspective", C2W, "null"),
            Error("has no \"fov\""),
        ),
        camera_case(
            "ns_zero_resolution",
            "camera_path.json",
            &nerfstudio("perspective", C2W, "50")
                .replace("\"render_width\":64", "\"render_width\":0"),
            Error("resolution 0x48 is not usable"),
        ),
        camera_case(
            "ns_empty_path",
            "camera_path.json",
            r#"{"render_width":64,"render_height":48,"camera_path":[]}"#,
            Error("holds no cameras"),
        ),
    ]
}

/// The table's cases for keyframe paths.
pub(super) fn keyframe_path_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    vec![
        camera_case(
            "kf_version_2",
            "path.json",
            &keyframes(2, "", KEY0),
            Error("keyframe path version 2 is not supported"),
        ),
        camera_case(
            "kf_no_keyframes",
            "path.json",
            &keyframes(1, "", ""),
            Error("has no keyframes"),
        ),
        camera_case(
            "kf_times_not_increasing",
            "path.json",
            &keyframes(1, "", &format!("{KEY1},{KEY0}")),
            Error("keyframe times must be strictly increasing"),
        ),
        camera_case(
            "kf_zero_rotation",
            "path.json",
            &keyframes(
                1,
                "",
                r#"{"time":0,"position":[0,0,-3],"rotation":[0,0,0,0],"vfov":50}"#,
            ),
            Error("rotation [0.0, 0.0, 0.0, 0.0] has zero length"),
        ),
        camera_case(
            "kf_look_at_itself",
            "path.json",
            &keyframes(
                1,
                "",
                r#"{"time":0,"position":[0,0,-3],"look_at":[0,0,-3],"vfov":50}"#,
            ),
            Error("look_at is the camera position itself"),
        ),
        camera_case(
            "kf_frames_2_pow_40",
            "path.json",
            &keyframes(1, ",\"frames\":1099511627776", KEY0),
            Error("frames 1099511627776 must be between 1 and 1000000"),
        ),
        camera_case(
            "kf_frames_zero",
            "path.json",
            &keyframes(1, ",\"frames\":0", KEY0),
            Error("frames 0 must be between 1 and 1000000"),
        ),
        camera_case(
            "kf_fps_negative",
            "path.json",
            &keyframes(1, ",\"fps\":-30", KEY0),
            Error("fps -30 must be a positive number"),
        ),
        camera_case(
            "kf_too_long",
            "path.json",
            &keyframes(
                1,
                ",\"fps\":1e9",
                &format!("{KEY0},{}", KEY1.replace("\"time\":1", "\"time\":1e9")),
            ),
            Error("more than 1000000 frames"),
        ),
        camera_case(
            "kf_unknown_field",
            "path.json",
            &keyframes(1, ",\"speed\":3", KEY0),
            Error("unknown field `speed`"),
        ),
        camera_case(
            "kf_two_frames",
            "path.json",
            &keyframes(1, ",\"frames\":2", &format!("{KEY0},{KEY1}")),
            Renders(2),
        ),
    ]
}

/// The table's cases for COLMAP text.
pub(super) fn colmap_text_cases() -> Vec<Case> {
    vec![
        colmap_case(
            "colmap_unknown_model",
            b"1 PINHOLEX 64 48 50 50 32 24\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "unknown camera model \"PINHOLEX\"",
        ),
        colmap_model_case(
            "colmap_fisheye",
            b"1 OPENCV_FISHEYE 64 48 50 50 32 24 0 0 0 0\n".to_vec(),
            COLMAP_IMAGES.into(),
            Expect::Renders(1),
        ),
        colmap_model_case(
            "colmap_distortion",
            b"1 SIMPLE_RADIAL 64 48 50 32 24 0.1\n".to_vec(),
            COLMAP_IMAGES.into(),
            Expect::Renders(1),
        ),
        colmap_case(
            "colmap_thin_prism",
            b"1 THIN_PRISM_FISHEYE 64 48 50 50 32 24 0.1 0 0 0 0 0 0 0\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "camera 1: the THIN_PRISM_FISHEYE model is not supported",
        ),
        colmap_case(
            "colmap_fov",
            b"1 FOV 64 48 50 50 32 24 0.5\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "camera 1: the FOV model is not supported",
        ),
        colmap_case(
            "colmap_too_few_params",
            b"1 PINHOLE 64 48 50 50 32\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "model PINHOLE takes 4 parameters, the line has 3",
        ),
        colmap_case(
            "colmap_width_2_pow_40",
            b"1 PINHOLE 1099511627776 48 50 50 32 24\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "resolution 1099511627776x48 is not usable",
        ),
        colmap_case(
            "colmap_nan_focal",
            b"1 PINHOLE 64 48 nan 50 32 24\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "non-finite or non-positive intrinsics",
        ),
        colmap_case(
            "colmap_zero_quaternion",
            COLMAP_CAMS.into(),
            b"1 0 0 0 0 0 0 3 1 a.png\n\n".to_vec(),
            false,
            "quaternion [0.0, 0.0, 0.0, 0.0] has zero length",
        ),
        colmap_case(
            "colmap_inf_translation",
            COLMAP_CAMS.into(),
            b"1 1 0 0 0 inf 0 3 1 a.png\n\n".to_vec(),
            false,
            "translation [inf, 0.0, 3.0] is not finite",
        ),
        colmap_case(
            "colmap_missing_camera",
            COLMAP_CAMS.into(),
            b"1 1 0 0 0 0 0 3 9 a.png\n\n".to_vec(),
            false,
            "refers to camera 9, which the cameras file does not have",
        ),
        colmap_case(
            "colmap_short_image_line",
            COLMAP_CAMS.into(),
            b"1 1 0 0 0 0 0 3\n\n".to_vec(),
            false,
            "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
        ),
        colmap_case(
            "colmap_no_images",
            COLMAP_CAMS.into(),
            b"# nothing\n".to_vec(),
            false,
            "holds no cameras",
        ),
    ]
}

/// The table's cases for COLMAP binary.
pub(super) fn colmap_binary_cases() -> Vec<Case> {
    vec![
        {
            let (c, i) = colmap_bin(1 << 40, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_camera_count_2_pow_40",
                c,
                i,
                true,
                "claims 1099511627776 cameras",
            )
        },
        {
            let (c, i) = colmap_bin(1, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 1 << 40);
            colmap_case(
                "colmap_bin_points_2_pow_40",
                c,
                i,
                true,
                "claims 1099511627776 2D points",
            )
        },
        {
            let (c, i) = colmap_bin(1, 42, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_unknown_model",
                c,
                i,
                true,
                "unknown camera model id 42",
            )
        },
        {
            let (c, i) = colmap_bin(1, 1, &PINHOLE[..3], [1.0, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_truncated_params",
                c,
                i,
                true,
                "truncated: needs 8 bytes for the camera parameter",
            )
        },
        {
            let (c, i) = colmap_bin(1, 1, &PINHOLE, [f64::NAN, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_nan_quaternion",
                c,
                i,
                true,
                "has zero length or is not finite",
            )
        },
        {
            let (c, mut i) = colmap_bin(1, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
            i.extend_from_slice(&[1, 2, 3]);
            colmap_case(
                "colmap_bin_trailing_bytes",
                c,
                i,
                true,
                "has 3 unexpected bytes after the last record",
            )
        },
    ]
}

/// A COLMAP model that is fine renders.
pub(super) fn colmap_ok() -> Case {
    use Expect::Renders;
    Case {
        name: "colmap_ok",
        kind: Kind::Cameras,
        files: vec![
            ("model/cameras.txt", COLMAP_CAMS.into()),
            ("model/images.txt", COLMAP_IMAGES.into()),
        ],
        arg: "model",
        expect: Renders(1),
    }
}
