//! Camera files: INRIA `cameras.json` ([`inria`]), COLMAP sparse models ([`colmap`]),
//! nerfstudio camera paths ([`nerfstudio`]) and `transforms.json` ([`transforms`]), our
//! keyframe paths ([`keyframes`]), and the detection of a file's kind ([`load_camera_file`]).
//! The cameras themselves, their lenses and the conventions are
//! [`crate::core::camera`].

pub mod colmap;
pub mod inria;
pub mod keyframes;
mod load;
pub mod nerfstudio;
pub mod transforms;

pub use inria::{load_cameras_json, parse_cameras_json};
pub use keyframes::{keyframes_to_json, KeyframePath};
pub use load::{detect_camera_format, load_camera_file, CameraFormat, PathTiming};

// What the readers share with the camera model (`super::` in each of them).
use crate::core::camera::{
    camera_from_c2w, check_resolution, distortion, quat_wxyz_to_mat, rotation_error, Camera,
    CameraError, Lens, MAX_IMAGE_SIDE,
};
