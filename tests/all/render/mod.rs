//! GPU frames against the CPU reference: whole frames and each stage, every blend kernel,
//! chunked and pipelined frames, compact scenes, feature channels, gsplat's rules, every lens
//! and the surface passes (normals, median depth).

mod chunked_frames;
mod compact;
mod features;
mod frames;
mod gsplat_rules;
mod lenses;
mod passes;
mod pipelined;
mod reproducible;
mod rgb8_readback;
mod stages;
