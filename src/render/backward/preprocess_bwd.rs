//! Preprocess backward stage (`glsl/render/backward/preprocess_bwd.comp`): one invocation per Gaussian
//! turns its accumulated gradients of the projected quantities into gradients of its
//! centre, opacity, (normalised) quaternion, scales and SH coefficients.

use crate::gpu::shader::{by_binding, BindingKind, Resource};
use crate::gpu::{dispatch_grid, BufferSlice, ComputePipeline, GpuContext, GpuResult};
use crate::render::shaders::bindings::preprocess_bwd as slot;
use ash::vk;

use crate::render::backward::grad_accumulate::GradPush;

/// Bytes of one Gaussian's gradients in the output (`GaussianGrad`: four vec4).
pub const GAUSSIAN_GRAD_BYTES: u64 =
    std::mem::size_of::<crate::core::shader_interface::GaussianGrad>() as u64;

/// What the preprocess backward binds: the frame's parameters and the scene, the forward's
/// splats, the accumulated sums, and the Gaussians' gradients it writes.
#[derive(Clone, Copy)]
pub struct PreprocessBwdBindings<'a> {
    /// The frame's parameters.
    pub params: BufferSlice<'a>,
    /// The uploaded Gaussians.
    pub gaussians: BufferSlice<'a>,
    /// The SH coefficients' texel view.
    pub sh_texels: vk::BufferView,
    /// The forward's splats.
    pub splats: BufferSlice<'a>,
    /// Each field's largest magnitude (the fixed-point scale).
    pub maxima: BufferSlice<'a>,
    /// Each Gaussian's accumulated sums.
    pub acc: BufferSlice<'a>,
    /// Out: each Gaussian's gradients.
    pub grads: BufferSlice<'a>,
    /// Out: dL/d SH coefficient.
    pub sh_grads: BufferSlice<'a>,
    /// Out: dL/d feature channel.
    pub feature_grads: BufferSlice<'a>,
}

/// The preprocess-backward pipeline.
pub struct PreprocessBwd {
    pipeline: ComputePipeline,
    /// Invocations per workgroup ([`crate::gpu::workgroup::wide_linear_workgroup`]).
    workgroup: u32,
}

impl PreprocessBwd {
    /// Builds the pipeline; `float_sums` reads accumulators written with float atomics,
    /// `lenses` differentiates frames through a lens other than the pinhole (the unscented
    /// transform's sigma points; the pinhole's variant is the EWA rule alone).
    pub fn new(ctx: &GpuContext, float_sums: bool, lenses: bool) -> GpuResult<Self> {
        let storage = BindingKind::StorageBuffer;
        let workgroup = crate::gpu::workgroup::wide_linear_workgroup(ctx.info());
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "preprocess_bwd",
            &[
                ("FLOAT_ATOMICS", u32::from(float_sums).to_string()),
                ("LENSES", u32::from(lenses).to_string()),
            ],
            &by_binding([
                (slot::PARAMS, storage),
                (slot::GAUSSIANS, storage),
                (slot::SH, BindingKind::UniformTexelBuffer),
                (slot::SPLATS, storage),
                (slot::MAXIMA, storage),
                (slot::ACC, storage),
                (slot::GRADS, storage),
                (slot::SH_GRADS, storage),
                (slot::FEATURE_GRADS, storage),
            ])?,
            &GradPush::LAYOUT,
            &[(crate::gpu::shader_set::WIDE_WG_SPEC, workgroup)],
        )?;
        Ok(PreprocessBwd {
            pipeline,
            workgroup,
        })
    }

    /// Records the dispatch over `count` Gaussians (`push.count` holds the count).
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &PreprocessBwdBindings,
        push: GradPush,
    ) -> GpuResult<()> {
        if push.count == 0 {
            return Ok(());
        }
        let PreprocessBwdBindings {
            params,
            gaussians,
            sh_texels,
            splats,
            maxima,
            acc,
            grads,
            sh_grads,
            feature_grads,
        } = *b;
        let resources = by_binding([
            (slot::PARAMS, Resource::Buffer(params)),
            (slot::GAUSSIANS, Resource::Buffer(gaussians)),
            (slot::SH, Resource::TexelBuffer(sh_texels)),
            (slot::SPLATS, Resource::Buffer(splats)),
            (slot::MAXIMA, Resource::Buffer(maxima)),
            (slot::ACC, Resource::Buffer(acc)),
            (slot::GRADS, Resource::Buffer(grads)),
            (slot::SH_GRADS, Resource::Buffer(sh_grads)),
            (slot::FEATURE_GRADS, Resource::Buffer(feature_grads)),
        ])?;
        let groups = dispatch_grid(
            push.count.div_ceil(self.workgroup),
            ctx.info().max_workgroup_count[0],
        );
        self.pipeline
            .dispatch_resources(ctx, cmd, &resources, bytemuck::bytes_of(&push), groups)
    }
}
