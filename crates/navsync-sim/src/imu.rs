//! IMU error models and the IMU's internal signal chain.
//!
//! Measurement model of each triad (gyro on ω_ib^b, accelerometer on f^b):
//!
//! m = (I + diag(s) + M)·x + b_on + b_drift(t) + n
//!
//! with a turn-on bias `b_on`, a scale-factor error `s` and a small axis
//! misalignment `M` (off-diagonal) drawn once per run; a bias drift that is
//! either flicker noise (the "bias instability" B of a datasheet, IEEE Std
//! 952 C.1.3, approximated by a bank of first-order Gauss–Markov processes
//! with log-spaced correlation times, each of variance B²·ln(r)/π: a bank
//! whose one-sided PSD is B²/(π f) between its corners) or a single
//! first-order Gauss–Markov process (KF-GINS's model); and white noise of
//! density N (ARW, VRW).
//!
//! The chain (seed 001 §1.2–1.4): the sensor is sampled at a high internal
//! rate (e.g. 2 kHz) on the IMU's own clock; each sample saturates at the
//! range; an optional low-pass filter (FIR/IIR, with its group delay)
//! runs at the internal rate; the output is decimated by N = DEC_RATE + 1
//! (ADIS16465: output rate = 2000/(DEC_RATE+1), seed 001 §1.3.1), either by
//! averaging (rate output = mean of the N samples; increment output =
//! Σ (x_n + x_{n−1})/2·T_int, the ADIS delta-angle formula, seed 001
//! figure 2) or by keeping one sample in N (point decimation; increment =
//! rate·T_out); outputs are quantized to their LSB. An IMU with no
//! internal rate (`internal_rate_hz = 0`) is an ideal integrating sensor:
//! its increments are the exact integrals, with the same errors applied
//! per output interval.
//!
//! Every error source draws from its own random stream (`imu.gyro.white`,
//! `imu.accel.turn_on`, …), so switching one off changes no other.

use std::f64::consts::{PI, SQRT_2};

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::clock::ImuClockSpec;
use super::rng::{self, SimRng};
pub use navsync::imu::spec::{AccelSpec, G0, GyroSpec};
use navsync::ins::ImuErrors;

const DEG: f64 = PI / 180.0;
const DEG_H: f64 = DEG / 3600.0;
const MGAL: f64 = 1e-5;

/// How the internal samples are reduced to the output rate.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Decimation {
    /// Mean of the N samples (rate) / trapezoid accumulation (increment).
    #[default]
    Average,
    /// One sample in N (aliases vibration).
    Point,
}

/// What the IMU sends (and what a `rig-log` `imu` record holds).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutputKind {
    /// Angular rate (rad/s) and specific force (m/s²).
    #[default]
    Rate,
    /// Angle (rad) and velocity (m/s) increments.
    Increment,
}

/// Model of the bias drift.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DriftModel {
    /// Flicker (1/f) noise of the bias instability over `flicker_band_s`.
    #[default]
    Flicker,
    /// One first-order Gauss–Markov process, σ = bias instability,
    /// correlation time `gm_corr_time_s`.
    GaussMarkov,
}

/// A low-pass filter inside the IMU (seed 001 §1.4: better off; if on,
/// its group delay must be compensated).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LowPassSpec {
    /// Triangular (Bartlett) FIR of `taps` taps (ADIS16465 FILT_CTRL kind):
    /// `navsync::imu::lowpass::triangular_weights`, the window
    /// `LowPassFilter::bartlett(n)` is for `taps` = 2n − 1.
    Bartlett { taps: usize },
    /// FIR with the given taps (normalised to unit DC gain).
    Fir { taps: Vec<f64> },
    /// IIR `b`/`a` (a[0] ≠ 0; normalised to unit DC gain).
    Iir { b: Vec<f64>, a: Vec<f64> },
    /// Second-order Butterworth (bilinear transform with pre-warping).
    Butterworth { cutoff_hz: f64 },
}

impl LowPassSpec {
    /// The filter coefficients (b, a) at sample rate `fs`, normalised to
    /// unit DC gain.
    pub fn coefficients(&self, fs: f64) -> Result<(Vec<f64>, Vec<f64>), String> {
        let (b, a) = match self {
            LowPassSpec::Bartlett { taps } => {
                if *taps == 0 {
                    return Err("bartlett filter needs at least 1 tap".into());
                }
                // The core's triangular window (two moving averages in series).
                (navsync::imu::lowpass::triangular_weights(*taps), vec![1.0])
            }
            LowPassSpec::Fir { taps } => (taps.clone(), vec![1.0]),
            LowPassSpec::Iir { b, a } => (b.clone(), a.clone()),
            LowPassSpec::Butterworth { cutoff_hz } => {
                if !(*cutoff_hz > 0.0 && *cutoff_hz < 0.5 * fs) {
                    return Err(format!(
                        "butterworth cutoff {cutoff_hz} Hz must be between 0 and half the internal rate ({fs} Hz)"
                    ));
                }
                // Bilinear transform of 1/(s² + √2 s + 1) with pre-warping
                // (Oppenheim & Schafer, Discrete-Time Signal Processing, §7.1).
                let k = (PI * cutoff_hz / fs).tan();
                let norm = 1.0 / (1.0 + SQRT_2 * k + k * k);
                let b0 = k * k * norm;
                (
                    vec![b0, 2.0 * b0, b0],
                    vec![
                        1.0,
                        2.0 * (k * k - 1.0) * norm,
                        (1.0 - SQRT_2 * k + k * k) * norm,
                    ],
                )
            }
        };
        if b.is_empty() || a.is_empty() || a[0] == 0.0 || b.iter().chain(&a).any(|x| !x.is_finite())
        {
            return Err("filter needs finite coefficients, b not empty and a[0] != 0".into());
        }
        let gain = b.iter().sum::<f64>() / a.iter().sum::<f64>();
        if !gain.is_finite() || gain == 0.0 {
            return Err("filter has no DC gain (it does not pass a constant)".into());
        }
        let a0 = a[0];
        let b: Vec<f64> = b.iter().map(|x| x / a0 / gain).collect();
        let a: Vec<f64> = a.iter().map(|x| x / a0).collect();
        Ok((b, a))
    }

    /// Group delay at DC (s) at sample rate `fs`: for H = B/A,
    /// τ = Σk·b_k/Σb_k − Σk·a_k/Σa_k samples (the derivative of the phase at
    /// ω = 0; a symmetric FIR of N taps gives (N−1)/2).
    pub fn group_delay_s(&self, fs: f64) -> Result<f64, String> {
        let (b, a) = self.coefficients(fs)?;
        let moment = |c: &[f64]| {
            c.iter().enumerate().map(|(k, x)| k as f64 * x).sum::<f64>() / c.iter().sum::<f64>()
        };
        Ok((moment(&b) - moment(&a)) / fs)
    }
}

/// Direct-form II transposed filter state.
#[derive(Clone, Debug)]
struct Filter {
    b: Vec<f64>,
    a: Vec<f64>,
    z: Vec<f64>,
}

impl Filter {
    fn new(b: Vec<f64>, a: Vec<f64>) -> Self {
        let n = b.len().max(a.len());
        let mut b = b;
        let mut a = a;
        b.resize(n, 0.0);
        a.resize(n, 0.0);
        Filter {
            b,
            a,
            z: vec![0.0; n.saturating_sub(1)],
        }
    }

    /// Sets the state as if `x` had been the input forever.
    fn prime(&mut self, x: f64) {
        let y = x; // unit DC gain
        let n = self.z.len();
        let mut next = 0.0;
        for i in (0..n).rev() {
            self.z[i] = self.b[i + 1] * x - self.a[i + 1] * y + next;
            next = self.z[i];
        }
    }

    #[inline]
    fn process(&mut self, x: f64) -> f64 {
        let n = self.z.len();
        if n == 0 {
            return self.b[0] * x;
        }
        let y = self.b[0] * x + self.z[0];
        for i in 0..n - 1 {
            self.z[i] = self.b[i + 1] * x - self.a[i + 1] * y + self.z[i + 1];
        }
        self.z[n - 1] = self.b[n] * x - self.a[n] * y;
        y
    }
}

/// An IMU: its chain, its errors and its sample clock.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuSpec {
    /// Preset this spec started from (informational).
    pub grade: String,
    pub output_rate_hz: f64,
    /// Internal sampling rate; an integer multiple of the output rate, or
    /// 0 for an ideal integrating IMU (exact increments).
    pub internal_rate_hz: f64,
    pub decimation: Decimation,
    pub output: OutputKind,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub filter: Option<LowPassSpec>,
    pub bias_drift: DriftModel,
    /// Correlation-time band of the flicker bank (s).
    pub flicker_band_s: [f64; 2],
    /// Correlation time of the Gauss–Markov drift (s).
    pub gm_corr_time_s: f64,
    pub gyro: GyroSpec,
    pub accel: AccelSpec,
    pub clock: ImuClockSpec,
}

impl Default for ImuSpec {
    fn default() -> Self {
        ImuSpec {
            grade: "custom".into(),
            output_rate_hz: 200.0,
            internal_rate_hz: 2000.0,
            decimation: Decimation::Average,
            output: OutputKind::Increment,
            filter: None,
            bias_drift: DriftModel::Flicker,
            flicker_band_s: [0.1, 20_000.0],
            gm_corr_time_s: navsync::imu::spec::PRESET_BIAS_CORR_TIME_S,
            gyro: GyroSpec::default(),
            accel: AccelSpec::default(),
            clock: ImuClockSpec::default(),
        }
    }
}

/// The named presets.
pub const IMU_PRESETS: &[&str] = &["nav", "tactical", "adis16465", "icm20602", "perfect"];

impl ImuSpec {
    /// Whether output rates are averages over their output interval (an
    /// averaging decimation, or the ideal integrating IMU) rather than
    /// instantaneous samples (point decimation).
    pub fn rates_are_interval_averages(&self) -> bool {
        self.decimation == Decimation::Average || self.internal_rate_hz == 0.0
    }

    /// A preset by name:
    /// - `nav`: navigation grade, Leador-A15 class (i2Nav reference IMU):
    ///   ARW 0.003°/√h, gyro bias instability 0.027°/h, VRW 0.03 m/s/√h,
    ///   accelerometer bias instability 15 mGal;
    /// - `tactical`: Honeywell HG1700 class: ARW 0.125°/√h, 1°/h, VRW 0.04
    ///   m/s/√h (65 µg/√Hz), 50 mGal, 1 mg turn-on;
    /// - `adis16465`: ADIS16465-1 datasheet: ARW 0.15°/√h, 2°/h in-run,
    ///   ±0.05° misalignment, ±125°/s, ±8 g, 3.6 µg in-run, 2 kHz internal
    ///   rate, DEC_RATE 9; VRW 0.04 m/s/√h and turn-on/scale as the shared
    ///   reference simulator's `adis16465` grade;
    /// - `icm20602`: InvenSense ICM-20602 datasheet: gyro noise 0.004°/s/√Hz
    ///   (ARW 0.24°/√h), accel 100 µg/√Hz (VRW 0.059 m/s/√h), ±250°/s and
    ///   ±4 g at 16 bits (LSB 1/131 °/s, 1/8192 g), ±1 % sensitivity, ±2 %
    ///   cross-axis; 1 kHz internal sampling (seed 001 §1.3.2), bias
    ///   instability 10°/h (i2Nav awesome-gins-datasets), a −400 ppm sample
    ///   clock (200 Hz really 199.92 Hz);
    /// - `perfect`: no errors, exact increments.
    pub fn preset(name: &str) -> Option<ImuSpec> {
        // The gyro and accelerometer figures are the datasheets' (the
        // core's `navsync::imu::spec`, shared with the sensor sheet); the
        // chain and the clock are the simulator's.
        let (gyro, accel) = navsync::imu::spec::preset_triads(name)?;
        let base = ImuSpec {
            grade: name.to_string(),
            gyro,
            accel,
            ..ImuSpec::default()
        };
        Some(match name {
            "adis16465" => ImuSpec {
                output: OutputKind::Rate,
                ..base
            },
            "icm20602" => ImuSpec {
                internal_rate_hz: 1000.0,
                output: OutputKind::Rate,
                clock: ImuClockSpec {
                    freq_error_ppm: -400.0,
                    temp_coeff_ppm_per_c: 1.0,
                    ..ImuClockSpec::default()
                },
                ..base
            },
            "perfect" => ImuSpec {
                internal_rate_hz: 0.0,
                ..base
            },
            _ => base,
        })
    }

    /// Decimation factor N = internal/output (DEC_RATE + 1); 0 for an
    /// ideal integrating IMU.
    pub fn decimation_factor(&self) -> Result<usize, String> {
        if !(self.output_rate_hz > 0.0 && self.output_rate_hz.is_finite()) {
            return Err(format!(
                "IMU output rate {} Hz must be positive",
                self.output_rate_hz
            ));
        }
        if self.internal_rate_hz == 0.0 {
            return Ok(0);
        }
        let r = self.internal_rate_hz / self.output_rate_hz;
        let n = r.round();
        if !(n >= 1.0 && (r - n).abs() < 1e-9) {
            return Err(format!(
                "IMU internal rate {} Hz must be an integer multiple of the output rate {} Hz (DEC_RATE + 1)",
                self.internal_rate_hz, self.output_rate_hz
            ));
        }
        Ok(n as usize)
    }

    /// Group delay of the low-pass filter (s), 0 without one.
    pub fn filter_delay_s(&self) -> Result<f64, String> {
        match (&self.filter, self.internal_rate_hz > 0.0) {
            (Some(f), true) => f.group_delay_s(self.internal_rate_hz),
            (Some(_), false) => Err("a low-pass filter needs an internal sampling rate".into()),
            (None, _) => Ok(0.0),
        }
    }
}

/// One triad's errors in SI units.
#[derive(Clone, Debug)]
struct TriadSi {
    /// White-noise density (unit/√s).
    density: f64,
    bias_instability: f64,
    turn_on_sd: f64,
    scale_sd: f64,
    misalign_sd: f64,
    range: f64,
    rate_lsb: f64,
    delta_lsb: f64,
}

impl TriadSi {
    fn gyro(g: &GyroSpec) -> Self {
        TriadSi {
            density: g.arw_deg_sqrt_h * DEG / 60.0,
            bias_instability: g.bias_instability_deg_h * DEG_H,
            turn_on_sd: g.turn_on_bias_deg_h * DEG_H,
            scale_sd: g.scale_ppm * 1e-6,
            misalign_sd: g.misalignment_deg * DEG,
            range: g.range_deg_s * DEG,
            rate_lsb: g.rate_lsb_deg_s * DEG,
            delta_lsb: g.delta_lsb_deg * DEG,
        }
    }

    fn accel(a: &AccelSpec) -> Self {
        TriadSi {
            density: a.vrw_mps_sqrt_h / 60.0,
            bias_instability: a.bias_instability_mgal * MGAL,
            turn_on_sd: a.turn_on_bias_mgal * MGAL,
            scale_sd: a.scale_ppm * 1e-6,
            misalign_sd: a.misalignment_deg * DEG,
            range: a.range_g * G0,
            rate_lsb: a.rate_lsb_mps2,
            delta_lsb: a.delta_lsb_mps,
        }
    }

    fn check(&self, what: &str) -> Result<(), String> {
        let v = [
            self.density,
            self.bias_instability,
            self.turn_on_sd,
            self.scale_sd,
            self.misalign_sd,
            self.range,
            self.rate_lsb,
            self.delta_lsb,
        ];
        if v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(format!("{what} error figures must be finite and >= 0"));
        }
        Ok(())
    }
}

/// A first-order Gauss–Markov process per axis, updated every `every`
/// output intervals: x ← φx + σ√(1−φ²)·w, φ = e^{−Δt/T} (exact
/// discretisation; Brown & Hwang, *Introduction to Random Signals*, §4.2).
#[derive(Clone, Debug)]
struct GaussMarkov {
    phi: f64,
    q: f64,
    every: u32,
    count: u32,
    x: Vector3<f64>,
}

/// The drawn errors of one triad (SI), reported in `scenario.json`.
#[derive(Clone, Debug, Serialize)]
pub struct TriadDrawn {
    /// rad/s or m/s².
    pub turn_on_bias: [f64; 3],
    /// Dimensionless.
    pub scale: [f64; 3],
    /// Full error matrix I + diag(s) + M (row-major).
    pub matrix: [[f64; 3]; 3],
    /// Drift at the start (rad/s or m/s²).
    pub drift_at_start: [f64; 3],
    /// Correlation times of the drift components (s) and their σ.
    pub drift_corr_times_s: Vec<f64>,
    pub drift_component_sd: Vec<f64>,
}

#[derive(Clone, Debug)]
struct Triad {
    si: TriadSi,
    m: Matrix3<f64>,
    turn_on: Vector3<f64>,
    scale: Vector3<f64>,
    drift: Vec<GaussMarkov>,
    drift_sum: Vector3<f64>,
    white: SimRng,
    drift_rng: SimRng,
    drawn: TriadDrawn,
}

impl Triad {
    fn new(si: TriadSi, spec: &ImuSpec, seed: u64, name: &str) -> Self {
        let mut turn_on_rng = rng::stream(seed, &format!("imu.{name}.turn_on"));
        let mut scale_rng = rng::stream(seed, &format!("imu.{name}.scale"));
        let mut mis_rng = rng::stream(seed, &format!("imu.{name}.misalignment"));
        let mut drift_rng = rng::stream(seed, &format!("imu.{name}.drift"));
        let white = rng::stream(seed, &format!("imu.{name}.white"));
        let n3 = |r: &mut SimRng, sd: f64| {
            Vector3::new(
                sd * rng::normal(r),
                sd * rng::normal(r),
                sd * rng::normal(r),
            )
        };
        let turn_on = n3(&mut turn_on_rng, si.turn_on_sd);
        let scale = n3(&mut scale_rng, si.scale_sd);
        let mut m = Matrix3::identity() + Matrix3::from_diagonal(&scale);
        for i in 0..3 {
            for j in 0..3 {
                if i != j {
                    m[(i, j)] = si.misalign_sd * rng::normal(&mut mis_rng);
                }
            }
        }
        let t_out = 1.0 / spec.output_rate_hz;
        let mut comps: Vec<(f64, f64)> = Vec::new();
        if si.bias_instability > 0.0 {
            match spec.bias_drift {
                DriftModel::GaussMarkov => comps.push((spec.gm_corr_time_s, si.bias_instability)),
                DriftModel::Flicker => {
                    // Half-decade spacing: each component carries B²·ln(r)/π.
                    let r = 10f64.sqrt();
                    let (lo, hi) = (spec.flicker_band_s[0], spec.flicker_band_s[1]);
                    let sd = si.bias_instability * (r.ln() / PI).sqrt();
                    // From `lo` up to the first correlation time ≥ `hi`.
                    let mut t = lo;
                    loop {
                        comps.push((t, sd));
                        if t >= hi * 0.9999 {
                            break;
                        }
                        t *= r;
                    }
                }
            }
        }
        let mut drift = Vec::new();
        let mut drift_sum = Vector3::zeros();
        for &(tc, sd) in &comps {
            // Update often enough to resolve the process (Δt ≤ T/20).
            let every = ((tc / 20.0 / t_out).floor() as u32).max(1);
            let dt = every as f64 * t_out;
            let phi = (-dt / tc).exp();
            let x = n3(&mut drift_rng, sd);
            drift_sum += x;
            drift.push(GaussMarkov {
                phi,
                q: sd * (1.0 - phi * phi).sqrt(),
                every,
                count: 0,
                x,
            });
        }
        let drawn = TriadDrawn {
            turn_on_bias: turn_on.into(),
            scale: scale.into(),
            matrix: [
                [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
            ],
            drift_at_start: drift_sum.into(),
            drift_corr_times_s: comps.iter().map(|c| c.0).collect(),
            drift_component_sd: comps.iter().map(|c| c.1).collect(),
        };
        Triad {
            si,
            m,
            turn_on,
            scale,
            drift,
            drift_sum,
            white,
            drift_rng,
            drawn,
        }
    }

    /// Advances the drift by one output interval.
    fn step_drift(&mut self) {
        if self.drift.is_empty() {
            return;
        }
        let mut sum = Vector3::zeros();
        for c in &mut self.drift {
            c.count += 1;
            if c.count >= c.every {
                c.count = 0;
                for k in 0..3 {
                    c.x[k] = c.phi * c.x[k] + c.q * rng::normal(&mut self.drift_rng);
                }
            }
            sum += c.x;
        }
        self.drift_sum = sum;
    }

    #[inline]
    /// The off-diagonal terms of M in [`ImuErrors`]' order.
    fn misalign(&self) -> [f64; 6] {
        let m = &self.m;
        [
            m[(0, 1)],
            m[(0, 2)],
            m[(1, 0)],
            m[(1, 2)],
            m[(2, 0)],
            m[(2, 1)],
        ]
    }

    fn bias(&self) -> Vector3<f64> {
        self.turn_on + self.drift_sum
    }

    /// Three white-noise draws of σ `sd` (no draw when `sd` is 0).
    #[inline]
    fn draw_white(&mut self, sd: f64) -> Vector3<f64> {
        if sd > 0.0 {
            Vector3::new(
                sd * rng::normal(&mut self.white),
                sd * rng::normal(&mut self.white),
                sd * rng::normal(&mut self.white),
            )
        } else {
            Vector3::zeros()
        }
    }

    /// One internal sample: errors, white noise of σ = N·√fs, saturation.
    #[inline]
    fn sample(&mut self, x: &Vector3<f64>, noise_sd: f64) -> Vector3<f64> {
        let mut y = self.m * x + self.bias();
        if noise_sd > 0.0 {
            for k in 0..3 {
                y[k] += noise_sd * rng::normal(&mut self.white);
            }
        }
        if self.si.range > 0.0 {
            y = y.map(|v| v.clamp(-self.si.range, self.si.range));
        }
        y
    }
}

#[inline]
fn quantize(x: f64, lsb: f64) -> f64 {
    if lsb > 0.0 {
        (x / lsb).round() * lsb
    } else {
        x
    }
}

/// One output sample of the IMU, in both forms (already quantized).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct ImuOutput {
    /// Angular rate (rad/s) and specific force (m/s²) as a rate output.
    pub gyro_rate: Vector3<f64>,
    pub accel_rate: Vector3<f64>,
    /// Angle (rad) and velocity (m/s) increments as an increment output.
    pub dtheta: Vector3<f64>,
    pub dvel: Vector3<f64>,
}

/// The drawn errors of an IMU, reported in `scenario.json`.
#[derive(Clone, Debug, Serialize)]
pub struct ImuDrawn {
    pub gyro: TriadDrawn,
    pub accel: TriadDrawn,
    pub filter_group_delay_s: f64,
    pub decimation_factor: usize,
}

/// A streaming IMU: push the true signal, get outputs.
#[derive(Clone, Debug)]
pub struct ImuSensor {
    gyro: Triad,
    accel: Triad,
    n_dec: usize,
    t_int: f64,
    t_out: f64,
    decimation: Decimation,
    filters: Option<Vec<Filter>>,
    filter_delay_s: f64,
    count: usize,
    sum: [f64; 6],
    trap: [f64; 6],
    prev: [f64; 6],
    last: [f64; 6],
    primed: bool,
    gyro_sd_int: f64,
    accel_sd_int: f64,
}

impl ImuSensor {
    /// Builds the sensor and draws its errors from `seed`.
    pub fn new(spec: &ImuSpec, seed: u64) -> Result<Self, String> {
        let n_dec = spec.decimation_factor()?;
        let g = TriadSi::gyro(&spec.gyro);
        let a = TriadSi::accel(&spec.accel);
        g.check("gyro")?;
        a.check("accelerometer")?;
        if spec.bias_drift == DriftModel::Flicker
            && !(spec.flicker_band_s[0] > 0.0 && spec.flicker_band_s[1] >= spec.flicker_band_s[0])
        {
            return Err(format!(
                "flicker_band_s {:?} must be increasing and positive",
                spec.flicker_band_s
            ));
        }
        if spec.bias_drift == DriftModel::GaussMarkov
            && spec.gm_corr_time_s.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        {
            return Err("gm_corr_time_s must be positive".into());
        }
        let filter_delay_s = spec.filter_delay_s()?;
        let filters = match &spec.filter {
            Some(f) if n_dec > 0 => {
                let (b, a) = f.coefficients(spec.internal_rate_hz)?;
                Some((0..6).map(|_| Filter::new(b.clone(), a.clone())).collect())
            }
            _ => None,
        };
        let t_out = 1.0 / spec.output_rate_hz;
        let (t_int, fs_int) = if n_dec > 0 {
            (1.0 / spec.internal_rate_hz, spec.internal_rate_hz)
        } else {
            (t_out, spec.output_rate_hz)
        };
        Ok(ImuSensor {
            gyro_sd_int: g.density * fs_int.sqrt(),
            accel_sd_int: a.density * fs_int.sqrt(),
            gyro: Triad::new(g, spec, seed, "gyro"),
            accel: Triad::new(a, spec, seed, "accel"),
            n_dec,
            t_int,
            t_out,
            decimation: spec.decimation,
            filters,
            filter_delay_s,
            count: 0,
            sum: [0.0; 6],
            trap: [0.0; 6],
            prev: [0.0; 6],
            last: [0.0; 6],
            primed: false,
        })
    }

    /// The drawn errors.
    pub fn drawn(&self) -> ImuDrawn {
        ImuDrawn {
            gyro: self.gyro.drawn.clone(),
            accel: self.accel.drawn.clone(),
            filter_group_delay_s: self.filter_delay_s,
            decimation_factor: self.n_dec,
        }
    }

    /// Internal samples per output sample (0: ideal integrating IMU).
    pub fn decimation_factor(&self) -> usize {
        self.n_dec
    }

    /// The current biases and scale factors in KF-GINS's terms.
    pub fn current_errors(&self) -> ImuErrors {
        ImuErrors {
            gyro_bias: self.gyro.bias(),
            accel_bias: self.accel.bias(),
            gyro_scale: self.gyro.scale,
            accel_scale: self.accel.scale,
            gyro_misalign: self.gyro.misalign(),
            accel_misalign: self.accel.misalign(),
        }
    }

    /// Feeds the internal sample that precedes the first output interval
    /// (the starting point of the first trapezoid and the filters' state).
    pub fn prime(&mut self, w_ib_b: &Vector3<f64>, f_b: &Vector3<f64>) {
        let g = self.gyro.sample(w_ib_b, self.gyro_sd_int);
        let a = self.accel.sample(f_b, self.accel_sd_int);
        let x = [g.x, g.y, g.z, a.x, a.y, a.z];
        if let Some(fs) = &mut self.filters {
            for (f, v) in fs.iter_mut().zip(x) {
                f.prime(v);
            }
        }
        self.prev = x;
        self.primed = true;
    }

    /// Pushes one internal sample of the true rates (sampled chain); returns
    /// the output at the end of each output interval.
    pub fn push_internal(
        &mut self,
        w_ib_b: &Vector3<f64>,
        f_b: &Vector3<f64>,
    ) -> Option<ImuOutput> {
        if self.count == 0 {
            self.gyro.step_drift();
            self.accel.step_drift();
        }
        let g = self.gyro.sample(w_ib_b, self.gyro_sd_int);
        let a = self.accel.sample(f_b, self.accel_sd_int);
        let mut x = [g.x, g.y, g.z, a.x, a.y, a.z];
        if let Some(fs) = &mut self.filters {
            for (f, v) in fs.iter_mut().zip(x.iter_mut()) {
                *v = f.process(*v);
            }
        }
        if !self.primed {
            self.prev = x;
            self.primed = true;
        }
        for k in 0..6 {
            self.sum[k] += x[k];
            self.trap[k] += 0.5 * (x[k] + self.prev[k]) * self.t_int;
        }
        self.prev = x;
        self.last = x;
        self.count += 1;
        if self.count < self.n_dec.max(1) {
            return None;
        }
        let n = self.count as f64;
        self.count = 0;
        let (rate, delta) = match self.decimation {
            Decimation::Average => (self.sum.map(|s| s / n), self.trap),
            Decimation::Point => (self.last, self.last.map(|v| v * self.t_out)),
        };
        self.sum = [0.0; 6];
        self.trap = [0.0; 6];
        Some(self.quantized(rate, delta))
    }

    /// True when [`ImuSensor::push_window`] needs every internal sample of
    /// the window (false for point decimation without a filter: only the
    /// last sample reaches the output).
    pub fn needs_full_window(&self) -> bool {
        self.filters.is_some() || self.decimation == Decimation::Average
    }

    /// Pushes the true rates `[ω_ib^b; f^b]` of one whole output interval
    /// (`decimation_factor()` internal samples) and returns the output.
    ///
    /// Equivalent in distribution to as many [`ImuSensor::push_internal`]
    /// calls. When the chain is linear (no filter, and no sample can reach
    /// the range: max|M·x + b| + 8σ below it), the output is formed from
    /// sums of the true signal and the noise sums are drawn directly — the
    /// last sample's noise w_N and the rest Σ_{n<N} w_n ~ N(0, (N−1)σ²),
    /// two normals per channel instead of N. The averaged rate is
    /// (M Σx + N b + Σw)/N and the trapezoid increment
    /// T_int·(Σm − m_N/2 + m_0/2) with m_0 the previous window's last
    /// sample: the same quantities, exactly, at a fifth of the cost.
    pub fn push_window(&mut self, xs: &[[f64; 6]]) -> Result<ImuOutput, String> {
        let n = self.n_dec;
        if n == 0 || xs.len() != n || self.count != 0 {
            return Err(format!(
                "push_window needs exactly {n} internal samples at a window start (got {})",
                xs.len()
            ));
        }
        let linear = self.filters.is_none()
            && (self.decimation == Decimation::Point || !self.may_saturate(xs));
        if !linear {
            let mut out = None;
            for x in xs {
                out = self.push_internal(
                    &Vector3::new(x[0], x[1], x[2]),
                    &Vector3::new(x[3], x[4], x[5]),
                );
            }
            return out.ok_or_else(|| "window produced no output".to_string());
        }
        self.gyro.step_drift();
        self.accel.step_drift();
        let last = &xs[n - 1];
        let mut rate = [0.0; 6];
        let mut delta = [0.0; 6];
        let mut m_last = [0.0; 6];
        for (t, (triad, sd)) in [
            (&mut self.gyro, self.gyro_sd_int),
            (&mut self.accel, self.accel_sd_int),
        ]
        .into_iter()
        .enumerate()
        {
            let o = 3 * t;
            let b = triad.bias();
            let x_last = Vector3::new(last[o], last[o + 1], last[o + 2]);
            let w_last = triad.draw_white(sd);
            let m_n = triad.m * x_last + b + w_last;
            match self.decimation {
                Decimation::Point => {
                    for k in 0..3 {
                        rate[o + k] = m_n[k];
                        delta[o + k] = m_n[k] * self.t_out;
                    }
                }
                Decimation::Average => {
                    let mut sx = Vector3::zeros();
                    for x in xs {
                        sx += Vector3::new(x[o], x[o + 1], x[o + 2]);
                    }
                    let w_rest = triad.draw_white(sd * ((n - 1) as f64).sqrt());
                    let sum_m = triad.m * sx + b * n as f64 + w_rest + w_last;
                    for k in 0..3 {
                        rate[o + k] = sum_m[k] / n as f64;
                        delta[o + k] =
                            self.t_int * (sum_m[k] - 0.5 * m_n[k] + 0.5 * self.prev[o + k]);
                    }
                }
            }
            for k in 0..3 {
                m_last[o + k] = m_n[k];
            }
        }
        self.prev = m_last;
        self.last = m_last;
        self.primed = true;
        Ok(self.quantized(rate, delta))
    }

    /// Could any sample of the window reach the range (with 8σ of noise)?
    fn may_saturate(&self, xs: &[[f64; 6]]) -> bool {
        for (t, (triad, sd)) in [
            (&self.gyro, self.gyro_sd_int),
            (&self.accel, self.accel_sd_int),
        ]
        .into_iter()
        .enumerate()
        {
            if triad.si.range <= 0.0 {
                continue;
            }
            let o = 3 * t;
            let b = triad.bias();
            let margin = triad.si.range - 8.0 * sd;
            for x in xs {
                let y = triad.m * Vector3::new(x[o], x[o + 1], x[o + 2]) + b;
                if y.amax() >= margin {
                    return true;
                }
            }
        }
        false
    }

    /// Pushes the exact increments of one output interval (ideal
    /// integrating IMU): m = M·Δx + b·T + N·√T·w, then saturation of the
    /// mean rate.
    pub fn push_exact(&mut self, dtheta: &Vector3<f64>, dvel: &Vector3<f64>) -> ImuOutput {
        self.gyro.step_drift();
        self.accel.step_drift();
        let t = self.t_out;
        // sample() adds white noise of σ·√fs on the mean rate: N·√(1/T) = N/√T,
        // i.e. N·√T on the increment.
        let g = self.gyro.sample(&(dtheta / t), self.gyro_sd_int) * t;
        let a = self.accel.sample(&(dvel / t), self.accel_sd_int) * t;
        let delta = [g.x, g.y, g.z, a.x, a.y, a.z];
        let rate = delta.map(|d| d / t);
        self.quantized(rate, delta)
    }

    fn quantized(&self, rate: [f64; 6], delta: [f64; 6]) -> ImuOutput {
        let (g, a) = (&self.gyro.si, &self.accel.si);
        let q = |v: &[f64], lsb: f64| {
            Vector3::new(
                quantize(v[0], lsb),
                quantize(v[1], lsb),
                quantize(v[2], lsb),
            )
        };
        ImuOutput {
            gyro_rate: q(&rate[0..3], g.rate_lsb),
            accel_rate: q(&rate[3..6], a.rate_lsb),
            dtheta: q(&delta[0..3], g.delta_lsb),
            dvel: q(&delta[3..6], a.delta_lsb),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync::allan::{FLICKER_FLOOR_FACTOR, fit_noise, overlapping_adev};

    /// Static input: Earth rate and gravity at 30° latitude, level, north.
    fn static_input() -> (Vector3<f64>, Vector3<f64>) {
        let lat = 30f64.to_radians();
        let w = 7.292115e-5;
        (
            Vector3::new(w * lat.cos(), 0.0, -w * lat.sin()),
            Vector3::new(0.0, 0.0, -9.79),
        )
    }

    /// Runs a static IMU for `n_out` outputs and returns the x-axis rate
    /// outputs of gyro and accelerometer.
    fn static_run(spec: &ImuSpec, seed: u64, n_out: usize) -> (Vec<f64>, Vec<f64>) {
        let mut imu = ImuSensor::new(spec, seed).unwrap();
        let (w, f) = static_input();
        let (mut g, mut a) = (Vec::with_capacity(n_out), Vec::with_capacity(n_out));
        let n_dec = imu.decimation_factor();
        if n_dec == 0 {
            let t = 1.0 / spec.output_rate_hz;
            for _ in 0..n_out {
                let o = imu.push_exact(&(w * t), &(f * t));
                g.push(o.gyro_rate.x);
                a.push(o.accel_rate.x);
            }
        } else {
            imu.prime(&w, &f);
            while g.len() < n_out {
                if let Some(o) = imu.push_internal(&w, &f) {
                    g.push(o.gyro_rate.x);
                    a.push(o.accel_rate.x);
                }
            }
        }
        (g, a)
    }

    fn noise_spec(internal_hz: f64, output_hz: f64) -> ImuSpec {
        ImuSpec {
            output_rate_hz: output_hz,
            internal_rate_hz: internal_hz,
            flicker_band_s: [0.1, 20_000.0],
            gyro: GyroSpec {
                arw_deg_sqrt_h: 0.15,
                bias_instability_deg_h: 10.0,
                ..Default::default()
            },
            accel: AccelSpec {
                vrw_mps_sqrt_h: 0.04,
                bias_instability_mgal: 50.0,
                ..Default::default()
            },
            ..ImuSpec::default()
        }
    }

    #[test]
    fn flicker_bank_has_a_flat_allan_floor() {
        // Analytic Allan variance of the bank: Σ σ²T²/τ²·(2τ/T − 3 + 4e^{−τ/T}
        // − e^{−2τ/T}) (first-order Gauss–Markov), against 0.664²·B² on the
        // floor (IEEE 952 C.1.3).
        let spec = noise_spec(0.0, 100.0);
        let imu = ImuSensor::new(&spec, 1).unwrap();
        let d = imu.drawn().gyro;
        let b = 10.0 * DEG_H;
        for k in 0..=20 {
            let tau = 10f64.powf(1.0 + 2.5 * k as f64 / 20.0); // 10 … 3160 s
            let var: f64 = d
                .drift_corr_times_s
                .iter()
                .zip(&d.drift_component_sd)
                .map(|(&t, &s)| {
                    let x = tau / t;
                    s * s * t * t / (tau * tau)
                        * (2.0 * x - 3.0 + 4.0 * (-x).exp() - (-2.0 * x).exp())
                })
                .sum();
            let ratio = var.sqrt() / (FLICKER_FLOOR_FACTOR * b);
            assert!((ratio - 1.0).abs() < 0.03, "tau {tau}: {ratio}");
        }
    }

    #[test]
    fn allan_deviation_recovers_the_configured_noise() {
        // 6 h of a static ideal integrating IMU at 20 Hz: ARW 0.15°/√h,
        // B 10°/h, VRW 0.04 m/s/√h, B 50 mGal. Over 12 seeds and 8–24 h the
        // fitted values scattered by at most ±5 % (sampling error of the
        // floor, relative sd ≈ 1/√(2·clusters) at its longest τ), so 10 %
        // (the criterion) holds with margin.
        let spec = noise_spec(0.0, 20.0);
        let (g, a) = static_run(&spec, 11, 20 * 6 * 3600);
        let fg = fit_noise(&overlapping_adev(&g, 0.05));
        let fa = fit_noise(&overlapping_adev(&a, 0.05));
        let arw = fg.random_walk / (DEG / 60.0);
        let vrw = fa.random_walk * 60.0;
        let bg = fg.bias_instability / DEG_H;
        let ba = fa.bias_instability / MGAL;
        eprintln!(
            "ARW {arw:.4} deg/sqrt(h), B {bg:.3} deg/h at {} s; VRW {vrw:.4} m/s/sqrt(h), B {ba:.2} mGal at {} s",
            fg.bias_instability_tau_s, fa.bias_instability_tau_s
        );
        assert!((arw / 0.15 - 1.0).abs() < 0.1, "ARW {arw}");
        assert!((vrw / 0.04 - 1.0).abs() < 0.1, "VRW {vrw}");
        assert!((bg / 10.0 - 1.0).abs() < 0.1, "gyro bias instability {bg}");
        assert!((ba / 50.0 - 1.0).abs() < 0.1, "accel bias instability {ba}");
    }

    #[test]
    fn averaged_internal_noise_has_the_configured_density() {
        // 2 kHz internal samples averaged by 10: the output white noise has
        // the same density (σ_out = N·√200), unlike point decimation
        // (σ_out = N·√2000: aliased broadband noise).
        let mut spec = noise_spec(2000.0, 200.0);
        spec.gyro.bias_instability_deg_h = 0.0;
        spec.accel.bias_instability_mgal = 0.0;
        let n = 100_000;
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
        };
        let (g, _) = static_run(&spec, 3, n);
        let expect = 0.15 * DEG / 60.0 * 200f64.sqrt();
        // 1e5 samples: relative sd of the sd estimate 0.2 %.
        assert!(
            (sd(&g) / expect - 1.0).abs() < 0.01,
            "{} vs {expect}",
            sd(&g)
        );
        spec.decimation = Decimation::Point;
        let (g, _) = static_run(&spec, 3, n);
        let expect = 0.15 * DEG / 60.0 * 2000f64.sqrt();
        assert!(
            (sd(&g) / expect - 1.0).abs() < 0.01,
            "{} vs {expect}",
            sd(&g)
        );
    }

    #[test]
    fn decimation_follows_dec_rate_and_increments_integrate() {
        // A ramp in rate: averaging gives the interval mean; the trapezoid
        // increment is exact for a linear signal; point decimation gives
        // the last sample.
        let spec = ImuSpec {
            output_rate_hz: 200.0,
            internal_rate_hz: 2000.0,
            ..ImuSpec::default()
        };
        assert_eq!(spec.decimation_factor().unwrap(), 10); // DEC_RATE = 9
        let mut imu = ImuSensor::new(&spec, 1).unwrap();
        let rate = |j: usize| Vector3::new(0.001 * j as f64, 0.0, 0.0);
        imu.prime(&rate(0), &Vector3::zeros());
        let mut out = None;
        for j in 1..=10 {
            out = imu.push_internal(&rate(j), &Vector3::zeros());
            assert_eq!(out.is_some(), j == 10);
        }
        let o = out.unwrap();
        assert!((o.gyro_rate.x - 0.0055).abs() < 1e-15);
        // ∫ of 2·t (rate = 0.001·j at t = j/2000 → 2 rad/s²·t) over 5 ms = 2.5e-5.
        assert!((o.dtheta.x - 2.5e-5).abs() < 1e-15, "{}", o.dtheta.x);
        let spec = ImuSpec {
            decimation: Decimation::Point,
            ..spec
        };
        let mut imu = ImuSensor::new(&spec, 1).unwrap();
        imu.prime(&rate(0), &Vector3::zeros());
        let o = (1..=10)
            .filter_map(|j| imu.push_internal(&rate(j), &Vector3::zeros()))
            .next()
            .unwrap();
        assert!((o.gyro_rate.x - 0.010).abs() < 1e-15);
        assert!(
            ImuSpec {
                internal_rate_hz: 1500.0,
                ..ImuSpec::default()
            }
            .decimation_factor()
            .is_err()
        );
    }

    #[test]
    fn filters_have_unit_gain_and_their_group_delay() {
        let fs = 2000.0;
        for (f, delay_samples) in [
            (LowPassSpec::Bartlett { taps: 9 }, Some(4.0)),
            (
                LowPassSpec::Fir {
                    taps: vec![1.0, 1.0, 1.0, 1.0],
                },
                Some(1.5),
            ),
            (LowPassSpec::Butterworth { cutoff_hz: 100.0 }, None),
            (
                LowPassSpec::Iir {
                    b: vec![0.1],
                    a: vec![1.0, -0.9],
                },
                Some(9.0),
            ),
        ] {
            let d = f.group_delay_s(fs).unwrap() * fs;
            if let Some(e) = delay_samples {
                assert!((d - e).abs() < 1e-9, "{f:?}: {d}");
            }
            // A slow ramp comes out delayed by the group delay.
            let (b, a) = f.coefficients(fs).unwrap();
            let mut flt = Filter::new(b, a);
            flt.prime(0.0);
            let mut y = 0.0;
            for k in 0..4000 {
                y = flt.process(k as f64);
            }
            assert!(
                (3999.0 - y - d).abs() < 1e-6,
                "{f:?}: lag {} vs {d}",
                3999.0 - y
            );
        }
        // Butterworth 2nd order: τ(0) = √2/(2π fc) (continuous prototype).
        let d = LowPassSpec::Butterworth { cutoff_hz: 100.0 }
            .group_delay_s(fs)
            .unwrap();
        assert!(
            (d / (SQRT_2 / (2.0 * PI * 100.0)) - 1.0).abs() < 0.05,
            "{d}"
        );
        assert!(
            LowPassSpec::Butterworth { cutoff_hz: 1500.0 }
                .group_delay_s(fs)
                .is_err()
        );
        assert!(
            LowPassSpec::Iir {
                b: vec![1.0],
                a: vec![0.0]
            }
            .coefficients(fs)
            .is_err()
        );
    }

    #[test]
    fn error_sources_draw_from_independent_streams() {
        let base = ImuSpec::preset("adis16465").unwrap();
        let a = ImuSensor::new(&base, 9).unwrap().drawn();
        // Switching the accelerometer errors off changes no gyro draw.
        let mut quiet = base.clone();
        quiet.accel = AccelSpec::default();
        let b = ImuSensor::new(&quiet, 9).unwrap().drawn();
        assert_eq!(a.gyro.turn_on_bias, b.gyro.turn_on_bias);
        assert_eq!(a.gyro.matrix, b.gyro.matrix);
        assert_eq!(a.gyro.drift_at_start, b.gyro.drift_at_start);
        assert_eq!(b.accel.turn_on_bias, [0.0; 3]);
        // The gyro white noise is the same whether or not the scale factor
        // is on (static input with zero rate on x: identical outputs).
        let mut s1 = base.clone();
        s1.gyro.bias_instability_deg_h = 0.0;
        s1.gyro.turn_on_bias_deg_h = 0.0;
        s1.gyro.misalignment_deg = 0.0;
        let mut s2 = s1.clone();
        s2.gyro.scale_ppm = 0.0;
        let mut i1 = ImuSensor::new(&s1, 4).unwrap();
        let mut i2 = ImuSensor::new(&s2, 4).unwrap();
        let z = Vector3::zeros();
        for _ in 0..25 {
            let o1 = i1.push_internal(&z, &z);
            let o2 = i2.push_internal(&z, &z);
            assert_eq!(o1, o2);
        }
        // Different seeds give different draws.
        let c = ImuSensor::new(&base, 10).unwrap().drawn();
        assert_ne!(a.gyro.turn_on_bias, c.gyro.turn_on_bias);
    }

    #[test]
    fn window_path_equals_sample_path() {
        // Without noise the linear fast path gives the same numbers as the
        // per-sample chain; with noise, the same distribution.
        let mut spec = ImuSpec::preset("adis16465").unwrap();
        spec.gyro.arw_deg_sqrt_h = 0.0;
        spec.accel.vrw_mps_sqrt_h = 0.0;
        for dec in [Decimation::Average, Decimation::Point] {
            spec.decimation = dec;
            let mut a = ImuSensor::new(&spec, 5).unwrap();
            let mut b = ImuSensor::new(&spec, 5).unwrap();
            let x = |j: usize| {
                let t = j as f64 * 5e-4;
                [0.3 * t.sin(), 0.1, -0.2 * t, 1.0 + t, -0.5, -9.8 + 0.01 * t]
            };
            let v = |x: [f64; 6]| {
                (
                    Vector3::new(x[0], x[1], x[2]),
                    Vector3::new(x[3], x[4], x[5]),
                )
            };
            let (w0, f0) = v(x(0));
            a.prime(&w0, &f0);
            b.prime(&w0, &f0);
            for k in 0..50 {
                let xs: Vec<[f64; 6]> = (1..=10).map(|j| x(10 * k + j)).collect();
                let oa = a.push_window(&xs).unwrap();
                let mut ob = None;
                for xj in &xs {
                    let (w, f) = v(*xj);
                    ob = b.push_internal(&w, &f);
                }
                let ob = ob.unwrap();
                for (p, q) in [
                    (oa.gyro_rate, ob.gyro_rate),
                    (oa.dtheta, ob.dtheta),
                    (oa.accel_rate, ob.accel_rate),
                    (oa.dvel, ob.dvel),
                ] {
                    assert!(
                        (p - q).amax() <= 1e-12 * (1.0 + q.amax()),
                        "{dec:?} {k}: {p} vs {q}"
                    );
                }
            }
        }
        // Noise: the sd of rate and increment outputs agree (2e4 windows:
        // relative sd of an sd estimate 0.5 %).
        let mut spec = noise_spec(2000.0, 200.0);
        spec.gyro.bias_instability_deg_h = 0.0;
        let mut fast = ImuSensor::new(&spec, 8).unwrap();
        let mut slow = ImuSensor::new(&spec, 9).unwrap();
        let z = [0.0; 6];
        let (mut rf, mut df, mut rs, mut ds) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        fast.prime(&Vector3::zeros(), &Vector3::zeros());
        slow.prime(&Vector3::zeros(), &Vector3::zeros());
        for _ in 0..20_000 {
            let o = fast.push_window(&[z; 10]).unwrap();
            rf.push(o.gyro_rate.x);
            df.push(o.dtheta.x);
            let mut q = None;
            for _ in 0..10 {
                q = slow.push_internal(&Vector3::zeros(), &Vector3::zeros());
            }
            let q = q.unwrap();
            rs.push(q.gyro_rate.x);
            ds.push(q.dtheta.x);
        }
        let sd = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        assert!(
            (sd(&rf) / sd(&rs) - 1.0).abs() < 0.03,
            "{} {}",
            sd(&rf),
            sd(&rs)
        );
        assert!(
            (sd(&df) / sd(&ds) - 1.0).abs() < 0.03,
            "{} {}",
            sd(&df),
            sd(&ds)
        );
        // Lag-1 correlation of the trapezoid increments (shared boundary
        // sample): 0.5·σ²T²/4 over ≈ (N−½)σ²T² → 0.026 for N = 10, both ways.
        let lag1 = |v: &[f64]| {
            v.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / v.iter().map(|x| x * x).sum::<f64>()
        };
        assert!(
            (lag1(&df) - lag1(&ds)).abs() < 0.03,
            "{} {}",
            lag1(&df),
            lag1(&ds)
        );
    }

    #[test]
    fn saturation_and_quantization() {
        let spec = ImuSpec {
            internal_rate_hz: 0.0,
            output_rate_hz: 100.0,
            gyro: GyroSpec {
                range_deg_s: 125.0,
                rate_lsb_deg_s: 0.1,
                ..Default::default()
            },
            ..ImuSpec::default()
        };
        let mut imu = ImuSensor::new(&spec, 1).unwrap();
        let o = imu.push_exact(
            &Vector3::new(3.0 * 0.01, 0.123_4f64.to_radians() * 0.01, 0.0),
            &Vector3::zeros(),
        );
        assert!(
            (o.gyro_rate.x - 1250.0f64.to_radians() / 10.0).abs() < 1e-12,
            "{}",
            o.gyro_rate.x
        );
        assert!((o.gyro_rate.y - 0.1f64.to_radians()).abs() < 1e-15);
    }

    #[test]
    fn presets_exist_and_are_valid() {
        for name in IMU_PRESETS {
            let spec = ImuSpec::preset(name).unwrap();
            ImuSensor::new(&spec, 1).unwrap();
        }
        assert!(ImuSpec::preset("nope").is_none());
        let icm = ImuSpec::preset("icm20602").unwrap();
        assert_eq!(icm.decimation_factor().unwrap(), 5);
        assert_eq!(icm.clock.freq_error_ppm, -400.0);
    }
}
