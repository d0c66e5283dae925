//! Inputs that used to make `fit` fail silently (issue 26, part 2): values in any unit,
//! scans on a plane or a line, degenerate inputs, the default Gaussian counts, a fit no
//! better than 0, dB magnitudes, the bounds `gen --rf` prints, and gradient clipping.

use crate::common::cli::{fails, ok, s, stderr};
use verisplat::core::gen::Rng;
use verisplat::fields::fit::{self, FieldData, FitConfig, Layout};

/// Two clamped dipole-like sources (magnitude `sin(theta) / r`, `r >= 0.25`), the field
/// the CSV held.
fn two_dipoles(p: [f32; 3]) -> f32 {
    let mut v = 0.0;
    for (c, a) in [([-0.5f32, 0.0, 0.0], 1.0f32), ([0.6, 0.2, 0.1], 0.7)] {
        let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(0.25);
        let cos = (d[2] / r).clamp(-1.0, 1.0);
        v += a * (1.0 - cos * cos).sqrt() / r;
    }
    v
}

/// `n` samples of [`two_dipoles`] times `scale`; `dims` axes spread over -2..2, the others 0.
fn samples(n: usize, dims: usize, scale: f64) -> FieldData {
    let mut rng = Rng(5);
    let positions: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let mut p = [0f32; 3];
            for v in p.iter_mut().take(dims) {
                *v = rng.range(-2.0, 2.0);
            }
            p
        })
        .collect();
    let values = positions
        .iter()
        .map(|p| (f64::from(two_dipoles(*p)) * scale) as f32)
        .collect();
    FieldData {
        bounds: fit::model::point_bounds(&positions),
        times: None,
        time_column: None,
        positions,
        values,
        k: 1,
        layout: Layout::SamplesNpy,
        bounds_source: "the samples' extent".into(),
    }
}

fn quick(initial: usize) -> FitConfig {
    FitConfig {
        initial,
        max_gaussians: 4 * initial,
        steps: 200,
        densify_every: 50,
        batch: 4096,
        ..FitConfig::default()
    }
}

fn holdout(data: &FieldData, cfg: &FitConfig) -> f64 {
    let out = fit::fit(data, cfg, &mut |_| {}).unwrap();
    out.holdout.unwrap().relative_l2
}

/// The same samples in units 1e-9 .. 1e30 times apart give the same held-out error to
/// 0.005 (f32 rounding of the scaled values changes the trajectory a little; measured
/// within 1e-4), and the fitted features carry the unit.
#[test]
fn the_fit_does_not_depend_on_the_unit_of_the_values() {
    let cfg = quick(100);
    let base = holdout(&samples(2000, 3, 1.0), &cfg);
    assert!(base < 0.3, "unscaled: {base}");
    for scale in [1e-9, 1e-6, 1e-3, 1e6, 1e9, 1e30] {
        let data = samples(2000, 3, scale);
        let out = fit::fit(&data, &cfg, &mut |_| {}).unwrap();
        let e = out.holdout.as_ref().unwrap().relative_l2;
        eprintln!("values x {scale:e}: held-out error {e:.4} (unscaled {base:.4})");
        assert!((e - base).abs() < 5e-3, "x {scale:e}: {e} vs {base}");
        let peak = out
            .model
            .params
            .chunks_exact(out.model.stride())
            .map(|g| g[11].abs())
            .fold(0f32, f32::max);
        assert!(
            f64::from(peak) > 0.05 * scale && f64::from(peak) < 20.0 * scale,
            "features in the data's unit: {peak}"
        );
    }
}

/// 2,000 samples on the plane z = 0 and 400 on the line y = z = 0: below 0.15 held-out
/// error (measured 0.041 and 0.011; before, a plane gave 1.4-1.6), each with a note on the
/// thickness chosen; `--bounds` gives scattered samples their box.
#[test]
fn scans_on_a_plane_or_a_line_fit() {
    for (dims, n) in [(2, 2000), (1, 400)] {
        let data = samples(n, dims, 1.0);
        let out = fit::fit(&data, &quick(50), &mut |_| {}).unwrap();
        let e = out.holdout.as_ref().unwrap().relative_l2;
        eprintln!("{dims}-D scan: held-out error {e:.4}; {:?}", out.notes);
        assert!(e < 0.15, "{dims}-D scan: {e}");
        let shape = if dims == 2 { "a plane" } else { "a line" };
        assert!(
            out.notes.iter().any(|n| n.contains(shape)),
            "{:?}",
            out.notes
        );
        assert!(
            out.fit_bounds[5] > out.fit_bounds[2],
            "the flat axis has a thickness"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("plane.csv");
    let mut text = String::from("x,y,z,v\n");
    let d = samples(500, 2, 1.0);
    for (p, v) in d.positions.iter().zip(&d.values) {
        text += &format!("{},{},{},{v}\n", p[0], p[1], p[2]);
    }
    std::fs::write(&csv, text).unwrap();
    let rep = dir.path().join("r.json");
    // The bounds exactly as gen --rf prints them (a space, then negative numbers).
    ok(&[
        "fit",
        s(&csv),
        "-o",
        s(&dir.path().join("p.ply")),
        "--bounds",
        "-2,-2,-0.1,2,2,0.1",
        "--steps",
        "50",
        "-q",
        "--report",
        s(&rep),
    ]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(r["fit_bounds"][2].as_f64().unwrap() as f32, -0.1);
    assert_eq!(r["bounds_from"], "--bounds");
    let out = dir.path().join("q.ply");
    let e = fails(
        &[
            "fit",
            s(&csv),
            "-o",
            s(&out),
            "--bounds",
            "-1,-2,-0.1,2,2,0.1",
        ],
        &out,
    );
    assert!(e.contains("lies outside --bounds"), "{e}");
}

/// One sample, every sample at one point, every value 0, and a magnitude channel with no
/// positive value (dB) are refused with the reason; --db fits dB in linear power: the
/// held-out RMS error in dB stays below 3 dB (measured 2.0 dB with 400 steps; the power
/// 1/r^2 is steeper than the magnitude, and the floor is 40 dB below the peak).
#[test]
fn degenerate_inputs_are_refused_and_db_is_fitted_in_power() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.ply");
    let case = |name: &str, rows: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, format!("x,y,z,v\n{rows}")).unwrap();
        p
    };
    for (name, rows, says) in [
        ("one.csv", "0,0,0,1\n".to_string(), "holds 1 sample"),
        (
            "point.csv",
            "1,1,1,1\n1,1,1,2\n1,1,1,3\n".to_string(),
            "lie at one point (1, 1, 1)",
        ),
        (
            "zero.csv",
            "0,0,0,0\n1,0,0,0\n0,1,0,0\n".to_string(),
            "every value is 0",
        ),
    ] {
        let p = case(name, &rows);
        let e = fails(&["fit", s(&p), "-o", s(&out)], &out);
        assert!(e.contains(says) && e.contains(name), "{name}: {e}");
    }
    let d = samples(1500, 3, 1.0);
    let mut rows = String::new();
    for (p, v) in d.positions.iter().zip(&d.values) {
        rows += &format!("{},{},{},{}\n", p[0], p[1], p[2], 20.0 * v.log10() - 60.0);
    }
    let p = case("db.csv", &rows);
    let e = fails(&["fit", s(&p), "-o", s(&out)], &out);
    assert!(e.contains("pass --db"), "{e}");
    let o = ok(&["fit", s(&p), "-o", s(&out), "--db", "--steps", "400", "-q"]);
    let line = String::from_utf8_lossy(&o.stdout).to_string();
    let db = line
        .split("magnitude RMS error ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("{line}"));
    eprintln!("dB input: held-out magnitude error {db} dB");
    assert!(db < 3.0, "{line}");
}

/// Zero-mean noise cannot be fitted: the fit says loudly (stderr, even with -q, and the
/// report) that it is no better than predicting 0; the default counts follow the samples
/// and are printed.
#[test]
fn a_fit_no_better_than_zero_says_so_and_defaults_follow_the_data() {
    assert_eq!(fit::default_counts(4050), (202, 810));
    assert_eq!(fit::default_counts(64 * 64 * 64), (1000, 4000));
    assert_eq!(fit::default_counts(40), (8, 8));
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(3);
    let mut text = String::from("x,y,z,v\n");
    for _ in 0..600 {
        let p = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ];
        let v = if rng.unit() < 0.5 { -1.0 } else { 1.0 } * (1.0 + rng.unit());
        text += &format!("{},{},{},{v}\n", p[0], p[1], p[2]);
    }
    let csv = dir.path().join("noise.csv");
    std::fs::write(&csv, text).unwrap();
    let rep = dir.path().join("r.json");
    let o = ok(&[
        "fit",
        s(&csv),
        "-o",
        s(&dir.path().join("n.ply")),
        "--steps",
        "100",
        "--report",
        s(&rep),
        "-q",
    ]);
    let err = stderr(&o);
    assert!(err.contains("no better than predicting 0"), "{err}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert!(r["holdout_relative_l2"].as_f64().unwrap() >= 1.0);
    assert_eq!(r["warnings"].as_array().unwrap().len(), 1);
    let o = ok(&[
        "fit",
        s(&csv),
        "-o",
        s(&dir.path().join("m.ply")),
        "--steps",
        "10",
    ]);
    assert!(
        stderr(&o).contains("chose --gaussians 30 --max-gaussians 120 for 600 samples"),
        "{}",
        stderr(&o)
    );
}

/// --clip-grad: a bound above every step's gradient norm changes nothing (same
/// parameters, bit for bit); a tiny one clips every step and the fit stays finite.
#[test]
fn gradient_clipping() {
    let data = samples(800, 3, 1.0);
    let base = fit::fit(&data, &quick(40), &mut |_| {}).unwrap();
    let loose = fit::fit(
        &data,
        &FitConfig {
            clip_grad: 1e30,
            ..quick(40)
        },
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(loose.clipped_steps, 0);
    assert_eq!(base.model.params, loose.model.params);
    let tight = fit::fit(
        &data,
        &FitConfig {
            clip_grad: 1e-6,
            ..quick(40)
        },
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(tight.clipped_steps, 200);
    assert!(tight.model.params.iter().all(|v| v.is_finite()));
    assert_ne!(tight.model.params, base.model.params);
}

/// A complex field given as magnitude and phase: a plane wave `exp(i k x)` (wavelength 0.8)
/// under a Gaussian envelope (sigma 0.6). Fitted as I/Q (`--complex 0,1`) the held-out
/// error is below 0.1 (measured 0.052); fitted as the two channels themselves the phase
/// channel's wraps cost it (measured 0.45; asserted worse by half). Rendered with
/// `--complex 0,1`, the slice z = 0 carries |f| and its phase: the magnitude within 0.06
/// relative L2 of the envelope (measured 0.027) and the phase within 0.1 rad RMS where the
/// envelope is above 0.3 (measured 0.025).
#[test]
fn complex_fields_fit_as_iq_and_render_their_magnitude_and_phase() {
    use verisplat::cpu::field;
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let k = std::f64::consts::TAU / 0.8;
    let envelope = |x: [f64; 3]| (-(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) / (2.0 * 0.36)).exp();
    let mut rng = Rng(4);
    let mut text = String::from("x,y,z,magnitude,phase\n");
    for _ in 0..3000 {
        let x = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ]
        .map(f64::from);
        let phase = (k * x[0]).sin().atan2((k * x[0]).cos());
        text += &format!("{},{},{},{},{phase}\n", x[0], x[1], x[2], envelope(x));
    }
    std::fs::write(p("wave.csv"), &text).unwrap();
    let csv = p("wave.csv");
    let held_out = |extra: &[&str], out: &str| {
        let (rep, o) = (p(&format!("{out}.json")), p(out));
        let mut a = vec![
            "fit",
            s(&csv),
            "-o",
            s(&o),
            "--steps",
            "400",
            "-q",
            "--report",
            s(&rep),
        ];
        a.extend_from_slice(extra);
        ok(&a);
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        r["holdout_relative_l2"].as_f64().unwrap()
    };
    let iq = held_out(&["--complex", "0,1"], "iq.ply");
    let plain = held_out(&[], "plain.ply");
    eprintln!("held-out error: as I/Q {iq:.4}, as magnitude and phase {plain:.4}");
    assert!(iq < 0.1, "{iq}");
    assert!(plain > 1.5 * iq, "{plain} vs {iq}");
    let cam = verisplat::core::camera::Camera::look_at(
        "wave",
        48,
        36,
        50f32.to_radians(),
        glam::Vec3::new(0.5, -2.0, -3.0),
        glam::Vec3::ZERO,
        glam::Vec3::NEG_Y,
    );
    std::fs::write(
        p("cam.json"),
        verisplat::io::camera::inria::to_json(&[(0, cam.clone())]).unwrap(),
    )
    .unwrap();
    let npy = p("slice.npy");
    ok(&[
        "render",
        s(&p("iq.ply")),
        "--cameras",
        s(&p("cam.json")),
        "--mode",
        "field-slice",
        "--slice-plane",
        "0,0,0,0,0,1",
        "--complex",
        "0,1",
        "-o",
        s(&npy),
        "-q",
    ]);
    let a =
        verisplat::io::image_file::parse_npy_array(&std::fs::read(&npy).unwrap(), &npy).unwrap();
    assert_eq!(a.shape, vec![36, 48, 4]);
    let (mut num, mut den, mut phase_sq, mut phased) = (0f64, 0f64, 0f64, 0);
    for py in 0..36u32 {
        for px in 0..48u32 {
            let (o, d) = field::pixel_ray(&cam, px, py);
            let Some(t) = field::slice_hit(o, d, [0.0; 3], [0.0, 0.0, 1.0]) else {
                continue;
            };
            let x = [o[0] + t * d[0], o[1] + t * d[1], 0.0];
            if x[0].abs() > 1.0 || x[1].abs() > 1.0 {
                continue;
            }
            let v = &a.data[((py * 48 + px) * 4) as usize..][..4];
            let env = envelope(x);
            num += (f64::from(v[2]) - env).powi(2);
            den += env * env;
            if env > 0.3 {
                let diff = f64::from(v[3]) - k * x[0];
                phase_sq += diff.sin().atan2(diff.cos()).powi(2);
                phased += 1;
            }
        }
    }
    let magnitude = (num / den).sqrt();
    let phase = (phase_sq / f64::from(phased)).sqrt();
    eprintln!("slice: magnitude relative L2 {magnitude:.4}, phase RMS {phase:.4} rad over {phased} pixels");
    assert!(phased > 100, "{phased}");
    assert!(magnitude < 0.06, "{magnitude}");
    assert!(phase < 0.1, "{phase}");
    let out = p("m.png");
    let e = crate::common::cli::fails(
        &[
            "render",
            s(&p("iq.ply")),
            "--mode",
            "field-max",
            "--complex",
            "0,1",
            "-o",
            s(&out),
        ],
        &out,
    );
    assert!(
        e.contains("--complex applies to field-slice and field-integral"),
        "{e}"
    );
}
