//! Shade backward stage (`glsl/render/backward/shade_bwd.comp`, then `glsl/render/backward/mlp_grad_reduce.comp`): the
//! neural shader's ([`crate::fields::mlp`]) backward pass on the device. From dL/d(shaded colour)
//! and dL/d(alpha) per pixel it writes dL/d(feature channels) and the shader's part of
//! dL/d(alpha) per pixel, which the feature blend's backward then takes, and the
//! network's weight and bias gradients.
//!
//! Deterministic without atomics: a workgroup takes 64 consecutive pixels (a chunk); the
//! parameters' sums over a chunk are added, in chunk order, to one of
//! [`PARTIAL_SLOTS`] partial sums (slot = chunk mod slots, one dispatch per round of
//! chunks), and the reduce sums the slots in order. The rules are
//! [`crate::cpu::backward::backward_shaded`]'s.

use crate::core::camera::Camera;
use crate::core::shader_interface::ShadeBwdPush;
use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::shader_set::{SHADE_CHUNK_PIXELS, SHADE_SPEC_ACTIVATIONS, SHADE_SPEC_WIDEST};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{BufferSlice, ComputePipeline, GpuContext, GpuResult};
use crate::render::forward::shade::{GpuShader, ShadePush};
use crate::render::shaders::bindings::{mlp_grad_reduce as rslot, shade_bwd as slot};
use ash::vk;

/// Pixels per chunk: one per invocation of a workgroup.
pub const PIXELS: u32 = SHADE_CHUNK_PIXELS;
/// Partial sums of the parameters' gradients: the most workgroups of one dispatch. A
/// constant, so the order of the sums depends on the frame's size only, not the device.
pub const PARTIAL_SLOTS: u32 = 256;

const _: () = assert!(std::mem::size_of::<ShadeBwdPush>() == 128);

/// The buffers of one shade backward pass.
pub struct ShadeBwdBuffers<'a> {
    /// The forward's feature planes and the vec4s from one plane to the next.
    pub features: (BufferSlice<'a>, u32),
    /// The frame's colour image (vec4 per pixel, a copy): its alpha.
    pub alpha: BufferSlice<'a>,
    /// dL/d(shaded rgb), dL/d alpha per pixel (vec4): the alpha's gains the shader's part.
    pub grad_color: BufferSlice<'a>,
    /// Out: dL/d(feature channels) per pixel, groups of four (vec4).
    pub grad_features: BufferSlice<'a>,
    /// [`ShadeBwd::scratch_bytes`].
    pub scratch: BufferSlice<'a>,
    /// [`ShadeBwd::partial_bytes`].
    pub partials: BufferSlice<'a>,
    /// Out: the parameters' gradients (f32), in the layout of the shader's weight words.
    pub grads: BufferSlice<'a>,
}

/// The shade backward pipelines for networks of one size (their per-pixel arrays).
pub struct ShadeBwd {
    pipeline: ComputePipeline,
    reduce: ComputePipeline,
    size: (u32, u32),
}

fn chunks(pixels: u64) -> u64 {
    pixels.div_ceil(u64::from(PIXELS))
}

fn slots(pixels: u64) -> u64 {
    chunks(pixels).clamp(1, u64::from(PARTIAL_SLOTS))
}

/// Scratch vec4s of one workgroup: per pixel a row of a layer's inputs and a 1, and a
/// row of its outputs' gradients, each padded to whole vec4s (`XROW`, `GROW` in the shader).
fn per_workgroup(shader: &GpuShader) -> u64 {
    let w = u64::from(shader.widest);
    u64::from(PIXELS) * ((w + 1).div_ceil(4) + w.div_ceil(4))
}

impl ShadeBwd {
    /// The pipelines for `shader`'s size (`GpuShader::activations`, `widest`).
    pub fn for_shader(ctx: &GpuContext, shader: &GpuShader) -> GpuResult<Self> {
        Self::new(ctx, shader.activations, shader.widest)
    }

    /// Whether these pipelines are sized for `shader`.
    pub fn fits(&self, shader: &GpuShader) -> bool {
        self.size == (shader.activations, shader.widest)
    }

    /// Builds the pipelines for networks of `activations` values per pixel (every layer's
    /// inputs and the last one's outputs) and layers at most `widest` wide.
    pub fn new(ctx: &GpuContext, activations: u32, widest: u32) -> GpuResult<Self> {
        let storage = BindingKind::StorageBuffer;
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "shade_bwd",
            &[],
            &by_binding([
                (slot::WORDS, BindingKind::UniformTexelBuffer),
                (slot::FEATURES, storage),
                (slot::ALPHA, storage),
                (slot::GRAD_COLOR, storage),
                (slot::GRAD_FEATURES, storage),
                (slot::SCRATCH, storage),
                (slot::PARTIALS, storage),
            ])?,
            &ShadeBwdPush::LAYOUT,
            &[
                (SHADE_SPEC_ACTIVATIONS, activations.max(1)),
                (SHADE_SPEC_WIDEST, widest.max(1)),
            ],
        )?;
        let reduce = ComputePipeline::from_embedded(
            ctx,
            "mlp_grad_reduce",
            &[],
            &by_binding([(rslot::PARTIALS, storage), (rslot::GRADS, storage)])?,
            &crate::core::shader_interface::CountsPush::LAYOUT,
        )?;
        Ok(ShadeBwd {
            pipeline,
            reduce,
            size: (activations, widest),
        })
    }

    /// Bytes of scratch a frame of `pixels` needs: per workgroup of a dispatch, a layer's
    /// inputs and its outputs' gradients for each of its 64 pixels.
    pub fn scratch_bytes(shader: &GpuShader, pixels: u64) -> u64 {
        slots(pixels) * per_workgroup(shader) * 16
    }

    /// Bytes of the partial sums a frame of `pixels` needs.
    pub fn partial_bytes(shader: &GpuShader, pixels: u64) -> u64 {
        slots(pixels) * u64::from(shader.params) * 4
    }

    /// Records the pass over `cam`'s frame (one piece, `cam.width x cam.height`), whose
    /// colour was shaded with `background`. Clears the partial sums itself; the caller
    /// orders the inputs' writes before it and the outputs' reads after.
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        shader: &GpuShader,
        bufs: &ShadeBwdBuffers,
        cam: &Camera,
        background: [f32; 3],
    ) -> GpuResult<()> {
        let pixels = u64::from(cam.width) * u64::from(cam.height);
        let (chunks, slots) = (chunks(pixels), slots(pixels));
        if !self.fits(shader) {
            return Err(crate::gpu::GpuError::Internal(
                "the shade backward pipelines were built for another network size".into(),
            ));
        }
        let mut push = ShadeBwdPush {
            shade: ShadePush::new(shader, cam, bufs.features.1, background),
            shape: [per_workgroup(shader) as u32, 0, shader.params, 0],
        };
        bufs.partials
            .buffer
            .fill(ctx, cmd, bufs.partials.offset, bufs.partials.size, 0);
        barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
        let resources = by_binding([
            (slot::WORDS, Resource::TexelBuffer(shader.view.handle())),
            (slot::FEATURES, Resource::Buffer(bufs.features.0)),
            (slot::ALPHA, Resource::Buffer(bufs.alpha)),
            (slot::GRAD_COLOR, Resource::Buffer(bufs.grad_color)),
            (slot::GRAD_FEATURES, Resource::Buffer(bufs.grad_features)),
            (slot::SCRATCH, Resource::Buffer(bufs.scratch)),
            (slot::PARTIALS, Resource::Buffer(bufs.partials)),
        ])?;
        let mut first = 0;
        while first < chunks {
            push.shade.code[3] = first as u32;
            let groups = (chunks - first).min(slots) as u32;
            self.pipeline.dispatch_resources(
                ctx,
                cmd,
                &resources,
                bytemuck::bytes_of(&push),
                [groups, 1, 1],
            )?;
            // The next round adds to the same partial sums and reuses the scratch.
            barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
            first += slots;
        }
        self.reduce.dispatch(
            ctx,
            cmd,
            &[bufs.partials, bufs.grads],
            bytemuck::bytes_of(&crate::core::shader_interface::CountsPush {
                counts: [shader.params, slots as u32, 0, 0],
            }),
            [
                shader
                    .params
                    .div_ceil(crate::gpu::shader_set::MLP_REDUCE_WG),
                1,
                1,
            ],
        )
    }
}
