//! A run's frames read back as 8-bit colour ([`FramePixels::Rgba8`]): their RGB bytes
//! (what a video's encoder is fed) and the files they can be written to, 8-bit RGB PNGs,
//! with the bytes a float frame quantised on the host gives.

use super::{encode_png_rgb8, to_u8, write_atomically, write_file, FileSpec, OutputError};
use crate::core::frame::FramePixels;

/// A frame's colour as 8-bit RGB, row-major, into `rgb` (cleared first, its allocation
/// reused): [`to_u8`] of the float colour, or the device's packed pixels (quantised the
/// same way) without their alpha. What an 8-bit RGB PNG of the frame holds, and what a
/// video's encoder is fed.
pub fn rgb8_into(pixels: &FramePixels, rgb: &mut Vec<u8>) {
    rgb.clear();
    match pixels {
        FramePixels::Float(f) => rgb.extend(f.color.iter().flat_map(|c| c.map(to_u8))),
        FramePixels::Rgba8(f) => {
            rgb.reserve(f.rgba.len() / 4 * 3);
            for p in f.rgba.chunks_exact(4) {
                rgb.extend_from_slice(&p[..3]);
            }
        }
    }
}

/// [`rgb8_into`] a new vector.
pub fn rgb8(pixels: &FramePixels) -> Vec<u8> {
    let mut rgb = Vec::new();
    rgb8_into(pixels, &mut rgb);
    rgb
}

/// Writes one planned file of a run's frame, atomically: [`write_file`] of a float frame;
/// an 8-bit frame writes only what [`super::FileContent::is_rgb8`] names (the same bytes
/// as the float frame it was quantised from would).
pub fn write_pixels(
    pixels: &FramePixels,
    file: &FileSpec,
    overwrite: bool,
) -> Result<(), OutputError> {
    let rgba = match pixels {
        FramePixels::Float(frame) => return write_file(frame, file, overwrite),
        FramePixels::Rgba8(rgba) => rgba,
    };
    if !file.content.is_rgb8() {
        return Err(OutputError::NeedsFloat(file.path.clone()));
    }
    let rgb = rgb8(pixels);
    write_atomically(&file.path, overwrite, |w| {
        encode_png_rgb8(&rgb, (rgba.width, rgba.height), w, &file.path)
    })
}
