//! Opening the chosen physical device: refusing it when it lacks what verisplat needs
//! ([`super::capabilities`]), the features and extensions enabled (float and 64-bit
//! integer atomics where the device has them), the one compute queue, and the allocator
//! and pipeline cache created on the new device.

use std::path::PathBuf;

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::capabilities::{self, has_extension, Lack};
use super::device_choice::ChosenDevice;
use super::device_info::DeviceProperties;
use super::pipeline_cache::{self, CacheIdentity};
use super::{GpuError, GpuResult, VkContext};

/// The optional features the device has and the context enables.
pub(crate) struct EnabledFeatures {
    /// computeFullSubgroups (with subgroup size control).
    pub(crate) full_subgroups: bool,
    /// `shaderBufferFloat32AtomicAdd` (VK_EXT_shader_atomic_float).
    pub(crate) float_atomic_add: bool,
    /// `shaderBufferInt64Atomics` and `shaderInt64` (the gradient accumulation's 64-bit
    /// fixed-point adds).
    pub(crate) int64_atomics: bool,
}

/// Refuses the device when it lacks a needed feature or extension (naming the first of
/// subgroup operations, synchronization2, maintenance4, push descriptors that it lacks)
/// and reads the optional features it has.
pub(crate) fn check_features(
    instance: &ash::Instance,
    chosen: &ChosenDevice,
    properties: &DeviceProperties,
    name: &str,
) -> GpuResult<EnabledFeatures> {
    let physical_device = chosen.physical_device;
    let mut features12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut features13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut features2 = vk::PhysicalDeviceFeatures2::default()
        .push_next(&mut features12)
        .push_next(&mut features13);
    // SAFETY: valid handle, chain of valid structs.
    unsafe { instance.get_physical_device_features2(physical_device, &mut features2) };
    let shader_int64 = features2.features.shader_int64 == vk::TRUE;
    // SAFETY: plain query.
    let device_exts = unsafe { instance.enumerate_device_extension_properties(physical_device) }
        .vk("vkEnumerateDeviceExtensionProperties")?;
    let lacks = capabilities::missing(
        chosen.props.api_version,
        true,
        &device_exts,
        &properties.props11,
        &features13,
    );
    let int64_atomics = shader_int64 && features12.shader_buffer_int64_atomics == vk::TRUE;
    let first_lack = [
        Lack::SubgroupOperations,
        Lack::Synchronization2,
        Lack::Maintenance4,
        Lack::PushDescriptor,
    ]
    .into_iter()
    .find(|l| lacks.contains(l));
    if let Some(lack) = first_lack {
        return Err(GpuError::Missing(format!("{name} lacks {lack}")));
    }
    // Float atomics, where the device has them (the backward pass's fast mode).
    let mut atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
    if has_extension(&device_exts, ash::ext::shader_atomic_float::NAME) {
        let mut query = vk::PhysicalDeviceFeatures2::default().push_next(&mut atomic_float);
        // SAFETY: valid handle, chain of valid structs.
        unsafe { instance.get_physical_device_features2(physical_device, &mut query) };
    }
    Ok(EnabledFeatures {
        full_subgroups: features13.compute_full_subgroups == vk::TRUE,
        float_atomic_add: atomic_float.shader_buffer_float32_atomic_add == vk::TRUE,
        int64_atomics,
    })
}

/// Creates the logical device with one compute queue of `chosen`'s compute family, push
/// descriptors, synchronization2, maintenance4 and the optional `features`.
pub(crate) fn create_device(
    instance: &ash::Instance,
    chosen: &ChosenDevice,
    features: &EnabledFeatures,
) -> GpuResult<ash::Device> {
    let full_subgroups = features.full_subgroups;
    let mut device_ext_names = vec![ash::khr::push_descriptor::NAME.as_ptr()];
    let mut enable_atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default()
        .shader_buffer_float32_atomic_add(features.float_atomic_add);
    if features.float_atomic_add {
        device_ext_names.push(ash::ext::shader_atomic_float::NAME.as_ptr());
    }
    let priorities = [1.0f32];
    let queue_infos = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(chosen.queue_family)
        .queue_priorities(&priorities)];
    let mut enable13 = vk::PhysicalDeviceVulkan13Features::default()
        .synchronization2(true)
        // glslang emits LocalSizeId for SPIR-V 1.6, which needs maintenance4.
        .maintenance4(true)
        .subgroup_size_control(full_subgroups)
        .compute_full_subgroups(full_subgroups);
    let enable10 = vk::PhysicalDeviceFeatures::default().shader_int64(features.int64_atomics);
    let mut enable12 = vk::PhysicalDeviceVulkan12Features::default()
        .shader_buffer_int64_atomics(features.int64_atomics);
    let mut device_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_infos)
        .enabled_extension_names(&device_ext_names)
        .enabled_features(&enable10)
        .push_next(&mut enable12)
        .push_next(&mut enable13);
    if features.float_atomic_add {
        device_info = device_info.push_next(&mut enable_atomic_float);
    }
    // SAFETY: valid physical device and create info.
    unsafe { instance.create_device(chosen.physical_device, &device_info, None) }
        .vk("vkCreateDevice")
}

/// The allocator and the pipeline cache of a new `device`.
pub(crate) struct DeviceMemory {
    pub(crate) allocator: Allocator,
    pub(crate) pipeline_cache: vk::PipelineCache,
    /// Where the cache is written back, its identity and the bytes it was loaded with.
    pub(crate) pipeline_cache_file: Option<(PathBuf, CacheIdentity, usize)>,
}

/// Creates the allocator and the pipeline cache (seeded from disk when this driver build
/// wrote one); destroys `device` when either fails.
pub(crate) fn allocator_and_cache(
    instance: &ash::Instance,
    device: &ash::Device,
    chosen: &ChosenDevice,
) -> GpuResult<DeviceMemory> {
    let allocator = match Allocator::new(&AllocatorCreateDesc {
        instance: instance.clone(),
        device: device.clone(),
        physical_device: chosen.physical_device,
        debug_settings: Default::default(),
        buffer_device_address: false,
        allocation_sizes: Default::default(),
    }) {
        Ok(a) => a,
        Err(e) => {
            // SAFETY: nothing else was created from the device yet.
            unsafe { device.destroy_device(None) };
            return Err(GpuError::Missing(format!("gpu-allocator: {e}")));
        }
    };
    // The pipeline cache, seeded from disk when this driver build wrote one.
    let base_props = chosen.props;
    let identity = CacheIdentity {
        vendor_id: base_props.vendor_id,
        device_id: base_props.device_id,
        uuid: base_props.pipeline_cache_uuid,
    };
    let cache_dir = pipeline_cache::cache_dir();
    let initial = cache_dir
        .as_deref()
        .and_then(|dir| pipeline_cache::load(dir, &identity))
        .unwrap_or_default();
    let cache_info = vk::PipelineCacheCreateInfo::default().initial_data(&initial);
    // SAFETY: valid device; the initial data's header was checked against this device
    // (drivers also check it and ignore data they cannot use).
    let pipeline_cache = match unsafe { device.create_pipeline_cache(&cache_info, None) } {
        Ok(cache) => cache,
        Err(result) => {
            drop(allocator);
            // SAFETY: nothing else was created from the device yet.
            unsafe { device.destroy_device(None) };
            return Err(GpuError::Vk {
                call: "vkCreatePipelineCache",
                result,
            });
        }
    };
    let pipeline_cache_file = cache_dir.map(|dir| (dir, identity, initial.len()));
    Ok(DeviceMemory {
        allocator,
        pipeline_cache,
        pipeline_cache_file,
    })
}
