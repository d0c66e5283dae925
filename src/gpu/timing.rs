//! Per-stage GPU timestamps and debug labels, recorded by one helper.

use std::ffi::CString;
use std::sync::Arc;

use ash::vk;

use super::context::Shared;
use super::{GpuContext, GpuError, GpuResult, VkContext};

/// A timestamp query pool recording one begin/end pair per named stage.
pub struct GpuTimer {
    shared: Arc<Shared>,
    pool: vk::QueryPool,
    capacity: u32,
    stages: Vec<String>,
    period_ns: f64,
    valid_mask: u64,
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
        let bits = ctx.info().timestamp_valid_bits;
        Ok(Self {
            shared: ctx.shared.clone(),
            pool,
            capacity,
            stages: Vec::new(),
            period_ns: f64::from(ctx.info().timestamp_period_ns),
            valid_mask: if bits >= 64 {
                u64::MAX
            } else {
                (1u64 << bits) - 1
            },
        })
    }

    /// Starts a new recording: forgets old stages and resets the pool inside `cmd`.
    pub fn reset(&mut self, ctx: &GpuContext, cmd: vk::CommandBuffer) {
        self.stages.clear();
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
        let debug = self.shared.debug_device.as_ref();
        if let Some(debug) = debug {
            let info = vk::DebugUtilsLabelEXT::default().label_name(&label);
            // SAFETY: cmd is recording; the label outlives the call.
            unsafe { debug.cmd_begin_debug_utils_label(cmd, &info) };
        }
        let timed = self.valid_mask != 0;
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
        let result = body(cmd);
        if timed {
            // SAFETY: as above for query `index + 1`.
            unsafe {
                ctx.device().cmd_write_timestamp2(
                    cmd,
                    vk::PipelineStageFlags2::ALL_COMMANDS,
                    self.pool,
                    index + 1,
                )
            };
            self.stages.push(name.to_string());
        }
        if let Some(debug) = debug {
            // SAFETY: matches the begin above.
            unsafe { debug.cmd_end_debug_utils_label(cmd) };
        }
        result
    }

    /// After the submission finished: each stage's name and duration in milliseconds.
    pub fn read(&self, ctx: &GpuContext) -> GpuResult<Vec<(String, f64)>> {
        if self.stages.is_empty() {
            return Ok(Vec::new());
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
        Ok(self
            .stages
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let begin = ticks[2 * i] & self.valid_mask;
                let end = ticks[2 * i + 1] & self.valid_mask;
                let delta = end.wrapping_sub(begin) & self.valid_mask;
                (name.clone(), delta as f64 * self.period_ns / 1e6)
            })
            .collect())
    }
}

impl GpuTimer {
    /// After the submission finished: milliseconds from the first stage's start to the
    /// last stage's end (0 when nothing was timed).
    pub fn span_ms(&self, ctx: &GpuContext) -> GpuResult<f64> {
        if self.stages.is_empty() {
            return Ok(0.0);
        }
        let mut first = [0u64; 1];
        let mut last = [0u64; 1];
        let last_index = self.stages.len() as u32 * 2 - 1;
        // SAFETY: the queries were written by a completed submission; WAIT blocks until
        // they are available.
        unsafe {
            let device = ctx.device();
            let flags = vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT;
            device
                .get_query_pool_results(self.pool, 0, &mut first, flags)
                .vk("vkGetQueryPoolResults")?;
            device
                .get_query_pool_results(self.pool, last_index, &mut last, flags)
                .vk("vkGetQueryPoolResults")?;
        }
        let delta =
            (last[0] & self.valid_mask).wrapping_sub(first[0] & self.valid_mask) & self.valid_mask;
        Ok(delta as f64 * self.period_ns / 1e6)
    }
}

impl Drop for GpuTimer {
    fn drop(&mut self) {
        // SAFETY: the owner guarantees no pending submission uses the pool.
        unsafe { self.shared.device.destroy_query_pool(self.pool, None) };
    }
}
