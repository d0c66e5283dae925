//! Feature blend stage (`glsl/blend_features.comp`): after the colour blend, composites a
//! scene's K feature channels over the same sorted bin lists, four channels per dispatch
//! (one dispatch per group of four), with the colour rules and background 0.

use crate::cpu::SplatKernel;
use crate::gpu::shader::BindingKind;
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuResult};
use ash::vk;

/// Channels blended per dispatch (one vec4 per Gaussian and per pixel).
pub const CHANNELS_PER_GROUP: usize = 4;

/// Groups of [`CHANNELS_PER_GROUP`] channels that hold `k` channels.
pub fn groups(k: usize) -> usize {
    k.div_ceil(CHANNELS_PER_GROUP)
}

/// The feature blend pipeline for one alpha falloff (compiled in as `SPLAT_KERNEL`).
pub struct FeatureBlend {
    pipeline: ComputePipeline,
}

/// Resources one group's dispatch reads and writes.
pub struct FeatureBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// Splats (preprocess output).
    pub splats: BufferSlice<'a>,
    /// Sorted values (Gaussian indices).
    pub values: BufferSlice<'a>,
    /// Bin ranges.
    pub ranges: BufferSlice<'a>,
    /// The group's four channels per Gaussian (vec4).
    pub features: BufferSlice<'a>,
    /// The group's four channels per pixel (vec4, row-major; written).
    pub output: BufferSlice<'a>,
    /// Counters (loop lengths reported).
    pub counters: BufferSlice<'a>,
}

impl FeatureBlend {
    /// Compiles the shader with the falloff of `kernel`.
    pub fn new(ctx: &GpuContext, kernel: SplatKernel) -> GpuResult<Self> {
        let defines = [("SPLAT_KERNEL", format!("{}u", kernel.shader_id()))];
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "blend_features",
            &defines,
            &[BindingKind::StorageBuffer; 7],
            0,
            16,
        )?;
        Ok(FeatureBlend { pipeline })
    }

    /// Records one group's dispatch: one 16x16 workgroup per 16x16 pixel block.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &FeatureBindings,
        size: (u32, u32),
    ) -> GpuResult<()> {
        self.pipeline.dispatch(
            ctx,
            cmd,
            &[
                b.params, b.splats, b.values, b.ranges, b.features, b.output, b.counters,
            ],
            &[],
            [size.0.div_ceil(16), size.1.div_ceil(16), 1],
        )
    }
}
