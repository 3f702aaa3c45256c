//! Helpers shared by the CLI's integration tests (each test file is its own
//! crate and uses a part of them).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The `navsync` binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_navsync"))
}

/// A test's own directory, removed when the test passes. A failing test
/// (dropped while panicking) leaves it in place to be looked at; its path
/// is in the failure's output wherever the test printed it.
pub struct TestDir(PathBuf);

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TestDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// A fresh directory `navsync-<test file>-<pid>-<name>` in the temp dir,
/// removed again when the returned guard is dropped (see [`TestDir`]).
pub fn temp_dir(name: &str) -> TestDir {
    let d = std::env::temp_dir().join(format!(
        "navsync-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    TestDir(d)
}

/// Runs `cmd`: (success, stdout, stderr).
pub fn run(cmd: &mut Command) -> (bool, String, String) {
    let out = cmd.output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A JSON file's contents.
pub fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Horizontal RMS of `nav` against `truth` (`navsync eval --json`, the
/// JSON written as `dir/eval.json`).
pub fn horizontal_rms(truth: &Path, nav: &Path, dir: &Path) -> f64 {
    let j = dir.join("eval.json");
    let (ok, _, err) = run(bin()
        .args(["eval", "--truth"])
        .arg(truth)
        .arg("--nav")
        .arg(nav)
        .arg("--json")
        .arg(&j));
    assert!(ok, "{err}");
    json(&j)["pos_horizontal_m"]["rms"].as_f64().unwrap()
}
