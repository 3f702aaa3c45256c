//! The smoother re-judges the GNSS fixes (issue 33 item 3,
//! `navsync::rejudge`): a ramp the forward fault monitor follows is
//! excluded from the smoothed solution, which comes within the test's
//! detection limit of the oracle (the same run without the ramp's
//! fixes); a clean run takes one pass and loses no fix.

mod common;

use std::collections::HashMap;
use std::path::Path;

use common::{bin, horizontal_rms, json, run, temp_dir};

/// `navsync fuse --smooth --no-gnss-velocity` (as the integrity bed) of the
/// simulated run's IMU with `gnss` into `out`.
fn fuse(sim: &Path, gnss: &Path, out: &Path) {
    let cfg = std::fs::read_to_string(sim.join("kf-gins.yaml"))
        .unwrap()
        .replace("./imu.txt", &sim.join("imu.txt").display().to_string())
        .replace("./gnss.txt", &gnss.display().to_string());
    std::fs::create_dir_all(out).unwrap();
    let yaml = out.with_extension("yaml");
    std::fs::write(&yaml, cfg).unwrap();
    let (ok, _, err) = run(bin()
        .args(["fuse", "--smooth", "--no-gnss-velocity", "--config"])
        .arg(&yaml)
        .arg("--output")
        .arg(out));
    assert!(ok, "{err}");
}

/// Position lines of a gnss_residuals.txt: time (ms) → (status, reason).
fn decisions(path: &Path) -> HashMap<i64, (String, String)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .filter(|f| f[1] == "position")
        .map(|f| {
            assert_eq!(f.len(), 15, "{f:?}");
            let ms = (f[0].parse::<f64>().unwrap() * 1e3).round() as i64;
            (ms, (f[12].to_string(), f[13].to_string()))
        })
        .collect()
}

fn simulate(dir: &Path) -> std::path::PathBuf {
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--scenario",
            "test-track",
            "--duration",
            "240",
            "--imu-grade",
            "adis16465",
            "--seed",
            "1",
            "--quiet",
            "--output",
        ])
        .arg(&sim));
    assert!(ok, "{err}");
    sim
}

#[test]
fn a_ramp_the_forward_pass_followed_is_excluded_when_smoothed() {
    let dir = temp_dir("ramp");
    let sim = simulate(&dir);
    // A ramp to 1.5 m horizontal over 20 s (slowly building multipath:
    // `navsync faults`), 100 s into the drive.
    let first: f64 = std::fs::read_to_string(sim.join("gnss.txt"))
        .unwrap()
        .lines()
        .find(|l| !l.starts_with('#'))
        .and_then(|l| l.split_whitespace().next()?.parse().ok())
        .unwrap();
    let plan = dir.join("plan.txt");
    std::fs::write(&plan, format!("ramp {:.3} 20 1.2 0.9 0\n", first + 100.0)).unwrap();
    let faulty = dir.join("faulty");
    let (ok, _, err) = run(bin()
        .arg("faults")
        .arg("--gnss")
        .arg(sim.join("gnss.txt"))
        .arg("--plan")
        .arg(&plan)
        .arg("--output")
        .arg(&faulty));
    assert!(ok, "{err}");
    // The labels: time (ms) → offset (m); the oracle leaves them out.
    let labels: HashMap<i64, f64> = std::fs::read_to_string(faulty.join("faults.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<f64> = l
                .split_whitespace()
                .filter_map(|w| w.parse().ok())
                .collect();
            ((f[0] * 1e3).round() as i64, f[2].hypot(f[3]).hypot(f[4]))
        })
        .collect();
    assert!(labels.len() >= 20, "{labels:?}");
    let oracle_gnss = dir.join("gnss-oracle.txt");
    let kept: String = std::fs::read_to_string(faulty.join("gnss.txt"))
        .unwrap()
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .next()
                .and_then(|w| w.parse::<f64>().ok())
                .is_none_or(|t| !labels.contains_key(&((t * 1e3).round() as i64)))
        })
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&oracle_gnss, kept).unwrap();

    let (run_dir, oracle) = (dir.join("run"), dir.join("oracle"));
    fuse(&sim, &faulty.join("gnss.txt"), &run_dir);
    fuse(&sim, &oracle_gnss, &oracle);
    let truth = sim.join("truth.nav");
    let smoothed = horizontal_rms(&truth, &run_dir.join("navresult.nav"), &run_dir);
    let forward = horizontal_rms(&truth, &run_dir.join("forward/navresult.nav"), &dir);
    let smoothed_oracle = horizontal_rms(&truth, &oracle.join("navresult.nav"), &oracle);

    // The smoothed decisions: every ramp fix above the test's detection
    // limit is excluded by the smoother (the forward pass used them).
    // The limit: χ²₃ at 1e-4 (21.1) on a fix of σ 1.8 cm plus the 5 cm
    // multipath floor, d = √(21.1 · (0.018² + 0.05²)) = 0.24 m; with the
    // smoothed σ and the horizontal share of the offset, 0.4 m is beyond it.
    let fwd = decisions(&run_dir.join("forward/gnss_residuals.txt"));
    let sm = decisions(&run_dir.join("gnss_residuals.txt"));
    let mut excluded = 0;
    let mut used_forward = 0;
    for (t, offset) in &labels {
        let (st, reason) = &sm[t];
        assert!(
            !fwd[t].1.starts_with("smoother"),
            "the forward output is the causal pass: {:?}",
            fwd[t]
        );
        if *offset >= 0.4 {
            assert_eq!(
                (st.as_str(), reason.as_str()),
                ("rejected", "smoother-excluded"),
                "ramp fix at {t} ms, {offset:.2} m"
            );
            excluded += 1;
            used_forward += usize::from(fwd[t].0 == "used");
        }
    }
    // The forward monitor cannot see a ramp (docs/integrity.md): the
    // smoother did the work.
    assert!(used_forward * 2 > excluded, "{used_forward} of {excluded}");
    let s = json(&run_dir.join("summary.json"))["stats"].clone();
    assert!(s["gnss_smoother_passes"].as_u64().unwrap() >= 2, "{s}");
    assert!(
        s["gnss_smoother_excluded"].as_u64().unwrap() >= excluded as u64,
        "{s}"
    );

    // The bound: the ramp fixes left in are those under the detection
    // limit d (at most d/1.5 m of the 20 fixes), each pulling the
    // solution by at most d for about a second of the 240 s run: an RMS
    // of at most d·√(n/240) over the oracle's.
    let d = (21.1f64 * (0.018f64.powi(2) + 0.05f64.powi(2))).sqrt();
    let n = (d / 1.5 * 20.0).ceil() + 1.0;
    let bound = smoothed_oracle + d * (n / 240.0).sqrt();
    assert!(
        smoothed <= bound,
        "smoothed {smoothed:.3} m, oracle {smoothed_oracle:.3} m, bound {bound:.3} m (forward {forward:.3} m)"
    );
}

#[test]
fn a_clean_run_is_smoothed_once_and_loses_no_fix() {
    let dir = temp_dir("clean");
    let sim = simulate(&dir);
    let out = dir.join("run");
    fuse(&sim, &sim.join("gnss.txt"), &out);
    let s = json(&out.join("summary.json"))["stats"].clone();
    assert_eq!(s["gnss_smoother_passes"].as_u64(), Some(1), "{s}");
    assert_eq!(s["gnss_smoother_excluded"].as_u64(), Some(0), "{s}");
    assert_eq!(s["gnss_smoother_readmitted"].as_u64(), Some(0), "{s}");
    // The smoothed run's residuals are the forward pass's decisions.
    let fwd = decisions(&out.join("forward/gnss_residuals.txt"));
    let sm = decisions(&out.join("gnss_residuals.txt"));
    assert_eq!(fwd, sm);
}
