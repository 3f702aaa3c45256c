//! A trajectory fitted to a reference navigation file (a real drive), so
//! that exact IMU data can be simulated along real vehicle dynamics.
//!
//! Each channel (north, east and down position in a local tangent frame
//! at the first reference point; roll, pitch and unwrapped yaw) is a
//! uniform quintic B-spline fitted by penalised least squares (P-splines:
//! Eilers & Marx, "Flexible smoothing with B-splines and penalties",
//! Statistical Science 11(2), 1996): the data residuals weighted by the
//! reference's resolution, plus a penalty on third differences of the
//! coefficients (the jerk, or the third derivative of an angle). A quintic
//! spline is C⁴, so the acceleration and the body rate are C² and the
//! truth generator's Gauss–Legendre quadrature integrates the sensed rates
//! to rounding (its sub-intervals need not meet the knots).
//!
//! B-spline values and derivatives: Cox–de Boor recursion on uniform knots
//! (Piegl & Tiller, *The NURBS Book*, 2nd ed., algorithm A2.2) and the
//! derivative of a spline as a spline of one degree less whose
//! coefficients are the differences (c_i − c_{i−1})/Δ (ibid. eq 3.8).
//!
//! The velocity is the derivative of the fitted position (the reference's
//! velocity columns are not used): the truth generator integrates it on
//! the ellipsoid, so the simulated truth follows the reference to the
//! fitting error while staying exactly consistent with the IMU data.

use nalgebra::{Matrix3, Vector3};

use navsync::attitude::{body_rate_from_euler_rates, dcm_from_sin_cos};
use navsync::earth::{Geodetic, radii};
use navsync::error::Error;
use navsync::io::kfgins::NavRecord;

/// Spline degree (quintic).
const DEGREE: usize = 5;
/// Knot spacing (s): 10 Hz, near the reference's rate (a real vehicle's
/// motion has little power above 2–3 Hz).
const KNOT_S: f64 = 0.1;
/// Standard deviation of a reference position sample in the fit (m).
const POS_SD_M: f64 = 0.005;
/// Standard deviation of a reference angle sample in the fit (rad): the
/// files' 0.001° resolution.
const ANGLE_SD_RAD: f64 = 3e-5;
/// Scale of the third derivative that the penalty allows per knot
/// interval: jerk (m/s³) and angular jerk (rad/s³).
const JERK_SD_MPS3: f64 = 20.0;
const ANGLE_JERK_SD_RADPS3: f64 = 5.0;

/// Values of the DEGREE+1 B-splines of degree `q` that are non-zero at
/// local parameter `u` ∈ [0, 1) of a uniform knot interval (Piegl & Tiller
/// A2.2 with left[k] = u + k − 1 and right[k] = k − u, whose sum over a
/// pair is k). Entry r belongs to the r-th basis function counted from the
/// one whose support started earliest.
#[inline]
fn uniform_basis(u: f64, q: usize) -> [f64; DEGREE + 1] {
    let mut n = [0.0; DEGREE + 1];
    n[0] = 1.0;
    for k in 1..=q {
        let kf = k as f64;
        let mut saved = 0.0;
        for r in 0..k {
            let temp = n[r] / kf;
            let right = (r + 1) as f64 - u;
            let left = u + (k - r) as f64 - 1.0;
            n[r] = saved + right * temp;
            saved = left * temp;
        }
        n[k] = saved;
    }
    n
}

/// One channel: uniform B-spline coefficients, knots `t_start + k·KNOT_S`.
#[derive(Clone, Debug)]
struct SplineChannel {
    coef: Vec<f64>,
}

impl SplineChannel {
    /// Value and first two derivatives at `t` (s from the start); outside
    /// the fitted span the end polynomials extend.
    #[inline]
    fn eval(&self, t: f64) -> [f64; 3] {
        let p = DEGREE;
        let intervals = self.coef.len() - p;
        let x = t / KNOT_S;
        let j = (x.floor().max(0.0) as usize).min(intervals - 1);
        let u = x - j as f64;
        let c = &self.coef;
        let b0 = uniform_basis(u, p);
        let b1 = uniform_basis(u, p - 1);
        let b2 = uniform_basis(u, p - 2);
        let mut v = [0.0; 3];
        for (r, b) in b0.iter().enumerate().take(p + 1) {
            v[0] += b * c[j + r];
        }
        for (r, b) in b1.iter().enumerate().take(p) {
            v[1] += b * (c[j + 1 + r] - c[j + r]);
        }
        for (r, b) in b2.iter().enumerate().take(p - 1) {
            v[2] += b * (c[j + 2 + r] - 2.0 * c[j + 1 + r] + c[j + r]);
        }
        v[1] /= KNOT_S;
        v[2] /= KNOT_S * KNOT_S;
        v
    }

    /// Penalised least-squares fit to (t, y) samples: data weight
    /// 1/data_sd², third-difference weight 1/(d3_sd·Δ³)² (a third
    /// difference of the coefficients is ≈ Δ³ times the third derivative).
    fn fit(ts: &[f64], ys: &[f64], duration_s: f64, data_sd: f64, d3_sd: f64) -> Self {
        let p = DEGREE;
        let intervals = ((duration_s / KNOT_S).ceil() as usize).max(1);
        let n = intervals + p;
        // Symmetric banded normal matrix: band[i][k] = A[i][i + k].
        let mut band = vec![[0.0f64; DEGREE + 1]; n];
        let mut rhs = vec![0.0; n];
        let wd = 1.0 / (data_sd * data_sd);
        for (&t, &y) in ts.iter().zip(ys) {
            let x = t / KNOT_S;
            let j = (x.floor().max(0.0) as usize).min(intervals - 1);
            let b = uniform_basis(x - j as f64, p);
            for r in 0..=p {
                rhs[j + r] += wd * b[r] * y;
                for s in r..=p {
                    band[j + r][s - r] += wd * b[r] * b[s];
                }
            }
        }
        let d3 = [-1.0, 3.0, -3.0, 1.0];
        let wp = 1.0 / (d3_sd * KNOT_S.powi(3)).powi(2);
        for i in 0..n.saturating_sub(3) {
            for r in 0..4 {
                for s in r..4 {
                    band[i + r][s - r] += wp * d3[r] * d3[s];
                }
            }
        }
        banded_cholesky_solve(&mut band, &mut rhs);
        SplineChannel { coef: rhs }
    }
}

/// Solves A x = b in place for a symmetric positive-definite banded A
/// (half-bandwidth DEGREE, upper band stored by rows) by Cholesky
/// factorisation A = Uᵀ U (Golub & Van Loan, *Matrix Computations*, 4th
/// ed., algorithm 4.3.5, band form).
fn banded_cholesky_solve(band: &mut [[f64; DEGREE + 1]], b: &mut [f64]) {
    let n = band.len();
    let w = DEGREE;
    for i in 0..n {
        // U[i][i..] from A[i][i..] − Σ_k U[k][i] U[k][i..].
        for k in i.saturating_sub(w)..i {
            let uki = band[k][i - k];
            if uki == 0.0 {
                continue;
            }
            for j in i..(k + w + 1).min(n) {
                band[i][j - i] -= uki * band[k][j - k];
            }
        }
        let d = band[i][0].max(f64::MIN_POSITIVE).sqrt();
        for v in band[i].iter_mut() {
            *v /= d;
        }
    }
    // Uᵀ y = b, then U x = y.
    for i in 0..n {
        for k in i.saturating_sub(w)..i {
            b[i] -= band[k][i - k] * b[k];
        }
        b[i] /= band[i][0];
    }
    for i in (0..n).rev() {
        for j in i + 1..(i + w + 1).min(n) {
            b[i] -= band[i][j - i] * b[j];
        }
        b[i] /= band[i][0];
    }
}

/// The fitted motion: position, velocity and acceleration in NED, the
/// attitude and its rates, at any time of the reference's span.
#[derive(Clone, Debug)]
pub struct FittedMotion {
    origin: Geodetic,
    duration_s: f64,
    /// Metres per radian of latitude and of longitude at the origin.
    m_per_rad: [f64; 2],
    pos: [SplineChannel; 3],
    att: [SplineChannel; 3],
}

/// The fitted state at one instant.
#[derive(Copy, Clone, Debug)]
pub struct FittedState {
    /// Position relative to the origin: latitude and longitude offsets
    /// times the origin's metres per radian, and height below it (m).
    pub pos_ned: Vector3<f64>,
    pub vel_n: Vector3<f64>,
    pub acc_n: Vector3<f64>,
    /// roll, pitch, yaw (rad; yaw unwrapped) and their rates and second
    /// derivatives.
    pub euler: [f64; 3],
    pub euler_rate: [f64; 3],
    pub euler_accel: [f64; 3],
}

impl FittedMotion {
    /// Fits the records (in time order, at least 10 over at least 2 s).
    /// Time 0 is the first record's time.
    pub fn fit(records: &[NavRecord]) -> Result<Self, Error> {
        if records.len() < 10 {
            return Err(Error::Invalid(format!(
                "a reference trajectory needs at least 10 states; it has {}",
                records.len()
            )));
        }
        let t0 = records[0].time;
        let ts: Vec<f64> = records.iter().map(|r| r.time.seconds_since(t0)).collect();
        if ts.windows(2).any(|w| w[1] <= w[0]) {
            return Err(Error::Invalid(
                "reference trajectory times must increase strictly".into(),
            ));
        }
        if let Some(w) = ts.windows(2).find(|w| w[1] - w[0] > 2.0) {
            return Err(Error::Invalid(format!(
                "reference trajectory has a gap of {:.2} s after {:.2} s: a fitted trajectory needs states at least every 2 s",
                w[1] - w[0],
                w[0]
            )));
        }
        let duration_s = *ts.last().unwrap_or(&0.0);
        if duration_s < 2.0 {
            return Err(Error::Invalid(format!(
                "reference trajectory lasts {duration_s:.2} s; at least 2 s are needed"
            )));
        }
        let r0 = &records[0];
        let origin = Geodetic::from_deg(r0.lat_deg, r0.lon_deg, r0.h_m);
        let (rm, rn) = radii(origin.lat_rad.sin());
        let m_per_rad = [rm + origin.h_m, (rn + origin.h_m) * origin.lat_rad.cos()];
        let mut chans: [Vec<f64>; 6] = Default::default();
        let mut yaw_prev = r0.att_deg[2].to_radians();
        let mut yaw_turns = 0.0;
        for r in records {
            let lat = r.lat_deg.to_radians() - origin.lat_rad;
            let lon = r.lon_deg.to_radians() - origin.lon_rad;
            chans[0].push(lat * m_per_rad[0]);
            chans[1].push(lon * m_per_rad[1]);
            chans[2].push(origin.h_m - r.h_m);
            chans[3].push(r.att_deg[0].to_radians());
            chans[4].push(r.att_deg[1].to_radians());
            let yaw = r.att_deg[2].to_radians();
            let d = yaw - yaw_prev;
            if d > std::f64::consts::PI {
                yaw_turns -= std::f64::consts::TAU;
            } else if d < -std::f64::consts::PI {
                yaw_turns += std::f64::consts::TAU;
            }
            yaw_prev = yaw;
            chans[5].push(yaw + yaw_turns);
        }
        if chans.iter().flatten().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(
                "reference trajectory has a non-finite value".into(),
            ));
        }
        let fit = |i: usize| {
            let (sd, d3) = if i < 3 {
                (POS_SD_M, JERK_SD_MPS3)
            } else {
                (ANGLE_SD_RAD, ANGLE_JERK_SD_RADPS3)
            };
            SplineChannel::fit(&ts, &chans[i], duration_s, sd, d3)
        };
        Ok(FittedMotion {
            origin,
            duration_s,
            m_per_rad,
            pos: [fit(0), fit(1), fit(2)],
            att: [fit(3), fit(4), fit(5)],
        })
    }

    /// The first reference point.
    pub fn origin(&self) -> Geodetic {
        self.origin
    }

    /// Span of the reference (s).
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The fitted state at `t` seconds after the first reference point.
    ///
    /// The channels hold latitude and longitude scaled by the origin's
    /// metres per radian (so they are angles: the truth generator, which
    /// integrates φ̇ = v_N/(R_M+h) and λ̇ = v_E/((R_N+h) cos φ) (Groves eq
    /// 5.56), reproduces the fitted geodetic track exactly). The NED
    /// velocity is therefore the channel rate times the ratio k of the
    /// local to the origin's metres per radian, and the acceleration
    /// d(k·ẋ)/dt = k·ẍ + k̇·ẋ.
    #[inline]
    pub fn state(&self, t: f64) -> FittedState {
        let p = self.pos.each_ref().map(|c| c.eval(t));
        let a = self.att.each_ref().map(|c| c.eval(t));
        let lat = self.origin.lat_rad + p[0][0] / self.m_per_rad[0];
        let h = self.origin.h_m - p[2][0];
        let lat_dot = p[0][1] / self.m_per_rad[0];
        let h_dot = -p[2][1];
        let (rm, rn) = radii(lat.sin());
        let (drm, drn) = radii_derivative(lat);
        let (sl, cl) = lat.sin_cos();
        let k_n = (rm + h) / self.m_per_rad[0];
        let k_n_dot = (drm * lat_dot + h_dot) / self.m_per_rad[0];
        let k_e = (rn + h) * cl / self.m_per_rad[1];
        let k_e_dot = ((drn * lat_dot + h_dot) * cl - (rn + h) * sl * lat_dot) / self.m_per_rad[1];
        FittedState {
            pos_ned: Vector3::new(p[0][0], p[1][0], p[2][0]),
            vel_n: Vector3::new(k_n * p[0][1], k_e * p[1][1], p[2][1]),
            acc_n: Vector3::new(
                k_n * p[0][2] + k_n_dot * p[0][1],
                k_e * p[1][2] + k_e_dot * p[1][1],
                p[2][2],
            ),
            euler: [a[0][0], a[1][0], a[2][0]],
            euler_rate: [a[0][1], a[1][1], a[2][1]],
            euler_accel: [a[0][2], a[1][2], a[2][2]],
        }
    }

    /// Geodetic position of a fitted `pos_ned` (the inverse of the fit's
    /// mapping).
    pub fn geodetic(&self, pos_ned: &Vector3<f64>) -> Geodetic {
        Geodetic::new(
            self.origin.lat_rad + pos_ned.x / self.m_per_rad[0],
            self.origin.lon_rad + pos_ned.y / self.m_per_rad[1],
            self.origin.h_m - pos_ned.z,
        )
    }
}

/// dR_M/dφ and dR_N/dφ (m/rad) by a central difference of
/// [`radii`] (relative error ~1e-10).
fn radii_derivative(lat: f64) -> (f64, f64) {
    let d = 1e-5;
    let (m1, n1) = radii((lat + d).sin());
    let (m0, n0) = radii((lat - d).sin());
    ((m1 - m0) / (2.0 * d), (n1 - n0) / (2.0 * d))
}

/// C_b^n and ω_nb^b from ZYX Euler angles and their rates (Groves 2013
/// eqs 2.24 and 2.56).
pub fn euler_kinematics(euler: &[f64; 3], rate: &[f64; 3]) -> (Matrix3<f64>, Vector3<f64>) {
    let (roll, pitch) = (euler[0].sin_cos(), euler[1].sin_cos());
    let c_nb = dcm_from_sin_cos(roll, pitch, euler[2].sin_cos());
    (c_nb, body_rate_from_euler_rates(roll, pitch, *rate))
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync::time::GpsTime;

    fn record(t: f64, n: f64, e: f64, yaw_deg: f64, origin: &Geodetic, m: [f64; 2]) -> NavRecord {
        NavRecord {
            week: 0,
            time: GpsTime::from_week_sow(2300, 1000.0 + t),
            lat_deg: (origin.lat_rad + n / m[0]).to_degrees(),
            lon_deg: (origin.lon_rad + e / m[1]).to_degrees(),
            h_m: origin.h_m,
            vel: [0.0; 3],
            att_deg: [0.0, 0.0, yaw_deg],
        }
    }

    #[test]
    fn basis_is_a_partition_of_unity_and_derivatives_match_differences() {
        for q in 0..=DEGREE {
            for &u in &[0.0, 0.3, 0.999] {
                let s: f64 = uniform_basis(u, q).iter().take(q + 1).sum();
                assert!((s - 1.0).abs() < 1e-14, "degree {q} u {u}: {s}");
            }
        }
        let ch = SplineChannel {
            coef: (0..20).map(|i| ((i * 7 % 11) as f64).sin()).collect(),
        };
        let h = 1e-5;
        for &t in &[0.33, 0.71, 1.05] {
            let [v, d1, d2] = ch.eval(t);
            let vp = ch.eval(t + h);
            let vm = ch.eval(t - h);
            assert!(((vp[0] - vm[0]) / (2.0 * h) - d1).abs() < 1e-6 * (1.0 + d1.abs()));
            assert!(((vp[1] - vm[1]) / (2.0 * h) - d2).abs() < 1e-5 * (1.0 + d2.abs()));
            assert!(v.is_finite());
        }
    }

    /// A circle driven at constant speed is reproduced: position to the
    /// fit's resolution, speed and centripetal acceleration to < 0.5 %.
    #[test]
    fn circle_is_reproduced_with_its_velocity_and_acceleration() {
        let origin = Geodetic::from_deg(30.5, 114.35, 20.0);
        let (rm, rn) = radii(origin.lat_rad.sin());
        let m = [rm + 20.0, (rn + 20.0) * origin.lat_rad.cos()];
        let (radius, speed) = (50.0, 10.0);
        let w = speed / radius;
        let recs: Vec<NavRecord> = (0..=600)
            .map(|k| {
                let t = k as f64 * 0.1;
                let yaw = (w * t).to_degrees();
                let yaw = (yaw + 180.0).rem_euclid(360.0) - 180.0;
                let (n, e) = (radius * (w * t).sin(), radius * (1.0 - (w * t).cos()));
                record(t, n, e, yaw, &origin, m)
            })
            .collect();
        let f = FittedMotion::fit(&recs).unwrap();
        for &t in &[5.0, 17.3, 31.05, 44.4] {
            let s = f.state(t);
            let want = Vector3::new(radius * (w * t).sin(), radius * (1.0 - (w * t).cos()), 0.0);
            assert!((s.pos_ned - want).norm() < 2e-3, "t {t}: {:?}", s.pos_ned);
            assert!((s.vel_n.norm() - speed).abs() < 0.05, "{}", s.vel_n.norm());
            assert!(
                (s.acc_n.norm() - speed * w).abs() < 0.01,
                "{}",
                s.acc_n.norm()
            );
            assert!((s.euler_rate[2] - w).abs() < 1e-3, "{}", s.euler_rate[2]);
            let (c, wb) = euler_kinematics(&s.euler, &s.euler_rate);
            assert!((c * Vector3::x() - s.vel_n / speed).norm() < 5e-3);
            assert!((wb.z - w).abs() < 1e-3);
        }
        let back = f.geodetic(&f.state(0.0).pos_ned);
        assert!((back.lat_rad - origin.lat_rad).abs() * m[0] < 5e-3);
    }

    #[test]
    fn bad_references_are_refused() {
        let origin = Geodetic::from_deg(30.5, 114.35, 20.0);
        let m = [6.3e6, 5.5e6];
        let few: Vec<_> = (0..5)
            .map(|k| record(k as f64, 0.0, 0.0, 0.0, &origin, m))
            .collect();
        assert!(FittedMotion::fit(&few).is_err());
        let mut gap: Vec<_> = (0..30)
            .map(|k| record(k as f64 * 0.1, 0.0, 0.0, 0.0, &origin, m))
            .collect();
        gap[20].time = gap[20].time.add_seconds(10.0);
        for r in gap.iter_mut().skip(21) {
            r.time = r.time.add_seconds(10.0);
        }
        let e = FittedMotion::fit(&gap).unwrap_err().to_string();
        assert!(e.contains("gap"), "{e}");
    }
}
