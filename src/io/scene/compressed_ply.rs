//! PlayCanvas / SuperSplat compressed PLY: a binary little-endian PLY with three elements.
//!
//! * `chunk` (one per 256 Gaussians): float bounds `min_/max_x,y,z`, `min_/max_scale_x,y,z`
//!   (log scales) and `min_/max_r,g,b` (DC colours `0.5 + C0 * f_dc`).
//! * `vertex`: four `uint`s. `packed_position` and `packed_scale` are 11-10-11 bit unorms
//!   (x in the top 11 bits) lerped between the chunk bounds; `packed_rotation` is 2-10-10-10:
//!   the top 2 bits index the largest of `(rot_0..rot_3)`, which is rebuilt as the positive
//!   square root, and the three others are `(v / 1023 - 0.5) * sqrt(2)`; `packed_color` is
//!   8-8-8-8 RGBA, colour lerped between the chunk bounds and alpha the opacity.
//! * `sh` (optional): one `uchar` per `f_rest_*` (channel-major as in INRIA PLYs), decoded
//!   as PlayCanvas's engine and splat-transform decode it: `((b + 0.5) / 256 - 0.5) * 8`,
//!   the middle of the byte's step, with 0 and 255 standing for -4 and 4.
//!
//! Axes are the PLY's. An alpha byte of 0 or 255 is clamped half a step inwards so the
//! opacity logit stays finite (SuperSplat writes 255 for fully opaque splats). A header
//! comment `SplatRenderMode: mip` (Brush, splat-transform) or `antialiased 1` (Postshot)
//! records antialiased training; the verisplat kernel and rules comments are read as in
//! INRIA PLYs. The writer is [`super::compressed_ply_write`].

use super::ply::{parse_header, Element, Format, Header, Property, ScalarType};
use super::{dc_from_color, logit_from_u8, Scene, SceneError};
use std::path::Path;

/// Gaussians per chunk.
pub const CHUNK_SIZE: u64 = 256;

/// Properties of each `chunk` row (bounds of its positions, scales and colours), in order.
pub const CHUNK_PROPS: [&str; 18] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
    "min_r",
    "min_g",
    "min_b",
    "max_r",
    "max_g",
    "max_b",
];
/// Properties of each packed `vertex` row, in order.
pub const VERTEX_PROPS: [&str; 4] = [
    "packed_position",
    "packed_rotation",
    "packed_scale",
    "packed_color",
];

/// True when a parsed PLY header has the compressed layout (a `chunk` element and a
/// `vertex` element with `packed_position`).
pub(crate) fn is_compressed(header: &Header) -> bool {
    header.element("chunk").is_some()
        && header
            .element("vertex")
            .is_some_and(|v| v.has("packed_position"))
}

/// Where one element's rows lie in the file, and where each property sits in a row.
struct Table<'a> {
    bytes: &'a [u8],
    start: usize,
    row: usize,
    count: usize,
    el: &'a Element,
}

impl Table<'_> {
    /// Byte offset and type of property `name` within a row.
    fn column(&self, name: &str, path: &Path) -> Result<(usize, ScalarType), SceneError> {
        let mut off = 0;
        for p in &self.el.properties {
            if let Property::Scalar { name: n, ty } = p {
                if n == name {
                    return Ok((off, *ty));
                }
                off += ty.size();
            }
        }
        Err(SceneError::invalid(
            path,
            format!(
                "is a compressed PLY whose \"{}\" element lacks the property \"{name}\"",
                self.el.name
            ),
        ))
    }

    fn get(&self, i: usize, (off, ty): (usize, ScalarType)) -> f64 {
        ty.read(&self.bytes[self.start + i * self.row + off..], false)
    }
}

fn unorm(v: u32, bits: u32) -> f32 {
    let max = (1u32 << bits) - 1;
    (v & max) as f32 / max as f32
}

fn unpack_11_10_11(v: u32) -> [f32; 3] {
    [unorm(v >> 21, 11), unorm(v >> 11, 10), unorm(v, 11)]
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// Decodes a 2-10-10-10 "largest omitted" quaternion into `(rot_0..rot_3)`.
fn unpack_rotation(v: u32) -> [f32; 4] {
    let norm = std::f32::consts::SQRT_2;
    let a = (unorm(v >> 20, 10) - 0.5) * norm;
    let b = (unorm(v >> 10, 10) - 0.5) * norm;
    let c = (unorm(v, 10) - 0.5) * norm;
    let m = (1.0 - (a * a + b * b + c * c)).max(0.0).sqrt();
    match v >> 30 {
        0 => [m, a, b, c],
        1 => [a, m, b, c],
        2 => [a, b, m, c],
        _ => [a, b, c, m],
    }
}

/// An SH byte's value: the middle of its step, `((b + 0.5) / 256 - 0.5) * 8`, with 0 and
/// 255 standing for the ends of the range, -4 and 4.
pub(crate) fn sh_from_byte(b: u8) -> f32 {
    let t = match b {
        0 => 0.0,
        255 => 1.0,
        b => (b as f32 + 0.5) / 256.0,
    };
    (t - 0.5) * 8.0
}

/// True when the header's comments record antialiased training: the last of
/// `SplatRenderMode: mip|default|2dgs` (Brush, splat-transform) or `antialiased 1|0`
/// (Postshot) decides, as in splat-transform.
fn antialiased(header: &Header) -> bool {
    let mut aa = false;
    for (_, text) in &header.comments {
        let lower = text.trim().to_ascii_lowercase();
        if let Some(mode) = lower.strip_prefix("splatrendermode:") {
            aa = mode.trim() == "mip";
        } else if let Some(v) = lower.strip_prefix("antialiased ") {
            match v.trim() {
                "1" => aa = true,
                "0" => aa = false,
                _ => {}
            }
        }
    }
    aa
}

/// Parses a compressed PLY held in memory. `path` is used in error messages only.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    let header = parse_header(bytes, path)?;
    let bad = |m: String| SceneError::invalid(path, m);
    if header.format != Format::BinaryLe {
        return Err(bad(
            "is a compressed PLY that is not binary_little_endian, which the format requires"
                .into(),
        ));
    }
    let tables = lay_out(bytes, &header, path)?;
    let table = |name: &str| tables.iter().find(|t| t.el.name == name);
    let (Some(chunks), Some(verts)) = (table("chunk"), table("vertex")) else {
        return Err(bad(
            "is not a compressed PLY: it needs \"chunk\" and \"vertex\" elements".into(),
        ));
    };
    let n = verts.count;
    if (chunks.count as u64).saturating_mul(CHUNK_SIZE) < n as u64 {
        return Err(bad(format!(
            "has {} chunks, too few for {n} Gaussians at {CHUNK_SIZE} per chunk",
            chunks.count
        )));
    }
    let chunk_cols = CHUNK_PROPS
        .iter()
        .map(|p| chunks.column(p, path))
        .collect::<Result<Vec<_>, _>>()?;
    let vert_cols = VERTEX_PROPS
        .iter()
        .map(|p| verts.column(p, path))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some((_, ty)) = vert_cols.iter().find(|(_, ty)| *ty != ScalarType::U32) {
        return Err(bad(format!(
            "is a compressed PLY whose packed vertex properties are {ty:?}, not uint"
        )));
    }
    let (sh_degree, sh_cols) = sh_columns(table("sh"), n, path)?;
    let k_rest = super::sh_coeffs_for_degree(sh_degree) - 1;

    let mut scene = Scene::empty(sh_degree);
    scene.kernel = header.kernel(path)?;
    scene.rules = header.rules(path)?;
    scene.mip_filter = header.mip_filter(path)?;
    scene.antialiased = antialiased(&header);
    scene.positions.reserve_exact(n);
    scene.log_scales.reserve_exact(n);
    scene.rotations.reserve_exact(n);
    scene.opacity_logits.reserve_exact(n);
    scene.sh.reserve_exact(n * scene.sh_stride());
    let sh_table = table("sh");
    let mut bounds = [0f32; 18];
    for i in 0..n {
        let ci = i / CHUNK_SIZE as usize;
        if i % CHUNK_SIZE as usize == 0 {
            for (b, &col) in bounds.iter_mut().zip(&chunk_cols) {
                *b = chunks.get(ci, col) as f32;
            }
        }
        let [pp, pr, ps, pc] = [0, 1, 2, 3].map(|k| verts.get(i, vert_cols[k]) as u32);
        let p = unpack_11_10_11(pp);
        scene.positions.push(std::array::from_fn(|a| {
            lerp(bounds[a], bounds[3 + a], p[a])
        }));
        let s = unpack_11_10_11(ps);
        scene.log_scales.push(std::array::from_fn(|a| {
            lerp(bounds[6 + a], bounds[9 + a], s[a])
        }));
        scene.rotations.push(unpack_rotation(pr));
        let rgba = pc.to_be_bytes();
        scene.opacity_logits.push(logit_from_u8(rgba[3]));
        for c in 0..3 {
            let col = lerp(bounds[12 + c], bounds[15 + c], rgba[c] as f32 / 255.0);
            scene.sh.push(dc_from_color(col));
        }
        if let Some(t) = sh_table {
            for k in 0..k_rest {
                for c in 0..3 {
                    let b = t.get(i, sh_cols[c * k_rest + k]) as u8;
                    scene.sh.push(sh_from_byte(b));
                }
            }
        }
    }
    super::check_decoded(&scene, path, "compressed PLY")?;
    Ok(scene)
}

/// Lays out every element of the body; the format only has fixed-size scalar rows, and
/// the elements must fill the file exactly.
fn lay_out<'a>(
    bytes: &'a [u8],
    header: &'a Header,
    path: &Path,
) -> Result<Vec<Table<'a>>, SceneError> {
    let bad = |m: String| SceneError::invalid(path, m);
    let mut tables = Vec::new();
    let mut pos = header.body_offset as u64;
    for el in &header.elements {
        let mut row = 0u64;
        for p in &el.properties {
            match p {
                Property::Scalar { ty, .. } => row += ty.size() as u64,
                Property::List { name, .. } => {
                    return Err(bad(format!(
                        "is a compressed PLY with a list property \"{name}\" in element \"{}\", which the format does not have",
                        el.name
                    )))
                }
            }
        }
        let end = row
            .checked_mul(el.count)
            .and_then(|size| pos.checked_add(size))
            .filter(|&e| e <= bytes.len() as u64)
            .ok_or_else(|| {
                bad(format!(
                    "is truncated or its header lies: it declares {} {} elements of {row} bytes but only {} bytes of data follow",
                    el.count,
                    el.name,
                    (bytes.len() as u64).saturating_sub(pos)
                ))
            })?;
        tables.push(Table {
            bytes,
            start: pos as usize,
            row: row as usize,
            count: el.count as usize,
            el,
        });
        pos = end;
    }
    if pos != bytes.len() as u64 {
        return Err(bad(format!(
            "has {} bytes after the last element the header declares; its counts do not match the data",
            bytes.len() as u64 - pos
        )));
    }
    Ok(tables)
}

/// The optional SH element (`f_rest_*` bytes, channel-major, one row per vertex of `n`):
/// its SH degree and columns (degree 0 and none without one).
fn sh_columns(
    sh: Option<&Table>,
    n: usize,
    path: &Path,
) -> Result<(u32, Vec<(usize, ScalarType)>), SceneError> {
    let bad = |m: String| SceneError::invalid(path, m);
    Ok(match sh {
        None => (0, Vec::new()),
        Some(t) => {
            if t.count != n {
                return Err(bad(format!(
                    "has {} sh rows for {n} vertices; a compressed PLY needs one per vertex",
                    t.count
                )));
            }
            let k =
                t.el.properties
                    .iter()
                    .filter(|p| p.name().starts_with("f_rest_"))
                    .count();
            let degree = match k {
                0 => 0,
                9 => 1,
                24 => 2,
                45 => 3,
                k => {
                    return Err(bad(format!(
                        "has {k} f_rest_* properties in its sh element; 0, 9, 24 or 45 (SH degree 0 to 3) are valid"
                    )))
                }
            };
            let cols = (0..k)
                .map(|j| t.column(&format!("f_rest_{j}"), path))
                .collect::<Result<Vec<_>, _>>()?;
            (degree, cols)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_unpacking_places_the_largest_component() {
        // Largest = rot_0 (index 0), the other three at the unorm midpoint (about zero).
        let mid = 511u32;
        let v = (mid << 20) | (mid << 10) | mid;
        let q = unpack_rotation(v);
        assert!((q[0] - 1.0).abs() < 1e-3 && q[1].abs() < 2e-3, "{q:?}");
        let q = unpack_rotation((3 << 30) | v);
        assert!((q[3] - 1.0).abs() < 1e-3, "{q:?}");
        assert_eq!(unpack_11_10_11(u32::MAX), [1.0, 1.0, 1.0]);
    }
}
