//! INRIA PLY loading: round trips, property lookup by name, encodings, model directories,
//! and one clear error per malformed input.

use crate::common;
use crate::common::random_scene;
use std::path::Path;
use verisplat::core::scene::{Scene, SceneError};
use verisplat::io;
use verisplat::io::scene::ply;

fn parse(bytes: &[u8]) -> Result<Scene, SceneError> {
    ply::parse(bytes, Path::new("test.ply"))
}

fn err(bytes: &[u8]) -> String {
    parse(bytes)
        .expect_err("malformed input must be rejected")
        .to_string()
}

#[test]
fn round_trip_every_field_all_sh_degrees_and_encodings() {
    for deg in 0..=3 {
        let s = random_scene(57, deg, 100 + deg as u64);
        for enc in [
            ply::PlyEncoding::BinaryLittleEndian,
            ply::PlyEncoding::BinaryBigEndian,
            ply::PlyEncoding::Ascii,
        ] {
            let back = parse(&ply::to_bytes(&s, enc)).unwrap();
            assert_eq!(back, s, "degree {deg}, {enc:?}");
        }
    }
}

#[test]
fn sh_layout_is_channel_major_in_the_file() {
    // f_rest_{c*K + k} is coefficient k+1 of channel c.
    let mut s = random_scene(1, 2, 1);
    let k = 8;
    for c in 0..3 {
        for j in 0..k {
            s.sh[(j + 1) * 3 + c] = (c * 100 + j) as f32;
        }
    }
    let bytes = ply::to_bytes(&s, ply::PlyEncoding::Ascii);
    let text = String::from_utf8(bytes).unwrap();
    let data_line = text.lines().last().unwrap();
    let values: Vec<f32> = data_line.split(' ').map(|v| v.parse().unwrap()).collect();
    // x y z nx ny nz f_dc_0..2, then f_rest_0.. at index 9.
    for c in 0..3 {
        for j in 0..k {
            assert_eq!(values[9 + c * k + j], (c * 100 + j) as f32);
        }
    }
}

/// Writes a binary PLY by hand with the given (type, name) properties and per-row values.
fn custom_ply(props: &[(&str, &str)], rows: &[Vec<f64>]) -> Vec<u8> {
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\ncomment hand made\nelement vertex {}\n",
        rows.len()
    );
    for (t, n) in props {
        h.push_str(&format!("property {t} {n}\n"));
    }
    h.push_str("element face 1\nproperty list uchar int vertex_indices\nend_header\n");
    let mut b = h.into_bytes();
    for r in rows {
        for ((t, _), v) in props.iter().zip(r) {
            match *t {
                "float" => b.extend_from_slice(&(*v as f32).to_le_bytes()),
                "double" => b.extend_from_slice(&v.to_le_bytes()),
                "uchar" => b.push(*v as u8),
                "int" => b.extend_from_slice(&(*v as i32).to_le_bytes()),
                _ => unreachable!(),
            }
        }
    }
    // The face element: a list of three ints.
    b.push(3);
    for i in 0..3i32 {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

#[test]
fn property_order_and_extra_properties_do_not_matter() {
    let props = [
        ("float", "opacity"),
        ("uchar", "red"),
        ("float", "rot_3"),
        ("double", "z"),
        ("float", "scale_2"),
        ("float", "f_dc_2"),
        ("float", "rot_0"),
        ("float", "x"),
        ("int", "label"),
        ("float", "f_dc_0"),
        ("float", "scale_0"),
        ("float", "rot_1"),
        ("float", "y"),
        ("float", "scale_1"),
        ("float", "f_dc_1"),
        ("float", "rot_2"),
    ];
    let rows = vec![
        vec![
            0.5, 7.0, 0.4, 3.0, -2.0, 0.3, 1.0, 1.0, 9.0, 0.1, -4.0, 0.2, 2.0, -3.0, 0.2, 0.3,
        ],
        vec![
            -1.5, 8.0, 0.0, 6.0, -1.0, 0.6, 0.5, 4.0, 1.0, 0.4, -2.5, 0.0, 5.0, -1.5, 0.5, 0.0,
        ],
    ];
    let s = parse(&custom_ply(&props, &rows)).unwrap();
    assert_eq!(s.len(), 2);
    assert_eq!(s.sh_degree, 0);
    assert_eq!(s.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(s.log_scales, vec![[-4.0, -3.0, -2.0], [-2.5, -1.5, -1.0]]);
    assert_eq!(
        s.rotations,
        vec![[1.0, 0.2, 0.3, 0.4], [0.5, 0.0, 0.0, 0.0]]
    );
    assert_eq!(s.opacity_logits, vec![0.5, -1.5]);
    assert_eq!(s.sh, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
}

#[test]
fn activations_follow_the_reference() {
    let mut s = Scene::empty(0);
    common::push_gaussian(&mut s, [0.0; 3], 0.5, 0.25, [0.5; 3]);
    s.rotations[0] = [2.0, 0.0, 0.0, 0.0];
    let a = s.activated();
    assert!((a.scales[0][0] - 0.5).abs() < 1e-6);
    assert!((a.opacities[0] - 0.25).abs() < 1e-6);
    assert_eq!(a.rotations[0], [1.0, 0.0, 0.0, 0.0]);
}

#[test]
fn model_directory_picks_the_largest_iteration() {
    let dir = tempfile::tempdir().unwrap();
    for (it, n) in [(7000, 3), (30000, 5), (900, 2)] {
        let d = dir.path().join(format!("point_cloud/iteration_{it}"));
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(
            d.join("point_cloud.ply"),
            ply::to_bytes(
                &random_scene(n, 1, it),
                ply::PlyEncoding::BinaryLittleEndian,
            ),
        )
        .unwrap();
    }
    // A higher iteration without a point cloud is ignored.
    std::fs::create_dir_all(dir.path().join("point_cloud/iteration_99999")).unwrap();
    let s = io::scene::load(dir.path()).unwrap();
    assert_eq!(s, random_scene(5, 1, 30000));
    let empty = tempfile::tempdir().unwrap();
    let e = io::scene::load(empty.path()).unwrap_err().to_string();
    assert!(e.contains("point_cloud"), "{e}");
}

#[test]
fn missing_file_names_the_file() {
    let e = io::scene::load(Path::new("/nonexistent/scene.ply"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/nonexistent/scene.ply") && e.contains("cannot read"),
        "{e}"
    );
}

#[test]
fn truncated_files_are_rejected_at_every_offset_class() {
    let full = ply::to_bytes(
        &random_scene(10, 3, 5),
        ply::PlyEncoding::BinaryLittleEndian,
    );
    let header_len = full.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    for cut in [
        4,
        20,
        header_len - 3,
        header_len,
        header_len + 1,
        header_len + 100,
        full.len() - 1,
    ] {
        let e = err(&full[..cut]);
        assert!(e.starts_with("test.ply: "), "{e}");
        assert!(
            e.contains("truncated") || e.contains("not a PLY"),
            "cut {cut}: {e}"
        );
    }
    // ASCII: drop the last row (a cut inside a number is indistinguishable from a shorter number).
    let ascii = ply::to_bytes(&random_scene(3, 0, 5), ply::PlyEncoding::Ascii);
    let last_row = ascii[..ascii.len() - 1]
        .iter()
        .rposition(|&b| b == b'\n')
        .unwrap();
    let e = err(&ascii[..last_row + 1]);
    assert!(e.contains("truncated"), "{e}");
}

/// Replaces `from` with `to` in the header of a binary PLY, leaving the data untouched.
fn edit_header(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..end])
        .unwrap()
        .replacen(from, to, 1);
    let mut out = header.into_bytes();
    out.extend_from_slice(&bytes[end..]);
    out
}

#[test]
fn header_that_lies_about_the_count() {
    let s = random_scene(10, 0, 9);
    let good = ply::to_bytes(&s, ply::PlyEncoding::BinaryLittleEndian);
    let e = err(&edit_header(
        &good,
        "element vertex 10",
        "element vertex 11",
    ));
    assert!(
        e.contains("declares 11 vertex") && e.contains("truncated or its header lies"),
        "{e}"
    );
    let e = err(&edit_header(&good, "element vertex 10", "element vertex 9"));
    assert!(e.contains("after the last element"), "{e}");
    // 2^40 claimed Gaussians fail before any allocation.
    let e = err(&edit_header(
        &good,
        "element vertex 10",
        "element vertex 1099511627776",
    ));
    assert!(e.contains("1099511627776"), "{e}");
}

#[test]
fn missing_required_property() {
    let s = random_scene(2, 0, 3);
    let text = String::from_utf8_lossy(&ply::to_bytes(&s, ply::PlyEncoding::Ascii)).replacen(
        "property float opacity\n",
        "",
        1,
    );
    // Remove the opacity column from the data rows too (it is the 10th value for degree 0).
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let start = lines.iter().position(|l| l == "end_header").unwrap() + 1;
    for l in &mut lines[start..] {
        let mut v: Vec<&str> = l.split(' ').collect();
        v.remove(9);
        *l = v.join(" ");
    }
    let e = err((lines.join("\n") + "\n").as_bytes());
    assert!(e.contains("missing the vertex property \"opacity\""), "{e}");
    let e = err(b"ply\nformat ascii 1.0\nelement face 0\nend_header\n");
    assert!(e.contains("no \"vertex\" element"), "{e}");
}

#[test]
fn non_finite_values_are_rejected_with_their_location() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut s = random_scene(4, 1, 7);
        s.log_scales[2][1] = bad;
        let e = err(&ply::to_bytes(&s, ply::PlyEncoding::BinaryLittleEndian));
        assert!(
            e.contains("vertex 2") && e.contains("scale_1") && e.contains("non-finite"),
            "{e}"
        );
    }
}

#[test]
fn zero_length_quaternion_is_rejected() {
    let mut s = random_scene(3, 0, 8);
    s.rotations[1] = [0.0; 4];
    let e = err(&ply::to_bytes(&s, ply::PlyEncoding::BinaryBigEndian));
    assert!(
        e.contains("vertex 1") && e.contains("zero-length rotation quaternion"),
        "{e}"
    );
}

#[test]
fn other_malformed_headers() {
    assert!(err(b"PK\x03\x04 zip").contains("not a PLY"));
    assert!(
        err(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n")
            .contains("no end_header")
    );
    assert!(err(b"ply\nformat weird 1.0\nend_header\n").contains("unknown PLY format"));
    assert!(
        err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quaternion x\nend_header\n")
            .contains("unknown property type")
    );
    let e = err(b"ply\nformat ascii 1.0\nelement vertex x\nend_header\n");
    assert!(e.contains("header line 3"), "{e}");
    let mut s = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
    for p in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3", "f_rest_0",
    ] {
        s.push_str(&format!("property float {p}\n"));
    }
    s.push_str("end_header\n");
    assert!(err(s.as_bytes()).contains("1 f_rest_* properties"));
    let ok = ply::to_bytes(&random_scene(1, 0, 1), ply::PlyEncoding::Ascii);
    let bad = String::from_utf8_lossy(&ok).replace("end_header\n", "end_header\nbanana ");
    assert!(err(bad.as_bytes()).contains("non-numeric value \"banana\""));
}
