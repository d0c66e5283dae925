//! Which physical device a context opens: the one `--device` / `VERISPLAT_DEVICE` names
//! (an index or part of a name), else the usable one of the best type (discrete, then
//! integrated, virtual, CPU); usable means Vulkan 1.3 and a compute queue.

use ash::vk;

use super::capabilities::cstr_array;
use super::{GpuError, GpuResult, VkContext};

/// The device a `--device` choice names: a whole number is an index and only an index
/// (`1` never matches the digits in "LLVM 15"); anything else matches a device whose
/// name contains it, ignoring case. `None` when nothing matches.
pub fn select_device(choice: &str, names: &[String]) -> Option<usize> {
    let choice = choice.trim();
    if let Ok(index) = choice.parse::<usize>() {
        return (index < names.len()).then_some(index);
    }
    let lower = choice.to_lowercase();
    if lower.is_empty() {
        return None;
    }
    names.iter().position(|n| n.to_lowercase().contains(&lower))
}

fn type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

/// The chosen device and what choosing it read.
pub(crate) struct ChosenDevice {
    /// Index among the enumerated physical devices.
    pub(crate) index: usize,
    pub(crate) physical_device: vk::PhysicalDevice,
    /// The chosen device's properties.
    pub(crate) props: vk::PhysicalDeviceProperties,
    /// Every device's name, by index.
    pub(crate) names: Vec<String>,
    /// The first queue family with compute, and its timestamps' valid bits.
    pub(crate) queue_family: u32,
    pub(crate) timestamp_valid_bits: u32,
    /// Indices of the usable devices of the chosen one's type, it included.
    pub(crate) same_kind_devices: Vec<usize>,
}

/// Enumerates the devices and chooses one: the one `choice` names, or the best usable one.
pub(crate) fn choose(instance: &ash::Instance, choice: Option<&str>) -> GpuResult<ChosenDevice> {
    // SAFETY: plain query.
    let physical_devices =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    if physical_devices.is_empty() {
        return Err(GpuError::NoDevice(
            "the Vulkan loader reports no devices".into(),
        ));
    }
    let props: Vec<vk::PhysicalDeviceProperties> = physical_devices
        .iter()
        // SAFETY: handles come from enumerate_physical_devices.
        .map(|&pd| unsafe { instance.get_physical_device_properties(pd) })
        .collect();
    let names: Vec<String> = props.iter().map(|p| cstr_array(&p.device_name)).collect();
    let compute_family = |pd: vk::PhysicalDevice| {
        // SAFETY: valid physical device handle.
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        families
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .map(|i| (i as u32, families[i].timestamp_valid_bits))
    };
    let usable = |i: usize| {
        props[i].api_version >= vk::API_VERSION_1_3 && compute_family(physical_devices[i]).is_some()
    };
    let index = match choice {
        Some(choice) => named_device(choice, &names, usable)?,
        None => (0..names.len())
            .filter(|&i| usable(i))
            .min_by_key(|&i| type_rank(props[i].device_type))
            .ok_or_else(|| {
                GpuError::NoDevice(format!(
                    "none of [{}] supports Vulkan 1.3 with a compute queue",
                    names.join(", ")
                ))
            })?,
    };
    let physical_device = physical_devices[index];
    let (queue_family, timestamp_valid_bits) = compute_family(physical_device)
        .ok_or_else(|| GpuError::NoDevice("no compute queue".into()))?;
    let same_kind_devices = (0..names.len())
        .filter(|&i| usable(i) && props[i].device_type == props[index].device_type)
        .collect();
    Ok(ChosenDevice {
        index,
        physical_device,
        props: props[index],
        names,
        queue_family,
        timestamp_valid_bits,
        same_kind_devices,
    })
}

/// The index of the device `choice` names, refused when it is not usable or when no
/// device matches (listing the devices there are).
fn named_device(
    choice: &str,
    names: &[String],
    usable: impl Fn(usize) -> bool,
) -> GpuResult<usize> {
    match select_device(choice, names) {
        Some(i) if usable(i) => Ok(i),
        Some(i) => Err(GpuError::NoDevice(format!(
            "device '{}' lacks Vulkan 1.3 or a compute queue",
            names[i]
        ))),
        None => {
            let what = if choice.trim().parse::<usize>().is_ok() {
                format!("there is no device #{}", choice.trim())
            } else {
                format!("no device name contains '{choice}'")
            };
            Err(GpuError::NoDevice(format!(
                "{what}; available: {}",
                names
                    .iter()
                    .enumerate()
                    .map(|(i, n)| format!("#{i} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::select_device;

    #[test]
    fn a_number_is_only_an_index_and_a_name_only_a_name() {
        let names = vec![
            "llvmpipe (LLVM 15.0.6, 256 bits)".to_string(),
            "NVIDIA H100".to_string(),
        ];
        assert_eq!(select_device("0", &names), Some(0));
        assert_eq!(select_device("1", &names), Some(1));
        // An index past the end does not fall back to the digits in "LLVM 15".
        assert_eq!(select_device("15", &names), None);
        assert_eq!(select_device("2", &names), None);
        assert_eq!(select_device("nvidia", &names), Some(1));
        assert_eq!(select_device("LLVMpipe", &names), Some(0));
        assert_eq!(select_device("radeon", &names), None);
        assert_eq!(select_device("", &names), None);
    }
}
