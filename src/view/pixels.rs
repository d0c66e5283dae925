//! A rendered [`Frame`] as the page shows it (8-bit RGBA of the view mode) and as the
//! screenshot button downloads it (PNG or EXR), with the encoders `vksplat render` uses,
//! so a frame or a screenshot equals the file `render` writes with the matching flags.

use super::source::{ShotFormat, ViewMode, ViewSettings};
use crate::camera::Camera;
use crate::frame::Frame;
use crate::output::{self, ExrChannels};
use std::path::Path;

/// The frame's pixels for `mode` as 8-bit RGBA (alpha 255), quantised like the PNG files
/// of `render --mode rgb|alpha|depth`: colour with its background, opacity as grey, depth
/// colour-mapped (turbo) over the frame's 1st-99th percentile.
pub fn frame_rgba8(frame: &Frame, mode: ViewMode) -> Vec<u8> {
    let n = frame.width as usize * frame.height as usize;
    let mut out = Vec::with_capacity(n * 4);
    match mode {
        ViewMode::Rgb => {
            for c in &frame.color {
                out.extend_from_slice(&[
                    output::to_u8(c[0]),
                    output::to_u8(c[1]),
                    output::to_u8(c[2]),
                    255,
                ]);
            }
        }
        ViewMode::Alpha => {
            for &a in &frame.alpha {
                let g = output::to_u8(a);
                out.extend_from_slice(&[g, g, g, 255]);
            }
        }
        ViewMode::Depth => {
            for c in output::depth_colormap(frame, None) {
                out.extend_from_slice(&[
                    output::to_u8(c[0]),
                    output::to_u8(c[1]),
                    output::to_u8(c[2]),
                    255,
                ]);
            }
        }
    }
    out
}

/// Encodes `frame` (rendered from `cam` with `settings`) as `render` writes it: PNG of
/// the view mode (`--mode rgb|alpha|depth`), or EXR with R, G, B, A, Z (premultiplied
/// colour over transparent black, the camera in the header), as `render -o shot.exr`.
pub fn encode_screenshot(
    frame: &Frame,
    cam: &Camera,
    settings: &ViewSettings,
    format: ShotFormat,
) -> anyhow::Result<Vec<u8>> {
    let name = Path::new(match format {
        ShotFormat::Png => "screenshot.png",
        ShotFormat::Exr => "screenshot.exr",
    });
    let mut bytes = std::io::Cursor::new(Vec::new());
    match (format, settings.mode) {
        (ShotFormat::Png, ViewMode::Rgb) => output::encode_png(frame, false, &mut bytes, name)?,
        (ShotFormat::Png, ViewMode::Alpha) => output::encode_png_grey(
            frame.width,
            frame.height,
            &frame.alpha,
            false,
            &mut bytes,
            name,
        )?,
        (ShotFormat::Png, ViewMode::Depth) => {
            let colours = Frame {
                color: output::depth_colormap(frame, None),
                alpha: Vec::new(),
                depth: Vec::new(),
                ..*frame
            };
            output::encode_png(&colours, false, &mut bytes, name)?
        }
        (ShotFormat::Exr, _) => {
            let channels = ExrChannels {
                remove_background: settings.background,
                ..ExrChannels::ALL
            };
            output::encode_exr_channels(frame, Some(cam), channels, &mut bytes, name)?
        }
    }
    Ok(bytes.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Frame {
        Frame {
            width: 2,
            height: 1,
            color: vec![[1.0, 0.5, 0.0], [0.2, 0.2, 0.2]],
            alpha: vec![1.0, 0.0],
            depth: vec![3.0, 0.0],
        }
    }

    #[test]
    fn modes_quantise_like_the_png_writers() {
        let f = frame();
        assert_eq!(
            frame_rgba8(&f, ViewMode::Rgb),
            vec![255, 128, 0, 255, 51, 51, 51, 255]
        );
        assert_eq!(
            frame_rgba8(&f, ViewMode::Alpha),
            vec![255, 255, 255, 255, 0, 0, 0, 255]
        );
        let depth = frame_rgba8(&f, ViewMode::Depth);
        // An empty pixel is black; a covered one takes a turbo colour.
        assert_eq!(&depth[4..], &[0, 0, 0, 255]);
        assert_ne!(&depth[..3], &[0, 0, 0]);
    }

    #[test]
    fn png_screenshot_decodes_to_the_frame() {
        let f = frame();
        let cam = crate::camera::default_camera(&[[0.0; 3]], 2, 1);
        for mode in [ViewMode::Rgb, ViewMode::Alpha, ViewMode::Depth] {
            let settings = ViewSettings {
                mode,
                ..Default::default()
            };
            let png = encode_screenshot(&f, &cam, &settings, ShotFormat::Png).unwrap();
            let img = image::load_from_memory(&png).unwrap().to_rgba8();
            assert_eq!(img.into_raw(), frame_rgba8(&f, mode), "{mode:?}");
        }
        let exr = encode_screenshot(&f, &cam, &ViewSettings::default(), ShotFormat::Exr).unwrap();
        assert_eq!(&exr[..4], &[0x76, 0x2f, 0x31, 0x01], "EXR magic");
    }
}
