//! The PlayCanvas SOG v2 writer: `meta.json` and lossless WebP textures in the layout
//! [`super::sog`] documents and reads, bundled as a zip (`.sog`) or as files in a
//! directory.
//!
//! As splat-transform writes it: the Gaussians in Morton order
//! ([`super::quantize::morton_order`]), textures `ceil(sqrt(n) / 4) * 4` pixels wide and a
//! multiple of 4 high; positions `sign(p) * ln(|p| + 1)` as 16-bit unorms between their
//! minimum and maximum (rounded, not truncated); quaternions as three bytes and the tag of
//! the dropped largest component; log scales and SH DC terms as indices into 256-entry
//! codebooks ([`super::quantize::codebook_1d`]); opacity as a byte (within 1..=254, so
//! no reader's inverse sigmoid is infinite); the higher SH bands as a palette
//! ([`super::quantize::sh_palette`], its size as splat-transform chooses it) whose
//! coefficients index a third codebook. Axes are the source's (no conversion, as the
//! reader applies none). Antialiased training is recorded both as `"antialias": true` and
//! as splat-transform's `"model": "antialiased"`. The zip stores its entries (WebP is
//! already compressed) with a fixed date, so the same scene gives the same bytes.

use super::compressed_ply_write::{alpha_byte, check_finite, largest_positive};
use super::{quantize, Scene};
use rayon::prelude::*;
use serde_json::json;
use std::io::Write;

/// The files of a SOG: `meta.json` and the textures it names, in writing order.
pub struct SogFiles {
    /// `meta.json`'s bytes.
    pub meta: Vec<u8>,
    /// `(file name, WebP bytes)` of each texture.
    pub textures: Vec<(String, Vec<u8>)>,
}

impl SogFiles {
    /// Bytes of all the files together.
    pub fn len(&self) -> usize {
        self.meta.len() + self.textures.iter().map(|(_, b)| b.len()).sum::<usize>()
    }

    /// True when there are no bytes (never, for an encoded SOG).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The files as a zip bundle (`.sog`): the textures, then `meta.json`, stored.
    pub fn to_zip(&self) -> Result<Vec<u8>, String> {
        let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .last_modified_time(zip::DateTime::default());
        let entries = self
            .textures
            .iter()
            .map(|(n, b)| (n.as_str(), b.as_slice()))
            .chain([("meta.json", self.meta.as_slice())]);
        for (name, bytes) in entries {
            zip.start_file(name, opts)
                .and_then(|_| zip.write_all(bytes).map_err(Into::into))
                .map_err(|e| format!("cannot build the SOG zip: {e}"))?;
        }
        let out = zip
            .finish()
            .map_err(|e| format!("cannot build the SOG zip: {e}"))?;
        Ok(out.into_inner())
    }
}

/// An RGBA8 texture being filled.
struct Texture {
    name: &'static str,
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

impl Texture {
    fn new(name: &'static str, width: usize, height: usize) -> Texture {
        Texture {
            name,
            width,
            height,
            rgba: vec![0; width * height * 4],
        }
    }

    fn set(&mut self, i: usize, px: [u8; 4]) {
        self.rgba[4 * i..4 * i + 4].copy_from_slice(&px);
    }

    /// Lossless WebP.
    fn encode(&self) -> Result<(String, Vec<u8>), String> {
        let mut out = Vec::new();
        image::codecs::webp::WebPEncoder::new_lossless(&mut out)
            .encode(
                &self.rgba,
                self.width as u32,
                self.height as u32,
                image::ExtendedColorType::Rgba8,
            )
            .map_err(|e| format!("cannot encode the SOG texture {}: {e}", self.name))?;
        Ok((self.name.to_string(), out))
    }
}

/// Largest texture side a WebP can have.
const MAX_WEBP_SIDE: usize = 16383;

/// `sign(v) * ln(|v| + 1)`, the transform SOG stores positions under.
fn log_transform(v: f64) -> f64 {
    v.signum() * v.abs().ln_1p()
}

/// Encodes a scene as SOG files. `Err`: the scene is empty, too large for WebP textures,
/// inconsistent or has non-finite values.
pub fn encode(scene: &Scene) -> Result<SogFiles, String> {
    scene.check_consistent()?;
    let n = scene.len();
    if n == 0 {
        return Err("the scene holds no Gaussians, and a SOG cannot be empty".into());
    }
    check_finite(scene)?;
    let width = ((n as f64).sqrt() / 4.0).ceil() as usize * 4;
    let height = n.div_ceil(width).div_ceil(4) * 4;
    if width > MAX_WEBP_SIDE || height > MAX_WEBP_SIDE {
        return Err(format!(
            "{n} Gaussians need {width}x{height} textures, beyond WebP's {MAX_WEBP_SIDE} pixels a side"
        ));
    }
    let order = quantize::morton_order(&scene.positions);
    let stride = scene.sh_stride();

    // Means: log-transformed, 16 bits between the bounds.
    let logged: Vec<[f64; 3]> = scene
        .positions
        .iter()
        .map(|p| p.map(|v| log_transform(f64::from(v))))
        .collect();
    let mut mins = [f64::INFINITY; 3];
    let mut maxs = [f64::NEG_INFINITY; 3];
    for l in &logged {
        for a in 0..3 {
            mins[a] = mins[a].min(l[a]);
            maxs[a] = maxs[a].max(l[a]);
        }
    }
    let mut means_l = Texture::new("means_l.webp", width, height);
    let mut means_u = Texture::new("means_u.webp", width, height);
    for (t, &i) in order.iter().enumerate() {
        let q: [u16; 3] = std::array::from_fn(|a| {
            let range = maxs[a] - mins[a];
            if range > 0.0 {
                ((logged[i][a] - mins[a]) / range * 65535.0)
                    .round()
                    .clamp(0.0, 65535.0) as u16
            } else {
                0
            }
        });
        means_l.set(t, [q[0] as u8, q[1] as u8, q[2] as u8, 255]);
        means_u.set(
            t,
            [(q[0] >> 8) as u8, (q[1] >> 8) as u8, (q[2] >> 8) as u8, 255],
        );
    }

    // Quaternions: three components of [-sqrt(1/2), sqrt(1/2)] as bytes, and the tag.
    let mut quats = Texture::new("quats.webp", width, height);
    for (t, &i) in order.iter().enumerate() {
        let (q, largest) = largest_positive(scene.rotations[i]);
        let mut px = [0u8, 0, 0, 252 + largest as u8];
        let mut slot = 0;
        for (k, &v) in q.iter().enumerate() {
            if k != largest {
                let b = (v * std::f32::consts::SQRT_2 * 0.5 + 0.5) * 255.0;
                px[slot] = b.round().clamp(0.0, 255.0) as u8;
                slot += 1;
            }
        }
        quats.set(t, px);
    }

    // Scales and SH DC terms: 256-entry codebooks over all three axes / channels.
    let scale_values: Vec<f32> = scene.log_scales.iter().flatten().copied().collect();
    let dc_values: Vec<f32> = (0..n)
        .flat_map(|i| scene.sh[i * stride..i * stride + 3].iter().copied())
        .collect();
    let (scale_book, dc_book) = rayon::join(
        || quantize::codebook_1d(&scale_values),
        || quantize::codebook_1d(&dc_values),
    );
    let mut scales = Texture::new("scales.webp", width, height);
    let mut sh0 = Texture::new("sh0.webp", width, height);
    for (t, &i) in order.iter().enumerate() {
        let s = scene.log_scales[i];
        let idx = |v: f32| quantize::nearest_index(&scale_book, v);
        scales.set(t, [idx(s[0]), idx(s[1]), idx(s[2]), 255]);
        let dc = &scene.sh[i * stride..i * stride + 3];
        let idx = |v: f32| quantize::nearest_index(&dc_book, v);
        sh0.set(
            t,
            [
                idx(dc[0]),
                idx(dc[1]),
                idx(dc[2]),
                alpha_byte(scene.opacity_logits[i]),
            ],
        );
    }
    let mut textures = vec![means_l, means_u, quats, scales, sh0];

    let mut meta = json!({
        "version": 2,
        "asset": { "generator": format!("verisplat {}", env!("CARGO_PKG_VERSION")) },
        "count": n,
        "means": { "mins": mins, "maxs": maxs, "files": ["means_l.webp", "means_u.webp"] },
        "scales": { "codebook": scale_book, "files": ["scales.webp"] },
        "quats": { "files": ["quats.webp"] },
        "sh0": { "codebook": dc_book, "files": ["sh0.webp"] },
    });
    if scene.antialiased {
        meta["antialias"] = json!(true);
        meta["model"] = json!("antialiased");
    }

    // Higher SH bands: a palette of k-means centroids, their coefficients codebooked.
    if scene.sh_degree > 0 {
        let (palette, label_tex, sh_n) = sh_palette_textures(scene, &order, width, height);
        textures.push(palette);
        textures.push(label_tex);
        meta["shN"] = sh_n;
    }
    let textures = textures
        .par_iter()
        .map(Texture::encode)
        .collect::<Result<Vec<_>, String>>()?;
    let meta = serde_json::to_vec(&meta).map_err(|e| format!("cannot write meta.json: {e}"))?;
    Ok(SogFiles { meta, textures })
}

/// The SH palette (k-means centroids of the bands above DC, their coefficients codebooked),
/// the per-Gaussian labels in `order`, and the `shN` entry of `meta.json`.
fn sh_palette_textures(
    scene: &Scene,
    order: &[usize],
    width: usize,
    height: usize,
) -> (Texture, Texture, serde_json::Value) {
    let n = scene.len();
    let stride = scene.sh_stride();
    let coeffs = scene.sh_coeffs() - 1;
    let dim = 3 * coeffs;
    let rest: Vec<f32> = (0..n)
        .flat_map(|i| scene.sh[i * stride + 3..(i + 1) * stride].iter().copied())
        .collect();
    let k = quantize::palette_size(n);
    let (centroids, labels) = quantize::sh_palette(&rest, dim, k);
    let book = quantize::codebook_1d(&centroids);
    let rows = k.div_ceil(64);
    let mut palette = Texture::new("shN_centroids.webp", 64 * coeffs, rows);
    for e in 0..k {
        for c in 0..coeffs {
            let v = &centroids[e * dim + 3 * c..e * dim + 3 * c + 3];
            let idx = |v: f32| quantize::nearest_index(&book, v);
            let x = (e % 64) * coeffs + c;
            palette.set(
                (e / 64) * 64 * coeffs + x,
                [idx(v[0]), idx(v[1]), idx(v[2]), 255],
            );
        }
    }
    let mut label_tex = Texture::new("shN_labels.webp", width, height);
    for (t, &i) in order.iter().enumerate() {
        let l = labels[i];
        label_tex.set(t, [l as u8, (l >> 8) as u8, 0, 255]);
    }
    let sh_n = json!({
        "count": k,
        "bands": scene.sh_degree,
        "codebook": book,
        "files": ["shN_centroids.webp", "shN_labels.webp"],
    });
    (palette, label_tex, sh_n)
}
