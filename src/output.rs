//! Image output: PNG (8 or 16 bit) and OpenEXR (32-bit float R, G, B, A, Z), written
//! atomically (a temporary file in the destination folder, then a rename), so a crash or
//! an error never leaves a truncated image behind.

use crate::frame::Frame;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Error raised while writing an image.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Filesystem failure.
    #[error("{path}: cannot write: {source}")]
    Io {
        /// File involved.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// Encoder failure.
    #[error("{path}: cannot encode: {message}")]
    Encode {
        /// File involved.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The destination exists and overwriting was not requested.
    #[error("{0}: already exists; pass --overwrite to replace it")]
    Exists(PathBuf),
    /// The file name's extension names no supported format.
    #[error("{0}: unknown image format; use a .png or .exr file name")]
    UnknownFormat(PathBuf),
}

/// Image file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8-bit RGB PNG.
    Png8,
    /// 16-bit RGB PNG.
    Png16,
    /// 32-bit float OpenEXR with R, G, B, A and Z channels.
    Exr,
}

impl ImageFormat {
    /// Chooses the format from a file name (`.png` gives `Png8`, or `Png16` when `png16`).
    pub fn from_path(path: &Path, png16: bool) -> Result<ImageFormat, OutputError> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("png") => Ok(if png16 {
                ImageFormat::Png16
            } else {
                ImageFormat::Png8
            }),
            Some("exr") => Ok(ImageFormat::Exr),
            _ => Err(OutputError::UnknownFormat(path.to_path_buf())),
        }
    }
}

/// Quantises a linear value to 8 bits like torchvision's `save_image`
/// (`clamp(x * 255 + 0.5, 0, 255)`, truncated).
pub fn to_u8(v: f32) -> u8 {
    (v * 255.0 + 0.5).clamp(0.0, 255.0) as u8
}

/// Quantises a linear value to 16 bits the same way.
pub fn to_u16(v: f32) -> u16 {
    (v * 65535.0 + 0.5).clamp(0.0, 65535.0) as u16
}

/// Runs `write` against a temporary file beside `path`, then renames it into place.
/// The temporary file is removed on failure. With `overwrite == false` an existing
/// `path` is an error and is left untouched.
pub fn write_atomically(
    path: &Path,
    overwrite: bool,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    if !overwrite && path.exists() {
        return Err(OutputError::Exists(path.to_path_buf()));
    }
    let io = |source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let file = std::fs::File::create(&tmp).map_err(io)?;
        let mut writer = std::io::BufWriter::new(file);
        write(&mut writer)?;
        writer.flush().map_err(io)?;
        let file = writer.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
        drop(file);
        if !overwrite && path.exists() {
            return Err(OutputError::Exists(path.to_path_buf()));
        }
        std::fs::rename(&tmp, path).map_err(io)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically (see [`write_atomically`]).
pub fn write_bytes_atomically(
    path: &Path,
    overwrite: bool,
    bytes: &[u8],
) -> Result<(), OutputError> {
    write_atomically(path, overwrite, |w| {
        w.write_all(bytes).map_err(|source| OutputError::Io {
            path: path.to_path_buf(),
            source,
        })
    })
}

/// Encodes the colour plane as PNG.
pub fn encode_png(
    frame: &Frame,
    sixteen_bit: bool,
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    use image::ImageEncoder;
    let enc_err = |e: image::ImageError| OutputError::Encode {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let encoder = image::codecs::png::PngEncoder::new(out);
    if sixteen_bit {
        // The encoder takes native-endian samples and writes them big-endian.
        let mut bytes = Vec::with_capacity(frame.color.len() * 6);
        for c in &frame.color {
            for &v in c {
                bytes.extend_from_slice(&to_u16(v).to_ne_bytes());
            }
        }
        encoder
            .write_image(
                &bytes,
                frame.width,
                frame.height,
                image::ExtendedColorType::Rgb16,
            )
            .map_err(enc_err)
    } else {
        let bytes: Vec<u8> = frame.color.iter().flat_map(|c| c.map(to_u8)).collect();
        encoder
            .write_image(
                &bytes,
                frame.width,
                frame.height,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(enc_err)
    }
}

/// Encodes colour, alpha and depth as a 32-bit float OpenEXR with channels R, G, B, A, Z.
pub fn encode_exr(
    frame: &Frame,
    out: &mut (impl Write + std::io::Seek),
    path: &Path,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let n = frame.color.len();
    let plane = |f: &dyn Fn(usize) -> f32| -> Vec<f32> { (0..n).map(f).collect() };
    let channel = |name: &str, data: Vec<f32>| AnyChannel::new(name, FlatSamples::F32(data));
    // OpenEXR wants channels sorted by name: A, B, G, R, Z.
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![
        channel("R", plane(&|i| frame.color[i][0])),
        channel("G", plane(&|i| frame.color[i][1])),
        channel("B", plane(&|i| frame.color[i][2])),
        channel("A", frame.alpha.clone()),
        channel("Z", frame.depth.clone()),
    ]));
    let layer = Layer::new(
        (frame.width as usize, frame.height as usize),
        LayerAttributes::named("vksplat"),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(out)
        .map_err(|e| OutputError::Encode {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// Writes a frame to `path` in `format`, atomically.
pub fn write_frame(
    frame: &Frame,
    path: &Path,
    format: ImageFormat,
    overwrite: bool,
) -> Result<(), OutputError> {
    write_atomically(path, overwrite, |w| match format {
        ImageFormat::Png8 => encode_png(frame, false, w, path),
        ImageFormat::Png16 => encode_png(frame, true, w, path),
        ImageFormat::Exr => encode_exr(frame, w, path),
    })
}
