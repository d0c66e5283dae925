//! GPU frames against the CPU reference: whole frames and each stage, every blend kernel,
//! chunked and pipelined frames, compact scenes, feature channels, gsplat's rules and every lens.

mod chunked_frames;
mod compact;
mod features;
mod frames;
mod gsplat_rules;
mod lenses;
mod pipelined;
mod stages;
