//! Tests of the alignment (`align`): static and in-motion levelling, the
//! course, the reversing check, dual-antenna and receiver headings.

use super::*;
use crate::earth::Geodetic;

fn sample(t: GpsTime, f_b: Vector3<f64>, dt: f64) -> ImuSample {
    ImuSample {
        time: t,
        dtheta: Vector3::zeros(),
        dvel: f_b * dt,
        odo_speed: None,
    }
}

/// C_bⁿ of a state at rest with attitude `att`.
fn c_nb_at(att: &Euler) -> Matrix3<f64> {
    NavState::new(
        GpsTime::from_week_ns(2300, 0),
        Geodetic::default(),
        Vector3::zeros(),
        att,
    )
    .c_nb()
}

/// The tilt error φ of levelling the specific force `f_meas` of an IMU at
/// C_bⁿ `c` (yaw `yaw_rad` kept), in the filter's convention:
/// (I − φ×) = Ĉ Cᵀ.
fn levelling_tilt_error(c: &Matrix3<f64>, yaw_rad: f64, f_meas: &Vector3<f64>) -> Vector3<f64> {
    let (r, p) = level(f_meas);
    let c_hat = c_nb_at(&Euler::new(r, p, yaw_rad));
    let x = Matrix3::identity() - c_hat * c.transpose();
    Vector3::new(x[(2, 1)], x[(0, 2)], x[(1, 0)])
}

/// The coupling predicts the tilt error that levelling makes from an
/// accelerometer bias, in the filter's convention (Ĉ = (I − φ×)C,
/// δb = b̂ − b with b̂ = 0 here).
#[test]
fn levelling_tilt_error_is_the_coupled_bias() {
    let g = 9.8;
    for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (3.0, -2.0, 40.0), (-5.0, 4.0, -120.0)] {
        let att = Euler::new(
            f64::to_radians(roll),
            f64::to_radians(pitch),
            f64::to_radians(yaw),
        );
        let c = c_nb_at(&att);
        let bias = Vector3::new(0.02, -0.015, 0.01);
        let f_meas = c.transpose() * Vector3::new(0.0, 0.0, -g) + bias;
        let phi = levelling_tilt_error(&c, att.yaw_rad, &f_meas);
        let predicted = levelling_tilt_coupling(&c, g) * (-bias);
        for i in 0..2 {
            assert!(
                (phi[i] - predicted[i]).abs() < 1e-5,
                "attitude ({roll}, {pitch}, {yaw}): φ {phi:?} vs M·δb {predicted:?}"
            );
        }
        // A first-order effect, visibly non-zero: 2 mrad.
        assert!(phi.xy().norm() > 1e-3);
    }
}

/// An accelerometer triad misaligned by δm (f̃ = f + J(f)·m, the
/// filter's misalignment model) levels with the tilt error M·J(f)·(−m),
/// the coupling the filter's P starts with (fusion's levelling block):
/// the misalignment acts as a bias J(f)·m.
#[test]
fn levelling_tilt_error_includes_the_accelerometer_misalignment() {
    let g = 9.8;
    let m = nalgebra::SVector::<f64, 6>::new(0.004, -0.005, 0.003, 0.006, -0.002, 0.001);
    for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (3.0, -2.0, 40.0), (-5.0, 4.0, -120.0)] {
        let att = Euler::new(
            f64::to_radians(roll),
            f64::to_radians(pitch),
            f64::to_radians(yaw),
        );
        let c = c_nb_at(&att);
        let f = c.transpose() * Vector3::new(0.0, 0.0, -g);
        let j = crate::filter::misalign_jacobian(&f);
        let phi = levelling_tilt_error(&c, att.yaw_rad, &(f + j * m));
        let predicted = levelling_tilt_coupling(&c, g) * j * (-m);
        for i in 0..2 {
            assert!(
                (phi[i] - predicted[i]).abs() < 2e-5,
                "attitude ({roll}, {pitch}, {yaw}): φ {phi:?} vs M·J·δm {predicted:?}"
            );
        }
        assert!(phi.xy().norm() > 2e-3);
    }
}

/// A static IMU tilted by known roll/pitch levels to them; then a
/// vehicle driving north-east at 10 m/s (accelerating forward, so the
/// reversing check can decide) gets heading 45°.
#[test]
fn levelling_and_course_recover_the_attitude() {
    let (roll, pitch) = (2.0f64.to_radians(), -3.0f64.to_radians());
    let g = GAMMA_E;
    let f_static = Vector3::new(
        g * pitch.sin(),
        -g * roll.sin() * pitch.cos(),
        -g * roll.cos() * pitch.cos(),
    );
    let (r, p) = level(&f_static);
    assert!((r - roll).abs() < 1e-12 && (p - pitch).abs() < 1e-12);

    let mut al = Aligner::new(AlignOptions::default());
    let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
    let dt = 0.01;
    let t0 = GpsTime::from_week_sow(2000, 1000.0);
    let mut t = t0;
    let fix_at = |t: GpsTime, v: Vector3<f64>| GnssFix {
        time: t,
        pos,
        pos_sd: Vector3::repeat(0.02),
        vel: Some(v),
        vel_sd: Some(Vector3::repeat(0.02)),
    };
    // 20 s standstill.
    for k in 1..=2000 {
        t = t0.add_seconds(k as f64 * dt);
        al.push_imu(&sample(t, f_static, dt));
        if k % 100 == 0 {
            assert!(al.push_gnss(&fix_at(t, Vector3::zeros())).is_none());
        }
    }
    // Accelerate at 1 m/s² along heading 45° (level vehicle now).
    let psi = 45f64.to_radians();
    let a = 1.0;
    let f_drive = Vector3::new(a, 0.0, -g);
    let mut out = None;
    for k in 1..=2000 {
        t = t.add_seconds(dt);
        al.push_imu(&sample(t, f_drive, dt));
        if k % 100 == 0 {
            let speed = a * k as f64 * dt;
            let v = Vector3::new(speed * psi.cos(), speed * psi.sin(), 0.0);
            if let Some(x) = al.push_gnss(&fix_at(t, v)) {
                out = Some(x);
                break;
            }
        }
    }
    let al_out = out.expect("aligned once moving");
    assert_eq!(al_out.method, AlignMethod::StaticLevellingAndCourse);
    assert!(al_out.reversing_checked && !al_out.reversing);
    let e = al_out.nav.euler();
    assert!((e.roll_rad - roll).abs() < 1e-6 && (e.pitch_rad - pitch).abs() < 1e-6);
    assert!((e.yaw_rad - psi).abs() < 1e-9, "{}", e.yaw_rad.to_degrees());
    assert!(al_out.speed_mps >= 3.0);
    // σ: 0.02 m/s at ≥ 3 m/s is ≤ 0.4°, plus the 0.5° allowance.
    assert!(al_out.att_sd_rad[2] < 0.7f64.to_radians());
}

/// The sheet's mounting yaw: an IMU whose x axis points to the
/// vehicle's right has yaw +90° in the vehicle; driving along course
/// 45°, its yaw is 135° — and the NHC's C_b^v built from the same angle
/// carries the IMU-frame velocity onto the vehicle's forward axis alone
/// (one sign convention for both; they disagreed before).
#[test]
fn the_mounting_yaw_turns_the_imu_from_the_course_as_the_nhc_has_it() {
    // Beyond ±90° the IMU's x axis points backwards: not a reversing
    // vehicle (the reversing check once ignored the mounting).
    for mount_deg in [90.0f64, -120.0, 37.0, 180.0] {
        let g = GAMMA_E;
        let mount = mount_deg.to_radians();
        let mut al = Aligner::new(AlignOptions {
            mount_yaw_rad: mount,
            ..AlignOptions::default()
        });
        let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
        let dt = 0.01;
        let t0 = GpsTime::from_week_sow(2000, 1000.0);
        let fix_at = |t: GpsTime, v: Vector3<f64>| GnssFix {
            time: t,
            pos,
            pos_sd: Vector3::repeat(0.02),
            vel: Some(v),
            vel_sd: Some(Vector3::repeat(0.02)),
        };
        let mut t = t0;
        for k in 1..=200 {
            t = t0.add_seconds(k as f64 * dt);
            al.push_imu(&sample(t, Vector3::new(0.0, 0.0, -g), dt));
            if k % 100 == 0 {
                assert!(al.push_gnss(&fix_at(t, Vector3::zeros())).is_none());
            }
        }
        let course = 45f64.to_radians();
        let a = 1.0;
        // The vehicle's forward acceleration seen in the IMU's axes:
        // C_v^b (a, 0, 0) = (a cos α, −a sin α, 0).
        let c_bv = crate::attitude::euler_to_dcm(&Euler {
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: mount,
        });
        let f_drive = c_bv.transpose() * Vector3::new(a, 0.0, 0.0) + Vector3::new(0.0, 0.0, -g);
        let mut out = None;
        for k in 1..=2000 {
            t = t.add_seconds(dt);
            al.push_imu(&sample(t, f_drive, dt));
            if k % 100 == 0 {
                let speed = a * k as f64 * dt;
                let v = Vector3::new(speed * course.cos(), speed * course.sin(), 0.0);
                if let Some(x) = al.push_gnss(&fix_at(t, v)) {
                    out = Some(x);
                    break;
                }
            }
        }
        let e = out.expect("aligned once moving").nav.euler();
        assert!(
            (wrap_pi(e.yaw_rad - (course + mount))).abs() < 1e-6,
            "{}",
            e.yaw_rad.to_degrees()
        );
        // The NHC: the IMU-frame velocity of a vehicle moving forward,
        // carried by C_b^v, is forward only.
        let c_nb = crate::attitude::euler_to_dcm(&e);
        let v_n = Vector3::new(course.cos(), course.sin(), 0.0) * 5.0;
        let v_v = c_bv * (c_nb.transpose() * v_n);
        assert!((v_v.x - 5.0).abs() < 1e-6 && v_v.y.abs() < 1e-6, "{v_v}");
    }
}

/// The alignment of a vehicle starting in motion: the IMU (mounted at
/// `mount_yaw_rad`) measures `f_b` throughout while the GNSS speed grows
/// at 1 m/s² northwards, a fix every second.
fn align_speeding_up_north(mount_yaw_rad: f64, f_b: Vector3<f64>) -> Alignment {
    let mut al = Aligner::new(AlignOptions {
        mount_yaw_rad,
        ..AlignOptions::default()
    });
    let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
    let dt = 0.01;
    let mut t = GpsTime::from_week_sow(2000, 1000.0);
    for k in 1..=1000 {
        t = t.add_seconds(dt);
        al.push_imu(&sample(t, f_b, dt));
        if k % 100 == 0 {
            let fix = GnssFix {
                time: t,
                pos,
                pos_sd: Vector3::repeat(0.02),
                vel: Some(Vector3::new(1.0 * k as f64 * dt, 0.0, 0.0)),
                vel_sd: Some(Vector3::repeat(0.02)),
            };
            if let Some(x) = al.push_gnss(&fix) {
                return x;
            }
        }
    }
    panic!("not aligned in 10 s of motion");
}

/// Reversing: the speed grows while the IMU's forward specific force is
/// negative: the heading is the course turned by 180°.
#[test]
fn a_reversing_vehicle_faces_away_from_its_course() {
    let a = align_speeding_up_north(0.0, Vector3::new(-1.0, 0.0, -GAMMA_E));
    assert_eq!(a.method, AlignMethod::InMotion);
    assert!(a.reversing_checked && a.reversing);
    assert!((a.nav.euler().yaw_rad.abs() - std::f64::consts::PI).abs() < 1e-9);
}

/// Starting in motion, the IMU mounted at yaw −120° (its x axis
/// backwards-left) in a vehicle accelerating forwards: not reversing,
/// and its yaw is the course + the mounting (the check once compared
/// the IMU's x axis with the course).
#[test]
fn an_imu_facing_backwards_in_a_forward_vehicle_is_not_reversing() {
    let mount = -120f64.to_radians();
    let c_bv = crate::attitude::euler_to_dcm(&Euler::new(0.0, 0.0, mount));
    let f = c_bv.transpose() * Vector3::new(1.0, 0.0, 0.0) + Vector3::new(0.0, 0.0, -GAMMA_E);
    let a = align_speeding_up_north(mount, f);
    assert_eq!(a.method, AlignMethod::InMotion);
    assert!(a.reversing_checked && !a.reversing);
    assert!(wrap_pi(a.nav.euler().yaw_rad - mount).abs() < 1e-6);
}

/// Starting in motion with noisy GNSS velocities: tilt and heading are
/// averaged over the window, the run starts at the window's first fix,
/// and the errors are inside the stated σ (3σ) while a single fix's
/// acceleration (velocity noise over 1 s) would be several times worse.
#[test]
fn in_motion_alignment_averages_over_the_window() {
    let mut al = Aligner::new(AlignOptions::default());
    let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
    let dt = 0.01;
    let t0 = GpsTime::from_week_sow(2000, 1000.0);
    let (roll, pitch, yaw) = (
        1.0f64.to_radians(),
        -2.0f64.to_radians(),
        30.0f64.to_radians(),
    );
    let c = NavState::new(t0, pos, Vector3::zeros(), &Euler::new(roll, pitch, yaw)).c_nb();
    let g = crate::earth::gravity(pos.lat_rad.sin(), pos.h_m);
    // Constant velocity along the heading: f^b = C_n^bᵀ (0, 0, −g).
    let f_b = c.transpose() * Vector3::new(0.0, 0.0, -g);
    let v_true = Vector3::new(10.0 * yaw.cos(), 10.0 * yaw.sin(), 0.0);
    let noise = [
        0.05, -0.04, 0.03, -0.05, 0.04, -0.03, 0.05, -0.05, 0.02, -0.04,
    ];
    let mut out = None;
    let mut first_fix = None;
    for k in 1..=2000 {
        let t = t0.add_seconds(k as f64 * dt);
        al.push_imu(&sample(t, f_b, dt));
        if k % 100 == 0 {
            let n = noise[(k / 100) % noise.len()];
            let fix = GnssFix {
                time: t,
                pos,
                pos_sd: Vector3::repeat(0.02),
                vel: Some(v_true + Vector3::new(n, -n, 0.5 * n)),
                vel_sd: Some(Vector3::repeat(0.05)),
            };
            first_fix.get_or_insert(t);
            if let Some(x) = al.push_gnss(&fix) {
                out = Some(x);
                break;
            }
        }
    }
    let a = out.expect("aligned");
    assert_eq!(a.method, AlignMethod::InMotion);
    assert_eq!(
        Some(a.time),
        first_fix,
        "the run starts at the window's first fix"
    );
    let e = a.nav.euler();
    let tilt = [(e.roll_rad - roll).abs(), (e.pitch_rad - pitch).abs()];
    for (err, sd) in tilt.iter().zip(&a.att_sd_rad[..2]) {
        assert!(*err < 3.0 * sd, "tilt error {err} rad, σ {sd} rad");
    }
    // One fix's acceleration error, 0.1 m/s² over g, is 0.6°.
    assert!(
        tilt[0].max(tilt[1]) < 0.15f64.to_radians(),
        "tilt errors {tilt:?} rad"
    );
    assert!(wrap_pi(e.yaw_rad - yaw).abs() < 3.0 * a.att_sd_rad[2]);
    assert!(a.levelling_coupling.is_some());
}

/// A baseline azimuth as the receiver measures it: az of C_b^n u^b.
fn baseline_az(att: &Euler, alpha: f64) -> f64 {
    let c = NavState::new(
        GpsTime::from_week_ns(2300, 0),
        Geodetic::default(),
        Vector3::zeros(),
        att,
    )
    .c_nb();
    let b = c * Vector3::new(alpha.cos(), alpha.sin(), 0.0);
    b.y.atan2(b.x)
}

/// A tilted vehicle standing still with a dual-antenna baseline at a
/// mounting yaw of −70° and 0.2° heading noise (deterministic ±0.2°,
/// the worst case of a 1σ draw): aligned one second into the
/// standstill, heading within 1° (and within 3σ), from the baseline.
#[test]
fn a_dual_antenna_heading_aligns_at_a_standstill() {
    let (roll, pitch, yaw) = (
        3.0f64.to_radians(),
        -2.0f64.to_radians(),
        -150.0f64.to_radians(),
    );
    let alpha = -70f64.to_radians();
    let opts = AlignOptions {
        dual_antenna_yaw_rad: alpha,
        ..AlignOptions::default()
    };
    let mut al = Aligner::new(opts);
    let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
    let att = Euler::new(roll, pitch, yaw);
    let c = NavState::new(GpsTime::from_week_ns(2300, 0), pos, Vector3::zeros(), &att).c_nb();
    let g = crate::earth::gravity(pos.lat_rad.sin(), pos.h_m);
    let f_b = c.transpose() * Vector3::new(0.0, 0.0, -g);
    let az = baseline_az(&att, alpha);
    let dt = 0.01;
    let t0 = GpsTime::from_week_sow(2300, 1000.0);
    let mut out = None;
    for k in 1..=1000 {
        let t = t0.add_seconds(k as f64 * dt);
        al.push_imu(&sample(t, f_b, dt));
        if k % 20 == 0 {
            // 5 Hz headings.
            let noise = if (k / 20) % 2 == 0 { 0.2 } else { -0.2 };
            al.push_heading(&HeadingObs {
                time: t,
                heading_rad: az + f64::to_radians(noise),
                sd_rad: 0.2f64.to_radians(),
                source: HeadingSource::Baseline,
            });
        }
        if k % 100 == 0 {
            let fix = GnssFix {
                time: t,
                pos,
                pos_sd: Vector3::repeat(0.02),
                vel: Some(Vector3::zeros()),
                vel_sd: Some(Vector3::repeat(0.02)),
            };
            if let Some(a) = al.push_gnss(&fix) {
                out = Some((a, t));
                break;
            }
        }
    }
    let (a, at) = out.expect("aligned at the standstill");
    assert_eq!(a.method, AlignMethod::StaticLevellingAndDualAntenna);
    assert!(at.seconds_since(t0) <= 2.0 + 1e-9, "aligned at {at}");
    assert_eq!(
        a.time,
        t0.add_seconds(1.0),
        "the run starts at the first fix"
    );
    let e = a.nav.euler();
    let err = wrap_pi(e.yaw_rad - yaw);
    assert!(err.abs() < 1f64.to_radians(), "{}°", err.to_degrees());
    assert!(err.abs() < 3.0 * a.att_sd_rad[2]);
    // σ: 0.2° from the receiver with the 0.5° mounting allowance.
    assert!((a.att_sd_rad[2].to_degrees() - 0.2f64.hypot(0.5)).abs() < 1e-9);
    assert!((e.roll_rad - roll).abs() < 1e-6 && (e.pitch_rad - pitch).abs() < 1e-6);
    assert!(a.note.contains("dual-antenna baseline"), "{}", a.note);
}

/// Never still long enough nor moving, with one baseline heading: the
/// end of the data takes the heading from it, within its σ.
#[test]
fn a_vehicle_that_never_moves_gets_its_heading_from_the_baseline() {
    let mut al = Aligner::new(AlignOptions::default());
    let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
    let yaw = 100f64.to_radians();
    let t = GpsTime::from_week_sow(2300, 1000.0);
    al.push_heading(&HeadingObs {
        time: t,
        heading_rad: yaw + 0.3f64.to_radians(),
        sd_rad: 0.3f64.to_radians(),
        source: HeadingSource::Baseline,
    });
    let fix = GnssFix {
        time: t,
        pos,
        pos_sd: Vector3::repeat(0.02),
        vel: Some(Vector3::zeros()),
        vel_sd: Some(Vector3::repeat(0.02)),
    };
    assert!(al.push_gnss(&fix).is_none());
    let a = al.finish().expect("a fix was seen");
    assert_eq!(a.method, AlignMethod::StaticLevellingAndDualAntenna);
    let err = wrap_pi(a.nav.euler().yaw_rad - yaw);
    assert!(
        err.abs() <= a.att_sd_rad[2],
        "{err} vs σ {}",
        a.att_sd_rad[2]
    );
}

/// Moving at 10 m/s after a standstill: a receiver's vehicle heading
/// (σ 0.1°) replaces the GNSS course (σ ≈ 0.5°) when they agree, and is
/// refused when it is 10° off.
#[test]
fn a_receiver_vehicle_heading_replaces_the_course_when_it_agrees() {
    for (offset_deg, expect) in [
        (0.05f64, AlignMethod::StaticLevellingAndReceiverHeading),
        (10.0, AlignMethod::StaticLevellingAndCourse),
    ] {
        let mut al = Aligner::new(AlignOptions::default());
        let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
        let dt = 0.01;
        let t0 = GpsTime::from_week_sow(2300, 1000.0);
        let psi = 60f64.to_radians();
        let mut out = None;
        for k in 1..=3000 {
            let t = t0.add_seconds(k as f64 * dt);
            let moving = k > 1000;
            let a = if moving { 1.0 } else { 0.0 };
            al.push_imu(&sample(t, Vector3::new(a, 0.0, -GAMMA_E), dt));
            if k % 100 == 0 {
                let speed = if moving { (k - 1000) as f64 * dt } else { 0.0 };
                if moving {
                    al.push_heading(&HeadingObs {
                        time: t,
                        heading_rad: psi + offset_deg.to_radians(),
                        sd_rad: 0.1f64.to_radians(),
                        source: HeadingSource::Vehicle,
                    });
                }
                let fix = GnssFix {
                    time: t,
                    pos,
                    pos_sd: Vector3::repeat(0.02),
                    vel: Some(Vector3::new(speed * psi.cos(), speed * psi.sin(), 0.0)),
                    vel_sd: Some(Vector3::repeat(0.05)),
                };
                if let Some(x) = al.push_gnss(&fix) {
                    out = Some(x);
                    break;
                }
            }
        }
        let a = out.expect("aligned");
        assert_eq!(a.method, expect, "{}", a.note);
        let err = wrap_pi(a.attitude_deg[2].to_radians() - psi).to_degrees();
        if offset_deg < 1.0 {
            assert!((err - offset_deg).abs() < 1e-9, "{err}");
            assert!((a.att_sd_rad[2].to_degrees() - 0.1).abs() < 1e-9);
        } else {
            assert!(err.abs() < 1e-9, "{err}");
            assert!(a.note.contains("not used"), "{}", a.note);
        }
    }
}

/// Never moving: levelled, heading unknown with σ 180°.
#[test]
fn a_vehicle_that_never_moves_has_an_unknown_heading() {
    let mut al = Aligner::new(AlignOptions::default());
    let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
    let dt = 0.01;
    let mut t = GpsTime::from_week_sow(2000, 1000.0);
    let f = Vector3::new(0.0, 0.0, -GAMMA_E);
    for k in 1..=1000 {
        t = t.add_seconds(dt);
        al.push_imu(&sample(t, f, dt));
        if k % 100 == 0 {
            let fix = GnssFix {
                time: t,
                pos,
                pos_sd: Vector3::repeat(0.02),
                vel: Some(Vector3::zeros()),
                vel_sd: Some(Vector3::repeat(0.02)),
            };
            assert!(al.push_gnss(&fix).is_none());
        }
    }
    let a = al.finish().expect("a fix was seen");
    assert_eq!(a.method, AlignMethod::NoMotion);
    assert!(a.att_sd_rad[2] > 3.0);
    assert!(a.standstill_s > 5.0);
    assert!(a.note.contains("unobservable"));
}
