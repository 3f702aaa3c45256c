//! The hardware clock model: local counter → GPS time from 1PPS edges
//! (seed 001 §2.1, eqs 1–3) labelled with their GPS second from the GNSS
//! messages, estimated robustly over a sliding window.
//!
//! Model. With `x = (c − c_ref)/f0` the counter's nominal seconds since a
//! reference pulse labelled `s_ref`, GPS time is `s_ref + x + p(x)`, where
//! the offset polynomial `p` (degree ≤ 2: offset, frequency error, drift)
//! is fitted by least squares to the pulses `y_k = (s_k − s_ref) − x_k`.
//! Seed 001 eq 3 is the special case of a line through two neighbouring
//! pulses; here every estimate uses a window of pulses, as chrony does
//! (`refclock.c`: a median-based prefilter, then a regression).
//!
//! Robustness. Acquisition fits a Theil–Sen line (median of pairwise
//! slopes, median intercept) to the first pulses, so up to half of them
//! may be displaced or spurious; afterwards each pulse must fall within a
//! gate of `gate_sigmas` predicted standard deviations (never wider than
//! needed, never narrower than `min_gate_s`). After a gap, pulses are only
//! accepted in consistent pairs (relock at the second good pulse).
//!
//! Labelling. A GNSS message valid at T and received at fractional pulse
//! index ν can only have arrived after T (latency ≥ 0), and at least some
//! messages arrive within a second: the label of pulse 0 is the largest
//! `ceil(T − ν)` supported by two messages.

#![warn(missing_docs)]

use std::collections::VecDeque;

use super::fit::{PolyFit, median};
use crate::time::{GpsTime, NS_PER_S};

/// Settings of the clock model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ClockConfig {
    /// Nominal counter frequency (Hz).
    pub counter_hz: f64,
    /// 1PPS edge jitter (s, 1σ), on top of the counter quantization.
    pub(crate) pps_jitter_s: f64,
    /// Pulses in the causal (real-time) regression window.
    pub(crate) causal_window: usize,
    /// Half-width of the post-processing smoothing window (s).
    pub(crate) smooth_half_window_s: f64,
    /// Gate on a pulse's innovation, in predicted standard deviations.
    pub(crate) gate_sigmas: f64,
    /// Narrowest gate (s).
    pub(crate) min_gate_s: f64,
    /// Largest plausible counter frequency error at start-up (ppm).
    pub(crate) max_freq_error_ppm: f64,
    /// Frequency random walk of the counter oscillator (1/s): the variance
    /// of the fractional-frequency change over Δ seconds is `q·Δ`.
    pub(crate) freq_random_walk: f64,
    /// Drift random walk (1/s³): variance of the drift change is `q·Δ`.
    pub(crate) drift_random_walk: f64,
    /// Largest change of drift the past cannot foresee (1/s), e.g. a
    /// temperature ramp starting during a dropout: adds ½·d·Δ² to bounds
    /// and gates after Δ seconds without pulses.
    pub(crate) max_drift_change: f64,
    /// Error bounds are this many standard deviations (plus the above).
    pub(crate) bound_sigmas: f64,
    /// Corrections larger than this are slewed, not stepped (s), causal mode.
    pub(crate) slew_threshold_s: f64,
    /// Slew rate (s/s).
    pub(crate) slew_rate: f64,
}

impl ClockConfig {
    /// Defaults for a counter of `counter_hz`.
    pub(crate) fn for_counter(counter_hz: f64) -> Self {
        let tick = 1.0 / counter_hz;
        ClockConfig {
            counter_hz,
            pps_jitter_s: 1e-7,
            causal_window: 64,
            smooth_half_window_s: 20.0,
            gate_sigmas: 6.0,
            // Ten ticks, at least 5 µs, at most 50 µs: a pulse displaced by
            // ≥ 0.1 ms is always outside while locked.
            min_gate_s: (10.0 * tick).clamp(5e-6, 5e-5),
            max_freq_error_ppm: 1000.0,
            freq_random_walk: Oscillator::Xo.freq_random_walk(),
            drift_random_walk: Oscillator::Xo.drift_random_walk(),
            max_drift_change: Oscillator::Xo.max_drift_change(),
            bound_sigmas: 3.0,
            slew_threshold_s: 0.5e-6,
            slew_rate: 1e-4,
        }
    }

    /// The unforeseeable part of the error after `dt` s without pulses.
    pub(crate) fn unmodelled(&self, dt: f64) -> f64 {
        0.5 * self.max_drift_change * dt.max(0.0).powi(2)
    }

    /// Error bound from a model standard deviation `sd` after `dt` s
    /// without pulses, including the stamp's own counter quantization.
    pub fn bound(&self, sd: f64, dt: f64) -> f64 {
        self.bound_sigmas * (sd * sd + self.tick_s().powi(2) / 12.0).sqrt() + self.unmodelled(dt)
    }

    fn tick_s(&self) -> f64 {
        1.0 / self.counter_hz
    }

    /// Measurement noise of one pulse: counter quantization ⊕ jitter.
    fn sigma_meas(&self) -> f64 {
        (self.tick_s().powi(2) / 12.0 + self.pps_jitter_s.powi(2)).sqrt()
    }

    /// Variance of free-running phase error after `dt` seconds from the
    /// oscillator noise alone (integrated random walks).
    pub(crate) fn process_var(&self, dt: f64) -> f64 {
        let dt = dt.max(0.0);
        self.freq_random_walk * dt.powi(3) / 3.0 + self.drift_random_walk * dt.powi(5) / 20.0
    }
}

/// `b − a` in ticks as `f64` (unwrapped counters are far closer than 2^63).
#[inline]
pub(crate) fn tick_diff(a: u64, b: u64) -> f64 {
    b.wrapping_sub(a) as i64 as f64
}

/// The kind of oscillator driving the counter: it sets how fast the
/// holdover error bound grows (the clock noise the past cannot predict).
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Oscillator {
    /// A plain crystal (±1 ppm/°C) in a vehicle whose temperature may start
    /// to ramp at 1 °C/min at any time: a drift change of 1.7e-8/s, i.e.
    /// 30 µs after 60 s, is a 3σ event.
    Xo,
    /// Temperature compensated (≈ 0.05 ppm/°C): 20× less.
    Tcxo,
    /// Oven controlled: 1000× less than a crystal.
    Ocxo,
}

impl Oscillator {
    /// Fractional-frequency random walk (1/s): var of the change over Δ is q·Δ.
    pub(crate) fn freq_random_walk(self) -> f64 {
        match self {
            Oscillator::Xo => 1e-20,
            Oscillator::Tcxo => 1e-21,
            Oscillator::Ocxo => 1e-23,
        }
    }

    /// Drift random walk (1/s³): the phase variance after Δ is q·Δ⁵/20.
    pub(crate) fn drift_random_walk(self) -> f64 {
        match self {
            Oscillator::Xo => 1e-20,
            Oscillator::Tcxo => 1e-22,
            Oscillator::Ocxo => 1e-25,
        }
    }

    /// Unforeseeable drift change (1/s): 1 °C/min at 1 ppm/°C for a crystal
    /// (30 µs after 60 s), 0.05 ppm/°C for a TCXO, 1e-11/s for an OCXO.
    pub(crate) fn max_drift_change(self) -> f64 {
        match self {
            Oscillator::Xo => 1.7e-8,
            Oscillator::Tcxo => 8.5e-10,
            Oscillator::Ocxo => 1e-11,
        }
    }
}

/// An accepted pulse: unwrapped counter and GPS second (since the epoch).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Pulse {
    pub counter: u64,
    pub(crate) second: i64,
}

/// Lock state of the clock model.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LockState {
    /// No model yet (not enough consistent, labelled pulses).
    Acquiring,
    /// Pulses arriving and accepted.
    Locked,
    /// No accepted pulse for more than 1.5 s: free-running on the model.
    Holdover,
}

/// Why a pulse was not used.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Rejection {
    /// Far from any GPS second (> 1 ms): an extra, spurious pulse.
    Spurious,
    /// Near a GPS second but outside the gate: displaced.
    Displaced,
    /// A second pulse for an already accepted second.
    Duplicate,
    /// After a gap, not confirmed by a consistent neighbour.
    Unconfirmed,
    /// Not on the consistent pulse train during acquisition.
    Acquisition,
}

/// A lock-state change, at GPS time `time`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct LockEvent {
    pub time: GpsTime,
    pub state: LockState,
}

/// Counts of pulse outcomes.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct PulseCounts {
    /// `pps` edges seen.
    pub received: u64,
    /// Edges accepted into the clock model.
    pub accepted: u64,
    /// Rejected: far from any GPS second (> 1 ms), an extra pulse.
    pub rejected_spurious: u64,
    /// Rejected: near a GPS second but outside the gate.
    pub rejected_displaced: u64,
    /// Rejected: a second pulse for an already accepted second.
    pub rejected_duplicate: u64,
    /// Rejected: after a gap, not confirmed by a consistent neighbour.
    pub rejected_unconfirmed: u64,
    /// Rejected: not on the consistent pulse train during acquisition.
    pub rejected_acquisition: u64,
    /// Times the label offset was corrected after lock (should be 0).
    pub(crate) label_corrections: u64,
    /// Times the model was re-acquired on a new consistent pulse train.
    pub(crate) reacquisitions: u64,
}

/// The causal model: a fit over the latest accepted pulses.
#[derive(Clone, Debug)]
pub(crate) struct CausalModel {
    c_ref: u64,
    s_ref: i64,
    fit: PolyFit,
    sigma: f64,
    last_counter: u64,
}

/// A GNSS message kept for labelling.
#[derive(Copy, Clone, Debug)]
struct Msg {
    counter: u64,
    valid: GpsTime,
}

/// The PPS clock model (causal part plus the history used for smoothing).
#[derive(Clone, Debug)]
pub(crate) struct PpsClock {
    pub cfg: ClockConfig,
    state: LockState,
    /// Unaccepted pulses during acquisition (counters).
    candidates: VecDeque<u64>,
    /// Consecutive rejected pulses after lock (for re-acquisition).
    rejected_run: VecDeque<u64>,
    /// A pulse waiting for confirmation after a gap.
    pending_relock: Option<Pulse>,
    causal: VecDeque<Pulse>,
    model: Option<CausalModel>,
    /// Accepted pulses kept for smoothing (pruned by the owner).
    pub(crate) history: VecDeque<Pulse>,
    msgs: VecDeque<Msg>,
    /// Recent label-correction votes after lock.
    votes: VecDeque<i64>,
    nonzero_vote_run: u32,
    pub(crate) counts: PulseCounts,
    pub events: Vec<LockEvent>,
    /// Slew: offset applied to causal outputs at `slew_anchor` (s).
    slew_offset: f64,
    slew_anchor: u64,
    last_stamp_counter: u64,
    /// Frequency-error track (ppm) at each accepted pulse, for the report.
    pub(crate) freq_ppm: crate::stats::Moments,
    /// Residual of accepted pulses against the causal prediction (s).
    pub(crate) innovation: crate::stats::Moments,
    /// Latest counter seen by the clock.
    now: u64,
    chi2_table: Vec<f64>,
}

impl PpsClock {
    pub(crate) fn new(cfg: ClockConfig) -> Self {
        PpsClock {
            cfg,
            state: LockState::Acquiring,
            candidates: VecDeque::new(),
            rejected_run: VecDeque::new(),
            pending_relock: None,
            causal: VecDeque::new(),
            model: None,
            history: VecDeque::new(),
            msgs: VecDeque::new(),
            votes: VecDeque::new(),
            nonzero_vote_run: 0,
            counts: PulseCounts::default(),
            events: Vec::new(),
            slew_offset: 0.0,
            slew_anchor: 0,
            last_stamp_counter: 0,
            freq_ppm: Default::default(),
            innovation: Default::default(),
            now: 0,
            chi2_table: Vec::new(),
        }
    }

    /// Current lock state (updated by [`Self::advance`]).
    pub(crate) fn state(&self) -> LockState {
        self.state
    }

    /// True once pulses are labelled and a model exists.
    pub(crate) fn has_model(&self) -> bool {
        self.model.is_some()
    }

    fn secs(&self, from: u64, to: u64) -> f64 {
        tick_diff(from, to) / self.cfg.counter_hz
    }

    /// GPS time (ns) of `s_ref + g` seconds.
    fn to_gps(s_ref: i64, g: f64) -> GpsTime {
        let whole = g.floor();
        let frac_ns = ((g - whole) * 1e9).round() as i64;
        GpsTime::from_ns((s_ref + whole as i64) * NS_PER_S + frac_ns)
    }

    /// Notes the passage of time (any record's counter): enters holdover
    /// when no pulse was accepted for 1.5 s.
    pub(crate) fn advance(&mut self, counter: u64) {
        self.now = self.now.max(counter);
        if self.state == LockState::Locked
            && let Some(m) = &self.model
            && self.secs(m.last_counter, self.now) > 1.5
        {
            let t = self.causal_time(m.last_counter).0.add_seconds(1.0);
            self.set_state(LockState::Holdover, t);
        }
    }

    fn set_state(&mut self, s: LockState, time: GpsTime) {
        if self.state != s {
            self.state = s;
            self.events.push(LockEvent { time, state: s });
        }
    }

    /// A GNSS message valid at `valid`, received at `counter`.
    pub(crate) fn push_gnss(&mut self, counter: u64, valid: GpsTime) {
        self.msgs.push_back(Msg { counter, valid });
        while self.msgs.len() > 64 {
            self.msgs.pop_front();
        }
        if self.model.is_none() {
            self.try_acquire();
            return;
        }
        // Label check after lock: δ = ceil(−latency) is 0 when labels are
        // right and the message arrived within a second.
        let lat = self.causal_time(counter).0.seconds_since(valid);
        let delta = (-lat).ceil() as i64;
        self.votes.push_back(delta);
        while self.votes.len() > 32 {
            self.votes.pop_front();
        }
        let best = best_supported(self.votes.iter().copied());
        match best {
            Some(d) if d != 0 => {
                self.nonzero_vote_run += 1;
                if self.nonzero_vote_run >= 8 {
                    self.relabel(d);
                }
            }
            _ => self.nonzero_vote_run = 0,
        }
    }

    fn relabel(&mut self, d: i64) {
        for p in self.causal.iter_mut().chain(self.history.iter_mut()) {
            p.second += d;
        }
        if let Some(p) = &mut self.pending_relock {
            p.second += d;
        }
        if let Some(m) = &mut self.model {
            m.s_ref += d;
        }
        self.votes.clear();
        self.nonzero_vote_run = 0;
        self.counts.label_corrections += 1;
    }

    /// A 1PPS edge latched at `counter`.
    /// Returns the GPS second the pulse was accepted as.
    pub(crate) fn push_pulse(&mut self, counter: u64) -> Result<i64, Rejection> {
        self.counts.received += 1;
        self.advance(counter);
        let Some(model) = self.model.clone() else {
            self.candidates.push_back(counter);
            while self.candidates.len() > 16 {
                self.candidates.pop_front();
                self.counts.rejected_acquisition += 1;
            }
            self.try_acquire();
            return if let Some(p) = self.causal.back().filter(|_| self.model.is_some()) {
                Ok(p.second)
            } else {
                Err(Rejection::Acquisition)
            };
        };
        let x = self.secs(model.c_ref, counter);
        let g = x + model.fit.eval(x);
        let nearest = g.round();
        let second = model.s_ref + nearest as i64;
        let innov = nearest - g; // measured offset − predicted offset
        let dt = self.secs(model.last_counter, counter).max(0.0);
        let var = model.sigma.powi(2) * (1.0 + model.fit.var_factor(x)) + self.cfg.process_var(dt);
        let gate =
            (self.cfg.gate_sigmas * var.sqrt() + self.cfg.unmodelled(dt)).max(self.cfg.min_gate_s);
        let last_second = self.causal.back().map(|p| p.second).unwrap_or(i64::MIN);
        let pulse = Pulse { counter, second };
        let verdict = if innov.abs() > gate {
            if innov.abs() > 1e-3 {
                Err(Rejection::Spurious)
            } else {
                Err(Rejection::Displaced)
            }
        } else if second <= last_second {
            Err(Rejection::Duplicate)
        } else if dt > 1.5 {
            // After a gap: accept only a consistent pair.
            match self.pending_relock.take() {
                Some(prev) if prev.second < second => {
                    let xp = self.secs(model.c_ref, prev.counter);
                    let innov_prev = (prev.second - model.s_ref) as f64 - (xp + model.fit.eval(xp));
                    let pair_tol = (self.cfg.gate_sigmas * 2f64.sqrt() * self.cfg.sigma_meas()
                        + model.fit.slope_var_factor(x).sqrt()
                            * model.sigma
                            * (self.secs(prev.counter, counter)))
                    .max(self.cfg.min_gate_s);
                    if (innov - innov_prev).abs() <= pair_tol {
                        self.accept(prev);
                        Ok(())
                    } else {
                        self.counts.rejected_unconfirmed += 1;
                        self.pending_relock = Some(pulse);
                        Err(Rejection::Unconfirmed)
                    }
                }
                other => {
                    if other.is_some() {
                        self.counts.rejected_unconfirmed += 1;
                    }
                    self.pending_relock = Some(pulse);
                    Err(Rejection::Unconfirmed)
                }
            }
        } else {
            Ok(())
        };
        match verdict {
            Ok(()) => {
                self.pending_relock = None;
                self.rejected_run.clear();
                self.innovation.push(innov);
                self.accept(pulse);
                Ok(pulse.second)
            }
            Err(r) => {
                match r {
                    Rejection::Spurious => self.counts.rejected_spurious += 1,
                    Rejection::Displaced => self.counts.rejected_displaced += 1,
                    Rejection::Duplicate => self.counts.rejected_duplicate += 1,
                    _ => {}
                }
                if r != Rejection::Unconfirmed {
                    self.rejected_run.push_back(counter);
                    while self.rejected_run.len() > 16 {
                        self.rejected_run.pop_front();
                    }
                    if self.rejected_run.len() >= 8 {
                        self.try_reacquire();
                    }
                }
                Err(r)
            }
        }
    }

    fn accept(&mut self, p: Pulse) {
        self.counts.accepted += 1;
        self.causal.push_back(p);
        while self.causal.len() > self.cfg.causal_window.max(4) {
            self.causal.pop_front();
        }
        if self.history.back().is_none_or(|h| h.second < p.second) {
            self.history.push_back(p);
        }
        self.refit();
        let t = GpsTime::from_ns(p.second * NS_PER_S);
        self.set_state(LockState::Locked, t);
    }

    /// Refits the causal model on the causal window; slews the output
    /// across the change when it is large.
    fn refit(&mut self) {
        let Some(last) = self.causal.back().copied() else {
            return;
        };
        let mut pts: Vec<(f64, f64)> = self
            .causal
            .iter()
            .map(|p| {
                let x = self.secs(last.counter, p.counter);
                (x, (p.second - last.second) as f64 - x)
            })
            .collect();
        let sm = self.cfg.sigma_meas();
        // Adaptive window (the spirit of chrony's runs test): while the
        // residuals are too large for the pulse noise (χ², 99.9 %), the
        // oldest quarter of the window is dropped, so a change of drift
        // (a temperature ramp starting) leaves the model quickly.
        let fit = loop {
            let span = pts.first().map(|f| -f.0).unwrap_or(0.0);
            let deg = if pts.len() >= 12 && span >= 10.0 {
                2
            } else if pts.len() >= 2 {
                1
            } else {
                0
            };
            let Some(fit) = PolyFit::fit(&pts, deg) else {
                return;
            };
            let dof = fit.dof();
            let too_large = dof >= 10
                && fit
                    .sigma()
                    .is_some_and(|s| s * s * dof as f64 > sm * sm * self.chi2_999(dof));
            if too_large && pts.len() > 16 {
                let drop = pts.len() / 4;
                pts.drain(..drop);
                let keep: Vec<Pulse> = self.causal.iter().skip(drop).copied().collect();
                self.causal = keep.into();
                continue;
            }
            break fit;
        };
        let sm = self.cfg.sigma_meas();
        let dof = fit.dof() as f64;
        let s2 = fit.sigma().map(|s| s * s).unwrap_or(sm * sm);
        let prior = 4.0;
        let sigma = ((dof * s2 + prior * sm * sm) / (dof + prior))
            .sqrt()
            .max(0.5 * sm);
        let new = CausalModel {
            c_ref: last.counter,
            s_ref: last.second,
            fit,
            sigma,
            last_counter: last.counter,
        };
        // Frequency error: dGPS/dx = 1 + p'(x) → counter fast by −p'/(1+p').
        let d = new.fit.slope(0.0);
        self.freq_ppm.push(-d / (1.0 + d) * 1e6);
        // Continuity of causal outputs at the latest stamped counter.
        if let Some(old) = &self.model {
            let c = self.last_stamp_counter.max(old.last_counter);
            let g_old = Self::model_g(old, c, self.cfg.counter_hz);
            let g_new = Self::model_g(&new, c, self.cfg.counter_hz);
            // express both relative to the same second
            let jump = (g_new + new.s_ref as f64 - old.s_ref as f64) - g_old;
            let current = self.slew_at(c);
            let total = current - jump;
            if total.abs() > self.cfg.slew_threshold_s {
                self.slew_offset = total;
                self.slew_anchor = c;
            } else {
                self.slew_offset = 0.0;
            }
        }
        self.model = Some(new);
    }

    /// χ² 99.9 % quantile for `dof` degrees of freedom (cached).
    fn chi2_999(&mut self, dof: usize) -> f64 {
        if self.chi2_table.len() <= dof {
            self.chi2_table.resize(dof + 1, f64::NAN);
        }
        if self.chi2_table[dof].is_nan() {
            self.chi2_table[dof] = crate::stats::chi2_quantile(0.999, dof as f64);
        }
        self.chi2_table[dof]
    }

    fn model_g(m: &CausalModel, c: u64, hz: f64) -> f64 {
        let x = tick_diff(m.c_ref, c) / hz;
        x + m.fit.eval(x)
    }

    /// The slew offset still applied at counter `c`.
    fn slew_at(&self, c: u64) -> f64 {
        if self.slew_offset == 0.0 {
            return 0.0;
        }
        let el = self.secs(self.slew_anchor, c).max(0.0);
        let left = (self.slew_offset.abs() - self.cfg.slew_rate * el).max(0.0);
        left.copysign(self.slew_offset)
    }

    /// Theil–Sen acquisition on the candidate pulses, labelled by the
    /// GNSS messages. Installs a model on success.
    fn try_acquire(&mut self) {
        let Some((inliers, train)) = consistent_train(&self.candidates, &self.cfg) else {
            return;
        };
        let Some(s0) = self.label_train(&train) else {
            return;
        };
        let rejected = self.candidates.len() - inliers.len();
        self.counts.rejected_acquisition += rejected as u64;
        self.candidates.clear();
        self.causal.clear();
        self.model = None;
        for &(n, c) in &inliers {
            let p = Pulse {
                counter: c,
                second: s0 + n,
            };
            self.counts.accepted += 1;
            self.causal.push_back(p);
            if self.history.back().is_none_or(|h| h.second < p.second) {
                self.history.push_back(p);
            }
        }
        self.refit();
        if let Some(p) = self.causal.back() {
            let t = GpsTime::from_ns(p.second * NS_PER_S);
            self.set_state(LockState::Locked, t);
        }
    }

    /// Re-acquisition when many consecutive pulses were rejected but agree
    /// among themselves (the PPS or the counter stepped).
    fn try_reacquire(&mut self) {
        let Some((inliers, train)) = consistent_train(&self.rejected_run, &self.cfg) else {
            return;
        };
        if inliers.len() < 6 {
            return;
        }
        let Some(s0) = self.label_train(&train) else {
            return;
        };
        self.counts.reacquisitions += 1;
        self.causal.clear();
        self.rejected_run.clear();
        self.pending_relock = None;
        // Smoothing must not mix the two trains: drop history from the step on.
        let first_c = inliers.first().map(|p| p.1).unwrap_or(0);
        self.history.retain(|h| h.counter < first_c);
        for &(n, c) in &inliers {
            let p = Pulse {
                counter: c,
                second: s0 + n,
            };
            self.counts.accepted += 1;
            self.causal.push_back(p);
            if self.history.back().is_none_or(|h| h.second < p.second) {
                self.history.push_back(p);
            }
        }
        self.refit();
    }

    /// The GPS second of pulse index 0 of `train` from the messages.
    fn label_train(&self, train: &Train) -> Option<i64> {
        if self.msgs.len() < 3 {
            return None;
        }
        let votes = self.msgs.iter().map(|m| {
            let nu = (m.counter as i128 - train.c0 as i128) as f64 / train.ticks_per_s;
            // seconds of the message's validity relative to whole seconds
            let t_s = m.valid.ns().div_euclid(NS_PER_S);
            let t_frac = m.valid.ns().rem_euclid(NS_PER_S) as f64 * 1e-9;
            t_s + (t_frac - nu).ceil() as i64
        });
        best_supported(votes)
    }

    /// GPS time of counter `c` from the causal model (with slew) and its
    /// error bound (s). EPOCH and an infinite bound without a model.
    pub(crate) fn causal_time(&self, c: u64) -> (GpsTime, f64) {
        let Some(m) = &self.model else {
            return (GpsTime::EPOCH, f64::INFINITY);
        };
        let x = self.secs(m.c_ref, c);
        let g = x + m.fit.eval(x) + self.slew_at(c);
        let dt = self.secs(m.last_counter, c).max(0.0);
        let var = m.sigma.powi(2) * m.fit.var_factor(x) + self.cfg.process_var(dt);
        (
            Self::to_gps(m.s_ref, g),
            self.cfg.bound(var.sqrt(), dt) + self.slew_at(c).abs(),
        )
    }

    /// Causal stamp for output: also remembers the counter for slewing.
    pub(crate) fn stamp_causal(&mut self, c: u64) -> (GpsTime, f64) {
        self.last_stamp_counter = self.last_stamp_counter.max(c);
        self.causal_time(c)
    }

    /// Drops history pulses that no stamp at or after counter `c` needs.
    pub(crate) fn prune_history(&mut self, c: u64) {
        let keep_s = self.cfg.smooth_half_window_s + 2.0;
        while self.history.len() > 2 {
            let second = self.history[1];
            if self.secs(second.counter, c) > keep_s {
                self.history.pop_front();
            } else {
                break;
            }
        }
    }

    /// Seconds of local time from the latest accepted pulse to `c`.
    pub(crate) fn since_last_pulse(&self, c: u64) -> f64 {
        self.history
            .back()
            .map(|p| self.secs(p.counter, c))
            .unwrap_or(f64::INFINITY)
    }

    /// Seconds between `a` and `b` on the nominal counter.
    pub(crate) fn seconds_between(&self, a: u64, b: u64) -> f64 {
        self.secs(a, b)
    }
}

/// A line through a pulse train: counter at index 0 and ticks per second.
#[derive(Copy, Clone, Debug)]
struct Train {
    c0: u64,
    ticks_per_s: f64,
}

/// Finds the consistent pulse train among `cands` (Theil–Sen line on
/// integer second indices relative to the latest pulse): inliers as
/// (index, counter), at least 4 at distinct indices spanning ≥ 3 s.
fn consistent_train(cands: &VecDeque<u64>, cfg: &ClockConfig) -> Option<(Vec<(i64, u64)>, Train)> {
    if cands.len() < 4 {
        return None;
    }
    let f0 = cfg.counter_hz;
    let tol_ppm = cfg.max_freq_error_ppm * 1e-6;
    // Try each of the latest few pulses as the anchor (a spurious latest
    // pulse must not spoil acquisition).
    let n = cands.len();
    let mut best: Option<(Vec<(i64, u64)>, Train)> = None;
    for a in (n.saturating_sub(4)..n).rev() {
        let anchor = cands[a];
        let mut pts: Vec<(i64, u64)> = Vec::new();
        for &c in cands {
            let r = (c as i128 - anchor as i128) as f64 / f0;
            let k = r.round();
            if (r - k).abs() <= tol_ppm * k.abs() + 2e-3 {
                pts.push((k as i64, c));
            }
        }
        if pts.len() < 4 {
            continue;
        }
        // Theil–Sen slope (ticks per second) and intercept.
        let mut slopes = Vec::new();
        for i in 0..pts.len() {
            for j in i + 1..pts.len() {
                if pts[i].0 != pts[j].0 {
                    slopes.push(
                        (pts[j].1 as i128 - pts[i].1 as i128) as f64 / (pts[j].0 - pts[i].0) as f64,
                    );
                }
            }
        }
        if slopes.is_empty() {
            continue;
        }
        let slope = median(&mut slopes);
        let mut icpt: Vec<f64> = pts
            .iter()
            .map(|&(k, c)| (c as i128 - anchor as i128) as f64 - slope * k as f64)
            .collect();
        let b = median(&mut icpt);
        let gate_ticks = cfg.min_gate_s * f0;
        let mut inl: Vec<(i64, u64)> = pts
            .iter()
            .copied()
            .filter(|&(k, c)| {
                ((c as i128 - anchor as i128) as f64 - slope * k as f64 - b).abs() <= gate_ticks
            })
            .collect();
        inl.sort_by_key(|p| p.0);
        inl.dedup_by_key(|p| p.0);
        let span = inl.last().map(|l| l.0).unwrap_or(0) - inl.first().map(|f| f.0).unwrap_or(0);
        if inl.len() >= 4 && span >= 3 && best.as_ref().is_none_or(|(b, _)| inl.len() > b.len()) {
            let train = Train {
                c0: (anchor as i128 + b.round() as i128) as u64,
                ticks_per_s: slope,
            };
            best = Some((inl, train));
        }
    }
    best
}

/// The largest value with at least two votes (one vote when it is the only
/// one).
fn best_supported(votes: impl Iterator<Item = i64>) -> Option<i64> {
    let mut v: Vec<i64> = votes.collect();
    if v.is_empty() {
        return None;
    }
    if v.len() == 1 {
        return Some(v[0]);
    }
    v.sort_unstable();
    let mut best = None;
    let mut i = 0;
    while i < v.len() {
        let mut j = i;
        while j < v.len() && v[j] == v[i] {
            j += 1;
        }
        if j - i >= 2 {
            best = Some(v[i]);
        }
        i = j;
    }
    best
}

/// Post-processing estimate at counter `c` from the accepted pulses around
/// it: a least-squares quadratic over the pulses within the smoothing
/// half-window of the two pulses that bracket `c` (seed 001 eq 3 with the
/// offsets of the bracketing pulses replaced by a window fit, which also
/// bridges gaps with the drift seen on both sides). Returns GPS time and
/// the standard deviation (s).
#[derive(Clone, Debug, Default)]
pub(crate) struct Smoother {
    cache_key: Option<(u64, u64)>,
    bracket: (Option<Pulse>, Option<Pulse>),
    cache: Option<(u64, i64, PolyFit, f64, f64)>,
}

impl Smoother {
    pub fn new() -> Self {
        Self::default()
    }

    /// GPS time, error bound, and whether `c` lies in a gap of the pulses
    /// (holdover), at counter `c`.
    pub(crate) fn time_at(&mut self, clock: &PpsClock, c: u64) -> Option<(GpsTime, f64, bool)> {
        let h = &clock.history;
        if h.is_empty() {
            return None;
        }
        let f0 = clock.cfg.counter_hz;
        // Samples come in order: most fall in the cached bracket.
        let cached = self
            .cache_key
            .is_some_and(|(l, r)| r != u64::MAX && l <= c && c < r);
        let (left, right) = if cached {
            (self.bracket.0, self.bracket.1)
        } else {
            let idx = h.partition_point(|p| p.counter <= c);
            (idx.checked_sub(1).map(|i| h[i]), h.get(idx).copied())
        };
        let key = (
            left.map(|p| p.counter).unwrap_or(0),
            right.map(|p| p.counter).unwrap_or(u64::MAX),
        );
        if self.cache_key != Some(key) {
            self.bracket = (left, right);
            let half = clock.cfg.smooth_half_window_s.round() as i64;
            let lo = left.or(right)?.second - half;
            let hi = right.or(left)?.second + half;
            let anchor = left.or(right)?;
            let mut pts: Vec<(f64, f64)> = h
                .iter()
                .filter(|p| p.second >= lo && p.second <= hi)
                .map(|p| {
                    let x = tick_diff(anchor.counter, p.counter) / f0;
                    (x, (p.second - anchor.second) as f64 - x)
                })
                .collect();
            let sm = clock.cfg.sigma_meas();
            let fit_of = |pts: &[(f64, f64)]| {
                let span = pts.last().map(|l| l.0).unwrap_or(0.0)
                    - pts.first().map(|f| f.0).unwrap_or(0.0);
                let deg = if pts.len() >= 10 && span >= 8.0 {
                    2
                } else if pts.len() >= 2 {
                    1
                } else {
                    0
                };
                PolyFit::fit(pts, deg)
            };
            let mut fit = fit_of(&pts)?;
            // Second layer of robustness: drop points far from the fit
            // (MAD scale) and refit once.
            if pts.len() >= 8 {
                let mut res: Vec<f64> = pts.iter().map(|&(x, y)| (y - fit.eval(x)).abs()).collect();
                let mad = median(&mut res) * 1.4826;
                let lim = (5.0 * mad).max(5.0 * sm);
                let before = pts.len();
                pts.retain(|&(x, y)| (y - fit.eval(x)).abs() <= lim);
                if pts.len() < before && pts.len() >= 3 {
                    fit = fit_of(&pts)?;
                }
            }
            let dof = fit.dof() as f64;
            let s2 = fit.sigma().map(|s| s * s).unwrap_or(sm * sm);
            let prior = 4.0;
            let sigma = ((dof * s2 + prior * sm * sm) / (dof + prior))
                .sqrt()
                .max(0.5 * sm);
            // Misfit at the bracketing pulses of a gap: a drift change the
            // quadratic cannot follow shows there first; added to bounds.
            let misfit = match (left, right) {
                (Some(l), Some(r)) if r.second - l.second > 1 => [l, r]
                    .iter()
                    .map(|p| {
                        let x = tick_diff(anchor.counter, p.counter) / f0;
                        ((p.second - anchor.second) as f64 - x - fit.eval(x)).abs()
                    })
                    .fold(0.0, f64::max),
                _ => 0.0,
            };
            self.cache = Some((anchor.counter, anchor.second, fit, sigma, misfit));
            self.cache_key = Some(key);
        }
        let (c_ref, s_ref, fit, sigma, misfit) = self.cache.as_ref()?;
        let x = tick_diff(*c_ref, c) / f0;
        let g = x + fit.eval(x);
        let near = [left, right]
            .iter()
            .flatten()
            .map(|p| tick_diff(p.counter, c).abs() / f0)
            .fold(f64::INFINITY, f64::min);
        let var = sigma * sigma * fit.var_factor(x) + clock.cfg.process_var(near);
        let gap = match (left, right) {
            (Some(l), Some(r)) => r.second - l.second > 1,
            _ => true,
        };
        Some((
            PpsClock::to_gps(*s_ref, g),
            clock.cfg.bound(var.sqrt(), near) + misfit,
            gap,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn votes_pick_the_largest_supported_value() {
        assert_eq!(best_supported([5, 5, 4, 4, 4, 6].into_iter()), Some(5));
        assert_eq!(best_supported([3].into_iter()), Some(3));
        assert_eq!(best_supported([1, 2, 3].into_iter()), None);
    }
}
