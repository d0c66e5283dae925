//! The project's former name, kept only to read what was written under it.
//!
//! verisplat was called vksplat until 2026-11-28, when another Vulkan 3DGS project turned
//! out to publish the same Python package name. Files written under the old name (PLY
//! header comments `comment vksplat kernel NAME`, safetensors metadata `vksplat_mlp` and
//! `vksplat_checkpoint`) are still read, and an old `VKSPLAT_*` environment variable is
//! still honoured, with a deprecation note, when its `VERISPLAT_*` name is not set (when
//! both are, a note says the old one is ignored). Nothing is written under the old name.
//! This module is the one place in the sources that spells it.

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::sync::Mutex;

/// The name as it was spelt in file keys and comments.
const FORMER: &str = "vksplat";
/// The current name, as file keys and comments spell it.
const CURRENT: &str = "verisplat";
/// The prefix of the project's environment variables under each name.
const FORMER_ENV: &str = "VKSPLAT_";
const CURRENT_ENV: &str = "VERISPLAT_";

/// The key or comment prefix a file written under the former name holds in place of `key`
/// (`verisplat_mlp` -> `vksplat_mlp`, `verisplat kernel` -> `vksplat kernel`); None when
/// `key` does not start with the current name.
pub fn former_key(key: &str) -> Option<String> {
    key.strip_prefix(CURRENT)
        .map(|rest| format!("{FORMER}{rest}"))
}

/// True when `text` is `key` or the key the former name wrote in its place.
pub fn matches_key(text: &str, key: &str) -> bool {
    text == key || former_key(key).is_some_and(|k| text == k)
}

/// The former name of the environment variable `name` (`VERISPLAT_DEVICE` ->
/// `VKSPLAT_DEVICE`); None for a variable that is not the project's.
pub fn former_env(name: &str) -> Option<String> {
    name.strip_prefix(CURRENT_ENV)
        .map(|rest| format!("{FORMER_ENV}{rest}"))
}

/// The environment variable `name` (a `VERISPLAT_*` name): its value, else the value of
/// its former `VKSPLAT_*` name with a note that the old name is deprecated. When both are
/// set the new one wins, with a note that the old one is ignored. Each note is printed
/// once per variable and process.
pub fn env_var_os(name: &str) -> Option<OsString> {
    let old = former_env(name);
    let old_value = old.as_deref().and_then(std::env::var_os);
    if let Some(v) = std::env::var_os(name) {
        if let (Some(old), Some(_)) = (&old, &old_value) {
            if first_note(old) {
                crate::core::console::note!(
                    "verisplat: {old} is ignored because {name} is set too (the project was called vksplat until 2026-11-28); unset {old}"
                );
            }
        }
        return Some(v);
    }
    let (old, v) = (old?, old_value?);
    if first_note(&old) {
        crate::core::console::note!(
            "verisplat: {old} is deprecated (the project was called vksplat until 2026-11-28); set {name} instead"
        );
    }
    Some(v)
}

/// True the first time it is asked about the former variable `old` in this process.
fn first_note(old: &str) -> bool {
    static NOTED: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());
    NOTED
        .lock()
        .map(|mut set| set.insert(old.to_string()))
        .unwrap_or(false)
}

/// [`env_var_os`] as a string; None when unset or not valid Unicode.
pub fn env_var(name: &str) -> Option<String> {
    env_var_os(name).and_then(|v| v.into_string().ok())
}

/// A flag variable ([`env_var`]): set, and neither empty nor `0`.
pub fn env_flag(name: &str) -> bool {
    env_var(name).is_some_and(|v| !v.is_empty() && v != "0")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn former_keys_and_variables() {
        assert_eq!(former_key("verisplat_mlp").as_deref(), Some("vksplat_mlp"));
        assert_eq!(
            former_key("verisplat kernel").as_deref(),
            Some("vksplat kernel")
        );
        assert_eq!(former_key("kernel"), None);
        assert!(matches_key("vksplat rules", "verisplat rules"));
        assert!(matches_key("verisplat rules", "verisplat rules"));
        assert!(!matches_key("other rules", "verisplat rules"));
        assert_eq!(
            former_env("VERISPLAT_DEVICE").as_deref(),
            Some("VKSPLAT_DEVICE")
        );
        assert_eq!(former_env("HOME"), None);
    }
}
