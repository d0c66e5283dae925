#![no_main]
//! antimatter15 `.splat`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::core::scene::splat::parse(data, std::path::Path::new("fuzz.splat"));
    let _ = verisplat::core::scene::splat::is_plausible(data);
});
