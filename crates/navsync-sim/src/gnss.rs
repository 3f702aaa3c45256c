//! GNSS receiver model: fixes of the antenna at multiples of the fix
//! period, with time-correlated noise, optional velocity, outages and
//! outliers.
//!
//! Position error per NED axis: e = e_GM + e_white, where e_GM is a
//! first-order Gauss–Markov process (exact discretisation, Brown & Hwang
//! §4.2) standing for the slowly varying multipath/atmosphere residuals of
//! RTK or single-point solutions, and e_white the epoch-to-epoch noise.
//! The antenna is at r_ant = r + C_b^n ℓ and moves at
//! v_ant = v + C_b^n (ω_eb^b × ℓ) (KF-GINS algorithm doc §3.5–3.6).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::rng::{self, SimRng};
use super::truth::{TruthGenerator, TruthPoint};
use navsync::earth::{Geodetic, LocalEarth};
use navsync::filter::gnss::GnssFix;
use navsync::filter::heading::baseline_azimuth;
use navsync::io::heading::{HeadingObs, HeadingSource};
use navsync::time::GpsTime;

/// Solution type; sets the default noise.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GnssMode {
    /// Carrier-phase fixed (cm level).
    #[default]
    Rtk,
    /// Single-point positioning (m level, strongly time-correlated).
    Spp,
}

/// The GNSS receiver as configured. Unset noise figures take the mode's
/// defaults (see [`GnssSpec::resolved`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssSpec {
    pub mode: GnssMode,
    /// Fix rate (Hz), 1–20.
    pub rate_hz: f64,
    /// White position noise per NED axis (m).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub white_sd_m: Option<[f64; 3]>,
    /// Gauss–Markov position noise per NED axis (m) and its correlation time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gm_sd_m: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gm_corr_time_s: Option<f64>,
    /// Standard deviations written into the files (m); default: the true
    /// total noise √(white² + GM²).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_written_m: Option<[f64; 3]>,
    /// Make the KF-GINS configuration use the 13-column file (position and
    /// velocity); both files are always written.
    pub velocity: bool,
    /// Velocity noise per NED axis (m/s), written as its standard deviation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vel_sd_mps: Option<[f64; 3]>,
    /// Antenna position in the body frame (FRD, m).
    pub lever_arm_m: [f64; 3],
    /// No fixes in these windows: `[start_s, length_s]` after the start.
    pub outages: Vec<[f64; 2]>,
    /// Probability that a fix is an outlier…
    pub outlier_prob: f64,
    /// …displaced by a magnitude uniform in this range (m).
    pub outlier_m: [f64; 2],
    /// Files carry validity time + this offset (a receiver's unsynchronised
    /// time tags); 0 for true time.
    pub time_offset_s: f64,
    /// Real fixes (a KF-GINS GNSS file) replayed against a reference drive
    /// (`reference_nav`): each fix's error from the reference antenna
    /// position, and its standard deviations, are kept; the rate and noise
    /// settings are then unused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub real_fixes: Option<String>,
    /// Column order of a 13-column `real_fixes` file: `cpp` or `matlab`.
    pub real_layout: RealLayout,
    /// A dual-antenna (moving-base) receiver: a baseline heading with
    /// every fix.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dual_antenna: Option<DualAntennaSpec>,
}

/// The antenna baseline of a dual-antenna receiver.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DualAntennaSpec {
    /// Yaw of the baseline (primary → secondary antenna) in the body frame,
    /// from x towards y (deg).
    pub mount_yaw_deg: f64,
    /// White noise of the measured azimuth (deg), also its stated σ.
    pub sd_deg: f64,
}

/// Column order of a 13-column real GNSS file (FORMATS.md §1).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RealLayout {
    #[default]
    Cpp,
    Matlab,
}

/// A real fix as an error to replay: its validity time, its error from
/// the reference antenna (NED, m; m/s) and its standard deviations.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ReplayFix {
    pub time: GpsTime,
    pub pos_error_ned: Vector3<f64>,
    pub pos_sd: Vector3<f64>,
    pub vel_error: Option<Vector3<f64>>,
    pub vel_sd: Option<Vector3<f64>>,
}

impl Default for GnssSpec {
    fn default() -> Self {
        GnssSpec {
            mode: GnssMode::Rtk,
            rate_hz: 1.0,
            white_sd_m: None,
            gm_sd_m: None,
            gm_corr_time_s: None,
            std_written_m: None,
            velocity: false,
            vel_sd_mps: None,
            lever_arm_m: [0.1, 0.5, -1.2],
            outages: Vec::new(),
            outlier_prob: 0.0,
            outlier_m: [2.0, 10.0],
            time_offset_s: 0.0,
            real_fixes: None,
            real_layout: RealLayout::Cpp,
            dual_antenna: None,
        }
    }
}

impl GnssSpec {
    /// The spec with every default filled in from the mode: RTK white
    /// (1.5, 1.5, 2.5) cm + Gauss–Markov (1, 1, 1.5) cm over 60 s, 2 cm/s;
    /// SPP white (0.3, 0.3, 0.6) m + Gauss–Markov (1.2, 1.2, 2.5) m over
    /// 300 s, 0.1 m/s.
    pub fn resolved(&self) -> GnssSpec {
        let (white, gm, tau, vel) = match self.mode {
            GnssMode::Rtk => ([0.015, 0.015, 0.025], [0.01, 0.01, 0.015], 60.0, [0.02; 3]),
            GnssMode::Spp => ([0.3, 0.3, 0.6], [1.2, 1.2, 2.5], 300.0, [0.1; 3]),
        };
        let white = self.white_sd_m.unwrap_or(white);
        let gm = self.gm_sd_m.unwrap_or(gm);
        let total = [0, 1, 2].map(|i| (white[i] * white[i] + gm[i] * gm[i]).sqrt());
        GnssSpec {
            white_sd_m: Some(white),
            gm_sd_m: Some(gm),
            gm_corr_time_s: Some(self.gm_corr_time_s.unwrap_or(tau)),
            std_written_m: Some(self.std_written_m.unwrap_or(total)),
            vel_sd_mps: Some(self.vel_sd_mps.unwrap_or(vel)),
            ..self.clone()
        }
    }

    /// Checks the figures.
    pub fn validate(&self) -> Result<(), String> {
        let r = self.resolved();
        if !(self.rate_hz > 0.0 && self.rate_hz <= 100.0) {
            return Err(format!(
                "GNSS rate {} Hz must be within (0, 100]",
                self.rate_hz
            ));
        }
        let all = r
            .white_sd_m
            .iter()
            .chain(r.gm_sd_m.iter())
            .chain(r.vel_sd_mps.iter())
            .flatten()
            .chain(r.std_written_m.iter().flatten());
        for v in all {
            if !(v.is_finite() && *v >= 0.0) {
                return Err("GNSS noise figures must be finite and >= 0".into());
            }
        }
        if r.std_written_m
            .unwrap_or_default()
            .iter()
            .any(|&s| s <= 0.0)
            || r.vel_sd_mps.unwrap_or_default().iter().any(|&s| s <= 0.0)
        {
            return Err(
                "written GNSS standard deviations must be positive (KF-GINS rejects 0)".into(),
            );
        }
        if r.gm_corr_time_s.unwrap_or(1.0) <= 0.0 {
            return Err("GNSS gm_corr_time_s must be positive".into());
        }
        if !(0.0..=1.0).contains(&self.outlier_prob) || self.outlier_m[1] < self.outlier_m[0] {
            return Err("GNSS outlier_prob must be within [0, 1] and outlier_m increasing".into());
        }
        if self.outages.iter().any(|o| o[1].is_nan() || o[1] < 0.0) {
            return Err("GNSS outage lengths must be >= 0".into());
        }
        Ok(())
    }

    /// Fix period in integer nanoseconds.
    pub fn period_ns(&self) -> i64 {
        (1e9 / self.rate_hz).round() as i64
    }
}

/// One GNSS epoch (also produced during outages, flagged, so that the
/// random streams advance the same way whether or not a fix is withheld).
#[derive(Clone, Debug)]
pub struct GnssEpoch {
    /// The fix as the receiver reports it (time = validity + offset).
    pub fix: GnssFix,
    /// True validity time.
    pub valid: GpsTime,
    /// True antenna position and velocity.
    pub truth_pos: Geodetic,
    pub truth_vel: Vector3<f64>,
    /// Error added (NED, m).
    pub error_ned: Vector3<f64>,
    pub outlier: bool,
    pub in_outage: bool,
    /// The measured azimuth of the antenna baseline (with
    /// [`GnssSpec::dual_antenna`]), at `valid`.
    pub heading: Option<HeadingObs>,
}

/// Streams GNSS epochs in time order.
pub struct GnssSim<'a> {
    spec: GnssSpec,
    truth: TruthGenerator<'a>,
    start: GpsTime,
    end: GpsTime,
    period_ns: i64,
    next: GpsTime,
    gm: Vector3<f64>,
    gm_phi: f64,
    gm_q: Vector3<f64>,
    white: SimRng,
    gm_rng: SimRng,
    vel_rng: SimRng,
    outlier_rng: SimRng,
    heading_rng: SimRng,
    /// Real fixes replayed in place of the noise model, and the next one.
    replay: Option<(Vec<ReplayFix>, usize)>,
}

impl<'a> GnssSim<'a> {
    /// Epochs strictly after `start` and before `end`.
    pub fn new(spec: &GnssSpec, truth: TruthGenerator<'a>, end: GpsTime, seed: u64) -> Self {
        let spec = spec.resolved();
        let start = truth.start();
        let period_ns = spec.period_ns();
        let first = GpsTime::from_ns((start.ns().div_euclid(period_ns) + 1) * period_ns);
        let gm_sd = Vector3::from(spec.gm_sd_m.unwrap_or_default());
        let tau = spec.gm_corr_time_s.unwrap_or(60.0);
        let gm_phi = (-(period_ns as f64 * 1e-9) / tau).exp();
        let mut gm_rng = rng::stream(seed, "gnss.gm");
        let gm = gm_sd.map(|s| s * rng::normal(&mut gm_rng));
        GnssSim {
            truth,
            start,
            end,
            period_ns,
            next: first,
            gm,
            gm_phi,
            gm_q: gm_sd * (1.0 - gm_phi * gm_phi).sqrt(),
            white: rng::stream(seed, "gnss.white"),
            gm_rng,
            vel_rng: rng::stream(seed, "gnss.vel"),
            outlier_rng: rng::stream(seed, "gnss.outlier"),
            heading_rng: rng::stream(seed, "gnss.heading"),
            spec,
            replay: None,
        }
    }

    /// Replays these real fixes (in time order) instead of drawing fixes;
    /// those outside (start, end) are skipped.
    pub fn with_replay(mut self, fixes: Vec<ReplayFix>) -> Self {
        let first = fixes.partition_point(|f| f.time <= self.start);
        self.replay = Some((fixes, first));
        self
    }

    /// The resolved spec.
    pub fn spec(&self) -> &GnssSpec {
        &self.spec
    }

    /// Validity time of the next epoch, if any.
    pub fn peek_time(&self) -> Option<GpsTime> {
        let next = match &self.replay {
            Some((fixes, i)) => fixes.get(*i)?.time,
            None => self.next,
        };
        (next < self.end).then_some(next)
    }

    /// Antenna position and velocity from the IMU-centre truth.
    pub fn antenna(p: &TruthPoint, lever: &Vector3<f64>) -> (Geodetic, Vector3<f64>) {
        let le = LocalEarth::new(&p.nav.pos, &p.nav.vel);
        let l_n = p.kin.c_nb * lever;
        let d = le.ned_to_geodetic_delta(&l_n);
        let pos = Geodetic::new(
            p.nav.pos.lat_rad + d.x,
            p.nav.pos.lon_rad + d.y,
            p.nav.pos.h_m + d.z,
        );
        let vel = p.nav.vel + p.kin.c_nb * p.w_eb_b().cross(lever);
        (pos, vel)
    }

    /// The baseline's measured azimuth at `t`: the filter's model of it
    /// ([`baseline_azimuth`], Groves §10.2.5) at the truth attitude, plus
    /// the spec's white noise (own stream: the other streams are those of
    /// a run without it).
    fn heading_at(&mut self, t: GpsTime, p: &TruthPoint) -> Option<HeadingObs> {
        let d = self.spec.dual_antenna?;
        let (truth_az, _) = baseline_azimuth(&p.nav, d.mount_yaw_deg.to_radians());
        let az = truth_az + d.sd_deg.to_radians() * rng::normal(&mut self.heading_rng);
        Some(HeadingObs {
            time: t.add_seconds(self.spec.time_offset_s),
            heading_rad: az.rem_euclid(std::f64::consts::TAU),
            sd_rad: d.sd_deg.to_radians(),
            source: HeadingSource::Baseline,
        })
    }

    /// The next epoch.
    pub fn next_epoch(&mut self) -> Option<GnssEpoch> {
        let t = self.peek_time()?;
        if let Some((fixes, i)) = &mut self.replay {
            let real = fixes[*i];
            *i += 1;
            return Some(self.replayed_epoch(&real));
        }
        self.next = t + self.period_ns;
        let s = &self.spec;
        let p = self.truth.state_at(t);
        let lever = Vector3::from(s.lever_arm_m);
        let (pos, vel) = Self::antenna(&p, &lever);

        // Every stream advances on every epoch (outage or not).
        let white_sd = Vector3::from(s.white_sd_m.unwrap_or_default());
        let white = white_sd.map(|sd| sd * rng::normal(&mut self.white));
        for k in 0..3 {
            self.gm[k] = self.gm_phi * self.gm[k] + self.gm_q[k] * rng::normal(&mut self.gm_rng);
        }
        let vel_sd = Vector3::from(s.vel_sd_mps.unwrap_or_default());
        let vel_err = vel_sd.map(|sd| sd * rng::normal(&mut self.vel_rng));
        let u = rng::uniform(&mut self.outlier_rng);
        let mag = rng::uniform_in(&mut self.outlier_rng, s.outlier_m[0], s.outlier_m[1]);
        let az = rng::uniform_in(&mut self.outlier_rng, 0.0, std::f64::consts::TAU);
        let up = rng::uniform_in(&mut self.outlier_rng, -0.5, 0.5);

        let outlier = u < s.outlier_prob;
        let mut err = self.gm + white;
        if outlier {
            err += Vector3::new(az.cos(), az.sin(), up) * mag;
        }
        let rel = t.seconds_since(self.start);
        let in_outage = s.outages.iter().any(|o| rel >= o[0] && rel < o[0] + o[1]);
        let le = LocalEarth::new(&pos, &vel);
        let d = le.ned_to_geodetic_delta(&err);
        let heading = self.heading_at(t, &p);
        let s = &self.spec;
        let fix = GnssFix {
            time: t.add_seconds(s.time_offset_s),
            pos: Geodetic::new(pos.lat_rad + d.x, pos.lon_rad + d.y, pos.h_m + d.z),
            pos_sd: Vector3::from(s.std_written_m.unwrap_or([1.0; 3])),
            vel: Some(vel + vel_err),
            vel_sd: Some(vel_sd),
        };
        Some(GnssEpoch {
            fix,
            valid: t,
            truth_pos: pos,
            truth_vel: vel,
            error_ned: err,
            outlier,
            in_outage,
            heading,
        })
    }
}

/// The errors of real fixes from a reference drive: each fix minus the
/// reference antenna at its time (position r + C_b^n ℓ, velocity
/// v + C_b^n (ω_nb^b × ℓ); KF-GINS algorithm doc §3.5–3.6), in the fix's
/// NED frame. Fixes outside the reference's span are left out.
pub fn replay_from_reference(
    motion: &super::fitted::FittedMotion,
    start: GpsTime,
    lever_b: &Vector3<f64>,
    fixes: &[GnssFix],
) -> Vec<ReplayFix> {
    let mut out = Vec::with_capacity(fixes.len());
    for f in fixes {
        let t = f.time.seconds_since(start);
        if !(t > 0.0 && t < motion.duration_s()) {
            continue;
        }
        let st = motion.state(t);
        let (c_nb, w_nb_b) = super::fitted::euler_kinematics(&st.euler, &st.euler_rate);
        let pos = motion.geodetic(&st.pos_ned);
        let le = LocalEarth::new(&pos, &st.vel_n);
        let l_n = c_nb * lever_b;
        let d = le.ned_to_geodetic_delta(&l_n);
        let ant = Geodetic::new(pos.lat_rad + d.x, pos.lon_rad + d.y, pos.h_m + d.z);
        let ant_vel = st.vel_n + c_nb * w_nb_b.cross(lever_b);
        let err = le.geodetic_delta_to_ned(
            f.pos.lat_rad - ant.lat_rad,
            f.pos.lon_rad - ant.lon_rad,
            f.pos.h_m - ant.h_m,
        );
        out.push(ReplayFix {
            time: f.time,
            pos_error_ned: err,
            pos_sd: f.pos_sd,
            vel_error: f.vel.map(|v| v - ant_vel),
            vel_sd: f.vel_sd,
        });
    }
    out
}

impl GnssSim<'_> {
    /// The simulated antenna at the fix's time plus the real fix's error.
    fn replayed_epoch(&mut self, real: &ReplayFix) -> GnssEpoch {
        let t = real.time;
        let p = self.truth.state_at(t);
        let lever = Vector3::from(self.spec.lever_arm_m);
        let (pos, vel) = Self::antenna(&p, &lever);
        let le = LocalEarth::new(&pos, &vel);
        let d = le.ned_to_geodetic_delta(&real.pos_error_ned);
        let rel = t.seconds_since(self.start);
        let in_outage = self
            .spec
            .outages
            .iter()
            .any(|o| rel >= o[0] && rel < o[0] + o[1]);
        let heading = self.heading_at(t, &p);
        let fix = GnssFix {
            time: t.add_seconds(self.spec.time_offset_s),
            pos: Geodetic::new(pos.lat_rad + d.x, pos.lon_rad + d.y, pos.h_m + d.z),
            pos_sd: real.pos_sd,
            vel: real.vel_error.map(|e| vel + e),
            vel_sd: real.vel_sd,
        };
        GnssEpoch {
            fix,
            valid: t,
            truth_pos: pos,
            truth_vel: vel,
            error_ned: real.pos_error_ned,
            outlier: false,
            in_outage,
            heading,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::{Segment, Trajectory, TrajectoryOptions};
    use navsync::earth::ned_offset;

    fn traj(segs: &[Segment], heading_deg: f64) -> Trajectory {
        let opts = TrajectoryOptions {
            initial_heading_rad: heading_deg.to_radians(),
            ..Default::default()
        };
        Trajectory::from_segments(Geodetic::from_deg(30.0, 114.0, 20.0), segs, opts).unwrap()
    }

    #[test]
    fn lever_arm_places_the_antenna() {
        // Static, heading east: the antenna 1 m forward and 0.5 m right is
        // 1 m east and 0.5 m south of the IMU, 1.2 m above it.
        let t = traj(&[Segment::Static { duration_s: 20.0 }], 90.0);
        let start = GpsTime::from_week_sow(2300, 100000.0);
        let spec = GnssSpec {
            white_sd_m: Some([0.0; 3]),
            gm_sd_m: Some([0.0; 3]),
            lever_arm_m: [1.0, 0.5, -1.2],
            ..Default::default()
        };
        let mut g = GnssSim::new(
            &spec,
            TruthGenerator::new(&t, start),
            start.add_seconds(20.0),
            1,
        );
        let e = g.next_epoch().unwrap();
        assert_eq!(e.valid, start.add_seconds(1.0));
        let d = ned_offset(&Geodetic::from_deg(30.0, 114.0, 20.0), &e.fix.pos);
        assert!((d - Vector3::new(-0.5, 1.0, -1.2)).norm() < 1e-6, "{d}");
        // 19 epochs in (start, start + 20 s).
        let mut n = 1;
        while g.next_epoch().is_some() {
            n += 1;
        }
        assert_eq!(n, 19);
    }

    #[test]
    fn turning_antenna_velocity_includes_the_lever_arm() {
        // Turning at 0.2 rad/s with the antenna 2 m ahead: the antenna moves
        // 0.4 m/s sideways relative to the IMU.
        let segs = [
            Segment::Accelerate {
                speed_mps: 10.0,
                accel_mps2: Some(2.0),
            },
            Segment::Turn {
                angle_deg: 180.0,
                yaw_rate_deg_s: Some(0.2f64.to_degrees()),
                radius_m: None,
                ramp_s: Some(1.0),
            },
        ];
        let t = traj(&segs, 0.0);
        let start = GpsTime::from_week_sow(2300, 0.0);
        let mut tg = TruthGenerator::new(&t, start);
        let p = tg.state_at(start.add_seconds(14.0));
        let (_, v) = GnssSim::antenna(&p, &Vector3::new(2.0, 0.0, 0.0));
        let side = p.nav.c_nb().transpose() * (v - p.nav.vel);
        assert!((side.y - 0.4).abs() < 1e-4, "{side}");
    }

    #[test]
    fn noise_statistics_outliers_and_outages() {
        let t = traj(&[Segment::Static { duration_s: 4000.0 }], 0.0);
        let start = GpsTime::from_week_sow(2300, 0.0);
        let spec = GnssSpec {
            mode: GnssMode::Spp,
            outages: vec![[100.0, 50.0]],
            outlier_prob: 0.01,
            outlier_m: [20.0, 30.0],
            ..Default::default()
        };
        let run = |spec: &GnssSpec| {
            let mut g = GnssSim::new(
                spec,
                TruthGenerator::new(&t, start),
                start.add_seconds(4000.0),
                5,
            );
            let mut v = Vec::new();
            while let Some(e) = g.next_epoch() {
                v.push(e);
            }
            v
        };
        let eps = run(&spec);
        assert_eq!(eps.len(), 3999);
        assert_eq!(eps.iter().filter(|e| e.in_outage).count(), 50);
        let outliers = eps.iter().filter(|e| e.outlier).count();
        // Binomial(3999, 0.01): mean 40, sd 6.3.
        assert!((20..=60).contains(&outliers), "{outliers}");
        let clean: Vec<&GnssEpoch> = eps.iter().filter(|e| !e.outlier).collect();
        let rms_n =
            (clean.iter().map(|e| e.error_ned.x.powi(2)).sum::<f64>() / clean.len() as f64).sqrt();
        // SPP north: √(0.3² + 1.2²) = 1.237 m; a GM of 300 s over 4000 s
        // gives ~7 independent samples: ±40 %.
        assert!((0.7..1.8).contains(&rms_n), "{rms_n}");
        // Turning outliers off changes nothing else.
        let no_out = GnssSpec {
            outlier_prob: 0.0,
            ..spec.clone()
        };
        let eps2 = run(&no_out);
        for (a, b) in eps.iter().zip(&eps2) {
            if !a.outlier {
                assert_eq!(a.fix.pos, b.fix.pos);
            }
        }
        assert!(
            GnssSpec {
                rate_hz: 0.0,
                ..GnssSpec::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            GnssSpec {
                std_written_m: Some([0.0, 0.1, 0.1]),
                ..GnssSpec::default()
            }
            .validate()
            .is_err()
        );
    }
}
