//! Unit tests of the fitting model: analytic gradients against central finite
//! differences, the cell culling against a brute-force sum, and thread-count independence.

use super::model::*;
use super::*;

/// A small random model: `g` Gaussians with `k` features, anisotropic and rotated, in the
/// box [-1, 1]^3.
fn random_model(g: usize, k: usize, seed: u64) -> Model {
    let mut rng = Rng(seed);
    let mut m = Model::new(k);
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
    }
    m
}

fn random_points(n: usize, k: usize, seed: u64) -> (CellGrid, Points) {
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
    let points = Points::binned(&grid, &pos, &values, &weights, k);
    (grid, points)
}

/// Checks every parameter of every Gaussian: the analytic derivative against the central
/// differences `(L(p + h) - L(p - h)) / 2h` for h = 3e-3, 1e-3, 3e-4 and 1e-4 (f32 evaluation,
/// f64 sums). One step size can be spoilt where it moves a sample across the Gaussian's
/// truncation at 4 sigma (a jump of 3.4e-4 in the kernel) or the power kernel's kink at
/// 3 sigma, so the check passes when the closest of the four agrees: within 2 % of the
/// larger of the two plus 2e-3 of the largest gradient component of the same parameter
/// group. A wrong formula misses at every step size.
fn check_gradients(kernel: SplatKernel) {
    let k = 3;
    let model = random_model(6, k, 11);
    let (grid, points) = random_points(600, k, 12);
    let cfg = LossConfig {
        kernel,
        scale_reg: 0.5,
        reg_length: 2.0,
    };
    let lg = loss_and_grad(&model, &cfg, &grid, &points);
    assert!((lg.total() - loss(&model, &cfg, &grid, &points)).abs() < 1e-9 * lg.total().max(1.0));
    let stride = model.stride();
    let groups: [(&str, std::ops::Range<usize>); 5] = [
        ("position", 0..3),
        ("log scale", SCALE..SCALE + 3),
        ("quaternion", ROT..ROT + 4),
        ("opacity logit", LOGIT..LOGIT + 1),
        ("feature", FEAT..FEAT + k),
    ];
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
    check_gradients(SplatKernel::Gaussian);
}

#[test]
fn gradients_match_finite_differences_power_kernel() {
    check_gradients(SplatKernel::Power);
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
    let (c, s) = optim::densify(&mut m, &mut adam, &score, 3);
    assert_eq!(c + s, 3);
    assert_eq!(m.len(), 8);
    assert_eq!(adam.m.len(), m.params.len());
    // Everything pruned: the most opaque one stays.
    let mut score = vec![0.0; 8];
    assert_eq!(optim::prune(&mut m, &mut adam, &mut score, 1.1), 7);
    assert_eq!(m.len(), 1);
}
