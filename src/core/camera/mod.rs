//! Cameras in OpenCV axes (x right, y down, z forward) with their lens, a built-in orbit,
//! a default camera that frames a scene's bulk, the choice of cameras from a list, and
//! resolution overrides. The camera files they come from (INRIA `cameras.json`, COLMAP
//! sparse models, nerfstudio camera paths and `transforms.json`, our keyframe paths) are
//! read and written in [`crate::io::camera`]. `docs/cameras.md` writes down every
//! convention and conversion.

pub mod distortion;
pub mod lens;
pub mod orbit;
mod select;

pub use orbit::{orbit, up_and_centre_of, OrbitParams};
pub use select::{
    describe_selection, index_span, parse_index_range, select_camera, select_camera_indices,
    select_cameras,
};

/// Frames a camera path may have at most (keyframe paths, orbits).
pub const MAX_PATH_FRAMES: usize = 1_000_000;

use crate::core::file_error::FileError;
use glam::{DMat3, DVec3, Mat3, Vec3};
pub use lens::{Intrinsics, Lens, LensSpec};
use std::path::PathBuf;

/// Largest accepted image side, in pixels (the common `maxImageDimension2D`).
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// A pinhole camera. Pixel `(i, j)` is evaluated at exactly `(i, j)` and a point projects
/// to `(fx * x / z + cx - 0.5, fy * y / z + cy - 0.5)`, the reference's convention
/// (principal point `cx = W / 2`, pixel centres at `+0.5`).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Name (the `img_name` of a cameras.json entry, or a description).
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f32,
    /// Focal length along y, in pixels.
    pub fy: f32,
    /// Principal point x, in pixels (`width / 2` for reference cameras).
    pub cx: f32,
    /// Principal point y, in pixels (`height / 2` for reference cameras).
    pub cy: f32,
    /// World-to-camera rotation.
    pub rotation: Mat3,
    /// World-to-camera translation: `p_cam = rotation * p_world + translation`.
    pub translation: Vec3,
    /// The lens: how camera-space points map to pixels ([`Lens::Pinhole`] for the
    /// reference's cameras; [`lens`] has the rest). Its pixel coordinates put pixel
    /// centres at `i + 0.5`; the renderers evaluate pixel `(i, j)` at `(i, j)`, half a
    /// pixel less.
    pub lens: Lens,
}

/// Error raised while building or loading cameras.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// The camera file could not be read, or is not what it should be (the readers' one
    /// file error).
    #[error(transparent)]
    File(#[from] FileError),
    /// A requested camera does not exist.
    #[error("{path}: {message}")]
    NotFound {
        /// File involved.
        path: PathBuf,
        /// What was asked for and what exists.
        message: String,
    },
    /// A camera parameter is unusable.
    #[error("{0}")]
    BadParameter(String),
}

impl Camera {
    /// Builds a camera from vertical field of view (radians), looking from `eye` at
    /// `target` with `up` the world's up direction.
    pub fn look_at(
        name: &str,
        width: u32,
        height: u32,
        vfov: f32,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
    ) -> Self {
        let forward = (target - eye).normalize_or(Vec3::Z);
        let down = -up.normalize_or(Vec3::NEG_Y);
        let mut right = down.cross(forward);
        if right.length_squared() < 1e-12 {
            // Looking straight along the up axis: any perpendicular will do.
            right = forward.any_orthonormal_vector();
        }
        let right = right.normalize();
        let cam_down = forward.cross(right);
        // Rows of the world-to-camera rotation are the camera axes in world space.
        let rotation = Mat3::from_cols(right, cam_down, forward).transpose();
        let fy = height as f32 / (2.0 * (vfov * 0.5).tan());
        Camera {
            name: name.to_string(),
            width,
            height,
            fx: fy,
            fy,
            cx: width as f32 / 2.0,
            cy: height as f32 / 2.0,
            rotation,
            translation: -(rotation * eye),
            lens: Lens::Pinhole,
        }
    }

    /// The focal lengths, principal point and image size, for [`Lens`]'s maps.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics {
            fx: self.fx as f64,
            fy: self.fy as f64,
            cx: self.cx as f64,
            cy: self.cy as f64,
            width: self.width,
            height: self.height,
        }
    }

    /// Camera centre in world space.
    pub fn position(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// `tan(fovx / 2)` as the reference derives it (`W / (2 fx)`).
    pub fn tan_half_fov_x(&self) -> f32 {
        self.width as f32 / (2.0 * self.fx)
    }

    /// `tan(fovy / 2)` as the reference derives it (`H / (2 fy)`).
    pub fn tan_half_fov_y(&self) -> f32 {
        self.height as f32 / (2.0 * self.fy)
    }

    /// Number of 16x16 tiles along x and y.
    pub fn tile_grid(&self) -> (u32, u32) {
        (self.width.div_ceil(16), self.height.div_ceil(16))
    }

    /// The same view at another resolution: focal lengths and principal point scale with it.
    pub fn with_resolution(&self, width: u32, height: u32) -> Result<Camera, CameraError> {
        check_resolution(width, height)?;
        let sx = width as f32 / self.width as f32;
        let sy = height as f32 / self.height as f32;
        Ok(Camera {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            ..self.clone()
        })
    }

    /// Applies `--width/--height` (either alone keeps the aspect ratio) or `--scale`.
    pub fn resized(
        &self,
        width: Option<u32>,
        height: Option<u32>,
        scale: Option<f32>,
    ) -> Result<Camera, CameraError> {
        if width.is_none() && height.is_none() && scale.is_none() {
            return Ok(self.clone());
        }
        let (w, h) = resized_dims((self.width, self.height), width, height, scale)?;
        self.with_resolution(w, h)
    }

    /// Checks that the camera can be rendered: sane resolution and finite, positive intrinsics.
    pub fn validate(&self) -> Result<(), CameraError> {
        check_resolution(self.width, self.height)?;
        let finite = [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|v| v.is_finite())
            && self.rotation.is_finite()
            && self.translation.is_finite();
        if !finite || self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(CameraError::BadParameter(format!(
                "camera \"{}\" has non-finite or non-positive intrinsics or pose (fx {}, fy {})",
                self.name, self.fx, self.fy
            )));
        }
        self.lens
            .check()
            .map_err(|e| CameraError::BadParameter(format!("camera \"{}\": {e}", self.name)))
    }
}

fn clamp_side(v: f64, flag: &str) -> Result<u32, CameraError> {
    if v >= 1.0 && v <= MAX_IMAGE_SIDE as f64 {
        Ok(v as u32)
    } else {
        Err(CameraError::BadParameter(format!(
            "{flag} gives an image side of {v} pixels; it must be between 1 and {MAX_IMAGE_SIDE}"
        )))
    }
}

/// The size `--width/--height` (either alone keeps the aspect ratio of `size`) or
/// `--scale` give an image of `size`.
pub fn resized_dims(
    size: (u32, u32),
    width: Option<u32>,
    height: Option<u32>,
    scale: Option<f32>,
) -> Result<(u32, u32), CameraError> {
    let aspect = size.1 as f64 / size.0 as f64;
    if scale.is_some() && (width.is_some() || height.is_some()) {
        return Err(CameraError::BadParameter(
            "give either --scale or --width/--height, not both".into(),
        ));
    }
    let (w, h) = match (width, height, scale) {
        (None, None, None) => (size.0, size.1),
        (_, _, Some(s)) => {
            if !(s.is_finite() && s > 0.0) {
                return Err(CameraError::BadParameter(format!(
                    "--scale {s} must be a positive number"
                )));
            }
            let w = (size.0 as f64 * s as f64).round();
            let h = (size.1 as f64 * s as f64).round();
            (clamp_side(w, "--scale")?, clamp_side(h, "--scale")?)
        }
        (Some(w), Some(h), _) => (w, h),
        (Some(w), None, _) => (w, clamp_side((w as f64 * aspect).round(), "--width")?),
        (None, Some(h), _) => (clamp_side((h as f64 / aspect).round(), "--height")?, h),
    };
    Ok((w, h))
}

/// Rejects zero or absurd resolutions.
pub fn check_resolution(width: u32, height: u32) -> Result<(), CameraError> {
    if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(CameraError::BadParameter(format!(
            "resolution {width}x{height} is not usable; each side must be between 1 and {MAX_IMAGE_SIDE} pixels"
        )));
    }
    Ok(())
}

/// Robust extent of a point set: per-axis median centre and the 95th-percentile
/// distance from it, so a few stray Gaussians far away do not spoil the framing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BulkBounds {
    /// Per-axis median of the positions.
    pub centre: Vec3,
    /// 95th percentile of the distances to `centre`.
    pub radius: f32,
    /// 2nd percentile per axis.
    pub lo: Vec3,
    /// 98th percentile per axis.
    pub hi: Vec3,
}

impl BulkBounds {
    /// Centre of the robust box `lo..hi`: the point generated cameras look at.
    pub fn box_centre(&self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }
}

/// Computes [`BulkBounds`] of `positions` (finite values only).
pub fn bulk_bounds(positions: &[[f32; 3]]) -> BulkBounds {
    if positions.is_empty() {
        return BulkBounds {
            centre: Vec3::ZERO,
            radius: 1.0,
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
        };
    }
    let pct = |v: &mut Vec<f32>, p: f64| -> f32 {
        let idx = ((v.len() - 1) as f64 * p).round() as usize;
        let (_, x, _) = v.select_nth_unstable_by(idx, |a, b| a.total_cmp(b));
        *x
    };
    let mut axes: Vec<Vec<f32>> = (0..3)
        .map(|a| positions.iter().map(|p| p[a]).collect())
        .collect();
    let mut centre = [0f32; 3];
    let mut lo = [0f32; 3];
    let mut hi = [0f32; 3];
    for a in 0..3 {
        centre[a] = pct(&mut axes[a], 0.5);
        lo[a] = pct(&mut axes[a], 0.02);
        hi[a] = pct(&mut axes[a], 0.98);
    }
    let centre = Vec3::from(centre);
    let mut dist: Vec<f32> = positions
        .iter()
        .map(|p| (Vec3::from(*p) - centre).length())
        .collect();
    let radius = pct(&mut dist, 0.95).max(1e-3);
    BulkBounds {
        centre,
        radius,
        lo: lo.into(),
        hi: hi.into(),
    }
}

/// Default vertical field of view of generated cameras (50 degrees).
pub const DEFAULT_VFOV_DEG: f32 = 50.0;

/// A camera that frames the bulk of `positions`: it looks at the centre of the robust
/// bounding box (2nd-98th percentile per axis, so stray Gaussians do not spoil it) from the
/// -z side, 20 degrees above the horizon (world up is -y, the INRIA/COLMAP convention),
/// far enough for the whole box to lie inside the view with a 5% margin. It is frame 0 of
/// the default [`orbit()`].
pub fn default_camera(positions: &[[f32; 3]], width: u32, height: u32) -> Camera {
    let b = bulk_bounds(positions);
    let vfov = DEFAULT_VFOV_DEG.to_radians();
    let elevation = orbit::DEFAULT_ELEVATION_DEG.to_radians();
    let centre = b.box_centre();
    let view = orbit::OrbitView {
        centre,
        distance: orbit::box_framing_distance(
            &b,
            centre,
            elevation,
            Vec3::NEG_Y,
            width,
            height,
            vfov,
        ),
        elevation,
        azimuth: 0.0,
        up: Vec3::NEG_Y,
    };
    view.camera("default", width, height, vfov)
}

/// Rotation matrix of a quaternion `(w, x, y, z)`, normalised first (as COLMAP does);
/// `None` for a zero-length or non-finite quaternion.
pub(crate) fn quat_wxyz_to_mat(q: [f64; 4]) -> Option<DMat3> {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !n.is_finite() || n < 1e-12 {
        return None;
    }
    // COLMAP's qvec2rotmat.
    Some(crate::core::quat::quat_to_dmat3(q.map(|v| v / n)))
}

/// Largest deviation of `r` from a proper rotation: `max |R^T R - I|` and `|det R - 1|`.
pub(crate) fn rotation_error(r: DMat3) -> f64 {
    let d = r.transpose() * r - DMat3::IDENTITY;
    let off =
        d.to_cols_array().iter().fold(
            0f64,
            |m, v| if v.is_nan() { f64::NAN } else { m.max(v.abs()) },
        );
    if off.is_nan() {
        return f64::INFINITY;
    }
    off.max((r.determinant() - 1.0).abs())
}

/// A pinhole camera from a camera-to-world pose in OpenCV axes (columns of `c2w` are the
/// camera's right, down and forward axes in world space) and the camera centre.
pub(crate) fn camera_from_c2w(
    name: String,
    width: u32,
    height: u32,
    focal: [f64; 2],
    principal: [f64; 2],
    c2w: DMat3,
    centre: DVec3,
) -> Camera {
    let w2c = c2w.transpose();
    Camera {
        name,
        width,
        height,
        fx: focal[0] as f32,
        fy: focal[1] as f32,
        cx: principal[0] as f32,
        cy: principal[1] as f32,
        rotation: w2c.as_mat3(),
        translation: (-(w2c * centre)).as_vec3(),
        lens: Lens::Pinhole,
    }
}
