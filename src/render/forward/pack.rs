//! Pack stage (`glsl/render/forward/pack.comp`): the colour image as 8-bit RGBA on the device, quantised
//! as [`crate::io::output::to_u8`], so a consumer that only shows the frame reads back a
//! quarter of the colour plane's bytes and no alpha or depth.

use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuImage, GpuResult};
use crate::render::shaders::bindings::pack as slot;
use ash::vk;

use crate::gpu::shader_set::{PIXEL_WG_X as SIDE, PIXEL_WG_Y as ROWS};

/// The pack pipeline.
pub struct Pack {
    pipeline: ComputePipeline,
}

/// What the pack stage binds.
#[derive(Clone, Copy)]
pub struct PackBindings<'a> {
    /// The frame's colour (GENERAL layout, written by the blend).
    pub color: &'a GpuImage,
    /// Out: `width * height` u32, row-major, top row first.
    pub packed: BufferSlice<'a>,
}

impl Pack {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "pack",
            &[],
            &by_binding([
                (slot::COLOR, BindingKind::StorageImage),
                (slot::PACKED, BindingKind::StorageBuffer),
            ])?,
            &crate::render::forward::types::PackPush::LAYOUT,
        )?;
        Ok(Pack { pipeline })
    }

    /// Records the packing of the frame's colour into 8-bit RGBA, `(width, height)` its
    /// size.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &PackBindings,
        (width, height): (u32, u32),
    ) -> GpuResult<()> {
        let PackBindings { color, packed } = *b;
        let push = crate::render::forward::types::PackPush { width, height };
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &by_binding([
                (
                    slot::COLOR,
                    Resource::Image {
                        view: color.view(),
                        layout: vk::ImageLayout::GENERAL,
                    },
                ),
                (slot::PACKED, Resource::Buffer(packed)),
            ])?,
            bytemuck::bytes_of(&push),
            [width.div_ceil(SIDE), height.div_ceil(ROWS), 1],
        )
    }
}
