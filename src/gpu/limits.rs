//! The device limits that shape work, each decided here from [`DeviceInfo`] (which holds
//! the emulated limits when [`super::emulate`] clamps them): how many bytes one storage
//! binding covers (maxStorageBufferRange) and how a dispatch's workgroups are laid out
//! (maxComputeWorkGroupCount).

use super::{DeviceInfo, GpuError, GpuResult};

/// Bytes one storage-buffer binding may cover (maxStorageBufferRange).
pub fn storage_binding_bytes(info: &DeviceInfo) -> u64 {
    u64::from(info.max_storage_buffer_range)
}

/// Elements of `element_bytes` each that one storage binding holds.
pub fn elements_per_binding(info: &DeviceInfo, element_bytes: u64) -> u64 {
    storage_binding_bytes(info) / element_bytes.max(1)
}

/// Refuses `bytes` in one storage binding beyond maxStorageBufferRange, with a
/// [`GpuError::DeviceLimit`] naming `what` and saying what to do (`advice`).
pub fn check_binding(info: &DeviceInfo, what: &str, bytes: u64, advice: &str) -> GpuResult<()> {
    check_binding_bytes(storage_binding_bytes(info), what, bytes, advice)
}

/// [`check_binding`] against a binding of `max` bytes.
pub fn check_binding_bytes(max: u64, what: &str, bytes: u64, advice: &str) -> GpuResult<()> {
    if bytes > max {
        return Err(GpuError::DeviceLimit {
            limit: "maxStorageBufferRange",
            needed: bytes,
            max,
            message: format!(
                "{what} needs {bytes} bytes in one storage buffer, but this device binds at most {max} bytes (maxStorageBufferRange); {advice}"
            ),
        });
    }
    Ok(())
}

/// The x/y grid of `groups` workgroups within maxComputeWorkGroupCount: x at most the
/// device's limit, y what it takes ([`super::dispatch_grid`]; shaders recover the linear
/// id as `x + y * gl_NumWorkGroups.x` and ignore ids past the end). A
/// [`GpuError::DeviceLimit`] when even the grid exceeds the limit.
pub fn dispatch_groups(info: &DeviceInfo, what: &str, groups: u64) -> GpuResult<[u32; 3]> {
    let [max_x, max_y, _] = info.max_workgroup_count;
    let max = u64::from(max_x.max(1)) * u64::from(max_y.max(1));
    if groups > max {
        return Err(GpuError::DeviceLimit {
            limit: "maxComputeWorkGroupCount",
            needed: groups,
            max,
            message: format!(
                "{what} needs {groups} workgroups, more than the {max_x} x {max_y} this device dispatches at once (maxComputeWorkGroupCount); use a smaller input"
            ),
        });
    }
    Ok(super::dispatch_grid(groups as u32, max_x.max(1)))
}

/// Refuses a dispatch of `groups` beyond maxComputeWorkGroupCount (the validation layer
/// checks the driver's limits, not emulated ones).
pub fn check_dispatch(info: &DeviceInfo, what: &str, groups: [u32; 3]) -> GpuResult<()> {
    for (axis, (&n, &max)) in groups.iter().zip(&info.max_workgroup_count).enumerate() {
        if n > max {
            return Err(GpuError::DeviceLimit {
                limit: "maxComputeWorkGroupCount",
                needed: u64::from(n),
                max: u64::from(max),
                message: format!(
                    "{what} dispatches {n} workgroups along {}, more than this device's {max} (maxComputeWorkGroupCount)",
                    ["x", "y", "z"][axis]
                ),
            });
        }
    }
    Ok(())
}
