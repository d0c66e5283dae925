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

/// Which planes of a frame an OpenEXR file holds, and at which precision.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExrChannels {
    /// R, G, B colour.
    pub rgb: bool,
    /// A (opacity `1 - T`).
    pub alpha: bool,
    /// Z (alpha-normalised view depth).
    pub depth: bool,
    /// 16-bit half floats instead of 32-bit floats.
    pub half: bool,
}

impl ExrChannels {
    /// R, G, B, A and Z in 32-bit float.
    pub const ALL: ExrChannels = ExrChannels {
        rgb: true,
        alpha: true,
        depth: true,
        half: false,
    };
}

/// Encodes the chosen planes of `frame` as an OpenEXR image (channels sorted by name,
/// as OpenEXR requires: A, B, G, R, Z).
pub fn encode_exr_channels(
    frame: &Frame,
    channels: ExrChannels,
    out: &mut (impl Write + std::io::Seek),
    path: &Path,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let samples = |data: Vec<f32>| {
        if channels.half {
            FlatSamples::F16(data.into_iter().map(f16::from_f32).collect())
        } else {
            FlatSamples::F32(data)
        }
    };
    let mut list = Vec::new();
    if channels.rgb {
        for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
            let plane = frame.color.iter().map(|p| p[c]).collect();
            list.push(AnyChannel::new(name, samples(plane)));
        }
    }
    if channels.alpha {
        list.push(AnyChannel::new("A", samples(frame.alpha.clone())));
    }
    if channels.depth {
        list.push(AnyChannel::new("Z", samples(frame.depth.clone())));
    }
    let layer = Layer::new(
        (frame.width as usize, frame.height as usize),
        LayerAttributes::named("vksplat"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(list)),
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

/// Encodes one 8- or 16-bit grey plane (values in [0, 1]) as PNG.
pub fn encode_png_grey(
    width: u32,
    height: u32,
    plane: &[f32],
    sixteen_bit: bool,
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    use image::ImageEncoder;
    let encoder = image::codecs::png::PngEncoder::new(out);
    let result = if sixteen_bit {
        let bytes: Vec<u8> = plane
            .iter()
            .flat_map(|&v| to_u16(v).to_ne_bytes())
            .collect();
        encoder.write_image(&bytes, width, height, image::ExtendedColorType::L16)
    } else {
        let bytes: Vec<u8> = plane.iter().map(|&v| to_u8(v)).collect();
        encoder.write_image(&bytes, width, height, image::ExtendedColorType::L8)
    };
    result.map_err(|e| OutputError::Encode {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// The "turbo" colour map (Google's polynomial approximation, Anton Mikhailov 2019),
/// `t` in [0, 1] from dark blue to dark red.
pub fn turbo(t: f32) -> [f32; 3] {
    let x = t.clamp(0.0, 1.0);
    let v = [1.0, x, x * x, x * x * x, x * x * x * x, x * x * x * x * x];
    let poly = |k: [f32; 6]| -> f32 { (0..6).map(|i| k[i] * v[i]).sum::<f32>().clamp(0.0, 1.0) };
    [
        poly([
            0.135_721_38,
            4.615_392_6,
            -42.660_32,
            132.131_08,
            -152.942_4,
            59.286_38,
        ]),
        poly([
            0.091_402_61,
            2.194_188_4,
            4.842_966_6,
            -14.185_033,
            4.277_298_5,
            2.829_566,
        ]),
        poly([
            0.106_673_3,
            12.641_946,
            -60.582_05,
            110.362_77,
            -89.903_11,
            27.348_25,
        ]),
    ]
}

/// The depth range a colour-mapped depth image spans: the 1st and 99th percentiles of
/// the depth of pixels whose alpha exceeds 0.5 (any covered pixel when there are none).
/// `None` for a frame that covers no pixel.
pub fn depth_percentiles(frame: &Frame) -> Option<[f32; 2]> {
    let pick = |min_alpha: f32| -> Vec<f32> {
        frame
            .depth
            .iter()
            .zip(&frame.alpha)
            .filter(|(d, a)| **a > min_alpha && d.is_finite() && **d > 0.0)
            .map(|(d, _)| *d)
            .collect()
    };
    let mut d = pick(0.5);
    if d.is_empty() {
        d = pick(0.0);
    }
    if d.is_empty() {
        return None;
    }
    d.sort_unstable_by(|a, b| a.total_cmp(b));
    let at = |p: f64| d[((d.len() - 1) as f64 * p).round() as usize];
    Some([at(0.01), at(0.99)])
}

/// The depth plane as an 8-bit colour-mapped image for looking at: near is warm, far is
/// cold (turbo), over `range` (`[near, far]`, by default [`depth_percentiles`]), and each
/// pixel is weighted by its alpha so empty space is black.
pub fn depth_colormap(frame: &Frame, range: Option<[f32; 2]>) -> Vec<[f32; 3]> {
    let Some([near, far]) = range.or_else(|| depth_percentiles(frame)) else {
        return vec![[0.0; 3]; frame.depth.len()];
    };
    let span = (far - near).abs().max(1e-6);
    frame
        .depth
        .iter()
        .zip(&frame.alpha)
        .map(|(&d, &a)| {
            if a <= 0.0 || !d.is_finite() {
                return [0.0; 3];
            }
            turbo((far - d) / span).map(|c| c * a.clamp(0.0, 1.0))
        })
        .collect()
}

/// Writes a frame to `path` in `format`, atomically (colour for PNG; R, G, B, A, Z for EXR).
pub fn write_frame(
    frame: &Frame,
    path: &Path,
    format: ImageFormat,
    overwrite: bool,
) -> Result<(), OutputError> {
    let content = match format {
        ImageFormat::Png8 => FileContent::PngColor { sixteen_bit: false },
        ImageFormat::Png16 => FileContent::PngColor { sixteen_bit: true },
        ImageFormat::Exr => FileContent::Exr(ExrChannels::ALL),
    };
    write_file(
        frame,
        &FileSpec {
            path: path.to_path_buf(),
            content,
        },
        overwrite,
    )
}

/// What a render writes per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderMode {
    /// Colour (EXR: R, G, B, A).
    Rgb,
    /// Opacity only (PNG: grey; EXR: A).
    Alpha,
    /// Depth only (PNG: colour-mapped for looking at; EXR: Z in view units).
    Depth,
    /// Colour and depth (PNG: the colour file plus a `<stem>.depth.png` beside it;
    /// EXR: R, G, B, A, Z in one file).
    RgbDepth,
}

impl std::str::FromStr for RenderMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rgb" => Ok(RenderMode::Rgb),
            "alpha" => Ok(RenderMode::Alpha),
            "depth" => Ok(RenderMode::Depth),
            "rgb+depth" => Ok(RenderMode::RgbDepth),
            _ => Err(format!(
                "unknown mode \"{s}\"; use rgb, alpha, depth or rgb+depth"
            )),
        }
    }
}

/// How frames are written: the file format comes from each file name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OutputOptions {
    /// What to write; `None` means colour for PNG and colour plus depth for EXR.
    pub mode: Option<RenderMode>,
    /// 16-bit PNG for colour and alpha (colour-mapped depth is always 8-bit).
    pub png16: bool,
    /// Half-float EXR channels.
    pub exr_half: bool,
    /// Fixed `[near, far]` of colour-mapped depth PNGs (default: per-frame percentiles).
    pub depth_range: Option<[f32; 2]>,
}

/// One file of a frame and what it holds.
#[derive(Clone, Debug, PartialEq)]
pub enum FileContent {
    /// PNG of the colour plane.
    PngColor {
        /// 16 bits per sample.
        sixteen_bit: bool,
    },
    /// Grey PNG of the alpha plane.
    PngAlpha {
        /// 16 bits per sample.
        sixteen_bit: bool,
    },
    /// 8-bit PNG of the colour-mapped depth plane.
    PngDepth {
        /// Fixed `[near, far]`, or per-frame percentiles.
        range: Option<[f32; 2]>,
    },
    /// OpenEXR with these channels.
    Exr(ExrChannels),
}

/// A file to write for a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FileSpec {
    /// Destination.
    pub path: PathBuf,
    /// What it holds.
    pub content: FileContent,
}

/// The files a frame written to `path` consists of under `opts`.
pub fn plan_files(path: &Path, opts: &OutputOptions) -> Result<Vec<FileSpec>, OutputError> {
    let format = ImageFormat::from_path(path, opts.png16)?;
    let spec = |path: PathBuf, content| FileSpec { path, content };
    if format == ImageFormat::Exr {
        let mode = opts.mode.unwrap_or(RenderMode::RgbDepth);
        let channels = ExrChannels {
            rgb: matches!(mode, RenderMode::Rgb | RenderMode::RgbDepth),
            alpha: matches!(
                mode,
                RenderMode::Rgb | RenderMode::RgbDepth | RenderMode::Alpha
            ),
            depth: matches!(mode, RenderMode::Depth | RenderMode::RgbDepth),
            half: opts.exr_half,
        };
        return Ok(vec![spec(path.to_path_buf(), FileContent::Exr(channels))]);
    }
    let sixteen_bit = opts.png16;
    let depth = FileContent::PngDepth {
        range: opts.depth_range,
    };
    Ok(match opts.mode.unwrap_or(RenderMode::Rgb) {
        RenderMode::Rgb => vec![spec(path.into(), FileContent::PngColor { sixteen_bit })],
        RenderMode::Alpha => vec![spec(path.into(), FileContent::PngAlpha { sixteen_bit })],
        RenderMode::Depth => vec![spec(path.into(), depth)],
        RenderMode::RgbDepth => vec![
            spec(path.into(), FileContent::PngColor { sixteen_bit }),
            spec(depth_sibling(path), depth),
        ],
    })
}

/// `dir/name.png` -> `dir/name.depth.png`.
pub fn depth_sibling(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}.depth.png"))
}

/// Writes one planned file of `frame`, atomically.
pub fn write_file(frame: &Frame, file: &FileSpec, overwrite: bool) -> Result<(), OutputError> {
    let path = file.path.as_path();
    write_atomically(path, overwrite, |w| match &file.content {
        FileContent::PngColor { sixteen_bit } => encode_png(frame, *sixteen_bit, w, path),
        FileContent::PngAlpha { sixteen_bit } => encode_png_grey(
            frame.width,
            frame.height,
            &frame.alpha,
            *sixteen_bit,
            w,
            path,
        ),
        FileContent::PngDepth { range } => {
            let colours = Frame {
                color: depth_colormap(frame, *range),
                alpha: Vec::new(),
                depth: Vec::new(),
                ..*frame
            };
            encode_png(&colours, false, w, path)
        }
        FileContent::Exr(channels) => encode_exr_channels(frame, *channels, w, path),
    })
}
