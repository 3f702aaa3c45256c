//! Heading found in the run from the GNSS track, for a land vehicle whose
//! heading was unknown at the start (it never moved fast enough for the
//! alignment's course, `crate::align`).
//!
//! While the heading is unknown the filter holds its yaw (a consider
//! state) and the gyros carry the nominal yaw ψ̂ from wherever it started,
//! so ψ̂(t) = ψ(t) − δ with one constant offset δ (the gyro's drift over a
//! few minutes aside). A land vehicle moves along its forward axis (no
//! sideslip at low lateral acceleration; Groves, *Principles of GNSS,
//! Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed.,
//! §6.1.4, heading from trajectory), so the course c of the track between
//! two fixes some metres apart is the vehicle's heading there, and each
//! such chord measures δ = c + α − ψ̂ (α the IMU's mounting yaw,
//! `mount_yaw_rad`: the IMU's yaw is the vehicle's heading + α, as the
//! NHC's C_b^v and the alignment have it),
//! whatever the speed: at 1 m/s a chord of 10 m with
//! fixes of 0.9 m σ measures the course to 7°, where the alignment's
//! instantaneous velocity would need 3 m/s.
//!
//! The hypothesis "constant δ" is then tested, not assumed: the chords
//! must agree (circular spread ≤ `max_spread_rad`) over courses that
//! differ by at least `min_course_span_rad` (a vehicle that turned: a
//! drone flying sideways, or a reversing vehicle, gives chords that
//! disagree, and nothing is acquired). The heading is then set by turning
//! the nominal attitude by the mean δ̄ about the vertical, with σ the
//! chords' spread plus the sideslip allowance (not the spread over √n: the
//! fixes' errors are time-correlated, so the chords are not independent), and the yaw is a filter
//! state again from there on. The epochs before, written with the held
//! yaw, are turned by the same δ̄ in the smoothed output
//! (`crate::smoother`), so the heading covers the whole run. Every later
//! chord is a heading measurement of its own (ψ̂ + δ, σ from the chord's
//! length and the fixes' σ, doubled for their time correlation, plus the
//! sideslip allowance), so the heading does not drift away with the
//! vertical gyro's bias, which nothing else observes on a slow vehicle.

use std::collections::VecDeque;

use nalgebra::{UnitQuaternion, Vector3};

use crate::attitude::wrap_pi;
use crate::time::GpsTime;

/// Settings of the in-run heading acquisition from the GNSS track.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CourseHeadingOptions {
    /// Yaw of the IMU's x axis relative to the vehicle's forward axis (rad).
    pub mount_yaw_rad: f64,
    /// A chord is used from this length on, in units of the fixes'
    /// horizontal σ (its course σ is then below 1/ratio rad).
    pub min_chord_sigmas: f64,
    /// …and from this length on (m).
    pub min_chord_m: f64,
    /// Chords spanning more than this (s) are not formed (the vehicle may
    /// have turned along them).
    pub max_chord_s: f64,
    /// Chords needed before the heading is set.
    pub min_chords: usize,
    /// Largest circular spread (1σ) of the chords' δ (rad).
    pub max_spread_rad: f64,
    /// The chords' courses must span at least this (rad).
    pub min_course_span_rad: f64,
    /// Sideslip and mounting allowance added to the heading σ (rad).
    pub allowance_rad: f64,
}

impl CourseHeadingOptions {
    /// The defaults, for an IMU mounted at yaw `mount_yaw_rad`.
    pub fn new(mount_yaw_rad: f64) -> Self {
        CourseHeadingOptions {
            mount_yaw_rad,
            min_chord_sigmas: 8.0,
            min_chord_m: 3.0,
            max_chord_s: 20.0,
            min_chords: 12,
            max_spread_rad: 12f64.to_radians(),
            min_course_span_rad: 30f64.to_radians(),
            allowance_rad: 2f64.to_radians(),
        }
    }
}

/// The heading found: the offset δ̄ that turns the held nominal yaw into
/// the heading, its σ, and when it was set.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct HeadingAcquired {
    /// When the heading was set.
    #[serde(skip)]
    pub time: GpsTime,
    /// Seconds of GPS week when the heading was set.
    pub time_sow: f64,
    /// The offset δ̄ added to the held yaw (rad).
    pub offset_rad: f64,
    /// Its σ (rad), the allowance included.
    pub sd_rad: f64,
    /// Chords averaged.
    pub chords: usize,
    /// Their circular spread (rad, 1σ).
    pub spread_rad: f64,
    /// The span of their courses (rad).
    pub course_span_rad: f64,
}

/// One fix of the recent track: time, local north/east (m) about the first
/// fix, its horizontal σ, and the nominal yaw then.
#[derive(Clone, Copy, Debug)]
struct TrackPoint {
    time: GpsTime,
    north_m: f64,
    east_m: f64,
    sd_h_m: f64,
    yaw_rad: f64,
}

/// The acquisition's state: the recent track and the chords' δ.
#[derive(Clone, Debug)]
pub(crate) struct CourseHeading {
    opts: CourseHeadingOptions,
    origin: Option<(f64, f64)>,
    track: VecDeque<TrackPoint>,
    /// (course, δ) of each chord.
    chords: Vec<(f64, f64)>,
    /// End time of the last chord (chords do not overlap).
    last_chord_end: Option<GpsTime>,
    /// The chord the last fix completed, if any.
    last_chord: Option<Chord>,
}

/// One chord of the track as a heading measurement: the held (or
/// estimated) nominal yaw plus `delta_rad` is the heading, with σ `sd_rad`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Chord {
    pub delta_rad: f64,
    pub sd_rad: f64,
}

/// The yaw of the body x axis (rad): ZYX Euler yaw, defined unless the
/// axis is vertical.
pub(crate) fn yaw_of(q_nb: &UnitQuaternion<f64>) -> f64 {
    let x = q_nb * Vector3::x();
    x.y.atan2(x.x)
}

impl CourseHeading {
    pub(crate) fn new(opts: CourseHeadingOptions) -> Self {
        CourseHeading {
            opts,
            origin: None,
            track: VecDeque::new(),
            chords: Vec::new(),
            last_chord_end: None,
            last_chord: None,
        }
    }

    /// A fix used by the filter at `time` (geodetic lat/lon in rad, its
    /// horizontal σ), with the nominal yaw then. Returns the heading once
    /// the chords agree (until then and after, [`Self::take_chord`] gives
    /// the chord this fix completed).
    pub(crate) fn push(
        &mut self,
        time: GpsTime,
        lat_rad: f64,
        lon_rad: f64,
        sd_h_m: f64,
        yaw_rad: f64,
    ) -> Option<HeadingAcquired> {
        self.last_chord = None;
        if !(lat_rad.is_finite() && lon_rad.is_finite() && sd_h_m.is_finite() && sd_h_m > 0.0) {
            return None;
        }
        let (lat0, lon0) = *self.origin.get_or_insert((lat_rad, lon_rad));
        // A local tangent plane is plenty over a few hundred metres.
        let r = crate::earth::A;
        let p = TrackPoint {
            time,
            north_m: (lat_rad - lat0) * r,
            east_m: (lon_rad - lon0) * r * lat0.cos(),
            sd_h_m,
            yaw_rad,
        };
        while self
            .track
            .front()
            .is_some_and(|f| (time - f.time) as f64 * 1e-9 > self.opts.max_chord_s)
        {
            self.track.pop_front();
        }
        self.track.push_back(p);
        self.chord_ending_at(&p);
        self.decide(time)
    }

    /// The chord the last [`Self::push`] completed.
    pub(crate) fn take_chord(&mut self) -> Option<Chord> {
        self.last_chord.take()
    }

    /// The shortest chord ending at `p` that is long enough, if it does not
    /// overlap the previous one.
    fn chord_ending_at(&mut self, p: &TrackPoint) {
        let o = &self.opts;
        let start = self.track.iter().rev().skip(1).find(|a| {
            let len = (p.north_m - a.north_m).hypot(p.east_m - a.east_m);
            let sd = a.sd_h_m.max(p.sd_h_m);
            len >= o.min_chord_m && len >= o.min_chord_sigmas * sd
        });
        let Some(a) = start.copied() else { return };
        if self.last_chord_end.is_some_and(|t| a.time < t) {
            return;
        }
        let course = (p.east_m - a.east_m).atan2(p.north_m - a.north_m);
        // The nominal yaw over the chord: the circular mean of the yaws of
        // its fixes (the gyros turn it as the vehicle turns).
        let (s, c) = self
            .track
            .iter()
            .filter(|t| t.time >= a.time && t.time <= p.time)
            .fold((0.0, 0.0), |(s, c), t| {
                (s + t.yaw_rad.sin(), c + t.yaw_rad.cos())
            });
        let yaw = s.atan2(c);
        let delta = wrap_pi(course + o.mount_yaw_rad - yaw);
        self.chords.push((course, delta));
        self.last_chord_end = Some(p.time);
        let len = (p.north_m - a.north_m).hypot(p.east_m - a.east_m);
        let sd = a.sd_h_m.max(p.sd_h_m);
        self.last_chord = Some(Chord {
            delta_rad: delta,
            sd_rad: 2.0 * std::f64::consts::SQRT_2 * sd / len + o.allowance_rad,
        });
    }

    /// The heading when the last `min_chords` chords agree over a wide
    /// enough span of courses.
    fn decide(&self, time: GpsTime) -> Option<HeadingAcquired> {
        let o = &self.opts;
        let n = self.chords.len();
        if n < o.min_chords {
            return None;
        }
        let recent = &self.chords[n - o.min_chords..];
        let (s, c) = recent
            .iter()
            .fold((0.0, 0.0), |(s, c), (_, d)| (s + d.sin(), c + d.cos()));
        let mean = s.atan2(c);
        // Circular spread: √(−2 ln R̄) (Mardia & Jupp, *Directional
        // Statistics*, 2000, §2.3.4).
        let r_bar = (s.hypot(c) / recent.len() as f64).min(1.0);
        let spread = (-2.0 * r_bar.max(1e-300).ln()).sqrt();
        if spread > o.max_spread_rad {
            return None;
        }
        // Span of the courses: the largest difference from the first.
        let c0 = recent[0].0;
        let (lo, hi) = recent.iter().fold((0.0f64, 0.0f64), |(lo, hi), (c, _)| {
            let d = wrap_pi(c - c0);
            (lo.min(d), hi.max(d))
        });
        let span = hi - lo;
        if span < o.min_course_span_rad {
            return None;
        }
        Some(HeadingAcquired {
            time,
            time_sow: time.sow(),
            offset_rad: mean,
            sd_rad: spread + o.allowance_rad,
            chords: recent.len(),
            spread_rad: spread,
            course_span_rad: span,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::rng;

    /// A vehicle driving a loop at 1 m/s with a nominal yaw 70° off the
    /// truth: the chords measure the 70° back within their σ.
    #[test]
    fn a_slow_loop_gives_the_heading_offset() {
        let mut r = rng::stream(3, "course-heading");
        let offset = 70f64.to_radians();
        let mut ch = CourseHeading::new(CourseHeadingOptions::new(0.0));
        let (mut n, mut e, mut psi) = (0.0f64, 0.0f64, 0.3f64);
        let mut got = None;
        for k in 0..2000 {
            let dt = 0.4;
            // a slow turn then straight, repeated
            let rate = if (k / 100) % 2 == 0 { 0.02 } else { 0.0 };
            psi += rate * dt;
            n += psi.cos() * 1.0 * dt;
            e += psi.sin() * 1.0 * dt;
            let sd = 0.3;
            let fix_n = n + rng::normal(&mut r) * sd;
            let fix_e = e + rng::normal(&mut r) * sd;
            let lat = fix_n / crate::earth::A;
            let lon = fix_e / crate::earth::A;
            let t = GpsTime::from_ns((k as f64 * dt * 1e9) as i64);
            if let Some(h) = ch.push(t, lat, lon, sd, psi - offset) {
                got = Some(h);
                break;
            }
        }
        let h = got.expect("acquired");
        let err = wrap_pi(h.offset_rad - offset).abs();
        assert!(err < 3.0 * h.sd_rad, "{err} vs σ {}", h.sd_rad);
        // σ: the chords' spread (3 m chords of 0.3 m fixes: ≈ 8°; not
        // divided by √n, the fixes' errors being time-correlated in
        // practice) plus the 2° allowance.
        assert!(h.sd_rad < 15f64.to_radians(), "{}", h.sd_rad.to_degrees());
        assert!(err < 5f64.to_radians(), "{}", err.to_degrees());
    }

    /// A drone that drifts in every direction while its nose stays put:
    /// the chords disagree and nothing is acquired.
    #[test]
    fn sideways_motion_acquires_nothing() {
        let mut ch = CourseHeading::new(CourseHeadingOptions::new(0.0));
        let (mut n, mut e) = (0.0f64, 0.0f64);
        for k in 0..3000 {
            let dt = 0.2;
            let course = (k as f64 * 0.013).sin() * 3.0;
            n += course.cos() * 1.5 * dt;
            e += course.sin() * 1.5 * dt;
            let t = GpsTime::from_ns((k as f64 * dt * 1e9) as i64);
            let got = ch.push(t, n / crate::earth::A, e / crate::earth::A, 0.2, 0.1);
            assert!(got.is_none(), "acquired at step {k}: {got:?}");
        }
    }
}
