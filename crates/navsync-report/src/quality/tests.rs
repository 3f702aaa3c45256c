//! Tests of the verdict (`quality`): each rule on built evidence, the
//! calibration examples of issue 34, and the helpers' analytic cases.

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
    // σ grows through the gap and falls after the first fix. The epoch of
    // the last fix before the gap (4.9 s) still carries the prediction
    // (0.9 m); the gap starts from the updated σ.
    let sig: Vec<(f64, f64)> = (0..130)
        .map(|k| {
            let t = 0.1 * k as f64;
            (
                t,
                if (t - 4.9).abs() < 1e-9 {
                    0.9
                } else if t > 4.9 && t < 10.0 {
                    0.5 + 0.3 * (t - 4.9)
                } else {
                    0.5
                },
            )
        })
        .collect();
    let (a, b) = drift_through(&sig, g[0].0, g[0].1).unwrap();
    // The start is the first epoch after the fix at 4.9 s: 0.5 + 0.3 × 0.1;
    // the peak the last epoch before the fix at 10 s: 0.5 + 0.3 × 5.0.
    assert!(close(a, 0.53, 1e-9) && close(b, 2.0, 1e-9), "{a} {b}");
    assert!(drift_through(&sig, -5.0, -1.0).is_none());
}

fn fixes(n: usize, rejected: usize, down: usize, nis: f64) -> FixEvidence {
    FixEvidence {
        fixes: n,
        rejected,
        down_weighted: down,
        nis: vec![nis; n - rejected],
        median_fix_h_sd_m: 1.0,
        faults: FaultEvidence::default(),
    }
}

fn graded<'a>(v: &'a Verdict, name: &str) -> &'a Check {
    v.checks.iter().find(|c| c.name == name).unwrap()
}

/// Fault episodes the INS bridged cost nothing; fixes followed again
/// after one it could not resolve make the run a caution, naming why.
#[test]
fn fault_episodes_are_counted_and_unresolved_ones_graded() {
    let mut f = fixes(600, 12, 0, 3.0);
    f.faults = FaultEvidence {
        episodes: 2,
        excluded: 12,
        persisted: 0,
    };
    let ev = |f: FixEvidence| Evidence {
        fixes: Some(f),
        ..Evidence::default()
    };
    let v = assess(&ev(f.clone()));
    let c = graded(&v, "GNSS fault episodes");
    assert_eq!(c.grade, Some(Grade::Good));
    assert!(
        c.finding.starts_with("2 episode(s), 12 fix(es) excluded"),
        "{}",
        c.finding
    );
    // The 12 rejected fixes were the episodes': not graded twice.
    let r = graded(&v, "GNSS fixes rejected");
    assert_eq!(r.grade, Some(Grade::Good), "{}", r.finding);
    assert!(r.finding.starts_with("0 of 600"), "{}", r.finding);
    // Episodes excluding a third of the fixes: caution, named.
    let mut many = f.clone();
    many.rejected = 200;
    many.faults.excluded = 200;
    let v = assess(&ev(many));
    assert_eq!(
        graded(&v, "GNSS fault episodes").grade,
        Some(Grade::Caution)
    );
    assert!(
        v.causes.iter().any(|c| c.contains("rests on the INS")),
        "{:?}",
        v.causes
    );
    f.faults.persisted = 1;
    let v = assess(&ev(f));
    assert_eq!(
        graded(&v, "GNSS fault episodes").grade,
        Some(Grade::Caution)
    );
    assert!(v.grade >= Grade::Caution);
    assert!(
        v.causes.iter().any(|c| c.contains("persisted")),
        "{:?}",
        v.causes
    );
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

    // NIS mean: 7 over 600 fixes is outside χ²(1800)/600 (≈ 2.80 … 3.20)
    // and more than twice 3: caution, naming the σ figures.
    let mut e = good.clone();
    e.fixes = Some(fixes(600, 0, 0, 7.0));
    let v = assess(&e);
    assert_eq!(graded(&v, "NIS mean").grade, Some(Grade::Caution), "{v:#?}");
    assert!(
        v.causes.iter().any(|c| c.starts_with("noise figures")),
        "{v:#?}"
    );
    // …but inside it over 2 fixes (≈ 0.21 … 7.22).
    e.fixes = Some(fixes(2, 0, 0, 7.0));
    assert_eq!(graded(&assess(&e), "NIS mean").grade, Some(Grade::Good));
    // 3.6: outside the interval, within the factor 2: good.
    e.fixes = Some(fixes(600, 0, 0, 3.6));
    assert_eq!(graded(&assess(&e), "NIS mean").grade, Some(Grade::Good));
    e.fixes = Some(fixes(600, 0, 0, 12.0));
    assert_eq!(assess(&e).grade, Grade::Poor);
    e.fixes = Some(fixes(600, 0, 0, 1.0));
    let v = assess(&e);
    assert_eq!(graded(&v, "NIS mean").grade, Some(Grade::Caution));
    assert!(graded(&v, "NIS mean").finding.contains("pessimistic"));

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
            cross_sd: 0.0,
            scale_force_mgal: 0.0,
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
            cross_sd: 0.0,
            scale_force_mgal: -G_MGAL,
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

/// Gravity through misalignment and scale: a level IMU's x and y axes
/// see g·σ_m, its z axis g·σ_s; on its side (roll 90°) y takes z's role.
#[test]
fn gravity_couples_into_the_accelerometer_envelope() {
    let m = 0.05f64.to_radians();
    let level = [0.0, 0.0, 1.0];
    let gx = gravity_coupling_sd(level, 0, m, 500.0);
    assert!(close(gx, 9.806_65e5 * m, 1e-12), "{gx}");
    assert!(close(gx, 855.8, 1e-3), "{gx}");
    assert!(close(gravity_coupling_sd(level, 2, m, 500.0), 490.33, 1e-4));
    let side = [0.0, 1.0, 0.0];
    assert!(close(gravity_coupling_sd(side, 1, m, 500.0), 490.33, 1e-4));
    assert!(close(gravity_coupling_sd(side, 2, m, 500.0), gx, 1e-12));
    assert_eq!(gravity_coupling_sd(level, 0, 0.0, 0.0), 0.0);
}

/// Correlated NIS values are fewer independent ones: the same mean that
/// is outside the interval of 600 independent fixes is inside that of
/// 600 strongly correlated ones.
#[test]
fn the_nis_interval_widens_for_correlated_fixes() {
    assert!(lag1_autocorrelation(&[1.0, 2.0]).abs() < 1e-12);
    let alternating: Vec<f64> = (0..100).map(|k| (k % 2) as f64).collect();
    assert!(lag1_autocorrelation(&alternating) < -0.9);
    // White: about n; an AR(1) with φ = 0.9: n (1 − φ)/(1 + φ) ≈ n/19.
    let mut r = navsync_sim::rng::stream(7, "nis test");
    let white: Vec<f64> = (0..4000)
        .map(|_| navsync_sim::rng::normal(&mut r))
        .collect();
    let w = effective_count(&white);
    assert!(w > 3000.0 && w <= 4000.0, "{w}");
    let mut x = 0.0;
    let ar: Vec<f64> = white
        .iter()
        .map(|e| {
            x = 0.9 * x + e;
            x
        })
        .collect();
    let a = effective_count(&ar);
    assert!(a > 4000.0 / 19.0 / 1.6 && a < 4000.0 / 19.0 * 1.6, "{a}");
    let nis_of = |slow: bool| -> Vec<f64> {
        // 1.2 and 11.2 (mean 6.2, just over twice 3), alternating
        // from fix to fix or in two blocks of 300 fixes.
        (0..600)
            .map(|k| {
                let phase = if slow { (k / 300) % 2 } else { k % 2 };
                if phase == 0 { 1.0 } else { 11.0 }
            })
            .collect()
    };
    let check = |nis: Vec<f64>| {
        let (mut c, mut causes) = (Vec::new(), Causes::default());
        nis_check(&nis, &mut c, &mut causes);
        c.remove(0)
    };
    let fast = check(nis_of(false).into_iter().map(|x| x + 0.2).collect());
    let slow = check(nis_of(true).into_iter().map(|x| x + 0.2).collect());
    assert_eq!(fast.grade, Some(Grade::Caution), "{fast:?}");
    assert_eq!(slow.grade, Some(Grade::Good), "{slow:?}");
    assert!(slow.finding.contains("independent"), "{slow:?}");
}

#[test]
fn a_zero_lever_arm_is_a_caution_with_its_cause() {
    let mut e = Evidence {
        fixes: Some(fixes(600, 0, 3, 3.0)),
        final_h_sd_m: Some(0.8),
        antenna_lever_m: Some([0.0; 3]),
        ..Evidence::default()
    };
    let v = assess(&e);
    assert_eq!(v.grade, Grade::Caution, "{v:#?}");
    assert!(v.causes.iter().any(|c| c.contains("antenna_lever_m")));
    e.antenna_lever_m = Some([0.1, 0.5, -1.2]);
    let v = assess(&e);
    assert_eq!(v.grade, Grade::Good, "{v:#?}");
    assert!(v.causes.is_empty());
}

/// With the lever-arm states on, the check grades what the drive
/// observed: a zero sheet whose horizontal components were observed is
/// good; not observed, a zero sheet stays a caution and a measured one
/// is shown ungraded (an unobserved estimate is not praised).
#[test]
fn an_estimated_lever_arm_is_graded_by_what_the_drive_observed() {
    let est = |observed: bool| navsync::fusion::LeverArmSummary {
        estimate_m: [0.39, -0.29, -0.1],
        sd_m: if observed {
            [0.02, 0.02, 0.45]
        } else {
            [0.45, 0.4, 0.48]
        },
        initial_sd_m: 0.5,
        sheet_m: [0.0; 3],
        observed: [observed, observed, false],
        difference_m: 0.49,
        difference_sigmas: 19.5,
        significant: observed,
        note: "n".into(),
    };
    let run = |sheet: [f64; 3], observed: bool| {
        let v = assess(&Evidence {
            fixes: Some(fixes(600, 0, 3, 3.0)),
            final_h_sd_m: Some(0.02),
            antenna_lever_m: Some(sheet),
            lever_estimate: Some(est(observed)),
            ..Evidence::default()
        });
        (graded(&v, "antenna lever arm").grade, v)
    };
    let (g, v) = run([0.0; 3], true);
    assert_eq!(g, Some(Grade::Good), "{v:#?}");
    assert!(v.causes.is_empty(), "{v:#?}");
    let (g, v) = run([0.0; 3], false);
    assert_eq!(g, Some(Grade::Caution), "{v:#?}");
    assert!(v.causes[0].contains("did not observe"), "{v:#?}");
    assert_eq!(run([0.4, -0.3, -0.8], false).0, None);
    // A signature left with the states on does not recommend them.
    let v = assess(&Evidence {
        innovation: Some(lever_signature()),
        antenna_lever_m: Some([0.0; 3]),
        lever_estimate: Some(est(true)),
        ..Evidence::default()
    });
    let c = v
        .causes
        .iter()
        .find(|c| c.contains("turn with the heading"))
        .unwrap();
    assert!(c.contains("states ran") && !c.contains("would help"), "{c}");
}

/// The signatures grade by the accuracy they cost: a lever-arm error
/// of 0.5 m against a 2 cm solution is poor, 3 cm is a caution, 1 cm
/// harmless; an insignificant one is good whatever its size.
#[test]
fn innovation_signatures_are_graded_by_their_cost() {
    use crate::innovation::InnovationEvidence;
    let base = lever_signature();
    let grade_of_lever = |e: InnovationEvidence| {
        let ev = Evidence {
            innovation: Some(e),
            ..Evidence::default()
        };
        let v = assess(&ev);
        (graded(&v, "innovations vs heading (lever arm)").grade, v)
    };
    let (g, v) = grade_of_lever(base.clone());
    assert_eq!(g, Some(Grade::Poor));
    assert!(v.causes[0].starts_with("antenna lever arm"), "{v:#?}");
    assert!(
        v.causes[0].contains("`estimate_lever_arm: true`") && v.causes[0].contains("would help"),
        "{v:#?}"
    );
    assert!(
        graded(&v, "innovations vs heading (lever arm)")
            .finding
            .contains("+0.400 m forward")
    );
    assert_eq!(
        graded(&v, "innovations vs speed (time offset)").grade,
        Some(Grade::Good)
    );
    let small = |m: f64| InnovationEvidence {
        lever_error_fr_m: [m, 0.0],
        ..base.clone()
    };
    // √(1 + 1.5²) = 1.8: good; √(1 + 4²) = 4.1: caution.
    assert_eq!(grade_of_lever(small(0.03)).0, Some(Grade::Good));
    assert_eq!(grade_of_lever(small(0.08)).0, Some(Grade::Caution));
    let unseen = InnovationEvidence {
        lever_p: 0.02,
        ..base.clone()
    };
    assert_eq!(grade_of_lever(unseen).0, Some(Grade::Good));
    // A time offset of 30 ms at 10 m/s: 0.3 m against 2 cm, poor.
    let late = InnovationEvidence {
        lever_p: 0.5,
        offset_s: 0.03,
        offset_p: 1e-6,
        ..base
    };
    let v = assess(&Evidence {
        innovation: Some(late),
        ..Evidence::default()
    });
    assert_eq!(
        graded(&v, "innovations vs speed (time offset)").grade,
        Some(Grade::Poor)
    );
    assert!(v.causes[0].starts_with("GNSS time offset"), "{v:#?}");
}

/// The probe's time offset: 13.7 ± 1.6 ms at 10 m/s against a 2 cm
/// solution (0.137 m, 6.9×) is poor; 3.7 ± 1.6 ms (2.3σ) is not
/// significant, good whatever it would cost; 5 ± 1 ms (0.05 m, 2.7×)
/// is a caution. Without the innovation evidence (speed, σ) it is not
/// graded.
#[test]
fn the_probes_time_offset_is_graded_by_significance_and_cost() {
    let inn = quiet_innovations(300, 150.0, 10.0, 0.02);
    let grade = |o: f64, sd: f64, with_innovation: bool| {
        let v = assess(&Evidence {
            innovation: with_innovation.then(|| inn.clone()),
            probe: Some(ProbeEvidence {
                time_offset_s: Some((o, sd)),
                lever_arm: None,
                failed: None,
            }),
            ..Evidence::default()
        });
        let g = v
            .checks
            .iter()
            .find(|c| c.name == "time offset (probe)")
            .map(|c| c.grade);
        (g, v)
    };
    let (g, v) = grade(0.0137, 0.0016, true);
    assert_eq!(g, Some(Some(Grade::Poor)));
    assert!(
        v.causes.iter().any(|c| c.contains("+14 ± 2 ms late")),
        "{v:#?}"
    );
    assert_eq!(grade(0.0037, 0.0016, true).0, Some(Some(Grade::Good)));
    assert_eq!(grade(-0.005, 0.001, true).0, Some(Some(Grade::Caution)));
    assert_eq!(grade(0.0137, 0.0016, false).0, None);
}

/// A probe whose lever-arm states ran to 132 m (the Husky bag with the
/// default sheet's mounting, 90° off) is poor, but its cause names the
/// mounting, not the antenna; a 3 m difference names the lever arm. States
/// the drive did not observe that still ran to 30 m (the Husky bag's probe
/// since its covariance inflations keep their σ near the initial one) are
/// as poor; unobserved ones near the sheet are not graded.
#[test]
fn an_implausible_probe_lever_arm_names_another_error() {
    let inn = quiet_innovations(900, 300.0, 1.0, 0.5);
    let verdict = |forward_m: f64, right_m: f64, observed: bool| {
        let l = navsync::fusion::LeverArmSummary {
            estimate_m: [forward_m, right_m, 0.0],
            sd_m: if observed {
                [0.1, 0.15, 1.0]
            } else {
                [0.51, 3.65, 318.8]
            },
            initial_sd_m: if observed { 1.0 } else { 0.5 },
            sheet_m: [0.0; 3],
            observed: [observed, observed, false],
            difference_m: if observed {
                forward_m.hypot(right_m)
            } else {
                0.0
            },
            difference_sigmas: if observed { 100.0 } else { 0.0 },
            significant: observed,
            note: String::new(),
        };
        let v = assess(&Evidence {
            innovation: Some(inn.clone()),
            probe: Some(ProbeEvidence {
                time_offset_s: None,
                lever_arm: Some(l),
                failed: None,
            }),
            ..Evidence::default()
        });
        let grade = graded(&v, "antenna lever arm (probe)").grade;
        (grade, v.causes.join(" | "))
    };
    for observed in [true, false] {
        let (grade, far) = verdict(89.6, -97.1, observed);
        assert_eq!(grade, Some(Grade::Poor), "{far}");
        assert!(
            far.contains("not the antenna") && far.contains("mount_deg"),
            "{far}"
        );
    }
    let (grade, husky) = verdict(-27.9, -12.7, false);
    assert_eq!(grade, Some(Grade::Poor), "{husky}");
    assert!(husky.contains("not the antenna"), "{husky}");
    // With the sheet's lever arm zero (a caution found first), the poor
    // check's cause still leads.
    let v = assess(&Evidence {
        innovation: Some(inn.clone()),
        antenna_lever_m: Some([0.0; 3]),
        probe: Some(ProbeEvidence {
            time_offset_s: None,
            lever_arm: Some(navsync::fusion::LeverArmSummary {
                estimate_m: [-27.9, -12.7, 0.0],
                sd_m: [0.51, 3.65, 318.8],
                initial_sd_m: 0.5,
                sheet_m: [0.0; 3],
                observed: [false; 3],
                difference_m: 0.0,
                difference_sigmas: 0.0,
                significant: false,
                note: String::new(),
            }),
            failed: None,
        }),
        ..Evidence::default()
    });
    assert_eq!(v.causes.len(), 2, "{:#?}", v.causes);
    assert!(
        v.causes[0].starts_with("not the antenna"),
        "{:#?}",
        v.causes
    );
    assert!(
        v.causes[1].starts_with("antenna lever arm: zero"),
        "{:#?}",
        v.causes
    );
    let (grade, near) = verdict(3.0, 0.0, true);
    assert_eq!(grade, Some(Grade::Poor), "{near}");
    assert!(near.starts_with("antenna lever arm"), "{near}");
    let (grade, unobserved) = verdict(0.4, -0.3, false);
    assert_eq!(grade, Some(Grade::Good), "{unobserved}");
    assert!(!unobserved.contains("antenna"), "{unobserved}");
}

/// Innovation evidence with no lever-arm or time-offset signature: `fixes`
/// (`effective` independent) at `speed_rms_mps` against a filter σ of
/// `filter_h_sd_m`.
fn quiet_innovations(
    fixes: usize,
    effective: f64,
    speed_rms_mps: f64,
    filter_h_sd_m: f64,
) -> crate::innovation::InnovationEvidence {
    crate::innovation::InnovationEvidence {
        fixes,
        effective_fixes: effective,
        lever_error_fr_m: [0.0, 0.0],
        lever_p: 0.5,
        offset_s: 0.0,
        offset_p: 0.5,
        speed_rms_mps,
        filter_h_sd_m,
    }
}

/// A significant lever-arm signature (0.4 m forward, 0.3 m left, p 1e-9)
/// over 300 fixes at 10 m/s against a 2 cm solution.
fn lever_signature() -> crate::innovation::InnovationEvidence {
    crate::innovation::InnovationEvidence {
        lever_error_fr_m: [0.4, -0.3],
        lever_p: 1e-9,
        ..quiet_innovations(300, 150.0, 10.0, 0.02)
    }
}

/// A time offset the run estimated with σ 36 ms (comma2k19's phone logs)
/// is poor, and its cause says what that costs along the track and what
/// removes it; at 0.5 ms it is good and says nothing.
#[test]
fn a_poorly_determined_time_offset_names_its_cost_and_remedy() {
    let verdict = |sd_s: f64| {
        assess(&Evidence {
            innovation: Some(quiet_innovations(600, 200.0, 20.0, 0.5)),
            time_offset_sd_s: Some(sd_s),
            ..Evidence::default()
        })
    };
    let v = verdict(0.036);
    assert_eq!(graded(&v, "time-offset σ").grade, Some(Grade::Poor));
    assert!(
        v.causes[0].starts_with("GNSS time offset poorly determined")
            && v.causes[0].contains("0.72 m along the track")
            && v.causes[0].contains("1PPS"),
        "{:#?}",
        v.causes
    );
    let v = verdict(0.0005);
    assert_eq!(graded(&v, "time-offset σ").grade, Some(Grade::Good));
    assert!(
        !v.causes.iter().any(|c| c.contains("time offset")),
        "{:#?}",
        v.causes
    );
}

/// A grade no cause explains (10 % of the fixes rejected, nothing else
/// wrong) is named by the check that set it, first; a grade a cause
/// already explains gets no such line.
#[test]
fn a_grade_without_a_cause_is_named_by_its_check() {
    let v = assess(&Evidence {
        fixes: Some(fixes(600, 60, 0, 3.0)),
        ..Evidence::default()
    });
    assert_eq!(v.grade, Grade::Poor, "{v:#?}");
    assert!(
        v.causes[0].starts_with("GNSS fixes rejected: 60 of 600"),
        "{:#?}",
        v.causes
    );
    let v = assess(&Evidence {
        fixes: Some(fixes(600, 0, 0, 3.0)),
        time_offset_sd_s: Some(0.036),
        ..Evidence::default()
    });
    assert_eq!(v.grade, Grade::Poor, "{v:#?}");
    assert_eq!(
        v.causes
            .iter()
            .filter(|c| c.contains("time offset") || c.starts_with("time-offset σ"))
            .count(),
        1,
        "{:#?}",
        v.causes
    );
}

/// The forward σ through gaps: a confirmed gap end past its σ makes a
/// forward file cautious, with the cause its σ growth points to (the INS
/// drifted, or the position entering the gap was off); a smoothed file
/// shows the forward pass's finding ungraded; ends within σ are good.
#[test]
fn a_gap_end_past_its_sigma_names_the_drift_or_the_entry() {
    use crate::gap_ends::{GapEnd, evidence};
    let drift = GapEnd {
        sow: 100202.0,
        gap_s: 26.0,
        offset_h_m: 4.7,
        filter_sd_h_m: 1.0,
        start_sd_h_m: 0.03,
        nees: 41.0,
        drift_confirmed: Some(true),
    };
    let entry = GapEnd {
        sow: 116715.0,
        gap_s: 6.0,
        offset_h_m: 1.09,
        filter_sd_h_m: 0.27,
        start_sd_h_m: 0.26,
        nees: 26.0,
        ..drift
    };
    let fine = GapEnd { nees: 1.0, ..drift };
    let judged = |ends: &[GapEnd], forward: bool| {
        assess(&Evidence {
            fixes: Some(fixes(600, 0, 0, 3.0)),
            gap_ends: evidence(ends, forward),
            ..Evidence::default()
        })
    };
    let v = judged(&[drift, entry, fine], true);
    assert_eq!(v.grade, Grade::Caution, "{v:#?}");
    let gap_causes: Vec<&String> = v
        .causes
        .iter()
        .filter(|c| c.starts_with("σ through GNSS gaps"))
        .collect();
    assert_eq!(gap_causes.len(), 2, "{:#?}", v.causes);
    assert!(
        gap_causes[0].contains("4.70 m off") && gap_causes[0].contains("--misalignment"),
        "{gap_causes:#?}"
    );
    assert!(
        gap_causes[1].contains("1.09 m off") && gap_causes[1].contains("correlated in time"),
        "{gap_causes:#?}"
    );
    // A smoothed file: the forward pass's finding, not graded.
    let v = judged(&[drift], false);
    assert_eq!(v.grade, Grade::Good, "{v:#?}");
    let c = v
        .checks
        .iter()
        .find(|c| c.name == "σ through GNSS gaps")
        .unwrap();
    assert_eq!(c.grade, None);
    assert!(c.finding.contains("the forward pass"), "{}", c.finding);
    // Within σ, or not confirmed by the next fix: good.
    let unconfirmed = GapEnd {
        drift_confirmed: Some(false),
        ..drift
    };
    for ends in [vec![fine], vec![unconfirmed, fine]] {
        let v = judged(&ends, true);
        assert_eq!(v.grade, Grade::Good, "{v:#?}");
    }
}
