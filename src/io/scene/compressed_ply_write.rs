//! The PlayCanvas / SuperSplat compressed-PLY writer: the layout
//! [`super::compressed_ply`] documents and reads, as splat-transform writes it.
//!
//! The Gaussians are stored in Morton order ([`super::quantize::morton_order`]) so each
//! chunk of 256 covers a small box. Per Gaussian, with the chunk's bounds:
//! * position and log scale: 11-10-11-bit unorms over the chunk's box (log scales'
//!   bounds clamped to [-20, 20], as splat-transform does), rounded to the nearest step;
//! * rotation: normalised, sign-flipped so the largest component is positive, the other
//!   three as 10-bit unorms of `v * sqrt(1/2) + 0.5`;
//! * colour: the DC colour `0.5 + C0 * f_dc` as a byte over the chunk's colour range;
//!   alpha `sigmoid(opacity)` as a byte, kept within 1..=254 so that no reader's inverse
//!   sigmoid is infinite (a byte of 0 or 255 is, in splat-transform's);
//! * SH bands above the DC: one byte per `f_rest_*`, the byte whose decoded value
//!   (`(b + 0.5) / 256 * 8 - 4`, with 0 and 255 standing for -4 and 4) is nearest.
//!
//! Header comments record what the format has no property for: the kernel and rules as
//! the INRIA PLY writer does, and antialiased training as `SplatRenderMode: mip` (the
//! comment splat-transform and Brush write).

use super::compressed_ply::{CHUNK_PROPS, CHUNK_SIZE, VERTEX_PROPS};
use super::ply::{KERNEL_COMMENT, MIP_FILTER_COMMENT, RULES_COMMENT};
use super::{color_from_dc, quantize, sigmoid, Scene};
use crate::core::model::{Rules, SplatKernel};

/// The header comment that records antialiased training (Brush's and splat-transform's).
pub const ANTIALIASED_COMMENT: &str = "SplatRenderMode: mip";

/// `v` in `[0, 1]` (clamped) as a `bits`-bit unorm, rounded.
fn unorm(v: f32, bits: u32) -> u32 {
    let max = ((1u32 << bits) - 1) as f32;
    (v.clamp(0.0, 1.0) * max).round() as u32
}

/// Where `x` lies between `lo` and `hi`, 0 to 1 (0 for an empty range).
fn normalize(x: f32, lo: f32, hi: f32) -> f32 {
    if x <= lo {
        0.0
    } else if x >= hi {
        1.0
    } else {
        (x - lo) / (hi - lo)
    }
}

fn pack_11_10_11(v: [f32; 3]) -> u32 {
    unorm(v[0], 11) << 21 | unorm(v[1], 10) << 11 | unorm(v[2], 11)
}

/// `(rot_0..rot_3)` as 2-10-10-10: the largest component's index in the top two bits.
pub(crate) fn pack_rotation(q: [f32; 4]) -> u32 {
    let (q, largest) = largest_positive(q);
    let mut out = largest as u32;
    for (k, &v) in q.iter().enumerate() {
        if k != largest {
            out = out << 10 | unorm(v * std::f32::consts::FRAC_1_SQRT_2 + 0.5, 10);
        }
    }
    out
}

/// The normalised quaternion with its largest-magnitude component (the first on ties)
/// made positive, and that component's index. A zero quaternion is the identity.
pub(crate) fn largest_positive(q: [f32; 4]) -> ([f32; 4], usize) {
    let norm = q
        .iter()
        .map(|&v| f64::from(v) * f64::from(v))
        .sum::<f64>()
        .sqrt();
    if norm == 0.0 || !norm.is_finite() {
        return ([1.0, 0.0, 0.0, 0.0], 0);
    }
    let mut largest = 0;
    for k in 1..4 {
        if q[k].abs() > q[largest].abs() {
            largest = k;
        }
    }
    let s = if q[largest] < 0.0 { -1.0 } else { 1.0 } / norm;
    (q.map(|v| (f64::from(v) * s) as f32), largest)
}

/// An opacity logit as an alpha byte, within 1..=254.
pub(crate) fn alpha_byte(logit: f32) -> u8 {
    (sigmoid(logit) * 255.0).round().clamp(1.0, 254.0) as u8
}

/// The SH byte whose decoded value is nearest `v`: byte `b` decodes to
/// `((b + 0.5) / 256 - 0.5) * 8`, except 0 and 255, which decode to -4 and 4.
pub(crate) fn sh_byte(v: f32) -> u8 {
    let t = (v / 8.0 + 0.5) * 256.0;
    if t.is_nan() {
        return 128;
    }
    let decoded = |b: i32| match b {
        0 => 0.0,
        255 => 256.0,
        b => b as f32 + 0.5,
    };
    let b = (t - 0.5).round().clamp(0.0, 255.0) as i32;
    let mut best = b;
    for c in [b - 1, b + 1] {
        if (0..=255).contains(&c) && (decoded(c) - t).abs() < (decoded(best) - t).abs() {
            best = c;
        }
    }
    best as u8
}

/// Checks that every value the writers quantise is finite (the loaders guarantee it; a
/// scene built in memory may not). `Err` names the first offending Gaussian.
pub(crate) fn check_finite(scene: &Scene) -> Result<(), String> {
    for i in 0..scene.len() {
        let stride = scene.sh_stride();
        let ok = scene.positions[i].iter().all(|v| v.is_finite())
            && scene.log_scales[i].iter().all(|v| v.is_finite())
            && scene.rotations[i].iter().all(|v| v.is_finite())
            && !scene.opacity_logits[i].is_nan()
            && scene.sh[i * stride..(i + 1) * stride]
                .iter()
                .all(|v| v.is_finite());
        if !ok {
            return Err(format!("Gaussian {i} has a non-finite value"));
        }
    }
    Ok(())
}

/// Serialises a scene as a compressed PLY. `Err`: the scene is empty (a compressed PLY
/// of no chunks is refused by viewers), inconsistent or has non-finite values.
pub fn to_bytes(scene: &Scene) -> Result<Vec<u8>, String> {
    scene.check_consistent()?;
    if scene.is_empty() {
        return Err("the scene holds no Gaussians".into());
    }
    check_finite(scene)?;
    let n = scene.len();
    let chunks = n.div_ceil(CHUNK_SIZE as usize);
    let k_rest = scene.sh_coeffs() - 1;
    let stride = scene.sh_stride();

    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header.push_str(&format!(
        "comment Generated by verisplat {}\n",
        env!("CARGO_PKG_VERSION")
    ));
    if scene.kernel != SplatKernel::Gaussian {
        header.push_str(&format!("comment {KERNEL_COMMENT} {}\n", scene.kernel));
    }
    if scene.rules != Rules::Original {
        header.push_str(&format!("comment {RULES_COMMENT} {}\n", scene.rules));
    }
    if scene.mip_filter {
        header.push_str(&format!("comment {MIP_FILTER_COMMENT} 3d\n"));
    }
    if scene.antialiased {
        header.push_str(&format!("comment {ANTIALIASED_COMMENT}\n"));
    }
    header.push_str(&format!("element chunk {chunks}\n"));
    for p in CHUNK_PROPS {
        header.push_str(&format!("property float {p}\n"));
    }
    header.push_str(&format!("element vertex {n}\n"));
    for p in VERTEX_PROPS {
        header.push_str(&format!("property uint {p}\n"));
    }
    if k_rest > 0 {
        header.push_str(&format!("element sh {n}\n"));
        for j in 0..3 * k_rest {
            header.push_str(&format!("property uchar f_rest_{j}\n"));
        }
    }
    header.push_str("end_header\n");

    let order = quantize::morton_order(&scene.positions);
    let mut chunk_bytes = Vec::with_capacity(chunks * 18 * 4);
    let mut vertex_bytes = Vec::with_capacity(n * 16);
    let mut sh_bytes = Vec::with_capacity(n * 3 * k_rest);
    let colour = |i: usize, c: usize| color_from_dc(scene.sh[i * stride + c]);
    for members in order.chunks(CHUNK_SIZE as usize) {
        // Bounds: position, log scale (clamped to [-20, 20]) and colour, per axis.
        let mut lo = [f32::INFINITY; 9];
        let mut hi = [f32::NEG_INFINITY; 9];
        for &i in members {
            let s = scene.log_scales[i];
            for a in 0..3 {
                let v = [scene.positions[i][a], s[a].clamp(-20.0, 20.0), colour(i, a)];
                for (g, v) in v.into_iter().enumerate() {
                    lo[3 * g + a] = lo[3 * g + a].min(v);
                    hi[3 * g + a] = hi[3 * g + a].max(v);
                }
            }
        }
        for g in 0..3 {
            for b in [&lo, &hi] {
                for a in 0..3 {
                    chunk_bytes.extend_from_slice(&b[3 * g + a].to_le_bytes());
                }
            }
        }
        for &i in members {
            let p = pack_11_10_11(std::array::from_fn(|a| {
                normalize(scene.positions[i][a], lo[a], hi[a])
            }));
            let s = pack_11_10_11(std::array::from_fn(|a| {
                normalize(scene.log_scales[i][a], lo[3 + a], hi[3 + a])
            }));
            let r = pack_rotation(scene.rotations[i]);
            let rgb: [u32; 3] =
                std::array::from_fn(|a| unorm(normalize(colour(i, a), lo[6 + a], hi[6 + a]), 8));
            let c = rgb[0] << 24
                | rgb[1] << 16
                | rgb[2] << 8
                | u32::from(alpha_byte(scene.opacity_logits[i]));
            for v in [p, r, s, c] {
                vertex_bytes.extend_from_slice(&v.to_le_bytes());
            }
            for c in 0..3 {
                for k in 0..k_rest {
                    sh_bytes.push(sh_byte(scene.sh[i * stride + (k + 1) * 3 + c]));
                }
            }
        }
    }
    let mut out = header.into_bytes();
    out.extend_from_slice(&chunk_bytes);
    out.extend_from_slice(&vertex_bytes);
    out.extend_from_slice(&sh_bytes);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sh_bytes_decode_to_the_nearest_value() {
        let decode = |b: u8| match b {
            0 => -4.0,
            255 => 4.0,
            b => ((b as f32 + 0.5) / 256.0 - 0.5) * 8.0,
        };
        for i in -500..=500 {
            let v = i as f32 * 0.0091;
            let b = sh_byte(v);
            let best = (0..=255u8)
                .map(|c| (decode(c) - v).abs())
                .fold(f32::INFINITY, f32::min);
            assert!((decode(b) - v).abs() <= best + 1e-6, "{v}: byte {b}");
        }
        assert_eq!(sh_byte(-10.0), 0);
        assert_eq!(sh_byte(10.0), 255);
    }

    #[test]
    fn rotation_packing_keeps_the_largest_positive() {
        let r = pack_rotation([0.1, -0.2, -0.9, 0.3]);
        assert_eq!(r >> 30, 2);
        // The other three flipped with the largest: 0.1 -> negative, so below midpoint.
        assert!((r >> 20) & 1023 < 511);
        assert_eq!(alpha_byte(100.0), 254);
        assert_eq!(alpha_byte(-100.0), 1);
    }
}
