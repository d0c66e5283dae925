//! What a context knows about its device ([`DeviceInfo`]): name, driver, subgroup sizes,
//! compute and buffer limits, memory types and budget; read once from the driver's
//! properties, then clamped by the [`Emulation`] in force. Every decision that depends on
//! the device reads it from here.

use ash::vk;

use super::budget::BudgetSource;
use super::capabilities::{cstr_array, version_string};
use super::device_choice::ChosenDevice;
use super::emulate::{spec_minimum, Emulation};

/// What we know about the chosen device, for printing and for dispatch limits.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// Index among the enumerated physical devices.
    pub index: usize,
    /// Device name.
    pub name: String,
    /// Device type (discrete, integrated, CPU, ...).
    pub device_type: vk::PhysicalDeviceType,
    /// Driver name and info.
    pub driver: String,
    /// Supported Vulkan API version, as "major.minor.patch".
    pub api_version: String,
    /// Subgroup size: the lanes that run together, as measured ([`super::subgroup`]); the
    /// driver's `subgroupSize` unless it misreports it.
    pub subgroup_size: u32,
    /// Smallest subgroup size a compute shader may run with (subgroup size control).
    pub min_subgroup_size: u32,
    /// Largest subgroup size a compute shader may run with.
    pub max_subgroup_size: u32,
    /// The driver's `subgroupSize`, as reported.
    pub reported_subgroup_size: u32,
    /// The measured subgroup size every pipeline uses in place of `gl_SubgroupSize`
    /// because the driver misreports it (`SUBGROUP_SIZE_SPEC`); 0 when it does not.
    pub subgroup_size_override: u32,
    /// maxComputeWorkGroupCount.
    pub max_workgroup_count: [u32; 3],
    /// maxComputeWorkGroupInvocations.
    pub max_workgroup_invocations: u32,
    /// maxComputeSharedMemorySize in bytes.
    pub max_shared_memory: u32,
    /// minStorageBufferOffsetAlignment in bytes.
    pub min_storage_buffer_offset_alignment: u64,
    /// maxStorageBufferRange in bytes.
    pub max_storage_buffer_range: u32,
    /// maxTexelBufferElements.
    pub max_texel_buffer_elements: u32,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f32,
    /// Valid bits in compute-queue timestamps (0 = no timestamps).
    pub timestamp_valid_bits: u32,
    /// Size of the largest device-local memory heap, in bytes.
    pub device_local_bytes: u64,
    /// nonCoherentAtomSize: the unit that flushes and invalidates of host memory that is
    /// not coherent are rounded out to ([`super::memory`]).
    pub non_coherent_atom_size: u64,
    /// The property flags of each memory type, by index ([`super::memory`] chooses).
    pub memory_types: Vec<vk::MemoryPropertyFlags>,
    /// Device memory this context allows itself (see [`ContextOptions::memory_limit`](super::ContextOptions::memory_limit)).
    pub memory_budget: u64,
    /// Where [`Self::memory_budget`] comes from.
    pub budget_source: BudgetSource,
    /// Float atomic add on storage buffers (`VK_EXT_shader_atomic_float`'s
    /// `shaderBufferFloat32AtomicAdd`), enabled when the device has it: the backward pass's
    /// opt-in fast accumulation uses it.
    pub float_atomic_add: bool,
    /// 64-bit integer atomics on storage buffers (`shaderBufferInt64Atomics` with
    /// `shaderInt64`), enabled when the device has them: the deterministic gradient
    /// accumulation adds its 64-bit fixed-point sums with one atomic each instead of two
    /// 32-bit halves and a carry (the same sums). Off under `spec-limits`, which the
    /// specification does not require.
    pub int64_atomics: bool,
    /// Subgroup shuffles in compute shaders (`VK_SUBGROUP_FEATURE_SHUFFLE_BIT`, optional in
    /// the specification; off under `spec-limits`): the blend backward's per-pixel layout
    /// sums a pair's pixels as a balanced tree with them, the same bits at every subgroup
    /// size (docs/reproducibility.md).
    pub subgroup_shuffle: bool,
    /// The device traits pretended ([`super::emulate`]): the limits above already
    /// include them.
    pub emulation: Emulation,
    /// Indices of the usable devices (Vulkan 1.3, a compute queue) of this device's type,
    /// this one included: the devices `render --devices all` spreads frames over.
    pub same_kind_devices: Vec<usize>,
}

impl DeviceInfo {
    /// Whether the device is a CPU implementation with llvmpipe's loop limit (every loop
    /// of a shader invocation ends after 65,535 iterations in all, silently).
    pub fn loop_limited(&self) -> bool {
        self.device_type == vk::PhysicalDeviceType::CPU && self.name.contains("llvmpipe")
    }
}

impl std::fmt::Display for DeviceInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "#{} {} ({:?}), driver {}, Vulkan {}, subgroup {}{}, max groups {:?}, \
             max invocations {}, shared {} B",
            self.index,
            self.name,
            self.device_type,
            self.driver,
            self.api_version,
            self.subgroup_size,
            if self.subgroup_size_override != 0 {
                format!(
                    " (the driver says {}: measured)",
                    self.reported_subgroup_size
                )
            } else {
                String::new()
            },
            self.max_workgroup_count,
            self.max_workgroup_invocations,
            self.max_shared_memory
        )
    }
}

/// The Vulkan 1.1/1.2/1.3 properties and the memory properties of the chosen device.
pub(crate) struct DeviceProperties {
    pub(crate) props11: vk::PhysicalDeviceVulkan11Properties<'static>,
    pub(crate) props12: vk::PhysicalDeviceVulkan12Properties<'static>,
    pub(crate) props13: vk::PhysicalDeviceVulkan13Properties<'static>,
    pub(crate) memory: vk::PhysicalDeviceMemoryProperties,
}

impl DeviceProperties {
    /// Queries them.
    pub(crate) fn query(instance: &ash::Instance, physical_device: vk::PhysicalDevice) -> Self {
        let mut props11 = vk::PhysicalDeviceVulkan11Properties::default();
        let mut props12 = vk::PhysicalDeviceVulkan12Properties::default();
        let mut props13 = vk::PhysicalDeviceVulkan13Properties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut props11)
            .push_next(&mut props12)
            .push_next(&mut props13);
        // SAFETY: valid handle, chain of valid structs.
        unsafe { instance.get_physical_device_properties2(physical_device, &mut props2) };
        // SAFETY: valid handle.
        let memory = unsafe { instance.get_physical_device_memory_properties(physical_device) };
        DeviceProperties {
            props11,
            props12,
            props13,
            memory,
        }
    }

    /// Size of the largest device-local memory heap, in bytes.
    pub(crate) fn device_local_bytes(&self) -> u64 {
        let mem = &self.memory;
        mem.memory_heaps[..mem.memory_heap_count as usize]
            .iter()
            .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
            .map(|h| h.size)
            .max()
            .unwrap_or(0)
    }
}

impl DeviceInfo {
    /// The info of the `chosen` device with its `properties` and memory budget, as the
    /// driver reports it (float atomics, the measured subgroup size and emulation are
    /// filled in later).
    pub(crate) fn from_properties(
        chosen: &ChosenDevice,
        properties: &DeviceProperties,
        (memory_budget, budget_source): (u64, BudgetSource),
    ) -> Self {
        let DeviceProperties {
            props11,
            props12,
            props13,
            memory: mem,
        } = properties;
        let props = &chosen.props;
        let limits = props.limits;
        DeviceInfo {
            index: chosen.index,
            name: chosen.names[chosen.index].clone(),
            device_type: props.device_type,
            driver: format!(
                "{} {}",
                cstr_array(&props12.driver_name),
                cstr_array(&props12.driver_info)
            ),
            api_version: version_string(props.api_version),
            subgroup_size: props11.subgroup_size,
            min_subgroup_size: props13
                .min_subgroup_size
                .clamp(1, props11.subgroup_size.max(1)),
            max_subgroup_size: props13.max_subgroup_size.max(props11.subgroup_size),
            reported_subgroup_size: props11.subgroup_size,
            subgroup_size_override: 0,
            max_workgroup_count: limits.max_compute_work_group_count,
            max_workgroup_invocations: limits.max_compute_work_group_invocations,
            max_shared_memory: limits.max_compute_shared_memory_size,
            min_storage_buffer_offset_alignment: limits.min_storage_buffer_offset_alignment,
            max_storage_buffer_range: limits.max_storage_buffer_range,
            max_texel_buffer_elements: limits.max_texel_buffer_elements,
            timestamp_period_ns: limits.timestamp_period,
            timestamp_valid_bits: chosen.timestamp_valid_bits,
            device_local_bytes: properties.device_local_bytes(),
            non_coherent_atom_size: limits.non_coherent_atom_size.max(1),
            memory_types: mem.memory_types[..mem.memory_type_count as usize]
                .iter()
                .map(|t| t.property_flags)
                .collect(),
            memory_budget,
            budget_source,
            float_atomic_add: false,
            int64_atomics: false,
            subgroup_shuffle: props11
                .subgroup_supported_operations
                .contains(vk::SubgroupFeatureFlags::SHUFFLE),
            emulation: Default::default(),
            same_kind_devices: chosen.same_kind_devices.clone(),
        }
    }
}

impl Emulation {
    /// Clamps `info`'s limits to the emulated ones (never raises one).
    pub fn apply(&self, info: &mut DeviceInfo) {
        if self.spec_limits {
            use spec_minimum as m;
            info.max_shared_memory = info.max_shared_memory.min(m::SHARED_MEMORY);
            info.max_workgroup_invocations =
                info.max_workgroup_invocations.min(m::WORKGROUP_INVOCATIONS);
            for c in &mut info.max_workgroup_count {
                *c = (*c).min(m::WORKGROUP_COUNT);
            }
        }
        if self.spec_limits || self.no_int64_atomics {
            // An optional feature: the 32-bit fallback runs instead.
            info.int64_atomics = false;
        }
        if self.spec_limits || self.no_subgroup_shuffle {
            // Optional too: the driver's subgroup sums run instead.
            info.subgroup_shuffle = false;
        }
        if let Some(bits) = self.timestamp_bits {
            if info.timestamp_valid_bits != 0 {
                info.timestamp_valid_bits = info.timestamp_valid_bits.min(bits);
            }
        }
        if let Some(range) = self.max_storage_buffer_range {
            info.max_storage_buffer_range = info.max_storage_buffer_range.min(range);
        }
        if let Some(n) = self.max_workgroup_count_x {
            info.max_workgroup_count[0] = info.max_workgroup_count[0].min(n);
        }
        info.emulation = self.clone();
    }
}
