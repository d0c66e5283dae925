//! Blend stage (`glsl/blend.comp`): one 16x16 workgroup per tile, writing colour+alpha and
//! depth storage images.

use crate::gpu::shader::{BindingKind, Resource};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuImage, GpuResult};
use ash::vk;

/// The blend pipeline.
pub struct Blend {
    pipeline: ComputePipeline,
    strip: u32,
}

/// Pixels per invocation the blend uses on a device: 1 on GPUs (shared-memory batches,
/// one pixel per thread); 8 on CPU implementations such as lavapipe, whose memory loads
/// are per-lane scalar loops, so one load should serve several pixels.
/// `VKSPLAT_BLEND_STRIP` (1, 2, 4, 8 or 16) overrides.
pub fn default_strip(ctx: &GpuContext) -> u32 {
    if let Some(s) = std::env::var("VKSPLAT_BLEND_STRIP")
        .ok()
        .and_then(|v| v.parse::<u32>().ok())
        .filter(|s| STRIPS.contains(s))
    {
        return s;
    }
    if ctx.info().device_type == vk::PhysicalDeviceType::CPU {
        8
    } else {
        1
    }
}

/// Supported pixels-per-invocation values.
pub const STRIPS: [u32; 5] = [1, 2, 4, 8, 16];

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
    /// Compiles the shader with `strip` pixels per invocation (one of [`STRIPS`]).
    pub fn new(ctx: &GpuContext, strip: u32) -> GpuResult<Self> {
        use BindingKind::{StorageBuffer as B, StorageImage as I};
        if !STRIPS.contains(&strip) {
            return Err(crate::gpu::GpuError::InvalidArgument(format!(
                "blend strip {strip} is not one of {STRIPS:?}"
            )));
        }
        let defines = [("STRIP", strip.to_string())];
        // local_size_x (the full-subgroups requirement looks at the X dimension).
        let invocations = 16 / strip;
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "blend",
            &defines,
            &[B, B, B, B, I, I],
            0,
            invocations,
        )?;
        Ok(Blend { pipeline, strip })
    }

    /// Pixels per invocation.
    pub fn strip(&self) -> u32 {
        self.strip
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
                Resource::Image {
                    view: b.color.view(),
                    layout: vk::ImageLayout::GENERAL,
                },
                Resource::Image {
                    view: b.depth.view(),
                    layout: vk::ImageLayout::GENERAL,
                },
            ],
            &[],
            [tiles.0, tiles.1, 1],
        )
    }
}
