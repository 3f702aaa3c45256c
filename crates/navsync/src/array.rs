//! IMU arrays with unknown relative time offsets (seed 004).
//!
//! Seed 004 estimates each IMU's time-synchronisation error as an EKF state
//! (observation row [H, −v], eqs 11–16) and then shifts the delayed IMU data
//! with a Lagrange fractional-delay FIR (eq 18) before fusing the array.
//! Here each IMU of the array is fused with the (correctly timed) GNSS with
//! the time-offset state of [`crate::fusion`] (the same rows −v and −a),
//! which gives each IMU's offset to GNSS time τ_i; every stream is then
//! shifted onto GNSS time by τ_i with [`crate::interp::fractional_delay_taps`]
//! and the aligned increments are averaged into one virtual IMU whose white
//! noise is 1/√N of a single unit's (independent sensors), which is fused.
//!
//! Sign convention: an IMU whose stamps are late by d (stamp = true + d)
//! sees GNSS fixes as early: τ = −d. Aligning it means advancing its
//! samples by d, i.e. a delay of τ/T samples.

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
pub struct FractionalShifter {
    whole: i64,
    taps: Vec<f64>,
    // Inputs with their indices.
    buf: VecDeque<(i64, [f64; 6])>,
    received: i64,
    emitted: i64,
    first: Option<[f64; 6]>,
}

impl FractionalShifter {
    pub fn new(order: usize, delay_samples: f64) -> Self {
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
    pub fn push(&mut self, x: [f64; 6], out: &mut Vec<[f64; 6]>) {
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
    pub fn finish(&mut self, out: &mut Vec<[f64; 6]>) {
        let last = self.received - 1;
        while self.emitted < self.received {
            out.push(self.output(self.emitted, last));
            self.emitted += 1;
        }
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
    let mut readers = paths
        .iter()
        .map(|p| ImuReader::open(p, week))
        .collect::<Result<Vec<_>, _>>()?;
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
    loop {
        let mut samples = Vec::with_capacity(readers.len());
        for r in readers.iter_mut() {
            samples.push(r.next_sample(diag)?);
        }
        if samples.iter().all(Option::is_none) {
            break;
        }
        let Some(first) = samples[0] else {
            return Err(Error::Invalid(format!(
                "{} ended before the other IMU files",
                paths[0].display()
            )));
        };
        for (i, s) in samples.iter().enumerate() {
            let Some(s) = s else {
                return Err(Error::Invalid(format!(
                    "{} ended before the other IMU files",
                    paths[i].display()
                )));
            };
            if (s.time - first.time).abs() > 1_000 {
                return Err(Error::Invalid(format!(
                    "{} record {} at {} is not on the sample grid of {} ({}): arrays need one grid",
                    paths[i].display(),
                    readers[i].count(),
                    s.time,
                    paths[0].display(),
                    first.time
                )));
            }
            let x = [
                s.dtheta.x, s.dtheta.y, s.dtheta.z, s.dvel.x, s.dvel.y, s.dvel.z,
            ];
            shifters[i].push(x, &mut outs[i]);
        }
        pending_times.push_back(first.time);
        emit(&mut outs, &mut pending_times, &mut writer)?;
    }
    for (s, o) in shifters.iter_mut().zip(outs.iter_mut()) {
        s.finish(o);
    }
    emit(&mut outs, &mut pending_times, &mut writer)?;
    writer.finish()?;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

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
