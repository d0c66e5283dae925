//! Duplicate-per-tile keys stage (`glsl/keys.comp`): one thread per Gaussian, in depth
//! order, writes its (tile | depth, index) pairs at its scanned offset.

use crate::gpu::shader::BindingKind;
use crate::gpu::{dispatch_grid, BufferSlice, ComputePipeline, GpuContext, GpuResult};
use ash::vk;

/// Invocations per workgroup (matches `local_size_x`).
pub const WORKGROUP: u32 = 256;

/// The key-duplication pipeline.
pub struct Keys {
    pipeline: ComputePipeline,
}

/// Buffers the stage reads and writes.
pub struct KeysBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// Splats (depth).
    pub splats: BufferSlice<'a>,
    /// Packed tile rectangles.
    pub rects: BufferSlice<'a>,
    /// Exclusive prefix sum of tiles touched, in depth order.
    pub offsets: BufferSlice<'a>,
    /// Keys, `uvec2(depth bits, tile id)` (written).
    pub keys: BufferSlice<'a>,
    /// Values, Gaussian indices (written).
    pub values: BufferSlice<'a>,
    /// Counters (sort count and ranges dispatch written).
    pub counters: BufferSlice<'a>,
    /// Gaussian indices in depth order.
    pub depth_order: BufferSlice<'a>,
    /// Receiving bins of small tile rectangles, from preprocess.
    pub bin_masks: BufferSlice<'a>,
}

impl Keys {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "keys",
            &[],
            &[BindingKind::StorageBuffer; 9],
            0,
            WORKGROUP,
        )?;
        Ok(Keys { pipeline })
    }

    /// Records the dispatch for `n` Gaussians (at least one workgroup, so the counters
    /// are always written).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &KeysBindings,
        n: u32,
    ) -> GpuResult<()> {
        let groups = dispatch_grid(
            n.div_ceil(WORKGROUP).max(1),
            ctx.info().max_workgroup_count[0],
        );
        self.pipeline.dispatch(
            ctx,
            cmd,
            &[
                b.params,
                b.splats,
                b.rects,
                b.offsets,
                b.keys,
                b.values,
                b.counters,
                b.depth_order,
                b.bin_masks,
            ],
            &[],
            groups,
        )
    }
}
