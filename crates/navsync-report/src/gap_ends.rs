//! The filter's σ through GNSS gaps, tested where each gap ends.
//!
//! The first fix after a gap measures the free INS: its innovation is the
//! drift since the last fix plus the fix's own error, with covariance
//! H P⁻ Hᵀ + R. A consistent filter's horizontal NEES there follows χ²₂
//! (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to
//! Tracking and Navigation", 2001, §5.4). A MEMS filter whose model
//! leaves errors out (axis misalignment in turns, flicker) drifts through
//! a gap several times past its σ while its σ, the drift table and any
//! protection level built on it look fine: inside the gap nothing else
//! can show it.
//!
//! A fix that is itself off after the gap (a receiver re-converging)
//! looks the same at the first fix. The fix after it tells the two apart:
//! with the first fix's gain K = σ_f²/(σ_f² + σ_fix²/w) per axis (w its
//! weight, 0 when rejected), the next innovation is (1 − K)·ν₁ when the
//! INS drifted (the update removed K of it) and −K·ν₁ when the first fix
//! was off (the update moved the INS away by K of it). Only gap ends the
//! next fix confirms as drift are counted.
//!
//! Where σ hardly grew through the gap (× < [`DRIFT_GROWTH`]), the gap end
//! tests the position that entered it: fixes before the gap whose errors
//! are correlated in time (float solutions, multipath) leave the filter
//! surer of its position than it is, and the first sharp fix after the gap
//! shows it.

use crate::inputs::FixWeight;

/// One gap's end, measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct GapEnd {
    /// The first fix after the gap (SOW).
    pub sow: f64,
    /// The gap's length (s).
    pub gap_s: f64,
    /// Horizontal distance between the INS's prediction and the fix (m).
    pub offset_h_m: f64,
    /// The filter's predicted horizontal σ just before the fix (m).
    pub filter_sd_h_m: f64,
    /// Its horizontal σ as the gap began (m): σ that hardly grew through
    /// the gap put the error in the position entering it (the fixes
    /// before it), not in the INS's drift.
    pub start_sd_h_m: f64,
    /// Horizontal NEES of the innovation against H P⁻ Hᵀ + R.
    pub nees: f64,
    /// Whether the fix after it confirms the INS drifted (`None` without
    /// a next fix close enough to tell).
    pub drift_confirmed: Option<bool>,
}

/// Gap ends over a run.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct GapEndEvidence {
    /// Gap ends tested (the INS's predicted spread larger than the fix's).
    pub tested: usize,
    /// NEES threshold: χ²₂ at [`FAMILY_FALSE_ALARM`] over the ends tested.
    pub threshold: f64,
    /// Ends past the threshold and confirmed as drift by the next fix.
    pub exceeded: usize,
    /// The confirmed ends with the largest NEES: where σ grew through the
    /// gap (the INS drifted) and where it hardly grew (the position
    /// entering the gap was off).
    pub worst_drift: Option<GapEnd>,
    pub worst_entry: Option<GapEnd>,
    /// The written file is the forward filter's (graded); a smoothed file
    /// has other σ, and the finding is about its forward pass.
    pub written_is_forward: bool,
}

/// Chance that a consistent run has any gap end past the threshold: the
/// per-end level is this over the ends tested (Bonferroni), as the
/// innovation signature tests' 1 % (issue 34's 5 % budget of consistent
/// runs called "not good").
pub(crate) const FAMILY_FALSE_ALARM: f64 = 1e-2;

/// The next fix counts for the confirmation when within this many seconds
/// of the first (past it the INS has drifted anew).
const CONFIRM_WITHIN_S: f64 = 5.0;

/// σ growth through a gap (end ÷ start) from which the gap end is taken
/// to test the INS's drift rather than the position entering the gap.
pub(crate) const DRIFT_GROWTH: f64 = 2.0;

/// χ²₂'s upper quantile at tail probability `alpha`: −2 ln α exactly.
fn chi2_2_upper(alpha: f64) -> f64 {
    -2.0 * alpha.ln()
}

/// The filter's σ north, east at the last std.txt row before `sow`
/// (rows: sow, σ_n, σ_e, …).
fn filter_sd_before(std: &[Vec<f64>], sow: f64) -> Option<[f64; 2]> {
    let r = crate::inputs::std_row_before(std, sow)?;
    (r.len() >= 3 && r[1].is_finite() && r[2].is_finite()).then(|| [r[1], r[2]])
}

/// One gap to measure: its length (s), the SOW of the first fix after it,
/// and the filter's horizontal σ just after the last fix before it (the
/// drift table's start, [`crate::quality::drift_through`]; NaN unknown).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct GapSpan {
    pub gap_s: f64,
    pub end_sow: f64,
    pub start_sd_h_m: f64,
}

/// Measures the end of the gap whose first fix is `fixes[k]`; `None` when
/// the fix is sharper than the INS there (the test would be about the
/// fix) or σ are missing.
fn measure(fixes: &[FixWeight], k: usize, span: GapSpan, std: &[Vec<f64>]) -> Option<GapEnd> {
    let f = &fixes[k];
    let sf = filter_sd_before(std, f.sow)?;
    let var_f = [sf[0] * sf[0], sf[1] * sf[1]];
    let var_r = [f.sd[0] * f.sd[0], f.sd[1] * f.sd[1]];
    if var_f[0] + var_f[1] <= var_r[0] + var_r[1] {
        return None;
    }
    let nu = [f.innovation[0], f.innovation[1]];
    let nees = (0..2)
        .map(|i| nu[i] * nu[i] / (var_f[i] + var_r[i]))
        .sum::<f64>();
    if !nees.is_finite() {
        return None;
    }
    let drift_confirmed = fixes
        .get(k + 1)
        .filter(|n| n.sow - f.sow <= CONFIRM_WITHIN_S)
        .and_then(|n| {
            let sn = filter_sd_before(std, n.sow)?;
            let (mut d_drift, mut d_off) = (0.0, 0.0);
            for i in 0..2 {
                let w = f.weight[i];
                let gain = if w > 0.0 {
                    var_f[i] / (var_f[i] + var_r[i] / w)
                } else {
                    0.0
                };
                let v = sn[i] * sn[i] + n.sd[i] * n.sd[i];
                let nu2 = n.innovation[i];
                d_drift += (nu2 - (1.0 - gain) * nu[i]).powi(2) / v;
                d_off += (nu2 + gain * nu[i]).powi(2) / v;
            }
            (d_drift.is_finite() && d_off.is_finite()).then_some(d_drift <= d_off)
        });
    Some(GapEnd {
        sow: f.sow,
        gap_s: span.gap_s,
        start_sd_h_m: span.start_sd_h_m,
        offset_h_m: nu[0].hypot(nu[1]),
        filter_sd_h_m: sf[0].hypot(sf[1]),
        nees,
        drift_confirmed,
    })
}

/// Measures every gap's end: `fixes` are the position lines of
/// gnss_residuals.txt in time order, `std` the forward filter's std.txt
/// rows. A gap whose first fix has no residual line (refused before
/// weighing) is skipped.
pub(crate) fn measure_all(
    gaps: &[GapSpan],
    fixes: &[FixWeight],
    std: &[Vec<f64>],
) -> Vec<Option<GapEnd>> {
    gaps.iter()
        .map(|&span| {
            let k = fixes.partition_point(|f| f.sow < span.end_sow - 1e-3);
            fixes
                .get(k)
                .filter(|f| (f.sow - span.end_sow).abs() <= 1e-3)
                .and_then(|_| measure(fixes, k, span, std))
        })
        .collect()
}

/// The run's evidence from its measured gap ends; `None` when none was
/// tested.
pub(crate) fn evidence(ends: &[GapEnd], written_is_forward: bool) -> Option<GapEndEvidence> {
    if ends.is_empty() {
        return None;
    }
    let threshold = chi2_2_upper(FAMILY_FALSE_ALARM / ends.len() as f64);
    let past: Vec<&GapEnd> = ends
        .iter()
        .filter(|e| e.nees > threshold && e.drift_confirmed == Some(true))
        .collect();
    let worst = |drift: bool| {
        past.iter()
            .filter(|e| e.drifted_through_gap() == drift)
            .max_by(|a, b| a.nees.total_cmp(&b.nees))
            .map(|e| **e)
    };
    Some(GapEndEvidence {
        tested: ends.len(),
        threshold,
        exceeded: past.len(),
        worst_drift: worst(true),
        worst_entry: worst(false),
        written_is_forward,
    })
}

impl GapEnd {
    /// σ grew by [`DRIFT_GROWTH`] or more through the gap: the end tests
    /// the INS's drift (an unknown start σ counts as grown).
    pub(crate) fn drifted_through_gap(&self) -> bool {
        self.start_sd_h_m.is_nan() || self.filter_sd_h_m >= DRIFT_GROWTH * self.start_sd_h_m
    }
}

impl GapEndEvidence {
    /// The confirmed end with the largest NEES, of either kind.
    pub(crate) fn worst(&self) -> Option<GapEnd> {
        [self.worst_drift, self.worst_entry]
            .into_iter()
            .flatten()
            .max_by(|a, b| a.nees.total_cmp(&b.nees))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(sow: f64, innov: [f64; 2], sd: f64, weight: f64) -> FixWeight {
        FixWeight {
            sow,
            innovation: [innov[0], innov[1], 0.0],
            sd: [sd, sd, sd],
            nis: 0.0,
            weight: [weight; 3],
            status: "used".into(),
            reason: "-".into(),
        }
    }

    /// A gap of `gap_s` ending at `end_sow`, entered at the rows' floor σ
    /// (0.02 m per axis).
    fn span(gap_s: f64, end_sow: f64) -> GapSpan {
        GapSpan {
            gap_s,
            end_sow,
            start_sd_h_m: 0.02f64.hypot(0.02),
        }
    }

    /// std.txt rows at 0.1 s: σ `floor` per axis, growing linearly from
    /// `start` (the last fix before a gap) to `peak` just before `update`
    /// (the first fix that updates the state), `floor` again from it.
    fn std_rows(start: f64, update: f64, peak: f64, floor: f64) -> Vec<Vec<f64>> {
        (0..600)
            .map(|k| {
                let t = k as f64 * 0.1 + 0.005;
                let s = if t > start && t < update {
                    floor + (peak - floor) * (t - start) / (update - start)
                } else {
                    floor
                };
                vec![t, s, s, 0.1]
            })
            .collect()
    }

    #[test]
    fn chi2_2_upper_is_the_exponential_tail() {
        // χ²₂ is exponential with mean 2: P(X > x) = e^(−x/2).
        for a in [0.05, 1e-2, 1e-4] {
            let x = chi2_2_upper(a);
            assert!(((-x / 2.0).exp() - a).abs() < 1e-12);
        }
        let x = navsync::stats::chi2_quantile(0.999, 2.0);
        assert!((chi2_2_upper(1e-3) - x).abs() < 1e-6, "{x}");
    }

    /// A 4.7 m drift where σ said 1 m, the next fix agreeing with the
    /// corrected INS: counted. The same first fix followed by one that
    /// says it was the fix that was off: not counted. A drift inside its
    /// σ: tested, not counted.
    #[test]
    fn a_drift_past_sigma_is_counted_only_when_the_next_fix_confirms_it() {
        let std = std_rows(4.0, 30.0, 0.7, 0.02);
        let gaps = [span(26.0, 30.0)];
        // Drifted 4.7 m; the fix (σ 2 cm, weight 1) takes K ≈ 1 of it, the
        // next innovation is ~0.
        let drifted = [
            fix(30.0, [-4.3, 1.9], 0.02, 1.0),
            fix(31.0, [-0.05, 0.0], 0.02, 1.0),
        ];
        let ends: Vec<GapEnd> = measure_all(&gaps, &drifted, &std)
            .into_iter()
            .flatten()
            .collect();
        assert_eq!(ends.len(), 1);
        assert_eq!(ends[0].drift_confirmed, Some(true));
        assert!((ends[0].offset_h_m - 4.3f64.hypot(1.9)).abs() < 1e-9);
        let e = evidence(&ends, true).unwrap();
        assert_eq!((e.tested, e.exceeded), (1, 1));
        assert!(e.worst().unwrap().nees > 20.0, "{e:?}");
        assert_eq!(e.worst_entry, None, "σ grew ×35 through the gap");
        // The first fix was off: the INS followed it, the next fix pulls
        // back by as much.
        let fix_off = [
            fix(30.0, [-4.3, 1.9], 0.02, 1.0),
            fix(31.0, [4.25, -1.88], 0.02, 1.0),
        ];
        let ends: Vec<GapEnd> = measure_all(&gaps, &fix_off, &std)
            .into_iter()
            .flatten()
            .collect();
        assert_eq!(ends[0].drift_confirmed, Some(false));
        assert_eq!(evidence(&ends, true).unwrap().exceeded, 0);
        // A rejected first fix (w = 0) and a next fix still as far off:
        // the INS drifted.
        let rejected = [
            fix(30.0, [-4.3, 1.9], 0.02, 0.0),
            fix(31.0, [-4.35, 1.92], 0.02, 1.0),
        ];
        let std_rej = std_rows(4.0, 32.0, 0.75, 0.02);
        let ends: Vec<GapEnd> = measure_all(&gaps, &rejected, &std_rej)
            .into_iter()
            .flatten()
            .collect();
        assert_eq!(ends[0].drift_confirmed, Some(true));
        // Inside σ: 0.8 m against 0.7 m per axis.
        let fine = [
            fix(30.0, [0.5, -0.6], 0.02, 1.0),
            fix(31.0, [0.0, 0.0], 0.02, 1.0),
        ];
        let ends: Vec<GapEnd> = measure_all(&gaps, &fine, &std)
            .into_iter()
            .flatten()
            .collect();
        let e = evidence(&ends, true).unwrap();
        assert_eq!((e.tested, e.exceeded, e.worst()), (1, 0, None));
    }

    /// A fix less certain than the INS tests the fix, not the INS: not
    /// tested; nor is a gap whose first fix has no residual line.
    #[test]
    fn a_fix_sharper_than_nothing_or_missing_is_not_tested() {
        let std = std_rows(25.0, 30.0, 0.05, 0.02);
        let coarse = [
            fix(30.0, [3.0, 0.0], 2.0, 1.0),
            fix(31.0, [0.0, 0.0], 2.0, 1.0),
        ];
        assert_eq!(measure_all(&[span(5.0, 30.0)], &coarse, &std), vec![None]);
        assert_eq!(measure_all(&[span(5.0, 29.0)], &coarse, &std), vec![None]);
        assert_eq!(evidence(&[], true), None);
    }

    /// The threshold falls with the ends tested (1 % over all of them):
    /// the same NEES passes among many ends that fails among few.
    #[test]
    fn the_threshold_holds_the_false_alarms_over_the_run() {
        let end = GapEnd {
            sow: 0.0,
            gap_s: 10.0,
            start_sd_h_m: 0.03,
            offset_h_m: 1.0,
            filter_sd_h_m: 0.3,
            nees: 15.0,
            drift_confirmed: Some(true),
        };
        assert_eq!(evidence(&[end], true).unwrap().exceeded, 1);
        let many = vec![GapEnd { nees: 1.0, ..end }; 99];
        let mut all = many.clone();
        all.push(end);
        let e = evidence(&all, true).unwrap();
        assert!((e.threshold - chi2_2_upper(1e-4)).abs() < 1e-12);
        assert_eq!(e.exceeded, 0, "15 < {}", e.threshold);
    }
}
