//! Rate → increment conversion (seed 001 §1.1).
//!
//! Navigation needs increments; an IMU that outputs rates is converted by
//! the trapezoid of two consecutive rate samples times their interval
//! (seed 001 §1.1: "使用前后两个IMU历元的速率测量值的平均值乘上时间间隔"):
//!
//! Δθ_k = (ω_{k−1} + ω_k)/2 · (t_k − t_{k−1}),  Δv_k = (f_{k−1} + f_k)/2 · (t_k − t_{k−1}),
//!
//! the increment over `(t_{k−1}, t_k]`, stamped `t_k`. This is exact for
//! rates linear in time and is what the ADIS16465 does internally for its
//! delta-angle output (seed 001 §1.3.1, fig. 2).
//!
//! A device that outputs rates already *averaged* over its output interval
//! (an averaging/decimating filter such as the ADIS16465 `DEC_RATE` stage)
//! gives the mean rate over `(t_{k−1}, t_k]`: its increment is ω̄_k·Δt
//! ([`RateRule::Average`]). Applying the trapezoid to such samples
//! would average two adjacent windows and delay the data by half an output
//! interval.
#![warn(missing_docs)]

use nalgebra::Vector3;
use serde::Serialize;

use super::RateSample;
use crate::types::ImuSample;

/// How rate samples become increments over (t_{k−1}, t_k]: the one rule
/// every rate path uses (files, rig logs, receivers, live).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RateRule {
    /// (ω_{k−1} + ω_k)/2 · Δt: for the rate at the time stamp (a raw or
    /// point sample; seed 001 §1.1).
    #[default]
    Trapezoid,
    /// ω_k · Δt: for rates that are already averages over the interval
    /// (an IMU's averaging decimation filter, seed 001 §1.3.1).
    Average,
}

/// The increments (Δθ, Δv) over an interval of `dt_s` that ends at the
/// sample (ω, f), the previous sample being (ω_prev, f_prev), by `rule`
/// (seed 001 §1.1 and §1.3.1).
///
/// ```
/// use nalgebra::Vector3;
/// use navsync::imu::convert::{RateRule, rate_increment};
/// // A rate rising linearly from 0.1 to 0.3 rad/s over 0.5 s turns by
/// // exactly 0.1 rad: the trapezoid is exact for linear rates.
/// let (w0, w1) = (Vector3::new(0.0, 0.0, 0.1), Vector3::new(0.0, 0.0, 0.3));
/// let f = Vector3::new(0.0, 0.0, -9.8);
/// let (dtheta, dvel) = rate_increment(RateRule::Trapezoid, &w0, &f, &w1, &f, 0.5);
/// assert!((dtheta.z - 0.1).abs() < 1e-15 && (dvel.z + 4.9).abs() < 1e-12);
/// // An interval average is the rate over its own interval.
/// let (dtheta, _) = rate_increment(RateRule::Average, &w0, &f, &w1, &f, 0.5);
/// assert!((dtheta.z - 0.15).abs() < 1e-15);
/// ```
#[inline]
pub fn rate_increment(
    rule: RateRule,
    gyro_prev: &Vector3<f64>,
    accel_prev: &Vector3<f64>,
    gyro: &Vector3<f64>,
    accel: &Vector3<f64>,
    dt_s: f64,
) -> (Vector3<f64>, Vector3<f64>) {
    match rule {
        RateRule::Trapezoid => (
            (gyro_prev + gyro) * (0.5 * dt_s),
            (accel_prev + accel) * (0.5 * dt_s),
        ),
        RateRule::Average => (gyro * dt_s, accel * dt_s),
    }
}

/// Counts of a rate-to-increment conversion.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ConvertStats {
    pub(crate) rates_in: usize,
    pub(crate) increments_out: usize,
    /// Samples whose time was not after the previous one (ignored).
    pub(crate) rejected_time: usize,
    /// Gaps longer than the bridging limit: the conversion restarted there
    /// and the gap stays visible in the output.
    pub gaps_not_bridged: usize,
}

/// Streaming rate → increment converter: push a rate sample, get the
/// increment over the interval it closes.
#[derive(Clone, Debug)]
pub struct RateToIncrement {
    kind: RateRule,
    max_bridge_ns: Option<i64>,
    prev: Option<RateSample>,
    stats: ConvertStats,
}

impl RateToIncrement {
    /// A converter for rates of `kind`. Gaps of any length are bridged
    /// (the trapezoid over the gap) until `Self::with_max_bridge` says
    /// otherwise.
    pub fn new(kind: RateRule) -> Self {
        RateToIncrement {
            kind,
            max_bridge_ns: None,
            prev: None,
            stats: ConvertStats::default(),
        }
    }

    /// Does not integrate across intervals longer than `seconds`: the
    /// sample after such a gap starts a new series (no increment is made
    /// for the gap, so it stays a gap downstream). Seed 001 §1.5 point 5
    /// calls any gap over 0.1 s a fault.
    pub(crate) fn with_max_bridge(mut self, seconds: f64) -> Self {
        self.max_bridge_ns = Some(crate::time::seconds_to_ns(seconds));
        self
    }

    /// What the conversion counted so far.
    pub fn stats(&self) -> &ConvertStats {
        &self.stats
    }

    /// The increment over `(t_prev, t]`, stamped `t`, or `None` for the
    /// first sample of a series and for a sample not after the previous.
    pub fn push(&mut self, s: &RateSample) -> Option<ImuSample> {
        self.stats.rates_in += 1;
        let Some(p) = self.prev else {
            self.prev = Some(*s);
            return None;
        };
        let dt_ns = s.time - p.time;
        if dt_ns <= 0 {
            self.stats.rejected_time += 1;
            return None;
        }
        if self.max_bridge_ns.is_some_and(|m| dt_ns > m) {
            self.stats.gaps_not_bridged += 1;
            self.prev = Some(*s);
            return None;
        }
        let dt = dt_ns as f64 * 1e-9;
        let (dtheta, dvel) = rate_increment(self.kind, &p.gyro, &p.accel, &s.gyro, &s.accel, dt);
        self.prev = Some(*s);
        self.stats.increments_out += 1;
        Some(ImuSample {
            time: s.time,
            dtheta,
            dvel,
            odo_speed: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::GpsTime;
    use nalgebra::Vector3;

    fn rate(t_s: f64, w: [f64; 3], f: [f64; 3]) -> RateSample {
        RateSample {
            time: GpsTime::from_seconds(t_s),
            gyro: Vector3::from(w),
            accel: Vector3::from(f),
        }
    }

    #[test]
    fn constant_rate_gives_rate_times_interval() {
        let mut c = RateToIncrement::new(RateRule::Trapezoid);
        assert!(
            c.push(&rate(1.0, [0.1, -0.2, 0.3], [0.0, 0.0, -9.8]))
                .is_none()
        );
        let inc = c
            .push(&rate(1.005, [0.1, -0.2, 0.3], [0.0, 0.0, -9.8]))
            .unwrap();
        assert_eq!(inc.time, GpsTime::from_seconds(1.005));
        // Exact up to rounding of 0.005 s: relative 1e-15.
        assert!((inc.dtheta - Vector3::new(0.0005, -0.001, 0.0015)).norm() < 1e-17);
        assert!((inc.dvel.z + 0.049).abs() < 1e-15);
    }

    #[test]
    fn trapezoid_is_exact_on_a_linear_ramp() {
        // ω(τ) = a + b τ, τ = t − t_base: ∫ over (τ0, τ1] = a Δτ + b (τ1² − τ0²)/2,
        // which the trapezoid reproduces exactly; irregular intervals on
        // purpose. Terms are ~1e-3, so f64 rounding stays below 1e-18.
        let (a, b) = (0.02, 0.7);
        let base_ns = 10_000_000_000i64;
        let offsets_ns = [
            0i64, 4_000_000, 10_500_000, 15_000_000, 30_100_000, 31_000_000,
        ];
        let tau = |k: usize| offsets_ns[k] as f64 * 1e-9;
        let mut c = RateToIncrement::new(RateRule::Trapezoid);
        for k in 0..offsets_ns.len() {
            let w = a + b * tau(k);
            let s = RateSample {
                time: GpsTime::from_ns(base_ns + offsets_ns[k]),
                gyro: Vector3::new(w, -w, 2.0 * w),
                accel: Vector3::new(w, 0.0, 0.0),
            };
            let out = c.push(&s);
            if k == 0 {
                assert!(out.is_none());
                continue;
            }
            let inc = out.unwrap();
            let (t0, t1) = (tau(k - 1), tau(k));
            let exact = a * (t1 - t0) + b * (t1 * t1 - t0 * t0) / 2.0;
            assert!(
                (inc.dtheta.x - exact).abs() < 1e-17,
                "{} vs {exact}",
                inc.dtheta.x
            );
            assert!((inc.dtheta.y + exact).abs() < 1e-17);
            assert!((inc.dtheta.z - 2.0 * exact).abs() < 2e-17);
            assert!((inc.dvel.x - exact).abs() < 1e-17);
        }
        assert_eq!(c.stats().increments_out, offsets_ns.len() - 1);
    }

    #[test]
    fn interval_average_uses_the_rectangle_over_its_own_interval() {
        let mut c = RateToIncrement::new(RateRule::Average);
        c.push(&rate(0.0, [1.0, 0.0, 0.0], [0.0; 3]));
        let inc = c.push(&rate(0.01, [3.0, 0.0, 0.0], [0.0; 3])).unwrap();
        assert!((inc.dtheta.x - 0.03).abs() < 1e-15);
    }

    #[test]
    fn gaps_beyond_the_bridge_limit_restart_and_bad_times_are_ignored() {
        let mut c = RateToIncrement::new(RateRule::Trapezoid).with_max_bridge(0.1);
        c.push(&rate(0.0, [1.0; 3], [0.0; 3]));
        assert!(c.push(&rate(0.005, [1.0; 3], [0.0; 3])).is_some());
        assert!(c.push(&rate(0.005, [1.0; 3], [0.0; 3])).is_none());
        assert!(c.push(&rate(0.5, [1.0; 3], [0.0; 3])).is_none());
        let inc = c.push(&rate(0.505, [1.0; 3], [0.0; 3])).unwrap();
        assert!((inc.dtheta.x - 0.005).abs() < 1e-15);
        assert_eq!(c.stats().rejected_time, 1);
        assert_eq!(c.stats().gaps_not_bridged, 1);
    }
}
