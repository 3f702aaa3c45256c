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

/// `navsync simulate` of `scenario` for `duration_s` with an ADIS16465
/// and seed 3 (the exact model: `--internal-rate 0`), plus `extra`
/// arguments, into `dir/sim`; returns that folder.
pub fn simulate_adis16465(
    dir: &Path,
    scenario: &str,
    duration_s: &str,
    extra: &[&str],
) -> std::path::PathBuf {
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--internal-rate", "0", "--scenario"])
        .arg(scenario)
        .args(["--duration", duration_s, "--imu-grade", "adis16465"])
        .args(["--seed", "3", "--output"])
        .arg(&sim)
        .args(extra));
    assert!(ok, "{err}");
    sim
}

/// `navsync simulate` of the 240 s test-track drive with seed 1 (at rest
/// for 26 s, then driving at up to 20 m/s), plus `extra` arguments (an
/// IMU grade, a GNSS rate), into `dir/sim`; returns that folder.
pub fn simulate_test_track(dir: &Path, extra: &[&str]) -> std::path::PathBuf {
    simulate_test_track_for(dir, "240", extra)
}

/// [`simulate_test_track`] for `duration_s` seconds.
pub fn simulate_test_track_for(dir: &Path, duration_s: &str, extra: &[&str]) -> std::path::PathBuf {
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--scenario",
            "test-track",
            "--duration",
            duration_s,
        ])
        .args(["--seed", "1", "--quiet", "--output"])
        .arg(&sim)
        .args(extra));
    assert!(ok, "{err}");
    sim
}

/// `navsync init --preset adis16465` written to `dir/name` with the
/// simulator's antenna lever arm (0.1 m forward, 0.5 m right, 1.2 m up)
/// and each `(from, to)` replacement of the template's text, every one of
/// which must apply; returns the sheet's path.
pub fn adis16465_sheet(dir: &Path, name: &str, edits: &[(&str, &str)]) -> std::path::PathBuf {
    let p = dir.join(name);
    let (ok, out, err) = run(bin()
        .args(["init", "--preset", "adis16465", "--output"])
        .arg(&p));
    assert!(ok && out.contains("wrote"), "{out}{err}");
    let mut text = std::fs::read_to_string(&p).unwrap();
    let lever = [(
        "antenna_lever_m: [0.0, 0.0, 0.0]",
        "antenna_lever_m: [0.1, 0.5, -1.2]",
    )];
    for (from, to) in lever.iter().chain(edits) {
        assert!(text.contains(from), "the sheet template has no '{from}'");
        text = text.replace(from, to);
    }
    std::fs::write(&p, text).unwrap();
    p
}

/// The numeric fields of each line of a text file, `#` comments left out.
pub fn number_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            l.split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect()
        })
        .collect()
}
