//! The heading file (`sow heading_deg sd_deg [source]`, docs/FORMATS.md):
//! headings measured by the GNSS receiver, beside the KF-GINS GNSS file.
//!
//! - `baseline`: the azimuth of a dual-antenna baseline (u-blox moving-base
//!   NAV-RELPOSNED relPosHeading, from the primary antenna to the second),
//!   clockwise from north; turned into the body heading with the
//!   baseline's mounting yaw.
//! - `vehicle`: a vehicle heading the receiver itself estimated (u-blox
//!   NAV-PVT headVeh with headVehValid, on dead-reckoning receivers).
//!
//! Bad lines (too few fields, not numbers, a heading that is not finite, a
//! σ that is not finite, not positive or above [`MAX_HEADING_SD_DEG`], an
//! unknown source, times not increasing) are reported with their file and
//! line and skipped.

#![warn(missing_docs)]

use std::path::Path;

use crate::error::{Diagnostics, Error};
use crate::io::text::{LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, split_fields};
use crate::time::{GpsTime, WeekTracker};

/// A heading σ above this (deg) carries no usable information: such a line
/// is reported and skipped (receivers report 180° when they have none).
pub const MAX_HEADING_SD_DEG: f64 = 30.0;

/// What a heading measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum HeadingSource {
    /// The azimuth of a dual-antenna baseline.
    Baseline,
    /// The vehicle's heading as the receiver estimated it.
    Vehicle,
}

impl HeadingSource {
    /// The word of the heading file's last column (`baseline` or `vehicle`).
    pub fn word(self) -> &'static str {
        match self {
            HeadingSource::Baseline => "baseline",
            HeadingSource::Vehicle => "vehicle",
        }
    }

    /// The source a word names (`baseline` or `vehicle`).
    pub fn from_word(word: &[u8]) -> Option<Self> {
        match word {
            b"baseline" => Some(HeadingSource::Baseline),
            b"vehicle" => Some(HeadingSource::Vehicle),
            _ => None,
        }
    }

    /// An optional source field: absent means a baseline; an unknown word
    /// is returned (as text) for the caller's message.
    pub fn from_field(word: Option<&[u8]>) -> Result<Self, String> {
        match word {
            None => Ok(HeadingSource::Baseline),
            Some(w) => Self::from_word(w).ok_or_else(|| String::from_utf8_lossy(w).into_owned()),
        }
    }
}

/// Whether a heading σ (deg) carries information: within
/// (0, [`MAX_HEADING_SD_DEG`]] (so not NaN).
pub fn usable_sd(sd_deg: f64) -> bool {
    sd_deg > 0.0 && sd_deg <= MAX_HEADING_SD_DEG
}

/// Why a heading σ (deg) is unusable, if it is: not [`usable_sd`].
pub fn sd_problem(sd_deg: f64) -> Option<String> {
    (!usable_sd(sd_deg)).then(|| {
        format!("heading σ {sd_deg}° is outside (0, {MAX_HEADING_SD_DEG}]°: no usable heading")
    })
}

/// One heading measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingObs {
    /// GPS time of the measurement.
    pub time: GpsTime,
    /// Clockwise from north (rad).
    pub heading_rad: f64,
    /// σ (rad).
    pub sd_rad: f64,
    /// What the heading measures.
    pub source: HeadingSource,
}

/// Reads a whole heading file; times are placed in GPS week `week`. A file
/// without any usable heading gives an empty list and a diagnostic.
pub fn read_headings(
    path: &Path,
    week: i64,
    diag: &mut Diagnostics,
) -> Result<Vec<HeadingObs>, Error> {
    let mut lines = LineReader::open(path)?;
    let mut weeks = WeekTracker::new(week);
    let mut out: Vec<HeadingObs> = Vec::new();
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 4] = [b""; 4];
        let n = split_fields(line, &mut f);
        if n < 3 {
            diag.push(
                path,
                no,
                format!("expected 3 or 4 fields (sow, heading_deg, sd_deg[, source]), found {n}; line skipped"),
            );
            continue;
        }
        let ns = match parse_seconds_ns(f[0]) {
            Ok(v) => v,
            Err(e) => {
                diag.push(path, no, format!("field 1 (sow): {e}; line skipped"));
                continue;
            }
        };
        let mut vals = [0.0; 2];
        let mut bad = None;
        for (k, name) in [(1usize, "heading_deg"), (2, "sd_deg")] {
            match parse_f64(f[k]) {
                Ok(v) if v.is_finite() => vals[k - 1] = v,
                Ok(v) => bad = Some(format!("field {} ({name}) is {v}", k + 1)),
                Err(e) => bad = Some(format!("field {} ({name}): {e}", k + 1)),
            }
        }
        if let Some(b) = bad {
            diag.push(path, no, format!("{b}; line skipped"));
            continue;
        }
        let [heading_deg, sd_deg] = vals;
        if let Some(why) = sd_problem(sd_deg) {
            diag.push(path, no, format!("{why}; line skipped"));
            continue;
        }
        let source = match HeadingSource::from_field((n >= 4).then(|| f[3])) {
            Ok(s) => s,
            Err(w) => {
                diag.push(
                    path,
                    no,
                    format!(
                        "field 4 (source) is `{w}`, expected `baseline` or `vehicle`; line skipped"
                    ),
                );
                continue;
            }
        };
        let t = weeks.peek(ns);
        // A baseline and a vehicle heading may share an epoch.
        if let Some(last) = out.last()
            && (t < last.time || (t == last.time && last.source == source))
        {
            diag.push(
                path,
                no,
                format!("time {t} does not increase; line skipped"),
            );
            continue;
        }
        let t = weeks.resolve(ns);
        out.push(HeadingObs {
            time: t,
            heading_rad: heading_deg.to_radians(),
            sd_rad: sd_deg.to_radians(),
            source,
        });
    }
    if out.is_empty() {
        diag.push(
            path,
            0,
            "no usable heading (expected lines of `sow heading_deg sd_deg [baseline|vehicle]`)",
        );
    }
    Ok(out)
}

/// Writes headings in the heading-file format (`sow heading_deg sd_deg
/// source`).
pub fn write_headings(path: &Path, obs: &[HeadingObs]) -> Result<(), Error> {
    let mut s = String::from(HEADING_FILE_HEADER);
    for o in obs {
        s.push_str(&heading_line(o));
    }
    super::output::write_file(path, s)
}

/// The first line of a heading file navsync writes.
pub const HEADING_FILE_HEADER: &str =
    "# navsync heading file: sow heading_deg sd_deg source (baseline|vehicle)\n";

/// One line of a heading file: seconds of week to the millisecond,
/// heading and σ to 1e-5°, the source word.
pub fn heading_line(o: &HeadingObs) -> String {
    format!(
        "{:.3} {:.5} {:.5} {}\n",
        o.time.sow(),
        o.heading_rad.to_degrees().rem_euclid(360.0),
        o.sd_rad.to_degrees(),
        o.source.word()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_lines_are_reported_with_their_line_and_skipped() {
        let d = crate::testfiles::TestDir::new("heading");
        let p = d.join("heading.txt");
        std::fs::write(
            &p,
            "# sow heading sd\n\
             100.0 45.0 0.2\n\
             101.0 NaN 0.2\n\
             102.0 46.0 180\n\
             103.0 46.0 0\n\
             104.0 47.0 0.3 vehicle\n\
             105.0 47.0 0.3 compass\n\
             103.5 47.0 0.3\n\
             106.0 48\n\
             107.0 49.0 0.25 baseline\n",
        )
        .unwrap();
        let mut diag = Diagnostics::default();
        let h = read_headings(&p, 2300, &mut diag).unwrap();
        assert_eq!(h.len(), 3);
        assert_eq!(h[1].source, HeadingSource::Vehicle);
        assert!((h[2].heading_rad.to_degrees() - 49.0).abs() < 1e-12);
        let lines: Vec<usize> = diag.items.iter().map(|d| d.line).collect();
        assert_eq!(lines, [3, 4, 5, 7, 8, 9], "{diag:?}");
        assert!(diag.items[0].message.contains("heading_deg"));
        assert!(diag.items[1].message.contains("180"));
        // Written back, read again: the same.
        let q = d.join("again.txt");
        write_headings(&q, &h).unwrap();
        let mut diag2 = Diagnostics::default();
        let h2 = read_headings(&q, 2300, &mut diag2).unwrap();
        assert!(diag2.is_empty());
        assert_eq!(h2.len(), 3);
        for (a, b) in h.iter().zip(&h2) {
            assert_eq!((a.time, a.source), (b.time, b.source));
            assert!((a.heading_rad - b.heading_rad).abs() < 1e-6);
        }
    }
}
