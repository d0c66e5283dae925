#![no_main]
//! SPZ: gzip-wrapped v2/v3, bare v2/v3 and zstd v4 (the wrapper is chosen by the magic).
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::core::scene::spz::parse(data, std::path::Path::new("fuzz.spz"));
});
