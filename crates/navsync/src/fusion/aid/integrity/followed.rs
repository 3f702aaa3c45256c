//! A false fix found at its end, after the fixes were followed onto it
//! (issue 33).
//!
//! An episode persists when the INS's predicted drift grows to cover the
//! fixes' offset: it can no longer tell the new level from its own drift,
//! and the fixes are followed again. Over the seconds a false RTK fix
//! lasts, a MEMS INS run free does drift that far (the 1 Hz ADIS16465
//! test-track drive: 0.3 m in 6 s in a turn), so a false fix of
//! decimetres is often followed. When it ends, the fixes jump back, and
//! the filter, now on the false level, takes the good fixes for a new
//! fault (measured: a 0.7 m false fix at 130 s left the solution 0.9 m
//! off for 30 s, 0.256 m RMS against the oracle's 0.072 m).
//!
//! The jump back tells the two levels apart where the INS's absolute
//! position cannot: a jump is measured against the INS's displacement
//! over a second, sharp to centimetres however far the INS drifted. A
//! constant false fix opens with a jump Δ₁ and ends with one Δ₂ = −Δ₁;
//! a real change of level (a receiver moving between solutions, an INS
//! that did drift) has no jump back that undoes it. So a jump from the
//! followed level whose sum with the opening jump is within both jumps'
//! test variance (χ²₃ at [`super::FALSE_ALARM_PROB`]) and less than half
//! the jump ends the false fix: the time-differenced test of the parent
//! module (after Joerger & Pervan 2013) applied to the episode's two
//! edges. Offline the wrapper then returns to the state after the clean
//! fix before the episode and runs again without the fixes since
//! (`fusion/rollback.rs`); in real time the fix is weighed as any fix is
//! (not excluded as a jump from the false level).
//!
//! A jump the monitor took for a ramp's end (back to the level of the
//! fixes seconds before, [`Judgement::RampEnd`]) is followed at once; when
//! a later jump undoes it, it was a false fix's onset, and ends the same
//! way (measured: a 1.5 m false fix 160 s into the ADIS16465 drive, taken
//! for a ramp's end, was followed and then held the clean fixes after it
//! off for 40 s, 0.961 m RMS against the oracle's 0.048 m).
//!
//! A level that persisted is followed from the jump that opened it, not
//! from the fix it persisted at ([`PersistedLevel`]). The episode held the
//! jump as a hypothesis (a false fix's onset) while the INS was the
//! sharper reference; once it persisted, the fixes stayed put for as long
//! as a false fix would have ended and the INS can no longer tell, and
//! the evidence is for the level, from its first fix. Coasting on until
//! then is the costly answer where the jump was a ramp's end the INS could
//! not see: an ICM-20602 led along a 24 s ramp refused the good fixes
//! back from it for 19 s while it drifted 2–4 m off (`drive-icm20602`
//! bed seed 2: 0.612 m RMS against the oracle's 0.386 m). Offline the
//! wrapper returns to the state before the jump and runs again with the
//! fixes since used; a false fix's end, the jump back, is watched for as
//! before and undoes it all.

use nalgebra::Vector3;

use super::*;

/// A level the monitor followed at once (taken for a ramp's end) is a
/// false fix's only once this many clean fixes held it: a level of one
/// fix between two jumps is a receiver flipping between two bad levels
/// (±0.3 m every second: taken for a false fix's end, the fix back, as
/// bad, was used and the good ones after it excluded for 7 s). A level
/// followed after an episode of excluded fixes has held already: one fix
/// on it is enough (asked of those too, 4 of the placed sweep's 96 false
/// fixes, followed for their last fix, were missed; asked to hold 2 s, 12).
pub(super) const LEVEL_HELD_MIN_FIXES: usize = 2;

/// An episode the fixes were followed out of (persisted), while its end
/// may still come.
#[derive(Copy, Clone, Debug)]
pub(super) struct Followed {
    /// The clean fix before the episode.
    pub(super) anchor: GpsTime,
    /// The episode's first fix, and the one followed from.
    pub(super) start: GpsTime,
    pub(super) followed_from: GpsTime,
    /// The opening jump Δ₁ and its test's variance per axis.
    pub(super) level: Vector3<f64>,
    pub(super) level_var: Vector3<f64>,
    /// Clean fixes that must hold the level before a jump can undo it.
    pub(super) min_held: usize,
}

/// Whether `jump` (variance `jump_var` per axis) undoes the jump `level`
/// that opened an episode (variance `level_var`): their sum within both
/// tests' variance (χ²₃ at [`super::FALSE_ALARM_PROB`]) and shorter than
/// [`RAMP_END_CLOSER`] times the jump.
pub(super) fn undoes(
    jump: &Vector3<f64>,
    jump_var: &Vector3<f64>,
    level: &Vector3<f64>,
    level_var: &Vector3<f64>,
) -> bool {
    let undone = jump + level;
    let d_undone: f64 = (0..3)
        .map(|i| undone[i] * undone[i] / (jump_var[i] + level_var[i]))
        .sum();
    d_undone <= fix_test_threshold() && undone.norm() <= RAMP_END_CLOSER * jump.norm()
}

impl Followed {
    /// The episode `ep`, persisted at the fix at `time`.
    pub(super) fn from_episode(ep: &Episode, time: GpsTime) -> Self {
        Followed {
            anchor: ep.anchor.time,
            start: ep.start,
            followed_from: time,
            level: ep.level,
            level_var: ep.level_var,
            min_held: 1,
        }
    }
}

impl FaultMonitor {
    /// Whether the level the fixes were followed onto at the fault episode
    /// that began at `episode_sow` (GPS seconds of week) is still watched
    /// for the jump back that would make it a false fix: at most
    /// [`MAX_EPISODE_S`] after the episode's start, until a jump undoes it
    /// or another level is followed.
    pub(in crate::fusion) fn watches_followed_level(&self, episode_sow: f64, now: GpsTime) -> bool {
        self.followed.is_some_and(|f| {
            (f.start.sow() - episode_sow).abs() < 1e-6
                && now.seconds_since(f.start) <= MAX_EPISODE_S
        })
    }

    /// Whether the fix (innovation `z`, as for [`Self::judge`]) jumped back
    /// from the level of the episode followed last, undoing its opening
    /// jump: then that level was a false fix, which ends here (see the
    /// module's notes). Needs clean fixes on the followed level (for one
    /// taken for a ramp's end, [`LEVEL_HELD_MIN_FIXES`]), the last within
    /// [`JUMP_MAX_GAP_S`] before, to measure the jump against; an episode
    /// older than [`MAX_EPISODE_S`] is forgotten.
    pub(super) fn false_fix_end(&mut self, fix: &FixView) -> Option<Judgement> {
        let time = fix.time;
        let f = self.followed?;
        if time.seconds_since(f.start) > MAX_EPISODE_S {
            self.followed = None;
            return None;
        }
        let last = self.anchors.back().copied()?;
        let held = self
            .anchors
            .iter()
            .filter(|a| a.time >= f.followed_from)
            .count();
        if held < f.min_held || time.seconds_since(last.time) > JUMP_MAX_GAP_S {
            return None;
        }
        let (delta, d, v) = self.test(&last, fix);
        if d <= fix_test_threshold() || !undoes(&delta, &v, &f.level, &f.level_var) {
            return None;
        }
        self.followed = None;
        // The anchors since stay: with the ledger they still measure the
        // INS's displacement (offline the re-run from before the episode
        // replaces them; forgotten, the monitor let 5 more of a receiver's
        // flips of ±0.3 m through in real time).
        Some(Judgement::FalseFixEnd {
            anchor: f.anchor,
            offset: delta,
        })
    }

    /// Prepares a false fix's re-run from a state stored at or before the
    /// clean fix `anchor`: the fixes after it and before `end` were the
    /// false fix's (the first a jump, the others its run), and the fix at
    /// `end` is back at the clean level.
    pub(in crate::fusion) fn replay_false_fix_end(&mut self, anchor: GpsTime, end: GpsTime) {
        self.replay_onset = Some((anchor, end));
        self.replay_return = Some(end);
        self.replay_jump = true;
    }
}

/// A jump's episode that persisted (not an onset's: that holds its own
/// anchor, `onset_followed`), followed again from the jump on in a
/// re-run from the state before it (offline, `fusion/rollback.rs`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(in crate::fusion) struct PersistedLevel {
    /// The clean fix before the jump, and the jump's fix.
    pub(in crate::fusion) anchor: GpsTime,
    pub(in crate::fusion) jump: GpsTime,
    /// Why it persisted, and the episode as it closed.
    by: PersistedBy,
    record: FaultEpisode,
}

impl PersistedLevel {
    /// The level of `ep`, which persisted `by` as the monitor's last
    /// closed episode: to be followed from its jump where a re-run can
    /// (the onset test's condition), this is no such re-run, and the fix
    /// it persisted at held the level: as sharp as the clean fix before
    /// the jump, and with the fix before it (and there was a fix before it
    /// in the episode: one persisted at the fix after its jump coasted
    /// for one fix interval only). (One that cannot tell is no
    /// evidence the level held: on dataset2 a real float fix at σ 0.5 m,
    /// 1.1 m off the 12th fix of a 0.8 m false fix at σ 1 cm, persisted
    /// its episode; followed from its jump, the false fix cost 0.305 →
    /// 0.319 m RMS.)
    pub(super) fn of(monitor: &FaultMonitor, ep: &Episode, by: PersistedBy) -> Option<Self> {
        if !monitor.onset_enabled || monitor.replay_level.is_some() || ep.fixes < 2 || !ep.steady {
            return None;
        }
        Some(PersistedLevel {
            anchor: ep.anchor.time,
            jump: ep.start,
            by,
            record: *monitor.episodes.last()?,
        })
    }
}

impl FaultMonitor {
    /// The level that persisted at the fix judged last, if any (cleared
    /// by the call).
    pub(in crate::fusion) fn take_persisted_level(&mut self) -> Option<PersistedLevel> {
        self.persisted_level.take()
    }

    /// Prepares a persisted level's re-run from a state stored at or
    /// before its anchor: the fixes are judged again as they were up to
    /// the jump, which is followed at once.
    pub(in crate::fusion) fn replay_persisted_level(&mut self, level: PersistedLevel) {
        self.replay_level = Some(level);
    }

    /// In a persisted level's re-run, the jump (excluded again, opening
    /// its episode) persists at once, for the same reason as first, and
    /// the episode's record is the one the first run closed; the fixes
    /// after it are judged as after any persisted episode (the INS no
    /// reference until clean fixes rebuild it).
    pub(super) fn follow_replayed_level(
        &mut self,
        time: GpsTime,
        judgement: Judgement,
    ) -> Judgement {
        let Some(level) = self.replay_level else {
            return judgement;
        };
        if time < level.jump {
            return judgement;
        }
        let out = match (judgement, self.episode) {
            (Judgement::Exclude(FaultReason::Jump), Some(ep)) if ep.start == time => {
                let out = self.end_unresolved(ep, level.by, time, ep.level);
                if let Some(last) = self.episodes.last_mut() {
                    *last = level.record;
                }
                out
            }
            _ => judgement,
        };
        self.replay_level = None;
        out
    }
}
