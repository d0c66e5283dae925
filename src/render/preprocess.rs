//! Preprocess stage (`glsl/preprocess.comp`): one thread per Gaussian.

use crate::gpu::shader::BindingKind;
use crate::gpu::{dispatch_grid, BufferSlice, ComputePipeline, GpuContext, GpuResult};
use ash::vk;

/// Invocations per workgroup (matches `local_size_x`).
pub const WORKGROUP: u32 = 256;

/// The preprocess pipeline.
pub struct Preprocess {
    pipeline: ComputePipeline,
}

/// Buffers the stage reads and writes.
pub struct PreprocessBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// GpuGaussian per Gaussian.
    pub gaussians: BufferSlice<'a>,
    /// SH coefficients.
    pub sh: BufferSlice<'a>,
    /// Splat per Gaussian (written).
    pub splats: BufferSlice<'a>,
    /// Packed tile rectangle per Gaussian (written).
    pub rects: BufferSlice<'a>,
    /// Depth sort key `(depth bits or !0 when culled, tiles touched)` per Gaussian (written).
    pub depth_keys: BufferSlice<'a>,
    /// Counters (atomically updated).
    pub counters: BufferSlice<'a>,
    /// Gaussian index per Gaussian, the depth sort's values (written).
    pub depth_values: BufferSlice<'a>,
}

impl Preprocess {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "preprocess",
            &[],
            &[BindingKind::StorageBuffer; 8],
            0,
            WORKGROUP,
        )?;
        Ok(Preprocess { pipeline })
    }

    /// Records the dispatch for `n` Gaussians.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &PreprocessBindings,
        n: u32,
    ) -> GpuResult<()> {
        let groups = dispatch_grid(n.div_ceil(WORKGROUP), ctx.info().max_workgroup_count[0]);
        self.pipeline.dispatch(
            ctx,
            cmd,
            &[
                b.params,
                b.gaussians,
                b.sh,
                b.splats,
                b.rects,
                b.depth_keys,
                b.counters,
                b.depth_values,
            ],
            &[],
            groups,
        )
    }
}
