//! An INS run free of updates, and the drift it may make (issue 33: the
//! stale-repeat and ramp's-end tests, `rollback.rs`).

use super::*;

/// An INS running free from a repeat run's first write, on the IMU
/// samples alone with the biases and scale factors estimated then: where
/// the antenna went if the repeats were stale (see `judge_run_end`).
#[derive(Clone)]
pub(in crate::fusion) struct FreeIns {
    nav: NavState,
    imu: ImuErrors,
    mech: Mechanization,
}

impl FreeIns {
    /// The INS as the filter has it now, to run on free of any update.
    pub(in crate::fusion) fn from_core(core: &Core) -> Self {
        FreeIns {
            nav: core.nav,
            imu: core.imu,
            mech: core.mech.clone(),
        }
    }

    /// Its antenna's offset from `pos` (m, NED), antenna lever `lever_b`.
    pub(in crate::fusion) fn antenna_from(
        &self,
        pos: &Geodetic,
        lever_b: &Vector3<f64>,
    ) -> Vector3<f64> {
        let le = LocalEarth::new(pos, &self.nav.vel);
        le.geodetic_delta_to_ned(
            self.nav.pos.lat_rad - pos.lat_rad,
            self.nav.pos.lon_rad - pos.lon_rad,
            self.nav.pos.h_m - pos.h_m,
        ) + self.nav.q_nb * lever_b
    }

    /// Advances over one raw increment (`Core::integrate`).
    pub(in crate::fusion) fn step(&mut self, dtheta: &Vector3<f64>, dvel: &Vector3<f64>, dt: f64) {
        let inc = self.imu.compensate(dtheta, dvel, dt);
        self.mech.step(&mut self.nav, &inc);
    }
}

/// The variance (summed over the axes, m²) of the error in the distance
/// an INS running free from now would travel in t s, t² (c₂ + c₃ t +
/// c₄ t²), as [c₂, c₃, c₄]: to second order, δp(t) − δp(0) = δv t + (f×φ − C δb_a) t²/2 (the velocity error
/// equation of `filter::model`; Groves, *Principles of GNSS, Inertial, and
/// Multisensor Integrated Navigation Systems*, 2nd ed., §14.2), so with
/// A(t) = A₁ t + A₂ t²/2 the variance is tr(A P Aᵀ) over the
/// filter's covariance with its correlations (at a standstill tilt and
/// accelerometer bias cancel: their sum is well known while each alone
/// is not). The specific force is taken as gravity's reaction.
pub(in crate::fusion) fn free_drift_variance(core: &Core) -> [f64; 3] {
    use idx::{ATT, BA, VEL};
    if core.filter.n() < BA + 3 {
        return [0.0; 3];
    }
    let p = core.filter.covariance();
    let g = crate::earth::gravity(core.nav.pos.lat_rad.sin(), core.nav.pos.h_m);
    let attitude_to_accel = crate::attitude::skew(&Vector3::new(0.0, 0.0, -g));
    let bias_to_accel = -core.nav.q_nb.to_rotation_matrix().into_inner();
    // P A₂ᵀ restricted to the rows of `row`: Σ over (att, ba) of P_row,j B_jᵀ.
    let p_a2 = |row: usize| {
        p.block3(row, ATT) * attitude_to_accel.transpose()
            + p.block3(row, BA) * bias_to_accel.transpose()
    };
    let a2_p_a2 = attitude_to_accel * p_a2(ATT) + bias_to_accel * p_a2(BA);
    [
        p.block3(VEL, VEL).trace(),
        p_a2(VEL).trace(),
        a2_p_a2.trace() / 4.0,
    ]
}

/// The σ (m) of the displacement error of an INS run free for `dt_s`:
/// √(λ t² (c₂ + c₃ t + c₄ t²)), the coefficients from
/// [`free_drift_variance`] at its start, λ ≥ 1 the INS overconfidence.
pub(in crate::fusion) fn free_drift_sd_m(coeffs: [f64; 3], lambda: f64, dt_s: f64) -> f64 {
    let t = dt_s.max(0.0);
    let [c2, c3, c4] = coeffs;
    let var = t * t * (c2 + t * (c3 + t * c4));
    (lambda * var.max(0.0)).sqrt()
}

/// 3 σ (m) of the difference of two fixes of stated σ `pos_sd` (N, E, D):
/// what a new position must leave an old one by to be another.
pub(in crate::fusion) fn fix_difference_3sd_m(pos_sd: &Vector3<f64>) -> f64 {
    3.0 * (2.0 * pos_sd.norm_squared()).sqrt()
}
