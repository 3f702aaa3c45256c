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
//!   actual noise bandwidth ([`PhaseErrorModel::discrete_noise_bandwidth`]);
//! - oscillator phase noise: the power-law phase PSD f_L² S_y(f)/f² through
//!   the discrete loop's phase-error transfer ([`discrete_response`]);
//! - aiding error (seed 003 appendix): a random ramp of the Doppler gives
//!   the steady-state error ΔḟΔ/ω_n² for the second-order loop (eq 16), a
//!   held first-order Gauss-Markov Doppler error gives the jitter of eq 22;
//!   for other orders the same error is integrated numerically through the
//!   loop (a third-order loop follows a ramp without steady-state error);
//!   the continuous-loop results are corrected to the discrete loop that is
//!   actually run (filter, NCO, interval-mean discriminator), which matters
//!   once Bn·T exceeds a few per cent (T = 20 ms);
//! - dynamic stress of an unaided loop (Kaplan §5.6): θ_e = (dⁿR/dtⁿ)/ω0ⁿ
//!   for an n-th order loop, with R in radians of carrier phase.
//!
//! The adaptive rule chooses the bandwidth that minimises the predicted
//! RMS phase error √(σ_t² + σ_osc² + σ_aid² + θ_e²) for the current C/N0
//! estimate and aiding statistics, then clamps it and limits its rate of
//! change.

use std::f64::consts::{PI, SQRT_2};

use nalgebra::{Complex, DMatrix};

use serde::Serialize;

use super::aiding::AidingStats;
use super::discriminator::Discriminator;
use super::dynamics::DynamicsEnvelope;
#[cfg(test)]
use super::loop_filter::{A2, A3, B3};
use super::loop_filter::{LoopCoefficients, LoopOrder};
use super::oscillator::AllanCoefficients;

/// Thermal-noise phase jitter (rad), Kaplan & Hegarty §5.6, for a noise
/// bandwidth `bn_hz` (use the discrete loop's actual bandwidth).
pub fn thermal_jitter_rad(disc: Discriminator, bn_hz: f64, cn0_hz: f64, t_s: f64) -> f64 {
    (bn_hz / cn0_hz * disc.squaring_loss(cn0_hz, t_s)).sqrt()
}

/// |1 − H(jω)|² of the analog prototype loop at normalised frequency
/// u = ω/ω0: the phase-error transfer sⁿ/(sⁿ + k_p sⁿ⁻¹ + …) of Kaplan
/// Table 5.6's filters.
#[cfg(test)]
pub(crate) fn error_transfer_sq(order: LoopOrder, u: f64) -> f64 {
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

/// Closed-loop responses of the discrete loop at angular frequency `w`
/// (rad/s): the loop filter (bilinear integrators B = (T/2)(1 + z⁻¹)/(1 − z⁻¹)),
/// the NCO holding each commanded frequency over the next interval, and a
/// discriminator that sees the interval-mean phase error. With
/// F = k_p + B(k_f + B k_r) and the open loop L = z⁻¹·F·B (NCO phase
/// averaged over the interval: B again, one interval late: z⁻¹), the
/// interval-mean phase error is E = Φ̄/(1 + L) − B·δω/(1 + L) for an input
/// phase Φ̄ and a frequency error δω added to the NCO (an aiding error).
/// Returns (1/(1 + L), −B/(1 + L), L/(1 + L)), the last being the response
/// of the NCO phase to discriminator noise.
pub fn discrete_response(
    order: LoopOrder,
    c: &LoopCoefficients,
    t_s: f64,
    w: f64,
) -> [Complex<f64>; 3] {
    let one = Complex::new(1.0, 0.0);
    let x = Complex::from_polar(1.0, -w * t_s);
    let b = (one + x) / (one - x) * (0.5 * t_s);
    let f = match order {
        LoopOrder::First => one * c.k_phase,
        LoopOrder::Second => b * c.k_freq + c.k_phase,
        LoopOrder::Third => b * (b * c.k_rate + c.k_freq) + c.k_phase,
    };
    let l = x * f * b;
    let e = one / (one + l);
    [e, -b * e, l * e]
}

/// True when the discrete loop is stable: every root of its characteristic
/// polynomial 1 + L(z) = 0 lies inside the unit circle. With x = z⁻¹ and
/// h = T/2 the polynomial is (1 − x)ⁿ + h x (1 + x)·P(x), P = k_p (n = 1),
/// k_p(1 − x) + k_f h(1 + x) (n = 2), k_p(1 − x)² + k_f h(1 − x²) + k_r h²(1 + x)²
/// (n = 3); its roots in x must lie outside the unit circle.
pub(crate) fn discrete_loop_is_stable(order: LoopOrder, bn_hz: f64, t_s: f64) -> bool {
    let c = LoopCoefficients::new(order, bn_hz);
    let h = 0.5 * t_s;
    let mul = |a: &[f64], b: &[f64]| {
        let mut out = vec![0.0; a.len() + b.len() - 1];
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                out[i + j] += x * y;
            }
        }
        out
    };
    let add = |a: &[f64], b: &[f64]| {
        let mut out = vec![0.0; a.len().max(b.len())];
        for (i, x) in a.iter().enumerate() {
            out[i] += x;
        }
        for (i, x) in b.iter().enumerate() {
            out[i] += x;
        }
        out
    };
    let scale = |a: &[f64], k: f64| a.iter().map(|v| v * k).collect::<Vec<f64>>();
    let (p1, m1) = ([1.0, 1.0], [1.0, -1.0]);
    let (mn, p) = match order {
        LoopOrder::First => (m1.to_vec(), vec![c.k_phase]),
        LoopOrder::Second => (
            mul(&m1, &m1),
            add(&scale(&m1, c.k_phase), &scale(&p1, c.k_freq * h)),
        ),
        LoopOrder::Third => {
            let m2 = mul(&m1, &m1);
            let p = add(
                &add(&scale(&m2, c.k_phase), &scale(&mul(&p1, &m1), c.k_freq * h)),
                &scale(&mul(&p1, &p1), c.k_rate * h * h),
            );
            (mul(&m2, &m1), p)
        }
    };
    // h·x·(1 + x)·P(x)
    let tail = scale(&mul(&[0.0, 1.0, 1.0], &p), h);
    let mut poly = add(&mn, &tail);
    while poly.len() > 1 && poly.last().is_some_and(|v| v.abs() < 1e-300) {
        poly.pop();
    }
    let n = poly.len() - 1;
    if n == 0 {
        return true;
    }
    // Roots in z = 1/x are the roots of the reversed polynomial: companion matrix.
    let lead = poly[0];
    let mut m = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        m[(0, i)] = -poly[i + 1] / lead;
        if i + 1 < n {
            m[(i + 1, i)] = 1.0;
        }
    }
    m.complex_eigenvalues()
        .iter()
        .all(|z| z.norm() < 1.0 - 1e-9)
}

/// ∫ f(e^s)·e^s ds = ∫ f(u) du over u ∈ [lo, hi], trapezoid on a log grid.
fn integrate_du(lo: f64, hi: f64, n: usize, f: impl Fn(f64) -> f64) -> f64 {
    integrate_log(lo, hi, n, |u| f(u) * u)
}

/// Bandwidth grid of the model's tables: 0.02–400 Hz, 30 points per decade.
const GRID_LO_HZ: f64 = 0.02;
const GRID_HI_HZ: f64 = 400.0;
const GRID_PER_DECADE: f64 = 30.0;

/// Tables of one loop order and coherent time, shared by every model.
#[derive(Debug)]
struct LoopTables {
    /// ln of the grid bandwidths.
    ln_bn: Vec<f64>,
    /// Discrete noise bandwidth (Hz); ∞ where unstable.
    bn_eff: Vec<f64>,
    /// ∫|E|² sinc²(πfT) f^−(2+k) df for k = 0, 1, 2 (oscillator, per unit
    /// h_k and unit carrier frequency); ∞ where unstable.
    osc: Vec<[f64; 3]>,
}

impl LoopTables {
    fn build(order: LoopOrder, t_coh_s: f64) -> Self {
        let n = ((GRID_HI_HZ / GRID_LO_HZ).log10() * GRID_PER_DECADE).round() as usize + 1;
        let (a, b) = (GRID_LO_HZ.ln(), GRID_HI_HZ.ln());
        let ln_bn: Vec<f64> = (0..n)
            .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
            .collect();
        let nyq = PI / t_coh_s;
        let mut bn_eff = Vec::with_capacity(n);
        let mut osc = Vec::with_capacity(n);
        for &lb in &ln_bn {
            let bn = lb.exp();
            if !discrete_loop_is_stable(order, bn, t_coh_s) {
                bn_eff.push(f64::INFINITY);
                osc.push([f64::INFINITY; 3]);
                continue;
            }
            let c = LoopCoefficients::new(order, bn);
            // Noise bandwidth ∫₀^{1/2T} |L/(1+L)|² df (= Σh²/2T).
            let be = integrate_du(1e-6 * c.w0.min(nyq), nyq, 1201, |w| {
                discrete_response(order, &c, t_coh_s, w)[2].norm_sqr()
            }) / (2.0 * PI);
            bn_eff.push(be);
            // Oscillator: f from 1e-5·ω0/2π to 200/T (sinc² and f⁻² make the
            // rest negligible); one pass for the three power laws.
            let (lo, hi) = (1e-5 * c.w0 / (2.0 * PI), 200.0 / t_coh_s);
            let m = 1601;
            let (la, lb2) = (lo.ln(), hi.ln());
            let h = (lb2 - la) / (m - 1) as f64;
            let mut o = [0.0; 3];
            for i in 0..m {
                let f = (la + h * i as f64).exp();
                let wgt = if i == 0 || i == m - 1 { 0.5 } else { 1.0 };
                let x = PI * f * t_coh_s;
                let sinc2 = if x < 1e-8 { 1.0 } else { (x.sin() / x).powi(2) };
                let g =
                    discrete_response(order, &c, t_coh_s, 2.0 * PI * f)[0].norm_sqr() * sinc2 / f;
                o[0] += wgt * g;
                o[1] += wgt * g / f;
                o[2] += wgt * g / (f * f);
            }
            osc.push(o.map(|v| v * h));
        }
        LoopTables { ln_bn, bn_eff, osc }
    }

    /// The tables of (order, T), built once per process.
    fn shared(order: LoopOrder, t_coh_s: f64) -> std::sync::Arc<LoopTables> {
        type Cache = std::sync::Mutex<Vec<((u32, u64), std::sync::Arc<LoopTables>)>>;
        static CACHE: std::sync::OnceLock<Cache> = std::sync::OnceLock::new();
        let key = (order.number(), t_coh_s.to_bits());
        let cache = CACHE.get_or_init(Default::default);
        if let Some((_, t)) = cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .find(|(k, _)| *k == key)
        {
            return t.clone();
        }
        let t = std::sync::Arc::new(LoopTables::build(order, t_coh_s));
        cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((key, t.clone()));
        t
    }
}

/// The phase-error model of one loop order and coherent integration time:
/// tables over the noise bandwidth of the discrete loop's quantities
/// (stability, actual noise bandwidth, oscillator response; built once per
/// process), and a cache of Gauss-Markov aiding responses per correlation
/// time.
#[derive(Clone, Debug)]
pub struct PhaseErrorModel {
    pub order: LoopOrder,
    pub t_coh_s: f64,
    tables: std::sync::Arc<LoopTables>,
    /// Per GM correlation rate α: the discrete-to-continuous jitter ratio
    /// (second order) or the discrete jitter per unit σ_u (other orders).
    gm_cache: std::cell::RefCell<Vec<(f64, std::sync::Arc<Vec<f64>>)>>,
}

impl PhaseErrorModel {
    pub fn new(order: LoopOrder, t_coh_s: f64) -> Self {
        PhaseErrorModel {
            order,
            t_coh_s,
            tables: LoopTables::shared(order, t_coh_s),
            gm_cache: std::cell::RefCell::new(Vec::new()),
        }
    }

    /// Linear interpolation of `table` in ln Bn (∞ where either neighbour is).
    fn interp(&self, table: impl Fn(usize) -> f64, bn_hz: f64) -> f64 {
        let ln_bn = &self.tables.ln_bn;
        let x = bn_hz.ln();
        let n = ln_bn.len();
        let step = ln_bn[1] - ln_bn[0];
        let pos = ((x - ln_bn[0]) / step).clamp(0.0, (n - 1) as f64);
        let i = (pos.floor() as usize).min(n - 2);
        let f = pos - i as f64;
        let (a, b) = (table(i), table(i + 1));
        if !a.is_finite() || !b.is_finite() {
            return f64::INFINITY;
        }
        if a > 0.0 && b > 0.0 {
            (a.ln() * (1.0 - f) + b.ln() * f).exp()
        } else {
            a * (1.0 - f) + b * f
        }
    }

    /// Largest tabulated bandwidth at which the discrete loop is stable (Hz).
    pub(crate) fn max_stable_bandwidth_hz(&self) -> f64 {
        let t = &self.tables;
        let i = t
            .bn_eff
            .iter()
            .position(|b| !b.is_finite())
            .unwrap_or(t.bn_eff.len());
        if i == 0 { 0.0 } else { t.ln_bn[i - 1].exp() }
    }

    /// Noise bandwidth (Hz) of the discrete loop of nominal bandwidth `bn_hz`.
    pub fn discrete_noise_bandwidth(&self, bn_hz: f64) -> f64 {
        self.interp(|i| self.tables.bn_eff[i], bn_hz)
    }

    /// Oscillator-induced jitter (rad): ∫|E|² sinc²(πfT) S_φ(f) df with
    /// S_φ = f_L² S_y(f)/f² (see [`super::oscillator`]).
    pub(crate) fn oscillator_jitter_rad(
        &self,
        osc: &AllanCoefficients,
        carrier_hz: f64,
        bn_hz: f64,
    ) -> f64 {
        let h = [osc.h0, osc.h_m1, osc.h_m2];
        let mut var = 0.0;
        for k in 0..3 {
            if h[k] > 0.0 {
                var += h[k] * self.interp(|i| self.tables.osc[i][k], bn_hz);
            }
        }
        carrier_hz * var.sqrt()
    }

    /// The GM table for correlation rate `alpha` (computed once per
    /// process for each order, T and α).
    fn gm_table(&self, alpha: f64) -> std::sync::Arc<Vec<f64>> {
        if let Some((_, t)) = self.gm_cache.borrow().iter().find(|(a, _)| *a == alpha) {
            return t.clone();
        }
        type Cache = std::sync::Mutex<Vec<((u32, u64, u64), std::sync::Arc<Vec<f64>>)>>;
        static CACHE: std::sync::OnceLock<Cache> = std::sync::OnceLock::new();
        let key = (self.order.number(), self.t_coh_s.to_bits(), alpha.to_bits());
        let shared = CACHE.get_or_init(Default::default);
        let found = shared
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, t)| t.clone());
        let table = match found {
            Some(t) => t,
            None => {
                let t = std::sync::Arc::new(self.build_gm_table(alpha));
                let mut c = shared.lock().unwrap_or_else(|e| e.into_inner());
                if c.len() >= 256 {
                    c.remove(0);
                }
                c.push((key, t.clone()));
                t
            }
        };
        let mut cache = self.gm_cache.borrow_mut();
        if cache.len() >= 8 {
            cache.remove(0);
        }
        cache.push((alpha, table.clone()));
        table
    }

    fn build_gm_table(&self, alpha: f64) -> Vec<f64> {
        let nyq = PI / self.t_coh_s;
        let table: Vec<f64> = self
            .tables
            .ln_bn
            .iter()
            .zip(&self.tables.bn_eff)
            .map(|(&lb, be)| {
                if !be.is_finite() {
                    return f64::INFINITY;
                }
                let c = LoopCoefficients::new(self.order, lb.exp());
                let lo = 1e-4 * c.w0.min(alpha);
                // Discrete: |B/(1+L)|² × 2α/(ω² + α²) over (0, π/T], unit σ_u.
                let disc = (integrate_du(lo, nyq, 1201, |w| {
                    discrete_response(self.order, &c, self.t_coh_s, w)[1].norm_sqr() * 2.0 * alpha
                        / (w * w + alpha * alpha)
                }) / PI)
                    .sqrt();
                if self.order == LoopOrder::Second {
                    // Ratio to the continuous loop's (the T → 0 limit of eq 22).
                    disc / gm_jitter_eq22(1.0, alpha, 0.0, c.w0)
                } else {
                    disc
                }
            })
            .collect();
        table
    }

    /// Phase jitter (rad) caused by a held first-order Gauss-Markov Doppler
    /// aiding error. Second order: seed 003 eq 22 (with eq 20 for σ_w and
    /// γ = e^{αT/2}·α from eq 21, T the filter update period), times the
    /// ratio of the discrete loop's response to the continuous loop's for
    /// the same GM error (1 for small Bn·T, larger towards instability).
    /// Other orders: the GM PSD 2σ_u²α/(ω² + α²) through the discrete
    /// loop's |B/(1 + L)|², integrated numerically.
    pub(crate) fn gm_aiding_jitter_rad(&self, stats: &AidingStats, bn_hz: f64) -> f64 {
        if stats.gm_sd_hz <= 0.0 || stats.gm_tau_s <= 0.0 {
            return 0.0;
        }
        let sigma_u = 2.0 * PI * stats.gm_sd_hz;
        let alpha = 1.0 / stats.gm_tau_s;
        let table = self.gm_table(alpha);
        let k = self.interp(|i| table[i], bn_hz);
        match self.order {
            LoopOrder::Second => {
                let w0 = bn_hz / self.order.bn_over_w0();
                gm_jitter_eq22(sigma_u, alpha, stats.update_period_s.max(0.0), w0) * k
            }
            _ => sigma_u * k,
        }
    }

    /// Steady-state phase error (rad) of a Doppler-rate error `ramp_hz_s`
    /// held over an update period: seed 003 eq 16, Δḟ·2π/ω_n², for the
    /// second order; zero for the third; for the first order the mean of
    /// the frequency error that builds up over the period, 2π·ḟ·T/2/ω0.
    pub(crate) fn ramp_bias_rad(&self, ramp_hz_s: f64, update_period_s: f64, bn_hz: f64) -> f64 {
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
    pub(crate) fn dynamic_stress_rad(
        &self,
        env: &DynamicsEnvelope,
        wavelength_m: f64,
        bn_hz: f64,
    ) -> f64 {
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
        let bn_eff = self.discrete_noise_bandwidth(bn_hz);
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
    pub(crate) fn optimal_bandwidth(&self, inp: &BudgetInputs, lo_hz: f64, hi_hz: f64) -> f64 {
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
pub(crate) fn gm_jitter_eq22(sigma_u: f64, alpha: f64, t_s: f64, wn: f64) -> f64 {
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
    pub(crate) cn0_hz: f64,
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
    pub(crate) fn jitter_rad(&self) -> f64 {
        (self.thermal_rad.powi(2) + self.oscillator_rad.powi(2) + self.aiding_rad.powi(2)).sqrt()
    }

    /// RMS phase error including the bias (rad): the adaptive criterion.
    pub(crate) fn total_rms_rad(&self) -> f64 {
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
    /// Upper bound on Bn·T; the rule also stays below 80 % of the discrete
    /// loop's stability limit.
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
            max_bn_t: 0.3,
            slew_per_s: 2.0,
            update_interval_s: 0.1,
        }
    }
}

/// The adaptive bandwidth controller: every `update_interval_s` it moves
/// the bandwidth towards the budget's optimum, within the clamps and the
/// slew limit.
#[derive(Clone, Debug)]
pub(crate) struct AdaptiveBandwidth {
    cfg: AdaptiveConfig,
    model: PhaseErrorModel,
    bn_hz: f64,
    target_hz: f64,
    next_update_s: f64,
    last_update_s: Option<f64>,
}

impl AdaptiveBandwidth {
    /// A controller for a loop of `order` updated every `t_coh_s`.
    pub(crate) fn new(
        cfg: AdaptiveConfig,
        order: LoopOrder,
        t_coh_s: f64,
        initial_hz: f64,
    ) -> Self {
        AdaptiveBandwidth {
            cfg,
            model: PhaseErrorModel::new(order, t_coh_s),
            bn_hz: initial_hz,
            target_hz: initial_hz,
            next_update_s: 0.0,
            last_update_s: None,
        }
    }

    /// The unconstrained optimum found at the last evaluation.
    #[cfg(test)]
    pub(crate) fn target_hz(&self) -> f64 {
        self.target_hz
    }

    /// Evaluates the rule at `t_s` if due; returns the (possibly unchanged)
    /// bandwidth.
    pub(crate) fn update(&mut self, t_s: f64, inp: &BudgetInputs) -> f64 {
        if t_s < self.next_update_s {
            return self.bn_hz;
        }
        self.next_update_s = t_s + self.cfg.update_interval_s;
        let hi = self
            .cfg
            .max_hz
            .min(self.cfg.max_bn_t / inp.t_coh_s)
            .min(0.8 * self.model.max_stable_bandwidth_hz());
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

    /// The frequency-domain noise bandwidth of the discrete loop equals the
    /// time-domain impulse-response sum of the loop actually run, up to
    /// Bn·T = 0.3 (quadrature and tabulation error < 0.5 %).
    #[test]
    fn discrete_bandwidth_matches_the_impulse_response() {
        for order in [LoopOrder::First, LoopOrder::Second, LoopOrder::Third] {
            for t in [0.001, 0.02] {
                let m = PhaseErrorModel::new(order, t);
                for bnt in [0.005, 0.02, 0.1, 0.2, 0.3] {
                    let bn = bnt / t;
                    if !discrete_loop_is_stable(order, bn, t) {
                        assert!(bnt >= 0.2, "{order:?} unstable at {bnt}");
                        continue;
                    }
                    let time = measured_noise_bandwidth(order, bn, t, 400_000);
                    let freq = m.discrete_noise_bandwidth(bn);
                    assert!(
                        (freq / time - 1.0).abs() < 0.005,
                        "{order:?} T {t} BnT {bnt}: {freq} vs {time}"
                    );
                }
            }
        }
    }

    #[test]
    fn stability_limits() {
        for order in [LoopOrder::First, LoopOrder::Second, LoopOrder::Third] {
            assert!(discrete_loop_is_stable(order, 1.0, 0.001));
            assert!(
                !discrete_loop_is_stable(order, 60.0, 0.02),
                "{order:?} at BnT 1.2"
            );
            // Where the roots say unstable, the impulse response grows.
            let m = PhaseErrorModel::new(order, 0.02);
            let lim = m.max_stable_bandwidth_hz();
            assert!(lim > 5.0 && lim < 40.0, "{order:?}: {lim}");
            let grows = measured_noise_bandwidth(order, lim * 1.1, 0.02, 20_000);
            assert!(!grows.is_finite() || grows > 1e6, "{order:?}: {grows}");
            assert!(measured_noise_bandwidth(order, lim * 0.95, 0.02, 20_000).is_finite());
        }
    }

    #[test]
    fn oscillator_response_of_a_narrow_loop_is_the_analog_one() {
        // White FM through the analog 2nd-order loop: σ² = f_L² h0 (2π/ω0)
        // ∫ u²/(1 + u⁴) du = f_L² h0 (2π/ω0)·π/(2√2). At Bn·T = 0.001 the
        // discrete loop and the interval averaging change it by < 1 %.
        let m = PhaseErrorModel::new(LoopOrder::Second, 0.001);
        let osc = AllanCoefficients {
            h0: 1e-21,
            h_m1: 0.0,
            h_m2: 0.0,
        };
        let w0 = 1.0 / 0.53;
        let want = (1e-21 * 2.0 * PI / w0 * PI / (2.0 * SQRT_2)).sqrt();
        let got = m.oscillator_jitter_rad(&osc, 1.0, 1.0);
        assert!((got / want - 1.0).abs() < 0.01, "{got} vs {want}");
        // And the GM correction factor of eq 22 tends to 1 for narrow loops.
        let s = AidingStats {
            ramp_hz_s: 0.0,
            gm_sd_hz: 0.1,
            gm_tau_s: 2.0,
            update_period_s: 0.0,
        };
        let k = m.gm_aiding_jitter_rad(&s, 1.0) / gm_jitter_eq22(2.0 * PI * 0.1, 0.5, 0.0, w0);
        assert!((k - 1.0).abs() < 0.01, "{k}");
    }

    #[test]
    fn numeric_gm_jitter_matches_eq22_in_the_continuous_limit() {
        // Order 2 uses eq 22; the numeric path of the other orders must give
        // the same number for the second-order transfer when T → 0.
        for (sd, tau, bn) in [(0.1, 5.0, 3.0), (0.5, 0.5, 10.0), (0.05, 50.0, 1.0)] {
            let s = AidingStats {
                ramp_hz_s: 0.0,
                gm_sd_hz: sd,
                gm_tau_s: tau,
                update_period_s: 0.0,
            };
            let eq22 = gm_jitter_eq22(2.0 * PI * s.gm_sd_hz, 1.0 / s.gm_tau_s, 0.0, bn / 0.53);
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
        let m = PhaseErrorModel::new(LoopOrder::Second, 0.001);
        let w0 = 3.0 / 0.53;
        assert!((m.ramp_bias_rad(1.0, 1.0, 3.0) - 2.0 * PI / (w0 * w0)).abs() < 1e-12);
        assert_eq!(
            PhaseErrorModel::new(LoopOrder::Third, 0.001).ramp_bias_rad(1.0, 1.0, 3.0),
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
        let m = PhaseErrorModel::new(LoopOrder::Second, 0.001);
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
        let mut a = AdaptiveBandwidth::new(cfg, LoopOrder::Second, 0.001, 10.0);
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
