use super::*;
use crate::testutil::TurningAtRest;

pub(super) fn setup(latency: LatencyMode) -> (TurningAtRest, FusionConfig) {
    let m = TurningAtRest {
        pos: Geodetic::from_deg(30.4, 114.5, 25.0),
        yaw0_rad: 0.3,
        rate_rad_s: 0.05,
        t0: GpsTime::from_week_sow(2300, 1000.0),
    };
    let std = InitialStd {
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
    let mut nav0 = m.state(m.t0);
    nav0.pos.h_m += 0.5; // an initial error for the fixes to correct
    let mut cfg = FusionConfig::new(nav0, std, noise, 200.0);
    cfg.latency = latency;
    (m, cfg)
}

/// Runs 30 s with 1 Hz fixes arriving `latency_s` after validity.
fn run(latency: LatencyMode, latency_s: f64) -> (NavState, NavState, FusionStats) {
    let (m, cfg) = setup(latency);
    let mut f = Fusion::new(cfg);
    let dt = 5_000_000;
    let mut t = m.t0;
    let mut last = None;
    let mut next_fix = m.t0.add_seconds(1.0);
    for _ in 0..(30 * 200) {
        let s = m.sample(t + -dt, t);
        let fix_arrival = next_fix.add_seconds(if latency == LatencyMode::Offline {
            -0.5
        } else {
            latency_s
        });
        if t >= fix_arrival {
            let truth = m.state(next_fix);
            f.push_gnss(GnssFix {
                time: next_fix,
                pos: truth.pos,
                pos_sd: Vector3::repeat(0.02),
                vel: None,
                vel_sd: None,
            })
            .unwrap();
            next_fix = next_fix.add_seconds(1.0);
        }
        if let Some(o) = f.push_imu(&s).unwrap() {
            last = Some(o.nav);
        }
        t = t + dt;
    }
    let nav = last.unwrap();
    (nav, m.state(nav.time), f.stats().clone())
}

#[test]
fn every_latency_mode_converges_on_a_consistent_scenario() {
    for (mode, lat) in [
        (LatencyMode::Offline, 0.0),
        (LatencyMode::Naive, 0.1),
        (LatencyMode::FixedLag { lag_s: 0.2 }, 0.1),
        (LatencyMode::Extrapolate, 0.1),
        (LatencyMode::DelayedState { max_latency_s: 0.5 }, 0.1),
    ] {
        let (nav, truth, stats) = run(mode, lat);
        let le = LocalEarth::new(&truth.pos, &truth.vel);
        let dp = le.geodetic_delta_to_ned(
            nav.pos.lat_rad - truth.pos.lat_rad,
            nav.pos.lon_rad - truth.pos.lon_rad,
            nav.pos.h_m - truth.pos.h_m,
        );
        // At rest latency costs nothing: all modes remove the 0.5 m
        // initial height error to well below the fixes' 2 cm.
        assert!(dp.norm() < 0.01, "{mode:?}: {dp}");
        assert!(stats.gnss_fixes_used >= 28, "{mode:?}: {stats:?}");
        assert_eq!(stats.gnss_fixes_late, 0, "{mode:?}");
    }
}

/// Runs 60 s at rest with 1 Hz fixes displaced north by `shift(t)` (m,
/// t in s from the start); returns the final north error against the
/// fixes' track and the statistics.
fn run_with_shifted_fixes(shift: impl Fn(f64) -> f64) -> (f64, FusionStats) {
    run_shifted(GnssWeighting::Gate { prob: 0.9999 }, shift)
}

fn run_shifted(weighting: GnssWeighting, shift: impl Fn(f64) -> f64) -> (f64, FusionStats) {
    let (m, mut cfg) = setup(LatencyMode::Offline);
    cfg.gnss_weighting = weighting;
    let mut f = Fusion::new(cfg);
    let dt = 5_000_000;
    let mut t = m.t0;
    let mut next_fix = m.t0.add_seconds(1.0);
    let mut last = None;
    for _ in 0..(60 * 200) {
        if t >= next_fix.add_seconds(-0.5) {
            let mut pos = m.state(next_fix).pos;
            let le = LocalEarth::new(&pos, &Vector3::zeros());
            pos.lat_rad += shift(next_fix.seconds_since(m.t0)) / le.rm_h;
            f.push_gnss(GnssFix {
                time: next_fix,
                pos,
                pos_sd: Vector3::repeat(0.02),
                vel: None,
                vel_sd: None,
            })
            .unwrap();
            next_fix = next_fix.add_seconds(1.0);
        }
        if let Some(o) = f.push_imu(&m.sample(t + -dt, t)).unwrap() {
            last = Some(o.nav);
        }
        t = t + dt;
    }
    let nav = last.unwrap();
    let truth = m.state(nav.time);
    let le = LocalEarth::new(&truth.pos, &truth.vel);
    let north = (nav.pos.lat_rad - truth.pos.lat_rad) * le.rm_h;
    (
        north - shift(nav.time.seconds_since(m.t0)),
        f.stats().clone(),
    )
}

#[test]
fn smooth_drift_past_the_gate_is_followed_and_a_jump_is_rejected() {
    // The fixes accelerate away from the INS at 0.05 m/s² from 20 s on:
    // to this overconfident filter (accelerometer bias σ 1 mm/s²) it is
    // an error its model left out, growing smoothly past the gate while
    // consecutive fixes agree. The filter must follow the fixes.
    let (err, stats) = run_with_shifted_fixes(|t| 0.025 * (t - 20.0).max(0.0).powi(2));
    // One drift episode: accepted once (the cooldown keeps a
    // disagreement that comes back from inflating P again and again).
    assert_eq!(stats.gnss_fixes_accepted_consistent, 1, "{stats:?}");
    assert!(
        stats.gnss_fixes_rejected <= 3 && stats.gate_reopened == 0,
        "{stats:?}"
    );
    assert!(err.abs() < 0.1, "north error against the fixes {err} m");
    // A 3 m jump for three epochs is a GNSS fault: all three rejected,
    // none taken for drift, and the solution stays on the true track.
    let (err, stats) =
        run_with_shifted_fixes(|t| if (30.0..33.0).contains(&t) { 3.0 } else { 0.0 });
    assert_eq!(stats.gnss_fixes_rejected, 3, "{stats:?}");
    assert_eq!(stats.gnss_fixes_accepted_consistent, 0, "{stats:?}");
    assert!(err.abs() < 0.01, "north error {err} m");
}

/// Robust weighting (the default): the same two cases as the gate.
#[test]
fn robust_weighting_follows_smooth_drift_and_rejects_a_jump() {
    let robust = GnssWeighting::default();
    let (err, stats) = run_shifted(robust, |t| 0.025 * (t - 20.0).max(0.0).powi(2));
    assert!(
        err.abs() < 0.1,
        "north error against the fixes {err} m; {stats:?}"
    );
    // A 3 m jump for three epochs: three fixes that agree with each
    // other, but the run began with a jump, so it is a fault.
    let (err, stats) = run_shifted(
        robust,
        |t| {
            if (30.0..33.0).contains(&t) { 3.0 } else { 0.0 }
        },
    );
    assert_eq!(stats.gnss_fixes_rejected, 3, "{stats:?}");
    assert_eq!(stats.gnss_fixes_accepted_consistent, 0, "{stats:?}");
    assert!(err.abs() < 0.01, "north error {err} m");
    // Moderately bad fixes (0.3 m jumps, 15 stated σ) for ten epochs
    // are used, down-weighted, and move the solution by less than their
    // error.
    let (err, stats) = run_shifted(robust, |t| {
        if (30.0..40.0).contains(&t) {
            if (t as i64) % 2 == 0 { 0.3 } else { -0.3 }
        } else {
            0.0
        }
    });
    assert!(stats.gnss_fixes_downweighted >= 5, "{stats:?}");
    assert!(err.abs() < 0.01, "north error {err} m; {stats:?}");
}

/// Robust weighting against fixes that leave the INS faster than its
/// model allows for the whole run: an acceleration of 0.2 m/s² (a 1.2°
/// tilt error) or a growing one. One covariance inflation may not be
/// enough (the model cannot hold the drift) and the cooldown forbids a
/// second, so the INS used to be left to drift 160–640 m from 2 cm fixes.
#[test]
fn robust_weighting_follows_a_drift_its_model_cannot_hold() {
    let robust = GnssWeighting::default();
    type Shift = fn(f64) -> f64;
    let drifts: [(&str, Shift); 3] = [
        ("0.2 m/s²", |t| 0.1 * (t - 20.0).max(0.0).powi(2)),
        ("0.1 m/s² growing 0.02 m/s³", |t| {
            let u = (t - 20.0).max(0.0);
            0.05 * u * u + 0.003 * u.powi(3)
        }),
        ("0.06 m/s³", |t| 0.01 * (t - 20.0).max(0.0).powi(3)),
    ];
    for (name, shift) in drifts {
        // Every fix at its stated σ (KF-GINS) lags such a drift by
        // 0.6–1.7 m; the robust weighting must follow at least as closely.
        let (lag_off, _) = run_shifted(GnssWeighting::Off, shift);
        let (err, stats) = run_shifted(robust, shift);
        assert!(
            err.abs() <= lag_off.abs().max(0.1),
            "{name}: north error against the fixes {err} m (every fix: {lag_off} m); {stats:?}"
        );
        assert!(
            stats.gnss_fixes_accepted_consistent >= 1,
            "{name}: {stats:?}"
        );
    }
}

/// 10 Hz fixes on the true track, each pushed 100 ms after its time:
/// pushes the fix `next_fix` when `t` reached that, and moves it on.
fn push_fix_100ms_late(f: &mut Fusion, m: &TurningAtRest, t: GpsTime, next_fix: &mut GpsTime) {
    if t >= next_fix.add_seconds(0.1) {
        f.push_gnss(GnssFix {
            time: *next_fix,
            pos: m.state(*next_fix).pos,
            pos_sd: Vector3::repeat(0.02),
            vel: None,
            vel_sd: None,
        })
        .unwrap();
        *next_fix = next_fix.add_seconds(0.1);
    }
}

/// Odometer updates of a 30 s run at rest (10 Hz speeds of 0 m/s, 10 Hz
/// fixes 100 ms late) in `mode`.
fn odometer_updates(mode: LatencyMode) -> usize {
    let (m, mut cfg) = setup(mode);
    cfg.odometer = Some(OdometerOptions {
        vehicle: crate::filter::nhc::VehicleConstraint::new(
            &crate::attitude::Euler::from_deg(0.0, 0.0, 0.0),
            Vector3::zeros(),
            0.1,
        ),
        sd_mps: 0.05,
        interval_s: 0.1,
        scale_sd: None,
    });
    let mut f = Fusion::new(cfg);
    let dt = 5_000_000;
    let mut t = m.t0;
    let mut next_fix = m.t0.add_seconds(0.1);
    for k in 0..(30 * 200) {
        push_fix_100ms_late(&mut f, &m, t, &mut next_fix);
        if k % 20 == 0 {
            f.push_speed(0.0);
        }
        f.push_imu(&m.sample(t + -dt, t)).unwrap();
        t = t + dt;
    }
    f.stats().odometer_updates
}

#[test]
fn odometer_speeds_survive_restores_and_wait_for_a_lagged_filter() {
    // Every late fix restores a state stored before it and re-runs the
    // samples since: the speeds given in that window must be given again,
    // or the re-run loses their updates.
    let offline = odometer_updates(LatencyMode::Offline);
    assert!(offline >= 295, "{offline}");
    let delayed = odometer_updates(LatencyMode::DelayedState { max_latency_s: 0.5 });
    assert!(
        delayed.abs_diff(offline) <= 1,
        "delayed state {delayed}, offline {offline}"
    );
    // A filter 0.5 s behind reaches all but the last 0.5 s of speeds.
    let lagged = odometer_updates(LatencyMode::FixedLag { lag_s: 0.5 });
    assert!(
        lagged.abs_diff(offline - 5) <= 1,
        "fixed lag {lagged}, offline {offline}"
    );
}

#[test]
fn delayed_state_fuses_each_heading_once_through_restores() {
    // Live: 10 Hz fixes 100 ms late restore a stored state each time;
    // 10 Hz dual-antenna headings fused between restores must be given
    // again on every re-run, and counted once, whether they arrive
    // before the IMU reaches their time (−30 ms: the IMU waits out its
    // lookahead), a little after it (40 ms) or after the next fix (300 ms).
    for heading_latency_s in [0.04, -0.03, 0.3] {
        headings_fused(
            LatencyMode::DelayedState { max_latency_s: 0.5 },
            heading_latency_s,
        );
    }
}

#[test]
fn fixed_lag_fuses_every_heading_it_holds() {
    // The filter runs 0.5 s behind real time, so five 10 Hz headings wait
    // for it at once: each is fused at its own epoch, none overwritten.
    for heading_latency_s in [0.04, 0.3] {
        headings_fused(LatencyMode::FixedLag { lag_s: 0.5 }, heading_latency_s);
    }
}

/// Pushes 10 Hz fixes 100 ms late and 10 Hz headings `heading_latency_s`
/// late through a filter in `mode`; checks that every heading is fused
/// once (the last may wait for its sample). The yaw starts 2° off while
/// the platform turns at 0.05 rad/s.
fn headings_fused(mode: LatencyMode, heading_latency_s: f64) {
    let (m, mut cfg) = setup(mode);
    let truth0 = m.state(m.t0);
    let e = truth0.euler().to_deg();
    cfg.init_nav = NavState::new(
        cfg.init_nav.time,
        cfg.init_nav.pos,
        cfg.init_nav.vel,
        &crate::attitude::Euler::from_deg(e[0], e[1], e[2] + 2.0),
    );
    cfg.init_std.att.z = 5f64.to_radians();
    cfg.heading = Some(HeadingOptions {
        dual_antenna_yaw_rad: 0.0,
        dual_antenna_yaw_sd_rad: 0.0,
        aligned_from_baseline: false,
    });
    let mut f = Fusion::new(cfg);
    let dt = 5_000_000;
    let mut t = m.t0;
    let (mut next_fix, mut next_heading) = (m.t0.add_seconds(0.1), m.t0.add_seconds(0.1));
    let (mut pushed, mut last) = (0, None);
    for _ in 0..(20 * 200) {
        push_fix_100ms_late(&mut f, &m, t, &mut next_fix);
        if t >= next_heading.add_seconds(heading_latency_s) {
            f.push_heading(crate::io::heading::HeadingObs {
                time: next_heading,
                heading_rad: m.state(next_heading).euler().yaw_rad,
                sd_rad: 0.2f64.to_radians(),
                source: crate::io::heading::HeadingSource::Baseline,
            });
            pushed += 1;
            next_heading = next_heading.add_seconds(0.1);
        }
        if let Some(o) = f.push_imu(&m.sample(t + -dt, t)).unwrap() {
            last = Some(o.nav);
        }
        t = t + dt;
    }
    let s = f.stats();
    // Headings the filter has not reached yet: the last, and those within
    // a fixed lag of the end.
    let waiting = match mode {
        LatencyMode::FixedLag { lag_s } => (lag_s / 0.1).ceil() as usize + 1,
        _ => 1,
    };
    assert!(
        s.heading_updates + waiting >= pushed && s.heading_updates <= pushed,
        "{mode:?}, {heading_latency_s} s: {pushed} pushed: {s:?}"
    );
    assert_eq!(s.heading_rejected, 0);
    let nav = last.unwrap();
    let yaw_err = crate::attitude::wrap_pi(nav.euler().yaw_rad - m.state(nav.time).euler().yaw_rad);
    assert!(
        yaw_err.abs() < 0.1f64.to_radians(),
        "yaw error {}°",
        yaw_err.to_degrees()
    );
}
