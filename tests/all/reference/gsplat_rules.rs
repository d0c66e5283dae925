//! gsplat's rules (`--rules gsplat`, `model::Rules::Gsplat`) in the CPU reference: every
//! tail of a splat is kept (the frame equals a blend of every Gaussian at every pixel),
//! where the original's 3-sigma disc cuts some. The device under them is
//! `render::gsplat_rules`, their gradients and training `train::gsplat_rules`.

use crate::common::gpu::move_towards;
use crate::common::{orbit, shared_scene, PLAYBOT_ORBIT};
use glam::Vec3;
use verisplat::cpu::{self, RenderOptions, Rules};

/// Pixel (x, y) blended from every projected Gaussian, front to back, without tiles.
fn dense_pixel(
    p: &[cpu::Projected],
    order: &[u32],
    x: u32,
    y: u32,
    opts: &RenderOptions,
) -> [f32; 4] {
    let r = cpu::blend_pixel(p, order, x as f32, y as f32, opts.kernel, opts.rules);
    let t = r.transmittance;
    let b = opts.background;
    [
        r.color[0] + t * b[0],
        r.color[1] + t * b[1],
        r.color[2] + t * b[2],
        1.0 - t,
    ]
}

/// Under gsplat's rules no tail of a splat is cut at a tile edge: the reference frame equals,
/// bit for bit at every pixel, the blend of every visible Gaussian in depth order (the box
/// holds every pixel where alpha >= 1/255). The original's 3-sigma disc cuts the tails of
/// opaque splats, so there the two differ.
#[test]
fn gsplat_rules_keep_every_tail_the_original_cuts() {
    let s = shared_scene("playbot_lod6_1873_sh2.ply").activated();
    let wide = orbit(PLAYBOT_ORBIT, 4, 160, 120);
    let close = move_towards(&wide, Vec3::new(0.0, -0.5, 0.0), 0.4, "closer");
    let mut cut = [0usize; 2];
    for cam in [&wide, &close] {
        for (k, rules) in Rules::ALL.into_iter().enumerate() {
            let opts = RenderOptions {
                rules,
                background: [0.1, 0.2, 0.3],
                ..Default::default()
            };
            let frame = cpu::render(&s, cam, &opts);
            let p = cpu::preprocess(&s, cam, &opts);
            let mut order: Vec<u32> = (0..p.len() as u32)
                .filter(|&i| p[i as usize].radius > 0)
                .collect();
            order.sort_by(|&a, &b| p[a as usize].depth.total_cmp(&p[b as usize].depth));
            for y in 0..cam.height {
                for x in 0..cam.width {
                    let i = (y * cam.width + x) as usize;
                    let got = [
                        frame.color[i][0],
                        frame.color[i][1],
                        frame.color[i][2],
                        frame.alpha[i],
                    ];
                    if got != dense_pixel(&p, &order, x, y, &opts) {
                        cut[k] += 1;
                    }
                }
            }
        }
    }
    eprintln!(
        "pixels that differ from the dense blend: original {}, gsplat {}",
        cut[0], cut[1]
    );
    assert_eq!(cut[1], 0, "gsplat's rules cut a tail");
    assert!(
        cut[0] > 0,
        "the original's disc cuts nothing here; the test shows nothing"
    );
}
