//! One entry point for camera files: the format is recognised from the path (a COLMAP
//! sparse model is a directory or its `images`/`cameras` file) or from the JSON content.

use super::{colmap, inria, keyframes, nerfstudio, transforms, Camera, CameraError};
use crate::core::file_error::FileError;
use std::fmt;
use std::path::{Path, PathBuf};

/// The camera file formats [`load_camera_file`] understands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraFormat {
    /// INRIA `cameras.json`: a JSON list of camera entries.
    InriaJson,
    /// COLMAP sparse model, text (`cameras.txt` + `images.txt`).
    ColmapText,
    /// COLMAP sparse model, binary (`cameras.bin` + `images.bin`).
    ColmapBinary,
    /// nerfstudio `camera_path.json` (a JSON object with `camera_path`).
    NerfstudioPath,
    /// Our keyframe path (a JSON object with `keyframes`, see `docs/cameras.md`).
    Keyframes,
    /// nerfstudio / instant-ngp / NeRF-synthetic `transforms.json` (a JSON object with a
    /// `frames` list).
    Transforms,
}

impl fmt::Display for CameraFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CameraFormat::InriaJson => "INRIA cameras.json",
            CameraFormat::ColmapText => "COLMAP sparse model (text)",
            CameraFormat::ColmapBinary => "COLMAP sparse model (binary)",
            CameraFormat::NerfstudioPath => "nerfstudio camera path",
            CameraFormat::Keyframes => "verisplat keyframe path",
            CameraFormat::Transforms => "transforms.json",
        })
    }
}

/// Frame timing for keyframe paths; `None` keeps the file's own value. `frames` wins over
/// `fps` (frames are then spread evenly from the first to the last keyframe), and either
/// wins over the file's `frames`/`fps`. Other formats list their frames explicitly and
/// ignore it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathTiming {
    /// Total number of frames.
    pub frames: Option<usize>,
    /// Frames per second.
    pub fps: Option<f32>,
}

/// Where the cameras of `path` are: a COLMAP model directory, or JSON text and its file.
enum Source {
    Colmap(PathBuf),
    Json(String, PathBuf),
}

/// Loads every camera of a camera file and tells which format it was.
/// A directory holding a `cameras.json` (a trained model directory) stands for that file;
/// a COLMAP model is given as its directory (holding `cameras`+`images` `.bin` or `.txt`,
/// directly or under `sparse/0/` or `sparse/`) or as the path of one of those files;
/// anything else must be JSON: a list (INRIA), or an object with `camera_path`
/// (nerfstudio), `keyframes` (ours) or a `frames` list (`transforms.json`).
pub fn load_camera_file(
    path: &Path,
    timing: &PathTiming,
) -> Result<(Vec<Camera>, CameraFormat), CameraError> {
    let (cams, format) = match locate(path)? {
        Source::Colmap(dir) => colmap::load_colmap_model(&dir)?,
        Source::Json(text, file) => {
            let path = file.as_path();
            let kind = detect_json(&text, path)?;
            let cams = match kind {
                JsonKind::Inria => inria::parse_cameras_json(&text, path)?,
                JsonKind::Nerfstudio => nerfstudio::parse_camera_path(&text, path)?,
                JsonKind::Transforms => transforms::parse_transforms(&text, path)?,
                JsonKind::Keyframes => keyframes::KeyframePath::parse(&text, path)?
                    .cameras(timing)
                    // Without --frames/--fps overrides, a sampling error (too many frames,
                    // a degenerate camera) is the file's own, so it names the file.
                    .map_err(|e| match e {
                        CameraError::BadParameter(message) if *timing == PathTiming::default() => {
                            CameraError::File(FileError::Invalid {
                                path: path.to_path_buf(),
                                message,
                            })
                        }
                        other => other,
                    })?,
            };
            (cams, kind.format())
        }
    };
    if cams.is_empty() {
        return Err(CameraError::File(FileError::Invalid {
            path: path.to_path_buf(),
            message: format!("holds no cameras ({format})"),
        }));
    }
    Ok((cams, format))
}

/// The format [`load_camera_file`] would read `path` as, without converting any camera.
pub fn detect_camera_format(path: &Path) -> Result<CameraFormat, CameraError> {
    match locate(path)? {
        Source::Colmap(dir) => Ok(colmap::find_model(&dir)?.1),
        Source::Json(text, file) => Ok(detect_json(&text, &file)?.format()),
    }
}

/// The JSON camera formats, told apart by their top level.
enum JsonKind {
    Inria,
    Nerfstudio,
    Keyframes,
    Transforms,
}

impl JsonKind {
    fn format(&self) -> CameraFormat {
        match self {
            JsonKind::Inria => CameraFormat::InriaJson,
            JsonKind::Nerfstudio => CameraFormat::NerfstudioPath,
            JsonKind::Keyframes => CameraFormat::Keyframes,
            JsonKind::Transforms => CameraFormat::Transforms,
        }
    }
}

fn locate(path: &Path) -> Result<Source, CameraError> {
    let io = |source| {
        CameraError::File(FileError::Io {
            path: path.to_path_buf(),
            source,
        })
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    let model_cameras = path.join("cameras.json");
    if meta.is_dir() && model_cameras.is_file() {
        return locate(&model_cameras);
    }
    if meta.is_dir() {
        return Ok(Source::Colmap(path.to_path_buf()));
    }
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if matches!(
        name,
        "images.txt" | "images.bin" | "cameras.txt" | "cameras.bin"
    ) {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        return Ok(Source::Colmap(dir));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    let text = String::from_utf8(bytes).map_err(|_| {
        CameraError::File(FileError::Invalid {
            path: path.to_path_buf(),
            message:
                "is not a camera file: it is not UTF-8 text (JSON), and a COLMAP model must be \
                  given as its directory or as its images.bin/images.txt"
                    .into(),
        })
    })?;
    Ok(Source::Json(text, path.to_path_buf()))
}

fn detect_json(text: &str, path: &Path) -> Result<JsonKind, CameraError> {
    let invalid = |message: String| {
        CameraError::File(FileError::Invalid {
            path: path.to_path_buf(),
            message,
        })
    };
    let value: serde_json::Value = serde_json::from_str(text).map_err(|e| {
        invalid(format!(
            "is not a camera file: not valid JSON ({e}); expected an INRIA cameras.json, a \
             nerfstudio camera_path.json, a transforms.json, a keyframe path, or a COLMAP \
             model directory"
        ))
    })?;
    match &value {
        serde_json::Value::Array(_) => Ok(JsonKind::Inria),
        serde_json::Value::Object(map) if map.contains_key("camera_path") => {
            Ok(JsonKind::Nerfstudio)
        }
        serde_json::Value::Object(map) if map.contains_key("keyframes") => Ok(JsonKind::Keyframes),
        serde_json::Value::Object(map) if map.get("frames").is_some_and(|f| f.is_array()) => {
            Ok(JsonKind::Transforms)
        }
        serde_json::Value::Object(map) => Err(invalid(format!(
            "is a JSON object with no \"camera_path\" (nerfstudio), \"keyframes\" (keyframe \
             path) or \"frames\" list (transforms.json); its keys are: {}",
            map.keys().take(8).cloned().collect::<Vec<_>>().join(", ")
        ))),
        _ => Err(invalid(
            "is JSON but not a camera file: expected a list (INRIA cameras.json) or an object \
             (nerfstudio camera path, transforms.json or keyframe path)"
                .into(),
        )),
    }
}
