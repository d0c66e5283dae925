//! Compact scenes (`--compact`, issue 17): SH coefficients uploaded as fp16 and read through
//! an RGBA16F texel view. Geometry (alpha, depth) must not change by a bit, since only the
//! colour's SH is rounded; the colour must stay within the project's GPU-vs-CPU thresholds
//! (PSNR >= 55 dB, >= 99.9 % of 8-bit pixels within 1/255) of the CPU reference, and the
//! SH buffer must take half the bytes.

mod common;

use common::gpu::{assert_validation_clean, compare, renderer};
use vksplat::camera;
use vksplat::cpu::{self, RenderOptions};
use vksplat::scene;

#[test]
fn compact_scenes_halve_the_sh_bytes_and_keep_geometry_exact() {
    let mut r = renderer();
    let data = common::shared_data();
    let cams =
        camera::load_cameras_json(&data.join("playbot_orbit_cameras.synthetic.json")).unwrap();
    for (file, sh_floats) in [
        ("playbot_lod3_31k_sh2.ply", 28u64), // 27 floats padded to 7 texels
        ("train3_sh3.ply", 48),
    ] {
        let s = scene::load(&data.join(file)).unwrap().activated();
        let cam = if file.starts_with("train3") {
            camera::default_camera(&s.positions, 320, 240)
        } else {
            cams[3].with_resolution(400, 225).unwrap()
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
            n * sh_floats * 2,
            "{file}: fp16 SH saves 2 bytes per float"
        );
        let exact = r.render(&exact_scene, &cam, &opts).unwrap();
        let compact = r.render(&compact_scene, &cam, &opts).unwrap();
        assert!(
            common::frame_bits(&exact) != common::frame_bits(&compact),
            "{file}: fp16 rounding must show somewhere (else the compact path was not taken)"
        );
        let alpha_depth = |f: &vksplat::frame::Frame| -> Vec<u32> {
            f.alpha
                .iter()
                .chain(&f.depth)
                .map(|v| v.to_bits())
                .collect()
        };
        assert!(
            alpha_depth(&exact) == alpha_depth(&compact),
            "{file}: alpha and depth do not depend on the SH"
        );
        let vs_exact = compare(&compact, &exact);
        let reference = cpu::render(&s, &cam, &opts);
        let vs_cpu = compare(&compact, &reference);
        eprintln!("{file}: compact vs exact {vs_exact:?}; vs the CPU reference {vs_cpu:?}");
        assert!(
            vs_cpu.psnr >= 55.0 && vs_cpu.within >= 0.999,
            "{file}: {vs_cpu:?}"
        );
        assert!(vs_exact.psnr >= 55.0, "{file}: {vs_exact:?}");
    }
    assert_validation_clean(&r);
}
