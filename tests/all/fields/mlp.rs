//! The neural shader: the file format and its errors, the CPU evaluation against an f64
//! evaluation written here, the background rule, and the GPU shade stage against the CPU
//! reference on a real scene (PSNR >= 55 dB, >= 99.9 % of 8-bit pixels within 1/255).

use crate::common;
use verisplat::cpu::{self, RenderOptions, SplatKernel};
use verisplat::fields::mlp::{self, Activation, Mlp, MlpInput};
use verisplat::io;
use verisplat::render::{FrameRequest, Rendered};

/// A safetensors file: F32 tensors and an optional `verisplat_mlp` description.
fn safetensors(tensors: &[(&str, Vec<usize>, Vec<f32>)], description: Option<&str>) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut data = Vec::new();
    for (name, shape, values) in tensors {
        let start = data.len();
        for v in values {
            data.extend_from_slice(&v.to_le_bytes());
        }
        header.insert(
            name.to_string(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [start, data.len()]}),
        );
    }
    if let Some(d) = description {
        header.insert(
            "__metadata__".into(),
            serde_json::json!({ "verisplat_mlp": d }),
        );
    }
    let mut text = serde_json::to_string(&header).unwrap().into_bytes();
    while text.len() % 8 != 0 {
        text.push(b' ');
    }
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend(text);
    out.extend(data);
    out
}

/// Named tensors: name, shape, values.
type Tensors = Vec<(String, Vec<usize>, Vec<f32>)>;

/// Layer sizes and activations -> (tensors, description), weights from a seeded RNG.
fn network(inputs: &[&str], sizes: &[usize], acts: &[&str], seed: u64) -> (Tensors, String) {
    let mut rng = common::Rng(seed);
    let mut tensors = Vec::new();
    let mut layers = Vec::new();
    for (l, act) in acts.iter().enumerate() {
        let (i, o) = (sizes[l], sizes[l + 1]);
        let scale = 1.5 / (i as f32).sqrt();
        let w = (0..i * o).map(|_| rng.range(-scale, scale)).collect();
        let b = (0..o).map(|_| rng.range(-0.3, 0.3)).collect();
        tensors.push((format!("{}.weight", 2 * l), vec![o, i], w));
        tensors.push((format!("{}.bias", 2 * l), vec![o], b));
        layers.push(serde_json::json!({
            "weight": format!("{}.weight", 2 * l),
            "bias": format!("{}.bias", 2 * l),
            "activation": act,
        }));
    }
    let description = serde_json::json!({ "inputs": inputs, "layers": layers }).to_string();
    (tensors, description)
}

fn file_of(tensors: &Tensors, description: Option<&str>) -> Vec<u8> {
    let t: Vec<(&str, Vec<usize>, Vec<f32>)> = tensors
        .iter()
        .map(|(n, s, v)| (n.as_str(), s.clone(), v.clone()))
        .collect();
    safetensors(&t, description)
}

/// The network in f64, from the tensors themselves (not through `Mlp`).
fn eval_f64(tensors: &Tensors, acts: &[&str], x: &[f64]) -> Vec<f64> {
    let mut cur = x.to_vec();
    for (l, act) in acts.iter().enumerate() {
        let (_, shape, w) = &tensors[2 * l];
        let (_, _, b) = &tensors[2 * l + 1];
        let (o, i) = (shape[0], shape[1]);
        cur = (0..o)
            .map(|r| {
                let s: f64 = f64::from(b[r])
                    + (0..i)
                        .map(|c| f64::from(w[r * i + c]) * cur[c])
                        .sum::<f64>();
                match *act {
                    "relu" => s.max(0.0),
                    "sigmoid" => 1.0 / (1.0 + (-s).exp()),
                    "tanh" => s.tanh(),
                    _ => s,
                }
            })
            .collect();
    }
    cur
}

#[test]
fn cpu_evaluation_matches_an_f64_evaluation() {
    let acts = ["relu", "tanh", "none", "sigmoid"];
    let k = 5;
    let (tensors, description) = network(
        &["features", "view_dir", "alpha"],
        &[k + 4, 16, 12, 8, 3],
        &acts,
        7,
    );
    let m = Mlp::parse(&file_of(&tensors, Some(&description)), None).unwrap();
    assert_eq!(
        m.inputs,
        [MlpInput::Features, MlpInput::ViewDir, MlpInput::Alpha]
    );
    assert_eq!(m.feature_channels(), k);
    assert_eq!(m.layers[1].activation, Activation::Tanh);
    let mut rng = common::Rng(3);
    let mut worst = 0.0f64;
    let mut x = Vec::new();
    for _ in 0..500 {
        let f: Vec<f32> = (0..k).map(|_| rng.range(-3.0, 3.0)).collect();
        let dir = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ];
        let a = rng.range(0.0, 1.0);
        m.input_vector(&f, dir, a, &mut x);
        assert_eq!(x.len(), k + 4);
        assert_eq!(&x[k..], &[dir[0], dir[1], dir[2], a]);
        let got = m.eval(&x);
        let want = eval_f64(
            &tensors,
            &acts,
            &x.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(),
        );
        for c in 0..3 {
            worst = worst.max((f64::from(got[c]) - want[c]).abs());
        }
    }
    assert!(worst < 2e-6, "largest difference from f64: {worst}");
}

#[test]
fn input_order_is_the_files() {
    // alpha first, then features: the first weight column multiplies alpha.
    let tensors = vec![
        (
            "w".to_string(),
            vec![3, 3],
            vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        ),
        ("b".to_string(), vec![3], vec![0.0; 3]),
    ];
    let d = r#"{"inputs": ["alpha", "features"], "layers": [{"weight": "w", "bias": "b", "activation": "none"}]}"#;
    let m = Mlp::parse(&file_of(&tensors, Some(d)), None).unwrap();
    assert_eq!(m.feature_channels(), 2);
    let mut x = Vec::new();
    m.input_vector(&[5.0, 6.0], [0.0; 3], 0.25, &mut x);
    assert_eq!(m.eval(&x), [0.25, 5.0, 6.0]);
    // The same description from a sidecar when the file has none.
    let m2 = Mlp::parse(&file_of(&tensors, None), Some(d)).unwrap();
    assert_eq!(m, m2);
}

#[test]
fn malformed_shader_files_give_one_clear_error_each() {
    let (tensors, _) = network(&["features"], &[4, 8, 3], &["relu", "sigmoid"], 1);
    let layer = |w: &str, b: &str, a: &str| {
        format!(r#"{{"weight": "{w}", "bias": "{b}", "activation": "{a}"}}"#)
    };
    let desc = |layers: &[String]| {
        format!(
            r#"{{"inputs": ["features"], "layers": [{}]}}"#,
            layers.join(",")
        )
    };
    let ok = desc(&[
        layer("0.weight", "0.bias", "relu"),
        layer("2.weight", "2.bias", "sigmoid"),
    ]);
    assert!(Mlp::parse(&file_of(&tensors, Some(&ok)), None).is_ok());
    let err = |bytes: Vec<u8>| Mlp::parse(&bytes, None).unwrap_err();

    // Shapes that do not chain: the second layer twice.
    let e = err(file_of(
        &tensors,
        Some(&desc(&[
            layer("2.weight", "2.bias", "relu"),
            layer("2.weight", "2.bias", "none"),
        ])),
    ));
    assert!(e.contains("do not chain"), "{e}");
    // Unknown activation.
    let e = err(file_of(
        &tensors,
        Some(&desc(&[
            layer("0.weight", "0.bias", "gelu"),
            layer("2.weight", "2.bias", "sigmoid"),
        ])),
    ));
    assert!(e.contains("unknown activation \"gelu\""), "{e}");
    // NaN weights.
    let mut nan = tensors.clone();
    nan[2].2[5] = f32::NAN;
    let e = err(file_of(&nan, Some(&ok)));
    assert!(e.contains("\"2.weight\" holds NaN at element 5"), "{e}");
    // A missing tensor, a wrong bias, the last layer not RGB, no description, not a file.
    let e = err(file_of(
        &tensors,
        Some(&desc(&[
            layer("0.weight", "9.bias", "relu"),
            layer("2.weight", "2.bias", "sigmoid"),
        ])),
    ));
    assert!(e.contains("no tensor \"9.bias\""), "{e}");
    let e = err(file_of(
        &tensors,
        Some(&desc(&[
            layer("0.weight", "2.bias", "relu"),
            layer("2.weight", "2.bias", "sigmoid"),
        ])),
    ));
    assert!(
        e.contains("bias \"2.bias\" has shape [3]; it must be [8]"),
        "{e}"
    );
    let e = err(file_of(
        &tensors,
        Some(&desc(&[layer("0.weight", "0.bias", "relu")])),
    ));
    assert!(e.contains("must give 3 (R, G, B)"), "{e}");
    let e = err(file_of(&tensors, None));
    assert!(e.contains("verisplat_mlp"), "{e}");
    let e = err(b"not a safetensors file at all".to_vec());
    assert!(e.contains("is not a safetensors file"), "{e}");
    let e = err(file_of(
        &tensors,
        Some(r#"{"inputs": ["normals"], "layers": []}"#),
    ));
    assert!(e.contains("unknown input \"normals\""), "{e}");
    // K mismatch with a scene.
    let m = Mlp::parse(&file_of(&tensors, Some(&ok)), None).unwrap();
    assert!(m.check_channels(4).is_ok());
    let e = m.check_channels(3).unwrap_err();
    assert!(
        e.contains("takes 4 feature channels but the scene has 3"),
        "{e}"
    );
    // Errors from a file name it.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.safetensors");
    std::fs::write(&path, file_of(&nan, Some(&ok))).unwrap();
    let e = Mlp::load(&path).unwrap_err().to_string();
    assert!(
        e.starts_with(&path.display().to_string()) && e.contains("NaN"),
        "{e}"
    );
}

#[test]
fn background_is_applied_after_shading_with_alpha() {
    let (tensors, d) = network(&["features", "alpha"], &[3, 6, 3], &["tanh", "sigmoid"], 5);
    let m = Mlp::parse(&file_of(&tensors, Some(&d)), None).unwrap();
    let cam = common::axis_camera(50.0);
    let n = (cam.width * cam.height) as usize;
    let features: Vec<f32> = (0..n * 2).map(|i| (i % 7) as f32 * 0.1).collect();
    let alpha: Vec<f32> = (0..n).map(|i| [0.0, 0.5, 1.0][i % 3]).collect();
    let bg = [0.2, 0.4, 0.8];
    let c = mlp::shade(&m, &cam, &features, 2, &alpha, bg);
    let mut x = Vec::new();
    for p in [0usize, 1, 2, 100, 101, 102] {
        m.input_vector(
            &features[p * 2..p * 2 + 2],
            mlp::view_dir(&cam, 0, 0),
            alpha[p],
            &mut x,
        );
        let s = m.eval(&x);
        for ch in 0..3 {
            let want = alpha[p] * s[ch] + (1.0 - alpha[p]) * bg[ch];
            assert!(
                (c[p][ch] - want).abs() < 1e-6,
                "pixel {p}: {} vs {want}",
                c[p][ch]
            );
        }
        if alpha[p] == 0.0 {
            assert_eq!(c[p], bg, "an empty pixel shows the background");
        }
    }
    // The view direction: unit length, straight ahead at the principal point.
    let centre = mlp::view_dir(&cam, (cam.cx - 0.5) as u32, (cam.cy - 0.5) as u32);
    let forward = cam.rotation.transpose() * glam::Vec3::Z;
    assert!((glam::Vec3::from(centre) - forward).length() < 1e-6);
}

#[test]
fn gpu_shade_stage_matches_the_reference() {
    let mut r = common::gpu::renderer();
    let mut s = io::scene::load(&common::shared_data().join("playbot_lod3_31k_sh2.ply")).unwrap();
    for (k, inputs, kernel, bg) in [
        (
            5usize,
            vec!["features", "view_dir", "alpha"],
            SplatKernel::Gaussian,
            [0.0; 3],
        ),
        (
            8,
            vec!["view_dir", "features"],
            SplatKernel::Power,
            [1.0, 0.5, 0.25],
        ),
    ] {
        let mut rng = common::Rng(k as u64);
        let feats = (0..s.len() * k).map(|_| rng.range(-1.0, 1.0)).collect();
        s.set_features(k, feats).unwrap();
        let extra = if inputs.contains(&"alpha") { 4 } else { 3 };
        let (tensors, d) = network(
            &inputs,
            &[k + extra, 24, 16, 3],
            &["relu", "tanh", "sigmoid"],
            11 + k as u64,
        );
        let m = Mlp::parse(&file_of(&tensors, Some(&d)), None).unwrap();
        let act = s.activated();
        let opts = RenderOptions {
            kernel,
            background: bg,
            ..Default::default()
        };
        let cam = common::orbit(common::PLAYBOT_ORBIT, 3, 200, 150);
        let frame = cpu::render_features(&act, &cam, &opts);
        let mut want = frame.clone();
        want.color = mlp::shade(&m, &cam, &frame.features, k, &frame.alpha, bg);
        let gs = r.upload(&act).unwrap();
        let gf = r.upload_features(&act).unwrap();
        let shader = verisplat::render::forward::shade::GpuShader::new(r.ctx(), &m).unwrap();
        let got = r
            .render(&FrameRequest::new(&gs, &cam, &opts).shaded(&gf, &shader))
            .and_then(Rendered::into_frame)
            .unwrap();
        let c = common::gpu::compare(&got, &want);
        assert!(
            c.meets(&common::gpu::Thresholds::COLOUR),
            "K = {k} {kernel}: PSNR {} dB, {} within 1/255\n{}",
            c.psnr,
            c.within,
            common::gpu::dump_failure(&format!("shade_k{k}"), &got, &want)
        );
        assert!(r.timings().shade > 0.0 && r.timings().features > 0.0);
        assert!(r.timings().stages().iter().any(|(n, _)| *n == "shade"));
        // The frame's alpha is the colour blend's.
        assert_eq!(got.alpha.len(), want.alpha.len());
        // K mismatch is refused.
        let (t2, d2) = network(&["features"], &[k + 1, 4, 3], &["relu", "sigmoid"], 2);
        let wrong = Mlp::parse(&file_of(&t2, Some(&d2)), None).unwrap();
        let wrong = verisplat::render::forward::shade::GpuShader::new(r.ctx(), &wrong).unwrap();
        let e = r
            .render(&FrameRequest::new(&gs, &cam, &opts).shaded(&gf, &wrong))
            .and_then(Rendered::into_frame)
            .unwrap_err()
            .to_string();
        assert!(e.contains("feature channels"), "{e}");
    }
    common::gpu::assert_validation_clean(&r);
}

#[test]
fn render_shader_on_the_gpu_and_the_cpu_and_its_errors() {
    use common::cli::{fails, ok, s};
    let dir = tempfile::tempdir().unwrap();
    let scene_file = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let n = io::scene::load(&scene_file).unwrap().len();
    let k = 3;
    let mut rng = common::Rng(9);
    let feats: Vec<f32> = (0..n * k).map(|_| rng.range(0.0, 1.0)).collect();
    let npy = dir.path().join("f.npy");
    std::fs::write(&npy, verisplat::io::image_file::npy_bytes(&[n, k], &feats)).unwrap();
    let (tensors, d) = network(
        &["features", "view_dir"],
        &[k + 3, 8, 3],
        &["relu", "sigmoid"],
        4,
    );
    let shader = dir.path().join("shader.safetensors");
    std::fs::write(&shader, file_of(&tensors, Some(&d))).unwrap();
    let out = |name: &str| dir.path().join(name);
    let common_args = |o: &std::path::Path| -> Vec<String> {
        [
            s(&scene_file),
            "--features",
            s(&npy),
            "--shader",
            s(&shader),
            "--width",
            "96",
            "--height",
            "72",
            "--background",
            "0.2,0.3,0.4",
            "-q",
            "-o",
            s(o),
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let run = |o: &std::path::Path, extra: &[&str]| {
        let mut a = vec!["render".to_string()];
        a.extend(common_args(o));
        a.extend(extra.iter().map(|x| x.to_string()));
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        ok(&refs)
    };
    run(&out("gpu.exr"), &["--timings"]);
    run(&out("cpu.exr"), &["--cpu"]);
    let o = run(&out("gpu.png"), &[]);
    assert!(o.status.success());
    let gpu = verisplat::io::image_file::read_image(&out("gpu.exr")).unwrap();
    let cpu = verisplat::io::image_file::read_image(&out("cpu.exr")).unwrap();
    let rgb = |p: &verisplat::io::image_file::Planes| p.interleave(&["R", "G", "B"]).unwrap();
    let (g, c) = (rgb(&gpu), rgb(&cpu));
    let psnr = verisplat::io::metrics::psnr(&c, &g, 1.0);
    assert!(
        psnr >= common::gpu::MIN_PSNR,
        "GPU vs CPU shaded: {psnr} dB"
    );
    // Not the plain colour render: the shader's output shows.
    let mut a = vec!["render".to_string()];
    a.extend(
        common_args(&out("plain2.exr"))
            .into_iter()
            .filter(|x| x != "--shader" && x != s(&shader)),
    );
    let refs: Vec<&str> = a.iter().map(String::as_str).collect();
    ok(&refs);
    let plain = verisplat::io::image_file::read_image(&out("plain2.exr")).unwrap();
    assert!(verisplat::io::metrics::psnr(&rgb(&plain), &g, 1.0) < 40.0);

    // Errors: K mismatch, no features, a broken file, with --mode features.
    let (t2, d2) = network(&["features"], &[k + 1, 4, 3], &["relu", "sigmoid"], 2);
    let wrong = out("wrong.safetensors");
    std::fs::write(&wrong, file_of(&t2, Some(&d2))).unwrap();
    let o = out("x.png");
    let e = fails(
        &[
            "render",
            s(&scene_file),
            "--features",
            s(&npy),
            "--shader",
            s(&wrong),
            "-o",
            s(&o),
        ],
        &o,
    );
    assert!(
        e.contains("takes 4 feature channels but the scene has 3"),
        "{e}"
    );
    let e = fails(
        &[
            "render",
            s(&scene_file),
            "--shader",
            s(&shader),
            "-o",
            s(&o),
        ],
        &o,
    );
    assert!(e.contains("but the scene has 0"), "{e}");
    let broken = out("broken.safetensors");
    std::fs::write(&broken, b"\x10\0\0\0\0\0\0\0{}").unwrap();
    let e = fails(
        &[
            "render",
            s(&scene_file),
            "--features",
            s(&npy),
            "--shader",
            s(&broken),
            "-o",
            s(&o),
        ],
        &o,
    );
    assert!(e.contains("broken.safetensors"), "{e}");
    let e = fails(
        &[
            "render",
            s(&scene_file),
            "--features",
            s(&npy),
            "--shader",
            s(&shader),
            "--mode",
            "features",
            "-o",
            s(&out("x.exr")),
        ],
        &out("x.exr"),
    );
    assert!(e.contains("choose one"), "{e}");
}

/// A network written by `Mlp::save` (what a trainer writes) reads back as the same
/// network, and an existing file is kept unless overwriting is asked for.
#[test]
fn a_saved_shader_reads_back_as_the_same_network() {
    let (tensors, description) = network(
        &["features", "view_dir", "alpha"],
        &[9, 7, 5, 3],
        &["tanh", "relu", "sigmoid"],
        21,
    );
    let mlp = Mlp::parse(&file_of(&tensors, Some(&description)), None).unwrap();
    assert_eq!(Mlp::parse(&mlp.to_safetensors(), None).unwrap(), mlp);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("shader.safetensors");
    mlp.save(&path, false).unwrap();
    assert_eq!(Mlp::load(&path).unwrap(), mlp);
    let before = std::fs::read(&path).unwrap();
    let (tensors, description) = network(&["features"], &[4, 3], &["none"], 22);
    let other = Mlp::parse(&file_of(&tensors, Some(&description)), None).unwrap();
    let e = other.save(&path, false).unwrap_err();
    assert!(e.to_string().contains("exists"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
    other.save(&path, true).unwrap();
    assert_eq!(Mlp::load(&path).unwrap(), other);
}
