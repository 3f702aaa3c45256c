//! Coarse search of the IMU–GNSS time offset before the filter refines it.
//!
//! Second differences of GNSS positions, D_k = r(t_{k+1}) − 2 r(t_k) +
//! r(t_{k−1}) with equal spacing Δ, equal the triangular-weighted integral of
//! the acceleration around the fixes' true validity time. The INS gives the
//! same quantity from its own kinematic position R (velocity changes
//! integrated twice, without any filter feedback, so constant velocity and
//! position errors cancel in the second difference): P_k(τ) = R(t_{k+1}−τ) −
//! 2R(t_k−τ) + R(t_{k−1}−τ) for a candidate offset τ (GNSS time tag minus
//! true validity time). The offset minimising Σ|D_k − P_k(τ)|²/σ² over a grid
//! is the coarse estimate; the curvature of that cost gives its σ.
//! Sensitivity comes from changes of acceleration (∂P/∂τ is a second
//! difference of velocity), so the search needs a drive with accelerations,
//! braking or turns; it reports nothing until the minimum is sharp and
//! unique.
#![warn(missing_docs)]

use std::collections::VecDeque;

use nalgebra::Vector3;

use crate::earth::{Geodetic, ned_offset};
use crate::time::GpsTime;

/// Result of a converged search.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct OffsetEstimate {
    /// Estimated offset (s): GNSS time tag − true time of validity.
    pub offset_s: f64,
    /// Its standard deviation from the cost curvature (s).
    pub sd_s: f64,
    /// Second differences used.
    pub epochs: usize,
}

/// Streaming coarse offset search.
pub(crate) struct CoarseOffsetSearch {
    range_s: f64,
    grid: Vec<f64>,
    cost: Vec<f64>,
    origin: Option<Geodetic>,
    // Kinematic INS position samples (time, NED metres from origin).
    kin: VecDeque<(GpsTime, Vector3<f64>)>,
    v_kin: Vector3<f64>,
    r_kin: Vector3<f64>,
    fixes: VecDeque<(GpsTime, Vector3<f64>, Vector3<f64>)>,
    epochs: usize,
    result: Option<OffsetEstimate>,
    /// Stop once σ falls below this (s).
    pub(crate) target_sd_s: f64,
}

impl CoarseOffsetSearch {
    /// Searches offsets in ±`range_s` with 1 ms steps; `v0` is the initial
    /// INS velocity (only its changes matter).
    pub(crate) fn new(range_s: f64, v0: Vector3<f64>) -> Self {
        // The grid extends 50 ms beyond the range so that an offset at the
        // range's end is still an interior minimum.
        // Bounded (FuseOptions::validate refuses a larger range first): a
        // range of 1e6 s would ask for 16 GB.
        let range_s = if range_s.is_finite() {
            range_s.clamp(0.0, crate::fusion::TimeOffsetOptions::MAX_SEARCH_RANGE_S)
        } else {
            0.0
        };
        let steps = ((range_s + 0.05) / 0.001).round() as i64;
        let grid: Vec<f64> = (-steps..=steps).map(|k| k as f64 * 0.001).collect();
        CoarseOffsetSearch {
            range_s,
            cost: vec![0.0; grid.len()],
            grid,
            origin: None,
            kin: VecDeque::new(),
            v_kin: v0,
            r_kin: Vector3::zeros(),
            fixes: VecDeque::new(),
            epochs: 0,
            result: None,
            target_sd_s: 0.020,
        }
    }

    /// The estimate, once converged.
    pub(crate) fn result(&self) -> Option<OffsetEstimate> {
        self.result
    }

    /// Adds one INS step ending at `t`: its total velocity change `dv_n`
    /// (NED, m/s) over `dt` seconds, and the antenna lever arm in NED
    /// (C_b^n ℓ) at that time, so that the search compares antenna
    /// positions with antenna positions (a rotating lever arm has second
    /// differences of its own in turns).
    pub(crate) fn push_step(
        &mut self,
        t: GpsTime,
        dv_n: &Vector3<f64>,
        dt: f64,
        lever_n: &Vector3<f64>,
    ) {
        if self.result.is_some() {
            return;
        }
        let v1 = self.v_kin + dv_n;
        self.r_kin += 0.5 * (self.v_kin + v1) * dt;
        self.v_kin = v1;
        self.kin.push_back((t, self.r_kin + lever_n));
        self.evaluate(t);
        // Keep what the oldest pending fix can still need.
        let keep_from = self
            .fixes
            .front()
            .map(|f| f.0.add_seconds(-self.range_s - 0.6))
            .unwrap_or(t.add_seconds(-self.range_s - 3.0));
        while self.kin.len() > 2 && self.kin[1].0 < keep_from {
            self.kin.pop_front();
        }
    }

    /// Adds a GNSS fix (time tag, position, NED standard deviations).
    pub(crate) fn push_fix(&mut self, tag: GpsTime, pos: &Geodetic, sd: &Vector3<f64>) {
        if self.result.is_some() {
            return;
        }
        let origin = *self.origin.get_or_insert(*pos);
        self.fixes.push_back((tag, ned_offset(&origin, pos), *sd));
        while self.fixes.len() > 64 {
            self.fixes.pop_front();
        }
    }

    fn kin_at(&self, t: GpsTime) -> Option<Vector3<f64>> {
        let n = self.kin.len();
        if n < 2 || t < self.kin[0].0 || t > self.kin[n - 1].0 {
            return None;
        }
        let i = self.kin.partition_point(|s| s.0 <= t).clamp(1, n - 1);
        let (ta, ra) = self.kin[i - 1];
        let (tb, rb) = self.kin[i];
        let u = (t - ta) as f64 / (tb - ta).max(1) as f64;
        Some(ra + (rb - ra) * u)
    }

    /// Processes every fix triple whose whole search window is covered.
    fn evaluate(&mut self, now: GpsTime) {
        loop {
            if self.fixes.len() < 3 {
                return;
            }
            // Triple: the first fix, one ~Δ ≥ 1 s later, one 2Δ later.
            let (t0, r0, sd0) = self.fixes[0];
            let Some(j) = self
                .fixes
                .iter()
                .position(|f| f.0.seconds_since(t0) >= 0.999)
            else {
                return;
            };
            let delta = self.fixes[j].0 - t0;
            let want = t0 + 2 * delta;
            let Some(k) = self.fixes.iter().position(|f| f.0 >= want) else {
                return;
            };
            if self.fixes[k].0 - want > 1_000_000 {
                // No equally spaced partner (gap): drop the first fix.
                self.fixes.pop_front();
                continue;
            }
            let (t2, r2, sd2) = self.fixes[k];
            if now < t2.add_seconds(self.range_s + 0.06) {
                return; // INS data not yet available for every candidate
            }
            let (t1, r1, sd1) = self.fixes[j];
            let d = r2 - 2.0 * r1 + r0;
            let var =
                (sd0.component_mul(&sd0) + 4.0 * sd1.component_mul(&sd1) + sd2.component_mul(&sd2))
                    .map(|v| v.max(1e-6));
            let mut any = false;
            for gi in 0..self.grid.len() {
                let g = self.grid[gi];
                let (Some(a), Some(b), Some(e)) = (
                    self.kin_at(t0.add_seconds(-g)),
                    self.kin_at(t1.add_seconds(-g)),
                    self.kin_at(t2.add_seconds(-g)),
                ) else {
                    continue;
                };
                any = true;
                let p = e - 2.0 * b + a;
                let r = d - p;
                // Each component's χ² contribution is capped so a GNSS
                // outlier cannot dominate (Huber-like robustness).
                self.cost[gi] += (0..3)
                    .map(|i| (r[i] * r[i] / var[i]).min(25.0))
                    .sum::<f64>();
            }
            if any {
                self.epochs += 1;
            }
            self.fixes.pop_front();
            self.check_convergence();
            if self.result.is_some() {
                return;
            }
        }
    }

    fn check_convergence(&mut self) {
        if self.epochs < 10 {
            return;
        }
        let (imin, &cmin) = self
            .cost
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .expect("non-empty grid");
        let step = self.grid[1] - self.grid[0];
        // Least-squares parabola over ±15 ms around the minimum (robust to
        // small wiggles of the cost): c ≈ c0 + c1 x + c2 x².
        let half = (0.015 / step).round() as usize;
        if imin < half || imin + half >= self.cost.len() {
            return; // at the edge of the range: not a minimum
        }
        let (mut s0, mut s1, mut s2, mut s3, mut s4) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut t0, mut t1, mut t2) = (0.0, 0.0, 0.0);
        for i in imin - half..=imin + half {
            let x = self.grid[i] - self.grid[imin];
            let y = self.cost[i] - cmin;
            s0 += 1.0;
            s1 += x;
            s2 += x * x;
            s3 += x * x * x;
            s4 += x * x * x * x;
            t0 += y;
            t1 += x * y;
            t2 += x * x * y;
        }
        let m = nalgebra::Matrix3::new(s0, s1, s2, s1, s2, s3, s2, s3, s4);
        let Some(c) = m.lu().solve(&Vector3::new(t0, t1, t2)) else {
            return;
        };
        if c.z <= 0.0 {
            return;
        }
        // J(τ) − J_min ≈ (τ − τ*)²/σ²  ⇒  σ = 1/√c2.
        let sd = (1.0 / c.z).sqrt();
        let vertex = (-c.y / (2.0 * c.z)).clamp(-(half as f64) * step, half as f64 * step);
        // Unique: everything beyond 4σ (and 20 ms) is at least 3σ worse.
        let sep = ((4.0 * sd).max(0.02) / step).ceil() as usize;
        let rival = self
            .cost
            .iter()
            .enumerate()
            .filter(|(i, _)| i.abs_diff(imin) > sep)
            .map(|(_, c)| *c)
            .fold(f64::INFINITY, f64::min);
        if sd <= self.target_sd_s && rival > cmin + 9.0 {
            self.result = Some(OffsetEstimate {
                offset_s: self.grid[imin] + vertex,
                sd_s: sd,
                epochs: self.epochs,
            });
            self.kin.clear();
            self.fixes.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::TimeOffsetOptions;
    use crate::pipeline::FuseOptions;

    #[test]
    fn a_search_range_beyond_its_bound_is_refused_and_never_allocated() {
        // `fuse --time-offset-search 1e300` overflowed the grid's capacity.
        for bad in [1e300, 1e6, f64::NAN, f64::INFINITY, -1.0, 5.001] {
            let o = FuseOptions {
                time_offset: Some(TimeOffsetOptions {
                    search_range_s: bad,
                    ..Default::default()
                }),
                ..FuseOptions::default()
            };
            let e = o.validate().unwrap_err().to_string();
            assert!(e.contains("time-offset search range"), "{e}");
        }
        // Called directly, the grid stays within ±(5 s + 50 ms) at 1 ms.
        let s = CoarseOffsetSearch::new(1e300, Vector3::zeros());
        assert_eq!(s.grid.len(), 2 * 5050 + 1);
        let s = CoarseOffsetSearch::new(f64::NAN, Vector3::zeros());
        assert_eq!(s.grid.len(), 2 * 50 + 1);
    }
}
