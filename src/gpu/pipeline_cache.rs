//! The `VkPipelineCache` kept on disk between runs, one file per driver build.
//!
//! The file is `<dir>/<pipelineCacheUUID>.bin` (dir: `$VERISPLAT_PIPELINE_CACHE`, else
//! `$XDG_CACHE_HOME/verisplat/pipelines`, else `~/.cache/verisplat/pipelines`;
//! `VERISPLAT_NO_PIPELINE_CACHE=1` turns it off). A file whose header does not name this
//! device and driver (vendor, device id, cache UUID), or that is damaged, is ignored with a
//! note and replaced. The cache is written back, atomically ([`crate::core::fsutil`]),
//! when the context goes and the driver's data grew. Whether it saves time depends on the
//! driver: Mesa's lavapipe keeps its own disk cache of compiled shaders and returns only a
//! header here (BENCHMARKS.md, "Start-up").

use std::path::{Path, PathBuf};

/// Bytes of the header Vulkan puts in front of pipeline cache data (version one).
const HEADER_BYTES: usize = 32;

/// Where pipeline caches are kept, or `None` (no disk cache).
pub fn cache_dir() -> Option<PathBuf> {
    if crate::core::former_name::env_var_os("VERISPLAT_NO_PIPELINE_CACHE").is_some() {
        return None;
    }
    if let Some(dir) = crate::core::former_name::env_var_os("VERISPLAT_PIPELINE_CACHE") {
        return Some(PathBuf::from(dir));
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("verisplat").join("pipelines"))
}

/// The identity a cache file must carry: `VkPipelineCacheHeaderVersionOne`'s fields.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CacheIdentity {
    /// `VkPhysicalDeviceProperties::vendorID`.
    pub vendor_id: u32,
    /// `VkPhysicalDeviceProperties::deviceID`.
    pub device_id: u32,
    /// `VkPhysicalDeviceProperties::pipelineCacheUUID`.
    pub uuid: [u8; 16],
}

impl CacheIdentity {
    /// The cache file of this identity in `dir`.
    pub fn file(&self, dir: &Path) -> PathBuf {
        let hex: String = self.uuid.iter().map(|b| format!("{b:02x}")).collect();
        dir.join(format!("{hex}.bin"))
    }

    /// Why `data` is not a pipeline cache of this device and driver, if it is not.
    pub fn check(&self, data: &[u8]) -> Result<(), String> {
        if data.len() < HEADER_BYTES {
            return Err(format!("{} bytes, shorter than a cache header", data.len()));
        }
        let word = |i: usize| u32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]);
        let (length, version) = (word(0), word(4));
        if length as usize != HEADER_BYTES || version != 1 {
            return Err(format!(
                "header of {length} bytes, version {version}: not a Vulkan pipeline cache"
            ));
        }
        if (word(8), word(12)) != (self.vendor_id, self.device_id) || data[16..32] != self.uuid {
            return Err("written by another device or driver build".into());
        }
        Ok(())
    }
}

/// Reads the cache file for `identity` in `dir`: its bytes if they belong to this device
/// and driver; `None`, with a note naming the file, when it is damaged or foreign.
pub fn load(dir: &Path, identity: &CacheIdentity) -> Option<Vec<u8>> {
    let path = identity.file(dir);
    let data = std::fs::read(&path).ok()?;
    match identity.check(&data) {
        Ok(()) => Some(data),
        Err(why) => {
            crate::core::console::note!(
                "verisplat: ignoring pipeline cache {} ({why}); it will be rewritten",
                path.display()
            );
            None
        }
    }
}

/// Writes `data` as the cache file for `identity` in `dir`, atomically; best effort (a
/// cache that cannot be written costs only the next start-up's time).
pub fn store(dir: &Path, identity: &CacheIdentity, data: &[u8]) {
    if identity.check(data).is_err() || std::fs::create_dir_all(dir).is_err() {
        return;
    }
    // The temporary file is unique per process and call, so concurrent writers never
    // share one.
    let _ = crate::core::fsutil::write_bytes_atomically(&identity.file(dir), true, data);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(identity: &CacheIdentity) -> Vec<u8> {
        let mut data = Vec::new();
        for w in [
            HEADER_BYTES as u32,
            1,
            identity.vendor_id,
            identity.device_id,
        ] {
            data.extend_from_slice(&w.to_le_bytes());
        }
        data.extend_from_slice(&identity.uuid);
        data
    }

    #[test]
    fn cache_files_round_trip_and_foreign_or_damaged_ones_are_ignored() {
        let dir =
            std::env::temp_dir().join(format!("verisplat-pcache-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let ours = CacheIdentity {
            vendor_id: 0x10005,
            device_id: 0,
            uuid: *b"0123456789abcdef",
        };
        assert_eq!(load(&dir, &ours), None, "no file yet");
        let mut data = header(&ours);
        data.extend_from_slice(b"driver blob");
        store(&dir, &ours, &data);
        assert_eq!(load(&dir, &ours).as_deref(), Some(&data[..]));
        let files: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert_eq!(files, vec![ours.file(&dir)], "one file, no temporary left");

        // Another driver build (same file name forced by copying): ignored, not loaded.
        let other = CacheIdentity {
            uuid: *b"fedcba9876543210",
            ..ours
        };
        std::fs::write(ours.file(&dir), header(&other)).unwrap();
        assert_eq!(load(&dir, &ours), None);
        assert!(ours
            .check(&header(&other))
            .unwrap_err()
            .contains("another device"));
        // Another device with the same driver.
        let device = CacheIdentity {
            device_id: 7,
            ..ours
        };
        assert!(ours.check(&header(&device)).is_err());
        // Damaged: too short, or not a cache header at all.
        std::fs::write(ours.file(&dir), b"garbage").unwrap();
        assert_eq!(load(&dir, &ours), None);
        let mut bad = header(&ours);
        bad[4] = 9;
        assert!(ours.check(&bad).unwrap_err().contains("version 9"));
        // Data that is not ours is never written.
        store(&dir, &ours, &header(&other));
        assert_eq!(std::fs::read(ours.file(&dir)).unwrap(), b"garbage");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
