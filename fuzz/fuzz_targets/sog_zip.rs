#![no_main]
//! PlayCanvas SOG bundle: the input is the zip.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::core::scene::sog::parse_zip(data, std::path::Path::new("fuzz.sog"));
});
