#![no_main]
//! nerfstudio camera_path.json.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = verisplat::core::camera::nerfstudio::parse_camera_path(
            text,
            std::path::Path::new("camera_path.json"),
        );
    }
});
