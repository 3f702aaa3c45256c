//! The speed file (`sow speed_mps`, docs/FORMATS.md): an odometer or CAN
//! speed read as a stream and interpolated at the IMU epochs.
#![warn(missing_docs)]

use std::path::{Path, PathBuf};

use crate::error::{Diagnostics, Error};
use crate::io::text::{LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, split_fields};
use crate::time::{GpsTime, WeekTracker};

/// Streams a speed file (`sow speed_mps`) and interpolates it at
/// increasing times. Bad lines (too few fields, not numbers, times not
/// increasing) are reported and skipped; a file without any speed is an
/// error.
pub struct SpeedStream {
    lines: LineReader<std::fs::File>,
    path: PathBuf,
    weeks: WeekTracker,
    prev: Option<(GpsTime, f64)>,
    next: Option<(GpsTime, f64)>,
    count: usize,
    done: bool,
    max_gap_ns: i64,
}

impl SpeedStream {
    /// Opens `path`; times are placed in GPS week `week`.
    pub fn open(path: &Path, week: i64, max_gap_s: f64) -> Result<Self, Error> {
        Ok(SpeedStream {
            lines: LineReader::open(path)?,
            path: path.to_path_buf(),
            weeks: WeekTracker::new(week),
            prev: None,
            next: None,
            count: 0,
            done: false,
            max_gap_ns: crate::time::seconds_to_ns(max_gap_s),
        })
    }

    fn read(&mut self, diag: &mut Diagnostics) -> Result<Option<(GpsTime, f64)>, Error> {
        if self.done {
            return Ok(None);
        }
        loop {
            let Some((line, no)) = self.lines.next_line()? else {
                self.done = true;
                if self.count == 0 {
                    return Err(Error::NoData {
                        path: self.path.clone(),
                        msg: "no speed records (expected lines of `sow speed_mps`)".into(),
                    });
                }
                return Ok(None);
            };
            if is_blank_or_comment(line) {
                continue;
            }
            let mut f: [&[u8]; 2] = [b""; 2];
            let n = split_fields(line, &mut f);
            if n < 2 {
                diag.push(
                    &self.path,
                    no,
                    format!("expected 2 fields (sow, speed_mps), found {n}; line skipped"),
                );
                continue;
            }
            let ns = match parse_seconds_ns(f[0]) {
                Ok(v) => v,
                Err(e) => {
                    diag.push(&self.path, no, format!("field 1 (sow): {e}; line skipped"));
                    continue;
                }
            };
            let v = match parse_f64(f[1]) {
                Ok(v) => v,
                Err(e) => {
                    diag.push(
                        &self.path,
                        no,
                        format!("field 2 (speed_mps): {e}; line skipped"),
                    );
                    continue;
                }
            };
            if let Some(why) = super::plausible::velocity_problem(&[v, 0.0, 0.0]) {
                diag.push(&self.path, no, format!("{why}; line skipped"));
                continue;
            }
            let t = self.weeks.peek(ns);
            let last = self.next.or(self.prev).map(|x| x.0);
            if last.is_some_and(|l| t <= l) {
                diag.push(
                    &self.path,
                    no,
                    format!("time {t} does not increase; line skipped"),
                );
                continue;
            }
            let t = self.weeks.resolve(ns);
            self.count += 1;
            return Ok(Some((t, v)));
        }
    }

    /// The speed at `t` (m/s) by linear interpolation, or `None` outside
    /// the file or in a gap longer than the limit. Calls must have
    /// non-decreasing `t`.
    pub fn at(&mut self, t: GpsTime, diag: &mut Diagnostics) -> Result<Option<f64>, Error> {
        if self.next.is_none() && self.prev.is_none() {
            self.next = self.read(diag)?;
        }
        while let Some(n) = self.next {
            if n.0 >= t {
                break;
            }
            self.prev = Some(n);
            self.next = self.read(diag)?;
        }
        match (self.prev, self.next) {
            (_, Some(n)) if n.0 == t => Ok(Some(n.1)),
            (Some(p), Some(n)) if n.0 - p.0 <= self.max_gap_ns => {
                let f = (t - p.0) as f64 / (n.0 - p.0) as f64;
                Ok(Some(p.1 + f * (n.1 - p.1)))
            }
            _ => Ok(None),
        }
    }
}
