//! glTF 2.0 Gaussian splats (Khronos `KHR_gaussian_splatting`), read from `.glb` or from
//! `.gltf` with its buffers (files beside it or `data:` URIs).
//!
//! A splat primitive is a `POINTS` primitive with the extension; its attributes are
//! `POSITION`, `KHR_gaussian_splatting:ROTATION` (unit quaternion, glTF's `x y z w`
//! order), `:SCALE` (linear), `:OPACITY` (after the sigmoid) and
//! `:SH_DEGREE_l_COEF_n` (the real SH coefficients in the order and with the signs of the
//! original 3DGS, so `l * l + n` is our coefficient index). Every component type the
//! extension and `KHR_mesh_quantization` allow is read (floats, normalised and plain
//! integers). A primitive whose extension carries `KHR_gaussian_splatting_compression_spz_2`
//! is decoded from its SPZ payload instead.
//!
//! Placement: every node instancing a mesh with splat primitives contributes the
//! primitive's Gaussians moved by the node's global transform (its TRS or matrix times its
//! parents'); all primitives of the default scene (or of every root node when there is no
//! scene) are merged into one scene, padded to the highest SH degree with zero
//! coefficients. A uniform scale, rotation and translation are applied exactly
//! ([`super::transform::SceneTransform`], SH rotated); a non-uniform scale scales each
//! covariance (re-diagonalised) and leaves the SH alone, as the extension describes.
//!
//! Axes: glTF's frame is left-up-front (`+Y` up, `+Z` the asset's front); our PLY frame
//! (COLMAP's, right-down-front) is a half turn about `z` from it, `(x, y, z)_ply =
//! (-x, -y, z)_gltf`, as PlayCanvas's splat-transform writes it. The SPZ payload of the
//! compressed variant is in SPZ's own frame (RUB), which [`super::spz::parse`] maps to
//! ours; it is moved into glTF's frame for its node's transform and back.

use super::transform::SceneTransform;
use super::{spz, Scene, SceneError};
use glam::{DMat3, DMat4, DQuat, DVec3};
use serde_json::Value;
use std::path::Path;

/// The GLB header's magic, `glTF` little-endian.
pub const GLB_MAGIC: u32 = 0x4654_6C67;
/// The GLB header's size: magic, version, total length.
const GLB_HEADER: usize = 12;
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
/// The extension's name.
pub const EXTENSION: &str = "KHR_gaussian_splatting";
/// Attribute semantics' prefix.
pub const PREFIX: &str = "KHR_gaussian_splatting:";
/// The SPZ compression extensions read (the ratified name and the draft's).
const SPZ_EXTENSIONS: [&str; 2] = [
    "KHR_gaussian_splatting_compression_spz_2",
    "KHR_gaussian_splatting_compression_spz",
];
/// Extensions a file may require that this reader handles.
const SUPPORTED_REQUIRED: [&str; 4] = [
    EXTENSION,
    "KHR_mesh_quantization",
    SPZ_EXTENSIONS[0],
    SPZ_EXTENSIONS[1],
];
/// Deepest node hierarchy followed (a guard against cycles in malformed files).
const MAX_DEPTH: usize = 64;

/// What a glTF file held, beside its scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GltfInfo {
    /// A `.glb` (true) or a JSON `.gltf` (false).
    pub binary: bool,
    /// Splat primitive instances merged into the scene (a primitive instanced by two nodes
    /// counts twice).
    pub primitives: usize,
    /// Instances whose Gaussians came from an SPZ payload.
    pub spz_compressed: usize,
}

/// True when `bytes` start as a GLB file.
pub fn is_glb(bytes: &[u8]) -> bool {
    bytes.len() >= 4 && u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) == GLB_MAGIC
}

/// True when `json` is a glTF document (an object with an `asset` object holding a
/// `version`), as opposed to another JSON file such as a SOG `meta.json`.
pub fn is_gltf_json(json: &[u8]) -> bool {
    serde_json::from_slice::<Value>(json)
        .ok()
        .and_then(|v| v.get("asset").and_then(|a| a.get("version")).cloned())
        .is_some()
}

/// Parses a `.glb` or `.gltf`. `dir` is where a `.gltf`'s external buffers lie (`None`:
/// only embedded `data:` buffers can be read).
pub fn parse(
    bytes: &[u8],
    path: &Path,
    dir: Option<&Path>,
) -> Result<(Scene, GltfInfo), SceneError> {
    let binary = is_glb(bytes);
    let (json, bin) = if binary {
        split_glb(bytes, path)?
    } else {
        (bytes, None)
    };
    let doc: Value = serde_json::from_slice(json)
        .map_err(|e| SceneError::invalid(path, format!("has invalid glTF JSON: {e}")))?;
    let file = Document::new(&doc, bin, path, dir)?;
    let (scene, primitives, spz_compressed) = file.load()?;
    Ok((
        scene,
        GltfInfo {
            binary,
            primitives,
            spz_compressed,
        },
    ))
}

/// The JSON and BIN chunks of a GLB.
fn split_glb<'a>(bytes: &'a [u8], path: &Path) -> Result<(&'a [u8], Option<&'a [u8]>), SceneError> {
    let u32_at = |o: usize| -> Option<u32> {
        bytes
            .get(o..o + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let bad = |m: String| SceneError::invalid(path, m);
    // The 12-byte header and at least one chunk's 8-byte header (the JSON chunk, first).
    if bytes.len() < GLB_HEADER + 8 {
        return Err(bad(format!(
            "is a truncated GLB: {} bytes, shorter than the 12-byte header and the JSON chunk that must follow it",
            bytes.len()
        )));
    }
    let version = u32_at(4).unwrap_or(0);
    if version != 2 {
        return Err(bad(format!(
            "is a GLB of version {version}; only glTF 2.0 is read"
        )));
    }
    let length = u32_at(8).unwrap_or(0) as usize;
    if length > bytes.len() {
        return Err(bad(format!(
            "is a truncated GLB: its header says {length} bytes, the file has {}",
            bytes.len()
        )));
    }
    let mut offset = GLB_HEADER;
    let mut json = None;
    let mut bin = None;
    while offset + 8 <= length {
        let chunk_len = u32_at(offset).unwrap_or(0) as usize;
        let kind = u32_at(offset + 4).unwrap_or(0);
        let start = offset + 8;
        let end = start
            .checked_add(chunk_len)
            .filter(|&e| e <= length)
            .ok_or_else(|| {
                bad(format!(
                    "has a GLB chunk at byte {offset} running past the end"
                ))
            })?;
        match kind {
            CHUNK_JSON if json.is_none() => json = Some(&bytes[start..end]),
            CHUNK_BIN if bin.is_none() => bin = Some(&bytes[start..end]),
            _ => {}
        }
        offset = end;
    }
    let json = json.ok_or_else(|| bad("is a GLB without a JSON chunk".into()))?;
    Ok((json, bin))
}

/// A parsed glTF document with its buffers loaded.
struct Document<'a> {
    doc: &'a Value,
    buffers: Vec<Vec<u8>>,
    path: &'a Path,
}

/// The Gaussians of one primitive in glTF's frame, or how to read them.
struct Instance {
    scene: Scene,
    spz: bool,
}

impl<'a> Document<'a> {
    fn new(
        doc: &'a Value,
        bin: Option<&[u8]>,
        path: &'a Path,
        dir: Option<&Path>,
    ) -> Result<Self, SceneError> {
        let bad = |m: String| SceneError::invalid(path, m);
        let version = doc
            .get("asset")
            .and_then(|a| a.get("version"))
            .and_then(Value::as_str)
            .ok_or_else(|| bad("is not a glTF file: it has no asset.version".into()))?;
        if !version.starts_with("2.") {
            return Err(bad(format!("is glTF {version}; only glTF 2.x is read")));
        }
        for ext in array(doc, "extensionsRequired") {
            let name = ext.as_str().unwrap_or("?");
            if !SUPPORTED_REQUIRED.contains(&name) {
                return Err(bad(format!(
                    "requires the glTF extension {name}, which verisplat does not read (it reads {})",
                    SUPPORTED_REQUIRED.join(", ")
                )));
            }
        }
        let mut buffers = Vec::new();
        for (i, b) in array(doc, "buffers").iter().enumerate() {
            let length = b.get("byteLength").and_then(Value::as_u64).unwrap_or(0) as usize;
            let data = match b.get("uri").and_then(Value::as_str) {
                None => match (i, bin) {
                    (0, Some(bin)) => bin.to_vec(),
                    _ => {
                        return Err(bad(format!(
                            "buffer {i} has no uri and there is no GLB binary chunk for it"
                        )))
                    }
                },
                Some(uri) if uri.starts_with("data:") => decode_data_uri(uri)
                    .ok_or_else(|| bad(format!("buffer {i} has a data: URI that is not base64")))?,
                Some(uri) => {
                    let dir = dir.ok_or_else(|| {
                        bad(format!("buffer {i} is the external file {uri}; load the .gltf from its file so it can be found"))
                    })?;
                    let file = dir.join(percent_decode(uri));
                    // The document names the file, so the error names both.
                    std::fs::read(&file).map_err(|e| {
                        bad(format!(
                            "buffer {i} is the file {}, which cannot be read: {e}",
                            file.display()
                        ))
                    })?
                }
            };
            if data.len() < length {
                return Err(bad(format!(
                    "buffer {i} holds {} bytes, less than its byteLength {length}",
                    data.len()
                )));
            }
            buffers.push(data);
        }
        Ok(Document { doc, buffers, path })
    }

    fn bad(&self, m: String) -> SceneError {
        SceneError::invalid(self.path, m)
    }

    /// Every splat primitive instance of the default scene, merged.
    fn load(&self) -> Result<(Scene, usize, usize), SceneError> {
        let meshes = array(self.doc, "meshes");
        let nodes = array(self.doc, "nodes");
        let mut placed: Vec<(usize, DMat4)> = Vec::new();
        let roots: Vec<usize> = match self.default_scene() {
            Some(scene) => array(scene, "nodes").iter().filter_map(index).collect(),
            None => {
                let mut child = vec![false; nodes.len()];
                for n in nodes {
                    for c in array(n, "children").iter().filter_map(index) {
                        if c < child.len() {
                            child[c] = true;
                        }
                    }
                }
                (0..nodes.len()).filter(|&i| !child[i]).collect()
            }
        };
        if nodes.is_empty() {
            placed.extend((0..meshes.len()).map(|m| (m, DMat4::IDENTITY)));
        }
        for root in roots {
            self.walk(root, DMat4::IDENTITY, 0, &mut placed)?;
        }
        let mut cache: Vec<Option<Vec<Option<Instance>>>> =
            (0..meshes.len()).map(|_| None).collect();
        let mut parts = Vec::new();
        let mut spz_count = 0;
        for (mesh, matrix) in placed {
            let Some(m) = meshes.get(mesh) else {
                return Err(self.bad(format!("a node names mesh {mesh}, which does not exist")));
            };
            if cache[mesh].is_none() {
                let prims = array(m, "primitives")
                    .iter()
                    .enumerate()
                    .map(|(p, prim)| self.primitive(mesh, p, prim))
                    .collect::<Result<Vec<_>, _>>()?;
                cache[mesh] = Some(prims);
            }
            for inst in cache[mesh].as_ref().into_iter().flatten().flatten() {
                spz_count += inst.spz as usize;
                parts.push(place(inst.scene.clone(), matrix).map_err(|m| self.bad(m))?);
            }
        }
        if parts.is_empty() {
            return Err(self.bad(format!(
                "holds no Gaussian splats: no mesh primitive of its scene has the {EXTENSION} extension"
            )));
        }
        let count = parts.len();
        let merged = merge(parts);
        let to_ply = SceneTransform::rotation([0.0, 0.0, 1.0], 180.0).expect("a half turn");
        let scene = to_ply.apply(merged).map_err(|m| self.bad(m))?;
        super::check_decoded(&scene, self.path, "glTF")?;
        Ok((scene, count, spz_count))
    }

    fn default_scene(&self) -> Option<&Value> {
        let scenes = array(self.doc, "scenes");
        let i = self.doc.get("scene").and_then(index).unwrap_or(0);
        scenes.get(i)
    }

    fn walk(
        &self,
        node: usize,
        parent: DMat4,
        depth: usize,
        out: &mut Vec<(usize, DMat4)>,
    ) -> Result<(), SceneError> {
        if depth > MAX_DEPTH {
            return Err(self.bad(format!(
                "has a node hierarchy deeper than {MAX_DEPTH} (a cycle through node {node}?)"
            )));
        }
        let n = array(self.doc, "nodes")
            .get(node)
            .ok_or_else(|| self.bad(format!("names node {node}, which does not exist")))?;
        let global = parent * local_matrix(n).map_err(|m| self.bad(format!("node {node}: {m}")))?;
        if let Some(mesh) = n.get("mesh").and_then(index) {
            out.push((mesh, global));
        }
        for c in array(n, "children").iter().filter_map(index) {
            self.walk(c, global, depth + 1, out)?;
        }
        Ok(())
    }

    /// The Gaussians of a splat primitive in glTF's frame (`None` for other primitives).
    fn primitive(
        &self,
        mesh: usize,
        p: usize,
        prim: &Value,
    ) -> Result<Option<Instance>, SceneError> {
        let Some(ext) = prim.get("extensions").and_then(|e| e.get(EXTENSION)) else {
            return Ok(None);
        };
        let here = format!("mesh {mesh} primitive {p}");
        let mode = prim.get("mode").and_then(Value::as_u64).unwrap_or(4);
        if mode != 0 {
            return Err(self.bad(format!(
                "{here} has the {EXTENSION} extension but mode {mode}; splats are POINTS (0)"
            )));
        }
        if let Some(kernel) = ext.get("kernel").and_then(Value::as_str) {
            if kernel != "ellipse" {
                return Err(self.bad(format!("{here} uses the kernel {kernel:?}; verisplat renders the \"ellipse\" kernel only")));
            }
        }
        if let Some(space) = ext.get("colorSpace").and_then(Value::as_str) {
            if space != "srgb_rec709_display" {
                return Err(self.bad(format!(
                    "{here} has colorSpace {space:?}; verisplat renders display-referred sRGB splats (\"srgb_rec709_display\") only"
                )));
            }
        }
        let inner = ext.get("extensions");
        if let Some(spz_ext) = SPZ_EXTENSIONS
            .iter()
            .find_map(|n| inner.and_then(|e| e.get(*n)))
        {
            let view = spz_ext
                .get("bufferView")
                .and_then(index)
                .ok_or_else(|| self.bad(format!("{here}: its SPZ extension has no bufferView")))?;
            let bytes = self.buffer_view(view)?.0;
            let (mut scene, _, _) = spz::parse(bytes, self.path)?;
            self.read_extras(prim, &here, &mut scene)?;
            // The payload decodes to our frame; bring it to glTF's for the node transform.
            let to_gltf = SceneTransform::rotation([0.0, 0.0, 1.0], 180.0).expect("a half turn");
            let scene = to_gltf
                .apply(scene)
                .map_err(|m| self.bad(format!("{here}: {m}")))?;
            return Ok(Some(Instance { scene, spz: true }));
        }
        let attrs = prim
            .get("attributes")
            .ok_or_else(|| self.bad(format!("{here} has no attributes")))?;
        let read = |name: &str, comps: usize| -> Result<Option<Vec<f32>>, SceneError> {
            match attrs.get(name).and_then(index) {
                None => Ok(None),
                Some(a) => self
                    .accessor(a, comps, &format!("{here} attribute {name}"))
                    .map(Some),
            }
        };
        let need = |name: &str, comps: usize| -> Result<Vec<f32>, SceneError> {
            read(name, comps)?.ok_or_else(|| {
                self.bad(format!(
                    "{here} has no {name} attribute, which {EXTENSION} requires"
                ))
            })
        };
        let positions = need("POSITION", 3)?;
        let n = positions.len() / 3;
        let rotations = need(&format!("{PREFIX}ROTATION"), 4)?;
        let scales = need(&format!("{PREFIX}SCALE"), 3)?;
        let opacities = need(&format!("{PREFIX}OPACITY"), 1)?;
        let dc = need(&format!("{PREFIX}SH_DEGREE_0_COEF_0"), 3)?;
        let mut degree = 0;
        let mut rest: Vec<Vec<f32>> = Vec::new();
        for l in 1..=3u32 {
            let coefs = (0..2 * l + 1)
                .map(|c| read(&format!("{PREFIX}SH_DEGREE_{l}_COEF_{c}"), 3))
                .collect::<Result<Vec<_>, _>>()?;
            let present = coefs.iter().filter(|c| c.is_some()).count();
            if present == 0 {
                break;
            }
            if present != coefs.len() {
                return Err(self.bad(format!(
                    "{here} defines {present} of the {} SH degree-{l} coefficients; a degree must be complete",
                    coefs.len()
                )));
            }
            degree = l;
            rest.extend(coefs.into_iter().flatten());
        }
        for (what, len) in [
            ("ROTATION", rotations.len() / 4),
            ("SCALE", scales.len() / 3),
            ("OPACITY", opacities.len()),
            ("SH_DEGREE_0_COEF_0", dc.len() / 3),
        ]
        .into_iter()
        .chain(rest.iter().map(|r| ("SH", r.len() / 3)))
        {
            if len != n {
                return Err(self.bad(format!("{here}: {what} has {len} values, POSITION has {n}")));
            }
        }
        let mut scene = Scene::empty(degree);
        let stride = scene.sh_stride();
        scene.sh = vec![0.0; n * stride];
        for i in 0..n {
            scene
                .positions
                .push([positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]]);
            let s = &scales[3 * i..3 * i + 3];
            if s.iter().any(|v| *v < 0.0) {
                return Err(self.bad(format!("{here}: Gaussian {i} has a negative scale ({s:?})")));
            }
            scene
                .log_scales
                .push([log_scale(s[0]), log_scale(s[1]), log_scale(s[2])]);
            let q = &rotations[4 * i..4 * i + 4];
            scene.rotations.push([q[3], q[0], q[1], q[2]]);
            let o = opacities[i];
            if !(0.0..=1.0).contains(&o) {
                return Err(self.bad(format!(
                    "{here}: Gaussian {i} has opacity {o}, outside [0, 1]"
                )));
            }
            scene.opacity_logits.push(logit(o));
            let sh = &mut scene.sh[i * stride..(i + 1) * stride];
            sh[..3].copy_from_slice(&dc[3 * i..3 * i + 3]);
            for (k, coef) in rest.iter().enumerate() {
                sh[3 * (k + 1)..3 * (k + 2)].copy_from_slice(&coef[3 * i..3 * i + 3]);
            }
        }
        self.read_extras(prim, &here, &mut scene)?;
        Ok(Some(Instance { scene, spz: false }))
    }

    /// The flags verisplat records in `extras.verisplat` (antialiased training, kernel,
    /// rules, the folded 3D filter; [`super::gltf_write`]).
    fn read_extras(&self, prim: &Value, here: &str, scene: &mut Scene) -> Result<(), SceneError> {
        let Some(ours) = prim.get("extras").and_then(|e| e.get("verisplat")) else {
            return Ok(());
        };
        scene.antialiased = ours
            .get("antialiased")
            .and_then(Value::as_bool)
            .unwrap_or(false);
        if let Some(k) = ours.get("kernel").and_then(Value::as_str) {
            scene.kernel = k
                .parse()
                .map_err(|e: String| self.bad(format!("{here}: extras.verisplat.kernel: {e}")))?;
        }
        if let Some(r) = ours.get("rules").and_then(Value::as_str) {
            scene.rules = r
                .parse()
                .map_err(|e: String| self.bad(format!("{here}: extras.verisplat.rules: {e}")))?;
        }
        match ours.get("mip_filter") {
            None => {}
            Some(Value::String(s)) if s == "3d" => scene.mip_filter = true,
            Some(other) => {
                return Err(self.bad(format!(
                    "{here}: extras.verisplat.mip_filter is {other}; the only one verisplat writes is \"3d\""
                )))
            }
        }
        Ok(())
    }

    /// A buffer view's bytes and its stride (0 when tightly packed).
    fn buffer_view(&self, view: usize) -> Result<(&[u8], usize), SceneError> {
        let v = array(self.doc, "bufferViews")
            .get(view)
            .ok_or_else(|| self.bad(format!("names bufferView {view}, which does not exist")))?;
        if v.get("extensions")
            .and_then(|e| e.get("EXT_meshopt_compression"))
            .is_some()
        {
            return Err(self.bad(format!(
                "bufferView {view} is meshopt-compressed (EXT_meshopt_compression), which verisplat does not read; decompress it first (gltfpack -noq)"
            )));
        }
        let buffer = v.get("buffer").and_then(index).unwrap_or(usize::MAX);
        let data = self.buffers.get(buffer).ok_or_else(|| {
            self.bad(format!(
                "bufferView {view} names buffer {buffer}, which does not exist"
            ))
        })?;
        let offset = v.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
        let length = v.get("byteLength").and_then(Value::as_u64).unwrap_or(0) as usize;
        let bytes = offset
            .checked_add(length)
            .and_then(|end| data.get(offset..end))
            .ok_or_else(|| {
                self.bad(format!(
                    "bufferView {view} runs past the end of buffer {buffer}"
                ))
            })?;
        let stride = v.get("byteStride").and_then(Value::as_u64).unwrap_or(0) as usize;
        Ok((bytes, stride))
    }

    /// An accessor's values as f32 (`comps` per element), normalised integers mapped as
    /// glTF defines.
    fn accessor(&self, a: usize, comps: usize, what: &str) -> Result<Vec<f32>, SceneError> {
        let acc = array(self.doc, "accessors")
            .get(a)
            .ok_or_else(|| self.bad(format!("{what} names accessor {a}, which does not exist")))?;
        let kind = acc.get("type").and_then(Value::as_str).unwrap_or("?");
        let want = match comps {
            1 => "SCALAR",
            3 => "VEC3",
            _ => "VEC4",
        };
        if kind != want {
            return Err(self.bad(format!("{what} is a {kind} accessor; it must be {want}")));
        }
        if acc.get("sparse").is_some() {
            return Err(self.bad(format!(
                "{what} is a sparse accessor, which verisplat does not read"
            )));
        }
        let count = acc.get("count").and_then(Value::as_u64).unwrap_or(0) as usize;
        let component = acc
            .get("componentType")
            .and_then(Value::as_u64)
            .unwrap_or(0);
        let normalized = acc
            .get("normalized")
            .and_then(Value::as_bool)
            .unwrap_or(false);
        let size = match component {
            5120 | 5121 => 1,
            5122 | 5123 => 2,
            5125 | 5126 => 4,
            _ => {
                return Err(self.bad(format!(
                    "{what} has componentType {component}, which glTF does not define"
                )))
            }
        };
        let Some(view) = acc.get("bufferView").and_then(index) else {
            // glTF: an accessor without a buffer view holds zeros.
            return Ok(vec![0.0; count * comps]);
        };
        let (bytes, stride) = self.buffer_view(view)?;
        let offset = acc.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
        let element = size * comps;
        let stride = if stride == 0 { element } else { stride };
        if count > 0 {
            let end = (count - 1)
                .checked_mul(stride)
                .and_then(|v| v.checked_add(offset + element));
            if end.map_or(true, |e| e > bytes.len()) {
                return Err(self.bad(format!(
                    "{what}: {count} elements of {element} bytes (stride {stride}) from byte {offset} run past the end of bufferView {view} ({} bytes)",
                    bytes.len()
                )));
            }
        }
        let mut out = Vec::with_capacity(count * comps);
        for i in 0..count {
            let base = offset + i * stride;
            for c in 0..comps {
                let b = &bytes[base + c * size..base + (c + 1) * size];
                out.push(component_value(component, normalized, b));
            }
        }
        if let Some(bad) = out.iter().position(|v| !v.is_finite()) {
            return Err(self.bad(format!("{what}: element {} is not finite", bad / comps)));
        }
        Ok(out)
    }
}

/// One component as f32 (glTF's normalisation: `max(c / 127, -1)` for signed bytes, ...).
fn component_value(component: u64, normalized: bool, b: &[u8]) -> f32 {
    match component {
        5120 => {
            let v = b[0] as i8 as f32;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        5121 => {
            let v = b[0] as f32;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        5122 => {
            let v = i16::from_le_bytes([b[0], b[1]]) as f32;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        5123 => {
            let v = u16::from_le_bytes([b[0], b[1]]) as f32;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        5125 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        _ => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
    }
}

/// The natural log of a linear scale; a zero scale (allowed) becomes the log of the
/// smallest normal f32, so it stays finite.
fn log_scale(s: f32) -> f32 {
    s.max(f32::MIN_POSITIVE).ln()
}

/// The logit of an opacity in `[0, 1]`, computed in f64 and with the ends moved to the
/// nearest f32 inside the open interval, so it stays finite (0 and 1 map to about -103 and
/// 16.6; the renderer's sigmoid gives back 0 and 0.99999994).
fn logit(o: f32) -> f32 {
    let p = (o as f64).clamp(f32::MIN_POSITIVE as f64, 1.0 - f32::EPSILON as f64 / 2.0);
    (p / (1.0 - p)).ln() as f32
}

fn array<'v>(v: &'v Value, key: &str) -> &'v [Value] {
    v.get(key)
        .and_then(Value::as_array)
        .map(Vec::as_slice)
        .unwrap_or(&[])
}

fn index(v: &Value) -> Option<usize> {
    v.as_u64().map(|i| i as usize)
}

/// A node's local matrix from `matrix` (column-major) or `translation`, `rotation`
/// (`x y z w`) and `scale`.
fn local_matrix(n: &Value) -> Result<DMat4, String> {
    let nums = |key: &str, len: usize| -> Result<Option<Vec<f64>>, String> {
        match n.get(key).and_then(Value::as_array) {
            None => Ok(None),
            Some(a) => {
                let v: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
                if v.len() != len || !v.iter().all(|x| x.is_finite()) {
                    return Err(format!("its {key} is not {len} finite numbers"));
                }
                Ok(Some(v))
            }
        }
    };
    if let Some(m) = nums("matrix", 16)? {
        return Ok(DMat4::from_cols_slice(&m));
    }
    let t = nums("translation", 3)?.map_or(DVec3::ZERO, |v| DVec3::from_slice(&v));
    let r = nums("rotation", 4)?.map_or(DQuat::IDENTITY, |v| {
        DQuat::from_xyzw(v[0], v[1], v[2], v[3])
    });
    let s = nums("scale", 3)?.map_or(DVec3::ONE, |v| DVec3::from_slice(&v));
    if r.length() == 0.0 {
        return Err("its rotation is a zero quaternion".into());
    }
    Ok(DMat4::from_scale_rotation_translation(s, r.normalize(), t))
}

/// Moves a primitive's Gaussians by a node's global matrix (see the module docs).
fn place(scene: Scene, m: DMat4) -> Result<Scene, String> {
    if m == DMat4::IDENTITY {
        return Ok(scene);
    }
    let row = m.row(3);
    if (row - glam::DVec4::W).abs().max_element() > 1e-9 {
        return Err(format!(
            "a node's global matrix has a projective last row {row:?}"
        ));
    }
    let linear = DMat3::from_mat4(m);
    let translation = m.w_axis.truncate();
    let scales = DVec3::new(
        linear.x_axis.length(),
        linear.y_axis.length(),
        linear.z_axis.length(),
    );
    if !(scales.min_element() > 0.0 && scales.is_finite()) {
        return Err(format!(
            "a node's global matrix has a zero or non-finite axis scale {scales:?}"
        ));
    }
    let rotation = DMat3::from_cols(
        linear.x_axis / scales.x,
        linear.y_axis / scales.y,
        linear.z_axis / scales.z,
    );
    let orthogonal = orthonormalized(rotation)
        .ok_or_else(|| format!("a node's global matrix has shear (its columns are not orthogonal: {linear:?}); the extension leaves such transforms undefined"))?;
    let uniform = scales.max_element() - scales.min_element() <= 1e-9 * scales.max_element();
    let mut scene = scene;
    let scale = if uniform {
        scales.x
    } else {
        scale_axes(&mut scene, scales);
        1.0
    };
    SceneTransform::from_parts(orthogonal, scale, translation)?.apply(scene)
}

/// `r` made exactly orthonormal (Gram-Schmidt in f64) when it is orthonormal within
/// 1e-6, else `None`.
fn orthonormalized(r: DMat3) -> Option<DMat3> {
    let err = (r.transpose() * r - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    if err.is_nan() || err > 1e-6 {
        return None;
    }
    let x = r.x_axis.normalize();
    let y = (r.y_axis - x * x.dot(r.y_axis)).normalize();
    let z = (r.z_axis - x * x.dot(r.z_axis) - y * y.dot(r.z_axis)).normalize();
    Some(DMat3::from_cols(x, y, z))
}

/// Scales space by `s` per axis (node-local, before its rotation): centres multiply,
/// each covariance becomes `D Sigma D` and is re-diagonalised into a rotation and scales.
fn scale_axes(scene: &mut Scene, s: DVec3) {
    let d = DMat3::from_diagonal(s);
    for i in 0..scene.len() {
        let p = &mut scene.positions[i];
        *p = [
            (p[0] as f64 * s.x) as f32,
            (p[1] as f64 * s.y) as f32,
            (p[2] as f64 * s.z) as f32,
        ];
        let [w, x, y, z] = scene.rotations[i];
        let q = DQuat::from_xyzw(x as f64, y as f64, z as f64, w as f64).normalize();
        let r = DMat3::from_quat(q);
        let l = scene.log_scales[i];
        let var = DVec3::new(
            (2.0 * l[0] as f64).exp(),
            (2.0 * l[1] as f64).exp(),
            (2.0 * l[2] as f64).exp(),
        );
        let cov = d * r * DMat3::from_diagonal(var) * r.transpose() * d;
        let (vectors, values) = symmetric_eigen(cov);
        let mut vectors = vectors;
        if vectors.determinant() < 0.0 {
            vectors.z_axis = -vectors.z_axis;
        }
        let q = DQuat::from_mat3(&vectors).normalize();
        scene.rotations[i] = [q.w as f32, q.x as f32, q.y as f32, q.z as f32];
        scene.log_scales[i] =
            [0, 1, 2].map(|k| (0.5 * values[k].max(f64::MIN_POSITIVE).ln()) as f32);
    }
}

/// Eigenvectors (columns) and eigenvalues of a symmetric 3x3 matrix, by cyclic Jacobi
/// rotations in f64.
pub(crate) fn symmetric_eigen(m: DMat3) -> (DMat3, [f64; 3]) {
    let mut a = m.to_cols_array_2d();
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..64 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for col in &mut a {
                let (akp, akq) = (col[p], col[q]);
                col[p] = c * akp - s * akq;
                col[q] = s * akp + c * akq;
            }
            let (ap, aq) = (a[p], a[q]);
            a[p] = [0, 1, 2].map(|k| c * ap[k] - s * aq[k]);
            a[q] = [0, 1, 2].map(|k| s * ap[k] + c * aq[k]);
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // v is row-major with eigenvectors as columns: v[row][col].
    let cols = DMat3::from_cols(
        DVec3::new(v[0][0], v[1][0], v[2][0]),
        DVec3::new(v[0][1], v[1][1], v[2][1]),
        DVec3::new(v[0][2], v[1][2], v[2][2]),
    );
    (cols, [a[0][0], a[1][1], a[2][2]])
}

/// The primitives' Gaussians as one scene, at the highest SH degree among them (missing
/// coefficients zero: the same colours).
fn merge(parts: Vec<Scene>) -> Scene {
    if parts.len() == 1 {
        return parts.into_iter().next().expect("one part");
    }
    let degree = parts.iter().map(|s| s.sh_degree).max().unwrap_or(0);
    let mut out = Scene::empty(degree);
    out.antialiased = parts[0].antialiased;
    out.kernel = parts[0].kernel;
    out.rules = parts[0].rules;
    // Folded filters stay folded; the mark only when every primitive has it.
    out.mip_filter = parts.iter().all(|p| p.mip_filter);
    let stride = out.sh_stride();
    for part in parts {
        out.positions.extend(&part.positions);
        out.log_scales.extend(&part.log_scales);
        out.rotations.extend(&part.rotations);
        out.opacity_logits.extend(&part.opacity_logits);
        let own = part.sh_stride();
        for i in 0..part.len() {
            out.sh.extend(&part.sh[i * own..(i + 1) * own]);
            out.sh.extend(std::iter::repeat(0.0).take(stride - own));
        }
    }
    out
}

/// The bytes of a base64 `data:` URI.
fn decode_data_uri(uri: &str) -> Option<Vec<u8>> {
    let (header, payload) = uri.split_once(',')?;
    if !header.ends_with(";base64") {
        return None;
    }
    data_encoding::BASE64.decode(payload.trim().as_bytes()).ok()
}

/// `%20`-style escapes of a relative URI decoded (glTF URIs are RFC 3986).
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let Some(v) = std::str::from_utf8(&bytes[i + 1..i + 3])
                .ok()
                .and_then(|h| u8::from_str_radix(h, 16).ok())
            {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}
