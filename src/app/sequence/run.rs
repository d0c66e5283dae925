//! Running a plan: rendering its frames (one at a time, or several in flight) and encoding
//! and writing their files on worker threads, with the summary of what was done.

use super::plan::{FramePlan, SequenceError};
use super::progress::{Progress, ProgressStyle};
use crate::core::camera::Camera;
use crate::core::frame::{Frame, FramePixels, FrameSource};
use crate::io::output::{self, FileSpec};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Options of [`run`].
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Replace files that exist when they are written.
    pub overwrite: bool,
    /// Encoding threads; 0 encodes on the rendering thread (no overlap).
    pub encode_threads: usize,
    /// Rendered frames that may wait for a free encoder.
    pub queue_depth: usize,
    /// Progress display.
    pub progress: ProgressStyle,
    /// Resuming: a file that another process wrote while this run was going is kept and
    /// counted in [`Summary::appeared`], not an error.
    pub skip_existing: bool,
    /// Set (by a Ctrl-C / SIGTERM handler) to stop before the next frame: frames already
    /// rendered are written completely, and the summary says the run was interrupted.
    pub cancel: Option<Arc<AtomicBool>>,
    /// Frames in flight with [`run_pipelined`]: 2 submits frame `n + 1` before frame `n`
    /// is read back; 1 renders one frame at a time. [`run`] always renders one at a time.
    pub frames_in_flight: usize,
    /// Instead of their files, frames go to this sink (a video encoder): in path order,
    /// on the rendering thread ([`RunOptions::encode_threads`] does not apply).
    pub sink: Option<Arc<dyn FrameSink>>,
}

/// Takes a run's frames in path order instead of writing each to its files
/// ([`RunOptions::sink`]): [`crate::io::video::VideoWriter`].
pub trait FrameSink: Send + Sync + std::fmt::Debug {
    /// Takes the next frame (floats, or 8-bit colour when every output of the run is that:
    /// see [`super::plan::reads_rgb8_only`]).
    fn write(&self, frame: &FramePixels) -> Result<(), output::OutputError>;
}

impl FrameSink for crate::io::video::VideoWriter {
    fn write(&self, frame: &FramePixels) -> Result<(), output::OutputError> {
        crate::io::video::VideoWriter::write(self, frame)
    }
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            overwrite: false,
            encode_threads: default_encode_threads(),
            queue_depth: 2,
            progress: ProgressStyle::Auto,
            skip_existing: false,
            cancel: None,
            frames_in_flight: 1,
            sink: None,
        }
    }
}

/// Encoding threads by default: the available parallelism, at most 4.
pub fn default_encode_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(4)
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    /// Frames rendered and written.
    pub written: usize,
    /// Wall-clock seconds of the whole run.
    pub wall_s: f64,
    /// Seconds spent rendering (including the read-back).
    pub render_s: f64,
    /// Seconds spent encoding and writing, summed over threads.
    pub encode_s: f64,
    /// Files that appeared while the run was going (another process wrote them) and were
    /// kept, with [`RunOptions::skip_existing`].
    pub appeared: usize,
    /// The run stopped early because [`RunOptions::cancel`] was set.
    pub interrupted: bool,
}

impl Summary {
    /// Frames written per wall-clock second.
    pub fn frames_per_s(&self) -> f64 {
        self.written as f64 / self.wall_s.max(1e-9)
    }
}

/// Renders every planned frame with `render` and writes its files. With
/// `encode_threads > 0`, frames are encoded and written on worker threads while the next
/// frame renders (at most `queue_depth` rendered frames wait). The first error stops the
/// run: frames already handed to the encoders are finished, so every file on disk is
/// complete, and the error says how many frames were written. One frame is rendered at a
/// time ([`RunOptions::frames_in_flight`] does not apply; see [`run_pipelined`]).
pub fn run(
    frames: &[FramePlan],
    render: &mut dyn FnMut(&Camera) -> anyhow::Result<Frame>,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    run_each(frames, &mut |p| render(&p.camera), opts)
}

/// A closure given each whole [`FramePlan`] (its number too) as a [`FrameSource`]:
/// [`render_frames`] submits the frames in order, so the `n`-th submit is `frames[n]`.
struct EachPlan<'r> {
    frames: &'r [FramePlan],
    next: usize,
    render: &'r mut dyn FnMut(&FramePlan) -> anyhow::Result<Frame>,
    done: VecDeque<FramePixels>,
}

impl FrameSource for EachPlan<'_> {
    fn submit(&mut self, cam: &Camera) -> anyhow::Result<()> {
        let p = self
            .frames
            .get(self.next)
            .filter(|p| p.camera.name == cam.name)
            .ok_or_else(|| anyhow::anyhow!("frames were submitted out of order"))?;
        self.next += 1;
        let frame = (self.render)(p)?;
        self.done.push_back(FramePixels::Float(frame));
        Ok(())
    }

    fn finish(&mut self) -> anyhow::Result<FramePixels> {
        self.done
            .pop_front()
            .ok_or_else(|| anyhow::anyhow!("no frame was submitted"))
    }

    fn discard(&mut self) {
        self.done.clear();
    }
}

/// [`run`] with a renderer given the whole [`FramePlan`] of each frame, not only its
/// camera: for frames that differ by more than the camera (`render --time-range`, whose
/// frame `n` shows its own time).
pub fn run_each(
    frames: &[FramePlan],
    render: &mut dyn FnMut(&FramePlan) -> anyhow::Result<Frame>,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    let mut source = EachPlan {
        frames,
        next: 0,
        render,
        done: VecDeque::new(),
    };
    let opts = RunOptions {
        frames_in_flight: 1,
        ..opts.clone()
    };
    run_pipelined(frames, &mut source, &opts)
}

/// [`run`] with a renderer that keeps up to [`RunOptions::frames_in_flight`] frames in
/// flight: frame `n + 1` is submitted before frame `n` is finished (read back) and handed
/// to the encoders. Files, errors and their frame numbers are those of [`run`]: a frame
/// that fails to submit is reported after the frames before it are written.
pub fn run_pipelined(
    frames: &[FramePlan],
    source: &mut dyn FrameSource,
    opts: &RunOptions,
) -> Result<Summary, SequenceError> {
    let start = Instant::now();
    let mut progress = Progress::new(frames.len(), opts.progress);
    let mut summary = Summary::default();
    let mut failure: Option<SequenceError> = None;
    let overwrite = opts.overwrite;
    let skip_existing = opts.skip_existing;
    let write_all = |frame: &FramePixels, files: &[FileSpec]| -> Written {
        let t = Instant::now();
        let mut appeared = 0;
        if let Some(sink) = &opts.sink {
            sink.write(frame)?;
        }
        for f in files {
            match output::write_pixels(frame, f, overwrite) {
                // Another process (a parallel run of the same path) wrote it meanwhile.
                Err(output::OutputError::Exists(_)) if skip_existing => appeared += 1,
                other => other?,
            }
        }
        Ok((t.elapsed().as_secs_f64(), appeared))
    };
    // Counts a frame whose files were written, or keeps the first error.
    let mut record = |written: Written,
                      summary: &mut Summary,
                      failure: &mut Option<SequenceError>| {
        match written {
            Ok((encode_s, appeared)) => {
                summary.encode_s += encode_s;
                summary.appeared += appeared;
                summary.written += 1;
                progress.frame_done();
            }
            Err(e) => {
                failure.get_or_insert(e.into());
            }
        }
    };
    let depth = opts.frames_in_flight.max(1);
    // A sink takes the frames in order: they are handed over on this thread.
    if opts.encode_threads == 0 || opts.sink.is_some() {
        render_frames(
            frames,
            opts.cancel.as_deref(),
            depth,
            source,
            &mut summary,
            &mut failure,
            |frame, p, summary, failure| {
                record(write_all(&frame, &p.files), summary, failure);
            },
        );
    } else {
        let (job_tx, job_rx) = mpsc::sync_channel::<(FramePixels, Vec<FileSpec>)>(opts.queue_depth);
        let job_rx = Arc::new(Mutex::new(job_rx));
        let (done_tx, done_rx) = mpsc::channel::<Written>();
        std::thread::scope(|scope| {
            for _ in 0..opts.encode_threads {
                let job_rx = Arc::clone(&job_rx);
                let done_tx = done_tx.clone();
                let write_all = &write_all;
                scope.spawn(move || loop {
                    let job = job_rx.lock().unwrap_or_else(|e| e.into_inner()).recv();
                    let Ok((frame, files)) = job else {
                        break;
                    };
                    if done_tx.send(write_all(&frame, &files)).is_err() {
                        break;
                    }
                });
            }
            drop(done_tx);
            render_frames(
                frames,
                opts.cancel.as_deref(),
                depth,
                source,
                &mut summary,
                &mut failure,
                |frame, p, summary, failure| {
                    // A full queue blocks here until an encoder is free. The encoders only stop
                    // once the queue is closed, so the send succeeds.
                    let _ = job_tx.send((frame, p.files.clone()));
                    while let Ok(d) = done_rx.try_recv() {
                        record(d, summary, failure);
                    }
                },
            );
            drop(job_tx);
            // Let the encoders finish what they hold, so every frame handed over is complete.
            for d in done_rx.iter() {
                record(d, &mut summary, &mut failure);
            }
        });
    }
    progress.finish();
    if let Some(SequenceError::Render { written, .. }) = &mut failure {
        *written = summary.written;
    }
    summary.wall_s = start.elapsed().as_secs_f64();
    match failure {
        Some(e) => Err(e),
        None => Ok(summary),
    }
}

/// The outcome of writing one frame's files: seconds spent encoding and the files found
/// already written by another process, or the error.
type Written = Result<(f64, usize), output::OutputError>;

/// Renders `frames` in order, up to `depth` in flight, and hands each to `deliver` in
/// order, until the first render error or until `deliver` has recorded a failure.
fn render_frames(
    frames: &[FramePlan],
    cancel: Option<&AtomicBool>,
    depth: usize,
    source: &mut dyn FrameSource,
    summary: &mut Summary,
    failure: &mut Option<SequenceError>,
    mut deliver: impl FnMut(FramePixels, &FramePlan, &mut Summary, &mut Option<SequenceError>),
) {
    let render_error = |p: &FramePlan, e: anyhow::Error| SequenceError::Render {
        index: p.index,
        message: format!("{e:#}"),
        // Filled in once the frames handed over are written.
        written: 0,
    };
    let mut next = frames.iter();
    let mut in_flight: VecDeque<&FramePlan> = VecDeque::new();
    // A frame that failed to submit: reported once the frames before it are delivered.
    let mut submit_failure = None;
    let mut submitting = true;
    loop {
        while submitting && in_flight.len() < depth && failure.is_none() {
            if cancel.is_some_and(|c| c.load(Ordering::SeqCst)) {
                // Frames in flight are rendered already: they are finished and written.
                summary.interrupted = true;
                submitting = false;
                break;
            }
            let Some(p) = next.next() else {
                submitting = false;
                break;
            };
            let t = Instant::now();
            let submitted = source.submit(&p.camera);
            summary.render_s += t.elapsed().as_secs_f64();
            match submitted {
                Ok(()) => in_flight.push_back(p),
                Err(e) => {
                    submit_failure = Some(render_error(p, e));
                    submitting = false;
                }
            }
        }
        if failure.is_some() {
            break;
        }
        let Some(p) = in_flight.pop_front() else {
            break;
        };
        let t = Instant::now();
        let finished = source.finish();
        summary.render_s += t.elapsed().as_secs_f64();
        match finished {
            Ok(frame) => deliver(frame, p, summary, failure),
            Err(e) => {
                *failure = Some(render_error(p, e));
                break;
            }
        }
    }
    if !in_flight.is_empty() {
        source.discard();
    }
    if failure.is_none() {
        *failure = submit_failure;
    }
}
