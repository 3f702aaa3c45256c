//! End-to-end tests of the `navsync` binary: a small generated data set
//! through `fuse` and `eval`, and the bad-input cases of issue 2 as a user
//! meets them (message naming the file/line/key, non-zero exit, no panic).

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::{bin, run, temp_dir};
use navsync::earth::{Geodetic, gravity, omega_ie_n};

const LAT: f64 = 30.5;
const LON: f64 = 114.3;
const H: f64 = 20.0;

/// A level IMU at rest facing north for `secs`: exact increments at 200 Hz,
/// 1 Hz GNSS fixes, a KF-GINS config and a truth file.
fn write_static_set(dir: &Path, secs: usize) -> PathBuf {
    let p = Geodetic::from_deg(LAT, LON, H);
    let (s, c) = p.lat_rad.sin_cos();
    let w = omega_ie_n(s, c);
    let g = gravity(s, H);
    let dt = 0.005;
    let mut imu = String::new();
    let mut truth = String::new();
    for k in 1..=secs * 200 {
        let t = 1000.0 + k as f64 * dt;
        // Body = NED here: ω_ib^b = ω_ie^n, f^b = [0, 0, −g].
        writeln!(
            imu,
            "{t:.3} {:e} {:e} {:e} 0 0 {:e}",
            w.x * dt,
            w.y * dt,
            w.z * dt,
            -g * dt
        )
        .unwrap();
        writeln!(truth, "2100 {t:.3} {LAT} {LON} {H} 0 0 0 0 0 0").unwrap();
    }
    std::fs::write(dir.join("imu.txt"), imu).unwrap();
    std::fs::write(dir.join("truth.nav"), truth).unwrap();
    let mut gnss = String::new();
    for k in 1..secs {
        writeln!(
            gnss,
            "{:.3} {LAT} {LON} {H} 0.02 0.02 0.03",
            1000.0 + k as f64
        )
        .unwrap();
    }
    std::fs::write(dir.join("gnss.txt"), gnss).unwrap();
    let cfg = format!(
        "imupath: \"{0}/imu.txt\"\ngnsspath: \"{0}/gnss.txt\"\noutputpath: \"{0}/out\"\nimudatalen: 7\nimudatarate: 200\n\
         starttime: 1000.005\nendtime: -1\ninitpos: [ {LAT}, {LON}, {H} ]\ninitvel: [ 0, 0, 0 ]\ninitatt: [ 0, 0, 0 ]\n\
         initgyrbias: [ 0, 0, 0 ]\ninitaccbias: [ 0, 0, 0 ]\ninitgyrscale: [ 0, 0, 0 ]\ninitaccscale: [ 0, 0, 0 ]\n\
         initposstd: [ 0.1, 0.1, 0.1 ]\ninitvelstd: [ 0.05, 0.05, 0.05 ]\ninitattstd: [ 0.1, 0.1, 0.5 ]\n\
         imunoise:\n  arw: [ 0.15, 0.15, 0.15 ]\n  vrw: [ 0.04, 0.04, 0.04 ]\n  gbstd: [ 2, 2, 2 ]\n  abstd: [ 3.6, 3.6, 3.6 ]\n  gsstd: \
         [ 500, 500, 500 ]\n  asstd: [ 500, 500, 500 ]\n  corrtime: 1.0\nantlever: [ 0, 0, 0 ]\n",
        dir.display()
    );
    let path = dir.join("kf-gins.yaml");
    std::fs::write(&path, cfg).unwrap();
    path
}

#[test]
fn fuse_and_eval_a_static_set() {
    let dir = temp_dir("static");
    let cfg = write_static_set(&dir, 30);
    let (ok, out, err) = run(bin().args(["fuse", "--config"]).arg(&cfg));
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("29 used"), "{out}");
    for f in ["navresult.nav", "imu_err.txt", "std.txt", "summary.json"] {
        assert!(dir.join("out").join(f).exists(), "{f} missing");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["stats"]["imu_samples"], 5999);
    let (ok, out, err) = run(bin()
        .args(["eval", "--truth"])
        .arg(dir.join("truth.nav"))
        .arg("--nav")
        .arg(dir.join("out/navresult.nav"))
        .arg("--json")
        .arg(dir.join("eval.json")));
    assert!(ok, "{err}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval.json")).unwrap()).unwrap();
    // At rest with exact increments and 2 cm fixes the solution stays within
    // a few centimetres (the fixes' noise level; these fixes are exact).
    let rms = report["pos_3d_m"]["rms"].as_f64().unwrap();
    assert!(rms < 0.01, "3D RMS {rms}\n{out}");
    assert_eq!(report["epochs_compared"], 5999);
}

#[test]
fn bad_inputs_give_clear_errors() {
    let dir = temp_dir("bad");
    let cfg = write_static_set(&dir, 5);
    let cfg_text = std::fs::read_to_string(&cfg).unwrap();

    // Settings the engine cannot take: a huge interpolation order (it
    // once overflowed a buffer's capacity and panicked), crossed robust
    // thresholds, a non-positive correlated-error time.
    for (args, want) in [
        (
            &["--output-at", "times.txt", "--interp-n", "1000000000000"][..],
            "invalid value '1000000000000' for '--interp-n <INTERP_N>': 1000000000000 is not in 0..=8",
        ),
        (&["--robust-k0", "5", "--robust-k1", "3"][..], "0 < k0 < k1"),
        (
            &["--gnss-gm-sd", "0.01,0.01,0.02", "--gnss-gm-time", "0"][..],
            "'--gnss-gm-time <S>': out of range; expected a number in [0.001, 1000000] s",
        ),
        (
            &["--accel-misalignment", "30"][..],
            "'--accel-misalignment <SD_DEG>': out of range; expected a number in [0, 10] deg",
        ),
    ] {
        let (ok, _, err) = run(bin().args(["fuse", "--config"]).arg(&cfg).args(args));
        assert!(!ok && err.contains(want), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }

    // A path that does not exist.
    let (ok, _, err) = run(bin().args(["fuse", "--config", "/no/such/kf-gins.yaml"]));
    assert!(!ok && err.contains("/no/such/kf-gins.yaml"), "{err}");

    // A misspelled key.
    let bad = dir.join("misspelled.yaml");
    std::fs::write(&bad, cfg_text.replace("initvel:", "initvell:")).unwrap();
    let (ok, _, err) = run(bin().args(["fuse", "--config"]).arg(&bad));
    assert!(
        !ok && err.contains("missing key 'initvel'") && err.contains("initvell"),
        "{err}"
    );

    // An IMU path that does not exist.
    let bad = dir.join("nopath.yaml");
    std::fs::write(&bad, cfg_text.replace("/imu.txt", "/missing-imu.txt")).unwrap();
    let (ok, _, err) = run(bin().args(["fuse", "--config"]).arg(&bad));
    assert!(!ok && err.contains("missing-imu.txt"), "{err}");

    // An empty IMU file.
    std::fs::write(dir.join("empty.txt"), "").unwrap();
    let bad = dir.join("empty.yaml");
    std::fs::write(&bad, cfg_text.replace("/imu.txt", "/empty.txt")).unwrap();
    let (ok, _, err) = run(bin().args(["fuse", "--config"]).arg(&bad));
    assert!(
        !ok && err.contains("empty.txt") && err.contains("no IMU records"),
        "{err}"
    );

    // Bad lines are reported with file and line and skipped; the run goes on.
    let imu = std::fs::read_to_string(dir.join("imu.txt")).unwrap();
    let mut lines: Vec<String> = imu.lines().map(String::from).collect();
    lines[10] = "1000.055 0 0".into(); // truncated
    lines[20] = lines[20].replacen(" 0 0 ", " zero 0 ", 1); // non-numeric
    lines[30] = lines[30].replacen(" 0 0 ", " NaN 0 ", 1); // NaN
    lines[40] = lines[39].clone(); // duplicate epoch
    lines[50] = "1000.100 0 0 0 0 0 -0.049".into(); // time going backwards
    std::fs::write(dir.join("imu.txt"), lines.join("\n")).unwrap();
    let mut gnss = std::fs::read_to_string(dir.join("gnss.txt")).unwrap();
    gnss = gnss.replacen("0.02 0.02 0.03", "0.0 0.02 0.03", 1); // GNSS std of 0
    std::fs::write(dir.join("gnss.txt"), gnss).unwrap();
    let (ok, out, err) = run(bin().args(["fuse", "--config"]).arg(&cfg));
    assert!(ok, "{out}\n{err}");
    for want in [
        "imu.txt:11: expected 7 fields",
        "imu.txt:21: field",
        "imu.txt:31: field",
        "imu.txt:41: duplicate epoch",
        "imu.txt:51: time goes backwards",
        "gnss.txt:1: position standard deviation",
    ] {
        assert!(err.contains(want), "missing '{want}' in:\n{err}");
    }
    assert!(!err.contains("panicked"));
}

#[test]
fn time_offset_is_found_and_held_through_a_standstill() {
    // docs/offset/standstill.toml: manoeuvres, a 60 s stop (199.5–259.5 s
    // after the start), more driving; GNSS time tags 50 ms late.
    let dir = temp_dir("standstill");
    let scn = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/offset/standstill.toml");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--internal-rate", "0", "--scenario"])
        .arg(&scn)
        .arg("--output")
        .arg(&sim));
    assert!(ok, "{err}");
    let (ok, out, err) = run(bin()
        .args(["fuse", "--estimate-time-offset", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(dir.join("out")));
    assert!(ok, "{out}\n{err}");
    let text = std::fs::read_to_string(dir.join("out/time_offset.txt")).unwrap();
    let rows: Vec<[f64; 3]> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0] - 100_000.0, v[1], v[2]]
        })
        .collect();
    // While standing (after the braking settles) the estimate may not move
    // by 0.1 ms: it is unobservable there.
    let still: Vec<f64> = rows
        .iter()
        .filter(|r| (202.0..259.5).contains(&r[0]))
        .map(|r| r[1])
        .collect();
    assert!(still.len() > 100);
    let moved = still.iter().cloned().fold(f64::MIN, f64::max)
        - still.iter().cloned().fold(f64::MAX, f64::min);
    assert!(moved < 1e-4, "moved {moved} s during the standstill");
    // And it was found: within 3σ of the true 50 ms, σ below 2 ms.
    let [_, est, sd] = *rows.last().unwrap();
    assert!(sd < 2e-3 && (est - 0.05).abs() < 3.0 * sd, "{est} ± {sd}");
}

#[test]
fn simulation_is_deterministic_and_faults_use_their_own_streams() {
    let dir = temp_dir("simdet");
    let sim = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let (ok, _, err) = run(bin()
            .args([
                "simulate",
                "--quiet",
                "--scenario",
                "urban",
                "--duration",
                "60",
            ])
            .args(["--seed", "3", "--output"])
            .arg(&out)
            .args(extra));
        assert!(ok, "{err}");
        out
    };
    let read = |d: &Path, f: &str| std::fs::read_to_string(d.join(f)).unwrap();
    let a = sim("a", &[]);
    let b = sim("b", &[]);
    for f in [
        "imu.txt",
        "gnss.txt",
        "truth.nav",
        "rig.csv",
        "imu_times_truth.txt",
    ] {
        assert!(read(&a, f) == read(&b, f), "{f} differs between two runs");
    }
    // Lost frames and PPS faults: the GNSS, the truth and the kept IMU
    // samples are unchanged, only records go missing from the rig log.
    let c = sim(
        "c",
        &[
            "--lost-frames",
            "0.02",
            "--set",
            "rig.pps.spurious_per_hour=600",
        ],
    );
    for f in ["gnss.txt", "truth.nav"] {
        assert!(read(&a, f) == read(&c, f), "{f} changed with rig faults");
    }
    let all: std::collections::HashSet<String> =
        read(&a, "imu.txt").lines().map(String::from).collect();
    let kept: Vec<String> = read(&c, "imu.txt").lines().map(String::from).collect();
    assert!(kept.len() < all.len() && kept.len() > all.len() * 9 / 10);
    assert!(
        kept.iter().all(|l| all.contains(l)),
        "a kept IMU sample changed"
    );
    assert!(
        read(&c, "rig.csv")
            .lines()
            .filter(|l| l.starts_with("pps,"))
            .count()
            > read(&a, "rig.csv")
                .lines()
                .filter(|l| l.starts_with("pps,"))
                .count()
    );
}

#[test]
fn turns_reveal_the_gyro_misalignment_that_couples_yaw_rate_into_tilt() {
    // ADIS16465-class IMU with ±0.05° axis misalignments on the test track
    // (10°/s curves): the terms that carry the yaw rate into the x gyro
    // (m_xz) and gravity into the horizontal accelerometers (m_xz, m_yz)
    // are found; without the states the gate rejects good fixes in turns.
    let dir = temp_dir("misalign");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--quiet",
            "--scenario",
            "test-track",
            "--seed",
            "1",
        ])
        .args([
            "--internal-rate",
            "0",
            "--set",
            "output.rig_log=false",
            "--output",
        ])
        .arg(&sim));
    assert!(ok, "{err}");
    let (ok, out, err) = run(bin()
        .args(["fuse", "--misalignment", "0.05", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(dir.join("out")));
    assert!(ok, "{out}\n{err}");
    let json = |p: PathBuf| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let s = json(dir.join("out/summary.json"));
    let scn = json(sim.join("scenario.json"));
    let truth = |sensor: &str, r: usize, c: usize| {
        scn["imu_drawn"][sensor]["matrix"][r][c]
            .as_f64()
            .unwrap()
            .to_degrees()
    };
    let est = |key: &str, k: usize| s[key][k].as_f64().unwrap();
    let checks = [
        ("gyro", "final_gyro_misalign_deg", 1, (0, 2)),
        ("accel", "final_accel_misalign_deg", 1, (0, 2)),
        ("accel", "final_accel_misalign_deg", 3, (1, 2)),
    ];
    for (sensor, key, k, (r, c)) in checks {
        let (e, t) = (est(key, k), truth(sensor, r, c));
        assert!(
            (e - t).abs() < 0.012,
            "{sensor} m[{r}][{c}]: {e:.4}° vs {t:.4}°"
        );
    }
    assert_eq!(s["stats"]["gnss_fixes_rejected"], 0, "{out}");
}

/// Fixes whose σ are stated 5× too small are rejected in runs, and each
/// run's drift acceptance inflates P. With the 12 misalignment states
/// inflated too, the fixes drove them and the biases to a solution at
/// 10⁴ m/s on this drive (the run stopped at SOW 100272.0); held, as the
/// datasheet constants they are, the run ends as well as the 21 states'
/// (0.046 against 0.051 m measured; 0.402 m with their σ capped at 1°).
#[test]
fn overconfident_fixes_do_not_drive_the_misalignment_states_off() {
    let dir = temp_dir("misalign-overconfident");
    // σ stated ×0.2 of the simulated RTK's [0.018, 0.018, 0.0292] m.
    let sim = common::simulate_adis16465(
        &dir,
        "test-track",
        "600",
        &[
            "--set",
            "output.rig_log=false",
            "--set",
            "gnss.std_written_m=[0.0036,0.0036,0.00584]",
        ],
    );
    let hrms = |name: &str, extra: &[&str]| -> f64 {
        let out = dir.join(name);
        let (ok, text, err) = run(bin()
            .arg("fuse")
            .args(extra)
            .arg("--config")
            .arg(sim.join("kf-gins.yaml"))
            .arg("--output")
            .arg(&out));
        assert!(ok, "{name}: {text}\n{err}");
        common::horizontal_rms(&sim.join("truth.nav"), &out.join("navresult.nav"), &out)
    };
    let core = hrms("core", &[]);
    let with_states = hrms("misalign", &["--misalignment", "0.05"]);
    assert!(
        with_states < 1.5 * core,
        "misalignment states {with_states:.3} m against 21 states {core:.3} m"
    );
}

#[test]
#[cfg(target_os = "linux")]
fn live_refuses_bad_settings_and_survives_missing_devices() {
    let dir = temp_dir("live");
    let cfg = write_static_set(&dir, 2);
    let cfg = cfg.to_str().unwrap();
    let live = |extra: &[&str]| {
        let base = ["live", "--gnss", "/dev/null", "--config", cfg];
        run(bin().args(base).args(extra))
    };
    let (ok, _, err) = live(&["--imu", "/dev/null", "--imu-baud", "7"]);
    let bad_baud = err.contains("--imu-baud") && err.contains("not a standard rate");
    assert!(!ok && bad_baud, "{err}");
    let (ok, _, err) = live(&["--imu", "/dev/null", "--imu-format", "ubx-esf"]);
    assert!(!ok && err.contains("drop --imu"), "{err}");
    // Devices that are not there: reported, retried, a clean end.
    let (ok, out, err) = run(bin()
        .args(["live", "--config", cfg, "--duration", "1.2"])
        .args([
            "--gnss",
            "/dev/navsync-none-1",
            "--imu",
            "/dev/navsync-none-2",
            "--pps",
            "/dev/navsync-none-3",
        ]));
    assert!(ok, "{err}");
    for d in ["none-1", "none-2", "none-3"] {
        assert!(
            err.contains(&format!("/dev/navsync-{d}: cannot open")),
            "{err}"
        );
    }
    assert!(
        out.contains("clock acquiring") && out.contains("0 solutions"),
        "{out}"
    );
}

#[test]
fn receiver_time_marks_check_hardware_sync_and_replace_the_gnss_envelope() {
    let dir = temp_dir("marks");
    let sync = |name: &str, extra: &[&str]| -> serde_json::Value {
        let sim = dir.join(name);
        let (ok, _, err) = run(bin()
            .args([
                "simulate",
                "--quiet",
                "--scenario",
                "urban",
                "--duration",
                "300",
            ])
            .args(["--seed", "6", "--internal-rate", "0", "--output"])
            .arg(&sim)
            .args(extra));
        assert!(ok, "{err}");
        let (ok, out, err) = run(bin()
            .arg("sync")
            .arg(sim.join("rig.csv"))
            .arg("--output")
            .arg(sim.join("sync"))
            .arg("--truth")
            .arg(sim.join("imu_times_truth.txt")));
        assert!(ok, "{out}\n{err}");
        let text = std::fs::read_to_string(sim.join("sync/sync_report.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    };
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    // Hardware sync: 10 Hz camera strobes time-marked by the receiver
    // (20 ns) agree with the counter-stamped times to the 1 µs tick.
    let hw = sync("hw", &["--set", "rig.marks.rate_hz=10"]);
    // Every mark of the 300 s (10 Hz from +0.5123 s) is compared.
    assert_eq!(hw["marks"]["received"], 2995);
    assert_eq!(hw["marks"]["compared"], 2995);
    assert!(f(&hw["marks"]["residual_rms_us"]) < 0.6, "{}", hw["marks"]);
    assert_eq!(hw["marks"]["used_as_clock_reference"], false);
    // Software sync with 1 Hz marks latched by a host interrupt (0–20 µs):
    // the marks map host time to GPS time, so the GNSS message latency
    // (70–110 ms here) no longer biases the stamps; what is left is the
    // IMU's fastest arrival (serial frame + T_c + 1 ms, ≈ 2.9 ms).
    let marks = [
        "--sync",
        "sw",
        "--set",
        "rig.marks.rate_hz=1",
        "--set",
        "rig.marks.latch_delay_s=2e-5",
    ];
    let sw = sync("sw", &marks);
    assert_eq!(sw["marks"]["used_as_clock_reference"], true);
    let t = &sw["truth"];
    assert!(f(&t["sd_us"]) < 50.0, "{t}");
    assert!((f(&t["mean_us"]) - 2_900.0).abs() < 500.0, "{t}");
    // Without marks the same rig's stamps are off by the GNSS latency.
    let env = sync("sw_env", &["--sync", "sw"]);
    assert!(f(&env["truth"]["mean_us"]) < -50_000.0, "{}", env["truth"]);
}

/// Issue 17: `convert` prints the dropped UBX epochs by reason with the
/// option that keeps them, and a stream with no fix exits non-zero with a
/// plain message (`--allow-no-fix` accepts it).
#[test]
fn convert_counts_dropped_epochs_and_fails_without_a_fix() {
    let dir = temp_dir("convert-nofix");
    // The shared NEO-M8T timing log: NAV-POSLLH + NAV-STATUS epochs, all
    // "time only" (fix type 5), and TIM-TP pulses.
    let log = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/gpsd-ublox/u-blox-m8t-time.log");
    assert!(log.exists(), "{} missing", log.display());
    let out = dir.join("out");
    let (ok, stdout, stderr) = run(bin()
        .args(["convert", "--from", "ubx"])
        .arg(&log)
        .arg("--output")
        .arg(&out));
    assert!(!ok, "{stdout}");
    assert!(
        stdout.contains("UBX NAV-SOL/POSLLH/VELNED/STATUS: 151 epochs, 0 gave a fix, 151 dropped"),
        "{stdout}"
    );
    assert!(stdout.contains("151  fix type 5 (time only)"), "{stdout}");
    assert!(
        stderr.contains("navsync: error: no GNSS fix in")
            && stderr.contains("--allow-no-fix")
            && !stderr.contains("panicked"),
        "{stderr}"
    );
    // What could be written still is (the PPS events), and the option
    // accepts the stream.
    assert!(out.join("events.rig").exists() && out.join("summary.json").exists());
    let (ok, _, stderr) = run(bin()
        .args(["convert", "--from", "ubx", "--allow-no-fix"])
        .arg(&log)
        .arg("--output")
        .arg(&out));
    assert!(ok, "{stderr}");
    assert!(stderr.contains("note: no GNSS fix"), "{stderr}");

    // 3D epochs with gnssFixOK = 0 name the option that keeps them.
    let mut s = Vec::new();
    for k in 1..=4u32 {
        let mut p = navsync_receivers::ubx::NavPvt::decode(&[0; 92]).unwrap();
        p.itow_ms = k * 1000;
        p.fix_type = 3;
        p.flags = u8::from(k == 4); // only the last one is gnssFixOK
        p.lat_e7 = 300_000_000;
        p.height_mm = 20_000;
        let tg = navsync_receivers::ubx::NavTimeGps {
            itow_ms: k * 1000,
            ftow_ns: 0,
            week: 2300,
            leap_s: 18,
            valid: 7,
            t_acc_ns: 10,
        };
        for m in [
            navsync_receivers::ubx::UbxMessage::NavTimeGps(tg),
            navsync_receivers::ubx::UbxMessage::NavPvt(p),
        ] {
            s.extend(m.to_frame().unwrap());
        }
    }
    let input = dir.join("pvt.ubx");
    std::fs::write(&input, s).unwrap();
    let (ok, stdout, stderr) = run(bin()
        .args(["convert", "--from", "ubx"])
        .arg(&input)
        .arg("--output")
        .arg(dir.join("pvt")));
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("UBX NAV-PVT: 4 epochs, 1 gave a fix, 3 dropped"),
        "{stdout}"
    );
    assert!(
        stdout.contains("3  gnssFixOK = 0") && stdout.contains("[kept with --keep-fix-not-ok]"),
        "{stdout}"
    );
    let (ok, stdout, _) = run(bin()
        .args(["convert", "--from", "ubx", "--keep-fix-not-ok"])
        .arg(&input)
        .arg("--output")
        .arg(dir.join("pvt-kept")));
    assert!(ok);
    assert!(stdout.contains("gnss.txt: 4 fixes"), "{stdout}");

    // An HDT σ outside (0, 30]° is refused before anything is read.
    for bad in ["0", "-1", "45", "NaN"] {
        let (ok, _, stderr) = run(bin()
            .args(["convert", "--from", "ubx", &format!("--hdt-sd={bad}")])
            .arg(&input)
            .arg("--output")
            .arg(dir.join("hdt-sd")));
        assert!(!ok, "--hdt-sd {bad} accepted");
        assert!(
            stderr.contains("--hdt-sd")
                && stderr.contains("(0, 30] deg")
                && !stderr.contains("panicked"),
            "{stderr}"
        );
    }
}

#[test]
fn convert_reads_standard_input() {
    // `gpspipe -R | navsync convert --from ubx - --output DIR`: a shared
    // gpsd log piped in small chunks (short reads, the `#` header split
    // across them) converts exactly as the file does.
    let dir = temp_dir("convert-stdin");
    let log = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/gpsd-ublox/ublox-neo-m8l.log");
    let bytes = std::fs::read(&log).unwrap();
    let (ok, _, stderr) = run(bin()
        .args(["convert", "--from", "ubx"])
        .arg(&log)
        .arg("--output")
        .arg(dir.join("file")));
    assert!(ok, "{stderr}");
    let mut child = bin()
        .args(["convert", "--from", "ubx", "-", "--output"])
        .arg(dir.join("stdin"))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut pipe = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || {
        use std::io::Write;
        for chunk in bytes.chunks(97) {
            pipe.write_all(chunk).unwrap();
            pipe.flush().unwrap();
        }
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stdout}{stderr}");
    let from_file = std::fs::read_to_string(dir.join("file/gnss.txt")).unwrap();
    let from_stdin = std::fs::read_to_string(dir.join("stdin/gnss.txt")).unwrap();
    assert!(from_file.lines().count() >= 10);
    assert_eq!(from_file, from_stdin);
    let summary = std::fs::read_to_string(dir.join("stdin/summary.json")).unwrap();
    assert!(summary.contains("\"input\": \"<stdin>\""), "{summary}");

    // Empty standard input: a plain error, no panic.
    let (ok, _, stderr) = run(bin()
        .args(["convert", "--from", "nmea", "-", "--output"])
        .arg(dir.join("empty"))
        .stdin(std::process::Stdio::null()));
    assert!(
        !ok && stderr.contains("<stdin>") && !stderr.contains("panicked"),
        "{stderr}"
    );
}

#[test]
fn smoothing_bridges_outages_and_keeps_the_forward_solution() {
    // A 400 s test-track drive, ADIS16465-class IMU, 1 Hz RTK-class GNSS,
    // 40 s outages every 150 s. A forward filter's drift through an outage
    // grows about as T³ (attitude error × g); an RTS smoother bridges it
    // from both ends, each side covering half the gap, (T/2)³ = T³/8, so
    // its worst drift is well under a quarter of the forward one.
    let dir = temp_dir("smooth");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--quiet",
            "--internal-rate",
            "0",
            "--scenario",
            "test-track",
            "--duration",
            "400",
            "--imu-grade",
            "adis16465",
            "--seed",
            "3",
            "--output",
        ])
        .arg(&sim));
    assert!(ok, "{err}");
    let out = dir.join("out");
    let (ok, text, err) = run(bin()
        .args([
            "fuse",
            "--smooth",
            "--outage-period",
            "150",
            "--outage-len",
            "40",
        ])
        .args(["--outage-first", "100", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(&out));
    assert!(ok, "{text}\n{err}");
    assert!(text.contains("smoother:"), "{text}");
    // Same files and epochs forward and smoothed.
    for f in ["navresult.nav", "std.txt", "imu_err.txt", "summary.json"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let lines = |p: PathBuf| std::fs::read_to_string(p).unwrap().lines().count();
    assert_eq!(
        lines(out.join("navresult.nav")),
        lines(out.join("forward/navresult.nav"))
    );
    assert_eq!(
        lines(out.join("std.txt")),
        lines(out.join("forward/std.txt"))
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let outages = summary["outages"].as_str().unwrap().to_string();
    assert!(summary["smoother"]["nodes"].as_u64().unwrap() > 300);
    let (ok, text, err) = run(bin()
        .args(["eval", "--truth"])
        .arg(sim.join("truth.nav"))
        .arg("--nav")
        .arg(out.join("navresult.nav"))
        .args(["--outages", &outages, "--json"])
        .arg(dir.join("eval.json")));
    assert!(ok, "{err}");
    assert!(text.contains("forward filter"), "{text}");
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval.json")).unwrap()).unwrap();
    let smoothed = e["outage_rms_max_horizontal_m"].as_f64().unwrap();
    let forward = e["forward"]["outage_rms_max_horizontal_m"]
        .as_f64()
        .unwrap();
    assert!(
        smoothed < forward / 4.0,
        "outage drift: smoothed {smoothed} m, forward {forward} m"
    );
    let rms = |v: &serde_json::Value| v["pos_horizontal_m"]["rms"].as_f64().unwrap();
    assert!(
        rms(&e) < rms(&e["forward"]),
        "{} vs {}",
        rms(&e),
        rms(&e["forward"])
    );

    // Smoothing is post-processing: a real-time latency mode is refused.
    let (ok, _, err) = run(bin()
        .args(["fuse", "--smooth", "--latency-mode", "naive", "--config"])
        .arg(sim.join("kf-gins.yaml"))
        .arg("--output")
        .arg(dir.join("naive")));
    assert!(!ok && err.contains("offline"), "{err}");
}

/// Hybrid synchronization (1PPS captured on the host counter, the IMU
/// stamped at receipt) and the implausible-log check of `sync`.
#[test]
fn hybrid_sync_recovers_sample_instants_and_implausible_logs_fail_loudly() {
    let dir = temp_dir("hybrid");
    let simulate = |name: &str, extra: &[&str]| -> PathBuf {
        let sim = dir.join(name);
        let (ok, _, err) = run(bin()
            .args(["simulate", "--quiet", "--scenario", "hybrid"])
            .args(["--seed", "3", "--internal-rate", "0", "--output"])
            .arg(&sim)
            .args(extra));
        assert!(ok, "{err}");
        sim
    };
    let sync = |sim: &Path, out: &str, extra: &[&str]| -> (bool, String, String) {
        run(bin()
            .arg("sync")
            .arg(sim.join("rig.csv"))
            .arg("--output")
            .arg(sim.join(out))
            .arg("--truth")
            .arg(sim.join("imu_times_truth.txt"))
            .args(extra))
    };
    let report = |sim: &Path, out: &str| -> serde_json::Value {
        let text = std::fs::read_to_string(sim.join(out).join("sync_report.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    };
    let f = |v: &serde_json::Value| v.as_f64().unwrap();

    // 600 s at 200 Hz, receive latency uniform 1–10 ms (FIFO), counter
    // 40 ppm warming by 25 °C, one frame in 10⁴ lost.
    let sim = simulate("uniform", &[]);
    let (ok, out, err) = sync(&sim, "auto", &[]);
    assert!(ok, "{out}\n{err}");
    assert!(
        !err.contains("IMPLAUSIBLE"),
        "a clean log passes silently: {err}"
    );
    let r = report(&sim, "auto");
    assert_eq!(r["mode"], "hybrid");
    assert!(r["implausible"].as_array().unwrap().is_empty());
    assert_eq!(r["hybrid"]["clock_segments"], 0, "one run, no restart");
    // Every injected loss is found and none is invented.
    let scn: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim.join("scenario.json")).unwrap()).unwrap();
    let injected = scn["report"]["imu_lost"]["count"].as_u64().unwrap();
    assert!(injected >= 5, "the run should inject losses: {injected}");
    assert_eq!(r["imu"]["lost"].as_u64().unwrap(), injected);
    // The stamp error's varying part: the envelope of ~4000 receive times
    // with a 9 ms spread is good to µs; what remains are the few samples
    // next to a loss whose place is uncertain (one period, 5 ms, off).
    // The requirement for this rig is 50 µs (1σ).
    let t = &r["truth"];
    assert!(f(&t["sd_us"]) <= 50.0, "{t}");
    // The constant is the fastest transport (frame 0.87 ms + output delay
    // 1 ms + fastest latency 1 ms): unobservable, reported as such.
    assert!((f(&t["mean_us"]) - 2_870.0).abs() < 100.0, "{t}");
    assert!(
        r["hybrid"]["unobservable"]
            .as_str()
            .unwrap()
            .contains("fastest transport latency")
    );

    // The same log forced into hardware mode: receive times taken for
    // captures give losses, duplicates and irregular intervals by the
    // thousand: loud, non-zero, no imu.txt left behind.
    let (ok, out, err) = sync(&sim, "hw", &["--mode", "hw"]);
    assert!(!ok, "{err}");
    assert!(err.contains("IMPLAUSIBLE"), "{err}");
    // Files withdrawn are not announced as written.
    assert!(!out.contains("wrote"), "{out}");
    assert!(err.contains("--mode hybrid"), "{err}");
    assert!(!sim.join("hw/imu.txt").exists());
    assert!(
        !report(&sim, "hw")["implausible"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    // --force writes them anyway.
    let (ok, out, err) = sync(&sim, "hw_forced", &["--mode", "hw", "--force"]);
    assert!(ok && out.contains("wrote"), "{out}\n{err}");
    assert!(err.contains("IMPLAUSIBLE"), "{err}");
    assert!(sim.join("hw_forced/imu.txt").exists());

    // The report page says how the stamps were made, and what was wrong.
    let page = |out: &str| -> String {
        let html = sim.join(out).join("report.html");
        let (ok, _, err) = run(bin()
            .args(["report", "--nav"])
            .arg(sim.join("truth.nav"))
            .arg("--sync-report")
            .arg(sim.join(out).join("sync_report.json"))
            .arg("--output")
            .arg(&html));
        assert!(ok, "{err}");
        std::fs::read_to_string(html).unwrap()
    };
    let hybrid = page("auto");
    assert!(
        hybrid.contains("<td>hybrid sync</td><td>IMU sample clock")
            && !hybrid.contains("clock restarted"),
        "the hybrid section is missing from the page"
    );
    assert!(!hybrid.contains("<td>implausible</td>"));
    let forced = page("hw_forced");
    assert!(forced.contains("<td>implausible</td>"));

    // A hardware-captured log with 5 % of its frames lost fails loudly;
    // its clean twin passes silently.
    let hw_args = ["--sync", "hw", "--duration", "120"];
    let lossy = simulate(
        "lossy",
        &[&hw_args[..], &["--lost-frames", "0.05"]].concat(),
    );
    let (ok, _, err) = sync(&lossy, "sync", &[]);
    assert!(!ok, "{err}");
    assert!(err.contains("lost") && err.contains("IMPLAUSIBLE"), "{err}");
    let clean = simulate("clean", &hw_args);
    let (ok, _, err) = sync(&clean, "sync", &[]);
    assert!(ok && !err.contains("IMPLAUSIBLE"), "{err}");
    let r = report(&clean, "sync");
    assert_eq!(r["mode"], "hw");
    assert!(f(&r["truth"]["rms_us"]) < 0.4, "{}", r["truth"]);
}

/// No initpos/initvel/initatt in the configuration: the run aligns itself
/// (levelling over the opening standstill, heading from GNSS course) and
/// ends as accurate as the run initialised from truth; a drive that never
/// moves says that heading is unobservable and still writes a solution.
#[test]
fn a_configuration_without_initial_state_aligns_from_the_data() {
    let dir = temp_dir("align");
    let strip = |cfg: &Path, out: &Path| {
        let text: String = std::fs::read_to_string(cfg)
            .unwrap()
            .lines()
            .filter(|l| {
                !(l.starts_with("initpos:")
                    || l.starts_with("initvel:")
                    || l.starts_with("initatt:"))
            })
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(out, text).unwrap();
    };
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--quiet",
            "--internal-rate",
            "0",
            "--scenario",
            "test-track",
        ])
        .args([
            "--duration",
            "300",
            "--imu-grade",
            "adis16465",
            "--seed",
            "1",
            "--output",
        ])
        .arg(&sim));
    assert!(ok, "{err}");
    strip(&sim.join("kf-gins.yaml"), &sim.join("align.yaml"));
    let eval = |cfg: &str, name: &str| -> (f64, String) {
        let out = dir.join(name);
        let (ok, text, err) = run(bin()
            .args(["fuse", "--config"])
            .arg(sim.join(cfg))
            .arg("--output")
            .arg(&out));
        assert!(ok, "{text}\n{err}");
        let (ok, _, err) = run(bin()
            .args(["eval", "--truth"])
            .arg(sim.join("truth.nav"))
            .arg("--nav")
            .arg(out.join("navresult.nav"))
            .arg("--json")
            .arg(out.join("eval.json")));
        assert!(ok, "{err}");
        let e: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
        (e["pos_horizontal_m"]["rms"].as_f64().unwrap(), text)
    };
    let (truth_init, _) = eval("kf-gins.yaml", "truth-init");
    let (aligned, text) = eval("align.yaml", "aligned");
    assert!(
        text.contains("alignment:") && text.contains("standstill"),
        "{text}"
    );
    // The alignment starts at the standstill; its errors are the levelling
    // error (accelerometer bias / g) and the course's σ, which the filter
    // removes within seconds of driving.
    assert!(
        aligned < 1.1 * truth_init,
        "aligned {aligned} m, from truth {truth_init} m"
    );

    // A drive that never moves.
    let still = dir.join("still");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--quiet",
            "--internal-rate",
            "0",
            "--scenario",
            "static",
        ])
        .args(["--duration", "60", "--seed", "1", "--output"])
        .arg(&still));
    assert!(ok, "{err}");
    strip(&still.join("kf-gins.yaml"), &still.join("align.yaml"));
    let (ok, text, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(still.join("align.yaml"))
        .arg("--output")
        .arg(dir.join("still-out")));
    assert!(ok, "{text}\n{err}");
    assert!(text.contains("unobservable"), "{text}");
    assert!(dir.join("still-out/navresult.nav").is_file());

    // No GNSS at all: the position is unknown, said plainly.
    std::fs::write(still.join("empty-gnss.txt"), "").unwrap();
    let cfg = std::fs::read_to_string(still.join("align.yaml"))
        .unwrap()
        .replace("./gnss.txt", "./empty-gnss.txt");
    std::fs::write(still.join("nognss.yaml"), cfg).unwrap();
    let (ok, _, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(still.join("nognss.yaml"))
        .arg("--output")
        .arg(dir.join("nognss-out")));
    assert!(
        !ok && (err.contains("GNSS") || err.contains("empty")),
        "{err}"
    );
}
