//! INRIA PLY cases: builders for small binary and ASCII PLY files, and the cases for
//! the header's structure, bad values and odd but usable files.

use super::case::{scene_case, Case, Expect};

/// The INRIA PLY vertex properties, in the trainer's order (SH degree 0).
pub(super) const PLY_PROPS: [&str; 17] = [
    "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
    "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
];

/// One PLY row: a Gaussian at `pos` with log scale `log_scale`, quaternion `rot`, opacity
/// logit 2 (0.88) and a grey-ish colour.
pub(super) fn ply_row(pos: [f32; 3], log_scale: f32, rot: [f32; 4]) -> [f32; 17] {
    [
        pos[0], pos[1], pos[2], 0.0, 0.0, 0.0, 0.5, 0.2, -0.3, 2.0, log_scale, log_scale,
        log_scale, rot[0], rot[1], rot[2], rot[3],
    ]
}

pub(super) fn good_row() -> [f32; 17] {
    ply_row([0.0; 3], -2.0, [1.0, 0.0, 0.0, 0.0])
}

/// A PLY header with `element vertex {count}` and the given property lines.
pub(super) fn ply_header(format: &str, count: &str, props: &[String]) -> String {
    let mut h = format!("ply\nformat {format} 1.0\nelement vertex {count}\n");
    for p in props {
        h.push_str(p);
        h.push('\n');
    }
    h.push_str("end_header\n");
    h
}

pub(super) fn float_props() -> Vec<String> {
    PLY_PROPS
        .iter()
        .map(|p| format!("property float {p}"))
        .collect()
}

/// A binary little-endian PLY declaring `count` vertices and holding `rows`.
pub(super) fn ply_le(count: &str, rows: &[[f32; 17]]) -> Vec<u8> {
    let mut b = ply_header("binary_little_endian", count, &float_props()).into_bytes();
    for r in rows {
        for v in r {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

/// A PLY with one good row but a changed property list.
pub(super) fn ply_props(props: Vec<String>, row_bytes: usize) -> Vec<u8> {
    let mut b = ply_header("binary_little_endian", "1", &props).into_bytes();
    b.resize(b.len() + row_bytes, 0);
    b
}

pub(super) fn ply_ascii(count: &str, rows: &[&str]) -> Vec<u8> {
    let mut b = ply_header("ascii", count, &float_props()).into_bytes();
    for r in rows {
        b.extend_from_slice(r.as_bytes());
        b.push(b'\n');
    }
    b
}

/// `bytes` with the first occurrence of `from` replaced by `to`.
pub(super) fn replace_first(bytes: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    let at = bytes
        .windows(from.len())
        .position(|w| w == from)
        .expect("present");
    [&bytes[..at], to, &bytes[at + from.len()..]].concat()
}

/// The table's cases for INRIA PLY: structure.
pub(super) fn ply_structure_cases() -> Vec<Case> {
    use Expect::Error;
    let two_40 = "1099511627776";
    let mut missing_opacity = float_props();
    missing_opacity.retain(|p| !p.ends_with(" opacity"));
    let mut five_rest = float_props();
    five_rest.extend((0..5).map(|i| format!("property float f_rest_{i}")));
    let mut bad_type = float_props();
    bad_type[9] = "property float128 opacity".into();
    let mut list_x = float_props();
    list_x[0] = "property list uchar float x".into();
    vec![
        scene_case(
            "ply_empty_file",
            "s.ply",
            Vec::new(),
            Error("is empty (0 bytes)"),
        ),
        scene_case(
            "ply_header_only_magic",
            "s.ply",
            b"ply\n".to_vec(),
            Error("no end_header line"),
        ),
        scene_case(
            "ply_header_truncated",
            "s.ply",
            ply_header("binary_little_endian", "1", &float_props()).as_bytes()[..120].to_vec(),
            Error("no end_header line"),
        ),
        scene_case(
            "ply_unknown_format",
            "s.ply",
            ply_header("binary_middle_endian", "1", &float_props()).into_bytes(),
            Error("unknown PLY format"),
        ),
        scene_case(
            "ply_count_too_large",
            "s.ply",
            ply_le("1000", &[good_row()]),
            Error("declares 1000 vertex elements"),
        ),
        scene_case(
            "ply_count_2_pow_40",
            "s.ply",
            ply_le(two_40, &[good_row()]),
            Error("declares 1099511627776 vertex elements"),
        ),
        scene_case(
            "ply_count_2_pow_64",
            "s.ply",
            ply_le("18446744073709551615", &[good_row()]),
            Error("more than 2^64"),
        ),
        scene_case(
            "ply_count_negative",
            "s.ply",
            ply_le("-1", &[good_row()]),
            Error("element count is not a non-negative integer"),
        ),
        scene_case(
            "ply_count_too_small",
            "s.ply",
            ply_le("1", &[good_row(), good_row()]),
            Error("68 bytes after the last element"),
        ),
        scene_case(
            "ply_ascii_count_too_large",
            "s.ply",
            ply_ascii("3", &["0 0 0 0 0 0 0.5 0.2 -0.3 2 -2 -2 -2 1 0 0 0"]),
            Error("is truncated: the data ends inside vertex 1"),
        ),
        scene_case(
            "ply_ascii_count_2_pow_40",
            "s.ply",
            ply_ascii(two_40, &["0 0 0 0 0 0 0.5 0.2 -0.3 2 -2 -2 -2 1 0 0 0"]),
            Error("is truncated: the data ends inside vertex 1"),
        ),
        scene_case(
            "ply_missing_opacity",
            "s.ply",
            ply_props(missing_opacity, 16 * 4),
            Error("missing the vertex property \"opacity\""),
        ),
        scene_case(
            "ply_five_f_rest",
            "s.ply",
            ply_props(five_rest, 22 * 4),
            Error("has 5 f_rest_* properties"),
        ),
        scene_case(
            "ply_unknown_property_type",
            "s.ply",
            ply_props(bad_type, 17 * 4),
            Error("unknown property type"),
        ),
        scene_case(
            "ply_list_where_scalar",
            "s.ply",
            ply_props(list_x, 17 * 4),
            Error("\"x\" is a list, but a scalar is required"),
        ),
        scene_case(
            "ply_no_vertex_element",
            "s.ply",
            b"ply\nformat ascii 1.0\nelement face 0\nend_header\n".to_vec(),
            Error("has no \"vertex\" element"),
        ),
        scene_case(
            "ply_no_format_line",
            "s.ply",
            b"ply\nelement vertex 0\nend_header\n".to_vec(),
            Error("has no format line"),
        ),
        scene_case(
            "ply_ascii_not_a_number",
            "s.ply",
            ply_ascii("1", &["0 0 zero 0 0 0 0.5 0.2 -0.3 2 -2 -2 -2 1 0 0 0"]),
            Error("non-numeric value \"zero\""),
        ),
        scene_case(
            "ply_ascii_extra_values",
            "s.ply",
            ply_ascii("1", &["0 0 0 0 0 0 0.5 0.2 -0.3 2 -2 -2 -2 1 0 0 0 7"]),
            Error("more values than its header declares"),
        ),
    ]
}

/// The table's cases for INRIA PLY: values.
pub(super) fn ply_value_cases() -> Vec<Case> {
    use Expect::Error;
    let nan_row = {
        let mut r = good_row();
        r[0] = f32::NAN;
        r
    };
    let inf_scale = {
        let mut r = good_row();
        r[10] = f32::INFINITY;
        r
    };
    let nan_opacity = {
        let mut r = good_row();
        r[9] = f32::NAN;
        r
    };
    let denormal = f32::from_bits(1); // the smallest positive subnormal
    let mut double_x = float_props();
    double_x[0] = "property double x".into();
    let double_x_bytes = {
        let mut b = ply_header("binary_little_endian", "1", &double_x).into_bytes();
        b.extend_from_slice(&0f64.to_le_bytes());
        for v in &good_row()[1..] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    };
    vec![
        scene_case(
            "ply_nan_position",
            "s.ply",
            ply_le("1", &[nan_row]),
            Error("vertex 0 has a non-finite value (NaN) in property \"x\""),
        ),
        scene_case(
            "ply_inf_scale",
            "s.ply",
            ply_le("1", &[inf_scale]),
            Error("non-finite value (inf) in property \"scale_0\""),
        ),
        scene_case(
            "ply_nan_opacity",
            "s.ply",
            ply_le("1", &[nan_opacity]),
            Error("non-finite value (NaN) in property \"opacity\""),
        ),
        scene_case(
            "ply_ascii_nan",
            "s.ply",
            ply_ascii("1", &["0 0 0 0 0 0 NaN 0.2 -0.3 2 -2 -2 -2 1 0 0 0"]),
            Error("non-finite value (NaN) in property \"f_dc_0\""),
        ),
        scene_case(
            "ply_ascii_inf_rotation",
            "s.ply",
            ply_ascii("1", &["0 0 0 0 0 0 0.5 0.2 -0.3 2 -2 -2 -2 inf 0 0 0"]),
            Error("non-finite value (inf) in property \"rot_0\""),
        ),
        scene_case(
            "ply_double_overflows_f32",
            "s.ply",
            {
                let mut b = double_x_bytes.clone();
                let at = b.len() - 16 * 4 - 8;
                b[at..at + 8].copy_from_slice(&1e300f64.to_le_bytes());
                b
            },
            Error("non-finite value (inf) in property \"x\""),
        ),
        scene_case(
            "ply_zero_quaternion",
            "s.ply",
            ply_le("1", &[ply_row([0.0; 3], -2.0, [0.0; 4])]),
            Error("vertex 0 has a zero-length rotation quaternion"),
        ),
        scene_case(
            "ply_denormal_quaternion",
            "s.ply",
            ply_le("1", &[ply_row([0.0; 3], -2.0, [denormal, 0.0, 0.0, 0.0])]),
            Error("zero-length rotation quaternion"),
        ),
    ]
}

/// The table's cases for INRIA PLY: odd but usable, and an element without properties.
pub(super) fn ply_usable_cases() -> Vec<Case> {
    use Expect::Renders;
    let nan_normal = {
        let mut r = good_row();
        r[3] = f32::NAN;
        r
    };
    let denormal = f32::from_bits(1); // the smallest positive subnormal
    let mut double_x = float_props();
    double_x[0] = "property double x".into();
    let double_x_bytes = {
        let mut b = ply_header("binary_little_endian", "1", &double_x).into_bytes();
        b.extend_from_slice(&0f64.to_le_bytes());
        for v in &good_row()[1..] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    };
    vec![
        scene_case("ply_zero_gaussians", "s.ply", ply_le("0", &[]), Renders(0)),
        scene_case(
            "ply_ascii_zero_gaussians",
            "s.ply",
            ply_ascii("0", &[]),
            Renders(0),
        ),
        scene_case(
            "ply_nan_in_unused_normal",
            "s.ply",
            ply_le("1", &[nan_normal]),
            Renders(1),
        ),
        scene_case(
            "ply_denormal_values",
            "s.ply",
            ply_le(
                "1",
                &[ply_row(
                    [denormal, -denormal, denormal],
                    -2.0,
                    [1.0, denormal, 0.0, denormal],
                )],
            ),
            Renders(1),
        ),
        scene_case(
            "ply_zero_log_scale",
            "s.ply",
            ply_le("1", &[ply_row([0.0; 3], 0.0, [1.0, 0.0, 0.0, 0.0])]),
            Renders(1),
        ),
        scene_case(
            "ply_scale_underflows_to_zero",
            "s.ply",
            ply_le("1", &[ply_row([0.0; 3], -1000.0, [1.0, 0.0, 0.0, 0.0])]),
            Renders(1),
        ),
        scene_case(
            "ply_negative_log_scale",
            "s.ply",
            ply_le("1", &[ply_row([0.0; 3], -7.5, [0.0, 0.0, 0.0, -3.0])]),
            Renders(1),
        ),
        scene_case("ply_double_x", "s.ply", double_x_bytes, Renders(1)),
        // An element without properties holds no bytes, whatever count it claims.
        scene_case(
            "ply_empty_element_2_pow_64",
            "s.ply",
            replace_first(
                &ply_le("1", &[good_row()]),
                b"end_header",
                b"element empty 18446744073709551615\nend_header",
            ),
            Renders(1),
        ),
    ]
}
