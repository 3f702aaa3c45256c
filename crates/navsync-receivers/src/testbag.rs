//! ROS 2 bags for tests: an XCDR1 encoder of `sensor_msgs/msg/Imu`,
//! `sensor_msgs/msg/NavSatFix` and `geometry_msgs/msg/TwistWithCovarianceStamped`
//! (independent of the decoder under test) and a writer using the `mcap`
//! crate. For tests (feature `test-bags`), never used by the decoder.

use std::collections::BTreeMap;
use std::io::Cursor;

pub const IMU: &str = "sensor_msgs/msg/Imu";
pub const FIX: &str = "sensor_msgs/msg/NavSatFix";
pub const TWIST: &str = "geometry_msgs/msg/TwistWithCovarianceStamped";

/// XCDR1 encoder (DDS-XTypes 1.3 §7.4.3): alignment counted from the end
/// of the 4-byte encapsulation header.
pub struct CdrOut {
    pub buf: Vec<u8>,
    le: bool,
}

impl CdrOut {
    pub fn new(le: bool) -> Self {
        CdrOut {
            buf: vec![0, le as u8, 0, 0],
            le,
        }
    }
    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }
    fn put(&mut self, mut b: Vec<u8>) {
        self.align(b.len());
        if !self.le {
            b.reverse();
        }
        self.buf.extend(b);
    }
    pub fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes().to_vec());
    }
    pub fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes().to_vec());
    }
    pub fn u16(&mut self, v: u16) {
        self.put(v.to_le_bytes().to_vec());
    }
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    pub fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes().to_vec());
    }
    pub fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.f64(*x);
        }
    }
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend(s.as_bytes());
        self.buf.push(0);
    }
    /// `std_msgs/Header` with a stamp in ns since the Unix epoch.
    pub fn header(&mut self, stamp_ns: i64, frame: &str) {
        self.i32((stamp_ns / 1_000_000_000) as i32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame);
    }
}

/// `sensor_msgs/Imu` without orientation (covariance[0] = −1), rates in
/// rad/s and specific force in m/s², body FLU.
pub fn imu_msg(le: bool, stamp_ns: i64, gyro: [f64; 3], acc: [f64; 3]) -> Vec<u8> {
    let mut c = CdrOut::new(le);
    c.header(stamp_ns, "imu_link");
    c.f64s(&[0.0, 0.0, 0.0, 1.0]);
    c.f64s(&[-1.0; 9]);
    c.f64s(&gyro);
    c.f64s(&[0.0; 9]);
    c.f64s(&acc);
    c.f64s(&[0.0; 9]);
    c.buf
}

/// `sensor_msgs/NavSatFix` (GPS service) with a diagonal ENU covariance.
pub fn fix_msg(le: bool, stamp_ns: i64, status: i8, llh: [f64; 3], var_enu: [f64; 3]) -> Vec<u8> {
    let mut c = CdrOut::new(le);
    c.header(stamp_ns, "gps");
    c.u8(status as u8);
    c.u16(1);
    c.f64s(&llh);
    let mut cov = [0.0; 9];
    cov[0] = var_enu[0];
    cov[4] = var_enu[1];
    cov[8] = var_enu[2];
    c.f64s(&cov);
    c.u8(2); // COVARIANCE_TYPE_DIAGONAL_KNOWN
    c.buf
}

/// `geometry_msgs/TwistWithCovarianceStamped`: ENU velocity, one variance.
pub fn twist_msg(le: bool, stamp_ns: i64, v_enu: [f64; 3], var: f64) -> Vec<u8> {
    let mut c = CdrOut::new(le);
    c.header(stamp_ns, "gps");
    c.f64s(&v_enu);
    c.f64s(&[0.0; 3]);
    let mut cov = [0.0; 36];
    for k in 0..6 {
        cov[k * 7] = var;
    }
    c.f64s(&cov);
    c.buf
}

/// One message: topic, schema, log time (ns since the Unix epoch), payload.
pub struct Msg {
    pub topic: &'static str,
    pub schema: &'static str,
    pub log_ns: i64,
    pub data: Vec<u8>,
}

/// A `ros2` profile MCAP file of `msgs` in 4 KiB chunks.
pub fn write_bag(msgs: &[Msg], compression: Option<mcap::Compression>) -> Vec<u8> {
    write_bag_chunked(msgs, compression, 4096)
}

pub fn write_bag_chunked(
    msgs: &[Msg],
    compression: Option<mcap::Compression>,
    chunk_size: u64,
) -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .compression(compression)
        .chunk_size(Some(chunk_size))
        .profile("ros2")
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let mut channels = BTreeMap::new();
    for (seq, m) in msgs.iter().enumerate() {
        let id = *channels.entry(m.topic).or_insert_with(|| {
            let s = w.add_schema(m.schema, "ros2msg", b"").unwrap();
            w.add_channel(s, m.topic, "cdr", &BTreeMap::new()).unwrap()
        });
        let h = mcap::records::MessageHeader {
            channel_id: id,
            sequence: seq as u32 + 1,
            log_time: m.log_ns as u64,
            publish_time: m.log_ns as u64,
        };
        w.write_to_known_channel(&h, &m.data).unwrap();
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}
