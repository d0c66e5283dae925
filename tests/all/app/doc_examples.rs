//! The command examples of README.md and docs/*.md, run. Every line that starts with
//! `verisplat ` inside a fenced `sh`, `bash` or `console` block (joined with the lines its
//! backslashes continue) is an example. Each page's examples run in document order in a
//! temporary folder of their own, prepared with the input files the page names (copies
//! of the small shared scenes in `../shared/data`, see [`PAGES`]), so an example can use
//! what the one before wrote. An example fails the test when it exits non-zero; one
//! that is neither run nor in [`NOT_RUN`] (with the reason it cannot run in a test)
//! fails it too, and so does an entry of [`NOT_RUN`] or [`CAPS`] that no example matches
//! any more. Long user commands keep their text in the docs: [`CAPS`] gives the few
//! options that make them small here.

use crate::common::cli::{bin, stderr, stdout};
use crate::common::{doc_pages, shared_data};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;

/// An example: where it is, and the command as one line.
#[derive(Debug, Clone)]
struct Example {
    page: String,
    line: usize,
    /// The command, continuations joined, without a trailing `# comment`.
    command: String,
}

/// An input file an example names, made before the page's examples run.
enum Input {
    /// A copy of a file of `../shared/data` under the example's name.
    Copy(&'static str, &'static str),
    /// A symbolic link to a folder of `../shared/data`.
    Link(&'static str, &'static str),
    /// A small INRIA cameras.json: cameras 0, 8 and 16 of the shared synthetic PLAYBOT
    /// orbit, at an eighth of their size (160x90).
    SmallCameras(&'static str),
}

/// A page, the inputs its examples name, and commands (run as the examples are) that
/// make the rest of what they read: a trained model's photos, the frames a cluster
/// job wrote.
struct Page {
    file: &'static str,
    inputs: &'static [Input],
    prepare: &'static [&'static str],
}

const PLAYBOT_LOD6: &str = "playbot_lod6_1873_sh2.ply";

/// Every page with examples. A page that gets examples must be added here
/// (`every_page_with_examples_is_listed` checks).
const PAGES: &[Page] = &[
    Page {
        file: "README.md",
        inputs: &[
            Input::Copy("scene.ply", PLAYBOT_LOD6),
            Input::SmallCameras("cameras.json"),
        ],
        prepare: &[],
    },
    Page {
        file: "docs/rendering.md",
        inputs: &[
            Input::Copy("scene.ply", PLAYBOT_LOD6),
            Input::SmallCameras("cameras.json"),
        ],
        prepare: &[],
    },
    Page {
        file: "docs/cluster.md",
        inputs: &[
            Input::Copy("scene.ply", PLAYBOT_LOD6),
            Input::SmallCameras("path.json"),
        ],
        // What the Slurm array of the page's first example writes.
        prepare: &["verisplat render scene.ply --cameras path.json -o 'renders/frame_%05d.png'"],
    },
    Page {
        file: "docs/compare-eval.md",
        inputs: &[
            Input::Copy("scene.ply", PLAYBOT_LOD6),
            Input::SmallCameras("cameras.json"),
            Input::Copy(
                "output/garden/point_cloud/iteration_30000/point_cloud.ply",
                PLAYBOT_LOD6,
            ),
            Input::SmallCameras("output/garden/cameras.json"),
        ],
        // The model's photos: its own renders, named after its cameras.
        prepare: &["verisplat render scene.ply --cameras cameras.json -o data/garden/images_4/{name}.png"],
    },
    Page {
        file: "docs/training.md",
        inputs: &[Input::Copy("scene.ply", PLAYBOT_LOD6)],
        // A COLMAP data set with a known answer; `eval` after `train -r 4` scales its
        // photos as the trainer did.
        prepare: &[
            "verisplat render scene.ply --orbit 24 --width 320 --height 240 --export-colmap data/garden",
        ],
    },
    Page {
        file: "docs/formats.md",
        inputs: &[
            Input::Copy("scene.spz", "playbot_lod3_31k_sh2.v3.spz"),
            Input::Link("playbot_sog", "playbot_lod3_31k_sh2_sog"),
        ],
        prepare: &[],
    },
    Page {
        file: "docs/cameras.md",
        inputs: &[Input::Copy("scene.ply", PLAYBOT_LOD6)],
        prepare: &[],
    },
    Page {
        file: "docs/rf-fields.md",
        inputs: &[],
        prepare: &[],
    },
];

/// Examples that cannot run in a test, each with the reason.
const NOT_RUN: &[(&str, &str)] = &[
    // The viewer serves until it is stopped (tests/all/app/view.rs and view_browser.rs test it).
    ("verisplat view scene.ply --open", "serves forever"),
    (
        "verisplat view ../shared/data/playbot_lod2_125k_sh2.ply --open",
        "serves forever",
    ),
    ("verisplat view output/garden", "serves forever"),
];

/// Long user commands made small here, keeping their text in the docs: (the example,
/// the options it runs with here, why). An option the example has gets the value given
/// here; one it lacks is appended.
type Cap = (
    &'static str,
    &'static [(&'static str, &'static str)],
    &'static str,
);
const CAPS: &[Cap] = &[
    (
        "verisplat render scene.ply --orbit 120 -o orbit/frame_{:05}.exr",
        &[("--frames", "0..2"), ("--width", "160")],
        "120 frames at 1280x720",
    ),
    (
        "verisplat train data/garden -o models/garden --eval -r 4",
        &[("--iterations", "50")],
        "30,000 iterations",
    ),
    (
        "verisplat train data/garden -o models/garden-masked --eval -r 4 --alpha-mode mask",
        &[("--iterations", "50")],
        "30,000 iterations",
    ),
    (
        "verisplat gen --rf dipole dipole.npy",
        &[("--size", "16")],
        "a 64^3 grid",
    ),
    (
        "verisplat fit dipole.npy -o dipole.ply --report dipole_fit.json",
        &[("--steps", "50")],
        "1,500 steps",
    ),
    (
        "verisplat render dipole.ply --mode field-slice --slice-plane 0,0,0.3,0,0,1 -o slice.png --colorbar --channel-name magnitude --units V/m",
        &[("--width", "160")],
        "1280x720",
    ),
    (
        "verisplat render dipole.ply --mode field-integral -o integral.npy",
        &[("--width", "160")],
        "1280x720",
    ),
    (
        "verisplat render dipole.ply --mode field-max -o max.png --range 0,0.5 --colorbar --width 320",
        &[("--width", "160")],
        "1280x720",
    ),
    (
        "verisplat render dipole.ply --mode field-slice --slice-plane 0,0,0,0,0,1 --shader shader.safetensors -o shaded.png",
        &[("--width", "160")],
        "1280x720",
    ),
    (
        "verisplat gen --rf moving-source moving.npy",
        &[("--size", "8"), ("--times", "5")],
        "16^3 points at 9 times",
    ),
    (
        "verisplat fit moving.npy -o moving.ply --gaussians 300 --max-gaussians 1000 --steps 800",
        &[("--steps", "50")],
        "800 steps",
    ),
    (
        "verisplat render moving.ply --time 0.25 --mode field-slice --slice-plane 0,0,0,0,0,1 -o t025.png",
        &[("--width", "160")],
        "1280x720",
    ),
    (
        "verisplat render moving.ply --time-range 0,1 --time-frames 30 --mode field-max --range 0,1 --width 320 -o anim/frame_%04d.png",
        &[("--frames", "0..3"), ("--width", "160")],
        "30 frames at 1280x720",
    ),
];

/// Other programs the examples run between `verisplat` lines, that later examples need
/// (the colour-map shader of the RF walkthrough): (the line's start, the command that
/// runs it).
const HELPERS: &[(&str, &str)] = &[(
    "tools/colormap_shader.py ",
    "python3 \"$VERISPLAT_REPO/tools/colormap_shader.py\" ",
)];

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The line without a trailing `# comment` (a `#` after a space, outside quotes).
fn strip_comment(line: &str) -> &str {
    let (mut single, mut double) = (false, false);
    let mut prev = ' ';
    for (i, c) in line.char_indices() {
        match c {
            '\'' if !double => single = !single,
            '"' if !single => double = !double,
            '#' if !single && !double && prev.is_whitespace() => return line[..i].trim_end(),
            _ => {}
        }
        prev = c;
    }
    line.trim_end()
}

/// The command lines of `prefixes` in a page's `sh`/`bash`/`console` blocks, in order.
fn commands(page: &str, text: &str, prefixes: &[&str]) -> Vec<Example> {
    let mut out = Vec::new();
    let mut fence: Option<String> = None;
    let mut lines = text.lines().enumerate();
    while let Some((i, line)) = lines.next() {
        let t = line.trim_start();
        if let Some(lang) = t.strip_prefix("```") {
            fence = match fence {
                None => Some(lang.trim().to_string()),
                Some(_) => None,
            };
            continue;
        }
        let shell = matches!(fence.as_deref(), Some("sh" | "bash" | "console"));
        let t = t.strip_prefix("$ ").unwrap_or(t);
        if !shell || !prefixes.iter().any(|p| t.starts_with(p)) {
            continue;
        }
        let mut command = t.to_string();
        while command.ends_with('\\') {
            command.pop();
            let (_, next) = lines.next().expect("a continuation line");
            command = format!("{} {}", command.trim_end(), next.trim());
        }
        out.push(Example {
            page: page.to_string(),
            line: i + 1,
            command: strip_comment(&command).to_string(),
        });
    }
    out
}

fn read(page: &str) -> String {
    std::fs::read_to_string(repo().join(page)).unwrap()
}

/// The `verisplat` examples of a page.
fn examples(page: &str) -> Vec<Example> {
    commands(page, &read(page), &["verisplat "])
}

fn not_run(e: &Example) -> bool {
    NOT_RUN.iter().any(|(c, _)| *c == e.command)
}

/// The example as it runs here, with its [`CAPS`].
fn capped(command: &str) -> String {
    let Some((_, options, _)) = CAPS.iter().find(|(c, _, _)| *c == command) else {
        return command.to_string();
    };
    let mut c = command.to_string();
    for (option, value) in *options {
        let flag = format!(" {option} ");
        match c.find(&flag) {
            Some(i) => {
                let at = i + flag.len();
                let end = c[at..].find(' ').map_or(c.len(), |j| at + j);
                c.replace_range(at..end, value);
            }
            None => c = format!("{c} {option} {value}"),
        }
    }
    c
}

/// Runs a command line of the docs in `dir` through `sh`, `verisplat` being the binary
/// under test (with the validation layer on) and helpers run as [`HELPERS`] says.
fn run(dir: &Path, command: &str) -> Output {
    let line = match command.strip_prefix("verisplat ") {
        Some(rest) => format!("\"$VERISPLAT\" {rest}"),
        None => {
            let (start, runner) = HELPERS
                .iter()
                .find(|(start, _)| command.starts_with(start))
                .expect("a known helper");
            format!("{runner}{}", &command[start.len()..])
        }
    };
    Command::new("sh")
        .arg("-c")
        .arg(line)
        .current_dir(dir)
        .env("VERISPLAT", bin())
        .env("VERISPLAT_REPO", repo())
        .env("VERISPLAT_VALIDATE", "1")
        .output()
        .expect("sh runs")
}

/// Writes the small cameras.json ([`Input::SmallCameras`]) to `to`.
fn small_cameras(to: &Path) {
    let file = shared_data().join("playbot_orbit_cameras.synthetic.json");
    let all: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    let cams: Vec<serde_json::Value> = [0, 8, 16]
        .iter()
        .map(|&i| {
            let mut c = all[i].clone();
            for key in ["width", "height"] {
                c[key] = (c[key].as_u64().unwrap() / 8).into();
            }
            for key in ["fx", "fy"] {
                c[key] = (c[key].as_f64().unwrap() / 8.0).into();
            }
            c
        })
        .collect();
    std::fs::write(to, serde_json::to_string_pretty(&cams).unwrap()).unwrap();
}

impl Input {
    /// Makes the input in `dir`.
    fn make(&self, dir: &Path) {
        let name = match self {
            Input::Copy(name, _) | Input::Link(name, _) | Input::SmallCameras(name) => name,
        };
        let to = dir.join(name);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        match self {
            Input::Copy(_, from) => {
                std::fs::copy(shared_data().join(from), &to).unwrap();
            }
            Input::Link(_, from) => {
                std::os::unix::fs::symlink(shared_data().join(from), &to).unwrap();
            }
            Input::SmallCameras(_) => small_cameras(&to),
        }
    }
}

/// Makes a page's inputs in `dir` and runs its preparing commands.
fn prepare(dir: &Path, page: &Page) {
    for input in page.inputs {
        input.make(dir);
    }
    for command in page.prepare {
        let o = run(dir, command);
        assert!(
            o.status.success(),
            "{}: preparing `{command}` failed:\n{}",
            page.file,
            stderr(&o)
        );
    }
}

/// Runs a page's examples in order; returns the failures.
fn run_page(page: &Page) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    prepare(dir.path(), page);
    let helpers: Vec<&str> = HELPERS.iter().map(|(s, _)| *s).collect();
    let mut prefixes = vec!["verisplat "];
    prefixes.extend(helpers);
    let mut failures = Vec::new();
    for e in commands(page.file, &read(page.file), &prefixes) {
        if not_run(&e) {
            continue;
        }
        let command = capped(&e.command);
        let start = Instant::now();
        let o = run(dir.path(), &command);
        eprintln!(
            "{}:{}: {:.1} s: {command}",
            e.page,
            e.line,
            start.elapsed().as_secs_f64()
        );
        if !o.status.success() {
            failures.push(format!(
                "{}:{}: `{command}` exited with {}:\n{}{}",
                e.page,
                e.line,
                o.status,
                stdout(&o),
                stderr(&o)
            ));
        }
    }
    failures
}

/// Every page with examples is in [`PAGES`] (so its examples run), and every entry of
/// [`NOT_RUN`] and [`CAPS`] still matches an example.
#[test]
fn every_page_with_examples_is_listed() {
    let all: Vec<Example> = doc_pages().iter().flat_map(|p| examples(p)).collect();
    for e in &all {
        assert!(
            not_run(e) || PAGES.iter().any(|p| p.file == e.page),
            "{}:{}: `{}` is neither run (add the page to PAGES) nor in NOT_RUN",
            e.page,
            e.line,
            e.command
        );
    }
    for (command, why) in NOT_RUN {
        assert!(
            all.iter().any(|e| e.command == *command),
            "NOT_RUN names `{command}` ({why}), which no page has any more"
        );
    }
    for (command, _, why) in CAPS {
        assert!(
            all.iter().any(|e| !not_run(e) && e.command == *command),
            "CAPS names `{command}` ({why}), which no example run has any more"
        );
    }
    for page in PAGES {
        assert!(
            doc_pages().iter().any(|p| p == page.file),
            "PAGES lists {}, which is not there",
            page.file
        );
    }
}

/// The examples of every page run and exit 0 (the pages in parallel).
#[test]
fn every_example_of_the_docs_runs() {
    let failures: Vec<String> = std::thread::scope(|s| {
        let runs: Vec<_> = PAGES.iter().map(|p| s.spawn(|| run_page(p))).collect();
        runs.into_iter().flat_map(|r| r.join().unwrap()).collect()
    });
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The extraction itself: continuations, comments, fences.
#[test]
fn examples_are_read_as_the_shell_reads_them() {
    let text = "```sh\n# a comment\nverisplat render a.ply \\\n    --orbit 3 -o 'x #1.png'   # note\nsbatch x\n```\n\n```python\nverisplat render not.ply\n```\nverisplat render outside.ply\n";
    let e = commands("t.md", text, &["verisplat "]);
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].line, 3);
    assert_eq!(
        e[0].command,
        "verisplat render a.ply --orbit 3 -o 'x #1.png'"
    );
    // A cap replaces the value of an option the example has, and appends one it lacks.
    assert_eq!(
        capped("verisplat render scene.ply --orbit 120 -o orbit/frame_{:05}.exr"),
        "verisplat render scene.ply --orbit 120 -o orbit/frame_{:05}.exr --frames 0..2 --width 160"
    );
    assert_eq!(
        capped(
            "verisplat fit moving.npy -o moving.ply --gaussians 300 --max-gaussians 1000 --steps 800"
        ),
        "verisplat fit moving.npy -o moving.ply --gaussians 300 --max-gaussians 1000 --steps 50"
    );
}
