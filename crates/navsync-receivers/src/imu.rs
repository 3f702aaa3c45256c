//! IMU samples from receivers and rate-form logs, turned into the increments
//! the mechanization needs.
//!
//! Seed 001 §1.1: a rate-output IMU's increment over an interval is the mean
//! of the two bounding rate samples times the interval (trapezoid rule):
//! Δθ_k = ½(ω_{k−1} + ω_k)(t_k − t_{k−1}), Δv_k = ½(f_{k−1} + f_k)(t_k − t_{k−1}),
//! stamped at t_k (FORMATS.md §1: the increments over the interval that ends
//! at `sow`). Seed 001 §1.5 point 5: gaps of 0.1 s or more must be flagged.

use nalgebra::Vector3;
use navsync::imu::convert::{RateRule, rate_increment};
use navsync::ins::ImuSample;
use navsync::time::GpsTime;

use crate::ubx::{EsfMeas, EsfRaw, EsfValue};

/// One rate-form sample: angular rate (rad/s) and specific force (m/s²).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RateSample {
    pub time: GpsTime,
    pub gyro_radps: Vector3<f64>,
    pub accel_mps2: Vector3<f64>,
}

/// What [`RateToIncrement::push`] noticed about a sample.
#[derive(Clone, Debug, PartialEq)]
pub enum RateIssue {
    /// Time did not increase: the sample was dropped.
    NotIncreasing { time: GpsTime, previous: GpsTime },
    /// The interval ending at `time` is at least the gap threshold
    /// (increment still formed, and flagged).
    Gap { time: GpsTime, dt_s: f64 },
}

/// Rate samples → increments, by the trapezoid rule (seed 001 §1.1).
#[derive(Clone, Debug)]
pub struct RateToIncrement {
    prev: Option<RateSample>,
    /// Intervals at least this long are reported (seed 001 §1.5: 0.1 s).
    pub gap_threshold_s: f64,
}

impl Default for RateToIncrement {
    fn default() -> Self {
        RateToIncrement {
            prev: None,
            gap_threshold_s: 0.1,
        }
    }
}

impl RateToIncrement {
    pub fn new(gap_threshold_s: f64) -> Self {
        RateToIncrement {
            prev: None,
            gap_threshold_s,
        }
    }

    /// The increment over the interval ending at `s` (none for the first
    /// sample), and anything to report.
    pub fn push(&mut self, s: RateSample) -> (Option<ImuSample>, Option<RateIssue>) {
        let Some(p) = self.prev else {
            self.prev = Some(s);
            return (None, None);
        };
        if s.time <= p.time {
            return (
                None,
                Some(RateIssue::NotIncreasing {
                    time: s.time,
                    previous: p.time,
                }),
            );
        }
        let dt = s.time.seconds_since(p.time);
        self.prev = Some(s);
        let (dtheta, dvel) = rate_increment(
            RateRule::Trapezoid,
            &p.gyro_radps,
            &p.accel_mps2,
            &s.gyro_radps,
            &s.accel_mps2,
            dt,
        );
        let issue = (dt >= self.gap_threshold_s).then_some(RateIssue::Gap {
            time: s.time,
            dt_s: dt,
        });
        (
            Some(ImuSample {
                time: s.time,
                dtheta,
                dvel,
                odo_speed: None,
            }),
            issue,
        )
    }
}

/// Unwraps a wrapping 32-bit sensor time tag into a monotonic count.
#[derive(Clone, Debug, Default)]
pub(crate) struct TagUnwrapper {
    last: Option<u32>,
    high: u64,
}

impl TagUnwrapper {
    /// Forward steps below 2³¹ ticks are progress; a larger step is taken
    /// as going back (it stays put, the caller sees time not increasing).
    pub(crate) fn unwrap(&mut self, tag: u32) -> u64 {
        if let Some(last) = self.last
            && tag < last
            && last - tag > 1 << 31
        {
            self.high += 1 << 32;
        }
        self.last = Some(tag);
        self.high + tag as u64
    }
}

#[derive(Copy, Clone, Debug, Default)]
struct Partial {
    tag: u64,
    v: [Option<f64>; 3],
}

impl Partial {
    fn full(&self) -> Option<Vector3<f64>> {
        Some(Vector3::new(self.v[0]?, self.v[1]?, self.v[2]?))
    }
}

/// ESF-MEAS / ESF-RAW data words → rate samples on the sensor time axis.
///
/// Gyro and accelerometer triads are gathered per time tag. When they
/// share a tag (ESF-RAW) they form a sample directly; when they do not
/// (NEO-M8L ESF-MEAS sends accelerometer and gyro sets ~5 ms apart) the
/// accelerometer triad is linearly interpolated to the gyro tag. A gyro
/// triad before the first or after the last accelerometer triad has no
/// partner and is counted in [`EsfImu::unpaired`].
#[derive(Clone, Debug)]
pub struct EsfImu {
    /// Seconds per sensor time-tag tick (ESF-MEAS: 1 ms on u-blox IMUs).
    tick_ns: f64,
    unwrap_meas: TagUnwrapper,
    unwrap_raw: TagUnwrapper,
    gyro: Partial,
    accel: Partial,
    waiting_gyro: std::collections::VecDeque<(u64, Vector3<f64>)>,
    accel_prev: Option<(u64, Vector3<f64>)>,
    accel_last: Option<(u64, Vector3<f64>)>,
    pub unpaired: usize,
    /// Time added to sensor time (ns), e.g. a known sensor→GPS offset.
    pub offset_ns: i64,
}

impl EsfImu {
    pub fn new(tick_s: f64) -> Self {
        EsfImu {
            tick_ns: tick_s * 1e9,
            unwrap_meas: TagUnwrapper::default(),
            unwrap_raw: TagUnwrapper::default(),
            gyro: Partial::default(),
            accel: Partial::default(),
            waiting_gyro: Default::default(),
            accel_prev: None,
            accel_last: None,
            unpaired: 0,
            offset_ns: 0,
        }
    }

    fn time(&self, tag: u64) -> GpsTime {
        GpsTime::from_ns((tag as f64 * self.tick_ns).round() as i64 + self.offset_ns)
    }

    pub fn push_meas(&mut self, m: &EsfMeas, out: &mut Vec<RateSample>) {
        let tag = self.unwrap_meas.unwrap(m.time_tag);
        for d in &m.data {
            self.add(tag, d.value(), out);
        }
    }

    pub fn push_raw(&mut self, m: &EsfRaw, out: &mut Vec<RateSample>) {
        for b in &m.blocks {
            let tag = self.unwrap_raw.unwrap(b.s_ttag);
            self.add(tag, b.value(), out);
        }
    }

    fn add(&mut self, tag: u64, v: EsfValue, out: &mut Vec<RateSample>) {
        let (slot, axis, x) = match v {
            EsfValue::Gyro(a, x) => (&mut self.gyro, a, x),
            EsfValue::Accel(a, x) => (&mut self.accel, a, x),
            _ => return,
        };
        if slot.tag != tag {
            *slot = Partial { tag, v: [None; 3] };
        }
        slot.v[axis] = Some(x);
        if let Some(full) = slot.full() {
            let is_gyro = matches!(v, EsfValue::Gyro(..));
            slot.v = [None; 3];
            if is_gyro {
                self.waiting_gyro.push_back((tag, full));
            } else {
                self.accel_prev = self.accel_last;
                self.accel_last = Some((tag, full));
            }
            self.pair(out);
        }
    }

    fn pair(&mut self, out: &mut Vec<RateSample>) {
        while let Some(&(tg, g)) = self.waiting_gyro.front() {
            let Some((t1, a1)) = self.accel_last else {
                return;
            };
            if tg > t1 {
                return; // wait for a later accelerometer triad
            }
            self.waiting_gyro.pop_front();
            let a = if tg == t1 {
                a1
            } else {
                match self.accel_prev {
                    Some((t0, a0)) if t0 <= tg => {
                        let w = (tg - t0) as f64 / (t1 - t0) as f64;
                        a0 + (a1 - a0) * w
                    }
                    _ => {
                        self.unpaired += 1;
                        continue;
                    }
                }
            };
            out.push(RateSample {
                time: self.time(tg),
                gyro_radps: g,
                accel_mps2: a,
            });
        }
    }

    /// End of data: gyro triads still waiting have no partner.
    pub fn finish(&mut self) {
        self.unpaired += self.waiting_gyro.len();
        self.waiting_gyro.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ubx::{EsfData, EsfRawBlock, esf_type};

    #[test]
    fn trapezoid_is_exact_for_linear_rates() {
        // ω(t) = a + b t integrates exactly under the trapezoid rule.
        let mut r = RateToIncrement::default();
        let (a, b) = (0.1, 0.02);
        let mut total = 0.0;
        for k in 0..=200 {
            let t = k as f64 * 0.005;
            let s = RateSample {
                time: GpsTime::from_seconds(100.0 + t),
                gyro_radps: Vector3::new(a + b * t, 0.0, 0.0),
                accel_mps2: Vector3::new(0.0, 0.0, -9.8),
            };
            if let (Some(inc), None) = r.push(s) {
                total += inc.dtheta.x;
                assert!((inc.dvel.z + 9.8 * 0.005).abs() < 1e-12);
            }
        }
        assert!((total - (a * 1.0 + b * 0.5)).abs() < 1e-12);
    }

    #[test]
    fn gaps_and_backward_time_are_reported() {
        let mut r = RateToIncrement::default();
        let s = |t: f64| RateSample {
            time: GpsTime::from_seconds(t),
            gyro_radps: Vector3::zeros(),
            accel_mps2: Vector3::zeros(),
        };
        r.push(s(1.0));
        assert!(matches!(r.push(s(1.2)).1, Some(RateIssue::Gap { .. })));
        assert!(matches!(
            r.push(s(1.1)),
            (None, Some(RateIssue::NotIncreasing { .. }))
        ));
        assert!(matches!(r.push(s(1.21)), (Some(_), None)));
    }

    #[test]
    fn esf_meas_accel_is_interpolated_to_gyro_tags() {
        let mut e = EsfImu::new(1e-3);
        let mut out = Vec::new();
        let acc = |t: u32, z: i32| {
            EsfMeas::new(
                t,
                0,
                vec![
                    EsfData {
                        data_type: esf_type::ACC_X,
                        field: 0,
                    },
                    EsfData {
                        data_type: esf_type::ACC_Y,
                        field: 0,
                    },
                    EsfData {
                        data_type: esf_type::ACC_Z,
                        field: (z as u32) & 0xFF_FFFF,
                    },
                ],
                None,
            )
        };
        let gyro = |t: u32| {
            EsfMeas::new(
                t,
                0,
                [esf_type::GYRO_X, esf_type::GYRO_Y, esf_type::GYRO_Z]
                    .iter()
                    .map(|&d| EsfData {
                        data_type: d,
                        field: 4096,
                    })
                    .collect(),
                None,
            )
        };
        e.push_meas(&gyro(995), &mut out); // before any accel: unpaired
        e.push_meas(&acc(1000, 1024), &mut out);
        e.push_meas(&gyro(1005), &mut out);
        assert!(out.is_empty());
        e.push_meas(&acc(1010, -1024), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].time, GpsTime::from_ns(1_005_000_000));
        assert!(out[0].accel_mps2.z.abs() < 1e-12); // midway between +1 and −1
        assert!((out[0].gyro_radps.x - 1f64.to_radians()).abs() < 1e-15);
        e.finish();
        assert_eq!(e.unpaired, 1);
    }

    #[test]
    fn esf_raw_shares_tags_and_unwraps() {
        let mut e = EsfImu::new(1e-3);
        let mut out = Vec::new();
        for tag in [u32::MAX - 4, 5] {
            let blocks = esf_type::IMU6
                .iter()
                .map(|&d| EsfRawBlock {
                    data_type: d,
                    field: 1,
                    s_ttag: tag,
                })
                .collect();
            e.push_raw(
                &EsfRaw {
                    reserved1: [0; 4],
                    blocks,
                },
                &mut out,
            );
        }
        assert_eq!(out.len(), 2);
        assert_eq!(out[1].time - out[0].time, 10_000_000);
    }
}
