//! A rendered frame: colour, alpha and depth planes, shared by both renderers and the writers.

use crate::core::camera::Camera;

/// The result of rendering one camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB including the background term `T * background`, row-major, unclamped.
    pub color: Vec<[f32; 3]>,
    /// Opacity `1 - T_final` per pixel.
    pub alpha: Vec<f32>,
    /// Alpha-weighted view-space depth normalised by alpha; 0 where alpha is 0.
    pub depth: Vec<f32>,
    /// Feature channels per pixel in [`Self::features`] (0 unless features were rendered).
    pub feature_count: usize,
    /// Blended feature channels (background 0), `feature_count` per pixel, row-major.
    pub features: Vec<f32>,
}

impl Frame {
    /// A frame filled with `background`, alpha 0 and depth 0.
    pub fn background(width: u32, height: u32, background: [f32; 3]) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width,
            height,
            color: vec![background; n],
            alpha: vec![0.0; n],
            depth: vec![0.0; n],
            feature_count: 0,
            features: Vec::new(),
        }
    }

    /// How many values of colour, alpha and depth (in that order) differ from `other`'s in
    /// their bits (NaNs compared by bits too): 0, 0, 0 for the same frame bit for bit.
    /// Frames of different sizes compare only their common prefix.
    pub fn differing_values(&self, other: &Frame) -> [usize; 3] {
        fn count<'a>(a: impl Iterator<Item = &'a f32>, b: impl Iterator<Item = &'a f32>) -> usize {
            a.zip(b).filter(|(x, y)| x.to_bits() != y.to_bits()).count()
        }
        [
            count(self.color.iter().flatten(), other.color.iter().flatten()),
            count(self.alpha.iter(), other.alpha.iter()),
            count(self.depth.iter(), other.depth.iter()),
        ]
    }

    /// Row-major pixel index.
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }
}

/// A frame's colour as 8-bit RGBA, packed on the device (`crate::render::Readback::Rgba8`)
/// and quantised as `crate::io::output::to_u8` quantises a [`Frame`]'s colour.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Rgba8Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes, row-major, top row first; alpha is 255.
    pub rgba: Vec<u8>,
}

/// What a renderer hands the writers of a run: the float frame, or, when every output of
/// the run is 8-bit colour, only that colour, quantised on the device
/// (`crate::app::sequence::FramePlan`s decide which).
#[derive(Clone, Debug, PartialEq)]
pub enum FramePixels {
    /// Colour, alpha and depth as floats.
    Float(Frame),
    /// The colour as 8-bit RGBA (alpha 255), equal to the float frame's colour through
    /// `crate::io::output::to_u8`.
    Rgba8(Rgba8Frame),
}

impl FramePixels {
    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        match self {
            FramePixels::Float(f) => (f.width, f.height),
            FramePixels::Rgba8(f) => (f.width, f.height),
        }
    }

    /// The float frame; `None` for an 8-bit one.
    pub fn into_float(self) -> Option<Frame> {
        match self {
            FramePixels::Float(f) => Some(f),
            FramePixels::Rgba8(_) => None,
        }
    }
}

/// A renderer that may keep several frames in flight: `app::sequence::run_pipelined`
/// submits frame
/// `n + 1` before it finishes frame `n` (the GPU renderer's path is one).
pub trait FrameSource {
    /// Starts rendering `cam` (recorded and submitted; not waited for).
    fn submit(&mut self, cam: &Camera) -> anyhow::Result<()>;
    /// Waits for the oldest frame submitted and not finished yet, and reads it back (as
    /// floats, or as 8-bit colour where the source was asked for that).
    fn finish(&mut self) -> anyhow::Result<FramePixels>;
    /// Drops the frames submitted and not finished (after an error stopped the run).
    fn discard(&mut self);
}
