//! Stale receiver output: a position repeated to the last bit while the
//! antenna moved, judged at each repeat and when the run ends (issue 33).

use super::*;

/// Where a run of identical fix positions began (see `is_stale`).
#[derive(Clone, Copy)]
pub(super) struct RepeatStart {
    pub(super) time: GpsTime,
    /// The solution after the first fix of the run.
    pub(super) nav_pos: Geodetic,
    /// The INS's predicted displacement-error variance running free from
    /// then, t² (c₂ + c₃ t + c₄ t²) in the time t since (m²): see
    /// [`free_drift_variance`].
    pub(super) drift_var_coeffs: [f64; 3],
}

/// A run of repeats ended by a new position is judged stale when the new
/// position is this many times closer to the free INS's antenna than to
/// the repeated position (see `judge_run_end`).
const RUN_END_RATIO: f64 = 4.0;

/// A run of repeats is judged at its end only when it lasted this long
/// (s, first write to last repeat). Shorter runs moved the solution
/// little (the robust weighting bounds each repeat), and a receiver that
/// writes each solution twice (10 Hz output of 5 Hz solutions) would
/// otherwise roll the filter back at every other fix at walking speed:
/// measured 166 rollbacks and 75× the time on a 240 s drive.
const RUN_END_MIN_S: f64 = 1.0;

impl GnssSource {
    /// When a new position ends a run of repeats that were used: were they
    /// stale? A receiver that repeats its position truly (a static hold, a
    /// coarse resolution) does so while the antenna stays within a cell of
    /// it, so the new position is near the repeated one; a stale output
    /// repeats while the antenna goes on, and the new position is where
    /// the IMU alone carried it from the first write (`FreeIns`). So the
    /// run was stale when the new position left the repeated one by more
    /// than the receiver's resolution and 3 σ of the difference of two
    /// fixes of the new one's σ, and is
    /// [`RUN_END_RATIO`] times closer to the free INS's antenna: the
    /// likelier hypothesis by far, with no model of the INS's drift needed
    /// (the test the repeats themselves could not make while they held
    /// the solution and dragged the INS to a stop: a receiver repeating
    /// from rest as its vehicle pulls away). Offline, the filter returns to
    /// its state before the run and runs again with the run stale
    /// (`rollback.rs`).
    pub(super) fn judge_run_end(&mut self, core: &mut Core, fix: &GnssFix) {
        let (Some(free), Some((last_time, repeated)), Some(start)) =
            (self.free_ins.as_ref(), self.last_fix, self.repeat_since)
        else {
            return;
        };
        if self.repeats_used == 0
            || !self.monitor.onset_enabled
            || core.rollback_to.is_some()
            || last_time.seconds_since(start.time) < RUN_END_MIN_S
        {
            return;
        }
        let le = LocalEarth::new(&fix.pos, &core.nav.vel);
        let left_repeated_m = le
            .geodetic_delta_to_ned(
                repeated.lat_rad - fix.pos.lat_rad,
                repeated.lon_rad - fix.pos.lon_rad,
                repeated.h_m - fix.pos.h_m,
            )
            .norm();
        let from_free_m = free.antenna_from(&fix.pos, &core.lever_b).norm();
        let fix_sd_m = fix_difference_3sd_m(&fix.pos_sd);
        if !(left_repeated_m > self.resolution_bound_m().max(fix_sd_m)
            && from_free_m * RUN_END_RATIO < left_repeated_m)
        {
            return;
        }
        core.notes.push(format!(
            "GNSS fix at {}: the position repeated since {} was stale: the new one is {left_repeated_m:.2} m from it and {from_free_m:.2} m from where the IMU alone carried the antenna; the filter returns to its state before the {} repeats used and runs again without them",
            fix.time, start.time, self.repeats_used
        ));
        core.rollback_to = Some(Rollback::Stale {
            since: start.time,
            until: last_time,
        });
        self.repeats_used = 0;
    }

    /// Prepares a rollback's re-run: the repeats of the position first
    /// written at `since`, up to the one at `until`, are stale.
    pub(in crate::fusion) fn replay_stale(&mut self, since: GpsTime, until: GpsTime) {
        self.replay_stale = Some((since, until));
    }

    /// Adds an update's position and velocity corrections to
    /// `repeat_corrections` (error-state convention: the state moved by
    /// −dx).
    pub(super) fn note_correction(&mut self, time: GpsTime, dx: &[f64]) {
        let Some(start) = self.repeat_since else {
            return;
        };
        let Some((dp, dv)) = super::integrity::state_change(dx, idx::POS, idx::VEL) else {
            return;
        };
        let [p, v, vt] = &mut self.repeat_corrections;
        *p += dp;
        *v += dv;
        *vt += dv * time.seconds_since(start.time);
    }

    /// Keeps the smallest nonzero change of each position axis between
    /// consecutive fixes (`position_step_m`).
    pub(super) fn note_position_step(&mut self, core: &Core, fix: &GnssFix) {
        let Some((_, prev)) = self.last_fix else {
            return;
        };
        // By the local radii, not `earth::ned_offset` through ECEF: an axis
        // the receiver did not change must give exactly 0, not round-off.
        let le = LocalEarth::new(&core.nav.pos, &core.nav.vel);
        let d = le.geodetic_delta_to_ned(
            fix.pos.lat_rad - prev.lat_rad,
            fix.pos.lon_rad - prev.lon_rad,
            fix.pos.h_m - prev.h_m,
        );
        for (step, di) in self.position_step_m.iter_mut().zip(d.iter()) {
            let di = di.abs();
            if di > 0.0 && di.is_finite() {
                *step = Some(step.map_or(di, |s| s.min(di)));
            }
        }
    }

    /// How far the antenna may move without the receiver writing a new
    /// position (m): twice the diagonal of the cell of the resolution it
    /// writes at (the smallest change seen per axis), kept within 0.1 m
    /// (twice the monitor's 5 cm fix floor) and 1 m. Before every axis has
    /// changed once the resolution is unknown: 1 m.
    fn resolution_bound_m(&self) -> f64 {
        let [Some(n), Some(e), Some(d)] = self.position_step_m else {
            return 1.0;
        };
        let cell = (n * n + e * e + d * d).sqrt();
        (2.0 * cell).clamp(2.0 * super::integrity::FIX_CHANGE_FLOOR_M, 1.0)
    }

    /// How far the solution may move between two fixes whose positions are
    /// identical to the last bit before the second is a stale repeat (m):
    /// the receiver's resolution (`resolution_bound_m`), or 5 σ of the
    /// INS's velocity times the interval if larger, at most 1 m.
    fn stale_motion_bound_m(&self, core: &Core, dt_s: f64) -> f64 {
        let f = &core.filter;
        let vel_var: f64 = (0..3).map(|i| f.sd(idx::VEL + i).powi(2)).sum();
        let ins = 5.0 * vel_var.sqrt() * dt_s.max(0.0);
        // (f64::max drops a NaN: the bound stays finite.)
        self.resolution_bound_m().max(ins.min(1.0))
    }

    /// How far the INS running free could have drifted in `dt_s` since a
    /// run of repeats began (m): 5 σ of its predicted displacement error
    /// ([`free_drift_sd_m`] from its covariance then, λ the robust
    /// weighting's overconfidence scale now).
    fn free_drift_bound_m(&self, start: &RepeatStart, dt_s: f64) -> f64 {
        5.0 * free_drift_sd_m(start.drift_var_coeffs, self.overconfidence_scale(), dt_s)
    }

    /// A fix whose position repeats the previous fix's to the last bit
    /// while, since that position was first written, either the solution
    /// moved more than the receiver's resolution and the INS's error allow
    /// (`stale_motion_bound_m`, at most 1 m), or the INS's own motion (the
    /// solution's less what the GNSS updates moved it) went past that and
    /// past the drift the INS could have made free (`free_drift_bound_m`)
    /// times the onset test's calibration: a receiver repeating a stale
    /// output. Reported and skipped. (Used, the repeats of a receiver as
    /// its vehicle pulls away hold the solution within centimetres of the
    /// repeated position, so its motion alone misses them. The INS's own
    /// motion needs the calibration: while the filter's σ settle, or with
    /// another IMU's figures, an INS at rest under a receiver's static
    /// hold runs past its model's drift within a second; judged by it
    /// uncalibrated, the repeats were refused and the INS ran 1 km off.)
    /// When repeats of the run were used before, offline, the filter
    /// returns to its state before them and runs again with the run stale
    /// up to this repeat (`rollback.rs`).
    pub(super) fn is_stale(&mut self, core: &mut Core, fix: &GnssFix) -> bool {
        let Some((_, prev_pos)) = self.last_fix else {
            return false;
        };
        if prev_pos != fix.pos {
            return false;
        }
        let Some(start) = self.repeat_since else {
            return false;
        };
        let dt_s = fix.time.seconds_since(start.time);
        let le = LocalEarth::new(&core.nav.pos, &core.nav.vel);
        let solution_moved = le.geodetic_delta_to_ned(
            core.nav.pos.lat_rad - start.nav_pos.lat_rad,
            core.nav.pos.lon_rad - start.nav_pos.lon_rad,
            core.nav.pos.h_m - start.nav_pos.h_m,
        );
        let [dp, dv, dvt] = self.repeat_corrections;
        let own_moved = (solution_moved - (dp + dv * dt_s - dvt)).norm();
        let solution_moved = solution_moved.norm();
        let bound = self.stale_motion_bound_m(core, dt_s);
        let replayed = self
            .replay_stale
            .is_some_and(|(since, until)| since == start.time && fix.time <= until);
        let what = if replayed {
            "a later repeat was found stale (the run is left out up to it)".to_string()
        } else if solution_moved > bound {
            format!("the solution moved {solution_moved:.2} m")
        } else if let Some(scale) = self.monitor.drift_test_scale()
            && own_moved
                > self
                    .resolution_bound_m()
                    .max(scale.sqrt() * self.free_drift_bound_m(&start, dt_s))
        {
            format!(
                "the INS moved {own_moved:.2} m on its own (more than it could drift; the fixes held the solution within {solution_moved:.2} m)"
            )
        } else {
            return false;
        };
        self.counts.stale += 1;
        self.monitor.note_stale(fix.time);
        core.propagate();
        let obs = Self::position_obs(core, fix);
        let s = core.filter.innovation_covariance(&obs);
        let record = excluded_record(
            core,
            &obs,
            &s,
            fix.time,
            FaultReason::Stale,
            self.overconfidence_scale(),
        );
        core.fix_log.push(record);
        core.notes.push(format!(
            "GNSS fix at {} repeats the position first written at {} while {what}: a stale receiver output; ignored",
            fix.time, start.time
        ));
        if self.repeats_used > 0 && self.monitor.onset_enabled && core.rollback_to.is_none() {
            core.notes.push(format!(
                "GNSS fix at {}: the {} repeats used since {} were stale too; the filter returns to its state before them and runs again without them",
                fix.time, self.repeats_used, start.time
            ));
            core.rollback_to = Some(Rollback::Stale {
                since: start.time,
                until: fix.time,
            });
            self.repeats_used = 0;
        }
        true
    }
}
