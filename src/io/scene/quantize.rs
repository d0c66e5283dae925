//! The quantisers the SOG and compressed-PLY writers share: the Morton order both write
//! their Gaussians in, the 256-entry 1-D codebooks of SOG, and SOG's SH palette.
//!
//! Everything here is deterministic: no random seeds, ties broken by index, and parallel
//! work only where each result is computed by one thread in a fixed order, so the same
//! scene gives the same bytes on any machine and thread count.

use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// The order the writers store the Gaussians in: by the 63-bit Morton code of their
/// centres (21 bits per axis over the scene's bounding box), ties by index. Neighbours
/// in space end up neighbours in the file, which keeps a compressed PLY's 256-Gaussian
/// chunks small (its positions are quantised within each chunk's box) and a SOG's
/// textures smooth (so WebP compresses them). Non-finite coordinates sort as the box's
/// low corner.
pub fn morton_order(positions: &[[f32; 3]]) -> Vec<usize> {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in positions {
        for a in 0..3 {
            if p[a].is_finite() {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
    }
    let max = ((1u32 << 21) - 1) as f64;
    let cell = |v: f32, a: usize| -> u64 {
        let extent = f64::from(hi[a]) - f64::from(lo[a]);
        if !v.is_finite() || extent <= 0.0 || !extent.is_finite() {
            return 0;
        }
        ((f64::from(v) - f64::from(lo[a])) / extent * max)
            .round()
            .clamp(0.0, max) as u64
    };
    let mut keys: Vec<(u64, usize)> = positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let (x, y, z) = (cell(p[0], 0), cell(p[1], 1), cell(p[2], 2));
            (spread3(x) << 2 | spread3(y) << 1 | spread3(z), i)
        })
        .collect();
    keys.par_sort_unstable();
    keys.into_iter().map(|(_, i)| i).collect()
}

/// The 21 low bits of `v` spread to every third bit.
fn spread3(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f00000000ffff;
    x = (x | x << 16) & 0x1f0000ff0000ff;
    x = (x | x << 8) & 0x100f00f00f00f00f;
    x = (x | x << 4) & 0x10c30c30c30c30c3;
    x = (x | x << 2) & 0x1249249249249249;
    x
}

/// Bins of the histogram the 1-D codebooks are fitted to, uniform over the values' range.
const CODEBOOK_BINS: usize = 16_384;
/// Lloyd iterations of the 1-D codebooks (they stop earlier once nothing moves).
const CODEBOOK_ITERATIONS: usize = 500;

/// A 256-entry codebook for `values` (SOG's `scales`, `sh0` and `shN` codebooks),
/// ascending: 1-D k-means over the occupied bins of a histogram of the values (16,384
/// bins over their range, each bin at its values' mean), every occupied bin weighing the
/// same whatever its count, so the entries spread over the whole range the values
/// occupy and sparse tails (the largest splats) get entries of their own. Started from
/// quantiles of the bins; Lloyd's iterations until nothing moves. Non-finite values are
/// left out; with 256 distinct values or fewer, the codebook is those values (the last
/// repeated).
///
/// The weighting was measured on the plant scene's log scales (BENCHMARKS.md,
/// "Quantisation of the SOG and compressed-PLY writers"): renders of the SOG were 73 to
/// 75 dB from the source with equal bins, 66 to 70 dB with splat-transform's square root
/// of the count, 63 to 67 dB with the count (plain k-means) and 58 to 61 dB with plain
/// quantiles.
pub fn codebook_1d(values: &[f32]) -> Vec<f32> {
    let mut sorted: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.par_sort_unstable_by(f32::total_cmp);
    if sorted.is_empty() {
        return vec![0.0; 256];
    }
    let mut distinct = sorted.clone();
    distinct.dedup();
    if distinct.len() <= 256 {
        let last = *distinct.last().expect("not empty");
        distinct.resize(256, last);
        return distinct;
    }
    let (lo, hi) = (f64::from(sorted[0]), f64::from(sorted[sorted.len() - 1]));
    // The means of the occupied bins, ascending.
    let mut bins: Vec<f64> = Vec::new();
    let mut start = 0;
    for b in 0..CODEBOOK_BINS {
        let edge = lo + (hi - lo) * (b + 1) as f64 / CODEBOOK_BINS as f64;
        let end = if b + 1 == CODEBOOK_BINS {
            sorted.len()
        } else {
            start + sorted[start..].partition_point(|&v| f64::from(v) < edge)
        };
        if end > start {
            let sum: f64 = sorted[start..end].iter().map(|&v| f64::from(v)).sum();
            let count = (end - start) as f64;
            bins.push(sum / count);
        }
        start = end;
    }
    // prefix[i]: the sum of the first i bins' means.
    let mut prefix = vec![0f64];
    for &m in &bins {
        prefix.push(prefix.last().expect("not empty") + m);
    }
    let mean = |a: usize, b: usize| (prefix[b] - prefix[a]) / (b - a) as f64;
    // Quantile start: centre j at bin (j + 0.5) / 256 of the way through the bins.
    let mut centres: Vec<f64> = (0..256)
        .map(|j| bins[((j * 2 + 1) * bins.len() / 512).min(bins.len() - 1)])
        .collect();
    for _ in 0..CODEBOOK_ITERATIONS {
        let mut next = centres.clone();
        let mut start = 0;
        for j in 0..256 {
            let end = if j == 255 {
                bins.len()
            } else {
                let mid = (centres[j] + centres[j + 1]) * 0.5;
                start + bins[start..].partition_point(|&b| b < mid)
            };
            if end > start {
                next[j] = mean(start, end);
            }
            start = end;
        }
        if next == centres {
            break;
        }
        centres = next;
    }
    let mut book: Vec<f32> = centres.iter().map(|&c| c as f32).collect();
    book.sort_by(f32::total_cmp);
    book
}

/// The index of the codebook entry nearest `v` (`book` ascending, at most 256 entries);
/// below the first entry (or NaN) the first, above the last the last.
pub fn nearest_index(book: &[f32], v: f32) -> u8 {
    // Entry i is chosen for v in [midpoint(i-1, i), midpoint(i, i+1)).
    let mut lo = 0usize;
    let mut hi = book.len() - 1;
    while lo < hi {
        let mid = (lo + hi) / 2;
        if v < (book[mid] + book[mid + 1]) * 0.5 {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo as u8
}

/// The SH palette size for `n` Gaussians, as splat-transform chooses it: the largest
/// power of two at most `n`, and at most 65,536 (1 for an empty scene).
pub fn palette_size(n: usize) -> usize {
    if n <= 1 {
        1
    } else {
        (1usize << (usize::BITS - 1 - n.leading_zeros())).min(65_536)
    }
}

/// A set of points of the palette's clustering: row `i` of `points` is `dim` floats.
struct Points<'a> {
    data: &'a [f32],
    dim: usize,
}

impl Points<'_> {
    fn row(&self, i: u32) -> &[f32] {
        let i = i as usize;
        &self.data[i * self.dim..(i + 1) * self.dim]
    }

    /// Mean and sum of squared distances to it of the points `members`, in f64.
    fn stats(&self, members: &[u32]) -> (Vec<f64>, f64) {
        let mut sum = vec![0f64; self.dim];
        let mut sq = 0f64;
        for &m in members {
            for (s, &v) in sum.iter_mut().zip(self.row(m)) {
                let v = f64::from(v);
                *s += v;
                sq += v * v;
            }
        }
        let inv = 1.0 / members.len().max(1) as f64;
        let mean: Vec<f64> = sum.iter().map(|s| s * inv).collect();
        let sse = sq - mean.iter().map(|m| m * m).sum::<f64>() * members.len() as f64;
        (mean, sse.max(0.0))
    }
}

/// A cluster of the palette's divisive clustering, ordered by its squared error for the
/// heap (ties: the earlier cluster first).
struct Cluster {
    sse: f64,
    id: usize,
    members: Vec<u32>,
}

impl PartialEq for Cluster {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Cluster {}
impl PartialOrd for Cluster {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Cluster {
    fn cmp(&self, other: &Self) -> Ordering {
        self.sse
            .total_cmp(&other.sse)
            .then_with(|| other.id.cmp(&self.id))
    }
}

/// Splits `members` in two across the axis of largest variance at its mean (at the median
/// when the mean leaves one side empty). `None`: all members are the same point.
fn split(points: &Points<'_>, members: &[u32], mean: &[f64]) -> Option<(Vec<u32>, Vec<u32>)> {
    let mut var = vec![0f64; points.dim];
    for &m in members {
        for ((v, &x), &mu) in var.iter_mut().zip(points.row(m)).zip(mean) {
            let d = f64::from(x) - mu;
            *v += d * d;
        }
    }
    let (axis, &largest) = var
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))?;
    if largest <= 0.0 {
        return None;
    }
    let value = |m: u32| points.row(m)[axis];
    let (left, right): (Vec<u32>, Vec<u32>) = members
        .iter()
        .partition(|&&m| f64::from(value(m)) <= mean[axis]);
    if !left.is_empty() && !right.is_empty() {
        return Some((left, right));
    }
    let mut sorted = members.to_vec();
    sorted.sort_by(|&a, &b| value(a).total_cmp(&value(b)).then(a.cmp(&b)));
    let right = sorted.split_off(sorted.len() / 2);
    Some((sorted, right))
}

/// Lloyd refinements of the palette after its divisive start.
const PALETTE_ITERATIONS: usize = 2;

/// SOG's SH palette: `k` centroids of the `n` points of `dim` floats in `points` and each
/// point's centroid. Divisive k-means: starting from one cluster, the cluster of largest
/// squared error is split in two (across its axis of largest variance, at the mean)
/// until there are `k`; then Lloyd's iterations refine the centroids, each point choosing
/// among the centroids of its own cluster's neighbours in the split tree (the clusters
/// descended from the same node three levels up), which keeps an iteration linear in the
/// points. Fewer than `k` distinct points give fewer clusters; the palette is padded to
/// `k` with the last centroid.
pub fn sh_palette(points: &[f32], dim: usize, k: usize) -> (Vec<f32>, Vec<u32>) {
    let n = points.len() / dim.max(1);
    let pts = Points { data: points, dim };
    if n == 0 {
        return (vec![0.0; k * dim], Vec::new());
    }
    // Divisive start over a binary tree of nodes: node 0 holds every point, and splitting
    // node `c` makes two new nodes whose `parent` is `c`; the clusters are the leaves.
    let all: Vec<u32> = (0..n as u32).collect();
    let (_, sse) = pts.stats(&all);
    let mut heap = BinaryHeap::new();
    heap.push(Cluster {
        sse,
        id: 0,
        members: all,
    });
    let mut done: Vec<Cluster> = Vec::new();
    let mut parent: Vec<usize> = vec![0];
    while heap.len() + done.len() < k {
        let Some(c) = heap.pop() else { break };
        let (mean, _) = pts.stats(&c.members);
        match split(&pts, &c.members, &mean) {
            None => done.push(Cluster { sse: 0.0, ..c }),
            Some((left, right)) => {
                for members in [left, right] {
                    let (_, sse) = pts.stats(&members);
                    heap.push(Cluster {
                        sse,
                        id: parent.len(),
                        members,
                    });
                    parent.push(c.id);
                }
            }
        }
    }
    let mut clusters: Vec<Cluster> = heap.into_vec();
    clusters.append(&mut done);
    clusters.sort_by_key(|c| c.id);
    let count = clusters.len();
    let mut labels = vec![0u32; n];
    for (slot, c) in clusters.iter().enumerate() {
        for &m in &c.members {
            labels[m as usize] = slot as u32;
        }
    }
    let mut centroids: Vec<f32> = clusters
        .iter()
        .flat_map(|c| pts.stats(&c.members).0.into_iter().map(|v| v as f32))
        .collect();
    // Neighbourhoods: the leaves sharing the ancestor three levels up (the root's leaves
    // within three levels share the root).
    let up3 = |id: usize| parent[parent[parent[id]]];
    let mut groups: std::collections::BTreeMap<usize, Vec<u32>> = Default::default();
    for (slot, c) in clusters.iter().enumerate() {
        groups.entry(up3(c.id)).or_default().push(slot as u32);
    }
    let neighbours: Vec<&Vec<u32>> = clusters.iter().map(|c| &groups[&up3(c.id)]).collect();
    for _ in 0..PALETTE_ITERATIONS {
        labels = (0..n)
            .into_par_iter()
            .map(|i| {
                let p = pts.row(i as u32);
                let mut best = (f32::INFINITY, labels[i]);
                for &c in neighbours[labels[i] as usize] {
                    let row = &centroids[c as usize * dim..(c as usize + 1) * dim];
                    let d: f32 = row.iter().zip(p).map(|(a, b)| (a - b) * (a - b)).sum();
                    if d < best.0 || (d == best.0 && c < best.1) {
                        best = (d, c);
                    }
                }
                best.1
            })
            .collect();
        let mut sums = vec![0f64; count * dim];
        let mut counts = vec![0usize; count];
        for (i, &label) in labels.iter().enumerate() {
            let c = label as usize;
            counts[c] += 1;
            for (s, &v) in sums[c * dim..(c + 1) * dim]
                .iter_mut()
                .zip(pts.row(i as u32))
            {
                *s += f64::from(v);
            }
        }
        for c in 0..count {
            if counts[c] > 0 {
                for j in 0..dim {
                    centroids[c * dim + j] = (sums[c * dim + j] / counts[c] as f64) as f32;
                }
            }
        }
    }
    let last = centroids[(count - 1) * dim..count * dim].to_vec();
    while centroids.len() < k * dim {
        centroids.extend_from_slice(&last);
    }
    (centroids, labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_order_groups_neighbours() {
        // Two clumps far apart, interleaved in the input: the order keeps each together.
        let p: Vec<[f32; 3]> = (0..8)
            .map(|i| {
                let off = if i % 2 == 0 { 0.0 } else { 100.0 };
                [off + i as f32 * 0.01, off, off]
            })
            .collect();
        let order = morton_order(&p);
        let first: Vec<bool> = order.iter().map(|&i| i % 2 == 0).collect();
        assert_eq!(first, [true, true, true, true, false, false, false, false]);
    }

    #[test]
    fn codebook_is_exact_for_few_values_and_close_for_many() {
        let few = [1.0f32, -2.0, 3.0, 1.0];
        let book = codebook_1d(&few);
        assert_eq!(&book[..3], &[-2.0, 1.0, 3.0]);
        for v in few {
            assert_eq!(book[nearest_index(&book, v) as usize], v);
        }
        // 10,000 values in [0, 1): 256 entries leave at most about half of 1/256.
        let many: Vec<f32> = (0..10_000).map(|i| (i as f32 * 0.618034).fract()).collect();
        let book = codebook_1d(&many);
        let worst = many
            .iter()
            .map(|&v| (book[nearest_index(&book, v) as usize] - v).abs())
            .fold(0f32, f32::max);
        assert!(worst < 1.5 / 256.0, "{worst}");
    }

    #[test]
    fn palette_sizes_follow_splat_transform() {
        assert_eq!(palette_size(1), 1);
        assert_eq!(palette_size(1873), 1024);
        assert_eq!(palette_size(31_000), 16_384);
        assert_eq!(palette_size(125_000), 65_536);
        assert_eq!(palette_size(1_000_000), 65_536);
    }

    #[test]
    fn palette_clusters_separated_points_exactly() {
        // Four well-separated blobs of 2-D points, four centroids: each blob one label.
        let mut pts = Vec::new();
        for b in 0..4 {
            for j in 0..10 {
                pts.push(b as f32 * 10.0 + j as f32 * 0.01);
                pts.push(-(b as f32) * 10.0);
            }
        }
        let (centroids, labels) = sh_palette(&pts, 2, 4);
        assert_eq!(centroids.len(), 8);
        for b in 0..4 {
            let l = &labels[b * 10..b * 10 + 10];
            assert!(l.iter().all(|&x| x == l[0]), "{labels:?}");
            let c = &centroids[l[0] as usize * 2..l[0] as usize * 2 + 2];
            assert!((c[0] - (b as f32 * 10.0 + 0.045)).abs() < 1e-4, "{c:?}");
        }
    }
}
