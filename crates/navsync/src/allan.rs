//! Allan deviation of inertial sensor data and the noise terms read off it
//! (IEEE Std 952-1997, Annex C: angle/velocity random walk on the −1/2
//! slope, bias instability at the flat floor, σ_min = 0.664·B).
//!
//! The overlapping estimator (Riley, *Handbook of Frequency Stability
//! Analysis*, NIST SP 1065, 2008, eq 14) is computed from cumulative sums,
//! so each cluster size costs one pass over the data.
#![warn(missing_docs)]

use serde::Serialize;

/// One point of an Allan deviation curve.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct AllanPoint {
    /// Cluster time τ = m·τ₀ (s).
    pub(crate) tau_s: f64,
    /// Overlapping Allan deviation at τ (units of the input).
    pub(crate) adev: f64,
    /// Independent (non-overlapping) clusters of length τ in the data,
    /// ⌊N/m⌋: a guide to the estimate's confidence (relative error ≈
    /// 1/√(2·(clusters − 1)) at worst).
    pub(crate) clusters: usize,
}

/// Overlapping Allan deviation of `rates` sampled every `tau0_s` seconds,
/// at octave-spaced cluster sizes m = 1, 2, 4, … while at least two
/// clusters fit (2m < N).
///
/// σ²(τ) = Σ_k (θ_{k+2m} − 2θ_{k+m} + θ_k)² / (2τ²(N − 2m + 1)), with
/// θ_k = τ₀·Σ_{i<k} y_i (NIST SP 1065 eq 14). The mean is removed first
/// (it cancels in the second differences) to keep the sums small.
pub fn overlapping_adev(rates: &[f64], tau0_s: f64) -> Vec<AllanPoint> {
    let n = rates.len();
    if n < 3 || tau0_s.is_nan() || tau0_s <= 0.0 {
        return Vec::new();
    }
    let mean = rates.iter().sum::<f64>() / n as f64;
    let mut theta = Vec::with_capacity(n + 1);
    theta.push(0.0);
    let mut acc = 0.0;
    for &y in rates {
        acc += (y - mean) * tau0_s;
        theta.push(acc);
    }
    let mut out = Vec::new();
    let mut m = 1usize;
    while 2 * m < n {
        let terms = n - 2 * m + 1;
        let mut s = 0.0;
        for k in 0..terms {
            let d = theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k];
            s += d * d;
        }
        let tau = m as f64 * tau0_s;
        out.push(AllanPoint {
            tau_s: tau,
            adev: (s / (2.0 * tau * tau * terms as f64)).sqrt(),
            clusters: n / m,
        });
        m *= 2;
    }
    out
}

/// Noise terms read off an Allan deviation curve.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct NoiseFit {
    /// White-noise density N (units/√s, e.g. rad/√s for a gyro = ARW):
    /// the line of slope −1/2 through the white-noise region, read at
    /// τ = 1 s (σ(τ) = N/√τ).
    pub random_walk: f64,
    /// Bias instability B = σ_min / 0.664 (units; IEEE Std 952 C.1.3:
    /// σ² = 2 ln 2 · B²/π on the flicker floor).
    pub bias_instability: f64,
    /// τ at which the minimum was found (s).
    pub bias_instability_tau_s: f64,
}

/// √(2 ln 2 / π): the Allan deviation of flicker noise of coefficient B.
pub const FLICKER_FLOOR_FACTOR: f64 = 0.664_282_082_772_373_6;

/// Reads the random walk and the bias instability off `points`.
///
/// The Allan variance is fitted with the IEEE Std 952 C.2 sum of terms
/// σ²(τ) = a₀·τ⁻² + a₁·τ⁻¹ + a₂ + a₃·τ + a₄·τ² (quantization 3Q², white
/// noise N², the flicker floor (2 ln2/π)·B², rate random walk K²/3, rate
/// ramp R²/2), by least squares on relative residuals with each point
/// weighted by its cluster count (its relative variance is ~1/clusters)
/// and non-negative coefficients (every subset of terms is tried; the
/// feasible one with the smallest residual wins).
///
/// - `random_walk` N = √a₁: the −1/2-slope line read at τ = 1 s;
/// - `bias_instability` = min over the data's τ range of the fitted Allan
///   deviation / 0.664, at `bias_instability_tau_s`.
///
/// Reading the minimum off the fitted curve rather than off the raw
/// points avoids the strong low bias of the raw minimum, which falls on
/// the noisiest long-τ points (with 8 clusters a raw minimum is 20–40 %
/// low on a flat flicker floor).
pub fn fit_noise(points: &[AllanPoint]) -> NoiseFit {
    let mut fit = NoiseFit {
        random_walk: f64::NAN,
        bias_instability: f64::NAN,
        bias_instability_tau_s: f64::NAN,
    };
    let pts: Vec<&AllanPoint> = points
        .iter()
        .filter(|p| p.adev > 0.0 && p.tau_s > 0.0 && p.adev.is_finite())
        .collect();
    if pts.is_empty() {
        return fit;
    }
    let Some(coef) = fit_terms(&pts) else {
        // No feasible fit (fewer points than any model): raw values.
        let min = pts.iter().min_by(|a, b| a.adev.total_cmp(&b.adev)).copied();
        if let Some(m) = min {
            fit.bias_instability = m.adev / FLICKER_FLOOR_FACTOR;
            fit.bias_instability_tau_s = m.tau_s;
        }
        fit.random_walk = pts
            .iter()
            .map(|p| p.adev * p.tau_s.sqrt())
            .fold(f64::INFINITY, f64::min);
        return fit;
    };
    if coef[1] > 0.0 {
        fit.random_walk = coef[1].sqrt();
    }
    let (lo, hi) = (pts[0].tau_s, pts[pts.len() - 1].tau_s);
    let model = |tau: f64| (0..5).map(|j| coef[j] * basis(tau, j)).sum::<f64>();
    // Dense log-spaced search of the fitted curve's minimum over the data.
    let steps = 400;
    let (mut best_tau, mut best) = (lo, f64::INFINITY);
    for k in 0..=steps {
        let tau = lo * (hi / lo).powf(k as f64 / steps as f64);
        let v = model(tau);
        if v < best {
            best = v;
            best_tau = tau;
        }
    }
    if best.is_finite() && best > 0.0 {
        fit.bias_instability = best.sqrt() / FLICKER_FLOOR_FACTOR;
        fit.bias_instability_tau_s = best_tau;
    }
    fit
}

#[inline]
fn basis(tau: f64, j: usize) -> f64 {
    match j {
        0 => 1.0 / (tau * tau),
        1 => 1.0 / tau,
        2 => 1.0,
        3 => tau,
        _ => tau * tau,
    }
}

/// Non-negative weighted least squares of σ² = Σ a_j·g_j(τ) by trying every
/// subset of the five terms (31 small systems).
fn fit_terms(pts: &[&AllanPoint]) -> Option<[f64; 5]> {
    let mut best: Option<(f64, [f64; 5])> = None;
    for mask in 1u32..32 {
        let subset: Vec<usize> = (0..5).filter(|j| mask & (1 << j) != 0).collect();
        let m = subset.len();
        if pts.len() < m {
            continue;
        }
        // Normal equations of Σ w_i (Σ_j a_j g_j(τ_i)/s_i − 1)², s_i = σ_i².
        let mut ata = [[0.0f64; 5]; 5];
        let mut atb = [0.0f64; 5];
        for p in pts {
            let s = p.adev * p.adev;
            let w = p.clusters.max(1) as f64;
            for (r, &jr) in subset.iter().enumerate() {
                let gr = basis(p.tau_s, jr) / s;
                atb[r] += w * gr;
                for (c, &jc) in subset.iter().enumerate() {
                    ata[r][c] += w * gr * basis(p.tau_s, jc) / s;
                }
            }
        }
        let Some(x) = solve(&mut ata, &mut atb, m) else {
            continue;
        };
        if x[..m].iter().any(|&v| v.is_nan() || v < 0.0) {
            continue;
        }
        let mut coef = [0.0; 5];
        for (k, &j) in subset.iter().enumerate() {
            coef[j] = x[k];
        }
        let resid: f64 = pts
            .iter()
            .map(|p| {
                let model: f64 = (0..5).map(|j| coef[j] * basis(p.tau_s, j)).sum();
                let r = model / (p.adev * p.adev) - 1.0;
                p.clusters.max(1) as f64 * r * r
            })
            .sum();
        if best.as_ref().is_none_or(|(b, _)| resid < *b) {
            best = Some((resid, coef));
        }
    }
    best.map(|b| b.1)
}

/// Solves the leading m×m system by Gaussian elimination with partial
/// pivoting; `None` when singular.
fn solve(a: &mut [[f64; 5]; 5], b: &mut [f64; 5], m: usize) -> Option<[f64; 5]> {
    for col in 0..m {
        let piv = (col..m).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..m {
            let f = a[r][col] / a[col][col];
            for c in col..m {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 5];
    for r in (0..m).rev() {
        let s: f64 = (r + 1..m).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
        if !x[r].is_finite() {
            return None;
        }
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::rng;

    #[test]
    fn white_noise_has_slope_minus_half_and_its_density() {
        // White noise of density N sampled at 100 Hz: σ_sample = N·√100.
        let n_density = 0.01;
        let fs: f64 = 100.0;
        let mut r = rng::stream(3, "allan.white");
        let y: Vec<f64> = (0..400_000)
            .map(|_| n_density * fs.sqrt() * rng::normal(&mut r))
            .collect();
        let pts = overlapping_adev(&y, 1.0 / fs);
        assert_eq!(pts[0].tau_s, 0.01);
        assert_eq!(pts[0].clusters, 400_000);
        for p in pts.iter().filter(|p| p.clusters >= 100) {
            let expect = n_density / p.tau_s.sqrt();
            // Overlapping estimate with ≥100 clusters: relative sd < 10%.
            assert!((p.adev / expect - 1.0).abs() < 0.1, "{p:?} vs {expect}");
        }
        let fit = fit_noise(&pts);
        // Weighted by clusters, the fit leans on the short-τ points
        // (relative sd ~1/√(N/m) ≈ 0.2 %): within 2 %.
        assert!((fit.random_walk / n_density - 1.0).abs() < 0.02, "{fit:?}");
    }

    #[test]
    fn random_walk_rises_with_slope_plus_half() {
        // A rate random walk K: σ(τ) = K·√(τ/3) (IEEE 952 C.1.4).
        let k = 1e-3;
        let dt: f64 = 0.1;
        let mut r = rng::stream(4, "allan.rrw");
        let mut x = 0.0;
        let y: Vec<f64> = (0..200_000)
            .map(|_| {
                x += k * dt.sqrt() * rng::normal(&mut r);
                x
            })
            .collect();
        let pts = overlapping_adev(&y, dt);
        for p in pts.iter().filter(|p| p.clusters >= 50 && p.tau_s >= 1.0) {
            let expect = k * (p.tau_s / 3.0).sqrt();
            assert!((p.adev / expect - 1.0).abs() < 0.25, "{p:?} vs {expect}");
        }
    }

    #[test]
    fn degenerate_input_gives_no_points() {
        assert!(overlapping_adev(&[1.0, 2.0], 0.01).is_empty());
        assert!(overlapping_adev(&[1.0; 10], 0.0).is_empty());
        let fit = fit_noise(&[]);
        assert!(fit.random_walk.is_nan());
        // A constant signal has zero deviation: no usable points, no fit.
        let pts = overlapping_adev(&[5.0; 100], 0.01);
        assert!(fit_noise(&pts).random_walk.is_nan());
    }

    #[test]
    fn quantization_and_floor_do_not_bias_the_white_term() {
        // An analytic curve: σ² = 3Q²/τ² + N²/τ + 0.44B² (exact points).
        let (q, n, b) = (1e-4, 5e-4, 5e-4);
        // Fitted exactly: the white term and the floor come out as built.
        let pts: Vec<AllanPoint> = (0..14)
            .map(|k| {
                let tau = 0.01 * 2f64.powi(k);
                let var =
                    3.0 * q * q / (tau * tau) + n * n / tau + FLICKER_FLOOR_FACTOR.powi(2) * b * b;
                AllanPoint {
                    tau_s: tau,
                    adev: var.sqrt(),
                    clusters: (1e6 / 2f64.powi(k)) as usize,
                }
            })
            .collect();
        let fit = fit_noise(&pts);
        assert!((fit.random_walk / n - 1.0).abs() < 1e-6, "{fit:?}");
        // Without a rising term the fitted curve's minimum is at the last τ
        // (81.92 s), where N²/τ still adds 1.4 % to the floor.
        let t = 81.92;
        let at_end = (3.0 * q * q / (t * t) + n * n / t + (FLICKER_FLOOR_FACTOR * b).powi(2))
            .sqrt()
            / FLICKER_FLOOR_FACTOR;
        assert!(
            (fit.bias_instability / at_end - 1.0).abs() < 1e-6,
            "{fit:?}"
        );
        assert!(at_end / b < 1.02);
        // With a rate random walk the curve turns up: the minimum is inside.
        let k = 1e-4;
        let pts: Vec<AllanPoint> = pts
            .iter()
            .map(|p| AllanPoint {
                adev: (p.adev.powi(2) + k * k * p.tau_s / 3.0).sqrt(),
                ..*p
            })
            .collect();
        let fit = fit_noise(&pts);
        assert!(
            fit.bias_instability_tau_s < 81.0 && fit.bias_instability > b,
            "{fit:?}"
        );
        assert!((fit.random_walk / n - 1.0).abs() < 1e-6, "{fit:?}");
    }
}
