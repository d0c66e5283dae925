//! `--help` as true as the binary (issue 59): every format a command reads or writes is
//! named where that command's help lists them, checked against the code that chooses the
//! format; the lens help says what draws lenses; no option shows its default twice; and
//! the PyTorch page's install line installs what its imports need.

use crate::common::cli::{ok, s, stdout};
use std::path::Path;
use verisplat::io::scene::write::OutputFormat;
use verisplat::io::video::VideoFormat;

/// `verisplat [command] --help`'s text.
fn help(command: &[&str]) -> String {
    let mut args = command.to_vec();
    args.push("--help");
    stdout(&ok(&args))
}

/// The entries of a help text, one per argument or option: its first line (`<INPUT>`,
/// `-o, --output <OUT>`, `--lens <LENS>`) with its text, on that line or the lines under
/// it, as clap lays out short and long help.
fn entries(help: &str) -> Vec<String> {
    let mut all: Vec<String> = Vec::new();
    let mut open = false;
    for line in help.lines() {
        let indent = line.len() - line.trim_start().len();
        let head = line.trim_start();
        if (2..=6).contains(&indent) && head.starts_with(['-', '<', '[']) {
            all.push(head.to_string());
            open = true;
        } else if open && indent > 6 {
            let last = all.last_mut().expect("open");
            last.push(' ');
            last.push_str(head);
        } else {
            open = false;
        }
    }
    all
}

/// The entry of `help` whose first line starts with `start` (`--lens`, `<OUTPUT>`).
fn option_help(help: &str, start: &str) -> String {
    entries(help)
        .into_iter()
        .find(|e| e.starts_with(start))
        .unwrap_or_else(|| panic!("no {start} in {help}"))
}

/// The commands that have a `--help` (every visible subcommand).
const COMMANDS: [&str; 11] = [
    "render", "info", "bench", "gen", "fit", "convert", "compare", "eval", "train", "view",
    "doctor",
];

/// The scene file names `convert` (and `gen`) write, each as the writer chooses it.
const SCENE_OUTPUTS: [&str; 7] = [
    ".ply",
    ".compressed.ply",
    ".splat",
    ".spz",
    ".sog",
    ".glb",
    ".gltf",
];

#[test]
fn help_names_every_format_the_binary_reads_and_writes() {
    let top = help(&[]);
    let line = |command: &str| -> String {
        top.lines()
            .find(|l| l.trim_start().starts_with(&format!("{command} ")))
            .unwrap_or_else(|| panic!("no {command} in {top}"))
            .to_string()
    };
    // render: images and videos, as `-o`'s name chooses.
    let render_line = line("render");
    let render = help(&["render"]);
    for ext in ["mp4", "webm", "gif"] {
        let format = VideoFormat::from_path(Path::new(&format!("out.{ext}")))
            .unwrap_or_else(|| panic!("render writes .{ext}"));
        let name = match format {
            VideoFormat::Mp4 => "MP4",
            VideoFormat::Webm => "WebM",
            VideoFormat::Gif => "GIF",
        };
        assert!(render_line.contains(name), "{render_line}");
        assert!(
            option_help(&render, "-o").contains(&format!("out.{ext}")),
            "render -o: .{ext}"
        );
    }
    assert!(
        render_line.contains("PNG") && render_line.contains("EXR"),
        "{render_line}"
    );
    // convert and gen: every writer.
    let convert_line = line("convert");
    let convert = help(&["convert"]);
    let convert_out = option_help(&convert, "<OUTPUT>");
    let gen_out = option_help(&help(&["gen"]), "-o");
    for ext in SCENE_OUTPUTS {
        assert!(
            OutputFormat::from_path(Path::new(&format!("scene{ext}"))).is_ok(),
            "{ext} is written"
        );
        assert!(convert_line.contains(ext), "{ext}: {convert_line}");
        assert!(convert_out.contains(ext), "{ext}: {convert_out}");
        assert!(gen_out.contains(ext), "{ext}: {gen_out}");
    }
    assert!(gen_out.contains("meta.json") && convert_out.contains("meta.json"));
    // What they read: glTF scenes, transforms.json cameras.
    let glb = "glTF (.glb, .gltf";
    let input = option_help(&convert, "<INPUT>");
    assert!(input.contains(glb), "{input}");
    let scene = option_help(&render, "[SCENE]");
    assert!(scene.contains(glb), "{scene}");
    let cameras = option_help(&render, "--cameras");
    assert!(cameras.contains("transforms.json"), "{cameras}");
}

/// What the help promises, done: `gen` writes glTF (a .gltf with its .bin, as convert),
/// and the scene and a transforms.json read back in `render`.
#[test]
fn gen_writes_what_its_help_names_and_render_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = dir.path().join("g.gltf");
    ok(&["gen", "50", "-o", s(&gltf)]);
    assert!(
        dir.path().join("g.bin").is_file(),
        "a .gltf's buffer beside it"
    );
    let glb = dir.path().join("g.glb");
    ok(&["gen", "50", "-o", s(&glb)]);
    let transforms = dir.path().join("transforms.json");
    std::fs::write(
        &transforms,
        r#"{"fl_x": 40, "fl_y": 40, "cx": 16, "cy": 12, "w": 32, "h": 24,
            "frames": [{"file_path": "a.png", "transform_matrix":
            [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]}"#,
    )
    .unwrap();
    for scene in [&gltf, &glb] {
        let out = dir.path().join("r.png");
        ok(&[
            "render",
            s(scene),
            "--cpu",
            "--cameras",
            s(&transforms),
            "-o",
            s(&out),
            "--overwrite",
            "-q",
        ]);
        assert!(out.is_file());
    }
}

/// `--lens` says the GPU draws every lens (it does: this renders a fisheye on the device).
#[test]
fn lens_help_says_every_lens_is_drawn_on_the_gpu() {
    for command in ["render", "compare", "bench", "view"] {
        let h = help(&[command]);
        let lens = option_help(&h, "--lens");
        assert!(!lens.contains("so far"), "{command}: {lens}");
        assert!(
            lens.contains("Every lens is drawn on the GPU and by the CPU reference"),
            "{command}: {lens}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fish.png");
    ok(&[
        "render",
        "--demo",
        "--lens",
        "fisheye:fov=200",
        "--width",
        "48",
        "--height",
        "48",
        "-o",
        s(&out),
        "-q",
    ]);
    assert!(out.is_file());
}

/// No option shows the same default twice (`--spz-axes` showed `[default: spec] [default:
/// spec]`: a `[default: ...]` in its text and clap's own).
#[test]
fn no_option_shows_its_default_twice() {
    let mut spz = 0;
    for command in COMMANDS {
        let h = help(&[command]);
        for entry in entries(&h) {
            // `--quality` has one per codec; the same one twice is the defect.
            let defaults: Vec<&str> = entry.split("[default:").skip(1).collect();
            let shown: Vec<&str> = defaults
                .iter()
                .filter_map(|d| d.split(']').next())
                .collect();
            for (k, d) in shown.iter().enumerate() {
                assert!(!shown[..k].contains(d), "{command}: {entry}");
            }
        }
        if h.contains("--spz-axes") {
            spz += 1;
            let axes = option_help(&h, "--spz-axes");
            assert_eq!(
                axes.matches("[default: spec]").count(),
                1,
                "{command}: {axes}"
            );
        }
    }
    assert!(spz >= 3, "render, compare and convert have --spz-axes");
}

/// The PyTorch page's install line for `verisplat.gsplat` (whose strategies subclass
/// gsplat's) installs gsplat, at the version the tests pin.
#[test]
fn the_gsplat_extra_installs_the_tested_gsplat() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let read = |p: &str| std::fs::read_to_string(root.join(p)).unwrap();
    let test_sh = read("tools/test.sh");
    let pinned = test_sh
        .split('"')
        .find(|w| w.starts_with("gsplat=="))
        .expect("tools/test.sh pins gsplat");
    let pyproject = read("python/pyproject.toml");
    let extra = format!("gsplat = [\"torch>=2\", \"{pinned}\"]");
    assert!(
        pyproject.contains(&extra),
        "no `{extra}` in python/pyproject.toml"
    );
    let page = read("docs/pytorch.md");
    assert!(
        page.contains("pip install \"./python[gsplat]\""),
        "docs/pytorch.md gives no install line for gsplat"
    );
    // Every extra the docs install exists.
    for doc in ["docs/pytorch.md", "docs/python.md", "README.md"] {
        let text = read(doc);
        for (at, opening) in text.match_indices("./python[") {
            let name: String = text[at + opening.len()..]
                .chars()
                .take_while(|c| *c != ']')
                .collect();
            assert!(
                pyproject.contains(&format!("\n{name} = [")),
                "{doc} installs the extra [{name}], which python/pyproject.toml lacks"
            );
        }
    }
}
