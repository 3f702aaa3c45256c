//! How good a run is without a reference trajectory: χ² bounds of the
//! GNSS innovations, data gaps, the filter's predicted drift through them
//! and a plain-language verdict made of explicit, physically motivated
//! checks.
//!
//! Every threshold is a named constant below with the reason for its value;
//! the report page prints the same rules beside each finding.

/// The `p` quantile of χ²(`dof`) ([`navsync::stats::chi2_quantile`]);
/// `None` unless 0 < p < 1 and dof > 0.
pub(crate) fn chi2_quantile(p: f64, dof: f64) -> Option<f64> {
    (p > 0.0 && p < 1.0 && dof > 0.0 && dof.is_finite())
        .then(|| navsync::stats::chi2_quantile(p, dof))
}

/// Degrees of freedom of a GNSS position fix's NIS (north, east, down).
pub(crate) const POSITION_DOF: f64 = 3.0;

/// The two-sided `conf` interval of the mean NIS over `n` independent
/// fixes of `dof` each: the sum of n NIS is χ²(n·dof), so the mean lies in
/// [χ²_{α/2}(n·dof)/n, χ²_{1−α/2}(n·dof)/n] (Bar-Shalom, Li & Kirubarajan,
/// "Estimation with Applications to Tracking and Navigation", 2001,
/// §5.4.2). With n = 1 it is the interval of a single NIS.
pub(crate) fn nis_mean_interval(n: usize, dof: f64, conf: f64) -> Option<(f64, f64)> {
    if n == 0 {
        return None;
    }
    let a = 0.5 * (1.0 - conf);
    let k = n as f64 * dof;
    Some((
        chi2_quantile(a, k)? / n as f64,
        chi2_quantile(1.0 - a, k)? / n as f64,
    ))
}

/// A GNSS gap is an interval between consecutive fixes longer than
/// `GAP_FACTOR` × the median interval (2.5: a 10 Hz receiver missing two
/// fixes in a row; one lost fix is ordinary).
pub(crate) const GAP_FACTOR: f64 = 2.5;
/// Gaps at least this long (s) get a predicted-drift row: below a few
/// seconds a MEMS INS drifts centimetres, which the σ tables already show.
pub(crate) const DRIFT_MIN_GAP_S: f64 = 2.0;

/// The gaps in sorted `times` (s): (last time before, first time after).
pub(crate) fn find_gaps(times: &[f64]) -> Vec<(f64, f64)> {
    if times.len() < 3 {
        return Vec::new();
    }
    let mut dt: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    dt.sort_by(f64::total_cmp);
    let median = dt[dt.len() / 2];
    if median.is_nan() || median <= 0.0 {
        return Vec::new();
    }
    times
        .windows(2)
        .filter(|w| w[1] - w[0] > GAP_FACTOR * median)
        .map(|w| (w[0], w[1]))
        .collect()
}

/// The filter's predicted horizontal σ through one gap, from a σ history
/// `(t, σ_h)` sorted by t: σ at the last epoch at or before the gap's
/// start and the largest σ inside it (reached just before the first fix
/// after it). `None` when the history does not cover the gap.
pub(crate) fn drift_through(sigma_h: &[(f64, f64)], start: f64, end: f64) -> Option<(f64, f64)> {
    let before = sigma_h.iter().rev().find(|(t, _)| *t <= start)?.1;
    let peak = sigma_h
        .iter()
        .filter(|(t, _)| *t >= start && *t <= end)
        .map(|p| p.1)
        .fold(before, f64::max);
    Some((before, peak))
}

/// How a check (or the whole run) came out.
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Grade {
    Good,
    Caution,
    Poor,
}

impl Grade {
    /// The words the page shows.
    pub fn words(self) -> &'static str {
        match self {
            Grade::Good => "good",
            Grade::Caution => "usable with caution",
            Grade::Poor => "poor",
        }
    }
}

/// One finding of the verdict: what was measured, against which rule.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Check {
    pub name: &'static str,
    /// `None`: shown for information, not graded.
    pub grade: Option<Grade>,
    pub finding: String,
    pub rule: String,
}

/// The verdict: the worst graded check, and every check.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Verdict {
    pub grade: Grade,
    pub checks: Vec<Check>,
}

/// What the GNSS position fixes said (from `gnss_residuals.txt`).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct FixEvidence {
    pub fixes: usize,
    pub rejected: usize,
    /// Used with a weight below 1 on some axis (not rejected).
    pub down_weighted: usize,
    /// NIS at the stated σ of every fix not rejected.
    pub nis: Vec<f64>,
    /// Median stated horizontal σ √(σ_n² + σ_e²) of the fixes (m).
    pub median_fix_h_sd_m: f64,
}

/// One IMU bias axis against the configured (datasheet) figures.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub(crate) struct BiasCheck {
    /// e.g. "gyro x".
    pub axis: String,
    pub unit: &'static str,
    /// The configured initial bias (the envelope's centre).
    pub center: f64,
    /// The configured initial σ (turn-on) and instability σ (Gauss–Markov).
    pub init_sd: f64,
    pub instability_sd: f64,
    pub corr_time_s: f64,
    pub final_estimate: f64,
    /// The envelope's σ at the last epoch ([`bias_prior_sd`]).
    pub final_sd: f64,
    /// Largest |estimate − centre| / σ(t) over the run.
    pub max_sigmas: f64,
}

/// The configured spread of a bias `t_s` after the start: a first-order
/// Gauss–Markov process with steady-state σ `instability_sd` and
/// correlation time τ, starting with σ `init_sd`, has
/// σ²(t) = σ₀² e^{−2t/τ} + σ_GM² (1 − e^{−2t/τ}) (the variance of a
/// first-order Markov process; Gelb, "Applied Optimal Estimation", 1974,
/// ch. 3; KF-GINS's bias model).
pub(crate) fn bias_prior_sd(init_sd: f64, instability_sd: f64, corr_time_s: f64, t_s: f64) -> f64 {
    let decay = if corr_time_s > 0.0 {
        (-2.0 * t_s.max(0.0) / corr_time_s).exp()
    } else {
        0.0
    };
    (init_sd * init_sd * decay + instability_sd * instability_sd * (1.0 - decay)).sqrt()
}

/// Synchronization facts (sync_report.json, summary.json).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct SyncEvidence {
    /// IMU samples lost / expected (sync_report.json).
    pub imu_loss_fraction: Option<f64>,
    /// Largest stamp-error bound (µs, sync_report.json).
    pub max_stamp_bound_us: Option<f64>,
    /// Longest IMU gap the fusion bridged (s, summary.json stats).
    pub max_imu_gap_s: Option<f64>,
}

/// The alignment outcome (summary.json `alignment`).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct AlignEvidence {
    pub method: String,
    pub time_sow: f64,
    pub yaw_sd_deg: f64,
    pub note: String,
}

/// Everything the verdict weighs; absent evidence is "not assessed".
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Evidence {
    pub fixes: Option<FixEvidence>,
    /// The filter's horizontal σ at the last epoch (m).
    pub final_h_sd_m: Option<f64>,
    pub biases: Vec<BiasCheck>,
    pub sync: Option<SyncEvidence>,
    /// Final σ of the time-offset state (s).
    pub time_offset_sd_s: Option<f64>,
    pub alignment: Option<AlignEvidence>,
    /// Predicted horizontal σ at the end of the worst GNSS gap: (gap
    /// length s, σ m).
    pub worst_gap: Option<(f64, f64)>,
    /// The written file against the fixes and the forward pass.
    pub written: Option<crate::written::WrittenEvidence>,
    /// Why the solution file is incomplete (a cut last line, or it ends
    /// before summary.json's last solution), if it is.
    pub solution_incomplete: Option<String>,
}

/// Rejected fixes: a consistent filter gates at 99.99 % (or IGG-III k1 =
/// 10σ), so chance rejections are ~1e-4; above 1 % the receiver had real
/// faults (or the INS diverged), above 5 % for long stretches.
pub(crate) const REJECTED_CAUTION: f64 = 0.01;
pub(crate) const REJECTED_POOR: f64 = 0.05;
/// Down-weighted fixes: the robust weighting's k0 = 4σ is exceeded by
/// chance on ~2e-4 of fixes; 5 % means degraded GNSS the filter had to
/// discount, 25 % means the GNSS was degraded most of the time.
pub(crate) const DOWN_WEIGHTED_CAUTION: f64 = 0.05;
pub(crate) const DOWN_WEIGHTED_POOR: f64 = 0.25;
/// NIS mean: inside its 95 % interval is consistent. Above it, up to
/// 3 × the expected 3 (innovations up to √3 ≈ 1.7× their stated σ) the σ
/// figures are optimistic; beyond, they cannot be trusted. Below the
/// interval the filter is pessimistic (σ figures conservative). Fixes at
/// 10 Hz are correlated, so the effective n is smaller than counted and
/// the interval too narrow: outside it is a caution, not a failure.
pub(crate) const NIS_CONF: f64 = 0.95;
pub(crate) const NIS_MEAN_POOR_FACTOR: f64 = 3.0;
/// Final horizontal σ against the fixes' stated σ: a filter updated by a
/// fix ends at or below its σ; above 1.5× the last fixes did not constrain
/// it, above 5× the solution is running on the INS alone.
pub(crate) const FINAL_SD_CAUTION: f64 = 1.5;
pub(crate) const FINAL_SD_POOR: f64 = 5.0;
/// Biases: the configured σ(t) ([`bias_prior_sd`]) is the bias's 1σ
/// spread; beyond 3σ (0.3 % chance per axis) the IMU is not what is
/// configured, or the bias state absorbs another error (misalignment,
/// lever arm, timing) or has not converged.
pub(crate) const BIAS_SIGMAS: f64 = 3.0;
/// IMU data loss: at most 1e-5 of samples (Tang, Zhang & Niu, "MEMS IMU
/// raw data acquisition and time synchronization pitfalls", 2022); above
/// 1e-3 the integration bridges gaps often.
pub(crate) const IMU_LOSS_GOOD: f64 = 1e-5;
pub(crate) const IMU_LOSS_POOR: f64 = 1e-3;
/// Synchronization error: < 1 ms good, < 10 ms required (same source);
/// applied to the stamp-error bound and the time-offset state's σ.
pub(crate) const SYNC_GOOD_S: f64 = 1e-3;
pub(crate) const SYNC_POOR_S: f64 = 10e-3;
/// No IMU gap of 0.1 s (same source).
pub(crate) const IMU_GAP_CAUTION_S: f64 = 0.1;
/// Alignment heading σ: a yaw error δψ drifts a vehicle's position
/// across-track by v·t·δψ; above 10° the small-angle error model of the
/// filter no longer holds.
pub(crate) const ALIGN_YAW_SD_CAUTION_DEG: f64 = 10.0;

/// The written (smoothed) solution against the fixes, relative to the
/// forward filter's: a smoother only ever moves the solution within the
/// forward pass's uncertainty, so it ends about as close to the fixes as
/// the forward filter or closer (the forward filter's 0.78 m became
/// 1 643 m on a slow robot whose heading was unknown). Above 1.5× (and by
/// more than the fixes' σ) is a caution, above 3× (and by more than twice
/// their σ) the smoothing diverged.
pub(crate) const WRITTEN_VS_FORWARD_CAUTION: f64 = 1.5;
pub(crate) const WRITTEN_VS_FORWARD_POOR: f64 = 3.0;
/// Any written solution further than this from the fixes, in units of
/// their stated σ (and at least [`WRITTEN_FAR_MIN_M`]), is not on the
/// fixes' trajectory at all: an antenna lever arm is metres at most.
pub(crate) const WRITTEN_FAR_SIGMAS: f64 = 10.0;
pub(crate) const WRITTEN_FAR_MIN_M: f64 = 10.0;
/// Written speeds above twice the fixes' fastest plus this (m/s) are not
/// the vehicle's.
pub(crate) const WRITTEN_SPEED_MARGIN_MPS: f64 = 5.0;
/// A written horizontal σ beyond this (m) says the solution is not a
/// position (no land or air vehicle application accepts it).
pub(crate) const WRITTEN_SD_POOR_M: f64 = 1000.0;

/// The checks of the written file ([`crate::written`]).
fn written_checks(w: &crate::written::WrittenEvidence, checks: &mut Vec<Check>) {
    let far = (WRITTEN_FAR_SIGMAS * w.median_fix_sd_h_m).max(WRITTEN_FAR_MIN_M);
    let (grade, how) = match w.forward_rms_vs_fixes_m {
        _ if !w.rms_vs_fixes_m.is_finite() || w.rms_vs_fixes_m > far => (
            Grade::Poor,
            format!("not on the fixes' trajectory (beyond {far:.1} m)"),
        ),
        Some(fwd) => {
            let ratio = w.rms_vs_fixes_m / fwd.max(1e-9);
            let excess = w.rms_vs_fixes_m - fwd;
            let g = if ratio > WRITTEN_VS_FORWARD_POOR && excess > 2.0 * w.median_fix_sd_h_m {
                Grade::Poor
            } else if ratio > WRITTEN_VS_FORWARD_CAUTION && excess > w.median_fix_sd_h_m {
                Grade::Caution
            } else {
                Grade::Good
            };
            (g, format!("{ratio:.2}× the forward filter's {fwd:.3} m"))
        }
        None => (Grade::Good, "on the fixes' trajectory".to_string()),
    };
    checks.push(Check {
        name: "written solution vs GNSS fixes",
        grade: Some(grade),
        finding: format!(
            "horizontal RMS {:.3} m over {} of {} fixes (their median σ {:.3} m; a lever arm adds to it): {how}",
            w.rms_vs_fixes_m, w.fixes_compared, w.fixes_total, w.median_fix_sd_h_m
        ),
        rule: format!(
            "poor beyond {WRITTEN_FAR_SIGMAS:.0}× the fixes' σ (at least {WRITTEN_FAR_MIN_M:.0} m); a smoothed file: caution above {WRITTEN_VS_FORWARD_CAUTION}× the forward filter's RMS, poor above {WRITTEN_VS_FORWARD_POOR}×"
        ),
    });
    let speed_limit = 2.0 * w.max_fix_speed_mps + WRITTEN_SPEED_MARGIN_MPS;
    checks.push(Check {
        name: "written speeds",
        grade: Some(
            if w.max_speed_mps.is_finite() && w.max_speed_mps <= speed_limit {
                Grade::Good
            } else {
                Grade::Poor
            },
        ),
        finding: format!(
            "up to {:.1} m/s; the fixes' track up to {:.1} m/s",
            w.max_speed_mps, w.max_fix_speed_mps
        ),
        rule: format!("poor above twice the fixes' fastest + {WRITTEN_SPEED_MARGIN_MPS:.0} m/s"),
    });
    if let Some(sd) = w.max_sd_h_m {
        checks.push(Check {
            name: "written σ",
            grade: Some(if sd.is_finite() && sd <= WRITTEN_SD_POOR_M {
                Grade::Good
            } else {
                Grade::Poor
            }),
            finding: format!("largest horizontal σ {sd:.2} m"),
            rule: format!("poor above {WRITTEN_SD_POOR_M:.0} m"),
        });
    }
}

/// The three-way grade of `x` with `good ≤ caution < poor` thresholds.
fn grade_of(x: f64, caution_above: f64, poor_above: f64) -> Grade {
    if x > poor_above {
        Grade::Poor
    } else if x > caution_above {
        Grade::Caution
    } else {
        Grade::Good
    }
}

fn pct(x: f64) -> String {
    format!("{:.2} %", 100.0 * x)
}

/// Weighs the evidence.
pub(crate) fn assess(ev: &Evidence) -> Verdict {
    let mut checks = Vec::new();
    if let Some(why) = &ev.solution_incomplete {
        checks.push(Check {
            name: "solution file",
            grade: Some(Grade::Poor),
            finding: why.clone(),
            rule: "a solution cut short (an interrupted run, a full disk, an older navsync's leftovers) is no result: run again".into(),
        });
    }
    if let Some(f) = &ev.fixes
        && f.fixes > 0
    {
        let n = f.fixes as f64;
        let rej = f.rejected as f64 / n;
        checks.push(Check {
            name: "GNSS fixes rejected",
            grade: Some(grade_of(rej, REJECTED_CAUTION, REJECTED_POOR)),
            finding: format!(
                "{} of {} position fixes ({})",
                f.rejected,
                f.fixes,
                pct(rej)
            ),
            rule: format!(
                "good ≤ {}, poor > {} (chance rejections ≈ 0.01 %)",
                pct(REJECTED_CAUTION),
                pct(REJECTED_POOR)
            ),
        });
        let dw = f.down_weighted as f64 / n;
        checks.push(Check {
            name: "GNSS fixes down-weighted",
            grade: Some(grade_of(dw, DOWN_WEIGHTED_CAUTION, DOWN_WEIGHTED_POOR)),
            finding: format!("{} of {} ({})", f.down_weighted, f.fixes, pct(dw)),
            rule: format!(
                "good ≤ {}, poor > {}",
                pct(DOWN_WEIGHTED_CAUTION),
                pct(DOWN_WEIGHTED_POOR)
            ),
        });
        if let Some((lo, hi)) = nis_mean_interval(f.nis.len(), POSITION_DOF, NIS_CONF) {
            let mean = f.nis.iter().sum::<f64>() / f.nis.len() as f64;
            let poor = NIS_MEAN_POOR_FACTOR * POSITION_DOF;
            let (grade, how) = if mean > poor {
                (Grade::Poor, "the filter's σ understate the errors")
            } else if mean > hi {
                (Grade::Caution, "σ figures optimistic")
            } else if mean < lo {
                (Grade::Caution, "σ figures pessimistic (conservative)")
            } else {
                (Grade::Good, "consistent")
            };
            checks.push(Check {
                name: "NIS mean",
                grade: Some(grade),
                finding: format!(
                    "{mean:.2} over {} fixes (expected {POSITION_DOF:.0}, 95 % interval {lo:.2} … {hi:.2}): {how}",
                    f.nis.len()
                ),
                rule: format!(
                    "good inside the interval χ²(3n)/n; poor above {poor:.0}; caution otherwise"
                ),
            });
        }
        if let Some(sd) = ev.final_h_sd_m
            && f.median_fix_h_sd_m > 0.0
        {
            let r = sd / f.median_fix_h_sd_m;
            checks.push(Check {
                name: "final horizontal σ",
                grade: Some(grade_of(r, FINAL_SD_CAUTION, FINAL_SD_POOR)),
                finding: format!(
                    "{sd:.3} m, {r:.2}× the fixes' median stated σ ({:.3} m)",
                    f.median_fix_h_sd_m
                ),
                rule: format!("good ≤ {FINAL_SD_CAUTION}× the fixes' σ, poor > {FINAL_SD_POOR}×"),
            });
        }
    } else if let Some(sd) = ev.final_h_sd_m {
        checks.push(Check {
            name: "final horizontal σ",
            grade: None,
            finding: format!("{sd:.3} m (no gnss_residuals.txt to compare it with)"),
            rule: "not graded".into(),
        });
    }
    if let Some(w) = &ev.written {
        written_checks(w, &mut checks);
    }
    if !ev.biases.is_empty() {
        let outside: Vec<&BiasCheck> = ev
            .biases
            .iter()
            .filter(|b| b.max_sigmas.is_nan() || b.max_sigmas > BIAS_SIGMAS)
            .collect();
        checks.push(Check {
            name: "IMU biases vs datasheet",
            grade: Some(if outside.is_empty() {
                Grade::Good
            } else {
                Grade::Caution
            }),
            finding: if outside.is_empty() {
                format!(
                    "all {} bias estimates stay inside ±{BIAS_SIGMAS:.0}σ",
                    ev.biases.len()
                )
            } else {
                format!(
                    "{} of {} leave ±{BIAS_SIGMAS:.0}σ: {}",
                    outside.len(),
                    ev.biases.len(),
                    outside
                        .iter()
                        .map(|b| format!("{} ({:.1}σ)", b.axis, b.max_sigmas))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            },
            rule: format!(
                "good when every estimate stays within ±{BIAS_SIGMAS:.0}σ of the configuration"
            ),
        });
    }
    if let Some(s) = &ev.sync {
        if let Some(l) = s.imu_loss_fraction {
            checks.push(Check {
                name: "IMU data loss",
                grade: Some(grade_of(l, IMU_LOSS_GOOD, IMU_LOSS_POOR)),
                finding: format!("{l:.2e} of samples"),
                rule: format!("good ≤ {IMU_LOSS_GOOD:.0e}, poor > {IMU_LOSS_POOR:.0e}"),
            });
        }
        if let Some(b) = s.max_stamp_bound_us {
            checks.push(Check {
                name: "IMU stamp-error bound",
                grade: Some(grade_of(b * 1e-6, SYNC_GOOD_S, SYNC_POOR_S)),
                finding: format!("max {b:.1} µs"),
                rule: "good ≤ 1 ms, poor > 10 ms".into(),
            });
        }
        if let Some(g) = s.max_imu_gap_s {
            checks.push(Check {
                name: "longest IMU gap",
                grade: Some(if g >= IMU_GAP_CAUTION_S {
                    Grade::Caution
                } else {
                    Grade::Good
                }),
                finding: format!("{g:.3} s"),
                rule: format!("caution from {IMU_GAP_CAUTION_S} s"),
            });
        }
    }
    if let Some(sd) = ev.time_offset_sd_s {
        checks.push(Check {
            name: "time-offset σ",
            grade: Some(grade_of(sd, SYNC_GOOD_S, SYNC_POOR_S)),
            finding: format!("{:.3} ms", sd * 1e3),
            rule: "good ≤ 1 ms, poor > 10 ms".into(),
        });
    }
    if let Some(a) = &ev.alignment {
        let no_heading = a.method == "no-motion";
        checks.push(Check {
            name: "alignment",
            grade: Some(
                if no_heading || a.yaw_sd_deg.is_nan() || a.yaw_sd_deg > ALIGN_YAW_SD_CAUTION_DEG {
                    Grade::Caution
                } else {
                    Grade::Good
                },
            ),
            finding: format!(
                "{} at SOW {:.3}, yaw σ {:.2}°: {}",
                a.method, a.time_sow, a.yaw_sd_deg, a.note
            ),
            rule: format!(
                "caution when the vehicle never moved or yaw σ > {ALIGN_YAW_SD_CAUTION_DEG}°"
            ),
        });
    }
    if let Some((len, sd)) = ev.worst_gap {
        checks.push(Check {
            name: "worst GNSS gap",
            grade: None,
            finding: format!("{len:.1} s; predicted horizontal σ at its end {sd:.2} m"),
            rule: "not graded (what is acceptable depends on the application)".into(),
        });
    }
    let grade = checks
        .iter()
        .filter_map(|c| c.grade)
        .max()
        .unwrap_or(Grade::Caution);
    if checks.iter().all(|c| c.grade.is_none()) {
        checks.push(Check {
            name: "evidence",
            grade: Some(Grade::Caution),
            finding: "nothing to grade: no gnss_residuals.txt, imu_err.txt with summary.json, sync report or time offset".into(),
            rule: "caution without evidence".into(),
        });
    }
    Verdict { grade, checks }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync::stats::{chi2_cdf, ln_gamma};

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs()
    }

    #[test]
    fn chi_square_quantiles_match_tables() {
        // Abramowitz & Stegun table 26.8 / NIST values.
        let cases = [
            (0.95, 1.0, 3.841_458_821),
            (0.95, 3.0, 7.814_727_903),
            (0.975, 3.0, 9.348_403_604),
            (0.025, 3.0, 0.215_795_283),
            (0.9999, 3.0, 21.107_513_49),
            (0.975, 100.0, 129.561_197_9),
            (0.025, 100.0, 74.221_927_72),
            (0.5, 10.0, 9.341_817_766),
        ];
        for (p, k, want) in cases {
            let q = chi2_quantile(p, k).unwrap();
            assert!(close(q, want, 1e-8), "χ²_{p}({k}) = {q}, want {want}");
        }
        // Two degrees of freedom: F(x) = 1 − e^{−x/2}, so F⁻¹(p) = −2 ln(1 − p).
        for p in [0.001, 0.3, 0.95, 0.999_999] {
            let want = -2.0 * (1.0f64 - p).ln();
            assert!(close(chi2_quantile(p, 2.0).unwrap(), want, 1e-10), "{p}");
        }
        // The round trip, both branches of P(a, x), a large dof.
        for k in [1.0, 3.0, 30.0, 3000.0] {
            for p in [0.025, 0.5, 0.975] {
                let q = chi2_quantile(p, k).unwrap();
                assert!((chi2_cdf(q, k) - p).abs() < 1e-10, "{k} {p}");
            }
        }
        assert!(chi2_quantile(0.0, 3.0).is_none() && chi2_quantile(0.5, 0.0).is_none());
        assert!(close(
            ln_gamma(0.5),
            std::f64::consts::PI.sqrt().ln(),
            1e-13
        ));
        assert!(close(ln_gamma(10.0), 362_880f64.ln(), 1e-13));
    }

    #[test]
    fn the_nis_mean_interval_narrows_around_the_dof() {
        let (lo1, hi1) = nis_mean_interval(1, 3.0, 0.95).unwrap();
        assert!(close(lo1, 0.215_795_283, 1e-8) && close(hi1, 9.348_403_604, 1e-8));
        let (lo, hi) = nis_mean_interval(100, 3.0, 0.95).unwrap();
        // χ²(300): mean 300, σ √600 ≈ 24.5, so about 3 ± 0.48.
        assert!(lo > 2.5 && lo < 2.6 && hi > 3.45 && hi < 3.55, "{lo} {hi}");
        assert!(nis_mean_interval(0, 3.0, 0.95).is_none());
    }

    #[test]
    fn the_bias_envelope_relaxes_from_turn_on_to_instability() {
        // At t = 0 the turn-on σ; after many τ the instability σ; at
        // t = τ/2 the variance is halfway in e^{−1}.
        assert!(close(bias_prior_sd(10.0, 2.0, 3600.0, 0.0), 10.0, 1e-12));
        assert!(close(bias_prior_sd(10.0, 2.0, 3600.0, 1e6), 2.0, 1e-12));
        let e = (-1.0f64).exp();
        let want = (100.0 * e + 4.0 * (1.0 - e)).sqrt();
        assert!(close(bias_prior_sd(10.0, 2.0, 3600.0, 1800.0), want, 1e-12));
        // No correlation time: the instability alone.
        assert!(close(bias_prior_sd(10.0, 2.0, 0.0, 5.0), 2.0, 1e-12));
    }

    #[test]
    fn gaps_and_the_drift_through_them() {
        let mut t: Vec<f64> = (0..50).map(|k| 0.1 * k as f64).collect();
        t.extend((0..20).map(|k| 10.0 + 0.1 * k as f64));
        t.push(12.1); // one lost fix (0.2 s): not a gap
        let g = find_gaps(&t);
        assert_eq!(g.len(), 1);
        assert!(close(g[0].0, 4.9, 1e-12) && close(g[0].1, 10.0, 1e-12));
        // σ grows through the gap and falls after the first fix.
        let sig: Vec<(f64, f64)> = (0..130)
            .map(|k| {
                let t = 0.1 * k as f64;
                (
                    t,
                    if t > 4.9 && t < 10.0 {
                        0.5 + 0.3 * (t - 4.9)
                    } else {
                        0.5
                    },
                )
            })
            .collect();
        let (a, b) = drift_through(&sig, g[0].0, g[0].1).unwrap();
        // The peak is the last epoch before the fix at 10 s: 0.5 + 0.3 × 5.0.
        assert!(close(a, 0.5, 1e-12) && close(b, 2.0, 1e-9), "{a} {b}");
        assert!(drift_through(&sig, -5.0, -1.0).is_none());
    }

    fn fixes(n: usize, rejected: usize, down: usize, nis: f64) -> FixEvidence {
        FixEvidence {
            fixes: n,
            rejected,
            down_weighted: down,
            nis: vec![nis; n - rejected],
            median_fix_h_sd_m: 1.0,
        }
    }

    fn graded<'a>(v: &'a Verdict, name: &str) -> &'a Check {
        v.checks.iter().find(|c| c.name == name).unwrap()
    }

    #[test]
    fn the_verdict_is_the_worst_check() {
        // A consistent run: NIS mean 3, nothing rejected, σ below the fixes'.
        let good = Evidence {
            fixes: Some(fixes(600, 0, 3, 3.0)),
            final_h_sd_m: Some(0.8),
            time_offset_sd_s: Some(0.2e-3),
            ..Evidence::default()
        };
        let v = assess(&good);
        assert_eq!(v.grade, Grade::Good, "{v:#?}");
        assert_eq!(v.grade.words(), "good");

        // 2 % rejected: caution; 10 %: poor.
        let mut e = good.clone();
        e.fixes = Some(fixes(600, 12, 0, 3.0));
        assert_eq!(assess(&e).grade, Grade::Caution);
        e.fixes = Some(fixes(600, 60, 0, 3.0));
        let v = assess(&e);
        assert_eq!(v.grade, Grade::Poor);
        assert_eq!(graded(&v, "GNSS fixes rejected").grade, Some(Grade::Poor));

        // NIS mean: 3.6 over 600 fixes is outside χ²(1800)/600 (≈ 2.80 … 3.20).
        let mut e = good.clone();
        e.fixes = Some(fixes(600, 0, 0, 3.6));
        let v = assess(&e);
        assert_eq!(graded(&v, "NIS mean").grade, Some(Grade::Caution), "{v:#?}");
        // …but inside it over 10 fixes (≈ 1.6 … 4.6).
        e.fixes = Some(fixes(10, 0, 0, 3.6));
        assert_eq!(graded(&assess(&e), "NIS mean").grade, Some(Grade::Good));
        e.fixes = Some(fixes(600, 0, 0, 12.0));
        assert_eq!(assess(&e).grade, Grade::Poor);
        e.fixes = Some(fixes(600, 0, 0, 1.0));
        assert_eq!(graded(&assess(&e), "NIS mean").grade, Some(Grade::Caution));

        // The final σ against the fixes' σ.
        let mut e = good.clone();
        e.final_h_sd_m = Some(2.0);
        assert_eq!(assess(&e).grade, Grade::Caution);
        e.final_h_sd_m = Some(6.0);
        assert_eq!(assess(&e).grade, Grade::Poor);

        // A bias outside 3σ of the datasheet: caution, named.
        let mut e = good.clone();
        e.biases = vec![
            BiasCheck {
                axis: "gyro z".into(),
                unit: "deg/h",
                center: 0.0,
                init_sd: 10.0,
                instability_sd: 10.0,
                corr_time_s: 3600.0,
                final_estimate: 35.0,
                final_sd: 10.0,
                max_sigmas: 3.5,
            },
            BiasCheck {
                axis: "accel x".into(),
                unit: "mGal",
                center: 0.0,
                init_sd: 100.0,
                instability_sd: 100.0,
                corr_time_s: 3600.0,
                final_estimate: 50.0,
                final_sd: 100.0,
                max_sigmas: 0.9,
            },
        ];
        let v = assess(&e);
        assert_eq!(v.grade, Grade::Caution);
        assert!(
            graded(&v, "IMU biases vs datasheet")
                .finding
                .contains("gyro z (3.5σ)")
        );

        // Synchronization: a 20 ms time-offset σ fails the 10 ms requirement.
        let mut e = good.clone();
        e.time_offset_sd_s = Some(20e-3);
        assert_eq!(assess(&e).grade, Grade::Poor);
        e.time_offset_sd_s = None;
        e.sync = Some(SyncEvidence {
            imu_loss_fraction: Some(1e-4),
            max_stamp_bound_us: Some(50.0),
            max_imu_gap_s: Some(0.02),
        });
        assert_eq!(assess(&e).grade, Grade::Caution);

        // An alignment that never saw motion leaves heading unknown.
        let mut e = good.clone();
        e.alignment = Some(AlignEvidence {
            method: "no-motion".into(),
            time_sow: 1.0,
            yaw_sd_deg: 180.0,
            note: String::new(),
        });
        assert_eq!(assess(&e).grade, Grade::Caution);

        // Information only does not grade; no evidence at all is a caution.
        let e = Evidence {
            worst_gap: Some((30.0, 12.0)),
            ..Evidence::default()
        };
        let v = assess(&e);
        assert_eq!(v.grade, Grade::Caution);
        assert_eq!(graded(&v, "worst GNSS gap").grade, None);
    }

    /// A smoothed file that left the fixes (a slow robot: forward 0.78 m,
    /// smoothed 1 643 m) is poor whatever the forward statistics say; one
    /// as close as the forward filter is good; a forward-only file far off
    /// the fixes is poor; absurd speeds and σ are poor.
    #[test]
    fn the_written_file_is_judged_as_written() {
        use crate::written::WrittenEvidence;
        let base = WrittenEvidence {
            fixes_compared: 989,
            fixes_total: 989,
            rms_vs_fixes_m: 0.5,
            median_fix_sd_h_m: 1.27,
            forward_rms_vs_fixes_m: Some(0.78),
            max_speed_mps: 1.7,
            max_fix_speed_mps: 2.0,
            max_sd_h_m: Some(0.9),
        };
        let grade = |w: WrittenEvidence| {
            let e = Evidence {
                fixes: Some(fixes(600, 0, 3, 3.0)),
                final_h_sd_m: Some(0.8),
                written: Some(w),
                ..Evidence::default()
            };
            assess(&e).grade
        };
        assert_eq!(grade(base.clone()), Grade::Good);
        let diverged = WrittenEvidence {
            rms_vs_fixes_m: 1643.0,
            max_speed_mps: 121.0,
            max_sd_h_m: Some(33_000.0),
            ..base.clone()
        };
        assert_eq!(grade(diverged), Grade::Poor);
        // Three times the forward filter's distance and beyond the fixes'
        // σ twice over: poor even while still near the fixes.
        let drifted = WrittenEvidence {
            rms_vs_fixes_m: 3.5,
            ..base.clone()
        };
        assert_eq!(grade(drifted), Grade::Poor);
        let slightly = WrittenEvidence {
            rms_vs_fixes_m: 2.2,
            ..base.clone()
        };
        assert_eq!(grade(slightly), Grade::Caution);
        // RTK: 2 cm against 1 cm is within the fixes' σ: not a divergence.
        let rtk = WrittenEvidence {
            rms_vs_fixes_m: 0.02,
            forward_rms_vs_fixes_m: Some(0.01),
            median_fix_sd_h_m: 0.028,
            ..base.clone()
        };
        assert_eq!(grade(rtk), Grade::Good);
        let forward_far = WrittenEvidence {
            rms_vs_fixes_m: 40.0,
            forward_rms_vs_fixes_m: None,
            ..base.clone()
        };
        assert_eq!(grade(forward_far), Grade::Poor);
        let fast = WrittenEvidence {
            max_speed_mps: 13.7,
            ..base
        };
        assert_eq!(grade(fast), Grade::Poor);
    }
}
