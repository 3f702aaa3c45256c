//! Software synchronization (seed 001 §2.2): no 1PPS, only the host's
//! receive times. Two lower envelopes (TICSync: one-way delays are only
//! ever positive, so the clock relation is the lower support of the
//! receive times, not their mean):
//!
//! * IMU: samples are periodic in the IMU's own clock, so receive time
//!   vs sample index `h_k = E_i(k) + μ_k`, `μ_k ≥ 0`, gives the host time
//!   of each sample up to the fastest IMU latency;
//! * GNSS: receive time vs validity time `g_m = E_g(T_m) + λ_m`,
//!   `λ_m ≥ 0`, maps host time to GPS time up to the fastest GNSS latency.
//!
//! A sample's GPS time is `E_g⁻¹(E_i(k) − T_c − μ_min + λ_min)`. The two
//! fastest latencies `μ_min`, `λ_min` are what synchronization alone
//! cannot observe: they are configured (default 0) and their error is a
//! constant offset of every stamp, reported as such.
//!
//! Receiver time marks (`mark` records: an edge latched on the host clock
//! and time-marked by the receiver, u-blox TIM-TM2) have no latency: when
//! the log has them, a least-squares fit of GPS time against host time
//! over the same window replaces the GNSS envelope, and `λ_min` drops out.

use std::collections::VecDeque;

use super::fit::EnvelopeFit;
use crate::time::{GpsTime, NS_PER_S};

/// Settings of software synchronization.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SwConfig {
    /// Window of the IMU envelope (s).
    pub imu_window_s: f64,
    /// Window of the host→GPS envelope (s).
    pub gnss_window_s: f64,
    /// Assumed latency of the fastest GNSS message (s).
    pub gnss_min_latency_s: f64,
    /// Assumed latency of the fastest IMU frame (s), beyond T_c.
    pub imu_min_latency_s: f64,
}

impl Default for SwConfig {
    fn default() -> Self {
        SwConfig {
            imu_window_s: 10.0,
            gnss_window_s: 600.0,
            gnss_min_latency_s: 0.0,
            imu_min_latency_s: 0.0,
        }
    }
}

const GNSS_BLOCK_S: f64 = 10.0;
const IMU_BLOCK_S: f64 = 1.0;

/// The host-time window of a fit: `window_s` centred on block `block` (of
/// `block_s`), or ending at `h` in causal mode.
fn window(block: i64, block_s: f64, window_s: f64, h: f64, causal: bool) -> (f64, f64) {
    if causal {
        (h - window_s, h)
    } else {
        let mid = (block as f64 + 0.5) * block_s;
        (mid - 0.5 * window_s, mid + 0.5 * window_s)
    }
}

/// `T` with `fit(T) = h` (Newton from the tangent line at 0).
fn invert(fit: &EnvelopeFit, h: f64) -> Option<f64> {
    let s = fit.slope(0.0);
    if s.abs() < 1e-6 {
        return None;
    }
    let mut t = (h - fit.eval(0.0)) / s;
    for _ in 0..4 {
        let d = fit.slope(t);
        if d.abs() < 1e-6 {
            break;
        }
        t -= (fit.eval(t) - h) / d;
    }
    Some(t)
}

/// A least-squares polynomial y = Σ c_i (x − x0)^i of degree ≤ 2.
#[derive(Copy, Clone, Debug)]
struct LsMap {
    x0: f64,
    coef: [f64; 3],
    n: usize,
}

impl LsMap {
    /// Fits `pts` (x, y) by least squares (normal equations about the mean
    /// of x, which keeps them well conditioned).
    fn fit(pts: &[(f64, f64)], deg: usize) -> Option<LsMap> {
        let n = pts.len();
        if n < deg + 1 {
            return None;
        }
        let x0 = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
        let k = deg + 1;
        let mut a = nalgebra::DMatrix::<f64>::zeros(k, k);
        let mut b = nalgebra::DVector::<f64>::zeros(k);
        for &(x, y) in pts {
            let u = x - x0;
            let pw = [1.0, u, u * u];
            for i in 0..k {
                b[i] += pw[i] * y;
                for j in 0..k {
                    a[(i, j)] += pw[i] * pw[j];
                }
            }
        }
        let c = a.lu().solve(&b)?;
        let mut coef = [0.0; 3];
        coef[..k].copy_from_slice(c.as_slice());
        coef.iter()
            .all(|v| v.is_finite())
            .then_some(LsMap { x0, coef, n })
    }

    fn eval(&self, x: f64) -> f64 {
        let u = x - self.x0;
        self.coef[0] + u * (self.coef[1] + u * self.coef[2])
    }

    fn slope(&self, x: f64) -> f64 {
        self.coef[1] + 2.0 * self.coef[2] * (x - self.x0)
    }
}

/// Host→GPS envelope over a window, cached per block.
#[derive(Clone, Debug)]
struct GnssMap {
    block: i64,
    fit: EnvelopeFit,
}

/// IMU index→host envelope, cached per block.
#[derive(Clone, Debug)]
struct ImuMap {
    block: i64,
    fit: EnvelopeFit,
}

/// The software clock: envelopes of IMU and GNSS receive times.
#[derive(Clone, Debug)]
pub(crate) struct SwClock {
    pub cfg: SwConfig,
    /// Host seconds of counter 0 reference.
    c0: Option<u64>,
    hz: f64,
    /// GPS second used as origin of validity times.
    t0: Option<i64>,
    /// (T_rel, h) of GNSS messages.
    gnss: VecDeque<(f64, f64)>,
    /// (k, h) of IMU samples.
    imu: VecDeque<(f64, f64)>,
    gnss_maps: Vec<GnssMap>,
    imu_maps: Vec<ImuMap>,
    /// (T_rel, h) of receiver time marks.
    marks: VecDeque<(f64, f64)>,
    mark_maps: Vec<(i64, LsMap)>,
    /// Index of the latest IMU sample and its receive time.
    last_k: Option<i64>,
    /// Latest envelope for loss detection: (k_ref, h_ref, period).
    live: Option<(f64, f64, f64)>,
    recent_lat: VecDeque<f64>,
    pub(crate) last_imu_fit_excess: f64,
    pub(crate) last_gnss_fit_excess: f64,
    pub(crate) gnss_fit_points: usize,
    pub(crate) imu_fit_points: usize,
    pub(crate) host_ppm: Option<f64>,
    now_h: f64,
}

impl SwClock {
    pub(crate) fn new(cfg: SwConfig, counter_hz: f64) -> Self {
        SwClock {
            cfg,
            c0: None,
            hz: counter_hz,
            t0: None,
            gnss: VecDeque::new(),
            imu: VecDeque::new(),
            gnss_maps: Vec::new(),
            imu_maps: Vec::new(),
            marks: VecDeque::new(),
            mark_maps: Vec::new(),
            last_k: None,
            live: None,
            recent_lat: VecDeque::new(),
            last_imu_fit_excess: f64::NAN,
            last_gnss_fit_excess: f64::NAN,
            gnss_fit_points: 0,
            imu_fit_points: 0,
            host_ppm: None,
            now_h: f64::NEG_INFINITY,
        }
    }

    /// Host seconds of an unwrapped counter.
    pub(crate) fn host(&mut self, c: u64) -> f64 {
        let c0 = *self.c0.get_or_insert(c);
        super::clock::tick_diff(c0, c) / self.hz
    }

    /// Latest host time seen.
    pub(crate) fn now(&self) -> f64 {
        self.now_h
    }

    pub(crate) fn advance(&mut self, h: f64) {
        self.now_h = self.now_h.max(h);
    }

    /// A GNSS message valid at `valid`, received at host `h`.
    pub(crate) fn push_gnss(&mut self, h: f64, valid: GpsTime) {
        let t0 = *self.t0.get_or_insert(valid.ns().div_euclid(NS_PER_S));
        let t = (valid.ns() - t0 * NS_PER_S) as f64 * 1e-9;
        if self.gnss.back().is_some_and(|&(tb, _)| t <= tb) {
            return; // repeated or out-of-order validity: ignored
        }
        self.gnss.push_back((t, h));
        self.advance(h);
    }

    /// A receiver time mark: an edge at host `h` that the receiver
    /// time-marked at GPS time `time`.
    pub(crate) fn push_mark(&mut self, h: f64, time: GpsTime) {
        let t0 = *self.t0.get_or_insert(time.ns().div_euclid(NS_PER_S));
        let t = (time.ns() - t0 * NS_PER_S) as f64 * 1e-9;
        if self.marks.back().is_some_and(|&(tb, _)| t <= tb) {
            return; // repeated or out-of-order: ignored
        }
        self.marks.push_back((t, h));
        self.advance(h);
    }

    /// True when the time marks, not the GNSS envelope, map host time.
    pub(crate) fn uses_marks(&self) -> bool {
        self.marks.len() >= 2
    }

    /// The host→GPS map of block `block` from the time marks: GPS time as
    /// a least-squares polynomial of host time over the window (degree 2
    /// over ≥ 120 s and ≥ 30 marks, as the envelope).
    fn mark_block(&mut self, block: i64, h: f64, causal: bool) -> Option<LsMap> {
        if let Some((_, m)) = self.mark_maps.iter().find(|(b, _)| *b == block)
            && !(causal && m.n < 30)
        {
            return Some(*m);
        }
        let (lo, hi) = window(block, GNSS_BLOCK_S, self.cfg.gnss_window_s, h, causal);
        let mut pts: Vec<(f64, f64)> = self
            .marks
            .iter()
            .filter(|&&(_, hm)| hm >= lo && hm <= hi)
            .map(|&(t, hm)| (hm, t))
            .collect();
        if pts.len() < 2 {
            pts = self.marks.iter().map(|&(t, hm)| (hm, t)).collect();
        }
        let span = pts.last()?.0 - pts.first()?.0;
        let deg = if pts.len() >= 30 && span >= 120.0 {
            2
        } else {
            1
        };
        let map = LsMap::fit(&pts, deg)?;
        self.host_ppm = Some((1.0 / map.slope(pts[pts.len() / 2].0) - 1.0) * 1e6);
        self.mark_maps
            .retain(|(b, _)| *b != block && (b - block).abs() <= 2);
        self.mark_maps.push((block, map));
        Some(map)
    }

    /// An IMU sample received at host `h`, after `known_lost` samples the
    /// reader knows were lost (corrupted lines); returns (index, lost
    /// before).
    pub(crate) fn push_imu(&mut self, h: f64, known_lost: u32) -> (i64, u32) {
        self.advance(h);
        let k = match (self.last_k, self.live) {
            (None, _) => 0,
            (Some(prev), None) => prev + 1 + known_lost as i64,
            (Some(prev), Some((kr, hr, p))) => {
                let next = prev + 1 + known_lost as i64;
                let lat1 = h - (hr + (next as f64 - kr) * p);
                let mut lats: Vec<f64> = self.recent_lat.iter().copied().collect();
                let hi = lats.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                if lats.len() >= 50 && lat1 > hi + 0.5 * p {
                    let med = super::fit::median(&mut lats);
                    next + ((lat1 - med) / p).round().max(1.0) as i64
                } else {
                    next
                }
            }
        };
        let lost = self.last_k.map(|p| (k - p - 1).max(0) as u32).unwrap_or(0);
        self.last_k = Some(k);
        self.imu.push_back((k as f64, h));
        if let Some((kr, hr, p)) = self.live {
            self.recent_lat.push_back(h - (hr + (k as f64 - kr) * p));
            if self.recent_lat.len() > 400 {
                self.recent_lat.pop_front();
            }
        }
        // Refit the live envelope about once a second (causal).
        if k % 200 == 0 || self.live.is_none() && self.imu.len() >= 20 {
            self.refit_live();
        }
        (k, lost)
    }

    fn refit_live(&mut self) {
        let Some(&(_, h_last)) = self.imu.back() else {
            return;
        };
        let pts: Vec<(f64, f64)> = self
            .imu
            .iter()
            .rev()
            .take_while(|&&(_, h)| h_last - h <= self.cfg.imu_window_s)
            .copied()
            .collect();
        if pts.len() < 10 {
            return;
        }
        if let Some(f) = EnvelopeFit::fit(&pts, 1) {
            let kr = pts[0].0;
            self.live = Some((kr, f.eval(kr), f.slope(kr)));
            self.recent_lat.clear();
        }
    }

    /// Drops stored points that no stamp at or after host `h` needs.
    pub(crate) fn prune(&mut self, h: f64) {
        let keep_i = self.cfg.imu_window_s;
        let keep_g = self.cfg.gnss_window_s;
        while self
            .imu
            .front()
            .is_some_and(|&(_, hi)| h - hi > keep_i + 2.0)
        {
            self.imu.pop_front();
        }
        // GNSS points and marks are pruned by their host time.
        while self
            .gnss
            .front()
            .is_some_and(|&(_, hg)| h - hg > keep_g + 10.0)
        {
            self.gnss.pop_front();
        }
        while self
            .marks
            .front()
            .is_some_and(|&(_, hm)| h - hm > keep_g + 10.0)
        {
            self.marks.pop_front();
        }
    }

    /// True when the window after host `h` is complete (non-causal).
    pub(crate) fn ready(&self, h: f64) -> bool {
        self.now_h - h >= 0.5 * self.cfg.gnss_window_s + 2.0
    }

    /// True when a GNSS latency envelope can be made.
    pub(crate) fn has_gnss(&self) -> bool {
        self.gnss.len() >= 3
    }

    /// True when a host→GPS map can be made (from GNSS or time marks).
    pub(crate) fn has_map(&self) -> bool {
        self.has_gnss() || self.uses_marks()
    }

    /// The host→GPS envelope of block `block` (10 s blocks of host time):
    /// fitted over the window centred on the block, or ending at `h` in
    /// causal mode.
    fn gnss_block(&mut self, block: i64, h: f64, causal: bool) -> Option<EnvelopeFit> {
        if let Some(m) = self.gnss_maps.iter().find(|m| m.block == block)
            && !(causal && m.fit.n < 30)
        {
            return Some(m.fit.clone());
        }
        let (lo, hi) = window(block, GNSS_BLOCK_S, self.cfg.gnss_window_s, h, causal);
        let mut pts: Vec<(f64, f64)> = self
            .gnss
            .iter()
            .filter(|&&(_, hg)| hg >= lo && hg <= hi)
            .copied()
            .collect();
        if pts.len() < 3 {
            // Not enough in the window: use everything there is.
            pts = self.gnss.iter().copied().collect();
        }
        let span = pts.last()?.0 - pts.first()?.0;
        let deg = if pts.len() >= 30 && span >= 120.0 {
            2
        } else {
            1
        };
        let fit = EnvelopeFit::fit(&pts, deg)?;
        self.last_gnss_fit_excess = fit.mean_excess;
        self.gnss_fit_points = pts.len();
        self.host_ppm = Some((fit.slope(pts[pts.len() / 2].0) - 1.0) * 1e6);
        self.gnss_maps
            .retain(|m| m.block != block && (m.block - block).abs() <= 2);
        self.gnss_maps.push(GnssMap {
            block,
            fit: fit.clone(),
        });
        Some(fit)
    }

    /// The IMU envelope of block `block` (1 s blocks of host time).
    fn imu_block(&mut self, block: i64, h: f64, causal: bool) -> Option<EnvelopeFit> {
        if let Some(m) = self.imu_maps.iter().find(|m| m.block == block)
            && !(causal && m.fit.n < 100)
        {
            return Some(m.fit.clone());
        }
        let (lo, hi) = window(block, IMU_BLOCK_S, self.cfg.imu_window_s, h, causal);
        let pts: Vec<(f64, f64)> = self
            .imu
            .iter()
            .filter(|&&(_, hi_)| hi_ >= lo && hi_ <= hi)
            .copied()
            .collect();
        let fit = EnvelopeFit::fit(&pts, 1)?;
        self.last_imu_fit_excess = fit.mean_excess;
        self.imu_fit_points = pts.len();
        self.imu_maps
            .retain(|m| m.block != block && (m.block - block).abs() <= 2);
        self.imu_maps.push(ImuMap {
            block,
            fit: fit.clone(),
        });
        Some(fit)
    }

    /// Blending weights: post-processing values are interpolated between
    /// the fits of the two nearest blocks, so stamps stay continuous.
    fn blend(x: f64, block_len: f64, causal: bool) -> (i64, i64, f64) {
        if causal {
            // Causal fits end at the sample: refit every second.
            let b = x.floor() as i64;
            return (b, b, 0.0);
        }
        let u = x / block_len - 0.5;
        let b0 = u.floor();
        (b0 as i64, b0 as i64 + 1, u - b0)
    }

    /// GPS time of IMU sample `k` received at host `h`; `output_delay_s`
    /// is the IMU's known output delay T_c (seed 000).
    pub(crate) fn imu_time(
        &mut self,
        k: i64,
        h: f64,
        output_delay_s: f64,
        causal: bool,
    ) -> Option<GpsTime> {
        let (b0, b1, w) = Self::blend(h, IMU_BLOCK_S, causal);
        let e0 = self.imu_block(b0, h, causal)?.eval(k as f64);
        let he = if w > 0.0 {
            let e1 = self.imu_block(b1, h, causal)?.eval(k as f64);
            e0 + w * (e1 - e0)
        } else {
            e0
        };
        let host_sample =
            he - output_delay_s - self.cfg.imu_min_latency_s + self.cfg.gnss_min_latency_s;
        self.host_to_gps(host_sample, causal)
    }

    /// GPS time of host time `h`.
    pub(crate) fn host_to_gps(&mut self, h: f64, causal: bool) -> Option<GpsTime> {
        let t0 = self.t0?;
        let (b0, b1, w) = Self::blend(h, GNSS_BLOCK_S, causal);
        let t = if self.uses_marks() {
            let mut t = self.mark_block(b0, h, causal)?.eval(h);
            if w > 0.0 {
                let t1 = self.mark_block(b1, h, causal)?.eval(h);
                t += w * (t1 - t);
            }
            t
        } else {
            let f0 = self.gnss_block(b0, h, causal)?;
            let mut t = invert(&f0, h)?;
            if w > 0.0 {
                let f1 = self.gnss_block(b1, h, causal)?;
                let t1 = invert(&f1, h)?;
                t += w * (t1 - t);
            }
            t
        };
        let whole = t.floor();
        Some(GpsTime::from_ns(
            (t0 + whole as i64) * NS_PER_S + ((t - whole) * 1e9).round() as i64,
        ))
    }

    /// Latency of a GNSS message valid at `valid` received at host `h`:
    /// its excess over the envelope plus the assumed fastest latency.
    pub(crate) fn gnss_latency(&mut self, h: f64, valid: GpsTime, causal: bool) -> Option<f64> {
        let t0 = self.t0?;
        let t = (valid.ns() - t0 * NS_PER_S) as f64 * 1e-9;
        let lam_min = self.cfg.gnss_min_latency_s;
        let (b0, b1, w) = Self::blend(h, GNSS_BLOCK_S, causal);
        let mut e = self.gnss_block(b0, h, causal)?.eval(t);
        if w > 0.0 {
            let e1 = self.gnss_block(b1, h, causal)?.eval(t);
            e += w * (e1 - e);
        }
        Some(h - e + lam_min)
    }
}
