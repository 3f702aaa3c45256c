//! Lagrange interpolation of navigation states to any epoch and Lagrange
//! fractional-delay FIR filters.
//!
//! - Seed 000 eq 1: the (2n+1)-order Lagrange interpolation
//!   X(t) = Σ_{i=k−n−1}^{k+n} X(t_i) Π_{j≠i} (t − t_j)/(t_i − t_j), using the
//!   n+1 samples on each side of t (n = 0 is linear interpolation, eq 2).
//! - Seed 004 eq 18: the Lagrange fractional-delay FIR of order N,
//!   h(m) = Π_{k=0, k≠m}^{N} (D − k)/(m − k), m = 0..N, with the delay D kept
//!   in [(N−1)/2, (N+1)/2] (centred) and whole samples of delay added in
//!   front; its frequency response approximates e^{−jωD} (Laakso et al.,
//!   "Splitting the unit delay", IEEE Signal Processing Magazine 13(1), 1996).
#![warn(missing_docs)]

use std::collections::VecDeque;

use nalgebra::{UnitQuaternion, Vector3};

use crate::attitude::{quat_to_rotvec, rotvec_to_quat};
use crate::earth::Geodetic;
use crate::time::GpsTime;
use crate::types::NavState;

/// Lagrange basis weights for interpolating at `t` from samples at `ts`
/// (offsets in seconds; any spacing, all distinct).
pub(crate) fn lagrange_weights(ts: &[f64], t: f64, out: &mut [f64]) {
    for (i, w) in out.iter_mut().enumerate().take(ts.len()) {
        let mut p = 1.0;
        for (j, &tj) in ts.iter().enumerate() {
            if j != i {
                p *= (t - tj) / (ts[i] - tj);
            }
        }
        *w = p;
    }
}

/// Largest n of the (2n+1)-order interpolation: beyond it Lagrange
/// polynomials on equally spaced nodes oscillate (Runge's phenomenon) and
/// the window outgrows any sensible buffer.
pub const MAX_INTERP_N: usize = 8;

/// Interpolates navigation states to requested epochs with (2n+1)-order
/// Lagrange polynomials (seed 000 eq 1), streaming: push the solution at
/// every IMU epoch, push the requested epochs in increasing order, and get
/// each requested state once n+1 solution epochs after it have arrived.
///
/// Position and velocity components are interpolated directly; attitude
/// through rotation vectors relative to the sample nearest the epoch (so
/// no Euler-angle wrap can occur).
pub struct NavInterpolator {
    n: usize,
    window: VecDeque<NavState>,
    requests: VecDeque<GpsTime>,
    /// Requested epochs that could not be served (outside the data).
    pub skipped: usize,
}

impl NavInterpolator {
    /// `n` = 0 linear, 1 cubic, 2 quintic, … (order 2n+1).
    pub fn new(n: usize) -> Self {
        NavInterpolator {
            n,
            window: VecDeque::with_capacity(2 * n + 3),
            requests: VecDeque::new(),
            skipped: 0,
        }
    }

    /// Adds an epoch to interpolate at (must not decrease).
    pub fn request(&mut self, t: GpsTime) {
        self.requests.push_back(t);
    }

    /// Adds the solution at the next IMU epoch; returns the requested
    /// states that became computable.
    pub fn push(&mut self, nav: &NavState) -> Vec<NavState> {
        self.window.push_back(*nav);
        let need = 2 * self.n + 2;
        let mut out = Vec::new();
        while let Some(&t) = self.requests.front() {
            let first = self.window.front().map(|s| s.time).unwrap_or(t);
            if t < first {
                // Before the data (or its window already passed).
                self.requests.pop_front();
                self.skipped += 1;
                continue;
            }
            // Index of the last sample at or before t.
            let Some(k) = self.window.iter().rposition(|s| s.time <= t) else {
                break;
            };
            let after = self.window.len() - 1 - k;
            if after < self.n + 1 && !(after == 0 && self.window[k].time == t) {
                break; // wait for more samples after t
            }
            if k < self.n {
                // Not enough history: use what exists (lower order near the start).
                let lo = 0;
                let hi = (k + self.n + 1).min(self.window.len() - 1);
                out.push(interpolate(&self.window, lo, hi, t));
            } else {
                let lo = k - self.n;
                let hi = (k + self.n + 1).min(self.window.len() - 1);
                out.push(interpolate(&self.window, lo, hi, t));
            }
            self.requests.pop_front();
        }
        while self.window.len() > need + 1 {
            self.window.pop_front();
        }
        out
    }

    /// Requests still pending at the end of the data are skipped.
    pub fn finish(&mut self) {
        self.skipped += self.requests.len();
        self.requests.clear();
    }
}

fn interpolate(w: &VecDeque<NavState>, lo: usize, hi: usize, t: GpsTime) -> NavState {
    let base = w[lo].time;
    let ts: Vec<f64> = (lo..=hi).map(|i| w[i].time.seconds_since(base)).collect();
    let mut wt = vec![0.0; ts.len()];
    lagrange_weights(&ts, t.seconds_since(base), &mut wt);
    // Attitude relative to the nearest sample.
    let nearest = (lo..=hi)
        .min_by_key(|&i| (w[i].time - t).abs())
        .expect("non-empty window");
    let q_ref = w[nearest].q_nb;
    let mut lat = 0.0;
    let mut lon = 0.0;
    let mut h = 0.0;
    let mut vel = Vector3::zeros();
    let mut rv = Vector3::zeros();
    for (k, i) in (lo..=hi).enumerate() {
        let s = &w[i];
        lat += wt[k] * (s.pos.lat_rad - w[nearest].pos.lat_rad);
        lon += wt[k] * (s.pos.lon_rad - w[nearest].pos.lon_rad);
        h += wt[k] * s.pos.h_m;
        vel += wt[k] * s.vel;
        rv += wt[k] * quat_to_rotvec(&(q_ref.inverse() * s.q_nb));
    }
    NavState {
        time: t,
        pos: Geodetic::new(
            w[nearest].pos.lat_rad + lat,
            w[nearest].pos.lon_rad + lon,
            h,
        ),
        vel,
        q_nb: UnitQuaternion::new_normalize((q_ref * rotvec_to_quat(&rv)).into_inner()),
    }
}

/// Taps of the order-`order` Lagrange fractional-delay FIR for a total
/// delay of `delay_samples` (seed 004 eq 18). Returns `(whole, taps)`:
/// the output is `y[k] = Σ_m taps[m] · x[k − whole − m]`, with the
/// fractional part centred: D = delay − whole ∈ [(N−1)/2, (N+1)/2].
pub(crate) fn fractional_delay_taps(order: usize, delay_samples: f64) -> (i64, Vec<f64>) {
    assert!((1..=15).contains(&order), "fractional-delay order 1..=15");
    let n = order as f64;
    // Choose the integer shift so the remaining delay sits in the centre.
    let whole = (delay_samples - (n - 1.0) / 2.0).floor() as i64;
    let d = delay_samples - whole as f64;
    let taps = (0..=order)
        .map(|m| {
            (0..=order)
                .filter(|&k| k != m)
                .map(|k| (d - k as f64) / (m as f64 - k as f64))
                .product()
        })
        .collect();
    (whole, taps)
}

/// Frequency response of taps at normalized angular frequency ω (rad/sample).
#[cfg(test)]
pub(crate) fn fir_response(taps: &[f64], omega: f64) -> (f64, f64) {
    let mut re = 0.0;
    let mut im = 0.0;
    for (m, &h) in taps.iter().enumerate() {
        re += h * (omega * m as f64).cos();
        im -= h * (omega * m as f64).sin();
    }
    (re, im)
}

/// Shifts a sampled sequence by a (possibly fractional) number of samples:
/// `out[k] ≈ x(k − delay)`; samples that would need data outside `x` are
/// taken from the nearest edge (the filter's transient is confined to
/// `order` samples at each end).
#[cfg(test)]
pub(crate) fn shift_sequence(x: &[f64], delay_samples: f64, order: usize) -> Vec<f64> {
    let (whole, taps) = fractional_delay_taps(order, delay_samples);
    let len = x.len() as i64;
    (0..len)
        .map(|k| {
            taps.iter()
                .enumerate()
                .map(|(m, &h)| {
                    let i = (k - whole - m as i64).clamp(0, len - 1);
                    h * x[i as usize]
                })
                .sum()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::Euler;

    #[test]
    fn lagrange_is_exact_for_polynomials_of_its_order() {
        // Cubic (n = 1) through 4 points reproduces any cubic.
        let ts = [0.0, 0.3, 0.7, 1.2];
        let f = |t: f64| 2.0 - t + 0.5 * t * t - 0.25 * t * t * t;
        let mut w = [0.0; 4];
        lagrange_weights(&ts, 0.55, &mut w);
        let v: f64 = ts.iter().zip(&w).map(|(t, w)| w * f(*t)).sum();
        assert!((v - f(0.55)).abs() < 1e-12);
    }

    #[test]
    fn fractional_delay_order5_error_below_1e3_to_02_nyquist() {
        // Laakso et al. 1996: the Lagrange FD error grows as ω^(N+1); with a
        // centred delay it stays below 1e-3 up to 0.2·π for N = 5.
        for step in 0..=20 {
            let frac = step as f64 / 20.0;
            let delay = 7.0 + frac;
            let (whole, taps) = fractional_delay_taps(5, delay);
            let d = delay - whole as f64;
            assert!((2.0..=3.0).contains(&d), "centred: {d}");
            for k in 0..=100 {
                let w = 0.2 * std::f64::consts::PI * k as f64 / 100.0;
                let (re, im) = fir_response(&taps, w);
                let (ire, iim) = ((w * d).cos(), -(w * d).sin());
                let err = ((re - ire).powi(2) + (im - iim).powi(2)).sqrt();
                assert!(err <= 1e-3, "delay {delay} ω {w}: error {err}");
            }
        }
    }

    #[test]
    fn fractional_delay_taps_sum_to_one_and_shift_a_sine() {
        for order in 1..=7 {
            let (_, taps) = fractional_delay_taps(order, 3.37);
            assert!((taps.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        let x: Vec<f64> = (0..400).map(|k| (0.05 * k as f64).sin()).collect();
        let y = shift_sequence(&x, 2.4, 5);
        for k in 20..380 {
            let want = (0.05 * (k as f64 - 2.4)).sin();
            assert!((y[k] - want).abs() < 1e-7, "{k}: {} vs {want}", y[k]);
        }
    }

    #[test]
    fn nav_interpolator_recovers_a_smooth_motion() {
        // A state moving with constant acceleration and turning at a
        // constant rate: cubic interpolation between 200 Hz samples is
        // exact for position (quadratic) and accurate for attitude.
        let t0 = GpsTime::from_week_sow(2300, 100.0);
        let state = |t: GpsTime| {
            let s = t.seconds_since(t0);
            NavState::new(
                t,
                Geodetic::new(0.5 + 1e-7 * s * s, 2.0 + 2e-7 * s, 10.0 + 0.3 * s * s),
                Vector3::new(1.0 + 0.2 * s, 0.5, -0.1 * s),
                &Euler::new(0.01 * s, 0.0, 3.1 + 0.2 * s),
            )
        };
        let mut ip = NavInterpolator::new(1);
        let req: Vec<GpsTime> = (1..40).map(|k| t0.add_seconds(0.0123 * k as f64)).collect();
        for &r in &req {
            ip.request(r);
        }
        let mut got = Vec::new();
        for k in 0..200 {
            got.extend(ip.push(&state(t0 + k * 5_000_000)));
        }
        ip.finish();
        assert_eq!(got.len(), req.len());
        assert_eq!(ip.skipped, 0);
        for g in &got {
            let want = state(g.time);
            assert!((g.pos.h_m - want.pos.h_m).abs() < 1e-9);
            assert!((g.pos.lat_rad - want.pos.lat_rad).abs() < 1e-15);
            assert!((g.vel - want.vel).norm() < 1e-9);
            assert!(
                g.q_nb.angle_to(&want.q_nb) < 1e-9,
                "{}",
                g.q_nb.angle_to(&want.q_nb)
            );
        }
    }
}
