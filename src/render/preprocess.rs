//! Preprocess stage (`glsl/preprocess.comp`): one thread per Gaussian.

use crate::gpu::shader::{BindingKind, Resource};
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
    /// SH coefficients: an RGBA32F texel view, `sh_texel_stride` texels per Gaussian.
    pub sh_texels: vk::BufferView,
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
    /// Receiving bins of small tile rectangles, one bit per bin (written).
    pub bin_masks: BufferSlice<'a>,
}

impl Preprocess {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "preprocess",
            &[],
            &[
                BindingKind::StorageBuffer,
                BindingKind::StorageBuffer,
                BindingKind::UniformTexelBuffer,
                BindingKind::StorageBuffer,
                BindingKind::StorageBuffer,
                BindingKind::StorageBuffer,
                BindingKind::StorageBuffer,
                BindingKind::StorageBuffer,
                BindingKind::StorageBuffer,
            ],
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
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &[
                Resource::Buffer(b.params),
                Resource::Buffer(b.gaussians),
                Resource::TexelBuffer(b.sh_texels),
                Resource::Buffer(b.splats),
                Resource::Buffer(b.rects),
                Resource::Buffer(b.depth_keys),
                Resource::Buffer(b.counters),
                Resource::Buffer(b.depth_values),
                Resource::Buffer(b.bin_masks),
            ],
            &[],
            groups,
        )
    }
}
