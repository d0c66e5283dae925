//! One backward submission: the pass's pipelines and buffers resolved for recording
//! ([`BackwardPass`]), and the commands it records, in order: the pixels' gradients, the
//! shader's backward pass of a shaded frame, the three stages, and what reads the results.

use super::buffers::BackwardBuffers;
use super::{
    BackwardClock, BackwardState, BlendKey, DeviceGrads, FeatureJob, FeatureValues, PassShape,
    ShadeJob,
};
use crate::gpu::shader::Resource;
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{BufferSlice, GpuBuffer, GpuContext, GpuResult, GpuTimer};
use crate::render::backward::blend_bwd::{BlendBwd, BlendBwdBand, BlendBwdBindings};
use crate::render::backward::grad_accumulate::{AccumulateBindings, GradAccumulate, GradPush};
use crate::render::backward::preprocess_bwd::{PreprocessBwd, PreprocessBwdBindings};
use crate::render::backward::shade_bwd::{ShadeBwd, ShadeBwdBuffers};
use crate::render::frame::bands::{band_rows, bin_rows};
use crate::render::Stage;
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
    fs: ForwardState<'a>,
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
    /// One per pair band.
    pair_grads: Vec<BufferSlice<'a>>,
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
        fs: ForwardState<'a>,
        scene: &'a GpuScene,
        last: BufferSlice<'a>,
        shape: PassShape,
        (blend_key, rows, p): (BlendKey, bool, usize),
        features: Option<FeatureJob<'a>>,
        shade: Option<(ShadeJob<'a>, (BufferSlice<'a>, u32))>,
    ) -> (Self, &'a mut BackwardClock) {
        let BackwardState {
            blend,
            accumulate,
            preprocess,
            shade: shade_bwd,
            buffers:
                BackwardBuffers {
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
                },
            clock,
            mode,
            ..
        } = st;
        let (shade_bwd, alpha, scratch, partials, mlp_grads) =
            (&*shade_bwd, &*alpha, &*scratch, &*partials, &*mlp_grads);
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
        let preprocess = preprocess[p].as_ref().expect("built");
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
            pair_grads: pair_grads.iter().map(GpuBuffer::whole).collect(),
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
        (pass, clock)
    }

    /// Starts the pass in `cmd`: the forward's writes (an earlier submission) before the
    /// pass reads them, and the timer reset.
    pub(super) fn open(&self, ctx: &GpuContext, cmd: ash::vk::CommandBuffer, timer: &mut GpuTimer) {
        barrier(ctx, cmd, Access::Any, Access::Any);
        timer.reset(ctx, cmd);
    }

    /// A pass whose pixels' gradients are recorded on the device: no depth gradient.
    pub(super) fn clear_depth_gradients(&self, ctx: &GpuContext, cmd: ash::vk::CommandBuffer) {
        self.grad_depth
            .buffer
            .fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 0);
    }

    /// The frame's colour image (what the loss reads) and the buffer the pixels'
    /// gradients go into (dL/d rgb, dL/d alpha, a vec4 per pixel).
    pub(super) fn pixel_target(&self) -> (&'a crate::gpu::GpuImage, BufferSlice<'a>) {
        (self.fs.color, self.grad_color)
    }

    /// Records the pass's stages after the pixels' gradients: the sums cleared, the
    /// shader's backward pass of a shaded frame, then blend backward, accumulation and
    /// preprocess backward.
    pub(super) fn record_stages(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        timer: &mut GpuTimer,
    ) -> GpuResult<()> {
        self.maxima.buffer.fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 0);
        self.acc.buffer.fill(ctx, cmd, 0, ash::vk::WHOLE_SIZE, 0);
        barrier(ctx, cmd, Access::TransferWrite, Access::ComputeReadWrite);
        barrier(ctx, cmd, Access::ComputeWrite, Access::ComputeRead);
        if let Some(shade) = &self.shade {
            self.record_shade(ctx, cmd, timer, shade)?;
        }
        self.record_gaussian_stages(ctx, cmd, timer)
    }

    /// The pass's results on the device, for what reads them in the same submission.
    pub(super) fn results(&self) -> DeviceGrads<'a> {
        DeviceGrads {
            grads: self.grads,
            sh_grads: self.sh_grads,
            splats: self.fs.splats,
            feature_grads: self.feature_grads,
            mlp_grads: self.mlp_grads,
        }
    }

    /// Ends the pass: its writes before whatever comes next.
    pub(super) fn close(&self, ctx: &GpuContext, cmd: ash::vk::CommandBuffer) {
        barrier(ctx, cmd, Access::ComputeWrite, Access::Any);
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
        timer.stage(ctx, cmd, Stage::ShadeBwd.name(), |cmd| {
            pipeline.record(ctx, cmd, job.shader, buffers, job.cam, job.background)
        })?;
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        Ok(())
    }

    /// Blend backward, accumulation and preprocess backward, each after a barrier on the
    /// one before. The blend backward runs once per pixel band and pair band, the
    /// accumulation once per pair band ([`crate::render::frame::bands`]; one of each for a frame whose
    /// buffers fit their bindings).
    fn record_gaussian_stages(
        &self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        timer: &mut GpuTimer,
    ) -> GpuResult<()> {
        let (fs, shape) = (self.fs, &self.shape);
        let pair_bands = shape.bands.pair_bands();
        let row_bands = shape.bands.row_bands();
        let width = u64::from(shape.width);
        let groups = u64::from(shape.groups);
        timer.stage(ctx, cmd, Stage::BlendBwd.name(), |cmd| {
            for &(y0, y1) in &row_bands {
                let rows = |s: BufferSlice<'a>, each: u64| band_rows(s, (y0, y1), width * each);
                let bin_rows = bin_rows((y0, y1), shape.height, fs.bin_size, fs.bins.1);
                for (&(lo, hi), &pair_grads) in pair_bands.iter().zip(&self.pair_grads) {
                    let bindings = BlendBwdBindings {
                        params: fs.params,
                        splats: self.splats,
                        values: self.values,
                        ranges: fs.ranges,
                        last: rows(self.last, 8),
                        grad_color: rows(self.grad_color, 16),
                        grad_depth: rows(self.grad_depth, 4),
                        pair_grads,
                        maxima: self.maxima,
                        features: self.features,
                        grad_features: rows(self.grad_features, 16 * groups),
                    };
                    let band = BlendBwdBand {
                        pairs: (lo as u32, hi as u32),
                        bin_rows,
                        first_row: y0,
                    };
                    self.blend.record(ctx, cmd, fs.bins.0, band, &bindings)?;
                }
            }
            Ok(())
        })?;
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        timer.stage(ctx, cmd, Stage::Accumulate.name(), |cmd| {
            for (&(lo, hi), &pair_grads) in pair_bands.iter().zip(&self.pair_grads) {
                let values = fs.sorted_gaussians;
                let bindings = AccumulateBindings {
                    values: BufferSlice {
                        offset: values.offset + lo * 4,
                        size: ((hi - lo) * 4).max(4),
                        ..values
                    },
                    pair_grads,
                    maxima: self.maxima,
                    acc: self.acc,
                };
                self.accumulate.record(
                    ctx,
                    cmd,
                    &bindings,
                    GradPush {
                        count: (hi - lo) as u32,
                        bits: shape.bits,
                        vecs: shape.vecs,
                    },
                )?;
            }
            Ok(())
        })?;
        barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
        timer.stage(ctx, cmd, Stage::PreprocessBwd.name(), |cmd| {
            let bindings = PreprocessBwdBindings {
                params: fs.params,
                gaussians: self.scene.gaussians.whole(),
                sh_texels: self.scene.sh_texels.handle(),
                splats: fs.splats,
                maxima: self.maxima,
                acc: self.acc,
                grads: self.grads,
                sh_grads: self.sh_grads,
                feature_grads: self.feature_grads,
            };
            self.preprocess.record(
                ctx,
                cmd,
                &bindings,
                GradPush {
                    count: self.scene.count,
                    bits: shape.bits,
                    vecs: shape.vecs,
                },
            )
        })
    }
}
