//! ROS 2 bags in MCAP form: `sensor_msgs/msg/Imu`, `sensor_msgs/msg/NavSatFix`
//! and `geometry_msgs/msg/TwistWithCovarianceStamped` messages, CDR-decoded
//! by hand, on GPS time.
//!
//! - Container: MCAP (mcap.dev/spec), read with the `mcap` crate; chunks
//!   may be uncompressed, zstd (the ROS 2 writer's default) or lz4.
//! - Payloads: the ROS 2 `cdr` message encoding, i.e. OMG CDR as in
//!   DDS-XTypes 1.3 §7.4.3 (XCDR1, "PLAIN_CDR"): a 4-byte encapsulation
//!   header (representation identifier 0x0000 CDR_BE or 0x0001 CDR_LE,
//!   then 2 option bytes), then the fields in declaration order, each
//!   primitive aligned to its own size counted from the end of that header;
//!   strings as a uint32 length that includes the terminating NUL; fixed
//!   arrays (`float64[9]`) without a length.
//! - Times: `header.stamp` (`builtin_interfaces/Time`: int32 sec, uint32
//!   nanosec) is ROS time, i.e. Unix time (UTC) when recorded from the
//!   system clock; it becomes GPS time with the leap-second table. The
//!   message's MCAP `log_time` (ns since the Unix epoch, when the recorder
//!   got it) is compared with it per topic.
//! - Frames (REP 103): IMU axes are body FLU, turned into navsync's FRD
//!   (y and z negated); NavSatFix covariance and Twist velocities are ENU,
//!   turned into NED.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::Vector3;
use navsync::earth::Geodetic;
use navsync::error::{Diagnostics, Error};
use navsync::filter::gnss::GnssFix;
use navsync::io::text::time_order_problem;
use navsync::time::GpsTime;

use crate::gnsstime::{UtcTime, utc_to_gps};
use crate::imu::RateSample;

pub const IMU_SCHEMA: &str = "sensor_msgs/msg/Imu";
pub const NAVSATFIX_SCHEMA: &str = "sensor_msgs/msg/NavSatFix";
pub const TWIST_SCHEMA: &str = "geometry_msgs/msg/TwistWithCovarianceStamped";

/// A CDR (XCDR1) reader over one serialized message.
#[derive(Debug)]
pub(crate) struct Cdr<'a> {
    /// The bytes after the encapsulation header (alignment origin).
    buf: &'a [u8],
    pos: usize,
    le: bool,
}

impl<'a> Cdr<'a> {
    /// Reads the encapsulation header (DDS-XTypes 1.3 §7.6.3.1.2).
    pub(crate) fn new(data: &'a [u8]) -> Result<Self, String> {
        if data.len() < 4 {
            return Err(format!(
                "{} bytes: shorter than the 4-byte CDR encapsulation header",
                data.len()
            ));
        }
        let le = match [data[0], data[1]] {
            [0, 0] => false,
            [0, 1] => true,
            [0, 2] | [0, 3] => {
                return Err("parameter-list CDR (PL_CDR) is not a ROS 2 message encoding".into());
            }
            [a, b] => {
                return Err(format!(
                    "CDR representation {a:#04x}{b:02x} is not XCDR1 CDR_BE (0x0000) or CDR_LE (0x0001)"
                ));
            }
        };
        Ok(Cdr {
            buf: &data[4..],
            pos: 0,
            le,
        })
    }

    fn take(&mut self, n: usize, align: usize) -> Result<&'a [u8], String> {
        let start = self.pos.div_ceil(align) * align;
        match start.checked_add(n) {
            Some(end) if end <= self.buf.len() => {
                self.pos = end;
                Ok(&self.buf[start..end])
            }
            _ => Err(format!(
                "truncated: {n} more bytes needed at offset {start} of a {}-byte body",
                self.buf.len()
            )),
        }
    }

    fn array<const N: usize>(&mut self, align: usize) -> Result<[u8; N], String> {
        let b = self.take(N, align)?;
        let mut a = [0u8; N];
        a.copy_from_slice(b);
        if self.le != cfg!(target_endian = "little") {
            a.reverse();
        }
        Ok(a)
    }

    pub(crate) fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1, 1)?[0])
    }
    pub(crate) fn i8(&mut self) -> Result<i8, String> {
        Ok(self.u8()? as i8)
    }
    pub(crate) fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_ne_bytes(self.array(2)?))
    }
    pub(crate) fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_ne_bytes(self.array(4)?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_ne_bytes(self.array(4)?))
    }
    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_ne_bytes(self.array(8)?))
    }
    pub(crate) fn f64s<const N: usize>(&mut self) -> Result<[f64; N], String> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f64()?;
        }
        Ok(a)
    }
    /// A CDR string: uint32 length counting the NUL, the bytes, the NUL.
    pub(crate) fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        let b = self.take(n, 1)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Ok(String::from_utf8_lossy(b).into_owned())
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub sec: i32,
    pub nanosec: u32,
    pub(crate) frame_id: String,
}

impl Header {
    fn read(c: &mut Cdr) -> Result<Self, String> {
        Ok(Header {
            sec: c.i32()?,
            nanosec: c.u32()?,
            frame_id: c.string()?,
        })
    }

    /// The stamp in ns since the Unix epoch (`builtin_interfaces/Time`
    /// requires nanosec < 10⁹).
    pub fn unix_ns(&self) -> Result<i64, String> {
        if self.nanosec >= 1_000_000_000 {
            return Err(format!(
                "header.stamp nanosec {} is not below 10^9",
                self.nanosec
            ));
        }
        Ok(self.sec as i64 * 1_000_000_000 + self.nanosec as i64)
    }
}

/// `sensor_msgs/msg/Imu` (body axes as sent, FLU by REP 103).
#[derive(Clone, Debug, PartialEq)]
pub struct Imu {
    pub header: Header,
    pub(crate) orientation_xyzw: [f64; 4],
    pub(crate) orientation_covariance: [f64; 9],
    pub angular_velocity: [f64; 3],
    pub(crate) angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: [f64; 3],
    pub(crate) linear_acceleration_covariance: [f64; 9],
}

impl Imu {
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        let mut c = Cdr::new(data)?;
        Ok(Imu {
            header: Header::read(&mut c)?,
            orientation_xyzw: c.f64s()?,
            orientation_covariance: c.f64s()?,
            angular_velocity: c.f64s()?,
            angular_velocity_covariance: c.f64s()?,
            linear_acceleration: c.f64s()?,
            linear_acceleration_covariance: c.f64s()?,
        })
    }
}

/// `sensor_msgs/msg/NavSatFix` (with its `NavSatStatus`).
#[derive(Clone, Debug, PartialEq)]
pub struct NavSatFix {
    pub header: Header,
    /// -1 NO_FIX, 0 FIX, 1 SBAS_FIX, 2 GBAS_FIX.
    pub status: i8,
    pub(crate) service: u16,
    pub(crate) latitude_deg: f64,
    pub(crate) longitude_deg: f64,
    /// Above the WGS 84 ellipsoid (the message's definition).
    pub(crate) altitude_m: f64,
    /// ENU, row-major, m².
    pub position_covariance: [f64; 9],
    /// 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub(crate) position_covariance_type: u8,
}

impl NavSatFix {
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        let mut c = Cdr::new(data)?;
        Ok(NavSatFix {
            header: Header::read(&mut c)?,
            status: c.i8()?,
            service: c.u16()?,
            latitude_deg: c.f64()?,
            longitude_deg: c.f64()?,
            altitude_m: c.f64()?,
            position_covariance: c.f64s()?,
            position_covariance_type: c.u8()?,
        })
    }
}

/// `geometry_msgs/msg/TwistWithCovarianceStamped`.
#[derive(Clone, Debug, PartialEq)]
pub struct TwistStamped {
    pub header: Header,
    pub linear: [f64; 3],
    pub angular: [f64; 3],
    /// 6×6 row-major (linear xyz, angular xyz).
    pub covariance: [f64; 36],
}

impl TwistStamped {
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        let mut c = Cdr::new(data)?;
        Ok(TwistStamped {
            header: Header::read(&mut c)?,
            linear: c.f64s()?,
            angular: c.f64s()?,
            covariance: c.f64s()?,
        })
    }
}

/// Which topics to read; `None` picks the only topic of the schema.
#[derive(Clone, Debug, Default)]
pub struct TopicChoice {
    pub imu: Option<String>,
    pub gnss: Option<String>,
    pub velocity: Option<String>,
}

/// `log_time − header.stamp` over a topic's messages (s).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct StampLag {
    pub min_s: f64,
    pub median_s: f64,
    pub max_s: f64,
}

/// One topic of the bag.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct TopicSummary {
    pub topic: String,
    pub schema: String,
    pub(crate) message_encoding: String,
    pub messages: u64,
    /// What navsync used it for (`imu`, `gnss`, `velocity`), if anything.
    pub role: Option<String>,
    /// Messages that went into the output.
    pub used: u64,
    pub log_time_minus_stamp: Option<StampLag>,
}

/// What the bag held.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BagSummary {
    pub topics: Vec<TopicSummary>,
    /// Messages before a read error that ended the file early, if one did.
    pub stopped_early: Option<String>,
    /// Fixes given a velocity from the velocity topic (same stamp).
    pub fixes_with_velocity: usize,
}

/// A fix with where its σ came from.
#[derive(Clone, Debug)]
pub struct BagFix {
    pub fix: GnssFix,
    pub default_sd: bool,
}

/// The IMU samples, fixes and drop counts read from a bag.
#[derive(Clone, Debug, Default)]
pub struct BagData {
    pub imu: Vec<RateSample>,
    pub imu_topic: Option<String>,
    pub fixes: Vec<BagFix>,
    pub gnss_topic: Option<String>,
    /// NavSatFix messages that gave no fix, by reason.
    pub(crate) fix_drops: BTreeMap<String, u64>,
    pub(crate) fix_messages: u64,
    pub summary: BagSummary,
}

enum Decoded {
    Imu(Imu),
    Fix(NavSatFix),
    Twist(TwistStamped),
}

struct Item {
    /// 1-based message number in the file.
    number: u64,
    log_time: u64,
    msg: Result<Decoded, String>,
}

#[derive(Default)]
struct Topic {
    summary: TopicSummary,
    items: Vec<Item>,
}

/// Reads the messages of a bag (the whole MCAP file in `bytes`) from the
/// chosen topics. `path` names the file in errors and diagnostics; each
/// skipped message is named by its number in the file, topic and log time.
pub fn read_bag(
    bytes: &[u8],
    path: &Path,
    choice: &TopicChoice,
    opts_default_sd: [f64; 3],
    diag: &mut Diagnostics,
) -> Result<BagData, Error> {
    let nodata = |msg: String| Error::NoData {
        path: path.to_path_buf(),
        msg,
    };
    // mcap 0.26 panics on a record length near u64::MAX (its offset sum
    // overflows): cut the file at the first record that overruns it.
    let (bytes, overrun) = frame_records(bytes);
    if let Some(off) = overrun {
        diag.push(
            path,
            0,
            format!(
                "the record at byte {off} claims more bytes than the file holds: read up to it"
            ),
        );
    }
    let stream = mcap::MessageStream::new(bytes).map_err(|e| nodata(mcap_error(&e)))?;
    let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
    let mut stopped = None;
    for (read, m) in stream.enumerate() {
        // Messages are named by their 1-based number in the file.
        let number = read as u64 + 1;
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                if read == 0 {
                    return Err(nodata(mcap_error(&e)));
                }
                let why = format!(
                    "reading stopped after message {read}: {}; the messages before it are used \
                     (`mcap recover` rewrites what a damaged file still holds)",
                    mcap_error(&e)
                );
                diag.push(path, 0, why.clone());
                stopped = Some(why);
                break;
            }
        };
        let ch = &m.channel;
        let schema = ch
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        let t = topics.entry(ch.topic.clone()).or_insert_with(|| Topic {
            summary: TopicSummary {
                topic: ch.topic.clone(),
                schema: schema.clone(),
                message_encoding: ch.message_encoding.clone(),
                ..Default::default()
            },
            items: Vec::new(),
        });
        t.summary.messages += 1;
        if ch.message_encoding != "cdr" {
            continue;
        }
        let msg = match schema.as_str() {
            IMU_SCHEMA => Imu::decode(&m.data).map(Decoded::Imu),
            NAVSATFIX_SCHEMA => NavSatFix::decode(&m.data).map(Decoded::Fix),
            TWIST_SCHEMA => TwistStamped::decode(&m.data).map(Decoded::Twist),
            _ => continue,
        };
        t.items.push(Item {
            number,
            log_time: m.log_time,
            msg,
        });
    }
    let listing = || {
        if topics.is_empty() {
            "the file holds no message".to_string()
        } else {
            let l: Vec<String> = topics
                .values()
                .map(|t| {
                    format!(
                        "{} ({}, {}, {} messages)",
                        t.summary.topic,
                        t.summary.schema,
                        t.summary.message_encoding,
                        t.summary.messages
                    )
                })
                .collect();
            format!("topics: {}", l.join("; "))
        }
    };
    let pick =
        |wanted: &Option<String>, schema: &str, option: &str| -> Result<Option<String>, Error> {
            if let Some(name) = wanted {
                let Some(t) = topics.get(name) else {
                    return Err(nodata(format!("no topic {name} ({option}); {}", listing())));
                };
                if t.summary.schema != schema {
                    return Err(nodata(format!(
                        "topic {name} ({option}) has schema {}, not {schema}",
                        if t.summary.schema.is_empty() {
                            "(none)"
                        } else {
                            &t.summary.schema
                        }
                    )));
                }
                if t.summary.message_encoding != "cdr" {
                    return Err(nodata(format!(
                        "topic {name} has message encoding {}; navsync reads ROS 2 CDR (`cdr`)",
                        t.summary.message_encoding
                    )));
                }
                return Ok(Some(name.clone()));
            }
            let found: Vec<&String> = topics
                .iter()
                .filter(|(_, t)| t.summary.schema == schema && t.summary.message_encoding == "cdr")
                .map(|(k, _)| k)
                .collect();
            match found.as_slice() {
                [] => Ok(None),
                [one] => Ok(Some((*one).clone())),
                many => Err(nodata(format!(
                    "{} topics have schema {schema} ({}): choose one with {option}",
                    many.len(),
                    many.iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))),
            }
        };
    let imu_topic = pick(&choice.imu, IMU_SCHEMA, "--imu-topic")?;
    let gnss_topic = pick(&choice.gnss, NAVSATFIX_SCHEMA, "--gnss-topic")?;
    let vel_topic = pick(&choice.velocity, TWIST_SCHEMA, "--velocity-topic")?;
    if imu_topic.is_none() && gnss_topic.is_none() {
        return Err(nodata(format!(
            "no {IMU_SCHEMA} or {NAVSATFIX_SCHEMA} topic in CDR encoding; {}",
            listing()
        )));
    }
    let mut out = BagData {
        imu_topic: imu_topic.clone(),
        gnss_topic: gnss_topic.clone(),
        ..Default::default()
    };
    let mut lags: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let skip = |diag: &mut Diagnostics, topic: &str, it: &Item, why: &str| {
        diag.push(
            path,
            0,
            format!(
                "message {} on {topic} (log time {} ns): {why}; skipped",
                it.number, it.log_time
            ),
        );
    };

    if let Some(name) = &imu_topic {
        let t = &topics[name];
        let mut last = None;
        let lag = lags.entry(name.clone()).or_default();
        for it in &t.items {
            let m = match &it.msg {
                Ok(Decoded::Imu(m)) => m,
                Ok(_) => continue,
                Err(e) => {
                    skip(diag, name, it, e);
                    continue;
                }
            };
            let time = match stamp_to_gps(&m.header) {
                Ok(t) => t,
                Err(e) => {
                    skip(diag, name, it, &e);
                    continue;
                }
            };
            let vals = m.angular_velocity.iter().chain(&m.linear_acceleration);
            if vals.clone().any(|v| !v.is_finite()) {
                skip(
                    diag,
                    name,
                    it,
                    "non-finite angular velocity or linear acceleration",
                );
                continue;
            }
            if let Some(why) = time_order_problem(last, time) {
                skip(diag, name, it, &format!("header.stamp: {why}"));
                continue;
            }
            last = Some(time);
            lag.push(lag_s(it, &m.header));
            let [wx, wy, wz] = m.angular_velocity;
            let [ax, ay, az] = m.linear_acceleration;
            // REP 103 body FLU → FRD.
            out.imu.push(RateSample {
                time,
                gyro_radps: Vector3::new(wx, -wy, -wz),
                accel_mps2: Vector3::new(ax, -ay, -az),
            });
        }
    }

    // Velocities by stamp (ns), ENU → NED.
    let mut vels: BTreeMap<i64, (Vector3<f64>, Option<Vector3<f64>>)> = BTreeMap::new();
    if let Some(name) = &vel_topic {
        let lag = lags.entry(name.clone()).or_default();
        for it in &topics[name].items {
            let m = match &it.msg {
                Ok(Decoded::Twist(m)) => m,
                Ok(_) => continue,
                Err(e) => {
                    skip(diag, name, it, e);
                    continue;
                }
            };
            let Ok(ns) = m.header.unix_ns() else {
                skip(diag, name, it, "header.stamp nanosec not below 10^9");
                continue;
            };
            let [e, n, u] = m.linear;
            if !(e.is_finite() && n.is_finite() && u.is_finite()) {
                skip(diag, name, it, "non-finite velocity");
                continue;
            }
            let c = &m.covariance;
            let sd = [c[7], c[0], c[14]]
                .iter()
                .all(|v| v.is_finite() && *v > 0.0)
                .then(|| Vector3::new(c[7].sqrt(), c[0].sqrt(), c[14].sqrt()));
            lag.push(lag_s(it, &m.header));
            vels.insert(ns, (Vector3::new(n, e, -u), sd));
        }
    }

    if let Some(name) = &gnss_topic {
        let lag = lags.entry(name.clone()).or_default();
        let mut last = None;
        let mut count_drop = |reason: String| *out.fix_drops.entry(reason).or_insert(0) += 1;
        for it in &topics[name].items {
            out.fix_messages += 1;
            let m = match &it.msg {
                Ok(Decoded::Fix(m)) => m,
                Ok(_) => continue,
                Err(e) => {
                    skip(diag, name, it, e);
                    count_drop("message does not decode".into());
                    continue;
                }
            };
            if m.status < 0 {
                count_drop(format!("status {} (NO_FIX)", m.status));
                continue;
            }
            let time = match stamp_to_gps(&m.header) {
                Ok(t) => t,
                Err(e) => {
                    skip(diag, name, it, &e);
                    count_drop("unusable header.stamp".into());
                    continue;
                }
            };
            let (lat, lon, h) = (m.latitude_deg, m.longitude_deg, m.altitude_m);
            if !(lat.is_finite() && lon.is_finite() && h.is_finite())
                || lat.abs() > 90.0
                || lon.abs() > 180.0
            {
                skip(
                    diag,
                    name,
                    it,
                    &format!("latitude {lat} / longitude {lon} / altitude {h} not a position"),
                );
                count_drop("non-finite or out-of-range position".into());
                continue;
            }
            if let Some(why) = time_order_problem(last, time) {
                skip(diag, name, it, &format!("header.stamp: {why}"));
                count_drop("header.stamp not after the previous fix".into());
                continue;
            }
            last = Some(time);
            lag.push(lag_s(it, &m.header));
            let c = &m.position_covariance;
            // ENU covariance → σ north, east, down.
            let diag_ned = [c[4], c[0], c[8]];
            let known = m.position_covariance_type > 0
                && diag_ned.iter().all(|v| v.is_finite() && *v > 0.0);
            if m.position_covariance_type > 0 && !known {
                skip(
                    diag,
                    name,
                    it,
                    "covariance type says known but its diagonal is not positive: default σ used",
                );
            }
            let pos_sd = if known {
                Vector3::new(diag_ned[0].sqrt(), diag_ned[1].sqrt(), diag_ned[2].sqrt())
            } else {
                Vector3::from(opts_default_sd)
            };
            let (vel, vel_sd) = match m.header.unix_ns().ok().and_then(|ns| vels.get(&ns)) {
                Some((v, sd)) => (Some(*v), *sd),
                None => (None, None),
            };
            out.fixes.push(BagFix {
                fix: GnssFix {
                    time,
                    pos: Geodetic::from_deg(lat, lon, h),
                    pos_sd,
                    vel,
                    vel_sd,
                },
                default_sd: !known,
            });
        }
        // KF-GINS files have 7 or 13 columns throughout: velocities only
        // when every fix has one (with its σ).
        let with = out
            .fixes
            .iter()
            .filter(|f| f.fix.vel.is_some() && f.fix.vel_sd.is_some())
            .count();
        if with < out.fixes.len() {
            if with > 0 {
                diag.note(format!(
                    "{with} of {} fixes have a velocity with σ from the velocity topic (same header.stamp); \
                     gnss.txt keeps positions only",
                    out.fixes.len()
                ));
            }
            for f in &mut out.fixes {
                f.fix.vel = None;
                f.fix.vel_sd = None;
            }
            out.summary.fixes_with_velocity = 0;
        } else {
            out.summary.fixes_with_velocity = with;
        }
    }

    for (name, t) in &mut topics {
        let role = if Some(name) == imu_topic.as_ref() {
            Some(("imu", out.imu.len() as u64))
        } else if Some(name) == gnss_topic.as_ref() {
            Some(("gnss", out.fixes.len() as u64))
        } else if Some(name) == vel_topic.as_ref() {
            Some(("velocity", out.summary.fixes_with_velocity as u64))
        } else {
            None
        };
        if let Some((r, n)) = role {
            t.summary.role = Some(r.into());
            t.summary.used = n;
        }
        if let Some(l) = lags.get_mut(name)
            && !l.is_empty()
        {
            l.sort_by(f64::total_cmp);
            let lag = StampLag {
                min_s: l[0],
                median_s: l[l.len() / 2],
                max_s: l[l.len() - 1],
            };
            if let Some(why) = lag_problem(lag.median_s) {
                diag.push(path, 0, format!(
                    "{name}: log_time − header.stamp is {:+.3} s (median; min {:+.3}, max {:+.3}): {why}",
                    lag.median_s,
                    lag.min_s,
                    lag.max_s
                ));
            }
            t.summary.log_time_minus_stamp = Some(lag);
        }
    }
    out.summary.topics = topics.into_values().map(|t| t.summary).collect();
    out.summary.stopped_early = stopped;
    Ok(out)
}

/// `bytes` up to the first top-level record whose length runs past the
/// end (MCAP spec, "Records": opcode u8, length u64 LE, body; after the
/// 8-byte magic), and that record's offset, if one does.
pub(crate) fn frame_records(bytes: &[u8]) -> (&[u8], Option<usize>) {
    let mut pos = 8;
    while let Some(h) = bytes.get(pos..pos + 9) {
        let mut len = [0u8; 8];
        len.copy_from_slice(&h[1..]);
        let len = u64::from_le_bytes(len);
        let left = (bytes.len() - pos - 9) as u64;
        if len > left {
            return (&bytes[..pos], Some(pos));
        }
        pos += 9 + len as usize;
    }
    (bytes, None)
}

fn lag_s(it: &Item, h: &Header) -> f64 {
    let stamp = h.unix_ns().unwrap_or(0) as i128;
    (it.log_time as i128 - stamp) as f64 * 1e-9
}

/// Why a median `log_time − header.stamp` looks systematic, if it does:
/// transport delays are milliseconds, so half a second or more means the
/// stamps are on another clock.
pub(crate) fn lag_problem(median_s: f64) -> Option<String> {
    let a = median_s.abs();
    if a < 0.5 {
        None
    } else if (a - 18.0).abs() < 0.5 {
        Some(
            "about the 18 s GPS − UTC: one of the two is GPS time, not UTC; \
             header.stamp is taken as UTC (correct with --imu-time-offset-s)"
                .into(),
        )
    } else if a > 86_400.0 {
        Some(
            "header.stamp is not on the recorder's (Unix) clock: sim time or a sensor/boot clock? \
             Times in the output follow header.stamp"
                .into(),
        )
    } else {
        Some(
            "a systematic offset, not transport delay: check the driver's stamping; \
             times in the output follow header.stamp"
                .into(),
        )
    }
}

/// GPS time of a ROS `header.stamp` taken as UTC (Unix time), with the
/// leap-second table.
pub(crate) fn stamp_to_gps(h: &Header) -> Result<GpsTime, String> {
    let ns = h.unix_ns()?;
    // 1980-01-06 in Unix seconds: earlier stamps are not Unix time.
    if h.sec < 315_964_800 {
        return Err(format!(
            "header.stamp {}.{:09} s is before the GPS epoch (1980-01-06): not Unix time (sim time or a boot clock?)",
            h.sec, h.nanosec
        ));
    }
    Ok(utc_to_gps(&UtcTime::from_unix_ns(ns)))
}

/// An MCAP read error in words, with what to do where there is something.
pub fn mcap_error(e: &mcap::McapError) -> String {
    use mcap::McapError as M;
    match e {
        M::UnsupportedCompression(c) => format!(
            "chunks compressed with \"{c}\", which MCAP does not define \
             (chunks are uncompressed, zstd or lz4)"
        ),
        M::BadMagic => {
            "not an MCAP file (bad magic bytes); a ROS 2 bag folder holds .mcap or .db3 files: \
             pass the .mcap (a .db3 bag needs `ros2 bag convert` to mcap first)"
                .into()
        }
        M::UnexpectedEof | M::UnexpectedEoc => format!("{e}: the file is truncated"),
        _ => format!("MCAP: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_headers_and_alignment() {
        // Big endian: int32 1, uint32 2, string "ab" (ends at 15), then an
        // f64 aligned to 8 from the end of the encapsulation header: one
        // pad byte (from the message start it would be five).
        let mut be = vec![0, 0, 0, 0];
        be.extend_from_slice(&1i32.to_be_bytes());
        be.extend_from_slice(&2u32.to_be_bytes());
        be.extend_from_slice(&3u32.to_be_bytes());
        be.extend_from_slice(b"ab\0");
        be.push(0);
        be.extend_from_slice(&1.5f64.to_be_bytes());
        let mut c = Cdr::new(&be).unwrap();
        let h = Header::read(&mut c).unwrap();
        assert_eq!((h.sec, h.nanosec, h.frame_id.as_str()), (1, 2, "ab"));
        assert_eq!(c.f64().unwrap(), 1.5);
        assert!(c.u8().unwrap_err().contains("truncated"));
        assert!(Cdr::new(&[0, 1, 0]).is_err());
        assert!(Cdr::new(&[0, 3, 0, 0]).unwrap_err().contains("PL_CDR"));
        assert!(Cdr::new(&[0, 0x11, 0, 0]).unwrap_err().contains("XCDR1"));
        // A string longer than the body is an error, not a panic.
        let mut s = vec![0, 1, 0, 0];
        s.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(Cdr::new(&s).unwrap().string().is_err());
    }

    #[test]
    fn records_overrunning_the_file_are_cut_off() {
        // Magic, then a header record whose length is u64::MAX (the fuzzer's
        // input that panics mcap 0.26).
        let mut f = b"\x89MCAP0\r\n".to_vec();
        f.push(1);
        f.extend_from_slice(&[0xff; 8]);
        f.extend_from_slice(&[0; 20]);
        assert_eq!(frame_records(&f), (&f[..8], Some(8)));
        let mut d = Diagnostics::default();
        let e = read_bag(
            &f,
            Path::new("x.mcap"),
            &TopicChoice::default(),
            [1.0; 3],
            &mut d,
        );
        assert!(e.is_err() && d.items[0].message.contains("byte 8"), "{d:?}");
        // Whole records pass untouched.
        let mut g = f[..8].to_vec();
        g.push(1);
        g.extend_from_slice(&3u64.to_le_bytes());
        g.extend_from_slice(b"abc");
        assert_eq!(frame_records(&g), (&g[..], None));
    }

    #[test]
    fn stamps_become_gps_time() {
        // 2024-01-01T00:00:00Z = 1704067200 Unix; GPS week 2295, day 1,
        // + 18 leap seconds.
        let h = Header {
            sec: 1_704_067_200,
            nanosec: 500_000_000,
            frame_id: String::new(),
        };
        let t = stamp_to_gps(&h).unwrap();
        assert_eq!(t.week(), 2295);
        assert!((t.sow() - (86_400.0 + 18.5)).abs() < 1e-9, "{}", t.sow());
        let boot = Header {
            sec: 1234,
            ..h.clone()
        };
        assert!(stamp_to_gps(&boot).unwrap_err().contains("GPS epoch"));
        let bad = Header {
            nanosec: 1_000_000_000,
            ..h
        };
        assert!(stamp_to_gps(&bad).is_err());
        assert!(lag_problem(0.02).is_none());
        assert!(lag_problem(-18.0).unwrap().contains("18 s"));
        assert!(lag_problem(1.7e9).unwrap().contains("sim time"));
    }
}
