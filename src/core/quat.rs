//! Rotation matrices of unit quaternions `(w, x, y, z)`: one path per precision, the f32
//! one the renderers' and the f64 one the backward reference's and the cameras', with the
//! same expressions element by element (a test holds them to each other).

use glam::{DMat3, DVec3, Mat3, Vec3};

/// Rotation matrix of a unit quaternion `(w, x, y, z)`.
pub fn quat_to_mat3(q: [f32; 4]) -> Mat3 {
    let [r, x, y, z] = q;
    Mat3::from_cols(
        Vec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + r * z),
            2.0 * (x * z - r * y),
        ),
        Vec3::new(
            2.0 * (x * y - r * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + r * x),
        ),
        Vec3::new(
            2.0 * (x * z + r * y),
            2.0 * (y * z - r * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    )
}

/// [`quat_to_mat3`] in f64.
pub fn quat_to_dmat3(q: [f64; 4]) -> DMat3 {
    let [r, x, y, z] = q;
    DMat3::from_cols(
        DVec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + r * z),
            2.0 * (x * z - r * y),
        ),
        DVec3::new(
            2.0 * (x * y - r * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + r * x),
        ),
        DVec3::new(
            2.0 * (x * z + r * y),
            2.0 * (y * z - r * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_precisions_agree_and_rotate() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..1000 {
            let q = [next(), next(), next(), next()];
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            let q = q.map(|v| v / n);
            let d = quat_to_dmat3(q);
            let f = quat_to_mat3(q.map(|v| v as f32));
            // A rotation: orthonormal, determinant 1.
            let e = (d.transpose() * d - DMat3::IDENTITY).to_cols_array();
            assert!(e.iter().all(|v| v.abs() < 1e-12), "{e:?}");
            assert!((d.determinant() - 1.0).abs() < 1e-12);
            // f32 within its rounding of the f64 matrix.
            for (a, b) in f.to_cols_array().iter().zip(d.to_cols_array()) {
                assert!((f64::from(*a) - b).abs() < 1e-6, "{a} vs {b}");
            }
        }
        // The identity quaternion and a quarter turn about z (x -> y).
        assert_eq!(quat_to_dmat3([1.0, 0.0, 0.0, 0.0]), DMat3::IDENTITY);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let m = quat_to_dmat3([h, 0.0, 0.0, h]);
        assert!((m * DVec3::X - DVec3::Y).length() < 1e-15);
    }
}
