//! Rollback after a ramp's onset or end, a false fix's end, or a stale
//! run (issue 33).
//!
//! A slow ramp in the fixes is followed fix by fix: each step is within
//! the jump test, and the filter moves its position, velocity, attitude and
//! biases toward it. When the fault monitor finds the onset against a
//! clean fix seconds back ([`super::aid::integrity`]), taking back the
//! position and velocity the ramp's fixes moved is not enough: the
//! attitude and bias corrections they made stay, consistent with the
//! dragged velocity, and a MEMS INS then coasts metres off (measured,
//! docs/integrity.md). So the wrapper returns to the whole filter state
//! stored after that clean fix (or the one before it: states are kept at
//! most every [`STORE_SPACING_S`]) and runs the IMU samples since again,
//! without the ramp's fixes: the stored-state replay of
//! [`LatencyMode::DelayedState`] (`latency.rs`), used here to drop
//! measurements instead of adding a late one.
//!
//! A receiver that begins to repeat its position at rest and goes on as
//! the vehicle pulls away is the same case: its first repeats are within
//! the INS's drift and used, and they drag its velocity and biases to a
//! stop until the INS's own motion shows them stale, or until the run
//! ends far from the repeated position and near the INS run free from
//! the first write (`aid::gnss`). The
//! re-run returns to the state at or before the position's first write
//! and leaves the run's repeats out (stale) up to the one found stale: a
//! repeat carries no measurement the first write did not.
//!
//! A ramp the onset test did not see (a MEMS INS is no sharper than the
//! fixes over the seconds a ramp needs to show) is followed to its end,
//! where the fixes jump back. A jump from the clean level is judged again
//! here against the INS run free from each state kept
//! ([`ramp_start`]): a fix back from a ramp is where the IMU alone
//! carried the antenna from before it. The re-run returns to that state
//! and leaves the fixes since out (`ramp`, `run`) up to the jump, which
//! ends the episode.
//!
//! A jump that test leaves open (the free INS only twice nearer the fix
//! than the solution, or the ramp begun further back than it reaches) is
//! held as a ramp's end for [`HELD_S`] ([`HeldRampEnd`]): a false fix's
//! onset that a free INS drifted near ends, the fixes coming back; a
//! ramp's end stays, and the re-run then returns to before the ramp.
//!
//! A ramp the onset test found whose fixes were followed all the same
//! (the INS's predicted drift grew to cover their offset before the
//! ramp ended) is found at its end too: the first jump after is judged
//! against the INS run free from the onset's clean fix alone
//! ([`onset_ramp_end`]), not against the states kept since, which the
//! ramp's fixes had led.
//!
//! A false fix the filter was led onto (its episode persisted: the INS
//! could no longer tell its level from its own drift) is found at its
//! end, where a jump back undoes the jump that opened it
//! (`aid::integrity`'s `followed`): the re-run returns to the state after
//! the clean fix before it and leaves its fixes out (`jump`, `run`).
//!
//! A jump whose level persisted (the fixes held it until the INS could
//! no longer tell, `aid::integrity`'s `PersistedLevel`) is followed from
//! the jump: the re-run returns to the state before it and uses the
//! fixes since, which the filter had coasted past (an ICM-20602 at a
//! ramp's end it could not see: 19 s, 2–4 m off). So is a run of fixes
//! the robust weighting refused (the monitor no reference yet) that began
//! with a jump and that it then took for INS drift (`aid::gnss`'s
//! `robust_drift_check`): the re-run takes its first fix so.
//!
//! A re-run stores its states as the run does, so that a rollback it calls
//! for returns to them, not to those of the run it replaced.
//!
//! The state from now on, the smoother's record and the fixes' records
//! (`gnss_residuals.txt`: the ramp's fixes become `ramp`, `run`) are those
//! of the re-run. The solutions already returned stay as they were (a
//! causal filter cannot take back what it output), but the re-run's are
//! kept for a writer that holds its output back
//! (`Navigator::with_revised_output`, `fuse`'s files), so that the
//! written forward solution is not one a found fault led off (a stale run
//! from rest left it 43 m off for 9 s, at centimetre σ). Offline only, and only
//! with no dual-antenna heading, odometer or coarse time-offset search,
//! whose inputs would have to be replayed too; elsewhere the monitor makes
//! no onset test.

use super::aid::gnss::{FreeIns, fix_difference_3sd_m, free_drift_sd_m, free_drift_variance};
use super::aid::integrity::{EpisodeEnd, PersistedLevel, RAMP_END_MIN_LAG_S};
use super::jump_doubt::JumpDoubt;
use super::*;

/// A fix's jump is judged at once against the states kept this long (s)
/// back ([`ramp_start`]): the monitor's anchors reach back this
/// far.
const AT_ONCE_REACH_S: f64 = 21.0;
/// A ramp's end that the test at once leaves open (its start further
/// back, or the free INS not that much closer than the solution) is held
/// as a hypothesis ([`HeldRampEnd`]) against the states this far back
/// (s)…
pub(super) const HELD_REACH_S: f64 = 35.0;
/// …for this long (s) after its jump: a false fix's onset that a free INS
/// drifted near ends within it, with the fixes back at the clean level
/// (the episode its jump opened returns); a ramp's end stays.
const HELD_S: f64 = 20.0;
/// A held ramp end's fix is this many times closer to a free INS than to
/// the solution (at least two consecutive states, as [`RAMP_END_MIN_STATES`]).
const HELD_RATIO: f64 = 2.0;
/// States are kept this long (s).
pub(crate) const KEEP_S: f64 = HELD_REACH_S + HELD_S;
/// A state is stored after a clean fix at least this long (s) after the
/// last stored one: a rollback returns to the newest stored at or before
/// its anchor and judges the clean fixes since again. With 10 Hz fixes a
/// state after every one cost 2.3× the time and 3.5× the memory of the
/// whole run (`fuse` on a 600 s drive).
const STORE_SPACING_S: f64 = 0.9;

/// What a rollback takes back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Rollback {
    /// A ramp: the fixes after the clean fix `anchor` up to `onset`.
    Ramp { anchor: GpsTime, onset: GpsTime },
    /// A stale run: the repeats of the position first written at `since`,
    /// up to the one found stale at `until`.
    Stale { since: GpsTime, until: GpsTime },
    /// A ramp found at its end: the fixes after the clean fix `anchor`
    /// before the one at `end`, which jumped back to the anchor's level.
    RampEnded { anchor: GpsTime, end: GpsTime },
    /// A false fix the filter was led onto, found at its end: the fixes
    /// after the clean fix `anchor` before the one at `end`, whose jump
    /// back undid the one that opened them.
    FalseFixEnded { anchor: GpsTime, end: GpsTime },
    /// A ramp's end held [`HELD_S`] and confirmed: as `RampEnded`, from a
    /// state up to [`HELD_REACH_S`] before the jump; the jump's fix was
    /// fused at `at` with the innovation `jump` (predicted − measured,
    /// NED, m).
    HeldRampEnded {
        anchor: GpsTime,
        end: GpsTime,
        at: GpsTime,
        jump: Vector3<f64>,
    },
    /// A jump's episode that persisted: the fixes after the clean fix
    /// before it are judged again, the jump followed at once
    /// (`aid::integrity`'s `PersistedLevel`).
    LevelPersisted(PersistedLevel),
    /// A run of fixes the robust weighting took for INS drift, which began
    /// at `first` with a jump: the re-run takes it so from `first` on.
    DriftRunAccepted { first: GpsTime },
}

impl Rollback {
    /// The clean fix (the stale run's first write) whose state the re-run
    /// starts from.
    fn anchor(self) -> GpsTime {
        match self {
            Rollback::Ramp { anchor, .. }
            | Rollback::RampEnded { anchor, .. }
            | Rollback::FalseFixEnded { anchor, .. }
            | Rollback::HeldRampEnded { anchor, .. } => anchor,
            Rollback::Stale { since, .. } => since,
            Rollback::LevelPersisted(level) => level.anchor,
            // The newest state stored before it.
            Rollback::DriftRunAccepted { first } => first.add_seconds(-1e-6),
        }
    }
}

/// A fix's jump that may have ended a ramp the filter followed from
/// further back than the test at once reaches, or whose free INS was only
/// [`HELD_RATIO`] times closer than the solution: a false fix's onset that
/// a free INS drifted near is as likely there. The two differ in what
/// follows: a false fix ends, and the fixes jump back to the level before
/// (the episode its jump opened returns); a ramp's end stays. So the
/// hypothesis is held for [`HELD_S`], the filter going on as if the jump
/// were a fault, and confirmed if nothing undid it: the filter then
/// returns to the state before the ramp, as for a ramp's end found at
/// once. A false fix longer than [`HELD_S`] whose onset a free INS drifted
/// near would be taken for a ramp's end.
#[derive(Clone, Copy, Debug)]
pub(super) struct HeldRampEnd {
    /// The clean fix of the state whose free INS was nearest the fix.
    anchor: GpsTime,
    /// The fix that jumped, and the INS time it was fused at.
    jump: JumpCheck,
    from_free_m: f64,
}

/// A fix at a ramp's end is this many times closer to the INS run free
/// from before the ramp than to the solution the ramp had led off (as for
/// a stale run's end, `aid::gnss`). At 3, a 0.7 m false fix's onset was
/// 0.21 m from the INS run free for 11 s on the 1 Hz ADIS16465 drive,
/// and taken for a ramp's end.
const RAMP_END_RATIO: f64 = 4.0;
/// …and farther from the solution than this many σ of the free INS's
/// predicted drift since the state (λ-scaled): where the INS could have
/// drifted as far, a fix that jumped to where it drifted is as likely a
/// false fix (an ICM-20602 16 s free: σ 12.7 m; a 4 m false fix's onset
/// was 0.83 m from one such free INS).
const RAMP_END_DRIFT_K: f64 = 3.0;
/// A jump after a ramp onset's fixes were followed is that ramp's end
/// when it is at least this many times closer to the INS run free from
/// the onset's anchor than to the solution ([`onset_ramp_end`]).
const ONSET_END_RATIO: f64 = 1.0;
/// Consecutive stored states whose free INS must fit a ramp's end.
const RAMP_END_MIN_STATES: usize = 2;

/// A fix that jumped from the clean level, as the GNSS source saw it, for
/// [`ramp_start`].
#[derive(Clone, Copy, Debug)]
pub(super) struct JumpCheck {
    /// The fix's time, and the INS time it was fused at.
    pub(super) time: GpsTime,
    pub(super) at: GpsTime,
    pub(super) pos: Geodetic,
    pub(super) pos_sd: Vector3<f64>,
    /// Its innovation (predicted − measured, NED, m), and whether the
    /// monitor excluded it (it kept the solution).
    pub(super) innovation: Vector3<f64>,
    pub(super) excluded: bool,
}

impl JumpCheck {
    /// The fix's distance from the filter's predicted antenna (m).
    pub(super) fn distance_from_filter_m(&self) -> f64 {
        self.innovation.norm()
    }
}

/// The filter after a clean fix, with the smoother's record lengths then.
pub(super) struct Stored {
    /// The clean fix (anchor) it follows.
    anchor: GpsTime,
    core: Core,
    nodes: usize,
    tape: usize,
}

impl Fusion {
    /// Turns the monitor's onset test on where a rollback can follow it.
    pub(super) fn with_onset_test(mut self) -> Self {
        let cfg = self.cfg();
        let enabled = cfg.latency == LatencyMode::Offline
            && cfg.heading.is_none()
            && cfg.odometer.is_none()
            && self.search.is_none();
        self.core.aid.gnss.monitor.onset_enabled = enabled;
        self
    }

    /// After each returned solution: rolls back when the monitor found an
    /// onset; stores the state after each new clean fix; keeps the IMU
    /// samples the stored states may need.
    pub(super) fn after_sample(&mut self, sample: &ImuSample) -> Result<(), Error> {
        if !self.core.aid.gnss.monitor.onset_enabled {
            return Ok(());
        }
        self.imu_buffer.push_back(*sample);
        if let Some(check) = self.core.jump_check.take()
            && self.core.rollback_to.is_none()
        {
            // A later jump, either way, ends what the one held stood for;
            // the first after a ramp onset's fixes were followed may be
            // that ramp's end, if the states kept still reach its anchor
            // (a ramp longer than that is no longer found by its end).
            self.held_ramp_end = None;
            let onset_followed = self
                .core
                .aid
                .gnss
                .monitor
                .onset_followed
                .take()
                .filter(|anchor| check.at.seconds_since(*anchor) <= HELD_REACH_S);
            if check.distance_from_filter_m() > fix_difference_3sd_m(&check.pos_sd) {
                // The states kept since that onset's anchor stood on the
                // ramp's fixes (the filter followed them): no ramp starts
                // there (a re-run from one, after the fix persisted on
                // the ramp, coasted 1 m off at an HPL of 0.11 m).
                let fits = self.free_fits(&check, onset_followed);
                let at_once = self.first_within(check.at, AT_ONCE_REACH_S);
                if let Some((anchor, from_free_m)) =
                    ramp_start(&fits, &check, RAMP_END_RATIO, true, at_once)
                {
                    self.core.notes.push(format!(
                        "GNSS fix at {}: {:.2} m from the solution and {from_free_m:.2} m from where the IMU alone carried the antenna from the clean fix at {anchor}: the fixes since had drifted away (a ramp the filter followed); the filter returns to its state then and runs again without them",
                        check.time, check.distance_from_filter_m()
                    ));
                    self.core.rollback_to = Some(Rollback::RampEnded {
                        anchor,
                        end: check.time,
                    });
                } else {
                    if let Some((anchor, from_free_m)) =
                        ramp_start(&fits, &check, HELD_RATIO, false, 0)
                            .or_else(|| onset_followed.and_then(|_| onset_ramp_end(&fits, &check)))
                    {
                        self.held_ramp_end = Some(HeldRampEnd {
                            anchor,
                            jump: check,
                            from_free_m,
                        });
                    }
                    self.doubt_jump(&fits, &check);
                }
            }
        }
        if let Some(jump) = self.core.jump_in_episode.take() {
            self.doubt_jump_in_episode(jump);
        }
        self.judge_held_ramp_end(sample.time);
        self.follow_jump_doubts(sample.time);
        if let Some(rollback) = self.core.rollback_to.take() {
            // A re-run from before the held jump judges it again; one from
            // after it (an onset the ramp's dragged velocity brought on)
            // leaves it and the states before it as they were.
            // (A persisted level's re-run leaves its jump's hypotheses as
            // they were: it follows the fixes from the jump instead of
            // from when they persisted, and the held ramp end, confirmed,
            // returns to before it all the same.)
            if let Rollback::LevelPersisted(level) = rollback {
                self.follow_jump_doubt_from_jump(level.jump);
            } else {
                if self
                    .held_ramp_end
                    .is_some_and(|h| rollback.anchor() < h.jump.time)
                {
                    self.held_ramp_end = None;
                }
                self.drop_jump_doubts_since(rollback.anchor());
            }
            self.roll_back(rollback, sample.time)?;
            if let Rollback::HeldRampEnded { end, at, jump, .. } = rollback {
                self.doubt_level_after_held_ramp_end(end, at, jump);
            }
        }
        self.store_state();
        let oldest = sample.time.add_seconds(-KEEP_S);
        while self.rollback_states.len() > 1
            && self
                .rollback_states
                .front()
                .is_some_and(|s| s.anchor < oldest)
        {
            self.rollback_states.pop_front();
        }
        let keep_from = self
            .rollback_states
            .front()
            .map_or(sample.time, |s| s.core.nav.time);
        self.imu_buffer.drop_through(keep_from);
        let current = &self.core;
        self.applied
            .drop_while(|f| current.proc_time(f) <= keep_from);
        Ok(())
    }

    /// Stores the state after a new clean fix (at most every
    /// [`STORE_SPACING_S`]).
    fn store_state(&mut self) {
        let monitor = &self.core.aid.gnss.monitor;
        if let Some(anchor) = monitor.last_anchor_time()
            && self
                .rollback_states
                .back()
                .is_none_or(|s| anchor.seconds_since(s.anchor) >= STORE_SPACING_S)
        {
            let (nodes, tape) = self.recorder.as_ref().map_or((0, 0), |r| r.lengths());
            self.rollback_states.push_back(Stored {
                anchor,
                core: self.core.clone(),
                nodes,
                tape,
            });
        }
    }

    /// Returns to the newest state stored after a clean fix at or before
    /// the ramp's anchor (the stale run's first write) and runs the
    /// samples since again, the ramp's fixes (the run's repeats up to the
    /// one found stale) excluded.
    /// Without such a state (it was not kept), nothing is done: the
    /// episode stands, without the rollback.
    fn roll_back(&mut self, rollback: Rollback, now: GpsTime) -> Result<(), Error> {
        let anchor = rollback.anchor();
        let reach_s = match rollback {
            Rollback::HeldRampEnded { .. }
            | Rollback::LevelPersisted(_)
            | Rollback::DriftRunAccepted { .. } => KEEP_S,
            _ => AT_ONCE_REACH_S,
        };
        let first = self.first_within(now, reach_s);
        let Some(k) = self
            .rollback_states
            .iter()
            .rposition(|s| s.anchor <= anchor)
            .filter(|&k| k >= first)
        else {
            return Ok(());
        };
        self.rollback_states.truncate(k + 1);
        let stored = &self.rollback_states[k];
        let mut core = stored.core.clone();
        if let Some(rec) = self.recorder.as_mut() {
            rec.truncate(stored.nodes, stored.tape)?;
        }
        core.notes = std::mem::take(&mut self.core.notes);
        match rollback {
            Rollback::Ramp { anchor, onset } => core.aid.gnss.monitor.replay_ramp(anchor, onset),
            Rollback::Stale { since, until } => core.aid.gnss.replay_stale(since, until),
            Rollback::RampEnded { anchor, end } | Rollback::HeldRampEnded { anchor, end, .. } => {
                core.aid.gnss.monitor.replay_ramp_end(anchor, end)
            }
            Rollback::FalseFixEnded { anchor, end } => {
                core.aid.gnss.monitor.replay_false_fix_end(anchor, end)
            }
            Rollback::LevelPersisted(level) => core.aid.gnss.monitor.replay_persisted_level(level),
            Rollback::DriftRunAccepted { first } => core.aid.gnss.replay_drift_accept = Some(first),
        }
        // Fixes pushed after the state was stored are queued again.
        super::latency::requeue_applied(&self.applied, &mut core);
        let replay = self.samples_after(core.nav.time);
        self.core = core;
        let mut revised = self.revisions.as_ref().map(|_| Vec::new());
        for s in &replay {
            let out = self.core.push_imu(s)?;
            self.store_nodes()?;
            if let (Some(rec), Some(o)) = (self.recorder.as_mut(), &out) {
                rec.push_nav(&o.nav)?;
            }
            // A rollback the re-run calls for returns to its states, not
            // to those of the run it replaced (which had judged the fixes
            // before it otherwise); the states after one it calls for are
            // replaced anyway.
            if self.core.rollback_to.is_none() {
                self.store_state();
            }
            if let (Some(list), Some(o)) = (revised.as_mut(), out) {
                list.push(self.revised(o));
            }
        }
        // A jump in the re-run was judged when its fix first came.
        self.core.jump_check = None;
        self.core.jump_in_episode = None;
        if let (Some(slot), Some(list)) = (self.revisions.as_mut(), revised) {
            *slot = list;
        }
        self.drain_notes();
        Ok(())
    }

    /// The INS run free (the IMU alone) from each state kept at least
    /// [`RAMP_END_MIN_LAG_S`] and at most [`HELD_REACH_S`] before the fix
    /// in `check`, and at or before the clean fix `newest` if given,
    /// against that fix ([`ramp_start`]): computed once for the test at
    /// once and the held hypothesis.
    fn free_fits(&self, check: &JumpCheck, newest: Option<GpsTime>) -> Vec<FreeFit> {
        let old_enough = |s: &(usize, &Stored)| {
            check.time.seconds_since(s.1.anchor) >= RAMP_END_MIN_LAG_S
                && newest.is_none_or(|n| s.1.anchor <= n)
        };
        let first = self.first_within(check.at, HELD_REACH_S);
        self.rollback_states
            .iter()
            .enumerate()
            .skip(first)
            .take_while(old_enough)
            .map(|(index, stored)| {
                let core = &stored.core;
                let drift_sd_m = free_drift_sd_m(
                    free_drift_variance(core),
                    core.aid.gnss.overconfidence_scale(),
                    check.at.seconds_since(core.nav.time),
                );
                FreeFit {
                    index,
                    anchor: stored.anchor,
                    from_free_m: self.free_distance(core, check),
                    drift_bound_m: RAMP_END_DRIFT_K * drift_sd_m,
                }
            })
            .collect()
    }

    /// Holds a jump as a doubt ([`JumpDoubt`]) from the oldest state kept
    /// up to [`HELD_REACH_S`] before it, not from the one whose INS run
    /// free was nearest its fix: that is no sure start of a ramp (a MEMS
    /// INS in turns drifts past its model: the fix back from a 24 s ramp
    /// on the 1 Hz ADIS16465 drive was 4.5–7.4 m from the INS run free
    /// from before it and 1.5 m from the solution; on the 10 Hz drive the
    /// nearest was a state on the ramp). A jump the monitor did not
    /// exclude (it took it for a ramp's end or for drift: the filter
    /// follows the fixes after it, its σ grown to fit) is a doubt about
    /// the solutions before it only.
    fn doubt_jump(&mut self, fits: &[FreeFit], check: &JumpCheck) {
        let start = fits
            .first()
            .map_or(check.at.add_seconds(-HELD_REACH_S), |f| f.anchor);
        if let Some(mut doubt) = JumpDoubt::new(start, check.time, check.at, check.innovation) {
            if !check.excluded {
                doubt.close(check.at);
            }
            self.jump_doubts.push(doubt);
        }
    }

    /// The index of the first stored state at most `reach_s` before `now`,
    /// or of the last if all are older (as the states kept were before
    /// they were kept longer than [`AT_ONCE_REACH_S`]).
    fn first_within(&self, now: GpsTime, reach_s: f64) -> usize {
        let oldest = now.add_seconds(-reach_s);
        self.rollback_states
            .iter()
            .position(|s| s.anchor >= oldest)
            .unwrap_or(self.rollback_states.len().saturating_sub(1))
    }

    /// Drops a held ramp end that the fixes undid (the episode its jump
    /// opened returned: the fixes came back to the level before it, a
    /// false fix or a spike) or that a rollback replaced; confirms one
    /// held [`HELD_S`].
    fn judge_held_ramp_end(&mut self, now: GpsTime) {
        let Some(held) = self.held_ramp_end else {
            return;
        };
        let jump_sow = held.jump.time.sow();
        let undone = self
            .core
            .aid
            .gnss
            .monitor
            .episodes
            .iter()
            .rev()
            .take_while(|e| e.start_sow >= jump_sow)
            .any(|e| e.start_sow == jump_sow && e.end == EpisodeEnd::Returned);
        if undone {
            self.held_ramp_end = None;
            return;
        }
        if now.seconds_since(held.jump.at) < HELD_S || self.core.rollback_to.is_some() {
            return;
        }
        self.held_ramp_end = None;
        self.core.notes.push(format!(
            "GNSS fix at {}: {:.2} m from the solution and {:.2} m from where the IMU alone carried the antenna from the clean fix at {}, and the fixes stayed at its level for {HELD_S:.0} s: the fixes before it had drifted away (a ramp the filter followed); the filter returns to its state then and runs again without them",
            held.jump.time, held.jump.distance_from_filter_m(), held.from_free_m, held.anchor
        ));
        self.core.rollback_to = Some(Rollback::HeldRampEnded {
            anchor: held.anchor,
            end: held.jump.time,
            at: held.jump.at,
            jump: held.jump.innovation,
        });
    }

    /// Says so of a held ramp end the data ended before it was judged
    /// (called when the run ends).
    pub(super) fn note_unresolved_ramp_end(&mut self) {
        let Some(held) = self.held_ramp_end.take() else {
            return;
        };
        self.diag.note(format!(
            "GNSS fix at {}: {:.2} m from the solution and {:.2} m from where the IMU alone carried the antenna from the clean fix at {}: either the fixes before it had drifted away (a ramp's end) or it began a false fix; the data ended {:.0} s after it, before the fixes could tell (a false fix's end comes back to the level before it), so the monitor's judgement stands (the fixes after it excluded until their level persisted) and the forward solution from {} on may be off by about {:.1} m (the smoothed solution weighs both sides)",
            held.jump.time,
            held.jump.distance_from_filter_m(),
            held.from_free_m,
            held.anchor,
            self.now.seconds_since(held.jump.at),
            held.anchor,
            held.jump.distance_from_filter_m()
        ));
    }

    /// The distance (m) of the fix in `check` from the antenna of the INS
    /// run free from `from` over the samples kept since, to the time the
    /// fix was fused at.
    fn free_distance(&self, from: &Core, check: &JumpCheck) -> f64 {
        let mut free = FreeIns::from_core(from);
        let start = from.nav.time;
        let mut prev = start;
        for s in self.imu_buffer.iter().filter(|s| s.time > start) {
            let dt = (s.time - prev) as f64 * 1e-9;
            if s.time <= check.at {
                free.step(&s.dtheta, &s.dvel, dt);
                prev = s.time;
                continue;
            }
            let frac = (check.at - prev) as f64 / (s.time - prev) as f64;
            if frac > 0.0 {
                free.step(&(s.dtheta * frac), &(s.dvel * frac), dt * frac);
            }
            break;
        }
        free.antenna_from(&check.pos, &from.lever_b).norm()
    }

    /// A re-run's solution with its auxiliary figures: the state σ and
    /// position covariance as of the last covariance propagation (at most
    /// `cov_step_s` old: propagating for each would change the re-run).
    fn revised(&self, out: NavOutput) -> Revised {
        // As written in the forward run (`Fusion::written_figures`).
        let (sd, position_covariance) = self.figures_as_propagated();
        Revised {
            out,
            offset: self.time_offset(),
            sd,
            position_covariance,
        }
    }

    /// Keeps the solutions of each rollback's re-run for
    /// [`Self::take_revision`] (a writer that holds its output back).
    /// Nothing is kept where there is no rollback (real time).
    pub(crate) fn keep_revisions(&mut self) {
        if self.core.aid.gnss.monitor.onset_enabled {
            self.revisions = Some(Vec::new());
        }
    }

    /// Whether [`Self::keep_revisions`] took effect.
    pub(crate) fn keeps_revisions(&self) -> bool {
        self.revisions.is_some()
    }

    /// The solutions of the last rollback's re-run, oldest first, when one
    /// ran since the last call: they replace those returned from the first
    /// one's time on (the last is the current sample's).
    pub(crate) fn take_revision(&mut self) -> Option<Vec<Revised>> {
        let list = self.revisions.as_mut()?;
        (!list.is_empty()).then(|| std::mem::take(list))
    }
}

/// A stored state's INS run free to a jump's fix ([`Fusion::free_fits`]).
struct FreeFit {
    /// The state's place among those kept, and its clean fix.
    index: usize,
    anchor: GpsTime,
    /// The fix's distance from the free INS's antenna (m), and
    /// [`RAMP_END_DRIFT_K`] σ of the free INS's predicted drift
    /// (λ-scaled, m).
    from_free_m: f64,
    drift_bound_m: f64,
}

/// Whether a fix that jumped from the clean level ended a ramp the
/// filter had followed, and where the ramp began. Two hypotheses meet
/// at such a jump: the fixes before it had drifted away (a ramp) and
/// this one is back, or the fixes were right and this one is off (a
/// false fix's onset, a spike). The INS run free (the IMU alone) from
/// a state stored seconds back tells them apart: a ramp's end is
/// [`RAMP_END_RATIO`] times closer to it than to the solution the
/// ramp had led off, farther from that solution than 3 σ of a fix
/// difference (checked before any INS is run), and farther than the
/// free INS could have drifted by its own predicted σ ([`RAMP_END_DRIFT_K`]: where it could have drifted
/// as far, a false fix may sit where it drifted). The distances are
/// compared with each other, not the free INS's with a bound of its
/// own (its drift model was measured optimistic in a MEMS INS's turns),
/// and the INS is run, not the monitor's ledger undone (which leaves
/// in the attitude that the ramp's fixes corrected). States
/// before the ramp fit; those on it do not (the ramp's fixes had
/// dragged their velocity), nor, by their drift, those long before it.
/// A run of [`RAMP_END_MIN_STATES`] fitting states is needed, not one:
/// a single state's free INS drifts by its own errors (metres in 20 s
/// in a MEMS INS's turns), and one of many may land near a false fix
/// by chance. Judged on the states from the `first` kept on (the test at
/// once reaches [`AT_ONCE_REACH_S`] back), with `ratio` in place of
/// [`RAMP_END_RATIO`], and the drift bound only with `drift_bound`.
/// Returns the clean fix of the state whose free INS is nearest the fix
/// (the ramp's start), and that distance.
fn ramp_start(
    fits: &[FreeFit],
    check: &JumpCheck,
    ratio: f64,
    drift_bound: bool,
    first: usize,
) -> Option<(GpsTime, f64)> {
    let mut run: Vec<(GpsTime, f64)> = Vec::new();
    let mut best: Option<(GpsTime, f64)> = None;
    let mut close_run = |run: &mut Vec<(GpsTime, f64)>| {
        if run.len() >= RAMP_END_MIN_STATES {
            for &(anchor, d) in run.iter() {
                if best.is_none_or(|(_, b)| d < b) {
                    best = Some((anchor, d));
                }
            }
        }
        run.clear();
    };
    for fit in fits.iter().filter(|f| f.index >= first) {
        if fit.from_free_m * ratio < check.distance_from_filter_m()
            && (!drift_bound || check.distance_from_filter_m() > fit.drift_bound_m)
        {
            run.push((fit.anchor, fit.from_free_m));
        } else {
            close_run(&mut run);
        }
    }
    close_run(&mut run);
    best
}

/// A jump after a ramp's onset whose episode persisted: the onset test
/// found the fixes drifting away from the INS run from the clean fix
/// `onset_anchor` (beyond its drift, at the test's calibrated false-alarm
/// rate), and the fixes were followed again only when the INS's drift
/// model could no longer tell, not because they came back. A jump after
/// that is then more likely the ramp's end than a false fix's onset (that
/// would need the onset to have been a false alarm too), and a fix closer
/// to where the IMU alone carried the antenna from that anchor than to
/// the solution the followed fixes led ([`ONSET_END_RATIO`]) is held as a
/// ramp's end ([`HeldRampEnd`]): a false fix ends within [`HELD_S`] and
/// undoes it. On the 10 Hz ADIS16465 drive a ramp found at its onset and
/// followed from 12 s on ended 2.07 m from the solution and 1.27 m from
/// the INS run free from the onset's anchor (a ratio of 1.6, under
/// [`HELD_RATIO`]): the solution stayed on the ramp's level, 2.2 m off,
/// until the fixes after the end persisted. `fits` are those of the
/// states kept at or before the anchor; judged against the newest (None
/// if there is none).
fn onset_ramp_end(fits: &[FreeFit], check: &JumpCheck) -> Option<(GpsTime, f64)> {
    let fit = fits.last()?;
    (fit.from_free_m * ONSET_END_RATIO < check.distance_from_filter_m())
        .then_some((fit.anchor, fit.from_free_m))
}

/// A solution of a rollback's re-run, with what the auxiliary output
/// writes beside it.
pub(crate) struct Revised {
    pub(crate) out: NavOutput,
    pub(crate) offset: Option<TimeOffsetState>,
    pub(crate) sd: Vec<f64>,
    pub(crate) position_covariance: Matrix3<f64>,
}
