//! How one frame's (bin, Gaussian) pairs fall ([`PairStats`]): counted on the host from the
//! frame's sorted lists, independently of the test that emitted them. `drawing` is the
//! check that only pairs that can draw are sorted: a pair draws when some pixel centre of
//! its bin gets alpha >= 1/255 from the Gaussian under the frame's kernel and rules (the
//! per-pixel evaluation of the blend, before any early stop), so `pairs / drawing` is the
//! work spent on pairs that cannot change a pixel.

use crate::core::camera::Camera;
use crate::core::model::{Rules, SplatKernel};
use crate::cpu::{self, Projected};
use rayon::prelude::*;
use serde::Serialize;

/// Pair statistics of one frame ([`super::BenchReport::pair_stats`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PairStats {
    /// Side in pixels of the bins pairs are keyed by (16: the reference's tiles).
    pub bin_size: u32,
    /// Bins of the frame (each with its own sorted list).
    pub bins: u64,
    /// Pairs per Gaussian that touches at least one bin.
    pub per_visible: f64,
    /// The longest list of one bin.
    pub per_bin_max: u64,
    /// The 99th percentile (nearest rank) of the bins' list lengths, empty bins included.
    pub per_bin_p99: u64,
    /// Pairs of which some pixel centre of the bin gets alpha >= 1/255.
    pub drawing: u64,
}

/// The bins' sorted lists of one frame, as the blend reads them.
pub struct BinLists<'a> {
    /// Side of a bin in pixels.
    pub size: u32,
    /// Bins along x.
    pub bins_x: u32,
    /// `[start, end)` into `values` per bin, row-major.
    pub ranges: &'a [[u32; 2]],
    /// Gaussian indices, each bin's in blend order.
    pub values: &'a [u32],
}

/// Counts [`PairStats`] of a frame whose lists are `lists` and whose `visible` Gaussians
/// touch at least one bin.
pub fn pair_stats(
    projected: &[Projected],
    cam: &Camera,
    kernel: SplatKernel,
    rules: Rules,
    lists: &BinLists,
    visible: u64,
) -> PairStats {
    let mut lengths: Vec<u64> = lists.ranges.iter().map(|[a, b]| u64::from(b - a)).collect();
    let pairs: u64 = lengths.iter().sum();
    let drawing = (0..lists.ranges.len())
        .into_par_iter()
        .map(|bin| {
            let [a, b] = lists.ranges[bin];
            let ids = &lists.values[a as usize..b as usize];
            let bin = bin as u32;
            let (bx, by) = (bin % lists.bins_x, bin / lists.bins_x);
            ids.iter()
                .filter(|&&id| {
                    let mut g = projected[id as usize];
                    if cam.lens.wraps() {
                        // The copy the blend draws in this bin's 16-pixel tile.
                        let x0 = bx * lists.size / cpu::TILE_SIZE * cpu::TILE_SIZE;
                        g = cpu::wrapped_copy(g, x0, cam.width);
                    }
                    draws_in(&g, [bx, by], lists.size, cam, kernel, rules)
                })
                .count() as u64
        })
        .sum();
    lengths.sort_unstable();
    let p99 = lengths
        .get(((lengths.len().saturating_sub(1)) as f64 * 0.99).round() as usize)
        .copied()
        .unwrap_or(0);
    PairStats {
        bin_size: lists.size,
        bins: lists.ranges.len() as u64,
        per_visible: pairs as f64 / visible.max(1) as f64,
        per_bin_max: lengths.last().copied().unwrap_or(0),
        per_bin_p99: p99,
        drawing,
    }
}

/// Whether some pixel centre of bin `bin` (of side `size`, within the image) gets an alpha
/// of at least 1/255 from `g`: the blend's own per-pair test ([`cpu::pixel_alpha`]).
fn draws_in(
    g: &Projected,
    bin: [u32; 2],
    size: u32,
    cam: &Camera,
    kernel: SplatKernel,
    rules: Rules,
) -> bool {
    let ys = bin[1] * size..((bin[1] + 1) * size).min(cam.height);
    ys.into_iter().any(|y| {
        (bin[0] * size..((bin[0] + 1) * size).min(cam.width))
            .any(|x| cpu::pixel_alpha(g, x as f32, y as f32, kernel, rules.alpha_max()).is_some())
    })
}
