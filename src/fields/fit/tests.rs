//! Unit tests of the fitting model: analytic gradients against central finite
//! differences, the cell culling against a brute-force sum, and thread-count independence.

use super::model::*;
use super::*;
use crate::core::gen::Rng;

/// A small random model: `g` Gaussians with `k` features, anisotropic and rotated, in the
/// box [-1, 1]^3.
fn random_model(g: usize, k: usize, seed: u64) -> Model {
    random_model_in_time(g, k, seed, false)
}

/// [`random_model`], with `time` a temporal mean in 0..1 and a temporal scale 0.15..0.5
/// per Gaussian.
fn random_model_in_time(g: usize, k: usize, seed: u64, time: bool) -> Model {
    let mut rng = Rng(seed);
    let mut m = if time {
        Model::with_time(k)
    } else {
        Model::new(k)
    };
    for _ in 0..g {
        for _ in 0..3 {
            m.params.push(rng.range(-0.5, 0.5));
        }
        for _ in 0..3 {
            m.params.push(rng.range(0.15f32.ln(), 0.5f32.ln()));
        }
        // An unnormalised quaternion (the gradient goes through the normalisation).
        let q = [
            rng.range(0.5, 1.5),
            rng.range(-0.6, 0.6),
            rng.range(-0.6, 0.6),
            rng.range(-0.6, 0.6),
        ];
        m.params.extend_from_slice(&q);
        m.params.push(rng.range(-1.0, 2.0));
        for _ in 0..k {
            m.params.push(rng.range(-1.0, 1.0));
        }
        if time {
            m.params.push(rng.range(0.0, 1.0));
            m.params.push(rng.range(0.15f32.ln(), 0.5f32.ln()));
        }
    }
    m
}

fn random_points(n: usize, k: usize, seed: u64) -> (CellGrid, Points) {
    random_points_in_time(n, k, seed, false)
}

/// [`random_points`], with `time` a time in 0..1 per sample.
fn random_points_in_time(n: usize, k: usize, seed: u64, time: bool) -> (CellGrid, Points) {
    let mut rng = Rng(seed);
    let pos: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            [
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ]
        })
        .collect();
    let values: Vec<f32> = (0..n * k).map(|_| rng.range(-1.0, 1.0)).collect();
    let weights: Vec<f32> = (0..n).map(|_| rng.range(0.1, 1.0)).collect();
    let grid = CellGrid::with_side([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0], 0.3);
    let times: Vec<f32> = if time {
        (0..n).map(|_| rng.range(0.0, 1.0)).collect()
    } else {
        Vec::new()
    };
    let points = Points::binned(&grid, &pos, &values, &weights, &times, k);
    (grid, points)
}

/// Checks every parameter of every Gaussian: the analytic derivative against the central
/// differences `(L(p + h) - L(p - h)) / 2h` for h = 3e-3, 1e-3, 3e-4 and 1e-4 (f32 evaluation,
/// f64 sums). One step size can be spoilt where it moves a sample across the Gaussian's
/// truncation at 4 sigma (a jump of 3.4e-4 in the kernel) or the power kernel's kink at
/// 3 sigma, so the check passes when the closest of the four agrees: within 2 % of the
/// larger of the two plus 2e-3 of the largest gradient component of the same parameter
/// group. A wrong formula misses at every step size.
fn check_gradients(kernel: SplatKernel, time: bool) {
    let k = 3;
    let model = random_model_in_time(6, k, 11, time);
    let (grid, points) = random_points_in_time(600, k, 12, time);
    let cfg = LossConfig {
        kernel,
        scale_reg: 0.5,
        reg_length: 2.0,
    };
    let lg = loss_and_grad(&model, &cfg, &grid, &points);
    assert!((lg.total() - loss(&model, &cfg, &grid, &points)).abs() < 1e-9 * lg.total().max(1.0));
    let stride = model.stride();
    let mut groups: Vec<(&str, std::ops::Range<usize>)> = vec![
        ("position", 0..3),
        ("log scale", SCALE..SCALE + 3),
        ("quaternion", ROT..ROT + 4),
        ("opacity logit", LOGIT..LOGIT + 1),
        ("feature", FEAT..FEAT + k),
    ];
    if time {
        let t = model.time_offset();
        groups.push(("temporal mean", t..t + 1));
        groups.push(("log temporal scale", t + 1..t + 2));
    }
    for (name, range) in groups {
        let group_max = (0..model.len())
            .flat_map(|i| range.clone().map(move |j| i * stride + j))
            .map(|p| lg.grad[p].abs())
            .fold(0f32, f32::max);
        assert!(
            group_max > 1e-4,
            "{kernel} {name}: the test exercises this group ({group_max})"
        );
        for i in 0..model.len() {
            for j in range.clone() {
                let p = i * stride + j;
                let an = f64::from(lg.grad[p]);
                let fd = [3e-3f32, 1e-3, 3e-4, 1e-4]
                    .map(|h| {
                        let mut plus = model.clone();
                        plus.params[p] += h;
                        let mut minus = model.clone();
                        minus.params[p] -= h;
                        (loss(&plus, &cfg, &grid, &points) - loss(&minus, &cfg, &grid, &points))
                            / (2.0 * f64::from(h))
                    })
                    .into_iter()
                    .min_by(|a, b| (a - an).abs().total_cmp(&(b - an).abs()))
                    .unwrap_or(f64::NAN);
                let tol = 0.02 * an.abs().max(fd.abs()) + 2e-3 * f64::from(group_max);
                assert!(
                    (an - fd).abs() <= tol,
                    "{kernel} kernel, {name} of Gaussian {i} (slot {j}): analytic {an:e}, finite difference {fd:e}"
                );
            }
        }
    }
}

#[test]
fn gradients_match_finite_differences_gaussian_kernel() {
    check_gradients(SplatKernel::Gaussian, false);
}

#[test]
fn gradients_match_finite_differences_power_kernel() {
    check_gradients(SplatKernel::Power, false);
}

/// Space-time Gaussians: every group, the temporal mean and log scale too, for both kernels
/// (the temporal factor is Gaussian with either).
#[test]
fn gradients_match_finite_differences_in_space_and_time() {
    check_gradients(SplatKernel::Gaussian, true);
    check_gradients(SplatKernel::Power, true);
}

/// The model's temporal factor is the scene's (the one the renders at a time apply):
/// a time-varying model evaluated at time t equals the static model of
/// `Scene::at_time(t)` to f32 rounding of the opacity's logit.
#[test]
fn model_at_a_time_equals_the_scene_at_that_time() {
    let model = random_model_in_time(8, 2, 21, true);
    let mut scene = crate::core::scene::Scene::empty(0);
    scene.feature_count = 2;
    let t_at = model.time_offset();
    let mut times = Vec::new();
    for i in 0..model.len() {
        let g = model.gaussian(i);
        scene.positions.push([g[0], g[1], g[2]]);
        scene
            .log_scales
            .push([g[SCALE], g[SCALE + 1], g[SCALE + 2]]);
        scene
            .rotations
            .push([g[ROT], g[ROT + 1], g[ROT + 2], g[ROT + 3]]);
        scene.opacity_logits.push(g[LOGIT]);
        scene.sh.extend_from_slice(&[0.0; 3]);
        scene.features.extend_from_slice(model.features(i));
        times.push([g[t_at], g[t_at + 1]]);
    }
    scene.time = Some(times);
    assert_eq!(Model::from_scene(&scene).params.len(), model.params.len());
    let mut rng = Rng(3);
    let pos: Vec<[f32; 3]> = (0..300)
        .map(|_| {
            [
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ]
        })
        .collect();
    let mut compared = 0;
    for t in [-0.5f32, 0.0, 0.3, 0.77, 1.0, 2.5] {
        let want = evaluate_at(
            &model,
            SplatKernel::Gaussian,
            &pos,
            Some(&vec![t; pos.len()]),
        )
        .unwrap();
        let at = Model::from_scene(&scene.at_time(t));
        assert!(!at.time);
        let got = evaluate(&at, SplatKernel::Gaussian, &pos);
        let peak = want.iter().fold(0f32, |m, v| m.max(v.abs()));
        for (a, b) in want.iter().zip(&got) {
            assert!(
                (a - b).abs() <= 1e-5 * peak.max(1e-3),
                "t = {t}: {a} vs {b}"
            );
        }
        compared += usize::from(peak > 1e-3);
    }
    assert!(compared >= 4, "the times compared see the field");
    assert!(evaluate_at(&model, SplatKernel::Gaussian, &pos, None).is_err());
    assert!(evaluate_at(
        &model.without_time(),
        SplatKernel::Gaussian,
        &pos,
        Some(&[0.0])
    )
    .is_err());
}

/// The cell culling loses nothing: the binned forward pass equals a sum over every
/// Gaussian and sample pair (the same kernel and cutoff).
#[test]
fn culled_forward_equals_brute_force() {
    for kernel in SplatKernel::ALL {
        let k = 2;
        let model = random_model(40, k, 3);
        let (grid, points) = random_points(2000, k, 4);
        let f = forward(&model, kernel, &grid, &points);
        let cut = cutoff(kernel);
        for (n, x) in points.positions.iter().enumerate() {
            let mut want = [0f64; 2];
            for i in 0..model.len() {
                let g = model.gaussian(i);
                let q = &g[ROT..ROT + 4];
                let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
                let r = rotation([q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm]);
                let d = [x[0] - g[0], x[1] - g[1], x[2] - g[2]];
                let d2: f32 = (0..3)
                    .map(|j| {
                        let u = r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2];
                        (u / g[SCALE + j].exp()).powi(2)
                    })
                    .sum();
                if d2 <= cut {
                    let a = sigmoid(g[LOGIT]) * kernel_value(kernel, d2).0;
                    for c in 0..k {
                        want[c] += f64::from(a * g[FEAT + c]);
                    }
                }
            }
            for c in 0..k {
                assert!(
                    (f64::from(f[n * k + c]) - want[c]).abs() < 1e-4,
                    "{kernel}: sample {n} channel {c}: {} vs {}",
                    f[n * k + c],
                    want[c]
                );
            }
        }
    }
}

/// The same bits with one thread and with three.
#[test]
fn results_do_not_depend_on_the_thread_count() {
    let model = random_model(50, 4, 5);
    let (grid, points) = random_points(3000, 4, 6);
    let cfg = LossConfig {
        kernel: SplatKernel::Gaussian,
        scale_reg: 0.01,
        reg_length: 3.0,
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let lg = loss_and_grad(&model, &cfg, &grid, &points);
                (lg.data.to_bits(), lg.grad, lg.score)
            })
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn bounds_parse_and_reject() {
    assert_eq!(
        parse_bounds("-1,-2,-3,1,2,3").unwrap(),
        [-1.0, -2.0, -3.0, 1.0, 2.0, 3.0]
    );
    assert!(parse_bounds("0,0,0,1,1").unwrap_err().contains("6 numbers"));
    assert!(parse_bounds("0,0,1,1,1,1")
        .unwrap_err()
        .contains("zmin (1) must be below zmax (1)"));
    assert!(parse_bounds("0,0,0,1,x,1").unwrap_err().contains("\"x\""));
    assert!(parse_bounds("0,0,0,1,nan,1")
        .unwrap_err()
        .contains("finite"));
}

/// Pruning drops exactly the Gaussians below the threshold; densification adds at most
/// its budget and splits large / clones small ones.
#[test]
fn density_control_counts() {
    let mut m = random_model(10, 2, 9);
    let stride = m.stride();
    for i in 0..5 {
        m.params[i * stride + LOGIT] = -8.0; // opacity 3e-4
    }
    let mut adam = optim::Adam::new(m.params.len());
    let mut score: Vec<f32> = (0..10).map(|i| i as f32).collect();
    assert_eq!(optim::prune(&mut m, &mut adam, &mut score, 0.01), 5);
    assert_eq!(m.len(), 5);
    assert_eq!(score, vec![5.0, 6.0, 7.0, 8.0, 9.0]);
    let (c, s) = optim::densify(&mut m, &mut adam, &score, 3, 0.0);
    assert_eq!(c + s, 3);
    assert_eq!(m.len(), 8);
    assert_eq!(adam.m.len(), m.params.len());
    // Everything pruned: the most opaque one stays.
    let mut score = vec![0.0; 8];
    assert_eq!(optim::prune(&mut m, &mut adam, &mut score, 1.1), 7);
    assert_eq!(m.len(), 1);
}

/// With time, the longest of the four axes is split: a Gaussian long in time becomes two
/// at tau -+ s_t with the same centre and a shorter temporal scale; one long in space two
/// centres apart with the same temporal mean.
#[test]
fn density_control_splits_along_time_or_space() {
    let mut m = random_model_in_time(6, 1, 13, true);
    let (stride, t) = (m.stride(), m.time_offset());
    for i in 0..6 {
        let g = &mut m.params[i * stride..(i + 1) * stride];
        g[SCALE..SCALE + 3].copy_from_slice(&[0.1f32.ln(); 3]);
        g[t] = 0.5;
        g[t + 1] = 0.05f32.ln();
    }
    // Gaussian 0: long in time (0.4 of the span against 0.1 / 1 of the largest side);
    // Gaussian 1: long along its first axis (0.6).
    m.params[t + 1] = 0.4f32.ln();
    m.params[stride + SCALE] = 0.6f32.ln();
    let before = m.clone();
    let mut adam = optim::Adam::new(m.params.len());
    let (cloned, split) =
        optim::densify(&mut m, &mut adam, &[2.0, 1.0, 0.0, 0.0, 0.0, 0.0], 2, 0.0);
    assert_eq!((cloned, split), (0, 2));
    let (g0, g1) = (m.gaussian(0), m.gaussian(6));
    assert_eq!(&g0[..3], &before.gaussian(0)[..3]);
    assert_eq!(&g1[..3], &before.gaussian(0)[..3]);
    assert!(
        (g0[t] - 0.1).abs() < 1e-6 && (g1[t] - 0.9).abs() < 1e-6,
        "{} {}",
        g0[t],
        g1[t]
    );
    assert!((g0[t + 1] - (0.4f32 / 1.6).ln()).abs() < 1e-5);
    let (h0, h1) = (m.gaussian(1), m.gaussian(7));
    assert_eq!((h0[t], h1[t]), (0.5, 0.5));
    assert_ne!(&h0[..3], &h1[..3]);
    assert_eq!(h0[t + 1], 0.05f32.ln());
}
