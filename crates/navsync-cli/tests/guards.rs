//! Regression tests of issue 32 ("Nothing silent, nothing half-written"):
//! the hostile tour's cases, each refused or reported with its cause.

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{bin, run, temp_dir};

/// A 30 s simulated drive in `dir`/sim (rig.csv, imu.txt, truth.nav, …).
fn simulate(dir: &Path) -> PathBuf {
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--scenario", "test-track", "--duration", "30"])
        .args(["--seed", "1", "--quiet", "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    sim
}

#[test]
fn the_tours_numbers_are_refused_at_parse_time_with_the_range() {
    let cases: &[(&[&str], &str, &str)] = &[
        (
            &[
                "fuse",
                "--config",
                "x.yaml",
                "--estimate-time-offset",
                "--time-offset-search",
                "1e300",
            ],
            "--time-offset-search",
            "[0, 5] s",
        ),
        (
            &[
                "imu",
                "convert",
                "a",
                "b",
                "--rate",
                "1e300",
                "--decimate",
                "2",
            ],
            "--rate",
            "[0.001, 1000000] Hz",
        ),
        (
            &["simulate", "--output", "o", "--internal-rate", "1e300"],
            "--internal-rate",
            "Hz",
        ),
        (
            &[
                "report",
                "--nav",
                "n",
                "--output",
                "o",
                "--time-offset-truth=inf",
            ],
            "--time-offset-truth",
            "[-60, 60] s",
        ),
        (&["montecarlo", "--jobs", "100000"], "--jobs", "1..=4096"),
        (
            &["fuse", "--config", "x", "--gnss-sd-floor", "NaN"],
            "--gnss-sd-floor",
            "(0, 1000] m",
        ),
        (
            &["fuse", "--config", "x", "--nhc", "--nhc-interval", "NaN"],
            "--nhc-interval",
            "s",
        ),
        (
            &[
                "fuse",
                "--config",
                "x",
                "--estimate-time-offset",
                "--time-offset-search",
                "NaN",
            ],
            "--time-offset-search",
            "s",
        ),
        (
            &[
                "fuse",
                "--config",
                "x",
                "--odometer",
                "o",
                "--odo-scale-sd",
                "NaN",
            ],
            "--odo-scale-sd",
            "[0, 1]",
        ),
        (
            &["sync", "r", "--output", "o", "--imu-output-delay", "NaN"],
            "--imu-output-delay",
            "s",
        ),
        (
            &["sync", "r", "--output", "o", "--imu-output-delay", "inf"],
            "--imu-output-delay",
            "[0, 10] s",
        ),
        (
            &[
                "convert",
                "--from",
                "ubx",
                "f",
                "--output",
                "o",
                "--imu-time-offset-s",
                "NaN",
            ],
            "--imu-time-offset-s",
            "s",
        ),
        (&["imu", "check", "f", "--rate", "NaN"], "--rate", "Hz"),
        (&["demo", "--duration", "NaN"], "--duration", "s"),
        (
            &[
                "convert",
                "--from",
                "ubx",
                "f",
                "--output",
                "o",
                "--esf-meas-tick-us",
                "0",
            ],
            "--esf-meas-tick-us",
            "µs",
        ),
    ];
    for (args, flag, range) in cases {
        let start = Instant::now();
        let out = bin().args(*args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("invalid value") && err.contains(flag) && err.contains(range),
            "{args:?}: {err}"
        );
        assert!(start.elapsed() < Duration::from_secs(5), "{args:?}");
    }
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = temp_dir("over-input");
    let sim = simulate(&dir);
    let f = dir.join("imu.txt");
    std::fs::copy(sim.join("imu.txt"), &f).unwrap();
    let before = std::fs::read(&f).unwrap();
    // The same file, also under another spelling of its path.
    for out in [f.clone(), dir.join(".").join("imu.txt")] {
        let (ok, _, err) = run(bin().args(["imu", "convert"]).arg(&f).arg(&out));
        assert!(!ok && err.contains("would overwrite the input"), "{err}");
        assert_eq!(std::fs::read(&f).unwrap(), before);
    }
    // Export's guard is the same helper (canonicalised now).
    let nav = dir.join("t.nav");
    std::fs::copy(sim.join("truth.nav"), &nav).unwrap();
    let (ok, _, err) = run(bin()
        .args(["export", "--to", "csv"])
        .arg(&nav)
        .arg("--output")
        .arg(dir.join(".").join("t.nav")));
    assert!(!ok && err.contains("would overwrite the input"), "{err}");
}

#[test]
fn a_config_that_never_ends_fails_at_once_and_os_errors_print_once() {
    let start = Instant::now();
    let (ok, _, err) = run(bin().args(["fuse", "--config", "/dev/zero"]));
    assert!(
        !ok && err.contains("/dev/zero: larger than 16 MiB"),
        "{err}"
    );
    assert!(start.elapsed() < Duration::from_secs(10));
    let (ok, _, err) = run(bin().args(["fuse", "--config", "/no/such/kf-gins.yaml"]));
    assert!(!ok);
    assert_eq!(err.matches("No such file or directory").count(), 1, "{err}");
}

/// The rig log's records (after the header) rewritten by `f`.
fn rewrite_records(src: &Path, dst: &Path, f: impl Fn(Vec<&str>) -> Vec<String>) {
    let text = std::fs::read_to_string(src).unwrap();
    let (head, recs): (Vec<&str>, Vec<&str>) = text.lines().partition(|l| l.starts_with('#'));
    let mut out = head.join("\n");
    out.push('\n');
    for l in f(recs) {
        out += &l;
        out.push('\n');
    }
    std::fs::write(dst, out).unwrap();
}

#[test]
fn rig_log_messages_name_the_cause() {
    let dir = temp_dir("rig-messages");
    let sim = simulate(&dir);
    let rig = sim.join("rig.csv");

    // A UTF-8 byte-order mark before '# rig-log v1' is not a bad header.
    let bom = dir.join("bom.csv");
    let mut bytes = b"\xEF\xBB\xBF".to_vec();
    bytes.extend(std::fs::read(&rig).unwrap());
    std::fs::write(&bom, bytes).unwrap();
    let (ok, _, err) = run(bin()
        .arg("sync")
        .arg(&bom)
        .arg("--output")
        .arg(dir.join("o-bom")));
    assert!(ok, "{err}");

    // A reversed log: its time runs backwards, it is not short of GNSS.
    let rev = dir.join("reversed.csv");
    rewrite_records(&rig, &rev, |r| {
        r.into_iter().rev().map(str::to_string).collect()
    });
    let (ok, _, err) = run(bin()
        .arg("sync")
        .arg(&rev)
        .arg("--output")
        .arg(dir.join("o-rev")));
    assert!(
        !ok && err.contains("time runs backwards from line"),
        "{err}"
    );
    assert!(!err.contains("needs at least 3 gnss"), "{err}");

    // Every record with one field too many: "extra fields", not "empty log".
    let extra = dir.join("extra.csv");
    rewrite_records(&rig, &extra, |r| {
        r.into_iter().map(|l| format!("{l},0")).collect()
    });
    let (ok, _, err) = run(bin()
        .arg("sync")
        .arg(&extra)
        .arg("--output")
        .arg(dir.join("o-x")));
    assert!(!ok && err.contains("extra fields"), "{err}");
    assert!(!err.contains("empty log"), "{err}");
}

#[test]
fn export_skips_positions_off_the_earth() {
    let dir = temp_dir("off-earth");
    let sim = simulate(&dir);
    let text = std::fs::read_to_string(sim.join("truth.nav")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let n = lines.len();
    // Line 2's latitude (column 3) set to 95°.
    let mut f: Vec<String> = lines[1].split_whitespace().map(str::to_string).collect();
    f[2] = "95.0".into();
    lines[1] = f.join(" ");
    let nav = dir.join("bad.nav");
    std::fs::write(&nav, lines.join("\n") + "\n").unwrap();
    let gpx = dir.join("bad.gpx");
    let (ok, out, err) = run(bin()
        .args(["export", "--to", "gpx"])
        .arg(&nav)
        .arg("--output")
        .arg(&gpx));
    assert!(ok, "{err}");
    // The navigation reader refuses the line at the door (io::plausible);
    // export's own check would say "not exported".
    assert!(
        err.contains("latitude 95°")
            && (err.contains("not on the earth; line skipped") || err.contains("not exported")),
        "{err}"
    );
    assert!(out.contains(&format!("{} epochs", n - 1)), "{out}");
    let written = std::fs::read_to_string(&gpx).unwrap();
    assert_eq!(written.matches("<trkpt ").count(), n - 1);
    assert!(!written.contains("lat=\"95"));
}

#[test]
fn a_sheet_rate_far_from_the_data_is_warned_about() {
    let dir = temp_dir("sheet-rate");
    let sim = simulate(&dir);
    let sheet = dir.join("sensor.yaml");
    let (ok, _, err) = run(bin()
        .args(["init", "--preset", "adis16465", "--output"])
        .arg(&sheet));
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&sheet).unwrap();
    assert!(text.contains("# rate_hz: 200"));
    std::fs::write(&sheet, text.replace("# rate_hz: 200", "rate_hz: 50")).unwrap();
    let (_, _, err) = run(bin()
        .arg("process")
        .arg(sim.join("rig.csv"))
        .arg("--sensor")
        .arg(&sheet)
        .arg("--output")
        .arg(dir.join("run")));
    assert!(
        err.contains("imu.rate_hz is 50 Hz but the data's median interval gives 200.0 Hz"),
        "{err}"
    );
}

/// An absurd figure in the sheet stops `process` before any work, naming
/// the file and the key (1e308 and `.inf` passed "finite and ≥ 0" or
/// overflowed the covariance before).
#[test]
fn process_refuses_an_absurd_sheet_figure_naming_the_key() {
    let dir = temp_dir("sheet-absurd");
    let sheet = dir.join("sensor.yaml");
    let (ok, _, err) = run(bin()
        .args(["init", "--preset", "adis16465", "--output"])
        .arg(&sheet));
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&sheet).unwrap();
    for (from, to, key) in [
        (
            "arw_deg_sqrt_h: 0.15",
            "arw_deg_sqrt_h: 1e308",
            "'imu.arw_deg_sqrt_h'",
        ),
        (
            "gyro_scale_ppm: 500.0",
            "gyro_scale_ppm: .inf",
            "'imu.gyro_scale_ppm'",
        ),
        ("# rate_hz: 200", "rate_hz: 1e308", "'imu.rate_hz'"),
    ] {
        assert!(text.contains(from), "{from}");
        std::fs::write(&sheet, text.replace(from, to)).unwrap();
        let (ok, _, err) = run(bin()
            .arg("process")
            .arg(dir.join("rig.csv"))
            .arg("--sensor")
            .arg(&sheet)
            .arg("--output")
            .arg(dir.join("run")));
        assert!(!ok);
        assert!(
            err.contains("sensor.yaml") && err.contains(key),
            "{to}: {err}"
        );
        assert!(!dir.join("run").exists(), "{to}");
    }
}

#[test]
fn convert_reports_a_gps_week_jump_of_concatenated_logs() {
    use navsync_receivers::ubx::{NavPvt, NavTimeGps, UbxMessage};
    let dir = temp_dir("week-jump");
    let mut s = Vec::new();
    for week in [2024i16, 2299] {
        for k in 1..=3u32 {
            let mut p = NavPvt::decode(&[0; 92]).unwrap();
            p.itow_ms = k * 1000;
            p.fix_type = 3;
            p.flags = 1;
            p.lat_e7 = 300_000_000;
            p.height_mm = 20_000;
            let tg = NavTimeGps {
                itow_ms: k * 1000,
                ftow_ns: 0,
                week,
                leap_s: 18,
                valid: 7,
                t_acc_ns: 10,
            };
            for m in [UbxMessage::NavTimeGps(tg), UbxMessage::NavPvt(p)] {
                s.extend(m.to_frame().unwrap());
            }
        }
    }
    let input = dir.join("two.ubx");
    std::fs::write(&input, s).unwrap();
    let out = dir.join("out");
    let (ok, _, err) = run(bin()
        .args(["convert", "--from", "ubx"])
        .arg(&input)
        .arg("--output")
        .arg(&out));
    assert!(ok, "{err}");
    assert!(
        err.contains("warning: byte ")
            && err.contains("GPS time jumps by")
            && err.contains("2024 3.")
            && err.contains("2299 1."),
        "{err}"
    );
    let summary = common::json(&out.join("summary.json"));
    assert_eq!(
        summary["time_jumps"].as_array().map(Vec::len),
        Some(1),
        "{summary}"
    );
}
