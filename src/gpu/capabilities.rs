//! What verisplat needs of a device (Vulkan 1.3, a compute queue, push descriptors,
//! synchronization2, maintenance4, basic/arithmetic/ballot subgroup operations) and the
//! one function that lists what a device lacks of it, for the context that refuses a
//! device and for `verisplat doctor`'s listing ([`super::devices`]); plus the helpers both
//! read driver strings and extension lists with.

use std::ffi::CStr;

use ash::vk;

/// The subgroup operation classes every kernel may use.
pub(crate) const NEEDED_SUBGROUP_OPS: vk::SubgroupFeatureFlags = vk::SubgroupFeatureFlags::from_raw(
    vk::SubgroupFeatureFlags::BASIC.as_raw()
        | vk::SubgroupFeatureFlags::ARITHMETIC.as_raw()
        | vk::SubgroupFeatureFlags::BALLOT.as_raw(),
);

/// One thing verisplat needs that a device lacks; `Display` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Lack {
    /// Vulkan 1.3 (the device's version).
    Vulkan13 { has: u32 },
    /// A queue family with compute.
    ComputeQueue,
    /// VK_KHR_push_descriptor.
    PushDescriptor,
    /// The synchronization2 feature.
    Synchronization2,
    /// The maintenance4 feature.
    Maintenance4,
    /// Basic/arithmetic/ballot subgroup operations in compute shaders.
    SubgroupOperations,
}

impl std::fmt::Display for Lack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Lack::Vulkan13 { has } => write!(f, "Vulkan 1.3 (it has {})", version_string(*has)),
            Lack::ComputeQueue => f.write_str("a compute queue"),
            Lack::PushDescriptor => f.write_str("VK_KHR_push_descriptor"),
            Lack::Synchronization2 => f.write_str("synchronization2"),
            Lack::Maintenance4 => f.write_str("maintenance4"),
            Lack::SubgroupOperations => {
                f.write_str("basic/arithmetic/ballot subgroup operations in compute shaders")
            }
        }
    }
}

/// Everything verisplat needs that a device lacks, in the order `verisplat doctor` lists them:
/// from its Vulkan version, whether it has a compute queue, its extensions, its
/// Vulkan 1.1 properties and its Vulkan 1.3 features (as queried; default when the device
/// is too old to report them).
pub(crate) fn missing(
    api_version: u32,
    compute_queue: bool,
    extensions: &[vk::ExtensionProperties],
    props11: &vk::PhysicalDeviceVulkan11Properties<'_>,
    features13: &vk::PhysicalDeviceVulkan13Features<'_>,
) -> Vec<Lack> {
    let mut lacks = Vec::new();
    if api_version < vk::API_VERSION_1_3 {
        lacks.push(Lack::Vulkan13 { has: api_version });
    }
    if !compute_queue {
        lacks.push(Lack::ComputeQueue);
    }
    if !has_extension(extensions, ash::khr::push_descriptor::NAME) {
        lacks.push(Lack::PushDescriptor);
    }
    if features13.synchronization2 == vk::FALSE {
        lacks.push(Lack::Synchronization2);
    }
    if features13.maintenance4 == vk::FALSE {
        lacks.push(Lack::Maintenance4);
    }
    if !props11
        .subgroup_supported_operations
        .contains(NEEDED_SUBGROUP_OPS)
        || !props11
            .subgroup_supported_stages
            .contains(vk::ShaderStageFlags::COMPUTE)
    {
        lacks.push(Lack::SubgroupOperations);
    }
    lacks
}

/// Whether `extensions` lists `name`.
pub(crate) fn has_extension(extensions: &[vk::ExtensionProperties], name: &CStr) -> bool {
    extensions
        .iter()
        .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
}

pub(crate) fn cstr_array(bytes: &[std::ffi::c_char]) -> String {
    // Fixed-size, NUL-terminated by the driver; stop at the array end regardless.
    let bytes: Vec<u8> = bytes
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

pub(crate) fn version_string(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}
