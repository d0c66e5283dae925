#![no_main]
//! INRIA PLY (ascii, binary little and big endian).
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::core::scene::ply::parse(data, std::path::Path::new("fuzz.ply"));
});
