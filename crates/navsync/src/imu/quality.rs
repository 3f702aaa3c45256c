//! Quality of a recorded IMU log against seed 001 §1 (checklist §1.5).
//!
//! One streaming pass ([`QualityAnalyzer::push`]) measures:
//! - intervals: statistics, jitter, the true rate (least squares of time on
//!   sample index, lost samples counted in the index);
//! - gaps (an interval over `gap_factor` nominal periods; any over 0.1 s
//!   violates §1.5 point 5), lost samples, duplicated and out-of-order
//!   records, stale records (all six values repeat the previous record
//!   where chance cannot explain it);
//! - per channel: stuck runs, saturation (a flat top at the channel's
//!   extreme, or a declared full-scale range), spikes (isolated one-sample
//!   excursions), the retained precision (significant digits written,
//!   quantization step, print rounding against the sensor noise; §1.5
//!   point 4);
//! - static segments, detected automatically, and their Allan deviation
//!   (angle/velocity random walk, bias instability).
//!
//! [`QualityAnalyzer::finish`] turns this into a [`QualityReport`] with one
//! verdict row per seed 001 criterion. Loss rate = lost / (received +
//! lost); bad-data rate = bad records / records, both against 1e-5 (§1.5
//! point 5).
#![warn(missing_docs)]

use std::path::{Path, PathBuf};
use std::sync::mpsc;

use serde::Serialize;

use super::log::{ImuLogFormat, ImuLogReader, LogRecord};
use super::lowpass::{GroupDelay, LowPassFilter};
use crate::allan::{AllanPoint, fit_noise, overlapping_adev};
use crate::error::{Diagnostics, Error};
use crate::stats::{Moments, quantile};

mod criteria;
mod figures;
mod report;
mod static_detect;

use criteria::criteria;
pub use report::*;
use static_detect::StaticDetector;

const CHANNELS: [&str; 6] = [
    "gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z",
];
/// Round rates: the measured (true) rate is taken as one of them when
/// within 1 % of it.
const ROUND_RATES: [f64; 29] = [
    1.0, 2.0, 4.0, 5.0, 8.0, 10.0, 16.0, 20.0, 25.0, 32.0, 40.0, 50.0, 64.0, 100.0, 125.0, 128.0,
    200.0, 250.0, 256.0, 400.0, 500.0, 512.0, 1000.0, 1024.0, 2000.0, 2048.0, 4000.0, 4096.0,
    8000.0,
];
/// Records used to find the nominal interval when none is given.
const WARMUP: usize = 64;
/// Events kept per kind (all are counted).
const EVENTS_PER_KIND: usize = 50;

/// Options and limits of a check.
#[derive(Clone, Debug, Serialize)]
pub struct QualityConfig {
    /// Nominal output rate (Hz); estimated from the first intervals when
    /// `None`.
    pub nominal_rate_hz: Option<f64>,
    /// The IMU's internal (raw) sampling rate, when known (§1.2).
    pub raw_rate_hz: Option<f64>,
    /// Lowest raw rate for the carrier (§1.2: a vehicle not below 200 Hz).
    pub min_raw_rate_hz: f64,
    /// An interval longer than this many nominal periods is a gap.
    pub gap_factor: f64,
    /// Longest acceptable gap (s): §1.5 point 5, 0.1 s for a vehicle.
    pub max_gap_s: f64,
    /// §1.5 point 5: loss and bad-data rates below 1e-5.
    pub max_loss_rate: f64,
    /// Largest acceptable bad-data rate: bad records (malformed, duplicate,
    /// out of order, stale, spiky, saturated, stuck) over records.
    pub max_bad_rate: f64,
    /// navsync's limit on interval jitter (RMS, fraction of the interval);
    /// seed 001 asks for a stable interval without a number.
    pub max_jitter_frac: f64,
    /// A spike exceeds this many times the running mean |second
    /// difference| of its channel.
    pub spike_factor: f64,
    /// Shortest stuck run (s); at least 20 samples, and longer for coarse
    /// channels where repeats are common (see [`QualityReport`]).
    pub stuck_min_s: f64,
    /// Full-scale ranges, when known: samples at ≥ 99.9 % are saturated.
    pub gyro_range_rad_s: Option<f64>,
    /// Accelerometer full-scale range (m/s²), when known.
    pub accel_range_mps2: Option<f64>,
    /// The low-pass filter the IMU applied, if any (§1.4).
    pub lowpass: Option<LowPassFilter>,
    /// Band of the carrier's dynamics (Hz) for the filter-delay report.
    pub dynamics_band_hz: f64,
    /// Static detection window (s): σ and mean are compared window by
    /// window.
    pub static_window_s: f64,
    /// Shortest static segment kept (s); the longest one found gets the
    /// Allan analysis.
    pub min_static_s: f64,
}

impl Default for QualityConfig {
    fn default() -> Self {
        QualityConfig {
            nominal_rate_hz: None,
            raw_rate_hz: None,
            min_raw_rate_hz: 200.0,
            gap_factor: 1.5,
            max_gap_s: 0.1,
            max_loss_rate: 1e-5,
            max_bad_rate: 1e-5,
            max_jitter_frac: 0.05,
            spike_factor: 12.0,
            stuck_min_s: 0.5,
            gyro_range_rad_s: None,
            accel_range_mps2: None,
            lowpass: None,
            dynamics_band_hz: 10.0,
            static_window_s: 1.0,
            min_static_s: 10.0,
        }
    }
}

/// A deterministic thinning sample of a long series (keeps every
/// `stride`-th value; halves itself when full).
#[derive(Clone, Debug)]
struct Reservoir {
    data: Vec<f64>,
    stride: usize,
    count: usize,
}

impl Reservoir {
    const CAP: usize = 4096;

    fn new() -> Self {
        Reservoir {
            data: Vec::new(),
            stride: 1,
            count: 0,
        }
    }

    #[inline]
    fn push(&mut self, v: f64) {
        self.count += 1;
        if !self.count.is_multiple_of(self.stride) {
            return;
        }
        self.data.push(v);
        if self.data.len() == Self::CAP {
            let mut k = 0;
            self.data.retain(|_| {
                k += 1;
                k % 2 == 0
            });
            self.stride *= 2;
        }
    }
}

/// Samples covered by `ranges` (`[start, end)` sample indices, in any
/// order, overlapping or not); sorts them.
fn union_len(ranges: &mut [(usize, usize)]) -> usize {
    ranges.sort_unstable();
    let mut total = 0;
    let mut cur: Option<(usize, usize)> = None;
    for &(a, b) in ranges.iter() {
        cur = match cur {
            Some((ca, cb)) if a <= cb => Some((ca, cb.max(b))),
            Some((ca, cb)) => {
                total += cb - ca;
                Some((a, b))
            }
            None => Some((a, b)),
        };
    }
    total + cur.map_or(0, |(a, b)| b - a)
}

/// Sample-index ranges `[start, end)` of flagged samples, consecutive
/// indices merged; at most `MAX_FLAGGED_RANGES`, after which `overflow`
/// says the ranges are incomplete (the bad-record count then falls back
/// to the plain count).
#[derive(Clone, Debug, Default)]
struct IndexRanges {
    ranges: Vec<(usize, usize)>,
    overflow: bool,
}

/// Enough for any real clipping episode list; bounds memory on
/// pathological inputs (every other sample at the extreme).
const MAX_FLAGGED_RANGES: usize = 4096;

impl IndexRanges {
    /// Flags samples `[start, end)`, merged with the last range when they
    /// touch it.
    fn add(&mut self, start: usize, end: usize) {
        if let Some(last) = self.ranges.last_mut()
            && (last.0..=last.1).contains(&start)
        {
            last.1 = last.1.max(end);
        } else if self.ranges.len() < MAX_FLAGGED_RANGES {
            self.ranges.push((start, end));
        } else {
            self.overflow = true;
        }
    }

    fn clear(&mut self) {
        self.ranges.clear();
        self.overflow = false;
    }
}

/// The extreme (max or min) of a channel and the flat tops at it.
#[derive(Clone, Debug, Default)]
struct Extreme {
    value: Option<f64>,
    run: usize,
    run_line: usize,
    longest: usize,
    longest_line: usize,
    /// Samples at the extreme inside runs of two or more.
    in_runs: usize,
    /// Those samples' indices.
    runs: IndexRanges,
}

impl Extreme {
    /// Sample `x` (accepted sample `idx`, file line `line`).
    #[inline]
    fn push(&mut self, x: f64, line: usize, idx: usize, is_max: bool) {
        match self.value {
            Some(v) if x == v => {
                self.run += 1;
                if self.run == 1 {
                    self.run_line = line;
                }
                if self.run == 2 {
                    self.in_runs += 2;
                    self.runs.add(idx.saturating_sub(1), idx + 1);
                } else if self.run > 2 {
                    self.in_runs += 1;
                    self.runs.add(idx, idx + 1);
                }
                if self.run > self.longest {
                    self.longest = self.run;
                    self.longest_line = self.run_line;
                }
            }
            Some(v) if (is_max && x < v) || (!is_max && x > v) => self.run = 0,
            _ => {
                self.value = Some(x);
                self.run = 1;
                self.run_line = line;
                self.longest = 1;
                self.longest_line = line;
                self.in_runs = 0;
                self.runs.clear();
            }
        }
    }
}

/// A run of identical values long enough to be a stuck candidate.
#[derive(Clone, Debug)]
struct Run {
    first_line: usize,
    first_ns: i64,
    first_idx: usize,
    len: usize,
    value: f64,
}

#[derive(Clone, Debug)]
struct ChannelState {
    moments: Moments,
    repeats: usize,
    prev_raw: Option<f64>,
    run: Run,
    stuck: Vec<Run>,
    max: Extreme,
    min: Extreme,
    range_hits: usize,
    range_first_line: usize,
    /// Indices of the samples at the declared full scale.
    range_runs: IndexRanges,
    // Spike test: the two previous rate values (contiguous).
    /// The last three values (oldest first), their lines and times.
    hist: [f64; 3],
    hist_line: [usize; 3],
    hist_ns: [i64; 3],
    hist_n: usize,
    scale: f64,
    scale_n: usize,
    /// The running level before each of the last two updates (to undo what
    /// a two-sample spike added to it before it was recognised).
    scale_before: [f64; 2],
    min_step: f64,
    spikes: usize,
    // Precision.
    min_sig: u8,
    sig_hist: [u32; 32],
    step_hist: [u32; 64],
    diffs: Reservoir,
    second: Reservoir,
}

impl ChannelState {
    /// The spike test on the middle of the last three contiguous samples
    /// and the new one `x` (and on the middle pair of four), updating the
    /// channel's running level; `q_step` the channel's resolution so far.
    /// Returns the spike's offset, line and time.
    fn spike_test(
        &mut self,
        x: f64,
        q_step: f64,
        gap: bool,
        k_spike: f64,
        alpha: f64,
    ) -> Option<(f64, usize, i64)> {
        // Spike test on the middle of three contiguous samples, and on
        // the middle pair of four: a one-sample spike in rates becomes
        // two equal halves in trapezoid increments (seed 001 §1.1).
        if gap {
            self.hist_n = 0;
        }
        let thr = (k_spike * self.scale).max(10.0 * q_step);
        let mut spike: Option<(f64, usize, i64)> = None;
        if self.hist_n >= 2 {
            let (a, b) = (self.hist[1], self.hist[2]);
            let d = b - 0.5 * (a + x);
            let spread = (x - a).abs();
            if self.scale_n >= 32 && d.abs() > thr && spread < 0.25 * d.abs() {
                spike = Some((d, self.hist_line[2], self.hist_ns[2]));
                self.hist[2] = 0.5 * (a + x);
            } else if self.hist_n >= 3 {
                let (a, b1, b2) = (self.hist[0], self.hist[1], self.hist[2]);
                let base = 0.5 * (a + x);
                let d2 = 0.5 * (b1 + b2) - base;
                let thr2 = (k_spike * self.scale_before[0]).max(10.0 * q_step);
                if self.scale_n >= 34
                    && d2.abs() > thr2
                    && (b1 - b2).abs() < 0.25 * d2.abs()
                    && (x - a).abs() < 0.25 * d2.abs()
                {
                    // The two updates the pair made to the level are undone.
                    self.scale = self.scale_before[0];
                    spike = Some((d2, self.hist_line[1], self.hist_ns[1]));
                    self.hist[1] = base;
                    self.hist[2] = base;
                }
            }
            if spike.is_none() {
                self.second.push(d);
                self.scale_before = [self.scale_before[1], self.scale];
                if self.scale_n < 32 {
                    self.scale =
                        (self.scale * self.scale_n as f64 + d.abs()) / (self.scale_n + 1) as f64;
                } else {
                    self.scale += alpha * (d.abs() - self.scale);
                }
                self.scale_n += 1;
            }
        }
        spike
    }

    fn new() -> Self {
        ChannelState {
            moments: Moments::default(),
            repeats: 0,
            prev_raw: None,
            run: Run {
                first_line: 0,
                first_ns: 0,
                first_idx: 0,
                len: 0,
                value: f64::NAN,
            },
            stuck: Vec::new(),
            max: Extreme::default(),
            min: Extreme::default(),
            range_hits: 0,
            range_first_line: 0,
            range_runs: IndexRanges::default(),
            hist: [0.0; 3],
            hist_line: [0; 3],
            hist_ns: [0; 3],
            hist_n: 0,
            scale: 0.0,
            scale_n: 0,
            scale_before: [0.0; 2],
            min_step: f64::INFINITY,
            spikes: 0,
            min_sig: u8::MAX,
            sig_hist: [0; 32],
            step_hist: [0; 64],
            diffs: Reservoir::new(),
            second: Reservoir::new(),
        }
    }
}

/// The streaming analyzer (see the module docs).
pub struct QualityAnalyzer {
    cfg: QualityConfig,
    path: PathBuf,
    format: ImuLogFormat,
    warm: Vec<LogRecord>,
    nominal_ns: i64,
    nominal_s: f64,
    last: Option<LogRecord>,
    first_ns: Option<i64>,
    records: usize,
    accepted: usize,
    // Order guard (reset detection).
    behind_run: usize,
    behind_line: usize,
    behind_by_ns: i64,
    // Intervals.
    hist: Vec<u32>,
    hist_bin_ns: f64,
    dt_all: Moments,
    dt_regular: Moments,
    longest_gap_s: f64,
    longest_gap_line: usize,
    // Regression of time on index (Welford).
    idx: f64,
    reg_n: f64,
    reg_mx: f64,
    reg_my: f64,
    reg_sxx: f64,
    reg_sxy: f64,
    counts: Counts,
    events: Vec<Event>,
    kind_events: [usize; 8],
    ch: Vec<ChannelState>,
    last_spike_line: usize,
    stale_ok_after: usize,
    statics: Option<StaticDetector>,
    notes: Vec<String>,
}

impl QualityAnalyzer {
    /// An analyzer for a log of `format` read from `path` (named in
    /// messages).
    pub fn new(cfg: QualityConfig, format: ImuLogFormat, path: &Path) -> Self {
        let mut a = QualityAnalyzer {
            cfg,
            path: path.to_path_buf(),
            format,
            warm: Vec::with_capacity(WARMUP),
            nominal_ns: 0,
            nominal_s: f64::NAN,
            last: None,
            first_ns: None,
            records: 0,
            accepted: 0,
            behind_run: 0,
            behind_line: 0,
            behind_by_ns: 0,
            hist: Vec::new(),
            hist_bin_ns: 1.0,
            dt_all: Moments::default(),
            dt_regular: Moments::default(),
            longest_gap_s: 0.0,
            longest_gap_line: 0,
            idx: 0.0,
            reg_n: 0.0,
            reg_mx: 0.0,
            reg_my: 0.0,
            reg_sxx: 0.0,
            reg_sxy: 0.0,
            counts: Counts::default(),
            events: Vec::new(),
            kind_events: [0; 8],
            ch: (0..6).map(|_| ChannelState::new()).collect(),
            last_spike_line: 0,
            stale_ok_after: 200,
            statics: None,
            notes: Vec::new(),
        };
        if let Some(r) = a.cfg.nominal_rate_hz
            && r > 0.0
        {
            a.set_nominal((1e9 / r).round() as i64);
        }
        a
    }

    fn set_nominal(&mut self, ns: i64) {
        self.nominal_ns = ns.max(1);
        self.nominal_s = self.nominal_ns as f64 * 1e-9;
        // 0.1 % bins up to four periods.
        self.hist_bin_ns = self.nominal_ns as f64 / 1000.0;
        self.hist = vec![0; 4000];
        let rate = 1.0 / self.nominal_s;
        let win_n = (self.cfg.static_window_s * rate).round() as usize;
        let min_len = (self.cfg.min_static_s * rate).round() as usize;
        self.statics = Some(StaticDetector::new(win_n, min_len, self.nominal_s));
    }

    /// Pushes one record (in file order). Errors when time goes back and
    /// stays back (a reset or two logs joined).
    pub fn push(&mut self, rec: &LogRecord) -> Result<(), Error> {
        self.records += 1;
        if self.nominal_ns == 0 {
            self.warm.push(*rec);
            if self.warm.len() >= WARMUP {
                self.end_warmup()?;
            }
            return Ok(());
        }
        self.process(rec)
    }

    fn end_warmup(&mut self) -> Result<(), Error> {
        let mut dts: Vec<f64> = self
            .warm
            .windows(2)
            .map(|w| (w[1].time_ns - w[0].time_ns) as f64)
            .filter(|&d| d > 0.0)
            .collect();
        if dts.is_empty() {
            return Err(Error::NoData {
                path: self.path.clone(),
                msg: "need at least two records with increasing time to find the sampling interval"
                    .into(),
            });
        }
        let med = quantile(&mut dts, 0.5);
        self.set_nominal(med.round() as i64);
        let warm = std::mem::take(&mut self.warm);
        for r in &warm {
            self.process(r)?;
        }
        Ok(())
    }

    fn event(
        &mut self,
        kind: EventKind,
        line: usize,
        time_ns: i64,
        channel: Option<usize>,
        detail: String,
    ) {
        let k = KINDS.iter().position(|&x| x == kind).unwrap_or(0);
        self.kind_events[k] += 1;
        if self.kind_events[k] <= EVENTS_PER_KIND {
            self.events.push(Event {
                kind,
                line,
                time_s: time_ns as f64 * 1e-9,
                channel: channel.map(|c| CHANNELS[c]),
                detail,
            });
        }
    }

    fn process(&mut self, rec: &LogRecord) -> Result<(), Error> {
        let Some(last) = self.last else {
            self.first_ns = Some(rec.time_ns);
            self.accept(rec, None);
            return Ok(());
        };
        if rec.time_ns == last.time_ns {
            self.counts.duplicates += 1;
            let same = rec.values == last.values;
            self.event(
                EventKind::Duplicate,
                rec.line,
                rec.time_ns,
                None,
                if same {
                    format!(
                        "duplicated sample (same time and values as line {})",
                        last.line
                    )
                } else {
                    format!(
                        "duplicate time stamp (line {} has the same time, other values)",
                        last.line
                    )
                },
            );
            return Ok(());
        }
        if rec.time_ns < last.time_ns {
            if self.behind_run == 0 {
                self.behind_line = rec.line;
                self.behind_by_ns = last.time_ns - rec.time_ns;
            }
            self.behind_run += 1;
            if self.behind_run >= super::log::TimeOrder::RESET_RUN {
                return Err(Error::parse(
                    &self.path,
                    self.behind_line,
                    format!(
                        "time goes back {:.6} s here and does not recover within {} records: expected increasing times in one IMU stream (a clock reset, or two logs joined?)",
                        self.behind_by_ns as f64 * 1e-9,
                        super::log::TimeOrder::RESET_RUN
                    ),
                ));
            }
            self.counts.out_of_order += 1;
            self.event(
                EventKind::OutOfOrder,
                rec.line,
                rec.time_ns,
                None,
                format!(
                    "time {:.6} s is {:.6} s before line {}; record not used",
                    rec.time_ns as f64 * 1e-9,
                    (last.time_ns - rec.time_ns) as f64 * 1e-9,
                    last.line
                ),
            );
            return Ok(());
        }
        self.behind_run = 0;
        self.accept(rec, Some(last));
        Ok(())
    }

    /// Accounts the interval from `last` to `rec` (histogram, moments, the
    /// index of samples); a gap is counted, with its lost samples and its
    /// event. Returns true for a gap.
    fn note_interval(&mut self, rec: &LogRecord, last: &LogRecord) -> bool {
        let dt_ns = rec.time_ns - last.time_ns;
        let dt = dt_ns as f64 * 1e-9;
        self.dt_all.push(dt);
        let bin = (dt_ns as f64 / self.hist_bin_ns) as usize;
        if let Some(h) = self.hist.get_mut(bin) {
            *h += 1;
        }
        let mut lost = 0usize;
        let gap = dt_ns as f64 > self.cfg.gap_factor * self.nominal_ns as f64;
        if gap {
            lost = ((dt_ns as f64 / self.nominal_ns as f64).round() as usize)
                .saturating_sub(1)
                .max(1);
            self.counts.gaps += 1;
            self.counts.lost_samples += lost;
            let over = dt > self.cfg.max_gap_s;
            if over {
                self.counts.gaps_over_limit += 1;
            }
            if dt > self.longest_gap_s {
                self.longest_gap_s = dt;
                self.longest_gap_line = rec.line;
            }
            self.event(
                EventKind::Gap,
                rec.line,
                rec.time_ns,
                None,
                format!(
                    "{dt:.6} s since line {} (≈ {lost} sample{} lost){}",
                    last.line,
                    if lost == 1 { "" } else { "s" },
                    if over {
                        format!(
                            "; longer than {} s (Tang, Zhang & Niu 2022 §1.5-5)",
                            self.cfg.max_gap_s
                        )
                    } else {
                        String::new()
                    }
                ),
            );
            if let Some(s) = self.statics.as_mut() {
                s.gap();
            }
        } else {
            self.dt_regular.push(dt);
        }
        self.idx += 1.0 + lost as f64;
        gap
    }

    /// A stale record: all six values repeat the previous record, where the
    /// channels' repeat rates make that a < 1e-6 chance.
    fn check_stale(&mut self, rec: &LogRecord, last: &LogRecord) {
        if rec.values == last.values && self.accepted > self.stale_ok_after {
            let n = (self.accepted - 1) as f64;
            let chance: f64 = self
                .ch
                .iter()
                .map(|c| (c.repeats as f64 / n).max(1.0 / n))
                .product();
            if chance < 1e-6 {
                self.counts.stale_records += 1;
                self.event(
                    EventKind::Stale,
                    rec.line,
                    rec.time_ns,
                    None,
                    format!(
                        "all six values repeat line {} (stale data re-sent?)",
                        last.line
                    ),
                );
            }
        }
    }

    fn accept(&mut self, rec: &LogRecord, last: Option<LogRecord>) {
        let gap = last.is_some_and(|last| self.note_interval(rec, &last));
        // Time-on-index regression (Welford), y relative to the first time.
        let y = (rec.time_ns - self.first_ns.unwrap_or(rec.time_ns)) as f64 * 1e-9;
        self.reg_n += 1.0;
        let dx = self.idx - self.reg_mx;
        self.reg_mx += dx / self.reg_n;
        let dy = y - self.reg_my;
        self.reg_my += dy / self.reg_n;
        self.reg_sxx += dx * (self.idx - self.reg_mx);
        self.reg_sxy += dx * (y - self.reg_my);

        self.accepted += 1;
        let scale = if self.format == ImuLogFormat::KfGins {
            1.0 / self.nominal_s
        } else {
            1.0
        };
        let mut r = [0.0; 6];
        for c in 0..6 {
            r[c] = rec.values[c] * scale;
        }

        if let Some(last) = last {
            self.check_stale(rec, &last);
        }
        let idx = self.accepted - 1;
        let k_spike = self.cfg.spike_factor;
        let alpha = 1.0 / (0.5 / self.nominal_s).clamp(16.0, 256.0);
        let mut q = [0.0; 6];
        for c in 0..6 {
            let raw = rec.values[c];
            let x = r[c];
            let st = &mut self.ch[c];
            st.moments.push(x);
            if rec.digits[c].significant > 0 {
                st.min_sig = st.min_sig.min(rec.digits[c].significant);
                st.sig_hist[(rec.digits[c].significant as usize).min(31)] += 1;
                let e = (rec.digits[c].step_exp as i32 + 50).clamp(0, 63) as usize;
                st.step_hist[e] += 1;
            }
            // Runs of identical values.
            if st.prev_raw == Some(raw) {
                st.repeats += 1;
                st.run.len += 1;
            } else {
                if st.run.len >= 20 {
                    st.stuck.push(st.run.clone());
                }
                st.run = Run {
                    first_line: rec.line,
                    first_ns: rec.time_ns,
                    first_idx: idx,
                    len: 1,
                    value: raw,
                };
            }
            if let Some(p) = st.prev_raw
                && !gap
            {
                let d = (raw - p).abs() * scale;
                if d > 0.0 {
                    st.diffs.push(d);
                    st.min_step = st.min_step.min(d);
                }
            }
            st.prev_raw = Some(raw);
            st.max.push(x, rec.line, idx, true);
            st.min.push(x, rec.line, idx, false);
            let range = if c < 3 {
                self.cfg.gyro_range_rad_s
            } else {
                self.cfg.accel_range_mps2
            };
            if let Some(fs) = range
                && x.abs() >= 0.999 * fs
            {
                if st.range_hits == 0 {
                    st.range_first_line = rec.line;
                }
                st.range_hits += 1;
                st.range_runs.add(idx, idx + 1);
            }
            q[c] = if st.min_step.is_finite() {
                st.min_step
            } else {
                0.0
            };
            let spike = st.spike_test(x, q[c], gap, k_spike, alpha);
            if let Some((d, line, t_ns)) = spike {
                st.spikes += 1;
                let detail = format!(
                    "{:+.6e} off its neighbours ({:.1} × the channel's running level)",
                    d,
                    d.abs() / st.scale.max(f64::MIN_POSITIVE)
                );
                self.counts.spikes += 1;
                if line != self.last_spike_line {
                    self.counts.spike_records += 1;
                    self.last_spike_line = line;
                }
                self.event(EventKind::Spike, line, t_ns, Some(c), detail);
            }
            let st = &mut self.ch[c];
            st.hist = [st.hist[1], st.hist[2], x];
            st.hist_line = [st.hist_line[1], st.hist_line[2], rec.line];
            st.hist_ns = [st.hist_ns[1], st.hist_ns[2], rec.time_ns];
            st.hist_n = (st.hist_n + 1).min(3);
        }
        if let Some(s) = self.statics.as_mut() {
            s.push(&r, rec.line, rec.time_ns, &q);
        }
        self.last = Some(*rec);
    }

    /// Closes the analysis. `malformed` lines (with their diagnostics)
    /// come from the reader and count as bad data.
    pub fn finish(
        mut self,
        malformed: usize,
        reader_diag: &Diagnostics,
    ) -> Result<QualityReport, Error> {
        if self.nominal_ns == 0 {
            self.end_warmup()?;
        }
        if self.accepted < 2 {
            return Err(Error::NoData {
                path: self.path.clone(),
                msg: "fewer than two usable IMU records".into(),
            });
        }
        self.counts.malformed_lines = malformed;
        for d in reader_diag.items.iter() {
            let k = 0;
            self.kind_events[k] += 1;
            if self.kind_events[k] <= EVENTS_PER_KIND {
                self.events.push(Event {
                    kind: EventKind::Malformed,
                    line: d.line,
                    time_s: f64::NAN,
                    channel: None,
                    detail: d.message.clone(),
                });
            }
        }
        let n_acc = self.accepted;

        let flat = self.flat_runs(n_acc);
        let (intervals, rates) = self.interval_stats();
        let channels = self.channel_reports(n_acc, &flat);
        let (static_segments, allan) = self.static_and_allan();
        let lowpass = self.cfg.lowpass.as_ref().map(|f| {
            let delay = f.group_delay(self.cfg.dynamics_band_hz);
            LowPassReport {
                warning: f.warning(&delay),
                filter: f.clone(),
                delay,
            }
        });

        let c = &self.counts;
        let bad = c.malformed_lines
            + c.duplicates
            + c.out_of_order
            + c.stale_records
            + c.spike_records
            + flat.records;
        let records = self.records + malformed;
        let loss_rate = c.lost_samples as f64 / (n_acc + c.lost_samples) as f64;
        let bad_rate = bad as f64 / records.max(1) as f64;
        self.events.sort_by_key(|e| (e.line, e.kind as u8));
        let first = self.first_ns.unwrap_or(0) as f64 * 1e-9;
        let last = self.last.map(|l| l.time_ns).unwrap_or(0) as f64 * 1e-9;
        let mut report = QualityReport {
            file: self.path.display().to_string(),
            format: self.format.name(),
            records,
            accepted: n_acc,
            first_time_s: first,
            last_time_s: last,
            duration_s: last - first,
            nominal_rate_hz: rates.nominal_hz,
            round_rate_hz: rates.round_hz,
            true_rate_hz: rates.true_hz,
            rate_error_ppm: rates.error_ppm,
            intervals,
            longest_gap_s: self.longest_gap_s,
            longest_gap_line: self.longest_gap_line,
            counts: self.counts.clone(),
            bad_records: bad,
            loss_rate,
            bad_data_rate: bad_rate,
            channels,
            static_segments,
            allan,
            lowpass,
            criteria: Vec::new(),
            verdict: Status::Pass,
            events: self.events,
            notes: self.notes,
        };
        if report.round_rate_hz.is_none() && report.rate_error_ppm.abs() > 100.0 {
            report.notes.push(format!(
                "the median interval ({:.6} ms) and the mean rate ({:.4} Hz) disagree by {:.0} ppm: the time stamps come in coarse clock ticks or unevenly (e.g. stamped at arrival)",
                report.intervals.median_s * 1e3,
                report.true_rate_hz,
                report.rate_error_ppm
            ));
        }
        report.criteria = criteria(&report, &self.cfg);
        report.verdict = report
            .criteria
            .iter()
            .map(|c| c.status)
            .filter(|s| *s != Status::Info)
            .max()
            .unwrap_or(Status::Pass);
        Ok(report)
    }
}

/// The sensor resolution, when the value differences sit on a grid: the
/// median of the smallest differences (within 1.5× the smallest), accepted
/// when ≥ 90 % of all differences are within 0.15 of a multiple of it.
fn quantization_step(diffs: &[f64]) -> Option<f64> {
    let min = diffs.iter().copied().fold(f64::INFINITY, f64::min);
    if !min.is_finite() || diffs.len() < 16 {
        return None;
    }
    let mut small: Vec<f64> = diffs.iter().copied().filter(|&d| d < 1.5 * min).collect();
    let q = quantile(&mut small, 0.5);
    let on_grid = diffs
        .iter()
        .filter(|&&d| {
            let k = d / q;
            (k - k.round()).abs() < 0.15
        })
        .count();
    // A continuous signal puts only ~30 % within ±0.15 of a multiple.
    (on_grid as f64 >= 0.9 * diffs.len() as f64 && diffs.iter().any(|&d| d > 1.5 * q)).then_some(q)
}

/// Lag-`lag` autocorrelation of a series.
fn lag_corr(y: &[f64], lag: usize) -> f64 {
    if y.len() < lag + 2 {
        return f64::NAN;
    }
    let m = y.iter().sum::<f64>() / y.len() as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..y.len() {
        let a = y[k] - m;
        den += a * a;
        if k + lag < y.len() {
            num += a * (y[k + lag] - m);
        }
    }
    if den > 0.0 { num / den } else { f64::NAN }
}

fn fmt_rate(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else {
        format!("{x:.2e}")
    }
}

/// Checks a log file. One thread reads blocks, worker threads parse them
/// (`super::log::parse_line`), the calling thread puts them back in
/// order (`ImuLogReader::sequence`) and analyzes. Malformed lines are
/// reported in `diag` (and counted as bad data).
pub fn check_file(
    path: &Path,
    format: Option<ImuLogFormat>,
    cfg: QualityConfig,
    diag: &mut Diagnostics,
) -> Result<QualityReport, Error> {
    use super::log::{Parsed, parse_line};
    use std::collections::BTreeMap;
    use std::io::Read;
    use std::sync::{Arc, Mutex};

    const BLOCK: usize = 1 << 20;
    let workers = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, 4);
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let (chunk_tx, chunk_rx) = mpsc::sync_channel::<(usize, Vec<u8>)>(2 * workers);
    let (res_tx, res_rx) = mpsc::sync_channel::<(usize, Vec<Parsed>)>(4 * workers);
    let p = path.to_path_buf();
    let chunker = std::thread::spawn(move || -> Result<(), Error> {
        let mut file = file;
        let mut carry: Vec<u8> = Vec::new();
        let mut idx = 0usize;
        loop {
            let mut buf = std::mem::take(&mut carry);
            let start = buf.len();
            buf.resize(start + BLOCK, 0);
            let n = loop {
                match file.read(&mut buf[start..]) {
                    Ok(n) => break n,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(Error::io(&p, e)),
                }
            };
            buf.truncate(start + n);
            if n == 0 {
                if !buf.is_empty() && chunk_tx.send((idx, buf)).is_err() {
                    return Ok(());
                }
                return Ok(());
            }
            match memchr::memrchr(b'\n', &buf) {
                Some(pos) => {
                    carry = buf[pos + 1..].to_vec();
                    buf.truncate(pos + 1);
                    if chunk_tx.send((idx, buf)).is_err() {
                        return Ok(());
                    }
                    idx += 1;
                }
                // No line end yet: keep reading into the same line.
                None => carry = buf,
            }
        }
    });
    let chunk_rx = Arc::new(Mutex::new(chunk_rx));
    let mut parsers = Vec::new();
    for _ in 0..workers {
        let rx = Arc::clone(&chunk_rx);
        let tx = res_tx.clone();
        parsers.push(std::thread::spawn(move || {
            loop {
                let msg = match rx.lock() {
                    Ok(guard) => guard.recv(),
                    Err(_) => return,
                };
                let Ok((idx, buf)) = msg else { return };
                let mut out = Vec::with_capacity(buf.len() / 64);
                let body = buf.strip_suffix(b"\n").unwrap_or(&buf);
                for (i, line) in body.split(|&b| b == b'\n').enumerate() {
                    let want = idx == 0 || i % 8 == 0;
                    out.push(parse_line(line, want));
                }
                if tx.send((idx, out)).is_err() {
                    return;
                }
            }
        }));
    }
    drop(res_tx);
    drop(chunk_rx);

    let mut seq = ImuLogReader::sequencer(path, format);
    let mut rdiag = Diagnostics::with_cap(1000);
    let mut analyzer: Option<QualityAnalyzer> = None;
    let mut pending: BTreeMap<usize, Vec<Parsed>> = BTreeMap::new();
    let mut next = 0usize;
    let mut line_base = 0usize;
    let feed = |rec: &LogRecord,
                fmt: Option<ImuLogFormat>,
                analyzer: &mut Option<QualityAnalyzer>|
     -> Result<(), Error> {
        if analyzer.is_none() {
            let f = fmt.unwrap_or(ImuLogFormat::KfGins);
            *analyzer = Some(QualityAnalyzer::new(cfg.clone(), f, path));
        }
        analyzer.as_mut().expect("set").push(rec)
    };
    let mut result: Result<(), Error> = Ok(());
    'outer: for (idx, lines) in res_rx.iter() {
        pending.insert(idx, lines);
        while let Some(lines) = pending.remove(&next) {
            let n = lines.len();
            for (i, parsed) in lines.into_iter().enumerate() {
                let step = seq
                    .sequence(line_base + i + 1, parsed, &mut rdiag)
                    .and_then(|_| {
                        while let Some(rec) = seq.take_record()? {
                            feed(&rec, seq.format(), &mut analyzer)?;
                        }
                        Ok(())
                    });
                if let Err(e) = step {
                    result = Err(e);
                    break 'outer;
                }
            }
            line_base += n;
            next += 1;
        }
    }
    drop(res_rx);
    for h in parsers {
        let _ = h.join();
    }
    chunker
        .join()
        .unwrap_or_else(|_| Err(Error::Invalid("IMU reader thread failed".into())))?;
    result?;
    for rec in seq.finish_sequence()? {
        feed(&rec, seq.format(), &mut analyzer)?;
    }
    let analyzer = analyzer.ok_or_else(|| Error::NoData {
        path: path.to_path_buf(),
        msg: "no IMU records".into(),
    })?;
    let report = analyzer.finish(seq.malformed(), &rdiag)?;
    diag.extend(rdiag);
    Ok(report)
}

#[cfg(test)]
mod tests;
