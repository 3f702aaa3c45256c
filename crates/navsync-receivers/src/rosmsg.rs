//! The ROS messages navsync reads and what it makes of them, shared by
//! ROS 1 bags ([`crate::ros1`], ROS 1 serialization) and ROS 2 bags
//! ([`crate::ros2`], CDR): `sensor_msgs/Imu`, `sensor_msgs/NavSatFix`,
//! `geometry_msgs/TwistWithCovarianceStamped`, `geometry_msgs/TwistStamped`
//! and `nav_msgs/Odometry`, decoded through one [`Wire`] reader per
//! serialization, then turned into IMU rates, fixes and speeds on GPS time.
//!
//! - Times: `header.stamp` is ROS time, i.e. Unix time (UTC) when recorded
//!   from the system clock; it becomes GPS time with the leap-second table.
//!   The recorder's time of each message (MCAP `log_time`, ROS 1 record
//!   `time`) is compared with it per topic.
//! - Frames (REP 103): IMU axes are body FLU, turned into navsync's FRD
//!   (y and z negated); NavSatFix covariance and world-frame Twist
//!   velocities are ENU, turned into NED. Odometry's twist is in its
//!   `child_frame_id` (the vehicle body, x forward): `linear.x` is the
//!   forward speed.
//! - NavSatFix altitude: "Altitude [m]. Positive is above the WGS 84
//!   ellipsoid" (sensor_msgs/NavSatFix.msg), but many drivers write height
//!   above mean sea level: [`AltitudeDatum`] says which to assume.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::Vector3;
use navsync::earth::Geodetic;
use navsync::error::{Diagnostics, Error};
use navsync::filter::gnss::GnssFix;
use navsync::io::text::time_order_problem;
use navsync::time::GpsTime;

use crate::geoid::{EGM96_SOURCE, Egm96Grid};
use crate::gnsstime::{UtcTime, utc_to_gps};
use crate::imu::RateSample;

/// A message body reader of one serialization (CDR or ROS 1).
pub(crate) trait Wire {
    fn u8(&mut self) -> Result<u8, String>;
    fn u16(&mut self) -> Result<u16, String>;
    fn u32(&mut self) -> Result<u32, String>;
    fn f64(&mut self) -> Result<f64, String>;
    fn string(&mut self) -> Result<String, String>;
    /// `std_msgs/Header` (ROS 1 has a `seq` first; ROS 2 does not).
    fn header(&mut self) -> Result<Header, String>;
    fn i8(&mut self) -> Result<i8, String> {
        Ok(self.u8()? as i8)
    }
    fn f64s<const N: usize>(&mut self) -> Result<[f64; N], String> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f64()?;
        }
        Ok(a)
    }
}

/// `std_msgs/Header`: the stamp and frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Seconds since the Unix epoch (ROS 1 `time`: uint32; ROS 2
    /// `builtin_interfaces/Time`: int32).
    pub sec: i64,
    pub nanosec: u32,
    pub(crate) frame_id: String,
}

impl Header {
    /// The stamp in ns since the Unix epoch (nanosec must be < 10⁹).
    pub fn unix_ns(&self) -> Result<i64, String> {
        if self.nanosec >= 1_000_000_000 {
            return Err(format!(
                "header.stamp nanosec {} is not below 10^9",
                self.nanosec
            ));
        }
        Ok(self.sec * 1_000_000_000 + self.nanosec as i64)
    }
}

/// `sensor_msgs/Imu` (body axes as sent, FLU by REP 103).
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
    pub(crate) fn read(c: &mut impl Wire) -> Result<Self, String> {
        Ok(Imu {
            header: c.header()?,
            orientation_xyzw: c.f64s()?,
            orientation_covariance: c.f64s()?,
            angular_velocity: c.f64s()?,
            angular_velocity_covariance: c.f64s()?,
            linear_acceleration: c.f64s()?,
            linear_acceleration_covariance: c.f64s()?,
        })
    }
}

/// `sensor_msgs/NavSatFix` (with its `NavSatStatus`).
#[derive(Clone, Debug, PartialEq)]
pub struct NavSatFix {
    pub header: Header,
    /// -1 NO_FIX, 0 FIX, 1 SBAS_FIX, 2 GBAS_FIX.
    pub status: i8,
    pub(crate) service: u16,
    pub(crate) latitude_deg: f64,
    pub(crate) longitude_deg: f64,
    /// Above the WGS 84 ellipsoid by the message's definition.
    pub(crate) altitude_m: f64,
    /// ENU, row-major, m².
    pub position_covariance: [f64; 9],
    /// 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub(crate) position_covariance_type: u8,
}

impl NavSatFix {
    pub(crate) fn read(c: &mut impl Wire) -> Result<Self, String> {
        Ok(NavSatFix {
            header: c.header()?,
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

/// `geometry_msgs/TwistWithCovarianceStamped`, or `TwistStamped` (its
/// covariance then all zero: unknown).
#[derive(Clone, Debug, PartialEq)]
pub struct TwistStamped {
    pub header: Header,
    pub linear: [f64; 3],
    pub angular: [f64; 3],
    /// 6×6 row-major (linear xyz, angular xyz).
    pub covariance: [f64; 36],
}

impl TwistStamped {
    pub(crate) fn read(c: &mut impl Wire, with_covariance: bool) -> Result<Self, String> {
        Ok(TwistStamped {
            header: c.header()?,
            linear: c.f64s()?,
            angular: c.f64s()?,
            covariance: if with_covariance {
                c.f64s()?
            } else {
                [0.0; 36]
            },
        })
    }
}

/// `nav_msgs/Odometry`: the pose is read past, the twist kept (in the
/// `child_frame_id` frame).
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub linear: [f64; 3],
    pub angular: [f64; 3],
    /// Twist covariance, 6×6 row-major.
    pub twist_covariance: [f64; 36],
}

impl Odometry {
    pub(crate) fn read(c: &mut impl Wire) -> Result<Self, String> {
        let header = c.header()?;
        let child_frame_id = c.string()?;
        // PoseWithCovariance: Point (3), Quaternion (4), float64[36].
        let _pose: [f64; 7] = c.f64s()?;
        let _pose_cov: [f64; 36] = c.f64s()?;
        Ok(Odometry {
            header,
            child_frame_id,
            linear: c.f64s()?,
            angular: c.f64s()?,
            twist_covariance: c.f64s()?,
        })
    }
}

/// The message types navsync reads.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum MsgKind {
    Imu,
    Fix,
    /// `TwistWithCovarianceStamped`: an ENU velocity.
    TwistCov,
    /// `TwistStamped`: an ENU velocity or a body-frame speed, by its frame.
    Twist,
    Odom,
}

#[derive(Debug)]
pub(crate) enum Decoded {
    Imu(Imu),
    Fix(NavSatFix),
    Twist(TwistStamped),
    Odom(Odometry),
}

/// One message of a topic.
pub(crate) struct Item {
    /// 1-based message number in the file.
    pub number: u64,
    /// The recorder's time (ns since the Unix epoch).
    pub log_time: u64,
    pub msg: Result<Decoded, String>,
}

/// A topic's messages as read by a container reader.
#[derive(Default)]
pub(crate) struct Topic {
    pub summary: TopicSummary,
    /// What its messages are, when navsync reads them.
    pub kind: Option<MsgKind>,
    /// Why a topic of a type navsync knows cannot be read (encoding,
    /// layout), if it cannot.
    pub unusable: Option<String>,
    pub items: Vec<Item>,
}

/// The container's names for things, in messages.
pub(crate) struct Dialect {
    /// `ROS 1` or `ROS 2`.
    pub name: &'static str,
    pub imu: &'static str,
    pub fix: &'static str,
    pub velocity: &'static str,
    pub speed: &'static str,
    /// Auto choice of the IMU topic: the one with most messages (else
    /// several are an error).
    pub imu_most_messages: bool,
}

/// Which topics to read; `None` picks the topic of the type (the only
/// one, or for ROS 1 IMUs the one with most messages).
#[derive(Clone, Debug, Default)]
pub struct TopicChoice {
    pub imu: Option<String>,
    pub gnss: Option<String>,
    /// ENU velocity: `TwistWithCovarianceStamped`, or `TwistStamped` in a
    /// world frame (ROS 1).
    pub velocity: Option<String>,
    /// Forward speed: `nav_msgs/Odometry`, or `TwistStamped` in a body
    /// frame (ROS 1).
    pub odom: Option<String>,
}

/// Which height NavSatFix altitudes are.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum AltitudeDatum {
    /// Above the WGS 84 ellipsoid (the message's definition).
    #[default]
    Ellipsoid,
    /// Above mean sea level: the EGM96 geoid separation is added.
    Msl,
}

/// How to read a bag.
#[derive(Copy, Clone, Debug)]
pub struct BagOptions {
    /// σ N, E, D (m) of fixes without a known covariance.
    pub default_sd_m: [f64; 3],
    pub altitude: AltitudeDatum,
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
    /// What navsync used it for (`imu`, `gnss`, `velocity`, `speed`), if anything.
    pub role: Option<String>,
    /// Messages that went into the output.
    pub used: u64,
    pub log_time_minus_stamp: Option<StampLag>,
    /// Why a topic of a type navsync reads was not used, or how it was read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The odometer speeds a bag gave.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SpeedSummary {
    pub topic: String,
    /// What the speed is (`twist.twist.linear.x` of Odometry, in frame …).
    pub source: String,
    pub speeds: usize,
    /// Median σ from the message's covariance (m/s), when it has one.
    pub median_sd_mps: Option<f64>,
    pub min_mps: f64,
    pub max_mps: f64,
}

/// What the bag held.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BagSummary {
    pub topics: Vec<TopicSummary>,
    /// Messages before a read error that ended the file early, if one did.
    pub stopped_early: Option<String>,
    /// Fixes given a velocity from the velocity topic (same stamp).
    pub fixes_with_velocity: usize,
    /// The datum NavSatFix altitudes were taken in, and the conversion.
    pub altitude_datum: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub speed: Option<SpeedSummary>,
}

/// A fix with where its σ came from.
#[derive(Clone, Debug)]
pub struct BagFix {
    pub fix: GnssFix,
    pub default_sd: bool,
}

/// The IMU samples, fixes, speeds and drop counts read from a bag.
#[derive(Clone, Debug, Default)]
pub struct BagData {
    pub imu: Vec<RateSample>,
    pub imu_topic: Option<String>,
    pub fixes: Vec<BagFix>,
    pub gnss_topic: Option<String>,
    /// Forward speeds (m/s) at their GPS times.
    pub speeds: Vec<(GpsTime, f64)>,
    /// NavSatFix messages that gave no fix, by reason.
    pub(crate) fix_drops: BTreeMap<String, u64>,
    pub(crate) fix_messages: u64,
    pub summary: BagSummary,
}

/// Whether a frame name is a world (ENU) frame (REP 105: `map`, `odom`,
/// `earth`; GNSS drivers' `gps`, `enu`, `utm`, `world`) rather than the
/// vehicle body (`base_link`, …).
pub(crate) fn is_world_frame(frame: &str) -> bool {
    let f = frame.trim_start_matches('/').to_ascii_lowercase();
    ["map", "odom", "earth", "world", "enu", "utm", "gps", "gnss"]
        .iter()
        .any(|w| f.contains(w))
}

fn first_twist_frame(t: &Topic) -> Option<&str> {
    t.items.iter().find_map(|it| match &it.msg {
        Ok(Decoded::Twist(m)) => Some(m.header.frame_id.as_str()),
        _ => None,
    })
}

/// Whether topic `t` serves `role` (`imu`, `gnss`, `velocity`, `speed`).
fn serves(t: &Topic, role: &str) -> bool {
    match (t.kind, role) {
        (Some(MsgKind::Imu), "imu") | (Some(MsgKind::Fix), "gnss") => true,
        (Some(MsgKind::TwistCov), "velocity") | (Some(MsgKind::Odom), "speed") => true,
        (Some(MsgKind::Twist), "velocity") => first_twist_frame(t).is_some_and(is_world_frame),
        (Some(MsgKind::Twist), "speed") => first_twist_frame(t).is_some_and(|f| !is_world_frame(f)),
        _ => false,
    }
}

fn listing(topics: &BTreeMap<String, Topic>) -> String {
    if topics.is_empty() {
        return "the file holds no message".to_string();
    }
    let l: Vec<String> = topics
        .values()
        .map(|t| {
            format!(
                "{} ({}, {}, {} messages)",
                t.summary.topic, t.summary.schema, t.summary.message_encoding, t.summary.messages
            )
        })
        .collect();
    format!("topics: {}", l.join("; "))
}

/// The topic for `role`: the one asked for (checked), else the only one
/// (for the IMU of a [`Dialect::imu_most_messages`] bag, the largest).
fn pick(
    topics: &BTreeMap<String, Topic>,
    d: &Dialect,
    wanted: &Option<String>,
    role: &str,
    nodata: &dyn Fn(String) -> Error,
) -> Result<Option<String>, Error> {
    let (option, expected) = match role {
        "imu" => ("--imu-topic", d.imu),
        "gnss" => ("--gnss-topic", d.fix),
        "velocity" => ("--velocity-topic", d.velocity),
        _ => ("--odom-topic", d.speed),
    };
    if let Some(name) = wanted {
        let Some(t) = topics.get(name) else {
            return Err(nodata(format!(
                "no topic {name} ({option}); {}",
                listing(topics)
            )));
        };
        if let Some(why) = &t.unusable {
            return Err(nodata(format!("topic {name} ({option}): {why}")));
        }
        if !serves(t, role) {
            let schema = if t.summary.schema.is_empty() {
                "(none)"
            } else {
                &t.summary.schema
            };
            let frame = match (t.kind, first_twist_frame(t)) {
                (Some(MsgKind::Twist), Some(f)) => format!(" in frame {f:?}"),
                _ => String::new(),
            };
            return Err(nodata(format!(
                "topic {name} ({option}) has schema {schema}{frame}, not {expected}"
            )));
        }
        return Ok(Some(name.clone()));
    }
    let found: Vec<&Topic> = topics
        .values()
        .filter(|t| t.unusable.is_none() && serves(t, role))
        .collect();
    match found.as_slice() {
        [] => Ok(None),
        [one] => Ok(Some(one.summary.topic.clone())),
        many if role == "imu" && d.imu_most_messages => Ok(many
            .iter()
            .max_by_key(|t| t.summary.messages)
            .map(|t| t.summary.topic.clone())),
        many => Err(nodata(format!(
            "{} topics have schema {expected} ({}): choose one with {option}",
            many.len(),
            many.iter()
                .map(|t| t.summary.topic.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

/// Reports one skipped message.
fn skip(diag: &mut Diagnostics, path: &Path, topic: &str, it: &Item, why: &str) {
    diag.push(
        path,
        0,
        format!(
            "message {} on {topic} (log time {} ns): {why}; skipped",
            it.number, it.log_time
        ),
    );
}

/// Turns the topics a container reader collected into IMU rates, fixes
/// and speeds on GPS time (`path` names the file in messages).
pub(crate) fn assemble(
    mut topics: BTreeMap<String, Topic>,
    d: &Dialect,
    path: &Path,
    choice: &TopicChoice,
    opts: &BagOptions,
    diag: &mut Diagnostics,
) -> Result<BagData, Error> {
    let nodata = |msg: String| Error::NoData {
        path: path.to_path_buf(),
        msg,
    };
    let imu_topic = pick(&topics, d, &choice.imu, "imu", &nodata)?;
    let gnss_topic = pick(&topics, d, &choice.gnss, "gnss", &nodata)?;
    let vel_topic = pick(&topics, d, &choice.velocity, "velocity", &nodata)?;
    let speed_topic = pick(&topics, d, &choice.odom, "speed", &nodata)?;
    if imu_topic.is_none() && gnss_topic.is_none() {
        let why = if d.name == "ROS 2" {
            " in CDR encoding"
        } else {
            ""
        };
        return Err(nodata(format!(
            "no {} or {} topic{why}; {}",
            d.imu,
            d.fix,
            listing(&topics)
        )));
    }
    let mut out = BagData {
        imu_topic: imu_topic.clone(),
        gnss_topic: gnss_topic.clone(),
        ..Default::default()
    };
    let mut lags: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    if let Some(name) = &imu_topic {
        read_imu(
            &topics[name],
            path,
            &mut out,
            lags.entry(name.clone()).or_default(),
            diag,
        );
    }
    let vels = match &vel_topic {
        Some(name) => read_velocities(
            &topics[name],
            path,
            lags.entry(name.clone()).or_default(),
            diag,
        ),
        None => BTreeMap::new(),
    };
    if let Some(name) = &gnss_topic {
        let lag = lags.entry(name.clone()).or_default();
        read_fixes(&topics[name], path, opts, &vels, &mut out, lag, diag);
    }
    out.summary.altitude_datum = match opts.altitude {
        AltitudeDatum::Ellipsoid => {
            "ellipsoid: NavSatFix altitude taken as height above the WGS 84 ellipsoid (the message's \
             definition; --ros-altitude msl if the driver wrote mean sea level)"
                .into()
        }
        AltitudeDatum::Msl => format!(
            "msl: NavSatFix altitude taken as height above mean sea level (--ros-altitude msl); \
             ellipsoidal height = altitude + geoid separation from the {EGM96_SOURCE}"
        ),
    };
    if let Some(name) = &speed_topic {
        let lag = lags.entry(name.clone()).or_default();
        out.summary.speed = Some(read_speeds(&topics[name], path, &mut out, lag, diag));
    }

    for (name, t) in &mut topics {
        let role = if Some(name) == imu_topic.as_ref() {
            Some(("imu", out.imu.len() as u64))
        } else if Some(name) == gnss_topic.as_ref() {
            Some(("gnss", out.fixes.len() as u64))
        } else if Some(name) == vel_topic.as_ref() {
            Some(("velocity", out.summary.fixes_with_velocity as u64))
        } else if Some(name) == speed_topic.as_ref() {
            Some(("speed", out.speeds.len() as u64))
        } else {
            None
        };
        if let Some((r, n)) = role {
            t.summary.role = Some(r.into());
            t.summary.used = n;
        }
        if t.summary.note.is_none() {
            t.summary.note = t.unusable.clone().or_else(|| match (t.kind, role) {
                (Some(_), None) => Some(
                    "not used: another topic of its role was chosen (--imu-topic, --gnss-topic, \
                     --velocity-topic, --odom-topic)"
                        .into(),
                ),
                _ => None,
            });
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
                diag.push(
                    path,
                    0,
                    format!(
                        "{name}: log_time − header.stamp is {:+.3} s (median; min {:+.3}, max {:+.3}): {why}",
                        lag.median_s, lag.min_s, lag.max_s
                    ),
                );
            }
            t.summary.log_time_minus_stamp = Some(lag);
        }
    }
    out.summary.topics = topics.into_values().map(|t| t.summary).collect();
    Ok(out)
}

fn read_imu(t: &Topic, path: &Path, out: &mut BagData, lag: &mut Vec<f64>, diag: &mut Diagnostics) {
    let name = &t.summary.topic;
    let mut last = None;
    for it in &t.items {
        let m = match &it.msg {
            Ok(Decoded::Imu(m)) => m,
            Ok(_) => continue,
            Err(e) => {
                skip(diag, path, name, it, e);
                continue;
            }
        };
        let time = match stamp_to_gps(&m.header) {
            Ok(t) => t,
            Err(e) => {
                skip(diag, path, name, it, &e);
                continue;
            }
        };
        let vals = m.angular_velocity.iter().chain(&m.linear_acceleration);
        if vals.clone().any(|v| !v.is_finite()) {
            let why = "non-finite angular velocity or linear acceleration";
            skip(diag, path, name, it, why);
            continue;
        }
        if let Some(why) = time_order_problem(last, time) {
            skip(diag, path, name, it, &format!("header.stamp: {why}"));
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

type Velocities = BTreeMap<i64, (Vector3<f64>, Option<Vector3<f64>>)>;

/// Velocities by stamp (ns), ENU → NED, with σ when the covariance has one.
fn read_velocities(
    t: &Topic,
    path: &Path,
    lag: &mut Vec<f64>,
    diag: &mut Diagnostics,
) -> Velocities {
    let name = &t.summary.topic;
    let mut vels = BTreeMap::new();
    for it in &t.items {
        let m = match &it.msg {
            Ok(Decoded::Twist(m)) => m,
            Ok(_) => continue,
            Err(e) => {
                skip(diag, path, name, it, e);
                continue;
            }
        };
        let Ok(ns) = m.header.unix_ns() else {
            skip(diag, path, name, it, "header.stamp nanosec not below 10^9");
            continue;
        };
        let [e, n, u] = m.linear;
        if !(e.is_finite() && n.is_finite() && u.is_finite()) {
            skip(diag, path, name, it, "non-finite velocity");
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
    vels
}

fn read_fixes(
    t: &Topic,
    path: &Path,
    opts: &BagOptions,
    vels: &Velocities,
    out: &mut BagData,
    lag: &mut Vec<f64>,
    diag: &mut Diagnostics,
) {
    let name = &t.summary.topic;
    let mut last = None;
    let mut geoid = (opts.altitude == AltitudeDatum::Msl).then(Egm96Grid::new);
    let count_drop =
        |out: &mut BagData, reason: String| *out.fix_drops.entry(reason).or_insert(0) += 1;
    for it in &t.items {
        out.fix_messages += 1;
        let m = match &it.msg {
            Ok(Decoded::Fix(m)) => m,
            Ok(_) => continue,
            Err(e) => {
                skip(diag, path, name, it, e);
                count_drop(out, "message does not decode".into());
                continue;
            }
        };
        if m.status < 0 {
            count_drop(out, format!("status {} (NO_FIX)", m.status));
            continue;
        }
        let time = match stamp_to_gps(&m.header) {
            Ok(t) => t,
            Err(e) => {
                skip(diag, path, name, it, &e);
                count_drop(out, "unusable header.stamp".into());
                continue;
            }
        };
        let (lat, lon, mut h) = (m.latitude_deg, m.longitude_deg, m.altitude_m);
        if !(lat.is_finite() && lon.is_finite() && h.is_finite())
            || lat.abs() > 90.0
            || lon.abs() > 180.0
        {
            let why = format!("latitude {lat} / longitude {lon} / altitude {h} not a position");
            skip(diag, path, name, it, &why);
            count_drop(out, "non-finite or out-of-range position".into());
            continue;
        }
        if let Some(why) = time_order_problem(last, time) {
            skip(diag, path, name, it, &format!("header.stamp: {why}"));
            count_drop(out, "header.stamp not after the previous fix".into());
            continue;
        }
        if let Some(g) = geoid.as_mut() {
            // Checked finite and in range above.
            h += g.separation_m(lat, lon).unwrap_or(0.0);
        }
        last = Some(time);
        lag.push(lag_s(it, &m.header));
        let c = &m.position_covariance;
        // ENU covariance → σ north, east, down.
        let diag_ned = [c[4], c[0], c[8]];
        let known =
            m.position_covariance_type > 0 && diag_ned.iter().all(|v| v.is_finite() && *v > 0.0);
        if m.position_covariance_type > 0 && !known {
            let why = "covariance type says known but its diagonal is not positive: default σ used";
            skip(diag, path, name, it, why);
        }
        let pos_sd = if known {
            Vector3::new(diag_ned[0].sqrt(), diag_ned[1].sqrt(), diag_ned[2].sqrt())
        } else {
            Vector3::from(opts.default_sd_m)
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
        let matched = out.fixes.iter().filter(|f| f.fix.vel.is_some()).count();
        if matched > 0 {
            diag.note(format!(
                "{matched} of {} fixes have a velocity from the velocity topic (same header.stamp), \
                 {with} of them with a σ from its covariance; gnss.txt keeps positions only",
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

/// Forward speeds: Odometry `twist.twist.linear.x` (child frame = body),
/// or a body-frame TwistStamped's `linear.x`.
fn read_speeds(
    t: &Topic,
    path: &Path,
    out: &mut BagData,
    lag: &mut Vec<f64>,
    diag: &mut Diagnostics,
) -> SpeedSummary {
    let name = &t.summary.topic;
    let mut last = None;
    let mut sds = Vec::new();
    let mut frame = None;
    for it in &t.items {
        let (h, v, var, child) = match &it.msg {
            Ok(Decoded::Odom(m)) => (
                &m.header,
                m.linear[0],
                m.twist_covariance[0],
                &m.child_frame_id,
            ),
            Ok(Decoded::Twist(m)) => (&m.header, m.linear[0], 0.0, &m.header.frame_id),
            Ok(_) => continue,
            Err(e) => {
                skip(diag, path, name, it, e);
                continue;
            }
        };
        let time = match stamp_to_gps(h) {
            Ok(t) => t,
            Err(e) => {
                skip(diag, path, name, it, &e);
                continue;
            }
        };
        if !v.is_finite() {
            skip(diag, path, name, it, "non-finite linear.x");
            continue;
        }
        if let Some(why) = time_order_problem(last, time) {
            skip(diag, path, name, it, &format!("header.stamp: {why}"));
            continue;
        }
        last = Some(time);
        frame.get_or_insert_with(|| child.clone());
        lag.push(lag_s(it, h));
        if var.is_finite() && var > 0.0 {
            sds.push(var.sqrt());
        }
        out.speeds.push((time, v));
    }
    sds.sort_by(f64::total_cmp);
    let frame = frame.unwrap_or_default();
    let source = match t.kind {
        Some(MsgKind::Odom) => format!(
            "nav_msgs/Odometry twist.twist.linear.x in its child frame {frame:?} (the vehicle body, x forward)"
        ),
        _ => format!(
            "geometry_msgs/TwistStamped linear.x in frame {frame:?}: a body frame (not map/odom/ENU/gps), \
             so taken as the forward speed"
        ),
    };
    SpeedSummary {
        topic: name.clone(),
        source,
        speeds: out.speeds.len(),
        median_sd_mps: sds.get(sds.len() / 2).copied(),
        min_mps: out.speeds.iter().map(|s| s.1).fold(f64::INFINITY, f64::min),
        max_mps: out
            .speeds
            .iter()
            .map(|s| s.1)
            .fold(f64::NEG_INFINITY, f64::max),
    }
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

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn world_and_body_frames() {
        for f in ["map", "/odom", "world", "gps", "enu", "utm_frame", "earth"] {
            assert!(is_world_frame(f), "{f}");
        }
        for f in ["base_link", "/base_footprint", "imu_link", ""] {
            assert!(!is_world_frame(f), "{f}");
        }
    }
}
