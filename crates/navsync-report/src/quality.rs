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
    // The σ just after the last fix before the gap, its update applied
    // (the epoch at or before it still has the prediction).
    let before = sigma_h
        .iter()
        .find(|(t, _)| *t > start && *t < end)
        .or_else(|| sigma_h.iter().rev().find(|(t, _)| *t <= start))?
        .1;
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
    /// The likely causes of the checks that failed: those of the worst
    /// checks first, the most specific first within a grade (not in the
    /// page's JSON block, whose format is fixed: FORMATS.md).
    #[serde(skip)]
    pub causes: Vec<String>,
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
    /// The integrity monitor's fault episodes (`reason` column).
    pub faults: FaultEvidence,
}

/// What the integrity monitor found (navsync's `fusion::aid::integrity`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct FaultEvidence {
    /// Fault episodes (jumps that opened one, runs of stale outputs).
    pub episodes: usize,
    /// Fixes excluded in them.
    pub excluded: usize,
    /// Fixes used again after an episode the INS could not resolve.
    pub persisted: usize,
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
    /// Gravity's share of the envelope ([`gravity_coupling_sd`]), in
    /// `unit`; σ(t) is √(bias_prior_sd² + cross_sd²).
    pub cross_sd: f64,
    /// The specific force (mGal) the axis's estimated scale factor
    /// multiplies in the judged estimate b̂ + ŝ·f: gravity's on an
    /// accelerometer axis, 0 for a gyro (`sections::bias_checks`).
    pub scale_force_mgal: f64,
}

/// Standard gravity in mGal (1 mGal = 1e-5 m/s²).
pub(crate) const G_MGAL: f64 = 9.806_65e5;

/// The σ (mGal) of what gravity puts on accelerometer `axis` through the
/// triad's axis misalignment (σ `misalign_sd_rad` per off-diagonal term)
/// and the axis's scale factor (σ `scale_sd_ppm`), with gravity along the
/// unit vector `down_b` in the IMU's axes: f_i = Σ_j M_ij g_j, so
/// σ² = g² (σ_m² Σ_{j≠i} u_j² + σ_s² u_i²) (the sensor model of Groves
/// 2013, §4.4.5, eq. 4.16). A bias state absorbs both while the attitude
/// stays near its usual tilt: a level ADIS16465 (0.05° misalignment) puts
/// 856 mGal on its x and y axes against a 100 mGal turn-on bias σ.
pub(crate) fn gravity_coupling_sd(
    down_b: [f64; 3],
    axis: usize,
    misalign_sd_rad: f64,
    scale_sd_ppm: f64,
) -> f64 {
    let u_i2 = down_b.get(axis).map_or(0.0, |u| u * u).min(1.0);
    let m = misalign_sd_rad.max(0.0);
    let s = scale_sd_ppm.max(0.0) * 1e-6;
    G_MGAL * (m * m * (1.0 - u_i2) + s * s * u_i2).sqrt()
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
    /// The first fixes after the gaps against the forward filter's σ.
    pub gap_ends: Option<crate::gap_ends::GapEndEvidence>,
    /// The written file against the fixes and the forward pass.
    pub written: Option<crate::written::WrittenEvidence>,
    /// Why the solution file is incomplete (a cut last line, or it ends
    /// before summary.json's last solution), if it is.
    pub solution_incomplete: Option<String>,
    /// The innovations against the lever-arm and time-offset signatures.
    pub innovation: Option<crate::innovation::InnovationEvidence>,
    /// The configured antenna lever arm (summary.json), FRD (m).
    pub antenna_lever_m: Option<[f64; 3]>,
    /// The consistency probe's estimates (`probe.json` of `navsync
    /// process`).
    pub probe: Option<ProbeEvidence>,
    /// The lever-arm states' estimate (summary.json), when they ran.
    pub lever_estimate: Option<navsync::fusion::LeverArmSummary>,
}

/// What the consistency probe (a second pass with the time offset
/// estimated as a state, `navsync::probe`) found.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct ProbeEvidence {
    /// The time offset (GNSS tag − validity, s) and its σ.
    pub time_offset_s: Option<(f64, f64)>,
    /// The lever-arm states' estimate against the sheet.
    pub lever_arm: Option<navsync::fusion::LeverArmSummary>,
    /// Why the probe failed, when it did (its filter broke down).
    pub failed: Option<String>,
}

/// A probe estimate is significant beyond this many σ (0.27 % by chance).
pub(crate) const PROBE_SIGMAS: f64 = 3.0;

/// Rejected fixes: a consistent filter gates at 99.99 % (or IGG-III k1 =
/// 10σ), so chance rejections are ~1e-4; above 1 % the receiver had real
/// faults (or the INS diverged), above 5 % for long stretches.
pub(crate) const REJECTED_CAUTION: f64 = 0.01;
pub(crate) const REJECTED_POOR: f64 = 0.05;
/// Fixes excluded in fault episodes the INS bridged: a good solution
/// still, but past a quarter of the fixes it rests on the INS for long
/// stretches and the receiver or antenna needs a look.
pub(crate) const FAULT_EXCLUDED_CAUTION: f64 = 0.25;
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
/// A NIS mean within this factor of its expected value (σ figures right
/// within √2) is good even outside the χ² interval: a datasheet's figures
/// and a receiver's σ are not known better, and a GNSS error correlated
/// over tens of seconds (RTK multipath) lifts the mean by some 20 % on a
/// consistent filter.
pub(crate) const NIS_TOLERANCE: f64 = 2.0;
/// An unmodelled error that makes the solution this many times worse than
/// the filter's σ: caution, poor.
pub(crate) const LOSS_CAUTION: f64 = 2.0;
pub(crate) const LOSS_POOR: f64 = 5.0;
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

/// The lag-`k` autocorrelation of `x` (0 for fewer than k + 2 values or
/// no spread).
pub(crate) fn autocorrelation(x: &[f64], k: usize) -> f64 {
    if x.len() < k + 2 {
        return 0.0;
    }
    let m = x.iter().sum::<f64>() / x.len() as f64;
    let var: f64 = x.iter().map(|v| (v - m).powi(2)).sum();
    if var.is_nan() || var <= 0.0 {
        return 0.0;
    }
    x[k..]
        .iter()
        .zip(x)
        .map(|(a, b)| (a - m) * (b - m))
        .sum::<f64>()
        / var
}

/// The lag-1 autocorrelation of `x`.
pub(crate) fn lag1_autocorrelation(x: &[f64]) -> f64 {
    autocorrelation(x, 1)
}

/// How many independent values a correlated sequence `x` is worth:
/// n / τ with the integrated autocorrelation time τ = 1 + 2 Σ ρ_k, summed
/// over pairs ρ_{2m−1} + ρ_{2m} while they stay positive (Geyer's initial
/// positive sequence, "Practical Markov chain Monte Carlo", Statistical
/// Science 1992, §3.3), up to lag n/4. A GNSS error correlated over a
/// minute makes 1 Hz fixes worth far fewer than their count.
pub(crate) fn effective_count(x: &[f64]) -> f64 {
    let n = x.len();
    let mut tau = 1.0;
    let mut k = 1;
    while k < n / 4 {
        let pair = autocorrelation(x, k) + autocorrelation(x, k + 1);
        if pair.is_nan() || pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        k += 2;
    }
    (n as f64 / tau).clamp(1.0_f64.min(n as f64), n as f64)
}

/// The NIS mean against χ² with the fixes' correlation taken into account,
/// and which way the σ figures are off.
fn nis_check(nis: &[f64], checks: &mut Vec<Check>, causes: &mut Causes) {
    let n = nis.len();
    if n == 0 {
        return;
    }
    let mean = nis.iter().sum::<f64>() / n as f64;
    // Correlated NIS values are fewer independent ones
    // ([`effective_count`]), for the interval only.
    let rho = lag1_autocorrelation(nis);
    let n_eff = effective_count(nis);
    let a = 0.5 * (1.0 - NIS_CONF);
    let k = n_eff * POSITION_DOF;
    let (Some(lo), Some(hi)) = (chi2_quantile(a, k), chi2_quantile(1.0 - a, k)) else {
        return;
    };
    let (lo, hi) = (lo / n_eff, hi / n_eff);
    let poor = NIS_MEAN_POOR_FACTOR * POSITION_DOF;
    let tol_hi = NIS_TOLERANCE * POSITION_DOF;
    let tol_lo = POSITION_DOF / NIS_TOLERANCE;
    // White innovations (lag-1 autocorrelation inside ±3/√n, Bartlett's
    // σ of a white sequence's autocorrelation) are the fixes' own noise;
    // correlated ones grow between fixes: the INS's drift.
    let white = rho < 3.0 / (n as f64).sqrt();
    let which_small = if white {
        "the fixes' stated σ are too small (innovations white: the fixes' own noise)"
    } else {
        "the innovations are correlated from fix to fix: something drifts between fixes that the filter does not model as it is: IMU noise figures too optimistic (a better IMU's than the data's), or an unestimated GNSS time offset or lever-arm error the signatures below could not separate on this drive"
    };
    let (grade, how) = if mean > poor {
        (
            Grade::Poor,
            format!("the filter's σ understate the errors: {which_small}"),
        )
    } else if mean > hi && mean > tol_hi {
        (
            Grade::Caution,
            format!("σ figures optimistic: {which_small}"),
        )
    } else if mean < lo && mean < tol_lo {
        (
            Grade::Caution,
            "σ figures pessimistic: the fixes' stated σ (or the IMU noise figures) are larger than the errors".to_string(),
        )
    } else if mean > hi || mean < lo {
        (
            Grade::Good,
            format!(
                "outside the interval but within a factor {NIS_TOLERANCE} of {POSITION_DOF:.0}: σ right within √{NIS_TOLERANCE}"
            ),
        )
    } else {
        (Grade::Good, "consistent".to_string())
    };
    if grade > Grade::Good {
        causes.add(grade, format!("noise figures: {how}"));
    }
    checks.push(Check {
        name: "NIS mean",
        grade: Some(grade),
        finding: format!(
            "{mean:.2} over {n} fixes (lag-1 autocorrelation {rho:.2}, {n_eff:.0} independent; expected {POSITION_DOF:.0}, 95 % interval {lo:.2} … {hi:.2}): {how}"
        ),
        rule: format!(
            "good inside the interval χ²(3n′)/n′ (n′ fixes after the reduction for autocorrelation) or within a factor {NIS_TOLERANCE} of 3; poor above {poor:.0}; caution otherwise"
        ),
    });
}

/// The forward σ through GNSS gaps, tested at their ends
/// ([`crate::gap_ends`]): a caution when a gap's end is past χ²₂ at 1 %
/// over the run and the fix after it confirms the INS drifted. Graded
/// only when the written file is the forward filter's.
fn gap_end_check(
    e: &crate::gap_ends::GapEndEvidence,
    checks: &mut Vec<Check>,
    causes: &mut Causes,
) {
    let grade = if e.exceeded > 0 {
        Grade::Caution
    } else {
        Grade::Good
    };
    let whose = if e.written_is_forward {
        ""
    } else {
        " (the forward pass; the smoothed σ written are not tested by it)"
    };
    let finding = match e.worst() {
        Some(w) => format!(
            "{} of {} gap ends past the predicted σ{whose}; worst after the {:.1} s gap ending at SOW {:.1}: the first fix {:.2} m from the prediction, σ {:.2} m (NEES {:.1}), and the fix after it agreed",
            e.exceeded, e.tested, w.gap_s, w.sow, w.offset_h_m, w.filter_sd_h_m, w.nees
        ),
        None => format!("{} gap ends within the predicted σ{whose}", e.tested),
    };
    checks.push(Check {
        name: "σ through GNSS gaps",
        grade: e.written_is_forward.then_some(grade),
        finding,
        rule: format!(
            "caution when the first fix after a gap is past χ²₂ at {:.0} % false alarms over the {} gap ends tested (NEES > {:.1}) and the next fix confirms the INS drifted",
            crate::gap_ends::FAMILY_FALSE_ALARM * 100.0,
            e.tested,
            e.threshold
        ),
    });
    if !e.written_is_forward {
        return;
    }
    for w in [e.worst_drift, e.worst_entry].into_iter().flatten() {
        let growth = w.filter_sd_h_m / w.start_sd_h_m;
        let why = if w.drifted_through_gap() {
            format!(
                "σ grew ×{growth:.1} through the gap, so the INS drifted past its model: the IMU has errors the model leaves out, in turns most often the axis misalignment (fuse --misalignment with the datasheet's figure estimates it)"
            )
        } else {
            format!(
                "σ hardly grew through the gap (×{growth:.1}), so the position entering it was off: the fixes before the gap had errors correlated in time (float solutions, multipath) that their stated σ treat as independent"
            )
        };
        causes.add(
            Grade::Caution,
            format!(
                "σ through GNSS gaps understated: after the {:.1} s gap ending at SOW {:.1} the solution was {:.2} m off where its σ said {:.2} m ({:.1}σ); {why}. Positions in and after gaps are worse than their σ; a smoothed run (--smooth) bridges gaps from both ends",
                w.gap_s,
                w.sow,
                w.offset_h_m,
                w.filter_sd_h_m,
                w.offset_h_m / w.filter_sd_h_m.max(1e-9)
            ),
        );
    }
}

/// The GNSS fault episodes (docs/integrity.md). Excluded faults cost
/// nothing when the INS bridged them; an episode that ended with the
/// fixes followed again (the INS's drift covered the offset, or it lasted
/// longer than the IMU can bridge) may have moved the solution.
fn fault_check(f: &FaultEvidence, fixes: usize, checks: &mut Vec<Check>, causes: &mut Causes) {
    let share = f.excluded as f64 / fixes.max(1) as f64;
    let grade = if f.persisted > 0 {
        causes.add(Grade::Caution, format!(
            "GNSS faults: {} fix(es) used again after a fault episode the INS could not resolve; the solution around them may follow the fault (gnss_residuals.txt, reason `persisted`)",
            f.persisted
        ));
        Grade::Caution
    } else if share > FAULT_EXCLUDED_CAUTION {
        causes.add(Grade::Caution, format!(
            "GNSS faults: {} of the fixes were excluded in fault episodes; the solution there rests on the INS alone: check the receiver and antenna (gnss_residuals.txt, reasons `jump`, `run`, `stale`)",
            pct(share)
        ));
        Grade::Caution
    } else {
        Grade::Good
    };
    checks.push(Check {
        name: "GNSS fault episodes",
        grade: Some(grade),
        finding: format!(
            "{} episode(s), {} fix(es) excluded ({}), {} used again after persisting",
            f.episodes,
            f.excluded,
            pct(share),
            f.persisted
        ),
        rule: format!(
            "good when every episode was bridged by the INS (the fixes came back); caution when fixes were followed again after an episode it could not resolve, or when episodes excluded more than {} of the fixes",
            pct(FAULT_EXCLUDED_CAUTION)
        ),
    });
}

/// A zero antenna lever arm is almost never the rig's: it is the sheet's
/// default, left unmeasured. Every centimetre of it goes into the position
/// and the filter cannot see it on a drive without varied turns.
fn lever_arm_checks(ev: &Evidence, checks: &mut Vec<Check>, causes: &mut Causes) {
    let Some(l) = ev.antenna_lever_m else { return };
    let zero = l.iter().all(|x| *x == 0.0);
    if let Some(est) = &ev.lever_estimate {
        estimated_lever_check(est, zero, checks, causes);
        return;
    }
    checks.push(Check {
        name: "antenna lever arm",
        grade: Some(if zero { Grade::Caution } else { Grade::Good }),
        finding: if zero {
            "[0, 0, 0] in the configuration: unmeasured? The lever arm goes straight into the position (a 0.5 m antenna offset is a 0.5 m error); if the antenna really is within a few cm of the IMU, this caution can be ignored".into()
        } else {
            format!("[{:.3}, {:.3}, {:.3}] m (forward, right, down)", l[0], l[1], l[2])
        },
        rule: "caution when zero (the sheet's default, not a measurement)".into(),
    });
    if zero {
        causes.add(
            Grade::Caution,
            "antenna lever arm: zero in the sheet (antenna_lever_m), measure it (or estimate it on a drive with turns: estimate_lever_arm: true)",
        );
    }
}

/// The lever-arm states ran: the sheet's value was a prior, and what
/// counts is whether the drive observed the horizontal components (their
/// σ fell below half the initial one). An estimate the drive did not
/// observe is not praised: with a zero sheet it stays a caution, else it
/// is shown ungraded.
fn estimated_lever_check(
    est: &navsync::fusion::LeverArmSummary,
    zero_sheet: bool,
    checks: &mut Vec<Check>,
    causes: &mut Causes,
) {
    let horizontal = est.observed[0] && est.observed[1];
    let grade = match (horizontal, zero_sheet) {
        (true, _) => Some(Grade::Good),
        (false, true) => Some(Grade::Caution),
        (false, false) => None,
    };
    checks.push(Check {
        name: "antenna lever arm",
        grade,
        finding: format!(
            "estimated as filter states{}: {}",
            if zero_sheet { " from a zero sheet value" } else { "" },
            est.note
        ),
        rule: format!(
            "good when the drive observed the horizontal components (σ below {:.0} % of the initial σ); \
             a zero sheet value the drive did not observe stays a caution",
            navsync::fusion::LEVER_OBSERVED_FRACTION * 100.0
        ),
    });
    if grade == Some(Grade::Caution) {
        causes.add(
            Grade::Caution,
            "antenna lever arm: zero in the sheet (antenna_lever_m) and the drive did not observe it \
             (too few turns for the lever-arm states): measure it",
        );
    }
}

/// The loss of accuracy an unmodelled error `e_m` adds to a solution of
/// σ `sd_m`: √(1 + (e/σ)²).
pub(crate) fn loss_factor(e_m: f64, sd_m: f64) -> f64 {
    (1.0 + (e_m / sd_m.max(1e-6)).powi(2)).sqrt()
}

/// The lever-arm and time-offset signatures of the innovations
/// ([`crate::innovation`]): present at the false-alarm rate, and graded by
/// the accuracy they cost against what the filter claims.
fn signature_checks(
    e: &crate::innovation::InnovationEvidence,
    lever_estimated: bool,
    checks: &mut Vec<Check>,
    causes: &mut Causes,
) {
    use crate::innovation::FALSE_ALARM;
    let rule = format!(
        "present when its F test passes at a {:.0} % false-alarm rate; then caution when the error it implies costs more than {LOSS_CAUTION}× the filter's σ (√(1 + (e/σ)²)), poor above {LOSS_POOR}×",
        FALSE_ALARM * 100.0
    );
    let grade = |p: f64, err: f64| cost_grade(p < FALSE_ALARM, loss_factor(err, e.filter_h_sd_m));
    let [df, dr] = e.lever_error_fr_m;
    let g = grade(e.lever_p, e.lever_error_m());
    checks.push(Check {
        name: "innovations vs heading (lever arm)",
        grade: Some(g),
        finding: format!(
            "{} (p = {:.1e} over {} fixes, {:.0} independent): the antenna looks {:+.3} m forward, {:+.3} m right of where the sheet puts it, {:.3} m against the filter's σ {:.3} m",
            if e.lever_p < FALSE_ALARM { "present" } else { "not present" },
            e.lever_p,
            e.fixes,
            e.effective_fixes,
            df,
            dr,
            e.lever_error_m(),
            e.filter_h_sd_m
        ),
        rule: rule.clone(),
    });
    if g > Grade::Good {
        let remedy = if lever_estimated {
            "The lever-arm states ran and did not absorb it: a lever arm that changes (a moving antenna) or another error that turns with the heading (IMU mounting yaw)"
        } else {
            "Measure it, or let the filter estimate it: lever-arm states (`estimate_lever_arm: true` in the sheet, `--estimate-lever-arm`) would help on a drive with turns like this one"
        };
        causes.add(g, format!(
            "antenna lever arm: the innovations turn with the heading; the antenna looks about {df:+.2} m forward, {dr:+.2} m right of the sheet's antenna_lever_m (an underestimate: the filter absorbs part of it). {remedy}. At a steady speed a GNSS time offset looks the same along the track (v·δt): if the lever arm is right, estimate the offset (time_offset: estimate: true)"
        ));
    }
    let g = grade(e.offset_p, e.offset_error_m());
    checks.push(Check {
        name: "innovations vs speed (time offset)",
        grade: Some(g),
        finding: format!(
            "{} (p = {:.1e}): GNSS tags look {:+.1} ms late, {:.3} m at the RMS speed {:.1} m/s against the filter's σ {:.3} m",
            if e.offset_p < FALSE_ALARM { "present" } else { "not present" },
            e.offset_p,
            e.offset_s * 1e3,
            e.offset_error_m(),
            e.speed_rms_mps,
            e.filter_h_sd_m
        ),
        rule,
    });
    if g > Grade::Good {
        causes.add(g, format!(
            "GNSS time offset: the innovations grow with the speed along the track; the tags look {:+.0} ms late. Estimate it (sheet: time_offset: estimate: true; fuse --estimate-time-offset) or synchronize with 1PPS",
            e.offset_s * 1e3
        ));
    }
}

/// The consistency probe's estimates against the sheet, graded as the
/// signatures are: significant beyond [`PROBE_SIGMAS`], then by the
/// accuracy the error costs against the filter's σ (the speed and σ of
/// the innovation evidence).
fn probe_checks(
    p: &ProbeEvidence,
    e: &crate::innovation::InnovationEvidence,
    checks: &mut Vec<Check>,
    causes: &mut Causes,
) {
    if let Some(why) = &p.failed {
        checks.push(Check {
            name: "time offset (probe)",
            grade: Some(Grade::Caution),
            finding: format!("the second pass, with the time offset as a state, failed: {why}"),
            rule: "caution when the probe's filter broke down: the data do not fit the sheet's model even with the offset free".into(),
        });
        causes.add(Grade::Caution, format!(
            "consistency probe: a filter estimating the GNSS time offset broke down on these data ({why}): check the fixes' σ and the IMU figures"
        ));
        return;
    }
    if let Some(l) = &p.lever_arm {
        probe_lever_check(l, e, checks, causes);
    }
    let Some((offset_s, sd_s)) = p.time_offset_s else {
        return;
    };
    let inflate = correlation_inflation(e);
    let significant = offset_s.abs() > PROBE_SIGMAS * sd_s * inflate;
    let err_m = offset_s.abs() * e.speed_rms_mps;
    let loss = loss_factor(err_m, e.filter_h_sd_m);
    let grade = cost_grade(significant, loss);
    checks.push(Check {
        name: "time offset (probe)",
        grade: Some(grade),
        finding: format!(
            "a second pass estimating it as a state finds GNSS tags {:+.1} ms ± {:.1} ms (×{inflate:.2} for correlated fixes) late ({}): {:.3} m at the RMS speed {:.1} m/s against the filter's σ {:.3} m ({loss:.1}×)",
            offset_s * 1e3,
            sd_s * 1e3,
            if significant { "significant" } else { "not significant" },
            err_m,
            e.speed_rms_mps,
            e.filter_h_sd_m
        ),
        rule: format!(
            "significant beyond {PROBE_SIGMAS:.0}σ (σ × √(fixes / independent fixes)); then caution when the error costs more than {LOSS_CAUTION}× the filter's σ (√(1 + (e/σ)²)), poor above {LOSS_POOR}×"
        ),
    });
    if grade > Grade::Good {
        causes.add(grade, format!(
            "GNSS time offset: with the offset estimated as a state the GNSS tags are {:+.0} ± {:.0} ms late, which the run's sheet assumes zero. Estimate it (sheet: time_offset: estimate: true; fuse --estimate-time-offset) or synchronize with 1PPS",
            offset_s * 1e3,
            sd_s * 1e3
        ));
    }
}

/// An error found (`significant`) is graded by its accuracy loss
/// √(1 + (e/σ)²): caution above [`LOSS_CAUTION`], poor above
/// [`LOSS_POOR`]; one not found is good whatever its size.
fn cost_grade(significant: bool, loss: f64) -> Grade {
    if significant {
        grade_of(loss, LOSS_CAUTION, LOSS_POOR)
    } else {
        Grade::Good
    }
}

/// The probe's σ assume white fix errors; errors correlated from fix to
/// fix carry the information of fewer fixes, n′ of n (the NIS's
/// integrated autocorrelation, [`crate::innovation`]), and a parameter
/// estimated from them is √(n/n′) less certain (Bartlett 1946; the same
/// count the NIS check uses).
fn correlation_inflation(e: &crate::innovation::InnovationEvidence) -> f64 {
    (e.fixes as f64 / e.effective_fixes.max(1.0))
        .sqrt()
        .max(1.0)
}

/// The probe's lever-arm estimate against the sheet: significant beyond
/// [`navsync::fusion::LEVER_SIGNIFICANT_SIGMAS`] on a component the drive
/// observed, then graded by the cost of the difference against the
/// filter's σ, as the time offset.
fn probe_lever_check(
    l: &navsync::fusion::LeverArmSummary,
    e: &crate::innovation::InnovationEvidence,
    checks: &mut Vec<Check>,
    causes: &mut Causes,
) {
    let d = [0, 1, 2].map(|k| l.estimate_m[k] - l.sheet_m[k]);
    let horizontal_m = d[0].hypot(d[1]);
    // States the drive did not observe stay within their prior in a
    // consistent filter (the estimate moves by at most √(σ₀² − σ²)); ones
    // that ran further than any antenna can be, observed or not, took up
    // an error the filter does not model (the Husky bag: 28 m forward, its
    // σ held near the initial 0.5 m by the covariance inflations).
    let ran_off = horizontal_m > PLAUSIBLE_LEVER_M;
    // The difference graded: over the observed components, or all of it
    // for states that ran off.
    let difference_m = if ran_off {
        horizontal_m
    } else {
        l.difference_m
    };
    let loss = loss_factor(difference_m, e.filter_h_sd_m);
    let inflate = correlation_inflation(e);
    let sigmas = (0..3)
        .filter(|&k| l.observed[k])
        .map(|k| d[k].abs() / (l.sd_m[k] * inflate).max(1e-9))
        .fold(0.0, f64::max);
    let significant = sigmas > navsync::fusion::LEVER_SIGNIFICANT_SIGMAS || ran_off;
    let grade = cost_grade(significant, loss);
    checks.push(Check {
        name: "antenna lever arm (probe)",
        grade: Some(grade),
        finding: format!(
            "a second pass estimating it as states finds the antenna {:+.3} m forward, {:+.3} m right of the sheet's (σ {:.3}, {:.3} m ×{inflate:.2} for correlated fixes; {}observed: {sigmas:.1}σ, {}): {:.3} m against the filter's σ {:.3} m ({loss:.1}×)",
            d[0],
            d[1],
            l.sd_m[0],
            l.sd_m[1],
            if l.observed[0] || l.observed[1] { "" } else { "not " },
            if ran_off {
                "beyond any antenna"
            } else if significant {
                "significant"
            } else {
                "not significant"
            },
            difference_m,
            e.filter_h_sd_m
        ),
        rule: format!(
            "significant beyond {:.0}σ (σ × √(fixes / independent fixes)) on a component the drive observed, or beyond {PLAUSIBLE_LEVER_M:.0} m horizontally on any; then caution when the difference costs more than {LOSS_CAUTION}× the filter's σ, poor above {LOSS_POOR}×",
            navsync::fusion::LEVER_SIGNIFICANT_SIGMAS
        ),
    });
    if grade > Grade::Good && ran_off {
        causes.add(grade, format!(
            "not the antenna: the probe's lever-arm states ran to {horizontal_m:.0} m from the sheet's, which no antenna is; they absorbed an error the filter does not model. Most often the IMU's mounting (mount_deg: the vehicle's forward axis in the IMU's) or a heading the drive could not observe; then the IMU figures"
        ));
    } else if grade > Grade::Good {
        causes.add(grade, format!(
            "antenna lever arm: with it estimated as states the antenna is {:+.2} m forward, {:+.2} m right of the sheet's antenna_lever_m ({sigmas:.1}σ). Measure it, or estimate it in the run (estimate_lever_arm: true). At a steady speed a forward error and a late GNSS tag look alike: the time-offset row says which the probe preferred",
            d[0], d[1]
        ));
    }
}

/// A probe's lever-arm difference beyond this (m) is no antenna offset:
/// the largest lever-arm σ a sheet may give (an antenna is metres from
/// the IMU at most).
const PLAUSIBLE_LEVER_M: f64 = navsync::pipeline::MAX_LEVER_ARM_SD_M;

/// The likely causes found, each with the grade of the check that
/// raised it.
#[derive(Default)]
struct Causes(Vec<(Grade, String)>);

impl Causes {
    fn add(&mut self, grade: Grade, cause: impl Into<String>) {
        self.0.push((grade, cause.into()));
    }

    /// The causes, those of the worst checks first; in the order they were
    /// found (the most specific first) within a grade.
    fn by_grade(mut self) -> Vec<String> {
        self.0.sort_by_key(|c| std::cmp::Reverse(c.0));
        self.0.into_iter().map(|(_, c)| c).collect()
    }
}

/// Weighs the evidence.
pub(crate) fn assess(ev: &Evidence) -> Verdict {
    let mut checks = Vec::new();
    let mut causes = Causes::default();
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
        // Fixes excluded in fault episodes are graded by the episodes'
        // check: the INS bridged them or it says it could not.
        let rejected = f.rejected.saturating_sub(f.faults.excluded);
        let rej = rejected as f64 / n;
        checks.push(Check {
            name: "GNSS fixes rejected",
            grade: Some(grade_of(rej, REJECTED_CAUTION, REJECTED_POOR)),
            finding: if f.faults.excluded > 0 {
                format!(
                    "{rejected} of {} position fixes ({}) outside fault episodes; {} more excluded in them (below)",
                    f.fixes,
                    pct(rej),
                    f.faults.excluded
                )
            } else {
                format!("{rejected} of {} position fixes ({})", f.fixes, pct(rej))
            },
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
        fault_check(&f.faults, f.fixes, &mut checks, &mut causes);
        nis_check(&f.nis, &mut checks, &mut causes);
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
    lever_arm_checks(ev, &mut checks, &mut causes);
    if let Some(e) = &ev.innovation {
        signature_checks(e, ev.lever_estimate.is_some(), &mut checks, &mut causes);
        if let Some(p) = &ev.probe {
            probe_checks(p, e, &mut checks, &mut causes);
        }
    }
    if let Some(bias_grade) = checks
        .iter()
        .filter(|c| c.name == "IMU biases vs datasheet")
        .filter_map(|c| c.grade)
        .max()
        .filter(|g| *g > Grade::Good)
    {
        causes.add(
            bias_grade,
            "IMU biases outside the datasheet envelope: the IMU is not the one the sheet describes, or the biases absorb another error (lever arm, time offset, mounting)",
        );
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
        let grade = grade_of(sd, SYNC_GOOD_S, SYNC_POOR_S);
        checks.push(Check {
            name: "time-offset σ",
            grade: Some(grade),
            finding: format!("{:.3} ms", sd * 1e3),
            rule: "good ≤ 1 ms, poor > 10 ms".into(),
        });
        if grade > Grade::Good {
            // The offset is seen as v·δt along the track: its σ costs
            // that much position at the drive's speed.
            let along = ev
                .innovation
                .as_ref()
                .map(|e| {
                    format!(
                        " ({:.2} m along the track at the RMS speed {:.1} m/s)",
                        sd * e.speed_rms_mps,
                        e.speed_rms_mps
                    )
                })
                .unwrap_or_default();
            causes.add(
                grade,
                format!(
                    "GNSS time offset poorly determined: the run estimated it with σ {:.1} ms{along}; it shows only as v·δt along the track, which the fixes' errors hide at this drive's speeds. Time the IMU and the receiver on one clock (1PPS: navsync sync), or use fixes of smaller σ",
                    sd * 1e3
                ),
            );
        }
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
    if let Some(e) = &ev.gap_ends {
        gap_end_check(e, &mut checks, &mut causes);
    }
    let grade = checks
        .iter()
        .filter_map(|c| c.grade)
        .max()
        .unwrap_or(Grade::Caution);
    // The verdict always says why: a grade no cause explains is named by
    // the checks that set it.
    if grade > Grade::Good && !causes.0.iter().any(|(g, _)| *g == grade) {
        for c in checks.iter().filter(|c| c.grade == Some(grade)) {
            causes.add(grade, format!("{}: {} ({})", c.name, c.finding, c.rule));
        }
    }
    if checks.iter().all(|c| c.grade.is_none()) {
        checks.push(Check {
            name: "evidence",
            grade: Some(Grade::Caution),
            finding: "nothing to grade: no gnss_residuals.txt, imu_err.txt with summary.json, sync report or time offset".into(),
            rule: "caution without evidence".into(),
        });
    }
    Verdict {
        grade,
        checks,
        causes: causes.by_grade(),
    }
}

#[cfg(test)]
mod tests;
