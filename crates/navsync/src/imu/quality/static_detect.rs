//! Static segments of an IMU log, detected automatically (quiet windows
//! against the quietest seen), for their Allan deviation.

use super::*;

/// Per-window statistics of the static detector.
#[derive(Clone, Copy, Debug)]
pub(super) struct WindowStat {
    pub(super) std: [f64; 6],
    /// Index of the window's first sample in the candidate buffer (base
    /// rate) and its length.
    pub(super) start: usize,
    pub(super) len: usize,
    pub(super) first_line: usize,
    pub(super) start_ns: i64,
}

/// Static-segment detector (see [`QualityAnalyzer`]).
#[derive(Clone, Debug)]
pub(super) struct StaticDetector {
    pub(super) win_n: usize,
    pub(super) n: usize,
    pub(super) sum: [f64; 6],
    pub(super) win_first_line: usize,
    pub(super) win_start_ns: i64,
    pub(super) win_buf: Vec<[f64; 6]>,
    pub(super) floor: [f64; 6],
    pub(super) prev_mean: Option<([f64; 6], [f64; 6])>,
    pub(super) cand_windows: Vec<WindowStat>,
    pub(super) cand: Vec<[f64; 6]>,
    pub(super) cand_decim: usize,
    pub(super) best: Option<(StaticSegment, Vec<[f64; 6]>, usize)>,
    pub(super) segments: Vec<StaticSegment>,
    pub(super) min_len: usize,
    pub(super) dt_s: f64,
}

/// Most samples kept for one static segment; beyond, pairs are averaged
/// (τ0 doubles; the Allan curve keeps its long-τ part).
pub(super) const STATIC_CAP: usize = 1 << 21;
/// A window is quiet when every channel's σ is within this factor of the
/// quietest window seen.
pub(super) const QUIET_FACTOR: f64 = 2.5;
/// Absolute ceilings for "static" (a car at rest vibrates less; any
/// navigation IMU is quieter): rad/s and m/s².
pub(super) const STATIC_GYRO_SD: f64 = 0.01;
pub(super) const STATIC_ACCEL_SD: f64 = 0.1;

impl StaticDetector {
    pub(super) fn new(win_n: usize, min_len: usize, dt_s: f64) -> Self {
        StaticDetector {
            win_n: win_n.max(8),
            n: 0,
            sum: [0.0; 6],
            win_first_line: 0,
            win_start_ns: 0,
            win_buf: Vec::new(),
            floor: [f64::INFINITY; 6],
            prev_mean: None,
            cand_windows: Vec::new(),
            cand: Vec::new(),
            cand_decim: 1,
            best: None,
            segments: Vec::new(),
            min_len: min_len.max(1),
            dt_s,
        }
    }

    /// A gap breaks the window and the candidate.
    pub(super) fn gap(&mut self) {
        self.n = 0;
        self.sum = [0.0; 6];
        self.win_buf.clear();
        self.prev_mean = None;
        self.finalize();
    }

    pub(super) fn push(&mut self, r: &[f64; 6], line: usize, t_ns: i64, q: &[f64; 6]) {
        if self.n == 0 {
            self.win_first_line = line;
            self.win_start_ns = t_ns;
        }
        self.n += 1;
        for c in 0..6 {
            self.sum[c] += r[c];
        }
        self.win_buf.push(*r);
        if self.n < self.win_n {
            return;
        }
        let n = self.n as f64;
        let mut mean = [0.0; 6];
        let mut std = [0.0; 6];
        for c in 0..6 {
            mean[c] = self.sum[c] / n;
            // Per-window values are centred by subtracting the mean in a
            // second pass over the (small) window buffer for accuracy.
            let var = self
                .win_buf
                .iter()
                .map(|x| (x[c] - mean[c]).powi(2))
                .sum::<f64>()
                / (n - 1.0);
            std[c] = var.sqrt();
        }
        let abs_ok =
            (0..3).all(|c| std[c] <= STATIC_GYRO_SD) && (3..6).all(|c| std[c] <= STATIC_ACCEL_SD);
        if abs_ok {
            for c in 0..6 {
                // A constant coarse channel has σ = 0: floor at its resolution.
                let s = std[c].max(q[c] / 12f64.sqrt()).max(1e-15);
                self.floor[c] = self.floor[c].min(s);
            }
        }
        let quiet_vs_floor =
            (0..6).all(|c| std[c] <= QUIET_FACTOR * self.floor[c].max(q[c] / 12f64.sqrt()));
        let stationary = match &self.prev_mean {
            None => true,
            Some((pm, ps)) => (0..6).all(|c| {
                let s = std[c].max(ps[c]).max(q[c] / 12f64.sqrt());
                (mean[c] - pm[c]).abs() <= 6.0 * s * (2.0 / n).sqrt()
            }),
        };
        let quiet = abs_ok && quiet_vs_floor && stationary;
        self.prev_mean = Some((mean, std));
        if quiet {
            let start = self
                .cand_windows
                .last()
                .map(|w| w.start + w.len)
                .unwrap_or(0);
            self.cand_windows.push(WindowStat {
                std,
                start,
                len: self.n,
                first_line: self.win_first_line,
                start_ns: self.win_start_ns,
            });
            let buf = std::mem::take(&mut self.win_buf);
            self.append(buf);
        } else {
            self.finalize();
        }
        self.n = 0;
        self.sum = [0.0; 6];
        self.win_buf.clear();
    }

    pub(super) fn append(&mut self, buf: Vec<[f64; 6]>) {
        // Samples enter at the current decimation (pairs averaged).
        if self.cand_decim == 1 {
            self.cand.extend(buf);
        } else {
            let d = self.cand_decim;
            for chunk in buf.chunks(d) {
                if chunk.len() == d {
                    let mut m = [0.0; 6];
                    for x in chunk {
                        for c in 0..6 {
                            m[c] += x[c] / d as f64;
                        }
                    }
                    self.cand.push(m);
                }
            }
        }
        if self.cand.len() >= STATIC_CAP {
            let halved: Vec<[f64; 6]> = self
                .cand
                .chunks(2)
                .filter(|c| c.len() == 2)
                .map(|p| {
                    let mut m = [0.0; 6];
                    for c in 0..6 {
                        m[c] = 0.5 * (p[0][c] + p[1][c]);
                    }
                    m
                })
                .collect();
            self.cand = halved;
            self.cand_decim *= 2;
        }
    }

    /// Closes the candidate: the longest run of its windows that is quiet
    /// against the final floor becomes a segment.
    pub(super) fn finalize(&mut self) {
        if self.cand_windows.is_empty() {
            self.cand.clear();
            self.cand_decim = 1;
            return;
        }
        let ok = |w: &WindowStat| (0..6).all(|c| w.std[c] <= QUIET_FACTOR * self.floor[c]);
        let (mut best_i, mut best_len, mut i) = (0, 0, 0);
        while i < self.cand_windows.len() {
            if ok(&self.cand_windows[i]) {
                let s = i;
                while i < self.cand_windows.len() && ok(&self.cand_windows[i]) {
                    i += 1;
                }
                if i - s > best_len {
                    best_len = i - s;
                    best_i = s;
                }
            } else {
                i += 1;
            }
        }
        if best_len > 0 {
            let ws = &self.cand_windows[best_i..best_i + best_len];
            let samples: usize = ws.iter().map(|w| w.len).sum();
            if samples >= self.min_len {
                let seg = StaticSegment {
                    first_line: ws[0].first_line,
                    start_s: ws[0].start_ns as f64 * 1e-9,
                    duration_s: samples as f64 * self.dt_s,
                };
                self.segments.push(seg.clone());
                let better = self
                    .best
                    .as_ref()
                    .is_none_or(|b| b.0.duration_s < seg.duration_s);
                if better {
                    let d = self.cand_decim;
                    let a = ws[0].start / d;
                    let b = ((ws[0].start + samples) / d).min(self.cand.len());
                    let data = self.cand[a..b].to_vec();
                    self.best = Some((seg, data, d));
                }
            }
        }
        self.cand_windows.clear();
        self.cand.clear();
        self.cand_decim = 1;
    }
}
