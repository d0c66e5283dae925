//! Cameras: the tuple a camera crosses the boundary as, and the camera functions (camera
//! files, orbits, the default camera, look-at, the scene's bulk centre).

use crate::errors::{guarded, py_err, value_err};
use crate::scene::PyScene;
use glam::{Mat3, Vec3};
use pyo3::prelude::*;
use std::path::PathBuf;
use verisplat::core::camera::{self, Camera};

/// A camera as it crosses the boundary: name, width, height, `[fx, fy, cx, cy]` and the
/// world-to-camera matrix, row-major 4x4 (OpenCV axes).
pub(crate) type CamTuple = (String, u32, u32, [f32; 4], [f32; 16]);

pub(crate) fn to_camera(t: &CamTuple) -> PyResult<Camera> {
    let (name, width, height, k, m) = t;
    // Row-major [R t; 0 1]: glam takes columns, so R's rows become the transpose's columns.
    let rotation = Mat3::from_cols_array(&[m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]]);
    let cam = Camera {
        name: name.clone(),
        width: *width,
        height: *height,
        fx: k[0],
        fy: k[1],
        cx: k[2],
        cy: k[3],
        rotation,
        translation: Vec3::new(m[3], m[7], m[11]),
        lens: verisplat::core::camera::Lens::Pinhole,
    };
    cam.validate()
        .map_err(|e| value_err(format!("camera \"{name}\": {e}")))?;
    Ok(cam)
}

fn from_camera(c: &Camera) -> CamTuple {
    let r = c.rotation.transpose().to_cols_array(); // rows of R
    let t = c.translation;
    (
        c.name.clone(),
        c.width,
        c.height,
        [c.fx, c.fy, c.cx, c.cy],
        [
            r[0], r[1], r[2], t.x, r[3], r[4], r[5], t.y, r[6], r[7], r[8], t.z, 0.0, 0.0, 0.0, 1.0,
        ],
    )
}

/// Every camera of a camera file (INRIA cameras.json, COLMAP model, nerfstudio path,
/// verisplat keyframes; a trained model directory stands for its cameras.json).
#[pyfunction]
#[pyo3(signature = (path, frames=None, fps=None))]
pub(crate) fn load_cameras(
    py: Python<'_>,
    path: PathBuf,
    frames: Option<usize>,
    fps: Option<f32>,
) -> PyResult<Vec<CamTuple>> {
    py.detach(|| {
        guarded(|| {
            let timing = camera::PathTiming { frames, fps };
            let (cams, _) =
                camera::load_camera_file(&path, &timing).map_err(|e| py_err(e.into()))?;
            Ok(cams.iter().map(from_camera).collect())
        })
    })
}

/// Writes cameras as an INRIA cameras.json (read back by `load_cameras` and the CLI's
/// `--cameras`), atomically.
#[pyfunction]
#[pyo3(signature = (path, cameras, overwrite=false))]
pub(crate) fn save_cameras(path: PathBuf, cameras: Vec<CamTuple>, overwrite: bool) -> PyResult<()> {
    guarded(|| {
        let cams = cameras
            .iter()
            .map(to_camera)
            .collect::<PyResult<Vec<_>>>()?;
        let numbered: Vec<(usize, Camera)> = cams.into_iter().enumerate().collect();
        let text = camera::inria::to_json(&numbered).map_err(|e| py_err(e.into()))?;
        verisplat::io::output::write_bytes_atomically(&path, overwrite, text.as_bytes())
            .map_err(|e| py_err(e.into()))
    })
}

/// A turntable orbit around the scene's bulk (see `verisplat render --orbit`).
#[pyfunction]
#[pyo3(signature = (scene, frames, width, height, vfov, elevation, start, up, centre=None, radius=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn orbit(
    scene: &PyScene,
    frames: usize,
    width: u32,
    height: u32,
    vfov: f32,
    elevation: f32,
    start: f32,
    up: [f32; 3],
    centre: Option<[f32; 3]>,
    radius: Option<f32>,
) -> PyResult<Vec<CamTuple>> {
    guarded(|| {
        let params = camera::OrbitParams {
            frames,
            centre: centre.map(Vec3::from),
            radius,
            elevation_deg: elevation,
            up: Vec3::from(up),
            start_deg: start,
            vfov_deg: vfov,
            width,
            height,
        };
        let cams = camera::orbit(&scene.raw.positions, &params).map_err(|e| py_err(e.into()))?;
        Ok(cams.iter().map(from_camera).collect())
    })
}

/// The camera `verisplat render` uses when given none.
#[pyfunction]
pub(crate) fn default_camera(scene: &PyScene, width: u32, height: u32) -> PyResult<CamTuple> {
    guarded(|| {
        camera::check_resolution(width, height).map_err(|e| py_err(e.into()))?;
        Ok(from_camera(&camera::default_camera(
            &scene.raw.positions,
            width,
            height,
        )))
    })
}

/// A camera at `eye` looking at `target`, `up` the world's up, vertical field of view in
/// degrees.
#[pyfunction]
#[pyo3(signature = (eye, target, up, width, height, vfov, name=String::new()))]
pub(crate) fn look_at(
    eye: [f32; 3],
    target: [f32; 3],
    up: [f32; 3],
    width: u32,
    height: u32,
    vfov: f32,
    name: String,
) -> PyResult<CamTuple> {
    guarded(|| {
        camera::check_resolution(width, height).map_err(|e| py_err(e.into()))?;
        if !(vfov > 0.0 && vfov < 180.0) {
            return Err(value_err(format!(
                "the vertical field of view must be between 0 and 180 degrees, got {vfov}"
            )));
        }
        let cam = Camera::look_at(
            &name,
            width,
            height,
            vfov.to_radians(),
            Vec3::from(eye),
            Vec3::from(target),
            Vec3::from(up),
        );
        cam.validate().map_err(|e| py_err(e.into()))?;
        Ok(from_camera(&cam))
    })
}

/// The centre of the scene's robust bounding box (2nd-98th percentile per axis), what
/// the default camera and orbits look at.
#[pyfunction]
pub(crate) fn bulk_centre(scene: &PyScene) -> [f32; 3] {
    camera::bulk_bounds(&scene.raw.positions)
        .box_centre()
        .to_array()
}
