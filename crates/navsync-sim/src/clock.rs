//! Clock models: a board temperature profile, oscillators with frequency
//! error, temperature drift and frequency random walk, the logger's local
//! counter, and the IMU's own sample clock.
//!
//! An oscillator's fractional frequency error is
//! y(t) = y₀ + c_T·(T(t) − T(0)) + y_rw(t), and its elapsed local time is
//! τ(t) = t + ∫₀ᵗ y(s) ds (t in true GPS seconds since the scenario start;
//! Allan, Ashby & Hodge, *The Science of Timekeeping*, HP AN 1289, §2).
//! The temperature term is integrated in closed form; the random walk is
//! piecewise linear between 1 s nodes and integrated exactly.

use serde::{Deserialize, Serialize};

use super::rng::{self, SimRng};

/// Temperature of the board over the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case", deny_unknown_fields)]
pub enum TemperatureSpec {
    Constant {
        celsius: f64,
    },
    /// T = T₀ + ΔT·(1 − e^{−t/τ}) (warm-up; the reference rig's profile).
    Exponential {
        t0_c: f64,
        delta_c: f64,
        tau_s: f64,
    },
    /// A linear ramp of `rate_c_per_min` from `start_s` to `end_s`.
    Ramp {
        t0_c: f64,
        rate_c_per_min: f64,
        #[serde(default)]
        start_s: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        end_s: Option<f64>,
    },
    /// Piecewise linear through `[t_s, celsius]` points, held outside.
    Points {
        points: Vec<[f64; 2]>,
    },
}

impl Default for TemperatureSpec {
    fn default() -> Self {
        TemperatureSpec::Constant { celsius: 25.0 }
    }
}

/// A temperature profile with the integral of T(t) − T(0).
#[derive(Clone, Debug)]
pub enum Temperature {
    Exponential {
        t0: f64,
        dt: f64,
        tau: f64,
    },
    /// Knots (t, T) and the integral of T − T(0) up to each knot.
    Linear {
        knots: Vec<(f64, f64)>,
        cum: Vec<f64>,
    },
}

impl Temperature {
    pub fn new(spec: &TemperatureSpec) -> Result<Self, String> {
        let linear = |knots: Vec<(f64, f64)>| -> Result<Temperature, String> {
            if knots.is_empty() {
                return Err("temperature points are empty".into());
            }
            if knots.iter().any(|k| !(k.0.is_finite() && k.1.is_finite())) {
                return Err("temperature points must be finite".into());
            }
            if knots.windows(2).any(|w| w[1].0 < w[0].0) {
                return Err("temperature points must be in increasing time".into());
            }
            let t_ref = knots[0].1;
            let mut cum = vec![0.0; knots.len()];
            for i in 1..knots.len() {
                let (a, b) = (knots[i - 1], knots[i]);
                cum[i] = cum[i - 1] + (b.0 - a.0) * (0.5 * (a.1 + b.1) - t_ref);
            }
            Ok(Temperature::Linear { knots, cum })
        };
        match spec {
            TemperatureSpec::Constant { celsius } => linear(vec![(0.0, *celsius)]),
            TemperatureSpec::Exponential {
                t0_c,
                delta_c,
                tau_s,
            } => {
                if tau_s.is_nan() || *tau_s <= 0.0 || !t0_c.is_finite() || !delta_c.is_finite() {
                    return Err(
                        "exponential temperature needs tau_s > 0 and finite temperatures".into(),
                    );
                }
                Ok(Temperature::Exponential {
                    t0: *t0_c,
                    dt: *delta_c,
                    tau: *tau_s,
                })
            }
            TemperatureSpec::Ramp {
                t0_c,
                rate_c_per_min,
                start_s,
                end_s,
            } => {
                let start = start_s.max(0.0);
                let end = end_s.unwrap_or(1e9).max(start);
                linear(vec![
                    (0.0, *t0_c),
                    (start, *t0_c),
                    (end, t0_c + rate_c_per_min / 60.0 * (end - start)),
                ])
            }
            TemperatureSpec::Points { points } => {
                let mut k: Vec<(f64, f64)> = points.iter().map(|p| (p[0], p[1])).collect();
                if k.first().is_some_and(|f| f.0 > 0.0) {
                    let f = k[0];
                    k.insert(0, (0.0, f.1));
                }
                linear(k)
            }
        }
    }

    /// T(t) (°C).
    pub fn at(&self, t: f64) -> f64 {
        match self {
            Temperature::Exponential { t0, dt, tau } => t0 + dt * (1.0 - (-t.max(0.0) / tau).exp()),
            Temperature::Linear { knots, .. } => {
                let i = knots.partition_point(|k| k.0 <= t);
                if i == 0 {
                    knots[0].1
                } else if i == knots.len() {
                    knots[i - 1].1
                } else {
                    let (a, b) = (knots[i - 1], knots[i]);
                    a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)
                }
            }
        }
    }

    /// ∫₀ᵗ (T(s) − T(0)) ds (°C·s), t ≥ 0.
    pub fn integral(&self, t: f64) -> f64 {
        let t = t.max(0.0);
        match self {
            Temperature::Exponential { dt, tau, .. } => dt * (t - tau * (1.0 - (-t / tau).exp())),
            Temperature::Linear { knots, cum } => {
                let t_ref = knots[0].1;
                let i = knots.partition_point(|k| k.0 <= t);
                if i == 0 {
                    return 0.0;
                }
                let a = knots[i - 1];
                (cum[i - 1]) + (t - a.0) * (0.5 * (a.1 + self.at(t)) - t_ref)
            }
        }
    }
}

/// An oscillator: fractional frequency error from an offset, a
/// temperature coefficient and a frequency random walk.
#[derive(Clone, Debug)]
pub struct Oscillator {
    y0: f64,
    tc: f64,
    temp: Temperature,
    rw_sd_per_node: f64,
    rw_rng0: SimRng,
    rw_rng: SimRng,
    /// Current random-walk cell [k, k+1] s: values and the integral to k.
    k: u64,
    ya: f64,
    yb: f64,
    pa: f64,
}

impl Oscillator {
    /// `freq_error_ppm` at the starting temperature, `temp_coeff_ppm_per_c`,
    /// and a random walk of `rw_ppm_per_sqrt_h` (the frequency wanders by
    /// that many ppm in one hour, 1σ), drawn from `rw_rng`.
    pub fn new(
        freq_error_ppm: f64,
        temp_coeff_ppm_per_c: f64,
        rw_ppm_per_sqrt_h: f64,
        temp: Temperature,
        rw_rng: SimRng,
    ) -> Self {
        let mut o = Oscillator {
            y0: freq_error_ppm * 1e-6,
            tc: temp_coeff_ppm_per_c * 1e-6,
            temp,
            rw_sd_per_node: rw_ppm_per_sqrt_h * 1e-6 / 60.0,
            rw_rng0: rw_rng.clone(),
            rw_rng,
            k: 0,
            ya: 0.0,
            yb: 0.0,
            pa: 0.0,
        };
        o.reset();
        o
    }

    fn reset(&mut self) {
        self.rw_rng = self.rw_rng0.clone();
        self.k = 0;
        self.ya = 0.0;
        self.pa = 0.0;
        self.yb = self.draw_step();
    }

    fn draw_step(&mut self) -> f64 {
        if self.rw_sd_per_node > 0.0 {
            self.ya + self.rw_sd_per_node * rng::normal(&mut self.rw_rng)
        } else {
            0.0
        }
    }

    fn seek(&mut self, t: f64) {
        if t < self.k as f64 {
            self.reset();
        }
        while t > (self.k + 1) as f64 {
            self.pa += 0.5 * (self.ya + self.yb);
            self.ya = self.yb;
            self.k += 1;
            self.yb = self.draw_step();
        }
    }

    /// Fractional frequency error at `t` (dimensionless).
    pub fn freq_error(&mut self, t: f64) -> f64 {
        let t = t.max(0.0);
        self.seek(t);
        let f = t - self.k as f64;
        let rw = self.ya + (self.yb - self.ya) * f;
        self.y0 + self.tc * (self.temp.at(t) - self.temp.at(0.0)) + rw
    }

    /// ∫₀ᵗ y(s) ds: the local clock's accumulated time error (s).
    pub fn phase(&mut self, t: f64) -> f64 {
        if t <= 0.0 {
            return self.freq_error(0.0) * t;
        }
        self.seek(t);
        let f = t - self.k as f64;
        let rw = self.pa + f * (self.ya + 0.5 * (self.yb - self.ya) * f);
        self.y0 * t + self.tc * self.temp.integral(t) + rw
    }

    /// Local elapsed time τ(t) = t + ∫₀ᵗ y.
    pub fn local_time(&mut self, t: f64) -> f64 {
        t + self.phase(t)
    }

    /// The true time t at which the local elapsed time reaches `tau`
    /// (Newton's method; τ is strictly increasing).
    pub fn true_time(&mut self, tau: f64, guess: f64) -> f64 {
        let mut t = guess;
        for _ in 0..6 {
            let err = self.local_time(t) - tau;
            let step = err / (1.0 + self.freq_error(t));
            t -= step;
            if step.abs() < 1e-13 {
                break;
            }
        }
        t
    }
}

/// The logger's free-running counter (the `counter` of a `rig-log`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CounterSpec {
    /// Nominal frequency (Hz).
    pub hz: f64,
    /// The counter wraps modulo 2^bits.
    pub bits: u32,
    /// Counter value at the scenario start (ticks); default: 200 s before
    /// the first wrap, so that every run crosses a wrap.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start_ticks: Option<f64>,
    pub freq_error_ppm: f64,
    pub temp_coeff_ppm_per_c: f64,
    pub random_walk_ppm_per_sqrt_h: f64,
}

impl Default for CounterSpec {
    fn default() -> Self {
        CounterSpec {
            hz: 1e6,
            bits: 32,
            start_ticks: None,
            freq_error_ppm: 20.0,
            temp_coeff_ppm_per_c: 0.5,
            random_walk_ppm_per_sqrt_h: 0.01,
        }
    }
}

/// A counter: counts of an oscillator, wrapped to its bit width.
#[derive(Clone, Debug)]
pub struct Counter {
    hz: f64,
    bits: u32,
    start: f64,
    osc: Oscillator,
}

impl Counter {
    pub fn new(spec: &CounterSpec, temp: Temperature, rw_rng: SimRng) -> Result<Self, String> {
        if !(spec.hz > 0.0 && spec.hz.is_finite()) {
            return Err(format!("counter frequency {} Hz must be positive", spec.hz));
        }
        if !(8..=64).contains(&spec.bits) {
            return Err(format!("counter bits {} must be within 8..=64", spec.bits));
        }
        let modulus = 2f64.powi(spec.bits as i32);
        let start = spec
            .start_ticks
            .unwrap_or_else(|| (modulus - 200.0 * spec.hz).max(0.0));
        if !(start >= 0.0 && start.is_finite()) {
            return Err(format!("counter start {start} must be >= 0"));
        }
        Ok(Counter {
            hz: spec.hz,
            bits: spec.bits,
            start,
            osc: Oscillator::new(
                spec.freq_error_ppm,
                spec.temp_coeff_ppm_per_c,
                spec.random_walk_ppm_per_sqrt_h,
                temp,
                rw_rng,
            ),
        })
    }

    /// Start value (ticks, fractional).
    pub fn start_ticks(&self) -> f64 {
        self.start
    }

    /// Unwrapped count at true time `t` (fractional ticks).
    pub fn ticks(&mut self, t: f64) -> f64 {
        self.start + self.hz * self.osc.local_time(t)
    }

    /// The value latched at `t`: ⌊count⌋ modulo 2^bits.
    pub fn latch(&mut self, t: f64) -> u64 {
        let c = self.ticks(t).floor();
        let c = if c < 0.0 { 0 } else { c as u128 };
        let modulus = 1u128 << self.bits;
        (c % modulus) as u64
    }

    /// Frequency error at `t` (ppm).
    pub fn freq_error_ppm(&mut self, t: f64) -> f64 {
        self.osc.freq_error(t) * 1e6
    }

    /// The true time of the first wrap after the start, if within `horizon_s`.
    pub fn first_wrap_s(&mut self, horizon_s: f64) -> Option<f64> {
        let modulus = 2f64.powi(self.bits as i32);
        let target = (self.start / modulus).floor() * modulus + modulus;
        let tau = (target - self.start) / self.hz;
        let t = self.osc.true_time(tau, tau);
        (t <= horizon_s).then_some(t)
    }
}

/// The IMU's own sample clock.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuClockSpec {
    pub freq_error_ppm: f64,
    pub temp_coeff_ppm_per_c: f64,
    pub random_walk_ppm_per_sqrt_h: f64,
    /// Start of the first output interval after the scenario start (s,
    /// within one output period); default 0.
    pub phase_s: f64,
}

/// Output-interval boundaries of an IMU in GPS time: boundary k is where
/// the IMU's local time reaches `phase + k·T_out`.
#[derive(Clone, Debug)]
pub struct ImuClock {
    osc: Oscillator,
    period_s: f64,
    phase_s: f64,
    k: u64,
    t: f64,
}

impl ImuClock {
    pub fn new(
        spec: &ImuClockSpec,
        period_s: f64,
        temp: Temperature,
        rw_rng: SimRng,
    ) -> Result<Self, String> {
        if !(spec.phase_s >= 0.0 && spec.phase_s < period_s) {
            return Err(format!(
                "IMU clock phase_s {} must be within [0, {period_s}) s",
                spec.phase_s
            ));
        }
        let mut osc = Oscillator::new(
            spec.freq_error_ppm,
            spec.temp_coeff_ppm_per_c,
            spec.random_walk_ppm_per_sqrt_h,
            temp,
            rw_rng,
        );
        let t0 = osc.true_time(spec.phase_s, spec.phase_s);
        Ok(ImuClock {
            osc,
            period_s,
            phase_s: spec.phase_s,
            k: 0,
            t: t0,
        })
    }

    /// The current boundary: index and true time (s since the start).
    pub fn current(&self) -> (u64, f64) {
        (self.k, self.t)
    }

    /// Advances to the next boundary and returns its true time.
    pub fn advance(&mut self) -> f64 {
        self.k += 1;
        let tau = self.phase_s + self.k as f64 * self.period_s;
        let guess = self.t + self.period_s;
        self.t = self.osc.true_time(tau, guess);
        self.t
    }

    /// Mean output rate over the run so far (Hz).
    pub fn mean_rate_hz(&self, t0: f64) -> f64 {
        if self.k == 0 {
            return 1.0 / self.period_s;
        }
        self.k as f64 / (self.t - t0)
    }

    /// The oscillator's frequency error at `t` (ppm).
    pub fn freq_error_ppm(&mut self, t: f64) -> f64 {
        self.osc.freq_error(t) * 1e6
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperature_integrals_match_quadrature() {
        let specs = [
            TemperatureSpec::Constant { celsius: 20.0 },
            TemperatureSpec::Exponential {
                t0_c: 20.0,
                delta_c: 25.0,
                tau_s: 600.0,
            },
            TemperatureSpec::Ramp {
                t0_c: 15.0,
                rate_c_per_min: 1.0,
                start_s: 100.0,
                end_s: Some(1300.0),
            },
            TemperatureSpec::Points {
                points: vec![[10.0, 20.0], [50.0, 30.0], [80.0, 25.0]],
            },
        ];
        for s in &specs {
            let t = Temperature::new(s).unwrap();
            let end = 2000.0;
            let n = 200_000;
            let h = end / n as f64;
            let t0 = t.at(0.0);
            let num: f64 = (0..n).map(|k| (t.at((k as f64 + 0.5) * h) - t0) * h).sum();
            assert!(
                (num - t.integral(end)).abs() < 1e-3,
                "{s:?}: {num} vs {}",
                t.integral(end)
            );
        }
        let r = Temperature::new(&specs[2]).unwrap();
        assert!((r.at(160.0) - 16.0).abs() < 1e-12);
    }

    #[test]
    fn counter_runs_fast_by_its_ppm_and_wraps() {
        let spec = CounterSpec {
            hz: 1e6,
            bits: 32,
            start_ticks: Some(4_294_967_296.0 - 1_000_000.0),
            freq_error_ppm: 37.0,
            temp_coeff_ppm_per_c: 0.0,
            random_walk_ppm_per_sqrt_h: 0.0,
        };
        let temp = Temperature::new(&TemperatureSpec::default()).unwrap();
        let mut c = Counter::new(&spec, temp, rng::stream(1, "c")).unwrap();
        // After 100 s the counter has run 100·(1+37e-6) s of ticks.
        let d = c.ticks(100.0) - c.ticks(0.0);
        assert!((d - 100_003_700.0).abs() < 1e-4, "{d}");
        // It wraps ~1/(1+37e-6) s after the start.
        let w = c.first_wrap_s(10.0).unwrap();
        assert!((w - 1.0 / (1.0 + 37e-6)).abs() < 1e-9, "{w}");
        assert!(c.latch(w + 1e-3) < 2000);
        assert!(c.latch(w - 1e-3) > 4_294_960_000);
    }

    #[test]
    fn imu_clock_boundaries_follow_the_frequency_error() {
        let temp = Temperature::new(&TemperatureSpec::default()).unwrap();
        let spec = ImuClockSpec {
            freq_error_ppm: -400.0,
            phase_s: 0.002,
            ..Default::default()
        };
        let mut c = ImuClock::new(&spec, 0.005, temp, rng::stream(1, "i")).unwrap();
        let (_, t0) = c.current();
        assert!((t0 - 0.002 / (1.0 - 400e-6)).abs() < 1e-15);
        let mut t = t0;
        for _ in 0..200_000 {
            t = c.advance();
        }
        // 200 Hz nominal really 199.92 Hz.
        let rate = 200_000.0 / (t - t0);
        assert!((rate - 199.92).abs() < 1e-9, "{rate}");
        assert!((c.mean_rate_hz(t0) - 199.92).abs() < 1e-9);
    }

    #[test]
    fn random_walk_is_continuous_and_reproducible() {
        let temp = Temperature::new(&TemperatureSpec::default()).unwrap();
        let mut a = Oscillator::new(0.0, 0.0, 1.0, temp.clone(), rng::stream(5, "rw"));
        let mut b = Oscillator::new(0.0, 0.0, 1.0, temp, rng::stream(5, "rw"));
        let pa = a.phase(3600.0);
        // Walking b in small steps gives the same phase.
        let mut pb = 0.0;
        for k in 1..=36000 {
            pb = b.phase(k as f64 * 0.1);
        }
        assert!((pa - pb).abs() < 1e-15, "{pa} {pb}");
        // The phase derivative equals the frequency error (central difference).
        let y = a.freq_error(1234.56);
        let d = (a.phase(1234.56 + 1e-3) - a.phase(1234.56 - 1e-3)) / 2e-3;
        assert!((y - d).abs() < 1e-12);
        // A query back in time regenerates the same walk.
        assert!((a.phase(3600.0) - pa).abs() < 1e-18);
    }
}
