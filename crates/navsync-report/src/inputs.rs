//! Reading what a report shows: the solution scored against the truth by
//! [`navsync::eval`] (the code of `navsync eval`), KF-GINS auxiliary
//! outputs, GNSS fixes and the synchronization report.
//!
//! The navigation and truth files are read as `navsync eval` reads them
//! (bad lines skipped and reported). The auxiliary tables (`std.txt`,
//! `imu_err.txt`, `time_offset.txt`) are machine-written with a fixed
//! number of columns, so any other line is an error naming file and line:
//! it catches one file given for another.

use std::path::{Path, PathBuf};

use navsync::earth::{Geodetic, ned_offset};
use navsync::eval::{self, EvalReport};
use navsync::io::kfgins::{GnssLayout, GnssReader, NavReader};
use navsync::io::text::{LineReader, is_blank_or_comment, parse_f64, split_fields};
use navsync::time::OutageWindow;
use navsync::timing::SyncReport;
use navsync::{Diagnostics, Error};

/// The files (and facts) a report is made from.
#[derive(Clone, Debug, Default)]
pub struct ReportInputs {
    pub title: String,
    /// Reference trajectory (11-column nav format); without it the report
    /// judges the run from the filter's own statistics.
    pub truth: Option<PathBuf>,
    /// The solution (11-column nav format).
    pub nav: PathBuf,
    pub sync_report: Option<PathBuf>,
    /// `summary.json` of `navsync fuse`.
    pub summary: Option<PathBuf>,
    /// `std.txt` (KF-GINS layout).
    pub std: Option<PathBuf>,
    /// `imu_err.txt` and the simulator's `imu_err_truth.txt` (KF-GINS layout).
    pub imu_err: Option<PathBuf>,
    pub imu_err_truth: Option<PathBuf>,
    /// GNSS fixes (7 or 13 columns).
    pub gnss: Option<PathBuf>,
    /// `time_offset.txt` of `navsync fuse --estimate-time-offset`.
    pub time_offset: Option<PathBuf>,
    /// `gnss_residuals.txt` of `navsync fuse` (robust weighting).
    pub gnss_residuals: Option<PathBuf>,
    /// The true time offset (s), when known.
    pub time_offset_truth_s: Option<f64>,
    /// GNSS outage windows (sow, length s); empty: the summary's, if any.
    pub outages: Vec<OutageWindow>,
    /// With a smoothed solution (`fuse --smooth`): the forward filter's
    /// solution and `std.txt`, shown beside it.
    pub forward_nav: Option<PathBuf>,
    pub forward_std: Option<PathBuf>,
    /// `probe.json` of `navsync process` (the consistency probe).
    pub probe: Option<PathBuf>,
}

impl ReportInputs {
    /// Fills the optional files `navsync fuse` writes beside `nav` when they
    /// exist and were not given.
    pub fn with_siblings_of_nav(mut self) -> Self {
        let dir = self.nav.parent().map(Path::to_path_buf).unwrap_or_default();
        let fill = |slot: &mut Option<PathBuf>, name: &str| {
            let p = dir.join(name);
            if slot.is_none() && p.is_file() {
                *slot = Some(p);
            }
        };
        fill(&mut self.std, "std.txt");
        fill(&mut self.imu_err, "imu_err.txt");
        fill(&mut self.time_offset, "time_offset.txt");
        fill(&mut self.summary, "summary.json");
        fill(&mut self.gnss_residuals, "gnss_residuals.txt");
        fill(&mut self.probe, "probe.json");
        fill(&mut self.forward_nav, "forward/navresult.nav");
        if self.forward_nav.is_some() {
            fill(&mut self.forward_std, "forward/std.txt");
        }
        self
    }
}

/// One GNSS position observation as the fusion weighed it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct FixWeight {
    pub sow: f64,
    /// Innovation N, E, D (m) and stated σ (m).
    pub innovation: [f64; 3],
    pub sd: [f64; 3],
    pub nis: f64,
    pub weight: [f64; 3],
    /// used, down-weighted, rejected or drift-accepted.
    pub status: String,
    /// The integrity monitor's reason (`jump`, `run`, `stale`,
    /// `persisted`, `outlier`; `-` or absent in older files).
    pub reason: String,
}

/// Reads the position lines of `gnss_residuals.txt`
/// (`sow kind innov_n innov_e innov_d sd_n sd_e sd_d nis w_n w_e w_d
/// status [reason hpl_m]`: files before the integrity monitor have 13
/// columns); any other line is an error naming file and line.
pub(crate) fn read_fix_weights(path: &Path) -> Result<Vec<FixWeight>, Error> {
    let mut lines = LineReader::open(path)?;
    let mut out = Vec::new();
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 16] = [b""; 16];
        let n = split_fields(line, &mut f);
        if n != 13 && n != 15 {
            return Err(Error::parse(
                path,
                no,
                format!(
                    "expected 15 columns (sow kind innov×3 sd×3 nis w×3 status reason hpl_m), or 13 without the last two, found {n}"
                ),
            ));
        }
        if f[1] != b"position" {
            continue;
        }
        let num = |k: usize| {
            parse_f64(f[k]).map_err(|e| Error::parse(path, no, format!("column {}: {e}", k + 1)))
        };
        out.push(FixWeight {
            sow: num(0)?,
            innovation: [num(2)?, num(3)?, num(4)?],
            sd: [num(5)?, num(6)?, num(7)?],
            nis: num(8)?,
            weight: [num(9)?, num(10)?, num(11)?],
            status: String::from_utf8_lossy(f[12]).into_owned(),
            reason: if n == 15 {
                String::from_utf8_lossy(f[13]).into_owned()
            } else {
                "-".into()
            },
        });
    }
    Ok(out)
}

/// Seconds from `t0_sow` to `sow`, across one week rollover.
pub(crate) fn rel_s(sow: f64, t0_sow: f64) -> f64 {
    let d = sow - t0_sow;
    if d < -302_400.0 {
        d + 604_800.0
    } else if d > 302_400.0 {
        d - 604_800.0
    } else {
        d
    }
}

/// The last std.txt row (sow, σ_n, σ_e, …) before `sow` (1 µs tolerance,
/// so a row at the fix's own epoch, which already has its update, is not
/// taken): the filter's prediction for a fix at `sow`.
pub(crate) fn std_row_before(std: &[Vec<f64>], sow: f64) -> Option<&[f64]> {
    let j = std.partition_point(|r| r[0] < sow - 1e-6).checked_sub(1)?;
    std.get(j).map(Vec::as_slice)
}

/// Every compared epoch of the solution (times relative to its first
/// epoch; horizontal positions relative to the first truth state, m).
#[derive(Clone, Debug, Default)]
pub(crate) struct Epochs {
    pub t0_sow: f64,
    pub week: i64,
    pub t: Vec<f64>,
    pub truth_ne: Vec<(f64, f64)>,
    pub sol_ne: Vec<(f64, f64)>,
    pub pos_err: Vec<[f64; 3]>,
    pub vel_err: Vec<[f64; 3]>,
    pub att_err: Vec<[f64; 3]>,
    pub origin: Option<Geodetic>,
}

/// The scores and the epochs, from one pass of [`eval::eval_files_with`].
pub(crate) fn score(
    truth: &Path,
    nav: &Path,
    outages: &[OutageWindow],
    diag: &mut Diagnostics,
) -> Result<(EvalReport, Epochs), Error> {
    let mut ep = Epochs::default();
    let report = eval::eval_files_with(truth, nav, outages, diag, &mut |rec, ts, e| {
        let origin = *ep.origin.get_or_insert(ts.pos);
        if ep.t.is_empty() {
            ep.t0_sow = rec.time.sow();
            ep.week = rec.week;
        }
        let sol = Geodetic::from_deg(rec.lat_deg, rec.lon_deg, rec.h_m);
        let dt = ned_offset(&origin, &ts.pos);
        let ds = ned_offset(&origin, &sol);
        ep.t.push(rel_s(rec.time.sow(), ep.t0_sow));
        ep.truth_ne.push((dt.x, dt.y));
        ep.sol_ne.push((ds.x, ds.y));
        ep.pos_err.push(e.pos_ned_m.into());
        ep.vel_err.push(e.vel_ned_mps.into());
        ep.att_err.push(e.att_deg.into());
    })?;
    Ok((report, ep))
}

/// The solution's epochs without a reference (positions relative to its
/// first epoch; no errors). Bad lines are skipped and reported, as
/// `navsync eval` does.
pub(crate) fn read_solution(nav: &Path, diag: &mut Diagnostics) -> Result<Epochs, Error> {
    let mut r = NavReader::open(nav)?;
    let mut ep = Epochs::default();
    while let Some(rec) = r.next_record(diag)? {
        let pos = Geodetic::from_deg(rec.lat_deg, rec.lon_deg, rec.h_m);
        let origin = *ep.origin.get_or_insert(pos);
        if ep.t.is_empty() {
            ep.t0_sow = rec.time.sow();
            ep.week = rec.week;
        }
        let d = ned_offset(&origin, &pos);
        ep.t.push(rel_s(rec.time.sow(), ep.t0_sow));
        ep.sol_ne.push((d.x, d.y));
    }
    Ok(ep)
}

/// Why the solution `nav` (read into `ep`) is incomplete, if it is: its
/// last line has no line end (cut by a crash or a full disk; the reader
/// skipped it as a bad line), or it ends more than 1 s before the last
/// solution summary.json's `end_sow` records (FORMATS.md: navresult.nav
/// has a line per solution).
pub(crate) fn incomplete_solution(
    nav: &Path,
    ep: &Epochs,
    summary: Option<&serde_json::Value>,
) -> Option<String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(nav).ok()?;
    let len = f.metadata().ok()?.len();
    let mut last = [0u8; 1];
    if len > 0
        && f.seek(SeekFrom::Start(len - 1)).is_ok()
        && f.read_exact(&mut last).is_ok()
        && last[0] != b'\n'
    {
        return Some(format!(
            "{}: the last line is cut (no line end at byte {len}): the file is incomplete",
            nav.display()
        ));
    }
    let end_sow = summary?.get("end_sow")?.as_f64()?;
    let end_rel = rel_s(end_sow, ep.t0_sow);
    let nav_end = ep.t.last().copied().unwrap_or(f64::NEG_INFINITY);
    (nav_end < end_rel - 1.0).then(|| {
        format!(
            "{} ends at {:.3} s of week, {:.1} s before the last solution summary.json records ({end_sow:.3}): the file is incomplete",
            nav.display(),
            ep.t0_sow + nav_end.max(0.0),
            end_rel - nav_end
        )
    })
}

/// Reads a whitespace/comma table whose every record has exactly
/// `columns` numbers; `layout` names the expected columns in messages.
pub(crate) fn read_table(
    path: &Path,
    columns: usize,
    layout: &str,
) -> Result<Vec<Vec<f64>>, Error> {
    let mut lines = LineReader::open(path)?;
    let mut rows = Vec::new();
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut fields: [&[u8]; 32] = [b""; 32];
        let n = split_fields(line, &mut fields);
        if n != columns {
            return Err(Error::parse(
                path,
                no,
                format!("expected {columns} columns ({layout}), found {n}"),
            ));
        }
        let mut row = Vec::with_capacity(columns);
        for (k, f) in fields[..n.min(32)].iter().enumerate() {
            let v = parse_f64(f)
                .map_err(|e| Error::parse(path, no, format!("column {}: {e}", k + 1)))?;
            row.push(v);
        }
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: format!("no records (expected lines of {layout})"),
        });
    }
    Ok(rows)
}

/// KF-GINS `std.txt`: sow and 21 standard deviations.
pub(crate) const STD_LAYOUT: &str = "KF-GINS std.txt: sow, position n e d (m), velocity (m/s), attitude (deg), gyro bias (deg/h), accel bias (mGal), gyro scale (ppm), accel scale (ppm)";
/// KF-GINS `imu_err.txt`: sow and 12 IMU errors.
pub(crate) const IMU_ERR_LAYOUT: &str = "KF-GINS imu_err.txt: sow, gyro bias x y z (deg/h), accel bias (mGal), gyro scale (ppm), accel scale (ppm)";
/// `time_offset.txt`.
pub(crate) const TIME_OFFSET_LAYOUT: &str = "navsync time_offset.txt: sow offset_s sd_s observable";

/// The synchronization report (`sync_report.json`).
pub(crate) fn read_sync_report(path: &Path) -> Result<SyncReport, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| {
        Error::parse(
            path,
            e.line(),
            format!("not a navsync sync_report.json: {e}"),
        )
    })
}

/// A `summary.json` of `navsync fuse` (read loosely: only a few fields
/// are shown).
pub(crate) fn read_summary(path: &Path) -> Result<serde_json::Value, Error> {
    read_json_object(path, "navsync fuse's summary.json")
}

/// A JSON object file of navsync (`what` names it in errors).
pub(crate) fn read_json_object(path: &Path, what: &str) -> Result<serde_json::Value, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| Error::parse(path, e.line(), format!("not JSON: {e}")))?;
    if !v.is_object() {
        return Err(Error::parse(
            path,
            1,
            format!("expected a JSON object ({what})"),
        ));
    }
    Ok(v)
}

/// GNSS fix positions (sow, north, east relative to `origin`, m).
pub(crate) fn read_gnss(
    path: &Path,
    origin: &Geodetic,
    diag: &mut Diagnostics,
) -> Result<Vec<(f64, f64, f64)>, Error> {
    let mut r = GnssReader::open(path, 0, GnssLayout::Cpp)?;
    let mut out = Vec::new();
    while let Some(f) = r.next_fix(diag)? {
        let d = ned_offset(origin, &f.pos);
        out.push((f.time.sow(), d.x, d.y));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str, text: &str) -> navsync::testfiles::TestDir {
        navsync::testfiles::temp_file("report", name, text)
    }

    #[test]
    fn tables_name_file_and_line() {
        let p = temp("t1.txt", "# c\n1 2 3\n\n4 5\n");
        let e = read_table(&p, 3, "a b c").unwrap_err().to_string();
        assert!(
            e.contains("t1.txt:4") && e.contains("expected 3 columns (a b c), found 2"),
            "{e}"
        );
        let p = temp("t2.txt", "1 2 x\n");
        let e = read_table(&p, 3, "a b c").unwrap_err().to_string();
        assert!(e.contains("t2.txt:1") && e.contains("column 3"), "{e}");
        let p = temp("t3.txt", "1 2 3 4\n");
        let e = read_table(&p, 3, "a b c").unwrap_err().to_string();
        assert!(e.contains("found 4"), "{e}");
        let p = temp("t4.txt", "# nothing\n");
        assert!(read_table(&p, 3, "a b c").is_err());
        let p = temp("t5.txt", "1,2 3\n4\t5 6\n");
        assert_eq!(read_table(&p, 3, "a b c").unwrap()[1], vec![4.0, 5.0, 6.0]);
        let e = read_sync_report(&temp("s.json", "{\"mode\": \"hw\"}"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.json:1") && e.contains("missing field"), "{e}");
    }

    #[test]
    fn relative_seconds_cross_the_week() {
        assert_eq!(rel_s(100.0, 604_790.0), 110.0);
        assert_eq!(rel_s(100_010.5, 100_000.0), 10.5);
    }
}
