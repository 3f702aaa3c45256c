//! GPS time with integer nanoseconds.
//!
//! All timestamps inside navsync are [`GpsTime`]: nanoseconds since the GPS
//! epoch (1980-01-06 00:00:00 UTC), so that no precision is lost over a week
//! (an `f64` seconds-of-week keeps ~0.1 ns, an `f32` only ~60 ms) and equal
//! epochs compare equal. Files carry week + seconds of week (SOW); KF-GINS
//! files carry SOW only, and `WeekTracker` turns such a stream into
//! absolute time across a week rollover.
#![warn(missing_docs)]

use std::fmt;
use std::ops::{Add, Sub};

/// Nanoseconds in one second.
pub const NS_PER_S: i64 = 1_000_000_000;
/// Seconds in one GPS week.
pub(crate) const SECONDS_PER_WEEK: i64 = 604_800;
/// Nanoseconds in one GPS week.
pub const NS_PER_WEEK: i64 = SECONDS_PER_WEEK * NS_PER_S;

/// Seconds to whole nanoseconds (rounded to the nearest ns).
pub(crate) fn seconds_to_ns(seconds: f64) -> i64 {
    (seconds * 1e9).round() as i64
}

/// A window of GPS time, such as a GNSS outage: its start and length.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct OutageWindow {
    /// First instant of the window.
    pub start: GpsTime,
    /// Length of the window (s).
    pub duration_s: f64,
}

impl OutageWindow {
    /// A window from `start` lasting `duration_s` seconds.
    pub fn new(start: GpsTime, duration_s: f64) -> Self {
        OutageWindow { start, duration_s }
    }

    /// The end of the window.
    pub fn end(&self) -> GpsTime {
        self.start.add_seconds(self.duration_s)
    }
}

/// `sow:length`, the `--outages` syntax.
impl fmt::Display for OutageWindow {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.3}:{}", self.start.sow(), self.duration_s)
    }
}

/// An instant of GPS time, as integer nanoseconds since the GPS epoch.
///
/// ```
/// use navsync::GpsTime;
/// let t = GpsTime::from_week_sow(2300, 100_000.005);
/// assert_eq!((t.week(), t.sow()), (2300, 100_000.005));
/// // Intervals are exact in nanoseconds, whatever the epoch.
/// assert_eq!(t.add_seconds(0.005).seconds_since(t), 0.005);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct GpsTime {
    ns: i64,
}

impl GpsTime {
    /// The GPS epoch itself.
    pub const EPOCH: GpsTime = GpsTime { ns: 0 };

    /// From nanoseconds since the GPS epoch.
    pub const fn from_ns(ns: i64) -> Self {
        GpsTime { ns }
    }

    /// Nanoseconds since the GPS epoch.
    pub const fn ns(self) -> i64 {
        self.ns
    }

    /// From a week number and nanoseconds of week (which may be outside
    /// `0..NS_PER_WEEK`; it is normalised).
    pub const fn from_week_ns(week: i64, ns_of_week: i64) -> Self {
        GpsTime {
            ns: week * NS_PER_WEEK + ns_of_week,
        }
    }

    /// From a week number and seconds of week. Rounded to the nearest ns.
    pub fn from_week_sow(week: i64, sow_s: f64) -> Self {
        Self::from_week_ns(week, seconds_to_ns(sow_s))
    }

    /// From seconds since the GPS epoch (rounded to the nearest ns).
    pub fn from_seconds(seconds: f64) -> Self {
        GpsTime {
            ns: seconds_to_ns(seconds),
        }
    }

    /// Seconds since the GPS epoch as `f64` (~0.1 µs resolution in 2026;
    /// use differences of [`GpsTime`] for precise intervals).
    pub fn seconds(self) -> f64 {
        self.ns as f64 * 1e-9
    }

    /// GPS week number.
    pub const fn week(self) -> i64 {
        self.ns.div_euclid(NS_PER_WEEK)
    }

    /// Nanoseconds of week, in `0..NS_PER_WEEK`.
    pub const fn ns_of_week(self) -> i64 {
        self.ns.rem_euclid(NS_PER_WEEK)
    }

    /// Seconds of week as `f64` (exact to ~0.1 ns).
    pub fn sow(self) -> f64 {
        let ns = self.ns_of_week();
        (ns / NS_PER_S) as f64 + (ns % NS_PER_S) as f64 * 1e-9
    }

    /// Interval `self - earlier` in seconds.
    pub fn seconds_since(self, earlier: GpsTime) -> f64 {
        (self.ns - earlier.ns) as f64 * 1e-9
    }

    /// This instant shifted by `seconds` (rounded to the nearest ns).
    pub fn add_seconds(self, seconds: f64) -> GpsTime {
        GpsTime {
            ns: self.ns + seconds_to_ns(seconds),
        }
    }

    /// Writes `sow` with 9 decimals (exact nanoseconds) into `out`.
    pub fn write_sow(self, out: &mut Vec<u8>) {
        let ns = self.ns_of_week();
        crate::numfmt::push_u64(out, (ns / NS_PER_S) as u64);
        out.push(b'.');
        crate::numfmt::push_u64_padded(out, (ns % NS_PER_S) as u64, 9);
    }
}

impl Add<i64> for GpsTime {
    type Output = GpsTime;
    /// Adds nanoseconds.
    fn add(self, ns: i64) -> GpsTime {
        GpsTime { ns: self.ns + ns }
    }
}

impl Sub for GpsTime {
    type Output = i64;
    /// Difference in nanoseconds.
    fn sub(self, other: GpsTime) -> i64 {
        self.ns - other.ns
    }
}

impl fmt::Display for GpsTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ns = self.ns_of_week();
        write!(f, "{} {}.{:09}", self.week(), ns / NS_PER_S, ns % NS_PER_S)
    }
}

/// A week rollover whose forward step (from the last line to the new one)
/// is longer than this is taken only when the next line confirms it.
const MAX_UNCONFIRMED_ROLLOVER_STEP_NS: i64 = 600 * NS_PER_S;

/// How a line's SOW stands to the last kept one's, for [`WeekTracker`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Rollover {
    /// No fall-back of more than half a week: the same week.
    No,
    /// A week rollover, taken.
    Taken,
    /// A rollover too far forward to take before the next line confirms it.
    Unconfirmed,
}

/// Turns a stream of seconds-of-week without week numbers (KF-GINS files)
/// into absolute [`GpsTime`], adding a week whenever SOW falls back by more
/// than half a week (a week rollover), so that time stays monotonic.
///
/// A fall-back that would make a forward step of more than ten minutes is
/// what one corrupt line looks like (a small SOW in mid-week), so it is not
/// taken for a rollover at once: that line reads as going backwards and is
/// skipped by the reader, and it is the next line, if it goes on from it
/// within ten minutes, that starts the new week. A real rollover after a long
/// gap thus costs one line; a corrupt line costs only itself.
///
/// Readers call [`WeekTracker::peek`] once per line, then
/// [`WeekTracker::resolve`] for the lines they keep.
#[derive(Clone, Debug)]
pub(crate) struct WeekTracker {
    week: i64,
    last_ns_of_week: Option<i64>,
    /// SOW (ns) of the last line peeked that was a rollover too far forward
    /// to take unconfirmed.
    unconfirmed_rollover_ns: Option<i64>,
}

impl WeekTracker {
    /// Starts in `week` (0 when the files carry no week).
    pub fn new(week: i64) -> Self {
        WeekTracker {
            week,
            last_ns_of_week: None,
            unconfirmed_rollover_ns: None,
        }
    }

    /// The week of a SOW after the last kept line, and what kind of step
    /// it is.
    fn week_of(&self, ns_of_week: i64) -> (i64, Rollover) {
        let Some(last) = self.last_ns_of_week else {
            return (self.week, Rollover::No);
        };
        if last - ns_of_week <= NS_PER_WEEK / 2 {
            return (self.week, Rollover::No);
        }
        let step_ns = ns_of_week + NS_PER_WEEK - last;
        let confirmed = self.unconfirmed_rollover_ns.is_some_and(|previous| {
            ns_of_week > previous && ns_of_week - previous <= MAX_UNCONFIRMED_ROLLOVER_STEP_NS
        });
        if step_ns <= MAX_UNCONFIRMED_ROLLOVER_STEP_NS || confirmed {
            (self.week + 1, Rollover::Taken)
        } else {
            (self.week, Rollover::Unconfirmed)
        }
    }

    /// Absolute time of a line's seconds-of-week (ns), before the reader
    /// checks its order; the tracker advances only on [`Self::resolve`].
    pub(crate) fn peek(&mut self, ns_of_week: i64) -> GpsTime {
        let (week, rollover) = self.week_of(ns_of_week);
        match rollover {
            Rollover::Unconfirmed => self.unconfirmed_rollover_ns = Some(ns_of_week),
            // A rollover taken on confirmation keeps what confirmed it for
            // `resolve`.
            Rollover::Taken => {}
            Rollover::No => self.unconfirmed_rollover_ns = None,
        }
        GpsTime::from_week_ns(week, ns_of_week)
    }

    /// Absolute time of a line the reader keeps; advances the tracker.
    pub(crate) fn resolve(&mut self, ns_of_week: i64) -> GpsTime {
        let (week, _) = self.week_of(ns_of_week);
        self.week = week;
        self.last_ns_of_week = Some(ns_of_week);
        self.unconfirmed_rollover_ns = None;
        GpsTime::from_week_ns(week, ns_of_week)
    }
}

/// GNSS outages simulated by withholding fixes: windows of `len_s` every
/// `period_s`, the first starting `first_s` after the first IMU epoch.
///
/// ```
/// use navsync::GpsTime;
/// use navsync::time::OutageSchedule;
/// // 60 s outages every 180 s, the first 120 s into the run.
/// let o = OutageSchedule { period_s: 180.0, len_s: 60.0, first_s: 120.0 };
/// let t0 = GpsTime::from_week_sow(2300, 0.0);
/// assert!(!o.contains(t0, t0.add_seconds(119.9)));
/// assert!(o.contains(t0, t0.add_seconds(150.0)));
/// assert!(!o.contains(t0, t0.add_seconds(180.0)));
/// assert!(o.contains(t0, t0.add_seconds(300.0)));
/// assert_eq!(o.windows(t0, t0.add_seconds(600.0)).len(), 3);
/// ```
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub struct OutageSchedule {
    /// Interval (s) from the start of one outage to the start of the next.
    pub period_s: f64,
    /// Length of each outage (s); an outage covers `[start, start + len_s)`.
    pub len_s: f64,
    /// Start of the first outage (s after the first IMU epoch).
    pub first_s: f64,
}

impl OutageSchedule {
    /// True when `t` falls inside an outage that starts from `t0`.
    pub fn contains(&self, t0: GpsTime, t: GpsTime) -> bool {
        let rel = t.seconds_since(t0) - self.first_s;
        if rel < 0.0 {
            return false;
        }
        let k = (rel / self.period_s).floor();
        rel - k * self.period_s < self.len_s
    }

    /// Checks 0 < length < period and first ≥ 0.
    pub fn validate(&self) -> Result<(), String> {
        let ok = self.period_s.is_finite()
            && self.len_s > 0.0
            && self.len_s < self.period_s
            && self.first_s.is_finite()
            && self.first_s >= 0.0;
        if ok {
            Ok(())
        } else {
            Err(format!(
                "outages need 0 < length ({} s) < period ({} s) and first start ({} s) >= 0",
                self.len_s, self.period_s, self.first_s
            ))
        }
    }

    /// The outage windows inside `[t0, t1]`.
    pub fn windows(&self, t0: GpsTime, t1: GpsTime) -> Vec<OutageWindow> {
        let mut out = Vec::new();
        let mut s = self.first_s;
        let span = t1.seconds_since(t0);
        while s < span {
            out.push(OutageWindow::new(
                t0.add_seconds(s),
                self.len_s.min(span - s),
            ));
            s += self.period_s;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn week_and_sow_round_trip() {
        let t = GpsTime::from_week_sow(2300, 100000.005);
        assert_eq!(t.week(), 2300);
        assert_eq!(t.ns_of_week(), 100_000_005_000_000);
        assert!((t.sow() - 100000.005).abs() < 1e-10);
        assert_eq!(t.to_string(), "2300 100000.005000000");
        let mut s = Vec::new();
        t.write_sow(&mut s);
        assert_eq!(std::str::from_utf8(&s).unwrap(), "100000.005000000");
    }

    #[test]
    fn differences_are_exact() {
        let a = GpsTime::from_week_sow(2300, 100000.005);
        let b = GpsTime::from_week_sow(2300, 100000.010);
        assert_eq!(b - a, 5_000_000);
        assert_eq!(b.seconds_since(a), 0.005);
    }

    #[test]
    fn negative_time_normalises_week() {
        let t = GpsTime::from_ns(-1);
        assert_eq!(t.week(), -1);
        assert_eq!(t.ns_of_week(), NS_PER_WEEK - 1);
    }

    #[test]
    fn week_tracker_handles_rollover() {
        let mut w = WeekTracker::new(2300);
        let a = w.resolve(604_799_990_000_000);
        let b = w.resolve(5_000_000);
        assert_eq!(a.week(), 2300);
        assert_eq!(b.week(), 2301);
        assert_eq!(b - a, 15_000_000);
        // a small step back (bad data) does not invent a week
        let c = w.resolve(1_000_000);
        assert_eq!(c.week(), 2301);
    }

    #[test]
    fn one_corrupt_mid_week_line_is_not_a_rollover_but_a_long_gap_across_one_is() {
        const S: i64 = NS_PER_S;
        let mut w = WeekTracker::new(2300);
        w.peek(500_000 * S);
        w.resolve(500_000 * S);
        // A corrupt SOW of 12 s: far back, and as a rollover a 29 h step.
        let corrupt = w.peek(12 * S);
        assert_eq!(corrupt.week(), 2300, "read as going backwards");
        // The reader skips it; the file goes on in the same week.
        let next = w.peek(500_001 * S);
        assert_eq!(next.week(), 2300);
        assert_eq!(w.resolve(500_001 * S).week(), 2300);

        // A logger that stopped 2 h before the week's end and resumed 1 h
        // into the next: the first line back cannot be told from a corrupt
        // one; the second, within ten minutes of it, confirms the new week.
        let mut w = WeekTracker::new(2300);
        w.peek((SECONDS_PER_WEEK - 7200) * S);
        w.resolve((SECONDS_PER_WEEK - 7200) * S);
        assert_eq!(w.peek(3600 * S).week(), 2300);
        assert_eq!(w.peek(3601 * S).week(), 2301);
        assert_eq!(w.resolve(3601 * S).week(), 2301);
        assert_eq!(w.peek(3602 * S).week(), 2301);

        // Within ten minutes a rollover needs no confirmation.
        let mut w = WeekTracker::new(2300);
        w.resolve((SECONDS_PER_WEEK - 300) * S);
        assert_eq!(w.peek(290 * S).week(), 2301);
        assert_eq!(w.resolve(290 * S).week(), 2301);
    }
}
