//! Tile-ranges stage (`glsl/render/forward/ranges.comp`): start/end of each tile's run in the sorted keys,
//! dispatched indirectly over the device-side key count.

use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuResult};
use crate::render::shaders::bindings::ranges as slot;
use ash::vk;

/// Invocations per workgroup (matches `local_size_x`; the keys stage computes the
/// indirect group count with the same value).
pub const WORKGROUP: u32 = crate::gpu::shader_set::LINEAR_WG;

/// The tile-ranges pipeline.
pub struct Ranges {
    pipeline: ComputePipeline,
    texel_io: bool,
}

/// What the ranges stage binds.
#[derive(Clone, Copy)]
pub struct RangesBindings<'a> {
    /// The sorted keys: a buffer slice, or their texel view for the texel-I/O pipeline.
    pub sorted_keys: Resource<'a>,
    /// Out: each bin's range of the sorted pairs.
    pub ranges: BufferSlice<'a>,
    /// The frame's counters.
    pub counters: BufferSlice<'a>,
    /// The VkDispatchIndirectCommand the keys stage wrote.
    pub args: BufferSlice<'a>,
}

impl Ranges {
    /// Compiles the shader and builds the pipeline: reading the sorted keys from a
    /// storage buffer or (`texel_io`, for CPU devices) an R32_UINT texel view.
    pub fn new(ctx: &GpuContext, texel_io: bool) -> GpuResult<Self> {
        let keys = if texel_io {
            BindingKind::UniformTexelBuffer
        } else {
            BindingKind::StorageBuffer
        };
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "ranges",
            &[("RANGES_TEXEL_IO", u32::from(texel_io).to_string())],
            &by_binding([
                (slot::KEYS, keys),
                (slot::RANGES, BindingKind::StorageBuffer),
                (slot::COUNTERS, BindingKind::StorageBuffer),
            ])?,
            &crate::core::shader_interface::NO_PUSH_CONSTANTS,
        )?;
        Ok(Ranges { pipeline, texel_io })
    }

    /// Whether the pipeline reads the keys through a texel view.
    pub fn texel_io(&self) -> bool {
        self.texel_io
    }

    /// Records the indirect dispatch.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &RangesBindings,
    ) -> GpuResult<()> {
        let RangesBindings {
            sorted_keys,
            ranges,
            counters,
            args,
        } = *b;
        let resources = by_binding([
            (slot::KEYS, sorted_keys),
            (slot::RANGES, Resource::Buffer(ranges)),
            (slot::COUNTERS, Resource::Buffer(counters)),
        ])?;
        self.pipeline
            .dispatch_indirect_resources(ctx, cmd, &resources, &[], args)
    }
}
