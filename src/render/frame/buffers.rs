//! Per-frame device resources: the frame buffers sized by the scene, the resolution and
//! the key capacity, the feature planes, and the set of them each frame in flight owns.

use crate::core::camera::Camera;
use crate::gpu::shader::Resource;
use crate::gpu::sort::{SortTexels, SORT_CONFIG_32};
use crate::gpu::{
    BufferView, FrameSlot, GpuBuffer, GpuContext, GpuError, GpuImage, GpuResult, GpuTimer,
    MemoryKind, RadixSort, Scan,
};
use crate::render::forward::types::{Counters, FrameParams, Splat};
use ash::vk;

use crate::render::forward::{keys, preprocess};
use crate::render::frame::pipelines::Pipelines;
use crate::render::{bin_grid, GpuFeatures, GpuScene, MAX_FRAMES_IN_FLIGHT, MAX_STAGES_PER_SUBMIT};

/// The feature images of a frame: one plane per group of four channels.
pub(crate) struct FeaturePlanes {
    pub(crate) buffer: GpuBuffer,
    /// Bytes from one plane to the next.
    pub(crate) plane_bytes: u64,
    /// Bytes of one plane's pixels.
    pub(crate) pixel_bytes: u64,
    /// Planes held.
    pub(crate) groups: u64,
}

/// Refuses a buffer that one storage-buffer binding of the device cannot cover
/// ([`crate::gpu::limits::check_binding`]).
pub(crate) fn check_binding(ctx: &GpuContext, what: &str, bytes: u64) -> GpuResult<()> {
    crate::gpu::limits::check_binding(
        ctx.info(),
        what,
        bytes,
        "use fewer Gaussians or a device with a larger limit",
    )
}

/// Texel views the sorts, preprocess, keys and ranges read and write on CPU devices
/// ([`SortConfig::texel_io`], `PREPROCESS_TEXEL_IO`, `KEYS_TEXEL_IO`, `RANGES_TEXEL_IO`),
/// R32_UINT unless noted: the depth order's keys, values and scratch halves, the pair
/// sort's (its values are viewed by [`FrameBuffers::value_texels`], the splats by
/// [`FrameBuffers::splat_texels`]), and the other per-Gaussian arrays.
pub(crate) struct SortViews {
    pub(crate) depth_keys: BufferView,
    pub(crate) depth_values: BufferView,
    pub(crate) depth_scratch: [BufferView; 2],
    pub(crate) keys: BufferView,
    pub(crate) pair_scratch: [BufferView; 2],
    /// R32G32_UINT.
    pub(crate) rects: BufferView,
    pub(crate) offsets: BufferView,
    pub(crate) bin_masks: BufferView,
    pub(crate) touched: BufferView,
}

/// Per-frame device buffers, sized by the scene, the resolution and the key capacity.
/// The name of the buffer of the pixels' last contributors, in errors.
pub(crate) const LAST_CONTRIBUTOR: &str = "last contributor per pixel";

/// (Fields drop in order: the texel views go before the buffers they view.)
pub(crate) struct FrameBuffers {
    pub(crate) sort_views: Option<SortViews>,
    pub(crate) splat_texels: BufferView,
    pub(crate) value_texels: Option<BufferView>,
    pub(crate) gaussians: u32,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) capacity: u32,
    pub(crate) params: GpuBuffer,
    pub(crate) counters: GpuBuffer,
    pub(crate) splats: GpuBuffer,
    pub(crate) rects: GpuBuffer,
    pub(crate) offsets: GpuBuffer,
    pub(crate) depth_keys: GpuBuffer,
    pub(crate) touched: GpuBuffer,
    pub(crate) depth_values: GpuBuffer,
    pub(crate) bin_masks: GpuBuffer,
    pub(crate) scan_scratch: GpuBuffer,
    pub(crate) keys: GpuBuffer,
    pub(crate) values: GpuBuffer,
    pub(crate) sort_scratch: GpuBuffer,
    pub(crate) ranges: GpuBuffer,
    pub(crate) color: GpuImage,
    pub(crate) depth: GpuImage,
    /// 8-bit RGBA of the colour image; made on the first [`Readback::Rgba8`] frame.
    pub(crate) packed: Option<GpuBuffer>,
    pub(crate) readback: GpuBuffer,
    /// The scanned offsets read back to plan a frame's chunks (host-visible); made on
    /// the first frame rendered in chunks.
    pub(crate) chunk_offsets: Option<GpuBuffer>,
    /// One past the sorted-pair index of each pixel's last contributor; made on the first
    /// frame that saves its forward state.
    pub(crate) last_contributor: Option<GpuBuffer>,
}

impl FrameBuffers {
    pub(crate) fn new(
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
            return Err(GpuError::DeviceLimit {
                limit: "maxTexelBufferElements",
                needed: (n * 3).max(u64::from(capacity)),
                max: max_texels,
                message: format!(
                    "{gaussians} Gaussians need texel buffers of {} texels (3 per splat), but this device addresses at most {max_texels} (maxTexelBufferElements); use fewer Gaussians or a device with a larger limit",
                    n * 3
                ),
            });
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
            last_contributor: None,
        })
    }

    /// The depth order's sort views, when the sorts read through texel views.
    pub(crate) fn depth_sort_texels(&self) -> Option<SortTexels> {
        self.sort_views.as_ref().map(|v| SortTexels {
            keys: v.depth_keys.handle(),
            values: v.depth_values.handle(),
            scratch_keys: v.depth_scratch[0].handle(),
            scratch_values: v.depth_scratch[1].handle(),
        })
    }

    /// The views of the texel-I/O preprocess, over this frame's buffers and `scene`'s
    /// records.
    pub(crate) fn preprocess_texels(
        &self,
        scene: &GpuScene,
    ) -> GpuResult<preprocess::PreprocessTexels> {
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
    pub(crate) fn keys_io(&self, texel_io: bool) -> GpuResult<keys::KeysIo<'_>> {
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
                return Err(GpuError::Internal(
                    "the keys stage's texel views are missing".into(),
                ))
            }
        })
    }

    /// The pair sort's views, when the sorts read through texel views.
    pub(crate) fn pair_sort_texels(&self) -> Option<SortTexels> {
        let v = self.sort_views.as_ref()?;
        Some(SortTexels {
            keys: v.keys.handle(),
            values: self.value_texels.as_ref()?.handle(),
            scratch_keys: v.pair_scratch[0].handle(),
            scratch_values: v.pair_scratch[1].handle(),
        })
    }

    pub(crate) fn device_bytes(&self) -> u64 {
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
            + self.last_contributor.as_ref().map_or(0, |b| b.size())
            + self.color.bytes()
            + self.depth.bytes()
    }

    pub(crate) fn readback_offsets(&self) -> (u64, u64, u64) {
        let pixels = u64::from(self.width) * u64::from(self.height);
        (0, pixels * 16, pixels * 20)
    }
}

/// The resources of one frame in flight: command buffer and fence, timestamp queries,
/// frame buffers and feature images. (Fields drop in order: the slot goes first and waits
/// for a submission still pending, before the buffers it uses go.)
pub(crate) struct FrameSet {
    pub(crate) slot: FrameSlot,
    pub(crate) timer: GpuTimer,
    pub(crate) frame: Option<FrameBuffers>,
    /// The feature images of this set's last features frame, one plane per group of four
    /// channels (vec4 per pixel) in one buffer, planes `plane_bytes` apart (a multiple of
    /// the storage-buffer offset alignment); kept across frames of the same size.
    pub(crate) feature_planes: Option<FeaturePlanes>,
    /// Bin size of the frame recorded in this set (see [`FrameStats::bin_size`]).
    pub(crate) bin_size: u32,
    /// The serial number of the frame submitted in this set and not finished yet.
    pub(crate) pending: Option<u64>,
    /// The frame last recorded in this set writes each pixel's last contributor (a frame
    /// in one piece recorded while the renderer saves its forward state).
    pub(crate) saves_last: bool,
}

impl FrameSet {
    pub(crate) fn new(ctx: &GpuContext, index: usize, bin_size: u32) -> GpuResult<Self> {
        Ok(FrameSet {
            slot: FrameSlot::new(ctx, &format!("frame {index}"))?,
            // Two timestamps per stage, as many stages as one submission records.
            timer: GpuTimer::new(
                ctx,
                &format!("frame {index} timestamps"),
                MAX_STAGES_PER_SUBMIT,
            )?,
            frame: None,
            feature_planes: None,
            bin_size,
            pending: None,
            saves_last: false,
        })
    }
}

impl FrameSet {
    /// Makes the set's feature planes hold `features`' groups for `pixels` pixels.
    pub(crate) fn ensure_feature_planes(
        &mut self,
        ctx: &GpuContext,
        features: &GpuFeatures,
        pixels: u64,
    ) -> GpuResult<()> {
        let groups = features.groups.len() as u64;
        let align = ctx.info().min_storage_buffer_offset_alignment.max(16);
        let plane_bytes = (pixels * 16).div_ceil(align) * align;
        let planes = &mut self.feature_planes;
        let fits = planes
            .as_ref()
            .is_some_and(|p| p.plane_bytes == plane_bytes && p.groups >= groups);
        if !fits {
            *planes = None;
            check_binding(ctx, "feature image", plane_bytes * groups)?;
            *planes = Some(FeaturePlanes {
                buffer: GpuBuffer::new(
                    ctx,
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

    /// Makes the set's frame buffers fit the scene, the camera and `capacity` pairs (with
    /// the texel views `pipelines` read and their kernel's bins).
    pub(crate) fn ensure_frame(
        &mut self,
        ctx: &GpuContext,
        pipelines: &Pipelines,
        scene: &GpuScene,
        cam: &Camera,
        capacity: u32,
    ) -> GpuResult<()> {
        let frame = &mut self.frame;
        let fits = frame.as_ref().is_some_and(|f| {
            f.gaussians >= scene.count
                && f.width == cam.width
                && f.height == cam.height
                && f.capacity >= capacity
        });
        if !fits {
            // Free the old buffers first so peak memory is not doubled.
            *frame = None;
            let views = pipelines.texel_io();
            *frame = Some(FrameBuffers::new(
                ctx,
                scene.count,
                cam.width,
                cam.height,
                capacity,
                views,
                pipelines.kernel().bin_size(),
            )?);
        }
        Ok(())
    }

    /// Makes the last-contributor buffer of the set's frame buffers.
    pub(crate) fn ensure_last_contributor(&mut self, ctx: &GpuContext) -> GpuResult<()> {
        let f = self
            .frame
            .as_mut()
            .ok_or_else(|| GpuError::Internal("frame buffers missing".into()))?;
        if f.last_contributor.is_none() {
            // (last contributor, final transmittance's bits) per pixel, written and read in
            // bands of rows where one binding cannot hold them all: refused only when no
            // band fits.
            let (w, h) = (f.width, f.height);
            let max = crate::gpu::limits::storage_binding_bytes(ctx.info());
            crate::render::frame::bands::pixel_bands(max, (w, h), (LAST_CONTRIBUTOR, 8))?;
            let bytes = (u64::from(w) * u64::from(h) * 8).max(8);
            f.last_contributor = Some(GpuBuffer::new(
                ctx,
                LAST_CONTRIBUTOR,
                bytes,
                MemoryKind::Device,
            )?);
        }
        Ok(())
    }

    /// Makes the packed RGBA8 buffer of the set's frame buffers.
    pub(crate) fn ensure_packed(&mut self, ctx: &GpuContext) -> GpuResult<()> {
        let f = self
            .frame
            .as_mut()
            .ok_or_else(|| GpuError::Internal("frame buffers missing".into()))?;
        if f.packed.is_none() {
            let bytes = u64::from(f.width) * u64::from(f.height) * 4;
            check_binding(ctx, "packed rgba8 frame", bytes)?;
            f.packed = Some(GpuBuffer::new(
                ctx,
                "packed rgba8 frame",
                bytes,
                MemoryKind::Device,
            )?);
        }
        Ok(())
    }
}

/// A set of `sets` with no frame in flight (made, for `bin_size`-pixel bins, when every set
/// made so far is busy).
pub(crate) fn free_set(
    sets: &mut Vec<FrameSet>,
    ctx: &GpuContext,
    bin_size: u32,
) -> GpuResult<usize> {
    if let Some(i) = sets.iter().position(|s| s.pending.is_none()) {
        return Ok(i);
    }
    if sets.len() >= MAX_FRAMES_IN_FLIGHT {
        return Err(GpuError::InvalidArgument(format!(
            "{MAX_FRAMES_IN_FLIGHT} frames are in flight already; finish one before submitting another"
        )));
    }
    let set = FrameSet::new(ctx, sets.len(), bin_size)?;
    sets.push(set);
    Ok(sets.len() - 1)
}
