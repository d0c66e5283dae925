//! The Vulkan instance: the loader, the validation layer (with synchronization validation
//! where the layer has it), `VK_EXT_debug_utils` and the messenger that records every
//! WARNING/ERROR message, and the guard that tears them down when a later setup step fails.

use std::ffi::{c_void, CStr};
use std::sync::{Arc, Mutex};

use ash::vk;

use super::capabilities::{has_extension, version_string};
use super::{GpuError, GpuResult, VkContext};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// The validation messages recorded so far.
pub(crate) type MessageLog = Arc<Mutex<Vec<String>>>;

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
    crate::core::console::note!("{text}");
    // SAFETY: `user` points at the boxed MessageLog owned by `Shared`, which outlives
    // the messenger (and the instance whose creation/destruction it also watches).
    if let Some(log) = unsafe { (user as *const MessageLog).as_ref() } {
        if let Ok(mut log) = log.lock() {
            log.push(text);
        }
    }
    vk::FALSE
}

/// Destroys the instance and its messenger when setup fails before
/// [`Shared`](super::device::Shared) owns them; [`InstanceGuard::disarm`] hands them over.
pub(crate) struct InstanceGuard(
    Option<(
        ash::Instance,
        Option<ash::ext::debug_utils::Instance>,
        vk::DebugUtilsMessengerEXT,
    )>,
);

impl InstanceGuard {
    /// Ownership of the instance and messenger has moved on: destroy nothing.
    pub(crate) fn disarm(&mut self) {
        self.0 = None;
    }
}

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

/// A created instance and what goes with it. The guard is the first field, so that on a
/// failed setup it runs while the callback's log and the loader are still alive.
pub(crate) struct VulkanInstance {
    /// Destroys the instance and messenger unless disarmed.
    pub(crate) guard: InstanceGuard,
    pub(crate) entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    pub(crate) debug_instance: Option<ash::ext::debug_utils::Instance>,
    pub(crate) messenger: vk::DebugUtilsMessengerEXT,
    /// Owns the log the messenger callback writes through a raw pointer.
    pub(crate) callback_log: Option<Box<MessageLog>>,
    /// The log itself, for the context to read.
    pub(crate) messages: MessageLog,
    /// `VK_EXT_debug_utils` is enabled (object names and labels).
    pub(crate) debug_utils: bool,
}

/// The layers and instance extensions to enable.
struct InstanceLayers {
    layers: Vec<*const std::ffi::c_char>,
    extensions: Vec<*const std::ffi::c_char>,
    sync_validation: bool,
    debug_utils: bool,
}

/// Loads the Vulkan loader and checks that it offers Vulkan 1.3.
fn load_entry() -> GpuResult<ash::Entry> {
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
    Ok(entry)
}

/// The validation layer (refused when asked for but not installed) with its
/// validation-features extension, and `VK_EXT_debug_utils` where the loader has it.
fn choose_layers(entry: &ash::Entry, validation: bool) -> GpuResult<InstanceLayers> {
    // SAFETY: plain query.
    let instance_exts = unsafe { entry.enumerate_instance_extension_properties(None) }
        .vk("vkEnumerateInstanceExtensionProperties")?;
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
        if has_extension(&layer_exts, ash::ext::validation_features::NAME) {
            extensions.push(ash::ext::validation_features::NAME.as_ptr());
            sync_validation = true;
        }
    }
    let debug_utils = has_extension(&instance_exts, ash::ext::debug_utils::NAME);
    if debug_utils {
        extensions.push(ash::ext::debug_utils::NAME.as_ptr());
    }
    Ok(InstanceLayers {
        layers,
        extensions,
        sync_validation,
        debug_utils,
    })
}

/// Creates the instance (with the validation layer when `validation`) and, when the
/// layer's messages can be caught, the messenger that records them.
pub(crate) fn create(validation: bool) -> GpuResult<VulkanInstance> {
    let entry = load_entry()?;
    let InstanceLayers {
        layers,
        extensions,
        sync_validation,
        debug_utils,
    } = choose_layers(&entry, validation)?;

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
        .application_name(c"verisplat")
        .engine_name(c"verisplat")
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
    let instance = unsafe { entry.create_instance(&instance_info, None) }.vk("vkCreateInstance")?;

    // From here on, failures must destroy what was created; the guard does that.
    let debug_instance =
        debug_utils.then(|| ash::ext::debug_utils::Instance::new(&entry, &instance));
    let mut vulkan = VulkanInstance {
        guard: InstanceGuard(Some((
            instance.clone(),
            debug_instance.clone(),
            vk::DebugUtilsMessengerEXT::null(),
        ))),
        entry,
        instance,
        debug_instance,
        messenger: vk::DebugUtilsMessengerEXT::null(),
        callback_log,
        messages,
        debug_utils,
    };
    if let (Some(debug), Some(_)) = (&vulkan.debug_instance, &vulkan.callback_log) {
        // SAFETY: valid create info; destroyed in Shared::drop or the guard.
        let m = unsafe { debug.create_debug_utils_messenger(&messenger_info, None) }
            .vk("vkCreateDebugUtilsMessengerEXT")?;
        if let Some(g) = vulkan.guard.0.as_mut() {
            g.2 = m;
        }
        vulkan.messenger = m;
    }
    Ok(vulkan)
}
