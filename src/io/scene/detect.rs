//! Format detection: every loader is chosen from the file's content (magic bytes or
//! header), so a misnamed file still loads and a wrongly named one gets a clear error.
//!
//! Order: a directory is an unbundled SOG (has `meta.json`) or a trained model folder;
//! `ply` starts a PLY, compressed when it has a `chunk` element and packed vertices;
//! `1f 8b` is gzip (SPZ v2/v3 inside); `NGSP` is SPZ (v4, or an unwrapped v2/v3);
//! `PK\x03\x04` is a zip (a SOG bundle); `glTF` is a GLB; a JSON object is a glTF document
//! when it has `asset.version`, else a SOG `meta.json` (its directory is loaded). `.splat`
//! has no magic: it is accepted last, for a non-empty multiple of 32 bytes with the
//! `.splat` extension, or without it when every record is plausible.

use super::ply::PlyEncoding;
use super::spz::SpzCompression;
use super::{compressed_ply, gltf, ply, sog, splat, spz, Scene, SceneError};
use std::path::Path;

/// A scene file format, with its version or variant where it has one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// The INRIA 3DGS PLY the trainer writes.
    InriaPly(PlyEncoding),
    /// PlayCanvas / SuperSplat compressed PLY.
    CompressedPly,
    /// antimatter15 `.splat`.
    Splat,
    /// Niantic SPZ.
    Spz {
        /// Header version (2, 3 or 4).
        version: u32,
        /// How the payload is wrapped.
        compression: SpzCompression,
    },
    /// glTF 2.0 with `KHR_gaussian_splatting` (several splat primitives merged).
    Gltf(super::gltf::GltfInfo),
    /// PlayCanvas SOG.
    Sog {
        /// `meta.json` version (2).
        version: u32,
        /// True for a zip bundle, false for a directory.
        bundled: bool,
    },
}

impl std::fmt::Display for SceneFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SceneFormat::InriaPly(enc) => write!(
                f,
                "INRIA PLY ({})",
                match enc {
                    PlyEncoding::BinaryLittleEndian => "binary little-endian",
                    PlyEncoding::BinaryBigEndian => "binary big-endian",
                    PlyEncoding::Ascii => "ascii",
                }
            ),
            SceneFormat::CompressedPly => f.write_str("PlayCanvas compressed PLY"),
            SceneFormat::Splat => f.write_str("antimatter15 .splat"),
            SceneFormat::Spz {
                version,
                compression,
            } => write!(f, "SPZ v{version} ({compression})"),
            SceneFormat::Gltf(info) => {
                write!(
                    f,
                    "glTF 2.0 KHR_gaussian_splatting ({}",
                    if info.binary {
                        "binary .glb"
                    } else {
                        "JSON .gltf"
                    }
                )?;
                if info.primitives > 1 {
                    write!(f, ", {} splat primitives merged", info.primitives)?;
                }
                if info.spz_compressed > 0 {
                    write!(f, ", SPZ-compressed")?;
                }
                f.write_str(")")
            }
            SceneFormat::Sog { version, bundled } => write!(
                f,
                "PlayCanvas SOG v{version} ({})",
                if *bundled { "zip" } else { "directory" }
            ),
        }
    }
}

/// Loads a scene from a file, an unbundled SOG directory or a trained model directory, and
/// says which format it was.
pub fn load_with_format(path: &Path) -> Result<(Scene, SceneFormat), SceneError> {
    let file = super::resolve_scene_path(path)?;
    let bytes = super::read_file(&file)?;
    let dir = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if gltf::is_glb(&bytes) || (looks_like_json(&bytes) && gltf::is_gltf_json(&bytes)) {
        let (scene, info) = gltf::parse(&bytes, &file, Some(dir))?;
        return Ok((scene, SceneFormat::Gltf(info)));
    }
    if looks_like_json(&bytes) {
        // A SOG meta.json: its textures lie beside it.
        let scene = sog::parse(sog::Source::Directory(dir), &file)?;
        return Ok((
            scene,
            SceneFormat::Sog {
                version: 2,
                bundled: false,
            },
        ));
    }
    parse_bytes(&bytes, &file)
}

fn looks_like_json(bytes: &[u8]) -> bool {
    bytes
        .iter()
        .find(|b| !b.is_ascii_whitespace())
        .is_some_and(|&b| b == b'{')
}

/// Loads a scene as [`load_with_format`] does (any format, a model directory), an SPZ
/// file read in `axes` ([`spz::SpzAxes`]), with a note on stderr where it looks upside
/// down in them ([`spz::axes_note`]). `Raw` for a file that is not SPZ is an error: the
/// option would do nothing.
pub fn load_with_axes(path: &Path, axes: spz::SpzAxes) -> Result<(Scene, SceneFormat), SceneError> {
    let (mut scene, format) = load_with_format(path)?;
    if axes == spz::SpzAxes::Raw {
        if !matches!(format, SceneFormat::Spz { .. }) {
            return Err(SceneError::invalid(
                path,
                format!("is {format}, not SPZ: raw SPZ axes (--spz-axes raw, spz_axes=\"raw\") apply to .spz files only"),
            ));
        }
        spz::flip_rub(&mut scene);
    }
    if matches!(format, SceneFormat::Spz { .. }) {
        if let Some(note) = spz::axes_note(path, &scene, axes) {
            crate::core::console::note!("{note}");
        }
    }
    Ok((scene, format))
}

/// Parses a scene held in memory, detecting its format from the content. `path` is used
/// for messages and, for `.splat` only, its extension. An unbundled SOG needs its
/// directory, so use [`load_with_format`] for it.
pub fn parse_bytes(bytes: &[u8], path: &Path) -> Result<(Scene, SceneFormat), SceneError> {
    if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
        let header = ply::parse_header(bytes, path)?;
        if compressed_ply::is_compressed(&header) {
            return Ok((
                compressed_ply::parse(bytes, path)?,
                SceneFormat::CompressedPly,
            ));
        }
        let encoding = header.encoding();
        return Ok((ply::parse(bytes, path)?, SceneFormat::InriaPly(encoding)));
    }
    if bytes.starts_with(&[0x1f, 0x8b]) || bytes.starts_with(&spz::MAGIC.to_le_bytes()) {
        let (scene, version, compression) = spz::parse(bytes, path)?;
        return Ok((
            scene,
            SceneFormat::Spz {
                version,
                compression,
            },
        ));
    }
    if bytes.starts_with(b"PK\x03\x04") {
        let scene = sog::parse(sog::Source::Zip(bytes), path)?;
        return Ok((
            scene,
            SceneFormat::Sog {
                version: 2,
                bundled: true,
            },
        ));
    }
    if gltf::is_glb(bytes) || (looks_like_json(bytes) && gltf::is_gltf_json(bytes)) {
        let (scene, info) = gltf::parse(bytes, path, None)?;
        return Ok((scene, SceneFormat::Gltf(info)));
    }
    if looks_like_json(bytes) {
        return Err(SceneError::invalid(
            path,
            "is JSON; if it is a SOG meta.json, load it from its file or directory so its textures can be found",
        ));
    }
    let has_splat_extension = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("splat"));
    if has_splat_extension || splat::is_plausible(bytes) {
        return Ok((splat::parse(bytes, path)?, SceneFormat::Splat));
    }
    if bytes.is_empty() {
        return Err(SceneError::invalid(path, "is empty (0 bytes)"));
    }
    Err(SceneError::invalid(
        path,
        format!(
            "is not a recognised scene format: it is not a PLY, SPZ (gzip or NGSP), SOG (zip or meta.json), glTF (.glb or .gltf) or .splat file (first bytes {})",
            bytes
                .iter()
                .take(8)
                .map(|b| format!("{b:02x}"))
                .collect::<Vec<_>>()
                .join(" ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_names_format_and_version() {
        assert_eq!(
            SceneFormat::Spz {
                version: 3,
                compression: SpzCompression::Gzip
            }
            .to_string(),
            "SPZ v3 (gzip)"
        );
        assert_eq!(
            SceneFormat::InriaPly(PlyEncoding::BinaryLittleEndian).to_string(),
            "INRIA PLY (binary little-endian)"
        );
        assert_eq!(
            SceneFormat::Sog {
                version: 2,
                bundled: false
            }
            .to_string(),
            "PlayCanvas SOG v2 (directory)"
        );
    }

    #[test]
    fn unknown_bytes_are_named_not_guessed() {
        let e = parse_bytes(b"hello world", Path::new("x.bin")).unwrap_err();
        assert!(
            e.to_string().contains("not a recognised scene format"),
            "{e}"
        );
        // An empty file says so, rather than listing no first bytes.
        let e = parse_bytes(b"", Path::new("x.bin")).unwrap_err();
        assert!(e.to_string().contains("is empty (0 bytes)"), "{e}");
    }
}
