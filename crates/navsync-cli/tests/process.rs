//! `navsync init` and `navsync process`: a whole simulated drive from its
//! raw rig log and a sensor sheet, and the bad inputs a new user meets.

mod common;

use std::path::{Path, PathBuf};

use common::{adis16465_sheet, bin, horizontal_rms, json, run, simulate_adis16465, temp_dir};

/// Simulates a short drive (ADIS16465, seed 3) and returns its folder.
fn simulate(dir: &Path, scenario: &str, duration_s: &str) -> PathBuf {
    simulate_adis16465(dir, scenario, duration_s, &[])
}

/// `navsync process RAW --sensor SENSOR --output OUT EXTRA…`.
fn process(raw: &Path, sensor: &Path, out: &Path, extra: &[&str]) -> (bool, String, String) {
    run(bin()
        .args(["process", raw.to_str().unwrap(), "--sensor"])
        .arg(sensor)
        .arg("--output")
        .arg(out)
        .args(extra))
}

/// `navsync init --preset adis16465`, with the simulator's lever arm.
fn sheet(dir: &Path) -> PathBuf {
    adis16465_sheet(dir, "sensor.yaml", &[])
}

#[test]
fn init_then_process_a_simulated_rig_log() {
    let d = temp_dir("sim-drive");
    let sim = simulate(&d, "test-track", "400");
    let sensor = sheet(&d);
    let out = d.join("out");
    let (ok, stdout, err) = process(
        &sim.join("rig.csv"),
        &sensor,
        &out,
        &["--truth", sim.join("truth.nav").to_str().unwrap()],
    );
    assert!(ok, "{stdout}{err}");
    assert!(stdout.contains("rig log (rig-log v1)"), "{stdout}");
    for f in [
        "sync/imu.txt",
        "sync/gnss.txt",
        "sync/sync_report.json",
        "fuse/navresult.nav",
        "fuse/std.txt",
        "fuse/summary.json",
        "fuse/forward/navresult.nav",
        "fuse/probe.json",
        "report.html",
        "process.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing:\n{stdout}{err}");
    }
    // The consistency probe on a synchronized drive: no offset beyond its σ.
    let probe = json(&out.join("fuse/probe.json"));
    let (o, sd) = (
        probe["time_offset_s"].as_f64().unwrap(),
        probe["time_offset_sd_s"].as_f64().unwrap(),
    );
    assert!(
        sd > 0.0 && sd < 0.005 && o.abs() < 4.0 * sd,
        "probe {probe}"
    );
    let p = json(&out.join("process.json"));
    assert!(p["alignment"]["method"].is_string(), "{p}");
    let rms = p["eval"]["pos_horizontal_m"]["rms"].as_f64().unwrap();
    // Bound: the fixes' own horizontal σ (RTK-like, 1.8 cm per axis here):
    // a smoothed solution through 1 Hz fixes must not be worse than the
    // fixes themselves.
    let sd_h = 0.018f64.hypot(0.018);
    assert!(rms < sd_h, "horizontal RMS {rms} m ≥ fix σ {sd_h} m");
    // And close to a run that knew the initial state (the simulator's
    // configuration, from truth), forward filter against forward filter.
    let (ok, _, err) = run(bin().args([
        "fuse",
        "--config",
        sim.join("kf-gins.yaml").to_str().unwrap(),
        "--output",
        d.join("truth-init").to_str().unwrap(),
    ]));
    assert!(ok, "{err}");
    let from_truth = horizontal_rms(
        &sim.join("truth.nav"),
        &d.join("truth-init/navresult.nav"),
        &d,
    );
    let aligned = horizontal_rms(
        &sim.join("truth.nav"),
        &out.join("fuse/forward/navresult.nav"),
        &d,
    );
    assert!(
        aligned < 1.5 * from_truth + 0.005,
        "aligned forward {aligned} m vs truth-initialised {from_truth} m"
    );
}

#[test]
fn init_refuses_to_overwrite() {
    let d = temp_dir("init-overwrite");
    let p = d.join("sensor.yaml");
    std::fs::write(&p, "mine").unwrap();
    let (ok, _, err) = run(bin().args(["init", "--output", p.to_str().unwrap()]));
    assert!(
        !ok && err.contains("exists") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&p).unwrap(), "mine");
    let (ok, _, err) = run(bin().args(["init", "--output", p.to_str().unwrap(), "--force"]));
    assert!(ok, "{err}");
    let (ok, _, err) = run(bin().args([
        "init",
        "--output",
        p.to_str().unwrap(),
        "--force",
        "--preset",
        "mems",
    ]));
    assert!(!ok && err.contains("unknown IMU preset 'mems'"), "{err}");
}

/// A process run expected to fail: its stderr.
fn process_fails(raw: &[&Path], sensor: &Path, out: &Path) -> String {
    let mut cmd = bin();
    cmd.arg("process");
    for r in raw {
        cmd.arg(r);
    }
    cmd.args([
        "--sensor",
        sensor.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    let (ok, stdout, err) = run(&mut cmd);
    assert!(!ok, "should fail:\n{stdout}{err}");
    err
}

#[test]
fn sensor_sheet_with_misspelled_or_missing_key() {
    let d = temp_dir("bad-sheet");
    let sensor = sheet(&d);
    let text = std::fs::read_to_string(&sensor).unwrap();
    let rig = d.join("rig.csv");
    std::fs::write(&rig, "# rig-log v1\n").unwrap();

    let bad = d.join("misspelled.yaml");
    std::fs::write(&bad, text.replace("mount_deg:", "mount_degs:")).unwrap();
    let line = text
        .lines()
        .position(|l| l.starts_with("mount_deg:"))
        .unwrap()
        + 1;
    let err = process_fails(&[&rig], &bad, &d.join("o1"));
    assert!(
        err.contains(&format!("misspelled.yaml:{line}:"))
            && err.contains("unknown field 'mount_degs'")
            && err.contains("mount_deg,"),
        "{err}"
    );

    let bad = d.join("missing.yaml");
    let without: String = text
        .lines()
        .filter(|l| !l.starts_with("antenna_lever_m"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&bad, without).unwrap();
    let err = process_fails(&[&rig], &bad, &d.join("o2"));
    assert!(
        err.contains("missing.yaml") && err.contains("missing field 'antenna_lever_m'"),
        "{err}"
    );
}

#[test]
fn drive_that_never_moves_says_heading_is_unobservable() {
    let d = temp_dir("static");
    let sim = simulate(&d, "static", "60");
    let sensor = sheet(&d);
    let out = d.join("out");
    let (ok, stdout, err) = process(&sim.join("rig.csv"), &sensor, &out, &["--no-smooth"]);
    assert!(ok, "{stdout}{err}");
    assert!(err.contains("heading is unobservable"), "{err}");
    // No reference: the report judges the run from its own statistics.
    assert!(out.join("report.html").is_file(), "{stdout}{err}");
    // The GNSS fixes agree with the solution once the lever arm's unknown
    // direction is in the position σ: none rejected.
    assert!(!err.contains("rejected"), "{err}");
    assert!(out.join("fuse/navresult.nav").is_file());
    // The heading σ written with the solution stays large (std.txt: sow,
    // position, velocity, attitude σ in deg).
    let std = std::fs::read_to_string(out.join("fuse/std.txt")).unwrap();
    let last = std.lines().last().unwrap();
    let yaw_sd: f64 = last.split_whitespace().nth(9).unwrap().parse().unwrap();
    assert!(yaw_sd >= 179.0, "yaw σ {yaw_sd}° at the end: {last}");
    // The probe's lever-arm states are held with the heading (C_bⁿ l turns
    // with a heading the filter does not have): the sheet's value is kept,
    // observed on no axis.
    let probe = json(&out.join("fuse/probe.json"));
    let l = &probe["lever_arm"];
    for k in 0..3 {
        assert_eq!(l["estimate_m"][k], l["sheet_m"][k], "{probe}");
        assert_eq!(l["observed"][k], false, "{probe}");
    }
    let p = json(&out.join("process.json"));
    assert_eq!(p["alignment"]["method"], "no-motion", "{p}");
}

#[test]
fn drive_without_gnss_and_unknown_files_are_refused() {
    let d = temp_dir("no-gnss");
    let sim = simulate(&d, "test-track", "30");
    let sensor = sheet(&d);
    let rig = std::fs::read_to_string(sim.join("rig.csv")).unwrap();
    let no_gnss = d.join("no-gnss.csv");
    let kept: String = rig
        .lines()
        .filter(|l| !l.starts_with("gnss,"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&no_gnss, kept).unwrap();
    let err = process_fails(&[&no_gnss], &sensor, &d.join("o1"));
    // With 1PPS, sync stops first (pulses cannot be labelled without
    // fixes); without, process does: either names the file and the cause.
    assert!(
        err.contains("no-gnss.csv")
            && (err.contains("no GNSS fix") || err.contains("no gnss messages")),
        "{err}"
    );
    // The same log without its 1PPS lines (software sync).
    let no_pps = d.join("no-gnss-no-pps.csv");
    let kept: String = rig
        .lines()
        .filter(|l| !l.starts_with("gnss,") && !l.starts_with("pps,"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&no_pps, kept).unwrap();
    let err = process_fails(&[&no_pps], &sensor, &d.join("o1b"));
    assert!(
        err.contains("no-gnss-no-pps.csv") && err.to_lowercase().contains("gnss"),
        "{err}"
    );

    // An IMU log alone: no GNSS log among the inputs.
    let imu_csv = d.join("imu.csv");
    std::fs::write(
        &imu_csv,
        "0.000 0.01 0 0 0.1 0 -9.8\n0.005 0.01 0 0 0.1 0 -9.8\n0.010 0.01 0 0 0.1 0 -9.8\n",
    )
    .unwrap();
    let err = process_fails(&[&imu_csv], &sensor, &d.join("o2"));
    assert!(err.contains("no GNSS log among the inputs"), "{err}");

    let junk = d.join("notes.txt");
    std::fs::write(&junk, "my drive on tuesday\nit rained\n").unwrap();
    let err = process_fails(&[&junk, &imu_csv], &sensor, &d.join("o3"));
    assert!(
        err.contains("notes.txt") && err.contains("unknown file type") && err.contains("rig log"),
        "{err}"
    );
}

/// A rate CSV (`time gyro accel`) from the simulator's KF-GINS increments:
/// rates = increment / interval, stamped mid-interval at `time(GPS sow)`.
fn rate_csv(imu_txt: &Path, out: &Path, time: impl Fn(f64) -> f64) {
    let mut text = String::from("# time_s gx gy gz ax ay az\n");
    let mut prev: Option<f64> = None;
    for line in std::fs::read_to_string(imu_txt).unwrap().lines() {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect();
        if let Some(p) = prev {
            let dt = v[0] - p;
            text += &format!("{:.6}", time(v[0] - 0.5 * dt));
            for x in &v[1..7] {
                text += &format!(" {:.9e}", x / dt);
            }
            text.push('\n');
        }
        prev = Some(v[0]);
    }
    std::fs::write(out, text).unwrap();
}

/// `process` on GNSS fixes + a rate CSV: (stdout + stderr, process.json) or
/// the failure's stderr.
fn process_rate_csv(
    sim: &Path,
    imu_csv: &Path,
    sensor: &Path,
    out: &Path,
) -> Result<serde_json::Value, String> {
    let (ok, stdout, err) = run(bin().args([
        "process",
        sim.join("gnss.txt").to_str().unwrap(),
        imu_csv.to_str().unwrap(),
        "--sensor",
        sensor.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "--no-smooth",
        "--truth",
        sim.join("truth.nav").to_str().unwrap(),
    ]));
    if ok {
        Ok(json(&out.join("process.json")))
    } else {
        Err(format!("{stdout}{err}"))
    }
}

#[test]
fn imu_on_an_unknown_clock_is_put_on_gps_time_from_the_motion() {
    let d = temp_dir("any-clock");
    let sim = simulate(&d, "test-track", "180");
    let sensor = sheet(&d);
    let rms = |p: &serde_json::Value| p["eval"]["pos_horizontal_m"]["rms"].as_f64().unwrap();
    // The reference: the IMU on GPS time (checked by the motion, kept).
    let csv = d.join("imu-gps.csv");
    rate_csv(&sim.join("imu.txt"), &csv, |t| t);
    let reference = process_rate_csv(&sim, &csv, &sensor, &d.join("o-gps")).unwrap();
    assert_eq!(reference["time_offset_estimated"], false, "{reference}");
    let kept = reference["notes"].to_string();
    assert!(kept.contains("GPS time within"), "{kept}");
    // An hour ahead (no overlap), and Unix (UTC) seconds with a host clock
    // 0.2371 s ahead (GPS week 2300; GPS − UTC = 18 s).
    let unix = |t: f64| 315_964_800.0 + 2300.0 * 604_800.0 + t - 18.0 + 0.2371;
    for (name, clock, truth_s) in [
        ("1h", &(|t: f64| t + 3600.0) as &dyn Fn(f64) -> f64, -3600.0),
        ("unix", &unix, -(315_964_800.0 - 18.0 + 0.2371)),
    ] {
        let csv = d.join(format!("imu-{name}.csv"));
        rate_csv(&sim.join("imu.txt"), &csv, clock);
        let p = process_rate_csv(&sim, &csv, &sensor, &d.join(format!("o-{name}")))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = &p["imu_clock_search"];
        // Offset on the shifted axis, plus the steps before it.
        let notes = p["notes"].to_string();
        let found = notes
            .split("GPS = IMU time + ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|x| x.parse::<f64>().ok())
            .unwrap_or_else(|| panic!("{name}: no offset in the notes: {notes}"));
        assert!(
            (found - truth_s).abs() < 0.010,
            "{name}: found {found} s, truth {truth_s} s: {s}"
        );
        assert!(s["sd_s"].as_f64().unwrap() < 0.05, "{name}: {s}");
        assert_eq!(p["time_offset_estimated"], true, "{name}");
        assert_eq!(
            name == "unix",
            notes.contains("Unix (UTC) seconds"),
            "{notes}"
        );
        assert!(
            rms(&p) <= 1.2 * rms(&reference),
            "{name}: horizontal RMS {} m vs {} m on GPS time",
            rms(&p),
            rms(&reference)
        );
    }
}

#[test]
fn imu_on_an_unknown_clock_on_a_straight_road_is_refused() {
    let d = temp_dir("any-clock-straight");
    let toml = d.join("straight.toml");
    std::fs::write(
        &toml,
        "[[segments]]\nkind = \"static\"\nduration_s = 10\n\n[[segments]]\nkind = \"accelerate\"\nspeed_mps = 12\n\n\
         [[segments]]\nkind = \"cruise\"\nduration_s = 110\n",
    )
    .unwrap();
    let sim = simulate(&d, toml.to_str().unwrap(), "120");
    let sensor = sheet(&d);
    let csv = d.join("imu.csv");
    rate_csv(&sim.join("imu.txt"), &csv, |t| t + 3600.0);
    let err = process_rate_csv(&sim, &csv, &sensor, &d.join("o")).unwrap_err();
    assert!(
        err.contains("no turns")
            && err.contains("Drive a few turns")
            && err.contains("--imu-time-offset-s"),
        "{err}"
    );
}

/// A sheet left with its zero antenna lever arm (the simulator's antenna
/// is 1.3 m from the IMU): warned at the start, and the verdict is not
/// "good" and names the lever arm (issue 34).
#[test]
fn a_zero_lever_arm_is_warned_and_not_good() {
    let d = temp_dir("zero-lever");
    let sim = simulate(&d, "test-track", "120");
    let p = d.join("sensor.yaml");
    let (ok, _, err) = run(bin().args([
        "init",
        "--preset",
        "adis16465",
        "--output",
        p.to_str().unwrap(),
    ]));
    assert!(ok, "{err}");
    let out = d.join("out");
    let (ok, stdout, err) = process(&sim.join("rig.csv"), &p, &out, &[]);
    assert!(ok, "{stdout}{err}");
    assert!(
        err.contains("WARNING") && err.contains("antenna lever arm is [0, 0, 0]"),
        "{err}"
    );
    let verdict = stdout
        .lines()
        .find_map(|l| l.split_once("verdict: ").map(|(_, v)| v.trim().to_string()))
        .unwrap_or_default();
    assert!(
        !verdict.is_empty() && verdict != "good",
        "verdict {verdict:?}\n{stdout}"
    );
    assert!(
        stdout.contains("likely cause: antenna lever arm"),
        "{stdout}"
    );
    let w = json(&out.join("process.json"));
    assert!(
        w["warnings"].as_array().is_some_and(|a| a
            .iter()
            .any(|x| x.as_str().is_some_and(|s| s.contains("lever arm")))),
        "{w}"
    );
}

/// GNSS tags 20 ms late on a drive synchronized otherwise, the sheet
/// right but for the offset: the innovations of a MEMS filter hardly show
/// it (its gain absorbs it), the consistency probe, with the offset as a
/// state, finds it, and the verdict is not good and names it.
#[test]
fn late_gnss_tags_are_found_by_the_consistency_probe() {
    let d = temp_dir("late-tags");
    let late = simulate_adis16465(
        &d,
        "test-track",
        "300",
        &["--set", "gnss.time_offset_s=0.02"],
    );
    let sensor = sheet(&d);
    let out = d.join("out");
    let (ok, stdout, err) = process(&late.join("rig.csv"), &sensor, &out, &[]);
    assert!(ok, "{stdout}{err}");
    let probe = json(&out.join("fuse/probe.json"));
    let (o, sd) = (
        probe["time_offset_s"].as_f64().unwrap(),
        probe["time_offset_sd_s"].as_f64().unwrap(),
    );
    // Within 4σ of the truth (and at least 1 ms: the sync stage's own
    // sample-level stamping).
    assert!((o - 0.02).abs() < (4.0 * sd).max(0.001), "probe {probe}");
    assert!(stdout.contains("consistency probe"), "{stdout}");
    let verdict = stdout
        .lines()
        .find_map(|l| l.split_once("verdict: ").map(|(_, v)| v.trim().to_string()))
        .unwrap_or_default();
    assert!(verdict == "poor", "verdict {verdict:?}\n{stdout}");
    assert!(
        stdout.contains("likely cause: GNSS time offset"),
        "{stdout}"
    );
    // --no-probe: no probe.json, the run otherwise the same.
    let out2 = d.join("out2");
    let (ok, stdout, err) = process(&late.join("rig.csv"), &sensor, &out2, &["--no-probe"]);
    assert!(ok, "{stdout}{err}");
    assert!(!out2.join("fuse/probe.json").exists());
}
