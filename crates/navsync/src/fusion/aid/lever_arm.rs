//! The GNSS antenna lever arm ℓ (body frame, FRD, m) as three filter
//! states: random constants, observed through the GNSS rows only (like τ,
//! a state this file controls, not an [`super::AidSource`]).
//!
//! The antenna is at r_G = r_I + C_bⁿ ℓ and moves at v_G = v_I + C_bⁿ
//! (ω_nbᵇ×) ℓ (KF-GINS algorithm doc §3.5–3.6; Groves, *Principles of GNSS,
//! Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed.,
//! §14.2.7, where the lever arm is estimated as states of this kind). With
//! this crate's convention δℓ = ℓ̂ − ℓ and innovations predicted minus
//! measured, the columns are ∂z_r/∂δℓ = C_bⁿ (NED m per m) and ∂z_v/∂δℓ =
//! C_bⁿ (ω_nbᵇ×). Observability is the motion's: C_bⁿ δℓ is a constant
//! NED offset, indistinguishable from a position error, until the heading
//! changes (the horizontal components) or the vehicle rolls and pitches
//! (the vertical one, hardly ever on a road), so the states' σ stays near
//! its initial value on a straight road: the covariance says what the
//! drive could not tell.

use super::*;

/// Process noise of each lever-arm state (m²/s): a random constant, with
/// a floor that keeps P well conditioned (1 mm over an hour).
pub(in crate::fusion) const LEVER_ARM_PSD: f64 = 3e-10;

/// The estimated lever arm and its σ.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct LeverArmState {
    /// Estimated lever arm, IMU to antenna, [forward, right, down] (m).
    pub lever_m: [f64; 3],
    /// σ of each component (m).
    pub sd_m: [f64; 3],
    /// The initial σ (m): a component whose σ stays near it was not
    /// observed by the drive.
    pub initial_sd_m: f64,
}

impl Core {
    /// Adds the lever arm's columns to a GNSS position observation.
    pub(in crate::fusion) fn lever_column_position(&self, obs: &mut Observation) {
        if let Some(i) = self.lever_index {
            obs.h.set_block3(0, i, &self.nav.c_nb());
        }
    }

    /// Adds the lever arm's columns to a GNSS velocity observation:
    /// C_bⁿ (ω_nbᵇ×), with ω_nbᵇ from the compensated body rate.
    pub(in crate::fusion) fn lever_column_velocity(&self, obs: &mut Observation) {
        if let Some(i) = self.lever_index {
            let w_nb = crate::ins::omega_nb_b(&self.nav, &self.last_w_ib);
            let h = self.nav.c_nb() * crate::attitude::skew(&w_nb);
            obs.h.set_block3(0, i, &h);
        }
    }

    /// Feeds an update's lever-arm correction back (ℓ̂ ← ℓ̂ − δℓ): later
    /// fixes use the corrected lever arm.
    pub(in crate::fusion) fn lever_feedback(&mut self, dx: &[f64]) {
        if let Some(i) = self.lever_index {
            for k in 0..3 {
                self.lever_b[k] -= dx[i + k];
            }
        }
    }

    /// The estimate, when the states are on.
    pub(in crate::fusion) fn lever_arm_state(&self) -> Option<LeverArmState> {
        let i = self.lever_index?;
        Some(LeverArmState {
            lever_m: self.lever_b.into(),
            sd_m: [0, 1, 2].map(|k| self.filter.sd(i + k)),
            initial_sd_m: self.cfg.lever_arm_sd_m.unwrap_or(0.0),
        })
    }
}

/// A component counts as observed when its σ fell below this fraction of
/// the initial σ: the drive carried information on it.
pub const LEVER_OBSERVED_FRACTION: f64 = 0.5;
/// A difference from the sheet beyond this many σ is significant.
pub const LEVER_SIGNIFICANT_SIGMAS: f64 = 3.0;

/// The lever-arm estimate against the sheet's value (summary.json).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct LeverArmSummary {
    /// Estimated lever arm [forward, right, down] (m).
    pub estimate_m: [f64; 3],
    /// σ of each component (m).
    pub sd_m: [f64; 3],
    /// The initial σ of each component (m).
    pub initial_sd_m: f64,
    /// The configured (sheet) lever arm (m).
    pub sheet_m: [f64; 3],
    /// Per component: observed by the drive (σ below
    /// [`LEVER_OBSERVED_FRACTION`] of the initial σ).
    pub observed: [bool; 3],
    /// Length of the difference estimate − sheet over the observed
    /// components (m; 0 when none is).
    pub difference_m: f64,
    /// The largest |estimate − sheet| / σ over the observed components.
    pub difference_sigmas: f64,
    /// True when that exceeds [`LEVER_SIGNIFICANT_SIGMAS`].
    pub significant: bool,
    /// One sentence for the user.
    pub note: String,
}

impl LeverArmState {
    /// The estimate weighed against the sheet's `sheet_m`.
    pub fn against_sheet(&self, sheet_m: [f64; 3]) -> LeverArmSummary {
        let observed =
            [0, 1, 2].map(|k| self.sd_m[k] < LEVER_OBSERVED_FRACTION * self.initial_sd_m);
        let d = [0, 1, 2].map(|k| self.lever_m[k] - sheet_m[k]);
        let (mut sq, mut sigmas) = (0.0f64, 0.0f64);
        for k in (0..3).filter(|&k| observed[k]) {
            sq += d[k] * d[k];
            sigmas = sigmas.max(d[k].abs() / self.sd_m[k].max(1e-9));
        }
        let difference_m = sq.sqrt();
        let significant = sigmas > LEVER_SIGNIFICANT_SIGMAS;
        let v3 = |v: [f64; 3]| format!("[{:.3}, {:.3}, {:.3}]", v[0], v[1], v[2]);
        const AXES: [&str; 3] = ["forward", "right", "down"];
        let unobserved: Vec<&str> = (0..3).filter(|&k| !observed[k]).map(|k| AXES[k]).collect();
        let mut note = format!(
            "antenna lever arm estimated {} ± {} m (forward, right, down; initial σ {:.2} m)",
            v3(self.lever_m),
            v3(self.sd_m),
            self.initial_sd_m
        );
        if unobserved.len() == 3 {
            note.push_str(&format!(
                ": not observed on this drive (every σ stays above {:.0} % of its initial value: \
                 too few turns); the sheet's {} m is neither confirmed nor corrected",
                LEVER_OBSERVED_FRACTION * 100.0,
                v3(sheet_m)
            ));
        } else if significant {
            note.push_str(&format!(
                "; differs from the sheet's {} m by {difference_m:.3} m ({sigmas:.1} σ): measure the \
                 lever arm and correct antenna_lever_m",
                v3(sheet_m)
            ));
        } else {
            note.push_str(&format!(
                "; agrees with the sheet's {} m (within {sigmas:.1} σ)",
                v3(sheet_m)
            ));
        }
        if (1..3).contains(&unobserved.len()) {
            note.push_str(&format!(
                "; the {} component{} not observed on this drive (σ near its initial value: the \
                 horizontal ones need the heading to change; the down one is held, a consider \
                 state, as a road's roll and pitch hardly observe it): the sheet's value stands \
                 there",
                unobserved.join(" and "),
                if unobserved.len() > 1 { "s are" } else { " is" }
            ));
        }
        LeverArmSummary {
            estimate_m: self.lever_m,
            sd_m: self.sd_m,
            initial_sd_m: self.initial_sd_m,
            sheet_m,
            observed,
            difference_m,
            difference_sigmas: sigmas,
            significant,
            note,
        }
    }
}

/// A position placed from a fix less the lever arm (r̂ = r_G − Ĉ ℓ̂) is
/// wrong by −C δℓ besides the fix's error: P_rr gains C Σ_ℓ Cᵀ (= σ² I
/// for Σ_ℓ = σ² I) and P_rℓ = −C Σ_ℓ. Without it the filter would take
/// the aligned position as independent of the lever arm and "observe"
/// the lever arm from the fix it was placed with.
pub(in crate::fusion) fn correlate_initial_position(
    filter: &mut crate::filter::ErrorStateFilter,
    nav: &NavState,
    first: usize,
    sd_m: f64,
) {
    use crate::filter::idx;
    let v = sd_m * sd_m;
    let c = nav.c_nb();
    let p = filter.covariance_mut();
    for r in 0..3 {
        p.add_at(idx::POS + r, idx::POS + r, v);
        for k in 0..3 {
            let x = -c[(r, k)] * v;
            p.set(idx::POS + r, first + k, x);
            p.set(first + k, idx::POS + r, x);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(sd_m: [f64; 3]) -> LeverArmState {
        LeverArmState {
            lever_m: [0.39, -0.31, 0.0],
            sd_m,
            initial_sd_m: 0.5,
        }
    }

    /// Observed components are weighed against the sheet in σ; the rest
    /// are named as not observed and left out of the difference.
    #[test]
    fn the_estimate_is_weighed_against_the_sheet_over_what_was_observed() {
        let s = state([0.02, 0.02, 0.49]).against_sheet([0.0; 3]);
        assert_eq!(s.observed, [true, true, false]);
        assert!(
            (s.difference_m - 0.39f64.hypot(0.31)).abs() < 1e-12,
            "{s:?}"
        );
        assert!((s.difference_sigmas - 19.5).abs() < 1e-9, "{s:?}");
        assert!(s.significant, "{s:?}");
        assert!(s.note.contains("differs from the sheet's"), "{}", s.note);
        assert!(
            s.note.contains("the down component is not observed"),
            "{}",
            s.note
        );
        // The right sheet, within 1σ: agrees.
        let s = state([0.02, 0.02, 0.49]).against_sheet([0.4, -0.3, 0.0]);
        assert!(!s.significant && s.note.contains("agrees"), "{}", s.note);
        // Nothing observed (a straight road): no difference is claimed.
        let s = state([0.45, 0.3, 0.49]).against_sheet([0.0; 3]);
        assert_eq!(s.observed, [false; 3]);
        assert!(!s.significant && s.difference_m == 0.0, "{s:?}");
        assert!(s.note.contains("not observed on this drive"), "{}", s.note);
        assert!(!s.note.contains("differs"), "{}", s.note);
    }
}
