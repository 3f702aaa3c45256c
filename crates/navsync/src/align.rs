//! Initial alignment of a land vehicle's INS from its own IMU and GNSS
//! data, with no initial attitude given: push IMU samples and GNSS fixes in
//! time order and get the initial navigation state and its σ once it is
//! determined.
//!
//! - **Roll and pitch by static levelling**: at rest the accelerometers
//!   measure f^b = −C_n^bᵀ·g^n, so (FRD body, NED navigation frame)
//!   θ = atan2(f_x, √(f_y² + f_z²)) and φ = atan2(−f_y, −f_z)
//!   (Groves, *Principles of GNSS, Inertial, and Multisensor Integrated
//!   Navigation Systems*, 2nd ed., §5.6.2, eqs 5.101–5.102). Their σ is
//!   the accelerometer bias over g (the bias is not separable from tilt at
//!   rest) and the averaged noise.
//! - **In motion, without a standstill**: the same from the specific force
//!   with the vehicle's acceleration (from GNSS velocity) removed,
//!   f^n = a^n − g^n.
//! - **Heading from GNSS velocity** (course over ground) once the vehicle
//!   moves faster than `min_speed_mps`: a land vehicle moves along its
//!   forward axis (no sideslip at low lateral acceleration; Groves §6.1.4,
//!   heading from trajectory), σ_ψ = σ_v / v plus a sideslip allowance. A
//!   vehicle that reverses moves against its forward axis: the IMU's
//!   forward specific force then has the opposite sign to the GNSS
//!   along-track acceleration, and the heading is turned by 180°.
//! - **No motion at all**: heading is unobservable (a MEMS gyro cannot
//!   sense the earth's rotation); the run starts levelled with heading 0
//!   and σ_ψ = 180°, and says so.

use nalgebra::Vector3;
use serde::Serialize;

use crate::attitude::Euler;
use crate::earth::{GAMMA_E, LocalEarth};
use crate::filter::gnss::GnssFix;
use crate::ins::{ImuSample, NavState};
use crate::time::GpsTime;

/// Settings of the alignment.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AlignOptions {
    /// Heading is taken from GNSS velocity from this horizontal speed on (m/s).
    pub min_speed_mps: f64,
    /// A standstill: GNSS speed below this (m/s)…
    pub still_speed_mps: f64,
    /// …and mean angular rate below this (rad/s) over the last second.
    pub still_rate_rad_s: f64,
    /// Sideslip and mounting allowance added to the heading σ (rad).
    pub heading_allowance_rad: f64,
    /// Accelerometer bias σ (m/s²), which limits levelling.
    pub accel_bias_sd_mps2: f64,
    /// GNSS antenna lever arm, body FRD (m).
    pub lever_b: [f64; 3],
    /// Yaw of the IMU's x axis relative to the vehicle's forward axis (rad).
    pub mount_yaw_rad: f64,
}

impl Default for AlignOptions {
    fn default() -> Self {
        AlignOptions {
            min_speed_mps: 3.0,
            still_speed_mps: 0.2,
            still_rate_rad_s: 1.0f64.to_radians(),
            heading_allowance_rad: 0.5f64.to_radians(),
            accel_bias_sd_mps2: 0.01,
            lever_b: [0.0; 3],
            mount_yaw_rad: 0.0,
        }
    }
}

/// How the attitude was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum AlignMethod {
    /// Roll/pitch from a standstill, heading from GNSS velocity.
    StaticLevellingAndCourse,
    /// Roll/pitch from acceleration-compensated specific force in motion,
    /// heading from GNSS velocity.
    InMotion,
    /// The vehicle never moved: levelled, heading unknown.
    NoMotion,
}

/// The initial state the alignment found.
#[derive(Clone, Debug, Serialize)]
pub struct Alignment {
    #[serde(skip)]
    pub time: GpsTime,
    pub time_sow: f64,
    #[serde(skip)]
    pub nav: NavState,
    pub attitude_deg: [f64; 3],
    /// σ of roll, pitch, yaw (rad).
    pub att_sd_rad: [f64; 3],
    pub pos_sd_m: [f64; 3],
    pub vel_sd_mps: [f64; 3],
    pub method: AlignMethod,
    /// Length of the standstill used for levelling (s).
    pub standstill_s: f64,
    /// Horizontal speed at alignment (m/s).
    pub speed_mps: f64,
    /// The vehicle was reversing (heading turned by 180°).
    pub reversing: bool,
    /// Whether the reversing check had enough acceleration to decide.
    pub reversing_checked: bool,
    pub note: String,
}

/// Running sums of specific force and angular rate over a span.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    dv: Vector3<f64>,
    dth: Vector3<f64>,
    dt: f64,
    n: usize,
}

impl Sums {
    fn add(&mut self, s: &ImuSample, dt: f64) {
        self.dv += s.dvel;
        self.dth += s.dtheta;
        self.dt += dt;
        self.n += 1;
    }
    fn f(&self) -> Vector3<f64> {
        self.dv / self.dt.max(1e-9)
    }
    fn w(&self) -> Vector3<f64> {
        self.dth / self.dt.max(1e-9)
    }
}

/// Levelling: roll and pitch from a specific force in the body frame that
/// is minus gravity (plus vehicle acceleration removed), Groves eqs
/// 5.101–5.102.
pub fn level(f_b: &Vector3<f64>) -> (f64, f64) {
    let pitch = f_b.x.atan2((f_b.y * f_b.y + f_b.z * f_b.z).sqrt());
    let roll = (-f_b.y).atan2(-f_b.z);
    (roll, pitch)
}

/// The streaming aligner.
#[derive(Clone, Debug)]
pub struct Aligner {
    opts: AlignOptions,
    last_imu: Option<GpsTime>,
    /// IMU sums since the last GNSS fix, and over the current standstill.
    since_fix: Sums,
    still: Sums,
    /// The standstill's sums up to its last still fix.
    still_confirmed: Sums,
    still_start: Option<GpsTime>,
    /// The last completed standstill: its sums, start and end.
    last_still: Option<(Sums, GpsTime, GpsTime)>,
    /// The first fix of the current standstill and of the last one.
    still_start_fix: Option<GnssFix>,
    last_still_fix: Option<GnssFix>,
    /// Angle increments since the last standstill ended (rad, body).
    dth_since_still: Vector3<f64>,
    /// The previous fix and its velocity, when it had one.
    prev_fix: Option<(GnssFix, Option<Vector3<f64>>)>,
    /// The previous interval's IMU sums (for the fix before).
    first_fix: Option<GnssFix>,
    /// The last velocity from positions: middle of its interval, value.
    last_mid: Option<(GpsTime, Vector3<f64>)>,
    /// The last such velocity's correction to the fix time (m/s).
    last_corr: Vector3<f64>,
    done: bool,
}

impl Aligner {
    pub fn new(opts: AlignOptions) -> Self {
        Aligner {
            opts,
            last_imu: None,
            since_fix: Sums::default(),
            still: Sums::default(),
            still_confirmed: Sums::default(),
            still_start: None,
            last_still: None,
            still_start_fix: None,
            last_still_fix: None,
            dth_since_still: Vector3::zeros(),
            prev_fix: None,
            first_fix: None,
            last_mid: None,
            last_corr: Vector3::zeros(),
            done: false,
        }
    }

    pub fn push_imu(&mut self, s: &ImuSample) {
        let dt = match self.last_imu {
            Some(t) if s.time > t => (s.time - t) as f64 * 1e-9,
            Some(_) => return,
            None => {
                self.last_imu = Some(s.time);
                return;
            }
        };
        self.last_imu = Some(s.time);
        // Gaps: do not average across them.
        if dt > 0.5 {
            self.since_fix = Sums::default();
            return;
        }
        self.since_fix.add(s, dt);
        if self.still_start.is_some() {
            self.still.add(s, dt);
        } else {
            self.dth_since_still += s.dtheta;
        }
    }

    /// Velocity of a fix at its time: its own, or from positions (≤ 2 s
    /// apart). A position difference gives the velocity at the middle of
    /// the interval; it is carried to the fix time with the acceleration
    /// between the last two middles, and its σ allows for the change of
    /// acceleration (half of that correction).
    fn velocity_of(&mut self, fix: &GnssFix) -> Option<(Vector3<f64>, Vector3<f64>)> {
        if let (Some(v), Some(sd)) = (fix.vel, fix.vel_sd) {
            return Some((v, sd));
        }
        if let Some(v) = fix.vel {
            return Some((v, Vector3::repeat(0.1)));
        }
        let (prev, _) = self.prev_fix.as_ref()?;
        let dt = fix.time.seconds_since(prev.time);
        if !(dt > 0.0 && dt <= 2.0) {
            self.last_mid = None;
            return None;
        }
        let le = LocalEarth::new(&fix.pos, &Vector3::zeros());
        let d = le.geodetic_delta_to_ned(
            fix.pos.lat_rad - prev.pos.lat_rad,
            fix.pos.lon_rad - prev.pos.lon_rad,
            fix.pos.h_m - prev.pos.h_m,
        );
        let v_mid = d / dt;
        let t_mid = prev.time.add_seconds(0.5 * dt);
        let mut sd = (fix.pos_sd.component_mul(&fix.pos_sd)
            + prev.pos_sd.component_mul(&prev.pos_sd))
        .map(f64::sqrt)
            / dt;
        let mut v = v_mid;
        self.last_corr = Vector3::zeros();
        if let Some((t0, v0)) = self.last_mid {
            let span = t_mid.seconds_since(t0);
            if span > 0.0 && span <= 2.0 {
                let corr = (v_mid - v0) / span * (0.5 * dt);
                v += corr;
                sd += corr.abs() * 0.5;
                self.last_corr = corr;
            }
        }
        self.last_mid = Some((t_mid, v_mid));
        Some((v, sd))
    }

    /// Pushes a GNSS fix (after the IMU samples up to its time); returns
    /// the alignment when this fix completes it.
    pub fn push_gnss(&mut self, fix: &GnssFix) -> Option<Alignment> {
        if self.done {
            return None;
        }
        self.first_fix.get_or_insert(*fix);
        let vel = self.velocity_of(fix);
        let interval = std::mem::take(&mut self.since_fix);
        let mut result = None;
        if let Some((v, v_sd)) = vel {
            let speed = v.x.hypot(v.y);
            let rate = interval.w().norm();
            let still = speed < self.opts.still_speed_mps
                && interval.n > 0
                && rate < self.opts.still_rate_rad_s;
            if still {
                if self.still_start.is_none() {
                    self.still_start = Some(fix.time);
                    self.still_start_fix = Some(*fix);
                    self.still = Sums::default();
                }
                self.still_confirmed = self.still;
            } else if let Some(start) = self.still_start.take() {
                // Only the samples up to the last still fix.
                let s = std::mem::take(&mut self.still_confirmed);
                if s.dt > 0.5 {
                    self.last_still = Some((s, start, start.add_seconds(s.dt)));
                    self.last_still_fix = self.still_start_fix;
                    // The rotation since the standstill counts from here:
                    // the samples after its last still fix.
                    self.dth_since_still = interval.dth;
                }
                self.still = Sums::default();
            }
            // In motion without a recent standstill, levelling needs the
            // vehicle's acceleration: a velocity at the previous fix too.
            let levelled = self
                .last_still
                .is_some_and(|(_, _, end)| fix.time.seconds_since(end) <= 60.0);
            let have_accel = self
                .prev_fix
                .as_ref()
                .is_some_and(|(p, pv)| pv.is_some() && fix.time.seconds_since(p.time) <= 2.0);
            if speed >= self.opts.min_speed_mps && interval.n > 0 && (levelled || have_accel) {
                result = Some(self.align_at(fix, &v, &v_sd, speed, &interval));
            }
            self.prev_fix = Some((*fix, Some(v)));
        } else {
            self.prev_fix = Some((*fix, None));
        }
        if result.is_some() {
            self.done = true;
        }
        result
    }

    fn align_at(
        &self,
        fix: &GnssFix,
        v: &Vector3<f64>,
        v_sd: &Vector3<f64>,
        speed: f64,
        interval: &Sums,
    ) -> Alignment {
        let o = &self.opts;
        let g = crate::earth::gravity(fix.pos.lat_rad.sin(), fix.pos.h_m);
        // Vehicle acceleration over the interval, from GNSS velocity.
        let accel = self.prev_fix.as_ref().and_then(|(p, pv)| {
            let dt = fix.time.seconds_since(p.time);
            let pv = (*pv)?;
            (dt > 0.0 && dt <= 2.0).then(|| (v - pv) / dt)
        });
        // Roll and pitch: a standstill that ended at most 60 s ago, else
        // in motion with the acceleration removed.
        let recent_still = self
            .last_still
            .filter(|(_, _, end)| fix.time.seconds_since(*end) <= 60.0);
        let mut reversing = false;
        let mut checked = false;
        let (roll, pitch, tilt_sd, method, standstill_s) = match recent_still {
            Some((s, start, end)) => {
                let (r, p) = level(&s.f());
                // σ: bias over g, and the mean of white noise over the span
                // (1 mg per √s floor).
                let sd = (o.accel_bias_sd_mps2 / g).hypot(0.001 / s.dt.max(1.0).sqrt());
                // Reversing: the along-track acceleration from GNSS against
                // the IMU's forward specific force with gravity removed
                // (pitch known from the standstill).
                if let Some(a_n) = accel {
                    let a_track = (a_n.x * v.x + a_n.y * v.y) / speed;
                    let a_x = interval.f().x - g * p.sin();
                    if a_track.abs() > 0.3 && a_x.abs() > 0.15 {
                        checked = true;
                        reversing = a_track * a_x < 0.0;
                    }
                }
                (
                    r,
                    p,
                    sd,
                    AlignMethod::StaticLevellingAndCourse,
                    end.seconds_since(start),
                )
            }
            None => {
                // f^b = C_n^b (a^n − g^n): remove the vehicle acceleration
                // expressed in a level frame along the course (forward) or
                // against it (reversing), then level. Only the right
                // hypothesis leaves a specific force of norm g; the wrong
                // one leaves ≈ √(g² + 4a²).
                let a_n = accel.unwrap_or_else(Vector3::zeros);
                let psi = v.y.atan2(v.x);
                let (sn, cs) = psi.sin_cos();
                let a_h = Vector3::new(cs * a_n.x + sn * a_n.y, -sn * a_n.x + cs * a_n.y, a_n.z);
                let f = interval.f();
                let f_fwd = f - a_h;
                let f_rev = f - Vector3::new(-a_h.x, -a_h.y, a_h.z);
                if a_h.x.hypot(a_h.y) > 0.5 {
                    checked = true;
                    reversing = (f_rev.norm() - g).abs() < (f_fwd.norm() - g).abs();
                }
                let (r, p) = level(if reversing { &f_rev } else { &f_fwd });
                let a_sd = v_sd.norm() * std::f64::consts::SQRT_2;
                let sd = (o.accel_bias_sd_mps2.hypot(a_sd)) / g;
                (r, p, sd, AlignMethod::InMotion, 0.0)
            }
        };
        let course = v.y.atan2(v.x);
        let mut yaw = course - o.mount_yaw_rad;
        if reversing {
            yaw += std::f64::consts::PI;
        }
        let yaw = wrap_pi(yaw);
        // Heading error comes from the cross-track velocity error only:
        // the noise part of σ_v, and half the cross-track part of the
        // correction of a velocity from positions to the fix time.
        let (sn, cs) = course.sin_cos();
        let corr_cross = (-sn * self.last_corr.x + cs * self.last_corr.y).abs();
        let corr_abs = self.last_corr.x.hypot(self.last_corr.y);
        let noise_h = (v_sd.x.hypot(v_sd.y) - 0.5 * corr_abs).max(0.0) / std::f64::consts::SQRT_2;
        let v_cross_sd = noise_h.hypot(0.5 * corr_cross);
        let yaw_sd = (v_cross_sd / speed).hypot(o.heading_allowance_rad);
        let att = Euler::new(roll, pitch, yaw);
        let mut nav = NavState::new(fix.time, fix.pos, *v, &att);
        // The fix is the antenna's: move to the IMU.
        let le = LocalEarth::new(&nav.pos, &nav.vel);
        let d = le.ned_to_geodetic_delta(&(nav.c_nb() * Vector3::from(o.lever_b)));
        nav.pos.lat_rad -= d.x;
        nav.pos.lon_rad -= d.y;
        nav.pos.h_m -= d.z;
        // Levelled over a standstill: the vehicle stood with this attitude
        // turned back by the rotation since (about the down axis, which is
        // −f̂ of the standstill in the body frame). Start the run at the
        // standstill's first fix, at rest, so that the filter learns the
        // biases there as it would from a known initial state.
        let mut start_s = 0.0;
        if let (Some((st, _, _)), Some(sf)) = (recent_still, self.last_still_fix) {
            let down_b = -st.f().normalize();
            let turned = self.dth_since_still.dot(&down_b);
            let yaw0 = wrap_pi(yaw - turned);
            let mut n0 = NavState::new(
                sf.time,
                sf.pos,
                Vector3::zeros(),
                &Euler::new(roll, pitch, yaw0),
            );
            let d = le.ned_to_geodetic_delta(&(n0.c_nb() * Vector3::from(o.lever_b)));
            n0.pos.lat_rad -= d.x;
            n0.pos.lon_rad -= d.y;
            n0.pos.h_m -= d.z;
            start_s = fix.time.seconds_since(sf.time);
            nav = n0;
        }
        let note = format!(
            "aligned at {:.3} s of week, {:.1} m/s: roll {:.2}°, pitch {:.2}° ({}), heading {:.2}° ± {:.2}° from GNSS course{}",
            fix.time.sow(),
            speed,
            roll.to_degrees(),
            pitch.to_degrees(),
            match method {
                AlignMethod::StaticLevellingAndCourse =>
                    format!("levelled over a {standstill_s:.0} s standstill"),
                _ => "levelled in motion".into(),
            },
            yaw.to_degrees(),
            yaw_sd.to_degrees(),
            match (checked, reversing) {
                (true, true) => ", vehicle reversing: turned by 180°",
                (true, false) => "",
                (false, _) => " (reversing not checked: too little acceleration)",
            }
        ) + &if start_s > 0.0 {
            format!(
                "; the run starts at the standstill, {start_s:.1} s earlier ({:.3} s of week)",
                nav.time.sow()
            )
        } else {
            String::new()
        };
        Alignment {
            time: nav.time,
            time_sow: nav.time.sow(),
            nav,
            attitude_deg: [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()],
            att_sd_rad: [tilt_sd, tilt_sd, yaw_sd],
            pos_sd_m: fix.pos_sd.into(),
            vel_sd_mps: if start_s > 0.0 {
                [0.05; 3]
            } else {
                (*v_sd).into()
            },
            method,
            standstill_s,
            speed_mps: speed,
            reversing,
            reversing_checked: checked,
            note,
        }
    }

    /// At the end of the data without alignment: levelled from the last
    /// standstill with an unknown heading, at the first fix; `None` without
    /// any GNSS fix (position unknown).
    pub fn finish(&mut self) -> Option<Alignment> {
        if self.done {
            return None;
        }
        let fix = self.first_fix?;
        let still = self
            .last_still
            .map(|(s, a, b)| (s, b.seconds_since(a)))
            .or_else(|| {
                (self.still_start.is_some() && self.still_confirmed.dt > 0.5)
                    .then_some((self.still_confirmed, self.still_confirmed.dt))
            });
        let (roll, pitch, standstill_s) = match still {
            Some((s, len)) => {
                let (r, p) = level(&s.f());
                (r, p, len)
            }
            None => (0.0, 0.0, 0.0),
        };
        let tilt_sd = if standstill_s > 0.0 {
            self.opts.accel_bias_sd_mps2 / GAMMA_E
        } else {
            10f64.to_radians()
        };
        let nav = NavState::new(
            fix.time,
            fix.pos,
            Vector3::zeros(),
            &Euler::new(roll, pitch, 0.0),
        );
        self.done = true;
        Some(Alignment {
            time: fix.time,
            time_sow: fix.time.sow(),
            nav,
            attitude_deg: [roll.to_degrees(), pitch.to_degrees(), 0.0],
            att_sd_rad: [tilt_sd, tilt_sd, std::f64::consts::PI],
            pos_sd_m: fix.pos_sd.into(),
            vel_sd_mps: [0.1; 3],
            method: AlignMethod::NoMotion,
            standstill_s,
            speed_mps: 0.0,
            reversing: false,
            reversing_checked: false,
            note: format!(
                "the vehicle never moved faster than {:.1} m/s: heading is unobservable (a MEMS gyro cannot sense the earth's rotation); levelled, heading set to 0° with σ 180°",
                self.opts.min_speed_mps
            ),
        })
    }
}

fn wrap_pi(a: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut x = a % two_pi;
    if x > std::f64::consts::PI {
        x -= two_pi;
    } else if x < -std::f64::consts::PI {
        x += two_pi;
    }
    x
}

#[cfg(test)]
mod tests {
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

    /// Reversing: the speed grows while the IMU's forward specific force is
    /// negative: the heading is the course turned by 180°.
    #[test]
    fn a_reversing_vehicle_faces_away_from_its_course() {
        let mut al = Aligner::new(AlignOptions::default());
        let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
        let dt = 0.01;
        let mut t = GpsTime::from_week_sow(2000, 1000.0);
        let f_back = Vector3::new(-1.0, 0.0, -GAMMA_E);
        let mut out = None;
        for k in 1..=1000 {
            t = t.add_seconds(dt);
            al.push_imu(&sample(t, f_back, dt));
            if k % 100 == 0 {
                let v = Vector3::new(1.0 * k as f64 * dt, 0.0, 0.0);
                let fix = GnssFix {
                    time: t,
                    pos,
                    pos_sd: Vector3::repeat(0.02),
                    vel: Some(v),
                    vel_sd: Some(Vector3::repeat(0.02)),
                };
                if let Some(x) = al.push_gnss(&fix) {
                    out = Some(x);
                    break;
                }
            }
        }
        let a = out.expect("aligned");
        assert_eq!(a.method, AlignMethod::InMotion);
        assert!(a.reversing_checked && a.reversing);
        assert!((a.nav.euler().yaw_rad.abs() - std::f64::consts::PI).abs() < 1e-9);
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
}
