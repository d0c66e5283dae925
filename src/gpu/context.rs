//! Vulkan instance, device, queue, command pool and allocator, plus validation plumbing.

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::pipeline_cache::{self, CacheIdentity};
use super::{GpuError, GpuResult, VkContext};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// How to create a [`GpuContext`].
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Device index or case-insensitive substring of its name; `VKSPLAT_DEVICE` overrides
    /// when this is `None`.
    pub device: Option<String>,
    /// Enable VK_LAYER_KHRONOS_validation (with synchronization validation when
    /// available); `VKSPLAT_VALIDATE=1` also turns it on.
    pub validation: bool,
    /// Device memory this context may allocate, in bytes; `VKSPLAT_MEMORY_LIMIT` (e.g.
    /// `512M`, `2G`) sets it when `None`. The default is the size of the largest
    /// device-local heap, which is also the ceiling on GPUs; on CPU devices, whose device
    /// memory is host memory, it is 3/4 of the host memory available when that is more,
    /// and a larger explicit limit is honoured.
    pub memory_limit: Option<u64>,
    /// Device traits to pretend ([`super::emulate`]); `VKSPLAT_EMULATE` adds to them.
    pub emulate: super::emulate::Emulation,
}

/// Parses a byte count: a number with an optional K, M, G or T suffix (powers of 1024).
pub fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let (num, mult) = match t.chars().last().map(|c| c.to_ascii_uppercase()) {
        Some('K') => (&t[..t.len() - 1], 1u64 << 10),
        Some('M') => (&t[..t.len() - 1], 1 << 20),
        Some('G') => (&t[..t.len() - 1], 1 << 30),
        Some('T') => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    num.trim()
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(mult))
        .ok_or_else(|| format!("\"{text}\" is not a byte count (e.g. 536870912, 512M, 2G)"))
}

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
    /// Device memory this context allows itself (see [`ContextOptions::memory_limit`]).
    pub memory_budget: u64,
    /// Where [`Self::memory_budget`] comes from.
    pub budget_source: BudgetSource,
    /// Float atomic add on storage buffers (`VK_EXT_shader_atomic_float`'s
    /// `shaderBufferFloat32AtomicAdd`), enabled when the device has it: the backward pass's
    /// opt-in fast accumulation uses it.
    pub float_atomic_add: bool,
    /// The device traits pretended ([`super::emulate`]): the limits above already
    /// include them.
    pub emulation: super::emulate::Emulation,
    /// Indices of the usable devices (Vulkan 1.3, a compute queue) of this device's type,
    /// this one included: the devices `render --devices all` spreads frames over.
    pub same_kind_devices: Vec<usize>,
}

/// Where a context's device-memory budget comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BudgetSource {
    /// [`ContextOptions::memory_limit`] or `VKSPLAT_MEMORY_LIMIT`.
    Limit,
    /// The largest device-local heap the driver advertises.
    Heap,
    /// Three quarters of the host memory available when the context was made (a CPU
    /// device, whose device memory is host memory, without an explicit limit).
    HostAvailable,
}

impl BudgetSource {
    /// What the budget is, for `-v`.
    pub fn describe(self) -> &'static str {
        match self {
            BudgetSource::Limit => "the explicit memory limit",
            BudgetSource::Heap => "the largest device-local heap",
            BudgetSource::HostAvailable => {
                "3/4 of the host memory available (a CPU device's memory is host memory; \
                 --memory-limit sets another)"
            }
        }
    }
}

/// `MemAvailable` of `/proc/meminfo` in bytes (Linux), if it can be read.
pub fn host_available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
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

type MessageLog = Arc<Mutex<Vec<String>>>;

/// Objects that must outlive every buffer and pipeline; shared through an `Arc` so
/// RAII resources can free themselves, and torn down in the right order last.
pub(crate) struct Shared {
    _entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    debug_instance: Option<ash::ext::debug_utils::Instance>,
    messenger: vk::DebugUtilsMessengerEXT,
    /// Owns the log the messenger callback writes through a raw pointer.
    _callback_log: Option<Box<MessageLog>>,
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
    pipeline_cache_file: Option<(PathBuf, CacheIdentity, usize)>,
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
    command_pool: Mutex<vk::CommandPool>,
    info: DeviceInfo,
    messages: MessageLog,
    validation: bool,
    /// computeFullSubgroups is enabled: pipelines may require full subgroups.
    pub(crate) full_subgroups: bool,
}

/// Records and prints every WARNING/ERROR message of the validation layer.
///
/// # Safety
/// Called by the Vulkan loader with valid callback data and the `user` pointer given
/// at messenger creation (a `*const MessageLog` that outlives the messenger).
unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes valid callback data for the duration of the call.
    let message = unsafe {
        data.as_ref()
            .filter(|d| !d.p_message.is_null())
            .map(|d| CStr::from_ptr(d.p_message).to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let text = format!("[vulkan {severity:?} {types:?}] {message}");
    crate::note!("{text}");
    // SAFETY: `user` points at the boxed MessageLog owned by `Shared`, which outlives
    // the messenger (and the instance whose creation/destruction it also watches).
    if let Some(log) = unsafe { (user as *const MessageLog).as_ref() } {
        if let Ok(mut log) = log.lock() {
            log.push(text);
        }
    }
    vk::FALSE
}

fn env_flag(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| !v.is_empty() && v != "0")
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

impl GpuContext {
    /// Creates the context: instance, device selection, queue, pool and allocator.
    pub fn new(options: &ContextOptions) -> GpuResult<Self> {
        let validation = options.validation || env_flag("VKSPLAT_VALIDATE");
        let emulation = super::emulate::Emulation::from_env()
            .map_err(GpuError::Input)?
            .union(&options.emulate);
        let device_choice = options.device.clone().or_else(|| {
            std::env::var("VKSPLAT_DEVICE")
                .ok()
                .filter(|s| !s.is_empty())
        });

        // SAFETY: loading the system Vulkan loader; its entry points are trusted.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| GpuError::Loader(e.to_string()))?;
        // SAFETY: plain queries through a loaded entry.
        let version = unsafe { entry.try_enumerate_instance_version() }
            .vk("vkEnumerateInstanceVersion")?
            .unwrap_or(vk::API_VERSION_1_0);
        if version < vk::API_VERSION_1_3 {
            return Err(GpuError::Missing(format!(
                "Vulkan 1.3 instance needed, loader offers {}",
                version_string(version)
            )));
        }
        // SAFETY: plain query.
        let instance_exts = unsafe { entry.enumerate_instance_extension_properties(None) }
            .vk("vkEnumerateInstanceExtensionProperties")?;
        let has_ext = |exts: &[vk::ExtensionProperties], name: &CStr| {
            exts.iter()
                .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
        };
        let mut layers = Vec::new();
        let mut extensions = Vec::new();
        let mut sync_validation = false;
        if validation {
            // SAFETY: plain query.
            let available = unsafe { entry.enumerate_instance_layer_properties() }
                .vk("vkEnumerateInstanceLayerProperties")?;
            if !available
                .iter()
                .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER))
            {
                return Err(GpuError::Missing(
                    "validation requested but VK_LAYER_KHRONOS_validation is not installed \
                     (apt-get install vulkan-validationlayers)"
                        .into(),
                ));
            }
            layers.push(VALIDATION_LAYER.as_ptr());
            // SAFETY: plain query of the layer's own extensions.
            let layer_exts =
                unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
                    .vk("vkEnumerateInstanceExtensionProperties(layer)")?;
            if has_ext(&layer_exts, ash::ext::validation_features::NAME) {
                extensions.push(ash::ext::validation_features::NAME.as_ptr());
                sync_validation = true;
            }
        }
        let debug_utils = has_ext(&instance_exts, ash::ext::debug_utils::NAME);
        if debug_utils {
            extensions.push(ash::ext::debug_utils::NAME.as_ptr());
        }

        let messages: MessageLog = Arc::new(Mutex::new(Vec::new()));
        let callback_log = (validation && debug_utils).then(|| Box::new(messages.clone()));
        let user_data = callback_log.as_ref().map_or(std::ptr::null_mut(), |b| {
            &**b as *const MessageLog as *mut c_void
        });
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(debug_callback))
            .user_data(user_data);
        let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut validation_features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);

        let app = vk::ApplicationInfo::default()
            .application_name(c"vksplat")
            .engine_name(c"vksplat")
            .api_version(vk::API_VERSION_1_3);
        let mut instance_info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers)
            .enabled_extension_names(&extensions);
        if callback_log.is_some() {
            instance_info = instance_info.push_next(&mut messenger_info);
        }
        if sync_validation {
            instance_info = instance_info.push_next(&mut validation_features);
        }
        // SAFETY: all pointers in the create info live until the call returns.
        let instance =
            unsafe { entry.create_instance(&instance_info, None) }.vk("vkCreateInstance")?;

        // From here on, failures must destroy what was created; a guard does that.
        struct InstanceGuard(
            Option<(
                ash::Instance,
                Option<ash::ext::debug_utils::Instance>,
                vk::DebugUtilsMessengerEXT,
            )>,
        );
        impl Drop for InstanceGuard {
            fn drop(&mut self) {
                if let Some((instance, debug, messenger)) = self.0.take() {
                    // SAFETY: nothing created from the instance survives a failed setup.
                    unsafe {
                        if let Some(debug) = debug {
                            if messenger != vk::DebugUtilsMessengerEXT::null() {
                                debug.destroy_debug_utils_messenger(messenger, None);
                            }
                        }
                        instance.destroy_instance(None);
                    }
                }
            }
        }
        let debug_instance =
            debug_utils.then(|| ash::ext::debug_utils::Instance::new(&entry, &instance));
        let mut guard = InstanceGuard(Some((
            instance.clone(),
            debug_instance.clone(),
            vk::DebugUtilsMessengerEXT::null(),
        )));
        let messenger = match (&debug_instance, &callback_log) {
            (Some(debug), Some(_)) => {
                // SAFETY: valid create info; destroyed in Shared::drop or the guard.
                let m = unsafe { debug.create_debug_utils_messenger(&messenger_info, None) }
                    .vk("vkCreateDebugUtilsMessengerEXT")?;
                if let Some(g) = guard.0.as_mut() {
                    g.2 = m;
                }
                m
            }
            _ => vk::DebugUtilsMessengerEXT::null(),
        };

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
            props[i].api_version >= vk::API_VERSION_1_3
                && compute_family(physical_devices[i]).is_some()
        };
        let index = match &device_choice {
            Some(choice) => match select_device(choice, &names) {
                Some(i) if usable(i) => i,
                Some(i) => {
                    return Err(GpuError::NoDevice(format!(
                        "device '{}' lacks Vulkan 1.3 or a compute queue",
                        names[i]
                    )))
                }
                None => {
                    let what = if choice.trim().parse::<usize>().is_ok() {
                        format!("there is no device #{}", choice.trim())
                    } else {
                        format!("no device name contains '{choice}'")
                    };
                    return Err(GpuError::NoDevice(format!(
                        "{what}; available: {}",
                        names
                            .iter()
                            .enumerate()
                            .map(|(i, n)| format!("#{i} {n}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )));
                }
            },
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

        // Device properties and features.
        let mut props11 = vk::PhysicalDeviceVulkan11Properties::default();
        let mut props12 = vk::PhysicalDeviceVulkan12Properties::default();
        let mut props13 = vk::PhysicalDeviceVulkan13Properties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut props11)
            .push_next(&mut props12)
            .push_next(&mut props13);
        // SAFETY: valid handle, chain of valid structs.
        unsafe { instance.get_physical_device_properties2(physical_device, &mut props2) };
        let limits = props[index].limits;
        // SAFETY: valid handle.
        let mem = unsafe { instance.get_physical_device_memory_properties(physical_device) };
        let device_local_bytes = mem.memory_heaps[..mem.memory_heap_count as usize]
            .iter()
            .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
            .map(|h| h.size)
            .max()
            .unwrap_or(0);
        let limit = match options.memory_limit {
            Some(l) => Some(l),
            None => match std::env::var("VKSPLAT_MEMORY_LIMIT") {
                Ok(v) if !v.trim().is_empty() => Some(
                    parse_bytes(&v)
                        .map_err(|e| GpuError::Input(format!("VKSPLAT_MEMORY_LIMIT: {e}")))?,
                ),
                _ => None,
            },
        };
        // On a CPU implementation device memory is host memory and the advertised heap is
        // only a figure (lavapipe: 2 GiB), so an explicit limit may go beyond it; on a GPU
        // the heap caps it.
        let host_memory = props[index].device_type == vk::PhysicalDeviceType::CPU;
        let (memory_budget, budget_source) = match limit {
            Some(l) if host_memory => (l, BudgetSource::Limit),
            Some(l) => (l.min(device_local_bytes), BudgetSource::Limit),
            // A CPU device's scene fits where the host's memory does: the budget follows
            // what the host has available, not the figure the driver advertises.
            None if host_memory => match host_available_bytes() {
                Some(available) if available / 4 * 3 > device_local_bytes => {
                    (available / 4 * 3, BudgetSource::HostAvailable)
                }
                _ => (device_local_bytes, BudgetSource::Heap),
            },
            None => (device_local_bytes, BudgetSource::Heap),
        };
        let mut info = DeviceInfo {
            index,
            name: names[index].clone(),
            device_type: props[index].device_type,
            driver: format!(
                "{} {}",
                cstr_array(&props12.driver_name),
                cstr_array(&props12.driver_info)
            ),
            api_version: version_string(props[index].api_version),
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
            timestamp_valid_bits,
            device_local_bytes,
            non_coherent_atom_size: limits.non_coherent_atom_size.max(1),
            memory_types: mem.memory_types[..mem.memory_type_count as usize]
                .iter()
                .map(|t| t.property_flags)
                .collect(),
            memory_budget,
            budget_source,
            float_atomic_add: false,
            emulation: Default::default(),
            same_kind_devices: (0..names.len())
                .filter(|&i| usable(i) && props[i].device_type == props[index].device_type)
                .collect(),
        };
        let needed_ops = vk::SubgroupFeatureFlags::BASIC
            | vk::SubgroupFeatureFlags::ARITHMETIC
            | vk::SubgroupFeatureFlags::BALLOT;
        if !props11.subgroup_supported_operations.contains(needed_ops)
            || !props11
                .subgroup_supported_stages
                .contains(vk::ShaderStageFlags::COMPUTE)
        {
            return Err(GpuError::Missing(format!(
                "{} lacks basic/arithmetic/ballot subgroup operations in compute shaders",
                info.name
            )));
        }

        let mut features13 = vk::PhysicalDeviceVulkan13Features::default();
        let mut features2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut features13);
        // SAFETY: valid handle, chain of valid structs.
        unsafe { instance.get_physical_device_features2(physical_device, &mut features2) };
        if features13.synchronization2 == vk::FALSE {
            return Err(GpuError::Missing(format!(
                "{} lacks synchronization2",
                info.name
            )));
        }
        if features13.maintenance4 == vk::FALSE {
            return Err(GpuError::Missing(format!(
                "{} lacks maintenance4",
                info.name
            )));
        }
        let full_subgroups = features13.compute_full_subgroups == vk::TRUE;
        // SAFETY: plain query.
        let device_exts =
            unsafe { instance.enumerate_device_extension_properties(physical_device) }
                .vk("vkEnumerateDeviceExtensionProperties")?;
        if !has_ext(&device_exts, ash::khr::push_descriptor::NAME) {
            return Err(GpuError::Missing(format!(
                "{} lacks VK_KHR_push_descriptor",
                info.name
            )));
        }
        // Float atomics, where the device has them (the backward pass's fast mode).
        let mut atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
        if has_ext(&device_exts, ash::ext::shader_atomic_float::NAME) {
            let mut query = vk::PhysicalDeviceFeatures2::default().push_next(&mut atomic_float);
            // SAFETY: valid handle, chain of valid structs.
            unsafe { instance.get_physical_device_features2(physical_device, &mut query) };
        }
        info.float_atomic_add = atomic_float.shader_buffer_float32_atomic_add == vk::TRUE;
        let mut device_ext_names = vec![ash::khr::push_descriptor::NAME.as_ptr()];
        let mut enable_atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default()
            .shader_buffer_float32_atomic_add(info.float_atomic_add);
        if info.float_atomic_add {
            device_ext_names.push(ash::ext::shader_atomic_float::NAME.as_ptr());
        }
        let priorities = [1.0f32];
        let queue_infos = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family)
            .queue_priorities(&priorities)];
        let mut enable13 = vk::PhysicalDeviceVulkan13Features::default()
            .synchronization2(true)
            // glslang emits LocalSizeId for SPIR-V 1.6, which needs maintenance4.
            .maintenance4(true)
            .subgroup_size_control(full_subgroups)
            .compute_full_subgroups(full_subgroups);
        let mut device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_infos)
            .enabled_extension_names(&device_ext_names)
            .push_next(&mut enable13);
        if info.float_atomic_add {
            device_info = device_info.push_next(&mut enable_atomic_float);
        }
        // SAFETY: valid physical device and create info.
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }
            .vk("vkCreateDevice")?;
        let debug_device =
            debug_utils.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        let push_descriptor = ash::khr::push_descriptor::Device::new(&instance, &device);
        let allocator = match Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
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
        let base_props = props[index];
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
        // Ownership of the instance/messenger moves into Shared.
        guard.0 = None;
        let shared = Arc::new(Shared {
            _entry: entry,
            instance,
            debug_instance,
            messenger,
            _callback_log: callback_log,
            device,
            debug_device,
            push_descriptor,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            memory_budget: info.memory_budget,
            pipeline_cache,
            pipeline_cache_file,
        });
        // SAFETY: queue family index and queue index 0 were requested above.
        let queue = unsafe { shared.device.get_device_queue(queue_family, 0) };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid device and create info.
        let command_pool = unsafe { shared.device.create_command_pool(&pool_info, None) }
            .vk("vkCreateCommandPool")?;
        shared.set_name(queue, "compute queue");
        shared.set_name(command_pool, "command pool");
        shared.set_name(shared.device.handle(), "vksplat device");
        let mut ctx = Self {
            shared,
            physical_device,
            queue,
            queue_family,
            command_pool: Mutex::new(command_pool),
            info,
            messages,
            validation,
            full_subgroups,
        };
        ctx.follow_measured_subgroups()?;
        emulation.apply(&mut ctx.info);
        Ok(ctx)
    }

    /// Measures the subgroup size the device runs ([`super::subgroup`]) and, where the
    /// driver misreports it, makes every later pipeline and size decision use the measured
    /// one; refuses a device whose subgroups are inconsistent.
    fn follow_measured_subgroups(&mut self) -> GpuResult<()> {
        let probe = super::subgroup::probe(self)?;
        if let super::subgroup::SubgroupVerdict::Misreported { runs, .. } =
            super::subgroup::size_to_use(&self.info.name, &probe)?
        {
            let info = &mut self.info;
            info.subgroup_size = runs;
            info.min_subgroup_size = info.min_subgroup_size.min(runs);
            info.max_subgroup_size = runs.max(info.min_subgroup_size);
            info.subgroup_size_override = runs;
        }
        Ok(())
    }

    /// The pipeline cache every pipeline is created through.
    pub fn pipeline_cache(&self) -> vk::PipelineCache {
        self.shared.pipeline_cache
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
            // SAFETY: freshly allocated command buffer.
            unsafe { device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
            let out = record(cmd)?;
            // SAFETY: recording started above.
            unsafe { device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
            let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(cmd)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cmds)];
            // SAFETY: the queue is only used from here while the pool mutex is held.
            unsafe { device.queue_submit2(self.queue, &submit, fence) }.vk("vkQueueSubmit2")?;
            // SAFETY: the fence was submitted above.
            unsafe { device.wait_for_fences(&[fence], true, u64::MAX) }.vk("vkWaitForFences")?;
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
                device
                    .queue_submit2(self.queue, &submit, slot.fence)
                    .vk("vkQueueSubmit2")?;
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
        // SAFETY: the fence was submitted with the slot's command buffer.
        let waited =
            unsafe { device.wait_for_fences(&[slot.fence], true, u64::MAX) }.vk("vkWaitForFences");
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
