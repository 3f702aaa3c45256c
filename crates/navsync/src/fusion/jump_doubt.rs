//! A jump the fixes have not yet decided, carried into the σ written
//! (issue 33).
//!
//! A fix that jumps from the clean level is either a false fix's onset or
//! a spike (the solution right, the fix off) or a ramp's end (the fixes
//! before it had drifted, the solution had followed them, and this one is
//! back). The monitor keeps the solution and excludes the jump; the
//! rollback (`rollback.rs`) returns to before the ramp when the INS run
//! free from there tells the two apart, at once or after
//! [`super::rollback`]'s hold. Where it cannot (a MEMS INS drifts as far
//! as the ramp over the seconds the ramp takes), the forward solution
//! written over the ramp is off by up to the jump at the centimetre σ of
//! the fixes it followed: on the bed's drives 1.3–1.9 m against a 6 σ
//! protection level of 3–10 cm, the wrong answer that looks right.
//!
//! So each such jump, and each jump inside a fault episode, is held as a
//! doubt ([`JumpDoubt`]) while the solutions it concerns are held back
//! (`Navigator::with_revised_output`): the σ written for them (std.txt,
//! the position covariance) carry the error the other hypothesis gives,
//! along the jump, and the fixes' protection levels in
//! gnss_residuals.txt carry it as a bias. That error grows linearly from
//! the state kept `rollback::HELD_REACH_S` before the jump (the
//! farthest a rollback reaches: any shorter ramp is covered) to the
//! jump's size at the jump, and on at the same rate after it (the ramp's
//! fixes dragged the solution's velocity) until the fixes are followed
//! again. From then on the solution stands on the level followed, off by
//! the jump should that level be a false fix, and the doubt holds the
//! jump's size while the fault monitor still watches that level for the
//! jump back that would say so (`aid::integrity::followed`: at most
//! `MAX_EPISODE_S` after the episode began). The error bound under a
//! fault hypothesis is the fault's bias plus the fault-free K σ, as in
//! solution separation (Brenner, "Integrated GPS/inertial fault detection
//! availability", Navigation 43(2), 1996). The doubt is dropped when the
//! fixes decide: the episode returns
//! (the fixes came back: a false fix or a spike; the solution was right),
//! or a rollback returns to before the jump (a ramp's end found: its
//! re-run is written instead). A doubt the data ends before is carried
//! by the smoothed σ too (`pipeline::smooth_stage`). Offline only, as the
//! rollback.

use super::aid::integrity::{EpisodeEnd, MAX_EPISODE_S};
use super::*;

/// A fix that jumped again inside a fault episode, as the GNSS source saw
/// it ([`Fusion::doubt_jump_in_episode`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct JumpInEpisode {
    /// The fix's time, and the INS time it was fused at.
    pub(crate) time: GpsTime,
    pub(crate) at: GpsTime,
    /// Predicted − measured (NED, m).
    pub(crate) innovation: Vector3<f64>,
    /// The episode's first excluded fix.
    pub(crate) episode_start: GpsTime,
}

/// A jump (from the clean level, or inside a fault episode) that neither
/// the tests nor the fixes since have decided.
#[derive(Clone, Copy, Debug)]
pub(crate) struct JumpDoubt {
    /// Where the other hypothesis's error begins: the oldest state kept
    /// up to `rollback::HELD_REACH_S` before the jump.
    start: GpsTime,
    /// The jump's fix, and the INS time it was fused at.
    fix: GpsTime,
    at: GpsTime,
    /// The GPS seconds of week of the start of the fault episode whose
    /// end decides it: the one the jump opened, or the one it jumped in.
    episode_sow: f64,
    /// The jump (m) and its direction (NED unit vector, predicted −
    /// measured).
    size_m: f64,
    unit: Vector3<f64>,
    /// When the fixes were followed again (the episode persisted, the
    /// monitor took the jump for a ramp's end, or the episode ran longer
    /// than the IMU can bridge).
    until: Option<GpsTime>,
    /// Whether the fault monitor watches the level followed (released when
    /// it stops); otherwise the doubt holds until `MAX_EPISODE_S` after
    /// the jump.
    watched: bool,
    /// When the monitor stopped watching the level the fixes were followed
    /// onto for the jump back that would make it a false fix. Until then
    /// the solution, moved onto that level, is off by the jump should the
    /// level be false, while its σ shrank to the fixes' (dataset2 with
    /// ADIS16465, a 0.8 m false fix followed after 8 s: 0.79 m off at a
    /// 6 σ protection level of 0.16–0.46 m for 5 s).
    released: Option<GpsTime>,
}

impl JumpDoubt {
    /// The doubt about a jump of `innovation` (predicted − measured, NED,
    /// m) at the fix `fix`, fused at `at`, over the solutions from `start`;
    /// none without a finite size, a direction or a span before the jump.
    pub(super) fn new(
        start: GpsTime,
        fix: GpsTime,
        at: GpsTime,
        innovation: Vector3<f64>,
    ) -> Option<Self> {
        if at.seconds_since(start) <= 0.0 {
            return None;
        }
        Self::along(start, fix, at, innovation)
    }

    /// The doubt about the level a confirmed ramp's end followed (the fix
    /// at `fix`, fused at `at`, jumped by `innovation`, predicted −
    /// measured): should it have been a false fix's onset, the solutions
    /// after it are off by the jump. None before it (the re-run excluded
    /// the fixes before it; its σ grew as it coasted). Held until
    /// `MAX_EPISODE_S` after the jump: the span a level followed is watched
    /// for the jump back, which the re-run's monitor no longer does.
    pub(super) fn level_followed(
        fix: GpsTime,
        at: GpsTime,
        innovation: Vector3<f64>,
    ) -> Option<Self> {
        let mut doubt = Self::along(at, fix, at, innovation)?;
        doubt.until = Some(at);
        doubt.watched = false;
        Some(doubt)
    }

    /// An open, watched doubt along `innovation`; none without a finite
    /// size or a direction.
    fn along(start: GpsTime, fix: GpsTime, at: GpsTime, innovation: Vector3<f64>) -> Option<Self> {
        let size_m = innovation.norm();
        if !size_m.is_finite() {
            return None;
        }
        Some(JumpDoubt {
            start,
            fix,
            at,
            episode_sow: fix.sow(),
            size_m,
            unit: innovation.try_normalize(1e-9)?,
            until: None,
            watched: true,
            released: None,
        })
    }

    /// The fixes were followed again from `t` on: the error is the jump
    /// from then until [`Self::release`].
    pub(super) fn close(&mut self, t: GpsTime) {
        self.until = Some(t);
    }

    /// The level followed is no longer in doubt from `t` on (the monitor
    /// stopped watching it).
    pub(super) fn release(&mut self, t: GpsTime) {
        self.released.get_or_insert(t);
    }

    /// Whether the fixes were followed again and the level followed is
    /// still in doubt.
    fn is_held(&self) -> bool {
        self.until.is_some() && self.released.is_none()
    }

    /// The other hypothesis's error (m) at `t`, along [`Self::unit`]:
    /// growing linearly from [`Self::start`] to the jump at the jump and on
    /// at the same rate; the jump itself from when the fixes were followed
    /// again until the level followed was released.
    fn error_m(&self, t: GpsTime) -> f64 {
        let since_start_s = t.seconds_since(self.start);
        if since_start_s < 0.0
            || t.seconds_since(self.at) > MAX_EPISODE_S
            || self.released.is_some_and(|r| t > r)
        {
            return 0.0;
        }
        let ramp_s = self.at.seconds_since(self.start);
        match self.until {
            Some(u) if t > u => self.size_m,
            // A step (`level_followed`): the jump from the jump on.
            _ if ramp_s <= 0.0 => self.size_m,
            _ => self.size_m * since_start_s / ramp_s,
        }
    }
}

impl Fusion {
    /// Follows each open doubt's episode at `now`: dropped when it
    /// returned (the fixes came back to the level before the jump), closed
    /// when the fixes were followed again, released when the monitor no
    /// longer watches the level they were followed onto.
    pub(super) fn follow_jump_doubts(&mut self, now: GpsTime) {
        let monitor = &self.core.aid.gnss.monitor;
        let episodes = &monitor.episodes;
        self.jump_doubts.retain_mut(|d| {
            if d.is_held() {
                if d.watched && !monitor.watches_followed_level(d.episode_sow, now) {
                    d.release(now);
                }
                return true;
            }
            if d.until.is_some() {
                return true;
            }
            let Some(e) = episodes.iter().rev().find(|e| e.start_sow == d.episode_sow) else {
                return true;
            };
            match e.end {
                EpisodeEnd::Returned => false,
                EpisodeEnd::Open => true,
                EpisodeEnd::Persisted | EpisodeEnd::Unbridged => {
                    d.close(d.fix.add_seconds(e.end_sow - d.fix.sow()));
                    true
                }
            }
        });
    }

    /// Holds a jump inside a fault episode as a doubt over the solutions
    /// from `rollback::HELD_REACH_S` before it, decided with the
    /// episode: a ramp's onset found after the filter had followed the
    /// ramp for seconds returns it to a state the ramp had dragged, and
    /// the fixes jump back at the ramp's end inside the onset's episode
    /// (`drive-adis16465` held-out seed 10: 2.15 m off at an HPL of
    /// 0.86 m when the jump came).
    pub(super) fn doubt_jump_in_episode(&mut self, jump: JumpInEpisode) {
        let start = jump.at.add_seconds(-super::rollback::HELD_REACH_S);
        if let Some(mut doubt) = JumpDoubt::new(start, jump.time, jump.at, jump.innovation) {
            doubt.episode_sow = jump.episode_start.sow();
            self.jump_doubts.push(doubt);
        }
    }

    /// Says, for each doubt that stood, which solutions' σ it widened
    /// (called when the run ends).
    pub(super) fn note_jump_doubts(&mut self) {
        for d in &self.jump_doubts {
            let until = match (d.until, d.released) {
                (None, _) => "the data's end (at most 60 s on)".to_string(),
                (Some(u), _) if !d.watched => format!(
                    "{u} and on, the level followed from then in doubt until 60 s after the jump (or the data's end)"
                ),
                (Some(u), None) => format!(
                    "{u} (the level followed from then watched until the data's end, at most 60 s after the jump)"
                ),
                (Some(u), Some(r)) if r > u => {
                    format!("{u} (the level followed from then watched until {r})")
                }
                (Some(u), Some(_)) => u.to_string(),
            };
            self.diag.note(format!(
                "GNSS fix at {}: jumped {:.2} m, and the fixes did not tell a ramp's end (the solution had followed drifting fixes before it) from a false fix's onset (the fixes after it off); the σ and protection levels written from {} to {} carry up to that offset along the jump",
                d.fix, d.size_m, d.start, until
            ));
        }
    }

    /// Drops the doubts about jumps after the fix `anchor`: a rollback
    /// returning to the state after it runs them again.
    pub(super) fn drop_jump_doubts_since(&mut self, anchor: GpsTime) {
        self.jump_doubts.retain(|d| d.fix <= anchor);
    }

    /// A persisted level's re-run follows the fixes from the jump at
    /// `jump` on: its doubt holds the jump's size from the jump, not from
    /// when the level persisted, and the doubts about jumps inside its
    /// episode, whose fixes the re-run follows, are dropped.
    pub(super) fn follow_jump_doubt_from_jump(&mut self, jump: GpsTime) {
        self.jump_doubts.retain(|d| d.fix <= jump);
        for d in self.jump_doubts.iter_mut().filter(|d| d.fix == jump) {
            d.until = Some(d.at);
        }
    }

    /// Holds the level a confirmed ramp's end followed as a doubt
    /// ([`JumpDoubt::level_followed`]): the ramp's end was held
    /// `rollback::HELD_S` because the INS run free from before the ramp
    /// was only twice nearer the fix than the solution, and a false fix
    /// that outlasts the hold reads the same (the 1 Hz ADIS16465
    /// test-track drive, a 0.7 m false fix from 200 s on: the 18 good
    /// fixes before it were taken for a ramp, and the solution on the
    /// false level was written at a protection level of 0.09–0.11 m).
    /// Kept in the order of the jumps.
    pub(super) fn doubt_level_after_held_ramp_end(
        &mut self,
        fix: GpsTime,
        at: GpsTime,
        innovation: Vector3<f64>,
    ) {
        if let Some(doubt) = JumpDoubt::level_followed(fix, at, innovation) {
            let k = self.jump_doubts.partition_point(|d| d.at <= doubt.at);
            self.jump_doubts.insert(k, doubt);
        }
    }

    /// The covariance (m², NED) the doubts add to the solution at `t`;
    /// `None` when there is none.
    pub(crate) fn doubt_covariance(&self, t: GpsTime) -> Option<Matrix3<f64>> {
        doubt_covariance(&self.jump_doubts, t)
    }

    /// The doubts the data ended before the fixes decided (their episode
    /// still open): the smoothed solution, which has no fixes after them
    /// either, carries them too.
    pub(crate) fn undecided_jumps(&self) -> Vec<JumpDoubt> {
        self.jump_doubts
            .iter()
            .filter(|d| d.until.is_none())
            .copied()
            .collect()
    }

    /// The horizontal protection level of each fix record with the
    /// doubts' horizontal error at its time added: a protection level
    /// under a fault hypothesis is the fault's bias plus the fault-free
    /// K σ (Blanch, Walter, Enge et al., "Advanced RAIM user algorithm
    /// description", ION GNSS 2012).
    pub(super) fn widen_protection_levels(&self, records: &mut [FixRecord]) {
        let Some(first) = self.jump_doubts.iter().map(|d| d.start).min() else {
            return;
        };
        for r in records.iter_mut() {
            let t = first.add_seconds(r.sow - first.sow());
            let bias_h_m: f64 = doubts_reaching(&self.jump_doubts, t)
                .map(|d| d.error_m(t) * d.unit.xy().norm())
                .sum();
            r.hpl_m += bias_h_m;
        }
    }
}

/// The doubts whose jump was at most [`MAX_EPISODE_S`] before `t` (none
/// older reaches it), newest first: they are kept in the order of their
/// jumps, so a long run's are not all read for each solution.
fn doubts_reaching(doubts: &[JumpDoubt], t: GpsTime) -> impl Iterator<Item = &JumpDoubt> {
    doubts
        .iter()
        .rev()
        .take_while(move |d| t.seconds_since(d.at) <= MAX_EPISODE_S)
}

/// The covariance (m², NED) `doubts` add to a solution at `t`: each
/// one's error along its jump, squared; `None` when none reaches `t`.
pub(crate) fn doubt_covariance(doubts: &[JumpDoubt], t: GpsTime) -> Option<Matrix3<f64>> {
    let mut sum: Option<Matrix3<f64>> = None;
    for d in doubts_reaching(doubts, t) {
        let e = d.error_m(t);
        if e > 0.0 {
            *sum.get_or_insert_with(Matrix3::zeros) += d.unit * d.unit.transpose() * (e * e);
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 m jump north-east 20 s after the doubt's start: the other
    /// hypothesis's error grows linearly to the jump at the jump and on
    /// at the same rate, along the jump; the jump itself once the fixes
    /// were followed again, until the level is released; nothing before
    /// the start or past an episode's longest.
    #[test]
    fn a_doubt_is_the_ramp_the_jump_would_have_ended() {
        let t = |s: f64| GpsTime::from_week_sow(2300, 100_000.0 + s);
        let innovation = Vector3::new(3.0, 3.0, 0.0) / 2f64.sqrt();
        let mut d = JumpDoubt::new(t(0.0), t(20.0), t(20.0), innovation).unwrap();
        let doubts = [d];
        assert!(doubt_covariance(&doubts, t(-1.0)).is_none());
        for (s, error_m) in [(10.0, 1.5), (20.0, 3.0), (30.0, 4.5)] {
            let c = doubt_covariance(&doubts, t(s)).unwrap();
            assert!((c.trace().sqrt() - error_m).abs() < 1e-9, "{s}: {c}");
            // Along the jump: north and east alike, fully correlated.
            assert!((c[(0, 0)] - c[(1, 1)]).abs() < 1e-9 && (c[(0, 1)] - c[(0, 0)]).abs() < 1e-9);
            assert_eq!(c[(2, 2)], 0.0);
        }
        assert!(doubt_covariance(&doubts, t(20.0 + MAX_EPISODE_S + 1.0)).is_none());
        // Followed again at 25 s: the solution on the level followed is
        // off by the jump itself, should it be false, until released.
        d.close(t(25.0));
        let held = [d];
        let at =
            |doubts: &[JumpDoubt], s: f64| doubt_covariance(doubts, t(s)).map(|c| c.trace().sqrt());
        assert!((at(&held, 24.0).unwrap() - 3.6).abs() < 1e-9);
        assert!((at(&held, 26.0).unwrap() - 3.0).abs() < 1e-9);
        d.release(t(30.0));
        d.release(t(40.0));
        let released = [d];
        assert!((at(&released, 30.0).unwrap() - 3.0).abs() < 1e-9);
        assert!(
            at(&released, 31.0).is_none(),
            "released at the first release"
        );
        // The level a confirmed ramp's end followed: nothing before the
        // jump, the jump from it on, until 60 s after it (no monitor
        // releases it).
        let step = JumpDoubt::level_followed(t(20.0), t(20.0), innovation).unwrap();
        assert!(!step.watched);
        let step = [step];
        assert!(at(&step, 19.9).is_none());
        for s in [20.0, 21.0, 19.9 + MAX_EPISODE_S] {
            let e = at(&step, s);
            assert!(e.is_some_and(|e| (e - 3.0).abs() < 1e-9), "{s}: {e:?}");
        }
        assert!(at(&step, 20.1 + MAX_EPISODE_S).is_none());
        assert!(JumpDoubt::level_followed(t(20.0), t(20.0), Vector3::zeros()).is_none());
        // No doubt without a direction or a span before the jump.
        assert!(JumpDoubt::new(t(0.0), t(20.0), t(20.0), Vector3::zeros()).is_none());
        assert!(JumpDoubt::new(t(20.0), t(20.0), t(20.0), innovation).is_none());
        let corrupt = Vector3::new(f64::NAN, 1.0, 0.0);
        assert!(JumpDoubt::new(t(0.0), t(20.0), t(20.0), corrupt).is_none());
    }
}
