//! Aid source: the non-holonomic constraint (zero lateral and vertical
//! velocity of a land vehicle in its own frame), a pseudo-measurement
//! fused every `interval_s`. Model: `filter/nhc.rs` (KF-GINS algorithm
//! document §3.7 ODO/NHC; Sun, Petovello & Cannon 2010).

use super::*;

/// Control state of the NHC source.
#[derive(Clone, Default)]
pub(in crate::fusion) struct NhcSource {
    /// When the next constraint is due.
    pub(in crate::fusion) next_due: GpsTime,
    /// Constraints accepted.
    pub(in crate::fusion) updates: usize,
}

impl NhcSource {
    /// The constraint's observation at the current state.
    fn observation(core: &Core, nhc: &NhcOptions) -> Observation {
        nhc.vehicle.nhc(&core.nav, &core.last_w_ib, core.filter.n())
    }
}

impl AidSource for NhcSource {
    fn due(&self, core: &Core) -> bool {
        core.cfg.nhc.is_some() && core.nav.time >= self.next_due
    }

    fn fuse(&mut self, core: &mut Core) -> Result<(), Error> {
        let Some(nhc) = core.cfg.nhc else {
            return Ok(());
        };
        self.next_due = core.nav.time.add_seconds(nhc.interval_s);
        let obs = Self::observation(core, &nhc);
        let frozen: Vec<usize> = core.tau_index.into_iter().collect();
        if core.apply(&obs, None, &frozen)?.accepted {
            self.updates += 1;
        }
        Ok(())
    }

    fn counters(&self, stats: &mut FusionStats) {
        stats.nhc_updates = self.updates;
    }
}
