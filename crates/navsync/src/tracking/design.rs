//! The carrier-loop phase-error budget and the adaptive bandwidth rule.
//!
//! Budget terms (all in radians at the carrier):
//! - thermal noise jitter, Kaplan & Hegarty 2nd ed. §5.6 (Ward, Betz,
//!   Hegarty): σ_t = √(Bn/(C/N0)·(1 + 1/(2T·C/N0))) for the Costas loop
//!   (360/2π times this in degrees), without the squaring term for a pure
//!   PLL ([`thermal_jitter_rad`]). The budget uses its exact discrete
//!   form 2·Bn·T·v/g², with v and g the arctangent's output variance and
//!   gain at ρ = C/N0·T ([`Discriminator::gain`]): equal to the formula
//!   above at high SNR and still right below threshold for a loop whose
//!   discriminator is normalised by its gain. Bn is the discrete loop's
//!   actual noise bandwidth ([`discrete_bandwidth_factor`]);
//! - oscillator phase noise: the power-law phase PSD f_L² S_y(f)/f² through
//!   the loop's phase-error transfer 1 − H (see [`PhaseErrorModel`]);
//! - aiding error (seed 003 appendix): a random ramp of the Doppler gives
//!   the steady-state error ΔḟΔ/ω_n² for the second-order loop (eq 16), a
//!   held first-order Gauss-Markov Doppler error gives the jitter of eq 22;
//!   for other orders the same error is integrated numerically through the
//!   loop (a third-order loop follows a ramp without steady-state error);
//! - dynamic stress of an unaided loop (Kaplan §5.6): θ_e = (dⁿR/dtⁿ)/ω0ⁿ
//!   for an n-th order loop, with R in radians of carrier phase.
//!
//! The adaptive rule chooses the bandwidth that minimises the predicted
//! RMS phase error √(σ_t² + σ_osc² + σ_aid² + θ_e²) for the current C/N0
//! estimate and aiding statistics, then clamps it and limits its rate of
//! change.

use std::f64::consts::{PI, SQRT_2};

use serde::Serialize;

use super::aiding::AidingStats;
use super::discriminator::Discriminator;
use super::dynamics::DynamicsEnvelope;
use super::loop_filter::{A2, A3, B3, LoopOrder};
use super::oscillator::AllanCoefficients;

/// Ratio of the discrete loop's noise bandwidth (bilinear filter, NCO
/// holding its frequency over the next interval, interval-average phase
/// discriminator) to the nominal Bn: 1/(1 − c·BnT) with c = 2 (first
/// order, exact), 2.25 (second) and 1.83 (third), fitted to
/// [`super::loop_filter::measured_noise_bandwidth`] (within 0.5 % for
/// BnT ≤ 0.1; tested). Infinite where the fit says the loop breaks.
pub fn discrete_bandwidth_factor(order: LoopOrder, bn_t: f64) -> f64 {
    let c = match order {
        LoopOrder::First => 2.0,
        LoopOrder::Second => 2.25,
        LoopOrder::Third => 1.83,
    };
    let d = 1.0 - c * bn_t;
    if d <= 0.05 { f64::INFINITY } else { 1.0 / d }
}

/// Thermal-noise phase jitter (rad), Kaplan & Hegarty §5.6, for a noise
/// bandwidth `bn_hz` (use the discrete loop's actual bandwidth).
pub fn thermal_jitter_rad(disc: Discriminator, bn_hz: f64, cn0_hz: f64, t_s: f64) -> f64 {
    (bn_hz / cn0_hz * disc.squaring_loss(cn0_hz, t_s)).sqrt()
}

/// |1 − H(jω)|² of the analog prototype loop at normalised frequency
/// u = ω/ω0: the phase-error transfer sⁿ/(sⁿ + k_p sⁿ⁻¹ + …) of Kaplan
/// Table 5.6's filters.
pub fn error_transfer_sq(order: LoopOrder, u: f64) -> f64 {
    let u2 = u * u;
    match order {
        LoopOrder::First => u2 / (u2 + 1.0),
        LoopOrder::Second => {
            let re = 1.0 - u2;
            u2 * u2 / (re * re + A2 * A2 * u2)
        }
        LoopOrder::Third => {
            let re = 1.0 - B3 * u2;
            let im = A3 * u - u2 * u;
            u2 * u2 * u2 / (re * re + im * im)
        }
    }
}

/// ∫ f(e^s) ds over s ∈ [ln lo, ln hi] by the trapezoid rule on `n` points.
fn integrate_log(lo: f64, hi: f64, n: usize, f: impl Fn(f64) -> f64) -> f64 {
    let (a, b) = (lo.ln(), hi.ln());
    let h = (b - a) / (n - 1) as f64;
    let mut sum = 0.0;
    for i in 0..n {
        let w = if i == 0 || i == n - 1 { 0.5 } else { 1.0 };
        sum += w * f((a + h * i as f64).exp());
    }
    sum * h
}

/// Loop-order constants of the budget: the oscillator integrals
/// J_k = ∫₀^∞ |1 − H(ju)|² u^−(2+k) du (k = 0, 1, 2 for h0, h−1, h−2),
/// so that σ_osc² = f_L² Σ h_k (2π/ω0)^(k+1) J_k. A first-order loop does
/// not converge for flicker and random-walk FM; its integrals are cut at
/// u = 1e-5 (documented over-estimate, finite for the optimiser).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PhaseErrorModel {
    pub order: LoopOrder,
    j: [f64; 3],
}

impl PhaseErrorModel {
    pub fn new(order: LoopOrder) -> Self {
        let mut j = [0.0; 3];
        for (k, jk) in j.iter_mut().enumerate() {
            *jk = integrate_log(1e-5, 1e5, 4001, |u| {
                error_transfer_sq(order, u) * u.powi(-(1 + k as i32))
            });
        }
        PhaseErrorModel { order, j }
    }

    /// The J_k integrals.
    pub fn oscillator_integrals(&self) -> [f64; 3] {
        self.j
    }

    /// Oscillator-induced phase jitter (rad) for noise bandwidth `bn_hz`.
    pub fn oscillator_jitter_rad(
        &self,
        osc: &AllanCoefficients,
        carrier_hz: f64,
        bn_hz: f64,
    ) -> f64 {
        let w0 = bn_hz / self.order.bn_over_w0();
        let r = 2.0 * PI / w0;
        let var = carrier_hz
            * carrier_hz
            * (osc.h0 * r * self.j[0]
                + osc.h_m1 * r * r * self.j[1]
                + osc.h_m2 * r * r * r * self.j[2]);
        var.sqrt()
    }

    /// Phase jitter (rad) caused by a held first-order Gauss-Markov Doppler
    /// aiding error. Second order: seed 003 eq 22 (with eq 20 for σ_w and
    /// γ = e^{αT/2}·α from eq 21). Other orders: the continuous GM PSD
    /// 2σ_u²α/(ω² + α²) (rad²/s² per rad/s) through |1 − H|²/ω²,
    /// integrated numerically.
    pub fn gm_aiding_jitter_rad(&self, stats: &AidingStats, bn_hz: f64) -> f64 {
        if stats.gm_sd_hz <= 0.0 || stats.gm_tau_s <= 0.0 {
            return 0.0;
        }
        let w0 = bn_hz / self.order.bn_over_w0();
        let sigma_u = 2.0 * PI * stats.gm_sd_hz;
        let alpha = 1.0 / stats.gm_tau_s;
        match self.order {
            LoopOrder::Second => gm_jitter_eq22(sigma_u, alpha, stats.update_period_s.max(0.0), w0),
            order => {
                let lo = 1e-4 * w0.min(alpha);
                let hi = 1e4 * w0.max(alpha);
                let var = integrate_log(lo, hi, 1201, |w| {
                    error_transfer_sq(order, w / w0) / w * 2.0 * sigma_u * sigma_u * alpha
                        / (w * w + alpha * alpha)
                }) / PI;
                var.sqrt()
            }
        }
    }

    /// Steady-state phase error (rad) of a Doppler-rate error `ramp_hz_s`
    /// held over an update period: seed 003 eq 16, Δḟ·2π/ω_n², for the
    /// second order; zero for the third; for the first order the mean of
    /// the frequency error that builds up over the period, 2π·ḟ·T/2/ω0.
    pub fn ramp_bias_rad(&self, ramp_hz_s: f64, update_period_s: f64, bn_hz: f64) -> f64 {
        let w0 = bn_hz / self.order.bn_over_w0();
        let rate = 2.0 * PI * ramp_hz_s.abs();
        match self.order {
            LoopOrder::First => rate * 0.5 * update_period_s / w0,
            LoopOrder::Second => rate / (w0 * w0),
            LoopOrder::Third => 0.0,
        }
    }

    /// Dynamic stress error (rad) of an unaided loop, Kaplan §5.6:
    /// θ_e = (dⁿR/dtⁿ)/ω0ⁿ with R in radians (range × 2π/λ).
    pub fn dynamic_stress_rad(&self, env: &DynamicsEnvelope, wavelength_m: f64, bn_hz: f64) -> f64 {
        let w0 = bn_hz / self.order.bn_over_w0();
        let k = 2.0 * PI / wavelength_m;
        match self.order {
            LoopOrder::First => k * env.rate_mps / w0,
            LoopOrder::Second => k * env.accel_mps2 / (w0 * w0),
            LoopOrder::Third => k * env.jerk_mps3 / (w0 * w0 * w0),
        }
    }

    /// The whole budget at noise bandwidth `bn_hz`.
    pub fn budget(&self, inp: &BudgetInputs, bn_hz: f64) -> ErrorBudget {
        let bn_eff = bn_hz * discrete_bandwidth_factor(self.order, bn_hz * inp.t_coh_s);
        // Discrete form of the thermal jitter: 2·Bn·T times the equivalent
        // noise variance of one interval (Kaplan & Hegarty's formula at
        // high SNR, exact for the gain-normalised arctangent below it).
        let rho = inp.cn0_hz * inp.t_coh_s;
        let thermal =
            (2.0 * bn_eff * inp.t_coh_s * inp.discriminator.equivalent_noise_variance(rho)).sqrt();
        let oscillator = self.oscillator_jitter_rad(&inp.oscillator, inp.carrier_hz, bn_hz);
        let (aiding, mut bias) = match &inp.aiding {
            Some(s) => (
                self.gm_aiding_jitter_rad(s, bn_hz),
                self.ramp_bias_rad(s.ramp_hz_s, s.update_period_s, bn_hz),
            ),
            None => (0.0, 0.0),
        };
        if let Some(env) = &inp.dynamics {
            bias += self.dynamic_stress_rad(env, inp.wavelength_m, bn_hz);
        }
        ErrorBudget {
            bn_hz,
            thermal_rad: thermal,
            oscillator_rad: oscillator,
            aiding_rad: aiding,
            bias_rad: bias,
        }
    }

    /// The bandwidth in `[lo_hz, hi_hz]` with the smallest predicted RMS
    /// phase error: a 64-point logarithmic grid, then golden-section search
    /// around the best point.
    pub fn optimal_bandwidth(&self, inp: &BudgetInputs, lo_hz: f64, hi_hz: f64) -> f64 {
        if hi_hz <= lo_hz {
            return lo_hz;
        }
        let cost = |bn: f64| self.budget(inp, bn).total_rms_rad();
        let n = 64;
        let (la, lb) = (lo_hz.ln(), hi_hz.ln());
        let step = (lb - la) / (n - 1) as f64;
        let mut best = (0usize, f64::INFINITY);
        for i in 0..n {
            let c = cost((la + step * i as f64).exp());
            if c < best.1 {
                best = (i, c);
            }
        }
        let mut a = la + step * (best.0 as f64 - 1.0).max(0.0);
        let mut b = la + step * ((best.0 + 1).min(n - 1) as f64);
        let g = 0.5 * (5f64.sqrt() - 1.0);
        let mut x1 = b - g * (b - a);
        let mut x2 = a + g * (b - a);
        let (mut f1, mut f2) = (cost(x1.exp()), cost(x2.exp()));
        for _ in 0..30 {
            if f1 < f2 {
                b = x2;
                x2 = x1;
                f2 = f1;
                x1 = b - g * (b - a);
                f1 = cost(x1.exp());
            } else {
                a = x1;
                x1 = x2;
                f1 = f2;
                x2 = a + g * (b - a);
                f2 = cost(x2.exp());
            }
        }
        (0.5 * (a + b)).exp()
    }
}

/// Seed 003 eq 22: jitter (rad) of a second-order loop (ζ = 0.707, natural
/// frequency `wn`) driven by a first-order GM Doppler error of standard
/// deviation `sigma_u` (rad/s) and inverse correlation time `alpha`, held
/// over the filter period `t_s` (eq 20: σ_w = σ_u √((1 − e^{−2αT})/T); eq 21:
/// γ = √(e^{αT})·α). For T → 0 it tends to the continuous-time result
/// (σ_w² e^{αT} → 2ασ_u², γ → α).
pub fn gm_jitter_eq22(sigma_u: f64, alpha: f64, t_s: f64, wn: f64) -> f64 {
    let eat = (alpha * t_s).exp();
    let sw2 = if t_s > 0.0 {
        sigma_u * sigma_u * (1.0 - (-2.0 * alpha * t_s).exp()) / t_s
    } else {
        2.0 * alpha * sigma_u * sigma_u
    };
    let gamma = eat.sqrt() * alpha;
    let var = eat * sw2 / (wn.powi(4) + gamma.powi(4))
        * (gamma * gamma / (2.0 * SQRT_2 * wn) + wn / (2.0 * SQRT_2) - gamma / 2.0);
    var.max(0.0).sqrt()
}

/// Everything the budget needs besides the bandwidth.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct BudgetInputs {
    pub t_coh_s: f64,
    pub discriminator: Discriminator,
    /// C/N0 (Hz, linear).
    pub cn0_hz: f64,
    pub carrier_hz: f64,
    pub wavelength_m: f64,
    pub oscillator: AllanCoefficients,
    /// Aiding-error statistics (aided loops).
    pub aiding: Option<AidingStats>,
    /// Line-of-sight dynamics the loop itself must follow (unaided loops).
    pub dynamics: Option<DynamicsEnvelope>,
}

/// The predicted phase-error terms at one bandwidth.
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize)]
pub struct ErrorBudget {
    pub bn_hz: f64,
    pub thermal_rad: f64,
    pub oscillator_rad: f64,
    pub aiding_rad: f64,
    pub bias_rad: f64,
}

impl ErrorBudget {
    /// 1σ jitter (rad).
    pub fn jitter_rad(&self) -> f64 {
        (self.thermal_rad.powi(2) + self.oscillator_rad.powi(2) + self.aiding_rad.powi(2)).sqrt()
    }

    /// RMS phase error including the bias (rad): the adaptive criterion.
    pub fn total_rms_rad(&self) -> f64 {
        (self.jitter_rad().powi(2) + self.bias_rad.powi(2)).sqrt()
    }

    /// Kaplan's rule-of-thumb quantity 3σ + |θ_e| (rad).
    pub fn three_sigma_rad(&self) -> f64 {
        3.0 * self.jitter_rad() + self.bias_rad.abs()
    }
}

/// Settings of the adaptive bandwidth rule.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct AdaptiveConfig {
    pub min_hz: f64,
    pub max_hz: f64,
    /// Upper bound on Bn·T (stability and accuracy of the discrete loop).
    pub max_bn_t: f64,
    /// Largest change of the bandwidth per second, as a factor (2 = it may
    /// double or halve within one second).
    pub slew_per_s: f64,
    /// Seconds between evaluations of the rule.
    pub update_interval_s: f64,
}

impl Default for AdaptiveConfig {
    fn default() -> Self {
        AdaptiveConfig {
            min_hz: 0.5,
            max_hz: 25.0,
            max_bn_t: 0.1,
            slew_per_s: 2.0,
            update_interval_s: 0.1,
        }
    }
}

/// The adaptive bandwidth controller: every `update_interval_s` it moves
/// the bandwidth towards the budget's optimum, within the clamps and the
/// slew limit.
#[derive(Clone, Debug)]
pub struct AdaptiveBandwidth {
    cfg: AdaptiveConfig,
    model: PhaseErrorModel,
    bn_hz: f64,
    target_hz: f64,
    next_update_s: f64,
    last_update_s: Option<f64>,
}

impl AdaptiveBandwidth {
    pub fn new(cfg: AdaptiveConfig, order: LoopOrder, initial_hz: f64) -> Self {
        AdaptiveBandwidth {
            cfg,
            model: PhaseErrorModel::new(order),
            bn_hz: initial_hz,
            target_hz: initial_hz,
            next_update_s: 0.0,
            last_update_s: None,
        }
    }

    pub fn bandwidth_hz(&self) -> f64 {
        self.bn_hz
    }

    /// The unconstrained optimum found at the last evaluation.
    pub fn target_hz(&self) -> f64 {
        self.target_hz
    }

    pub fn model(&self) -> &PhaseErrorModel {
        &self.model
    }

    /// Evaluates the rule at `t_s` if due; returns the (possibly unchanged)
    /// bandwidth.
    pub fn update(&mut self, t_s: f64, inp: &BudgetInputs) -> f64 {
        if t_s < self.next_update_s {
            return self.bn_hz;
        }
        self.next_update_s = t_s + self.cfg.update_interval_s;
        let hi = self.cfg.max_hz.min(self.cfg.max_bn_t / inp.t_coh_s);
        let lo = self.cfg.min_hz.min(hi);
        self.target_hz = self.model.optimal_bandwidth(inp, lo, hi);
        let dt = self.last_update_s.map(|l| t_s - l).unwrap_or(0.0);
        self.last_update_s = Some(t_s);
        let max_step = self.cfg.slew_per_s.powf(dt);
        self.bn_hz = self
            .target_hz
            .clamp(self.bn_hz / max_step, self.bn_hz * max_step)
            .clamp(lo, hi);
        self.bn_hz
    }
}

#[cfg(test)]
mod tests {
    use super::super::loop_filter::measured_noise_bandwidth;
    use super::*;

    #[test]
    fn discrete_factor_matches_the_measured_loop() {
        for order in [LoopOrder::First, LoopOrder::Second, LoopOrder::Third] {
            for bnt in [0.005, 0.02, 0.05, 0.1] {
                let t = 0.001;
                let m = measured_noise_bandwidth(order, bnt / t, t, 100_000) / (bnt / t);
                let f = discrete_bandwidth_factor(order, bnt);
                assert!(
                    (m / f - 1.0).abs() < 0.005,
                    "{order:?} {bnt}: measured {m}, fit {f}"
                );
            }
        }
    }

    #[test]
    fn oscillator_integral_of_second_order_white_fm_is_analytic() {
        // |1−H|²/u² = u²/(1 + u⁴) for a2 = √2: ∫ = π/(2√2). a2 = 1.414 is
        // √2 to 1.5e-4, so the integral agrees to ~1e-4.
        let m = PhaseErrorModel::new(LoopOrder::Second);
        let j0 = m.oscillator_integrals()[0];
        assert!((j0 / (PI / (2.0 * SQRT_2)) - 1.0).abs() < 5e-4, "{j0}");
        // First order: ∫ 1/(1 + u²) du = π/2.
        let j0 = PhaseErrorModel::new(LoopOrder::First).oscillator_integrals()[0];
        assert!((j0 / (PI / 2.0) - 1.0).abs() < 1e-4, "{j0}");
    }

    #[test]
    fn numeric_gm_jitter_matches_eq22_in_the_continuous_limit() {
        // Order 2 uses eq 22; the numeric path of the other orders must give
        // the same number for the second-order transfer when T → 0.
        let m = PhaseErrorModel::new(LoopOrder::Second);
        for (sd, tau, bn) in [(0.1, 5.0, 3.0), (0.5, 0.5, 10.0), (0.05, 50.0, 1.0)] {
            let s = AidingStats {
                ramp_hz_s: 0.0,
                gm_sd_hz: sd,
                gm_tau_s: tau,
                update_period_s: 0.0,
            };
            let eq22 = m.gm_aiding_jitter_rad(&s, bn);
            let w0 = bn / 0.53;
            let (sigma_u, alpha) = (2.0 * PI * sd, 1.0 / tau);
            let lo = 1e-4 * w0.min(alpha);
            let hi = 1e4 * w0.max(alpha);
            let num = (integrate_log(lo, hi, 4001, |w| {
                error_transfer_sq(LoopOrder::Second, w / w0) / w * 2.0 * sigma_u * sigma_u * alpha
                    / (w * w + alpha * alpha)
            }) / PI)
                .sqrt();
            // a2 = 1.414 vs √2 in eq 22: agreement to 1e-3.
            assert!(
                (num / eq22 - 1.0).abs() < 1e-3,
                "{sd} {tau} {bn}: {num} vs {eq22}"
            );
        }
    }

    #[test]
    fn ramp_bias_is_eq16() {
        let m = PhaseErrorModel::new(LoopOrder::Second);
        let w0 = 3.0 / 0.53;
        assert!((m.ramp_bias_rad(1.0, 1.0, 3.0) - 2.0 * PI / (w0 * w0)).abs() < 1e-12);
        assert_eq!(
            PhaseErrorModel::new(LoopOrder::Third).ramp_bias_rad(1.0, 1.0, 3.0),
            0.0
        );
    }

    #[test]
    fn thermal_formula_in_degrees() {
        // Bn = 15 Hz, T = 1 ms, 28 dB-Hz (631 Hz): 15/631·(1 + 1/1.262)
        // = 0.0426 rad², 0.2064 rad = 11.83°.
        let cn0 = 10f64.powf(2.8);
        let s = thermal_jitter_rad(Discriminator::Costas, 15.0, cn0, 0.001).to_degrees();
        let want = 360.0 / (2.0 * PI) * (15.0 / cn0 * (1.0 + 1.0 / (2.0 * 0.001 * cn0))).sqrt();
        assert!((s - want).abs() < 1e-12 && (s - 11.83).abs() < 0.01, "{s}");
    }

    fn inputs(cn0_db: f64, aiding: Option<AidingStats>) -> BudgetInputs {
        BudgetInputs {
            t_coh_s: 0.001,
            discriminator: Discriminator::Costas,
            cn0_hz: 10f64.powf(cn0_db / 10.0),
            carrier_hz: 1575.42e6,
            wavelength_m: 0.190_293_672_798_364_88,
            oscillator: AllanCoefficients::TCXO,
            aiding,
            dynamics: None,
        }
    }

    #[test]
    fn optimum_narrows_with_weak_signals_and_widens_with_poor_aiding() {
        let m = PhaseErrorModel::new(LoopOrder::Second);
        let good = AidingStats {
            ramp_hz_s: 0.05,
            gm_sd_hz: 0.05,
            gm_tau_s: 5.0,
            update_period_s: 1.0,
        };
        let bad = AidingStats {
            ramp_hz_s: 1.0,
            gm_sd_hz: 0.5,
            gm_tau_s: 1.0,
            update_period_s: 1.0,
        };
        let strong = m.optimal_bandwidth(&inputs(45.0, Some(good)), 0.5, 25.0);
        let weak = m.optimal_bandwidth(&inputs(25.0, Some(good)), 0.5, 25.0);
        let weak_bad = m.optimal_bandwidth(&inputs(25.0, Some(bad)), 0.5, 25.0);
        assert!(weak < strong, "{weak} {strong}");
        assert!(weak_bad > weak, "{weak_bad} {weak}");
        // The optimum really is a minimum of the budget.
        let inp = inputs(30.0, Some(good));
        let best = m.optimal_bandwidth(&inp, 0.5, 25.0);
        let c = m.budget(&inp, best).total_rms_rad();
        for f in [0.8, 0.9, 1.1, 1.25] {
            assert!(m.budget(&inp, best * f).total_rms_rad() >= c - 1e-12);
        }
    }

    #[test]
    fn adaptive_rule_is_clamped_and_rate_limited() {
        let cfg = AdaptiveConfig::default();
        let mut a = AdaptiveBandwidth::new(cfg, LoopOrder::Second, 10.0);
        let inp = inputs(
            25.0,
            Some(AidingStats {
                ramp_hz_s: 0.0,
                gm_sd_hz: 0.0,
                gm_tau_s: 1.0,
                update_period_s: 1.0,
            }),
        );
        let mut last = a.update(0.0, &inp);
        assert_eq!(
            last, 10.0,
            "the first evaluation has no elapsed time to slew over"
        );
        let mut t = 0.0;
        for _ in 0..100 {
            t += 0.1;
            let bn = a.update(t, &inp);
            assert!(bn >= last / 2f64.powf(0.1) - 1e-9 && bn <= last * 2f64.powf(0.1) + 1e-9);
            assert!(bn >= cfg.min_hz && bn <= cfg.max_hz);
            last = bn;
        }
        assert!(
            (last - a.target_hz()).abs() < 1e-9,
            "converged to the target {}",
            a.target_hz()
        );
    }
}
