//! Cameras: the tuple a camera crosses the boundary as, and the camera functions (camera
//! files, orbits, the default camera, look-at, the scene's bulk centre).

use crate::errors::{guarded, py_err, value_err};
use crate::scene::PyScene;
use glam::{Mat3, Vec3};
use pyo3::prelude::*;
use std::path::PathBuf;
use verisplat::core::camera::{self, lens, Camera, Lens};
use verisplat::io;

/// A camera as it crosses the boundary: name, width, height, `[fx, fy, cx, cy]`, the
/// world-to-camera matrix, row-major 4x4 (OpenCV axes), and the lens ([`LensTuple`]).
pub(crate) type CamTuple = (String, u32, u32, [f32; 4], [f32; 16], LensTuple);

/// A lens as it crosses the boundary: its kind (`Lens::name`) and its numbers:
/// `pinhole` and `orthographic` none, `distorted` `k1..k6, p1, p2`, `fisheye` `k1..k4`
/// and optionally `max_theta` (radians; without it, as far as the polynomial grows),
/// `equirectangular` the longitudes of the left and right edges and the latitudes of the
/// top and bottom ones (radians).
pub(crate) type LensTuple = (String, Vec<f64>);

/// The lens of a [`LensTuple`], checked ([`Lens::check`]).
pub(crate) fn to_lens((kind, v): &LensTuple) -> PyResult<Lens> {
    let want = |n: &str| {
        value_err(format!(
            "a {kind} lens takes {n}, got {} number{}",
            v.len(),
            if v.len() == 1 { "" } else { "s" }
        ))
    };
    let lens = match kind.as_str() {
        "pinhole" | "orthographic" if !v.is_empty() => return Err(want("no numbers")),
        "pinhole" => Lens::Pinhole,
        "orthographic" => Lens::Orthographic,
        "distorted" => match v.as_slice() {
            [k1, k2, k3, k4, k5, k6, p1, p2] => Lens::RadialTangential {
                radial: [*k1, *k2, *k3, *k4, *k5, *k6],
                tangential: [*p1, *p2],
            },
            _ => return Err(want("8 numbers (k1..k6, p1, p2)")),
        },
        "fisheye" => match v.as_slice() {
            [k1, k2, k3, k4] => {
                let k = [*k1, *k2, *k3, *k4];
                Lens::Fisheye {
                    k,
                    max_theta: lens::fisheye_max_theta(&k),
                }
            }
            [k1, k2, k3, k4, max_theta] => Lens::Fisheye {
                k: [*k1, *k2, *k3, *k4],
                max_theta: *max_theta,
            },
            _ => return Err(want("4 or 5 numbers (k1..k4, and max_theta)")),
        },
        "equirectangular" => match v.as_slice() {
            [] => Lens::FULL_SPHERE,
            [l0, l1, t0, t1] => Lens::Equirectangular {
                longitude: [*l0, *l1],
                latitude: [*t0, *t1],
            },
            _ => return Err(want("none (the whole sphere) or 4 numbers (two longitudes, two latitudes)")),
        },
        other => {
            return Err(value_err(format!(
                "unknown lens kind \"{other}\"; the kinds are pinhole, distorted, fisheye, orthographic and equirectangular"
            )))
        }
    };
    lens.check()
        .map_err(|e| value_err(format!("the {kind} lens: {e}")))?;
    Ok(lens)
}

/// The [`LensTuple`] of a lens.
pub(crate) fn from_lens(lens: &Lens) -> LensTuple {
    let v = match lens {
        Lens::Pinhole | Lens::Orthographic => vec![],
        Lens::RadialTangential { radial, tangential } => {
            radial.iter().chain(tangential).copied().collect()
        }
        Lens::Fisheye { k, max_theta } => k.iter().chain([max_theta]).copied().collect(),
        Lens::Equirectangular {
            longitude,
            latitude,
        } => longitude.iter().chain(latitude).copied().collect(),
    };
    (lens.name().to_string(), v)
}

/// Checks a lens ([`to_lens`]): ValueError with the reason.
#[pyfunction]
pub(crate) fn check_lens(lens: LensTuple) -> PyResult<()> {
    to_lens(&lens).map(|_| ())
}

/// The largest angle from the axis a fisheye with coefficients `k1..k4` images: where its
/// radius stops growing (at most 180 degrees), the lens's default `max_theta`.
#[pyfunction]
pub(crate) fn fisheye_max_theta(k: [f64; 4]) -> f64 {
    lens::fisheye_max_theta(&k)
}

pub(crate) fn to_camera(t: &CamTuple) -> PyResult<Camera> {
    let (name, width, height, k, m, lens) = t;
    let lens = to_lens(lens).map_err(|e| value_err(format!("camera \"{name}\": {e}")))?;
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
        lens,
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
        from_lens(&c.lens),
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
            let timing = io::camera::PathTiming { frames, fps };
            let (cams, _) =
                io::camera::load_camera_file(&path, &timing).map_err(|e| py_err(e.into()))?;
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
        let text = io::camera::inria::to_json(&numbered).map_err(|e| py_err(e.into()))?;
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
