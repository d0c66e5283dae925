//! The additive Gaussian field `fit` optimises, its loss, and the loss's analytic gradient.
//!
//! The field at `x` is `f(x) = sum_i o_i G_i(x) feat_i` (K channels), with
//! `o_i = sigmoid(logit_i)` and `G_i` the unnormalised Gaussian `exp(-d2 / 2)` truncated
//! at `d2 <= 16` (4 sigma, where it has fallen to 3.4e-4) or the power kernel
//! `max(0, 1 - d2 / 9)`, `d2 = |S^-1 R^T (x - mu)|^2` the squared Mahalanobis distance
//! (`S = diag(exp(log_scale))`, `R` the rotation of the normalised quaternion, as the
//! renderers build the covariance `R S S^T R^T`).
//!
//! A time-varying model ([`Model::time`], samples with a time) is separable in space and
//! time: `f(x, t) = sum_i o_i T_i(t) G_i(x) feat_i` with the temporal factor
//! `T_i(t) = exp(-0.5 ((t - tau_i) / s_i)^2)` truncated at 4 temporal sigma
//! ([`crate::core::scene::temporal_weight`], the same function the renders at a time use), `tau_i`
//! and `log s_i` two more parameters after the features.
//!
//! Samples are binned into a uniform grid of cubic cells ([`CellGrid`]); a Gaussian visits
//! only the cells its support box (the axis-aligned box of its `d2 <= cutoff` ellipsoid)
//! overlaps. Both passes loop over Gaussians: the forward pass in a fixed number of chunks
//! ([`FORWARD_CHUNKS`]) whose partial sums are added in chunk order, the backward pass one
//! Gaussian per task, each accumulating its own gradient. So every result is the same for
//! any number of threads.

// The kernel's support and value and the rotation, shared with the CPU reference's field
// renders (`cpu::field`), live in `model::field`; their paths here are kept.
pub use crate::core::model::field::{
    cutoff, kernel_value, rotation, GAUSSIAN_CUTOFF, POWER_CUTOFF,
};
use crate::core::model::SplatKernel;
use rayon::prelude::*;

/// Fixed number of Gaussian chunks in the forward pass (independent of the thread count,
/// so the summation order, and with it every bit of the result, is too).
pub const FORWARD_CHUNKS: usize = 16;

/// Parameters per Gaussian before the features: position (3), log scales (3), quaternion
/// `w, x, y, z` (4) and the opacity logit (1).
pub const BASE_PARAMS: usize = 11;
/// Offset of the log scales in a Gaussian's parameters.
pub const SCALE: usize = 3;
/// Offset of the quaternion.
pub const ROT: usize = 6;
/// Offset of the opacity logit.
pub const LOGIT: usize = 10;
/// Offset of the features.
pub const FEAT: usize = 11;

/// The logistic sigmoid.
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// The Gaussians: `stride()` floats each, `[x y z | log s0 s1 s2 | w qx qy qz | logit |
/// feat_0 .. feat_{K-1} | tau log_s_t]` (the last two only with [`Model::time`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Feature channels.
    pub k: usize,
    /// Each Gaussian has a temporal mean and log temporal scale after its features.
    pub time: bool,
    /// `len() * stride()` parameters.
    pub params: Vec<f32>,
}

impl Model {
    /// An empty static model with `k` channels.
    pub fn new(k: usize) -> Model {
        Model {
            k,
            time: false,
            params: Vec::new(),
        }
    }
    /// An empty time-varying model with `k` channels.
    pub fn with_time(k: usize) -> Model {
        Model {
            time: true,
            ..Model::new(k)
        }
    }
    /// Floats per Gaussian.
    pub fn stride(&self) -> usize {
        BASE_PARAMS + self.k + if self.time { 2 } else { 0 }
    }
    /// Offset of the temporal mean (the log temporal scale follows) in a Gaussian's
    /// parameters, with [`Model::time`].
    pub fn time_offset(&self) -> usize {
        FEAT + self.k
    }
    /// Gaussian `i`'s features.
    pub fn features(&self, i: usize) -> &[f32] {
        &self.gaussian(i)[FEAT..FEAT + self.k]
    }
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.params.len() / self.stride()
    }
    /// True without Gaussians.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }
    /// Gaussian `i`'s parameters.
    pub fn gaussian(&self, i: usize) -> &[f32] {
        let s = self.stride();
        &self.params[i * s..(i + 1) * s]
    }
    /// The Gaussians of a scene with feature channels (a fitted PLY): its positions, log
    /// scales, normalised rotations, opacity logits, features and (a time-varying scene)
    /// temporal means and log scales, so [`evaluate_at`] gives the field the scene holds.
    pub fn from_scene(scene: &crate::core::scene::Scene) -> Model {
        let k = scene.feature_count;
        let time = scene.time.as_ref();
        let mut params = Vec::with_capacity(scene.len() * (BASE_PARAMS + k + 2));
        for i in 0..scene.len() {
            params.extend_from_slice(&scene.positions[i]);
            params.extend_from_slice(&scene.log_scales[i]);
            params.extend_from_slice(&crate::core::scene::normalize_quat(scene.rotations[i]));
            params.push(scene.opacity_logits[i]);
            params.extend_from_slice(&scene.features[i * k..(i + 1) * k]);
            if let Some(t) = time {
                params.extend_from_slice(&t[i]);
            }
        }
        Model {
            k,
            time: time.is_some(),
            params,
        }
    }
    /// The static model of the same Gaussians, their temporal parameters dropped.
    pub fn without_time(&self) -> Model {
        if !self.time {
            return self.clone();
        }
        let (s, keep) = (self.stride(), BASE_PARAMS + self.k);
        Model {
            k: self.k,
            time: false,
            params: self
                .params
                .chunks_exact(s)
                .flat_map(|g| &g[..keep])
                .copied()
                .collect(),
        }
    }
    /// The activated opacity of Gaussian `i`.
    pub fn opacity(&self, i: usize) -> f32 {
        sigmoid(self.gaussian(i)[LOGIT])
    }
}

/// A uniform grid of cubic cells over a box; cell `(ix, iy, iz)` is number
/// `(ix * ny + iy) * nz + iz`, so the cells of one `(ix, iy)` column are consecutive.
#[derive(Clone, Debug, PartialEq)]
pub struct CellGrid {
    /// The lower corner.
    pub origin: [f32; 3],
    /// The side of a cell.
    pub cell: f32,
    /// Cells per axis.
    pub dims: [usize; 3],
}

impl CellGrid {
    /// Cells over `bounds` (`[min xyz, max xyz]`) holding about `per_cell` of `n` evenly
    /// spread samples each (at most 128 per axis).
    pub fn new(bounds: [f32; 6], n: usize, per_cell: f32) -> CellGrid {
        let ext = extents(bounds);
        let volume = f64::from(ext[0]) * f64::from(ext[1]) * f64::from(ext[2]);
        let cells = (n as f64 / f64::from(per_cell)).max(1.0);
        CellGrid::with_side(bounds, (volume / cells).cbrt() as f32)
    }
    /// Cells of side `side` over `bounds` (larger when that would make more than 128 per
    /// axis).
    pub fn with_side(bounds: [f32; 6], side: f32) -> CellGrid {
        let ext = extents(bounds);
        let largest = ext.iter().fold(0f32, |m, &e| m.max(e));
        let cell = if side.is_finite() && side > 0.0 {
            side
        } else {
            largest
        }
        .max(largest / 128.0);
        let dims = [0, 1, 2].map(|a| ((ext[a] / cell).ceil() as usize).clamp(1, 128));
        CellGrid {
            origin: [bounds[0], bounds[1], bounds[2]],
            cell,
            dims,
        }
    }
    /// Number of cells.
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
    /// True for a grid without cells (never: every axis has one).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The cell index along axis `a` of coordinate `v`, clamped into the grid.
    fn axis_cell(&self, a: usize, v: f32) -> usize {
        let c = ((v - self.origin[a]) / self.cell).floor();
        if c.is_nan() || c < 0.0 {
            0
        } else {
            (c as usize).min(self.dims[a] - 1)
        }
    }
    /// The cell holding `p` (points outside go to the nearest border cell).
    pub fn cell_of(&self, p: [f32; 3]) -> usize {
        let c = [0, 1, 2].map(|a| self.axis_cell(a, p[a]));
        (c[0] * self.dims[1] + c[1]) * self.dims[2] + c[2]
    }
    /// The cell range `[lo, hi]` (inclusive, per axis) that a box from `lo` to `hi`
    /// overlaps, clamped into the grid (a box outside maps to border cells, whose samples
    /// the exact `d2` test then rejects).
    pub fn range(&self, lo: [f32; 3], hi: [f32; 3]) -> ([usize; 3], [usize; 3]) {
        (
            [0, 1, 2].map(|a| self.axis_cell(a, lo[a])),
            [0, 1, 2].map(|a| self.axis_cell(a, hi[a])),
        )
    }
}

/// The axis-aligned box of `positions`: (xmin, ymin, zmin, xmax, ymax, zmax); infinite
/// and empty (min > max) when there are none.
pub fn point_bounds(positions: &[[f32; 3]]) -> [f32; 6] {
    let mut b = [
        f32::INFINITY,
        f32::INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
    ];
    for p in positions {
        for a in 0..3 {
            b[a] = b[a].min(p[a]);
            b[a + 3] = b[a + 3].max(p[a]);
        }
    }
    b
}

/// The sides of `bounds`, each at least 1e-3 of the largest (and 1e-6), so flat data
/// still gets a box.
pub fn extents(bounds: [f32; 6]) -> [f32; 3] {
    let ext = [0, 1, 2].map(|a| (bounds[a + 3] - bounds[a]).max(0.0));
    let largest = ext.iter().fold(0f32, |m, &e| m.max(e)).max(1e-6);
    ext.map(|e| e.max(1e-3 * largest))
}

/// Samples sorted by cell: positions, target values (K each; empty when only evaluating),
/// loss weights, and where each cell's samples start.
#[derive(Clone, Debug)]
pub struct Points {
    /// Positions, sorted by cell.
    pub positions: Vec<[f32; 3]>,
    /// Target values, `k` per sample (or none).
    pub values: Vec<f32>,
    /// Loss weights, one per sample (or none).
    pub weights: Vec<f32>,
    /// Times, sorted by cell (none for a static field).
    pub times: Vec<f32>,
    /// The sample's index in the input order given to [`Points::binned`].
    pub order: Vec<u32>,
    /// `cell_start[c] .. cell_start[c + 1]` are cell `c`'s samples.
    pub cell_start: Vec<u32>,
}

impl Points {
    /// Bins the samples at `positions` (with `k` values each, weights and times, any of
    /// them may be empty) into `grid`'s cells, keeping the input order within a cell.
    pub fn binned(
        grid: &CellGrid,
        positions: &[[f32; 3]],
        values: &[f32],
        weights: &[f32],
        times: &[f32],
        k: usize,
    ) -> Points {
        let cells: Vec<usize> = positions.iter().map(|&p| grid.cell_of(p)).collect();
        let mut start = vec![0u32; grid.len() + 1];
        for &c in &cells {
            start[c + 1] += 1;
        }
        for c in 0..grid.len() {
            start[c + 1] += start[c];
        }
        let mut next = start.clone();
        let mut order = vec![0u32; positions.len()];
        for (i, &c) in cells.iter().enumerate() {
            order[next[c] as usize] = i as u32;
            next[c] += 1;
        }
        let has_values = !values.is_empty();
        Points {
            positions: order.iter().map(|&i| positions[i as usize]).collect(),
            values: if has_values {
                order
                    .iter()
                    .flat_map(|&i| &values[i as usize * k..(i as usize + 1) * k])
                    .copied()
                    .collect()
            } else {
                Vec::new()
            },
            weights: if weights.is_empty() {
                Vec::new()
            } else {
                order.iter().map(|&i| weights[i as usize]).collect()
            },
            times: if times.is_empty() {
                Vec::new()
            } else {
                order.iter().map(|&i| times[i as usize]).collect()
            },
            order,
            cell_start: start,
        }
    }
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    /// True without samples.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// One Gaussian, ready to evaluate: `v = m (x - mu)` gives `d2 = |v|^2`.
#[derive(Clone, Copy, Debug)]
struct Prepared {
    mu: [f32; 3],
    m: [[f32; 3]; 3],
    opacity: f32,
    lo: [usize; 3],
    hi: [usize; 3],
    /// The temporal mean and the inverse temporal scale (time-varying models).
    time: Option<(f32, f32)>,
}

fn prepare(model: &Model, i: usize, kernel: SplatKernel, grid: &CellGrid) -> Prepared {
    let g = model.gaussian(i);
    let mu = [g[0], g[1], g[2]];
    let s = [g[SCALE].exp(), g[SCALE + 1].exp(), g[SCALE + 2].exp()];
    let q = &g[ROT..ROT + 4];
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let r = rotation([q[0] / n, q[1] / n, q[2] / n, q[3] / n]);
    // m = S^-1 R^T: row j is column j of R over s_j.
    let m = [0, 1, 2].map(|j| [r[0][j] / s[j], r[1][j] / s[j], r[2][j] / s[j]]);
    // Support box: half extent along world axis a is sqrt(cutoff * Sigma_aa).
    let c = cutoff(kernel);
    let half = [0, 1, 2].map(|a| {
        let var: f32 = (0..3).map(|j| r[a][j] * r[a][j] * s[j] * s[j]).sum();
        (c * var).sqrt()
    });
    let (lo, hi) = grid.range(
        [0, 1, 2].map(|a| mu[a] - half[a]),
        [0, 1, 2].map(|a| mu[a] + half[a]),
    );
    let time = model.time.then(|| {
        let t = model.time_offset();
        // The inverse scale as crate::core::scene::temporal_weight computes it, so both give the
        // same bits.
        (g[t], (-g[t + 1]).exp())
    });
    Prepared {
        mu,
        m,
        opacity: sigmoid(g[LOGIT]),
        lo,
        hi,
        time,
    }
}

/// One sample within a Gaussian's support, as [`visit`] hands it over.
#[derive(Clone, Copy)]
struct Hit {
    /// The sample's index in `points`.
    n: usize,
    /// `x - mu`.
    d: [f32; 3],
    /// `m (x - mu)`.
    v: [f32; 3],
    /// `|v|^2`.
    d2: f32,
    /// The temporal factor (1 for a static model).
    tw: f32,
    /// `(t - tau) / s_t` (0 for a static model).
    u: f32,
}

/// Calls `f` for every sample of `points` within the support of `p` (in space and, for a
/// time-varying model, in time: [`crate::core::scene::TEMPORAL_CUTOFF`]).
#[inline]
fn visit(p: &Prepared, grid: &CellGrid, points: &Points, cut: f32, mut f: impl FnMut(Hit)) {
    for ix in p.lo[0]..=p.hi[0] {
        for iy in p.lo[1]..=p.hi[1] {
            let column = (ix * grid.dims[1] + iy) * grid.dims[2];
            let a = points.cell_start[column + p.lo[2]] as usize;
            let b = points.cell_start[column + p.hi[2] + 1] as usize;
            for n in a..b {
                let x = points.positions[n];
                let d = [x[0] - p.mu[0], x[1] - p.mu[1], x[2] - p.mu[2]];
                let v = [0, 1, 2].map(|j| p.m[j][0] * d[0] + p.m[j][1] * d[1] + p.m[j][2] * d[2]);
                let d2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                if d2 > cut {
                    continue;
                }
                let (tw, u) = match p.time {
                    None => (1.0, 0.0),
                    Some((tau, inv_s)) => {
                        // crate::core::scene::temporal_weight, with u kept for the gradient.
                        let u = (points.times[n] - tau) * inv_s;
                        let u2 = u * u;
                        if u2 > crate::core::scene::TEMPORAL_CUTOFF {
                            continue;
                        }
                        ((-0.5 * u2).exp(), u)
                    }
                };
                f(Hit { n, d, v, d2, tw, u });
            }
        }
    }
}

/// The model's field at every sample of `points` (`k` values each, in `points`' order).
pub fn forward(model: &Model, kernel: SplatKernel, grid: &CellGrid, points: &Points) -> Vec<f32> {
    let k = model.k;
    let g_count = model.len();
    let cut = cutoff(kernel);
    let partials: Vec<Vec<f32>> = (0..FORWARD_CHUNKS)
        .into_par_iter()
        .map(|c| {
            let mut acc = vec![0f32; points.len() * k];
            let (a, b) = (
                c * g_count / FORWARD_CHUNKS,
                (c + 1) * g_count / FORWARD_CHUNKS,
            );
            for i in a..b {
                let p = prepare(model, i, kernel, grid);
                let feat = model.features(i);
                visit(&p, grid, points, cut, |h| {
                    let w = p.opacity * kernel_value(kernel, h.d2).0 * h.tw;
                    let n = h.n;
                    for (o, f) in acc[n * k..(n + 1) * k].iter_mut().zip(feat) {
                        *o += w * f;
                    }
                });
            }
            acc
        })
        .collect();
    let mut out = vec![0f32; points.len() * k];
    out.par_chunks_mut(4096).enumerate().for_each(|(j, chunk)| {
        let base = j * 4096;
        let len = chunk.len();
        for part in &partials {
            for (o, v) in chunk.iter_mut().zip(&part[base..base + len]) {
                *o += v;
            }
        }
    });
    out
}

/// The loss's settings besides the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossConfig {
    /// The falloff.
    pub kernel: SplatKernel,
    /// Weight of the scale regulariser.
    pub scale_reg: f32,
    /// The length scales are measured in by the regulariser (the data's diagonal).
    pub reg_length: f32,
}

/// The loss, its gradient and each Gaussian's residual score.
#[derive(Clone, Debug)]
pub struct LossGrad {
    /// The data term: `sum_n w_n |f(x_n) - y_n|^2 / (K sum_n w_n)`.
    pub data: f64,
    /// The scale regulariser: `scale_reg / G * sum_i sum_j (s_ij / reg_length)^2`.
    pub reg: f64,
    /// d loss / d params, the model's layout.
    pub grad: Vec<f32>,
    /// Per Gaussian: `sum_n G_i(x_n) w_n |f(x_n) - y_n|^2`, where the fit is poor.
    pub score: Vec<f32>,
}

impl LossGrad {
    /// Data term plus regulariser.
    pub fn total(&self) -> f64 {
        self.data + self.reg
    }
}

/// The data term alone for the fitted values `f` against `points` (cheap; no gradient).
pub fn data_loss(f: &[f32], points: &Points, k: usize) -> f64 {
    let sum_w: f64 = points.weights.iter().map(|&w| f64::from(w)).sum();
    let mut total = 0f64;
    for (n, w) in points.weights.iter().enumerate() {
        let r2: f64 = (0..k)
            .map(|c| f64::from(f[n * k + c] - points.values[n * k + c]).powi(2))
            .sum();
        total += f64::from(*w) * r2;
    }
    total / (k as f64 * sum_w.max(1e-30))
}

/// The scale regulariser, its gradient added into `grad` when given.
pub fn regulariser(model: &Model, cfg: &LossConfig, grad: Option<&mut [f32]>) -> f64 {
    if model.is_empty() || cfg.scale_reg == 0.0 {
        return 0.0;
    }
    let per = f64::from(cfg.scale_reg) / model.len() as f64;
    let l2 = f64::from(cfg.reg_length).powi(2);
    let mut total = 0f64;
    let stride = model.stride();
    let mut grad = grad;
    for i in 0..model.len() {
        for j in 0..3 {
            let s2 = f64::from(model.params[i * stride + SCALE + j])
                .exp()
                .powi(2)
                / l2;
            total += per * s2;
            if let Some(g) = grad.as_deref_mut() {
                g[i * stride + SCALE + j] += (per * 2.0 * s2) as f32;
            }
        }
    }
    total
}

/// The loss on `points` (which must have values and weights) and its analytic gradient.
pub fn loss_and_grad(
    model: &Model,
    cfg: &LossConfig,
    grid: &CellGrid,
    points: &Points,
) -> LossGrad {
    let k = model.k;
    let f = forward(model, cfg.kernel, grid, points);
    let sum_w: f64 = points.weights.iter().map(|&w| f64::from(w)).sum();
    let norm = 1.0 / (k as f64 * sum_w.max(1e-30));
    // e_n = d data / d f_n = 2 w_n r_n / (K sum w); energy_n = w_n |r_n|^2.
    let mut e = vec![0f32; f.len()];
    let mut energy = vec![0f32; points.len()];
    let mut data = 0f64;
    for n in 0..points.len() {
        let w = f64::from(points.weights[n]);
        let mut r2 = 0f64;
        for c in 0..k {
            let r = f64::from(f[n * k + c]) - f64::from(points.values[n * k + c]);
            r2 += r * r;
            e[n * k + c] = (2.0 * w * r * norm) as f32;
        }
        energy[n] = (w * r2) as f32;
        data += w * r2;
    }
    data *= norm;
    let stride = model.stride();
    let mut grad = vec![0f32; model.params.len()];
    let mut score = vec![0f32; model.len()];
    let cut = cutoff(cfg.kernel);
    grad.par_chunks_mut(stride)
        .zip(score.par_iter_mut())
        .enumerate()
        .for_each(|(i, (gi, score_i))| {
            let p = prepare(model, i, cfg.kernel, grid);
            let params = model.gaussian(i);
            let feat = model.features(i);
            let o = p.opacity;
            let mut g_feat = vec![0f64; k];
            let mut g_a = 0f64; // d loss / d opacity
            let mut sv = [0f64; 3];
            let mut sv2 = [0f64; 3];
            let mut a_mat = [[0f64; 3]; 3];
            let mut sc = 0f64;
            // d loss / d tau and d loss / d log s_t.
            let (mut g_tau, mut g_log_st) = (0f64, 0f64);
            let inv_st = p.time.map_or(0.0, |t| f64::from(t.1));
            visit(&p, grid, points, cut, |h| {
                let Hit { n, d, v, d2, tw, u } = h;
                let (g, dg) = kernel_value(cfg.kernel, d2);
                let en = &e[n * k..(n + 1) * k];
                let mut ea = 0f32;
                for c in 0..k {
                    ea += en[c] * feat[c];
                    g_feat[c] += f64::from(en[c] * o * g * tw);
                }
                g_a += f64::from(ea * g * tw);
                // T = exp(-u^2 / 2): dT / dtau = T u / s_t, dT / dlog s_t = T u^2.
                let d_tw = f64::from(ea * o * g * tw);
                g_tau += d_tw * f64::from(u) * inv_st;
                g_log_st += d_tw * f64::from(u * u);
                let dd2 = f64::from(ea * o * dg * tw);
                for j in 0..3 {
                    let vj = f64::from(v[j]);
                    sv[j] += dd2 * vj;
                    sv2[j] += dd2 * vj * vj;
                    for (row, &dk) in a_mat.iter_mut().zip(&d) {
                        row[j] += dd2 * f64::from(dk) * vj;
                    }
                }
                sc += f64::from(g * tw * energy[n]);
            });
            *score_i = sc as f32;
            // Position: d d2 / d mu = -2 m^T v.
            for (a, out) in gi[..3].iter_mut().enumerate() {
                *out = (-2.0 * (0..3).map(|j| f64::from(p.m[j][a]) * sv[j]).sum::<f64>()) as f32;
            }
            // Log scales: d d2 / d log s_j = -2 v_j^2.
            for j in 0..3 {
                gi[SCALE + j] = (-2.0 * sv2[j]) as f32;
            }
            // Rotation: d d2 / d R_aj = 2 d_a v_j / s_j.
            let s = [0, 1, 2].map(|j| f64::from(params[SCALE + j]).exp());
            let mut g_r = [[0f64; 3]; 3];
            for a in 0..3 {
                for j in 0..3 {
                    g_r[a][j] = 2.0 * a_mat[a][j] / s[j];
                }
            }
            let q: Vec<f64> = params[ROT..ROT + 4].iter().map(|&v| f64::from(v)).collect();
            let gq = quaternion_grad(&q, &g_r);
            for c in 0..4 {
                gi[ROT + c] = gq[c] as f32;
            }
            gi[LOGIT] = (g_a * f64::from(o) * (1.0 - f64::from(o))) as f32;
            for c in 0..k {
                gi[FEAT + c] = g_feat[c] as f32;
            }
            if model.time {
                gi[FEAT + k] = g_tau as f32;
                gi[FEAT + k + 1] = g_log_st as f32;
            }
        });
    let reg = regulariser(model, cfg, Some(&mut grad));
    LossGrad {
        data,
        reg,
        grad,
        score,
    }
}

/// The loss alone (data term plus regulariser), for checks.
pub fn loss(model: &Model, cfg: &LossConfig, grid: &CellGrid, points: &Points) -> f64 {
    let f = forward(model, cfg.kernel, grid, points);
    data_loss(&f, points, model.k) + regulariser(model, cfg, None)
}

/// d loss / d q for an unnormalised quaternion `q`, from `g_r = d loss / d R` of the
/// rotation of `q / |q|`.
fn quaternion_grad(q: &[f64], g_r: &[[f64; 3]; 3]) -> [f64; 4] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
    let g = g_r;
    let gw =
        2.0 * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]);
    let gx = 2.0
        * (y * g[0][1] + z * g[0][2] + y * g[1][0] - 2.0 * x * g[1][1] - w * g[1][2]
            + z * g[2][0]
            + w * g[2][1]
            - 2.0 * x * g[2][2]);
    let gy = 2.0
        * (-2.0 * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2]
            - w * g[2][0]
            + z * g[2][1]
            - 2.0 * y * g[2][2]);
    let gz = 2.0
        * (-2.0 * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - 2.0 * z * g[1][1]
            + y * g[1][2]
            + x * g[2][0]
            + y * g[2][1]);
    // Through the normalisation: (I - qn qn^T) / |q|.
    let gn = [gw, gx, gy, gz];
    let qn = [w, x, y, z];
    let dot: f64 = (0..4).map(|c| gn[c] * qn[c]).sum();
    [0, 1, 2, 3].map(|c| (gn[c] - qn[c] * dot) / n)
}

/// The field of a static model at arbitrary `positions` (input order), `k` values each
/// (a time-varying model: [`evaluate_at`]).
pub fn evaluate(model: &Model, kernel: SplatKernel, positions: &[[f32; 3]]) -> Vec<f32> {
    evaluate_points(model, kernel, positions, &[])
}

/// The field at `positions` at `times` (one per position; none for a static model): `k`
/// values each, in input order. Refuses times for a static model, none (or a count other
/// than the positions') for a time-varying one, and non-finite times.
pub fn evaluate_at(
    model: &Model,
    kernel: SplatKernel,
    positions: &[[f32; 3]],
    times: Option<&[f32]>,
) -> Result<Vec<f32>, String> {
    match (model.time, times) {
        (false, None) => Ok(evaluate_points(model, kernel, positions, &[])),
        (false, Some(_)) => Err(
            "the field is static (its Gaussians have no t_mean, t_scale); evaluate it without a time"
                .into(),
        ),
        (true, None) => Err(
            "the field is time-varying (t_mean, t_scale per Gaussian); give the time of the points"
                .into(),
        ),
        (true, Some(t)) => {
            if t.len() != positions.len() {
                return Err(format!(
                    "{} times for {} points; give one time per point",
                    t.len(),
                    positions.len()
                ));
            }
            if let Some(i) = t.iter().position(|v| !v.is_finite()) {
                return Err(format!("time {i} is {}, not a finite number", t[i]));
            }
            Ok(evaluate_points(model, kernel, positions, t))
        }
    }
}

/// The field at `positions` (at `times`, one each, for a time-varying model; a
/// time-varying model without them is taken at its Gaussians' temporal means: weight 1).
fn evaluate_points(
    model: &Model,
    kernel: SplatKernel,
    positions: &[[f32; 3]],
    times: &[f32],
) -> Vec<f32> {
    if positions.is_empty() {
        return Vec::new();
    }
    let grid = CellGrid::new(point_bounds(positions), positions.len(), 8.0);
    let static_model;
    let model = if model.time && times.len() != positions.len() {
        static_model = model.without_time();
        &static_model
    } else {
        model
    };
    let times = if model.time { times } else { &[] };
    let points = Points::binned(&grid, positions, &[], &[], times, model.k);
    let f = forward(model, kernel, &grid, &points);
    let k = model.k;
    let mut out = vec![0f32; f.len()];
    for (n, &orig) in points.order.iter().enumerate() {
        out[orig as usize * k..(orig as usize + 1) * k].copy_from_slice(&f[n * k..(n + 1) * k]);
    }
    out
}
