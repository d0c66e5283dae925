//! The README's RF walkthrough, small: gen --rf -> fit -> render --mode features -> a
//! colour-map shader from tools/colormap_shader.py -> render --shader, on the GPU and the
//! CPU reference (which agree to PSNR >= 55 dB per channel and for the shaded colour).

use crate::common::cli::{ok, s};
use std::path::Path;

fn planes(path: &Path, names: &[&str]) -> Vec<f32> {
    vksplat::image_file::read_image(path)
        .unwrap()
        .interleave(names)
        .unwrap()
}

#[test]
fn gen_fit_render_features_and_shade() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    ok(&["gen", "--rf", "dipole", "--size", "16", s(&p("d.npy"))]);
    let fit = ok(&[
        "fit",
        s(&p("d.npy")),
        "-o",
        s(&p("d.ply")),
        "--gaussians",
        "150",
        "--max-gaussians",
        "300",
        "--steps",
        "120",
        "-q",
    ]);
    let summary = String::from_utf8_lossy(&fit.stdout).to_string();
    assert!(summary.contains("held-out relative L2 error"), "{summary}");
    let args = |o: &Path, extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "render",
            s(&p("d.ply")),
            "--width",
            "120",
            "--height",
            "90",
            "-q",
            "-o",
            s(o),
        ]
        .iter()
        .map(|x| x.to_string())
        .collect();
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    let run = |a: Vec<String>| {
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        ok(&refs);
    };
    run(args(&p("g.exr"), &["--mode", "features"]));
    run(args(&p("c.exr"), &["--mode", "features", "--cpu"]));
    let ch = ["feat.0", "feat.1", "feat.2", "feat.3"];
    for c in ch {
        let (g, cpu) = (planes(&p("g.exr"), &[c]), planes(&p("c.exr"), &[c]));
        let peak = cpu.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
        assert!(peak > 0.0, "{c} is empty");
        let psnr = vksplat::metrics::psnr(&cpu, &g, peak);
        assert!(psnr >= 55.0, "{c}: {psnr} dB");
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/colormap_shader.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args([
            "--channels",
            "4",
            "--range",
            "0,0.06",
            "-o",
            s(&p("sh.safetensors")),
        ])
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    run(args(&p("g.png"), &["--shader", s(&p("sh.safetensors"))]));
    run(args(&p("gs.exr"), &["--shader", s(&p("sh.safetensors"))]));
    run(args(
        &p("cs.exr"),
        &["--shader", s(&p("sh.safetensors")), "--cpu"],
    ));
    let rgb = ["R", "G", "B"];
    let (g, cpu) = (planes(&p("gs.exr"), &rgb), planes(&p("cs.exr"), &rgb));
    let psnr = vksplat::metrics::psnr(&cpu, &g, 1.0);
    assert!(psnr >= 55.0, "shaded: {psnr} dB");
    // The colour map shows: some pixel is far from grey.
    assert!(
        g.chunks(3).any(|c| (c[0] - c[2]).abs() > 0.3),
        "no colour in the shaded image"
    );
}
