//! PlayCanvas compressed PLY cases: the chunked-file builder and the cases.

use super::case::{scene_case, Case, Expect};
use super::ply::replace_first;
use verisplat::io::scene::compressed_ply::{CHUNK_PROPS, VERTEX_PROPS};

/// A PlayCanvas compressed PLY: `chunks` chunk rows of `bounds`, `verts` packed vertices of
/// type `packed_ty`, and the element counts the header declares.
pub(super) fn cply(
    declared_chunks: &str,
    declared_verts: &str,
    chunk_props: &[&str],
    packed_ty: &str,
    bounds: [f32; 18],
    verts: usize,
) -> Vec<u8> {
    let mut h = format!("ply\nformat binary_little_endian 1.0\nelement chunk {declared_chunks}\n");
    for p in chunk_props {
        h.push_str(&format!("property float {p}\n"));
    }
    h.push_str(&format!("element vertex {declared_verts}\n"));
    for p in VERTEX_PROPS {
        h.push_str(&format!("property {packed_ty} {p}\n"));
    }
    h.push_str("end_header\n");
    let mut b = h.into_bytes();
    if declared_chunks != "0" {
        for v in &bounds[..chunk_props.len()] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    for _ in 0..verts {
        // Centre of the bounds, identity-ish rotation, mid scale, opaque grey.
        for v in [
            1023u32 << 21 | 511 << 11 | 1023,
            0x1ff7_fdff,
            0x4000_0200,
            0x8080_80f0,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

pub(super) fn good_bounds() -> [f32; 18] {
    [
        -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, -4.0, -4.0, -4.0, -2.0, -2.0, -2.0, 0.0, 0.0, 0.0, 1.0,
        1.0, 1.0,
    ]
}

/// The table's cases for PlayCanvas compressed PLY.
pub(super) fn compressed_ply_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    let two_40 = "1099511627776";
    vec![
        scene_case(
            "cply_too_few_chunks",
            "s.compressed.ply",
            cply("1", "300", &CHUNK_PROPS, "uint", good_bounds(), 300),
            Error("has 1 chunks, too few for 300 Gaussians"),
        ),
        scene_case(
            "cply_vertex_count_2_pow_40",
            "s.compressed.ply",
            cply("1", two_40, &CHUNK_PROPS, "uint", good_bounds(), 1),
            Error("declares 1099511627776 vertex elements"),
        ),
        scene_case(
            "cply_float_packed",
            "s.compressed.ply",
            cply("1", "1", &CHUNK_PROPS, "float", good_bounds(), 1),
            Error("packed vertex properties are F32, not uint"),
        ),
        scene_case(
            "cply_missing_chunk_property",
            "s.compressed.ply",
            cply("1", "1", &CHUNK_PROPS[..17], "uint", good_bounds(), 1),
            Error("lacks the property \"max_b\""),
        ),
        scene_case(
            "cply_nan_bounds",
            "s.compressed.ply",
            {
                let mut b = good_bounds();
                b[0] = f32::NAN;
                cply("1", "1", &CHUNK_PROPS, "uint", b, 1)
            },
            Error("compressed PLY Gaussian 0 decodes to a non-finite value"),
        ),
        scene_case(
            "cply_inf_colour_bounds",
            "s.compressed.ply",
            {
                let mut b = good_bounds();
                b[15] = f32::INFINITY;
                cply("1", "1", &CHUNK_PROPS, "uint", b, 1)
            },
            Error("decodes to a non-finite SH coefficient"),
        ),
        scene_case(
            "cply_ascii",
            "s.compressed.ply",
            replace_first(
                &cply("1", "1", &CHUNK_PROPS, "uint", good_bounds(), 1),
                b"binary_little_endian",
                b"ascii",
            ),
            Error("not binary_little_endian"),
        ),
        scene_case(
            "cply_zero_gaussians",
            "s.compressed.ply",
            cply("0", "0", &CHUNK_PROPS, "uint", good_bounds(), 0),
            Renders(0),
        ),
        scene_case(
            "cply_one_gaussian",
            "s.compressed.ply",
            cply("1", "1", &CHUNK_PROPS, "uint", good_bounds(), 1),
            Renders(1),
        ),
    ]
}
