//! The project was called vksplat until 2026-11-28 (README). What was written under that
//! name still reads (PLY header comments, the neural shader's and the checkpoint's
//! safetensors metadata), old `VKSPLAT_*` variables still work with a deprecation note,
//! and no other file of the repository spells the old name. This file, `src/core/former_name.rs`,
//! the README's one sentence and BENCHMARKS.md's history are the only places that do.

use crate::common;
use crate::common::cli::{ok, s, stderr, verisplat_env};
use std::path::Path;

/// Replaces every `from` in `bytes` by `to` (which may differ in length).
fn replace(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    let (from, to) = (from.as_bytes(), to.as_bytes());
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    let mut n = 0;
    while i < bytes.len() {
        if bytes[i..].starts_with(from) {
            out.extend_from_slice(to);
            i += from.len();
            n += 1;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    assert!(n > 0, "{} not found", String::from_utf8_lossy(from));
    out
}

/// The scene as a binary PLY.
fn ply_bytes(scene: &verisplat::core::scene::Scene) -> Vec<u8> {
    verisplat::io::scene::write::to_bytes(scene, verisplat::io::scene::write::OutputFormat::Ply)
        .unwrap()
}

/// A PLY written under the former name (`comment vksplat kernel power`, `comment vksplat
/// rules gsplat`) loads with its kernel and rules, as the current comments do.
#[test]
fn a_ply_with_the_former_header_comments_keeps_its_kernel_and_rules() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let power = d.join("power.ply");
    ok(&["convert", s(&plain), s(&power), "--kernel", "power"]);
    let mut scene = verisplat::io::scene::load(&power).unwrap();
    scene.rules = verisplat::core::model::Rules::Gsplat;
    let both = d.join("both.ply");
    let current = ply_bytes(&scene);
    std::fs::write(&both, &current).unwrap();
    let old = replace(&current, "comment verisplat ", "comment vksplat ");
    let old_path = d.join("old.ply");
    std::fs::write(&old_path, &old).unwrap();
    let (new_scene, old_scene) = (
        verisplat::io::scene::load(&both).unwrap(),
        verisplat::io::scene::load(&old_path).unwrap(),
    );
    assert_eq!(new_scene.kernel, verisplat::cpu::SplatKernel::Power);
    assert_eq!(new_scene.rules, verisplat::core::model::Rules::Gsplat);
    assert_eq!(old_scene.kernel, new_scene.kernel);
    assert_eq!(old_scene.rules, new_scene.rules);
    assert_eq!(old_scene.positions, new_scene.positions);
    // Written again, the file carries the current name only.
    assert_eq!(ply_bytes(&old_scene), current);
}

/// A neural shader whose safetensors metadata names its description `vksplat_mlp` parses
/// as the same network under `verisplat_mlp`.
#[test]
fn a_shader_file_with_the_former_metadata_key_parses() {
    use safetensors::tensor::TensorView;
    let le = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let weight = le(&[0.5, -0.25, 0.75, 1.0, -1.0, 0.125]);
    let bias = le(&[0.1, -0.2, 0.3]);
    let views = [
        (
            "0.weight",
            TensorView::new(safetensors::Dtype::F32, vec![3, 2], &weight).unwrap(),
        ),
        (
            "0.bias",
            TensorView::new(safetensors::Dtype::F32, vec![3], &bias).unwrap(),
        ),
    ];
    let description = serde_json::json!({
        "inputs": ["features"],
        "layers": [{"weight": "0.weight", "bias": "0.bias", "activation": "sigmoid"}],
    })
    .to_string();
    let file = |key: &str| {
        let meta = std::collections::HashMap::from([(key.to_string(), description.clone())]);
        safetensors::serialize(views.clone(), Some(meta)).unwrap()
    };
    let current = verisplat::fields::mlp::Mlp::parse(&file("verisplat_mlp"), None).unwrap();
    let old = verisplat::fields::mlp::Mlp::parse(&file("vksplat_mlp"), None).unwrap();
    assert_eq!(current.feature_channels(), 2);
    assert_eq!(old.to_safetensors(), current.to_safetensors());
    // Another key is still no description.
    let e = verisplat::fields::mlp::Mlp::parse(&file("other_mlp"), None).unwrap_err();
    assert!(e.contains("verisplat_mlp"), "{e}");
}

/// A training checkpoint written under the former name (`vksplat_checkpoint`) resumes.
#[test]
fn a_checkpoint_with_the_former_metadata_key_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::dataset::make_dataset(&data, 4, 32, 24);
    let train = |out: &str, extra: &[&str]| {
        let model = dir.path().join(out);
        let mut args = vec![
            "train",
            s(&data),
            "-o",
            s(&model),
            "--iterations",
            "6",
            "--save-iterations",
            "6",
            "--test-iterations",
            "6",
            "-q",
        ];
        args.extend_from_slice(extra);
        ok(&args);
        model
    };
    let a = train("a", &["--checkpoint-iterations", "3"]);
    let chk = a.join("chkpnt3.safetensors");
    // Same length: the safetensors header's size is unchanged.
    let old = replace(
        &std::fs::read(&chk).unwrap(),
        "\"verisplat_checkpoint\"",
        "\"vksplat_checkpoint\"  ",
    );
    let old_chk = dir.path().join("old.safetensors");
    std::fs::write(&old_chk, old).unwrap();
    let b = train("b", &["--resume", s(&old_chk)]);
    let ply = "point_cloud/iteration_6/point_cloud.ply";
    assert_eq!(
        std::fs::read(a.join(ply)).unwrap(),
        std::fs::read(b.join(ply)).unwrap(),
        "the run resumed from the old checkpoint differs"
    );
}

/// An old `VKSPLAT_*` variable is honoured with a note naming its new name; the new name
/// wins when both are set, with a note that the old one is ignored.
#[test]
fn a_former_environment_variable_works_with_a_deprecation_note() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let o = verisplat_env(
        &["render", "--demo", "--width", "64", "-o", s(&out)],
        &[("VKSPLAT_EMULATE", "no-such-trait")],
    );
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("VKSPLAT_EMULATE is deprecated") && e.contains("set VERISPLAT_EMULATE instead"),
        "{e}"
    );
    assert!(e.contains("no-such-trait"), "{e}");
    assert!(!out.exists());
    let o = verisplat_env(
        &["render", "--demo", "--width", "64", "-o", s(&out)],
        &[
            ("VKSPLAT_EMULATE", "no-such-trait"),
            ("VERISPLAT_EMULATE", ""),
        ],
    );
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(!e.contains("deprecated"), "{e}");
    let ignored = "VKSPLAT_EMULATE is ignored because VERISPLAT_EMULATE is set too";
    assert_eq!(e.matches(ignored).count(), 1, "{e}");
    // The device as the issue found it: the old name set beside the new one.
    let o = verisplat_env(
        &[
            "render",
            "--demo",
            "--width",
            "64",
            "-o",
            s(&out),
            "--overwrite",
        ],
        &[
            ("VKSPLAT_DEVICE", "no-such-device"),
            ("VERISPLAT_DEVICE", ""),
        ],
    );
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("VKSPLAT_DEVICE is ignored because VERISPLAT_DEVICE is set too")
            && e.contains("unset VKSPLAT_DEVICE"),
        "{e}"
    );
}

/// No tracked file spells the former name except the ones that must: this file,
/// `src/core/former_name.rs`, the README's sentence and BENCHMARKS.md (history as written).
#[test]
fn the_former_name_is_spelt_only_where_old_files_are_read() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let listed = std::process::Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(root)
        .output();
    let files: Vec<String> = match listed {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout)
            .split('\0')
            .filter(|f| !f.is_empty())
            .map(String::from)
            .collect(),
        // Not a git checkout (a source archive): nothing to list, nothing to check.
        _ => return,
    };
    assert!(files.len() > 100, "git ls-files listed {}", files.len());
    let allowed = [
        "tests/all/app/former_name.rs",
        "src/core/former_name.rs",
        "BENCHMARKS.md",
    ];
    let mut offenders = Vec::new();
    for f in &files {
        if allowed.contains(&f.as_str()) {
            continue;
        }
        let Ok(bytes) = std::fs::read(root.join(f)) else {
            continue;
        };
        let text = String::from_utf8_lossy(&bytes).to_lowercase();
        // The README says it in one paragraph; elsewhere it is not said at all.
        let paragraphs = text.split("\n\n").filter(|p| p.contains("vksplat")).count();
        let expected = usize::from(f == "README.md");
        if paragraphs != expected {
            offenders.push(format!("{f}: {paragraphs} paragraphs"));
        }
    }
    assert!(offenders.is_empty(), "the former name in: {offenders:?}");
}
