//! Feature blend stage (`glsl/render/forward/blend_features.comp`): after the colour blend, composites a
//! scene's K feature channels over the same sorted bin lists, four channels per dispatch
//! (one dispatch per group of four), with the colour rules and background 0.

use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuError, GpuImage, GpuResult};
use crate::render::forward::blend::Falloff;
use crate::render::shaders::bindings::blend_features as slot;
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
    texel: bool,
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
    /// Texel views of `splats` (R32G32B32A32_SFLOAT), `values` (R32_UINT) and `features`
    /// (R32G32B32A32_SFLOAT), for the texel-fetch variant.
    pub texels: Option<[vk::BufferView; 3]>,
    /// The colour image: between chunks it holds each pixel's transmittance and stop.
    pub color: &'a GpuImage,
    /// Resume every pixel from the output and the colour image's between-chunk state
    /// (every chunk of a frame in chunks but the first), instead of starting afresh.
    pub resume: bool,
}

impl FeatureBlend {
    /// Compiles the shader with the falloff of `kernel`; `texel` reads the splats, values
    /// and features through texel-buffer views (for CPU devices, as the texel blend);
    /// `surface` blends the surface pass's facing normals and median depth
    /// ([`crate::core::model::surface`]) instead of the channels as they are.
    pub fn new(ctx: &GpuContext, falloff: Falloff, texel: bool, surface: bool) -> GpuResult<Self> {
        use BindingKind::{StorageBuffer as B, StorageImage as I, UniformTexelBuffer as T};
        let defines = [
            ("SPLAT_KERNEL", format!("{}u", falloff.kernel.shader_id())),
            ("TEXEL_FETCH", u32::from(texel).to_string()),
            ("SURFACE", u32::from(surface).to_string()),
        ];
        let read = if texel { T } else { B };
        let bindings = by_binding([
            (slot::PARAMS, B),
            (slot::SPLATS, read),
            (slot::VALUES, read),
            (slot::RANGES, B),
            (slot::FEATURES, read),
            (slot::OUTPUT, B),
            (slot::COUNTERS, B),
            (slot::COLOR_STATE, I),
        ])?;
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "blend_features",
            &defines,
            &bindings,
            &crate::render::forward::types::FeatureBlendPush::LAYOUT,
            &falloff.specialization(),
        )?;
        Ok(FeatureBlend { pipeline, texel })
    }

    /// Whether the pipeline reads texel-buffer views.
    pub fn texel(&self) -> bool {
        self.texel
    }

    /// Records one group's dispatch: one 16x8 workgroup per 16x8 pixel block.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &FeatureBindings,
        size: (u32, u32),
    ) -> GpuResult<()> {
        let (splats, values, features) =
            match (self.texel, b.texels) {
                (false, _) => (
                    Resource::Buffer(b.splats),
                    Resource::Buffer(b.values),
                    Resource::Buffer(b.features),
                ),
                (true, Some([s, v, f])) => (
                    Resource::TexelBuffer(s),
                    Resource::TexelBuffer(v),
                    Resource::TexelBuffer(f),
                ),
                (true, None) => return Err(GpuError::Internal(
                    "the texel feature blend needs texel views of the splats, values and features"
                        .into(),
                )),
            };
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &by_binding([
                (slot::PARAMS, Resource::Buffer(b.params)),
                (slot::SPLATS, splats),
                (slot::VALUES, values),
                (slot::RANGES, Resource::Buffer(b.ranges)),
                (slot::FEATURES, features),
                (slot::OUTPUT, Resource::Buffer(b.output)),
                (slot::COUNTERS, Resource::Buffer(b.counters)),
                (
                    slot::COLOR_STATE,
                    Resource::Image {
                        view: b.color.view(),
                        layout: vk::ImageLayout::GENERAL,
                    },
                ),
            ])?,
            bytemuck::bytes_of(&crate::render::forward::types::FeatureBlendPush {
                resume: u32::from(b.resume),
                pad: 0,
            }),
            [
                size.0.div_ceil(crate::gpu::shader_set::PIXEL_WG_X),
                size.1.div_ceil(crate::gpu::shader_set::PIXEL_WG_Y),
                1,
            ],
        )
    }
}
