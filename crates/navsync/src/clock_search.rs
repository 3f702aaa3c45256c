//! The offset between an IMU's own clock and GPS time, found from the
//! motion alone when nothing else relates the two clocks (an IMU log on a
//! host clock, a receiver log without receive times): no overlap of the two
//! time axes is needed.
//!
//! Method: temporal calibration by registering the same motion seen by two
//! sensors (Furgale, Rehder & Siegwart, "Unified temporal and spatial
//! calibration for multi-sensor systems", IROS 2013; Kelly & Sukhatme, "On
//! determining the time delay between inertial and visual sensor
//! measurements", IEEE T-RO 30(6), 2014), initialised as in Mair et al.,
//! "Spatio-temporal initialization for IMU to camera registration" (ROBIO
//! 2011) by the peak of a normalised cross-correlation (Knapp & Carter, "The
//! generalized correlation method for estimation of time delay", IEEE
//! T-ASSP 24(4), 1976). Two signals, both independent of how the IMU is
//! mounted:
//!
//! - yaw rate: the gyro's component along the down direction (the mean
//!   specific force over the log points up) against the GNSS course rate
//!   (consecutive velocities, at speeds where the course is defined);
//! - horizontal specific force magnitude against the magnitude of the
//!   GNSS horizontal velocity change.
//!
//! Each GNSS interval [t_k, t_{k+1}] gives one sample; the IMU's is the
//! exact mean over the same interval shifted by the candidate offset (from
//! cumulative integrals on a 10 ms grid). The correlation is normalised by
//! the energies of the whole signals (not of the overlap), so that a lag
//! that overlaps one turn of several scores accordingly. Search: every lag
//! on a 1 s grid over the whole range where the spans overlap by
//! `min_overlap_s` (whole-signal normalisation: the peak and its rivals),
//! then 10 ms steps ±1.5 s around the best by the Pearson correlation over
//! the overlap (whose peak, unlike the whole-signal one's, is not pulled by
//! the means of the parts outside: 20–30 ms on the simulated test track),
//! parabolic interpolation. The result is refused when the drive has no turns, the
//! peak is low (flat) or a second peak nearly as high (ambiguous).
#![warn(missing_docs)]

use nalgebra::Vector3;

use crate::earth::ned_offset;
use crate::types::{GnssFix, ImuSample};

/// Settings of the search.
#[derive(Clone, Debug)]
pub struct ClockSearchOptions {
    /// Course rates only where both velocities are at least this fast (m/s).
    pub min_speed_mps: f64,
    /// The two spans must overlap by at least this much at a candidate (s).
    pub min_overlap_s: f64,
    /// Coarse grid step (s).
    pub coarse_step_s: f64,
    /// Fine grid step (s) and half-width of the fine search (s).
    pub fine_step_s: f64,
    /// Half-width of the fine search around the coarse peak (s).
    pub fine_half_width_s: f64,
    /// An interval is a turn when its course rate is at least this (deg/s).
    pub turn_rate_deg_s: f64,
    /// Fewest turning intervals for a search.
    pub min_turn_intervals: usize,
    /// Lowest acceptable peak correlation.
    pub min_peak_corr: f64,
    /// Highest acceptable ratio of the second peak to the first.
    pub max_second_ratio: f64,
    /// Largest acceptable σ of the offset (s).
    pub max_sd_s: f64,
}

impl Default for ClockSearchOptions {
    fn default() -> Self {
        ClockSearchOptions {
            min_speed_mps: 2.0,
            min_overlap_s: 20.0,
            coarse_step_s: 1.0,
            fine_step_s: 0.01,
            fine_half_width_s: 1.5,
            turn_rate_deg_s: 3.0,
            min_turn_intervals: 5,
            min_peak_corr: 0.5,
            max_second_ratio: 0.75,
            max_sd_s: 0.1,
        }
    }
}

/// The offset found, and how well.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ClockOffset {
    /// GPS time = IMU time + `offset_s` (s).
    pub offset_s: f64,
    /// Its standard deviation from the peak's curvature (s).
    pub sd_s: f64,
    /// Pearson correlation over the overlap at the peak (mean of the two
    /// signals').
    pub peak_corr: f64,
    /// The coarse peak's correlation normalised by the whole signals
    /// (lower when the logs cover different spans).
    pub whole_corr: f64,
    /// The yaw-rate signal's correlation at the peak.
    pub yaw_corr: f64,
    /// The specific-force signal's correlation at the peak.
    pub accel_corr: f64,
    /// Full width of the coarse peak at half its height (s).
    pub width_s: f64,
    /// The best correlation outside the main peak, over the peak's.
    pub second_peak_ratio: f64,
    /// Where that second peak is (s).
    pub second_offset_s: f64,
    /// GNSS intervals that gave a course rate, and of them turning.
    pub yaw_intervals: usize,
    /// Turning intervals (course rate ≥ the threshold).
    pub turn_intervals: usize,
    /// Candidate offsets searched: first and last (s).
    pub range_s: [f64; 2],
}

/// Why no offset was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClockSearchError {
    /// Too few samples to search.
    #[error("too little data: {0}")]
    TooLittle(String),
    /// The IMU's mean specific force is not gravity.
    #[error(
        "the IMU's mean specific force is {0:.2} m/s², not gravity (≈ 9.8): are the accelerations in m/s²?"
    )]
    NotGravity(f64),
    /// The drive has no turns.
    #[error(
        "the drive has no turns to time against: {turns} of {intervals} GNSS intervals above {min_speed_mps} m/s turn faster than {rate_deg_s}°/s (at least {needed} needed)"
    )]
    NoTurns {
        /// Turning intervals.
        turns: usize,
        /// Intervals with a defined course.
        intervals: usize,
        /// The speed threshold (m/s).
        min_speed_mps: f64,
        /// The turn-rate threshold (deg/s).
        rate_deg_s: f64,
        /// Turning intervals needed.
        needed: usize,
    },
    /// The correlation found no clear peak.
    #[error(
        "no clear match between the IMU's and the GNSS's motion: best correlation {peak:.2} at offset {offset_s:.3} s (at least {min:.2} needed){detail}"
    )]
    Flat {
        /// The best correlation.
        peak: f64,
        /// Where.
        offset_s: f64,
        /// The threshold.
        min: f64,
        /// More.
        detail: String,
    },
    /// Two offsets match about equally well.
    #[error(
        "ambiguous: offsets {offset_s:.3} s and {second_s:.3} s match about equally well (correlation {peak:.2}, second peak {ratio:.2} of it; at most {max:.2} accepted)"
    )]
    Ambiguous {
        /// The best offset.
        offset_s: f64,
        /// The second.
        second_s: f64,
        /// The best correlation.
        peak: f64,
        /// Second over best.
        ratio: f64,
        /// The threshold.
        max: f64,
    },
    /// The peak is too broad for the filter's fine search.
    #[error(
        "imprecise: offset {offset_s:.3} ± {sd_s:.3} s (at most ± {max:.3} s accepted; peak width {width_s:.2} s)"
    )]
    Imprecise {
        /// The offset.
        offset_s: f64,
        /// Its σ.
        sd_s: f64,
        /// The threshold.
        max: f64,
        /// The peak's width.
        width_s: f64,
    },
}

/// Cumulative integrals of the IMU's two signals on a uniform grid.
struct ImuTrack {
    t0_s: f64,
    step_s: f64,
    /// ∫ yaw rate (about down) dt, rad.
    yaw: Vec<f64>,
    /// ∫ |horizontal specific force| dt, m/s.
    fh: Vec<f64>,
    /// Gaps (intervals > 5 median intervals) before each grid point;
    /// `INSIDE_GAP` for a point inside one.
    gaps: Vec<u32>,
}

const GRID_STEP_S: f64 = 0.01;
const INSIDE_GAP: u32 = u32::MAX;

impl ImuTrack {
    fn new(imu: &[ImuSample]) -> Result<Self, ClockSearchError> {
        if imu.len() < 100 {
            return Err(ClockSearchError::TooLittle(format!(
                "{} IMU samples (at least 100 needed)",
                imu.len()
            )));
        }
        let t: Vec<f64> = imu.iter().map(|s| s.time.seconds()).collect();
        let span = t[t.len() - 1] - t[0];
        let sum_dv: Vector3<f64> = imu[1..].iter().map(|s| s.dvel).sum();
        if span.is_nan() || span <= 0.0 {
            return Err(ClockSearchError::TooLittle(
                "IMU times do not increase".into(),
            ));
        }
        let mean_f = sum_dv / span;
        if !(5.0..=15.0).contains(&mean_f.norm()) {
            return Err(ClockSearchError::NotGravity(mean_f.norm()));
        }
        let up = mean_f.normalize();
        let mut dts: Vec<f64> = t.windows(2).take(5000).map(|w| w[1] - w[0]).collect();
        dts.sort_by(f64::total_cmp);
        let gap_s = 5.0 * dts[dts.len() / 2].max(1e-4);
        let n = (span / GRID_STEP_S).floor() as usize + 1;
        let mut tr = ImuTrack {
            t0_s: t[0],
            step_s: GRID_STEP_S,
            yaw: Vec::with_capacity(n),
            fh: Vec::with_capacity(n),
            gaps: Vec::with_capacity(n),
        };
        // Sample j covers (t[j-1], t[j]] with constant rates; the integral
        // at a grid time interpolates within the sample.
        let (mut cy, mut cf, mut g, mut j) = (0.0, 0.0, 0u32, 1usize);
        for m in 0..n {
            let tm = t[0] + m as f64 * GRID_STEP_S;
            while j < t.len() && t[j] <= tm {
                let s = &imu[j];
                cy -= s.dtheta.dot(&up);
                cf += (s.dvel - up * s.dvel.dot(&up)).norm();
                if t[j] - t[j - 1] > gap_s {
                    g += 1;
                }
                j += 1;
            }
            let (mut y, mut f, mut gm) = (cy, cf, g);
            if j < t.len() {
                let s = &imu[j];
                if t[j] - t[j - 1] > gap_s {
                    gm = INSIDE_GAP;
                }
                let frac = (tm - t[j - 1]) / (t[j] - t[j - 1]);
                y -= frac * s.dtheta.dot(&up);
                f += frac * (s.dvel - up * s.dvel.dot(&up)).norm();
            }
            tr.yaw.push(y);
            tr.fh.push(f);
            tr.gaps.push(gm);
        }
        Ok(tr)
    }

    fn end_s(&self) -> f64 {
        self.t0_s + (self.yaw.len() - 1) as f64 * self.step_s
    }

    /// Mean yaw rate and horizontal specific force over [a, b] (IMU time)
    /// clipped to the log, with the covered fraction of [a, b] (a weight
    /// that lets an interval enter the correlation smoothly as the lag
    /// moves it over the log's ends); none across a gap.
    fn mean(&self, a: f64, b: f64) -> Option<(f64, f64, f64)> {
        let (ca, cb) = (a.max(self.t0_s), b.min(self.end_s()));
        if (cb - ca).is_nan() || cb - ca <= 1e-6 {
            return None;
        }
        let ia = self.locate(ca)?;
        let ib = self.locate(cb)?;
        if self.gaps[ib.0] != self.gaps[ia.0] || self.gaps[ia.0] == INSIDE_GAP {
            return None;
        }
        let at = |v: &[f64], (i, f): (usize, f64)| {
            if f == 0.0 {
                v[i]
            } else {
                v[i] + f * (v[i + 1] - v[i])
            }
        };
        let d = cb - ca;
        Some((
            (at(&self.yaw, ib) - at(&self.yaw, ia)) / d,
            (at(&self.fh, ib) - at(&self.fh, ia)) / d,
            d / (b - a),
        ))
    }

    fn locate(&self, t: f64) -> Option<(usize, f64)> {
        let last = (self.yaw.len() - 1) as f64;
        // Rounding may put the log's own ends a hair outside it.
        let x = (t - self.t0_s) / self.step_s;
        if !(x >= -1e-6 && x <= last + 1e-6) {
            return None;
        }
        let x = x.clamp(0.0, last);
        let i = (x.floor() as usize).min(self.yaw.len() - 1);
        Some((
            i,
            if i + 1 < self.yaw.len() {
                x - i as f64
            } else {
                0.0
            },
        ))
    }
}

/// One GNSS interval's signals.
struct Interval {
    a_s: f64,
    b_s: f64,
    /// Course rate about down (rad/s), when defined.
    yaw: Option<f64>,
    /// |Δv_horizontal| / Δt (m/s²).
    accel: f64,
}

/// The GNSS intervals: between consecutive receiver velocities, or between
/// the midpoints of consecutive fixes (velocity from positions).
fn gnss_intervals(fixes: &[GnssFix], min_speed_mps: f64) -> Vec<Interval> {
    let mut vel: Vec<(f64, Vector3<f64>)> = Vec::with_capacity(fixes.len());
    if fixes.iter().all(|f| f.vel.is_some()) {
        vel.extend(
            fixes
                .iter()
                .filter_map(|f| Some((f.time.seconds(), f.vel?))),
        );
    } else if let Some(first) = fixes.first() {
        for w in fixes.windows(2) {
            let dt = w[1].time.seconds_since(w[0].time);
            if dt > 0.0 {
                let d = ned_offset(&first.pos, &w[1].pos) - ned_offset(&first.pos, &w[0].pos);
                vel.push((w[0].time.seconds() + 0.5 * dt, d / dt));
            }
        }
    }
    let mut dts: Vec<f64> = vel.windows(2).map(|w| w[1].0 - w[0].0).collect();
    dts.sort_by(f64::total_cmp);
    let Some(&med) = dts.get(dts.len() / 2) else {
        return Vec::new();
    };
    let mut out = Vec::with_capacity(vel.len());
    for w in vel.windows(2) {
        let ((a, va), (b, vb)) = (w[0], w[1]);
        let dt = b - a;
        // A gap (missing fixes) or a repeated time: no sample.
        if dt.is_nan() || dt <= 0.0 || dt > 2.5 * med {
            continue;
        }
        let (sa, sb) = (va.xy().norm(), vb.xy().norm());
        let yaw = (sa >= min_speed_mps && sb >= min_speed_mps).then(|| {
            let d = vb.y.atan2(vb.x) - va.y.atan2(va.x);
            // Wrapped to (−π, π]: the course change over one interval.
            let d = d - std::f64::consts::TAU
                * ((d + std::f64::consts::PI) / std::f64::consts::TAU).floor();
            d / dt
        });
        out.push(Interval {
            a_s: a,
            b_s: b,
            yaw,
            accel: (vb.xy() - va.xy()).norm() / dt,
        });
    }
    out
}

/// Mean and energy (sum of squared deviations) of a signal.
fn moments(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = v.clone().count().max(1) as f64;
    let mean = v.clone().sum::<f64>() / n;
    (mean, v.map(|x| (x - mean) * (x - mean)).sum())
}

/// The correlation machinery: GNSS samples with their means and energies,
/// the IMU's means and energies over tiles of the median interval.
struct Correlator<'a> {
    track: &'a ImuTrack,
    iv: &'a [Interval],
    g_yaw: (f64, f64),
    g_acc: (f64, f64),
    i_yaw: (f64, f64),
    i_acc: (f64, f64),
}

impl<'a> Correlator<'a> {
    fn new(track: &'a ImuTrack, iv: &'a [Interval]) -> Self {
        let g_yaw = moments(iv.iter().filter_map(|k| k.yaw));
        let g_acc = moments(iv.iter().map(|k| k.accel));
        let mut d: Vec<f64> = iv.iter().map(|k| k.b_s - k.a_s).collect();
        d.sort_by(f64::total_cmp);
        let tile = d.get(d.len() / 2).copied().unwrap_or(1.0);
        let tiles: Vec<(f64, f64)> = (0..)
            .map(|m| track.t0_s + m as f64 * tile)
            .take_while(|a| a + tile <= track.end_s())
            .filter_map(|a| track.mean(a, a + tile))
            .map(|(y, f, _)| (y, f))
            .collect();
        let i_yaw = moments(tiles.iter().map(|t| t.0));
        let i_acc = moments(tiles.iter().map(|t| t.1));
        Correlator {
            track,
            iv,
            g_yaw,
            g_acc,
            i_yaw,
            i_acc,
        }
    }

    /// (combined, yaw, accel) Pearson correlation over the intervals the
    /// IMU covers at offset `c`: the fine search's measure (normalised by
    /// the overlap's own means and energies, the peak is not pulled by the
    /// parts of the log outside it).
    fn pearson(&self, c: f64) -> (f64, f64, f64) {
        // Weighted sums: w, wx, wy, wxx, wyy, wxy per signal.
        let (mut ys, mut as_) = ([0.0; 6], [0.0; 6]);
        let add = |acc: &mut [f64; 6], w: f64, x: f64, y: f64| {
            for (a, v) in acc
                .iter_mut()
                .zip([w, w * x, w * y, w * x * x, w * y * y, w * x * y])
            {
                *a += v;
            }
        };
        for k in self.iv {
            let Some((iy, ia, w)) = self.track.mean(k.a_s - c, k.b_s - c) else {
                continue;
            };
            if let Some(gy) = k.yaw {
                add(&mut ys, w, gy, iy);
            }
            add(&mut as_, w, k.accel, ia);
        }
        let r = |a: &[f64; 6]| {
            if a[0] <= 0.0 {
                return 0.0;
            }
            let sxx = a[3] - a[1] * a[1] / a[0];
            let syy = a[4] - a[2] * a[2] / a[0];
            let sxy = a[5] - a[1] * a[2] / a[0];
            let e = (sxx * syy).sqrt();
            if e > 0.0 { sxy / e } else { 0.0 }
        };
        let (ry, ra) = (r(&ys), r(&as_));
        (0.5 * (ry + ra), ry, ra)
    }

    /// (combined, yaw, accel) correlation at offset `c` (GPS = IMU + c),
    /// normalised by the whole signals' energies: the coarse search's
    /// measure (a lag that overlaps part of the drive scores less).
    fn corr(&self, c: f64) -> (f64, f64, f64) {
        let (mut sy, mut sa) = (0.0, 0.0);
        for k in self.iv {
            let Some((iy, ia, w)) = self.track.mean(k.a_s - c, k.b_s - c) else {
                continue;
            };
            if let Some(gy) = k.yaw {
                sy += w * (gy - self.g_yaw.0) * (iy - self.i_yaw.0);
            }
            sa += w * (k.accel - self.g_acc.0) * (ia - self.i_acc.0);
        }
        let norm = |s: f64, g: (f64, f64), i: (f64, f64)| {
            let e = (g.1 * i.1).sqrt();
            if e > 0.0 { s / e } else { 0.0 }
        };
        let ry = norm(sy, self.g_yaw, self.i_yaw);
        let ra = norm(sa, self.g_acc, self.i_acc);
        (0.5 * (ry + ra), ry, ra)
    }
}

/// Finds GPS time − IMU time from the motion (module docs). `imu` and
/// `fixes` in time order, each on its own clock.
pub fn search_clock_offset(
    imu: &[ImuSample],
    fixes: &[GnssFix],
    o: &ClockSearchOptions,
) -> Result<ClockOffset, ClockSearchError> {
    let track = ImuTrack::new(imu)?;
    let iv = gnss_intervals(fixes, o.min_speed_mps);
    if iv.len() < 10 {
        return Err(ClockSearchError::TooLittle(format!(
            "{} usable GNSS intervals (at least 10 needed)",
            iv.len()
        )));
    }
    let yaw_intervals = iv.iter().filter(|k| k.yaw.is_some()).count();
    let turn = o.turn_rate_deg_s.to_radians();
    let turn_intervals = iv
        .iter()
        .filter(|k| k.yaw.is_some_and(|y| y.abs() >= turn))
        .count();
    if turn_intervals < o.min_turn_intervals {
        return Err(ClockSearchError::NoTurns {
            turns: turn_intervals,
            intervals: yaw_intervals,
            min_speed_mps: o.min_speed_mps,
            rate_deg_s: o.turn_rate_deg_s,
            needed: o.min_turn_intervals,
        });
    }
    let cor = Correlator::new(&track, &iv);
    let (g0, g1) = (iv[0].a_s, iv[iv.len() - 1].b_s);
    let overlap = o
        .min_overlap_s
        .min(0.5 * (g1 - g0))
        .min(0.5 * (track.end_s() - track.t0_s));
    let (lo, hi) = (g0 - track.end_s() + overlap, g1 - track.t0_s - overlap);
    if hi.is_nan() || lo.is_nan() || hi < lo {
        return Err(ClockSearchError::TooLittle(
            "the IMU and GNSS spans are too short to overlap".into(),
        ));
    }
    // Coarse: every lag on the grid over the whole range.
    let n = ((hi - lo) / o.coarse_step_s).floor() as usize + 1;
    let coarse: Vec<f64> = (0..n)
        .map(|m| cor.corr(lo + m as f64 * o.coarse_step_s).0)
        .collect();
    let best = (0..n)
        .max_by(|&a, &b| coarse[a].total_cmp(&coarse[b]))
        .unwrap_or(0);
    let (second, second_ix) = second_peak(&coarse, best);
    // Fine: 10 ms steps around the coarse peak, then a parabola.
    let c0 = lo + best as f64 * o.coarse_step_s;
    let m = (o.fine_half_width_s / o.fine_step_s).round() as i64;
    let fine: Vec<(f64, f64)> = (-m..=m)
        .map(|k| {
            let c = c0 + k as f64 * o.fine_step_s;
            (c, cor.pearson(c).0)
        })
        .collect();
    let fb = (0..fine.len())
        .max_by(|&a, &b| fine[a].1.total_cmp(&fine[b].1))
        .unwrap_or(0);
    let mut offset_s = fine[fb].0;
    if fb > 0 && fb + 1 < fine.len() {
        let (ym, y0, yp) = (fine[fb - 1].1, fine[fb].1, fine[fb + 1].1);
        let den = ym - 2.0 * y0 + yp;
        if den < 0.0 {
            offset_s += 0.5 * o.fine_step_s * (ym - yp) / den;
        }
    }
    let (peak_corr, yaw_corr, accel_corr) = cor.pearson(offset_s);
    // Curvature over ±0.1 s; σ² = (1 − ρ²) / (N ρ |ρ''|), the delay
    // estimator's variance for a least-squares fit of one signal to the
    // other (N independent samples; Knapp & Carter 1976).
    let h = 0.1;
    let d2 =
        (cor.pearson(offset_s + h).0 - 2.0 * peak_corr + cor.pearson(offset_s - h).0) / (h * h);
    let n_eff = iv.len() as f64;
    let sd_s = if d2 < 0.0 && peak_corr > 0.0 {
        ((1.0 - peak_corr * peak_corr).max(0.0) / (n_eff * peak_corr * -d2))
            .sqrt()
            .max(o.fine_step_s / 12f64.sqrt())
    } else {
        f64::INFINITY
    };
    let width_s = half_width_coarse(&coarse, best, coarse[best]) * o.coarse_step_s;
    let result = ClockOffset {
        offset_s,
        sd_s,
        peak_corr,
        yaw_corr,
        accel_corr,
        width_s,
        whole_corr: coarse[best],
        second_peak_ratio: if coarse[best] > 0.0 {
            second / coarse[best]
        } else {
            1.0
        },
        second_offset_s: lo + second_ix as f64 * o.coarse_step_s,
        yaw_intervals,
        turn_intervals,
        range_s: [lo, hi],
    };
    check(result, o)
}

fn check(r: ClockOffset, o: &ClockSearchOptions) -> Result<ClockOffset, ClockSearchError> {
    if r.whole_corr.is_nan() || r.whole_corr < o.min_peak_corr {
        return Err(ClockSearchError::Flat {
            peak: r.whole_corr,
            offset_s: r.offset_s,
            min: o.min_peak_corr,
            detail: format!(
                " (yaw rate {:.2}, specific force {:.2})",
                r.yaw_corr, r.accel_corr
            ),
        });
    }
    if r.second_peak_ratio > o.max_second_ratio {
        return Err(ClockSearchError::Ambiguous {
            offset_s: r.offset_s,
            second_s: r.second_offset_s,
            peak: r.peak_corr,
            ratio: r.second_peak_ratio,
            max: o.max_second_ratio,
        });
    }
    if r.sd_s.is_nan() || r.sd_s > o.max_sd_s {
        return Err(ClockSearchError::Imprecise {
            offset_s: r.offset_s,
            sd_s: r.sd_s,
            max: o.max_sd_s,
            width_s: r.width_s,
        });
    }
    Ok(r)
}

/// The highest value outside the main lobe around `best` (the lobe ends at
/// the first local minimum below half the peak on each side) and its index.
fn second_peak(v: &[f64], best: usize) -> (f64, usize) {
    let half = 0.5 * v[best];
    let mut l = best;
    while l > 0 && (v[l - 1] <= v[l] || v[l] > half) {
        l -= 1;
    }
    let mut r = best;
    while r + 1 < v.len() && (v[r + 1] <= v[r] || v[r] > half) {
        r += 1;
    }
    v.iter()
        .enumerate()
        .filter(|&(i, _)| i < l || i > r)
        .map(|(i, &x)| (x, i))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or((0.0, best))
}

/// Full width at half `peak` of a uniform curve around index `b`, in
/// steps (the curve's ends when not reached).
fn half_width_coarse(v: &[f64], b: usize, peak: f64) -> f64 {
    let half = 0.5 * peak;
    let l = (0..b).rev().find(|&i| v[i] < half).unwrap_or(0);
    let r = (b + 1..v.len())
        .find(|&i| v[i] < half)
        .unwrap_or(v.len() - 1);
    (r - l) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::earth::Geodetic;
    use crate::testutil::rng;
    use crate::time::GpsTime;

    /// A level drive from a yaw-rate profile (rad/s) and a speed profile
    /// (m/s): a 100 Hz IMU (FRD, level; white noise of `noise` × typical
    /// MEMS figures) stamped on GPS time − `offset_s`, and 1 Hz GNSS fixes
    /// (positions; velocities too when `with_vel`) on GPS time.
    fn drive(
        duration_s: f64,
        yaw_rate: impl Fn(f64) -> f64,
        speed: impl Fn(f64) -> f64,
        offset_s: f64,
        with_vel: bool,
        seed: u64,
    ) -> (Vec<ImuSample>, Vec<GnssFix>) {
        let mut r = rng::stream(seed, "clock-search");
        let t0 = 200_000.0;
        let dt = 0.01;
        let (mut psi, mut n, mut e) = (0.3, 0.0, 0.0);
        let origin = Geodetic::from_deg(30.0, 114.0, 20.0);
        let (mut imu, mut fixes) = (Vec::new(), Vec::new());
        let steps = (duration_s / dt).round() as usize;
        for k in 1..=steps {
            let (ta, tb) = ((k - 1) as f64 * dt, k as f64 * dt);
            let tm = 0.5 * (ta + tb);
            let (w, v) = (yaw_rate(tm), speed(tm));
            let vdot = (speed(tb) - speed(ta)) / dt;
            psi += w * dt;
            n += v * psi.cos() * dt;
            e += v * psi.sin() * dt;
            let gyro = Vector3::new(0.0, 0.0, w)
                + Vector3::new(
                    rng::normal(&mut r),
                    rng::normal(&mut r),
                    rng::normal(&mut r),
                ) * 0.003;
            let f = Vector3::new(vdot, v * w, -9.8)
                + Vector3::new(
                    rng::normal(&mut r),
                    rng::normal(&mut r),
                    rng::normal(&mut r),
                ) * 0.05;
            imu.push(ImuSample {
                time: GpsTime::from_seconds(t0 + tb - offset_s),
                dtheta: gyro * dt,
                dvel: f * dt,
                odo_speed: None,
            });
            if k % 100 == 0 {
                let pos = Geodetic::new(
                    origin.lat_rad + (n + 0.02 * rng::normal(&mut r)) / 6_378_137.0,
                    origin.lon_rad
                        + (e + 0.02 * rng::normal(&mut r)) / (6_378_137.0 * origin.lat_rad.cos()),
                    origin.h_m,
                );
                fixes.push(GnssFix {
                    time: GpsTime::from_seconds(t0 + tb),
                    pos,
                    pos_sd: Vector3::repeat(0.02),
                    vel: with_vel.then(|| Vector3::new(v * psi.cos(), v * psi.sin(), 0.0)),
                    vel_sd: None,
                });
            }
        }
        (imu, fixes)
    }

    /// A raised-cosine bump of `peak` over [t0, t0 + len].
    fn bump(t: f64, t0: f64, len: f64, peak: f64) -> f64 {
        if t < t0 || t > t0 + len {
            0.0
        } else {
            0.5 * peak * (1.0 - (std::f64::consts::TAU * (t - t0) / len).cos())
        }
    }

    /// Irregular turns, both ways, and a stop in the middle.
    fn turns(t: f64) -> f64 {
        let d = 0.35;
        bump(t, 15.0, 8.0, d)
            + bump(t, 40.0, 5.0, -0.5)
            + bump(t, 61.0, 12.0, 0.25)
            + bump(t, 95.0, 6.0, -0.3)
            + bump(t, 130.0, 9.0, 0.4)
            + bump(t, 151.0, 4.0, -0.45)
    }

    fn speed(t: f64) -> f64 {
        // Starts at 8 m/s, a slow-down around 110 s.
        8.0 + 3.0 * (t / 37.0).sin() - bump(t, 105.0, 12.0, 6.0)
    }

    #[test]
    fn known_offsets_are_recovered_within_10_ms() {
        for (offset_s, with_vel, seed) in [
            (3.0, true, 1),
            (3600.237, false, 2),
            (-216_000.5, false, 3),
            (0.0, true, 4),
        ] {
            let (imu, fixes) = drive(180.0, turns, speed, offset_s, with_vel, seed);
            let r = search_clock_offset(&imu, &fixes, &ClockSearchOptions::default())
                .unwrap_or_else(|e| panic!("offset {offset_s}: {e}"));
            let err = r.offset_s - offset_s;
            assert!(err.abs() < 0.010, "offset {offset_s}: {r:?}");
            // The stated σ covers the error and is not absurdly loose.
            assert!(err.abs() < 3.0 * r.sd_s + 0.002 && r.sd_s < 0.02, "{r:?}");
            assert!(r.peak_corr > 0.8 && r.second_peak_ratio < 0.6, "{r:?}");
        }
    }

    #[test]
    fn a_straight_road_is_refused() {
        let (imu, fixes) = drive(150.0, |_| 0.0, speed, 42.0, false, 5);
        let e = search_clock_offset(&imu, &fixes, &ClockSearchOptions::default()).unwrap_err();
        assert!(
            matches!(e, ClockSearchError::NoTurns { turns: 0, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("no turns"), "{e}");
    }

    #[test]
    fn identical_repeated_turns_are_ambiguous() {
        // The same turn every 20 s: any whole number of periods fits
        // nearly as well.
        let periodic = |t: f64| bump(t % 20.0, 5.0, 6.0, 0.4);
        let (imu, fixes) = drive(200.0, periodic, |_| 10.0, 7.0, true, 6);
        let e = search_clock_offset(&imu, &fixes, &ClockSearchOptions::default()).unwrap_err();
        assert!(matches!(e, ClockSearchError::Ambiguous { .. }), "{e}");
    }

    #[test]
    fn another_drives_imu_is_refused() {
        let (imu, _) = drive(180.0, turns, speed, 0.0, true, 7);
        let other = |t: f64| bump(t, 20.0, 30.0, 0.05) - bump(t, 100.0, 30.0, 0.05);
        let (_, fixes) = drive(180.0, other, |_| 10.0, 0.0, true, 8);
        let o = ClockSearchOptions {
            turn_rate_deg_s: 1.0,
            ..ClockSearchOptions::default()
        };
        let e = search_clock_offset(&imu, &fixes, &o).unwrap_err();
        assert!(
            matches!(
                e,
                ClockSearchError::Flat { .. } | ClockSearchError::Ambiguous { .. }
            ),
            "{e}"
        );
    }

    #[test]
    fn accelerations_not_in_m_per_s2_are_named() {
        let (mut imu, fixes) = drive(60.0, turns, speed, 0.0, true, 9);
        for s in &mut imu {
            s.dvel /= 9.8; // in g
        }
        let e = search_clock_offset(&imu, &fixes, &ClockSearchOptions::default()).unwrap_err();
        assert!(matches!(e, ClockSearchError::NotGravity(_)), "{e}");
    }
}
