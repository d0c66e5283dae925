//! NumPy `.npy` arrays of floats, read for feature channels (scenes), sampled fields
//! (fits) and images (`io::image_file`).

use crate::core::file_error::FileError;
use std::path::Path;

fn invalid(path: &Path, message: impl Into<String>) -> FileError {
    FileError::invalid(path, message)
}

/// A NumPy array of floats read by [`parse_npy_array`]: its shape and its values in C
/// order, converted to f32.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The array's shape.
    pub shape: Vec<usize>,
    /// `shape.iter().product()` values, C order.
    pub data: Vec<f32>,
}

/// Reads a NumPy `.npy` array of float32, float16 or float64 (little-endian, C order) of
/// any shape; errors name the file.
pub fn parse_npy_array(bytes: &[u8], path: &Path) -> Result<NpyArray, FileError> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(invalid(
            path,
            "is not a NumPy .npy file (no \\x93NUMPY magic)",
        ));
    }
    let major = bytes[6];
    let (header_len, start) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10usize),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        _ => {
            return Err(invalid(
                path,
                format!(
                    "has .npy format version {major}, which this reader does not know (1, 2 or 3)"
                ),
            ))
        }
    };
    let header = bytes
        .get(start..start.saturating_add(header_len))
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| invalid(path, "has a truncated or non-text .npy header"))?;
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))? + key.len() + 2;
        let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
        Some(rest)
    };
    let descr = field("descr")
        .and_then(|r| r.strip_prefix('\''))
        .and_then(|r| r.split('\'').next())
        .ok_or_else(|| invalid(path, "has no 'descr' (dtype) in its .npy header"))?;
    if field("fortran_order").is_some_and(|r| r.starts_with("True")) {
        return Err(invalid(
            path,
            "is stored in Fortran order; save it in C order (numpy.ascontiguousarray)",
        ));
    }
    let shape: Vec<usize> = field("shape")
        .and_then(|r| r.strip_prefix('('))
        .and_then(|r| r.split(')').next())
        .map(|s| {
            s.split(',')
                .map(str::trim)
                .filter(|t| !t.is_empty())
                .map(|t| t.parse::<usize>())
                .collect::<Result<Vec<_>, _>>()
        })
        .and_then(Result::ok)
        .ok_or_else(|| invalid(path, "has no readable 'shape' in its .npy header"))?;
    let size = match descr {
        "<f4" => 4,
        "<f2" => 2,
        "<f8" => 8,
        other => {
            return Err(invalid(
                path,
                format!(
                    "holds dtype '{other}'; verisplat reads little-endian float32, float16 or float64 arrays (<f4, <f2, <f8)"
                ),
            ))
        }
    };
    let count = shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| invalid(path, format!("has an unusable shape {shape:?}")))?;
    let data = &bytes[start + header_len..];
    if count.checked_mul(size) != Some(data.len()) {
        return Err(invalid(
            path,
            format!(
                "holds {} bytes of data where shape {shape:?} of {descr} needs {}",
                data.len(),
                count as u128 * size as u128
            ),
        ));
    }
    let data: Vec<f32> = match size {
        4 => data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        2 => data
            .chunks_exact(2)
            .map(|b| exr::prelude::f16::from_bits(u16::from_le_bytes([b[0], b[1]])).to_f32())
            .collect(),
        _ => data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])) as f32)
            .collect(),
    };
    Ok(NpyArray { shape, data })
}
