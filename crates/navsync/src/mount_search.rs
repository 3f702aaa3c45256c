//! The IMU's mounting yaw in a land vehicle, from the motion: without the
//! INS heading, from the IMU's specific force against the GNSS track's
//! acceleration.
//!
//! A land vehicle moves along its forward axis (no sideslip at low lateral
//! acceleration; Groves, *Principles of GNSS, Inertial, and Multisensor
//! Integrated Navigation Systems*, 2nd ed., §6.1.4, heading from
//! trajectory), so its horizontal acceleration in its own axes is
//! (along-track dv/dt, cross-track v·dχ/dt), and dχ/dt is its yaw rate ω,
//! which the vertical gyro measures whatever the mounting yaw: the
//! along-track part from the GNSS speed, the cross-track part v·ω from the
//! GNSS speed and the gyro. (The cross-track part from the GNSS positions'
//! second difference alone drowns at 1 m/s: on the Husky's 0.9 m fixes the
//! fit was 135° ± 9°, where v·ω gives 90°, its mounting.) The IMU, levelled by its roll and pitch (gravity
//! is vertical, so the levelled horizontal specific force is the
//! acceleration), measures the same vector in its own levelled axes, turned
//! by the mounting yaw α (`mount_deg[2]`: the IMU's yaw is the vehicle's
//! heading + α, C_b^v = R_z(α)·R_y(pitch)·R_x(roll), the NHC's
//! `filter::nhc`). So a_v = R(α)·f_l + c, with c a constant (accelerometer
//! bias and the levelling's error, which gravity leaks into the horizontal
//! axes), and α is the 2-D rotation that fits one set of vectors to the
//! other: the orthogonal Procrustes problem (Wahba, "A least squares
//! estimate of satellite attitude", SIAM Review 7(3), 1965; Kabsch, Acta
//! Cryst. A32, 1976), after removing each set's mean for c. u-blox's
//! dead-reckoning receivers estimate the same angle from the motion
//! (u-blox ZED-F9R Integration manual, "Automatic IMU-mount alignment"),
//! the product reference for what this does.
//!
//! Pairing. The along-track acceleration is the speeds' difference over
//! three fixes a, b, c at least `half_span_s` apart (positions only, so any
//! receiver will do): (|v_bc| − |v_ab|)/((t_c − t_a)/2) is the speed's
//! rate averaged with the triangular kernel K(t) = (t − t_a)/(t_b − t_a)
//! on [t_a, t_b], (t_c − t)/(t_c − t_b) on [t_b, t_c] (a second
//! difference); v·ω at each IMU sample (v interpolated between the chords'
//! middles) and the IMU's specific force are averaged with the same
//! kernel, all expressed in their axes at t_b (turned by the vertical
//! gyro's yaw since t_b). Windows do not overlap, so the samples'
//! GNSS noise is independent; the residuals' lag-one correlation (slope,
//! bank, sideslip) reduces the count of independent samples the σ uses.
//!
//! The angle's σ is σ_r/√(Σ|f_l − f̄_l|²) (σ_r the residuals' per-axis σ),
//! inflated by n/n_eff. A drive without acceleration (straight at constant
//! speed) has Σ|f_l − f̄_l|² near zero: the σ is large and the estimate is
//! "not observable", with the reason. So is a fit whose gain
//! Σ a·R(α)f / Σ|f|² is not near 1: an IMU whose horizontal specific force
//! is mostly vibration or tilt changes (the Husky's: 0.13 m/s² of it against
//! 0.06 m/s² of v·ω) gives an angle, but not the mounting's. The roll and pitch are the
//! alignment's (levelled at the start): a road's grade or bank changing by
//! δ leaks g·δ into the horizontal, which the residuals carry into the σ.

use std::collections::VecDeque;

use nalgebra::{Matrix3, Vector2};
use serde::Serialize;

use crate::attitude::{Euler, euler_to_dcm, wrap_pi};
use crate::earth::{Geodetic, ned_offset};
use crate::time::GpsTime;
use crate::types::{GnssFix, ImuSample};

/// Settings of the mounting-yaw search.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MountSearchOptions {
    /// Least time between the three fixes of a second difference (s); the
    /// span used is the larger of this and what brings the second
    /// difference's noise (√6·σ_h/h²) down to `accel_noise_mps2`.
    pub half_span_s: f64,
    /// Longest time between two fixes of a second difference, in units of
    /// the span used (longer: a gap, the window restarts).
    pub max_gap_spans: f64,
    /// The largest span used (s).
    pub max_half_span_s: f64,
    /// The second difference's noise aimed at (m/s², per axis).
    pub accel_noise_mps2: f64,
    /// Least speed at the middle fix (m/s): moving forwards, clearly.
    pub min_speed_mps: f64,
    /// Fixes with a horizontal σ above this (m) are not used.
    pub max_fix_sd_m: f64,
    /// The estimate is observable when its σ is at most this (rad)…
    pub max_sd_rad: f64,
    /// …from at least this many independent samples.
    pub min_effective_samples: f64,
}

impl Default for MountSearchOptions {
    fn default() -> Self {
        MountSearchOptions {
            half_span_s: 1.0,
            max_gap_spans: 2.0,
            max_half_span_s: 4.0,
            accel_noise_mps2: 0.25,
            min_speed_mps: 0.5,
            max_fix_sd_m: 10.0,
            max_sd_rad: 5f64.to_radians(),
            min_effective_samples: 8.0,
        }
    }
}

/// The mounting yaw found in the motion.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MountYawEstimate {
    /// The estimate (deg, `mount_deg[2]`'s convention), when there was any
    /// sample; meaningful only when `observable`.
    pub yaw_deg: Option<f64>,
    /// Its σ (deg).
    pub sd_deg: Option<f64>,
    /// Paired samples used (outliers excluded) and excluded as outliers.
    pub samples: usize,
    /// Samples excluded as outliers (residual over 4σ: reversing, slips).
    pub outliers: usize,
    /// Independent samples (from the residuals' lag-one correlation).
    /// The gain must be within [1/`MAX_GAIN_RATIO`, `MAX_GAIN_RATIO`] too.
    pub effective_samples: f64,
    /// RMS of the GNSS horizontal acceleration about its mean (m/s²): how
    /// much the drive excites the estimate.
    pub accel_rms_mps2: f64,
    /// RMS of the fit's residuals per axis (m/s²).
    pub residual_sd_mps2: f64,
    /// The least-squares gain of the turned specific force onto the
    /// acceleration, Σ a·R(α)f / Σ|f|² (centred): 1 when the IMU sees the
    /// vehicle's acceleration; far from 1 when vibration, tilt changes or a
    /// time offset dominate what it sees.
    pub gain: f64,
    /// True when the σ and the sample count meet the options' bounds.
    pub observable: bool,
    /// Why it is not observable (empty when it is).
    pub reason: String,
}

/// One IMU sample, levelled: its horizontal velocity increment in the
/// levelled IMU axes and its vertical angle increment.
#[derive(Clone, Copy, Debug)]
struct Levelled {
    t_end: GpsTime,
    dt_s: f64,
    dv_l: Vector2<f64>,
    /// Yaw (rad) integrated to the end of the sample, from an arbitrary
    /// origin (only its differences over a window are used).
    yaw_end_rad: f64,
    dyaw_rad: f64,
}

/// A GNSS second difference waiting for the IMU samples over its window.
#[derive(Clone, Copy, Debug)]
struct Window {
    t_a: GpsTime,
    t_b: GpsTime,
    t_c: GpsTime,
    /// The speeds of the chords a→b and b→c (m/s), at their middles.
    speeds_mps: [f64; 2],
    /// The along-track acceleration (m/s²): the speeds' second difference.
    along_mps2: f64,
}

#[derive(Clone, Copy, Debug)]
struct Fix {
    time: GpsTime,
    ne_m: Vector2<f64>,
    sd_h_m: f64,
}

/// The streaming estimator: push IMU samples and fixes in time order (in
/// any interleaving), then [`MountSearch::finish`].
#[derive(Clone, Debug)]
pub struct MountSearch {
    opts: MountSearchOptions,
    c_bl: Matrix3<f64>,
    origin: Option<Geodetic>,
    anchor: Option<Fix>,
    middle: Option<Fix>,
    pending: VecDeque<Window>,
    imu: VecDeque<Levelled>,
    last_imu: Option<GpsTime>,
    yaw_rad: f64,
    /// (IMU levelled specific force, GNSS vehicle-axes acceleration).
    pairs: Vec<(Vector2<f64>, Vector2<f64>)>,
}

impl MountSearch {
    /// For an IMU levelled by `roll_rad`, `pitch_rad` (its attitude's roll
    /// and pitch; the yaw is not needed).
    pub fn new(opts: MountSearchOptions, roll_rad: f64, pitch_rad: f64) -> Self {
        MountSearch {
            opts,
            c_bl: euler_to_dcm(&Euler::new(roll_rad, pitch_rad, 0.0)),
            origin: None,
            anchor: None,
            middle: None,
            pending: VecDeque::new(),
            imu: VecDeque::new(),
            last_imu: None,
            yaw_rad: 0.0,
            pairs: Vec::new(),
        }
    }

    /// One IMU sample (increments over the interval ending at its time).
    pub fn push_imu(&mut self, s: &ImuSample) {
        let Some(prev) = self.last_imu.replace(s.time) else {
            return;
        };
        let dt_s = s.time.seconds_since(prev);
        if dt_s.is_nan()
            || dt_s <= 0.0
            || !s.dvel.iter().chain(s.dtheta.iter()).all(|x| x.is_finite())
        {
            return;
        }
        let dv = self.c_bl * s.dvel;
        let dyaw_rad = (self.c_bl * s.dtheta).z;
        self.yaw_rad += dyaw_rad;
        self.imu.push_back(Levelled {
            t_end: s.time,
            dt_s,
            dv_l: Vector2::new(dv.x, dv.y),
            yaw_end_rad: self.yaw_rad,
            dyaw_rad,
        });
        while let Some(w) = self.pending.front().copied()
            && w.t_c <= s.time
        {
            self.pending.pop_front();
            if let Some(pair) = self.imu_over(&w) {
                self.pairs.push(pair);
            }
        }
        // Keep the samples a window may still need.
        let keep_from = self
            .pending
            .front()
            .map(|w| w.t_a)
            .or(self.anchor.map(|a| a.time))
            .unwrap_or(s.time);
        while self.imu.front().is_some_and(|l| l.t_end < keep_from) {
            self.imu.pop_front();
        }
    }

    /// One GNSS fix (its position and σ; velocities are not needed).
    pub fn push_fix(&mut self, f: &GnssFix) {
        let sd_h_m = f.pos_sd.x.hypot(f.pos_sd.y);
        if sd_h_m.is_nan()
            || sd_h_m > self.opts.max_fix_sd_m
            || !f.pos.lat_rad.is_finite()
            || !f.pos.lon_rad.is_finite()
        {
            return;
        }
        let origin = *self.origin.get_or_insert(f.pos);
        let d = ned_offset(&origin, &f.pos);
        let fix = Fix {
            time: f.time,
            ne_m: Vector2::new(d.x, d.y),
            sd_h_m,
        };
        let Some(a) = self.anchor else {
            self.anchor = Some(fix);
            return;
        };
        let span = self.span_s(a.sd_h_m.max(sd_h_m));
        let max_gap = span * self.opts.max_gap_spans;
        let last = self.middle.unwrap_or(a);
        let dt = fix.time.seconds_since(last.time);
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        if dt > max_gap {
            // A gap: start again from here.
            self.anchor = Some(fix);
            self.middle = None;
            return;
        }
        if dt < span {
            return;
        }
        match self.middle {
            None => self.middle = Some(fix),
            Some(b) => {
                if let Some(w) = self.window(&a, &b, &fix) {
                    self.pending.push_back(w);
                }
                self.anchor = Some(fix);
                self.middle = None;
            }
        }
    }

    /// The half span for fixes of horizontal σ `sd_h_m`: the second
    /// difference's per-axis noise is √6·σ/h² (σ per axis = σ_h/√2).
    fn span_s(&self, sd_h_m: f64) -> f64 {
        let sd_axis = sd_h_m / std::f64::consts::SQRT_2;
        let h = (6f64.sqrt() * sd_axis / self.opts.accel_noise_mps2).sqrt();
        h.clamp(self.opts.half_span_s, self.opts.max_half_span_s)
    }

    /// The chords' speeds of three fixes and their second difference.
    fn window(&self, a: &Fix, b: &Fix, c: &Fix) -> Option<Window> {
        let h1 = b.time.seconds_since(a.time);
        let h2 = c.time.seconds_since(b.time);
        let s1 = (b.ne_m - a.ne_m).norm() / h1;
        let s2 = (c.ne_m - b.ne_m).norm() / h2;
        // The speed at t_b, interpolated between the chords' middles.
        if (s1 * h2 + s2 * h1) / (h1 + h2) < self.opts.min_speed_mps {
            return None;
        }
        Some(Window {
            t_a: a.time,
            t_b: b.time,
            t_c: c.time,
            speeds_mps: [s1, s2],
            along_mps2: (s2 - s1) / (0.5 * (h1 + h2)),
        })
    }

    /// Over a window, with the second difference's kernel, in the axes at
    /// t_b: the IMU's levelled specific force and the vehicle's acceleration
    /// (along-track from the speeds, cross-track v·ω); None when the IMU
    /// does not cover the window.
    fn imu_over(&self, w: &Window) -> Option<(Vector2<f64>, Vector2<f64>)> {
        let h1 = w.t_b.seconds_since(w.t_a);
        let h2 = w.t_c.seconds_since(w.t_b);
        // The yaw at t_b: the end of the last sample before it.
        let yaw_b = self
            .imu
            .iter()
            .take_while(|l| l.t_end <= w.t_b)
            .last()?
            .yaw_end_rad;
        let (mut f_sum, mut a_sum) = (Vector2::zeros(), Vector2::zeros());
        let (mut weight_s, mut covered_s) = (0.0, 0.0);
        for l in &self.imu {
            let t_mid = l.t_end.add_seconds(-0.5 * l.dt_s);
            let (u1, u2) = (t_mid.seconds_since(w.t_a), w.t_c.seconds_since(t_mid));
            if u1 < 0.0 || u2 < 0.0 {
                continue;
            }
            let k = if u1 <= h1 { u1 / h1 } else { u2 / h2 };
            let yaw = l.yaw_end_rad - 0.5 * l.dyaw_rad - yaw_b;
            // The speed here: linear between the chords' middles.
            let u = ((u1 - 0.5 * h1) / (0.5 * (h1 + h2))).clamp(0.0, 1.0);
            let speed = w.speeds_mps[0] + u * (w.speeds_mps[1] - w.speeds_mps[0]);
            // Δv of the vehicle over the sample: (a_along, v·ω)·dt.
            let dv_v = Vector2::new(w.along_mps2 * l.dt_s, speed * l.dyaw_rad);
            f_sum += rotate(&l.dv_l, yaw) * k;
            a_sum += rotate(&dv_v, yaw) * k;
            weight_s += k * l.dt_s;
            covered_s += l.dt_s;
        }
        (covered_s >= 0.9 * (h1 + h2) && weight_s > 0.0)
            .then(|| (f_sum / weight_s, a_sum / weight_s))
    }

    /// The estimate from the samples so far.
    pub fn finish(&self) -> MountYawEstimate {
        fit(&self.pairs, &self.opts)
    }
}

/// `v` turned by `angle_rad` (x towards y).
fn rotate(v: &Vector2<f64>, angle_rad: f64) -> Vector2<f64> {
    let (s, c) = angle_rad.sin_cos();
    Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

/// The rotation α fitting a = R(α)·f + c over the pairs (f, a), one
/// robust pass (residuals over 4σ excluded, then refitted).
fn fit(pairs: &[(Vector2<f64>, Vector2<f64>)], o: &MountSearchOptions) -> MountYawEstimate {
    let mut used: Vec<(Vector2<f64>, Vector2<f64>)> = pairs.to_vec();
    let mut outliers = 0;
    let mut est = procrustes(&used);
    if let Some(e) = &est {
        // |r| of a 2-D normal residual with σ per axis is Rayleigh: median
        // σ·√(2 ln 2).
        let mut norms: Vec<f64> = e.residuals.iter().map(|r| r.norm()).collect();
        norms.sort_by(f64::total_cmp);
        let sigma = norms[norms.len() / 2] / (2.0 * std::f64::consts::LN_2).sqrt();
        let keep: Vec<bool> = e
            .residuals
            .iter()
            .map(|r| r.norm() <= 4.0 * sigma)
            .collect();
        outliers = keep.iter().filter(|k| !**k).count();
        if outliers > 0 {
            used = used
                .into_iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(p, _)| p)
                .collect();
            est = procrustes(&used);
        }
    }
    let Some(e) = est else {
        return MountYawEstimate {
            yaw_deg: None,
            sd_deg: None,
            samples: used.len(),
            outliers,
            effective_samples: 0.0,
            accel_rms_mps2: 0.0,
            residual_sd_mps2: 0.0,
            gain: 0.0,
            observable: false,
            reason: format!(
                "{} paired samples of IMU specific force and GNSS acceleration (moving at ≥ {} m/s with fixes \
                 ≤ {} m σ): too few to fit",
                used.len(),
                o.min_speed_mps,
                o.max_fix_sd_m
            ),
        };
    };
    let n = used.len() as f64;
    // Lag-one correlation of the residuals: n_eff = n(1 − ρ)/(1 + ρ).
    let ss: f64 = e.residuals.iter().map(|r| r.norm_squared()).sum();
    let lag1: f64 = e.residuals.windows(2).map(|w| w[0].dot(&w[1])).sum();
    let rho = if ss > 0.0 {
        (lag1 / ss).clamp(0.0, 0.9)
    } else {
        0.0
    };
    let n_eff = n * (1.0 - rho) / (1.0 + rho);
    let dof = (2.0 * n - 3.0).max(1.0);
    let sigma_r = (ss / dof).sqrt();
    let sd_rad = if e.spread > 0.0 {
        sigma_r / e.spread.sqrt() * (n / n_eff).sqrt()
    } else {
        f64::INFINITY
    };
    let accel_rms = (e.accel_spread / n).sqrt();
    let gain_ok = e.gain <= MAX_GAIN_RATIO && e.gain >= 1.0 / MAX_GAIN_RATIO;
    let observable = sd_rad <= o.max_sd_rad && n_eff >= o.min_effective_samples && gain_ok;
    let reason = if observable {
        String::new()
    } else if sd_rad <= o.max_sd_rad && n_eff >= o.min_effective_samples {
        format!(
            "the IMU's horizontal specific force does not follow the vehicle's acceleration (gain {:.2}, \
             expected 1 within a factor {MAX_GAIN_RATIO}): vibration, tilt changes or a time offset dominate it",
            e.gain
        )
    } else {
        format!(
            "the drive has too little horizontal acceleration for it: {:.2} m/s² RMS about its mean against \
             {:.2} m/s² of noise over {} samples ({:.0} independent), σ {:.1}° (observable from σ ≤ {:.0}° and \
             ≥ {:.0} independent samples: turns, starts and stops)",
            accel_rms,
            sigma_r,
            used.len(),
            n_eff,
            sd_rad.to_degrees().min(999.0),
            o.max_sd_rad.to_degrees(),
            o.min_effective_samples
        )
    };
    MountYawEstimate {
        yaw_deg: Some(e.angle_rad.to_degrees()),
        sd_deg: Some(sd_rad.to_degrees().min(180.0)),
        samples: used.len(),
        outliers,
        effective_samples: n_eff,
        accel_rms_mps2: accel_rms,
        residual_sd_mps2: sigma_r,
        gain: e.gain,
        observable,
        reason,
    }
}

struct Procrustes {
    angle_rad: f64,
    residuals: Vec<Vector2<f64>>,
    /// Σ|f − f̄|² (the IMU side's spread, (m/s²)²).
    spread: f64,
    /// Σ|a − ā|².
    accel_spread: f64,
    /// Σ a·R(α)f / Σ|f|² (centred).
    gain: f64,
}

/// The fit's gain must be within a factor of this of 1.
pub const MAX_GAIN_RATIO: f64 = 1.25;

/// The 2-D orthogonal Procrustes fit with translation: α = atan2(Σ f×a,
/// Σ f·a) over the centred pairs (Kabsch 1976 in two dimensions).
fn procrustes(pairs: &[(Vector2<f64>, Vector2<f64>)]) -> Option<Procrustes> {
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let f_mean = pairs.iter().map(|p| p.0).sum::<Vector2<f64>>() / n;
    let a_mean = pairs.iter().map(|p| p.1).sum::<Vector2<f64>>() / n;
    let (mut dot, mut cross, mut spread, mut accel_spread) = (0.0, 0.0, 0.0, 0.0);
    for (f, a) in pairs {
        let (f, a) = (f - f_mean, a - a_mean);
        dot += f.dot(&a);
        cross += f.x * a.y - f.y * a.x;
        spread += f.norm_squared();
        accel_spread += a.norm_squared();
    }
    let angle_rad = wrap_pi(cross.atan2(dot));
    let residuals = pairs
        .iter()
        .map(|(f, a)| (a - a_mean) - rotate(&(f - f_mean), angle_rad))
        .collect();
    Some(Procrustes {
        angle_rad,
        residuals,
        spread,
        accel_spread,
        gain: if spread > 0.0 {
            dot.hypot(cross) / spread
        } else {
            0.0
        },
    })
}

/// What a run does with an estimate, given the sheet's mounting yaw.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MountYawDecision {
    /// The estimate.
    pub estimate: MountYawEstimate,
    /// The sheet's `mount_deg[2]` (deg).
    pub sheet_yaw_deg: f64,
    /// The mounting yaw the run used (deg).
    pub used_yaw_deg: f64,
    /// True when the run took the estimate instead of the sheet's 0.
    pub adopted: bool,
    /// True when the sheet's nonzero yaw disagrees with the estimate by
    /// more than 3σ (kept, and warned).
    pub disagrees: bool,
    /// What to tell the user (empty when the estimate changed nothing and
    /// agreed).
    pub message: String,
}

/// The least difference (deg) from a default 0 for which an estimate is
/// taken (and 3σ).
pub const ADOPT_MIN_DEG: f64 = 5.0;

/// Decides: with the sheet's default 0, an observable estimate beyond
/// max(3σ, 5°) is taken; a nonzero sheet yaw is kept, and warned about when
/// the estimate disagrees by more than 3σ.
pub fn decide(estimate: MountYawEstimate, sheet_yaw_deg: f64) -> MountYawDecision {
    let mut d = MountYawDecision {
        sheet_yaw_deg,
        used_yaw_deg: sheet_yaw_deg,
        adopted: false,
        disagrees: false,
        message: String::new(),
        estimate,
    };
    let e = &d.estimate;
    let (Some(yaw), Some(sd), true) = (e.yaw_deg, e.sd_deg, e.observable) else {
        d.message = format!(
            "the IMU's mounting yaw is not observable from the motion: {}; the sensor sheet's mount_deg[2] \
             {:.1}° is used unchecked",
            e.reason, sheet_yaw_deg
        );
        return d;
    };
    let diff = wrap_pi((yaw - sheet_yaw_deg).to_radians()).to_degrees();
    if sheet_yaw_deg == 0.0 {
        if diff.abs() > (3.0 * sd).max(ADOPT_MIN_DEG) {
            d.adopted = true;
            d.used_yaw_deg = yaw;
            d.message = format!(
                "the IMU's mounting yaw found in the motion is {yaw:.1}° (σ {sd:.1}°, from {} samples of specific \
                 force against the GNSS acceleration) and the sensor sheet gives mount_deg[2] 0: taken as \
                 {yaw:.1}° for the course heading, the alignment's course, the NHC and the odometer (set \
                 mount_deg[2] in the sheet to override)",
                e.samples
            );
        }
    } else if diff.abs() > 3.0 * sd {
        d.disagrees = true;
        d.message = format!(
            "the sensor sheet's mount_deg[2] is {sheet_yaw_deg:.1}° but the motion gives {yaw:.1}° (σ {sd:.1}°, \
             {:.1}° apart, over 3σ): the sheet's is used; check mount_deg (docs/real-logs.md, Mounting)",
            diff.abs()
        );
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::rng::{normal, stream};
    use nalgebra::Vector3;

    /// A level drive: speed s(t) and heading ψ(t) given, the IMU mounted
    /// at `mount` in the vehicle; 100 Hz IMU with white noise, 5 Hz fixes
    /// with `fix_sd_m` per axis. Returns the estimate.
    fn drive(
        mount: Euler,
        duration_s: f64,
        speed: impl Fn(f64) -> (f64, f64),
        yaw_rate: impl Fn(f64) -> f64,
        fix_sd_m: f64,
        seed: u64,
    ) -> MountYawEstimate {
        let mut rng = stream(seed, "mount");
        let c_bv = euler_to_dcm(&mount);
        let c_vb = c_bv.transpose();
        let origin = Geodetic::from_deg(30.5, 114.3, 20.0);
        let (r_m, r_n) = crate::earth::radii(origin.lat_rad.sin());
        // The IMU's levelled roll and pitch are the mounting's (level vehicle).
        let mut m = MountSearch::new(
            MountSearchOptions::default(),
            mount.roll_rad,
            mount.pitch_rad,
        );
        let dt = 0.01;
        let (mut psi, mut pos) = (0.3, Vector2::<f64>::zeros());
        let t0 = GpsTime::from_week_sow(2200, 1000.0);
        let g = 9.8;
        for k in 0..(duration_s / dt) as usize {
            let t = k as f64 * dt;
            let tm = t + 0.5 * dt;
            let (v, dv) = speed(tm);
            let w = yaw_rate(tm);
            let psi_m = psi + 0.5 * w * dt;
            // Specific force in the vehicle's axes (forward, right, down).
            let f_v = Vector3::new(dv, v * w, -g);
            let dvel = c_vb * f_v * dt + Vector3::from_fn(|_, _| 0.002 * normal(&mut rng));
            let dtheta = c_vb * Vector3::new(0.0, 0.0, w * dt);
            pos += Vector2::new(psi_m.cos(), psi_m.sin()) * v * dt;
            psi += w * dt;
            let time = t0.add_seconds(t + dt);
            m.push_imu(&ImuSample {
                time,
                dtheta,
                dvel,
                odo_speed: None,
            });
            if (k + 1) % 20 == 0 {
                let n = pos + Vector2::from_fn(|_, _| fix_sd_m * normal(&mut rng));
                m.push_fix(&GnssFix {
                    time,
                    pos: Geodetic::new(
                        origin.lat_rad + n.x / (r_m + origin.h_m),
                        origin.lon_rad + n.y / ((r_n + origin.h_m) * origin.lat_rad.cos()),
                        origin.h_m,
                    ),
                    pos_sd: Vector3::new(fix_sd_m, fix_sd_m, 2.0 * fix_sd_m),
                    vel: None,
                    vel_sd: None,
                });
            }
        }
        m.finish()
    }

    /// Figure-of-eight at 8–12 m/s: yaw rate ±0.2 rad/s, speed varying.
    fn urban(mount: Euler, fix_sd_m: f64, seed: u64) -> MountYawEstimate {
        drive(
            mount,
            240.0,
            |t| (10.0 + 2.0 * (0.1 * t).sin(), 0.2 * (0.1 * t).cos()),
            |t| 0.2 * (2.0 * std::f64::consts::PI * t / 60.0).sin(),
            fix_sd_m,
            seed,
        )
    }

    #[test]
    fn recovers_the_mounting_yaw_of_a_turning_drive() {
        // Noise: fixes 0.3 m per axis → span h = √(√6·0.3/0.25) = 1.7 s
        // (1.8 s at 5 Hz), the speeds' second difference ≤ √6·0.3/1.8² =
        // 0.23 m/s² along track (v·ω across is nearly noise-free); the
        // acceleration varies by 1.4 m/s² RMS over 66 windows, so σ ≤
        // 0.23/(1.4·√66) rad = 1.2°; the test allows 4σ and needs σ ≤ 2°.
        for (yaw, roll, seed) in [
            (37.0, 0.0, 1),
            (90.0, 90.0, 2),
            (-120.0, 0.0, 3),
            (0.0, 5.0, 4),
        ] {
            let e = urban(Euler::from_deg(roll, 0.0, yaw), 0.3, seed);
            let (est, sd) = (e.yaw_deg.unwrap(), e.sd_deg.unwrap());
            assert!(e.observable, "{e:?}");
            assert!(sd < 2.0 && sd > 0.05 && (e.gain - 1.0).abs() < 0.1, "{e:?}");
            let err = wrap_pi((est - yaw).to_radians()).to_degrees();
            assert!(err.abs() < 4.0 * sd, "mount {yaw}: {e:?}");
        }
    }

    #[test]
    fn slow_robot_turning_on_the_spot_between_legs() {
        // A Husky-like drive: 1 m/s, turns of 0.5 rad/s, fixes 0.5 m: σ ≤
        // 0.23/(0.46·√113) rad = 2.7°; within 4σ, and σ < 5°. (The real
        // Husky's IMU sees more vibration and tilt than acceleration.)
        let e = drive(
            Euler::from_deg(90.0, 0.0, 90.0),
            600.0,
            |t| (1.0 + 0.4 * (0.3 * t).sin(), 0.12 * (0.3 * t).cos()),
            |t| 0.5 * (2.0 * std::f64::consts::PI * t / 30.0).sin(),
            0.5,
            5,
        );
        let (est, sd) = (e.yaw_deg.unwrap(), e.sd_deg.unwrap());
        let err = wrap_pi((est - 90.0).to_radians()).to_degrees();
        assert!(e.observable && err.abs() < 4.0 * sd && sd < 5.0, "{e:?}");
    }

    #[test]
    fn straight_drive_at_constant_speed_is_not_observable() {
        let e = drive(
            Euler::from_deg(0.0, 0.0, 37.0),
            240.0,
            |_| (15.0, 0.0),
            |_| 0.0,
            0.3,
            6,
        );
        assert!(!e.observable, "{e:?}");
        assert!(
            e.reason.contains("too little horizontal acceleration"),
            "{}",
            e.reason
        );
        let d = decide(e, 0.0);
        assert!(
            !d.adopted && d.used_yaw_deg == 0.0 && d.message.contains("not observable"),
            "{d:?}"
        );
    }

    #[test]
    fn an_imu_that_does_not_see_the_acceleration_is_not_observable() {
        // The IMU's specific force 5 times the acceleration (as if
        // vibration or tilt changes dominated it): σ 3.2° (0.8/√200 rad),
        // within the 5° bound, but gain 0.2.
        let mut rng = stream(8, "gain");
        let pairs: Vec<_> = (0..200)
            .map(|_| {
                let a = Vector2::new(normal(&mut rng), normal(&mut rng));
                (rotate(&a, -0.5) * 5.0, a)
            })
            .collect();
        let e = fit(&pairs, &MountSearchOptions::default());
        assert!(!e.observable && (e.gain - 0.2).abs() < 1e-9, "{e:?}");
        assert!(e.reason.contains("does not follow"), "{}", e.reason);
    }

    #[test]
    fn standing_still_gives_no_samples() {
        let e = drive(
            Euler::from_deg(0.0, 0.0, 0.0),
            60.0,
            |_| (0.0, 0.0),
            |_| 0.0,
            0.3,
            7,
        );
        assert!(
            !e.observable && e.yaw_deg.is_none() && e.reason.contains("too few"),
            "{e:?}"
        );
    }

    fn observed(yaw_deg: f64, sd_deg: f64) -> MountYawEstimate {
        MountYawEstimate {
            yaw_deg: Some(yaw_deg),
            sd_deg: Some(sd_deg),
            samples: 50,
            outliers: 0,
            effective_samples: 40.0,
            accel_rms_mps2: 1.0,
            residual_sd_mps2: 0.1,
            gain: 1.0,
            observable: true,
            reason: String::new(),
        }
    }

    #[test]
    fn decision_takes_adopts_warns_and_keeps() {
        // Default 0, far beyond max(3σ, 5°): taken.
        let d = decide(observed(89.0, 1.0), 0.0);
        assert!(
            d.adopted && d.used_yaw_deg == 89.0 && d.message.contains("taken as 89.0°"),
            "{d:?}"
        );
        // Within 5° of the default: kept (a small yaw is the NHC's business).
        let d = decide(observed(4.0, 0.5), 0.0);
        assert!(
            !d.adopted && d.used_yaw_deg == 0.0 && d.message.is_empty(),
            "{d:?}"
        );
        // Beyond 5° but within 3σ: kept.
        let d = decide(observed(8.0, 3.0), 0.0);
        assert!(!d.adopted && !d.disagrees, "{d:?}");
        // The sheet's right yaw: nothing to say; across ±180°.
        let d = decide(observed(-179.0, 1.0), 179.0);
        assert!(
            !d.adopted && !d.disagrees && d.used_yaw_deg == 179.0,
            "{d:?}"
        );
        // The sheet's wrong yaw: kept, warned with the key and both figures.
        let d = decide(observed(90.0, 1.0), -90.0);
        assert!(
            !d.adopted && d.disagrees && d.used_yaw_deg == -90.0,
            "{d:?}"
        );
        assert!(
            d.message.contains("mount_deg[2] is -90.0°") && d.message.contains("gives 90.0°"),
            "{}",
            d.message
        );
    }

    #[test]
    fn procrustes_recovers_an_exact_rotation_and_offset() {
        let pairs: Vec<_> = (0..20)
            .map(|i| {
                let f = Vector2::new((i as f64).sin(), (0.7 * i as f64).cos());
                (f, rotate(&f, 0.5) + Vector2::new(0.3, -0.2))
            })
            .collect();
        let p = procrustes(&pairs).unwrap();
        assert!((p.angle_rad - 0.5).abs() < 1e-12);
        assert!(p.residuals.iter().all(|r| r.norm() < 1e-12));
    }
}
