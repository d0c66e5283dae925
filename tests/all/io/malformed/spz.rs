//! SPZ cases: builders for gzip-wrapped v3 and zstd-framed v4 files, and the cases.

use super::case::{scene_case, Case, Expect};
use std::io::Write;

pub(super) const SPZ_MAGIC: u32 = 0x5053_474e;

pub(super) fn spz_header(
    version: u32,
    count: u32,
    degree: u8,
    fractional_bits: u8,
    flags: u8,
) -> Vec<u8> {
    let mut h = Vec::new();
    h.extend_from_slice(&SPZ_MAGIC.to_le_bytes());
    h.extend_from_slice(&version.to_le_bytes());
    h.extend_from_slice(&count.to_le_bytes());
    h.extend_from_slice(&[degree, fractional_bits, flags, 0]);
    h
}

/// The six SPZ attribute arrays of `n` Gaussians at SH degree 0 (v3 rotations).
pub(super) fn spz_streams(n: usize) -> Vec<Vec<u8>> {
    vec![
        vec![0u8; 9 * n],
        vec![200u8; n],
        vec![128u8; 3 * n],
        vec![100u8; 3 * n],
        // Smallest three with every kept component 0: the identity.
        vec![0u8; 4 * n],
        Vec::new(),
    ]
}

pub(super) fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(bytes).unwrap();
    gz.finish().unwrap()
}

/// A gzip-wrapped SPZ v3 whose header declares `count` Gaussians and whose payload holds
/// `n`.
pub(super) fn spz_v3(count: u32, n: usize) -> Vec<u8> {
    let mut b = spz_header(3, count, 0, 12, 0);
    b.extend(spz_streams(n).concat());
    gzip(&b)
}

/// A zstd frame holding `data` in one raw (stored) block.
pub(super) fn zstd_raw(data: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    f.extend_from_slice(&0xFD2F_B528u32.to_le_bytes());
    // Frame header descriptor: single segment, 4-byte content size.
    f.push(0xA0);
    f.extend_from_slice(&(data.len() as u32).to_le_bytes());
    // Block header: last block, raw, size.
    f.extend_from_slice(&((data.len() as u32) << 3 | 1).to_le_bytes()[..3]);
    f.extend_from_slice(data);
    f
}

/// An SPZ v4 of `n` Gaussians (SH degree 0, 5 streams); `toc_offset` and the table's
/// uncompressed sizes can be made to lie.
pub(super) fn spz_v4(count: u32, n: usize, toc_offset: u32, size_delta: u64) -> Vec<u8> {
    let streams: Vec<Vec<u8>> = spz_streams(n).into_iter().take(5).collect();
    let frames: Vec<Vec<u8>> = streams.iter().map(|s| zstd_raw(s)).collect();
    let mut b = spz_header(4, count, 0, 12, 0);
    b[15] = 5;
    b.extend_from_slice(&toc_offset.to_le_bytes());
    b.extend_from_slice(&[0u8; 12]);
    for (f, s) in frames.iter().zip(&streams) {
        b.extend_from_slice(&(f.len() as u64).to_le_bytes());
        b.extend_from_slice(&(s.len() as u64 + size_delta).to_le_bytes());
    }
    b.extend(frames.concat());
    b
}

/// The table's cases for SPZ.
pub(super) fn spz_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    vec![
        scene_case(
            "spz_count_lies",
            "s.spz",
            spz_v3(1000, 2),
            Error("declares 1000 Gaussians"),
        ),
        scene_case(
            "spz_count_2_pow_32",
            "s.spz",
            spz_v3(u32::MAX, 2),
            Error("declares 4294967295 Gaussians"),
        ),
        scene_case(
            "spz_count_too_small",
            "s.spz",
            spz_v3(1, 2),
            Error("holds more data than its SPZ header declares"),
        ),
        scene_case(
            "spz_bare_count_lies",
            "s.spz",
            [spz_header(3, 7, 0, 12, 0), spz_streams(2).concat()].concat(),
            Error("declares 7 Gaussians"),
        ),
        scene_case(
            "spz_version_1",
            "s.spz",
            gzip(&spz_header(1, 0, 0, 12, 0)),
            Error("SPZ version 1"),
        ),
        scene_case(
            "spz_version_9",
            "s.spz",
            gzip(&spz_header(9, 0, 0, 12, 0)),
            Error("is SPZ version 9"),
        ),
        scene_case(
            "spz_sh_degree_4",
            "s.spz",
            gzip(&spz_header(3, 0, 4, 12, 0)),
            Error("declares SH degree 4"),
        ),
        scene_case(
            "spz_fractional_bits_30",
            "s.spz",
            gzip(&spz_header(3, 0, 0, 30, 0)),
            Error("declares 30 fractional bits"),
        ),
        scene_case(
            "spz_extensions_flag",
            "s.spz",
            gzip(&spz_header(3, 0, 0, 12, 2)),
            Error("uses SPZ extensions"),
        ),
        scene_case(
            "spz_truncated_gzip",
            "s.spz",
            {
                let b = spz_v3(2, 2);
                b[..b.len() - 12].to_vec()
            },
            Error("corrupt or truncated gzip stream"),
        ),
        scene_case(
            "spz_header_truncated",
            "s.spz",
            gzip(&spz_header(3, 0, 0, 12, 0)[..10]),
            Error("its SPZ header needs 16 bytes but only 10 are there"),
        ),
        scene_case(
            "spz_v4_in_gzip",
            "s.spz",
            gzip(&spz_header(4, 0, 0, 12, 0)),
            Error("version 4 files are not gzip-wrapped"),
        ),
        scene_case(
            "spz_v4_toc_outside",
            "s.spz",
            spz_v4(2, 2, 1 << 30, 0),
            Error("table of contents at byte 1073741824 does not fit"),
        ),
        scene_case(
            "spz_v4_stream_size_lies",
            "s.spz",
            spz_v4(2, 2, 32, 5),
            Error("positions stream of 23 bytes"),
        ),
        scene_case(
            "spz_v4_count_2_pow_32",
            "s.spz",
            spz_v4(u32::MAX, 2, 32, 0),
            Error("but 4294967295 Gaussians need"),
        ),
        scene_case(
            "spz_v4_header_truncated",
            "s.spz",
            spz_v4(2, 2, 32, 0)[..20].to_vec(),
            Error("SPZ v4 header needs 32 bytes"),
        ),
        scene_case("spz_zero_gaussians", "s.spz", spz_v3(0, 0), Renders(0)),
        scene_case(
            "spz_v4_zero_gaussians",
            "s.spz",
            spz_v4(0, 0, 32, 0),
            Renders(0),
        ),
        scene_case(
            "spz_two_gaussians",
            "s.spz",
            spz_v4(2, 2, 32, 0),
            Renders(2),
        ),
    ]
}
