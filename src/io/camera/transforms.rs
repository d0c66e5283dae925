//! A nerfstudio / instant-ngp / NeRF-synthetic `transforms.json` as a camera file: a JSON
//! object whose `frames` list holds, per photo, `file_path` and a camera-to-world
//! `transform_matrix` (4x4, rows, OpenGL camera axes: x right, y up, z backwards), with
//! the intrinsics per frame or for the whole file (a frame's value wins):
//!
//! - `w`, `h`: the image size (without them, the size of the photo at `file_path`, `.png`
//!   added when it has no extension, as the trainer finds it);
//! - `fl_x`, `fl_y`, `cx`, `cy` in pixels, or `camera_angle_x` (and `camera_angle_y`), the
//!   full horizontal (vertical) field of view in radians; `fl_y` defaults to `fl_x`, the
//!   principal point to the image centre;
//! - `camera_model` and the distortion keys `k1..k4`, `p1`, `p2` (or instant-ngp's
//!   `is_fisheye`), as [`super::distortion::from_transforms`] reads them: `OPENCV` (and the
//!   pinhole and radial COLMAP names) is [`Lens::RadialTangential`] (the pinhole when every
//!   coefficient is zero), `OPENCV_FISHEYE` is [`Lens::Fisheye`], and `EQUIRECTANGULAR` is
//!   the whole sphere ([`Lens::FULL_SPHERE`], as nerfstudio's equirectangular camera; it
//!   needs no focal length).
//!
//! The matrices are taken as they are (the trainer reads the same files the same way), so
//! the cameras are those of the data set's world. Cameras are named by their photo's file
//! name.

use super::{
    camera_from_c2w, distortion, rotation_error, Camera, CameraError, Lens, MAX_IMAGE_SIDE,
};
use crate::core::file_error::FileError;
use glam::{DMat3, DVec3};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The photo of a frame whose `file_path` is `rel`, in the data set folder `dir`: `.png`
/// added when the path has no extension (NeRF-synthetic writes `./train/r_0`).
pub fn frame_photo(dir: &Path, rel: &str) -> PathBuf {
    let mut photo = dir.join(rel);
    if photo.extension().is_none() {
        photo.set_extension("png");
    }
    photo
}

/// The lens a `transforms.json` frame gives through `key` (the frame's value, else the
/// file's): `EQUIRECTANGULAR` (no distortion coefficient allowed), else
/// [`distortion::from_transforms`]'s model as a lens.
pub fn lens_from_transforms<'a>(key: &dyn Fn(&str) -> Option<&'a Value>) -> Result<Lens, String> {
    if key("camera_model").and_then(Value::as_str) == Some("EQUIRECTANGULAR") {
        let coefficient = ["k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2"]
            .into_iter()
            .find(|n| key(n).and_then(Value::as_f64).is_some_and(|v| v != 0.0));
        if let Some(n) = coefficient {
            return Err(format!(
                "\"{n}\" is not 0 but the EQUIRECTANGULAR camera model has no distortion; it cannot be ignored"
            ));
        }
        return Ok(Lens::FULL_SPHERE);
    }
    Ok(distortion::from_transforms(key)?.map_or(Lens::Pinhole, |d| Lens::from_distortion(&d)))
}

/// Parses a `transforms.json` held in memory (`path` names it in errors, and the photos
/// of frames without `w` and `h` are found beside it): one camera per frame.
pub fn parse_transforms(text: &str, path: &Path) -> Result<Vec<Camera>, CameraError> {
    let invalid = |message: String| {
        CameraError::File(FileError::Invalid {
            path: path.to_path_buf(),
            message,
        })
    };
    let doc: Value = serde_json::from_str(text)
        .map_err(|e| invalid(format!("is not a transforms.json: {e}")))?;
    let frames = doc
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| invalid("has no \"frames\" list".into()))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let num = |v: Option<&Value>| v.and_then(Value::as_f64);
    let gl_to_cv = DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
    let mut cams = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let bad = |what: String| invalid(format!("frame {i}: {what}"));
        let key = |k: &str| f.get(k).or_else(|| doc.get(k));
        let value = |k: &str| -> Result<Option<f64>, CameraError> {
            match key(k) {
                None | Some(Value::Null) => Ok(None),
                Some(v) => num(Some(v))
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| bad(format!("\"{k}\" is not a finite number"))),
            }
        };
        let file_path = f.get("file_path").and_then(Value::as_str);
        let name = file_path
            .and_then(|p| Path::new(p).file_name())
            .map_or_else(
                || format!("frame_{i}"),
                |n| n.to_string_lossy().into_owned(),
            );
        let m = f
            .get("transform_matrix")
            .and_then(Value::as_array)
            .filter(|rows| rows.len() == 3 || rows.len() == 4)
            .ok_or_else(|| bad("has no 4x4 \"transform_matrix\"".into()))?;
        let mut c2w = [[0f64; 4]; 3];
        for (r, row) in m.iter().take(3).enumerate() {
            let row = row
                .as_array()
                .filter(|row| row.len() == 4)
                .ok_or_else(|| bad("\"transform_matrix\" rows must have 4 numbers".into()))?;
            for (c, v) in row.iter().enumerate() {
                c2w[r][c] = num(Some(v))
                    .ok_or_else(|| bad("\"transform_matrix\" holds a non-number".into()))?;
            }
        }
        let c2w_gl =
            DMat3::from_cols_array_2d(&[0, 1, 2].map(|c| [c2w[0][c], c2w[1][c], c2w[2][c]]));
        let centre = DVec3::new(c2w[0][3], c2w[1][3], c2w[2][3]);
        let err = rotation_error(c2w_gl);
        if err >= 1e-3 || !centre.is_finite() {
            return Err(bad(format!(
                "\"transform_matrix\" is not a rigid transform (rotation part off by {err:.3e}, or non-finite values)"
            )));
        }
        let (width, height) = match (value("w")?, value("h")?) {
            (Some(w), Some(h)) => {
                let side = |v: f64, k: &str| {
                    (v >= 1.0 && v <= MAX_IMAGE_SIDE as f64 && v.fract() == 0.0)
                        .then_some(v as u32)
                        .ok_or_else(|| {
                            bad(format!(
                                "\"{k}\" {v} is not a whole number of pixels between 1 and {MAX_IMAGE_SIDE}"
                            ))
                        })
                };
                (side(w, "w")?, side(h, "h")?)
            }
            _ => {
                let rel = file_path.ok_or_else(|| {
                    bad("has no \"w\" and \"h\" and no \"file_path\" to take the size from".into())
                })?;
                let photo = frame_photo(dir, rel);
                image::image_dimensions(&photo).map_err(|e| {
                    bad(format!(
                        "has no \"w\" and \"h\", and its photo {} gives no size ({e})",
                        photo.display()
                    ))
                })?
            }
        };
        let lens = lens_from_transforms(&key).map_err(bad)?;
        let (w, h) = (width as f64, height as f64);
        let angle = |k: &str, side: f64| -> Result<Option<f64>, CameraError> {
            match value(k)? {
                Some(a) if a > 0.0 && a < std::f64::consts::PI => {
                    Ok(Some(side / (2.0 * (a / 2.0).tan())))
                }
                Some(a) => Err(bad(format!(
                    "\"{k}\" {a} is not an angle between 0 and pi radians"
                ))),
                None => Ok(None),
            }
        };
        let fx = match (value("fl_x")?, angle("camera_angle_x", w)?) {
            (Some(f), _) | (None, Some(f)) => f,
            // nerfstudio's equirectangular camera: fx = W / 2, fy = H.
            (None, None) if lens == Lens::FULL_SPHERE => w / 2.0,
            (None, None) => {
                return Err(bad(
                    "no \"fl_x\" or \"camera_angle_x\" gives the focal length".into(),
                ))
            }
        };
        let fy = match (value("fl_y")?, angle("camera_angle_y", h)?) {
            (Some(f), _) | (None, Some(f)) => f,
            (None, None) if lens == Lens::FULL_SPHERE && value("fl_x")?.is_none() => h,
            (None, None) => fx,
        };
        let cx = value("cx")?.unwrap_or(w / 2.0);
        let cy = value("cy")?.unwrap_or(h / 2.0);
        let mut cam = camera_from_c2w(
            name,
            width,
            height,
            [fx, fy],
            [cx, cy],
            c2w_gl * gl_to_cv,
            centre,
        );
        cam.lens = lens;
        cam.validate().map_err(|e| bad(e.to_string()))?;
        cams.push(cam);
    }
    Ok(cams)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(json: serde_json::Value) -> Result<Vec<Camera>, String> {
        parse_transforms(&json.to_string(), Path::new("t/transforms.json"))
            .map_err(|e| e.to_string())
    }

    const EYE: [[f64; 4]; 4] = [
        [1.0, 0.0, 0.0, 0.5],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ];

    #[test]
    fn transforms_cameras_carry_their_lens() {
        let cams = load(serde_json::json!({
            "w": 640, "h": 480, "fl_x": 300.0, "fl_y": 310.0, "cx": 322.0, "cy": 238.0,
            "camera_model": "OPENCV", "k1": -0.1, "k2": 0.02, "p1": 0.001, "p2": 0.0,
            "frames": [
                {"file_path": "images/a.jpg", "transform_matrix": EYE},
                {"file_path": "images/b.jpg", "transform_matrix": EYE,
                 "camera_model": "OPENCV_FISHEYE", "k1": 0.01, "k2": 0.0, "k3": 0.0, "k4": 0.0, "p1": 0.0},
                {"file_path": "images/c.jpg", "transform_matrix": EYE,
                 "camera_model": "EQUIRECTANGULAR", "k1": 0.0, "k2": 0.0, "p1": 0.0,
                 "fl_x": null, "fl_y": null, "w": 2048, "h": 1024, "cx": null, "cy": null},
            ]
        }))
        .unwrap();
        assert_eq!(
            cams[0].lens,
            Lens::RadialTangential {
                radial: [-0.1, 0.02, 0.0, 0.0, 0.0, 0.0],
                tangential: [0.001, 0.0]
            }
        );
        assert_eq!((cams[0].fx, cams[0].fy, cams[0].cx), (300.0, 310.0, 322.0));
        assert_eq!(cams[0].name, "a.jpg");
        // OpenGL axes: the camera at (0.5, 0, 3) looks along -z of the world.
        assert!((cams[0].position() - glam::Vec3::new(0.5, 0.0, 3.0)).length() < 1e-6);
        assert!((cams[0].rotation.row(2) - glam::Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        assert!(matches!(cams[1].lens, Lens::Fisheye { k, .. } if k == [0.01, 0.0, 0.0, 0.0]));
        assert_eq!(cams[2].lens, Lens::FULL_SPHERE);
        assert_eq!(
            (cams[2].width, cams[2].fx, cams[2].fy),
            (2048, 1024.0, 1024.0)
        );
    }

    #[test]
    fn the_trainers_models_and_the_whole_sphere() {
        let json = serde_json::json!({"camera_model": "EQUIRECTANGULAR"});
        let key = |k: &str| json.get(k);
        assert_eq!(lens_from_transforms(&key), Ok(Lens::FULL_SPHERE));
        let json = serde_json::json!({"camera_model": "OPENCV_FISHEYE", "k1": 0.1});
        let key = |k: &str| json.get(k);
        assert!(matches!(
            lens_from_transforms(&key),
            Ok(Lens::Fisheye { k, .. }) if k == [0.1, 0.0, 0.0, 0.0]
        ));
        let json = serde_json::json!({"k1": 0.0, "p2": 0.0});
        let key = |k: &str| json.get(k);
        assert_eq!(lens_from_transforms(&key), Ok(Lens::Pinhole));
    }

    #[test]
    fn transforms_refusals_name_the_frame() {
        let e = load(serde_json::json!({"w": 64, "h": 48, "frames": [{"transform_matrix": EYE}]}))
            .unwrap_err();
        assert!(e.contains("frame 0") && e.contains("fl_x"), "{e}");
        let e = load(serde_json::json!({"w": 64, "h": 48, "fl_x": 50,
            "camera_model": "EQUIRECTANGULAR", "k1": 0.1, "frames": [{"transform_matrix": EYE}]}))
        .unwrap_err();
        assert!(e.contains("\"k1\"") && e.contains("EQUIRECTANGULAR"), "{e}");
        let e = load(serde_json::json!({"w": 64, "h": 48, "fl_x": 50,
            "camera_model": "FOV", "frames": [{"transform_matrix": EYE}]}))
        .unwrap_err();
        assert!(
            e.contains("\"FOV\"") && e.contains("transforms.json"),
            "{e}"
        );
        let e = load(serde_json::json!({"fl_x": 50, "frames": [{"file_path": "nowhere/x", "transform_matrix": EYE}]}))
            .unwrap_err();
        assert!(e.contains("x.png") && e.contains("gives no size"), "{e}");
    }
}
