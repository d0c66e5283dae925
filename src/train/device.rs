//! The Gaussians being trained, kept on the device between iterations: their parameters,
//! Adam's moments and the densification statistics in device buffers, stepped by
//! `glsl/train_step.comp` right after the backward pass in the same submission, which also
//! writes the activated records the next forward pass reads. Nothing per Gaussian crosses
//! to the host during an iteration; the state comes down ([`DeviceModel::download`]) only
//! for what the host does every few hundred iterations (densification, opacity reset,
//! evaluation, checkpoints, saving) and goes up again after.
//!
//! The arithmetic is [`super::model::Model::step`]'s and `add_stats`' (same order of
//! operations, `precise`); the device's `exp` and `sqrt` may round differently from the
//! host's, so a device run and a host run of the same settings agree closely, not to the
//! bit. A device run is bit-for-bit reproducible: every value is one Gaussian's own.

use super::model::{Model, Settings};
use crate::gpu::shader::{by_binding, BindingKind};
use crate::gpu::shader_set::bindings::train_step as slot;
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{
    dispatch_grid, ComputePipeline, GpuBuffer, GpuContext, GpuError, GpuResult, MemoryKind,
};
use crate::render::backward::DeviceGrads;
use crate::render::{sh_texel_stride, GpuRenderer, GpuScene};

/// Invocations per workgroup.
const WORKGROUP: u32 = 256;

/// `STEP_*` bits of the shader.
const STEP_STATS: u32 = 1;
const STEP_ADAM: u32 = 2;
const STEP_SKIP_OPACITY: u32 = 4;

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct StepPush {
    counts: [u32; 4],
    flags_size: [u32; 4],
    lr: [f32; 4],
    lr_sh: [f32; 4],
    c1: [f32; 4],
    c2: [f32; 4],
}

/// What one iteration's step does.
#[derive(Clone, Copy, Debug)]
pub struct Step {
    /// Add the frame's densification statistics.
    pub stats: bool,
    /// Take an Adam step, with these step counts per group (`Model::advance_steps`);
    /// `None`: no step (an iteration that densifies).
    pub adam: Option<[u32; 7]>,
    /// Leave the opacities (just reset) alone.
    pub skip_opacity: bool,
    /// The centres' learning rate.
    pub position_lr: f32,
    /// The frame's size.
    pub size: (u32, u32),
}

/// The model's state on the device.
pub struct DeviceModel {
    pipeline: ComputePipeline,
    count: u32,
    record: u32,
    sh_floats: u32,
    texel_floats: u32,
    state: GpuBuffer,
    m: GpuBuffer,
    v: GpuBuffer,
    stats: GpuBuffer,
    /// Bound where a pass reads no gradients (the first activation).
    empty: GpuBuffer,
    /// The activated Gaussians the forward pass renders.
    pub scene: GpuScene,
}

fn bias(beta: f32, t: u32) -> f32 {
    1.0 - beta.powi(t as i32)
}

impl DeviceModel {
    /// Puts `model` on the device (SH colour only: feature splats train on the host) and
    /// writes its activated records.
    pub fn new(renderer: &GpuRenderer, model: &Model) -> GpuResult<Self> {
        if model.shader.is_some() {
            return Err(GpuError::InvalidArgument(
                "feature splats train with the host optimiser".into(),
            ));
        }
        let ctx = renderer.ctx();
        let count = u32::try_from(model.len())
            .map_err(|_| GpuError::Input(format!("{} Gaussians exceed 2^32", model.len())))?;
        let record = model.record_floats() as u32;
        let degree = model.scene.sh_degree;
        let scene = renderer.scene_for_device_writes(count, degree)?;
        let s = BindingKind::StorageBuffer;
        let pipeline = ComputePipeline::from_embedded(
            ctx,
            "train_step",
            &[],
            &by_binding([
                (slot::STATE, s),
                (slot::M, s),
                (slot::V, s),
                (slot::GRADS, s),
                (slot::SH_GRADS, s),
                (slot::SPLATS, s),
                (slot::STATS, s),
                (slot::GAUSSIANS, s),
                (slot::SH, s),
            ])?,
            std::mem::size_of::<StepPush>() as u32,
            WORKGROUP,
        )?;
        let bytes = (u64::from(count) * u64::from(record) * 4).max(16);
        let make = |name: &str, bytes: u64| -> GpuResult<GpuBuffer> {
            crate::render::check_storage_binding(ctx, name, bytes)?;
            GpuBuffer::new(ctx, name, bytes, MemoryKind::Device)
        };
        let [params, m, v, stats] = model.device_state();
        let dm = DeviceModel {
            pipeline,
            count,
            record,
            sh_floats: model.scene.sh_stride() as u32,
            texel_floats: sh_texel_stride(degree) * 4,
            state: make("training parameters", bytes)?,
            m: make("Adam first moments", bytes)?,
            v: make("Adam second moments", bytes)?,
            stats: make("densification statistics", (u64::from(count) * 16).max(16))?,
            empty: GpuBuffer::new(ctx, "no gradients", 16, MemoryKind::Device)?,
            scene,
        };
        if count > 0 {
            dm.state.upload(ctx, &params)?;
            dm.m.upload(ctx, &m)?;
            dm.v.upload(ctx, &v)?;
            dm.stats.upload(ctx, &stats)?;
        }
        let push = dm.push(0, [0.0; 4], [0.0; 4], [1.0; 4], [1.0; 4], (0, 0));
        ctx.submit_and_wait("activate", |cmd| {
            barrier(ctx, cmd, Access::Any, Access::Any);
            dm.dispatch(ctx, cmd, None, &push)?;
            barrier(ctx, cmd, Access::ComputeWrite, Access::Any);
            Ok(())
        })?;
        Ok(dm)
    }

    /// Gaussians held.
    pub fn len(&self) -> usize {
        self.count as usize
    }

    /// True without Gaussians.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Device bytes of the state (parameters, moments, statistics, activated records and
    /// SH texels).
    pub fn device_bytes(&self) -> u64 {
        self.state.size()
            + self.m.size()
            + self.v.size()
            + self.stats.size()
            + self.scene.device_bytes()
    }

    fn push(
        &self,
        flags: u32,
        lr: [f32; 4],
        lr_sh: [f32; 4],
        c1: [f32; 4],
        c2: [f32; 4],
        size: (u32, u32),
    ) -> StepPush {
        StepPush {
            counts: [self.count, self.record, self.sh_floats, self.texel_floats],
            flags_size: [
                flags,
                (size.0 as f32 / 2.0).to_bits(),
                (size.1 as f32 / 2.0).to_bits(),
                0,
            ],
            lr,
            lr_sh,
            c1,
            c2,
        }
    }

    fn dispatch(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        grads: Option<DeviceGrads>,
        push: &StepPush,
    ) -> GpuResult<()> {
        if self.count == 0 {
            return Ok(());
        }
        let empty = self.empty.whole();
        let (g, sh, splats) =
            grads.map_or((empty, empty, empty), |g| (g.grads, g.sh_grads, g.splats));
        let (records, sh_out) = self.scene.device_buffers();
        let groups = dispatch_grid(
            self.count.div_ceil(WORKGROUP),
            ctx.info().max_workgroup_count[0],
        );
        self.pipeline.dispatch(
            ctx,
            cmd,
            &[
                self.state.whole(),
                self.m.whole(),
                self.v.whole(),
                g,
                sh,
                splats,
                self.stats.whole(),
                records,
                sh_out,
            ],
            bytemuck::bytes_of(push),
            groups,
        )
    }

    /// Records one iteration's step after its backward pass (`grads`, in the same
    /// command buffer, ordered before by the caller).
    pub fn record_step(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        grads: DeviceGrads,
        step: &Step,
        settings: &Settings,
    ) -> GpuResult<()> {
        let mut flags = 0;
        if step.stats {
            flags |= STEP_STATS;
        }
        let (mut c1, mut c2, mut sh_c) = ([1.0f32; 4], [1.0f32; 4], [1.0f32; 2]);
        if let Some(t) = step.adam {
            flags |= STEP_ADAM;
            if step.skip_opacity {
                flags |= STEP_SKIP_OPACITY;
            }
            for g in 0..4 {
                // A group not stepped yet keeps its correction at 1 (it is not read).
                if t[g] > 0 {
                    c1[g] = bias(0.9, t[g]);
                    c2[g] = bias(0.999, t[g]).sqrt();
                }
            }
            if t[4] > 0 {
                sh_c = [bias(0.9, t[4]), bias(0.999, t[4]).sqrt()];
            }
        }
        let lr = [
            step.position_lr,
            settings.scaling_lr,
            settings.rotation_lr,
            settings.opacity_lr,
        ];
        let lr_sh = [
            settings.feature_lr,
            settings.feature_lr / 20.0,
            sh_c[0],
            sh_c[1],
        ];
        let push = self.push(flags, lr, lr_sh, c1, c2, step.size);
        self.dispatch(ctx, cmd, Some(grads), &push)
    }

    /// Brings the state down into `model` (which must hold as many Gaussians).
    pub fn download(&self, ctx: &GpuContext, model: &mut Model) -> GpuResult<()> {
        if model.len() != self.len() || model.record_floats() as u32 != self.record {
            return Err(GpuError::Internal(format!(
                "the device holds {} Gaussians of {} floats, the model {} of {}",
                self.len(),
                self.record,
                model.len(),
                model.record_floats()
            )));
        }
        let n = self.len() * self.record as usize;
        if self.count == 0 {
            model.set_device_state([Vec::new(), Vec::new(), Vec::new(), Vec::new()]);
            return Ok(());
        }
        model.set_device_state([
            self.state.read(ctx, n)?,
            self.m.read(ctx, n)?,
            self.v.read(ctx, n)?,
            self.stats.read(ctx, self.len() * 4)?,
        ]);
        Ok(())
    }
}
