//! Analytic motions with exact IMU increments, for tests of the core.
//!
//! A vehicle at rest on the ellipsoid, level, turning about the down axis
//! at a constant rate r: C_b^n(t) = R_z(ψ0 + r t), so ω_ib^b(t) =
//! C_n^b(t) ω_ie^n + [0, 0, r] and f^b = −C_n^b g^n = [0, 0, −g]. The
//! increments over an interval have closed forms (integrals of sin/cos).

use nalgebra::Vector3;

use crate::attitude::Euler;
use crate::earth::{Geodetic, gravity, omega_ie_n};
use crate::ins::{ImuSample, NavState};
use crate::time::GpsTime;

/// A level vehicle at rest turning about the down axis at `rate_rad_s`.
#[derive(Clone, Copy, Debug)]
pub struct TurningAtRest {
    pub pos: Geodetic,
    pub yaw0_rad: f64,
    pub rate_rad_s: f64,
    pub t0: GpsTime,
}

impl TurningAtRest {
    /// The true state at `t`.
    pub fn state(&self, t: GpsTime) -> NavState {
        let yaw = self.yaw0_rad + self.rate_rad_s * t.seconds_since(self.t0);
        NavState::new(t, self.pos, Vector3::zeros(), &Euler::new(0.0, 0.0, yaw))
    }

    /// Exact increments over (t_a, t_b].
    pub fn sample(&self, ta: GpsTime, tb: GpsTime) -> ImuSample {
        let (s, c) = self.pos.lat_rad.sin_cos();
        let w = omega_ie_n(s, c);
        let g = gravity(s, self.pos.h_m);
        let dt = tb.seconds_since(ta);
        let y0 = self.yaw0_rad + self.rate_rad_s * ta.seconds_since(self.t0);
        let y1 = y0 + self.rate_rad_s * dt;
        let r = self.rate_rad_s;
        // ∫ R_z(ψ)ᵀ [w_n, 0, w_d] dt = [w_n ∫cosψ, −w_n ∫sinψ, w_d dt]
        let (int_cos, int_sin) = if r.abs() > 1e-12 {
            ((y1.sin() - y0.sin()) / r, (y0.cos() - y1.cos()) / r)
        } else {
            (y0.cos() * dt, y0.sin() * dt)
        };
        ImuSample {
            time: tb,
            dtheta: Vector3::new(w.x * int_cos, -w.x * int_sin, w.z * dt + r * dt),
            dvel: Vector3::new(0.0, 0.0, -g * dt),
            odo_speed: None,
        }
    }
}
