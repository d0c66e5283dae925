#![no_main]
//! Content detection: every loader reachable from arbitrary bytes.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::core::scene::parse_bytes(data, std::path::Path::new("fuzz.bin"));
});
