//! Evaluation at the test iterations: the test views (or, without them, up to five
//! training views) rendered and compared with their photos (PSNR, SSIM, L1, FLIP).

use super::{Evaluation, Job, Run, TrainError};
use crate::core::model::RenderOptions;
use crate::render::backward::differentiable::DiffRasterizer;
use crate::train::data::View;
use crate::train::model::Model;

impl Run<'_> {
    /// Evaluates the model after iteration `it`, notes the figures and keeps them.
    pub(super) fn evaluate(
        &mut self,
        job: &Job,
        rast: &mut DiffRasterizer,
        it: u32,
        note: &mut dyn FnMut(String),
    ) -> Result<(), TrainError> {
        let data = job.data;
        let (views, split): (Vec<&View>, &str) = if data.test.is_empty() {
            (
                data.train
                    .iter()
                    .step_by((data.train.len() / 5).max(1))
                    .take(5)
                    .collect(),
                "train",
            )
        } else {
            (data.test.iter().collect(), "test")
        };
        let e = evaluate_views(rast, &self.model, &views, &job.render_opts, it, split)?;
        note(format!(
            "[ITER {it}] evaluating {split} ({} views): L1 {:.5} PSNR {:.2} dB SSIM {:.4} FLIP {:.4}; {} Gaussians",
            e.views,
            e.l1,
            e.psnr,
            e.ssim,
            e.flip,
            self.model.len()
        ));
        self.evaluations.push(e);
        Ok(())
    }
}

/// Renders `views` and compares them with their photos.
fn evaluate_views(
    rast: &mut DiffRasterizer,
    model: &Model,
    views: &[&View],
    opts: &RenderOptions,
    iteration: u32,
    split: &str,
) -> Result<Evaluation, TrainError> {
    let params = model.params();
    rast.set_shader(model.shader.as_ref())?;
    let (mut psnr, mut ssim, mut l1, mut flip) = (0.0, 0.0, 0.0, 0.0);
    for v in views {
        let (frame, _) = rast.forward(&params, &v.camera, opts)?;
        let img: Vec<f32> = frame
            .color
            .iter()
            .flatten()
            .map(|c| c.clamp(0.0, 1.0))
            .collect();
        let gt: Vec<f32> = v.image.iter().flatten().copied().collect();
        let (w, h) = (v.camera.width as usize, v.camera.height as usize);
        let ppd = crate::io::metrics::flip_default_ppd();
        let Some(keep) = &v.mask else {
            psnr += crate::io::metrics::psnr(&gt, &img, 1.0);
            ssim += crate::io::metrics::ssim(&gt, &img, w, h, 3);
            flip += crate::io::metrics::flip(&gt, &img, w, h, ppd);
            l1 += img
                .iter()
                .zip(&gt)
                .map(|(a, b)| (a - b).abs() as f64)
                .sum::<f64>()
                / img.len() as f64;
            continue;
        };
        // A masked view: its kept pixels only (crate::train::masks).
        let (p, s, f) = crate::train::masks::masked_metrics(&gt, &img, (w, h), keep, ppd);
        (psnr, ssim, flip) = (psnr + p, ssim + s, flip + f);
        let kept = keep.iter().filter(|&&k| k).count().max(1);
        l1 += (0..img.len())
            .filter(|i| keep[i / 3])
            .map(|i| (img[i] - gt[i]).abs() as f64)
            .sum::<f64>()
            / (3 * kept) as f64;
    }
    let n = views.len().max(1) as f64;
    Ok(Evaluation {
        iteration,
        split: split.to_string(),
        views: views.len(),
        psnr: psnr / n,
        ssim: ssim / n,
        l1: l1 / n,
        flip: flip / n,
    })
}
