//! Exact truth along a trajectory: the navigation state at any instant and
//! the exact IMU increments over any interval.
//!
//! The IMU senses (Groves 2013 eqs 5.38 and 5.53, in the NED frame, with
//! the same Earth model as [`navsync::ins::Mechanization`]):
//!
//! ω_ib^b = ω_nb^b + C_n^b (ω_ie^n + ω_en^n)
//! f^b    = C_n^b (dv^n/dt + (2ω_ie^n + ω_en^n) × v^n − g^n),  g^n = [0, 0, γ(φ, h)]
//!
//! and its ideal increments are Δθ = ∫ω_ib^b dt and Δv = ∫f^b dt over
//! (t_{k−1}, t_k] (FORMATS.md §1), computed here by composite 4-point
//! Gauss–Legendre quadrature (exact for polynomials of degree 7 on each
//! sub-interval; sub-intervals of at most 10 ms and a quarter period of
//! the fastest vibration tone).
//!
//! The position is integrated from the vehicle's NED velocity on a fixed
//! 10 ms grid by the classical Runge–Kutta method on (φ, λ, h)
//! (φ̇ = v_N/(R_M+h), λ̇ = v_E/((R_N+h) cos φ), ḣ = −v_D; Groves eq 5.56)
//! and interpolated between grid nodes by cubic Hermite polynomials (error
//! ~h⁴/384·|p⁗| ≈ 1e-10 m). The position-dependent Earth terms (sin φ,
//! 1/(R+h), γ) are interpolated linearly between grid nodes, as allowed
//! for quantities that change by ~1e-12 of themselves over 10 ms.

use nalgebra::Vector3;

use super::trajectory::{Cursor, Kinematics, Trajectory};
use navsync::earth::{Geodetic, OMEGA_E, gravity, radii};
use navsync::ins::{ImuSample, NavState};
use navsync::time::GpsTime;

/// Position-only Earth terms at a grid node.
#[derive(Copy, Clone, Debug, Default)]
struct EarthPos {
    sin_lat: f64,
    cos_lat: f64,
    inv_rm_h: f64,
    inv_rn_h: f64,
    g: f64,
}

impl EarthPos {
    fn at(lat: f64, h: f64) -> Self {
        let (s, c) = lat.sin_cos();
        let (rm, rn) = radii(s);
        EarthPos {
            sin_lat: s,
            cos_lat: c,
            inv_rm_h: 1.0 / (rm + h),
            inv_rn_h: 1.0 / (rn + h),
            g: gravity(s, h),
        }
    }

    fn lerp(a: &Self, b: &Self, f: f64) -> Self {
        let l = |x: f64, y: f64| x + (y - x) * f;
        EarthPos {
            sin_lat: l(a.sin_lat, b.sin_lat),
            cos_lat: l(a.cos_lat, b.cos_lat),
            inv_rm_h: l(a.inv_rm_h, b.inv_rm_h),
            inv_rn_h: l(a.inv_rn_h, b.inv_rn_h),
            g: l(a.g, b.g),
        }
    }
}

#[derive(Copy, Clone, Debug, Default)]
struct Node {
    t: f64,
    /// latitude (rad), longitude (rad), height (m)
    y: [f64; 3],
    dy: [f64; 3],
    earth: EarthPos,
}

/// The truth at one instant.
#[derive(Copy, Clone, Debug)]
pub struct TruthPoint {
    /// Position, velocity and attitude of the IMU centre.
    pub nav: NavState,
    /// Everything about the motion except the position.
    pub kin: Kinematics,
    /// Angular rate sensed by an ideal gyro, ω_ib^b (rad/s).
    pub w_ib_b: Vector3<f64>,
    /// Specific force sensed by an ideal accelerometer, f^b (m/s²).
    pub f_b: Vector3<f64>,
    /// ω_ie^n and ω_en^n (rad/s).
    pub w_ie_n: Vector3<f64>,
    pub w_en_n: Vector3<f64>,
}

impl TruthPoint {
    /// ω_eb^b = ω_nb^b + C_n^b ω_en^n: the body rate relative to the Earth
    /// (for lever-arm velocities).
    pub fn w_eb_b(&self) -> Vector3<f64> {
        self.kin.w_nb_b + self.kin.c_nb.transpose() * self.w_en_n
    }
}

/// Sensed rates at one instant (the fast path for internal IMU sampling).
#[derive(Copy, Clone, Debug)]
pub struct SensedRates {
    pub w_ib_b: Vector3<f64>,
    pub f_b: Vector3<f64>,
}

/// Streams the truth along a trajectory: the state at any time, and exact
/// increments between successive calls of [`TruthGenerator::next`].
///
/// Queries should come in non-decreasing time (a query before the current
/// 10 ms grid cell re-integrates from the start: correct, but slow).
#[derive(Clone, Debug)]
pub struct TruthGenerator<'a> {
    traj: &'a Trajectory,
    start: GpsTime,
    step_s: f64,
    a: Node,
    b: Node,
    k: u64,
    prev: GpsTime,
    quad_sub_s: f64,
    cursor: Cursor,
    grid_cursor: Cursor,
}

/// 4-point Gauss–Legendre nodes and weights on [−1, 1].
const GL_X: [f64; 4] = [
    -0.861_136_311_594_052_6,
    -0.339_981_043_584_856_3,
    0.339_981_043_584_856_3,
    0.861_136_311_594_052_6,
];
const GL_W: [f64; 4] = [
    0.347_854_845_137_453_9,
    0.652_145_154_862_546_1,
    0.652_145_154_862_546_1,
    0.347_854_845_137_453_9,
];

const GRID_STEP_S: f64 = 0.01;

impl<'a> TruthGenerator<'a> {
    /// A generator for `traj`, whose time 0 is GPS time `start`.
    pub fn new(traj: &'a Trajectory, start: GpsTime) -> Self {
        let f_max = traj.vibration().max_freq_hz();
        let quad_sub_s = if f_max > 0.0 {
            (0.25 / f_max).min(0.01)
        } else {
            0.01
        };
        let mut g = TruthGenerator {
            traj,
            start,
            step_s: GRID_STEP_S,
            a: Node::default(),
            b: Node::default(),
            k: 0,
            prev: start,
            quad_sub_s,
            cursor: Cursor::default(),
            grid_cursor: Cursor::default(),
        };
        g.reset();
        g
    }

    /// The trajectory.
    pub fn trajectory(&self) -> &'a Trajectory {
        self.traj
    }

    /// GPS time of the trajectory's time 0.
    pub fn start(&self) -> GpsTime {
        self.start
    }

    fn reset(&mut self) {
        let o = self.traj.origin();
        self.grid_cursor = Cursor::default();
        let vel = self.traj.vehicle_velocity_at(0.0, &mut self.grid_cursor);
        let y = [o.lat_rad, o.lon_rad, o.h_m];
        self.a = Node {
            t: 0.0,
            y,
            dy: self.deriv(&y, &vel),
            earth: EarthPos::at(y[0], y[2]),
        };
        self.k = 0;
        self.b = self.integrate(&self.a.clone(), 1);
    }

    /// Geodetic rates from NED velocity (Groves eq 5.56).
    #[inline]
    fn deriv(&self, y: &[f64; 3], vel: &Vector3<f64>) -> [f64; 3] {
        let (s, c) = y[0].sin_cos();
        let (rm, rn) = radii(s);
        [vel.x / (rm + y[2]), vel.y / ((rn + y[2]) * c), -vel.z]
    }

    /// One classical Runge–Kutta step from node `a` to grid index `k`.
    fn integrate(&mut self, a: &Node, k: u64) -> Node {
        let h = self.step_s;
        let t1 = k as f64 * h;
        let tm = t1 - 0.5 * h;
        let vm = self.traj.vehicle_velocity_at(tm, &mut self.grid_cursor);
        let v1 = self.traj.vehicle_velocity_at(t1, &mut self.grid_cursor);
        let add = |y: &[f64; 3], d: &[f64; 3], s: f64| {
            [y[0] + s * d[0], y[1] + s * d[1], y[2] + s * d[2]]
        };
        let k1 = a.dy;
        let k2 = self.deriv(&add(&a.y, &k1, 0.5 * h), &vm);
        let k3 = self.deriv(&add(&a.y, &k2, 0.5 * h), &vm);
        let k4 = self.deriv(&add(&a.y, &k3, h), &v1);
        let y = [
            a.y[0] + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            a.y[1] + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            a.y[2] + h / 6.0 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
        ];
        Node {
            t: t1,
            y,
            dy: self.deriv(&y, &v1),
            earth: EarthPos::at(y[0], y[2]),
        }
    }

    /// Moves the grid cell so that `a.t <= t <= b.t`.
    #[inline]
    fn seek(&mut self, t: f64) {
        if t < self.a.t {
            self.reset();
        }
        while t > self.b.t {
            self.a = self.b;
            self.k += 1;
            let a = self.a;
            self.b = self.integrate(&a, self.k + 1);
        }
    }

    /// Seconds since the start.
    #[inline]
    fn rel(&self, t: GpsTime) -> f64 {
        (t - self.start) as f64 * 1e-9
    }

    /// Vehicle position (without vibration) and the interpolated Earth terms.
    #[inline]
    fn position(&mut self, t: f64) -> ([f64; 3], EarthPos) {
        if t <= 0.0 {
            // Before the start: extrapolate linearly (the IMU never needs it).
            let a = if self.a.t == 0.0 {
                self.a
            } else {
                self.reset();
                self.a
            };
            let y = [
                a.y[0] + t * a.dy[0],
                a.y[1] + t * a.dy[1],
                a.y[2] + t * a.dy[2],
            ];
            return (y, a.earth);
        }
        self.seek(t);
        let (a, b) = (&self.a, &self.b);
        let h = b.t - a.t;
        let s = (t - a.t) / h;
        let s2 = s * s;
        let s3 = s2 * s;
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        let y =
            [0, 1, 2].map(|i| h00 * a.y[i] + h10 * h * a.dy[i] + h01 * b.y[i] + h11 * h * b.dy[i]);
        (y, EarthPos::lerp(&a.earth, &b.earth, s))
    }

    #[inline]
    fn sensed(
        kin: &Kinematics,
        e: &EarthPos,
    ) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let v = &kin.vel_n;
        let w_ie = Vector3::new(OMEGA_E * e.cos_lat, 0.0, -OMEGA_E * e.sin_lat);
        let tan_lat = e.sin_lat / e.cos_lat;
        let w_en = Vector3::new(
            v.y * e.inv_rn_h,
            -v.x * e.inv_rm_h,
            -v.y * tan_lat * e.inv_rn_h,
        );
        let c_bn = kin.c_nb.transpose();
        let w_ib = kin.w_nb_b + c_bn * (w_ie + w_en);
        let f_n = kin.acc_n + (2.0 * w_ie + w_en).cross(v) - Vector3::new(0.0, 0.0, e.g);
        (w_ib, c_bn * f_n, w_ie, w_en)
    }

    /// Interpolated Earth terms at `t` (no position needed).
    #[inline]
    fn earth_at(&mut self, t: f64) -> EarthPos {
        if t <= 0.0 {
            return self.position(t).1;
        }
        self.seek(t);
        let s = (t - self.a.t) / (self.b.t - self.a.t);
        EarthPos::lerp(&self.a.earth, &self.b.earth, s)
    }

    /// Ideal gyro and accelerometer rates at `t` seconds after the start
    /// (the fast path for high-rate internal IMU sampling).
    #[inline]
    pub fn rates_at_s(&mut self, t: f64) -> SensedRates {
        let kin = self.traj.kinematics_at(t, &mut self.cursor);
        let e = self.earth_at(t);
        let (w_ib_b, f_b, _, _) = Self::sensed(&kin, &e);
        SensedRates { w_ib_b, f_b }
    }

    /// Ideal rates at GPS time `t`.
    pub fn rates_at(&mut self, t: GpsTime) -> SensedRates {
        let s = self.rel(t);
        self.rates_at_s(s)
    }

    /// The full truth at GPS time `t`.
    pub fn state_at(&mut self, t: GpsTime) -> TruthPoint {
        let ts = self.rel(t);
        let kin = self.traj.kinematics_at(ts, &mut self.cursor);
        let (y, e) = self.position(ts);
        let (w_ib_b, f_b, w_ie_n, w_en_n) = Self::sensed(&kin, &e);
        // Vibration displacement in NED → geodetic offset (D_R⁻¹).
        let d = &kin.dr_n;
        let pos = Geodetic::new(
            y[0] + d.x * e.inv_rm_h,
            y[1] + d.y * e.inv_rn_h / e.cos_lat,
            y[2] - d.z,
        );
        TruthPoint {
            nav: NavState {
                time: t,
                pos,
                vel: kin.vel_n,
                q_nb: kin.q_nb(),
            },
            kin,
            w_ib_b,
            f_b,
            w_ie_n,
            w_en_n,
        }
    }

    /// Exact increments ∫ω_ib^b dt and ∫f^b dt over `(t0, t1]`.
    pub fn increment_between(&mut self, t0: GpsTime, t1: GpsTime) -> (Vector3<f64>, Vector3<f64>) {
        let (a, b) = (self.rel(t0), self.rel(t1));
        self.increment_s(a, b)
    }

    /// Exact increments over `(a, b]` in seconds after the start.
    pub fn increment_s(&mut self, a: f64, b: f64) -> (Vector3<f64>, Vector3<f64>) {
        let mut dth = Vector3::zeros();
        let mut dv = Vector3::zeros();
        if b <= a {
            return (dth, dv);
        }
        let n = ((b - a) / self.quad_sub_s).ceil().max(1.0) as usize;
        let h = (b - a) / n as f64;
        for j in 0..n {
            let mid = a + (j as f64 + 0.5) * h;
            for (x, w) in GL_X.iter().zip(GL_W.iter()) {
                let r = self.rates_at_s(mid + 0.5 * h * x);
                dth += r.w_ib_b * (0.5 * h * w);
                dv += r.f_b * (0.5 * h * w);
            }
        }
        (dth, dv)
    }

    /// The truth at `t` and the exact increments since the previous call
    /// (since the start for the first call).
    pub fn next(&mut self, t: GpsTime) -> (NavState, ImuSample) {
        let (dtheta, dvel) = self.increment_between(self.prev, t);
        self.prev = t;
        let p = self.state_at(t);
        (
            p.nav,
            ImuSample {
                time: t,
                dtheta,
                dvel,
                odo_speed: None,
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::{Segment, TrajectoryOptions, builtin_segments};
    use navsync::attitude::wrap_pi;
    use navsync::earth::{LocalEarth, ned_offset};
    use navsync::ins::{Increment, Mechanization};

    fn origin() -> Geodetic {
        Geodetic::from_deg(30.4447873701, 114.4718632047, 20.9)
    }

    fn start() -> GpsTime {
        GpsTime::from_week_sow(2300, 100000.0)
    }

    #[test]
    fn static_imu_reads_earth_rate_and_gravity() {
        let segs = [Segment::Static { duration_s: 10.0 }];
        for &yaw_deg in &[0.0, 37.0] {
            let opts = TrajectoryOptions {
                initial_heading_rad: f64::to_radians(yaw_deg),
                ..Default::default()
            };
            let traj = Trajectory::from_segments(origin(), &segs, opts).unwrap();
            let mut g = TruthGenerator::new(&traj, start());
            let t = start().add_seconds(1.0);
            let (nav, s) = g.next(t);
            let lat = origin().lat_rad;
            let gamma = gravity(lat.sin(), origin().h_m);
            // Expected in NED, rotated into the body by the heading.
            let w_n = Vector3::new(OMEGA_E * lat.cos(), 0.0, -OMEGA_E * lat.sin());
            let w_b = nav.c_nb().transpose() * w_n;
            assert!((s.dtheta - w_b).norm() < 1e-15, "{} vs {w_b}", s.dtheta);
            // Accelerometers read −γ on the down axis and nothing else.
            assert!(
                (s.dvel - Vector3::new(0.0, 0.0, -gamma)).norm() < 1e-13,
                "{}",
                s.dvel
            );
            // The north component is Ω cos φ = 6.28666e-5 rad/s at 30.4448°.
            assert!((w_n.x - 6.286_662e-5).abs() < 1e-10, "{}", w_n.x);
            // The position does not move.
            assert!(ned_offset(&origin(), &nav.pos).norm() < 1e-9);
        }
    }

    /// Integrates exact increments with the mechanization from the true
    /// initial state and returns the largest position, velocity and
    /// attitude errors against the truth at every step.
    fn mechanize(traj: &Trajectory, rate_hz: f64) -> (f64, f64, f64) {
        let mut g = TruthGenerator::new(traj, start());
        let dt_ns = (1e9 / rate_hz).round() as i64;
        let mut t = start() + dt_ns;
        let (mut nav, first) = g.next(t);
        let mut mech = Mechanization::new();
        mech.set_previous(Increment {
            dtheta: first.dtheta,
            dvel: first.dvel,
            dt: dt_ns as f64 * 1e-9,
        });
        let (mut ep, mut ev, mut ea) = (0.0f64, 0.0f64, 0.0f64);
        let end = start().add_seconds(traj.duration_s());
        while t + dt_ns <= end {
            let t0 = t;
            t = t + dt_ns;
            let (truth, s) = g.next(t);
            let inc = Increment {
                dtheta: s.dtheta,
                dvel: s.dvel,
                dt: t.seconds_since(t0),
            };
            mech.step(&mut nav, &inc);
            ep = ep.max(ned_offset(&truth.pos, &nav.pos).norm());
            ev = ev.max((truth.vel - nav.vel).norm());
            ea = ea.max(truth.q_nb.angle_to(&nav.q_nb));
        }
        (ep, ev, ea)
    }

    #[test]
    fn constant_rate_turn_integrates_to_the_expected_heading() {
        // 10 m/s, then a 270° turn whose yaw rate ramps to 12°/s and holds.
        let segs = [
            Segment::Accelerate {
                speed_mps: 10.0,
                accel_mps2: Some(2.0),
            },
            Segment::Turn {
                angle_deg: 270.0,
                yaw_rate_deg_s: Some(12.0),
                radius_m: None,
                ramp_s: Some(1.0),
            },
        ];
        let opts = TrajectoryOptions {
            initial_heading_rad: 0.2,
            ..Default::default()
        };
        let traj = Trajectory::from_segments(origin(), &segs, opts).unwrap();
        let (ep, _, ea) = mechanize(&traj, 200.0);
        // Mechanization from exact increments keeps the heading to ~1e-8 rad
        // (two-sample coning on a smooth rate); 1e-6 rad leaves margin.
        assert!(ea < 1e-6, "attitude error {ea}");
        assert!(ep < 1e-3, "position error {ep}");
        // The heading reached is the initial heading plus 270°, checked
        // through the truth itself (attitude of the final state).
        let mut g = TruthGenerator::new(&traj, start());
        let end = g.state_at(start().add_seconds(traj.duration_s()));
        let yaw = end.nav.euler().yaw_rad;
        assert!(
            wrap_pi(yaw - (0.2 + 270f64.to_radians())).abs() < 1e-12,
            "{yaw}"
        );
    }

    fn drive(duration_s: f64) -> Trajectory {
        let segs = builtin_segments("urban", duration_s, 3).unwrap();
        let opts = TrajectoryOptions {
            initial_heading_rad: 45f64.to_radians(),
            roll_gain_rad_per_mps2: 0.5f64.to_radians(),
            ..Default::default()
        };
        Trajectory::from_segments(origin(), &segs, opts).unwrap()
    }

    #[test]
    fn mechanization_of_exact_increments_stays_within_1cm_for_60s() {
        // 60 s of hard driving: 3 m/s² start, a 15°/s turn, a lane change,
        // a 4° hill, a 4 m/s² stop.
        let segs = [
            Segment::Static { duration_s: 2.0 },
            Segment::Accelerate {
                speed_mps: 15.0,
                accel_mps2: Some(3.0),
            },
            Segment::Turn {
                angle_deg: 90.0,
                yaw_rate_deg_s: Some(15.0),
                radius_m: None,
                ramp_s: Some(1.0),
            },
            Segment::LaneChange {
                offset_m: -3.5,
                duration_s: Some(3.0),
            },
            Segment::Hill {
                grade_deg: 4.0,
                duration_s: 20.0,
            },
            Segment::Turn {
                angle_deg: -45.0,
                yaw_rate_deg_s: Some(10.0),
                radius_m: None,
                ramp_s: Some(1.0),
            },
            Segment::Stop {
                duration_s: 3.0,
                decel_mps2: Some(4.0),
            },
        ];
        let opts = TrajectoryOptions {
            initial_heading_rad: 45f64.to_radians(),
            roll_gain_rad_per_mps2: 0.5f64.to_radians(),
            duration_s: Some(60.0),
            ..Default::default()
        };
        let traj = Trajectory::from_segments(origin(), &segs, opts).unwrap();
        assert!(traj.segments().last().unwrap().t1 <= 60.0);
        let (ep, ev, ea) = mechanize(&traj, 200.0);
        eprintln!(
            "exact increments through the mechanization over {} s: max errors {ep:.3e} m, {ev:.3e} m/s, {ea:.3e} rad",
            traj.duration_s()
        );
        assert!(ep < 0.01, "position error {ep} m");
        assert!(
            ev < 1e-3 && ea < 1e-5,
            "velocity {ev} m/s, attitude {ea} rad"
        );
    }

    /// A reference drive sampled at 10 Hz (as a real reference system's
    /// file, rounded as KF-GINS writes it) and fitted: its exact
    /// increments mechanize to its own truth within 1 cm over 10 min, and
    /// that truth follows the reference to the fit's resolution.
    #[test]
    fn fitted_reference_drive_mechanizes_to_its_truth_and_follows_the_reference() {
        use crate::fitted::FittedMotion;
        use navsync::io::kfgins::NavRecord;
        let source = drive(600.0);
        let mut g = TruthGenerator::new(&source, start());
        let round = |x: f64, d: i32| (x * 10f64.powi(d)).round() / 10f64.powi(d);
        let records: Vec<NavRecord> = (0..=6000)
            .map(|k| {
                let t = start().add_seconds(k as f64 * 0.1);
                let p = g.state_at(t);
                let e = p.nav.euler().to_deg();
                NavRecord {
                    week: 0,
                    time: t,
                    lat_deg: round(p.nav.pos.lat_rad.to_degrees(), 10),
                    lon_deg: round(p.nav.pos.lon_rad.to_degrees(), 10),
                    h_m: round(p.nav.pos.h_m, 4),
                    vel: [0.0; 3],
                    att_deg: [round(e[0], 5), round(e[1], 5), round(e[2], 5)],
                }
            })
            .collect();
        let fitted = Trajectory::from_fitted(FittedMotion::fit(&records).unwrap());
        let (ep, ev, ea) = mechanize(&fitted, 200.0);
        eprintln!(
            "fitted drive: exact increments through the mechanization over {} s: max errors {ep:.3e} m, {ev:.3e} m/s, {ea:.3e} rad",
            fitted.duration_s()
        );
        assert!(ep < 0.01, "position error {ep} m");
        assert!(
            ev < 1e-3 && ea < 1e-5,
            "velocity {ev} m/s, attitude {ea} rad"
        );
        // The fitted truth against the source (its speed reaches > 10 m/s).
        let mut gf = TruthGenerator::new(&fitted, start());
        let mut worst: f64 = 0.0;
        for k in (5..6000).step_by(7) {
            let t = start().add_seconds(k as f64 * 0.1 + 0.05);
            let (a, b) = (g.state_at(t).nav, gf.state_at(t).nav);
            let le = LocalEarth::new(&a.pos, &a.vel);
            let d = le.geodetic_delta_to_ned(
                b.pos.lat_rad - a.pos.lat_rad,
                b.pos.lon_rad - a.pos.lon_rad,
                b.pos.h_m - a.pos.h_m,
            );
            worst = worst.max(d.norm());
        }
        assert!(worst < 0.05, "fitted truth {worst} m from the reference");
    }

    #[test]
    fn mechanization_of_exact_increments_stays_within_1cm_for_10min() {
        // A 10 min random urban drive (turns, lane changes, hills, stops);
        // the truth is exact, so the whole error is the mechanization's.
        let traj = drive(600.0);
        let v_max = (0..6000)
            .map(|k| traj.vehicle(k as f64 * 0.1).speed_mps)
            .fold(0.0, f64::max);
        assert!(v_max > 10.0, "the drive should move: {v_max}");
        let (ep, ev, ea) = mechanize(&traj, 200.0);
        eprintln!(
            "exact increments through the mechanization over {} s: max errors {ep:.3e} m, {ev:.3e} m/s, {ea:.3e} rad",
            traj.duration_s()
        );
        assert!(ep < 0.01, "position error {ep} m");
        assert!(
            ev < 1e-3 && ea < 1e-5,
            "velocity {ev} m/s, attitude {ea} rad"
        );
    }

    #[test]
    fn remaining_error_is_the_mechanizations_second_order_term() {
        // Halving the step divides the error by ~4: what remains is the
        // O(Δt²) error of the two-sample mechanization, and the truth is
        // self-consistent (an error of the truth would not shrink).
        let traj = drive(300.0);
        let (e100, _, _) = mechanize(&traj, 100.0);
        let (e200, _, _) = mechanize(&traj, 200.0);
        let ratio = e100 / e200;
        assert!((3.5..4.5).contains(&ratio), "{e100} / {e200} = {ratio}");
    }

    #[test]
    fn truth_position_follows_the_velocity() {
        // The Hermite-interpolated position between grid nodes agrees with
        // the velocity (central difference over 1 ms).
        let traj = drive(200.0);
        let mut g = TruthGenerator::new(&traj, start());
        for &ts in &[61.003, 87.1234, 150.5] {
            let t = start().add_seconds(ts);
            let p0 = g.state_at(t.add_seconds(-5e-4));
            let p = g.state_at(t);
            let p1 = g.state_at(t.add_seconds(5e-4));
            let d = ned_offset(&p0.nav.pos, &p1.nav.pos) / 1e-3;
            // ECEF differences of ~1 cm carry ~1e-9 m of rounding: 1e-6 m/s here.
            assert!((d - p.nav.vel).norm() < 1e-5, "{d} vs {}", p.nav.vel);
            let le = LocalEarth::new(&p.nav.pos, &p.nav.vel);
            assert!(le.g > 9.79);
        }
        // Going back in time re-integrates and gives the same answer.
        let a = g.state_at(start().add_seconds(10.0));
        let b = TruthGenerator::new(&traj, start()).state_at(start().add_seconds(10.0));
        assert_eq!(a.nav.pos, b.nav.pos);
    }
}
