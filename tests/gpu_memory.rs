//! Long-run memory: host and device memory stay flat over many frames. In its own test
//! binary so that no other test allocates in the process while resident memory is measured.

mod common;

use vksplat::camera;
use vksplat::cpu::RenderOptions;
use vksplat::scene;

fn resident_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: u64 = statm
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    pages * 4096
}

#[test]
fn two_hundred_frames_do_not_grow_memory() {
    let frames: usize = std::env::var("VKSPLAT_MEMORY_TEST_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200);
    let mut r = common::gpu::new_renderer(None);
    let s = scene::load(&common::shared_data().join("playbot_lod6_1873_sh2.ply"))
        .unwrap()
        .activated();
    let gs = r.upload(&s).unwrap();
    let cams = camera::load_cameras_json(
        &common::shared_data().join("playbot_orbit_cameras.synthetic.json"),
    )
    .unwrap();
    let mut samples = Vec::new();
    for i in 0..frames {
        let cam = cams[i % cams.len()].with_resolution(160, 90).unwrap();
        r.render(&gs, &cam, &RenderOptions::default()).unwrap();
        if i % 50 == 49 {
            samples.push((
                i + 1,
                resident_bytes(),
                r.frame_device_bytes(),
                r.ctx().live_allocations(),
            ));
        }
    }
    eprintln!("(frame, resident bytes, per-frame device bytes, live allocations): {samples:?}");
    let first = samples[0];
    let last = *samples.last().unwrap();
    assert_eq!(last.2, first.2, "device buffers grew");
    assert_eq!(last.3, first.3, "gpu-allocator allocations grew");
    // Allow 512 KiB of allocator and driver noise between frame 50 and the last (measured:
    // about 24 KiB over 550 frames; before the frame slot was reused, 10 KiB per frame).
    assert!(
        last.1 <= first.1 + 2 * 1024 * 1024,
        "host memory grew from {} to {} bytes",
        first.1,
        last.1
    );
    common::gpu::assert_validation_clean(&r);
}
