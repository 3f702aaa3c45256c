//! Raw IMU log reading for quality checks and conversion.
//!
//! Unlike [`crate::io::kfgins::ImuReader`], which hands the navigation only
//! good, increasing records, this reader keeps every record that parses —
//! duplicates and records out of time order included — so that the
//! quality analysis can count them. Lines that do not parse are reported
//! (file and line) and skipped, and counted as bad data.
//!
//! Two formats (FORMATS.md conventions: fields split by any mix of spaces,
//! tabs and commas; `#` comments and blank lines ignored):
//! - `kf-gins`: `sow dθx dθy dθz dvx dvy dvz [odo_speed]` (rad, m/s),
//!   increments over the interval ending at `sow` (FORMATS.md §1);
//! - `rate-csv`: `time gx gy gz ax ay az` (s, rad/s, m/s²), rates at
//!   `time`; one header line of column names may open the file.
//!
//! Mixed formats are errors, not skips: a run of records with another
//! field count, or whose values are rates where increments are expected
//! (or the reverse). Rates and increments are told apart by the specific
//! force: |f| ≈ g for rates, |Δv| ≈ g·Δt for increments; the geometric mean
//! g·√Δt separates them for Δt < 0.2 s.
#![warn(missing_docs)]

use std::collections::VecDeque;
use std::fs::File;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{Diagnostics, Error};
use crate::io::text::{LineReader, is_blank_or_comment, parse_seconds_ns};

/// Normal gravity used only to tell rates from increments (m/s²).
const G: f64 = 9.80665;
/// Records that decide (or confirm) the format at the start of a file.
const PROBE: usize = 32;
/// A run this long of records of another layout is a mixed-format error.
const MIXED_RUN: usize = 16;

/// The layout of an IMU log.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
pub enum ImuLogFormat {
    /// KF-GINS increments: `sow dθ(3) dv(3) [odo]`.
    KfGins,
    /// Rates: `time gyro(3) rad/s accel(3) m/s²`.
    RateCsv,
}

impl ImuLogFormat {
    /// The format's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            ImuLogFormat::KfGins => "kf-gins",
            ImuLogFormat::RateCsv => "rate-csv",
        }
    }

    fn holds_rates(self) -> bool {
        self == ImuLogFormat::RateCsv
    }
}

/// How a number was written: significant digits and the decimal exponent
/// of its last digit (the value is written to a resolution of
/// 10^`step_exp`).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FieldDigits {
    /// Significant digits written (leading zeros not counted).
    pub(crate) significant: u8,
    /// Decimal exponent of the last digit written.
    pub(crate) step_exp: i16,
}

impl FieldDigits {
    /// Counts digits of a numeric field (assumed to have parsed).
    #[inline]
    pub fn of(field: &[u8]) -> FieldDigits {
        let mut sig = 0u32;
        let mut leading = true;
        let mut decimals = 0i32;
        let mut after_dot = false;
        let mut exp = 0i32;
        let mut i = 0;
        let n = field.len();
        while i < n {
            let b = field[i];
            match b {
                b'0'..=b'9' => {
                    if b != b'0' || !leading {
                        leading = false;
                        sig += 1;
                    }
                    if after_dot {
                        decimals += 1;
                    }
                }
                b'.' => after_dot = true,
                b'e' | b'E' => {
                    let s = std::str::from_utf8(&field[i + 1..]).unwrap_or("0");
                    exp = s.parse().unwrap_or(0);
                    break;
                }
                _ => {}
            }
            i += 1;
        }
        FieldDigits {
            significant: sig.clamp(1, 255) as u8,
            step_exp: (exp - decimals).clamp(-400, 400) as i16,
        }
    }
}

/// One record as written.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LogRecord {
    /// 1-based line in the file.
    pub line: usize,
    /// The time stamp as written, in nanoseconds (sow or boot time).
    pub time_ns: i64,
    /// Increments (rad, m/s) for `kf-gins`, rates (rad/s, m/s²) for
    /// `rate-csv`: gyro x y z, then accelerometer x y z.
    pub values: [f64; 6],
    /// The optional odometer column of a KF-GINS file.
    pub odo: Option<f64>,
    /// How each of the six values was written (all zero on lines where
    /// digits were not counted: past line 4096, only every 8th line is).
    pub digits: [FieldDigits; 6],
}

/// Streams the records of an IMU log (see the module docs).
pub struct ImuLogReader {
    lines: Option<LineReader<File>>,
    path: PathBuf,
    declared: Option<ImuLogFormat>,
    format: Option<ImuLogFormat>,
    n_fields: Option<usize>,
    header: Option<String>,
    queue: VecDeque<LogRecord>,
    probe_votes_rate: usize,
    probe_votes: usize,
    probe_median_accel: Vec<f64>,
    records: usize,
    malformed: usize,
    other_fields_run: usize,
    other_fields_count: usize,
    other_fields_line: usize,
    other_class_run: usize,
    other_class_line: usize,
    prev_time_ns: Option<i64>,
    eof: bool,
}

impl ImuLogReader {
    /// Opens `path`; `format` `None` detects it from the first records.
    pub fn open(path: &Path, format: Option<ImuLogFormat>) -> Result<Self, Error> {
        let mut r = Self::sequencer(path, format);
        r.lines = Some(LineReader::open(path)?);
        Ok(r)
    }

    /// A reader fed by the caller through [`Self::sequence`] (lines parsed
    /// elsewhere, e.g. in parallel); `path` names the file in messages.
    pub(crate) fn sequencer(path: &Path, format: Option<ImuLogFormat>) -> Self {
        ImuLogReader {
            lines: None,
            path: path.to_path_buf(),
            declared: format,
            format: None,
            n_fields: None,
            header: None,
            queue: VecDeque::with_capacity(PROBE + 1),
            probe_votes_rate: 0,
            probe_votes: 0,
            probe_median_accel: Vec::with_capacity(PROBE),
            records: 0,
            malformed: 0,
            other_fields_run: 0,
            other_fields_count: 0,
            other_fields_line: 0,
            other_class_run: 0,
            other_class_line: 0,
            prev_time_ns: None,
            eof: false,
        }
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The format (declared, or detected once the first records are read).
    pub fn format(&self) -> Option<ImuLogFormat> {
        self.format.or(self.declared)
    }

    /// The header line of a `rate-csv`, if it had one.
    pub fn header(&self) -> Option<&str> {
        self.header.as_deref()
    }

    /// Records returned or queued so far.
    pub fn records(&self) -> usize {
        self.records
    }

    /// Lines that did not parse (reported and skipped).
    pub(crate) fn malformed(&self) -> usize {
        self.malformed
    }

    /// The next record; malformed lines are reported into `diag` and
    /// skipped. Errors: an empty file, mixed formats, a declared format the
    /// values contradict, I/O.
    pub fn next_record(&mut self, diag: &mut Diagnostics) -> Result<Option<LogRecord>, Error> {
        while self.format.is_none() {
            if !self.read_one(diag)? {
                self.decide_format()?;
                break;
            }
            if self.queue.len() > PROBE {
                self.decide_format()?;
            }
        }
        if self.queue.is_empty() && !self.eof {
            self.read_one(diag)?;
        }
        Ok(self.queue.pop_front())
    }

    fn decide_format(&mut self) -> Result<(), Error> {
        if self.queue.is_empty() {
            return Err(Error::NoData {
                path: self.path.clone(),
                msg: "no IMU records (expected `time gx gy gz ax ay az` rates or `sow dθx dθy dθz dvx dvy dvz` increments)".into(),
            });
        }
        let first_line = self.queue[0].line;
        let looks_rate = if self.probe_votes == 0 {
            None
        } else {
            let frac = self.probe_votes_rate as f64 / self.probe_votes as f64;
            if frac >= 0.75 {
                Some(true)
            } else if frac <= 0.25 {
                Some(false)
            } else {
                None
            }
        };
        let fmt = match (self.declared, looks_rate) {
            (Some(d), Some(r)) if d.holds_rates() != r => {
                let mut m = self.probe_median_accel.clone();
                let med = crate::stats::quantile(&mut m, 0.5);
                let (seen, want) = if r {
                    ("rates", ImuLogFormat::RateCsv)
                } else {
                    ("increments", ImuLogFormat::KfGins)
                };
                return Err(Error::parse(
                    &self.path,
                    first_line,
                    format!(
                        "the values look like {seen} (median |accel| {med:.4}), but format {} expects {}; use --format {}",
                        d.name(),
                        if d.holds_rates() {
                            "rates (|f| ≈ 9.8 m/s²)"
                        } else {
                            "increments (|Δv| ≈ 9.8 m/s² × Δt)"
                        },
                        want.name()
                    ),
                ));
            }
            (Some(d), _) => d,
            (None, Some(true)) => ImuLogFormat::RateCsv,
            (None, Some(false)) => ImuLogFormat::KfGins,
            (None, None) => {
                return Err(Error::parse(
                    &self.path,
                    first_line,
                    "cannot tell rates from increments in the first records: give --format kf-gins or --format rate-csv",
                ));
            }
        };
        if fmt == ImuLogFormat::RateCsv && self.n_fields != Some(7) {
            return Err(Error::parse(
                &self.path,
                first_line,
                format!(
                    "rate-csv expects 7 fields (time gx gy gz ax ay az), found {}",
                    self.n_fields.unwrap_or(0)
                ),
            ));
        }
        self.format = Some(fmt);
        Ok(())
    }

    /// Reads lines until one record is queued or the file ends; false at
    /// the end.
    fn read_one(&mut self, diag: &mut Diagnostics) -> Result<bool, Error> {
        loop {
            let Some(lines) = self.lines.as_mut() else {
                self.eof = true;
                return Ok(false);
            };
            let Some((line, line_no)) = lines.next_line()? else {
                self.eof = true;
                return Ok(false);
            };
            let want_digits = digits_wanted(line_no);
            let parsed = parse_line(line, want_digits);
            if self.sequence(line_no, parsed, diag)? {
                return Ok(true);
            }
        }
    }

    /// Takes the lines of a file in order (parsed by [`parse_line`],
    /// possibly on other threads) and applies the checks that need
    /// order: header, field count, mixed formats. Returns true when a
    /// record was queued for [`Self::take_record`].
    pub(crate) fn sequence(
        &mut self,
        line_no: usize,
        parsed: Parsed,
        diag: &mut Diagnostics,
    ) -> Result<bool, Error> {
        let (nf, rec) = match parsed {
            Parsed::Blank => return Ok(false),
            Parsed::Record(nf, rec) => (Some(nf), Ok(rec)),
            Parsed::Bad {
                nf,
                first_numeric,
                text,
                msg,
            } => {
                // A header of column names may open the file.
                if self.records == 0 && self.header.is_none() && !first_numeric {
                    self.header = Some(text);
                    return Ok(false);
                }
                (nf, Err(msg))
            }
        };
        if let Some(nf) = nf {
            let expected = match self.n_fields {
                Some(n) => n,
                None => {
                    if !(7..=8).contains(&nf) {
                        self.bad(diag, line_no, format!(
                            "expected 7 fields (time and six values) or 8 (KF-GINS with odometer), found {nf}; line skipped"
                        ));
                        return Ok(false);
                    }
                    nf
                }
            };
            if nf != expected {
                if self.other_fields_run > 0 && nf == self.other_fields_count {
                    self.other_fields_run += 1;
                } else {
                    self.other_fields_run = 1;
                    self.other_fields_count = nf;
                    self.other_fields_line = line_no;
                }
                if self.other_fields_run >= MIXED_RUN {
                    return Err(Error::parse(
                        &self.path,
                        self.other_fields_line,
                        format!(
                            "mixed formats: from this line on, records have {nf} fields where the file began with {expected} (two logs joined?)"
                        ),
                    ));
                }
                self.bad(diag, line_no, format!(
                    "expected {expected} fields like the records before, found {nf}; line skipped"
                ));
                return Ok(false);
            }
            self.other_fields_run = 0;
        }
        let mut rec = match rec {
            Ok(r) => r,
            Err(m) => {
                self.bad(diag, line_no, m);
                return Ok(false);
            }
        };
        rec.line = line_no;
        // Plausibility (`crate::io::plausible`): rates, or increments over
        // at most 1 s, within the limits of any sensor.
        let v = &rec.values;
        if let Some(why) = crate::io::plausible::rate_problem(
            &nalgebra::Vector3::new(v[0], v[1], v[2]),
            &nalgebra::Vector3::new(v[3], v[4], v[5]),
        ) {
            self.bad(diag, line_no, format!("{why}; line skipped"));
            return Ok(false);
        }
        if self.n_fields.is_none() {
            self.n_fields = nf;
        }
        self.classify(rec.time_ns, &rec.values, line_no)?;
        self.prev_time_ns = Some(rec.time_ns);
        self.records += 1;
        self.queue.push_back(rec);
        Ok(true)
    }

    /// After [`Self::sequence`]: the next record once the format is known
    /// (`None` while the format probe is still collecting).
    pub(crate) fn take_record(&mut self) -> Result<Option<LogRecord>, Error> {
        if self.format.is_none() {
            if self.queue.len() <= PROBE {
                return Ok(None);
            }
            self.decide_format()?;
        }
        Ok(self.queue.pop_front())
    }

    /// At the end of a file fed through [`Self::sequence`]: decides the
    /// format if the file was shorter than the probe, and returns the
    /// records still queued.
    pub(crate) fn finish_sequence(&mut self) -> Result<Vec<LogRecord>, Error> {
        if self.format.is_none() {
            self.decide_format()?;
        }
        Ok(self.queue.drain(..).collect())
    }

    /// Votes rate vs increment during the probe, then watches for a run
    /// of records of the other kind.
    fn classify(&mut self, time_ns: i64, v: &[f64; 6], line_no: usize) -> Result<(), Error> {
        let Some(prev) = self.prev_time_ns else {
            return Ok(());
        };
        let dt = (time_ns - prev) as f64 * 1e-9;
        if !(dt > 0.0 && dt < 0.2) {
            return Ok(());
        }
        let a = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5]).sqrt();
        if a == 0.0 {
            return Ok(());
        }
        let rate_like = a > G * dt.sqrt();
        match self.format {
            None => {
                self.probe_votes += 1;
                self.probe_votes_rate += usize::from(rate_like);
                self.probe_median_accel.push(a);
            }
            Some(fmt) => {
                if rate_like != fmt.holds_rates() {
                    if self.other_class_run == 0 {
                        self.other_class_line = line_no;
                    }
                    self.other_class_run += 1;
                    if self.other_class_run >= 2 * MIXED_RUN {
                        return Err(Error::parse(
                            &self.path,
                            self.other_class_line,
                            format!(
                                "mixed formats: from this line on the values look like {} while the file holds {} (two logs joined?)",
                                if rate_like { "rates" } else { "increments" },
                                if fmt.holds_rates() {
                                    "rates"
                                } else {
                                    "increments"
                                }
                            ),
                        ));
                    }
                } else {
                    self.other_class_run = 0;
                }
            }
        }
        Ok(())
    }

    fn bad(&mut self, diag: &mut Diagnostics, line: usize, msg: String) {
        self.malformed += 1;
        diag.push(&self.path, line, msg);
    }
}

/// One line, parsed without context (so lines can be parsed in parallel;
/// [`ImuLogReader::sequence`] applies the checks that need order).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Parsed {
    /// Blank or a `#` comment.
    Blank,
    /// A record with its field count (not yet checked against the file).
    Record(usize, LogRecord),
    /// A line that does not parse: its field count (None if unknown),
    /// whether its first field is a number (else it may be a header), its
    /// text, and why.
    Bad {
        nf: Option<usize>,
        first_numeric: bool,
        text: String,
        msg: String,
    },
}

/// Digit counts are gathered on the first 4096 lines and every 8th line
/// after (they describe how the file was written, which does not change).
#[inline]
pub(crate) fn digits_wanted(line_no: usize) -> bool {
    line_no <= 4096 || line_no.is_multiple_of(8)
}

/// Parses one line (without its terminator); `want_digits` also counts the
/// digits written ([`FieldDigits`]; zeros otherwise).
pub(crate) fn parse_line(line: &[u8], want_digits: bool) -> Parsed {
    if is_blank_or_comment(line) {
        return Parsed::Blank;
    }
    // One UTF-8 check per line; fields are then `&str` slices at ASCII
    // separators.
    let Ok(text) = std::str::from_utf8(line) else {
        return Parsed::Bad {
            nf: None,
            first_numeric: true,
            text: String::new(),
            msg: "not text (invalid UTF-8); line skipped".into(),
        };
    };
    let mut f: [&str; 12] = [""; 12];
    let nf = split_str(text, &mut f);
    let bad = |first_numeric: bool, msg: String| Parsed::Bad {
        nf: Some(nf),
        first_numeric,
        text: if first_numeric {
            String::new()
        } else {
            text.to_string()
        },
        msg,
    };
    let time_ns = match parse_seconds_ns(f[0].as_bytes()) {
        Ok(v) => v,
        Err(e) => {
            let numeric = f[0].parse::<f64>().is_ok();
            return bad(numeric, format!("field 1 (time): {e}; line skipped"));
        }
    };
    if nf < 7 {
        return bad(true, format!("expected 7 fields, found {nf}; line skipped"));
    }
    let mut values = [0.0; 6];
    let mut digits = [FieldDigits::default(); 6];
    for k in 0..6 {
        match parse_finite(f[k + 1]) {
            Ok(v) => {
                values[k] = v;
                if want_digits {
                    digits[k] = FieldDigits::of(f[k + 1].as_bytes());
                }
            }
            Err(e) => return bad(true, format!("field {}: {e}; line skipped", k + 2)),
        }
    }
    let odo = if nf == 8 {
        match parse_finite(f[7]) {
            Ok(v) => Some(v),
            Err(e) => return bad(true, format!("field 8 (odometer): {e}; line skipped")),
        }
    } else {
        None
    };
    Parsed::Record(
        nf,
        LogRecord {
            line: 0,
            time_ns,
            values,
            odo,
            digits,
        },
    )
}

/// Splits a line at any mix of spaces, tabs and commas (FORMATS.md);
/// returns the field count (at most `out.len()` stored).
#[inline]
fn split_str<'a>(line: &'a str, out: &mut [&'a str]) -> usize {
    let mut count = 0;
    // Separators are ASCII: every range is on a character boundary.
    crate::io::text::for_each_field(line.as_bytes(), |s, e| {
        if count < out.len() {
            out[count] = &line[s..e];
        }
        count += 1;
    });
    count
}

/// A finite `f64`, or why not.
#[inline]
fn parse_finite(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("'{s}' is not a finite number")),
        Err(_) => Err(format!("'{s}' is not a number")),
    }
}

/// What [`TimeOrder::check`] found about one record.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Order {
    /// After the last accepted record.
    Next,
    /// Same time as the last accepted record.
    Duplicate,
    /// Before the last accepted record.
    Backwards,
}

/// Guards time order for conversion: duplicates and isolated records out
/// of order are for the caller to report and skip; a time that goes back
/// and stays back (a clock reset, two logs joined) is an error naming the
/// line where it happened.
#[derive(Clone, Debug, Default)]
pub struct TimeOrder {
    last_ns: Option<i64>,
    behind_run: usize,
    behind_line: usize,
    behind_by_ns: i64,
}

impl TimeOrder {
    /// Records behind the last accepted time that make a reset.
    pub(crate) const RESET_RUN: usize = 16;

    /// Checks the time order of the next record (`path` names the file in errors).
    pub fn check(&mut self, path: &Path, rec: &LogRecord) -> Result<Order, Error> {
        let Some(last) = self.last_ns else {
            self.last_ns = Some(rec.time_ns);
            return Ok(Order::Next);
        };
        if rec.time_ns > last {
            self.last_ns = Some(rec.time_ns);
            self.behind_run = 0;
            return Ok(Order::Next);
        }
        if rec.time_ns == last {
            return Ok(Order::Duplicate);
        }
        if self.behind_run == 0 {
            self.behind_line = rec.line;
            self.behind_by_ns = last - rec.time_ns;
        }
        self.behind_run += 1;
        if self.behind_run >= Self::RESET_RUN {
            return Err(Error::parse(
                path,
                self.behind_line,
                format!(
                    "time goes back {:.6} s here and does not recover within {} records: expected increasing times in one IMU stream (a clock reset, or two logs joined?)",
                    self.behind_by_ns as f64 * 1e-9,
                    Self::RESET_RUN
                ),
            ));
        }
        Ok(Order::Backwards)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn temp_file(name: &str, content: &str) -> crate::testfiles::TestDir {
        crate::testfiles::temp_file("imulog", name, content)
    }

    fn read_all(
        p: &Path,
        fmt: Option<ImuLogFormat>,
    ) -> (Result<Vec<LogRecord>, Error>, Diagnostics) {
        let mut d = Diagnostics::default();
        let mut r = match ImuLogReader::open(p, fmt) {
            Ok(r) => r,
            Err(e) => return (Err(e), d),
        };
        let mut out = Vec::new();
        let res = loop {
            match r.next_record(&mut d) {
                Ok(Some(x)) => out.push(x),
                Ok(None) => break Ok(out),
                Err(e) => break Err(e),
            }
        };
        (res, d)
    }

    fn rate_lines(n: usize, t0: f64) -> String {
        (0..n)
            .map(|k| format!("{:.6},0.01,-0.02,0.03,0.1,0.2,-9.8\n", t0 + k as f64 * 0.01))
            .collect()
    }

    fn inc_lines(n: usize, t0: f64) -> String {
        (0..n)
            .map(|k| {
                format!(
                    "{:.3} 1e-5 2e-5 -3e-5 1e-4 2e-4 -4.9e-2\n",
                    t0 + k as f64 * 0.005
                )
            })
            .collect()
    }

    #[test]
    fn digits_are_counted() {
        assert_eq!(
            FieldDigits::of(b"-0.02810668945"),
            FieldDigits {
                significant: 10,
                step_exp: -11
            }
        );
        assert_eq!(
            FieldDigits::of(b"2.2899799383470081e-07"),
            FieldDigits {
                significant: 17,
                step_exp: -23
            }
        );
        assert_eq!(
            FieldDigits::of(b"12"),
            FieldDigits {
                significant: 2,
                step_exp: 0
            }
        );
        assert_eq!(
            FieldDigits::of(b"0.000"),
            FieldDigits {
                significant: 1,
                step_exp: -3
            }
        );
        assert_eq!(
            FieldDigits::of(b"-9.8E+1"),
            FieldDigits {
                significant: 2,
                step_exp: 0
            }
        );
    }

    #[test]
    fn formats_are_detected_and_a_header_is_kept() {
        let p = temp_file(
            "r.csv",
            &format!("# note\ntime,gx,gy,gz,ax,ay,az\n{}", rate_lines(50, 100.0)),
        );
        let (recs, d) = read_all(&p, None);
        assert_eq!(recs.unwrap().len(), 50);
        assert!(d.is_empty());
        let mut r = ImuLogReader::open(&p, None).unwrap();
        let mut d = Diagnostics::default();
        let first = r.next_record(&mut d).unwrap().unwrap();
        assert_eq!(first.line, 3);
        assert_eq!(r.format(), Some(ImuLogFormat::RateCsv));
        assert_eq!(r.header(), Some("time,gx,gy,gz,ax,ay,az"));

        let p = temp_file("i.txt", &inc_lines(50, 1000.0));
        let mut r = ImuLogReader::open(&p, None).unwrap();
        r.next_record(&mut d).unwrap().unwrap();
        assert_eq!(r.format(), Some(ImuLogFormat::KfGins));
        // A short file (fewer records than the probe) is still decided.
        let p = temp_file("short.txt", &inc_lines(3, 1000.0));
        assert_eq!(read_all(&p, None).0.unwrap().len(), 3);
    }

    #[test]
    fn a_declared_format_the_values_contradict_is_an_error_naming_the_line() {
        let p = temp_file(
            "r.csv",
            &format!("time,gx,gy,gz,ax,ay,az\n{}", rate_lines(50, 100.0)),
        );
        let err = read_all(&p, Some(ImuLogFormat::KfGins))
            .0
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("r.csv:2:")
                && err.contains("look like rates")
                && err.contains("--format rate-csv"),
            "{err}"
        );
        let p = temp_file("i.txt", &inc_lines(50, 1000.0));
        let err = read_all(&p, Some(ImuLogFormat::RateCsv))
            .0
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("i.txt:1:") && err.contains("look like increments"),
            "{err}"
        );
    }

    #[test]
    fn malformed_lines_are_reported_with_file_and_line_and_skipped() {
        let mut s = rate_lines(40, 100.0);
        s.push_str("100.400,0.01,x,0.03,0.1,0.2,-9.8\n");
        s.push_str("100.410,0.01,0.02\n");
        s.push_str("100.420,0.01,0.02,nan,0.1,0.2,-9.8\n");
        s.push_str("1O0.430,0.01,0.02,0.03,0.1,0.2,-9.8\n");
        s.push_str("100.435,1e20,0.02,0.03,0.1,0.2,-9.8\n");
        s.push_str(&rate_lines(5, 100.44));
        let p = temp_file("bad.csv", &s);
        let (recs, d) = read_all(&p, Some(ImuLogFormat::RateCsv));
        assert_eq!(recs.unwrap().len(), 45);
        assert_eq!(d.total, 5);
        let m: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
        assert!(
            m[0].contains("bad.csv:41: field 3: 'x' is not a number"),
            "{}",
            m[0]
        );
        assert!(m[1].contains("bad.csv:42: expected 7 fields"), "{}", m[1]);
        assert!(
            m[2].contains("bad.csv:43: field 4: 'nan' is not a finite number"),
            "{}",
            m[2]
        );
        assert!(m[3].contains("bad.csv:44: field 1 (time)"), "{}", m[3]);
        assert!(
            m[4].contains("bad.csv:45: angular rate 1e20 rad/s"),
            "{}",
            m[4]
        );
    }

    #[test]
    fn mixed_formats_are_errors_at_the_line_where_they_start() {
        // A KF-GINS file with an odometer column joined to one without.
        let mut s: String = inc_lines(40, 1000.0)
            .lines()
            .map(|l| format!("{l} 5.0\n"))
            .collect();
        s.push_str(&inc_lines(40, 1000.2));
        let p = temp_file("mix.txt", &s);
        let err = read_all(&p, None).0.unwrap_err().to_string();
        assert!(
            err.contains("mix.txt:41: mixed formats")
                && err.contains("7 fields")
                && err.contains("began with 8"),
            "{err}"
        );
        // Increments followed by rates with the same field count.
        let mut s = inc_lines(40, 1000.0);
        s.push_str(&rate_lines(60, 1000.2));
        let p = temp_file("mix2.txt", &s);
        let err = read_all(&p, None).0.unwrap_err().to_string();
        assert!(
            err.contains("mix2.txt:41: mixed formats") && err.contains("look like rates"),
            "{err}"
        );
    }

    #[test]
    fn an_empty_file_is_an_error() {
        let p = temp_file("empty.csv", "# nothing\n\n");
        let err = read_all(&p, None).0.unwrap_err().to_string();
        assert!(
            err.contains("empty.csv") && err.contains("no IMU records"),
            "{err}"
        );
    }

    #[test]
    fn time_order_reports_duplicates_and_fails_on_a_reset() {
        let rec = |line, t: i64| LogRecord {
            line,
            time_ns: t,
            values: [0.0; 6],
            odo: None,
            digits: [FieldDigits::default(); 6],
        };
        let p = Path::new("log.csv");
        let mut o = TimeOrder::default();
        assert_eq!(o.check(p, &rec(1, 10)).unwrap(), Order::Next);
        assert_eq!(o.check(p, &rec(2, 20)).unwrap(), Order::Next);
        assert_eq!(o.check(p, &rec(3, 20)).unwrap(), Order::Duplicate);
        assert_eq!(o.check(p, &rec(4, 15)).unwrap(), Order::Backwards);
        assert_eq!(o.check(p, &rec(5, 30)).unwrap(), Order::Next);
        let mut last = Ok(Order::Next);
        for k in 0..TimeOrder::RESET_RUN {
            last = o.check(p, &rec(100 + k, 1 + k as i64));
        }
        let err = last.unwrap_err().to_string();
        assert!(err.contains("log.csv:100: time goes back"), "{err}");
    }
}
