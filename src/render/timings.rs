//! GPU time per stage (timestamp queries) and what a frame needed.

use crate::gpu::GpuResult;

use super::GpuRenderer;

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
    /// Adds another submission's times of the same frame (a frame in chunks).
    pub(super) fn add(&mut self, other: &StageTimings) {
        for (mine, theirs) in [
            (&mut self.preprocess, other.preprocess),
            (&mut self.order, other.order),
            (&mut self.scan, other.scan),
            (&mut self.keys, other.keys),
            (&mut self.sort, other.sort),
            (&mut self.ranges, other.ranges),
            (&mut self.blend, other.blend),
            (&mut self.features, other.features),
            (&mut self.shade, other.shade),
            (&mut self.readback, other.readback),
            (&mut self.total, other.total),
        ] {
            *mine += theirs;
        }
    }

    /// The stages in pipeline order with their names; `features` only when the frame
    /// blended feature channels.
    pub fn stages(&self) -> Vec<(&'static str, f64)> {
        let mut stages = vec![
            ("preprocess", self.preprocess),
            ("order", self.order),
            ("scan", self.scan),
            ("keys", self.keys),
            ("sort", self.sort),
            ("ranges", self.ranges),
            ("blend", self.blend),
        ];
        if self.features > 0.0 {
            stages.push(("features", self.features));
        }
        if self.shade > 0.0 {
            stages.push(("shade", self.shade));
        }
        stages.push(("readback", self.readback));
        stages
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
    /// the key buffers at once (see [`GpuRenderer`]'s chunked frames).
    pub chunks: u32,
}

impl GpuRenderer {
    pub(super) fn read_timings(&self, set: usize) -> GpuResult<StageTimings> {
        let timer = &self.sets[set].timer;
        let stages = timer.read(&self.ctx)?;
        let mut t = StageTimings::default();
        for (name, ms) in &stages {
            let slot = match name.as_str() {
                "preprocess" => &mut t.preprocess,
                "order" => &mut t.order,
                "scan" => &mut t.scan,
                "keys" => &mut t.keys,
                "sort" => &mut t.sort,
                "ranges" => &mut t.ranges,
                "blend" => &mut t.blend,
                "features" => &mut t.features,
                "shade" => &mut t.shade,
                "readback" => &mut t.readback,
                _ => continue,
            };
            // Chunks time their stages once each.
            *slot += *ms;
        }
        t.total = timer.span_ms(&self.ctx)?;
        Ok(t)
    }
}
