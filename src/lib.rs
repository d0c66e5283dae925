//! vksplat: a 3D Gaussian Splatting renderer on raw Vulkan compute, with an exact CPU reference.
pub mod gpu;
