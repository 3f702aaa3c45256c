//! Export of a navigation solution (11-column nav format) to the formats
//! users' tools read: GPX 1.1 (Topografix schema), KML 2.2 (OGC 07-147r2),
//! GeoJSON (RFC 7946), CSV with a header naming units, and the TUM
//! trajectory format (TUM RGB-D benchmark: `timestamp tx ty tz qx qy qz
//! qw`, as `evo` reads it).
//!
//! The solution's standard deviations come from a KF-GINS `std.txt`
//! ([`read_std`]) and go where a format has a place for them. Geoid
//! heights and UTC times are computed by the caller (the geoid model and
//! the leap-second table live in `navsync-receivers`) and handed in per
//! point, so this module only formats.
#![warn(missing_docs)]

use std::path::Path;

use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use super::kfgins::NavRecord;
use super::text::{
    LineReader, is_blank_or_comment, parse_f64, parse_seconds_ns, push_fixed, push_u64,
    push_u64_padded, split_fields,
};
use crate::attitude::{Euler, euler_to_dcm};
use crate::earth::{Geodetic, c_ne, ned_offset};
use crate::error::{Diagnostics, Error};
use crate::time::{GpsTime, NS_PER_S, WeekTracker};

/// Output formats of `navsync export`.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum ExportFormat {
    /// GPX 1.1: one track, MSL heights, UTC times, position σ as
    /// extension elements.
    Gpx,
    /// KML 2.2: a track line and a folder of time-stamped points, absolute
    /// (MSL) altitudes.
    Kml,
    /// GeoJSON (RFC 7946): the track and one point per epoch, ellipsoidal
    /// heights.
    GeoJson,
    /// CSV with a header naming each column and its unit; ellipsoidal
    /// heights.
    Csv,
    /// TUM trajectory (`timestamp tx ty tz qx qy qz qw`) in the NED tangent
    /// plane at the first epoch.
    Tum,
}

impl ExportFormat {
    /// The usual file extension.
    pub fn extension(self) -> &'static str {
        match self {
            ExportFormat::Gpx => "gpx",
            ExportFormat::Kml => "kml",
            ExportFormat::GeoJson => "geojson",
            ExportFormat::Csv => "csv",
            ExportFormat::Tum => "tum",
        }
    }
}

/// The solution's standard deviations at one epoch (first nine columns of
/// KF-GINS `std.txt` after the time).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SolutionSd {
    /// Position σ north, east, down (m).
    pub(crate) pos_m: [f64; 3],
    /// Velocity σ north, east, down (m/s).
    pub(crate) vel_mps: [f64; 3],
    /// Attitude σ roll, pitch, yaw (deg).
    pub(crate) att_deg: [f64; 3],
}

/// Reads a KF-GINS `std.txt` (`sow pos×3 vel×3 att×3 …`, at least 10
/// fields; `format_std_line` in `kfgins.rs`). Times are placed in GPS week
/// `week` (KF-GINS files carry none) and followed across a rollover. Bad
/// lines are reported into `diag` and skipped.
pub fn read_std(
    path: &Path,
    week: i64,
    diag: &mut Diagnostics,
) -> Result<Vec<(GpsTime, SolutionSd)>, Error> {
    let mut lines = LineReader::open(path)?;
    let mut weeks = WeekTracker::new(week);
    let mut out: Vec<(GpsTime, SolutionSd)> = Vec::new();
    while let Some((line, line_no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 10] = [b""; 10];
        let nf = split_fields(line, &mut f);
        if nf < 10 {
            diag.push(
                path,
                line_no,
                format!("expected at least 10 fields (sow, position, velocity and attitude σ), found {nf}; line skipped"),
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
        let mut v = [0.0; 9];
        let mut bad = None;
        for k in 0..9 {
            match parse_f64(f[k + 1]) {
                Ok(x) if x >= 0.0 => v[k] = x,
                Ok(x) => {
                    bad = Some(format!("field {}: negative σ {x}; line skipped", k + 2));
                    break;
                }
                Err(e) => {
                    bad = Some(format!("field {}: {e}; line skipped", k + 2));
                    break;
                }
            }
        }
        if let Some(msg) = bad {
            diag.push(path, line_no, msg);
            continue;
        }
        let t = weeks.peek(ns);
        if out.last().is_some_and(|&(l, _)| t <= l) {
            diag.push(
                path,
                line_no,
                format!("time {t} not after the previous line; line skipped"),
            );
            continue;
        }
        let t = weeks.resolve(ns);
        out.push((
            t,
            SolutionSd {
                pos_m: [v[0], v[1], v[2]],
                vel_mps: [v[3], v[4], v[5]],
                att_deg: [v[6], v[7], v[8]],
            },
        ));
    }
    if out.is_empty() {
        return Err(Error::NoData {
            path: path.to_path_buf(),
            msg: "no standard-deviation records (KF-GINS std.txt: sow then 9 or 21 σ)".into(),
        });
    }
    Ok(out)
}

/// σ at `t`: linear interpolation between the bracketing `std.txt` lines
/// (written at a coarser interval than the solution); `None` outside them.
pub fn sd_at(sd: &[(GpsTime, SolutionSd)], t: GpsTime) -> Option<SolutionSd> {
    let i = sd.partition_point(|&(ts, _)| ts < t);
    let (t1, s1) = *sd.get(i)?;
    if t1 == t {
        return Some(s1);
    }
    let (t0, s0) = *sd.get(i.checked_sub(1)?)?;
    let w = t.seconds_since(t0) / t1.seconds_since(t0);
    let lerp = |a: [f64; 3], b: [f64; 3]| std::array::from_fn(|k| a[k] + w * (b[k] - a[k]));
    Some(SolutionSd {
        pos_m: lerp(s0.pos_m, s1.pos_m),
        vel_mps: lerp(s0.vel_mps, s1.vel_mps),
        att_deg: lerp(s0.att_deg, s1.att_deg),
    })
}

/// Keeps the first record of each `every_s`-long bin of GPS time (so with
/// `every_s` = 1 the records on whole seconds, plus the very first one).
/// `every_s` ≤ 0 keeps all.
pub fn decimate(recs: &[NavRecord], every_s: f64) -> Vec<NavRecord> {
    let bin_ns = crate::time::seconds_to_ns(every_s);
    if bin_ns <= 0 {
        return recs.to_vec();
    }
    let mut last_bin = None;
    recs.iter()
        .filter(|r| {
            let bin = r.time.ns().div_euclid(bin_ns);
            let keep = last_bin != Some(bin);
            last_bin = Some(bin);
            keep
        })
        .copied()
        .collect()
}

/// Why a record's position is not on the earth (latitude outside ±90°,
/// longitude outside ±180°, a non-finite value), or `None`: such a point
/// would be drawn (GPX 1.1 `latType`/`lonType`, RFC 7946 §3.1.1) where no
/// vehicle was, so it is not exported.
pub fn off_earth(r: &NavRecord) -> Option<String> {
    let (lat, lon, h) = (r.lat_deg, r.lon_deg, r.h_m);
    if !(lat.is_finite() && lon.is_finite() && h.is_finite()) {
        return Some(format!("position {lat}, {lon}, {h} m is not finite"));
    }
    if lat.abs() > 90.0 {
        return Some(format!("latitude {lat}° outside −90…90°"));
    }
    if lon.abs() > 180.0 {
        return Some(format!("longitude {lon}° outside −180…180°"));
    }
    None
}

/// One epoch to export, with what the caller could add to it.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ExportPoint {
    /// The solution record (nav format).
    pub rec: NavRecord,
    /// Its standard deviations from `std.txt` ([`sd_at`]); `None` when
    /// unknown (outside the `std.txt` span, or no file).
    pub sd: Option<SolutionSd>,
    /// Geoid separation N (m): MSL height = h − N (GPX `<ele>`, KML
    /// `altitudeMode` absolute are heights above mean sea level).
    pub geoid_m: Option<f64>,
    /// UTC of the epoch as Unix ns (`None` when the file has no week).
    pub utc_unix_ns: Option<i64>,
}

/// What a file says about itself.
#[derive(Clone, Debug, Default)]
pub struct ExportMeta {
    /// A name for the track (e.g. the input file name).
    pub name: String,
    /// Text for the `creator`/`generator` fields.
    pub creator: String,
}

/// Namespace of navsync's GPX extension elements (σ in metres: GPX's own
/// `<hdop>`/`<vdop>` are dilutions of precision, not lengths).
pub(crate) const GPX_EXTENSION_NS: &str = "urn:navsync:gpx:sd:1";

/// Writes `points` in `format` into `out`.
pub fn write(format: ExportFormat, points: &[ExportPoint], meta: &ExportMeta, out: &mut Vec<u8>) {
    match format {
        ExportFormat::Gpx => write_gpx(points, meta, out),
        ExportFormat::Kml => write_kml(points, meta, out),
        ExportFormat::GeoJson => write_geojson(points, meta, out),
        ExportFormat::Csv => write_csv(points, out),
        ExportFormat::Tum => write_tum(points, out),
    }
}

/// Longitude in [−180, 180) (GPX `longitudeType`; RFC 7946 §4).
fn lon_180(lon_deg: f64) -> f64 {
    (lon_deg + 180.0).rem_euclid(360.0) - 180.0
}

/// ISO 8601 UTC (`xsd:dateTime` with `Z`, millisecond precision).
fn push_utc(out: &mut Vec<u8>, unix_ns: i64) {
    let ms = (unix_ns as f64 / 1e6).round() as i64;
    let (days, ms_of_day) = (ms.div_euclid(86_400_000), ms.rem_euclid(86_400_000));
    let (y, m, d) = civil_from_days(days);
    push_u64_padded(out, y.max(0) as u64, 4);
    out.push(b'-');
    push_u64_padded(out, m as u64, 2);
    out.push(b'-');
    push_u64_padded(out, d as u64, 2);
    out.push(b'T');
    let s = ms_of_day / 1000;
    push_u64_padded(out, (s / 3600) as u64, 2);
    out.push(b':');
    push_u64_padded(out, (s / 60 % 60) as u64, 2);
    out.push(b':');
    push_u64_padded(out, (s % 60) as u64, 2);
    out.push(b'.');
    push_u64_padded(out, (ms_of_day % 1000) as u64, 3);
    out.push(b'Z');
}

/// Days since 1970-01-01 → civil date (H. Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + (m <= 2) as i64, m, d)
}

fn push_str(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(s.as_bytes());
}

/// XML character data / attribute value with `& < > "` escaped.
fn push_xml_text(out: &mut Vec<u8>, s: &str) {
    for c in s.chars() {
        match c {
            '&' => push_str(out, "&amp;"),
            '<' => push_str(out, "&lt;"),
            '>' => push_str(out, "&gt;"),
            '"' => push_str(out, "&quot;"),
            c if (c as u32) < 0x20 && c != '\n' && c != '\t' => {}
            c => {
                let mut b = [0u8; 4];
                push_str(out, c.encode_utf8(&mut b));
            }
        }
    }
}

/// JSON string literal.
fn push_json_str(out: &mut Vec<u8>, s: &str) {
    out.push(b'"');
    for c in s.chars() {
        match c {
            '"' => push_str(out, "\\\""),
            '\\' => push_str(out, "\\\\"),
            c if (c as u32) < 0x20 => push_str(out, &format!("\\u{:04x}", c as u32)),
            c => {
                let mut b = [0u8; 4];
                push_str(out, c.encode_utf8(&mut b));
            }
        }
    }
    out.push(b'"');
}

/// Height for GPX `<ele>` and KML absolute altitude: MSL when the geoid is
/// known, else ellipsoidal.
fn msl_or_h(p: &ExportPoint) -> f64 {
    p.rec.h_m - p.geoid_m.unwrap_or(0.0)
}

/// GPX 1.1 (Topografix `gpx.xsd`): one track of `<trkpt>` with `<ele>`
/// (MSL height), `<time>` (UTC), `<geoidheight>` (N, "as in NMEA GGA") and
/// the position σ in metres as extension elements (`sd_n_m`, `sd_e_m`,
/// `sd_d_m` in [`GPX_EXTENSION_NS`]), allowed by `extensionsType`
/// (`xsd:any namespace="##other"`).
pub(crate) fn write_gpx(points: &[ExportPoint], meta: &ExportMeta, out: &mut Vec<u8>) {
    push_str(out, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    push_str(out, "<gpx version=\"1.1\" creator=\"");
    push_xml_text(out, &meta.creator);
    push_str(
        out,
        "\" xmlns=\"http://www.topografix.com/GPX/1/1\" xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xmlns:navsync=\"",
    );
    push_str(out, GPX_EXTENSION_NS);
    push_str(
        out,
        "\" xsi:schemaLocation=\"http://www.topografix.com/GPX/1/1 http://www.topografix.com/GPX/1/1/gpx.xsd\">\n",
    );
    push_str(out, "<metadata><name>");
    push_xml_text(out, &meta.name);
    push_str(
        out,
        "</name><desc>navsync solution; ele = height above mean sea level (EGM96) where geoidheight is given, else ellipsoidal; navsync:sd_*_m = position standard deviation (m)</desc></metadata>\n<trk><name>",
    );
    push_xml_text(out, &meta.name);
    push_str(out, "</name><trkseg>\n");
    for p in points {
        push_str(out, "<trkpt lat=\"");
        push_fixed(out, p.rec.lat_deg, 9);
        push_str(out, "\" lon=\"");
        push_fixed(out, lon_180(p.rec.lon_deg), 9);
        push_str(out, "\"><ele>");
        push_fixed(out, msl_or_h(p), 4);
        push_str(out, "</ele>");
        if let Some(ns) = p.utc_unix_ns {
            push_str(out, "<time>");
            push_utc(out, ns);
            push_str(out, "</time>");
        }
        if let Some(n) = p.geoid_m {
            push_str(out, "<geoidheight>");
            push_fixed(out, n, 4);
            push_str(out, "</geoidheight>");
        }
        if let Some(sd) = &p.sd {
            push_str(out, "<extensions>");
            for (name, v) in ["sd_n_m", "sd_e_m", "sd_d_m"].iter().zip(sd.pos_m) {
                push_str(out, "<navsync:");
                push_str(out, name);
                out.push(b'>');
                push_fixed(out, v, 4);
                push_str(out, "</navsync:");
                push_str(out, name);
                out.push(b'>');
            }
            push_str(out, "</extensions>");
        }
        push_str(out, "</trkpt>\n");
    }
    push_str(out, "</trkseg></trk>\n</gpx>\n");
}

/// KML 2.2 (OGC 07-147r2): a `LineString` track and a `Folder` of point
/// `Placemark`s, each with its `TimeStamp` (UTC), a `description` with the
/// σ for the viewer's balloon and the same values as `ExtendedData`.
/// Altitudes are `absolute` (above sea level, §16.1 altitudeModeEnumType).
pub(crate) fn write_kml(points: &[ExportPoint], meta: &ExportMeta, out: &mut Vec<u8>) {
    push_str(
        out,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<kml xmlns=\"http://www.opengis.net/kml/2.2\">\n<Document>\n<name>",
    );
    push_xml_text(out, &meta.name);
    push_str(out, "</name>\n<description>");
    push_xml_text(out, &meta.creator);
    push_str(
        out,
        "</description>\n<Style id=\"track\"><LineStyle><color>ff0000ff</color><width>3</width></LineStyle></Style>\n<Style id=\"epoch\"><IconStyle><scale>0.4</scale></IconStyle></Style>\n",
    );
    push_str(
        out,
        "<Placemark><name>track</name><styleUrl>#track</styleUrl><LineString><altitudeMode>absolute</altitudeMode><coordinates>\n",
    );
    let push_coord = |out: &mut Vec<u8>, p: &ExportPoint| {
        push_fixed(out, lon_180(p.rec.lon_deg), 9);
        out.push(b',');
        push_fixed(out, p.rec.lat_deg, 9);
        out.push(b',');
        push_fixed(out, msl_or_h(p), 4);
    };
    for p in points {
        push_coord(out, p);
        out.push(b'\n');
    }
    push_str(
        out,
        "</coordinates></LineString></Placemark>\n<Folder><name>epochs</name>\n",
    );
    for p in points {
        push_str(out, "<Placemark><name>");
        p.rec.time.write_sow(out);
        push_str(out, "</name><description>");
        push_str(out, "week ");
        push_u64(out, p.rec.week.max(0) as u64);
        push_str(out, " sow ");
        p.rec.time.write_sow(out);
        push_str(out, "; h ");
        push_fixed(out, p.rec.h_m, 3);
        push_str(out, " m (ellipsoid)");
        if let Some(sd) = &p.sd {
            push_str(out, "; σ N/E/D ");
            for (k, v) in sd.pos_m.iter().enumerate() {
                if k > 0 {
                    out.push(b'/');
                }
                push_fixed(out, *v, 3);
            }
            push_str(out, " m");
        }
        push_str(out, "</description>");
        if let Some(ns) = p.utc_unix_ns {
            push_str(out, "<TimeStamp><when>");
            push_utc(out, ns);
            push_str(out, "</when></TimeStamp>");
        }
        push_str(out, "<styleUrl>#epoch</styleUrl>");
        if let Some(sd) = &p.sd {
            push_str(out, "<ExtendedData>");
            for (name, v) in ["sd_n_m", "sd_e_m", "sd_d_m"].iter().zip(sd.pos_m) {
                push_str(out, "<Data name=\"");
                push_str(out, name);
                push_str(out, "\"><value>");
                push_fixed(out, v, 4);
                push_str(out, "</value></Data>");
            }
            push_str(out, "</ExtendedData>");
        }
        push_str(
            out,
            "<Point><altitudeMode>absolute</altitudeMode><coordinates>",
        );
        push_coord(out, p);
        push_str(out, "</coordinates></Point></Placemark>\n");
    }
    push_str(out, "</Folder>\n</Document>\n</kml>\n");
}

/// Names of the 9 σ columns/properties, with units.
pub(crate) const SD_NAMES: [&str; 9] = [
    "sd_n_m",
    "sd_e_m",
    "sd_d_m",
    "sd_vn_mps",
    "sd_ve_mps",
    "sd_vd_mps",
    "sd_roll_deg",
    "sd_pitch_deg",
    "sd_yaw_deg",
];

/// Names of the nav columns after week and sow, with units.
pub(crate) const NAV_NAMES: [&str; 9] = [
    "lat_deg",
    "lon_deg",
    "h_m",
    "vn_mps",
    "ve_mps",
    "vd_mps",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
];

/// Decimals of the nav values as the nav format prints them.
const NAV_DECIMALS: [usize; 9] = [12, 12, 6, 9, 9, 9, 9, 9, 9];
/// Decimals of the σ as `std.txt` prints them.
const SD_DECIMALS: [usize; 9] = [6, 6, 6, 6, 6, 6, 8, 8, 8];

fn nav_values(r: &NavRecord) -> [f64; 9] {
    [
        r.lat_deg,
        r.lon_deg,
        r.h_m,
        r.vel[0],
        r.vel[1],
        r.vel[2],
        r.att_deg[0],
        r.att_deg[1],
        r.att_deg[2],
    ]
}

fn sd_values(s: &SolutionSd) -> [f64; 9] {
    [
        s.pos_m[0],
        s.pos_m[1],
        s.pos_m[2],
        s.vel_mps[0],
        s.vel_mps[1],
        s.vel_mps[2],
        s.att_deg[0],
        s.att_deg[1],
        s.att_deg[2],
    ]
}

/// CSV (RFC 4180, for pandas and spreadsheets): a header naming each
/// column with its unit, `week,sow_s,lat_deg,…,yaw_deg,sd_n_m,…,sd_yaw_deg`
/// (heights ellipsoidal; σ fields empty where `std.txt` has none), values at
/// the precision of the nav and std files.
pub(crate) fn write_csv(points: &[ExportPoint], out: &mut Vec<u8>) {
    push_str(out, "week,sow_s");
    for n in NAV_NAMES.iter().chain(&SD_NAMES) {
        out.push(b',');
        push_str(out, n);
    }
    out.push(b'\n');
    for p in points {
        push_u64(out, p.rec.week.max(0) as u64);
        out.push(b',');
        p.rec.time.write_sow(out);
        for (v, d) in nav_values(&p.rec).iter().zip(NAV_DECIMALS) {
            out.push(b',');
            push_fixed(out, *v, d);
        }
        match &p.sd {
            Some(sd) => {
                for (v, d) in sd_values(sd).iter().zip(SD_DECIMALS) {
                    out.push(b',');
                    push_fixed(out, *v, d);
                }
            }
            None => out.extend_from_slice(&[b','; 9]),
        }
        out.push(b'\n');
    }
}

/// GeoJSON (RFC 7946): a `FeatureCollection` whose first feature is the
/// track (`LineString`) and then one `Point` per epoch with the nav values
/// and σ (null where unknown) as properties. Positions are `[lon, lat, h]`,
/// h above the WGS 84 ellipsoid (§4), longitudes in [−180, 180).
pub(crate) fn write_geojson(points: &[ExportPoint], meta: &ExportMeta, out: &mut Vec<u8>) {
    let push_pos = |out: &mut Vec<u8>, r: &NavRecord| {
        out.push(b'[');
        push_fixed(out, lon_180(r.lon_deg), 12);
        out.push(b',');
        push_fixed(out, r.lat_deg, 12);
        out.push(b',');
        push_fixed(out, r.h_m, 6);
        out.push(b']');
    };
    push_str(out, "{\"type\":\"FeatureCollection\",\"features\":[\n");
    push_str(out, "{\"type\":\"Feature\",\"properties\":{\"name\":");
    push_json_str(out, &meta.name);
    push_str(out, ",\"generator\":");
    push_json_str(out, &meta.creator);
    push_str(
        out,
        "},\"geometry\":{\"type\":\"LineString\",\"coordinates\":[",
    );
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            out.push(b',');
        }
        push_pos(out, &p.rec);
    }
    push_str(out, "]}}");
    for p in points {
        push_str(out, ",\n{\"type\":\"Feature\",\"properties\":{\"week\":");
        push_u64(out, p.rec.week.max(0) as u64);
        push_str(out, ",\"sow_s\":");
        p.rec.time.write_sow(out);
        if let Some(ns) = p.utc_unix_ns {
            push_str(out, ",\"time_utc\":\"");
            push_utc(out, ns);
            out.push(b'"');
        }
        for (k, (v, d)) in nav_values(&p.rec)
            .iter()
            .zip(NAV_DECIMALS)
            .enumerate()
            .skip(3)
        {
            push_str(out, ",\"");
            push_str(out, NAV_NAMES[k]);
            push_str(out, "\":");
            push_fixed(out, *v, d);
        }
        let sd = p.sd.as_ref().map(sd_values);
        for (k, name) in SD_NAMES.iter().enumerate() {
            push_str(out, ",\"");
            push_str(out, name);
            push_str(out, "\":");
            match sd {
                Some(s) => push_fixed(out, s[k], SD_DECIMALS[k]),
                None => push_str(out, "null"),
            }
        }
        push_str(out, "},\"geometry\":{\"type\":\"Point\",\"coordinates\":");
        push_pos(out, &p.rec);
        push_str(out, "}}");
    }
    push_str(out, "\n]}\n");
}

/// TUM trajectory (TUM RGB-D benchmark format, read by `evo_traj tum`):
/// `timestamp tx ty tz qx qy qz qw` per line. Frame: NED tangent plane at
/// the first epoch (x north, y east, z down, metres, exact through ECEF);
/// the quaternion rotates body (FRD) into that frame, C_b^{n0} =
/// C_e^{n0} C_n^e(p) C_b^n(p), so it stays consistent with the positions
/// far from the origin. Timestamp: GPS seconds since 1980-01-06 (the
/// seconds of week when the nav file's week is 0), to the nanosecond.
pub(crate) fn write_tum(points: &[ExportPoint], out: &mut Vec<u8>) {
    let Some(first) = points.first() else {
        return;
    };
    let origin = Geodetic::from_deg(first.rec.lat_deg, first.rec.lon_deg, first.rec.h_m);
    let c_en0 = c_ne(&origin).transpose();
    push_str(
        out,
        "# timestamp tx ty tz qx qy qz qw; navsync export: frame NED at the first epoch (lat ",
    );
    push_fixed(out, first.rec.lat_deg, 9);
    push_str(out, " deg, lon ");
    push_fixed(out, first.rec.lon_deg, 9);
    push_str(out, " deg, h ");
    push_fixed(out, first.rec.h_m, 4);
    push_str(out, " m), body FRD, time GPS s\n");
    for p in points {
        let pos = Geodetic::from_deg(p.rec.lat_deg, p.rec.lon_deg, p.rec.h_m);
        let d: Vector3<f64> = ned_offset(&origin, &pos);
        let [r, pi, y] = p.rec.att_deg;
        let c = c_en0 * c_ne(&pos) * euler_to_dcm(&Euler::from_deg(r, pi, y));
        let mut q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(c));
        if q.w < 0.0 {
            q = UnitQuaternion::new_unchecked(-q.into_inner());
        }
        let ns = p.rec.time.ns();
        push_u64(out, ns.div_euclid(NS_PER_S).max(0) as u64);
        out.push(b'.');
        push_u64_padded(out, ns.rem_euclid(NS_PER_S) as u64, 9);
        for v in [d.x, d.y, d.z] {
            out.push(b' ');
            push_fixed(out, v, 6);
        }
        for v in [q.i, q.j, q.k, q.w] {
            out.push(b' ');
            push_fixed(out, v, 9);
        }
        out.push(b'\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::quat_to_euler;
    use nalgebra::Quaternion;

    fn rec(week: i64, sow: f64, lat: f64, lon: f64, h: f64, att: [f64; 3]) -> NavRecord {
        NavRecord {
            week,
            time: GpsTime::from_week_sow(week, sow),
            lat_deg: lat,
            lon_deg: lon,
            h_m: h,
            vel: [1.25, -2.5, 0.125],
            att_deg: att,
        }
    }

    fn point(r: NavRecord, sd: Option<SolutionSd>) -> ExportPoint {
        ExportPoint {
            rec: r,
            sd,
            geoid_m: None,
            utc_unix_ns: None,
        }
    }

    fn sample() -> Vec<ExportPoint> {
        let sd = SolutionSd {
            pos_m: [0.011, 0.012, 0.031],
            vel_mps: [0.001, 0.002, 0.003],
            att_deg: [0.01, 0.02, 0.3],
        };
        (0..20)
            .map(|k| {
                let r = rec(
                    2300,
                    100000.005 + 0.5 * k as f64,
                    30.444787370123 + 1e-5 * k as f64,
                    114.471863204789 - 2e-5 * k as f64,
                    20.9 + 0.01 * k as f64,
                    [0.5, -1.25, 45.0 + k as f64],
                );
                point(r, (k % 3 != 0).then_some(sd))
            })
            .collect()
    }

    #[test]
    fn csv_round_trips_to_printed_precision() {
        let pts = sample();
        let mut out = Vec::new();
        write_csv(&pts, &mut out);
        let text = String::from_utf8(out).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(header.len(), 20);
        assert_eq!(&header[..4], ["week", "sow_s", "lat_deg", "lon_deg"]);
        assert_eq!(header[11], "sd_n_m");
        let mut n = 0;
        for (line, p) in lines.zip(&pts) {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), 20, "{line}");
            assert_eq!(f[0].parse::<i64>().unwrap(), p.rec.week);
            let sow_ns = parse_seconds_ns(f[1].as_bytes()).unwrap();
            assert_eq!(GpsTime::from_week_ns(p.rec.week, sow_ns), p.rec.time);
            for (k, (v, d)) in nav_values(&p.rec).iter().zip(NAV_DECIMALS).enumerate() {
                let back: f64 = f[2 + k].parse().unwrap();
                assert!(
                    (back - v).abs() <= 0.5 * 10f64.powi(-(d as i32)) * 1.001,
                    "{k}"
                );
            }
            match &p.sd {
                Some(sd) => {
                    for (k, v) in sd_values(sd).iter().enumerate() {
                        let back: f64 = f[11 + k].parse().unwrap();
                        assert!((back - v).abs() < 1e-6, "{k}");
                    }
                }
                None => assert!(f[11..].iter().all(|x| x.is_empty()), "{line}"),
            }
            n += 1;
        }
        assert_eq!(n, pts.len());
    }

    #[test]
    fn geojson_round_trips_and_follows_rfc7946() {
        let mut pts = sample();
        pts[0].rec.lon_deg = 200.0; // east of the antimeridian: written −160
        let mut out = Vec::new();
        write_geojson(
            &pts,
            &ExportMeta {
                name: "a \"quoted\" name".into(),
                creator: "navsync".into(),
            },
            &mut out,
        );
        let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(v["type"], "FeatureCollection");
        let feats = v["features"].as_array().unwrap();
        assert_eq!(feats.len(), pts.len() + 1);
        assert_eq!(feats[0]["geometry"]["type"], "LineString");
        assert_eq!(feats[0]["properties"]["name"], "a \"quoted\" name");
        assert_eq!(
            feats[0]["geometry"]["coordinates"]
                .as_array()
                .unwrap()
                .len(),
            pts.len()
        );
        for (f, p) in feats[1..].iter().zip(&pts) {
            let c = f["geometry"]["coordinates"].as_array().unwrap();
            let lon = c[0].as_f64().unwrap();
            assert!((-180.0..180.0).contains(&lon));
            assert!((lon_180(p.rec.lon_deg) - lon).abs() < 1e-12);
            assert!((c[1].as_f64().unwrap() - p.rec.lat_deg).abs() < 1e-12);
            assert!((c[2].as_f64().unwrap() - p.rec.h_m).abs() < 1e-6);
            let pr = &f["properties"];
            assert_eq!(pr["week"], p.rec.week);
            let sow = pr["sow_s"].as_f64().unwrap();
            assert!((sow - p.rec.time.sow()).abs() < 1e-9);
            assert!((pr["yaw_deg"].as_f64().unwrap() - p.rec.att_deg[2]).abs() < 1e-9);
            match &p.sd {
                Some(sd) => assert!((pr["sd_d_m"].as_f64().unwrap() - sd.pos_m[2]).abs() < 1e-6),
                None => assert!(pr["sd_d_m"].is_null()),
            }
        }
        assert!((lon_180(200.0) + 160.0).abs() < 1e-12);
    }

    #[test]
    fn tum_is_ned_at_first_epoch_with_body_to_frame_quaternion() {
        let pts = sample();
        let mut out = Vec::new();
        write_tum(&pts, &mut out);
        let text = String::from_utf8(out).unwrap();
        let rows: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.split(' ').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), pts.len());
        // First epoch: origin, attitude as in the file.
        assert_eq!(&rows[0][1..4], &[0.0, 0.0, 0.0]);
        let q0 = UnitQuaternion::from_quaternion(Quaternion::new(
            rows[0][7], rows[0][4], rows[0][5], rows[0][6],
        ));
        let e = quat_to_euler(&q0).to_deg();
        for k in 0..3 {
            assert!((e[k] - pts[0].rec.att_deg[k]).abs() < 1e-6, "{e:?}");
        }
        // Timestamp = GPS seconds since the epoch.
        assert!((rows[0][0] - (2300.0 * 604_800.0 + 100000.005)).abs() < 1e-6);
        // Later epochs: north/east/down offsets from the geodetic differences.
        let last = rows.last().unwrap();
        let dn = 19.0 * 1e-5_f64.to_radians() * 6_335_500.0; // ~ R_M at 30°
        assert!((last[1] - dn).abs() / dn < 0.01, "{}", last[1]);
        assert!(last[2] < 0.0, "went west: {}", last[2]);
        assert!((last[3] + 0.19).abs() < 1e-3, "went up 0.19 m: {}", last[3]);
        for r in &rows {
            let n = (r[4] * r[4] + r[5] * r[5] + r[6] * r[6] + r[7] * r[7]).sqrt();
            assert!((n - 1.0).abs() < 1e-8 && r[7] >= 0.0);
        }
    }

    #[test]
    fn std_is_read_interpolated_and_bad_lines_reported() {
        let p = crate::testfiles::temp_file(
            "export",
            "std.txt",
            "100.0 1 2 3 0.1 0.2 0.3 0.01 0.02 0.03 9 9 9\n\
             101.0 3 2 1\n\
             101.0 3 2 1 0.3 0.2 0.1 0.03 0.02 0.01\n\
             101.5 3 2 -1 0.3 0.2 0.1 0.03 0.02 0.01\n\
             100.5 3 2 1 0.3 0.2 0.1 0.03 0.02 0.01\n",
        );
        let mut d = Diagnostics::default();
        let sd = read_std(&p, 2300, &mut d).unwrap();
        assert_eq!(sd.len(), 2);
        assert_eq!(d.total, 3, "{:?}", d.items);
        let t = |s| GpsTime::from_week_sow(2300, s);
        let mid = sd_at(&sd, t(100.25)).unwrap();
        assert!((mid.pos_m[0] - 1.5).abs() < 1e-12 && (mid.pos_m[2] - 2.5).abs() < 1e-12);
        assert_eq!(sd_at(&sd, t(101.0)).unwrap().att_deg, [0.03, 0.02, 0.01]);
        assert!(sd_at(&sd, t(99.9)).is_none() && sd_at(&sd, t(101.1)).is_none());
    }

    #[test]
    fn decimate_keeps_first_of_each_bin() {
        let recs: Vec<NavRecord> = (1..=1000)
            .map(|k| {
                rec(
                    2300,
                    100000.0 + 0.005 * k as f64,
                    30.0,
                    114.0,
                    0.0,
                    [0.0; 3],
                )
            })
            .collect();
        let kept = decimate(&recs, 1.0);
        let sows: Vec<f64> = kept.iter().map(|r| r.time.sow()).collect();
        assert_eq!(
            sows,
            vec![100000.005, 100001.0, 100002.0, 100003.0, 100004.0, 100005.0]
        );
        assert_eq!(decimate(&recs, 0.0).len(), 1000);
    }

    #[test]
    fn utc_text_is_iso8601() {
        let mut out = Vec::new();
        // 2026-12-01T23:39:11.005Z
        push_utc(&mut out, 1_796_168_351_005_000_000);
        assert_eq!(String::from_utf8(out).unwrap(), "2026-12-01T23:39:11.005Z");
    }
}
