//! Scheduling a frame: the capacity and bin-size policy, regrowing, and depth-ordered
//! chunks for frames whose pairs exceed one key buffer.

use crate::core::camera::Camera;
use crate::core::model::RenderOptions;
use crate::gpu::{limits, GpuBuffer, GpuContext, GpuError, GpuResult, MemoryKind};
use crate::render::forward::types::{Counters, Splat};

use crate::render::forward::blend::BlendKernel;
use crate::render::forward::{keys, preprocess};
use crate::render::frame::buffers::{free_set, FrameSet};
use crate::render::frame::pipelines::Pipelines;
use crate::render::{FeatureJob, FrameStats, GpuScene, LastFrame, Readback, StageTimings, Ticket};

/// Key bits that order the pairs for `num_tiles` bins: 32 depth bits plus the bin id's.
pub fn key_bits(num_tiles: u32) -> u32 {
    32 + tile_bits(num_tiles)
}

/// Side in pixels and grid of the bins pairs are keyed by, for a bin size and image.
pub fn bin_grid(bin_size: u32, width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(bin_size), height.div_ceil(bin_size))
}

/// Bits of a bin (tile) id for `num_tiles` bins.
pub fn tile_bits(num_tiles: u32) -> u32 {
    32 - num_tiles.saturating_sub(1).leading_zeros()
}

/// Overrides of the device limits that split a frame, so that small scenes in tests take
/// the paths large scenes take. Splitting never changes the image: it is bit-identical.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SplitLimits {
    /// Gaussians per preprocess window, rounded down to a multiple of 256 (0: as many as
    /// one storage binding holds, 2.8 M on lavapipe).
    pub window: u32,
    /// Pairs per chunk (0: as many as one key buffer holds, 33.5 M on lavapipe). Nonzero
    /// renders every colour frame in chunks, even one that would fit at once.
    pub chunk_pairs: u32,
}

/// Chunks recorded per submission of a chunked frame (four timed stages each, within the
/// frame timer's capacity).
pub(crate) const CHUNKS_PER_SUBMIT: usize = 6;

/// What one submission of a frame records.
#[derive(Clone, Copy)]
pub(crate) enum Pass<'a> {
    /// The whole frame: preprocess to readback, every Gaussian in one chunk.
    Whole,
    /// Preprocess, depth order and scan, then the counters and the scanned offsets to
    /// the host, which plans the chunks.
    Front,
    /// Keys, sort, ranges and blend for each chunk, after a [`Pass::Front`]; `first`:
    /// the frame's first chunk is among them; `last`: so is its last (then the readback).
    Chunks {
        chunks: &'a [keys::Chunk],
        first: bool,
        last: bool,
    },
}

/// Smallest key capacity allocated.
pub(crate) const MIN_CAPACITY: u32 = 1 << 16;

/// llvmpipe (lavapipe) ends all loops of a shader invocation after this many iterations in
/// total (gallivm's `LP_MAX_TGSI_LOOP_ITERATIONS`), silently. The shaders report their
/// longest loops (`Counters::max_bins_loop`, `max_list_loop`) so a frame that would hit
/// the limit is rendered with larger bins or refused, never returned incomplete.
pub const CPU_LOOP_LIMIT: u32 = 65_535;

/// Most pairs a frame keys by 8-pixel bins (the texel kernel's); past this it uses
/// 16-pixel bins, whose fewer pairs then cost less to sort than the shorter lists save in
/// the blend (measured on lavapipe: 1e6 Gaussians at 1080p took 5.76 s with 30.8 M pairs
/// of 8-pixel bins and 3.41 s with 9.0 M of 16-pixel bins; BENCHMARKS.md, "Scaling").
pub const SMALL_BIN_MAX_PAIRS: u32 = 1 << 24;

/// Bin side (pixels) a frame falls back to when its preferred bins do not do.
pub(crate) const LARGE_BIN: u32 = 16;

/// The bin-size rule, in one place: 16-pixel bins when smaller ones are in use and either
/// the pairs exceed what small bins may key or a shader loop would be cut.
pub(crate) fn wants_large_bins(bin_size: u32, too_many_pairs: bool, loop_cut: bool) -> bool {
    bin_size < LARGE_BIN && (too_many_pairs || loop_cut)
}

/// Pairs past which a frame does not use small bins (`max`: one key buffer's pairs).
pub(crate) fn small_bin_limit(max: u32) -> u64 {
    u64::from(max.min(SMALL_BIN_MAX_PAIRS))
}

/// What a frame's counters, read after a submission, say about its buffers and bins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Reading {
    /// Pairs the frame needs.
    pub pairs: u64,
    /// Pairs its key buffers hold.
    pub capacity: u32,
    /// Pairs one key buffer can hold on this device.
    pub max: u32,
    /// Bin side it was keyed with, and the blend kernel's preferred one.
    pub bin_size: u32,
    pub preferred_bin: u32,
    /// It was rendered in chunks (then its pairs are complete whatever the capacity).
    pub chunked: bool,
    /// Its longest loops: bins of one Gaussian, Gaussians in one bin.
    pub bins_loop: u32,
    pub list_loop: u32,
    /// The device ends shader loops after [`CPU_LOOP_LIMIT`] iterations.
    pub loop_limited: bool,
}

/// What to do after a submission ([`next_attempt`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Next {
    /// The frame is complete; `large_bins_stick`: the next frame of the same scene and
    /// size starts with [`LARGE_BIN`] bins (its pairs say the preferred ones would not do).
    Done { large_bins_stick: bool },
    /// Again, in one piece, with [`LARGE_BIN`] bins.
    LargerBins,
    /// Again in chunks: more pairs than one key buffer holds.
    Chunks,
    /// Again with key buffers of this many pairs.
    Grow(u32),
    /// Refused: a shader loop of this many iterations, past the device's limit.
    LoopLimit(u32),
}

/// The growth decision, pure: complete frames are done (or, on a loop-limited device,
/// rendered again with larger bins, or refused); incomplete ones try larger bins first,
/// then chunks, then larger key buffers with a quarter's headroom so that a camera path
/// does not regrow every few frames.
pub(crate) fn next_attempt(r: &Reading) -> Next {
    let complete = r.chunked || r.pairs <= u64::from(r.capacity);
    if complete && r.loop_limited {
        // Four times fewer bins per Gaussian with 16-pixel bins.
        if !r.chunked && wants_large_bins(r.bin_size, false, r.bins_loop > CPU_LOOP_LIMIT) {
            return Next::LargerBins;
        }
        let worst = r.bins_loop.max(r.list_loop);
        if worst > CPU_LOOP_LIMIT {
            return Next::LoopLimit(worst);
        }
    }
    if complete {
        // An 8-pixel bin frame has at most 4 times the pairs of a 16-pixel one.
        let large_bins_stick = r.bin_size > r.preferred_bin && r.pairs * 4 > small_bin_limit(r.max);
        return Next::Done { large_bins_stick };
    }
    // Fewer, larger bins need fewer pairs; the texel kernel blends either.
    if wants_large_bins(r.bin_size, r.pairs > small_bin_limit(r.max), false) {
        return Next::LargerBins;
    }
    if r.pairs > u64::from(r.max) {
        return Next::Chunks;
    }
    Next::Grow((r.pairs + r.pairs / 4).min(u64::from(r.max)) as u32)
}

/// The frame machinery's state, which [`crate::render::GpuRenderer`] owns and drives: the
/// frame sets, the pipelines, the last finished frame and what the schedule learned from
/// the frames before (key capacity, bin size, chunks).
pub(crate) struct Frames {
    /// The resources of each frame in flight: one set, and a second one made when a frame
    /// is submitted while another is still in flight. First, so that it drops first: a
    /// set waits for a frame still in flight before the pipelines go.
    pub(crate) sets: Vec<FrameSet>,
    /// Built the first time a frame needs each.
    pub(crate) pipelines: Pipelines,
    /// The last finished frame (its set is what [`Readback::Intermediates`] reads;
    /// forward handles name it by its serial).
    pub(crate) last: LastFrame,
    /// Key capacity the frames have needed so far (the largest set's); a new or resized
    /// set starts with it.
    pub(crate) capacity: Option<u32>,
    /// Number of the next frame submitted (matches tickets to their sets).
    pub(crate) serial: u64,
    pub(crate) timings: StageTimings,
    pub(crate) stats: FrameStats,
    /// (Gaussians, width, height) of the last finished frame that needed 16-pixel bins
    /// for its pairs where the kernel prefers smaller ones: the next frames of that size
    /// start with 16-pixel bins instead of planning and dropping a first attempt.
    pub(crate) large_bins: Option<(u32, u32, u32)>,
    /// Whether frames are rendered in chunks: set by the first frame whose pairs do not
    /// fit one key buffer, and kept (a camera path does not find out again).
    pub(crate) chunked: bool,
    pub(crate) split: SplitLimits,
    /// Frames save what a backward pass reads.
    pub(crate) save_forward: bool,
}

/// Keys and values are 4 bytes; one storage-buffer binding must cover them all.
pub(crate) fn max_capacity(ctx: &GpuContext) -> u32 {
    limits::elements_per_binding(ctx.info(), 4).min(u64::from(u32::MAX)) as u32
}

impl Frames {
    /// No frame yet, one set, pipelines for the blend `kernel` built on first use.
    pub(crate) fn new(ctx: &GpuContext, kernel: BlendKernel) -> GpuResult<Self> {
        Ok(Frames {
            sets: vec![FrameSet::new(ctx, 0, kernel.bin_size())?],
            pipelines: Pipelines::new(kernel),
            last: LastFrame {
                set: 0,
                serial: u64::MAX,
                falloff: Default::default(),
                lens: false,
            },
            capacity: None,
            serial: 0,
            timings: StageTimings::default(),
            stats: FrameStats::default(),
            large_bins: None,
            chunked: false,
            split: SplitLimits::default(),
            save_forward: false,
        })
    }

    /// Gaussians per preprocess window: as many as one storage binding holds of the
    /// largest per-Gaussian record (48 bytes), a multiple of the workgroup.
    pub(crate) fn preprocess_window(&self, ctx: &GpuContext) -> u32 {
        let per_binding =
            limits::elements_per_binding(ctx.info(), std::mem::size_of::<Splat>() as u64)
                .min(u64::from(u32::MAX));
        let device = (per_binding as u32 / preprocess::WORKGROUP * preprocess::WORKGROUP)
            .max(preprocess::WORKGROUP);
        match self.split.window {
            0 => device,
            w => w.clamp(preprocess::WORKGROUP, device),
        }
    }

    /// Pairs one piece of a frame may hold: one key buffer's worth, or fewer under the
    /// split limits of tests ([`SplitLimits::chunk_pairs`]).
    pub(crate) fn pairs_per_piece(&self, ctx: &GpuContext) -> u32 {
        let max = max_capacity(ctx);
        match self.split.chunk_pairs {
            0 => max,
            forced => forced.min(max),
        }
    }

    /// Checks a frame, makes its resources in a free set, and records and submits it.
    pub(crate) fn submit_with<'a>(
        &mut self,
        ctx: &GpuContext,
        scene: &'a GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        readback: Readback,
        features: Option<FeatureJob<'a>>,
    ) -> GpuResult<Ticket<'a>> {
        cam.validate().map_err(|e| GpuError::Input(e.to_string()))?;
        opts.validate().map_err(GpuError::Input)?;
        let set = free_set(&mut self.sets, ctx, self.pipelines.kernel().bin_size())?;
        let initial = self
            .capacity
            .unwrap_or(MIN_CAPACITY.max(scene.count.saturating_mul(4)))
            .min(max_capacity(ctx));
        self.sets[set].ensure_frame(ctx, &self.pipelines, scene, cam, initial)?;
        let preferred = self.pipelines.kernel().bin_size();
        self.sets[set].bin_size = if self.large_bins == Some((scene.count, cam.width, cam.height)) {
            LARGE_BIN
        } else {
            preferred
        };
        // A frame rendered in chunks needs the host between its submissions (to plan the
        // chunks), so it is rendered when it is finished, not in flight. Frames go in
        // chunks once one frame's pairs did not fit one key buffer, when the test limits
        // say so, or when the first guess of pairs (4 per Gaussian) exceeds one key buffer
        // already. Feature channels are blended chunk by chunk too (before each chunk's
        // colour blend), and the neural shader runs once after the last chunk.
        let chunked = self.chunked
            || self.split.chunk_pairs > 0
            || u64::from(scene.count) * 4 > u64::from(max_capacity(ctx));
        let ticket = Ticket {
            set,
            serial: self.serial,
            scene,
            cam: cam.clone(),
            opts: opts.clone(),
            readback,
            features,
            chunked,
        };
        self.serial += 1;
        if !chunked {
            self.record_ticket(ctx, &ticket, false, Pass::Whole)?;
        }
        self.sets[set].pending = Some(ticket.serial);
        Ok(ticket)
    }

    /// Makes what the ticket's readback and features need in its set, then records and
    /// submits `pass` of the frame (and waits for it when `wait`).
    pub(crate) fn record_ticket(
        &mut self,
        ctx: &GpuContext,
        t: &Ticket,
        wait: bool,
        pass: Pass,
    ) -> GpuResult<()> {
        if t.readback == Readback::Rgba8 {
            self.sets[t.set].ensure_packed(ctx)?;
        }
        // Only a frame in one piece has one list per bin for the index to point into.
        let saves_last = self.save_forward && matches!(pass, Pass::Whole);
        if saves_last {
            self.sets[t.set].ensure_last_contributor(ctx)?;
        }
        self.sets[t.set].saves_last = saves_last;
        if let Some((features, _)) = t.features {
            let pixels = u64::from(t.cam.width) * u64::from(t.cam.height);
            self.sets[t.set].ensure_feature_planes(ctx, features, pixels)?;
        }
        let window = self.preprocess_window(ctx);
        let set = self
            .sets
            .get_mut(t.set)
            .ok_or_else(|| GpuError::Internal(format!("no frame set {}", t.set)))?;
        super::record::record_and_submit(ctx, &mut self.pipelines, set, window, (t, wait, pass))
    }

    /// Waits for the ticket's frame and checks its counters: when the frame needed more
    /// pairs than its buffers hold, or larger bins, it is recorded again with larger
    /// buffers or bins and waited for, until it is complete; when it needs more pairs than
    /// one key buffer holds, it is rendered in chunks. Then the timings and counts are the
    /// frame's.
    pub(crate) fn complete(&mut self, ctx: &GpuContext, t: &Ticket) -> GpuResult<()> {
        let set = self.sets.get_mut(t.set).ok_or_else(|| {
            GpuError::InvalidArgument("the ticket is not from this renderer".into())
        })?;
        if set.pending != Some(t.serial) {
            return Err(GpuError::InvalidArgument(
                "the ticket's frame was finished already, or is not from this renderer".into(),
            ));
        }
        // The set is free again whatever happens below.
        set.pending = None;
        ctx.wait_slot(&mut set.slot)?;
        let cam = &t.cam;
        let max = max_capacity(ctx);
        let mut chunked = t.chunked;
        let mut regrows = 0;
        loop {
            let (counters, chunks) = if chunked {
                match self.render_chunks(ctx, t)? {
                    Some(done) => done,
                    None => {
                        // Larger bins or key buffers: the frame is planned again.
                        regrows += 1;
                        continue;
                    }
                }
            } else {
                (self.sets[t.set].counters()?, 1)
            };
            let pairs = counters.pairs();
            let set = &self.sets[t.set];
            let capacity = set.frame.as_ref().map_or(0, |f| f.capacity);
            let bin_size = set.bin_size;
            let reading = Reading {
                pairs,
                capacity,
                max,
                bin_size,
                preferred_bin: self.pipelines.kernel().bin_size(),
                chunked,
                bins_loop: counters.max_bins_loop,
                list_loop: counters.max_list_loop,
                loop_limited: ctx.info().loop_limited(),
            };
            match next_attempt(&reading) {
                Next::Done { large_bins_stick } => {
                    self.large_bins =
                        large_bins_stick.then_some((t.scene.count, cam.width, cam.height));
                    let (bx, by) = bin_grid(bin_size, cam.width, cam.height);
                    self.stats = FrameStats {
                        visible: counters.visible,
                        pairs,
                        key_bits: key_bits(bx * by),
                        regrows,
                        bin_size,
                        chunks,
                        key_capacity: capacity,
                    };
                    self.capacity = Some(self.capacity.unwrap_or(0).max(capacity));
                    break;
                }
                Next::LoopLimit(worst) => {
                    return Err(GpuError::DeviceLimit {
                        limit: "llvmpipe's loop iterations per invocation",
                        needed: u64::from(worst),
                        max: u64::from(CPU_LOOP_LIMIT),
                        message: format!(
                        "this frame needs a shader loop of {worst} iterations ({} bins of one Gaussian, {} Gaussians in one bin), but {} ends every shader invocation's loops after {CPU_LOOP_LIMIT} iterations in total, which would silently drop Gaussians; render at a lower resolution, or on another device",
                        counters.max_bins_loop,
                        counters.max_list_loop,
                        ctx.info().name
                    ),
                    });
                }
                Next::LargerBins => {
                    regrows += 1;
                    self.sets[t.set].bin_size = LARGE_BIN;
                    self.record_ticket(ctx, t, true, Pass::Whole)?;
                }
                Next::Chunks => {
                    // This frame and the next in chunks.
                    regrows += 1;
                    self.chunked = true;
                    chunked = true;
                }
                Next::Grow(grown) => {
                    regrows += 1;
                    self.sets[t.set].ensure_frame(ctx, &self.pipelines, t.scene, cam, grown)?;
                    self.record_ticket(ctx, t, true, Pass::Whole)?;
                }
            }
        }
        if !chunked {
            self.timings = self.sets[t.set].read_timings(ctx)?;
        }
        self.last = LastFrame {
            set: t.set,
            serial: t.serial,
            falloff: crate::render::Falloff::of(&t.opts),
            lens: !cam.lens.is_pinhole(),
        };
        Ok(())
    }

    /// Renders the ticket's frame in depth-ordered chunks whose pairs fit the key buffers:
    /// one submission up to the scan, whose offsets the host reads to plan the chunks, then
    /// keys, sort, ranges and blend per chunk, each blend resuming every pixel where the
    /// previous chunk left it (`glsl/render/forward/blend.comp`). The chunks' lists are, tile by tile,
    /// consecutive runs of the one-piece frame's lists, so the image is bit-identical.
    /// Returns the frame's counters and its number of chunks, or None when the frame must
    /// be planned again (larger bins, or key buffers grown for its largest chunk).
    pub(crate) fn render_chunks(
        &mut self,
        ctx: &GpuContext,
        t: &Ticket,
    ) -> GpuResult<Option<(Counters, u32)>> {
        let max = max_capacity(ctx);
        let f = self.sets[t.set]
            .frame
            .as_mut()
            .ok_or_else(|| GpuError::Internal("frame buffers missing".into()))?;
        if f.chunk_offsets.is_none() {
            f.chunk_offsets = Some(GpuBuffer::new(
                ctx,
                "scanned offsets (chunk planning)",
                u64::from(f.gaussians.max(1)) * 4,
                MemoryKind::Readback,
            )?);
        }
        self.record_ticket(ctx, t, true, Pass::Front)?;
        let mut timings = self.sets[t.set].read_timings(ctx)?;
        let front = self.sets[t.set].counters()?;
        let pairs = front.pairs();
        let bins_cut = ctx.info().loop_limited() && front.max_bins_loop > CPU_LOOP_LIMIT;
        let too_many = pairs > small_bin_limit(max);
        if wants_large_bins(self.sets[t.set].bin_size, too_many, bins_cut) {
            // As in one piece: 16-pixel bins first (fewer pairs and bin-loop iterations).
            self.sets[t.set].bin_size = LARGE_BIN;
            return Ok(None);
        }
        let limit = self.pairs_per_piece(ctx);
        let (chunks, capacity) = {
            let f = self.sets[t.set]
                .frame
                .as_ref()
                .ok_or_else(|| GpuError::Internal("frame buffers missing".into()))?;
            let visible = (front.visible as usize).min(t.scene.count as usize);
            let bytes = f
                .chunk_offsets
                .as_ref()
                .ok_or_else(|| GpuError::Internal("chunk offsets missing".into()))?
                .mapped_range(0, visible as u64 * 4)?;
            let offsets: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
            (
                keys::plan_chunks(&offsets, pairs, u64::from(limit)),
                f.capacity,
            )
        };
        let largest = chunks.iter().map(|c| c.pairs).max().unwrap_or(0);
        if largest > u64::from(capacity) {
            if largest > u64::from(max) {
                return Err(GpuError::DeviceLimit {
                    limit: "maxStorageBufferRange",
                    needed: largest,
                    max: u64::from(max),
                    message: format!(
                    "one Gaussian of this frame touches {largest} bins, more than the {max} pairs one storage buffer of this device can hold; render at a lower resolution"
                ),
                });
            }
            let grown = (largest + largest / 4).min(u64::from(max)) as u32;
            self.sets[t.set].ensure_frame(ctx, &self.pipelines, t.scene, &t.cam, grown)?;
            return Ok(None);
        }
        let batches = chunks.len().div_ceil(CHUNKS_PER_SUBMIT);
        for (b, batch) in chunks.chunks(CHUNKS_PER_SUBMIT).enumerate() {
            let pass = Pass::Chunks {
                chunks: batch,
                first: b == 0,
                last: b + 1 == batches,
            };
            self.record_ticket(ctx, t, true, pass)?;
            timings.add(&self.sets[t.set].read_timings(ctx)?);
        }
        self.timings = timings;
        // Copied after the last chunk: the front's totals, the chunks' loop lengths.
        let counters = self.sets[t.set].counters()?;
        Ok(Some((counters, chunks.len() as u32)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A complete one-piece frame of `pairs` in buffers of 1 M pairs, 8-pixel bins
    /// preferred and used, on a GPU (no loop limit).
    fn reading(pairs: u64) -> Reading {
        Reading {
            pairs,
            capacity: 1 << 20,
            max: 1 << 26,
            bin_size: 8,
            preferred_bin: 8,
            chunked: false,
            bins_loop: 10,
            list_loop: 10,
            loop_limited: false,
        }
    }

    #[test]
    fn frames_that_fit_are_done() {
        let r = reading(1000);
        assert_eq!(
            next_attempt(&r),
            Next::Done {
                large_bins_stick: false
            }
        );
        // Larger bins stick while the pairs say the preferred ones would not fit.
        let large = Reading {
            bin_size: 16,
            pairs: (1 << 22) + 1,
            capacity: 1 << 23,
            ..r
        };
        assert_eq!(
            next_attempt(&large),
            Next::Done {
                large_bins_stick: true
            }
        );
        let few = Reading {
            pairs: 1 << 22,
            ..large
        };
        assert_eq!(
            next_attempt(&few),
            Next::Done {
                large_bins_stick: false
            }
        );
        // A chunked frame is complete whatever its buffers hold.
        let chunked = Reading {
            chunked: true,
            pairs: 1 << 30,
            ..r
        };
        assert!(matches!(next_attempt(&chunked), Next::Done { .. }));
    }

    #[test]
    fn frames_that_do_not_fit_try_bins_then_chunks_then_growth() {
        // Past small bins' limit: 16-pixel bins first, then chunks past one key buffer.
        let many = Reading {
            pairs: u64::from(SMALL_BIN_MAX_PAIRS) + 1,
            ..reading(0)
        };
        assert_eq!(next_attempt(&many), Next::LargerBins);
        let large = Reading {
            bin_size: 16,
            ..many
        };
        assert_eq!(
            next_attempt(&large),
            Next::Grow((many.pairs + many.pairs / 4) as u32)
        );
        let huge = Reading {
            pairs: (1 << 26) + 1,
            ..large
        };
        assert_eq!(next_attempt(&huge), Next::Chunks);
        // A small device's key buffer is also the small bins' limit.
        let small = Reading {
            max: 1 << 21,
            pairs: (1 << 21) + 1,
            ..reading(0)
        };
        assert_eq!(next_attempt(&small), Next::LargerBins);
        // Otherwise the buffers grow by a quarter, capped at one key buffer.
        assert_eq!(next_attempt(&reading(2_000_000)), Next::Grow(2_500_000));
        let capped = Reading {
            max: 2_100_000,
            ..reading(2_000_000)
        };
        assert_eq!(next_attempt(&capped), Next::Grow(2_100_000));
    }

    #[test]
    fn loop_limited_devices_take_larger_bins_or_refuse() {
        let cpu = Reading {
            loop_limited: true,
            bins_loop: CPU_LOOP_LIMIT + 1,
            ..reading(1000)
        };
        assert_eq!(next_attempt(&cpu), Next::LargerBins);
        let large = Reading {
            bin_size: 16,
            ..cpu
        };
        assert_eq!(next_attempt(&large), Next::LoopLimit(CPU_LOOP_LIMIT + 1));
        let list = Reading {
            bins_loop: 1,
            list_loop: CPU_LOOP_LIMIT + 7,
            ..cpu
        };
        assert_eq!(next_attempt(&list), Next::LoopLimit(CPU_LOOP_LIMIT + 7));
        // A GPU runs any loop.
        let gpu = Reading {
            loop_limited: false,
            ..list
        };
        assert!(matches!(next_attempt(&gpu), Next::Done { .. }));
        assert!(wants_large_bins(8, true, false) && wants_large_bins(8, false, true));
        assert!(!wants_large_bins(16, true, true) && !wants_large_bins(8, false, false));
    }
}
