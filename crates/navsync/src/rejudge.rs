//! The smoother re-judges the GNSS position fixes (issue 33, item 3).
//!
//! The forward fault monitor (`fusion::aid::integrity`) judges each fix
//! causally. A ramp (an offset growing over tens of seconds) passes it: over
//! that time a free MEMS INS drifts as a ramp does. What it sees is the
//! ramp's end, a jump back to the truth, and it then excludes the correct
//! fixes until their episode persists. A smoothed solution anchored by
//! clean fixes on both sides of a fault is accurate to centimetres, so
//! after the first forward–backward pass every position fix is tested
//! against the smoothed solution, in the manner of Baarda's data snooping
//! (Baarda, "A testing procedure for use in geodetic networks",
//! Netherlands Geodetic Commission, 1968) inside Teunissen's detection,
//! identification and adaptation (Teunissen, "An integrity and quality
//! control procedure for use in multi sensor integration", ION GPS 1990):
//!
//! - a fix the pass used, by its smoothed residual e = z − H x̂ˢ, whose
//!   covariance is R − H Pˢ Hᵀ (a least-squares residual's covariance is
//!   the observation's minus the adjusted observation's; floored at 10 %
//!   of R, where R − H Pˢ Hᵀ is near singular);
//! - a fix the pass excluded, by its innovation against the smoothed state,
//!   covariance R + H Pˢ Hᵀ;
//!
//! each per axis plus the monitor's 5 cm floor for the multipath a stated
//! RTK σ leaves out, the sum divided by the fixes' a-posteriori variance
//! factor (the used fixes' median statistic over χ²₃'s median, at least
//! 1: a receiver whose σ are optimistic) and tested against the χ²₃
//! quantile at the monitor's false-alarm rate. Identification among fixes that mask each
//! other is by alternative hypotheses for each forward episode of more
//! than one fix (a jump, then excluded fixes), tested by smoothing under
//! them (Teunissen's identification by the hypotheses' own tests):
//!
//! - A, the monitor's: the fixes after the jump are the fault (pass 1);
//! - B: the jump ended a fault the monitor followed (a ramp): pass 2
//!   excludes the used fixes up to [`RAMP_WINDOW_S`] before the jump and
//!   uses the episode's. B stands when every other fix from the window's
//!   start to [`CHECK_AFTER_S`] after the jump is consistent with pass 2's
//!   smoothed solution; then the window's fixes consistent with it are
//!   used again;
//! - C, when B falls for an episode that persisted (the monitor followed
//!   the new level) and a fix after it was inconsistent with pass 1's
//!   solution: the persisted level up to that fix was the fault.
//!
//! Where B falls, pass 1's verdicts are restored. The decisions are forced
//! on the forward filter (`GnssDecision`): excluded, or used at the stated
//! σ without the monitor or the robust weights. A pass runs only when a
//! verdict changed, at most [`MAX_PASSES`] in all; a run whose verdicts
//! still change after the last says so in its diagnostics. When the
//! verdicts come back to pass 1's, pass 1's solution is kept.
#![warn(missing_docs)]

use std::collections::BTreeMap;

use nalgebra::Vector3;
use serde::Serialize;

use crate::error::{Diagnostics, Error};
use crate::filter::gnss::GnssFix;
use crate::fusion::{FaultReason, FixRecord, FixStatus, Fusion, GnssDecision};
use crate::smoother::Smoothed;
use crate::time::GpsTime;

/// How far before a persisted episode's jump the fixes are suspected of a
/// fault the monitor followed (s): the longest ramp `navsync faults` draws
/// by default (25 s) with margin.
pub const RAMP_WINDOW_S: f64 = 30.0;
/// Forward–backward passes at most (the first included).
pub const MAX_PASSES: usize = 3;
/// A window's hypothesis is checked on the fixes up to this long after
/// its jump (s) or to its episode's end: long enough to see a false fix
/// end (8–15 s by default in `navsync faults`), short of the next fault.
const CHECK_AFTER_S: f64 = 20.0;
/// R − H Pˢ Hᵀ of a used fix is floored at this share of R.
const USED_FLOOR: f64 = 0.1;
/// A fix farther than this from the nearest smoothed epoch is not tested (s).
const MAX_EPOCH_GAP_S: f64 = 0.5;

/// What the re-judgement did (in `summary.json`'s stats).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RejudgeSummary {
    /// Forward–backward passes run.
    pub passes: usize,
    /// Fixes the first pass used that the smoothed solution excluded.
    pub excluded: usize,
    /// Fixes the first pass excluded that the smoothed solution used.
    pub readmitted: usize,
    /// Fixes whose verdict still changed after the last pass.
    pub unsettled: usize,
}

/// A position record's use and reason, by fix time.
type Judged = BTreeMap<GpsTime, (bool, FaultReason)>;

fn judged(records: &[FixRecord]) -> Judged {
    records
        .iter()
        .filter(|r| r.kind == "position" && r.reason != FaultReason::Stale)
        .map(|r| (r.time, (r.status != FixStatus::Rejected, r.reason)))
        .collect()
}

/// The χ²₃ statistic of every judged fix against the smoothed solution,
/// by fix time (see the module's header). `tau_state`: the fixes' time
/// tags are corrected by the smoothed time offset.
pub(crate) fn test_fixes(
    smoothed: &mut Smoothed,
    fixes: &[GnssFix],
    judged: &Judged,
    lever_b: &Vector3<f64>,
    n: usize,
    tau_state: bool,
) -> Result<BTreeMap<GpsTime, f64>, Error> {
    let mut order: Vec<&GnssFix> = fixes
        .iter()
        .filter(|f| judged.contains_key(&f.time))
        .collect();
    order.sort_by_key(|f| f.time);
    let floor2 = crate::fusion::FIX_CHANGE_FLOOR_M.powi(2);
    let mut out = BTreeMap::new();
    let mut next = 0usize;
    smoothed.for_each(|ep| {
        while let Some(fix) = order.get(next) {
            let valid = if tau_state {
                fix.time.add_seconds(-ep.time_offset_s)
            } else {
                fix.time
            };
            if valid > ep.nav.time {
                break;
            }
            next += 1;
            let dt = ep.nav.time.seconds_since(valid);
            let Some(&(used, _)) = judged.get(&fix.time) else {
                continue;
            };
            if dt > MAX_EPOCH_GAP_S {
                continue;
            }
            // Innovation (predicted − measured) at the epoch, carried back
            // to the fix's time along the smoothed velocity.
            let obs = crate::filter::gnss::position(&ep.nav, fix, lever_b, n);
            let mut t = 0.0;
            for i in 0..3 {
                let z = obs.z[i] - ep.nav.vel[i] * dt;
                let r = fix.pos_sd[i] * fix.pos_sd[i];
                let hph = ep.p_pos[(i, i)].max(0.0);
                let s = if used {
                    (r - hph).max(USED_FLOOR * r)
                } else {
                    r + hph
                } + floor2;
                t += z * z / s;
            }
            out.insert(fix.time, (t, used));
        }
        Ok(())
    })?;
    // The fixes' a-posteriori variance factor, robustly: the median of the
    // used fixes' statistics over χ²₃'s median (2.366), at least 1. Fixes
    // noisier than stated (a receiver's optimistic σ) would otherwise be
    // taken for faults; a fault is a minority of the fixes.
    let mut used_t: Vec<f64> = out.values().filter(|v| v.1).map(|v| v.0).collect();
    let factor = if used_t.is_empty() {
        1.0
    } else {
        let mid = used_t.len() / 2;
        let (_, m, _) = used_t.select_nth_unstable_by(mid, f64::total_cmp);
        (*m / CHI2_3_MEDIAN).max(1.0)
    };
    Ok(out.into_iter().map(|(k, v)| (k, v.0 / factor)).collect())
}

/// The median of χ² with 3 degrees of freedom.
const CHI2_3_MEDIAN: f64 = 2.366;

/// Whether each judged fix should be used after the tests.
fn verdicts(
    current: &Judged,
    tests: &BTreeMap<GpsTime, f64>,
    threshold: f64,
) -> BTreeMap<GpsTime, bool> {
    current
        .iter()
        .map(|(t, (used, _))| (*t, tests.get(t).map_or(*used, |s| *s <= threshold)))
        .collect()
}

/// The second hypothesis for one forward episode: the fixes before its
/// jump were the fault.
struct Window {
    /// The window's fixes (excluded) and the episode's (used).
    suspects: Vec<GpsTime>,
    episode: Vec<GpsTime>,
    /// An episode that persisted: the fixes after it within
    /// [`RAMP_WINDOW_S`] of its jump, up to another episode (the third
    /// hypothesis's).
    followers: Vec<GpsTime>,
    /// The span whose fixes must all be consistent for the hypothesis to
    /// stand: the window's start to [`CHECK_AFTER_S`] after the jump or
    /// the episode's end.
    span: (GpsTime, GpsTime),
}

/// The windows before the first pass's episodes of more than one fix
/// (a jump, then a run of excluded fixes, ended by a persisted fix, by the
/// monitor's ramp-end test, by the fixes coming back or by the data's end).
fn windows(first_records: &[FixRecord]) -> Vec<Window> {
    let pos: Vec<&FixRecord> = first_records
        .iter()
        .filter(|r| r.kind == "position" && r.reason != FaultReason::Stale)
        .collect();
    let excluded = |r: &FixRecord| {
        r.status == FixStatus::Rejected && matches!(r.reason, FaultReason::Jump | FaultReason::Run)
    };
    let mut out = Vec::new();
    let mut k = 0;
    while k < pos.len() {
        let persisted_alone = pos[k].reason == FaultReason::Persisted
            && pos[k].status != FixStatus::Rejected
            && (k == 0 || !excluded(pos[k - 1]));
        let opens = pos[k].reason == FaultReason::Jump && excluded(pos[k]);
        if !(opens || persisted_alone) {
            k += 1;
            continue;
        }
        let j = k;
        k += 1;
        while k < pos.len() && pos[k].reason == FaultReason::Run && excluded(pos[k]) {
            k += 1;
        }
        let persisted =
            persisted_alone || (k < pos.len() && pos[k].reason == FaultReason::Persisted);
        if k < pos.len() && pos[k].reason == FaultReason::Persisted {
            k += 1;
        }
        if k - j < 2 && !persisted_alone {
            continue; // a spike
        }
        let jump = pos[j].time;
        let suspects: Vec<GpsTime> = pos[..j]
            .iter()
            .rev()
            .take_while(|w| {
                jump.seconds_since(w.time) <= RAMP_WINDOW_S && w.status != FixStatus::Rejected
            })
            .map(|w| w.time)
            .collect();
        let Some(&start) = suspects.last() else {
            continue;
        };
        let episode: Vec<GpsTime> = pos[j..k].iter().map(|r| r.time).collect();
        let end = pos[k - 1].time.max(jump.add_seconds(CHECK_AFTER_S));
        let followers = if persisted {
            pos[k..]
                .iter()
                .take_while(|f| {
                    f.time.seconds_since(jump) <= RAMP_WINDOW_S
                        && !matches!(f.reason, FaultReason::Jump | FaultReason::Run)
                })
                .map(|f| f.time)
                .collect()
        } else {
            Vec::new()
        };
        out.push(Window {
            suspects,
            episode,
            followers,
            span: (start, end),
        });
    }
    out
}

/// The decisions forced on the next forward pass: every judged fix of the
/// first pass, excluded or used, its reason kept where the first pass
/// agreed.
fn decisions(first: &Judged, want: &BTreeMap<GpsTime, bool>) -> BTreeMap<GpsTime, GnssDecision> {
    first
        .iter()
        .map(|(t, (used, reason))| {
            let d = match (want.get(t).copied().unwrap_or(*used), used) {
                (false, true) => GnssDecision::Exclude(FaultReason::SmootherExcluded),
                (false, false) => GnssDecision::Exclude(*reason),
                (true, false) => GnssDecision::Follow(FaultReason::SmootherReadmitted),
                (true, true) if *reason == FaultReason::Persisted => GnssDecision::Follow(*reason),
                (true, true) => GnssDecision::Keep,
            };
            (*t, d)
        })
        .collect()
}

/// The smoothed solution with the fixes re-judged: smooths the first
/// forward pass (`fusion`, its `records` and the `fixes` it was given),
/// tests the fixes, and while a verdict changes (at most [`MAX_PASSES`]
/// passes) runs the forward filter again through `rerun` with the
/// decisions forced and smooths that. Returns the last smoothed solution,
/// its fix records, what was done and the notes for the run.
pub(crate) fn smooth_rejudged(
    fusion: &mut Fusion,
    records: &[FixRecord],
    fixes: &[GnssFix],
    lever_b: &Vector3<f64>,
    mut rerun: impl FnMut(BTreeMap<GpsTime, GnssDecision>) -> Result<(Fusion, Vec<FixRecord>), Error>,
) -> Result<(Smoothed, Vec<FixRecord>, RejudgeSummary, Diagnostics), Error> {
    let n = fusion.state_layout().n();
    let tau_state = fusion.state_layout().index_of("time_offset").is_some();
    let threshold = crate::stats::chi2_quantile(1.0 - crate::fusion::FALSE_ALARM_PROB, 3.0);
    let first = judged(records);
    let mut smoothed = fusion.smooth()?;
    let mut current_records = records.to_vec();
    let mut summary = RejudgeSummary {
        passes: 1,
        ..Default::default()
    };
    let mut notes = Diagnostics::with_cap(100);
    let windows = windows(records);
    // The first smoothed solution's verdicts, restored where a window's
    // hypothesis falls.
    let mut first_verdicts = BTreeMap::new();
    let mut first_smoothed: Option<Smoothed> = None;
    loop {
        let current = judged(&current_records);
        let tests = test_fixes(&mut smoothed, fixes, &current, lever_b, n, tau_state)?;
        let mut want = verdicts(&current, &tests, threshold);
        match summary.passes {
            // The second hypothesis for every episode.
            1 => {
                first_verdicts = want.clone();
                for w in &windows {
                    for t in &w.suspects {
                        want.insert(*t, false);
                    }
                    for t in &w.episode {
                        want.insert(*t, true);
                    }
                }
            }
            // A hypothesis stands when every fix around it but its
            // suspects and other episodes' is consistent with its smoothed
            // solution; otherwise the first solution's verdicts there are
            // restored.
            2 => {
                for w in &windows {
                    let stands = current
                        .range(w.span.0..=w.span.1)
                        .filter(|(t, _)| {
                            !w.suspects.contains(t)
                                && (w.episode.contains(t)
                                    || first.get(t).is_some_and(|f| {
                                        !matches!(f.1, FaultReason::Jump | FaultReason::Run)
                                    }))
                        })
                        .all(|(t, _)| tests.get(t).is_none_or(|s| *s <= threshold));
                    if stands {
                        continue;
                    }
                    for (t, _) in current.range(w.span.0..=w.span.1) {
                        if let Some(v) = first_verdicts.get(t) {
                            want.insert(*t, *v);
                        }
                    }
                    // The third hypothesis, for an episode that persisted
                    // and was followed until a fix the first smoothed
                    // solution found inconsistent: the persisted level was
                    // the fault, up to that fix.
                    let evidence = w
                        .followers
                        .iter()
                        .position(|t| first_verdicts.get(t) == Some(&false));
                    if let Some(i) = evidence {
                        for t in w.episode.iter().chain(&w.followers[..i]) {
                            want.insert(*t, false);
                        }
                        for t in &w.followers[i..] {
                            want.insert(*t, true);
                        }
                    }
                }
            }
            _ => {}
        }
        let changed = want
            .iter()
            .filter(|(t, w)| current.get(t).map(|c| c.0) != Some(**w))
            .count();
        if changed == 0 {
            break;
        }
        if summary.passes == MAX_PASSES {
            summary.unsettled = changed;
            notes.note(format!(
                "the smoother's re-judgement of the GNSS fixes did not settle in {MAX_PASSES} passes: \
                 {changed} fixes are still inconsistent with the smoothed solution or were excluded \
                 and are consistent with it; the smoothed solution near them is uncertain"
            ));
            break;
        }
        if summary.passes > 1
            && want
                .iter()
                .all(|(t, w)| first.get(t).map(|f| f.0) == Some(*w))
        {
            // Back to the first pass's judgement: its solution.
            if let Some(f) = first_smoothed.take() {
                smoothed = f;
                current_records = records.to_vec();
                break;
            }
        }
        let (mut f, recs) = rerun(decisions(&first, &want))?;
        let previous = std::mem::replace(&mut smoothed, f.smooth()?);
        if summary.passes == 1 {
            first_smoothed = Some(previous);
        }
        current_records = recs;
        summary.passes += 1;
    }
    for r in current_records.iter().filter(|r| r.kind == "position") {
        match r.reason {
            FaultReason::SmootherExcluded => summary.excluded += 1,
            FaultReason::SmootherReadmitted => summary.readmitted += 1,
            _ => {}
        }
    }
    if summary.passes > 1 {
        notes.note(format!(
            "the smoother re-judged the GNSS fixes against its solution ({} passes): {} fixes the forward \
             pass used were excluded, {} it excluded were used again (reasons smoother-excluded, \
             smoother-readmitted in gnss_residuals.txt)",
            summary.passes, summary.excluded, summary.readmitted
        ));
    }
    Ok((smoothed, current_records, summary, notes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(t_s: i64, status: FixStatus, reason: FaultReason) -> FixRecord {
        let time = GpsTime::from_week_ns(2000, t_s * 1_000_000_000);
        FixRecord {
            time,
            sow: time.sow(),
            kind: "position",
            innovation: [0.0; 3],
            sd: [0.02; 3],
            nis: 0.0,
            weight: [1.0; 3],
            status,
            reason,
            hpl_m: 0.0,
        }
    }

    /// 1 Hz fixes 0–99 s: used, except an episode at 60 s (a jump, two run
    /// fixes, then persisted) and a spike at 80 s.
    fn run_records() -> Vec<FixRecord> {
        (0..100)
            .map(|t| match t {
                60 => record(t, FixStatus::Rejected, FaultReason::Jump),
                61 | 62 => record(t, FixStatus::Rejected, FaultReason::Run),
                63 => record(t, FixStatus::DriftAccepted, FaultReason::Persisted),
                80 => record(t, FixStatus::Rejected, FaultReason::Jump),
                _ => record(t, FixStatus::Used, FaultReason::None),
            })
            .collect()
    }

    #[test]
    fn the_window_before_an_episode_and_its_followers() {
        let recs = run_records();
        let w = windows(&recs);
        // The spike (one fix) has no window.
        assert_eq!(w.len(), 1);
        let w = &w[0];
        let at = |t: i64| GpsTime::from_week_ns(2000, t * 1_000_000_000);
        // The used fixes less than 30 s before the jump: 31..=59 (30 s in
        // ns times 1e-9 is a hair above 30).
        assert_eq!(w.suspects.len(), 29);
        assert_eq!(*w.suspects.last().unwrap(), at(31));
        assert_eq!(w.suspects[0], at(59));
        assert_eq!(w.episode, (60..=63).map(at).collect::<Vec<_>>());
        // Followers up to 30 s after the jump, stopping at the spike (80).
        assert_eq!(w.followers, (64..80).map(at).collect::<Vec<_>>());
        // Checked up to 20 s after the jump.
        assert_eq!(w.span, (at(31), at(80)));
    }

    #[test]
    fn decisions_keep_the_first_reasons_and_mark_the_changes() {
        let recs = run_records();
        let first = judged(&recs);
        let mut want: BTreeMap<GpsTime, bool> = first.iter().map(|(t, j)| (*t, j.0)).collect();
        let at = |t: i64| GpsTime::from_week_ns(2000, t * 1_000_000_000);
        want.insert(at(50), false);
        want.insert(at(61), true);
        let d = decisions(&first, &want);
        assert_eq!(
            d[&at(50)],
            GnssDecision::Exclude(FaultReason::SmootherExcluded)
        );
        assert_eq!(
            d[&at(61)],
            GnssDecision::Follow(FaultReason::SmootherReadmitted)
        );
        assert_eq!(d[&at(62)], GnssDecision::Exclude(FaultReason::Run));
        assert_eq!(d[&at(63)], GnssDecision::Follow(FaultReason::Persisted));
        assert_eq!(d[&at(10)], GnssDecision::Keep);
        assert_eq!(d.len(), 100);
    }
}
