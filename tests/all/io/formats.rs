//! Scene formats: each loader on the real files in `../shared/data/` against the INRIA PLY
//! of the same Gaussians (per-field bounds derived from each format's quantisation),
//! renders of the same camera (PSNR), writer round trips, malformed input and the
//! `convert` / `info` commands.

use crate::common;
use crate::common::cli::{s, stderr, verisplat};
use std::path::{Path, PathBuf};
use verisplat::core::camera;
use verisplat::core::scene::{self, sigmoid, Scene};
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;
use verisplat::io::scene::spz::SpzCompression;
use verisplat::io::scene::write::{self, OutputFormat};
use verisplat::io::scene::{ply, SceneFormat};

const SH_C0: f32 = verisplat::cpu::sh::SH_C0;
/// Slack for f32 evaluation differences between two decoders of the same bytes.
const F32_SLACK: f32 = 1e-5;

fn data(name: &str) -> PathBuf {
    common::shared_data().join(name)
}

fn load(name: &str) -> (Scene, SceneFormat) {
    io::scene::load_with_format(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Largest per-field differences between two scenes whose Gaussian `i` of `a` corresponds
/// to Gaussian `map[i]` of `b`.
#[derive(Debug, Default)]
struct FieldErrors {
    position: f32,
    log_scale: f32,
    /// Largest component difference of the normalised quaternions, sign aligned.
    rotation: f32,
    /// Difference of `sigmoid(logit)`.
    opacity: f32,
    /// Difference of the DC term (f_dc units), over the Gaussians `dc_included` keeps.
    dc: f32,
    /// Difference of band 1 coefficients and of bands 2 and 3.
    sh1: f32,
    sh_rest: f32,
    dc_excluded: usize,
}

fn field_errors(
    a: &Scene,
    b: &Scene,
    map: &[usize],
    dc_included: impl Fn(f32) -> bool,
    sh_expected: impl Fn(f32) -> f32,
) -> FieldErrors {
    let mut e = FieldErrors::default();
    let (sa, sb) = (a.sh_stride(), b.sh_stride());
    let shared = sa.min(sb);
    for (i, &j) in map.iter().enumerate() {
        for k in 0..3 {
            e.position = e
                .position
                .max((a.positions[i][k] - b.positions[j][k]).abs());
            e.log_scale = e
                .log_scale
                .max((a.log_scales[i][k] - b.log_scales[j][k]).abs());
        }
        let qa = scene::normalize_quat(a.rotations[i]);
        let qb = scene::normalize_quat(b.rotations[j]);
        let dot: f32 = qa.iter().zip(&qb).map(|(x, y)| x * y).sum();
        for k in 0..4 {
            e.rotation = e.rotation.max((qa[k] - dot.signum() * qb[k]).abs());
        }
        e.opacity = e
            .opacity
            .max((sigmoid(a.opacity_logits[i]) - sigmoid(b.opacity_logits[j])).abs());
        let dca = &a.sh[i * sa..i * sa + 3];
        if dca.iter().all(|&v| dc_included(v)) {
            for (x, y) in dca.iter().zip(&b.sh[j * sb..j * sb + 3]) {
                e.dc = e.dc.max((x - y).abs());
            }
        } else {
            e.dc_excluded += 1;
        }
        for k in 3..shared {
            let d = (sh_expected(a.sh[i * sa + k]) - b.sh[j * sb + k]).abs();
            if k < 12 {
                e.sh1 = e.sh1.max(d);
            } else {
                e.sh_rest = e.sh_rest.max(d);
            }
        }
    }
    e
}

fn identity(n: usize) -> Vec<usize> {
    (0..n).collect()
}

/// For each position of `a`, the index of the nearest position of `b` (uniform grid).
fn nearest_map(a: &[[f32; 3]], b: &[[f32; 3]]) -> Vec<usize> {
    let cell = 0.01f32;
    let key = |p: &[f32; 3]| p.map(|v| (v / cell).floor() as i64);
    let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> = Default::default();
    for (j, p) in b.iter().enumerate() {
        grid.entry(key(p)).or_default().push(j);
    }
    a.iter()
        .map(|p| {
            let k = key(p);
            let mut best = (f32::INFINITY, usize::MAX);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                            for &j in list {
                                let d: f32 = (0..3).map(|c| (p[c] - b[j][c]).powi(2)).sum();
                                if d < best.0 {
                                    best = (d, j);
                                }
                            }
                        }
                    }
                }
            }
            assert!(best.1 != usize::MAX, "no neighbour within a cell of {p:?}");
            best.1
        })
        .collect()
}

/// Bounds of one comparison, one per field of [`FieldErrors`].
#[derive(Debug)]
struct Bounds {
    position: f32,
    log_scale: f32,
    rotation: f32,
    opacity: f32,
    dc: f32,
    sh1: f32,
    sh_rest: f32,
}

fn check(name: &str, e: &FieldErrors, b: &Bounds) {
    println!("{name}: measured {e:?}");
    let ok = e.position <= b.position
        && e.log_scale <= b.log_scale
        && e.rotation <= b.rotation
        && e.opacity <= b.opacity
        && e.dc <= b.dc
        && e.sh1 <= b.sh1
        && e.sh_rest <= b.sh_rest;
    assert!(ok, "{name}: {e:?} exceeds {b:?}");
}

// SPZ (Niantic's default encoder): positions are 24-bit fixed point with 12 fractional bits
// in these files (half a step, 2^-13); log scales are bytes of 1/16 (half step 1/32);
// quaternions keep three components as 9-bit magnitudes of sqrt(1/2)/511 (half step 6.9e-4)
// and rebuild the largest from them, which can amplify that about threefold (3e-3);
// alpha is one byte (half step 0.5/255); the DC term is a byte of 1/(0.15*255) (half step
// 0.0131) and saturates at |f_dc| = 3.33, so Gaussians with |f_dc| > 3.3 are left out of the
// colour comparison (248 in the PLAYBOT LOD3 file, see the data README); SH bytes are
// `(b - 128) / 128` on a grid of 8 (band 1) or 16 (bands 2, 3) values, so half a bucket
// (1/32, 1/16) off the value clamped to [-1, 127/128], plus one byte (1/128) because
// Niantic's current encoder quantises with `round((x + 1) * 127.5)` while the decoder
// inverts `x * 128 + 128`.
const SPZ_BOUNDS: Bounds = Bounds {
    position: 1.0 / 8192.0 + 1e-6,
    log_scale: 1.0 / 32.0 + F32_SLACK,
    rotation: 3e-3,
    opacity: 0.5 / 255.0 + 1e-6,
    dc: 0.5 / (0.15 * 255.0) + F32_SLACK,
    sh1: 4.0 / 128.0 + 1.0 / 128.0 + F32_SLACK,
    sh_rest: 8.0 / 128.0 + 1.0 / 128.0 + F32_SLACK,
};
const SPZ_DC_LIMIT: f32 = 3.3;

fn spz_sh_expected(v: f32) -> f32 {
    v.clamp(-1.0, 127.0 / 128.0)
}

#[test]
fn spz_v3_and_v4_match_the_playbot_ply() {
    let (reference, _) = load("playbot_lod3_31k_sh2.ply");
    for (name, version, compression) in [
        ("playbot_lod3_31k_sh2.v3.spz", 3, SpzCompression::Gzip),
        ("playbot_lod3_31k_sh2.v4.spz", 4, SpzCompression::Zstd),
    ] {
        let (s, format) = load(name);
        assert_eq!(
            format,
            SceneFormat::Spz {
                version,
                compression
            }
        );
        assert_eq!((s.len(), s.sh_degree), (31_000, 2), "{name}");
        let e = field_errors(
            &reference,
            &s,
            &identity(s.len()),
            |v| v.abs() <= SPZ_DC_LIMIT,
            spz_sh_expected,
        );
        assert_eq!(
            e.dc_excluded, 248,
            "{name}: the README's count of clamped DC terms"
        );
        check(name, &e, &SPZ_BOUNDS);
    }
}

#[test]
fn spz_v3_matches_the_train3_ply() {
    let (reference, _) = load("train3_sh3.ply");
    let (s, format) = load("train3_sh3.v3.spz");
    assert_eq!(format.to_string(), "SPZ v3 (gzip)");
    assert_eq!((s.len(), s.sh_degree), (3, 3));
    let e = field_errors(
        &reference,
        &s,
        &identity(3),
        |v| v.abs() <= SPZ_DC_LIMIT,
        spz_sh_expected,
    );
    check("train3_sh3.v3.spz", &e, &SPZ_BOUNDS);
}

#[test]
fn sog_directory_and_zip_match_the_playbot_ply() {
    // The PLY was decoded from this SOG, so the values agree up to f32 evaluation order;
    // only the opacity differs where alpha is 0 or 255, which this loader clamps half an
    // 8-bit step inwards (splat-transform clamps to 1e-6).
    let bounds = Bounds {
        position: F32_SLACK,
        log_scale: F32_SLACK,
        rotation: F32_SLACK,
        opacity: 0.5 / 255.0 + 1e-6,
        dc: F32_SLACK,
        sh1: F32_SLACK,
        sh_rest: F32_SLACK,
    };
    let (reference, _) = load("playbot_lod3_31k_sh2.ply");
    let (s, format) = load("playbot_lod3_31k_sh2_sog");
    assert_eq!(format.to_string(), "PlayCanvas SOG v2 (directory)");
    assert_eq!((s.len(), s.sh_degree), (31_000, 2));
    let e = field_errors(&reference, &s, &identity(s.len()), |_| true, |v| v);
    check("SOG directory", &e, &bounds);
    // meta.json named directly loads the same directory.
    let (by_meta, _) = load("playbot_lod3_31k_sh2_sog/meta.json");
    assert_eq!(by_meta, s);
    // The same files bundled as a zip (.sog).
    let dir = tempfile::tempdir().unwrap();
    let bundle = dir.path().join("playbot.sog");
    std::fs::write(&bundle, sog_zip(&data("playbot_lod3_31k_sh2_sog"), None)).unwrap();
    let (zipped, format) = io::scene::load_with_format(&bundle).unwrap();
    assert_eq!(format.to_string(), "PlayCanvas SOG v2 (zip)");
    assert_eq!(zipped, s);
}

/// Zips every file of a SOG directory (deflated), replacing meta.json when given.
fn sog_zip(dir: &Path, meta: Option<&[u8]>) -> Vec<u8> {
    use std::io::Write;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let mut names: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    for name in names {
        zip.start_file(name.as_str(), opts).unwrap();
        let bytes = match (name.as_str(), meta) {
            ("meta.json", Some(m)) => m.to_vec(),
            _ => std::fs::read(dir.join(&name)).unwrap(),
        };
        zip.write_all(&bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// Largest extent of each axis over the 256-Gaussian chunks of a compressed PLY, from
/// the decoded values (the chunk bounds are the extremes of its members).
fn chunk_extents(values: &[[f32; 3]]) -> [f32; 3] {
    let mut ext = [0f32; 3];
    for chunk in values.chunks(256) {
        for a in 0..3 {
            let lo = chunk.iter().map(|v| v[a]).fold(f32::INFINITY, f32::min);
            let hi = chunk.iter().map(|v| v[a]).fold(f32::NEG_INFINITY, f32::max);
            ext[a] = ext[a].max(hi - lo);
        }
    }
    ext
}

#[test]
fn compressed_ply_matches_the_playbot_ply() {
    let (reference, _) = load("playbot_lod3_31k_sh2.ply");
    let (c, format) = load("playbot_lod3_31k_sh2.compressed.ply");
    assert_eq!(format, SceneFormat::CompressedPly);
    assert_eq!((c.len(), c.sh_degree), (31_000, 2));
    // Reordered (Morton order): match each PLY Gaussian to its nearest decoded centre.
    let map = nearest_map(&reference.positions, &c.positions);
    let e = field_errors(&reference, &c, &map, |_| true, |v| v);
    // Positions and log scales are 11/10/11-bit unorms over their chunk's box, so half a
    // step is extent / (2 * 2047) (x, z) or extent / (2 * 1023) (y); colours are bytes over
    // the chunk's colour range (extent / 510, in f_dc units); quaternions keep three
    // components as 10-bit values over [-sqrt(1/2), sqrt(1/2)] (half step 6.9e-4, about
    // threefold on the rebuilt one); SH bytes are `(b / 256 - 0.5) * 8`, a step of 1/32, and
    // splat-transform's encoder truncates, so a whole step.
    let half_step = |ext: [f32; 3]| (ext[0] / 4094.0).max(ext[1] / 2046.0).max(ext[2] / 4094.0);
    let dc: Vec<[f32; 3]> = (0..c.len())
        .map(|i| [c.sh[i * 27], c.sh[i * 27 + 1], c.sh[i * 27 + 2]])
        .collect();
    let dc_ext = chunk_extents(&dc);
    let bounds = Bounds {
        position: half_step(chunk_extents(&c.positions)) + 1e-6,
        log_scale: half_step(chunk_extents(&c.log_scales)) + F32_SLACK,
        rotation: 3e-3,
        opacity: 0.5 / 255.0 + 1e-6,
        dc: dc_ext[0].max(dc_ext[1]).max(dc_ext[2]) / 510.0 + F32_SLACK,
        sh1: 1.0 / 32.0 + F32_SLACK,
        sh_rest: 1.0 / 32.0 + F32_SLACK,
    };
    println!("compressed PLY bounds {bounds:?}");
    check("compressed PLY", &e, &bounds);
    // The README's nearest-neighbour check.
    assert!(e.position <= 6e-4);
}

#[test]
fn supersplat_fixture_with_opaque_splats_loads_finite() {
    let (s, format) = load("pc_test_64_sh3.compressed.ply");
    assert_eq!(format.to_string(), "PlayCanvas compressed PLY");
    assert_eq!((s.len(), s.sh_degree), (64, 3));
    // Packed alpha 255 would be an infinite logit; it is clamped to half a step below 1.
    assert!(s.opacity_logits.iter().all(|o| o.is_finite()));
    let most = s.opacity_logits.iter().fold(f32::MIN, |a, &b| a.max(b));
    assert!((sigmoid(most) - 254.5 / 255.0).abs() < 1e-6, "{most}");
}

#[test]
fn splat_files_match_their_plys() {
    // plant: the PLY was decoded from these bytes by splat-transform. Positions and scales
    // are the same f32s (log scale up to f32 rounding of ln); splat-transform decodes
    // quaternion bytes as (b - 127.5) / 127.5 where this loader uses antimatter15's
    // (b - 128) / 128, which differ by up to one 1/128 step after normalisation; alpha 255 is
    // clamped half a step inwards here.
    let (reference, _) = load("plant_113k_sh0.ply");
    let (s, format) = load("plant_113k.splat");
    assert_eq!(format, SceneFormat::Splat);
    assert_eq!((s.len(), s.sh_degree), (113_648, 0));
    let e = field_errors(&reference, &s, &identity(s.len()), |_| true, |v| v);
    check(
        "plant_113k.splat",
        &e,
        &Bounds {
            position: 0.0,
            log_scale: 1e-6,
            rotation: 1.0 / 128.0,
            opacity: 0.5 / 255.0 + 1e-6,
            dc: F32_SLACK,
            sh1: 0.0,
            sh_rest: 0.0,
        },
    );
    // train3: the original trained floats, written by antimatter15's converter, which
    // truncates to bytes, so a whole step: 1/(255 C0) of f_dc, 1/255 of opacity, 1/128 per
    // quaternion component (1.5/128 after renormalising). Colours beyond [0, 1] saturate and
    // are left out.
    let (reference, _) = load("train3_sh3.ply");
    let (s, _) = load("train3.splat");
    let in_gamut = |v: f32| (0.0..=1.0).contains(&(0.5 + SH_C0 * v));
    let e = field_errors(&reference, &s, &identity(3), in_gamut, |v| v);
    check(
        "train3.splat",
        &e,
        &Bounds {
            position: 0.0,
            log_scale: 1e-6,
            rotation: 1.5 / 128.0,
            opacity: 1.0 / 255.0 + 1e-6,
            dc: 1.0 / (255.0 * SH_C0) + F32_SLACK,
            sh1: 0.0,
            sh_rest: 0.0,
        },
    );
}

/// PSNR of two CPU renders of the same camera (colour clamped to [0, 1]).
fn render_psnr(a: &Scene, b: &Scene, cam: &camera::Camera) -> f64 {
    let opts = RenderOptions::default();
    let fa = cpu::render(&a.activated(), cam, &opts);
    let fb = cpu::render(&b.activated(), cam, &opts);
    common::gpu::compare(&fb, &fa).psnr
}

#[test]
fn renders_agree_with_the_ply_render() {
    // Measured at 320x180 from orbit camera 0 (printed): SOG 156 dB, plant .splat 73 dB,
    // compressed PLY 54 dB, SPZ v3/v4 49 dB. SOG decodes to the PLY's values up to f32
    // evaluation order, so anything below 100 dB would be a decoding bug. The plant .splat
    // differs from its PLY only by the quaternion byte centre (128 vs 127.5, under one 1/128
    // step) and the alpha-255 clamp: 65 dB. Compressed PLY quantises positions to ~5e-4 and
    // colours to ~0.03 of f_dc: 50 dB. SPZ quantises log scales to 1/16 and SH to 1/16..1/8
    // and saturates 248 bright DC terms: 45 dB. Each threshold is 3 to 5 dB under the
    // measurement, so a real regression (a sign flip, a swapped channel) fails by far more.
    let playbot = common::orbit(common::PLAYBOT_ORBIT, 0, 320, 180);
    let (reference, _) = load("playbot_lod3_31k_sh2.ply");
    for (name, threshold) in [
        ("playbot_lod3_31k_sh2_sog", 100.0),
        ("playbot_lod3_31k_sh2.v3.spz", 45.0),
        ("playbot_lod3_31k_sh2.v4.spz", 45.0),
        ("playbot_lod3_31k_sh2.compressed.ply", 50.0),
    ] {
        let (s, _) = load(name);
        let psnr = render_psnr(&reference, &s, &playbot);
        println!("{name}: PSNR {psnr:.2} dB (threshold {threshold})");
        assert!(psnr >= threshold, "{name}: PSNR {psnr:.2} dB < {threshold}");
    }
    let (plant, _) = load("plant_113k_sh0.ply");
    let (plant_splat, _) = load("plant_113k.splat");
    let psnr = render_psnr(
        &plant,
        &plant_splat,
        &common::orbit("plant_orbit_cameras.synthetic.json", 0, 320, 180),
    );
    println!("plant_113k.splat: PSNR {psnr:.2} dB (threshold 65)");
    assert!(psnr >= 65.0, "plant: {psnr}");
}

#[test]
fn ply_round_trip_is_byte_exact() {
    let bytes = std::fs::read(data("playbot_lod6_1873_sh2.ply")).unwrap();
    let (s, format) = io::scene::parse_bytes(&bytes, Path::new("x.ply")).unwrap();
    assert_eq!(format.to_string(), "INRIA PLY (binary little-endian)");
    assert_eq!(write::to_bytes(&s, OutputFormat::Ply).unwrap(), bytes);
}

#[test]
fn splat_and_spz_round_trips_stay_within_quantisation() {
    let (reference, _) = load("playbot_lod3_31k_sh2.ply");
    // .splat written by this crate rounds (not truncates): half steps, except the rotation,
    // whose half step of 0.5/128 per byte can grow to about 1/128 after normalising.
    let bytes = write::to_bytes(&reference, OutputFormat::Splat).unwrap();
    assert_eq!(bytes.len(), 32 * reference.len());
    let (s, format) = io::scene::parse_bytes(&bytes, Path::new("x.splat")).unwrap();
    assert_eq!(format, SceneFormat::Splat);
    let in_gamut = |v: f32| (0.0..=1.0).contains(&(0.5 + SH_C0 * v));
    let e = field_errors(&reference, &s, &identity(s.len()), in_gamut, |v| v);
    check(
        "PLY -> .splat",
        &e,
        &Bounds {
            position: 0.0,
            log_scale: 1e-5,
            rotation: 1.0 / 128.0,
            opacity: 0.5 / 255.0 + 1e-6,
            dc: 0.5 / (255.0 * SH_C0) + F32_SLACK,
            sh1: 0.0,
            sh_rest: 0.0,
        },
    );
    // SPZ v3 written by this crate: the SPZ bounds, without the extra byte of Niantic's SH
    // encoder (this one quantises exactly as the decoder inverts).
    let bytes = write::to_bytes(&reference, OutputFormat::Spz).unwrap();
    let (s, format) = io::scene::parse_bytes(&bytes, Path::new("x.bin")).unwrap();
    assert_eq!(format.to_string(), "SPZ v3 (gzip)");
    let e = field_errors(
        &reference,
        &s,
        &identity(s.len()),
        |v| v.abs() <= SPZ_DC_LIMIT,
        spz_sh_expected,
    );
    check(
        "PLY -> SPZ",
        &e,
        &Bounds {
            sh1: 4.0 / 128.0 + F32_SLACK,
            sh_rest: 8.0 / 128.0 + F32_SLACK,
            ..SPZ_BOUNDS
        },
    );
    // Re-encoding the decoded scene lands on the same grid: positions, scales and opacity
    // bytes reproduce exactly.
    let again = write::to_bytes(&s, OutputFormat::Spz).unwrap();
    let (s2, _) = io::scene::parse_bytes(&again, Path::new("x.spz")).unwrap();
    assert_eq!(s2.positions, s.positions);
    assert_eq!(s2.log_scales, s.log_scales);
    assert_eq!(s2.opacity_logits, s.opacity_logits);
}

#[test]
fn spz_writer_reproduces_niantics_train3_payload_values() {
    // The train3 SPZ was written by Niantic's library from train3_sh3.ply; this crate's
    // writer, decoded, agrees with it within one quantisation step per field.
    let (reference, _) = load("train3_sh3.ply");
    let (niantic, _) = load("train3_sh3.v3.spz");
    let ours = write::to_bytes(&reference, OutputFormat::Spz).unwrap();
    let (ours, _) = io::scene::parse_bytes(&ours, Path::new("t.spz")).unwrap();
    assert_eq!(ours.positions, niantic.positions);
    assert_eq!(ours.log_scales, niantic.log_scales);
    assert_eq!(ours.opacity_logits, niantic.opacity_logits);
    assert_eq!(ours.sh[..3], niantic.sh[..3]);
    let e = field_errors(&ours, &niantic, &identity(3), |_| true, |v| v);
    assert!(e.sh1 <= 8.0 / 128.0 && e.sh_rest <= 16.0 / 128.0, "{e:?}");
    assert!(e.rotation <= 3e-3, "{e:?}");
}

fn err_of(bytes: &[u8], name: &str) -> String {
    match io::scene::parse_bytes(bytes, Path::new(name)) {
        Ok((s, f)) => panic!(
            "{name}: malformed input accepted as {f} with {} Gaussians",
            s.len()
        ),
        Err(e) => e.to_string(),
    }
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(bytes).unwrap();
    gz.finish().unwrap()
}

fn spz_header(version: u32, count: u32, degree: u8) -> Vec<u8> {
    let mut h = Vec::new();
    h.extend_from_slice(b"NGSP");
    h.extend_from_slice(&version.to_le_bytes());
    h.extend_from_slice(&count.to_le_bytes());
    h.extend_from_slice(&[degree, 12, 0, 0]);
    h
}

#[test]
fn malformed_spz_gives_clear_errors() {
    let v3 = std::fs::read(data("playbot_lod3_31k_sh2.v3.spz")).unwrap();
    let e = err_of(&v3[..v3.len() / 2], "t.spz");
    assert!(e.contains("gzip") && e.contains("truncated"), "{e}");
    // gzip of something that is not SPZ.
    let e = err_of(&gzip(b"hello, this is not a splat file"), "t.spz");
    assert!(e.contains("SPZ magic"), "{e}");
    // A count the data cannot hold: no huge allocation, a clear sentence.
    let mut lying = spz_header(3, 1_000_000_000, 3);
    lying.extend_from_slice(&[0u8; 100]);
    let e = err_of(&gzip(&lying), "t.spz");
    assert!(
        e.contains("1000000000 Gaussians") && e.contains("holds only 100 bytes"),
        "{e}"
    );
    let e = err_of(&gzip(&spz_header(7, 1, 0)), "t.spz");
    assert!(e.contains("version 7"), "{e}");
    let e = err_of(&gzip(&spz_header(3, 1, 4)), "t.spz");
    assert!(e.contains("SH degree 4"), "{e}");
    // Too much data for the count.
    let mut extra = spz_header(3, 0, 0);
    extra.push(1);
    let e = err_of(&gzip(&extra), "t.spz");
    assert!(e.contains("more data"), "{e}");
    // v4 whose table of contents lies about a stream size or points past the end.
    let v4 = std::fs::read(data("playbot_lod3_31k_sh2.v4.spz")).unwrap();
    let mut bad = v4.clone();
    bad[40] ^= 1; // uncompressed size of the positions stream
    let e = err_of(&bad, "t.spz");
    assert!(e.contains("positions stream"), "{e}");
    let mut bad = v4.clone();
    bad[32..40].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = err_of(&bad, "t.spz");
    assert!(e.contains("runs past the end"), "{e}");
    let mut bad = v4.clone();
    bad[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = err_of(&bad, "t.spz");
    assert!(e.contains("table of contents"), "{e}");
    let mut bad = v4.clone();
    let last = bad.len() - 10;
    bad[last] ^= 0xff;
    let _ = io::scene::parse_bytes(&bad, Path::new("t.spz")); // corrupt zstd: any result, no panic
}

#[test]
fn truncated_files_fail_at_every_offset_without_panicking() {
    let dir = tempfile::tempdir().unwrap();
    let sog = sog_zip(&data("playbot_lod3_31k_sh2_sog"), None);
    let files: Vec<(&str, Vec<u8>)> = vec![
        ("v3.spz", std::fs::read(data("train3_sh3.v3.spz")).unwrap()),
        (
            "v3big.spz",
            std::fs::read(data("playbot_lod3_31k_sh2.v3.spz")).unwrap(),
        ),
        (
            "v4.spz",
            std::fs::read(data("playbot_lod3_31k_sh2.v4.spz")).unwrap(),
        ),
        (
            "c.ply",
            std::fs::read(data("pc_test_64_sh3.compressed.ply")).unwrap(),
        ),
        ("t.splat", std::fs::read(data("train3.splat")).unwrap()),
        ("b.sog", sog),
    ];
    for (name, bytes) in &files {
        let len = bytes.len();
        let mut offsets: Vec<usize> = (0..64.min(len)).collect();
        offsets.extend((1..97).map(|k| k * len / 97));
        offsets.extend([len - 1]);
        for cut in offsets {
            if name.ends_with(".splat") && cut % 32 == 0 {
                continue; // whole records: a valid, shorter .splat
            }
            let e = err_of(&bytes[..cut], name);
            assert!(!e.is_empty());
        }
    }
    drop(dir);
}

#[test]
fn malformed_compressed_ply_and_sog_give_clear_errors() {
    let c = std::fs::read(data("pc_test_64_sh3.compressed.ply")).unwrap();
    let text = String::from_utf8_lossy(&c[..c.len().min(2000)]).into_owned();
    assert!(text.contains("element chunk 1"));
    // More vertices than the chunks cover (and than the data holds).
    let lying = {
        let mut b = c.clone();
        let at = text.find("element vertex 64").unwrap() + "element vertex ".len();
        b[at..at + 2].copy_from_slice(b"99");
        b
    };
    let e = err_of(&lying, "c.ply");
    assert!(e.contains("truncated or its header lies"), "{e}");
    // Bad JSON in a SOG meta.json, as a zip and as a directory.
    let dir = tempfile::tempdir().unwrap();
    let bundle = sog_zip(
        &data("playbot_lod3_31k_sh2_sog"),
        Some(b"{\"version\": 2, \"count\": "),
    );
    let e = err_of(&bundle, "b.sog");
    assert!(e.contains("meta.json that is not valid"), "{e}");
    let sog_dir = dir.path().join("sog");
    std::fs::create_dir(&sog_dir).unwrap();
    for entry in std::fs::read_dir(data("playbot_lod3_31k_sh2_sog")).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), sog_dir.join(entry.file_name())).unwrap();
    }
    let meta_path = sog_dir.join("meta.json");
    let meta = std::fs::read_to_string(&meta_path).unwrap();
    let set_meta = |m: &str| {
        std::fs::write(&meta_path, m).unwrap();
        io::scene::load(&sog_dir).unwrap_err().to_string()
    };
    let e = set_meta("{not json");
    assert!(e.contains("meta.json that is not valid"), "{e}");
    let e = set_meta(&meta.replace("\"count\":31000", "\"count\":99999999"));
    assert!(e.contains("too small for the 99999999 Gaussians"), "{e}");
    let e = set_meta(&meta.replace("\"version\":2", "\"version\":3"));
    assert!(e.contains("SOG version 3"), "{e}");
    let e = set_meta(&meta.replace("means_l.webp", "../means_l.webp"));
    assert!(e.contains("only plain file names"), "{e}");
    std::fs::write(&meta_path, &meta).unwrap();
    std::fs::write(sog_dir.join("quats.webp"), b"RIFF....WEBPjunk").unwrap();
    let e = io::scene::load(&sog_dir).unwrap_err().to_string();
    assert!(e.contains("quats.webp") && e.contains("WebP"), "{e}");
    // A zip that is not a SOG.
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    zip.start_file("readme.txt", zip::write::SimpleFileOptions::default())
        .unwrap();
    let not_sog = zip.finish().unwrap().into_inner();
    let e = err_of(&not_sog, "x.sog");
    assert!(e.contains("meta.json"), "{e}");
}

#[test]
fn detection_uses_content_not_extension() {
    // An SPZ named .ply and a PLY named .spz still load as what they are.
    let spz = std::fs::read(data("train3_sh3.v3.spz")).unwrap();
    let (_, f) = io::scene::parse_bytes(&spz, Path::new("misnamed.ply")).unwrap();
    assert_eq!(f.to_string(), "SPZ v3 (gzip)");
    let ply_bytes = std::fs::read(data("train3_sh3.ply")).unwrap();
    let (_, f) = io::scene::parse_bytes(&ply_bytes, Path::new("misnamed.spz")).unwrap();
    assert!(matches!(f, SceneFormat::InriaPly(_)));
    // A .splat without its extension is recognised by its plausible records.
    let splat = std::fs::read(data("train3.splat")).unwrap();
    let (_, f) = io::scene::parse_bytes(&splat, Path::new("noext")).unwrap();
    assert_eq!(f, SceneFormat::Splat);
    // Random bytes of a multiple of 32 without the extension are not guessed as .splat.
    let junk: Vec<u8> = (0..64u32).map(|i| (i * 37 % 251) as u8 | 0x80).collect();
    let e = err_of(&junk, "noext");
    assert!(e.contains("not a recognised scene format"), "{e}");
    let e = err_of(
        &ply::to_bytes(&Scene::empty(0), ply::PlyEncoding::Ascii)[..10],
        "t.ply",
    );
    assert!(e.contains("end_header"), "{e}");
}

#[test]
fn cli_convert_and_info() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let src = data("playbot_lod6_1873_sh2.ply");
    let src = src.to_str().unwrap();
    // PLY -> SPZ, then info reports the detected format.
    let o = verisplat(&["convert", src, &d("a.spz")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = verisplat(&["info", &d("a.spz")]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && out.contains("format      SPZ v3 (gzip)"),
        "{out}"
    );
    assert!(out.contains("gaussians   1873"), "{out}");
    let o = verisplat(&["info", data("playbot_lod3_31k_sh2_sog").to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("PlayCanvas SOG v2 (directory)"), "{out}");
    // An existing output is refused without --overwrite and left untouched.
    let before = std::fs::read(d("a.spz")).unwrap();
    let o = verisplat(&["convert", src, &d("a.spz"), "--sh-degree", "0"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("already exists") && e.contains("--overwrite"),
        "{e}"
    );
    assert_eq!(std::fs::read(d("a.spz")).unwrap(), before);
    let o = verisplat(&[
        "convert",
        src,
        &d("a.spz"),
        "--sh-degree",
        "0",
        "--overwrite",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        io::scene::load(Path::new(&d("a.spz"))).unwrap().sh_degree,
        0
    );
    // Filters: the same selection SceneFilter makes in the library.
    let full = io::scene::load(Path::new(src)).unwrap();
    let o = verisplat(&[
        "convert",
        src,
        &d("f.ply"),
        "--min-opacity",
        "0.5",
        "--max-scale",
        "0.05",
        "--crop",
        "-1,-2,-1,1,0,1",
        "--sh-degree",
        "1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let filter = scene::filter::SceneFilter {
        min_opacity: Some(0.5),
        max_scale: Some(0.05),
        crop: Some([[-1.0, -2.0, -1.0], [1.0, 0.0, 1.0]]),
        sh_degree: Some(1),
    };
    let expected = filter.apply(&full);
    assert!(expected.len() > 100 && expected.len() < full.len());
    assert_eq!(io::scene::load(Path::new(&d("f.ply"))).unwrap(), expected);
    // .splat output; unknown extensions and bad filters are one clear error, no file.
    let o = verisplat(&["convert", src, &d("b.splat")]);
    assert!(o.status.success());
    assert_eq!(std::fs::metadata(d("b.splat")).unwrap().len(), 32 * 1873);
    let o = verisplat(&["convert", src, &d("c.xyz")]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("unknown output format"),
        "{e}"
    );
    let o = verisplat(&["convert", src, &d("c.ply"), "--min-opacity", "2"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--min-opacity"), "{e}");
    let o = verisplat(&["convert", "/nonexistent.spz", &d("c.ply")]);
    assert!(!o.status.success());
    assert!(!Path::new(&d("c.xyz")).exists() && !Path::new(&d("c.ply")).exists());
    // Atomic writes leave no temporary files behind.
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["a.spz", "b.splat", "f.ply"]);
}

#[test]
fn mutated_files_never_panic() {
    // Seeded byte flips in every small real file and in an uncompressed SPZ payload: any
    // result is fine (many flips are still valid scenes), a panic is not.
    let mut rng = common::Rng(99);
    let payload = {
        use std::io::Read;
        let gz = std::fs::read(data("train3_sh3.v3.spz")).unwrap();
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(&gz[..])
            .read_to_end(&mut out)
            .unwrap();
        out
    };
    let v4 = std::fs::read(data("playbot_lod3_31k_sh2.v4.spz")).unwrap();
    let files: Vec<(&str, Vec<u8>)> = vec![
        ("raw.spz", payload),
        ("v4head.spz", v4[..4096].to_vec()),
        (
            "c.ply",
            std::fs::read(data("pc_test_64_sh3.compressed.ply")).unwrap(),
        ),
        ("t.ply", std::fs::read(data("train3_sh3.ply")).unwrap()),
        ("t.splat", std::fs::read(data("train3.splat")).unwrap()),
    ];
    for (name, bytes) in &files {
        for _ in 0..300 {
            let mut b = bytes.clone();
            for _ in 0..1 + (rng.range(0.0, 4.0) as usize) {
                let at = (rng.range(0.0, 1.0) * b.len() as f32) as usize % b.len();
                b[at] = (rng.range(0.0, 256.0) as u32 % 256) as u8;
            }
            let _ = io::scene::parse_bytes(&b, Path::new(name));
        }
    }
    // The uncompressed payload itself is a valid SPZ v3.
    let (_, f) = io::scene::parse_bytes(&files[0].1, Path::new("raw.spz")).unwrap();
    assert_eq!(f.to_string(), "SPZ v3 (uncompressed)");
}

/// A file that records antialiased training (SPZ header flag, SOG `antialias`) renders with
/// the opacity compensation by default; `--no-antialiased` turns it off, and converting
/// to a format that cannot record the flag says so.
#[test]
fn antialiased_training_flag_is_read_written_and_honoured() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene =
        verisplat::io::scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply"))
            .unwrap();
    scene.antialiased = true;
    let spz = dir.path().join("aa.spz");
    std::fs::write(
        &spz,
        verisplat::io::scene::spz::to_bytes_v3(&scene).unwrap(),
    )
    .unwrap();
    let back = verisplat::io::scene::load(&spz).unwrap();
    assert!(back.antialiased);
    scene.antialiased = false;
    let plain = verisplat::io::scene::spz::to_bytes_v3(&scene).unwrap();
    assert!(
        !verisplat::io::scene::parse_bytes(&plain, Path::new("plain.spz"))
            .unwrap()
            .0
            .antialiased
    );

    let run = |out: &str, extra: &[&str]| -> String {
        let out = dir.path().join(out);
        let mut args = vec!["render", s(&spz), "--width", "160", "--cpu", "-o", s(&out)];
        args.extend_from_slice(extra);
        let o = verisplat(&args);
        let e = stderr(&o);
        assert!(o.status.success(), "{e}");
        e
    };
    let e = run("default.png", &[]);
    assert!(e.contains("trained with antialiasing"), "{e}");
    run("forced.png", &["--antialiased"]);
    run("off.png", &["--no-antialiased"]);
    let read = |n: &str| std::fs::read(dir.path().join(n)).unwrap();
    assert_eq!(read("default.png"), read("forced.png"));
    assert_ne!(read("default.png"), read("off.png"));

    // SOG: the `antialias` field of meta.json.
    let sog = dir.path().join("sog");
    std::fs::create_dir(&sog).unwrap();
    let src = common::shared_data().join("playbot_lod3_31k_sh2_sog");
    for e in std::fs::read_dir(&src).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), sog.join(e.file_name())).unwrap();
    }
    assert!(!verisplat::io::scene::load(&sog).unwrap().antialiased);
    let meta = sog.join("meta.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&meta).unwrap()).unwrap();
    json["antialias"] = true.into();
    std::fs::write(&meta, json.to_string()).unwrap();
    assert!(verisplat::io::scene::load(&sog).unwrap().antialiased);

    // PLY cannot record the flag: convert says so.
    let o = verisplat(&["convert", s(&spz), s(&dir.path().join("aa.ply"))]);
    let e = stderr(&o);
    assert!(o.status.success() && e.contains("--antialiased"), "{e}");
}
