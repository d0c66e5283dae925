//! INRIA 3DGS PLY reading and writing.
//!
//! Accepts `binary_little_endian`, `binary_big_endian` and `ascii` files. Vertex
//! properties are looked up by name, so extra or reordered properties are fine. Other
//! elements (e.g. faces) are parsed past and ignored. A header line
//! `comment verisplat kernel power` records that the scene is made for the power-function
//! kernel ([`SplatKernel`]); the writer adds it for such scenes. Float properties
//! `feat_0 .. feat_{K-1}` (K <= 64) are the Gaussians' feature channels, written back after
//! `rot_*`. Float properties `t_mean` and `t_scale` (both or neither) make a time-varying
//! scene ([`Scene::time`]: temporal mean and natural log of the temporal scale), written
//! back last.

use super::{sh_coeffs_for_degree, Scene, SceneError, MAX_FEATURES};
use crate::core::model::SplatKernel;
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => ScalarType::I8,
            "uchar" | "uint8" => ScalarType::U8,
            "short" | "int16" => ScalarType::I16,
            "ushort" | "uint16" => ScalarType::U16,
            "int" | "int32" => ScalarType::I32,
            "uint" | "uint32" => ScalarType::U32,
            "float" | "float32" => ScalarType::F32,
            "double" | "float64" => ScalarType::F64,
            _ => return None,
        })
    }
    pub(crate) fn size(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }
    pub(crate) fn read(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big_endian {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        match self {
            ScalarType::I8 => b[0] as i8 as f64,
            ScalarType::U8 => b[0] as f64,
            ScalarType::I16 => rd!(i16, 2),
            ScalarType::U16 => rd!(u16, 2),
            ScalarType::I32 => rd!(i32, 4),
            ScalarType::U32 => rd!(u32, 4),
            ScalarType::F32 => rd!(f32, 4),
            ScalarType::F64 => rd!(f64, 8),
        }
    }
}

#[derive(Clone, Debug)]
pub(crate) enum Property {
    Scalar {
        name: String,
        ty: ScalarType,
    },
    List {
        name: String,
        count: ScalarType,
        item: ScalarType,
    },
}

impl Property {
    pub(crate) fn name(&self) -> &str {
        match self {
            Property::Scalar { name, .. } | Property::List { name, .. } => name,
        }
    }
}

#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub(crate) name: String,
    pub(crate) count: u64,
    pub(crate) properties: Vec<Property>,
}

pub(crate) struct Header {
    pub(crate) format: Format,
    pub(crate) elements: Vec<Element>,
    pub(crate) body_offset: usize,
    /// `comment` lines: the header line number (1-based) and the text after `comment`.
    pub(crate) comments: Vec<(usize, String)>,
}

/// The header comment that records a scene's alpha falloff: `comment verisplat kernel NAME`.
pub const KERNEL_COMMENT: &str = "verisplat kernel";
/// The header comment that records a scene's rasterizer rules: `comment verisplat rules NAME`.
pub const RULES_COMMENT: &str = "verisplat rules";
/// The header comment that records Mip-Splatting's 3D filter folded into the scales and
/// opacities: `comment verisplat mip-filter 3d` ([`Scene::mip_filter`]).
pub const MIP_FILTER_COMMENT: &str = "verisplat mip-filter";

/// The value of a `comment verisplat mip-filter` line: "3d" is the only one written.
#[derive(Default)]
struct MipFilterMark(bool);

impl std::str::FromStr for MipFilterMark {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "3d" => Ok(MipFilterMark(true)),
            _ => Err("the only mip-filter verisplat writes is \"3d\"".into()),
        }
    }
}

impl Header {
    /// The element called `name`, if the header declares one.
    pub(crate) fn element(&self, name: &str) -> Option<&Element> {
        self.elements.iter().find(|e| e.name == name)
    }

    /// The alpha falloff a `comment verisplat kernel NAME` line records (Gaussian without
    /// one); an unknown name is an error naming the line.
    pub(crate) fn kernel(&self, path: &Path) -> Result<SplatKernel, SceneError> {
        self.recorded(path, KERNEL_COMMENT)
    }

    /// The rules a `comment verisplat rules NAME` line records (the original's without one).
    pub(crate) fn rules(&self, path: &Path) -> Result<crate::core::model::Rules, SceneError> {
        self.recorded(path, RULES_COMMENT)
    }

    /// Whether a `comment verisplat mip-filter 3d` line says the 3D filter is folded in; any
    /// other value is an error naming the line.
    pub(crate) fn mip_filter(&self, path: &Path) -> Result<bool, SceneError> {
        Ok(self.recorded::<MipFilterMark>(path, MIP_FILTER_COMMENT)?.0)
    }

    /// The value the last `comment PREFIX VALUE` line records (the default without one); a
    /// file written under the former name has that name in the prefix ([`crate::core::former_name`]).
    fn recorded<T: Default + std::str::FromStr<Err = String>>(
        &self,
        path: &Path,
        prefix: &str,
    ) -> Result<T, SceneError> {
        let mut value = T::default();
        for (line, text) in &self.comments {
            let words: Vec<&str> = text.split_whitespace().collect();
            if words.len() < 2
                || !crate::core::former_name::matches_key(&words[..2].join(" "), prefix)
            {
                continue;
            }
            value = words[2..].join(" ").parse().map_err(|e: String| {
                SceneError::invalid(path, format!("header line {line}: \"comment {text}\": {e}"))
            })?;
        }
        Ok(value)
    }

    /// The body encoding as the public enum.
    pub(crate) fn encoding(&self) -> PlyEncoding {
        match self.format {
            Format::Ascii => PlyEncoding::Ascii,
            Format::BinaryLe => PlyEncoding::BinaryLittleEndian,
            Format::BinaryBe => PlyEncoding::BinaryBigEndian,
        }
    }
}

impl Element {
    /// True when the element has a property called `name`.
    pub(crate) fn has(&self, name: &str) -> bool {
        self.properties.iter().any(|p| p.name() == name)
    }
}

pub(crate) fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, SceneError> {
    let bad = |m: String| SceneError::invalid(path, m);
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err(bad(
            "is not a PLY file (it does not start with \"ply\")".into()
        ));
    }
    let limit = bytes.len().min(1 << 20);
    let end = find_subslice(&bytes[..limit], b"end_header").ok_or_else(|| {
        bad("has no end_header line in its first megabyte; the PLY header is truncated".into())
    })?;
    let mut body_offset = end + b"end_header".len();
    if bytes.get(body_offset) == Some(&b'\r') {
        body_offset += 1;
    }
    if bytes.get(body_offset) != Some(&b'\n') {
        return Err(bad(
            "ends right after end_header, without a newline or any data; the file is truncated"
                .into(),
        ));
    }
    body_offset += 1;
    let header = std::str::from_utf8(&bytes[..end])
        .map_err(|_| bad("has a PLY header that is not valid text".into()))?;

    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut comments = Vec::new();
    for (lineno, line) in header.lines().enumerate().skip(1) {
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        let rest: Vec<&str> = words.collect();
        let line_err = |what: &str| {
            bad(format!(
                "header line {}: {what}: \"{}\"",
                lineno + 1,
                line.trim()
            ))
        };
        match keyword {
            "format" => {
                format = Some(match rest.first().copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    _ => return Err(line_err("unknown PLY format")),
                });
            }
            "comment" => comments.push((lineno + 1, rest.join(" "))),
            "obj_info" => {}
            "element" => {
                if rest.len() != 2 {
                    return Err(line_err("malformed element line"));
                }
                let count: u64 = rest[1]
                    .parse()
                    .map_err(|_| line_err("element count is not a non-negative integer"))?;
                elements.push(Element {
                    name: rest[0].to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            "property" => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| line_err("property before any element"))?;
                let prop = if rest.first() == Some(&"list") {
                    if rest.len() != 4 {
                        return Err(line_err("malformed list property"));
                    }
                    Property::List {
                        count: ScalarType::parse(rest[1])
                            .ok_or_else(|| line_err("unknown property type"))?,
                        item: ScalarType::parse(rest[2])
                            .ok_or_else(|| line_err("unknown property type"))?,
                        name: rest[3].to_string(),
                    }
                } else {
                    if rest.len() != 2 {
                        return Err(line_err("malformed property line"));
                    }
                    Property::Scalar {
                        ty: ScalarType::parse(rest[0])
                            .ok_or_else(|| line_err("unknown property type"))?,
                        name: rest[1].to_string(),
                    }
                };
                el.properties.push(prop);
            }
            _ => return Err(line_err("unknown header keyword")),
        }
    }
    let format = format.ok_or_else(|| bad("has no format line in its PLY header".into()))?;
    Ok(Header {
        format,
        elements,
        body_offset,
        comments,
    })
}

fn find_subslice(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Where each scene attribute lives among the vertex properties.
struct VertexMap {
    xyz: [usize; 3],
    f_dc: [usize; 3],
    f_rest: Vec<usize>,
    opacity: usize,
    scale: [usize; 3],
    rot: [usize; 4],
    sh_degree: u32,
    /// `feat_0 .. feat_{K-1}`.
    features: Vec<usize>,
    /// `t_mean`, `t_scale` of a time-varying scene.
    time: Option<[usize; 2]>,
}

fn map_vertex(el: &Element, path: &Path) -> Result<VertexMap, SceneError> {
    let find = |name: &str| -> Result<usize, SceneError> {
        let idx = el
            .properties
            .iter()
            .position(|p| p.name() == name)
            .ok_or_else(|| {
                SceneError::invalid(
                    path,
                    format!("is missing the vertex property \"{name}\" required for a 3DGS scene"),
                )
            })?;
        if matches!(el.properties[idx], Property::List { .. }) {
            return Err(SceneError::invalid(
                path,
                format!("vertex property \"{name}\" is a list, but a scalar is required"),
            ));
        }
        Ok(idx)
    };
    let n_rest = el
        .properties
        .iter()
        .filter(|p| p.name().starts_with("f_rest_"))
        .count();
    let sh_degree = match n_rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => {
            return Err(SceneError::invalid(
                path,
                format!(
                "has {n} f_rest_* properties; 3DGS files have 0, 9, 24 or 45 (SH degree 0 to 3)"
            ),
            ))
        }
    };
    let f_rest = (0..n_rest)
        .map(|i| find(&format!("f_rest_{i}")))
        .collect::<Result<Vec<_>, _>>()?;
    let n_feat = el
        .properties
        .iter()
        .filter(|p| p.name().starts_with("feat_"))
        .count();
    if n_feat > MAX_FEATURES {
        return Err(SceneError::invalid(
            path,
            format!("has {n_feat} feat_* properties; a Gaussian carries at most {MAX_FEATURES} feature channels"),
        ));
    }
    // Named feat_0 .. feat_{K-1}: a gap is reported as the missing name.
    let features = (0..n_feat)
        .map(|i| find(&format!("feat_{i}")))
        .collect::<Result<Vec<_>, _>>()?;
    let has = |name: &str| el.properties.iter().any(|p| p.name() == name);
    let time = match (has("t_mean"), has("t_scale")) {
        (true, true) => Some([find("t_mean")?, find("t_scale")?]),
        (false, false) => None,
        (with, _) => {
            let (present, missing) = if with {
                ("t_mean", "t_scale")
            } else {
                ("t_scale", "t_mean")
            };
            return Err(SceneError::invalid(
                path,
                format!("has the vertex property \"{present}\" but not \"{missing}\"; a time-varying scene needs both (temporal mean and log temporal scale)"),
            ));
        }
    };
    Ok(VertexMap {
        time,
        xyz: [find("x")?, find("y")?, find("z")?],
        f_dc: [find("f_dc_0")?, find("f_dc_1")?, find("f_dc_2")?],
        f_rest,
        opacity: find("opacity")?,
        scale: [find("scale_0")?, find("scale_1")?, find("scale_2")?],
        rot: [
            find("rot_0")?,
            find("rot_1")?,
            find("rot_2")?,
            find("rot_3")?,
        ],
        sh_degree,
        features,
    })
}

/// Cursor over the body that reads element rows in any of the three encodings.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    format: Format,
    path: &'a Path,
}

impl Body<'_> {
    fn truncated(&self, what: &str) -> SceneError {
        SceneError::invalid(self.path, format!("is truncated: the data ends inside {what}; the header promises more than the file holds"))
    }

    fn next_ascii_token(&mut self, ty: ScalarType, what: &str) -> Result<f64, SceneError> {
        let b = self.bytes;
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.truncated(what));
        }
        let tok = std::str::from_utf8(&b[start..self.pos]).unwrap_or("?");
        // Floats parse straight to f32 so a shortest-round-trip decimal is exact.
        let parsed = if ty == ScalarType::F32 {
            tok.parse::<f32>().map(f64::from)
        } else {
            tok.parse::<f64>()
        };
        parsed.map_err(|_| {
            SceneError::invalid(
                self.path,
                format!("has a non-numeric value \"{tok}\" in {what}"),
            )
        })
    }

    fn read_scalar(&mut self, ty: ScalarType, what: &str) -> Result<f64, SceneError> {
        match self.format {
            Format::Ascii => self.next_ascii_token(ty, what),
            Format::BinaryLe | Format::BinaryBe => {
                let n = ty.size();
                if self.bytes.len() - self.pos < n {
                    return Err(self.truncated(what));
                }
                let v = ty.read(&self.bytes[self.pos..], self.format == Format::BinaryBe);
                self.pos += n;
                Ok(v)
            }
        }
    }

    /// Reads one row into `out` (scalar properties only; list properties are skipped).
    fn read_row(&mut self, el: &Element, row: u64, out: &mut [f64]) -> Result<(), SceneError> {
        for (pi, p) in el.properties.iter().enumerate() {
            match p {
                Property::Scalar { ty, name } => {
                    out[pi] =
                        self.read_scalar(*ty, &format!("{} {row} property {name}", el.name))?;
                }
                Property::List { count, item, name } => {
                    let what = format!("{} {row} list {name}", el.name);
                    let n = self.read_scalar(*count, &what)?;
                    if !(0.0..=1e9).contains(&n) || n.fract() != 0.0 {
                        return Err(SceneError::invalid(
                            self.path,
                            format!("has an invalid list length {n} in {what}"),
                        ));
                    }
                    for _ in 0..n as u64 {
                        self.read_scalar(*item, &what)?;
                    }
                    out[pi] = n;
                }
            }
        }
        Ok(())
    }

    /// Checks up front that a fixed-size binary element fits, so a lying count fails fast.
    fn check_fits(&self, el: &Element) -> Result<(), SceneError> {
        if self.format == Format::Ascii {
            return Ok(());
        }
        let mut row = 0u64;
        for p in &el.properties {
            match p {
                Property::Scalar { ty, .. } => row += ty.size() as u64,
                Property::List { .. } => return Ok(()),
            }
        }
        let need = row.checked_mul(el.count);
        let have = (self.bytes.len() - self.pos) as u64;
        match need {
            Some(need) if need <= have => Ok(()),
            _ => Err(SceneError::invalid(
                self.path,
                format!(
                    "is truncated or its header lies: it declares {} {} elements of {row} bytes ({} bytes) but only {have} bytes of data follow the header",
                    el.count,
                    el.name,
                    need.map_or("more than 2^64".to_string(), |n| n.to_string()),
                ),
            )),
        }
    }
}

/// Parses an INRIA 3DGS PLY held in memory. `path` is used in error messages only.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    let header = parse_header(bytes, path)?;
    let vi = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| {
            SceneError::invalid(path, "has no \"vertex\" element; it is not a 3DGS scene")
        })?;
    let map = map_vertex(&header.elements[vi], path)?;

    let mut body = Body {
        bytes,
        pos: header.body_offset,
        format: header.format,
        path,
    };
    let mut scene = Scene::empty(map.sh_degree);
    scene.kernel = header.kernel(path)?;
    scene.rules = header.rules(path)?;
    scene.mip_filter = header.mip_filter(path)?;
    scene.feature_count = map.features.len();
    if map.time.is_some() {
        scene.time = Some(Vec::new());
    }
    for (ei, el) in header.elements.iter().enumerate() {
        body.check_fits(el)?;
        if ei != vi {
            // A row without properties holds no bytes: there is nothing to read, and
            // looping over a claimed 2^64 of them would never end.
            if el.properties.is_empty() {
                continue;
            }
            let mut row = vec![0f64; el.properties.len()];
            for r in 0..el.count {
                body.read_row(el, r, &mut row)?;
            }
            continue;
        }
        read_vertices(&mut body, el, &map, &mut scene)?;
    }
    check_end(&body, header.body_offset)?;
    Ok(scene)
}

/// Reads the rows of the vertex element `el` into `scene`, as `map` places them.
fn read_vertices(
    body: &mut Body,
    el: &Element,
    map: &VertexMap,
    scene: &mut Scene,
) -> Result<(), SceneError> {
    let bytes = body.bytes;
    let mut row = vec![0f64; el.properties.len()];
    // Every property of a row takes at least one byte in any encoding, so a lying
    // count (an ASCII header may claim 2^40 vertices) cannot reserve more rows than
    // the remaining bytes can hold.
    let room = (bytes.len() - body.pos) / el.properties.len().max(1);
    let n = (el.count as usize).min(room);
    scene.positions.reserve_exact(n);
    scene.log_scales.reserve_exact(n);
    scene.rotations.reserve_exact(n);
    scene.opacity_logits.reserve_exact(n);
    scene.sh.reserve_exact(n * scene.sh_stride());
    scene.features.reserve_exact(n * map.features.len());
    let all_f32 = body.format != Format::Ascii
        && el.properties.iter().all(|p| {
            matches!(
                p,
                Property::Scalar {
                    ty: ScalarType::F32,
                    ..
                }
            )
        });
    for r in 0..el.count {
        if all_f32 {
            // Fast path for the all-float layout every trainer writes.
            let be = body.format == Format::BinaryBe;
            for (pi, v) in row.iter_mut().enumerate() {
                *v = ScalarType::F32.read(&bytes[body.pos + 4 * pi..], be);
            }
            body.pos += 4 * el.properties.len();
        } else {
            body.read_row(el, r, &mut row)?;
        }
        push_vertex(&row, r, el, map, scene, body.path)?;
    }
    Ok(())
}

/// Appends vertex `r` (its property values `row`) to `scene`; every value it uses must
/// be finite and its rotation of non-zero length.
fn push_vertex(
    row: &[f64],
    r: u64,
    el: &Element,
    map: &VertexMap,
    scene: &mut Scene,
    path: &Path,
) -> Result<(), SceneError> {
    let k_rest = sh_coeffs_for_degree(map.sh_degree) - 1;
    let get = |pi: usize| -> Result<f32, SceneError> {
        let v = row[pi] as f32;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(SceneError::invalid(
                path,
                format!(
                    "vertex {r} has a non-finite value ({v}) in property \"{}\"",
                    el.properties[pi].name()
                ),
            ))
        }
    };
    scene
        .positions
        .push([get(map.xyz[0])?, get(map.xyz[1])?, get(map.xyz[2])?]);
    scene
        .log_scales
        .push([get(map.scale[0])?, get(map.scale[1])?, get(map.scale[2])?]);
    let q = [
        get(map.rot[0])?,
        get(map.rot[1])?,
        get(map.rot[2])?,
        get(map.rot[3])?,
    ];
    let norm2 = q.iter().map(|v| v * v).sum::<f32>();
    if norm2 == 0.0 || !norm2.is_finite() {
        return Err(SceneError::invalid(
            path,
            format!("vertex {r} has a zero-length rotation quaternion (rot_0..rot_3 = {q:?}), which cannot be normalised"),
        ));
    }
    scene.rotations.push(q);
    scene.opacity_logits.push(get(map.opacity)?);
    for c in 0..3 {
        scene.sh.push(get(map.f_dc[c])?);
    }
    // f_rest is channel-major in the file; store coefficient-major, channel innermost.
    for k in 0..k_rest {
        for c in 0..3 {
            scene.sh.push(get(map.f_rest[c * k_rest + k])?);
        }
    }
    for &f in &map.features {
        scene.features.push(get(f)?);
    }
    if let (Some([m, l]), Some(t)) = (map.time, scene.time.as_mut()) {
        t.push([get(m)?, get(l)?]);
    }
    Ok(())
}

/// Checks what follows the last element: nothing in a binary file; in an ASCII one, the
/// line break that ends the last row and nothing but white space.
fn check_end(body: &Body, body_offset: usize) -> Result<(), SceneError> {
    let (bytes, path) = (body.bytes, body.path);
    if body.format != Format::Ascii && body.pos != bytes.len() {
        return Err(SceneError::invalid(
            path,
            format!(
                "has {} bytes after the last element the header declares; its counts do not match the data",
                bytes.len() - body.pos
            ),
        ));
    }
    if body.format == Format::Ascii
        && body.pos > body_offset
        && !bytes[body.pos..].iter().any(|&b| b == b'\n' || b == b'\r')
    {
        // Every writer ends the last row with a line break; without one, a file cut
        // inside its last number would load with that number shortened.
        return Err(SceneError::invalid(
            path,
            "ends inside its last value, without a line break after it; the file is truncated",
        ));
    }
    if body.format == Format::Ascii && bytes[body.pos..].iter().any(|b| !b.is_ascii_whitespace()) {
        return Err(SceneError::invalid(
            path,
            "has more values than its header declares; its counts do not match the data",
        ));
    }
    Ok(())
}

/// Encoding of a PLY body, as read or as written by [`to_bytes`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyEncoding {
    /// `binary_little_endian`, what the trainer writes.
    BinaryLittleEndian,
    /// `binary_big_endian`.
    BinaryBigEndian,
    /// `ascii`.
    Ascii,
}

/// Serialises a scene as an INRIA PLY with the trainer's property order
/// (`x y z nx ny nz f_dc_* f_rest_* opacity scale_* rot_*`), then `feat_*` when the scene
/// has feature channels, then `t_mean t_scale` when it is time-varying.
pub fn to_bytes(scene: &Scene, encoding: PlyEncoding) -> Vec<u8> {
    let k_rest = scene.sh_coeffs() - 1;
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    names.extend((0..3 * k_rest).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names.extend((0..scene.feature_count).map(|i| format!("feat_{i}")));
    if scene.time.is_some() {
        names.extend(["t_mean".to_string(), "t_scale".to_string()]);
    }
    let format = match encoding {
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::BinaryBigEndian => "binary_big_endian",
        PlyEncoding::Ascii => "ascii",
    };
    let mut out = format!("ply\nformat {format} 1.0\n");
    // Only a non-default kernel is recorded, so Gaussian scenes keep the trainer's header.
    if scene.kernel != SplatKernel::Gaussian {
        out.push_str(&format!("comment {KERNEL_COMMENT} {}\n", scene.kernel));
    }
    if scene.rules != crate::core::model::Rules::Original {
        out.push_str(&format!("comment {RULES_COMMENT} {}\n", scene.rules));
    }
    if scene.mip_filter {
        out.push_str(&format!("comment {MIP_FILTER_COMMENT} 3d\n"));
    }
    out.push_str(&format!("element vertex {}\n", scene.len()));
    for n in &names {
        out.push_str(&format!("property float {n}\n"));
    }
    out.push_str("end_header\n");
    let mut bytes = out.into_bytes();
    let stride = scene.sh_stride();
    let mut row = Vec::with_capacity(names.len());
    for i in 0..scene.len() {
        row.clear();
        row.extend_from_slice(&scene.positions[i]);
        row.extend_from_slice(&[0.0, 0.0, 0.0]);
        let sh = &scene.sh[i * stride..(i + 1) * stride];
        row.extend_from_slice(&sh[0..3]);
        for c in 0..3 {
            for k in 0..k_rest {
                row.push(sh[(k + 1) * 3 + c]);
            }
        }
        row.push(scene.opacity_logits[i]);
        row.extend_from_slice(&scene.log_scales[i]);
        row.extend_from_slice(&scene.rotations[i]);
        let k = scene.feature_count;
        row.extend_from_slice(&scene.features[i * k..(i + 1) * k]);
        if let Some(t) = &scene.time {
            row.extend_from_slice(&t[i]);
        }
        match encoding {
            PlyEncoding::BinaryLittleEndian => row
                .iter()
                .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes())),
            PlyEncoding::BinaryBigEndian => row
                .iter()
                .for_each(|v| bytes.extend_from_slice(&v.to_be_bytes())),
            PlyEncoding::Ascii => {
                let line: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
                bytes.extend_from_slice(line.join(" ").as_bytes());
                bytes.push(b'\n');
            }
        }
    }
    bytes
}
