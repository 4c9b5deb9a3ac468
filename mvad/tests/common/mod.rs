//! Helpers shared by the tests of the `mvad` binary (`cli.rs`, `cli_hygiene.rs`): run it from
//! the workspace root, check its exit status and that nothing panicked, read its output, and
//! write scratch files into temporary directories that are removed when dropped.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

/// The workspace root (the models are under `models/`).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Runs the binary with `args` from the workspace root.
pub fn mvad(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mvad"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the binary runs")
}

/// Standard output as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs and asserts the exit status, and that nothing panicked.
pub fn run_status(args: &[&str], status: i32) -> Output {
    let o = mvad(args);
    let err = stderr(&o);
    assert!(!err.contains("panicked"), "panic for {args:?}: {err}");
    assert_eq!(
        o.status.code(),
        Some(status),
        "exit status of {args:?}\nstdout: {}\nstderr: {err}",
        stdout(&o)
    );
    o
}

/// Standard output parsed as JSON.
pub fn json(o: &Output) -> Value {
    serde_json::from_str(&stdout(o)).unwrap_or_else(|e| panic!("not JSON ({e}): {}", stdout(o)))
}

/// A scratch file `name` holding `contents` in a fresh temporary directory: the directory
/// (removed when dropped) and the file's path as text.
pub fn scratch(name: &str, contents: &[u8]) -> (tempfile::TempDir, String) {
    let dir = tempfile::Builder::new()
        .prefix("mvad-cli-")
        .tempdir()
        .expect("temp dir");
    let path = dir.path().join(name);
    std::fs::write(&path, contents).expect("write");
    let path = path.to_string_lossy().into_owned();
    (dir, path)
}
