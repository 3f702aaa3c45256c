//! Aid sources: the measurements that correct the INS, one file each.
//!
//! The layout follows PX4 EKF2's `aid_sources/` (PX4-Autopilot,
//! <https://github.com/PX4/PX4-Autopilot>, `src/modules/ekf2/EKF/aid_sources/`):
//! each source has its control logic (enabled by the configuration, due
//! now, gating and fault handling, its counters) and its measurement model
//! (innovation z, rows H, noise R) in its own file, and every source
//! corrects the filter through one update path, [`Core::apply`]:
//! propagate P to now, hold the states that must not move (an unknown
//! yaw, an unobservable τ), Joseph update with an optional χ² gate, feed
//! the correction back (INS, IMU errors, odometer scale, τ, GNSS error
//! states). Measurements that arrive asynchronously wait in a
//! [`DelayBuffer`] (PX4's `RingBuffer`) until the filter's time reaches
//! them; the latency modes (`latency.rs`) are policies over that buffer.
//!
//! | file | source | model (cited in the file) |
//! |---|---|---|
//! | `gnss.rs` | GNSS position and velocity | lever arm (KF-GINS, `filter/gnss.rs`); χ² gate; robust weights IGG-III (Yang, Song & Xu 2002), noise scale (Särkkä & Nummenmaa 2009), drift inflation (Xia et al. 1994) |
//! | `nhc.rs` | non-holonomic constraint | KF-GINS §3.7 ODO/NHC (`filter/nhc.rs`); Sun, Petovello & Cannon 2010 |
//! | `odometer.rs` | odometer speed, scale-factor state | the same |
//! | `zupt.rs` | standstill: ZUPT and ZARU | Groves §15.3.1, Skog et al. 2010 (`filter/standstill.rs`) |
//! | `integrity/` | GNSS fault episodes (jumps, ramp onsets, runs) against the INS's displacement | time-differenced tests (Joerger & Pervan 2013); INS error growth (Titterton & Weston §12.3) |
//! | `heading.rs` | dual-antenna heading | Groves §10.2.5, §16.3.2 (`filter/heading.rs`) |
//! | `time_offset.rs` | the IMU–GNSS time offset τ | seed 004 eqs 11–16 (Wang, Guan & Ding 2019) |
//! | `lever_arm.rs` | the antenna lever arm as states | KF-GINS §3.5–3.6; Groves §14.2.7 |
//!
//! GNSS position and velocity are one source: the velocity row of a fix
//! is fused only after its position was used, with the same held states,
//! and the fix is remembered after both (the staleness test). τ has no
//! measurement of its own: it is observed through the GNSS rows (its
//! columns come from `time_offset.rs`) and reset by the coarse search, so
//! it is a state that file controls, not an [`AidSource`].
//!
//! Order at an IMU epoch (the order of [`AidSources::all`]): GNSS
//! fixes due at the epoch, NHC, ZUPT/ZARU, odometer, heading. Fixes inside the IMU
//! interval are fused by the driver where it splits the interval.

use super::*;

mod buffer;
pub(super) mod gnss;
mod heading;
pub(super) mod integrity;
pub(super) mod lever_arm;
mod nhc;
mod odometer;
pub(super) mod time_offset;
mod zupt;

pub(super) use buffer::{DelayBuffer, Timed};
use gnss::GnssSource;
use heading::HeadingAid;
use nhc::NhcSource;
use odometer::OdometerSource;
use zupt::StandstillSource;

/// One aid source: control logic and measurement model.
///
/// The model (z, H, R at the current state, from the rows of
/// [`crate::filter`]) is built in the source's file; the control logic
/// decides whether a measurement is due and fuses it through
/// [`Core::apply`], counting the outcome. A source reads and corrects the
/// filter core, never another source (the sources are out of the core
/// while they run).
pub(super) trait AidSource {
    /// Whether a measurement is due at the current epoch (configuration,
    /// schedule, pending input).
    fn due(&self, core: &Core) -> bool;

    /// Fuses what is due: builds the observation, gates it, handles its
    /// faults and counts.
    fn fuse(&mut self, core: &mut Core) -> Result<(), Error>;

    /// Writes the source's diagnostics counters into `stats`.
    fn counters(&self, stats: &mut FusionStats);
}

/// The aid sources of a filter core, with their control state.
#[derive(Clone, Default)]
pub(super) struct AidSources {
    pub(super) gnss: GnssSource,
    pub(super) nhc: NhcSource,
    pub(super) standstill: StandstillSource,
    pub(super) odometer: OdometerSource,
    pub(super) heading: HeadingAid,
}

impl AidSources {
    pub(super) fn new(cfg: &FusionConfig) -> Self {
        AidSources {
            gnss: GnssSource::new(cfg),
            nhc: NhcSource {
                next_due: cfg.init_nav.time,
                updates: 0,
            },
            standstill: StandstillSource::new(cfg.standstill),
            odometer: OdometerSource {
                next_due: cfg.init_nav.time,
                speed_mps: None,
                updates: 0,
            },
            heading: HeadingAid::default(),
        }
    }

    /// The first IMU epoch: the schedules start here.
    pub(super) fn start(&mut self, t: GpsTime) {
        self.nhc.next_due = t;
        self.odometer.next_due = t;
    }

    /// Every source, in the order they are fused at an epoch.
    fn all(&self) -> [&dyn AidSource; 5] {
        [
            &self.gnss,
            &self.nhc,
            &self.standstill,
            &self.odometer,
            &self.heading,
        ]
    }

    /// Every source, mutable, in the same order.
    fn all_mut(&mut self) -> [&mut dyn AidSource; 5] {
        [
            &mut self.gnss,
            &mut self.nhc,
            &mut self.standstill,
            &mut self.odometer,
            &mut self.heading,
        ]
    }

    /// The statistics with every source's counters written in.
    pub(super) fn counters(&self, stats: &mut FusionStats) {
        for source in self.all() {
            source.counters(stats);
        }
    }

    /// Number of corrections by the sources so far (used GNSS positions
    /// and velocities, NHC and odometer updates).
    pub(super) fn corrections(&self) -> usize {
        let g = &self.gnss.counts;
        g.fixes_used + g.velocity_used + self.nhc.updates + self.odometer.updates
    }

    /// Fuses every source's measurements that are due at the epoch (a
    /// fusion can make a later source due or not: each is asked in turn).
    fn fuse_due(&mut self, core: &mut Core) -> Result<(), Error> {
        for source in self.all_mut() {
            if source.due(core) {
                source.fuse(core)?;
            }
        }
        Ok(())
    }
}

/// χ² gate of a track-course heading (1 degree of freedom, 99.9 %).
const COURSE_GATE_NIS: f64 = 10.83;

impl Core {
    /// Fuses the aid sources that are due at the epoch (most epochs have
    /// none: then the sources stay in place).
    pub(super) fn fuse_due(&mut self) -> Result<(), Error> {
        if !self.aid.all().iter().any(|s| s.due(self)) {
            return Ok(());
        }
        self.with_sources(|aid, core| aid.fuse_due(core))
    }

    /// Runs `f` with the sources taken out of the core, so that a source
    /// can update the core through [`Core::apply`].
    pub(super) fn with_sources<R>(&mut self, f: impl FnOnce(&mut AidSources, &mut Core) -> R) -> R {
        let mut aid = std::mem::take(&mut self.aid);
        let out = f(&mut aid, self);
        self.aid = aid;
        out
    }

    /// Fuses one GNSS fix now.
    pub(super) fn gnss_update(&mut self, fix: &GnssFix) -> Result<(), Error> {
        self.with_sources(|aid, core| aid.gnss.fuse_fix(core, fix))?;
        let Some(ch) = self.course_heading.as_mut() else {
            return Ok(());
        };
        let sd_h = fix.pos_sd.x.max(fix.pos_sd.y);
        let yaw = super::course_heading::yaw_of(&self.nav.q_nb);
        let acquired = ch.push(self.nav.time, fix.pos.lat_rad, fix.pos.lon_rad, sd_h, yaw);
        let chord = ch.take_chord();
        if self.heading_unknown {
            if let Some(h) = acquired {
                self.acquire_heading(h);
            }
        } else if let Some(c) = chord {
            // The track's course as a heading measurement of the body now.
            let obs = crate::filter::heading::baseline_heading(
                &self.nav,
                0.0,
                yaw + c.delta_rad,
                c.sd_rad,
                0.0,
                self.filter.n(),
            );
            let frozen = self.frozen_states();
            let outcome = self.apply(&obs, Some(COURSE_GATE_NIS), &frozen)?;
            if outcome.accepted {
                self.stats.course_heading_updates += 1;
            } else {
                self.stats.course_heading_rejected += 1;
            }
        }
        Ok(())
    }

    /// Sets the heading found from the GNSS track: the nominal attitude
    /// turned by the offset about the vertical, the yaw's covariance reset
    /// to its σ (uncorrelated: it was held), and the yaw a state again.
    fn acquire_heading(&mut self, h: super::course_heading::HeadingAcquired) {
        self.nav.q_nb = crate::attitude::turned_in_yaw(&self.nav.q_nb, h.offset_rad);
        let yaw = crate::filter::idx::ATT + 2;
        let p = self.filter.covariance_mut();
        for i in 0..p.rows {
            p.set(yaw, i, 0.0);
            p.set(i, yaw, 0.0);
        }
        p.set(yaw, yaw, h.sd_rad * h.sd_rad);
        self.heading_unknown = false;
        self.notes.push(format!(
            "heading found from the GNSS track at {:.1} s of week: {} chords agree within {:.1}° over courses spanning {:.0}°; \
             the held yaw turned by {:.1}° (σ {:.1}°); the smoothed output turns the epochs before by the same angle",
            h.time_sow,
            h.chords,
            h.spread_rad.to_degrees(),
            h.course_span_rad.to_degrees(),
            h.offset_rad.to_degrees(),
            h.sd_rad.to_degrees()
        ));
        self.heading_acquired = Some(h);
    }

    /// The one update path of every source: propagates the covariance to
    /// now, holds the `frozen` states (and an unknown yaw), updates with
    /// an optional χ² `gate` and feeds the correction back.
    pub(super) fn apply(
        &mut self,
        obs: &Observation,
        gate: Option<f64>,
        frozen: &[usize],
    ) -> Result<UpdateOutcome, Error> {
        self.propagate();
        // An unknown heading (σ beyond 90°: a vehicle that never moved) is
        // held: a small-angle error model linearised at a wrong heading
        // would let the lever arm or gyrocompassing terms "observe" it.
        let held_yaw;
        let frozen = if self.heading_unknown {
            held_yaw = [frozen, &[crate::filter::idx::ATT + 2]].concat();
            &held_yaw[..]
        } else {
            frozen
        };
        // The dual-antenna mounting yaw is a consider state: never updated.
        let held_mount;
        let frozen = match self.heading_mount_index {
            Some(i) => {
                held_mount = [frozen, &[i]].concat();
                &held_mount[..]
            }
            None => frozen,
        };
        // The lever arm's down component is a consider state (carried,
        // never updated): `lever_arm.rs`. While the heading is unknown its
        // horizontal components are too: C_bⁿ l turns with a heading the
        // filter does not have (held, the Husky bag's probe ran to
        // −510 m without this).
        let held_lever;
        let frozen = match self.lever_index {
            Some(i) if self.heading_unknown => {
                held_lever = [frozen, &[i, i + 1, i + 2]].concat();
                &held_lever[..]
            }
            Some(i) => {
                held_lever = [frozen, &[i + 2]].concat();
                &held_lever[..]
            }
            None => frozen,
        };
        let outcome = self
            .filter
            .update_with_frozen(obs, gate, frozen, self.nav.time)?;
        if outcome.accepted {
            feedback(
                &outcome.dx,
                self.filter.layout(),
                &mut self.nav,
                &mut self.imu,
            );
            if let Some(i) = self.odo_scale_index {
                self.odo_scale -= outcome.dx[i];
            }
            if let Some(i) = self.tau_index {
                self.tau -= outcome.dx[i];
                self.bound_time_offset();
            }
            if let Some(i) = self.gnss_bias_index {
                for k in 0..3 {
                    self.gnss_bias[k] -= outcome.dx[i + k];
                }
            }
            self.lever_feedback(&outcome.dx);
        }
        Ok(outcome)
    }
}
