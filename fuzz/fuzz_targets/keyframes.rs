#![no_main]
//! Keyframe path JSON: parse, then sample it at a small frame count (the file's own frame
//! count or fps could ask for a million frames, which is allowed but slow to fuzz).
use libfuzzer_sys::fuzz_target;
use verisplat::core::camera::{KeyframePath, PathTiming};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(path) = KeyframePath::parse(text, std::path::Path::new("keyframes.json")) {
        let frames = 1 + data.len() % 7;
        let _ = path.cameras(&PathTiming {
            frames: Some(frames),
            fps: None,
        });
    }
});
