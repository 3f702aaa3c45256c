//! A PX4 ULog end to end: a simulated drive with known truth, written as
//! PX4's logger writes it (sensor_combined on the autopilot's drifting
//! boot clock, sensor_gps with UTC validity times arriving 60–90 ms late,
//! the autopilot's attitude and position), then `navsync process`.

mod common;

use std::path::Path;

use common::{bin, json, run, temp_dir};
use nalgebra::UnitQuaternion;
use navsync_receivers::testulog::*;

/// GPS − UTC since 2017-01-01 (IERS Bulletin C).
const LEAP_S: i64 = 18;
/// 1980-01-06T00:00:00Z, the GPS epoch, in Unix seconds.
const GPS_EPOCH_UNIX_S: i64 = 315_964_800;
/// The autopilot's crystal runs this fast (ppm).
const BOOT_DRIFT_PPM: f64 = 10.0;

fn rows(p: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            l.split([' ', ','])
                .filter(|s| !s.is_empty())
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect()
}

/// One message to write at its boot time.
enum Msg {
    Imu([f64; 6]),
    Gps(Vec<f64>, u64),
    Nav(Vec<f64>),
}

/// The simulator's drive as a ULog.
fn ulog_of(sim: &Path, week: i64) -> Vec<u8> {
    let imu: Vec<Vec<f64>> = rows(&sim.join("rig.csv"))
        .into_iter()
        .filter(|r| r.len() == 8 && r[0].is_nan()) // "imu,..." → NaN first
        .collect();
    let times = rows(&sim.join("imu_times_truth.txt"));
    assert_eq!(imu.len(), times.len());
    let sow0 = times[0][1];
    // Boot time (µs) of a GPS second of week: booted 5 s before the drive.
    let boot =
        |sow: f64| ((sow - sow0) * (1.0 + BOOT_DRIFT_PPM * 1e-6) * 1e6).round() as u64 + 5_000_000;
    let mut msgs: Vec<(u64, Msg)> = Vec::new();
    for (r, t) in imu.iter().zip(&times) {
        msgs.push((boot(t[1]), Msg::Imu([r[2], r[3], r[4], r[5], r[6], r[7]])));
    }
    for (k, f) in rows(&sim.join("gnss.txt")).into_iter().enumerate() {
        let utc_us =
            ((GPS_EPOCH_UNIX_S + week * 604_800 - LEAP_S) as f64 * 1e6 + f[0] * 1e6).round() as u64;
        msgs.push((
            boot(f[0] + 0.06 + (k % 4) as f64 * 0.01),
            Msg::Gps(f, utc_us),
        ));
    }
    for (k, n) in rows(&sim.join("truth.nav")).into_iter().enumerate() {
        if k % 20 == 0 {
            msgs.push((boot(n[1]), Msg::Nav(n)));
        }
    }
    msgs.sort_by_key(|m| m.0);
    let mut w = UlogWriter::new(1_000_000);
    w.info("sys_name", "PX4");
    for d in [
        SENSOR_COMBINED,
        SENSOR_GPS,
        VEHICLE_ATTITUDE,
        VEHICLE_GLOBAL_POSITION,
        VEHICLE_LOCAL_POSITION,
    ] {
        w.format(d);
    }
    for (id, name) in [
        "sensor_combined",
        "sensor_gps",
        "vehicle_attitude",
        "vehicle_global_position",
        "vehicle_local_position",
    ]
    .iter()
    .enumerate()
    {
        w.add(0, id as u16, name);
    }
    for (i, (t, m)) in msgs.iter().enumerate() {
        match m {
            Msg::Imu(v) => w.data_at(0, "sensor_combined", *t, &|n, i| match n {
                "gyro_rad" => v[i],
                "accelerometer_m_s2" => v[3 + i],
                "gyro_integral_dt" => 5000.0,
                _ => 0.0,
            }),
            Msg::Gps(f, utc_us) => w.data_at(1, "sensor_gps", *t, &|n, _| match n {
                "time_utc_usec" => *utc_us as f64,
                "latitude_deg" => f[1],
                "longitude_deg" => f[2],
                "altitude_ellipsoid_m" => f[3],
                "altitude_msl_m" => f[3] - 47.0,
                "eph" => f[4].max(f[5]),
                "epv" => f[6],
                "fix_type" => 6.0,
                _ => 0.0,
            }),
            Msg::Nav(n) => {
                let q = UnitQuaternion::from_euler_angles(
                    n[8].to_radians(),
                    n[9].to_radians(),
                    n[10].to_radians(),
                );
                let q = [q.w, q.i, q.j, q.k];
                w.data_at(2, "vehicle_attitude", *t, &|f, i| {
                    if f == "q" { q[i] } else { 0.0 }
                });
                w.data_at(3, "vehicle_global_position", *t, &|f, _| match f {
                    "lat" => n[2],
                    "lon" => n[3],
                    "alt" => n[4] - 47.0,
                    "alt_ellipsoid" => n[4],
                    _ => 0.0,
                });
                w.data_at(4, "vehicle_local_position", *t, &|f, _| match f {
                    "vx" => n[5],
                    "vy" => n[6],
                    "vz" => n[7],
                    _ => 0.0,
                });
            }
        }
        if i % 5000 == 0 {
            w.sync();
        }
    }
    w.buf
}

#[test]
fn simulated_drive_as_a_px4_ulog_processes() {
    let dir = temp_dir("drive");
    let sim = dir.join("sim");
    // An ideal integrating ADIS16465-class IMU at 200 Hz whose rates are
    // interval averages, as sensor_combined's; 1 Hz RTK fixes.
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--internal-rate", "0"])
        .args(["--scenario", "test-track", "--duration", "300"])
        .args(["--imu-grade", "adis16465", "--seed", "3"])
        .args(["--imu-record", "rate", "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    let week = json(&sim.join("scenario.json"))["gps_week"]
        .as_i64()
        .unwrap();
    assert!(week >= 1930, "week {week}: GPS − UTC was not {LEAP_S} s");
    let ulg = dir.join("flight.ulg");
    std::fs::write(&ulg, ulog_of(&sim, week)).unwrap();

    let sensor = dir.join("sensor.yaml");
    let (ok, out, err) = run(bin()
        .args(["init", "--preset", "adis16465", "--output"])
        .arg(&sensor));
    assert!(ok, "{out}{err}");
    // The simulator's antenna: 0.1 m forward, 0.5 m right, 1.2 m up.
    let text = std::fs::read_to_string(&sensor).unwrap().replace(
        "antenna_lever_m: [0.0, 0.0, 0.0]",
        "antenna_lever_m: [0.1, 0.5, -1.2]",
    );
    std::fs::write(&sensor, text).unwrap();

    let out = dir.join("out");
    let (ok, stdout, err) = run(bin()
        .arg("process")
        .arg(&ulg)
        .arg("--sensor")
        .arg(&sensor)
        .arg("--output")
        .arg(&out)
        .arg("--truth")
        .arg(sim.join("truth.nav")));
    assert!(ok, "{stdout}{err}");
    assert!(stdout.contains("PX4 ULog flight log"), "{stdout}");
    let conv = json(&out.join("convert/summary.json"));
    let n_fix = rows(&sim.join("gnss.txt")).len() as u64;
    assert_eq!(conv["ulog"]["fixes"].as_u64(), Some(n_fix), "{conv}");
    assert_eq!(conv["diagnostics"]["total"], 0, "{conv}");
    assert!(
        conv["ulog"]["autopilot_nav_epochs"].as_u64().unwrap() > 1000,
        "{conv}"
    );
    let p = json(&out.join("process.json"));
    let rms = p["eval"]["pos_horizontal_m"]["rms"].as_f64().unwrap();
    let f = &rows(&sim.join("gnss.txt"))[0];
    let sd_h = f[4].hypot(f[5]);
    let fuse = json(&out.join("fuse/summary.json"));
    eprintln!(
        "ULog: horizontal RMS {rms:.4} m (fix σh {sd_h:.4} m); time offset {}",
        fuse["time_offset_s"]
    );
    // Bound from the physics, as for the ROS 2 bag (tests/ros2_drive.rs):
    // held to 1 Hz fixes of σh, drifting about σh between them. A wrong
    // leap second, axis convention or boot → GPS map is off by metres.
    assert!(
        rms < 2.0 * sd_h,
        "horizontal RMS {rms} m ≥ 2 × fix σh {sd_h} m"
    );
    // Software sync maps boot time to GPS time up to the fastest fix
    // latency (60 ms here); the filter's time-offset state finds it.
    let offset = fuse["time_offset_s"].as_f64().unwrap();
    assert!(
        (offset - 0.060).abs() < 0.010,
        "time offset {offset} s, expected ≈ 0.060 s"
    );
}
