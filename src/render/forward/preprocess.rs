//! Preprocess stage (`glsl/render/forward/preprocess.comp`): one thread per Gaussian, dispatched once per
//! window of Gaussians whose per-Gaussian arrays fit one storage binding each.

use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{dispatch_grid, BufferSlice, ComputePipeline, GpuContext, GpuResult};
use ash::vk;

/// Invocations per workgroup (matches `local_size_x`).
pub const WORKGROUP: u32 = crate::gpu::shader_set::LINEAR_WG;

/// The preprocess pipeline.
pub struct Preprocess {
    pipeline: ComputePipeline,
    /// Bytes per Gaussian record: 48 (`GpuGaussian`) or 32 (`GpuGaussianCompact`).
    record_bytes: u64,
    texel_io: bool,
}

/// Texel views of the texel-I/O variant (CPU devices), each over a whole buffer and
/// indexed by the global Gaussian index: the records (RGBA32UI), the splats (RGBA32F),
/// the rectangles (RG32UI) and the rest (R32UI).
#[derive(Clone, Copy)]
pub struct PreprocessTexels {
    /// The Gaussian records.
    pub gaussians: vk::BufferView,
    /// The splats (written).
    pub splats: vk::BufferView,
    /// The tile rectangles (written).
    pub rects: vk::BufferView,
    /// The depth keys (written).
    pub depth_keys: vk::BufferView,
    /// The depth sort's values (written).
    pub depth_values: vk::BufferView,
    /// The bin masks (written).
    pub bin_masks: vk::BufferView,
    /// Tiles touched (written).
    pub touched: vk::BufferView,
}

/// Buffers the stage reads and writes.
pub struct PreprocessBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// GpuGaussian (or GpuGaussianCompact, for the compact pipeline) per Gaussian.
    pub gaussians: BufferSlice<'a>,
    /// SH coefficients: an RGBA32F texel view, `sh_texel_stride` texels per Gaussian.
    pub sh_texels: vk::BufferView,
    /// Splat per Gaussian (written).
    pub splats: BufferSlice<'a>,
    /// Packed tile rectangle per Gaussian (written).
    pub rects: BufferSlice<'a>,
    /// Depth sort key (depth bits, or !0 when culled) per Gaussian (written).
    pub depth_keys: BufferSlice<'a>,
    /// Counters (atomically updated).
    pub counters: BufferSlice<'a>,
    /// Gaussian index per Gaussian, the depth sort's values (written).
    pub depth_values: BufferSlice<'a>,
    /// Receiving bins of small tile rectangles, one bit per bin, by global Gaussian
    /// index (written; bound whole).
    pub bin_masks: BufferSlice<'a>,
    /// Tiles touched, by global Gaussian index (written; bound whole).
    pub touched: BufferSlice<'a>,
    /// The views the texel-I/O variant binds instead of the buffers above.
    pub texels: Option<PreprocessTexels>,
}

impl Preprocess {
    /// Compiles the shader and builds the pipeline, for 48-byte records or (`compact`)
    /// 32-byte ones, reading and writing storage buffers or (`texel_io`, for CPU devices)
    /// texel views, for pinhole cameras or (`lenses`) every lens.
    pub fn new(ctx: &GpuContext, compact: bool, texel_io: bool, lenses: bool) -> GpuResult<Self> {
        use crate::render::shaders::bindings::preprocess as b;
        use BindingKind::*;
        let (read, write) = if texel_io {
            (UniformTexelBuffer, StorageTexelBuffer)
        } else {
            (StorageBuffer, StorageBuffer)
        };
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "preprocess",
            &[
                ("COMPACT_GAUSSIANS", u32::from(compact).to_string()),
                ("PREPROCESS_TEXEL_IO", u32::from(texel_io).to_string()),
                ("LENSES", u32::from(lenses).to_string()),
            ],
            &by_binding([
                (b::PARAMS, StorageBuffer),
                (b::GAUSSIANS, read),
                (b::SH, UniformTexelBuffer),
                (b::SPLATS, write),
                (b::RECTS, write),
                (b::DEPTH_KEYS, write),
                (b::COUNTERS, StorageBuffer),
                (b::DEPTH_VALUES, write),
                (b::BIN_MASKS, write),
                (b::TOUCHED, write),
            ])?,
            &crate::render::forward::types::WindowPush::LAYOUT,
        )?;
        Ok(Preprocess {
            pipeline,
            record_bytes: if compact { 32 } else { 48 },
            texel_io,
        })
    }

    /// Whether the pipeline reads and writes texel views.
    pub fn texel_io(&self) -> bool {
        self.texel_io
    }

    /// Records the dispatches for `n` Gaussians, `window` (a multiple of [`WORKGROUP`]) at
    /// a time: each binds the window's slices of the per-Gaussian buffers (the whole
    /// buffers when one window holds every Gaussian).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &PreprocessBindings,
        n: u32,
        window: u32,
    ) -> GpuResult<()> {
        use crate::render::shaders::bindings::preprocess as slot;
        let window = window.max(WORKGROUP) / WORKGROUP * WORKGROUP;
        let mut first = 0u32;
        while first < n {
            let count = window.min(n - first);
            if first > 0 {
                // The previous window's counter atomics -> this window's.
                barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
            }
            let whole = count == n;
            let part = |s, stride| window_slice(s, whole, first, count, stride);
            let groups =
                dispatch_grid(count.div_ceil(WORKGROUP), ctx.info().max_workgroup_count[0]);
            let push = crate::render::forward::types::WindowPush { first, count };
            let resources = match (self.texel_io, b.texels) {
                (true, Some(t)) => by_binding([
                    (slot::PARAMS, Resource::Buffer(b.params)),
                    (slot::GAUSSIANS, Resource::TexelBuffer(t.gaussians)),
                    (slot::SH, Resource::TexelBuffer(b.sh_texels)),
                    (slot::SPLATS, Resource::TexelBuffer(t.splats)),
                    (slot::RECTS, Resource::TexelBuffer(t.rects)),
                    (slot::DEPTH_KEYS, Resource::TexelBuffer(t.depth_keys)),
                    (slot::COUNTERS, Resource::Buffer(b.counters)),
                    (slot::DEPTH_VALUES, Resource::TexelBuffer(t.depth_values)),
                    (slot::BIN_MASKS, Resource::TexelBuffer(t.bin_masks)),
                    (slot::TOUCHED, Resource::TexelBuffer(t.touched)),
                ])?,
                (false, _) => by_binding([
                    (slot::PARAMS, Resource::Buffer(b.params)),
                    (
                        slot::GAUSSIANS,
                        Resource::Buffer(part(b.gaussians, self.record_bytes)),
                    ),
                    (slot::SH, Resource::TexelBuffer(b.sh_texels)),
                    (slot::SPLATS, Resource::Buffer(part(b.splats, 48))),
                    (slot::RECTS, Resource::Buffer(part(b.rects, 8))),
                    (slot::DEPTH_KEYS, Resource::Buffer(part(b.depth_keys, 4))),
                    (slot::COUNTERS, Resource::Buffer(b.counters)),
                    (
                        slot::DEPTH_VALUES,
                        Resource::Buffer(part(b.depth_values, 4)),
                    ),
                    (slot::BIN_MASKS, Resource::Buffer(b.bin_masks)),
                    (slot::TOUCHED, Resource::Buffer(b.touched)),
                ])?,
                (true, None) => {
                    return Err(crate::gpu::GpuError::Internal(
                        "the preprocess stage's texel views are missing".into(),
                    ))
                }
            };
            self.pipeline.dispatch_resources(
                ctx,
                cmd,
                &resources,
                bytemuck::bytes_of(&push),
                groups,
            )?;
            first += count;
        }
        Ok(())
    }
}

/// Gaussians `first..first + count` of a per-Gaussian buffer of `stride` bytes each (the
/// buffer as given when the window is `whole`).
fn window_slice(s: BufferSlice, whole: bool, first: u32, count: u32, stride: u64) -> BufferSlice {
    if whole {
        return s;
    }
    BufferSlice {
        buffer: s.buffer,
        offset: s.offset + u64::from(first) * stride,
        size: u64::from(count) * stride,
    }
}
