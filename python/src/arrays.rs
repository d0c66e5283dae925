//! Arrays as they cross the boundary: little-endian `f32` bytes to vectors and rows,
//! vectors back to `bytearray`s, and the check that every value is finite.

use crate::errors::value_err;
use pyo3::prelude::*;
use pyo3::types::PyByteArray;

pub(crate) fn floats(bytes: &[u8], what: &str, count: usize) -> PyResult<Vec<f32>> {
    if bytes.len() != count * 4 {
        return Err(value_err(format!(
            "{what}: expected {count} float32 values, got {} bytes",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

pub(crate) fn rows<const N: usize>(v: &[f32]) -> Vec<[f32; N]> {
    v.chunks_exact(N)
        .map(|c| std::array::from_fn(|i| c[i]))
        .collect()
}

pub(crate) fn byte_array<'py, T: bytemuck::Pod>(
    py: Python<'py>,
    v: &[T],
) -> Bound<'py, PyByteArray> {
    PyByteArray::new(py, bytemuck::cast_slice(v))
}

pub(crate) fn check_finite(name: &str, v: &[f32], per: usize) -> PyResult<()> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(value_err(format!(
            "{name}[{}] is {}; every value must be finite",
            i / per.max(1),
            v[i]
        )));
    }
    Ok(())
}
