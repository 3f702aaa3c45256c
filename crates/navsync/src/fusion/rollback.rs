//! Rollback after a ramp's onset or a stale run (issue 33).
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

use super::*;

/// States are kept this long (s): the monitor's anchors reach back this far.
const KEEP_S: f64 = 21.0;
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
        if let Some(rollback) = self.core.rollback_to.take() {
            self.roll_back(rollback)?;
        }
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

    /// Returns to the newest state stored after a clean fix at or before
    /// the ramp's anchor (the stale run's first write) and runs the
    /// samples since again, the ramp's fixes (the run's repeats up to the
    /// one found stale) excluded.
    /// Without such a state (it was not kept), nothing is done: the
    /// episode stands, without the rollback.
    fn roll_back(&mut self, rollback: Rollback) -> Result<(), Error> {
        let anchor = match rollback {
            Rollback::Ramp { anchor, .. } => anchor,
            Rollback::Stale { since, .. } => since,
        };
        let Some(k) = self
            .rollback_states
            .iter()
            .rposition(|s| s.anchor <= anchor)
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
            if let (Some(list), Some(o)) = (revised.as_mut(), out) {
                list.push(self.revised(o));
            }
        }
        if let (Some(slot), Some(list)) = (self.revisions.as_mut(), revised) {
            *slot = list;
        }
        self.drain_notes();
        Ok(())
    }

    /// A re-run's solution with its auxiliary figures: the state σ and
    /// position covariance as of the last covariance propagation (at most
    /// `cov_step_s` old: propagating for each would change the re-run).
    fn revised(&self, out: NavOutput) -> Revised {
        let f = &self.core.filter;
        Revised {
            out,
            offset: self.time_offset(),
            sd: (0..f.n()).map(|i| f.sd(i)).collect(),
            position_covariance: self.position_covariance(),
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

/// A solution of a rollback's re-run, with what the auxiliary output
/// writes beside it.
pub(crate) struct Revised {
    pub(crate) out: NavOutput,
    pub(crate) offset: Option<TimeOffsetState>,
    pub(crate) sd: Vec<f64>,
    pub(crate) position_covariance: Matrix3<f64>,
}
