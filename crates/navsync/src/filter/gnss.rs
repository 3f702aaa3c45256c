//! GNSS position and velocity observations of the antenna, with lever arm.
//!
//! KF-GINS algorithm doc §3.5 (position: r_G = r_I + C_b^n ℓ, H = [I, 0,
//! (C_b^n ℓ)×, 0…]) and §3.6 (velocity: v_G = v_I + C_b^n (ω_nb^b×) ℓ), with
//! this crate's sign convention δx = x̂ − x. Innovations are predicted minus
//! measured, in NED metres (m/s).

use nalgebra::Vector3;

use super::{Observation, idx};
use crate::attitude::skew;
use crate::earth::LocalEarth;
use crate::ins::NavState;

// The fix itself is a base-layer type (io reads and writes it).
pub use crate::types::GnssFix;

/// Antenna position observation for a state with `n` error states.
pub fn position(nav: &NavState, fix: &GnssFix, lever_b: &Vector3<f64>, n: usize) -> Observation {
    let le = LocalEarth::new(&nav.pos, &nav.vel);
    let l_n = nav.c_nb() * lever_b;
    let z = le.geodetic_delta_to_ned(
        nav.pos.lat_rad - fix.pos.lat_rad,
        nav.pos.lon_rad - fix.pos.lon_rad,
        nav.pos.h_m - fix.pos.h_m,
    ) + l_n;
    let mut obs = Observation::new("gnss-position", 3, n);
    obs.z.copy_from_slice(z.as_slice());
    for i in 0..3 {
        obs.h.set(i, idx::POS + i, 1.0);
        obs.r.set(i, i, fix.pos_sd[i] * fix.pos_sd[i]);
    }
    obs.h.set_block3(0, idx::ATT, &skew(&l_n));
    obs
}

/// Antenna velocity observation; `w_ib_b` is the compensated body rate
/// (rad/s) at the fix time. Returns `None` when the fix has no velocity.
pub fn velocity(
    nav: &NavState,
    fix: &GnssFix,
    lever_b: &Vector3<f64>,
    w_ib_b: &Vector3<f64>,
    n: usize,
) -> Option<Observation> {
    let (vel, sd) = (fix.vel?, fix.vel_sd?);
    let le = LocalEarth::new(&nav.pos, &nav.vel);
    let c = nav.c_nb();
    let w_in = le.w_in();
    let w_nb = w_ib_b - c.transpose() * w_in;
    let predicted = nav.vel + c * w_nb.cross(lever_b);
    let z = predicted - vel;
    let mut obs = Observation::new("gnss-velocity", 3, n);
    obs.z.copy_from_slice(z.as_slice());
    let l_n = c * lever_b;
    let h_att = -skew(&w_in) * skew(&l_n) + skew(&(c * w_ib_b.cross(lever_b)));
    let h_bg = c * skew(lever_b);
    let h_sg = h_bg * nalgebra::Matrix3::from_diagonal(w_ib_b);
    for i in 0..3 {
        obs.h.set(i, idx::VEL + i, 1.0);
        obs.r.set(i, i, sd[i] * sd[i]);
    }
    obs.h.set_block3(0, idx::ATT, &h_att);
    obs.h.set_block3(0, idx::BG, &h_bg);
    obs.h.set_block3(0, idx::SG, &h_sg);
    Some(obs)
}
