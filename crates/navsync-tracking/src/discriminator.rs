//! Carrier-phase discriminators, the phase lock indicator and the C/N0
//! estimator, all working on prompt correlator outputs (I, Q).
//!
//! Kaplan & Hegarty, 2nd ed., ch. 5 (Ward, Betz, Hegarty): Table 5.4
//! (PLL and Costas discriminators), §5.11 (phase lock detector: the
//! normalised narrow-band difference NBD/NBP ≈ cos 2Δφ), §5.6.1 (tracking
//! threshold rule of thumb: 3σ of the phase error at most one quarter of the
//! discriminator's pull-in range).

use std::f64::consts::PI;

/// The carrier-phase discriminator.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Discriminator {
    /// Costas loop, two-quadrant arctangent atan(Q/I): insensitive to the
    /// 180° phase flips of navigation data bits; stable points every π.
    Costas,
    /// Pure PLL, four-quadrant arctangent atan2(Q, I): needs data wipe-off
    /// (a pilot channel or known bits); stable points every 2π.
    Pll,
}

impl Discriminator {
    /// Phase error estimate (rad) from prompt I and Q.
    #[inline]
    pub(crate) fn phase_error(self, i: f64, q: f64) -> f64 {
        match self {
            Discriminator::Costas => {
                if i == 0.0 {
                    if q >= 0.0 { PI / 2.0 } else { -PI / 2.0 }
                } else {
                    (q / i).atan()
                }
            }
            Discriminator::Pll => q.atan2(i),
        }
    }

    /// Spacing of the stable tracking points (rad): a cycle slip moves the
    /// loop by a multiple of this.
    pub(crate) fn ambiguity_rad(self) -> f64 {
        match self {
            Discriminator::Costas => PI,
            Discriminator::Pll => 2.0 * PI,
        }
    }

    /// Kaplan's rule-of-thumb limit for 3σ + |bias| (deg): one quarter of
    /// the pull-in range (45° for the Costas atan, 90° for atan2).
    pub fn threshold_deg(self) -> f64 {
        match self {
            Discriminator::Costas => 45.0,
            Discriminator::Pll => 90.0,
        }
    }

    /// Squaring loss of the thermal-noise jitter: Kaplan & Hegarty §5.6
    /// (PLL thermal noise, σ_tPLL) has the factor 1 + 1/(2 T C/N0) for the
    /// Costas (squaring) loop; a pure PLL with data wipe-off has none.
    pub(crate) fn squaring_loss(self, cn0_hz: f64, t_s: f64) -> f64 {
        match self {
            Discriminator::Costas => 1.0 + 1.0 / (2.0 * t_s * cn0_hz),
            Discriminator::Pll => 1.0,
        }
    }
}

/// Statistics of the discriminators below threshold.
///
/// At low SNR ρ = C/N0·T (per-interval signal-to-noise ratio, A²/2 with
/// unit noise per arm) the arctangent discriminators are nonlinear: their
/// mean slope at zero phase error (the loop gain) drops below 1 and their
/// output variance saturates (π²/12 for the Costas atan, π²/3 for atan2, at
/// ρ → 0). Both follow from the density of the phase θ of a sinusoid in
/// Gaussian noise (e.g. Proakis, *Digital Communications*; Lindsey & Simon,
/// *Telecommunication Systems Engineering*, 1973):
///     p(θ) = e^{−ρ}/(2π) + ½√(ρ/π)·cos θ·e^{−ρ sin²θ}·(1 + erf(√ρ cos θ)).
/// The discriminator output d(θ) is θ folded into (−π/2, π/2] (Costas) or
/// (−π, π] (PLL). Integrating E[d](φ) = ∫ d(θ) p(θ − φ) dθ by parts, the
/// slope at φ = 0 is 1 minus the jumps of d weighted by p there:
///     Costas: g = 1 − 2π p(π/2) = 1 − e^{−ρ},
///     PLL:    g = 1 − 2π p(π) = 1 − e^{−ρ} + √(πρ)·erfc(√ρ).
/// The variance ∫ d² p dθ is integrated numerically once into a table.
/// The equivalent phase-noise variance of one interval is v/g², which
/// tends to (1/(2ρ))(1 + 1/(2ρ)) (Costas) or 1/(2ρ) (PLL) at high SNR:
/// the Kaplan & Hegarty thermal-noise formula.
impl Discriminator {
    /// Mean slope of the output at zero phase error (closed forms above).
    pub fn gain(self, rho: f64) -> f64 {
        let rho = rho.max(0.0);
        match self {
            Discriminator::Costas => 1.0 - (-rho).exp(),
            Discriminator::Pll => 1.0 - (-rho).exp() + (PI * rho).sqrt() * (1.0 - erf(rho.sqrt())),
        }
    }

    /// Output variance (rad²) at zero phase error for SNR `rho`.
    pub(crate) fn output_variance(self, rho: f64) -> f64 {
        let table = variance_table();
        let col = match self {
            Discriminator::Costas => 0,
            Discriminator::Pll => 1,
        };
        let x = rho.max(1e-12).ln();
        let (lo, hi) = (TABLE_RHO_MIN.ln(), TABLE_RHO_MAX.ln());
        if x >= hi {
            // Beyond the table both arctangents follow the high-SNR
            // expansion 1/(2ρ) + 1/(4ρ²) to better than 1e-4.
            return 1.0 / (2.0 * rho) * (1.0 + 1.0 / (2.0 * rho));
        }
        let pos = ((x - lo) / (hi - lo) * (TABLE_N - 1) as f64).max(0.0);
        let i = (pos.floor() as usize).min(TABLE_N - 2);
        let f = pos - i as f64;
        // Interpolate ln v in ln ρ (smooth, monotone).
        (table[i][col].ln() * (1.0 - f) + table[i + 1][col].ln() * f).exp()
    }

    /// Equivalent phase-noise variance of one interval, v/g² (rad²).
    pub(crate) fn equivalent_noise_variance(self, rho: f64) -> f64 {
        let g = self.gain(rho).max(1e-6);
        self.output_variance(rho) / (g * g)
    }
}

const TABLE_N: usize = 161;
const TABLE_RHO_MIN: f64 = 1e-3;
const TABLE_RHO_MAX: f64 = 1e4;

/// ln-spaced table of the output variances (Costas, PLL).
fn variance_table() -> &'static [[f64; 2]; TABLE_N] {
    static TABLE: std::sync::OnceLock<[[f64; 2]; TABLE_N]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [[0.0; 2]; TABLE_N];
        let (lo, hi) = (TABLE_RHO_MIN.ln(), TABLE_RHO_MAX.ln());
        for (i, row) in t.iter_mut().enumerate() {
            let rho = (lo + (hi - lo) * i as f64 / (TABLE_N - 1) as f64).exp();
            *row = variances_by_integration(rho);
        }
        t
    })
}

/// ∫ d(θ)² p(θ) dθ for both discriminators by the midpoint rule on 8192
/// points (d² is continuous on (−π, π] for both folds, so the rule
/// converges fast; its error is below 1e-6 relative).
fn variances_by_integration(rho: f64) -> [f64; 2] {
    let n = 8192;
    let h = 2.0 * PI / n as f64;
    let (mut vc, mut vp) = (0.0, 0.0);
    let sr = rho.sqrt();
    let c0 = (-rho).exp() / (2.0 * PI);
    let c1 = 0.5 * (rho / PI).sqrt();
    for k in 0..n {
        let th = -PI + (k as f64 + 0.5) * h;
        let (s, c) = th.sin_cos();
        let p = c0 + c1 * c * (-rho * s * s).exp() * (1.0 + erf(sr * c));
        let d = if th > PI / 2.0 {
            th - PI
        } else if th < -PI / 2.0 {
            th + PI
        } else {
            th
        };
        vc += d * d * p;
        vp += th * th * p;
    }
    [vc * h, vp * h]
}

/// The error function, through the regularised incomplete gamma function
/// (erf x = P(½, x²)).
fn erf(x: f64) -> f64 {
    let v = navsync::stats::gamma_p(0.5, x * x);
    if x < 0.0 { -v } else { v }
}

/// Phase lock indicator cos 2Δφ ≈ NBD/NBP (Kaplan §5.11; Van Dierendonck
/// 1996): NBD = (ΣI)² − (ΣQ)², NBP = (ΣI)² + (ΣQ)², sums over `m` coherent
/// intervals (within one data bit), both low-pass filtered with time
/// constant `k` sums before the ratio is taken. Near 1 in lock, near 0 with
/// a random phase. Noise biases NBP up, so the indicator sinks at low C/N0
/// even in lock: it is a lock *indicator*, the simulator counts slips
/// against the true phase.
#[derive(Clone, Debug)]
pub(crate) struct LockDetector {
    m: usize,
    count: usize,
    sum_i: f64,
    sum_q: f64,
    alpha: f64,
    nbd: f64,
    nbp: f64,
    threshold: f64,
}

impl LockDetector {
    /// Sums of `m` intervals, smoothed over about `k` sums; `threshold` is
    /// the indicator value above which the loop is declared locked.
    pub(crate) fn new(m: usize, k: f64, threshold: f64) -> Self {
        LockDetector {
            m: m.max(1),
            count: 0,
            sum_i: 0.0,
            sum_q: 0.0,
            alpha: 1.0 / k.max(1.0),
            nbd: 0.0,
            nbp: 0.0,
            threshold,
        }
    }

    /// Adds one prompt correlation.
    pub(crate) fn push(&mut self, i: f64, q: f64) {
        self.sum_i += i;
        self.sum_q += q;
        self.count += 1;
        if self.count == self.m {
            let (i2, q2) = (self.sum_i * self.sum_i, self.sum_q * self.sum_q);
            if self.nbp == 0.0 {
                self.nbd = i2 - q2;
                self.nbp = i2 + q2;
            } else {
                self.nbd += self.alpha * (i2 - q2 - self.nbd);
                self.nbp += self.alpha * (i2 + q2 - self.nbp);
            }
            self.count = 0;
            self.sum_i = 0.0;
            self.sum_q = 0.0;
        }
    }

    /// The indicator cos 2Δφ estimate (0 before the first sum).
    pub(crate) fn indicator(&self) -> f64 {
        if self.nbp > 0.0 {
            self.nbd / self.nbp
        } else {
            0.0
        }
    }

    pub(crate) fn locked(&self) -> bool {
        self.indicator() > self.threshold
    }
}

/// C/N0 from the second and fourth moments of the prompt correlator
/// (M2M4 estimator; Pauluzzi & Beaulieu, IEEE Trans. Commun. 48(10), 2000):
/// for y = s + n with |s|² = S and complex Gaussian noise of power N,
/// E|y|² = S + N and E|y|⁴ = S² + 4SN + 2N², hence S = √(2M2² − M4),
/// N = M2 − S and C/N0 = (S/N)/T. It needs neither phase lock nor data
/// wipe-off, so it works for every coherent time (1–20 ms). The moments
/// are exponentially averaged with time constant `tau_s`.
#[derive(Clone, Debug)]
pub(crate) struct Cn0Estimator {
    t_s: f64,
    alpha: f64,
    m2: f64,
    m4: f64,
    n: usize,
}

impl Cn0Estimator {
    pub(crate) fn new(t_s: f64, tau_s: f64) -> Self {
        Cn0Estimator {
            t_s,
            alpha: (t_s / tau_s).min(1.0),
            m2: 0.0,
            m4: 0.0,
            n: 0,
        }
    }

    pub(crate) fn push(&mut self, i: f64, q: f64) {
        let p = i * i + q * q;
        self.n += 1;
        // Plain averaging until the exponential window is full: no start-up bias.
        let a = self.alpha.max(1.0 / self.n as f64);
        self.m2 += a * (p - self.m2);
        self.m4 += a * (p * p - self.m4);
    }

    /// Estimated C/N0 (Hz, linear); `None` before any sample. Floors the
    /// signal power at a small positive value when noise makes 2M2² − M4
    /// negative (very weak signals).
    pub(crate) fn cn0_hz(&self) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        let s = (2.0 * self.m2 * self.m2 - self.m4).max(0.0).sqrt();
        let s = s.max(1e-3 * self.m2);
        let noise = (self.m2 - s).max(1e-9 * self.m2);
        Some(s / noise / self.t_s)
    }

    #[cfg(test)]
    pub(crate) fn cn0_dbhz(&self) -> Option<f64> {
        self.cn0_hz().map(|c| 10.0 * c.log10())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;
    use rand::SeedableRng;
    use rand_distr::StandardNormal;

    #[test]
    fn discriminators_are_exact_without_noise() {
        for k in -17..=17 {
            let phi = k as f64 * 0.09;
            let (i, q) = (3.0 * phi.cos(), 3.0 * phi.sin());
            assert!((Discriminator::Pll.phase_error(i, q) - phi).abs() < 1e-12);
            // Costas folds into ±π/2 and ignores a data-bit sign flip.
            let folded = (phi + PI / 2.0).rem_euclid(PI) - PI / 2.0;
            assert!((Discriminator::Costas.phase_error(i, q) - folded).abs() < 1e-12);
            assert!((Discriminator::Costas.phase_error(-i, -q) - folded).abs() < 1e-12);
        }
    }

    #[test]
    fn lock_indicator_tracks_cos_2phi() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        for phi in [0.0f64, 0.3, 0.6, 0.785] {
            let mut d = LockDetector::new(20, 50.0, 0.8);
            // 45 dB-Hz, T = 1 ms: amplitude √(2·C/N0·T) with unit noise.
            let a = (2.0 * 10f64.powf(4.5) * 1e-3).sqrt();
            for k in 0..20_000 {
                let bit = if (k / 20) % 2 == 0 { 1.0 } else { -1.0 };
                let ni: f64 = rng.sample(StandardNormal);
                let nq: f64 = rng.sample(StandardNormal);
                d.push(bit * a * phi.cos() + ni, bit * a * phi.sin() + nq);
            }
            // NBP is biased by the noise power 2m against (m·a)²: about 0.1 % here.
            assert!(
                (d.indicator() - (2.0 * phi).cos()).abs() < 0.03,
                "{phi}: {}",
                d.indicator()
            );
        }
    }

    #[test]
    fn cn0_estimator_is_unbiased_enough() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2);
        for (cn0_db, t) in [(45.0, 0.001), (35.0, 0.001), (25.0, 0.001), (25.0, 0.02)] {
            let cn0 = 10f64.powf(cn0_db / 10.0);
            let a = (2.0 * cn0 * t).sqrt();
            let mut e = Cn0Estimator::new(t, 1e9);
            let n = 200_000;
            for k in 0..n {
                let phi = k as f64 * 0.01; // phase need not be locked
                let ni: f64 = rng.sample(StandardNormal);
                let nq: f64 = rng.sample(StandardNormal);
                e.push(a * phi.cos() + ni, a * phi.sin() + nq);
            }
            let est = e.cn0_dbhz().unwrap();
            // With 2·10⁵ samples the M2M4 estimate's σ is below 0.1 dB at
            // SNR ≥ 0.3 per sample (normalised variance ≈ (2 + 4/ρ + 2/ρ²)/N).
            assert!((est - cn0_db).abs() < 0.25, "{cn0_db} dB-Hz: {est}");
        }
    }

    #[test]
    fn nonlinear_statistics_match_monte_carlo_and_the_high_snr_limit() {
        // Monte Carlo (2·10⁶ draws, σ of the estimates < 0.002) at ρ = 1
        // and 0.316: Costas g 0.632 / 0.271, v 0.468 / 0.681; PLL g 0.911, v 0.759.
        let c = Discriminator::Costas;
        assert!((c.gain(1.0) - 0.632).abs() < 0.002);
        assert!((c.gain(0.316) - 0.271).abs() < 0.002);
        assert!(
            (c.output_variance(1.0) - 0.468).abs() < 0.003,
            "{}",
            c.output_variance(1.0)
        );
        assert!((c.output_variance(0.316) - 0.682).abs() < 0.003);
        assert!((Discriminator::Pll.gain(1.0) - 0.911).abs() < 0.002);
        assert!((Discriminator::Pll.output_variance(1.0) - 0.759).abs() < 0.003);
        // ρ → 0: uniform outputs, variance π²/12 and π²/3. The first-order
        // term of p, √(πρ)·cos θ/(2π), changes the PLL's by −2√(πρ)
        // (∫θ² cos θ dθ = −4π) and cancels for the folded Costas output.
        assert!((c.output_variance(1e-3) - PI * PI / 12.0).abs() < 0.005);
        let pll0 = PI * PI / 3.0 - 2.0 * (PI * 1e-3).sqrt();
        assert!((Discriminator::Pll.output_variance(1e-3) - pll0).abs() < 0.005);
        // High SNR: the Kaplan & Hegarty thermal formula per interval.
        for rho in [20.0, 100.0, 1000.0, 5e4] {
            let want = 1.0 / (2.0 * rho) * (1.0 + 1.0 / (2.0 * rho));
            let got = c.equivalent_noise_variance(rho);
            assert!((got / want - 1.0).abs() < 0.01, "{rho}: {got} vs {want}");
        }
    }

    #[test]
    fn squaring_loss_and_thresholds() {
        assert!((Discriminator::Costas.squaring_loss(1000.0, 0.001) - 1.5).abs() < 1e-12);
        assert_eq!(Discriminator::Pll.squaring_loss(1000.0, 0.001), 1.0);
        assert_eq!(Discriminator::Costas.threshold_deg(), 45.0);
        assert_eq!(Discriminator::Pll.threshold_deg(), 90.0);
    }
}
