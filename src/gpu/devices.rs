//! Every Vulkan device the loader offers, described from read-only queries (no logical
//! device is created): what `verisplat doctor` lists, and whether verisplat can run on each.

use ash::vk;

use super::capabilities::{self, cstr_array, version_string};
use serde::Serialize;

use super::{GpuError, GpuResult, VkContext};

/// One memory heap of a device.
#[derive(Clone, Debug, Serialize)]
pub struct HeapSummary {
    /// Size in bytes.
    pub size: u64,
    /// Device-local (VRAM on a discrete GPU).
    pub device_local: bool,
    /// What `VK_EXT_memory_budget` says this process may use of it, in bytes.
    pub budget: Option<u64>,
    /// What `VK_EXT_memory_budget` says is in use (by every process), in bytes.
    pub usage: Option<u64>,
}

/// What the read-only queries tell about one physical device.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceSummary {
    /// Index among the enumerated physical devices (what `--device N` takes).
    pub index: usize,
    /// Device name.
    pub name: String,
    /// Device type: discrete, integrated, virtual, CPU or other.
    pub device_type: String,
    /// Driver name (Vulkan 1.2 driver properties).
    pub driver_name: String,
    /// Driver info (version string).
    pub driver_info: String,
    /// Vulkan version the device supports, "major.minor.patch".
    pub api_version: String,
    /// `subgroupSize` as the driver reports it.
    pub subgroup_size: u32,
    /// Smallest and largest subgroup size (subgroup size control), 0 when not reported.
    pub min_subgroup_size: u32,
    /// Largest subgroup size (subgroup size control).
    pub max_subgroup_size: u32,
    /// Subgroup operations compute shaders may use (basic, vote, arithmetic, ...).
    pub subgroup_operations: Vec<String>,
    /// maxComputeSharedMemorySize in bytes.
    pub max_shared_memory: u32,
    /// maxComputeWorkGroupInvocations.
    pub max_workgroup_invocations: u32,
    /// maxComputeWorkGroupCount.
    pub max_workgroup_count: [u32; 3],
    /// maxStorageBufferRange in bytes.
    pub max_storage_buffer_range: u32,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f32,
    /// Valid timestamp bits of the first compute queue family (0: no timestamps).
    pub timestamp_valid_bits: u32,
    /// `shaderBufferFloat32AtomicAdd` (VK_EXT_shader_atomic_float).
    pub float32_atomic_add: bool,
    /// `shaderBufferInt64Atomics`.
    pub int64_atomics: bool,
    /// The memory heaps.
    pub heaps: Vec<HeapSummary>,
    /// VK_EXT_memory_budget is supported (the heaps' budgets are filled in).
    pub memory_budget_ext: bool,
    /// Whether verisplat can run on it: Vulkan 1.3, a compute queue, push descriptors,
    /// synchronization2, maintenance4 and basic/arithmetic/ballot subgroup operations.
    pub usable: bool,
    /// What it lacks when it is not usable.
    pub missing: Vec<String>,
}

/// A device type in words.
pub fn type_name(t: vk::PhysicalDeviceType) -> &'static str {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
        vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
        vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
        vk::PhysicalDeviceType::CPU => "CPU",
        _ => "other",
    }
}

/// The names of the subgroup operation classes in `flags`.
pub fn subgroup_operation_names(flags: vk::SubgroupFeatureFlags) -> Vec<String> {
    [
        (vk::SubgroupFeatureFlags::BASIC, "basic"),
        (vk::SubgroupFeatureFlags::VOTE, "vote"),
        (vk::SubgroupFeatureFlags::ARITHMETIC, "arithmetic"),
        (vk::SubgroupFeatureFlags::BALLOT, "ballot"),
        (vk::SubgroupFeatureFlags::SHUFFLE, "shuffle"),
        (
            vk::SubgroupFeatureFlags::SHUFFLE_RELATIVE,
            "shuffle_relative",
        ),
        (vk::SubgroupFeatureFlags::CLUSTERED, "clustered"),
        (vk::SubgroupFeatureFlags::QUAD, "quad"),
    ]
    .into_iter()
    .filter(|(f, _)| flags.contains(*f))
    .map(|(_, n)| n.to_string())
    .collect()
}

/// Describes every physical device the Vulkan loader offers, in enumeration order.
pub fn enumerate() -> GpuResult<Vec<DeviceSummary>> {
    // SAFETY: loading the system Vulkan loader; its entry points are trusted.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| GpuError::Loader(e.to_string()))?;
    // SAFETY: plain query through a loaded entry.
    let version = unsafe { entry.try_enumerate_instance_version() }
        .vk("vkEnumerateInstanceVersion")?
        .unwrap_or(vk::API_VERSION_1_0);
    // A 1.1 instance is enough for the *2 queries; ask for 1.3 where the loader has it.
    let api = if version >= vk::API_VERSION_1_3 {
        vk::API_VERSION_1_3
    } else {
        vk::API_VERSION_1_1.min(version)
    };
    let app = vk::ApplicationInfo::default()
        .application_name(c"verisplat doctor")
        .engine_name(c"verisplat")
        .api_version(api);
    let info = vk::InstanceCreateInfo::default().application_info(&app);
    // SAFETY: the create info and what it points at live until the call returns.
    let instance = unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?;
    // Destroys the instance however this function returns.
    struct Guard(ash::Instance);
    impl Drop for Guard {
        fn drop(&mut self) {
            // SAFETY: nothing created from the instance outlives this function.
            unsafe { self.0.destroy_instance(None) };
        }
    }
    let guard = Guard(instance);
    let instance = &guard.0;
    // SAFETY: plain query.
    let physical =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    physical
        .iter()
        .enumerate()
        .map(|(index, &pd)| describe(instance, index, pd))
        .collect()
}

fn describe(
    instance: &ash::Instance,
    index: usize,
    pd: vk::PhysicalDevice,
) -> GpuResult<DeviceSummary> {
    // SAFETY (every query below): `pd` comes from vkEnumeratePhysicalDevices of
    // `instance`, and each chain is of valid structs that live across the call.
    let props = unsafe { instance.get_physical_device_properties(pd) };
    let modern = props.api_version >= vk::API_VERSION_1_3;
    let exts = unsafe { instance.enumerate_device_extension_properties(pd) }
        .vk("vkEnumerateDeviceExtensionProperties")?;
    let has_ext = |name| capabilities::has_extension(&exts, name);
    let mut props11 = vk::PhysicalDeviceVulkan11Properties::default();
    let mut props12 = vk::PhysicalDeviceVulkan12Properties::default();
    let mut props13 = vk::PhysicalDeviceVulkan13Properties::default();
    let mut features12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut features13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
    if props.api_version >= vk::API_VERSION_1_2 {
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut props11)
            .push_next(&mut props12);
        if modern {
            props2 = props2.push_next(&mut props13);
        }
        unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
        let mut features2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut features12);
        if modern {
            features2 = features2.push_next(&mut features13);
        }
        if has_ext(ash::ext::shader_atomic_float::NAME) {
            features2 = features2.push_next(&mut atomic_float);
        }
        unsafe { instance.get_physical_device_features2(pd, &mut features2) };
    }
    let budget_ext = has_ext(ash::ext::memory_budget::NAME);
    let mut budget = vk::PhysicalDeviceMemoryBudgetPropertiesEXT::default();
    let mut mem2 = vk::PhysicalDeviceMemoryProperties2::default();
    if budget_ext {
        mem2 = mem2.push_next(&mut budget);
    }
    unsafe { instance.get_physical_device_memory_properties2(pd, &mut mem2) };
    let mem = mem2.memory_properties;
    let heaps = (0..mem.memory_heap_count as usize)
        .map(|i| HeapSummary {
            size: mem.memory_heaps[i].size,
            device_local: mem.memory_heaps[i]
                .flags
                .contains(vk::MemoryHeapFlags::DEVICE_LOCAL),
            budget: budget_ext.then_some(budget.heap_budget[i]),
            usage: budget_ext.then_some(budget.heap_usage[i]),
        })
        .collect();
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let compute = families
        .iter()
        .find(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE));

    let missing: Vec<String> = capabilities::missing(
        props.api_version,
        compute.is_some(),
        &exts,
        &props11,
        &features13,
    )
    .iter()
    .map(|lack| lack.to_string())
    .collect();
    let limits = props.limits;
    Ok(DeviceSummary {
        index,
        name: cstr_array(&props.device_name),
        device_type: type_name(props.device_type).to_string(),
        driver_name: cstr_array(&props12.driver_name),
        driver_info: cstr_array(&props12.driver_info),
        api_version: version_string(props.api_version),
        subgroup_size: props11.subgroup_size,
        min_subgroup_size: props13.min_subgroup_size,
        max_subgroup_size: props13.max_subgroup_size,
        subgroup_operations: subgroup_operation_names(props11.subgroup_supported_operations),
        max_shared_memory: limits.max_compute_shared_memory_size,
        max_workgroup_invocations: limits.max_compute_work_group_invocations,
        max_workgroup_count: limits.max_compute_work_group_count,
        max_storage_buffer_range: limits.max_storage_buffer_range,
        timestamp_period_ns: limits.timestamp_period,
        timestamp_valid_bits: compute.map_or(0, |f| f.timestamp_valid_bits),
        float32_atomic_add: atomic_float.shader_buffer_float32_atomic_add == vk::TRUE,
        int64_atomics: features12.shader_buffer_int64_atomics == vk::TRUE,
        heaps,
        memory_budget_ext: budget_ext,
        usable: missing.is_empty(),
        missing,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subgroup_operations_are_named_in_order() {
        let flags = vk::SubgroupFeatureFlags::BALLOT | vk::SubgroupFeatureFlags::BASIC;
        assert_eq!(subgroup_operation_names(flags), ["basic", "ballot"]);
    }
}
