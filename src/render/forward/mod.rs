//! The forward stages, in the order a frame records them: [`preprocess`] (cull, project,
//! conic, radius, tile rectangle, colour), [`order`] (the depth sort's keys and the pair
//! counts), [`keys`] (one key per (tile, Gaussian) pair), [`ranges`] (each tile's span of
//! the sorted pairs), [`blend`] (or [`features`] for feature channels) into the frame's
//! images, then [`shade`] (a neural shader's colour) and [`pack`] (8-bit RGBA for display).
//! [`types`] holds the records and push blocks the stages share with their shaders.
//!
//! Each stage is a pipeline built once and a `record` that takes the frame's buffers as a
//! bindings struct; the frame machinery ([`super::frame`]) decides what to record.

pub mod blend;
pub mod features;
pub mod keys;
pub mod order;
pub mod pack;
pub mod preprocess;
pub mod ranges;
pub mod shade;
pub mod types;
