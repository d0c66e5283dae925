//! Device traits forced for testing: what a discrete GPU or a minimal device does
//! differently from lavapipe, so every path that depends on it runs here too.
//!
//! The one place each such decision is made reads [`DeviceInfo`](super::DeviceInfo), and
//! the context applies an [`Emulation`] to that info before anything reads it
//! ([`Emulation::apply`], beside the info in [`super::device_info`]): a kernel
//! chooser sees 16 KiB of shared memory and 128 invocations under `spec-limits`, exactly
//! as on a device that has no more. `VERISPLAT_EMULATE` (a comma-separated list, e.g.
//! `spec-limits,timestamp-bits=36`) or [`ContextOptions::emulate`](super::ContextOptions)
//! turn them on; the GPU tests force each one.

/// The Vulkan specification's guaranteed minimums that `spec-limits` clamps to.
pub mod spec_minimum {
    /// maxComputeSharedMemorySize.
    pub const SHARED_MEMORY: u32 = 16384;
    /// maxComputeWorkGroupInvocations.
    pub const WORKGROUP_INVOCATIONS: u32 = 128;
    /// maxComputeWorkGroupCount[0..3].
    pub const WORKGROUP_COUNT: u32 = 65535;
    /// maxStorageBufferRange (2^27; not clamped by `spec-limits`).
    pub const STORAGE_BUFFER_RANGE: u32 = 1 << 27;
    /// maxTexelBufferElements (not clamped by `spec-limits`).
    pub const TEXEL_BUFFER_ELEMENTS: u32 = 65536;
}

/// Device traits to pretend (all off by default).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Emulation {
    /// Clamp the compute limits to the specification's minimums ([`spec_minimum`]): shared
    /// memory, invocations and workgroup counts. The buffer limits have their own traits
    /// (`max-storage-buffer-range`): the spec's 128 MiB and 65,536 texels are far below
    /// every GPU's, and a scene past a device's limit is refused with a sentence saying so.
    pub spec_limits: bool,
    /// Device-local memory is not host-visible: every transfer goes through staging.
    pub device_local_not_host_visible: bool,
    /// Host-visible memory is not coherent: mapped writes are flushed and mapped reads
    /// invalidated, in `nonCoherentAtomSize` units.
    pub non_coherent: bool,
    /// Valid bits of the compute queue's timestamps (fewer than 64: they wrap).
    pub timestamp_bits: Option<u32>,
    /// maxStorageBufferRange in bytes.
    pub max_storage_buffer_range: Option<u32>,
    /// `maxComputeWorkGroupCount[0]`.
    pub max_workgroup_count_x: Option<u32>,
    /// No 64-bit integer atomics (`shaderBufferInt64Atomics`, optional in the
    /// specification; also off under `spec-limits`): the gradient accumulation adds
    /// 32-bit halves with a carry.
    pub no_int64_atomics: bool,
    /// No subgroup shuffles (optional in the specification; also off under
    /// `spec-limits`): the blend backward's per-pixel layout sums with the driver's
    /// subgroupAdd.
    pub no_subgroup_shuffle: bool,
}

impl Emulation {
    /// Parses a `VERISPLAT_EMULATE` list: `spec-limits`, `discrete` (device-local memory not
    /// host-visible and host memory not coherent), `no-host-visible-device`,
    /// `non-coherent`, `timestamp-bits=N`, `max-storage-buffer-range=BYTES`,
    /// `max-workgroup-count=N`, `no-int64-atomics`, `no-subgroup-shuffle`.
    pub fn parse(text: &str) -> Result<Emulation, String> {
        let mut e = Emulation::default();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, value) = match item.split_once('=') {
                Some((n, v)) => (n.trim(), Some(v.trim())),
                None => (item, None),
            };
            let number = |what: &str| -> Result<u32, String> {
                let v = value.ok_or_else(|| format!("{what} needs a value ({what}=N)"))?;
                super::budget::parse_bytes(v)
                    .ok()
                    .and_then(|n| u32::try_from(n).ok())
                    .ok_or_else(|| format!("{what}={v}: not a whole number below 2^32"))
            };
            match name {
                "spec-limits" => e.spec_limits = true,
                "discrete" => {
                    e.device_local_not_host_visible = true;
                    e.non_coherent = true;
                }
                "no-host-visible-device" => e.device_local_not_host_visible = true,
                "non-coherent" => e.non_coherent = true,
                "no-int64-atomics" => e.no_int64_atomics = true,
                "no-subgroup-shuffle" => e.no_subgroup_shuffle = true,
                "timestamp-bits" => {
                    let bits = number(name)?;
                    if !(1..=64).contains(&bits) {
                        return Err(format!("timestamp-bits={bits}: 1 to 64"));
                    }
                    e.timestamp_bits = Some(bits);
                }
                "max-storage-buffer-range" => e.max_storage_buffer_range = Some(number(name)?),
                "max-workgroup-count" => {
                    let n = number(name)?;
                    if n == 0 {
                        return Err("max-workgroup-count=0: at least 1".into());
                    }
                    e.max_workgroup_count_x = Some(n);
                }
                other => {
                    return Err(format!(
                        "unknown trait '{other}' (spec-limits, discrete, \
                         no-host-visible-device, non-coherent, timestamp-bits=N, \
                         max-storage-buffer-range=BYTES, max-workgroup-count=N, \
                         no-int64-atomics, no-subgroup-shuffle)"
                    ))
                }
            }
        }
        Ok(e)
    }

    /// `VERISPLAT_EMULATE`, parsed (empty when unset).
    pub fn from_env() -> Result<Emulation, String> {
        match crate::core::former_name::env_var("VERISPLAT_EMULATE") {
            Some(v) => Emulation::parse(&v).map_err(|e| format!("VERISPLAT_EMULATE: {e}")),
            None => Ok(Emulation::default()),
        }
    }

    /// Both together: each trait that either turns on.
    pub fn union(&self, other: &Emulation) -> Emulation {
        let min = |a: Option<u32>, b: Option<u32>| match (a, b) {
            (Some(x), Some(y)) => Some(x.min(y)),
            (x, y) => x.or(y),
        };
        Emulation {
            spec_limits: self.spec_limits || other.spec_limits,
            device_local_not_host_visible: self.device_local_not_host_visible
                || other.device_local_not_host_visible,
            non_coherent: self.non_coherent || other.non_coherent,
            timestamp_bits: min(self.timestamp_bits, other.timestamp_bits),
            max_storage_buffer_range: min(
                self.max_storage_buffer_range,
                other.max_storage_buffer_range,
            ),
            max_workgroup_count_x: min(self.max_workgroup_count_x, other.max_workgroup_count_x),
            no_int64_atomics: self.no_int64_atomics || other.no_int64_atomics,
            no_subgroup_shuffle: self.no_subgroup_shuffle || other.no_subgroup_shuffle,
        }
    }

    /// Whether any trait is on.
    pub fn any(&self) -> bool {
        *self != Emulation::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_parse_and_bad_items_are_named() {
        let e = Emulation::parse("spec-limits, timestamp-bits=36,max-workgroup-count=1000")
            .expect("parses");
        assert!(e.spec_limits && !e.non_coherent);
        assert_eq!(e.timestamp_bits, Some(36));
        assert_eq!(e.max_workgroup_count_x, Some(1000));
        let d = Emulation::parse("discrete").expect("parses");
        assert!(d.device_local_not_host_visible && d.non_coherent);
        assert_eq!(
            Emulation::parse("max-storage-buffer-range=64M")
                .expect("parses")
                .max_storage_buffer_range,
            Some(64 << 20)
        );
        assert!(Emulation::parse("warp-drive")
            .unwrap_err()
            .contains("warp-drive"));
        assert!(Emulation::parse("timestamp-bits=0").is_err());
        assert!(Emulation::parse("timestamp-bits").is_err());
        assert!(!Emulation::parse("").expect("empty").any());
    }
}
