//! Running the `verisplat` binary from the integration tests, with the validation layer on.

use std::path::Path;
use std::process::{Command, Output};

/// The binary under test.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_verisplat")
}

/// A command for the binary with `VERISPLAT_VALIDATE=1` (any validation message fails it).
pub fn command() -> Command {
    let mut c = Command::new(bin());
    c.env("VERISPLAT_VALIDATE", "1");
    c
}

/// Runs the binary in `dir` with `env` added.
pub fn verisplat_in_env(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = command();
    c.args(args).current_dir(dir);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("the binary runs")
}

/// Runs the binary in `dir`.
pub fn verisplat_in(dir: &Path, args: &[&str]) -> Output {
    verisplat_in_env(dir, args, &[])
}

/// Runs the binary with `env` added.
pub fn verisplat_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    verisplat_in_env(Path::new("."), args, env)
}

/// Runs the binary.
pub fn verisplat(args: &[&str]) -> Output {
    verisplat_env(args, &[])
}

/// Its standard error, lossily decoded.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Its standard output, lossily decoded.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs a command that must succeed (and not panic); returns its output.
pub fn ok(args: &[&str]) -> Output {
    let o = verisplat(args);
    let e = stderr(&o);
    assert!(o.status.success(), "{args:?} failed: {e}");
    assert!(!e.contains("panicked"), "{args:?} panicked: {e}");
    o
}

/// Runs a command that must succeed (and not panic); returns its standard error.
pub fn ok_stderr(args: &[&str]) -> String {
    stderr(&ok(args))
}

/// Runs a command that must fail with one `error:` sentence (no panic) and leave `out`
/// absent; returns the sentence.
pub fn fails(args: &[&str], out: &Path) -> String {
    let o = verisplat(args);
    let e = stderr(&o);
    assert!(!o.status.success(), "{args:?} must fail");
    assert!(!e.contains("panicked"), "{args:?} panicked: {e}");
    assert!(e.starts_with("error: "), "{args:?}: {e}");
    assert_eq!(e.trim_end().lines().count(), 1, "one sentence: {e}");
    assert!(!out.exists(), "{args:?} left {}", out.display());
    e
}

/// The last line of a command's standard error, checking that the command failed and did
/// not panic (a run that stops part-way prints its progress first).
pub fn failure_last_line(o: &Output) -> String {
    let e = stderr(o);
    assert!(!o.status.success(), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    e.trim_end().lines().last().unwrap_or_default().to_string()
}

/// A path as the `&str` argument the binary takes.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}
