//! Making a [`GpuContext`]: the options, and the steps from the Vulkan instance to a
//! device whose subgroup size is measured and whose emulated limits are in force. Each
//! step has its own module: `gpu::instance`, `gpu::device_choice`,
//! [`super::device_info`] with [`super::budget`], `gpu::logical_device` (which checks
//! `gpu::capabilities`), then [`super::subgroup`]'s probe on the finished context. The
//! context itself ([`super::device`]) and its frame slots ([`super::frame_slot`]) are
//! re-exported here under their old paths.

use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex};

use ash::vk;

pub use super::budget::{host_available_bytes, parse_bytes, BudgetSource};
pub use super::device::GpuContext;
pub use super::device_choice::select_device;
pub use super::device_info::DeviceInfo;
pub use super::frame_slot::FrameSlot;

use super::budget;
use super::device::Shared;
use super::device_choice;
use super::device_info::DeviceProperties;
use super::emulate::Emulation;
use super::instance;
use super::logical_device;
use super::subgroup::{self, SubgroupVerdict};
use super::{GpuError, GpuResult, VkContext};

/// How to create a [`GpuContext`].
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Device index or case-insensitive substring of its name; `VERISPLAT_DEVICE` overrides
    /// when this is `None`.
    pub device: Option<String>,
    /// Enable VK_LAYER_KHRONOS_validation (with synchronization validation when
    /// available); `VERISPLAT_VALIDATE=1` also turns it on.
    pub validation: bool,
    /// Device memory this context may allocate, in bytes; `VERISPLAT_MEMORY_LIMIT` (e.g.
    /// `512M`, `2G`) sets it when `None`. The default is the size of the largest
    /// device-local heap, which is also the ceiling on GPUs; on CPU devices, whose device
    /// memory is host memory, it is 3/4 of the host memory available when that is more,
    /// and a larger explicit limit is honoured.
    pub memory_limit: Option<u64>,
    /// Device traits to pretend ([`super::emulate`]); `VERISPLAT_EMULATE` adds to them.
    pub emulate: Emulation,
}

impl GpuContext {
    /// Creates the context: instance, device selection, queue, pool and allocator.
    pub fn new(options: &ContextOptions) -> GpuResult<Self> {
        let validation =
            options.validation || crate::core::former_name::env_flag("VERISPLAT_VALIDATE");
        let emulation = Emulation::from_env()
            .map_err(GpuError::Input)?
            .union(&options.emulate);
        let device_choice = options.device.clone().or_else(|| {
            crate::core::former_name::env_var("VERISPLAT_DEVICE").filter(|s| !s.is_empty())
        });

        let mut vulkan = instance::create(validation)?;
        let instance = &vulkan.instance;
        let chosen = device_choice::choose(instance, device_choice.as_deref())?;
        let properties = DeviceProperties::query(instance, chosen.physical_device);
        let limit = budget::explicit_limit(options.memory_limit)?;
        let host_memory = chosen.props.device_type == vk::PhysicalDeviceType::CPU;
        let budget = budget::choose_budget(limit, properties.device_local_bytes(), host_memory);
        let mut info = DeviceInfo::from_properties(&chosen, &properties, budget);
        let features = logical_device::check_features(instance, &chosen, &properties, &info.name)?;
        info.float_atomic_add = features.float_atomic_add;
        info.int64_atomics = features.int64_atomics;
        let device = logical_device::create_device(instance, &chosen, &features)?;
        let memory = logical_device::allocator_and_cache(instance, &device, &chosen)?;

        // Ownership of the instance/messenger moves into Shared.
        vulkan.guard.disarm();
        let debug_device = vulkan
            .debug_utils
            .then(|| ash::ext::debug_utils::Device::new(&vulkan.instance, &device));
        let push_descriptor = ash::khr::push_descriptor::Device::new(&vulkan.instance, &device);
        let shared = Arc::new(Shared {
            _entry: vulkan.entry,
            instance: vulkan.instance,
            debug_instance: vulkan.debug_instance,
            messenger: vulkan.messenger,
            _callback_log: vulkan.callback_log,
            device,
            debug_device,
            push_descriptor,
            allocator: ManuallyDrop::new(Mutex::new(memory.allocator)),
            memory_budget: info.memory_budget,
            pipeline_cache: memory.pipeline_cache,
            pipeline_cache_file: memory.pipeline_cache_file,
        });
        let queue_family = chosen.queue_family;
        let (queue, command_pool) = queue_and_pool(&shared, queue_family)?;
        let mut ctx = Self {
            shared,
            physical_device: chosen.physical_device,
            queue,
            queue_family,
            command_pool: Mutex::new(command_pool),
            info,
            messages: vulkan.messages,
            validation,
            full_subgroups: features.full_subgroups,
            host_clock: Default::default(),
        };
        ctx.follow_measured_subgroups()?;
        emulation.apply(&mut ctx.info);
        Ok(ctx)
    }

    /// Measures the subgroup size the device runs ([`super::subgroup`]) and, where the
    /// driver misreports it, makes every later pipeline and size decision use the measured
    /// one; refuses a device whose subgroups are inconsistent.
    fn follow_measured_subgroups(&mut self) -> GpuResult<()> {
        let probe = subgroup::probe(self)?;
        if let SubgroupVerdict::Misreported { runs, .. } =
            subgroup::size_to_use(&self.info.name, &probe)?
        {
            let info = &mut self.info;
            info.subgroup_size = runs;
            info.min_subgroup_size = info.min_subgroup_size.min(runs);
            info.max_subgroup_size = runs.max(info.min_subgroup_size);
            info.subgroup_size_override = runs;
        }
        Ok(())
    }
}

/// The compute queue (family `queue_family`, index 0) and the context's command pool,
/// both named for capture tools.
fn queue_and_pool(shared: &Shared, queue_family: u32) -> GpuResult<(vk::Queue, vk::CommandPool)> {
    // SAFETY: queue family index and queue index 0 were requested at device creation.
    let queue = unsafe { shared.device.get_device_queue(queue_family, 0) };
    let pool_info = vk::CommandPoolCreateInfo::default()
        .queue_family_index(queue_family)
        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
    // SAFETY: valid device and create info.
    let command_pool =
        unsafe { shared.device.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
    shared.set_name(queue, "compute queue");
    shared.set_name(command_pool, "command pool");
    shared.set_name(shared.device.handle(), "verisplat device");
    Ok((queue, command_pool))
}
