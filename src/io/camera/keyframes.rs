//! Our keyframe camera paths (schema in `docs/cameras.md`): a few keyframes with a time,
//! a position and either a target to look at or a camera-to-world rotation, sampled into
//! frames. Positions (and look-at targets) follow a Catmull-Rom spline in time, rotations
//! a shortest-path slerp, the field of view a straight line; every sample at a keyframe's
//! time is that keyframe exactly.

use super::{
    camera_from_c2w, check_resolution, quat_wxyz_to_mat, rotation_error, Camera, CameraError,
    PathTiming,
};
use crate::core::file_error::FileError;
use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The only schema version so far.
pub const KEYFRAME_VERSION: u32 = 1;
/// Frames per second when the file gives none.
pub const DEFAULT_FPS: f64 = 30.0;
/// Largest number of frames a generated path (keyframes or orbit) may have.
pub use crate::core::camera::MAX_PATH_FRAMES as MAX_FRAMES;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileJson {
    version: u32,
    width: u32,
    height: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    fps: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frames: Option<usize>,
    keyframes: Vec<KeyframeJson>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyframeJson {
    time: f64,
    position: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    look_at: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    rotation: Option<[f64; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    up: Option<[f64; 3]>,
    vfov: f64,
}

/// How a keyframe's camera is turned.
#[derive(Clone, Debug, PartialEq)]
pub enum Orientation {
    /// Looks at `target` with `up` as the world's up (default -y).
    LookAt {
        /// Point looked at.
        target: DVec3,
        /// World up direction (unit length).
        up: DVec3,
    },
    /// Camera-to-world rotation in OpenCV camera axes (unit quaternion).
    Rotation(DQuat),
}

/// One validated keyframe.
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    /// Time in seconds.
    pub time: f64,
    /// Camera centre in world space.
    pub position: DVec3,
    /// Where the camera looks.
    pub orientation: Orientation,
    /// Vertical field of view in degrees.
    pub vfov_deg: f64,
}

/// A validated keyframe path (built by [`KeyframePath::parse`]).
#[derive(Clone, Debug, PartialEq)]
pub struct KeyframePath {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Frames per second (the file's, or [`DEFAULT_FPS`]).
    pub fps: f64,
    /// Total frame count, spread evenly from the first to the last keyframe, if the file
    /// gives one.
    pub frames: Option<usize>,
    /// Keyframes: at least one, strictly increasing in time (private so that holds).
    keyframes: Vec<Keyframe>,
}

impl KeyframePath {
    /// The keyframes, in time order.
    pub fn keyframes(&self) -> &[Keyframe] {
        &self.keyframes
    }

    /// Parses and validates a keyframe file held in memory (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Self, CameraError> {
        let invalid = |message: String| {
            CameraError::File(FileError::Invalid {
                path: path.to_path_buf(),
                message,
            })
        };
        let file: FileJson = serde_json::from_str(text).map_err(|e| {
            invalid(format!(
                "is not a keyframe path ({{version, width, height, fps, frames, keyframes: \
                 [{{time, position, look_at | rotation, up, vfov}}]}}, see docs/cameras.md): {e}"
            ))
        })?;
        if file.version != KEYFRAME_VERSION {
            return Err(invalid(format!(
                "keyframe path version {} is not supported (this build reads version {KEYFRAME_VERSION})",
                file.version
            )));
        }
        check_resolution(file.width, file.height).map_err(|e| invalid(e.to_string()))?;
        let fps = file.fps.unwrap_or(DEFAULT_FPS);
        check_fps(fps).map_err(invalid)?;
        if let Some(n) = file.frames {
            check_frames(n).map_err(invalid)?;
        }
        if file.keyframes.is_empty() {
            return Err(invalid("has no keyframes".into()));
        }
        let mut keyframes: Vec<Keyframe> = Vec::with_capacity(file.keyframes.len());
        for (i, k) in file.keyframes.iter().enumerate() {
            let bad = |what: String| invalid(format!("keyframe {i} (time {}): {what}", k.time));
            if !k.time.is_finite() {
                return Err(bad("time is not a finite number".into()));
            }
            if let Some(prev) = keyframes.last() {
                if k.time <= prev.time {
                    return Err(bad(format!(
                        "keyframe times must be strictly increasing, but the previous keyframe is at {}",
                        prev.time
                    )));
                }
            }
            let position = DVec3::from_array(k.position);
            if !position.is_finite() {
                return Err(bad("position is not finite".into()));
            }
            if !(k.vfov.is_finite() && k.vfov > 0.0 && k.vfov < 180.0) {
                return Err(bad(format!(
                    "vfov {} degrees must be between 0 and 180",
                    k.vfov
                )));
            }
            let orientation = match (k.look_at, k.rotation) {
                (Some(target), None) => {
                    let target = DVec3::from_array(target);
                    let up = DVec3::from_array(k.up.unwrap_or([0.0, -1.0, 0.0]));
                    if !(target.is_finite() && up.is_finite() && up.length() > 1e-12) {
                        return Err(bad("look_at and up must be finite, up non-zero".into()));
                    }
                    let up = up.normalize();
                    let forward = target - position;
                    if forward.length() < 1e-9 {
                        return Err(bad("look_at is the camera position itself".into()));
                    }
                    if forward.normalize().cross(up).length() < 1e-6 {
                        return Err(bad(
                            "looks straight along up, so the roll is undefined; give another up or a rotation".into(),
                        ));
                    }
                    Orientation::LookAt { target, up }
                }
                (None, Some(q)) => {
                    if k.up.is_some() {
                        return Err(bad("up only goes with look_at, not with rotation".into()));
                    }
                    let m = quat_wxyz_to_mat(q).ok_or_else(|| {
                        bad(format!("rotation {q:?} has zero length or is not finite"))
                    })?;
                    Orientation::Rotation(DQuat::from_mat3(&m).normalize())
                }
                (Some(_), Some(_)) => return Err(bad("give look_at or rotation, not both".into())),
                (None, None) => return Err(bad("needs look_at or rotation".into())),
            };
            keyframes.push(Keyframe {
                time: k.time,
                position,
                orientation,
                vfov_deg: k.vfov,
            });
        }
        Ok(KeyframePath {
            width: file.width,
            height: file.height,
            fps,
            frames: file.frames,
            keyframes,
        })
    }

    /// Times of the frames: with a frame count (from `timing`, else the file, unless
    /// `timing` gives an fps) evenly from the first to the last keyframe, both included;
    /// otherwise every `1 / fps` seconds from the first keyframe up to the last.
    pub fn frame_times(&self, timing: &PathTiming) -> Result<Vec<f64>, CameraError> {
        let bad = CameraError::BadParameter;
        let t0 = self.keyframes[0].time;
        let tn = self.keyframes[self.keyframes.len() - 1].time;
        let frames = match (timing.frames, timing.fps) {
            (Some(n), _) => Some(n),
            (None, Some(_)) => None,
            (None, None) => self.frames,
        };
        if let Some(n) = frames {
            check_frames(n).map_err(bad)?;
            if n == 1 {
                return Ok(vec![t0]);
            }
            let mut times: Vec<f64> = (0..n)
                .map(|k| t0 + (tn - t0) * (k as f64 / (n - 1) as f64))
                .collect();
            times[n - 1] = tn;
            return Ok(times);
        }
        let fps = timing.fps.map_or(self.fps, f64::from);
        check_fps(fps).map_err(bad)?;
        let span = (tn - t0) * fps;
        if span + 1.0 > MAX_FRAMES as f64 {
            return Err(bad(format!(
                "the path lasts {:.1} s; at {fps} fps that is more than {MAX_FRAMES} frames",
                tn - t0
            )));
        }
        let n = (span + 1e-9).floor() as usize + 1;
        Ok((0..n).map(|k| t0 + k as f64 / fps).collect())
    }

    /// The frames of the path, named `frame_00000`, `frame_00001`, ...
    pub fn cameras(&self, timing: &PathTiming) -> Result<Vec<Camera>, CameraError> {
        let cams: Vec<Camera> = self
            .frame_times(timing)?
            .into_iter()
            .enumerate()
            .map(|(k, t)| self.sample(t, format!("frame_{k:05}")))
            .collect();
        for c in &cams {
            c.validate()?;
        }
        Ok(cams)
    }

    /// The camera at time `t` (clamped to the keyframes' span).
    pub fn sample(&self, t: f64, name: String) -> Camera {
        let keys = &self.keyframes;
        let last = keys.len() - 1;
        // Segment i spans keys[i]..keys[i + 1]; s is the fraction of it at t.
        let (i, s) = if t <= keys[0].time || last == 0 {
            (0, 0.0)
        } else if t >= keys[last].time {
            (last - 1, 1.0)
        } else {
            let i = keys.partition_point(|k| k.time <= t) - 1;
            (i, (t - keys[i].time) / (keys[i + 1].time - keys[i].time))
        };
        // Exactly at a keyframe: that keyframe, untouched by any arithmetic.
        let exact = if s == 0.0 {
            Some(&keys[i])
        } else if s == 1.0 {
            Some(&keys[i + 1])
        } else {
            None
        };
        let (position, c2w, vfov) = match exact {
            Some(k) => (k.position, self.key_c2w(k), k.vfov_deg),
            None => {
                let position = self.spline(i, s, |k| k.position);
                let all_look_at = keys
                    .iter()
                    .all(|k| matches!(k.orientation, Orientation::LookAt { .. }));
                let c2w = if all_look_at {
                    // Keep looking at the (interpolated) target, not just near it.
                    let target = self.spline(i, s, |k| match k.orientation {
                        Orientation::LookAt { target, .. } => target,
                        Orientation::Rotation(_) => DVec3::ZERO,
                    });
                    let up_of = |k: &Keyframe| match k.orientation {
                        Orientation::LookAt { up, .. } => up,
                        Orientation::Rotation(_) => DVec3::NEG_Y,
                    };
                    let up = up_of(&keys[i]).lerp(up_of(&keys[i + 1]), s);
                    look_at_c2w(position, target, up)
                } else {
                    let a = self.key_quat(&keys[i]);
                    let mut b = self.key_quat(&keys[i + 1]);
                    if a.dot(b) < 0.0 {
                        b = -b;
                    }
                    DMat3::from_quat(a.slerp(b, s).normalize())
                };
                let vfov = keys[i].vfov_deg + (keys[i + 1].vfov_deg - keys[i].vfov_deg) * s;
                (position, c2w, vfov)
            }
        };
        let focal = self.height as f64 / (2.0 * (vfov.to_radians() * 0.5).tan());
        camera_from_c2w(
            name,
            self.width,
            self.height,
            [focal, focal],
            [self.width as f64 / 2.0, self.height as f64 / 2.0],
            c2w,
            position,
        )
    }

    fn key_c2w(&self, k: &Keyframe) -> DMat3 {
        match k.orientation {
            Orientation::LookAt { target, up } => look_at_c2w(k.position, target, up),
            Orientation::Rotation(q) => DMat3::from_quat(q),
        }
    }

    fn key_quat(&self, k: &Keyframe) -> DQuat {
        match k.orientation {
            Orientation::LookAt { .. } => DQuat::from_mat3(&self.key_c2w(k)).normalize(),
            Orientation::Rotation(q) => q,
        }
    }

    /// Catmull-Rom in time on segment `i` at fraction `s`: a cubic Hermite curve whose
    /// tangents are `(p[i+1] - p[i-1]) / (t[i+1] - t[i-1])`, the ends duplicated.
    fn spline(&self, i: usize, s: f64, value: impl Fn(&Keyframe) -> DVec3) -> DVec3 {
        let keys = &self.keyframes;
        let last = keys.len() - 1;
        let tangent = |j: usize| -> DVec3 {
            // A duplicated end point sits one segment beyond the end, at the same place.
            let (a, ta) = if j == 0 {
                (value(&keys[0]), 2.0 * keys[0].time - keys[1].time)
            } else {
                (value(&keys[j - 1]), keys[j - 1].time)
            };
            let (b, tb) = if j == last {
                (
                    value(&keys[last]),
                    2.0 * keys[last].time - keys[last - 1].time,
                )
            } else {
                (value(&keys[j + 1]), keys[j + 1].time)
            };
            (b - a) / (tb - ta)
        };
        let h = keys[i + 1].time - keys[i].time;
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        value(&keys[i]) * h00
            + tangent(i) * (h10 * h)
            + value(&keys[i + 1]) * h01
            + tangent(i + 1) * (h11 * h)
    }
}

/// Camera-to-world rotation (columns right, down, forward) of a camera at `eye` looking
/// at `target` with `up` as the world's up; any roll when looking along `up`.
fn look_at_c2w(eye: DVec3, target: DVec3, up: DVec3) -> DMat3 {
    let forward = (target - eye).normalize_or(DVec3::Z);
    let down = -up.normalize_or(DVec3::NEG_Y);
    let mut right = down.cross(forward);
    if right.length_squared() < 1e-18 {
        right = forward.any_orthonormal_vector();
    }
    let right = right.normalize();
    DMat3::from_cols(right, forward.cross(right), forward)
}

fn check_fps(fps: f64) -> Result<(), String> {
    if fps.is_finite() && fps > 0.0 {
        Ok(())
    } else {
        Err(format!("fps {fps} must be a positive number"))
    }
}

fn check_frames(n: usize) -> Result<(), String> {
    if (1..=MAX_FRAMES).contains(&n) {
        Ok(())
    } else {
        Err(format!("frames {n} must be between 1 and {MAX_FRAMES}"))
    }
}

/// Writes `cams` as a keyframe path with keyframe `i` at `times[i]` (seconds, strictly
/// increasing), as rotations so any camera round-trips. Keyframes hold one resolution
/// and a vertical field of view per key, so the cameras must share a resolution; their
/// `fy` is kept (as vfov) while `fx` and the principal point are not (a keyframe camera
/// has square pixels and a centred principal point).
pub fn keyframes_to_json(cams: &[Camera], times: &[f64], fps: f32) -> Result<String, CameraError> {
    let bad = |m: String| Err(CameraError::BadParameter(m));
    let Some(first) = cams.first() else {
        return bad("a keyframe path needs at least one camera".into());
    };
    if cams.len() != times.len() {
        return bad(format!(
            "{} cameras but {} keyframe times",
            cams.len(),
            times.len()
        ));
    }
    check_fps(fps as f64).map_err(CameraError::BadParameter)?;
    let mut keyframes = Vec::with_capacity(cams.len());
    for (i, (c, &time)) in cams.iter().zip(times).enumerate() {
        c.validate()?;
        if !time.is_finite() || (i > 0 && time <= times[i - 1]) {
            return bad(format!(
                "keyframe times must be finite and strictly increasing; time {i} is {time}"
            ));
        }
        if (c.width, c.height) != (first.width, first.height) {
            return bad(format!(
                "camera \"{}\" is {}x{} but the first is {}x{}; a keyframe path has one resolution",
                c.name, c.width, c.height, first.width, first.height
            ));
        }
        let w2c = c.rotation.as_dmat3();
        let err = rotation_error(w2c);
        if err > 1e-4 {
            return bad(format!(
                "camera \"{}\" has a rotation that is not orthonormal (off by {err:.2e})",
                c.name
            ));
        }
        let c2w = w2c.transpose();
        let position = -(c2w * c.translation.as_dvec3());
        let q = DQuat::from_mat3(&c2w).normalize();
        let vfov = 2.0 * (c.height as f64 / (2.0 * c.fy as f64)).atan();
        keyframes.push(KeyframeJson {
            time,
            position: position.to_array(),
            look_at: None,
            rotation: Some([q.w, q.x, q.y, q.z]),
            up: None,
            vfov: vfov.to_degrees(),
        });
    }
    let file = FileJson {
        version: KEYFRAME_VERSION,
        width: first.width,
        height: first.height,
        fps: Some(fps as f64),
        frames: None,
        keyframes,
    };
    serde_json::to_string_pretty(&file)
        .map_err(|e| CameraError::BadParameter(format!("cannot write the keyframe path: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_matrix_matches_glam() {
        for q in [
            DQuat::from_xyzw(0.1, -0.7, 0.3, 0.6).normalize(),
            DQuat::from_rotation_y(2.0),
            DQuat::IDENTITY,
        ] {
            let ours = quat_wxyz_to_mat([q.w, q.x, q.y, q.z]).unwrap();
            let glam = DMat3::from_quat(q);
            assert!(ours.abs_diff_eq(glam, 1e-12), "{ours} vs {glam}");
            // The scale of the quaternion does not matter.
            let scaled = quat_wxyz_to_mat([3.0 * q.w, 3.0 * q.x, 3.0 * q.y, 3.0 * q.z]).unwrap();
            assert!(scaled.abs_diff_eq(glam, 1e-12));
        }
        assert!(quat_wxyz_to_mat([0.0; 4]).is_none());
        assert!(quat_wxyz_to_mat([f64::NAN, 0.0, 0.0, 1.0]).is_none());
        assert!(quat_wxyz_to_mat([f64::INFINITY, 0.0, 0.0, 1.0]).is_none());
    }

    #[test]
    fn spline_is_exact_at_keys_and_linear_for_linear_motion() {
        let text = r#"{"version":1,"width":64,"height":48,"keyframes":[
            {"time":0,"position":[0,0,-5],"look_at":[0,0,0],"vfov":40},
            {"time":1,"position":[1,0,-5],"look_at":[1,0,0],"vfov":40},
            {"time":3,"position":[3,0,-5],"look_at":[3,0,0],"vfov":40},
            {"time":4,"position":[4,0,-5],"look_at":[4,0,0],"vfov":40}]}"#;
        let p = KeyframePath::parse(text, Path::new("k.json")).unwrap();
        // Catmull-Rom in time reproduces motion at constant speed between interior keys.
        for t in [1.25, 1.5, 2.0, 2.75] {
            let c = p.sample(t, "x".into());
            assert!(
                (c.position() - glam::Vec3::new(t as f32, 0.0, -5.0)).length() < 1e-5,
                "{t}"
            );
        }
        assert_eq!(p.frame_times(&PathTiming::default()).unwrap().len(), 121);
        let even = p
            .frame_times(&PathTiming {
                frames: Some(5),
                fps: None,
            })
            .unwrap();
        assert_eq!(even, vec![0.0, 1.0, 2.0, 3.0, 4.0]);
    }
}
