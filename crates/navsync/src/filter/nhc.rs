//! Land-vehicle velocity constraints in the vehicle frame: the
//! non-holonomic constraint (zero lateral and vertical velocity) and an
//! optional odometer forward speed.
//!
//! KF-GINS algorithm doc §3.7 (ODO/NHC): v^v = C_b^v (C_n^b v^n + ω_nb^b × ℓ),
//! linearised with this crate's sign convention δx = x̂ − x.

use nalgebra::{Matrix3, Vector3};

use super::{Observation, idx};
use crate::attitude::{Euler, euler_to_dcm, skew};
use crate::earth::LocalEarth;
use crate::ins::NavState;

/// How the IMU sits in the vehicle and how tightly the constraint holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct VehicleConstraint {
    /// C_b^v from the IMU's mounting angles relative to the vehicle frame
    /// (forward-right-down): roll, pitch, yaw of the IMU in the vehicle.
    pub(crate) c_bv: Matrix3<f64>,
    /// Lever arm from the IMU to the constraint point (e.g. the rear-axle
    /// centre), in the body frame (m).
    pub(crate) lever_b: Vector3<f64>,
    /// Standard deviation of the lateral and vertical zero velocity (m/s).
    pub(crate) nhc_sd: f64,
}

impl VehicleConstraint {
    /// From mounting angles and a lever arm.
    pub fn new(mount: &Euler, lever_b: Vector3<f64>, nhc_sd: f64) -> Self {
        VehicleConstraint {
            c_bv: euler_to_dcm(mount),
            lever_b,
            nhc_sd,
        }
    }

    /// The velocity of the constraint point in the vehicle frame and the
    /// rows of its Jacobian (3 × 3 blocks for δv, φ, δb_g, δs_g).
    fn velocity_and_blocks(
        &self,
        nav: &NavState,
        w_ib_b: &Vector3<f64>,
    ) -> (Vector3<f64>, [Matrix3<f64>; 4]) {
        let le = LocalEarth::new(&nav.pos, &nav.vel);
        let c = nav.c_nb();
        let ct = c.transpose();
        let w_in = le.w_in();
        let w_nb = w_ib_b - ct * w_in;
        let v_v = self.c_bv * (ct * nav.vel + w_nb.cross(&self.lever_b));
        let sl = skew(&self.lever_b);
        let h_v = self.c_bv * ct;
        let h_att = -self.c_bv * ct * skew(&nav.vel) - self.c_bv * sl * ct * skew(&w_in);
        let h_bg = self.c_bv * sl;
        let h_sg = h_bg * Matrix3::from_diagonal(w_ib_b);
        (v_v, [h_v, h_att, h_bg, h_sg])
    }

    /// The non-holonomic constraint: lateral and vertical velocity zero.
    pub fn nhc(&self, nav: &NavState, w_ib_b: &Vector3<f64>, n: usize) -> Observation {
        let (v_v, blocks) = self.velocity_and_blocks(nav, w_ib_b);
        let mut obs = Observation::new("nhc", 2, n);
        for (row, axis) in [1usize, 2].into_iter().enumerate() {
            obs.z[row] = v_v[axis];
            obs.r.set(row, row, self.nhc_sd * self.nhc_sd);
            for (b, start) in blocks.iter().zip([idx::VEL, idx::ATT, idx::BG, idx::SG]) {
                for j in 0..3 {
                    obs.h.set(row, start + j, b[(axis, j)]);
                }
            }
        }
        obs
    }

    /// Odometer forward speed `speed_mps` with standard deviation `sd`;
    /// `scale_index` is the odometer scale-factor state, if estimated
    /// (measured = (1 + s) · true).
    pub fn odometer(
        &self,
        nav: &NavState,
        w_ib_b: &Vector3<f64>,
        speed_mps: f64,
        sd: f64,
        odo_scale: Option<(usize, f64)>,
        n: usize,
    ) -> Observation {
        let (v_v, blocks) = self.velocity_and_blocks(nav, w_ib_b);
        let mut obs = Observation::new("odometer", 1, n);
        let (scale_state, scale) = match odo_scale {
            Some((i, s)) => (Some(i), s),
            None => (None, 0.0),
        };
        // Predicted odometer reading (1+s)·v_x minus measured.
        obs.z[0] = (1.0 + scale) * v_v.x - speed_mps;
        obs.r.set(0, 0, sd * sd);
        for (b, start) in blocks.iter().zip([idx::VEL, idx::ATT, idx::BG, idx::SG]) {
            for j in 0..3 {
                obs.h.set(0, start + j, (1.0 + scale) * b[(0, j)]);
            }
        }
        if let Some(i) = scale_state {
            obs.h.set(0, i, v_v.x);
        }
        obs
    }
}
