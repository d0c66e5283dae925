//! The Vulkan device behind a renderer or rasterizer: opening it and failing a call on
//! any message of the validation layer.

use crate::errors::py_err;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use verisplat::gpu::{ContextOptions, GpuContext};

/// Opens `device` (VERISPLAT_VALIDATE=1 also turns the validation layer on): the context,
/// the device's name and whether the validation layer is on.
pub(crate) fn open_context(
    device: Option<String>,
    validation: bool,
) -> PyResult<(GpuContext, String, bool)> {
    let ctx = GpuContext::new(&ContextOptions {
        device,
        validation,
        memory_limit: None,
        ..Default::default()
    })
    .map_err(|e| py_err(e.into()))?;
    let name = ctx.info().name.clone();
    let validation = ctx.validation_enabled();
    Ok((ctx, name, validation))
}

/// With the validation layer on, any message it printed fails the call.
pub(crate) fn check_validation(ctx: &GpuContext, on: bool) -> PyResult<()> {
    if on {
        let messages = ctx.validation_messages();
        if !messages.is_empty() {
            return Err(PyRuntimeError::new_err(format!(
                "the Vulkan validation layer reported {} message(s): {}",
                messages.len(),
                messages.join(" | ")
            )));
        }
    }
    Ok(())
}
