//! ArduPilot DataFlash logs through `convert`: logs written by the test
//! writer (`testdataflash`, independent of the parser's decoding) in the
//! 2014 `TimeMS` layout and the current `TimeUS`/`GMS`/`GWk`/`GPA` layout,
//! read back from `rig.csv` and `autopilot.nav`; bad input; the real
//! ArduCopter log of the shared data.

use std::path::{Path, PathBuf};

use navsync::Diagnostics;
use navsync::io::riglog::{RigLogReader, RigRecord};
use navsync::testfiles::TestDir;
use navsync::time::GpsTime;
use navsync_receivers::convert::{ConvertOptions, ConvertSummary, InputFormat, convert};
use navsync_receivers::detect::{FileKind, detect};
use navsync_receivers::geoid::Egm96Grid;
use navsync_receivers::testdataflash::{DataFlashWriter, LAYOUT_2014, LAYOUT_CURRENT};

const WEEK: f64 = 1823.0;
/// GPS ms of week of the first fix's validity, and its boot ms.
const TOW0_MS: f64 = 148_000_000.0;
const BOOT0_MS: f64 = 50_000.0;
/// Arrival after validity: 60 ms plus 0, 10 or 20 ms.
const LAT_MS: f64 = 60.0;
const LAT0: f64 = 42.8458113;
const LON0: f64 = -2.6885197;
const ALT_MSL: f64 = 530.44;

fn imu_values(k: usize) -> [f64; 6] {
    let x = k as f64;
    [
        0.01 * (x * 0.1).sin(),
        -0.02,
        0.003 * x.cos(),
        0.1,
        -0.05,
        -9.8 + 0.001 * x,
    ]
}

/// The boot clock runs 100 ppm fast.
const BOOT_RATE: f64 = 1.0001;

/// Boot ms (whole: TimeMS, T and SMS are integers) at which fix `k` arrives.
fn arrival_ms(k: usize) -> f64 {
    (BOOT0_MS + 200.0 * k as f64 * BOOT_RATE + LAT_MS + 10.0 * (k % 3) as f64).round()
}

/// 20 s of a 2014 log: IMU at 50 Hz, GPS at 5 Hz (fix 7 without a 3D fix)
/// with a UBX3 before each, EKF1 and AHR2 at 10 Hz.
fn log_2014() -> Vec<u8> {
    let mut w = DataFlashWriter::with_layouts(&LAYOUT_2014);
    for k in 0..1000usize {
        let t = BOOT0_MS - 100.0 + 20.0 * k as f64;
        let v = imu_values(k);
        w.msg("IMU", &[t, v[0], v[1], v[2], v[3], v[4], v[5]]);
        if k % 10 == 5 {
            // The fix valid 200 ms earlier arrives now (k / 10 = fix index).
            let f = k / 10;
            let status = if f == 7 { 2.0 } else { 3.0 };
            w.msg("UBX3", &[arrival_ms(f), 0.0, 0.8, 1.2, 0.3]);
            w.msg(
                "GPS",
                &[
                    status,
                    TOW0_MS + 200.0 * f as f64,
                    WEEK,
                    9.0,
                    1.97,
                    LAT0 + 1e-6 * f as f64,
                    LON0,
                    0.0,
                    ALT_MSL,
                    0.04,
                    0.0,
                    0.01,
                    arrival_ms(f),
                ],
            );
        }
        if k % 5 == 0 {
            w.msg("EKF1", &[t, -0.12, -1.54, 350.0, 0.1, 0.2, -0.3]);
            w.msg("AHR2", &[t, -0.12, -1.54, 350.0, ALT_MSL, LAT0, LON0]);
        }
    }
    w.bytes
}

/// 20 s of a current log: one IMU message with two instances (instance 1
/// every other sample), GPS + GPA (SMS = arrival), XKF1 of two cores.
fn log_current() -> Vec<u8> {
    let mut w = DataFlashWriter::with_layouts(&LAYOUT_CURRENT);
    for k in 0..1000usize {
        let t_us = (BOOT0_MS - 100.0 + 20.0 * k as f64) * 1e3;
        let v = imu_values(k);
        w.msg("IMU", &[t_us, 0.0, v[0], v[1], v[2], v[3], v[4], v[5]]);
        if k % 2 == 0 {
            w.msg("IMU", &[t_us, 1.0, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0]);
        }
        if k % 10 == 5 {
            let f = k / 10;
            // Logged 5 ms after it arrived.
            let logged_us = (arrival_ms(f) + 5.0) * 1e3;
            w.msg(
                "GPS",
                &[
                    logged_us,
                    0.0,
                    if f == 7 { 1.0 } else { 3.0 },
                    TOW0_MS + 200.0 * f as f64,
                    WEEK,
                    12.0,
                    0.9,
                    LAT0 + 1e-6 * f as f64,
                    LON0,
                    ALT_MSL,
                    0.04,
                    0.0,
                    0.01,
                    0.0,
                    1.0,
                ],
            );
            w.msg(
                "GPA",
                &[
                    logged_us,
                    0.0,
                    1.2,
                    0.55,
                    0.9,
                    0.2,
                    0.0,
                    1.0,
                    arrival_ms(f),
                    200.0,
                ],
            );
        }
        if k % 5 == 0 {
            for core in [0.0, 1.0] {
                w.msg(
                    "XKF1",
                    &[t_us, core, -0.12 + core, -1.54, 350.0, 0.1, 0.2, -0.3],
                );
            }
            w.msg("AHR2", &[t_us, -0.12, -1.54, 350.0, ALT_MSL, LAT0, LON0]);
        }
    }
    w.bytes
}

fn run(name: &str, bytes: &[u8]) -> (TestDir, PathBuf, Result<ConvertSummary, navsync::Error>) {
    let dir = TestDir::new(&format!("dataflash-{name}"));
    let input = dir.join("log.BIN");
    std::fs::write(&input, bytes).unwrap();
    let out = dir.join("out");
    let s = convert(
        InputFormat::DataFlash,
        &input,
        &out,
        &ConvertOptions::default(),
    );
    (dir, out, s)
}

fn rig_records(path: &Path) -> Vec<RigRecord> {
    let mut diag = Diagnostics::default();
    let mut r = RigLogReader::open(path, &mut diag).unwrap();
    assert_eq!(r.header().counter_hz, 1e6);
    assert_eq!(r.header().counter_bits, 64);
    let mut v = Vec::new();
    while let Some((rec, _)) = r.next_record(&mut diag).unwrap() {
        v.push(rec);
    }
    assert!(diag.is_empty(), "{diag:?}");
    v
}

/// The rig log holds every IMU sample and fix, as written.
fn check_rig(out: &Path, imu_us: impl Fn(usize) -> u64, sd: [f64; 3]) {
    let recs = rig_records(&out.join("rig.csv"));
    let imu: Vec<_> = recs
        .iter()
        .filter_map(|r| match r {
            RigRecord::Imu { counter, values } => Some((*counter, *values)),
            _ => None,
        })
        .collect();
    assert_eq!(imu.len(), 1000);
    for (k, (c, v)) in imu.iter().enumerate() {
        assert_eq!(*c, imu_us(k));
        for (a, b) in v.iter().zip(imu_values(k)) {
            assert_eq!(*a, b as f32 as f64);
        }
    }
    let gnss: Vec<_> = recs
        .iter()
        .filter_map(|r| match r {
            RigRecord::Gnss(g) => Some(*g),
            _ => None,
        })
        .collect();
    // 100 fixes, fix 7 without a 3D fix.
    assert_eq!(gnss.len(), 99);
    let mut geoid = Egm96Grid::new();
    for g in &gnss {
        let f = ((g.time.ns_of_week() as f64 * 1e-6 - TOW0_MS) / 200.0).round() as usize;
        assert_ne!(f, 7);
        assert_eq!(g.time.week(), WEEK as i64);
        assert_eq!(g.counter, (arrival_ms(f) * 1e3) as u64);
        assert!((g.lat_deg - (LAT0 + 1e-6 * f as f64)).abs() < 1e-7);
        let n = geoid.separation_m(g.lat_deg, LON0).unwrap();
        assert!(
            (g.h_m - (ALT_MSL + n)).abs() < 1e-4,
            "{} vs {}",
            g.h_m,
            ALT_MSL + n
        );
        for (a, b) in g.sd_m.iter().zip(sd) {
            assert!((a - b).abs() < 1e-6, "{:?}", g.sd_m);
        }
    }
    // Records by boot time (arrival order).
    assert!(recs.windows(2).all(|w| w[0].counter() <= w[1].counter()));
}

/// autopilot.nav on GPS time: boot b → first validity + (b − its boot) −
/// the fastest latency (unobservable from arrivals alone, as in sync).
fn check_nav(out: &Path) {
    let text = std::fs::read_to_string(out.join("autopilot.nav")).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 200);
    let g0 = GpsTime::from_week_ns(WEEK as i64, TOW0_MS as i64 * 1_000_000);
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r.len(), 11);
        let boot_ms = BOOT0_MS - 100.0 + 100.0 * k as f64;
        let want = g0.add_seconds(((boot_ms - BOOT0_MS) / BOOT_RATE - LAT_MS) * 1e-3);
        // The rate is a least-squares line through arrivals that jitter
        // by 20 ms: good to a few percent of that over 20 s.
        assert!(
            (r[1] - want.sow()).abs() < 1e-3,
            "{} vs {}",
            r[1],
            want.sow()
        );
        assert!((r[8] + 0.12).abs() < 1e-9 && (r[9] + 1.54).abs() < 1e-9);
        assert!((r[10] + 10.0).abs() < 1e-9, "yaw 350° is −10°");
        assert!((r[5] - 0.1).abs() < 1e-6 && (r[7] + 0.3).abs() < 1e-6);
    }
}

#[test]
fn layout_2014_round_trip() {
    let bytes = log_2014();
    let (dir, out, s) = run("2014", &bytes);
    let s = s.unwrap();
    assert_eq!(detect(&dir.join("log.BIN")).unwrap(), FileKind::DataFlash);
    check_rig(
        &out,
        |k| ((BOOT0_MS - 100.0 + 20.0 * k as f64) * 1e3) as u64,
        [0.8, 0.8, 1.2],
    );
    check_nav(&out);
    let d = s.dataflash.as_ref().unwrap();
    assert!(d.time_field.starts_with("TimeMS"));
    assert_eq!(d.gps_drops.get("no 3D fix (Status < 3)"), Some(&1));
    assert!(d.sigma_source.starts_with("UBX3"), "{}", d.sigma_source);
    assert_eq!(
        (s.gnss_fixes, s.gnss_default_sd, s.imu_samples),
        (99, 0, 1000)
    );
    let ppm = d.boot_clock_error_ppm.unwrap();
    // 100 ppm; a least-squares rate through 20 ms of arrival jitter over
    // 20 s is uncertain by about 50 ppm (1σ).
    assert!((ppm - 100.0).abs() < 50.0, "{ppm}");
    let lat = d.fix_latency_above_fastest_ms.unwrap();
    assert!((lat.max - 20.0).abs() < 2.0 && lat.min == 0.0, "{lat:?}");
    assert!(s.diagnostics.is_empty(), "{:?}", s.diagnostics);
    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(json.contains("\"dataflash\"") && json.contains("\"EKF1\": 200"));
}

#[test]
fn layout_current_round_trip() {
    let (_dir, out, s) = run("current", &log_current());
    let s = s.unwrap();
    check_rig(
        &out,
        |k| ((BOOT0_MS - 100.0 + 20.0 * k as f64) * 1e3) as u64,
        [0.55, 0.55, 0.9],
    );
    check_nav(&out);
    let d = s.dataflash.as_ref().unwrap();
    assert!(d.time_field.starts_with("TimeUS"));
    assert_eq!(d.imu_instances.get("IMU[0]"), Some(&1000));
    assert_eq!(d.imu_instances.get("IMU[1]"), Some(&500));
    assert_eq!(d.imu_instance_used, Some(0));
    // Every fix's arrival is GPA.SMS, not the 5 ms later TimeUS.
    assert_eq!(d.arrival_from_gpa_sms, 99);
    assert_eq!(d.gps_drops.get("no 3D fix (Status < 3)"), Some(&1));
    assert!(d.estimate_source.as_ref().unwrap().starts_with("XKF1"));
}

#[test]
fn truncated_garbage_and_unknown_layouts_are_reported() {
    let mut bytes = log_2014();
    // Garbage and a message of a type no FMT described, early on.
    let at = 89 * 6 + 31 + 43 + 25; // after the first IMU, EKF1, AHR2
    let mut junk = b"\x00\x01garbage".to_vec();
    junk.extend_from_slice(&[0xA3, 0x95, 200, 1, 2, 3, 4]);
    bytes.splice(at..at, junk);
    // Cut the last message short.
    bytes.truncate(bytes.len() - 7);
    let (_dir, out, s) = run("bad", &bytes);
    let s = s.unwrap();
    let d = s.dataflash.as_ref().unwrap();
    assert_eq!(d.parse.unknown_type_messages.get(&200), Some(&1));
    assert_eq!(d.parse.garbage_bytes, 9);
    assert!(d.parse.truncated_at.is_some());
    let msgs: Vec<&str> = s
        .diagnostics
        .items
        .iter()
        .map(|d| d.message.as_str())
        .collect();
    assert!(msgs.iter().any(|m| m.contains("cut short")), "{msgs:?}");
    assert!(
        msgs.iter().any(|m| m.contains("type 200 has no FMT")),
        "{msgs:?}"
    );
    assert!(
        msgs.iter().any(|m| m.contains("outside any message")),
        "{msgs:?}"
    );
    // Everything else is intact: the message cut was the last IMU sample.
    assert_eq!((s.imu_samples, s.gnss_fixes), (999, 99));
    assert!(out.join("rig.csv").is_file());
}

#[test]
fn log_without_gps_is_imu_only_and_without_imu_an_error() {
    let mut w = DataFlashWriter::with_layouts(&LAYOUT_2014);
    for k in 0..100usize {
        let v = imu_values(k);
        w.msg(
            "IMU",
            &[20.0 * k as f64, v[0], v[1], v[2], v[3], v[4], v[5]],
        );
    }
    let (_dir, out, s) = run("nogps", &w.bytes);
    let s = s.unwrap();
    assert_eq!((s.imu_samples, s.gnss_fixes), (100, 0));
    assert!(s.no_fix_message().is_none());
    assert!(
        s.diagnostics
            .items
            .iter()
            .any(|d| d.message.contains("IMU only"))
    );
    assert!(!out.join("autopilot.nav").exists());

    let mut w = DataFlashWriter::with_layouts(&LAYOUT_2014);
    w.msg(
        "GPS",
        &[
            3.0, TOW0_MS, WEEK, 9.0, 1.0, LAT0, LON0, 0.0, ALT_MSL, 0.0, 0.0, 0.0, 1000.0,
        ],
    );
    let (_dir, _out, s) = run("noimu", &w.bytes);
    let e = s.unwrap_err().to_string();
    assert!(
        e.contains("log.BIN") && e.contains("no IMU samples") && e.contains("GPS"),
        "{e}"
    );
    // Not a DataFlash log at all: not recognised as one.
    let (dir, _out, _s) = run("text", b"hello\n");
    assert!(detect(&dir.join("log.BIN")).is_err());
}

/// The ArduCopter log of the shared data (its README: 7 600 IMU samples,
/// 761 3D fixes in week 1823, UBX3 hAcc median 0.65 m, the boot clock
/// about 25 ppm slow).
#[test]
fn real_arducopter_log() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-logs/ardupilot-copter-dataflash/16.BIN");
    if !path.is_file() {
        eprintln!("skipped: {} not found", path.display());
        return;
    }
    assert_eq!(detect(&path).unwrap(), FileKind::DataFlash);
    let dir = TestDir::new("dataflash-real");
    let s = convert(
        InputFormat::DataFlash,
        &path,
        &dir,
        &ConvertOptions::default(),
    )
    .unwrap();
    let d = s.dataflash.as_ref().unwrap();
    assert_eq!(
        (s.imu_samples, s.gnss_fixes, s.gnss_default_sd),
        (7600, 761, 0)
    );
    assert_eq!(d.parse.garbage_bytes, 0);
    assert!(d.sigma_source.starts_with("UBX3"));
    let recs = rig_records(&dir.join("rig.csv"));
    let mut h: Vec<f64> = recs
        .iter()
        .filter_map(|r| match r {
            RigRecord::Gnss(g) => {
                assert_eq!(g.time.week(), 1823);
                Some(g.sd_m[0])
            }
            _ => None,
        })
        .collect();
    h.sort_by(f64::total_cmp);
    assert!(
        (h[h.len() / 2] - 0.65).abs() < 0.05,
        "median hAcc {}",
        h[h.len() / 2]
    );
    let ppm = d.boot_clock_error_ppm.unwrap();
    // |25| ppm; the boot clock runs fast: GPS − boot falls over the log.
    assert!((15.0..35.0).contains(&ppm), "boot clock {ppm} ppm");
    assert!(d.estimate_rows > 7000, "{}", d.estimate_rows);
}
