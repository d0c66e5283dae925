//! The camera a benchmark times ([`BenchCamera`]) and how reports name it ([`CameraReport`]).

use crate::core::camera::Camera;
use serde::Serialize;

/// The camera a benchmark times and where it comes from.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchCamera {
    /// The camera, at the benchmarked resolution.
    pub camera: Camera,
    /// Its index in the camera file, if it comes from one.
    pub index: Option<usize>,
    /// Where it comes from: the camera file described (`path (format, N cameras)`), or
    /// `the default camera` (framing the scene).
    pub source: String,
}

/// Which camera was timed, as reported.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CameraReport {
    /// The camera's name (`img_name` of a cameras.json, `default` for the default camera).
    pub name: String,
    /// Its index in the camera file (`null` for the default camera).
    pub index: Option<usize>,
    /// The camera file described (`path (format, N cameras)`), or `the default camera`.
    pub source: String,
}

impl BenchCamera {
    pub(super) fn report(&self) -> CameraReport {
        CameraReport {
            name: self.camera.name.clone(),
            index: self.index,
            source: self.source.clone(),
        }
    }

    /// `"name" (index 3 of cameras.json)` or `"default" (default camera)`.
    pub fn describe(&self) -> String {
        describe_camera(&self.report())
    }
}

pub(super) fn describe_camera(c: &CameraReport) -> String {
    match c.index {
        Some(i) => format!("\"{}\" (camera {i} of {})", c.name, c.source),
        None => format!("\"{}\" ({})", c.name, c.source),
    }
}
