//! Helpers shared by the CLI's integration tests (each test file is its own
//! crate and uses a part of them).
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

/// The `navsync` binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_navsync"))
}

pub use navsync::testfiles::TestDir;

/// A fresh directory `navsync-<test file>-<name>-<pid>-<n>` in the temp
/// dir, removed when the test passes and kept when it fails (see
/// [`TestDir`]).
pub fn temp_dir(name: &str) -> TestDir {
    TestDir::new(&format!("{}-{name}", env!("CARGO_CRATE_NAME")))
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
