//! Aid source: standstill. The detector runs on every mechanized step;
//! a still window yields a zero-velocity (ZUPT) and a zero-angular-rate
//! (ZARU) update. Detection and models: `filter/standstill.rs` (Groves,
//! *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
//! Systems*, 2nd ed., §15.3.1; Skog et al., IEEE Trans. Biomed. Eng.
//! 57(11), 2010).

use super::*;

/// Control state of the standstill source: the detector and the still
/// window awaiting its updates.
#[derive(Clone, Default)]
pub(in crate::fusion) struct StandstillSource {
    pub(in crate::fusion) detector: Option<StandstillDetector>,
    window: Option<StillWindow>,
    /// ZUPT and ZARU updates accepted.
    zupt_updates: usize,
    zaru_updates: usize,
    /// Time found still (s).
    still_s: f64,
}

impl StandstillSource {
    pub(in crate::fusion) fn new(opts: Option<StandstillOptions>) -> Self {
        StandstillSource {
            detector: opts.map(StandstillDetector::new),
            ..Default::default()
        }
    }

    /// Feeds one mechanized step (specific force in n, compensated rate,
    /// over `dt` s) to the detector.
    pub(in crate::fusion) fn detect(
        &mut self,
        f_n: &Vector3<f64>,
        w_ib: &Vector3<f64>,
        gyro_bias: &Vector3<f64>,
        dt: f64,
        speed_mps: f64,
    ) {
        let Some(d) = self.detector.as_mut() else {
            return;
        };
        let window_s = d.options().window_s;
        match d.push(f_n, w_ib, gyro_bias, dt, speed_mps) {
            Some(Some(w)) => {
                self.window = Some(w);
                self.still_s += window_s;
            }
            Some(None) => self.window = None,
            None => {}
        }
    }

    /// A data gap: the detector starts over.
    pub(in crate::fusion) fn reset(&mut self) {
        if let Some(d) = self.detector.as_mut() {
            d.reset();
        }
    }
}

impl AidSource for StandstillSource {
    fn due(&self, core: &Core) -> bool {
        core.cfg.standstill.is_some() && self.window.is_some()
    }

    fn fuse(&mut self, core: &mut Core) -> Result<(), Error> {
        let (Some(opts), Some(w)) = (core.cfg.standstill, self.window.take()) else {
            return Ok(());
        };
        let n = core.filter.n();
        let frozen: Vec<usize> = core.tau_index.into_iter().collect();
        let obs = standstill::zupt(&core.nav, opts.zupt_sd_mps, n);
        if core.apply(&obs, None, &frozen)?.accepted {
            self.zupt_updates += 1;
        }
        let obs = standstill::zaru(&core.nav, &core.imu.gyro_bias, &w, opts.zaru_floor_rad_s, n);
        if core.apply(&obs, None, &frozen)?.accepted {
            self.zaru_updates += 1;
        }
        Ok(())
    }

    fn counters(&self, stats: &mut FusionStats) {
        stats.zupt_updates = self.zupt_updates;
        stats.zaru_updates = self.zaru_updates;
        stats.standstill_s = self.still_s;
    }
}
