#![no_main]
//! COLMAP text model: the input is `cameras.txt`, a NUL byte, then `images.txt`.
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let (cams, images) = verisplat_fuzz::split_at_nul(data);
    if let (Ok(cams), Ok(images)) = (std::str::from_utf8(cams), std::str::from_utf8(images)) {
        let _ = verisplat::core::camera::colmap::parse_colmap_text(
            cams,
            Path::new("cameras.txt"),
            images,
            Path::new("images.txt"),
        );
    }
});
