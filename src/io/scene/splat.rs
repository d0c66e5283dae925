//! antimatter15 `.splat`: 32 bytes per Gaussian, no header, no magic.
//!
//! Record layout (little-endian): position `f32 x3`, linear scale `f32 x3`, colour and
//! opacity `u8 RGBA`, rotation `u8 x4` as `(w, x, y, z)` with `q = (b - 128) / 128`.
//! Colour is the rendered DC colour `0.5 + C0 * f_dc` in `[0, 1]`, so it is decoded to the
//! SH DC term `f_dc = (rgb / 255 - 0.5) / C0`; the format has no higher SH bands. Axes are
//! the PLY's (INRIA/COLMAP, y down).

use super::{color_from_dc, dc_from_color, logit_from_u8, sigmoid, Scene, SceneError};
use std::path::Path;

/// Bytes per Gaussian.
pub const RECORD_BYTES: usize = 32;

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Parses a `.splat` file held in memory. `path` is used in error messages only.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    if bytes.len() % RECORD_BYTES != 0 {
        return Err(SceneError::invalid(
            path,
            format!(
                "is {} bytes long, which is not a multiple of the 32-byte .splat record; the file is truncated or not a .splat",
                bytes.len()
            ),
        ));
    }
    let n = bytes.len() / RECORD_BYTES;
    let mut scene = Scene::empty(0);
    scene.positions.reserve_exact(n);
    scene.log_scales.reserve_exact(n);
    scene.rotations.reserve_exact(n);
    scene.opacity_logits.reserve_exact(n);
    scene.sh.reserve_exact(3 * n);
    for (i, r) in bytes.chunks_exact(RECORD_BYTES).enumerate() {
        let p = [f32_at(r, 0), f32_at(r, 4), f32_at(r, 8)];
        let s = [f32_at(r, 12), f32_at(r, 16), f32_at(r, 20)];
        if !p.iter().all(|v| v.is_finite()) {
            return Err(SceneError::invalid(
                path,
                format!(".splat record {i} has a non-finite position {p:?}"),
            ));
        }
        if !s.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(SceneError::invalid(
                path,
                format!(".splat record {i} has a scale {s:?} that is not a positive finite number"),
            ));
        }
        let q = [r[28], r[29], r[30], r[31]].map(|b| (b as f32 - 128.0) / 128.0);
        if q.iter().all(|v| *v == 0.0) {
            return Err(SceneError::invalid(
                path,
                format!(".splat record {i} has a zero-length rotation (all four bytes are 128)"),
            ));
        }
        scene.positions.push(p);
        scene.log_scales.push(s.map(f32::ln));
        scene.rotations.push(q);
        scene.opacity_logits.push(logit_from_u8(r[27]));
        scene
            .sh
            .extend(r[24..27].iter().map(|&c| dc_from_color(c as f32 / 255.0)));
    }
    Ok(scene)
}

/// True when `bytes` looks like a `.splat` file: a non-empty multiple of 32 bytes whose
/// records have finite positions and positive finite scales. Used to recognise a `.splat`
/// that does not carry the extension, after every format with a magic was ruled out.
pub fn is_plausible(bytes: &[u8]) -> bool {
    !bytes.is_empty()
        && bytes.len() % RECORD_BYTES == 0
        && bytes.chunks_exact(RECORD_BYTES).all(|r| {
            (0..3).all(|k| f32_at(r, 4 * k).is_finite() && f32_at(r, 4 * k).abs() < 1e7)
                && (3..6).all(|k| {
                    let s = f32_at(r, 4 * k);
                    s.is_finite() && s > 0.0
                })
                && r[28..32].iter().any(|&b| b != 128)
        })
}

fn to_u8(v: f32) -> u8 {
    (v.round()).clamp(0.0, 255.0) as u8
}

/// Serialises a scene as `.splat` (SH bands above the DC term are dropped; Gaussians keep
/// their order). Colours outside `[0, 1]` are clamped, as the format cannot hold them.
pub fn to_bytes(scene: &Scene) -> Vec<u8> {
    let stride = scene.sh_stride();
    let mut out = Vec::with_capacity(scene.len() * RECORD_BYTES);
    for i in 0..scene.len() {
        for v in scene.positions[i] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in scene.log_scales[i] {
            out.extend_from_slice(&v.exp().to_le_bytes());
        }
        for c in 0..3 {
            out.push(to_u8(color_from_dc(scene.sh[i * stride + c]) * 255.0));
        }
        out.push(to_u8(sigmoid(scene.opacity_logits[i]) * 255.0));
        let q = super::normalize_quat(scene.rotations[i]);
        for v in q {
            out.push(to_u8(v * 128.0 + 128.0));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_record_decodes_to_the_documented_values() {
        let mut b = Vec::new();
        for v in [1.0f32, -2.0, 3.0, 0.5, 1.0, 2.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&[255, 128, 0, 191, 255, 128, 128, 128]);
        let s = parse(&b, Path::new("t.splat")).unwrap();
        assert_eq!(s.positions, vec![[1.0, -2.0, 3.0]]);
        assert!((s.log_scales[0][0] - 0.5f32.ln()).abs() < 1e-7);
        assert_eq!(s.rotations[0], [127.0 / 128.0, 0.0, 0.0, 0.0]);
        let c0 = crate::core::model::sh::SH_C0;
        assert!((s.sh[0] - 0.5 / c0).abs() < 1e-5);
        assert!((s.sh[2] + 0.5 / c0).abs() < 1e-5);
        assert!((sigmoid(s.opacity_logits[0]) - 191.0 / 255.0).abs() < 1e-6);
        // Fully opaque alpha still gives a finite logit.
        b[27] = 255;
        assert!(parse(&b, Path::new("t.splat")).unwrap().opacity_logits[0].is_finite());
        // Writing it back gives the same bytes.
        b[27] = 191;
        assert_eq!(to_bytes(&parse(&b, Path::new("t.splat")).unwrap()), b);
    }

    #[test]
    fn bad_lengths_and_values_are_rejected() {
        let e = parse(&[0u8; 33], Path::new("t.splat")).unwrap_err();
        assert!(
            e.to_string().contains("not a multiple of the 32-byte"),
            "{e}"
        );
        let mut b = vec![0u8; 32];
        b[12..16].copy_from_slice(&(-1.0f32).to_le_bytes());
        let e = parse(&b, Path::new("t.splat")).unwrap_err();
        assert!(e.to_string().contains("positive finite"), "{e}");
        assert!(!is_plausible(&b));
    }
}
