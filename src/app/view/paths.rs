//! Keyframe paths from the page: the exported files (our keyframe JSON, nerfstudio's
//! camera_path.json) and the sampled frames the preview plays, made with the crate's own
//! writers and readers so that they are what `render --cameras` renders.

use super::protocol::{camera_from_entry, KeyframeIn, PathFormat};
use crate::core::camera::Camera;
use crate::io::camera::{keyframes, nerfstudio, PathTiming};
use std::path::Path;

/// The file of an exported path and its keyframes' cameras as `render --cameras` reads
/// them back from it.
pub fn export_path(
    format: PathFormat,
    fps: f32,
    keyframes: &[KeyframeIn],
) -> Result<(String, Vec<Camera>), String> {
    let (text, path) = keyframe_path(fps, keyframes)?;
    let at_keys: Vec<Camera> = path
        .keyframes()
        .iter()
        .enumerate()
        .map(|(i, k)| path.sample(k.time, format!("keyframe_{i}")))
        .collect();
    match format {
        PathFormat::Verisplat => Ok((text, at_keys)),
        PathFormat::Nerfstudio => {
            let frames = path
                .cameras(&PathTiming::default())
                .map_err(|e| format!("cannot sample the path: {e}"))?;
            let text = nerfstudio::to_camera_path_json(&frames, path.fps)
                .map_err(|e| format!("cannot export the camera path: {e}"))?;
            Ok((text, at_keys))
        }
    }
}

/// Most frames a path preview sends to the page.
pub const MAX_PREVIEW_FRAMES: usize = 10_000;

/// The frames of the keyframe path, as `render --cameras keyframes.json` renders them.
pub fn sample_path(fps: f32, keyframes: &[KeyframeIn]) -> Result<Vec<Camera>, String> {
    let (_, path) = keyframe_path(fps, keyframes)?;
    let frames = path
        .cameras(&PathTiming::default())
        .map_err(|e| format!("cannot sample the path: {e}"))?;
    if frames.len() > MAX_PREVIEW_FRAMES {
        return Err(format!(
            "the path has {} frames; a preview shows at most {MAX_PREVIEW_FRAMES} (lower Frames/s)",
            frames.len()
        ));
    }
    Ok(frames)
}

/// The keyframe file of the page's keyframes and the path it reads back as.
fn keyframe_path(
    fps: f32,
    keyframes: &[KeyframeIn],
) -> Result<(String, keyframes::KeyframePath), String> {
    if keyframes.is_empty() {
        return Err("no keyframes to export: add the current camera with \"Add\" first".into());
    }
    let mut cams = Vec::with_capacity(keyframes.len());
    let mut times = Vec::with_capacity(keyframes.len());
    for (i, k) in keyframes.iter().enumerate() {
        let c = camera_from_entry(&k.camera).map_err(|e| format!("keyframe {i}: {e}"))?;
        cams.push(c);
        times.push(k.time);
    }
    let text = keyframes::keyframes_to_json(&cams, &times, fps)
        .map_err(|e| format!("cannot export the keyframes: {e}"))?;
    let name = Path::new("keyframes.json");
    let path = keyframes::KeyframePath::parse(&text, name)
        .map_err(|e| format!("the exported keyframes do not read back: {e}"))?;
    Ok((text, path))
}
