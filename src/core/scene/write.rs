//! Scene writers and `verisplat convert`: load any format, transform, filter, write INRIA
//! PLY, `.splat` or SPZ v3 chosen by the output's extension, atomically.

use super::filter::SceneFilter;
use super::transform::SceneTransform;
use super::{ply, splat, spz, Scene, SceneError, SceneFormat};
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
}

impl OutputFormat {
    /// Chooses the writer from a file name's extension (`.ply`, `.splat`, `.spz`). A
    /// `.compressed.ply` name is refused rather than silently written as INRIA PLY: there
    /// is no compressed-PLY writer.
    pub fn from_path(path: &Path) -> Result<OutputFormat, ConvertError> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if name.ends_with(".compressed.ply") {
            return Err(ConvertError::Unsupported {
                path: path.to_path_buf(),
                message: "writing PlayCanvas compressed PLY is not supported; name the output .ply (INRIA, lossless), .splat or .spz".into(),
            });
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
            _ => Err(ConvertError::UnknownFormat(path.to_path_buf())),
        }
    }
}

impl OutputFormat {
    /// The highest SH degree the format stores (`.splat` keeps only the DC colour).
    pub fn max_sh_degree(self) -> u32 {
        match self {
            OutputFormat::Ply | OutputFormat::Spz => 3,
            OutputFormat::Splat => 0,
        }
    }
}

impl std::fmt::Display for OutputFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OutputFormat::Ply => "INRIA PLY (binary little-endian)",
            OutputFormat::Splat => "antimatter15 .splat",
            OutputFormat::Spz => "SPZ v3 (gzip)",
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
    #[error("{0}: unknown output format; use a .ply, .splat or .spz file name")]
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
    }
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
    /// Bytes written.
    pub bytes: usize,
    /// The input records antialiased training but the output format cannot say so.
    pub antialiased_flag_lost: bool,
    /// The input records a non-Gaussian kernel (`cpu::SplatKernel`) that the output format
    /// cannot record (only PLY can).
    pub kernel_lost: Option<crate::core::model::SplatKernel>,
    /// The input records gsplat's rules (`model::Rules`), which the output format cannot
    /// record (only PLY can).
    pub rules_lost: Option<crate::core::model::Rules>,
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
    let bytes = if raw && output_format == OutputFormat::Spz {
        let mut turned = filtered.clone();
        spz::flip_rub(&mut turned);
        to_bytes(&turned, output_format)
    } else {
        to_bytes(&filtered, output_format)
    };
    let bytes = bytes.map_err(|message| ConvertError::Encode {
        path: output.to_path_buf(),
        format: output_format,
        message,
    })?;
    fsutil::write_bytes_atomically(output, options.overwrite, &bytes)?;
    Ok(ConvertReport {
        input_format,
        output_format,
        read,
        written: filtered.len(),
        sh_degree: filtered.sh_degree.min(output_format.max_sh_degree()),
        sh_dropped_from: (filtered.sh_degree > output_format.max_sh_degree())
            .then_some(filtered.sh_degree),
        bytes: bytes.len(),
        antialiased_flag_lost: scene.antialiased && output_format != OutputFormat::Spz,
        kernel_lost: (scene.kernel != crate::core::model::SplatKernel::Gaussian
            && output_format != OutputFormat::Ply)
            .then_some(scene.kernel),
        rules_lost: (scene.rules != crate::core::model::Rules::Original
            && output_format != OutputFormat::Ply)
            .then_some(scene.rules),
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
