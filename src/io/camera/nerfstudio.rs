//! nerfstudio `camera_path.json`, as its viewer exports it for `ns-render camera-path`:
//! top-level `render_width`, `render_height` (and `fps`, `seconds`, which only say how
//! the frames were made), optional `camera_type`, and `camera_path`, one entry per frame
//! with `camera_to_world` (16 numbers, a row-major 4x4) and `fov` (vertical, degrees).
//!
//! `camera_type` is read as nerfstudio's `get_path_from_json` reads it:
//! - `"perspective"` (or none): the pinhole, focal length `H / (2 tan(fov / 2))`;
//! - `"fisheye"`: nerfstudio's fisheye, equidistant without distortion, with the same
//!   focal length as the perspective camera of that `fov` (so the `fov` is not the
//!   fisheye's field of view: the top edge sees `tan(fov / 2)` radians off the axis), and
//!   every ray up to 180 degrees from the axis imaged;
//! - `"equirectangular"`: the whole sphere across the image (the `fov` is not used).
//!
//! `camera_to_world` uses OpenGL camera axes (x right, y up, z backwards); ours are
//! OpenCV (x right, y down, z forward), so the camera's y and z axes are negated. The
//! matrices are taken as they are, in the world frame of the file. nerfstudio's world
//! for a scene trained from COLMAP data is not COLMAP's (its dataparser applies an
//! orientation/centring transform and a scale), so a path exported from nerfstudio for
//! such a scene only lines up with a 3DGS model trained on the same transformed data;
//! for a scene in INRIA/COLMAP coordinates, make the path in that frame (see
//! `docs/cameras.md`).

use super::{camera_from_c2w, check_resolution, rotation_error, Camera, CameraError, Lens};
use crate::core::file_error::FileError;
use glam::{DMat3, DVec3};
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize)]
struct PathFile {
    render_width: u32,
    render_height: u32,
    #[serde(default)]
    camera_type: Option<String>,
    #[serde(default)]
    default_fov: Option<f64>,
    camera_path: Vec<PathEntry>,
}

#[derive(Deserialize)]
struct PathEntry {
    camera_to_world: Vec<f64>,
    #[serde(default)]
    fov: Option<f64>,
}

/// The `camera_type`s nerfstudio renders a path with that verisplat reads.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Perspective,
    Fisheye,
    Equirectangular,
}

impl Kind {
    /// The lens: nerfstudio's fisheye images rays up to 180 degrees from the axis.
    fn lens(self) -> Lens {
        match self {
            Kind::Perspective => Lens::Pinhole,
            Kind::Fisheye => Lens::Fisheye {
                k: [0.0; 4],
                max_theta: std::f64::consts::PI,
            },
            Kind::Equirectangular => Lens::FULL_SPHERE,
        }
    }

    /// Its `camera_type`, and the kind of `lens` (`None`: nerfstudio has no such camera).
    fn of(lens: &Lens) -> Option<(Kind, &'static str)> {
        [
            (Kind::Perspective, "perspective"),
            (Kind::Fisheye, "fisheye"),
            (Kind::Equirectangular, "equirectangular"),
        ]
        .into_iter()
        .find(|(k, _)| k.lens() == *lens)
    }
}

/// Parses a nerfstudio camera path held in memory (`path` names it in errors): one
/// camera per entry, named `path_00000`, `path_00001`, ...
pub fn parse_camera_path(text: &str, path: &Path) -> Result<Vec<Camera>, CameraError> {
    let invalid = |message: String| {
        CameraError::File(FileError::Invalid {
            path: path.to_path_buf(),
            message,
        })
    };
    let file: PathFile = serde_json::from_str(text).map_err(|e| {
        invalid(format!(
            "is not a nerfstudio camera path (render_width, render_height, camera_path: \
             [{{camera_to_world, fov}}]): {e}"
        ))
    })?;
    let kind = match file.camera_type.as_deref() {
        None | Some("perspective") => Kind::Perspective,
        Some("fisheye") => Kind::Fisheye,
        Some("equirectangular") => Kind::Equirectangular,
        Some(other) => {
            return Err(invalid(format!(
                "camera_type \"{other}\" is not supported; it must be \"perspective\", \"fisheye\" or \"equirectangular\""
            )))
        }
    };
    let (width, height) = (file.render_width, file.render_height);
    check_resolution(width, height).map_err(|e| invalid(e.to_string()))?;
    // OpenGL camera axes to OpenCV: negate the camera's y and z columns.
    let gl_to_cv = DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
    let mut cams = Vec::with_capacity(file.camera_path.len());
    for (i, e) in file.camera_path.iter().enumerate() {
        let bad = |what: String| invalid(format!("camera_path[{i}]: {what}"));
        let m: [f64; 16] = e.camera_to_world.as_slice().try_into().map_err(|_| {
            bad(format!(
                "camera_to_world has {} numbers; it must be a 4x4 matrix (16 numbers, row-major)",
                e.camera_to_world.len()
            ))
        })?;
        // Row-major: element (r, c) is m[4 r + c].
        let c2w_gl =
            DMat3::from_cols_array(&[m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]]);
        let centre = DVec3::new(m[3], m[7], m[11]);
        let err = rotation_error(c2w_gl);
        // rotation_error is infinite for non-finite input.
        if err >= 1e-3 || !centre.is_finite() {
            return Err(bad(format!(
                "camera_to_world is not a rigid transform (rotation part off by {err:.3e}, or \
                 non-finite values)"
            )));
        }
        // nerfstudio: an equirectangular camera has fx = W / 2, fy = H (its lens spans the
        // image whatever they are); the others focal = H / (2 tan(fov/2)), square pixels.
        // The principal point is the centre.
        let focal = if kind == Kind::Equirectangular {
            [width as f64 / 2.0, height as f64]
        } else {
            let fov = e
                .fov
                .or(file.default_fov)
                .ok_or_else(|| bad("has no \"fov\" (and the file no \"default_fov\")".into()))?;
            if !(fov.is_finite() && fov > 0.0 && fov < 180.0) {
                return Err(bad(format!("fov {fov} degrees must be between 0 and 180")));
            }
            let f = height as f64 / (2.0 * (fov.to_radians() * 0.5).tan());
            [f, f]
        };
        let mut cam = camera_from_c2w(
            format!("path_{i:05}"),
            width,
            height,
            focal,
            [width as f64 / 2.0, height as f64 / 2.0],
            c2w_gl * gl_to_cv,
            centre,
        );
        cam.lens = kind.lens();
        cam.validate().map_err(|e| bad(e.to_string()))?;
        cams.push(cam);
    }
    Ok(cams)
}

/// Writes `cams` as a nerfstudio camera path, one entry per camera (the frames, as
/// `ns-render camera-path` renders them), which [`parse_camera_path`] reads back as the
/// same poses. nerfstudio cameras have square pixels and a centred principal point, so
/// each camera's `fy` is kept (as the vertical `fov`) and `fx`, `cx`, `cy` are not; the
/// cameras must share a resolution and a lens that is a nerfstudio `camera_type` (the
/// pinhole, the undistorted 360-degree fisheye, the whole-sphere equirectangular).
pub fn to_camera_path_json(cams: &[Camera], fps: f64) -> Result<String, CameraError> {
    let bad = |m: String| Err(CameraError::BadParameter(m));
    let Some(first) = cams.first() else {
        return bad("a camera path needs at least one camera".into());
    };
    if !(fps.is_finite() && fps > 0.0) {
        return bad(format!("fps {fps} must be a positive number"));
    }
    let Some((_, camera_type)) = Kind::of(&first.lens) else {
        return bad(format!(
            "camera \"{}\" has a lens ({}) that nerfstudio has no camera_type for (perspective, fisheye of 360 degrees without distortion, equirectangular of the whole sphere)",
            first.name,
            first.lens.name()
        ));
    };
    let gl_to_cv = DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
    let mut entries = Vec::with_capacity(cams.len());
    for c in cams {
        c.validate()?;
        if c.lens != first.lens {
            return bad(format!(
                "camera \"{}\" has another lens ({}) than the first ({}); a camera path has one camera_type",
                c.name,
                c.lens.name(),
                first.lens.name()
            ));
        }
        if (c.width, c.height) != (first.width, first.height) {
            return bad(format!(
                "camera \"{}\" is {}x{} but the first is {}x{}; a camera path has one resolution",
                c.name, c.width, c.height, first.width, first.height
            ));
        }
        let c2w = c.rotation.as_dmat3().transpose();
        let centre = -(c2w * c.translation.as_dvec3());
        let gl = c2w * gl_to_cv;
        // Row-major: element (r, c) is the row r of column c.
        let mut m = [0.0f64; 16];
        for r in 0..3 {
            for k in 0..3 {
                m[4 * r + k] = gl.col(k)[r] + 0.0;
            }
            m[4 * r + 3] = centre[r];
        }
        m[15] = 1.0;
        let fov = (2.0 * (c.height as f64 / (2.0 * c.fy as f64)).atan()).to_degrees();
        entries.push(serde_json::json!({
            "camera_to_world": m,
            "fov": fov,
            "aspect": c.width as f64 / c.height as f64,
        }));
    }
    let file = serde_json::json!({
        "camera_type": camera_type,
        "render_width": first.width,
        "render_height": first.height,
        "fps": fps,
        "seconds": cams.len() as f64 / fps,
        "camera_path": entries,
    });
    serde_json::to_string_pretty(&file)
        .map_err(|e| CameraError::BadParameter(format!("cannot write the camera path: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_paths_read_back() {
        let cams: Vec<Camera> = (0..3)
            .map(|i| {
                let mut c = crate::core::camera::default_camera(
                    &[[0.0, 0.0, 0.0], [1.0, 2.0, 3.0 + i as f32]],
                    80,
                    60,
                );
                c.name = format!("c{i}");
                c
            })
            .collect();
        let text = to_camera_path_json(&cams, 24.0).unwrap();
        let back = parse_camera_path(&text, Path::new("p.json")).unwrap();
        assert_eq!(back.len(), 3);
        for (a, b) in cams.iter().zip(&back) {
            assert_eq!((a.width, a.height), (b.width, b.height));
            assert!((a.position() - b.position()).length() < 1e-5);
            assert!(a.rotation.abs_diff_eq(b.rotation, 1e-6));
            assert!((a.fy - b.fy).abs() < 1e-3, "{} {}", a.fy, b.fy);
        }
        // nerfstudio's fisheye and equirectangular cameras read back with their lens.
        for lens in [Lens::FULL_SPHERE, Kind::Fisheye.lens()] {
            let with: Vec<Camera> = cams
                .iter()
                .map(|c| Camera {
                    lens: lens.clone(),
                    ..c.clone()
                })
                .collect();
            let text = to_camera_path_json(&with, 24.0).unwrap();
            let back = parse_camera_path(&text, Path::new("p.json")).unwrap();
            assert!(back.iter().all(|c| c.lens == lens), "{text}");
        }
        let mut odd = cams[0].clone();
        odd.lens = Lens::Orthographic;
        let e = to_camera_path_json(&[odd], 24.0).unwrap_err().to_string();
        assert!(
            e.contains("orthographic") && e.contains("camera_type"),
            "{e}"
        );
        let mut other = cams[1].clone();
        other.width = 81;
        assert!(to_camera_path_json(&[cams[0].clone(), other], 24.0).is_err());
        assert!(to_camera_path_json(&[], 24.0).is_err());
    }
}
