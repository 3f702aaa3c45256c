//! RTKLIB solution files (`.pos`, RTKLIB manual appendix B "Output File
//! Formats": solution format) as GNSS input for `fuse`.
//!
//! Columns are found by the header line RTKLIB writes before the data:
//! `%  GPST  latitude(deg) longitude(deg) height(m) Q ns sdn(m) sde(m)
//! sdu(m) sdne(m) sdeu(m) sdun(m) age(s) ratio` (llh), or `x-ecef(m)
//! y-ecef(m) z-ecef(m) Q ns sdx(m) sdy(m) sdz(m) sdxy(m) sdyz(m) sdzx(m) …`
//! (xyz), optionally followed by velocities (`vn(m/s) ve(m/s) vu(m/s)
//! sdvn …` or `vx(m/s) vy(m/s) vz(m/s) sdvx …`). Time is GPST as `week tow`
//! or `yyyy/mm/dd hh:mm:ss.sss`. The off-diagonal σ are RTKLIB's signed
//! square roots (sdne = sign(c)·√|c|). Heights must be ellipsoidal (RTKLIB's
//! default `out-height=ellipsoidal`); UTC/JST time, degree-minute-second
//! latitudes and NMEA output are refused with a message, never guessed.
//!
//! Quality flag Q: 1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP; lines
//! with Q above `max_q` are skipped and counted (`q_skipped`).
#![warn(missing_docs)]

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};

use super::text::{
    LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, split_fields, time_order_problem,
};
use crate::earth::{Geodetic, c_ne, ecef_to_geodetic};
use crate::error::{Diagnostics, Error};
use crate::time::{GpsTime, NS_PER_S, NS_PER_WEEK, WeekTracker};
use crate::types::GnssFix;

/// Which GNSS file format `fuse` reads (an explicit choice or the `.pos`
/// extension, reported: never guessed from the numbers).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum GnssFormat {
    /// KF-GINS text (7 or 13 columns).
    #[default]
    Kfgins,
    /// RTKLIB `.pos` solution.
    Rtklib,
}

/// Highest RTKLIB quality flag (6 = PPP).
pub(crate) const RTKLIB_MAX_Q: u8 = 6;

#[derive(Copy, Clone, Debug, PartialEq, Eq)]
enum Frame {
    Llh,
    Xyz,
}

/// Column indexes in a data line (time takes fields 0 and 1).
#[derive(Clone, Debug)]
struct Columns {
    frame: Frame,
    pos: [usize; 3],
    q: usize,
    sd: [usize; 3],
    /// sdne sdeu sdun (llh) or sdxy sdyz sdzx (xyz).
    sd_cross: Option<[usize; 3]>,
    vel: Option<[usize; 3]>,
    vel_sd: Option<[usize; 3]>,
    min_fields: usize,
}

impl Columns {
    /// From the header's column names after `%` (the first is the time
    /// system, one name for two data fields).
    fn from_header(names: &[&str]) -> Result<Columns, String> {
        match names.first() {
            Some(&"GPST") => {}
            Some(t @ (&"UTC" | &"JST")) => {
                return Err(format!(
                    "time system {t}: only GPST is read (set RTKLIB's out-timesys=gpst)"
                ));
            }
            _ => return Err("header does not start with the time system `GPST`".into()),
        }
        let find = |n: &str| names.iter().position(|&x| x == n).map(|i| i + 1);
        let all = |ns: [&str; 3]| -> Option<[usize; 3]> {
            Some([find(ns[0])?, find(ns[1])?, find(ns[2])?])
        };
        let (frame, pos, sd, cross, vel, vel_sd) = if let Some(pos) =
            all(["latitude(deg)", "longitude(deg)", "height(m)"])
        {
            (
                Frame::Llh,
                pos,
                all(["sdn(m)", "sde(m)", "sdu(m)"]),
                all(["sdne(m)", "sdeu(m)", "sdun(m)"]),
                all(["vn(m/s)", "ve(m/s)", "vu(m/s)"]),
                all(["sdvn", "sdve", "sdvu"]),
            )
        } else if let Some(pos) = all(["x-ecef(m)", "y-ecef(m)", "z-ecef(m)"]) {
            (
                Frame::Xyz,
                pos,
                all(["sdx(m)", "sdy(m)", "sdz(m)"]),
                all(["sdxy(m)", "sdyz(m)", "sdzx(m)"]),
                all(["vx(m/s)", "vy(m/s)", "vz(m/s)"]),
                all(["sdvx", "sdvy", "sdvz"]),
            )
        } else if names.iter().any(|n| n.starts_with("latitude(d'")) {
            return Err(
                "latitudes in degrees-minutes-seconds: set RTKLIB's out-solformat=llh with degrees"
                    .into(),
            );
        } else {
            return Err("no latitude(deg)/longitude(deg)/height(m) or x-ecef(m)/y-ecef(m)/z-ecef(m) columns".into());
        };
        let q = find("Q").ok_or("no Q column")?;
        let sd = sd.ok_or("no position standard-deviation columns (sdn/sde/sdu or sdx/sdy/sdz)")?;
        let vel_sd = if vel.is_some() { vel_sd } else { None };
        let vel = if vel_sd.is_some() { vel } else { None };
        let min_fields = [Some(pos), Some(sd), cross, vel, vel_sd]
            .iter()
            .flatten()
            .flat_map(|c| c.iter())
            .chain([&q])
            .max()
            .copied()
            .unwrap_or(0)
            + 1;
        Ok(Columns {
            frame,
            pos,
            q,
            sd,
            sd_cross: cross,
            vel,
            vel_sd,
            min_fields,
        })
    }
}

/// Days since 1970-01-01 of a civil date (H. Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// 1980-01-06 in days since 1970-01-01.
const GPS_EPOCH_DAYS: i64 = 3657;

/// GPS ns since the GPS epoch of `yyyy/mm/dd` and `hh:mm:ss.sss` (GPST).
fn parse_date_time(date: &[u8], time: &[u8]) -> Result<i64, String> {
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    let ymd: Vec<&[u8]> = date.split(|&c| c == b'/').collect();
    let hms: Vec<&[u8]> = time.split(|&c| c == b':').collect();
    if ymd.len() != 3 || hms.len() != 3 {
        return Err(format!(
            "'{} {}' is not `yyyy/mm/dd hh:mm:ss.sss`",
            text(date),
            text(time)
        ));
    }
    let int = |b: &[u8], lo: i64, hi: i64| -> Result<i64, String> {
        std::str::from_utf8(b)
            .ok()
            .and_then(|s| s.parse::<i64>().ok())
            .filter(|v| (lo..=hi).contains(v))
            .ok_or_else(|| format!("'{}' is not a number in {lo}..{hi}", text(b)))
    };
    let (y, mo, d) = (
        int(ymd[0], 1980, 2200)?,
        int(ymd[1], 1, 12)?,
        int(ymd[2], 1, 31)?,
    );
    let (h, mi) = (int(hms[0], 0, 23)?, int(hms[1], 0, 59)?);
    let s_ns = parse_seconds_ns(hms[2])?;
    if !(0..61 * NS_PER_S).contains(&s_ns) {
        return Err(format!("seconds '{}' out of range", text(hms[2])));
    }
    let days = days_from_civil(y, mo, d) - GPS_EPOCH_DAYS;
    Ok((days * 86_400 + h * 3600 + mi * 60) * NS_PER_S + s_ns)
}

/// Reads an RTKLIB `.pos` file fix by fix.
pub struct PosReader<R = File> {
    lines: LineReader<R>,
    path: PathBuf,
    columns: Option<Columns>,
    weeks: WeekTracker,
    last: Option<GpsTime>,
    count: usize,
    /// Keep solutions with quality flag Q ≤ this (1 fix … 6 PPP).
    pub max_q: u8,
    /// Replace standard deviations below this (m, m/s) instead of skipping.
    pub(crate) sd_floor: Option<f64>,
    /// Solutions skipped by Q, indexed by Q (0 unused).
    pub(crate) q_skipped: [usize; 7],
}

impl PosReader<File> {
    /// Opens `path`. Times are placed in GPS week `week` by their time of
    /// week, like KF-GINS files (0 when the run has no week), so fixes meet
    /// IMU times on the same axis.
    pub fn open(path: &Path, week: i64) -> Result<Self, Error> {
        Ok(Self::from_reader(
            File::open(path).map_err(|e| Error::io(path, e))?,
            path,
            week,
        ))
    }
}

impl<R: Read> PosReader<R> {
    /// Reads from any reader (`path` names it in messages).
    pub fn from_reader(inner: R, path: &Path, week: i64) -> Self {
        PosReader {
            lines: LineReader::new(inner, path),
            path: path.to_path_buf(),
            columns: None,
            weeks: WeekTracker::new(week),
            last: None,
            count: 0,
            max_q: RTKLIB_MAX_Q,
            sd_floor: None,
            q_skipped: [0; 7],
        }
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The next kept fix; bad lines are reported into `diag` and skipped,
    /// lines above `max_q` counted. A file without a column header, or
    /// with one navsync cannot read, is an error naming the line.
    pub fn next_fix(&mut self, diag: &mut Diagnostics) -> Result<Option<GnssFix>, Error> {
        loop {
            let Some((line, line_no)) = self.lines.next_line()? else {
                if self.count == 0 {
                    let skipped: usize = self.q_skipped.iter().sum();
                    return Err(Error::NoData {
                        path: self.path.clone(),
                        msg: if skipped > 0 {
                            format!(
                                "no RTKLIB solution with Q ≤ {} ({skipped} above it)",
                                self.max_q
                            )
                        } else {
                            "no RTKLIB solutions (expected a `%  GPST  latitude(deg) …` header and data lines)".into()
                        },
                    });
                }
                return Ok(None);
            };
            if line.first() == Some(&b'%') {
                let text = String::from_utf8_lossy(&line[1..]);
                let names: Vec<&str> = text.split_ascii_whitespace().collect();
                // The column header is the `%` line naming the time system
                // (other `%` lines are program, input and option notes).
                if matches!(names.first(), Some(&("GPST" | "UTC" | "JST"))) {
                    self.columns = Some(
                        Columns::from_header(&names)
                            .map_err(|m| Error::parse(&self.path, line_no, m))?,
                    );
                }
                continue;
            }
            if is_blank_or_comment(line) {
                continue;
            }
            let Some(cols) = &self.columns else {
                return Err(Error::parse(
                    &self.path,
                    line_no,
                    "data before the RTKLIB column header (`%  GPST  latitude(deg) …` or `x-ecef(m)`): write the .pos with out-outhead=on",
                ));
            };
            let mut f: [&[u8]; 32] = [b""; 32];
            let nf = split_fields(line, &mut f);
            if nf < cols.min_fields {
                diag.push(
                    &self.path,
                    line_no,
                    format!(
                        "expected {} fields as the header says, found {nf}; line skipped",
                        cols.min_fields
                    ),
                );
                continue;
            }
            // Time: `week tow` or `yyyy/mm/dd hh:mm:ss.sss`.
            let gps_ns = if f[0].contains(&b'/') {
                parse_date_time(f[0], f[1])
            } else {
                match (parse_f64(f[0]), parse_seconds_ns(f[1])) {
                    (Ok(w), Ok(tow)) if w >= 0.0 && w.fract() == 0.0 && w < 1e5 => {
                        Ok(w as i64 * NS_PER_WEEK + tow)
                    }
                    _ => Err(format!(
                        "'{} {}' is not `week tow` or `yyyy/mm/dd hh:mm:ss`",
                        String::from_utf8_lossy(f[0]),
                        String::from_utf8_lossy(f[1])
                    )),
                }
            };
            let gps_ns = match gps_ns {
                Ok(v) => v,
                Err(e) => {
                    diag.push(&self.path, line_no, format!("time: {e}; line skipped"));
                    continue;
                }
            };
            let num = |k: usize| -> Result<f64, String> {
                parse_f64(f[k]).map_err(|e| format!("field {}: {e}; line skipped", k + 1))
            };
            let three = |c: [usize; 3]| -> Result<Vector3<f64>, String> {
                Ok(Vector3::new(num(c[0])?, num(c[1])?, num(c[2])?))
            };
            let q = match num(cols.q) {
                Ok(q) if q.fract() == 0.0 && (1.0..=RTKLIB_MAX_Q as f64).contains(&q) => q as u8,
                Ok(q) => {
                    diag.push(
                        &self.path,
                        line_no,
                        format!("quality flag Q = {q} is not 1..6; line skipped"),
                    );
                    continue;
                }
                Err(e) => {
                    diag.push(&self.path, line_no, e);
                    continue;
                }
            };
            if q > self.max_q {
                self.q_skipped[q as usize] += 1;
                continue;
            }
            let parsed = (|| -> Result<_, String> {
                let p = three(cols.pos)?;
                let sd = three(cols.sd)?;
                let cross = cols.sd_cross.map(three).transpose()?;
                let vel = cols.vel.map(three).transpose()?;
                let vel_sd = cols.vel_sd.map(three).transpose()?;
                Ok((p, sd, cross, vel, vel_sd))
            })();
            let (p, sd, cross, vel, vel_sd) = match parsed {
                Ok(v) => v,
                Err(e) => {
                    diag.push(&self.path, line_no, e);
                    continue;
                }
            };
            let (pos, pos_sd, vel, vel_sd) = match cols.frame {
                Frame::Llh => {
                    if p.x.abs() > 90.0 || p.y.abs() > 360.0 {
                        diag.push(
                            &self.path,
                            line_no,
                            format!(
                                "latitude {} / longitude {} out of range; line skipped",
                                p.x, p.y
                            ),
                        );
                        continue;
                    }
                    // Up → down: the σ are the same, the velocity flips.
                    (
                        Geodetic::from_deg(p.x, p.y, p.z),
                        sd,
                        vel.map(|v| Vector3::new(v.x, v.y, -v.z)),
                        vel_sd,
                    )
                }
                Frame::Xyz => {
                    let r = p.norm();
                    if !(6.0e6..7.0e7).contains(&r) {
                        diag.push(
                            &self.path,
                            line_no,
                            format!("ECEF position {r:.0} m from the Earth's centre; line skipped"),
                        );
                        continue;
                    }
                    let pos = ecef_to_geodetic(&p);
                    let c_en = c_ne(&pos).transpose();
                    // Covariance from RTKLIB's signed square roots, rotated
                    // to NED: P_n = C_e^n P_e C_n^e.
                    let signed_sq = |s: f64| s * s.abs();
                    let cr = cross.unwrap_or_else(Vector3::zeros);
                    let p_e = Matrix3::new(
                        sd.x * sd.x,
                        signed_sq(cr.x),
                        signed_sq(cr.z),
                        signed_sq(cr.x),
                        sd.y * sd.y,
                        signed_sq(cr.y),
                        signed_sq(cr.z),
                        signed_sq(cr.y),
                        sd.z * sd.z,
                    );
                    let p_n = c_en * p_e * c_en.transpose();
                    let pos_sd = Vector3::new(p_n[(0, 0)], p_n[(1, 1)], p_n[(2, 2)])
                        .map(|v| v.max(0.0).sqrt());
                    let vel_sd = vel_sd.map(|s| {
                        let pv =
                            c_en * Matrix3::from_diagonal(&s.component_mul(&s)) * c_en.transpose();
                        Vector3::new(pv[(0, 0)], pv[(1, 1)], pv[(2, 2)]).map(|v| v.sqrt())
                    });
                    (pos, pos_sd, vel.map(|v| c_en * v), vel_sd)
                }
            };
            let floor = |s: Vector3<f64>| -> Option<Vector3<f64>> {
                if s.iter().all(|&v| v > 0.0) {
                    Some(s)
                } else {
                    self.sd_floor.map(|fl| s.map(|v| v.max(fl)))
                }
            };
            let Some(pos_sd) = floor(pos_sd) else {
                diag.push(
                    &self.path,
                    line_no,
                    format!("position standard deviation {:?} is not positive; fix skipped (see --gnss-sd-floor)", pos_sd.as_slice()),
                );
                continue;
            };
            let (vel, vel_sd) = match vel_sd.map(floor) {
                Some(Some(s)) => (vel, Some(s)),
                _ => (None, None),
            };
            let ns_of_week = gps_ns.rem_euclid(NS_PER_WEEK);
            let time = self.weeks.peek(ns_of_week);
            if let Some(why) = time_order_problem(self.last, time) {
                diag.push(&self.path, line_no, format!("{why}; line skipped"));
                continue;
            }
            let time = self.weeks.resolve(ns_of_week);
            self.last = Some(time);
            self.count += 1;
            return Ok(Some(GnssFix {
                time,
                pos,
                pos_sd,
                vel,
                vel_sd,
            }));
        }
    }

    /// A one-line account of the solutions skipped by Q, if any.
    pub fn q_summary(&self) -> Option<String> {
        let total: usize = self.q_skipped.iter().sum();
        (total > 0).then(|| {
            let parts: Vec<String> = (1..=6)
                .filter(|&q| self.q_skipped[q] > 0)
                .map(|q| format!("Q={q}: {}", self.q_skipped[q]))
                .collect();
            format!(
                "{}: {total} RTKLIB solutions with Q > {} skipped ({}); see --rtklib-max-q",
                self.path.display(),
                self.max_q,
                parts.join(", ")
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::earth::geodetic_to_ecef;

    fn temp(name: &str, content: &str) -> crate::testfiles::TestDir {
        crate::testfiles::temp_file("rtklib", name, content)
    }

    fn read(
        p: &Path,
        week: i64,
        max_q: u8,
    ) -> (Result<Vec<GnssFix>, Error>, Diagnostics, PosReader) {
        let mut r = PosReader::open(p, week).unwrap();
        r.max_q = max_q;
        let mut d = Diagnostics::default();
        let mut out = Vec::new();
        let res = loop {
            match r.next_fix(&mut d) {
                Ok(Some(f)) => out.push(f),
                Ok(None) => break Ok(out),
                Err(e) => break Err(e),
            }
        };
        (res, d, r)
    }

    // Shaped as RTKLIB 2.4.3 rnx2rtkp writes it (manual appendix B).
    const LLH_WEEK: &str = "% program   : RTKLIB ver.2.4.3 b34\n\
% pos mode  : Kinematic\n\
%\n\
%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n\
2300 100000.000   30.444787370  114.471863205    20.9000   1   9   0.0030   0.0040   0.0100   0.0010  -0.0010   0.0020   1.00   12.3\n\
2300 100001.000   30.444787370  114.471863205    20.9000   2   9   0.0530   0.0540   0.1100   0.0010  -0.0010   0.0020   1.00    1.3\n\
2300 100002.000   30.444787370  114.471863205    20.9000   5   7   1.5300   1.5400   3.1100   0.0010  -0.0010   0.0020   0.00    0.0\n\
2300 100003.000   30.444787370  x                20.9000   1   9   0.0030   0.0040   0.0100   0.0010  -0.0010   0.0020   1.00   12.3\n\
2300 100004.000   30.444787370  114.471863205    20.9000   1   9\n\
2300 100003.500   30.444787370  114.471863205    20.9000   6   9   0.0030   0.0040   0.0100   0.0010  -0.0010   0.0020   1.00   12.3\n";

    #[test]
    fn llh_week_tow_with_q_filter_and_bad_lines() {
        let p = temp("llh.pos", LLH_WEEK);
        let (res, d, r) = read(&p, 2300, 6);
        let fixes = res.unwrap();
        assert_eq!(fixes.len(), 4);
        assert_eq!(fixes[0].time, GpsTime::from_week_sow(2300, 100000.0));
        assert_eq!(fixes[0].pos_sd, Vector3::new(0.003, 0.004, 0.01));
        assert!((fixes[0].pos.lat_rad.to_degrees() - 30.44478737).abs() < 1e-12);
        assert!(fixes[0].vel.is_none());
        assert_eq!(d.total, 2, "{:?}", d.items);
        let msgs: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
        assert!(msgs[0].contains("llh.pos:8: field 4: 'x'"), "{}", msgs[0]);
        assert!(msgs[1].contains("llh.pos:9: expected"), "{}", msgs[1]);
        assert!(r.q_summary().is_none());

        // Keep fix and float only: the single (Q=5) and PPP (Q=6) are counted.
        let (res, _, r) = read(&p, 2300, 2);
        assert_eq!(res.unwrap().len(), 2);
        assert_eq!(r.q_skipped[5], 1);
        assert_eq!(r.q_skipped[6], 1);
        assert!(r.q_summary().unwrap().contains("Q=5: 1, Q=6: 1"));
        // Week 0 (KF-GINS style run): same seconds of week.
        let (res, _, _) = read(&p, 0, 6);
        assert_eq!(res.unwrap()[0].time, GpsTime::from_week_sow(0, 100000.0));
    }

    #[test]
    fn xyz_with_calendar_time_rotates_the_covariance_to_ned() {
        let g = Geodetic::from_deg(30.5, 114.3, 25.0);
        let r = geodetic_to_ecef(&g);
        // A covariance that is diagonal in NED (σ 0.01, 0.02, 0.05 m),
        // turned into ECEF and written with RTKLIB's signed square roots.
        let c = c_ne(&g);
        let p_e = c * Matrix3::from_diagonal(&Vector3::new(1e-4, 4e-4, 2.5e-3)) * c.transpose();
        let ssq = |v: f64| v.signum() * v.abs().sqrt();
        let text = format!(
            "%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio\n\
             2024/02/05 03:46:40.000 {:.4} {:.4} {:.4} 1 10 {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} 0.00 0.0\n\
             2024/02/05 03:46:41.000 {:.4} {:.4} {:.4} 1 10 {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} 0.00 0.0\n\
             2024/13/05 03:46:42.000 1 2 3 1 10 1 1 1 0 0 0 0 0\n\
             2024/02/05 03:46:43.000 1 2 3 1 10 1 1 1 0 0 0 0 0\n",
            r.x,
            r.y,
            r.z,
            p_e[(0, 0)].sqrt(),
            p_e[(1, 1)].sqrt(),
            p_e[(2, 2)].sqrt(),
            ssq(p_e[(0, 1)]),
            ssq(p_e[(1, 2)]),
            ssq(p_e[(2, 0)]),
            r.x,
            r.y,
            r.z,
            p_e[(0, 0)].sqrt(),
            p_e[(1, 1)].sqrt(),
            p_e[(2, 2)].sqrt(),
            ssq(p_e[(0, 1)]),
            ssq(p_e[(1, 2)]),
            ssq(p_e[(2, 0)]),
        );
        let p = temp("xyz.pos", &text);
        let (res, d, _) = read(&p, 2300, 6);
        let fixes = res.unwrap();
        assert_eq!(fixes.len(), 2, "{:?}", d.items);
        // 2024-02-04 is the Sunday that starts week 2300: Monday 03:46:40
        // GPST is sow 86 400 + 13 600.
        assert_eq!(
            fixes[0].time,
            GpsTime::from_week_sow(2300, 86_400.0 + 13_600.0)
        );
        assert!((fixes[0].pos.h_m - 25.0).abs() < 1e-3);
        let want = Vector3::new(0.01, 0.02, 0.05);
        assert!(
            (fixes[0].pos_sd - want).norm() < 2e-5,
            "{:?}",
            fixes[0].pos_sd
        );
        assert_eq!(d.total, 2, "{:?}", d.items);
        assert!(
            d.items[0].to_string().contains("xyz.pos:4: time"),
            "{}",
            d.items[0]
        );
        assert!(
            d.items[1].to_string().contains("xyz.pos:5: ECEF position"),
            "{}",
            d.items[1]
        );
    }

    #[test]
    fn headers_that_cannot_be_read_are_errors_not_guesses() {
        for (content, want) in [
            (
                "2300 100000.0 30 114 20 1 9 0.1 0.1 0.1 0 0 0 0 0\n",
                ":1: data before the RTKLIB column header",
            ),
            (
                "%  UTC   latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)\n",
                ":1: time system UTC",
            ),
            (
                "%  GPST  latitude(d'\") longitude(d'\")  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)\n",
                "degrees-minutes-seconds",
            ),
            ("% only notes\n", "no RTKLIB solutions"),
        ] {
            let p = temp("bad.pos", content);
            let (res, _, _) = read(&p, 0, 6);
            let e = res.unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        }
    }

    #[test]
    fn llh_velocity_columns_are_read_up_to_down() {
        let text = "%  GPST  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)      sdvn     sdve     sdvu    sdvne    sdveu    sdvun\n\
2300 100000.000 30.5 114.3 20.0 1 9 0.003 0.004 0.010 0 0 0 0 0 1.5 -2.0 0.25 0.01 0.02 0.03 0 0 0\n";
        let p = temp("vel.pos", text);
        let (res, d, _) = read(&p, 2300, 6);
        let f = &res.unwrap()[0];
        assert!(d.is_empty(), "{:?}", d.items);
        assert_eq!(f.vel.unwrap(), Vector3::new(1.5, -2.0, -0.25));
        assert_eq!(f.vel_sd.unwrap(), Vector3::new(0.01, 0.02, 0.03));
    }
}
