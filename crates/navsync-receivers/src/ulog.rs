//! PX4 ULog (`.ulg`) files, read directly: the self-describing binary log
//! of the PX4 autopilot (PX4 User Guide, "ULog File Format",
//! docs.px4.io/main/en/dev_log/ulog_file_format; cited below as [ULog]).
//!
//! - [`read`] streams the messages: the 16-byte header, then messages of
//!   `uint16 msg_size, uint8 msg_type, payload` ([ULog] "Data Section").
//!   Format definitions (`F`) are resolved into flat layouts (nested
//!   types, arrays `type[n]`, `_padding` fields) with the depth bounded;
//!   subscriptions (`A`) bind a msg_id to a topic and instance; data
//!   (`D`) of the topics navsync uses are decoded by field *name*, never
//!   by offset, so that every PX4 version's layout is read.
//! - Every size is checked against the file: a message cut by the end of
//!   the file, an unknown msg_id, a payload shorter than its layout are
//!   reported with their byte offset and skipped; a message type that is
//!   not a letter (a corrupt size field) makes the reader look for the
//!   next sync message (`S`, [ULog] "Synchronization message").
//! - [`convert_ulog`] writes what `navsync convert --from ulog` gives:
//!   `rig.csv` (rig-log v1, FORMATS.md §2) with the IMU on the autopilot's
//!   boot clock and the GPS fixes at their GPS time of validity and boot
//!   time of arrival, for `navsync sync`; `autopilot.nav` (the autopilot's
//!   own estimate, 11-column nav, FORMATS.md §1) for comparison.

use std::collections::{BTreeMap, HashMap};
use std::io::{BufReader, Read};
use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion};
use navsync::earth::Geodetic;
use navsync::error::{Diagnostics, Error};
use navsync::io::kfgins::{TextWriter, format_nav_line};
use navsync::io::riglog::{ImuKind, RateSampling, RigGnss, RigHeader, write as rig_write};
use navsync::time::GpsTime;

use crate::gnsstime::{UtcTime, utc_to_gps};

/// File magic ([ULog] "Header Section"): `ULog` then 0x01 0x12 0x35.
pub const MAGIC: [u8; 7] = *b"ULog\x01\x12\x35";
/// Payload of the synchronization message ([ULog] "S").
pub const SYNC_MAGIC: [u8; 8] = [0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12];
/// Nesting depth of format definitions beyond which a layout is refused
/// (PX4's deepest topics nest two levels; a cycle would recurse forever).
pub const MAX_NESTING: usize = 8;
/// Largest resolved layout (bytes): a data message holds at most
/// 65535 − 2 bytes of struct.
const MAX_LAYOUT_BYTES: usize = u16::MAX as usize;
/// Most flattened fields of one layout (PX4's largest topics have a few
/// hundred): bounds the work of resolving a corrupt definition.
const MAX_FIELDS: usize = 8192;

// ------------------------------------------------------------ layouts

/// The basic types ([ULog] "Data types"), little-endian.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum BaseType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Bool,
    Char,
}

impl BaseType {
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "int8_t" => BaseType::I8,
            "uint8_t" => BaseType::U8,
            "int16_t" => BaseType::I16,
            "uint16_t" => BaseType::U16,
            "int32_t" => BaseType::I32,
            "uint32_t" => BaseType::U32,
            "int64_t" => BaseType::I64,
            "uint64_t" => BaseType::U64,
            "float" => BaseType::F32,
            "double" => BaseType::F64,
            "bool" => BaseType::Bool,
            "char" => BaseType::Char,
            _ => return None,
        })
    }

    pub fn size(self) -> usize {
        match self {
            BaseType::I8 | BaseType::U8 | BaseType::Bool | BaseType::Char => 1,
            BaseType::I16 | BaseType::U16 => 2,
            BaseType::I32 | BaseType::U32 | BaseType::F32 => 4,
            BaseType::I64 | BaseType::U64 | BaseType::F64 => 8,
        }
    }

    /// The value at the start of `b` (which holds at least `size()` bytes).
    fn read(self, b: &[u8]) -> f64 {
        let a = |n: usize| -> [u8; 8] {
            let mut x = [0u8; 8];
            x[..n].copy_from_slice(&b[..n]);
            x
        };
        match self {
            BaseType::I8 => b[0] as i8 as f64,
            BaseType::U8 | BaseType::Bool | BaseType::Char => b[0] as f64,
            BaseType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            BaseType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            BaseType::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            BaseType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            BaseType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            BaseType::I64 => i64::from_le_bytes(a(8)) as f64,
            BaseType::U64 => u64::from_le_bytes(a(8)) as f64,
            BaseType::F64 => f64::from_le_bytes(a(8)),
        }
    }
}

/// One field of a format definition as written: `type[n] name`.
#[derive(Clone, Debug, PartialEq)]
struct RawField {
    ty: String,
    count: Option<usize>,
    name: String,
}

/// Where a flattened field's values are.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Slot {
    pub ty: BaseType,
    /// Byte offset in the struct (after the data message's msg_id).
    pub offset: usize,
    /// Array length (1 for a scalar).
    pub count: usize,
}

impl Slot {
    /// Element `i` of the field in `data`, `None` when `data` is short.
    pub fn get(&self, data: &[u8], i: usize) -> Option<f64> {
        if i >= self.count {
            return None;
        }
        let at = self.offset + i * self.ty.size();
        data.get(at..at + self.ty.size()).map(|b| self.ty.read(b))
    }

    /// A u64 field read exactly (timestamps: µs beyond 2^53 stay whole).
    pub fn get_u64(&self, data: &[u8]) -> Option<u64> {
        let b = data.get(self.offset..self.offset + 8)?;
        match self.ty {
            BaseType::U64 | BaseType::I64 => {
                Some(u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
            }
            _ => None,
        }
    }
}

/// A format resolved into flat fields (nested structs as `outer.inner`,
/// elements of arrays of structs as `outer[i].inner`; padding left out).
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    pub fields: Vec<(String, Slot)>,
    pub size: usize,
    /// Bytes of padding at the end of the struct, which the logger does
    /// not write ([ULog] "Format Message": a trailing padding field is not
    /// logged).
    pub trailing_padding: usize,
}

impl Layout {
    pub fn slot(&self, name: &str) -> Option<Slot> {
        self.fields.iter().find(|(n, _)| n == name).map(|(_, s)| *s)
    }

    /// The shortest data a message may hold.
    pub fn min_len(&self) -> usize {
        self.size - self.trailing_padding
    }
}

/// `message_name:type0 name0;type1[n] name1;…` ([ULog] "F").
fn parse_format(text: &str) -> Result<(String, Vec<RawField>), String> {
    let (name, rest) = text
        .split_once(':')
        .ok_or("expected 'message_name:field;…' (no ':')")?;
    if name.is_empty() {
        return Err("empty message name".into());
    }
    let mut fields = Vec::new();
    for f in rest.split(';').filter(|f| !f.is_empty()) {
        let (ty, fname) = f
            .trim()
            .split_once(' ')
            .ok_or_else(|| format!("field '{f}': expected 'type name'"))?;
        let (ty, count) = match ty.split_once('[') {
            Some((t, n)) => {
                let n = n
                    .strip_suffix(']')
                    .and_then(|n| n.parse::<usize>().ok())
                    .filter(|n| *n > 0 && *n <= MAX_LAYOUT_BYTES)
                    .ok_or_else(|| format!("field '{f}': bad array length"))?;
                (t, Some(n))
            }
            None => (ty, None),
        };
        fields.push(RawField {
            ty: ty.to_string(),
            count,
            name: fname.trim().to_string(),
        });
    }
    Ok((name.to_string(), fields))
}

/// Resolves `name` against the definitions into a flat [`Layout`].
fn resolve(defs: &HashMap<String, Vec<RawField>>, name: &str) -> Result<Layout, String> {
    let mut fields = Vec::new();
    let size = flatten(defs, name, "", 0, 0, &mut fields)?;
    // Trailing padding: the last raw field, when it is one.
    let trailing_padding = defs
        .get(name)
        .and_then(|f| f.last())
        .filter(|f| f.name.starts_with("_padding"))
        .and_then(|f| Some(BaseType::parse(&f.ty)?.size() * f.count.unwrap_or(1)))
        .unwrap_or(0);
    Ok(Layout {
        fields,
        size,
        trailing_padding,
    })
}

fn flatten(
    defs: &HashMap<String, Vec<RawField>>,
    name: &str,
    prefix: &str,
    base: usize,
    depth: usize,
    out: &mut Vec<(String, Slot)>,
) -> Result<usize, String> {
    if depth > MAX_NESTING {
        return Err(format!(
            "'{name}' nested deeper than {MAX_NESTING} levels (a definition that contains itself?)"
        ));
    }
    let raw = defs
        .get(name)
        .ok_or_else(|| format!("type '{name}' is neither a basic type nor defined"))?;
    // An empty struct would let arrays of it loop without growing the layout.
    if raw.is_empty() {
        return Err(format!("type '{name}' has no fields"));
    }
    let mut off = 0usize;
    for f in raw {
        let n = f.count.unwrap_or(1);
        let fname = format!("{prefix}{}", f.name);
        if let Some(t) = BaseType::parse(&f.ty) {
            if !f.name.starts_with("_padding") {
                out.push((
                    fname,
                    Slot {
                        ty: t,
                        offset: base + off,
                        count: n,
                    },
                ));
            }
            off += t.size() * n;
        } else {
            for i in 0..n {
                let p = match f.count {
                    Some(_) => format!("{fname}[{i}]."),
                    None => format!("{fname}."),
                };
                off += flatten(defs, &f.ty, &p, base + off, depth + 1, out)?;
                if base + off > MAX_LAYOUT_BYTES {
                    break;
                }
            }
        }
        if base + off > MAX_LAYOUT_BYTES || out.len() > MAX_FIELDS {
            return Err(format!(
                "'{name}' is larger than a ULog message can hold ({MAX_LAYOUT_BYTES} bytes, \
                 {MAX_FIELDS} fields)"
            ));
        }
    }
    Ok(off)
}

// ------------------------------------------------------------ records

/// One `sensor_combined` sample ([PX4 msg] SensorCombined.msg): body
/// rates and specific force in the FRD body frame, averaged over the
/// integration interval that ends at `t_us`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ImuRecord {
    /// Gyro sample time (boot µs): the message's `timestamp`.
    pub t_us: u64,
    pub gyro_rad_s: [f64; 3],
    pub accel_m_s2: [f64; 3],
    /// `accelerometer_timestamp_relative` (µs; accel time − gyro time).
    pub accel_relative_us: i64,
    /// `gyro_integral_dt` (µs), when the layout has it.
    pub gyro_integral_dt_us: Option<f64>,
}

/// One GPS receiver solution (`vehicle_gps_position` / `sensor_gps`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GpsRecord {
    /// Arrival at the autopilot (boot µs): the message's `timestamp`.
    pub t_us: u64,
    /// UTC of the solution (Unix µs), 0 when the receiver had none.
    pub time_utc_us: u64,
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_msl_m: f64,
    pub alt_ellipsoid_m: Option<f64>,
    /// Horizontal and vertical position accuracy (m).
    pub eph_m: f64,
    pub epv_m: f64,
    pub fix_type: u8,
    pub vel_ned_m_s: Option<[f64; 3]>,
    /// Speed accuracy (m/s; the field is named a variance but PX4's
    /// drivers fill it with the receiver's speed accuracy, e.g. u-blox sAcc).
    pub s_acc_m_s: Option<f64>,
}

/// `vehicle_attitude`: the body (FRD) → NED rotation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct AttitudeRecord {
    pub t_us: u64,
    /// w, x, y, z.
    pub q: [f64; 4],
}

/// `vehicle_global_position` (position) with what `vehicle_local_position`
/// gives (velocity).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PositionRecord {
    pub t_us: u64,
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_msl_m: f64,
    pub alt_ellipsoid_m: Option<f64>,
}

#[derive(Copy, Clone, Debug, PartialEq)]
pub struct VelocityRecord {
    pub t_us: u64,
    pub vel_ned_m_s: [f64; 3],
}

/// A value with its scale to SI / degrees.
#[derive(Copy, Clone, Debug)]
struct Num(Slot, f64);

impl Num {
    fn get(&self, d: &[u8], i: usize) -> Option<f64> {
        self.0.get(d, i).map(|v| v * self.1)
    }
}

/// The first of `names` (with its scale) the layout has.
fn pick(l: &Layout, names: &[(&str, f64)]) -> Option<Num> {
    names
        .iter()
        .find_map(|(n, s)| l.slot(n).map(|x| Num(x, *s)))
}

/// What a subscription's data are decoded into.
// One per subscription, not per message: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Copy, Clone, Debug)]
enum Decoder {
    Imu {
        ts: Slot,
        gyro: Slot,
        accel: Slot,
        accel_rel: Option<Slot>,
        dt: Option<Slot>,
    },
    Gps {
        ts: Slot,
        utc: Slot,
        lat: Num,
        lon: Num,
        alt: Num,
        alt_ell: Option<Num>,
        eph: Num,
        epv: Num,
        fix_type: Slot,
        vel: Option<[Num; 3]>,
        vel_valid: Option<Slot>,
        s_acc: Option<Num>,
    },
    Attitude {
        ts: Slot,
        q: Slot,
    },
    Position {
        ts: Slot,
        lat: Num,
        lon: Num,
        alt: Num,
        alt_ell: Option<Num>,
    },
    Velocity {
        ts: Slot,
        v: [Num; 3],
    },
    /// Counted only.
    None,
}

/// IMU topics navsync reads, in order of preference.
pub const IMU_TOPIC: &str = "sensor_combined";
/// GPS topics: older PX4 (≤ 1.13) and newer names of the same message.
pub const GPS_TOPICS: [&str; 2] = ["vehicle_gps_position", "sensor_gps"];

/// The decoder of `topic`, or why its layout lacks what is needed.
fn decoder_for(topic: &str, l: &Layout) -> Result<Decoder, String> {
    let need = |n: &str| l.slot(n).ok_or_else(|| format!("no field '{n}'"));
    let need3 = |n: &str| {
        need(n).and_then(|s| {
            if s.count >= 3 {
                Ok(s)
            } else {
                Err(format!("field '{n}' is not an array of 3"))
            }
        })
    };
    let num = |names: &[(&str, f64)]| {
        pick(l, names).ok_or_else(|| {
            format!(
                "none of the fields {}",
                names.iter().map(|n| n.0).collect::<Vec<_>>().join(", ")
            )
        })
    };
    Ok(match topic {
        IMU_TOPIC => Decoder::Imu {
            ts: need("timestamp")?,
            gyro: need3("gyro_rad")?,
            accel: need3("accelerometer_m_s2")?,
            accel_rel: l.slot("accelerometer_timestamp_relative"),
            dt: l.slot("gyro_integral_dt"),
        },
        t if GPS_TOPICS.contains(&t) => {
            let vel = match (
                pick(l, &[("vel_n_m_s", 1.0)]),
                pick(l, &[("vel_e_m_s", 1.0)]),
                pick(l, &[("vel_d_m_s", 1.0)]),
            ) {
                (Some(n), Some(e), Some(d)) => Some([n, e, d]),
                _ => None,
            };
            Decoder::Gps {
                ts: need("timestamp")?,
                utc: need("time_utc_usec")?,
                // PX4 ≤ 1.13: int32 1e-7 deg and int32 mm; 1.14 on: doubles.
                lat: num(&[("latitude_deg", 1.0), ("lat", 1e-7)])?,
                lon: num(&[("longitude_deg", 1.0), ("lon", 1e-7)])?,
                alt: num(&[("altitude_msl_m", 1.0), ("alt", 1e-3)])?,
                alt_ell: pick(l, &[("altitude_ellipsoid_m", 1.0), ("alt_ellipsoid", 1e-3)]),
                eph: num(&[("eph", 1.0)])?,
                epv: num(&[("epv", 1.0)])?,
                fix_type: need("fix_type")?,
                vel,
                vel_valid: l.slot("vel_ned_valid"),
                s_acc: pick(l, &[("s_variance_m_s", 1.0)]),
            }
        }
        "vehicle_attitude" => Decoder::Attitude {
            ts: need("timestamp")?,
            q: l.slot("q")
                .filter(|q| q.count == 4)
                .ok_or("no field 'q[4]'")?,
        },
        "vehicle_global_position" => Decoder::Position {
            ts: need("timestamp")?,
            lat: num(&[("lat", 1.0)])?,
            lon: num(&[("lon", 1.0)])?,
            alt: num(&[("alt", 1.0)])?,
            alt_ell: pick(l, &[("alt_ellipsoid", 1.0)]),
        },
        "vehicle_local_position" => Decoder::Velocity {
            ts: need("timestamp")?,
            v: [
                num(&[("vx", 1.0)])?,
                num(&[("vy", 1.0)])?,
                num(&[("vz", 1.0)])?,
            ],
        },
        _ => Decoder::None,
    })
}

// ------------------------------------------------------------ the file

/// One topic instance and what was read of it.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct TopicTally {
    pub topic: String,
    pub multi_id: u8,
    pub messages: u64,
    /// Messages whose payload was shorter than the layout (skipped).
    #[serde(skip_serializing_if = "is_zero")]
    pub short: u64,
    /// Why the topic's layout could not be decoded, if it could not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layout_problem: Option<String>,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// Everything read from a ULog.
#[derive(Clone, Debug, Default)]
pub struct UlogData {
    pub version: u8,
    /// Logging start (boot µs), from the header.
    pub start_us: u64,
    /// `char[]` info messages (sys_name, ver_hw, ver_sw, …), as text.
    pub info: BTreeMap<String, String>,
    /// Incompatible flag bits set ([ULog] "B"): bit 0 = appended data.
    pub incompat_flags: [u8; 8],
    pub topics: Vec<TopicTally>,
    /// Per (topic, multi_id) the decoded records.
    pub imu: BTreeMap<u8, Vec<ImuRecord>>,
    pub gps: BTreeMap<(String, u8), Vec<GpsRecord>>,
    pub attitude: BTreeMap<u8, Vec<AttitudeRecord>>,
    pub position: BTreeMap<u8, Vec<PositionRecord>>,
    pub velocity: BTreeMap<u8, Vec<VelocityRecord>>,
    /// Messages by type letter.
    pub messages: BTreeMap<char, u64>,
    /// Logged dropouts ([ULog] "O"): count and total ms.
    pub dropouts: u64,
    pub dropout_ms: u64,
    /// Bytes skipped to resynchronize after corruption.
    pub skipped_bytes: u64,
    pub truncated: bool,
    pub bytes: u64,
}

/// Bytes of `r` read so far, with the offset for messages.
struct Src<R: Read> {
    r: BufReader<R>,
    offset: u64,
}

impl<R: Read> Src<R> {
    /// Fills `buf`; `Ok(false)` at a clean end of file, an error naming the
    /// offset when the end cuts `buf` short.
    fn fill(&mut self, buf: &mut [u8], path: &Path) -> Result<usize, Error> {
        let mut n = 0;
        while n < buf.len() {
            match self.r.read(&mut buf[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Error::io(path, e)),
            }
        }
        self.offset += n as u64;
        Ok(n)
    }

    /// Skips to just after the next sync magic; the bytes skipped, or
    /// `None` at the end of the file.
    fn resync(&mut self, path: &Path) -> Result<Option<u64>, Error> {
        let mut win = [0u8; 8];
        let mut have = 0usize;
        let mut skipped = 0u64;
        let mut b = [0u8; 1];
        loop {
            if self.fill(&mut b, path)? == 0 {
                return Ok(None);
            }
            skipped += 1;
            if have < 8 {
                win[have] = b[0];
                have += 1;
            } else {
                win.copy_within(1.., 0);
                win[7] = b[0];
            }
            if have == 8 && win == SYNC_MAGIC {
                return Ok(Some(skipped));
            }
        }
    }
}

/// A subscription ([ULog] "A").
struct Sub {
    topic_index: usize,
    multi_id: u8,
    decoder: Decoder,
    min_len: usize,
}

/// The reader's state between messages.
struct Parser<'p> {
    path: &'p Path,
    d: UlogData,
    defs: HashMap<String, Vec<RawField>>,
    layouts: HashMap<String, Result<Layout, String>>,
    subs: HashMap<u16, Sub>,
    unknown_ids: BTreeMap<u16, u64>,
}

impl Parser<'_> {
    /// One whole message of type `ty` at byte offset `at`.
    fn message(&mut self, at: u64, ty: u8, body: &[u8], diag: &mut Diagnostics) {
        *self.d.messages.entry(ty as char).or_default() += 1;
        match ty {
            b'B' => {
                if let Some(f) = body.get(8..16) {
                    self.d.incompat_flags.copy_from_slice(f);
                }
            }
            b'F' => match std::str::from_utf8(body)
                .map_err(|_| "not UTF-8".to_string())
                .and_then(parse_format)
            {
                Ok((name, fields)) => {
                    self.layouts.clear();
                    self.defs.insert(name, fields);
                }
                Err(e) => diag.push(
                    self.path,
                    0,
                    format!("byte offset {at}: format definition skipped: {e}"),
                ),
            },
            b'I' => read_info(body, &mut self.d.info),
            b'A' => self.add(at, body, diag),
            b'R' => {
                if let Some(b) = body.get(..2) {
                    self.subs.remove(&u16::from_le_bytes([b[0], b[1]]));
                }
            }
            b'D' => self.data(at, body, diag),
            b'O' => {
                self.d.dropouts += 1;
                if let Some(b) = body.get(..2) {
                    self.d.dropout_ms += u16::from_le_bytes([b[0], b[1]]) as u64;
                }
            }
            // Params, multi info, log strings, sync: counted; unknown
            // letters skipped by their size, as [ULog] asks of parsers.
            _ => {}
        }
    }

    /// 'A': `uint8 multi_id, uint16 msg_id, char message_name[]`.
    fn add(&mut self, at: u64, body: &[u8], diag: &mut Diagnostics) {
        if body.len() < 3 {
            diag.push(
                self.path,
                0,
                format!("byte offset {at}: 'A' message too short"),
            );
            return;
        }
        let multi_id = body[0];
        let msg_id = u16::from_le_bytes([body[1], body[2]]);
        let name = String::from_utf8_lossy(&body[3..]).into_owned();
        let defs = &self.defs;
        let layout = self
            .layouts
            .entry(name.clone())
            .or_insert_with(|| resolve(defs, &name))
            .clone();
        let (decoder, min_len, problem) = match layout {
            Ok(l) => match decoder_for(&name, &l) {
                Ok(dec) => (dec, l.min_len(), None),
                Err(e) => (Decoder::None, 0, Some(e)),
            },
            Err(e) => (Decoder::None, 0, Some(e)),
        };
        if let Some(p) = &problem
            && is_wanted(&name)
        {
            diag.push(
                self.path,
                0,
                format!("byte offset {at}: topic {name} (instance {multi_id}) not read: {p}"),
            );
        }
        self.subs.insert(
            msg_id,
            Sub {
                topic_index: self.d.topics.len(),
                multi_id,
                decoder,
                min_len,
            },
        );
        self.d.topics.push(TopicTally {
            topic: name,
            multi_id,
            layout_problem: problem,
            ..Default::default()
        });
    }

    /// 'D': `uint16 msg_id, uint8 data[]`.
    fn data(&mut self, at: u64, body: &[u8], diag: &mut Diagnostics) {
        if body.len() < 2 {
            diag.push(
                self.path,
                0,
                format!("byte offset {at}: 'D' message too short"),
            );
            return;
        }
        let msg_id = u16::from_le_bytes([body[0], body[1]]);
        let Some(sub) = self.subs.get(&msg_id) else {
            let c = self.unknown_ids.entry(msg_id).or_default();
            *c += 1;
            if *c == 1 {
                diag.push(
                    self.path,
                    0,
                    format!(
                        "byte offset {at}: data for msg_id {msg_id}, which no 'A' message \
                         subscribed; skipped (further ones counted)"
                    ),
                );
            }
            return;
        };
        let data = &body[2..];
        let t = &mut self.d.topics[sub.topic_index];
        t.messages += 1;
        if data.len() < sub.min_len {
            t.short += 1;
            if t.short == 1 {
                diag.push(
                    self.path,
                    0,
                    format!(
                        "byte offset {at}: {} data of {} bytes, its layout needs {}; skipped \
                         (further ones counted in the summary's topics)",
                        t.topic,
                        data.len(),
                        sub.min_len
                    ),
                );
            }
            return;
        }
        let topic = t.topic.clone();
        decode(&sub.decoder, &topic, sub.multi_id, data, &mut self.d);
    }
}

/// Reads a ULog from `r` (`path` names it in messages).
pub fn read<R: Read>(r: R, path: &Path, diag: &mut Diagnostics) -> Result<UlogData, Error> {
    let mut src = Src {
        r: BufReader::with_capacity(1 << 16, r),
        offset: 0,
    };
    let mut head = [0u8; 16];
    let n = src.fill(&mut head, path)?;
    if n < 16 || head[..7] != MAGIC {
        return Err(Error::config(
            path,
            format!(
                "not a PX4 ULog: expected the 16-byte header starting 'ULog' 0x01 0x12 0x35 \
                 ({n} bytes read{})",
                if n >= 7 { ", magic differs" } else { "" }
            ),
        ));
    }
    let mut p = Parser {
        path,
        d: UlogData {
            version: head[7],
            start_us: u64::from_le_bytes(head[8..16].try_into().unwrap_or([0; 8])),
            ..Default::default()
        },
        defs: HashMap::new(),
        layouts: HashMap::new(),
        subs: HashMap::new(),
        unknown_ids: BTreeMap::new(),
    };
    // msg_size is a uint16: one buffer holds any message.
    let mut payload = vec![0u8; u16::MAX as usize];
    loop {
        let at = src.offset;
        let mut mh = [0u8; 3];
        let n = src.fill(&mut mh, path)?;
        if n == 0 {
            break;
        }
        if n < 3 {
            p.d.truncated = true;
            diag.push(
                path,
                0,
                format!("byte offset {at}: file ends inside a message header ({n} of 3 bytes)"),
            );
            break;
        }
        let size = u16::from_le_bytes([mh[0], mh[1]]) as usize;
        let ty = mh[2];
        if !ty.is_ascii_uppercase() {
            // A corrupt size sent the reader into the middle of a message.
            let skipped = src.resync(path)?;
            p.d.skipped_bytes += skipped.unwrap_or(0) + 3;
            diag.push(
                path,
                0,
                format!(
                    "byte offset {at}: message type 0x{ty:02x} is not a ULog message letter \
                     (corrupt data); {}",
                    match skipped {
                        Some(k) =>
                            format!("resumed after the next sync message, {} bytes on", k + 3),
                        None => "no sync message follows: the rest of the file is skipped".into(),
                    }
                ),
            );
            if skipped.is_none() {
                break;
            }
            continue;
        }
        let got = src.fill(&mut payload[..size], path)?;
        if got < size {
            p.d.truncated = true;
            diag.push(
                path,
                0,
                format!(
                    "byte offset {at}: file ends inside a '{}' message ({got} of {size} bytes): \
                     the log was cut (logger stopped mid-write?); that message is dropped",
                    ty as char
                ),
            );
            break;
        }
        p.message(at, ty, &payload[..size], diag);
    }
    p.d.bytes = src.offset;
    if !p.unknown_ids.is_empty() {
        diag.push(
            path,
            0,
            format!(
                "data messages of unsubscribed msg_ids skipped: {}",
                p.unknown_ids
                    .iter()
                    .map(|(k, v)| format!("id {k}: {v}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
    }
    Ok(p.d)
}

fn is_wanted(topic: &str) -> bool {
    topic == IMU_TOPIC
        || GPS_TOPICS.contains(&topic)
        || matches!(
            topic,
            "vehicle_attitude" | "vehicle_global_position" | "vehicle_local_position"
        )
}

/// Keeps `char[n] key` info values ([ULog] "I"): at most 64, 256 bytes each.
fn read_info(body: &[u8], info: &mut BTreeMap<String, String>) {
    let Some(&klen) = body.first() else { return };
    let Some(key) = body.get(1..1 + klen as usize) else {
        return;
    };
    let key = String::from_utf8_lossy(key);
    let Some((ty, name)) = key.split_once(' ') else {
        return;
    };
    if ty.starts_with("char[") && info.len() < 64 {
        let v = &body[1 + klen as usize..];
        let v = &v[..v.len().min(256)];
        info.insert(
            name.to_string(),
            String::from_utf8_lossy(v)
                .trim_end_matches('\0')
                .to_string(),
        );
    }
}

/// Decodes one data message (its length checked against the layout).
fn decode(dec: &Decoder, topic: &str, multi_id: u8, x: &[u8], d: &mut UlogData) {
    let v3 = |s: &Slot| -> Option<[f64; 3]> { Some([s.get(x, 0)?, s.get(x, 1)?, s.get(x, 2)?]) };
    match dec {
        Decoder::Imu {
            ts,
            gyro,
            accel,
            accel_rel,
            dt,
        } => {
            let (Some(t_us), Some(g), Some(a)) = (ts.get_u64(x), v3(gyro), v3(accel)) else {
                return;
            };
            d.imu.entry(multi_id).or_default().push(ImuRecord {
                t_us,
                gyro_rad_s: g,
                accel_m_s2: a,
                accel_relative_us: accel_rel.and_then(|s| s.get(x, 0)).unwrap_or(0.0) as i64,
                gyro_integral_dt_us: dt.and_then(|s| s.get(x, 0)),
            });
        }
        Decoder::Gps {
            ts,
            utc,
            lat,
            lon,
            alt,
            alt_ell,
            eph,
            epv,
            fix_type,
            vel,
            vel_valid,
            s_acc,
        } => {
            let f = || -> Option<GpsRecord> {
                let valid = vel_valid.and_then(|s| s.get(x, 0)).unwrap_or(1.0) != 0.0;
                Some(GpsRecord {
                    t_us: ts.get_u64(x)?,
                    time_utc_us: utc.get_u64(x)?,
                    lat_deg: lat.get(x, 0)?,
                    lon_deg: lon.get(x, 0)?,
                    alt_msl_m: alt.get(x, 0)?,
                    alt_ellipsoid_m: alt_ell.and_then(|n| n.get(x, 0)),
                    eph_m: eph.get(x, 0)?,
                    epv_m: epv.get(x, 0)?,
                    fix_type: fix_type.get(x, 0)? as u8,
                    vel_ned_m_s: vel
                        .filter(|_| valid)
                        .and_then(|v| Some([v[0].get(x, 0)?, v[1].get(x, 0)?, v[2].get(x, 0)?])),
                    s_acc_m_s: s_acc.and_then(|n| n.get(x, 0)),
                })
            };
            if let Some(r) = f() {
                d.gps
                    .entry((topic.to_string(), multi_id))
                    .or_default()
                    .push(r);
            }
        }
        Decoder::Attitude { ts, q } => {
            let f = || Some([q.get(x, 0)?, q.get(x, 1)?, q.get(x, 2)?, q.get(x, 3)?]);
            if let (Some(t_us), Some(q)) = (ts.get_u64(x), f()) {
                d.attitude
                    .entry(multi_id)
                    .or_default()
                    .push(AttitudeRecord { t_us, q });
            }
        }
        Decoder::Position {
            ts,
            lat,
            lon,
            alt,
            alt_ell,
        } => {
            let f = || {
                Some(PositionRecord {
                    t_us: ts.get_u64(x)?,
                    lat_deg: lat.get(x, 0)?,
                    lon_deg: lon.get(x, 0)?,
                    alt_msl_m: alt.get(x, 0)?,
                    alt_ellipsoid_m: alt_ell.and_then(|n| n.get(x, 0)),
                })
            };
            if let Some(r) = f() {
                d.position.entry(multi_id).or_default().push(r);
            }
        }
        Decoder::Velocity { ts, v } => {
            let f = || {
                Some(VelocityRecord {
                    t_us: ts.get_u64(x)?,
                    vel_ned_m_s: [v[0].get(x, 0)?, v[1].get(x, 0)?, v[2].get(x, 0)?],
                })
            };
            if let Some(r) = f() {
                d.velocity.entry(multi_id).or_default().push(r);
            }
        }
        Decoder::None => {}
    }
}

// ------------------------------------------------------------ conversion

/// What a ULog conversion read and wrote (`summary.json`, key `ulog`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct UlogSummary {
    pub version: u8,
    /// Logging start (boot µs).
    pub start_us: u64,
    /// `sys_name`, `ver_hw`, `ver_sw`, … as logged.
    pub info: BTreeMap<String, String>,
    /// Incompatible flag bit 0 ([ULog] "B"): data appended at the end
    /// (read in file order here).
    pub appended_data: bool,
    /// Every topic instance subscribed, with its message count.
    pub topics: Vec<TopicTally>,
    /// Messages by type letter.
    pub messages: BTreeMap<char, u64>,
    pub dropouts: u64,
    pub dropout_ms: u64,
    pub skipped_bytes: u64,
    pub truncated: bool,
    /// `sensor_combined` instance read, its samples and median rate.
    pub imu_instance: u8,
    pub imu_samples: usize,
    pub imu_rate_hz: f64,
    /// accel time − gyro time within a sample (µs): median and largest
    /// magnitude. The rig log stamps both at the gyro time.
    pub accel_relative_us: [i64; 2],
    /// What the IMU values are.
    pub imu_axes: String,
    /// GPS topic and instance read, its messages and the fixes written.
    pub gps_topic: String,
    pub gps_instance: u8,
    pub gps_messages: usize,
    pub fixes: usize,
    pub fix_drops: BTreeMap<String, u64>,
    /// Fixes whose ellipsoidal height came from the EGM96 model (the topic
    /// has no ellipsoid height).
    pub geoid_model_heights: usize,
    /// Instances of the same topics not read (fewer samples).
    pub other_instances: Vec<String>,
    /// GPS time − boot time (s): the largest (GPS time of validity −
    /// arrival) over the fixes, i.e. up to the fastest fix latency.
    pub boot_to_gps_s: Option<f64>,
    /// Epochs written to autopilot.nav, or why none were.
    pub autopilot_nav_epochs: usize,
    pub autopilot_nav: String,
}

/// The instance with most records; the others named for the summary.
fn most<K: Ord + Clone + std::fmt::Debug, V>(
    m: &BTreeMap<K, Vec<V>>,
    what: &str,
    others: &mut Vec<String>,
) -> Option<(K, usize)> {
    let best = m.iter().max_by_key(|(_, v)| v.len())?.0.clone();
    for (k, v) in m {
        if *k != best {
            others.push(format!("{what} {k:?}: {} samples, not read", v.len()));
        }
    }
    Some((best.clone(), m.get(&best).map(Vec::len).unwrap_or(0)))
}

/// Lower bound of GPS times this far from year 2000 (µs): a zero or
/// garbage `time_utc_usec` is no time.
const MIN_UTC_US: u64 = 946_684_800_000_000;

/// GPS fix from a GPS record, or why none.
fn gps_fix(
    r: &GpsRecord,
    geoid: &mut crate::geoid::Egm96Grid,
) -> Result<(RigGnss, bool), &'static str> {
    if r.fix_type < 3 {
        return Err("fix_type < 3 (no 3D fix)");
    }
    if r.time_utc_us < MIN_UTC_US {
        return Err("no UTC time (time_utc_usec before 2000)");
    }
    if !(r.lat_deg.abs() <= 90.0 && r.lon_deg.abs() <= 180.0 && r.alt_msl_m.is_finite()) {
        return Err("position out of range");
    }
    if !(r.eph_m > 0.0 && r.epv_m > 0.0 && r.eph_m < 1e3 && r.epv_m < 1e3) {
        return Err("eph/epv not in (0, 1000) m");
    }
    let utc = UtcTime::from_unix_ns(r.time_utc_us as i64 * 1000);
    let (h_m, from_model) = match r.alt_ellipsoid_m.filter(|h| h.is_finite() && *h != 0.0) {
        Some(h) => (h, false),
        None => (
            r.alt_msl_m
                + geoid
                    .separation_m(r.lat_deg, r.lon_deg)
                    .ok_or("no geoid separation at the position")?,
            true,
        ),
    };
    Ok((
        RigGnss {
            counter: r.t_us,
            time: utc_to_gps(&utc),
            lat_deg: r.lat_deg,
            lon_deg: r.lon_deg,
            h_m,
            // eph on north and east, epv down: accuracy estimates, read as
            // σ per axis (the conservative reading, as for u-blox hAcc).
            sd_m: [r.eph_m, r.eph_m, r.epv_m],
        },
        from_model,
    ))
}

fn median_i64(mut v: Vec<i64>) -> i64 {
    if v.is_empty() {
        return 0;
    }
    v.sort_unstable();
    v[v.len() / 2]
}

/// Converts a ULog into `rig.csv` and `autopilot.nav` in `out_dir`.
pub fn convert_ulog(
    r: Box<dyn Read>,
    input: &Path,
    out_dir: &Path,
    s: &mut crate::convert::ConvertSummary,
) -> Result<(), Error> {
    let d = read(r, input, &mut s.diagnostics)?;
    let mut u = UlogSummary {
        version: d.version,
        start_us: d.start_us,
        info: d.info.clone(),
        appended_data: d.incompat_flags[0] & 1 != 0,
        topics: d.topics.clone(),
        messages: d.messages.clone(),
        dropouts: d.dropouts,
        dropout_ms: d.dropout_ms,
        skipped_bytes: d.skipped_bytes,
        truncated: d.truncated,
        ..Default::default()
    };
    if d.incompat_flags[0] & !1 != 0 || d.incompat_flags[1..].iter().any(|b| *b != 0) {
        return Err(Error::config(
            input,
            format!(
                "ULog incompatible flags {:02x?} hold bits this reader does not know \
                 ([ULog] 'B': a parser must refuse such a file)",
                d.incompat_flags
            ),
        ));
    }
    let present = || {
        let mut t: Vec<&str> = d.topics.iter().map(|t| t.topic.as_str()).collect();
        t.dedup();
        t.join(", ")
    };
    let Some((imu_id, n_imu)) =
        most(&d.imu, "sensor_combined instance", &mut u.other_instances).filter(|(_, n)| *n >= 2)
    else {
        let why = if d
            .topics
            .iter()
            .any(|t| t.topic == "sensor_accel" || t.topic == "sensor_gyro")
        {
            "; sensor_accel/sensor_gyro are in the board frame before PX4's SENS_BOARD_ROT \
             rotation and are not read: log sensor_combined (body frame)"
        } else {
            ""
        };
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: format!(
                "no IMU data: topic {IMU_TOPIC} with at least two samples is needed (topics present: {}){why}",
                present()
            ),
        });
    };
    let Some((gps_key, n_gps)) = most(&d.gps, "GPS", &mut u.other_instances) else {
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: format!(
                "no GPS topic ({} with lat/lon, time_utc_usec): navsync needs the GPS fixes to put \
                 the log on GPS time (topics present: {})",
                GPS_TOPICS.join(" or "),
                present()
            ),
        });
    };
    let imu = &d.imu[&imu_id];
    let gps = &d.gps[&gps_key];
    u.imu_instance = imu_id;
    u.imu_samples = n_imu;
    u.gps_topic = gps_key.0.clone();
    u.gps_instance = gps_key.1;
    u.gps_messages = n_gps;
    let dts: Vec<i64> = imu
        .windows(2)
        .map(|w| w[1].t_us as i64 - w[0].t_us as i64)
        .filter(|d| *d > 0)
        .collect();
    let dt_us = median_i64(dts);
    u.imu_rate_hz = if dt_us > 0 { 1e6 / dt_us as f64 } else { 0.0 };
    let rel: Vec<i64> = imu.iter().map(|r| r.accel_relative_us).collect();
    u.accel_relative_us = [
        median_i64(rel.clone()),
        rel.iter().map(|r| r.abs()).max().unwrap_or(0),
    ];
    // PX4 sensor_combined: "gyro_rad: average angular rate measured in the
    // FRD body frame XYZ-axis in rad/s", accelerometer_m_s2 likewise
    // (PX4 msg/SensorCombined.msg).
    u.imu_axes = "FRD body frame (sensor_combined, after SENS_BOARD_ROT); rates averaged over \
                  gyro_integral_dt, ending at timestamp"
        .into();

    let mut geoid = crate::geoid::Egm96Grid::new();
    let fixes = fixes_of(gps, &mut geoid, &mut u);
    s.fix_epochs.push(crate::convert::EpochTally {
        source: format!("PX4 {} instance {}", u.gps_topic, u.gps_instance),
        epochs: n_gps as u64,
        fixes: fixes.len() as u64,
        dropped: u
            .fix_drops
            .iter()
            .map(|(reason, &epochs)| crate::convert::DropTally {
                reason: reason.clone(),
                epochs,
                kept_by: None,
            })
            .collect(),
    });
    if u.geoid_model_heights > 0 {
        s.geoid_model = Some(crate::geoid::EGM96_SOURCE.to_string());
    }
    let rig = out_dir.join("rig.csv");
    write_rig(&rig, imu, &fixes, u.imu_rate_hz)?;
    s.files.push(rig.display().to_string());
    s.imu_samples = n_imu;
    s.imu_time_axis = "autopilot boot time (µs, rig.csv counter): `navsync sync rig.csv` puts it \
                       on GPS time"
        .into();
    s.gnss_fixes = fixes.len();
    s.gnss_columns = 0;
    s.gnss_source = format!(
        "PX4 {} instance {} (time_utc_usec + leap seconds; arrival = timestamp)",
        u.gps_topic, u.gps_instance
    );
    s.leap_source = Some(crate::gnsstime::LeapSource::Table);

    // autopilot.nav: the autopilot's estimate on GPS time.
    u.boot_to_gps_s = fixes
        .iter()
        .map(|f| f.time.seconds() - f.counter as f64 * 1e-6)
        .max_by(f64::total_cmp);
    match write_autopilot_nav(&d, &fixes, &out_dir.join("autopilot.nav"), &mut geoid) {
        Ok(n) => {
            u.autopilot_nav_epochs = n;
            u.autopilot_nav = "vehicle_global_position + vehicle_local_position velocity + \
                               vehicle_attitude, on GPS time by boot + (GPS − arrival) of the \
                               fixes (lower envelope over ±30 s: early by the fastest fix latency)"
                .into();
            s.files
                .push(out_dir.join("autopilot.nav").display().to_string());
        }
        Err(why) => u.autopilot_nav = format!("not written: {why}"),
    }
    s.ulog = Some(u);
    Ok(())
}

/// The usable fixes of a GPS topic, in time order; drops counted in `u`.
fn fixes_of(
    gps: &[GpsRecord],
    geoid: &mut crate::geoid::Egm96Grid,
    u: &mut UlogSummary,
) -> Vec<RigGnss> {
    let mut fixes: Vec<RigGnss> = Vec::with_capacity(gps.len());
    for r in gps {
        match gps_fix(r, geoid) {
            Ok((f, model)) => {
                if fixes.last().is_some_and(|l| f.time <= l.time) {
                    *u.fix_drops
                        .entry("time not after the previous fix".into())
                        .or_default() += 1;
                    continue;
                }
                u.geoid_model_heights += model as usize;
                fixes.push(f);
            }
            Err(why) => *u.fix_drops.entry(why.into()).or_default() += 1,
        }
    }
    u.fixes = fixes.len();
    fixes
}

/// `rig.csv`: the IMU on the boot clock (counter = boot µs, 64 bits) and
/// the fixes at their arrival, records in counter order (a logger's
/// arrival order, FORMATS.md §2).
fn write_rig(path: &Path, imu: &[ImuRecord], fixes: &[RigGnss], rate_hz: f64) -> Result<(), Error> {
    let mut w = TextWriter::create(path)?;
    let mut h = RigHeader::new(1e6, 64, ImuKind::Rate);
    h.imu_rate_hz = (rate_hz > 0.0).then_some(rate_hz.round());
    // The counter is each sample's own time (sensor_combined.timestamp is
    // the gyro's sample time), not a receipt: data-ready timing, and the
    // values are averages over the interval ending there.
    h.imu_timing = Some(navsync::io::riglog::ImuTiming::DataReady);
    h.imu_rates = Some(RateSampling::IntervalAverage);
    w.write(h.to_text().as_bytes())?;
    let mut buf = Vec::with_capacity(1 << 16);
    let mut fi = fixes.iter().peekable();
    for r in imu {
        while let Some(f) = fi.next_if(|f| f.counter < r.t_us) {
            rig_write::gnss(&mut buf, f);
        }
        let g = r.gyro_rad_s;
        let a = r.accel_m_s2;
        rig_write::imu(&mut buf, r.t_us, &[g[0], g[1], g[2], a[0], a[1], a[2]]);
        if buf.len() > 1 << 16 {
            w.write(&buf)?;
            buf.clear();
        }
    }
    for f in fi {
        rig_write::gnss(&mut buf, f);
    }
    w.write(&buf)?;
    w.finish()
}

/// Half-width of the window of the boot → GPS envelope (s).
const ENVELOPE_HALF_S: f64 = 30.0;

/// The autopilot's own solution, 11 columns: returns the epochs written
/// or why none.
fn write_autopilot_nav(
    d: &UlogData,
    fixes: &[RigGnss],
    path: &Path,
    geoid: &mut crate::geoid::Egm96Grid,
) -> Result<usize, String> {
    let pos = d
        .position
        .values()
        .max_by_key(|v| v.len())
        .ok_or("no vehicle_global_position")?;
    let att = d
        .attitude
        .values()
        .max_by_key(|v| v.len())
        .ok_or("no vehicle_attitude")?;
    let vel = d.velocity.values().max_by_key(|v| v.len());
    if fixes.is_empty() {
        return Err("no GPS fix to relate boot time to GPS time".into());
    }
    // Boot → GPS: per fix, the largest (validity − arrival) within ±30 s
    // (latency is never negative: Tang, Zhang & Niu 2022, software sync).
    let c: Vec<(f64, f64)> = fixes
        .iter()
        .map(|f| {
            let t = f.counter as f64 * 1e-6;
            let lo = fixes.partition_point(|g| (g.counter as f64 * 1e-6) < t - ENVELOPE_HALF_S);
            let hi = fixes.partition_point(|g| (g.counter as f64 * 1e-6) <= t + ENVELOPE_HALF_S);
            let m = fixes[lo..hi]
                .iter()
                .map(|g| g.time.seconds() - g.counter as f64 * 1e-6)
                .fold(f64::NEG_INFINITY, f64::max);
            (t, m)
        })
        .collect();
    let offset_at = |t: f64| -> f64 {
        let i = c.partition_point(|p| p.0 < t);
        match (i.checked_sub(1).map(|j| c[j]), c.get(i)) {
            (Some(a), Some(b)) if b.0 > a.0 => a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0),
            (Some(a), _) => a.1,
            (None, Some(b)) => b.1,
            (None, None) => f64::NAN,
        }
    };
    let mut w = TextWriter::create(path).map_err(|e| e.to_string())?;
    let mut line = Vec::with_capacity(160);
    let mut n = 0;
    let mut last_time = None;
    for p in pos {
        // The last attitude and velocity at or before the position.
        let ai = att.partition_point(|a| a.t_us <= p.t_us);
        let Some(a) = ai.checked_sub(1).map(|i| att[i]) else {
            continue;
        };
        let v = vel
            .and_then(|v| {
                v.partition_point(|x| x.t_us <= p.t_us)
                    .checked_sub(1)
                    .map(|i| v[i])
            })
            .map(|x| x.vel_ned_m_s)
            .unwrap_or([f64::NAN; 3]);
        let q = UnitQuaternion::from_quaternion(Quaternion::new(a.q[0], a.q[1], a.q[2], a.q[3]));
        // nalgebra's (roll, pitch, yaw) are those of R = Rz(yaw)·Ry(pitch)·Rx(roll):
        // the ZYX body → NED Euler angles of FORMATS.md.
        let (roll, pitch, yaw) = q.euler_angles();
        let h_m = match p.alt_ellipsoid_m.filter(|h| h.is_finite() && *h != 0.0) {
            Some(h) => h,
            None => match geoid.separation_m(p.lat_deg, p.lon_deg) {
                Some(nn) => p.alt_msl_m + nn,
                None => continue,
            },
        };
        let t_s = p.t_us as f64 * 1e-6;
        let gps = t_s + offset_at(t_s);
        if !gps.is_finite() || !a.q.iter().all(|x| x.is_finite()) {
            continue;
        }
        let time = GpsTime::from_seconds(gps);
        if last_time.is_some_and(|l| time <= l) {
            continue;
        }
        last_time = Some(time);
        line.clear();
        format_nav_line(
            &mut line,
            time.week(),
            time,
            &Geodetic::from_deg(p.lat_deg, p.lon_deg, h_m),
            &nalgebra::Vector3::new(v[0], v[1], v[2]),
            &[
                roll.to_degrees(),
                pitch.to_degrees(),
                yaw.to_degrees().rem_euclid(360.0),
            ],
        );
        w.write(&line).map_err(|e| e.to_string())?;
        n += 1;
    }
    w.finish().map_err(|e| e.to_string())?;
    if n == 0 {
        let _ = std::fs::remove_file(path);
        return Err("no vehicle_global_position epoch with an attitude before it".into());
    }
    Ok(n)
}

#[cfg(test)]
#[path = "ulog_tests.rs"]
mod tests;
