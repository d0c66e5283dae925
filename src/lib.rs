//! verisplat: a 3D Gaussian Splatting renderer on raw Vulkan compute, with an exact CPU
//! reference renderer that the GPU is checked against.
//!
//! The crate in wings, each using only the wings before it (`tools/module_graph.py
//! --wings` checks it; docs/module-graph.md):
//! [`core`] (the splat model, rules, cameras, scenes, frames, the shader interface) <
//! [`io`] (image files in and out, outputs, image metrics) < [`fields`] (feature fields,
//! RF fits, the MLP) < [`cpu`] (the CPU reference) < [`gpu`] (Vulkan building blocks) <
//! [`render`] (the GPU splatting pipeline) < [`train`] < [`app`] (bench, doctor, viewer,
//! sequences, shards; the command line is the binary's, in `src/cli/`).

pub mod app;
pub mod core;
pub mod cpu;
pub mod fields;
pub mod gpu;
pub mod io;
pub mod render;
pub mod train;
