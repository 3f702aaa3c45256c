//! Tests of the ULog reader and converter (module `ulog`), on files the
//! test writer (`testulog`) makes.

use std::path::Path;

use navsync::error::Diagnostics;
use navsync::io::riglog::{RigLogReader, RigRecord};
use navsync::testfiles::TestDir;

use super::*;
use crate::convert::{ConvertOptions, InputFormat, convert};
use crate::testulog::*;

/// 2024-03-01T00:00:00Z in Unix µs (GPS − UTC = 18 s then).
const UTC0_US: u64 = 1_709_251_200_000_000;
/// Boot time (µs) of UTC0.
const BOOT0_US: u64 = 120_000_000;

fn gyro(k: usize) -> [f64; 3] {
    let t = k as f64 * 0.004;
    [0.01 * t.sin(), -0.02, 0.3 * (0.5 * t).cos()]
}

fn accel(k: usize) -> [f64; 3] {
    [0.1 + 1e-3 * k as f64, -0.2, -9.81]
}

/// `secs` of a drive: sensor_combined at 250 Hz (instance 0, and a shorter
/// instance 1), vehicle_gps_position at 5 Hz arriving 80 ms after its
/// epoch, attitude 50 Hz, global and local position 10 Hz, a nested
/// esc_status, info, a parameter, a log string, a dropout and syncs.
fn drive(secs: usize, with_gps: bool, with_imu: bool) -> Vec<u8> {
    let mut w = UlogWriter::new(BOOT0_US - 1_000_000);
    w.info("sys_name", "PX4");
    w.info("ver_hw", "PX4_FMU_V5");
    for def in [
        SENSOR_COMBINED,
        VEHICLE_GPS_POSITION,
        VEHICLE_ATTITUDE,
        VEHICLE_GLOBAL_POSITION,
        VEHICLE_LOCAL_POSITION,
        ESC_REPORT,
        ESC_STATUS,
    ] {
        w.format(def);
    }
    w.param_i32("SENS_BOARD_ROT", 0);
    if with_imu {
        w.add(0, 0, "sensor_combined");
        w.add(1, 7, "sensor_combined");
    }
    if with_gps {
        w.add(0, 1, "vehicle_gps_position");
    }
    w.add(0, 2, "vehicle_attitude");
    w.add(0, 3, "vehicle_global_position");
    w.add(0, 4, "vehicle_local_position");
    w.add(0, 5, "esc_status");
    for k in 0..secs * 250 {
        let t_us = BOOT0_US + k as u64 * 4000;
        if with_imu {
            w.data_at(0, "sensor_combined", t_us, &|n, i| match n {
                "gyro_rad" => gyro(k)[i],
                "accelerometer_m_s2" => accel(k)[i],
                "gyro_integral_dt" => 4000.0,
                "accelerometer_timestamp_relative" => 0.0,
                _ => 0.0,
            });
            if k % 2 == 0 && k < 100 {
                w.data_at(7, "sensor_combined", t_us, &|_, _| 1.0);
            }
        }
        if k % 50 == 20 && with_gps {
            // The epoch at t_us − 80 ms, 5 Hz.
            let e = k / 50;
            let lat = 47.0 + 1e-5 * e as f64;
            w.data_at(1, "vehicle_gps_position", t_us, &|n, _| match n {
                "time_utc_usec" => (UTC0_US + (t_us - 80_000 - BOOT0_US)) as f64,
                "lat" => lat * 1e7,
                "lon" => 8.5e7,
                "alt" => 500_000.0,
                "alt_ellipsoid" => 548_000.0,
                "eph" => 0.8,
                "epv" => 1.5,
                "fix_type" => {
                    if e == 3 {
                        2.0
                    } else {
                        3.0
                    }
                }
                "vel_n_m_s" => 1.0,
                "vel_ned_valid" => 1.0,
                "s_variance_m_s" => 0.2,
                _ => 0.0,
            });
        }
        if k % 5 == 0 {
            // Yaw 30°: q = (cos 15°, 0, 0, sin 15°).
            let h = 15f64.to_radians();
            w.data_at(2, "vehicle_attitude", t_us, &|n, i| match (n, i) {
                ("q", 0) => h.cos(),
                ("q", 3) => h.sin(),
                _ => 0.0,
            });
        }
        if k % 25 == 1 {
            w.data_at(3, "vehicle_global_position", t_us, &|n, _| match n {
                "lat" => 47.0,
                "lon" => 8.5,
                "alt" => 500.0,
                "alt_ellipsoid" => 548.0,
                _ => 0.0,
            });
            w.data_at(4, "vehicle_local_position", t_us, &|n, _| match n {
                "vx" => 1.0,
                "vy" => 2.0,
                _ => 0.0,
            });
            w.data_at(5, "esc_status", t_us, &|n, _| match n {
                "esc[1].esc_rpm" => 1234.0,
                _ => 0.0,
            });
        }
        if k % 250 == 0 {
            w.sync();
        }
    }
    w.log(6, BOOT0_US, "[commander] Takeoff detected");
    w.dropout(12);
    w.buf
}

fn read_bytes(b: &[u8]) -> (Result<UlogData, navsync::error::Error>, Diagnostics) {
    let mut diag = Diagnostics::default();
    let r = read(b, Path::new("t.ulg"), &mut diag);
    (r, diag)
}

#[test]
fn nested_layout_flattens_with_padding_and_offsets() {
    let mut defs = HashMap::new();
    for d in [ESC_REPORT, ESC_STATUS] {
        let (n, f) = parse_format(d).unwrap();
        defs.insert(n, f);
    }
    let l = resolve(&defs, "esc_status").unwrap();
    // 8 + 2 + 1 + 1 + 4 padding = 16; esc_report = 8 + 4 + 4 + 4 + 1 + 1 + 2 = 24.
    assert_eq!(l.size, 16 + 8 * 24);
    assert_eq!(l.trailing_padding, 0);
    let rpm = l.slot("esc[1].esc_rpm").unwrap();
    assert_eq!((rpm.offset, rpm.ty), (16 + 24 + 16, BaseType::I32));
    assert!(l.fields.iter().all(|(n, _)| !n.contains("_padding")));
    let r = resolve(&defs, "esc_report").unwrap();
    assert_eq!((r.size, r.trailing_padding, r.min_len()), (24, 2, 22));
    // A definition containing itself, and an undefined type.
    let (n, f) = parse_format("loop:uint64_t timestamp;loop inner;").unwrap();
    defs.insert(n, f);
    assert!(
        resolve(&defs, "loop")
            .unwrap_err()
            .contains("nested deeper")
    );
    let (n, f) = parse_format("odd:uint64_t timestamp;quaternion q;").unwrap();
    defs.insert(n, f);
    assert!(resolve(&defs, "odd").unwrap_err().contains("'quaternion'"));
    // Arrays of an empty struct, nested: refused, not looped over.
    for d in ["e0:", "e1:e0[65535] a;", "e2:e1[65535] b;"] {
        let (n, f) = parse_format(d).unwrap();
        defs.insert(n, f);
    }
    assert!(
        resolve(&defs, "e2")
            .unwrap_err()
            .contains("'e0' has no fields")
    );
    assert!(parse_format("no colon").is_err());
    assert!(parse_format("x:float[0] a;").is_err());
    assert!(parse_format("x:float[99999999] a;").is_err());
}

#[test]
fn round_trip_values_and_times() {
    let bytes = drive(10, true, true);
    let (d, diag) = read_bytes(&bytes);
    let d = d.unwrap();
    assert!(diag.is_empty(), "{diag:?}");
    assert_eq!(d.version, 1);
    assert_eq!(d.info["sys_name"], "PX4");
    assert_eq!((d.dropouts, d.dropout_ms, d.truncated), (1, 12, false));
    let imu = &d.imu[&0];
    assert_eq!(imu.len(), 2500);
    assert_eq!(d.imu[&1].len(), 50);
    for (k, r) in imu.iter().enumerate() {
        assert_eq!(r.t_us, BOOT0_US + k as u64 * 4000);
        for i in 0..3 {
            // Logged as float32.
            assert_eq!(r.gyro_rad_s[i], gyro(k)[i] as f32 as f64);
            assert_eq!(r.accel_m_s2[i], accel(k)[i] as f32 as f64);
        }
    }
    let gps = &d.gps[&("vehicle_gps_position".to_string(), 0)];
    assert_eq!(gps.len(), 50);
    assert_eq!(gps[1].lat_deg, 470_000_100f64 * 1e-7);
    assert_eq!(gps[1].alt_ellipsoid_m, Some(548.0));
    assert_eq!(
        gps[1].time_utc_us + 80_000 - UTC0_US + BOOT0_US,
        gps[1].t_us
    );
    assert_eq!(gps[1].vel_ned_m_s, Some([1.0, 0.0, 0.0]));
    let esc = d.topics.iter().find(|t| t.topic == "esc_status").unwrap();
    assert_eq!((esc.messages, esc.layout_problem.clone()), (100, None));

    // Through convert: rig.csv read back by the rig-log reader.
    let dir = TestDir::new("ulog-round-trip");
    let input = dir.join("drive.ulg");
    std::fs::write(&input, &bytes).unwrap();
    let out = dir.join("conv");
    let s = convert(InputFormat::Ulog, &input, &out, &ConvertOptions::default()).unwrap();
    let u = s.ulog.as_ref().unwrap();
    assert_eq!((u.imu_samples, u.fixes), (2500, 49));
    assert_eq!(u.fix_drops["fix_type < 3 (no 3D fix)"], 1);
    assert_eq!(u.imu_rate_hz, 250.0);
    assert!(u.other_instances[0].contains("50 samples"), "{u:?}");
    let mut rd = Diagnostics::default();
    let mut rig = RigLogReader::open(&out.join("rig.csv"), &mut rd).unwrap();
    assert_eq!(rig.header().counter_bits, 64);
    let (mut n_imu, mut fixes) = (0, Vec::new());
    while let Some((rec, _)) = rig.next_record(&mut rd).unwrap() {
        match rec {
            RigRecord::Imu { counter, values } => {
                assert_eq!(counter, BOOT0_US + n_imu as u64 * 4000);
                assert_eq!(values[2], gyro(n_imu)[2] as f32 as f64);
                n_imu += 1;
            }
            RigRecord::Gnss(g) => fixes.push(g),
            other => panic!("unexpected {other:?}"),
        }
    }
    assert!(rd.is_empty(), "{rd:?}");
    assert_eq!((n_imu, fixes.len()), (2500, 49));
    // GPS time of validity: UTC + 18 s, by hifitime as the oracle.
    let utc = hifitime::Epoch::from_unix_seconds(UTC0_US as f64 * 1e-6);
    let (week, sow_ns) = utc
        .to_time_scale(hifitime::TimeScale::GPST)
        .to_time_of_week();
    let f = fixes[0];
    assert_eq!(
        (f.time.week(), f.time.ns_of_week()),
        (week as i64, sow_ns as i64)
    );
    assert_eq!(f.counter, BOOT0_US + 80_000);
    // σ written to 0.1 mm.
    assert_eq!((f.h_m, f.sd_m), (548.0, [0.8, 0.8, 1.5]));
    // autopilot.nav: yaw 30°, the velocity of vehicle_local_position, on
    // GPS time = boot + the fixes' (validity − arrival) = boot − 80 ms + …
    let nav = std::fs::read_to_string(out.join("autopilot.nav")).unwrap();
    let first: Vec<f64> = nav
        .lines()
        .next()
        .unwrap()
        .split_whitespace()
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(u.autopilot_nav_epochs, 100);
    assert!(
        (first[10] - 30.0).abs() < 1e-4 && first[8].abs() < 1e-6,
        "{first:?}"
    );
    assert_eq!((first[5], first[6]), (1.0, 2.0));
    let boot_us = BOOT0_US + 4000;
    let gps0 = f.time.seconds() - f.counter as f64 * 1e-6;
    let t_expect = boot_us as f64 * 1e-6 + gps0;
    assert!(
        (first[1] - t_expect.rem_euclid(604_800.0)).abs() < 1e-6,
        "{first:?}"
    );
}

#[test]
fn newer_sensor_gps_layout_in_degrees() {
    let mut w = UlogWriter::new(0);
    w.format(SENSOR_GPS);
    w.add(0, 0, "sensor_gps");
    w.data_at(0, "sensor_gps", 5_000_000, &|n, _| match n {
        "latitude_deg" => 47.123456789,
        "longitude_deg" => -122.5,
        "altitude_msl_m" => 12.25,
        "altitude_ellipsoid_m" => -20.5,
        "time_utc_usec" => UTC0_US as f64,
        "eph" => 0.5,
        "epv" => 0.9,
        "fix_type" => 6.0,
        _ => 0.0,
    });
    let (d, diag) = read_bytes(&w.buf);
    let d = d.unwrap();
    assert!(diag.is_empty(), "{diag:?}");
    let g = d.gps[&("sensor_gps".to_string(), 0)][0];
    assert_eq!((g.lat_deg, g.lon_deg), (47.123456789, -122.5));
    assert_eq!((g.alt_msl_m, g.alt_ellipsoid_m), (12.25, Some(-20.5)));
    assert_eq!((g.t_us, g.time_utc_us, g.fix_type), (5_000_000, UTC0_US, 6));
}

#[test]
fn truncated_file_keeps_what_came_before() {
    let bytes = drive(4, true, true);
    let cut = &bytes[..bytes.len() * 2 / 3 + 5];
    let (d, diag) = read_bytes(cut);
    let d = d.unwrap();
    assert!(d.truncated);
    assert!(
        diag.items[0].message.contains("file ends inside"),
        "{diag:?}"
    );
    let n = d.imu[&0].len();
    assert!(n > 500 && n < 1000, "{n}");
    // Header alone, or not a ULog.
    let (r, _) = read_bytes(&bytes[..10]);
    assert!(r.unwrap_err().to_string().contains("not a PX4 ULog"));
    let (r, _) = read_bytes(b"\x89MCAP0\r\n and more bytes than sixteen");
    assert!(r.unwrap_err().to_string().contains("not a PX4 ULog"));
}

#[test]
fn corrupt_size_resyncs_at_the_next_sync_message() {
    let mut bytes = drive(3, true, true);
    // Corrupt the size field of a data message about a third in: the
    // reader lands inside a message and must find the next sync.
    let mut at = bytes.len() / 3;
    while !(bytes[at + 2] == b'D' && bytes[at] == 50 && bytes[at + 1] == 0) {
        at += 1;
    }
    bytes[at] = 7;
    let (d, diag) = read_bytes(&bytes);
    let d = d.unwrap();
    assert!(d.skipped_bytes > 0, "{diag:?}");
    assert!(
        diag.items
            .iter()
            .any(|x| x.message.contains("not a ULog message letter")),
        "{diag:?}"
    );
    // Samples lost up to the next sync (1 s apart), the rest read.
    let imu = &d.imu[&0];
    assert!(imu.len() < 750 && imu.len() > 250, "{}", imu.len());
    assert_eq!(imu.last().unwrap().t_us, BOOT0_US + 749 * 4000);
    // An unknown message letter is skipped by its size, silently.
    let mut w = UlogWriter::new(0);
    w.msg(b'X', &[1, 2, 3]);
    w.format(SENSOR_COMBINED);
    let (d, diag) = read_bytes(&w.buf);
    assert!(diag.is_empty() && d.unwrap().messages[&'X'] == 1);
}

#[test]
fn unknown_layouts_and_missing_topics_are_named() {
    // sensor_combined defined without its accelerometer: reported, not read.
    let mut w = UlogWriter::new(0);
    w.format("sensor_combined:uint64_t timestamp;float[3] gyro_rad;");
    w.format(VEHICLE_GPS_POSITION);
    w.add(0, 0, "sensor_combined");
    w.add(0, 1, "vehicle_gps_position");
    w.data_at(0, "sensor_combined", 1, &|_, _| 0.0);
    let dir = TestDir::new("ulog-missing");
    let p = dir.join("a.ulg");
    std::fs::write(&p, &w.buf).unwrap();
    let e = convert(
        InputFormat::Ulog,
        &p,
        &dir.join("a"),
        &ConvertOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("a.ulg") && e.contains("no IMU data"), "{e}");
    // No GPS topic.
    let p = dir.join("b.ulg");
    std::fs::write(&p, drive(2, false, true)).unwrap();
    let e = convert(
        InputFormat::Ulog,
        &p,
        &dir.join("b"),
        &ConvertOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("no GPS topic") && e.contains("sensor_combined"),
        "{e}"
    );
    // No IMU topic.
    let p = dir.join("c.ulg");
    std::fs::write(&p, drive(2, true, false)).unwrap();
    let e = convert(
        InputFormat::Ulog,
        &p,
        &dir.join("c"),
        &ConvertOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no IMU data"), "{e}");
    // A data message of a type defined with an undefined nested type.
    let mut w = UlogWriter::new(0);
    w.msg(b'F', b"vehicle_attitude:uint64_t timestamp;quaternion q;");
    w.add(0, 0, "vehicle_attitude");
    w.msg(b'D', &[0, 0, 1, 2, 3]);
    let (d, diag) = read_bytes(&w.buf);
    let d = d.unwrap();
    assert!(
        d.topics[0]
            .layout_problem
            .as_ref()
            .unwrap()
            .contains("quaternion")
    );
    assert!(diag.items[0].message.contains("not read"), "{diag:?}");
}
