#![no_main]
//! NumPy .npy arrays as `compare` and `eval` read them.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = verisplat::io::image_file::parse_image(data, std::path::Path::new("image.npy"));
});
