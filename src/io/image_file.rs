//! Reading images to compare: PNG (8 or 16 bit), JPEG and WebP through `image`, OpenEXR
//! (half or float channels, by name) and NumPy `.npy` float arrays (`H x W x C` or
//! `H x W`, as PyTorch users dump renders). Every image becomes named planes of `f32`.

pub use crate::core::npy::{parse_npy_array, NpyArray};
use std::path::Path;

/// Error raised while reading an image (the readers' one file error).
pub type ImageError = crate::core::file_error::FileError;

fn invalid(path: &Path, message: impl Into<String>) -> ImageError {
    ImageError::invalid(path, message)
}

/// One named channel of an image, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// `R`, `G`, `B`, `A`, `Z`, `Y` (grey), or an OpenEXR channel's own name.
    pub name: String,
    /// `width * height` values; 8- and 16-bit files are scaled to [0, 1].
    pub values: Vec<f32>,
}

/// An image as named planes.
#[derive(Clone, Debug, PartialEq)]
pub struct Planes {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The channels, in the file's order (OpenEXR: R, G, B, A, Z first, then the rest).
    pub channels: Vec<Channel>,
}

impl Planes {
    /// The channel called `name`.
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels.iter().find(|c| c.name == name)
    }

    /// The channel names, in order.
    pub fn names(&self) -> Vec<&str> {
        self.channels.iter().map(|c| c.name.as_str()).collect()
    }

    /// `H x W x C` samples of the named channels, interleaved per pixel.
    pub fn interleave(&self, names: &[&str]) -> Option<Vec<f32>> {
        let planes: Vec<&[f32]> = names
            .iter()
            .map(|n| self.channel(n).map(|c| c.values.as_slice()))
            .collect::<Option<_>>()?;
        let n = self.width as usize * self.height as usize;
        let mut out = Vec::with_capacity(n * planes.len());
        for i in 0..n {
            out.extend(planes.iter().map(|p| p[i]));
        }
        Some(out)
    }
}

/// Channel names for `count` interleaved channels of an 8/16-bit image or an array.
fn default_names(count: usize) -> Option<&'static [&'static str]> {
    match count {
        1 => Some(&["Y"]),
        2 => Some(&["Y", "A"]),
        3 => Some(&["R", "G", "B"]),
        4 => Some(&["R", "G", "B", "A"]),
        5 => Some(&["R", "G", "B", "A", "Z"]),
        _ => None,
    }
}

/// Splits interleaved samples into named planes.
fn deinterleave(width: u32, height: u32, names: &[&str], samples: &[f32]) -> Planes {
    let c = names.len();
    Planes {
        width,
        height,
        channels: names
            .iter()
            .enumerate()
            .map(|(k, name)| Channel {
                name: name.to_string(),
                values: samples.iter().skip(k).step_by(c).copied().collect(),
            })
            .collect(),
    }
}

/// The image file kinds [`read_image`] knows, from the extension.
fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default()
}

/// File extensions [`read_image`] reads, lower case.
pub const EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "webp", "exr", "npy"];

/// Reads a PNG, JPEG, WebP, OpenEXR or `.npy` file (chosen by the extension; PNG, JPEG
/// and WebP are also recognised from their content).
pub fn read_image(path: &Path) -> Result<Planes, ImageError> {
    let bytes = std::fs::read(path).map_err(|source| ImageError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_image(&bytes, path)
}

/// Decodes an image file held in memory; `path` chooses the format by its extension, as
/// in [`read_image`], and names the file in errors.
pub fn parse_image(bytes: &[u8], path: &Path) -> Result<Planes, ImageError> {
    match extension(path).as_str() {
        "exr" => read_exr(bytes, path),
        "npy" => read_npy(bytes, path),
        _ => read_raster(bytes, path),
    }
}

fn read_raster(bytes: &[u8], path: &Path) -> Result<Planes, ImageError> {
    use image::DynamicImage as D;
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| invalid(path, format!("cannot read: {e}")))?;
    if reader.format().is_none() {
        return Err(invalid(
            path,
            format!(
                "is not an image this command reads (PNG, JPEG, WebP, OpenEXR .exr or NumPy .npy; extensions: {})",
                EXTENSIONS.join(", ")
            ),
        ));
    }
    let img = reader
        .decode()
        .map_err(|e| invalid(path, format!("cannot decode: {e}")))?;
    let (w, h) = (img.width(), img.height());
    let scale8 = |v: &[u8]| v.iter().map(|&x| x as f32 / 255.0).collect::<Vec<_>>();
    let scale16 = |v: &[u16]| v.iter().map(|&x| x as f32 / 65535.0).collect::<Vec<_>>();
    let (count, samples) = match &img {
        D::ImageLuma8(i) => (1, scale8(i.as_raw())),
        D::ImageLumaA8(i) => (2, scale8(i.as_raw())),
        D::ImageRgb8(i) => (3, scale8(i.as_raw())),
        D::ImageRgba8(i) => (4, scale8(i.as_raw())),
        D::ImageLuma16(i) => (1, scale16(i.as_raw())),
        D::ImageLumaA16(i) => (2, scale16(i.as_raw())),
        D::ImageRgb16(i) => (3, scale16(i.as_raw())),
        D::ImageRgba16(i) => (4, scale16(i.as_raw())),
        D::ImageRgb32F(i) => (3, i.as_raw().clone()),
        D::ImageRgba32F(i) => (4, i.as_raw().clone()),
        other => {
            let has_alpha = other.color().has_alpha();
            if has_alpha {
                (4, other.to_rgba32f().into_raw())
            } else {
                (3, other.to_rgb32f().into_raw())
            }
        }
    };
    let names = default_names(count).unwrap_or(&["R", "G", "B"]);
    Ok(deinterleave(w, h, names, &samples))
}

fn read_exr(bytes: &[u8], path: &Path) -> Result<Planes, ImageError> {
    use exr::prelude::*;
    let image = exr::image::read::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| invalid(path, format!("is not a readable OpenEXR image: {e}")))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let mut channels: Vec<Channel> = layer
        .channel_data
        .list
        .iter()
        .map(|c| Channel {
            name: c.name.to_string(),
            values: match &c.sample_data {
                FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
                FlatSamples::F32(v) => v.clone(),
                FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
            },
        })
        .collect();
    // OpenEXR stores channels sorted by name (A, B, G, R, Z); present them as R, G, B, A, Z.
    let rank = |n: &str| {
        ["R", "G", "B", "A", "Z"]
            .iter()
            .position(|k| *k == n)
            .unwrap_or(5)
    };
    channels.sort_by_key(|c| rank(&c.name));
    Ok(Planes {
        width: u32::try_from(w).map_err(|_| invalid(path, "is wider than 2^32 pixels"))?,
        height: u32::try_from(h).map_err(|_| invalid(path, "is taller than 2^32 pixels"))?,
        channels,
    })
}

/// Reads a NumPy `.npy` array of float32, float16 or float64 (little-endian, C order),
/// shaped `H x W x C` (C from 1 to 5: Y, Y A, R G B, R G B A, R G B A Z) or `H x W` (Y).
fn read_npy(bytes: &[u8], path: &Path) -> Result<Planes, ImageError> {
    let NpyArray {
        shape,
        data: samples,
    } = parse_npy_array(bytes, path)?;
    let (h, w, c) = match shape[..] {
        [h, w] => (h, w, 1),
        [h, w, c] if (1..=5).contains(&c) => (h, w, c),
        [c, h, w] if (1..=5).contains(&c) => {
            return Err(invalid(
                path,
                format!(
                    "has shape ({c}, {h}, {w}), which looks like C x H x W; save H x W x C (tensor.permute(1, 2, 0))"
                ),
            ))
        }
        _ => {
            return Err(invalid(
                path,
                format!(
                    "has shape {shape:?}; expected H x W or H x W x C with C from 1 to 5"
                ),
            ))
        }
    };
    if h == 0 || w == 0 {
        return Err(invalid(path, format!("has an unusable shape {shape:?}")));
    }
    let too_big = |_| invalid(path, format!("has sides {w}x{h} beyond 2^32 pixels"));
    let names = default_names(c).unwrap_or(&["Y"]);
    Ok(deinterleave(
        u32::try_from(w).map_err(too_big)?,
        u32::try_from(h).map_err(too_big)?,
        names,
        &samples,
    ))
}

/// The bytes of a version 1 `.npy` file holding `samples` as a little-endian float32
/// array of `shape` in C order (for tests and tools that hand images to NumPy).
pub fn npy_bytes(shape: &[usize], samples: &[f32]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    // The magic, version and length take 10 bytes; pad the header with spaces to a
    // multiple of 64 including its closing newline, as NumPy does.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in samples {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_round_trip_and_shapes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let samples: Vec<f32> = (0..2 * 3 * 4).map(|i| i as f32 * 0.5).collect();
        std::fs::write(&p, npy_bytes(&[2, 3, 4], &samples)).unwrap();
        let img = read_image(&p).unwrap();
        assert_eq!((img.width, img.height), (3, 2));
        assert_eq!(img.names(), ["R", "G", "B", "A"]);
        assert_eq!(img.interleave(&["R", "G", "B", "A"]).unwrap(), samples);
        std::fs::write(&p, npy_bytes(&[2, 3], &samples[..6])).unwrap();
        let grey = read_image(&p).unwrap();
        assert_eq!((grey.names(), grey.width), (vec!["Y"], 3));
        // C x H x W is refused with the permute hint.
        std::fs::write(&p, npy_bytes(&[3, 8, 8], &[0.0; 3 * 8 * 8])).unwrap();
        let e = read_image(&p).unwrap_err().to_string();
        assert!(e.contains("C x H x W") && e.contains("permute"), "{e}");
    }

    /// Replaces text of the same length in a `.npy` file's header.
    fn edit_header(mut file: Vec<u8>, from: &str, to: &str) -> Vec<u8> {
        assert_eq!(from.len(), to.len());
        let at = file
            .windows(from.len())
            .position(|w| w == from.as_bytes())
            .unwrap();
        file[at..at + to.len()].copy_from_slice(to.as_bytes());
        file
    }

    /// Every prefix of a valid file and every single-byte corruption of its header is an
    /// error or an image, never a panic (the `npy` fuzz target explores further).
    #[test]
    fn truncated_or_corrupted_npy_never_panics() {
        let good = npy_bytes(&[2, 3, 3], &[0.5; 18]);
        let path = Path::new("x.npy");
        for n in 0..good.len() {
            let _ = parse_image(&good[..n], path);
        }
        for i in 0..128.min(good.len()) {
            for b in [0u8, b'9', b',', b')', b'(', b'\'', 0xff] {
                let mut bad = good.clone();
                bad[i] = b;
                let _ = parse_image(&bad, path);
            }
        }
        // Shapes whose element or byte counts overflow 64 bits.
        for shape in [[1u64 << 32, 1 << 32, 5], [1 << 30, 1 << 30, 5]] {
            let text = format!(
                "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}\n",
                shape[0], shape[1], shape[2]
            );
            let mut file = b"\x93NUMPY\x01\x00".to_vec();
            file.extend_from_slice(&(text.len() as u16).to_le_bytes());
            file.extend_from_slice(text.as_bytes());
            file.extend_from_slice(&[0; 16]);
            let e = parse_image(&file, path).unwrap_err().to_string();
            assert!(e.contains("shape") || e.contains("bytes of data"), "{e}");
        }
    }

    #[test]
    fn npy_float16_and_float64_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        for (descr, bytes) in [
            (
                "<f2",
                exr::prelude::f16::from_f32(0.25)
                    .to_bits()
                    .to_le_bytes()
                    .to_vec(),
            ),
            ("<f8", 0.25f64.to_le_bytes().to_vec()),
        ] {
            let mut file = edit_header(npy_bytes(&[1, 1], &[0.0]), "<f4", descr);
            file.truncate(file.len() - 4);
            file.extend_from_slice(&bytes);
            std::fs::write(&p, file).unwrap();
            let img = read_image(&p).unwrap();
            assert_eq!(img.channels[0].values, [0.25], "{descr}");
        }
    }

    #[test]
    fn bad_npy_files_give_one_sentence() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"not numpy".to_vec(), "magic"),
            (npy_bytes(&[2, 2, 3], &[0.0; 5]), "bytes of data"),
            (
                edit_header(npy_bytes(&[1, 1], &[0.0]), "<f4", "<i4"),
                "dtype",
            ),
            (
                edit_header(npy_bytes(&[1, 1], &[0.0]), "False", "True "),
                "Fortran",
            ),
            (npy_bytes(&[8, 8, 7], &[0.0; 448]), "expected H x W"),
        ];
        for (bytes, want) in cases {
            std::fs::write(&p, bytes).unwrap();
            let e = read_image(&p).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("a.npy"), "{want}: {e}");
        }
    }
}
