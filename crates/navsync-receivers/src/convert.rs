//! File conversion behind `navsync convert`: receiver logs and rate-form
//! IMU logs → KF-GINS files (FORMATS.md §1) and rig-logs (FORMATS.md §2).
//!
//! Outputs in the output directory, where the input has the data:
//! - `gnss.txt`: KF-GINS GNSS file at each fix's time of validity in GPS
//!   time; 13 columns (C++ order) from NAV-PVT, 7 from NMEA or comma2k19.
//! - `imu.txt`: KF-GINS increments (trapezoid rule, seed 001 §1.1) from
//!   ESF-MEAS/ESF-RAW or a rate CSV. ESF data are on the receiver's sensor
//!   time-tag axis (seconds), not GPS time (no message of the stream relates
//!   the two); `--imu-time-offset-s` shifts them when the offset is known.
//! - `events.rig`: rig-log v1 of TIM-TP pulses (`pps`) and TIM-TM2 edges
//!   (`mark`), whose counter is the receiver's GNSS time in ns (said so in
//!   its header): a receiver stream has no logger counter.
//! - `gnss_receipt.txt` (comma2k19): each fix's GPS time and boot time of
//!   receipt, to study latency.
//! - From a ROS 2 bag (`.mcap`, [`crate::ros2`]): `imu.txt` from
//!   `sensor_msgs/Imu` rates (FLU → FRD) and `gnss.txt` from `NavSatFix`
//!   (σ from its covariance; 13 columns when every fix has a
//!   `TwistWithCovarianceStamped` velocity of the same stamp), both at
//!   `header.stamp` turned from UTC into GPS time.
//! - From a ROS 1 bag (`.bag`, [`crate::ros1`]): the same, and
//!   `speed.txt` (`sow speed_mps`, the odometer file of `navsync::io::speed`)
//!   from `nav_msgs/Odometry` `twist.twist.linear.x` (or a body-frame
//!   `TwistStamped`); NavSatFix altitudes taken as ellipsoidal or, with
//!   `ros_altitude: Msl`, as MSL + EGM96 (said in the summary).
//! - From an ArduPilot DataFlash log ([`crate::autopilot`]): `rig.csv`
//!   (IMU on the boot clock, fixes with GPS time and arrival boot time,
//!   for `navsync sync`) and `autopilot.nav` (the autopilot's estimate).
//! - `summary.json`: counts, stream statistics, every navigation epoch
//!   (UBX or NMEA GGA) that gave no fix counted by reason (`fix_epochs`),
//!   and every reported problem.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use navsync::error::{Diagnostics, Error};
use navsync::filter::gnss::GnssFix;
use navsync::io::heading::{HeadingObs, HeadingSource, MAX_HEADING_SD_DEG, write_headings};
use navsync::io::kfgins::{TextWriter, format_gnss_line, format_imu_line};
use navsync::io::riglog::write as rig_write;
use navsync::io::text::{
    LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, split_fields,
};
use navsync::time::GpsTime;

use crate::fixes::{
    DropReason, FixOptions, NmeaDrop, NmeaFixes, NmeaOutcome, ReceiverFix, TimeContext, UbxEpochs,
    UbxFixSource, UbxOutcome, nav_pvt_fix,
};
use crate::gnsstime::{LeapSource, UtcTime, utc_to_gps};
use crate::imu::{EsfImu, RateIssue, RateSample, RateToIncrement};
use crate::marks::{Edge, QErrCorrector, TimeMarks, pps_edge_gps};
use crate::rosmsg::{AltitudeDatum, BagData, BagOptions, TopicChoice};
use crate::stream::{Event, EventKind, StreamReader, StreamStats, gpsd_log_header_len};
use crate::ubx::{NavRelPosNed, UbxMessage};

/// Input formats.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub enum InputFormat {
    /// u-blox stream (UBX, possibly mixed with NMEA).
    Ubx,
    /// NMEA 0183 stream (possibly mixed with UBX).
    Nmea,
    /// Rate-form IMU CSV: time s, gyro xyz rad/s, accel xyz m/s².
    RateCsv,
    /// comma2k19 `gnss_ublox.csv`.
    CommaGnss,
    /// ROS 2 bag in MCAP form (`sensor_msgs/Imu`, `NavSatFix`).
    Mcap,
    /// PX4 ULog (`.ulg`): to a rig log on the autopilot's boot clock
    /// ([`crate::ulog`]).
    Ulog,
    /// ROS 1 bag, format 2.0 (`sensor_msgs/Imu`, `NavSatFix`, `nav_msgs/Odometry`).
    Ros1Bag,
    /// ArduPilot DataFlash `.BIN` log ([`crate::dataflash`]): a rig log.
    DataFlash,
}

/// Which fixes go into `gnss.txt` when a stream holds both kinds.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum GnssSource {
    /// UBX (NAV-PVT, or NAV-SOL/POSLLH/VELNED epochs) when the stream has
    /// UBX fixes, else NMEA.
    #[default]
    Auto,
    Ubx,
    Nmea,
}

/// Conversion options.
#[derive(Copy, Clone, Debug)]
pub struct ConvertOptions {
    pub fix: FixOptions,
    pub gnss_source: GnssSource,
    /// Seconds per ESF-MEAS time-tag tick (u-blox IMUs: 1 ms).
    pub esf_meas_tick_s: f64,
    /// Seconds per ESF-RAW sTtag tick (checked against GPS time in the
    /// summary; see `sensor_clock`).
    pub esf_raw_tick_s: f64,
    /// Added to IMU times (s): a known sensor/boot → GPS offset.
    pub imu_time_offset_s: f64,
    /// IMU intervals at least this long are reported (seed 001 §1.5).
    pub gap_threshold_s: f64,
    /// σ (deg) given to NMEA HDT headings, which carry none: the
    /// receiver's datasheet heading accuracy for its antenna baseline.
    pub hdt_sd_deg: f64,
    /// Which height ROS NavSatFix altitudes are.
    pub ros_altitude: AltitudeDatum,
}

/// The default σ of an NMEA HDT heading (deg): dual-antenna receivers
/// state 0.1–0.3° RMS for a 1 m baseline; 0.5° covers shorter baselines.
pub const DEFAULT_HDT_SD_DEG: f64 = 0.5;

impl Default for ConvertOptions {
    fn default() -> Self {
        ConvertOptions {
            fix: FixOptions::default(),
            gnss_source: GnssSource::Auto,
            esf_meas_tick_s: 1e-3,
            esf_raw_tick_s: 1e-3,
            imu_time_offset_s: 0.0,
            gap_threshold_s: 0.1,
            hdt_sd_deg: DEFAULT_HDT_SD_DEG,
            ros_altitude: AltitudeDatum::Ellipsoid,
        }
    }
}

/// Sensor time-tag rate measured against GPS time over the stream.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SensorClock {
    /// Sensor ticks per second of GPS time, from the first and last ESF
    /// data and the GPS time of the last fix before each in the stream
    /// (arrival order): uncertain by about one fix interval over the span,
    /// see `relative_uncertainty`.
    pub ticks_per_gps_second: Option<f64>,
    /// ≈ fix interval / span.
    pub relative_uncertainty: f64,
    pub configured_ticks_per_second: f64,
    pub gps_span_s: f64,
}

/// Navigation epochs of one source and what became of them.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct EpochTally {
    /// The messages the epochs came from (`UBX NAV-PVT`,
    /// `UBX NAV-SOL/POSLLH/VELNED/STATUS`, `NMEA GGA`).
    pub source: String,
    pub epochs: u64,
    /// Epochs that gave a fix (before the time-order check and the choice
    /// of source for gnss.txt).
    pub fixes: u64,
    /// Epochs that gave none, by reason.
    pub dropped: Vec<DropTally>,
}

/// Epochs dropped for one reason.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct DropTally {
    pub reason: String,
    pub epochs: u64,
    /// The `navsync convert` option that keeps them, when one does.
    pub kept_by: Option<String>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// What a conversion did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ConvertSummary {
    pub input: String,
    pub format: Option<InputFormat>,
    /// Bytes of the file header skipped (gpsd `#` lines).
    pub header_bytes: u64,
    pub stream: Option<StreamStats>,
    /// Decoded messages and intact frames by type.
    pub frames: BTreeMap<String, u64>,
    pub gnss_fixes: usize,
    /// The GPS week of the first fix written (gnss.txt holds seconds of
    /// week only), so that the solution carries its week.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gps_week: Option<i64>,
    pub gnss_columns: usize,
    pub gnss_source: String,
    pub gnss_default_sd: usize,
    /// Navigation epochs by source (UBX NAV-PVT, the older UBX set, NMEA
    /// GGA), with every epoch that gave no fix counted by reason.
    pub fix_epochs: Vec<EpochTally>,
    /// UBX fixes whose position came from NAV-HPPOSLLH.
    pub ubx_high_precision_positions: usize,
    /// Fixes (in gnss.txt) whose ellipsoidal height needed the geoid model
    /// (NMEA GGA without a geoid separation).
    pub geoid_model_heights: usize,
    /// The geoid model, when it was used.
    pub geoid_model: Option<String>,
    pub leap_source: Option<LeapSource>,
    /// ROS 2 bag: its topics, what each was used for, stamp vs log time.
    pub ros2: Option<crate::ros2::BagSummary>,
    /// PX4 ULog: topics, instances, what was read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ulog: Option<crate::ulog::UlogSummary>,
    /// ROS 1 bag: the same, with the odometer speeds and altitude datum.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ros1: Option<crate::ros2::BagSummary>,
    /// Speeds written to speed.txt (ROS 1 odometry).
    #[serde(skip_serializing_if = "is_zero")]
    pub speeds: usize,
    /// ArduPilot DataFlash log: messages, instances, σ source, drops.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dataflash: Option<crate::dataflash::DataFlashSummary>,
    pub imu_samples: usize,
    pub imu_time_axis: String,
    pub imu_gaps: usize,
    pub sensor_clock: Option<SensorClock>,
    pub pps: usize,
    pub pps_without_qerr: usize,
    pub mark_edges: usize,
    pub strobes: usize,
    /// Headings written to heading.txt (dual-antenna NAV-RELPOSNED, NAV-PVT
    /// headVeh) and those skipped, by reason.
    #[serde(skip_serializing_if = "is_zero")]
    pub headings: usize,
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub heading_drops: BTreeMap<String, u64>,
    pub files: Vec<String>,
    /// GPS time jumps between consecutive fixes (concatenated logs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub time_jumps: Vec<TimeJump>,
    pub diagnostics: Diagnostics,
}

impl ConvertSummary {
    /// For a receiver stream or fix file that gave no fix, a plain
    /// sentence saying so and why (the drop reasons, or that no position
    /// message was found); `None` when there are fixes or the input is not
    /// a fix source (rate CSV).
    pub fn no_fix_message(&self) -> Option<String> {
        if self.gnss_fixes > 0 || self.format == Some(InputFormat::RateCsv) {
            return None;
        }
        let epochs: u64 = self.fix_epochs.iter().map(|t| t.epochs).sum();
        let mut m = format!("no GNSS fix in {}", self.input);
        if matches!(
            self.format,
            Some(InputFormat::Mcap | InputFormat::Ros1Bag | InputFormat::DataFlash)
        ) {
            // A bag without a NavSatFix topic (an autopilot log without
            // GPS messages) is an IMU log, not a failure.
            if self.fix_epochs.is_empty() {
                return None;
            }
            if epochs == 0 {
                m.push_str(": its NavSatFix topic holds no message");
                return Some(m);
            }
        }
        if epochs == 0 {
            m.push_str(
                ": the stream holds no position message navsync reads \
                 (UBX NAV-PVT, NAV-SOL, NAV-POSLLH, NAV-HPPOSLLH or NMEA GGA)",
            );
            return Some(m);
        }
        let mut parts = Vec::new();
        for t in &self.fix_epochs {
            for d in &t.dropped {
                parts.push(format!(
                    "{} {} epochs: {}{}",
                    d.epochs,
                    t.source,
                    d.reason,
                    d.kept_by
                        .as_ref()
                        .map(|o| format!(" (kept with {o})"))
                        .unwrap_or_default()
                ));
            }
        }
        if !parts.is_empty() {
            m.push_str(": ");
            m.push_str(&parts.join("; "));
        }
        Some(m)
    }
}

/// Converts `input` of `format` into files in `out_dir` (created if
/// needed).
pub fn convert(
    format: InputFormat,
    input: &Path,
    out_dir: &Path,
    opts: &ConvertOptions,
) -> Result<ConvertSummary, Error> {
    convert_with_topics(format, input, out_dir, opts, &TopicChoice::default())
}

/// [`convert`], with the topics to read from a ROS 2 bag.
pub fn convert_with_topics(
    format: InputFormat,
    input: &Path,
    out_dir: &Path,
    opts: &ConvertOptions,
    topics: &TopicChoice,
) -> Result<ConvertSummary, Error> {
    // Ticks are divided by and times shifted: a zero tick would put every
    // ESF sample at one time (an empty imu.txt), a NaN offset everywhere.
    for (name, v) in [
        ("ESF-MEAS tick", opts.esf_meas_tick_s),
        ("ESF-RAW tick", opts.esf_raw_tick_s),
        ("IMU gap threshold", opts.gap_threshold_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::Invalid(format!(
                "{name} {v} s: expected a positive number of seconds"
            )));
        }
    }
    if !opts.imu_time_offset_s.is_finite() {
        return Err(Error::Invalid(format!(
            "IMU time offset {} s: expected a finite number",
            opts.imu_time_offset_s
        )));
    }
    let (reader, input) = open_input(input)?;
    std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, e))?;
    let mut s = ConvertSummary {
        input: input.display().to_string(),
        format: Some(format),
        diagnostics: Diagnostics::with_cap(2000),
        ..Default::default()
    };
    match format {
        InputFormat::Ubx | InputFormat::Nmea => {
            convert_stream(reader, input, out_dir, opts, &mut s)?
        }
        InputFormat::RateCsv => {
            convert_rate_csv(LineReader::new(reader, input), out_dir, opts, &mut s)?
        }
        InputFormat::CommaGnss => {
            convert_comma_gnss(LineReader::new(reader, input), out_dir, opts, &mut s)?
        }
        InputFormat::Mcap | InputFormat::Ros1Bag => {
            convert_bag(format, reader, input, out_dir, opts, topics, &mut s)?
        }
        InputFormat::Ulog => crate::ulog::convert_ulog(reader, input, out_dir, &mut s)?,
        InputFormat::DataFlash => {
            crate::autopilot::convert_dataflash(reader, input, out_dir, opts, &mut s)?
        }
    }
    let path = out_dir.join("summary.json");
    let json = serde_json::to_string_pretty(&s).map_err(|e| Error::Invalid(e.to_string()))?;
    navsync::io::output::write_file(&path, json)?;
    s.files.push(path.display().to_string());
    Ok(s)
}

/// The name standard input goes by in messages and summary.json.
pub(crate) const STDIN_NAME: &str = "<stdin>";

/// Opens `input`, or standard input for `-` (so that `gpspipe -R |
/// navsync convert --from ubx -` works); returns the reader and the name
/// to use in messages.
fn open_input(input: &Path) -> Result<(Box<dyn Read>, &Path), Error> {
    if input.as_os_str() == "-" {
        return Ok((Box::new(std::io::stdin().lock()), Path::new(STDIN_NAME)));
    }
    let file = std::fs::File::open(input).map_err(|e| Error::io(input, e))?;
    Ok((Box::new(file), input))
}

/// Reads until `buf` is full or the input ends (a pipe gives short reads:
/// the gpsd header must be seen whole).
fn read_full(r: &mut dyn Read, buf: &mut [u8], input: &Path) -> Result<usize, Error> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::io(input, e)),
        }
    }
    Ok(n)
}

fn write_gnss(path: &Path, fixes: &[GnssFix], s: &mut ConvertSummary) -> Result<(), Error> {
    let mut w = TextWriter::create(path)?;
    let mut line = Vec::with_capacity(160);
    for f in fixes {
        line.clear();
        format_gnss_line(&mut line, f);
        w.write(&line)?;
    }
    w.finish()?;
    s.gnss_fixes = fixes.len();
    s.gps_week = fixes.first().map(|f| f.time.week());
    s.gnss_columns = if fixes.iter().all(|f| f.vel.is_some()) {
        13
    } else {
        7
    };
    s.files.push(path.display().to_string());
    Ok(())
}

/// Keeps fixes strictly increasing in time (duplicates and steps back are
/// reported and dropped).
fn monotonic(fixes: Vec<ReceiverFix>, file: &Path, diag: &mut Diagnostics) -> Vec<ReceiverFix> {
    let mut out: Vec<ReceiverFix> = Vec::with_capacity(fixes.len());
    for f in fixes {
        if let Some(last) = out.last()
            && f.fix.time <= last.fix.time
        {
            diag.push(
                file,
                0,
                format!(
                    "fix at {} not after the previous one ({}); dropped",
                    f.fix.time, last.fix.time
                ),
            );
            continue;
        }
        out.push(f);
    }
    out
}

fn convert_stream(
    mut file: Box<dyn Read>,
    input: &Path,
    out_dir: &Path,
    opts: &ConvertOptions,
    s: &mut ConvertSummary,
) -> Result<(), Error> {
    let diag_path = input.to_path_buf();
    let mut block = vec![0u8; 1 << 20];
    let mut conv = StreamConverter::new(opts);
    // gpsd logs start with `#` comment lines; headers are short, so the
    // first block holds them.
    let n = read_full(&mut file, &mut block, input)?;
    let h = gpsd_log_header_len(&block[..n]);
    s.header_bytes = h as u64;
    let mut r = StreamReader::new().starting_at(h as u64);
    r.push(&block[h..n]);
    loop {
        while let Some(ev) = r.next_event() {
            conv.push(&ev, &diag_path, s);
        }
        let n = read_full(&mut file, &mut block, input)?;
        if n == 0 {
            break;
        }
        r.push(&block[..n]);
    }
    r.finish();
    while let Some(ev) = r.next_event() {
        conv.push(&ev, &diag_path, s);
    }
    let reader = Some(r);
    let stats = reader.map(|r| r.stats().clone()).unwrap_or_default();
    if stats.bytes == 0 {
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: "no bytes after the header".into(),
        });
    }
    s.stream = Some(stats);
    conv.finish(input, out_dir, s)
}

/// The streaming part of a receiver-log conversion: events in, records
/// out (kept in memory here; the live mode will write them as they come).
struct StreamConverter {
    opts: ConvertOptions,
    ctx: TimeContext,
    ubx_epochs: UbxEpochs,
    ubx_out: Vec<UbxOutcome>,
    ubx_fixes: Vec<ReceiverFix>,
    /// Per source: epochs, fixes, drops by reason.
    ubx_tally: BTreeMap<UbxFixSource, (u64, u64, BTreeMap<DropReason, u64>)>,
    ubx_hp: usize,
    nmea: NmeaFixes,
    nmea_out: Vec<NmeaOutcome>,
    esf: EsfImu,
    esf_raw: EsfImu,
    rates: Vec<RateSample>,
    rates_raw: Vec<RateSample>,
    marks: TimeMarks,
    qerr: QErrCorrector,
    last_pulse: Option<GpsTime>,
    rig: Vec<u8>,
    /// (first, last) ESF tick and GPS time of the latest fix at that point.
    esf_clock: Option<((u64, GpsTime), (u64, GpsTime))>,
    last_fix_time: Option<GpsTime>,
    /// Receiver headings (heading.txt).
    headings: Vec<HeadingObs>,
    /// Largest interval between consecutive fix times (s).
    fix_interval_s: f64,
    /// Byte offset of the event being converted (for time jumps).
    offset: u64,
    /// GPS time jumps between consecutive fixes (two logs concatenated).
    time_jumps: Vec<TimeJump>,
}

/// A jump of GPS time between consecutive fixes in arrival order larger
/// than [`MAX_FIX_STEP_S`]: two logs concatenated, or a receiver that lost
/// its week. Reported in summary.json and on the console.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TimeJump {
    /// Byte offset of the message whose time jumped.
    pub byte_offset: u64,
    /// GPS time (week sow) of the fix before and of this one.
    pub from: String,
    pub to: String,
    pub jump_s: f64,
}

/// Largest step of GPS time between consecutive fixes of one log taken
/// as a pause (s): one day. A larger step is a jump.
pub const MAX_FIX_STEP_S: f64 = 86_400.0;
/// Time jumps kept in the summary (the rest are counted in diagnostics).
const MAX_TIME_JUMPS: usize = 16;

impl StreamConverter {
    fn new(opts: &ConvertOptions) -> Self {
        let offset_ns = (opts.imu_time_offset_s * 1e9).round() as i64;
        let mut esf = EsfImu::new(opts.esf_meas_tick_s);
        esf.offset_ns = offset_ns;
        let mut esf_raw = EsfImu::new(opts.esf_raw_tick_s);
        esf_raw.offset_ns = offset_ns;
        StreamConverter {
            opts: *opts,
            ctx: TimeContext::default(),
            ubx_epochs: UbxEpochs::new(opts.fix),
            ubx_out: Vec::new(),
            ubx_fixes: Vec::new(),
            ubx_tally: BTreeMap::new(),
            ubx_hp: 0,
            nmea: NmeaFixes::new(opts.fix),
            nmea_out: Vec::new(),
            esf,
            esf_raw,
            rates: Vec::new(),
            rates_raw: Vec::new(),
            marks: TimeMarks::new(),
            qerr: QErrCorrector::new(),
            last_pulse: None,
            rig: Vec::new(),
            esf_clock: None,
            last_fix_time: None,
            headings: Vec::new(),
            fix_interval_s: 0.0,
            offset: 0,
            time_jumps: Vec::new(),
        }
    }

    fn note_fix_time(&mut self, t: GpsTime) {
        if let Some(last) = self.last_fix_time {
            let step = t.seconds_since(last);
            if step.abs() > MAX_FIX_STEP_S {
                if self.time_jumps.len() < MAX_TIME_JUMPS {
                    self.time_jumps.push(TimeJump {
                        byte_offset: self.offset,
                        from: last.to_string(),
                        to: t.to_string(),
                        jump_s: step,
                    });
                }
            } else if step > 0.0 {
                self.fix_interval_s = self.fix_interval_s.max(step);
            }
        }
        self.last_fix_time = Some(t);
    }

    fn note_esf_tag(&mut self, tag: Option<u32>) {
        let (Some(tag), Some(t)) = (tag, self.last_fix_time) else {
            return;
        };
        let tag = tag as u64;
        self.esf_clock = Some(match self.esf_clock {
            None => ((tag, t), (tag, t)),
            Some((first, _)) => (first, (tag.max(first.0), t)),
        });
    }

    fn push(&mut self, ev: &Event, file: &Path, s: &mut ConvertSummary) {
        let (kind, offset) = (&ev.kind, ev.offset);
        self.offset = offset;
        let diag = &mut s.diagnostics;
        let key = match kind {
            EventKind::Ubx(m) => m.id().to_string(),
            EventKind::Nmea(m) => format!("NMEA {}", m.kind()),
            EventKind::Unknown(id) => format!("{id} (not read)"),
            EventKind::Invalid { frame, .. } => format!("{frame} (invalid)"),
            EventKind::Corrupt(_) => "corrupt runs".to_string(),
        };
        *s.frames.entry(key).or_default() += 1;
        if let EventKind::Ubx(m) = kind {
            // Before the time context takes a NAV-TIMEGPS: it may close
            // the previous epoch, whose week must not come from it.
            self.ubx_epochs.push(m, &self.ctx, &mut self.ubx_out);
            self.take_ubx_outcomes(file, diag);
        }
        match kind {
            EventKind::Ubx(m) => match m {
                UbxMessage::NavTimeGps(t) => {
                    self.ctx.push_timegps(t);
                    if let Some(ns) = t.time_ns() {
                        self.note_fix_time(GpsTime::from_ns(ns));
                    }
                }
                UbxMessage::NavPvt(p) => self.push_pvt(p, "NAV-PVT headVeh", s),
                // A dead-reckoning receiver's fused solution: its fix comes
                // when the epoch closes (fixes::UbxEpochs), its heading here.
                UbxMessage::NavPvat(p) => self.push_pvt(&p.as_nav_pvt(), "NAV-PVAT vehHeading", s),
                UbxMessage::NavAtt(a) => self.push_att(a, s),
                UbxMessage::NavRelPosNed(r) => self.push_relposned(r, offset, file, s),
                UbxMessage::NavSol(_)
                | UbxMessage::NavPosLlh(_)
                | UbxMessage::NavHpPosLlh(_)
                | UbxMessage::NavVelNed(_)
                | UbxMessage::NavStatus(_) => {}
                UbxMessage::EsfMeas(m) => {
                    self.note_esf_tag(Some(m.time_tag));
                    self.esf.push_meas(m, &mut self.rates);
                }
                UbxMessage::EsfRaw(m) => {
                    self.note_esf_tag(m.blocks.last().map(|b| b.s_ttag));
                    self.esf_raw.push_raw(m, &mut self.rates_raw);
                }
                UbxMessage::TimTp(tp) => {
                    if let Some(p) = self.qerr.push_tim_tp(tp, &self.ctx.leap)
                        && self.last_pulse != Some(p.time)
                    {
                        self.last_pulse = Some(p.time);
                        let edge = if p.q_err_valid {
                            pps_edge_gps(p.time, p.q_err_ps)
                        } else {
                            s.pps_without_qerr += 1;
                            p.time
                        };
                        rig_write::pps(&mut self.rig, edge.ns() as u64);
                        s.pps += 1;
                    }
                }
                UbxMessage::TimTm2(tm) => {
                    let out = self.marks.push(tm, &self.ctx.leap);
                    for p in out.problems {
                        diag.push(file, 0, format!("byte {offset}: {p}"));
                    }
                    for e in &out.edges {
                        let rising = u64::from(e.edge == Edge::Rising);
                        rig_write::mark(
                            &mut self.rig,
                            e.time.ns() as u64,
                            e.time,
                            &[
                                u64::from(e.channel),
                                rising,
                                u64::from(e.count),
                                u64::from(e.acc_ns),
                            ],
                        );
                    }
                    s.mark_edges += out.edges.len();
                    s.strobes += out.strobes.len();
                }
            },
            EventKind::Nmea(m) => {
                self.nmea.push(m, &self.ctx, &mut self.nmea_out);
            }
            EventKind::Unknown(_) => {}
            EventKind::Invalid { frame, what } => diag.push(
                file,
                0,
                format!("byte {offset}: {frame} frame invalid: {what}"),
            ),
            EventKind::Corrupt(_) => {
                diag.push(file, 0, format!("{ev}"));
            }
        }
    }

    /// The time of a NAV-PVT (or NAV-PVAT in its form), noted on arrival for
    /// the sensor-clock check (its fix comes when the epoch closes), and a
    /// dead-reckoning receiver's vehicle heading (headVeh / vehHeading
    /// when valid, σ = headAcc / accHeading).
    fn push_pvt(&mut self, p: &crate::ubx::NavPvt, what: &str, s: &mut ConvertSummary) {
        let Ok(Some(f)) = nav_pvt_fix(p, &self.ctx) else {
            return;
        };
        self.note_fix_time(f.fix.time);
        if p.head_veh_valid() && p.gnss_fix_ok() {
            let sd_deg = p.head_acc_e5 as f64 * 1e-5;
            match heading_problem(sd_deg) {
                None => self.headings.push(HeadingObs {
                    time: f.fix.time,
                    heading_rad: (p.head_veh_e5 as f64 * 1e-5).to_radians(),
                    sd_rad: sd_deg.to_radians(),
                    source: HeadingSource::Vehicle,
                }),
                Some(why) => {
                    *s.heading_drops.entry(format!("{what}: {why}")).or_default() += 1;
                }
            }
        }
    }

    /// NAV-ATT ([HPS] UBX-NAV-ATT): a dead-reckoning receiver's vehicle
    /// heading, σ = accHeading, at its iTOW in the week of the last fix.
    fn push_att(&mut self, a: &crate::ubx::NavAtt, s: &mut ConvertSummary) {
        let why = match self.last_fix_time {
            None => Some("no GPS week known yet (no fix before it)".to_string()),
            Some(_) => heading_problem(a.acc_heading_deg()),
        };
        match (why, self.last_fix_time) {
            (None, Some(last)) => self.headings.push(HeadingObs {
                time: itow_near(last, a.itow_ms),
                heading_rad: a.heading_deg().to_radians(),
                sd_rad: a.acc_heading_deg().to_radians(),
                source: HeadingSource::Vehicle,
            }),
            (why, _) => {
                *s.heading_drops
                    .entry(format!("NAV-ATT: {}", why.unwrap_or_default()))
                    .or_default() += 1;
            }
        }
    }

    /// A dual-antenna heading (moving-base NAV-RELPOSNED), kept by the
    /// rules of [`relposned_heading`]; otherwise counted and reported with
    /// its byte offset.
    fn push_relposned(
        &mut self,
        r: &NavRelPosNed,
        offset: u64,
        file: &Path,
        s: &mut ConvertSummary,
    ) {
        match relposned_heading(r, self.last_fix_time) {
            Ok(h) => self.headings.push(h),
            Err(why) => {
                s.diagnostics.push(
                    file,
                    0,
                    format!(
                        "byte {offset}: NAV-RELPOSNED iTOW {} ms: {why}; heading skipped",
                        r.itow_ms
                    ),
                );
                *s.heading_drops
                    .entry(format!("NAV-RELPOSNED: {why}"))
                    .or_default() += 1;
            }
        }
    }

    /// Fixes and drops of closed UBX epochs.
    fn take_ubx_outcomes(&mut self, file: &Path, diag: &mut Diagnostics) {
        for o in std::mem::take(&mut self.ubx_out) {
            match o {
                UbxOutcome::Fix {
                    fix,
                    source,
                    high_precision,
                } => {
                    let t = self.ubx_tally.entry(source).or_default();
                    t.0 += 1;
                    t.1 += 1;
                    self.ubx_hp += high_precision as usize;
                    if source == UbxFixSource::Combined {
                        self.note_fix_time(fix.fix.time);
                    }
                    self.ubx_fixes.push(fix);
                }
                UbxOutcome::Dropped {
                    source,
                    reason,
                    detail,
                    ..
                } => {
                    let t = self.ubx_tally.entry(source).or_default();
                    t.0 += 1;
                    *t.2.entry(reason).or_default() += 1;
                    if let Some(d) = detail {
                        // The detail names the epoch's iTOW.
                        diag.push(file, 0, format!("{}: {d}; fix skipped", source.name()));
                    }
                }
            }
        }
    }

    fn finish(mut self, input: &Path, out_dir: &Path, s: &mut ConvertSummary) -> Result<(), Error> {
        self.ubx_epochs.finish(&self.ctx, &mut self.ubx_out);
        self.take_ubx_outcomes(input, &mut s.diagnostics);
        for j in &self.time_jumps {
            s.diagnostics.push(
                input,
                0,
                format!(
                    "byte {}: GPS time jumps by {:.0} s from {} to {}: two logs concatenated? \
                     Convert each log on its own",
                    j.byte_offset, j.jump_s, j.from, j.to
                ),
            );
        }
        s.time_jumps = std::mem::take(&mut self.time_jumps);
        s.ubx_high_precision_positions = self.ubx_hp;
        s.fix_epochs = self
            .ubx_tally
            .iter()
            .map(|(src, (epochs, fixes, drops))| EpochTally {
                source: src.name().to_string(),
                epochs: *epochs,
                fixes: *fixes,
                dropped: drops
                    .iter()
                    .map(|(r, n)| DropTally {
                        reason: r.describe(),
                        epochs: *n,
                        kept_by: r.kept_by().map(str::to_string),
                    })
                    .collect(),
            })
            .collect();
        self.nmea.finish(&self.ctx, &mut self.nmea_out);
        self.esf.finish();
        self.esf_raw.finish();
        let mut nmea_fixes = Vec::new();
        let (mut gga_epochs, mut nmea_drops) = (0u64, BTreeMap::<NmeaDrop, u64>::new());
        let mut nmea_problems = 0u64;
        for o in std::mem::take(&mut self.nmea_out) {
            match o {
                NmeaOutcome::Fix(f) => {
                    gga_epochs += 1;
                    nmea_fixes.push(f);
                }
                NmeaOutcome::NoFix {
                    reason: NmeaDrop::NoGga,
                    ..
                } => {}
                NmeaOutcome::NoFix { reason, .. } => {
                    gga_epochs += 1;
                    *nmea_drops.entry(reason).or_default() += 1;
                }
                NmeaOutcome::Problem(p) => {
                    gga_epochs += 1;
                    nmea_problems += 1;
                    s.diagnostics.push(input, 0, p);
                }
                NmeaOutcome::Heading {
                    time,
                    heading_deg,
                    talker,
                    from_gnss,
                } => match hdt_heading(time, heading_deg, &talker, from_gnss, self.opts.hdt_sd_deg)
                {
                    Ok(h) => self.headings.push(h),
                    Err(why) => *s.heading_drops.entry(why).or_default() += 1,
                },
                NmeaOutcome::NoHeading => {
                    *s.heading_drops
                        .entry("HDT with an empty heading (no baseline solution)".into())
                        .or_default() += 1;
                }
                NmeaOutcome::HeadingProblem(p) => {
                    *s.heading_drops
                        .entry("HDT unusable (each one in the problems listed)".into())
                        .or_default() += 1;
                    s.diagnostics.push(input, 0, p);
                }
            }
        }
        if gga_epochs > 0 {
            let mut dropped: Vec<DropTally> = nmea_drops
                .iter()
                .map(|(r, n)| DropTally {
                    reason: r.describe(),
                    epochs: *n,
                    kept_by: None,
                })
                .collect();
            if nmea_problems > 0 {
                dropped.push(DropTally {
                    reason:
                        "GGA unusable (no time, date or altitude: each one in the problems listed)"
                            .into(),
                    epochs: nmea_problems,
                    kept_by: None,
                });
            }
            s.fix_epochs.push(EpochTally {
                source: "NMEA GGA".into(),
                epochs: gga_epochs,
                fixes: nmea_fixes.len() as u64,
                dropped,
            });
        }
        let use_ubx = match self.opts.gnss_source {
            GnssSource::Ubx => true,
            GnssSource::Nmea => false,
            GnssSource::Auto => !self.ubx_fixes.is_empty(),
        };
        let (chosen, name) = if use_ubx {
            let names: Vec<&str> = self
                .ubx_tally
                .iter()
                .filter(|(_, t)| t.1 > 0)
                .map(|(src, _)| src.name())
                .collect();
            let name = if names.is_empty() {
                "UBX".to_string()
            } else {
                names.join(" + ")
            };
            (std::mem::take(&mut self.ubx_fixes), name)
        } else {
            (nmea_fixes, "NMEA GGA (+GST, RMC/ZDA)".to_string())
        };
        s.gnss_source = name;
        let chosen = monotonic(chosen, input, &mut s.diagnostics);
        s.gnss_default_sd = chosen.iter().filter(|f| f.default_sd).count();
        s.geoid_model_heights = chosen.iter().filter(|f| f.geoid_from_model).count();
        if s.geoid_model_heights > 0 {
            s.geoid_model = Some(crate::geoid::EGM96_SOURCE.to_string());
        }
        s.leap_source = chosen.iter().rev().find_map(|f| f.leap);
        if !chosen.is_empty() {
            let fixes: Vec<GnssFix> = chosen.iter().map(|f| f.fix).collect();
            write_gnss(&out_dir.join("gnss.txt"), &fixes, s)?;
        }
        // IMU: ESF-RAW when present (full rate), else ESF-MEAS.
        let (rates, tick, what) = if !self.rates_raw.is_empty() {
            (
                std::mem::take(&mut self.rates_raw),
                self.opts.esf_raw_tick_s,
                "ESF-RAW sTtag",
            )
        } else {
            (
                std::mem::take(&mut self.rates),
                self.opts.esf_meas_tick_s,
                "ESF-MEAS timeTag",
            )
        };
        let unpaired = self.esf.unpaired + self.esf_raw.unpaired;
        if unpaired > 0 {
            s.diagnostics.note(format!(
                "{unpaired} gyro triads had no accelerometer triad around them (start/end of data); dropped"
            ));
        }
        if !rates.is_empty() {
            let mean_fz = rates.iter().map(|r| r.accel_mps2.z).sum::<f64>() / rates.len() as f64;
            if mean_fz > 4.9 {
                s.diagnostics.note(format!(
                    "ESF accelerometer z averages {mean_fz:+.2} m/s²: the receiver's sensor frame is z-up, not FRD; \
                     imu.txt keeps the sensor axes as sent (rotate before fusing)"
                ));
            }
            s.imu_time_axis = format!(
                "receiver sensor time ({what} × {} s{}), not GPS time",
                tick,
                if self.opts.imu_time_offset_s != 0.0 {
                    format!(", + {} s", self.opts.imu_time_offset_s)
                } else {
                    String::new()
                }
            );
            if let Some(((t0, g0), (t1, g1))) = self.esf_clock {
                let span = g1.seconds_since(g0);
                s.sensor_clock = Some(SensorClock {
                    ticks_per_gps_second: (span > 0.0).then(|| (t1 - t0) as f64 / span),
                    relative_uncertainty: if span > 0.0 {
                        self.fix_interval_s / span
                    } else {
                        f64::INFINITY
                    },
                    configured_ticks_per_second: 1.0 / tick,
                    gps_span_s: span,
                });
            }
            write_increments(
                &out_dir.join("imu.txt"),
                rates,
                input,
                self.opts.gap_threshold_s,
                s,
            )?;
        }
        if !self.headings.is_empty() {
            let mut h = std::mem::take(&mut self.headings);
            h.sort_by_key(|o| (o.time, o.source == HeadingSource::Vehicle));
            // One heading per epoch and source: a dead-reckoning receiver
            // gives its vehicle heading in NAV-ATT (at iTOW) and NAV-PVAT
            // (at UTC + nano, within 1 ms of it).
            h.dedup_by(|b, a| a.source == b.source && (b.time - a.time).abs() < 1_000_000);
            let path = out_dir.join("heading.txt");
            write_headings(&path, &h)?;
            s.headings = h.len();
            s.files.push(path.display().to_string());
        }
        if !self.rig.is_empty() {
            let path = out_dir.join("events.rig");
            let mut w = TextWriter::create(&path)?;
            w.write(RIG_HEADER.as_bytes())?;
            w.write(&self.rig)?;
            w.finish()?;
            s.files.push(path.display().to_string());
        }
        Ok(())
    }
}

/// The baseline heading of an NMEA HDT epoch, with the σ the user gave
/// (HDT carries none); an HDT from a talker that is not a GNSS receiver
/// (HE gyrocompass) is not a dual-antenna heading: why not.
pub fn hdt_heading(
    time: GpsTime,
    heading_deg: f64,
    talker: &str,
    from_gnss: bool,
    sd_deg: f64,
) -> Result<HeadingObs, String> {
    if !from_gnss {
        return Err(format!(
            "{talker}HDT: talker {talker} is not a GNSS receiver, so not a dual-antenna baseline heading"
        ));
    }
    Ok(HeadingObs {
        time,
        heading_rad: heading_deg.to_radians(),
        sd_rad: sd_deg.to_radians(),
        source: HeadingSource::Baseline,
    })
}

/// The heading of a moving-base NAV-RELPOSNED: used when gnssFixOK,
/// relPosValid and relPosHeadingValid are set and accHeading is in
/// (0, 30]°, at the GPS time of its iTOW in the week of `last_fix_time`
/// (a fix's time: RELPOSNED carries no week); otherwise why not.
pub fn relposned_heading(
    r: &NavRelPosNed,
    last_fix_time: Option<GpsTime>,
) -> Result<HeadingObs, String> {
    let acc = r.acc_heading_deg();
    let why = if !r.gnss_fix_ok() {
        Some("gnssFixOK not set".to_string())
    } else if !r.rel_pos_valid() {
        Some("relPosValid not set".to_string())
    } else if !r.rel_pos_heading_valid() {
        Some("relPosHeadingValid not set".to_string())
    } else {
        heading_problem(acc)
    };
    if let Some(why) = why {
        return Err(why);
    }
    let Some(last) = last_fix_time else {
        return Err("no GPS week known yet (no fix before it)".into());
    };
    Ok(HeadingObs {
        time: itow_near(last, r.itow_ms),
        heading_rad: r.heading_deg().to_radians(),
        sd_rad: acc.to_radians(),
        source: HeadingSource::Baseline,
    })
}

/// Why a heading σ (deg) is unusable, if it is: not finite, not positive,
/// or above [`MAX_HEADING_SD_DEG`] (receivers send 180° without one).
/// Also the check of a σ given for headings that carry none (`hdt_sd_deg`).
pub fn heading_problem(sd_deg: f64) -> Option<String> {
    (!navsync::io::heading::usable_sd(sd_deg))
        .then(|| format!("heading accuracy {sd_deg:.2}° outside (0, {MAX_HEADING_SD_DEG}]°"))
}

/// The GPS time of an iTOW (ms) in the week of `near`, the week before or
/// after when iTOW is more than half a week away from it.
fn itow_near(near: GpsTime, itow_ms: u32) -> GpsTime {
    let t = GpsTime::from_week_ns(near.week(), itow_ms as i64 * 1_000_000);
    let half = navsync::time::NS_PER_WEEK / 2;
    if t.ns() - near.ns() > half {
        GpsTime::from_week_ns(near.week() - 1, itow_ms as i64 * 1_000_000)
    } else if near.ns() - t.ns() > half {
        GpsTime::from_week_ns(near.week() + 1, itow_ms as i64 * 1_000_000)
    } else {
        t
    }
}

/// Header of the receiver-time rig-log (FORMATS.md §2).
pub(crate) const RIG_HEADER: &str = "# rig-log v1
# counter_hz: 1000000000
# counter_bits: 64
# imu: rate                  (no imu records here; the header needs the line)
# The counter is the receiver's own GNSS (GPS) time in ns since 1980-01-06;
# a receiver stream has no logger counter, so each record carries the
# receiver's measurement of the event.
# pps = 1PPS edge from UBX TIM-TP = announced pulse time - qErr (edge early by qErr)
# mark = UBX TIM-TM2 edge = mark,counter,week,tow_s,channel,rising(1)/falling(0),rising-edge count,accuracy ns
";

fn write_increments(
    path: &Path,
    rates: Vec<RateSample>,
    file: &Path,
    gap_threshold_s: f64,
    s: &mut ConvertSummary,
) -> Result<(), Error> {
    let mut w = TextWriter::create(path)?;
    let mut conv = RateToIncrement::new(gap_threshold_s);
    let mut line = Vec::with_capacity(200);
    let mut n = 0;
    for r in rates {
        let (inc, issue) = conv.push(r);
        match issue {
            Some(RateIssue::Gap { time, dt_s }) => {
                s.imu_gaps += 1;
                s.diagnostics
                    .push(file, 0, format!("IMU gap of {dt_s:.4} s ending at {time}"));
            }
            Some(RateIssue::NotIncreasing { time, previous }) => s.diagnostics.push(
                file,
                0,
                format!("IMU sample at {time} not after {previous}; dropped"),
            ),
            None => {}
        }
        if let Some(inc) = inc {
            line.clear();
            format_imu_line(&mut line, &inc);
            w.write(&line)?;
            n += 1;
        }
    }
    w.finish()?;
    s.imu_samples = n;
    s.files.push(path.display().to_string());
    Ok(())
}

fn convert_rate_csv(
    mut lines: LineReader<Box<dyn Read>>,
    out_dir: &Path,
    opts: &ConvertOptions,
    s: &mut ConvertSummary,
) -> Result<(), Error> {
    let input = &lines.path().to_path_buf();
    let offset_ns = (opts.imu_time_offset_s * 1e9).round() as i64;
    let mut rates = Vec::new();
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 8] = [b""; 8];
        let nf = split_fields(line, &mut f);
        if nf < 7 {
            s.diagnostics.push(
                input,
                no,
                format!("expected 7 fields (time, gyro x y z rad/s, accel x y z m/s²), found {nf}; line skipped"),
            );
            continue;
        }
        let t = match parse_seconds_ns(f[0]) {
            Ok(t) => t,
            Err(e) => {
                s.diagnostics
                    .push(input, no, format!("field 1 (time): {e}; line skipped"));
                continue;
            }
        };
        let mut v = [0.0; 6];
        let mut bad = None;
        for k in 0..6 {
            match parse_f64(f[k + 1]) {
                Ok(x) => v[k] = x,
                Err(e) => {
                    bad = Some(format!("field {}: {e}; line skipped", k + 2));
                    break;
                }
            }
        }
        if let Some(b) = bad {
            s.diagnostics.push(input, no, b);
            continue;
        }
        rates.push(RateSample {
            time: GpsTime::from_ns(t + offset_ns),
            gyro_radps: Vector3::new(v[0], v[1], v[2]),
            accel_mps2: Vector3::new(v[3], v[4], v[5]),
        });
    }
    if rates.len() < 2 {
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: "fewer than two rate samples (expected lines of `time gyro_x gyro_y gyro_z acc_x acc_y acc_z`)".into(),
        });
    }
    s.imu_time_axis = if opts.imu_time_offset_s != 0.0 {
        format!("the file's time + {} s", opts.imu_time_offset_s)
    } else {
        "the file's time column".into()
    };
    write_increments(
        &out_dir.join("imu.txt"),
        rates,
        input,
        opts.gap_threshold_s,
        s,
    )
}

fn convert_comma_gnss(
    mut lines: LineReader<Box<dyn Read>>,
    out_dir: &Path,
    opts: &ConvertOptions,
    s: &mut ConvertSummary,
) -> Result<(), Error> {
    let input = &lines.path().to_path_buf();
    let mut fixes: Vec<ReceiverFix> = Vec::new();
    let mut receipts: Vec<(GpsTime, Vec<u8>)> = Vec::new();
    let sd = opts.fix.default_sd_m;
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 8] = [b""; 8];
        let nf = split_fields(line, &mut f);
        if nf < 7 {
            s.diagnostics.push(
                input,
                no,
                format!("expected 7 fields (t_boot_s, lat, lon, speed, utc_unix_ms, alt, bearing), found {nf}; line skipped"),
            );
            continue;
        }
        let parsed = (|| -> Result<(f64, f64, i64, f64), String> {
            let lat = parse_f64(f[1]).map_err(|e| format!("field 2 (lat): {e}"))?;
            let lon = parse_f64(f[2]).map_err(|e| format!("field 3 (lon): {e}"))?;
            let ms = std::str::from_utf8(f[4])
                .ok()
                .and_then(|x| x.parse::<i64>().ok())
                .ok_or_else(|| "field 5 (utc_unix_ms): not an integer".to_string())?;
            let alt = parse_f64(f[5]).map_err(|e| format!("field 6 (alt): {e}"))?;
            if lat.abs() > 90.0 || lon.abs() > 180.0 {
                return Err(format!("latitude {lat} / longitude {lon} out of range"));
            }
            Ok((lat, lon, ms, alt))
        })();
        let (lat, lon, ms, alt) = match parsed {
            Ok(v) => v,
            Err(e) => {
                s.diagnostics.push(input, no, format!("{e}; line skipped"));
                continue;
            }
        };
        if parse_seconds_ns(f[0]).is_err() {
            s.diagnostics
                .push(input, no, "field 1 (t_boot_s): not a number; line skipped");
            continue;
        }
        let t = utc_to_gps(&UtcTime::from_unix_ns(ms * 1_000_000));
        fixes.push(ReceiverFix {
            fix: GnssFix {
                time: t,
                pos: navsync::earth::Geodetic::from_deg(lat, lon, alt),
                pos_sd: Vector3::new(sd[0], sd[1], sd[2]),
                vel: None,
                vel_sd: None,
            },
            leap: Some(LeapSource::Table),
            default_sd: true,
            geoid_from_model: false,
        });
        receipts.push((t, f[0].to_vec()));
    }
    if fixes.is_empty() {
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: "no fixes (expected comma2k19 gnss_ublox.csv lines)".into(),
        });
    }
    let fixes = monotonic(fixes, input, &mut s.diagnostics);
    s.gnss_source = "comma2k19 u-blox fixes (UTC fix time + leap seconds)".into();
    s.gnss_default_sd = fixes.len();
    s.leap_source = Some(LeapSource::Table);
    let gf: Vec<GnssFix> = fixes.iter().map(|f| f.fix).collect();
    write_gnss(&out_dir.join("gnss.txt"), &gf, s)?;
    let path: PathBuf = out_dir.join("gnss_receipt.txt");
    let mut w = TextWriter::create(&path)?;
    w.write(b"# gps_week gps_sow t_boot_received_s  (fix time of validity in GPS time; device boot time at receipt)\n")?;
    let mut kept = fixes.iter().map(|f| f.fix.time).peekable();
    let mut line = Vec::new();
    for (t, boot) in receipts {
        if kept.peek() != Some(&t) {
            continue;
        }
        kept.next();
        line.clear();
        line.extend_from_slice(format!("{} ", t.week()).as_bytes());
        t.write_sow(&mut line);
        line.push(b' ');
        line.extend_from_slice(&boot);
        line.push(b'\n');
        w.write(&line)?;
    }
    w.finish()?;
    s.files.push(path.display().to_string());
    Ok(())
}

fn convert_bag(
    format: InputFormat,
    mut reader: Box<dyn Read>,
    input: &Path,
    out_dir: &Path,
    opts: &ConvertOptions,
    topics: &TopicChoice,
    s: &mut ConvertSummary,
) -> Result<(), Error> {
    let mut bytes = Vec::new();
    reader
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(input, e))?;
    let bag_opts = BagOptions {
        default_sd_m: opts.fix.default_sd_m,
        altitude: opts.ros_altitude,
    };
    let ros = if format == InputFormat::Ros1Bag {
        "ROS 1"
    } else {
        "ROS 2"
    };
    let bag = if format == InputFormat::Ros1Bag {
        crate::ros1::read_bag(&bytes, input, topics, &bag_opts, &mut s.diagnostics)?
    } else {
        crate::ros2::read_bag_with(&bytes, input, topics, &bag_opts, &mut s.diagnostics)?
    };
    drop(bytes);
    if let Some(topic) = &bag.gnss_topic {
        s.fix_epochs.push(EpochTally {
            source: format!("{ros} NavSatFix {topic}"),
            epochs: bag.fix_messages,
            fixes: bag.fixes.len() as u64,
            dropped: bag
                .fix_drops
                .iter()
                .map(|(reason, &epochs)| DropTally {
                    reason: reason.clone(),
                    epochs,
                    kept_by: None,
                })
                .collect(),
        });
        if !bag.fixes.is_empty() {
            s.gnss_source =
                format!("{ros} NavSatFix on {topic} (header.stamp, UTC + leap seconds)");
            s.gnss_default_sd = bag.fixes.iter().filter(|f| f.default_sd).count();
            s.leap_source = Some(LeapSource::Table);
            if opts.ros_altitude == AltitudeDatum::Msl {
                s.geoid_model_heights = bag.fixes.len();
                s.geoid_model = Some(crate::geoid::EGM96_SOURCE.into());
            }
            let gf: Vec<GnssFix> = bag.fixes.iter().map(|f| f.fix).collect();
            write_gnss(&out_dir.join("gnss.txt"), &gf, s)?;
        }
    }
    if !bag.speeds.is_empty() {
        write_speeds(&out_dir.join("speed.txt"), &bag, s)?;
    }
    if let Some(topic) = &bag.imu_topic
        && !bag.imu.is_empty()
    {
        let offset = opts.imu_time_offset_s;
        s.imu_time_axis = format!(
            "GPS time from header.stamp on {topic} (UTC + leap seconds){}; axes FLU → FRD",
            if offset != 0.0 {
                format!(", + {offset} s")
            } else {
                String::new()
            }
        );
        let rates = bag
            .imu
            .into_iter()
            .map(|mut r| {
                r.time = r.time.add_seconds(offset);
                r
            })
            .collect();
        write_increments(
            &out_dir.join("imu.txt"),
            rates,
            input,
            opts.gap_threshold_s,
            s,
        )?;
    }
    if format == InputFormat::Ros1Bag {
        s.ros1 = Some(bag.summary);
    } else {
        s.ros2 = Some(bag.summary);
    }
    Ok(())
}

/// `speed.txt`: `sow speed_mps` lines (FORMATS.md, `navsync::io::speed`).
fn write_speeds(path: &Path, bag: &BagData, s: &mut ConvertSummary) -> Result<(), Error> {
    let mut w = TextWriter::create(path)?;
    let src = bag
        .summary
        .speed
        .as_ref()
        .map(|p| format!("{} on {}", p.source, p.topic))
        .unwrap_or_default();
    w.write(format!("# sow speed_mps  (GPS seconds of week; {src})\n").as_bytes())?;
    let mut line = Vec::with_capacity(48);
    for (t, v) in &bag.speeds {
        line.clear();
        t.write_sow(&mut line);
        line.extend_from_slice(format!(" {v}\n").as_bytes());
        w.write(&line)?;
    }
    w.finish()?;
    s.speeds = bag.speeds.len();
    s.files.push(path.display().to_string());
    Ok(())
}
