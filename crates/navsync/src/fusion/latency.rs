//! Real-time latency modes, as policies over the delayed-measurement
//! buffer ([`DelayBuffer`], `aid/buffer.rs`):
//!
//! | mode | fix on arrival | IMU sample |
//! |---|---|---|
//! | offline | into the core's buffer, fused at its processing time | fused at once |
//! | naive | fused now, stamped now | fused at once |
//! | fixed lag | into the core's buffer | buffered; the core runs `lag_s` behind, the output is predicted through the buffer (PX4 EKF2's delayed horizon and output predictor) |
//! | extrapolate | moved by the INS change since its time (seed 002 step 5), fused now | fused; the solution kept 5 s for that |
//! | delayed state | past the solution: the stored core before it is restored, the fix inserted, the buffered samples re-run | fused; core every 50 ms and samples kept `max_latency_s` |
//!
//! Each buffer is a [`DelayBuffer`] keyed by GPS time. The delayed-state
//! log of received fixes (`applied`) stays apart from the core's buffer:
//! a restored core brings back its buffer as of its time, and the fixes
//! received since are queued into it again from the log. Dual-antenna
//! headings are logged the same way and given again during the re-run,
//! each at its own time, and odometer speeds with the sample each preceded
//! (which is also how a fixed-lag filter gets them when it reaches it).

use super::*;

/// When a measurement was given to the filter, as an order against stored
/// states: at filter time `t`, after the sample at `t` (`after_sample`, as
/// a live heading is pushed) or just before it (fed ahead of the sample in
/// a re-run). A state stored after the sample at `t` has seen exactly the
/// measurements of order ≤ `given_order(t, false)`.
pub(super) fn given_order(t: GpsTime, after_sample: bool) -> i128 {
    2 * t.ns() as i128 + i128::from(after_sample)
}

/// The fixed-lag mode's output predictor: the lagged filter state carried
/// forward through the buffered samples.
#[derive(Clone)]
pub(super) struct Predictor {
    pub(super) nav: NavState,
    pub(super) mech: Mechanization,
    pub(super) last: GpsTime,
    /// The lagged filter's correction count this prediction started from.
    pub(super) corrections: usize,
}

impl Predictor {
    pub(super) fn step(&mut self, s: &ImuSample, imu: &ImuErrors) {
        let dt = s.time.seconds_since(self.last);
        if dt <= 0.0 {
            return;
        }
        let inc = imu.compensate(&s.dtheta, &s.dvel, dt);
        self.mech.step(&mut self.nav, &inc);
        self.nav.time = s.time;
        self.last = s.time;
    }
}

/// Interval between stored filter states in the delayed-state mode.
pub(super) const SNAPSHOT_INTERVAL_NS: i64 = 50_000_000;

/// A recent solution epoch kept for real-time latency handling.
#[derive(Copy, Clone, Debug)]
pub(super) struct HistoryEntry {
    pub(super) time: GpsTime,
    pub(super) pos: Geodetic,
    pub(super) vel: Vector3<f64>,
}

impl Timed for HistoryEntry {
    fn time(&self) -> GpsTime {
        self.time
    }
}

impl Timed for Core {
    /// A stored core is keyed by its solution time.
    fn time(&self) -> GpsTime {
        self.nav.time
    }
}

/// How long the extrapolation mode keeps the solution (s).
const HISTORY_S: f64 = 5.0;

impl Fusion {
    /// (a) The filter consumes samples `lag_s` behind; the output is its
    /// state predicted through the buffered samples.
    pub(super) fn push_imu_lagged(
        &mut self,
        sample: &ImuSample,
        lag_s: f64,
    ) -> Result<Option<NavOutput>, Error> {
        self.imu_buffer.push_back(*sample);
        if let Some(v) = self.speed_for_next.take() {
            self.speeds_given.push_back((sample.time, v));
        }
        let horizon = sample.time.add_seconds(-lag_s);
        while let Some(s) = self.imu_buffer.front().copied()
            && s.time <= horizon
        {
            self.imu_buffer.pop_front();
            let given = self.give_speeds(0, s.time);
            self.speeds_given.drain(..given);
            self.core.push_imu(&s)?;
        }
        if !self.core.started {
            return Ok(None);
        }
        // Output predictor: the lagged state carried through the buffered
        // samples. It is rebuilt only when the lagged filter corrected its
        // state; otherwise the newest sample is integrated onto it.
        let corrections = self.core.corrections();
        let rebuild = self
            .predictor
            .as_ref()
            .is_none_or(|p| p.corrections != corrections);
        if rebuild {
            let mut p = Predictor {
                nav: self.core.nav,
                mech: self.core.mech.clone(),
                last: self.core.last_time,
                corrections,
            };
            for s in &self.imu_buffer {
                p.step(s, &self.core.imu);
            }
            self.predictor = Some(p);
        } else if let Some(p) = self.predictor.as_mut() {
            p.step(sample, &self.core.imu);
        }
        let nav = self
            .predictor
            .as_ref()
            .map(|p| p.nav)
            .unwrap_or(self.core.nav);
        Ok(Some(NavOutput {
            nav,
            imu: self.core.imu,
        }))
    }

    /// (b) Seed 002 step 5: shift the fix by the INS change between its time
    /// of validity and now, and apply it now.
    pub(super) fn extrapolated_update(&mut self, fix: GnssFix) -> Result<(), Error> {
        if !self.core.started {
            self.core.queue(fix);
            return Ok(());
        }
        let now = self.core.nav;
        let Some(then) = self.history_at(fix.time) else {
            self.core.stats.gnss_fixes_late += 1;
            self.core.notes.push(format!(
                "GNSS fix at {} is older than the kept INS history; dropped",
                fix.time
            ));
            return Ok(());
        };
        let le = LocalEarth::new(&then.pos, &then.vel);
        let d_ned = le.geodetic_delta_to_ned(
            now.pos.lat_rad - then.pos.lat_rad,
            now.pos.lon_rad - then.pos.lon_rad,
            now.pos.h_m - then.pos.h_m,
        );
        let d = LocalEarth::new(&fix.pos, &then.vel).ned_to_geodetic_delta(&d_ned);
        let mut moved = fix;
        moved.time = now.time;
        moved.pos = Geodetic::new(
            fix.pos.lat_rad + d.x,
            fix.pos.lon_rad + d.y,
            fix.pos.h_m + d.z,
        );
        moved.vel = fix.vel.map(|v| v + (now.vel - then.vel));
        self.core.gnss_update(&moved)
    }

    /// Keeps the solution for [`Self::extrapolated_update`].
    pub(super) fn record_history(&mut self, o: &NavOutput) {
        self.history.push_back(HistoryEntry {
            time: o.nav.time,
            pos: o.nav.pos,
            vel: o.nav.vel,
        });
        let oldest = o.nav.time.add_seconds(-HISTORY_S);
        while self.history.len() > 2 && self.history[1].time <= oldest {
            self.history.pop_front();
        }
    }

    /// The solution at `t`, interpolated in the history.
    pub(super) fn history_at(&self, t: GpsTime) -> Option<HistoryEntry> {
        let h = &self.history;
        let n = h.len();
        if n == 0 || t < h[0].time {
            return None;
        }
        if t >= h[n - 1].time {
            return Some(h[n - 1]);
        }
        let i = h.count_through(t).clamp(1, n - 1);
        let (a, b) = (h[i - 1], h[i]);
        let u = (t - a.time) as f64 / (b.time - a.time) as f64;
        Some(HistoryEntry {
            time: t,
            pos: Geodetic::new(
                a.pos.lat_rad + (b.pos.lat_rad - a.pos.lat_rad) * u,
                a.pos.lon_rad + (b.pos.lon_rad - a.pos.lon_rad) * u,
                a.pos.h_m + (b.pos.h_m - a.pos.h_m) * u,
            ),
            vel: a.vel + (b.vel - a.vel) * u,
        })
    }

    /// (c) The core runs on the samples as they come; the samples and
    /// stored cores a fix up to `max_latency_s` old can need are kept.
    pub(super) fn push_imu_delayed_state(
        &mut self,
        sample: &ImuSample,
        max_latency_s: f64,
    ) -> Result<Option<NavOutput>, Error> {
        let speed = self.speed_for_next.take();
        let out = self.core.push_imu(sample)?;
        if out.is_some() {
            self.imu_buffer.push_back(*sample);
            if let Some(v) = speed {
                self.speeds_given.push_back((sample.time, v));
            }
            self.maybe_snapshot();
            let oldest = sample.time.add_seconds(-max_latency_s);
            while self.snapshots.len() > 1 && self.snapshots[1].nav.time <= oldest {
                self.snapshots.pop_front();
            }
            let keep_from = self
                .snapshots
                .front()
                .map(|s| s.nav.time)
                .unwrap_or(sample.time);
            self.imu_buffer.drop_through(keep_from);
            while self
                .speeds_given
                .front()
                .is_some_and(|(t, _)| *t <= keep_from)
            {
                self.speeds_given.pop_front();
            }
        }
        Ok(out)
    }

    /// Gives the core the recorded odometer speeds from index `from` on
    /// that were given ahead of samples up to `t` (the latest wins, as
    /// when they were pushed); returns the index after the last given.
    fn give_speeds(&mut self, from: usize, t: GpsTime) -> usize {
        let mut next = from;
        while let Some(&(at, v)) = self.speeds_given.get(next)
            && at <= t
        {
            self.core.aid.odometer.speed_mps = Some(v);
            next += 1;
        }
        next
    }

    /// Forgets the headings every stored state has seen.
    pub(super) fn forget_old_headings(&mut self) {
        let Some(oldest) = self.snapshots.iter().next().map(|s| s.nav.time) else {
            return;
        };
        let seen = given_order(oldest, false);
        while self
            .headings_received
            .front()
            .is_some_and(|(given, _)| *given <= seen)
        {
            self.headings_received.pop_front();
        }
    }

    /// The buffered IMU samples after `t`, for a re-run from a stored state.
    pub(super) fn samples_after(&self, t: GpsTime) -> Vec<ImuSample> {
        self.imu_buffer
            .iter()
            .filter(|s| s.time > t)
            .copied()
            .collect()
    }

    /// Stores the filter state every [`SNAPSHOT_INTERVAL_NS`] (a delayed fix
    /// replays at most that much more than its latency).
    pub(super) fn maybe_snapshot(&mut self) {
        let due = self
            .snapshots
            .back()
            .is_none_or(|s| self.core.nav.time - s.nav.time >= SNAPSHOT_INTERVAL_NS);
        if due {
            self.snapshots.push_back(self.core.clone());
        }
    }

    /// (c) Return to the stored state before the fix, insert it, and
    /// re-process the buffered IMU samples.
    pub(super) fn delayed_update(&mut self, fix: GnssFix) -> Result<(), Error> {
        let tp = self.core.proc_time(&fix);
        if !self.core.started || tp > self.core.nav.time {
            self.core.queue(fix);
            self.applied.push_back(fix);
            return Ok(());
        }
        let Some(k) = self.snapshots.iter().rposition(|s| s.nav.time < tp) else {
            self.core.stats.gnss_fixes_late += 1;
            self.core.notes.push(format!(
                "GNSS fix at {} is older than the stored states; dropped (raise the maximum latency)",
                fix.time
            ));
            return Ok(());
        };
        let notes = std::mem::take(&mut self.core.notes);
        let mut core = self.snapshots[k].clone();
        core.notes = notes;
        self.replays += 1;
        // Fixes already applied after the snapshot must be applied again.
        let t_snap = core.nav.time;
        requeue_applied(&self.applied, &mut core);
        core.queue(fix);
        self.applied.push_back(fix);
        let oldest = self.snapshots[0].nav.time;
        let current = &self.core;
        self.applied.drop_while(|f| current.proc_time(f) < oldest);
        self.snapshots.truncate(k + 1);
        let replay = self.samples_after(t_snap);
        self.core = core;
        // Headings given to the filter after the snapshot was stored are
        // given again, each before the first sample at or after its time
        // (the restored core never saw them).
        let stored = given_order(t_snap, false);
        let mut redo: Vec<usize> = (0..self.headings_received.len())
            .filter(|&i| self.headings_received[i].0 > stored)
            .collect();
        redo.sort_by_key(|&i| self.headings_received[i].1.time);
        let mut next = 0;
        let mut next_speed = self.speeds_given.partition_point(|(t, _)| *t <= t_snap);
        for s in &replay {
            // Odometer speeds as they were given ahead of this sample.
            next_speed = self.give_speeds(next_speed, s.time);
            while let Some(&i) = redo.get(next)
                && self.headings_received[i].1.time <= s.time
            {
                let entry = &mut self.headings_received[i];
                entry.0 = given_order(s.time, false);
                self.core.aid.heading.give(entry.1);
                next += 1;
            }
            self.core.push_imu(s)?;
            self.maybe_snapshot();
        }
        // A speed given after the last sample: the restored core lost it.
        if let Some(v) = self.speed_for_next {
            self.core.aid.odometer.speed_mps = Some(v);
        }
        // Not yet due: queued, given after the last sample.
        for &i in &redo[next..] {
            let entry = &mut self.headings_received[i];
            entry.0 = given_order(self.core.nav.time, true);
            self.core.aid.heading.give(entry.1);
        }
        self.forget_old_headings();
        // The coarse search already saw these steps on the first pass.
        self.core.steps.clear();
        Ok(())
    }
}

/// Queues again, into a stored `core`, the fixes pushed after its time
/// that it has not queued yet (a re-run from a stored state).
pub(super) fn requeue_applied(applied: &DelayBuffer<GnssFix>, core: &mut Core) {
    let t_stored = core.nav.time;
    for f in applied {
        if core.proc_time(f) > t_stored && !core.pending.contains_time(f.time) {
            core.queue(*f);
        }
    }
}
