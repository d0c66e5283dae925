//! Rendering a camera path to a sequence of image files: output name patterns, frame
//! ranges, resuming, atomic writes, a progress display, and encoding on worker threads
//! that overlaps the rendering of the next frame.
//!
//! Frame `k` of a path is always written to the same file name whatever part of the path
//! a run covers, so a path split into `--frames` ranges across machines gives exactly the
//! files of one run, and `--skip-existing` resumes an interrupted run. Every file is
//! written to a temporary file and renamed, so an interrupted run never leaves a
//! truncated frame; the temporaries a killed run leaves behind are removed on the next.

//!
//! The rooms: output name patterns (`pattern`), frame selections (`selection`), the plan
//! of a run and its checks on disk (`plan`), the progress display (`progress`) and the
//! run itself, rendering and encoding (`run`).

mod pattern;
mod plan;
mod progress;
mod run;
mod selection;

pub use crate::core::frame::FrameSource;
pub use pattern::{file_safe_name, names_directory, OutputPattern};
pub use plan::{
    plan, plan_frames, prepare, reads_rgb8_only, remove_stale_temporaries_of, verify, Existing,
    FramePlan, Plan, Problem, SequenceError,
};
pub use progress::ProgressStyle;
pub use run::{
    default_encode_threads, run, run_each, run_pipelined, FrameSink, RunOptions, Summary,
};
pub use selection::FrameSelection;
