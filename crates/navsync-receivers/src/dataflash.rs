//! ArduPilot DataFlash `.BIN` logs: the self-describing binary log of
//! ArduPilot autopilots, read into IMU samples on the boot clock, GNSS
//! fixes with both their GPS time and their arrival boot time, and the
//! autopilot's own estimate.
//!
//! Layout (ArduPilot `libraries/AP_Logger/LogStructure.h`; pymavlink
//! `DFReader.py`): every message starts with the bytes `0xA3 0x95`
//! (`HEAD_BYTE1`, `HEAD_BYTE2`) and a type byte. Type 128 (`FMT`,
//! `struct log_Format`, 89 bytes) describes another type: its id, its full
//! length (header included), a 4-character name, a 16-character format
//! string and 64 characters of comma-separated labels. The format
//! characters and their sizes are those of the comment at the top of
//! LogStructure.h ([`field_size`]); `c C e E` are integers 100× the value,
//! `L` latitude/longitude in 1e-7 degrees (DFReader scales them the same
//! way).
//!
//! Two eras of message layouts are read, by their labels:
//! - ArduCopter ≤ 3.3 (2014): `TimeMS` (boot ms); `GPS`/`GPS2` with
//!   `TimeMS` = GPS ms of week, `Week`, and `T` = boot ms at arrival; σ
//!   from `UBX3` (`hAcc`, `vAcc`, `sAcc`);
//! - current (`libraries/AP_GPS/LogStructure.h`): `TimeUS` (boot µs);
//!   `GPS` with `I` (instance), `GMS`, `GWk`; σ from `GPA` (`HAcc`,
//!   `VAcc`, `SAcc`) whose `SMS` is the boot ms the fix arrived; IMU
//!   instances either as `IMU`/`IMU2`/`IMU3` or as one `IMU` with `I`.
//!
//! Robustness: bytes between messages are skipped to the next header and
//! reported with their offset; a message of a type no `FMT` described is
//! counted and skipped to the next header; an `FMT` whose format string
//! does not add up to its length, or has an unknown character, is reported
//! and its type left undescribed; a last message cut short is reported.
//! Nothing allocates from a length in the file beyond the file itself.

use std::collections::BTreeMap;
use std::path::Path;

use navsync::error::Diagnostics;

/// First two bytes of every message (LogStructure.h `HEAD_BYTE1/2`).
pub const HEAD: [u8; 2] = [0xA3, 0x95];
/// Type id of `FMT` (LogStructure.h `LOG_FORMAT_MSG`).
pub const FMT_TYPE: u8 = 128;
/// Full length of an `FMT` message: header 3 + type 1 + length 1 + name 4
/// + format 16 + labels 64 (`struct log_Format`).
pub const FMT_LEN: usize = 89;

/// Bytes of one field of format character `c` (LogStructure.h, "Format
/// characters in the format string for binary log messages"); `None` for
/// a character it does not define.
pub fn field_size(c: u8) -> Option<usize> {
    Some(match c {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' => 2,
        b'i' | b'I' | b'f' | b'e' | b'E' | b'L' | b'n' => 4,
        b'd' | b'q' | b'Q' => 8,
        b'N' => 16,
        b'Z' | b'a' => 64,
        _ => return None,
    })
}

/// One message layout, from an `FMT` message.
#[derive(Clone, Debug, PartialEq)]
pub struct MessageFormat {
    pub type_id: u8,
    /// Full length of a message of this type, header included.
    pub length: usize,
    pub name: String,
    pub format: Vec<u8>,
    pub labels: Vec<String>,
    /// Offset of each field in the payload (after the 3-byte header).
    offsets: Vec<usize>,
}

/// Text of a fixed-size, NUL-padded character field.
fn fixed_str(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

impl MessageFormat {
    /// The layout an `FMT` payload (86 bytes after the header) describes,
    /// or why it cannot be used.
    pub fn from_fmt_payload(p: &[u8]) -> Result<Self, String> {
        if p.len() < FMT_LEN - 3 {
            return Err(format!("FMT payload of {} bytes, expected 86", p.len()));
        }
        let type_id = p[0];
        let length = p[1] as usize;
        let name = fixed_str(&p[2..6]);
        let format = {
            let f = &p[6..22];
            f[..f.iter().position(|&c| c == 0).unwrap_or(16)].to_vec()
        };
        let labels_text = fixed_str(&p[22..86]);
        let labels: Vec<String> = if labels_text.is_empty() {
            Vec::new()
        } else {
            labels_text.split(',').map(str::to_string).collect()
        };
        let mut offsets = Vec::with_capacity(format.len());
        let mut off = 0;
        for &c in &format {
            let Some(sz) = field_size(c) else {
                return Err(format!(
                    "FMT of type {type_id} ({name}): unknown format character '{}' in '{}'",
                    c.escape_ascii(),
                    String::from_utf8_lossy(&format)
                ));
            };
            offsets.push(off);
            off += sz;
        }
        if off + 3 != length {
            return Err(format!(
                "FMT of type {type_id} ({name}): format '{}' makes {} bytes but the length says {length}",
                String::from_utf8_lossy(&format),
                off + 3
            ));
        }
        if labels.len() != format.len() {
            return Err(format!(
                "FMT of type {type_id} ({name}): {} labels for {} fields",
                labels.len(),
                format.len()
            ));
        }
        if type_id == FMT_TYPE && length != FMT_LEN {
            return Err(format!(
                "FMT describing FMT with length {length}, expected 89"
            ));
        }
        Ok(MessageFormat {
            type_id,
            length,
            name,
            format,
            labels,
            offsets,
        })
    }

    /// Index of the field labelled `label`.
    pub fn field(&self, label: &str) -> Option<usize> {
        self.labels.iter().position(|l| l == label)
    }

    /// The numeric value of field `idx` of `payload` in the log's units:
    /// `c C e E` divided by 100, `L` times 1e-7 (degrees); `None` for a
    /// character field or a payload too short.
    pub fn value(&self, payload: &[u8], idx: usize) -> Option<f64> {
        let c = *self.format.get(idx)?;
        let o = *self.offsets.get(idx)?;
        let b = payload.get(o..o + field_size(c)?)?;
        let arr = |n: usize| -> [u8; 8] {
            let mut a = [0u8; 8];
            a[..n].copy_from_slice(&b[..n]);
            a
        };
        let i16v = || i16::from_le_bytes([b[0], b[1]]) as f64;
        let u16v = || u16::from_le_bytes([b[0], b[1]]) as f64;
        let i32v = || i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
        let u32v = || u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
        Some(match c {
            b'b' => b[0] as i8 as f64,
            b'B' | b'M' => b[0] as f64,
            b'h' => i16v(),
            b'H' => u16v(),
            b'c' => i16v() / 100.0,
            b'C' => u16v() / 100.0,
            b'i' => i32v(),
            b'I' => u32v(),
            b'e' => i32v() / 100.0,
            b'E' => u32v() / 100.0,
            b'L' => i32v() * 1e-7,
            b'f' => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            b'd' => f64::from_le_bytes(arr(8)),
            b'q' => i64::from_le_bytes(arr(8)) as f64,
            b'Q' => u64::from_le_bytes(arr(8)) as f64,
            _ => return None,
        })
    }

    /// An unsigned integer field exactly (`B H I Q` and friends), for
    /// times: `None` for a negative, fractional or non-integer field.
    pub fn uint(&self, payload: &[u8], idx: usize) -> Option<u64> {
        let c = *self.format.get(idx)?;
        let o = *self.offsets.get(idx)?;
        let b = payload.get(o..o + field_size(c)?)?;
        match c {
            b'Q' => Some(u64::from_le_bytes(b.try_into().ok()?)),
            b'q' => u64::try_from(i64::from_le_bytes(b.try_into().ok()?)).ok(),
            b'I' => Some(u32::from_le_bytes(b.try_into().ok()?) as u64),
            b'i' => u64::try_from(i32::from_le_bytes(b.try_into().ok()?)).ok(),
            b'H' => Some(u16::from_le_bytes(b.try_into().ok()?) as u64),
            b'B' => Some(b[0] as u64),
            _ => None,
        }
    }

    /// The value of the field labelled `label`.
    pub fn get(&self, payload: &[u8], label: &str) -> Option<f64> {
        self.value(payload, self.field(label)?)
    }

    /// Boot time (µs) of a message: `TimeUS`, or `TimeMS` × 1000.
    pub fn boot_us(&self, payload: &[u8]) -> Option<u64> {
        if let Some(i) = self.field("TimeUS") {
            return self.uint(payload, i);
        }
        self.uint(payload, self.field("TimeMS")?)?.checked_mul(1000)
    }
}

/// One message: its layout, payload (after the header) and byte offset.
#[derive(Copy, Clone, Debug)]
pub struct Message<'a> {
    pub format: &'a MessageFormat,
    pub payload: &'a [u8],
    pub offset: usize,
}

/// What [`parse`] met.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ParseStats {
    /// Messages by name (`FMT` included).
    pub messages: BTreeMap<String, u64>,
    /// Message types described by a usable `FMT`.
    pub formats: usize,
    /// `FMT` messages that could not be used (reported).
    pub bad_formats: u64,
    /// Messages of a type no `FMT` described, by type id (skipped).
    pub unknown_type_messages: BTreeMap<u8, u64>,
    /// Bytes skipped outside messages, and in how many runs.
    pub garbage_bytes: u64,
    pub garbage_runs: u64,
    /// Offset of a last message cut short, when the file ends in one.
    pub truncated_at: Option<u64>,
}

/// Position of the next message header at or after `from`.
fn next_head(bytes: &[u8], from: usize) -> usize {
    bytes
        .get(from..)
        .and_then(|b| b.windows(2).position(|w| w == HEAD))
        .map_or(bytes.len(), |p| from + p)
}

/// Walks every message of a DataFlash log, calling `visit` for each one
/// of a described type (the `FMT` messages included); problems go to
/// `diag` with their byte offset.
pub fn parse(
    bytes: &[u8],
    path: &Path,
    diag: &mut Diagnostics,
    mut visit: impl FnMut(Message<'_>),
) -> ParseStats {
    let mut st = ParseStats::default();
    let mut formats: BTreeMap<u8, MessageFormat> = BTreeMap::new();
    let fmt_fmt = MessageFormat {
        type_id: FMT_TYPE,
        length: FMT_LEN,
        name: "FMT".into(),
        format: b"BBnNZ".to_vec(),
        labels: ["Type", "Length", "Name", "Format", "Columns"]
            .map(String::from)
            .to_vec(),
        offsets: vec![0, 1, 2, 6, 22],
    };
    let mut i = 0;
    while i < bytes.len() {
        if !bytes[i..].starts_with(&HEAD) {
            let next = next_head(bytes, i + 1);
            if next >= bytes.len() && bytes.len() - i < 3 && bytes[i] == HEAD[0] {
                // The file ends in the first byte of a header.
                st.truncated_at = Some(i as u64);
                diag.push(
                    path,
                    0,
                    format!("byte offset {i}: the log ends in a message header; ignored"),
                );
                break;
            }
            st.garbage_bytes += (next - i) as u64;
            st.garbage_runs += 1;
            diag.push(
                path,
                0,
                format!(
                    "byte offset {i}: {} bytes outside any message (expected the header 0xA3 0x95); skipped to the next header",
                    next - i
                ),
            );
            i = next;
            continue;
        }
        let Some(&t) = bytes.get(i + 2) else {
            st.truncated_at = Some(i as u64);
            diag.push(
                path,
                0,
                format!("byte offset {i}: the log ends in a message header; ignored"),
            );
            break;
        };
        let fmt = if t == FMT_TYPE {
            formats.get(&t).unwrap_or(&fmt_fmt)
        } else if let Some(f) = formats.get(&t) {
            f
        } else {
            let n = st.unknown_type_messages.entry(t).or_insert(0);
            *n += 1;
            if *n == 1 {
                diag.push(
                    path,
                    0,
                    format!(
                        "byte offset {i}: message type {t} has no FMT (layout unknown); its messages are counted and skipped"
                    ),
                );
            }
            i = next_head(bytes, i + 3);
            continue;
        };
        let end = i + fmt.length;
        if end > bytes.len() {
            st.truncated_at = Some(i as u64);
            diag.push(
                path,
                0,
                format!(
                    "byte offset {i}: the last message ({}) is cut short: {} of {} bytes; ignored",
                    fmt.name,
                    bytes.len() - i,
                    fmt.length
                ),
            );
            break;
        }
        let payload = &bytes[i + 3..end];
        *st.messages.entry(fmt.name.clone()).or_insert(0) += 1;
        visit(Message {
            format: fmt,
            payload,
            offset: i,
        });
        if t == FMT_TYPE {
            match MessageFormat::from_fmt_payload(payload) {
                Ok(f) => {
                    formats.insert(f.type_id, f);
                }
                Err(e) => {
                    st.bad_formats += 1;
                    diag.push(
                        path,
                        0,
                        format!("byte offset {i}: {e}; messages of that type are skipped"),
                    );
                    // A type whose layout cannot be trusted is undescribed.
                    let tid = payload[0];
                    if tid != FMT_TYPE {
                        formats.remove(&tid);
                    }
                }
            }
        }
        i = end;
    }
    st.formats = formats.len();
    st
}

/// Whether `buf` starts like a DataFlash log: an `FMT` message at offset 0
/// describing a type with a name and a layout that adds up.
pub fn looks_like_dataflash(buf: &[u8]) -> bool {
    buf.len() >= FMT_LEN
        && buf.starts_with(&HEAD)
        && buf[2] == FMT_TYPE
        && MessageFormat::from_fmt_payload(&buf[3..FMT_LEN]).is_ok()
}

/// Labels of the gyro and accelerometer fields of `IMU` messages (both eras).
const IMU_LABELS: [&str; 6] = ["GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"];

/// The instance of a message: its `I` (or `Instance`) field, else the
/// digit its name ends in minus one (`IMU2` → 1), else 0.
fn instance(f: &MessageFormat, p: &[u8]) -> u8 {
    if let Some(v) = f
        .field("I")
        .or_else(|| f.field("Instance"))
        .and_then(|i| f.uint(p, i))
    {
        return v.min(255) as u8;
    }
    match f.name.as_bytes().last() {
        Some(d @ b'2'..=b'9') => d - b'1',
        _ => 0,
    }
}

/// One IMU sample on the boot clock.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BootImu {
    /// Boot time of the sample (µs).
    pub boot_us: u64,
    /// Gyro x y z (rad/s) then accelerometer x y z (m/s²), FRD.
    pub values: [f64; 6],
}

/// One GNSS fix: valid at GPS time `time`, arrived at boot time `arrival_us`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BootFix {
    pub arrival_us: u64,
    pub time: navsync::time::GpsTime,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Ellipsoidal height (m).
    pub h_m: f64,
    /// σ north, east, down (m).
    pub sd_m: [f64; 3],
    /// True when the log gave no accuracy for it (the default σ was used).
    pub default_sd: bool,
}

/// The autopilot's own estimate at a boot time.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BootEstimate {
    pub boot_us: u64,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Ellipsoidal height (m).
    pub h_m: f64,
    /// Velocity north, east, down (m/s).
    pub vel_ned_mps: [f64; 3],
    /// Roll, pitch, yaw (deg).
    pub att_deg: [f64; 3],
}

/// A GPS message before the choice of instance.
#[derive(Copy, Clone, Debug)]
struct RawGps {
    seq: u64,
    offset: usize,
    status: f64,
    week: f64,
    tow_ms: f64,
    logged_us: u64,
    arrival_us: Option<u64>,
    lat_deg: f64,
    lon_deg: f64,
    alt_msl_m: f64,
}

/// An accuracy message (`GPA` or `UBX3`).
#[derive(Copy, Clone, Debug)]
struct RawAcc {
    seq: u64,
    /// `GPA` follows its `GPS` message; `UBX3` precedes it.
    after_fix: bool,
    boot_us: Option<u64>,
    /// `GPA.SMS`: boot ms the fix arrived.
    sample_us: Option<u64>,
    h_m: f64,
    v_m: f64,
}

/// What a DataFlash log held and what was taken from it (`summary.json`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct DataFlashSummary {
    pub parse: ParseStats,
    /// `TimeMS` (boot ms: ArduPilot ≤ 3.3) or `TimeUS` (boot µs).
    pub time_field: String,
    /// IMU samples by instance (`IMU[0]`, …).
    pub imu_instances: BTreeMap<String, u64>,
    pub imu_instance_used: Option<u8>,
    /// GPS messages by instance and how many gave a fix.
    pub gps_instances: BTreeMap<String, u64>,
    pub gps_instance_used: Option<u8>,
    /// GPS messages of the instance used that gave no fix, by reason.
    pub gps_drops: BTreeMap<String, u64>,
    /// Where the fixes' σ came from.
    pub sigma_source: String,
    /// Fixes whose arrival time is `GPA.SMS` (the rest: `T` or `TimeUS`).
    pub arrival_from_gpa_sms: u64,
    /// The autopilot's estimate written to autopilot.nav: its messages.
    pub estimate_source: Option<String>,
    pub estimate_rows: usize,
    /// Boot-clock rate against GPS time from the fixes (ppm, positive:
    /// the boot clock runs fast) and the fixes' latency above the fastest.
    pub boot_clock_error_ppm: Option<f64>,
    pub fix_latency_above_fastest_ms: Option<MinMedMax>,
    /// IMU samples dropped for a non-finite value (all instances).
    pub imu_nonfinite_dropped: u64,
    /// IMU gaps (boot time of the last sample before, length s), the first 100.
    pub imu_gaps: Vec<BootGap>,
}

#[derive(Copy, Clone, Debug, Default, serde::Serialize)]
pub struct MinMedMax {
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

#[derive(Copy, Clone, Debug, serde::Serialize)]
pub struct BootGap {
    pub after_boot_s: f64,
    pub length_s: f64,
}

/// A DataFlash log read: the IMU instance with most samples, the fixes of
/// the GPS instance with most fixes, the estimate, what was met.
#[derive(Clone, Debug, Default)]
pub struct DataFlashRead {
    pub imu: Vec<BootImu>,
    pub fixes: Vec<BootFix>,
    pub estimate: Vec<BootEstimate>,
    pub summary: DataFlashSummary,
}

/// An EKF row: boot µs, roll pitch yaw (deg), velocity NED (m/s).
type EkfRow = (u64, [f64; 3], [f64; 3]);

/// One GPS instance's fixes, drops by reason, arrivals from `GPA.SMS`.
type InstanceFixes = (Vec<BootFix>, BTreeMap<String, u64>, u64);

/// Everything collected from one pass over the messages.
#[derive(Default)]
struct Collected {
    imu: BTreeMap<u8, Vec<BootImu>>,
    gps: BTreeMap<u8, Vec<RawGps>>,
    acc: BTreeMap<u8, Vec<RawAcc>>,
    acc_names: BTreeMap<String, u64>,
    /// (boot µs, [roll, pitch, yaw], [vn, ve, vd]) by message name.
    ekf: BTreeMap<String, Vec<EkfRow>>,
    /// AHR2 (boot µs, lat, lon, alt MSL).
    ahr2: Vec<(u64, f64, f64, f64)>,
    time_us: bool,
    seq: u64,
    imu_nonfinite: u64,
    notes: Vec<String>,
}

impl Collected {
    fn push(&mut self, m: Message<'_>) {
        let (f, p) = (m.format, m.payload);
        self.seq += 1;
        let seq = self.seq;
        let get = |l: &str| f.get(p, l);
        if f.field("TimeUS").is_some() {
            self.time_us = true;
        }
        match f.name.as_str() {
            "IMU" | "IMU2" | "IMU3" => {
                let (Some(t), Some(idx)) = (
                    f.boot_us(p),
                    IMU_LABELS
                        .map(|l| f.field(l))
                        .into_iter()
                        .collect::<Option<Vec<_>>>(),
                ) else {
                    return;
                };
                let mut values = [0.0; 6];
                for (v, i) in values.iter_mut().zip(idx) {
                    *v = f.value(p, i).unwrap_or(f64::NAN);
                }
                if !values.iter().all(|v| v.is_finite()) {
                    self.imu_nonfinite += 1;
                    if self.imu_nonfinite <= 20 {
                        self.notes.push(format!(
                            "byte offset {}: {} sample with a non-finite value; dropped",
                            m.offset, f.name
                        ));
                    }
                    return;
                }
                self.imu
                    .entry(instance(f, p))
                    .or_default()
                    .push(BootImu { boot_us: t, values });
            }
            "GPS" | "GPS2" => {
                let current = f.field("GMS").is_some();
                let (tow, week, arrival) = if current {
                    (get("GMS"), get("GWk"), None)
                } else {
                    (
                        get("TimeMS"),
                        get("Week"),
                        f.field("T")
                            .and_then(|i| f.uint(p, i))
                            .and_then(|t| t.checked_mul(1000)),
                    )
                };
                let logged = if current { f.boot_us(p) } else { arrival };
                self.gps.entry(instance(f, p)).or_default().push(RawGps {
                    seq,
                    offset: m.offset,
                    status: get("Status").unwrap_or(f64::NAN),
                    week: week.unwrap_or(f64::NAN),
                    tow_ms: tow.unwrap_or(f64::NAN),
                    logged_us: logged.unwrap_or(0),
                    arrival_us: arrival.or(logged),
                    lat_deg: get("Lat").unwrap_or(f64::NAN),
                    lon_deg: get("Lng").unwrap_or(f64::NAN),
                    alt_msl_m: get("Alt").unwrap_or(f64::NAN),
                });
            }
            "GPA" | "GPA2" | "UBX3" => {
                let gpa = f.name != "UBX3";
                let (h, v) = if gpa {
                    (get("HAcc"), get("VAcc"))
                } else {
                    (get("hAcc"), get("vAcc"))
                };
                *self.acc_names.entry(f.name.clone()).or_insert(0) += 1;
                self.acc.entry(instance(f, p)).or_default().push(RawAcc {
                    seq,
                    after_fix: gpa,
                    boot_us: f.boot_us(p),
                    sample_us: f
                        .field("SMS")
                        .and_then(|i| f.uint(p, i))
                        .filter(|&t| t > 0)
                        .and_then(|t| t.checked_mul(1000)),
                    h_m: h.unwrap_or(f64::NAN),
                    v_m: v.unwrap_or(f64::NAN),
                });
            }
            "EKF1" | "NKF1" | "XKF1" => {
                // The primary core only (field C, when the log has it).
                if get("C").is_some_and(|c| c != 0.0) {
                    return;
                }
                let (Some(t), Some(r), Some(pi), Some(y), Some(vn), Some(ve), Some(vd)) = (
                    f.boot_us(p),
                    get("Roll"),
                    get("Pitch"),
                    get("Yaw"),
                    get("VN"),
                    get("VE"),
                    get("VD"),
                ) else {
                    return;
                };
                self.ekf
                    .entry(f.name.clone())
                    .or_default()
                    .push((t, [r, pi, y], [vn, ve, vd]));
            }
            "AHR2" => {
                if let (Some(t), Some(la), Some(lo), Some(a)) =
                    (f.boot_us(p), get("Lat"), get("Lng"), get("Alt"))
                {
                    self.ahr2.push((t, la, lo, a));
                }
            }
            _ => {}
        }
    }
}

/// Reads a whole DataFlash log. `default_sd_m`: σ for fixes the log gives
/// no accuracy for.
pub fn read_dataflash(
    bytes: &[u8],
    path: &Path,
    default_sd_m: [f64; 3],
    diag: &mut Diagnostics,
) -> DataFlashRead {
    let mut c = Collected::default();
    let parse_stats = parse(bytes, path, diag, |m| c.push(m));
    for n in c.notes.drain(..) {
        diag.push(path, 0, n);
    }
    let mut s = DataFlashSummary {
        parse: parse_stats,
        time_field: if c.time_us {
            "TimeUS (boot µs)".into()
        } else {
            "TimeMS (boot ms, ArduPilot ≤ 3.3)".into()
        },
        imu_nonfinite_dropped: c.imu_nonfinite,
        ..Default::default()
    };
    let mut geoid = crate::geoid::Egm96Grid::new();
    // IMU: the instance with most samples.
    for (i, v) in &c.imu {
        s.imu_instances.insert(format!("IMU[{i}]"), v.len() as u64);
    }
    let imu_pick = c
        .imu
        .iter()
        .max_by_key(|(i, v)| (v.len(), std::cmp::Reverse(**i)))
        .map(|(i, _)| *i);
    s.imu_instance_used = imu_pick;
    let imu = imu_pick.and_then(|i| c.imu.remove(&i)).unwrap_or_default();
    let mut prev: Option<u64> = None;
    for x in &imu {
        if let Some(p) = prev
            && x.boot_us > p
            && x.boot_us - p > 1_000_000
            && s.imu_gaps.len() < 100
        {
            s.imu_gaps.push(BootGap {
                after_boot_s: p as f64 * 1e-6,
                length_s: (x.boot_us - p) as f64 * 1e-6,
            });
        }
        prev = Some(x.boot_us);
    }
    // GPS: every instance's fixes, then the instance with most.
    let mut best: Option<(u8, InstanceFixes)> = None;
    for (&inst, msgs) in &c.gps {
        let accs = c.acc.get(&inst).map(Vec::as_slice).unwrap_or(&[]);
        let (fixes, drops, from_sms) = gps_fixes(msgs, accs, default_sd_m, &mut geoid, path, diag);
        s.gps_instances
            .insert(format!("GPS[{inst}] messages"), msgs.len() as u64);
        s.gps_instances
            .insert(format!("GPS[{inst}] fixes"), fixes.len() as u64);
        if best.as_ref().is_none_or(|b| fixes.len() > b.1.0.len()) {
            best = Some((inst, (fixes, drops, from_sms)));
        }
    }
    let fixes = match best {
        Some((inst, (fixes, drops, from_sms))) => {
            s.gps_instance_used = Some(inst);
            s.gps_drops = drops;
            s.arrival_from_gpa_sms = from_sms;
            fixes
        }
        None => Vec::new(),
    };
    let with_acc = fixes.iter().filter(|f| !f.default_sd).count();
    s.sigma_source = if fixes.is_empty() {
        String::new()
    } else if with_acc == 0 {
        format!(
            "none in the log: the default σ {:?} m (N, E, D) for every fix",
            default_sd_m
        )
    } else {
        format!(
            "{} (horizontal accuracy for N and E, vertical for D) for {with_acc} of {} fixes, the default σ {:?} m for the rest",
            c.acc_names.keys().cloned().collect::<Vec<_>>().join(", "),
            fixes.len(),
            default_sd_m
        )
    };
    let estimate = estimate_rows(&c, &mut geoid, &mut s);
    DataFlashRead {
        imu,
        fixes,
        estimate,
        summary: s,
    }
}

/// The fixes of one GPS instance with their σ; drops by reason; how many
/// arrival times came from `GPA.SMS`.
fn gps_fixes(
    msgs: &[RawGps],
    accs: &[RawAcc],
    default_sd_m: [f64; 3],
    geoid: &mut crate::geoid::Egm96Grid,
    path: &Path,
    diag: &mut Diagnostics,
) -> InstanceFixes {
    let mut drops: BTreeMap<String, u64> = BTreeMap::new();
    let mut drop = |r: &str| *drops.entry(r.to_string()).or_insert(0) += 1;
    let mut out: Vec<BootFix> = Vec::new();
    let mut from_sms = 0;
    for (k, g) in msgs.iter().enumerate() {
        if g.status.is_nan() || g.status < 3.0 {
            drop("no 3D fix (Status < 3)");
            continue;
        }
        if !(g.week >= 1.0 && g.week < 10_000.0 && (0.0..604_800_000.0).contains(&g.tow_ms)) {
            drop("no GPS time (week 0 or time of week out of range)");
            continue;
        }
        let pos_ok = g.lat_deg.is_finite()
            && g.lon_deg.is_finite()
            && g.lat_deg.abs() <= 90.0
            && g.lon_deg.abs() <= 180.0
            && !(g.lat_deg == 0.0 && g.lon_deg == 0.0)
            && g.alt_msl_m.is_finite()
            && g.alt_msl_m.abs() < 1e5;
        let Some(n) = pos_ok
            .then(|| geoid.separation_m(g.lat_deg, g.lon_deg))
            .flatten()
        else {
            drop("no valid position");
            continue;
        };
        // The accuracy of this fix: GPA is written just after its GPS
        // message (AP_GPS Write_GPS), UBX3 just before (ArduPilot 3.x).
        let next_seq = msgs.get(k + 1).map_or(u64::MAX, |x| x.seq);
        let prev_seq = if k > 0 { msgs[k - 1].seq } else { 0 };
        let acc = accs
            .iter()
            .find(|a| a.after_fix && a.seq > g.seq && a.seq < next_seq)
            .or_else(|| {
                accs.iter().rev().find(|a| {
                    !a.after_fix
                        && a.seq < g.seq
                        && a.seq > prev_seq
                        && a.boot_us
                            .zip(g.arrival_us)
                            .is_some_and(|(x, y)| x.abs_diff(y) <= 1_000_000)
                })
            });
        let mut arrival = g.arrival_us;
        if let Some(sms) = acc.and_then(|a| a.sample_us)
            && sms.abs_diff(g.logged_us) <= 1_000_000
        {
            arrival = Some(sms);
            from_sms += 1;
        }
        let Some(arrival_us) = arrival.filter(|&t| t > 0) else {
            drop("no arrival boot time");
            continue;
        };
        let time = navsync::time::GpsTime::from_week_ns(g.week as i64, g.tow_ms as i64 * 1_000_000);
        if out.last().is_some_and(|p| time <= p.time) {
            drop("GPS time not after the previous fix");
            diag.push(
                path,
                0,
                format!(
                    "byte offset {}: GPS fix at {} s of week not after the previous one; dropped",
                    g.offset,
                    g.tow_ms * 1e-3
                ),
            );
            continue;
        }
        let (sd_m, default_sd) = match acc {
            Some(a) if a.h_m > 0.0 && a.v_m > 0.0 && a.h_m < 1e3 && a.v_m < 1e3 => {
                ([a.h_m, a.h_m, a.v_m], false)
            }
            _ => (default_sd_m, true),
        };
        out.push(BootFix {
            arrival_us,
            time,
            lat_deg: g.lat_deg,
            lon_deg: g.lon_deg,
            h_m: g.alt_msl_m + n,
            sd_m,
            default_sd,
        });
    }
    (out, drops, from_sms)
}

/// The autopilot's estimate: attitude and velocity from its EKF (the
/// message with most primary-core rows among EKF1, NKF1, XKF1), position
/// from AHR2 at the same boot time (within 10 ms).
fn estimate_rows(
    c: &Collected,
    geoid: &mut crate::geoid::Egm96Grid,
    s: &mut DataFlashSummary,
) -> Vec<BootEstimate> {
    let Some((name, ekf)) = c.ekf.iter().max_by_key(|(_, v)| v.len()) else {
        return Vec::new();
    };
    if c.ahr2.is_empty() {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(ekf.len());
    let mut j = 0;
    for &(t, att, vel) in ekf {
        while j + 1 < c.ahr2.len() && c.ahr2[j + 1].0 <= t {
            j += 1;
        }
        let near = [j, j + 1]
            .into_iter()
            .filter_map(|k| c.ahr2.get(k))
            .min_by_key(|a| a.0.abs_diff(t));
        let Some(&(ta, la, lo, alt)) = near else {
            continue;
        };
        if ta.abs_diff(t) > 10_000
            || !(att.iter().chain(&vel).all(|v| v.is_finite()) && alt.abs() < 1e5)
        {
            continue;
        }
        let Some(n) = geoid.separation_m(la, lo) else {
            continue;
        };
        if la == 0.0 && lo == 0.0 {
            continue;
        }
        let yaw = (att[2] + 180.0).rem_euclid(360.0) - 180.0;
        out.push(BootEstimate {
            boot_us: t,
            lat_deg: la,
            lon_deg: lo,
            h_m: alt + n,
            vel_ned_mps: vel,
            att_deg: [att[0], att[1], yaw],
        });
    }
    if !out.is_empty() {
        s.estimate_source = Some(format!(
            "{name} (attitude, velocity; primary core) with AHR2 (position, MSL + EGM96)"
        ));
    }
    s.estimate_rows = out.len();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fmt(type_id: u8, name: &str, format: &str, labels: &str) -> Vec<u8> {
        let len: usize = 3 + format
            .bytes()
            .map(|c| field_size(c).unwrap())
            .sum::<usize>();
        let mut m = vec![0xA3, 0x95, FMT_TYPE, type_id, len as u8];
        let mut pad = |s: &str, n: usize| {
            let mut b = s.as_bytes().to_vec();
            b.resize(n, 0);
            m.extend_from_slice(&b);
        };
        pad(name, 4);
        pad(format, 16);
        pad(labels, 64);
        m
    }

    #[test]
    fn sizes_match_logstructure() {
        // The FMT layout itself: BBnNZ = 1+1+4+16+64 plus the header.
        let f = MessageFormat::from_fmt_payload(
            &fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")[3..],
        )
        .unwrap();
        assert_eq!(f.length, FMT_LEN);
        // 2014 GPS: BIHBcLLeeEefI is 45 bytes in the real log's FMT.
        let g = MessageFormat::from_fmt_payload(
            &fmt(
                130,
                "GPS",
                "BIHBcLLeeEefI",
                "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T",
            )[3..],
        )
        .unwrap();
        assert_eq!(g.length, 45);
        assert!(field_size(b'x').is_none());
    }

    #[test]
    fn scaled_values_and_resync() {
        let mut log = fmt(140, "TST", "cCeELq", "A,B,C,D,E,F");
        log.extend_from_slice(b"junk\xA3");
        let mut m = vec![0xA3, 0x95, 140];
        m.extend_from_slice(&(-1234i16).to_le_bytes());
        m.extend_from_slice(&(36000u16).to_le_bytes());
        m.extend_from_slice(&(-5300i32).to_le_bytes());
        m.extend_from_slice(&(5300u32).to_le_bytes());
        m.extend_from_slice(&(428_458_113i32).to_le_bytes());
        m.extend_from_slice(&(-7i64).to_le_bytes());
        log.extend_from_slice(&m);
        // An undescribed type, then a message cut short.
        log.extend_from_slice(&[0xA3, 0x95, 77, 1, 2, 3]);
        log.extend_from_slice(&m[..10]);
        let mut diag = Diagnostics::default();
        let mut vals = Vec::new();
        let st = parse(&log, Path::new("t.bin"), &mut diag, |msg| {
            if msg.format.name == "TST" {
                vals = (0..6)
                    .map(|k| msg.format.value(msg.payload, k).unwrap())
                    .collect();
            }
        });
        assert_eq!(vals, vec![-12.34, 360.0, -53.0, 53.0, 42.8458113, -7.0]);
        assert_eq!(st.messages.get("TST"), Some(&1));
        assert_eq!((st.garbage_runs, st.garbage_bytes), (1, 5));
        assert_eq!(st.unknown_type_messages.get(&77), Some(&1));
        assert!(st.truncated_at.is_some());
        assert!(diag.items.iter().any(|d| d.message.contains("cut short")));
    }

    #[test]
    fn bad_fmt_is_reported_and_type_skipped() {
        // Length byte says 10, the format makes 3 + 4.
        let mut f = fmt(141, "BAD", "I", "TimeMS");
        f[4] = 10;
        let mut log = f;
        log.extend_from_slice(&[0xA3, 0x95, 141, 0, 0, 0, 0]);
        let mut diag = Diagnostics::default();
        let st = parse(&log, Path::new("t.bin"), &mut diag, |_| {});
        assert_eq!(st.bad_formats, 1);
        assert_eq!(st.unknown_type_messages.get(&141), Some(&1));
        assert!(diag.items[0].message.contains("makes 7 bytes"));
        // An unknown character.
        let f = fmt(142, "BAD", "I", "TimeMS");
        let mut p = f[3..].to_vec();
        p[6] = b'x';
        assert!(
            MessageFormat::from_fmt_payload(&p)
                .unwrap_err()
                .contains("unknown format character")
        );
    }
}
