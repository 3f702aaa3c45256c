//! The IMU–GNSS time offset τ as a filter state (Wang, Guan & Ding 2019:
//! seed 004 eqs 11–16): its columns in the GNSS rows, the kinematics that
//! make it observable, holding it while it is not, and the coarse search's
//! re-initialisation. τ has no measurement of its own (it is observed
//! through the GNSS rows), so this file controls a state, not an
//! [`super::AidSource`].

use super::*;

/// Exponential-moving-average kinematics of the solution, used to decide
/// whether the time offset is observable and for the velocity row −a.
#[derive(Copy, Clone, Debug, Default)]
pub(in crate::fusion) struct Kinematics {
    pub(in crate::fusion) acc: Vector3<f64>,
    pub(in crate::fusion) acc_slow: Vector3<f64>,
}

impl Kinematics {
    pub(in crate::fusion) const TAU_FAST_S: f64 = 0.05;
    pub(in crate::fusion) const TAU_SLOW_S: f64 = 1.0;

    pub(in crate::fusion) fn push(&mut self, step: &StepInfo) {
        if step.dt <= 0.0 {
            return;
        }
        let a = step.dv_n / step.dt;
        let kf = (step.dt / Self::TAU_FAST_S).min(1.0);
        let ks = (step.dt / Self::TAU_SLOW_S).min(1.0);
        self.acc += (a - self.acc) * kf;
        self.acc_slow += (a - self.acc_slow) * ks;
    }
}

impl Core {
    /// The position row's τ column: ∂z/∂δτ = −v of the antenna (seed 004
    /// eq 15).
    pub(in crate::fusion) fn offset_column_position(&self, obs: &mut Observation) {
        if let Some(i) = self.tau_index {
            let lever = self.lever_b;
            let c = self.nav.c_nb();
            let w_nb = crate::ins::omega_nb_b(&self.nav, &self.last_w_ib);
            let v_ant = self.nav.vel + c * w_nb.cross(&lever);
            for r in 0..3 {
                obs.h.set(r, i, -v_ant[r]);
            }
        }
    }

    /// The velocity row's τ column: ∂z/∂δτ = −a (seed 004 eqs 11–16).
    pub(in crate::fusion) fn offset_column_velocity(&self, obs: &mut Observation) {
        if let Some(i) = self.tau_index {
            for r in 0..3 {
                obs.h.set(r, i, -self.kin.acc[r]);
            }
        }
    }

    /// Whether the motion currently carries information on the time offset:
    /// the fix's along-track offset −v·δτ can only be told from a position
    /// error while the velocity changes (speed or direction).
    pub(in crate::fusion) fn offset_observable(&self) -> bool {
        let speed = (self.nav.vel.x.powi(2) + self.nav.vel.y.powi(2)).sqrt();
        let acc_h = self.kin.acc_slow.norm();
        speed > 0.5 && acc_h > 0.1
    }

    pub(in crate::fusion) fn frozen_states(&mut self) -> Vec<usize> {
        match (self.tau_index, self.cfg.time_offset) {
            (Some(i), Some(to)) => {
                self.tau_observable = self.offset_observable();
                if to.hold_when_unobservable && !self.tau_observable {
                    self.stats.time_offset_held_updates += 1;
                    vec![i]
                } else {
                    vec![]
                }
            }
            _ => vec![],
        }
    }

    /// The range τ̂ must stay in: the coarse search's (± `search_range_s`),
    /// or without a search the initial value ± 3σ₀.
    fn offset_bound_s(to: &TimeOffsetOptions) -> f64 {
        let b = if to.search_range_s > 0.0 {
            to.search_range_s
        } else {
            to.init_s.abs() + 3.0 * to.sd_s
        };
        b.max(to.init_s.abs())
    }

    /// Resets τ̂ to its initial value and σ when an update carried it out
    /// of [`Self::offset_bound_s`]: an offset the search never allowed is a
    /// symptom (an IMU gap, a GNSS jump taken for a time offset), not an
    /// estimate, and left alone it carries the solution kilometres away.
    pub(in crate::fusion) fn bound_time_offset(&mut self) {
        let (Some(i), Some(to)) = (self.tau_index, self.cfg.time_offset) else {
            return;
        };
        let bound = Self::offset_bound_s(&to);
        if self.tau.abs() <= bound {
            return;
        }
        let was = self.tau;
        let mut dx = vec![0.0; self.filter.n()];
        dx[i] = self.tau - to.init_s;
        self.filter.record_correction(self.nav.time, &dx);
        self.tau = to.init_s;
        let p = self.filter.covariance_mut();
        for j in 0..p.rows {
            p.set(i, j, 0.0);
            p.set(j, i, 0.0);
        }
        p.set(i, i, to.sd_s * to.sd_s);
        self.stats.time_offset_resets += 1;
        if self.stats.time_offset_resets <= 20 {
            self.notes.push(format!(
                "time offset estimate {was:.4} s at {} left its range ±{bound:.3} s: reset to {:.4} s ± {:.4} s \
                 (an IMU gap or a GNSS jump taken for a time offset)",
                self.nav.time, to.init_s, to.sd_s
            ));
        }
    }

    /// Re-initialises τ̂ from the coarse search when the filter disagrees.
    pub(in crate::fusion) fn adopt_coarse(&mut self, est: &OffsetEstimate) -> Option<String> {
        let i = self.tau_index?;
        let sd_f = self.filter.sd(i);
        let diff = self.tau - est.offset_s;
        if diff.abs() <= 3.0 * (sd_f * sd_f + est.sd_s * est.sd_s).sqrt() {
            return Some(format!(
                "time-offset coarse search: {:.4} s ± {:.4} s agrees with the filter ({:.4} s ± {:.4} s)",
                est.offset_s, est.sd_s, self.tau, sd_f
            ));
        }
        let mut dx = vec![0.0; self.filter.n()];
        dx[i] = self.tau - est.offset_s;
        self.filter.record_correction(self.nav.time, &dx);
        self.tau = est.offset_s;
        let p = self.filter.covariance_mut();
        for j in 0..p.rows {
            p.set(i, j, 0.0);
            p.set(j, i, 0.0);
        }
        let sd = est.sd_s.max(0.002);
        p.set(i, i, sd * sd);
        Some(format!(
            "time-offset coarse search: {:.4} s ± {:.4} s over {} epochs; filter re-initialised from {:.4} s",
            est.offset_s,
            est.sd_s,
            est.epochs,
            est.offset_s + diff
        ))
    }
}
