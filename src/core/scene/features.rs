//! Feature channels attached from a NumPy file (`--features FILE.npy`): an `N x K` array
//! of float32 or float16 (float64 too), one row per Gaussian of the scene, 1 <= K <= 64.

use super::{Scene, SceneError, MAX_FEATURES};
use std::path::Path;

/// Reads `path` as `N x K` features for `scene` and attaches them (replacing any the scene
/// had). Errors name the file: not a float array, not two-dimensional, N not the scene's
/// Gaussian count, K outside 1..=64, or a NaN or infinite value (with its row and column).
pub fn attach_npy(scene: &mut Scene, path: &Path) -> Result<(), SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let (k, data) = parse_npy(&bytes, path, scene.len())?;
    scene
        .set_features(k, data)
        .map_err(|m| SceneError::invalid(path, m))
}

/// Parses the bytes of an `N x K` feature array for a scene of `n` Gaussians.
pub fn parse_npy(bytes: &[u8], path: &Path, n: usize) -> Result<(usize, Vec<f32>), SceneError> {
    let array = crate::core::npy::parse_npy_array(bytes, path)
        .map_err(|e| SceneError::invalid(path, strip_path(&e.to_string(), path)))?;
    let (rows, k) = match array.shape[..] {
        [rows, k] => (rows, k),
        [rows] => (rows, 1),
        _ => {
            return Err(SceneError::invalid(
                path,
                format!(
                "has shape {:?}; features are an N x K array (one row of K channels per Gaussian)",
                array.shape
            ),
            ))
        }
    };
    if rows != n {
        return Err(SceneError::invalid(
            path,
            format!("has {rows} rows of features, but the scene has {n} Gaussians"),
        ));
    }
    if !(1..=MAX_FEATURES).contains(&k) {
        return Err(SceneError::invalid(
            path,
            format!("has {k} feature channels per Gaussian; 1 to {MAX_FEATURES} are supported"),
        ));
    }
    if let Some(at) = array.data.iter().position(|v| !v.is_finite()) {
        return Err(SceneError::invalid(
            path,
            format!(
                "has a non-finite feature ({}) at row {}, channel {}",
                array.data[at],
                at / k,
                at % k
            ),
        ));
    }
    Ok((k, array.data))
}

/// The image reader's message without its leading `path: `.
fn strip_path(message: &str, path: &Path) -> String {
    let prefix = format!("{}: ", path.display());
    message.strip_prefix(&prefix).unwrap_or(message).to_string()
}

/// Per channel: minimum, mean and maximum over the Gaussians.
pub fn channel_stats(scene: &Scene) -> Vec<[f64; 3]> {
    let k = scene.feature_count;
    let mut out = vec![[f64::INFINITY, 0.0, f64::NEG_INFINITY]; k];
    if k == 0 || scene.is_empty() {
        return vec![[0.0; 3]; k];
    }
    for row in scene.features.chunks_exact(k) {
        for (s, &v) in out.iter_mut().zip(row) {
            let v = f64::from(v);
            s[0] = s[0].min(v);
            s[1] += v;
            s[2] = s[2].max(v);
        }
    }
    for s in &mut out {
        s[1] /= scene.len() as f64;
    }
    out
}
