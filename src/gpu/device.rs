//! The open device: `Shared` (instance, device, allocator and pipeline cache, which
//! every buffer and pipeline keeps alive and which are torn down last, in order) and
//! [`GpuContext`]'s fields, accessors, budget check and one-off submissions. The context
//! is made in [`super::context`].

use std::ffi::CString;
use std::mem::ManuallyDrop;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::Allocator;

use super::device_info::DeviceInfo;
use super::instance::MessageLog;
use super::pipeline_cache::{self, CacheIdentity};
use super::{GpuError, GpuResult, VkContext};

/// Objects that must outlive every buffer and pipeline; shared through an `Arc` so
/// RAII resources can free themselves, and torn down in the right order last.
pub(crate) struct Shared {
    pub(super) _entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    pub(super) debug_instance: Option<ash::ext::debug_utils::Instance>,
    pub(super) messenger: vk::DebugUtilsMessengerEXT,
    /// Owns the log the messenger callback writes through a raw pointer.
    pub(super) _callback_log: Option<Box<MessageLog>>,
    pub(crate) device: ash::Device,
    pub(crate) debug_device: Option<ash::ext::debug_utils::Device>,
    pub(crate) push_descriptor: ash::khr::push_descriptor::Device,
    pub(crate) allocator: ManuallyDrop<Mutex<Allocator>>,
    /// Bytes the allocator may hand out in all (see [`DeviceInfo::memory_budget`]).
    pub(crate) memory_budget: u64,
    /// Every pipeline is created through this cache.
    pub(crate) pipeline_cache: vk::PipelineCache,
    /// Where the cache is written back when the device goes, and the bytes it was loaded
    /// with (written back only when the driver's data grew).
    pub(super) pipeline_cache_file: Option<(PathBuf, CacheIdentity, usize)>,
}

impl Shared {
    /// Names a Vulkan object for validation messages and capture tools.
    pub(crate) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(debug) = &self.debug_device else {
            return;
        };
        let Ok(name) = CString::new(name) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: the handle belongs to this device and the info outlives the call.
        // Naming is best-effort, so a failure is ignored.
        let _ = unsafe { debug.set_debug_utils_object_name(&info) };
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        // SAFETY: every buffer and pipeline holds an Arc to this, so nothing created from
        // the device is alive any more; the allocator goes before the device, the
        // device before the messenger and instance.
        unsafe {
            let _ = self.device.device_wait_idle();
            if let Some((dir, identity, loaded)) = &self.pipeline_cache_file {
                if let Ok(data) = self.device.get_pipeline_cache_data(self.pipeline_cache) {
                    if data.len() > *loaded {
                        pipeline_cache::store(dir, identity, &data);
                    }
                }
            }
            self.device
                .destroy_pipeline_cache(self.pipeline_cache, None);
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some(debug) = &self.debug_instance {
                if self.messenger != vk::DebugUtilsMessengerEXT::null() {
                    debug.destroy_debug_utils_messenger(self.messenger, None);
                }
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// The Vulkan device with one compute queue, a command pool and an allocator.
pub struct GpuContext {
    pub(crate) shared: Arc<Shared>,
    pub(crate) physical_device: vk::PhysicalDevice,
    pub(crate) queue: vk::Queue,
    pub(crate) queue_family: u32,
    pub(super) command_pool: Mutex<vk::CommandPool>,
    pub(super) info: DeviceInfo,
    pub(super) messages: MessageLog,
    pub(super) validation: bool,
    /// computeFullSubgroups is enabled: pipelines may require full subgroups.
    pub(crate) full_subgroups: bool,
    /// The host's time recording, submitting and waiting ([`Self::host_time`]).
    pub(crate) host_clock: super::host_time::HostClock,
}

impl GpuContext {
    /// The pipeline cache every pipeline is created through.
    pub fn pipeline_cache(&self) -> vk::PipelineCache {
        self.shared.pipeline_cache
    }

    /// The host's totals so far of recording, submitting and waiting for this context's
    /// command buffers ([`super::host_time`]).
    pub fn host_time(&self) -> super::HostTime {
        self.host_clock.now()
    }

    /// The raw ash device.
    pub fn device(&self) -> &ash::Device {
        &self.shared.device
    }

    /// The chosen physical device.
    pub fn physical_device(&self) -> vk::PhysicalDevice {
        self.physical_device
    }

    /// The compute queue and its family index.
    pub fn queue(&self) -> (vk::Queue, u32) {
        (self.queue, self.queue_family)
    }

    /// What was chosen: name, driver, limits.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// Whether validation layers are on.
    pub fn validation_enabled(&self) -> bool {
        self.validation
    }

    /// Every WARNING/ERROR message the validation layer reported so far.
    pub fn validation_messages(&self) -> Vec<String> {
        self.messages.lock().map(|m| m.clone()).unwrap_or_default()
    }

    /// Live gpu-allocator allocations and their bytes (what its leak log would report if
    /// the allocator were dropped now).
    pub fn live_allocations(&self) -> (usize, u64) {
        match self.shared.allocator.lock() {
            Ok(a) => {
                let report = a.generate_report();
                (report.allocations.len(), report.total_allocated_bytes)
            }
            Err(_) => (0, 0),
        }
    }

    /// Fails with [`GpuError::OutOfMemory`] when allocating `bytes` more for `name`
    /// would exceed the memory budget; called before every allocation.
    pub(crate) fn check_budget(shared: &Shared, name: &str, bytes: u64) -> GpuResult<()> {
        let in_use = match shared.allocator.lock() {
            Ok(a) => a.generate_report().total_allocated_bytes,
            Err(_) => 0,
        };
        if in_use.saturating_add(bytes) > shared.memory_budget {
            return Err(GpuError::OutOfMemory {
                name: name.to_string(),
                bytes,
                in_use,
                budget: shared.memory_budget,
            });
        }
        Ok(())
    }

    /// The shared message log itself, to inspect messages emitted while the context
    /// is torn down (leaked objects are reported at vkDestroyDevice).
    pub fn validation_log(&self) -> Arc<Mutex<Vec<String>>> {
        self.messages.clone()
    }

    /// Gives a Vulkan object a debug name (no-op without VK_EXT_debug_utils).
    pub fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        self.shared.set_name(handle, name);
    }

    /// Whether debug labels/names are available.
    pub fn has_debug_utils(&self) -> bool {
        self.shared.debug_device.is_some()
    }

    /// Records commands into a fresh primary command buffer, submits it, waits for it,
    /// and frees it. For set-up, tests and read-backs, not per-frame work.
    pub fn submit_and_wait<R>(
        &self,
        label: &str,
        record: impl FnOnce(vk::CommandBuffer) -> GpuResult<R>,
    ) -> GpuResult<R> {
        let device = &self.shared.device;
        let pool = self
            .command_pool
            .lock()
            .map_err(|_| GpuError::Internal("command pool mutex poisoned".into()))?;
        let alloc_info = vk::CommandBufferAllocateInfo::default()
            .command_pool(*pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool is externally synchronised by the mutex held here.
        let cmd = unsafe { device.allocate_command_buffers(&alloc_info) }
            .vk("vkAllocateCommandBuffers")?[0];
        self.set_name(cmd, label);
        // SAFETY: the fence is destroyed below on every path.
        let fence = match unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) } {
            Ok(f) => f,
            Err(result) => {
                // SAFETY: cmd came from this pool and is not in use.
                unsafe { device.free_command_buffers(*pool, &[cmd]) };
                return Err(GpuError::Vk {
                    call: "vkCreateFence",
                    result,
                });
            }
        };
        self.set_name(fence, label);
        let run = || -> GpuResult<R> {
            let begin = vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            let t = std::time::Instant::now();
            // SAFETY: freshly allocated command buffer.
            unsafe { device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
            let out = record(cmd)?;
            // SAFETY: recording started above.
            unsafe { device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
            self.host_clock.recorded(t);
            let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(cmd)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cmds)];
            let t = std::time::Instant::now();
            // SAFETY: the queue is only used from here while the pool mutex is held.
            unsafe { device.queue_submit2(self.queue, &submit, fence) }.vk("vkQueueSubmit2")?;
            self.host_clock.submitted(t);
            let t = std::time::Instant::now();
            // SAFETY: the fence was submitted above.
            unsafe { device.wait_for_fences(&[fence], true, u64::MAX) }.vk("vkWaitForFences")?;
            self.host_clock.waited(t);
            Ok(out)
        };
        let result = run();
        if result.is_err() {
            // SAFETY: make sure nothing is pending before freeing.
            let _ = unsafe { device.queue_wait_idle(self.queue) };
        }
        // SAFETY: the work completed (fence waited or queue idle), so both are unused.
        unsafe {
            device.destroy_fence(fence, None);
            device.free_command_buffers(*pool, &[cmd]);
        }
        result
    }
}

impl Drop for GpuContext {
    fn drop(&mut self) {
        // SAFETY: waits for all work; the pool is ours and no command buffer from it runs.
        unsafe {
            let _ = self.shared.device.device_wait_idle();
            if let Ok(pool) = self.command_pool.lock() {
                self.shared.device.destroy_command_pool(*pool, None);
            }
        }
    }
}
