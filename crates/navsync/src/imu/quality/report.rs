//! The IMU log's quality report: one row per seed 001 criterion, the
//! events found, the counts, per-channel and static-segment findings.

use super::*;

/// Outcome of one criterion.
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// The criterion is met.
    Pass,
    /// Information only: not graded, left out of the verdict.
    Info,
    /// Cannot be decided from the log alone, or marginal.
    Warn,
    /// The criterion is violated.
    Fail,
}

impl Status {
    /// The status as a word for reports.
    pub fn label(self) -> &'static str {
        match self {
            Status::Pass => "PASS",
            Status::Info => "info",
            Status::Warn => "WARN",
            Status::Fail => "FAIL",
        }
    }
}

/// One row of the verdict.
#[derive(Clone, Debug, Serialize)]
pub struct Criterion {
    /// Section of Tang, Zhang & Niu 2022 (seed 001), e.g. "§1.5-5"; or
    /// "noise" for the Allan-deviation rows.
    pub section: &'static str,
    /// The rule, in words.
    pub rule: String,
    /// Outcome of the rule on this log.
    pub status: Status,
    /// What the log shows, with units.
    pub measured: String,
    /// The threshold the measurement was held to.
    pub limit: String,
}

/// Kinds of findings.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EventKind {
    /// A line that did not parse (reported by the reader; no time).
    Malformed,
    /// An interval longer than `gap_factor` nominal periods.
    Gap,
    /// A record with the previous record's time stamp (not used).
    Duplicate,
    /// A record earlier than the previous one (not used).
    OutOfOrder,
    /// All six values repeat the previous record where the channels'
    /// repeat rates make that a < 1e-6 chance.
    Stale,
    /// A channel repeats one value longer than chance allows (at least 20
    /// samples and `stuck_min_s`).
    Stuck,
    /// A flat top at a channel's extreme, or samples at ≥ 99.9 % of a
    /// declared full-scale range.
    Saturation,
    /// An isolated one-sample excursion (a two-sample one in increments)
    /// beyond `spike_factor` times the channel's running level.
    Spike,
}

pub(super) const KINDS: [EventKind; 8] = [
    EventKind::Malformed,
    EventKind::Gap,
    EventKind::Duplicate,
    EventKind::OutOfOrder,
    EventKind::Stale,
    EventKind::Stuck,
    EventKind::Saturation,
    EventKind::Spike,
];

/// One finding, located in the file.
#[derive(Clone, Debug, Serialize)]
pub struct Event {
    /// What was found.
    pub kind: EventKind,
    /// 1-based line of the record (of the first record of a stuck run or
    /// flat top).
    pub line: usize,
    /// The time stamp as written (s); NaN for malformed lines and
    /// saturation.
    pub time_s: f64,
    /// The channel (`gyro x` … `accel z`); `None` for findings about the
    /// whole record.
    pub channel: Option<&'static str>,
    /// What was seen, in words, with values.
    pub detail: String,
}

/// Counts of findings by kind.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct Counts {
    /// Lines that did not parse (from the reader).
    pub malformed_lines: usize,
    /// Intervals longer than `gap_factor` nominal periods.
    pub gaps: usize,
    /// Gaps longer than `max_gap_s`.
    pub(crate) gaps_over_limit: usize,
    /// Samples missing in the gaps (interval / nominal − 1, at least 1 per
    /// gap).
    pub(crate) lost_samples: usize,
    /// Records repeating the previous record's time stamp.
    pub duplicates: usize,
    /// Records earlier than the previous record.
    pub out_of_order: usize,
    /// Records whose six values all repeat the previous record beyond
    /// chance.
    pub stale_records: usize,
    /// Stuck runs, over all channels.
    pub stuck_segments: usize,
    /// Samples inside stuck runs (union over channels).
    pub(crate) stuck_samples: usize,
    /// Flat tops at a channel's extreme, plus one per channel that reached
    /// a declared full-scale range.
    pub saturation_events: usize,
    /// Saturated samples, summed over channels.
    pub(crate) saturated_samples: usize,
    /// Spikes, over all channels.
    pub spikes: usize,
    /// Records with at least one spike.
    pub(crate) spike_records: usize,
}

impl Counts {
    /// Events of one kind (segments for stuck, flat tops for saturation).
    pub fn of(&self, k: EventKind) -> usize {
        match k {
            EventKind::Malformed => self.malformed_lines,
            EventKind::Gap => self.gaps,
            EventKind::Duplicate => self.duplicates,
            EventKind::OutOfOrder => self.out_of_order,
            EventKind::Stale => self.stale_records,
            EventKind::Stuck => self.stuck_segments,
            EventKind::Saturation => self.saturation_events,
            EventKind::Spike => self.spikes,
        }
    }
}

/// Interval statistics (s).
#[derive(Clone, Debug, Default, Serialize)]
pub struct IntervalStats {
    pub(crate) nominal_s: f64,
    pub(crate) mean_s: f64,
    pub(crate) median_s: f64,
    pub(crate) min_s: f64,
    pub(crate) max_s: f64,
    /// RMS deviation from the mean over intervals that are not gaps.
    pub(crate) jitter_rms_s: f64,
    pub(crate) jitter_rms_frac: f64,
    /// 99th percentile of |interval − nominal| (histogram, 0.1 % bins).
    pub(crate) p99_abs_dev_s: f64,
}

/// Per-channel findings (values in rate units: rad/s, m/s²).
#[derive(Clone, Debug, Serialize)]
pub struct ChannelReport {
    /// `gyro x`, `gyro y`, `gyro z`, `accel x`, `accel y` or `accel z`.
    pub name: &'static str,
    /// `rad/s` or `m/s^2`.
    pub(crate) unit: &'static str,
    /// Mean (rad/s or m/s²; increments divided by the nominal interval).
    pub mean: f64,
    /// Sample standard deviation (rad/s or m/s²).
    pub std: f64,
    /// Smallest value (rad/s or m/s²).
    pub min: f64,
    /// Largest value (rad/s or m/s²).
    pub max: f64,
    /// Fraction of samples equal to the one before.
    pub(crate) repeat_fraction: f64,
    /// Sensor resolution found in the values (None: no grid).
    pub(crate) quantization_step: Option<f64>,
    pub(crate) min_significant_digits: u8,
    /// Median significant digits written.
    pub(crate) typical_significant_digits: u8,
    /// Typical resolution of the written numbers.
    pub(crate) print_step: f64,
    /// High-frequency noise σ (robust, from second differences).
    pub(crate) noise_sd: f64,
    /// Print rounding noise (step/√12) over `noise_sd`.
    pub(crate) rounding_to_noise: f64,
    pub(crate) stuck_segments: usize,
    pub(crate) saturated_samples: usize,
    pub(crate) spikes: usize,
}

/// A static segment found in the log.
#[derive(Clone, Debug, Serialize)]
pub struct StaticSegment {
    /// 1-based line of its first record.
    pub(crate) first_line: usize,
    /// Its first time stamp as written (s).
    pub(crate) start_s: f64,
    /// Length (s): samples × the nominal interval.
    pub duration_s: f64,
}

/// Allan results of one channel.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct AllanChannel {
    pub name: &'static str,
    /// Random walk in SI (rad/√s, m/s/√s) and in display units
    /// (deg/√h, m/s/√h).
    pub(crate) random_walk: f64,
    pub(crate) random_walk_display: f64,
    /// Bias instability in SI (rad/s, m/s²) and display (deg/h, mGal).
    pub(crate) bias_instability: f64,
    pub(crate) bias_instability_display: f64,
    pub(crate) bias_instability_tau_s: f64,
    /// False when the curve had not turned up within the segment (the
    /// value is then an upper bound).
    pub(crate) bias_instability_resolved: bool,
    /// Lag-1 and lag-2 autocorrelation of the static noise (≈ 0 when
    /// white; a low-pass filter makes them large). Increments converted
    /// from white rates by the trapezoid have lag-1 0.5 and lag-2 0 (a
    /// two-sample average with no delay beyond its own interval), so for
    /// increment logs only lag 2 tells a filter.
    pub(crate) lag1_correlation: f64,
    pub(crate) lag2_correlation: f64,
    pub(crate) curve: Vec<AllanPoint>,
}

/// Allan analysis of the longest static segment.
#[derive(Clone, Debug, Serialize)]
pub struct AllanReport {
    pub(crate) segment: StaticSegment,
    pub(crate) tau0_s: f64,
    pub(crate) channels: Vec<AllanChannel>,
}

/// The delay of a declared low-pass filter.
#[derive(Clone, Debug, Serialize)]
pub struct LowPassReport {
    /// The filter as declared.
    pub filter: LowPassFilter,
    /// Its group delay: at DC (the delay compensated) and over the
    /// dynamics band.
    pub delay: GroupDelay,
    /// Text for the report: the delay, the advice to turn the filter off,
    /// and the compensation applied.
    pub warning: String,
}

/// Everything a check found.
#[derive(Clone, Debug, Serialize)]
pub struct QualityReport {
    /// Path of the log, as given.
    pub file: String,
    /// `kf-gins` or `rate-csv`.
    pub format: &'static str,
    /// Lines that held a record or tried to (records + malformed).
    pub records: usize,
    /// Records in time order (duplicates and out-of-order excluded).
    pub accepted: usize,
    /// First accepted time stamp as written (s).
    pub(crate) first_time_s: f64,
    /// Last accepted time stamp as written (s).
    pub(crate) last_time_s: f64,
    /// Last minus first accepted time stamp (s).
    pub duration_s: f64,
    /// Nominal output rate (Hz): declared, or from the median interval of
    /// the first 64 records.
    pub nominal_rate_hz: f64,
    /// A round rate within 1 % of the measured one, if any.
    pub(crate) round_rate_hz: Option<f64>,
    /// From a least-squares fit of time on sample index.
    pub true_rate_hz: f64,
    /// (round or nominal period / true period − 1) × 1e6.
    pub(crate) rate_error_ppm: f64,
    /// Statistics of the intervals between accepted records.
    pub intervals: IntervalStats,
    /// Longest gap (s), 0 without gaps.
    pub(crate) longest_gap_s: f64,
    /// Line of the record that ends the longest gap.
    pub(crate) longest_gap_line: usize,
    /// Findings by kind.
    pub counts: Counts,
    /// Bad records: malformed, duplicate, out of order, stale, spiky,
    /// saturated and stuck (a record saturated or stuck in several
    /// channels counts once).
    pub(crate) bad_records: usize,
    /// Lost / (accepted + lost) samples.
    pub(crate) loss_rate: f64,
    /// Bad records / records.
    pub(crate) bad_data_rate: f64,
    /// Per-channel findings: gyro x y z, then accelerometer x y z.
    pub channels: Vec<ChannelReport>,
    /// Every static segment found, in file order.
    pub(crate) static_segments: Vec<StaticSegment>,
    /// Allan analysis of the longest static segment; `None` when no
    /// segment of `min_static_s` was found.
    pub allan: Option<AllanReport>,
    /// Delay of the declared low-pass filter; `None` when none was
    /// declared.
    pub lowpass: Option<LowPassReport>,
    /// The verdict rows, one per criterion.
    pub criteria: Vec<Criterion>,
    /// Worst status among the criteria, `Info` rows left out.
    pub verdict: Status,
    /// Findings (at most 50 of each kind; all are counted in `counts`).
    pub events: Vec<Event>,
    /// Remarks that fit no criterion (e.g. time stamps in coarse ticks).
    pub notes: Vec<String>,
}
