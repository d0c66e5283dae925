#![no_main]
//! COLMAP binary model: the input is the length of `cameras.bin` (u32 LE), `cameras.bin`,
//! then `images.bin`.
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let (cams, images) = verisplat_fuzz::split_len_prefixed(data);
    let _ = verisplat::core::camera::colmap::parse_colmap_binary(
        cams,
        Path::new("cameras.bin"),
        images,
        Path::new("images.bin"),
    );
});
