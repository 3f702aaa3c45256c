//! `navsync faults` end to end: the labelled files, determinism, the
//! faulty file through `fuse` (every label's time is a fix the filter
//! weighed, so the integrity bed can join labels and residuals), and the
//! refusals.

mod common;

use common::{bin, json, run, temp_dir};

#[test]
fn faults_are_labelled_reproducible_and_fused() {
    let dir = temp_dir("faults");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--scenario",
            "test-track",
            "--duration",
            "240",
            "--seed",
            "1",
            "--quiet",
            "--output",
        ])
        .arg(&sim));
    assert!(ok, "{err}");
    let faulty = |out: &std::path::Path, seed: &str| {
        let (ok, stdout, err) = run(bin()
            .arg("faults")
            .arg("--gnss")
            .arg(sim.join("gnss.txt"))
            .args(["--count", "4", "--seed", seed, "--output"])
            .arg(out));
        assert!(ok, "{err}");
        stdout
    };
    let (a, b, c) = (dir.join("a"), dir.join("b"), dir.join("c"));
    let said = faulty(&a, "5");
    faulty(&b, "5");
    faulty(&c, "6");
    assert!(said.contains("4 episodes"), "{said}");
    let read = |p: &std::path::Path| std::fs::read_to_string(p).unwrap();
    assert_eq!(read(&a.join("gnss.txt")), read(&b.join("gnss.txt")));
    assert_eq!(read(&a.join("faults.txt")), read(&b.join("faults.txt")));
    assert_ne!(read(&a.join("faults.txt")), read(&c.join("faults.txt")));
    let labels: Vec<Vec<String>> = read(&a.join("faults.txt"))
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(' ').map(str::to_string).collect())
        .collect();
    let j = json(&a.join("faults.json"));
    assert_eq!(j["faulty_fixes"].as_u64().unwrap() as usize, labels.len());
    assert_eq!(j["episodes"].as_array().unwrap().len(), 4);
    assert_eq!(j["options"]["ranges"]["spike_m"][1].as_f64(), Some(50.0));
    // Fused: the faulty file is a valid GNSS file and every label is a
    // fix the filter weighed; the 15–50 m spike is not used as it is.
    let cfg = read(&sim.join("kf-gins.yaml"))
        .replace("./imu.txt", &sim.join("imu.txt").display().to_string());
    std::fs::write(a.join("kf-gins.yaml"), cfg).unwrap();
    let (ok, _, err) = run(bin()
        .arg("fuse")
        .arg("--config")
        .arg(a.join("kf-gins.yaml"))
        .arg("--output")
        .arg(a.join("fused")));
    assert!(ok, "{err}");
    let res = read(&a.join("fused/gnss_residuals.txt"));
    let status: std::collections::HashMap<String, (String, String)> = res
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .filter(|f| f[1] == "position")
        .map(|f| {
            (
                format!("{:.3}", f[0].parse::<f64>().unwrap()),
                (f[12].to_string(), f[13].to_string()),
            )
        })
        .collect();
    // A stale repeat is refused before weighing (the filter's stale
    // check: counted in summary.json, a `rejected` line with reason
    // `stale` in the residuals).
    let refused_stale = json(&a.join("fused/summary.json"))["stats"]["gnss_fixes_stale"]
        .as_u64()
        .unwrap();
    let mut stale_lines = 0;
    for l in &labels {
        let key = format!("{:.3}", l[0].parse::<f64>().unwrap());
        let Some((st, reason)) = status.get(&key) else {
            panic!("label {l:?} not among the fused fixes");
        };
        if reason == "stale" {
            assert_eq!(l[1], "stale", "{l:?}");
            assert_eq!(st, "rejected", "{l:?}");
            stale_lines += 1;
        }
        if l[1] == "spike" {
            assert_ne!(st, "used", "{l:?}");
        }
    }
    assert_eq!(stale_lines, refused_stale);
}

#[test]
fn faults_refuse_bad_requests() {
    let dir = temp_dir("faults-bad");
    let gnss = dir.join("gnss.txt");
    let mut text = String::new();
    for k in 0..100 {
        text += &format!("{}.0 30.5 114.{:04} 20.0 0.01 0.01 0.03\n", 1000 + k, k);
    }
    std::fs::write(&gnss, text).unwrap();
    let (ok, _, err) = run(bin()
        .arg("faults")
        .arg("--gnss")
        .arg(&gnss)
        .arg("--output")
        .arg(&*dir));
    assert!(!ok && err.contains("would overwrite the input"), "{err}");
    assert!(gnss.exists(), "the input is left where it was");
    let (ok, _, err) = run(bin()
        .arg("faults")
        .arg("--gnss")
        .arg(&gnss)
        .args(["--count", "8", "--output"])
        .arg(dir.join("out")));
    assert!(
        !ok && err.contains("gnss.txt: no room for episode"),
        "{err}"
    );
    let (ok, _, err) = run(bin()
        .arg("faults")
        .arg("--gnss")
        .arg(&gnss)
        .args(["--classes", "spike,jump", "--output"])
        .arg(dir.join("out")));
    assert!(!ok && err.contains("unknown fault class 'jump'"), "{err}");
}
