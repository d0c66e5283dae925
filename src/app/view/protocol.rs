//! The messages between the page and the server.
//!
//! Page to server: JSON text, `{"type": ..., "seq": N, ...}` ([`ClientMessage`]). Cameras
//! are INRIA `cameras.json` entries (`position`, `rotation` camera-to-world rows, `fx`,
//! `fy`, `width`, `height`, optional `cx`, `cy`), read by the same code as `--cameras`.
//! Server to page: JSON text for the scene (`hello`), errors, snapped cameras and exports
//! ([`ServerMessage`]); binary for frames and screenshots: a little-endian `u32` header
//! length, the JSON header ([`FrameHeader`], [`ShotHeader`]), then the image bytes.

use super::source::{ShotFormat, ViewSettings};
use crate::core::camera::Camera;
use crate::io::camera::inria;
use crate::render::StageTimings;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

/// Protocol version in `hello`; the page refuses another.
pub const PROTOCOL_VERSION: u32 = 1;

/// A message from the page.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// Render this camera (its size is the canvas's) with these settings (or the last
    /// ones); `interactive` asks for a fast preview frame (smaller, JPEG), and a full
    /// frame follows when the camera rests.
    View {
        #[serde(default)]
        seq: u64,
        camera: Value,
        #[serde(default)]
        settings: Option<ViewSettings>,
        #[serde(default)]
        interactive: bool,
    },
    /// New settings for the last camera.
    Settings {
        #[serde(default)]
        seq: u64,
        settings: ViewSettings,
    },
    /// The camera rests: render the last request at full quality.
    Rest {
        #[serde(default)]
        seq: u64,
    },
    /// Snap to scene camera `index` (its pose and intrinsics); the server answers with a
    /// `camera` message and renders it at `width` x `height` (the camera's own size when
    /// absent; one alone keeps its aspect ratio).
    SelectCamera {
        #[serde(default)]
        seq: u64,
        index: usize,
        #[serde(default)]
        width: Option<u32>,
        #[serde(default)]
        height: Option<u32>,
    },
    /// The view (this camera, or the last one) at full resolution as a file.
    Screenshot {
        #[serde(default)]
        seq: u64,
        format: ShotFormat,
        #[serde(default)]
        camera: Option<Value>,
        #[serde(default)]
        settings: Option<ViewSettings>,
    },
    /// Export keyframes as a camera path file.
    ExportKeyframes {
        #[serde(default)]
        seq: u64,
        format: PathFormat,
        fps: f32,
        keyframes: Vec<KeyframeIn>,
    },
    /// The frames of the keyframe path (as `render --cameras` renders the exported
    /// file), for the page's preview; answered with a `path` message.
    SampleKeyframes {
        #[serde(default)]
        seq: u64,
        fps: f32,
        keyframes: Vec<KeyframeIn>,
    },
}

/// A keyframe as the page sends it.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyframeIn {
    /// Seconds from the start of the path.
    pub time: f64,
    /// The camera; every keyframe's size must be the first one's.
    pub camera: Value,
}

/// Camera path file formats of an export.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PathFormat {
    /// Our keyframe JSON (`render --cameras` reads it; docs/cameras.md).
    Verisplat,
    /// nerfstudio's `camera_path.json`, the path sampled at its fps.
    Nerfstudio,
}

/// A scene camera in `hello`.
#[derive(Debug, Serialize)]
pub struct NamedCamera {
    /// Its name (the image name of cameras.json).
    pub name: String,
    /// Its cameras.json entry.
    pub camera: Value,
}

/// What the page learns about the scene on connecting.
#[derive(Debug, Serialize)]
pub struct Hello {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// The scene's name (its file).
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// The scene's SH degree (the SH slider's maximum).
    pub sh_degree: u32,
    /// Centre of the robust bounding box: the default orbit focus.
    pub centre: [f32; 3],
    /// Robust bounding box (2nd-98th percentile per axis), low corner.
    pub bounds_lo: [f32; 3],
    /// Robust bounding box, high corner.
    pub bounds_hi: [f32; 3],
    /// Size of the scene's bulk (its robust radius): the unit of fly speed and zoom.
    pub size: f32,
    /// Smallest and largest per-Gaussian max scale (the edges of the log-binned
    /// histogram of `info`): the range of the max-scale slider.
    pub max_scale_range: [f64; 2],
    /// The log-binned histogram of the per-Gaussian max scale (bin edges, one more than
    /// the counts), drawn under the slider.
    pub max_scale_histogram: ScaleHistogram,
    /// World up (-y for INRIA/COLMAP scenes).
    pub up: [f32; 3],
    /// The scene's cameras.
    pub cameras: Vec<NamedCamera>,
    /// The camera the page starts from.
    pub initial_camera: Value,
    /// What renders the frames.
    pub device: String,
    /// Largest frame, `--max-resolution`.
    pub max_resolution: [u32; 2],
    /// Pixels of a preview frame while the camera moves.
    pub preview_pixels: u32,
}

/// A histogram in `hello`.
#[derive(Debug, Default, Serialize)]
pub struct ScaleHistogram {
    /// Bin edges, increasing.
    pub edges: Vec<f64>,
    /// Gaussians per bin.
    pub counts: Vec<usize>,
}

/// A text message to the page.
#[derive(Debug, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// The scene, on connecting.
    Hello(Box<Hello>),
    /// A request failed; `seq` is its sequence number.
    Error {
        /// One sentence for the page's banner.
        message: String,
        /// The request's `seq`, if the message was understood that far.
        seq: Option<u64>,
    },
    /// The camera a `select_camera` snapped to, at the size it is rendered.
    Camera {
        /// The request's `seq`.
        seq: u64,
        /// Scene camera index.
        index: usize,
        /// Its cameras.json entry.
        camera: Value,
    },
    /// An exported camera path.
    Export {
        /// The request's `seq`.
        seq: u64,
        /// Its format.
        format: PathFormat,
        /// A file name for the download.
        filename: String,
        /// The file's text.
        text: String,
        /// The keyframes as `render --cameras` reads them back from the file (the view at
        /// each keyframe equals the rendered frame at its time).
        cameras: Vec<Value>,
    },
    /// The frames of a keyframe path, for the preview.
    Path {
        /// The request's `seq`.
        seq: u64,
        /// Frames per second.
        fps: f64,
        /// One cameras.json entry per frame.
        cameras: Vec<Value>,
    },
}

/// How a frame is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// While moving: smaller, JPEG.
    Preview,
    /// At rest: the requested size (capped by `--max-resolution`), lossless PNG.
    Full,
}

/// The header of a binary frame message.
#[derive(Debug, Serialize)]
pub struct FrameHeader {
    /// `"frame"`.
    pub kind: &'static str,
    /// The request's sequence number.
    pub seq: u64,
    /// Rendered width.
    pub width: u32,
    /// Rendered height.
    pub height: u32,
    /// Preview or full.
    pub quality: Quality,
    /// `"jpeg"` or `"png"`.
    pub encoding: &'static str,
    /// Stage times.
    pub timings: StageTimings,
    /// Gaussians the frame was drawn from (a preview may draw the most important only).
    pub gaussians: u32,
    /// Gaussians that touched a tile.
    pub visible: u32,
    /// (tile, Gaussian) pairs.
    pub pairs: u64,
    /// Wall time of the render call, ms.
    pub wall_ms: f64,
    /// Encoding time, ms.
    pub encode_ms: f64,
}

/// The header of a binary screenshot message.
#[derive(Debug, Serialize)]
pub struct ShotHeader {
    /// `"screenshot"`.
    pub kind: &'static str,
    /// The request's sequence number.
    pub seq: u64,
    /// PNG or EXR.
    pub format: ShotFormat,
    /// A file name for the download.
    pub filename: String,
}

/// A binary message: header length (`u32` little-endian), JSON header, payload.
pub fn binary_message(header: &impl Serialize, payload: &[u8]) -> Vec<u8> {
    // Serialising these plain structs cannot fail.
    let json = serde_json::to_vec(header).unwrap_or_default();
    let mut out = Vec::with_capacity(4 + json.len() + payload.len());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(payload);
    out
}

/// Splits a binary message into its JSON header and payload.
pub fn split_binary(message: &[u8]) -> Option<(Value, &[u8])> {
    let len = u32::from_le_bytes(message.get(..4)?.try_into().ok()?) as usize;
    let header = message.get(4..4usize.checked_add(len)?)?;
    let value = serde_json::from_slice(header).ok()?;
    Some((value, &message[4 + len..]))
}

/// Reads a camera entry with the `cameras.json` reader (so it is the camera `render
/// --cameras` makes of the same entry); the message says what is wrong.
pub fn camera_from_entry(entry: &Value) -> Result<Camera, String> {
    let text = format!("[{entry}]");
    let mut cams =
        inria::parse_cameras_json(&text, Path::new("the camera")).map_err(|e| e.to_string())?;
    cams.pop()
        .ok_or_else(|| "the camera entry is empty".to_string())
}

/// A camera as a `cameras.json` entry (the writer of `render --export-cameras`).
pub fn camera_to_entry(cam: &Camera, id: usize) -> Result<Value, String> {
    let text = inria::to_json(&[(id, cam.clone())]).map_err(|e| e.to_string())?;
    let mut list: Vec<Value> = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    list.pop()
        .ok_or_else(|| "the camera writer wrote no entry".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_entries_round_trip() {
        let cam = crate::core::camera::default_camera(&[[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]], 96, 64);
        let entry = camera_to_entry(&cam, 3).unwrap();
        let back = camera_from_entry(&entry).unwrap();
        assert_eq!((back.width, back.height), (96, 64));
        assert_eq!(back.rotation, cam.rotation);
        assert!((back.translation - cam.translation).length() < 1e-5);
        // NaN arrives as null from JSON.stringify; infinities do not parse.
        let mut bad = entry.clone();
        bad["position"][0] = Value::Null;
        assert!(camera_from_entry(&bad).is_err());
        bad = entry.clone();
        bad["width"] = 0.into();
        assert!(camera_from_entry(&bad).is_err());
    }

    #[test]
    fn a_cameras_lens_survives_the_page() {
        // The page keeps an entry's "lens" and sends it back with its moves.
        let cam = Camera {
            lens: crate::core::camera::Lens::Fisheye {
                k: [0.01, 0.0, 0.0, 0.0],
                max_theta: 1.6,
            },
            ..Camera::look_at(
                "fish",
                64,
                48,
                1.0,
                glam::Vec3::ZERO,
                glam::Vec3::Z,
                glam::Vec3::NEG_Y,
            )
        };
        let entry = camera_to_entry(&cam, 0).unwrap();
        assert!(entry.get("lens").is_some(), "{entry}");
        assert_eq!(camera_from_entry(&entry).unwrap().lens, cam.lens);
    }

    #[test]
    fn messages_parse_and_refuse() {
        let m: ClientMessage = serde_json::from_str(r#"{"type":"rest","seq":4}"#).unwrap();
        assert!(matches!(m, ClientMessage::Rest { seq: 4 }));
        let m: ClientMessage =
            serde_json::from_str(r#"{"type":"settings","settings":{"scale_modifier":0.5}}"#)
                .unwrap();
        let ClientMessage::Settings { settings, .. } = m else {
            panic!("settings")
        };
        assert_eq!(settings.scale_modifier, 0.5);
        assert_eq!(settings.mode, super::super::source::ViewMode::Rgb);
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"dance"}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"seq":1}"#).is_err());
        let bin = binary_message(&serde_json::json!({"kind": "frame"}), b"abc");
        let (h, p) = split_binary(&bin).unwrap();
        assert_eq!(h["kind"], "frame");
        assert_eq!(p, b"abc");
        assert!(split_binary(&[9, 0, 0, 0, b'{']).is_none());
    }
}
