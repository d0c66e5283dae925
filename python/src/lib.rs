//! `verisplat._native`: the Rust side of the Python package.
//!
//! The public API is the Python package `verisplat` (python/verisplat/), which turns numpy
//! arrays into the little-endian `f32` bytes this module takes and wraps the bytes it
//! returns as arrays. Arrays cross as bytes so the module needs nothing beyond
//! the stable ABI (one wheel for every CPython >= 3.9). Everything long-running releases
//! the GIL; every error becomes a Python exception carrying the sentence the command line
//! prints; a panic is caught and raised as `RuntimeError`, never unwound into Python.

mod arrays;
mod cameras;
mod device;
mod differentiable;
mod errors;
mod fit;
mod images;
mod reference;
mod render;
mod rules;
mod scene;
mod shader;

use pyo3::prelude::*;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<scene::PyScene>()?;
    m.add_class::<render::PyRenderer>()?;
    m.add_class::<differentiable::PyRasterizer>()?;
    m.add_function(wrap_pyfunction!(reference::reference_forward, m)?)?;
    m.add_function(wrap_pyfunction!(reference::reference_backward, m)?)?;
    m.add_function(wrap_pyfunction!(shader::shader_from_layers, m)?)?;
    m.add_function(wrap_pyfunction!(shader::shader_file, m)?)?;
    m.add_function(wrap_pyfunction!(shader::shader_layers, m)?)?;
    m.add_function(wrap_pyfunction!(scene::load, m)?)?;
    m.add_function(wrap_pyfunction!(scene::demo, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_function(wrap_pyfunction!(scene::scene_from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::load_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::save_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::orbit, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::default_camera, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::look_at, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::bulk_centre, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::fisheye_max_theta, m)?)?;
    m.add_function(wrap_pyfunction!(cameras::check_lens, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_cpu, m)?)?;
    m.add_function(wrap_pyfunction!(images::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(images::compare, m)?)?;
    m.add_function(wrap_pyfunction!(images::encode_png, m)?)?;
    m.add_function(wrap_pyfunction!(images::save_image, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    rules::add_constants(m)?;
    Ok(())
}
