//! Scene files: the readers and writers of every format (INRIA PLY, compressed PLY, SPZ,
//! SOG, glTF, `.splat`), the detection of a file's format from its content
//! ([`detect`]), the quantisation the compact writers share ([`quantize`]), and scene
//! paths: a file, an unbundled SOG directory or a trained model directory
//! ([`resolve_scene_path`], [`load`]). The scene itself is [`crate::core::scene::Scene`].

pub mod compressed_ply;
pub mod compressed_ply_write;
pub mod detect;
pub mod gltf;
pub mod gltf_write;
pub mod ply;
pub mod quantize;
pub mod sog;
pub mod sog_write;
pub mod splat;
pub mod spz;
pub mod write;

pub use detect::{load_with_format, parse_bytes, SceneFormat};

// What the readers and writers share with the scene model (`super::` in each of them).
use crate::core::scene::{
    check_decoded, color_from_dc, dc_from_color, features, filter, logit_from_u8, normalize_quat,
    sh_coeffs_for_degree, sigmoid, transform, Scene, SceneError, MAX_FEATURES,
};
use std::path::{Path, PathBuf};

/// Resolves a scene path: a file is used as is; an unbundled SOG directory resolves to its
/// `meta.json`; a trained model directory resolves to
/// `point_cloud/iteration_<largest N>/point_cloud.ply`, as the reference viewer does.
pub fn resolve_scene_path(path: &Path) -> Result<PathBuf, SceneError> {
    resolve_scene_path_at(path, None)
}

/// [`resolve_scene_path`], with `iteration` choosing `point_cloud/iteration_<N>` of a
/// trained model directory instead of the largest (an error listing the iterations there
/// when it is missing, or when `path` is not a model directory).
pub fn resolve_scene_path_at(path: &Path, iteration: Option<u64>) -> Result<PathBuf, SceneError> {
    let meta = std::fs::metadata(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !meta.is_dir() || path.join("meta.json").is_file() {
        if let Some(n) = iteration {
            return Err(SceneError::invalid(
                path,
                format!(
                    "is not a trained model directory, so iteration {n} cannot be chosen in it"
                ),
            ));
        }
        return Ok(if meta.is_dir() {
            path.join("meta.json")
        } else {
            path.to_path_buf()
        });
    }
    let pc_dir = path.join("point_cloud");
    let entries = std::fs::read_dir(&pc_dir).map_err(|_| {
        SceneError::invalid(
            path,
            "is a directory but has neither a point_cloud/ folder nor a SOG meta.json; pass a scene file, a SOG directory or a trained model directory",
        )
    })?;
    let mut found: Vec<(u64, PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let n: u64 = name.strip_prefix("iteration_")?.parse().ok()?;
            e.path()
                .join("point_cloud.ply")
                .is_file()
                .then_some((n, e.path()))
        })
        .collect();
    found.sort_by_key(|(n, _)| *n);
    let chosen = match iteration {
        None => found.last(),
        Some(n) => found.iter().find(|(k, _)| *k == n),
    };
    match (chosen, iteration) {
        (Some((_, dir)), _) => Ok(dir.join("point_cloud.ply")),
        (None, Some(n)) if !found.is_empty() => Err(SceneError::invalid(
            path,
            format!(
                "has no point_cloud/iteration_{n}/point_cloud.ply; its iterations are {}",
                found
                    .iter()
                    .map(|(k, _)| k.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
        _ => Err(SceneError::invalid(
            path,
            "has no point_cloud/iteration_<N>/point_cloud.ply",
        )),
    }
}

/// Loads a scene from any supported file (format detected from its content), an unbundled
/// SOG directory or a trained model directory.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_with_format(path).map(|(scene, _)| scene)
}

/// Reads a whole file, mapping failures to [`SceneError::Io`].
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, SceneError> {
    std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })
}
