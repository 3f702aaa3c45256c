//! KF-GINS text formats (FORMATS.md §1): IMU increments, GNSS positions
//! (7 columns) and positions+velocities (13 columns, C++ or Matlab order),
//! navigation results/truth (11 columns), and KF-GINS's IMU-error and
//! standard-deviation outputs.
//!
//! Readers stream (one record at a time) and report, then skip, any record
//! that is bad on its own: too few fields, a field that is not a finite
//! number, a value no sensor or vehicle produces (`super::plausible`: rates
//! implied by the increments, positions off the earth, speeds), a time that
//! goes backwards or repeats, or jumps and is not confirmed by the next
//! line, a GNSS standard deviation that is not positive. An empty file is
//! an error.
#![warn(missing_docs)]

use std::fs::File;
use std::io::Read;
use std::path::Path;

use nalgebra::Vector3;

use super::plausible::{
    Preceding, TimeGuard, Timed, increment_problem, position_problem, velocity_problem,
};
use super::text::{
    LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, push_fixed, split_fields,
};
use crate::earth::Geodetic;
use crate::error::{Diagnostics, Error};
use crate::time::{GpsTime, WeekTracker};
use crate::types::{GnssFix, ImuErrors, ImuSample};

/// Steps of an IMU file kept at once (s); a longer one waits for the next
/// line to confirm it ([`TimeGuard`]).
const IMU_MAX_STEP_S: f64 = 0.05;
/// Steps of a GNSS, navigation or truth file kept at once (s).
const FIX_MAX_STEP_S: f64 = 1.5;

/// Reads a KF-GINS IMU file: `sow dθx dθy dθz dvx dvy dvz [odo_speed]`.
pub struct ImuReader<R = File> {
    lines: LineReader<R>,
    path: std::path::PathBuf,
    weeks: WeekTracker,
    guard: TimeGuard<ImuSample>,
    count: usize,
}

impl ImuReader {
    /// Opens `path`; times are placed in GPS week `week` (0 when unknown).
    pub fn open(path: &Path, week: i64) -> Result<Self, Error> {
        Ok(Self::with_lines(LineReader::open(path)?, week))
    }
}

impl<R: Read> ImuReader<R> {
    /// Reads from `reader`, reported as `path`.
    pub fn from_reader(reader: R, path: &Path, week: i64) -> Self {
        Self::with_lines(LineReader::new(reader, path), week)
    }

    fn with_lines(lines: LineReader<R>, week: i64) -> Self {
        ImuReader {
            path: lines.path().to_path_buf(),
            lines,
            weeks: WeekTracker::new(week),
            guard: TimeGuard::new(IMU_MAX_STEP_S),
            count: 0,
        }
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Records read so far.
    pub(crate) fn count(&self) -> usize {
        self.count
    }

    /// The next good record; bad records (unreadable, implausible, a time
    /// out of order or an unconfirmed jump) are reported into `diag` and
    /// skipped. Errors at the end of an empty file.
    pub fn next_sample(&mut self, diag: &mut Diagnostics) -> Result<Option<ImuSample>, Error> {
        loop {
            let Self {
                lines,
                path,
                weeks,
                guard,
                ..
            } = self;
            let path: &Path = path;
            let kept = guard.next(path, diag, |prev, d| {
                Self::parse_next(lines, path, weeks, prev, d)
            })?;
            let Some(kept) = kept else {
                if self.count == 0 {
                    return Err(Error::NoData {
                        path: self.path.clone(),
                        msg: "no IMU records (expected lines of `sow dtheta_x dtheta_y dtheta_z dvel_x dvel_y dvel_z`)".into(),
                    });
                }
                return Ok(None);
            };
            // The first sample has no interval of its own: it was checked
            // over 1 s; now the next sample is known, over the interval to it.
            if self.count == 0
                && let Some(next) = self.guard.following()
                && let Some(why) = increment_problem(
                    &kept.rec.dtheta,
                    &kept.rec.dvel,
                    next.seconds_since(kept.time),
                )
            {
                diag.push(&self.path, kept.line, format!("{why}; line skipped"));
                continue;
            }
            self.weeks.resolve(kept.ns);
            self.count += 1;
            return Ok(Some(kept.rec));
        }
    }

    /// `prev`: what the sample would follow (its increments' interval).
    fn parse_next(
        lines: &mut LineReader<R>,
        path: &Path,
        weeks: &mut WeekTracker,
        prev: Preceding,
        diag: &mut Diagnostics,
    ) -> Result<Option<Timed<ImuSample>>, Error> {
        loop {
            let mut f: [&[u8]; 8] = [b""; 8];
            let Some((line, line_no)) = lines.next_line()? else {
                return Ok(None);
            };
            if is_blank_or_comment(line) {
                continue;
            }
            let nf = split_fields(line, &mut f);
            if nf < 7 {
                diag.push(
                    path,
                    line_no,
                    format!("expected 7 fields (sow, 3 angle and 3 velocity increments), found {nf}; line skipped"),
                );
                continue;
            }
            let ns = match parse_seconds_ns(f[0]) {
                Ok(v) => v,
                Err(e) => {
                    diag.push(path, line_no, format!("field 1 (sow): {e}; line skipped"));
                    continue;
                }
            };
            let mut vals = [0.0; 7];
            let mut bad = None;
            for k in 1..nf.min(8) {
                match parse_f64(f[k]) {
                    Ok(v) => vals[k - 1] = v,
                    Err(e) => {
                        bad = Some(format!("field {}: {e}; line skipped", k + 1));
                        break;
                    }
                }
            }
            if let Some(msg) = bad {
                diag.push(path, line_no, msg);
                continue;
            }
            let time = weeks.peek(ns);
            let dtheta = Vector3::new(vals[0], vals[1], vals[2]);
            let dvel = Vector3::new(vals[3], vals[4], vals[5]);
            // The interval since the sample this one follows (the held one
            // when this confirms it: a real gap ends there); 1 s for the
            // first (rechecked in `next_sample`) and for one out of order
            // (the guard reports its time).
            let dt_s = prev.before(time).map_or(1.0, |p| time.seconds_since(p));
            let odo_speed = (nf >= 8).then_some(vals[6]);
            let why = increment_problem(&dtheta, &dvel, dt_s).or_else(|| {
                odo_speed
                    .and_then(|v| velocity_problem(&[v, 0.0, 0.0]).map(|w| format!("odometer {w}")))
            });
            if let Some(why) = why {
                diag.push(path, line_no, format!("{why}; line skipped"));
                continue;
            }
            return Ok(Some(Timed {
                rec: ImuSample {
                    time,
                    dtheta,
                    dvel,
                    odo_speed,
                },
                ns,
                time,
                line: line_no,
            }));
        }
    }
}

/// Column order of a 13-column GNSS file (FORMATS.md §1: an explicit
/// option, never a guess).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum GnssLayout {
    /// KF-GINS C++: `sow lat lon h vn ve vd sd_n sd_e sd_d sd_vn sd_ve sd_vd`.
    #[default]
    Cpp,
    /// KF-GINS-Matlab: `sow lat lon h sd_n sd_e sd_d vn ve vd sd_vn sd_ve sd_vd`.
    Matlab,
}

/// Reads a KF-GINS GNSS file of 7 or 13 columns.
pub struct GnssReader<R = File> {
    lines: LineReader<R>,
    path: std::path::PathBuf,
    layout: GnssLayout,
    weeks: WeekTracker,
    guard: TimeGuard<GnssFix>,
    count: usize,
    /// Replace standard deviations below this (m or m/s) instead of skipping
    /// the fix; `None` skips fixes with a non-positive std.
    pub(crate) sd_floor: Option<f64>,
}

impl GnssReader {
    /// Opens a KF-GINS GNSS file of this layout; `week` dates its seconds of week.
    pub fn open(path: &Path, week: i64, layout: GnssLayout) -> Result<Self, Error> {
        Ok(Self::with_lines(LineReader::open(path)?, week, layout))
    }
}

impl<R: Read> GnssReader<R> {
    /// Reads from `reader`, reported as `path`.
    pub fn from_reader(reader: R, path: &Path, week: i64, layout: GnssLayout) -> Self {
        Self::with_lines(LineReader::new(reader, path), week, layout)
    }

    fn with_lines(lines: LineReader<R>, week: i64, layout: GnssLayout) -> Self {
        GnssReader {
            path: lines.path().to_path_buf(),
            lines,
            layout,
            weeks: WeekTracker::new(week),
            guard: TimeGuard::new(FIX_MAX_STEP_S),
            count: 0,
            sd_floor: None,
        }
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The next good fix; bad lines (unreadable, off the earth, σ not
    /// positive, a time out of order or an unconfirmed jump) are reported
    /// into `diag` and skipped.
    pub fn next_fix(&mut self, diag: &mut Diagnostics) -> Result<Option<GnssFix>, Error> {
        let Self {
            lines,
            path,
            layout,
            weeks,
            guard,
            sd_floor,
            ..
        } = self;
        let path: &Path = path;
        let kept = guard.next(path, diag, |_, d| {
            Self::parse_next(lines, path, weeks, *layout, *sd_floor, d)
        })?;
        let Some(kept) = kept else {
            if self.count == 0 {
                // Every line skipped (σ all 0, all unreadable, …): say why,
                // not only that nothing was found.
                let file = self.path.display().to_string();
                let mut skipped = diag.items.iter().filter(|d| d.file == file);
                let first = skipped
                    .next()
                    .map(|d| format!(" The first: line {}: {}", d.line, d.message));
                let msg = match first {
                    Some(first) => format!(
                        "no usable GNSS fix: {} line(s) were skipped and none kept.{first}",
                        1 + skipped.count()
                    ),
                    None => "no GNSS records (expected 7 or 13 columns: `sow lat_deg lon_deg h_m sd_n sd_e sd_d`)".into(),
                };
                return Err(Error::NoData {
                    path: self.path.clone(),
                    msg,
                });
            }
            return Ok(None);
        };
        self.weeks.resolve(kept.ns);
        self.count += 1;
        Ok(Some(kept.rec))
    }

    /// The next line that parses and is plausible on its own.
    fn parse_next(
        lines: &mut LineReader<R>,
        path: &Path,
        weeks: &mut WeekTracker,
        layout: GnssLayout,
        sd_floor: Option<f64>,
        diag: &mut Diagnostics,
    ) -> Result<Option<Timed<GnssFix>>, Error> {
        loop {
            let mut f: [&[u8]; 13] = [b""; 13];
            let Some((line, line_no)) = lines.next_line()? else {
                return Ok(None);
            };
            if is_blank_or_comment(line) {
                continue;
            }
            let nf = split_fields(line, &mut f);
            if nf != 7 && nf != 13 {
                diag.push(
                    path,
                    line_no,
                    format!("expected 7 or 13 fields, found {nf}; line skipped"),
                );
                continue;
            }
            let ns = match parse_seconds_ns(f[0]) {
                Ok(v) => v,
                Err(e) => {
                    diag.push(path, line_no, format!("field 1 (sow): {e}; line skipped"));
                    continue;
                }
            };
            let mut v = [0.0; 13];
            let mut bad = None;
            for k in 1..nf {
                match parse_f64(f[k]) {
                    Ok(x) => v[k] = x,
                    Err(e) => {
                        bad = Some(format!("field {}: {e}; line skipped", k + 1));
                        break;
                    }
                }
            }
            if let Some(msg) = bad {
                diag.push(path, line_no, msg);
                continue;
            }
            if let Some(why) = position_problem(v[1], v[2], v[3]) {
                diag.push(path, line_no, format!("{why}; line skipped"));
                continue;
            }
            let (pos_sd, vel, vel_sd) = if nf == 7 {
                (Vector3::new(v[4], v[5], v[6]), None, None)
            } else {
                match layout {
                    GnssLayout::Cpp => (
                        Vector3::new(v[7], v[8], v[9]),
                        Some(Vector3::new(v[4], v[5], v[6])),
                        Some(Vector3::new(v[10], v[11], v[12])),
                    ),
                    GnssLayout::Matlab => (
                        Vector3::new(v[4], v[5], v[6]),
                        Some(Vector3::new(v[7], v[8], v[9])),
                        Some(Vector3::new(v[10], v[11], v[12])),
                    ),
                }
            };
            let fix_sd = |sd: Vector3<f64>,
                          what: &str,
                          diag: &mut Diagnostics|
             -> Option<Vector3<f64>> {
                if sd.iter().all(|&s| s > 0.0 && s.is_finite()) {
                    return Some(sd);
                }
                match sd_floor {
                    Some(floor) => Some(sd.map(|s| s.max(floor))),
                    None => {
                        diag.push(
                            path,
                            line_no,
                            format!("{what} standard deviation {:?} is not positive; fix skipped (see --gnss-sd-floor)", sd.as_slice()),
                        );
                        None
                    }
                }
            };
            let Some(pos_sd) = fix_sd(pos_sd, "position", diag) else {
                continue;
            };
            let vel_sd = match vel_sd {
                Some(sd) => match fix_sd(sd, "velocity", diag) {
                    Some(s) => Some(s),
                    None => continue,
                },
                None => None,
            };
            if let Some(why) = vel.and_then(|v| velocity_problem(&[v.x, v.y, v.z])) {
                diag.push(path, line_no, format!("{why}; line skipped"));
                continue;
            }
            let time = weeks.peek(ns);
            return Ok(Some(Timed {
                rec: GnssFix {
                    time,
                    pos: Geodetic::from_deg(v[1], v[2], v[3]),
                    pos_sd,
                    vel,
                    vel_sd,
                },
                ns,
                time,
                line: line_no,
            }));
        }
    }
}

/// One line of the navigation-result / truth format:
/// `week sow lat_deg lon_deg h_m vn ve vd roll_deg pitch_deg yaw_deg`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct NavRecord {
    /// Week as written in the file (0 when unknown, as KF-GINS writes).
    pub week: i64,
    /// Time: in the file's week, or, when it has 0, in week 0 and then 1
    /// after a rollover.
    pub time: GpsTime,
    /// Latitude (deg), positive north.
    pub lat_deg: f64,
    /// Longitude (deg), positive east.
    pub lon_deg: f64,
    /// Ellipsoidal height (m).
    pub h_m: f64,
    /// Velocity north, east, down (m/s).
    pub vel: [f64; 3],
    /// roll, pitch, yaw (deg).
    pub att_deg: [f64; 3],
}

/// Streams an 11-column navigation file (result or truth).
pub struct NavReader<R = File> {
    lines: LineReader<R>,
    path: std::path::PathBuf,
    guard: TimeGuard<NavRecord>,
    count: usize,
    /// Follows records of week 0 across a week rollover.
    weeks: WeekTracker,
}

impl NavReader {
    /// Opens a KF-GINS navigation result (`.nav`).
    pub fn open(path: &Path) -> Result<Self, Error> {
        Ok(Self::with_lines(LineReader::open(path)?))
    }

    /// Reads the whole file (for truth files that are interpolated).
    pub fn read_all(path: &Path, diag: &mut Diagnostics) -> Result<Vec<NavRecord>, Error> {
        let mut r = NavReader::open(path)?;
        let mut out = Vec::new();
        while let Some(rec) = r.next_record(diag)? {
            out.push(rec);
        }
        Ok(out)
    }
}

impl<R: Read> NavReader<R> {
    /// Reads from `reader`, reported as `path`.
    pub fn from_reader(reader: R, path: &Path) -> Self {
        Self::with_lines(LineReader::new(reader, path))
    }

    fn with_lines(lines: LineReader<R>) -> Self {
        NavReader {
            path: lines.path().to_path_buf(),
            lines,
            guard: TimeGuard::new(FIX_MAX_STEP_S),
            count: 0,
            weeks: WeekTracker::new(0),
        }
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The next good record; bad lines are reported and skipped. A record
    /// of week 0 (KF-GINS writes no week) is timed in week 0, and in week
    /// 1 after its seconds of week roll over (fall back by more than half
    /// a week), so that a drive across the rollover keeps going forward.
    /// Records off the earth, faster than [`super::plausible::MAX_SPEED_MPS`] or with a
    /// time that jumps unconfirmed are reported and skipped too.
    pub fn next_record(&mut self, diag: &mut Diagnostics) -> Result<Option<NavRecord>, Error> {
        let Self {
            lines,
            path,
            weeks,
            guard,
            ..
        } = self;
        let path: &Path = path;
        let kept = guard.next(path, diag, |_, d| Self::parse_next(lines, path, weeks, d))?;
        let Some(kept) = kept else {
            if self.count == 0 {
                return Err(Error::NoData {
                    path: self.path.clone(),
                    msg: "no navigation records (expected 11 columns: week sow lat lon h vn ve vd roll pitch yaw)"
                        .into(),
                });
            }
            return Ok(None);
        };
        if kept.rec.week == 0 {
            self.weeks.resolve(kept.ns);
        }
        self.count += 1;
        Ok(Some(kept.rec))
    }

    /// The next line that parses and is plausible on its own.
    fn parse_next(
        lines: &mut LineReader<R>,
        path: &Path,
        weeks: &mut WeekTracker,
        diag: &mut Diagnostics,
    ) -> Result<Option<Timed<NavRecord>>, Error> {
        loop {
            let mut f: [&[u8]; 12] = [b""; 12];
            let Some((line, line_no)) = lines.next_line()? else {
                return Ok(None);
            };
            if is_blank_or_comment(line) {
                continue;
            }
            let nf = split_fields(line, &mut f);
            if nf < 11 {
                diag.push(
                    path,
                    line_no,
                    format!("expected 11 fields, found {nf}; line skipped"),
                );
                continue;
            }
            let week = match parse_f64(f[0]) {
                Ok(w) if w >= 0.0 && w.fract() == 0.0 => w as i64,
                _ => {
                    diag.push(
                        path,
                        line_no,
                        "field 1 (week) is not a whole number; line skipped",
                    );
                    continue;
                }
            };
            let ns = match parse_seconds_ns(f[1]) {
                Ok(v) => v,
                Err(e) => {
                    diag.push(path, line_no, format!("field 2 (sow): {e}; line skipped"));
                    continue;
                }
            };
            let mut v = [0.0; 11];
            let mut bad = None;
            for k in 2..11 {
                match parse_f64(f[k]) {
                    Ok(x) => v[k] = x,
                    Err(e) => {
                        bad = Some(format!("field {}: {e}; line skipped", k + 1));
                        break;
                    }
                }
            }
            if let Some(msg) = bad {
                diag.push(path, line_no, msg);
                continue;
            }
            // Week 0: a time far back in mid-week is a bad line, not a new
            // week (see `WeekTracker`).
            let time = if week == 0 {
                weeks.peek(ns)
            } else {
                GpsTime::from_week_ns(week, ns)
            };
            let vel = [v[5], v[6], v[7]];
            if let Some(why) = position_problem(v[2], v[3], v[4])
                .or_else(|| velocity_problem(&vel))
                .or_else(|| {
                    // Attitude in degrees: roll and yaw within ±360, pitch ±90.
                    (v[8].abs() > 360.0 || v[9].abs() > 90.0 || v[10].abs() > 360.0)
                        .then(|| format!("attitude {:?}° is out of range", [v[8], v[9], v[10]]))
                })
            {
                diag.push(path, line_no, format!("{why}; line skipped"));
                continue;
            }
            return Ok(Some(Timed {
                rec: NavRecord {
                    week,
                    time,
                    lat_deg: v[2],
                    lon_deg: v[3],
                    h_m: v[4],
                    vel,
                    att_deg: [v[8], v[9], v[10]],
                },
                ns,
                time,
                line: line_no,
            }));
        }
    }
}

/// Reads a list of epochs, one per line: `sow` or `week sow` (any
/// separators, `#` comments). Epochs are placed in `week` when the file has
/// none or when `week` is 0 (KF-GINS files carry no week). Epochs must
/// increase; others are errors naming the line.
pub(crate) fn read_times(path: &Path, week: i64) -> Result<Vec<GpsTime>, Error> {
    let mut lines = LineReader::open(path)?;
    let mut out: Vec<GpsTime> = Vec::new();
    while let Some((line, line_no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 3] = [b""; 3];
        let nf = split_fields(line, &mut f);
        let (w, sow_field) = match nf {
            1 => (week, f[0]),
            2 => {
                let w = parse_f64(f[0])
                    .map_err(|e| Error::parse(path, line_no, format!("week: {e}")))?;
                (if week == 0 { 0 } else { w as i64 }, f[1])
            }
            _ => {
                return Err(Error::parse(
                    path,
                    line_no,
                    format!("expected `sow` or `week sow`, found {nf} fields"),
                ));
            }
        };
        let ns = parse_seconds_ns(sow_field)
            .map_err(|e| Error::parse(path, line_no, format!("sow: {e}")))?;
        let t = GpsTime::from_week_ns(w, ns);
        if out.last().is_some_and(|&l| t <= l) {
            return Err(Error::parse(
                path,
                line_no,
                format!("epoch {t} does not increase"),
            ));
        }
        out.push(t);
    }
    if out.is_empty() {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: "no epochs (expected one `sow` or `week sow` per line)".into(),
        });
    }
    Ok(out)
}

/// Appends one navigation line (KF-GINS nav format, precision as the
/// shared truth files: 1e-9 s, 1e-12 deg, 1e-6 m, 1e-9 m/s and deg).
pub fn format_nav_line(
    out: &mut Vec<u8>,
    week: i64,
    time: GpsTime,
    pos: &Geodetic,
    vel: &Vector3<f64>,
    att_deg: &[f64; 3],
) {
    super::text::push_u64(out, week.max(0) as u64);
    out.push(b' ');
    time.write_sow(out);
    out.push(b' ');
    push_fixed(out, pos.lat_rad.to_degrees(), 12);
    out.push(b' ');
    push_fixed(out, pos.lon_rad.to_degrees(), 12);
    out.push(b' ');
    push_fixed(out, pos.h_m, 6);
    for k in 0..3 {
        out.push(b' ');
        push_fixed(out, vel[k], 9);
    }
    for a in att_deg {
        out.push(b' ');
        push_fixed(out, *a, 9);
    }
    out.push(b'\n');
}

/// Appends one IMU-error line in KF-GINS's layout:
/// `sow gyro_bias(deg/h ×3) accel_bias(mGal ×3) gyro_scale(ppm ×3) accel_scale(ppm ×3)`.
pub fn format_imu_err_line(out: &mut Vec<u8>, time: GpsTime, e: &ImuErrors) {
    time.write_sow(out);
    let groups = [
        (e.gyro_bias, 180.0 / std::f64::consts::PI * 3600.0),
        (e.accel_bias, 1e5),
        (e.gyro_scale, 1e6),
        (e.accel_scale, 1e6),
    ];
    for (v, scale) in groups {
        for k in 0..3 {
            out.push(b' ');
            push_fixed(out, v[k] * scale, 6);
        }
    }
    out.push(b'\n');
}

/// Appends one standard-deviation line in KF-GINS's layout:
/// `sow pos(m ×3) vel(m/s ×3) att(deg ×3) gyro_bias(deg/h ×3)
/// accel_bias(mGal ×3) gyro_scale(ppm ×3) accel_scale(ppm ×3)`; `sd` holds
/// the 21 core standard deviations in SI units.
pub(crate) fn format_std_line(out: &mut Vec<u8>, time: GpsTime, sd: &[f64]) {
    time.write_sow(out);
    let deg = 180.0 / std::f64::consts::PI;
    for (i, &s) in sd.iter().take(21).enumerate() {
        let (scale, dec) = match i {
            0..=5 => (1.0, 6),
            6..=8 => (deg, 8),
            9..=11 => (deg * 3600.0, 6),
            12..=14 => (1e5, 6),
            _ => (1e6, 6),
        };
        out.push(b' ');
        push_fixed(out, s * scale, dec);
    }
    out.push(b'\n');
}

/// Writes KF-GINS IMU increments (one line per sample).
pub fn format_imu_line(out: &mut Vec<u8>, s: &ImuSample) {
    s.time.write_sow(out);
    // Shortest round-trip form: every bit of an increment is kept (seed 001
    // §1.5 point 4: never truncate IMU data).
    for v in s.dtheta.iter().chain(s.dvel.iter()) {
        out.push(b' ');
        super::text::push_f64(out, *v);
    }
    if let Some(o) = s.odo_speed {
        out.push(b' ');
        push_fixed(out, o, 6);
    }
    out.push(b'\n');
}

/// Writes one GNSS fix line (7 columns, or 13 in KF-GINS C++ order when it
/// has a velocity).
pub fn format_gnss_line(out: &mut Vec<u8>, fix: &GnssFix) {
    fix.time.write_sow(out);
    out.push(b' ');
    push_fixed(out, fix.pos.lat_rad.to_degrees(), 11);
    out.push(b' ');
    push_fixed(out, fix.pos.lon_rad.to_degrees(), 11);
    out.push(b' ');
    push_fixed(out, fix.pos.h_m, 4);
    if let (Some(v), Some(_)) = (fix.vel, fix.vel_sd) {
        for k in 0..3 {
            out.push(b' ');
            push_fixed(out, v[k], 4);
        }
    }
    for k in 0..3 {
        out.push(b' ');
        push_fixed(out, fix.pos_sd[k], 4);
    }
    if let (Some(_), Some(sd)) = (fix.vel, fix.vel_sd) {
        for k in 0..3 {
            out.push(b' ');
            push_fixed(out, sd[k], 4);
        }
    }
    out.push(b'\n');
}

/// A buffered text writer that reports errors with the file name; the file
/// appears under its name only when [`TextWriter::finish`] succeeds (an
/// [`AtomicFile`](super::output::AtomicFile): dropped unfinished, it
/// leaves nothing).
pub struct TextWriter {
    inner: super::output::AtomicFile,
}

impl TextWriter {
    /// Starts the file (replacing an existing one when finished).
    pub fn create(path: &Path) -> Result<Self, Error> {
        Ok(TextWriter {
            inner: super::output::AtomicFile::with_capacity(path, 1 << 20)?,
        })
    }

    /// Appends bytes (buffered).
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), Error> {
        self.inner.write(bytes)
    }

    /// Flushes the buffer and puts the file under its name; an error names
    /// the file.
    pub fn finish(self) -> Result<(), Error> {
        self.inner.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_file(name: &str, content: &str) -> crate::testfiles::TestDir {
        crate::testfiles::temp_file("kfgins", name, content)
    }

    fn read_imu(content: &str) -> (Result<Vec<ImuSample>, Error>, Diagnostics) {
        let p = temp_file("imu.txt", content);
        let mut d = Diagnostics::default();
        let mut r = ImuReader::open(&p, 0).unwrap();
        let mut out = Vec::new();
        let res = loop {
            match r.next_sample(&mut d) {
                Ok(Some(s)) => out.push(s),
                Ok(None) => break Ok(out),
                Err(e) => break Err(e),
            }
        };
        (res, d)
    }

    #[test]
    fn imu_bad_lines_are_reported_and_skipped() {
        let content = "# comment\n\
            1.000 0 0 0 0 0 -0.049\n\
            1.005 0 0 0 0 0\n\
            1.010 0 0 x 0 0 -0.049\n\
            1.015 0 0 nan 0 0 -0.049\n\
            1.020 0 0 0 0 0 -0.049\n\
            1.020 0 0 0 0 0 -0.049\n\
            1.015 0 0 0 0 0 -0.049\n\
            1.025,0,0,0,0,0,-0.049\n";
        let (res, d) = read_imu(content);
        let samples = res.unwrap();
        assert_eq!(samples.len(), 3, "{samples:?}");
        assert_eq!(d.total, 5);
        let msgs: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
        assert!(msgs[0].contains(":3: expected 7 fields"), "{}", msgs[0]);
        assert!(
            msgs[1].contains(":4: field 4: 'x' is not a number"),
            "{}",
            msgs[1]
        );
        assert!(
            msgs[2].contains(":5: field 4: 'nan' is not a finite number"),
            "{}",
            msgs[2]
        );
        assert!(msgs[3].contains(":7: duplicate epoch"), "{}", msgs[3]);
        assert!(msgs[4].contains(":8: time goes backwards"), "{}", msgs[4]);
    }

    #[test]
    fn a_corrupt_mid_week_time_costs_its_own_line_only() {
        // 500 000 s of week, one line's SOW garbled to 12 s: not a week
        // rollover (that would jump 29 h ahead and strand every later
        // line behind it).
        let content = "500000.000 0 0 0 0 0 -0.049\n\
            500000.005 0 0 0 0 0 -0.049\n\
            12.010 0 0 0 0 0 -0.049\n\
            500000.015 0 0 0 0 0 -0.049\n\
            500000.020 0 0 0 0 0 -0.049\n";
        let (res, d) = read_imu(content);
        let samples = res.unwrap();
        assert_eq!(samples.len(), 4, "{samples:?}");
        assert!(samples.iter().all(|s| s.time.week() == 0));
        assert_eq!(d.total, 1, "{d:?}");
        assert!(
            d.items[0].to_string().contains(":3: time goes backwards"),
            "{d:?}"
        );
    }

    #[test]
    fn implausible_values_and_unconfirmed_time_jumps_cost_their_own_line() {
        // Line 3: a gyro increment of 1e20 rad; line 5: a time of 1e308 s;
        // line 7: a time garbled 90 000 s ahead; line 9 ends a real 60 s gap.
        let content = "500000.000 0 0 0 0 0 -0.049\n\
            500000.005 0 0 0 0 0 -0.049\n\
            500000.010 1e20 0 0 0 0 -0.049\n\
            500000.015 0 0 0 0 0 -0.049\n\
            1e308 0 0 0 0 0 -0.049\n\
            500000.020 0 0 0 0 0 -0.049\n\
            590000.025 0 0 0 0 0 -0.049\n\
            500000.030 0 0 0 0 0 -0.049\n\
            500060.030 0 0 0 0 0 -0.049\n\
            500060.035 0 0 0 0 0 -0.049\n";
        let (res, d) = read_imu(content);
        let t: Vec<f64> = res.unwrap().iter().map(|s| s.time.sow()).collect();
        assert_eq!(
            t,
            [
                500000.0, 500000.005, 500000.015, 500000.02, 500000.03, 500060.03, 500060.035
            ]
        );
        let msgs: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
        assert_eq!(msgs.len(), 3, "{msgs:?}");
        assert!(
            msgs[0].contains(":3: angular rate 2e22 rad/s"),
            "{}",
            msgs[0]
        );
        assert!(
            msgs[1].contains(":5: field 1 (sow): time 1e308 s"),
            "{}",
            msgs[1]
        );
        assert!(
            msgs[2].contains(":7: time") && msgs[2].contains("does not go on from it"),
            "{}",
            msgs[2]
        );
    }

    /// Increments are checked over the interval to the sample they follow,
    /// also when that one was held for its jump (the file's first sample,
    /// the end of a real gap); the first is checked over the interval to
    /// the next. Found by the `kfgins_text` fuzz target: line 2 below, 1.08
    /// rad in 15 ms (72 rad/s), was checked over 1 s and kept.
    #[test]
    fn increments_are_checked_over_the_interval_they_follow() {
        let rates = |content: &str| {
            let (res, d) = read_imu(content);
            let t: Vec<f64> = res.unwrap().iter().map(|s| s.time.sow()).collect();
            let msgs: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
            (t, msgs)
        };
        // The fuzzer's case: line 2 follows the held first line.
        let (t, msgs) = rates(
            "100000.0050007 3.5e-06 -1.9e-07 -2.2e-06 5.8e-07 3.4e-05 -4.9e-02\n\
             100000.020 1.0845 2.3e-07 3.6e-06 -1.9e-07 -2.2e-06 -4.9e-02\n\
             100000.025 0 0 0 0 0 -0.049\n",
        );
        assert_eq!(t, [100000.0050007, 100000.025]);
        assert_eq!(msgs.len(), 1, "{msgs:?}");
        assert!(msgs[0].contains(":2: angular rate 7.2"), "{}", msgs[0]);
        // After a real 0.1 s gap (line 3 held, line 4 confirms it), 0.5 rad
        // in 5 ms (100 rad/s) is implausible; over the 105 ms since line 2
        // it would not be.
        let (t, msgs) = rates(
            "200000.000 0 0 0 0 0 -0.049\n\
             200000.005 0 0 0 0 0 -0.049\n\
             200000.105 0 0 0 0 0 -0.049\n\
             200000.110 0.5 0 0 0 0 -0.049\n\
             200000.115 0 0 0 0 0 -0.049\n",
        );
        assert_eq!(t, [200000.0, 200000.005, 200000.105, 200000.115]);
        assert_eq!(msgs.len(), 1, "{msgs:?}");
        assert!(
            msgs[0].contains(":4: angular rate 1e2 rad/s"),
            "{}",
            msgs[0]
        );
        // The first sample: 1 rad in 5 ms is checked against the next line.
        let (t, msgs) = rates(
            "300000.000 1.0 0 0 0 0 -0.049\n\
             300000.005 0 0 0 0 0 -0.049\n\
             300000.010 0 0 0 0 0 -0.049\n",
        );
        assert_eq!(t, [300000.005, 300000.01]);
        assert_eq!(msgs.len(), 1, "{msgs:?}");
        assert!(
            msgs[0].contains(":1: angular rate 2e2 rad/s"),
            "{}",
            msgs[0]
        );
    }

    #[test]
    fn gnss_fixes_off_the_earth_or_jumping_are_skipped() {
        let content = "100.0 30.0 114.0 20.0 0.02 0.02 0.03\n\
            101.0 143545.0 114.0 20.0 0.02 0.02 0.03\n\
            102.0 30.0 114.0 1e308 0.02 0.02 0.03\n\
            103.0 30.0 114.0 20.0 0.02 1e308 0.03\n\
            9e7 30.0 114.0 20.0 0.02 0.02 0.03\n\
            104.0 30.0 114.0 20.0 0.02 0.02 0.03\n";
        let p = temp_file("gnss.txt", content);
        let mut d = Diagnostics::default();
        let mut r = GnssReader::open(&p, 0, GnssLayout::Cpp).unwrap();
        let mut t = Vec::new();
        while let Some(f) = r.next_fix(&mut d).unwrap() {
            t.push(f.time.sow());
        }
        // 1e308 as a σ is finite; the fusion refuses σ > 1 km with its own note.
        assert_eq!(t, [100.0, 103.0, 104.0]);
        let msgs: Vec<String> = d.items.iter().map(|x| x.to_string()).collect();
        assert_eq!(msgs.len(), 3, "{msgs:?}");
        assert!(msgs[0].contains(":2: latitude 143545"), "{}", msgs[0]);
        assert!(msgs[1].contains(":3: height 1e308 m"), "{}", msgs[1]);
        assert!(msgs[2].contains(":5: time"), "{}", msgs[2]);
    }

    #[test]
    fn imu_empty_file_is_an_error() {
        let (res, _) = read_imu("# only a comment\n\n");
        let err = res.unwrap_err().to_string();
        assert!(
            err.contains("imu.txt") && err.contains("no IMU records"),
            "{err}"
        );
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = ImuReader::open(Path::new("/nonexistent/dir/imu.txt"), 0)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("/nonexistent/dir/imu.txt"), "{err}");
    }

    #[test]
    fn gnss_layouts_and_zero_std() {
        let content = "1.0 30.0 114.0 20.0 1 2 3 0.02 0.02 0.03 0.1 0.1 0.1\n\
                       2.0 30.0 114.0 20.0 0.02 0.0 0.03\n";
        let p = temp_file("gnss.txt", content);
        let mut d = Diagnostics::default();
        let mut r = GnssReader::open(&p, 0, GnssLayout::Cpp).unwrap();
        let fix = r.next_fix(&mut d).unwrap().unwrap();
        assert_eq!(fix.vel.unwrap(), Vector3::new(1.0, 2.0, 3.0));
        assert_eq!(fix.pos_sd, Vector3::new(0.02, 0.02, 0.03));
        assert!(r.next_fix(&mut d).unwrap().is_none());
        assert_eq!(d.total, 1);
        assert!(
            d.items[0]
                .to_string()
                .contains(":2: position standard deviation")
        );

        let mut r = GnssReader::open(&p, 0, GnssLayout::Matlab).unwrap();
        let fix = r.next_fix(&mut d).unwrap().unwrap();
        assert_eq!(fix.pos_sd, Vector3::new(1.0, 2.0, 3.0));
        assert_eq!(fix.vel.unwrap(), Vector3::new(0.02, 0.02, 0.03));

        let mut r = GnssReader::open(&p, 0, GnssLayout::Cpp).unwrap();
        r.sd_floor = Some(0.01);
        let _ = r.next_fix(&mut d).unwrap().unwrap();
        let fix = r.next_fix(&mut d).unwrap().unwrap();
        assert_eq!(fix.pos_sd[1], 0.01);

        // Every σ zero: the error says why nothing was kept.
        let p = temp_file(
            "gnss.txt",
            "1.0 30.0 114.0 20.0 0 0 0\n2.0 30.0 114.0 20.0 0 0 0\n",
        );
        let mut d = Diagnostics::default();
        let mut r = GnssReader::open(&p, 0, GnssLayout::Cpp).unwrap();
        let e = r.next_fix(&mut d).unwrap_err().to_string();
        assert!(
            e.contains("2 line(s) were skipped and none kept")
                && e.contains(
                    "line 1: position standard deviation [0.0, 0.0, 0.0] is not positive"
                ),
            "{e}"
        );
    }

    #[test]
    fn nav_line_round_trips() {
        let pos = Geodetic::from_deg(30.444787370100, 114.471863204700, 20.9);
        let mut out = Vec::new();
        let t = GpsTime::from_week_sow(2300, 100000.005);
        format_nav_line(
            &mut out,
            2300,
            t,
            &pos,
            &Vector3::new(1.0, -2.5, 0.001),
            &[0.5, -1.25, 45.0],
        );
        let s = String::from_utf8(out).unwrap();
        assert_eq!(
            s,
            "2300 100000.005000000 30.444787370100 114.471863204700 20.900000 1.000000000 -2.500000000 0.001000000 0.500000000 -1.250000000 45.000000000\n"
        );
        let p = temp_file("nav.txt", &s);
        let mut d = Diagnostics::default();
        let recs = NavReader::read_all(&p, &mut d).unwrap();
        assert_eq!(recs.len(), 1);
        assert_eq!(recs[0].time, t);
        assert_eq!(recs[0].att_deg[2], 45.0);
    }

    #[test]
    fn imu_line_keeps_full_precision() {
        let s = ImuSample {
            time: GpsTime::from_week_sow(0, 1.005),
            dtheta: Vector3::new(2.289_979_938_347_008e-7, -1.0 / 3.0, 0.0),
            dvel: Vector3::new(1e-300, 5.0, -4.889_923_517_563_737e-2),
            odo_speed: None,
        };
        let mut out = Vec::new();
        format_imu_line(&mut out, &s);
        let p = temp_file("imu-rt.txt", std::str::from_utf8(&out).unwrap());
        let mut d = Diagnostics::default();
        let mut r = ImuReader::open(&p, 0).unwrap();
        let back = r.next_sample(&mut d).unwrap().unwrap();
        assert_eq!(back, s);
    }
}
