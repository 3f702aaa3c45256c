//! ArduPilot DataFlash logs through `navsync process`: the real ArduCopter
//! log with a 22 s IMU logging gap cut into it (accepted, the gap
//! reported, the time offset kept in its range, the forward solution on
//! the fixes), and a log without GPS (a clear error).

mod common;

use std::path::{Path, PathBuf};

use common::{bin, json, run, temp_dir};
use navsync::Diagnostics;
use navsync_receivers::dataflash::parse;
use navsync_receivers::testdataflash::{DataFlashWriter, LAYOUT_2014};

fn real_log() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-logs/ardupilot-copter-dataflash/16.BIN");
    p.is_file().then_some(p)
}

fn sheet(dir: &Path) -> PathBuf {
    let p = dir.join("sensor.yaml");
    let (ok, out, err) = run(bin().args(["init", "--output", p.to_str().unwrap()]));
    assert!(ok, "{out}{err}");
    p
}

/// Numeric columns of a text file (comments skipped).
fn rows(p: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect()
        })
        .collect()
}

/// Horizontal RMS (m) of an 11-column nav file at the fixes' times (linear
/// interpolation), against the fixes of a KF-GINS gnss.txt.
fn rms_against_fixes(nav: &Path, gnss: &Path) -> (f64, usize) {
    let nav = rows(nav);
    let mut se = Vec::new();
    for f in rows(gnss) {
        let i = nav.partition_point(|r| r[1] < f[0]);
        if i == 0 || i >= nav.len() {
            continue;
        }
        let (a, b) = (&nav[i - 1], &nav[i]);
        let w = (f[0] - a[1]) / (b[1] - a[1]);
        let lat = a[2] + w * (b[2] - a[2]);
        let lon = a[3] + w * (b[3] - a[3]);
        let dn = (lat - f[1]).to_radians() * 6.378e6;
        let de = (lon - f[2]).to_radians() * 6.378e6 * f[1].to_radians().cos();
        se.push(dn * dn + de * de);
    }
    let n = se.len();
    ((se.iter().sum::<f64>() / n.max(1) as f64).sqrt(), n)
}

#[test]
fn arducopter_log_with_a_22_s_imu_gap() {
    let Some(src) = real_log() else {
        eprintln!("skipped: 16.BIN not in the shared data");
        return;
    };
    let d = temp_dir("gap");
    // The IMU messages with boot times in (100 s, 122 s) left out.
    let bytes = std::fs::read(&src).unwrap();
    let mut keep = Vec::with_capacity(bytes.len());
    let mut cut = 0;
    parse(&bytes, &src, &mut Diagnostics::default(), |m| {
        let t = m.format.boot_us(m.payload);
        if m.format.name == "IMU" && t.is_some_and(|t| t > 100_000_000 && t < 122_000_000) {
            cut += 1;
        } else {
            keep.extend_from_slice(&bytes[m.offset..m.offset + m.format.length]);
        }
    });
    assert_eq!(cut, 1100);
    let log = d.join("gap.BIN");
    std::fs::write(&log, &keep).unwrap();
    let out = d.join("out");
    let (ok, stdout, err) = run(bin()
        .arg("process")
        .arg(&log)
        .arg("--sensor")
        .arg(sheet(&d))
        .arg("--output")
        .arg(&out));
    assert!(ok, "{stdout}{err}");
    assert!(stdout.contains("imu logging gap: 22.0 s"), "{stdout}");
    let r = json(&out.join("sync/sync_report.json"));
    assert_eq!(r["implausible"].as_array().unwrap().len(), 0);
    let gaps = r["imu"]["logging_gaps"].as_array().unwrap();
    assert_eq!(gaps.len(), 1);
    let len = gaps[0]["length_s"].as_f64().unwrap();
    assert!((len - 22.02).abs() < 0.05, "{len}");
    let missing = gaps[0]["samples_missing"].as_u64().unwrap();
    assert!(missing.abs_diff(1100) <= 2, "{missing}");
    // The rate counts the gap's samples: 50 Hz, not 6500 / 152 s.
    let rate = r["imu"]["rate_hz"].as_f64().unwrap();
    assert!((rate - 50.0).abs() < 0.1, "{rate}");
    // The time offset never leaves the search range (±0.5 s).
    let tau = rows(&out.join("fuse/forward/time_offset.txt"));
    assert!(tau.len() > 100);
    let worst = tau.iter().map(|r| r[1].abs()).fold(0.0, f64::max);
    assert!(worst <= 0.5, "time offset reached {worst} s");
    // The forward solution stays on the fixes (no km errors).
    let (rms, n) = rms_against_fixes(
        &out.join("fuse/forward/navresult.nav"),
        &out.join("sync/gnss.txt"),
    );
    assert!(
        n > 700 && rms < 5.0,
        "forward horizontal RMS {rms} m over {n} fixes"
    );
}

#[test]
fn dataflash_without_gps_is_a_clear_error_in_process() {
    let d = temp_dir("nogps");
    let mut w = DataFlashWriter::with_layouts(&LAYOUT_2014);
    for k in 0..500 {
        w.msg("IMU", &[20.0 * k as f64, 0.0, 0.0, 0.0, 0.0, 0.0, -9.8]);
    }
    let log = d.join("imu_only.BIN");
    std::fs::write(&log, &w.bytes).unwrap();
    let (ok, stdout, err) = run(bin()
        .arg("process")
        .arg(&log)
        .arg("--sensor")
        .arg(sheet(&d))
        .arg("--output")
        .arg(d.join("out")));
    assert!(!ok, "{stdout}");
    assert!(
        err.contains("imu_only.BIN")
            && err.contains("no GPS messages")
            && err.contains("GNSS positions"),
        "{err}"
    );
    // convert alone writes the IMU and says so.
    let (ok, stdout, err) = run(bin()
        .args(["convert", "--from", "dataflash"])
        .arg(&log)
        .arg("--output")
        .arg(d.join("conv")));
    assert!(ok, "{stdout}{err}");
    assert!(stdout.contains("rig.csv: 500 IMU samples"), "{stdout}");
}
