//! GPU building blocks on raw Vulkan compute: context, buffers, shaders, barriers,
//! timing, and the reusable prefix-sum and radix-sort stages.

pub mod budget;
pub mod buffer;
pub(crate) mod capabilities;
pub mod context;
pub mod device;
pub(crate) mod device_choice;
pub mod device_info;
pub mod devices;
pub mod emulate;
pub mod frame_slot;
pub mod host_time;
pub mod image;
pub(crate) mod instance;
pub mod limits;
pub(crate) mod logical_device;
pub mod memory;
pub mod pipeline_cache;
pub mod reflect;
pub mod scan;
pub mod shader;
pub mod shader_set;
pub mod sort;
pub mod subgroup;
pub mod sync;
pub mod timing;
pub mod traffic;
pub mod workgroup;

pub use budget::BudgetSource;
pub use buffer::{BufferSlice, BufferView, GpuBuffer, MemoryKind};
pub use context::ContextOptions;
pub use device::GpuContext;
pub use device_info::DeviceInfo;
pub use frame_slot::FrameSlot;
pub use host_time::HostTime;
pub use image::GpuImage;
pub use scan::Scan;
pub use shader::{ComputePipeline, ShaderError};
pub use sort::{Count, RadixSort};
pub use sync::Access;
pub use timing::GpuTimer;
pub use traffic::Traffic;

use ash::vk;

/// Every error the GPU layer reports, with enough context to act on it.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// The Vulkan loader library could not be loaded.
    #[error("could not load the Vulkan loader (is libvulkan1 installed?): {0}")]
    Loader(String),
    /// A Vulkan call failed.
    #[error("Vulkan call {call} failed: {result:?}{}", vk_hint(*result))]
    Vk {
        /// The Vulkan entry point (and what it was doing).
        call: &'static str,
        /// The result code.
        result: vk::Result,
    },
    /// No usable device, or the requested one does not exist.
    #[error("no suitable Vulkan device: {0}")]
    NoDevice(String),
    /// A required layer, extension or feature is missing.
    #[error("missing Vulkan support: {0}")]
    Missing(String),
    /// Memory allocation failed.
    #[error("allocating {bytes} bytes for buffer '{name}' failed: {source}")]
    Alloc {
        /// Buffer name.
        name: String,
        /// Bytes requested.
        bytes: u64,
        /// Allocator error.
        source: gpu_allocator::AllocationError,
    },
    /// An allocation would exceed the device memory budget (or the device is out of
    /// memory).
    #[error("out of device memory: buffer '{name}' needs {bytes} bytes, {in_use} of the {budget} bytes this renderer may use are taken (the budget is the device-local heap, on CPU devices 3/4 of the host memory available, or VERISPLAT_MEMORY_LIMIT / --memory-limit); use a smaller resolution, fewer Gaussians or a larger device")]
    OutOfMemory {
        /// Buffer or image name.
        name: String,
        /// Bytes requested.
        bytes: u64,
        /// Bytes already allocated.
        in_use: u64,
        /// The budget.
        budget: u64,
    },
    /// A shader failed to compile or load.
    #[error(transparent)]
    Shader(#[from] ShaderError),
    /// A caller of the library passed something out of range (a buffer too small, key
    /// bits outside the key, a ticket of another renderer, ...).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// What the user asked for cannot be rendered as asked (a camera, options, features
    /// that do not fit the scene, an environment setting); the message says what to change.
    #[error("{0}")]
    Input(String),
    /// The frame or scene needs more of a device limit than the device has.
    #[error("{message}")]
    DeviceLimit {
        /// The Vulkan limit (e.g. `maxStorageBufferRange`) or the driver's.
        limit: &'static str,
        /// What the work needs, in the limit's unit.
        needed: u64,
        /// What the device allows.
        max: u64,
        /// The whole sentence, with what to do about it.
        message: String,
    },
    /// An invariant of verisplat itself does not hold: a bug, not a problem of the input
    /// or the device.
    #[error("internal error (a bug in verisplat; please report it): {0}")]
    Internal(String),
}

fn vk_hint(result: vk::Result) -> &'static str {
    match result {
        vk::Result::ERROR_DEVICE_LOST => " (the device was lost: a driver reset or crash)",
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY | vk::Result::ERROR_OUT_OF_HOST_MEMORY => {
            " (out of memory: use a smaller resolution or fewer Gaussians)"
        }
        _ => "",
    }
}

impl GpuError {
    /// Maps an allocator failure: running out of memory becomes [`GpuError::OutOfMemory`].
    pub(crate) fn from_alloc(
        shared: &device::Shared,
        name: &str,
        bytes: u64,
        source: gpu_allocator::AllocationError,
    ) -> GpuError {
        match source {
            gpu_allocator::AllocationError::OutOfMemory => GpuError::OutOfMemory {
                name: name.to_string(),
                bytes,
                in_use: shared
                    .allocator
                    .lock()
                    .map(|a| a.generate_report().total_allocated_bytes)
                    .unwrap_or(0),
                budget: shared.memory_budget,
            },
            source => GpuError::Alloc {
                name: name.to_string(),
                bytes,
                source,
            },
        }
    }
}

/// Result alias for the GPU layer.
pub type GpuResult<T> = Result<T, GpuError>;

/// Helper turning a `VkResult` into a [`GpuError::Vk`] naming the call.
pub(crate) trait VkContext<T> {
    fn vk(self, call: &'static str) -> GpuResult<T>;
}

impl<T> VkContext<T> for Result<T, vk::Result> {
    fn vk(self, call: &'static str) -> GpuResult<T> {
        self.map_err(|result| GpuError::Vk { call, result })
    }
}

/// Splits `groups` workgroups into an x/y grid that respects `max_x`
/// (`maxComputeWorkGroupCount[0]`); shaders recover the linear id as `x + y * num_x`
/// and ignore ids past the end.
pub fn dispatch_grid(groups: u32, max_x: u32) -> [u32; 3] {
    if groups <= max_x {
        [groups, 1, 1]
    } else {
        [max_x, groups.div_ceil(max_x), 1]
    }
}

/// Rounds `value` up to a multiple of `align` (a power of two or any non-zero value).
pub(crate) fn align_up(value: u64, align: u64) -> u64 {
    value.div_ceil(align) * align
}
