//! Writes a scene as glTF 2.0 with `KHR_gaussian_splatting` ([`super::gltf`] reads it):
//! one node, one mesh, one `POINTS` primitive, every value as 32-bit floats (lossless up to
//! the activations), in glTF's frame (a half turn about `z` from ours).
//!
//! Attributes: `POSITION` (with its bounds, which glTF requires), `COLOR_0` (the fallback
//! colour for viewers without the extension: the DC colour clamped to [0, 1] and decoded
//! from sRGB to linear, as glTF's `COLOR_0` is linear, and the opacity; 8-bit), and the
//! extension's `ROTATION` (unit quaternions, `x y z w`), `SCALE` (`exp` of ours),
//! `OPACITY` (the sigmoid of ours) and `SH_DEGREE_l_COEF_n` for every band the scene has.
//! The flags only verisplat reads (antialiased training, the kernel, the rules) go in the
//! primitive's `extras.verisplat`.

use super::gltf::{EXTENSION, GLB_MAGIC, PREFIX};
use super::transform::SceneTransform;
use super::Scene;
use serde_json::{json, Value};

/// `ARRAY_BUFFER`: the bufferView target of vertex attributes.
const ARRAY_BUFFER: u32 = 34962;
const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;

/// One attribute's data and accessor description.
struct Attribute {
    name: String,
    kind: &'static str,
    component: u32,
    normalized: bool,
    data: Vec<u8>,
    bounds: Option<([f32; 3], [f32; 3])>,
}

/// The JSON document and the binary buffer of a scene; `uri` names the buffer's file for a
/// `.gltf` (`None` for a `.glb`, whose buffer is its BIN chunk).
fn document(scene: &Scene, uri: Option<&str>) -> Result<(Value, Vec<u8>), String> {
    let (scene, attrs) = attributes(scene)?;
    assemble(&scene, &attrs, uri)
}

/// The scene in glTF's frame and its attributes.
fn attributes(scene: &Scene) -> Result<(Scene, Vec<Attribute>), String> {
    if scene.is_empty() {
        return Err(
            "the scene has no Gaussians; glTF accessors must hold at least one element".into(),
        );
    }
    let to_gltf = SceneTransform::rotation([0.0, 0.0, 1.0], 180.0).expect("a half turn");
    let scene = to_gltf.apply(scene.clone())?;
    let n = scene.len();
    let stride = scene.sh_stride();
    let floats =
        |v: &mut dyn Iterator<Item = f32>| -> Vec<u8> { v.flat_map(f32::to_le_bytes).collect() };
    let mut attrs = Vec::new();
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &scene.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    attrs.push(Attribute {
        name: "POSITION".into(),
        kind: "VEC3",
        component: FLOAT,
        normalized: false,
        data: floats(&mut scene.positions.iter().flatten().copied()),
        bounds: Some((lo, hi)),
    });
    let mut color = Vec::with_capacity(4 * n);
    for i in 0..n {
        for c in 0..3 {
            let srgb = super::color_from_dc(scene.sh[i * stride + c]).clamp(0.0, 1.0);
            color.push((srgb_to_linear(srgb) * 255.0).round() as u8);
        }
        color.push((super::sigmoid(scene.opacity_logits[i]) * 255.0).round() as u8);
    }
    attrs.push(Attribute {
        name: "COLOR_0".into(),
        kind: "VEC4",
        component: UNSIGNED_BYTE,
        normalized: true,
        data: color,
        bounds: None,
    });
    let mut rotation = Vec::with_capacity(4 * n);
    for (i, q) in scene.rotations.iter().enumerate() {
        let len = q
            .iter()
            .map(|v| (*v as f64) * (*v as f64))
            .sum::<f64>()
            .sqrt();
        if !(len > 0.0 && len.is_finite()) {
            return Err(format!(
                "Gaussian {i} has a zero or non-finite rotation quaternion"
            ));
        }
        // glTF order x y z w, unit length (the extension's renderers do not renormalise).
        for v in [q[1], q[2], q[3], q[0]] {
            rotation.push((v as f64 / len) as f32);
        }
    }
    attrs.push(float_attribute("ROTATION", "VEC4", rotation));
    let scales: Vec<f32> = scene.log_scales.iter().flatten().map(|s| s.exp()).collect();
    if let Some(i) = scales.iter().position(|s| !s.is_finite()) {
        return Err(format!(
            "Gaussian {} has a scale too large for 32-bit floats",
            i / 3
        ));
    }
    attrs.push(float_attribute("SCALE", "VEC3", scales));
    let opacity: Vec<f32> = scene
        .opacity_logits
        .iter()
        .map(|&o| super::sigmoid(o))
        .collect();
    attrs.push(float_attribute("OPACITY", "SCALAR", opacity));
    for l in 0..=scene.sh_degree as usize {
        for c in 0..2 * l + 1 {
            let k = l * l + c;
            let v = (0..n)
                .flat_map(|i| scene.sh[i * stride + 3 * k..i * stride + 3 * k + 3].to_vec())
                .collect();
            attrs.push(float_attribute(
                &format!("SH_DEGREE_{l}_COEF_{c}"),
                "VEC3",
                v,
            ));
        }
    }
    Ok((scene, attrs))
}

/// The document and buffer holding `attrs` (one view and accessor each).
fn assemble(
    scene: &Scene,
    attrs: &[Attribute],
    uri: Option<&str>,
) -> Result<(Value, Vec<u8>), String> {
    let n = scene.len();
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut attributes = serde_json::Map::new();
    for (i, a) in attrs.iter().enumerate() {
        let offset = bin.len();
        bin.extend(&a.data);
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": a.data.len(),
            "target": ARRAY_BUFFER,
        }));
        let mut acc = json!({
            "bufferView": i,
            "componentType": a.component,
            "count": n,
            "type": a.kind,
        });
        if a.normalized {
            acc["normalized"] = json!(true);
        }
        if let Some((lo, hi)) = a.bounds {
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        accessors.push(acc);
        attributes.insert(a.name.clone(), json!(i));
    }
    if bin.len() > u32::MAX as usize - 64 {
        return Err(format!(
            "the scene needs {} bytes of glTF buffer, more than the 4 GiB a GLB chunk can hold",
            bin.len()
        ));
    }
    let mut buffer = json!({ "byteLength": bin.len() });
    if let Some(uri) = uri {
        buffer["uri"] = json!(uri);
    }
    let mut primitive = json!({
        "attributes": attributes,
        "mode": 0,
        "extensions": {
            EXTENSION: {
                "kernel": "ellipse",
                "colorSpace": "srgb_rec709_display",
                "projection": "perspective",
                "sortingMethod": "cameraDistance",
            }
        },
    });
    let mut extras = serde_json::Map::new();
    if scene.antialiased {
        extras.insert("antialiased".into(), json!(true));
    }
    if scene.kernel != crate::core::model::SplatKernel::Gaussian {
        extras.insert("kernel".into(), json!(scene.kernel.name()));
    }
    if scene.rules != crate::core::model::Rules::Original {
        extras.insert("rules".into(), json!(scene.rules.name()));
    }
    if scene.mip_filter {
        extras.insert("mip_filter".into(), json!("3d"));
    }
    if !extras.is_empty() {
        primitive["extras"] = json!({ "verisplat": extras });
    }
    let doc = json!({
        "asset": {
            "version": "2.0",
            "generator": format!("verisplat {}", env!("CARGO_PKG_VERSION")),
        },
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [primitive] }],
        "buffers": [buffer],
        "bufferViews": views,
        "accessors": accessors,
    });
    Ok((doc, bin))
}

fn float_attribute(name: &str, kind: &'static str, values: Vec<f32>) -> Attribute {
    Attribute {
        name: format!("{PREFIX}{name}"),
        kind,
        component: FLOAT,
        normalized: false,
        data: values.into_iter().flat_map(f32::to_le_bytes).collect(),
        bounds: None,
    }
}

/// The sRGB transfer function's inverse (IEC 61966-2-1).
fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// A `.glb`: the 12-byte header, the JSON chunk (space-padded) and the BIN chunk.
pub fn to_glb(scene: &Scene) -> Result<Vec<u8>, String> {
    let (doc, bin) = document(scene, None)?;
    let mut json = serde_json::to_vec(&doc).map_err(|e| e.to_string())?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total32 = u32::try_from(total)
        .map_err(|_| format!("the GLB would be {total} bytes, over glTF's 4 GiB"))?;
    let mut out = Vec::with_capacity(total);
    out.extend(GLB_MAGIC.to_le_bytes());
    out.extend(2u32.to_le_bytes());
    out.extend(total32.to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes());
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(0x004E_4942u32.to_le_bytes());
    out.extend(bin);
    Ok(out)
}

/// A `.gltf` document naming its buffer `bin_name` (a file beside it), and that buffer.
pub fn to_gltf(scene: &Scene, bin_name: &str) -> Result<(Vec<u8>, Vec<u8>), String> {
    let (doc, bin) = document(scene, Some(&percent_encode(bin_name)))?;
    let json = serde_json::to_vec_pretty(&doc).map_err(|e| e.to_string())?;
    Ok((json, bin))
}

/// A file name as a relative URI: bytes other than RFC 3986's unreserved ones `%XX`-escaped.
fn percent_encode(name: &str) -> String {
    name.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

/// A `.gltf` whose buffer is embedded as a base64 `data:` URI: one self-contained file
/// (a third larger than the buffer), for writers that produce one file's bytes.
pub fn to_gltf_embedded(scene: &Scene) -> Result<Vec<u8>, String> {
    let (mut doc, bin) = document(scene, None)?;
    doc["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        data_encoding::BASE64.encode(&bin)
    ));
    serde_json::to_vec_pretty(&doc).map_err(|e| e.to_string())
}

/// The buffer file a `.gltf` at `path` is written with: its stem plus `.bin`, beside it.
pub fn bin_path(path: &std::path::Path) -> std::path::PathBuf {
    path.with_extension("bin")
}

/// Writes `path` (`.gltf`) and its buffer [`bin_path`] beside it, each to a temporary
/// file renamed into place, the buffer first, so the `.gltf` never names a missing or
/// half-written buffer. With `overwrite == false` either file existing is an error and
/// nothing is written. Returns the bytes written.
pub fn write_gltf_files(
    scene: &Scene,
    path: &std::path::Path,
    overwrite: bool,
) -> Result<usize, GltfWriteError> {
    let bin_file = bin_path(path);
    let bin_name = bin_file
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene.bin".into());
    let (json, bin) = to_gltf(scene, &bin_name).map_err(GltfWriteError::Encode)?;
    if !overwrite {
        if let Some(existing) = [path, bin_file.as_path()].into_iter().find(|p| p.exists()) {
            return Err(GltfWriteError::Write(
                crate::core::fsutil::WriteError::Exists(existing.to_path_buf()),
            ));
        }
    }
    crate::core::fsutil::write_bytes_atomically(&bin_file, overwrite, &bin)
        .map_err(GltfWriteError::Write)?;
    crate::core::fsutil::write_bytes_atomically(path, overwrite, &json)
        .map_err(GltfWriteError::Write)?;
    Ok(json.len() + bin.len())
}

/// Why [`write_gltf_files`] failed.
#[derive(Debug)]
pub enum GltfWriteError {
    /// The scene cannot be written as glTF.
    Encode(String),
    /// A file could not be written.
    Write(crate::core::fsutil::WriteError),
}
