//! Carrier-loop filters of order 1–3 in the standard analog-prototype form
//! digitised with the bilinear transform.
//!
//! Analog prototypes (Kaplan & Hegarty, *Understanding GPS*, 2nd ed., ch. 5
//! by Ward, Betz & Hegarty, Table 5.6 and Fig. 5.21):
//!
//! | order | filter F(s)                         | ω0 from Bn     |
//! |-------|-------------------------------------|----------------|
//! | 1     | ω0                                  | Bn / 0.25      |
//! | 2     | a2 ω0 + ω0²/s          (a2 = 1.414) | Bn / 0.53      |
//! | 3     | b3 ω0 + a3 ω0²/s + ω0³/s² (a3 = 1.1, b3 = 2.4) | Bn / 0.7845 |
//!
//! Each 1/s is a bilinear-transform integrator (T/2)(1 + z⁻¹)/(1 − z⁻¹),
//! i.e. a trapezoid on the integrand (Kaplan Fig. 5.21; the same structure as
//! gnss-sdr's `tracking_loop_filter.cc`, written here from the equations).
//! The NCO that follows is a boxcar integrator of the filter's frequency
//! output over the next coherent interval.
//!
//! The integrator states are kept as physical quantities — the frequency
//! (rad/s) and the frequency rate (rad/s²) the loop has learned — and the
//! previous discriminator output, never as products with ω0. Changing the
//! bandwidth therefore changes only the gains applied to *new* phase errors:
//! the NCO frequency does not jump (seed 003's adaptive loop needs exactly
//! this).

use std::f64::consts::PI;

/// Loop order.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub enum LoopOrder {
    First,
    Second,
    Third,
}

impl LoopOrder {
    /// From 1, 2 or 3.
    pub fn from_number(n: u32) -> Option<Self> {
        match n {
            1 => Some(LoopOrder::First),
            2 => Some(LoopOrder::Second),
            3 => Some(LoopOrder::Third),
            _ => None,
        }
    }

    pub fn number(self) -> u32 {
        match self {
            LoopOrder::First => 1,
            LoopOrder::Second => 2,
            LoopOrder::Third => 3,
        }
    }

    /// Bn/ω0 of the analog prototype (Kaplan Table 5.6).
    pub(crate) fn bn_over_w0(self) -> f64 {
        match self {
            LoopOrder::First => 0.25,
            LoopOrder::Second => 0.53,
            LoopOrder::Third => 0.7845,
        }
    }
}

/// Second-order loop coefficient a2 = √2 (damping 0.707), Kaplan Table 5.6.
pub const A2: f64 = 1.414;
/// Third-order loop coefficients (Kaplan Table 5.6).
pub(crate) const A3: f64 = 1.1;
pub(crate) const B3: f64 = 2.4;

/// Gains of the analog prototype for a noise bandwidth.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LoopCoefficients {
    /// Natural radian frequency ω0 (rad/s).
    pub w0: f64,
    /// Proportional gain on the phase error (1/s): ω0, a2 ω0 or b3 ω0.
    pub(crate) k_phase: f64,
    /// Gain into the frequency integrator (1/s²): ω0² (2nd order) or a3 ω0² (3rd).
    pub(crate) k_freq: f64,
    /// Gain into the frequency-rate integrator (1/s³): ω0³ (3rd order only).
    pub(crate) k_rate: f64,
}

impl LoopCoefficients {
    /// Kaplan Table 5.6 for noise bandwidth `bn_hz`.
    pub fn new(order: LoopOrder, bn_hz: f64) -> Self {
        let w0 = bn_hz / order.bn_over_w0();
        match order {
            LoopOrder::First => LoopCoefficients {
                w0,
                k_phase: w0,
                k_freq: 0.0,
                k_rate: 0.0,
            },
            LoopOrder::Second => LoopCoefficients {
                w0,
                k_phase: A2 * w0,
                k_freq: w0 * w0,
                k_rate: 0.0,
            },
            LoopOrder::Third => LoopCoefficients {
                w0,
                k_phase: B3 * w0,
                k_freq: A3 * w0 * w0,
                k_rate: w0 * w0 * w0,
            },
        }
    }
}

/// A carrier-loop filter: phase error in, NCO frequency correction out.
#[derive(Clone, Debug)]
pub(crate) struct LoopFilter {
    order: LoopOrder,
    bn_hz: f64,
    t_s: f64,
    coef: LoopCoefficients,
    /// Frequency learned by the loop (rad/s).
    freq: f64,
    /// Frequency rate learned by the loop (rad/s²).
    freq_rate: f64,
    prev_err: f64,
}

impl LoopFilter {
    /// A filter of `order` with noise bandwidth `bn_hz`, updated every
    /// `t_s` seconds (the coherent integration time).
    pub(crate) fn new(order: LoopOrder, bn_hz: f64, t_s: f64) -> Self {
        LoopFilter {
            order,
            bn_hz,
            t_s,
            coef: LoopCoefficients::new(order, bn_hz),
            freq: 0.0,
            freq_rate: 0.0,
            prev_err: 0.0,
        }
    }

    pub(crate) fn bandwidth_hz(&self) -> f64 {
        self.bn_hz
    }

    #[cfg(test)]
    pub(crate) fn coefficients(&self) -> LoopCoefficients {
        self.coef
    }

    /// Changes the noise bandwidth; the learned frequency and frequency
    /// rate are kept, so the output does not jump.
    pub(crate) fn set_bandwidth(&mut self, bn_hz: f64) {
        self.bn_hz = bn_hz;
        self.coef = LoopCoefficients::new(self.order, bn_hz);
    }

    /// Presets the learned frequency (rad/s) and frequency rate (rad/s²),
    /// e.g. from acquisition.
    pub(crate) fn set_state(&mut self, freq_rad_s: f64, freq_rate_rad_s2: f64) {
        self.freq = freq_rad_s;
        self.freq_rate = freq_rate_rad_s2;
    }

    /// Learned frequency (rad/s).
    #[cfg(test)]
    pub(crate) fn frequency(&self) -> f64 {
        self.freq
    }

    /// Learned frequency rate (rad/s²).
    #[cfg(test)]
    pub(crate) fn frequency_rate(&self) -> f64 {
        self.freq_rate
    }

    /// One update with discriminator output `err_rad`; returns the NCO
    /// frequency correction (rad/s) for the next interval.
    ///
    /// Bilinear integrators (trapezoid of the integrand, Kaplan Fig. 5.21):
    /// ρ_k = ρ_{k−1} + T k_r (e_k + e_{k−1})/2,
    /// ν_k = ν_{k−1} + T [k_f (e_k + e_{k−1})/2 + (ρ_k + ρ_{k−1})/2],
    /// output ν_k + k_p e_k (a first-order loop has no integrator: its ν
    /// stays at the preset frequency, a feed-forward).
    pub(crate) fn update(&mut self, err_rad: f64) -> f64 {
        let t = self.t_s;
        let e_avg = 0.5 * (err_rad + self.prev_err);
        self.prev_err = err_rad;
        match self.order {
            LoopOrder::First => {}
            LoopOrder::Second => {
                self.freq += t * self.coef.k_freq * e_avg;
            }
            LoopOrder::Third => {
                let rate_prev = self.freq_rate;
                self.freq_rate += t * self.coef.k_rate * e_avg;
                self.freq += t * (self.coef.k_freq * e_avg + 0.5 * (self.freq_rate + rate_prev));
            }
        }
        self.freq + self.coef.k_phase * err_rad
    }
}

/// The noise bandwidth (Hz) of the complete discrete loop — this filter,
/// an NCO that holds each output frequency over the next interval, and a
/// discriminator that measures the interval-average phase error — computed
/// from its impulse response h from discriminator noise to the NCO's
/// interval-average phase: Bn = Σ h² / (2T) (a white discriminator error of
/// variance σ² then gives a phase jitter σ² Σh² = σ² 2 Bn T, the discrete
/// form of σ² = Bn N0/C, Kaplan & Hegarty §5.6). `steps` bounds the response
/// length (it decays like exp(−ζ ω0 t)).
#[cfg(test)]
pub(crate) fn measured_noise_bandwidth(
    order: LoopOrder,
    bn_hz: f64,
    t_s: f64,
    steps: usize,
) -> f64 {
    let mut f = LoopFilter::new(order, bn_hz, t_s);
    // NCO phase at the start of the interval and its frequency.
    let mut theta = 0.0;
    let mut w = 0.0;
    let mut sum_sq = 0.0;
    let mut quiet = 0;
    for k in 0..steps {
        let theta_avg = theta + 0.5 * w * t_s;
        // The input phase is zero: the discriminator sees −θ̄ plus the impulse.
        let noise = if k == 0 { 1.0 } else { 0.0 };
        let e = -theta_avg + noise;
        sum_sq += theta_avg * theta_avg;
        // Stop once the response has been negligible for 1000 steps (and
        // before it sinks into subnormal numbers, which are slow).
        if k > 0 && theta_avg * theta_avg < 1e-30 * sum_sq {
            quiet += 1;
            if quiet > 1000 {
                break;
            }
        } else {
            quiet = 0;
        }
        theta += w * t_s;
        w = f.update(e);
    }
    sum_sq / (2.0 * t_s)
}

/// Degrees per radian.
pub const DEG: f64 = 180.0 / PI;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coefficients_follow_kaplan_table_5_6() {
        let c1 = LoopCoefficients::new(LoopOrder::First, 10.0);
        assert!((c1.w0 - 40.0).abs() < 1e-12 && c1.k_phase == c1.w0 && c1.k_freq == 0.0);
        let c2 = LoopCoefficients::new(LoopOrder::Second, 5.3);
        assert!((c2.w0 - 10.0).abs() < 1e-12);
        assert!(
            (c2.k_phase - 14.14).abs() < 1e-9
                && (c2.k_freq - 100.0).abs() < 1e-9
                && c2.k_rate == 0.0
        );
        let c3 = LoopCoefficients::new(LoopOrder::Third, 7.845);
        assert!((c3.w0 - 10.0).abs() < 1e-12);
        assert!((c3.k_phase - 24.0).abs() < 1e-9);
        assert!((c3.k_freq - 110.0).abs() < 1e-9);
        assert!((c3.k_rate - 1000.0).abs() < 1e-9);
    }

    /// Done-when: the discrete loop's noise bandwidth within 5 % of the
    /// nominal for Bn·T ≤ 0.02 (every order). The impulse response is
    /// summed over 200 000 steps: ≥ 40 time constants even at Bn·T = 0.001.
    #[test]
    fn discrete_noise_bandwidth_is_within_five_percent() {
        for order in [LoopOrder::First, LoopOrder::Second, LoopOrder::Third] {
            for bnt in [0.001, 0.005, 0.01, 0.02] {
                for t in [0.001, 0.02] {
                    let bn = bnt / t;
                    let m = measured_noise_bandwidth(order, bn, t, 200_000);
                    assert!(
                        (m / bn - 1.0).abs() < 0.05,
                        "{order:?} BnT {bnt} T {t}: {m} vs {bn}"
                    );
                    // And it converges to the analog design as BnT → 0.
                    if bnt == 0.001 {
                        assert!((m / bn - 1.0).abs() < 0.005);
                    }
                }
            }
        }
    }

    #[test]
    fn bandwidth_changes_do_not_jump_the_output() {
        for order in [LoopOrder::First, LoopOrder::Second, LoopOrder::Third] {
            let mut f = LoopFilter::new(order, 10.0, 0.001);
            f.set_state(100.0, 5.0);
            for k in 0..50 {
                f.update(0.01 * (k as f64 * 0.3).sin());
            }
            let (w, r) = (f.frequency(), f.frequency_rate());
            f.set_bandwidth(2.0);
            assert_eq!((f.frequency(), f.frequency_rate()), (w, r));
            // With zero phase error the next output is the learned frequency
            // advanced by its rate, whatever the new gains.
            let prev_err = 0.01 * (49.0f64 * 0.3).sin();
            let out = f.update(0.0);
            let c = f.coefficients();
            let expect = match order {
                LoopOrder::First => w,
                LoopOrder::Second => w + 0.001 * c.k_freq * 0.5 * prev_err,
                LoopOrder::Third => {
                    let r1 = r + 0.001 * c.k_rate * 0.5 * prev_err;
                    w + 0.001 * (c.k_freq * 0.5 * prev_err + 0.5 * (r + r1))
                }
            };
            assert!((out - expect).abs() < 1e-9, "{order:?}: {out} vs {expect}");
        }
    }

    #[test]
    fn steady_state_ramp_error_is_rate_over_w0_squared() {
        // Phase ramp of rate θ'' into the bare loop (linear discriminator):
        // the second-order loop settles at θ''/ω0², the third at zero.
        for (order, want) in [
            (LoopOrder::Second, 2.0 / (3.0f64 / 0.53).powi(2)),
            (LoopOrder::Third, 0.0),
        ] {
            let t = 0.001;
            let mut f = LoopFilter::new(order, 3.0, t);
            let (mut theta, mut w) = (0.0, 0.0);
            let mut e = 0.0;
            for k in 0..40_000 {
                let tm = (k as f64 + 0.5) * t;
                // Interval-mean input phase of θ(t) = ½·2·t².
                let phi = tm * tm + t * t / 12.0;
                e = phi - (theta + 0.5 * w * t);
                theta += w * t;
                w = f.update(e);
            }
            assert!(
                (e - want).abs() < 1e-3 * want.max(1e-3),
                "{order:?}: {e} vs {want}"
            );
        }
    }
}
