#![no_main]
//! INRIA cameras.json.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ =
            verisplat::core::camera::parse_cameras_json(text, std::path::Path::new("cameras.json"));
    }
});
