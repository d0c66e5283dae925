//! Gradient accumulation stage (`glsl/render/backward/grad_accumulate.comp`): one invocation per sorted
//! pair adds the pair's partial sums to its Gaussian's accumulators, in 64-bit fixed
//! point (deterministic, the default: `glsl/render/backward/grad_common.glsl` states range and resolution;
//! one 64-bit atomic per value where the device has them, else two 32-bit halves)
//! or with float atomics (the opt-in fast mode; by compare-and-swap where the device has no
//! float atomic add).

pub use crate::core::shader_interface::GradPush;
use crate::gpu::shader::{by_binding, BindingKind};
use crate::gpu::{dispatch_grid, BufferSlice, ComputePipeline, GpuContext, GpuResult};
use crate::render::shaders::bindings::grad_accumulate as slot;
use ash::vk;

/// How per-pair gradients are added into per-Gaussian sums.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Accumulation {
    /// 64-bit fixed-point integer atomics: bit-identical gradients run after run.
    #[default]
    Deterministic,
    /// Float atomic adds (`VK_EXT_shader_atomic_float` where the device has it): the
    /// order of additions, and so the last bits of the result, vary from run to run.
    FloatAtomics,
    /// Float adds by a compare-and-swap loop on the float's bits: the fast mode's fallback
    /// for devices without float atomics (forced in tests on devices that have them).
    CompareAndSwap,
}

impl Accumulation {
    /// The name the `bench` and the Python package use.
    pub fn name(self) -> &'static str {
        match self {
            Accumulation::Deterministic => "deterministic",
            Accumulation::FloatAtomics => "float-atomics",
            Accumulation::CompareAndSwap => "cas",
        }
    }
}

impl std::str::FromStr for Accumulation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "deterministic" => Ok(Accumulation::Deterministic),
            "float-atomics" => Ok(Accumulation::FloatAtomics),
            "cas" => Ok(Accumulation::CompareAndSwap),
            other => Err(format!(
                "unknown gradient accumulation {other:?}; use deterministic, float-atomics or cas"
            )),
        }
    }
}

/// The accumulation pipeline of one [`Accumulation`].
pub struct GradAccumulate {
    pipeline: ComputePipeline,
    /// Invocations per workgroup ([`crate::gpu::workgroup::wide_linear_workgroup`]).
    workgroup: u32,
}

/// What the accumulation binds: the sorted pairs' Gaussian indices, the pairs' gradient
/// fields and their maxima, and the Gaussians' sums it adds to.
#[derive(Clone, Copy)]
pub struct AccumulateBindings<'a> {
    /// The sorted pairs' Gaussian indices.
    pub values: BufferSlice<'a>,
    /// Each pair's gradient fields.
    pub pair_grads: BufferSlice<'a>,
    /// Each field's largest magnitude.
    pub maxima: BufferSlice<'a>,
    /// Out: each Gaussian's sums.
    pub acc: BufferSlice<'a>,
}

impl GradAccumulate {
    /// Builds the pipeline for `mode`.
    pub fn new(ctx: &GpuContext, mode: Accumulation) -> GpuResult<Self> {
        let (float, cas) = match mode {
            Accumulation::Deterministic => (false, false),
            Accumulation::FloatAtomics => (true, false),
            Accumulation::CompareAndSwap => (true, true),
        };
        let storage = BindingKind::StorageBuffer;
        let int64 = !float && ctx.info().int64_atomics;
        let workgroup = crate::gpu::workgroup::wide_linear_workgroup(ctx.info());
        let pipeline = ComputePipeline::from_embedded_specialized(
            ctx,
            "grad_accumulate",
            &[
                ("FLOAT_ATOMICS", u32::from(float).to_string()),
                ("CAS_FALLBACK", u32::from(cas).to_string()),
                ("INT64_ATOMICS", u32::from(int64).to_string()),
            ],
            &by_binding([
                (slot::VALUES, storage),
                (slot::PAIR_GRADS, storage),
                (slot::MAXIMA, storage),
                (slot::ACC, storage),
            ])?,
            &GradPush::LAYOUT,
            &[(crate::gpu::shader_set::WIDE_WG_SPEC, workgroup)],
        )?;
        Ok(GradAccumulate {
            pipeline,
            workgroup,
        })
    }

    /// Records the dispatch over `push.count` pairs.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        b: &AccumulateBindings,
        push: GradPush,
    ) -> GpuResult<()> {
        if push.count == 0 {
            return Ok(());
        }
        let AccumulateBindings {
            values,
            pair_grads,
            maxima,
            acc,
        } = *b;
        let buffers = by_binding([
            (slot::VALUES, values),
            (slot::PAIR_GRADS, pair_grads),
            (slot::MAXIMA, maxima),
            (slot::ACC, acc),
        ])?;
        let groups = dispatch_grid(
            push.count.div_ceil(self.workgroup),
            ctx.info().max_workgroup_count[0],
        );
        self.pipeline
            .dispatch(ctx, cmd, &buffers, bytemuck::bytes_of(&push), groups)
    }
}
