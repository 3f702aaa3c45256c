//! The synchronization engine: push rig-log records in arrival order, get
//! GPS-stamped IMU samples and GNSS fixes out — at once in causal mode,
//! after a bounded lookahead in post-processing mode.

#![warn(missing_docs)]

use std::collections::VecDeque;

use super::clock::{ClockConfig, LockState, Oscillator, PpsClock, Rejection, Smoother};
use super::imu::{ImuFlags, ImuTracker, RateEstimator};
use super::report::*;
use super::sampleclock::{SampleClock, SampleClockConfig, SampleHint, Timed};
use super::swsync::{SwClock, SwConfig};
use super::unwrap::{Unwrapped, Unwrapper};
use crate::error::{Diagnostics, Error};
use crate::io::heading::HeadingObs;
use crate::io::riglog::{RigGnss, RigHeader, RigHeading, RigRecord};
use crate::time::GpsTime;

/// Which synchronization to run.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SyncMode {
    /// Hardware sync when the log holds `pps` records, software otherwise.
    Auto,
    /// 1PPS + local counter (seed 001 §2.1).
    Hw,
    /// Receive times only (seed 001 §2.2).
    Sw,
    /// 1PPS + local counter for GPS time; IMU counters are receive times,
    /// turned into sample instants by the IMU's own sample clock
    /// ([`super::sampleclock`]).
    Hybrid,
}

/// Settings of the engine.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SyncConfig {
    /// Which synchronization to run (`--mode`).
    pub mode: SyncMode,
    /// Stamp each sample from past data only (real time).
    pub causal: bool,
    /// The IMU's known output delay T_c (s), subtracted from every IMU
    /// stamp: for an IMU timed by its serial frame (seed 000). `None`: the
    /// log header's `imu_output_delay_s`, else 0.
    pub imu_output_delay_s: Option<f64>,
    /// Clock-model settings (defaults follow the header's counter).
    pub clock: Option<ClockConfig>,
    /// The counter's oscillator, for the default clock settings: sets how
    /// fast holdover bounds grow.
    pub oscillator: Oscillator,
    /// Software-sync settings.
    pub sw: SwConfig,
    /// Longest wait for pulses to return before a post-processing stamp
    /// falls back to one-sided holdover (s); bounds memory.
    pub max_lookahead_s: f64,
    /// In auto mode, decide software sync when no pulse came in this many
    /// seconds of counter time.
    pub auto_wait_s: f64,
    /// Tolerated step back of the counter between records (s).
    pub reorder_tolerance_s: f64,
    /// Hybrid mode: receive time the sample clock looks ahead before it
    /// decides that samples were lost before a late one (samples on time
    /// are decided at once). `None`: 1 s and 100 samples, for
    /// post-processing; real time wants tens of ms, which decides losses
    /// on less evidence (a latency excursion longer than this is taken for
    /// a loss).
    pub hybrid_lookahead_s: Option<f64>,
    /// File name used in diagnostics.
    pub source: String,
}

impl Default for SyncConfig {
    fn default() -> Self {
        SyncConfig {
            mode: SyncMode::Auto,
            causal: false,
            imu_output_delay_s: None,
            clock: None,
            oscillator: Oscillator::Xo,
            sw: SwConfig::default(),
            max_lookahead_s: 600.0,
            auto_wait_s: 5.0,
            reorder_tolerance_s: 0.01,
            hybrid_lookahead_s: None,
            source: String::new(),
        }
    }
}

/// An IMU record with its GPS time.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StampedImu {
    /// Index of this record among the log's `imu` records (0-based).
    pub seq: u64,
    /// GPS time of the sample (meaningless when `flags.unstamped`).
    pub time: GpsTime,
    /// Error bound of `time` (s): ≥ 99 % of true errors lie within (hardware
    /// sync); the jitter estimate (software sync, constant part excluded).
    pub bound_s: f64,
    /// The six values as logged (rates or increments, FRD).
    pub values: [f64; 6],
    /// What the timing found about the record (duplicate, losses before it,
    /// holdover, unstamped…).
    pub flags: ImuFlags,
}

/// A GNSS fix with its latency.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StampedGnss {
    /// Time of validity (from the message; never moved).
    pub time: GpsTime,
    /// GPS time at which its last byte arrived.
    pub received: GpsTime,
    /// `received − time` (s): seed 002's latency from the 1PPS edge.
    pub latency_s: f64,
    /// Latitude (deg), positive north.
    pub lat_deg: f64,
    /// Longitude (deg), positive east.
    pub lon_deg: f64,
    /// Ellipsoidal height (m).
    pub h_m: f64,
    pub(crate) sd_m: [f64; 3],
}

impl StampedGnss {
    /// The fix at its time of validity, for the filter or a KF-GINS file.
    pub fn fix(&self) -> crate::types::GnssFix {
        crate::types::GnssFix {
            time: self.time,
            pos: crate::earth::Geodetic::from_deg(self.lat_deg, self.lon_deg, self.h_m),
            pos_sd: nalgebra::Vector3::from(self.sd_m),
            vel: None,
            vel_sd: None,
        }
    }
}

/// One output of the engine.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum SyncOutput {
    /// A GPS-stamped IMU sample.
    Imu(StampedImu),
    /// A GNSS fix with its receive time.
    Gnss(StampedGnss),
    /// A receiver heading (`heading` record): already on GPS time, passed
    /// through in order with the fixes, once its receive counter is
    /// stamped.
    Heading(HeadingObs),
}

#[derive(Copy, Clone, Debug)]
struct PendingImu {
    seq: u64,
    counter: u64,
    values: [f64; 6],
    flags: ImuFlags,
    /// Software sync: sample index and host time.
    k: i64,
    h: f64,
    /// What the source knew about the sample ([`SyncEngine::note_imu_lost`]).
    hint: ImuHint,
}

/// What the source of `imu` records knows beyond their counters.
#[derive(Copy, Clone, Debug, Default)]
struct ImuHint {
    /// Samples known lost just before the record.
    lost: u32,
    /// The stream restarted just before the record (a port reopened).
    restart: bool,
    /// Sample records read after it together (the same counter).
    behind: u32,
}

#[derive(Copy, Clone, Debug)]
struct PendingGnss {
    counter: u64,
    h: f64,
    what: GnssRecord,
}

/// A receiver record waiting for its receive counter to be stamped.
#[derive(Copy, Clone, Debug)]
enum GnssRecord {
    Fix(RigGnss),
    Heading(RigHeading),
}

/// A receiver time mark waiting to be stamped through the counter.
#[derive(Copy, Clone, Debug)]
struct PendingMark {
    counter: u64,
    h: f64,
    time: GpsTime,
}

enum Engine {
    /// Auto mode before the decision: raw records buffered.
    Undecided(Vec<(RigRecord, usize, ImuHint)>),
    Hw,
    Sw,
    Hybrid,
}

/// An IMU record on its way through the sample clock (hybrid mode).
#[derive(Copy, Clone, Debug)]
struct HybridTag {
    p: PendingImu,
    bound: f64,
    hold: bool,
    unstamped: bool,
}

/// Intervals of the first `imu` counters, for the interval jitter.
const JITTER_INTERVALS: usize = 2000;

/// The streaming synchronization engine. See the module documentation.
pub struct SyncEngine {
    cfg: SyncConfig,
    header: RigHeader,
    state: Engine,
    unwrap: Unwrapper,
    clock: PpsClock,
    smoother: Smoother,
    sw: SwClock,
    tracker: ImuTracker,
    rate: RateEstimator,
    pending_imu: VecDeque<PendingImu>,
    pending_gnss: VecDeque<PendingGnss>,
    pending_marks: VecDeque<PendingMark>,
    /// Counter-stamped time − receiver time of each mark (s).
    mark_residuals: crate::stats::Moments,
    imu_seq: u64,
    now: u64,
    first_counter: Option<u64>,
    tick_s: f64,
    // statistics
    counts: RecordCounts,
    latencies_ms: Vec<f32>,
    negative_latency: u64,
    holdover: Vec<HoldoverSpan>,
    open_holdover: Option<HoldoverSpan>,
    bounds: crate::stats::Moments,
    max_bound_s: f64,
    last_time: Option<GpsTime>,
    nonincreasing: u64,
    /// Stamp intervals over [`LOGGING_GAP_S`] (the first 1000) and the
    /// losses the sync counted inside them.
    logging_gaps: Vec<LoggingGap>,
    logging_gap_count: u64,
    lost_in_logging_gaps: u64,
    first_time: Option<GpsTime>,
    backwards: u64,
    reorders: u64,
    resets: u64,
    pps_ignored: u64,
    unstamped: u64,
    diag: Diagnostics,
    out_of_order_imu: u64,
    rejected_pulses: Vec<RejectedPulse>,
    /// Hybrid mode: the IMU's sample clock and the GPS second its times
    /// count from.
    sample_clock: SampleClock<HybridTag>,
    hybrid_origin: Option<i64>,
    /// Raw counters of the first `imu` records (interval jitter).
    first_imu_counters: Vec<u64>,
    /// Why auto mode chose hybrid, when it did.
    hybrid_reason: Option<String>,
    /// Told by the source, for the next `imu` record.
    next_hint: ImuHint,
    /// Hints of records the sample clock passed (duplicates, unstamped),
    /// for the next sample.
    carried_hint: ImuHint,
}

impl SyncEngine {
    /// A new engine for a log with `header`.
    pub fn new(header: &RigHeader, mut cfg: SyncConfig) -> Self {
        cfg.imu_output_delay_s = Some(
            cfg.imu_output_delay_s
                .or(header.imu_output_delay_s)
                .unwrap_or(0.0),
        );
        let hz = header.counter_hz;
        let clock_cfg = cfg
            .clock
            .clone()
            .unwrap_or_else(|| ClockConfig::for_counter(hz));
        let reorder = (cfg.reorder_tolerance_s * hz) as u64;
        // Records are far closer than an hour; half the wrap period caps it.
        let max_forward = (3600.0 * hz).min(u64::MAX as f64 / 4.0) as u64;
        let state = match cfg.mode {
            SyncMode::Auto => Engine::Undecided(Vec::new()),
            SyncMode::Hw => Engine::Hw,
            SyncMode::Sw => Engine::Sw,
            SyncMode::Hybrid => Engine::Hybrid,
        };
        let nominal_period = header.imu_rate_hz.map(|r| hz / r);
        let nominal_period_s = header.imu_rate_hz.filter(|r| *r > 0.0).map(|r| 1.0 / r);
        let mut sc_cfg = SampleClockConfig {
            nominal_period_s,
            causal: cfg.causal,
            ..Default::default()
        };
        if let Some(l) = cfg
            .hybrid_lookahead_s
            .filter(|l| l.is_finite() && *l >= 0.0)
        {
            sc_cfg.lookahead_s = l;
            // The samples in that time, at least one.
            sc_cfg.lookahead = nominal_period_s
                .map_or(1.0, |p| (l / p).ceil())
                .clamp(1.0, 1e6) as usize;
        }
        let sample_clock = SampleClock::new(sc_cfg);
        SyncEngine {
            sw: SwClock::new(cfg.sw.clone(), hz),
            cfg,
            header: header.clone(),
            state,
            unwrap: Unwrapper::new(header.counter_bits, reorder, max_forward),
            clock: PpsClock::new(clock_cfg),
            smoother: Smoother::new(),
            tracker: ImuTracker::new(nominal_period),
            rate: RateEstimator::default(),
            pending_imu: VecDeque::new(),
            pending_gnss: VecDeque::new(),
            pending_marks: VecDeque::new(),
            mark_residuals: crate::stats::Moments::default(),
            imu_seq: 0,
            now: 0,
            first_counter: None,
            tick_s: 1.0 / hz,
            counts: RecordCounts::default(),
            latencies_ms: Vec::new(),
            negative_latency: 0,
            holdover: Vec::new(),
            open_holdover: None,
            bounds: Default::default(),
            max_bound_s: 0.0,
            last_time: None,
            nonincreasing: 0,
            logging_gaps: Vec::new(),
            logging_gap_count: 0,
            lost_in_logging_gaps: 0,
            first_time: None,
            backwards: 0,
            reorders: 0,
            resets: 0,
            pps_ignored: 0,
            unstamped: 0,
            diag: Diagnostics::default(),
            out_of_order_imu: 0,
            rejected_pulses: Vec::new(),
            sample_clock,
            hybrid_origin: None,
            first_imu_counters: Vec::new(),
            hybrid_reason: None,
            next_hint: ImuHint::default(),
            carried_hint: ImuHint::default(),
        }
    }

    /// `n` samples are known lost before the next `imu` record (a serial
    /// reader saw their lines arrive corrupted). Hybrid mode counts them
    /// there, whatever the timing shows; other modes find losses from
    /// counters alone.
    pub fn note_imu_lost(&mut self, n: u32) {
        self.next_hint.lost = self.next_hint.lost.saturating_add(n);
    }

    /// The IMU stream restarted before the next `imu` record (its port
    /// was reopened; the IMU may have restarted its sample clock). Hybrid
    /// mode starts its sample clock afresh there and counts the samples of
    /// the gap as lost.
    pub fn note_imu_restart(&mut self) {
        self.next_hint.restart = true;
    }

    /// The next `imu` record was read together with `n` more sample lines
    /// after it (all with the read's counter). Hybrid mode takes it as
    /// received `n` periods earlier for the envelope, and counts its
    /// lookahead from the read.
    pub fn note_imu_read_behind(&mut self, n: u32) {
        self.next_hint.behind = n;
    }

    /// Current lock state of the hardware clock.
    pub fn lock_state(&self) -> LockState {
        self.clock.state()
    }

    /// Pushes one record (line 0: not from a file).
    pub fn push(&mut self, rec: RigRecord) -> Vec<SyncOutput> {
        let mut out = Vec::new();
        self.push_into(rec, 0, &mut out);
        out
    }

    /// Pushes one record read at `line`; outputs are appended to `out`.
    pub fn push_into(&mut self, rec: RigRecord, line: usize, out: &mut Vec<SyncOutput>) {
        let mut hint = ImuHint::default();
        if let RigRecord::Imu { counter, .. } = rec {
            hint = std::mem::take(&mut self.next_hint);
            if self.first_imu_counters.len() <= JITTER_INTERVALS {
                self.first_imu_counters.push(counter);
            }
        }
        match rec {
            RigRecord::Imu { .. } => self.counts.imu += 1,
            RigRecord::Pps { .. } => self.counts.pps += 1,
            RigRecord::Gnss(_) => self.counts.gnss += 1,
            RigRecord::Mark { .. } => self.counts.marks += 1,
            RigRecord::Heading(_) => self.counts.headings += 1,
        }
        if let Engine::Undecided(buf) = &mut self.state {
            let c = rec.counter();
            buf.push((rec, line, hint));
            let first = buf[0].0.counter();
            let span = self.unwrap_span(first, c);
            // Hardware when a pulse came; but wait for 200 imu records
            // (their interval jitter tells captures from receive times).
            let pps = self.counts.pps > 0;
            let enough_imu = self.first_imu_counters.len() > 200;
            if pps && (enough_imu || span > self.cfg.auto_wait_s) {
                self.decide(true, out);
            } else if span > self.cfg.auto_wait_s {
                self.decide(false, out);
            }
            return;
        }
        self.process(rec, line, hint, out);
    }

    /// Counter seconds from `a` to `b` (modular, for the auto decision).
    fn unwrap_span(&self, a: u64, b: u64) -> f64 {
        let bits = self.header.counter_bits;
        let d = if bits >= 64 {
            b.wrapping_sub(a)
        } else {
            b.wrapping_sub(a) & ((1u64 << bits) - 1)
        };
        d as f64 * self.tick_s
    }

    /// Robust spread (1.4826·MAD) of the intervals of the first `imu`
    /// counters (s); `None` below 20 intervals.
    fn interval_jitter_s(&self) -> Option<f64> {
        let c = &self.first_imu_counters;
        if c.len() < 21 {
            return None;
        }
        let mut d: Vec<f64> = c
            .windows(2)
            .map(|w| self.unwrap_span(w[0], w[1]))
            .filter(|d| *d < 1.0) // wraps and gaps are not jitter
            .collect();
        if d.len() < 20 {
            return None;
        }
        let m = super::fit::median(&mut d);
        let mut dev: Vec<f64> = d.iter().map(|x| (x - m).abs()).collect();
        Some(1.4826 * super::fit::median(&mut dev))
    }

    fn decide(&mut self, hw: bool, out: &mut Vec<SyncOutput>) {
        let next = if !hw {
            Engine::Sw
        } else if self.header.imu_timing == Some(crate::io::riglog::ImuTiming::Receive) {
            self.hybrid_reason = Some("header imu_timing: receive".into());
            Engine::Hybrid
        } else if let Some(j) = self
            .interval_jitter_s()
            .filter(|j| *j * 1e6 > RECEIVE_JITTER_US && *j > 20.0 * self.tick_s)
        {
            self.hybrid_reason = Some(format!(
                "imu intervals jitter by {:.3} ms (1.4826·MAD), far beyond the counter tick: receive times, not hardware captures",
                j * 1e3
            ));
            Engine::Hybrid
        } else {
            Engine::Hw
        };
        if let Some(r) = &self.hybrid_reason {
            self.diag.push(
                std::path::Path::new(&self.cfg.source),
                0,
                format!("hybrid sync (1PPS + IMU receive times) chosen: {r}"),
            );
        }
        let Engine::Undecided(buf) = std::mem::replace(&mut self.state, next) else {
            return;
        };
        for (rec, line, hint) in buf {
            self.process(rec, line, hint, out);
        }
    }

    fn unwrap_counter(&mut self, raw: u64, line: usize) -> Option<u64> {
        match self.unwrap.push(raw) {
            Unwrapped::Ok(c) => Some(c),
            Unwrapped::Reordered(c) => {
                self.reorders += 1;
                Some(c)
            }
            Unwrapped::Backwards { ticks } => {
                self.backwards += 1;
                self.diag.push(
                    std::path::Path::new(&self.cfg.source),
                    line,
                    format!(
                        "counter went back by {ticks} ticks ({:.6} s) without wrapping; record skipped",
                        ticks as f64 * self.tick_s
                    ),
                );
                None
            }
            Unwrapped::JumpForward { ticks } => {
                self.backwards += 1;
                self.diag.push(
                    std::path::Path::new(&self.cfg.source),
                    line,
                    format!(
                        "counter jumped forward by {ticks} ticks ({:.3} s); record skipped",
                        ticks as f64 * self.tick_s
                    ),
                );
                None
            }
            Unwrapped::Reset(c) => {
                self.resets += 1;
                self.diag.push(
                    std::path::Path::new(&self.cfg.source),
                    line,
                    "counter restarted (confirmed by three records): new segment, clock re-acquired",
                );
                // No clock relation carries over a reset.
                let cfg = self.clock.cfg.clone();
                let mut fresh = PpsClock::new(cfg);
                fresh.events = std::mem::take(&mut self.clock.events);
                self.clock = fresh;
                self.smoother = Smoother::new();
                Some(c)
            }
        }
    }

    fn process(&mut self, rec: RigRecord, line: usize, hint: ImuHint, out: &mut Vec<SyncOutput>) {
        let hybrid = matches!(self.state, Engine::Hybrid);
        let hw = matches!(self.state, Engine::Hw) || hybrid;
        let counter = self.unwrap_counter(rec.counter(), line);
        if let RigRecord::Imu { values, .. } = rec {
            let seq = self.imu_seq;
            self.imu_seq += 1;
            let Some(c) = counter else {
                // Keep order: an unstamped placeholder.
                let flags = ImuFlags {
                    unstamped: true,
                    ..Default::default()
                };
                self.pending_imu.push_back(PendingImu {
                    seq,
                    counter: self
                        .pending_imu
                        .back()
                        .map(|p| p.counter)
                        .unwrap_or(self.now),
                    values,
                    flags,
                    k: 0,
                    h: self
                        .pending_imu
                        .back()
                        .map(|p| p.h)
                        .unwrap_or(f64::NEG_INFINITY),
                    hint,
                });
                self.drain(out, false);
                return;
            };
            self.note_time(c);
            let (flags, k, h) = if hybrid {
                // Receive times: duplicates by their values; losses are
                // found by the sample clock.
                (self.tracker.classify_sw(&values), 0, 0.0)
            } else if hw {
                (self.tracker.classify_hw(seq, c, &values), 0, 0.0)
            } else {
                let h = self.sw.host(c);
                let mut flags = self.tracker.classify_sw(&values);
                if flags.duplicate {
                    (flags, self.pending_imu.back().map(|p| p.k).unwrap_or(0), h)
                } else {
                    let (k, lost) = self.sw.push_imu(h, hint.lost);
                    if lost > 0 {
                        flags.lost_before = lost;
                        self.tracker.note_lost(seq, lost);
                    }
                    (flags, k, h)
                }
            };
            if hw
                && !hybrid
                && self
                    .pending_imu
                    .back()
                    .is_some_and(|p| c < p.counter && !p.flags.unstamped)
            {
                self.out_of_order_imu += 1;
            }
            self.pending_imu.push_back(PendingImu {
                seq,
                counter: c,
                values,
                flags,
                k,
                h,
                hint,
            });
        } else {
            let Some(c) = counter else {
                return;
            };
            self.note_time(c);
            match rec {
                RigRecord::Pps { .. } => {
                    if hw {
                        if let Err(r) = self.clock.push_pulse(c) {
                            self.note_rejection(c, r);
                        }
                    } else {
                        self.pps_ignored += 1;
                    }
                }
                RigRecord::Gnss(g) => {
                    let h = if hw {
                        self.clock.push_gnss(c, g.time);
                        0.0
                    } else {
                        let h = self.sw.host(c);
                        self.sw.push_gnss(h, g.time);
                        h
                    };
                    self.pending_gnss.push_back(PendingGnss {
                        counter: c,
                        h,
                        what: GnssRecord::Fix(g),
                    });
                }
                RigRecord::Heading(hd) => {
                    // Not a clock observation: its receive time only
                    // orders it among the fixes.
                    let h = if hw { 0.0 } else { self.sw.host(c) };
                    self.pending_gnss.push_back(PendingGnss {
                        counter: c,
                        h,
                        what: GnssRecord::Heading(hd),
                    });
                }
                RigRecord::Mark { time, .. } => {
                    let h = if hw {
                        0.0
                    } else {
                        let h = self.sw.host(c);
                        self.sw.push_mark(h, time);
                        h
                    };
                    self.pending_marks.push_back(PendingMark {
                        counter: c,
                        h,
                        time,
                    });
                }
                RigRecord::Imu { .. } => {}
            }
        }
        self.drain(out, false);
    }

    /// Keeps the time of a pulse rejected after lock (the first 1000);
    /// pulses pending acquisition or confirmation are not rejections yet.
    fn note_rejection(&mut self, c: u64, r: Rejection) {
        let reason = match r {
            Rejection::Spurious => "spurious",
            Rejection::Displaced => "displaced",
            Rejection::Duplicate => "duplicate",
            Rejection::Unconfirmed | Rejection::Acquisition => return,
        };
        if self.clock.has_model() && self.rejected_pulses.len() < 1000 {
            let (t, _) = self.clock.causal_time(c);
            self.rejected_pulses.push(RejectedPulse {
                time: WeekSow::from(t),
                reason: reason.into(),
            });
        }
    }

    fn note_time(&mut self, c: u64) {
        self.first_counter.get_or_insert(c);
        self.now = self.now.max(c);
        self.clock.advance(c);
    }

    /// Stamps every pending record that is ready (all of them when `flush`).
    fn drain(&mut self, out: &mut Vec<SyncOutput>, flush: bool) {
        match self.state {
            Engine::Hw | Engine::Hybrid => self.drain_hw(out, flush),
            Engine::Sw => self.drain_sw(out, flush),
            Engine::Undecided(_) => {}
        }
    }

    fn hw_ready(&self, c: u64, flush: bool) -> bool {
        if !self.clock.has_model() {
            return false;
        }
        if flush || self.cfg.causal {
            return true;
        }
        let need = self.clock.cfg.smooth_half_window_s + 2.0;
        let h = &self.clock.history;
        match h.get(h.partition_point(|p| p.counter <= c)) {
            Some(p) => self.clock.seconds_between(p.counter, self.now) >= need,
            None => self.clock.seconds_between(c, self.now) >= self.cfg.max_lookahead_s,
        }
    }

    /// GPS time, error bound and holdover flag of counter `c`.
    fn hw_time(&mut self, c: u64) -> Option<(GpsTime, f64, bool)> {
        if self.cfg.causal {
            let (t, sd) = self.clock.stamp_causal(c);
            let hold = self.clock.since_last_pulse(c) > 1.5;
            Some((t, sd, hold))
        } else {
            self.smoother.time_at(&self.clock, c)
        }
    }

    fn drain_hw(&mut self, out: &mut Vec<SyncOutput>, flush: bool) {
        let tc = self.cfg.imu_output_delay_s.unwrap_or(0.0);
        let locked_once = self.clock.has_model();
        let hybrid = matches!(self.state, Engine::Hybrid);
        let mut timed = Vec::new();
        while let Some(p) = self.pending_imu.front().copied() {
            if p.flags.unstamped {
                self.pending_imu.pop_front();
                self.pass_unstamped(p, hybrid, &mut timed, out);
                continue;
            }
            if !self.hw_ready(p.counter, flush) {
                break;
            }
            self.pending_imu.pop_front();
            let Some((t, sd, hold)) = self.hw_time(p.counter) else {
                self.pass_unstamped(p, hybrid, &mut timed, out);
                continue;
            };
            if hybrid {
                // The receive time on GPS time, in seconds from a GPS second.
                let origin = *self
                    .hybrid_origin
                    .get_or_insert(t.ns().div_euclid(crate::time::NS_PER_S));
                let rel = (t.ns() - origin * crate::time::NS_PER_S) as f64 * 1e-9;
                let tag = HybridTag {
                    p,
                    bound: sd,
                    hold,
                    unstamped: false,
                };
                if p.flags.duplicate {
                    self.carry_hint(p.hint);
                    self.sample_clock.pass(tag, &mut timed);
                } else {
                    let h = std::mem::take(&mut self.carried_hint);
                    let hint = SampleHint {
                        lost_before: h.lost.saturating_add(p.hint.lost),
                        new_segment: h.restart || p.hint.restart,
                        read_behind: p.hint.behind,
                    };
                    self.sample_clock.push_with(tag, rel, hint, &mut timed);
                }
                continue;
            }
            let mut flags = p.flags;
            flags.holdover = hold;
            flags.before_lock = self
                .clock
                .history
                .front()
                .is_none_or(|f| p.counter < f.counter)
                && self.cfg.causal;
            let bound = sd;
            self.emit_imu(p, t.add_seconds(-tc), bound, flags, out);
        }
        if hybrid {
            if flush {
                self.sample_clock.flush(&mut timed);
            }
            for x in timed {
                self.emit_hybrid(x, tc, out);
            }
        }
        while let Some(g) = self.pending_gnss.front().copied() {
            if !self.hw_ready(g.counter, flush) {
                break;
            }
            self.pending_gnss.pop_front();
            match g.what {
                GnssRecord::Fix(fix) => {
                    if let Some((rx, _, _)) = self.hw_time(g.counter) {
                        self.emit_gnss(fix, rx, out);
                    }
                }
                GnssRecord::Heading(hd) => out.push(SyncOutput::Heading(hd.obs())),
            }
        }
        while let Some(m) = self.pending_marks.front().copied() {
            if !self.hw_ready(m.counter, flush) {
                break;
            }
            self.pending_marks.pop_front();
            if let Some((t, _, _)) = self.hw_time(m.counter) {
                self.mark_residuals.push((t - m.time) as f64 * 1e-9);
            }
        }
        // Memory: history needed only around the oldest pending record.
        let oldest = self
            .pending_imu
            .front()
            .map(|p| p.counter)
            .into_iter()
            .chain(self.pending_gnss.front().map(|g| g.counter))
            .chain(self.pending_marks.front().map(|m| m.counter))
            .min()
            .unwrap_or(self.now);
        if locked_once {
            self.clock.prune_history(oldest.min(self.now));
        }
    }

    fn drain_sw(&mut self, out: &mut Vec<SyncOutput>, flush: bool) {
        let tc = self.cfg.imu_output_delay_s.unwrap_or(0.0);
        let causal = self.cfg.causal;
        while let Some(p) = self.pending_imu.front().copied() {
            if p.flags.unstamped {
                self.pending_imu.pop_front();
                self.emit_unstamped(p, out);
                continue;
            }
            if !self.sw.has_map() && !flush {
                break;
            }
            if !causal && !flush && !self.sw.ready(p.h) {
                break;
            }
            self.pending_imu.pop_front();
            match self.sw.imu_time(p.k, p.h, tc, causal) {
                Some(t) => {
                    let sd = self.sw_sd();
                    self.emit_imu(p, t, 3.0 * sd, p.flags, out);
                }
                None => self.emit_unstamped(p, out),
            }
        }
        while let Some(g) = self.pending_gnss.front().copied() {
            if !self.sw.has_gnss() && !flush {
                break;
            }
            if !causal && !flush && !self.sw.ready(g.h) {
                break;
            }
            self.pending_gnss.pop_front();
            match g.what {
                GnssRecord::Fix(fix) => {
                    if let Some(lat) = self.sw.gnss_latency(g.h, fix.time, causal) {
                        let rx = fix.time.add_seconds(lat);
                        self.emit_gnss(fix, rx, out);
                    }
                }
                GnssRecord::Heading(hd) => out.push(SyncOutput::Heading(hd.obs())),
            }
        }
        while let Some(m) = self.pending_marks.front().copied() {
            if !causal && !flush && !self.sw.ready(m.h) {
                break;
            }
            self.pending_marks.pop_front();
            if let Some(t) = self.sw.host_to_gps(m.h, causal) {
                self.mark_residuals.push((t - m.time) as f64 * 1e-9);
            }
        }
        let oldest = self
            .pending_imu
            .front()
            .map(|p| p.h)
            .into_iter()
            .chain(self.pending_gnss.front().map(|g| g.h))
            .chain(self.pending_marks.front().map(|m| m.h))
            .fold(self.sw.now(), f64::min);
        let keep = if causal {
            oldest
        } else {
            oldest - 0.5 * self.sw.cfg.gnss_window_s
        };
        self.sw.prune(keep);
    }

    /// Jitter estimate of software stamps: an envelope through N points
    /// whose delays above it average `e` is uncertain by about e/N per
    /// coefficient; the factor 2 was calibrated on the synthetic rig
    /// (uniform 1–10 ms delays), where it keeps the estimate above the
    /// measured wander.
    fn sw_sd(&self) -> f64 {
        let gi = if self.sw.imu_fit_points > 0 {
            2.0 * self.sw.last_imu_fit_excess * 2f64.sqrt() / self.sw.imu_fit_points as f64
        } else {
            0.0
        };
        let gg = if self.sw.uses_marks() {
            // A least-squares line through the marks: their scatter over √n.
            let n = self.mark_residuals.n.max(1) as f64;
            self.mark_residuals.std() / n.sqrt()
        } else if self.sw.gnss_fit_points > 0 {
            2.0 * self.sw.last_gnss_fit_excess * 3f64.sqrt() / self.sw.gnss_fit_points as f64
        } else {
            0.0
        };
        (gi * gi + gg * gg).sqrt()
    }

    /// 1σ of the envelope's varying error: an envelope through N points
    /// whose delays above it average `e` is uncertain by about e/N per
    /// coefficient (as `sw_sd`).
    fn hybrid_sd(&self) -> f64 {
        let n = self.sample_clock.fit_points;
        if n == 0 || !self.sample_clock.mean_excess_s.is_finite() {
            return 0.0;
        }
        2.0 * self.sample_clock.mean_excess_s * 3f64.sqrt() / n as f64
    }

    /// A record handed back by the sample clock (hybrid mode).
    fn emit_hybrid(&mut self, x: Timed<HybridTag>, tc: f64, out: &mut Vec<SyncOutput>) {
        let HybridTag {
            p,
            bound,
            hold,
            unstamped,
        } = x.tag;
        let origin = self.hybrid_origin.unwrap_or(0);
        if unstamped || !x.time.is_finite() {
            self.emit_unstamped(p, out);
            return;
        }
        let whole = x.time.floor();
        let t = GpsTime::from_ns(
            (origin + whole as i64) * crate::time::NS_PER_S
                + ((x.time - whole) * 1e9).round() as i64,
        )
        .add_seconds(-tc);
        let mut flags = p.flags;
        flags.holdover = hold;
        if x.sample {
            flags.lost_before = x.lost_before;
            flags.ambiguous = x.ambiguous;
            if x.lost_before > 0 {
                self.tracker.note_lost(p.seq, x.lost_before);
            }
        }
        let period = self.sample_clock.current_period_s().unwrap_or(0.0);
        let mut b = (bound * bound + (3.0 * self.hybrid_sd()).powi(2)).sqrt();
        if flags.ambiguous {
            b = b.max(period);
        }
        self.emit_imu(p, t, b, flags, out);
    }

    /// A sample that cannot be stamped: through the sample clock in hybrid
    /// mode (it still holds a place in the sample count), else out as is.
    fn pass_unstamped(
        &mut self,
        p: PendingImu,
        hybrid: bool,
        timed: &mut Vec<Timed<HybridTag>>,
        out: &mut Vec<SyncOutput>,
    ) {
        if hybrid {
            self.carry_hint(p.hint);
            let tag = HybridTag {
                p,
                bound: f64::INFINITY,
                hold: false,
                unstamped: true,
            };
            self.sample_clock.pass(tag, timed);
        } else {
            self.emit_unstamped(p, out);
        }
    }

    /// A hint of a record that is not a sample goes to the next sample.
    fn carry_hint(&mut self, h: ImuHint) {
        let c = &mut self.carried_hint;
        c.lost = c.lost.saturating_add(h.lost);
        c.restart |= h.restart;
    }

    fn emit_unstamped(&mut self, p: PendingImu, out: &mut Vec<SyncOutput>) {
        self.unstamped += 1;
        let mut flags = p.flags;
        flags.unstamped = true;
        out.push(SyncOutput::Imu(StampedImu {
            seq: p.seq,
            time: GpsTime::EPOCH,
            bound_s: f64::INFINITY,
            values: p.values,
            flags,
        }));
    }

    fn emit_imu(
        &mut self,
        p: PendingImu,
        t: GpsTime,
        bound: f64,
        flags: ImuFlags,
        out: &mut Vec<SyncOutput>,
    ) {
        if !flags.duplicate {
            if self.last_time.is_some_and(|l| t <= l) {
                self.nonincreasing += 1;
            }
            let lost = self.note_logging_gap(t, flags.lost_before);
            self.last_time = Some(t);
            self.rate.push(t, lost);
            self.bounds.push(bound);
            self.first_time.get_or_insert(t);
        }
        if flags.holdover {
            match &mut self.open_holdover {
                Some(h) => {
                    h.end = WeekSow::from(t);
                    h.max_bound_us = h.max_bound_us.max(bound * 1e6);
                    h.samples += 1;
                }
                None => {
                    self.open_holdover = Some(HoldoverSpan {
                        start: WeekSow::from(t),
                        end: WeekSow::from(t),
                        duration_s: 0.0,
                        max_bound_us: bound * 1e6,
                        samples: 1,
                    })
                }
            }
        } else if let Some(mut h) = self.open_holdover.take() {
            h.duration_s = h.end.seconds_since(&h.start);
            self.holdover.push(h);
        }
        self.max_bound_s = self.max_bound_s.max(bound);
        out.push(SyncOutput::Imu(StampedImu {
            seq: p.seq,
            time: t,
            bound_s: bound,
            values: p.values,
            flags,
        }));
    }

    /// A stamp more than [`LOGGING_GAP_S`] after the previous one: a
    /// logging gap (the logger stopped writing), kept apart from random
    /// loss. Returns the samples missing before `t`: the sync's count, or
    /// the gap over the mean period so far when that is more (a software
    /// clock may not see a whole gap as loss).
    fn note_logging_gap(&mut self, t: GpsTime, lost_before: u32) -> u32 {
        let Some(last) = self.last_time else {
            return lost_before;
        };
        let gap_s = t.seconds_since(last);
        if gap_s <= LOGGING_GAP_S {
            return lost_before;
        }
        let missing = self
            .rate
            .rate_hz()
            .map(|hz| ((gap_s * hz).round() - 1.0).clamp(0.0, u32::MAX as f64) as u32)
            .unwrap_or(0)
            .max(lost_before);
        self.lost_in_logging_gaps += lost_before as u64;
        self.logging_gap_count += 1;
        if self.logging_gaps.len() < 1000 {
            self.logging_gaps.push(LoggingGap {
                start: WeekSow::from(last),
                length_s: gap_s,
                samples_missing: missing as u64,
            });
        }
        missing
    }

    fn emit_gnss(&mut self, fix: RigGnss, rx: GpsTime, out: &mut Vec<SyncOutput>) {
        let lat = rx.seconds_since(fix.time);
        if lat < 0.0 {
            self.negative_latency += 1;
        }
        self.latencies_ms.push((lat * 1e3) as f32);
        out.push(SyncOutput::Gnss(StampedGnss {
            time: fix.time,
            received: rx,
            latency_s: lat,
            lat_deg: fix.lat_deg,
            lon_deg: fix.lon_deg,
            h_m: fix.h_m,
            sd_m: fix.sd_m,
        }));
    }

    /// Ends the stream: stamps everything still pending and returns the
    /// report. Errors when nothing could be put on GPS time.
    pub fn finish(mut self) -> Result<(Vec<SyncOutput>, SyncReport), Error> {
        let mut out = Vec::new();
        let src = std::path::PathBuf::from(&self.cfg.source);
        if matches!(self.state, Engine::Undecided(_)) {
            self.decide(self.counts.pps > 0, &mut out);
        }
        let total = self.counts.imu + self.counts.pps + self.counts.gnss;
        if total == 0 {
            return Err(Error::NoData {
                path: src,
                msg: "empty log: no pps, gnss or imu records".into(),
            });
        }
        let hybrid = matches!(self.state, Engine::Hybrid);
        let hw = matches!(self.state, Engine::Hw) || hybrid;
        if hw && !self.clock.has_model() {
            let msg = if self.counts.pps == 0 {
                "no pps records: hardware sync impossible (use --mode sw for receive-time sync)"
                    .to_string()
            } else if self.counts.gnss == 0 {
                format!(
                    "{} pps records but no gnss messages: the pulses cannot be labelled with GPS seconds",
                    self.counts.pps
                )
            } else {
                format!(
                    "{} pps records and {} gnss messages, but no 4 consistent pulses labelled by ≥ 3 messages: no GPS time",
                    self.counts.pps, self.counts.gnss
                )
            };
            return Err(Error::NoData { path: src, msg });
        }
        if !hw && !self.sw.has_gnss() {
            return Err(Error::NoData {
                path: src,
                msg: format!(
                    "software sync needs at least 3 gnss messages to map receive time to GPS time; found {}",
                    self.counts.gnss
                ),
            });
        }
        self.drain(&mut out, true);
        if let Some(mut h) = self.open_holdover.take() {
            h.duration_s = h.end.seconds_since(&h.start);
            self.holdover.push(h);
        }
        let mut report = self.report(hw);
        report.implausible = report.check_plausible();
        Ok((out, report))
    }

    fn report(&mut self, hw: bool) -> SyncReport {
        let mut lat = self.latencies_ms.clone();
        lat.sort_by(|a, b| a.total_cmp(b));
        let q = |p: f64| -> Option<f64> {
            if lat.is_empty() {
                None
            } else {
                let i = ((lat.len() - 1) as f64 * p).round() as usize;
                Some(lat[i] as f64)
            }
        };
        let gnss = GnssReport {
            messages: self.counts.gnss,
            stamped: lat.len() as u64,
            latency_ms: LatencyStats {
                min: q(0.0),
                median: q(0.5),
                p99: q(0.99),
                max: q(1.0),
            },
            negative_latency: self.negative_latency,
            latency_histogram_ms: Histogram::of(
                &lat.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(),
                1.0,
                100,
            ),
        };
        let timeline = self.timeline(hw);
        let clock = &self.clock;
        let freq = &clock.freq_ppm;
        let counter = CounterReport {
            nominal_hz: self.header.counter_hz,
            bits: self.header.counter_bits,
            wraps: self.unwrap.wraps,
            went_backwards_or_jumped: self.backwards,
            reordered_records: self.reorders,
            resets: self.resets,
            freq_error_ppm: (hw && freq.n > 0).then(|| RangeStats {
                mean: freq.mean(),
                min: freq.min,
                max: freq.max,
            }),
        };
        let odd = self.rate.odd();
        let imu = ImuReport {
            records: self.counts.imu,
            kind: self.header.imu_kind,
            nominal_rate_hz: self.header.imu_rate_hz,
            rate_hz: self.rate.rate_hz(),
            rate_ls_hz: self.rate.rate_ls_hz(),
            lost: self.tracker.lost,
            duplicated: self.tracker.duplicated,
            irregular_intervals: self.tracker.irregular,
            unstamped: self.unstamped,
            out_of_order: self.out_of_order_imu,
            gaps: self.tracker.gaps.clone(),
            gap_count: self.tracker.gaps_total,
            samples_per_gps_second: self
                .rate
                .per_second
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
            odd_seconds: odd
                .into_iter()
                .map(|(s, c)| OddSecond {
                    gps_second: s,
                    samples: c,
                })
                .collect(),
            output_delay_s: self.cfg.imu_output_delay_s.unwrap_or(0.0),
            timestamps_not_increasing: self.nonincreasing,
            logging_gaps: self.logging_gaps.clone(),
            logging_gap_count: self.logging_gap_count,
            lost_in_logging_gaps: self.lost_in_logging_gaps,
            interval_jitter_us: self.interval_jitter_s().map(|j| j * 1e6),
        };
        let hybrid = matches!(self.state, Engine::Hybrid).then(|| {
            let sc = &self.sample_clock;
            let period = sc.current_period_s();
            let tc = self.cfg.imu_output_delay_s.unwrap_or(0.0);
            HybridReport {
                period_s: period,
                rate_hz: period.filter(|p| *p > 0.0).map(|p| 1.0 / p),
                imu_clock_ppm: match (period, self.header.imu_rate_hz) {
                    (Some(p), Some(r)) if p > 0.0 && r > 0.0 => Some((1.0 / (p * r) - 1.0) * 1e6),
                    _ => None,
                },
                mean_latency_above_fastest_ms: sc.mean_excess_s * 1e3,
                envelope_points: sc.fit_points,
                ambiguous_samples: sc.ambiguous,
                clock_segments: sc.segments,
                jitter_sd_us: self.hybrid_sd() * 1e6,
                assumed_fastest_latency_s: tc,
                unobservable: format!(
                    "every IMU stamp is the sample instant plus the fastest transport latency (IMU output delay + fastest serial/driver latency) minus the {tc} s subtracted (--imu-output-delay or the header's imu_output_delay_s): receive times cannot observe it. Estimate it in the filter's time-offset state (--estimate-time-offset) or measure it once with a sync pin."
                ),
            }
        });
        let pps = hw.then(|| PpsReport {
            counts: clock.counts.clone(),
            innovation_rms_us: (clock.innovation.n > 0).then(|| clock.innovation.rms() * 1e6),
            ignored: 0,
        });
        let software = (!hw).then(|| {
            let sd = self.sw_sd();
            SoftwareReport {
                imu_envelope_mean_delay_ms: self.sw.last_imu_fit_excess * 1e3,
                gnss_envelope_mean_delay_ms: self.sw.last_gnss_fit_excess * 1e3,
                host_clock_error_ppm: self.sw.host_ppm,
                jitter_sd_ms: sd * 1e3,
                assumed_fastest_gnss_latency_s: self.sw.cfg.gnss_min_latency_s,
                assumed_fastest_imu_latency_s: self.sw.cfg.imu_min_latency_s,
                unobservable: if self.sw.uses_marks() {
                    "receiver time marks map host time to GPS time; every IMU stamp is still off by the same constant: the fastest true IMU latency − assumed. Estimate it in the filter or measure it once with 1PPS.".into()
                } else {
                    "every IMU stamp is off by the same constant: (fastest true GNSS latency − assumed) − (fastest true IMU latency − assumed). Receive times alone cannot observe it; estimate it in the filter, use receiver time marks, or measure it once with 1PPS.".into()
                },
                pps_records_ignored: self.pps_ignored,
            }
        });
        SyncReport {
            mode: if matches!(self.state, Engine::Hybrid) {
                "hybrid"
            } else if hw {
                "hw"
            } else {
                "sw"
            }
            .into(),
            causal: self.cfg.causal,
            records: self.counts.clone(),
            counter,
            lock_timeline: timeline,
            pps,
            rejected_pulses: self.rejected_pulses.clone(),
            holdover: self.holdover.clone(),
            imu,
            gnss,
            software,
            hybrid,
            implausible: Vec::new(),
            marks: (self.counts.marks > 0).then(|| {
                let r = &self.mark_residuals;
                MarkReport {
                    received: self.counts.marks,
                    compared: r.n as u64,
                    residual_mean_us: r.mean() * 1e6,
                    residual_rms_us: r.rms() * 1e6,
                    residual_max_abs_us: r.max_abs * 1e6,
                    used_as_clock_reference: !hw && self.sw.uses_marks(),
                }
            }),
            stamp_bound_us: BoundStats {
                mean: (self.bounds.n > 0).then(|| self.bounds.mean() * 1e6),
                max: (self.bounds.n > 0).then_some(self.max_bound_s * 1e6),
            },
            first_stamp: self.first_time.map(WeekSow::from),
            last_stamp: self.last_time.map(WeekSow::from),
            diagnostics: self.diag.clone(),
            truth: None,
        }
    }

    fn timeline(&self, hw: bool) -> Vec<LockSpan> {
        let (Some(first), Some(last)) = (self.first_time, self.last_time) else {
            return Vec::new();
        };
        if !hw {
            return vec![LockSpan {
                state: "software".into(),
                start: WeekSow::from(first),
                end: WeekSow::from(last),
            }];
        }
        let mut spans = Vec::new();
        let mut cur_state = LockState::Acquiring;
        let mut cur_start = first;
        for e in &self.clock.events {
            let t = e.time.max(first).min(last);
            if e.state != cur_state {
                if t > cur_start {
                    spans.push(LockSpan {
                        state: format!("{cur_state:?}").to_lowercase(),
                        start: WeekSow::from(cur_start),
                        end: WeekSow::from(t),
                    });
                }
                cur_state = e.state;
                cur_start = t;
            }
        }
        if last > cur_start {
            spans.push(LockSpan {
                state: format!("{cur_state:?}").to_lowercase(),
                start: WeekSow::from(cur_start),
                end: WeekSow::from(last),
            });
        }
        spans
    }
}
