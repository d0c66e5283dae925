//! GPU time per stage (timestamp queries) and what a frame needed.

use crate::gpu::{GpuError, GpuResult};

use crate::gpu::GpuContext;
use crate::render::frame::buffers::FrameSet;
use crate::render::CHUNKS_PER_SUBMIT;

/// The timed stages of a frame and of its backward pass: each stage's timestamp pair and
/// debug label are named by it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Cull, project, covariance, SH colour, tile rectangles.
    Preprocess,
    /// Depth sort of the Gaussians and tiles touched in depth order.
    Order,
    /// Prefix sum of tiles touched.
    Scan,
    /// Duplicate-per-tile keys.
    Keys,
    /// Radix sort of the keys.
    Sort,
    /// Tile ranges.
    Ranges,
    /// Feature channels, blended before the colour of the same chunk.
    Features,
    /// Per-tile blending.
    Blend,
    /// The neural shader.
    Shade,
    /// Copies (and packing) to host-visible memory.
    Readback,
    /// Training's loss, recorded before a device backward pass (its pixels' gradients).
    Loss,
    /// The neural shader's backward pass.
    ShadeBwd,
    /// Blend backward: per bin, back to front, each pair's gradients.
    BlendBwd,
    /// Each pair's sums added to its Gaussian's.
    Accumulate,
    /// The chain rule through projection, covariance and SH.
    PreprocessBwd,
    /// Training's optimiser step, recorded after a device backward pass.
    Step,
}

impl Stage {
    /// Every forward stage, in the order reports list them (a chunk records its features
    /// before its blend).
    pub const FORWARD: [Stage; 10] = [
        Stage::Preprocess,
        Stage::Order,
        Stage::Scan,
        Stage::Keys,
        Stage::Sort,
        Stage::Ranges,
        Stage::Blend,
        Stage::Features,
        Stage::Shade,
        Stage::Readback,
    ];

    /// The backward pass's stages, in the order a pass records them (the shader's and the
    /// loss and step only where there are).
    pub const BACKWARD: [Stage; 6] = [
        Stage::Loss,
        Stage::ShadeBwd,
        Stage::BlendBwd,
        Stage::Accumulate,
        Stage::PreprocessBwd,
        Stage::Step,
    ];

    /// The stage's name in timings, debug labels and reports.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Preprocess => "preprocess",
            Stage::Order => "order",
            Stage::Scan => "scan",
            Stage::Keys => "keys",
            Stage::Sort => "sort",
            Stage::Ranges => "ranges",
            Stage::Features => "features",
            Stage::Blend => "blend",
            Stage::Shade => "shade",
            Stage::Readback => "readback",
            Stage::Loss => "loss",
            Stage::ShadeBwd => "shade_bwd",
            Stage::BlendBwd => "blend_bwd",
            Stage::Accumulate => "accumulate",
            Stage::PreprocessBwd => "preprocess_bwd",
            Stage::Step => "step",
        }
    }

    fn from_name(name: &str) -> Option<Stage> {
        Stage::FORWARD.into_iter().find(|s| s.name() == name)
    }
}

/// Stages the front of a frame records (preprocess, order, scan).
pub(crate) const FRONT_STAGES: u32 = 3;
/// Stages each chunk records (keys, sort, ranges, features, blend).
pub(crate) const CHUNK_STAGES: u32 = 5;
/// Stages after the last chunk (shade, readback).
pub(crate) const FINAL_STAGES: u32 = 2;

/// Timed stages one submission records at most: a whole frame, or a batch of
/// [`CHUNKS_PER_SUBMIT`] chunks with the frame's end; the frame timers hold this many.
pub(crate) const MAX_STAGES_PER_SUBMIT: u32 = {
    let whole = FRONT_STAGES + CHUNK_STAGES + FINAL_STAGES;
    let chunks = CHUNKS_PER_SUBMIT as u32 * CHUNK_STAGES + FINAL_STAGES;
    if whole > chunks {
        whole
    } else {
        chunks
    }
};

/// GPU time of each stage of the last frame, in milliseconds (timestamp queries).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimings {
    /// Cull, project, covariance, SH colour, tile rectangles.
    pub preprocess: f64,
    /// Depth sort of the Gaussians and tiles-touched counts in depth order.
    pub order: f64,
    /// Prefix sum of tiles touched.
    pub scan: f64,
    /// Duplicate-per-tile keys.
    pub keys: f64,
    /// Radix sort of the keys.
    pub sort: f64,
    /// Tile ranges.
    pub ranges: f64,
    /// Per-tile blending.
    pub blend: f64,
    /// Feature channels blended after the colour (0 unless the frame rendered features).
    pub features: f64,
    /// The neural shader (0 unless the frame was shaded).
    pub shade: f64,
    /// Image copies to host-visible memory.
    pub readback: f64,
    /// First timestamp to last.
    pub total: f64,
}

impl StageTimings {
    /// The slot of a forward stage (a frame's timings hold no backward stage).
    fn slot(&mut self, stage: Stage) -> Option<&mut f64> {
        Some(match stage {
            Stage::Preprocess => &mut self.preprocess,
            Stage::Order => &mut self.order,
            Stage::Scan => &mut self.scan,
            Stage::Keys => &mut self.keys,
            Stage::Sort => &mut self.sort,
            Stage::Ranges => &mut self.ranges,
            Stage::Features => &mut self.features,
            Stage::Blend => &mut self.blend,
            Stage::Shade => &mut self.shade,
            Stage::Readback => &mut self.readback,
            Stage::Loss
            | Stage::ShadeBwd
            | Stage::BlendBwd
            | Stage::Accumulate
            | Stage::PreprocessBwd
            | Stage::Step => return None,
        })
    }

    /// Milliseconds of `stage` (0 for a backward stage: the backward pass reports its own,
    /// `GpuRenderer::backward_timings`).
    pub fn get(&self, stage: Stage) -> f64 {
        match stage {
            Stage::Preprocess => self.preprocess,
            Stage::Order => self.order,
            Stage::Scan => self.scan,
            Stage::Keys => self.keys,
            Stage::Sort => self.sort,
            Stage::Ranges => self.ranges,
            Stage::Features => self.features,
            Stage::Blend => self.blend,
            Stage::Shade => self.shade,
            Stage::Readback => self.readback,
            Stage::Loss
            | Stage::ShadeBwd
            | Stage::BlendBwd
            | Stage::Accumulate
            | Stage::PreprocessBwd
            | Stage::Step => 0.0,
        }
    }

    /// Adds another submission's times of the same frame (a frame in chunks).
    pub(crate) fn add(&mut self, other: &StageTimings) {
        for stage in Stage::FORWARD {
            if let Some(slot) = self.slot(stage) {
                *slot += other.get(stage);
            }
        }
        self.total += other.total;
    }

    /// The stages in pipeline order with their names; `features` and `shade` only when the
    /// frame had them.
    pub fn stages(&self) -> Vec<(&'static str, f64)> {
        Stage::FORWARD
            .into_iter()
            .filter(|&s| !matches!(s, Stage::Features | Stage::Shade) || self.get(s) > 0.0)
            .map(|s| (s.name(), self.get(s)))
            .collect()
    }
}

/// What the last frame needed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Gaussians that touched at least one tile.
    pub visible: u32,
    /// (tile, Gaussian) pairs sorted.
    pub pairs: u64,
    /// Key bits that order the pairs: 32 depth bits (sorted once per Gaussian by the
    /// order stage) plus the tile id's bits (sorted per pair by the sort stage).
    pub key_bits: u32,
    /// Times the frame was recorded again after growing the key buffers.
    pub regrows: u32,
    /// Side of the bins the pairs were keyed by (the kernel's preferred size, or 16 when a
    /// frame needed more pairs than one buffer holds at the smaller size).
    pub bin_size: u32,
    /// Depth-ordered chunks the pairs were keyed, sorted and blended in: 1 when they fit
    /// the key buffers at once (see [`GpuRenderer`](crate::render::GpuRenderer)'s chunked frames).
    pub chunks: u32,
    /// Pairs the key buffers hold (the pair sort's digit tables are laid out for them).
    pub key_capacity: u32,
}

impl FrameSet {
    /// The stage times of the set's last submission, each stage's chunks added.
    pub(crate) fn read_timings(&self, ctx: &GpuContext) -> GpuResult<StageTimings> {
        let timer = &self.timer;
        let stages = timer.read(ctx)?;
        let mut t = StageTimings::default();
        for (name, ms) in &stages {
            // Chunks time their stages once each.
            let slot = Stage::from_name(name).and_then(|stage| t.slot(stage));
            *slot.ok_or_else(|| {
                GpuError::Internal(format!("the frame timed an unknown stage {name:?}"))
            })? += *ms;
        }
        t.total = timer.span_ms(ctx)?;
        Ok(t)
    }
}
