//! IMU sample timing: lost and duplicated samples, samples per PPS second
//! (seed 002: a counter of IMU samples reset at every 1PPS), the IMU's true
//! rate, and the rate → increment conversion (seed 001 §1.1).

use std::collections::{BTreeMap, VecDeque};

use nalgebra::Vector3;

use super::fit::median;
use crate::io::riglog::ImuKind;
use crate::time::{GpsTime, NS_PER_S};
use crate::types::ImuSample;

/// What the timing found about one IMU record.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ImuFlags {
    /// The same sample again (counter within half a period of the previous
    /// one, or identical values in software sync): not integrated.
    pub duplicate: bool,
    /// Samples missing just before this one (flagged, never bridged silently).
    pub lost_before: u32,
    /// The interval to the previous sample is not a whole number of periods.
    pub irregular: bool,
    /// Stamped while the clock was in holdover.
    pub holdover: bool,
    /// Stamped before the clock first locked (extrapolated backwards).
    pub(crate) before_lock: bool,
    /// No usable counter (corrupt): no time, not integrated.
    pub unstamped: bool,
    /// Receive-time (hybrid) timing: the place of a loss next to this
    /// sample was not certain; its stamp may be one period off.
    pub ambiguous: bool,
}

/// A gap in the IMU stream.
#[derive(Copy, Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ImuGap {
    /// Index (0-based among `imu` records) of the sample after the gap.
    pub record: u64,
    /// Samples lost.
    pub lost: u32,
}

/// Classifies IMU records by their counter spacing (hardware timing) or by
/// their values (software timing, where receive jitter may exceed a period).
#[derive(Clone, Debug)]
pub(crate) struct ImuTracker {
    period_ticks: Option<f64>,
    deltas: VecDeque<f64>,
    prev_counter: Option<u64>,
    prev_values: Option<[f64; 6]>,
    pub lost: u64,
    pub(crate) duplicated: u64,
    pub(crate) irregular: u64,
    pub gaps: Vec<ImuGap>,
    pub(crate) gaps_total: u64,
    since_update: u32,
}

impl ImuTracker {
    /// `nominal_period_ticks` from the header's `imu_rate_hz`, if any.
    pub(crate) fn new(nominal_period_ticks: Option<f64>) -> Self {
        ImuTracker {
            period_ticks: nominal_period_ticks,
            deltas: VecDeque::with_capacity(16),
            prev_counter: None,
            prev_values: None,
            lost: 0,
            duplicated: 0,
            irregular: 0,
            gaps: Vec::new(),
            gaps_total: 0,
            since_update: 0,
        }
    }

    /// Hardware-timed record `seq` latched at unwrapped `counter`.
    pub(crate) fn classify_hw(&mut self, seq: u64, counter: u64, values: &[f64; 6]) -> ImuFlags {
        let mut f = ImuFlags::default();
        let Some(prev) = self.prev_counter else {
            self.prev_counter = Some(counter);
            self.prev_values = Some(*values);
            return f;
        };
        let d = counter as f64 - prev as f64;
        match self.period_ticks {
            Some(p) if d < 0.5 * p => {
                f.duplicate = true;
                self.duplicated += 1;
                return f;
            }
            None if d <= 0.0 => {
                f.duplicate = true;
                self.duplicated += 1;
                return f;
            }
            _ => {}
        }
        if let Some(p) = self.period_ticks {
            let m = (d / p).round().max(1.0);
            if (d / p - m).abs() > 0.25 {
                f.irregular = true;
                self.irregular += 1;
            }
            if m >= 2.0 {
                let lost = (m - 1.0).min(u32::MAX as f64) as u32;
                f.lost_before = lost;
                self.lost += lost as u64;
                self.gaps_total += 1;
                if self.gaps.len() < 1000 {
                    self.gaps.push(ImuGap { record: seq, lost });
                }
            } else {
                self.track_period(d);
            }
        } else {
            self.track_period(d);
        }
        self.prev_counter = Some(counter);
        self.prev_values = Some(*values);
        f
    }

    fn track_period(&mut self, d: f64) {
        self.deltas.push_back(d);
        if self.deltas.len() > 15 {
            self.deltas.pop_front();
        }
        self.since_update += 1;
        // The period drifts slowly (ppm): a median every 16 samples suffices.
        if self.deltas.len() >= 5 && (self.period_ticks.is_none() || self.since_update >= 16) {
            self.since_update = 0;
            let mut v: Vec<f64> = self.deltas.iter().copied().collect();
            let m = median(&mut v);
            // Accept the running median once it agrees with the nominal
            // period (or there is none); a badly wrong header rate is
            // replaced as soon as the median is stable.
            self.period_ticks = Some(m);
        }
    }

    /// Software-timed record: duplicates by identical values; losses are
    /// decided by the software clock fit.
    pub(crate) fn classify_sw(&mut self, values: &[f64; 6]) -> ImuFlags {
        let mut f = ImuFlags::default();
        if self.prev_values.as_ref() == Some(values) {
            f.duplicate = true;
            self.duplicated += 1;
            return f;
        }
        self.prev_values = Some(*values);
        f
    }

    /// Records a loss found by the software clock fit.
    pub(crate) fn note_lost(&mut self, seq: u64, lost: u32) {
        self.lost += lost as u64;
        self.gaps_total += 1;
        if self.gaps.len() < 1000 {
            self.gaps.push(ImuGap { record: seq, lost });
        }
    }
}

/// The IMU's true rate (a regression of stamps on sample index, lost
/// samples counted) and the number of samples in each GPS second.
#[derive(Clone, Debug, Default)]
pub(crate) struct RateEstimator {
    n: f64,
    mean_k: f64,
    mean_t: f64,
    ckk: f64,
    ckt: f64,
    t0: Option<GpsTime>,
    last: Option<GpsTime>,
    index: u64,
    current_second: Option<i64>,
    current_count: u32,
    first_second: Option<i64>,
    /// Samples per GPS second → number of such seconds.
    pub(crate) per_second: BTreeMap<u32, u64>,
    /// Seconds whose count differs from the most common one (first 100).
    pub(crate) odd_seconds: Vec<(i64, u32)>,
}

impl RateEstimator {
    /// A stamped, non-duplicate sample; `lost_before` samples were missing.
    pub(crate) fn push(&mut self, time: GpsTime, lost_before: u32) {
        self.index += lost_before as u64;
        let t0 = *self.t0.get_or_insert(time);
        self.last = Some(time);
        let k = self.index as f64;
        let t = time.seconds_since(t0);
        self.n += 1.0;
        let dk = k - self.mean_k;
        self.mean_k += dk / self.n;
        self.mean_t += (t - self.mean_t) / self.n;
        self.ckk += dk * (k - self.mean_k);
        self.ckt += dk * (t - self.mean_t);
        self.index += 1;
        let sec = time.ns().div_euclid(NS_PER_S);
        match self.current_second {
            Some(s) if s == sec => self.current_count += 1,
            Some(s) => {
                if self.first_second.is_some_and(|f| f != s) {
                    *self.per_second.entry(self.current_count).or_default() += 1;
                    self.odd_seconds.push((s, self.current_count));
                } else if self.first_second.is_none() {
                    self.first_second = Some(s);
                }
                // seconds without any sample
                for _ in s + 1..sec {
                    *self.per_second.entry(0).or_default() += 1;
                }
                self.current_second = Some(sec);
                self.current_count = 1;
            }
            None => {
                self.current_second = Some(sec);
                self.first_second = Some(sec);
                self.current_count = 1;
            }
        }
        if self.odd_seconds.len() > 4096 {
            self.compact_odd();
        }
    }

    fn compact_odd(&mut self) {
        let mode = self.mode();
        self.odd_seconds
            .retain(|&(_, c)| Some(c) != mode && c.abs_diff(mode.unwrap_or(c)) > 1);
        self.odd_seconds.truncate(100);
    }

    /// The most common count per second.
    pub(crate) fn mode(&self) -> Option<u32> {
        self.per_second
            .iter()
            .max_by_key(|(_, n)| **n)
            .map(|(c, _)| *c)
    }

    /// Seconds whose count differs from the most common one by more than
    /// one (a rate that is not an integer makes ±1 normal).
    pub(crate) fn odd(&mut self) -> Vec<(i64, u32)> {
        self.compact_odd();
        self.odd_seconds.clone()
    }

    /// Mean rate over the run (Hz): sample periods elapsed (lost ones
    /// counted) over the time from the first to the last stamp.
    pub(crate) fn rate_hz(&self) -> Option<f64> {
        let span = self.last?.seconds_since(self.t0?);
        (self.n >= 3.0 && span > 0.0).then(|| (self.index - 1) as f64 / span)
    }

    /// Rate from the least-squares slope of stamps on sample index (Hz):
    /// weights the middle of the run; differs from the mean rate when the
    /// IMU clock drifts.
    pub(crate) fn rate_ls_hz(&self) -> Option<f64> {
        (self.n >= 3.0 && self.ckk > 0.0 && self.ckt > 0.0).then(|| self.ckk / self.ckt)
    }
}

/// Streaming conversion of stamped IMU records to KF-GINS increments over
/// (t_{k−1}, t_k], stamped t_k: rates by the trapezoid of consecutive
/// samples times the interval (seed 001 §1.1), increments passed through.
#[derive(Clone, Debug)]
pub struct IncrementBuilder {
    kind: ImuKind,
    rule: RateRule,
    prev: Option<(GpsTime, [f64; 6])>,
}

pub use crate::imu::convert::RateRule;
use crate::imu::convert::rate_increment;

impl RateRule {
    /// The rule a rig log's header asks for: its `imu_rates`, else
    /// instantaneous samples (seed 001 §1.1's trapezoid).
    pub(crate) fn for_header(header: &crate::io::riglog::RigHeader) -> Self {
        match header.imu_rates {
            Some(crate::io::riglog::RateSampling::IntervalAverage) => RateRule::Average,
            _ => RateRule::Trapezoid,
        }
    }
}

impl IncrementBuilder {
    /// A builder for IMU values of this kind.
    pub fn new(kind: ImuKind) -> Self {
        Self::with_rule(kind, RateRule::Trapezoid)
    }

    pub(crate) fn with_rule(kind: ImuKind, rule: RateRule) -> Self {
        IncrementBuilder {
            kind,
            rule,
            prev: None,
        }
    }

    /// The increment ending at this sample, if any (the first rate sample
    /// has none; duplicates and unstamped records are skipped).
    pub fn push(
        &mut self,
        time: GpsTime,
        values: &[f64; 6],
        flags: &ImuFlags,
    ) -> Option<ImuSample> {
        if flags.duplicate || flags.unstamped {
            return None;
        }
        match self.kind {
            ImuKind::Increment => {
                if self.prev.is_some_and(|(t, _)| time <= t) {
                    return None;
                }
                self.prev = Some((time, *values));
                Some(ImuSample {
                    time,
                    dtheta: Vector3::new(values[0], values[1], values[2]),
                    dvel: Vector3::new(values[3], values[4], values[5]),
                    odo_speed: None,
                })
            }
            ImuKind::Rate => {
                let prev = self.prev.replace((time, *values));
                let (t0, v0) = prev?;
                if time <= t0 {
                    self.prev = Some((t0, v0));
                    return None;
                }
                let dt = time.seconds_since(t0);
                let v3 = |v: &[f64; 6], i: usize| Vector3::new(v[i], v[i + 1], v[i + 2]);
                let (dtheta, dvel) = rate_increment(
                    self.rule,
                    &v3(&v0, 0),
                    &v3(&v0, 3),
                    &v3(values, 0),
                    &v3(values, 3),
                    dt,
                );
                Some(ImuSample {
                    time,
                    dtheta,
                    dvel,
                    odo_speed: None,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lost_and_duplicated_samples_are_flagged() {
        let mut t = ImuTracker::new(Some(5000.0));
        let mut c = 1_000_000u64;
        let v = [0.0; 6];
        assert_eq!(t.classify_hw(0, c, &v), ImuFlags::default());
        c += 5002;
        assert_eq!(t.classify_hw(1, c, &v).lost_before, 0);
        // duplicate line (same counter)
        assert!(t.classify_hw(2, c, &v).duplicate);
        c += 3 * 5002;
        let f = t.classify_hw(3, c, &v);
        assert_eq!(f.lost_before, 2);
        assert!(!f.irregular);
        c += 7000;
        assert!(t.classify_hw(4, c, &v).irregular);
        assert_eq!((t.lost, t.duplicated, t.irregular), (2, 1, 1));
        assert_eq!(t.gaps[0].record, 3);
    }

    #[test]
    fn trapezoid_of_rates_and_pass_through_of_increments() {
        let mut b = IncrementBuilder::new(ImuKind::Rate);
        let t0 = GpsTime::from_week_sow(2300, 100.0);
        let f = ImuFlags::default();
        assert!(b.push(t0, &[1.0, 0.0, 0.0, 2.0, 0.0, 0.0], &f).is_none());
        let s = b
            .push(t0 + 5_000_000, &[3.0, 0.0, 0.0, 4.0, 0.0, 0.0], &f)
            .unwrap();
        // (1 + 3)/2 · 0.005 = 0.01; (2 + 4)/2 · 0.005 = 0.015
        assert!((s.dtheta.x - 0.01).abs() < 1e-15);
        assert!((s.dvel.x - 0.015).abs() < 1e-15);
        let mut b = IncrementBuilder::new(ImuKind::Increment);
        let s = b.push(t0, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &f).unwrap();
        assert_eq!(s.dvel.z, 6.0);
    }

    #[test]
    fn rate_and_per_second_counts() {
        let mut r = RateEstimator::default();
        let period_ns = 5_002_000i64; // 199.92 Hz
        let t0 = GpsTime::from_week_sow(2300, 100.0);
        for k in 0..2000i64 {
            if k == 1000 {
                continue; // a lost sample
            }
            r.push(t0 + k * period_ns + 123, u32::from(k == 1001));
        }
        assert!((r.rate_hz().unwrap() - 1e9 / period_ns as f64).abs() < 1e-9);
        // 199.92 Hz: most seconds hold 200 samples, some 199.
        let mode = r.mode().unwrap();
        assert!(mode == 200 || mode == 199, "{:?}", r.per_second);
    }
}
