//! Receiver reference oscillator: the power-law model of its fractional
//! frequency noise, its Allan variance, and a simulator of the carrier
//! phase noise it puts on every tracked signal.
//!
//! Model (Barnes et al., "Characterization of frequency stability", IEEE
//! Trans. Instrum. Meas. IM-20, 1971; the three-term form used for GNSS
//! receiver clocks by Van Dierendonck, McGraw & Brown 1984 and Brown &
//! Hwang, *Introduction to Random Signals and Applied Kalman Filtering*,
//! §9.3): one-sided PSD of the fractional frequency y
//!     S_y(f) = h0 + h−1/f + h−2/f²,
//! Allan variance σ_y²(τ) = h0/(2τ) + 2 ln2 h−1 + (2π²/3) h−2 τ, and the
//! carrier phase noise φ = 2π f_L ∫y dt with S_φ(f) = f_L² S_y(f)/f² (rad²/Hz).

#[cfg(test)]
use std::f64::consts::LN_2;
use std::f64::consts::PI;

use rand::RngExt;
use rand::SeedableRng;
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;

/// h-coefficients of the fractional-frequency PSD (one-sided).
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub struct AllanCoefficients {
    /// White frequency noise h0 (1/Hz).
    pub h0: f64,
    /// Flicker frequency noise h−1 (dimensionless).
    pub h_m1: f64,
    /// Random-walk frequency noise h−2 (Hz).
    pub h_m2: f64,
}

impl AllanCoefficients {
    /// A perfect oscillator.
    pub(crate) const IDEAL: AllanCoefficients = AllanCoefficients {
        h0: 0.0,
        h_m1: 0.0,
        h_m2: 0.0,
    };

    /// A good temperature-compensated crystal of a current GNSS receiver:
    /// σ_y ≈ 1.1e-10 at 0.1 s, 6.2e-11 at 1 s, 9.7e-11 at 100 s (white FM
    /// dominating below 0.5 s, a 5e-11 flicker floor, slow random walk).
    pub const TCXO: AllanCoefficients = AllanCoefficients {
        h0: 2e-21,
        h_m1: 2e-21,
        h_m2: 1e-23,
    };

    /// An older, low-quality compensated crystal (Brown & Hwang's table of
    /// clock h-parameters, "compensated crystal": h0 = 2e-19, h−1 = 7e-21,
    /// h−2 = 2e-20; σ_y ≈ 4.9e-10 at 1 s): narrow loops are limited by it.
    pub(crate) const TCXO_LOW: AllanCoefficients = AllanCoefficients {
        h0: 2e-19,
        h_m1: 7e-21,
        h_m2: 2e-20,
    };

    /// An oven-controlled crystal: σ_y ≈ 1e-12 around 1 s.
    pub const OCXO: AllanCoefficients = AllanCoefficients {
        h0: 2e-24,
        h_m1: 7e-25,
        h_m2: 1e-27,
    };

    /// A preset by name: `ideal`, `tcxo`, `tcxo-low`, `ocxo`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "ideal" | "none" => Some(Self::IDEAL),
            "tcxo" => Some(Self::TCXO),
            "tcxo-low" => Some(Self::TCXO_LOW),
            "ocxo" => Some(Self::OCXO),
            _ => None,
        }
    }

    /// Allan variance at averaging time `tau_s` (Barnes et al. 1971).
    #[cfg(test)]
    pub(crate) fn allan_variance(&self, tau_s: f64) -> f64 {
        self.h0 / (2.0 * tau_s) + 2.0 * LN_2 * self.h_m1 + 2.0 * PI * PI / 3.0 * self.h_m2 * tau_s
    }

    #[cfg(test)]
    pub(crate) fn allan_deviation(&self, tau_s: f64) -> f64 {
        self.allan_variance(tau_s).sqrt()
    }
}

/// Simulates the oscillator's carrier phase error (rad at `carrier_hz`).
///
/// White FM: the time error x = ∫y gains N(0, (h0/2)·Δt) per step (two-sided
/// PSD h0/2). Random-walk FM: y_rw is a random walk with increment
/// variance 2π² h−2 Δt (Brown & Hwang's S_g = 2π² h−2). Flicker FM: a bank
/// of first-order Gauss-Markov processes with correlation times spaced by a
/// factor r = √10 and equal variances h−1 ln r, whose PSDs sum to h−1/f
/// between about 1/(2π τ_max) and 1/(2π τ_min) (the integral of
/// 4σ²τ/(1 + (2πfτ)²) over ln τ is σ²/f per unit ln τ). Steps must not
/// exceed `MAX_STEP_S`.
#[derive(Clone, Debug)]
pub struct OscillatorNoise {
    h: AllanCoefficients,
    carrier_hz: f64,
    rng: Pcg64Mcg,
    y_rw: f64,
    flicker: Vec<FlickerComponent>,
    y_flicker: f64,
    x_s: f64,
}

#[derive(Clone, Debug)]
struct FlickerComponent {
    tau_s: f64,
    sd: f64,
    y: f64,
    /// Cached decay and drive for the last step length.
    dt: f64,
    decay: f64,
    drive: f64,
}

/// Shortest flicker correlation time (s); also twice the largest step.
pub const MAX_STEP_S: f64 = 1e-3;
const FLICKER_TAU_MIN_S: f64 = 2e-3;
const FLICKER_TAU_MAX_S: f64 = 2e4;

impl OscillatorNoise {
    pub fn new(h: AllanCoefficients, carrier_hz: f64, seed: u64) -> Self {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let ratio: f64 = 10f64.sqrt();
        let mut flicker = Vec::new();
        if h.h_m1 > 0.0 {
            let sd = (h.h_m1 * ratio.ln()).sqrt();
            let mut tau = FLICKER_TAU_MIN_S;
            while tau <= FLICKER_TAU_MAX_S {
                // Start each component in its stationary distribution.
                let y0: f64 = rng.sample::<f64, _>(StandardNormal) * sd;
                flicker.push(FlickerComponent {
                    tau_s: tau,
                    sd,
                    y: y0,
                    dt: 0.0,
                    decay: 0.0,
                    drive: 0.0,
                });
                tau *= ratio;
            }
        }
        let y_flicker = flicker.iter().map(|c| c.y).sum();
        OscillatorNoise {
            h,
            carrier_hz,
            rng,
            y_rw: 0.0,
            flicker,
            y_flicker,
            x_s: 0.0,
        }
    }

    pub fn coefficients(&self) -> AllanCoefficients {
        self.h
    }

    /// Advances by `dt_s` (≤ `MAX_STEP_S`) and returns the carrier phase
    /// error (rad) accumulated since the start.
    pub fn step(&mut self, dt_s: f64) -> f64 {
        let mut dx = 0.0;
        if self.h.h0 > 0.0 {
            let n: f64 = self.rng.sample(StandardNormal);
            dx += n * (0.5 * self.h.h0 * dt_s).sqrt();
        }
        if self.h.h_m2 > 0.0 {
            let y0 = self.y_rw;
            let n: f64 = self.rng.sample(StandardNormal);
            self.y_rw += n * (2.0 * PI * PI * self.h.h_m2 * dt_s).sqrt();
            dx += 0.5 * (y0 + self.y_rw) * dt_s;
        }
        if !self.flicker.is_empty() {
            let y0 = self.y_flicker;
            let mut sum = 0.0;
            for c in &mut self.flicker {
                if c.dt != dt_s {
                    c.dt = dt_s;
                    c.decay = (-dt_s / c.tau_s).exp();
                    c.drive = c.sd * (1.0 - c.decay * c.decay).sqrt();
                }
                let n: f64 = self.rng.sample(StandardNormal);
                c.y = c.decay * c.y + c.drive * n;
                sum += c.y;
            }
            self.y_flicker = sum;
            dx += 0.5 * (y0 + sum) * dt_s;
        }
        self.x_s += dx;
        self.phase_rad()
    }

    /// Accumulated clock time error (s).
    #[cfg(test)]
    pub(crate) fn time_error_s(&self) -> f64 {
        self.x_s
    }

    /// Accumulated carrier phase error (rad).
    pub(crate) fn phase_rad(&self) -> f64 {
        2.0 * PI * self.carrier_hz * self.x_s
    }
}

/// Overlapping Allan deviation of time-error samples `x_s` taken every
/// `tau0_s`, at averaging time m·tau0 (IEEE Std 1139).
pub fn overlapping_adev(x_s: &[f64], tau0_s: f64, m: usize) -> f64 {
    let n = x_s.len();
    if m == 0 || n < 2 * m + 1 {
        return f64::NAN;
    }
    let mut sum = 0.0;
    let count = n - 2 * m;
    for i in 0..count {
        let d = x_s[i + 2 * m] - 2.0 * x_s[i + m] + x_s[i];
        sum += d * d;
    }
    let tau = m as f64 * tau0_s;
    (sum / (2.0 * tau * tau * count as f64)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn simulate(h: AllanCoefficients, seconds: f64, seed: u64) -> Vec<f64> {
        let dt = 1e-3;
        let mut osc = OscillatorNoise::new(h, 1575.42e6, seed);
        let n = (seconds / dt) as usize;
        let mut x = Vec::with_capacity(n);
        for _ in 0..n {
            osc.step(dt);
            x.push(osc.time_error_s());
        }
        x
    }

    fn check(h: AllanCoefficients, seconds: f64, taus: &[(usize, f64)]) {
        let x = simulate(h, seconds, 11);
        for &(m, tol) in taus {
            let tau = m as f64 * 1e-3;
            let got = overlapping_adev(&x, 1e-3, m);
            let want = h.allan_deviation(tau);
            assert!(
                (got / want - 1.0).abs() < tol,
                "{h:?} tau {tau}: simulated {got:e}, model {want:e}"
            );
        }
    }

    // Tolerances: the overlapping estimator of σ² from a record of length
    // L at τ has about L/τ degrees of freedom for white FM (relative σ of
    // σ_y ≈ 1/√(2·L/τ)·~1.2) and fewer for flicker and random walk;
    // each bound below is ≥ 3 such σ.
    #[test]
    fn white_fm_allan_deviation() {
        let h = AllanCoefficients {
            h0: 2e-21,
            h_m1: 0.0,
            h_m2: 0.0,
        };
        check(h, 200.0, &[(10, 0.03), (100, 0.05), (1000, 0.15)]);
    }

    #[test]
    fn random_walk_fm_allan_deviation() {
        let h = AllanCoefficients {
            h0: 0.0,
            h_m1: 0.0,
            h_m2: 1e-22,
        };
        check(h, 400.0, &[(100, 0.10), (1000, 0.15), (5000, 0.35)]);
    }

    #[test]
    fn flicker_fm_allan_deviation() {
        // The Gauss-Markov bank ripples about ±0.2 dB (±5 % in σ) around 1/f.
        let h = AllanCoefficients {
            h0: 0.0,
            h_m1: 2e-21,
            h_m2: 0.0,
        };
        check(h, 400.0, &[(20, 0.15), (200, 0.20), (2000, 0.35)]);
    }

    #[test]
    fn presets_have_documented_stability() {
        let t = AllanCoefficients::TCXO;
        assert!((t.allan_deviation(0.1) / 1.1e-10 - 1.0).abs() < 0.03);
        assert!((t.allan_deviation(1.0) / 6.2e-11 - 1.0).abs() < 0.03);
        assert!((t.allan_deviation(100.0) / 9.7e-11 - 1.0).abs() < 0.03);
        assert!((AllanCoefficients::TCXO_LOW.allan_deviation(1.0) / 4.9e-10 - 1.0).abs() < 0.03);
        assert!((AllanCoefficients::OCXO.allan_deviation(1.0) / 1.4e-12 - 1.0).abs() < 0.03);
        assert_eq!(AllanCoefficients::preset("tcxo"), Some(t));
        assert_eq!(AllanCoefficients::preset("rubidium"), None);
    }
}
