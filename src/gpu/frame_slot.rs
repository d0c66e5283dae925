//! [`FrameSlot`]: a command buffer and fence reused frame after frame, and the
//! [`GpuContext`] methods that record, submit and wait on one.

use std::sync::Arc;

use ash::vk;

use super::device::{GpuContext, Shared};
use super::{GpuError, GpuResult, VkContext};

/// A command buffer and fence reused frame after frame (with their own command pool), so a
/// long camera path allocates nothing per frame. Submit through [`GpuContext::submit_slot`].
pub struct FrameSlot {
    shared: Arc<Shared>,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    /// A submission of this slot has not been waited for yet
    /// ([`GpuContext::submit_slot_nowait`]).
    pending: bool,
}

impl FrameSlot {
    /// Creates the pool, command buffer and fence, named `label`.
    pub fn new(ctx: &GpuContext, label: &str) -> GpuResult<Self> {
        let device = &ctx.shared.device;
        let pool_info = vk::CommandPoolCreateInfo::default().queue_family_index(ctx.queue_family);
        // SAFETY: valid create infos; everything is destroyed in Drop (null handles are
        // ignored there if a later step fails).
        let pool =
            unsafe { device.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let mut slot = FrameSlot {
            shared: ctx.shared.clone(),
            pool,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            pending: false,
        };
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool was just created and is only used through this slot.
        slot.cmd =
            unsafe { device.allocate_command_buffers(&alloc) }.vk("vkAllocateCommandBuffers")?[0];
        // SAFETY: as above.
        slot.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .vk("vkCreateFence")?;
        ctx.set_name(pool, label);
        ctx.set_name(slot.cmd, label);
        ctx.set_name(slot.fence, label);
        Ok(slot)
    }
}

impl Drop for FrameSlot {
    fn drop(&mut self) {
        let device = &self.shared.device;
        // SAFETY: submit_slot waits for its submission before returning (or idles the
        // queue on error); a submission left pending by submit_slot_nowait is waited for
        // here, so nothing is pending; freeing the pool frees the buffer.
        unsafe {
            if self.pending {
                let _ = device.wait_for_fences(&[self.fence], true, u64::MAX);
            }
            device.destroy_fence(self.fence, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}

impl GpuContext {
    /// Records into `slot`'s command buffer (reset first), submits it and waits for it.
    pub fn submit_slot<R>(
        &self,
        slot: &mut FrameSlot,
        record: impl FnOnce(vk::CommandBuffer) -> GpuResult<R>,
    ) -> GpuResult<R> {
        let out = self.submit_slot_nowait(slot, record)?;
        self.wait_slot(slot)?;
        Ok(out)
    }

    /// Records into `slot`'s command buffer (reset first) and submits it without waiting:
    /// the CPU can record another slot meanwhile. [`Self::wait_slot`] waits for it. A slot
    /// still pending from an earlier call is waited for before it is reused.
    pub fn submit_slot_nowait<R>(
        &self,
        slot: &mut FrameSlot,
        record: impl FnOnce(vk::CommandBuffer) -> GpuResult<R>,
    ) -> GpuResult<R> {
        self.wait_slot(slot)?;
        let device = &self.shared.device;
        // The queue is externally synchronised by the context's pool mutex.
        let queue = self
            .command_pool
            .lock()
            .map_err(|_| GpuError::Internal("command pool mutex poisoned".into()))?;
        let run = |slot: &mut FrameSlot| -> GpuResult<R> {
            let t = std::time::Instant::now();
            // SAFETY: the previous submission of this slot completed (waited for above),
            // so the pool and fence can be reset.
            unsafe {
                device
                    .reset_command_pool(slot.pool, vk::CommandPoolResetFlags::empty())
                    .vk("vkResetCommandPool")?;
                device.reset_fences(&[slot.fence]).vk("vkResetFences")?;
                let begin = vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
                device
                    .begin_command_buffer(slot.cmd, &begin)
                    .vk("vkBeginCommandBuffer")?;
            }
            let out = record(slot.cmd)?;
            let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(slot.cmd)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cmds)];
            // SAFETY: recording began above; the queue is held through the mutex guard.
            unsafe {
                device
                    .end_command_buffer(slot.cmd)
                    .vk("vkEndCommandBuffer")?;
                self.host_clock.recorded(t);
                let t = std::time::Instant::now();
                device
                    .queue_submit2(self.queue, &submit, slot.fence)
                    .vk("vkQueueSubmit2")?;
                self.host_clock.submitted(t);
            }
            slot.pending = true;
            Ok(out)
        };
        let result = run(slot);
        if result.is_err() {
            // SAFETY: make sure nothing of this slot is still pending.
            let _ = unsafe { device.queue_wait_idle(self.queue) };
            slot.pending = false;
        }
        drop(queue);
        result
    }

    /// Waits for `slot`'s submission (nothing to wait for when none is pending).
    pub fn wait_slot(&self, slot: &mut FrameSlot) -> GpuResult<()> {
        if !slot.pending {
            return Ok(());
        }
        let device = &self.shared.device;
        let t = std::time::Instant::now();
        // SAFETY: the fence was submitted with the slot's command buffer.
        let waited =
            unsafe { device.wait_for_fences(&[slot.fence], true, u64::MAX) }.vk("vkWaitForFences");
        self.host_clock.waited(t);
        if waited.is_err() {
            // The queue is externally synchronised by the context's pool mutex.
            if let Ok(_queue) = self.command_pool.lock() {
                // SAFETY: make sure nothing of this slot is still pending.
                let _ = unsafe { device.queue_wait_idle(self.queue) };
            }
        }
        slot.pending = false;
        waited
    }
}
