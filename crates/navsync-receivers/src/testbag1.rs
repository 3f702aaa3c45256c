//! ROS 1 bags for tests (feature `test-bags`): a serializer of the message
//! types navsync reads and a bag 2.0 writer (ROS wiki "Bags/Format/2.0":
//! bag header padded to 4096 bytes, chunks of connection and message
//! records each followed by its index data, then the connections and
//! chunk infos at `index_pos`), with uncompressed, bz2 or lz4 chunks.
//! Written from the specification, independent of the reader under test.

use std::collections::BTreeMap;
use std::io::Write;

pub const IMU: (&str, &str) = ("sensor_msgs/Imu", "6a62c6daae103f4ff57a132d6f95cec2");
pub const FIX: (&str, &str) = ("sensor_msgs/NavSatFix", "2d3a8cd499b9b4a0249fb98fd05cfa48");
pub const ODOM: (&str, &str) = ("nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7");
pub const TWIST: (&str, &str) = (
    "geometry_msgs/TwistStamped",
    "98d34b0043a2093cf9d9345ab6eef12e",
);
pub const TWIST_COV: (&str, &str) = (
    "geometry_msgs/TwistWithCovarianceStamped",
    "8927a1a12fb2607ceea095b2dc440a96",
);

/// ROS 1 serialization: little-endian, packed.
#[derive(Default)]
pub struct Out(pub Vec<u8>);

impl Out {
    pub fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.0.extend_from_slice(s.as_bytes());
    }
    /// `std_msgs/Header`: seq, stamp (ns since the Unix epoch), frame.
    pub fn header(&mut self, seq: u32, stamp_ns: i64, frame: &str) {
        self.u32(seq);
        self.u32((stamp_ns / 1_000_000_000) as u32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame);
    }
}

/// `sensor_msgs/Imu`, body FLU, no orientation.
pub fn imu_msg(stamp_ns: i64, gyro: [f64; 3], acc: [f64; 3]) -> Vec<u8> {
    let mut o = Out::default();
    o.header(7, stamp_ns, "imu_link");
    o.f64s(&[0.0, 0.0, 0.0, 1.0]);
    o.f64s(&[-1.0; 9]);
    o.f64s(&gyro);
    o.f64s(&[0.0; 9]);
    o.f64s(&acc);
    o.f64s(&[0.0; 9]);
    o.0
}

/// `sensor_msgs/NavSatFix` with a diagonal ENU covariance.
pub fn fix_msg(stamp_ns: i64, status: i8, llh: [f64; 3], var_enu: [f64; 3]) -> Vec<u8> {
    let mut o = Out::default();
    o.header(1, stamp_ns, "gps");
    o.0.push(status as u8);
    o.0.extend_from_slice(&1u16.to_le_bytes());
    o.f64s(&llh);
    let mut cov = [0.0; 9];
    cov[0] = var_enu[0];
    cov[4] = var_enu[1];
    cov[8] = var_enu[2];
    o.f64s(&cov);
    o.0.push(2); // COVARIANCE_TYPE_DIAGONAL_KNOWN
    o.0
}

/// `nav_msgs/Odometry` in frame `odom`, child `child`: forward speed `vx`
/// with variance `var` in the twist covariance.
pub fn odom_msg(stamp_ns: i64, child: &str, vx: f64, var: f64) -> Vec<u8> {
    let mut o = Out::default();
    o.header(2, stamp_ns, "odom");
    o.string(child);
    o.f64s(&[1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    o.f64s(&[0.0; 36]);
    o.f64s(&[vx, 0.0, 0.0, 0.0, 0.0, 0.05]);
    let mut cov = [0.0; 36];
    cov[0] = var;
    o.f64s(&cov);
    o.0
}

/// `geometry_msgs/TwistStamped` in `frame`.
pub fn twist_msg(stamp_ns: i64, frame: &str, linear: [f64; 3]) -> Vec<u8> {
    let mut o = Out::default();
    o.header(3, stamp_ns, frame);
    o.f64s(&linear);
    o.f64s(&[0.0; 3]);
    o.0
}

/// `geometry_msgs/TwistWithCovarianceStamped`: ENU velocity, one variance.
pub fn twist_cov_msg(stamp_ns: i64, v_enu: [f64; 3], var: f64) -> Vec<u8> {
    let mut o = Out::default();
    o.header(4, stamp_ns, "gps");
    o.f64s(&v_enu);
    o.f64s(&[0.0; 3]);
    let mut cov = [0.0; 36];
    for k in 0..6 {
        cov[k * 7] = var;
    }
    o.f64s(&cov);
    o.0
}

/// One message: topic, (type, md5sum), record time (ns), payload.
pub struct Msg1 {
    pub topic: &'static str,
    pub ty: (&'static str, &'static str),
    pub log_ns: i64,
    pub data: Vec<u8>,
}

/// Chunk compression.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Compression {
    None,
    Bz2,
    Lz4,
}

impl Compression {
    pub fn name(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::Bz2 => "bz2",
            Compression::Lz4 => "lz4",
        }
    }
}

fn field(out: &mut Vec<u8>, name: &str, value: &[u8]) {
    out.extend_from_slice(&((name.len() + 1 + value.len()) as u32).to_le_bytes());
    out.extend_from_slice(name.as_bytes());
    out.push(b'=');
    out.extend_from_slice(value);
}

/// A record of `fields` and `data`.
pub fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
    let mut h = Vec::new();
    for (n, v) in fields {
        field(&mut h, n, v);
    }
    let mut r = (h.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(&h);
    r.extend_from_slice(&(data.len() as u32).to_le_bytes());
    r.extend_from_slice(data);
    r
}

fn time_bytes(ns: i64) -> [u8; 8] {
    let mut t = [0u8; 8];
    t[..4].copy_from_slice(&((ns / 1_000_000_000) as u32).to_le_bytes());
    t[4..].copy_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
    t
}

fn connection(id: u32, m: &Msg1) -> Vec<u8> {
    let mut data = Vec::new();
    field(&mut data, "topic", m.topic.as_bytes());
    field(&mut data, "type", m.ty.0.as_bytes());
    field(&mut data, "md5sum", m.ty.1.as_bytes());
    field(&mut data, "message_definition", b"# (not needed)\n");
    record(
        &[
            ("op", &[0x07]),
            ("conn", &id.to_le_bytes()),
            ("topic", m.topic.as_bytes()),
        ],
        &data,
    )
}

fn compress(c: Compression, raw: &[u8]) -> Vec<u8> {
    match c {
        Compression::None => raw.to_vec(),
        Compression::Bz2 => {
            let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::best());
            e.write_all(raw).unwrap();
            e.finish().unwrap()
        }
        Compression::Lz4 => {
            let mut e = lz4::EncoderBuilder::new().build(Vec::new()).unwrap();
            e.write_all(raw).unwrap();
            let (v, r) = e.finish();
            r.unwrap();
            v
        }
    }
}

/// A ROS 1 bag of `msgs` in chunks of about `chunk_bytes` uncompressed.
pub fn write_bag1(msgs: &[Msg1], c: Compression, chunk_bytes: usize) -> Vec<u8> {
    let mut ids: BTreeMap<&str, (u32, usize)> = BTreeMap::new();
    for (k, m) in msgs.iter().enumerate() {
        let n = ids.len() as u32;
        ids.entry(m.topic).or_insert((n, k));
    }
    let mut body = Vec::new();
    let mut chunk = Vec::new();
    let mut in_chunk: BTreeMap<u32, Vec<(i64, u32)>> = BTreeMap::new();
    let mut chunk_infos = Vec::new();
    let mut times = (i64::MAX, i64::MIN);
    let header_len = 13 + 4096;
    let flush = |chunk: &mut Vec<u8>,
                 in_chunk: &mut BTreeMap<u32, Vec<(i64, u32)>>,
                 body: &mut Vec<u8>,
                 infos: &mut Vec<Vec<u8>>,
                 times: &mut (i64, i64)| {
        if chunk.is_empty() {
            return;
        }
        let pos = (header_len + body.len()) as u64;
        let data = compress(c, chunk);
        body.extend(record(
            &[
                ("op", &[0x05]),
                ("compression", c.name().as_bytes()),
                ("size", &(chunk.len() as u32).to_le_bytes()),
            ],
            &data,
        ));
        let mut counts = Vec::new();
        for (id, entries) in in_chunk.iter() {
            let mut d = Vec::new();
            for (t, off) in entries {
                d.extend_from_slice(&time_bytes(*t));
                d.extend_from_slice(&off.to_le_bytes());
            }
            body.extend(record(
                &[
                    ("op", &[0x04]),
                    ("ver", &1u32.to_le_bytes()),
                    ("conn", &id.to_le_bytes()),
                    ("count", &(entries.len() as u32).to_le_bytes()),
                ],
                &d,
            ));
            counts.extend_from_slice(&id.to_le_bytes());
            counts.extend_from_slice(&(entries.len() as u32).to_le_bytes());
        }
        infos.push(record(
            &[
                ("op", &[0x06]),
                ("ver", &1u32.to_le_bytes()),
                ("chunk_pos", &pos.to_le_bytes()),
                ("start_time", &time_bytes(times.0)),
                ("end_time", &time_bytes(times.1)),
                ("count", &(in_chunk.len() as u32).to_le_bytes()),
            ],
            &counts,
        ));
        chunk.clear();
        in_chunk.clear();
        *times = (i64::MAX, i64::MIN);
    };
    for m in msgs {
        let id = ids[m.topic].0;
        if !in_chunk.contains_key(&id) {
            chunk.extend(connection(id, m));
        }
        in_chunk
            .entry(id)
            .or_default()
            .push((m.log_ns, chunk.len() as u32));
        times = (times.0.min(m.log_ns), times.1.max(m.log_ns));
        chunk.extend(record(
            &[
                ("op", &[0x02]),
                ("conn", &id.to_le_bytes()),
                ("time", &time_bytes(m.log_ns)),
            ],
            &m.data,
        ));
        if chunk.len() >= chunk_bytes {
            flush(
                &mut chunk,
                &mut in_chunk,
                &mut body,
                &mut chunk_infos,
                &mut times,
            );
        }
    }
    flush(
        &mut chunk,
        &mut in_chunk,
        &mut body,
        &mut chunk_infos,
        &mut times,
    );
    let index_pos = (header_len + body.len()) as u64;
    for (id, k) in ids.values() {
        body.extend(connection(*id, &msgs[*k]));
    }
    let n_chunks = chunk_infos.len() as u32;
    for ci in chunk_infos {
        body.extend(ci);
    }
    let fields: [(&str, &[u8]); 4] = [
        ("op", &[0x03]),
        ("index_pos", &index_pos.to_le_bytes()),
        ("conn_count", &(ids.len() as u32).to_le_bytes()),
        ("chunk_count", &n_chunks.to_le_bytes()),
    ];
    let mut h = Vec::new();
    for (n, v) in fields {
        field(&mut h, n, v);
    }
    // The bag header record is padded with spaces to 4096 bytes.
    let pad = vec![b' '; 4096 - 8 - h.len()];
    let mut out = b"#ROSBAG V2.0\n".to_vec();
    out.extend(record(&fields, &pad));
    debug_assert_eq!(out.len(), header_len);
    out.extend(body);
    out
}
