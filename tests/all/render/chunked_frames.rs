//! Split frames (issue 17): preprocess in index windows and frames keyed, sorted and
//! blended in depth-ordered chunks, forced on real scenes with tiny limits
//! ([`SplitLimits`]) so that they take the paths large scenes take on lavapipe. Splitting
//! must not change a single bit of colour, alpha or depth: compositing is sequential per
//! pixel and the chunks' per-tile lists are consecutive runs of the one-piece lists. The
//! split frames are also held to the CPU reference with the whole-frame thresholds of
//! `tests/all/render/frames.rs` (PSNR >= 55 dB, >= 99.9 % of 8-bit pixels within 1/255).
//!
//! A real scene over one storage binding's worth of Gaussians is
//! `a_scene_beyond_one_storage_binding_renders_in_preprocess_windows` in
//! `tests/all/render/frames.rs`; the 10 M-Gaussian frame is checked by hand (BENCHMARKS.md).

use crate::common;
use crate::common::gpu::{
    assert_validation_clean, check_against_reference, new_renderer, renderer,
};
use crate::common::orbit;
use verisplat::core::camera::Camera;
use verisplat::core::frame::Frame;
use verisplat::core::scene::ActivatedScene;
use verisplat::cpu::{self, RenderOptions, SplatKernel};
use verisplat::io;

use verisplat::render::forward::blend::BlendKernel;
use verisplat::render::{FrameRequest, Readback, Rendered};
use verisplat::render::{GpuRenderer, SplitLimits};

fn load(name: &str) -> ActivatedScene {
    io::scene::load(&common::shared_data().join(name))
        .unwrap()
        .activated()
}

/// Colour, alpha and depth equal bit for bit (NaN-safe: the bits are compared).
fn assert_bit_identical(label: &str, split: &Frame, whole: &Frame) {
    assert_eq!((split.width, split.height), (whole.width, whole.height));
    let (a, b) = (common::frame_bits(split), common::frame_bits(whole));
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(differing, 0, "{label}: {differing} values differ");
}

/// Renders `cam` in one piece, then with `limits`, and requires identical frames (and
/// identical 8-bit frames packed on the device); returns the split frame.
fn split_equals_whole(
    r: &mut GpuRenderer,
    label: &str,
    s: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
    limits: SplitLimits,
) -> Frame {
    let gs = r.upload(s).unwrap();
    r.set_split_limits(SplitLimits::default());
    let whole = r
        .render(&FrameRequest::new(&gs, cam, opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    let whole_rgba = r
        .render(&FrameRequest::new(&gs, cam, opts).readback(Readback::Rgba8))
        .and_then(Rendered::into_rgba8)
        .unwrap();
    assert_eq!(
        r.stats().chunks,
        1,
        "{label}: the unforced frame fits at once"
    );
    r.set_split_limits(limits);
    let split = r
        .render(&FrameRequest::new(&gs, cam, opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    let stats = r.stats().clone();
    let timings = r.timings().clone();
    let split_rgba = r
        .render(&FrameRequest::new(&gs, cam, opts).readback(Readback::Rgba8))
        .and_then(Rendered::into_rgba8)
        .unwrap();
    r.set_split_limits(SplitLimits::default());
    eprintln!(
        "{label}: {} pairs in {} chunks (limit {}), bins {}, keys {:.1} ms, blend {:.1} ms",
        stats.pairs, stats.chunks, limits.chunk_pairs, stats.bin_size, timings.keys, timings.blend
    );
    if limits.chunk_pairs > 0 {
        assert!(
            stats.chunks > 1
                && u64::from(stats.chunks) >= stats.pairs / u64::from(limits.chunk_pairs),
            "{label}: {stats:?}"
        );
        assert!(timings.keys > 0.0 && timings.blend > 0.0, "{timings:?}");
    }
    assert_bit_identical(label, &split, &whole);
    assert!(split_rgba == whole_rgba, "{label}: the 8-bit frames differ");
    assert_validation_clean(r);
    split
}

#[test]
fn tiny_chunks_and_windows_equal_one_piece_and_the_reference() {
    let mut r = renderer();
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 5, 480, 270);
    let opts = RenderOptions::default();
    // More chunks than one submission records, windows of 768 Gaussians (41 windows).
    let limits = SplitLimits {
        window: 1000,
        chunk_pairs: 2000,
    };
    let split = split_equals_whole(&mut r, "playbot 31k texel", &s, &cam, &opts, limits);
    check_against_reference("playbot 31k in chunks", &split, &s, &cam);
    // Windows alone (one chunk), and chunks alone.
    for limits in [
        SplitLimits {
            window: 256,
            chunk_pairs: 0,
        },
        SplitLimits {
            window: 0,
            chunk_pairs: 50_000,
        },
    ] {
        split_equals_whole(&mut r, "playbot 31k", &s, &cam, &opts, limits);
    }
}

#[test]
fn chunks_equal_one_piece_with_the_shared_kernel_the_power_falloff_and_a_background() {
    let limits = SplitLimits {
        window: 512,
        chunk_pairs: 3000,
    };
    let opts = RenderOptions {
        background: [0.2, 0.4, 0.9],
        ..Default::default()
    };
    let plant = load("plant_113k_sh0.ply");
    let cam = orbit("plant_orbit_cameras.synthetic.json", 0, 320, 240);
    let mut shared = new_renderer(Some(BlendKernel::Shared));
    split_equals_whole(
        &mut shared,
        "plant 113k shared",
        &plant,
        &cam,
        &opts,
        limits,
    );
    let power = RenderOptions {
        kernel: SplatKernel::Power,
        ..opts
    };
    let playbot = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 320, 240);
    let mut r = renderer();
    split_equals_whole(
        &mut r,
        "playbot 31k texel power",
        &playbot,
        &cam,
        &power,
        limits,
    );
}

#[test]
fn features_frames_in_chunks_equal_one_piece_and_the_reference() {
    // Feature channels are blended chunk by chunk, each chunk resuming every pixel's
    // channels and transmittance: K = 5 (two groups of four) must not change by a bit.
    let mut r = renderer();
    let mut sc = io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply")).unwrap();
    let k = 5;
    let mut rng = common::Rng(5);
    let v = (0..sc.len() * k).map(|_| rng.range(-1.0, 1.0)).collect();
    sc.set_features(k, v).unwrap();
    let s = sc.activated();
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 5, 320, 180);
    let opts = RenderOptions::default();
    let gs = r.upload(&s).unwrap();
    let gf = r.upload_features(&s).unwrap();
    let whole = r
        .render(&FrameRequest::new(&gs, &cam, &opts).features(&gf))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert_eq!(r.stats().chunks, 1);
    r.set_split_limits(SplitLimits {
        window: 4096,
        chunk_pairs: 4_000,
    });
    let split = r
        .render(&FrameRequest::new(&gs, &cam, &opts).features(&gf))
        .and_then(Rendered::into_frame)
        .unwrap();
    let chunks = r.stats().chunks;
    r.set_split_limits(SplitLimits::default());
    assert!(chunks >= 4, "{chunks} chunks");
    assert_bit_identical("features frame in chunks", &split, &whole);
    let bits = |f: &Frame| f.features.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(split.features.len(), whole.features.len());
    let differing = bits(&split)
        .iter()
        .zip(&bits(&whole))
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(
        differing, 0,
        "{differing} feature values differ ({chunks} chunks)"
    );
    // And the split frame's channels against the CPU reference's, like a colour plane.
    let c = cpu::render_features(&s, &cam, &opts);
    let worst = split
        .features
        .iter()
        .zip(&c.features)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst < 2e-3,
        "largest feature difference to the CPU reference {worst}"
    );
    assert_validation_clean(&r);
}
