//! Correlator-level simulation of one GPS L1 C/A carrier-tracking channel.
//!
//! Signal model (Kaplan & Hegarty 2nd ed. §5.6; Van Dierendonck 1996):
//! after coherent integration over T with the noise of each I and Q arm
//! normalised to unit variance, the prompt correlation is
//!     I + jQ = A·D·R(ε)·(1/T)∫ e^{jΔφ(t)} dt + n,  A = √(2·C/N0·T),
//! with D the navigation data bit (±1 at 50 bps; integrations are
//! bit-aligned, i.e. bit synchronisation is assumed, so T must divide
//! 20 ms), R(ε) = 1 − |ε| the C/A correlation triangle at code error ε
//! (chips), and Δφ = φ_signal − φ_NCO. The integral is evaluated over
//! sub-intervals of at most 1 ms in which Δφ is linear: each contributes
//! e^{jΔφ_mid}·sinc(δ/2) where δ is the phase change across it. Early and
//! late use R(ε ± d/2) and noise correlated with the prompt's by
//! 1 − d/2 (and 1 − d between them).
//!
//! The signal phase is φ = −2π·R_LOS/λ + φ_osc: the line-of-sight range
//! of a [`Trajectory`] seen towards a [`SatelliteLos`], plus the receiver
//! oscillator's phase noise ([`OscillatorNoise`]). The NCO holds the
//! frequency the channel commands over each interval (phase continuous).
//! An aided channel's NCO frequency is the loop output plus the aiding
//! Doppler −2π·Ṙ/λ (from the navigation solution) corrupted by an
//! [`AidingErrorProcess`].
//!
//! Statistics are taken against the true phase: the interval-mean phase
//! error, referred to the nearest stable point of the discriminator
//! (multiples of π for Costas, 2π for a PLL). A cycle slip is counted when
//! the error comes within a quarter period of a neighbouring stable point.

use std::f64::consts::PI;

use rand::RngExt;
use rand::SeedableRng;
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use serde::Serialize;

use super::aiding::{AidingErrorConfig, AidingErrorProcess};
use super::channel::{BandwidthMode, ChannelConfig, Correlators, TrackingChannel};
use super::design::{BudgetInputs, ErrorBudget, PhaseErrorModel, thermal_jitter_rad};
use super::discriminator::Discriminator;
use super::dynamics::{DynamicsEnvelope, SatelliteLos, Trajectory};
use super::loop_filter::LoopOrder;
use super::oscillator::{AllanCoefficients, OscillatorNoise};
use super::{CARRIER_CYCLES_PER_CA_CHIP, GPS_L1_HZ, SPEED_OF_LIGHT};
use navsync::error::Error;
use navsync::stats::Moments;

/// Everything one simulated tracking run needs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrackConfig {
    pub cn0_dbhz: f64,
    /// Coherent integration time (s): 1–20 ms, dividing 20 ms when the
    /// signal carries data bits.
    pub t_coh_s: f64,
    pub order: LoopOrder,
    pub bandwidth: BandwidthMode,
    pub discriminator: Discriminator,
    /// Navigation data bits at 50 bps (a pilot signal when false). With a
    /// PLL (atan2) discriminator the bits are wiped off (known data).
    pub data_bits: bool,
    pub oscillator: AllanCoefficients,
    pub carrier_hz: f64,
    /// Doppler aiding from the navigation solution.
    pub aided: bool,
    pub aiding_error: AidingErrorConfig,
    pub el_spacing_chips: f64,
    pub dll_bn_hz: f64,
    pub cn0_tau_s: f64,
    /// Normalise the discriminator by its gain at the estimated C/N0 (see
    /// [`ChannelConfig::normalize_gain`]).
    pub normalize_gain: bool,
    pub duration_s: f64,
    /// Statistics start after this (s).
    pub settle_s: f64,
    pub seed: u64,
    /// Record a time series every this many seconds (0: none).
    pub record_interval_s: f64,
}

impl Default for TrackConfig {
    fn default() -> Self {
        TrackConfig {
            cn0_dbhz: 40.0,
            t_coh_s: 0.001,
            order: LoopOrder::Third,
            bandwidth: BandwidthMode::Fixed(15.0),
            discriminator: Discriminator::Costas,
            data_bits: true,
            oscillator: AllanCoefficients::TCXO,
            carrier_hz: GPS_L1_HZ,
            aided: false,
            aiding_error: AidingErrorConfig::None,
            el_spacing_chips: 1.0,
            dll_bn_hz: 0.5,
            cn0_tau_s: 2.0,
            normalize_gain: false,
            duration_s: 60.0,
            settle_s: 2.0,
            seed: 1,
            record_interval_s: 0.0,
        }
    }
}

impl TrackConfig {
    /// Checks the settings; errors name the offending option.
    pub fn validate(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Invalid(m));
        if !(0.000_999..=0.020_001).contains(&self.t_coh_s) {
            return bad(format!(
                "coherent integration {} s is outside 1–20 ms",
                self.t_coh_s
            ));
        }
        let ms = self.t_coh_s * 1000.0;
        if (ms - ms.round()).abs() > 1e-9 {
            return bad(format!(
                "coherent integration {ms} ms must be a whole number of milliseconds"
            ));
        }
        if self.data_bits && (20.0 / ms.round()).fract() != 0.0 {
            return bad(format!(
                "coherent integration {ms} ms does not divide the 20 ms data bit (use 1, 2, 4, 5, 10 or 20 ms, or a pilot signal)"
            ));
        }
        let bn = match self.bandwidth {
            BandwidthMode::Fixed(b) => b,
            BandwidthMode::Adaptive { initial_hz, cfg } => {
                if !(cfg.min_hz > 0.0 && cfg.max_hz >= cfg.min_hz && cfg.slew_per_s >= 1.0) {
                    return bad("adaptive bandwidth needs 0 < min ≤ max and slew ≥ 1".into());
                }
                initial_hz
            }
        };
        if !(bn > 0.0 && bn.is_finite()) {
            return bad(format!("loop bandwidth {bn} Hz must be positive"));
        }
        if !(self.duration_s > self.settle_s && self.settle_s >= 0.0) {
            return bad("duration must exceed the settling time".into());
        }
        if !self.cn0_dbhz.is_finite() {
            return bad("C/N0 must be finite".into());
        }
        Ok(())
    }

    pub fn wavelength_m(&self) -> f64 {
        SPEED_OF_LIGHT / self.carrier_hz
    }
}

/// The signal side: true phase, code error, data bits and noise.
struct SignalSim<'a> {
    traj: &'a dyn Trajectory,
    los: SatelliteLos,
    osc: OscillatorNoise,
    rng: Pcg64Mcg,
    amp: f64,
    t_s: f64,
    sub: usize,
    dt_sub: f64,
    data_bits: bool,
    bit: f64,
    bit_index: i64,
    k_phase: f64,
    /// Signal phase at `t_s` (rad).
    phase: f64,
    nco_phase: f64,
    code_err_chips: f64,
    half_spacing: f64,
    /// Cholesky factor of the E/P/L noise correlation.
    chol: [[f64; 3]; 3],
}

impl<'a> SignalSim<'a> {
    fn new(cfg: &TrackConfig, traj: &'a dyn Trajectory, los: SatelliteLos) -> Self {
        let d = cfg.el_spacing_chips;
        let (r1, r2) = (1.0 - 0.5 * d, (1.0 - d).max(0.0));
        // Cholesky of [[1, r1, r2], [r1, 1, r1], [r2, r1, 1]].
        let l10 = r1;
        let l11 = (1.0 - r1 * r1).sqrt();
        let l20 = r2;
        let l21 = (r1 - l20 * l10) / l11;
        let l22 = (1.0 - l20 * l20 - l21 * l21).max(0.0).sqrt();
        let sub = ((cfg.t_coh_s / 1e-3).round() as usize).max(1);
        let k_phase = -2.0 * PI / cfg.wavelength_m();
        let k0 = traj.kinematics(0.0);
        let mut sim = SignalSim {
            traj,
            los,
            osc: OscillatorNoise::new(cfg.oscillator, cfg.carrier_hz, cfg.seed ^ 0x05c1_11a7),
            rng: Pcg64Mcg::seed_from_u64(cfg.seed),
            amp: (2.0 * 10f64.powf(cfg.cn0_dbhz / 10.0) * cfg.t_coh_s).sqrt(),
            t_s: 0.0,
            sub,
            dt_sub: cfg.t_coh_s / sub as f64,
            data_bits: cfg.data_bits && cfg.discriminator == Discriminator::Costas,
            bit: 1.0,
            bit_index: -1,
            k_phase,
            phase: 0.0,
            nco_phase: 0.0,
            code_err_chips: 0.0,
            half_spacing: 0.5 * d,
            chol: [[1.0, 0.0, 0.0], [l10, l11, 0.0], [l20, l21, l22]],
        };
        sim.phase = k_phase * los.state(0.0, &k0).range_m;
        sim.nco_phase = sim.phase;
        sim
    }

    /// Geometric signal phase (rad) and its rate (rad/s) at `t`.
    fn geometric(&self, t: f64) -> (f64, f64, f64) {
        let s = self.los.state(t, &self.traj.kinematics(t));
        (
            self.k_phase * s.range_m,
            self.k_phase * s.rate_mps,
            self.k_phase * s.accel_mps2,
        )
    }

    /// Integrates one coherent interval with the NCO at `nco_freq` (rad/s)
    /// and the code NCO corrected by `code_corr` (chips/s). Returns the
    /// correlations and the true interval-mean phase error (rad, continuous).
    fn integrate(&mut self, nco_freq: f64, code_corr: f64) -> (Correlators, f64) {
        let mut re = 0.0;
        let mut im = 0.0;
        let mut err_sum = 0.0;
        let mut signal_phase_change = 0.0;
        let t0 = self.t_s;
        let mut err0 = self.phase - self.nco_phase;
        for m in 0..self.sub {
            let t1 = t0 + (m + 1) as f64 * self.dt_sub;
            let phase1 = self.geometric(t1).0 + self.osc.step(self.dt_sub);
            let nco1 = self.nco_phase + nco_freq * self.dt_sub;
            let err1 = phase1 - nco1;
            let mid = 0.5 * (err0 + err1);
            let half = 0.5 * (err1 - err0);
            let sinc = if half.abs() < 1e-8 {
                1.0
            } else {
                half.sin() / half
            };
            re += mid.cos() * sinc;
            im += mid.sin() * sinc;
            err_sum += mid;
            signal_phase_change += phase1 - self.phase;
            self.phase = phase1;
            self.nco_phase = nco1;
            err0 = err1;
        }
        let n = self.sub as f64;
        let (re, im) = (re / n, im / n);
        let t_coh = self.dt_sub * n;
        self.t_s = t0 + t_coh;
        // Code error: carrier-aided code NCO (1 chip per 1540 carrier
        // cycles) plus the DLL correction.
        let freq_err = (signal_phase_change - nco_freq * t_coh) / (2.0 * PI);
        let eps = self.code_err_chips;
        self.code_err_chips += freq_err / CARRIER_CYCLES_PER_CA_CHIP - code_corr * t_coh;
        // Data bit of this interval (integrations are bit-aligned).
        if self.data_bits {
            let idx = (t0 / 0.02 + 1e-9).floor() as i64;
            if idx != self.bit_index {
                self.bit_index = idx;
                self.bit = if self.rng.random::<bool>() { 1.0 } else { -1.0 };
            }
        }
        let tri = |x: f64| (1.0 - x.abs()).max(0.0);
        let gains = [
            tri(eps + self.half_spacing),
            tri(eps),
            tri(eps - self.half_spacing),
        ];
        let mut out = [[0.0; 2]; 3];
        for (arm, phasor) in [re, im].into_iter().enumerate() {
            let w: [f64; 3] = [
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
            ];
            for k in 0..3 {
                let noise: f64 = (0..=k).map(|j| self.chol[k][j] * w[j]).sum();
                out[k][arm] = self.amp * self.bit * gains[k] * phasor + noise;
            }
        }
        (
            Correlators {
                early: out[0],
                prompt: out[1],
                late: out[2],
            },
            err_sum / n,
        )
    }
}

/// One point of a recorded time series.
#[derive(Copy, Clone, Debug, Serialize)]
pub struct TrackSample {
    pub t_s: f64,
    pub phase_error_deg: f64,
    pub bn_hz: f64,
    pub cn0_est_dbhz: f64,
    pub aiding_error_hz: f64,
}

/// What a run measured.
#[derive(Clone, Debug, Serialize)]
pub struct TrackResult {
    pub cn0_dbhz: f64,
    /// Seconds of statistics (after settling).
    pub seconds: f64,
    pub jitter_deg: f64,
    pub bias_deg: f64,
    pub rms_deg: f64,
    pub max_abs_deg: f64,
    /// 3σ + |bias| (deg): Kaplan's rule-of-thumb quantity.
    pub three_sigma_deg: f64,
    pub slips: usize,
    pub slips_per_min: f64,
    pub lock_fraction: f64,
    pub cn0_est_dbhz: f64,
    pub bn_mean_hz: f64,
    pub bn_min_hz: f64,
    pub bn_max_hz: f64,
    /// The budget's prediction at the mean bandwidth and the true C/N0
    /// (aiding statistics at t = 0).
    pub predicted: ErrorBudget,
    /// Kaplan & Hegarty's thermal-noise jitter formula at the nominal mean
    /// bandwidth and the true C/N0 (deg).
    pub kaplan_thermal_deg: f64,
    pub series: Vec<TrackSample>,
}

/// Runs one simulated tracking channel over `traj` towards `los`.
pub fn run(
    cfg: &TrackConfig,
    traj: &dyn Trajectory,
    los: &SatelliteLos,
) -> Result<TrackResult, Error> {
    cfg.validate()?;
    let lambda = cfg.wavelength_m();
    let t = cfg.t_coh_s;
    let dynamics = if cfg.aided {
        None
    } else {
        Some(DynamicsEnvelope::scan(
            traj,
            los,
            cfg.duration_s.min(traj.duration_s()),
            0.01,
        ))
    };
    let ch_cfg = ChannelConfig {
        t_coh_s: t,
        order: cfg.order,
        bandwidth: cfg.bandwidth,
        discriminator: cfg.discriminator,
        carrier_hz: cfg.carrier_hz,
        wavelength_m: lambda,
        oscillator: cfg.oscillator,
        el_spacing_chips: cfg.el_spacing_chips,
        dll_bn_hz: cfg.dll_bn_hz,
        cn0_tau_s: cfg.cn0_tau_s,
        dynamics,
        normalize_gain: cfg.normalize_gain,
    };
    let mut channel = TrackingChannel::new(ch_cfg);
    let mut signal = SignalSim::new(cfg, traj, *los);
    let mut aid_err = AidingErrorProcess::new(cfg.aiding_error.clone(), cfg.seed ^ 0xa1d1_0000);
    let aid_freq = |sim: &SignalSim, err: &mut AidingErrorProcess, tm: f64| -> (f64, f64) {
        let e = err.error_hz(tm);
        (sim.geometric(tm).1 + 2.0 * PI * e, e)
    };
    // Start in lock: an unaided loop has learned the Doppler (and its rate).
    let mut last_aid_err = 0.0;
    let mut nco_freq = if cfg.aided {
        let (f, e) = aid_freq(&signal, &mut aid_err, 0.5 * t);
        last_aid_err = e;
        f
    } else {
        let (_, w, wdot) = signal.geometric(0.5 * t);
        channel.set_loop_state(w, wdot);
        w
    };
    let mut code_corr = 0.0;

    let period = cfg.discriminator.ambiguity_rad();
    let n_int = (cfg.duration_s / t).round() as usize;
    let settle_k = (cfg.settle_s / t).round() as usize;
    let mut k_ref: Option<f64> = None;
    let mut slips = 0usize;
    let mut err_stats = Moments::default();
    let mut bn_stats = Moments::default();
    let mut cn0_stats = Moments::default();
    let mut locked = 0usize;
    let mut series = Vec::new();
    let record_every = if cfg.record_interval_s > 0.0 {
        ((cfg.record_interval_s / t).round() as usize).max(1)
    } else {
        0
    };
    for k in 0..n_int {
        let (corr, err) = signal.integrate(nco_freq, code_corr);
        let t_end = (k + 1) as f64 * t;
        let stats = cfg.aided.then(|| aid_err.stats_at(t_end));
        let step = channel.push(t_end, &corr, stats);
        code_corr = step.code_corr_chips_s;
        nco_freq = step.loop_freq_rad_s;
        if cfg.aided {
            let (f, e) = aid_freq(&signal, &mut aid_err, t_end + 0.5 * t);
            nco_freq += f;
            last_aid_err = e;
        }
        if k + 1 < settle_k {
            continue;
        }
        // Cycle slips: the error settles within a quarter period of another
        // stable point (hysteresis), or has left its own by more than a
        // period (a runaway loop counts every point passed).
        let nearest = (err / period).round();
        let kr = k_ref.get_or_insert(nearest);
        if nearest != *kr
            && ((err - nearest * period).abs() < 0.25 * period
                || (err - *kr * period).abs() > period)
        {
            slips += (nearest - *kr).abs() as usize;
            *kr = nearest;
        }
        let resid = err - *kr * period;
        err_stats.push(resid.to_degrees());
        bn_stats.push(step.bn_hz);
        if let Some(c) = step.cn0_dbhz {
            cn0_stats.push(c);
        }
        locked += usize::from(channel.locked());
        if record_every > 0 && (k + 1) % record_every == 0 {
            series.push(TrackSample {
                t_s: t_end,
                phase_error_deg: resid.to_degrees(),
                bn_hz: step.bn_hz,
                cn0_est_dbhz: step.cn0_dbhz.unwrap_or(f64::NAN),
                aiding_error_hz: last_aid_err,
            });
        }
    }
    let seconds = err_stats.n as f64 * t;
    let model = PhaseErrorModel::new(cfg.order, t);
    let predicted = model.budget(
        &BudgetInputs {
            t_coh_s: t,
            discriminator: cfg.discriminator,
            cn0_hz: 10f64.powf(cfg.cn0_dbhz / 10.0),
            carrier_hz: cfg.carrier_hz,
            wavelength_m: lambda,
            oscillator: cfg.oscillator,
            aiding: cfg.aided.then(|| cfg.aiding_error.stats_at(0.0)),
            dynamics,
        },
        bn_stats.mean(),
    );
    let jitter = err_stats.std();
    let bias = err_stats.mean();
    let kaplan_thermal_deg = thermal_jitter_rad(
        cfg.discriminator,
        bn_stats.mean(),
        10f64.powf(cfg.cn0_dbhz / 10.0),
        t,
    )
    .to_degrees();
    Ok(TrackResult {
        cn0_dbhz: cfg.cn0_dbhz,
        seconds,
        jitter_deg: jitter,
        bias_deg: bias,
        rms_deg: err_stats.rms(),
        max_abs_deg: err_stats.max_abs,
        three_sigma_deg: 3.0 * jitter + bias.abs(),
        slips,
        slips_per_min: slips as f64 / (seconds / 60.0),
        lock_fraction: locked as f64 / err_stats.n.max(1) as f64,
        cn0_est_dbhz: cn0_stats.mean(),
        bn_mean_hz: bn_stats.mean(),
        bn_min_hz: bn_stats.min,
        bn_max_hz: bn_stats.max,
        predicted,
        kaplan_thermal_deg,
        series,
    })
}

/// Runs `cfg` at every C/N0 of `cn0s` (in parallel). Every point uses the
/// same seed (common random numbers: the same noise, oscillator and aiding
/// realisations), so curves and configurations compare point by point.
pub fn sweep(
    cfg: &TrackConfig,
    cn0s: &[f64],
    traj: &dyn Trajectory,
    los: &SatelliteLos,
) -> Result<Vec<TrackResult>, Error> {
    cn0s.par_iter()
        .map(|&c| {
            let mut p = cfg.clone();
            p.cn0_dbhz = c;
            run(&p, traj, los)
        })
        .collect()
}

/// A tracking threshold read off a C/N0 sweep.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct Threshold {
    /// The C/N0 (dB-Hz) where the criterion is crossed (linear
    /// interpolation between the last failing and the first passing point).
    pub dbhz: f64,
    /// The criterion held down to the lowest C/N0 tried: the threshold is
    /// at or below `dbhz`.
    pub at_or_below: bool,
    /// The criterion failed even at the highest C/N0 tried.
    pub above_range: bool,
}

/// The lowest C/N0 above which every point of the sweep has
/// `metric < limit`.
pub fn threshold(
    results: &[TrackResult],
    metric: impl Fn(&TrackResult) -> f64,
    limit: f64,
) -> Option<Threshold> {
    let mut pts: Vec<(f64, f64)> = results.iter().map(|r| (r.cn0_dbhz, metric(r))).collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (&first, &last) = (pts.first()?, pts.last()?);
    // NaN (no statistics) fails.
    let fails = |m: f64| m.is_nan() || m >= limit;
    let Some(i) = pts.iter().rposition(|p| fails(p.1)) else {
        return Some(Threshold {
            dbhz: first.0,
            at_or_below: true,
            above_range: false,
        });
    };
    if i + 1 == pts.len() {
        return Some(Threshold {
            dbhz: last.0,
            at_or_below: false,
            above_range: true,
        });
    }
    let (f, p) = (pts[i], pts[i + 1]);
    let dbhz = if f.1.is_finite() && f.1 > p.1 {
        p.0 - (p.0 - f.0) * (limit - p.1) / (f.1 - p.1)
    } else {
        p.0
    };
    Some(Threshold {
        dbhz,
        at_or_below: false,
        above_range: false,
    })
}

/// Kaplan's rule of thumb: 3σ + |bias| below a quarter of the pull-in range.
pub fn threshold_three_sigma(results: &[TrackResult], disc: Discriminator) -> Option<Threshold> {
    threshold(results, |r| r.three_sigma_deg, disc.threshold_deg())
}

/// Fewer than one cycle slip per minute.
pub fn threshold_slips(results: &[TrackResult]) -> Option<Threshold> {
    threshold(results, |r| r.slips_per_min, 1.0)
}

#[cfg(test)]
mod tests {
    use super::super::aiding::AidingStats;
    use super::super::design::AdaptiveConfig;
    use super::super::dynamics::{LandVehicleOptions, LandVehicleProfile, StaticTrajectory};
    use super::super::scenario::varying_aiding;
    use super::*;

    fn static_los() -> SatelliteLos {
        SatelliteLos::from_elevation_azimuth(0.5, 0.3, 0.0, 0.0)
    }

    fn land() -> (LandVehicleProfile, SatelliteLos) {
        let p = LandVehicleProfile::new(&LandVehicleOptions {
            duration_s: 121.0,
            seed: 1,
            ..Default::default()
        });
        (
            p,
            SatelliteLos::from_elevation_azimuth(
                30f64.to_radians(),
                45f64.to_radians(),
                300.0,
                0.1,
            ),
        )
    }

    /// Done-when: thermal jitter within ±5 % of Kaplan & Hegarty's formula
    /// at ≥ 40 dB-Hz and at most 25 % above it at 30 dB-Hz. Static receiver,
    /// perfect oscillator, unaided 2nd-order loop at 10 Hz, T = 1 ms. 150 s
    /// give ≈ 3000 independent error samples (correlation time ≈ 1/(2Bn)):
    /// the jitter estimate's relative σ is ≈ 1.3 %, and the discrete loop's
    /// bandwidth is 2.3 % above nominal (jitter +1.1 %): ±5 % is > 3σ.
    #[test]
    fn thermal_jitter_follows_the_standard_formula() {
        let base = TrackConfig {
            order: LoopOrder::Second,
            bandwidth: BandwidthMode::Fixed(10.0),
            oscillator: AllanCoefficients::IDEAL,
            duration_s: 150.0,
            ..Default::default()
        };
        let rs = sweep(&base, &[30.0, 40.0, 45.0], &StaticTrajectory, &static_los()).unwrap();
        for r in &rs {
            let f = thermal_jitter_rad(
                Discriminator::Costas,
                10.0,
                10f64.powf(r.cn0_dbhz / 10.0),
                0.001,
            )
            .to_degrees();
            let ratio = r.jitter_deg / f;
            if r.cn0_dbhz >= 40.0 {
                assert!(
                    (ratio - 1.0).abs() < 0.05,
                    "{} dB-Hz: {} vs {f}",
                    r.cn0_dbhz,
                    r.jitter_deg
                );
            } else {
                assert!(
                    ratio > 0.95 && ratio < 1.25,
                    "{} dB-Hz: ratio {ratio}",
                    r.cn0_dbhz
                );
            }
            assert_eq!(r.slips, 0);
            assert!(
                (r.cn0_est_dbhz - r.cn0_dbhz).abs() < 0.3,
                "C/N0 estimate {}",
                r.cn0_est_dbhz
            );
        }
    }

    /// Done-when: a 1 Hz/s aiding ramp gives a bias within ±5 % of θ''/ω_n²
    /// (seed 003 eq 16) in the aided second-order loop. At 60 dB-Hz with a
    /// perfect oscillator the jitter is 0.1°, its mean over 20 s known to
    /// 0.01°; the bias is 11.2°. A third-order loop removes it.
    #[test]
    fn aiding_ramp_bias_is_eq16() {
        let base = TrackConfig {
            cn0_dbhz: 60.0,
            order: LoopOrder::Second,
            bandwidth: BandwidthMode::Fixed(3.0),
            oscillator: AllanCoefficients::IDEAL,
            aided: true,
            aiding_error: AidingErrorConfig::ConstantRamp { rate_hz_s: 1.0 },
            duration_s: 20.0,
            settle_s: 5.0,
            ..Default::default()
        };
        let r = run(&base, &StaticTrajectory, &static_los()).unwrap();
        let wn = 3.0 / 0.53;
        let want = -(2.0 * PI / (wn * wn)).to_degrees();
        assert!(
            (r.bias_deg / want - 1.0).abs() < 0.05,
            "bias {} vs {want}",
            r.bias_deg
        );
        let third = run(
            &TrackConfig {
                order: LoopOrder::Third,
                ..base
            },
            &StaticTrajectory,
            &static_los(),
        )
        .unwrap();
        assert!(
            third.bias_deg.abs() < 0.3,
            "third-order bias {}",
            third.bias_deg
        );
    }

    /// The budget's aiding-error term (eq 22) against the simulation: a
    /// held GM Doppler error of 0.5 Hz, τ = 1 s, updated every 0.1 s, at
    /// 50 dB-Hz (thermal 0.5°). 100 s hold ≈ 100 correlation times of the
    /// aiding error: the jitter estimate's σ is ≈ 7 %; tolerance 20 %.
    #[test]
    fn gauss_markov_aiding_jitter_matches_eq22() {
        let cfg = TrackConfig {
            cn0_dbhz: 50.0,
            order: LoopOrder::Second,
            bandwidth: BandwidthMode::Fixed(3.0),
            oscillator: AllanCoefficients::IDEAL,
            aided: true,
            aiding_error: AidingErrorConfig::constant(AidingStats {
                ramp_hz_s: 0.0,
                gm_sd_hz: 0.5,
                gm_tau_s: 1.0,
                update_period_s: 0.1,
            }),
            duration_s: 100.0,
            ..Default::default()
        };
        let r = run(&cfg, &StaticTrajectory, &static_los()).unwrap();
        let want = r.predicted.jitter_rad().to_degrees();
        assert!(
            r.predicted.aiding_rad > 3.0 * r.predicted.thermal_rad,
            "aiding must dominate"
        );
        assert!(
            (r.jitter_deg / want - 1.0).abs() < 0.2,
            "jitter {} vs eq 22 {want}",
            r.jitter_deg
        );
    }

    /// Done-when: the adaptive loop's RMS phase error within 10 % of the best
    /// fixed bandwidth across 25–45 dB-Hz, with aiding quality alternating
    /// every 30 s. Same seed for every run (common random numbers), so the
    /// comparison is not noise against noise.
    #[test]
    fn adaptive_is_within_ten_percent_of_the_best_fixed_bandwidth() {
        let (traj, los) = land();
        let base = TrackConfig {
            order: LoopOrder::Second,
            bandwidth: BandwidthMode::Adaptive {
                cfg: AdaptiveConfig::default(),
                initial_hz: 5.0,
            },
            aided: true,
            aiding_error: varying_aiding(30.0, 60.0),
            normalize_gain: true,
            duration_s: 60.0,
            ..Default::default()
        };
        let cn0s = [25.0, 35.0, 45.0];
        let adaptive = sweep(&base, &cn0s, &traj, &los).unwrap();
        let mut best = [f64::INFINITY; 3];
        for bw in [1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 18.0] {
            let cfg = TrackConfig {
                bandwidth: BandwidthMode::Fixed(bw),
                normalize_gain: false,
                ..base.clone()
            };
            for (b, r) in best
                .iter_mut()
                .zip(sweep(&cfg, &cn0s, &traj, &los).unwrap())
            {
                *b = b.min(r.rms_deg);
            }
        }
        for (a, b) in adaptive.iter().zip(best) {
            assert!(
                a.rms_deg < 1.1 * b,
                "{} dB-Hz: adaptive {} vs best fixed {b}",
                a.cn0_dbhz,
                a.rms_deg
            );
        }
        // It does adapt: wider with strong signals.
        assert!(adaptive[2].bn_mean_hz > 2.0 * adaptive[0].bn_mean_hz);
    }

    /// The threshold ordering of the done-when (land vehicle, jerk ≤ 1 g/s):
    /// at C/N0 values between the two thresholds measured by `navsync track`
    /// (T = 1 ms: 27 vs 31 dB-Hz; T = 20 ms: 21 vs 28 dB-Hz) the INS-aided
    /// 3 Hz loop holds 3σ + |bias| ≤ 45° without slips while the unaided
    /// 15 Hz third-order loop does not.
    #[test]
    fn aided_narrow_loop_tracks_where_the_unaided_loop_fails() {
        let (traj, los) = land();
        for (t_coh, cn0) in [(0.001, 28.5), (0.02, 24.0)] {
            let unaided = TrackConfig {
                cn0_dbhz: cn0,
                t_coh_s: t_coh,
                duration_s: 120.0,
                ..Default::default()
            };
            let aided = TrackConfig {
                order: LoopOrder::Second,
                bandwidth: BandwidthMode::Fixed(3.0),
                aided: true,
                aiding_error: AidingErrorConfig::constant(AidingStats {
                    ramp_hz_s: 0.05,
                    gm_sd_hz: 0.05,
                    gm_tau_s: 5.0,
                    update_period_s: 1.0,
                }),
                ..unaided.clone()
            };
            let u = run(&unaided, &traj, &los).unwrap();
            let a = run(&aided, &traj, &los).unwrap();
            assert!(
                a.three_sigma_deg < 45.0 && a.slips == 0,
                "T {t_coh}: aided {} {}",
                a.three_sigma_deg,
                a.slips
            );
            assert!(
                u.three_sigma_deg > 45.0,
                "T {t_coh}: unaided {}",
                u.three_sigma_deg
            );
        }
    }

    #[test]
    fn thresholds_are_read_off_a_sweep() {
        let mk = |c: f64, m: f64| TrackResult {
            cn0_dbhz: c,
            seconds: 1.0,
            jitter_deg: m / 3.0,
            bias_deg: 0.0,
            rms_deg: 0.0,
            max_abs_deg: 0.0,
            three_sigma_deg: m,
            slips: 0,
            slips_per_min: 0.0,
            lock_fraction: 1.0,
            cn0_est_dbhz: c,
            bn_mean_hz: 1.0,
            bn_min_hz: 1.0,
            bn_max_hz: 1.0,
            predicted: ErrorBudget::default(),
            kaplan_thermal_deg: 0.0,
            series: Vec::new(),
        };
        let rs = vec![
            mk(30.0, 20.0),
            mk(25.0, 65.0),
            mk(20.0, 200.0),
            mk(27.0, 40.0),
            mk(26.0, 50.0),
        ];
        let t = threshold_three_sigma(&rs, Discriminator::Costas).unwrap();
        assert!((t.dbhz - 26.5).abs() < 1e-9 && !t.at_or_below && !t.above_range);
        let all_good = vec![mk(30.0, 20.0), mk(25.0, 30.0)];
        assert!(
            threshold_three_sigma(&all_good, Discriminator::Costas)
                .unwrap()
                .at_or_below
        );
        let all_bad = vec![mk(30.0, 50.0), mk(25.0, 60.0)];
        assert!(
            threshold_three_sigma(&all_bad, Discriminator::Costas)
                .unwrap()
                .above_range
        );
        assert!(threshold_slips(&[]).is_none());
    }

    #[test]
    fn invalid_settings_are_rejected() {
        let ok = TrackConfig::default();
        assert!(ok.validate().is_ok());
        let t3 = TrackConfig {
            t_coh_s: 0.003,
            ..ok.clone()
        };
        assert!(
            t3.validate()
                .unwrap_err()
                .to_string()
                .contains("20 ms data bit")
        );
        assert!(
            TrackConfig {
                data_bits: false,
                ..t3
            }
            .validate()
            .is_ok()
        );
        assert!(
            TrackConfig {
                t_coh_s: 0.05,
                ..ok.clone()
            }
            .validate()
            .is_err()
        );
        assert!(
            TrackConfig {
                t_coh_s: 0.0015,
                data_bits: false,
                ..ok.clone()
            }
            .validate()
            .is_err()
        );
        assert!(
            TrackConfig {
                bandwidth: BandwidthMode::Fixed(-1.0),
                ..ok.clone()
            }
            .validate()
            .is_err()
        );
        assert!(
            TrackConfig {
                settle_s: 100.0,
                ..ok
            }
            .validate()
            .is_err()
        );
    }
}
