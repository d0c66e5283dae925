//! The Gaussians being trained, kept on the device between iterations: their parameters,
//! Adam's moments and the densification statistics in device buffers, stepped by
//! `glsl/train/train_step.comp` right after the backward pass in the same submission, which also
//! writes the activated records (and feature channels) the next forward pass reads; with
//! feature splats the neural shader's weights too (`glsl/train/train_mlp_step.comp`, written
//! into the shader's own buffer). With `--clip-grad` a first pass sums the squared
//! gradients in a fixed order (`loss_reduce`) and the step scales them. Nothing per
//! Gaussian crosses to the host during an iteration; the state comes down
//! ([`DeviceModel::download`]) only for what the host does every few hundred iterations
//! (densification, opacity reset, evaluation, checkpoints, saving) and goes up again after.
//!
//! The arithmetic is [`super::model::Model::step`]'s and `add_stats`' (same order of
//! operations, `precise`); the device's `exp` and `sqrt` may round differently from the
//! host's, so a device run and a host run of the same settings agree closely, not to the
//! bit. A device run is bit-for-bit reproducible: every value is one Gaussian's own, and
//! the norm's sum has a fixed order.

use super::model::{Model, Settings};
use crate::core::shader_interface::{
    MlpPush, StepPush, STEP_ADAM, STEP_CLIP, STEP_FEATURES, STEP_MIP, STEP_NOISE, STEP_NORM,
    STEP_SKIP_OPACITY, STEP_STATS,
};
use crate::gpu::shader::{by_binding, BindingKind};
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{
    dispatch_grid, BufferSlice, ComputePipeline, GpuBuffer, GpuContext, GpuError, GpuResult,
    MemoryKind,
};
use crate::render::backward::DeviceGrads;
use crate::render::forward::shade::GpuShader;
use crate::render::{sh_texel_stride, GpuFeatures, GpuRenderer, GpuScene};
use crate::train::shaders::bindings::{loss_reduce, train_mlp_step as mslot, train_step as slot};

/// Invocations per workgroup.
const WORKGROUP: u32 = crate::gpu::shader_set::LINEAR_WG;
/// Values a `loss_reduce` workgroup sums.
const REDUCE_SPAN: u64 = crate::gpu::shader_set::REDUCE_SPAN as u64;

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
    /// The MCMC strategy's regularisers and noise (with the Adam step).
    pub mcmc: Option<McmcStep>,
}

/// One iteration's MCMC terms.
#[derive(Clone, Copy, Debug)]
pub struct McmcStep {
    /// Noise scale: `noise_lr` times the centres' learning rate.
    pub noise_scale: f32,
    /// The iteration's noise key ([`super::model::noise_key`]).
    pub key: u32,
    /// Weight of the mean opacity over the Gaussians' count.
    pub opacity_reg: f32,
    /// Weight of the mean scale over three times the count.
    pub scale_reg: f32,
}

/// The pipelines of the step (built once per run; a [`DeviceModel`] is rebuilt after
/// each densification).
pub struct StepPipelines {
    train: ComputePipeline,
    /// Invocations per workgroup of `train` ([`crate::gpu::workgroup::wide_linear_workgroup`]).
    train_workgroup: u32,
    reduce: ComputePipeline,
    mlp: ComputePipeline,
}

impl StepPipelines {
    /// Builds them.
    pub fn new(ctx: &GpuContext) -> GpuResult<Self> {
        let s = BindingKind::StorageBuffer;
        let train_workgroup = crate::gpu::workgroup::wide_linear_workgroup(ctx.info());
        Ok(StepPipelines {
            train_workgroup,
            train: ComputePipeline::from_embedded_specialized(
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
                    (slot::FEATURE_GRADS, s),
                    (slot::FEATURES, s),
                    (slot::FEAT0, s),
                    (slot::FEAT1, s),
                    (slot::FEAT2, s),
                    (slot::FEAT3, s),
                    (slot::NORMS, s),
                    (slot::NORM_TOTAL, s),
                ])?,
                &StepPush::LAYOUT,
                &[(crate::gpu::shader_set::WIDE_WG_SPEC, train_workgroup)],
            )?,
            reduce: ComputePipeline::from_embedded(
                ctx,
                "loss_reduce",
                &[],
                &by_binding([(loss_reduce::VALUES, s), (loss_reduce::SUMS, s)])?,
                &crate::core::shader_interface::CountsPush::LAYOUT,
            )?,
            mlp: ComputePipeline::from_embedded(
                ctx,
                "train_mlp_step",
                &[],
                &by_binding([
                    (mslot::STATE, s),
                    (mslot::M, s),
                    (mslot::V, s),
                    (mslot::GRADS, s),
                    (mslot::WORDS, s),
                    (mslot::NORMS, s),
                    (mslot::NORM_TOTAL, s),
                ])?,
                &MlpPush::LAYOUT,
            )?,
        })
    }
}

/// The neural shader's weights on the device, and their Adam state.
struct ShaderState {
    gpu: GpuShader,
    params: u32,
    state: GpuBuffer,
    m: GpuBuffer,
    v: GpuBuffer,
}

/// The model's state on the device.
pub struct DeviceModel<'p> {
    pipelines: &'p StepPipelines,
    count: u32,
    record: u32,
    colours: u32,
    texel_floats: u32,
    groups: u32,
    state: GpuBuffer,
    m: GpuBuffer,
    v: GpuBuffer,
    stats: GpuBuffer,
    /// Feature splats: the channels Gaussian-major in groups of four (what the backward
    /// pass reads).
    interleaved: Option<GpuBuffer>,
    /// Squared gradient norms (one vec4 per Gaussian and shader value) and the two
    /// buffers their sum is reduced through (`--clip-grad`).
    norms: Option<[GpuBuffer; 3]>,
    /// Bound where a pass reads nothing (`empty`) or writes nothing (`sink`): never the
    /// same buffer for both, so that no dispatch seems to read another's writes.
    empty: GpuBuffer,
    sink: GpuBuffer,
    shader: Option<ShaderState>,
    /// The activated Gaussians the forward pass renders.
    pub scene: GpuScene,
    /// Their feature channels (feature splats).
    pub features: Option<GpuFeatures>,
    /// Mip-Splatting's 3D filter is on (in each record's float 11: STEP_MIP).
    mip: bool,
}

/// The push's `clip` vector without the clipping norm: the noise scale and the
/// regularisers' weights per value (over n and 3 n).
fn mcmc_terms(m: Option<McmcStep>) -> [f32; 4] {
    m.map_or([0.0; 4], |m| {
        [0.0, m.noise_scale, m.opacity_reg, m.scale_reg]
    })
}

/// Bias corrections of a group stepped `t` times (1 before its first step: not read).
fn corrections(t: u32) -> (f32, f32) {
    if t == 0 {
        (1.0, 1.0)
    } else {
        super::model::adam_corrections(t)
    }
}

impl<'p> DeviceModel<'p> {
    /// Puts `model` on the device and writes its activated records (and feature channels).
    pub fn new(
        renderer: &GpuRenderer,
        pipelines: &'p StepPipelines,
        model: &Model,
        clip: bool,
    ) -> GpuResult<Self> {
        let ctx = renderer.ctx();
        let count = u32::try_from(model.len())
            .map_err(|_| GpuError::Input(format!("{} Gaussians exceed 2^32", model.len())))?;
        let record = model.record_floats() as u32;
        let featured = model.shader.is_some();
        let degree = if featured { 0 } else { model.scene.sh_degree };
        let scene = renderer.scene_for_device_writes(count, degree)?;
        let make = |name: &str, bytes: u64| -> GpuResult<GpuBuffer> {
            let bytes = bytes.max(16);
            crate::render::check_storage_binding(ctx, name, bytes)?;
            GpuBuffer::new(ctx, name, bytes, MemoryKind::Device)
        };
        let bytes = u64::from(count) * u64::from(record) * 4;
        let k = model.scene.feature_count;
        let groups = if featured { k.div_ceil(4) as u32 } else { 0 };
        let (features, interleaved) = if featured {
            (
                Some(renderer.features_for_device_writes(count, k)?),
                Some(make(
                    "feature values",
                    u64::from(count) * u64::from(groups) * 16,
                )?),
            )
        } else {
            (None, None)
        };
        let shader = match (&model.shader, model.device_shader_state()) {
            (Some(mlp), Some([flat, m, v])) => {
                let params = flat.len() as u32;
                let st = ShaderState {
                    gpu: GpuShader::new(ctx, mlp)?,
                    params,
                    state: make("shader parameters", u64::from(params) * 4)?,
                    m: make("shader Adam first moments", u64::from(params) * 4)?,
                    v: make("shader Adam second moments", u64::from(params) * 4)?,
                };
                if params > 0 {
                    st.state.upload(ctx, &flat)?;
                    st.m.upload(ctx, &m)?;
                    st.v.upload(ctx, &v)?;
                }
                Some(st)
            }
            _ => None,
        };
        let norms = if clip {
            let values = u64::from(count) + shader.as_ref().map_or(0, |s| u64::from(s.params));
            let sums = values.div_ceil(REDUCE_SPAN).max(1);
            Some([
                make("gradient norms", values * 16)?,
                make("gradient norm sums", sums * 16)?,
                make("gradient norm sums (2)", sums * 16)?,
            ])
        } else {
            None
        };
        let [params, m, v, stats] = model.device_state();
        let dm = DeviceModel {
            pipelines,
            count,
            record,
            colours: model.colour_floats() as u32,
            texel_floats: sh_texel_stride(degree) * 4,
            groups,
            state: make("training parameters", bytes)?,
            m: make("Adam first moments", bytes)?,
            v: make("Adam second moments", bytes)?,
            stats: make("densification statistics", u64::from(count) * 16)?,
            interleaved,
            norms,
            empty: GpuBuffer::new(ctx, "nothing to read", 16, MemoryKind::Device)?,
            sink: GpuBuffer::new(ctx, "nothing to write", 16, MemoryKind::Device)?,
            shader,
            scene,
            features,
            mip: model.mip_filters.is_some(),
        };
        if count > 0 {
            dm.state.upload(ctx, &params)?;
            dm.m.upload(ctx, &m)?;
            dm.v.upload(ctx, &v)?;
            dm.stats.upload(ctx, &stats)?;
        }
        let push = dm.push(0, [0.0; 4], [0.0; 4], [1.0; 4], [1.0; 4], (0, 0), [0.0; 4]);
        ctx.submit_and_wait("activate", |cmd| {
            barrier(ctx, cmd, Access::Any, Access::Any);
            dm.dispatch(ctx, cmd, None, &push, None)?;
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

    /// The neural shader as the device holds it (feature splats).
    pub fn shader(&self) -> Option<&GpuShader> {
        self.shader.as_ref().map(|s| &s.gpu)
    }

    /// The feature channels Gaussian-major in groups of four, and their count.
    pub fn feature_values(&self) -> Option<(BufferSlice<'_>, usize)> {
        self.interleaved
            .as_ref()
            .zip(self.features.as_ref())
            .map(|(b, f)| (b.whole(), f.channels()))
    }

    /// Device bytes of the state (parameters, moments, statistics, activated records,
    /// SH texels and feature channels, the shader's).
    pub fn device_bytes(&self) -> u64 {
        let mut bytes = self.state.size()
            + self.m.size()
            + self.v.size()
            + self.stats.size()
            + self.scene.device_bytes();
        bytes += self.interleaved.as_ref().map_or(0, |b| b.size());
        bytes += self.features.as_ref().map_or(0, |f| f.device_bytes());
        bytes += self
            .norms
            .as_ref()
            .map_or(0, |n| n.iter().map(|b| b.size()).sum());
        if let Some(s) = &self.shader {
            bytes += s.state.size() + s.m.size() + s.v.size() + s.gpu.device_bytes();
        }
        bytes
    }

    #[allow(clippy::too_many_arguments)]
    fn push(
        &self,
        flags: u32,
        lr: [f32; 4],
        lr_sh: [f32; 4],
        c1: [f32; 4],
        c2: [f32; 4],
        size: (u32, u32),
        clip: [f32; 4],
    ) -> StepPush {
        let features = if self.interleaved.is_some() {
            STEP_FEATURES
        } else {
            0
        };
        StepPush {
            counts: [self.count, self.record, self.colours, self.texel_floats],
            flags_size: [
                flags | features | if self.mip { STEP_MIP } else { 0 },
                (size.0 as f32 / 2.0).to_bits(),
                (size.1 as f32 / 2.0).to_bits(),
                self.groups,
            ],
            lr,
            lr_sh,
            c1,
            c2,
            clip,
            noise: [0; 4],
        }
    }

    fn dispatch(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        grads: Option<DeviceGrads>,
        push: &StepPush,
        norm_total: Option<BufferSlice>,
    ) -> GpuResult<()> {
        if self.count == 0 {
            return Ok(());
        }
        let (empty, sink) = (self.empty.whole(), self.sink.whole());
        let (g, sh, splats, feature_grads) = grads.map_or((empty, empty, empty, empty), |g| {
            (g.grads, g.sh_grads, g.splats, g.feature_grads)
        });
        let (records, sh_out) = self.scene.device_buffers();
        let group_bufs = self
            .features
            .as_ref()
            .map_or_else(Vec::new, |f| f.device_buffers());
        let group = |i: usize| group_bufs.get(i).copied().unwrap_or(sink);
        let groups = dispatch_grid(
            self.count.div_ceil(self.pipelines.train_workgroup),
            ctx.info().max_workgroup_count[0],
        );
        let norms = self.norms.as_ref().map_or(sink, |n| n[0].whole());
        self.pipelines.train.dispatch(
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
                feature_grads,
                self.interleaved.as_ref().map_or(sink, |b| b.whole()),
                group(0),
                group(1),
                group(2),
                group(3),
                norms,
                norm_total.unwrap_or(empty),
            ],
            bytemuck::bytes_of(push),
            groups,
        )
    }

    fn dispatch_mlp(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        grads: BufferSlice,
        push: &MlpPush,
        norm_total: Option<BufferSlice>,
    ) -> GpuResult<()> {
        let Some(s) = &self.shader else {
            return Ok(());
        };
        if s.params == 0 {
            return Ok(());
        }
        let (empty, sink) = (self.empty.whole(), self.sink.whole());
        let groups = dispatch_grid(
            s.params.div_ceil(WORKGROUP),
            ctx.info().max_workgroup_count[0],
        );
        self.pipelines.mlp.dispatch(
            ctx,
            cmd,
            &[
                s.state.whole(),
                s.m.whole(),
                s.v.whole(),
                grads,
                s.gpu.words_buffer(),
                self.norms.as_ref().map_or(sink, |n| n[0].whole()),
                norm_total.unwrap_or(empty),
            ],
            bytemuck::bytes_of(push),
            groups,
        )
    }

    /// Records the gradient norm's sum (`--clip-grad`): each value's square, then sums in
    /// a fixed order down to one. Returns the buffer holding it (in its first float).
    fn record_norm<'a>(
        &'a self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        grads: DeviceGrads,
        mlp_grads: Option<BufferSlice>,
        mcmc: Option<McmcStep>,
    ) -> GpuResult<&'a GpuBuffer> {
        let [values, part_a, part_b] = self.norms.as_ref().expect("made with clipping");
        // The regularisers' gradients count in the norm (STEP_NOISE adds them).
        let flags = STEP_NORM | if mcmc.is_some() { STEP_NOISE } else { 0 };
        let push = self.push(
            flags,
            [0.0; 4],
            [0.0; 4],
            [1.0; 4],
            [1.0; 4],
            (0, 0),
            mcmc_terms(mcmc),
        );
        self.dispatch(ctx, cmd, Some(grads), &push, None)?;
        let mut count = u64::from(self.count);
        if let (Some(s), Some(g)) = (&self.shader, mlp_grads) {
            // Both write the norms (their own entries).
            barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeWrite);
            let push = MlpPush {
                sizes: [s.params, GpuShader::WEIGHTS_OFFSET, STEP_NORM, self.count],
                lr_c: [0.0, 1.0, 1.0, 0.0],
            };
            self.dispatch_mlp(ctx, cmd, g, &push, None)?;
            count += u64::from(s.params);
        }
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        let mut src = values;
        let mut dst = part_a;
        loop {
            let out = count.div_ceil(REDUCE_SPAN).max(1);
            self.pipelines.reduce.dispatch(
                ctx,
                cmd,
                &[src.whole(), dst.whole()],
                bytemuck::bytes_of(&crate::core::shader_interface::CountsPush {
                    counts: [count as u32, 0, 0, 0],
                }),
                [out as u32, 1, 1],
            )?;
            barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
            if out == 1 {
                return Ok(dst);
            }
            count = out;
            src = dst;
            dst = if std::ptr::eq(dst, part_a) {
                part_b
            } else {
                part_a
            };
        }
    }

    /// Records one iteration's step after its backward pass (`grads`, in the same
    /// command buffer, ordered before by the caller). With clipping
    /// (`settings.clip_grad`, and the model put up with `clip`), returns the buffer whose
    /// first float is the squared gradient norm, to read after the submission.
    pub fn record_step<'a>(
        &'a self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        grads: DeviceGrads,
        step: &Step,
        settings: &Settings,
    ) -> GpuResult<Option<&'a GpuBuffer>> {
        let mut flags = 0;
        if step.stats {
            flags |= STEP_STATS;
        }
        let featured = self.interleaved.is_some();
        let (mut c1, mut c2, mut colour_c, mut mlp_c) =
            ([1.0f32; 4], [1.0f32; 4], (1.0, 1.0), (1.0, 1.0));
        let mut norm_total = None;
        if let Some(t) = step.adam {
            flags |= STEP_ADAM;
            if step.skip_opacity {
                flags |= STEP_SKIP_OPACITY;
            }
            for g in 0..4 {
                (c1[g], c2[g]) = corrections(t[g]);
            }
            colour_c = corrections(t[if featured { 5 } else { 4 }]);
            mlp_c = corrections(t[6]);
            if settings.clip_grad.is_some() {
                if self.norms.is_none() {
                    return Err(GpuError::Internal(
                        "gradient clipping on a device model made without it".into(),
                    ));
                }
                norm_total = Some(self.record_norm(ctx, cmd, grads, grads.mlp_grads, step.mcmc)?);
                flags |= STEP_CLIP;
            }
        }
        let clip = settings.clip_grad.unwrap_or(0.0);
        if step.mcmc.is_some() && step.adam.is_some() {
            flags |= STEP_NOISE;
        }
        let mut terms = mcmc_terms(step.mcmc);
        terms[0] = clip;
        let lr = [
            step.position_lr,
            settings.scaling_lr,
            settings.rotation_lr,
            settings.opacity_lr,
        ];
        let lr_sh = [
            settings.feature_lr,
            settings.feature_lr / 20.0,
            colour_c.0,
            colour_c.1,
        ];
        let mut push = self.push(flags, lr, lr_sh, c1, c2, step.size, terms);
        push.noise[0] = step.mcmc.map_or(0, |m| m.key);
        let total = norm_total.map(|b| b.whole());
        self.dispatch(ctx, cmd, Some(grads), &push, total)?;
        if let (Some(s), Some(g), true) = (&self.shader, grads.mlp_grads, step.adam.is_some()) {
            // Independent values, but both write the unused `sink`.
            barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeWrite);
            let push = MlpPush {
                sizes: [
                    s.params,
                    GpuShader::WEIGHTS_OFFSET,
                    STEP_ADAM | (flags & STEP_CLIP),
                    self.count,
                ],
                lr_c: [settings.shader_lr, mlp_c.0, mlp_c.1, clip],
            };
            self.dispatch_mlp(ctx, cmd, g, &push, total)?;
        }
        Ok(norm_total)
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
        if let Some(s) = &self.shader {
            let p = s.params as usize;
            if p > 0 {
                model.set_device_shader_state([
                    s.state.read(ctx, p)?,
                    s.m.read(ctx, p)?,
                    s.v.read(ctx, p)?,
                ]);
            }
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
