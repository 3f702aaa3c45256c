//! Aid source: dual-antenna heading (the azimuth of the antenna baseline),
//! fused at the first IMU epoch at or after each measurement. Model:
//! `filter/heading.rs` (Groves §10.2.5, §16.3.2). A measurement whose
//! normalised innovation exceeds the χ² gate (1 degree of freedom, 99.9 %)
//! is rejected and reported; after [`MAX_HEADING_REJECTS`] rejections in a
//! row the next one is used anyway (the filter's heading, not the
//! receiver's, is then the likely culprit), as the GNSS position gate does.

use super::*;
use crate::io::heading::HeadingObs;
use std::collections::VecDeque;

/// Consecutive rejections after which a heading is used ungated.
const MAX_HEADING_REJECTS: usize = 5;
/// Rejections reported one by one; later ones are only counted.
const REPORTED_REJECTS: usize = 10;

/// Headings waiting for the solution to reach their time, at most (a
/// filter running a lag behind real time holds a few; beyond this the
/// oldest is dropped).
const MAX_PENDING_HEADINGS: usize = 1000;

/// Control state of the heading source.
#[derive(Clone, Default)]
pub(in crate::fusion) struct HeadingAid {
    /// Headings not yet used, in time order.
    pending: VecDeque<HeadingObs>,
    pub(in crate::fusion) updates: usize,
    pub(in crate::fusion) rejected: usize,
    consecutive_rejects: usize,
}

impl HeadingAid {
    /// Queues a heading for the first IMU epoch at or after its time.
    pub(in crate::fusion) fn give(&mut self, h: HeadingObs) {
        let at = self.pending.partition_point(|p| p.time <= h.time);
        self.pending.insert(at, h);
        if self.pending.len() > MAX_PENDING_HEADINGS {
            self.pending.pop_front();
        }
    }

    /// The earliest queued heading, when the solution reached its time.
    fn next_due(&self, core: &Core) -> Option<HeadingObs> {
        let h = *self.pending.front()?;
        (core.cfg.heading.is_some() && core.nav.time >= h.time && !core.heading_unknown)
            .then_some(h)
    }

    /// Fuses one heading.
    fn fuse_one(&mut self, core: &mut Core, h: HeadingObs) -> Result<(), Error> {
        let Some(opts) = core.cfg.heading else {
            return Ok(());
        };
        // The azimuth turned since the measurement: the body's yaw rate
        // (ω_nb ≈ ω_ib for the ms involved) resolved about down.
        let dt = core.nav.time.seconds_since(h.time);
        let yaw_rate = (core.nav.c_nb() * core.last_w_ib).z;
        let obs = crate::filter::heading::baseline_heading(
            &core.nav,
            opts.dual_antenna_yaw_rad,
            h.heading_rad,
            h.sd_rad,
            yaw_rate * dt,
            core.filter.n(),
        );
        // The measured azimuth holds the mounting error ε: aẑ − az ∋ ε̂ − ε.
        let mut obs = obs;
        if let Some(i) = core.heading_mount_index {
            obs.h.set(0, i, 1.0);
        }
        let gate = (self.consecutive_rejects < MAX_HEADING_REJECTS).then_some(HEADING_GATE_NIS);
        let frozen = core.frozen_states();
        let outcome = core.apply(&obs, gate, &frozen)?;
        if outcome.accepted {
            self.updates += 1;
            self.consecutive_rejects = 0;
        } else {
            self.rejected += 1;
            self.consecutive_rejects += 1;
            if self.rejected <= REPORTED_REJECTS {
                core.notes.push(format!(
                    "dual-antenna heading at {} ({:.2}° ± {:.2}°) disagrees with the solution by {:.2}° (NIS {:.1} > {HEADING_GATE_NIS}): rejected",
                    h.time,
                    h.heading_rad.to_degrees().rem_euclid(360.0),
                    h.sd_rad.to_degrees(),
                    obs.z[0].to_degrees(),
                    outcome.nis
                ));
            }
        }
        Ok(())
    }
}

impl AidSource for HeadingAid {
    fn due(&self, core: &Core) -> bool {
        self.next_due(core).is_some()
    }

    fn fuse(&mut self, core: &mut Core) -> Result<(), Error> {
        // Headings fall due one at a time as the solution moves on; several
        // at once only waited (for the heading to become known, or through
        // an IMU gap), and the latest supersedes the older ones.
        let mut latest = None;
        while let Some(h) = self.next_due(core) {
            self.pending.pop_front();
            latest = Some(h);
        }
        if let Some(h) = latest {
            self.fuse_one(core, h)?;
        }
        Ok(())
    }

    fn counters(&self, stats: &mut FusionStats) {
        stats.heading_updates = self.updates;
        stats.heading_rejected = self.rejected;
    }
}

/// χ² quantile of 1 degree of freedom at 99.9 %.
const HEADING_GATE_NIS: f64 = 10.83;
