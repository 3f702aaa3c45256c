//! Heading observation of a dual-antenna baseline.
//!
//! The baseline from the primary to the secondary antenna is fixed in the
//! body: u^b = (cos α, sin α, 0) at the mounting yaw α. The receiver
//! measures the azimuth of b^n = C_b^n u^b, az = atan2(b_E, b_N) (u-blox
//! NAV-RELPOSNED relPosHeading; Groves, *Principles of GNSS, Inertial, and
//! Multisensor Integrated Navigation Systems*, 2nd ed., §10.2.5 attitude
//! from multiple antennas, and §16.3.2 heading measurements in
//! integration). With this crate's attitude error Ĉ = (I − φ×)C, the
//! predicted baseline is b̂ = b + b×φ, so
//! δaz = (b_N δb_E − b_E δb_N)/h², h² = b_N² + b_E², which gives
//! H_φ = (b_N b_D, b_E b_D, −h²)/h² (for a level baseline, −1 on φ_D).
//! The innovation is predicted minus measured, wrapped to ±π.

use nalgebra::Vector3;

use super::{Observation, idx};
use crate::ins::NavState;

/// The baseline's azimuth at the state (rad) and its attitude row.
pub fn baseline_azimuth(nav: &NavState, alpha_rad: f64) -> (f64, Vector3<f64>) {
    let b = nav.c_nb() * Vector3::new(alpha_rad.cos(), alpha_rad.sin(), 0.0);
    let h2 = (b.x * b.x + b.y * b.y).max(1e-12);
    (
        b.y.atan2(b.x),
        Vector3::new(b.x * b.z / h2, b.y * b.z / h2, -1.0),
    )
}

/// A heading observation: `measured_rad` with σ `sd_rad`, for a baseline
/// at yaw `alpha_rad` in the body; `back_rad` is the azimuth's change from
/// the measurement's time to the state's (subtracted from the prediction).
pub fn baseline_heading(
    nav: &NavState,
    alpha_rad: f64,
    measured_rad: f64,
    sd_rad: f64,
    back_rad: f64,
    n: usize,
) -> Observation {
    let (az, h) = baseline_azimuth(nav, alpha_rad);
    let mut obs = Observation::new("heading", 1, n);
    obs.z[0] = crate::attitude::wrap_pi(az - back_rad - measured_rad);
    obs.r.set(0, 0, sd_rad * sd_rad);
    for j in 0..3 {
        obs.h.set(0, idx::ATT + j, h[j]);
    }
    obs
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::Euler;
    use crate::earth::Geodetic;
    use crate::time::GpsTime;

    /// The row predicts the azimuth change of a small attitude error
    /// applied as the filter applies it (C = exp(φ×)Ĉ), at a tilted
    /// attitude and an oblique baseline.
    #[test]
    fn heading_row_matches_a_perturbed_attitude() {
        let att = Euler::new(8f64.to_radians(), -6f64.to_radians(), 130f64.to_radians());
        let nav = NavState::new(
            GpsTime::from_week_sow(2300, 0.0),
            Geodetic::from_deg(30.0, 114.0, 20.0),
            Vector3::zeros(),
            &att,
        );
        let alpha = 35f64.to_radians();
        let (az_hat, h) = baseline_azimuth(&nav, alpha);
        let phi = Vector3::new(2e-4, -3e-4, 5e-4);
        // The true state: C = exp(φ×) Ĉ (filter::feedback).
        let mut truth = nav;
        truth.q_nb = crate::attitude::rotvec_to_quat(&phi) * truth.q_nb;
        let (az, _) = baseline_azimuth(&truth, alpha);
        let predicted = h.dot(&phi);
        let actual = crate::attitude::wrap_pi(az_hat - az);
        assert!(
            (predicted - actual).abs() < 1e-7,
            "H·φ {predicted} vs aẑ − az {actual}"
        );
        // Level: the azimuth is yaw + α.
        let level = NavState::new(
            nav.time,
            nav.pos,
            Vector3::zeros(),
            &Euler::new(0.0, 0.0, 130f64.to_radians()),
        );
        let (az0, _) = baseline_azimuth(&level, alpha);
        assert!((az0 - crate::attitude::wrap_pi(165f64.to_radians())).abs() < 1e-12);
        // The alignment's inversion gives the yaw back at the tilt.
        let yaw = crate::align::yaw_from_baseline(az_hat, att.roll_rad, att.pitch_rad, alpha);
        assert!((yaw - att.yaw_rad).abs() < 1e-12, "{yaw}");
    }
}
