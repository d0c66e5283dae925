//! Niantic SPZ, versions 2 and 3 (a gzip-wrapped payload) and 4 (an `NGSP` header with one
//! zstd stream per attribute).
//!
//! Payload (all versions), for `N` Gaussians, attribute-major in this order:
//! positions (`9N`: three 24-bit signed fixed-point values each, `fractional_bits` from the
//! header), alphas (`N`: `sigmoid(opacity) * 255`), colours (`3N`: `f_dc * 0.15 * 255 +
//! 127.5`), scales (`3N`: `(log_scale + 10) * 16`), rotations (`3N` in v2: `x, y, z` of the
//! `w >= 0` quaternion as `(q + 1) * 127.5`; `4N` from v3: "smallest three", a 2-bit index of
//! the largest component of `(x, y, z, w)` and three sign + 9-bit magnitudes in units of
//! `sqrt(1/2) / 511`, packed little-endian, the first kept component in the highest bits),
//! and SH (`N * 3 * (coeffs - 1)` bytes, coefficient-major with the colour channel
//! innermost, `(b - 128) / 128`).
//!
//! v2/v3 header (16 bytes, little-endian): magic `0x5053474e` ("NGSP"), version,
//! Gaussian count, SH degree (u8), fractional bits (u8), flags (u8: 1 antialiased,
//! 2 extensions follow), reserved (u8). The whole file is one gzip member.
//!
//! v4 header (32 bytes): the same first 15 bytes, then the stream count (u8), the byte
//! offset of the table of contents (u32) and 12 reserved bytes. The table holds one
//! `(compressed size u64, uncompressed size u64)` pair per stream, and the zstd streams
//! follow it back to back in the payload order above.
//!
//! Axes: SPZ stores Niantic's RUB frame, `(x, y, z)_spz = (x, -y, -z)_ply`. Decoding maps
//! positions to `(x, -y, -z)`, quaternions `(w, x, y, z)` to `(w, x, -y, -z)` (conjugation by
//! the 180 degree turn about x) and negates the SH coefficients whose basis function is odd
//! in `y` and `z` together ([`RUB_SH_SIGN`]). Encoding applies the same involution.
//!
//! That is the spec ([`SpzAxes::Spec`], what Niantic's library and Scaniverse write), but a
//! file's bytes do not say which frame its writer used: PlayCanvas's splat-transform writes
//! PLY axes as they are ([`SpzAxes::Raw`]). Reading or writing with `Raw` skips the
//! involution, which is the `Spec` result turned 180 degrees about x ([`flip_rub`]):
//! exactly, as the involution only changes signs.

use super::{logit_from_u8, sigmoid, Scene, SceneError};
use std::io::Read;
use std::path::Path;

/// `"NGSP"` read as a little-endian u32.
pub const MAGIC: u32 = 0x5053_474e;
/// The DC colour scale: `byte = f_dc * COLOR_SCALE * 255 + 127.5`.
pub const COLOR_SCALE: f32 = 0.15;
/// Fractional bits the writer uses when the positions fit (Niantic's default, 1/4096).
pub const DEFAULT_FRACTIONAL_BITS: u8 = 12;

pub use crate::core::scene::transform::RUB_SH_SIGN;

const FLAG_EXTENSIONS: u8 = 0x2;
/// Header flag: the scene was trained with antialiasing.
const FLAG_ANTIALIASED: u8 = 0x1;

/// The frame an SPZ file's coordinates are in (a file does not record it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SpzAxes {
    /// The SPZ spec's RUB axes, `(x, y, z)_spz = (x, -y, -z)_ply`: Niantic's spz library,
    /// Scaniverse, and verisplat by default.
    #[default]
    Spec,
    /// PLY axes as they are, with no conversion: PlayCanvas's splat-transform.
    Raw,
}

impl std::fmt::Display for SpzAxes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SpzAxes::Spec => "spec",
            SpzAxes::Raw => "raw",
        })
    }
}

impl SpzAxes {
    /// The other convention.
    pub fn other(self) -> SpzAxes {
        match self {
            SpzAxes::Spec => SpzAxes::Raw,
            SpzAxes::Raw => SpzAxes::Spec,
        }
    }

    /// What the convention is and who writes it, for messages.
    pub fn describe(self) -> &'static str {
        match self {
            SpzAxes::Spec => {
                "SPZ's own RUB axes (--spz-axes spec: Niantic's spz library, Scaniverse)"
            }
            SpzAxes::Raw => "PLY axes (--spz-axes raw: PlayCanvas splat-transform)",
        }
    }
}

/// Whether a scene looks upside down in the renderers' frame (PLY axes, world up -y, as
/// scenes trained from COLMAP cameras are and the default cameras assume): most of its
/// Gaussians gather near its top (-y) with a thin part below, as a ground seen from
/// beneath, where a scene the right way up has its ground at the bottom and what stands
/// on it above. Measured on the 2nd, 50th and 98th percentiles of y: the part below the
/// median more than 4 times as tall as the part above (PLAYBOT, a ground patch with a
/// robot on it: 0.03 times the right way up, 33 times upside down). Scenes without such
/// a ground (the plant: 1.07 either way) say nothing; neither do fewer than 100
/// Gaussians. A hint for files that do not record their axes (SPZ), not a proof.
pub fn looks_upside_down(scene: &Scene) -> bool {
    let mut y: Vec<f32> = scene
        .positions
        .iter()
        .map(|p| p[1])
        .filter(|v| v.is_finite())
        .collect();
    if y.len() < 100 {
        return false;
    }
    let last = y.len() - 1;
    let mut at = |f: f64| -> f32 {
        let k = (last as f64 * f).round() as usize;
        *y.select_nth_unstable_by(k, f32::total_cmp).1
    };
    let (top, middle, bottom) = (at(0.02), at(0.5), at(0.98));
    let (above, below) = (middle - top, bottom - middle);
    above > 0.0 && below > 4.0 * above
}

/// A one-line note when the scene read from SPZ file `path` in `axes` looks upside down
/// ([`looks_upside_down`]) and would not in the other axes: SPZ files do not record which
/// convention wrote them.
pub fn axes_note(path: &Path, scene: &Scene, axes: SpzAxes) -> Option<String> {
    looks_upside_down(scene).then(|| {
        format!(
            "note: {} looks upside down read in {} (most Gaussians at the top, a thin part below, as a ground seen from beneath); SPZ files do not record their axes: if it was written in {}, pass --spz-axes {}",
            path.display(),
            axes.describe(),
            axes.other().describe(),
            axes.other()
        )
    })
}

impl std::str::FromStr for SpzAxes {
    type Err = String;
    fn from_str(s: &str) -> Result<SpzAxes, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "spec" => Ok(SpzAxes::Spec),
            "raw" => Ok(SpzAxes::Raw),
            _ => Err(format!(
                "unknown SPZ axes \"{s}\"; use spec (the SPZ spec's RUB axes: Niantic's spz library, Scaniverse) or raw (PLY axes, no conversion: PlayCanvas splat-transform)"
            )),
        }
    }
}

/// Turns a scene 180 degrees about x, the difference between reading an SPZ file with
/// [`SpzAxes::Spec`] and with [`SpzAxes::Raw`]: positions `(x, y, z) -> (x, -y, -z)`,
/// quaternions `(w, x, y, z) -> (w, x, -y, -z)` and the SH coefficients by
/// [`RUB_SH_SIGN`]. Only signs change, so applying it twice gives the scene back exactly.
pub fn flip_rub(scene: &mut Scene) {
    for p in &mut scene.positions {
        p[1] = -p[1];
        p[2] = -p[2];
    }
    for q in &mut scene.rotations {
        q[2] = -q[2];
        q[3] = -q[3];
    }
    let stride = scene.sh_stride();
    for g in scene.sh.chunks_exact_mut(stride) {
        for (j, v) in g[3..].iter_mut().enumerate() {
            *v *= RUB_SH_SIGN[j / 3];
        }
    }
}

/// How an SPZ payload is wrapped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpzCompression {
    /// One gzip member around header and payload (v2, v3).
    Gzip,
    /// One zstd stream per attribute after the v4 header.
    Zstd,
    /// A bare v2/v3 payload without the gzip wrapper.
    None,
}

impl std::fmt::Display for SpzCompression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SpzCompression::Gzip => "gzip",
            SpzCompression::Zstd => "zstd",
            SpzCompression::None => "uncompressed",
        })
    }
}

/// The fields of an SPZ header that decoding needs.
#[derive(Clone, Copy, Debug)]
struct Header {
    version: u32,
    count: u32,
    sh_degree: u32,
    fractional_bits: u32,
    flags: u8,
}

impl Header {
    /// Reads and checks the 16 bytes common to every version.
    fn parse(b: &[u8], path: &Path) -> Result<Header, SceneError> {
        if b.len() < 16 {
            return Err(SceneError::invalid(
                path,
                format!(
                    "is truncated: its SPZ header needs 16 bytes but only {} are there",
                    b.len()
                ),
            ));
        }
        let u32_at = |at: usize| u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        if u32_at(0) != MAGIC {
            return Err(SceneError::invalid(
                path,
                "does not start with the SPZ magic \"NGSP\"",
            ));
        }
        let h = Header {
            version: u32_at(4),
            count: u32_at(8),
            sh_degree: b[12] as u32,
            fractional_bits: b[13] as u32,
            flags: b[14],
        };
        match h.version {
            2..=4 => {}
            1 => {
                return Err(SceneError::invalid(
                    path,
                    "is SPZ version 1 (float16 positions), which was never released and is not supported; versions 2 to 4 are",
                ))
            }
            v => {
                return Err(SceneError::invalid(
                    path,
                    format!("is SPZ version {v}; versions 2 to 4 are supported"),
                ))
            }
        }
        if h.sh_degree > 3 {
            return Err(SceneError::invalid(
                path,
                format!(
                    "declares SH degree {} in its SPZ header; degrees 0 to 3 are supported",
                    h.sh_degree
                ),
            ));
        }
        if h.fractional_bits > 23 {
            return Err(SceneError::invalid(
                path,
                format!(
                    "declares {} fractional bits for its 24-bit positions; at most 23 make sense",
                    h.fractional_bits
                ),
            ));
        }
        if h.flags & FLAG_EXTENSIONS != 0 {
            return Err(SceneError::invalid(
                path,
                "uses SPZ extensions (header flag 0x2), which verisplat does not read",
            ));
        }
        Ok(h)
    }

    fn rotation_bytes(&self) -> u64 {
        if self.version >= 3 {
            4
        } else {
            3
        }
    }

    fn sh_bytes(&self) -> u64 {
        3 * (super::sh_coeffs_for_degree(self.sh_degree) as u64 - 1)
    }

    /// Byte sizes of the six attribute arrays, in payload order.
    fn stream_sizes(&self) -> [u64; 6] {
        let n = self.count as u64;
        [
            9 * n,
            n,
            3 * n,
            3 * n,
            self.rotation_bytes() * n,
            self.sh_bytes() * n,
        ]
    }
}

const STREAM_NAMES: [&str; 6] = [
    "positions",
    "alphas",
    "colours",
    "scales",
    "rotations",
    "SH",
];

/// Parses an SPZ file (any supported version and wrapper) held in memory; returns the
/// scene, the version and the wrapper. `path` is used in error messages only.
pub fn parse(bytes: &[u8], path: &Path) -> Result<(Scene, u32, SpzCompression), SceneError> {
    if bytes.starts_with(&[0x1f, 0x8b]) {
        let payload = gunzip_payload(bytes, path)?;
        let h = Header::parse(&payload, path)?;
        if h.version >= 4 {
            return Err(SceneError::invalid(
                path,
                format!(
                    "is a gzip-wrapped SPZ declaring version {}, but version 4 files are not gzip-wrapped",
                    h.version
                ),
            ));
        }
        let scene = decode_flat(&h, &payload[16..], path)?;
        return Ok((scene, h.version, SpzCompression::Gzip));
    }
    let h = Header::parse(bytes, path)?;
    if h.version >= 4 {
        let streams = unzstd_streams(&h, bytes, path)?;
        let s: [&[u8]; 6] = std::array::from_fn(|i| streams[i].as_slice());
        let scene = decode(&h, s, path)?;
        Ok((scene, h.version, SpzCompression::Zstd))
    } else {
        let scene = decode_flat(&h, &bytes[16..], path)?;
        Ok((scene, h.version, SpzCompression::None))
    }
}

/// [`parse`] of a file written in `axes`: [`SpzAxes::Raw`] gives the scene as its writer
/// had it in PLY axes (the spec's result turned by [`flip_rub`]).
pub fn parse_with_axes(
    bytes: &[u8],
    path: &Path,
    axes: SpzAxes,
) -> Result<(Scene, u32, SpzCompression), SceneError> {
    let (mut scene, version, compression) = parse(bytes, path)?;
    if axes == SpzAxes::Raw {
        flip_rub(&mut scene);
    }
    Ok((scene, version, compression))
}

/// Decompresses a gzip-wrapped v2/v3 file, reading no more than its header says exists.
fn gunzip_payload(bytes: &[u8], path: &Path) -> Result<Vec<u8>, SceneError> {
    let corrupt = |e: std::io::Error| {
        SceneError::invalid(
            path,
            format!("has a corrupt or truncated gzip stream ({e})"),
        )
    };
    let mut gz = flate2::read::GzDecoder::new(bytes);
    let mut head = Vec::with_capacity(16);
    (&mut gz).take(16).read_to_end(&mut head).map_err(corrupt)?;
    let h = Header::parse(&head, path)?;
    // Read at most one byte more than the header promises, so a lying count cannot make
    // this allocate more than the stream really holds, and extra data is detected.
    let want: u64 = h.stream_sizes().iter().sum();
    let mut payload = head;
    (&mut gz)
        .take(want.saturating_add(1))
        .read_to_end(&mut payload)
        .map_err(corrupt)?;
    let have = payload.len() as u64 - 16;
    if have < want {
        return Err(SceneError::invalid(
            path,
            format!(
                "is truncated or its header lies: it declares {} Gaussians ({want} bytes of attributes) but the gzip stream holds only {have} bytes after the header",
                h.count
            ),
        ));
    }
    if have > want {
        return Err(SceneError::invalid(
            path,
            format!(
                "holds more data than its SPZ header declares for {} Gaussians; its count does not match the data",
                h.count
            ),
        ));
    }
    Ok(payload)
}

/// Splits a flat v2/v3 payload (after the header) into the six attribute arrays.
fn decode_flat(h: &Header, data: &[u8], path: &Path) -> Result<Scene, SceneError> {
    let sizes = h.stream_sizes();
    let want: u64 = sizes.iter().sum();
    if data.len() as u64 != want {
        return Err(SceneError::invalid(
            path,
            format!(
                "is truncated or its header lies: it declares {} Gaussians ({want} bytes of attributes) but {} bytes follow the header",
                h.count,
                data.len()
            ),
        ));
    }
    let mut rest = data;
    let streams: [&[u8]; 6] = std::array::from_fn(|i| {
        let (a, b) = rest.split_at(sizes[i] as usize);
        rest = b;
        a
    });
    decode(h, streams, path)
}

/// Reads the v4 table of contents and decompresses each zstd stream, checking its size.
fn unzstd_streams(h: &Header, bytes: &[u8], path: &Path) -> Result<Vec<Vec<u8>>, SceneError> {
    let bad = |m: String| SceneError::invalid(path, m);
    if bytes.len() < 32 {
        return Err(bad(format!(
            "is truncated: its SPZ v4 header needs 32 bytes but the file has {}",
            bytes.len()
        )));
    }
    let stream_count = bytes[15] as usize;
    let want_streams = if h.sh_degree == 0 { 5..=6 } else { 6..=6 };
    if !want_streams.contains(&stream_count) {
        return Err(bad(format!(
            "declares {stream_count} data streams in its SPZ v4 header; positions, alphas, colours, scales, rotations and SH need 6"
        )));
    }
    let toc_offset = u32::from_le_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]) as usize;
    let toc_end = toc_offset
        .checked_add(16 * stream_count)
        .filter(|&e| toc_offset >= 32 && e <= bytes.len())
        .ok_or_else(|| {
            bad(format!(
                "is truncated or corrupt: its SPZ v4 table of contents at byte {toc_offset} does not fit in the {}-byte file",
                bytes.len()
            ))
        })?;
    let u64_at = |at: usize| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&bytes[at..at + 8]);
        u64::from_le_bytes(a)
    };
    let sizes = h.stream_sizes();
    let mut offset = toc_end as u64;
    let mut streams = Vec::with_capacity(6);
    for (i, &want) in sizes.iter().enumerate() {
        let name = STREAM_NAMES[i];
        if i >= stream_count {
            // Only the SH stream may be absent, and only for SH degree 0 (want == 0).
            streams.push(Vec::new());
            continue;
        }
        let compressed = u64_at(toc_offset + 16 * i);
        let uncompressed = u64_at(toc_offset + 16 * i + 8);
        if uncompressed != want {
            return Err(bad(format!(
                "has a {name} stream of {uncompressed} bytes in its SPZ v4 table of contents, but {} Gaussians need {want}",
                h.count
            )));
        }
        let end = offset
            .checked_add(compressed)
            .filter(|&e| e <= bytes.len() as u64)
            .ok_or_else(|| {
                bad(format!(
                    "is truncated: its {name} stream ({compressed} compressed bytes at byte {offset}) runs past the end of the {}-byte file",
                    bytes.len()
                ))
            })?;
        let src = &bytes[offset as usize..end as usize];
        let mut out = Vec::new();
        if want > 0 || !src.is_empty() {
            let decoder = ruzstd::decoding::StreamingDecoder::new(src)
                .map_err(|e| bad(format!("has a corrupt zstd {name} stream ({e})")))?;
            decoder
                .take(want.saturating_add(1))
                .read_to_end(&mut out)
                .map_err(|e| {
                    bad(format!(
                        "has a corrupt or truncated zstd {name} stream ({e})"
                    ))
                })?;
        }
        if out.len() as u64 != want {
            return Err(bad(format!(
                "has a zstd {name} stream that decompresses to {} bytes, but its table of contents says {want}",
                out.len()
            )));
        }
        streams.push(out);
        offset = end;
    }
    if offset != bytes.len() as u64 {
        return Err(bad(format!(
            "has {} bytes after its last SPZ v4 stream; its table of contents does not match the data",
            bytes.len() as u64 - offset
        )));
    }
    Ok(streams)
}

/// Decodes the six attribute arrays (sizes already checked) into a scene in PLY axes.
fn decode(h: &Header, s: [&[u8]; 6], path: &Path) -> Result<Scene, SceneError> {
    let [positions, alphas, colors, scales, rotations, sh] = s;
    let n = h.count as usize;
    let mut scene = Scene::empty(h.sh_degree);
    scene.antialiased = h.flags & FLAG_ANTIALIASED != 0;
    let rest = h.sh_bytes() as usize;
    let step = 1.0 / (1u32 << h.fractional_bits) as f32;
    let flip = [1.0f32, -1.0, -1.0];
    scene.positions.reserve_exact(n);
    scene.log_scales.reserve_exact(n);
    scene.rotations.reserve_exact(n);
    scene.opacity_logits.reserve_exact(n);
    scene.sh.reserve_exact(n * scene.sh_stride());
    for i in 0..n {
        let p: [f32; 3] = std::array::from_fn(|a| {
            let b = &positions[9 * i + 3 * a..9 * i + 3 * a + 3];
            // Sign-extend the 24-bit value by placing it in the top bytes of an i32.
            let fixed = i32::from_le_bytes([0, b[0], b[1], b[2]]) >> 8;
            flip[a] * fixed as f32 * step
        });
        scene.positions.push(p);
        scene.log_scales.push(std::array::from_fn(|a| {
            scales[3 * i + a] as f32 / 16.0 - 10.0
        }));
        let xyzw = if h.version >= 3 {
            let r = &rotations[4 * i..4 * i + 4];
            unpack_smallest_three(u32::from_le_bytes([r[0], r[1], r[2], r[3]]))
        } else {
            let r = &rotations[3 * i..3 * i + 3];
            let v = [r[0], r[1], r[2]].map(|b| b as f32 / 127.5 - 1.0);
            let w = (1.0 - v.iter().map(|c| c * c).sum::<f32>()).max(0.0).sqrt();
            [v[0], v[1], v[2], w]
        };
        scene.rotations.push([xyzw[3], xyzw[0], -xyzw[1], -xyzw[2]]);
        scene.opacity_logits.push(logit_from_u8(alphas[i]));
        for c in 0..3 {
            scene
                .sh
                .push((colors[3 * i + c] as f32 / 255.0 - 0.5) / COLOR_SCALE);
        }
        for (j, &b) in sh[rest * i..rest * (i + 1)].iter().enumerate() {
            scene
                .sh
                .push(RUB_SH_SIGN[j / 3] * (b as f32 - 128.0) / 128.0);
        }
    }
    super::check_decoded(&scene, path, "SPZ")?;
    Ok(scene)
}

/// Unpacks a "smallest three" quaternion into `(x, y, z, w)`.
fn unpack_smallest_three(mut comp: u32) -> [f32; 4] {
    const MASK: u32 = (1 << 9) - 1;
    let largest = (comp >> 30) as usize;
    let mut q = [0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i == largest {
            continue;
        }
        let mag = comp & MASK;
        let negative = (comp >> 9) & 1 == 1;
        comp >>= 10;
        let v = std::f32::consts::FRAC_1_SQRT_2 * mag as f32 / MASK as f32;
        q[i] = if negative { -v } else { v };
        sum += q[i] * q[i];
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    q
}

/// Packs a unit quaternion `(x, y, z, w)` as "smallest three".
fn pack_smallest_three(q: [f32; 4]) -> u32 {
    let mut largest = 0;
    for i in 1..4 {
        if q[i].abs() > q[largest].abs() {
            largest = i;
        }
    }
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (i, &v) in q.iter().enumerate() {
        if i == largest {
            continue;
        }
        let negbit = ((v < 0.0) ^ negate) as u32;
        let mag = (511.0 * (v.abs() / std::f32::consts::FRAC_1_SQRT_2) + 0.5) as u32;
        comp = (comp << 10) | (negbit << 9) | mag.min(511);
    }
    comp
}

fn to_u8(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// Quantises one SH coefficient to the byte `x * 128 + 128` rounded once, straight to a grid
/// of `bucket` (8 for band 1, 16 above: Niantic's default 5 and 4 bits), so the error is at
/// most half a bucket inside the representable range.
fn quantize_sh(x: f32, bucket: i32) -> u8 {
    let steps = (x * 128.0 / bucket as f32).round().clamp(-256.0, 256.0) as i32;
    (steps * bucket + 128).clamp(0, 255) as u8
}

/// The largest `fractional_bits <= 12` at which every position fits the signed 24-bit range.
pub fn fractional_bits_for(scene: &Scene) -> Option<u8> {
    let max = scene
        .positions
        .iter()
        .flatten()
        .fold(0f32, |m, v| m.max(v.abs()));
    (0..=DEFAULT_FRACTIONAL_BITS)
        .rev()
        .find(|&fb| (max as f64 * (1u64 << fb) as f64).round() <= ((1 << 23) - 1) as f64)
}

/// [`to_bytes_v3`] in `axes`: [`SpzAxes::Raw`] writes the PLY axes as they are (what
/// PlayCanvas's splat-transform reads and writes).
pub fn to_bytes_v3_with_axes(scene: &Scene, axes: SpzAxes) -> Result<Vec<u8>, String> {
    match axes {
        SpzAxes::Spec => to_bytes_v3(scene),
        SpzAxes::Raw => {
            let mut turned = scene.clone();
            flip_rub(&mut turned);
            to_bytes_v3(&turned)
        }
    }
}

/// Serialises a scene as SPZ v3 (gzip, RUB axes, Niantic's default quantisation: 12
/// fractional bits unless the scene is too large for them, 5-bit band-1 SH, 4-bit higher
/// bands). Fails when a position is too far from the origin for 24-bit fixed point.
pub fn to_bytes_v3(scene: &Scene) -> Result<Vec<u8>, String> {
    let fb = fractional_bits_for(scene).ok_or_else(|| {
        "the scene has positions beyond +-8388607 units, which SPZ's 24-bit fixed point cannot hold"
            .to_string()
    })?;
    let n = scene.len();
    let count = u32::try_from(n).map_err(|_| "SPZ holds at most 2^32-1 Gaussians".to_string())?;
    let rest = scene.sh_stride() - 3;
    let mut out = Vec::with_capacity(16 + n * (20 + rest));
    out.extend_from_slice(&MAGIC.to_le_bytes());
    out.extend_from_slice(&3u32.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    let flags = if scene.antialiased {
        FLAG_ANTIALIASED
    } else {
        0
    };
    out.extend_from_slice(&[scene.sh_degree as u8, fb, flags, 0]);
    let scale = (1u32 << fb) as f32;
    let flip = [1.0f32, -1.0, -1.0];
    for p in &scene.positions {
        for a in 0..3 {
            let fixed = (flip[a] * p[a] * scale).round() as i32;
            out.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    for &o in &scene.opacity_logits {
        out.push(to_u8(sigmoid(o) * 255.0));
    }
    let stride = scene.sh_stride();
    for i in 0..n {
        for c in 0..3 {
            out.push(to_u8(
                scene.sh[i * stride + c] * (COLOR_SCALE * 255.0) + 127.5,
            ));
        }
    }
    for s in &scene.log_scales {
        for v in s {
            out.push(to_u8((v + 10.0) * 16.0));
        }
    }
    for q in &scene.rotations {
        let q = super::normalize_quat(*q);
        let packed = pack_smallest_three([q[1], -q[2], -q[3], q[0]]);
        out.extend_from_slice(&packed.to_le_bytes());
    }
    for i in 0..n {
        for (j, &v) in scene.sh[i * stride + 3..(i + 1) * stride]
            .iter()
            .enumerate()
        {
            let bucket = if j < 9 { 8 } else { 16 };
            out.push(quantize_sh(RUB_SH_SIGN[j / 3] * v, bucket));
        }
    }
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut gz, &out).map_err(|e| e.to_string())?;
    gz.finish().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ground_on_top_looks_upside_down() {
        // A ground patch at y in [0, 0.02] (900 Gaussians) with 100 rising to y = -1.
        let mut s = Scene::empty(0);
        s.positions = (0..1000)
            .map(|i| {
                let y = if i < 900 {
                    i as f32 * 2e-5
                } else {
                    -((i - 900) as f32) * 0.01
                };
                [i as f32 * 1e-3, y, 0.0]
            })
            .collect();
        assert!(!looks_upside_down(&s));
        let right_way = axes_note(Path::new("a.spz"), &s, SpzAxes::Spec);
        assert!(right_way.is_none());
        for p in &mut s.positions {
            p[1] = -p[1];
        }
        assert!(looks_upside_down(&s));
        let note = axes_note(Path::new("a.spz"), &s, SpzAxes::Spec).unwrap();
        assert!(
            note.contains("a.spz looks upside down") && note.contains("--spz-axes raw"),
            "{note}"
        );
        // Even along y, or too few Gaussians: nothing to say.
        s.positions = (0..1000).map(|i| [0.0, i as f32, 0.0]).collect();
        assert!(!looks_upside_down(&s));
        s.positions.truncate(99);
        s.positions[0][1] = -1e6;
        assert!(!looks_upside_down(&s));
    }

    #[test]
    fn smallest_three_round_trips_within_its_step() {
        // xorshift64, uniform in [-1, 1): the scene module does not lean on `gen`.
        let mut state = 7u64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
        };
        for _ in 0..1000 {
            let q = super::super::normalize_quat([uniform(), uniform(), uniform(), uniform()]);
            let back = unpack_smallest_three(pack_smallest_three(q));
            // Same rotation up to sign; each kept component within half a 9-bit step.
            let dot: f32 = q.iter().zip(&back).map(|(a, b)| a * b).sum();
            let s = dot.signum();
            for k in 0..4 {
                assert!((q[k] - s * back[k]).abs() < 2e-3, "{q:?} {back:?}");
            }
        }
    }

    #[test]
    fn sh_quantisation_hits_its_grid() {
        assert_eq!(quantize_sh(0.0, 8), 128);
        assert_eq!(quantize_sh(0.5, 16), 192);
        assert_eq!(quantize_sh(-2.0, 8), 0);
        assert_eq!(quantize_sh(2.0, 16), 255);
    }

    /// A small scene with every field set and SH degree 3, made of distinct values.
    fn scene_of_every_field() -> Scene {
        let mut scene = Scene::empty(3);
        for i in 0..5 {
            let f = i as f32;
            scene.positions.push([0.5 + f, -1.25 * f, 2.0 - f]);
            scene.log_scales.push([-2.0, -1.5 - 0.1 * f, -3.0]);
            scene.rotations.push(super::super::normalize_quat([
                0.9,
                0.1 * f,
                -0.3,
                0.2 + 0.05 * f,
            ]));
            scene.opacity_logits.push(0.5 - 0.2 * f);
            scene
                .sh
                .extend((0..48).map(|k| 0.4 * ((k as f32 + f) * 0.7).sin()));
        }
        scene
    }

    #[test]
    fn raw_axes_are_the_spec_turned_about_x() {
        let scene = scene_of_every_field();
        let path = Path::new("t.spz");
        for axes in [SpzAxes::Spec, SpzAxes::Raw] {
            // Written and read in the same axes: the scene within SPZ's quantisation.
            let bytes = to_bytes_v3_with_axes(&scene, axes).unwrap();
            let (back, _, _) = parse_with_axes(&bytes, path, axes).unwrap();
            for (a, b) in scene.positions.iter().zip(&back.positions) {
                for k in 0..3 {
                    assert!(
                        (a[k] - b[k]).abs() <= 0.5 / 4096.0 + 1e-6,
                        "{axes}: {a:?} {b:?}"
                    );
                }
            }
            // Read in the other axes: exactly the turn about x of the same-axes read.
            let other = if axes == SpzAxes::Spec {
                SpzAxes::Raw
            } else {
                SpzAxes::Spec
            };
            let (mut turned, _, _) = parse_with_axes(&bytes, path, other).unwrap();
            assert_ne!(turned.positions, back.positions);
            flip_rub(&mut turned);
            assert_eq!(turned.positions, back.positions, "{axes}");
            assert_eq!(turned.rotations, back.rotations, "{axes}");
            assert_eq!(turned.sh, back.sh, "{axes}");
            assert_eq!(turned.log_scales, back.log_scales, "{axes}");
            assert_eq!(turned.opacity_logits, back.opacity_logits, "{axes}");
        }
        // Raw bytes hold the PLY's axes: y of a raw file is y of the scene, the spec's -y.
        let raw = to_bytes_v3_with_axes(&scene, SpzAxes::Raw).unwrap();
        let spec = to_bytes_v3(&scene).unwrap();
        assert_ne!(raw, spec);
        let (as_spec, _, _) = parse(&raw, path).unwrap();
        assert!(
            (as_spec.positions[1][1] - 1.25).abs() < 1e-3,
            "{:?}",
            as_spec.positions[1]
        );
        // The spec read of the raw file draws the same Gaussians seen turned: each one's
        // SH, evaluated at the turned direction, gives the colour of the original.
        let d = glam::Vec3::new(0.3, -0.5, 0.81).normalize();
        let f = glam::Vec3::new(d.x, -d.y, -d.z);
        let (raw_read, _, _) = parse_with_axes(&raw, path, SpzAxes::Raw).unwrap();
        let a = crate::core::model::sh::eval_sh(3, &raw_read.sh[48..96], d)[0];
        let b = crate::core::model::sh::eval_sh(3, &as_spec.sh[48..96], f)[0];
        assert!((a - b).abs() < 1e-5, "{a} {b}");
    }

    #[test]
    fn axes_parse_and_name_themselves() {
        assert_eq!("spec".parse::<SpzAxes>(), Ok(SpzAxes::Spec));
        assert_eq!("RAW".parse::<SpzAxes>(), Ok(SpzAxes::Raw));
        assert_eq!(SpzAxes::default(), SpzAxes::Spec);
        assert_eq!(SpzAxes::Raw.to_string(), "raw");
        let e = "rub".parse::<SpzAxes>().unwrap_err();
        assert!(
            e.contains("unknown SPZ axes \"rub\"") && e.contains("splat-transform"),
            "{e}"
        );
    }

    #[test]
    fn sh_signs_match_a_y_z_flip_of_the_basis() {
        // Evaluate the real SH basis at d and at (x, -y, -z): each coefficient's sign rule
        // must make the two evaluations agree.
        let d = glam::Vec3::new(0.3, -0.5, 0.81).normalize();
        let f = glam::Vec3::new(d.x, -d.y, -d.z);
        for k in 1..16 {
            let mut sh = vec![0f32; 48];
            sh[3 * k] = 0.1;
            let a = crate::core::model::sh::eval_sh(3, &sh, d)[0];
            sh[3 * k] = 0.1 * RUB_SH_SIGN[k - 1];
            let b = crate::core::model::sh::eval_sh(3, &sh, f)[0];
            assert!((a - b).abs() < 1e-5, "coefficient {k}: {a} vs {b}");
        }
    }
}
