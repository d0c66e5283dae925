//! The renderer's rule constants as module attributes (`verisplat._native.NEAR_PLANE`, ...),
//! so that the package's Python (`_projection.py`, `torch.py`, `raster.py`, `_scene.py`)
//! takes each number from the crate that renders with it instead of a copy.
//!
//! An `f32` crosses as the shortest decimal that rounds back to it, the digits its source
//! spells (0.3, not 0.30000001192092896): a Python float that numpy and torch round to the
//! crate's `f32` exactly, and that compares equal to the same literal a caller writes
//! (gsplat's `eps2d=0.3`).

use pyo3::prelude::*;
use pyo3::types::PyTuple;
use verisplat::core::model::sh::{SH_C0, SH_C1, SH_C2, SH_C3};
use verisplat::core::rules::{
    ALPHA_MAX, ALPHA_MIN, ANTIALIAS_MIN_RATIO, COV2D_DILATION, GSPLAT_ALPHA_MAX, GSPLAT_EXTEND,
    GSPLAT_NEAR_PLANE, NEAR_PLANE, TILE_SIZE, T_MIN,
};

/// `x` as the shortest decimal that rounds back to it (Rust's `Display` of an `f32`).
fn decimal(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// Adds the constants to the module `m`.
pub(crate) fn add_constants(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let floats = [
        ("NEAR_PLANE", NEAR_PLANE),
        ("COV2D_DILATION", COV2D_DILATION),
        ("ANTIALIAS_MIN_RATIO", ANTIALIAS_MIN_RATIO),
        ("ALPHA_MAX", ALPHA_MAX),
        ("ALPHA_MIN", ALPHA_MIN),
        ("T_MIN", T_MIN),
        ("GSPLAT_NEAR_PLANE", GSPLAT_NEAR_PLANE),
        ("GSPLAT_ALPHA_MAX", GSPLAT_ALPHA_MAX),
        ("GSPLAT_EXTEND", GSPLAT_EXTEND),
        ("SH_C0", SH_C0),
        ("SH_C1", SH_C1),
    ];
    for (name, value) in floats {
        m.add(name, decimal(value))?;
    }
    let py = m.py();
    m.add("SH_C2", PyTuple::new(py, SH_C2.map(decimal))?)?;
    m.add("SH_C3", PyTuple::new(py, SH_C3.map(decimal))?)?;
    m.add("TILE_SIZE", TILE_SIZE)?;
    // Direct colour channels one backward pass on the device differentiates at most.
    let groups = verisplat::gpu::shader_set::MAX_FEATURE_GROUPS as usize;
    m.add(
        "BACKWARD_CHANNELS",
        groups * verisplat::render::forward::features::CHANNELS_PER_GROUP,
    )?;
    m.add("MAX_FEATURES", verisplat::core::scene::MAX_FEATURES)?;
    Ok(())
}
