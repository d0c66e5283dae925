//! The f64 reference's projection through a lens other than the pinhole, and its
//! derivative: the unscented transform of [`crate::core::model::unscented`] (the same
//! function the f32 CPU renderer projects with), differentiated through its sigma points.
//!
//! Forward: the camera-space mean `v` and scaled axes `A = W R S` give the sigma points
//! `p_0 = v`, `p_(2i+1) = v + s A_i`, `p_(2i+2) = v - s A_i` (`s` the spread), their pixels
//! `u_j = f(p_j)` through the lens's exact map, the mean `mu = sum_j wm_j u_j` and the
//! covariance `C = sum_j wc_j e_j e_j^T` with `e_j = u_j - mu` (the mean weights sum to one,
//! the covariance weights do not). Backward, from `dL/dmu` and `dL/dC`:
//!
//! - `dL/de_j = wc_j (dL/dC + dL/dC^T) e_j`;
//! - `dL/du_j = dL/de_j + wm_j (dL/dmu - sum_k dL/de_k)` (`mu` depends on every `u_k`);
//! - `dL/dp_j = J_j^T dL/du_j`, `J_j` the lens's Jacobian at `p_j` ([`Lens::jacobian`]);
//! - `dL/dv = sum_j dL/dp_j`, `dL/dA_i = s (dL/dp_(2i+1) - dL/dp_(2i+2))`.
//!
//! The seam of an equirectangular image moves a sigma point's pixel by whole turns, a
//! constant: its derivative is the map's own. Culling (a sigma point not imaged, every
//! one outside the margin) is a decision, constant under a small change.

use crate::core::camera::lens::{Intrinsics, Lens};
use crate::core::model::unscented::{self, UnscentedParams};
use glam::{DMat3, DVec2, DVec3};

/// The depth a lens frame sorts by and tests against the near plane: the distance from
/// the camera for the lenses that see behind their image plane (fisheye,
/// equirectangular), else the distance along the axis (as `cpu::through_lens`).
pub(super) fn depth(lens: &Lens, v: DVec3) -> f64 {
    match lens {
        Lens::Fisheye { .. } | Lens::Equirectangular { .. } => v.length(),
        _ => v.z,
    }
}

/// `d depth / d v`.
fn depth_grad(lens: &Lens, v: DVec3) -> DVec3 {
    match lens {
        Lens::Fisheye { .. } | Lens::Equirectangular { .. } => v / v.length(),
        _ => DVec3::Z,
    }
}

/// The unscented projection of the camera-space Gaussian `(v, axes)`: the pixel mean
/// (pixel `(i, j)` at `(i, j)`, as the reference's `mean2d`) and the covariance
/// `[xx, xy, yy]` before the dilation, or `None` when it is culled.
pub(super) fn project(
    lens: &Lens,
    k: &Intrinsics,
    v: DVec3,
    axes: DMat3,
) -> Option<([f64; 2], [f64; 3])> {
    let p = unscented::project(lens, k, v, axes, &UnscentedParams::default()).ok()?;
    let c = p.cov;
    Some((
        [p.mean.x - 0.5, p.mean.y - 0.5],
        [c.col(0).x, c.col(1).x, c.col(1).y],
    ))
}

/// The chain rule through [`project`] and [`depth`] of a Gaussian it did not cull:
/// from `dL/d mean2d`, `dL/d[xx, xy, yy]` (the covariance's three distinct entries,
/// before or after the dilation alike) and `dL/d depth` to `dL/dv` and `dL/d axes`, in
/// camera space.
pub(super) fn project_backward(
    lens: &Lens,
    k: &Intrinsics,
    v: DVec3,
    axes: DMat3,
    g_mean: [f64; 2],
    g_cov: [f64; 3],
    g_depth: f64,
) -> (DVec3, DMat3) {
    let params = UnscentedParams::default();
    let [spread, ..] = params.weights();
    let (points, wm, wc) = unscented::sigma_points(v, axes, &params);
    let jacobians = points.map(|p| {
        lens.jacobian(k, p)
            .expect("every sigma point of a projected Gaussian is imaged")
    });
    // The pixels relative to the centre's, on the centre's turn (as the forward).
    let (_, d) = unscented::pixel_offsets(lens, k, &points)
        .expect("every sigma point of a projected Gaussian is imaged");
    let shift: DVec2 = d.iter().zip(wm).map(|(o, w)| w * *o).sum();
    let [ga, gb, gc] = g_cov;
    // dL/de = wc (G + G^T) e with G = [[ga, gb / 2], [gb / 2, gc]] (xy counted once).
    let g_e: [DVec2; 7] = std::array::from_fn(|j| {
        let e = d[j] - shift;
        wc[j] * DVec2::new(2.0 * ga * e.x + gb * e.y, gb * e.x + 2.0 * gc * e.y)
    });
    let g_mu = DVec2::from(g_mean) - g_e.iter().sum::<DVec2>();
    let g_p: [DVec3; 7] = std::array::from_fn(|j| {
        let g_u = g_e[j] + wm[j] * g_mu;
        let jac = &jacobians[j];
        DVec3::new(jac[0].dot(g_u), jac[1].dot(g_u), jac[2].dot(g_u))
    });
    let g_v = g_p.iter().sum::<DVec3>() + g_depth * depth_grad(lens, v);
    let g_axes = DMat3::from_cols_array_2d(&std::array::from_fn(|i| {
        (spread * (g_p[1 + 2 * i] - g_p[2 + 2 * i])).to_array()
    }));
    (g_v, g_axes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::quat::quat_to_dmat3;

    const K: Intrinsics = Intrinsics {
        fx: 300.0,
        fy: 310.0,
        cx: 160.0,
        cy: 120.0,
        width: 320,
        height: 240,
    };

    /// A scalar of the projection with fixed weights on every output.
    fn loss(lens: &Lens, v: DVec3, axes: DMat3) -> f64 {
        let (m, c) = project(lens, &K, v, axes).unwrap();
        0.3 * m[0] - 0.7 * m[1] + 0.05 * c[0] - 0.08 * c[1] + 0.02 * c[2] + 1.5 * depth(lens, v)
    }

    #[test]
    fn the_chain_rule_through_the_sigma_points_matches_central_differences() {
        let q = [0.8, 0.3, -0.4, 0.2];
        let n = q.iter().map(|x: &f64| x * x).sum::<f64>().sqrt();
        let axes =
            quat_to_dmat3(q.map(|x| x / n)) * DMat3::from_diagonal(DVec3::new(0.3, 0.12, 0.05));
        let lenses = [
            Lens::RadialTangential {
                radial: [-0.12, 0.03, 0.004, 0.02, -0.01, 0.003],
                tangential: [0.002, -0.001],
            },
            Lens::Fisheye {
                k: [0.05, -0.01, 0.002, 0.0],
                max_theta: 1.7,
            },
            Lens::Orthographic,
            Lens::FULL_SPHERE,
        ];
        for lens in lenses {
            let mut points = vec![DVec3::new(0.4, -0.3, 2.5), DVec3::new(-0.5, 0.3, 1.2)];
            if let Lens::Equirectangular { .. } = lens {
                // Behind the camera, across the seam, and near the pole.
                points.extend([DVec3::new(0.02, 0.2, -2.0), DVec3::new(0.3, -3.0, 0.4)]);
            }
            for v in points {
                let (g_v, g_axes) =
                    project_backward(&lens, &K, v, axes, [0.3, -0.7], [0.05, -0.08, 0.02], 1.5);
                let h = 1e-6;
                for i in 0..3 {
                    let mut e = DVec3::ZERO;
                    e[i] = h;
                    let fd = (loss(&lens, v + e, axes) - loss(&lens, v - e, axes)) / (2.0 * h);
                    assert!(
                        (fd - g_v[i]).abs() <= 1e-6 * (1.0 + fd.abs()),
                        "{lens:?} v {i}: {fd} vs {}",
                        g_v[i]
                    );
                    for c in 0..3 {
                        let mut a = axes;
                        a.col_mut(c)[i] += h;
                        let mut b = axes;
                        b.col_mut(c)[i] -= h;
                        let fd = (loss(&lens, v, a) - loss(&lens, v, b)) / (2.0 * h);
                        let got = g_axes.col(c)[i];
                        assert!(
                            (fd - got).abs() <= 1e-6 * (1.0 + fd.abs()),
                            "{lens:?} axes[{c}][{i}]: {fd} vs {got}"
                        );
                    }
                }
            }
        }
    }
}
