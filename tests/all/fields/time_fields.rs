//! Time-varying fields: `gen --rf moving-source` -> `fit` in space and time -> `render
//! --time T` / `--time-range`, against the analytic moving source; the PLY's `t_mean`,
//! `t_scale`; `Scene::at_time` on the GPU and the CPU reference; the animation's frames;
//! the errors for bad time inputs.

use crate::common::cli::{fails, ok, s, stderr, verisplat};
use crate::common::npy_image as npy;
use crate::common::push_gaussian;
use std::path::Path;
use verisplat::core::scene::Scene;
use verisplat::cpu::field;
use verisplat::fields::rf::MovingSource;
use verisplat::io::scene::ply::{self, PlyEncoding};

/// The moving source fitted in space and time, rendered at three times (two of them
/// between the sampled times) as a slice through z = 0 and as a maximum along each ray,
/// against the analytic field at those times.
///
/// The fit is small (12^3 points at 7 times, 150 Gaussians growing to 294, 400 steps; a
/// held-out relative L2 error of 0.022 measured, limit 0.06), so the renders match the
/// analytic field as well as the fit does: relative L2 over the pixels within 0.08 for the
/// slice (measured 0.014 at t = 0.5, a sampled time, and 0.055 / 0.056 at t = 0.1 and 0.9,
/// between sampled times near the ends) and within 0.08 for the maximum (0.015, 0.058,
/// 0.056); the maximum's analytic value is over each ray's chord through the box, 2,000
/// midpoints. The centroid of the slice's bright part lies within 0.1 of the source's
/// centre (measured up to 0.017) and moves with it. GPU and CPU agree to 1e-4 of the peak,
/// but for samples of the maximum at a Gaussian's 4-sigma cutoff (see below).
#[test]
fn moving_source_renders_match_the_analytic_field_at_three_times() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let jump = fit_the_moving_source(dir.path());

    let (w, h) = (48u32, 36u32);
    let cam = moving_source_camera(w, h);
    std::fs::write(
        p("cam.json"),
        verisplat::io::camera::inria::to_json(&[(0, cam.clone())]).unwrap(),
    )
    .unwrap();
    let (ply, cams) = (p("m.ply"), p("cam.json"));
    let render = |t: f32, mode: &str, extra: &[&str], out: &str| {
        let ts = t.to_string();
        let o = p(out);
        let mut a = vec![
            "render",
            s(&ply),
            "--cameras",
            s(&cams),
            "--time",
            &ts,
            "--mode",
            mode,
            "-q",
            "--overwrite",
            "-o",
            s(&o),
        ];
        a.extend_from_slice(extra);
        ok(&a);
        npy(&o)
    };
    let mut peaks = Vec::new();
    for t in [0.1f32, 0.5, 0.9] {
        for (mode, extra) in [
            ("field-slice", vec!["--slice-plane", "0,0,0,0,0,1"]),
            ("field-max", vec!["--max-samples", "128"]),
        ] {
            let (gw, gh, k, gpu) = render(t, mode, &extra, "g.npy");
            assert_eq!((gw, gh, k), (w as usize, h as usize, 1));
            let mut cpu_extra = extra.clone();
            cpu_extra.push("--cpu");
            let (_, _, _, cpu) = render(t, mode, &cpu_extra, "c.npy");
            let peak = cpu
                .iter()
                .filter(|v| v.is_finite())
                .fold(0f32, |m, v| m.max(v.abs()));
            assert!(peak > 0.5, "{mode} at {t}: peak {peak}");
            // A sample within f32 rounding of a Gaussian's 4-sigma cutoff counts on one side
            // and not on the other: a jump of exp(-8) o_i feat_i (3.4e-4 of a unit Gaussian),
            // allowed at a few pixels of the maximum (which samples the field at points).
            gpu_matches_cpu(mode, t, &gpu, &cpu, peak, jump);
            let (num, den, pixels, centroid, weight_sum) =
                error_against_the_analytic_field(&cam, mode, t, &gpu, peak);
            let err = (num / den).sqrt();
            eprintln!("{mode} at t = {t}: relative L2 against the analytic field {err:.4} over {pixels} pixels");
            assert!(pixels > 300, "{mode}: {pixels} pixels see the field");
            assert!(err <= 0.08, "{mode} at t = {t}: {err}");
            if mode == "field-slice" {
                let at = centroid.map(|v| v / weight_sum);
                let c = MovingSource::centre(f64::from(t));
                let off = ((at[0] - c[0]).powi(2) + (at[1] - c[1]).powi(2)).sqrt();
                eprintln!("slice peak at t = {t}: {at:?}, {off:.3} from the centre");
                assert!(off <= 0.1, "t = {t}: peak at {at:?}, centre {c:?}");
                peaks.push(at[0]);
            }
        }
    }
    assert!(
        peaks[0] < peaks[1] && peaks[1] < peaks[2],
        "the peak moves along +x: {peaks:?}"
    );
}

/// Generates the moving source's samples and fits them in space and time, checking the
/// report and the fitted time range; returns the largest jump a sample at a Gaussian's
/// 4-sigma cutoff can make, `exp(-8) o_i |feat_i|` (with 1% to spare).
fn fit_the_moving_source(dir: &Path) -> f32 {
    let p = |n: &str| dir.join(n);
    ok(&[
        "gen",
        "--rf",
        "moving-source",
        "--size",
        "12",
        "--times",
        "7",
        s(&p("m.npy")),
    ]);
    let fit = ok(&[
        "fit",
        s(&p("m.npy")),
        "-o",
        s(&p("m.ply")),
        "--gaussians",
        "150",
        "--max-gaussians",
        "400",
        "--steps",
        "400",
        "--report",
        s(&p("m.json")),
        "-q",
    ]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("m.json")).unwrap()).unwrap();
    let holdout = report["holdout_relative_l2"].as_f64().unwrap();
    eprintln!("{}", String::from_utf8_lossy(&fit.stdout));
    assert!(holdout < 0.06, "held-out error {holdout}");
    assert_eq!(report["time_column"], 3);
    assert_eq!(report["time_range"], serde_json::json!([0.0, 1.0]));
    let scene = verisplat::io::scene::load(&p("m.ply")).unwrap();
    let (lo, hi) = scene.time_range().unwrap();
    let jump = (0..scene.len())
        .map(|i| verisplat::core::scene::sigmoid(scene.opacity_logits[i]) * scene.features[i].abs())
        .fold(0f32, f32::max)
        * (-8f32).exp()
        * 1.01;
    assert!((0.0..=1.0).contains(&lo) && (0.0..=1.0).contains(&hi) && lo < hi);
    jump
}

/// The camera the moving source is rendered from, `w` x `h`.
fn moving_source_camera(w: u32, h: u32) -> verisplat::core::camera::Camera {
    verisplat::core::camera::Camera::look_at(
        "front",
        w,
        h,
        50f32.to_radians(),
        glam::Vec3::new(0.5, -1.0, -6.5),
        glam::Vec3::ZERO,
        glam::Vec3::NEG_Y,
    )
}

/// The GPU render equals the CPU one to 1e-4 of the peak, but at a few pixels of the
/// maximum by at most `jump`.
fn gpu_matches_cpu(mode: &str, t: f32, gpu: &[f32], cpu: &[f32], peak: f32, jump: f32) {
    let (mut beyond, mut worst) = (0, 0f32);
    for (a, c) in gpu.iter().zip(cpu) {
        assert!(
            a.is_nan() == c.is_nan(),
            "{mode} at {t}: GPU {a} vs CPU {c}"
        );
        let d = (a - c).abs();
        if d > 1e-4 * peak {
            beyond += 1;
            worst = worst.max(d);
        }
    }
    assert!(
        beyond <= gpu.len() / 50 && worst <= jump,
        "{mode} at {t}: {beyond} pixels differ beyond 1e-4 of the peak, up to {worst}"
    );
}

/// The squared error of the render `gpu` against the analytic field at time `t` and the
/// squared field, summed over the `pixels` that see the field, with (for the slice) the
/// value-weighted sum of the points of its bright part and their weight.
fn error_against_the_analytic_field(
    cam: &verisplat::core::camera::Camera,
    mode: &str,
    t: f32,
    gpu: &[f32],
    peak: f32,
) -> (f64, f64, usize, [f64; 3], f64) {
    let (w, h) = (cam.width, cam.height);
    let b = MovingSource::BOUNDS.map(f64::from);
    let in_box = |x: [f64; 3]| (0..3).all(|a| x[a] >= b[a] && x[a] <= b[a + 3]);
    let truth = |x: [f64; 3]| MovingSource::magnitude(x, f64::from(t));
    let (mut num, mut den, mut pixels, mut weight_sum) = (0f64, 0f64, 0, 0f64);
    // The slice's bright part (above half its peak): its centroid, weighted by value.
    let mut centroid = [0f64; 3];
    for py in 0..h {
        for px in 0..w {
            let (o, d) = field::pixel_ray(cam, px, py);
            let at = |s: f64| [o[0] + s * d[0], o[1] + s * d[1], o[2] + s * d[2]];
            let got = f64::from(gpu[(py * w + px) as usize]);
            let expect = if mode == "field-slice" {
                let Some(s) = field::slice_hit(o, d, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]) else {
                    continue;
                };
                if !in_box(at(s)) {
                    continue;
                }
                if got > 0.5 * f64::from(peak) {
                    for (a, c) in centroid.iter_mut().enumerate() {
                        *c += got * at(s)[a];
                    }
                    weight_sum += got;
                }
                truth(at(s))
            } else {
                let Some((s0, s1)) = field::chord(o, d, b) else {
                    continue;
                };
                let m = 2000;
                let ds = (s1 - s0) / m as f64;
                (0..m)
                    .map(|j| truth(at(s0 + (j as f64 + 0.5) * ds)))
                    .fold(0f64, f64::max)
            };
            num += (got - expect).powi(2);
            den += expect * expect;
            pixels += 1;
        }
    }
    (num, den, pixels, centroid, weight_sum)
}

/// Three coloured Gaussians in a row, each at its own time (temporal means 0, 0.4, 1,
/// scales 0.15), with two feature channels.
fn blinking_scene() -> Scene {
    let mut sc = Scene::empty(0);
    let colours = [[1.0, 0.2, 0.1], [0.1, 1.0, 0.2], [0.2, 0.1, 1.0]];
    for (i, rgb) in colours.iter().enumerate() {
        push_gaussian(&mut sc, [0.5 * i as f32 - 0.5, 0.0, 0.0], 0.3, 0.9, *rgb);
    }
    sc.set_features(2, vec![1.0, -0.5, 0.5, 2.0, -1.0, 0.25])
        .unwrap();
    sc.time = Some(vec![
        [0.0, 0.15f32.ln()],
        [0.4, 0.15f32.ln()],
        [1.0, 0.15f32.ln()],
    ]);
    sc
}

/// A camera file (`cam.json` in `dir`) looking at the blinking scene from the front.
fn front_camera(dir: &Path) -> std::path::PathBuf {
    let cam = verisplat::core::camera::Camera::look_at(
        "front",
        64,
        48,
        50f32.to_radians(),
        glam::Vec3::new(0.0, -0.5, -2.5),
        glam::Vec3::ZERO,
        glam::Vec3::NEG_Y,
    );
    let path = dir.join("cam.json");
    std::fs::write(
        &path,
        verisplat::io::camera::inria::to_json(&[(0, cam)]).unwrap(),
    )
    .unwrap();
    path
}

/// `t_mean` and `t_scale` survive a PLY round trip in every encoding; a file without them
/// loads static; one with only one of them is refused, naming the other.
#[test]
fn ply_round_trips_t_mean_and_t_scale() {
    let sc = blinking_scene();
    for enc in [
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
        PlyEncoding::Ascii,
    ] {
        let bytes = ply::to_bytes(&sc, enc);
        let text = String::from_utf8_lossy(&bytes).to_string();
        assert!(text.contains("property float t_mean\nproperty float t_scale\n"));
        let (back, _) = verisplat::io::scene::parse_bytes(&bytes, Path::new("b.ply")).unwrap();
        assert_eq!(back, sc, "{enc:?}");
    }
    let mut static_scene = sc.clone();
    static_scene.time = None;
    let bytes = ply::to_bytes(&static_scene, PlyEncoding::Ascii);
    assert!(!String::from_utf8_lossy(&bytes).contains("t_mean"));
    let (back, _) = verisplat::io::scene::parse_bytes(&bytes, Path::new("s.ply")).unwrap();
    assert_eq!(back.time, None);
    let half = String::from_utf8_lossy(&ply::to_bytes(&sc, PlyEncoding::Ascii))
        .replace("property float t_scale\n", "property float other\n");
    let e = verisplat::io::scene::parse_bytes(half.as_bytes(), Path::new("half.ply"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("half.ply") && e.contains("\"t_scale\""), "{e}");
}

/// `Scene::at_time`: opacity times the temporal factor (to f32 rounding), Gaussians beyond
/// 4 temporal scales left out, the result static.
#[test]
fn at_time_scales_the_opacity_by_the_temporal_factor() {
    let sc = blinking_scene();
    let at = sc.at_time(0.65);
    assert_eq!(at.time, None);
    // Gaussian 0 is 4.3 scales (0.65) away: out; 1 at 0.25 / 0.15; 2 at 0.35 / 0.15.
    assert_eq!(at.len(), 2);
    for (j, i) in [1usize, 2].iter().enumerate() {
        let mean = [0.0, 0.4, 1.0][*i];
        let want = 0.9 * (-0.5 * ((0.65f64 - mean) / 0.15).powi(2)).exp();
        let got = f64::from(verisplat::core::scene::sigmoid(at.opacity_logits[j]));
        assert!(
            (got - want).abs() <= 1e-6 * want.max(1e-3),
            "{got} vs {want}"
        );
        assert_eq!(at.features[j * 2..j * 2 + 2], sc.features[i * 2..i * 2 + 2]);
    }
    let mut st = sc.clone();
    st.time = None;
    assert_eq!(st.at_time(5.0), st);
}

/// A time-varying scene on the GPU and the CPU reference at a time agree as a static scene
/// does (colour: PSNR >= 50 dB; features and the field slice: 1e-4 of the peak), and the
/// frame at a time is the frame of the scene `at_time` wrote out as a static PLY.
#[test]
fn gpu_equals_cpu_reference_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let sc = blinking_scene();
    std::fs::write(
        p("b.ply"),
        ply::to_bytes(&sc, PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    std::fs::write(
        p("b03.ply"),
        ply::to_bytes(&sc.at_time(0.3), PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    let cams = front_camera(dir.path());
    let base = |scene: &Path, out: &Path, extra: &[&str]| {
        let mut a = vec![
            "render",
            s(scene),
            "--cameras",
            s(&cams),
            "-q",
            "--overwrite",
            "-o",
            s(out),
        ];
        a.extend_from_slice(extra);
        ok(&a);
    };
    let t = ["--time", "0.3"];
    base(&p("b.ply"), &p("g.exr"), &t);
    base(&p("b.ply"), &p("c.exr"), &[t[0], t[1], "--cpu"]);
    base(&p("b03.ply"), &p("s.exr"), &[]);
    let rgb = |f: &Path| {
        verisplat::io::image_file::read_image(f)
            .unwrap()
            .interleave(&["R", "G", "B"])
            .unwrap()
    };
    let (g, c, st) = (rgb(&p("g.exr")), rgb(&p("c.exr")), rgb(&p("s.exr")));
    let brightest = g.iter().fold(0f32, |m, v| m.max(*v));
    assert!(
        brightest > 0.2,
        "the frame shows the Gaussians: {brightest}, {} values",
        g.len()
    );
    let psnr = verisplat::io::metrics::psnr(&c, &g, 1.0);
    assert!(psnr >= 50.0, "GPU vs CPU at a time: {psnr} dB");
    assert_eq!(g, st, "--time 0.3 renders Scene::at_time(0.3)");
    for (mode, extra) in [
        ("features", vec![]),
        ("field-slice", vec!["--slice-plane", "0,0,0,0,0,1"]),
    ] {
        let mut a = vec![t[0], t[1], "--mode", mode];
        a.extend_from_slice(&extra);
        base(&p("b.ply"), &p("g.npy"), &a);
        a.push("--cpu");
        base(&p("b.ply"), &p("c.npy"), &a);
        let (_, _, k, gv) = npy(&p("g.npy"));
        let (_, _, _, cv) = npy(&p("c.npy"));
        assert_eq!(k, 2);
        let peak = cv
            .iter()
            .filter(|v| v.is_finite())
            .fold(0f32, |m, v| m.max(v.abs()));
        assert!(peak > 0.1, "{mode}: peak {peak}");
        for (a, c) in gv.iter().zip(&cv) {
            assert!(
                (a.is_nan() && c.is_nan()) || (a - c).abs() <= 1e-4 * peak,
                "{mode}: GPU {a} vs CPU {c}"
            );
        }
    }
}

/// `--time-range 0,1 --time-frames 4`: four frames at times 0, 1/3, 2/3 and 1 that differ
/// (each shows another Gaussian's colour most); frame 2 equals `--time 0.6666667`; a
/// deleted frame is written again by `--skip-existing` with the same bytes; the CPU
/// reference writes the same sequence to PSNR >= 50 dB.
#[test]
fn animation_writes_n_frames_that_differ_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    std::fs::write(
        p("b.ply"),
        ply::to_bytes(&blinking_scene(), PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    let scene_file = p("b.ply");
    let anim = |out: &str, extra: &[&str]| {
        let o = p(out);
        let mut a = vec![
            "render",
            s(&scene_file),
            "--width",
            "40",
            "--height",
            "30",
            "-q",
            "--time-range",
            "0,1",
            "--time-frames",
            "4",
            "-o",
            s(&o),
        ];
        a.extend_from_slice(extra);
        ok(&a)
    };
    anim("a/f_%04d.png", &[]);
    let names: Vec<String> = (0..4).map(|k| format!("a/f_{k:04}.png")).collect();
    let read = |n: &str| {
        verisplat::io::image_file::read_image(&p(n))
            .unwrap()
            .interleave(&["R", "G", "B"])
            .unwrap()
    };
    let frames: Vec<Vec<f32>> = names.iter().map(|n| read(n)).collect();
    assert_eq!(std::fs::read_dir(p("a")).unwrap().count(), 4);
    for i in 0..4 {
        for j in i + 1..4 {
            let diff = frames[i]
                .iter()
                .zip(&frames[j])
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            assert!(diff > 0.1, "frames {i} and {j} differ by {diff} at most");
        }
    }
    // The dominant channel follows the Gaussian in time: red, then green, then blue.
    let sum = |f: &[f32], c: usize| f.iter().skip(c).step_by(3).sum::<f32>();
    assert!(sum(&frames[0], 0) > sum(&frames[0], 2));
    assert!(sum(&frames[3], 2) > sum(&frames[3], 0));
    ok(&[
        "render",
        s(&p("b.ply")),
        "--width",
        "40",
        "--height",
        "30",
        "-q",
        "--time",
        &(2.0f32 / 3.0).to_string(),
        "-o",
        s(&p("t.png")),
    ]);
    assert_eq!(read("t.png"), frames[2], "frame 2 is time 2/3");
    let before = std::fs::read(p(&names[1])).unwrap();
    std::fs::remove_file(p(&names[1])).unwrap();
    let o = anim("a/f_%04d.png", &["--skip-existing"]);
    assert!(o.status.success());
    assert_eq!(std::fs::read(p(&names[1])).unwrap(), before);
    anim("c/f_%04d.png", &["--cpu"]);
    for (k, g) in frames.iter().enumerate() {
        let c = read(&format!("c/f_{k:04}.png"));
        let psnr = verisplat::io::metrics::psnr(&c, g, 1.0);
        assert!(psnr >= 40.0, "frame {k}: GPU vs CPU {psnr} dB");
    }
    // The field modes animate too: frames differ.
    anim(
        "m/f_%04d.npy",
        &["--mode", "field-slice", "--slice-plane", "0,0,0,0,0,1"],
    );
    let (_, _, _, a) = npy(&p("m/f_0000.npy"));
    let (_, _, _, b) = npy(&p("m/f_0003.npy"));
    assert!(a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 0.1));
}

/// Bad time inputs: one `error:` sentence naming the file and what is wrong, nothing
/// written.
#[test]
fn bad_time_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    bad_time_columns_of_csv_files(dir.path());
    bad_time_columns_of_npy_files(dir.path());
    bad_times_to_render_and_convert(dir.path());
}

/// CSV samples: one time for all, a NaN time, a time column that is not there or is a
/// coordinate.
fn bad_time_columns_of_csv_files(dir: &Path) {
    let p = |n: &str| dir.join(n);
    let out = p("o.ply");
    let csv = |name: &str, text: &str| {
        std::fs::write(p(name), text).unwrap();
        p(name)
    };
    let rows = |t: &dyn Fn(usize) -> String| -> String {
        (0..20)
            .map(|i| format!("{},{},{},{},{}\n", i % 3, i % 5, i % 7, t(i), 1 + i % 4))
            .collect()
    };
    let constant = csv("c.csv", &format!("x,y,z,t,v\n{}", rows(&|_| "2.5".into())));
    let e = fails(&["fit", s(&constant), "-o", s(&out), "-q"], &out);
    assert!(
        e.contains("c.csv") && e.contains("every sample has the time 2.5") && e.contains("drop"),
        "{e}"
    );
    let nan = csv(
        "n.csv",
        &format!(
            "x,y,z,t,v\n{}",
            rows(&|i| if i == 7 { "nan".into() } else { i.to_string() })
        ),
    );
    let e = fails(&["fit", s(&nan), "-o", s(&out), "-q"], &out);
    assert!(
        e.contains("n.csv") && e.contains("line 9") && e.contains("finite"),
        "{e}"
    );
    let plain = csv(
        "p.csv",
        &format!("x,y,z,when,v\n{}", rows(&|i| i.to_string())),
    );
    let e = fails(
        &[
            "fit",
            s(&plain),
            "-o",
            s(&out),
            "--time-column",
            "time",
            "-q",
        ],
        &out,
    );
    assert!(
        e.contains("p.csv") && e.contains("no such column") && e.contains("when"),
        "{e}"
    );
    let e = fails(
        &["fit", s(&plain), "-o", s(&out), "--time-column", "1", "-q"],
        &out,
    );
    assert!(e.contains("p.csv") && e.contains("is y"), "{e}");
}

/// A .npy: a name is no column; 4 columns leave no value; a grid has no time.
fn bad_time_columns_of_npy_files(dir: &Path) {
    let p = |n: &str| dir.join(n);
    let out = p("o.ply");
    let four: Vec<f32> = (0..40).map(|i| i as f32).collect();
    std::fs::write(
        p("f.npy"),
        verisplat::io::image_file::npy_bytes(&[10, 4], &four),
    )
    .unwrap();
    let e = fails(
        &[
            "fit",
            s(&p("f.npy")),
            "-o",
            s(&out),
            "--time-column",
            "t",
            "-q",
        ],
        &out,
    );
    assert!(e.contains("f.npy") && e.contains("no column names"), "{e}");
    let e = fails(
        &[
            "fit",
            s(&p("f.npy")),
            "-o",
            s(&out),
            "--time-column",
            "3",
            "-q",
        ],
        &out,
    );
    assert!(e.contains("f.npy") && e.contains("4 columns"), "{e}");
    ok(&["gen", "--rf", "dipole", "--size", "4", s(&p("d.npy"))]);
    let e = fails(
        &[
            "fit",
            s(&p("d.npy")),
            "-o",
            s(&out),
            "--time-column",
            "3",
            "-q",
        ],
        &out,
    );
    assert!(e.contains("d.npy") && e.contains("dense grid"), "{e}");
}

/// Renders: a static scene takes no time; a time-varying one needs one, and formats and
/// commands without time refuse it.
fn bad_times_to_render_and_convert(dir: &Path) {
    let p = |n: &str| dir.join(n);
    std::fs::write(
        p("b.ply"),
        ply::to_bytes(&blinking_scene(), PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    let mut st = blinking_scene();
    st.time = None;
    std::fs::write(
        p("s.ply"),
        ply::to_bytes(&st, PlyEncoding::BinaryLittleEndian),
    )
    .unwrap();
    let img = p("o.png");
    let e = fails(
        &["render", s(&p("s.ply")), "--time", "0.5", "-o", s(&img)],
        &img,
    );
    assert!(e.contains("s.ply") && e.contains("static"), "{e}");
    let e = fails(&["render", s(&p("b.ply")), "-o", s(&img)], &img);
    assert!(
        e.contains("b.ply") && e.contains("time-varying") && e.contains("from 0 to 1"),
        "{e}"
    );
    let frames = p("a_%04d.png");
    let e = fails(
        &[
            "render",
            s(&p("b.ply")),
            "--time-range",
            "0,1",
            "-o",
            s(&frames),
        ],
        &p("a_0000.png"),
    );
    assert!(e.contains("--time-frames N"), "{e}");
    let e = fails(
        &[
            "render",
            s(&p("b.ply")),
            "--orbit",
            "5",
            "--time-range",
            "0,1",
            "--time-frames",
            "3",
            "-o",
            s(&frames),
        ],
        &p("a_0000.png"),
    );
    assert!(
        e.contains("--time-frames 3") && e.contains("5 frames"),
        "{e}"
    );
    let o = verisplat(&["render", s(&p("b.ply")), "--time", "nan", "-o", s(&img)]);
    assert!(
        !o.status.success() && stderr(&o).contains("--time"),
        "{}",
        stderr(&o)
    );
    // Formats without t_mean, t_scale refuse the scene; commands without --time too.
    let spz = p("b.spz");
    let e = fails(&["convert", s(&p("b.ply")), s(&spz)], &spz);
    assert!(e.contains("time-varying") && e.contains("only PLY"), "{e}");
    let e = fails(&["compare", s(&p("b.ply"))], &p("none"));
    assert!(e.contains("b.ply") && e.contains("render --time"), "{e}");
}
