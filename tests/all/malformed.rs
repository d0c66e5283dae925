//! Malformed-input suite: a table of small hand-made bad (or odd but usable) files for every
//! scene and camera format, each with what must happen.
//!
//! The files are generated here (the table below is the source of truth) into a temporary
//! `malformed/<case>/` directory. Each case is checked twice:
//! * through the library (`scene::load`, `camera::load_camera_file`): an error is one
//!   sentence that names the file and contains the expected fragment; a usable file decodes
//!   to the stated number of Gaussians and renders correctly on the CPU reference;
//! * through the `vksplat` binary (with `VKSPLAT_VALIDATE=1`, under a timeout): a bad file
//!   gives one `error:` line with the same fragment, a non-zero exit, no panic and nothing
//!   in the output folder (no partial or temporary file); a usable one renders a PNG.
//!
//! Policy for values (the PLY loader's, applied to every format): a NaN or infinite value
//! in any attribute a Gaussian is rendered from (position, scale, rotation, opacity, SH)
//! is an error naming the Gaussian and the property: such values come from a diverged
//! training run and dropping them silently would hide that. Values the renderer does not
//! read (PLY normals, unknown extra properties) are ignored whatever they hold. Denormal
//! values, zero and negative log scales (a scale that underflows to 0 renders as the
//! 0.3-pixel dilation) and 0 Gaussians (the background) are valid. A `.splat` stores linear
//! scales, so a zero or negative scale there has no log scale and is an error.
//!
//! Truncation sweeps cut small valid files of every format at many offsets.

use crate::common;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use vksplat::camera::{self, Camera, PathTiming};
use vksplat::cpu::{self, RenderOptions};
use vksplat::scene::compressed_ply::{CHUNK_PROPS, VERTEX_PROPS};
use vksplat::scene::{self, Scene};

/// The longest a CLI run on a tiny file may take before it counts as a hang.
const CLI_TIMEOUT: Duration = Duration::from_secs(120);
/// Renders of usable cases are this small: the checks are about values, not detail.
const W: u32 = 64;
const H: u32 = 48;

/// What a case must do.
enum Expect {
    /// Loading fails with one sentence containing this fragment.
    Error(&'static str),
    /// The data is usable: it loads with this many Gaussians and renders (checked by
    /// [`check_render`]: the background for 0 Gaussians, else a visible splat at the centre).
    Renders(usize),
}

/// Which loader a case goes through.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Scene,
    Cameras,
}

struct Case {
    /// Directory name under `malformed/`, and the name used in failure messages.
    name: &'static str,
    kind: Kind,
    /// Files to write, relative to the case directory.
    files: Vec<(&'static str, Vec<u8>)>,
    /// What to load, relative to the case directory.
    arg: &'static str,
    expect: Expect,
}

fn scene_case(name: &'static str, file: &'static str, bytes: Vec<u8>, expect: Expect) -> Case {
    Case {
        name,
        kind: Kind::Scene,
        files: vec![(file, bytes)],
        arg: file,
        expect,
    }
}

fn camera_case(name: &'static str, file: &'static str, text: &str, expect: Expect) -> Case {
    Case {
        name,
        kind: Kind::Cameras,
        files: vec![(file, text.as_bytes().to_vec())],
        arg: file,
        expect,
    }
}

fn colmap_case(
    name: &'static str,
    cams: Vec<u8>,
    images: Vec<u8>,
    bin: bool,
    fragment: &'static str,
) -> Case {
    let (c, i) = if bin {
        ("model/cameras.bin", "model/images.bin")
    } else {
        ("model/cameras.txt", "model/images.txt")
    };
    Case {
        name,
        kind: Kind::Cameras,
        files: vec![(c, cams), (i, images)],
        arg: "model",
        expect: Expect::Error(fragment),
    }
}

// ---------------------------------------------------------------------------------------
// Builders for small files of each format.

/// The INRIA PLY vertex properties, in the trainer's order (SH degree 0).
const PLY_PROPS: [&str; 17] = [
    "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
    "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
];

/// One PLY row: a Gaussian at `pos` with log scale `log_scale`, quaternion `rot`, opacity
/// logit 2 (0.88) and a grey-ish colour.
fn ply_row(pos: [f32; 3], log_scale: f32, rot: [f32; 4]) -> [f32; 17] {
    [
        pos[0], pos[1], pos[2], 0.0, 0.0, 0.0, 0.5, 0.2, -0.3, 2.0, log_scale, log_scale,
        log_scale, rot[0], rot[1], rot[2], rot[3],
    ]
}

fn good_row() -> [f32; 17] {
    ply_row([0.0; 3], -2.0, [1.0, 0.0, 0.0, 0.0])
}

/// A PLY header with `element vertex {count}` and the given property lines.
fn ply_header(format: &str, count: &str, props: &[String]) -> String {
    let mut h = format!("ply\nformat {format} 1.0\nelement vertex {count}\n");
    for p in props {
        h.push_str(p);
        h.push('\n');
    }
    h.push_str("end_header\n");
    h
}

fn float_props() -> Vec<String> {
    PLY_PROPS
        .iter()
        .map(|p| format!("property float {p}"))
        .collect()
}

/// A binary little-endian PLY declaring `count` vertices and holding `rows`.
fn ply_le(count: &str, rows: &[[f32; 17]]) -> Vec<u8> {
    let mut b = ply_header("binary_little_endian", count, &float_props()).into_bytes();
    for r in rows {
        for v in r {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

/// A PLY with one good row but a changed property list.
fn ply_props(props: Vec<String>, row_bytes: usize) -> Vec<u8> {
    let mut b = ply_header("binary_little_endian", "1", &props).into_bytes();
    b.resize(b.len() + row_bytes, 0);
    b
}

fn ply_ascii(count: &str, rows: &[&str]) -> Vec<u8> {
    let mut b = ply_header("ascii", count, &float_props()).into_bytes();
    for r in rows {
        b.extend_from_slice(r.as_bytes());
        b.push(b'\n');
    }
    b
}

/// One `.splat` record.
fn splat_rec(p: [f32; 3], s: [f32; 3], q: [u8; 4]) -> Vec<u8> {
    let mut b = Vec::new();
    for v in p.iter().chain(&s) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(&[200, 100, 50, 230]);
    b.extend_from_slice(&q);
    b
}

const SPZ_MAGIC: u32 = 0x5053_474e;

fn spz_header(version: u32, count: u32, degree: u8, fractional_bits: u8, flags: u8) -> Vec<u8> {
    let mut h = Vec::new();
    h.extend_from_slice(&SPZ_MAGIC.to_le_bytes());
    h.extend_from_slice(&version.to_le_bytes());
    h.extend_from_slice(&count.to_le_bytes());
    h.extend_from_slice(&[degree, fractional_bits, flags, 0]);
    h
}

/// The six SPZ attribute arrays of `n` Gaussians at SH degree 0 (v3 rotations).
fn spz_streams(n: usize) -> Vec<Vec<u8>> {
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

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(bytes).unwrap();
    gz.finish().unwrap()
}

/// A gzip-wrapped SPZ v3 whose header declares `count` Gaussians and whose payload holds
/// `n`.
fn spz_v3(count: u32, n: usize) -> Vec<u8> {
    let mut b = spz_header(3, count, 0, 12, 0);
    b.extend(spz_streams(n).concat());
    gzip(&b)
}

/// A zstd frame holding `data` in one raw (stored) block.
fn zstd_raw(data: &[u8]) -> Vec<u8> {
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
fn spz_v4(count: u32, n: usize, toc_offset: u32, size_delta: u64) -> Vec<u8> {
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

/// A PlayCanvas compressed PLY: `chunks` chunk rows of `bounds`, `verts` packed vertices of
/// type `packed_ty`, and the element counts the header declares.
fn cply(
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

fn good_bounds() -> [f32; 18] {
    [
        -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, -4.0, -4.0, -4.0, -2.0, -2.0, -2.0, 0.0, 0.0, 0.0, 1.0,
        1.0, 1.0,
    ]
}

// SOG: a 4-Gaussian bundle with 2x2 textures (and a 192x1 SH palette).

fn webp(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut out)
        .encode(rgba, width, height, image::ExtendedColorType::Rgba8)
        .unwrap();
    out
}

fn sog_meta(
    count: &str,
    version: &str,
    codebook_len: usize,
    sh_count: u32,
    files_means: &str,
) -> String {
    let cb: Vec<String> = (0..256)
        .map(|i| format!("{}", -5.0 + i as f32 / 32.0))
        .collect();
    let short: Vec<String> = (0..codebook_len)
        .map(|i| format!("{}", i as f32 / 64.0))
        .collect();
    let (cb, short) = (cb.join(","), short.join(","));
    format!(
        r#"{{"version":{version},"count":{count},"means":{{"mins":[-1,-1,-1],"maxs":[1,1,1],"files":[{files_means}]}},"scales":{{"codebook":[{short}],"files":["scales.webp"]}},"quats":{{"files":["quats.webp"]}},"sh0":{{"codebook":[{cb}],"files":["sh0.webp"]}},"shN":{{"count":{sh_count},"bands":1,"codebook":[{cb}],"files":["shN_centroids.webp","shN_labels.webp"]}}}}"#
    )
}

fn good_sog_meta() -> String {
    sog_meta("4", "2", 256, 4, r#""means_l.webp","means_u.webp""#)
}

/// A stored zip of `meta` and the tiny SOG's textures, with `replace` swapping one of them.
fn sog_zip(meta: &str, replace: Option<(&str, Vec<u8>)>) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in sog_files(meta) {
        let bytes = match &replace {
            Some((r, b)) if *r == name => b.clone(),
            _ => bytes,
        };
        zip.start_file(name, opts).unwrap();
        zip.write_all(&bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// The files of the tiny SOG: `meta` and its WebP textures.
fn sog_files(meta: &str) -> Vec<(&'static str, Vec<u8>)> {
    let px = |f: &dyn Fn(u8) -> [u8; 4]| -> Vec<u8> { (0..4u8).flat_map(f).collect() };
    let centroids: Vec<u8> = (0..192u32)
        .flat_map(|i| [i as u8, 128, 255 - i as u8, 255])
        .collect();
    let files: Vec<(&str, Vec<u8>)> = vec![
        ("meta.json", meta.as_bytes().to_vec()),
        ("means_l.webp", webp(2, 2, &px(&|i| [17 * i, 3, 250, 255]))),
        (
            "means_u.webp",
            webp(2, 2, &px(&|i| [60 * i, 128, 127, 255])),
        ),
        ("scales.webp", webp(2, 2, &px(&|i| [100 + i, 90, 80, 255]))),
        ("quats.webp", webp(2, 2, &px(&|i| [128, 120, 140, 252 + i]))),
        ("sh0.webp", webp(2, 2, &px(&|i| [150, 160, 170, 200 + i]))),
        ("shN_centroids.webp", webp(192, 1, &centroids)),
        ("shN_labels.webp", webp(2, 2, &px(&|i| [i, 0, 0, 255]))),
    ];
    files
}

/// An unbundled SOG directory `sog/` (loaded as the directory).
fn sog_dir_case(name: &'static str, meta: &str, expect: Expect) -> Case {
    let names = [
        "sog/meta.json",
        "sog/means_l.webp",
        "sog/means_u.webp",
        "sog/scales.webp",
        "sog/quats.webp",
        "sog/sh0.webp",
        "sog/shN_centroids.webp",
        "sog/shN_labels.webp",
    ];
    let files = sog_files(meta);
    assert_eq!(files.len(), names.len());
    Case {
        name,
        kind: Kind::Scene,
        files: names
            .into_iter()
            .zip(files.into_iter().map(|(_, b)| b))
            .collect(),
        arg: "sog",
        expect,
    }
}

// Cameras.

fn inria_json(width: i64, fx: &str, rotation: &str) -> String {
    format!(
        r#"[{{"id":0,"img_name":"a","width":{width},"height":48,"position":[0,0,-3],"rotation":{rotation},"fx":{fx},"fy":50}}]"#
    )
}

const IDENTITY: &str = "[[1,0,0],[0,1,0],[0,0,1]]";

fn nerfstudio(camera_type: &str, c2w: &str, fov: &str) -> String {
    format!(
        r#"{{"camera_type":"{camera_type}","render_width":64,"render_height":48,"camera_path":[{{"camera_to_world":{c2w},"fov":{fov}}}]}}"#
    )
}

const C2W: &str = "[1,0,0,0, 0,1,0,0, 0,0,1,3, 0,0,0,1]";

fn keyframes(version: u32, frames: &str, keys: &str) -> String {
    format!(r#"{{"version":{version},"width":64,"height":48{frames},"keyframes":[{keys}]}}"#)
}

const KEY0: &str = r#"{"time":0,"position":[0,0,-3],"look_at":[0,0,0],"vfov":50}"#;
const KEY1: &str = r#"{"time":1,"position":[1,0,-3],"look_at":[0,0,0],"vfov":50}"#;

const COLMAP_CAMS: &str = "1 PINHOLE 64 48 50 50 32 24\n";
const COLMAP_IMAGES: &str = "1 1 0 0 0 0 0 3 1 a.png\n\n";

/// COLMAP binary files: one camera of `model_id` with `params`, and one image of camera 1
/// with quaternion `q` and `points` claimed 2D points (none stored).
fn colmap_bin(
    cam_count: u64,
    model_id: i32,
    params: &[f64],
    q: [f64; 4],
    points: u64,
) -> (Vec<u8>, Vec<u8>) {
    let mut c = Vec::new();
    c.extend_from_slice(&cam_count.to_le_bytes());
    c.extend_from_slice(&1i32.to_le_bytes());
    c.extend_from_slice(&model_id.to_le_bytes());
    c.extend_from_slice(&64u64.to_le_bytes());
    c.extend_from_slice(&48u64.to_le_bytes());
    for p in params {
        c.extend_from_slice(&p.to_le_bytes());
    }
    let mut i = Vec::new();
    i.extend_from_slice(&1u64.to_le_bytes());
    i.extend_from_slice(&1i32.to_le_bytes());
    for v in q.iter().chain(&[0.0, 0.0, 3.0]) {
        i.extend_from_slice(&v.to_le_bytes());
    }
    i.extend_from_slice(&1i32.to_le_bytes());
    i.extend_from_slice(b"a.png\0");
    i.extend_from_slice(&points.to_le_bytes());
    (c, i)
}

const PINHOLE: [f64; 4] = [50.0, 50.0, 32.0, 24.0];

// ---------------------------------------------------------------------------------------
// The table.

fn cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    let two_40 = "1099511627776";
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
    let nan_normal = {
        let mut r = good_row();
        r[3] = f32::NAN;
        r
    };
    let denormal = f32::from_bits(1); // the smallest positive subnormal
    let mut missing_opacity = float_props();
    missing_opacity.retain(|p| !p.ends_with(" opacity"));
    let mut five_rest = float_props();
    five_rest.extend((0..5).map(|i| format!("property float f_rest_{i}")));
    let mut bad_type = float_props();
    bad_type[9] = "property float128 opacity".into();
    let mut list_x = float_props();
    list_x[0] = "property list uchar float x".into();
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
    let splat_ok = |p, s| splat_rec(p, s, [255, 128, 128, 128]);

    let mut v = vec![
        // INRIA PLY: structure.
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
        // INRIA PLY: values.
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
        // INRIA PLY: odd but usable.
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
        // .splat.
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
        // SPZ.
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
        // PlayCanvas compressed PLY.
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
        // PlayCanvas SOG (zip bundles).
        scene_case(
            "sog_not_a_zip",
            "s.sog",
            b"PK\x03\x04 this is not a zip archive".to_vec(),
            Error("is not a readable zip archive"),
        ),
        scene_case(
            "sog_zip_truncated",
            "s.sog",
            {
                let z = sog_zip(&good_sog_meta(), None);
                z[..z.len() / 2].to_vec()
            },
            Error("is not a readable zip archive"),
        ),
        scene_case(
            "sog_bad_json",
            "s.sog",
            sog_zip("{\"version\": 2, \"count\": ", None),
            Error("has a SOG meta.json that is not valid"),
        ),
        scene_case(
            "sog_version_3",
            "s.sog",
            sog_zip(
                &sog_meta("4", "3", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("is SOG version 3"),
        ),
        scene_case(
            "sog_count_2_pow_40",
            "s.sog",
            sog_zip(
                &sog_meta(two_40, "2", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("too small for the 1099511627776 Gaussians"),
        ),
        scene_case(
            "sog_count_negative",
            "s.sog",
            sog_zip(
                &sog_meta("-4", "2", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("has a SOG meta.json that is not valid"),
        ),
        scene_case(
            "sog_short_codebook",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 10, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("SOG scales codebook of 10 entries"),
        ),
        scene_case(
            "sog_too_few_files",
            "s.sog",
            sog_zip(&sog_meta("4", "2", 256, 4, r#""means_l.webp""#), None),
            Error("whose means entry lists too few files"),
        ),
        scene_case(
            "sog_path_traversal",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 256, 4, r#""../means_l.webp","means_u.webp""#),
                None,
            ),
            Error("only plain file names beside meta.json are allowed"),
        ),
        scene_case(
            "sog_missing_entry",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 256, 4, r#""means_l.webp","nope.webp""#),
                None,
            ),
            Error("without a readable \"nope.webp\" entry"),
        ),
        scene_case(
            "sog_texture_not_webp",
            "s.sog",
            sog_zip(
                &good_sog_meta(),
                Some(("quats.webp", b"RIFF\x10\0\0\0WEBPjunkjunk".to_vec())),
            ),
            Error("cannot decode its SOG texture \"quats.webp\""),
        ),
        scene_case(
            "sog_texture_too_small",
            "s.sog",
            sog_zip(
                &good_sog_meta(),
                Some(("sh0.webp", webp(1, 1, &[1, 2, 3, 4]))),
            ),
            Error("\"sh0.webp\" of 1x1 pixels, too small for the 4 Gaussians"),
        ),
        scene_case(
            "sog_bad_quaternion_tag",
            "s.sog",
            sog_zip(
                &good_sog_meta(),
                Some(("quats.webp", webp(2, 2, &[128, 128, 128, 7].repeat(4)))),
            ),
            Error("invalid quaternion tag 7 for Gaussian 0"),
        ),
        scene_case(
            "sog_palette_label_too_large",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 256, 2, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("SH palette label 2 for Gaussian 2"),
        ),
        scene_case(
            "sog_zero_gaussians",
            "s.sog",
            sog_zip(
                &sog_meta("0", "2", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Renders(0),
        ),
        scene_case(
            "sog_four_gaussians",
            "s.sog",
            sog_zip(&good_sog_meta(), None),
            Renders(4),
        ),
        // PlayCanvas SOG (unbundled directories).
        sog_dir_case(
            "sog_dir_count_2_pow_40",
            &sog_meta(two_40, "2", 256, 4, r#""means_l.webp","means_u.webp""#),
            Error("too small for the 1099511627776 Gaussians"),
        ),
        sog_dir_case(
            "sog_dir_bad_json",
            "{\"version\": 2, \"count\": 4,",
            Error("has a SOG meta.json that is not valid"),
        ),
        sog_dir_case(
            "sog_dir_path_traversal",
            &sog_meta("4", "2", 256, 4, r#""../sog/means_l.webp","means_u.webp""#),
            Error("only plain file names beside meta.json are allowed"),
        ),
        sog_dir_case("sog_dir_four_gaussians", &good_sog_meta(), Renders(4)),
        // Content detection.
        scene_case(
            "unknown_bytes",
            "s.bin",
            b"GIF89a\x01\x00".to_vec(),
            Error("is not a recognised scene format"),
        ),
        scene_case(
            "meta_json_alone",
            "meta.json",
            b"{\"version\": 2}".to_vec(),
            Error("has a SOG meta.json that is not valid"),
        ),
        // INRIA cameras.json.
        camera_case(
            "cams_not_json",
            "cameras.json",
            "[{\"id\": 0,",
            Error("not valid JSON"),
        ),
        camera_case(
            "cams_empty_list",
            "cameras.json",
            "[]",
            Error("holds no cameras (INRIA cameras.json)"),
        ),
        camera_case(
            "cams_missing_fx",
            "cameras.json",
            &inria_json(64, "50", IDENTITY).replace("\"fx\":50,", ""),
            Error("missing field `fx`"),
        ),
        camera_case(
            "cams_zero_width",
            "cameras.json",
            &inria_json(0, "50", IDENTITY),
            Error("resolution 0x48 is not usable"),
        ),
        camera_case(
            "cams_negative_width",
            "cameras.json",
            &inria_json(-64, "50", IDENTITY),
            Error("is not an INRIA cameras.json"),
        ),
        camera_case(
            "cams_huge_width",
            "cameras.json",
            &inria_json(1 << 40, "50", IDENTITY),
            Error("is not an INRIA cameras.json"),
        ),
        camera_case(
            "cams_zero_fx",
            "cameras.json",
            &inria_json(64, "0", IDENTITY),
            Error("non-finite or non-positive intrinsics"),
        ),
        camera_case(
            "cams_fx_overflows",
            "cameras.json",
            &inria_json(64, "1e39", IDENTITY),
            Error("non-finite or non-positive intrinsics"),
        ),
        camera_case(
            "cams_fx_out_of_json_range",
            "cameras.json",
            &inria_json(64, "1e999", IDENTITY),
            Error("not valid JSON"),
        ),
        camera_case(
            "cams_singular_rotation",
            "cameras.json",
            &inria_json(64, "50", "[[1,0,0],[0,1,0],[0,0,0]]"),
            Error("rotation is not a rotation matrix (determinant 0.0000)"),
        ),
        camera_case(
            "cams_denormal_position",
            "cameras.json",
            &inria_json(64, "50", IDENTITY).replace("[0,0,-3]", "[4.9e-324,0,-3]"),
            Renders(1),
        ),
        // nerfstudio camera_path.json.
        camera_case(
            "ns_fisheye",
            "camera_path.json",
            &nerfstudio("fisheye", C2W, "50"),
            Error("camera_type \"fisheye\" is not supported"),
        ),
        camera_case(
            "ns_fifteen_numbers",
            "camera_path.json",
            &nerfstudio("perspective", "[1,0,0,0, 0,1,0,0, 0,0,1,3, 0,0,0]", "50"),
            Error("camera_to_world has 15 numbers"),
        ),
        camera_case(
            "ns_not_rigid",
            "camera_path.json",
            &nerfstudio("perspective", "[2,0,0,0, 0,1,0,0, 0,0,1,3, 0,0,0,1]", "50"),
            Error("is not a rigid transform"),
        ),
        camera_case(
            "ns_zero_fov",
            "camera_path.json",
            &nerfstudio("perspective", C2W, "0"),
            Error("fov 0 degrees must be between 0 and 180"),
        ),
        camera_case(
            "ns_no_fov",
            "camera_path.json",
            &nerfstudio("perspective", C2W, "null"),
            Error("has no \"fov\""),
        ),
        camera_case(
            "ns_zero_resolution",
            "camera_path.json",
            &nerfstudio("perspective", C2W, "50")
                .replace("\"render_width\":64", "\"render_width\":0"),
            Error("resolution 0x48 is not usable"),
        ),
        camera_case(
            "ns_empty_path",
            "camera_path.json",
            r#"{"render_width":64,"render_height":48,"camera_path":[]}"#,
            Error("holds no cameras"),
        ),
        // Keyframe paths.
        camera_case(
            "kf_version_2",
            "path.json",
            &keyframes(2, "", KEY0),
            Error("keyframe path version 2 is not supported"),
        ),
        camera_case(
            "kf_no_keyframes",
            "path.json",
            &keyframes(1, "", ""),
            Error("has no keyframes"),
        ),
        camera_case(
            "kf_times_not_increasing",
            "path.json",
            &keyframes(1, "", &format!("{KEY1},{KEY0}")),
            Error("keyframe times must be strictly increasing"),
        ),
        camera_case(
            "kf_zero_rotation",
            "path.json",
            &keyframes(
                1,
                "",
                r#"{"time":0,"position":[0,0,-3],"rotation":[0,0,0,0],"vfov":50}"#,
            ),
            Error("rotation [0.0, 0.0, 0.0, 0.0] has zero length"),
        ),
        camera_case(
            "kf_look_at_itself",
            "path.json",
            &keyframes(
                1,
                "",
                r#"{"time":0,"position":[0,0,-3],"look_at":[0,0,-3],"vfov":50}"#,
            ),
            Error("look_at is the camera position itself"),
        ),
        camera_case(
            "kf_frames_2_pow_40",
            "path.json",
            &keyframes(1, ",\"frames\":1099511627776", KEY0),
            Error("frames 1099511627776 must be between 1 and 1000000"),
        ),
        camera_case(
            "kf_frames_zero",
            "path.json",
            &keyframes(1, ",\"frames\":0", KEY0),
            Error("frames 0 must be between 1 and 1000000"),
        ),
        camera_case(
            "kf_fps_negative",
            "path.json",
            &keyframes(1, ",\"fps\":-30", KEY0),
            Error("fps -30 must be a positive number"),
        ),
        camera_case(
            "kf_too_long",
            "path.json",
            &keyframes(
                1,
                ",\"fps\":1e9",
                &format!("{KEY0},{}", KEY1.replace("\"time\":1", "\"time\":1e9")),
            ),
            Error("more than 1000000 frames"),
        ),
        camera_case(
            "kf_unknown_field",
            "path.json",
            &keyframes(1, ",\"speed\":3", KEY0),
            Error("unknown field `speed`"),
        ),
        camera_case(
            "kf_two_frames",
            "path.json",
            &keyframes(1, ",\"frames\":2", &format!("{KEY0},{KEY1}")),
            Renders(2),
        ),
        // COLMAP text.
        colmap_case(
            "colmap_unknown_model",
            b"1 PINHOLEX 64 48 50 50 32 24\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "unknown camera model \"PINHOLEX\"",
        ),
        colmap_case(
            "colmap_fisheye",
            b"1 OPENCV_FISHEYE 64 48 50 50 32 24 0 0 0 0\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "a fisheye projection",
        ),
        colmap_case(
            "colmap_distortion",
            b"1 SIMPLE_RADIAL 64 48 50 32 24 0.1\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "non-zero distortion (parameter 0.1)",
        ),
        colmap_case(
            "colmap_too_few_params",
            b"1 PINHOLE 64 48 50 50 32\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "model PINHOLE takes 4 parameters, the line has 3",
        ),
        colmap_case(
            "colmap_width_2_pow_40",
            b"1 PINHOLE 1099511627776 48 50 50 32 24\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "resolution 1099511627776x48 is not usable",
        ),
        colmap_case(
            "colmap_nan_focal",
            b"1 PINHOLE 64 48 nan 50 32 24\n".to_vec(),
            COLMAP_IMAGES.into(),
            false,
            "non-finite or non-positive intrinsics",
        ),
        colmap_case(
            "colmap_zero_quaternion",
            COLMAP_CAMS.into(),
            b"1 0 0 0 0 0 0 3 1 a.png\n\n".to_vec(),
            false,
            "quaternion [0.0, 0.0, 0.0, 0.0] has zero length",
        ),
        colmap_case(
            "colmap_inf_translation",
            COLMAP_CAMS.into(),
            b"1 1 0 0 0 inf 0 3 1 a.png\n\n".to_vec(),
            false,
            "translation [inf, 0.0, 3.0] is not finite",
        ),
        colmap_case(
            "colmap_missing_camera",
            COLMAP_CAMS.into(),
            b"1 1 0 0 0 0 0 3 9 a.png\n\n".to_vec(),
            false,
            "refers to camera 9, which the cameras file does not have",
        ),
        colmap_case(
            "colmap_short_image_line",
            COLMAP_CAMS.into(),
            b"1 1 0 0 0 0 0 3\n\n".to_vec(),
            false,
            "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
        ),
        colmap_case(
            "colmap_no_images",
            COLMAP_CAMS.into(),
            b"# nothing\n".to_vec(),
            false,
            "holds no cameras",
        ),
        // COLMAP binary.
        {
            let (c, i) = colmap_bin(1 << 40, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_camera_count_2_pow_40",
                c,
                i,
                true,
                "claims 1099511627776 cameras",
            )
        },
        {
            let (c, i) = colmap_bin(1, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 1 << 40);
            colmap_case(
                "colmap_bin_points_2_pow_40",
                c,
                i,
                true,
                "claims 1099511627776 2D points",
            )
        },
        {
            let (c, i) = colmap_bin(1, 42, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_unknown_model",
                c,
                i,
                true,
                "unknown camera model id 42",
            )
        },
        {
            let (c, i) = colmap_bin(1, 1, &PINHOLE[..3], [1.0, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_truncated_params",
                c,
                i,
                true,
                "truncated: needs 8 bytes for the camera parameter",
            )
        },
        {
            let (c, i) = colmap_bin(1, 1, &PINHOLE, [f64::NAN, 0.0, 0.0, 0.0], 0);
            colmap_case(
                "colmap_bin_nan_quaternion",
                c,
                i,
                true,
                "has zero length or is not finite",
            )
        },
        {
            let (c, mut i) = colmap_bin(1, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
            i.extend_from_slice(&[1, 2, 3]);
            colmap_case(
                "colmap_bin_trailing_bytes",
                c,
                i,
                true,
                "has 3 unexpected bytes after the last record",
            )
        },
    ];
    // A COLMAP model that is fine renders.
    v.push(Case {
        name: "colmap_ok",
        kind: Kind::Cameras,
        files: vec![
            ("model/cameras.txt", COLMAP_CAMS.into()),
            ("model/images.txt", COLMAP_IMAGES.into()),
        ],
        arg: "model",
        expect: Renders(1),
    });
    v
}

/// `bytes` with the first occurrence of `from` replaced by `to`.
fn replace_first(bytes: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    let at = bytes
        .windows(from.len())
        .position(|w| w == from)
        .expect("present");
    [&bytes[..at], to, &bytes[at + from.len()..]].concat()
}

// ---------------------------------------------------------------------------------------
// Checks.

fn write_case(root: &Path, case: &Case) -> PathBuf {
    let dir = root.join(case.name);
    for (name, bytes) in &case.files {
        let p = dir.join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, bytes).unwrap();
    }
    dir.join(case.arg)
}

/// A camera looking at the origin from `(0, 0, -3)`, `W`x`H`.
fn test_camera() -> Camera {
    Camera::look_at(
        "t",
        W,
        H,
        50f32.to_radians(),
        glam::Vec3::new(0.0, 0.0, -3.0),
        glam::Vec3::ZERO,
        glam::Vec3::NEG_Y,
    )
}

/// A usable scene renders with finite values: the background for no Gaussians, otherwise
/// colour at the image centre where the splat(s) sit.
fn check_render(name: &str, s: &Scene) {
    let bg = [0.25, 0.5, 0.75];
    let frame = cpu::render(
        &s.activated(),
        &test_camera(),
        &RenderOptions {
            background: bg,
            ..Default::default()
        },
    );
    assert!(
        frame
            .color
            .iter()
            .flatten()
            .chain(&frame.alpha)
            .chain(&frame.depth)
            .all(|v| v.is_finite()),
        "{name}: non-finite pixels"
    );
    if s.is_empty() {
        assert!(
            frame.color.iter().all(|c| *c == bg),
            "{name}: not the background"
        );
        assert!(frame.alpha.iter().all(|&a| a == 0.0), "{name}: alpha");
    } else {
        let centre = (H / 2 * W + W / 2) as usize;
        assert!(
            frame.alpha[centre] > 0.3,
            "{name}: centre alpha {}",
            frame.alpha[centre]
        );
    }
}

/// An error must be one sentence that names the file and contains the fragment.
fn check_message(name: &str, msg: &str, file: &Path, fragment: &str) {
    assert!(!msg.contains('\n'), "{name}: more than one line: {msg}");
    let dir = file.parent().unwrap().to_string_lossy().into_owned();
    assert!(
        msg.contains(&dir) || msg.contains(&*file.to_string_lossy()),
        "{name}: does not name the file: {msg}"
    );
    assert!(
        msg.contains(fragment),
        "{name}: expected \"{fragment}\" in: {msg}"
    );
}

fn library_check(case: &Case, path: &Path) {
    let name = case.name;
    match case.kind {
        Kind::Scene => match (scene::load(path), &case.expect) {
            (Err(e), Expect::Error(frag)) => check_message(name, &e.to_string(), path, frag),
            (Ok(s), Expect::Renders(n)) => {
                assert_eq!(s.len(), *n, "{name}");
                s.check_consistent().unwrap();
                check_render(name, &s);
            }
            (Ok(s), Expect::Error(frag)) => {
                panic!("{name}: loaded {} Gaussians, expected \"{frag}\"", s.len())
            }
            (Err(e), Expect::Renders(_)) => panic!("{name}: {e}"),
        },
        Kind::Cameras => match (
            camera::load_camera_file(path, &PathTiming::default()),
            &case.expect,
        ) {
            (Err(e), Expect::Error(frag)) => check_message(name, &e.to_string(), path, frag),
            (Ok((cams, _)), Expect::Renders(n)) => {
                assert_eq!(cams.len(), *n, "{name}");
                for c in &cams {
                    c.validate().unwrap();
                }
            }
            (Ok((cams, _)), Expect::Error(frag)) => {
                panic!("{name}: loaded {} cameras, expected \"{frag}\"", cams.len())
            }
            (Err(e), Expect::Renders(_)) => panic!("{name}: {e}"),
        },
    }
}

/// Runs the binary with a timeout; returns (success, stderr).
fn run_cli(args: &[&std::ffi::OsStr], stderr_file: &Path) -> (bool, String) {
    let err = std::fs::File::create(stderr_file).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_vksplat"))
        .args(args)
        .env("VKSPLAT_VALIDATE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > CLI_TIMEOUT {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("vksplat {args:?} hung (killed after {CLI_TIMEOUT:?})");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (
        status.success(),
        std::fs::read_to_string(stderr_file).unwrap(),
    )
}

/// Renders through the CLI: a bad file fails cleanly with nothing written, a usable one
/// writes its frames.
fn cli_check(case_name: &str, kind: Kind, path: &Path, expect: &Expect, work: &Path) {
    let out_dir = work.join(format!("{case_name}.out"));
    std::fs::create_dir_all(&out_dir).unwrap();
    let (w, h) = (W.to_string(), H.to_string());
    let mut args: Vec<&std::ffi::OsStr> = vec!["render".as_ref()];
    match kind {
        Kind::Scene => args.push(path.as_os_str()),
        Kind::Cameras => args.extend(["--demo".as_ref(), "--cameras".as_ref(), path.as_os_str()]),
    }
    let out = out_dir.join("frame_{:05}.png");
    args.extend([
        "--cpu".as_ref(),
        "-q".as_ref(),
        "--width".as_ref(),
        w.as_ref(),
        "--height".as_ref(),
        h.as_ref(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    let (ok, stderr) = run_cli(&args, &work.join(format!("{case_name}.stderr")));
    assert!(
        !stderr.contains("panicked"),
        "{case_name}: the CLI panicked: {stderr}"
    );
    let written: Vec<_> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    match expect {
        Expect::Error(frag) => {
            assert!(!ok, "{case_name}: the CLI succeeded on a bad file");
            assert!(stderr.starts_with("error: "), "{case_name}: {stderr}");
            assert_eq!(
                stderr.trim_end().lines().count(),
                1,
                "{case_name}: one line: {stderr}"
            );
            assert!(
                stderr.contains(frag),
                "{case_name}: expected \"{frag}\" in: {stderr}"
            );
            assert!(
                written.is_empty(),
                "{case_name}: the failed run left {written:?}"
            );
        }
        Expect::Renders(n) => {
            assert!(ok, "{case_name}: {stderr}");
            let frames = if kind == Kind::Cameras { *n } else { 1 };
            assert_eq!(written.len(), frames, "{case_name}: wrote {written:?}");
            for f in &written {
                let img = image::open(out_dir.join(f)).unwrap();
                assert_eq!((img.width(), img.height()), (W, H), "{case_name}");
            }
        }
    }
}

#[test]
fn every_malformed_case_fails_clearly_or_renders_through_the_library() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("malformed");
    let cases = cases();
    let mut names = std::collections::HashSet::new();
    for case in &cases {
        assert!(names.insert(case.name), "duplicate case {}", case.name);
        let path = write_case(&root, case);
        library_check(case, &path);
    }
}

#[test]
fn every_malformed_case_fails_clearly_or_renders_through_the_cli() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("malformed");
    let work = tmp.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    for case in &cases() {
        let path = write_case(&root, case);
        cli_check(case.name, case.kind, &path, &case.expect, &work);
    }
}

// ---------------------------------------------------------------------------------------
// Truncation sweeps.

/// Small valid files of every scene format, with the loader's name for them.
fn valid_scene_files() -> Vec<(&'static str, Vec<u8>)> {
    let s = common::random_scene(5, 3, 11);
    let s0 = common::random_scene(3, 0, 12);
    vec![
        (
            "t.ply",
            scene::ply::to_bytes(&s, scene::ply::PlyEncoding::BinaryLittleEndian),
        ),
        (
            "t_be.ply",
            scene::ply::to_bytes(&s0, scene::ply::PlyEncoding::BinaryBigEndian),
        ),
        (
            "t_ascii.ply",
            scene::ply::to_bytes(&s0, scene::ply::PlyEncoding::Ascii),
        ),
        ("t.splat", scene::splat::to_bytes(&s)),
        ("t.spz", scene::spz::to_bytes_v3(&s).unwrap()),
        ("t_v4.spz", spz_v4(3, 3, 32, 0)),
        (
            "t.compressed.ply",
            cply("1", "3", &CHUNK_PROPS, "uint", good_bounds(), 3),
        ),
        ("t.sog", sog_zip(&good_sog_meta(), None)),
    ]
}

/// Fragments a truncated file's error may contain: each says the file is cut short or
/// is no longer recognisable as its format.
const TRUNCATION_FRAGMENTS: [&str; 10] = [
    "truncated",
    "is empty (0 bytes)",
    "header lies",
    "not a recognised scene format",
    "not a multiple of the 32-byte",
    "not a readable zip",
    "corrupt",
    "no end_header",
    "does not start with the SPZ magic",
    "non-numeric value",
];

fn truncation_ok(name: &str, cut: usize) -> bool {
    // A .splat cut at a record boundary is a valid, shorter .splat (and empty is empty).
    name.ends_with(".splat") && cut % 32 == 0
}

#[test]
fn truncated_scene_files_fail_clearly_at_every_offset() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, bytes) in valid_scene_files() {
        let full = tmp.path().join(name);
        std::fs::write(&full, &bytes).unwrap();
        scene::load(&full).unwrap_or_else(|e| panic!("the uncut {name} must load: {e}"));
        for cut in 0..bytes.len() {
            let path = tmp.path().join(format!("cut_{cut}_{name}"));
            std::fs::write(&path, &bytes[..cut]).unwrap();
            match scene::load(&path) {
                Ok(s) => assert!(
                    truncation_ok(name, cut),
                    "{name} cut at {cut} loaded {} Gaussians",
                    s.len()
                ),
                Err(e) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains(&*path.to_string_lossy()) && !msg.contains('\n'),
                        "{msg}"
                    );
                    assert!(
                        TRUNCATION_FRAGMENTS.iter().any(|f| msg.contains(f)),
                        "{name} cut at {cut}: unexpected message: {msg}"
                    );
                }
            }
            std::fs::remove_file(&path).unwrap();
        }
    }
}

#[test]
fn truncated_camera_files_fail_clearly_at_every_offset() {
    let json = [
        ("cameras.json", inria_json(64, "50", IDENTITY)),
        ("camera_path.json", nerfstudio("perspective", C2W, "50")),
        (
            "path.json",
            keyframes(1, ",\"frames\":2", &format!("{KEY0},{KEY1}")),
        ),
    ];
    let tmp = tempfile::tempdir().unwrap();
    for (name, text) in &json {
        for cut in 0..text.len() {
            let path = tmp.path().join(format!("cut_{cut}_{name}"));
            std::fs::write(&path, &text.as_bytes()[..cut]).unwrap();
            let e = camera::load_camera_file(&path, &PathTiming::default())
                .expect_err(&format!("{name} cut at {cut}"));
            let msg = e.to_string();
            assert!(
                msg.contains(&*path.to_string_lossy()) && !msg.contains('\n'),
                "{msg}"
            );
            assert!(
                msg.contains("not valid JSON") || msg.contains("EOF"),
                "{name} cut at {cut}: {msg}"
            );
        }
    }
    // COLMAP binary: cut either file anywhere.
    let (c, i) = colmap_bin(1, 1, &PINHOLE, [1.0, 0.0, 0.0, 0.0], 0);
    for which in 0..2 {
        let full = if which == 0 { &c } else { &i };
        for cut in 0..full.len() {
            let dir = tmp.path().join(format!("bin_{which}_{cut}"));
            std::fs::create_dir_all(&dir).unwrap();
            let (cc, ii) = if which == 0 {
                (&c[..cut], &i[..])
            } else {
                (&c[..], &i[..cut])
            };
            std::fs::write(dir.join("cameras.bin"), cc).unwrap();
            std::fs::write(dir.join("images.bin"), ii).unwrap();
            let e = camera::load_camera_file(&dir, &PathTiming::default())
                .expect_err(&format!("COLMAP binary file {which} cut at {cut}"));
            let msg = e.to_string();
            assert!(
                msg.contains("truncated") || msg.contains("claims"),
                "file {which} cut at {cut}: {msg}"
            );
        }
    }
}

#[test]
fn truncated_scene_files_fail_cleanly_through_the_cli() {
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    for (name, bytes) in valid_scene_files() {
        let len = bytes.len();
        let mut cuts = vec![0, 1, 3, 7, 16, len / 3, len / 2, len - 1];
        cuts.sort();
        cuts.dedup();
        for cut in cuts {
            if truncation_ok(name, cut) {
                continue;
            }
            let case = format!("cut_{cut}_{name}");
            let path = tmp.path().join(&case);
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let msg = scene::load(&path).expect_err(&case).to_string();
            let frag = TRUNCATION_FRAGMENTS
                .iter()
                .find(|f| msg.contains(*f))
                .unwrap();
            cli_check(&case, Kind::Scene, &path, &Expect::Error(frag), &work);
        }
    }
}
