//! Decimation (seed 001 §1.3): averaging for rates, accumulation for
//! increments — never point sampling, which aliases vibration into the
//! navigation band. Point decimation is provided to show what it costs.
//!
//! Output rate = input rate / (DEC_RATE + 1), the ADIS16465 semantics
//! (seed 001 §1.3.1: DEC_RATE = 9 turns 2000 Hz into 200 Hz). Each output
//! covers the interval since the previous output and is stamped at the end
//! of that interval (the time of its last input sample).
//!
//! Windows are either counted (`DEC_RATE + 1` input samples, as the
//! device does) or aligned to a time grid of the output period (the sample
//! nearest each multiple of the period closes a window), which keeps
//! output epochs on round times across gaps and clock drift. A gap in the
//! input (an interval longer than `gap_factor` nominal periods) closes the
//! current window early: the partial window is emitted, stamped at its
//! last sample, and counted; nothing is dropped.
#![warn(missing_docs)]

use nalgebra::Vector3;
use serde::Serialize;

use super::convert::{RateRule, RateToIncrement};
use super::{RateSample, period_ns};
use crate::error::Error;
use crate::time::GpsTime;
use crate::types::ImuSample;

/// The ADIS16465 decimation register: output rate = input rate /
/// (DEC_RATE + 1) (seed 001 §1.3.1).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
pub struct DecRate(pub u32);

impl DecRate {
    /// Largest DEC_RATE the ADIS16465 accepts (2000 Hz / 2000 = 1 Hz).
    pub(crate) const ADIS16465_MAX: u32 = 1999;
    /// The ADIS16465's internal sampling rate (Hz).
    #[cfg(test)]
    pub(crate) const ADIS16465_INTERNAL_HZ: f64 = 2000.0;

    /// A register value checked against the ADIS16465 range 0..=1999.
    pub fn adis16465(reg: u32) -> Result<Self, Error> {
        if reg > Self::ADIS16465_MAX {
            return Err(Error::Invalid(format!(
                "DEC_RATE {reg} is outside the ADIS16465 range 0..={}",
                Self::ADIS16465_MAX
            )));
        }
        Ok(DecRate(reg))
    }

    /// The register value that divides by `factor` (≥ 1).
    pub fn from_factor(factor: u32) -> Result<Self, Error> {
        if factor == 0 {
            return Err(Error::Invalid(
                "decimation factor must be at least 1".into(),
            ));
        }
        Ok(DecRate(factor - 1))
    }

    /// The register value that turns `input_hz` into `output_hz`; the
    /// ratio must be a whole number (within 1e-6).
    pub fn from_rates(input_hz: f64, output_hz: f64) -> Result<Self, Error> {
        if !(input_hz > 0.0 && output_hz > 0.0 && output_hz <= input_hz) {
            return Err(Error::Invalid(format!(
                "cannot decimate {input_hz} Hz to {output_hz} Hz: need 0 < output <= input"
            )));
        }
        let ratio = input_hz / output_hz;
        let n = ratio.round();
        if (ratio - n).abs() > 1e-6 * ratio || n > u32::MAX as f64 {
            return Err(Error::Invalid(format!(
                "{input_hz} Hz / {output_hz} Hz = {ratio:.6} is not a whole number: decimation by averaging needs an integer factor (DEC_RATE + 1)"
            )));
        }
        Self::from_factor(n as u32)
    }

    /// Input samples per output sample, DEC_RATE + 1.
    pub fn factor(self) -> u32 {
        self.0 + 1
    }

    /// Output rate for `input_hz`: input / (DEC_RATE + 1).
    pub fn output_rate_hz(self, input_hz: f64) -> f64 {
        input_hz / self.factor() as f64
    }
}

/// How a window of input samples becomes one output sample.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub enum DecimationMethod {
    /// Rates averaged, increments accumulated (seed 001 §1.3).
    #[default]
    Average,
    /// Naive point decimation: one sample per window, the rest thrown
    /// away (for an increment stream: the last sub-interval's rate held
    /// over the whole window). Aliases; provided for comparison only.
    Point,
}

/// Where windows end.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
pub(crate) enum WindowMode {
    /// Every `factor` input samples (device semantics).
    Count,
    /// At the sample nearest each multiple of `period_ns` (GPS time).
    Grid { period_ns: i64, tol_ns: i64 },
}

/// Counters of a decimator.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DecimatorStats {
    pub(crate) samples_in: usize,
    pub(crate) samples_out: usize,
    /// Outputs made of fewer (or, in grid mode, more) input samples than
    /// the factor: at the start, around gaps, under clock drift.
    pub partial_windows: usize,
    /// Input intervals longer than `gap_factor` nominal periods.
    pub gaps: usize,
    /// Samples not after the previous one (ignored).
    pub(crate) rejected_time: usize,
}

/// The outputs of one push: none, one, or (when a gap closes a window
/// and the new sample closes its own at once) two, in time order.
#[derive(Clone, Debug)]
pub struct Emitted<T> {
    items: [Option<T>; 2],
    next: usize,
}

impl<T> Default for Emitted<T> {
    fn default() -> Self {
        Emitted {
            items: [None, None],
            next: 0,
        }
    }
}

impl<T> Emitted<T> {
    fn put(&mut self, v: T) {
        if self.items[0].is_none() {
            self.items[0] = Some(v);
        } else {
            self.items[1] = Some(v);
        }
    }
}

impl<T> Iterator for Emitted<T> {
    type Item = T;
    fn next(&mut self) -> Option<T> {
        while self.next < 2 {
            let k = self.next;
            self.next += 1;
            if let Some(v) = self.items[k].take() {
                return Some(v);
            }
        }
        None
    }
}

/// The window bookkeeping shared by the rate and increment decimators.
#[derive(Clone, Debug)]
struct Windows {
    factor: u32,
    mode: WindowMode,
    gap_ns: Option<i64>,
    count: u32,
    end_ns: i64,
    last_time: Option<GpsTime>,
    stats: DecimatorStats,
}

/// What to do with a new sample.
enum Action {
    /// Close the open window before this sample, then handle it again.
    CloseBefore,
    /// Add it; `true` when it closes the window.
    Add(bool),
    /// Ignore it (time not increasing).
    Reject,
}

impl Windows {
    fn new(factor: u32, mode: WindowMode, gap_ns: Option<i64>) -> Self {
        Windows {
            factor: factor.max(1),
            mode,
            gap_ns,
            count: 0,
            end_ns: 0,
            last_time: None,
            stats: DecimatorStats::default(),
        }
    }

    fn action(&mut self, t: GpsTime) -> Action {
        if let Some(last) = self.last_time {
            let dt = t - last;
            if dt <= 0 {
                self.stats.rejected_time += 1;
                return Action::Reject;
            }
            if self.count > 0 {
                if self.gap_ns.is_some_and(|g| dt > g) {
                    return Action::CloseBefore;
                }
                if let WindowMode::Grid { tol_ns, .. } = self.mode
                    && t.ns() > self.end_ns + tol_ns
                {
                    return Action::CloseBefore;
                }
            }
        }
        if self.count == 0
            && let WindowMode::Grid { period_ns, tol_ns } = self.mode
        {
            // The grid multiple at or after t − tol ends this window.
            self.end_ns = (t.ns() - tol_ns).div_euclid(period_ns) * period_ns;
            if self.end_ns < t.ns() - tol_ns {
                self.end_ns += period_ns;
            }
        }
        let closes = match self.mode {
            WindowMode::Count => self.count + 1 >= self.factor,
            WindowMode::Grid { tol_ns, .. } => (t.ns() - self.end_ns).abs() <= tol_ns,
        };
        Action::Add(closes)
    }

    fn added(&mut self, t: GpsTime) {
        if let (Some(last), Some(g)) = (self.last_time, self.gap_ns)
            && t - last > g
        {
            self.stats.gaps += 1;
        }
        self.stats.samples_in += 1;
        self.count += 1;
        self.last_time = Some(t);
    }

    fn closed(&mut self) {
        self.stats.samples_out += 1;
        if self.count != self.factor {
            self.stats.partial_windows += 1;
        }
        self.count = 0;
    }
}

/// Builds the window mode from the options.
fn window_mode(factor: u32, input_rate_hz: Option<f64>, align_to_grid: bool) -> WindowMode {
    match (align_to_grid, input_rate_hz) {
        (true, Some(r)) if r > 0.0 && factor > 1 => {
            // At least 1 ns (a rate above 1 GHz would round the period to
            // 0 and divide by it); saturating for huge factors.
            let dt = period_ns(r).max(1);
            WindowMode::Grid {
                period_ns: dt.saturating_mul(factor as i64),
                tol_ns: (dt / 2 - 1).max(0),
            }
        }
        _ => WindowMode::Count,
    }
}

/// Decimates an increment stream by accumulation (or point sampling).
#[derive(Clone, Debug)]
pub struct IncrementDecimator {
    win: Windows,
    method: DecimationMethod,
    /// Start of the open window (time of the sample before it).
    begin: Option<GpsTime>,
    prev_time: Option<GpsTime>,
    sum_dtheta: Vector3<f64>,
    sum_dvel: Vector3<f64>,
    last: Option<ImuSample>,
    last_dt_s: f64,
    nominal_dt_s: Option<f64>,
}

impl IncrementDecimator {
    /// Decimation by `dec` with `method`. `input_rate_hz` (when known)
    /// enables gap detection (`gap_factor` nominal periods) and, with
    /// `align_to_grid`, windows that end on multiples of the output period.
    pub fn new(
        dec: DecRate,
        method: DecimationMethod,
        input_rate_hz: Option<f64>,
        align_to_grid: bool,
        gap_factor: f64,
    ) -> Self {
        let factor = dec.factor();
        let gap_ns = input_rate_hz.map(|r| (gap_factor * period_ns(r) as f64) as i64);
        IncrementDecimator {
            win: Windows::new(
                factor,
                window_mode(factor, input_rate_hz, align_to_grid),
                gap_ns,
            ),
            method,
            begin: None,
            prev_time: None,
            sum_dtheta: Vector3::zeros(),
            sum_dvel: Vector3::zeros(),
            last: None,
            last_dt_s: f64::NAN,
            nominal_dt_s: input_rate_hz.map(|r| 1.0 / r),
        }
    }

    /// What the decimator counted so far.
    pub fn stats(&self) -> &DecimatorStats {
        &self.win.stats
    }

    /// Pushes one increment sample; yields the outputs it completes (at
    /// most two: a window closed early by a gap, then a window this sample
    /// closes at once).
    pub fn push(&mut self, s: &ImuSample) -> Emitted<ImuSample> {
        let mut out = Emitted::default();
        loop {
            match self.win.action(s.time) {
                Action::Reject => return out,
                Action::CloseBefore => {
                    if let Some(o) = self.close() {
                        out.put(o);
                    }
                }
                Action::Add(closes) => {
                    if self.win.count == 0 {
                        self.begin = self.prev_time;
                        self.sum_dtheta = Vector3::zeros();
                        self.sum_dvel = Vector3::zeros();
                    }
                    self.last_dt_s = match self.prev_time {
                        Some(p) => s.time.seconds_since(p),
                        None => self.nominal_dt_s.unwrap_or(f64::NAN),
                    };
                    self.sum_dtheta += s.dtheta;
                    self.sum_dvel += s.dvel;
                    self.last = Some(*s);
                    self.prev_time = Some(s.time);
                    self.win.added(s.time);
                    if closes && let Some(o) = self.close() {
                        out.put(o);
                    }
                    return out;
                }
            }
        }
    }

    /// Emits the open window (if any) as it stands: call at the end of
    /// the stream to flush a partial window.
    pub fn flush(&mut self) -> Option<ImuSample> {
        if self.win.count == 0 {
            return None;
        }
        self.close()
    }

    fn close(&mut self) -> Option<ImuSample> {
        let last = self.last?;
        let count = self.win.count;
        self.win.closed();
        let (dtheta, dvel) = match self.method {
            DecimationMethod::Average => (self.sum_dtheta, self.sum_dvel),
            DecimationMethod::Point => {
                // The last sub-interval's mean rate held over the window.
                let window_s = match self.begin {
                    Some(b) => last.time.seconds_since(b),
                    None => count as f64 * self.last_dt_s,
                };
                let k = if self.last_dt_s > 0.0 && window_s.is_finite() {
                    window_s / self.last_dt_s
                } else {
                    count as f64
                };
                (last.dtheta * k, last.dvel * k)
            }
        };
        Some(ImuSample {
            time: last.time,
            dtheta,
            dvel,
            odo_speed: last.odo_speed,
        })
    }
}

/// Decimates a rate stream by averaging (or point sampling); the output
/// rate sample is the mean over its window ([`RateRule::Average`])
/// stamped at the window's last sample.
#[derive(Clone, Debug)]
pub struct RateDecimator {
    win: Windows,
    method: DecimationMethod,
    sum_gyro: Vector3<f64>,
    sum_accel: Vector3<f64>,
    last: Option<RateSample>,
}

impl RateDecimator {
    /// See [`IncrementDecimator::new`] for the arguments.
    pub fn new(
        dec: DecRate,
        method: DecimationMethod,
        input_rate_hz: Option<f64>,
        align_to_grid: bool,
        gap_factor: f64,
    ) -> Self {
        let factor = dec.factor();
        let gap_ns = input_rate_hz.map(|r| (gap_factor * period_ns(r) as f64) as i64);
        RateDecimator {
            win: Windows::new(
                factor,
                window_mode(factor, input_rate_hz, align_to_grid),
                gap_ns,
            ),
            method,
            sum_gyro: Vector3::zeros(),
            sum_accel: Vector3::zeros(),
            last: None,
        }
    }

    /// What the decimator counted so far.
    pub fn stats(&self) -> &DecimatorStats {
        &self.win.stats
    }

    /// Pushes one rate sample; yields the outputs it completes.
    pub fn push(&mut self, s: &RateSample) -> Emitted<RateSample> {
        let mut out = Emitted::default();
        loop {
            match self.win.action(s.time) {
                Action::Reject => return out,
                Action::CloseBefore => {
                    if let Some(o) = self.close() {
                        out.put(o);
                    }
                }
                Action::Add(closes) => {
                    if self.win.count == 0 {
                        self.sum_gyro = Vector3::zeros();
                        self.sum_accel = Vector3::zeros();
                    }
                    self.sum_gyro += s.gyro;
                    self.sum_accel += s.accel;
                    self.last = Some(*s);
                    self.win.added(s.time);
                    if closes && let Some(o) = self.close() {
                        out.put(o);
                    }
                    return out;
                }
            }
        }
    }

    /// Emits the open (partial) window, if any.
    pub fn flush(&mut self) -> Option<RateSample> {
        if self.win.count == 0 {
            return None;
        }
        self.close()
    }

    fn close(&mut self) -> Option<RateSample> {
        let last = self.last?;
        let n = self.win.count as f64;
        self.win.closed();
        Some(match self.method {
            DecimationMethod::Average => RateSample {
                time: last.time,
                gyro: self.sum_gyro / n,
                accel: self.sum_accel / n,
            },
            DecimationMethod::Point => last,
        })
    }
}

/// What a log holds.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
pub enum InputKind {
    /// Angle and velocity increments (KF-GINS): passed through.
    Increment,
    /// Angular rates and specific forces, converted by
    /// [`RateToIncrement`].
    Rate(RateRule),
}

/// One sample of a log, as read.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum InputSample {
    /// Angular rate (rad/s) and specific force (m/s²) at its time stamp.
    Rate(RateSample),
    /// Angle (rad) and velocity (m/s) increments over the interval ending
    /// at its time stamp.
    Increment(ImuSample),
}

/// How a [`Conditioner`] turns a log into navigation increments.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct ConditionerConfig {
    /// Whether the log holds increments or rates (and how rates are
    /// integrated).
    pub input: InputKind,
    /// Decimation register: output rate = input rate / (DEC_RATE + 1);
    /// `DecRate(0)` keeps every sample.
    pub dec: DecRate,
    /// Averaging/accumulation, or naive point decimation (comparison only).
    pub method: DecimationMethod,
    /// Nominal input rate (Hz): gap detection and grid alignment.
    pub input_rate_hz: Option<f64>,
    /// End output windows on multiples of the output period.
    pub align_to_grid: bool,
    /// An input interval longer than this many nominal periods is a gap.
    pub gap_factor: f64,
    /// Rates are not integrated across gaps longer than this (s).
    pub max_bridge_s: Option<f64>,
    /// Subtracted from every output time stamp (s): the group delay of a
    /// low-pass filter the IMU applied (seed 001 §1.4).
    pub delay_compensation_s: f64,
}

impl Default for ConditionerConfig {
    fn default() -> Self {
        ConditionerConfig {
            input: InputKind::Increment,
            dec: DecRate(0),
            method: DecimationMethod::Average,
            input_rate_hz: None,
            align_to_grid: true,
            gap_factor: 1.5,
            max_bridge_s: Some(0.1),
            delay_compensation_s: 0.0,
        }
    }
}

/// A log's samples in, navigation increments out: rate→increment
/// conversion, decimation, delay compensation, in the order seed 001 §1.3
/// prescribes (rates converted at the full input rate, then accumulated;
/// point decimation, for comparison, picks rate samples first and
/// converts the survivors).
#[derive(Clone, Debug)]
pub struct Conditioner {
    cfg: ConditionerConfig,
    conv: Option<RateToIncrement>,
    rate_dec: Option<RateDecimator>,
    inc_dec: IncrementDecimator,
    shift_ns: i64,
}

impl ConditionerConfig {
    /// Highest input rate accepted (Hz): its period is 1 µs, the time
    /// base is 1 ns (MEMS IMUs sample at most at tens of kHz).
    pub const MAX_INPUT_RATE_HZ: f64 = 1e6;

    /// Checks the values the conditioner divides by or adds to times.
    pub fn validate(&self) -> Result<(), Error> {
        if let Some(r) = self.input_rate_hz
            && !(r.is_finite() && r > 0.0 && r <= Self::MAX_INPUT_RATE_HZ)
        {
            return Err(Error::Invalid(format!(
                "IMU input rate {r} Hz: expected a rate in (0, {}] Hz",
                Self::MAX_INPUT_RATE_HZ
            )));
        }
        if !(self.gap_factor.is_finite() && self.gap_factor > 1.0) {
            return Err(Error::Invalid(format!(
                "gap factor {} must be a finite number above 1",
                self.gap_factor
            )));
        }
        if !self.delay_compensation_s.is_finite()
            || self
                .max_bridge_s
                .is_some_and(|s| !(s.is_finite() && s >= 0.0))
        {
            return Err(Error::Invalid(format!(
                "delay compensation {} s and bridge limit {:?} s must be finite (the limit ≥ 0)",
                self.delay_compensation_s, self.max_bridge_s
            )));
        }
        Ok(())
    }
}

impl Conditioner {
    /// A conditioner over this configuration, checked
    /// ([`ConditionerConfig::validate`]).
    pub fn new(cfg: ConditionerConfig) -> Result<Self, Error> {
        cfg.validate()?;
        let bridge = |c: RateToIncrement| match cfg.max_bridge_s {
            Some(s) => c.with_max_bridge(s),
            None => c,
        };
        let (conv, rate_dec, inc_dec) = match (cfg.input, cfg.method) {
            (InputKind::Increment, m) => (
                None,
                None,
                IncrementDecimator::new(
                    cfg.dec,
                    m,
                    cfg.input_rate_hz,
                    cfg.align_to_grid,
                    cfg.gap_factor,
                ),
            ),
            (InputKind::Rate(kind), DecimationMethod::Average) => (
                Some(bridge(RateToIncrement::new(kind))),
                None,
                IncrementDecimator::new(
                    cfg.dec,
                    DecimationMethod::Average,
                    cfg.input_rate_hz,
                    cfg.align_to_grid,
                    cfg.gap_factor,
                ),
            ),
            (InputKind::Rate(_), DecimationMethod::Point) => (
                Some(bridge(RateToIncrement::new(RateRule::Trapezoid))),
                Some(RateDecimator::new(
                    cfg.dec,
                    DecimationMethod::Point,
                    cfg.input_rate_hz,
                    cfg.align_to_grid,
                    cfg.gap_factor,
                )),
                IncrementDecimator::new(
                    DecRate(0),
                    DecimationMethod::Average,
                    cfg.input_rate_hz.map(|r| cfg.dec.output_rate_hz(r)),
                    false,
                    cfg.gap_factor,
                ),
            ),
        };
        Ok(Conditioner {
            cfg,
            conv,
            rate_dec,
            inc_dec,
            shift_ns: crate::time::seconds_to_ns(cfg.delay_compensation_s),
        })
    }

    /// Its configuration.
    pub fn config(&self) -> &ConditionerConfig {
        &self.cfg
    }

    /// Decimation counters (of the stage that decimates).
    pub fn decimator_stats(&self) -> DecimatorStats {
        match &self.rate_dec {
            Some(r) => *r.stats(),
            None => *self.inc_dec.stats(),
        }
    }

    /// Conversion counters (rate input only).
    pub fn convert_stats(&self) -> Option<super::convert::ConvertStats> {
        self.conv.as_ref().map(|c| *c.stats())
    }

    /// Pushes one input sample; calls `emit` with each finished output.
    pub fn push(&mut self, s: &InputSample, emit: &mut dyn FnMut(ImuSample)) {
        let shift = self.shift_ns;
        let mut out = |o: ImuSample| {
            emit(ImuSample {
                time: o.time + (-shift),
                ..o
            })
        };
        match s {
            InputSample::Increment(inc) => {
                if self.conv.is_some() {
                    return;
                }
                self.inc_dec.push(inc).for_each(&mut out);
            }
            InputSample::Rate(r) => {
                let Some(conv) = self.conv.as_mut() else {
                    return;
                };
                match self.rate_dec.as_mut() {
                    None => {
                        if let Some(inc) = conv.push(r) {
                            self.inc_dec.push(&inc).for_each(&mut out);
                        }
                    }
                    Some(rd) => {
                        for picked in rd.push(r) {
                            if let Some(inc) = conv.push(&picked) {
                                self.inc_dec.push(&inc).for_each(&mut out);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Flushes a partial last window at the end of the stream.
    pub fn finish(&mut self, emit: &mut dyn FnMut(ImuSample)) {
        let shift = self.shift_ns;
        let mut out = |o: ImuSample| {
            emit(ImuSample {
                time: o.time + (-shift),
                ..o
            })
        };
        if let (Some(rd), Some(conv)) = (self.rate_dec.as_mut(), self.conv.as_mut())
            && let Some(picked) = rd.flush()
            && let Some(inc) = conv.push(&picked)
        {
            self.inc_dec.push(&inc).for_each(&mut out);
        }
        if let Some(o) = self.inc_dec.flush() {
            out(o);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    const T0_NS: i64 = 1_000_000_000_000;

    fn inc(t_ns: i64, dth: f64, dv: f64) -> ImuSample {
        ImuSample {
            time: GpsTime::from_ns(t_ns),
            dtheta: Vector3::new(dth, 0.0, 0.0),
            dvel: Vector3::new(dv, 0.0, 0.0),
            odo_speed: None,
        }
    }

    fn run(dec: &mut IncrementDecimator, input: &[ImuSample]) -> Vec<ImuSample> {
        let mut out = Vec::new();
        for s in input {
            out.extend(dec.push(s));
        }
        out.extend(dec.flush());
        out
    }

    /// Increments of ω(t) at `rate_hz` by the trapezoid (what an IMU such as
    /// the ADIS16465 integrates internally).
    fn increments_of(w: &dyn Fn(f64) -> f64, rate_hz: f64, n: usize) -> Vec<ImuSample> {
        let dt_ns = period_ns(rate_hz);
        let mut conv = RateToIncrement::new(RateRule::Trapezoid);
        let mut out = Vec::new();
        for k in 0..=n {
            let t_ns = T0_NS + k as i64 * dt_ns;
            let t = (t_ns - T0_NS) as f64 * 1e-9;
            let r = RateSample {
                time: GpsTime::from_ns(t_ns),
                gyro: Vector3::new(w(t), 0.0, 0.0),
                accel: Vector3::new(w(t), 0.0, 0.0),
            };
            out.extend(conv.push(&r));
        }
        out
    }

    #[test]
    fn dec_rate_arithmetic() {
        // Seed 001 §1.3.1: DEC_RATE = 9 turns 2000 Hz into 200 Hz.
        let d = DecRate(9);
        assert_eq!(d.factor(), 10);
        assert_eq!(d.output_rate_hz(DecRate::ADIS16465_INTERNAL_HZ), 200.0);
        assert_eq!(DecRate::from_rates(2000.0, 200.0).unwrap(), DecRate(9));
        assert_eq!(DecRate::from_rates(200.0, 200.0).unwrap(), DecRate(0));
        assert_eq!(DecRate::from_rates(200.0, 25.0).unwrap().factor(), 8);
        assert!(DecRate::from_rates(2000.0, 300.0).is_err());
        assert!(DecRate::from_rates(200.0, 400.0).is_err());
        assert!(DecRate::from_rates(200.0, 0.0).is_err());
        assert!(DecRate::from_factor(0).is_err());
        assert_eq!(
            DecRate::adis16465(1999).unwrap().output_rate_hz(2000.0),
            1.0
        );
        assert!(DecRate::adis16465(2000).is_err());
    }

    #[test]
    fn constant_rate_accumulates_exactly_and_point_agrees() {
        let input = increments_of(&|_| 0.25, 2000.0, 100);
        for method in [DecimationMethod::Average, DecimationMethod::Point] {
            let mut d = IncrementDecimator::new(DecRate(9), method, Some(2000.0), false, 1.5);
            let out = run(&mut d, &input);
            assert_eq!(out.len(), 10);
            for o in &out {
                // 10 sub-intervals of 0.5 ms at 0.25 rad/s: 1.25e-3 rad; the
                // sum of ten f64 terms is exact to a few ulp.
                assert!(
                    (o.dtheta.x - 1.25e-3).abs() < 1e-17,
                    "{method:?} {}",
                    o.dtheta.x
                );
            }
            assert_eq!(out[0].time, GpsTime::from_ns(T0_NS + 5_000_000));
            assert_eq!(d.stats().partial_windows, 0);
        }
    }

    #[test]
    fn linear_ramp_average_is_exact_point_is_biased_by_bt_t_minus_dt_over_2() {
        // ω = a + b t. Accumulated trapezoid increments are the exact window
        // integral; point decimation holds the last sub-interval's mean rate
        // (a + b (t1 − dt/2)) over T, in error by b T (T − dt)/2.
        let (a, b) = (0.1, 2.0);
        let input = increments_of(&|t| a + b * t, 2000.0, 200);
        let dt = 0.5e-3;
        let tw = 5e-3;
        let mut avg = IncrementDecimator::new(
            DecRate(9),
            DecimationMethod::Average,
            Some(2000.0),
            false,
            1.5,
        );
        let mut pt = IncrementDecimator::new(
            DecRate(9),
            DecimationMethod::Point,
            Some(2000.0),
            false,
            1.5,
        );
        let out_a = run(&mut avg, &input);
        let out_p = run(&mut pt, &input);
        assert_eq!(out_a.len(), 20);
        for (oa, op) in out_a.iter().zip(&out_p) {
            let t1 = (oa.time.ns() - T0_NS) as f64 * 1e-9;
            let t0 = t1 - tw;
            let exact = a * tw + b * (t1 * t1 - t0 * t0) / 2.0;
            assert!(
                (oa.dtheta.x - exact).abs() < 1e-15,
                "{} {exact}",
                oa.dtheta.x
            );
            let bias = b * tw * (tw - dt) / 2.0;
            assert!(
                (op.dtheta.x - exact - bias).abs() < 1e-14,
                "{}",
                op.dtheta.x - exact
            );
        }
    }

    #[test]
    fn vibration_aliases_under_point_decimation_not_under_averaging() {
        // 190 Hz vibration sampled at 2 kHz, decimated to 200 Hz. Its window
        // integrals are A/(2πf)(cos 2πf t0 − cos 2πf t1).
        // Averaging: only the 2 kHz trapezoid error remains, bounded per
        // window by 10 · dt³/12 · A (2πf)².
        // Point: the rate at one sub-interval held over 5 ms aliases to
        // 10 Hz with amplitude ≈ A·T: RMS error ≈ A T/√2 (minus the small
        // true integral).
        let (amp, f) = (1.0, 190.0);
        let w = 2.0 * PI * f;
        let input = increments_of(&|t| amp * (w * t).sin(), 2000.0, 2000);
        let mut avg = IncrementDecimator::new(
            DecRate(9),
            DecimationMethod::Average,
            Some(2000.0),
            false,
            1.5,
        );
        let mut pt = IncrementDecimator::new(
            DecRate(9),
            DecimationMethod::Point,
            Some(2000.0),
            false,
            1.5,
        );
        let out_a = run(&mut avg, &input);
        let out_p = run(&mut pt, &input);
        let (tw, dt): (f64, f64) = (5e-3, 0.5e-3);
        let bound = 10.0 * dt.powi(3) / 12.0 * amp * w * w;
        let (mut ea, mut ep, mut angle_a, mut angle_p) = (0.0f64, 0.0f64, 0.0, 0.0);
        for (oa, op) in out_a.iter().zip(&out_p) {
            let t1 = (oa.time.ns() - T0_NS) as f64 * 1e-9;
            let t0 = t1 - tw;
            let exact = amp / w * ((w * t0).cos() - (w * t1).cos());
            assert!(
                (oa.dtheta.x - exact).abs() <= bound,
                "{} > {bound}",
                (oa.dtheta.x - exact).abs()
            );
            ea += (oa.dtheta.x - exact).powi(2);
            ep += (op.dtheta.x - exact).powi(2);
            angle_a += oa.dtheta.x - exact;
            angle_p += op.dtheta.x - exact;
        }
        let n = out_a.len() as f64;
        let (rms_a, rms_p) = ((ea / n).sqrt(), (ep / n).sqrt());
        assert!(rms_p > 0.5 * amp * tw / 2f64.sqrt(), "point rms {rms_p}");
        assert!(rms_p > 20.0 * rms_a, "point {rms_p} vs average {rms_a}");
        // The accumulated angle error stays at the trapezoid level; the
        // point-decimated one wanders with the 10 Hz alias.
        assert!(angle_a.abs() < 200.0 * bound, "{angle_a}");
        assert!(angle_p.abs() > angle_a.abs());
    }

    #[test]
    fn grid_windows_end_on_round_times_and_lose_nothing_across_gaps() {
        // 200 Hz starting 5 ms after a whole second (KF-GINS style), to 25 Hz.
        let mut input = Vec::new();
        for k in 1..=400i64 {
            if (101..=112).contains(&k) || (250..=251).contains(&k) {
                continue; // a 60 ms gap and a 15 ms gap
            }
            input.push(inc(T0_NS + k * 5_000_000, 1e-3 * k as f64, 1.0));
        }
        let mut d = IncrementDecimator::new(
            DecRate(7),
            DecimationMethod::Average,
            Some(200.0),
            true,
            1.5,
        );
        let out = run(&mut d, &input);
        let sum_in: f64 = input.iter().map(|s| s.dtheta.x).sum();
        let sum_out: f64 = out.iter().map(|s| s.dtheta.x).sum();
        assert!((sum_in - sum_out).abs() < 1e-12);
        let n_in: f64 = input.iter().map(|s| s.dvel.x).sum();
        let n_out: f64 = out.iter().map(|s| s.dvel.x).sum();
        assert_eq!(n_in, n_out);
        // Full windows end on 40 ms multiples and hold 8 samples.
        let mut full = 0;
        for o in &out {
            if o.dvel.x == 8.0 {
                full += 1;
                assert_eq!((o.time.ns() - T0_NS) % 40_000_000, 0, "{}", o.time);
            }
        }
        assert_eq!(out[0].time, GpsTime::from_ns(T0_NS + 40_000_000));
        assert!(full >= 44, "{full}");
        assert_eq!(d.stats().gaps, 2);
        // Each gap cuts its window short: before it and after it.
        assert_eq!(d.stats().partial_windows, out.len() - full);
        assert!(d.stats().partial_windows >= 2);
        for w in out.windows(2) {
            assert!(w[1].time > w[0].time);
        }
    }

    #[test]
    fn count_windows_close_early_at_a_gap() {
        let mut input: Vec<ImuSample> = (1..=10)
            .map(|k| inc(T0_NS + k * 5_000_000, 1.0, 0.0))
            .collect();
        input.push(inc(T0_NS + 20 * 5_000_000, 1.0, 0.0));
        let mut d = IncrementDecimator::new(
            DecRate(3),
            DecimationMethod::Average,
            Some(200.0),
            false,
            1.5,
        );
        let out = run(&mut d, &input);
        let counts: Vec<f64> = out.iter().map(|o| o.dtheta.x).collect();
        assert_eq!(counts, vec![4.0, 4.0, 2.0, 1.0]);
        assert_eq!(out[2].time, GpsTime::from_ns(T0_NS + 10 * 5_000_000));
        assert_eq!(d.stats().gaps, 1);
    }

    #[test]
    fn rate_average_is_stamped_at_the_window_end() {
        let mut d = RateDecimator::new(
            DecRate(4),
            DecimationMethod::Average,
            Some(1000.0),
            false,
            1.5,
        );
        let mut out = Vec::new();
        for k in 1..=10i64 {
            out.extend(d.push(&RateSample {
                time: GpsTime::from_ns(T0_NS + k * 1_000_000),
                gyro: Vector3::new(k as f64, 0.0, 0.0),
                accel: Vector3::zeros(),
            }));
        }
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].time, GpsTime::from_ns(T0_NS + 5_000_000));
        assert_eq!(out[0].gyro.x, 3.0);
        assert_eq!(out[1].gyro.x, 8.0);
    }

    #[test]
    fn a_rate_the_time_base_cannot_hold_is_refused_not_divided_by() {
        // `imu convert --rate 1e300 --decimate 2` divided by a zero period.
        for bad in [1e300, f64::NAN, f64::INFINITY, 0.0, -200.0, 2e6] {
            let cfg = ConditionerConfig {
                dec: DecRate(1),
                input_rate_hz: Some(bad),
                ..Default::default()
            };
            let e = Conditioner::new(cfg).unwrap_err().to_string();
            assert!(e.contains("expected a rate in (0, 1000000] Hz"), "{e}");
        }
        // The decimator alone (its own constructor) does not divide by zero.
        let mut d = IncrementDecimator::new(
            DecRate(1),
            DecimationMethod::Average,
            Some(1e300),
            true,
            1.5,
        );
        let s = ImuSample {
            time: GpsTime::from_ns(T0_NS),
            dtheta: Vector3::zeros(),
            dvel: Vector3::zeros(),
            odo_speed: None,
        };
        let _ = d.push(&s);
    }

    #[test]
    fn conditioner_converts_accumulates_and_compensates_delay() {
        let cfg = ConditionerConfig {
            input: InputKind::Rate(RateRule::Trapezoid),
            dec: DecRate(1),
            input_rate_hz: Some(1000.0),
            align_to_grid: false,
            delay_compensation_s: 0.0015,
            ..Default::default()
        };
        let mut c = Conditioner::new(cfg).unwrap();
        let mut out = Vec::new();
        for k in 0..=8i64 {
            let s = InputSample::Rate(RateSample {
                time: GpsTime::from_ns(T0_NS + k * 1_000_000),
                gyro: Vector3::new(k as f64, 0.0, 0.0),
                accel: Vector3::new(0.0, 0.0, -9.8),
            });
            c.push(&s, &mut |o| out.push(o));
        }
        c.finish(&mut |o| out.push(o));
        assert_eq!(out.len(), 4);
        // Window (0, 2 ms]: trapezoids (0+1)/2 + (1+2)/2 = 2 → 2e-3 rad.
        assert!((out[0].dtheta.x - 2e-3).abs() < 1e-15);
        assert!((out[0].dvel.z + 9.8 * 2e-3).abs() < 1e-15);
        assert_eq!(out[0].time, GpsTime::from_ns(T0_NS + 2_000_000 - 1_500_000));
    }
}
