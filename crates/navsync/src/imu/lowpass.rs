//! Low-pass filters and their delay (seed 001 §1.4).
//!
//! An IMU's noise-reduction low-pass filter (e.g. the ADIS16465's FIR
//! bank) delays the data and so harms dead reckoning; it should be off —
//! the integration in the mechanization already low-passes far better —
//! and, if it cannot be turned off, set to its highest cut-off (seed 001
//! §1.4, citing Ban et al. 2013). When a log was recorded with a filter on,
//! navsync computes the filter's group delay and shifts the time stamps
//! back by it.
//!
//! Group delay of H(z) = B(z)/A(z) with B = Σ b_n z^−n, A = Σ a_n z^−n:
//! τ(ω) = τ_B(ω) − τ_A(ω), τ_C(ω) = Re[ Σ n c_n e^{−jωn} / Σ c_n e^{−jωn} ]
//! (J. O. Smith, *Introduction to Digital Filters*, "Numerical
//! computation of group delay"). At DC, τ(0) = Σ n b_n/Σ b_n − Σ n a_n/Σ a_n
//! samples; a symmetric FIR of N taps has τ = (N − 1)/2 at every frequency.
//! Vehicle dynamics live far below the cut-off, where τ(ω) ≈ τ(0): the
//! DC delay is the one compensated, and the report says how much the
//! delay varies up to a stated dynamics band.
#![warn(missing_docs)]

use std::path::Path;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::error::Error;

/// A linear low-pass filter the IMU applied, running at `sample_rate_hz`
/// (the rate of the stage where it runs: the ADIS16465 filters at its
/// internal 2 kHz, before decimation).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LowPassFilter {
    /// A name for reports.
    pub name: String,
    /// Rate (Hz) of the samples the filter runs on; converts its delay
    /// from samples to seconds.
    pub sample_rate_hz: f64,
    /// Numerator coefficients b_0, b_1, … (FIR taps).
    pub b: Vec<f64>,
    /// Denominator a_0, a_1, … (`[1]` for an FIR).
    pub a: Vec<f64>,
}

/// The file form (TOML), one of:
///
/// ```toml
/// sample_rate_hz = 2000
/// kind = "fir"            # taps = [ ... ]
/// kind = "iir"            # b = [ ... ], a = [ ... ]
/// kind = "moving-average" # n = 16
/// kind = "bartlett"       # n = 8 (two n-tap moving averages in series)
/// kind = "first-order"    # cutoff_hz = 50
/// ```
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LowPassSpec {
    /// `fir`, `iir`, `moving-average`, `bartlett` or `first-order`.
    pub kind: String,
    /// Rate (Hz) of the samples the filter runs on.
    pub sample_rate_hz: f64,
    /// Name for reports; `None` keeps the one derived from the kind.
    #[serde(default)]
    pub name: Option<String>,
    /// FIR taps b_0, b_1, … (`kind = "fir"`), used as written.
    #[serde(default)]
    pub taps: Option<Vec<f64>>,
    /// IIR numerator b_0, b_1, … (`kind = "iir"`).
    #[serde(default)]
    pub b: Option<Vec<f64>>,
    /// IIR denominator a_0, a_1, … (`kind = "iir"`; normalised to a_0 = 1).
    #[serde(default)]
    pub a: Option<Vec<f64>>,
    /// Taps of the moving average, or of each of the two averages of a
    /// Bartlett filter (`2n − 1` taps in all).
    #[serde(default)]
    pub n: Option<usize>,
    /// Cut-off frequency (Hz) of a `first-order` filter.
    #[serde(default)]
    pub cutoff_hz: Option<f64>,
}

/// One point of the delay curve.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub(crate) struct DelayPoint {
    pub(crate) freq_hz: f64,
    pub(crate) delay_s: f64,
    pub(crate) gain_db: f64,
}

/// The group delay of a filter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroupDelay {
    /// At DC, in samples of the filter's rate and in seconds: the delay
    /// compensated in the time stamps.
    pub(crate) dc_samples: f64,
    pub(crate) dc_s: f64,
    pub(crate) dc_gain: f64,
    /// −3 dB frequency (Hz), if the gain falls that far below Nyquist.
    pub cutoff_hz: Option<f64>,
    /// Dynamics band used below (Hz): up to `band_hz` or the cut-off.
    pub(crate) band_hz: f64,
    /// Smallest and largest delay in the band (s).
    pub(crate) band_min_s: f64,
    pub(crate) band_max_s: f64,
    /// The curve from DC to Nyquist (frequencies where the gain is zero
    /// are left out).
    pub(crate) curve: Vec<DelayPoint>,
}

/// The triangular (Bartlett) window of `taps` taps, unnormalised:
/// w_k = min(k + 1, taps − k), k = 0 … taps − 1. It is two moving averages
/// of ⌈taps/2⌉ and ⌊taps/2⌋ + 1 taps in series: an odd count 2n − 1 is two
/// n-tap averages (the FIR stage of many MEMS IMUs, e.g. the ADIS16465's
/// FILT_CTRL), an even count has a flat top of two taps. The simulator's
/// IMU filters and [`LowPassFilter::bartlett`] both use it.
pub fn triangular_weights(taps: usize) -> Vec<f64> {
    (0..taps).map(|k| (k + 1).min(taps - k) as f64).collect()
}

impl LowPassFilter {
    /// An FIR filter from its taps.
    pub fn fir(name: &str, taps: Vec<f64>, sample_rate_hz: f64) -> Result<Self, Error> {
        Self::iir(name, taps, vec![1.0], sample_rate_hz)
    }

    /// An IIR filter b/a (a_0 ≠ 0; normalised so that a_0 = 1).
    pub fn iir(name: &str, b: Vec<f64>, a: Vec<f64>, sample_rate_hz: f64) -> Result<Self, Error> {
        let bad = |m: String| Err(Error::Invalid(format!("low-pass filter '{name}': {m}")));
        if !(sample_rate_hz > 0.0 && sample_rate_hz.is_finite()) {
            return bad(format!(
                "sample_rate_hz must be positive, got {sample_rate_hz}"
            ));
        }
        if b.is_empty() || a.is_empty() {
            return bad("needs at least one coefficient in b (taps) and in a".into());
        }
        if b.iter().chain(&a).any(|x| !x.is_finite()) {
            return bad("coefficients must be finite numbers".into());
        }
        if a[0] == 0.0 {
            return bad("a[0] must not be zero".into());
        }
        let a0 = a[0];
        let b: Vec<f64> = b.iter().map(|x| x / a0).collect();
        let a: Vec<f64> = a.iter().map(|x| x / a0).collect();
        let f = LowPassFilter {
            name: name.to_string(),
            sample_rate_hz,
            b,
            a,
        };
        if f.b.iter().sum::<f64>() == 0.0 || f.a.iter().sum::<f64>() == 0.0 {
            return bad("gain at DC is zero or infinite: not a low-pass filter".into());
        }
        if let Some(r) = f.largest_pole_radius()
            && r >= 1.0
        {
            return bad(format!("unstable: a pole has radius {r:.6} >= 1"));
        }
        Ok(f)
    }

    /// An `n`-tap moving average (boxcar).
    pub(crate) fn moving_average(n: usize, sample_rate_hz: f64) -> Result<Self, Error> {
        if n == 0 {
            return Err(Error::Invalid("moving average needs n >= 1".into()));
        }
        Self::fir(
            &format!("{n}-tap moving average"),
            vec![1.0 / n as f64; n],
            sample_rate_hz,
        )
    }

    /// Two `n`-tap moving averages in series: a (2n − 1)-tap triangular
    /// (Bartlett) window, the form of the FIR stage of many MEMS IMUs.
    pub fn bartlett(n: usize, sample_rate_hz: f64) -> Result<Self, Error> {
        if n == 0 {
            return Err(Error::Invalid("Bartlett filter needs n >= 1".into()));
        }
        let mut f = Self::triangular(2 * n - 1, sample_rate_hz)?;
        f.name = format!("Bartlett (2 x {n}-tap average)");
        Ok(f)
    }

    /// The triangular window of `taps` taps ([`triangular_weights`]),
    /// normalised to unit DC gain.
    pub(crate) fn triangular(taps: usize, sample_rate_hz: f64) -> Result<Self, Error> {
        if taps == 0 {
            return Err(Error::Invalid(
                "triangular filter needs at least 1 tap".into(),
            ));
        }
        let w = triangular_weights(taps);
        let sum: f64 = w.iter().sum();
        Self::fir(
            &format!("triangular ({taps} taps)"),
            w.iter().map(|x| x / sum).collect(),
            sample_rate_hz,
        )
    }

    /// A first-order low-pass y_k = α x_k + (1 − α) y_{k−1}, with
    /// α = 1 − exp(−2π f_c / f_s) (the sampled RC filter).
    pub(crate) fn first_order(cutoff_hz: f64, sample_rate_hz: f64) -> Result<Self, Error> {
        if cutoff_hz.is_nan() || cutoff_hz <= 0.0 {
            return Err(Error::Invalid(
                "first-order filter needs cutoff_hz > 0".into(),
            ));
        }
        let alpha = 1.0 - (-2.0 * std::f64::consts::PI * cutoff_hz / sample_rate_hz).exp();
        Self::iir(
            &format!("first-order {cutoff_hz} Hz"),
            vec![alpha],
            vec![1.0, -(1.0 - alpha)],
            sample_rate_hz,
        )
    }

    /// Builds a filter from its file form.
    pub(crate) fn from_spec(spec: &LowPassSpec) -> Result<Self, Error> {
        let fs = spec.sample_rate_hz;
        let mut f = match spec.kind.as_str() {
            "fir" => {
                let taps = spec
                    .taps
                    .clone()
                    .ok_or_else(|| Error::Invalid("kind = \"fir\" needs taps = [...]".into()))?;
                Self::fir("FIR", taps, fs)?
            }
            "iir" => match (&spec.b, &spec.a) {
                (Some(b), Some(a)) => Self::iir("IIR", b.clone(), a.clone(), fs)?,
                _ => {
                    return Err(Error::Invalid(
                        "kind = \"iir\" needs b = [...] and a = [...]".into(),
                    ));
                }
            },
            "moving-average" => Self::moving_average(
                spec.n
                    .ok_or_else(|| Error::Invalid("kind = \"moving-average\" needs n".into()))?,
                fs,
            )?,
            "bartlett" => Self::bartlett(
                spec.n
                    .ok_or_else(|| Error::Invalid("kind = \"bartlett\" needs n".into()))?,
                fs,
            )?,
            "first-order" => Self::first_order(
                spec.cutoff_hz.ok_or_else(|| {
                    Error::Invalid("kind = \"first-order\" needs cutoff_hz".into())
                })?,
                fs,
            )?,
            k => {
                return Err(Error::Invalid(format!(
                    "unknown filter kind '{k}' (expected fir, iir, moving-average, bartlett, first-order)"
                )));
            }
        };
        if let Some(n) = &spec.name {
            f.name = n.clone();
        }
        Ok(f)
    }

    /// Reads a filter description file (see [`LowPassSpec`]) with `parse`,
    /// the parser of its format: the file form is TOML, and the core has no
    /// TOML parser, so the reader of the file passes one (the CLI:
    /// `LowPassFilter::load_with(path, |t| toml::from_str(t))`). Errors name the
    /// file (and, through the parser's message, the line).
    pub fn load_with<E: std::fmt::Display>(
        path: &Path,
        parse: impl FnOnce(&str) -> Result<LowPassSpec, E>,
    ) -> Result<Self, Error> {
        let text = crate::io::text::read_config_text(path)?;
        let spec: LowPassSpec = parse(&text)
            .map_err(|e| Error::config(path, format!("not a filter description: {e}")))?;
        Self::from_spec(&spec).map_err(|e| Error::config(path, e.to_string()))
    }

    /// Complex frequency response at ω (rad/sample): (re, im).
    fn response(c: &[f64], w: f64) -> ((f64, f64), (f64, f64)) {
        // Σ c_n e^{−jωn} and Σ n c_n e^{−jωn}.
        let (mut re, mut im, mut nre, mut nim) = (0.0, 0.0, 0.0, 0.0);
        for (n, &cn) in c.iter().enumerate() {
            let (s, co) = (w * n as f64).sin_cos();
            re += cn * co;
            im -= cn * s;
            nre += n as f64 * cn * co;
            nim -= n as f64 * cn * s;
        }
        ((re, im), (nre, nim))
    }

    /// τ_C(ω) = Re[ Σ n c_n e^{−jωn} / Σ c_n e^{−jωn} ] (Smith), and |C|².
    fn poly_delay(c: &[f64], w: f64) -> (f64, f64) {
        let ((re, im), (nre, nim)) = Self::response(c, w);
        let mag2 = re * re + im * im;
        ((nre * re + nim * im) / mag2, mag2)
    }

    /// Group delay (samples) and gain |H| at ω (rad/sample); NaN delay
    /// where the gain is zero.
    pub(crate) fn delay_and_gain(&self, w: f64) -> (f64, f64) {
        let (tb, mb) = Self::poly_delay(&self.b, w);
        let (ta, ma) = Self::poly_delay(&self.a, w);
        let gain = (mb / ma).sqrt();
        if mb < 1e-24 * self.b.iter().map(|x| x * x).sum::<f64>() {
            return (f64::NAN, gain);
        }
        (tb - ta, gain)
    }

    /// Group delay at DC in samples: Σ n b_n/Σ b_n − Σ n a_n/Σ a_n.
    pub(crate) fn dc_delay_samples(&self) -> f64 {
        let m = |c: &[f64]| {
            c.iter().enumerate().map(|(n, x)| n as f64 * x).sum::<f64>() / c.iter().sum::<f64>()
        };
        m(&self.b) - m(&self.a)
    }

    /// The delay to subtract from time stamps (s): the DC group delay.
    pub fn delay_compensation_s(&self) -> f64 {
        self.dc_delay_samples() / self.sample_rate_hz
    }

    /// The delay report; `band_hz` is the dynamics band of interest (e.g.
    /// 10 Hz for a land vehicle) over which the delay spread is given.
    pub fn group_delay(&self, band_hz: f64) -> GroupDelay {
        let fs = self.sample_rate_hz;
        let nyq = fs / 2.0;
        let dc_gain = self.b.iter().sum::<f64>() / self.a.iter().sum::<f64>();
        let points = 512;
        let mut curve = Vec::with_capacity(points + 1);
        let mut cutoff = None;
        for k in 0..=points {
            let f = nyq * k as f64 / points as f64;
            let w = 2.0 * std::f64::consts::PI * f / fs;
            let (d, g) = self.delay_and_gain(w);
            let rel = g / dc_gain.abs();
            if cutoff.is_none() && rel < std::f64::consts::FRAC_1_SQRT_2 && k > 0 {
                // Refine between the previous point and this one by bisection.
                let (mut lo, mut hi) = (nyq * (k - 1) as f64 / points as f64, f);
                for _ in 0..50 {
                    let mid = 0.5 * (lo + hi);
                    let (_, gm) = self.delay_and_gain(2.0 * std::f64::consts::PI * mid / fs);
                    if gm / dc_gain.abs() < std::f64::consts::FRAC_1_SQRT_2 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                cutoff = Some(0.5 * (lo + hi));
            }
            if d.is_finite() {
                curve.push(DelayPoint {
                    freq_hz: f,
                    delay_s: d / fs,
                    gain_db: 20.0 * rel.max(1e-300).log10(),
                });
            }
        }
        let band = band_hz.min(cutoff.unwrap_or(nyq)).max(0.0);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let steps = 200;
        for k in 0..=steps {
            let f = band * k as f64 / steps as f64;
            let (d, _) = self.delay_and_gain(2.0 * std::f64::consts::PI * f / fs);
            if d.is_finite() {
                lo = lo.min(d / fs);
                hi = hi.max(d / fs);
            }
        }
        let dc = self.dc_delay_samples();
        GroupDelay {
            dc_samples: dc,
            dc_s: dc / fs,
            dc_gain,
            cutoff_hz: cutoff,
            band_hz: band,
            band_min_s: lo,
            band_max_s: hi,
            curve,
        }
    }

    /// The warning seed 001 §1.4 asks for.
    pub fn warning(&self, gd: &GroupDelay) -> String {
        format!(
            "the IMU applied a low-pass filter ({}, {} Hz): it delays the data by {:.3} ms ({:.2} samples at DC{}). \
             Tang, Zhang & Niu (\"MEMS IMU raw data acquisition and time synchronization pitfalls\", 2022, §1.4) advise: turn the filter off (or set its cut-off to the highest); \
             navsync shifts the time stamps back by {:.3} ms (the delay varies {:.3}–{:.3} ms up to {:.1} Hz)",
            self.name,
            self.sample_rate_hz,
            gd.dc_s * 1e3,
            gd.dc_samples,
            gd.cutoff_hz
                .map(|c| format!(", −3 dB at {c:.1} Hz"))
                .unwrap_or_default(),
            gd.dc_s * 1e3,
            gd.band_min_s * 1e3,
            gd.band_max_s * 1e3,
            gd.band_hz
        )
    }

    /// Radius of the largest pole (None for an FIR).
    fn largest_pole_radius(&self) -> Option<f64> {
        let n = self.a.len() - 1;
        if n == 0 {
            return None;
        }
        // Poles: roots of z^n + a_1 z^{n−1} + … + a_n; companion matrix.
        let mut m = DMatrix::<f64>::zeros(n, n);
        for j in 0..n {
            m[(0, j)] = -self.a[j + 1];
        }
        for i in 1..n {
            m[(i, i - 1)] = 1.0;
        }
        let ev = m.complex_eigenvalues();
        Some(ev.iter().map(|c| c.norm()).fold(0.0, f64::max))
    }

    /// A streaming instance of the filter (direct form II transposed).
    #[cfg(test)]
    pub(crate) fn runner(&self) -> FilterRunner {
        FilterRunner {
            b: self.b.clone(),
            a: self.a.clone(),
            z: vec![0.0; self.b.len().max(self.a.len())],
        }
    }
}

/// Runs a filter on one channel, sample by sample (to simulate what the
/// IMU did, and in tests).
#[cfg(test)]
#[derive(Clone, Debug)]
pub(crate) struct FilterRunner {
    b: Vec<f64>,
    a: Vec<f64>,
    z: Vec<f64>,
}

#[cfg(test)]
impl FilterRunner {
    /// Starts the filter in steady state at `x0` (no start-up transient).
    pub(crate) fn prime(&mut self, x0: f64) {
        let gain = self.b.iter().sum::<f64>() / self.a.iter().sum::<f64>();
        let y0 = gain * x0;
        // DF-II transposed steady state: z_i = Σ_{k>i} (b_k x0 − a_k y0).
        let n = self.z.len();
        for i in 0..n {
            let mut s = 0.0;
            for k in (i + 1)..n {
                s += self.b.get(k).copied().unwrap_or(0.0) * x0
                    - self.a.get(k).copied().unwrap_or(0.0) * y0;
            }
            self.z[i] = s;
        }
    }

    /// Filters one sample.
    pub(crate) fn step(&mut self, x: f64) -> f64 {
        let n = self.z.len();
        let b = |k: usize| self.b.get(k).copied().unwrap_or(0.0);
        let a = |k: usize| self.a.get(k).copied().unwrap_or(0.0);
        let y = b(0) * x + if n > 1 { self.z[0] } else { 0.0 };
        for i in 0..n.saturating_sub(1) {
            let next = if i + 1 < n - 1 { self.z[i + 1] } else { 0.0 };
            self.z[i] = b(i + 1) * x - a(i + 1) * y + next;
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangular_window_is_two_moving_averages_in_series() {
        // ⌈N/2⌉- and (⌊N/2⌋+1)-tap boxes convolved: odd and even counts.
        for taps in 1..12usize {
            let (p, q) = (taps.div_ceil(2), taps / 2 + 1);
            let mut conv = vec![0.0; p + q - 1];
            for i in 0..p {
                for j in 0..q {
                    conv[i + j] += 1.0;
                }
            }
            assert_eq!(triangular_weights(taps), conv, "{taps} taps");
        }
        assert_eq!(triangular_weights(4), vec![1.0, 2.0, 2.0, 1.0]);
        // Bartlett(n) is the (2n − 1)-tap window at unit DC gain.
        let b = LowPassFilter::bartlett(3, 100.0).unwrap();
        let w: Vec<f64> = [1.0, 2.0, 3.0, 2.0, 1.0].iter().map(|x| x / 9.0).collect();
        assert_eq!(b.b, w);
        assert!(LowPassFilter::triangular(0, 100.0).is_err());
    }

    #[test]
    fn symmetric_fir_delays_half_its_length_at_every_frequency() {
        // A symmetric (linear-phase) FIR of N taps: τ = (N − 1)/2 exactly.
        let taps = vec![0.05, 0.1, 0.2, 0.3, 0.2, 0.1, 0.05];
        let f = LowPassFilter::fir("sym", taps, 2000.0).unwrap();
        assert!((f.dc_delay_samples() - 3.0).abs() < 1e-12);
        let gd = f.group_delay(10.0);
        for p in &gd.curve {
            // Near a zero of the response (gain below −60 dB) the ratio
            // loses digits; elsewhere it is exact to rounding.
            let tol = if p.gain_db > -60.0 { 1e-9 } else { 1e-5 };
            assert!((p.delay_s * 2000.0 - 3.0).abs() < tol, "{p:?}");
        }
        assert!((gd.dc_s - 1.5e-3).abs() < 1e-15);
        let b = LowPassFilter::bartlett(8, 2000.0).unwrap();
        assert_eq!(b.b.len(), 15);
        assert!((b.dc_delay_samples() - 7.0).abs() < 1e-12);
        let m = LowPassFilter::moving_average(16, 2000.0).unwrap();
        assert!((m.dc_delay_samples() - 7.5).abs() < 1e-12);
        // Its nulls (multiples of 125 Hz) have no defined delay and are skipped.
        assert!(
            m.group_delay(10.0)
                .curve
                .iter()
                .all(|p| (p.delay_s * 2000.0 - 7.5).abs() < 1e-5)
        );
    }

    #[test]
    fn first_order_iir_delay_at_dc_is_one_minus_alpha_over_alpha() {
        // y_k = α x_k + (1 − α) y_{k−1}: H(z) = α/(1 − (1 − α) z⁻¹),
        // τ(0) = (1 − α)/α samples.
        let alpha = 0.2;
        let f = LowPassFilter::iir("rc", vec![alpha], vec![1.0, -(1.0 - alpha)], 100.0).unwrap();
        assert!((f.dc_delay_samples() - 4.0).abs() < 1e-12);
        let gd = f.group_delay(1.0);
        assert!((gd.dc_s - 0.04).abs() < 1e-12);
        // Closed form for a one-pole filter with pole p: τ(ω) = (p cos ω − p²)/(1 − 2p cos ω + p²).
        let p: f64 = 1.0 - alpha;
        for w in [0.0f64, 0.1, 0.5, 1.0, 3.0] {
            let want = (p * w.cos() - p * p) / (1.0 - 2.0 * p * w.cos() + p * p);
            let (d, _) = f.delay_and_gain(w);
            assert!((d - want).abs() < 1e-12, "{w}: {d} vs {want}");
        }
        // −3 dB of the one-pole filter: cos ω_c = 1 − (1−p)²/(2p).
        let wc = (1.0 - (1.0 - p).powi(2) / (2.0 * p)).acos();
        assert!((gd.cutoff_hz.unwrap() - wc * 100.0 / (2.0 * std::f64::consts::PI)).abs() < 1e-6);
    }

    #[test]
    fn a_ramp_through_the_filter_lags_by_the_dc_delay() {
        // A unit-DC-gain LTI filter turns a ramp x = c·k into c·(k − τ(0))
        // in steady state: the definition of the DC group delay in time.
        for f in [
            LowPassFilter::first_order(30.0, 1000.0).unwrap(),
            LowPassFilter::bartlett(4, 1000.0).unwrap(),
            LowPassFilter::iir(
                "2nd",
                vec![0.02, 0.04, 0.02],
                vec![1.0, -1.56, 0.64],
                1000.0,
            )
            .unwrap(),
        ] {
            let mut r = f.runner();
            r.prime(0.0);
            let c = 0.01;
            let mut y = 0.0;
            let n = 4000;
            for k in 0..=n {
                y = r.step(c * k as f64);
            }
            let lag = n as f64 - y / c / (f.b.iter().sum::<f64>() / f.a.iter().sum::<f64>());
            assert!(
                (lag - f.dc_delay_samples()).abs() < 1e-6,
                "{}: {lag} vs {}",
                f.name,
                f.dc_delay_samples()
            );
        }
    }

    #[test]
    fn bad_descriptions_are_refused_with_reasons() {
        assert!(
            LowPassFilter::iir("x", vec![1.0], vec![1.0, -1.5], 100.0)
                .unwrap_err()
                .to_string()
                .contains("unstable")
        );
        assert!(
            LowPassFilter::fir("x", vec![1.0, -1.0], 100.0)
                .unwrap_err()
                .to_string()
                .contains("DC")
        );
        assert!(LowPassFilter::iir("x", vec![1.0], vec![0.0, 1.0], 100.0).is_err());
        assert!(LowPassFilter::fir("x", vec![], 100.0).is_err());
        let spec: LowPassSpec =
            toml::from_str("kind = \"iir\"\nsample_rate_hz = 100\nb = [1]").unwrap();
        assert!(
            LowPassFilter::from_spec(&spec)
                .unwrap_err()
                .to_string()
                .contains("needs b")
        );
        let spec: LowPassSpec = toml::from_str(
            "kind = \"bartlett\"\nsample_rate_hz = 2000\nn = 4\nname = \"ADIS FIR\"",
        )
        .unwrap();
        let f = LowPassFilter::from_spec(&spec).unwrap();
        assert_eq!(f.name, "ADIS FIR");
        assert!((f.delay_compensation_s() - 1.5e-3).abs() < 1e-15);
        assert!(f.warning(&f.group_delay(10.0)).contains("1.500 ms"));
    }
}
