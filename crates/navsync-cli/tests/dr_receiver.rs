//! `navsync process` on a u-blox dead-reckoning receiver's log that holds
//! its fused solution (NAV-PVAT) and no raw IMU: a clear refusal.

mod common;

use common::{bin, run, temp_dir};

#[test]
fn process_says_a_fused_solution_has_no_imu() {
    let log = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-logs/ublox-dr-navpvat/pygpsdata-SF-calibration.log");
    if !log.is_file() {
        eprintln!("skipped: {} not found", log.display());
        return;
    }
    let dir = temp_dir("fused");
    let sensor = dir.join("sensor.yaml");
    let (ok, out, err) = run(bin().args(["init", "--output"]).arg(&sensor));
    assert!(ok, "{out}{err}");
    let (ok, out, err) = run(bin()
        .arg("process")
        .arg(&log)
        .arg("--sensor")
        .arg(&sensor)
        .arg("--output")
        .arg(dir.join("out")));
    assert!(!ok, "{out}");
    assert!(
        err.contains("FUSED solution") && err.contains("no raw IMU data"),
        "{err}"
    );
}
