//! Aid source: odometer (wheel or CAN) speed along the vehicle's forward
//! axis, with an optional scale-factor state, fused every `interval_s`
//! when a speed arrived. Model: `filter/nhc.rs` (KF-GINS algorithm
//! document §3.7 ODO/NHC; Sun, Petovello & Cannon 2010).

use super::*;

/// Control state of the odometer source.
#[derive(Clone, Default)]
pub(in crate::fusion) struct OdometerSource {
    /// When the next speed update is due.
    pub(in crate::fusion) next_due: GpsTime,
    /// The latest speed (m/s) not yet used.
    pub(in crate::fusion) speed_mps: Option<f64>,
    /// Speed updates accepted.
    pub(in crate::fusion) updates: usize,
}

impl OdometerSource {
    /// The speed's observation at the current state, with the scale
    /// factor's column when it is estimated.
    fn observation(core: &Core, odo: &OdometerOptions, speed_mps: f64) -> Observation {
        let scale = core.odo_scale_index.map(|i| (i, core.odo_scale));
        odo.vehicle.odometer(
            &core.nav,
            &core.last_w_ib,
            speed_mps,
            odo.sd_mps,
            scale,
            core.filter.n(),
        )
    }
}

impl AidSource for OdometerSource {
    fn due(&self, core: &Core) -> bool {
        core.cfg.odometer.is_some() && core.nav.time >= self.next_due && self.speed_mps.is_some()
    }

    fn fuse(&mut self, core: &mut Core) -> Result<(), Error> {
        let (Some(odo), Some(speed)) = (core.cfg.odometer, self.speed_mps.take()) else {
            return Ok(());
        };
        self.next_due = core.nav.time.add_seconds(odo.interval_s);
        let obs = Self::observation(core, &odo, speed);
        let frozen: Vec<usize> = core.tau_index.into_iter().collect();
        if core.apply(&obs, None, &frozen)?.accepted {
            self.updates += 1;
        }
        Ok(())
    }

    fn counters(&self, stats: &mut FusionStats) {
        stats.odometer_updates = self.updates;
    }
}
