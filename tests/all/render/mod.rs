//! GPU frames against the CPU reference: whole frames and each stage, every blend kernel,
//! chunked and pipelined frames, compact scenes, feature channels and gsplat's rules.

mod chunked_frames;
mod compact;
mod features;
mod frames;
mod gsplat_rules;
mod pipelined;
mod stages;
