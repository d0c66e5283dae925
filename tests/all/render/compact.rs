//! Compact scenes (`--compact`, issue 17): SH coefficients uploaded as fp16 and read through
//! an RGBA16F texel view, axis scales and rotations as fp16 in 32-byte records. A compact
//! frame must equal, bit for bit, the exact render of the scene rounded as the upload rounds
//! it (`ActivatedScene::compact_rounded`), and so stay within the project's GPU-vs-CPU
//! thresholds (PSNR >= 55 dB, >= 99.9 % of 8-bit pixels within 1/255) of the CPU reference
//! of that scene; the upload must take 16 bytes fewer per Gaussian plus half the SH bytes.

use crate::common;
use crate::common::gpu::{assert_validation_clean, compare, renderer, Thresholds, MIN_WITHIN};
use verisplat::core::camera;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;
use verisplat::render::{FrameRequest, Rendered};

#[test]
fn compact_scenes_render_their_fp16_rounding_exactly_in_fewer_bytes() {
    let mut r = renderer();
    let data = common::shared_data();
    for (file, sh_floats) in [
        ("playbot_lod3_31k_sh2.ply", 28u64), // 27 floats padded to 7 texels
        ("train3_sh3.ply", 48),
    ] {
        let s = io::scene::load(&data.join(file)).unwrap().activated();
        let cam = if file.starts_with("train3") {
            camera::default_camera(&s.positions, 320, 240)
        } else {
            common::orbit(common::PLAYBOT_ORBIT, 3, 400, 225)
        };
        let opts = RenderOptions::default();
        r.set_compact(false);
        let exact_scene = r.upload(&s).unwrap();
        r.set_compact(true);
        let compact_scene = r.upload(&s).unwrap();
        r.set_compact(false);
        assert!(compact_scene.is_compact() && !exact_scene.is_compact());
        let n = s.len() as u64;
        assert_eq!(
            exact_scene.device_bytes() - compact_scene.device_bytes(),
            n * (16 + sh_floats * 2),
            "{file}: 32-byte records and fp16 SH (2 bytes per float)"
        );
        let exact = r
            .render(&FrameRequest::new(&exact_scene, &cam, &opts))
            .and_then(Rendered::into_frame)
            .unwrap();
        let compact = r
            .render(&FrameRequest::new(&compact_scene, &cam, &opts))
            .and_then(Rendered::into_frame)
            .unwrap();
        let alpha_depth = |f: &verisplat::core::frame::Frame| -> Vec<u32> {
            f.alpha
                .iter()
                .chain(&f.depth)
                .map(|v| v.to_bits())
                .collect()
        };
        assert!(
            alpha_depth(&exact) != alpha_depth(&compact)
                && common::frame_bits(&exact) != common::frame_bits(&compact),
            "{file}: fp16 scales, rotations and SH must show in alpha, depth and colour \
             (else the compact path was not taken)"
        );
        // The compact upload holds exactly the rounded values, and unpacking them is exact.
        let rounded = s.compact_rounded();
        let rounded_scene = r.upload(&rounded).unwrap();
        let rounded_exact = r
            .render(&FrameRequest::new(&rounded_scene, &cam, &opts))
            .and_then(Rendered::into_frame)
            .unwrap();
        assert!(
            common::frame_bits(&rounded_exact) == common::frame_bits(&compact),
            "{file}: a compact frame is the exact render of the rounded scene, bit for bit"
        );
        let vs_exact = compare(&compact, &exact);
        let reference = cpu::render(&rounded, &cam, &opts);
        let vs_cpu = compare(&compact, &reference);
        eprintln!("{file}: compact vs exact {vs_exact:?}; vs the CPU reference {vs_cpu:?}");
        assert!(
            vs_cpu.meets(&Thresholds {
                depth_within: Some(MIN_WITHIN),
                ..Thresholds::COLOUR_AND_ALPHA
            }),
            "{file}: {vs_cpu:?}"
        );
        assert!(vs_exact.meets(&Thresholds::PSNR), "{file}: {vs_exact:?}");
    }
    assert_validation_clean(&r);
}
