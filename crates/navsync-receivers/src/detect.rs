//! What kind of log a file is, from its content (not its name): a raw rig
//! log, a receiver stream (UBX, NMEA), a ROS 1 or ROS 2 bag, a comma2k19 GNSS CSV,
//! a rate-form IMU CSV, or KF-GINS increment / fix files. Used by
//! `navsync process` to route each input to `sync` or `convert`.

use std::io::Read;
use std::path::Path;

use navsync::error::Error;

use crate::stream::{gpsd_log_header_len, read_all};

/// The kinds of input navsync reads.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub enum FileKind {
    /// `rig-log v1` (FORMATS.md §2): IMU, GNSS and 1PPS on a logger counter.
    RigLog,
    /// u-blox UBX stream (possibly mixed with NMEA).
    Ubx,
    /// NMEA 0183 stream.
    Nmea,
    /// ROS 2 bag (MCAP).
    Mcap,
    /// ROS 1 bag (format 2.0).
    Ros1Bag,
    /// comma2k19 `gnss_ublox.csv`.
    CommaGnss,
    /// Rate-form IMU CSV: time s, gyro xyz rad/s, accel xyz m/s².
    RateCsv,
    /// KF-GINS IMU increments (7 columns).
    KfginsImu,
    /// KF-GINS GNSS fixes (7 or 13 columns).
    KfginsGnss,
    /// PX4 ULog flight log (IMU and GPS on the autopilot's boot clock).
    Ulog,
    /// ArduPilot DataFlash `.BIN` log (IMU and GNSS on the boot clock).
    DataFlash,
}

impl FileKind {
    /// Whether the file holds GNSS fixes.
    pub fn has_gnss(self) -> bool {
        matches!(
            self,
            FileKind::RigLog
                | FileKind::Ubx
                | FileKind::Nmea
                | FileKind::Mcap
                | FileKind::Ros1Bag
                | FileKind::CommaGnss
                | FileKind::KfginsGnss
                | FileKind::Ulog
                | FileKind::DataFlash
        )
    }

    /// An autopilot log: IMU and fix arrivals on one boot clock, converted
    /// into a rig log (`convert/rig.csv`) that `sync` puts on GPS time.
    pub fn is_autopilot_log(self) -> bool {
        matches!(self, FileKind::DataFlash | FileKind::Ulog)
    }

    pub fn describe(self) -> &'static str {
        match self {
            FileKind::RigLog => "rig log (rig-log v1)",
            FileKind::Ubx => "u-blox UBX receiver log",
            FileKind::Nmea => "NMEA 0183 receiver log",
            FileKind::Mcap => "ROS 2 bag (MCAP)",
            FileKind::Ros1Bag => "ROS 1 bag (format 2.0)",
            FileKind::CommaGnss => "comma2k19 GNSS CSV",
            FileKind::RateCsv => "rate-form IMU CSV",
            FileKind::KfginsImu => "KF-GINS IMU increments",
            FileKind::KfginsGnss => "KF-GINS GNSS fixes",
            FileKind::Ulog => "PX4 ULog flight log",
            FileKind::DataFlash => "ArduPilot DataFlash log (.BIN)",
        }
    }
}

/// What an unknown file should have been.
pub(crate) const EXPECTED: &str = "expected a rig log ('# rig-log v1' first line), a u-blox UBX or \
    NMEA 0183 receiver log, a ROS 2 .mcap bag, a ROS 1 .bag, a PX4 .ulg log, an ArduPilot DataFlash .BIN log, a comma2k19 gnss_ublox.csv, an IMU log \
    (lines of 'time gyro_x gyro_y gyro_z acc_x acc_y acc_z' in s, rad/s, m/s²) or KF-GINS \
    imu/gnss text files";

/// Bytes read to decide.
const SNIFF_BYTES: usize = 256 * 1024;

/// Reads the start of `path` and says what it is.
pub fn detect(path: &Path) -> Result<FileKind, Error> {
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut buf = Vec::with_capacity(SNIFF_BYTES);
    f.by_ref()
        .take(SNIFF_BYTES as u64)
        .read_to_end(&mut buf)
        .map_err(|e| Error::io(path, e))?;
    detect_bytes(&buf).ok_or_else(|| {
        Error::config(
            path,
            if buf.is_empty() {
                format!("empty file: {EXPECTED}")
            } else {
                format!("unknown file type: {EXPECTED}")
            },
        )
    })
}

/// Whether a UBX log holds a sensor-fusion receiver's fused solution
/// (NAV-PVAT) and no raw IMU data (ESF-RAW / ESF-MEAS), judged on its
/// first megabyte: such a log cannot feed navsync's own INS.
pub fn ubx_fused_without_imu(path: &Path) -> Result<bool, Error> {
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut buf = Vec::new();
    f.by_ref()
        .take(1 << 20)
        .read_to_end(&mut buf)
        .map_err(|e| Error::io(path, e))?;
    let mut r = crate::stream::StreamReader::new();
    r.push(&buf[gpsd_log_header_len(&buf).min(buf.len())..]);
    r.finish();
    let (mut pvat, mut raw) = (0, 0);
    while let Some(ev) = r.next_event() {
        if let crate::stream::EventKind::Ubx(m) = &ev.kind {
            match m {
                crate::ubx::UbxMessage::NavPvat(_) => pvat += 1,
                crate::ubx::UbxMessage::EsfRaw(_) | crate::ubx::UbxMessage::EsfMeas(_) => raw += 1,
                _ => {}
            }
        }
    }
    Ok(pvat > 0 && raw == 0)
}

/// [`detect`] on the first bytes of a file.
pub(crate) fn detect_bytes(buf: &[u8]) -> Option<FileKind> {
    if buf.starts_with(b"\x89MCAP") {
        return Some(FileKind::Mcap);
    }
    if buf.starts_with(&crate::ulog::MAGIC) {
        return Some(FileKind::Ulog);
    }
    if buf.starts_with(crate::ros1::MAGIC) {
        return Some(FileKind::Ros1Bag);
    }
    if crate::dataflash::looks_like_dataflash(buf) {
        return Some(FileKind::DataFlash);
    }
    let first_line = buf
        .split(|b| *b == b'\n')
        .map(|l| l.trim_ascii())
        .find(|l| !l.is_empty());
    if first_line == Some(b"# rig-log v1".as_slice()) {
        return Some(FileKind::RigLog);
    }
    // Receiver streams: frames the stream reader decodes (after a gpsd
    // header, if any).
    let body = &buf[gpsd_log_header_len(buf).min(buf.len())..];
    let (_, stats) = read_all(body, 0);
    if stats.ubx_messages >= 2 {
        return Some(FileKind::Ubx);
    }
    if stats.nmea_messages >= 2 {
        return Some(FileKind::Nmea);
    }
    detect_text(buf)
}

/// Numeric text files, told apart by their columns and magnitudes.
fn detect_text(buf: &[u8]) -> Option<FileKind> {
    let text = std::str::from_utf8(buf).ok().or_else(|| {
        // A cut multi-byte character at the end of the sample.
        let end = buf.iter().rposition(|b| *b == b'\n')?;
        std::str::from_utf8(&buf[..end]).ok()
    })?;
    if text
        .lines()
        .take(5)
        .any(|l| l.starts_with('#') && l.contains("utc_unix_ms") && l.contains("lat"))
    {
        return Some(FileKind::CommaGnss);
    }
    let rows: Vec<Vec<f64>> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .take(200)
        .map(|l| {
            l.split(|c: char| c == ',' || c.is_ascii_whitespace())
                .filter(|f| !f.is_empty())
                .map(|f| f.parse::<f64>().unwrap_or(f64::NAN))
                .collect()
        })
        // A file may end in a cut line.
        .filter(|r: &Vec<f64>| r.iter().all(|x| x.is_finite()))
        .collect();
    if rows.len() < 2 {
        return None;
    }
    let n = rows[0].len();
    if !rows.iter().all(|r| r.len() == n) {
        return None;
    }
    let median = |mut v: Vec<f64>| -> f64 {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let dt = median(rows.windows(2).map(|w| w[1][0] - w[0][0]).collect());
    if !(dt.is_finite() && dt > 0.0) {
        return None;
    }
    match n {
        7 => {
            // comma2k19 GNSS: field 5 is the fix's UTC time in Unix ms.
            if rows.iter().all(|r| r[4] > 1e11) {
                return Some(FileKind::CommaGnss);
            }
            // Specific force at rest or driving is about g: a rate file's
            // accelerometer columns have a norm of metres per second²,
            // an increment file's of g·dt (≈ 0.05 m/s at 200 Hz).
            let acc = median(
                rows.iter()
                    .map(|r| (r[4] * r[4] + r[5] * r[5] + r[6] * r[6]).sqrt())
                    .collect(),
            );
            let gyro = median(
                rows.iter()
                    .map(|r| (r[1] * r[1] + r[2] * r[2] + r[3] * r[3]).sqrt())
                    .collect(),
            );
            if (2.0..60.0).contains(&acc) && gyro < 20.0 && dt < 0.1 {
                return Some(FileKind::RateCsv);
            }
            // Increments: g·dt matches the sampling interval.
            if dt < 0.1 && (acc / (9.8 * dt) - 1.0).abs() < 0.8 && gyro < 1.0 {
                return Some(FileKind::KfginsImu);
            }
            if is_fixes(&rows) {
                return Some(FileKind::KfginsGnss);
            }
            None
        }
        13 if is_fixes(&rows) => Some(FileKind::KfginsGnss),
        _ => None,
    }
}

/// `sow lat lon h …` rows with plausible coordinates and positive σ.
fn is_fixes(rows: &[Vec<f64>]) -> bool {
    rows.iter().all(|r| {
        (0.0..=604_800.0).contains(&r[0])
            && r[1].abs() <= 90.0
            && r[2].abs() <= 180.0
            && r[3].abs() < 1e5
    }) && rows.iter().all(|r| {
        // σ columns: 5–7 (7 columns, or the Matlab order) or 8–10 (C++).
        r[4..7].iter().all(|s| *s > 0.0) || r.get(7..10).is_some_and(|s| s.iter().all(|x| *x > 0.0))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_by_content() {
        assert_eq!(
            detect_bytes(b"# rig-log v1\n# counter_hz: 1000000\nimu,1,0,0,0,0,0,-9.8\n"),
            Some(FileKind::RigLog)
        );
        let nmea = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n\
$GPGGA,123520,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*4D\r\n";
        assert_eq!(detect_bytes(nmea), Some(FileKind::Nmea));
        let rate = b"# t gyro accel\n0.000 0.01 0.0 0.0 0.1 0.0 -9.8\n0.005 0.01 0.0 0.0 0.1 0.0 -9.8\n0.010 0.01 0.0 0.0 0.1 0.0 -9.8\n";
        assert_eq!(detect_bytes(rate), Some(FileKind::RateCsv));
        let inc = b"100.005 1e-5 0 0 0.0005 0 -0.049\n100.010 1e-5 0 0 0.0005 0 -0.049\n100.015 1e-5 0 0 0.0005 0 -0.049\n";
        assert_eq!(detect_bytes(inc), Some(FileKind::KfginsImu));
        let gnss =
            b"100.0 30.44 114.47 20.9 0.02 0.02 0.03\n101.0 30.44 114.47 20.9 0.02 0.02 0.03\n";
        assert_eq!(detect_bytes(gnss), Some(FileKind::KfginsGnss));
        let comma = b"# t_boot_s_received,lat_deg,lon_deg,speed_mps,utc_unix_ms,alt_m,bearing_deg\n46408.65,37.72,-122.47,7.8,1533226488299,33.37,2.1\n46408.74,37.72,-122.47,7.9,1533226488399,33.35,2.2\n";
        assert_eq!(detect_bytes(comma), Some(FileKind::CommaGnss));
        assert_eq!(detect_bytes(b"hello world\nthis is text\n"), None);
        assert_eq!(detect_bytes(b""), None);
        assert_eq!(detect_bytes(b"\x89MCAP0\r\n"), Some(FileKind::Mcap));
        assert_eq!(
            detect_bytes(b"ULog\x01\x12\x35\x01\0\0\0\0\0\0\0\0"),
            Some(FileKind::Ulog)
        );
        assert_eq!(
            detect_bytes(b"#ROSBAG V2.0\n\x45\0\0\0"),
            Some(FileKind::Ros1Bag)
        );
    }
}
