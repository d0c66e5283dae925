//! Scene transforms: a similarity `x' = s Q x + t` (uniform scale `s > 0`, orthogonal `Q`
//! that may include a reflection, translation `t`) applied to every Gaussian's centre,
//! shape and view-dependent colour, before a scene is rendered or converted.
//!
//! A Gaussian with centre `p`, rotation `R` and scales `S` becomes:
//! - centre `s Q p + t`;
//! - log scales `+ ln s` (its covariance is `s^2 Q R S S^T R^T Q^T`);
//! - rotation `R' = Q R`, or `R' = -Q R` when `Q` is a reflection (`det Q = -1`): a
//!   quaternion can only hold a proper rotation, and `(-Q) Sigma (-Q)^T = Q Sigma Q^T`, so
//!   negating the whole matrix gives a proper rotation with exactly the reflected
//!   covariance, without touching the scales;
//! - SH: the colour seen along a direction `d` after the transform is the colour seen
//!   along `Q^T d` before it (the uniform scale and the translation do not change a
//!   direction). Every band of real SH is mapped onto itself by any orthogonal `Q`, proper
//!   or not, so each band's coefficients are multiplied by one small matrix
//!   ([`SceneTransform::sh_band_matrix`]), fitted in f64 to the exact basis the renderers
//!   evaluate (`crate::core::model::sh::eval_sh`, its order, signs and constants).
//!
//! Composition ([`SceneTransform::then`]) is closed: flips, rotations, scales and
//! translations in any order collapse into one `s Q x + t`.

use super::Scene;
use crate::core::model::sh::{SH_C1, SH_C2, SH_C3};
use glam::{DMat3, DQuat, DVec3};

/// Sign of each SH coefficient `k = 1..=15` (index `k - 1`) under `(x, y, z) -> (x, -y, -z)`:
/// `(-1)^(deg_y + deg_z)` of its basis polynomial (band 1: y, z, x; band 2: xy, yz,
/// 3z^2-1, xz, x^2-y^2; band 3: y(3x^2-y^2), xyz, y(4z^2-x^2-y^2), z(2z^2-3x^2-3y^2),
/// x(4z^2-x^2-y^2), z(x^2-y^2), x(x^2-3y^2)).
pub const RUB_SH_SIGN: [f32; 15] = [
    -1.0, -1.0, 1.0, //
    -1.0, 1.0, 1.0, -1.0, 1.0, //
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0,
];

/// Entries of `Q` and of the SH band matrices this close to -1, 0 or 1 are set to that
/// value, so quarter and half turns and axis flips move values exactly (bitwise) instead
/// of mixing in 1e-16 of the other coordinates (`cos 90°` is 6e-17 in f64). The change is
/// four orders of magnitude below f32 resolution.
const SNAP: f64 = 1e-12;

/// Directions at which each SH band is sampled to fit its transform matrix: many more
/// than the largest band's 7 functions, spread over the sphere, so the fit is well
/// conditioned.
const SH_SAMPLES: usize = 64;

/// A similarity transform of a scene, `x' = scale * orthogonal * x + translation`.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneTransform {
    orthogonal: DMat3,
    scale: f64,
    translation: DVec3,
}

impl Default for SceneTransform {
    fn default() -> Self {
        Self::identity()
    }
}

impl SceneTransform {
    /// The transform that changes nothing.
    pub fn identity() -> Self {
        SceneTransform {
            orthogonal: DMat3::IDENTITY,
            scale: 1.0,
            translation: DVec3::ZERO,
        }
    }

    /// Mirrors the chosen axes (`x -> -x` for `x`, ...). One or three flips are a
    /// reflection; two are a half turn about the third axis.
    pub fn flip_axes(x: bool, y: bool, z: bool) -> Self {
        let sign = |f: bool| if f { -1.0 } else { 1.0 };
        SceneTransform {
            orthogonal: DMat3::from_diagonal(DVec3::new(sign(x), sign(y), sign(z))),
            ..Self::identity()
        }
    }

    /// A rotation about the origin by `degrees` around `axis` (right-hand rule; the axis
    /// need not be unit length but must be finite and non-zero).
    pub fn rotation(axis: [f64; 3], degrees: f64) -> Result<Self, String> {
        let a = DVec3::from(axis);
        let len = a.length();
        if !(a.is_finite() && len.is_finite() && len > 0.0) {
            return Err(format!(
                "the rotation axis ({}, {}, {}) must be finite and non-zero",
                axis[0], axis[1], axis[2]
            ));
        }
        if !degrees.is_finite() {
            return Err(format!(
                "the rotation angle {degrees} is not a finite number"
            ));
        }
        Ok(SceneTransform {
            orthogonal: snap_mat3(DMat3::from_axis_angle(a / len, degrees.to_radians())),
            ..Self::identity()
        })
    }

    /// A uniform scaling about the origin by `factor` (finite and > 0).
    pub fn scaling(factor: f64) -> Result<Self, String> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(format!(
                "the scale factor {factor} must be a finite number above 0"
            ));
        }
        Ok(SceneTransform {
            scale: factor,
            ..Self::identity()
        })
    }

    /// A translation by `offset` (finite).
    pub fn translation(offset: [f64; 3]) -> Result<Self, String> {
        let t = DVec3::from(offset);
        if !t.is_finite() {
            return Err(format!(
                "the translation ({}, {}, {}) must be finite",
                offset[0], offset[1], offset[2]
            ));
        }
        Ok(SceneTransform {
            translation: t,
            ..Self::identity()
        })
    }

    /// `x' = scale * orthogonal * x + translation` from its parts; `orthogonal` must be
    /// orthogonal (`Q^T Q = I` within 1e-9 per entry), `scale` finite and > 0.
    pub fn from_parts(orthogonal: DMat3, scale: f64, translation: DVec3) -> Result<Self, String> {
        let err = (orthogonal.transpose() * orthogonal - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        if !(orthogonal.is_finite() && err <= 1e-9) {
            return Err(format!(
                "the linear part is not orthogonal (Q^T Q differs from I by {err:e})"
            ));
        }
        let mut t = Self::translation(translation.to_array())?;
        t.scale = Self::scaling(scale)?.scale;
        t.orthogonal = snap_mat3(orthogonal);
        Ok(t)
    }

    /// This transform followed by `next` (`next(self(x))`).
    pub fn then(&self, next: &SceneTransform) -> SceneTransform {
        SceneTransform {
            orthogonal: snap_mat3(next.orthogonal * self.orthogonal),
            scale: next.scale * self.scale,
            translation: next.scale * (next.orthogonal * self.translation) + next.translation,
        }
    }

    /// The orthogonal part `Q` (determinant +1, or -1 for a reflection).
    pub fn orthogonal(&self) -> DMat3 {
        self.orthogonal
    }

    /// The uniform scale factor `s`.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// The translation `t`, applied last.
    pub fn offset(&self) -> DVec3 {
        self.translation
    }

    /// True when the orthogonal part mirrors the scene (`det Q = -1`).
    pub fn is_reflection(&self) -> bool {
        self.orthogonal.determinant() < 0.0
    }

    /// True when the transform changes nothing.
    pub fn is_identity(&self) -> bool {
        self.orthogonal == DMat3::IDENTITY && self.scale == 1.0 && self.translation == DVec3::ZERO
    }

    /// Where the point `p` goes.
    pub fn apply_point(&self, p: DVec3) -> DVec3 {
        self.scale * (self.orthogonal * p) + self.translation
    }

    /// The proper rotation applied to every Gaussian's orientation: `Q`, or `-Q` for a
    /// reflection (same covariance, see the module docs).
    pub fn gaussian_rotation(&self) -> DQuat {
        let proper = if self.is_reflection() {
            -self.orthogonal
        } else {
            self.orthogonal
        };
        DQuat::from_mat3(&proper).normalize()
    }

    /// The matrix `M` ((2l+1) x (2l+1), row-major) that maps the coefficients `c` of SH band
    /// `band` (1..=3) of one colour channel to the transformed coefficients `M c`, so that
    /// the transformed SH evaluated at `d` equals the original at `Q^T d`. Band 0 is
    /// unchanged (`[1.0]`). Panics for a band above 3, which no scene holds.
    pub fn sh_band_matrix(&self, band: u32) -> Vec<f64> {
        assert!(band <= 3, "SH band {band} is above 3");
        let m = 2 * band as usize + 1;
        if band == 0 {
            return vec![1.0];
        }
        // Least squares over sample directions d_j: find M with
        // sum_k M[k][j] Y_k(d) = Y_j(Q^T d) for every j, i.e. M = G^-1 B with
        // G = sum y y^T and B = sum y yq^T (y = Y(d), yq = Y(Q^T d)). The basis spans a
        // space that Q maps onto itself, so the residual is zero and M is exact up to
        // f64 rounding.
        let qt = self.orthogonal.transpose();
        let mut g = vec![0.0; m * m];
        let mut b = vec![0.0; m * m];
        let (mut y, mut yq) = ([0.0; 7], [0.0; 7]);
        for d in sample_directions() {
            sh_band_basis(band, d, &mut y);
            sh_band_basis(band, qt * d, &mut yq);
            for r in 0..m {
                for c in 0..m {
                    g[r * m + c] += y[r] * y[c];
                    b[r * m + c] += y[r] * yq[c];
                }
            }
        }
        solve_spd(&g, &b, m).into_iter().map(snap).collect()
    }

    /// Applies the transform to every Gaussian of `scene` (see the module docs). Fails
    /// when a transformed value is not finite (a huge scale or translation).
    pub fn apply(&self, mut scene: Scene) -> Result<Scene, String> {
        scene.check_consistent()?;
        for (i, p) in scene.positions.iter_mut().enumerate() {
            let v = self.apply_point(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            *p = [v.x as f32, v.y as f32, v.z as f32];
            if !p.iter().all(|c| c.is_finite()) {
                return Err(format!(
                    "the transform moves Gaussian {i} to a position that is not finite in 32-bit floats ({}, {}, {})",
                    v.x, v.y, v.z
                ));
            }
        }
        if self.scale != 1.0 {
            let ln_s = self.scale.ln();
            for (i, ls) in scene.log_scales.iter_mut().enumerate() {
                for v in ls.iter_mut() {
                    *v = (*v as f64 + ln_s) as f32;
                }
                if !ls.iter().all(|c| c.is_finite()) {
                    return Err(format!(
                        "the transform makes Gaussian {i}'s scale not finite in 32-bit floats"
                    ));
                }
            }
        }
        if self.orthogonal == DMat3::IDENTITY {
            // Nothing turns: orientations and view-dependent colour stay as they are.
            return Ok(scene);
        }
        let r = self.gaussian_rotation();
        for q in scene.rotations.iter_mut() {
            *q = quat_mul([r.w, r.x, r.y, r.z], q.map(|v| v as f64)).map(|v| v as f32);
        }
        let stride = scene.sh_stride();
        let bands: Vec<Vec<f64>> = (1..=scene.sh_degree)
            .map(|l| self.sh_band_matrix(l))
            .collect();
        let mut band_in = [0.0f64; 7];
        for coeffs in scene.sh.chunks_exact_mut(stride) {
            for (l, matrix) in (1..=scene.sh_degree as usize).zip(&bands) {
                let (first, m) = (l * l, 2 * l + 1);
                for c in 0..3 {
                    for (j, v) in band_in[..m].iter_mut().enumerate() {
                        *v = coeffs[(first + j) * 3 + c] as f64;
                    }
                    for k in 0..m {
                        let row = &matrix[k * m..(k + 1) * m];
                        let v: f64 = row.iter().zip(&band_in[..m]).map(|(a, b)| a * b).sum();
                        coeffs[(first + k) * 3 + c] = v as f32;
                    }
                }
            }
        }
        Ok(scene)
    }
}

impl std::fmt::Display for SceneTransform {
    /// One phrase in application order, e.g. "rotation by 90° about (0, 0, 1), then scale
    /// by 2, then translation by (1, 0, 0)"; a reflection prints the rows of `Q`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut parts = Vec::new();
        if self.is_reflection() {
            let r = |i: usize| {
                let row = self.orthogonal.row(i);
                format!("{} {} {}", num(row.x), num(row.y), num(row.z))
            };
            parts.push(format!(
                "reflection with rows [{}; {}; {}]",
                r(0),
                r(1),
                r(2)
            ));
        } else if self.orthogonal != DMat3::IDENTITY {
            let (axis, angle) = DQuat::from_mat3(&self.orthogonal).to_axis_angle();
            parts.push(format!(
                "rotation by {}° about ({}, {}, {})",
                num(angle.to_degrees()),
                num(axis.x),
                num(axis.y),
                num(axis.z)
            ));
        }
        if self.scale != 1.0 {
            parts.push(format!("scale by {}", num(self.scale)));
        }
        if self.translation != DVec3::ZERO {
            let t = self.translation;
            parts.push(format!(
                "translation by ({}, {}, {})",
                num(t.x),
                num(t.y),
                num(t.z)
            ));
        }
        if parts.is_empty() {
            f.write_str("identity")
        } else {
            f.write_str(&parts.join(", then "))
        }
    }
}

/// A number with at most 6 decimals and no trailing zeros (`90`, `0.5`, `-0.707107`).
fn num(v: f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

fn snap(v: f64) -> f64 {
    for target in [-1.0, 0.0, 1.0] {
        if (v - target).abs() < SNAP {
            return target;
        }
    }
    v
}

fn snap_mat3(m: DMat3) -> DMat3 {
    DMat3::from_cols_array(&m.to_cols_array().map(snap))
}

/// Hamilton product `a b` of quaternions `(w, x, y, z)`: the rotation `b`, then `a`.
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// Unit directions on a Fibonacci spiral, evenly spread over the sphere.
fn sample_directions() -> impl Iterator<Item = DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..SH_SAMPLES).map(move |i| {
        let z = 1.0 - (2 * i + 1) as f64 / SH_SAMPLES as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = golden * i as f64;
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    })
}

/// The basis functions of SH band `band` at unit direction `d`, in f64, in the order, with
/// the signs and with the (f32) constants of `crate::core::model::sh::eval_sh`, written into
/// `out[..2 * band + 1]`.
fn sh_band_basis(band: u32, d: DVec3, out: &mut [f64; 7]) {
    let (x, y, z) = (d.x, d.y, d.z);
    let c1 = SH_C1 as f64;
    let c2 = SH_C2.map(|c| c as f64);
    let c3 = SH_C3.map(|c| c as f64);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    match band {
        1 => out[..3].copy_from_slice(&[-c1 * y, c1 * z, -c1 * x]),
        2 => out[..5].copy_from_slice(&[
            c2[0] * x * y,
            c2[1] * y * z,
            c2[2] * (2.0 * zz - xx - yy),
            c2[3] * x * z,
            c2[4] * (xx - yy),
        ]),
        3 => out.copy_from_slice(&[
            c3[0] * y * (3.0 * xx - yy),
            c3[1] * x * y * z,
            c3[2] * y * (4.0 * zz - xx - yy),
            c3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
            c3[4] * x * (4.0 * zz - xx - yy),
            c3[5] * z * (xx - yy),
            c3[6] * x * (xx - 3.0 * yy),
        ]),
        _ => unreachable!("sh_band_matrix checks the band"),
    }
}

/// Solves `G X = B` for a symmetric positive definite `m x m` matrix `G` (Cholesky); `B`
/// and the result are `m x m`, row-major. `G` is a Gram matrix of the fixed sample
/// directions, never user data, and is well conditioned.
fn solve_spd(g: &[f64], b: &[f64], m: usize) -> Vec<f64> {
    let mut l = vec![0.0; m * m];
    for i in 0..m {
        for j in 0..=i {
            let sum = g[i * m + j] - (0..j).map(|k| l[i * m + k] * l[j * m + k]).sum::<f64>();
            l[i * m + j] = if i == j {
                sum.sqrt()
            } else {
                sum / l[j * m + j]
            };
        }
    }
    let mut x = vec![0.0; m * m];
    for col in 0..m {
        // L y = b, then L^T x = y.
        let mut y = vec![0.0; m];
        for i in 0..m {
            let s = b[i * m + col] - (0..i).map(|k| l[i * m + k] * y[k]).sum::<f64>();
            y[i] = s / l[i * m + i];
        }
        for i in (0..m).rev() {
            let s = y[i]
                - (i + 1..m)
                    .map(|k| l[k * m + i] * x[k * m + col])
                    .sum::<f64>();
            x[i * m + col] = s / l[i * m + i];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_matrices_of_the_identity_are_identities() {
        let t = SceneTransform::identity();
        for band in 1..=3u32 {
            let m = 2 * band as usize + 1;
            let id: Vec<f64> = (0..m * m)
                .map(|i| if i / m == i % m { 1.0 } else { 0.0 })
                .collect();
            assert_eq!(t.sh_band_matrix(band), id, "band {band}");
        }
    }

    #[test]
    fn a_half_turn_about_x_negates_the_coefficients_spz_negates() {
        // The SPZ loader's RUB <-> RDF conversion (x, y, z) -> (x, -y, -z) was written
        // independently from the basis polynomials; the fitted band matrices must be
        // exactly the diagonal of its signs.
        for t in [
            SceneTransform::rotation([1.0, 0.0, 0.0], 180.0).unwrap(),
            SceneTransform::flip_axes(false, true, true),
        ] {
            assert_eq!(
                t.orthogonal(),
                DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0))
            );
            for band in 1..=3u32 {
                let m = 2 * band as usize + 1;
                let first = (band * band) as usize - 1;
                let want: Vec<f64> = (0..m * m)
                    .map(|i| {
                        if i / m == i % m {
                            RUB_SH_SIGN[first + i / m] as f64
                        } else {
                            0.0
                        }
                    })
                    .collect();
                assert_eq!(t.sh_band_matrix(band), want, "band {band}");
            }
        }
    }

    #[test]
    fn parameters_are_checked_and_described() {
        assert!(SceneTransform::rotation([0.0, 0.0, 0.0], 90.0).is_err());
        assert!(SceneTransform::rotation([1.0, 0.0, f64::NAN], 90.0).is_err());
        assert!(SceneTransform::rotation([1.0, 0.0, 0.0], f64::INFINITY).is_err());
        assert!(SceneTransform::scaling(0.0).is_err());
        assert!(SceneTransform::scaling(-2.0).is_err());
        assert!(SceneTransform::translation([0.0, f64::INFINITY, 0.0]).is_err());
        assert!(SceneTransform::from_parts(
            DMat3::from_diagonal(DVec3::splat(2.0)),
            1.0,
            DVec3::ZERO
        )
        .is_err());
        let t = SceneTransform::rotation([0.0, 0.0, 2.0], 90.0)
            .unwrap()
            .then(&SceneTransform::scaling(2.0).unwrap())
            .then(&SceneTransform::translation([1.0, -0.5, 0.0]).unwrap());
        assert_eq!(
            t.to_string(),
            "rotation by 90° about (0, 0, 1), then scale by 2, then translation by (1, -0.5, 0)"
        );
        assert_eq!(
            SceneTransform::flip_axes(false, true, false).to_string(),
            "reflection with rows [1 0 0; 0 -1 0; 0 0 1]"
        );
        assert_eq!(SceneTransform::identity().to_string(), "identity");
    }
}
