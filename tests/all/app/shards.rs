//! Splitting work into shards (`--shard I/N|slurm`) through the binary: render shards give
//! the files of one process, `--verify` names missing and unreadable frames, eval shards
//! merge into the report of one run, bench sweeps split their points, `--devices` spreads
//! frames over renderers, and bad input is one sentence. (The same under a real Slurm
//! cluster: tools/slurm_test.sh.)

use crate::common::cli::{command, fails, s, stderr, stdout, verisplat, verisplat_env};
use crate::common::shared_data;
use std::path::{Path, PathBuf};
use std::process::Output;

/// The Slurm array variables, removed from every run here so a test suite that runs
/// inside a Slurm job sees the same as one that does not.
const SLURM_VARS: [&str; 5] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_STEP",
];

/// Runs the binary without any Slurm variable but those of `env`.
fn run(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = command();
    c.args(args);
    for v in SLURM_VARS {
        c.env_remove(v);
    }
    c.envs(env.iter().copied());
    c.output().expect("the binary runs")
}

fn succeeds(args: &[&str], env: &[(&str, &str)]) -> Output {
    let o = run(args, env);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    o
}

/// Owned arguments as the `&str`s the helpers take.
fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// The 24 cameras of the shared PLAYBOT orbit and its smallest scene.
fn scene_and_cameras() -> (String, String) {
    let d = shared_data();
    (
        s(&d.join("playbot_lod6_1873_sh2.ply")).to_string(),
        s(&d.join("playbot_orbit_cameras.synthetic.json")).to_string(),
    )
}

/// `render SCENE --cameras CAMERAS --width 64`: the path at a small size.
fn render_path<'a>(scene: &'a str, cams: &'a str) -> Vec<&'a str> {
    vec!["render", scene, "--cameras", cams, "--width", "64"]
}

/// The sorted file names and contents of a folder.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn render_shards_write_the_files_of_one_process_and_verify_checks_them() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cams) = scene_and_cameras();
    let base = ["render", &scene, "--cameras", &cams, "--width", "96", "-q"];
    let with = |out: &Path, more: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = base.iter().map(|x| x.to_string()).collect();
        a.extend(["-o".into(), format!("{}/f_%02d.png", s(out))]);
        a.extend(more.iter().map(|x| x.to_string()));
        a
    };
    let one = dir.path().join("one");
    succeeds(&strs(&with(&one, &[])), &[]);
    // 5 shards of 24 frames: blocks of 4 or 5, in order.
    let split = dir.path().join("split");
    let mut blocks = Vec::new();
    for i in 0..5 {
        let o = succeeds(&strs(&with(&split, &["--shard", &format!("{i}/5")])), &[]);
        let note = stderr(&o);
        blocks.push(
            note.lines()
                .find(|l| l.starts_with(&format!("shard {i}/5: ")))
                .unwrap_or_else(|| panic!("{note}"))
                .to_string(),
        );
    }
    assert_eq!(
        blocks,
        [
            "shard 0/5: 4 frames of the 24 selected, frames 0..=3",
            "shard 1/5: 5 frames of the 24 selected, frames 4..=8",
            "shard 2/5: 5 frames of the 24 selected, frames 9..=13",
            "shard 3/5: 5 frames of the 24 selected, frames 14..=18",
            "shard 4/5: 5 frames of the 24 selected, frames 19..=23",
        ]
    );
    let want = files(&one);
    assert_eq!(want.len(), 24);
    assert!(
        files(&split) == want,
        "the shards' files differ from one process's"
    );

    // --verify: all there.
    let o = succeeds(&strs(&with(&split, &["--verify"])), &[]);
    assert!(stdout(&o).is_empty(), "{}", stdout(&o));
    // A missing frame and a truncated one are listed, and the check fails.
    std::fs::remove_file(split.join("f_05.png")).unwrap();
    let f17 = split.join("f_17.png");
    let bytes = std::fs::read(&f17).unwrap();
    std::fs::write(&f17, &bytes[..bytes.len() / 2]).unwrap();
    let o = run(&strs(&with(&split, &["--verify"])), &[]);
    assert!(!o.status.success());
    let listed: Vec<String> = stdout(&o).lines().map(str::to_string).collect();
    assert_eq!(listed.len(), 2, "{listed:?}");
    assert!(listed[0].starts_with("frame 5: ") && listed[0].ends_with(": missing"));
    assert!(
        listed[1].starts_with("frame 17: ") && listed[1].contains("unreadable"),
        "{listed:?}"
    );
    let last = stderr(&o).trim_end().lines().last().unwrap().to_string();
    assert!(
        last.starts_with("error: 2 of 24 frames incomplete: 1 file(s) missing, 1 unreadable"),
        "{last}"
    );
    // --verify with a shard checks only its block: shard 0 is complete.
    succeeds(&strs(&with(&split, &["--verify", "--shard", "0/5"])), &[]);
    // Resuming the damaged shards: the missing frame is rendered again.
    std::fs::remove_file(&f17).unwrap();
    for i in [1, 3] {
        let sh = format!("{i}/5");
        succeeds(
            &strs(&with(&split, &["--shard", &sh, "--skip-existing"])),
            &[],
        );
    }
    succeeds(&strs(&with(&split, &["--verify"])), &[]);
    assert!(files(&split) == want);
}

#[test]
fn shard_slurm_reads_the_array_task_and_bad_shards_are_one_sentence() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cams) = scene_and_cameras();
    let out = dir.path().join("out");
    let pattern = format!("{}/f_%02d.png", s(&out));
    let render = |shard: &str| {
        vec![
            "render".to_string(),
            scene.clone(),
            "--cameras".into(),
            cams.clone(),
            "--width".into(),
            "64".into(),
            "-q".into(),
            "-o".into(),
            pattern.clone(),
            "--shard".into(),
            shard.into(),
        ]
    };
    // sbatch --array=1-3: task 3 is shard 2 of 3, frames 16..=23.
    let slurm = [
        ("SLURM_ARRAY_TASK_ID", "3"),
        ("SLURM_ARRAY_TASK_COUNT", "3"),
        ("SLURM_ARRAY_TASK_MIN", "1"),
        ("SLURM_ARRAY_TASK_MAX", "3"),
    ];
    let o = succeeds(&strs(&render("slurm")), &slurm);
    assert!(
        stderr(&o).contains("shard 2/3: 8 frames of the 24 selected, frames 16..=23"),
        "{}",
        stderr(&o)
    );
    let written: Vec<String> = files(&out).into_iter().map(|(n, _)| n).collect();
    assert_eq!(
        written,
        (16..24).map(|k| format!("f_{k}.png")).collect::<Vec<_>>()
    );
    std::fs::remove_dir_all(&out).unwrap();

    // --export-cameras: shard 0 writes the whole path's cameras, the others nothing (so
    // they do not refuse the file shard 0 wrote).
    let exported = dir.path().join("cams.json");
    for i in [1, 0, 2] {
        let mut a = render(&format!("{i}/3"));
        a.extend(["--export-cameras".into(), s(&exported).into()]);
        succeeds(&strs(&a), &[]);
        assert_eq!(exported.exists(), i != 1, "after shard {i}");
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&exported).unwrap()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 24);
    std::fs::remove_dir_all(&out).unwrap();

    // More shards than frames: the extra ones have nothing to do and succeed.
    // (Blocks of 3 frames in 8 shards: shards 2, 5 and 7 take one each.)
    let mut few = render("4/8");
    few.extend(["--frames".into(), "0..3".into()]);
    let o = succeeds(&strs(&few), &[]);
    assert!(
        stderr(&o).contains("shard 4/8: no frames"),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(&out);

    for (shard, needle) in [
        (
            "4/4",
            "--shard 4/4: shard 4 does not exist: shards are numbered 0 to 3",
        ),
        (
            "1/0",
            "--shard 1/0: the number of shards must be at least 1",
        ),
        ("2", "expected I/N"),
        (
            "slurm",
            "--shard slurm: SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT are not set",
        ),
    ] {
        let o = run(&strs(&render(shard)), &[]);
        let e = stderr(&o);
        assert!(!o.status.success(), "{shard}: {e}");
        assert!(
            e.starts_with("error: ") && e.contains(needle),
            "{shard}: {e}"
        );
        assert_eq!(e.trim_end().lines().count(), 1, "{shard}: {e}");
        assert!(!out.exists(), "{shard} wrote files");
    }
    // A task of an array whose ids are not evenly spaced (--array=0,3,7).
    let o = run(
        &strs(&render("slurm")),
        &[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_MAX", "7"),
        ],
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("evenly spaced"), "{}", stderr(&o));
    // Shards whose outputs overlap: one file for all the frames of the path.
    let single = dir.path().join("one.png");
    let mut a = render_path(&scene, &cams);
    a.extend(["-o", s(&single), "--shard", "0/24"]);
    let e = fails(&a, &single);
    assert!(e.contains("24 frames but the output names one file"), "{e}");
    // The same for eval and bench.
    let e = fails(
        &[
            "eval",
            &scene,
            "--cameras",
            &cams,
            "--images",
            s(dir.path()),
            "--shard",
            "3/3",
        ],
        &dir.path().join("eval_report"),
    );
    assert!(e.contains("shard 3 does not exist"), "{e}");
    let o = verisplat_env(
        &[
            "bench",
            "--demo",
            "--sweep",
            "resolution=64x64",
            "--shard",
            "0/0",
        ],
        &[],
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("at least 1"), "{}", stderr(&o));
}

/// Renders the finer LOD3 scene at the cameras as "photos" for evaluating LOD6 against.
fn photos(dir: &Path, cams: &str) -> PathBuf {
    let images = dir.join("photos");
    let lod3 = shared_data().join("playbot_lod3_31k_sh2.ply");
    let pattern = format!("{}/{{name}}.png", s(&images));
    succeeds(
        &[
            "render",
            s(&lod3),
            "--cameras",
            cams,
            "--width",
            "96",
            "-q",
            "-o",
            &pattern,
        ],
        &[],
    );
    images
}

#[test]
fn eval_shards_merge_into_the_report_of_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cams) = scene_and_cameras();
    let images = photos(dir.path(), &cams);
    let eval = |out: &Path, split: &str, more: &[&str]| {
        let mut a = vec![
            "eval",
            &scene,
            "--cameras",
            &cams,
            "--images",
            s(&images),
            "--split",
            split,
            "-q",
        ];
        a.extend(["-o", s(out)]);
        a.extend(more);
        succeeds(&a, &[])
    };
    let one = dir.path().join("one");
    eval(&one, "all", &[]);
    let parts = dir.path().join("parts");
    for i in 0..3 {
        eval(&parts, "all", &["--shard", &format!("{i}/3")]);
        assert!(parts.join(format!("report.shard-{i}-of-3.json")).is_file());
    }
    assert!(!parts.join("report.json").exists());
    // A re-run of a finished shard with --skip-existing does nothing.
    let o = eval(&parts, "all", &["--shard", "1/3", "--skip-existing"]);
    assert!(stderr(&o).contains("nothing to evaluate"), "{}", stderr(&o));
    // Merge into another folder; the report and CSV are those of one run, byte for byte
    // (the JSON numbers read back exactly).
    let merged = dir.path().join("merged");
    let o = succeeds(&["eval", "--merge", s(&parts), "-o", s(&merged)], &[]);
    assert!(stdout(&o).contains("mean of 24"), "{}", stdout(&o));
    for f in ["report.json", "report.csv"] {
        let (a, b) = (
            std::fs::read_to_string(one.join(f)).unwrap(),
            std::fs::read_to_string(merged.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs:\n{a}\n---\n{b}");
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(merged.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["results"].as_array().unwrap().len(), 24);
    assert!(json.get("shard").is_none());
    let psnr = json["mean"]["psnr"].as_f64().unwrap();
    assert!((15.0..60.0).contains(&psnr), "{psnr}");

    // A missing shard, and a shard of another evaluation, are refused.
    let gap = dir.path().join("gap");
    std::fs::create_dir_all(&gap).unwrap();
    for i in [0, 2] {
        let f = format!("report.shard-{i}-of-3.json");
        std::fs::copy(parts.join(&f), gap.join(&f)).unwrap();
    }
    let e = fails(&["eval", "--merge", s(&gap)], &gap.join("report.json"));
    assert!(
        e.contains("1 of 3 shard report(s) missing: shard(s) 1"),
        "{e}"
    );
    let other = dir.path().join("other");
    eval(&other, "test", &["--shard", "1/3"]);
    std::fs::copy(
        other.join("report.shard-1-of-3.json"),
        gap.join("report.shard-1-of-3.json"),
    )
    .unwrap();
    let e = fails(&["eval", "--merge", s(&gap)], &gap.join("report.json"));
    assert!(e.contains("is not a shard of the same evaluation"), "{e}");
    // Two runs of the same shard given together.
    let e = fails(
        &[
            "eval",
            "--merge",
            s(&parts),
            s(&other),
            "-o",
            s(&gap.join("x")),
        ],
        &gap.join("x"),
    );
    assert!(e.contains("both are shard 1/3"), "{e}");

    // More shards than the 3 test views: the empty shard renders nothing and names no
    // renderer, so the merge is still one run's report, byte for byte.
    let one_test = dir.path().join("one-test");
    eval(&one_test, "test", &[]);
    let thin = dir.path().join("thin");
    for i in 0..4 {
        eval(&thin, "test", &["--shard", &format!("{i}/4")]);
    }
    let merged_thin = dir.path().join("merged-thin");
    succeeds(&["eval", "--merge", s(&thin), "-o", s(&merged_thin)], &[]);
    for f in ["report.json", "report.csv"] {
        let (a, b) = (
            std::fs::read_to_string(one_test.join(f)).unwrap(),
            std::fs::read_to_string(merged_thin.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs:\n{a}\n---\n{b}");
    }
}

#[test]
fn bench_sweep_shards_split_the_points() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("b.json");
    let mut names = Vec::new();
    for i in 0..2 {
        let o = verisplat(&[
            "bench",
            "--demo",
            "--sweep",
            "resolution=32x32,48x48,64x64",
            "--frames",
            "1",
            "--warmup",
            "0",
            "-q",
            "--json",
            s(&json),
            "--shard",
            &format!("{i}/2"),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let file = dir.path().join(format!("b.shard-{i}-of-2.json"));
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        for run in v["runs"].as_array().unwrap() {
            names.push(run["width"].as_u64().unwrap());
        }
    }
    assert!(!json.exists(), "a shard wrote the unsharded file");
    assert_eq!(names, [32, 48, 64], "each point once, in order");
    // The shards' reports merge into one of every point, in the sweep's order.
    let shard = |i: usize| dir.path().join(format!("b.shard-{i}-of-2.json"));
    let o = verisplat(&[
        "bench",
        "--merge",
        s(&shard(1)),
        s(&shard(0)),
        "--json",
        s(&json),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["schema_version"], 1);
    let widths: Vec<u64> = v["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["width"].as_u64().unwrap())
        .collect();
    assert_eq!(widths, [32, 48, 64]);
    // A missing shard, a shard twice, or a file that is no shard's: one sentence each.
    let merged = dir.path().join("m.json");
    for (files, says) in [
        (vec![shard(0)], "missing"),
        (vec![shard(0), shard(0)], "both are"),
        (vec![json.clone()], "not a shard's report"),
    ] {
        let mut a = vec!["bench", "--merge"];
        a.extend(files.iter().map(|f| s(f)));
        a.extend(["--json", s(&merged)]);
        let o = verisplat(&a);
        assert!(!o.status.success());
        assert!(stderr(&o).contains(says), "{}", stderr(&o));
    }
}

#[test]
fn devices_spread_frames_over_renderers_with_the_files_of_one() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cams) = scene_and_cameras();
    let out = |name: &str| format!("{}/{name}/f_%02d.png", s(dir.path()));
    let mut base = render_path(&scene, &cams);
    base.extend(["-q", "--frames", "0..7"]);
    let one = out("one");
    let mut a = base.to_vec();
    a.extend(["-o", &one]);
    succeeds(&a, &[]);
    // lavapipe is one device: naming it twice gives two renderers on it.
    let two = out("two");
    let mut a = base.to_vec();
    a.extend(["-o", &two, "--devices", "0,0"]);
    let o = succeeds(&a, &[]);
    assert!(stderr(&o).contains("(2 renderers)"), "{}", stderr(&o));
    assert!(stderr(&o).contains("frames 0..=2") && stderr(&o).contains("frames 3..=6"));
    let all = out("all");
    let mut a = base.to_vec();
    a.extend(["-o", &all, "--devices", "all"]);
    succeeds(&a, &[]);
    let want = files(&dir.path().join("one"));
    assert_eq!(want.len(), 7);
    assert!(files(&dir.path().join("two")) == want);
    assert!(files(&dir.path().join("all")) == want);
    let o = run(&["render", &scene, "--devices", "9", "-o", &out("x")], &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("there is no device #9"),
        "{}",
        stderr(&o)
    );
}
