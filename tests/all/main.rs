//! The integration tests, in one test binary (the library is linked once, not once per
//! file). Each module is a group of tests that was its own `tests/<name>.rs`; run one
//! group with `cargo test --test all <name>::` (e.g. `cargo test --test all gpu_frames::`).
//! `common` and `view_common` are the helpers they share.
//!
//! The tests share one process and run in parallel threads: a test must not change
//! process-wide state (environment variables, the current directory), and one that
//! measures the process (`gpu_memory`) runs itself in a process of its own.

mod common;
mod view_common;

mod camera_sources;
mod chunked_frames;
mod cli;
mod cli_defects;
mod compact;
mod compare;
mod discrete;
mod doc_examples;
mod doctor;
mod features;
mod field_renders;
mod fit;
mod fit_inputs;
mod formats;
mod former_name;
mod fuzz_regressions;
mod gpu_frames;
mod gpu_memory;
mod gpu_sort;
mod gpu_stages;
mod gradients;
mod gsplat_rules;
mod house;
mod limits;
mod loss;
mod malformed;
mod mlp;
mod output;
mod output_compositing;
mod pipelined;
mod ply_loader;
mod real_scenes;
mod reference_renderer;
mod rf_usability;
mod rf_walkthrough;
mod sequences;
mod shader_interface;
mod shards;
mod time_fields;
mod train;
mod train_captures;
mod transform;
mod undistort;
mod view;
mod view_browser;
