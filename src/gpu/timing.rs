//! Per-stage GPU timestamps and debug labels, recorded by one helper.
//!
//! Timestamps count ticks of `timestampPeriod` nanoseconds in `timestampValidBits` bits
//! of the compute queue ([`TimestampClock`]). A counter of fewer than 64 bits wraps:
//! durations are taken modulo 2^bits, which undoes one wrap between two timestamps, but
//! a duration as long as the wrap period or longer cannot be told from a shorter one.
//! So a reading counts only when the host saw the whole submission (from the timer's
//! reset while recording to the read after the fence) take less than one wrap period;
//! otherwise the timer reports [`Untimed::WrapTooShort`] and its stages as untimed,
//! never a wrong number. Without timestamps (0 valid bits) it reports
//! [`Untimed::NoTimestamps`]. Under `VERISPLAT_EMULATE=timestamp-bits=N` the counter also
//! starts at the worst phase: it wraps in the middle of each reading's span, so the
//! wrap-around path runs in every emulated reading.

use std::ffi::CString;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::device::Shared;
use super::{DeviceInfo, GpuContext, GpuError, GpuResult, VkContext};

/// What a device's timestamps measure: valid bits and nanoseconds per tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimestampClock {
    /// timestampValidBits of the compute queue (0: no timestamps).
    pub valid_bits: u32,
    /// timestampPeriod: nanoseconds per tick.
    pub period_ns: f64,
}

impl TimestampClock {
    /// The clock of `info`'s device (with its emulated valid bits).
    pub fn of(info: &DeviceInfo) -> Self {
        TimestampClock {
            valid_bits: info.timestamp_valid_bits.min(64),
            period_ns: f64::from(info.timestamp_period_ns),
        }
    }

    /// Whether timestamps can be written at all.
    pub fn available(&self) -> bool {
        self.valid_bits > 0 && self.period_ns > 0.0
    }

    /// The valid bits of a raw timestamp.
    pub fn mask(&self) -> u64 {
        match self.valid_bits {
            0 => 0,
            b if b >= 64 => u64::MAX,
            b => (1u64 << b) - 1,
        }
    }

    /// Nanoseconds after which the counter wraps to 0.
    pub fn wrap_ns(&self) -> f64 {
        2f64.powi(self.valid_bits as i32) * self.period_ns
    }

    /// Ticks from `begin` to `end` (raw timestamps): masked, and one wrap between them
    /// undone (`end < begin` after masking adds 2^bits).
    pub fn ticks_between(&self, begin: u64, end: u64) -> u64 {
        let m = self.mask();
        (end & m).wrapping_sub(begin & m) & m
    }

    /// Milliseconds of `ticks`.
    pub fn ms(&self, ticks: u64) -> f64 {
        ticks as f64 * self.period_ns / 1e6
    }
}

/// Why a reading has no durations.
#[derive(Clone, Debug, PartialEq)]
pub enum Untimed {
    /// The device writes no timestamps on its compute queue (0 valid bits).
    NoTimestamps,
    /// The counter wraps sooner than the submission took, so durations are ambiguous.
    WrapTooShort {
        /// timestampValidBits.
        bits: u32,
        /// Milliseconds from one wrap to the next.
        wrap_ms: f64,
        /// Host milliseconds from recording to reading, which bound the GPU's.
        elapsed_ms: f64,
    },
}

impl std::fmt::Display for Untimed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Untimed::NoTimestamps => write!(
                f,
                "this device writes no timestamps on its compute queue (timestampValidBits = 0): GPU stage times are not measured"
            ),
            Untimed::WrapTooShort {
                bits,
                wrap_ms,
                elapsed_ms,
            } => write!(
                f,
                "this device's timestamps have {bits} valid bits and wrap every {wrap_ms:.6} ms, but the work took up to {elapsed_ms:.3} ms: its GPU stage times cannot be measured and are not reported"
            ),
        }
    }
}

/// The durations of a finished recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Reading {
    /// Each stage's name and milliseconds, in recording order.
    pub stages: Vec<(String, f64)>,
    /// Milliseconds from the first stage's start to the last stage's end.
    pub span_ms: f64,
    /// The masked counter wrapped between the first and last timestamp (and the wrap was
    /// undone).
    pub wrapped: bool,
}

/// A timestamp query pool recording one begin/end pair per named stage.
pub struct GpuTimer {
    shared: Arc<Shared>,
    pool: vk::QueryPool,
    capacity: u32,
    stages: Vec<String>,
    clock: TimestampClock,
    /// The emulated counter wraps mid-reading ([`super::emulate`]'s `timestamp-bits`).
    worst_phase: bool,
    /// When the current recording began ([`Self::reset`]): the host's bound on how long
    /// its work took.
    recorded_at: Option<Instant>,
    /// The stage [`Self::begin`] opened and [`Self::end`] has not closed: its name and
    /// whether it writes timestamps.
    open: Option<(String, bool)>,
}

impl GpuTimer {
    /// A timer for up to `max_stages` stages per recording.
    pub fn new(ctx: &GpuContext, name: &str, max_stages: u32) -> GpuResult<Self> {
        let capacity = max_stages.max(1) * 2;
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(capacity);
        // SAFETY: valid create info; destroyed in Drop.
        let pool =
            unsafe { ctx.device().create_query_pool(&info, None) }.vk("vkCreateQueryPool")?;
        ctx.set_name(pool, name);
        Ok(Self {
            shared: ctx.shared.clone(),
            pool,
            capacity,
            stages: Vec::new(),
            open: None,
            clock: TimestampClock::of(ctx.info()),
            worst_phase: ctx.info().emulation.timestamp_bits.is_some(),
            recorded_at: None,
        })
    }

    /// Starts a new recording: forgets old stages and resets the pool inside `cmd`.
    pub fn reset(&mut self, ctx: &GpuContext, cmd: vk::CommandBuffer) {
        self.stages.clear();
        self.open = None;
        self.recorded_at = Some(Instant::now());
        // SAFETY: cmd is recording outside a render pass; the range is within the pool.
        unsafe {
            ctx.device()
                .cmd_reset_query_pool(cmd, self.pool, 0, self.capacity)
        };
    }

    /// Records `body` between a debug label and a timestamp pair named `name`.
    /// Without timestamp support only the label is recorded; a stage past the timer's
    /// capacity is an error ([`GpuError::Internal`]), never silently untimed.
    pub fn stage<R>(
        &mut self,
        ctx: &GpuContext,
        cmd: vk::CommandBuffer,
        name: &str,
        body: impl FnOnce(vk::CommandBuffer) -> GpuResult<R>,
    ) -> GpuResult<R> {
        self.begin(ctx, cmd, name)?;
        let result = body(cmd);
        self.end(ctx, cmd)?;
        result
    }

    /// Opens stage `name` in `cmd`: its debug label and first timestamp. What is recorded
    /// until [`Self::end`] is the stage ([`Self::stage`] around a body).
    pub fn begin(&mut self, ctx: &GpuContext, cmd: vk::CommandBuffer, name: &str) -> GpuResult<()> {
        if let Some((open, _)) = &self.open {
            return Err(GpuError::Internal(format!(
                "stage {name} begun inside stage {open}"
            )));
        }
        let label = CString::new(name)
            .map_err(|_| GpuError::InvalidArgument(format!("stage name {name:?} has a NUL")))?;
        let index = self.stages.len() as u32 * 2;
        if index + 1 >= self.capacity {
            // A stage would go untimed: the owner sized the timer for fewer stages than it
            // records.
            return Err(GpuError::Internal(format!(
                "a timer of {} stages cannot time stage {} ({name})",
                self.capacity / 2,
                self.stages.len() + 1
            )));
        }
        if let Some(debug) = self.shared.debug_device.as_ref() {
            let info = vk::DebugUtilsLabelEXT::default().label_name(&label);
            // SAFETY: cmd is recording; the label outlives the call.
            unsafe { debug.cmd_begin_debug_utils_label(cmd, &info) };
        }
        let timed = self.clock.available();
        if timed {
            // SAFETY: query `index` was reset by `reset` in this command buffer.
            unsafe {
                ctx.device().cmd_write_timestamp2(
                    cmd,
                    vk::PipelineStageFlags2::ALL_COMMANDS,
                    self.pool,
                    index,
                )
            };
        }
        self.open = Some((name.to_string(), timed));
        Ok(())
    }

    /// Closes the stage [`Self::begin`] opened: its second timestamp and the label's end.
    pub fn end(&mut self, ctx: &GpuContext, cmd: vk::CommandBuffer) -> GpuResult<()> {
        let (name, timed) = self
            .open
            .take()
            .ok_or_else(|| GpuError::Internal("a stage ended that was not begun".into()))?;
        let index = self.stages.len() as u32 * 2;
        if timed {
            // SAFETY: as in `begin` for query `index + 1`.
            unsafe {
                ctx.device().cmd_write_timestamp2(
                    cmd,
                    vk::PipelineStageFlags2::ALL_COMMANDS,
                    self.pool,
                    index + 1,
                )
            };
        }
        self.stages.push(name);
        if let Some(debug) = self.shared.debug_device.as_ref() {
            // SAFETY: matches the label `begin` opened.
            unsafe { debug.cmd_end_debug_utils_label(cmd) };
        }
        Ok(())
    }

    /// The device's timestamp clock.
    pub fn clock(&self) -> TimestampClock {
        self.clock
    }

    /// After the submission finished: each stage's duration and the span, or why they
    /// cannot be measured ([`Untimed`]). No stages recorded: an empty reading.
    pub fn read_checked(&self, ctx: &GpuContext) -> GpuResult<Result<Reading, Untimed>> {
        if self.stages.is_empty() {
            return Ok(Ok(Reading {
                stages: Vec::new(),
                span_ms: 0.0,
                wrapped: false,
            }));
        }
        if !self.clock.available() {
            return Ok(Err(Untimed::NoTimestamps));
        }
        let mut ticks = vec![0u64; self.stages.len() * 2];
        // SAFETY: the queries were written by a completed submission; WAIT makes the
        // call block until they are available.
        unsafe {
            ctx.device().get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .vk("vkGetQueryPoolResults")?;
        // The host saw the work take at most this long; a counter that wraps sooner
        // cannot tell its durations apart.
        let elapsed_ns = self
            .recorded_at
            .map_or(f64::INFINITY, |t| t.elapsed().as_nanos() as f64);
        if elapsed_ns >= self.clock.wrap_ns() {
            return Ok(Err(Untimed::WrapTooShort {
                bits: self.clock.valid_bits,
                wrap_ms: self.clock.wrap_ns() / 1e6,
                elapsed_ms: elapsed_ns / 1e6,
            }));
        }
        let (first, last) = (ticks[0], ticks[ticks.len() - 1]);
        if self.worst_phase && self.clock.valid_bits < 64 {
            // Emulated: a counter whose phase puts its wrap in the middle of the span.
            let m = self.clock.mask();
            let middle = first.wrapping_add(last.wrapping_sub(first) / 2) & m;
            let phase = (m - middle).wrapping_add(1) & m;
            for t in &mut ticks {
                *t = t.wrapping_add(phase) & m;
            }
        }
        let m = self.clock.mask();
        let (first, last) = (ticks[0] & m, ticks[ticks.len() - 1] & m);
        Ok(Ok(Reading {
            stages: self
                .stages
                .iter()
                .enumerate()
                .map(|(i, name)| {
                    let t = self.clock.ticks_between(ticks[2 * i], ticks[2 * i + 1]);
                    (name.clone(), self.clock.ms(t))
                })
                .collect(),
            span_ms: self.clock.ms(self.clock.ticks_between(first, last)),
            wrapped: last < first,
        }))
    }

    /// After the submission finished: each stage's name and duration in milliseconds;
    /// none when they cannot be measured (said once per process on stderr).
    pub fn read(&self, ctx: &GpuContext) -> GpuResult<Vec<(String, f64)>> {
        Ok(self.reading(ctx)?.map_or(Vec::new(), |r| r.stages))
    }

    /// After the submission finished: milliseconds from the first stage's start to the
    /// last stage's end (0 when nothing was timed or times cannot be measured).
    pub fn span_ms(&self, ctx: &GpuContext) -> GpuResult<f64> {
        Ok(self.reading(ctx)?.map_or(0.0, |r| r.span_ms))
    }

    fn reading(&self, ctx: &GpuContext) -> GpuResult<Option<Reading>> {
        match self.read_checked(ctx)? {
            Ok(r) => Ok(Some(r)),
            Err(untimed) => {
                static SAID: AtomicBool = AtomicBool::new(false);
                if !SAID.swap(true, Ordering::Relaxed) {
                    crate::core::console::note!("verisplat: {untimed}");
                }
                Ok(None)
            }
        }
    }
}

impl Drop for GpuTimer {
    fn drop(&mut self) {
        // SAFETY: the owner guarantees no pending submission uses the pool.
        unsafe { self.shared.device.destroy_query_pool(self.pool, None) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_undo_one_wrap_of_the_valid_bits() {
        let c = TimestampClock {
            valid_bits: 8,
            period_ns: 1.0,
        };
        assert_eq!(c.ticks_between(10, 50), 40);
        // end < begin after masking: 2^8 added.
        assert_eq!(c.ticks_between(250, 4), 10);
        // Bits above the valid ones are ignored.
        assert_eq!(c.ticks_between(0xFF00 + 250, 0xAB00 + 4), 10);
        assert_eq!(c.wrap_ns(), 256.0);
        let full = TimestampClock {
            valid_bits: 64,
            period_ns: 52.08,
        };
        assert_eq!(full.ticks_between(u64::MAX - 1, 3), 5);
        assert!(full.wrap_ns() > 1e20);
        assert!((full.ms(1_000_000) - 52.08).abs() < 1e-9);
        let none = TimestampClock {
            valid_bits: 0,
            period_ns: 1.0,
        };
        assert!(!none.available() && none.mask() == 0);
        let m36 = TimestampClock {
            valid_bits: 36,
            period_ns: 1.0,
        };
        assert_eq!(m36.ticks_between((1 << 36) - 5, 7), 12);
    }

    #[test]
    fn untimed_readings_say_why() {
        let e = Untimed::WrapTooShort {
            bits: 8,
            wrap_ms: 0.000256,
            elapsed_ms: 3.5,
        }
        .to_string();
        assert!(
            e.contains("8 valid bits") && e.contains("not reported"),
            "{e}"
        );
        assert!(Untimed::NoTimestamps
            .to_string()
            .contains("timestampValidBits = 0"));
    }
}
