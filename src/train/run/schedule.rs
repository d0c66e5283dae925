//! When things happen: the SH degree's rise and the order of the training views, what an
//! iteration's step does (densification statistics, densification or MCMC refinement,
//! opacity reset, the centres' learning rate, the MCMC terms), and which outputs are due
//! after it.

use super::{Job, Run};
use crate::train::data::View;
use crate::train::device::McmcStep;
use crate::train::model::{noise_key, position_lr};

/// What an iteration does besides rendering and the loss, from the schedule.
#[derive(Clone, Copy, Debug)]
pub(super) struct Plan {
    /// The iteration (1-based).
    pub(super) it: u32,
    /// Before the end of the densification (or the MCMC refinement).
    pub(super) in_densify: bool,
    /// Densify (or refine) after this iteration, which then takes no Adam step.
    pub(super) densify_now: bool,
    /// Reset the opacities after this iteration, whose step leaves them alone.
    pub(super) reset_now: bool,
    /// The centres' learning rate.
    pub(super) lr_now: f32,
    /// The MCMC strategy's noise and regularisers.
    pub(super) mcmc_step: Option<McmcStep>,
    /// Compute Mip-Splatting's 3D filter again after this iteration (after a
    /// densification too): every 100 iterations after the densification, but in the last
    /// 100 (the reference's schedule).
    pub(super) mip_now: bool,
}

impl Plan {
    /// Iteration `it`'s plan, the model holding `gaussians`.
    pub(super) fn at(job: &Job, it: u32, gaussians: usize) -> Self {
        let s = &job.opts.settings;
        // The original's densification (statistics, clone/split/prune, opacity resets) or
        // the MCMC strategy's refinement (relocation and growth).
        let mcmc = s.mcmc.as_ref();
        let until = mcmc.map_or(s.densify_until_iter, |m| m.refine_until);
        let in_densify = it < until;
        let densify_now =
            in_densify && it > s.densify_from_iter && it % s.densification_interval == 0;
        // The original also resets at the start of the densification on a white
        // background.
        let reset_now = mcmc.is_none()
            && in_densify
            && (it % s.opacity_reset_interval == 0
                || (job.opts.white_background && it == s.densify_from_iter));
        let lr_now = position_lr(s, job.data.extent, it);
        let n_now = gaussians.max(1);
        let mcmc_step = mcmc.map(|m| McmcStep {
            noise_scale: m.noise_lr * lr_now,
            key: noise_key(job.opts.seed, it),
            opacity_reg: m.opacity_reg / n_now as f32,
            scale_reg: m.scale_reg / (3 * n_now) as f32,
        });
        let mip_now = job.opts.mip_filter
            && (densify_now
                || (it > s.densify_until_iter
                    && it % crate::train::model::mip::RECOMPUTE_INTERVAL == 0
                    && it + crate::train::model::mip::RECOMPUTE_INTERVAL < s.iterations));
        Plan {
            it,
            in_densify,
            densify_now,
            reset_now,
            lr_now,
            mcmc_step,
            mip_now,
        }
    }
}

/// What the host writes or checks after an iteration.
pub(super) struct Due {
    /// Evaluate (a test iteration, or the last).
    pub(super) evaluate: bool,
    /// Write a checkpoint.
    pub(super) checkpoint: bool,
    /// Save the model (a save iteration, or the last).
    pub(super) save: bool,
    /// A signal asked to stop.
    pub(super) cancelled: bool,
}

impl Due {
    /// What is due after iteration `it`.
    pub(super) fn at(job: &Job, it: u32) -> Self {
        let (opts, s) = (job.opts, &job.opts.settings);
        Due {
            evaluate: opts.test_iterations.contains(&it) || it == s.iterations,
            checkpoint: opts.checkpoint_iterations.contains(&it),
            save: opts.save_iterations.contains(&it) || it == s.iterations,
            cancelled: opts
                .cancel
                .as_ref()
                .is_some_and(|c| c.load(std::sync::atomic::Ordering::SeqCst)),
        }
    }
}

impl Run<'_> {
    /// The start of iteration `it`: the SH degree in use rises every
    /// `sh_increase_interval` iterations, and the next training view is taken (a fresh
    /// random order of them when the round is done): its index among the training views,
    /// and the view.
    pub(super) fn next_view<'d>(&mut self, job: &Job<'d>, it: u32) -> (usize, &'d View) {
        let (s, data) = (&job.opts.settings, job.data);
        if it % s.sh_increase_interval == 0 && self.model.active_sh_degree < job.opts.sh_degree {
            self.model.active_sh_degree += 1;
        }
        if self.order.is_empty() {
            // A fresh random order of the training views (Fisher-Yates).
            self.order = (0..data.train.len()).collect();
            for i in (1..self.order.len()).rev() {
                self.order
                    .swap(i, (self.rng.next_u64() % (i as u64 + 1)) as usize);
            }
        }
        let photo = self.order.pop().expect("refilled above");
        (photo, &data.train[photo])
    }
}
