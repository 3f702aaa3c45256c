//! A ROS 2 bag end to end: a simulated drive with known truth, written as
//! a recorder writes it (the `mcap` crate, zstd chunks, CDR messages as
//! drivers publish them), then `convert --from mcap`, `fuse` and `eval`.

mod common;

use std::path::Path;

use common::{bin, horizontal_rms, json, run, temp_dir};
use navsync_receivers::testbag::{FIX, IMU, Msg, fix_msg, imu_msg, write_bag_chunked};

/// GPS − UTC since 2017-01-01 (GPS week 1930; IERS Bulletin C).
const LEAP_S: i64 = 18;
/// 1980-01-06T00:00:00Z, the GPS epoch, in Unix seconds.
const GPS_EPOCH_UNIX_S: i64 = 315_964_800;

/// Unix (UTC) ns of GPS week/seconds of week: what a ROS driver stamps.
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

/// The simulator's drive as a ROS 2 bag: `/imu/data` at the IMU's rate
/// (its instantaneous body rates, FRD turned to FLU, at their true sample
/// instants), `/gnss/fix` at 1 Hz with the fixes' σ as covariance, and a
/// topic navsync does not read; stamps UTC, logged a little later.
fn bag_of(sim: &Path, week: i64) -> Vec<u8> {
    // rig.csv's IMU records (FRD rad/s, m/s²) in order, and each sample's
    // true GPS time.
    let rates: Vec<Vec<f64>> = data_lines(&sim.join("rig.csv"))
        .iter()
        .filter_map(|l| l.strip_prefix("imu,"))
        .map(|l| numbers(l, ',')[1..].to_vec())
        .collect();
    let times: Vec<Vec<f64>> = data_lines(&sim.join("imu_times_truth.txt"))
        .iter()
        .map(|l| numbers(l, ' '))
        .collect();
    assert_eq!(rates.len(), times.len());
    let mut msgs = Vec::new();
    for (k, (r, t)) in rates.iter().zip(&times).enumerate() {
        assert_eq!(t[0] as i64, week);
        let stamp = utc_ns(week, t[1]);
        msgs.push(Msg {
            topic: "/imu/data",
            schema: IMU,
            // 1.2–2.6 ms of driver and transport delay.
            log_ns: stamp + 1_200_000 + (k as i64 % 8) * 200_000,
            data: imu_msg(true, stamp, [r[0], -r[1], -r[2]], [r[3], -r[4], -r[5]]),
        });
    }
    for (k, l) in data_lines(&sim.join("gnss.txt")).iter().enumerate() {
        // sow lat lon h σn σe σd; ENU variances on the diagonal.
        let f = numbers(l, ' ');
        let stamp = utc_ns(week, f[0]);
        let var = |s: f64| s * s;
        msgs.push(Msg {
            topic: "/gnss/fix",
            schema: FIX,
            // A receiver's solution comes out 60–90 ms after its epoch.
            log_ns: stamp + 60_000_000 + (k as i64 % 4) * 10_000_000,
            data: fix_msg(
                true,
                stamp,
                0,
                [f[1], f[2], f[3]],
                [var(f[5]), var(f[4]), var(f[6])],
            ),
        });
        msgs.push(Msg {
            topic: "/diagnostics",
            schema: "diagnostic_msgs/msg/DiagnosticArray",
            log_ns: stamp + 500_000_000,
            data: vec![0, 1, 0, 0, 0, 0, 0, 0],
        });
    }
    // A recorder writes in arrival order.
    msgs.sort_by_key(|m| m.log_ns);
    // rosbag2 (the MCAP C++ writer's defaults): zstd chunks of 768 KiB.
    write_bag_chunked(&msgs, Some(mcap::Compression::Zstd), 768 * 1024)
}

#[test]
fn simulated_drive_as_a_ros2_bag_converts_and_fuses() {
    let dir = temp_dir("drive");
    let sim = dir.join("sim");
    // 3 min of the urban drive (turns, hills, up to 17 m/s), ADIS16465,
    // IMU at its native 200 Hz (instantaneous rates), 1 Hz RTK fixes.
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--quiet",
            "--scenario",
            "urban",
            "--duration",
            "180",
        ])
        .args(["--imu-grade", "adis16465", "--seed", "3"])
        .args(["--imu-record", "rate", "--decimation", "point", "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    let week = json(&sim.join("scenario.json"))["gps_week"]
        .as_i64()
        .unwrap();
    assert!(week >= 1930, "week {week}: GPS − UTC was not {LEAP_S} s");
    let bag = dir.join("drive.mcap");
    std::fs::write(&bag, bag_of(&sim, week)).unwrap();

    let conv = dir.join("conv");
    let (ok, out, err) = run(bin()
        .args(["convert", "--from", "mcap"])
        .arg(&bag)
        .arg("--output")
        .arg(&conv));
    assert!(ok, "{out}{err}");
    let s = json(&conv.join("summary.json"));
    assert_eq!(s["diagnostics"]["total"], 0, "{s}");
    let fixes = data_lines(&sim.join("gnss.txt"));
    assert_eq!(s["gnss_fixes"].as_u64(), Some(fixes.len() as u64));
    // The first IMU message only opens the first interval.
    assert_eq!(
        s["imu_samples"].as_u64(),
        Some(data_lines(&sim.join("imu_times_truth.txt")).len() as u64 - 1)
    );
    let lag = |topic: &str| {
        let t = s["ros2"]["topics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["topic"] == topic)
            .unwrap();
        t["log_time_minus_stamp"]["median_s"].as_f64().unwrap()
    };
    assert!((lag("/imu/data") - 0.002).abs() < 1e-6 && (lag("/gnss/fix") - 0.07).abs() < 1e-6);

    // The simulator's KF-GINS configuration (initial state from truth, IMU
    // noise, lever arm) next to the converted files, which have the same
    // names as its own.
    std::fs::copy(sim.join("kf-gins.yaml"), conv.join("kf-gins.yaml")).unwrap();
    let fuse_eval = |cfg: &Path, name: &str| {
        let out = dir.join(name);
        let (ok, text, err) = run(bin()
            .args(["fuse", "--config"])
            .arg(cfg)
            .arg("--output")
            .arg(&out));
        assert!(ok, "{text}{err}");
        horizontal_rms(&sim.join("truth.nav"), &out.join("navresult.nav"), &out)
    };
    let rms = fuse_eval(&conv.join("kf-gins.yaml"), "bag");
    // Bound from the physics: at each 1 Hz fix the filter is held to the
    // fix, whose horizontal error is σh = √(σn² + σe²) (RTK error is partly
    // time-correlated: not averaged away); in the ≤ 1 s to the next fix an
    // ADIS16465-grade INS drifts by δv·T + ½·δa·T² ≈ 2 cm + 1 cm (δv ≈
    // 2 cm/s; δa ≈ g × 0.05° tilt + 3 m/s² lateral × 0.2° heading), about
    // σh again. A wrong leap second, axis convention or rate unit is off
    // by metres to kilometres.
    let f = numbers(&fixes[0], ' ');
    let sd_h = f[4].hypot(f[5]);
    let native = fuse_eval(&sim.join("kf-gins.yaml"), "native");
    eprintln!(
        "bag: horizontal RMS {rms:.4} m (bound {:.4} m; the simulator's own files {native:.4} m)",
        2.0 * sd_h
    );
    assert!(
        rms < 2.0 * sd_h,
        "horizontal RMS {rms} m ≥ 2 × fix σh {sd_h} m"
    );
    // And within 10 % of the simulator's own KF-GINS files: the same
    // samples, as rate × interval there and by the trapezoid rule here.
    assert!(
        rms < 1.1 * native,
        "bag {rms} m vs the simulator's files {native} m"
    );
}
