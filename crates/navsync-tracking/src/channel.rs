//! The receiver side of one tracking channel, streaming: push the
//! correlator outputs of each coherent interval, get the NCO commands for
//! the next. Carrier: Costas or PLL discriminator → loop filter (fixed or
//! adaptive bandwidth) → carrier NCO frequency, to which the caller adds
//! the Doppler aiding of an integrated navigation solution. Code: a
//! carrier-aided first-order DLL on the normalised early-minus-late
//! envelope. Also a phase lock indicator and a C/N0 estimate.

use serde::Serialize;

use super::aiding::AidingStats;
use super::design::{AdaptiveBandwidth, AdaptiveConfig, BudgetInputs};
use super::discriminator::{Cn0Estimator, Discriminator, LockDetector};
use super::dynamics::DynamicsEnvelope;
use super::loop_filter::{LoopFilter, LoopOrder};
use super::oscillator::AllanCoefficients;

/// Fixed or adaptive carrier-loop noise bandwidth.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub enum BandwidthMode {
    Fixed(f64),
    /// Adaptive, starting from `initial_hz`.
    Adaptive {
        cfg: AdaptiveConfig,
        initial_hz: f64,
    },
}

/// One interval's early, prompt and late correlations (I, Q).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub(crate) struct Correlators {
    pub early: [f64; 2],
    pub prompt: [f64; 2],
    pub late: [f64; 2],
}

/// Channel settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChannelConfig {
    pub t_coh_s: f64,
    pub order: LoopOrder,
    pub bandwidth: BandwidthMode,
    pub discriminator: Discriminator,
    pub carrier_hz: f64,
    pub wavelength_m: f64,
    /// The receiver's model of its own oscillator (for the adaptive budget).
    pub oscillator: AllanCoefficients,
    /// Early-to-late spacing (chips).
    pub(crate) el_spacing_chips: f64,
    pub(crate) dll_bn_hz: f64,
    /// Time constant of the C/N0 estimator (s).
    pub(crate) cn0_tau_s: f64,
    /// Line-of-sight dynamics an unaided loop must follow (adaptive budget).
    pub dynamics: Option<DynamicsEnvelope>,
    /// Divide the discriminator output by its mean gain at the estimated
    /// C/N0 ([`Discriminator::gain`]), so that the loop keeps its design
    /// bandwidth below threshold (where the arctangent's gain drops) and the
    /// adaptive budget describes it exactly.
    pub normalize_gain: bool,
}

/// What the channel asks of the NCOs for the next interval.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct ChannelStep {
    /// Loop-filter frequency (rad/s); the NCO runs at this plus the aiding.
    pub(crate) loop_freq_rad_s: f64,
    /// DLL correction of the code rate (chips/s) on top of carrier aiding.
    pub(crate) code_corr_chips_s: f64,
    /// Discriminator output of this interval (rad).
    pub(crate) discriminator_rad: f64,
    /// Bandwidth in force for the next interval (Hz).
    pub bn_hz: f64,
    pub cn0_dbhz: Option<f64>,
    pub(crate) lock_indicator: f64,
}

/// One tracking channel.
#[derive(Clone, Debug)]
pub(crate) struct TrackingChannel {
    cfg: ChannelConfig,
    filter: LoopFilter,
    adaptive: Option<AdaptiveBandwidth>,
    lock: LockDetector,
    cn0: Cn0Estimator,
}

impl TrackingChannel {
    pub(crate) fn new(cfg: ChannelConfig) -> Self {
        let initial = match cfg.bandwidth {
            BandwidthMode::Fixed(b) => b,
            BandwidthMode::Adaptive { initial_hz, .. } => initial_hz,
        };
        let adaptive = match cfg.bandwidth {
            BandwidthMode::Adaptive { cfg: a, initial_hz } => Some(AdaptiveBandwidth::new(
                a,
                cfg.order,
                cfg.t_coh_s,
                initial_hz,
            )),
            BandwidthMode::Fixed(_) => None,
        };
        // Lock detector sums within one 20 ms data bit, smoothed over ~1 s.
        let m = ((0.02 / cfg.t_coh_s).round() as usize).max(1);
        let sums_per_s = 1.0 / (m as f64 * cfg.t_coh_s);
        TrackingChannel {
            filter: LoopFilter::new(cfg.order, initial, cfg.t_coh_s),
            adaptive,
            lock: LockDetector::new(m, sums_per_s, 0.5),
            cn0: Cn0Estimator::new(cfg.t_coh_s, cfg.cn0_tau_s),
            cfg,
        }
    }

    /// Presets the loop's learned frequency and rate (e.g. from acquisition).
    pub(crate) fn set_loop_state(&mut self, freq_rad_s: f64, freq_rate_rad_s2: f64) {
        self.filter.set_state(freq_rad_s, freq_rate_rad_s2);
    }

    pub(crate) fn locked(&self) -> bool {
        self.lock.locked()
    }

    /// Processes the correlations of the interval ending at `t_s`.
    /// `aiding` carries the navigation filter's aiding-error statistics
    /// when the loop is aided.
    pub(crate) fn push(
        &mut self,
        t_s: f64,
        c: &Correlators,
        aiding: Option<AidingStats>,
    ) -> ChannelStep {
        let [i, q] = c.prompt;
        self.lock.push(i, q);
        self.cn0.push(i, q);
        let cn0_hz = self.cn0.cn0_hz();
        if let (Some(a), Some(cn0_hz)) = (self.adaptive.as_mut(), cn0_hz) {
            let inp = BudgetInputs {
                t_coh_s: self.cfg.t_coh_s,
                discriminator: self.cfg.discriminator,
                cn0_hz,
                carrier_hz: self.cfg.carrier_hz,
                wavelength_m: self.cfg.wavelength_m,
                oscillator: self.cfg.oscillator,
                aiding,
                dynamics: if aiding.is_some() {
                    None
                } else {
                    self.cfg.dynamics
                },
            };
            let bn = a.update(t_s, &inp);
            if bn != self.filter.bandwidth_hz() {
                self.filter.set_bandwidth(bn);
            }
        }
        let mut err = self.cfg.discriminator.phase_error(i, q);
        if self.cfg.normalize_gain
            && let Some(c) = cn0_hz
        {
            // Floor 0.1 (ρ ≈ 0.1, 20 dB-Hz at 1 ms): below that the estimate
            // itself is too noisy to scale by.
            err /= self.cfg.discriminator.gain(c * self.cfg.t_coh_s).max(0.1);
        }
        let freq = self.filter.update(err);
        // DLL: ε̂ = (|L| − |E|)/(|L| + |E|)·(2 − d)/2 for a triangular
        // correlation (valid for |ε| < d/2); first-order loop gain 4·Bn.
        let e = c.early[0].hypot(c.early[1]);
        let l = c.late[0].hypot(c.late[1]);
        let d = self.cfg.el_spacing_chips;
        let eps = if e + l > 0.0 {
            (l - e) / (l + e) * (2.0 - d) / 2.0
        } else {
            0.0
        };
        ChannelStep {
            loop_freq_rad_s: freq,
            code_corr_chips_s: 4.0 * self.cfg.dll_bn_hz * eps,
            discriminator_rad: err,
            bn_hz: self.filter.bandwidth_hz(),
            cn0_dbhz: cn0_hz.map(|c| 10.0 * c.log10()),
            lock_indicator: self.lock.indicator(),
        }
    }
}
