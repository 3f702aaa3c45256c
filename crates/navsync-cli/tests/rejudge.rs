//! The smoother re-judges the GNSS fixes (issue 33 item 3,
//! `navsync::rejudge`): a ramp the forward fault monitor follows is
//! excluded from the smoothed solution, which comes within the test's
//! detection limit of the oracle (the same run without the ramp's
//! fixes); so is a ramp that ends in a gap, for which the monitor opens
//! no episode (found from the step in the smoothed residuals); a clean run
//! takes one pass and loses no fix.

mod common;

use std::collections::HashMap;
use std::path::Path;

use common::{bin, horizontal_rms, json, run, simulate_test_track, temp_dir};

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

/// A 240 s test-track drive with an IMU of `grade`, seed 1.
fn simulate(dir: &Path, grade: &str) -> std::path::PathBuf {
    simulate_at(dir, grade, 1.0)
}

/// [`simulate`] with fixes at `gnss_rate_hz`.
fn simulate_at(dir: &Path, grade: &str, gnss_rate_hz: f64) -> std::path::PathBuf {
    let rate = gnss_rate_hz.to_string();
    simulate_test_track(dir, &["--imu-grade", grade, "--gnss-rate", &rate])
}

/// The first fix's time (s of week) in a gnss.txt.
fn first_fix_sow(gnss: &Path) -> f64 {
    std::fs::read_to_string(gnss)
        .unwrap()
        .lines()
        .find(|l| !l.starts_with('#'))
        .and_then(|l| l.split_whitespace().next()?.parse().ok())
        .unwrap()
}

/// A copy of `gnss` without the fixes whose time (ms) `drop` holds.
fn without(gnss: &Path, out: &Path, drop: impl Fn(i64) -> bool) {
    let kept: String = std::fs::read_to_string(gnss)
        .unwrap()
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .next()
                .and_then(|w| w.parse::<f64>().ok())
                .is_none_or(|t| !drop((t * 1e3).round() as i64))
        })
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(out, kept).unwrap();
}

/// `navsync faults --plan` with one ramp to (1.2, 0.9, 0) m NED over 20 s
/// (slowly building multipath), `at_s` into the simulated drive: the
/// faulty folder and the labels, time (ms) → offset (m).
fn inject_ramp(dir: &Path, sim: &Path, at_s: f64) -> (std::path::PathBuf, HashMap<i64, f64>) {
    let first = first_fix_sow(&sim.join("gnss.txt"));
    let plan = dir.join("plan.txt");
    std::fs::write(&plan, format!("ramp {:.3} 20 1.2 0.9 0\n", first + at_s)).unwrap();
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
    (faulty, labels)
}

/// The test's detection limit for one fix: χ²₃ at 1e-4 (21.1) on a fix of
/// σ 1.8 cm plus the 5 cm multipath floor, √(21.1 · (0.018² + 0.05²)) =
/// 0.24 m.
fn detection_limit_m() -> f64 {
    (21.1f64 * (0.018f64.powi(2) + 0.05f64.powi(2))).sqrt()
}

/// The bound on the smoothed RMS over the oracle's: the ramp fixes left
/// in are those under the detection limit d (at most d/1.5 m of the 20
/// fixes), each pulling the solution by at most d for about a second of
/// the 240 s run: an RMS of at most d·√(n/240) more.
fn ramp_bound_m(smoothed_oracle: f64) -> f64 {
    let d = detection_limit_m();
    let n = (d / 1.5 * 20.0).ceil() + 1.0;
    smoothed_oracle + d * (n / 240.0).sqrt()
}

#[test]
fn a_ramp_the_forward_pass_followed_is_excluded_when_smoothed() {
    let dir = temp_dir("ramp");
    let sim = simulate(&dir, "adis16465");
    // A ramp to 1.5 m horizontal over 20 s, 100 s into the drive; the
    // oracle leaves its fixes out.
    let (faulty, labels) = inject_ramp(&dir, &sim, 100.0);
    let oracle_gnss = dir.join("gnss-oracle.txt");
    without(&faulty.join("gnss.txt"), &oracle_gnss, |ms| {
        labels.contains_key(&ms)
    });

    let (run_dir, oracle) = (dir.join("run"), dir.join("oracle"));
    fuse(&sim, &faulty.join("gnss.txt"), &run_dir);
    fuse(&sim, &oracle_gnss, &oracle);
    let truth = sim.join("truth.nav");
    let smoothed = horizontal_rms(&truth, &run_dir.join("navresult.nav"), &run_dir);
    let forward = horizontal_rms(&truth, &run_dir.join("forward/navresult.nav"), &dir);
    let smoothed_oracle = horizontal_rms(&truth, &oracle.join("navresult.nav"), &oracle);

    // The smoothed decisions: every ramp fix above the test's detection
    // limit (0.24 m; with the smoothed σ and the horizontal share of the
    // offset, 0.4 m is beyond it) is excluded by the smoother (the forward
    // pass used them).
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

    let bound = ramp_bound_m(smoothed_oracle);
    assert!(
        smoothed <= bound,
        "smoothed {smoothed:.3} m, oracle {smoothed_oracle:.3} m, bound {bound:.3} m (forward {forward:.3} m)"
    );
}

#[test]
fn a_clean_run_is_smoothed_once_and_loses_no_fix() {
    let dir = temp_dir("clean");
    let sim = simulate(&dir, "adis16465");
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

#[test]
fn a_ramp_ending_in_a_gap_is_found_from_the_smoothed_residual_step() {
    let dir = temp_dir("gap");
    let sim = simulate(&dir, "adis16465");
    // The ramp of the test above, then no fix for 10 s: the first fixes
    // after the gap are judged alone (no jump test over a gap), so the
    // forward monitor opens no episode of more than one fix at the ramp's
    // end; only the smoothed residuals' step shows it.
    let (faulty, labels) = inject_ramp(&dir, &sim, 100.0);
    let last_ms = *labels.keys().max().unwrap();
    let in_gap = |ms: i64| ms > last_ms && ms <= last_ms + 10_000;
    let gnss = dir.join("gnss-gap.txt");
    without(&faulty.join("gnss.txt"), &gnss, in_gap);
    let oracle_gnss = dir.join("gnss-oracle.txt");
    without(&faulty.join("gnss.txt"), &oracle_gnss, |ms| {
        in_gap(ms) || labels.contains_key(&ms)
    });
    let (run_dir, oracle) = (dir.join("run"), dir.join("oracle"));
    fuse(&sim, &gnss, &run_dir);
    fuse(&sim, &oracle_gnss, &oracle);
    let truth = sim.join("truth.nav");
    let smoothed = horizontal_rms(&truth, &run_dir.join("navresult.nav"), &run_dir);
    let smoothed_oracle = horizontal_rms(&truth, &oracle.join("navresult.nav"), &oracle);

    let fwd = decisions(&run_dir.join("forward/gnss_residuals.txt"));
    let sm = decisions(&run_dir.join("gnss_residuals.txt"));
    // The premise: no episode (a jump, then a run) forward.
    assert!(
        fwd.values().all(|(_, reason)| reason != "run"),
        "the forward monitor opened an episode"
    );
    let mut excluded = 0;
    for (t, offset) in &labels {
        assert_eq!(
            fwd[t].0, "used",
            "ramp fix at {t} ms: the forward pass used it"
        );
        if *offset >= 0.4 {
            assert_eq!(
                (sm[t].0.as_str(), sm[t].1.as_str()),
                ("rejected", "smoother-excluded"),
                "ramp fix at {t} ms, {offset:.2} m"
            );
            excluded += 1;
        }
    }
    assert!(excluded >= 10, "{excluded}");
    let bound = ramp_bound_m(smoothed_oracle);
    assert!(
        smoothed <= bound,
        "smoothed {smoothed:.3} m, oracle {smoothed_oracle:.3} m, bound {bound:.3} m"
    );
}

#[test]
fn a_step_at_the_last_fix_is_reported_not_guessed() {
    let dir = temp_dir("last");
    let sim = simulate(&dir, "adis16465");
    // A 15 m spike on the drive's last fix: with no fix after it, a spike
    // and the end of a ramp the fixes before it followed look alike.
    let gnss = sim.join("gnss.txt");
    let last: f64 = std::fs::read_to_string(&gnss)
        .unwrap()
        .lines()
        .rev()
        .filter(|l| !l.starts_with('#'))
        .find_map(|l| l.split_whitespace().next()?.parse().ok())
        .unwrap();
    let plan = dir.join("plan.txt");
    std::fs::write(&plan, format!("spike {last:.3} 0 12 -9 0\n")).unwrap();
    let faulty = dir.join("faulty");
    let (ok, _, err) = run(bin()
        .arg("faults")
        .arg("--gnss")
        .arg(&gnss)
        .arg("--plan")
        .arg(&plan)
        .arg("--output")
        .arg(&faulty));
    assert!(ok, "{err}");
    let oracle_gnss = dir.join("gnss-oracle.txt");
    let last_ms = (last * 1e3).round() as i64;
    without(&faulty.join("gnss.txt"), &oracle_gnss, |ms| ms == last_ms);
    let (run_dir, oracle) = (dir.join("run"), dir.join("oracle"));
    fuse(&sim, &faulty.join("gnss.txt"), &run_dir);
    fuse(&sim, &oracle_gnss, &oracle);
    let truth = sim.join("truth.nav");
    let smoothed = horizontal_rms(&truth, &run_dir.join("navresult.nav"), &run_dir);
    let smoothed_oracle = horizontal_rms(&truth, &oracle.join("navresult.nav"), &oracle);
    // The fixes before it are not thrown out for it (that once cost
    // 3.1 m), the spike is, and the run says the data cannot tell.
    let sm = decisions(&run_dir.join("gnss_residuals.txt"));
    assert_eq!(sm[&last_ms].0, "rejected", "{:?}", sm[&last_ms]);
    assert!(
        sm.iter()
            .filter(|(t, _)| **t != last_ms)
            .all(|(_, (_, reason))| reason != "smoother-excluded"),
        "fixes before the last were excluded"
    );
    assert!(
        smoothed <= smoothed_oracle + 0.005,
        "smoothed {smoothed:.3} m, oracle {smoothed_oracle:.3} m"
    );
    let summary = std::fs::read_to_string(run_dir.join("summary.json")).unwrap();
    assert!(summary.contains("with no fix after it"), "{summary}");
}

/// A navigation-grade INS drifts millimetres in the seconds a ramp takes to
/// grow past the fixes' noise: the forward monitor finds the ramp's onset
/// against the clean fixes before it, returns to the filter's state after
/// the last of them and runs again without the ramp's fixes
/// (`navsync::fusion` rollback). Every ramp fix past the detection limit
/// is excluded forward, and the forward solution comes within the
/// issue's bar (1.25×) of the oracle's.
#[test]
fn a_navigation_grade_ins_catches_a_ramp_forward() {
    catches_a_ramp_forward("onset", 1.0);
}

/// The same with 10 Hz fixes. The filter's state is stored after a clean
/// fix at most every 0.9 s, so the onset's anchor usually falls between
/// stored states: the rollback returns to the one before it and judges
/// the clean fixes up to the anchor again.
#[test]
fn a_navigation_grade_ins_catches_a_ramp_forward_at_10_hz() {
    catches_a_ramp_forward("onset10", 10.0);
}

fn catches_a_ramp_forward(name: &str, gnss_rate_hz: f64) {
    let dir = temp_dir(name);
    let sim = simulate_at(&dir, "nav", gnss_rate_hz);
    // 160 s in: the onset test is calibrated on at least 120 s of clean
    // fixes first (the filter's σ is optimistic while it settles).
    let (faulty, labels) = inject_ramp(&dir, &sim, 160.0);
    let oracle_gnss = dir.join("gnss-oracle.txt");
    without(&faulty.join("gnss.txt"), &oracle_gnss, |ms| {
        labels.contains_key(&ms)
    });
    let (run_dir, oracle) = (dir.join("run"), dir.join("oracle"));
    fuse(&sim, &faulty.join("gnss.txt"), &run_dir);
    fuse(&sim, &oracle_gnss, &oracle);

    let fwd = decisions(&run_dir.join("forward/gnss_residuals.txt"));
    for (t, offset) in &labels {
        let (st, reason) = &fwd[t];
        if *offset >= detection_limit_m() {
            assert_eq!(
                st, "rejected",
                "ramp fix at {t} ms, {offset:.2} m: {reason}"
            );
            assert!(reason == "ramp" || reason == "run", "{t} ms: {reason}");
        }
    }
    // One onset opens the episode (its first fix may be a clean one just
    // before the ramp: the fixes after the anchor rolled back to).
    let onsets = fwd.values().filter(|(_, reason)| reason == "ramp").count();
    assert_eq!(onsets, 1, "one onset opens the episode");
    let episodes = json(&run_dir.join("summary.json"))["stats"]["gnss_fault_episodes"].clone();
    assert!(
        episodes
            .as_array()
            .is_some_and(|e| e.iter().any(|e| e["class"] == "ramp")),
        "{episodes}"
    );
    let truth = sim.join("truth.nav");
    let forward = horizontal_rms(&truth, &run_dir.join("forward/navresult.nav"), &dir);
    let forward_oracle = horizontal_rms(&truth, &oracle.join("forward/navresult.nav"), &oracle);
    assert!(
        forward <= 1.25 * forward_oracle,
        "forward {forward:.3} m, oracle {forward_oracle:.3} m"
    );
}
