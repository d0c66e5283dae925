//! Image output: PNG (8 or 16 bit; RGB, RGBA, grey or colour-mapped depth) and OpenEXR
//! (R, G, B, A, Z for compositing, with the camera in the header), written atomically
//! ([`crate::core::fsutil`]: a temporary file in the destination folder, then a rename), so a
//! crash or an error never leaves a truncated image behind.
//!
//! A frame's colour holds the background term `T * background` (the reference's image).
//! EXR and RGBA PNG files are made for compositing instead: their colour is the frame's
//! colour without that term, recovered as `color - (1 - alpha) * background` (the
//! renderers give `alpha = 1 - T`, so this is exact up to a float rounding of about 1e-7).
//! EXR stores it premultiplied by alpha, as OpenEXR expects; PNG stores it straight
//! (divided by alpha), as PNG expects.

use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::fsutil::{self, WriteError};
use crate::core::model::surface::NormalSpace;
use std::io::Write;
use std::path::{Path, PathBuf};

mod eight_bit;
mod surface;
pub use eight_bit::{rgb8, rgb8_into, write_pixels};
pub use surface::{
    encode_exr_median_depth, encode_exr_normal, encode_png_median_depth, encode_png_normal,
    frame_surface, normal_color,
};

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
    /// `--mode features` with a file that is neither EXR nor `.npy`.
    #[error("{0}: --mode features writes EXR (feat.0 ... feat.K-1, A, Z) or NumPy .npy (H x W x K); use a .exr or .npy file name")]
    FeaturesFormat(PathBuf),
    /// A `.npy` output without `--mode features`.
    #[error("{0}: .npy output holds feature channels; add --mode features (or use a .png or .exr file name)")]
    NpyNeedsFeatures(PathBuf),
    /// A file that needs the float frame, given a frame read back as 8-bit colour.
    #[error("{0}: needs the frame's float planes, but it was read back as 8-bit colour")]
    NeedsFloat(PathBuf),
    /// A feature output for a frame rendered without feature channels.
    #[error("{0}: the frame has no feature channels to write")]
    NoFeatures(PathBuf),
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

impl From<WriteError> for OutputError {
    fn from(e: WriteError) -> OutputError {
        match e {
            WriteError::Io { path, source } => OutputError::Io { path, source },
            WriteError::Exists(path) => OutputError::Exists(path),
        }
    }
}

/// Runs `write` against a temporary file beside `path`, then renames it into place
/// ([`fsutil::write_atomically`]). The temporary file is removed on failure. With
/// `overwrite == false` an existing `path` is an error and is left untouched.
pub fn write_atomically(
    path: &Path,
    overwrite: bool,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    fsutil::write_atomically(path, overwrite, write)
}

/// Writes `bytes` to `path` atomically (see [`write_atomically`]).
pub fn write_bytes_atomically(
    path: &Path,
    overwrite: bool,
    bytes: &[u8],
) -> Result<(), OutputError> {
    Ok(fsutil::write_bytes_atomically(path, overwrite, bytes)?)
}

/// Encodes the colour plane as PNG.
pub fn encode_png(
    frame: &Frame,
    sixteen_bit: bool,
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    use image::ImageEncoder;
    let size = (frame.width, frame.height);
    if !sixteen_bit {
        let bytes: Vec<u8> = frame.color.iter().flat_map(|c| c.map(to_u8)).collect();
        return encode_png_rgb8(&bytes, size, out, path);
    }
    // The encoder takes native-endian samples and writes them big-endian.
    let mut bytes = Vec::with_capacity(frame.color.len() * 6);
    for c in &frame.color {
        for &v in c {
            bytes.extend_from_slice(&to_u16(v).to_ne_bytes());
        }
    }
    image::codecs::png::PngEncoder::new(out)
        .write_image(&bytes, size.0, size.1, image::ExtendedColorType::Rgb16)
        .map_err(|e| OutputError::Encode {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// Encodes 8-bit RGB pixels (`rgb`, row-major, of `(width, height)`) as PNG: what
/// [`encode_png`] writes of a frame whose colour quantises to them.
pub fn encode_png_rgb8(
    rgb: &[u8],
    (width, height): (u32, u32),
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    use image::ImageEncoder;
    image::codecs::png::PngEncoder::new(out)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| OutputError::Encode {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// Which planes of a frame an OpenEXR file holds, and at which precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExrChannels {
    /// R, G, B colour.
    pub rgb: bool,
    /// A (opacity `1 - T`).
    pub alpha: bool,
    /// Z (alpha-normalised view depth; `+inf`, "no surface", where alpha is 0).
    pub depth: bool,
    /// 16-bit half floats for R, G, B and A instead of 32-bit floats (Z stays 32-bit:
    /// half floats hold depth to only 11 significant bits).
    pub half: bool,
    /// The background the frame's colour holds as `T * background`, removed from R, G, B
    /// to give premultiplied colour. Zero keeps the colour as rendered (the reference's
    /// image, background included).
    pub remove_background: [f32; 3],
}

impl ExrChannels {
    /// R, G, B, A and Z in 32-bit float, the colour as rendered.
    pub const ALL: ExrChannels = ExrChannels {
        rgb: true,
        alpha: true,
        depth: true,
        half: false,
        remove_background: [0.0; 3],
    };
}

/// The frame's colour without its background term: `color - (1 - alpha) * background`,
/// premultiplied colour (the accumulated `sum c_i alpha_i T_i` of the reference).
pub fn premultiplied_color(frame: &Frame, background: [f32; 3]) -> Vec<[f32; 3]> {
    if background == [0.0; 3] {
        return frame.color.clone();
    }
    frame
        .color
        .iter()
        .zip(&frame.alpha)
        .map(|(c, &a)| {
            let t = 1.0 - a;
            [
                c[0] - t * background[0],
                c[1] - t * background[1],
                c[2] - t * background[2],
            ]
        })
        .collect()
}

/// `worldToCamera` of OpenEXR's standard attributes for `cam`, as the 16 floats of an
/// `M44f`, row by row. OpenEXR multiplies row vectors (`p_camera = p_world * M`, the
/// translation in the last row) and its camera space is x right, y up, z forward (the
/// direction of view; points in front have positive z): our OpenCV camera space with y
/// negated.
pub fn exr_world_to_camera(cam: &Camera) -> [f32; 16] {
    let r = cam.rotation.as_dmat3();
    let t = cam.translation.as_dvec3();
    let flip = [1.0, -1.0, 1.0];
    let mut m = [0f32; 16];
    for axis in 0..3 {
        // Column `axis` of the row-vector matrix is the camera axis' row of [R | t].
        // `+ 0.0` turns the -0.0 of a negated zero into 0.0.
        let row = r.row(axis) * flip[axis] + 0.0;
        m[axis] = row.x as f32;
        m[4 + axis] = row.y as f32;
        m[8 + axis] = row.z as f32;
        m[12 + axis] = (t[axis] * flip[axis] + 0.0) as f32;
    }
    m[15] = 1.0;
    m
}

/// `worldToNDC` of OpenEXR's standard attributes for `cam`, row by row (row vectors, as
/// [`exr_world_to_camera`]). A world point `p` maps to `(x, y, z, w) = (p, 1) * M`, and
/// `(x / w, y / w)` is its position in the image with `(0, 0)` the top-left and `(1, 1)`
/// the bottom-right corner of the image: `((fx X / Z + cx) / W, (fy Y / Z + cy) / H)` for
/// the OpenCV camera point `(X, Y, Z)`. `z / w = 1 - 0.2 / Z` is 0 at the renderer's near
/// plane (0.2) and tends to 1 far away (OpenEXR discards it).
pub fn exr_world_to_ndc(cam: &Camera) -> [f32; 16] {
    let r = cam.rotation.as_dmat3();
    let t = cam.translation.as_dvec3();
    let (w, h) = (cam.width as f64, cam.height as f64);
    let (fx, fy, cx, cy) = (
        cam.fx as f64 / w,
        cam.fy as f64 / h,
        cam.cx as f64 / w,
        cam.cy as f64 / h,
    );
    let near = crate::core::model::NEAR_PLANE as f64;
    // Column-vector rows of the projection: [x, y, z, w] = P * (p, 1).
    let depth = (r.row(2), t.z);
    let rows = [
        (r.row(0) * fx + depth.0 * cx, t.x * fx + depth.1 * cx),
        (r.row(1) * fy + depth.0 * cy, t.y * fy + depth.1 * cy),
        (depth.0, depth.1 - near),
        depth,
    ];
    let mut m = [0f32; 16];
    for (col, (v, tr)) in rows.iter().enumerate() {
        m[col] = v.x as f32;
        m[4 + col] = v.y as f32;
        m[8 + col] = v.z as f32;
        m[12 + col] = *tr as f32;
    }
    m
}

/// Encodes the chosen planes of `frame` as an OpenEXR image (channels sorted by name,
/// as OpenEXR requires: A, B, G, R, Z). R, G, B lose `channels.remove_background`; Z is
/// `+inf` where alpha is 0 (no surface) and always 32-bit float. With a camera, the header
/// holds its `worldToCamera` and `worldToNDC` ([`exr_world_to_camera`],
/// [`exr_world_to_ndc`]).
pub fn encode_exr_channels(
    frame: &Frame,
    camera: Option<&Camera>,
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
        let color = premultiplied_color(frame, channels.remove_background);
        for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
            let plane = color.iter().map(|p| p[c]).collect();
            list.push(AnyChannel::new(name, samples(plane)));
        }
    }
    if channels.alpha {
        list.push(AnyChannel::new("A", samples(frame.alpha.clone())));
    }
    if channels.depth {
        list.push(exr_depth_channel(frame));
    }
    write_exr_layer(list, frame, camera, out, path)
}

/// Straight (un-premultiplied) colour for an RGBA PNG: the frame's colour without its
/// background term, divided by alpha; black where alpha is 0 (fully transparent, so the
/// colour there is never seen).
pub fn straight_color(frame: &Frame, background: [f32; 3]) -> Vec<[f32; 3]> {
    premultiplied_color(frame, background)
        .into_iter()
        .zip(&frame.alpha)
        .map(|(c, &a)| if a > 0.0 { c.map(|v| v / a) } else { [0.0; 3] })
        .collect()
}

/// Encodes `frame` as an RGBA PNG with a transparent background: straight colour
/// ([`straight_color`]) and alpha `1 - T`, each quantised like [`to_u8`] / [`to_u16`].
pub fn encode_png_rgba(
    frame: &Frame,
    background: [f32; 3],
    sixteen_bit: bool,
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    use image::ImageEncoder;
    let color = straight_color(frame, background);
    let pixels = color
        .iter()
        .zip(&frame.alpha)
        .map(|(c, &a)| [c[0], c[1], c[2], a]);
    let encoder = image::codecs::png::PngEncoder::new(out);
    let result = if sixteen_bit {
        // The encoder takes native-endian samples and writes them big-endian.
        let bytes: Vec<u8> = pixels
            .flat_map(|p| p.map(|v| to_u16(v).to_ne_bytes()))
            .flatten()
            .collect();
        encoder.write_image(
            &bytes,
            frame.width,
            frame.height,
            image::ExtendedColorType::Rgba16,
        )
    } else {
        let bytes: Vec<u8> = pixels.flat_map(|p| p.map(to_u8)).collect();
        encoder.write_image(
            &bytes,
            frame.width,
            frame.height,
            image::ExtendedColorType::Rgba8,
        )
    };
    result.map_err(|e| OutputError::Encode {
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
    quantiles(d, 0.01, 0.99)
}

/// The `lo` and `hi` quantiles (0..1, nearest rank) of `values`; `None` when empty.
pub fn quantiles(mut values: Vec<f32>, lo: f64, hi: f64) -> Option<[f32; 2]> {
    if values.is_empty() {
        return None;
    }
    values.sort_unstable_by(|a, b| a.total_cmp(b));
    let at = |p: f64| values[((values.len() - 1) as f64 * p).round() as usize];
    Some([at(lo), at(hi)])
}

/// The colour-map range `--range auto` picks for channel `channel` of a field frame: the
/// 1st and 99th percentiles of its values (empty pixels left out), widened to a nonzero
/// span; `None` when every pixel is empty.
pub fn field_auto_range(frame: &Frame, channel: usize) -> Option<[f32; 2]> {
    let k = frame.feature_count.max(1);
    let values: Vec<f32> = frame.features[channel..]
        .iter()
        .step_by(k)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let [lo, hi] = quantiles(values, 0.01, 0.99)?;
    Some(if hi > lo {
        [lo, hi]
    } else {
        let pad = (lo.abs() * 1e-3).max(f32::MIN_POSITIVE);
        [lo - pad, hi + pad]
    })
}

/// Channel `channel` of a field frame through the turbo colour map over `range`: values
/// below the range get the bottom colour, above it the top colour (clamped, never black);
/// empty pixels (NaN) get `background`.
pub fn field_colormap(
    frame: &Frame,
    channel: usize,
    range: [f32; 2],
    background: [f32; 3],
) -> Vec<[f32; 3]> {
    let k = frame.feature_count.max(1);
    let span = range[1] - range[0];
    frame.features[channel..]
        .iter()
        .step_by(k)
        .map(|&v| {
            if v.is_nan() {
                background
            } else {
                turbo((v - range[0]) / span)
            }
        })
        .collect()
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

/// Writes a frame to `path` in `format`, atomically (colour for PNG; R, G, B, A, Z for EXR,
/// the colour as rendered and no camera in the header).
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
            camera: None,
        },
        overwrite,
    )
}

/// What a render writes per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderMode {
    /// Colour (PNG: RGB with the background; EXR: R, G, B, A).
    Rgb,
    /// Colour with alpha over a transparent background (PNG: RGBA, straight colour; EXR:
    /// R, G, B, A as for `Rgb`).
    Rgba,
    /// Opacity only (PNG: grey; EXR: A).
    Alpha,
    /// Depth only (PNG: colour-mapped for looking at; EXR: Z in view units).
    Depth,
    /// Colour and depth (PNG: the colour file plus a `<stem>.depth.png` beside it;
    /// EXR: R, G, B, A, Z in one file).
    RgbDepth,
    /// The scene's feature channels blended with the colour rules, background 0 (EXR:
    /// `feat.0` ... `feat.{K-1}`, A, Z; `.npy`: H x W x K float32). No PNG.
    Features,
    /// The fitted field on a plane (`cpu::field`): EXR and `.npy` as `Features`, PNG the
    /// colour-mapped channel.
    FieldSlice,
    /// The line integral of the fitted field along each ray (files as `FieldSlice`).
    FieldIntegral,
    /// The maximum of the fitted field along each ray (files as `FieldSlice`).
    FieldMax,
    /// Unit normals of the Gaussians' smallest axes, facing the camera, blended like colour
    /// ([`crate::core::model::surface`]; EXR: `N.x`, `N.y`, `N.z`, `A`; PNG: the normals
    /// as colour, [`normal_color`]).
    Normal,
    /// The depth where the transmittance first reaches 0.5 (EXR: `Z`; PNG: colour-mapped
    /// as depth).
    MedianDepth,
}

impl RenderMode {
    /// One of the field renders (`field-slice`, `field-integral`, `field-max`).
    pub fn is_field(self) -> bool {
        matches!(
            self,
            RenderMode::FieldSlice | RenderMode::FieldIntegral | RenderMode::FieldMax
        )
    }

    /// One of the surface passes (`normal`, `median-depth`).
    pub fn is_surface(self) -> bool {
        matches!(self, RenderMode::Normal | RenderMode::MedianDepth)
    }
}

impl std::str::FromStr for RenderMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rgb" => Ok(RenderMode::Rgb),
            "rgba" => Ok(RenderMode::Rgba),
            "alpha" => Ok(RenderMode::Alpha),
            "depth" => Ok(RenderMode::Depth),
            "rgb+depth" => Ok(RenderMode::RgbDepth),
            "features" => Ok(RenderMode::Features),
            "field-slice" => Ok(RenderMode::FieldSlice),
            "field-integral" => Ok(RenderMode::FieldIntegral),
            "field-max" => Ok(RenderMode::FieldMax),
            "normal" => Ok(RenderMode::Normal),
            "median-depth" => Ok(RenderMode::MedianDepth),
            _ => Err(format!(
                "unknown mode \"{s}\"; use rgb, rgba, alpha, depth, rgb+depth, features, normal, median-depth, field-slice, field-integral or field-max"
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
    /// The background the frames are rendered over (their colour holds `T * background`);
    /// EXR and RGBA PNG files leave it out.
    pub background: [f32; 3],
    /// Keep the background in EXR R, G, B (the reference's image, as in RGB PNGs) instead
    /// of premultiplied colour over transparent black.
    pub exr_background: bool,
    /// The space `RenderMode::Normal` writes normals in.
    pub normal_space: NormalSpace,
}

/// One file of a frame and what it holds.
#[derive(Clone, Debug, PartialEq)]
pub enum FileContent {
    /// PNG of the colour plane.
    PngColor {
        /// 16 bits per sample.
        sixteen_bit: bool,
    },
    /// RGBA PNG: straight colour without the background, and alpha.
    PngRgba {
        /// 16 bits per sample.
        sixteen_bit: bool,
        /// The background the frame's colour holds, removed.
        background: [f32; 3],
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
    /// OpenEXR of the feature channels `feat.0` ... `feat.{K-1}`, A and Z.
    ExrFeatures {
        /// 16-bit half floats for the features and A (Z stays 32-bit).
        half: bool,
    },
    /// NumPy `.npy` of the feature channels, H x W x K float32.
    NpyFeatures,
    /// RGB PNG of the surface pass's normals ([`normal_color`]).
    PngNormal {
        /// 16 bits per sample.
        sixteen_bit: bool,
        /// The normals' space.
        space: NormalSpace,
    },
    /// OpenEXR of the surface pass's normals: `N.x`, `N.y`, `N.z`, `A`.
    ExrNormal {
        /// 16-bit half floats.
        half: bool,
        /// The normals' space.
        space: NormalSpace,
    },
    /// 8-bit PNG of the colour-mapped median depth.
    PngMedianDepth {
        /// Fixed `[near, far]`, or per-frame percentiles.
        range: Option<[f32; 2]>,
    },
    /// OpenEXR of the median depth: `Z` (32-bit).
    ExrMedianDepth,
}

impl FileContent {
    /// Whether the file holds only the frame's colour at 8 bits (an 8-bit RGB PNG), which
    /// a frame packed on the device ([`crate::core::frame::FramePixels::Rgba8`]) gives bit
    /// for bit.
    pub fn is_rgb8(&self) -> bool {
        matches!(self, FileContent::PngColor { sixteen_bit: false })
    }
}

/// A file to write for a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FileSpec {
    /// Destination.
    pub path: PathBuf,
    /// What it holds.
    pub content: FileContent,
    /// The camera the frame is rendered from, recorded in EXR headers.
    pub camera: Option<Camera>,
}

/// The files a frame from `camera` written to `path` consists of under `opts`.
pub fn plan_files(
    path: &Path,
    camera: Option<&Camera>,
    opts: &OutputOptions,
) -> Result<Vec<FileSpec>, OutputError> {
    let spec = |path: PathBuf, content| FileSpec {
        path,
        content,
        camera: camera.cloned(),
    };
    let npy = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    let field = opts.mode.is_some_and(RenderMode::is_field);
    if opts.mode == Some(RenderMode::Features) || field {
        let content = match ImageFormat::from_path(path, opts.png16) {
            _ if npy => FileContent::NpyFeatures,
            Ok(ImageFormat::Exr) => FileContent::ExrFeatures {
                half: opts.exr_half,
            },
            // The colour-mapped channel (the frame's colour).
            Ok(_) if field => FileContent::PngColor {
                sixteen_bit: opts.png16,
            },
            Err(e) if field => return Err(e),
            _ => return Err(OutputError::FeaturesFormat(path.to_path_buf())),
        };
        return Ok(vec![spec(path.to_path_buf(), content)]);
    }
    if npy {
        return Err(OutputError::NpyNeedsFeatures(path.to_path_buf()));
    }
    let format = ImageFormat::from_path(path, opts.png16)?;
    let exr = format == ImageFormat::Exr;
    let (sixteen_bit, space) = (opts.png16, opts.normal_space);
    let surface = match opts.mode {
        Some(RenderMode::Normal) if exr => Some(FileContent::ExrNormal {
            half: opts.exr_half,
            space,
        }),
        Some(RenderMode::Normal) => Some(FileContent::PngNormal { sixteen_bit, space }),
        Some(RenderMode::MedianDepth) if exr => Some(FileContent::ExrMedianDepth),
        Some(RenderMode::MedianDepth) => Some(FileContent::PngMedianDepth {
            range: opts.depth_range,
        }),
        _ => None,
    };
    if let Some(content) = surface {
        return Ok(vec![spec(path.to_path_buf(), content)]);
    }
    if format == ImageFormat::Exr {
        let mode = opts.mode.unwrap_or(RenderMode::RgbDepth);
        let colour = matches!(
            mode,
            RenderMode::Rgb | RenderMode::Rgba | RenderMode::RgbDepth
        );
        let channels = ExrChannels {
            rgb: colour,
            alpha: colour || mode == RenderMode::Alpha,
            depth: matches!(mode, RenderMode::Depth | RenderMode::RgbDepth),
            half: opts.exr_half,
            remove_background: if opts.exr_background {
                [0.0; 3]
            } else {
                opts.background
            },
        };
        return Ok(vec![spec(path.to_path_buf(), FileContent::Exr(channels))]);
    }
    let sixteen_bit = opts.png16;
    let depth = FileContent::PngDepth {
        range: opts.depth_range,
    };
    Ok(match opts.mode.unwrap_or(RenderMode::Rgb) {
        // Planned above.
        RenderMode::Normal | RenderMode::MedianDepth => Vec::new(),
        RenderMode::Features
        | RenderMode::FieldSlice
        | RenderMode::FieldIntegral
        | RenderMode::FieldMax => return Err(OutputError::FeaturesFormat(path.to_path_buf())),
        RenderMode::Rgb => vec![spec(path.into(), FileContent::PngColor { sixteen_bit })],
        RenderMode::Rgba => vec![spec(
            path.into(),
            FileContent::PngRgba {
                sixteen_bit,
                background: opts.background,
            },
        )],
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
    write_atomically(&file.path, overwrite, |w| encode_file(frame, file, w))
}

/// Encodes one planned file of `frame` into `w` (what [`write_file`] writes; `file.path`
/// names it in errors). The viewer's screenshots are encoded by this too.
pub fn encode_file(
    frame: &Frame,
    file: &FileSpec,
    w: &mut (impl Write + std::io::Seek),
) -> Result<(), OutputError> {
    let path = file.path.as_path();
    match &file.content {
        FileContent::PngColor { sixteen_bit } => encode_png(frame, *sixteen_bit, w, path),
        FileContent::PngRgba {
            sixteen_bit,
            background,
        } => encode_png_rgba(frame, *background, *sixteen_bit, w, path),
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
                feature_count: 0,
                features: Vec::new(),
                ..*frame
            };
            encode_png(&colours, false, w, path)
        }
        FileContent::Exr(channels) => {
            encode_exr_channels(frame, file.camera.as_ref(), *channels, w, path)
        }
        FileContent::ExrFeatures { half } => {
            encode_exr_features(frame, file.camera.as_ref(), *half, w, path)
        }
        FileContent::PngNormal { sixteen_bit, space } => {
            encode_png_normal(frame, file.camera.as_ref(), *space, *sixteen_bit, w, path)
        }
        FileContent::ExrNormal { half, space } => {
            encode_exr_normal(frame, file.camera.as_ref(), *space, *half, w, path)
        }
        FileContent::PngMedianDepth { range } => encode_png_median_depth(frame, *range, w, path),
        FileContent::ExrMedianDepth => {
            encode_exr_median_depth(frame, file.camera.as_ref(), w, path)
        }
        FileContent::NpyFeatures => {
            if frame.feature_count == 0 {
                return Err(OutputError::NoFeatures(path.to_path_buf()));
            }
            let bytes = crate::io::image_file::npy_bytes(
                &[
                    frame.height as usize,
                    frame.width as usize,
                    frame.feature_count,
                ],
                &frame.features,
            );
            w.write_all(&bytes).map_err(|e| OutputError::Encode {
                path: path.to_path_buf(),
                message: e.to_string(),
            })
        }
    }
}

/// Encodes the frame's feature channels as an OpenEXR image with channels `feat.0` ...
/// `feat.{K-1}` (half floats with `half`), A (`1 - T`) and Z (as [`encode_exr_channels`]),
/// and the camera in the header.
pub fn encode_exr_features(
    frame: &Frame,
    camera: Option<&Camera>,
    half: bool,
    out: &mut (impl Write + std::io::Seek),
    path: &Path,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let k = frame.feature_count;
    if k == 0 {
        return Err(OutputError::NoFeatures(path.to_path_buf()));
    }
    let samples = |data: Vec<f32>| {
        if half {
            FlatSamples::F16(data.into_iter().map(f16::from_f32).collect())
        } else {
            FlatSamples::F32(data)
        }
    };
    let mut list: Vec<AnyChannel<FlatSamples>> = (0..k)
        .map(|c| {
            let plane = frame.features.iter().skip(c).step_by(k).copied().collect();
            AnyChannel::new(format!("feat.{c}").as_str(), samples(plane))
        })
        .collect();
    list.push(AnyChannel::new("A", samples(frame.alpha.clone())));
    list.push(exr_depth_channel(frame));
    write_exr_layer(list, frame, camera, out, path)
}

/// The EXR `Z` channel of a frame: always 32-bit, +inf where nothing was hit.
fn exr_depth_channel(frame: &Frame) -> exr::prelude::AnyChannel<exr::prelude::FlatSamples> {
    use exr::prelude::*;
    let z = frame
        .depth
        .iter()
        .zip(&frame.alpha)
        .map(|(&d, &a)| if a > 0.0 { d } else { f32::INFINITY })
        .collect();
    AnyChannel::new("Z", FlatSamples::F32(z))
}

/// Writes `channels` as one EXR layer of the frame's size, with the camera's matrices.
fn write_exr_layer(
    channels: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
    frame: &Frame,
    camera: Option<&Camera>,
    out: &mut (impl Write + std::io::Seek),
    path: &Path,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let mut attributes = LayerAttributes::named("verisplat");
    if let Some(cam) = camera {
        attributes.world_to_camera = Some(exr_world_to_camera(cam));
        attributes.world_to_normalized_device = Some(exr_world_to_ndc(cam));
    }
    let layer = Layer::new(
        (frame.width as usize, frame.height as usize),
        attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(channels)),
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
