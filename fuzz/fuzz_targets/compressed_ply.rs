#![no_main]
//! PlayCanvas / SuperSplat compressed PLY.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::core::scene::compressed_ply::parse(
        data,
        std::path::Path::new("fuzz.compressed.ply"),
    );
});
