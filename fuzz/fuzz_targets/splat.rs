#![no_main]
//! antimatter15 `.splat`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = vksplat::scene::splat::parse(data, std::path::Path::new("fuzz.splat"));
    let _ = vksplat::scene::splat::is_plausible(data);
});
