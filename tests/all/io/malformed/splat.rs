//! `.splat` cases: the 32-byte record builder and the cases.

use super::case::{scene_case, Case, Expect};

/// One `.splat` record.
pub(super) fn splat_rec(p: [f32; 3], s: [f32; 3], q: [u8; 4]) -> Vec<u8> {
    let mut b = Vec::new();
    for v in p.iter().chain(&s) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(&[200, 100, 50, 230]);
    b.extend_from_slice(&q);
    b
}

/// The table's cases for `.splat`.
pub(super) fn splat_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    let denormal = f32::from_bits(1); // the smallest positive subnormal
    let splat_ok = |p, s| splat_rec(p, s, [255, 128, 128, 128]);
    vec![
        scene_case(
            "splat_not_multiple_of_32",
            "s.splat",
            [splat_ok([0.0; 3], [0.1; 3]), vec![0]].concat(),
            Error("not a multiple of the 32-byte .splat record"),
        ),
        scene_case(
            "splat_nan_position",
            "s.splat",
            splat_ok([f32::NAN, 0.0, 0.0], [0.1; 3]),
            Error(".splat record 0 has a non-finite position"),
        ),
        scene_case(
            "splat_inf_position",
            "s.splat",
            [
                splat_ok([0.0; 3], [0.1; 3]),
                splat_ok([0.0, f32::NEG_INFINITY, 0.0], [0.1; 3]),
            ]
            .concat(),
            Error(".splat record 1 has a non-finite position"),
        ),
        scene_case(
            "splat_zero_scale",
            "s.splat",
            splat_ok([0.0; 3], [0.1, 0.0, 0.1]),
            Error("not a positive finite number"),
        ),
        scene_case(
            "splat_negative_scale",
            "s.splat",
            splat_ok([0.0; 3], [0.1, 0.1, -0.1]),
            Error("not a positive finite number"),
        ),
        scene_case(
            "splat_nan_scale",
            "s.splat",
            splat_ok([0.0; 3], [f32::NAN, 0.1, 0.1]),
            Error("not a positive finite number"),
        ),
        scene_case(
            "splat_zero_quaternion",
            "s.splat",
            splat_rec([0.0; 3], [0.1; 3], [128; 4]),
            Error("zero-length rotation (all four bytes are 128)"),
        ),
        scene_case("splat_empty", "s.splat", Vec::new(), Renders(0)),
        scene_case(
            "splat_denormal_scale",
            "s.splat",
            splat_ok([0.0; 3], [denormal, 0.1, 0.1]),
            Renders(1),
        ),
    ]
}
