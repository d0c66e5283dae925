//! The built-in turntable: cameras evenly spaced on a circle around the scene, all looking
//! at its centre. With default parameters, frame 0 is [`default_camera`](super::default_camera).

use super::MAX_PATH_FRAMES as MAX_FRAMES;
use super::{bulk_bounds, check_resolution, BulkBounds, Camera, CameraError, DEFAULT_VFOV_DEG};
use glam::Vec3;

/// Default elevation of generated cameras above the horizon, in degrees.
pub const DEFAULT_ELEVATION_DEG: f32 = 20.0;

/// Parameters of [`orbit`]. `None` fields are derived from the scene's robust bounds.
#[derive(Clone, Debug, PartialEq)]
pub struct OrbitParams {
    /// Number of frames over the full 360 degrees (the last frame stops one step short
    /// of the first, so the sequence loops).
    pub frames: usize,
    /// Point looked at and orbited; default: the centre of the robust bounding box
    /// (2nd-98th percentile per axis).
    pub centre: Option<Vec3>,
    /// Distance of every camera from `centre`; default: far enough for the whole robust
    /// box to be inside the view from every azimuth, as `default_camera`.
    pub radius: Option<f32>,
    /// Angle of the cameras above the plane through `centre` perpendicular to `up`, in
    /// degrees (strictly between -90 and 90).
    pub elevation_deg: f32,
    /// World up direction; default -y, the INRIA/COLMAP convention.
    pub up: Vec3,
    /// Azimuth of frame 0 in degrees. Azimuth 0 is on the -z side of the centre (for up
    /// -y; in general -z made perpendicular to `up`), and it grows towards +x.
    pub start_deg: f32,
    /// Vertical field of view in degrees.
    pub vfov_deg: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Default for OrbitParams {
    fn default() -> Self {
        OrbitParams {
            frames: 120,
            centre: None,
            radius: None,
            elevation_deg: DEFAULT_ELEVATION_DEG,
            up: Vec3::NEG_Y,
            start_deg: 0.0,
            vfov_deg: DEFAULT_VFOV_DEG,
            width: 1280,
            height: 720,
        }
    }
}

/// Cameras `orbit_00000`, `orbit_00001`, ... evenly spaced over 360 degrees of azimuth
/// around the scene, each looking at the centre with `up` as the world's up.
pub fn orbit(positions: &[[f32; 3]], p: &OrbitParams) -> Result<Vec<Camera>, CameraError> {
    let bad = |m: String| Err(CameraError::BadParameter(m));
    check_resolution(p.width, p.height)?;
    if !(1..=MAX_FRAMES).contains(&p.frames) {
        return bad(format!(
            "an orbit has {} frames; it needs between 1 and {MAX_FRAMES}",
            p.frames
        ));
    }
    if !(p.vfov_deg.is_finite() && p.vfov_deg > 0.0 && p.vfov_deg < 180.0) {
        return bad(format!(
            "orbit field of view {} degrees must be between 0 and 180",
            p.vfov_deg
        ));
    }
    if !(p.elevation_deg.is_finite() && p.elevation_deg.abs() < 90.0) {
        return bad(format!(
            "orbit elevation {} degrees must be strictly between -90 and 90",
            p.elevation_deg
        ));
    }
    if !p.start_deg.is_finite() {
        return bad(format!("orbit start angle {} is not a number", p.start_deg));
    }
    if !(p.up.is_finite() && p.up.length() > 1e-6) {
        return bad(format!(
            "orbit up vector {} must be finite and non-zero",
            p.up
        ));
    }
    if let Some(c) = p.centre {
        if !c.is_finite() {
            return bad(format!("orbit centre {c} is not finite"));
        }
    }
    if let Some(r) = p.radius {
        if !(r.is_finite() && r > 0.0) {
            return bad(format!("orbit radius {r} must be a positive number"));
        }
    }
    let vfov = p.vfov_deg.to_radians();
    // Bounds are only needed for what the caller left out (they sort the whole scene).
    let bounds = (p.centre.is_none() || p.radius.is_none()).then(|| bulk_bounds(positions));
    let centre = p
        .centre
        .unwrap_or_else(|| bounds.map_or(Vec3::ZERO, |b| b.box_centre()));
    let distance = match (p.radius, bounds) {
        (Some(r), _) => r,
        (None, Some(b)) => box_framing_distance(
            &b,
            centre,
            p.elevation_deg.to_radians(),
            p.up,
            p.width,
            p.height,
            vfov,
        ),
        (None, None) => framing_distance(1.0, p.width, p.height, vfov),
    };
    let step = 360.0 / p.frames as f64;
    Ok((0..p.frames)
        .map(|k| {
            let azimuth_deg = p.start_deg as f64 + step * k as f64;
            let view = OrbitView {
                centre,
                distance,
                elevation: p.elevation_deg.to_radians(),
                azimuth: (azimuth_deg as f32).to_radians(),
                up: p.up,
            };
            view.camera(&format!("orbit_{k:05}"), p.width, p.height, vfov)
        })
        .collect())
}

/// What a set of cameras (a capture's, a trained model's `cameras.json`) says about the
/// scene's orientation: the world's up, the mean of the cameras' up directions (their
/// -y axes), and the point their optical axes pass closest to (least squares), which
/// captures that circle an object look at. `None` where the cameras do not tell: ups
/// that cancel out, or optical axes too close to parallel (a forward-facing capture)
/// or meeting behind the cameras.
pub fn up_and_centre_of(cams: &[Camera]) -> (Option<Vec3>, Option<Vec3>) {
    use glam::{DMat3, DVec3};
    if cams.is_empty() {
        return (None, None);
    }
    let n = cams.len() as f64;
    let mut up = DVec3::ZERO;
    let (mut a, mut b) = (DMat3::ZERO, DVec3::ZERO);
    let mut rays = Vec::with_capacity(cams.len());
    for c in cams {
        let to_world = c.rotation.as_dmat3().transpose();
        up -= to_world.y_axis;
        let d = to_world.z_axis.normalize();
        let centre = c.position().as_dvec3();
        // The projection onto the plane across the optical axis.
        let p = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += p;
        b += p * centre;
        rays.push((centre, d));
    }
    let up = (up.length() > 0.5 * n).then(|| up.normalize().as_vec3());
    // Each projection has eigenvalues 1, 1, 0; the sum's smallest eigenvalue (at most
    // n) is small when the axes are nearly parallel. det(A/n) bounds it from below by
    // det / (largest eigenvalue)^2 >= det / 4.
    let a_n = a * (1.0 / n);
    let centre = (a_n.determinant() > 0.02)
        .then(|| a.inverse() * b)
        .filter(|p| {
            p.is_finite() && rays.iter().map(|(c, d)| (*p - *c).dot(*d)).sum::<f64>() > 0.0
        });
    (up, centre.map(|p| p.as_vec3()))
}

/// Distance at which a sphere of `radius` fits the narrower of the two fields of view
/// (with a 5% margin); `vfov` in radians.
pub(crate) fn framing_distance(radius: f32, width: u32, height: u32, vfov: f32) -> f32 {
    let hfov = 2.0 * ((width as f32 / height as f32) * (vfov * 0.5).tan()).atan();
    let half = 0.5 * vfov.min(hfov);
    radius / half.sin() * 1.05
}

/// Distance from `centre` at which all eight corners of the robust box `b.lo..b.hi` lie
/// inside the view (with a 5% margin on each side) of a camera looking at `centre` from
/// `elevation` (radians) above the plane perpendicular to `up`, at any azimuth: the largest
/// distance over 72 azimuths, so an orbit keeps the whole box in view and its frame 0 is
/// the default camera.
pub(crate) fn box_framing_distance(
    b: &BulkBounds,
    centre: Vec3,
    elevation: f32,
    up: Vec3,
    width: u32,
    height: u32,
    vfov: f32,
) -> f32 {
    let tan_y = (0.5 * vfov).tan() / 1.05;
    let tan_x = tan_y * width as f32 / height as f32;
    // Corners relative to the point looked at.
    let corners: Vec<Vec3> = (0..8)
        .map(|k| {
            Vec3::new(
                if k & 1 == 0 { b.lo.x } else { b.hi.x },
                if k & 2 == 0 { b.lo.y } else { b.hi.y },
                if k & 4 == 0 { b.lo.z } else { b.hi.z },
            ) - centre
        })
        .collect();
    let mut distance: f32 = 0.0;
    for step in 0..72 {
        let view = OrbitView {
            centre,
            distance: 1.0,
            elevation,
            azimuth: (step as f32 * 5.0).to_radians(),
            up,
        };
        let cam = view.camera("", width, height, vfov);
        // Camera axes in world space: rows of the world-to-camera rotation.
        let (right, down, forward) = (
            cam.rotation.row(0),
            cam.rotation.row(1),
            cam.rotation.row(2),
        );
        for c in &corners {
            // At distance d the corner sits at depth d + c.forward; it is inside the view
            // when |c.right| <= tan_x * depth and |c.down| <= tan_y * depth.
            let along = c.dot(forward);
            distance = distance
                .max(c.dot(right).abs() / tan_x - along)
                .max(c.dot(down).abs() / tan_y - along);
        }
    }
    // A flat or empty box still gets a usable distance.
    distance.max(1e-3)
}

/// One viewpoint on a sphere around `centre` (angles in radians).
pub(crate) struct OrbitView {
    pub centre: Vec3,
    pub distance: f32,
    pub elevation: f32,
    pub azimuth: f32,
    pub up: Vec3,
}

impl OrbitView {
    /// Camera centre: azimuth 0 lies towards -z (made perpendicular to `up`), growing
    /// towards `up x (-z)`, which is +x for up = -y.
    pub fn eye(&self) -> Vec3 {
        let up = self.up.normalize();
        let mut ahead = Vec3::NEG_Z - up * up.dot(Vec3::NEG_Z);
        if ahead.length_squared() < 1e-8 {
            // Up is along z: start on the -x side instead.
            ahead = Vec3::NEG_X - up * up.dot(Vec3::NEG_X);
        }
        let ahead = ahead.normalize();
        let side = up.cross(ahead);
        let horizontal = ahead * self.azimuth.cos() + side * self.azimuth.sin();
        let dir = horizontal * self.elevation.cos() + up * self.elevation.sin();
        self.centre + dir * self.distance
    }

    /// The camera at [`eye`](Self::eye) looking at `centre`; `vfov` in radians.
    pub fn camera(&self, name: &str, width: u32, height: u32, vfov: f32) -> Camera {
        Camera::look_at(name, width, height, vfov, self.eye(), self.centre, self.up)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_parameters_are_errors() {
        let ok = OrbitParams::default();
        let cases = [
            OrbitParams {
                frames: 0,
                ..ok.clone()
            },
            OrbitParams {
                width: 0,
                ..ok.clone()
            },
            OrbitParams {
                vfov_deg: 180.0,
                ..ok.clone()
            },
            OrbitParams {
                vfov_deg: f32::NAN,
                ..ok.clone()
            },
            OrbitParams {
                elevation_deg: 90.0,
                ..ok.clone()
            },
            OrbitParams {
                up: Vec3::ZERO,
                ..ok.clone()
            },
            OrbitParams {
                radius: Some(-1.0),
                ..ok.clone()
            },
            OrbitParams {
                centre: Some(Vec3::NAN),
                ..ok.clone()
            },
            OrbitParams {
                start_deg: f32::INFINITY,
                ..ok.clone()
            },
        ];
        for p in cases {
            assert!(
                matches!(orbit(&[[0.0; 3]], &p), Err(CameraError::BadParameter(_))),
                "{p:?}"
            );
        }
    }

    #[test]
    fn a_capture_s_cameras_give_its_up_and_centre() {
        // An orbit with z up around (1, 2, 3): its cameras give that up and centre back.
        let p = OrbitParams {
            frames: 12,
            up: Vec3::Z,
            centre: Some(Vec3::new(1.0, 2.0, 3.0)),
            radius: Some(4.0),
            elevation_deg: 25.0,
            ..Default::default()
        };
        let cams = orbit(&[], &p).unwrap();
        let (up, centre) = up_and_centre_of(&cams);
        assert!(up.unwrap().abs_diff_eq(Vec3::Z, 1e-4), "{up:?}");
        assert!(
            centre.unwrap().abs_diff_eq(Vec3::new(1.0, 2.0, 3.0), 1e-3),
            "{centre:?}"
        );
        // Parallel optical axes (a forward-facing capture) give no centre.
        let mut forward = cams[0].clone();
        let mut shifted = forward.clone();
        shifted.translation += Vec3::X;
        forward.name = "a".into();
        let (up, centre) = up_and_centre_of(&[forward, shifted]);
        assert!(up.is_some());
        assert_eq!(centre, None);
        assert_eq!(up_and_centre_of(&[]), (None, None));
    }

    #[test]
    fn up_along_z_still_orbits() {
        let p = OrbitParams {
            frames: 4,
            up: Vec3::Z,
            centre: Some(Vec3::ZERO),
            radius: Some(2.0),
            ..Default::default()
        };
        for c in orbit(&[], &p).unwrap() {
            c.validate().unwrap();
            assert!((c.position().length() - 2.0).abs() < 1e-5);
        }
    }
}
