//! What a tab's next preview (a frame while the camera moves) draws: how many of the
//! scene's Gaussians, the most important first, and how many pixels.
//!
//! A frame's time has two parts that shrink with different knobs: the per-Gaussian
//! stages (preprocess, depth order, scan, keys, sort, ranges: their work grows with the
//! Gaussians drawn and their tile pairs) shrink only with fewer Gaussians, the
//! per-pixel stages (blend, readback) with fewer pixels. After each preview the plan is
//! rescaled from its measured stage times so that each part takes half of
//! [`PREVIEW_GPU_MS`]; a part that reaches its limit (the whole scene, the largest
//! preview) leaves its unused time to the other. So a scene whose Gaussians are cheap
//! previews larger, one whose Gaussians are dear draws fewer of them instead of
//! shrinking the frame to its floor, and a smaller scene never needs more time than a
//! larger one: at the same size it draws at most as many Gaussians.

/// GPU time a preview frame should take (ms): about 15 to 20 previews a second with the
/// encoding and the transfer.
pub const PREVIEW_GPU_MS: f64 = 50.0;
/// Previews are never smaller than this many pixels (the canvas allowing).
pub const MIN_PREVIEW_PIXELS: f64 = 60_000.0;

/// What one preview draws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewPlan {
    /// Gaussians, the most important first (the scene's count: all of them).
    pub gaussians: f64,
    /// Pixels at most (the canvas scaled down to them, aspect kept).
    pub pixels: f64,
}

/// The range a plan stays in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewLimits {
    /// Gaussians in the scene.
    pub scene: f64,
    /// The most a preview draws short of the whole scene (the preview subset's size);
    /// 0: previews draw the whole scene.
    pub subset: f64,
    /// The fewest Gaussians a preview draws (the scene's count when it is smaller).
    pub min_gaussians: f64,
    /// The largest preview, pixels.
    pub max_pixels: f64,
}

impl PreviewLimits {
    /// Limits for a scene of `scene` Gaussians with a preview subset of `subset` (0: none)
    /// and previews of at most `max_pixels`.
    pub fn new(scene: u32, subset: u32, max_pixels: u32) -> PreviewLimits {
        let scene = f64::from(scene);
        let subset = f64::from(subset);
        let min_gaussians = if subset > 0.0 {
            scene
                .min(subset)
                .min(super::source::MIN_PREVIEW_GAUSSIANS as f64)
        } else {
            scene
        };
        PreviewLimits {
            scene,
            subset,
            min_gaussians,
            max_pixels: f64::from(max_pixels),
        }
    }

    /// The first preview of a tab: the largest size, and at most 24,576 Gaussians
    /// (about 25 ms of per-Gaussian stages on lavapipe) or the subset's size; later ones
    /// follow the timings.
    pub fn first_plan(&self) -> PreviewPlan {
        let most = if self.subset > 0.0 {
            self.subset
        } else {
            self.scene
        };
        PreviewPlan {
            gaussians: self.gaussians(most.min(24_576.0)),
            pixels: self.max_pixels,
        }
    }

    /// `g` as a count a preview can draw: the whole scene, or between the fewest and the
    /// subset's size.
    fn gaussians(&self, g: f64) -> f64 {
        let g = g.round();
        if self.subset <= 0.0 || g >= self.scene {
            self.scene
        } else {
            g.clamp(self.min_gaussians, self.subset.max(self.min_gaussians))
        }
    }

    fn pixels(&self, p: f64) -> f64 {
        p.clamp(MIN_PREVIEW_PIXELS.min(self.max_pixels), self.max_pixels)
    }
}

/// GPU times of a preview, split by what shrinks them (ms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewCost {
    /// Stages whose work grows with the Gaussians drawn (everything but the two below).
    pub per_gaussian_ms: f64,
    /// Blend and readback, whose work grows with the pixels.
    pub per_pixel_ms: f64,
}

impl PreviewCost {
    /// From a frame's stage timings.
    pub fn of(t: &crate::render::StageTimings) -> PreviewCost {
        let per_pixel_ms = t.blend + t.readback;
        PreviewCost {
            per_gaussian_ms: (t.total - per_pixel_ms).max(0.0),
            per_pixel_ms,
        }
    }
}

/// The plan after a preview that drew `gaussians` Gaussians on `pixels` pixels at `cost`
/// under plan `plan`. Each knob moves at most halfway (in ratio) towards its target per
/// frame, so one slow frame does not swing it.
pub fn next_plan(
    plan: PreviewPlan,
    gaussians: f64,
    pixels: f64,
    cost: PreviewCost,
    limits: &PreviewLimits,
) -> PreviewPlan {
    let PreviewCost {
        per_gaussian_ms: g_ms,
        per_pixel_ms: p_ms,
    } = cost;
    if !(gaussians > 0.0 && pixels > 0.0 && g_ms.is_finite() && p_ms.is_finite()) {
        return plan;
    }
    let half = PREVIEW_GPU_MS / 2.0;
    // Time per Gaussian and per pixel, as measured (a stage that took no time costs
    // nothing: the knob goes to its limit).
    let per_g = g_ms / gaussians;
    let per_p = p_ms / pixels;
    let g_for = |ms: f64| {
        if per_g > 0.0 {
            limits.gaussians(ms.max(0.0) / per_g)
        } else {
            limits.scene
        }
    };
    let p_for = |ms: f64| {
        if per_p > 0.0 {
            limits.pixels(ms.max(0.0) / per_p)
        } else {
            limits.max_pixels
        }
    };
    // Half the time each; then what one part leaves unused (at its limit) to the other.
    let g_target = g_for(half);
    let p_target = p_for(PREVIEW_GPU_MS - g_target * per_g);
    let g_target = g_for(PREVIEW_GPU_MS - p_target * per_p);
    let toward = |from: f64, to: f64| {
        let ratio = to / from;
        if (0.99..=1.01).contains(&ratio) {
            to
        } else {
            from * ratio.clamp(0.25, 4.0).sqrt()
        }
    };
    // A preview smaller than the plan (a small canvas) that was fast keeps the plan's
    // pixels: the canvas, not the time, made it small.
    let next_pixels = if p_target >= pixels {
        plan.pixels.max(toward(pixels, p_target))
    } else {
        toward(pixels, p_target)
    };
    // Between the subset's size and the whole scene there is nothing to draw: a plan
    // that outgrows the subset while the whole scene is the target jumps to it.
    let next_gaussians = toward(gaussians, g_target);
    let next_gaussians = if g_target >= limits.scene && next_gaussians > limits.subset {
        limits.scene
    } else {
        limits.gaussians(next_gaussians)
    };
    PreviewPlan {
        gaussians: next_gaussians,
        pixels: limits.pixels(next_pixels),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device where the per-Gaussian stages cost `per_g` ms per Gaussian and the
    /// per-pixel ones `per_p` ms per pixel, plus what the Gaussians add to the blend.
    fn cost(g: f64, p: f64, per_g: f64, per_p: f64) -> PreviewCost {
        PreviewCost {
            per_gaussian_ms: g * per_g,
            per_pixel_ms: p * per_p * (1.0 + g / 100_000.0),
        }
    }

    /// The plan a tab settles on for a scene after `frames` previews, and its time.
    fn settle(scene: u32, per_g: f64, per_p: f64) -> (PreviewPlan, f64) {
        let limits = PreviewLimits::new(scene, 131_072.min(scene), 250_000);
        let limits = if f64::from(scene) <= 8_192.0 {
            PreviewLimits::new(scene, 0, 250_000)
        } else {
            limits
        };
        let mut plan = limits.first_plan();
        let mut ms = 0.0;
        for _ in 0..60 {
            let c = cost(plan.gaussians, plan.pixels, per_g, per_p);
            ms = c.per_gaussian_ms + c.per_pixel_ms;
            plan = next_plan(plan, plan.gaussians, plan.pixels, c, &limits);
        }
        (plan, ms)
    }

    #[test]
    fn a_smaller_scene_never_previews_slower() {
        // Lavapipe-like costs (the 31k and 125k robots measured about 0.6 ms per 1,000
        // Gaussians and 0.15 ms per 1,000 pixels), a slower and a much faster device.
        for (per_g, per_p) in [(6e-4, 1.5e-4), (2e-3, 4e-4), (1e-6, 1e-7)] {
            let mut last = 0.0;
            for scene in [1_873, 31_000, 125_000, 250_000, 1_000_000, 10_000_000] {
                let (plan, ms) = settle(scene, per_g, per_p);
                // (Within 1 %: the plans settle to within that of their targets.)
                assert!(
                    ms >= 0.99 * last,
                    "{scene} Gaussians preview in {ms} ms, a smaller scene took {last} ms ({per_g}, {per_p})"
                );
                assert!(
                    ms <= PREVIEW_GPU_MS * 1.05 || plan.gaussians <= 8_192.0,
                    "{ms}"
                );
                last = ms;
            }
        }
    }

    #[test]
    fn dear_gaussians_shrink_the_subset_not_the_frame() {
        // The old rule shrank only the pixels, down to 60,000, however slow the
        // per-Gaussian stages were. Here they are dear and pixels cheap: the subset
        // shrinks and the preview keeps a good size.
        let (plan, ms) = settle(125_000, 2e-3, 5e-5);
        assert!(plan.gaussians < 20_000.0, "{plan:?}");
        assert!(plan.pixels >= 200_000.0, "{plan:?}");
        assert!((ms - PREVIEW_GPU_MS).abs() < 5.0, "{ms}");
        // On a fast device every Gaussian is drawn at the largest size.
        let (plan, _) = settle(125_000, 1e-6, 1e-7);
        assert_eq!(
            plan,
            PreviewPlan {
                gaussians: 125_000.0,
                pixels: 250_000.0
            }
        );
        // A scene up to the floor is always drawn whole.
        let (plan, _) = settle(1_873, 1.0, 1e-7);
        assert_eq!(plan.gaussians, 1_873.0);
    }

    #[test]
    fn plans_stay_in_their_limits_and_ignore_missing_timings() {
        let limits = PreviewLimits::new(500_000, 131_072, 250_000);
        let plan = limits.first_plan();
        assert_eq!(
            plan,
            PreviewPlan {
                gaussians: 24_576.0,
                pixels: 250_000.0
            }
        );
        let none = PreviewCost {
            per_gaussian_ms: f64::NAN,
            per_pixel_ms: 1.0,
        };
        assert_eq!(next_plan(plan, 24_576.0, 250_000.0, none, &limits), plan);
        // Fast: up to the whole scene, never between the subset's size and it.
        let fast = PreviewCost {
            per_gaussian_ms: 1.0,
            per_pixel_ms: 1.0,
        };
        let mut p = plan;
        for _ in 0..20 {
            p = next_plan(p, p.gaussians, p.pixels, fast, &limits);
            assert!(
                p.gaussians == 500_000.0 || p.gaussians <= 131_072.0,
                "{p:?}"
            );
        }
        assert_eq!(p.gaussians, 500_000.0);
        // Very slow: down to the floors.
        let slow = PreviewCost {
            per_gaussian_ms: 1e4,
            per_pixel_ms: 1e4,
        };
        for _ in 0..20 {
            p = next_plan(p, p.gaussians, p.pixels, slow, &limits);
        }
        assert_eq!(
            p,
            PreviewPlan {
                gaussians: 8_192.0,
                pixels: MIN_PREVIEW_PIXELS
            }
        );
        // A small canvas rendered fast keeps the pixel budget.
        let p = next_plan(plan, 24_576.0, 10_000.0, fast, &limits);
        assert_eq!(p.pixels, 250_000.0);
    }
}
