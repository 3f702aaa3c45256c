//! Aid sources of the vehicle: the non-holonomic constraint, odometer
//! speeds and standstill (ZUPT/ZARU) updates, scheduled on the IMU epochs.

use super::*;

impl Core {
    pub(super) fn vehicle_updates(&mut self) -> Result<(), Error> {
        let n = self.filter.n();
        let frozen: Vec<usize> = self.tau_index.into_iter().collect();
        if let Some(nhc) = self.cfg.nhc
            && self.nav.time >= self.next_nhc
        {
            self.next_nhc = self.nav.time.add_seconds(nhc.interval_s);
            let obs = nhc.vehicle.nhc(&self.nav, &self.last_w_ib, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.nhc_updates += 1;
            }
        }
        if let (Some(opts), Some(w)) = (self.cfg.standstill, self.still_window.take()) {
            let obs = standstill::zupt(&self.nav, opts.zupt_sd_mps, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.zupt_updates += 1;
            }
            let obs =
                standstill::zaru(&self.nav, &self.imu.gyro_bias, &w, opts.zaru_floor_rad_s, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.zaru_updates += 1;
            }
        }
        if let Some(odo) = self.cfg.odometer
            && self.nav.time >= self.next_odo
            && let Some(speed) = self.pending_speed.take()
        {
            self.next_odo = self.nav.time.add_seconds(odo.interval_s);
            let scale = self.odo_scale_index.map(|i| (i, self.odo_scale));
            let obs = odo
                .vehicle
                .odometer(&self.nav, &self.last_w_ib, speed, odo.sd_mps, scale, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.odometer_updates += 1;
            }
        }
        Ok(())
    }
}
