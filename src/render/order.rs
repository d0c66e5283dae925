//! Depth order stage: a stable radix sort of every Gaussian by view depth (culled ones
//! last; 32-bit keys, the Gaussian indices as values), then `glsl/order.comp` gathers the
//! tiles-touched counts into that order for the scan. Emitting pairs in depth order lets the pair sort order the tile bits only, with
//! the same result as sorting the full `tile << 32 | depth` keys (see `glsl/order.comp`).

use crate::gpu::shader::BindingKind;
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{
    dispatch_grid, BufferSlice, ComputePipeline, Count, GpuBuffer, GpuContext, GpuResult, RadixSort,
};
use ash::vk;

/// Invocations per workgroup of the gather (matches `local_size_x`).
pub const WORKGROUP: u32 = 256;

/// Depth bits sorted: the whole float (positive, so its bits order like the values).
pub const DEPTH_BITS: u32 = 32;

/// The gather pipeline of the depth order stage.
pub struct Order {
    pipeline: ComputePipeline,
}

impl Order {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "order",
            &[],
            &[BindingKind::StorageBuffer; 4],
            0,
            WORKGROUP,
        )?;
        Ok(Order { pipeline })
    }

    /// Records the depth sort of `n` Gaussians (`depth_keys`/`depth_values` hold the
    /// result afterwards; `sort` takes 32-bit keys) and the gather of their tiles-touched
    /// counts (`touched`, by Gaussian index) into `touched_in_order`. The caller places
    /// the barrier after (compute write -> read).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        sort: &RadixSort,
        params: BufferSlice,
        depth_keys: &GpuBuffer,
        depth_values: &GpuBuffer,
        scratch: &GpuBuffer,
        touched: BufferSlice,
        touched_in_order: BufferSlice,
        n: u32,
    ) -> GpuResult<()> {
        sort.record(
            ctx,
            cmd,
            depth_keys,
            depth_values,
            scratch,
            Count::Host(n),
            DEPTH_BITS,
        )?;
        // Sorted depth keys -> gather.
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        let groups = dispatch_grid(n.div_ceil(WORKGROUP), ctx.info().max_workgroup_count[0]);
        self.pipeline.dispatch(
            ctx,
            cmd,
            &[params, depth_values.whole(), touched, touched_in_order],
            &[],
            groups,
        )
    }
}
