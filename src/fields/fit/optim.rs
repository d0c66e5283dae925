//! Adam over the model's parameters, and adaptive density control (prune, clone, split).

use super::model::{rotation, Model, FEAT, ROT, SCALE};

/// Adam (Kingma & Ba) with one learning rate per parameter slot of a Gaussian.
#[derive(Clone, Debug)]
pub struct Adam {
    /// First moments, the model's layout.
    pub m: Vec<f32>,
    /// Second moments.
    pub v: Vec<f32>,
    /// Steps taken (for the bias correction).
    pub t: u32,
}

/// Adam's decay rates and epsilon (tiny: the gradients of a normalised loss are small).
const BETA1: f32 = 0.9;
const BETA2: f32 = 0.999;
const EPS: f32 = 1e-15;

impl Adam {
    /// Zero state for `n` parameters.
    pub fn new(n: usize) -> Adam {
        Adam {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// One step: `lr[j]` is the learning rate of slot `j` of every Gaussian.
    pub fn step(&mut self, params: &mut [f32], grad: &[f32], lr: &[f32]) {
        self.t += 1;
        let c1 = 1.0 - BETA1.powi(self.t as i32);
        let c2 = 1.0 - BETA2.powi(self.t as i32);
        let stride = lr.len();
        for (j, ((p, &g), (m, v))) in params
            .iter_mut()
            .zip(grad)
            .zip(self.m.iter_mut().zip(self.v.iter_mut()))
            .enumerate()
        {
            *m = BETA1 * *m + (1.0 - BETA1) * g;
            *v = BETA2 * *v + (1.0 - BETA2) * g * g;
            let mh = *m / c1;
            let vh = *v / c2;
            *p -= lr[j % stride] * mh / (vh.sqrt() + EPS);
        }
    }
}

/// What one density-control step did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct DensityStep {
    /// The optimisation step after which it ran.
    pub step: usize,
    /// Gaussians before.
    pub before: usize,
    /// Removed for an opacity below `--min-opacity`.
    pub pruned: usize,
    /// Small Gaussians copied.
    pub cloned: usize,
    /// Large Gaussians replaced by two smaller ones.
    pub split: usize,
    /// Gaussians after.
    pub after: usize,
}

/// Removes the Gaussians whose opacity is below `min_opacity` (keeping the most opaque
/// one if all are), with their optimiser state and scores. Returns how many went.
pub fn prune(model: &mut Model, adam: &mut Adam, score: &mut Vec<f32>, min_opacity: f32) -> usize {
    let n = model.len();
    let mut keep: Vec<usize> = (0..n)
        .filter(|&i| model.opacity(i) >= min_opacity)
        .collect();
    if keep.is_empty() && n > 0 {
        let best = (0..n)
            .max_by(|&a, &b| {
                model
                    .opacity(a)
                    .total_cmp(&model.opacity(b))
                    .then(b.cmp(&a))
            })
            .unwrap_or(0);
        keep.push(best);
    }
    let stride = model.stride();
    let pick = |v: &[f32]| -> Vec<f32> {
        keep.iter()
            .flat_map(|&i| &v[i * stride..(i + 1) * stride])
            .copied()
            .collect()
    };
    model.params = pick(&model.params);
    adam.m = pick(&adam.m);
    adam.v = pick(&adam.v);
    *score = keep.iter().map(|&i| score[i]).collect();
    n - keep.len()
}

/// Adds up to `budget` Gaussians where `score` (accumulated residual) is largest, highest
/// first (ties: lower index first): a Gaussian whose largest scale is above the median of
/// the largest scales is split (two copies at +-1 largest scale along its longest axis,
/// scales divided by 1.6), any other is cloned (a copy half its largest scale along its
/// longest axis, both halves keeping half the features, so the field barely changes).
/// Optimiser state of every touched Gaussian restarts at zero. Returns (cloned, split).
///
/// A time-varying model has a fourth axis, time: its scale counts as `log s_t + time_to_space`
/// (`time_to_space` = log of the spatial length one unit of time compares to), and when it
/// is the longest, the split or clone is along time (the temporal means move, only the
/// temporal scale shrinks); along a spatial axis both copies keep the temporal mean.
pub fn densify(
    model: &mut Model,
    adam: &mut Adam,
    score: &[f32],
    budget: usize,
    time_to_space: f32,
) -> (usize, usize) {
    let n = model.len();
    if n == 0 || budget == 0 {
        return (0, 0);
    }
    let stride = model.stride();
    let k = model.k;
    let t_at = model.time.then(|| model.time_offset());
    // The longest axis, 0..3 in space or 3 for time, and its log scale on the spatial scale.
    let longest = |g: &[f32]| -> (usize, f32) {
        let mut best =
            (0..3)
                .map(|a| (a, g[SCALE + a]))
                .fold(
                    (0, f32::NEG_INFINITY),
                    |b, (a, v)| if v > b.1 { (a, v) } else { b },
                );
        if let Some(t) = t_at {
            let v = g[t + 1] + time_to_space;
            if v > best.1 {
                best = (3, v);
            }
        }
        best
    };
    let max_scale = |i: usize| longest(model.gaussian(i)).1;
    let mut scales: Vec<f32> = (0..n).map(max_scale).collect();
    scales.sort_by(f32::total_cmp);
    let median = scales[n / 2];
    let mut order: Vec<usize> = (0..n).filter(|&i| score[i] > 0.0).collect();
    order.sort_by(|&a, &b| score[b].total_cmp(&score[a]).then(a.cmp(&b)));
    order.truncate(budget);
    let (mut cloned, mut split) = (0, 0);
    let shrink = 1.6f32.ln();
    for &i in &order {
        let g: Vec<f32> = model.gaussian(i).to_vec();
        let (axis_or_time, size) = longest(&g);
        let (mut a, mut b) = (g.clone(), g.clone());
        let splits = size > median;
        if let (3, Some(t)) = (axis_or_time, t_at) {
            // Along time: split at +-1 temporal scale, or clone half a scale later.
            let st = g[t + 1].exp();
            if splits {
                a[t] = g[t] - st;
                b[t] = g[t] + st;
                a[t + 1] -= shrink;
                b[t + 1] -= shrink;
            } else {
                b[t] = g[t] + 0.5 * st;
            }
        } else {
            // Longest axis: column j of R.
            let j = (0..3)
                .max_by(|&a, &b| g[SCALE + a].total_cmp(&g[SCALE + b]).then(b.cmp(&a)))
                .unwrap_or(0);
            let q = &g[ROT..ROT + 4];
            let norm = (q.iter().map(|v| v * v).sum::<f32>()).sqrt();
            let r = rotation([q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm]);
            let axis = [r[0][j], r[1][j], r[2][j]];
            let s = g[SCALE + j].exp();
            if splits {
                for c in 0..3 {
                    a[c] = g[c] + s * axis[c];
                    b[c] = g[c] - s * axis[c];
                    a[SCALE + c] -= shrink;
                    b[SCALE + c] -= shrink;
                }
            } else {
                for c in 0..3 {
                    b[c] = g[c] + 0.5 * s * axis[c];
                }
            }
        }
        if splits {
            split += 1;
        } else {
            // A clone halves the features of both copies: the sum stays.
            for c in FEAT..FEAT + k {
                a[c] *= 0.5;
                b[c] *= 0.5;
            }
            cloned += 1;
        }
        model.params[i * stride..(i + 1) * stride].copy_from_slice(&a);
        model.params.extend_from_slice(&b);
        for state in [&mut adam.m, &mut adam.v] {
            state[i * stride..(i + 1) * stride].fill(0.0);
            state.extend(std::iter::repeat(0.0).take(stride));
        }
    }
    (cloned, split)
}
