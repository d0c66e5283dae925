//! The library's core, below any renderer: scene transforms and the default camera.

mod cameras;
mod transforms;
