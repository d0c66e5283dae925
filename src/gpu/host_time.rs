//! Where the host's time goes around the device: recording command buffers, handing them
//! to the queue and waiting for them. On a CPU device the waits are the device's work; on
//! a real GPU they are the idle host, and what is neither is the host's own work, which a
//! GPU waits through (the first H200 run, BENCHMARKS.md: 2.3 ms of device time in 9.4 ms
//! of a training iteration). Every submission of a [`super::GpuContext`] is counted here.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The running totals (nanoseconds) of one context.
#[derive(Debug, Default)]
pub struct HostClock {
    submissions: AtomicU64,
    record_ns: AtomicU64,
    submit_ns: AtomicU64,
    wait_ns: AtomicU64,
}

/// The totals at one moment; [`HostTime::since`] makes an interval of two.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct HostTime {
    /// Command buffers submitted.
    pub submissions: u64,
    /// Milliseconds spent recording them (from begin to end of the command buffer).
    pub record_ms: f64,
    /// Milliseconds in vkQueueSubmit2.
    pub submit_ms: f64,
    /// Milliseconds waiting for fences.
    pub wait_ms: f64,
}

fn ns(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

impl HostClock {
    /// Adds a submission's recording time (from `start`, now ending) and counts it.
    pub(crate) fn recorded(&self, start: Instant) {
        self.submissions.fetch_add(1, Ordering::Relaxed);
        self.record_ns
            .fetch_add(ns(start.elapsed()), Ordering::Relaxed);
    }

    /// Adds time in vkQueueSubmit2 (from `start`, now ending).
    pub(crate) fn submitted(&self, start: Instant) {
        self.submit_ns
            .fetch_add(ns(start.elapsed()), Ordering::Relaxed);
    }

    /// Adds time waiting for a fence (from `start`, now ending).
    pub(crate) fn waited(&self, start: Instant) {
        self.wait_ns
            .fetch_add(ns(start.elapsed()), Ordering::Relaxed);
    }

    /// The totals now.
    pub fn now(&self) -> HostTime {
        let ms = |a: &AtomicU64| a.load(Ordering::Relaxed) as f64 / 1e6;
        HostTime {
            submissions: self.submissions.load(Ordering::Relaxed),
            record_ms: ms(&self.record_ns),
            submit_ms: ms(&self.submit_ns),
            wait_ms: ms(&self.wait_ns),
        }
    }
}

impl std::ops::AddAssign for HostTime {
    fn add_assign(&mut self, d: HostTime) {
        self.submissions += d.submissions;
        self.record_ms += d.record_ms;
        self.submit_ms += d.submit_ms;
        self.wait_ms += d.wait_ms;
    }
}

impl HostTime {
    /// The interval from `earlier` to `self`.
    pub fn since(&self, earlier: &HostTime) -> HostTime {
        HostTime {
            submissions: self.submissions.saturating_sub(earlier.submissions),
            record_ms: self.record_ms - earlier.record_ms,
            submit_ms: self.submit_ms - earlier.submit_ms,
            wait_ms: self.wait_ms - earlier.wait_ms,
        }
    }

    /// Every figure divided by `n` (a mean per iteration or frame; `n` of 0 counts as 1).
    pub fn per(&self, n: u64) -> HostTime {
        let d = n.max(1) as f64;
        HostTime {
            submissions: self.submissions / n.max(1),
            record_ms: self.record_ms / d,
            submit_ms: self.submit_ms / d,
            wait_ms: self.wait_ms / d,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_and_means() {
        let c = HostClock::default();
        let t0 = c.now();
        let start = Instant::now();
        std::thread::sleep(Duration::from_millis(2));
        c.recorded(start);
        c.waited(start);
        let d = c.now().since(&t0);
        assert_eq!(d.submissions, 1);
        assert!(d.record_ms >= 2.0 && d.wait_ms >= d.record_ms, "{d:?}");
        assert_eq!(d.submit_ms, 0.0);
        let half = d.per(2);
        assert_eq!(half.submissions, 0);
        assert!((half.record_ms - d.record_ms / 2.0).abs() < 1e-12);
    }
}
