//! One iteration's step: the view rendered, the loss and its gradient, the backward pass
//! and the Adam step, with the model's state on the device ([`crate::train::device`]) or,
//! for comparisons, on the host ([`crate::train::model::Model::step`]).

use super::schedule::Plan;
use super::{Job, Run, TrainError};
use crate::core::model::grad::PixelGrads;
use crate::core::model::RenderOptions;
use crate::gpu::sync::{barrier, Access};
use crate::render::backward::differentiable::DiffRasterizer;
use crate::render::backward::{BackwardRequest, DeviceFeatures};
use crate::render::{FrameRequest, Readback, Rendered};
use crate::train::data::View;
use crate::train::device::{DeviceModel, Step, StepPipelines};
use crate::train::loss::{GpuLoss, LossValue};
use std::cell::OnceCell;

impl<'p> Run<'p> {
    /// The step with the state on the device: the model goes up first when it is not
    /// there (at the start, and after the host changed it), the pipelines are built at the
    /// first; then render, the loss and its gradient, backward and the step are recorded
    /// without a Gaussian crossing to the host, and only the loss's sums (and, with
    /// clipping, the gradient's norm) are read back.
    pub(super) fn device_step(
        &mut self,
        job: &Job,
        pipelines: &'p OnceCell<StepPipelines>,
        rast: &mut DiffRasterizer,
        loss: &mut GpuLoss,
        (photo, view): (usize, &View),
        plan: &Plan,
    ) -> Result<LossValue, TrainError> {
        let s = &job.opts.settings;
        let render_opts = &job.render_opts;
        let bg = render_opts.background;
        let affine = self.affine_of(job, photo, plan.it);
        let cam = &view.camera;
        let mcmc = s.mcmc.as_ref();
        let Plan {
            it,
            in_densify,
            densify_now,
            reset_now,
            lr_now,
            mcmc_step,
            ..
        } = *plan;
        let Run {
            model,
            dev,
            stage_sums,
            appearance,
            ..
        } = self;
        if dev.is_none() {
            let pipelines = match pipelines.get() {
                Some(p) => p,
                None => {
                    let made = StepPipelines::new(rast.renderer().ctx())?;
                    pipelines.get_or_init(|| made)
                }
            };
            *dev = Some(DeviceModel::new(
                rast.renderer(),
                pipelines,
                model,
                s.clip_grad.is_some(),
            )?);
        }
        let d = dev.as_ref().expect("made above");
        let it_opts = RenderOptions {
            sh_degree: Some(model.active_sh_degree),
            ..*render_opts
        };
        let renderer = rast.renderer();
        let forward = match (&d.features, d.shader()) {
            (Some(features), Some(shader)) => renderer
                .render(
                    &FrameRequest::new(&d.scene, cam, &it_opts)
                        .shaded(features, shader)
                        .readback(Readback::Counters),
                )
                .and_then(Rendered::into_forward)?,
            _ => renderer
                .render(&FrameRequest::new(&d.scene, cam, &it_opts).readback(Readback::Counters))
                .and_then(Rendered::into_forward)?,
        };
        if renderer.forward_state()?.last_contributor.is_none() {
            return Err(TrainError::Other(format!(
                "the {}x{} view {} of {} Gaussians is too large to render in one piece, which training needs; use a lower --resolution",
                cam.width, cam.height, cam.name, model.len()
            )));
        }
        loss.stage_photo(renderer.ctx(), photo, &view.image, view.mask.as_deref())?;
        let step = Step {
            stats: in_densify && mcmc.is_none(),
            adam: (!densify_now).then(|| model.advance_steps(reset_now)),
            skip_opacity: reset_now,
            position_lr: lr_now,
            size: (cam.width, cam.height),
            mcmc: mcmc_step,
        };
        let (w, h, lambda) = (cam.width, cam.height, s.lambda_dssim);
        let features = match (d.feature_values(), d.shader()) {
            (Some((values, channels)), Some(shader)) => Some(DeviceFeatures {
                values,
                channels,
                shader,
                cam,
                background: bg,
            }),
            _ => None,
        };
        stage_sums.add(renderer.timings().stages());
        // One submission, top to bottom: the loss writes the pixels' gradients, the
        // backward pass turns them into the Gaussians', the step reads those.
        let mut req = BackwardRequest::recorded(&forward, &d.scene);
        if let Some(features) = features {
            req = req.shaded_on_device(features);
        }
        let mut pass = renderer.device_backward(&req)?;
        let ctx = pass.ctx();
        let mut norm_buffer = None;
        ctx.submit_and_wait("backward", |cmd| {
            let (image, pixel_grads) = pass.begin(cmd)?;
            match affine.as_ref().map(crate::train::appearance::rows) {
                // The photo's transform between the render and the loss; the pixels'
                // gradients leave it as the render's.
                Some(rows) => {
                    loss.record_image_affine(ctx, cmd, image, pixel_grads, w, h, lambda, &rows)?
                }
                None => loss.record_image(ctx, cmd, image, pixel_grads, w, h, lambda)?,
            }
            let grads = pass.record(cmd)?;
            barrier(ctx, cmd, Access::ComputeReadWrite, Access::ComputeReadWrite);
            norm_buffer = d.record_step(ctx, cmd, grads, &step, s)?;
            pass.end(cmd)
        })?;
        pass.finish()?;
        stage_sums.add(rast.renderer().backward_timings());
        let ctx = rast.renderer().ctx();
        let value = loss.read_value(ctx)?;
        if let (Some(a), Some(_)) = (appearance.as_mut(), affine) {
            if value.total.is_finite() {
                a.step(photo, &loss.read_affine_grads()?, &job.opts.appearance);
            }
        }
        if let Some(b) = norm_buffer {
            // The squared norm of the whole gradient, clipped against (one float).
            let sq: Vec<[f32; 4]> = b.read(ctx, 1)?;
            let norm = sq[0][0].sqrt();
            if !norm.is_finite() && value.total.is_finite() {
                return Err(TrainError::Other(format!(
                    "training diverged at iteration {it}: the gradient's norm is {norm}; the last model saved is the last good one"
                )));
            }
        }
        Ok(value)
    }

    /// The step on the host: the Gaussians uploaded, rendered, the loss's gradient and
    /// the backward pass read back, the densification statistics added and Adam stepped
    /// on the host ([`crate::train::model::Model::step`]).
    pub(super) fn host_step(
        &mut self,
        job: &Job,
        rast: &mut DiffRasterizer,
        loss: &mut GpuLoss,
        (photo, view): (usize, &View),
        plan: &Plan,
    ) -> Result<LossValue, TrainError> {
        let s = &job.opts.settings;
        let render_opts = &job.render_opts;
        let cam = &view.camera;
        let affine = self.affine_of(job, photo, plan.it);
        let mcmc = s.mcmc.as_ref();
        let Plan {
            it,
            in_densify,
            densify_now,
            reset_now,
            lr_now,
            mcmc_step,
            ..
        } = *plan;
        let Run {
            model,
            stage_sums,
            appearance,
            ..
        } = self;
        let params = model.params();
        rast.set_shader(model.shader.as_ref())?;
        let (frame, token) = rast.forward(&params, cam, render_opts)?;
        stage_sums.add(rast.renderer().timings().stages());
        // The photo's transform between the render and the loss, and back.
        let transformed = affine.map(|a| crate::train::appearance::apply(&frame.color, &a));
        let (value, mut grad) = loss.compute_masked(
            rast.renderer().ctx(),
            transformed.as_deref().unwrap_or(&frame.color),
            &view.image,
            view.mask.as_deref(),
            cam.width,
            cam.height,
            s.lambda_dssim,
        )?;
        if let (Some(a), Some(t)) = (appearance.as_mut(), affine) {
            let (pixel, sums) = crate::train::appearance::backward(&frame.color, &grad, &t);
            grad = pixel;
            if value.total.is_finite() {
                a.step(photo, &sums, &job.opts.appearance);
            }
        }
        if value.total.is_finite() {
            let pixel_grads = PixelGrads {
                color: grad.iter().flatten().copied().collect(),
                alpha: Vec::new(),
                depth: Vec::new(),
            };
            let (grads, shader_grads) = if model.shader.is_some() {
                let (g, m) =
                    rast.backward_shaded(&params, cam, render_opts, token, &pixel_grads)?;
                (g, Some(m))
            } else {
                (
                    rast.backward(&params, cam, render_opts, token, &pixel_grads)?,
                    None,
                )
            };
            stage_sums.add(rast.renderer().backward_timings());
            if in_densify && mcmc.is_none() {
                let radii: Vec<f32> = rast
                    .projected()?
                    .iter()
                    .map(|sp| sp.color_radius[3])
                    .collect();
                model.add_stats(&grads, &radii, cam.width, cam.height);
            }
            if !densify_now {
                let norm = model.step(&grads, shader_grads.as_ref(), lr_now, s, reset_now);
                if !norm.is_finite() {
                    return Err(TrainError::Other(format!(
                        "training diverged at iteration {it}: the gradient's norm is {norm}; the last model saved is the last good one"
                    )));
                }
                if let Some(m) = mcmc_step {
                    model.add_noise(m.noise_scale, m.key);
                }
            }
        }
        Ok(value)
    }

    /// The transform of training photo `photo` at iteration `it` (row r of `[A | b]`), when
    /// the run learns one and its steps have begun (`--appearance-from`).
    fn affine_of(
        &self,
        job: &Job,
        photo: usize,
        it: u32,
    ) -> Option<crate::train::appearance::Affine> {
        let a = self.appearance.as_ref()?;
        (it >= job.opts.appearance.from).then(|| a.affines[photo])
    }
}
