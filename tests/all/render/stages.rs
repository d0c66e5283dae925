//! Each GPU stage against the CPU reference's intermediate values on real scenes
//! (lavapipe, validation layer on).
//!
//! Tolerances and why:
//! - Projected centre: 1e-3 px + 2e-6 relative. Both sides are f32 but the GPU compiler may
//!   fuse multiply-adds and orders the matrix products differently, so a few ulp of the
//!   view-space position (and of the centre, which can be thousands of pixels off-screen)
//!   differ.
//! - Depth: 2e-6 relative (one dot product, a few ulp).
//! - Conic: 2e-3 of its largest entry. It is the inverse of the 2D covariance; the
//!   determinant a c - b^2 cancels for thin ellipses, amplifying ulp-level differences of
//!   a, b, c by up to (a c) / det.
//! - Radius: equal, or 1 apart when 3 sqrt(lambda) sits within rounding of an integer (ceil).
//! - Colour: 2e-5 absolute (a sum of up to 16 SH terms of order 1).
//! - Tile membership: the GPU keeps a pair unless the Gaussian provably gives alpha < 1/255
//!   to every pixel of the tile. A pair may differ from the CPU's only in a band: its tile
//!   lies on the edge of the rectangle (radius or centre rounding moved the edge), or the
//!   Gaussian's largest alpha in the tile is within 0.1 % of 1/255. Order within a tile is
//!   compared exactly on the Gaussians both sides keep.

use crate::common;
use crate::common::gpu::{assert_validation_clean, move_towards, new_renderer, renderer};
use crate::common::orbit;
use std::collections::{BTreeMap, HashSet};
use verisplat::core::camera;
use verisplat::core::camera::Camera;
use verisplat::core::scene::ActivatedScene;
use verisplat::cpu::{self, Projected, RenderOptions, SplatKernel};
use verisplat::io;

use verisplat::render::backward::BackwardRequest;
use verisplat::render::forward::blend::BlendKernel;
use verisplat::render::forward::types::unpack_tile;
use verisplat::render::{FrameRequest, Readback, Rendered};
use verisplat::render::{GpuRenderer, Intermediates};

fn load(name: &str) -> ActivatedScene {
    io::scene::load(&common::shared_data().join(name))
        .unwrap()
        .activated()
}

fn check_preprocess(
    label: &str,
    cpu_p: &[Projected],
    inter: &Intermediates,
    cam: &Camera,
    kernel: SplatKernel,
) {
    let n = cpu_p.len();
    let (mut gpu_visible, mut gpu_keyed) = (0u32, 0u32);
    // Whether every tile of the CPU's rectangle receives less than 1/255 from `c` (so exact
    // tile culling keys none of them).
    let all_empty = |c: &Projected| {
        (c.rect_min[1]..c.rect_max[1]).all(|y| {
            (c.rect_min[0]..c.rect_max[0]).all(|x| {
                cpu::max_alpha_in_tile(c, kernel, [x, y], 16, cam.width, cam.height)
                    < 1.0 / 255.0 * 1.001
            })
        })
    };
    for (i, (c, g)) in cpu_p.iter().zip(&inter.splats).enumerate() {
        let g_radius = g.color_radius[3];
        if g_radius == 0.0 {
            // Culled on the GPU: culled on the CPU too, or it sits on the near plane within
            // rounding.
            let near = (c.depth - cpu::NEAR_PLANE).abs() < 1e-5;
            assert!(
                c.tiles_touched() == 0 || near,
                "{label}: Gaussian {i} culled on the GPU but visible on the CPU: {c:?}"
            );
            continue;
        }
        gpu_visible += 1;
        assert!(
            c.radius > 0,
            "{label}: Gaussian {i} visible on the GPU only: {g:?}"
        );
        let [mx, my, opacity, bound] = g.mean_opacity_bound;
        let depth = g.conic_depth[3];
        for (gv, cv) in [(mx, c.mean2d[0]), (my, c.mean2d[1])] {
            assert!(
                (gv - cv).abs() <= 1e-3 + 2e-6 * cv.abs(),
                "{label}: Gaussian {i} mean {gv} vs {cv}"
            );
        }
        assert!(
            (depth - c.depth).abs() <= 2e-6 * c.depth,
            "{label}: Gaussian {i} depth {depth} vs {}",
            c.depth
        );
        assert_eq!(opacity, c.opacity, "{label}: Gaussian {i} opacity");
        // The tile-culling bound is the kernel's own (log and division: a few ulp).
        let want = kernel.alpha_bound(c.opacity);
        assert!(
            (bound - want).abs() <= 1e-5 * want.abs().max(1.0),
            "{label}: Gaussian {i} bound {bound} vs {want} ({kernel} kernel)"
        );
        let scale = c.conic.iter().fold(0f32, |m, v| m.max(v.abs()));
        for k in 0..3 {
            assert!(
                (g.conic_depth[k] - c.conic[k]).abs() <= 2e-3 * scale,
                "{label}: Gaussian {i} conic {:?} vs {:?}",
                &g.conic_depth[..3],
                c.conic
            );
        }
        assert!(
            (g_radius - c.radius as f32).abs() <= 1.0,
            "{label}: Gaussian {i} radius {g_radius} vs {}",
            c.radius
        );
        for k in 0..3 {
            assert!(
                (g.color_radius[k] - c.color[k]).abs() <= 2e-5,
                "{label}: Gaussian {i} colour {:?} vs {:?}",
                &g.color_radius[..3],
                c.color
            );
        }
        // The packed rectangle agrees with the CPU's, up to one tile where the radius or
        // centre rounding moved an edge; it is empty (the splat not keyed) only where
        // every tile of the CPU's receives less than 1/255 (exact tile culling).
        let [lo, hi] = inter.rects[i];
        let (lo, hi) = (unpack_tile(lo), unpack_tile(hi));
        if hi[0] <= lo[0] || hi[1] <= lo[1] {
            assert!(
                all_empty(c),
                "{label}: Gaussian {i} seen but not keyed: {c:?}"
            );
            continue;
        }
        gpu_keyed += 1;
        for a in 0..2 {
            assert!(
                lo[a].abs_diff(c.rect_min[a]) <= 1 && hi[a].abs_diff(c.rect_max[a]) <= 1,
                "{label}: Gaussian {i} rect"
            );
        }
    }
    assert_eq!(
        inter.counters.visible, gpu_keyed,
        "{label}: visible counter"
    );
    assert!(gpu_visible >= gpu_keyed);
    assert_eq!(inter.splats.len(), n);
}

fn check_scan_keys_sort_ranges(label: &str, inter: &Intermediates) {
    let n = inter.offsets.len();
    let pairs = inter.counters.pairs();
    assert_eq!(
        pairs,
        u64::from(inter.counters.sort_count),
        "{label}: capacity sufficed"
    );
    assert_eq!(inter.keys.len() as u64, pairs);
    // Depth order: a permutation of the Gaussians, keyed ones (a bin receives them: their
    // rectangle is written) by (depth, index), the others after them in index order (a
    // stable sort of (depth bits or !0) keys).
    let keyed = |i: u32| {
        let [lo, hi] = inter.rects[i as usize];
        let (lo, hi) = (unpack_tile(lo), unpack_tile(hi));
        hi[0] > lo[0] && hi[1] > lo[1]
    };
    let sort_key = |i: u32| {
        let sp = &inter.splats[i as usize];
        let depth_bits = if keyed(i) {
            sp.conic_depth[3].to_bits()
        } else {
            u32::MAX
        };
        (depth_bits, i)
    };
    let mut expected: Vec<u32> = (0..n as u32).collect();
    expected.sort_by_key(|&i| sort_key(i));
    assert_eq!(inter.order, expected, "{label}: depth order");
    // Scan: exclusive prefix sum in depth order; each Gaussian's pairs fill exactly its slot.
    let mut per_gaussian = vec![0u32; n];
    for &v in &inter.values {
        per_gaussian[v as usize] += 1;
    }
    let mut acc = 0u32;
    for (k, (&offset, &g)) in inter.offsets.iter().zip(&inter.order).enumerate() {
        assert_eq!(offset, acc, "{label}: offset of depth rank {k}");
        acc += per_gaussian[g as usize];
    }
    assert_eq!(u64::from(acc), pairs);
    assert_eq!(inter.counters.scan_total, acc);
    // Keys: the tile of each pair; pairs sorted by (tile, depth of their Gaussian, index),
    // so stable for equal tiles.
    let tiles = inter.bins.0 * inter.bins.1;
    let depth = |v: u32| inter.splats[v as usize].conic_depth[3].to_bits();
    for (k, (&key, &v)) in inter.keys.iter().zip(&inter.values).enumerate() {
        assert!(key < tiles, "{label}: key {k} tile {key}");
        if k > 0 {
            let p = inter.values[k - 1];
            let prev = (inter.keys[k - 1], depth(p), p);
            assert!(
                prev < (key, depth(v), v),
                "{label}: pairs {} and {k} out of order",
                k - 1
            );
        }
    }
    // Ranges: each tile's run, empty tiles [0, 0).
    let mut covered = 0u32;
    for (t, r) in inter.ranges.iter().enumerate() {
        if r[1] > r[0] {
            covered += r[1] - r[0];
            assert!(
                inter.keys[r[0] as usize..r[1] as usize]
                    .iter()
                    .all(|&k| k == t as u32),
                "{label}: range of tile {t}"
            );
            assert!(r[0] == 0 || inter.keys[r[0] as usize - 1] != t as u32);
            assert!(r[1] as usize == inter.keys.len() || inter.keys[r[1] as usize] != t as u32);
        } else {
            assert_eq!(*r, [0, 0], "{label}: empty tile {t}");
        }
    }
    assert_eq!(u64::from(covered), pairs);
}

fn check_tile_membership(
    label: &str,
    cpu_p: &[Projected],
    inter: &Intermediates,
    cam: &Camera,
    kernel: SplatKernel,
) {
    let (keys, values) = cpu::tile_keys(cpu_p, cam);
    let (sk, sv) = cpu::sort_pairs(&keys, &values);
    let mut cpu_tiles: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (k, v) in sk.iter().zip(&sv) {
        cpu_tiles.entry((k >> 32) as u32).or_default().push(*v);
    }
    let mut gpu_tiles: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (k, v) in inter.keys.iter().zip(&inter.values) {
        gpu_tiles.entry(*k).or_default().push(*v);
    }
    // The GPU keys pairs by bins of `size` pixels (16: the reference tiles, or 8: their
    // quarters); each bin is compared with the reference list of the tile containing it.
    let (size, (bins_x, bins_y)) = (inter.bin_size, inter.bins);
    let tx = cam.tile_grid().0;
    let (mut dropped, mut band) = (0usize, 0usize);
    for b in 0..bins_x * bins_y {
        let bin = [b % bins_x, b / bins_x];
        let tile = [bin[0] * size / 16, bin[1] * size / 16];
        let c = cpu_tiles
            .get(&(tile[1] * tx + tile[0]))
            .cloned()
            .unwrap_or_default();
        let g = gpu_tiles.get(&b).cloned().unwrap_or_default();
        let cs: HashSet<u32> = c.iter().copied().collect();
        let gs: HashSet<u32> = g.iter().copied().collect();
        let on_edge = |p: &Projected| {
            tile[0] + 1 == p.rect_min[0]
                || tile[0] == p.rect_max[0]
                || tile[1] + 1 == p.rect_min[1]
                || tile[1] == p.rect_max[1]
                || tile[0] == p.rect_min[0]
                || tile[0] + 1 == p.rect_max[0]
                || tile[1] == p.rect_min[1]
                || tile[1] + 1 == p.rect_max[1]
        };
        for &id in cs.difference(&gs) {
            let p = &cpu_p[id as usize];
            let a = cpu::max_alpha_in_tile(p, kernel, bin, size, cam.width, cam.height);
            if a < 1.0 / 255.0 {
                dropped += 1; // exact culling: contributes nothing to this bin
            } else {
                assert!(
                    a < 1.001 / 255.0 || on_edge(p),
                    "{label}: bin {bin:?} lost Gaussian {id} with alpha {a}"
                );
                band += 1;
            }
        }
        for &id in gs.difference(&cs) {
            let p = &cpu_p[id as usize];
            assert!(
                p.radius == 0 || on_edge(p),
                "{label}: bin {bin:?} gained Gaussian {id}"
            );
            band += 1;
        }
        let common_c: Vec<u32> = c.iter().copied().filter(|v| gs.contains(v)).collect();
        let common_g: Vec<u32> = g.iter().copied().filter(|v| cs.contains(v)).collect();
        assert_eq!(common_c, common_g, "{label}: order in bin {bin:?}");
    }
    eprintln!(
        "{label}: cpu pairs {}, gpu pairs {}, culled exactly {dropped}, boundary band {band}",
        sk.len(),
        inter.keys.len()
    );
    assert!(
        band * 1000 <= sk.len().max(1000),
        "{label}: too many boundary differences ({band})"
    );
}

fn run_case(label: &str, scene: &ActivatedScene, cam: &Camera) {
    run_case_on(&mut renderer(), label, scene, cam);
}

fn run_case_on(r: &mut GpuRenderer, label: &str, scene: &ActivatedScene, cam: &Camera) {
    run_case_with(r, label, scene, cam, &RenderOptions::default());
}

fn run_case_with(
    r: &mut GpuRenderer,
    label: &str,
    scene: &ActivatedScene,
    cam: &Camera,
    opts: &RenderOptions,
) -> Intermediates {
    let gs = r.upload(scene).unwrap();
    let (_, inter) = r
        .render(&FrameRequest::new(&gs, cam, opts).readback(Readback::Intermediates))
        .and_then(Rendered::into_intermediates)
        .unwrap();
    let cpu_p = cpu::preprocess(scene, cam, opts);
    check_preprocess(label, &cpu_p, &inter, cam, opts.kernel);
    check_scan_keys_sort_ranges(label, &inter);
    check_tile_membership(label, &cpu_p, &inter, cam, opts.kernel);
    assert_validation_clean(r);
    inter
}

#[test]
fn stages_match_on_playbot_lod3_orbit_and_close_up() {
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 640, 360);
    run_case("lod3 orbit", &s, &cam);
    let close = move_towards(&cam, glam::Vec3::new(0.0, -0.5, 0.0), 0.3, "close-up");
    run_case("lod3 close-up", &s, &close);
}

#[test]
fn stages_match_with_16_pixel_bins_of_the_gpu_kernel() {
    // The default kernel on lavapipe keys pairs by 8-pixel bins; the GPU kernel by the
    // reference's 16-pixel tiles. Both are held to the same checks.
    let Some(mut r) = crate::common::gpu::renderer_if_it_fits(BlendKernel::Shared) else {
        return;
    };
    assert_eq!(r.blend_kernel().bin_size(), 16);
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 640, 360);
    run_case_on(&mut r, "lod3 orbit, 16-pixel bins", &s, &cam);
}

#[test]
fn stages_match_on_plant_inside_view() {
    let s = load("plant_113k_sh0.ply");
    // From inside the plant's foliage, looking out sideways: many Gaussians behind the
    // camera and at the near plane.
    let cam = Camera::look_at(
        "inside",
        480,
        320,
        1.2,
        glam::Vec3::new(0.0, -0.15, 0.0),
        glam::Vec3::new(1.0, -0.15, 0.3),
        glam::Vec3::NEG_Y,
    );
    run_case("plant inside", &s, &cam);
}

#[test]
fn stages_match_on_train3_sh3() {
    let s = load("train3_sh3.ply");
    let cam = camera::default_camera(&s.positions, 320, 240);
    run_case("train3", &s, &cam);
}

/// The keys stage culls tiles with the power kernel's own bound, `d2 <= 9 (1 - 1/(255
/// opacity))`: every pair of the reference rectangle it drops gets alpha < 1/255 at every
/// pixel under that kernel (checked pixel by pixel in `check_tile_membership`), and it
/// drops more pairs than the Gaussian bound would (whose support is wider), on both bin
/// sizes.
#[test]
fn stages_match_with_the_power_kernel_and_its_tile_culling() {
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 640, 360);
    let close = move_towards(&cam, glam::Vec3::new(0.0, -0.5, 0.0), 0.3, "close-up");
    let power = RenderOptions {
        kernel: SplatKernel::Power,
        ..Default::default()
    };
    for (kernel, label) in [
        (None, "power, device kernel"),
        (Some(BlendKernel::Shared), "power, 16-pixel bins"),
    ] {
        let mut r = new_renderer(kernel);
        for (cam, view) in [(&cam, "orbit"), (&close, "close-up")] {
            let label = format!("{label}, {view}");
            let p = run_case_with(&mut r, &label, &s, cam, &power);
            let gs = r.upload(&s).unwrap();
            let (_, g) = r
                .render(
                    &FrameRequest::new(&gs, cam, &RenderOptions::default())
                        .readback(Readback::Intermediates),
                )
                .and_then(Rendered::into_intermediates)
                .unwrap();
            assert!(
                p.counters.pairs() < g.counters.pairs(),
                "{label}: power pairs {} vs Gaussian pairs {}",
                p.counters.pairs(),
                g.counters.pairs()
            );
        }
    }
}

/// The saved forward state a backward pass reads (`GpuRenderer::forward_state`) is the
/// frame just finished: its splats, its sorted pairs and bin ranges, and its image, whose
/// alpha is `1 - T_final`.
#[test]
fn forward_state_is_the_finished_frames_pairs_ranges_and_transmittance() {
    let mut r = renderer();
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 320, 180);
    let gs = r.upload(&s).unwrap();
    let (frame, inter) = r
        .render(
            &FrameRequest::new(&gs, &cam, &RenderOptions::default())
                .readback(Readback::Intermediates),
        )
        .and_then(Rendered::into_intermediates)
        .unwrap();
    let state = r.forward_state().unwrap();
    let ctx = r.ctx();
    assert_eq!(state.pairs as usize, inter.values.len());
    assert!(state.pairs > 1000, "a real frame: {} pairs", state.pairs);
    assert_eq!((state.bin_size, state.bins), (inter.bin_size, inter.bins));
    let values: Vec<u32> = state
        .sorted_gaussians
        .buffer
        .read(ctx, inter.values.len())
        .unwrap();
    let keys: Vec<u32> = state
        .sorted_bins
        .buffer
        .read(ctx, inter.keys.len())
        .unwrap();
    let ranges: Vec<[u32; 2]> = state.ranges.buffer.read(ctx, inter.ranges.len()).unwrap();
    let splats: Vec<verisplat::render::forward::types::Splat> =
        state.splats.buffer.read(ctx, inter.splats.len()).unwrap();
    assert_eq!((values, keys), (inter.values.clone(), inter.keys.clone()));
    assert_eq!(ranges, inter.ranges);
    assert_eq!(splats, inter.splats);
    assert_eq!(state.color.size(), (frame.width, frame.height));
    assert_validation_clean(&r);
}

/// With `set_save_forward_state` a frame also saves each pixel's last contributor: one
/// past the index, in the sorted pairs, of the last Gaussian composited into it. Checked
/// against a host walk of the frame's own lists with the blend's rules, and the image
/// must not change for it.
#[test]
fn the_last_contributor_is_the_last_gaussian_each_pixel_composited() {
    // The texel kernel (CPU devices' default) and the shared one (GPUs').
    check_last_contributor(&mut renderer());
    let mut shared = new_renderer(Some(BlendKernel::Shared));
    check_last_contributor(&mut shared);
}

/// A device backward pass takes the forward handle of the frame it differentiates, and
/// the renderer refuses a handle once it has finished a later frame (whose state replaced
/// the first's); the one request type serves both entry points, each refusing the other's
/// kind of pixel gradients.
#[test]
fn a_device_backward_takes_the_handle_of_the_renderers_last_frame() {
    let mut r = renderer();
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 64, 48);
    let gs = r.upload(&s).unwrap();
    let opts = RenderOptions::default();
    r.set_save_forward_state(true);
    let first = r
        .render(&FrameRequest::new(&gs, &cam, &opts).readback(Readback::Counters))
        .and_then(Rendered::into_forward)
        .unwrap();
    let second = r
        .render(&FrameRequest::new(&gs, &cam, &opts).readback(Readback::Counters))
        .and_then(Rendered::into_forward)
        .unwrap();
    // A frame read back as floats has its handle too; the host backward takes it.
    let float = r.render(&FrameRequest::new(&gs, &cam, &opts)).unwrap();
    let third = float.forward();
    let frame = float.into_frame().unwrap();
    r.set_save_forward_state(false);
    let grads = verisplat::core::model::grad::PixelGrads::<f32>::default();
    let e = r
        .backward(&BackwardRequest::new(&second, &gs, &frame, &grads))
        .unwrap_err();
    assert!(
        e.to_string().contains("no longer the renderer's last"),
        "{e}"
    );
    let small = verisplat::core::frame::Frame::background(32, 24, [0.0; 3]);
    let e = r
        .backward(&BackwardRequest::new(&third, &gs, &small, &grads))
        .unwrap_err();
    assert!(e.to_string().contains("the frame given 32x24"), "{e}");
    assert_ne!(first, second);
    assert_eq!(second.size(), (64, 48));
    let e = r
        .device_backward(&BackwardRequest::recorded(&second, &gs))
        .err()
        .expect("an old handle is refused");
    assert!(
        e.to_string().contains("no longer the renderer's last"),
        "{e}"
    );
    // One request for both entry points; each refuses the other's pixel gradients.
    let e = r
        .device_backward(&BackwardRequest::new(&third, &gs, &frame, &grads))
        .err()
        .expect("host gradients on the device path");
    assert!(
        e.to_string().contains("one from the host is backward's"),
        "{e}"
    );
    let e = r
        .backward(&BackwardRequest::recorded(&third, &gs))
        .unwrap_err();
    assert!(e.to_string().contains("device_backward's"), "{e}");
    r.device_backward(&BackwardRequest::recorded(&third, &gs))
        .expect("the last frame's handle");
    assert_validation_clean(&r);
}

fn check_last_contributor(r: &mut GpuRenderer) {
    use verisplat::render::forward::types::Splat;
    let s = load("playbot_lod3_31k_sh2.ply");
    let cam = orbit("playbot_orbit_cameras.synthetic.json", 2, 160, 96);
    let gs = r.upload(&s).unwrap();
    let opts = RenderOptions::default();
    let plain = r
        .render(&FrameRequest::new(&gs, &cam, &opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    assert!(r.forward_state().unwrap().last_contributor.is_none());
    r.set_save_forward_state(true);
    let (saved, inter) = r
        .render(&FrameRequest::new(&gs, &cam, &opts).readback(Readback::Intermediates))
        .and_then(Rendered::into_intermediates)
        .unwrap();
    let state = r.forward_state().unwrap();
    let pixels = (cam.width * cam.height) as usize;
    let last_state: Vec<[u32; 2]> = state
        .last_contributor
        .expect("saved")
        .buffer
        .read(r.ctx(), pixels)
        .unwrap();
    let last: Vec<u32> = last_state.iter().map(|s| s[0]).collect();
    // The saved final transmittance is the frame's: alpha = 1 - T exactly as the blend
    // computed it.
    for (s, a) in last_state.iter().zip(&saved.alpha) {
        assert_eq!(1.0 - f32::from_bits(s[1]), *a);
    }
    r.set_save_forward_state(false);
    assert_eq!(saved, plain, "saving the state changes no pixel");
    // What counts is how the last frame was rendered, not the switch: a frame rendered
    // without it has no last contributor, even when the switch is turned on after it.
    r.render(&FrameRequest::new(&gs, &cam, &opts))
        .and_then(Rendered::into_frame)
        .unwrap();
    r.set_save_forward_state(true);
    assert!(r.forward_state().unwrap().last_contributor.is_none());
    r.set_save_forward_state(false);
    let (bins_x, bin) = (inter.bins.0, inter.bin_size);
    let (mut equal, mut covered) = (0usize, 0usize);
    for y in 0..cam.height {
        for x in 0..cam.width {
            let [start, end] = inter.ranges[((y / bin) * bins_x + x / bin) as usize];
            let (mut t, mut want) = (1.0f32, 0u32);
            for k in start..end {
                let g: &Splat = &inter.splats[inter.values[k as usize] as usize];
                let [mx, my, opacity, _] = g.mean_opacity_bound;
                let [a, b, c, _] = g.conic_depth;
                let (dx, dy) = (mx - x as f32, my - y as f32);
                let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let alpha = (opacity * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let test_t = t * (1.0 - alpha);
                if test_t < 1e-4 {
                    break;
                }
                t = test_t;
                want = k + 1;
            }
            let got = last[(y * cam.width + x) as usize];
            covered += usize::from(want > 0);
            equal += usize::from(got == want);
            if want > 0 {
                assert!(
                    got > start && got <= end,
                    "pixel ({x}, {y}): {got} outside {start}..{end}"
                );
            }
        }
    }
    // exp and the FMA contraction of the device may flip a 1/255 or 1e-4 decision on a
    // rare pixel; every other pixel names the same Gaussian.
    let share = equal as f64 / pixels as f64;
    assert!(
        covered > pixels / 10,
        "{covered} of {pixels} pixels covered"
    );
    assert!(share >= 0.999, "{equal} of {pixels} pixels agree ({share})");
    assert_validation_clean(r);
}
