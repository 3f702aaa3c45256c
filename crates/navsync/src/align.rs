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
//!   rest) and the averaged noise. The tilt error is the bias itself seen
//!   through gravity (see `levelling_tilt_coupling`), so a run started at
//!   the standstill gets that correlation in its initial covariance.
//! - **In motion, without a standstill**: the same from the specific force
//!   with the vehicle's acceleration (from GNSS velocity) removed,
//!   f^n = a^n − g^n, averaged over a window of GNSS velocities
//!   (`motion_window_s`, 5 s) with the specific force carried into the body
//!   frame at the window's start by the gyros; the run starts there.
//! - **Heading from GNSS velocity** (course over ground) once the vehicle
//!   moves faster than `min_speed_mps`: a land vehicle moves along its
//!   forward axis (no sideslip at low lateral acceleration; Groves §6.1.4,
//!   heading from trajectory), σ_ψ = σ_v / v plus a sideslip allowance. A
//!   vehicle that reverses moves against its forward axis: the IMU's
//!   forward specific force then has the opposite sign to the GNSS
//!   along-track acceleration, and the heading is turned by 180°.
//! - **Heading from a dual-antenna baseline** when the receiver measures
//!   one (u-blox moving base, NAV-RELPOSNED relPosHeading): the azimuth of
//!   the baseline b^n = C_b^n u^b, u^b = (cos α, sin α, 0) at the mounting
//!   yaw α (`dual_antenna_yaw_rad`). With C_b^n = R_z(ψ) R_y(θ) R_x(φ)
//!   (Groves eq 2.22), az(b^n) = ψ + atan2(w_y, w_x), w = R_y(θ) R_x(φ) u^b,
//!   so ψ = az − atan2(sin α cos φ, cos θ cos α + sin θ sin α sin φ) with the
//!   levelled roll and pitch (Groves §10.2.5, attitude from multiple
//!   antennas). No motion is needed: over a standstill of a second the run
//!   starts at once, heading σ from the receiver's accHeading plus the
//!   mounting allowance. In motion it replaces the GNSS course.
//! - **A receiver's vehicle heading** (u-blox NAV-PVT headVeh with
//!   headVehValid, dead-reckoning receivers) above `min_speed_mps`, when
//!   its σ (headAcc) beats the course's and it agrees with the course
//!   (turned by 180° when reversing) within 3σ; NAV-PVT's heading of
//!   motion is the course of the velocity used already and adds nothing.
//! - **No motion at all**: heading is unobservable (a MEMS gyro cannot
//!   sense the earth's rotation); the run starts levelled with heading 0
//!   and σ_ψ = 180°, and says so.

#![warn(missing_docs)]

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::attitude::{Euler, wrap_pi};
use crate::earth::{GAMMA_E, LocalEarth};
use crate::filter::gnss::GnssFix;
use crate::ins::{ImuSample, NavState};
use crate::io::heading::{HeadingObs, HeadingSource};
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
    /// Yaw of the IMU's x axis relative to the vehicle's forward axis
    /// (rad), positive from forward towards the vehicle's right: the IMU's
    /// yaw is the vehicle's heading plus this (the sensor sheet's
    /// `mount_deg[2]`, the same convention as the NHC's C_b^v,
    /// `filter::nhc`).
    pub mount_yaw_rad: f64,
    /// Starting in motion: the span of GNSS velocities (s) over which the
    /// tilt and heading are averaged before the run starts at its beginning.
    pub motion_window_s: f64,
    /// Yaw of a dual-antenna baseline (primary → secondary antenna) in the
    /// body frame, from x towards y (rad; 0: along body x).
    pub dual_antenna_yaw_rad: f64,
    /// σ of that mounting yaw (rad), added to the receiver's heading σ.
    pub dual_antenna_yaw_sd_rad: f64,
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
            motion_window_s: 5.0,
            dual_antenna_yaw_rad: 0.0,
            dual_antenna_yaw_sd_rad: 0.5f64.to_radians(),
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
    /// The vehicle never moved fast enough for the course: levelled, the
    /// heading found in the GNSS track before the run
    /// (`pipeline`'s alignment stage, `fusion::course_heading`'s chords).
    NoMotionTrackHeading,
    /// Roll/pitch from a standstill, heading from a dual-antenna baseline.
    StaticLevellingAndDualAntenna,
    /// Roll/pitch in motion, heading from a dual-antenna baseline.
    InMotionDualAntenna,
    /// Roll/pitch from a standstill, heading from the receiver's vehicle
    /// heading.
    StaticLevellingAndReceiverHeading,
    /// Roll/pitch in motion, heading from the receiver's vehicle heading.
    InMotionReceiverHeading,
}

impl AlignMethod {
    /// The method with the heading taken from `from` instead of the course.
    fn with_heading(self, from: HeadingFrom) -> Self {
        let static_levelled = matches!(
            self,
            AlignMethod::StaticLevellingAndCourse
                | AlignMethod::StaticLevellingAndDualAntenna
                | AlignMethod::StaticLevellingAndReceiverHeading
        );
        match (from, static_levelled) {
            (HeadingFrom::Course, _) => self,
            (HeadingFrom::Baseline, true) => AlignMethod::StaticLevellingAndDualAntenna,
            (HeadingFrom::Baseline, false) => AlignMethod::InMotionDualAntenna,
            (HeadingFrom::Vehicle, true) => AlignMethod::StaticLevellingAndReceiverHeading,
            (HeadingFrom::Vehicle, false) => AlignMethod::InMotionReceiverHeading,
        }
    }
}

/// Where an aligned heading came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum HeadingFrom {
    Course,
    Baseline,
    Vehicle,
}

/// Body yaw ψ from a baseline azimuth `az` at roll φ and pitch θ, for a
/// baseline at yaw α in the body frame: az = ψ + atan2(w_y, w_x) with
/// w = R_y(θ) R_x(φ) (cos α, sin α, 0) (C_b^n = R_z R_y R_x, Groves eq 2.22).
pub fn yaw_from_baseline(az: f64, roll: f64, pitch: f64, alpha: f64) -> f64 {
    let (sa, ca) = alpha.sin_cos();
    let w_x = pitch.cos() * ca + pitch.sin() * sa * roll.sin();
    let w_y = sa * roll.cos();
    wrap_pi(az - w_y.atan2(w_x))
}

/// How long headings are kept for the alignment to look up (s).
const HEADING_HISTORY_S: f64 = 15.0;
/// A heading is used for an epoch when it is at most this far from it (s).
const HEADING_MATCH_S: f64 = 0.5;
/// A standstill this long (s) with a dual-antenna heading aligns at once.
const DUAL_ANTENNA_STILL_S: f64 = 1.0;

/// Levelling in motion: f^b = C_n^b (a^n − g^n), so the vehicle
/// acceleration `a_n` (NED), expressed in a level frame along `course_rad`
/// (forward) or against it (reversing), is removed from the specific force
/// `f_b` before levelling (tilt × acceleration neglected). Only the right
/// hypothesis leaves a specific force of norm g; the wrong one leaves
/// ≈ √(g² + 4a²), which decides once the horizontal acceleration exceeds
/// `min_accel_mps2`. Returns roll, pitch, reversing, and whether it was
/// checked.
fn level_in_motion(
    f_b: &Vector3<f64>,
    a_n: &Vector3<f64>,
    course_rad: f64,
    g: f64,
    min_accel_mps2: f64,
) -> (f64, f64, bool, bool) {
    let (sn, cs) = course_rad.sin_cos();
    let a_h = Vector3::new(cs * a_n.x + sn * a_n.y, -sn * a_n.x + cs * a_n.y, a_n.z);
    let f_fwd = f_b - a_h;
    let f_rev = f_b - Vector3::new(-a_h.x, -a_h.y, a_h.z);
    let checked = a_h.x.hypot(a_h.y) > min_accel_mps2;
    let reversing = checked && (f_rev.norm() - g).abs() < (f_fwd.norm() - g).abs();
    let (roll, pitch) = level(if reversing { &f_rev } else { &f_fwd });
    (roll, pitch, reversing, checked)
}

/// The alignment note's words on the heading's source.
fn heading_words(from: HeadingFrom) -> &'static str {
    match from {
        HeadingFrom::Course => "GNSS course",
        HeadingFrom::Baseline => "the dual-antenna baseline",
        HeadingFrom::Vehicle => "the receiver's vehicle heading",
    }
}

/// The alignment note's words on reversing.
fn reversing_note(checked: bool, reversing: bool) -> &'static str {
    match (checked, reversing) {
        (true, true) => ", vehicle reversing: turned by 180°",
        (true, false) => "",
        (false, _) => " (reversing not checked: too little acceleration)",
    }
}

/// Moves a state placed at the GNSS antenna to the IMU: minus the lever
/// arm (body FRD, m) resolved with the state's attitude.
fn antenna_to_imu(nav: &mut NavState, lever_b: &[f64; 3]) {
    let le = LocalEarth::new(&nav.pos, &nav.vel);
    let d = le.ned_to_geodetic_delta(&(nav.c_nb() * Vector3::from(*lever_b)));
    nav.pos.lat_rad -= d.x;
    nav.pos.lon_rad -= d.y;
    nav.pos.h_m -= d.z;
}

/// How far back fixes are kept for velocities from positions (s).
const BASELINE_HISTORY_S: f64 = 2.0;

/// The initial state the alignment found.
#[derive(Clone, Debug, Serialize)]
pub struct Alignment {
    /// GPS time of the aligned state.
    #[serde(skip)]
    pub time: GpsTime,
    /// Seconds of GPS week of the aligned state.
    pub time_sow: f64,
    /// The initial navigation state of the IMU centre (antenna lever arm
    /// removed).
    #[serde(skip)]
    pub nav: NavState,
    pub(crate) attitude_deg: [f64; 3],
    /// σ of roll, pitch, yaw (rad).
    pub att_sd_rad: [f64; 3],
    pub(crate) pos_sd_m: [f64; 3],
    /// σ of the velocity N, E, D (m/s).
    pub vel_sd_mps: [f64; 3],
    /// How attitude and heading were found.
    pub method: AlignMethod,
    /// Length of the standstill used for levelling (s).
    pub standstill_s: f64,
    /// Horizontal speed at alignment (m/s).
    pub speed_mps: f64,
    /// The vehicle was reversing (heading turned by 180°).
    pub reversing: bool,
    /// Whether the reversing check had enough acceleration to decide.
    pub(crate) reversing_checked: bool,
    /// One-line account of the alignment for the user.
    pub note: String,
    /// Levelled at the run's start (over a standstill the run starts at, or
    /// in motion): the tilt error is M·δb_a ([`levelling_tilt_coupling`]),
    /// and `tilt_noise_sd_rad` is the part of the tilt σ that is not the
    /// accelerometer bias.
    #[serde(skip)]
    pub(crate) levelling_coupling: Option<Matrix3<f64>>,
    /// σ of the tilt not due to the accelerometer bias (rad); see
    /// `levelling_coupling`.
    #[serde(skip)]
    pub tilt_noise_sd_rad: f64,
}

/// The attitude error φ (Ĉ = (I − φ×)C, NED) that static levelling makes
/// from an accelerometer bias error δb_a = b̂ − b (body), φ = M·δb_a.
///
/// Levelling makes Ĉ(f^b − b̂) point up. The true specific force at rest
/// has C f^b = (0, 0, −g), so to first order in φ and δb
/// φ × (0, 0, −g) = −C δb, i.e. φ_N = −(C δb)_E / g, φ_E = (C δb)_N / g,
/// φ_D = 0 (Groves, *Principles of GNSS, Inertial, and Multisensor
/// Integrated Navigation Systems*, 2nd ed., §5.6.2: levelling's tilt error
/// is the horizontal accelerometer bias over g). The two are one unknown
/// at rest; starting the filter with them uncorrelated lets it misassign
/// the first GNSS-observed tilt to the bias or back.
pub(crate) fn levelling_tilt_coupling(c_nb: &Matrix3<f64>, g_mps2: f64) -> Matrix3<f64> {
    let swap = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    swap * c_nb / g_mps2
}

/// The levelling at an alignment fix (`Aligner::level_at`).
struct Levelling {
    roll: f64,
    pitch: f64,
    /// σ of roll and pitch (rad).
    tilt_sd: f64,
    method: AlignMethod,
    /// Length of the standstill levelled over (s; 0 in motion).
    standstill_s: f64,
    /// The vehicle found reversing, and whether that could be checked.
    reversing: bool,
    checked: bool,
    /// The standstill levelled over: its sums, start and end.
    recent_still: Option<(Sums, GpsTime, GpsTime)>,
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
pub(crate) fn level(f_b: &Vector3<f64>) -> (f64, f64) {
    let pitch = f_b.x.atan2((f_b.y * f_b.y + f_b.z * f_b.z).sqrt());
    let roll = (-f_b.y).atan2(-f_b.z);
    (roll, pitch)
}

/// The streaming aligner.
#[derive(Clone, Debug)]
pub(crate) struct Aligner {
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
    /// Fixes of the last [`BASELINE_HISTORY_S`], for velocities from
    /// positions over a baseline of about a second.
    recent_fixes: std::collections::VecDeque<GnssFix>,
    /// The baseline of the last velocity from positions (s; 0: the
    /// receiver's own velocity).
    last_baseline_s: f64,
    /// The previous interval's IMU sums (for the fix before).
    first_fix: Option<GnssFix>,
    /// The last velocity from positions: middle of its interval, value.
    last_mid: Option<(GpsTime, Vector3<f64>)>,
    /// The last such velocity's correction to the fix time (m/s).
    last_corr: Vector3<f64>,
    /// Starting in motion: the window being averaged.
    window: Option<MotionWindow>,
    /// Headings of the last [`HEADING_HISTORY_S`], and the first baseline
    /// heading (for a run that never stood still nor moved).
    headings: std::collections::VecDeque<HeadingObs>,
    first_baseline: Option<HeadingObs>,
    done: bool,
}

/// In-motion levelling and heading averaged over a window that starts at a
/// fix: the specific force carried into the body frame at the start, b₀,
/// by the gyros, f̄^{b₀} = (1/T)∫C_b^{b₀} f^b dt = C_n^{b₀}(Δv^n/T − g^n)
/// (Groves §5.6.2 with the vehicle acceleration from GNSS velocity over the
/// window, whose error σ_v√2/T shrinks with T), and the course at each fix
/// turned back by the gyro yaw since b₀.
#[derive(Clone, Debug)]
struct MotionWindow {
    fix0: GnssFix,
    v0: Vector3<f64>,
    v0_sd: Vector3<f64>,
    /// Body at the window start ← current body.
    c_b0_b: Matrix3<f64>,
    /// ∫ C_b^{b₀} f^b dt (m/s) and the span summed (s).
    dv_b0: Vector3<f64>,
    dt_s: f64,
    /// Σ sin, Σ cos of the heading at b₀ from each fix, Σ of 1/σ² of each.
    heading_sin: f64,
    heading_cos: f64,
    heading_info: f64,
    fixes: usize,
    /// Σ of the position baselines of the velocities (s; 0 for receiver
    /// velocities).
    baseline_sum_s: f64,
}

impl Aligner {
    pub(crate) fn new(opts: AlignOptions) -> Self {
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
            recent_fixes: std::collections::VecDeque::new(),
            last_baseline_s: 0.0,
            first_fix: None,
            last_mid: None,
            last_corr: Vector3::zeros(),
            window: None,
            headings: std::collections::VecDeque::new(),
            first_baseline: None,
            done: false,
        }
    }

    /// Pushes a receiver heading (in time order with the fixes: before the
    /// fix after it).
    pub(crate) fn push_heading(&mut self, h: &HeadingObs) {
        if h.source == HeadingSource::Baseline {
            self.first_baseline.get_or_insert(*h);
        }
        while self
            .headings
            .front()
            .is_some_and(|f| h.time.seconds_since(f.time) > HEADING_HISTORY_S)
        {
            self.headings.pop_front();
        }
        self.headings.push_back(*h);
    }

    /// The heading of `source` nearest to `t`, within [`HEADING_MATCH_S`].
    fn heading_near(&self, t: GpsTime, source: HeadingSource) -> Option<HeadingObs> {
        self.headings
            .iter()
            .filter(|h| h.source == source && t.seconds_since(h.time).abs() <= HEADING_MATCH_S)
            .min_by(|a, b| {
                t.seconds_since(a.time)
                    .abs()
                    .total_cmp(&t.seconds_since(b.time).abs())
            })
            .copied()
    }

    /// The body yaw and its σ from a baseline heading at this roll/pitch.
    fn baseline_yaw(&self, h: &HeadingObs, roll: f64, pitch: f64) -> (f64, f64) {
        let o = &self.opts;
        (
            yaw_from_baseline(h.heading_rad, roll, pitch, o.dual_antenna_yaw_rad),
            h.sd_rad.hypot(o.dual_antenna_yaw_sd_rad),
        )
    }

    /// The yaw for an epoch at `t` with roll/pitch known: a dual-antenna
    /// heading when there is one, else the receiver's vehicle heading when
    /// it beats the course (`course_yaw`, reversing applied) and agrees
    /// with it, else the course. Returns yaw, σ, source and a note.
    fn choose_yaw(
        &self,
        t: GpsTime,
        roll: f64,
        pitch: f64,
        course_yaw: f64,
        course_sd: f64,
    ) -> (f64, f64, HeadingFrom, String) {
        if let Some(h) = self.heading_near(t, HeadingSource::Baseline) {
            let (yaw, sd) = self.baseline_yaw(&h, roll, pitch);
            let d = wrap_pi(yaw - course_yaw);
            // Sideslip and a wrong mounting yaw show here (3σ, with the
            // allowance already in course_sd).
            let note = if d.abs() > 3.0 * sd.hypot(course_sd) {
                format!(
                    "; the GNSS course differs by {:.1}° (beyond 3σ: check dual_antenna_yaw_deg and mount_yaw_deg)",
                    d.to_degrees()
                )
            } else {
                String::new()
            };
            return (yaw, sd, HeadingFrom::Baseline, note);
        }
        if let Some(h) = self.heading_near(t, HeadingSource::Vehicle) {
            let yaw = wrap_pi(h.heading_rad + self.opts.mount_yaw_rad);
            let sd = h.sd_rad;
            let d = wrap_pi(yaw - course_yaw);
            if sd < course_sd && d.abs() <= 3.0 * sd.hypot(course_sd) {
                return (yaw, sd, HeadingFrom::Vehicle, String::new());
            }
            if d.abs() > 3.0 * sd.hypot(course_sd) {
                return (
                    course_yaw,
                    course_sd,
                    HeadingFrom::Course,
                    format!(
                        "; the receiver's vehicle heading differs by {:.1}° (beyond 3σ): not used",
                        d.to_degrees()
                    ),
                );
            }
        }
        (course_yaw, course_sd, HeadingFrom::Course, String::new())
    }

    pub(crate) fn push_imu(&mut self, s: &ImuSample) {
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
            self.window = None;
            return;
        }
        if let Some(w) = self.window.as_mut() {
            // The velocity increment in b₀ with the rotation over the step
            // to first order (dθ × dv / 2; Savage, Strapdown Analytics §7).
            w.dv_b0 += w.c_b0_b * (s.dvel + 0.5 * s.dtheta.cross(&s.dvel));
            w.c_b0_b *= nalgebra::Rotation3::new(s.dtheta).into_inner();
            w.dt_s += dt;
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
        if let Some(v) = fix.vel {
            self.last_baseline_s = 0.0;
            return Some((v, fix.vel_sd.unwrap_or(Vector3::repeat(0.1))));
        }
        // The baseline: the latest fix at least 0.9 s older (a 10 Hz
        // receiver's neighbouring fixes 0.1 s apart would give 10× the
        // velocity noise), else the previous fix; at most 2 s.
        while self
            .recent_fixes
            .front()
            .is_some_and(|f| fix.time.seconds_since(f.time) > BASELINE_HISTORY_S)
        {
            self.recent_fixes.pop_front();
        }
        let prev = self
            .recent_fixes
            .iter()
            .rev()
            .find(|f| fix.time.seconds_since(f.time) >= 0.9)
            .or(self.recent_fixes.back())
            .copied();
        self.recent_fixes.push_back(*fix);
        let prev = prev?;
        let dt = fix.time.seconds_since(prev.time);
        if !(dt > 0.0 && dt <= 2.0) {
            self.last_mid = None;
            return None;
        }
        self.last_baseline_s = dt;
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
        // The acceleration from two middles at least 0.5 s apart (at 10 Hz
        // neighbouring middles 0.1 s apart would amplify the noise).
        let span = self.last_mid.map(|(t0, _)| t_mid.seconds_since(t0));
        if let (Some((_, v0)), Some(span)) = (self.last_mid, span)
            && (0.5..=2.0).contains(&span)
        {
            let corr = (v_mid - v0) / span * (0.5 * dt);
            v += corr;
            sd += corr.abs() * 0.5;
            self.last_corr = corr;
        }
        if span.is_none_or(|s| !(0.0..0.5).contains(&s)) {
            self.last_mid = Some((t_mid, v_mid));
        }
        Some((v, sd))
    }

    /// Pushes a GNSS fix (after the IMU samples up to its time); returns
    /// the alignment when this fix completes it.
    pub(crate) fn push_gnss(&mut self, fix: &GnssFix) -> Option<Alignment> {
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
                if self.still_confirmed.dt >= DUAL_ANTENNA_STILL_S
                    && let Some(a) = self.align_still_dual_antenna(fix)
                {
                    self.done = true;
                    return Some(a);
                }
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
            if speed >= self.opts.min_speed_mps && interval.n > 0 && levelled {
                result = Some(self.align_at(fix, &v, &v_sd, speed, &interval));
            } else if speed >= self.opts.min_speed_mps && interval.n > 0 {
                result = self.push_motion_fix(fix, &v, &v_sd, speed, have_accel, &interval);
            } else {
                self.window = None;
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

    /// At a standstill of [`DUAL_ANTENNA_STILL_S`] with dual-antenna
    /// headings: levelled over it, the heading their weighted circular
    /// mean, the run starting at the standstill's first fix. The σ is the
    /// mean of their σ (a baseline's multipath errors are correlated over
    /// seconds: averaging is not credited) plus the mounting allowance.
    fn align_still_dual_antenna(&self, fix: &GnssFix) -> Option<Alignment> {
        let (start, sf) = (self.still_start?, self.still_start_fix?);
        let s = self.still_confirmed;
        let o = &self.opts;
        let (roll, pitch) = level(&s.f());
        let (mut sn, mut cs, mut sd_sum, mut n) = (0.0, 0.0, 0.0, 0usize);
        for h in self.headings.iter().filter(|h| {
            h.source == HeadingSource::Baseline
                && h.time.seconds_since(start) >= -HEADING_MATCH_S
                && fix.time.seconds_since(h.time) >= -HEADING_MATCH_S
        }) {
            let yaw = yaw_from_baseline(h.heading_rad, roll, pitch, o.dual_antenna_yaw_rad);
            let w = 1.0 / (h.sd_rad * h.sd_rad);
            sn += w * yaw.sin();
            cs += w * yaw.cos();
            sd_sum += h.sd_rad;
            n += 1;
        }
        if n == 0 {
            return None;
        }
        let yaw = sn.atan2(cs);
        let yaw_sd = (sd_sum / n as f64).hypot(o.dual_antenna_yaw_sd_rad);
        let g = crate::earth::gravity(sf.pos.lat_rad.sin(), sf.pos.h_m);
        let noise_sd = levelling_noise_sd_rad(s.dt);
        let tilt_sd = (o.accel_bias_sd_mps2 / g).hypot(noise_sd);
        let mut nav = NavState::new(
            sf.time,
            sf.pos,
            Vector3::zeros(),
            &Euler::new(roll, pitch, yaw),
        );
        antenna_to_imu(&mut nav, &o.lever_b);
        let standstill_s = fix.time.seconds_since(start);
        let note = format!(
            "aligned at a standstill at {:.3} s of week: roll {:.2}°, pitch {:.2}° (levelled over {:.1} s), heading {:.2}° ± {:.2}° from the dual-antenna baseline ({n} headings, baseline yaw {:.2}° in the body)",
            sf.time.sow(),
            roll.to_degrees(),
            pitch.to_degrees(),
            s.dt,
            yaw.to_degrees(),
            yaw_sd.to_degrees(),
            o.dual_antenna_yaw_rad.to_degrees(),
        );
        Some(Alignment {
            time: nav.time,
            time_sow: nav.time.sow(),
            levelling_coupling: Some(levelling_tilt_coupling(&nav.c_nb(), g)),
            tilt_noise_sd_rad: noise_sd,
            nav,
            attitude_deg: [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()],
            att_sd_rad: [tilt_sd, tilt_sd, yaw_sd],
            pos_sd_m: sf.pos_sd.into(),
            vel_sd_mps: [0.05; 3],
            method: AlignMethod::StaticLevellingAndDualAntenna,
            standstill_s,
            speed_mps: 0.0,
            reversing: false,
            reversing_checked: false,
            note,
        })
    }

    /// σ of the course from one GNSS velocity (rad): the cross-track
    /// velocity error only, the noise part of σ_v and half the cross-track
    /// part of the correction of a velocity from positions to the fix time.
    fn course_sd(&self, v: &Vector3<f64>, v_sd: &Vector3<f64>, speed: f64) -> f64 {
        let course = v.y.atan2(v.x);
        let (sn, cs) = course.sin_cos();
        let corr_cross = (-sn * self.last_corr.x + cs * self.last_corr.y).abs();
        let corr_abs = self.last_corr.x.hypot(self.last_corr.y);
        let noise_h = (v_sd.x.hypot(v_sd.y) - 0.5 * corr_abs).max(0.0) / std::f64::consts::SQRT_2;
        noise_h.hypot(0.5 * corr_cross) / speed
    }

    /// Starting in motion: opens the averaging window at this fix, adds the
    /// fix to it, and aligns at the window's start once it spans
    /// `motion_window_s`. With a window of 0 it aligns at once (needs the
    /// acceleration at this fix).
    fn push_motion_fix(
        &mut self,
        fix: &GnssFix,
        v: &Vector3<f64>,
        v_sd: &Vector3<f64>,
        speed: f64,
        have_accel: bool,
        interval: &Sums,
    ) -> Option<Alignment> {
        if self.opts.motion_window_s <= 0.0 {
            return have_accel.then(|| self.align_at(fix, v, v_sd, speed, interval));
        }
        let course_sd = self.course_sd(v, v_sd, speed);
        let w = self.window.get_or_insert_with(|| MotionWindow {
            fix0: *fix,
            v0: *v,
            v0_sd: *v_sd,
            c_b0_b: Matrix3::identity(),
            dv_b0: Vector3::zeros(),
            dt_s: 0.0,
            heading_sin: 0.0,
            heading_cos: 0.0,
            heading_info: 0.0,
            fixes: 0,
            baseline_sum_s: 0.0,
        });
        // The gyro yaw since b₀ (rotation of the forward axis about the
        // down axis of b₀; tilt over the window is small).
        let fwd = w.c_b0_b.column(0);
        let heading_b0 = v.y.atan2(v.x) - fwd.y.atan2(fwd.x);
        let info = 1.0 / (course_sd * course_sd).max(1e-12);
        w.heading_sin += info * heading_b0.sin();
        w.heading_cos += info * heading_b0.cos();
        w.heading_info += info;
        w.fixes += 1;
        w.baseline_sum_s += self.last_baseline_s;
        let span = fix.time.seconds_since(w.fix0.time);
        if span + 1e-6 < self.opts.motion_window_s || w.fixes < 3 {
            return None;
        }
        let w = self.window.take()?;
        Some(self.align_over_window(&w, fix, v, v_sd, span))
    }

    fn align_over_window(
        &self,
        w: &MotionWindow,
        fix: &GnssFix,
        v: &Vector3<f64>,
        v_sd: &Vector3<f64>,
        span_s: f64,
    ) -> Alignment {
        let o = &self.opts;
        let g = crate::earth::gravity(w.fix0.pos.lat_rad.sin(), w.fix0.pos.h_m);
        // Course at b₀ (the vehicle's forward axis at the window start).
        let course0 = w.heading_sin.atan2(w.heading_cos);
        // The mean acceleration over the window against the mean specific
        // force in b₀ (the window's averaging tells reversing from 0.3 m/s²).
        let a_n = (v - w.v0) / span_s;
        let f = w.dv_b0 / w.dt_s.max(1e-9);
        // In the IMU's axes: the course turned by the mounting yaw.
        let (roll, pitch, reversing, checked) =
            level_in_motion(&f, &a_n, course0 + o.mount_yaw_rad, g, 0.3);
        // σ: the acceleration error from two velocities T apart, the bias,
        // and the neglected Coriolis and transport terms (2 ω_ie v ≤ 2 mm/s²
        // at 15 m/s).
        let a_sd = (w.v0_sd.norm().hypot(v_sd.norm()) / span_s).hypot(0.002);
        let tilt_sd = o.accel_bias_sd_mps2.hypot(a_sd) / g;
        let mut course_yaw = course0 + o.mount_yaw_rad;
        if reversing {
            course_yaw += std::f64::consts::PI;
        }
        let course_yaw = wrap_pi(course_yaw);
        // Velocities from positions share fixes: independent ones are at
        // most half the fixes, and at most the span over the mean baseline.
        let fixes = w.fixes as f64;
        let mean_baseline_s = w.baseline_sum_s / fixes;
        let independent = if mean_baseline_s > 0.0 {
            (0.5 * fixes).min(span_s / mean_baseline_s).max(1.0)
        } else {
            0.5 * fixes
        };
        let mean_var = fixes / w.heading_info;
        let course_sd = (mean_var / independent)
            .sqrt()
            .hypot(o.heading_allowance_rad);
        let (yaw, yaw_sd, from, extra) =
            self.choose_yaw(w.fix0.time, roll, pitch, course_yaw, course_sd);
        let att = Euler::new(roll, pitch, yaw);
        let mut nav = NavState::new(w.fix0.time, w.fix0.pos, w.v0, &att);
        antenna_to_imu(&mut nav, &o.lever_b);
        let speed0 = w.v0.x.hypot(w.v0.y);
        let note = format!(
            "aligned in motion over {span_s:.1} s of GNSS velocity ({} fixes) from {:.3} s of week, {speed0:.1} m/s: roll {:.2}°, pitch {:.2}°, heading {:.2}° ± {:.2}° from {}{}{extra}; the run starts at the window's start (aligned at {:.3} s of week)",
            w.fixes,
            w.fix0.time.sow(),
            roll.to_degrees(),
            pitch.to_degrees(),
            yaw.to_degrees(),
            yaw_sd.to_degrees(),
            heading_words(from),
            reversing_note(checked, reversing),
            fix.time.sow(),
        );
        Alignment {
            time: nav.time,
            time_sow: nav.time.sow(),
            // Levelled in motion, the tilt error is the accelerometer bias
            // error seen through gravity just as at rest.
            levelling_coupling: Some(levelling_tilt_coupling(&nav.c_nb(), g)),
            tilt_noise_sd_rad: a_sd / g,
            nav,
            attitude_deg: [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()],
            att_sd_rad: [tilt_sd, tilt_sd, yaw_sd],
            pos_sd_m: w.fix0.pos_sd.into(),
            vel_sd_mps: w.v0_sd.into(),
            method: AlignMethod::InMotion.with_heading(from),
            standstill_s: 0.0,
            speed_mps: speed0,
            reversing,
            reversing_checked: checked,
            note,
        }
    }

    /// Roll and pitch at `fix`: levelled over a standstill that ended at
    /// most 60 s before (with the reversing check against the GNSS
    /// along-track acceleration), else in motion with the acceleration from
    /// the GNSS velocity removed.
    fn level_at(
        &self,
        fix: &GnssFix,
        v: &Vector3<f64>,
        v_sd: &Vector3<f64>,
        speed: f64,
        interval: &Sums,
        g: f64,
    ) -> Levelling {
        let o = &self.opts;
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
                let sd = (o.accel_bias_sd_mps2 / g).hypot(levelling_noise_sd_rad(s.dt));
                // Reversing: the along-track acceleration from GNSS against
                // the vehicle's forward specific force (the IMU's levelled
                // by the standstill's roll and pitch, turned by the mounting
                // yaw: f^v = R_z(α)·f^l, `filter::nhc`).
                if let Some(a_n) = accel {
                    let a_track = (a_n.x * v.x + a_n.y * v.y) / speed;
                    let f_l = crate::attitude::euler_to_dcm(&Euler::new(r, p, 0.0)) * interval.f();
                    let (s_m, c_m) = o.mount_yaw_rad.sin_cos();
                    let a_x = c_m * f_l.x - s_m * f_l.y;
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
                let a_n = accel.unwrap_or_else(Vector3::zeros);
                let imu_course = v.y.atan2(v.x) + o.mount_yaw_rad;
                let (r, p, rev, chk) = level_in_motion(&interval.f(), &a_n, imu_course, g, 0.5);
                (reversing, checked) = (rev, chk);
                let a_sd = v_sd.norm() * std::f64::consts::SQRT_2;
                let sd = (o.accel_bias_sd_mps2.hypot(a_sd)) / g;
                (r, p, sd, AlignMethod::InMotion, 0.0)
            }
        };
        Levelling {
            roll,
            pitch,
            tilt_sd,
            method,
            standstill_s,
            reversing,
            checked,
            recent_still,
        }
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
        let Levelling {
            roll,
            pitch,
            tilt_sd,
            method,
            standstill_s,
            reversing,
            checked,
            recent_still,
        } = self.level_at(fix, v, v_sd, speed, interval, g);
        let course = v.y.atan2(v.x);
        let mut course_yaw = course + o.mount_yaw_rad;
        if reversing {
            course_yaw += std::f64::consts::PI;
        }
        let course_yaw = wrap_pi(course_yaw);
        let course_sd = self
            .course_sd(v, v_sd, speed)
            .hypot(o.heading_allowance_rad);
        let (yaw, yaw_sd, from, extra) =
            self.choose_yaw(fix.time, roll, pitch, course_yaw, course_sd);
        let method = method.with_heading(from);
        let att = Euler::new(roll, pitch, yaw);
        let mut nav = NavState::new(fix.time, fix.pos, *v, &att);
        // The fix is the antenna's: move to the IMU.
        antenna_to_imu(&mut nav, &o.lever_b);
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
            antenna_to_imu(&mut n0, &o.lever_b);
            start_s = fix.time.seconds_since(sf.time);
            nav = n0;
        }
        let note = format!(
            "aligned at {:.3} s of week, {:.1} m/s: roll {:.2}°, pitch {:.2}° ({}), heading {:.2}° ± {:.2}° from {}{}{extra}",
            fix.time.sow(),
            speed,
            roll.to_degrees(),
            pitch.to_degrees(),
            if recent_still.is_some() {
                format!("levelled over a {standstill_s:.0} s standstill")
            } else {
                "levelled in motion".into()
            },
            yaw.to_degrees(),
            yaw_sd.to_degrees(),
            heading_words(from),
            reversing_note(checked, reversing)
        ) + &if start_s > 0.0 {
            format!(
                "; the run starts at the standstill, {start_s:.1} s earlier ({:.3} s of week)",
                nav.time.sow()
            )
        } else {
            String::new()
        };
        // The tilt error is M·δb_a with M at the attitude levelled: the
        // standstill's when the run starts there, else this fix's when
        // levelled in motion (a levelling from an earlier standstill that
        // the run does not start at is left uncoupled).
        let (levelling_coupling, tilt_noise_sd_rad) = match (recent_still, start_s > 0.0) {
            (Some((s, _, _)), true) => (
                Some(levelling_tilt_coupling(&nav.c_nb(), g)),
                levelling_noise_sd_rad(s.dt),
            ),
            (Some(_), false) => (None, tilt_sd),
            (None, _) => (
                Some(levelling_tilt_coupling(&nav.c_nb(), g)),
                (tilt_sd * tilt_sd - (o.accel_bias_sd_mps2 / g).powi(2))
                    .max(0.0)
                    .sqrt(),
            ),
        };
        Alignment {
            time: nav.time,
            time_sow: nav.time.sow(),
            nav,
            levelling_coupling,
            tilt_noise_sd_rad,
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
    pub(crate) fn finish(&mut self) -> Option<Alignment> {
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
        let (roll, pitch, standstill_s, averaged_s) = match still {
            Some((s, len)) => {
                let (r, p) = level(&s.f());
                (r, p, len, s.dt)
            }
            None => (0.0, 0.0, 0.0, 0.0),
        };
        let noise_sd = levelling_noise_sd_rad(averaged_s);
        let tilt_sd = if standstill_s > 0.0 {
            (self.opts.accel_bias_sd_mps2 / GAMMA_E).hypot(noise_sd)
        } else {
            10f64.to_radians()
        };
        // A dual-antenna heading needs no motion.
        let dual = self
            .first_baseline
            .map(|h| self.baseline_yaw(&h, roll, pitch));
        let (yaw, yaw_sd) = dual.unwrap_or((0.0, std::f64::consts::PI));
        let mut nav = NavState::new(
            fix.time,
            fix.pos,
            Vector3::zeros(),
            &Euler::new(roll, pitch, yaw),
        );
        // The fix is the antenna's: move to the IMU. With heading 0 for an
        // unknown one, the horizontal part of the lever arm points
        // anywhere: its length joins the horizontal σ.
        antenna_to_imu(&mut nav, &self.opts.lever_b);
        let lever_h_m = if dual.is_some() {
            0.0
        } else {
            (nav.c_nb() * Vector3::from(self.opts.lever_b)).xy().norm()
        };
        let pos_sd_m = [
            fix.pos_sd.x.hypot(lever_h_m),
            fix.pos_sd.y.hypot(lever_h_m),
            fix.pos_sd.z,
        ];
        self.done = true;
        let levelling_coupling =
            (standstill_s > 0.0).then(|| levelling_tilt_coupling(&nav.c_nb(), GAMMA_E));
        Some(Alignment {
            time: fix.time,
            time_sow: fix.time.sow(),
            nav,
            levelling_coupling,
            tilt_noise_sd_rad: if standstill_s > 0.0 {
                noise_sd
            } else {
                tilt_sd
            },
            attitude_deg: [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()],
            att_sd_rad: [tilt_sd, tilt_sd, yaw_sd],
            pos_sd_m,
            vel_sd_mps: [0.1; 3],
            method: if dual.is_some() {
                AlignMethod::StaticLevellingAndDualAntenna
            } else {
                AlignMethod::NoMotion
            },
            standstill_s,
            speed_mps: 0.0,
            reversing: false,
            reversing_checked: false,
            note: if dual.is_some() {
                format!(
                    "the vehicle never moved faster than {:.1} m/s nor stood still for {DUAL_ANTENNA_STILL_S:.0} s: {}, heading {:.2}° ± {:.2}° from the dual-antenna baseline",
                    self.opts.min_speed_mps,
                    if standstill_s > 0.0 {
                        "levelled"
                    } else {
                        "not levelled (tilt σ 10°)"
                    },
                    yaw.to_degrees(),
                    yaw_sd.to_degrees()
                )
            } else {
                format!(
                    "the vehicle never moved faster than {:.1} m/s: heading is unobservable (a MEMS gyro cannot sense the earth's rotation); levelled, heading set to 0° with σ 180°",
                    self.opts.min_speed_mps
                )
            },
        })
    }
}

/// The tilt σ (rad) of averaging the accelerometers over `span_s` of
/// standstill, apart from the bias: a 1 mg/√s floor over g (vehicle
/// rocking and noise; conservative against a MEMS VRW).
fn levelling_noise_sd_rad(span_s: f64) -> f64 {
    0.001 / span_s.max(1.0).sqrt()
}

#[cfg(test)]
mod tests;
