//! Land-vehicle trajectories built from smooth segments.
//!
//! The vehicle is described by three scalar profiles of time: speed `v`
//! along the body x axis (no side slip, no vertical slip), heading `ψ` and
//! road grade `θ` (pitch: the velocity climbs with it); roll follows the
//! lateral acceleration, `φ = −k·v·ψ̇` (the body leans out of a turn), as
//! the reference simulator of `sim-drive-adis16465` does.
//!
//! Every change of a profile uses a transition whose first and second
//! derivatives vanish at both ends, so that speed, acceleration, attitude,
//! body rates and specific force are continuous (the position is C³):
//! the smooth step S(τ) = τ − sin(2πτ)/(2π) for speed, grade and bell-shaped
//! turns, a smooth ramp of the yaw rate (ψ̇ = r·S(τ)) for constant-radius
//! curves, and the bump (1 − cos 2πτ)²/4 of the heading for lane changes.
//!
//! Optional vibration (engine, road) is a sum of sinusoids: a small body
//! rotation α(t) (C_b^n = C_v^n·Exp(α)) and a small displacement δr(t)
//! along the local-level NED axes, both part of the truth, so that the
//! truth stays exact and consistent with the IMU signals.

use std::f64::consts::{PI, TAU};

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use std::sync::Arc;

use super::fitted::{FittedMotion, FittedState, euler_kinematics};
use super::rng;
use navsync::attitude::{
    Euler, body_rate_from_euler_rates, dcm_from_sin_cos, euler_to_quat, rotvec_to_quat, skew,
};
use navsync::earth::Geodetic;
use navsync::error::Error;

/// One transition shape over `[t0, t0 + dur]`, with τ = (t − t0)/dur.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Shape {
    /// q = q0 + Δ·S(τ), S(τ) = τ − sin(2πτ)/(2π): peak rate 2Δ/dur.
    Step(f64),
    /// q̇ = r·S(τ): the rate ramps smoothly from 0 to r.
    RampUp(f64),
    /// q̇ = r: constant rate.
    Linear(f64),
    /// q̇ = r·(1 − S(τ)): the rate ramps smoothly from r to 0.
    RampDown(f64),
    /// q = q0 + A·(1 − cos 2πτ)²/4: out and back (all derivatives up to the
    /// third vanish at both ends).
    Bump(f64),
}

#[derive(Clone, Copy, Debug)]
struct Piece {
    t0: f64,
    dur: f64,
    q0: f64,
    shape: Shape,
}

impl Piece {
    fn end_value(&self) -> f64 {
        match self.shape {
            Shape::Step(d) => self.q0 + d,
            Shape::RampUp(r) | Shape::RampDown(r) => self.q0 + 0.5 * r * self.dur,
            Shape::Linear(r) => self.q0 + r * self.dur,
            Shape::Bump(_) => self.q0,
        }
    }

    /// Value, first and second derivative at `t` inside the piece.
    #[inline]
    #[cfg(test)]
    fn eval(&self, t: f64) -> [f64; 3] {
        self.eval_with(t, &mut TrigCache::default())
    }

    /// [`Piece::eval`] with the sine and cosine of 2πτ from `trig`.
    #[inline]
    fn eval_with(&self, t: f64, trig: &mut TrigCache) -> [f64; 3] {
        let big_t = self.dur;
        let tau = (t - self.t0) / big_t;
        let q0 = self.q0;
        match self.shape {
            Shape::Linear(r) => [q0 + r * (t - self.t0), r, 0.0],
            Shape::Step(d) => {
                let (s, c) = trig.sin_cos(TAU * tau);
                [
                    q0 + d * (tau - s / TAU),
                    d / big_t * (1.0 - c),
                    d / (big_t * big_t) * TAU * s,
                ]
            }
            Shape::RampUp(r) => {
                let (s, c) = trig.sin_cos(TAU * tau);
                [
                    q0 + r * big_t * (0.5 * tau * tau + (c - 1.0) / (TAU * TAU)),
                    r * (tau - s / TAU),
                    r / big_t * (1.0 - c),
                ]
            }
            Shape::RampDown(r) => {
                let (s, c) = trig.sin_cos(TAU * tau);
                [
                    q0 + r * big_t * (tau - 0.5 * tau * tau - (c - 1.0) / (TAU * TAU)),
                    r * (1.0 - tau + s / TAU),
                    -r / big_t * (1.0 - c),
                ]
            }
            Shape::Bump(a) => {
                let (s, c) = trig.sin_cos(TAU * tau);
                let u = 1.0 - c;
                [
                    q0 + 0.25 * a * u * u,
                    a * PI * s * u / big_t,
                    2.0 * PI * PI * a / (big_t * big_t) * (c * u + s * s),
                ]
            }
        }
    }
}

/// A smooth scalar profile made of transitions; between and after them the
/// value holds.
#[derive(Clone, Debug)]
struct Channel {
    start: f64,
    pieces: Vec<Piece>,
}

impl Channel {
    fn new(start: f64) -> Self {
        Channel {
            start,
            pieces: Vec::new(),
        }
    }

    fn last_value(&self) -> f64 {
        self.pieces.last().map_or(self.start, Piece::end_value)
    }

    fn push(&mut self, t0: f64, dur: f64, shape: Shape) {
        let q0 = self.last_value();
        self.pieces.push(Piece { t0, dur, q0, shape });
    }

    /// Value, first and second derivative at `t`, starting the search at
    /// `*hint` (the number of pieces starting at or before the previous
    /// query), which makes queries in increasing time O(1).
    #[inline]
    fn eval_hint(&self, t: f64, hint: &mut usize, trig: &mut TrigCache) -> [f64; 3] {
        let n = self.pieces.len();
        let mut i = *hint;
        let ok = |i: usize| {
            i <= n && (i == 0 || self.pieces[i - 1].t0 <= t) && (i == n || self.pieces[i].t0 > t)
        };
        if !ok(i) {
            if i < n && ok(i + 1) {
                i += 1;
            } else {
                i = self.pieces.partition_point(|p| p.t0 <= t);
            }
        }
        *hint = i;
        if i == 0 {
            return [self.start, 0.0, 0.0];
        }
        let p = &self.pieces[i - 1];
        if t >= p.t0 + p.dur {
            [p.end_value(), 0.0, 0.0]
        } else {
            p.eval_with(t, trig)
        }
    }
}

/// One step of a scenario (user TOML `[[segments]]` tables; angles in
/// degrees, positive turns and offsets to the right).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Segment {
    /// Standing still (the vehicle must be stopped).
    Static { duration_s: f64 },
    /// Change speed with a smooth profile of peak acceleration `accel_mps2`
    /// (default 2.0).
    Accelerate {
        speed_mps: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        accel_mps2: Option<f64>,
    },
    /// Slow down to `speed_mps` (default 0) with peak deceleration
    /// `decel_mps2` (default 2.5).
    Brake {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        speed_mps: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        decel_mps2: Option<f64>,
    },
    /// Keep speed, heading and grade for a duration or a distance.
    Cruise {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        duration_s: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        distance_m: Option<f64>,
    },
    /// Turn by `angle_deg` with a peak yaw rate (or a radius at the current
    /// speed); the yaw rate ramps in and out over `ramp_s` (default 1.5 s),
    /// with a constant-rate (constant-radius) part in between when the
    /// angle allows.
    Turn {
        angle_deg: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        yaw_rate_deg_s: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        radius_m: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ramp_s: Option<f64>,
    },
    /// Move sideways by `offset_m` (positive right) over `duration_s`
    /// (default 4 s), ending on the original heading.
    LaneChange {
        offset_m: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        duration_s: Option<f64>,
    },
    /// Up a grade of `grade_deg` and down again (net height change zero at
    /// constant speed) over `duration_s`.
    Hill { grade_deg: f64, duration_s: f64 },
    /// Change to a sustained grade over `ramp_s` (default 5 s).
    Grade {
        grade_deg: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ramp_s: Option<f64>,
    },
    /// Brake to a stop (peak deceleration `decel_mps2`, default 2.5) if
    /// moving, then stand for `duration_s`.
    Stop {
        duration_s: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        decel_mps2: Option<f64>,
    },
}

/// What one built segment did, for `scenario.json`.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SegmentInfo {
    pub t0: f64,
    pub t1: f64,
    pub what: String,
}

/// Builds the profiles segment by segment.
#[derive(Clone, Debug)]
pub struct TrajectoryBuilder {
    t: f64,
    speed: Channel,
    heading: Channel,
    grade: Channel,
    infos: Vec<SegmentInfo>,
}

const DEFAULT_ACCEL: f64 = 2.0;
const DEFAULT_DECEL: f64 = 2.5;
const DEFAULT_TURN_RAMP_S: f64 = 1.5;
const DEFAULT_LANE_CHANGE_S: f64 = 4.0;
const DEFAULT_GRADE_RAMP_S: f64 = 5.0;

fn positive(x: f64, what: &str) -> Result<f64, String> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(format!("{what} must be a positive number (got {x})"))
    }
}

impl TrajectoryBuilder {
    /// Starts at time 0 with a speed (m/s) and heading (rad).
    pub fn new(initial_speed_mps: f64, initial_heading_rad: f64) -> Self {
        TrajectoryBuilder {
            t: 0.0,
            speed: Channel::new(initial_speed_mps.max(0.0)),
            heading: Channel::new(initial_heading_rad),
            grade: Channel::new(0.0),
            infos: Vec::new(),
        }
    }

    /// Time at the end of the segments so far (s).
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Speed at the end of the segments so far (m/s).
    pub fn speed(&self) -> f64 {
        self.speed.last_value()
    }

    fn info(&mut self, t0: f64, what: String) {
        self.infos.push(SegmentInfo {
            t0,
            t1: self.t,
            what,
        });
    }

    fn change_speed(&mut self, target: f64, peak: f64, verb: &str) -> Result<(), String> {
        if !(target.is_finite() && target >= 0.0) {
            return Err(format!("target speed must be >= 0 m/s (got {target})"));
        }
        let peak = positive(peak, "peak acceleration")?;
        let dv = target - self.speed();
        if dv.abs() < 1e-12 {
            return Ok(());
        }
        let dur = 2.0 * dv.abs() / peak;
        let t0 = self.t;
        self.speed.push(t0, dur, Shape::Step(dv));
        self.t += dur;
        self.info(
            t0,
            format!("{verb} to {target:.1} m/s (peak {peak:.2} m/s^2)"),
        );
        Ok(())
    }

    fn moving(&self, what: &str) -> Result<f64, String> {
        let v = self.speed();
        if v < 0.1 {
            return Err(format!(
                "a {what} needs the vehicle moving (speed {v:.2} m/s); accelerate first"
            ));
        }
        Ok(v)
    }

    /// Appends one segment; the error says what is wrong with it.
    pub fn add(&mut self, seg: &Segment) -> Result<(), String> {
        let t0 = self.t;
        match *seg {
            Segment::Static { duration_s } => {
                let d = positive(duration_s, "duration_s")?;
                if self.speed() > 1e-9 {
                    return Err(format!(
                        "a static segment needs the vehicle stopped (speed {:.2} m/s); add `brake` or `stop` first",
                        self.speed()
                    ));
                }
                self.t += d;
                self.info(t0, format!("static {d:.1}s"));
            }
            Segment::Accelerate {
                speed_mps,
                accel_mps2,
            } => self.change_speed(
                speed_mps,
                accel_mps2.unwrap_or(DEFAULT_ACCEL),
                if speed_mps >= self.speed() {
                    "accelerate"
                } else {
                    "brake"
                },
            )?,
            Segment::Brake {
                speed_mps,
                decel_mps2,
            } => self.change_speed(
                speed_mps.unwrap_or(0.0),
                decel_mps2.unwrap_or(DEFAULT_DECEL),
                "brake",
            )?,
            Segment::Cruise {
                duration_s,
                distance_m,
            } => {
                let d = match (duration_s, distance_m) {
                    (Some(d), None) => positive(d, "duration_s")?,
                    (None, Some(x)) => {
                        let v = self.moving("cruise over a distance")?;
                        positive(x, "distance_m")? / v
                    }
                    _ => return Err("cruise needs exactly one of duration_s, distance_m".into()),
                };
                self.t += d;
                self.info(t0, format!("cruise {d:.1}s @ {:.1} m/s", self.speed()));
            }
            Segment::Turn {
                angle_deg,
                yaw_rate_deg_s,
                radius_m,
                ramp_s,
            } => {
                let v = self.moving("turn")?;
                let angle = angle_deg.to_radians();
                if !angle.is_finite() || angle == 0.0 {
                    return Err(format!("turn angle must be non-zero (got {angle_deg})"));
                }
                let rate = match (yaw_rate_deg_s, radius_m) {
                    (Some(r), None) => positive(r.abs(), "yaw_rate_deg_s")?.to_radians(),
                    (None, Some(rad)) => v / positive(rad, "radius_m")?,
                    (None, None) => (2.5 / v).min(25f64.to_radians()),
                    _ => return Err("turn takes yaw_rate_deg_s or radius_m, not both".into()),
                };
                let ramp = positive(ramp_s.unwrap_or(DEFAULT_TURN_RAMP_S), "ramp_s")?;
                let sign = angle.signum();
                let total = angle.abs();
                let (rate, lin) = if total >= rate * ramp {
                    (rate, (total - rate * ramp) / rate)
                } else {
                    (total / ramp, 0.0)
                };
                self.heading.push(self.t, ramp, Shape::RampUp(sign * rate));
                self.t += ramp;
                if lin > 0.0 {
                    self.heading.push(self.t, lin, Shape::Linear(sign * rate));
                    self.t += lin;
                }
                self.heading
                    .push(self.t, ramp, Shape::RampDown(sign * rate));
                self.t += ramp;
                self.info(
                    t0,
                    format!(
                        "turn {angle_deg:+.0} deg, yaw rate {:.1} deg/s (radius {:.0} m) @ {v:.1} m/s",
                        rate.to_degrees(),
                        v / rate
                    ),
                );
            }
            Segment::LaneChange {
                offset_m,
                duration_s,
            } => {
                let v = self.moving("lane change")?;
                let d = positive(duration_s.unwrap_or(DEFAULT_LANE_CHANGE_S), "duration_s")?;
                if !offset_m.is_finite() || offset_m == 0.0 {
                    return Err(format!(
                        "lane change offset must be non-zero (got {offset_m})"
                    ));
                }
                let amp = lane_change_amplitude(offset_m, v, d).ok_or_else(|| {
                    format!("lane change of {offset_m} m in {d} s at {v:.1} m/s is too sharp")
                })?;
                self.heading.push(self.t, d, Shape::Bump(amp));
                self.t += d;
                self.info(t0, format!("lane change {offset_m:+.1} m @ {v:.1} m/s"));
            }
            Segment::Hill {
                grade_deg,
                duration_s,
            } => {
                let d = positive(duration_s, "duration_s")?;
                let g = grade_deg.to_radians();
                if !(g.is_finite() && g.abs() < 0.35) {
                    return Err(format!(
                        "hill grade must be within ±20 deg (got {grade_deg})"
                    ));
                }
                let s = d / 6.0;
                let t = self.t;
                self.grade.push(t, s, Shape::Step(g));
                self.grade.push(t + 2.0 * s, 2.0 * s, Shape::Step(-2.0 * g));
                self.grade.push(t + 5.0 * s, s, Shape::Step(g));
                self.t += d;
                self.info(
                    t0,
                    format!("hill +/-{grade_deg:.1} deg @ {:.1} m/s", self.speed()),
                );
            }
            Segment::Grade { grade_deg, ramp_s } => {
                let g = grade_deg.to_radians();
                if !(g.is_finite() && g.abs() < 0.35) {
                    return Err(format!("grade must be within ±20 deg (got {grade_deg})"));
                }
                let r = positive(ramp_s.unwrap_or(DEFAULT_GRADE_RAMP_S), "ramp_s")?;
                let dg = g - self.grade.last_value();
                self.grade.push(self.t, r, Shape::Step(dg));
                self.t += r;
                self.info(t0, format!("grade to {grade_deg:.1} deg"));
            }
            Segment::Stop {
                duration_s,
                decel_mps2,
            } => {
                let d = positive(duration_s, "duration_s")?;
                if self.speed() > 0.0 {
                    self.change_speed(0.0, decel_mps2.unwrap_or(DEFAULT_DECEL), "brake")?;
                }
                let t1 = self.t;
                self.t += d;
                self.info(t1, format!("stop {d:.1}s"));
            }
        }
        Ok(())
    }

    /// The trajectory over `[0, duration_s]` starting at `origin` (after
    /// the last segment the vehicle keeps its final speed, heading and grade).
    pub fn finish(
        self,
        origin: Geodetic,
        duration_s: f64,
        roll_gain_rad_per_mps2: f64,
        vibration: Vibration,
    ) -> Trajectory {
        Trajectory {
            origin,
            duration_s,
            speed: self.speed,
            heading: self.heading,
            grade: self.grade,
            roll_gain: roll_gain_rad_per_mps2,
            vibration,
            segments: self.infos,
            fitted: None,
        }
    }
}

/// Heading-bump amplitude A (rad) that moves the vehicle sideways by
/// `offset_m` at speed `v` over `dur`: solves ∫ v·sin(A·b(τ)) dt = offset
/// with b(τ) = (1 − cos 2πτ)²/4 (∫b = 3/8) by Newton's method on a
/// 256-interval Simpson rule.
fn lane_change_amplitude(offset_m: f64, v: f64, dur: f64) -> Option<f64> {
    let n = 256;
    let lateral = |a: f64| -> (f64, f64) {
        let (mut f, mut df) = (0.0, 0.0);
        for k in 0..=n {
            let tau = k as f64 / n as f64;
            let u = 1.0 - (TAU * tau).cos();
            let b = 0.25 * u * u;
            let w = if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            f += w * (a * b).sin();
            df += w * b * (a * b).cos();
        }
        let h = dur / n as f64 / 3.0 * v;
        (f * h, df * h)
    };
    let mut a = offset_m / (v * dur * 0.375);
    for _ in 0..20 {
        let (f, df) = lateral(a);
        if df <= 0.0 {
            return None;
        }
        let step = (f - offset_m) / df;
        a -= step;
        if step.abs() < 1e-15 {
            break;
        }
    }
    (a.abs() < 0.5).then_some(a)
}

/// A vibration tone as configured (amplitudes of the angular rate and of
/// the acceleration; the phases are drawn).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ToneSpec {
    pub freq_hz: f64,
    /// Angular-rate amplitude about body x, y, z (deg/s).
    #[serde(default)]
    pub gyro_amp_deg_s: [f64; 3],
    /// Acceleration amplitude along north, east, down (m/s²).
    #[serde(default)]
    pub accel_amp_mps2: [f64; 3],
}

/// Broadband vibration as `tones` sinusoids of random frequency in a band.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RandomVibrationSpec {
    pub band_hz: [f64; 2],
    /// RMS angular rate per axis (deg/s).
    #[serde(default)]
    pub gyro_rms_deg_s: f64,
    /// RMS acceleration per axis (m/s²).
    #[serde(default)]
    pub accel_rms_mps2: f64,
    #[serde(default = "default_random_tones")]
    pub tones: usize,
}

fn default_random_tones() -> usize {
    12
}

/// Vibration of the IMU (engine, road): tones and a random band.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct VibrationSpec {
    #[serde(default)]
    pub tones: Vec<ToneSpec>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub random: Option<RandomVibrationSpec>,
}

impl VibrationSpec {
    pub fn is_empty(&self) -> bool {
        self.tones.is_empty() && self.random.is_none()
    }
}

/// One drawn vibration tone (SI units), reported in `scenario.json`.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Tone {
    pub freq_hz: f64,
    pub gyro_amp_rad_s: [f64; 3],
    pub accel_amp_mps2: [f64; 3],
    pub gyro_phase_rad: [f64; 3],
    pub accel_phase_rad: [f64; 3],
}

/// Precomputed form of a tone: A·sin(ωt + φ) = A cos φ · sin ωt + A sin φ · cos ωt.
#[derive(Clone, Debug)]
struct ToneEval {
    w: f64,
    rot_c: Vector3<f64>,
    rot_s: Vector3<f64>,
    lin_c: Vector3<f64>,
    lin_s: Vector3<f64>,
}

/// The vibration of a run.
#[derive(Clone, Debug, Default)]
pub struct Vibration {
    tones: Vec<Tone>,
    eval: Vec<ToneEval>,
}

/// Vibration state at one instant.
#[derive(Copy, Clone, Debug, Default)]
pub struct VibrationState {
    /// Small body rotation vector (rad).
    pub alpha: Vector3<f64>,
    /// Its time derivative (rad/s).
    pub alpha_dot: Vector3<f64>,
    /// NED displacement (m), velocity (m/s) and acceleration (m/s²).
    pub dr: Vector3<f64>,
    pub dr_dot: Vector3<f64>,
    pub dr_ddot: Vector3<f64>,
}

impl Vibration {
    /// Draws the phases (and the random band's frequencies) from `rng`.
    pub fn draw(spec: &VibrationSpec, rng: &mut rng::SimRng) -> Result<Self, String> {
        let mut tones = Vec::new();
        let phases = |rng: &mut rng::SimRng| {
            [
                rng::uniform_in(rng, 0.0, TAU),
                rng::uniform_in(rng, 0.0, TAU),
                rng::uniform_in(rng, 0.0, TAU),
            ]
        };
        for t in &spec.tones {
            positive(t.freq_hz, "vibration freq_hz")?;
            tones.push(Tone {
                freq_hz: t.freq_hz,
                gyro_amp_rad_s: t.gyro_amp_deg_s.map(f64::to_radians),
                accel_amp_mps2: t.accel_amp_mps2,
                gyro_phase_rad: phases(rng),
                accel_phase_rad: phases(rng),
            });
        }
        if let Some(r) = &spec.random {
            let (lo, hi) = (r.band_hz[0], r.band_hz[1]);
            positive(lo, "vibration band low edge")?;
            if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
                return Err(format!("vibration band {lo}..{hi} Hz is empty"));
            }
            let m = r.tones.max(1);
            // M tones of amplitude a have RMS a·sqrt(M/2).
            let k = (2.0 / m as f64).sqrt();
            for _ in 0..m {
                let f = rng::uniform_in(rng, lo, hi);
                tones.push(Tone {
                    freq_hz: f,
                    gyro_amp_rad_s: [r.gyro_rms_deg_s.to_radians() * k; 3],
                    accel_amp_mps2: [r.accel_rms_mps2 * k; 3],
                    gyro_phase_rad: phases(rng),
                    accel_phase_rad: phases(rng),
                });
            }
        }
        let eval = tones
            .iter()
            .map(|t| {
                let cs = |amp: &[f64; 3], ph: &[f64; 3]| {
                    (
                        Vector3::from_fn(|i, _| amp[i] * ph[i].cos()),
                        Vector3::from_fn(|i, _| amp[i] * ph[i].sin()),
                    )
                };
                let (rot_c, rot_s) = cs(&t.gyro_amp_rad_s, &t.gyro_phase_rad);
                let (lin_c, lin_s) = cs(&t.accel_amp_mps2, &t.accel_phase_rad);
                ToneEval {
                    w: TAU * t.freq_hz,
                    rot_c,
                    rot_s,
                    lin_c,
                    lin_s,
                }
            })
            .collect();
        Ok(Vibration { tones, eval })
    }

    pub fn is_empty(&self) -> bool {
        self.eval.is_empty()
    }

    pub fn tones(&self) -> &[Tone] {
        &self.tones
    }

    /// Highest tone frequency (Hz), 0 without vibration.
    pub fn max_freq_hz(&self) -> f64 {
        self.tones.iter().map(|t| t.freq_hz).fold(0.0, f64::max)
    }

    /// α(t) = Σ A/ω·sin(ωt+φ) (so that α̇ is the rate tone A·cos(ωt+φ));
    /// δr(t) = −Σ B/ω²·sin(ωt+χ) (so that δr̈ is the acceleration tone).
    #[inline]
    pub fn at(&self, t: f64) -> VibrationState {
        let mut v = VibrationState::default();
        for e in &self.eval {
            let (s, c) = (e.w * t).sin_cos();
            let rot_sin = e.rot_c * s + e.rot_s * c;
            let rot_cos = e.rot_c * c - e.rot_s * s;
            let lin_sin = e.lin_c * s + e.lin_s * c;
            let lin_cos = e.lin_c * c - e.lin_s * s;
            v.alpha += rot_sin / e.w;
            v.alpha_dot += rot_cos;
            v.dr -= lin_sin / (e.w * e.w);
            v.dr_dot -= lin_cos / e.w;
            v.dr_ddot += lin_sin;
        }
        v
    }
}

/// The vehicle profiles at one instant.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct VehicleState {
    pub speed_mps: f64,
    pub accel_mps2: f64,
    pub heading_rad: f64,
    pub yaw_rate_rad_s: f64,
    pub yaw_accel_rad_s2: f64,
    pub pitch_rad: f64,
    pub pitch_rate_rad_s: f64,
    pub roll_rad: f64,
    pub roll_rate_rad_s: f64,
}

/// Everything about the motion at one instant except the position.
#[derive(Copy, Clone, Debug)]
pub struct Kinematics {
    pub vehicle: VehicleState,
    /// Velocity in NED including vibration (m/s).
    pub vel_n: Vector3<f64>,
    /// dv^n/dt (m/s²).
    pub acc_n: Vector3<f64>,
    /// C_b^n including vibration.
    pub c_nb: Matrix3<f64>,
    /// ω_nb^b (rad/s).
    pub w_nb_b: Vector3<f64>,
    /// Vibration rotation vector (rad) and NED displacement (m).
    pub alpha: Vector3<f64>,
    pub dr_n: Vector3<f64>,
}

impl Kinematics {
    /// q_nb = q(Euler) ⊗ q(α).
    pub fn q_nb(&self) -> UnitQuaternion<f64> {
        let v = &self.vehicle;
        let q = euler_to_quat(&Euler::new(v.roll_rad, v.pitch_rad, v.heading_rad));
        if self.alpha == Vector3::zeros() {
            q
        } else {
            q * rotvec_to_quat(&self.alpha)
        }
    }
}

/// Where the last query fell in each profile, and the last sines and
/// cosines: queries in increasing time then cost O(1) searches and few
/// trigonometric calls.
#[derive(Copy, Clone, Debug, Default)]
pub struct Cursor {
    hint: [usize; 3],
    /// 2πτ of the speed, heading and grade pieces; heading, pitch, roll.
    trig: [TrigCache; 6],
}

/// sin and cos of an angle near the previous one: rotated from an anchor
/// where they were computed exactly, sin(x₀+δ) = s₀ cos δ + c₀ sin δ,
/// with sin δ and cos δ from their Taylor series for |δ| < 0.1 (truncation
/// below 3e-19; a few ulps of rounding), and re-anchored beyond.
#[derive(Copy, Clone, Debug)]
pub struct TrigCache {
    x0: f64,
    s0: f64,
    c0: f64,
}

impl Default for TrigCache {
    fn default() -> Self {
        TrigCache {
            x0: f64::NAN,
            s0: 0.0,
            c0: 1.0,
        }
    }
}

impl TrigCache {
    #[inline]
    pub fn sin_cos(&mut self, x: f64) -> (f64, f64) {
        let d = x - self.x0;
        if d.abs() < 0.1 {
            let d2 = d * d;
            let sd = d
                * (1.0
                    + d2 * (-1.0 / 6.0
                        + d2 * (1.0 / 120.0
                            + d2 * (-1.0 / 5040.0 + d2 * (1.0 / 362_880.0 - d2 / 39_916_800.0)))));
            let cd = 1.0
                + d2 * (-0.5
                    + d2 * (1.0 / 24.0
                        + d2 * (-1.0 / 720.0 + d2 * (1.0 / 40_320.0 - d2 / 3_628_800.0))));
            (self.s0 * cd + self.c0 * sd, self.c0 * cd - self.s0 * sd)
        } else {
            let (s, c) = x.sin_cos();
            self.x0 = x;
            self.s0 = s;
            self.c0 = c;
            (s, c)
        }
    }
}

/// sin and cos, exact and free for the frequent zero (level road, no roll).
#[inline]
fn sin_cos0(x: f64, trig: &mut TrigCache) -> (f64, f64) {
    if x == 0.0 {
        (0.0, 1.0)
    } else {
        trig.sin_cos(x)
    }
}

/// Options of [`Trajectory::from_segments`].
#[derive(Clone, Debug, Default)]
pub struct TrajectoryOptions {
    pub initial_speed_mps: f64,
    pub initial_heading_rad: f64,
    /// Length of the run; `None` for the end of the segments.
    pub duration_s: Option<f64>,
    /// Roll per lateral acceleration, φ = −k·v·ψ̇ (rad per m/s²).
    pub roll_gain_rad_per_mps2: f64,
    pub vibration: Vibration,
}

/// A land-vehicle trajectory: profiles of speed, heading and grade, roll
/// from lateral acceleration, optional vibration. Time `t` in seconds from
/// the scenario start.
#[derive(Clone, Debug)]
pub struct Trajectory {
    origin: Geodetic,
    duration_s: f64,
    speed: Channel,
    heading: Channel,
    grade: Channel,
    roll_gain: f64,
    vibration: Vibration,
    segments: Vec<SegmentInfo>,
    /// A trajectory fitted to a reference drive replaces the profiles.
    fitted: Option<Arc<FittedMotion>>,
}

impl Trajectory {
    /// The trajectory of a fitted reference drive over its whole span.
    pub fn from_fitted(motion: FittedMotion) -> Self {
        Trajectory {
            origin: motion.origin(),
            duration_s: motion.duration_s(),
            speed: Channel::new(0.0),
            heading: Channel::new(0.0),
            grade: Channel::new(0.0),
            roll_gain: 0.0,
            vibration: Vibration::default(),
            segments: Vec::new(),
            fitted: Some(Arc::new(motion)),
        }
    }

    /// The fitted reference drive, when the trajectory is one.
    pub fn fitted(&self) -> Option<&FittedMotion> {
        self.fitted.as_deref()
    }

    /// Builds a trajectory from segments, starting at `origin`.
    pub fn from_segments(
        origin: Geodetic,
        segments: &[Segment],
        opts: TrajectoryOptions,
    ) -> Result<Self, Error> {
        let mut b = TrajectoryBuilder::new(opts.initial_speed_mps, opts.initial_heading_rad);
        for (i, s) in segments.iter().enumerate() {
            b.add(s)
                .map_err(|e| Error::Invalid(format!("segment {} ({s:?}): {e}", i + 1)))?;
        }
        let duration = opts.duration_s.unwrap_or(b.time());
        if !(duration.is_finite() && duration > 0.0) {
            return Err(Error::Invalid(format!(
                "the scenario lasts {duration} s; give segments or a positive duration"
            )));
        }
        Ok(b.finish(
            origin,
            duration,
            opts.roll_gain_rad_per_mps2,
            opts.vibration,
        ))
    }

    /// Initial position.
    pub fn origin(&self) -> Geodetic {
        self.origin
    }

    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    pub fn segments(&self) -> &[SegmentInfo] {
        &self.segments
    }

    pub fn vibration(&self) -> &Vibration {
        &self.vibration
    }

    /// The vehicle profiles at `t`.
    #[inline]
    pub fn vehicle(&self, t: f64) -> VehicleState {
        self.vehicle_at(t, &mut Cursor::default())
    }

    /// [`Trajectory::vehicle`] with a search cursor (fast for increasing `t`).
    #[inline]
    pub fn vehicle_at(&self, t: f64, c: &mut Cursor) -> VehicleState {
        if let Some(f) = &self.fitted {
            return fitted_vehicle(&f.state(t));
        }
        let [v, v_dot, _] = self.speed.eval_hint(t, &mut c.hint[0], &mut c.trig[0]);
        let [psi, psi_dot, psi_ddot] = self.heading.eval_hint(t, &mut c.hint[1], &mut c.trig[1]);
        let [theta, theta_dot, _] = self.grade.eval_hint(t, &mut c.hint[2], &mut c.trig[2]);
        VehicleState {
            speed_mps: v,
            accel_mps2: v_dot,
            heading_rad: psi,
            yaw_rate_rad_s: psi_dot,
            yaw_accel_rad_s2: psi_ddot,
            pitch_rad: theta,
            pitch_rate_rad_s: theta_dot,
            roll_rad: -self.roll_gain * v * psi_dot,
            roll_rate_rad_s: -self.roll_gain * (v_dot * psi_dot + v * psi_ddot),
        }
    }

    /// NED velocity of the vehicle without vibration (for the position
    /// integration): v·[cos θ cos ψ, cos θ sin ψ, −sin θ].
    #[inline]
    pub fn vehicle_velocity(&self, t: f64) -> Vector3<f64> {
        self.vehicle_velocity_at(t, &mut Cursor::default())
    }

    /// [`Trajectory::vehicle_velocity`] with a search cursor.
    #[inline]
    pub fn vehicle_velocity_at(&self, t: f64, c: &mut Cursor) -> Vector3<f64> {
        if let Some(f) = &self.fitted {
            return f.state(t).vel_n;
        }
        let v = self.speed.eval_hint(t, &mut c.hint[0], &mut c.trig[0])[0];
        let psi = self.heading.eval_hint(t, &mut c.hint[1], &mut c.trig[1])[0];
        let theta = self.grade.eval_hint(t, &mut c.hint[2], &mut c.trig[2])[0];
        let (sp, cp) = c.trig[3].sin_cos(psi);
        let (st, ct) = sin_cos0(theta, &mut c.trig[4]);
        Vector3::new(v * ct * cp, v * ct * sp, -v * st)
    }

    /// Velocity, acceleration, attitude and body rate at `t`.
    #[inline]
    pub fn kinematics(&self, t: f64) -> Kinematics {
        self.kinematics_at(t, &mut Cursor::default())
    }

    /// [`Trajectory::kinematics`] with a search cursor (fast for
    /// increasing `t`).
    #[inline]
    pub fn kinematics_at(&self, t: f64, cursor: &mut Cursor) -> Kinematics {
        if let Some(f) = &self.fitted {
            let st = f.state(t);
            let (c_nb, w_nb_b) = euler_kinematics(&st.euler, &st.euler_rate);
            return Kinematics {
                vehicle: fitted_vehicle(&st),
                vel_n: st.vel_n,
                acc_n: st.acc_n,
                c_nb,
                w_nb_b,
                alpha: Vector3::zeros(),
                dr_n: Vector3::zeros(),
            };
        }
        let s = self.vehicle_at(t, cursor);
        let (sps, cps) = cursor.trig[3].sin_cos(s.heading_rad);
        let (sth, cth) = sin_cos0(s.pitch_rad, &mut cursor.trig[4]);
        let (sph, cph) = sin_cos0(s.roll_rad, &mut cursor.trig[5]);
        let v = s.speed_mps;
        let u = Vector3::new(cth * cps, cth * sps, -sth);
        let du_dpsi = Vector3::new(-cth * sps, cth * cps, 0.0);
        let du_dth = Vector3::new(-sth * cps, -sth * sps, -cth);
        let mut vel_n = u * v;
        let mut acc_n =
            u * s.accel_mps2 + (du_dpsi * s.yaw_rate_rad_s + du_dth * s.pitch_rate_rad_s) * v;
        let mut c_nb = dcm_from_sin_cos((sph, cph), (sth, cth), (sps, cps));
        let mut w_nb_b = body_rate_from_euler_rates(
            (sph, cph),
            (sth, cth),
            [s.roll_rate_rad_s, s.pitch_rate_rad_s, s.yaw_rate_rad_s],
        );
        let mut alpha = Vector3::zeros();
        let mut dr_n = Vector3::zeros();
        if !self.vibration.is_empty() {
            let vib = self.vibration.at(t);
            // C = C_v Exp(α) ⇒ ω = Exp(α)ᵀ ω_v + J_r(α) α̇ (right Jacobian of SO(3)).
            let (exp_a, jr) = exp_and_right_jacobian(&vib.alpha);
            w_nb_b = exp_a.transpose() * w_nb_b + jr * vib.alpha_dot;
            c_nb *= exp_a;
            vel_n += vib.dr_dot;
            acc_n += vib.dr_ddot;
            alpha = vib.alpha;
            dr_n = vib.dr;
        }
        Kinematics {
            vehicle: s,
            vel_n,
            acc_n,
            c_nb,
            w_nb_b,
            alpha,
            dr_n,
        }
    }
}

/// The vehicle profiles of a fitted state (speed along the velocity).
fn fitted_vehicle(st: &FittedState) -> VehicleState {
    let speed = st.vel_n.norm();
    VehicleState {
        speed_mps: speed,
        accel_mps2: if speed > 1e-9 {
            st.vel_n.dot(&st.acc_n) / speed
        } else {
            0.0
        },
        heading_rad: st.euler[2],
        yaw_rate_rad_s: st.euler_rate[2],
        yaw_accel_rad_s2: st.euler_accel[2],
        pitch_rad: st.euler[1],
        pitch_rate_rad_s: st.euler_rate[1],
        roll_rad: st.euler[0],
        roll_rate_rad_s: st.euler_rate[0],
    }
}

/// Exp(α) (Rodrigues) and the right Jacobian of SO(3),
/// J_r(α) = I − (1−cos a)/a²·[α×] + (a − sin a)/a³·[α×]², with series
/// below 1e-3 rad (Barfoot, *State Estimation for Robotics*, 2017, eqs
/// 7.14 and 7.77).
fn exp_and_right_jacobian(alpha: &Vector3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let a2 = alpha.norm_squared();
    let (s1, s2, s3) = if a2 < 1e-6 {
        (1.0 - a2 / 6.0, 0.5 - a2 / 24.0, 1.0 / 6.0 - a2 / 120.0)
    } else {
        let a = a2.sqrt();
        let (sa, ca) = a.sin_cos();
        (sa / a, (1.0 - ca) / a2, (a - sa) / (a2 * a))
    };
    let k = skew(alpha);
    let k2 = k * k;
    let i = Matrix3::identity();
    (i + k * s1 + k2 * s2, i - k * s2 + k2 * s3)
}

/// The named built-in scenarios.
pub const BUILTIN_SCENARIOS: &[&str] = &["test-track", "urban", "figure8", "static"];

/// The segments of a built-in scenario lasting `duration_s`, ending
/// stopped. `urban` is a random drive drawn from `traj_seed`.
pub fn builtin_segments(name: &str, duration_s: f64, traj_seed: u64) -> Option<Vec<Segment>> {
    let mut out = SegmentList::new();
    match name {
        "static" => out.push(Segment::Static {
            duration_s: duration_s.max(1.0),
        }),
        "test-track" => test_track(&mut out, duration_s),
        "figure8" => figure8(&mut out, duration_s),
        "urban" => urban(&mut out, duration_s, traj_seed),
        _ => return None,
    }
    Some(out.segments)
}

/// A list of segments with a builder alongside, to know times and speed.
struct SegmentList {
    segments: Vec<Segment>,
    b: TrajectoryBuilder,
}

impl SegmentList {
    fn new() -> Self {
        SegmentList {
            segments: Vec::new(),
            b: TrajectoryBuilder::new(0.0, 0.0),
        }
    }

    fn push(&mut self, s: Segment) {
        // Built-in segments are valid by construction; a rejected one is
        // skipped rather than breaking the scenario.
        if self.b.add(&s).is_ok() {
            self.segments.push(s);
        }
    }

    fn t(&self) -> f64 {
        self.b.time()
    }

    /// Brakes to a stop and stands still until `duration_s`.
    fn finish(&mut self, duration_s: f64) {
        if self.b.speed() > 0.0 {
            self.push(Segment::Brake {
                speed_mps: Some(0.0),
                decel_mps2: Some(2.0),
            });
        }
        let rest = duration_s - self.t();
        if rest > 1e-6 {
            self.push(Segment::Static { duration_s: rest });
        }
    }
}

fn accel(speed: f64, a: f64) -> Segment {
    Segment::Accelerate {
        speed_mps: speed,
        accel_mps2: Some(a),
    }
}

fn brake(speed: f64, a: f64) -> Segment {
    Segment::Brake {
        speed_mps: Some(speed),
        decel_mps2: Some(a),
    }
}

fn cruise(d: f64) -> Segment {
    Segment::Cruise {
        duration_s: Some(d),
        distance_m: None,
    }
}

/// Seed 000's vehicle performance test, lap after lap: a straight line
/// (acceleration, constant speed), a constant-radius curve, hard braking
/// to a stop, and back round the second curve of an oval.
fn test_track(out: &mut SegmentList, duration_s: f64) {
    let curve = |angle: f64| Segment::Turn {
        angle_deg: angle,
        yaw_rate_deg_s: None,
        radius_m: Some(80.0),
        ramp_s: Some(2.0),
    };
    let lap = [
        accel(20.0, 2.5),
        cruise(10.0),
        brake(14.0, 2.0),
        curve(180.0),
        accel(22.0, 2.5),
        cruise(6.0),
        brake(0.0, 5.0),
        Segment::Stop {
            duration_s: 6.0,
            decel_mps2: None,
        },
        accel(14.0, 2.0),
        curve(180.0),
        brake(0.0, 2.0),
        Segment::Stop {
            duration_s: 4.0,
            decel_mps2: None,
        },
    ];
    let lap_s = {
        let mut b = TrajectoryBuilder::new(0.0, 0.0);
        for s in &lap {
            let _ = b.add(s);
        }
        b.time()
    };
    let static_s = (duration_s * 0.1).clamp(5.0, 60.0);
    out.push(Segment::Static {
        duration_s: static_s,
    });
    while out.t() + lap_s <= duration_s - 5.0 {
        for s in &lap {
            out.push(s.clone());
        }
    }
    out.finish(duration_s);
}

/// Two constant-radius loops, right then left, repeated.
fn figure8(out: &mut SegmentList, duration_s: f64) {
    let static_s = (duration_s * 0.1).clamp(5.0, 30.0);
    out.push(Segment::Static {
        duration_s: static_s,
    });
    out.push(accel(10.0, 1.5));
    let lp = |a: f64| Segment::Turn {
        angle_deg: a,
        yaw_rate_deg_s: None,
        radius_m: Some(40.0),
        ramp_s: Some(2.0),
    };
    // One loop at 10 m/s, radius 40 m: 2π·40/10 ≈ 25 s plus ramps.
    while out.t() + 2.0 * 27.5 + 12.0 <= duration_s {
        out.push(lp(360.0));
        out.push(lp(-360.0));
    }
    out.finish(duration_s);
}

/// A random urban drive: starts and stops, intersections (±90° turns after
/// braking), gentle curves, lane changes and hills, drawn from `traj_seed`.
fn urban(out: &mut SegmentList, duration_s: f64, traj_seed: u64) {
    let mut r = rng::stream(traj_seed, "trajectory.urban");
    let u = |r: &mut rng::SimRng, lo: f64, hi: f64| rng::uniform_in(r, lo, hi);
    let static_s = (duration_s * 0.1).clamp(5.0, 60.0);
    out.push(Segment::Static {
        duration_s: static_s,
    });
    // Keep ~35 s for the final stop.
    let reserve = 35.0;
    while out.t() < duration_s - reserve - 30.0 {
        if out.b.speed() < 1.0 {
            let v = u(&mut r, 10.0, 18.0);
            out.push(accel(v, u(&mut r, 1.5, 3.0)));
        }
        out.push(cruise(u(&mut r, 2.0, 12.0)));
        let v = out.b.speed();
        let pick = u(&mut r, 0.0, 1.0);
        if pick < 0.30 {
            // Intersection: slow down, turn ±90° at 2–3.5 m/s² lateral.
            let vt = u(&mut r, 8.0, 12.0);
            if v > vt {
                out.push(brake(vt, u(&mut r, 1.5, 3.0)));
            }
            let sign = if u(&mut r, 0.0, 1.0) < 0.5 { 1.0 } else { -1.0 };
            let lat = u(&mut r, 2.0, 3.5);
            out.push(Segment::Turn {
                angle_deg: 90.0 * sign,
                yaw_rate_deg_s: Some((lat / out.b.speed()).to_degrees()),
                radius_m: None,
                ramp_s: Some(u(&mut r, 1.0, 2.0)),
            });
            out.push(accel(u(&mut r, 12.0, 24.0), 2.0));
        } else if pick < 0.45 {
            let sign = if u(&mut r, 0.0, 1.0) < 0.5 { 1.0 } else { -1.0 };
            out.push(Segment::Turn {
                angle_deg: sign * u(&mut r, 20.0, 50.0),
                yaw_rate_deg_s: Some(u(&mut r, 3.0, 6.0)),
                radius_m: None,
                ramp_s: Some(2.0),
            });
        } else if pick < 0.60 {
            let sign = if u(&mut r, 0.0, 1.0) < 0.5 { 1.0 } else { -1.0 };
            out.push(Segment::LaneChange {
                offset_m: 3.5 * sign,
                duration_s: Some(u(&mut r, 3.5, 6.0)),
            });
        } else if pick < 0.75 {
            out.push(Segment::Hill {
                grade_deg: u(&mut r, 1.5, 4.0),
                duration_s: u(&mut r, 30.0, 60.0),
            });
        } else if pick < 0.90 {
            out.push(Segment::Stop {
                duration_s: u(&mut r, 4.0, 15.0),
                decel_mps2: Some(u(&mut r, 1.5, 3.5)),
            });
        } else {
            let target = (v + u(&mut r, -6.0, 6.0)).clamp(8.0, 25.0);
            out.push(accel(target, 1.5));
        }
    }
    out.finish(duration_s);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn origin() -> Geodetic {
        Geodetic::from_deg(30.0, 114.0, 20.0)
    }

    fn numeric_derivative(f: impl Fn(f64) -> f64, t: f64) -> f64 {
        let h = 1e-5;
        (f(t + h) - f(t - h)) / (2.0 * h)
    }

    #[test]
    fn shapes_are_consistent_and_smooth_at_the_ends() {
        for shape in [
            Shape::Step(1.7),
            Shape::RampUp(0.3),
            Shape::Linear(-0.2),
            Shape::RampDown(0.4),
            Shape::Bump(0.15),
        ] {
            let p = Piece {
                t0: 2.0,
                dur: 3.0,
                q0: 0.5,
                shape,
            };
            for &t in &[2.3, 3.1, 4.4] {
                let e = p.eval(t);
                let d1 = numeric_derivative(|x| p.eval(x)[0], t);
                let d2 = numeric_derivative(|x| p.eval(x)[1], t);
                assert!((e[1] - d1).abs() < 1e-8, "{shape:?} q' {e:?} {d1}");
                assert!((e[2] - d2).abs() < 1e-7, "{shape:?} q'' {e:?} {d2}");
            }
            // The end value agrees with the formula at τ = 1.
            assert!((p.eval(5.0 - 1e-12)[0] - p.end_value()).abs() < 1e-9);
            // Second derivative vanishes at both ends (continuity of body
            // rates and specific force at joints).
            assert!(p.eval(2.0)[2].abs() < 1e-12, "{shape:?}");
            assert!(p.eval(5.0 - 1e-12)[2].abs() < 1e-9, "{shape:?}");
        }
    }

    #[test]
    fn trig_cache_matches_libm() {
        let mut c = TrigCache::default();
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            let x = -40.0 + k as f64 * 4.1e-4 + 0.03 * (k as f64 * 0.37).sin();
            let (s, co) = c.sin_cos(x);
            let (s1, c1) = x.sin_cos();
            worst = worst.max((s - s1).abs()).max((co - c1).abs());
        }
        assert!(worst < 5e-16, "{worst}");
    }

    #[test]
    fn turn_reaches_its_angle_with_the_requested_rate() {
        let segs = vec![
            accel(10.0, 2.0),
            Segment::Turn {
                angle_deg: 90.0,
                yaw_rate_deg_s: Some(10.0),
                radius_m: None,
                ramp_s: Some(2.0),
            },
            cruise(1.0),
        ];
        let traj =
            Trajectory::from_segments(origin(), &segs, TrajectoryOptions::default()).unwrap();
        let end = traj.vehicle(traj.duration_s());
        assert!((end.heading_rad - 90f64.to_radians()).abs() < 1e-12);
        let mid = traj.vehicle(10.0 + 2.0 + 3.0);
        assert!((mid.yaw_rate_rad_s - 10f64.to_radians()).abs() < 1e-12);
    }

    #[test]
    fn lane_change_moves_sideways_by_the_offset() {
        let a = lane_change_amplitude(3.5, 12.0, 4.4).unwrap();
        // Integrate the lateral displacement independently (fine trapezoid).
        let n = 20000;
        let mut y = 0.0;
        for k in 0..n {
            let tau = (k as f64 + 0.5) / n as f64;
            let u = 1.0 - (TAU * tau).cos();
            y += 12.0 * (a * 0.25 * u * u).sin() * 4.4 / n as f64;
        }
        assert!((y - 3.5).abs() < 1e-6, "{y}");
    }

    #[test]
    fn builtins_fill_the_duration_and_end_stopped() {
        for name in BUILTIN_SCENARIOS {
            for &d in &[120.0, 600.0, 3600.0] {
                let segs = builtin_segments(name, d, 3).unwrap();
                let t = Trajectory::from_segments(origin(), &segs, TrajectoryOptions::default())
                    .unwrap();
                assert!(
                    (t.duration_s() - d).abs() < 1e-6,
                    "{name} {d}: {}",
                    t.duration_s()
                );
                assert!(t.vehicle(d).speed_mps.abs() < 1e-9, "{name} {d}");
            }
        }
        assert!(builtin_segments("nope", 10.0, 0).is_none());
    }

    #[test]
    fn bad_segments_are_explained() {
        let err = Trajectory::from_segments(
            origin(),
            &[Segment::Turn {
                angle_deg: 90.0,
                yaw_rate_deg_s: None,
                radius_m: None,
                ramp_s: None,
            }],
            TrajectoryOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("segment 1") && err.contains("needs the vehicle moving"),
            "{err}"
        );
        let err = Trajectory::from_segments(
            origin(),
            &[accel(5.0, 1.0), Segment::Static { duration_s: 3.0 }],
            TrajectoryOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("segment 2") && err.contains("stopped"),
            "{err}"
        );
    }

    #[test]
    fn body_rate_matches_attitude_change_with_vibration() {
        let spec = VibrationSpec {
            tones: vec![ToneSpec {
                freq_hz: 23.0,
                gyro_amp_deg_s: [0.5, 0.3, 0.2],
                accel_amp_mps2: [0.1, 0.1, 0.5],
            }],
            random: None,
        };
        let vib = Vibration::draw(&spec, &mut rng::stream(1, "vib")).unwrap();
        let segs = vec![
            accel(12.0, 2.0),
            Segment::Turn {
                angle_deg: 60.0,
                yaw_rate_deg_s: Some(12.0),
                radius_m: None,
                ramp_s: Some(1.0),
            },
            Segment::Hill {
                grade_deg: 3.0,
                duration_s: 20.0,
            },
        ];
        let opts = TrajectoryOptions {
            initial_heading_rad: 0.3,
            roll_gain_rad_per_mps2: 0.5f64.to_radians(),
            vibration: vib,
            ..Default::default()
        };
        let traj = Trajectory::from_segments(origin(), &segs, opts).unwrap();
        for &t in &[3.0, 7.7, 9.1, 15.0, 21.3] {
            let k = traj.kinematics(t);
            // C(t+h) ≈ C(t)·Exp(ω h) over a short symmetric step.
            let h = 1e-6;
            let c0 = traj.kinematics(t - h).c_nb;
            let c1 = traj.kinematics(t + h).c_nb;
            let dc = c0.transpose() * c1;
            let w_num = Vector3::new(
                dc[(2, 1)] - dc[(1, 2)],
                dc[(0, 2)] - dc[(2, 0)],
                dc[(1, 0)] - dc[(0, 1)],
            ) / (2.0 * 2.0 * h);
            assert!(
                (w_num - k.w_nb_b).norm() < 1e-6,
                "t={t}: {w_num} vs {}",
                k.w_nb_b
            );
            let a_num = (traj.kinematics(t + h).vel_n - traj.kinematics(t - h).vel_n) / (2.0 * h);
            assert!(
                (a_num - k.acc_n).norm() < 1e-5,
                "t={t}: {a_num} vs {}",
                k.acc_n
            );
            let q = k.q_nb();
            assert!((q.to_rotation_matrix().matrix() - k.c_nb).abs().max() < 1e-12);
        }
    }
}
