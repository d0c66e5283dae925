//! The colour-corrected comparison trainers report beside plain PSNR for models whose photos
//! differ in exposure and white balance (gsplat's `cc_psnr`): the rendered image moved by
//! the affine colour transform (a 3x3 matrix and an offset) that best matches the photo in
//! least squares, then clamped to [0, 1] and measured as usual. It scores the scene's
//! geometry and relative colours, not the one photo's exposure.

/// `test` (RGB interleaved) moved by the affine colour transform fitted, by least squares
/// over the pixels `keep` keeps (every pixel when `None`), to map it onto `reference`, and
/// clamped to [0, 1]. The identity is one of the transforms fitted over, so the result is
/// never further from `reference` over the kept pixels than `test` is, for a `reference`
/// within [0, 1].
pub fn affine_color_corrected(reference: &[f32], test: &[f32], keep: Option<&[bool]>) -> Vec<f32> {
    assert_eq!(reference.len(), test.len(), "images of different sizes");
    // Normal equations of each output channel: (sum x x^T) w = sum x y, x = (r, g, b, 1).
    let mut gram = [[0f64; 4]; 4];
    let mut rhs = [[0f64; 3]; 4];
    let kept = |p: usize| keep.map_or(true, |k| k[p]);
    for (p, (t, r)) in test
        .chunks_exact(3)
        .zip(reference.chunks_exact(3))
        .enumerate()
    {
        if !kept(p) {
            continue;
        }
        let x = [f64::from(t[0]), f64::from(t[1]), f64::from(t[2]), 1.0];
        for i in 0..4 {
            for j in 0..4 {
                gram[i][j] += x[i] * x[j];
            }
            for c in 0..3 {
                rhs[i][c] += x[i] * f64::from(r[c]);
            }
        }
    }
    let Some(w) = solve4(gram, rhs) else {
        return test.to_vec();
    };
    test.chunks_exact(3)
        .flat_map(|t| {
            let x = [f64::from(t[0]), f64::from(t[1]), f64::from(t[2]), 1.0];
            (0..3).map(move |c| {
                let v: f64 = (0..4).map(|i| x[i] * w[i][c]).sum();
                v.clamp(0.0, 1.0) as f32
            })
        })
        .collect()
}

/// Solves `a w = b` for three right-hand sides by Gaussian elimination with partial
/// pivoting; `None` when `a` is singular to working precision (a flat image: the
/// transform is not determined, and the image is left as it is).
fn solve4(mut a: [[f64; 4]; 4], mut b: [[f64; 3]; 4]) -> Option<[[f64; 3]; 4]> {
    let scale = (0..4).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for col in 0..4 {
        let pivot = (col..4).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() <= scale * 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let (pivot_a, pivot_b) = (a[col], b[col]);
        for row in col + 1..4 {
            let f = a[row][col] / pivot_a[col];
            for (v, p) in a[row].iter_mut().zip(pivot_a).skip(col) {
                *v -= f * p;
            }
            for (v, p) in b[row].iter_mut().zip(pivot_b) {
                *v -= f * p;
            }
        }
    }
    let mut w = [[0f64; 3]; 4];
    for row in (0..4).rev() {
        for c in 0..3 {
            let rest: f64 = (row + 1..4).map(|k| a[row][k] * w[k][c]).sum();
            w[row][c] = (b[row][c] - rest) / a[row][row];
        }
    }
    Some(w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::metrics::psnr;

    /// A pseudo-random image in [0.1, 0.9] (a fixed LCG: no dependency).
    fn image(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..n * 3)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                0.1 + 0.8 * ((s >> 40) as f32 / (1u64 << 24) as f32)
            })
            .collect()
    }

    #[test]
    fn an_affine_colour_change_is_undone() {
        let truth = image(500, 1);
        // Exposure, white balance and a cross-talk of the channels, all within [0, 1].
        let render: Vec<f32> = truth
            .chunks_exact(3)
            .flat_map(|p| {
                [
                    0.7 * p[0] + 0.1 * p[1] + 0.05,
                    0.8 * p[1] + 0.02,
                    0.6 * p[2] + 0.1 * p[0] + 0.1,
                ]
            })
            .collect();
        assert!(psnr(&truth, &render, 1.0) < 25.0);
        let fixed = affine_color_corrected(&truth, &render, None);
        let db = psnr(&truth, &fixed, 1.0);
        assert!(db > 90.0, "{db}");
    }

    #[test]
    fn the_fit_never_scores_worse_and_uses_only_kept_pixels() {
        let truth = image(400, 2);
        let render = image(400, 3);
        let fixed = affine_color_corrected(&truth, &render, None);
        assert!(psnr(&truth, &fixed, 1.0) >= psnr(&truth, &render, 1.0));
        // Pixels outside the mask do not move the fit: a wild value there changes nothing
        // in the kept pixels' correction.
        let keep: Vec<bool> = (0..400).map(|p| p % 4 != 0).collect();
        let mut wild = truth.clone();
        wild[0..3].copy_from_slice(&[1.0, 0.0, 1.0]);
        let a = affine_color_corrected(&truth, &render, Some(&keep));
        let b = affine_color_corrected(&wild, &render, Some(&keep));
        assert_eq!(a, b);
        // A flat render has no determined transform: it is left as it is.
        let flat = vec![0.5f32; 1200];
        assert_eq!(affine_color_corrected(&truth, &flat, None), flat);
    }
}
