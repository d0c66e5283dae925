//! Training from images (the `vksplat train` issue), built on the differentiable
//! rasterizer ([`crate::render::differentiable`]). This module holds the pieces that
//! exist so far: the original 3DGS loss with its gradient, on the CPU (the reference) and
//! on the device ([`loss`]).

pub mod checkpoint;
pub mod data;
pub mod loss;
pub mod model;
pub mod run;
