//! Shade stage (`glsl/shade.comp`): the neural shader ([`crate::mlp`]) over the blended
//! feature image, after the blend and the feature blend, writing the colour image.

use crate::camera::Camera;
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::shader_set::bindings::shade as slot;
use crate::gpu::{
    BufferSlice, BufferView, ComputePipeline, GpuBuffer, GpuContext, GpuImage, GpuResult,
    MemoryKind,
};
use crate::mlp::Mlp;
use ash::vk;

/// Workgroup side (16 x 16 invocations).
const SIDE: u32 = 16;

/// The push constants of `glsl/shade.comp`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ShadePush {
    size: [u32; 4],
    code: [u32; 4],
    intrinsics: [f32; 4],
    rot: [[f32; 4]; 3],
    background: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<ShadePush>() == 112);

/// A neural shader on the device.
pub struct GpuShader {
    /// The words as an R32_UINT texel view: on CPU devices a loop-indexed storage-buffer
    /// load becomes a per-lane scalar loop, a texel fetch does not.
    view: BufferView,
    words: GpuBuffer,
    channels: usize,
    layers: u32,
    input_code: u32,
    /// Multiply-adds and loop iterations per pixel (for llvmpipe's loop limit).
    pub(crate) iterations: u64,
}

impl GpuShader {
    /// Uploads `mlp`.
    pub fn new(ctx: &GpuContext, mlp: &Mlp) -> GpuResult<Self> {
        let words = mlp.gpu_words();
        let max = u64::from(ctx.info().max_texel_buffer_elements);
        if words.len() as u64 > max {
            return Err(crate::gpu::GpuError::Input(format!(
                "the neural shader's {} weights exceed the {max} texels this device reads from one texel buffer (maxTexelBufferElements); use a smaller network",
                words.len()
            )));
        }
        let buf = GpuBuffer::new(
            ctx,
            "neural shader weights",
            (words.len() * 4) as u64,
            MemoryKind::Device,
        )?;
        buf.upload(ctx, &words)?;
        let view = BufferView::new(ctx, &buf, vk::Format::R32_UINT, 0, buf.size())?;
        let iterations = mlp
            .layers
            .iter()
            .map(|l| (l.inputs as u64 + 1) * l.outputs as u64 + 1)
            .sum::<u64>()
            + (mlp.feature_channels() + mlp.extra_inputs()) as u64;
        Ok(GpuShader {
            view,
            words: buf,
            channels: mlp.feature_channels(),
            layers: mlp.layers.len() as u32,
            input_code: mlp.input_code(),
            iterations,
        })
    }

    /// Feature channels the shader takes.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Device bytes of the weights.
    pub fn device_bytes(&self) -> u64 {
        self.words.size()
    }
}

/// The shade pipeline.
pub struct Shade {
    pipeline: ComputePipeline,
}

impl Shade {
    /// Compiles the shader and builds the pipeline.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "shade",
            &[],
            &by_binding([
                (slot::WORDS, BindingKind::UniformTexelBuffer),
                (slot::FEATURES, BindingKind::StorageBuffer),
                (slot::COLOR, BindingKind::StorageImage),
            ])?,
            std::mem::size_of::<ShadePush>() as u32,
            SIDE,
        )?;
        Ok(Shade { pipeline })
    }

    /// Records the shading of `color` (GENERAL layout, written by the blend) from the
    /// feature planes `features` (`plane_stride` vec4s apart).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        shader: &GpuShader,
        features: BufferSlice,
        plane_stride: u32,
        color: &GpuImage,
        cam: &Camera,
        background: [f32; 3],
    ) -> GpuResult<()> {
        let r = cam.rotation.transpose().to_cols_array_2d(); // rows of R
        let push = ShadePush {
            size: [
                cam.width,
                cam.height,
                shader.channels as u32,
                shader.channels.div_ceil(4) as u32,
            ],
            code: [shader.input_code, shader.layers, plane_stride, 0],
            intrinsics: [cam.fx, cam.fy, cam.cx, cam.cy],
            rot: [
                [r[0][0], r[0][1], r[0][2], 0.0],
                [r[1][0], r[1][1], r[1][2], 0.0],
                [r[2][0], r[2][1], r[2][2], 0.0],
            ],
            background: [background[0], background[1], background[2], 0.0],
        };
        self.pipeline.dispatch_resources(
            ctx,
            cmd,
            &by_binding([
                (slot::WORDS, Resource::TexelBuffer(shader.view.handle())),
                (slot::FEATURES, Resource::Buffer(features)),
                (
                    slot::COLOR,
                    Resource::Image {
                        view: color.view(),
                        layout: vk::ImageLayout::GENERAL,
                    },
                ),
            ])?,
            bytemuck::bytes_of(&push),
            [cam.width.div_ceil(SIDE), cam.height.div_ceil(SIDE), 1],
        )
    }
}
