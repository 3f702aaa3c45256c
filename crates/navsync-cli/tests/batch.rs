//! `navsync batch`: several drives in parallel, a failing one a row of the
//! table, the same numbers as the drive run alone.

mod common;

use std::path::Path;

use common::{bin, run, temp_dir};

fn simulate(out: &Path, seed: &str) {
    let (ok, _, err) = run(bin().args([
        "simulate",
        "--quiet",
        "--internal-rate",
        "0",
        "--scenario",
        "demo",
        "--duration",
        "90",
        "--seed",
        seed,
        "--output",
        out.to_str().unwrap(),
    ]));
    assert!(ok, "{err}");
}

#[test]
fn batch_runs_every_drive_and_reports_failures_as_rows() {
    let dir = temp_dir("batch");
    let (a, b, bad) = (dir.join("a"), dir.join("b"), dir.join("broken"));
    simulate(&a, "1");
    simulate(&b, "2");
    // A drive whose rig log is cut in its header: its row carries the error.
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::copy(a.join("kf-gins.yaml"), bad.join("kf-gins.yaml")).unwrap();
    std::fs::write(bad.join("rig.csv"), "not a rig log\n").unwrap();
    let out = dir.join("out");
    let (ok, stdout, stderr) = run(bin().args([
        "batch",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        bad.to_str().unwrap(),
        dir.join("missing").to_str().unwrap(),
        "--jobs",
        "2",
        "--no-html",
        "--output",
        out.to_str().unwrap(),
    ]));
    // Two failures: non-zero exit, but every drive has its row.
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("2 of 4 drives failed"), "{stderr}");
    assert!(stdout.contains("4 drives (2 failed)"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("batch.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 5, "{csv}");
    assert!(lines[0].starts_with("drive,ok,verdict,pos_horizontal_rms_m"));
    for (line, name, good) in [
        (lines[1], "a,", true),
        (lines[2], "b,", true),
        (lines[3], "broken,", false),
        (lines[4], "missing,", false),
    ] {
        assert!(line.starts_with(name), "{line}");
        assert_eq!(line.starts_with(&format!("{name}true")), good, "{line}");
    }
    assert!(lines[4].contains("not a folder"), "{}", lines[4]);
    // A good drive: synchronized, fused, scored; the same score as `eval`.
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("batch.json")).unwrap()).unwrap();
    let h = rows[0]["pos_horizontal_rms_m"].as_f64().unwrap();
    assert!(h > 0.0 && h < 0.5, "{h}");
    assert_eq!(rows[0]["sync_mode"], "hw");
    assert!(rows[0]["verdict"].is_string());
    let (ok, _, err) = run(bin().args([
        "eval",
        "--truth",
        a.join("truth.nav").to_str().unwrap(),
        "--nav",
        out.join("a/fused/navresult.nav").to_str().unwrap(),
        "--json",
        dir.join("eval.json").to_str().unwrap(),
    ]));
    assert!(ok, "{err}");
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval.json")).unwrap()).unwrap();
    assert_eq!(e["pos_horizontal_m"]["rms"].as_f64(), Some(h));
    assert!(out.join("a/fused/forward/navresult.nav").is_file());
}

/// Readers and writers inline (one drive, one core, as `--jobs N` and the
/// fleet run them) or on their own threads: the same files, byte for byte.
#[test]
fn inline_and_threaded_io_write_the_same_files() {
    let dir = temp_dir("inline");
    let drive = dir.join("d");
    simulate(&drive, "3");
    // Threads by the environment (as the default), inline by the option.
    for threads in ["1", "0"] {
        let out = dir.join(format!("out-{threads}"));
        let mut cmd = bin();
        cmd.env("NAVSYNC_IO_THREADS", "1").args([
            "batch",
            drive.to_str().unwrap(),
            "--jobs",
            "1",
            "--no-html",
            "--output",
            out.to_str().unwrap(),
        ]);
        if threads == "0" {
            cmd.arg("--single-core");
        }
        let (ok, _, err) = run(&mut cmd);
        assert!(ok, "{err}");
    }
    let mut compared = 0;
    for sub in ["synced", "fused", "fused/forward"] {
        let a = dir.join("out-1/d").join(sub);
        for entry in std::fs::read_dir(&a).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_str().unwrap().to_string();
            // summary.json holds the run's wall time.
            if path.is_dir() || name == "summary.json" {
                continue;
            }
            let b = dir.join("out-0/d").join(sub).join(&name);
            assert!(
                std::fs::read(&path).unwrap() == std::fs::read(&b).unwrap(),
                "{sub}/{name} differs"
            );
            compared += 1;
        }
    }
    // imu.txt, gnss.txt, imu_times.txt, navresult.nav, std.txt, ... of both runs.
    assert!(compared >= 8, "{compared} files compared");
}
