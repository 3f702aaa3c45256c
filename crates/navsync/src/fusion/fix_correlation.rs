//! The part of the fixes' error that outlasts their spacing, carried into
//! the written σ.
//!
//! A receiver's position error is white noise plus slow errors (multipath,
//! the atmosphere, an ambiguity-fixed solution's bias) correlated over
//! seconds to minutes (Groves, "Principles of GNSS, Inertial, and
//! Multisensor Integrated Navigation Systems", 2nd ed., ch. 9). The filter
//! takes each fix as independent: after N fixes its position variance P is
//! about R/N, right for the white part, while the slow part passes into the
//! solution whole. With 10 Hz RTK fixes the written σ fall to millimetres
//! while the solution is off by the slow part's centimetres, and the σ and
//! protection levels stop covering the error.
//!
//! The fault monitor measures the share w of the stated variance by which
//! the error changes from one clean fix to the next
//! (`FaultMonitor::correlated_fix_share`); c = 1 − w does not average.
//! Take that part as one error through the fixes the solution rests on
//! (those of the last minute or so, [`FIX_MEMORY_S`]), of σ √c·σ_k in fix
//! k. Where fix k weighs P/σ_k² in the solution (a least-squares average
//! with prior information), the error it passes has σ √c·P·Σσ_k⁻¹, where
//! the filter counted variance c·P²·Σσ_k⁻²: the written variance gets
//! the difference, c·P²·((Σσ_k⁻¹)² − Σσ_k⁻²) per axis. For N equal
//! fixes and no other information (P = σ²/N) that is c·(σ² − P): the
//! whole slow part less what the filter counted. It is at most c·(R̄ − P),
//! R̄ = (Σσ_k⁻¹ / Σσ_k⁻²)² the σ-weighted variance of the fixes: a filter
//! whose memory is shorter than the window (P above 1/Σσ_k⁻²) rests on
//! fewer fixes than the sums hold. This is a consider term for an error
//! left out of the state (Schmidt, "Application of state-space methods to
//! navigation problems", Advances in Control Systems 3, 1966), for the
//! sequentially correlated measurement noise of Bryson & Henrikson
//! ("Estimation using sampled data containing sequentially correlated
//! noise", J. Spacecraft and Rockets 5(6), 1968) in its limit of a
//! correlation time longer than the filter averages over: the safe side
//! when it is not known. Where P ≥ R̄ the filter is not averaging fixes
//! (coasting, or too few fixes) and nothing is added; where the INS holds
//! the solution better than the fixes could, little is. The positions are
//! unchanged: only what is written beside them.

use nalgebra::{Matrix3, Vector3};

use crate::fusion::config::{FixRecord, FixStatus};
use crate::time::GpsTime;

/// The e-folding time (s) of the fixes the solution is taken to rest on.
pub(crate) const FIX_MEMORY_S: f64 = 60.0;

/// Σσ⁻¹ and Σσ⁻² of fused fixes (per axis), each weighed by e^(−age/
/// [`FIX_MEMORY_S`]), as of `time`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FixSums {
    time: GpsTime,
    inv_sd: Vector3<f64>,
    inv_var: Vector3<f64>,
}

impl FixSums {
    /// The sums of one fix of stated variance `fix_var` at `time`.
    fn first(time: GpsTime, fix_var: &Vector3<f64>) -> FixSums {
        FixSums {
            time,
            inv_sd: fix_var.map(|v| 1.0 / v.sqrt()),
            inv_var: fix_var.map(|v| 1.0 / v),
        }
    }

    /// These sums carried to `time` (decayed by the time between, either
    /// way: a sweep may run backward), then with a fix of stated variance
    /// `fix_var` added.
    fn add(self, time: GpsTime, fix_var: &Vector3<f64>) -> FixSums {
        let decay = (-time.seconds_since(self.time).abs() / FIX_MEMORY_S).exp();
        let fix = FixSums::first(time, fix_var);
        FixSums {
            time,
            inv_sd: self.inv_sd * decay + fix.inv_sd,
            inv_var: self.inv_var * decay + fix.inv_var,
        }
    }

    /// R̄ = (Σσ⁻¹ / Σσ⁻²)² per axis: the σ-weighted variance of the fixes.
    fn averaged_var(&self) -> Vector3<f64> {
        Vector3::from_fn(|i, _| (self.inv_sd[i] / self.inv_var[i]).powi(2))
    }

    /// The covariance (m², NED) to add to a written position covariance
    /// `p_pos` for the correlated share `share` of these fixes' error (see
    /// the module's notes); `None` when there is nothing to add.
    pub(crate) fn consider(
        &self,
        share: &Vector3<f64>,
        p_pos: &Matrix3<f64>,
    ) -> Option<Matrix3<f64>> {
        let extra = Vector3::from_fn(|i, _| {
            let (s1, s2, p) = (self.inv_sd[i], self.inv_var[i], p_pos[(i, i)]);
            let passed = p * p * (s1 * s1 - s2);
            let averaged = self.averaged_var()[i] - p;
            let e = share[i].clamp(0.0, 1.0) * passed.min(averaged);
            if e.is_finite() { e.max(0.0) } else { 0.0 }
        });
        (extra.max() > 0.0).then(|| Matrix3::from_diagonal(&extra))
    }
}

/// What the written covariance needs of the fixes: the correlated share
/// of their stated variance and the sums of the fixes fused.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FixCorrelation {
    /// 1 − the share that changes from fix to fix (per axis), once measured.
    share: Option<Vector3<f64>>,
    sums: Option<FixSums>,
}

impl FixCorrelation {
    /// A position fix of stated variance `fix_var` was fused at `time`;
    /// `share` the correlated share measured so far.
    pub(crate) fn note_fused(
        &mut self,
        time: GpsTime,
        fix_var: Vector3<f64>,
        share: Option<Vector3<f64>>,
    ) {
        if !fix_var.iter().all(|v| v.is_finite() && *v > 0.0) {
            return;
        }
        self.sums = Some(match self.sums {
            Some(s) => s.add(time, &fix_var),
            None => FixSums::first(time, &fix_var),
        });
        self.share = share;
    }

    /// The covariance (m², NED) to add to a written position covariance
    /// `p_pos`; `None` when there is nothing to add.
    pub(crate) fn covariance(&self, p_pos: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        self.sums?.consider(&self.share?, p_pos)
    }
}

/// The sums of the fused position fixes around each fix of a run, for the
/// smoothed solution's σ: the smoother rests on the fixes on both sides,
/// so the sums are taken over both (each side weighed as
/// [`FixCorrelation`] weighs the past).
pub(crate) struct FixSumsTimeline(Vec<FixSums>);

impl FixSumsTimeline {
    /// From a run's fix records (in time order): the position fixes fused.
    pub(crate) fn from_records(records: &[FixRecord]) -> Self {
        let fixes: Vec<(GpsTime, Vector3<f64>)> = records
            .iter()
            .filter(|r| {
                r.kind == "position"
                    && matches!(
                        r.status,
                        FixStatus::Used | FixStatus::DownWeighted | FixStatus::DriftAccepted
                    )
            })
            .map(|r| (r.time, Vector3::from_fn(|i, _| r.sd[i] * r.sd[i])))
            .filter(|(_, v)| v.iter().all(|v| v.is_finite() && *v > 0.0))
            .collect();
        let sweep = |order: &mut dyn Iterator<Item = &(GpsTime, Vector3<f64>)>| {
            let mut sums: Option<FixSums> = None;
            order
                .map(|(t, v)| {
                    let s = sums.map_or_else(|| FixSums::first(*t, v), |s| s.add(*t, v));
                    sums = Some(s);
                    s
                })
                .collect::<Vec<_>>()
        };
        let past = sweep(&mut fixes.iter());
        let mut future = sweep(&mut fixes.iter().rev());
        future.reverse();
        let both = fixes
            .iter()
            .zip(past.iter().zip(&future))
            .map(|(&(time, v), (p, f))| {
                // The fix itself is in both.
                let own = FixSums::first(time, &v);
                FixSums {
                    time,
                    inv_sd: p.inv_sd + f.inv_sd - own.inv_sd,
                    inv_var: p.inv_var + f.inv_var - own.inv_var,
                }
            })
            .collect();
        FixSumsTimeline(both)
    }

    /// The sums in force at `t`: the last fused fix's at or before it, or
    /// the first's before the first.
    pub(crate) fn at(&self, t: GpsTime) -> Option<&FixSums> {
        let k = self.0.partition_point(|s| s.time <= t);
        self.0.get(k.saturating_sub(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: f64) -> GpsTime {
        GpsTime::from_week_sow(2300, 100_000.0 + s)
    }

    #[test]
    fn the_filter_is_given_back_what_it_averaged_of_a_correlated_error() {
        let share = Vector3::new(0.5, 0.5, 0.0);
        let r = Vector3::new(4e-4, 4e-4, 9e-4);
        // 16 equal fixes at once.
        let sums = (1..16).fold(FixSums::first(t(0.0), &r), |s, _| s.add(t(0.0), &r));
        // Averaged alone: P = R/16. Half the error does not average: its
        // variance is R/2 + R/32, the filter's R/16.
        let p = Matrix3::from_diagonal(&(r / 16.0));
        let extra = sums.consider(&share, &p).unwrap();
        assert!((p[(0, 0)] + extra[(0, 0)] - (r[0] / 2.0 + r[0] / 32.0)).abs() < 1e-15);
        assert_eq!(extra[(2, 2)], 0.0, "no correlated share, nothing added");
        assert_eq!(extra[(0, 1)], 0.0);
        // With an INS four times sharper (P = R/64) each fix weighs 1/64:
        // the slow part passes a quarter of itself, variance cR/16, of
        // which the filter counted cR/256.
        let p = Matrix3::from_diagonal(&(r / 64.0));
        let extra = sums.consider(&share, &p).unwrap();
        assert!((extra[(0, 0)] - 0.5 * (r[0] / 16.0 - r[0] / 256.0)).abs() < 1e-15);
        // Coasting past the fixes' own variance: nothing to add.
        assert!(
            sums.consider(&share, &Matrix3::from_diagonal(&(r * 2.0)))
                .is_none()
        );
        // A corrupt figure adds nothing rather than NaN.
        assert!(sums.consider(&Vector3::repeat(f64::NAN), &p).is_none());
        assert!(FixCorrelation::default().covariance(&p).is_none());
    }

    #[test]
    fn the_fixes_a_solution_rests_on_are_its_good_ones() {
        let record = |s: f64, sd: f64, status| FixRecord {
            time: t(s),
            sow: t(s).sow(),
            kind: "position",
            innovation: [0.0; 3],
            sd: [sd; 3],
            nis: 0.0,
            weight: [1.0; 3],
            status,
            reason: Default::default(),
            hpl_m: 0.0,
        };
        // 1 cm fixes for 20 s with one 30 cm fix and one rejected wild
        // one among them; 20 cm fixes from 1000 s on.
        let mut records: Vec<FixRecord> = (0..20)
            .map(|k| record(k as f64, if k == 10 { 0.3 } else { 0.01 }, FixStatus::Used))
            .collect();
        records.insert(5, record(4.5, 5.0, FixStatus::Rejected));
        records.extend((0..20).map(|k| record(1000.0 + k as f64, 0.2, FixStatus::DownWeighted)));
        let sums = FixSumsTimeline::from_records(&records);
        assert_eq!(
            sums.0.len(),
            40,
            "the rejected fix is not one the solution rests on"
        );
        let at = |s: f64| sums.at(t(s)).unwrap().averaged_var()[0];
        // Equal fixes: their own variance.
        assert!((at(2.0) - 1e-4).abs() < 1e-4 * 0.2, "{}", at(2.0));
        // The poor fix barely moves the variance the solution rests on.
        assert!(at(10.0) < 1.2e-4, "{}", at(10.0));
        // Long after: the new fixes alone; before the first, the first's.
        assert!((at(1010.0) - 0.04).abs() < 0.04 * 1e-3, "{}", at(1010.0));
        assert_eq!(at(-5.0), at(0.0));
        assert!(FixSumsTimeline::from_records(&[]).at(t(1.0)).is_none());

        // The forward filter's sums are the same over the past.
        let mut c = FixCorrelation::default();
        for r in records
            .iter()
            .filter(|r| r.status != FixStatus::Rejected)
            .take(20)
        {
            c.note_fused(
                r.time,
                Vector3::repeat(r.sd[0] * r.sd[0]),
                Some(Vector3::repeat(1.0)),
            );
        }
        let p = Matrix3::from_diagonal(&Vector3::repeat(1e-5));
        let extra = c.covariance(&p).unwrap();
        assert!(
            extra[(0, 0)] > 0.8e-4 && extra[(0, 0)] < 1.2e-4,
            "{}",
            extra[(0, 0)]
        );
        // A corrupt σ is no fix to rest on.
        c.note_fused(t(21.0), Vector3::repeat(f64::NAN), None);
        assert_eq!(c.covariance(&p), Some(extra));
    }
}
