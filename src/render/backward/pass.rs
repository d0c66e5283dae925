//! One backward submission: the pass's pipelines and buffers resolved for recording
//! ([`BackwardPass`]), and the commands it records, in order: the pixels' gradients, the
//! shader's backward pass of a shaded frame, the three stages, and what reads the results.

use super::{
    BackwardState, BlendKey, DeviceGrads, FeatureJob, FeatureValues, GradsRecorder, PassShape,
    PixelInput, ShadeJob, BACKWARD_STAGES, DEVICE_LOSS_STAGE, DEVICE_STEP_STAGE,
    SHADE_BACKWARD_STAGE,
};
use crate::gpu::shader::Resource;
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{BufferSlice, GpuBuffer, GpuContext, GpuResult, GpuTimer};
use crate::render::backward::blend_bwd::BlendBwd;
use crate::render::backward::grad_accumulate::{GradAccumulate, GradPush};
use crate::render::backward::preprocess_bwd::PreprocessBwd;
use crate::render::backward::shade_bwd::{ShadeBwd, ShadeBwdBuffers};
use crate::render::{ForwardState, GpuScene};

/// The shader's backward pass of a shaded frame, resolved.
struct ShadePass<'a> {
    job: ShadeJob<'a>,
    pipeline: &'a ShadeBwd,
    buffers: ShadeBwdBuffers<'a>,
    /// Where the frame's colour image is copied for the pass to read its alpha.
    alpha: &'a GpuBuffer,
}

/// Everything one backward submission records with.
pub(super) struct BackwardPass<'a> {
    fs: &'a ForwardState<'a>,
    scene: &'a GpuScene,
    last: BufferSlice<'a>,
    shape: PassShape,
    blend: &'a BlendBwd,
    splats: Resource<'a>,
    values: Resource<'a>,
    accumulate: &'a GradAccumulate,
    preprocess: &'a PreprocessBwd,
    grad_color: BufferSlice<'a>,
    grad_depth: BufferSlice<'a>,
    pair_grads: BufferSlice<'a>,
    maxima: BufferSlice<'a>,
    acc: BufferSlice<'a>,
    grads: BufferSlice<'a>,
    sh_grads: BufferSlice<'a>,
    features: BufferSlice<'a>,
    grad_features: BufferSlice<'a>,
    feature_grads: BufferSlice<'a>,
    shade: Option<ShadePass<'a>>,
    /// The shader's gradients, for what reads the results (shaded frames).
    mlp_grads: Option<BufferSlice<'a>>,
}

fn buf(b: &Option<GpuBuffer>) -> BufferSlice<'_> {
    b.as_ref().expect("made above").whole()
}

impl<'a> BackwardPass<'a> {
    /// The pass's pipelines (the blend backward's of `blend`: its key and whether it reads
    /// rows of texels) and buffers in `st`, which the pipelines and buffers were made in;
    /// and `st`'s timer, to record with.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn resolve(
        st: &'a mut BackwardState,
        fs: &'a ForwardState<'a>,
        scene: &'a GpuScene,
        last: BufferSlice<'a>,
        shape: PassShape,
        (blend_key, rows): (BlendKey, bool),
        features: Option<FeatureJob<'a>>,
        shade: Option<(ShadeJob<'a>, (BufferSlice<'a>, u32))>,
    ) -> (Self, &'a mut GpuTimer) {
        let BackwardState {
            blend,
            accumulate,
            preprocess,
            shade: shade_bwd,
            grad_color,
            grad_depth,
            pair_grads,
            maxima,
            acc,
            grads,
            sh_grads,
            features: feature_values,
            grad_features,
            feature_grads,
            alpha,
            scratch,
            partials,
            mlp_grads,
            timer,
            mode,
            ..
        } = st;
        let (shade_bwd, alpha, scratch, partials, mlp_grads) =
            (&*shade_bwd, &*alpha, &*scratch, &*partials, &*mlp_grads);
        let float_sums =
            *mode != crate::render::backward::grad_accumulate::Accumulation::Deterministic;
        let blend = &blend
            .iter()
            .find(|(k, _)| *k == blend_key)
            .expect("built")
            .1;
        let (splats, values) = match (rows, fs.value_texels) {
            (true, Some(v)) => (
                Resource::TexelBuffer(fs.splat_texels),
                Resource::TexelBuffer(v),
            ),
            _ => (
                Resource::Buffer(fs.splats),
                Resource::Buffer(fs.sorted_gaussians),
            ),
        };
        let accumulate = &accumulate
            .iter()
            .find(|(m, _)| *m == *mode)
            .expect("built")
            .1;
        let preprocess = preprocess[usize::from(float_sums)].as_ref().expect("built");
        let (grad_color, grad_features) = (buf(grad_color), buf(grad_features));
        fn need(b: &Option<GpuBuffer>) -> BufferSlice<'_> {
            b.as_ref().expect("made above").whole()
        }
        let shade = shade.map(|(job, planes)| ShadePass {
            job,
            pipeline: shade_bwd.as_ref().expect("built above"),
            buffers: ShadeBwdBuffers {
                features: planes,
                alpha: need(alpha),
                grad_color,
                grad_features,
                scratch: need(scratch),
                partials: need(partials),
                grads: need(mlp_grads),
            },
            alpha: alpha.as_ref().expect("made above"),
        });
        let pass = BackwardPass {
            fs,
            scene,
            last,
            shape,
            blend,
            splats,
            values,
            accumulate,
            preprocess,
            grad_color,
            grad_depth: buf(grad_depth),
            pair_grads: buf(pair_grads),
            maxima: buf(maxima),
            acc: buf(acc),
            grads: buf(grads),
            sh_grads: buf(sh_grads),
            features: match features {
                Some((FeatureValues::Device(values), _, _)) => values,
                _ => buf(feature_values),
            },
            grad_features,
            feature_grads: buf(feature_grads),
            mlp_grads: mlp_grads
                .as_ref()
                .filter(|_| shade.is_some())
                .map(|b| b.whole()),
            shade,
        };
        (pass, timer)
    }

    /// Records the whole pass into `cmd`: `input`'s pixel gradients when the device makes
    /// them, the shader's backward pass, the three stages, then `after`.
    pub(super) fn record(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        timer: &mut GpuTimer,
        input: &mut PixelInput,
        after: Option<GradsRecorder>,
    ) -> GpuResult<()> {
        // The forward's writes (an earlier submission) before this pass reads them.
        barrier(ctx, cmd, Access::Any, Access::Any);
        timer.reset(ctx, cmd);
        if let PixelInput::Device(record) = input {
            self.grad_depth
                .buffer
                .fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 0);
            timer.stage(ctx, cmd, DEVICE_LOSS_STAGE, |cmd| {
                record(ctx, cmd, self.fs.color, self.grad_color)
            })?;
        }
        self.maxima.buffer.fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 0);
        self.acc.buffer.fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 0);
        barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        if let Some(shade) = &self.shade {
            self.record_shade(ctx, cmd, timer, shade)?;
        }
        self.record_stages(ctx, cmd, timer)?;
        if let Some(after) = after {
            barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
            timer.stage(ctx, cmd, DEVICE_STEP_STAGE, |cmd| {
                after(
                    ctx,
                    cmd,
                    DeviceGrads {
                        grads: self.grads,
                        sh_grads: self.sh_grads,
                        splats: self.fs.splats,
                        feature_grads: self.feature_grads,
                        mlp_grads: self.mlp_grads,
                    },
                )
            })?;
        }
        barrier(ctx, cmd, Access::ComputeWrite, Access::Any);
        Ok(())
    }

    /// The shader's backward pass: the frame's alpha (its colour image, a copy source
    /// since its forward pass) copied where the pass reads it, then the pass.
    fn record_shade(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        timer: &mut GpuTimer,
        shade: &ShadePass,
    ) -> GpuResult<()> {
        let ShadePass {
            job,
            pipeline,
            buffers,
            alpha,
        } = shade;
        // The frame's alpha: its colour image (a copy source since its forward
        // pass) copied where the shader's backward pass reads it.
        self.fs.color.copy_to_buffer(ctx, cmd, alpha, 0);
        barrier(ctx, cmd, Access::TransferWrite, Access::ComputeRead);
        timer.stage(ctx, cmd, SHADE_BACKWARD_STAGE, |cmd| {
            pipeline.record(ctx, cmd, job.shader, buffers, job.cam, job.background)
        })?;
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        Ok(())
    }

    /// Blend backward, accumulation and preprocess backward, each after a barrier on the
    /// one before.
    fn record_stages(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        timer: &mut GpuTimer,
    ) -> GpuResult<()> {
        let (fs, shape) = (self.fs, &self.shape);
        timer.stage(ctx, cmd, BACKWARD_STAGES[0], |cmd| {
            self.blend.record(
                ctx,
                cmd,
                fs.bins,
                fs.params,
                self.splats,
                self.values,
                fs.ranges,
                self.last,
                self.grad_color,
                self.grad_depth,
                self.pair_grads,
                self.maxima,
                self.features,
                self.grad_features,
            )
        })?;
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        timer.stage(ctx, cmd, BACKWARD_STAGES[1], |cmd| {
            self.accumulate.record(
                ctx,
                cmd,
                fs.sorted_gaussians,
                self.pair_grads,
                self.maxima,
                self.acc,
                GradPush {
                    count: fs.pairs,
                    bits: shape.bits,
                    vecs: shape.vecs,
                },
            )
        })?;
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        timer.stage(ctx, cmd, BACKWARD_STAGES[2], |cmd| {
            self.preprocess.record(
                ctx,
                cmd,
                fs.params,
                self.scene.gaussians.whole(),
                self.scene.sh_texels.handle(),
                fs.splats,
                self.maxima,
                self.acc,
                self.grads,
                self.sh_grads,
                self.feature_grads,
                GradPush {
                    count: self.scene.count,
                    bits: shape.bits,
                    vecs: shape.vecs,
                },
            )
        })
    }
}
