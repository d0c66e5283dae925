//! What the host does on the model after a step: the device's state comes down when the
//! host needs it; then, after the outputs the original writes first (evaluation, save),
//! the original's densification or the MCMC strategy's refinement, and the opacity
//! reset.

use super::schedule::{Due, Plan};
use super::{Job, Run, TrainError};
use crate::render::backward::differentiable::DiffRasterizer;

impl Run<'_> {
    /// Brings the device's state down for the evaluation and the save, which see the
    /// model before the iteration's step; the device keeps it.
    pub(super) fn bring_down_for_outputs(
        &mut self,
        rast: &mut DiffRasterizer,
    ) -> Result<(), TrainError> {
        if let Some(d) = &self.dev {
            d.download(rast.renderer().ctx(), &mut self.model)?;
        }
        Ok(())
    }

    /// Brings the device's state down after iteration `plan.it`'s step when the host
    /// changes the model or writes a checkpoint; it goes up again (rebuilt) at the next
    /// iteration when the host changed it.
    pub(super) fn bring_down(
        &mut self,
        rast: &mut DiffRasterizer,
        plan: &Plan,
        due: &Due,
    ) -> Result<(), TrainError> {
        let changes = plan.densify_now || plan.reset_now || plan.mip_now;
        if let Some(d) = &self.dev {
            if changes || due.checkpoint || due.cancelled {
                d.download(rast.renderer().ctx(), &mut self.model)?;
            }
            if changes {
                self.dev = None;
            }
        }
        Ok(())
    }

    /// Iteration `plan.it`'s changes to the model on the host (after
    /// [`Run::bring_down`]; the iteration's evaluation and save came before its step, as
    /// the original's).
    pub(super) fn change_model(&mut self, job: &Job, plan: &Plan) -> Result<(), TrainError> {
        let s = &job.opts.settings;
        let (it, densify_now, reset_now) = (plan.it, plan.densify_now, plan.reset_now);
        if let (true, Some(m)) = (densify_now, s.mcmc.as_ref()) {
            // 3dgs-mcmc's order: relocate and grow, the step (skipped: the parameters are
            // new), the noise.
            self.model.mcmc_refine(m.cap_max, &mut self.rng);
            if let Some(ms) = plan.mcmc_step {
                self.model.add_noise(ms.noise_scale, ms.key);
            }
        } else if densify_now {
            let screen = (it > s.opacity_reset_interval).then_some(20.0);
            self.model
                .densify_and_prune(s, job.data.extent, screen, &mut self.rng);
            if self.model.is_empty() {
                return Err(TrainError::Other(format!(
                    "every Gaussian was pruned at iteration {it}; the scene is empty (check the photos and cameras)"
                )));
            }
        }
        // Mip-Splatting's order: the filter of the densified centres, then the reset
        // (which caps the filtered opacity).
        if plan.mip_now {
            self.model.mip_filters = Some(job.mip_filters(&self.model.scene.positions));
        }
        if reset_now {
            self.model.reset_opacity();
        }
        Ok(())
    }
}
