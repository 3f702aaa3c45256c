//! A ROS 1 bag end to end: a simulated drive with known truth written as
//! a ROS 1 recorder writes it (bz2 chunks: `/imu/data`, `/fix`, wheel
//! odometry), then `navsync process` with a sensor sheet that has no
//! odometer: the bag's speeds become the odometer, and it says so.

mod common;

use std::path::Path;

use common::{bin, json, run, temp_dir};
use navsync_receivers::testbag1::{
    Compression, FIX, IMU, Msg1, ODOM, fix_msg, imu_msg, odom_msg, write_bag1,
};

/// GPS − UTC since 2017-01-01 (IERS Bulletin C).
const LEAP_S: i64 = 18;
/// 1980-01-06T00:00:00Z in Unix seconds.
const GPS_EPOCH_UNIX_S: i64 = 315_964_800;

fn utc_ns(week: i64, sow: f64) -> i64 {
    (GPS_EPOCH_UNIX_S + week * 604_800 - LEAP_S) * 1_000_000_000 + (sow * 1e9).round() as i64
}

fn numbers(line: &str, sep: char) -> Vec<f64> {
    line.split(sep)
        .filter(|s| !s.is_empty())
        .map(|x| x.parse().unwrap())
        .collect()
}

fn data_lines(p: &Path) -> Vec<String> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

/// The simulator's drive as ROS 1 messages: IMU rates FRD → FLU at their
/// true instants, 1 Hz fixes with their σ, odometry at 10 Hz (the true
/// horizontal speed, σ 0.05 m/s) in `base_link`.
fn messages(sim: &Path, week: i64, with_fixes: bool) -> Vec<Msg1> {
    let rates: Vec<Vec<f64>> = data_lines(&sim.join("rig.csv"))
        .iter()
        .filter_map(|l| l.strip_prefix("imu,"))
        .map(|l| numbers(l, ',')[1..].to_vec())
        .collect();
    let times: Vec<Vec<f64>> = data_lines(&sim.join("imu_times_truth.txt"))
        .iter()
        .map(|l| numbers(l, ' '))
        .collect();
    let mut msgs = Vec::new();
    for (r, t) in rates.iter().zip(&times) {
        let stamp = utc_ns(week, t[1]);
        msgs.push(Msg1 {
            topic: "/imu/data",
            ty: IMU,
            log_ns: stamp + 2_000_000,
            data: imu_msg(stamp, [r[0], -r[1], -r[2]], [r[3], -r[4], -r[5]]),
        });
    }
    if with_fixes {
        for l in data_lines(&sim.join("gnss.txt")) {
            let f = numbers(&l, ' ');
            let stamp = utc_ns(week, f[0]);
            msgs.push(Msg1 {
                topic: "/fix",
                ty: FIX,
                log_ns: stamp + 70_000_000,
                data: fix_msg(
                    stamp,
                    0,
                    [f[1], f[2], f[3]],
                    [f[5] * f[5], f[4] * f[4], f[6] * f[6]],
                ),
            });
        }
    }
    // truth.nav: week sow lat lon h vn ve vd roll pitch yaw, every 5 ms.
    for (k, l) in data_lines(&sim.join("truth.nav")).iter().enumerate() {
        if k % 20 != 0 {
            continue;
        }
        let n = numbers(l, ' ');
        let stamp = utc_ns(week, n[1]);
        msgs.push(Msg1 {
            topic: "/odom",
            ty: ODOM,
            log_ns: stamp + 1_000_000,
            data: odom_msg(stamp, "base_link", n[5].hypot(n[6]), 0.0025),
        });
    }
    msgs.sort_by_key(|m| m.log_ns);
    msgs
}

#[test]
fn a_ros1_bag_is_processed_with_its_odometry_as_the_odometer() {
    let dir = temp_dir("ros1-drive");
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--scenario", "test-track"])
        .args([
            "--duration",
            "240",
            "--imu-grade",
            "adis16465",
            "--seed",
            "3",
        ])
        .args(["--imu-record", "rate", "--decimation", "point", "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    let week = json(&sim.join("scenario.json"))["gps_week"]
        .as_i64()
        .unwrap();
    let sheet = dir.join("sensor.yaml");
    let (ok, _, err) = run(bin()
        .args(["init", "--preset", "adis16465", "--output"])
        .arg(&sheet));
    assert!(ok, "{err}");
    // The simulator's antenna lever arm.
    let text = std::fs::read_to_string(&sheet).unwrap().replace(
        "antenna_lever_m: [0.0, 0.0, 0.0]",
        "antenna_lever_m: [0.1, 0.5, -1.2]",
    );
    std::fs::write(&sheet, text).unwrap();

    let bag = dir.join("drive.bag");
    std::fs::write(
        &bag,
        write_bag1(&messages(&sim, week, true), Compression::Bz2, 768 * 1024),
    )
    .unwrap();
    let out = dir.join("out");
    let (ok, stdout, err) = run(bin()
        .arg("process")
        .arg(&bag)
        .arg("--sensor")
        .arg(&sheet)
        .arg("--output")
        .arg(&out)
        .arg("--truth")
        .arg(sim.join("truth.nav")));
    assert!(ok, "{stdout}{err}");
    assert!(stdout.contains("ROS 1 bag (format 2.0)"), "{stdout}");
    assert!(
        stdout.contains("/odom") && stdout.contains("used as speed"),
        "{stdout}"
    );
    assert!(stdout.contains("used as the odometer"), "{stdout}");
    assert!(out.join("convert/gnss/speed.txt").is_file());
    let p = json(&out.join("process.json"));
    let notes = p["notes"].to_string();
    assert!(
        notes.contains("used as the odometer")
            && notes.contains("σ 0.050 m/s (its covariance's, floored at 0.05 m/s)"),
        "{notes}"
    );
    assert!(notes.contains("altitude datum: ellipsoid"), "{notes}");
    // Bound: the fixes' own horizontal σ (RTK-like): a smoothed solution
    // through 1 Hz fixes, aided by speed, must not be worse than them.
    let f = numbers(&data_lines(&sim.join("gnss.txt"))[0], ' ');
    let sd_h = f[4].hypot(f[5]);
    let rms = p["eval"]["pos_horizontal_m"]["rms"].as_f64().unwrap();
    eprintln!("ROS 1 bag drive: horizontal RMS {rms:.4} m (fix σh {sd_h:.4} m)");
    assert!(rms < sd_h, "horizontal RMS {rms} m ≥ fix σh {sd_h} m");

    // The same bag without NavSatFix: an IMU log, and process says there
    // is no GNSS.
    let imu_only = dir.join("imu-only.bag");
    std::fs::write(
        &imu_only,
        write_bag1(&messages(&sim, week, false), Compression::Lz4, 768 * 1024),
    )
    .unwrap();
    let (ok, stdout, err) = run(bin()
        .arg("process")
        .arg(&imu_only)
        .arg("--sensor")
        .arg(&sheet)
        .arg("--output")
        .arg(dir.join("out2")));
    assert!(!ok, "{stdout}");
    assert!(
        err.contains("no GNSS in")
            && err.contains("no NavSatFix topic")
            && err.contains("/imu/data"),
        "{err}"
    );
}
