//! An IMU gap with GNSS going on (issue 32 item 3): after a gap longer
//! than [`REINIT_GAP_S`], the INS has nothing to carry its state across
//! (holding the last rates over a minute is a guess of hundreds of metres,
//! and the robust weighting then rejects good fixes as outliers). The
//! fixes that arrived during the gap are what is known: position and
//! velocity are re-initialised from the last three, yaw from their course
//! (with the yaw−course offset the vehicle had before the gap), roll and
//! pitch kept, and the covariance of the navigation states reset to what
//! the fixes say, with the attitude σ inflated.

use nalgebra::Vector3;

use super::Core;
use crate::attitude::{euler_to_quat, quat_to_euler};
use crate::earth::{LocalEarth, ned_offset};
use crate::filter::gnss::GnssFix;
use crate::time::GpsTime;

/// An IMU gap at least this long (s) with fixes inside re-initialises the
/// navigation state from them.
pub(crate) const REINIT_GAP_S: f64 = 1.0;
/// Horizontal speed (m/s) above which the course gives the heading.
const COURSE_MIN_SPEED_MPS: f64 = 3.0;
/// Roll/pitch σ added at a re-initialisation (rad): 2°, the slope change a
/// road gives within a minute.
const TILT_SD_ADD_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Yaw σ added when the course gives the heading (rad): 3° for the
/// sideslip change; 20° without a course.
const YAW_SD_COURSE_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;
const YAW_SD_NO_COURSE_RAD: f64 = 20.0 * std::f64::consts::PI / 180.0;
/// Velocity σ floor (m/s): acceleration changes between the fixes.
const VEL_SD_FLOOR_MPS: f64 = 0.2;

impl Core {
    /// Re-initialises the state at `end` (the sample ending a gap of
    /// `gap_s`) from the fixes due by then; false (nothing changed, the
    /// fixes left queued) without three recent fixes.
    pub(super) fn reinit_after_gap(&mut self, end: GpsTime, gap_s: f64) -> bool {
        let start = end.add_seconds(-gap_s);
        let due: Vec<GnssFix> = self
            .pending
            .iter()
            .filter(|f| self.proc_time(f) <= end && self.proc_time(f) > start)
            .copied()
            .collect();
        let n = due.len();
        if n < 3 {
            return false;
        }
        let (f0, f1, f2) = (&due[n - 3], &due[n - 2], &due[n - 1]);
        let (t0, t1, t2) = (self.proc_time(f0), self.proc_time(f1), self.proc_time(f2));
        let lead_s = end.seconds_since(t2);
        let (h1, h2) = (t2.seconds_since(t1), t1.seconds_since(t0));
        if lead_s > 1.5 || h1 > 2.0 || h2 > 2.0 || h1 <= 0.0 || h2 <= 0.0 {
            return false;
        }
        // Antenna velocity at t2: derivative of the parabola through the
        // three positions (Lagrange), in NED about f2.
        let (p0, p1) = (ned_offset(&f2.pos, &f0.pos), ned_offset(&f2.pos, &f1.pos));
        let vel = match (f2.vel, self.cfg.use_gnss_velocity) {
            (Some(v), true) => v,
            _ => -p1 * ((h1 + h2) / (h1 * h2)) + p0 * (h1 / (h2 * (h1 + h2))),
        };
        let sd_p = f2.pos_sd.amax();
        let sd_v = match (f2.vel_sd, f2.vel, self.cfg.use_gnss_velocity) {
            (Some(s), Some(_), true) => s.amax(),
            _ => 2.5 * sd_p / h1.min(h2),
        }
        .max(VEL_SD_FLOOR_MPS);

        // Attitude: roll and pitch kept; yaw from the course plus the
        // yaw−course offset before the gap (mounting, sideslip).
        let before = quat_to_euler(&self.nav.q_nb);
        let mut att = before;
        let speed = vel.x.hypot(vel.y);
        let speed_before = self.nav.vel.x.hypot(self.nav.vel.y);
        let yaw_add = if speed > COURSE_MIN_SPEED_MPS {
            let offset = if speed_before > COURSE_MIN_SPEED_MPS {
                wrap_pi(before.yaw_rad - self.nav.vel.y.atan2(self.nav.vel.x))
            } else {
                0.0
            };
            att.yaw_rad = wrap_pi(vel.y.atan2(vel.x) + offset);
            YAW_SD_COURSE_RAD.hypot(sd_v / speed)
        } else {
            YAW_SD_NO_COURSE_RAD
        };
        let q_nb = euler_to_quat(&att);

        // Position of the IMU centre at `end`: the antenna's carried on by
        // the velocity, less the lever arm.
        let le = LocalEarth::new(&f2.pos, &vel);
        let d = vel * lead_s - q_nb * self.lever_b;
        let g = le.ned_to_geodetic_delta(&d);
        let mut pos = f2.pos;
        pos.lat_rad += g.x;
        pos.lon_rad += g.y;
        pos.h_m += g.z;

        // Covariance: what has accumulated propagated first, then the
        // navigation block replaced.
        self.propagate();
        let att_sd = [
            self.filter.sd(6).hypot(TILT_SD_ADD_RAD),
            self.filter.sd(7).hypot(TILT_SD_ADD_RAD),
            self.filter.sd(8).hypot(yaw_add),
        ];
        let sd_pos = Vector3::from_fn(|k, _| f2.pos_sd[k].hypot(sd_v * lead_s));
        let nstates = self.filter.n();
        let p = self.filter.covariance_mut();
        for i in 0..9 {
            for j in 0..nstates {
                p.data[i * nstates + j] = 0.0;
                p.data[j * nstates + i] = 0.0;
            }
        }
        for k in 0..3 {
            p.data[k * nstates + k] = sd_pos[k] * sd_pos[k];
            p.data[(3 + k) * nstates + 3 + k] = sd_v * sd_v;
            p.data[(6 + k) * nstates + 6 + k] = att_sd[k] * att_sd[k];
        }

        // The fixes up to `end` are spent: the last three initialised the
        // state, the earlier ones fell in the gap with nothing to fuse them
        // against.
        while let Some(f) = self.pending.front()
            && self.proc_time(f) <= end
        {
            self.pending.pop_front();
        }
        self.nav.pos = pos;
        self.nav.vel = vel;
        self.nav.q_nb = q_nb;
        self.mech.reset_history();
        self.aid.standstill.reset();
        self.stats.gaps += 1;
        self.stats.gap_total_s += gap_s;
        self.stats.max_gap_s = self.stats.max_gap_s.max(gap_s);
        self.stats.gap_reinits += 1;
        self.notes.push(format!(
            "IMU data gap of {gap_s:.3} s ending at {end} with GNSS going on: position and velocity \
             re-initialised from the fixes at {t0}, {t1}, {t2} (σ {sd_p:.3} m, {sd_v:.3} m/s), \
             yaw {} ({:.1}° σ), roll/pitch kept with σ {:.1}°/{:.1}°; the {} fixes inside the gap \
             were used for that only",
            if speed > COURSE_MIN_SPEED_MPS {
                "from the GNSS course"
            } else {
                "kept (too slow for a course)"
            },
            att_sd[2].to_degrees(),
            att_sd[0].to_degrees(),
            att_sd[1].to_degrees(),
            n
        ));
        // The INS was replaced: nothing before is a reference for faults.
        self.aid.gnss.monitor.reset();
        true
    }
}

/// An angle wrapped into (−π, π].
fn wrap_pi(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let w = a.rem_euclid(t);
    if w > std::f64::consts::PI { w - t } else { w }
}
