//! Stopping a run by Ctrl-C or SIGTERM: the flag a signal sets and the error that ends
//! the command with status 130.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// The render was stopped by Ctrl-C or SIGTERM; `main` prints the message without
/// "error:" and exits with status 130.
#[derive(Debug)]
pub(crate) struct Interrupted(pub(crate) String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// A flag set by the first Ctrl-C or SIGTERM, so a path stops after the frames in hand
/// are written completely; a second signal ends the process at once.
pub(crate) fn interrupt_flag() -> Arc<AtomicBool> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [SIGINT, SIGTERM] {
        // Registered first, so it sees the flag as the previous signal left it.
        let _ = signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&flag));
        let _ = signal_hook::flag::register(signal, Arc::clone(&flag));
    }
    flag
}
