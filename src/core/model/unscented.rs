//! The projection of a 3D Gaussian through a lens by the unscented transform (3DGUT, Wu
//! et al. 2025): the Gaussian's seven sigma points (its mean, and the mean moved along
//! each scaled axis both ways) go through the lens's exact map
//! ([`crate::core::camera::lens::Lens::project`]), and the 2D Gaussian is the weighted
//! mean and covariance of their pixels. A pinhole camera keeps the EWA projection of
//! the reference rules; every other lens is projected this way, never by the pinhole's
//! rule.
//!
//! The sigma points and weights are the scaled unscented transform's (Wan and van der
//! Merwe 2000) with gsplat's defaults (`alpha = 0.1`, `beta = 2`, `kappa = 0`): with
//! `n = 3` and `lambda = alpha^2 (n + kappa) - n`, the points are `mu` and
//! `mu +- sqrt(n + lambda) R S e_i`, the mean weights `lambda / (n + lambda)` and
//! `1 / (2 (n + lambda))`, and the centre's covariance weight adds `1 - alpha^2 + beta`.
//! A Gaussian with a sigma point the lens does not image (behind a pinhole-like lens,
//! beyond a fisheye's field of view) is culled, and so is one whose sigma points all
//! land further outside the image than the margin (a tenth of the image on each side).

use crate::core::camera::lens::{Intrinsics, Lens};
use glam::{DMat2, DMat3, DVec2, DVec3};

/// The unscented transform's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnscentedParams {
    /// The sigma points' spread.
    pub alpha: f64,
    /// Prior knowledge of the distribution (2 for a Gaussian).
    pub beta: f64,
    /// The secondary spread.
    pub kappa: f64,
    /// How far outside the image, as a fraction of its width and height, a sigma point
    /// still counts as in view.
    pub in_image_margin: f64,
}

impl Default for UnscentedParams {
    /// gsplat's defaults.
    fn default() -> Self {
        UnscentedParams {
            alpha: 0.1,
            beta: 2.0,
            kappa: 0.0,
            in_image_margin: 0.1,
        }
    }
}

/// A Gaussian projected to the image: the 2D mean and covariance in pixels (before the
/// rules' dilation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    /// The mean pixel.
    pub mean: DVec2,
    /// The covariance in pixels squared.
    pub cov: DMat2,
}

/// Why a Gaussian has no projection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Culled {
    /// A sigma point is not imaged by the lens (behind it or beyond its field of view).
    SigmaPointNotImaged,
    /// Every sigma point lands outside the image and its margin.
    OutOfView,
}

impl UnscentedParams {
    /// The sigma points' spread `sqrt(n + lambda)`, the centre's mean weight, every other
    /// point's weight (mean and covariance alike), and the centre's covariance weight.
    pub fn weights(&self) -> [f64; 4] {
        const N: f64 = 3.0;
        let lambda = self.alpha * self.alpha * (N + self.kappa) - N;
        let centre = lambda / (N + lambda);
        [
            (N + lambda).sqrt(),
            centre,
            1.0 / (2.0 * (N + lambda)),
            centre + (1.0 - self.alpha * self.alpha + self.beta),
        ]
    }
}

/// The sigma points of the 3D Gaussian with mean `mean` and covariance `R S S^T R^T`
/// (`axes = R S`: its scaled axes as columns), and their mean and covariance weights.
pub fn sigma_points(
    mean: DVec3,
    axes: DMat3,
    params: &UnscentedParams,
) -> ([DVec3; 7], [f64; 7], [f64; 7]) {
    let [spread, centre, side, centre_cov] = params.weights();
    let mut points = [mean; 7];
    for i in 0..3 {
        let d = spread * axes.col(i);
        points[1 + 2 * i] = mean + d;
        points[2 + 2 * i] = mean - d;
    }
    let mut wm = [side; 7];
    let mut wc = [side; 7];
    wm[0] = centre;
    wc[0] = centre_cov;
    (points, wm, wc)
}

/// The pixel of the first of `points` (the centre) and every point's pixel less it, each
/// on the turn nearest the centre's where an equirectangular image's seam falls between
/// them; or [`Culled::SigmaPointNotImaged`].
pub fn pixel_offsets(
    lens: &Lens,
    k: &Intrinsics,
    points: &[DVec3; 7],
) -> Result<(DVec2, [DVec2; 7]), Culled> {
    let mut pixels = [DVec2::ZERO; 7];
    for (pixel, p) in pixels.iter_mut().zip(points) {
        *pixel = lens.project(k, *p).ok_or(Culled::SigmaPointNotImaged)?;
    }
    let centre = pixels[0];
    let mut offsets = pixels.map(|p| p - centre);
    if let Lens::Equirectangular { longitude, .. } = lens {
        // Sigma points across the seam: each on the turn nearest the mean's pixel.
        let turn = k.width as f64 * std::f64::consts::TAU / (longitude[1] - longitude[0]).abs();
        for d in &mut offsets[1..] {
            d.x -= turn * (d.x / turn).round();
        }
    }
    Ok((centre, offsets))
}

/// Projects the camera-space Gaussian with mean `mean` and scaled axes `axes` (`R S`,
/// camera space) through `lens` by the unscented transform.
///
/// The sums are taken relative to the centre's pixel (the weights sum to one), as the GPU
/// does in f32, where the points' pixels nearly cancel: the mean is `p0 + m` with
/// `m = sum_i w_i (p_i - p0)`, and the covariance `sum_i w'_i (p_i - p0 - m)(...)^T`.
pub fn project(
    lens: &Lens,
    k: &Intrinsics,
    mean: DVec3,
    axes: DMat3,
    params: &UnscentedParams,
) -> Result<Projected, Culled> {
    let (points, wm, wc) = sigma_points(mean, axes, params);
    let (centre, offsets) = pixel_offsets(lens, k, &points)?;
    let (w, h) = (k.width as f64, k.height as f64);
    let margin = params.in_image_margin;
    let in_view = |d: &DVec2| {
        let p = centre + *d;
        p.x >= -margin * w
            && p.x <= (1.0 + margin) * w
            && p.y >= -margin * h
            && p.y <= (1.0 + margin) * h
    };
    if !offsets.iter().any(in_view) {
        return Err(Culled::OutOfView);
    }
    let shift = offsets[1..]
        .iter()
        .zip(&wm[1..])
        .map(|(d, w)| *w * *d)
        .sum::<DVec2>();
    let mut cov = DMat2::ZERO;
    for (d, w) in offsets.iter().zip(wc) {
        let e = *d - shift;
        cov += w * DMat2::from_cols(e * e.x, e * e.y);
    }
    Ok(Projected {
        mean: centre + shift,
        cov,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::quat::quat_to_dmat3;

    const K: Intrinsics = Intrinsics {
        fx: 500.0,
        fy: 480.0,
        cx: 320.0,
        cy: 240.0,
        width: 640,
        height: 480,
    };

    fn axes(q: [f64; 4], s: [f64; 3]) -> DMat3 {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        quat_to_dmat3(q.map(|v| v / n)) * DMat3::from_diagonal(DVec3::from(s))
    }

    /// The Jacobian of the lens's map at `p`, by central differences.
    fn jacobian(lens: &Lens, p: DVec3) -> [DVec2; 3] {
        let h = 1e-6;
        let mut cols = [DVec2::ZERO; 3];
        for (i, col) in cols.iter_mut().enumerate() {
            let mut e = DVec3::ZERO;
            e[i] = h;
            *col =
                (lens.project(&K, p + e).unwrap() - lens.project(&K, p - e).unwrap()) / (2.0 * h);
        }
        cols
    }

    /// `0.5 sum_ij d2f/dx_i dx_j Sigma_ij`, by central differences.
    fn second_order_shift(lens: &Lens, p: DVec3, a: DMat3) -> DVec2 {
        let h = 1e-4;
        let f = |d: DVec3| lens.project(&K, p + d).unwrap();
        let sigma = a * a.transpose();
        let mut shift = DVec2::ZERO;
        for i in 0..3 {
            for j in 0..3 {
                let (mut ei, mut ej) = (DVec3::ZERO, DVec3::ZERO);
                ei[i] = h;
                ej[j] = h;
                let d2 = (f(ei + ej) - f(ei - ej) - f(ej - ei) + f(-ei - ej)) / (4.0 * h * h);
                shift += 0.5 * d2 * sigma.col(j)[i];
            }
        }
        shift
    }

    /// `J Sigma J^T`: the linearised (EWA) covariance.
    fn ewa(lens: &Lens, p: DVec3, a: DMat3) -> DMat2 {
        let j = jacobian(lens, p);
        let sigma = a * a.transpose();
        let mut c = DMat2::ZERO;
        for r in 0..2 {
            for s in 0..2 {
                let mut v = 0.0;
                for i in 0..3 {
                    for l in 0..3 {
                        v += j[i][r] * sigma.col(l)[i] * j[l][s];
                    }
                }
                c.col_mut(s)[r] = v;
            }
        }
        c
    }

    fn close(a: DMat2, b: DMat2, rel: f64) -> bool {
        let scale = b.col(0).length().max(b.col(1).length());
        (a - b).col(0).length().max((a - b).col(1).length()) <= rel * scale
    }

    #[test]
    fn the_weights_sum_to_one_and_recover_the_covariance() {
        let a = axes([0.9, 0.1, -0.3, 0.2], [0.3, 0.1, 0.05]);
        let mean = DVec3::new(0.1, -0.2, 3.0);
        let (points, wm, wc) = sigma_points(mean, a, &UnscentedParams::default());
        assert!((wm.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        // Through the identity the points give back the mean and covariance exactly.
        let m = points.iter().zip(wm).map(|(p, w)| w * *p).sum::<DVec3>();
        assert!((m - mean).length() < 1e-9);
        let mut cov = DMat3::ZERO;
        for (p, w) in points.iter().zip(wc) {
            let d = *p - m;
            cov += w * DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        }
        let want = a * a.transpose();
        for i in 0..3 {
            assert!((cov.col(i) - want.col(i)).length() < 1e-9, "{cov} {want}");
        }
    }

    #[test]
    fn an_orthographic_projection_is_exact() {
        // A linear map: the transform gives J Sigma J^T exactly.
        let a = axes([0.7, 0.2, 0.5, -0.1], [0.4, 0.2, 0.1]);
        let p = DVec3::new(0.2, 0.1, 5.0);
        let got = project(&Lens::Orthographic, &K, p, a, &UnscentedParams::default()).unwrap();
        assert!((got.mean - DVec2::new(500.0 * 0.2 + 320.0, 480.0 * 0.1 + 240.0)).length() < 1e-9);
        assert!(close(got.cov, ewa(&Lens::Orthographic, p, a), 1e-9));
    }

    #[test]
    fn a_small_gaussian_projects_as_its_linearisation() {
        // Far from the lens's curvature the sigma points see a near-linear map: the
        // transform agrees with EWA (the pinhole's rule) and with the fisheye's and the
        // distorted lens's Jacobians.
        let a = axes([0.8, -0.3, 0.4, 0.1], [0.02, 0.01, 0.005]);
        let p = DVec3::new(0.3, -0.2, 4.0);
        for lens in [
            Lens::Pinhole,
            Lens::Fisheye {
                k: [0.03, -0.01, 0.0, 0.0],
                max_theta: 1.6,
            },
            Lens::RadialTangential {
                radial: [-0.2, 0.05, 0.0, 0.0, 0.0, 0.0],
                tangential: [0.001, 0.0005],
            },
        ] {
            let got = project(&lens, &K, p, a, &UnscentedParams::default()).unwrap();
            assert!(
                close(got.cov, ewa(&lens, p, a), 1e-4),
                "{lens:?}: {} vs {}",
                got.cov,
                ewa(&lens, p, a)
            );
            // The mean moves by the map's second-order term, 0.5 tr(H Sigma).
            let want = lens.project(&K, p).unwrap() + second_order_shift(&lens, p, a);
            let off = (got.mean - want).length();
            assert!(off < 1e-5, "{lens:?}: the mean is {off} px off");
        }
    }

    #[test]
    fn a_gaussian_beyond_a_fisheyes_field_is_culled_and_one_past_90_degrees_is_not() {
        let lens = Lens::Fisheye {
            k: [0.0; 4],
            max_theta: 100f64.to_radians(),
        };
        let a = axes([1.0, 0.0, 0.0, 0.0], [0.05, 0.05, 0.05]);
        let at = |deg: f64| {
            let t = deg.to_radians();
            DVec3::new(2.0 * t.sin(), 0.0, 2.0 * t.cos())
        };
        let wide = Intrinsics {
            fx: 150.0,
            fy: 150.0,
            ..K
        };
        let seen = project(&lens, &wide, at(95.0), a, &UnscentedParams::default()).unwrap();
        assert!(seen.mean.x > K.cx + 150.0 * 1.6, "{}", seen.mean);
        assert_eq!(
            project(&lens, &wide, at(99.9), a, &UnscentedParams::default()),
            Err(Culled::SigmaPointNotImaged)
        );
        assert_eq!(
            project(
                &Lens::Pinhole,
                &K,
                DVec3::new(0.0, 0.0, -2.0),
                a,
                &UnscentedParams::default()
            ),
            Err(Culled::SigmaPointNotImaged)
        );
    }

    #[test]
    fn a_gaussian_across_the_equirectangular_seam_stays_whole() {
        // Straight behind the camera, on the seam of a full-sphere image: the sigma
        // points fall on both edges, and are taken on the mean's side.
        let k = Intrinsics {
            width: 1024,
            height: 512,
            ..K
        };
        let a = axes([1.0, 0.0, 0.0, 0.0], [0.1, 0.1, 0.1]);
        let got = project(
            &Lens::FULL_SPHERE,
            &k,
            DVec3::new(0.0, 0.0, -2.0),
            a,
            &UnscentedParams::default(),
        )
        .unwrap();
        // 0.1 at distance 2 is 0.05 rad; 1024 px per turn: a sd of about 8 px.
        let sd = got.cov.col(0).x.sqrt();
        assert!(
            (sd - 1024.0 * 0.05 / std::f64::consts::TAU).abs() < 0.1,
            "{sd}"
        );
        assert!(
            got.mean.x.abs() < 1e-6 || (got.mean.x - 1024.0).abs() < 1e-6,
            "{}",
            got.mean
        );
    }

    #[test]
    fn a_gaussian_outside_the_view_is_culled() {
        let a = axes([1.0, 0.0, 0.0, 0.0], [0.01, 0.01, 0.01]);
        assert_eq!(
            project(
                &Lens::Pinhole,
                &K,
                DVec3::new(10.0, 0.0, 1.0),
                a,
                &UnscentedParams::default()
            ),
            Err(Culled::OutOfView)
        );
    }
}
