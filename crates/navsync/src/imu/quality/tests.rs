//! Tests of the IMU log quality check (`imu::quality`).

use super::*;
use crate::testutil::SyntheticImu;
use std::fmt::Write as _;

const RATE: f64 = 200.0;

/// 120 s at 200 Hz of rates: 40 s static, then motion (rate-csv rows:
/// time, gyro, accel).
fn clean_rows() -> Vec<(i64, [f64; 6])> {
    let mut imu = SyntheticImu::new(RATE, 1_000 * 1_000_000_000, 40.0, 3);
    (0..24_000)
        .map(|_| {
            let s = imu.next_rate();
            (
                s.time.ns(),
                [
                    s.gyro.x, s.gyro.y, s.gyro.z, s.accel.x, s.accel.y, s.accel.z,
                ],
            )
        })
        .collect()
}

fn write_rows(
    name: &str,
    rows: &[(i64, [f64; 6])],
    extra: &[(usize, &str)],
) -> crate::testfiles::TestDir {
    let mut s = String::from("time,gx,gy,gz,ax,ay,az\n");
    for (k, (t, v)) in rows.iter().enumerate() {
        for (at, line) in extra {
            if *at == k {
                s.push_str(line);
                s.push('\n');
            }
        }
        let _ = write!(s, "{}.{:09}", t / 1_000_000_000, t % 1_000_000_000);
        for x in v {
            let _ = write!(s, ",{x:.12e}");
        }
        s.push('\n');
    }
    crate::testfiles::temp_file("quality", name, s)
}

fn check(p: &Path) -> Result<QualityReport, Error> {
    let mut d = Diagnostics::default();
    check_file(
        p,
        Some(ImuLogFormat::RateCsv),
        QualityConfig::default(),
        &mut d,
    )
}

#[test]
fn clean_data_raises_nothing() {
    let p = write_rows("clean.csv", &clean_rows(), &[]);
    let r = check(&p).unwrap();
    assert_eq!(r.counts, Counts::default(), "{:#?}", r.events);
    assert!(r.events.is_empty());
    assert_eq!(r.accepted, 24_000);
    assert!((r.true_rate_hz - RATE).abs() < 1e-6);
    assert_eq!(r.round_rate_hz, Some(RATE));
    assert_eq!(r.verdict, Status::Pass, "{:#?}", r.criteria);
    // The static start is found and its Allan deviation gives back the
    // generator's ARW (0.15 deg/√h) and VRW (0.04 m/s/√h): 40 s hold 40
    // clusters at τ = 1 s, a ±25 % (≈ 3σ) band.
    let a = r.allan.as_ref().expect("static segment");
    assert!(
        a.segment.duration_s >= 35.0 && a.segment.duration_s <= 41.0,
        "{:?}",
        a.segment
    );
    for c in &a.channels[..3] {
        assert!(
            (c.random_walk_display / 0.15 - 1.0).abs() < 0.25,
            "{} {}",
            c.name,
            c.random_walk_display
        );
    }
    for c in &a.channels[3..] {
        assert!(
            (c.random_walk_display / 0.04 - 1.0).abs() < 0.25,
            "{} {}",
            c.name,
            c.random_walk_display
        );
    }
    assert!(r.channels.iter().all(|c| c.rounding_to_noise < 1e-6));
}

#[test]
fn every_injected_fault_is_found_by_kind() {
    let clean = clean_rows();
    let mut rows: Vec<(i64, [f64; 6])> = Vec::new();
    let mut injected = Counts::default();
    for (k, row) in clean.iter().enumerate() {
        let mut row = *row;
        // Gaps: 1 lost sample, 30 lost (0.155 s > 0.1 s), 5 lost.
        if k == 5000 || (9000..9030).contains(&k) || (14000..14005).contains(&k) {
            continue;
        }
        // Stale record: all six values of the previous record re-sent.
        if k == 16000 {
            row.1 = rows.last().unwrap().1;
        }
        // Stuck gyro y for 1 s in motion.
        if (18000..18200).contains(&k) {
            row.1[1] = clean[18000].1[1];
        }
        // Accel x clipped at a 4 g full scale for 10 samples.
        if (20000..20010).contains(&k) {
            row.1[3] = 39.2266;
        }
        // Spikes: static gyro x, moving gyro z and accel y, static accel z.
        match k {
            6000 => row.1[0] -= 0.3,
            22000 => row.1[2] += 0.5,
            23000 => row.1[4] += 20.0,
            7000 => row.1[5] += 1.0,
            // A one-sample rate spike after trapezoid conversion: two
            // equal halves (moving gyro y).
            21000 | 21001 => row.1[1] += 0.25,
            _ => {}
        }
        rows.push(row);
        // A duplicated sample and a duplicate time stamp.
        if k == 3000 {
            rows.push(row);
        }
        if k == 12000 {
            let mut other = row;
            other.1[0] += 1e-3;
            rows.push(other);
        }
        // A record re-sent out of order (an old one).
        if k == 11000 {
            rows.push(clean[10990]);
        }
    }
    injected.gaps = 3;
    injected.gaps_over_limit = 1;
    injected.lost_samples = 36;
    injected.duplicates = 2;
    injected.out_of_order = 1;
    injected.stale_records = 1;
    injected.stuck_segments = 1;
    injected.stuck_samples = 199;
    injected.saturation_events = 1;
    injected.saturated_samples = 10;
    injected.spikes = 5;
    injected.spike_records = 5;
    injected.malformed_lines = 3;
    let extra = [
        (100, "garbage line"),
        (2000, "1000.5,0.1,0.2"),
        (2500, "1012.5,0.1,nan,0.1,0.1,0.1,-9.8"),
    ];
    let p = write_rows("faults.csv", &rows, &extra);
    let r = check(&p).unwrap();
    for kind in KINDS {
        let got: Vec<usize> = r
            .events
            .iter()
            .filter(|e| e.kind == kind)
            .map(|e| e.line)
            .collect();
        assert_eq!(
            r.counts.of(kind),
            injected.of(kind),
            "{kind:?}: detected at lines {got:?}"
        );
    }
    assert_eq!(r.counts, injected, "{:#?}", r.events);
    let stuck = r
        .events
        .iter()
        .find(|e| e.kind == EventKind::Stuck)
        .unwrap();
    assert_eq!(stuck.channel, Some("gyro y"));
    let sat = r
        .events
        .iter()
        .find(|e| e.kind == EventKind::Saturation)
        .unwrap();
    assert_eq!(sat.channel, Some("accel x"));
    let spike_channels: Vec<_> = r
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Spike)
        .map(|e| e.channel.unwrap())
        .collect();
    assert_eq!(
        spike_channels,
        vec!["gyro x", "accel z", "gyro y", "gyro z", "accel y"]
    );
    assert!((r.longest_gap_s - 0.155).abs() < 1e-9);
    assert_eq!(r.verdict, Status::Fail);
    let gap_row = r
        .criteria
        .iter()
        .find(|c| c.rule.starts_with("no gap"))
        .unwrap();
    assert_eq!(gap_row.status, Status::Fail);
    // Loss: 36 of 24 000 expected; bad data: 3 + 2 + 1 + 1 + 5 + 10 + 199.
    assert!((r.loss_rate - 36.0 / 24_000.0).abs() < 1e-12);
    assert_eq!(r.bad_records, 221);
}

/// A shock clips the three accelerometer axes at once for 10 samples,
/// the last 5 of a stuck gyro's 200: three saturation findings of 10
/// samples each (30 channel samples, as `saturated_samples` counts
/// them) and 199 stuck samples, but 204 bad records (the stuck ones
/// and the 5 shock records after them), not 229.
#[test]
fn a_record_bad_in_several_channels_counts_once() {
    let clean = clean_rows();
    let rows: Vec<(i64, [f64; 6])> = clean
        .iter()
        .enumerate()
        .map(|(k, row)| {
            let mut row = *row;
            if (20095..20105).contains(&k) {
                row.1[3] = 39.2266;
                row.1[4] = -39.2266;
                row.1[5] = 39.2266;
            }
            // Gyro y stuck for 1 s up to the middle of the shock.
            if (19900..20100).contains(&k) {
                row.1[1] = clean[19900].1[1];
            }
            row
        })
        .collect();
    let p = write_rows("shock.csv", &rows, &[]);
    let r = check(&p).unwrap();
    assert_eq!(r.counts.saturation_events, 3, "{:#?}", r.events);
    assert_eq!(r.counts.saturated_samples, 30);
    assert_eq!(r.counts.stuck_samples, 199);
    assert_eq!(r.bad_records, 204);
}

#[test]
fn increments_are_checked_like_rates() {
    // The same clean signal as KF-GINS increments: nothing raised, the
    // true rate found, and a declared filter fails §1.4 with its delay.
    use crate::imu::convert::{RateRule, RateToIncrement};
    let mut buf = Vec::new();
    let mut conv = RateToIncrement::new(RateRule::Trapezoid);
    let mut imu = SyntheticImu::new(RATE, 1_000 * 1_000_000_000, 40.0, 4);
    for _ in 0..12_000 {
        if let Some(inc) = conv.push(&imu.next_rate()) {
            crate::io::kfgins::format_imu_line(&mut buf, &inc);
        }
    }
    let p = crate::testfiles::temp_file("quality", "inc.txt", buf);
    let mut d = Diagnostics::default();
    let cfg = QualityConfig {
        lowpass: Some(LowPassFilter::bartlett(4, 2000.0).unwrap()),
        ..Default::default()
    };
    let r = check_file(&p, None, cfg, &mut d).unwrap();
    assert_eq!(r.format, "kf-gins");
    assert_eq!(r.counts, Counts::default(), "{:#?}", r.events);
    assert!((r.true_rate_hz - RATE).abs() < 1e-6);
    let lp = r
        .criteria
        .iter()
        .find(|c| c.section.starts_with("§1.4"))
        .unwrap();
    assert_eq!(lp.status, Status::Fail);
    assert!(lp.measured.contains("1.500 ms"), "{}", lp.measured);
    assert_eq!(r.verdict, Status::Fail);
}

#[test]
fn a_time_reset_is_an_error_naming_its_line() {
    let mut rows = clean_rows();
    rows.truncate(2000);
    let later: Vec<(i64, [f64; 6])> = rows[..100].to_vec();
    rows.extend(later);
    let p = write_rows("reset.csv", &rows, &[]);
    let err = check(&p).unwrap_err().to_string();
    // Line 1 is the header: record k sits on line k + 2.
    assert!(err.contains("reset.csv:2002: time goes back"), "{err}");
}

#[test]
fn quantization_and_truncated_printing_are_told_apart() {
    // Values on a 1e-3 grid written with 3 decimals: the grid is the
    // print step, and against σ = 6e-4 the rounding (2.9e-4) fails §1.5-4.
    let mut rows = clean_rows();
    rows.truncate(4000);
    let mut s = String::new();
    for (t, v) in &rows {
        let _ = write!(s, "{}.{:09}", t / 1_000_000_000, t % 1_000_000_000);
        for x in v {
            let _ = write!(s, " {x:.3}");
        }
        s.push('\n');
    }
    let p = crate::testfiles::temp_file("quality", "trunc.txt", s);
    let r = check(&p).unwrap();
    let gx = &r.channels[0];
    assert_eq!(gx.print_step, 1e-3);
    assert!(gx.rounding_to_noise > 0.1, "{}", gx.rounding_to_noise);
    let row = r.criteria.iter().find(|c| c.section == "§1.5-4").unwrap();
    assert_eq!(row.status, Status::Fail);
    assert_eq!(
        quantization_step(&[
            1e-3, 2e-3, 1e-3, 3e-3, 1e-3, 1e-3, 2e-3, 1e-3, 5e-3, 1e-3, 1e-3, 2e-3, 4e-3, 1e-3,
            1e-3, 2e-3
        ]),
        Some(1e-3)
    );
}

#[test]
fn bad_input_through_the_parallel_reader_names_file_and_line() {
    let mut rows = clean_rows();
    rows.truncate(3000);
    let p = write_rows(
        "bad.csv",
        &rows,
        &[(10, "1000.05,0.1,zz,0,0,0,-9.8"), (20, "1000.1,1,2")],
    );
    let mut d = Diagnostics::default();
    let r = check_file(&p, None, QualityConfig::default(), &mut d).unwrap();
    assert_eq!(r.counts.malformed_lines, 2);
    let m: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
    assert!(
        m[0].contains("bad.csv:12: field 3: 'zz' is not a number"),
        "{m:?}"
    );
    assert!(m[1].contains("bad.csv:23: expected 7 fields"), "{m:?}");
    // Rates joined to increments: a mixed-format error at the join.
    let mut s = std::fs::read_to_string(&p).unwrap();
    for k in 0..100 {
        let _ = writeln!(
            s,
            "{:.3} 1e-5 2e-5 -3e-5 1e-4 2e-4 -4.9e-2",
            1015.0 + k as f64 * 0.005
        );
    }
    std::fs::write(&p, s).unwrap();
    let err = check(&p).unwrap_err().to_string();
    assert!(err.contains("bad.csv:3004: mixed formats"), "{err}");
    // Increments declared as rates.
    let err = check_file(
        &p,
        Some(ImuLogFormat::KfGins),
        QualityConfig::default(),
        &mut d,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("look like rates") && err.contains("--format rate-csv"),
        "{err}"
    );
}
