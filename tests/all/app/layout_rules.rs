//! The repository's layout rules (the house rules of issue 36): rooms a newcomer can read
//! in one sitting. No source file over 1,000 lines, no function over 150 (Rust and Python
//! alike), and no import circle among the library's modules, the command line's
//! (`tools/module_graph.py`, down to submodules) or the Python package's (`--python`), and
//! no arrow back up between the library's wings or to the crate root (`--wings`).

use std::path::{Path, PathBuf};
use std::process::Command;

const MAX_FILE_LINES: usize = 1000;
const MAX_FN_LINES: usize = 150;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every file under `dir` (relative to the repository) whose name ends in one of `exts`.
fn files(dir: &str, exts: &[&str]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root().join(dir)];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if exts.iter().any(|e| path.to_string_lossy().ends_with(e)) {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

fn sources() -> Vec<PathBuf> {
    let mut all = Vec::new();
    for dir in ["src", "python/src", "tests", "benches"] {
        all.extend(files(dir, &[".rs"]));
    }
    all.push(root().join("build.rs"));
    all.extend(files("glsl", &[".comp", ".glsl"]));
    for dir in ["python/verisplat", "python/tests", "tools"] {
        all.extend(files(dir, &[".py"]));
    }
    all
}

fn rel(p: &Path) -> String {
    p.strip_prefix(root()).unwrap_or(p).display().to_string()
}

/// The name of the function a line opens (`pub(crate) async fn name(`...), if any.
fn fn_name(line: &str) -> Option<&str> {
    let mut rest = line.trim_start();
    for prefix in [
        "pub(crate) ",
        "pub(super) ",
        "pub ",
        "const ",
        "async ",
        "unsafe ",
    ] {
        rest = rest.strip_prefix(prefix).unwrap_or(rest);
    }
    let rest = rest.strip_prefix("extern \"C\" ").unwrap_or(rest);
    let name = rest.strip_prefix("fn ")?;
    let end = name.find(|c: char| !(c.is_alphanumeric() || c == '_'))?;
    Some(&name[..end])
}

/// (name, first line, length) of every function body over `MAX_FN_LINES` lines in rustfmt
/// layout: from the `fn` line to the `}` at the same indentation.
fn long_functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let Some(name) = fn_name(line) else { continue };
        if line.trim_end().ends_with(';') {
            continue; // a declaration without a body (a trait's)
        }
        let indent = &line[..line.len() - line.trim_start().len()];
        let close = lines[i..]
            .iter()
            .position(|l| l.starts_with(indent) && l[indent.len()..].starts_with('}'));
        if let Some(k) = close {
            if k + 1 > MAX_FN_LINES {
                out.push((name.to_string(), i + 1, k + 1));
            }
        }
    }
    out
}

/// (name, first line, length) of every Python function over `MAX_FN_LINES` lines: from
/// its `def` line past its header (until the header's brackets close) to the last line
/// indented deeper than the `def` (blank lines and comments do not end it). Brackets in a
/// header's strings, and a multi-line string's lines indented less than its function, are
/// not read as such (no file here has them).
fn long_python_functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let indent_of = |l: &str| l.len() - l.trim_start().len();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let rest = line.trim_start();
        let rest = rest.strip_prefix("async ").unwrap_or(rest);
        let Some(rest) = rest.strip_prefix("def ") else {
            continue;
        };
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let mut header_end = i;
        let mut depth = 0i64;
        for (k, l) in lines.iter().enumerate().skip(i) {
            header_end = k;
            depth += l
                .chars()
                .map(|c| match c {
                    '(' | '[' | '{' => 1,
                    ')' | ']' | '}' => -1,
                    _ => 0,
                })
                .sum::<i64>();
            if depth <= 0 {
                break;
            }
        }
        let mut last = header_end;
        for (j, l) in lines.iter().enumerate().skip(header_end + 1) {
            let code = l.trim_start();
            if code.is_empty() || code.starts_with('#') {
                continue;
            }
            if indent_of(l) <= indent_of(line) {
                break;
            }
            last = j;
        }
        if last - i + 1 > MAX_FN_LINES {
            out.push((name, i + 1, last - i + 1));
        }
    }
    out
}

#[test]
fn the_function_finder_measures_what_it_should() {
    let body = |n: usize| "    let x = 1;\n".repeat(n);
    let text = format!(
        "pub(crate) fn short() {{\n{}}}\n\nimpl A {{\n    pub fn long(\n        a: u32,\n    ) -> u32 {{\n    {}    }}\n    fn decl(&self);\n}}\n",
        body(3),
        body(MAX_FN_LINES)
    );
    let found = long_functions(&text);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].0, "long");
    assert_eq!(found[0].1, 8);
    assert_eq!(found[0].2, MAX_FN_LINES + 4);
}

#[test]
fn the_python_function_finder_measures_what_it_should() {
    let body = |n: usize| "        x = 1\n".repeat(n);
    let text = format!(
        "def short():\n{}\n\nclass A:\n    @staticmethod\n    async def long(\n        a,\n    ) -> int:\n{}\n# a comment\n{}        return 1\n\n    def after(self):\n        pass\n",
        body(3),
        body(MAX_FN_LINES - 10),
        body(5)
    );
    let found = long_python_functions(&text);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].0, "long");
    assert_eq!(found[0].1, 9);
    assert_eq!(found[0].2, MAX_FN_LINES + 1);
}

#[test]
fn no_file_over_1000_lines_and_no_function_over_150() {
    let mut faults = Vec::new();
    for path in sources() {
        let text = std::fs::read_to_string(&path).unwrap();
        let n = text.lines().count();
        if n > MAX_FILE_LINES {
            faults.push(format!("{}: {n} lines", rel(&path)));
        }
        if path.extension().is_some_and(|e| e == "rs") {
            for (name, line, len) in long_functions(&text) {
                faults.push(format!("{}:{line}: fn {name} is {len} lines", rel(&path)));
            }
        }
        if path.extension().is_some_and(|e| e == "py") {
            for (name, line, len) in long_python_functions(&text) {
                faults.push(format!("{}:{line}: def {name} is {len} lines", rel(&path)));
            }
        }
    }
    assert!(
        faults.is_empty(),
        "over the house limits ({MAX_FILE_LINES} lines a file, {MAX_FN_LINES} a function):\n{}",
        faults.join("\n")
    );
}

/// `GpuRenderer`'s face is one file (issue 64, item 1): every `impl GpuRenderer` block is
/// in `src/render/mod.rs`, and the frame machinery and the stages below it never name the
/// renderer (they are methods of the types that own their state: `Frames`, `FrameSet`,
/// `BackwardState`, ...). The two files below it that do are its clients, built on its
/// public face: the pipelined camera path (`frame/path.rs`) and the differentiable
/// rasterizer (`backward/differentiable.rs`).
#[test]
fn the_renderer_has_one_face_and_its_machinery_never_names_it() {
    let clients = [
        "src/render/frame/path.rs",
        "src/render/backward/differentiable.rs",
    ];
    let mut found = Vec::new();
    for path in files("src", &[".rs"]) {
        let text = std::fs::read_to_string(&path).unwrap();
        let name = rel(&path);
        let code = || {
            text.lines()
                .filter(|l| !l.trim_start().starts_with("//"))
                .collect::<Vec<_>>()
        };
        if name != "src/render/mod.rs" && code().iter().any(|l| l.starts_with("impl GpuRenderer")) {
            found.push(format!("{name}: impl GpuRenderer"));
        }
        if name.starts_with("src/render/")
            && name != "src/render/mod.rs"
            && !clients.contains(&name.as_str())
            && code().iter().any(|l| l.contains("GpuRenderer"))
        {
            found.push(format!("{name}: names GpuRenderer"));
        }
    }
    assert!(found.is_empty(), "{found:#?}");
    let face = std::fs::read_to_string(root().join("src/render/mod.rs")).unwrap();
    assert!(face.lines().any(|l| l.starts_with("impl GpuRenderer")));
}

#[test]
fn no_import_circle_in_the_library_or_the_command_line() {
    for args in [&["--depth", "3"][..], &["--bin", "--depth", "2"]] {
        let (ok, text) = module_graph(args);
        assert!(ok && text.contains("cycles: none"), "{text}");
    }
}

/// The Python package's modules import each other without a circle, function-local
/// imports included (`_carried.py` and `torch.py` did: what both need is `_passes.py`).
#[test]
fn no_import_circle_in_the_python_package() {
    let (ok, text) = module_graph(&["--python"]);
    assert!(ok && text.contains("cycles: none"), "{text}");
}

#[test]
fn every_arrow_between_the_wings_runs_down() {
    let (ok, text) = module_graph(&["--wings"]);
    assert!(
        ok && text.contains("wings: every arrow runs down core < io < fields < cpu"),
        "{text}"
    );
}

/// Runs tools/module_graph.py with `args`: whether it exited 0, and what it printed
/// (its arguments, its exit status, its stdout and stderr, for a failure's message).
fn module_graph(args: &[&str]) -> (bool, String) {
    let out = Command::new("python3")
        .arg(root().join("tools/module_graph.py"))
        .args(args)
        .output()
        .expect("python3 runs tools/module_graph.py");
    let text = format!(
        "tools/module_graph.py {}: {}\n{}{}",
        args.join(" "),
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}
