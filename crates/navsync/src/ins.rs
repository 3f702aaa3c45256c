//! Strapdown inertial navigation in the local-level NED frame on increments
//! (Δθ, Δv), with two-sample coning and sculling corrections.
//!
//! Algorithm: Savage, *Strapdown Analytics* (2000) §7 (velocity), §4
//! (position), §3 (attitude); written down for this two-sample, linear-rate
//! form in the KF-GINS algorithm documentation (i2Nav, `kf-gins-algorithm-
//! docs.tex` §2: velocity eqs for Δv_f^n, Δv_f^b, Δv_g/cor; position; the
//! attitude quaternion update with φ_k = Δθ_k + Δθ_{k−1}×Δθ_k/12).
//!
//! Each step uses its own interval `dt`; nothing here assumes a fixed rate.
#![warn(missing_docs)]

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::attitude::rotvec_to_quat;
use crate::earth::{Geodetic, LocalEarth};

// The IMU record, the navigation state and the IMU error parameters are
// base-layer types (io and interp use them); the compensation of the
// errors and the mechanization are here.
pub use crate::types::{ImuErrors, ImuSample, NavState};

/// M v for the off-diagonal matrix M of `m` (see [`ImuErrors`]).
#[inline]
pub(crate) fn misalign_times(m: &[f64; 6], v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        m[0] * v.y + m[1] * v.z,
        m[2] * v.x + m[3] * v.z,
        m[4] * v.x + m[5] * v.y,
    )
}

impl ImuErrors {
    /// Removes the errors from raw increments over `dt`:
    /// Δθ = (I + diag(s_g))⁻¹ (Δθ̃ − b_g Δt) (KF-GINS algorithm doc eq for
    /// IMU error compensation); with misalignments, to first order in M:
    /// Δθ = D⁻¹ (u − M D⁻¹ u), u = Δθ̃ − b_g Δt, D = I + diag(s_g).
    #[inline]
    pub(crate) fn compensate(
        &self,
        dtheta: &Vector3<f64>,
        dvel: &Vector3<f64>,
        dt: f64,
    ) -> Increment {
        let d_g = self.gyro_scale.add_scalar(1.0);
        let d_a = self.accel_scale.add_scalar(1.0);
        let mut th = (dtheta - self.gyro_bias * dt).component_div(&d_g);
        let mut dv = (dvel - self.accel_bias * dt).component_div(&d_a);
        if self.gyro_misalign.iter().any(|&m| m != 0.0) {
            th -= misalign_times(&self.gyro_misalign, &th).component_div(&d_g);
        }
        if self.accel_misalign.iter().any(|&m| m != 0.0) {
            dv -= misalign_times(&self.accel_misalign, &dv).component_div(&d_a);
        }
        Increment {
            dtheta: th,
            dvel: dv,
            dt,
        }
    }
}

/// Compensated increments over an interval of `dt` seconds.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Increment {
    /// Angle increment Δθ (rad), body frame, bias, scale factor and
    /// misalignment removed.
    pub dtheta: Vector3<f64>,
    /// Specific-force velocity increment Δv (m/s), body frame, bias, scale
    /// factor and misalignment removed.
    pub dvel: Vector3<f64>,
    /// Length of the interval (s).
    pub dt: f64,
}

impl Increment {}

/// What one mechanization step hands to the error model: the quantities it
/// already computed, so that the filter does not recompute them.
#[derive(Copy, Clone, Debug)]
pub struct StepInfo {
    pub(crate) dt: f64,
    /// C_b^n at the start of the step.
    pub(crate) c_nb: Matrix3<f64>,
    /// Specific-force velocity increment in NED, Δv_f^n (m/s).
    pub(crate) dv_f_n: Vector3<f64>,
    /// Total velocity change over the step (specific force, gravity,
    /// Coriolis): the kinematic acceleration times Δt (m/s).
    pub(crate) dv_n: Vector3<f64>,
    /// Compensated body increments of the step.
    pub(crate) inc: Increment,
}

/// The strapdown integrator. Holds the previous increment (for the
/// two-sample coning and sculling terms) and the previous velocity change
/// (to extrapolate mid-interval velocity).
#[derive(Clone, Debug, Default)]
pub struct Mechanization {
    prev: Option<Increment>,
    prev_dv_total: Option<(Vector3<f64>, f64)>,
}

impl Mechanization {
    /// A mechanization with no previous sample.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the increment that precedes the first step (for the coning and
    /// sculling terms of the first step).
    pub fn set_previous(&mut self, inc: Increment) {
        self.prev = Some(inc);
    }

    /// Forgets the history (after a data gap the two-sample terms would
    /// couple unrelated intervals).
    pub(crate) fn reset_history(&mut self) {
        self.prev = None;
        self.prev_dv_total = None;
    }

    /// Advances `nav` over one compensated increment.
    pub fn step(&mut self, nav: &mut NavState, inc: &Increment) -> StepInfo {
        let dt = inc.dt;
        let (dth_prev, dv_prev) = match &self.prev {
            Some(p) => (p.dtheta, p.dvel),
            None => (Vector3::zeros(), Vector3::zeros()),
        };

        // Mid-interval estimates for the gravity/Coriolis and n-frame rotation
        // terms: velocity extrapolated from the previous step's change,
        // position advanced half a step (KF-GINS doc, eq for v_{k-1/2}, p_{k-1/2}).
        let v0 = nav.vel;
        let v_mid_est = match self.prev_dv_total {
            Some((dv, dt_prev)) if dt_prev > 0.0 => v0 + dv * (0.5 * dt / dt_prev),
            _ => v0,
        };
        let le0 = LocalEarth::new(&nav.pos, &v0);
        let half = le0.ned_to_geodetic_delta(&(v_mid_est * (0.5 * dt)));
        let pos_mid_est = Geodetic::new(
            nav.pos.lat_rad + half.x,
            nav.pos.lon_rad + half.y,
            nav.pos.h_m + half.z,
        );
        let le_mid = LocalEarth::new(&pos_mid_est, &v_mid_est);

        // Velocity update (KF-GINS doc, velocity update eqs).
        let c_nb = nav.c_nb();
        let zeta = le_mid.w_in() * dt;
        let dv_rot = 0.5 * inc.dtheta.cross(&inc.dvel);
        let dv_scul = (dth_prev.cross(&inc.dvel) + dv_prev.cross(&inc.dtheta)) / 12.0;
        let dv_f_b = inc.dvel + dv_rot + dv_scul;
        let c_dv = c_nb * dv_f_b;
        let dv_f_n = c_dv - 0.5 * zeta.cross(&c_dv);
        let g_n = Vector3::new(0.0, 0.0, le_mid.g);
        let coriolis = (2.0 * le_mid.w_ie + le_mid.w_en).cross(&v_mid_est);
        let dv_total = dv_f_n + (g_n - coriolis) * dt;
        let v1 = v0 + dv_total;

        // Position update with the trapezoidal mid-interval velocity.
        let v_mid = 0.5 * (v0 + v1);
        let h1 = nav.pos.h_m - v_mid.z * dt;
        let h_mid = 0.5 * (nav.pos.h_m + h1);
        let lat_mid = nav.pos.lat_rad + 0.5 * v_mid.x * dt / le0.rm_h;
        let (s_mid, c_mid) = lat_mid.sin_cos();
        let (rm, rn) = crate::earth::radii(s_mid);
        let lat1 = nav.pos.lat_rad + v_mid.x * dt / (rm + h_mid);
        let lon1 = nav.pos.lon_rad + v_mid.y * dt / ((rn + h_mid) * c_mid);

        // Attitude update (KF-GINS doc, attitude quaternion update), with
        // the n-frame rotation evaluated at the refined mid-interval point.
        let pos_mid = Geodetic::new(lat_mid, 0.5 * (nav.pos.lon_rad + lon1), h_mid);
        let le_mid2 = LocalEarth::new(&pos_mid, &v_mid);
        let zeta2 = le_mid2.w_in() * dt;
        let phi_b = inc.dtheta + dth_prev.cross(&inc.dtheta) / 12.0;
        let q1 = rotvec_to_quat(&(-zeta2)) * nav.q_nb * rotvec_to_quat(&phi_b);

        nav.pos = Geodetic::new(lat1, lon1, h1);
        nav.vel = v1;
        nav.q_nb = UnitQuaternion::new_normalize(q1.into_inner());

        self.prev = Some(*inc);
        self.prev_dv_total = Some((dv_total, dt));
        StepInfo {
            dt,
            c_nb,
            dv_f_n,
            dv_n: dv_total,
            inc: *inc,
        }
    }
}

/// ω_nb^b = ω_ib^b − C_n^b ω_in^n, the body rate relative to NED, from a
/// compensated gyro rate (for lever-arm velocity terms).
pub(crate) fn omega_nb_b(nav: &NavState, w_ib_b: &Vector3<f64>) -> Vector3<f64> {
    let le = LocalEarth::new(&nav.pos, &nav.vel);
    w_ib_b - nav.q_nb.inverse_transform_vector(&le.w_in())
}
