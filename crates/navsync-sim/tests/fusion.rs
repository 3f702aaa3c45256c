//! The fusion filter on the simulator's exact truth (moved here from the
//! core's `fusion/tests.rs` with the simulator).

use nalgebra::Vector3;
use navsync::earth::{Geodetic, LocalEarth};
use navsync::filter::gnss::GnssFix;
use navsync::filter::{ImuNoise, InitialStd};
use navsync::fusion::{Fusion, FusionConfig};
use navsync::time::GpsTime;
use navsync_sim::trajectory::{Segment, Trajectory, TrajectoryOptions};
use navsync_sim::truth::TruthGenerator;

/// A straight drive at 10 m/s with 1 Hz fixes of 2 cm, among which
/// bad ones: every bad fix is reported, none stops the run, and the
/// solution stays on the true track.
#[test]
fn bad_fixes_are_reported_and_leave_the_state_intact() {
    let traj = Trajectory::from_segments(
        Geodetic::from_deg(30.4, 114.5, 25.0),
        &[Segment::Cruise {
            duration_s: Some(80.0),
            distance_m: None,
        }],
        TrajectoryOptions {
            initial_speed_mps: 10.0,
            initial_heading_rad: 0.4,
            ..Default::default()
        },
    )
    .unwrap();
    let t0 = GpsTime::from_week_sow(2300, 1000.0);
    let mut truth = TruthGenerator::new(&traj, t0);
    // The initial σ and IMU noise of the fusion unit tests' set-up
    // (`navsync/src/fusion/tests.rs`, `setup`).
    let init_std = InitialStd {
        pos: Vector3::repeat(1.0),
        vel: Vector3::repeat(0.1),
        att: Vector3::repeat(0.01),
        gyro_bias: Vector3::repeat(1e-5),
        accel_bias: Vector3::repeat(1e-3),
        gyro_scale: Vector3::repeat(1e-4),
        accel_scale: Vector3::repeat(1e-4),
    };
    let noise = ImuNoise {
        arw: Vector3::repeat(1e-5),
        vrw: Vector3::repeat(1e-4),
        gyro_bias_sd: Vector3::repeat(1e-6),
        accel_bias_sd: Vector3::repeat(1e-5),
        gyro_scale_sd: Vector3::repeat(1e-5),
        accel_scale_sd: Vector3::repeat(1e-5),
        corr_time_s: 3600.0,
    };
    let mut cfg = FusionConfig::new(truth.state_at(t0).nav, init_std, noise, 200.0);
    cfg.init_std.pos = Vector3::repeat(0.05);
    let mut f = Fusion::new(cfg);
    let good = |truth: &mut TruthGenerator, t: GpsTime| GnssFix {
        time: t,
        pos: truth.state_at(t).nav.pos,
        pos_sd: Vector3::repeat(0.02),
        vel: None,
        vel_sd: None,
    };
    let mut worst: f64 = 0.0;
    let mut stale = None;
    for k in 1..=200 * 80 {
        let t = t0.add_seconds(k as f64 * 0.005);
        if k % 200 == 100 {
            let sec = k / 200 + 1;
            let tf = t0.add_seconds(sec as f64);
            let mut fix = good(&mut truth, tf);
            match sec {
                10 => fix.pos_sd = Vector3::new(0.0, 0.02, 0.02),
                12 => fix.pos.h_m = f64::NAN,
                14 => fix.pos_sd = Vector3::repeat(1e6),
                16 => fix.pos.lat_rad += 10_000.0 / 6.4e6,
                18 => {
                    // A burst of 20 identical fixes (same time).
                    for _ in 0..19 {
                        f.push_gnss(fix).unwrap();
                    }
                }
                // A receiver repeating its 30 s fix for 5 s while moving.
                30 => stale = Some(fix.pos),
                31..=35 => fix.pos = stale.unwrap(),
                _ => {}
            }
            f.push_gnss(fix).unwrap();
        }
        let (nav, sample) = truth.next(t);
        if let Some(o) = f.push_imu(&sample).unwrap() {
            let le = LocalEarth::new(&nav.pos, &nav.vel);
            let d = le.geodetic_delta_to_ned(
                o.nav.pos.lat_rad - nav.pos.lat_rad,
                o.nav.pos.lon_rad - nav.pos.lon_rad,
                o.nav.pos.h_m - nav.pos.h_m,
            );
            if k > 200 {
                worst = worst.max(d.norm());
            }
        }
    }
    let st = f.stats();
    assert_eq!(st.gnss_fixes_invalid, 3, "{st:?}");
    assert_eq!(st.gnss_fixes_duplicate, 19, "{st:?}");
    assert_eq!(st.gnss_fixes_stale, 5, "{st:?}");
    assert_eq!(st.gnss_fixes_rejected, 1, "{st:?}");
    let notes: Vec<String> = f
        .diagnostics()
        .items
        .iter()
        .map(|d| d.to_string())
        .collect();
    let has = |s: &str| notes.iter().any(|n| n.contains(s));
    assert!(has("must be positive numbers"), "{notes:?}");
    assert!(has("not a number"), "{notes:?}");
    assert!(has("no usable information"), "{notes:?}");
    // The 10 km jump: excluded by the fault monitor (a one-fix episode).
    assert!(has("excluded by the integrity monitor (jump"), "{notes:?}");
    assert!(has("repeats the time"), "{notes:?}");
    assert!(has("stale receiver output"), "{notes:?}");
    assert!(worst < 0.1, "worst position error {worst} m");
}

/// The set-up of the test above: a drive on `segments` at 10 m/s, its
/// truth generator and a fusion started on the true state.
fn drive(segments: &[Segment]) -> (Trajectory, GpsTime, FusionConfig) {
    let traj = Trajectory::from_segments(
        Geodetic::from_deg(30.4, 114.5, 25.0),
        segments,
        TrajectoryOptions {
            initial_speed_mps: 10.0,
            initial_heading_rad: 0.4,
            ..Default::default()
        },
    )
    .unwrap();
    let t0 = GpsTime::from_week_sow(2300, 1000.0);
    let mut truth = TruthGenerator::new(&traj, t0);
    let init_std = InitialStd {
        pos: Vector3::repeat(0.05),
        vel: Vector3::repeat(0.1),
        att: Vector3::repeat(0.01),
        gyro_bias: Vector3::repeat(1e-5),
        accel_bias: Vector3::repeat(1e-3),
        gyro_scale: Vector3::repeat(1e-4),
        accel_scale: Vector3::repeat(1e-4),
    };
    let noise = ImuNoise {
        arw: Vector3::repeat(1e-5),
        vrw: Vector3::repeat(1e-4),
        gyro_bias_sd: Vector3::repeat(1e-6),
        accel_bias_sd: Vector3::repeat(1e-5),
        gyro_scale_sd: Vector3::repeat(1e-5),
        accel_scale_sd: Vector3::repeat(1e-5),
        corr_time_s: 3600.0,
    };
    let cfg = FusionConfig::new(truth.state_at(t0).nav, init_std, noise, 200.0);
    (traj, t0, cfg)
}

/// An IMU gap of 20 s through a 90° turn with 1 Hz fixes going on: the
/// state is re-initialised from the fixes (one reported re-initialisation)
/// and the solution after the gap stays within 0.3 m of the truth (before:
/// the rates held over the gap put it tens of metres off and the robust
/// weighting rejected the good fixes).
#[test]
fn an_imu_gap_with_gnss_going_on_reinitialises_from_the_fixes() {
    let segments = [
        Segment::Cruise {
            duration_s: Some(20.0),
            distance_m: None,
        },
        Segment::Turn {
            angle_deg: 90.0,
            yaw_rate_deg_s: Some(9.0),
            radius_m: None,
            ramp_s: None,
        },
        Segment::Cruise {
            duration_s: Some(50.0),
            distance_m: None,
        },
    ];
    let (traj, t0, cfg) = drive(&segments);
    let mut truth = TruthGenerator::new(&traj, t0);
    let mut f = Fusion::new(cfg);
    let mut worst_after: f64 = 0.0;
    let (gap_from, gap_to) = (200 * 18, 200 * 38);
    for k in 1..=200 * 75 {
        let t = t0.add_seconds(k as f64 * 0.005);
        if k % 200 == 100 {
            let tf = t0.add_seconds((k / 200 + 1) as f64);
            let fix = GnssFix {
                time: tf,
                pos: truth.state_at(tf).nav.pos,
                pos_sd: Vector3::repeat(0.02),
                vel: None,
                vel_sd: None,
            };
            f.push_gnss(fix).unwrap();
        }
        let (nav, sample) = truth.next(t);
        if (gap_from..gap_to).contains(&k) {
            continue;
        }
        if let Some(o) = f.push_imu(&sample).unwrap()
            && k >= gap_to
        {
            let le = LocalEarth::new(&nav.pos, &nav.vel);
            let d = le.geodetic_delta_to_ned(
                o.nav.pos.lat_rad - nav.pos.lat_rad,
                o.nav.pos.lon_rad - nav.pos.lon_rad,
                o.nav.pos.h_m - nav.pos.h_m,
            );
            worst_after = worst_after.max(d.xy().norm());
        }
    }
    let st = f.stats();
    assert_eq!(st.gap_reinits, 1, "{st:?}");
    assert!(
        worst_after < 0.3,
        "worst horizontal error after the gap {worst_after} m"
    );
    let notes: Vec<String> = f
        .diagnostics()
        .items
        .iter()
        .map(|d| d.to_string())
        .collect();
    assert!(
        notes
            .iter()
            .any(|n| n.contains("re-initialised from the fixes")),
        "{notes:?}"
    );
}

/// A corrupt increment that reaches the filter (the readers refuse it;
/// this one is pushed directly) stops the run with the record's time and
/// values instead of writing a NaN state.
#[test]
fn a_broken_state_stops_the_run_naming_the_record() {
    let (traj, t0, cfg) = drive(&[Segment::Cruise {
        duration_s: Some(10.0),
        distance_m: None,
    }]);
    let mut truth = TruthGenerator::new(&traj, t0);
    let mut f = Fusion::new(cfg);
    let mut err = None;
    for k in 1..=200 * 5 {
        let t = t0.add_seconds(k as f64 * 0.005);
        let (_, mut sample) = truth.next(t);
        if k == 500 {
            sample.dtheta.x = 1e308;
        }
        match f.push_imu(&sample) {
            Ok(Some(o)) => {
                assert!(o.nav.pos.h_m.is_finite() && o.nav.vel.iter().all(|v| v.is_finite()))
            }
            Ok(None) => {}
            Err(e) => {
                err = Some((k, e.to_string()));
                break;
            }
        }
    }
    let (k, msg) = err.expect("the run must stop");
    assert_eq!(k, 500, "{msg}");
    assert!(
        msg.contains("broke down") && msg.contains("sow 1002.500000") && msg.contains("1e308"),
        "{msg}"
    );
}
