//! Tests of the mechanization and the error model against exact motions
//! and numerical perturbation.

use nalgebra::Vector3;

use super::gnss::{self, GnssFix};
use super::nhc::VehicleConstraint;
use super::*;
use crate::attitude::{Euler, quat_to_rotvec, rotvec_to_quat};
use crate::earth::{Geodetic, LocalEarth};
use crate::ins::{ImuErrors, Mechanization, NavState};
use crate::testutil::TurningAtRest;
use crate::time::GpsTime;

fn motion(rate_deg_s: f64) -> TurningAtRest {
    TurningAtRest {
        pos: Geodetic::from_deg(30.4, 114.5, 25.0),
        yaw0_rad: 40f64.to_radians(),
        rate_rad_s: rate_deg_s.to_radians(),
        t0: GpsTime::from_week_sow(2300, 1000.0),
    }
}

/// Integrates `m` from its true start for `secs` at `rate_hz` with the given
/// IMU errors applied to the compensation (so `errors` act as estimate
/// errors), feeding every step into `filter` when given.
fn integrate(
    m: &TurningAtRest,
    start: NavState,
    errors: &ImuErrors,
    secs: f64,
    rate_hz: f64,
    mut filter: Option<&mut ErrorStateFilter>,
) -> NavState {
    let mut nav = start;
    let mut mech = Mechanization::new();
    let dt_ns = (1e9 / rate_hz).round() as i64;
    let steps = (secs * rate_hz).round() as i64;
    let mut t = m.t0;
    let first = m.sample(t + -dt_ns, t);
    mech.set_previous(errors.compensate(&first.dtheta, &first.dvel, dt_ns as f64 * 1e-9));
    for _ in 0..steps {
        let s = m.sample(t, t + dt_ns);
        let inc = errors.compensate(&s.dtheta, &s.dvel, dt_ns as f64 * 1e-9);
        let info = mech.step(&mut nav, &inc);
        if let Some(f) = filter.as_deref_mut() {
            f.accumulate(&info);
            if f.pending_dt() >= 0.1 {
                f.propagate(&nav);
            }
        }
        t = t + dt_ns;
        nav.time = t;
    }
    if let Some(f) = filter {
        f.propagate(&nav);
    }
    nav
}

fn pos_error_m(a: &NavState, b: &NavState) -> Vector3<f64> {
    let le = LocalEarth::new(&b.pos, &b.vel);
    le.geodetic_delta_to_ned(
        a.pos.lat_rad - b.pos.lat_rad,
        a.pos.lon_rad - b.pos.lon_rad,
        a.pos.h_m - b.pos.h_m,
    )
}

#[test]
fn stationary_imu_stays_put() {
    // Exact increments of a level IMU at rest: any drift is the algorithm's.
    let m = motion(0.0);
    let end = integrate(&m, m.state(m.t0), &ImuErrors::default(), 600.0, 200.0, None);
    let truth = m.state(end.time);
    let dp = pos_error_m(&end, &truth);
    assert!(dp.norm() < 1e-4, "position drift {dp} m after 10 min");
    assert!(end.vel.norm() < 1e-6, "velocity {}", end.vel);
    assert!(end.q_nb.angle_to(&truth.q_nb) < 1e-9);
}

#[test]
fn constant_turn_integrates_to_known_heading() {
    // 10 deg/s for 100 s: 1000 deg of heading, exactly known.
    let m = motion(10.0);
    let end = integrate(&m, m.state(m.t0), &ImuErrors::default(), 100.0, 200.0, None);
    let truth = m.state(end.time);
    let yaw_err = end.q_nb.angle_to(&truth.q_nb);
    assert!(yaw_err < 1e-9, "attitude error {yaw_err} rad");
    assert!(pos_error_m(&end, &truth).norm() < 1e-4);
    assert!(end.vel.norm() < 1e-6);
}

/// Navigation error state x̂ − x (9 states) between an estimate and the
/// truth, in this crate's convention (φ from Ĉ = (I − φ×) C).
fn error_state(est: &NavState, truth: &NavState) -> Vec<f64> {
    let mut dx = vec![0.0; 9];
    let dp = pos_error_m(est, truth);
    let dv = est.vel - truth.vel;
    // C = exp(φ×) Ĉ  ⇒  φ = rotvec(q_true ⊗ q̂⁻¹)
    let phi = quat_to_rotvec(&(truth.q_nb * est.q_nb.inverse()));
    for i in 0..3 {
        dx[idx::POS + i] = dp[i];
        dx[idx::VEL + i] = dv[i];
        dx[idx::ATT + i] = phi[i];
    }
    dx
}

fn zero_noise() -> ImuNoise {
    ImuNoise {
        arw: Vector3::zeros(),
        vrw: Vector3::zeros(),
        gyro_bias_sd: Vector3::zeros(),
        accel_bias_sd: Vector3::zeros(),
        gyro_scale_sd: Vector3::zeros(),
        accel_scale_sd: Vector3::zeros(),
        corr_time_s: 1e12,
    }
}

#[test]
fn error_model_matches_nonlinear_propagation() {
    check_error_model(&ImuErrors {
        gyro_bias: Vector3::new(3e-6, -2e-6, 4e-6),
        accel_bias: Vector3::new(2e-3, -1e-3, 1.5e-3),
        gyro_scale: Vector3::new(0.0, 0.0, 300e-6),
        accel_scale: Vector3::new(0.0, 0.0, 200e-6),
        ..ImuErrors::default()
    });
}

#[test]
fn misalignment_error_model_matches_nonlinear_propagation() {
    // The turn's rate about down reaches the horizontal gyros through
    // m_xz, m_yz; gravity reaches the horizontal accelerometers likewise.
    check_error_model(&ImuErrors {
        gyro_bias: Vector3::new(3e-6, -2e-6, 4e-6),
        accel_bias: Vector3::new(2e-3, -1e-3, 1.5e-3),
        gyro_misalign: [2e-4, 6e-4, -3e-4, -5e-4, 4e-4, 1e-4],
        accel_misalign: [1e-4, 4e-4, -2e-4, -3e-4, 2e-4, 5e-4],
        ..ImuErrors::default()
    });
}

/// Perturbs the initial state and the IMU error estimates by `err`,
/// integrates both the truth and the perturbed estimate through the
/// nonlinear mechanization, and compares the error after 20 s with the
/// filter's linear propagation of a rank-one covariance δx₀ δx₀ᵀ (no
/// process noise): P(T) must equal δx(T) δx(T)ᵀ up to second-order terms.
/// Misalignment states are in the layout when `err` has misalignments.
fn check_error_model(err: &ImuErrors) {
    let m = motion(6.0);
    let truth0 = m.state(m.t0);
    let d_pos = Vector3::new(0.8, -0.5, 0.3);
    let d_vel = Vector3::new(0.02, -0.01, 0.015);
    let phi0 = Vector3::new(2e-4, -1.5e-4, 3e-4);
    let le = LocalEarth::new(&truth0.pos, &truth0.vel);
    let dg = le.ned_to_geodetic_delta(&d_pos);
    let mut est0 = truth0;
    est0.pos = Geodetic::new(
        truth0.pos.lat_rad + dg.x,
        truth0.pos.lon_rad + dg.y,
        truth0.pos.h_m + dg.z,
    );
    est0.vel += d_vel;
    // Ĉ = (I − φ×) C = exp(−φ×) C
    est0.q_nb = rotvec_to_quat(&(-phi0)) * truth0.q_nb;

    let mut dx0 = error_state(&est0, &truth0);
    dx0.extend_from_slice(err.gyro_bias.as_slice());
    dx0.extend_from_slice(err.accel_bias.as_slice());
    dx0.extend_from_slice(err.gyro_scale.as_slice());
    dx0.extend_from_slice(err.accel_scale.as_slice());
    let mut layout = StateLayout::default();
    if err
        .gyro_misalign
        .iter()
        .chain(&err.accel_misalign)
        .any(|&x| x != 0.0)
    {
        layout.add_misalignment();
        dx0.extend_from_slice(&err.gyro_misalign);
        dx0.extend_from_slice(&err.accel_misalign);
    }

    let zero_std = InitialStd {
        pos: Vector3::zeros(),
        vel: Vector3::zeros(),
        att: Vector3::zeros(),
        gyro_bias: Vector3::zeros(),
        accel_bias: Vector3::zeros(),
        gyro_scale: Vector3::zeros(),
        accel_scale: Vector3::zeros(),
    };
    let n = layout.n();
    let mut f = ErrorStateFilter::new(layout, zero_noise(), &zero_std, &vec![0.0; n - idx::CORE]);
    for i in 0..n {
        for j in 0..n {
            f.covariance_mut().set(i, j, dx0[i] * dx0[j]);
        }
    }
    let secs = 20.0;
    let est = integrate(&m, est0, err, secs, 200.0, Some(&mut f));
    let truth = integrate(&m, truth0, &ImuErrors::default(), secs, 200.0, None);
    let dx = error_state(&est, &truth);
    let p = f.covariance();
    for i in 0..9 {
        let predicted = p.get(i, i).sqrt();
        let actual = dx[i].abs();
        // Neglected second-order terms are ~|φ|·|δx| and the window's
        // truncation; measured agreement is ~0.3 %, so 1 % catches any
        // wrong or missing block of F (each changes some state by >10 %).
        assert!(
            (predicted - actual).abs() <= 0.01 * actual + 1e-6,
            "state {i}: linear {predicted:.6e} vs nonlinear {actual:.6e}"
        );
        // Signs agree: P(i, 0) = δx_i δx_0.
        if actual > 1e-5 {
            assert!(
                p.get(i, 0).signum() == (dx[i] * dx[0]).signum(),
                "sign of state {i}"
            );
        }
    }
}

fn numeric_check(h_analytic: &dense::Mat, f: impl Fn(&[f64]) -> Vec<f64>, n: usize, eps: &[f64]) {
    let z0 = f(&vec![0.0; n]);
    for j in 0..n {
        let mut dx = vec![0.0; n];
        dx[j] = eps[j];
        let zp = f(&dx);
        dx[j] = -eps[j];
        let zm = f(&dx);
        for i in 0..z0.len() {
            let num = (zp[i] - zm[i]) / (2.0 * eps[j]);
            let ana = h_analytic.get(i, j);
            let scale = num.abs().max(ana.abs()).max(1e-9);
            assert!(
                // 1e-6 absolute: second-order terms of the residual itself
                // (e.g. D_R evaluated at the perturbed latitude).
                (num - ana).abs() <= 1e-4 * scale + 1e-6,
                "H[{i}][{j}]: analytic {ana:.6e}, numeric {num:.6e}"
            );
        }
    }
}

/// Applies an error state to a true state and IMU errors (x̂ = x + δx).
fn perturb(truth: &NavState, dx: &[f64]) -> (NavState, ImuErrors) {
    let mut est = *truth;
    let le = LocalEarth::new(&truth.pos, &truth.vel);
    let dg = le.ned_to_geodetic_delta(&Vector3::new(dx[0], dx[1], dx[2]));
    est.pos = Geodetic::new(
        truth.pos.lat_rad + dg.x,
        truth.pos.lon_rad + dg.y,
        truth.pos.h_m + dg.z,
    );
    est.vel += Vector3::new(dx[3], dx[4], dx[5]);
    est.q_nb = rotvec_to_quat(&(-Vector3::new(dx[6], dx[7], dx[8]))) * truth.q_nb;
    let v = |i: usize| Vector3::new(dx[i], dx[i + 1], dx[i + 2]);
    let e = ImuErrors {
        gyro_bias: v(idx::BG),
        accel_bias: v(idx::BA),
        gyro_scale: v(idx::SG),
        accel_scale: v(idx::SA),
        ..ImuErrors::default()
    };
    (est, e)
}

fn moving_state() -> (NavState, Vector3<f64>) {
    let nav = NavState::new(
        GpsTime::from_week_sow(2300, 5.0),
        Geodetic::from_deg(30.4, 114.5, 30.0),
        Vector3::new(12.0, -7.0, 0.4),
        &Euler::from_deg(3.0, -2.0, 150.0),
    );
    // True body rate; the estimate sees w_true·(1 + s_g) + b_g after
    // compensation errors: ω̂ = ω − δb_g − diag(ω) δs_g.
    (nav, Vector3::new(0.05, -0.03, 0.25))
}

const EPS: [f64; 21] = [
    1e-3, 1e-3, 1e-3, 1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6, 1e-7, 1e-7, 1e-7, 1e-5, 1e-5, 1e-5, 1e-5,
    1e-5, 1e-5, 1e-5, 1e-5, 1e-5,
];

#[test]
fn gnss_position_jacobian_is_exact() {
    let (truth, _) = moving_state();
    let lever = Vector3::new(0.1, 0.5, -1.2);
    let fix = GnssFix {
        time: truth.time,
        pos: Geodetic::from_deg(30.40001, 114.50002, 31.0),
        pos_sd: Vector3::repeat(0.02),
        vel: None,
        vel_sd: None,
    };
    let h = gnss::position(&truth, &fix, &lever, 21).h;
    numeric_check(
        &h,
        |dx| gnss::position(&perturb(&truth, dx).0, &fix, &lever, 21).z,
        21,
        &EPS,
    );
}

#[test]
fn gnss_velocity_jacobian_is_exact() {
    let (truth, w) = moving_state();
    let lever = Vector3::new(0.1, 0.5, -1.2);
    let fix = GnssFix {
        time: truth.time,
        pos: truth.pos,
        pos_sd: Vector3::repeat(0.02),
        vel: Some(Vector3::new(12.1, -6.9, 0.3)),
        vel_sd: Some(Vector3::repeat(0.05)),
    };
    let h = gnss::velocity(&truth, &fix, &lever, &w, 21).unwrap().h;
    numeric_check(
        &h,
        |dx| {
            let (est, e) = perturb(&truth, dx);
            let w_hat = w - e.gyro_bias - w.component_mul(&e.gyro_scale);
            gnss::velocity(&est, &fix, &lever, &w_hat, 21).unwrap().z
        },
        21,
        &EPS,
    );
}

#[test]
fn nhc_and_odometer_jacobians_are_exact() {
    let (truth, w) = moving_state();
    let vc = VehicleConstraint::new(
        &Euler::from_deg(0.5, -1.0, 2.0),
        Vector3::new(-1.0, 0.2, 0.8),
        0.1,
    );
    let h = vc.nhc(&truth, &w, 21).h;
    let est_w = |e: &ImuErrors| w - e.gyro_bias - w.component_mul(&e.gyro_scale);
    numeric_check(
        &h,
        |dx| {
            let (est, e) = perturb(&truth, dx);
            vc.nhc(&est, &est_w(&e), 21).z
        },
        21,
        &EPS,
    );
    let h = vc.odometer(&truth, &w, 13.0, 0.05, None, 21).h;
    numeric_check(
        &h,
        |dx| {
            let (est, e) = perturb(&truth, dx);
            vc.odometer(&est, &est_w(&e), 13.0, 0.05, None, 21).z
        },
        21,
        &EPS,
    );
}

/// The σ of a filter after GNSS updates: 2 cm, 1 cm/s, 1 mrad, biases and
/// scale factors near their stable values.
fn converged_std() -> InitialStd {
    InitialStd {
        pos: Vector3::repeat(0.02),
        vel: Vector3::repeat(0.01),
        att: Vector3::repeat(1e-3),
        gyro_bias: Vector3::repeat(1e-5),
        accel_bias: Vector3::repeat(1e-3),
        gyro_scale: Vector3::repeat(1e-3),
        accel_scale: Vector3::repeat(1e-3),
    }
}

fn converged_filter() -> ErrorStateFilter {
    ErrorStateFilter::new(StateLayout::default(), zero_noise(), &converged_std(), &[])
}

#[test]
fn update_shrinks_covariance_and_gates_outliers() {
    let (truth, _) = moving_state();
    let lever = Vector3::zeros();
    let mut fix = GnssFix {
        time: truth.time,
        pos: truth.pos,
        pos_sd: Vector3::repeat(0.02),
        vel: None,
        vel_sd: None,
    };
    let mut f = converged_filter();
    let before = f.covariance().clone();
    let obs = gnss::position(&truth, &fix, &lever, 21);
    let gate = Some(crate::stats::chi2_quantile(0.9999, 3.0));
    let out = f.update(&obs, gate, truth.time).unwrap();
    assert!(out.accepted && out.nis.abs() < 1e-12);
    for i in 0..21 {
        assert!(
            f.covariance().get(i, i) <= before.get(i, i) + 1e-18,
            "state {i} variance grew"
        );
    }
    // Position σ ≈ 1/√(1/0.02² + 1/0.02²) = 0.0141 m.
    assert!((f.sd(0) - 0.02 / 2f64.sqrt()).abs() < 1e-4, "{}", f.sd(0));
    f.check_covariance(truth.time).unwrap();

    // A 1 m jump on a 2 cm fix is far outside the gate.
    fix.pos.h_m += 1.0;
    let obs = gnss::position(&truth, &fix, &lever, 21);
    let out = f.update(&obs, gate, truth.time).unwrap();
    assert!(!out.accepted && out.nis > 1000.0, "nis {}", out.nis);
}

#[test]
fn broken_covariance_is_reported() {
    let mut f = converged_filter();
    f.covariance_mut().set(4, 4, -1.0);
    let err = f
        .check_covariance(GpsTime::from_week_sow(2300, 7.0))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("2300 7.000000000") && err.contains("state 4"),
        "{err}"
    );
    let mut f = converged_filter();
    // Correlation > 1 between two states: not positive definite.
    let v = f.covariance().get(0, 0).sqrt() * f.covariance().get(1, 1).sqrt() * 1.5;
    f.covariance_mut().set(0, 1, v);
    f.covariance_mut().set(1, 0, v);
    let err = f.check_covariance(GpsTime::EPOCH).unwrap_err().to_string();
    // The message names the state and the likely cause (issue 32).
    assert!(
        err.contains("at position east (state 1)") && err.contains("Likely cause"),
        "{err}"
    );
}

#[test]
fn a_singular_innovation_covariance_names_its_cause() {
    let (truth, _) = moving_state();
    let fix = GnssFix {
        time: truth.time,
        pos: truth.pos,
        pos_sd: Vector3::repeat(0.02),
        vel: None,
        vel_sd: None,
    };
    let mut f = converged_filter();
    let mut obs = gnss::position(&truth, &fix, &Vector3::zeros(), 21);
    obs.r.set(1, 1, -1.0);
    let err = f.update(&obs, None, truth.time).unwrap_err().to_string();
    assert!(
        err.contains("innovation covariance S = HPHᵀ + R is not positive definite")
            && err.contains("axis 1 has measurement variance R = -1e0"),
        "{err}"
    );
    // A covariance that overflowed: named with its state.
    let mut f = converged_filter();
    f.covariance_mut().set(0, 0, f64::INFINITY);
    let obs = gnss::position(&truth, &fix, &Vector3::zeros(), 21);
    let err = f.update(&obs, None, truth.time).unwrap_err().to_string();
    assert!(
        err.contains("covariance of position north (state 0) overflowed"),
        "{err}"
    );
}

#[test]
fn feedback_undoes_a_known_error() {
    let (truth, _) = moving_state();
    let mut dx = vec![0.0; 21];
    dx[..9].copy_from_slice(&[1.0, -2.0, 0.5, 0.1, 0.2, -0.1, 1e-3, -2e-3, 5e-3]);
    dx[idx::BG] = 1e-5;
    let (mut est, mut e) = perturb(&truth, &dx);
    feedback(&dx, &StateLayout::default(), &mut est, &mut e);
    assert!(pos_error_m(&est, &truth).norm() < 1e-6);
    assert!((est.vel - truth.vel).norm() < 1e-12);
    assert!(est.q_nb.angle_to(&truth.q_nb) < 1e-8);
    assert!(e.gyro_bias.norm() < 1e-15);
}

/// The fading-memory inflation scales every state's variance by the
/// factor but holds the misalignment states' block; their
/// cross-covariances scale by √factor (D P D, so P stays positive
/// semi-definite and every correlation coefficient is kept). Without
/// misalignment states the whole P scales, exactly.
#[test]
fn inflation_holds_the_misalignment_states() {
    let std = converged_std();
    let mut layout = StateLayout::default();
    let first = layout.add_misalignment();
    let n = layout.n();
    let mut f = ErrorStateFilter::new(layout, zero_noise(), &std, &vec![1e-6; n - idx::CORE]);
    // Misalignment σ 1 mrad (0.057°), correlated 0.5 with the north position.
    let c = 0.5 * std.pos.x * 1e-3;
    f.covariance_mut().set(0, first, c);
    f.covariance_mut().set(first, 0, c);
    let before = f.covariance().clone();
    f.inflate(16.0);
    let p = f.covariance();
    assert_eq!(p.get(0, 0), 16.0 * before.get(0, 0));
    assert_eq!(p.get(idx::BA, idx::BA), 16.0 * before.get(idx::BA, idx::BA));
    for k in first..first + 12 {
        assert_eq!(p.get(k, k), before.get(k, k), "state {k}");
    }
    assert_eq!(p.get(0, first), 4.0 * c);
    assert_eq!(p.get(first, 0), 4.0 * c);
    let rho = |m: &Mat| m.get(0, first) / (m.get(0, 0) * m.get(first, first)).sqrt();
    assert!((rho(p) - 0.5).abs() < 1e-12 && (rho(&before) - 0.5).abs() < 1e-12);
    // No misalignment states: the whole P, exactly.
    let mut g = ErrorStateFilter::new(StateLayout::default(), zero_noise(), &std, &[]);
    let before = g.covariance().clone();
    g.inflate(16.0);
    for i in 0..idx::CORE {
        assert_eq!(g.covariance().get(i, i), 16.0 * before.get(i, i));
    }
    // Factors at or below 1, or not finite, change nothing.
    for bad in [1.0, 0.5, f64::NAN, f64::INFINITY] {
        let mut h = ErrorStateFilter::new(StateLayout::default(), zero_noise(), &std, &[]);
        h.inflate(bad);
        assert_eq!(h.covariance().get(0, 0), before.get(0, 0));
    }
}
