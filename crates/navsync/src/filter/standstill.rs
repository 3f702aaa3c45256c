//! Standstill: detection from the IMU and the filter's own speed, and the
//! zero-velocity (ZUPT) and zero-angular-rate (ZARU) updates applied while
//! the vehicle stands.
//!
//! A land vehicle at a traffic light has v^n = 0 and ω_nb = 0. Without GNSS
//! updates of heading (heading is unobservable at rest) the INS heading
//! drifts with the gyro bias; ZARU observes that bias directly
//! (ω̄_ib^b = b_g + ω_ie^b at rest), and ZUPT holds velocity and, through
//! it, tilt and the horizontal accelerometer bias (Groves, *Principles of
//! GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed.,
//! §15.3.1 "Zero velocity updates" and "Zero angular rate updates").
//!
//! Detection (Groves §15.3.1; Skog et al., "Zero-velocity detection — an
//! algorithm evaluation", IEEE Trans. Biomed. Eng. 57(11), 2010: a moving-
//! window test on the specific force's spread and the angular rate): over a
//! window, the spread of the specific force vector about its mean, its
//! mean's horizontal part in the navigation frame (the vehicle's
//! acceleration: a constant deceleration has no spread), and the mean
//! compensated angular rate, all under thresholds. A vehicle cruising
//! on a smooth road passes both tests, so a window only counts when the
//! filter's own speed is also below `max_speed_mps`: the IMU test finds the
//! moment of stopping and starting, the speed guard rules out cruising.

use nalgebra::Vector3;
use serde::Serialize;

use super::{Observation, idx};
use crate::earth::omega_ie_n;
use crate::ins::NavState;

/// Settings of standstill detection and its updates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StandstillOptions {
    /// Detection window (s); the updates are applied once per still window.
    pub window_s: f64,
    /// RMS spread of the specific force about its window mean (m/s²) below
    /// which the window may be still (engine idle vibration of a car IMU is
    /// typically 0.01–0.1 m/s²; accelerating from rest at 1 m/s² over a
    /// 1 s window spreads ≈ 0.29 m/s²). The mean horizontal specific force
    /// in the navigation frame (the vehicle's acceleration) must be below
    /// it too.
    pub accel_spread_mps2: f64,
    /// Mean compensated angular rate (rad/s) below which it may be still.
    pub rate_rad_s: f64,
    /// The filter's horizontal speed must be below this (m/s).
    pub max_speed_mps: f64,
    /// σ of the zero velocity (m/s, per NED axis): rocking of a standing
    /// vehicle.
    pub zupt_sd_mps: f64,
    /// Floor of the ZARU σ (rad/s): rotational vibration at idle.
    pub zaru_floor_rad_s: f64,
}

impl Default for StandstillOptions {
    fn default() -> Self {
        StandstillOptions {
            window_s: 1.0,
            accel_spread_mps2: 0.15,
            rate_rad_s: 0.5f64.to_radians(),
            max_speed_mps: 0.5,
            zupt_sd_mps: 0.02,
            zaru_floor_rad_s: 0.005f64.to_radians(),
        }
    }
}

impl StandstillOptions {
    /// Every threshold and σ positive and finite.
    pub fn validate(&self) -> Result<(), String> {
        let fields = [
            ("window_s", self.window_s),
            ("accel_spread_mps2", self.accel_spread_mps2),
            ("rate_rad_s", self.rate_rad_s),
            ("max_speed_mps", self.max_speed_mps),
            ("zupt_sd_mps", self.zupt_sd_mps),
            ("zaru_floor_rad_s", self.zaru_floor_rad_s),
        ];
        for (name, v) in fields {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("standstill {name} must be positive, got {v}"));
            }
        }
        Ok(())
    }
}

/// One window's verdict.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct StillWindow {
    /// Mean raw angular rate over the window (compensated rate plus the
    /// gyro bias estimate in force at each sample), rad/s.
    pub(crate) mean_raw_rate: Vector3<f64>,
    /// σ of that mean from the samples' spread (rad/s).
    pub(crate) mean_rate_sd: Vector3<f64>,
}

/// Streaming detector: push every compensated sample; at the end of each
/// window it says whether the window was still.
#[derive(Clone, Debug, Default)]
pub(crate) struct StandstillDetector {
    opts: StandstillOptions,
    n: usize,
    dt_s: f64,
    f_sum: Vector3<f64>,
    f_sq: Vector3<f64>,
    w_sum: Vector3<f64>,
    raw_sum: Vector3<f64>,
    raw_sq: Vector3<f64>,
}

impl StandstillDetector {
    pub(crate) fn new(opts: StandstillOptions) -> Self {
        StandstillDetector {
            opts,
            ..Default::default()
        }
    }

    pub(crate) fn options(&self) -> &StandstillOptions {
        &self.opts
    }

    /// Forgets the current window (after a data gap).
    pub(crate) fn reset(&mut self) {
        *self = StandstillDetector::new(self.opts);
    }

    /// Adds a sample: compensated specific force resolved in the navigation
    /// frame (NED), compensated body angular rate, the gyro bias estimate
    /// that compensated it, and its length. Returns the
    /// window's verdict when this sample completes a window: `Some(None)`
    /// moving, `Some(Some(w))` still.
    pub(crate) fn push(
        &mut self,
        f_n: &Vector3<f64>,
        w_b: &Vector3<f64>,
        gyro_bias: &Vector3<f64>,
        dt_s: f64,
        speed_mps: f64,
    ) -> Option<Option<StillWindow>> {
        let raw = w_b + gyro_bias;
        self.n += 1;
        self.dt_s += dt_s;
        self.f_sum += f_n;
        self.f_sq += f_n.component_mul(f_n);
        self.w_sum += w_b;
        self.raw_sum += raw;
        self.raw_sq += raw.component_mul(&raw);
        if self.dt_s + 1e-9 < self.opts.window_s {
            return None;
        }
        let n = self.n as f64;
        let var = |sum: &Vector3<f64>, sq: &Vector3<f64>| {
            (sq / n - (sum / n).component_mul(&(sum / n))).map(|v| v.max(0.0))
        };
        let spread = var(&self.f_sum, &self.f_sq).sum().sqrt();
        let mean_w = (self.w_sum / n).norm();
        let accel_h = (self.f_sum.x / n).hypot(self.f_sum.y / n);
        let still = n >= 3.0
            && spread < self.opts.accel_spread_mps2
            && accel_h < self.opts.accel_spread_mps2
            && mean_w < self.opts.rate_rad_s
            && speed_mps < self.opts.max_speed_mps;
        let out = still.then(|| StillWindow {
            mean_raw_rate: self.raw_sum / n,
            mean_rate_sd: (var(&self.raw_sum, &self.raw_sq) / (n - 1.0)).map(f64::sqrt),
        });
        self.reset();
        Some(out)
    }
}

/// Zero velocity: the observation v^n = 0 (z = v̂^n − 0 = δv, with this
/// crate's convention δx = x̂ − x).
pub fn zupt(nav: &NavState, sd_mps: f64, n: usize) -> Observation {
    let mut obs = Observation::new("zupt", 3, n);
    for k in 0..3 {
        obs.z[k] = nav.vel[k];
        obs.h.set(k, idx::VEL + k, 1.0);
        obs.r.set(k, k, sd_mps * sd_mps);
    }
    obs
}

/// Zero angular rate: at rest the gyros measure b_g + ω_ie^b (scale-factor
/// error on the earth rate, ≤ 10⁻⁶ rad/s, neglected), so with the window's
/// mean raw rate ω̄, z = (b̂_g + ω_ie^b) − ω̄ = δb_g − noise.
pub(crate) fn zaru(
    nav: &NavState,
    gyro_bias: &Vector3<f64>,
    window: &StillWindow,
    floor_rad_s: f64,
    n: usize,
) -> Observation {
    let (s, c) = nav.pos.lat_rad.sin_cos();
    let w_ie_b = nav.c_nb().transpose() * omega_ie_n(s, c);
    let mut obs = Observation::new("zaru", 3, n);
    for k in 0..3 {
        obs.z[k] = gyro_bias[k] + w_ie_b[k] - window.mean_raw_rate[k];
        obs.h.set(k, idx::BG + k, 1.0);
        let sd = window.mean_rate_sd[k].hypot(floor_rad_s);
        obs.r.set(k, k, sd * sd);
    }
    obs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push_window(
        d: &mut StandstillDetector,
        f: impl Fn(usize) -> Vector3<f64>,
        w: Vector3<f64>,
        speed: f64,
    ) -> Option<Option<StillWindow>> {
        let mut out = None;
        for k in 0..200 {
            if let Some(v) = d.push(&f(k), &w, &Vector3::new(0.001, 0.0, 0.0), 0.005, speed) {
                out = Some(v);
            }
        }
        out
    }

    #[test]
    fn detects_rest_and_refuses_motion() {
        let g = Vector3::new(0.0, 0.0, -9.8);
        let idle = |k: usize| g + Vector3::new(0.03 * ((k as f64) * 1.3).sin(), 0.0, 0.02);
        let mut d = StandstillDetector::new(StandstillOptions::default());
        // Idling: still; the raw mean adds the bias back.
        let w = push_window(&mut d, idle, Vector3::zeros(), 0.0).expect("window");
        let w = w.expect("still");
        assert!((w.mean_raw_rate.x - 0.001).abs() < 1e-12);
        // Pulling away at 1 m/s² from the window's middle: moving.
        let pull = |k: usize| g + Vector3::new(if k > 100 { 1.0 } else { 0.0 }, 0.0, 0.0);
        assert_eq!(push_window(&mut d, pull, Vector3::zeros(), 0.2), Some(None));
        // Braking at a constant 0.8 m/s² (no spread) at 0.4 m/s: moving.
        let brake = |_: usize| g + Vector3::new(-0.8, 0.0, 0.0);
        assert_eq!(
            push_window(&mut d, brake, Vector3::zeros(), 0.4),
            Some(None)
        );
        // Turning on the spot at 2°/s: moving.
        let turn = Vector3::new(0.0, 0.0, 2f64.to_radians());
        assert_eq!(push_window(&mut d, idle, turn, 0.0), Some(None));
        // Cruising smoothly at 20 m/s passes the IMU tests; the speed
        // guard refuses it.
        assert_eq!(
            push_window(&mut d, idle, Vector3::zeros(), 20.0),
            Some(None)
        );
    }
}
