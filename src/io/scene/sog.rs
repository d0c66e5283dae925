//! PlayCanvas SOG v2 ("spatially ordered Gaussians"): a `meta.json` plus lossless WebP
//! textures, either unbundled in a directory or bundled as a zip (`.sog`).
//!
//! Pixel `i` (row-major) of every per-Gaussian texture belongs to Gaussian `i`:
//! * `means_l` / `means_u`: low / high bytes of 16-bit unorms per axis, lerped between
//!   `means.mins` and `means.maxs` and then un-logged: `p = sign(n) * (exp(|n|) - 1)`.
//! * `scales`: RGB indices into the 256-entry `scales.codebook` of log scales.
//! * `quats`: RGB are three components `(b / 255 * 2 - 1) / sqrt(2)`, alpha `252 + i` where
//!   `i` indexes the omitted largest component of `(rot_0..rot_3)`, rebuilt positive.
//! * `sh0`: RGB indices into `sh0.codebook` (SH DC terms), alpha the opacity `a / 255`.
//! * `shN_labels`: a 16-bit palette index `r + 256 g`; `shN_centroids` holds the palette,
//!   64 entries per row, entry `n`'s coefficient `c` at pixel `((n % 64) * coeffs + c, n / 64)`
//!   with RGB indices into `shN.codebook`.
//!
//! Axes: the files written by splat-transform keep the source PLY's axes, so no
//! conversion is applied (the spec's "y up" describes the viewer, not the data).
//!
//! Antialiased training is `"antialias": true` or splat-transform's
//! `"model": "antialiased"`. The writer is [`super::sog_write`].

use super::{logit_from_u8, Scene, SceneError};
use serde::Deserialize;
use std::io::Read;
use std::path::Path;

/// Largest entry read from a zip bundle (a guard against zip bombs; real textures are far
/// smaller: a 4-million-Gaussian SOG has 16 MiB RGBA textures before compression).
const MAX_ENTRY_BYTES: u64 = 1 << 30;

#[derive(Deserialize)]
struct Meta {
    version: Option<u32>,
    count: u64,
    /// The scene was trained with antialiasing.
    #[serde(default)]
    antialias: bool,
    /// splat-transform's record of the splat model: `"antialiased"` also means
    /// antialiased training.
    #[serde(default)]
    model: Option<String>,
    means: Means,
    scales: Codebooked,
    quats: Files,
    sh0: Codebooked,
    #[serde(rename = "shN")]
    sh_n: Option<ShN>,
}

#[derive(Deserialize)]
struct Means {
    mins: [f64; 3],
    maxs: [f64; 3],
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Codebooked {
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Files {
    files: Vec<String>,
}

#[derive(Deserialize)]
struct ShN {
    count: u64,
    bands: u32,
    codebook: Vec<f32>,
    files: Vec<String>,
}

/// Where the SOG's files come from.
pub(crate) enum Source<'a> {
    /// An unbundled directory.
    Directory(&'a Path),
    /// A zip archive held in memory.
    Zip(&'a [u8]),
}

/// Reads the named files of a SOG from a directory or a zip.
struct SogFiles<'a> {
    path: &'a Path,
    dir: Option<&'a Path>,
    zip: Option<zip::ZipArchive<std::io::Cursor<&'a [u8]>>>,
}

impl SogFiles<'_> {
    fn read(&mut self, name: &str) -> Result<Vec<u8>, SceneError> {
        if name.is_empty() || name.contains(['/', '\\']) || name == ".." {
            return Err(SceneError::invalid(
                self.path,
                format!("names the file \"{name}\" in its SOG meta.json; only plain file names beside meta.json are allowed"),
            ));
        }
        if let Some(dir) = self.dir {
            return super::read_file(&dir.join(name));
        }
        let zip = self.zip.as_mut().expect("either a directory or a zip");
        let entry = zip.by_name(name).map_err(|e| {
            SceneError::invalid(
                self.path,
                format!("is a SOG bundle without a readable \"{name}\" entry ({e})"),
            )
        })?;
        let declared = entry.size();
        if declared > MAX_ENTRY_BYTES {
            return Err(SceneError::invalid(
                self.path,
                format!("has a \"{name}\" entry of {declared} bytes, more than the {MAX_ENTRY_BYTES} a SOG texture can need"),
            ));
        }
        let mut out = Vec::new();
        entry
            .take(declared + 1)
            .read_to_end(&mut out)
            .map_err(|e| {
                SceneError::invalid(
                    self.path,
                    format!("has a corrupt or truncated \"{name}\" entry in its zip ({e})"),
                )
            })?;
        Ok(out)
    }
}

/// An RGBA8 texture.
struct Texture {
    width: usize,
    rgba: Vec<u8>,
}

impl Texture {
    fn px(&self, i: usize) -> &[u8] {
        &self.rgba[4 * i..4 * i + 4]
    }
}

/// Parses a SOG from a directory (`meta.json` inside) or a zip bundle.
pub(crate) fn parse(source: Source<'_>, path: &Path) -> Result<Scene, SceneError> {
    let mut files = match source {
        Source::Directory(dir) => SogFiles {
            path,
            dir: Some(dir),
            zip: None,
        },
        Source::Zip(bytes) => SogFiles {
            path,
            dir: None,
            zip: Some(
                zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| {
                    SceneError::invalid(path, format!("is not a readable zip archive ({e})"))
                })?,
            ),
        },
    };
    let meta_bytes = files.read("meta.json")?;
    parse_with(&meta_bytes, &mut files, path)
}

/// Parses a SOG zip bundle (`.sog`) held in memory. `path` is used in error messages only.
pub fn parse_zip(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    parse(Source::Zip(bytes), path)
}

fn parse_with(
    meta_bytes: &[u8],
    files: &mut SogFiles<'_>,
    path: &Path,
) -> Result<Scene, SceneError> {
    let bad = |m: String| SceneError::invalid(path, m);
    let meta = parse_meta(meta_bytes, path)?;
    let n = meta.count;
    let means_l = files.texture(&meta.means.files, 0, "means", n)?;
    let means_u = files.texture(&meta.means.files, 1, "means", n)?;
    let scales = files.texture(&meta.scales.files, 0, "scales", n)?;
    let quats = files.texture(&meta.quats.files, 0, "quats", n)?;
    let sh0 = files.texture(&meta.sh0.files, 0, "sh0", n)?;
    // The textures are at least n pixels, so n fits in memory from here on.
    let n = n as usize;

    let sh_n = match &meta.sh_n {
        None => None,
        Some(s) => Some(ShPalette::load(s, files, meta.count)?),
    };
    let degree = sh_n.as_ref().map_or(0, |p| p.meta.bands);

    let mut scene = Scene::empty(degree);
    scene.antialiased = meta.antialias || meta.model.as_deref() == Some("antialiased");
    scene.positions.reserve_exact(n);
    scene.log_scales.reserve_exact(n);
    scene.rotations.reserve_exact(n);
    scene.opacity_logits.reserve_exact(n);
    scene.sh.reserve_exact(n * scene.sh_stride());
    let (mins, maxs) = (meta.means.mins, meta.means.maxs);
    let unlog = |v: f64| v.signum() * (v.abs().exp() - 1.0);
    for i in 0..n {
        let (lo, hi) = (means_l.px(i), means_u.px(i));
        scene.positions.push(std::array::from_fn(|a| {
            let q = (lo[a] as u32 | (hi[a] as u32) << 8) as f64 / 65535.0;
            unlog(mins[a] + (maxs[a] - mins[a]) * q) as f32
        }));
        let s = scales.px(i);
        scene
            .log_scales
            .push(std::array::from_fn(|a| meta.scales.codebook[s[a] as usize]));
        scene.rotations.push(rotation(quats.px(i), i).map_err(bad)?);
        let c = sh0.px(i);
        scene.opacity_logits.push(logit_from_u8(c[3]));
        scene
            .sh
            .extend(c[..3].iter().map(|&b| meta.sh0.codebook[b as usize]));
        if let Some(palette) = &sh_n {
            palette.extend(&mut scene.sh, i).map_err(bad)?;
        }
    }
    super::check_decoded(&scene, path, "SOG")?;
    Ok(scene)
}

/// Reads `meta.json` and checks what the decoding relies on: version 2, 256 finite
/// entries in each codebook, finite means bounds.
fn parse_meta(meta_bytes: &[u8], path: &Path) -> Result<Meta, SceneError> {
    let bad = |m: String| SceneError::invalid(path, m);
    let meta: Meta = serde_json::from_slice(meta_bytes)
        .map_err(|e| bad(format!("has a SOG meta.json that is not valid: {e}")))?;
    match meta.version {
        Some(2) => {}
        Some(v) => {
            return Err(bad(format!(
                "is SOG version {v}; only version 2 is supported"
            )))
        }
        None => {
            return Err(bad(
                "has a SOG meta.json without \"version\" (a version 1 SOG); only version 2 is supported"
                    .into(),
            ))
        }
    }
    for (what, cb) in [
        ("scales", &meta.scales.codebook),
        ("sh0", &meta.sh0.codebook),
    ] {
        if cb.len() != 256 || cb.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!(
                "has a SOG {what} codebook of {} entries; it must hold 256 finite numbers",
                cb.len()
            )));
        }
    }
    if !meta
        .means
        .mins
        .iter()
        .chain(&meta.means.maxs)
        .all(|v| v.is_finite())
    {
        return Err(bad("has non-finite SOG means bounds".into()));
    }
    Ok(meta)
}

impl SogFiles<'_> {
    /// The texture named by entry `k` of a meta.json file list (`what` names the entry),
    /// decoded from WebP; it must hold at least `n` pixels.
    fn texture(
        &mut self,
        list: &[String],
        k: usize,
        what: &str,
        n: u64,
    ) -> Result<Texture, SceneError> {
        let path = self.path;
        let bad = |m: String| SceneError::invalid(path, m);
        let name = list.get(k).cloned().ok_or_else(|| {
            bad(format!(
                "has a SOG meta.json whose {what} entry lists too few files"
            ))
        })?;
        let bytes = self.read(&name)?;
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::WebP)
            .map_err(|e| {
                bad(format!(
                    "cannot decode its SOG texture \"{name}\" as WebP: {e}"
                ))
            })?
            .to_rgba8();
        let (w, h) = (img.width() as u64, img.height() as u64);
        if w * h < n {
            return Err(bad(format!(
                "has a SOG texture \"{name}\" of {w}x{h} pixels, too small for the {n} Gaussians meta.json declares"
            )));
        }
        Ok(Texture {
            width: w as usize,
            rgba: img.into_raw(),
        })
    }
}

/// The rotation of Gaussian `i` from its pixel of the quats texture: three components and
/// the tag of the omitted largest one, rebuilt positive. `Err`: the tag is invalid.
fn rotation(q: &[u8], i: usize) -> Result<[f32; 4], String> {
    let largest = match q[3] {
        252..=255 => (q[3] - 252) as usize,
        tag => {
            return Err(format!(
                "has an invalid quaternion tag {tag} for Gaussian {i} in its SOG quats texture; 252 to 255 are valid"
            ))
        }
    };
    let mut rot = [0f32; 4];
    let mut kept = q[..3]
        .iter()
        .map(|&b| (b as f32 / 255.0 * 2.0 - 1.0) / std::f32::consts::SQRT_2);
    for (k, r) in rot.iter_mut().enumerate() {
        if k != largest {
            *r = kept.next().unwrap_or(0.0);
        }
    }
    rot[largest] = (1.0 - rot.iter().map(|v| v * v).sum::<f32>())
        .max(0.0)
        .sqrt();
    Ok(rot)
}

/// The SH palette of the `shN` entry: its meta.json entry, the centroids (the palette)
/// and labels (each Gaussian's entry) textures, and the coefficients per entry.
struct ShPalette<'m> {
    meta: &'m ShN,
    centroids: Texture,
    labels: Texture,
    coeffs: usize,
}

impl<'m> ShPalette<'m> {
    /// Checks the `shN` entry and loads its textures (the labels of `n` Gaussians).
    fn load(s: &'m ShN, files: &mut SogFiles<'_>, n: u64) -> Result<ShPalette<'m>, SceneError> {
        let path = files.path;
        let bad = |m: String| SceneError::invalid(path, m);
        if !(1..=3).contains(&s.bands) {
            return Err(bad(format!(
                "has {} SH bands in its SOG shN entry; 1 to 3 are valid",
                s.bands
            )));
        }
        if s.codebook.len() != 256 || s.codebook.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!(
                "has a SOG shN codebook of {} entries; it must hold 256 finite numbers",
                s.codebook.len()
            )));
        }
        if !(1..=65536).contains(&s.count) {
            return Err(bad(format!(
                "has a SOG SH palette of {} entries; 1 to 65536 are valid",
                s.count
            )));
        }
        let centroids = files.texture(&s.files, 0, "shN", n)?;
        let labels = files.texture(&s.files, 1, "shN", n)?;
        let coeffs = super::sh_coeffs_for_degree(s.bands) - 1;
        let rows = (s.count as usize).div_ceil(64);
        if centroids.width < 64 * coeffs || centroids.rgba.len() / 4 / centroids.width < rows {
            return Err(bad(format!(
                "has a SOG shN_centroids texture too small for {} palette entries of {coeffs} coefficients",
                s.count
            )));
        }
        Ok(ShPalette {
            meta: s,
            centroids,
            labels,
            coeffs,
        })
    }

    /// Appends the higher SH coefficients of Gaussian `i` (its palette entry's) to `sh`.
    /// `Err`: its label is beyond the palette.
    fn extend(&self, sh: &mut Vec<f32>, i: usize) -> Result<(), String> {
        let (s, centroids, coeffs) = (self.meta, &self.centroids, &self.coeffs);
        let l = self.labels.px(i);
        let label = l[0] as usize | (l[1] as usize) << 8;
        if label as u64 >= s.count {
            return Err(format!(
                "has SH palette label {label} for Gaussian {i}, beyond its {} palette entries",
                s.count
            ));
        }
        for k in 0..*coeffs {
            let x = (label % 64) * coeffs + k;
            let y = label / 64;
            let p = centroids.px(y * centroids.width + x);
            sh.extend(p[..3].iter().map(|&b| s.codebook[b as usize]));
        }
        Ok(())
    }
}
