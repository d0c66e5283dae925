//! INRIA `cameras.json` (what the 3DGS trainer writes next to its model): a JSON list of
//! `{id, img_name, width, height, position, rotation, fx, fy}` where `position` is the
//! camera centre and `rotation` the camera-to-world rotation, stored row by row (so its
//! columns are the camera's right, down and forward axes in world space).

use super::{Camera, CameraError};
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize)]
struct JsonCamera {
    #[serde(default)]
    id: Option<serde_json::Value>,
    #[serde(default)]
    img_name: Option<String>,
    width: u32,
    height: u32,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
}

/// Loads every camera of an INRIA `cameras.json`.
pub fn load_cameras_json(path: &Path) -> Result<Vec<Camera>, CameraError> {
    let text = std::fs::read_to_string(path).map_err(|source| CameraError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_cameras_json(&text, path)
}

/// Parses an INRIA `cameras.json` held in memory; `path` names it in errors.
pub fn parse_cameras_json(text: &str, path: &Path) -> Result<Vec<Camera>, CameraError> {
    let invalid = |message: String| CameraError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let entries: Vec<JsonCamera> = serde_json::from_str(text).map_err(|e| {
        invalid(format!(
            "is not an INRIA cameras.json (a list of {{id, img_name, width, height, position, rotation, fx, fy}}): {e}"
        ))
    })?;
    let mut cams = Vec::with_capacity(entries.len());
    for (i, e) in entries.iter().enumerate() {
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
            cx: e.width as f32 / 2.0,
            cy: e.height as f32 / 2.0,
            rotation: w2c.as_mat3(),
            translation: t.as_vec3(),
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
