//! Blend stage (`glsl/blend.comp`): one 16x16 workgroup per tile, writing colour+alpha and
//! depth storage images.

use crate::gpu::shader::{BindingKind, Resource};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuImage, GpuResult};
use ash::vk;

/// The blend pipeline.
pub struct Blend {
    pipeline: ComputePipeline,
}

/// Resources the stage reads and writes.
pub struct BlendBindings<'a> {
    /// FrameParams.
    pub params: BufferSlice<'a>,
    /// Splats.
    pub splats: BufferSlice<'a>,
    /// Sorted values (Gaussian indices).
    pub values: BufferSlice<'a>,
    /// Tile ranges.
    pub ranges: BufferSlice<'a>,
    /// rgba32f colour + alpha image (written, GENERAL layout).
    pub color: &'a GpuImage,
    /// r32f depth image (written, GENERAL layout).
    pub depth: &'a GpuImage,
}

impl Blend {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        use BindingKind::{StorageBuffer as B, StorageImage as I};
        let pipeline =
            ComputePipeline::from_embedded(ctx, "blend", &[], &[B, B, B, B, I, I], 0, 256)?;
        Ok(Blend { pipeline })
    }

    /// Records one workgroup per tile (the tile grid is at most 1024x1024).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &BlendBindings,
        tiles: (u32, u32),
    ) -> GpuResult<()> {
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &[
                Resource::Buffer(b.params),
                Resource::Buffer(b.splats),
                Resource::Buffer(b.values),
                Resource::Buffer(b.ranges),
                Resource::Image(b.color),
                Resource::Image(b.depth),
            ],
            &[],
            [tiles.0, tiles.1, 1],
        )
    }
}
