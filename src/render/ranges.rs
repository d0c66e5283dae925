//! Tile-ranges stage (`glsl/ranges.comp`): start/end of each tile's run in the sorted keys,
//! dispatched indirectly over the device-side key count.

use crate::gpu::shader::BindingKind;
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuResult};
use ash::vk;

/// Invocations per workgroup (matches `local_size_x`; the keys stage computes the
/// indirect group count with the same value).
pub const WORKGROUP: u32 = 256;

/// The tile-ranges pipeline.
pub struct Ranges {
    pipeline: ComputePipeline,
}

impl Ranges {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "ranges",
            &[],
            &[BindingKind::StorageBuffer; 3],
            0,
            WORKGROUP,
        )?;
        Ok(Ranges { pipeline })
    }

    /// Records the indirect dispatch; `args` holds the VkDispatchIndirectCommand.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        sorted_keys: BufferSlice,
        ranges: BufferSlice,
        counters: BufferSlice,
        args: BufferSlice,
    ) -> GpuResult<()> {
        self.pipeline
            .dispatch_indirect(ctx, cmd, &[sorted_keys, ranges, counters], &[], args)
    }
}
