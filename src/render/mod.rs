//! The Vulkan splatting pipeline. A frame is recorded top to bottom as
//! preprocess -> order -> scan -> keys -> sort -> ranges -> blend -> readback, in one
//! command buffer with a barrier between each pair of stages and a timestamp pair around
//! each stage. The frame's recording (up to the blend) is one path for every consumer;
//! only the readback differs by what the consumer needs ([`Readback`]): float colour,
//! alpha and depth for files and checks, or 8-bit RGBA packed on the device for display.
//!
//! Sorting: the reference orders each tile's Gaussians by a stable sort of
//! `tile << 32 | depth` keys emitted in Gaussian order. Here the Gaussians are first sorted
//! by depth (stable, 32 bits, one key per Gaussian), the pairs are emitted in that order,
//! and the pair sort orders only the tile bits: the result is the same
//! `(tile, depth, index)` order with far fewer passes over the (many more) pairs. Both sorts
//! use 32-bit keys (depth bits; bin id), so each pass moves 8 bytes per element, not 12.
//!
//! The number of (tile, Gaussian) pairs is only known on the GPU. The key buffers are
//! sized from a capacity kept across frames; the keys stage drops pairs beyond it and the
//! preprocess stage counts the exact 64-bit total, so after the frame the host sees whether
//! the capacity sufficed. Only when a frame proves it too small are the buffers grown and
//! the frame recorded again; the CPU never waits in the middle of a frame.
//!
//! Frames in flight: [`GpuRenderer::submit`] records and submits a frame and returns a
//! [`Ticket`]; [`GpuRenderer::finish`] waits for it, checks its counters (recording it
//! again when it needs more), and reads it back. Each of the (at most two) frames in flight
//! has its own command buffer, fence, timestamp queries and frame buffers, so frame n+1
//! renders while frame n is read back ([`path::GpuPath`] drives camera paths this way).
//! [`GpuRenderer::render`] is a submit followed by its finish.

pub mod blend;
pub mod features;
pub mod keys;
pub mod order;
pub mod pack;
pub mod path;
pub mod preprocess;
pub mod ranges;
pub mod shade;
pub mod types;

use crate::camera::Camera;
use crate::frame::Frame;
use crate::gpu::shader::Resource;
use crate::gpu::sort::{SortConfig, SortTexels, SORT_CONFIG_32};
use crate::gpu::sync::{barrier, barrier_uses, Access};
use crate::gpu::{
    BufferView, Count, FrameSlot, GpuBuffer, GpuContext, GpuError, GpuImage, GpuResult, GpuTimer,
    MemoryKind, RadixSort, Scan,
};
use crate::model::{ActivatedScene, RenderOptions, SplatKernel};
use ash::vk;
use types::{Counters, FrameParams, GpuGaussian, GpuGaussianCompact, Splat};

/// What a frame reads back to the host after it is rendered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Readback {
    /// Colour, alpha and depth as floats (a [`Frame`]): 20 bytes per pixel.
    #[default]
    Float,
    /// Colour packed to 8-bit RGBA on the device (alpha 255), quantised as
    /// [`crate::output::to_u8`]: 4 bytes per pixel. For display.
    Rgba8,
}

/// A frame read back as 8-bit RGBA.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Rgba8Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes, row-major, top row first; alpha is 255.
    pub rgba: Vec<u8>,
}

/// A scene uploaded to the device.
pub struct GpuScene {
    // The views go before the buffers they view.
    sh_texels: BufferView,
    /// RGBA32UI view of the records, for the texel-I/O preprocess (CPU devices).
    gaussian_texels: Option<BufferView>,
    gaussians: GpuBuffer,
    sh: GpuBuffer,
    count: u32,
    sh_degree: u32,
    sh_coeffs: u32,
    compact: bool,
}

impl GpuScene {
    /// Whether the scene was uploaded compact ([`GpuRenderer::set_compact`]: fp16 SH, scales and rotations).
    pub fn is_compact(&self) -> bool {
        self.compact
    }
    /// Number of Gaussians.
    pub fn len(&self) -> u32 {
        self.count
    }
    /// True when the scene is empty.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// Device bytes held by the scene.
    pub fn device_bytes(&self) -> u64 {
        self.gaussians.size() + self.sh.size()
    }
}

/// A scene's feature channels uploaded to the device: one buffer per group of four
/// channels, a vec4 per Gaussian (zero past the last channel).
pub struct GpuFeatures {
    // The views go before the buffers they view.
    views: Vec<BufferView>,
    groups: Vec<GpuBuffer>,
    channels: usize,
    count: u32,
}

impl GpuFeatures {
    /// Channels per Gaussian (K).
    pub fn channels(&self) -> usize {
        self.channels
    }
}

/// What a frame blends besides colour: the scene's features, and the neural shader
/// applied to them.
type FeatureJob<'a> = (&'a GpuFeatures, Option<&'a shade::GpuShader>);

/// The feature images of a frame: one plane per group of four channels.
struct FeaturePlanes {
    buffer: GpuBuffer,
    /// Bytes from one plane to the next.
    plane_bytes: u64,
    /// Bytes of one plane's pixels.
    pixel_bytes: u64,
    /// Planes held.
    groups: u64,
}

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
    fn add(&mut self, other: &StageTimings) {
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

/// Intermediate buffers of a frame, read back for tests against the CPU reference.
#[derive(Clone, Debug, Default)]
pub struct Intermediates {
    /// Preprocess output per Gaussian.
    pub splats: Vec<Splat>,
    /// Packed tile rectangles per Gaussian (`x | y << 16`, min inclusive, max exclusive).
    pub rects: Vec<[u32; 2]>,
    /// Gaussian indices in depth order (culled Gaussians last).
    pub order: Vec<u32>,
    /// Exclusive prefix sum of tiles touched, in depth order.
    pub offsets: Vec<u32>,
    /// Frame counters.
    pub counters: Counters,
    /// Sorted keys: the bin (tile) ids; pairs arrive in depth order, so the keys carry no
    /// depth (of the last chunk, for a frame in chunks; so are the values, the ranges and
    /// the sort count).
    pub keys: Vec<u32>,
    /// Sorted values (Gaussian indices).
    pub values: Vec<u32>,
    /// `[start, end)` per bin.
    pub ranges: Vec<[u32; 2]>,
    /// Side of the bins in pixels (16: the reference tiles; 8: their quarters).
    pub bin_size: u32,
    /// Bins along x and y.
    pub bins: (u32, u32),
}

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

/// Refuses a buffer that one storage-buffer binding of the device cannot cover.
fn check_binding(ctx: &GpuContext, what: &str, bytes: u64) -> GpuResult<()> {
    let max = u64::from(ctx.info().max_storage_buffer_range);
    if bytes > max {
        return Err(GpuError::InvalidArgument(format!(
            "{what} needs {bytes} bytes in one storage buffer, but this device binds at most {max} bytes (maxStorageBufferRange); use fewer Gaussians or a device with a larger limit"
        )));
    }
    Ok(())
}

/// RGBA32F texels of SH per Gaussian: the `3 (d + 1)^2` floats rounded up to whole texels
/// (`glsl/preprocess.comp` computes the same stride).
pub fn sh_texel_stride(sh_degree: u32) -> u32 {
    (3 * (sh_degree + 1) * (sh_degree + 1)).div_ceil(4)
}

/// Texel views the sorts, preprocess, keys and ranges read and write on CPU devices
/// ([`SortConfig::texel_io`], `PREPROCESS_TEXEL_IO`, `KEYS_TEXEL_IO`, `RANGES_TEXEL_IO`),
/// R32_UINT unless noted: the depth order's keys, values and scratch halves, the pair
/// sort's (its values are viewed by [`FrameBuffers::value_texels`], the splats by
/// [`FrameBuffers::splat_texels`]), and the other per-Gaussian arrays.
struct SortViews {
    depth_keys: BufferView,
    depth_values: BufferView,
    depth_scratch: [BufferView; 2],
    keys: BufferView,
    pair_scratch: [BufferView; 2],
    /// R32G32_UINT.
    rects: BufferView,
    offsets: BufferView,
    bin_masks: BufferView,
    touched: BufferView,
}

/// Per-frame device buffers, sized by the scene, the resolution and the key capacity.
/// (Fields drop in order: the texel views go before the buffers they view.)
struct FrameBuffers {
    sort_views: Option<SortViews>,
    splat_texels: BufferView,
    value_texels: Option<BufferView>,
    gaussians: u32,
    width: u32,
    height: u32,
    capacity: u32,
    params: GpuBuffer,
    counters: GpuBuffer,
    splats: GpuBuffer,
    rects: GpuBuffer,
    offsets: GpuBuffer,
    depth_keys: GpuBuffer,
    touched: GpuBuffer,
    depth_values: GpuBuffer,
    bin_masks: GpuBuffer,
    scan_scratch: GpuBuffer,
    keys: GpuBuffer,
    values: GpuBuffer,
    sort_scratch: GpuBuffer,
    ranges: GpuBuffer,
    color: GpuImage,
    depth: GpuImage,
    /// 8-bit RGBA of the colour image; made on the first [`Readback::Rgba8`] frame.
    packed: Option<GpuBuffer>,
    readback: GpuBuffer,
    /// The scanned offsets read back to plan a frame's chunks (host-visible); made on
    /// the first frame rendered in chunks.
    chunk_offsets: Option<GpuBuffer>,
}

impl FrameBuffers {
    fn new(
        ctx: &GpuContext,
        gaussians: u32,
        width: u32,
        height: u32,
        capacity: u32,
        texel_views: bool,
        bin_size: u32,
    ) -> GpuResult<Self> {
        let n = u64::from(gaussians.max(1));
        let (bins_x, bins_y) = bin_grid(bin_size, width, height);
        let bins = u64::from(bins_x) * u64::from(bins_y);
        let pixels = u64::from(width) * u64::from(height);
        let dev = |name: &str, bytes: u64| {
            check_binding(ctx, name, bytes)?;
            GpuBuffer::new(ctx, name, bytes, MemoryKind::Device)
        };
        // The splats are written in preprocess windows and read through a texel view (keys,
        // texel blend), so one binding need not hold them all; the shared blend kernel
        // binds them whole.
        let splat_bytes = n * std::mem::size_of::<Splat>() as u64;
        if !texel_views {
            check_binding(ctx, "splats", splat_bytes)?;
        }
        let max_texels = u64::from(ctx.info().max_texel_buffer_elements);
        if n * 3 > max_texels || (texel_views && u64::from(capacity) > max_texels) {
            return Err(GpuError::InvalidArgument(format!(
                "{gaussians} Gaussians need texel buffers of {} texels (3 per splat), but this device addresses at most {max_texels} (maxTexelBufferElements); use fewer Gaussians or a device with a larger limit",
                n * 3
            )));
        }
        let splats = GpuBuffer::new(ctx, "splats", splat_bytes, MemoryKind::Device)?;
        let values = dev("values", u64::from(capacity) * 4)?;
        let splat_texels = BufferView::new(
            ctx,
            &splats,
            vk::Format::R32G32B32A32_SFLOAT,
            0,
            splats.size(),
        )?;
        let value_texels = if texel_views {
            Some(BufferView::new(
                ctx,
                &values,
                vk::Format::R32_UINT,
                0,
                values.size(),
            )?)
        } else {
            None
        };
        let depth_keys = dev("depth keys", n * 4)?;
        let depth_values = dev("depth order", n * 4)?;
        let keys = dev("keys", u64::from(capacity) * 4)?;
        let rects = dev("tile rects", n * 8)?;
        let offsets = dev("tiles touched / offsets in depth order", n * 4)?;
        let bin_masks = dev("bin masks", n * 4)?;
        let touched = dev("tiles touched by Gaussian", n * 4)?;
        // Shared by the depth sort (the Gaussians) and the pair sort (capacity pairs). The
        // sort binds slices of it, the largest 4 bytes per key, which the capacity bound
        // (max_capacity) keeps inside one binding.
        let sort_scratch = GpuBuffer::new(
            ctx,
            "sort scratch",
            RadixSort::scratch_size_with(&SORT_CONFIG_32, capacity.max(gaussians)),
            MemoryKind::Device,
        )?;
        let sort_views = if texel_views {
            let view = |b: &GpuBuffer, (offset, size): (u64, u64)| {
                BufferView::new(ctx, b, vk::Format::R32_UINT, offset, size.max(4))
            };
            let whole = |b: &GpuBuffer| view(b, (0, b.size()));
            let scratch_views = |max_n: u32| -> GpuResult<[BufferView; 2]> {
                let [k, v] = RadixSort::scratch_pair_ranges(&SORT_CONFIG_32, max_n);
                Ok([view(&sort_scratch, k)?, view(&sort_scratch, v)?])
            };
            Some(SortViews {
                depth_keys: whole(&depth_keys)?,
                depth_values: whole(&depth_values)?,
                depth_scratch: scratch_views(gaussians.max(1))?,
                keys: whole(&keys)?,
                pair_scratch: scratch_views(capacity)?,
                rects: BufferView::new(ctx, &rects, vk::Format::R32G32_UINT, 0, rects.size())?,
                offsets: whole(&offsets)?,
                bin_masks: whole(&bin_masks)?,
                touched: whole(&touched)?,
            })
        } else {
            None
        };
        Ok(FrameBuffers {
            sort_views,
            splat_texels,
            value_texels,
            gaussians,
            width,
            height,
            capacity,
            params: dev("frame params", std::mem::size_of::<FrameParams>() as u64)?,
            counters: dev("counters", std::mem::size_of::<Counters>() as u64)?,
            splats,
            rects,
            offsets,
            depth_keys,
            touched,
            depth_values,
            bin_masks,
            scan_scratch: dev("scan scratch", Scan::scratch_size(gaussians).max(16))?,
            keys,
            values,
            sort_scratch,
            ranges: dev("bin ranges", bins * 8)?,
            color: GpuImage::new(
                ctx,
                "color+alpha image",
                width,
                height,
                vk::Format::R32G32B32A32_SFLOAT,
            )?,
            depth: GpuImage::new(ctx, "depth image", width, height, vk::Format::R32_SFLOAT)?,
            packed: None,
            readback: GpuBuffer::new(
                ctx,
                "frame readback",
                pixels * 20 + std::mem::size_of::<Counters>() as u64,
                MemoryKind::Readback,
            )?,
            chunk_offsets: None,
        })
    }

    /// The depth order's sort views, when the sorts read through texel views.
    fn depth_sort_texels(&self) -> Option<SortTexels> {
        self.sort_views.as_ref().map(|v| SortTexels {
            keys: v.depth_keys.handle(),
            values: v.depth_values.handle(),
            scratch_keys: v.depth_scratch[0].handle(),
            scratch_values: v.depth_scratch[1].handle(),
        })
    }

    /// The views of the texel-I/O preprocess, over this frame's buffers and `scene`'s
    /// records.
    fn preprocess_texels(&self, scene: &GpuScene) -> GpuResult<preprocess::PreprocessTexels> {
        match (self.sort_views.as_ref(), scene.gaussian_texels.as_ref()) {
            (Some(v), Some(g)) => Ok(preprocess::PreprocessTexels {
                gaussians: g.handle(),
                splats: self.splat_texels.handle(),
                rects: v.rects.handle(),
                depth_keys: v.depth_keys.handle(),
                depth_values: v.depth_values.handle(),
                bin_masks: v.bin_masks.handle(),
                touched: v.touched.handle(),
            }),
            _ => Err(GpuError::InvalidArgument(
                "the preprocess stage's texel views are missing (scene uploaded by another renderer?)".into(),
            )),
        }
    }

    /// What the keys stage reads and writes, as its pipeline binds them.
    fn keys_io(&self, texel_io: bool) -> GpuResult<keys::KeysIo<'_>> {
        let views = (self.sort_views.as_ref(), self.value_texels.as_ref());
        Ok(match (texel_io, views) {
            (false, _) => keys::KeysIo {
                rects: Resource::Buffer(self.rects.whole()),
                offsets: Resource::Buffer(self.offsets.whole()),
                keys: Resource::Buffer(self.keys.whole()),
                values: Resource::Buffer(self.values.whole()),
                depth_order: Resource::Buffer(self.depth_values.whole()),
                bin_masks: Resource::Buffer(self.bin_masks.whole()),
            },
            (true, (Some(v), Some(values))) => keys::KeysIo {
                rects: Resource::TexelBuffer(v.rects.handle()),
                offsets: Resource::TexelBuffer(v.offsets.handle()),
                keys: Resource::TexelBuffer(v.keys.handle()),
                values: Resource::TexelBuffer(values.handle()),
                depth_order: Resource::TexelBuffer(v.depth_values.handle()),
                bin_masks: Resource::TexelBuffer(v.bin_masks.handle()),
            },
            (true, _) => {
                return Err(GpuError::InvalidArgument(
                    "the keys stage's texel views are missing".into(),
                ))
            }
        })
    }

    /// The pair sort's views, when the sorts read through texel views.
    fn pair_sort_texels(&self) -> Option<SortTexels> {
        let v = self.sort_views.as_ref()?;
        Some(SortTexels {
            keys: v.keys.handle(),
            values: self.value_texels.as_ref()?.handle(),
            scratch_keys: v.pair_scratch[0].handle(),
            scratch_values: v.pair_scratch[1].handle(),
        })
    }

    fn device_bytes(&self) -> u64 {
        [
            &self.params,
            &self.counters,
            &self.splats,
            &self.rects,
            &self.offsets,
            &self.depth_keys,
            &self.touched,
            &self.depth_values,
            &self.bin_masks,
            &self.scan_scratch,
            &self.keys,
            &self.values,
            &self.sort_scratch,
            &self.ranges,
        ]
        .iter()
        .map(|b| b.size())
        .sum::<u64>()
            + self.packed.as_ref().map_or(0, |b| b.size())
            + self.color.bytes()
            + self.depth.bytes()
    }

    fn readback_offsets(&self) -> (u64, u64, u64) {
        let pixels = u64::from(self.width) * u64::from(self.height);
        (0, pixels * 16, pixels * 20)
    }
}

/// The GPU renderer: pipelines, per-frame buffers and the timestamp pool.
pub struct GpuRenderer {
    /// The resources of each frame in flight: one set, and a second one made when a frame
    /// is submitted while another is still in flight ([`Self::submit`]). First, so that
    /// it drops first: a set waits for a frame still in flight before the pipelines go.
    sets: Vec<FrameSet>,
    preprocess: preprocess::Preprocess,
    /// The preprocess pipeline of compact scenes, built on the first frame of one.
    compact_preprocess: Option<preprocess::Preprocess>,
    order: order::Order,
    scan: Scan,
    keys: keys::Keys,
    sort: RadixSort,
    ranges: ranges::Ranges,
    /// Blend pipelines by alpha falloff: the Gaussian one is built with the renderer, the
    /// power one on the first frame that needs it.
    blend: blend::Blend,
    power_blend: Option<blend::Blend>,
    /// Feature blend pipelines by `SplatKernel::shader_id`, built on first use.
    feature_blends: [Option<features::FeatureBlend>; 2],
    /// The neural shader's pipeline, built on first use.
    shade: Option<shade::Shade>,
    pack: pack::Pack,
    /// The set of the last finished frame (what [`Self::render_with_intermediates`] reads).
    last: usize,
    /// Key capacity the frames have needed so far (the largest set's); a new or resized
    /// set starts with it.
    capacity: Option<u32>,
    /// Number of the next frame submitted (matches tickets to their sets).
    serial: u64,
    timings: StageTimings,
    stats: FrameStats,
    /// (Gaussians, width, height) of the last finished frame that needed 16-pixel bins
    /// for its pairs where the kernel prefers smaller ones: the next frames of that size
    /// start with 16-pixel bins instead of planning and dropping a first attempt.
    large_bins: Option<(u32, u32, u32)>,
    /// Whether frames are rendered in chunks: set by the first frame whose pairs do not
    /// fit one key buffer, and kept (a camera path does not find out again).
    chunked: bool,
    split: SplitLimits,
    /// Upload scenes compact: fp16 SH, scales and rotations ([`Self::set_compact`]).
    compact: bool,
    ctx: GpuContext,
}

/// Frames one renderer keeps in flight at most ([`GpuRenderer::submit`]).
pub const MAX_FRAMES_IN_FLIGHT: usize = 2;

/// The resources of one frame in flight: command buffer and fence, timestamp queries,
/// frame buffers and feature images. (Fields drop in order: the slot goes first and waits
/// for a submission still pending, before the buffers it uses go.)
struct FrameSet {
    slot: FrameSlot,
    timer: GpuTimer,
    frame: Option<FrameBuffers>,
    /// The feature images of this set's last features frame, one plane per group of four
    /// channels (vec4 per pixel) in one buffer, planes `plane_bytes` apart (a multiple of
    /// the storage-buffer offset alignment); kept across frames of the same size.
    feature_planes: Option<FeaturePlanes>,
    /// Bin size of the frame recorded in this set (see [`FrameStats::bin_size`]).
    bin_size: u32,
    /// The serial number of the frame submitted in this set and not finished yet.
    pending: Option<u64>,
}

impl FrameSet {
    fn new(ctx: &GpuContext, index: usize, bin_size: u32) -> GpuResult<Self> {
        Ok(FrameSet {
            slot: FrameSlot::new(ctx, &format!("frame {index}"))?,
            // Two timestamps per stage: up to ten stages (features and shade included).
            timer: GpuTimer::new(ctx, &format!("frame {index} timestamps"), 32)?,
            frame: None,
            feature_planes: None,
            bin_size,
            pending: None,
        })
    }
}

/// A frame submitted by [`GpuRenderer::submit`] (or [`GpuRenderer::submit_features`]),
/// still being rendered; [`GpuRenderer::finish`] (or [`GpuRenderer::finish_rgba8`]) waits
/// for it and reads it back. It borrows the scene (and features) the frame reads, so they
/// outlive the work on the device.
#[must_use = "a submitted frame is read back (and its resources freed for the next) by GpuRenderer::finish"]
pub struct Ticket<'a> {
    set: usize,
    serial: u64,
    scene: &'a GpuScene,
    cam: Camera,
    opts: RenderOptions,
    readback: Readback,
    features: Option<FeatureJob<'a>>,
    /// Rendered in chunks when finished (nothing of it is in flight).
    chunked: bool,
}

impl Ticket<'_> {
    /// The camera of the frame.
    pub fn camera(&self) -> &Camera {
        &self.cam
    }
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
const CHUNKS_PER_SUBMIT: usize = 6;

/// What one submission of a frame records.
#[derive(Clone, Copy)]
enum Pass<'a> {
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
const MIN_CAPACITY: u32 = 1 << 16;

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

impl GpuRenderer {
    /// Builds every pipeline on `ctx`, with the blend kernel suited to the device.
    pub fn new(ctx: GpuContext) -> GpuResult<Self> {
        let kernel = blend::BlendKernel::for_device(&ctx);
        Self::with_blend_kernel(ctx, kernel)
    }

    /// Builds every pipeline with the given blend kernel.
    pub fn with_blend_kernel(ctx: GpuContext, kernel: blend::BlendKernel) -> GpuResult<Self> {
        Ok(GpuRenderer {
            preprocess: preprocess::Preprocess::new(&ctx, false, kernel.texel())?,
            compact_preprocess: None,
            order: order::Order::new(&ctx)?,
            scan: Scan::new(&ctx)?,
            keys: keys::Keys::new(&ctx, kernel.texel())?,
            // Texel-view I/O where the blend reads texel views too (CPU devices).
            sort: RadixSort::with_config(
                &ctx,
                SortConfig {
                    texel_io: kernel.texel(),
                    ..SORT_CONFIG_32
                },
            )?,
            ranges: ranges::Ranges::new(&ctx, kernel.texel())?,
            blend: blend::Blend::new(&ctx, kernel, SplatKernel::Gaussian)?,
            power_blend: None,
            feature_blends: [None, None],
            shade: None,
            pack: pack::Pack::new(&ctx)?,
            sets: vec![FrameSet::new(&ctx, 0, kernel.bin_size())?],
            last: 0,
            capacity: None,
            serial: 0,
            timings: StageTimings::default(),
            stats: FrameStats::default(),
            chunked: false,
            large_bins: None,
            split: SplitLimits::default(),
            compact: false,
            ctx,
        })
    }

    /// Splits frames as if the device's limits were `limits` (for tests; see
    /// [`SplitLimits`]).
    pub fn set_split_limits(&mut self, limits: SplitLimits) {
        self.split = limits;
    }

    /// Gaussians per preprocess window: as many as one storage binding holds of the
    /// largest per-Gaussian record (48 bytes), a multiple of the workgroup.
    fn preprocess_window(&self) -> u32 {
        let range = u64::from(self.ctx.info().max_storage_buffer_range);
        let per_binding = (range / std::mem::size_of::<Splat>() as u64).min(u64::from(u32::MAX));
        let device = (per_binding as u32 / preprocess::WORKGROUP * preprocess::WORKGROUP)
            .max(preprocess::WORKGROUP);
        match self.split.window {
            0 => device,
            w => w.clamp(preprocess::WORKGROUP, device),
        }
    }

    /// The blend kernel in use.
    pub fn blend_kernel(&self) -> blend::BlendKernel {
        self.blend.kernel()
    }

    /// Destroys the pipelines and per-frame resources and returns the context (for
    /// checking that nothing is left allocated).
    pub fn into_context(self) -> GpuContext {
        self.ctx
    }

    /// The device context.
    pub fn ctx(&self) -> &GpuContext {
        &self.ctx
    }

    /// Compact mode for the scenes uploaded from now on: SH coefficients as fp16 (half the
    /// bytes of the largest per-Gaussian array: 96 instead of 192 at SH degree 3), read
    /// through an RGBA16F texel view, and 32-byte records instead of 48 (axis scales and
    /// rotation as fp16; centre and opacity stay f32), unpacked by a preprocess variant.
    /// Not exact: frames equal the exact render of [`ActivatedScene::compact_rounded`],
    /// which differs from the scene by fp16's rounding (BENCHMARKS.md measures the PSNR).
    pub fn set_compact(&mut self, on: bool) {
        self.compact = on;
    }

    /// Uploads activated Gaussians.
    pub fn upload(&self, scene: &ActivatedScene) -> GpuResult<GpuScene> {
        let count = u32::try_from(scene.len()).map_err(|_| {
            GpuError::InvalidArgument(format!(
                "{} Gaussians exceed the 2^32 limit of one upload",
                scene.len()
            ))
        })?;
        // Preprocess binds windows of the records, so one binding need not hold them all.
        let gaussians = if self.compact {
            let records: Vec<GpuGaussianCompact> = (0..scene.len())
                .map(|i| {
                    GpuGaussianCompact::new(
                        scene.positions[i],
                        scene.opacities[i],
                        scene.scales[i],
                        scene.rotations[i],
                    )
                })
                .collect();
            self.upload_records("gaussians (compact)", &records)?
        } else {
            let records: Vec<GpuGaussian> = (0..scene.len())
                .map(|i| {
                    let p = scene.positions[i];
                    let s = scene.scales[i];
                    GpuGaussian {
                        pos_opacity: [p[0], p[1], p[2], scene.opacities[i]],
                        scale: [s[0], s[1], s[2], 0.0],
                        rotation: scene.rotations[i],
                    }
                })
                .collect();
            self.upload_records("gaussians", &records)?
        };
        // SH is read through an RGBA32F texel buffer (texel buffers address up to
        // maxTexelBufferElements texels, far beyond one storage binding on lavapipe), each
        // Gaussian's floats padded to whole texels.
        let stride = scene.sh_stride();
        let padded = sh_texel_stride(scene.sh_degree) as usize * 4;
        let texels = scene.len() as u64 * padded as u64 / 4;
        let max_texels = u64::from(self.ctx.info().max_texel_buffer_elements);
        if texels > max_texels {
            return Err(GpuError::InvalidArgument(format!(
                "the SH coefficients of {count} Gaussians need {texels} texels ({} bytes) in one texel buffer, but this device addresses at most {max_texels} (maxTexelBufferElements); use fewer Gaussians, a lower --sh-degree or a device with a larger limit",
                texels * 16
            )));
        }
        // SH degrees 1 and 3 fill whole texels already and upload as they are.
        let sh_padded: std::borrow::Cow<[f32]> = if stride == padded {
            std::borrow::Cow::Borrowed(&scene.sh)
        } else {
            let mut v = vec![0f32; scene.len() * padded];
            for (dst, src) in v
                .chunks_exact_mut(padded)
                .zip(scene.sh.chunks_exact(stride))
            {
                dst[..stride].copy_from_slice(src);
            }
            std::borrow::Cow::Owned(v)
        };
        let (sh, format, sh_bytes) = if self.compact {
            // Round to nearest fp16; beyond fp16's range (|x| > 65504) becomes infinite.
            let halves: Vec<u16> = sh_padded
                .iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect();
            let bytes = (halves.len() * 2).max(8) as u64;
            let sh = GpuBuffer::new(
                &self.ctx,
                "sh coefficients (fp16)",
                bytes,
                MemoryKind::Device,
            )?;
            sh.upload(&self.ctx, &halves)?;
            (sh, vk::Format::R16G16B16A16_SFLOAT, bytes)
        } else {
            let bytes = (sh_padded.len() * 4).max(16) as u64;
            let sh = GpuBuffer::new(&self.ctx, "sh coefficients", bytes, MemoryKind::Device)?;
            sh.upload(&self.ctx, &sh_padded)?;
            (sh, vk::Format::R32G32B32A32_SFLOAT, bytes)
        };
        let sh_texels = BufferView::new(&self.ctx, &sh, format, 0, sh_bytes)?;
        let gaussian_texels = if self.preprocess.texel_io() {
            let bytes = gaussians.size() / 16 * 16;
            Some(BufferView::new(
                &self.ctx,
                &gaussians,
                vk::Format::R32G32B32A32_UINT,
                0,
                bytes,
            )?)
        } else {
            None
        };
        Ok(GpuScene {
            sh_texels,
            gaussian_texels,
            gaussians,
            sh,
            count,
            sh_degree: scene.sh_degree,
            sh_coeffs: (scene.sh_degree + 1) * (scene.sh_degree + 1),
            compact: self.compact,
        })
    }

    /// A device buffer holding `records`.
    fn upload_records<T: bytemuck::Pod>(&self, name: &str, records: &[T]) -> GpuResult<GpuBuffer> {
        // At least one texel, so the preprocess's texel view is valid for an empty scene.
        let bytes = (std::mem::size_of_val(records) as u64).max(16);
        let buffer = GpuBuffer::new(&self.ctx, name, bytes, MemoryKind::Device)?;
        buffer.upload(&self.ctx, records)?;
        Ok(buffer)
    }

    /// Uploads the scene's feature channels (four per buffer, for the feature blend).
    pub fn upload_features(&self, scene: &ActivatedScene) -> GpuResult<GpuFeatures> {
        let k = scene.feature_count;
        let n = scene.len();
        if k == 0 || scene.features.len() != n * k {
            return Err(GpuError::InvalidArgument(format!(
                "the scene has no feature channels to upload ({} values for {n} Gaussians and {k} channels)",
                scene.features.len()
            )));
        }
        let count = u32::try_from(n).map_err(|_| {
            GpuError::InvalidArgument(format!("{n} Gaussians exceed the 2^32 limit of one upload"))
        })?;
        let (mut groups, mut views) = (Vec::new(), Vec::new());
        for g in 0..features::groups(k) {
            let mut v = vec![[0f32; 4]; n.max(1)];
            for (i, dst) in v.iter_mut().enumerate().take(n) {
                for (c, d) in dst.iter_mut().enumerate() {
                    let ch = g * features::CHANNELS_PER_GROUP + c;
                    if ch < k {
                        *d = scene.features[i * k + ch];
                    }
                }
            }
            let name = format!("features {}..{}", g * 4, (g * 4 + 4).min(k));
            let bytes = (v.len() * 16) as u64;
            check_binding(&self.ctx, &name, bytes)?;
            let buf = GpuBuffer::new(&self.ctx, &name, bytes, MemoryKind::Device)?;
            buf.upload(&self.ctx, &v)?;
            if self.blend.needs_texel_views() {
                views.push(BufferView::new(
                    &self.ctx,
                    &buf,
                    vk::Format::R32G32B32A32_SFLOAT,
                    0,
                    bytes,
                )?);
            }
            groups.push(buf);
        }
        Ok(GpuFeatures {
            views,
            groups,
            channels: k,
            count,
        })
    }

    /// Renders one frame and blends the uploaded feature channels over the same sorted
    /// lists with the colour rules (background 0), timed as the `features` stage: the frame
    /// with [`Frame::features`] (`width * height * K` floats, pixel-major).
    pub fn render_features(
        &mut self,
        scene: &GpuScene,
        features: &GpuFeatures,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<Frame> {
        let ticket = self.submit_features(scene, features, None, cam, opts)?;
        self.finish(ticket)
    }

    /// Renders one frame, blends the uploaded feature channels and shades them with the
    /// neural shader ([`crate::mlp`]) as its own `shade` stage: the frame's colour is
    /// `alpha * mlp(...) + (1 - alpha) * background`; alpha and depth are the frame's.
    pub fn render_shaded(
        &mut self,
        scene: &GpuScene,
        features: &GpuFeatures,
        shader: &shade::GpuShader,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<Frame> {
        let ticket = self.submit_features(scene, features, Some(shader), cam, opts)?;
        self.finish(ticket)
    }

    /// What every features frame needs before it is recorded: features uploaded for this
    /// scene, the feature blend pipeline of the frame's kernel and, with a shader, the
    /// shader's checks and pipeline.
    fn prepare_features(
        &mut self,
        scene: &GpuScene,
        features: &GpuFeatures,
        shader: Option<&shade::GpuShader>,
        opts: &RenderOptions,
    ) -> GpuResult<()> {
        if features.count != scene.count {
            return Err(GpuError::InvalidArgument(format!(
                "the features were uploaded for {} Gaussians, the scene has {}",
                features.count, scene.count
            )));
        }
        let slot = opts.kernel.shader_id() as usize;
        if self.feature_blends[slot].is_none() {
            self.feature_blends[slot] = Some(features::FeatureBlend::new(
                &self.ctx,
                opts.kernel,
                self.blend.needs_texel_views(),
            )?);
        }
        if let Some(shader) = shader {
            if shader.channels() != features.channels {
                return Err(GpuError::InvalidArgument(format!(
                    "the shader takes {} feature channels but the scene has {}",
                    shader.channels(),
                    features.channels
                )));
            }
            if self.loop_limited() && shader.iterations > u64::from(CPU_LOOP_LIMIT) {
                return Err(GpuError::InvalidArgument(format!(
                    "the neural shader needs {} loop iterations per pixel, but {} ends every shader invocation's loops after {CPU_LOOP_LIMIT} iterations; use narrower layers, or the CPU reference (--cpu)",
                    shader.iterations,
                    self.ctx.info().name
                )));
            }
            if self.shade.is_none() {
                self.shade = Some(shade::Shade::new(&self.ctx)?);
            }
        }
        Ok(())
    }

    /// Makes set `set`'s feature planes hold `features`' groups for `pixels` pixels.
    fn ensure_feature_planes(
        &mut self,
        set: usize,
        features: &GpuFeatures,
        pixels: u64,
    ) -> GpuResult<()> {
        let groups = features.groups.len() as u64;
        let align = self.ctx.info().min_storage_buffer_offset_alignment.max(16);
        let plane_bytes = (pixels * 16).div_ceil(align) * align;
        let planes = &mut self.sets[set].feature_planes;
        let fits = planes
            .as_ref()
            .is_some_and(|p| p.plane_bytes == plane_bytes && p.groups >= groups);
        if !fits {
            *planes = None;
            check_binding(&self.ctx, "feature image", plane_bytes * groups)?;
            *planes = Some(FeaturePlanes {
                buffer: GpuBuffer::new(
                    &self.ctx,
                    "feature images",
                    plane_bytes * groups,
                    MemoryKind::Device,
                )?,
                plane_bytes,
                pixel_bytes: pixels * 16,
                groups,
            });
        }
        Ok(())
    }

    /// The `k` blended channels of set `set`'s last features frame, pixel-major.
    fn read_feature_planes(&self, set: usize, k: usize, pixels: usize) -> GpuResult<Vec<f32>> {
        let planes = self.sets[set]
            .feature_planes
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no feature image was rendered".into()))?;
        let stride = (planes.plane_bytes / 16) as usize;
        let groups = features::groups(k);
        let all: Vec<[f32; 4]> = planes.buffer.read(&self.ctx, stride * groups)?;
        let mut out = vec![0f32; pixels * k];
        for g in 0..groups {
            let plane = &all[g * stride..g * stride + pixels];
            for (dst, src) in out.chunks_exact_mut(k).zip(plane) {
                for (c, v) in src.iter().enumerate() {
                    let ch = g * features::CHANNELS_PER_GROUP + c;
                    if ch < k {
                        dst[ch] = *v;
                    }
                }
            }
        }
        Ok(out)
    }

    /// GPU time per stage of the last frame finished.
    pub fn timings(&self) -> &StageTimings {
        &self.timings
    }

    /// Counts of the last frame finished.
    pub fn stats(&self) -> &FrameStats {
        &self.stats
    }

    /// Device bytes held by the per-frame buffers, of every frame in flight: with two
    /// frames in flight ([`Self::submit`]) there are two sets of them.
    pub fn frame_device_bytes(&self) -> u64 {
        self.sets
            .iter()
            .filter_map(|s| s.frame.as_ref())
            .map(|f| f.device_bytes())
            .sum()
    }

    /// Sets of per-frame resources made so far: 1, or 2 once two frames were in flight.
    pub fn frame_sets(&self) -> usize {
        self.sets.len()
    }

    /// Frames submitted and not finished yet.
    pub fn frames_in_flight(&self) -> usize {
        self.sets.iter().filter(|s| s.pending.is_some()).count()
    }

    /// Renders one frame.
    pub fn render(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<Frame> {
        let ticket = self.submit(scene, cam, opts, Readback::Float)?;
        self.finish(ticket)
    }

    /// Renders one frame and reads back only its colour, packed to 8-bit RGBA on the
    /// device (equal to [`crate::output::to_u8`] of [`Self::render`]'s colour).
    pub fn render_rgba8(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<Rgba8Frame> {
        let ticket = self.submit(scene, cam, opts, Readback::Rgba8)?;
        self.finish_rgba8(ticket)
    }

    /// Renders one frame and reads back every intermediate buffer (for tests).
    pub fn render_with_intermediates(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<(Frame, Intermediates)> {
        let frame = self.render(scene, cam, opts)?;
        Ok((frame, self.read_intermediates(scene, cam)?))
    }

    /// Records frame `cam` and submits it to the device without waiting for it: the CPU
    /// can submit the next frame (up to [`MAX_FRAMES_IN_FLIGHT`] in flight, each with its
    /// own command buffer, fence, timestamps and frame buffers) while this one renders,
    /// and read it back with [`Self::finish`] (or [`Self::finish_rgba8`] for
    /// [`Readback::Rgba8`]). Frames may be finished in any order. The second set of
    /// per-frame resources is made the first time two frames are in flight (doubling the
    /// device memory of [`Self::frame_device_bytes`]).
    pub fn submit<'a>(
        &mut self,
        scene: &'a GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        readback: Readback,
    ) -> GpuResult<Ticket<'a>> {
        self.submit_with(scene, cam, opts, readback, None)
    }

    /// [`Self::submit`] for a frame that also blends the uploaded feature channels
    /// ([`Self::render_features`]) and, with a shader, shades them
    /// ([`Self::render_shaded`]); [`Self::finish`] reads it back.
    pub fn submit_features<'a>(
        &mut self,
        scene: &'a GpuScene,
        features: &'a GpuFeatures,
        shader: Option<&'a shade::GpuShader>,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> GpuResult<Ticket<'a>> {
        self.prepare_features(scene, features, shader, opts)?;
        self.submit_with(scene, cam, opts, Readback::Float, Some((features, shader)))
    }

    /// Waits for a frame submitted with [`Readback::Float`] and reads it back (with its
    /// feature channels when it was submitted with features and no shader). When the
    /// frame needed more tile/Gaussian pairs than its buffers hold, or larger bins, it is
    /// recorded again (and waited for) here, as [`Self::render`] does. The timings and
    /// counts ([`Self::timings`], [`Self::stats`]) become this frame's.
    pub fn finish(&mut self, ticket: Ticket) -> GpuResult<Frame> {
        if ticket.readback != Readback::Float {
            // Still wait, so the set is free again.
            self.complete(&ticket)?;
            return Err(GpuError::InvalidArgument(
                "the frame was submitted with Readback::Rgba8; finish it with finish_rgba8".into(),
            ));
        }
        self.complete(&ticket)?;
        let mut frame = self.read_frame(ticket.set, &ticket.cam)?;
        if let Some((features, None)) = ticket.features {
            let pixels = ticket.cam.width as usize * ticket.cam.height as usize;
            frame.feature_count = features.channels;
            frame.features = self.read_feature_planes(ticket.set, features.channels, pixels)?;
        }
        Ok(frame)
    }

    /// [`Self::finish`] for a frame submitted with [`Readback::Rgba8`].
    pub fn finish_rgba8(&mut self, ticket: Ticket) -> GpuResult<Rgba8Frame> {
        self.complete(&ticket)?;
        if ticket.readback != Readback::Rgba8 {
            return Err(GpuError::InvalidArgument(
                "the frame was submitted with Readback::Float; finish it with finish".into(),
            ));
        }
        self.read_rgba8(ticket.set, &ticket.cam)
    }

    /// Waits for a submitted frame without reading it back, freeing its resources for the
    /// next frame (after an error stopped a path).
    pub fn discard(&mut self, ticket: Ticket) -> GpuResult<()> {
        let set = self.sets.get_mut(ticket.set).ok_or_else(|| {
            GpuError::InvalidArgument("the ticket is not from this renderer".into())
        })?;
        if set.pending == Some(ticket.serial) {
            set.pending = None;
            self.ctx.wait_slot(&mut set.slot)?;
        }
        Ok(())
    }

    /// Whether the device is a CPU implementation with llvmpipe's loop limit.
    fn loop_limited(&self) -> bool {
        let info = self.ctx.info();
        info.device_type == vk::PhysicalDeviceType::CPU && info.name.contains("llvmpipe")
    }

    fn max_capacity(&self) -> u32 {
        // Keys and values are 4 bytes; one storage-buffer binding must cover them all.
        let range = u64::from(self.ctx.info().max_storage_buffer_range);
        (range / 4).min(u64::from(u32::MAX)) as u32
    }

    /// Pairs one piece of a frame may hold: one key buffer's worth, or fewer under the
    /// split limits of tests ([`SplitLimits::chunk_pairs`]).
    fn pairs_per_piece(&self) -> u32 {
        let max = self.max_capacity();
        match self.split.chunk_pairs {
            0 => max,
            forced => forced.min(max),
        }
    }

    /// Makes set `set`'s frame buffers fit the scene, the camera and `capacity` pairs.
    fn ensure_frame(
        &mut self,
        set: usize,
        scene: &GpuScene,
        cam: &Camera,
        capacity: u32,
    ) -> GpuResult<()> {
        let frame = &mut self.sets[set].frame;
        let fits = frame.as_ref().is_some_and(|f| {
            f.gaussians >= scene.count
                && f.width == cam.width
                && f.height == cam.height
                && f.capacity >= capacity
        });
        if !fits {
            // Free the old buffers first so peak memory is not doubled.
            *frame = None;
            let views = self.blend.needs_texel_views();
            *frame = Some(FrameBuffers::new(
                &self.ctx,
                scene.count,
                cam.width,
                cam.height,
                capacity,
                views,
                self.blend.kernel().bin_size(),
            )?);
        }
        Ok(())
    }

    /// A set with no frame in flight (made when every set made so far is busy).
    fn free_set(&mut self) -> GpuResult<usize> {
        if let Some(i) = self.sets.iter().position(|s| s.pending.is_none()) {
            return Ok(i);
        }
        if self.sets.len() >= MAX_FRAMES_IN_FLIGHT {
            return Err(GpuError::InvalidArgument(format!(
                "{MAX_FRAMES_IN_FLIGHT} frames are in flight already; finish one before submitting another"
            )));
        }
        let set = FrameSet::new(&self.ctx, self.sets.len(), self.blend.kernel().bin_size())?;
        self.sets.push(set);
        Ok(self.sets.len() - 1)
    }

    /// Checks a frame, makes its resources in a free set, and records and submits it.
    fn submit_with<'a>(
        &mut self,
        scene: &'a GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        readback: Readback,
        features: Option<FeatureJob<'a>>,
    ) -> GpuResult<Ticket<'a>> {
        cam.validate()
            .map_err(|e| GpuError::InvalidArgument(e.to_string()))?;
        opts.validate().map_err(GpuError::InvalidArgument)?;
        if scene.compact && self.compact_preprocess.is_none() {
            self.compact_preprocess = Some(preprocess::Preprocess::new(
                &self.ctx,
                true,
                self.preprocess.texel_io(),
            )?);
        }
        if opts.kernel == SplatKernel::Power && self.power_blend.is_none() {
            self.power_blend = Some(blend::Blend::new(
                &self.ctx,
                self.blend.kernel(),
                SplatKernel::Power,
            )?);
        }
        let set = self.free_set()?;
        let initial = self
            .capacity
            .unwrap_or(MIN_CAPACITY.max(scene.count.saturating_mul(4)))
            .min(self.max_capacity());
        self.ensure_frame(set, scene, cam, initial)?;
        let preferred = self.blend.kernel().bin_size();
        self.sets[set].bin_size = if self.large_bins == Some((scene.count, cam.width, cam.height)) {
            16
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
            || u64::from(scene.count) * 4 > u64::from(self.max_capacity());
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
            self.record_ticket(&ticket, false, Pass::Whole)?;
        }
        self.sets[set].pending = Some(ticket.serial);
        Ok(ticket)
    }

    /// Makes what the ticket's readback and features need in its set, then records and
    /// submits `pass` of the frame (and waits for it when `wait`).
    fn record_ticket(&mut self, t: &Ticket, wait: bool, pass: Pass) -> GpuResult<()> {
        if t.readback == Readback::Rgba8 {
            self.ensure_packed(t.set)?;
        }
        if let Some((features, _)) = t.features {
            let pixels = u64::from(t.cam.width) * u64::from(t.cam.height);
            self.ensure_feature_planes(t.set, features, pixels)?;
        }
        self.record_and_submit(
            t.set, t.scene, &t.cam, &t.opts, t.readback, t.features, wait, pass,
        )
    }

    /// Waits for the ticket's frame and checks its counters: when the frame needed more
    /// pairs than its buffers hold, or larger bins, it is recorded again with larger
    /// buffers or bins and waited for, until it is complete; when it needs more pairs than
    /// one key buffer holds, it is rendered in chunks. Then the timings and counts are the
    /// frame's.
    fn complete(&mut self, t: &Ticket) -> GpuResult<()> {
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
        self.ctx.wait_slot(&mut set.slot)?;
        let cam = &t.cam;
        let max = self.max_capacity();
        let mut chunked = t.chunked;
        let mut regrows = 0;
        loop {
            let (counters, chunks) = if chunked {
                match self.render_chunks(t)? {
                    Some(done) => done,
                    None => {
                        // Larger bins or key buffers: the frame is planned again.
                        regrows += 1;
                        continue;
                    }
                }
            } else {
                (self.read_counters(t.set)?, 1)
            };
            let pairs = counters.pairs();
            let set = &self.sets[t.set];
            let capacity = set.frame.as_ref().map_or(0, |f| f.capacity);
            let bin_size = set.bin_size;
            let complete = chunked || pairs <= u64::from(capacity);
            if complete && self.loop_limited() {
                let bins_loop = counters.max_bins_loop;
                if !chunked && bins_loop > CPU_LOOP_LIMIT && bin_size < 16 {
                    // Four times fewer iterations per Gaussian with 16-pixel bins.
                    self.sets[t.set].bin_size = 16;
                    regrows += 1;
                    self.record_ticket(t, true, Pass::Whole)?;
                    continue;
                }
                let worst = bins_loop.max(counters.max_list_loop);
                if worst > CPU_LOOP_LIMIT {
                    return Err(GpuError::InvalidArgument(format!(
                        "this frame needs a shader loop of {worst} iterations ({} bins of one Gaussian, {} Gaussians in one bin), but {} ends every shader invocation's loops after {CPU_LOOP_LIMIT} iterations in total, which would silently drop Gaussians; render at a lower resolution, or on another device",
                        bins_loop,
                        counters.max_list_loop,
                        self.ctx.info().name
                    )));
                }
            }
            if complete {
                // Larger bins stick while the pairs say the preferred ones would not do: an
                // 8-pixel bin frame has at most 4 times the pairs of a 16-pixel one.
                let preferred = self.blend.kernel().bin_size();
                let sticky =
                    bin_size > preferred && pairs * 4 > u64::from(max.min(SMALL_BIN_MAX_PAIRS));
                self.large_bins = sticky.then_some((t.scene.count, cam.width, cam.height));
                let (bx, by) = bin_grid(bin_size, cam.width, cam.height);
                self.stats = FrameStats {
                    visible: counters.visible,
                    pairs,
                    key_bits: key_bits(bx * by),
                    regrows,
                    bin_size,
                    chunks,
                };
                self.capacity = Some(self.capacity.unwrap_or(0).max(capacity));
                break;
            }
            if pairs > u64::from(max.min(SMALL_BIN_MAX_PAIRS)) && bin_size < 16 {
                // Fewer, larger bins need fewer pairs; the texel kernel blends either.
                self.sets[t.set].bin_size = 16;
                regrows += 1;
                self.record_ticket(t, true, Pass::Whole)?;
                continue;
            }
            if pairs > u64::from(max) {
                // Too many pairs for one key buffer: this frame and the next in chunks.
                self.chunked = true;
                chunked = true;
                regrows += 1;
                continue;
            }
            // Grow with headroom so a camera path does not regrow every few frames.
            let grown = (pairs + pairs / 4).min(u64::from(max)) as u32;
            self.ensure_frame(t.set, t.scene, cam, grown)?;
            regrows += 1;
            self.record_ticket(t, true, Pass::Whole)?;
        }
        if !chunked {
            self.timings = self.read_timings(t.set)?;
        }
        self.last = t.set;
        Ok(())
    }

    /// Renders the ticket's frame in depth-ordered chunks whose pairs fit the key buffers:
    /// one submission up to the scan, whose offsets the host reads to plan the chunks, then
    /// keys, sort, ranges and blend per chunk, each blend resuming every pixel where the
    /// previous chunk left it (`glsl/blend.comp`). The chunks' lists are, tile by tile,
    /// consecutive runs of the one-piece frame's lists, so the image is bit-identical.
    /// Returns the frame's counters and its number of chunks, or None when the frame must
    /// be planned again (larger bins, or key buffers grown for its largest chunk).
    fn render_chunks(&mut self, t: &Ticket) -> GpuResult<Option<(Counters, u32)>> {
        let max = self.max_capacity();
        let f = self.sets[t.set]
            .frame
            .as_mut()
            .ok_or_else(|| GpuError::InvalidArgument("frame buffers missing".into()))?;
        if f.chunk_offsets.is_none() {
            f.chunk_offsets = Some(GpuBuffer::new(
                &self.ctx,
                "scanned offsets (chunk planning)",
                u64::from(f.gaussians.max(1)) * 4,
                MemoryKind::Readback,
            )?);
        }
        self.record_ticket(t, true, Pass::Front)?;
        let mut timings = self.read_timings(t.set)?;
        let front = self.read_counters(t.set)?;
        let pairs = front.pairs();
        let bins_cut = self.loop_limited() && front.max_bins_loop > CPU_LOOP_LIMIT;
        let too_many = pairs > u64::from(max.min(SMALL_BIN_MAX_PAIRS));
        if (bins_cut || too_many) && self.sets[t.set].bin_size < 16 {
            // As in one piece: 16-pixel bins first (fewer pairs and bin-loop iterations).
            self.sets[t.set].bin_size = 16;
            return Ok(None);
        }
        let limit = self.pairs_per_piece();
        let (chunks, capacity) = {
            let f = self.sets[t.set]
                .frame
                .as_ref()
                .ok_or_else(|| GpuError::InvalidArgument("frame buffers missing".into()))?;
            let visible = (front.visible as usize).min(t.scene.count as usize);
            let bytes = f
                .chunk_offsets
                .as_ref()
                .ok_or_else(|| GpuError::InvalidArgument("chunk offsets missing".into()))?
                .mapped()?;
            let offsets: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[..visible * 4]);
            (
                keys::plan_chunks(&offsets, pairs, u64::from(limit)),
                f.capacity,
            )
        };
        let largest = chunks.iter().map(|c| c.pairs).max().unwrap_or(0);
        if largest > u64::from(capacity) {
            if largest > u64::from(max) {
                return Err(GpuError::InvalidArgument(format!(
                    "one Gaussian of this frame touches {largest} bins, more than the {max} pairs one storage buffer of this device can hold; render at a lower resolution"
                )));
            }
            let grown = (largest + largest / 4).min(u64::from(max)) as u32;
            self.ensure_frame(t.set, t.scene, &t.cam, grown)?;
            return Ok(None);
        }
        let batches = chunks.len().div_ceil(CHUNKS_PER_SUBMIT);
        for (b, batch) in chunks.chunks(CHUNKS_PER_SUBMIT).enumerate() {
            let pass = Pass::Chunks {
                chunks: batch,
                first: b == 0,
                last: b + 1 == batches,
            };
            self.record_ticket(t, true, pass)?;
            timings.add(&self.read_timings(t.set)?);
        }
        self.timings = timings;
        // Copied after the last chunk: the front's totals, the chunks' loop lengths.
        let counters = self.read_counters(t.set)?;
        Ok(Some((counters, chunks.len() as u32)))
    }

    /// Makes the packed RGBA8 buffer of set `set`'s frame buffers.
    fn ensure_packed(&mut self, set: usize) -> GpuResult<()> {
        let f = self.sets[set]
            .frame
            .as_mut()
            .ok_or_else(|| GpuError::InvalidArgument("frame buffers missing".into()))?;
        if f.packed.is_none() {
            let bytes = u64::from(f.width) * u64::from(f.height) * 4;
            check_binding(&self.ctx, "packed rgba8 frame", bytes)?;
            f.packed = Some(GpuBuffer::new(
                &self.ctx,
                "packed rgba8 frame",
                bytes,
                MemoryKind::Device,
            )?);
        }
        Ok(())
    }

    /// Records the frame into set `set`'s command buffer and submits it; waits for it
    /// when `wait`.
    #[allow(clippy::too_many_arguments)]
    fn record_and_submit(
        &mut self,
        set: usize,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        readback: Readback,
        features: Option<FeatureJob>,
        wait: bool,
        pass: Pass,
    ) -> GpuResult<()> {
        let window = self.preprocess_window();
        let Self {
            preprocess,
            compact_preprocess,
            order,
            scan,
            keys,
            sort,
            ranges,
            blend,
            power_blend,
            feature_blends,
            shade,
            pack,
            sets,
            ctx,
            ..
        } = self;
        let FrameSet {
            slot,
            timer,
            frame,
            feature_planes,
            bin_size,
            ..
        } = sets
            .get_mut(set)
            .ok_or_else(|| GpuError::InvalidArgument(format!("no frame set {set}")))?;
        let feature_job = match features {
            Some((feat, _)) => Some((
                feat,
                feature_blends[opts.kernel.shader_id() as usize]
                    .as_ref()
                    .ok_or_else(|| {
                        GpuError::InvalidArgument("the feature blend pipeline is missing".into())
                    })?,
            )),
            None => None,
        };
        let preprocess = match (scene.compact, compact_preprocess.as_ref()) {
            (false, _) => &*preprocess,
            (true, Some(p)) => p,
            (true, None) => {
                return Err(GpuError::InvalidArgument(
                    "the compact preprocess pipeline is missing".into(),
                ))
            }
        };
        let blend = match (opts.kernel, power_blend.as_ref()) {
            (SplatKernel::Gaussian, _) => &*blend,
            (SplatKernel::Power, Some(b)) => b,
            (SplatKernel::Power, None) => {
                return Err(GpuError::InvalidArgument(
                    "the power-kernel blend pipeline is missing".into(),
                ))
            }
        };
        let f = frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("frame buffers missing".into()))?;
        let (tiles_x, tiles_y) = cam.tile_grid();
        let bin_size = *bin_size;
        let (bins_x, bins_y) = bin_grid(bin_size, cam.width, cam.height);
        let pos = cam.position();
        let r = cam.rotation;
        let t = cam.translation;
        let params = FrameParams {
            w2c_row0: [r.x_axis.x, r.y_axis.x, r.z_axis.x, t.x],
            w2c_row1: [r.x_axis.y, r.y_axis.y, r.z_axis.y, t.y],
            w2c_row2: [r.x_axis.z, r.y_axis.z, r.z_axis.z, t.z],
            cam_pos: [
                pos.x,
                pos.y,
                pos.z,
                if opts.antialiased { 1.0 } else { 0.0 },
            ],
            focal: [cam.fx, cam.fy, cam.cx, cam.cy],
            tan_fov: [cam.tan_half_fov_x(), cam.tan_half_fov_y(), 0.0, 0.0],
            background: [
                opts.background[0],
                opts.background[1],
                opts.background[2],
                0.0,
            ],
            image: [cam.width, cam.height, tiles_x, tiles_y],
            counts: [
                scene.count,
                opts.active_sh_degree(scene.sh_degree),
                scene.sh_coeffs,
                f.capacity,
            ],
            bins: [bin_size, bins_x, bins_y, 16 / bin_size],
            filters: [
                opts.scale_modifier,
                opts.max_scale.unwrap_or(-1.0),
                opts.min_opacity.unwrap_or(-1.0),
                opts.kernel.shader_id() as f32,
            ],
        };
        let n = scene.count;
        let pair_bits = 0..tile_bits(bins_x * bins_y);
        let whole = [keys::Chunk::whole(n)];
        let (chunks, first_chunks, last_chunks) = match pass {
            Pass::Whole => (&whole[..], true, true),
            Pass::Front => (&[][..], true, false),
            Pass::Chunks {
                chunks,
                first,
                last,
            } => (chunks, first, last),
        };
        let front = !matches!(pass, Pass::Chunks { .. });
        let record = |cmd| {
            let device = ctx.device();
            timer.reset(ctx, cmd);
            if !front {
                // Everything the previous submission of this frame wrote (the scan, the
                // images, the counters) -> this one; its reads -> this one's writes.
                barrier(ctx, cmd, Access::Any, Access::Any);
            } else {
                // SAFETY: cmd is recording; the buffers are alive and large enough.
                unsafe {
                    device.cmd_update_buffer(
                        cmd,
                        f.params.handle(),
                        0,
                        bytemuck::bytes_of(&params),
                    );
                    device.cmd_fill_buffer(cmd, f.counters.handle(), 0, vk::WHOLE_SIZE, 0);
                    device.cmd_fill_buffer(cmd, f.ranges.handle(), 0, vk::WHOLE_SIZE, 0);
                }
                f.color.transition_to_general(ctx, cmd);
                f.depth.transition_to_general(ctx, cmd);
                // Params, counters and ranges: from the clears to the shaders that use them.
                barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);

                timer.stage(ctx, cmd, "preprocess", |cmd| {
                    preprocess.record(
                        ctx,
                        cmd,
                        &preprocess::PreprocessBindings {
                            params: f.params.whole(),
                            gaussians: scene.gaussians.whole(),
                            sh_texels: scene.sh_texels.handle(),
                            splats: f.splats.whole(),
                            rects: f.rects.whole(),
                            depth_keys: f.depth_keys.whole(),
                            counters: f.counters.whole(),
                            depth_values: f.depth_values.whole(),
                            bin_masks: f.bin_masks.whole(),
                            touched: f.touched.whole(),
                            texels: if preprocess.texel_io() {
                                Some(f.preprocess_texels(scene)?)
                            } else {
                                None
                            },
                        },
                        n,
                        window,
                    )
                })?;
                // The depth sort opens with its own barrier from compute writes (its contract).
                timer.stage(ctx, cmd, "order", |cmd| {
                    order.record(
                        ctx,
                        cmd,
                        sort,
                        &f.params,
                        &f.depth_keys,
                        &f.depth_values,
                        &f.sort_scratch,
                        f.depth_sort_texels().as_ref(),
                        f.touched.whole(),
                        f.offsets.whole(),
                        (n, f.gaussians.max(1)),
                    )
                })?;
                // Tiles touched in depth order -> scan; depth order and counters -> keys.
                barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);

                timer.stage(ctx, cmd, "scan", |cmd| {
                    scan.record(
                        ctx,
                        cmd,
                        f.offsets.slice(0, u64::from(n) * 4),
                        f.offsets.slice(0, u64::from(n) * 4),
                        (&f.counters, types::COUNTER_SCAN_TOTAL),
                        f.scan_scratch.whole(),
                        n,
                    )
                })?;
                // Offsets and the scan total -> keys; the splats (preprocess) -> its texel reads.
                barrier_uses(
                    ctx,
                    cmd,
                    &[Access::ComputeWrite],
                    &[Access::ComputeReadWrite, Access::ComputeSampledRead],
                );
            }
            if let Pass::Front = pass {
                // The counters and the scanned offsets -> copies for the host.
                barrier(ctx, cmd, Access::ComputeReadWrite, Access::TransferRead);
                let planning = f.chunk_offsets.as_ref().ok_or_else(|| {
                    GpuError::InvalidArgument("the chunk planning buffer is missing".into())
                })?;
                let (_, _, counters_off) = f.readback_offsets();
                let counters = [vk::BufferCopy::default()
                    .dst_offset(counters_off)
                    .size(std::mem::size_of::<Counters>() as u64)];
                let offsets = [vk::BufferCopy::default().size(planning.size())];
                // SAFETY: the buffers are alive and the regions are inside them (the
                // planning buffer holds one offset per Gaussian, as the offsets buffer).
                unsafe {
                    device.cmd_copy_buffer(
                        cmd,
                        f.counters.handle(),
                        f.readback.handle(),
                        &counters,
                    );
                    device.cmd_copy_buffer(cmd, f.offsets.handle(), planning.handle(), &offsets);
                }
                barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
                return Ok(());
            }
            for (c, &chunk) in chunks.iter().enumerate() {
                let resume = !(first_chunks && c == 0);
                if resume {
                    if c > 0 {
                        // The previous chunk's uses of the keys, values, ranges, counters
                        // and images -> this chunk's clears and writes.
                        barrier(ctx, cmd, Access::Any, Access::Any);
                    }
                    f.ranges.fill(ctx, cmd, 0, vk::WHOLE_SIZE, 0);
                    // Cleared ranges -> the ranges stage.
                    barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
                }
                timer.stage(ctx, cmd, "keys", |cmd| {
                    keys.record(
                        ctx,
                        cmd,
                        &keys::KeysBindings {
                            params: f.params.whole(),
                            splat_texels: f.splat_texels.handle(),
                            counters: f.counters.whole(),
                            io: f.keys_io(keys.texel_io())?,
                        },
                        chunk,
                    )
                })?;
                // The sort opens with its own barrier from compute writes (its contract).
                // Pairs arrive in depth order: only the tile bits remain to be sorted.
                timer.stage(ctx, cmd, "sort", |cmd| {
                    let count = Count::Device {
                        buffer: &f.counters,
                        offset: types::COUNTER_SORT_COUNT,
                        max_n: f.capacity,
                    };
                    let (k, v, s) = (&f.keys, &f.values, &f.sort_scratch);
                    let texels = f.pair_sort_texels();
                    sort.record_views(ctx, cmd, k, v, s, count, pair_bits.clone(), texels.as_ref())
                })?;
                // Sorted keys -> ranges (storage or texel reads); the ranges dispatch
                // arguments (written by keys) -> indirect read.
                barrier_uses(
                    ctx,
                    cmd,
                    &[Access::ComputeWrite],
                    &[
                        Access::ComputeRead,
                        Access::ComputeSampledRead,
                        Access::IndirectRead,
                    ],
                );

                timer.stage(ctx, cmd, "ranges", |cmd| {
                    let sorted_keys = match (ranges.texel_io(), f.sort_views.as_ref()) {
                        (true, Some(v)) => Resource::TexelBuffer(v.keys.handle()),
                        _ => Resource::Buffer(f.keys.whole()),
                    };
                    ranges.record(
                        ctx,
                        cmd,
                        sorted_keys,
                        f.ranges.whole(),
                        f.counters.whole(),
                        f.counters.slice(types::COUNTER_RANGES_GROUPS, 12),
                    )
                })?;
                // Ranges, sorted values and splats -> blend and feature blend (storage reads,
                // or texel fetches in the texel kernels); counters -> their loop-length atomics.
                barrier_uses(
                    ctx,
                    cmd,
                    &[Access::ComputeWrite],
                    &[Access::ComputeReadWrite, Access::ComputeSampledRead],
                );

                if let Some((feat, pipeline)) = &feature_job {
                    // Before the colour blend: a resumed chunk reads the pixels' transmittance
                    // as the previous chunk left it in the colour image.
                    timer.stage(ctx, cmd, "features", |cmd| {
                        let planes = feature_planes.as_ref().ok_or_else(|| {
                            GpuError::InvalidArgument("the feature images are missing".into())
                        })?;
                        for (g, input) in feat.groups.iter().enumerate() {
                            let output = planes
                                .buffer
                                .slice(g as u64 * planes.plane_bytes, planes.pixel_bytes);
                            let texels = match (&f.splat_texels, &f.value_texels, feat.views.get(g))
                            {
                                (s, Some(v), Some(fv)) if pipeline.texel() => {
                                    Some([s.handle(), v.handle(), fv.handle()])
                                }
                                _ => None,
                            };
                            pipeline.record(
                                ctx,
                                cmd,
                                &features::FeatureBindings {
                                    params: f.params.whole(),
                                    splats: f.splats.whole(),
                                    values: f.values.whole(),
                                    ranges: f.ranges.whole(),
                                    features: input.whole(),
                                    output,
                                    counters: f.counters.whole(),
                                    texels,
                                    color: &f.color,
                                    resume,
                                },
                                (cam.width, cam.height),
                            )?;
                        }
                        Ok(())
                    })?;
                    // Its colour-image reads and loop-length atomics -> the blend's.
                    barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
                }

                timer.stage(ctx, cmd, "blend", |cmd| {
                    blend.record(
                        ctx,
                        cmd,
                        &blend::BlendBindings {
                            params: f.params.whole(),
                            splats: f.splats.whole(),
                            values: f.values.whole(),
                            splat_texels: Some(f.splat_texels.handle()),
                            value_texels: f.value_texels.as_ref().map(|v| v.handle()),
                            ranges: f.ranges.whole(),
                            color: &f.color,
                            depth: &f.depth,
                            counters: f.counters.whole(),
                            resume,
                            last: last_chunks && c + 1 == chunks.len(),
                        },
                        (tiles_x, tiles_y),
                    )
                })?;
            }
            if !last_chunks {
                return Ok(());
            }
            if feature_job.is_some() {
                if let Some(shader) = features.and_then(|(_, s)| s) {
                    let (planes, pipeline) = match (feature_planes.as_ref(), shade.as_ref()) {
                        (Some(p), Some(s)) => (p, s),
                        _ => {
                            return Err(GpuError::InvalidArgument(
                                "the neural shader's pipeline or images are missing".into(),
                            ))
                        }
                    };
                    // The feature blend's writes (and the blend's colour image) -> reads.
                    barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
                    timer.stage(ctx, cmd, "shade", |cmd| {
                        pipeline.record(
                            ctx,
                            cmd,
                            shader,
                            planes.buffer.whole(),
                            (planes.plane_bytes / 16) as u32,
                            &f.color,
                            cam,
                            opts.background,
                        )
                    })?;
                }
            }
            // Only what the consumer needs leaves the device. Float: the images are the
            // copy sources. Rgba8: the colour image is packed by a compute pass (timed
            // with the readback) and only the packed buffer is copied.
            timer.stage(ctx, cmd, "readback", |cmd| {
                let (color_off, depth_off, counters_off) = f.readback_offsets();
                match (readback, f.packed.as_ref()) {
                    (Readback::Float, _) => {
                        // Images -> copy sources; counters (written by compute) -> copy.
                        f.color.transition_for_copy(ctx, cmd);
                        f.depth.transition_for_copy(ctx, cmd);
                        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                        f.color.copy_to_buffer(ctx, cmd, &f.readback, color_off);
                        f.depth.copy_to_buffer(ctx, cmd, &f.readback, depth_off);
                    }
                    (Readback::Rgba8, Some(packed)) => {
                        // The blend's image writes -> the pack's image reads.
                        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
                        pack.record(ctx, cmd, &f.color, packed.whole(), (f.width, f.height))?;
                        // Packed pixels and counters (written by compute) -> copy.
                        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
                        let region = [vk::BufferCopy::default()
                            .src_offset(0)
                            .dst_offset(color_off)
                            .size(packed.size())];
                        // SAFETY: both buffers are alive; the readback holds 16 bytes per
                        // pixel at color_off, the packed buffer 4.
                        unsafe {
                            device.cmd_copy_buffer(
                                cmd,
                                packed.handle(),
                                f.readback.handle(),
                                &region,
                            )
                        };
                    }
                    (Readback::Rgba8, None) => {
                        return Err(GpuError::InvalidArgument(
                            "the packed frame buffer is missing".into(),
                        ))
                    }
                }
                let region = [vk::BufferCopy::default()
                    .src_offset(0)
                    .dst_offset(counters_off)
                    .size(std::mem::size_of::<Counters>() as u64)];
                // SAFETY: both buffers are alive and the region is inside them.
                unsafe {
                    device.cmd_copy_buffer(cmd, f.counters.handle(), f.readback.handle(), &region)
                };
                Ok(())
            })?;
            barrier(ctx, cmd, Access::TransferWrite, Access::HostRead);
            Ok(())
        };
        if wait {
            ctx.submit_slot(slot, record)
        } else {
            ctx.submit_slot_nowait(slot, record)
        }
    }

    fn read_counters(&self, set: usize) -> GpuResult<Counters> {
        let f = self.sets[set]
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no frame".into()))?;
        let (_, _, off) = f.readback_offsets();
        let bytes = f.readback.mapped()?;
        Ok(bytemuck::pod_read_unaligned(
            &bytes[off as usize..off as usize + std::mem::size_of::<Counters>()],
        ))
    }

    fn read_timings(&self, set: usize) -> GpuResult<StageTimings> {
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

    fn read_frame(&self, set: usize, cam: &Camera) -> GpuResult<Frame> {
        let f = self.sets[set]
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no frame".into()))?;
        let bytes = f.readback.mapped()?;
        let pixels = cam.width as usize * cam.height as usize;
        let (color_off, depth_off, _) = f.readback_offsets();
        let rgba: &[[f32; 4]] =
            bytemuck::cast_slice(&bytes[color_off as usize..color_off as usize + pixels * 16]);
        let depth: &[f32] =
            bytemuck::cast_slice(&bytes[depth_off as usize..depth_off as usize + pixels * 4]);
        Ok(Frame {
            width: cam.width,
            height: cam.height,
            color: rgba.iter().map(|p| [p[0], p[1], p[2]]).collect(),
            alpha: rgba.iter().map(|p| p[3]).collect(),
            depth: depth.to_vec(),
            feature_count: 0,
            features: Vec::new(),
        })
    }

    fn read_rgba8(&self, set: usize, cam: &Camera) -> GpuResult<Rgba8Frame> {
        let f = self.sets[set]
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no frame".into()))?;
        let bytes = f.readback.mapped()?;
        let len = cam.width as usize * cam.height as usize * 4;
        let (color_off, _, _) = f.readback_offsets();
        Ok(Rgba8Frame {
            width: cam.width,
            height: cam.height,
            rgba: bytes[color_off as usize..color_off as usize + len].to_vec(),
        })
    }

    /// The intermediate buffers of the last frame finished.
    fn read_intermediates(&self, scene: &GpuScene, cam: &Camera) -> GpuResult<Intermediates> {
        let set = &self.sets[self.last];
        let f = set
            .frame
            .as_ref()
            .ok_or_else(|| GpuError::InvalidArgument("no frame".into()))?;
        let ctx = &self.ctx;
        let n = scene.count as usize;
        let counters = self.read_counters(self.last)?;
        let sorted = counters.sort_count as usize;
        let bin_size = set.bin_size;
        let (bx, by) = bin_grid(bin_size, cam.width, cam.height);
        Ok(Intermediates {
            splats: f.splats.read(ctx, n)?,
            rects: f.rects.read(ctx, n)?,
            order: f.depth_values.read(ctx, n)?,
            offsets: f.offsets.read(ctx, n)?,
            counters,
            keys: f.keys.read(ctx, sorted)?,
            values: f.values.read(ctx, sorted)?,
            ranges: f.ranges.read(ctx, (bx * by) as usize)?,
            bin_size,
            bins: (bx, by),
        })
    }
}
