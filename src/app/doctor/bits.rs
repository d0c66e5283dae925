//! Whether a device reproduces the CPU reference bit for bit, and where it first does not
//! (issue 63): the render check counts, besides its PSNR gate, every preprocess record
//! and every frame value that is not the reference's exact float. docs/reproducibility.md
//! says what is guaranteed today.

use serde::Serialize;

use crate::core::frame::Frame;
use crate::cpu::Projected;
use crate::render::Intermediates;

/// Per stage, how many of a device's values differ in any bit from the CPU reference's.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct BitReport {
    /// Gaussians the preprocess compared (kept on either side).
    pub gaussians: usize,
    /// Kept on one side only.
    pub culling: usize,
    /// Of the Gaussians kept on both sides, those whose field differs: view depth, 2D
    /// mean, conic, opacity, SH colour, radius.
    pub depth: usize,
    pub mean2d: usize,
    pub conic: usize,
    pub opacity: usize,
    pub colour: usize,
    pub radius: usize,
    /// Frame values compared and those that differ: colour (3 a pixel), alpha, depth.
    pub frame_values: [usize; 3],
    pub frame_differing: [usize; 3],
}

/// How many of the pairs of values differ in any bit.
fn differing<'a>(
    a: impl IntoIterator<Item = &'a f32>,
    b: impl IntoIterator<Item = &'a f32>,
) -> usize {
    a.into_iter()
        .zip(b)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .count()
}

/// 1 when any of the values differ, else 0 (one Gaussian's field).
fn differs(a: &[f32], b: &[f32]) -> usize {
    usize::from(differing(a, b) > 0)
}

impl BitReport {
    /// Adds one frame's preprocess records: the device's (`gpu`) against the reference's.
    pub fn add_preprocess(&mut self, reference: &[Projected], gpu: &Intermediates) {
        for (c, g) in reference.iter().zip(&gpu.splats) {
            let g_radius = g.color_radius[3];
            let (kept_gpu, kept_cpu) = (g_radius != 0.0, c.radius > 0);
            if !kept_gpu && !kept_cpu {
                continue;
            }
            self.gaussians += 1;
            if kept_gpu != kept_cpu {
                self.culling += 1;
                continue;
            }
            let [mx, my, opacity, _] = g.mean_opacity_bound;
            let [a, b, cc, depth] = g.conic_depth;
            let [r, gg, bb, _] = g.color_radius;
            self.depth += differs(&[depth], &[c.depth]);
            self.mean2d += differs(&[mx, my], &c.mean2d);
            self.conic += differs(&[a, b, cc], &c.conic);
            self.opacity += differs(&[opacity], &[c.opacity]);
            self.colour += differs(&[r, gg, bb], &c.color);
            self.radius += usize::from(g_radius != c.radius as f32);
        }
    }

    /// Adds one frame: the device's (`gpu`) against the reference's.
    pub fn add_frame(&mut self, reference: &Frame, gpu: &Frame) {
        let values = [
            reference.color.len() * 3,
            reference.alpha.len(),
            reference.depth.len(),
        ];
        let differ = reference.differing_values(gpu);
        for k in 0..3 {
            self.frame_values[k] += values[k];
            self.frame_differing[k] += differ[k];
        }
    }

    /// The preprocess fields that differ, in the order the stage computes them, with
    /// their counts.
    fn preprocess_fields(&self) -> Vec<(&'static str, usize)> {
        [
            ("culling", self.culling),
            ("depth", self.depth),
            ("2D mean", self.mean2d),
            ("conic", self.conic),
            ("opacity", self.opacity),
            ("colour", self.colour),
            ("radius", self.radius),
        ]
        .into_iter()
        .filter(|f| f.1 > 0)
        .collect()
    }

    /// Every compared value equal.
    pub fn identical(&self) -> bool {
        self.preprocess_fields().is_empty() && self.frame_differing.iter().all(|&d| d == 0)
    }

    /// The first stage whose output differs: `preprocess` (its fields that differ),
    /// `blend` when only the frame does, or `None`.
    pub fn first_stage(&self) -> Option<String> {
        let fields = self.preprocess_fields();
        if !fields.is_empty() {
            let list: Vec<String> = fields
                .iter()
                .map(|(name, n)| format!("{name} of {n}"))
                .collect();
            return Some(format!(
                "preprocess ({} of {} Gaussians)",
                list.join(", "),
                self.gaussians
            ));
        }
        (!self.identical()).then(|| "blend".to_string())
    }

    /// "yes", or "no, first in <stage>" with the share of frame values that differ.
    pub fn verdict(&self) -> String {
        match self.first_stage() {
            None => "yes".to_string(),
            Some(stage) => {
                let differ: usize = self.frame_differing.iter().sum();
                let values: usize = self.frame_values.iter().sum();
                format!(
                    "no, first in {stage}; {:.2} % of frame values differ",
                    100.0 * differ as f64 / values.max(1) as f64
                )
            }
        }
    }

    /// One sentence for the doctor's report.
    pub fn sentence(&self) -> String {
        let share =
            |k: usize| 100.0 * self.frame_differing[k] as f64 / self.frame_values[k].max(1) as f64;
        match self.first_stage() {
            None => format!(
                "bit for bit: yes (every preprocess record of {} Gaussians and all {} frame \
                 values equal the CPU reference's)",
                self.gaussians,
                self.frame_values.iter().sum::<usize>()
            ),
            Some(stage) => format!(
                "bit for bit: no, first in {stage}; frame values that differ: colour \
                 {:.2} %, alpha {:.2} %, depth {:.2} % (docs/reproducibility.md)",
                share(0),
                share(1),
                share(2)
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(v: f32) -> Frame {
        Frame {
            width: 2,
            height: 1,
            color: vec![[v, 0.5, 0.25]; 2],
            alpha: vec![0.5; 2],
            depth: vec![1.0; 2],
            feature_count: 0,
            features: Vec::new(),
        }
    }

    #[test]
    fn equal_frames_are_bit_for_bit_and_one_bit_is_not() {
        let mut same = BitReport::default();
        same.add_frame(&frame(0.1), &frame(0.1));
        assert!(same.identical() && same.first_stage().is_none());
        assert!(
            same.sentence().starts_with("bit for bit: yes"),
            "{}",
            same.sentence()
        );
        let mut off = BitReport::default();
        let next = f32::from_bits(0.1f32.to_bits() + 1);
        off.add_frame(&frame(0.1), &frame(next));
        assert_eq!(off.frame_differing, [2, 0, 0]);
        assert_eq!(off.first_stage().as_deref(), Some("blend"));
        assert!(
            off.sentence().contains("colour 33.33 %"),
            "{}",
            off.sentence()
        );
    }
}
