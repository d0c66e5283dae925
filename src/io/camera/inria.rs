//! INRIA `cameras.json` (what the 3DGS trainer writes next to its model): a JSON list of
//! `{id, img_name, width, height, position, rotation, fx, fy}` where `position` is the
//! camera centre and `rotation` the camera-to-world rotation, stored row by row (so its
//! columns are the camera's right, down and forward axes in world space). Optional `cx`
//! and `cy` (pixels) give a principal point other than the image centre, and an optional
//! `lens` a lens other than the pinhole (`{"kind": "distorted", "radial": [k1..k6],
//! "tangential": [p1, p2]}`, `{"kind": "fisheye", "k": [k1..k4], "max_theta": RADIANS}`,
//! `{"kind": "orthographic"}`, `{"kind": "equirectangular", "longitude": [A, B],
//! "latitude": [C, D]}` in radians); verisplat writes them only for such cameras, and
//! other readers ignore them.

use super::{Camera, CameraError, Lens};
use crate::core::file_error::FileError;
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Deserialize, Serialize)]
struct JsonCamera {
    #[serde(default)]
    id: Option<serde_json::Value>,
    #[serde(default)]
    img_name: Option<String>,
    width: u32,
    height: u32,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fy: f64,
    fx: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cy: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    /// A lens other than the pinhole (`Lens`'s own serde form, named by [`Lens::name`]).
    lens: Option<Lens>,
}

/// Writes cameras as an INRIA `cameras.json`, one camera per line: `id` is the given
/// number (the camera's frame in its path), `img_name` the camera's name. The file reads
/// back ([`parse_cameras_json`]) as the same cameras: rotation, focal lengths, lens and
/// resolution exactly; `position` is computed in double precision so that the
/// translation read back is the camera's to within 1e-15 of its size.
pub fn to_json(cameras: &[(usize, Camera)]) -> Result<String, CameraError> {
    let mut lines = Vec::with_capacity(cameras.len());
    for (id, cam) in cameras {
        cam.validate()?;
        let w2c = cam.rotation.as_dmat3();
        // The inverse of the stored (f32) rotation rather than its transpose, which is
        // orthonormal only to f32 precision: the reader's `-R * position` then gives back
        // the translation.
        let inverse = w2c.inverse();
        if !inverse.is_finite() {
            return Err(CameraError::BadParameter(format!(
                "camera \"{}\" has a singular rotation",
                cam.name
            )));
        }
        let position = -(inverse * cam.translation.as_dvec3());
        let centred = |c: f32, side: u32| (c != side as f32 / 2.0).then_some(c as f64);
        let entry = JsonCamera {
            id: Some((*id).into()),
            img_name: Some(cam.name.clone()),
            width: cam.width,
            height: cam.height,
            position: position.to_array().map(|v| v + 0.0),
            // Stored rows are the camera-to-world rotation's rows: the columns of w2c.
            // (`+ 0.0` writes a negative zero as 0.0.)
            rotation: w2c.to_cols_array_2d().map(|row| row.map(|v| v + 0.0)),
            fy: cam.fy as f64,
            fx: cam.fx as f64,
            cx: centred(cam.cx, cam.width),
            cy: centred(cam.cy, cam.height),
            lens: (!cam.lens.is_pinhole()).then(|| cam.lens.clone()),
        };
        lines.push(serde_json::to_string(&entry).map_err(|e| {
            CameraError::BadParameter(format!("cannot write camera \"{}\": {e}", cam.name))
        })?);
    }
    Ok(format!("[\n{}\n]\n", lines.join(",\n")))
}

/// Loads every camera of an INRIA `cameras.json`.
pub fn load_cameras_json(path: &Path) -> Result<Vec<Camera>, CameraError> {
    let text = std::fs::read_to_string(path).map_err(|source| {
        CameraError::File(FileError::Io {
            path: path.to_path_buf(),
            source,
        })
    })?;
    parse_cameras_json(&text, path)
}

/// Parses an INRIA `cameras.json` held in memory; `path` names it in errors.
pub fn parse_cameras_json(text: &str, path: &Path) -> Result<Vec<Camera>, CameraError> {
    let invalid = |message: String| {
        CameraError::File(FileError::Invalid {
            path: path.to_path_buf(),
            message,
        })
    };
    let mut entries: Vec<JsonCamera> = serde_json::from_str(text).map_err(|e| {
        invalid(format!(
            "is not an INRIA cameras.json (a list of {{id, img_name, width, height, position, rotation, fx, fy}}): {e}"
        ))
    })?;
    let mut cams = Vec::with_capacity(entries.len());
    for (i, e) in entries.iter_mut().enumerate() {
        let name = e.img_name.clone().unwrap_or_else(|| match &e.id {
            Some(id) => format!("camera_{id}"),
            None => format!("camera_{i}"),
        });
        // Stored rows are the camera-to-world rotation; world-to-camera is its transpose.
        let c2w = glam::DMat3::from_cols_array_2d(&e.rotation).transpose();
        let w2c = c2w.transpose();
        let pos = glam::DVec3::from_array(e.position);
        let t = -(w2c * pos);
        let cam = Camera {
            name,
            width: e.width,
            height: e.height,
            fx: e.fx as f32,
            fy: e.fy as f32,
            cx: e.cx.map_or(e.width as f32 / 2.0, |c| c as f32),
            cy: e.cy.map_or(e.height as f32 / 2.0, |c| c as f32),
            rotation: w2c.as_mat3(),
            translation: t.as_vec3(),
            lens: e.lens.take().unwrap_or(Lens::Pinhole),
        };
        cam.validate()
            .map_err(|err| invalid(format!("entry {i} (\"{}\"): {err}", cam.name)))?;
        let det = c2w.determinant();
        if !((0.9..1.1).contains(&det)) {
            return Err(invalid(format!(
                "entry {i} (\"{}\"): rotation is not a rotation matrix (determinant {det:.4})",
                cam.name
            )));
        }
        cams.push(cam);
    }
    Ok(cams)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_lens_reads_back_as_written() {
        let lenses = [
            Lens::Pinhole,
            Lens::RadialTangential {
                radial: [-0.28, 0.07, 0.001, 0.05, -0.01, 0.002],
                tangential: [0.001, -0.0005],
            },
            Lens::Fisheye {
                k: [0.02, -0.005, 0.001, 1e-5],
                max_theta: 100f64.to_radians(),
            },
            Lens::Orthographic,
            Lens::FULL_SPHERE,
            Lens::Equirectangular {
                longitude: [2.0, 4.5],
                latitude: [0.3, -0.7],
            },
        ];
        let cams: Vec<(usize, Camera)> = lenses
            .iter()
            .enumerate()
            .map(|(i, lens)| {
                let mut c = crate::core::camera::default_camera(
                    &[[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]],
                    64,
                    48,
                );
                c.name = format!("c{i}");
                c.lens = lens.clone();
                (i, c)
            })
            .collect();
        let text = to_json(&cams).unwrap();
        // The pinhole keeps the INRIA layout: no "lens" key.
        assert_eq!(text.matches("\"lens\"").count(), lenses.len() - 1, "{text}");
        let back = parse_cameras_json(&text, Path::new("cameras.json")).unwrap();
        for ((_, a), b) in cams.iter().zip(&back) {
            assert_eq!(a.lens, b.lens);
        }
        // A lens with a misspelt key or impossible parameters is refused, naming the entry.
        let bad = text.replace("\"max_theta\"", "\"max_thet\"");
        let e = parse_cameras_json(&bad, Path::new("cameras.json")).unwrap_err();
        assert!(e.to_string().contains("max_thet"), "{e}");
        let bad = r#"[{"id":0,"img_name":"a","width":64,"height":48,"position":[0,0,-3],"rotation":[[1,0,0],[0,1,0],[0,0,1]],"fx":50,"fy":50,"lens":{"kind":"fisheye","k":[0,0,0,0],"max_theta":4}}]"#;
        let e = parse_cameras_json(bad, Path::new("cameras.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("entry 0") && e.contains("field of view"), "{e}");
    }
}
