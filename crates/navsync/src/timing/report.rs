//! The synchronization report (`sync_report.json`) and the comparison of
//! stamps with a truth file.

#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::clock::PulseCounts;
use super::imu::ImuGap;
use crate::error::{Diagnostics, Error};
use crate::io::riglog::ImuKind;
use crate::io::text::{LineReader, is_blank_or_comment, parse_seconds_ns, split_fields};
use crate::time::GpsTime;

/// A GPS time as week and seconds of week.
#[derive(Copy, Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct WeekSow {
    /// GPS week (weeks since 1980-01-06).
    pub week: i64,
    /// Seconds of GPS week.
    pub sow: f64,
}

impl From<GpsTime> for WeekSow {
    fn from(t: GpsTime) -> Self {
        WeekSow {
            week: t.week(),
            sow: t.sow(),
        }
    }
}

impl WeekSow {
    /// `self − other` in seconds.
    pub fn seconds_since(&self, other: &WeekSow) -> f64 {
        (self.week - other.week) as f64 * 604_800.0 + (self.sow - other.sow)
    }
}

/// How many records of each kind the log held.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct RecordCounts {
    /// `imu` records (samples, duplicates included).
    pub imu: u64,
    /// `pps` records (1PPS edges latched by the counter).
    pub pps: u64,
    /// `gnss` records (fixes with their receive counter).
    pub gnss: u64,
    /// `mark` records (edges time-marked by the receiver, TIM-TM2).
    #[serde(default)]
    pub marks: u64,
    /// `heading` records (receiver headings, passed through on their GPS
    /// time); absent when there are none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub headings: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// Receiver time marks (`mark` records) against the clock model: with
/// 1PPS they check the whole timing chain; without, they are the
/// host→GPS map of software sync.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct MarkReport {
    /// `mark` records in the log.
    pub received: u64,
    /// Marks stamped through the counter and compared with their GPS time.
    pub compared: u64,
    /// Counter-stamped time − the receiver's time of the mark (µs).
    pub residual_mean_us: f64,
    /// RMS of the residuals (µs).
    pub residual_rms_us: f64,
    /// Largest absolute residual (µs).
    pub residual_max_abs_us: f64,
    /// Software sync: the marks, not the GNSS receive times, map host time
    /// to GPS time.
    pub used_as_clock_reference: bool,
}

/// Mean, minimum and maximum of a quantity.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RangeStats {
    /// Mean.
    pub mean: f64,
    /// Minimum.
    pub min: f64,
    /// Maximum.
    pub max: f64,
}

/// The counter: its frequency, width, wraps and faults.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CounterReport {
    pub(crate) nominal_hz: f64,
    /// Counter width (bits) from the log header; it wraps at 2^bits.
    pub bits: u32,
    /// Counter wraps unwrapped.
    pub wraps: u64,
    /// Records skipped because the counter went back (or jumped) without wrapping.
    pub(crate) went_backwards_or_jumped: u64,
    /// Records slightly out of counter order (within tolerance).
    pub(crate) reordered_records: u64,
    /// Confirmed counter restarts.
    pub resets: u64,
    /// Counter frequency error (ppm; positive = counter fast), over the
    /// causal fits at each accepted pulse.
    pub freq_error_ppm: Option<RangeStats>,
}

/// A span of one lock state of the clock model.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LockSpan {
    /// `acquiring`, `locked` or `holdover` (hardware/hybrid sync); `software` for
    /// software sync (one span over the whole run).
    pub state: String,
    /// Start of the span (GPS time): the first IMU stamp or the state change.
    pub start: WeekSow,
    /// End of the span (GPS time): the next state change or the last IMU stamp.
    pub end: WeekSow,
}

/// A span of IMU stamps made in holdover (no recent pulse).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HoldoverSpan {
    /// First and last IMU stamp made without a pulse within 1.5 s.
    pub start: WeekSow,
    /// GPS time of the last stamp in the span.
    pub end: WeekSow,
    /// From `start` to `end` (s).
    pub duration_s: f64,
    /// Largest error bound of a stamp in the span (µs).
    pub max_bound_us: f64,
    /// IMU stamps in the span.
    pub samples: u64,
}

/// The 1PPS edges: counts and the fit of accepted ones.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PpsReport {
    /// Pulse outcomes (flattened into this object in the JSON).
    #[serde(flatten)]
    pub counts: PulseCounts,
    /// RMS of accepted pulses' innovations against the causal prediction (µs).
    pub innovation_rms_us: Option<f64>,
    /// Always 0 here; software sync counts ignored `pps` records in
    /// `software.pps_records_ignored`.
    pub ignored: u64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct OddSecond {
    pub(crate) gps_second: i64,
    pub samples: u32,
}

/// The IMU records: rate, losses and stamp quality.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ImuReport {
    /// `imu` records in the log.
    pub records: u64,
    /// What the six values are: rates or increments.
    pub kind: ImuKind,
    /// Rate from the log header's `imu_rate_hz` (Hz); `None` when absent.
    pub nominal_rate_hz: Option<f64>,
    /// The IMU's true mean rate from its stamps (Hz), lost samples counted.
    pub rate_hz: Option<f64>,
    /// Least-squares rate (stamps on sample index) (Hz).
    pub(crate) rate_ls_hz: Option<f64>,
    /// Samples lost in gaps (sum of the gaps' `lost`).
    pub lost: u64,
    /// Duplicated records (same counter tick, or identical values in software sync).
    pub duplicated: u64,
    /// Intervals more than a quarter period off a whole number of periods.
    pub irregular_intervals: u64,
    /// Samples output without a GPS time (flagged `unstamped`).
    pub unstamped: u64,
    /// Samples whose counter was below the previous one's (`hw` mode only).
    pub out_of_order: u64,
    /// Gaps (first 1000): record index after the gap, samples lost.
    pub gaps: Vec<ImuGap>,
    /// Logging gaps: stamp intervals over [`LOGGING_GAP_S`] (the first
    /// 1000), where the logger stopped writing; reported, not counted as
    /// random loss in the plausibility checks.
    #[serde(default)]
    pub logging_gaps: Vec<LoggingGap>,
    /// All logging gaps.
    #[serde(default)]
    pub logging_gap_count: u64,
    /// Of `lost`, the samples inside logging gaps.
    #[serde(default)]
    pub lost_in_logging_gaps: u64,
    pub(crate) gap_count: u64,
    /// Samples counted in each full GPS second → how many seconds (seed 002).
    pub samples_per_gps_second: BTreeMap<String, u64>,
    /// Seconds whose count is off the most common one by more than one.
    pub(crate) odd_seconds: Vec<OddSecond>,
    /// T_c subtracted from every stamp (s).
    pub output_delay_s: f64,
    pub(crate) timestamps_not_increasing: u64,
    /// Robust spread (1.4826·MAD) of the intervals between the first
    /// ≤ 2000 `imu` counters (µs): about a tick for hardware captures,
    /// milliseconds for receive times.
    #[serde(default)]
    pub interval_jitter_us: Option<f64>,
}

/// A stretch without IMU samples longer than [`LOGGING_GAP_S`]: the
/// logger stopped writing (a full card buffer, a logging restart), not a
/// link that drops frames at random.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LoggingGap {
    /// GPS time of the last sample before the gap.
    pub start: WeekSow,
    /// Time from that sample to the next (s).
    pub length_s: f64,
    /// Sample periods missing in it.
    pub samples_missing: u64,
}

/// Hybrid synchronization: 1PPS maps the counter to GPS time, the IMU's
/// sample instants come from its receive times by a model of its own
/// sample clock (see `timing::sampleclock`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HybridReport {
    /// The IMU's sample period from the envelope (s) and its rate (Hz).
    pub period_s: Option<f64>,
    /// Rate of the sample clock, `1 / period_s` (Hz).
    pub rate_hz: Option<f64>,
    /// The IMU clock's frequency error against the nominal rate (ppm).
    pub imu_clock_ppm: Option<f64>,
    /// Mean receive latency above the fastest one (ms).
    pub mean_latency_above_fastest_ms: f64,
    /// Points in the last envelope fit.
    pub(crate) envelope_points: usize,
    /// Samples whose place next to a loss was not certain (may be one
    /// period off).
    pub ambiguous_samples: u64,
    /// Sample-clock segments started after the first: the port reopened,
    /// or the IMU's rate changed. Each starts its envelope afresh, so its
    /// first second is stamped from fewer receive times.
    #[serde(default)]
    pub clock_segments: u64,
    /// Estimated 1σ of the stamps' varying error (µs), constant excluded.
    pub jitter_sd_us: f64,
    /// The constant subtracted as the fastest transport latency (s).
    pub(crate) assumed_fastest_latency_s: f64,
    /// Explains the constant error receive times cannot observe, and how to
    /// estimate it.
    pub unobservable: String,
}

/// A figure of the log that is not plausible, with its likely cause and
/// the option that fixes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Implausible {
    /// The figure and its value.
    pub what: String,
    /// Its likely cause.
    pub cause: String,
    /// The option or change that fixes it.
    pub fix: String,
}

/// Statistics of a latency (ms).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LatencyStats {
    /// Minimum; `None` without stamped messages.
    pub min: Option<f64>,
    /// Median.
    pub median: Option<f64>,
    pub(crate) p99: Option<f64>,
    /// Maximum.
    pub max: Option<f64>,
}

/// Counts in equal bins: bin `i` holds values in
/// `[start + i·width, start + (i+1)·width)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Histogram {
    /// Lower edge of bin 0.
    pub start: f64,
    /// Bin width (same unit as the values).
    pub width: f64,
    /// Values in each bin.
    pub counts: Vec<u64>,
}

impl Histogram {
    /// Bins of `width` (widened so that at most `max_bins` cover the
    /// values) starting at a multiple of the width; `None` without values.
    pub fn of(values: &[f64], width: f64, max_bins: usize) -> Option<Histogram> {
        if !(width.is_finite() && width > 0.0) {
            return None;
        }
        let finite = || values.iter().copied().filter(|v| v.is_finite());
        let lo = finite().reduce(f64::min)?;
        let hi = finite().reduce(f64::max)?;
        let mut w = width;
        while ((hi - lo) / w).floor() as usize + 1 > max_bins.max(1) {
            w *= 2.0;
        }
        let start = (lo / w).floor() * w;
        let n = ((hi - start) / w).floor() as usize + 1;
        let mut counts = vec![0u64; n];
        for v in finite() {
            let i = (((v - start) / w).floor() as usize).min(n - 1);
            counts[i] += 1;
        }
        Some(Histogram {
            start,
            width: w,
            counts,
        })
    }
}

/// The GNSS messages: counts and latencies.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GnssReport {
    /// `gnss` records in the log.
    pub messages: u64,
    /// Messages put on GPS time (the latencies counted).
    pub stamped: u64,
    /// Latency from validity (the 1PPS edge for whole-second fixes) to the
    /// last byte (ms), seed 002.
    pub latency_ms: LatencyStats,
    pub(crate) negative_latency: u64,
    /// The latencies (ms) in bins of 1 ms (or wider: at most 100 bins).
    #[serde(default)]
    pub latency_histogram_ms: Option<Histogram>,
}

/// A 1PPS edge the clock model did not use, at its GPS time (causal
/// estimate).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RejectedPulse {
    /// GPS time of the edge (causal estimate).
    pub time: WeekSow,
    /// `spurious` (far from any GPS second), `displaced` (near one but
    /// outside the gate) or `duplicate`.
    pub reason: String,
}

/// Software synchronization: host-clock estimates and their limits.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SoftwareReport {
    pub(crate) imu_envelope_mean_delay_ms: f64,
    pub(crate) gnss_envelope_mean_delay_ms: f64,
    /// Host clock's frequency error against GPS time (ppm); `None` when not
    /// estimated.
    pub host_clock_error_ppm: Option<f64>,
    /// Estimated standard deviation of the stamps' varying error (ms).
    pub jitter_sd_ms: f64,
    pub(crate) assumed_fastest_gnss_latency_s: f64,
    pub(crate) assumed_fastest_imu_latency_s: f64,
    /// Explains the constant error receive times cannot observe, and how to
    /// estimate it.
    pub unobservable: String,
    pub(crate) pps_records_ignored: u64,
}

/// Mean and maximum of a stamp error bound (µs).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BoundStats {
    /// Mean bound (µs); `None` without stamped samples.
    pub mean: Option<f64>,
    /// Largest bound (µs); `None` without stamped samples.
    pub max: Option<f64>,
}

/// Stamps compared with the true times.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TruthComparison {
    /// Stamps compared (one per `imu` record with a GPS time).
    pub compared: u64,
    /// RMS of the stamp error, stamp − truth (µs).
    pub rms_us: f64,
    /// Largest absolute error (µs).
    pub max_abs_us: f64,
    /// Mean error (µs): the constant part.
    pub mean_us: f64,
    /// Standard deviation about the mean (µs): the jitter.
    pub sd_us: f64,
    /// Share of stamps whose error lies within their reported bound.
    pub within_bound: f64,
    /// Over holdover stamps only.
    pub holdover_compared: u64,
    /// RMS error of the holdover stamps (µs); 0 without any.
    pub holdover_rms_us: f64,
    /// Largest absolute error of the holdover stamps (µs).
    pub holdover_max_abs_us: f64,
    /// Share of holdover stamps within their bound.
    pub holdover_within_bound: f64,
    /// Largest difference between consecutive errors (µs): a jump.
    pub max_step_us: f64,
}

/// Everything `navsync sync` learned.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SyncReport {
    /// `hw` (1PPS), `hybrid` (1PPS + IMU receive times) or `sw` (receive times
    /// only).
    pub mode: String,
    /// Stamps made from past data only (`--causal`).
    pub causal: bool,
    /// Records of each kind in the log.
    pub records: RecordCounts,
    /// The counter's width, wraps and faults.
    pub counter: CounterReport,
    /// Lock states over the run, in time order.
    pub lock_timeline: Vec<LockSpan>,
    /// The 1PPS edges; `None` in software sync.
    pub pps: Option<PpsReport>,
    /// Rejected pulses after lock (the first 1000).
    #[serde(default)]
    pub rejected_pulses: Vec<RejectedPulse>,
    /// Holdover spans of the IMU stamps, in time order.
    pub holdover: Vec<HoldoverSpan>,
    /// The IMU records.
    pub imu: ImuReport,
    /// The GNSS messages.
    pub gnss: GnssReport,
    /// Software synchronization; `None` with 1PPS (hw and hybrid).
    pub software: Option<SoftwareReport>,
    /// Hybrid synchronization (1PPS + IMU receive times).
    #[serde(default)]
    pub hybrid: Option<HybridReport>,
    /// Implausible figures (empty for a clean log).
    #[serde(default)]
    pub implausible: Vec<Implausible>,
    /// Receiver time marks, when the log has `mark` records.
    #[serde(default)]
    pub marks: Option<MarkReport>,
    /// Error bounds of the IMU stamps (µs).
    pub stamp_bound_us: BoundStats,
    /// GPS time of the first IMU stamp; `None` when nothing was stamped.
    pub first_stamp: Option<WeekSow>,
    /// GPS time of the last IMU stamp.
    pub last_stamp: Option<WeekSow>,
    /// Warnings and skipped lines of the run.
    pub diagnostics: Diagnostics,
    /// Stamps against a truth file (`--truth`); `None` without one.
    pub truth: Option<TruthComparison>,
}

/// Accumulates stamp errors against truth, in record order.
#[derive(Clone, Debug, Default)]
pub(crate) struct TruthAccumulator {
    all: crate::stats::Moments,
    hold: crate::stats::Moments,
    within: u64,
    hold_within: u64,
    prev_err: Option<f64>,
    max_step: f64,
}

impl TruthAccumulator {
    /// One stamp: estimated `t`, true `truth`, its bound, holdover flag.
    pub(crate) fn push(&mut self, t: GpsTime, truth: GpsTime, bound_s: f64, holdover: bool) {
        let e = (t - truth) as f64 * 1e-9;
        self.all.push(e);
        if e.abs() <= bound_s {
            self.within += 1;
        }
        if holdover {
            self.hold.push(e);
            if e.abs() <= bound_s {
                self.hold_within += 1;
            }
        }
        if let Some(p) = self.prev_err {
            self.max_step = self.max_step.max((e - p).abs());
        }
        self.prev_err = Some(e);
    }

    pub(crate) fn finish(&self) -> TruthComparison {
        let n = self.all.n.max(1) as f64;
        let hn = self.hold.n.max(1) as f64;
        TruthComparison {
            compared: self.all.n as u64,
            rms_us: self.all.rms() * 1e6,
            max_abs_us: self.all.max_abs * 1e6,
            mean_us: self.all.mean() * 1e6,
            sd_us: self.all.std() * 1e6,
            within_bound: self.within as f64 / n,
            holdover_compared: self.hold.n as u64,
            holdover_rms_us: if self.hold.n > 0 {
                self.hold.rms() * 1e6
            } else {
                0.0
            },
            holdover_max_abs_us: self.hold.max_abs * 1e6,
            holdover_within_bound: self.hold_within as f64 / hn,
            max_step_us: self.max_step * 1e6,
        }
    }
}

/// Reads a truth file of `week sow` lines (one per `imu` record), streaming.
pub(crate) struct TruthTimes {
    lines: LineReader<std::fs::File>,
    path: std::path::PathBuf,
}

impl TruthTimes {
    pub(crate) fn open(path: &Path) -> Result<Self, Error> {
        Ok(TruthTimes {
            lines: LineReader::open(path)?,
            path: path.to_path_buf(),
        })
    }

    /// The next true time; `None` at the end. A bad line is an error (the
    /// file must align with the records).
    pub(crate) fn next_time(&mut self) -> Result<Option<GpsTime>, Error> {
        loop {
            let Some((line, no)) = self.lines.next_line()? else {
                return Ok(None);
            };
            if is_blank_or_comment(line) {
                continue;
            }
            let mut f: [&[u8]; 2] = [b""; 2];
            let n = split_fields(line, &mut f);
            if n < 2 {
                return Err(Error::parse(&self.path, no, "expected 'week sow'"));
            }
            let week: i64 = std::str::from_utf8(f[0])
                .ok()
                .and_then(|s| s.parse().ok())
                .ok_or_else(|| Error::parse(&self.path, no, "week is not an integer"))?;
            let ns = parse_seconds_ns(f[1]).map_err(|e| Error::parse(&self.path, no, e))?;
            return Ok(Some(GpsTime::from_week_ns(week, ns)));
        }
    }
}

/// Formats `week sow` with nanoseconds (the imu_times.txt layout).
pub(crate) fn format_week_sow(out: &mut Vec<u8>, t: GpsTime) {
    crate::io::text::push_u64(out, t.week().max(0) as u64);
    out.push(b' ');
    t.write_sow(out);
    out.push(b'\n');
}

/// Share of records above which losses, duplicates or irregular
/// intervals make a log implausible (i2Nav's acquisition guide asks for
/// loss rates below 1e-5: Tang, Zhang & Niu, "MEMS IMU raw data
/// acquisition and time synchronization pitfalls", 2022).
pub(crate) const IMPLAUSIBLE_SHARE: f64 = 0.01;
/// Stamp interval (s) beyond which missing IMU samples are a logging gap,
/// reported on its own and left out of the loss rate: one long silence is
/// not random loss (a link dropping frames loses them spread over the run).
pub const LOGGING_GAP_S: f64 = 1.0;
/// Relative difference of the measured IMU rate from the nominal one
/// above which the rate is implausible (crystals are within 1e-4).
pub(crate) const IMPLAUSIBLE_RATE: f64 = 0.01;
/// Interval jitter of `imu` counters (µs) beyond which they cannot be
/// hardware captures (a capture input is exact to a tick; an interrupt
/// to tens of µs).
pub(crate) const RECEIVE_JITTER_US: f64 = 100.0;

fn ppm_text(ppm: Option<f64>) -> String {
    ppm.map_or_else(|| "unknown".into(), |p| format!("{p:+.2} ppm"))
}

impl SoftwareReport {
    /// One line for people: stamp jitter and host clock error.
    pub fn describe(&self) -> String {
        format!(
            "stamp jitter ≈ {:.4} ms (1σ), host clock {}",
            self.jitter_sd_ms,
            ppm_text(self.host_clock_error_ppm)
        )
    }
}

impl HybridReport {
    /// One line for people: the IMU's sample clock and the stamps' quality
    /// (restarts only when there were some).
    pub fn describe(&self) -> String {
        let mut s = format!(
            "IMU sample clock {:.6} Hz ({}), receive latency above the fastest {:.3} ms mean, stamp jitter ≈ {:.2} µs (1σ), {} samples next to a loss of uncertain place",
            self.rate_hz.unwrap_or(f64::NAN),
            ppm_text(self.imu_clock_ppm),
            self.mean_latency_above_fastest_ms,
            self.jitter_sd_us,
            self.ambiguous_samples
        );
        if self.clock_segments > 0 {
            s += &format!(
                ", the clock restarted {}× (port reopened or rate changed)",
                self.clock_segments
            );
        }
        s
    }
}

impl MarkReport {
    /// One line for people: the marks' residuals against the counter.
    pub fn describe(&self) -> String {
        format!(
            "{} ({} compared): counter-stamped − receiver time mean {:.3} µs, RMS {:.3} µs, max {:.3} µs{}",
            self.received,
            self.compared,
            self.residual_mean_us,
            self.residual_rms_us,
            self.residual_max_abs_us,
            if self.used_as_clock_reference {
                "; they map host time to GPS time"
            } else {
                ""
            }
        )
    }
}

impl SyncReport {
    /// The implausible figures of this report (see [`IMPLAUSIBLE_SHARE`]).
    pub(crate) fn check_plausible(&self) -> Vec<Implausible> {
        let mut v = Vec::new();
        let i = &self.imu;
        let n = i.records.max(1) as f64;
        let receive_like = i.interval_jitter_us.is_some_and(|j| j > RECEIVE_JITTER_US);
        let jitter = i
            .interval_jitter_us
            .map(|j| format!("{:.3} ms", j * 1e-3))
            .unwrap_or_else(|| "-".into());
        let (cause_timing, fix_timing) = if self.mode == "hw" && receive_like {
            (
                format!(
                    "the imu counters jitter by {jitter} between samples: they are receive times (an IMU on a serial port without sync pin), not hardware captures"
                ),
                "run with --mode hybrid (or --mode auto), or add '# imu_timing: receive' to the log header".to_string(),
            )
        } else if self.mode == "sw" && self.records.pps > 0 {
            (
                "software sync ignores the log's pps records".to_string(),
                "run with --mode hybrid (1PPS + receive times) or --mode auto".to_string(),
            )
        } else {
            (
                "the logger or its link drops, repeats or delays IMU frames (buffer overruns, baud rate too low for the IMU rate, a loaded host)".to_string(),
                "fix the acquisition; --force writes the output anyway, gaps flagged".to_string(),
            )
        };
        let mut add = |what: String| {
            v.push(Implausible {
                what,
                cause: cause_timing.clone(),
                fix: fix_timing.clone(),
            })
        };
        // Losses inside logging gaps are the gaps' own finding, not random loss.
        let random_lost = i.lost.saturating_sub(i.lost_in_logging_gaps);
        for (count, name) in [
            (random_lost, "lost"),
            (i.duplicated, "duplicated"),
            (i.irregular_intervals, "irregular intervals"),
        ] {
            let share = count as f64 / n;
            if share > IMPLAUSIBLE_SHARE {
                add(format!(
                    "imu: {count} {name} of {} records ({:.2} %, more than {:.0} %)",
                    i.records,
                    100.0 * share,
                    100.0 * IMPLAUSIBLE_SHARE
                ));
            }
        }
        if let (Some(r), Some(nom)) = (i.rate_hz, i.nominal_rate_hz)
            && nom > 0.0
            && ((r / nom) - 1.0).abs() > IMPLAUSIBLE_RATE
        {
            add(format!(
                "imu: measured rate {r:.3} Hz against the nominal {nom} Hz ({:+.2} %)",
                100.0 * (r / nom - 1.0)
            ));
        }
        if v.is_empty() && self.mode == "hw" && receive_like {
            v.push(Implausible {
                what: format!("imu: intervals jitter by {jitter}, far beyond the counter tick"),
                cause: cause_timing,
                fix: fix_timing,
            });
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::Histogram;

    #[test]
    fn histogram_bins_hold_every_value_once() {
        let v = [69.1, 70.0, 70.9, 83.7, 99.0, f64::NAN];
        let h = Histogram::of(&v, 1.0, 100).unwrap();
        assert_eq!((h.start, h.width, h.counts.len()), (69.0, 1.0, 31));
        assert_eq!(h.counts[0], 1); // 69.1
        assert_eq!(h.counts[1], 2); // 70.0, 70.9
        assert_eq!(h.counts[30], 1); // 99.0
        assert_eq!(h.counts.iter().sum::<u64>(), 5);
        // A wide range doubles the width until 10 bins suffice.
        let h = Histogram::of(&[0.0, 95.0], 1.0, 10).unwrap();
        assert_eq!((h.width, h.counts.len()), (16.0, 6));
        assert!(Histogram::of(&[], 1.0, 10).is_none());
        assert!(Histogram::of(&[1.0], 0.0, 10).is_none());
    }
}
