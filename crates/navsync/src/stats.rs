//! Small statistics helpers: the chi-square distribution (for innovation
//! gating and NEES/NIS consistency bounds) and running moments.
//!
//! The regularized lower incomplete gamma function P(a, x) is evaluated by
//! its series for x < a + 1 and by Lentz's continued fraction otherwise
//! (Press et al., *Numerical Recipes*, 3rd ed., §6.2, eqs 6.2.5 and 6.2.7).
#![warn(missing_docs)]

/// ln Γ(x) for x > 0 (Lanczos approximation, g = 7, n = 9; accurate to
/// ~1e-15 relative).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection formula.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, &c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularized lower incomplete gamma P(a, x).
pub fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        let mut ap = a;
        let mut sum = 1.0 / a;
        let mut del = sum;
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (sum.ln() - x + a * x.ln() - gln).exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        1.0 - (-x + a * x.ln() - gln).exp() * h
    }
}

/// CDF of the chi-square distribution with `dof` degrees of freedom.
pub fn chi2_cdf(x: f64, dof: f64) -> f64 {
    gamma_p(0.5 * dof, 0.5 * x)
}

/// Quantile of the chi-square distribution: the x with CDF(x) = p.
/// Bisection on the CDF, good to ~1e-10 relative.
pub fn chi2_quantile(p: f64, dof: f64) -> f64 {
    assert!(p > 0.0 && p < 1.0 && dof > 0.0, "chi2_quantile domain");
    let mut lo = 0.0;
    let mut hi = dof.max(1.0);
    while chi2_cdf(hi, dof) < p {
        hi *= 2.0;
    }
    for _ in 0..400 {
        let mid = 0.5 * (lo + hi);
        if chi2_cdf(mid, dof) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Running mean, RMS and extremes of a series.
#[derive(Clone, Copy, Debug, Default)]
pub struct Moments {
    /// Number of values pushed.
    pub n: usize,
    sum: f64,
    sum_sq: f64,
    /// Running mean and sum of squared deviations (Welford, "Note on a
    /// method for calculating corrected sums of squares and products",
    /// Technometrics 4(3), 1962): the spread of values with a large mean
    /// (sample intervals, counter readings) without cancellation.
    running_mean: f64,
    sum_sq_dev: f64,
    /// Smallest value (0 while `n == 0`).
    pub min: f64,
    /// Largest value (0 while `n == 0`).
    pub max: f64,
    /// Largest absolute value.
    pub max_abs: f64,
}

impl Moments {
    /// Adds a value.
    pub fn push(&mut self, v: f64) {
        if self.n == 0 {
            self.min = v;
            self.max = v;
        } else {
            self.min = self.min.min(v);
            self.max = self.max.max(v);
        }
        self.max_abs = self.max_abs.max(v.abs());
        self.n += 1;
        self.sum += v;
        self.sum_sq += v * v;
        let d = v - self.running_mean;
        self.running_mean += d / self.n as f64;
        self.sum_sq_dev += d * (v - self.running_mean);
    }

    /// Mean of the values (NaN when none).
    pub fn mean(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            self.sum / self.n as f64
        }
    }

    /// Root mean square of the values (NaN when none).
    pub fn rms(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            (self.sum_sq / self.n as f64).sqrt()
        }
    }

    /// Sample standard deviation.
    pub fn std(&self) -> f64 {
        if self.n < 2 {
            return f64::NAN;
        }
        (self.sum_sq_dev / (self.n as f64 - 1.0)).max(0.0).sqrt()
    }
}

/// The `q`-quantile (0..=1) of `values` by linear interpolation between
/// order statistics; sorts in place. NaN when empty.
pub fn quantile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(|a, b| a.total_cmp(b));
    let pos = q.clamp(0.0, 1.0) * (values.len() - 1) as f64;
    let i = pos.floor() as usize;
    let frac = pos - i as f64;
    if i + 1 < values.len() {
        values[i] * (1.0 - frac) + values[i + 1] * frac
    } else {
        values[i]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spread of values far from zero: 5 ms intervals jittered by
    /// ±1 ns (std exactly 1 ns over the alternating pattern, n−1 scaled),
    /// which Σx² − n·m² loses to cancellation.
    #[test]
    fn std_of_values_with_a_large_mean_keeps_its_precision() {
        let mut m = Moments::default();
        let n = 1_000_000;
        for k in 0..n {
            m.push(5e-3 + if k % 2 == 0 { 1e-9 } else { -1e-9 });
        }
        let want = 1e-9 * (n as f64 / (n as f64 - 1.0)).sqrt();
        assert!((m.std() - want).abs() < 1e-6 * want, "{}", m.std());
        assert!((m.mean() - 5e-3).abs() < 1e-12);
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        // Standard table values.
        for &(p, k, want) in &[
            (0.95, 1.0, 3.841_458_820_694_124),
            (0.99, 3.0, 11.344_866_730_144_373),
            (0.999, 3.0, 16.266_236_196_238_13),
            (0.975, 10.0, 20.483_177_350_807_4),
            (0.025, 50.0, 32.357_363_695_658_4),
        ] {
            let q = chi2_quantile(p, k);
            assert!((q - want).abs() < 1e-6 * want, "p={p} k={k}: {q} vs {want}");
        }
    }

    #[test]
    fn gamma_function() {
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-12);
    }

    #[test]
    fn moments_and_quantiles() {
        let mut m = Moments::default();
        for v in [1.0, -2.0, 3.0] {
            m.push(v);
        }
        assert_eq!(m.n, 3);
        assert!((m.mean() - 2.0 / 3.0).abs() < 1e-12);
        assert!((m.rms() - (14.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(m.max_abs, 3.0);
        let mut v = vec![3.0, 1.0, 2.0, 4.0];
        assert_eq!(quantile(&mut v, 0.5), 2.5);
        assert_eq!(quantile(&mut v, 1.0), 4.0);
    }
}
