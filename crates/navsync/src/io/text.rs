//! Fast, careful text plumbing shared by every text format: a buffered line
//! reader that counts lines, a field splitter for "any mix of spaces, tabs
//! or commas" (FORMATS.md), exact decimal-seconds parsing into nanoseconds,
//! and fixed-decimal number formatting without allocation.
#![warn(missing_docs)]

use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::time::GpsTime;

/// Reads a file line by line into a reused buffer, counting lines (1-based)
/// and never holding more than one block of the file in memory.
pub struct LineReader<R> {
    inner: R,
    path: PathBuf,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    eof: bool,
    line_no: usize,
    /// Whether the line last returned ended in `\n`.
    terminated: bool,
}

const BLOCK: usize = 1 << 20;
/// Longest line read (bytes): a record of any navsync text format is a
/// few hundred bytes; a longer "line" is a binary file or a runaway
/// writer, refused before it fills memory.
pub const MAX_LINE_BYTES: usize = BLOCK;
/// The UTF-8 byte-order mark some Windows editors put at a file's start
/// (Unicode §23.8): skipped, it is not part of the first line.
const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// A line, its 1-based number, and whether it ended in `\n`.
pub type EndedLine<'a> = (&'a [u8], usize, bool);

impl LineReader<File> {
    /// Opens `path`; a missing file is an error naming it.
    pub fn open(path: &Path) -> Result<Self, Error> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        Ok(Self::new(file, path))
    }
}

impl<R: Read> LineReader<R> {
    /// Wraps any reader; `path` is used in messages only.
    pub fn new(inner: R, path: &Path) -> Self {
        LineReader {
            inner,
            path: path.to_path_buf(),
            buf: vec![0; BLOCK],
            start: 0,
            end: 0,
            eof: false,
            line_no: 0,
            terminated: true,
        }
    }

    /// The file name used in messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The next line without its terminator (`\n` or `\r\n`) and its
    /// 1-based number, or `None` at the end of the file.
    pub fn next_line(&mut self) -> Result<Option<(&[u8], usize)>, Error> {
        Ok(self
            .advance()?
            .map(|(a, b)| (&self.buf[a..b], self.line_no)))
    }

    /// As [`Self::next_line`], with whether the line ended in `\n` (false
    /// only for a last line cut short).
    pub fn next_line_ended(&mut self) -> Result<Option<EndedLine<'_>>, Error> {
        Ok(self
            .advance()?
            .map(|(a, b)| (&self.buf[a..b], self.line_no, self.terminated)))
    }

    /// Moves to the next line; its byte range in `buf`.
    fn advance(&mut self) -> Result<Option<(usize, usize)>, Error> {
        loop {
            if let Some(pos) = memchr_newline(&self.buf[self.start..self.end]) {
                let line_start = self.start;
                let mut line_end = self.start + pos;
                self.start = line_end + 1;
                if line_end > line_start && self.buf[line_end - 1] == b'\r' {
                    line_end -= 1;
                }
                self.line_no += 1;
                self.terminated = true;
                return Ok(Some((self.skip_bom(line_start, line_end), line_end)));
            }
            if self.eof {
                if self.start < self.end {
                    let line_start = self.start;
                    let mut line_end = self.end;
                    self.start = self.end;
                    if self.buf[line_end - 1] == b'\r' {
                        line_end -= 1;
                    }
                    self.line_no += 1;
                    self.terminated = false;
                    return Ok(Some((self.skip_bom(line_start, line_end), line_end)));
                }
                return Ok(None);
            }
            // Move the partial line to the front, grow if one line fills the block.
            if self.start > 0 {
                self.buf.copy_within(self.start..self.end, 0);
                self.end -= self.start;
                self.start = 0;
            }
            if self.end == self.buf.len() {
                return Err(Error::parse(
                    &self.path,
                    self.line_no + 1,
                    format!(
                        "line longer than {} MiB without a line break: not a text log \
                         (expected one record per line)",
                        MAX_LINE_BYTES >> 20
                    ),
                ));
            }
            let n = loop {
                match self.inner.read(&mut self.buf[self.end..]) {
                    Ok(n) => break n,
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(Error::io(&self.path, e)),
                }
            };
            if n == 0 {
                self.eof = true;
            }
            self.end += n;
        }
    }
}

/// Largest configuration file read whole (YAML, TOML: KF-GINS
/// configurations, sensor sheets, scenarios, filter files): 16 MiB, a
/// thousand times a real one; `/dev/zero` given as a configuration fails
/// at once instead of filling memory.
pub const MAX_CONFIG_BYTES: u64 = 16 << 20;

/// A whole text file (a configuration) of at most [`MAX_CONFIG_BYTES`],
/// its UTF-8 byte-order mark removed; the error names the file and what
/// is wrong (too large, not UTF-8 at byte N).
pub fn read_config_text(path: &Path) -> Result<String, Error> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut bytes = Vec::new();
    file.take(MAX_CONFIG_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > MAX_CONFIG_BYTES {
        return Err(Error::config(
            path,
            format!(
                "larger than {} MiB: not a configuration file",
                MAX_CONFIG_BYTES >> 20
            ),
        ));
    }
    let body = bytes.strip_prefix(UTF8_BOM).unwrap_or(&bytes);
    match std::str::from_utf8(body) {
        Ok(s) => Ok(s.to_string()),
        Err(e) => Err(Error::config(
            path,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.valid_up_to() + (bytes.len() - body.len())
            ),
        )),
    }
}

impl<R> LineReader<R> {
    /// The first line's start past a UTF-8 byte-order mark.
    fn skip_bom(&self, start: usize, end: usize) -> usize {
        if self.line_no == 1 && self.buf[start..end].starts_with(UTF8_BOM) {
            start + UTF8_BOM.len()
        } else {
            start
        }
    }
}

#[inline]
fn memchr_newline(hay: &[u8]) -> Option<usize> {
    memchr::memchr(b'\n', hay)
}

/// True for a line that carries no record: blank, or a `#` comment.
#[inline]
pub fn is_blank_or_comment(line: &[u8]) -> bool {
    match line.iter().find(|b| !b.is_ascii_whitespace()) {
        None => true,
        Some(&b) => b == b'#',
    }
}

/// Splits a record into fields separated by any mix of spaces, tabs and
/// commas (FORMATS.md "Conventions everywhere"). Returns the number of
/// fields found; at most `out.len()` are stored, the rest only counted.
#[inline]
pub fn split_fields<'a>(line: &'a [u8], out: &mut [&'a [u8]]) -> usize {
    let mut count = 0;
    for_each_field(line, |s, e| {
        if count < out.len() {
            out[count] = &line[s..e];
        }
        count += 1;
    });
    count
}

/// Calls `f(start, end)` for each field of `line` (byte ranges), fields
/// split at any mix of spaces, tabs, commas and carriage returns.
#[inline]
pub(crate) fn for_each_field(line: &[u8], mut f: impl FnMut(usize, usize)) {
    let mut i = 0;
    let n = line.len();
    while i < n {
        while i < n && is_sep(line[i]) {
            i += 1;
        }
        if i >= n {
            break;
        }
        let s = i;
        while i < n && !is_sep(line[i]) {
            i += 1;
        }
        f(s, i);
    }
}

#[inline]
fn is_sep(b: u8) -> bool {
    b == b' ' || b == b'\t' || b == b',' || b == b'\r'
}

/// The time-order rule every record reader applies: a record must come
/// strictly after the one kept before it. Returns why `time` breaks it
/// (a repeat, or how far it goes back), for the caller's diagnostic.
pub fn time_order_problem(last: Option<GpsTime>, time: GpsTime) -> Option<String> {
    let last = last?;
    if time == last {
        Some(format!("duplicate epoch {time}"))
    } else if time < last {
        Some(format!(
            "time goes backwards ({} s after {last})",
            time.seconds_since(last)
        ))
    } else {
        None
    }
}

/// Parses a field as a finite `f64`; NaN, infinities and junk are errors
/// with a short description.
#[inline]
pub fn parse_f64(field: &[u8]) -> Result<f64, String> {
    let s = std::str::from_utf8(field).map_err(|_| "not text".to_string())?;
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("'{s}' is not a finite number")),
        Err(_) => Err(format!("'{s}' is not a number")),
    }
}

/// Largest time field accepted (s): GPS seconds since 1980 until 2106;
/// beyond it (a corrupt 1e308) a time is one bad field, and a week plus it
/// stays far inside `i64` nanoseconds.
pub const MAX_TIME_S: f64 = 4e9;

/// Parses decimal seconds (e.g. `100000.005000000`) into integer
/// nanoseconds exactly, rounding digits beyond the ninth decimal. Accepts an
/// exponent form through `f64` as a fallback.
pub fn parse_seconds_ns(field: &[u8]) -> Result<i64, String> {
    let (neg, digits) = match field.first() {
        Some(b'-') => (true, &field[1..]),
        Some(b'+') => (false, &field[1..]),
        _ => (false, field),
    };
    let mut int_part: i64 = 0;
    let mut frac: i64 = 0;
    let mut frac_digits = 0u32;
    let mut seen_dot = false;
    let mut round_up = false;
    let mut any_digit = false;
    for (k, &b) in digits.iter().enumerate() {
        match b {
            b'0'..=b'9' => {
                any_digit = true;
                let d = (b - b'0') as i64;
                if !seen_dot {
                    int_part = int_part
                        .checked_mul(10)
                        .and_then(|v| v.checked_add(d))
                        .ok_or_else(|| "time value too large".to_string())?;
                } else if frac_digits < 9 {
                    frac = frac * 10 + d;
                    frac_digits += 1;
                } else if frac_digits == 9 {
                    round_up = d >= 5;
                    frac_digits += 1;
                }
            }
            b'.' if !seen_dot => seen_dot = true,
            b'e' | b'E' => {
                let _ = k;
                let v = parse_f64(field)?;
                if v.abs() > MAX_TIME_S {
                    return Err(format!("time {v:e} s is beyond {MAX_TIME_S:e} s"));
                }
                return Ok(crate::time::seconds_to_ns(v));
            }
            _ => {
                return Err(format!(
                    "'{}' is not a time in seconds",
                    String::from_utf8_lossy(field)
                ));
            }
        }
    }
    if !any_digit {
        return Err(format!(
            "'{}' is not a time in seconds",
            String::from_utf8_lossy(field)
        ));
    }
    while frac_digits < 9 {
        frac *= 10;
        frac_digits += 1;
    }
    if int_part as f64 > MAX_TIME_S {
        return Err(format!("time {int_part} s is beyond {MAX_TIME_S:e} s"));
    }
    let mut ns = int_part
        .checked_mul(crate::time::NS_PER_S)
        .ok_or_else(|| "time value too large".to_string())?
        + frac;
    if round_up {
        ns += 1;
    }
    Ok(if neg { -ns } else { ns })
}

pub use crate::numfmt::{push_f64, push_u64};
pub(crate) use crate::numfmt::{push_fixed, push_u64_padded};

/// A number for a header or configuration line: integers without a
/// decimal point, other values in their shortest round-trip form.
pub fn plain_number(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{}", x as i64)
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_order_rule() {
        let t = GpsTime::from_week_ns(2300, 5_000_000_000);
        assert_eq!(time_order_problem(None, t), None);
        assert_eq!(time_order_problem(Some(t), t.add_seconds(0.1)), None);
        let dup = time_order_problem(Some(t), t).unwrap();
        assert!(dup.starts_with("duplicate epoch 2300 5."), "{dup}");
        let back = time_order_problem(Some(t), t.add_seconds(-0.5)).unwrap();
        assert!(
            back.contains("goes backwards (-0.5 s after 2300 5."),
            "{back}"
        );
    }

    #[test]
    fn seconds_parse_exactly() {
        assert_eq!(
            parse_seconds_ns(b"100000.005000000").unwrap(),
            100_000_005_000_000
        );
        assert_eq!(
            parse_seconds_ns(b"100000.005").unwrap(),
            100_000_005_000_000
        );
        assert_eq!(parse_seconds_ns(b"1.0000000005").unwrap(), 1_000_000_001);
        assert_eq!(parse_seconds_ns(b"-1.5").unwrap(), -1_500_000_000);
        assert_eq!(parse_seconds_ns(b"12").unwrap(), 12_000_000_000);
        assert_eq!(parse_seconds_ns(b"1.5e3").unwrap(), 1_500_000_000_000);
        assert!(parse_seconds_ns(b"12a").is_err());
        assert!(parse_seconds_ns(b"1e308").is_err());
        assert!(parse_seconds_ns(b"99999999999").is_err());
        assert!(parse_seconds_ns(b".").is_err());
        assert!(parse_seconds_ns(b"").is_err());
        assert!(parse_seconds_ns(b"99999999999999999999").is_err());
    }

    #[test]
    fn fields_split_on_any_separator() {
        let mut f: [&[u8]; 8] = [b""; 8];
        let n = split_fields(b"  1.0,\t2 ,3  4\r", &mut f);
        assert_eq!(n, 4);
        assert_eq!(f[0], b"1.0");
        assert_eq!(f[3], b"4");
        assert_eq!(split_fields(b"", &mut f), 0);
        assert_eq!(split_fields(b"a b c d e f g h i j", &mut f), 10);
    }

    #[test]
    fn floats_reject_nan_and_junk() {
        assert_eq!(parse_f64(b"-1.5e-3").unwrap(), -1.5e-3);
        assert!(parse_f64(b"nan").is_err());
        assert!(parse_f64(b"inf").is_err());
        assert!(parse_f64(b"1.2.3").is_err());
    }

    #[test]
    fn fixed_formatting_matches_std() {
        for &(v, d) in &[
            (30.444787370100, 12usize),
            (-0.000000001, 9),
            (114.471863204700, 12),
            (-1.5, 3),
            (0.0, 6),
            (123456.0, 0),
            (9.99999999999, 6),
            (1e30, 3),
        ] {
            let mut out = Vec::new();
            push_fixed(&mut out, v, d);
            let want = format!("{v:.d$}");
            let got = String::from_utf8(out).unwrap();
            // std may print "-0.000000000" for tiny negatives; we print "0.000000000"
            assert_eq!(
                got.trim_start_matches('-'),
                want.trim_start_matches('-'),
                "{v}"
            );
        }
    }

    #[test]
    fn line_reader_counts_lines_and_strips_cr() {
        let data = b"a\r\nbb\n\nccc";
        let mut r = LineReader::new(&data[..], Path::new("mem"));
        let mut lines = Vec::new();
        while let Some((l, n)) = r.next_line().unwrap() {
            lines.push((n, l.to_vec()));
        }
        assert_eq!(
            lines,
            vec![
                (1, b"a".to_vec()),
                (2, b"bb".to_vec()),
                (3, b"".to_vec()),
                (4, b"ccc".to_vec())
            ]
        );
    }

    #[test]
    fn line_reader_takes_a_line_up_to_its_cap_and_refuses_a_longer_one() {
        let mut data = b"first\n".to_vec();
        data.extend(vec![b'x'; MAX_LINE_BYTES - 1]);
        data.push(b'\n');
        data.extend_from_slice(b"end");
        let mut r = LineReader::new(&data[..], Path::new("mem"));
        assert_eq!(r.next_line().unwrap().unwrap().0, b"first");
        assert_eq!(r.next_line().unwrap().unwrap().0.len(), MAX_LINE_BYTES - 1);
        assert_eq!(r.next_line().unwrap().unwrap().0, b"end");
        assert!(r.next_line().unwrap().is_none());
        // /dev/zero as a log: one endless line, refused at the cap.
        let mut r = LineReader::new(std::io::repeat(0), Path::new("/dev/zero"));
        let e = r.next_line().unwrap_err().to_string();
        assert!(e.starts_with("/dev/zero:1: line longer than 1 MiB"), "{e}");
    }

    #[test]
    fn line_reader_skips_a_utf8_bom_on_the_first_line_only() {
        let data = b"\xEF\xBB\xBF# rig-log v1\n\xEF\xBB\xBFx";
        let mut r = LineReader::new(&data[..], Path::new("mem"));
        assert_eq!(r.next_line().unwrap().unwrap().0, b"# rig-log v1");
        assert_eq!(r.next_line().unwrap().unwrap().0, b"\xEF\xBB\xBFx");
        let mut r = LineReader::new(&b"\xEF\xBB\xBF"[..], Path::new("mem"));
        assert_eq!(r.next_line().unwrap().unwrap().0, b"");
    }
}
