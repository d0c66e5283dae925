//! Scene writers and `verisplat convert`: load any format, transform, filter, write INRIA
//! PLY, `.splat`, SPZ v3, PlayCanvas compressed PLY, SOG or glTF (`.glb`, `.gltf`) chosen
//! by the output's name, atomically.

use super::filter::SceneFilter;
use super::transform::SceneTransform;
use super::{compressed_ply_write, ply, sog_write, splat, spz, Scene, SceneError, SceneFormat};
use crate::core::fsutil::{self, WriteError};
use std::path::{Path, PathBuf};

/// A format [`to_bytes`] can write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// INRIA PLY, binary little-endian, any SH degree (lossless).
    Ply,
    /// antimatter15 `.splat` (SH DC only, 8-bit colour/opacity/rotation).
    Splat,
    /// Niantic SPZ v3, gzip, RUB axes.
    Spz,
    /// PlayCanvas / SuperSplat compressed PLY (chunked, quantised; `.compressed.ply`).
    CompressedPly,
    /// PlayCanvas SOG v2: a `.sog` zip bundle, or the files of an unbundled SOG beside an
    /// output named `meta.json`.
    Sog,
    /// glTF 2.0 binary (`.glb`) with `KHR_gaussian_splatting`, 32-bit floats.
    Glb,
    /// glTF 2.0 JSON (`.gltf`) with `KHR_gaussian_splatting`; its buffer is written as
    /// `<stem>.bin` beside it (by [`write_scene`]; [`to_bytes`] embeds it as a `data:` URI).
    Gltf,
}

impl OutputFormat {
    /// Chooses the writer from a file name: `.compressed.ply` (PlayCanvas compressed PLY)
    /// before `.ply` (INRIA), `.splat`, `.spz`, `.sog` (a SOG bundle), and `meta.json`
    /// (an unbundled SOG: its textures are written beside it).
    pub fn from_path(path: &Path) -> Result<OutputFormat, ConvertError> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if name.ends_with(".compressed.ply") {
            return Ok(OutputFormat::CompressedPly);
        }
        if name == "meta.json" {
            return Ok(OutputFormat::Sog);
        }
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("ply") => Ok(OutputFormat::Ply),
            Some("splat") => Ok(OutputFormat::Splat),
            Some("spz") => Ok(OutputFormat::Spz),
            Some("sog") => Ok(OutputFormat::Sog),
            Some("glb") => Ok(OutputFormat::Glb),
            Some("gltf") => Ok(OutputFormat::Gltf),
            _ => Err(ConvertError::UnknownFormat(path.to_path_buf())),
        }
    }
}

impl OutputFormat {
    /// The highest SH degree the format stores (`.splat` keeps only the DC colour).
    pub fn max_sh_degree(self) -> u32 {
        match self {
            OutputFormat::Ply
            | OutputFormat::Spz
            | OutputFormat::CompressedPly
            | OutputFormat::Sog
            | OutputFormat::Glb
            | OutputFormat::Gltf => 3,
            OutputFormat::Splat => 0,
        }
    }
}

impl OutputFormat {
    /// The format records antialiased training (SPZ's flag, SOG's `antialias`, the
    /// compressed PLY's `SplatRenderMode: mip` comment).
    pub fn records_antialiasing(self) -> bool {
        matches!(
            self,
            OutputFormat::Spz
                | OutputFormat::Sog
                | OutputFormat::CompressedPly
                | OutputFormat::Glb
                | OutputFormat::Gltf
        )
    }

    /// The format records a non-Gaussian kernel, gsplat's rules and a folded 3D filter
    /// (PLY header comments, in the INRIA and the compressed PLY; glTF extras).
    pub fn records_kernel_and_rules(self) -> bool {
        matches!(
            self,
            OutputFormat::Ply
                | OutputFormat::CompressedPly
                | OutputFormat::Glb
                | OutputFormat::Gltf
        )
    }
}

impl std::fmt::Display for OutputFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OutputFormat::Ply => "INRIA PLY (binary little-endian)",
            OutputFormat::Splat => "antimatter15 .splat",
            OutputFormat::Spz => "SPZ v3 (gzip)",
            OutputFormat::CompressedPly => "PlayCanvas compressed PLY",
            OutputFormat::Sog => "PlayCanvas SOG v2",
            OutputFormat::Glb => "glTF 2.0 binary (KHR_gaussian_splatting)",
            OutputFormat::Gltf => "glTF 2.0 JSON + .bin (KHR_gaussian_splatting)",
        })
    }
}

/// Error raised by [`convert`].
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// The input could not be loaded.
    #[error(transparent)]
    Load(#[from] SceneError),
    /// The output could not be written.
    #[error(transparent)]
    Write(#[from] WriteError),
    /// The output's extension names no writer.
    #[error("{0}: unknown output format; use a .ply, .compressed.ply, .splat, .spz, .sog, .glb or .gltf file name, or DIR/meta.json for an unbundled SOG")]
    UnknownFormat(PathBuf),
    /// The output names a format or a destination that cannot be written.
    #[error("{path}: {message}")]
    Unsupported {
        /// Output file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The filter parameters are invalid.
    #[error("{0}")]
    Filter(String),
    /// The transform gives values that are not finite.
    #[error("{path}: {message}")]
    Transform {
        /// Input file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The scene cannot be represented in the output format.
    #[error("{path}: cannot be written as {format}: {message}")]
    Encode {
        /// Output file.
        path: PathBuf,
        /// Output format.
        format: OutputFormat,
        /// Why.
        message: String,
    },
}

/// Serialises a scene in `format` (a time-varying scene only as PLY).
pub fn to_bytes(scene: &Scene, format: OutputFormat) -> Result<Vec<u8>, String> {
    if scene.time.is_some() && format != OutputFormat::Ply {
        return Err("the scene is time-varying (t_mean, t_scale per Gaussian), which only PLY holds; write a .ply, or the scene at one time".into());
    }
    match format {
        OutputFormat::Ply => Ok(ply::to_bytes(scene, ply::PlyEncoding::BinaryLittleEndian)),
        OutputFormat::Splat => Ok(splat::to_bytes(scene)),
        OutputFormat::Spz => spz::to_bytes_v3(scene),
        OutputFormat::CompressedPly => compressed_ply_write::to_bytes(scene),
        OutputFormat::Sog => sog_write::encode(scene)?.to_zip(),
        OutputFormat::Glb => super::gltf_write::to_glb(scene),
        OutputFormat::Gltf => super::gltf_write::to_gltf_embedded(scene),
    }
}

/// True when `path` names an unbundled SOG's `meta.json` (its textures go beside it).
fn is_sog_directory(path: &Path) -> bool {
    path.file_name()
        .is_some_and(|n| n.eq_ignore_ascii_case("meta.json"))
}

/// Writes `scene` to `path` in `format`, atomically, and returns the bytes written. An
/// unbundled SOG (`format` SOG, `path` named `meta.json`) writes its textures beside
/// `meta.json`, creating the folder if needed, each file atomically and `meta.json`
/// last; with `overwrite == false` any of its files existing is an error, and nothing is
/// written.
pub fn write_scene(
    scene: &Scene,
    path: &Path,
    format: OutputFormat,
    overwrite: bool,
) -> Result<usize, ConvertError> {
    let encode = |message| ConvertError::Encode {
        path: path.to_path_buf(),
        format,
        message,
    };
    if format == OutputFormat::Sog && is_sog_directory(path) {
        if scene.time.is_some() {
            return Err(encode(to_bytes(scene, format).unwrap_err()));
        }
        let files = sog_write::encode(scene).map_err(encode)?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let targets: Vec<PathBuf> = files.textures.iter().map(|(n, _)| dir.join(n)).collect();
        if !overwrite {
            if let Some(t) = std::iter::once(path)
                .chain(targets.iter().map(PathBuf::as_path))
                .find(|t| t.exists())
            {
                return Err(WriteError::Exists(t.to_path_buf()).into());
            }
        }
        std::fs::create_dir_all(&dir).map_err(|source| WriteError::Io {
            path: dir.clone(),
            source,
        })?;
        for ((_, bytes), target) in files.textures.iter().zip(&targets) {
            fsutil::write_bytes_atomically(target, overwrite, bytes)?;
        }
        fsutil::write_bytes_atomically(path, overwrite, &files.meta)?;
        return Ok(files.len());
    }
    if format == OutputFormat::Gltf {
        if scene.time.is_some() {
            return Err(encode(to_bytes(scene, format).unwrap_err()));
        }
        return super::gltf_write::write_gltf_files(scene, path, overwrite).map_err(|e| match e {
            super::gltf_write::GltfWriteError::Encode(m) => encode(m),
            super::gltf_write::GltfWriteError::Write(w) => w.into(),
        });
    }
    let bytes = to_bytes(scene, format).map_err(encode)?;
    fsutil::write_bytes_atomically(path, overwrite, &bytes)?;
    Ok(bytes.len())
}

/// Options of [`convert`].
#[derive(Clone, Debug, Default)]
pub struct ConvertOptions {
    /// Transform applied to the loaded scene, before the filter (so a crop box is in the
    /// transformed frame).
    pub transform: Option<SceneTransform>,
    /// Selection and SH truncation applied before writing.
    pub filter: SceneFilter,
    /// Replace an existing output file.
    pub overwrite: bool,
    /// Record this alpha falloff in the output instead of the input's (`Scene::kernel`;
    /// only PLY can record one).
    pub kernel: Option<crate::core::model::SplatKernel>,
    /// Feature channels to attach to the input first: an N x K NumPy array
    /// ([`super::features::attach_npy`]); only PLY keeps them.
    pub features: Option<std::path::PathBuf>,
    /// The frame of the SPZ input and of the SPZ output, whichever are SPZ
    /// ([`spz::SpzAxes`]); `Raw` is an error when neither is.
    pub spz_axes: spz::SpzAxes,
}

/// What [`convert`] did.
#[derive(Clone, Debug)]
pub struct ConvertReport {
    /// Detected input format.
    pub input_format: SceneFormat,
    /// Output format.
    pub output_format: OutputFormat,
    /// Gaussians read.
    pub read: usize,
    /// Gaussians written (after the filters).
    pub written: usize,
    /// SH degree written.
    pub sh_degree: u32,
    /// SH degree of the scene before writing, when the output format stores fewer bands
    /// (`.splat`: DC only) and higher bands were dropped.
    pub sh_dropped_from: Option<u32>,
    /// Bytes written (all the files of an unbundled SOG).
    pub bytes: usize,
    /// The input records antialiased training but the output format cannot say so.
    pub antialiased_flag_lost: bool,
    /// The input records a non-Gaussian kernel (`cpu::SplatKernel`) that the output format
    /// cannot record (only PLY can).
    pub kernel_lost: Option<crate::core::model::SplatKernel>,
    /// The input records gsplat's rules (`model::Rules`), which the output format cannot
    /// record (only PLY can).
    pub rules_lost: Option<crate::core::model::Rules>,
    /// The input says Mip-Splatting's 3D filter is folded into its scales and opacities
    /// ([`Scene::mip_filter`]); the output holds the same Gaussians but cannot say so.
    pub mip_filter_mark_lost: bool,
    /// Feature channels per Gaussian that the output format cannot hold and dropped (only
    /// PLY keeps `feat_*`); 0 when none were lost.
    pub features_dropped: usize,
}

/// Loads `input` (any supported format), applies the transform and then the filter, and
/// writes `output` in the format its extension names. An existing output is refused unless
/// `overwrite`; the file is written to a temporary name and renamed, so it never appears
/// half-written.
pub fn convert(
    input: &Path,
    output: &Path,
    options: &ConvertOptions,
) -> Result<ConvertReport, ConvertError> {
    let output_format = OutputFormat::from_path(output)?;
    options.filter.validate().map_err(ConvertError::Filter)?;
    if same_file(input, output) {
        return Err(ConvertError::Unsupported {
            path: output.to_path_buf(),
            message: "is the input file; write the converted scene to another file".into(),
        });
    }
    if !options.overwrite && output.exists() {
        return Err(WriteError::Exists(output.to_path_buf()).into());
    }
    let (mut scene, input_format) = super::load_with_format(input)?;
    let spz_in = matches!(input_format, SceneFormat::Spz { .. });
    let raw = options.spz_axes == spz::SpzAxes::Raw;
    if raw && !spz_in && output_format != OutputFormat::Spz {
        return Err(ConvertError::Unsupported {
            path: input.to_path_buf(),
            message: format!("is {input_format} and the output is not SPZ: raw SPZ axes (--spz-axes raw) apply to an SPZ input or output"),
        });
    }
    if raw && spz_in {
        spz::flip_rub(&mut scene);
    }
    if spz_in {
        if let Some(note) = spz::axes_note(input, &scene, options.spz_axes) {
            crate::core::console::note!("{note}");
        }
    }
    if let Some(kernel) = options.kernel {
        scene.kernel = kernel;
    }
    if let Some(file) = &options.features {
        super::features::attach_npy(&mut scene, file)?;
    }
    if scene.time.is_some() && output_format != OutputFormat::Ply {
        return Err(ConvertError::Encode {
            path: output.to_path_buf(),
            format: output_format,
            message: format!(
                "{} is time-varying (t_mean, t_scale per Gaussian), which only PLY holds; write a .ply, or render a time with `verisplat render --time T`",
                input.display()
            ),
        });
    }
    let read = scene.len();
    let scene = match &options.transform {
        Some(t) => t.apply(scene).map_err(|message| ConvertError::Transform {
            path: input.to_path_buf(),
            message,
        })?,
        None => scene,
    };
    let filtered = options.filter.apply(&scene);
    if filtered.is_empty()
        && matches!(
            output_format,
            OutputFormat::Sog
                | OutputFormat::CompressedPly
                | OutputFormat::Glb
                | OutputFormat::Gltf
        )
    {
        return Err(ConvertError::Encode {
            path: output.to_path_buf(),
            format: output_format,
            message: if read > 0 {
                format!(
                    "the filters removed all {read} Gaussians, and it cannot hold an empty scene"
                )
            } else {
                format!(
                    "{} holds no Gaussians, and it cannot hold an empty scene",
                    input.display()
                )
            },
        });
    }
    let bytes = if raw && output_format == OutputFormat::Spz {
        let mut turned = filtered.clone();
        spz::flip_rub(&mut turned);
        write_scene(&turned, output, output_format, options.overwrite)?
    } else {
        write_scene(&filtered, output, output_format, options.overwrite)?
    };
    Ok(ConvertReport {
        input_format,
        output_format,
        read,
        written: filtered.len(),
        sh_degree: filtered.sh_degree.min(output_format.max_sh_degree()),
        sh_dropped_from: (filtered.sh_degree > output_format.max_sh_degree())
            .then_some(filtered.sh_degree),
        bytes,
        antialiased_flag_lost: scene.antialiased && !output_format.records_antialiasing(),
        kernel_lost: (scene.kernel != crate::core::model::SplatKernel::Gaussian
            && !output_format.records_kernel_and_rules())
        .then_some(scene.kernel),
        rules_lost: (scene.rules != crate::core::model::Rules::Original
            && !output_format.records_kernel_and_rules())
        .then_some(scene.rules),
        mip_filter_mark_lost: scene.mip_filter && !output_format.records_kernel_and_rules(),
        features_dropped: if output_format == OutputFormat::Ply {
            0
        } else {
            scene.feature_count
        },
    })
}

/// True when `a` and `b` name the same existing file (through links or `..`, too).
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
