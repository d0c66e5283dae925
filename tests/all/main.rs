//! The integration tests, in one test binary (the library is linked once, not once per
//! file), grouped in folders by the layer they test, lowest first:
//!
//! - `core`: scene transforms and the default camera;
//! - `reference`: the CPU reference renderer on its own (closed forms, gsplat's rules);
//! - `gpu`: the Vulkan layer (context, sort and scan, shader interface, limits, discrete-GPU
//!   semantics, memory over long runs);
//! - `render`: GPU frames and stages against the CPU reference;
//! - `train`: gradients, the loss and `train`;
//! - `fields`: `fit`, RF fields, the neural shader, time-varying fields;
//! - `io`: scene and camera files, malformed input, image outputs;
//! - `app`: the command line, the viewer, `doctor`, `compare`, sequences, shards, the docs'
//!   examples and the repository's own rules.
//!
//! Run one folder or one module with its path: `cargo test --test all render::` or
//! `cargo test --test all render::frames::`. `common` holds the helpers they share (scenes,
//! orbit cameras, the GPU-vs-CPU thresholds, running the binary, the viewer client).
//!
//! The tests share one process and run in parallel threads: a test must not change
//! process-wide state (environment variables, the current directory), and one that
//! measures the process (`gpu::memory`) runs itself in a process of its own.

mod common;

mod app;
mod core;
mod fields;
mod gpu;
mod io;
mod reference;
mod render;
mod train;
