//! Console output that never panics.
//!
//! `println!`/`eprintln!` panic when the stream is closed (`verisplat info scene.ply | head`
//! closes stdout after ten lines). A closed pipe is normal use of a command-line tool, so
//! [`outln!`] stops writing to stdout quietly and lets the command finish its work (a
//! `bench --json` piped into `head` still writes its JSON). Any other stdout error (a full
//! disk behind a redirect) is remembered and reported by [`stdout_error`] at the end.
//! [`note!`] writes to stderr and ignores errors: there is nowhere left to report them.

use std::fmt;
use std::io::{ErrorKind, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);
static STDOUT_ERROR: Mutex<Option<String>> = Mutex::new(None);

/// Writes formatted text to stdout (used by [`out!`] and [`outln!`]).
pub fn write_stdout(args: fmt::Arguments) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|_| out.flush()) {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != ErrorKind::BrokenPipe {
            if let Ok(mut slot) = STDOUT_ERROR.lock() {
                slot.get_or_insert_with(|| e.to_string());
            }
        }
    }
}

/// Writes formatted text to stderr, ignoring errors (used by [`note!`]).
pub fn write_stderr(args: fmt::Arguments) {
    let _ = std::io::stderr().lock().write_fmt(args);
}

/// The first stdout error other than a closed pipe, if any happened.
pub fn stdout_error() -> Option<String> {
    STDOUT_ERROR.lock().ok().and_then(|slot| slot.clone())
}

/// True once stdout was found closed (or failed): further output is dropped.
pub fn stdout_closed() -> bool {
    STDOUT_CLOSED.load(Ordering::Relaxed)
}

// `#[macro_export]` puts a `macro_rules!` macro at the crate root whatever its file, so the
// macros are exported under hidden names and named by this module's path
// (`crate::core::console::note!`, `verisplat::core::console::note!`): nothing in a wing
// reaches up to the crate root for them (`tools/module_graph.py --wings` checks it).

/// `print!` that stops quietly when stdout is closed.
#[doc(hidden)]
#[macro_export]
macro_rules! __console_out {
    ($($arg:tt)*) => { $crate::core::console::write_stdout(format_args!($($arg)*)) };
}

/// `println!` that stops quietly when stdout is closed.
#[doc(hidden)]
#[macro_export]
macro_rules! __console_outln {
    () => { $crate::core::console::write_stdout(format_args!("\n")) };
    ($($arg:tt)*) => { $crate::core::console::write_stdout(format_args!("{}\n", format_args!($($arg)*))) };
}

/// `eprintln!` that never panics.
#[doc(hidden)]
#[macro_export]
macro_rules! __console_note {
    () => { $crate::core::console::write_stderr(format_args!("\n")) };
    ($($arg:tt)*) => { $crate::core::console::write_stderr(format_args!("{}\n", format_args!($($arg)*))) };
}

// The macros' names (their documentation is the macros' own, shown here).
#[doc(inline)]
pub use crate::__console_note as note;
#[doc(inline)]
pub use crate::__console_out as out;
#[doc(inline)]
pub use crate::__console_outln as outln;

/// An error as one sentence: the outermost message with each cause appended that it
/// does not already contain (`context: cause: cause`).
pub fn error_sentence(e: &anyhow::Error) -> String {
    let mut s = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !s.contains(&c) {
            s.push_str(": ");
            s.push_str(&c);
        }
    }
    s
}
