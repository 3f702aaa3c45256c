//! IMU arrays with unknown relative time offsets (seed 004).
//!
//! Seed 004 estimates each IMU's time-synchronisation error as an EKF state
//! (observation row [H, −v], eqs 11–16) and then shifts the delayed IMU data
//! with a Lagrange fractional-delay FIR (eq 18) before fusing the array.
//! Here each IMU of the array is fused with the (correctly timed) GNSS with
//! the time-offset state of [`crate::fusion`] (the same rows −v and −a),
//! which gives each IMU's offset to GNSS time τ_i; every stream is then
//! shifted onto GNSS time by τ_i with `crate::interp::fractional_delay_taps`
//! and the aligned increments are averaged into one virtual IMU whose white
//! noise is 1/√N of a single unit's (independent sensors), which is fused.
//!
//! The relative offsets inside the array are better found from the IMUs
//! themselves than through GNSS: a rigid body has one angular velocity, so
//! every gyro triad sees the same signal, shifted by its unit's delay
//! ([`relative_delays`]: cross-correlation, then Gauss–Newton least squares
//! on the fractional delay with per-axis bias and gain). The offset common
//! to all units is then what the filter's time-offset state estimates on
//! the aligned array.
//!
//! Sign convention: an IMU whose stamps are late by d (stamp = true + d)
//! sees GNSS fixes as early: τ = −d. Aligning it means advancing its
//! samples by d, i.e. a delay of τ/T samples.
#![warn(missing_docs)]

use std::collections::VecDeque;
use std::path::Path;

use nalgebra::Vector3;

use crate::error::{Diagnostics, Error};
use crate::ins::ImuSample;
use crate::interp::fractional_delay_taps;
use crate::io::kfgins::{ImuReader, TextWriter, format_imu_line};

/// Streams one sequence through a Lagrange fractional-delay FIR with any
/// (also negative) delay: `y[k] ≈ x[k − delay]`. Output lags input by the
/// number of future samples the filter needs; samples outside the data are
/// taken from the nearest edge.
pub(crate) struct FractionalShifter {
    whole: i64,
    taps: Vec<f64>,
    // Inputs with their indices.
    buf: VecDeque<(i64, [f64; 6])>,
    received: i64,
    emitted: i64,
    first: Option<[f64; 6]>,
}

impl FractionalShifter {
    pub(crate) fn new(order: usize, delay_samples: f64) -> Self {
        let (whole, taps) = fractional_delay_taps(order, delay_samples);
        FractionalShifter {
            whole,
            taps,
            buf: VecDeque::new(),
            received: 0,
            emitted: 0,
            first: None,
        }
    }

    fn value(&self, i: i64, last_index: i64) -> [f64; 6] {
        if i < 0 {
            return self.first.unwrap_or([0.0; 6]);
        }
        let i = i.min(last_index);
        let front = self.buf.front().map(|e| e.0).unwrap_or(0);
        let pos = (i - front).clamp(0, self.buf.len() as i64 - 1) as usize;
        self.buf[pos].1
    }

    fn output(&self, k: i64, last_index: i64) -> [f64; 6] {
        let mut y = [0.0; 6];
        for (m, &h) in self.taps.iter().enumerate() {
            let x = self.value(k - self.whole - m as i64, last_index);
            for c in 0..6 {
                y[c] += h * x[c];
            }
        }
        y
    }

    /// Adds input sample k (in order); returns outputs that became ready.
    pub(crate) fn push(&mut self, x: [f64; 6], out: &mut Vec<[f64; 6]>) {
        if self.first.is_none() {
            self.first = Some(x);
        }
        self.buf.push_back((self.received, x));
        self.received += 1;
        // Output k needs inputs up to index k − whole.
        while self.emitted < self.received && self.emitted - self.whole < self.received {
            let y = self.output(self.emitted, self.received - 1);
            out.push(y);
            self.emitted += 1;
        }
        // Keep the inputs that future outputs can need.
        let oldest_needed = self.emitted - self.whole - self.taps.len() as i64;
        while self.buf.len() > 1 && self.buf.front().is_some_and(|e| e.0 < oldest_needed) {
            self.buf.pop_front();
        }
    }

    /// Emits the outputs still pending at the end of the data.
    pub(crate) fn finish(&mut self, out: &mut Vec<[f64; 6]>) {
        let last = self.received - 1;
        while self.emitted < self.received {
            out.push(self.output(self.emitted, last));
            self.emitted += 1;
        }
    }
}

/// The IMU files of an array read in lockstep: one record of each per
/// step, all on one sample grid (within 1 µs).
pub(crate) struct Lockstep<'a> {
    paths: &'a [&'a Path],
    readers: Vec<ImuReader>,
}

impl<'a> Lockstep<'a> {
    pub(crate) fn open(paths: &'a [&'a Path], week: i64) -> Result<Self, Error> {
        let readers = paths
            .iter()
            .map(|p| ImuReader::open(p, week))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Lockstep { paths, readers })
    }

    /// The next record of every file (`None` at the common end); errors
    /// when one file ends early or leaves the first file's grid.
    pub(crate) fn next(&mut self, diag: &mut Diagnostics) -> Result<Option<Vec<ImuSample>>, Error> {
        let mut samples = Vec::with_capacity(self.readers.len());
        let mut ended = Vec::new();
        for (i, r) in self.readers.iter_mut().enumerate() {
            match r.next_sample(diag)? {
                Some(s) => samples.push(s),
                None => ended.push(i),
            }
        }
        if ended.len() == self.readers.len() {
            return Ok(None);
        }
        if let Some(&i) = ended.first() {
            return Err(Error::Invalid(format!(
                "{} ended before the other IMU files",
                self.paths[i].display()
            )));
        }
        let first = samples[0].time;
        for (i, s) in samples.iter().enumerate() {
            if (s.time - first).abs() > 1_000 {
                return Err(Error::Invalid(format!(
                    "{} record {} at {} is not on the sample grid of {} ({}): arrays need one grid",
                    self.paths[i].display(),
                    self.readers[i].count(),
                    s.time,
                    self.paths[0].display(),
                    first
                )));
            }
        }
        Ok(Some(samples))
    }
}

/// Reads the IMU files in lockstep (they must share one sample grid),
/// shifts stream i by `delays_samples[i]` with an order-`order` Lagrange
/// fractional-delay FIR, averages the aligned increments and writes them as
/// a KF-GINS IMU file. Returns the number of samples written.
pub fn combine(
    paths: &[&Path],
    delays_samples: &[f64],
    order: usize,
    week: i64,
    out_path: &Path,
    diag: &mut Diagnostics,
) -> Result<usize, Error> {
    if paths.len() != delays_samples.len() || paths.is_empty() {
        return Err(Error::Invalid(
            "combine: one delay per IMU file is needed".into(),
        ));
    }
    let mut files = Lockstep::open(paths, week)?;
    let mut shifters: Vec<FractionalShifter> = delays_samples
        .iter()
        .map(|&d| FractionalShifter::new(order, d))
        .collect();
    let mut outs: Vec<Vec<[f64; 6]>> = vec![Vec::new(); paths.len()];
    let mut pending_times: VecDeque<crate::time::GpsTime> = VecDeque::new();
    let mut writer = TextWriter::create(out_path)?;
    let mut line = Vec::with_capacity(256);
    let mut written = 0usize;
    let n = paths.len() as f64;
    let mut emit = |outs: &mut Vec<Vec<[f64; 6]>>,
                    times: &mut VecDeque<crate::time::GpsTime>,
                    writer: &mut TextWriter|
     -> Result<(), Error> {
        let ready = outs.iter().map(Vec::len).min().unwrap_or(0);
        for k in 0..ready {
            let Some(t) = times.pop_front() else {
                break;
            };
            let mut avg = [0.0; 6];
            for o in outs.iter() {
                for c in 0..6 {
                    avg[c] += o[k][c] / n;
                }
            }
            line.clear();
            format_imu_line(
                &mut line,
                &ImuSample {
                    time: t,
                    dtheta: Vector3::new(avg[0], avg[1], avg[2]),
                    dvel: Vector3::new(avg[3], avg[4], avg[5]),
                    odo_speed: None,
                },
            );
            writer.write(&line)?;
            written += 1;
        }
        for o in outs.iter_mut() {
            o.drain(..ready);
        }
        Ok(())
    };
    while let Some(samples) = files.next(diag)? {
        for (i, s) in samples.iter().enumerate() {
            let x = [
                s.dtheta.x, s.dtheta.y, s.dtheta.z, s.dvel.x, s.dvel.y, s.dvel.z,
            ];
            shifters[i].push(x, &mut outs[i]);
        }
        pending_times.push_back(samples[0].time);
        emit(&mut outs, &mut pending_times, &mut writer)?;
    }
    for (s, o) in shifters.iter_mut().zip(outs.iter_mut()) {
        s.finish(o);
    }
    emit(&mut outs, &mut pending_times, &mut writer)?;
    writer.finish()?;
    Ok(written)
}

/// The delay of one IMU's data relative to the first IMU of the array.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RelativeDelay {
    /// The unit's data are late by this much relative to the first unit's
    /// (s): `ω_i(t) = ω_1(t − delay)` on the common time tags.
    pub delay_s: f64,
    /// Its standard deviation (s), from the least-squares covariance with
    /// the residuals' serial correlation taken into account.
    pub sd_s: f64,
    /// Correlation coefficient of the two gyro signals at the delay.
    pub correlation: f64,
    /// Samples used.
    pub samples: usize,
}

/// Gyro rates (rad/s) of each unit at one step; the sample interval is the
/// first file's.
fn rates(samples: &[ImuSample], dt: f64) -> Vec<[f64; 3]> {
    samples
        .iter()
        .map(|s| [s.dtheta.x / dt, s.dtheta.y / dt, s.dtheta.z / dt])
        .collect()
}

/// Half span (samples) of the central difference that gives ∂ω/∂δ. The
/// order-5 fractional-delay taps cover 6 samples, so at ±6 the derivative
/// shares no noise sample with the shifted reference itself: it acts as an
/// instrumental variable and the noisy reference biases no delay (with ±½
/// it did, by 3 % of a sample at ADIS16465 noise).
const DERIV_HALF_SPAN: f64 = 6.0;

/// One Gauss–Newton pass of [`relative_delays`] for one unit: the normal
/// equations of `ω_i[k] = g_a · ω_1(k − δ)_a + c_a` linearised at `theta`
/// = [δ (samples), c_x, c_y, c_z, g_x, g_y, g_z], over samples
/// `first..end` (the ends, where the filters see the edges, are left out).
struct DelayFit {
    theta: [f64; 7],
    first: usize,
    end: usize,
    /// ω_1 shifted by δ, δ − h and δ + h samples (h = [`DERIV_HALF_SPAN`]).
    shifters: [FractionalShifter; 3],
    shifted: [Vec<[f64; 6]>; 3],
    /// This unit's rates waiting for the shifted reference.
    own: VecDeque<[f64; 3]>,
    emitted: usize,
    normal: nalgebra::SMatrix<f64, 7, 7>,
    rhs: nalgebra::SVector<f64, 7>,
    rr: f64,
    r_prev: Option<[f64; 3]>,
    r_lag1: f64,
    used: usize,
}

impl DelayFit {
    fn new(theta: [f64; 7], first: usize, end: usize) -> Self {
        let d = theta[0];
        DelayFit {
            theta,
            first,
            end,
            shifters: [
                FractionalShifter::new(5, d),
                FractionalShifter::new(5, d - DERIV_HALF_SPAN),
                FractionalShifter::new(5, d + DERIV_HALF_SPAN),
            ],
            shifted: [Vec::new(), Vec::new(), Vec::new()],
            own: VecDeque::new(),
            emitted: 0,
            normal: nalgebra::SMatrix::zeros(),
            rhs: nalgebra::SVector::zeros(),
            rr: 0.0,
            r_prev: None,
            r_lag1: 0.0,
            used: 0,
        }
    }

    /// The reference unit's and this unit's rates at the next step.
    fn push(&mut self, reference: [f64; 3], own: [f64; 3]) {
        let x = [reference[0], reference[1], reference[2], 0.0, 0.0, 0.0];
        for (sh, out) in self.shifters.iter_mut().zip(self.shifted.iter_mut()) {
            sh.push(x, out);
        }
        self.own.push_back(own);
        self.consume();
    }

    fn finish(&mut self) {
        for (sh, out) in self.shifters.iter_mut().zip(self.shifted.iter_mut()) {
            sh.finish(out);
        }
        self.consume();
    }

    fn consume(&mut self) {
        let ready = self
            .shifted
            .iter()
            .map(Vec::len)
            .min()
            .unwrap_or(0)
            .min(self.own.len());
        let th = self.theta;
        for j in 0..ready {
            let idx = self.emitted + j;
            if idx < self.first || idx >= self.end {
                continue;
            }
            let y = self.own[j];
            let mut r_now = [0.0; 3];
            for a in 0..3 {
                let yh = self.shifted[0][j][a];
                // ∂ω_1(k − δ)/∂δ by central difference over ±h samples.
                let dy = (self.shifted[2][j][a] - self.shifted[1][j][a]) / (2.0 * DERIV_HALF_SPAN);
                let (c, g) = (th[1 + a], th[4 + a]);
                let r = y[a] - (g * yh + c);
                let mut jac = nalgebra::SVector::<f64, 7>::zeros();
                jac[0] = g * dy;
                jac[1 + a] = 1.0;
                jac[4 + a] = yh;
                self.normal += jac * jac.transpose();
                self.rhs += jac * r;
                self.rr += r * r;
                r_now[a] = r;
            }
            if let Some(p) = self.r_prev {
                self.r_lag1 += (0..3).map(|a| p[a] * r_now[a]).sum::<f64>();
            }
            self.r_prev = Some(r_now);
            self.used += 1;
        }
        for o in self.shifted.iter_mut() {
            o.drain(..ready);
        }
        self.own.drain(..ready);
        self.emitted += ready;
    }
}

/// Estimates the delay of every unit's gyro data relative to the first
/// unit's, within ±`max_lag_s`. Streaming, in passes over the files:
/// (1) the cross-correlation of the mean-removed rates, summed over the
/// three axes, at every whole-sample lag, its peak refined by a parabola;
/// (2–5) Gauss–Newton on `ω_i[k] = g_a · ω_1(k − δ)_a + c_a` per axis a
/// (gain g and bias c absorb the units' scale factor and bias
/// differences), ω_1 shifted by an order-5 Lagrange fractional-delay
/// filter (seed 004 eq 18) and its δ-derivative taken by central
/// difference of two more shifted copies (an instrumental variable, see
/// `DERIV_HALF_SPAN`). σ(δ) is the least-squares
/// covariance inflated by √((1+ρ)/(1−ρ)), ρ the residuals' lag-1
/// correlation (an AR(1) effective sample size, Bartlett 1946).
pub fn relative_delays(
    paths: &[&Path],
    sample_interval_s: f64,
    max_lag_s: f64,
    week: i64,
    diag: &mut Diagnostics,
) -> Result<Vec<RelativeDelay>, Error> {
    let units = paths.len();
    if units < 2 {
        return Err(Error::Invalid(
            "relative delays need at least two IMU files".into(),
        ));
    }
    let dt = sample_interval_s;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(Error::Invalid(format!(
            "sample interval {dt} s must be positive"
        )));
    }
    let lags = (max_lag_s / dt).round().max(1.0) as usize;
    let width = 2 * lags + 1;

    // Pass 1: Σ_k ω_i[c + l] · ω_1[c] over centres c, for l ∈ [−L, L].
    let mut corr = vec![vec![0.0f64; width]; units];
    let mut sum = vec![[0.0f64; 3]; units];
    let mut sum_sq = vec![[0.0f64; 3]; units];
    let mut ring: Vec<VecDeque<[f64; 3]>> = vec![VecDeque::with_capacity(width + 1); units];
    let mut centres = 0usize;
    let mut n = 0usize;
    let mut files = Lockstep::open(paths, week)?;
    while let Some(samples) = files.next(diag)? {
        let y = rates(&samples, dt);
        for (i, v) in y.iter().enumerate() {
            for a in 0..3 {
                sum[i][a] += v[a];
                sum_sq[i][a] += v[a] * v[a];
            }
            ring[i].push_back(*v);
            if ring[i].len() > width {
                ring[i].pop_front();
            }
        }
        n += 1;
        if ring[0].len() == width {
            let centre = ring[0][lags];
            for i in 1..units {
                for (l, c) in corr[i].iter_mut().enumerate() {
                    let v = ring[i][l];
                    *c += v[0] * centre[0] + v[1] * centre[1] + v[2] * centre[2];
                }
            }
            centres += 1;
        }
    }
    if centres < 10 * width {
        return Err(Error::Invalid(format!(
            "{} samples are too few to search ±{max_lag_s} s of delay",
            n
        )));
    }
    let mean: Vec<[f64; 3]> = sum.iter().map(|s| s.map(|x| x / n as f64)).collect();
    let var: Vec<f64> = (0..units)
        .map(|i| {
            (0..3)
                .map(|a| sum_sq[i][a] / n as f64 - mean[i][a] * mean[i][a])
                .sum()
        })
        .collect();
    let mut start = vec![(0.0f64, 0.0f64); units]; // (δ in samples, ρ)
    for i in 1..units {
        let m_dot: f64 = (0..3).map(|a| mean[i][a] * mean[0][a]).sum();
        let c: Vec<f64> = corr[i].iter().map(|x| x / centres as f64 - m_dot).collect();
        let (best, &peak) = c
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .ok_or_else(|| Error::Invalid("empty correlation".into()))?;
        let mut frac = 0.0;
        if best > 0 && best + 1 < width {
            let (a, b, e) = (c[best - 1], c[best], c[best + 1]);
            let den = a - 2.0 * b + e;
            if den < 0.0 {
                frac = (0.5 * (a - e) / den).clamp(-0.5, 0.5);
            }
        }
        let rho = peak / (var[i] * var[0]).sqrt().max(f64::MIN_POSITIVE);
        start[i] = (best as f64 - lags as f64 + frac, rho);
    }

    // Passes 2–5: Gauss–Newton on [δ, c_x, c_y, c_z, g_x, g_y, g_z].
    let edge = lags + 16;
    if n <= 2 * edge + 20 {
        return Err(Error::Invalid(format!(
            "{n} samples are too few for the delay estimate"
        )));
    }
    let mut theta: Vec<[f64; 7]> = start
        .iter()
        .map(|&(d, _)| [d, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
        .collect();
    let mut result = vec![
        RelativeDelay {
            delay_s: 0.0,
            sd_s: 0.0,
            correlation: 1.0,
            samples: n,
        };
        units
    ];
    for _ in 0..4 {
        let mut fits: Vec<DelayFit> = theta
            .iter()
            .map(|t| DelayFit::new(*t, edge, n - edge))
            .collect();
        let mut files = Lockstep::open(paths, week)?;
        while let Some(samples) = files.next(diag)? {
            let y = rates(&samples, dt);
            for i in 1..units {
                fits[i].push(y[0], y[i]);
            }
        }
        for i in 1..units {
            let fit = &mut fits[i];
            fit.finish();
            let Some(inv) = fit.normal.try_inverse() else {
                return Err(Error::Invalid(format!(
                    "{}: the gyro signals carry no information on the delay (no rotation?)",
                    paths[i].display()
                )));
            };
            let step = inv * fit.rhs;
            for (t, s) in theta[i].iter_mut().zip(step.iter()) {
                *t += s;
            }
            let dof = (3 * fit.used).saturating_sub(7).max(1) as f64;
            let s2 = fit.rr / dof;
            let rho1 = (fit.r_lag1 / fit.rr.max(f64::MIN_POSITIVE)).clamp(0.0, 0.99);
            let inflation = ((1.0 + rho1) / (1.0 - rho1)).sqrt();
            result[i] = RelativeDelay {
                delay_s: theta[i][0] * dt,
                sd_s: (s2 * inv[(0, 0)]).max(0.0).sqrt() * inflation * dt,
                correlation: start[i].1,
                samples: fit.used,
            };
        }
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::GpsTime;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A vehicle-like angular rate (rad/s) at time t (s): turns and
    /// weaving, smooth.
    fn omega(t: f64) -> [f64; 3] {
        [
            0.02 * (1.3 * t).sin() + 0.01 * (3.1 * t + 1.0).sin(),
            0.015 * (0.9 * t + 0.5).sin() + 0.01 * (2.3 * t).cos(),
            0.15 * (0.21 * t).sin() + 0.05 * (0.77 * t + 2.0).sin(),
        ]
    }

    /// Writes a 200 Hz KF-GINS file of `secs` whose data are `delay_s` late
    /// on the common tags, with gain error, bias and ADIS-class white noise.
    fn write_unit(path: &Path, secs: usize, delay_s: f64, gain: f64, bias: f64, seed: u64) {
        let dt = 0.005;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        // ARW 0.15 deg/√h → per-sample σ of the rate at 200 Hz.
        let noise = Normal::new(0.0, (0.15f64).to_radians() / 60.0 * 200f64.sqrt()).unwrap();
        let mut w = TextWriter::create(path).unwrap();
        let mut line = Vec::new();
        for k in 1..=secs * 200 {
            let t = k as f64 * dt;
            // The increment over (t − dt, t] of the delayed signal (midpoint).
            let o = omega(t - 0.5 * dt - delay_s);
            let mut d = |a: usize| (gain * o[a] + bias + noise.sample(&mut rng)) * dt;
            let dtheta = Vector3::new(d(0), d(1), d(2));
            line.clear();
            format_imu_line(
                &mut line,
                &ImuSample {
                    time: GpsTime::from_week_sow(0, 1000.0 + t),
                    dtheta,
                    dvel: Vector3::new(0.0, 0.0, -9.8 * dt),
                    odo_speed: None,
                },
            );
            w.write(&line).unwrap();
        }
        w.finish().unwrap();
    }

    #[test]
    fn relative_delays_come_from_the_gyros_to_a_tenth_of_a_millisecond() {
        let dir = crate::testfiles::TestDir::new("array");
        let files = [
            (dir.join("a.txt"), 0.0, 1.0, 0.0),
            (dir.join("b.txt"), 0.0123, 1.0005, 2e-4),
            (dir.join("c.txt"), -0.0071, 0.9996, -1e-4),
        ];
        for (i, (p, d, g, b)) in files.iter().enumerate() {
            write_unit(p, 300, *d, *g, *b, i as u64 + 1);
        }
        let paths: Vec<&Path> = files.iter().map(|f| f.0.as_path()).collect();
        let mut diag = Diagnostics::default();
        let r = relative_delays(&paths, 0.005, 0.1, 0, &mut diag).unwrap();
        assert_eq!(r.len(), 3);
        for (est, (_, truth, _, _)) in r.iter().zip(&files).skip(1) {
            let err = est.delay_s - truth;
            assert!(est.sd_s < 1e-4, "{est:?}");
            assert!(err.abs() < 4.0 * est.sd_s.max(1e-6), "{est:?} vs {truth}");
            assert!(est.correlation > 0.9, "{est:?}");
        }
        // Files on different grids are refused with both names.
        write_unit(&dir.join("late.txt"), 300, 0.0, 1.0, 0.0, 9);
        let text = std::fs::read_to_string(dir.join("late.txt")).unwrap();
        let shifted: String = text.lines().skip(1).map(|l| format!("{l}\n")).collect();
        std::fs::write(dir.join("late.txt"), shifted).unwrap();
        let late_path = dir.join("late.txt");
        let late: Vec<&Path> = vec![files[0].0.as_path(), late_path.as_path()];
        let e = relative_delays(&late, 0.005, 0.1, 0, &mut diag).unwrap_err();
        assert!(e.to_string().contains("late.txt"), "{e}");
    }

    #[test]
    fn streaming_shifter_matches_batch_shift() {
        let x: Vec<f64> = (0..300)
            .map(|k| (0.07 * k as f64).sin() + 0.01 * k as f64)
            .collect();
        for delay in [2.3, -3.6, 0.0, -0.4, 7.9] {
            let want = crate::interp::shift_sequence(&x, delay, 5);
            let mut sh = FractionalShifter::new(5, delay);
            let mut got = Vec::new();
            for &v in &x {
                sh.push([v, 0.0, 0.0, 0.0, 0.0, 0.0], &mut got);
            }
            sh.finish(&mut got);
            assert_eq!(got.len(), x.len(), "delay {delay}");
            for k in 0..x.len() {
                assert!(
                    (got[k][0] - want[k]).abs() < 1e-12,
                    "delay {delay} k {k}: {} vs {}",
                    got[k][0],
                    want[k]
                );
            }
        }
    }
}
