//! Physical plausibility of input values, and a one-record lookahead
//! against a time that jumps (issue 32, "nothing silent"): a value no
//! sensor or vehicle can produce is one bad record (reported with its file
//! and line, skipped), never data, and a time that jumps is the new present
//! only once the next record goes on from it.
//!
//! The limits are generous on purpose: they catch corruption (1e20, 1e308,
//! a garbled digit), not dynamics. [`MAX_RATE_RAD_S`] (50 rad/s ≈ 2 865 °/s)
//! is above the ±2 000 °/s of the widest MEMS gyro ranges (e.g. Analog
//! Devices ADIS16465-3 data sheet, Table 1) and [`MAX_ACCEL_MPS2`]
//! (1 000 m/s² ≈ 100 g) above the ±40 g of the widest accelerometers
//! (ADIS16465-3: ±40 g, the same table).
#![warn(missing_docs)]

use std::path::Path;

use nalgebra::Vector3;

use crate::error::{Diagnostics, Error};
use crate::time::GpsTime;

/// Largest plausible angular rate (rad/s), see the module docs.
pub const MAX_RATE_RAD_S: f64 = 50.0;
/// Largest plausible specific force (m/s²), see the module docs.
pub const MAX_ACCEL_MPS2: f64 = 1000.0;
/// Lowest plausible ellipsoidal height (m): below the Dead Sea shore
/// (−430 m) with room for the geoid (±110 m) and mines.
pub const MIN_HEIGHT_M: f64 = -1000.0;
/// Highest plausible ellipsoidal height (m): the Kármán line.
pub const MAX_HEIGHT_M: f64 = 100_000.0;
/// Largest plausible speed (m/s): a jet's, three times a car's record.
pub const MAX_SPEED_MPS: f64 = 1000.0;

/// Why a pair of IMU increments over `dt_s` is implausible, if it is:
/// the rate it implies exceeds [`MAX_RATE_RAD_S`] or [`MAX_ACCEL_MPS2`].
pub fn increment_problem(dtheta: &Vector3<f64>, dvel: &Vector3<f64>, dt_s: f64) -> Option<String> {
    let dt = dt_s.max(1e-6);
    rate_problem(&(dtheta / dt), &(dvel / dt))
        .map(|why| format!("{why} (increments over {dt_s:.6} s)"))
}

/// Why an angular rate (rad/s) and a specific force (m/s²) are
/// implausible, if they are.
pub fn rate_problem(gyro: &Vector3<f64>, accel: &Vector3<f64>) -> Option<String> {
    let max_abs = |v: &Vector3<f64>| {
        if v.iter().all(|x| x.is_finite()) {
            v.amax()
        } else {
            f64::INFINITY
        }
    };
    let (w, f) = (max_abs(gyro), max_abs(accel));
    if w.is_nan() || w > MAX_RATE_RAD_S {
        return Some(format!(
            "angular rate {w:e} rad/s exceeds the plausible {MAX_RATE_RAD_S} rad/s"
        ));
    }
    if f.is_nan() || f > MAX_ACCEL_MPS2 {
        return Some(format!(
            "specific force {f:e} m/s² exceeds the plausible {MAX_ACCEL_MPS2} m/s²"
        ));
    }
    None
}

/// Why a geodetic position is not on the earth, if it is not: |lat| ≤ 90°,
/// −180° ≤ lon ≤ 360° (0…360° is a common notation), height within
/// [`MIN_HEIGHT_M`] … [`MAX_HEIGHT_M`].
pub fn position_problem(lat_deg: f64, lon_deg: f64, h_m: f64) -> Option<String> {
    if !(-90.0..=90.0).contains(&lat_deg) || !(-180.0..=360.0).contains(&lon_deg) {
        return Some(format!(
            "latitude {}° / longitude {}° is not on the earth",
            short(lat_deg),
            short(lon_deg)
        ));
    }
    if !((MIN_HEIGHT_M..=MAX_HEIGHT_M).contains(&h_m)) {
        return Some(format!(
            "height {} m is outside the plausible {MIN_HEIGHT_M} … {MAX_HEIGHT_M} m",
            short(h_m)
        ));
    }
    None
}

/// A value for a message: plain, or in exponent form when huge.
fn short(x: f64) -> String {
    if x.abs() < 1e9 {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Why a velocity (m/s) is implausible, if it is.
pub fn velocity_problem(vel: &[f64; 3]) -> Option<String> {
    let v = vel.iter().map(|x| x * x).sum::<f64>().sqrt();
    (v.is_nan() || v > MAX_SPEED_MPS)
        .then(|| format!("speed {v:e} m/s exceeds the plausible {MAX_SPEED_MPS} m/s"))
}

/// Why a set of standard deviations is unusable, if it is: each must be
/// finite and positive.
pub fn sd_problem(what: &str, sd: &[f64]) -> Option<String> {
    (!sd.iter().all(|s| s.is_finite() && *s > 0.0))
        .then(|| format!("{what} standard deviation {sd:?} is not finite and positive"))
}

/// The last record of a file, held for its jump, is kept when it steps
/// forward by at most this many times the step limit…
pub(crate) const END_STEP_FACTOR: i64 = 10;
/// …or this many seconds, whichever is more.
pub(crate) const END_STEP_MIN_S: f64 = 60.0;

/// A parsed record with its time and line, as the [`TimeGuard`] holds it.
#[derive(Clone, Debug)]
pub(crate) struct Timed<T> {
    /// The record.
    pub rec: T,
    /// Its time as the line gives it (seconds of week, ns), for the week
    /// tracker.
    pub ns: i64,
    /// Its absolute time.
    pub time: GpsTime,
    /// 1-based line number.
    pub line: usize,
}

/// What a new record would follow, for checks that need the interval to
/// its predecessor (IMU increments → rates): the last record kept, or the
/// record held for its jump, which a later record confirms.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Preceding {
    /// Time of the last record kept.
    pub last: Option<GpsTime>,
    /// Time of the record held for its jump, if any.
    pub held: Option<GpsTime>,
}

impl Preceding {
    /// The time of the record a record at `t` follows if it is kept: the
    /// held one when `t` is after it (`t` confirms it), else the last kept
    /// one; `None` for the file's first record (or one out of order, which
    /// the guard reports).
    pub fn before(&self, t: GpsTime) -> Option<GpsTime> {
        match (self.held, self.last) {
            (Some(h), _) if t > h => Some(h),
            (_, Some(l)) if t > l => Some(l),
            _ => None,
        }
    }
}

/// One-record lookahead against a time that jumps: a record whose time
/// steps more than `max_step_ns` past the last kept one (or the first
/// record of the file) is held until the next record says whether it is
/// the new present (the next goes on after it: kept) or one corrupt line
/// (the next falls between the last kept and it: reported and skipped). A
/// real gap thus costs nothing and a corrupt time only its own line — the
/// idea of `WeekTracker`'s unconfirmed rollover (`crate::time`), for any
/// jump. Records going backwards or repeating a time are skipped as before.
#[derive(Debug)]
pub(crate) struct TimeGuard<T> {
    max_step_ns: i64,
    last: Option<GpsTime>,
    pending: Option<Timed<T>>,
    ready: Option<Timed<T>>,
}

impl<T> TimeGuard<T> {
    /// Steps up to `max_step_s` are kept at once.
    pub fn new(max_step_s: f64) -> Self {
        TimeGuard {
            max_step_ns: crate::time::seconds_to_ns(max_step_s),
            last: None,
            pending: None,
            ready: None,
        }
    }

    /// Time of the record after the last one returned, when the guard
    /// already holds it (the one that confirmed a held record).
    pub fn following(&self) -> Option<GpsTime> {
        self.ready
            .as_ref()
            .or(self.pending.as_ref())
            .map(|r| r.time)
    }

    /// A record confirmed by the last offer, to be returned before reading
    /// on.
    pub fn take_ready(&mut self) -> Option<Timed<T>> {
        let r = self.ready.take()?;
        self.last = Some(r.time);
        Some(r)
    }

    fn jumps(&self, c: &Timed<T>) -> bool {
        self.last
            .is_none_or(|l| c.time - l > self.max_step_ns || c.time < l)
    }

    /// Offers the next parsed record; returns the one to keep now, if any.
    pub fn offer(&mut self, c: Timed<T>, path: &Path, diag: &mut Diagnostics) -> Option<Timed<T>> {
        if let Some(p) = self.pending.take() {
            if c.time > p.time {
                // Confirmed: p is the new present; c goes on from it.
                self.last = Some(p.time);
                if c.time - p.time > self.max_step_ns {
                    self.pending = Some(c);
                } else {
                    self.ready = Some(c);
                }
                return Some(p);
            }
            if c.time == p.time {
                diag.push(
                    path,
                    c.line,
                    format!("duplicate epoch {}; line skipped", c.time),
                );
                self.pending = Some(p);
                return None;
            }
            if self.last.is_some_and(|l| c.time <= l) {
                let why = super::text::time_order_problem(self.last, c.time).unwrap_or_default();
                diag.push(path, c.line, format!("{why}; line skipped"));
                self.pending = Some(p);
                return None;
            }
            // c falls between the last kept record and p: p was the bad one.
            let ahead = match self.last {
                Some(l) => format!(
                    "jumps {} s ahead of the line before",
                    p.time.seconds_since(l)
                ),
                None => "is the file's first".to_string(),
            };
            diag.push(
                path,
                p.line,
                format!(
                    "time {} {ahead} and the next line ({}, {}) does not go on from it; line skipped",
                    p.time, c.line, c.time
                ),
            );
        }
        if let Some(why) = super::text::time_order_problem(self.last, c.time) {
            diag.push(path, c.line, format!("{why}; line skipped"));
            return None;
        }
        if self.jumps(&c) {
            self.pending = Some(c);
            return None;
        }
        self.last = Some(c.time);
        Some(c)
    }

    /// The next record to keep, or `None` at the end: the one driver loop
    /// of every reader. `parse` gives the next record that parses and is
    /// plausible on its own (it gets what the record would follow, for
    /// checks on the interval), `None` at the end of the file; each goes
    /// through [`Self::offer`], the end through [`Self::finish`].
    pub fn next(
        &mut self,
        path: &Path,
        diag: &mut Diagnostics,
        mut parse: impl FnMut(Preceding, &mut Diagnostics) -> Result<Option<Timed<T>>, Error>,
    ) -> Result<Option<Timed<T>>, Error> {
        loop {
            if let Some(r) = self.take_ready() {
                return Ok(Some(r));
            }
            let prev = Preceding {
                last: self.last,
                held: self.pending.as_ref().map(|p| p.time),
            };
            let Some(c) = parse(prev, diag)? else {
                return Ok(self.finish(path, diag));
            };
            if let Some(r) = self.offer(c, path, diag) {
                return Ok(Some(r));
            }
        }
    }

    /// At the end of the file: a held record is kept when it is the only
    /// one (nothing contradicts it) or when it steps forward by no more
    /// than [`END_STEP_FACTOR`] × the step limit, at least
    /// [`END_STEP_MIN_S`] (a last fix after a short outage is not a
    /// corrupt line); otherwise reported and skipped (no line confirms its
    /// jump).
    pub fn finish(&mut self, path: &Path, diag: &mut Diagnostics) -> Option<Timed<T>> {
        if let Some(r) = self.take_ready() {
            return Some(r);
        }
        let p = self.pending.take()?;
        let end_limit_ns = (self.max_step_ns.saturating_mul(END_STEP_FACTOR))
            .max(crate::time::seconds_to_ns(END_STEP_MIN_S));
        match self.last {
            None => {
                self.last = Some(p.time);
                Some(p)
            }
            Some(l) if p.time > l && p.time - l <= end_limit_ns => {
                self.last = Some(p.time);
                Some(p)
            }
            Some(l) => {
                diag.push(
                    path,
                    p.line,
                    format!(
                        "time {} jumps {} s ahead of the line before and no line follows to confirm it; line skipped",
                        p.time,
                        p.time.seconds_since(l)
                    ),
                );
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(times_s: &[f64], max_step_s: f64) -> (Vec<usize>, Diagnostics) {
        let mut g = TimeGuard::new(max_step_s);
        let mut d = Diagnostics::default();
        let mut kept = Vec::new();
        let path = Path::new("t.txt");
        for (k, &t) in times_s.iter().enumerate() {
            if let Some(r) = g.take_ready() {
                kept.push(r.line);
            }
            let ns = crate::time::seconds_to_ns(t);
            let c = Timed {
                rec: (),
                ns,
                time: GpsTime::from_ns(ns),
                line: k + 1,
            };
            if let Some(r) = g.offer(c, path, &mut d) {
                kept.push(r.line);
            }
        }
        while let Some(r) = g.finish(path, &mut d) {
            kept.push(r.line);
        }
        (kept, d)
    }

    #[test]
    fn a_corrupt_time_costs_its_own_line_and_a_real_gap_nothing() {
        // Line 3 jumps 1e6 s ahead (corrupt); line 6 starts a real 60 s gap.
        let t = [1.0, 1.005, 1e6, 1.010, 1.015, 61.015, 61.020, 61.025];
        let (kept, d) = run(&t, 0.05);
        assert_eq!(kept, vec![1, 2, 4, 5, 6, 7, 8]);
        assert_eq!(d.total, 1, "{d:?}");
        assert!(
            d.items[0].to_string().contains("t.txt:3: time"),
            "{:?}",
            d.items
        );
    }

    #[test]
    fn a_corrupt_first_line_and_a_corrupt_last_jump_are_skipped() {
        let (kept, d) = run(&[9e5, 1.0, 1.005, 1.010, 5e5], 0.05);
        assert_eq!(kept, vec![2, 3, 4]);
        assert_eq!(d.total, 2, "{d:?}");
        assert!(
            d.items[0].to_string().contains(":1: time") && d.items[0].to_string().contains("first")
        );
        assert!(
            d.items[1].to_string().contains(":5: time")
                && d.items[1].to_string().contains("no line follows")
        );
        // A last record after a short gap (a fix after a 30 s outage) is
        // kept: up to 10 × the step limit or 60 s.
        assert_eq!(run(&[1.0, 2.0, 3.0, 33.0], 1.5).0, vec![1, 2, 3, 4]);
        assert_eq!(run(&[1.0, 2.0, 3.0, 3.0 + 61.0], 1.5).0, vec![1, 2, 3]);
        // A file of one record keeps it; backwards and repeated lines are skipped.
        assert_eq!(run(&[7.0], 0.05).0, vec![1]);
        let (kept, d) = run(&[1.0, 1.005, 1.005, 0.5, 1.010], 0.05);
        assert_eq!((kept, d.total), (vec![1, 2, 5], 2));
    }

    #[test]
    fn limits_catch_corruption_not_dynamics() {
        let z = Vector3::zeros();
        // 3 rad/s and 10 g over 5 ms: a hard manoeuvre, plausible.
        assert!(
            increment_problem(
                &Vector3::new(0.015, 0.0, 0.0),
                &Vector3::new(0.49, 0.0, 0.0),
                0.005
            )
            .is_none()
        );
        assert!(
            increment_problem(&Vector3::new(1e20, 0.0, 0.0), &z, 0.005)
                .unwrap()
                .contains("angular rate")
        );
        assert!(
            increment_problem(&z, &Vector3::new(0.0, 0.0, 6.0), 0.005)
                .unwrap()
                .contains("specific force")
        );
        assert!(rate_problem(&z, &Vector3::new(f64::NAN, 0.0, 0.0)).is_some());
        assert!(position_problem(30.0, 114.0, 20.0).is_none());
        assert!(position_problem(143_545.0, 114.0, 20.0).is_some());
        assert!(position_problem(30.0, 114.0, 1e9).is_some());
        assert!(position_problem(30.0, -181.0, 0.0).is_some());
        assert!(velocity_problem(&[30.0, 0.0, 0.0]).is_none());
        assert!(velocity_problem(&[1e5, 0.0, 0.0]).is_some());
        assert!(sd_problem("position", &[0.02, 0.0, 0.03]).is_some());
        assert!(sd_problem("position", &[0.02, 0.02, f64::INFINITY]).is_some());
        assert!(sd_problem("position", &[0.02, 0.02, 0.03]).is_none());
    }
}
