#![no_main]
//! PlayCanvas SOG `meta.json`: the input is put into a zip with the textures of a valid
//! 4-Gaussian SOG, so the fuzzer explores the JSON and its counts, not the zip format.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let bundle = verisplat_fuzz::sog_zip(data);
    let _ = verisplat::core::scene::sog::parse_zip(&bundle, std::path::Path::new("fuzz.sog"));
});
