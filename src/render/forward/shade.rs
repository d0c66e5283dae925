//! Shade stage (`glsl/render/forward/shade.comp`): the neural shader ([`crate::fields::mlp`]) over the blended
//! feature image, after the blend and the feature blend, writing the colour image.

use crate::core::camera::Camera;
pub(crate) use crate::core::shader_interface::ShadePush;
use crate::fields::mlp::Mlp;
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{
    BufferSlice, BufferView, ComputePipeline, GpuBuffer, GpuContext, GpuImage, GpuResult,
    MemoryKind,
};
use crate::render::shaders::bindings::shade as slot;
use ash::vk;

use crate::gpu::shader_set::{PIXEL_WG_X as SIDE, PIXEL_WG_Y as ROWS};

const _: () = assert!(std::mem::size_of::<ShadePush>() == 112);

impl ShadePush {
    /// The constants of `shader` over `cam`'s frame, whose feature planes are
    /// `plane_stride` vec4s apart, shaded over `background`.
    pub(crate) fn new(
        shader: &GpuShader,
        cam: &Camera,
        plane_stride: u32,
        background: [f32; 3],
    ) -> Self {
        let r = cam.rotation.transpose().to_cols_array_2d(); // rows of R
        ShadePush {
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
        }
    }
}

/// A neural shader on the device.
pub struct GpuShader {
    /// The words as an R32_UINT texel view: on CPU devices a loop-indexed storage-buffer
    /// load becomes a per-lane scalar loop, a texel fetch does not.
    pub(crate) view: BufferView,
    words: GpuBuffer,
    channels: usize,
    pub(crate) layers: u32,
    pub(crate) input_code: u32,
    /// Multiply-adds and loop iterations per pixel (for llvmpipe's loop limit).
    pub(crate) iterations: u64,
    /// Loop iterations of one `shade_bwd` invocation (for llvmpipe's loop limit).
    pub(crate) backward_iterations: u64,
    /// Weights and biases, all layers.
    pub(crate) params: u32,
    /// Values a pixel's evaluation keeps: every layer's inputs and the last one's outputs.
    pub(crate) activations: u32,
    /// The widest layer's inputs or outputs.
    pub(crate) widest: u32,
    /// The layers' (inputs, outputs), to check that an update keeps the shape.
    shape: Vec<(usize, usize)>,
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
        let params: usize = mlp.layers.iter().map(|l| (l.inputs + 1) * l.outputs).sum();
        let activations = mlp.layers.iter().map(|l| l.inputs).sum::<usize>()
            + mlp.layers.last().map_or(0, |l| l.outputs);
        let widest = mlp
            .layers
            .iter()
            .map(|l| l.inputs.max(l.outputs))
            .max()
            .unwrap_or(0);
        // shade_bwd: the forward, then per layer the activations' derivatives, the inputs'
        // gradients and the owned parameters' sums over a chunk's 64 pixels.
        let chunk = u64::from(crate::gpu::shader_set::SHADE_CHUNK_PIXELS);
        let backward_iterations = iterations
            + mlp
                .layers
                .iter()
                .map(|l| {
                    let (i, o) = (l.inputs as u64, l.outputs as u64);
                    o + i * (o + 1) + ((i + 1) * o).div_ceil(chunk) * (chunk + 1) + 2
                })
                .sum::<u64>()
            + mlp.feature_channels() as u64
            + 8;
        Ok(GpuShader {
            view,
            words: buf,
            channels: mlp.feature_channels(),
            layers: mlp.layers.len() as u32,
            input_code: mlp.input_code(),
            iterations,
            backward_iterations,
            params: params as u32,
            activations: activations as u32,
            widest: widest as u32,
            shape: mlp.layers.iter().map(|l| (l.inputs, l.outputs)).collect(),
        })
    }

    /// Uploads `mlp`'s weights in place of the current ones: a network of the same layers
    /// and inputs (a training step's update), else an error.
    pub fn update(&mut self, ctx: &GpuContext, mlp: &Mlp) -> GpuResult<()> {
        if !self.same_shape(mlp) {
            return Err(crate::gpu::GpuError::InvalidArgument(
                "the new weights are of another network (layers or inputs differ)".into(),
            ));
        }
        self.words.upload(ctx, &mlp.gpu_words())
    }

    /// Whether this shader holds a network of `mlp`'s shape and inputs.
    pub fn same_shape(&self, mlp: &Mlp) -> bool {
        self.input_code == mlp.input_code()
            && self.shape.len() == mlp.layers.len()
            && self
                .shape
                .iter()
                .zip(&mlp.layers)
                .all(|(&(i, o), l)| i == l.inputs && o == l.outputs)
    }

    /// Feature channels the shader takes.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The words (header, then the weights and biases as f32 bits) as a storage buffer,
    /// for a device pass that writes new weights ([`Self::WEIGHTS_OFFSET`] words in).
    pub fn words_buffer(&self) -> crate::gpu::BufferSlice<'_> {
        self.words.whole()
    }

    /// Words of the header before the weights ([`crate::fields::mlp::Mlp::gpu_words`]).
    pub const WEIGHTS_OFFSET: u32 = 4 * crate::fields::mlp::MAX_LAYERS as u32;

    /// Weights and biases, all layers.
    pub fn param_count(&self) -> u32 {
        self.params
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

/// What the shade stage binds (and the shader's words, which the shader holds).
#[derive(Clone, Copy)]
pub struct ShadeBindings<'a> {
    /// The feature planes.
    pub features: BufferSlice<'a>,
    /// vec4s from one plane to the next.
    pub plane_stride: u32,
    /// The frame's colour (GENERAL layout, written by the blend), shaded in place.
    pub color: &'a GpuImage,
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
            &ShadePush::LAYOUT,
        )?;
        Ok(Shade { pipeline })
    }

    /// Records the shading of the frame's colour by `shader`, from `cam` over
    /// `background`.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        shader: &GpuShader,
        b: &ShadeBindings,
        cam: &Camera,
        background: [f32; 3],
    ) -> GpuResult<()> {
        let ShadeBindings {
            features,
            plane_stride,
            color,
        } = *b;
        let push = ShadePush::new(shader, cam, plane_stride, background);
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
            [cam.width.div_ceil(SIDE), cam.height.div_ceil(ROWS), 1],
        )
    }
}
