//! Training from images (`verisplat train`): the original 3DGS method on the differentiable
//! rasterizer. The data sets ([`data`]), the loss on the CPU (the reference) and on the
//! device ([`loss`]), the model with its optimiser and density control ([`model`]), the
//! model's state kept on the device between iterations ([`device`]), the loop ([`run`])
//! and its checkpoints ([`checkpoint`]); the per-photo appearance
//! ([`appearance`], `--appearance affine`).

pub mod appearance;
pub mod checkpoint;
pub mod data;
pub mod device;
pub mod loss;
pub mod masks;
pub mod model;
pub mod run;
/// The train wing's shaders: their named bindings and variants (`glsl/train/`).
pub mod shaders;
pub mod undistort;
