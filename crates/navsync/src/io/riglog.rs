//! Streaming reader of the raw acquisition log `rig-log v1` (FORMATS.md §2).
//!
//! The header (`# rig-log v1`, `# counter_hz`, `# counter_bits`, `# imu`)
//! is read on open; unknown `# key: value` header lines are kept and
//! reported as warnings (`# imu_rate_hz: 200` is understood). Records are
//! returned one at a time in file order. A record that is bad on its own
//! (unknown type, wrong field count, a field that is not a number, a
//! counter that does not fit the counter's width, a value no sensor
//! produces: `crate::io::plausible`) is reported with file and
//! line into [`Diagnostics`] and skipped: nothing else is lost. So is a last
//! line without newline (a logger killed mid-write): it may parse and still
//! be cut short.
#![warn(missing_docs)]

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use super::text::{
    LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, plain_number, split_fields,
};
use nalgebra::Vector3;

use crate::error::{Diagnostics, Error};
use crate::io::heading::{HeadingObs, HeadingSource, sd_problem};
use crate::io::plausible;
use crate::time::{GpsTime, NS_PER_WEEK};
use crate::words;

/// What the six values of an `imu` record are.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImuKind {
    /// Gyro rates (rad/s) then specific forces (m/s²), FRD.
    Rate,
    /// Angle increments (rad) then velocity increments (m/s), FRD.
    Increment,
}

/// What the counter of an `imu` record latched (header `imu_timing`).
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ImuTiming {
    /// The IMU's data-ready edge (hardware sync).
    DataReady,
    /// The start of the IMU's serial frame (no sync pin, seed 000): the
    /// data are `imu_output_delay_s` older.
    FrameStart,
    /// The receipt of the frame by the host (software sync).
    Receive,
}

/// What an `imu` rate value is (header `imu_rates`): it decides how rates
/// become increments (seed 001 §1.1 trapezoid for instantaneous samples;
/// the rectangle over its own interval for an average, §1.3.1).
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RateSampling {
    /// Samples of the rates at the counter's instant: converted by the
    /// trapezoid rule.
    Instantaneous,
    /// Averages over the interval since the previous sample (an averaging
    /// IMU's output): converted by the rectangle rule.
    IntervalAverage,
}

/// The header of a rig log.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RigHeader {
    /// Nominal counter frequency (Hz).
    pub counter_hz: f64,
    /// Counter width: it wraps modulo 2^bits (1..=64).
    pub counter_bits: u32,
    /// Meaning of the IMU values.
    pub imu_kind: ImuKind,
    /// Nominal IMU rate (Hz) when the header gives `imu_rate_hz`.
    pub imu_rate_hz: Option<f64>,
    /// What the `imu` counters latch, when the header gives `imu_timing`.
    pub imu_timing: Option<ImuTiming>,
    /// The IMU's known output delay T_c (s, seed 000) from the frame's
    /// data instant to the frame start, when the header gives
    /// `imu_output_delay_s`.
    pub imu_output_delay_s: Option<f64>,
    /// Whether `imu` rates are instantaneous samples or averages over
    /// their interval, when the header gives `imu_rates`.
    pub imu_rates: Option<RateSampling>,
    /// Other `key: value` header lines, in order.
    pub extra: Vec<(String, String)>,
}

/// One GNSS fix as logged: valid at `time`, last byte received at `counter`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RigGnss {
    /// Raw counter (not unwrapped) at the last byte.
    pub counter: u64,
    /// Time of validity (GPS).
    pub time: GpsTime,
    /// Latitude (deg), positive north.
    pub lat_deg: f64,
    /// Longitude (deg), positive east.
    pub lon_deg: f64,
    /// Ellipsoidal height (m).
    pub h_m: f64,
    /// Standard deviations N, E, D (m).
    pub sd_m: [f64; 3],
}

/// One receiver heading as logged (a navsync extension of FORMATS.md §2,
/// docs/FORMATS.md): valid at `time`, last byte received at `counter`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RigHeading {
    /// Raw counter (not unwrapped) at the last byte.
    pub counter: u64,
    /// Time of validity (GPS).
    pub time: GpsTime,
    /// Clockwise from north (deg), in [0, 360).
    pub heading_deg: f64,
    /// σ (deg), in (0, [`crate::io::heading::MAX_HEADING_SD_DEG`]].
    pub sd_deg: f64,
    /// What it measures.
    pub source: HeadingSource,
}

impl RigHeading {
    /// The record of a measurement received at `counter`.
    pub fn from_obs(counter: u64, obs: &HeadingObs) -> Self {
        RigHeading {
            counter,
            time: obs.time,
            heading_deg: obs.heading_rad.to_degrees().rem_euclid(360.0),
            sd_deg: obs.sd_rad.to_degrees(),
            source: obs.source,
        }
    }

    /// The heading as a measurement.
    pub fn obs(&self) -> HeadingObs {
        HeadingObs {
            time: self.time,
            heading_rad: self.heading_deg.to_radians(),
            sd_rad: self.sd_deg.to_radians(),
            source: self.source,
        }
    }
}

/// One record of a rig log.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum RigRecord {
    /// Raw counter latched at a 1PPS rising edge.
    Pps {
        /// Raw counter (not unwrapped) at the edge.
        counter: u64,
    },
    /// A GNSS fix and its receive counter.
    Gnss(RigGnss),
    /// Raw counter at the IMU data-ready edge (or receipt) and six values.
    Imu {
        /// Raw counter (not unwrapped) at the latch (see [`ImuTiming`]).
        counter: u64,
        /// Gyro x y z then accelerometer x y z, FRD: rates (rad/s, m/s²) or
        /// increments (rad, m/s) as the header's [`ImuKind`] says.
        values: [f64; 6],
    },
    /// Raw counter latched at an edge that the GNSS receiver time-marked
    /// too (u-blox TIM-TM2 on EXTINT: a camera strobe, an IMU sync pulse
    /// divided down), and the receiver's GPS time of that edge:
    /// `mark,<counter>,<week>,<tow_s>[,…]`.
    Mark {
        /// Raw counter (not unwrapped) at the edge.
        counter: u64,
        /// The receiver's GPS time of the same edge.
        time: GpsTime,
    },
    /// A receiver heading (dual-antenna baseline or the receiver's vehicle
    /// heading) and its receive counter:
    /// `heading,<counter_rx>,<week>,<tow_s>,<heading_deg>,<sd_deg>[,<source>]`.
    Heading(RigHeading),
}

impl RigRecord {
    /// The raw counter of the record.
    pub fn counter(&self) -> u64 {
        match self {
            RigRecord::Pps { counter }
            | RigRecord::Imu { counter, .. }
            | RigRecord::Mark { counter, .. } => *counter,
            RigRecord::Gnss(g) => g.counter,
            RigRecord::Heading(h) => h.counter,
        }
    }
}

impl ImuKind {
    /// The header's words, both ways.
    const WORDS: [(ImuKind, &'static str); 2] =
        [(ImuKind::Rate, "rate"), (ImuKind::Increment, "increment")];

    /// The header's word for it.
    pub fn name(self) -> &'static str {
        words::word_of(&Self::WORDS, self)
    }
}

impl ImuTiming {
    /// The header's words, both ways.
    const WORDS: [(ImuTiming, &'static str); 3] = [
        (ImuTiming::DataReady, "data-ready"),
        (ImuTiming::FrameStart, "frame-start"),
        (ImuTiming::Receive, "receive"),
    ];

    /// The header's word for it.
    pub fn name(self) -> &'static str {
        words::word_of(&Self::WORDS, self)
    }
}

impl RateSampling {
    /// The header's words, both ways.
    const WORDS: [(RateSampling, &'static str); 2] = [
        (RateSampling::Instantaneous, "instantaneous"),
        (RateSampling::IntervalAverage, "interval-average"),
    ];

    /// The header's word for it.
    pub fn name(self) -> &'static str {
        words::word_of(&Self::WORDS, self)
    }
}

impl RigHeader {
    /// A header for a log on a `counter_hz`, `counter_bits` counter with
    /// `imu` records of `imu_kind`; the optional keys unset.
    pub fn new(counter_hz: f64, counter_bits: u32, imu_kind: ImuKind) -> Self {
        RigHeader {
            counter_hz,
            counter_bits,
            imu_kind,
            imu_rate_hz: None,
            imu_timing: None,
            imu_output_delay_s: None,
            imu_rates: None,
            extra: Vec::new(),
        }
    }

    /// The header lines (FORMATS.md §2) as [`RigLogReader`] reads them
    /// back: version, counter, IMU keys, then the extra keys.
    pub fn to_text(&self) -> String {
        let mut h = String::from("# rig-log v1\n");
        h.push_str(&format!(
            "# counter_hz: {}\n",
            plain_number(self.counter_hz)
        ));
        h.push_str(&format!("# counter_bits: {}\n", self.counter_bits));
        h.push_str(&format!("# imu: {}\n", self.imu_kind.name()));
        if let Some(r) = self.imu_rate_hz {
            h.push_str(&format!("# imu_rate_hz: {}\n", plain_number(r)));
        }
        if let Some(t) = self.imu_timing {
            h.push_str(&format!("# imu_timing: {}\n", t.name()));
        }
        if let Some(r) = self.imu_rates {
            h.push_str(&format!("# imu_rates: {}\n", r.name()));
        }
        if let Some(d) = self.imu_output_delay_s {
            h.push_str(&format!("# imu_output_delay_s: {}\n", plain_number(d)));
        }
        for (k, v) in &self.extra {
            h.push_str(&format!("# {k}: {v}\n"));
        }
        h
    }
}

/// Writers of rig-log records (FORMATS.md §2), one line each, appended to
/// a buffer: the simulator, the receiver converter and the sync benchmark
/// write through these, and [`RigLogReader`] reads every bit back.
pub mod write {
    use super::{RigGnss, RigHeading, RigRecord};
    use crate::numfmt::{push_f64, push_fixed, push_u64};
    use crate::time::GpsTime;

    /// Any record (a `mark` without the receiver's extra fields).
    pub fn record(buf: &mut Vec<u8>, r: &RigRecord) {
        match r {
            RigRecord::Pps { counter } => pps(buf, *counter),
            RigRecord::Imu { counter, values } => imu(buf, *counter, values),
            RigRecord::Gnss(g) => gnss(buf, g),
            RigRecord::Mark { counter, time } => mark(buf, *counter, *time, &[]),
            RigRecord::Heading(h) => heading(buf, h),
        }
    }

    /// `heading,<counter_rx>,<week>,<tow_s>,<heading_deg>,<sd_deg>,<source>`:
    /// the time of validity to the nanosecond, heading and σ in their
    /// shortest round-trip form (no bit lost).
    pub fn heading(buf: &mut Vec<u8>, h: &RigHeading) {
        buf.extend_from_slice(b"heading,");
        push_u64(buf, h.counter);
        buf.push(b',');
        push_u64(buf, h.time.week().max(0) as u64);
        buf.push(b',');
        h.time.write_sow(buf);
        for v in [h.heading_deg, h.sd_deg] {
            buf.push(b',');
            push_f64(buf, v);
        }
        buf.push(b',');
        buf.extend_from_slice(h.source.word().as_bytes());
        buf.push(b'\n');
    }

    /// `pps,<counter>`
    pub fn pps(buf: &mut Vec<u8>, counter: u64) {
        buf.extend_from_slice(b"pps,");
        push_u64(buf, counter);
        buf.push(b'\n');
    }

    /// `imu,<counter>,<x1>..<x6>`, the values in their shortest round-trip
    /// form (no bit lost).
    pub fn imu(buf: &mut Vec<u8>, counter: u64, values: &[f64; 6]) {
        buf.extend_from_slice(b"imu,");
        push_u64(buf, counter);
        for &v in values {
            buf.push(b',');
            push_f64(buf, v);
        }
        buf.push(b'\n');
    }

    /// `mark,<counter>,<week>,<tow_s>[,<extra>…]` (the receiver's edge
    /// time to the nanosecond; `extra`: channel, edge, count, accuracy as
    /// u-blox TIM-TM2 gives them).
    pub fn mark(buf: &mut Vec<u8>, counter: u64, time: GpsTime, extra: &[u64]) {
        buf.extend_from_slice(b"mark,");
        push_u64(buf, counter);
        buf.push(b',');
        push_u64(buf, time.week().max(0) as u64);
        buf.push(b',');
        time.write_sow(buf);
        for &x in extra {
            buf.push(b',');
            push_u64(buf, x);
        }
        buf.push(b'\n');
    }

    /// `gnss,<counter_rx>,<week>,<tow_s>,<lat_deg>,<lon_deg>,<h_m>,<sd_n>,<sd_e>,<sd_d>`:
    /// the time of validity to the millisecond when it is whole
    /// milliseconds (else to the nanosecond), latitude and longitude to
    /// 1e-11° (1 mm), height and σ to 0.1 mm.
    pub fn gnss(buf: &mut Vec<u8>, g: &RigGnss) {
        let (counter, time) = (g.counter, g.time);
        buf.extend_from_slice(b"gnss,");
        push_u64(buf, counter);
        buf.push(b',');
        push_u64(buf, time.week().max(0) as u64);
        buf.push(b',');
        let ns = time.ns_of_week();
        if ns % 1_000_000 == 0 {
            push_fixed(buf, ns as f64 * 1e-9, 3);
        } else {
            time.write_sow(buf);
        }
        for (v, dec) in [
            (g.lat_deg, 11),
            (g.lon_deg, 11),
            (g.h_m, 4),
            (g.sd_m[0], 4),
            (g.sd_m[1], 4),
            (g.sd_m[2], 4),
        ] {
            buf.push(b',');
            push_fixed(buf, v, dec);
        }
        buf.push(b'\n');
    }
}

/// Streaming rig-log reader over any byte source.
pub struct RigLogReader<R> {
    lines: LineReader<R>,
    path: PathBuf,
    header: RigHeader,
    /// First record line, read while scanning the header, and whether it
    /// ended in a newline.
    pending: Option<(Vec<u8>, usize, bool)>,
    records: usize,
    counter_max: u64,
}

impl RigLogReader<File> {
    /// Opens `path` and reads its header. Header warnings go to `diag`.
    pub fn open(path: &Path, diag: &mut Diagnostics) -> Result<Self, Error> {
        Self::new(LineReader::open(path)?, diag)
    }
}

impl<R: Read> RigLogReader<R> {
    /// Reads the header from `lines`.
    pub fn new(mut lines: LineReader<R>, diag: &mut Diagnostics) -> Result<Self, Error> {
        let path = lines.path().to_path_buf();
        let mut magic = false;
        let mut counter_hz = None;
        let mut counter_bits = None;
        let mut imu_kind = None;
        let mut imu_rate_hz = None;
        let mut imu_timing = None;
        let mut imu_output_delay_s = None;
        let mut imu_rates = None;
        let mut extra = Vec::new();
        let mut pending = None;
        let mut first_line = true;
        while let Some((line, no, ended)) = lines.next_line_ended()? {
            let text = String::from_utf8_lossy(line);
            let t = text.trim();
            if t.is_empty() {
                continue;
            }
            let Some(comment) = t.strip_prefix('#') else {
                pending = Some((line.to_vec(), no, ended));
                break;
            };
            let c = comment.trim();
            if first_line {
                first_line = false;
                if c == "rig-log v1" {
                    magic = true;
                    continue;
                }
                if c.starts_with("rig-log") {
                    return Err(Error::parse(
                        &path,
                        no,
                        format!("unsupported version '{c}' (this reader knows 'rig-log v1')"),
                    ));
                }
            }
            let Some((key, value)) = c.split_once(':') else {
                continue; // a plain comment
            };
            let (key, value) = (key.trim(), value.trim());
            // Values may be followed by a comment ("1000000   nominal ...").
            let first = value.split_whitespace().next().unwrap_or("");
            match key {
                "counter_hz" => match first.parse::<f64>() {
                    Ok(v) if v.is_finite() && v > 0.0 => counter_hz = Some(v),
                    _ => {
                        return Err(Error::parse(
                            &path,
                            no,
                            format!(
                                "counter_hz: expected a positive frequency in Hz, found '{value}'"
                            ),
                        ));
                    }
                },
                "counter_bits" => match first.parse::<u32>() {
                    Ok(v) if (1..=64).contains(&v) => counter_bits = Some(v),
                    _ => {
                        return Err(Error::parse(
                            &path,
                            no,
                            format!(
                                "counter_bits: expected an integer from 1 to 64, found '{value}'"
                            ),
                        ));
                    }
                },
                "imu" => {
                    imu_kind = Some(match words::from_word(&ImuKind::WORDS, first) {
                        Some(k) => k,
                        None => {
                            return Err(Error::parse(
                                &path,
                                no,
                                format!(
                                    "imu: expected {}, found '{value}'",
                                    words::quoted_choices(&ImuKind::WORDS)
                                ),
                            ));
                        }
                    })
                }
                "imu_rate_hz" => match first.parse::<f64>() {
                    Ok(v) if v.is_finite() && v > 0.0 => imu_rate_hz = Some(v),
                    _ => diag.push(
                        &path,
                        no,
                        format!("imu_rate_hz: '{value}' is not a positive rate; ignored"),
                    ),
                },
                "imu_timing" => match words::from_word(&ImuTiming::WORDS, first) {
                    Some(t) => imu_timing = Some(t),
                    None => diag.push(
                        &path,
                        no,
                        format!(
                            "imu_timing: expected {}, found '{value}'; ignored",
                            words::quoted_choices(&ImuTiming::WORDS)
                        ),
                    ),
                },
                "imu_rates" => match words::from_word(&RateSampling::WORDS, first) {
                    Some(r) => imu_rates = Some(r),
                    None => diag.push(
                        &path,
                        no,
                        format!(
                            "imu_rates: expected {}, found '{value}'; ignored",
                            words::quoted_choices(&RateSampling::WORDS)
                        ),
                    ),
                },
                "imu_output_delay_s" => match first.parse::<f64>() {
                    Ok(v) if v.is_finite() && (0.0..1.0).contains(&v) => {
                        imu_output_delay_s = Some(v)
                    }
                    _ => diag.push(
                        &path,
                        no,
                        format!(
                            "imu_output_delay_s: expected a delay in seconds in [0, 1), found '{value}'; ignored"
                        ),
                    ),
                },
                _ => {
                    diag.push(
                        &path,
                        no,
                        format!("unknown header line '{key}: {value}' skipped"),
                    );
                    extra.push((key.to_string(), value.to_string()));
                }
            }
        }
        if !magic {
            let msg = if pending.is_none() && counter_hz.is_none() {
                "empty log: expected a '# rig-log v1' header and records".to_string()
            } else {
                "not a rig log: the first line must be '# rig-log v1'".to_string()
            };
            return Err(Error::parse(&path, 1, msg));
        }
        let counter_hz = counter_hz
            .ok_or_else(|| Error::parse(&path, 1, "header has no '# counter_hz: <Hz>' line"))?;
        let counter_bits = match counter_bits {
            Some(b) => b,
            None => {
                diag.push(
                    &path,
                    1,
                    "header has no '# counter_bits' line: assuming a 64-bit counter that never wraps",
                );
                64
            }
        };
        let imu_kind = imu_kind
            .ok_or_else(|| Error::parse(&path, 1, "header has no '# imu: rate|increment' line"))?;
        let counter_max = if counter_bits == 64 {
            u64::MAX
        } else {
            (1u64 << counter_bits) - 1
        };
        Ok(RigLogReader {
            lines,
            path,
            header: RigHeader {
                counter_hz,
                counter_bits,
                imu_kind,
                imu_rate_hz,
                imu_timing,
                imu_output_delay_s,
                imu_rates,
                extra,
            },
            pending,
            records: 0,
            counter_max,
        })
    }

    /// The header read on open.
    pub fn header(&self) -> &RigHeader {
        &self.header
    }

    /// The file name used in messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Good records returned so far.
    pub fn records(&self) -> usize {
        self.records
    }

    /// The next good record with its line number; bad lines are reported
    /// into `diag` and skipped. `None` at the end of the file.
    pub fn next_record(
        &mut self,
        diag: &mut Diagnostics,
    ) -> Result<Option<(RigRecord, usize)>, Error> {
        if let Some((line, no, terminated)) = self.pending.take() {
            if !terminated {
                torn_line(&line, no, &self.path, diag);
            } else if let Some(r) = parse_record(&line, no, &self.path, self.counter_max, diag)
                && self.plausible(&r, no, diag)
            {
                self.records += 1;
                return Ok(Some((r, no)));
            }
        }
        loop {
            let Some((line, no, ended)) = self.lines.next_line_ended()? else {
                return Ok(None);
            };
            if is_blank_or_comment(line) {
                continue;
            }
            if !ended {
                // It may parse and still be wrong ("pps,12" of "pps,1234").
                torn_line(line, no, &self.path, diag);
                return Ok(None);
            }
            let rec = parse_record(line, no, &self.path, self.counter_max, diag);
            if let Some(r) = rec
                && self.plausible(&r, no, diag)
            {
                self.records += 1;
                return Ok(Some((r, no)));
            }
        }
    }

    /// False (reported) for a record no sensor produces
    /// (`crate::io::plausible`): rates beyond its limits, increments beyond
    /// them over ten nominal periods (1 s when the header gives no rate),
    /// a fix off the earth.
    fn plausible(&self, r: &RigRecord, no: usize, diag: &mut Diagnostics) -> bool {
        let why = match r {
            RigRecord::Imu { values, .. } => {
                let g = Vector3::new(values[0], values[1], values[2]);
                let a = Vector3::new(values[3], values[4], values[5]);
                match self.header.imu_kind {
                    ImuKind::Rate => plausible::rate_problem(&g, &a),
                    ImuKind::Increment => {
                        let dt_s = self.header.imu_rate_hz.map_or(1.0, |hz| 10.0 / hz);
                        plausible::increment_problem(&g, &a, dt_s)
                    }
                }
            }
            RigRecord::Gnss(g) => plausible::position_problem(g.lat_deg, g.lon_deg, g.h_m),
            _ => None,
        };
        match why {
            Some(why) => {
                diag.push(&self.path, no, format!("{why}; line skipped"));
                false
            }
            None => true,
        }
    }
}

/// Exact powers of ten representable in an `f64`.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Parses a decimal number. Fast path (Clinger 1990, "How to read floating
/// point numbers accurately"): a mantissa below 2^53 and a power of ten up
/// to 22 are both exact doubles, so one IEEE multiplication or division is
/// correctly rounded. Anything else goes to the standard parser.
#[inline]
fn parse_number(field: &[u8]) -> Result<f64, String> {
    let n = field.len();
    let mut i = 0;
    let neg = match field.first() {
        Some(b'-') => {
            i = 1;
            true
        }
        Some(b'+') => {
            i = 1;
            false
        }
        _ => false,
    };
    let mut m: u64 = 0;
    let mut digits = 0u32;
    let mut frac = 0i32;
    let mut seen_dot = false;
    let mut any = false;
    while i < n {
        let c = field[i];
        if c.is_ascii_digit() {
            any = true;
            if digits < 19 {
                m = m * 10 + (c - b'0') as u64;
                if m > 0 {
                    digits += 1;
                }
                if seen_dot {
                    frac += 1;
                }
            } else {
                return parse_f64(field);
            }
        } else if c == b'.' && !seen_dot {
            seen_dot = true;
        } else {
            break;
        }
        i += 1;
    }
    let mut exp: i32 = 0;
    if i < n {
        if !(field[i] == b'e' || field[i] == b'E') || !any {
            return parse_f64(field);
        }
        i += 1;
        let eneg = match field.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let start = i;
        while i < n && field[i].is_ascii_digit() && i - start < 4 {
            exp = exp * 10 + (field[i] - b'0') as i32;
            i += 1;
        }
        if i == start || i < n {
            return parse_f64(field);
        }
        if eneg {
            exp = -exp;
        }
    }
    if !any {
        return parse_f64(field);
    }
    let e10 = exp - frac;
    let v = if m == 0 {
        0.0
    } else if m < (1u64 << 53) && (-22..=22).contains(&e10) {
        let x = m as f64;
        if e10 >= 0 {
            x * POW10[e10 as usize]
        } else {
            x / POW10[(-e10) as usize]
        }
    } else {
        return parse_f64(field);
    };
    Ok(if neg { -v } else { v })
}

fn parse_counter(field: &[u8], counter_max: u64) -> Result<u64, String> {
    // Fast path: plain digits.
    if !field.is_empty() && field.len() <= 19 && field.iter().all(u8::is_ascii_digit) {
        let v = field.iter().fold(0u64, |a, &c| a * 10 + (c - b'0') as u64);
        if v > counter_max {
            return Err(format!(
                "counter {v} does not fit the counter width (max {counter_max})"
            ));
        }
        return Ok(v);
    }
    let s = std::str::from_utf8(field).map_err(|_| "counter is not text".to_string())?;
    let v: u64 = s
        .parse()
        .map_err(|_| format!("counter '{s}' is not a non-negative integer"))?;
    if v > counter_max {
        return Err(format!(
            "counter {v} does not fit the counter width (max {counter_max})"
        ));
    }
    Ok(v)
}

/// The counter in field 2 of a record, or a reported skip.
fn counter_field(
    field: &[u8],
    counter_max: u64,
    no: usize,
    path: &Path,
    diag: &mut Diagnostics,
) -> Option<u64> {
    parse_counter(field, counter_max)
        .map_err(|e| diag.push(path, no, format!("field 2: {e}; line skipped")))
        .ok()
}

/// GPS week and time of week in fields 3 and 4 of a record.
fn gps_time_fields(
    week: &[u8],
    tow: &[u8],
    no: usize,
    path: &Path,
    diag: &mut Diagnostics,
) -> Option<GpsTime> {
    let week = match std::str::from_utf8(week)
        .ok()
        .and_then(|s| s.parse::<i64>().ok())
    {
        Some(w) if (0..=100_000).contains(&w) => w,
        _ => {
            diag.push(
                path,
                no,
                format!(
                    "field 3: week '{}' is not a GPS week number; line skipped",
                    String::from_utf8_lossy(week)
                ),
            );
            return None;
        }
    };
    match parse_seconds_ns(tow) {
        Ok(t) if (0..NS_PER_WEEK).contains(&t) => Some(GpsTime::from_week_ns(week, t)),
        Ok(_) => {
            diag.push(
                path,
                no,
                "field 4: time of week outside 0..604800 s; line skipped",
            );
            None
        }
        Err(e) => {
            diag.push(path, no, format!("field 4: {e}; line skipped"));
            None
        }
    }
}

/// Reports the file's last line when it has no newline: a log cut while
/// the line was written (a logger killed, power lost). Even when it parses,
/// its last field may be cut short, so it is skipped.
fn torn_line(line: &[u8], no: usize, path: &Path, diag: &mut Diagnostics) {
    let shown = String::from_utf8_lossy(&line[..line.len().min(48)]);
    let more = if line.len() > 48 { "…" } else { "" };
    diag.push(
        path,
        no,
        format!(
            "last line '{shown}{more}' has no end of line: the log was cut while it was written; expected a whole record ending in a newline; line skipped (the records before it are kept)"
        ),
    );
}

/// `N` numbers from fields `from..from + N` (0-based; reported 1-based);
/// the first that does not parse is reported and gives `None`.
#[inline]
fn number_fields<const N: usize>(
    f: &[&[u8]],
    from: usize,
    parse: impl Fn(&[u8]) -> Result<f64, String>,
    no: usize,
    path: &Path,
    diag: &mut Diagnostics,
) -> Option<[f64; N]> {
    let mut v = [0.0; N];
    for (k, x) in v.iter_mut().enumerate() {
        match parse(f[from + k]) {
            Ok(n) => *x = n,
            Err(e) => {
                diag.push(
                    path,
                    no,
                    format!("field {}: {e}; line skipped", from + k + 1),
                );
                return None;
            }
        }
    }
    Some(v)
}

/// Parses one record line; reports and returns `None` when it is bad.
fn parse_record(
    line: &[u8],
    no: usize,
    path: &Path,
    counter_max: u64,
    diag: &mut Diagnostics,
) -> Option<RigRecord> {
    let mut f: [&[u8]; 11] = [b""; 11];
    let n = split_fields(line, &mut f);
    let kind = f[0];
    let expect = |diag: &mut Diagnostics, want: usize, layout: &str| {
        diag.push(
            path,
            no,
            if n > want {
                format!("extra fields: expected {want} ({layout}), found {n}; line skipped")
            } else {
                format!("expected {want} fields ({layout}), found {n}; line skipped")
            },
        );
    };
    match kind {
        b"imu" => {
            if n != 8 {
                expect(diag, 8, "imu,counter,x1..x6");
                return None;
            }
            let counter = counter_field(f[1], counter_max, no, path, diag)?;
            let values = number_fields::<6>(&f, 2, parse_number, no, path, diag)?;
            Some(RigRecord::Imu { counter, values })
        }
        b"pps" => {
            if n != 2 {
                expect(diag, 2, "pps,counter");
                return None;
            }
            let counter = counter_field(f[1], counter_max, no, path, diag)?;
            Some(RigRecord::Pps { counter })
        }
        b"gnss" => {
            if n != 10 {
                expect(
                    diag,
                    10,
                    "gnss,counter_rx,week,tow_s,lat_deg,lon_deg,h_m,sd_n,sd_e,sd_d",
                );
                return None;
            }
            let counter = counter_field(f[1], counter_max, no, path, diag)?;
            let time = gps_time_fields(f[2], f[3], no, path, diag)?;
            let v = number_fields::<6>(&f, 4, parse_f64, no, path, diag)?;
            if !(-90.0..=90.0).contains(&v[0]) || !(-180.0..=360.0).contains(&v[1]) {
                diag.push(path, no, "latitude or longitude out of range; line skipped");
                return None;
            }
            if v[3..].iter().any(|&s| s <= 0.0) {
                diag.push(
                    path,
                    no,
                    "GNSS standard deviations must be positive; line skipped",
                );
                return None;
            }
            Some(RigRecord::Gnss(RigGnss {
                counter,
                time,
                lat_deg: v[0],
                lon_deg: v[1],
                h_m: v[2],
                sd_m: [v[3], v[4], v[5]],
            }))
        }
        b"heading" => {
            if !(6..=7).contains(&n) {
                expect(
                    diag,
                    6,
                    "heading,counter_rx,week,tow_s,heading_deg,sd_deg[,baseline|vehicle]",
                );
                return None;
            }
            let counter = counter_field(f[1], counter_max, no, path, diag)?;
            let time = gps_time_fields(f[2], f[3], no, path, diag)?;
            let [heading_deg, sd_deg] = number_fields::<2>(&f, 4, parse_f64, no, path, diag)?;
            if !(heading_deg.is_finite() && (0.0..360.0).contains(&heading_deg)) {
                diag.push(
                    path,
                    no,
                    format!("heading {heading_deg}° outside [0, 360); line skipped"),
                );
                return None;
            }
            if let Some(why) = sd_problem(sd_deg) {
                diag.push(path, no, format!("{why}; line skipped"));
                return None;
            }
            let source = match HeadingSource::from_field((n == 7).then(|| f[6])) {
                Ok(s) => s,
                Err(w) => {
                    diag.push(
                        path,
                        no,
                        format!(
                            "heading source '{w}' is neither baseline nor vehicle; line skipped"
                        ),
                    );
                    return None;
                }
            };
            Some(RigRecord::Heading(RigHeading {
                counter,
                time,
                heading_deg,
                sd_deg,
                source,
            }))
        }
        b"mark" => {
            if n < 4 {
                expect(diag, 4, "mark,counter,week,tow_s");
                return None;
            }
            let counter = counter_field(f[1], counter_max, no, path, diag)?;
            let time = gps_time_fields(f[2], f[3], no, path, diag)?;
            Some(RigRecord::Mark { counter, time })
        }
        _ => {
            diag.push(
                path,
                no,
                format!(
                    "unknown record type '{}' skipped",
                    String::from_utf8_lossy(kind)
                ),
            );
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> (Result<Vec<RigRecord>, Error>, Diagnostics) {
        let mut diag = Diagnostics::default();
        let lines = LineReader::new(text.as_bytes(), Path::new("rig.csv"));
        let r = RigLogReader::new(lines, &mut diag).and_then(|mut r| {
            let mut v = Vec::new();
            while let Some((rec, _)) = r.next_record(&mut diag)? {
                v.push(rec);
            }
            Ok(v)
        });
        (r, diag)
    }

    #[test]
    fn a_torn_last_line_is_skipped_with_its_line_and_the_rest_kept() {
        let head = "# rig-log v1\n# counter_hz: 1000000000\n# counter_bits: 64\n# imu: rate\n";
        // Cut inside a counter: "pps,12" would parse, and be wrong.
        for cut in ["pps,12", "imu,5000,0.1,0.2,0.3,0.4,0.5,9.8", "gnss,7,2400"] {
            let text = format!("{head}pps,1000\nimu,2000,0,0,0,0,0,-9.8\n{cut}");
            let (r, d) = read(&text);
            assert_eq!(r.unwrap().len(), 2, "{cut}");
            assert_eq!(d.items.len(), 1, "{:?}", d.items);
            let m = &d.items[0].message;
            assert_eq!(d.items[0].line, 7);
            assert!(m.contains("no end of line") && m.contains(cut), "{m}");
        }
        // The only record, torn.
        let (r, d) = read(&format!("{head}pps,1"));
        assert!(r.unwrap().is_empty());
        assert_eq!(d.items[0].line, 5);
        // A whole last line is kept.
        let (r, d) = read(&format!("{head}pps,1000\npps,2000\n"));
        assert_eq!(r.unwrap().len(), 2);
        assert!(d.is_empty());
    }

    #[test]
    fn written_header_and_records_read_back_exactly() {
        let mut h = RigHeader::new(1e6, 32, ImuKind::Rate);
        h.imu_rate_hz = Some(200.0);
        h.imu_timing = Some(ImuTiming::FrameStart);
        h.imu_rates = Some(RateSampling::IntervalAverage);
        h.imu_output_delay_s = Some(0.0021);
        h.extra.push(("site".into(), "test track".into()));
        let t = GpsTime::from_week_sow(2300, 100001.0);
        let records = [
            RigRecord::Imu {
                counter: 4_095_394_224,
                values: [
                    4.7e-4,
                    -8.5e-4,
                    6.5e-6,
                    1.4e-2,
                    1.1e-2,
                    -9.793_512_345_678_9,
                ],
            },
            RigRecord::Pps { counter: 1 << 31 },
            RigRecord::Gnss(RigGnss {
                counter: 4_096_461_055,
                time: t,
                lat_deg: 30.444_784_635_51,
                lon_deg: -114.471_867_431_79,
                h_m: 22.1037,
                sd_m: [0.02, 0.025, 0.03],
            }),
            RigRecord::Mark {
                counter: 17,
                time: t + 123_456_789,
            },
        ];
        let mut text = h.to_text();
        let mut buf = Vec::new();
        for r in &records {
            write::record(&mut buf, r);
        }
        text.push_str(std::str::from_utf8(&buf).unwrap());
        let mut diag = Diagnostics::default();
        let lines = LineReader::new(text.as_bytes(), Path::new("rig.csv"));
        let mut r = RigLogReader::new(lines, &mut diag).unwrap();
        assert_eq!(r.header(), &h, "{text}");
        for want in records {
            let (got, _) = r.next_record(&mut diag).unwrap().unwrap();
            assert_eq!(got, want, "{text}");
        }
        assert!(r.next_record(&mut diag).unwrap().is_none());
        // The extra key is kept and noted as unknown to the reader.
        assert_eq!(diag.total, 1, "{diag:?}");
        assert!(diag.items[0].message.contains("site"), "{diag:?}");
    }

    const HEAD: &str = "# rig-log v1\n# counter_hz: 1000000        nominal\n# counter_bits: 32\n# imu: rate\n# imu_rate_hz: 200\n";

    #[test]
    fn reads_header_and_records() {
        let text = format!(
            "{HEAD}imu,4095394224,4.7e-04,8.5e-04,6.5e-06,1.4e-02,1.1e-02,-9.79\npps,4096372991\ngnss,4096461055,2300,100001.000,30.44478463551,114.47186743179,22.1037,0.0200,0.0200,0.0300\n"
        );
        let mut diag = Diagnostics::default();
        let lines = LineReader::new(text.as_bytes(), Path::new("rig.csv"));
        let mut r = RigLogReader::new(lines, &mut diag).unwrap();
        assert_eq!(r.header().counter_hz, 1e6);
        assert_eq!(r.header().counter_bits, 32);
        assert_eq!(r.header().imu_kind, ImuKind::Rate);
        assert_eq!(r.header().imu_rate_hz, Some(200.0));
        let (a, la) = r.next_record(&mut diag).unwrap().unwrap();
        assert_eq!(la, 6);
        assert!(matches!(
            a,
            RigRecord::Imu {
                counter: 4095394224,
                ..
            }
        ));
        let (b, _) = r.next_record(&mut diag).unwrap().unwrap();
        assert_eq!(
            b,
            RigRecord::Pps {
                counter: 4096372991
            }
        );
        let (c, _) = r.next_record(&mut diag).unwrap().unwrap();
        let RigRecord::Gnss(g) = c else { panic!() };
        assert_eq!(g.time, GpsTime::from_week_sow(2300, 100001.0));
        assert_eq!(g.sd_m, [0.02, 0.02, 0.03]);
        assert!(r.next_record(&mut diag).unwrap().is_none());
        assert!(diag.is_empty(), "{diag:?}");
    }

    #[test]
    fn imu_timing_and_output_delay_headers() {
        let text = format!(
            "{HEAD}# imu_timing: frame-start\n# imu_output_delay_s: 0.0015  T_c\n# imu_rates: interval-average\nimu,1,1,2,3,4,5,6\n"
        );
        let mut diag = Diagnostics::default();
        let lines = LineReader::new(text.as_bytes(), Path::new("rig.csv"));
        let r = RigLogReader::new(lines, &mut diag).unwrap();
        assert_eq!(r.header().imu_timing, Some(ImuTiming::FrameStart));
        assert_eq!(r.header().imu_output_delay_s, Some(0.0015));
        assert_eq!(r.header().imu_rates, Some(RateSampling::IntervalAverage));
        assert!(diag.is_empty(), "{diag:?}");
        // Bad values are reported with their line and ignored.
        let text = format!(
            "{HEAD}# imu_timing: sometimes\n# imu_output_delay_s: -1\n# imu_rates: smoothed\n"
        );
        let lines = LineReader::new(text.as_bytes(), Path::new("rig.csv"));
        let r = RigLogReader::new(lines, &mut diag).unwrap();
        assert_eq!(r.header().imu_timing, None);
        assert_eq!(r.header().imu_output_delay_s, None);
        assert_eq!(r.header().imu_rates, None);
        let msgs: Vec<String> = diag.items.iter().map(|d| d.to_string()).collect();
        assert_eq!(msgs.len(), 3, "{msgs:?}");
        assert!(
            msgs[2].contains("rig.csv:8") && msgs[2].contains("imu_rates"),
            "{msgs:?}"
        );
        assert!(
            msgs[0].contains("rig.csv:6") && msgs[0].contains("imu_timing"),
            "{msgs:?}"
        );
        assert!(
            msgs[1].contains("rig.csv:7") && msgs[1].contains("imu_output_delay_s"),
            "{msgs:?}"
        );
    }

    #[test]
    fn mark_records_carry_the_receivers_time() {
        let text = format!(
            "{HEAD}mark,4095479611,2300,100000.512299985,0,1\nmark,7,2300\nmark,8,2300,604800.5\nmark,x,2300,1.0\n"
        );
        let (r, diag) = read(&text);
        let v = r.unwrap();
        assert_eq!(
            v,
            vec![RigRecord::Mark {
                counter: 4095479611,
                time: GpsTime::from_week_ns(2300, 100_000_512_299_985),
            }]
        );
        let msgs: Vec<String> = diag.items.iter().map(|d| d.to_string()).collect();
        assert_eq!(msgs.len(), 3, "{msgs:?}");
        assert!(msgs[0].contains(":7:") && msgs[0].contains("mark,counter,week,tow_s"));
        assert!(msgs[1].contains(":8:") && msgs[1].contains("time of week"));
        assert!(msgs[2].contains(":9:") && msgs[2].contains("field 2"));
    }

    #[test]
    fn heading_records_round_trip_and_bad_ones_are_skipped() {
        let good = [
            RigHeading {
                counter: 4095479611,
                time: GpsTime::from_week_ns(2300, 100_000_100_000_000),
                heading_deg: 359.123456,
                sd_deg: 0.25,
                source: HeadingSource::Baseline,
            },
            RigHeading {
                counter: 12,
                time: GpsTime::from_week_ns(2300, 100_000_512_299_985),
                heading_deg: 0.0,
                sd_deg: 30.0,
                source: HeadingSource::Vehicle,
            },
        ];
        let mut text = HEAD.to_string().into_bytes();
        for h in &good {
            write::record(&mut text, &RigRecord::Heading(*h));
        }
        // Without the source column: a baseline heading.
        text.extend_from_slice(b"heading,13,2300,100000.2,10.5,0.5\n");
        for bad in [
            "heading,14,2300,100000.3,10.5\n",
            "heading,15,2300,100000.3,360,0.5\n",
            "heading,16,2300,100000.3,nan,0.5\n",
            "heading,17,2300,100000.3,10,0\n",
            "heading,18,2300,100000.3,10,45\n",
            "heading,19,2300,100000.3,10,0.5,compass\n",
        ] {
            text.extend_from_slice(bad.as_bytes());
        }
        let (r, diag) = read(std::str::from_utf8(&text).unwrap());
        let v = r.unwrap();
        let third = RigHeading {
            counter: 13,
            time: GpsTime::from_week_ns(2300, 100_000_200_000_000),
            heading_deg: 10.5,
            sd_deg: 0.5,
            source: HeadingSource::Baseline,
        };
        let want: Vec<RigRecord> = good
            .iter()
            .chain([&third])
            .map(|h| RigRecord::Heading(*h))
            .collect();
        assert_eq!(v, want);
        let msgs: Vec<String> = diag.items.iter().map(|d| d.to_string()).collect();
        assert_eq!(msgs.len(), 6, "{msgs:?}");
        for (m, what) in msgs.iter().zip([
            "heading,counter_rx,week,tow_s,heading_deg,sd_deg",
            "outside [0, 360)",
            "field 5",
            "outside (0, 30]°",
            "outside (0, 30]°",
            "neither baseline nor vehicle",
        ]) {
            assert!(m.contains(what), "{m} lacks {what}");
        }
    }

    #[test]
    fn bad_lines_are_reported_and_skipped() {
        let text = format!(
            "{HEAD}# vendor: acme\nimu,1,1,2,3,4,5\nimu,2,1,2,3,4,5,6\nimu,x,1,2,3,4,5,6\nimu,3,1,2,nan,4,5,6\npps,4294967296\npps\ncam,5,6\ngnss,9,2300,1.0,30,114,10,0.1,0.1\ngnss,9,2300,1.0,30,114,10,0.1,0.1,0\npps,7\n"
        );
        let (r, diag) = read(&text);
        let recs = r.unwrap();
        assert_eq!(recs.len(), 2);
        assert!(matches!(recs[0], RigRecord::Imu { counter: 2, .. }));
        assert_eq!(recs[1], RigRecord::Pps { counter: 7 });
        // vendor header, 8 bad records
        assert_eq!(diag.total, 9, "{:#?}", diag.items);
        let lines: Vec<usize> = diag.items.iter().map(|d| d.line).collect();
        assert_eq!(lines, vec![6, 7, 9, 10, 11, 12, 13, 14, 15]);
        assert!(diag.items[1].message.contains("expected 8 fields"));
        assert!(diag.items[4].message.contains("does not fit"));
        assert!(diag.items[6].message.contains("unknown record type 'cam'"));
        assert!(diag.items.iter().all(|d| d.file == "rig.csv"));
    }

    #[test]
    fn fast_number_parsing_matches_the_standard_parser() {
        for s in [
            "4.7151651886e-04",
            "-9.7927725367e+00",
            "0",
            "-0.0",
            "1e22",
            "1e23",
            "123456789012345678901234",
            "0.1",
            "3.14159265358979323846",
            "-1.5E-3",
            "9007199254740993",
            "2.2250738585072014e-308",
            "7.",
            ".5",
            "+2.5",
        ] {
            let want: f64 = s.parse().unwrap();
            let got = parse_number(s.as_bytes()).unwrap();
            assert_eq!(got.to_bits(), want.to_bits(), "{s}");
        }
        for bad in ["", "-", "1e", "1.2.3", "e5", "nan", "inf", "1x", "1e5x"] {
            assert!(parse_number(bad.as_bytes()).is_err(), "{bad}");
        }
    }

    #[test]
    fn empty_and_headerless_logs_are_clear_errors() {
        let (r, _) = read("");
        let e = r.unwrap_err().to_string();
        assert!(e.contains("empty log"), "{e}");
        let (r, _) = read("pps,1\n");
        assert!(r.unwrap_err().to_string().contains("first line must be"));
        let (r, _) = read("# rig-log v1\n# counter_bits: 32\n# imu: rate\npps,1\n");
        assert!(r.unwrap_err().to_string().contains("counter_hz"));
        let (r, _) = read("# rig-log v2\n");
        assert!(r.unwrap_err().to_string().contains("unsupported version"));
        let (r, _) = read("# rig-log v1\n# counter_hz: 1e6\n# counter_bits: 99\n");
        assert!(r.unwrap_err().to_string().contains("counter_bits"));
        // header only: a valid, empty log (the engine reports "no records")
        let (r, _) = read(HEAD);
        assert!(r.unwrap().is_empty());
    }
}
