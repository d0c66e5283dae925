//! Depth order stage: a stable radix sort of every Gaussian by view depth (culled ones
//! last; 32-bit keys, the Gaussian indices as values), then `glsl/render/forward/order.comp` gathers the
//! tiles-touched counts into that order for the scan. Emitting pairs in depth order lets the pair sort order the tile bits only, with
//! the same result as sorting the full `tile << 32 | depth` keys (see `glsl/render/forward/order.comp`).

use crate::gpu::shader::{by_binding, BindingKind};
use crate::gpu::sort::{SortJob, SortTexels};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{
    dispatch_grid, BufferSlice, ComputePipeline, Count, GpuBuffer, GpuContext, GpuResult, RadixSort,
};
use crate::render::shaders::bindings::order as slot;
use ash::vk;

/// Invocations per workgroup of the gather (matches `local_size_x`).
pub const WORKGROUP: u32 = crate::gpu::shader_set::LINEAR_WG;

/// Depth bits sorted: the whole float (positive, so its bits order like the values).
pub const DEPTH_BITS: u32 = 32;

/// Byte offset of `FrameParams::counts` (`x`: the Gaussian count) in the params buffer.
const COUNTS_OFFSET: u64 =
    std::mem::offset_of!(crate::render::forward::types::FrameParams, counts) as u64;

/// The gather pipeline of the depth order stage.
pub struct Order {
    pipeline: ComputePipeline,
}

/// What the order stage binds: the frame's parameters (the count), the depth sort's keys,
/// values and scratch (and its texel views), and the tiles-touched counts it gathers.
#[derive(Clone, Copy)]
pub struct OrderBindings<'a> {
    /// The frame's parameters: the Gaussian count the sort reads.
    pub params: &'a GpuBuffer,
    /// The depth keys, sorted in place.
    pub depth_keys: &'a GpuBuffer,
    /// The Gaussian indices, sorted with them (the depth order).
    pub depth_values: &'a GpuBuffer,
    /// The sort's scratch.
    pub scratch: &'a GpuBuffer,
    /// The sort's texel views, where it reads through them.
    pub texels: Option<&'a SortTexels>,
    /// Tiles touched, by Gaussian index.
    pub touched: BufferSlice<'a>,
    /// Out: tiles touched in depth order.
    pub touched_in_order: BufferSlice<'a>,
}

impl Order {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "order",
            &[],
            &by_binding([
                (slot::PARAMS, BindingKind::StorageBuffer),
                (slot::DEPTH_ORDER, BindingKind::StorageBuffer),
                (slot::TOUCHED, BindingKind::StorageBuffer),
                (slot::TOUCHED_IN_ORDER, BindingKind::StorageBuffer),
            ])?,
            &crate::core::shader_interface::NO_PUSH_CONSTANTS,
        )?;
        Ok(Order { pipeline })
    }

    /// Records the depth sort of the frame's `n` Gaussians (`depth_keys`/`depth_values`
    /// hold the result afterwards; `sort` takes 32-bit keys; the count is read from
    /// `params` on the device, so the scratch is laid out for the `max_n` the buffers hold,
    /// as `texels` are when the sort reads through texel views) and the gather of their
    /// tiles-touched counts (`touched`, by Gaussian index) into `touched_in_order`. The
    /// caller places the barrier after (compute write -> read).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        sort: &RadixSort,
        b: &OrderBindings,
        (n, max_n): (u32, u32),
    ) -> GpuResult<()> {
        let OrderBindings {
            params,
            depth_keys,
            depth_values,
            scratch,
            texels,
            touched,
            touched_in_order,
        } = *b;
        let count = Count::Device {
            buffer: params,
            offset: COUNTS_OFFSET,
            max_n,
        };
        let job = SortJob::new(depth_keys, depth_values, scratch, count, DEPTH_BITS).texels(texels);
        sort.record(ctx, cmd, &job)?;
        // Sorted depth keys -> gather.
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        let groups = dispatch_grid(n.div_ceil(WORKGROUP), ctx.info().max_workgroup_count[0]);
        self.pipeline.dispatch(
            ctx,
            cmd,
            &by_binding([
                (slot::PARAMS, params.whole()),
                (slot::DEPTH_ORDER, depth_values.whole()),
                (slot::TOUCHED, touched),
                (slot::TOUCHED_IN_ORDER, touched_in_order),
            ])?,
            &[],
            groups,
        )
    }
}
