//! The fault monitor's tests.

use super::*;

const RTK_VAR_M2: f64 = 1e-4;

/// An INS with 5 mm/s velocity σ, 0.01° tilt, 0.1° yaw at 10 m/s.
fn sharp_ins() -> StateSpread {
    StateSpread {
        vel_sd: Vector3::repeat(0.005),
        tilt_sd: 0.01f64.to_radians(),
        yaw_sd: 0.1f64.to_radians(),
        accel_bias_sd: 1e-3,
        gyro_bias_sd: 1e-6,
        speed_mps: 10.0,
    }
}
/// A monitor with clean 1 Hz fixes up to `t0 + n − 1` s ([`sharp_ins`]).
fn primed(n: usize) -> (FaultMonitor, GpsTime) {
    primed_with(n, sharp_ins())
}
fn primed_with(n: usize, spread: StateSpread) -> (FaultMonitor, GpsTime) {
    let mut m = FaultMonitor::new(0.04 / 60.0);
    let t0 = GpsTime::from_week_sow(2300, 1000.0);
    for k in 0..n {
        let t = t0.add_seconds(k as f64);
        assert_eq!(
            m.judge(t, &Vector3::zeros(), &hph(), &r(), 1.0),
            Judgement::Clean
        );
        m.add_anchor(
            t,
            Vector3::zeros(),
            Vector3::repeat(1e-4),
            r(),
            spread,
            false,
        );
    }
    (m, t0.add_seconds(n as f64))
}
fn hph() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::repeat(1.2e-4))
}
/// Judges fixes `z(k)` at `t + k` s for k < n, each of which must be
/// excluded; their reasons.
fn exclusions(
    m: &mut FaultMonitor,
    t: GpsTime,
    n: usize,
    z: impl Fn(usize) -> Vector3<f64>,
) -> Vec<FaultReason> {
    (0..n)
        .map(
            |k| match m.judge(t.add_seconds(k as f64), &z(k), &hph(), &r(), 1.0) {
                Judgement::Exclude(why) => why,
                other => panic!("fix {k}: {other:?}"),
            },
        )
        .collect()
}
fn r() -> Vector3<f64> {
    Vector3::repeat(RTK_VAR_M2)
}
/// A monitor after 18 clean 1 Hz fixes from `t0` with the state's σ
/// `spread`, the fixes pulling the state `pull_m` north a fix from the
/// 6th on (GNSS corrections), the fix at `dragged_at` used only because
/// the robust weighting judged the INS drifted.
fn pulled(spread: StateSpread, pull_m: f64, dragged_at: Option<usize>) -> (FaultMonitor, GpsTime) {
    let mut m = FaultMonitor::new(0.04 / 60.0);
    let t0 = GpsTime::from_week_sow(2300, 1000.0);
    for k in 0..18 {
        let t = t0.add_seconds(k as f64);
        assert_eq!(
            m.judge(t, &Vector3::zeros(), &hph(), &r(), 1.0),
            Judgement::Clean
        );
        let pulled_north = (k >= 6).then_some(pull_m);
        use_fix(&mut m, t, pulled_north, spread, dragged_at == Some(k));
    }
    (m, t0.add_seconds(18.0))
}
/// Records the fix at `t` as used: its update moved the state
/// `north_m` north (a GNSS correction, when given), and it became an
/// anchor with the state's σ `spread`.
fn use_fix(
    m: &mut FaultMonitor,
    t: GpsTime,
    north_m: Option<f64>,
    spread: StateSpread,
    dragged: bool,
) {
    if let Some(north_m) = north_m {
        let mut dx = vec![0.0; 21];
        dx[0] = -north_m;
        m.record_correction(t, &dx, 0, 3);
    }
    m.add_anchor(
        t,
        Vector3::zeros(),
        Vector3::repeat(1e-4),
        r(),
        spread,
        dragged,
    );
}

/// A coarse receiver (stated σ 2 m horizontal) whose fixes move by a
/// centimetre or two from one to the next at 10 Hz, as a standalone or
/// DGNSS error does: once 20 clean pairs measured that, a 12 m jump
/// is one (4.2 σ of the stated difference: it passed before, and the
/// robust weighting took the false fix for INS drift on comma2k19).
/// Before 20 pairs, or into a fix of another σ (the receiver changed
/// its solution), the stated σ holds and the jump passes.
#[test]
fn a_jump_is_judged_by_the_receivers_measured_change_not_its_stated_sigma() {
    let spread = sharp_ins();
    let coarse = Vector3::new(4.0, 4.0, 9.0);
    let wobble = |k: usize| Vector3::new(0.01 * ((k % 3) as f64 - 1.0), 0.01 * (k % 2) as f64, 0.0);
    let t0 = GpsTime::from_week_sow(2300, 1000.0);
    let at = |k: usize| t0.add_seconds(0.1 * k as f64);
    let primed = |n: usize| {
        let mut m = FaultMonitor::new(0.04 / 60.0);
        for k in 0..n {
            assert_eq!(
                m.judge(at(k), &wobble(k), &hph(), &coarse, 1.0),
                Judgement::Clean
            );
            m.add_anchor(
                at(k),
                wobble(k),
                Vector3::repeat(1e-4),
                coarse,
                spread,
                false,
            );
        }
        m
    };
    let jump = |n: usize| wobble(n) + Vector3::new(0.0, 12.0, 0.0);
    let mut learned = primed(40);
    let mut other_sd = learned.clone();
    assert_eq!(
        learned.judge(at(40), &jump(40), &hph(), &coarse, 1.0),
        Judgement::Exclude(FaultReason::Jump)
    );
    let mut young = primed(10);
    assert_eq!(
        young.judge(at(10), &jump(10), &hph(), &coarse, 1.0),
        Judgement::Clean
    );
    let worse = Vector3::new(9.0, 9.0, 16.0);
    assert_eq!(
        other_sd.judge(at(40), &jump(40), &hph(), &worse, 1.0),
        Judgement::Clean
    );
}

/// A false fix: 3 m for 8 s is excluded whole (a jump, then a run) and
/// the fixes that come back are clean; the episode is a run that
/// returned.
#[test]
fn a_false_fix_is_excluded_until_the_fixes_come_back() {
    let (mut m, t) = primed(10);
    let fault = Vector3::new(-2.0, 2.2, 0.0); // z = predicted − measured
    let reasons = exclusions(&mut m, t, 8, |_| fault);
    assert_eq!(reasons[0], FaultReason::Jump);
    assert!(reasons[1..].iter().all(|w| *w == FaultReason::Run));
    let back = m.judge(t.add_seconds(8.0), &Vector3::zeros(), &hph(), &r(), 1.0);
    assert_eq!(back, Judgement::Clean);
    let eps = m.all_episodes();
    assert_eq!(eps.len(), 1);
    assert_eq!(eps[0].class, EpisodeClass::Run);
    assert_eq!(eps[0].end, EpisodeEnd::Returned);
    assert_eq!(eps[0].fixes, 8);
    assert!((eps[0].max_offset_m - fault.norm()).abs() < 1e-9);
}

/// One wild fix is a spike; fixes within their σ never open anything.
#[test]
fn a_spike_is_one_fix_and_noise_opens_nothing() {
    let (mut m, t) = primed(10);
    let spike = Vector3::new(20.0, -15.0, 5.0);
    assert_eq!(
        m.judge(t, &spike, &hph(), &r(), 1.0),
        Judgement::Exclude(FaultReason::Jump)
    );
    assert_eq!(
        m.judge(t.add_seconds(1.0), &Vector3::zeros(), &hph(), &r(), 1.0),
        Judgement::Clean
    );
    assert_eq!(m.all_episodes()[0].class, EpisodeClass::Spike);
    // 3 σ of the stated noise on every axis, 10 cm: below the floor.
    let (mut m, t) = primed(10);
    let z = Vector3::repeat(0.1);
    assert_eq!(m.judge(t, &z, &hph(), &r(), 1.0), Judgement::Clean);
    assert!(m.all_episodes().is_empty());
}

/// When the INS's own predicted spread grows to cover the offset (a
/// fault longer than the IMU bridges at its precision), the fixes are
/// used again and the episode ends as persisted; one longer than
/// MAX_EPISODE_S with an INS that stays sharp ends unbridged.
#[test]
fn a_fault_the_ins_cannot_bridge_is_followed_and_said() {
    let (mut m, t) = primed(10);
    let fault = Vector3::new(1.0, 0.0, 0.0);
    assert!(matches!(
        m.judge(t, &fault, &hph(), &r(), 1.0),
        Judgement::Exclude(_)
    ));
    // H P Hᵀ grown to 1 m² per axis: a 1 m offset is within it.
    let wide = Matrix3::from_diagonal(&Vector3::repeat(1.0));
    match m.judge(t.add_seconds(1.0), &fault, &wide, &r(), 1.0) {
        Judgement::Persisted { by, offset } => {
            assert_eq!(by, PersistedBy::DriftCovers);
            assert!((offset - fault).norm() < 1e-9);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(m.all_episodes()[0].end, EpisodeEnd::Persisted);

    let (mut m, t) = primed(10);
    let big = Vector3::new(100.0, 0.0, 0.0);
    let mut k = 0.0;
    let end = loop {
        match m.judge(t.add_seconds(k), &big, &hph(), &r(), 1.0) {
            Judgement::Exclude(_) => k += 1.0,
            other => break other,
        }
        assert!(k < 100.0, "never ended");
    };
    assert!(matches!(
        end,
        Judgement::Persisted {
            by: PersistedBy::Unbridged,
            ..
        }
    ));
    assert!(k >= MAX_EPISODE_S, "ended after {k} s");
    assert_eq!(m.all_episodes()[0].end, EpisodeEnd::Unbridged);
}

/// An INS drifting 8 cm/s from the fixes while its model says 1 cm: in
/// an 8 m false fix the drift shows within 5 s, but at that rate, over
/// the episode and the memory before it, it builds 4 m, not 8. The
/// fault stays excluded. The first fix back is 0.64 m from the INS,
/// far past its predicted growth since the anchor, but its jump from
/// the last fix undoes the one that opened the episode: the fixes are
/// back, and it is clean (before, it was followed as persisted, the
/// level the INS could no longer tell). A 1.5 m level (a ramp the INS
/// had been led along) is within what it builds: followed at 5 s.
#[test]
fn an_ins_that_drifts_follows_offsets_it_could_build_not_a_false_fix() {
    let drift = |k: f64| Vector3::new(0.0, 0.08 * k, 0.0);
    let (mut m, t) = primed(10);
    let fault = Vector3::new(-8.0, 1.0, 0.0);
    exclusions(&mut m, t, 8, |k| fault + drift(k as f64));
    assert_eq!(
        m.judge(t.add_seconds(8.0), &drift(8.0), &hph(), &r(), 1.0),
        Judgement::Clean
    );
    let ep = &m.all_episodes()[0];
    assert_eq!((ep.end, ep.fixes), (EpisodeEnd::Returned, 8));

    let (mut m, t) = primed(10);
    let level = Vector3::new(1.2, -0.9, 0.0);
    let mut k = 0.0;
    let end = loop {
        match m.judge(t.add_seconds(k), &(level + drift(k)), &hph(), &r(), 1.0) {
            Judgement::Exclude(_) => k += 1.0,
            other => break other,
        }
        assert!(k < 10.0, "never followed");
    };
    assert!(
        matches!(
            end,
            Judgement::Persisted {
                by: PersistedBy::InsDrifts,
                ..
            }
        ),
        "{end:?}"
    );
    assert_eq!(k, 5.0);
}

/// A jump to a 1 m level whose fixes the INS then drifts from at
/// 0.1 m/s, within its own predicted growth (0.03 m/s): the fixes after
/// the jump are off by a constant (a false fix) or right (a ramp's end),
/// so the change of their offset is the INS's own drift. Once that passes
/// the level, 11 s in, the INS is no nearer the truth than the level it
/// refuses, and the fixes are followed (before, they were excluded until
/// its predicted growth covered the whole offset, 27 s in).
#[test]
fn an_ins_that_drifted_past_the_level_it_judges_follows_the_fixes() {
    let (mut m, t) = primed(10);
    let fix = |k: usize| {
        let z = Vector3::new(1.0 + 0.1 * k as f64, 0.0, 0.0);
        let growth_sd_m = 0.03 * k as f64;
        let hph = Matrix3::from_diagonal(&Vector3::repeat(1.2e-4 + growth_sd_m * growth_sd_m));
        (t.add_seconds(k as f64), z, hph)
    };
    for k in 0..=10 {
        let (tk, z, hph) = fix(k);
        let why = if k == 0 {
            FaultReason::Jump
        } else {
            FaultReason::Run
        };
        assert_eq!(
            m.judge(tk, &z, &hph, &r(), 1.0),
            Judgement::Exclude(why),
            "{k} s"
        );
    }
    let (tk, z, hph) = fix(11);
    let judged = m.judge(tk, &z, &hph, &r(), 1.0);
    assert!(
        matches!(
            judged,
            Judgement::Persisted {
                by: PersistedBy::InsDriftedPastLevel { .. },
                ..
            }
        ),
        "{judged:?}"
    );
}

/// A jump's level that persisted (as above) is followed from the jump on
/// where a re-run can: the monitor hands the wrapper the clean fix before
/// the jump and the jump, and in the re-run the jump persists at once,
/// for the same reason, its episode recorded as first closed. The re-run
/// asks for no re-run of its own, and a real-time monitor for none.
#[test]
fn a_persisted_level_is_followed_from_its_jump_in_a_rerun() {
    let fix = |t: GpsTime, k: usize| {
        let z = Vector3::new(1.0 + 0.1 * k as f64, 0.0, 0.0);
        let growth_sd_m = 0.03 * k as f64;
        let hph = Matrix3::from_diagonal(&Vector3::repeat(1.2e-4 + growth_sd_m * growth_sd_m));
        (t.add_seconds(k as f64), z, hph)
    };
    let run = |onset_enabled: bool| {
        let (mut m, t) = primed(10);
        m.onset_enabled = onset_enabled;
        let mut judged = Judgement::Clean;
        for k in 0..=11 {
            let (tk, z, hph) = fix(t, k);
            judged = m.judge(tk, &z, &hph, &r(), 1.0);
        }
        (m, t, judged)
    };
    let (mut first, t, judged) = run(true);
    let Judgement::Persisted { by, .. } = judged else {
        panic!("{judged:?}");
    };
    let level = first.take_persisted_level().expect("a level to follow");
    assert_eq!((level.anchor, level.jump), (t.add_seconds(-1.0), t));
    assert!(first.take_persisted_level().is_none());
    let record = *first.episodes.last().unwrap();
    assert_eq!((record.fixes, record.end), (11, EpisodeEnd::Persisted));

    let (mut rerun, t) = primed(10);
    rerun.onset_enabled = true;
    rerun.replay_persisted_level(level);
    let (tk, z, hph) = fix(t, 0);
    let judged = rerun.judge(tk, &z, &hph, &r(), 1.0);
    assert!(
        matches!(judged, Judgement::Persisted { by: b, .. } if b == by),
        "{judged:?}"
    );
    assert_eq!(rerun.episodes.last(), Some(&record));
    assert!(rerun.take_persisted_level().is_none());

    let (mut real_time, _, _) = run(false);
    assert!(real_time.take_persisted_level().is_none());
}

/// A 0.9 m false fix the INS could no longer tell from its own drift
/// (H P Hᵀ grown to 1 m² a fix in): followed, four fixes on its level,
/// then a jump that undoes the one that opened it is the false fix's
/// end, after the clean fix before it. A jump of another size or
/// direction is no such end: a new level is not undone by it.
#[test]
fn a_jump_that_undoes_a_followed_level_ends_a_false_fix() {
    let followed_then = |back: Vector3<f64>| {
        let (mut m, t) = primed(10);
        let fault = Vector3::new(0.8, -0.4, 0.05);
        assert_eq!(
            m.judge(t, &fault, &hph(), &r(), 1.0),
            Judgement::Exclude(FaultReason::Jump)
        );
        let wide = Matrix3::from_diagonal(&Vector3::repeat(1.0));
        let t1 = t.add_seconds(1.0);
        assert!(matches!(
            m.judge(t1, &fault, &wide, &r(), 1.0),
            Judgement::Persisted {
                by: PersistedBy::DriftCovers,
                ..
            }
        ));
        // The update moved the state onto the false level.
        use_fix(&mut m, t1, Some(-0.8), sharp_ins(), false);
        for k in 2..6 {
            let tk = t.add_seconds(k as f64);
            assert_eq!(
                m.judge(tk, &Vector3::zeros(), &hph(), &r(), 1.0),
                Judgement::Clean
            );
            use_fix(&mut m, tk, None, sharp_ins(), false);
        }
        (m.judge(t.add_seconds(6.0), &back, &hph(), &r(), 1.0), t)
    };
    let fault = Vector3::new(0.8, -0.4, 0.05);
    match followed_then(-fault + Vector3::new(0.03, 0.02, 0.0)) {
        (Judgement::FalseFixEnd { anchor, offset }, t) => {
            assert_eq!(anchor, t.add_seconds(-1.0));
            assert!((offset + fault).norm() < 0.05, "{offset:?}");
        }
        (other, _) => panic!("the jump back: {other:?}"),
    }
    for other in [
        -0.4 * fault,
        -fault + Vector3::new(0.0, 0.0, 0.8),
        Vector3::new(0.4, 0.8, 0.0),
    ] {
        let (j, _) = followed_then(other);
        assert!(
            !matches!(j, Judgement::FalseFixEnd { .. }),
            "{other:?}: {j:?}"
        );
    }
}

/// A 46 m spike 10 s into a 1.5 m false fix: a new fault inside the
/// episode, excluded; it is no evidence that the INS drifted (taken for
/// it, the episode ended and the filter was moved 46 m). The false
/// fix's next fixes stay excluded, and the fixes that come back end the
/// episode.
#[test]
fn a_spike_inside_an_episode_is_excluded_not_taken_for_drift() {
    let (mut m, t) = primed(10);
    let fault = Vector3::new(1.2, -0.9, 0.0);
    let spike = Vector3::new(-29.0, -34.5, 9.4);
    let reasons = exclusions(&mut m, t, 13, |k| if k == 10 { spike } else { fault });
    assert_eq!(reasons[10], FaultReason::Jump);
    assert!(reasons[11..].iter().all(|w| *w == FaultReason::Run));
    let back = m.judge(t.add_seconds(13.0), &Vector3::zeros(), &hph(), &r(), 1.0);
    assert_eq!(back, Judgement::Clean);
    assert_eq!(m.all_episodes()[0].end, EpisodeEnd::Returned);
}

/// A MEMS INS whose accelerometer bias (0.1 m/s²) and tilt (0.5°) the
/// fixes have not told apart: from their σ alone its drift would reach
/// 5 m in 6 s, but the filter's own H P Hᵀ, which holds their
/// correlation, grows to 0.5 m σ in 10 s. Judged by the latter, a 5 m
/// false fix for 10 s stays excluded whole and the fixes that come
/// back are clean (judged by the former it was taken for drift and
/// followed).
#[test]
fn a_false_fix_is_judged_by_the_filters_own_growth_without_updates() {
    let (mut m, t) = primed_with(
        10,
        StateSpread {
            vel_sd: Vector3::repeat(0.01),
            tilt_sd: 0.5f64.to_radians(),
            yaw_sd: 1f64.to_radians(),
            accel_bias_sd: 0.1,
            gyro_bias_sd: 1e-5,
            speed_mps: 10.0,
        },
    );
    let grown = |k: f64| Matrix3::from_diagonal(&Vector3::repeat(1.2e-4 + (0.05 * k).powi(2)));
    let fault = Vector3::new(3.0, -4.0, 0.0);
    for k in 0..10 {
        let j = m.judge(
            t.add_seconds(k as f64),
            &fault,
            &grown(k as f64 + 1.0),
            &r(),
            1.0,
        );
        assert!(
            matches!(j, Judgement::Exclude(_)),
            "fix {k} of the fault: {j:?}"
        );
    }
    let back = m.judge(
        t.add_seconds(10.0),
        &Vector3::zeros(),
        &grown(11.0),
        &r(),
        1.0,
    );
    assert_eq!(back, Judgement::Clean);
    assert_eq!(m.all_episodes()[0].end, EpisodeEnd::Returned);
    assert_eq!(m.all_episodes()[0].fixes, 10);
}

/// A MEMS INS's σ: 0.1° tilt, 0.2° heading at 10 m/s.
fn mems_ins() -> StateSpread {
    StateSpread {
        vel_sd: Vector3::repeat(0.01),
        tilt_sd: 0.1f64.to_radians(),
        yaw_sd: 0.2f64.to_radians(),
        accel_bias_sd: 0.02,
        gyro_bias_sd: 1e-5,
        speed_mps: 10.0,
    }
}

/// A MEMS INS (0.1° tilt, 0.2° heading σ at 10 m/s) follows fixes for
/// 18 s, corrected by 1 cm a fix from the 6th on, then the fixes jump
/// 1.44 m: sharp against the last fix (a jump), within the INS's drift
/// since the first (18 s back) but no closer to it. That is a ramp's
/// end only if the fixes had dragged the INS meanwhile (a fix used
/// because the robust weighting judged the INS drifted), and only once
/// the INS was a reference (not a drift acceptance among the first
/// fixes after a start, which is the INS catching up).
#[test]
fn a_jump_after_the_fixes_dragged_the_ins_is_a_ramp_end() {
    let spread = mems_ins();
    let jump_after = |dragged_at: Option<usize>| {
        let (mut m, t) = pulled(spread, 0.01, dragged_at);
        let z = Vector3::new(1.2, -0.8, 0.0);
        m.judge(t, &z, &hph(), &r(), 1.0)
    };
    assert!(
        matches!(jump_after(Some(10)), Judgement::RampEnd { .. }),
        "{:?}",
        jump_after(Some(10))
    );
    assert_eq!(jump_after(None), Judgement::Exclude(FaultReason::Jump));
    assert_eq!(jump_after(Some(2)), Judgement::Exclude(FaultReason::Jump));
}

/// The jump of the test above, taken for a ramp's end and followed,
/// then undone 4 s later by a jump back: it was a false fix's onset,
/// which ends there, after the clean fix before it.
#[test]
fn a_ramp_end_that_a_later_jump_undoes_was_a_false_fixs_onset() {
    let spread = mems_ins();
    let (mut m, t) = pulled(spread, 0.01, Some(10));
    let z = Vector3::new(1.2, -0.8, 0.0);
    assert!(matches!(
        m.judge(t, &z, &hph(), &r(), 1.0),
        Judgement::RampEnd { .. }
    ));
    use_fix(&mut m, t, Some(-1.2), spread, false);
    for k in 1..4 {
        let tk = t.add_seconds(k as f64);
        assert_eq!(
            m.judge(tk, &Vector3::zeros(), &hph(), &r(), 1.0),
            Judgement::Clean
        );
        use_fix(&mut m, tk, None, spread, false);
    }
    match m.judge(t.add_seconds(4.0), &-z, &hph(), &r(), 1.0) {
        Judgement::FalseFixEnd { anchor, .. } => assert_eq!(anchor, t.add_seconds(-1.0)),
        other => panic!("the jump back: {other:?}"),
    }
}

/// A jump back to the level of an anchor seconds before is a ramp's
/// end only where that anchor can tell the two levels apart: with an
/// INS whose drift since it is tens of metres wide (tilt 1° over
/// 18 s), a 6 m jump is no nearer one level than the other and opens
/// an episode; with one of centimetres (0.01°) it is a ramp's end.
/// (comma2k19 with the IMU alone: a 30 m spike was followed as a
/// ramp's end against an anchor at σ 151 m.)
#[test]
fn a_jump_back_the_old_anchor_cannot_resolve_is_no_ramp_end() {
    let jump_back = |tilt_deg: f64| {
        let spread = StateSpread {
            vel_sd: Vector3::repeat(0.01),
            tilt_sd: tilt_deg.to_radians(),
            yaw_sd: 0.01f64.to_radians(),
            accel_bias_sd: 1e-3,
            gyro_bias_sd: 1e-6,
            speed_mps: 10.0,
        };
        // The fixes pull the state 0.5 m north a second from 6 s.
        let (mut m, t) = pulled(spread, 0.5, None);
        // 6 m back: where the fixes were before the pull.
        m.judge(t, &Vector3::new(6.0, 0.0, 0.0), &hph(), &r(), 1.0)
    };
    assert!(
        matches!(jump_back(0.01), Judgement::RampEnd { .. }),
        "{:?}",
        jump_back(0.01)
    );
    assert_eq!(jump_back(1.0), Judgement::Exclude(FaultReason::Jump));
}

/// The onset test measures a ramp from settled anchors only: the
/// first clean fixes after a reset (an episode the fixes outlasted)
/// follow an INS the episode had led off, and the fixes put its velocity
/// right over seconds, not over a count of fixes. With an onset test
/// calibrated on 130 s of clean fixes, fixes that the filter follows
/// north by 0.1 m a second are a ramp's onset within 8 s, at 1 Hz and
/// at 10 Hz; the same fixes right after a reset are not, at either rate
/// (at 10 Hz, five fixes after the reset span 0.4 s).
#[test]
fn an_onset_is_not_measured_from_the_first_fixes_after_a_reset() {
    let onset_within_8_s = |reset: bool, rate_hz: usize| {
        let mut m = FaultMonitor::new(0.04 / 60.0);
        m.onset_enabled = true;
        let t0 = GpsTime::from_week_sow(2300, 1000.0);
        let spread = StateSpread {
            speed_mps: 0.0,
            ..sharp_ins()
        };
        // The fix at k / rate_hz s whose innovation is `z_north` (m);
        // used, it moves the state that far north.
        let fix = |m: &mut FaultMonitor, k: usize, z_north: f64| {
            let t = t0.add_seconds(k as f64 / rate_hz as f64);
            let z = Vector3::new(z_north, 0.0, 0.0);
            let judged = m.judge(t, &z, &hph(), &r(), 1.0);
            if judged == Judgement::Clean {
                use_fix(m, t, Some(-z_north), spread, false);
            }
            judged
        };
        for k in 0..130 * rate_hz {
            assert_eq!(fix(&mut m, k, 0.0), Judgement::Clean);
        }
        assert_eq!(m.drift_test_scale(), Some(1.0), "calibrated");
        if reset {
            m.reset();
        }
        let ramp_step_m = -0.1 / rate_hz as f64;
        (130 * rate_hz..138 * rate_hz)
            .any(|k| matches!(fix(&mut m, k, ramp_step_m), Judgement::Onset { .. }))
    };
    for rate_hz in [1, 10] {
        assert!(onset_within_8_s(false, rate_hz), "{rate_hz} Hz");
        assert!(!onset_within_8_s(true, rate_hz), "{rate_hz} Hz, reset");
    }
}

/// The ledger: a GNSS correction the filter applied after the anchor
/// is taken out of the comparison (position, and velocity carried).
#[test]
fn corrections_after_the_anchor_are_taken_out() {
    let (mut m, t) = primed(3);
    // The state moved 0.5 m north and 0.1 m/s north at t (dx negative:
    // the state moves by −dx).
    let mut dx = vec![0.0; 21];
    dx[0] = -0.5;
    dx[3] = -0.1;
    m.record_correction(t, &dx, 0, 3);
    // Two seconds later the prediction carries +0.7 m north of the
    // free INS: an innovation of 0.7 m is no fault.
    let z = Vector3::new(0.7, 0.0, 0.0);
    let a = *m.anchors.back().expect("anchor");
    let (delta, _, _) = m.test(&a, &FixView::new(t.add_seconds(2.0), z, hph(), r(), 1.0));
    assert!(delta.norm() < 1e-9, "{delta:?}");
}
