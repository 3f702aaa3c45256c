//! ROS 1 bags (format 2.0): `sensor_msgs/Imu`, `sensor_msgs/NavSatFix`,
//! `nav_msgs/Odometry`, `geometry_msgs/TwistStamped` and
//! `geometry_msgs/TwistWithCovarianceStamped`, read by hand, on GPS time
//! (what becomes of the messages is shared with ROS 2: [`crate::rosmsg`]).
//!
//! - Container (ROS wiki "Bags/Format/2.0"): the line `#ROSBAG V2.0\n`,
//!   then records of int32 header length, header, int32 data length,
//!   data, all little-endian. A header is fields of int32 length +
//!   `name=value`, one of them `op`: 0x03 bag header (`index_pos`,
//!   `conn_count`, `chunk_count`; data padding), 0x05 chunk (`compression`
//!   `none`, `bz2` or `lz4`, `size` uncompressed; data: connection and
//!   message records), 0x07 connection (`conn`, `topic`; data: a
//!   connection header with `topic`, `type`, `md5sum`,
//!   `message_definition`), 0x02 message data (`conn`, `time`: uint32 sec,
//!   uint32 nsec), 0x04 index data and 0x06 chunk info (not needed: the
//!   records are read in file order). `lz4` chunks are roslz4's stream,
//!   the LZ4 frame format (lz4.org, "LZ4 Frame Format Description").
//! - Messages (ROS wiki "msg", "Serialization"): little-endian, packed,
//!   no alignment; `string` = uint32 length + bytes; `time` = uint32 sec +
//!   uint32 nsec; fixed arrays without a length; `std_msgs/Header` = uint32
//!   seq, time stamp, string frame_id. A type is recognised by the
//!   connection's `type` and checked by its `md5sum` (the MD5 of the
//!   message definition as `gendeps` computes it): another layout under a
//!   known name is reported and its topic skipped.
//! - Guards: every length is checked against the bytes that remain; a
//!   chunk's uncompressed size is capped at [`MAX_CHUNK_BYTES`]; a record
//!   that runs past the end of the file ends the reading there (the whole
//!   records before it are used, and the summary says the file was cut);
//!   a chunk that does not decompress is reported and skipped.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::Path;

use navsync::error::{Diagnostics, Error};

use crate::rosmsg::{
    BagData, BagOptions, Decoded, Dialect, Header, Imu, Item, MsgKind, NavSatFix, Odometry, Topic,
    TopicChoice, TopicSummary, TwistStamped, Wire, assemble,
};

/// The first line of a ROS 1 bag (format 2.0).
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
/// The largest uncompressed chunk read (rosbag's default chunk is 768 KiB).
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// Record op codes (Bags/Format/2.0).
const OP_MSG_DATA: u8 = 0x02;
const OP_BAG_HEADER: u8 = 0x03;
const OP_CHUNK: u8 = 0x05;
const OP_CONNECTION: u8 = 0x07;

/// The types navsync reads: ROS 1 name, md5sum, kind.
pub const KNOWN_TYPES: [(&str, &str); 5] = [
    ("sensor_msgs/Imu", "6a62c6daae103f4ff57a132d6f95cec2"),
    ("sensor_msgs/NavSatFix", "2d3a8cd499b9b4a0249fb98fd05cfa48"),
    ("nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7"),
    (
        "geometry_msgs/TwistStamped",
        "98d34b0043a2093cf9d9345ab6eef12e",
    ),
    (
        "geometry_msgs/TwistWithCovarianceStamped",
        "8927a1a12fb2607ceea095b2dc440a96",
    ),
];

fn kind_of(type_name: &str) -> Option<MsgKind> {
    Some(match type_name {
        "sensor_msgs/Imu" => MsgKind::Imu,
        "sensor_msgs/NavSatFix" => MsgKind::Fix,
        "nav_msgs/Odometry" => MsgKind::Odom,
        "geometry_msgs/TwistStamped" => MsgKind::Twist,
        "geometry_msgs/TwistWithCovarianceStamped" => MsgKind::TwistCov,
        _ => return None,
    })
}

const DIALECT: Dialect = Dialect {
    name: "ROS 1",
    imu: "sensor_msgs/Imu",
    fix: "sensor_msgs/NavSatFix",
    velocity: "geometry_msgs/TwistWithCovarianceStamped, or geometry_msgs/TwistStamped in a world frame",
    speed: "nav_msgs/Odometry, or geometry_msgs/TwistStamped in a body frame",
    imu_most_messages: true,
};

/// A ROS 1 serialized message body.
pub(crate) struct Ros1<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Ros1<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Ros1 { buf, pos: 0 }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let b = self.bytes(N)?;
        let mut a = [0u8; N];
        a.copy_from_slice(b);
        Ok(a)
    }

    fn bytes(&mut self, n: usize) -> Result<&'a [u8], String> {
        match self.pos.checked_add(n) {
            Some(end) if end <= self.buf.len() => {
                let b = &self.buf[self.pos..end];
                self.pos = end;
                Ok(b)
            }
            _ => Err(format!(
                "truncated: {n} more bytes needed at offset {} of a {}-byte message",
                self.pos,
                self.buf.len()
            )),
        }
    }

    /// Bytes not read.
    pub(crate) fn left(&self) -> usize {
        self.buf.len() - self.pos
    }
}

impl Wire for Ros1<'_> {
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.take()?))
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.take()?))
    }
    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.bytes(n)?).into_owned())
    }
    fn header(&mut self) -> Result<Header, String> {
        let _seq = self.u32()?;
        Ok(Header {
            sec: self.u32()? as i64,
            nanosec: self.u32()?,
            frame_id: self.string()?,
        })
    }
}

/// Decodes one message of `kind`; bytes left over mean another layout.
fn decode(kind: MsgKind, data: &[u8]) -> Result<Decoded, String> {
    let mut r = Ros1::new(data);
    let d = match kind {
        MsgKind::Imu => Decoded::Imu(Imu::read(&mut r)?),
        MsgKind::Fix => Decoded::Fix(NavSatFix::read(&mut r)?),
        MsgKind::TwistCov => Decoded::Twist(TwistStamped::read(&mut r, true)?),
        MsgKind::Twist => Decoded::Twist(TwistStamped::read(&mut r, false)?),
        MsgKind::Odom => Decoded::Odom(Odometry::read(&mut r)?),
    };
    match r.left() {
        0 => Ok(d),
        n => Err(format!(
            "{n} bytes left after the message's last field: not the layout of its type"
        )),
    }
}

/// Decodes `data` as the ROS 1 message of `type_name` (one of
/// [`KNOWN_TYPES`]); for tests and fuzzing.
pub fn decode_message(type_name: &str, data: &[u8]) -> Result<(), String> {
    let kind = kind_of(type_name).ok_or_else(|| format!("{type_name} is not read"))?;
    decode(kind, data).map(|_| ())
}

/// One record: its op, header fields, data and where it starts.
struct Record<'a> {
    offset: usize,
    fields: Vec<Field<'a>>,
    data: &'a [u8],
}

impl<'a> Record<'a> {
    fn field(&self, name: &str) -> Option<&'a [u8]> {
        self.fields
            .iter()
            .find(|(n, _)| *n == name.as_bytes())
            .map(|(_, v)| *v)
    }
    fn op(&self) -> Option<u8> {
        match self.field("op") {
            Some([op]) => Some(*op),
            _ => None,
        }
    }
    fn u32(&self, name: &str) -> Result<u32, String> {
        match self.field(name) {
            Some(v) if v.len() == 4 => Ok(u32::from_le_bytes([v[0], v[1], v[2], v[3]])),
            Some(v) => Err(format!("field {name} has {} bytes, not 4", v.len())),
            None => Err(format!("no field {name}")),
        }
    }
    fn u64(&self, name: &str) -> Result<u64, String> {
        match self.field(name) {
            Some(v) if v.len() == 8 => {
                let mut a = [0u8; 8];
                a.copy_from_slice(v);
                Ok(u64::from_le_bytes(a))
            }
            Some(v) => Err(format!("field {name} has {} bytes, not 8", v.len())),
            None => Err(format!("no field {name}")),
        }
    }
    fn text(&self, name: &str) -> Option<String> {
        self.field(name)
            .map(|v| String::from_utf8_lossy(v).into_owned())
    }
}

/// A header field: name, value.
type Field<'a> = (&'a [u8], &'a [u8]);

/// `name=value` fields, each behind an int32 length (a record header and
/// a connection record's data).
fn parse_fields(mut b: &[u8]) -> Result<Vec<Field<'_>>, String> {
    let mut out = Vec::new();
    while !b.is_empty() {
        let Some((len, rest)) = split_len(b) else {
            return Err(format!("{} stray bytes after the last field", b.len()));
        };
        if len > rest.len() {
            return Err(format!(
                "a field of {len} bytes where {} remain",
                rest.len()
            ));
        }
        let (f, rest) = rest.split_at(len);
        let Some(eq) = f.iter().position(|c| *c == b'=') else {
            return Err("a field without '='".into());
        };
        out.push((&f[..eq], &f[eq + 1..]));
        b = rest;
    }
    Ok(out)
}

/// An int32 little-endian length and what follows it.
fn split_len(b: &[u8]) -> Option<(usize, &[u8])> {
    let (l, rest) = b.split_first_chunk::<4>()?;
    Some((u32::from_le_bytes(*l) as usize, rest))
}

/// Why reading records stopped before the end of a buffer.
enum Cut {
    /// A length runs past the end: `(offset, what)`.
    Overrun(usize, String),
    /// A header that does not parse.
    BadHeader(usize, String),
}

/// The records of `buf` (offsets counted from `base`), up to the first
/// that runs past its end or whose header does not parse.
fn records(buf: &[u8], base: usize) -> (Vec<Record<'_>>, Option<Cut>) {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < buf.len() {
        let offset = base + pos;
        let b = &buf[pos..];
        let Some((hlen, rest)) = split_len(b).filter(|(l, r)| *l <= r.len()) else {
            let why = format!(
                "the record at byte {offset} claims a header longer than the {} bytes left",
                b.len()
            );
            return (out, Some(Cut::Overrun(offset, why)));
        };
        let (header, rest) = rest.split_at(hlen);
        let Some((dlen, rest)) = split_len(rest).filter(|(l, r)| *l <= r.len()) else {
            let why = format!(
                "the record at byte {offset} claims more data than the {} bytes left",
                rest.len()
            );
            return (out, Some(Cut::Overrun(offset, why)));
        };
        let fields = match parse_fields(header) {
            Ok(f) => f,
            Err(e) => {
                let why = format!("the record header at byte {offset}: {e}");
                return (out, Some(Cut::BadHeader(offset, why)));
            }
        };
        out.push(Record {
            offset,
            fields,
            data: &rest[..dlen],
        });
        pos += 8 + hlen + dlen;
    }
    (out, None)
}

/// A connection: its topic and how its messages are read.
struct Conn {
    topic: String,
    kind: Option<MsgKind>,
}

/// What the reader has gathered.
#[derive(Default)]
struct State {
    conns: HashMap<u32, Conn>,
    topics: BTreeMap<String, Topic>,
    /// Messages read (numbers them).
    messages: u64,
    /// Connection ids of messages with no connection record, and their count.
    orphans: BTreeMap<u32, u64>,
}

impl State {
    fn connection(&mut self, r: &Record) -> Result<(), String> {
        let id = r.u32("conn")?;
        let topic = r.text("topic").ok_or("no field topic")?;
        if self.conns.contains_key(&id) {
            return Ok(());
        }
        let ch = parse_fields(r.data).map_err(|e| format!("connection header: {e}"))?;
        let get = |n: &str| {
            ch.iter()
                .find(|(k, _)| *k == n.as_bytes())
                .map(|(_, v)| String::from_utf8_lossy(v).into_owned())
                .unwrap_or_default()
        };
        let (ty, md5) = (get("type"), get("md5sum"));
        let known = KNOWN_TYPES.iter().find(|(t, _)| *t == ty);
        let mut kind = kind_of(&ty);
        let mut unusable = None;
        if let Some((_, want)) = known
            && md5 != *want
            && md5 != "*"
        {
            unusable = Some(format!(
                "md5sum {md5} is not {ty}'s {want}: another layout under a known name; topic skipped"
            ));
            kind = None;
        }
        let t = self.topics.entry(topic.clone()).or_insert_with(|| Topic {
            summary: TopicSummary {
                topic: topic.clone(),
                schema: ty.clone(),
                message_encoding: "ros1".into(),
                ..Default::default()
            },
            kind,
            unusable: unusable.clone(),
            items: Vec::new(),
        });
        if t.summary.schema != ty {
            // Two types on one topic: the first connection's is read.
            kind = None;
        }
        self.conns.insert(id, Conn { topic, kind });
        Ok(())
    }

    fn message(&mut self, r: &Record) -> Result<(), String> {
        let id = r.u32("conn")?;
        let time = r.u64("time")?;
        let log_time = (time & 0xffff_ffff) * 1_000_000_000 + (time >> 32);
        self.messages += 1;
        let Some(c) = self.conns.get(&id) else {
            *self.orphans.entry(id).or_insert(0) += 1;
            return Ok(());
        };
        let Some(t) = self.topics.get_mut(&c.topic) else {
            return Ok(());
        };
        t.summary.messages += 1;
        if let Some(kind) = c.kind {
            t.items.push(Item {
                number: self.messages,
                log_time,
                msg: decode(kind, r.data),
            });
        }
        Ok(())
    }

    /// Connection and message records of `recs`; problems reported.
    fn take(&mut self, recs: &[Record], path: &Path, diag: &mut Diagnostics) {
        for r in recs {
            let res = match r.op() {
                Some(OP_CONNECTION) => self.connection(r),
                Some(OP_MSG_DATA) => self.message(r),
                _ => Ok(()),
            };
            if let Err(e) = res {
                diag.push(
                    path,
                    0,
                    format!("record at byte {}: {e}; skipped", r.offset),
                );
            }
        }
    }
}

/// The uncompressed records of a chunk record.
fn unchunk(r: &Record) -> Result<Vec<u8>, String> {
    let compression = r.text("compression").ok_or("no field compression")?;
    let size = r.u32("size")? as u64;
    if size > MAX_CHUNK_BYTES {
        return Err(format!(
            "uncompressed size {size} bytes is over the {MAX_CHUNK_BYTES}-byte limit"
        ));
    }
    let mut out = Vec::new();
    let read = |rd: &mut dyn Read, out: &mut Vec<u8>| {
        rd.take(size + 1)
            .read_to_end(out)
            .map(|_| ())
            .map_err(|e| format!("{compression} data do not decompress: {e}"))
    };
    match compression.as_str() {
        "none" => out.extend_from_slice(r.data),
        "bz2" => read(&mut bzip2::read::BzDecoder::new(r.data), &mut out)?,
        "lz4" => {
            let mut d =
                lz4::Decoder::new(r.data).map_err(|e| format!("lz4 frame does not open: {e}"))?;
            read(&mut d, &mut out)?
        }
        c => {
            return Err(format!(
                "compression {c:?} is not one of ROS 1's none, bz2, lz4"
            ));
        }
    }
    if out.len() as u64 != size {
        return Err(format!(
            "{} bytes after decompression where the chunk says {size}",
            out.len()
        ));
    }
    Ok(out)
}

/// Reads the messages of a ROS 1 bag (the whole file in `bytes`) from the
/// chosen topics. `path` names the file in errors and diagnostics.
pub fn read_bag(
    bytes: &[u8],
    path: &Path,
    choice: &TopicChoice,
    opts: &BagOptions,
    diag: &mut Diagnostics,
) -> Result<BagData, Error> {
    let nodata = |msg: String| Error::NoData {
        path: path.to_path_buf(),
        msg,
    };
    let Some(body) = bytes.strip_prefix(MAGIC) else {
        let v1 = bytes.starts_with(b"#ROSRECORD V1.2") || bytes.starts_with(b"#ROSBAG V1.");
        return Err(nodata(if v1 {
            "a ROS bag of format 1.x: navsync reads 2.0 (`rosbag fix` or `rosbag reindex` upgrades it)"
                .into()
        } else {
            "not a ROS 1 bag (it does not start with \"#ROSBAG V2.0\")".into()
        }));
    };
    let (recs, cut) = records(body, MAGIC.len());
    let mut st = State::default();
    let mut index_pos = None;
    let (mut chunks, mut bad_chunks) = (0u64, 0u64);
    for r in &recs {
        match r.op() {
            Some(OP_BAG_HEADER) => index_pos = r.u64("index_pos").ok(),
            Some(OP_CHUNK) => {
                chunks += 1;
                match unchunk(r) {
                    Ok(inner) => {
                        let base = r.offset;
                        let (inner_recs, inner_cut) = records(&inner, 0);
                        st.take(&inner_recs, path, diag);
                        if let Some(Cut::Overrun(o, why) | Cut::BadHeader(o, why)) = inner_cut {
                            bad_chunks += 1;
                            diag.push(
                                path,
                                0,
                                format!(
                                    "chunk at byte {base}: at uncompressed offset {o}: {why}; the rest of the chunk skipped"
                                ),
                            );
                        }
                    }
                    Err(e) => {
                        bad_chunks += 1;
                        diag.push(
                            path,
                            0,
                            format!("chunk at byte {}: {e}; chunk skipped", r.offset),
                        );
                    }
                }
            }
            _ => st.take(std::slice::from_ref(r), path, diag),
        }
    }
    let mut stopped = match cut {
        Some(Cut::Overrun(_, why)) => Some(format!(
            "the file is cut: {why}; the whole records before it are read"
        )),
        Some(Cut::BadHeader(_, why)) => Some(format!(
            "corrupt record: {why}; the records before it are read"
        )),
        None => None,
    };
    if stopped.is_none()
        && let Some(ip) = index_pos
        && (ip == 0 || ip > bytes.len() as u64)
    {
        stopped = Some(format!(
            "the bag header's index position ({ip}) is {}: the recording was not closed or the file \
             was cut; the whole records are read (`rosbag reindex` rebuilds the index)",
            if ip == 0 { "unset" } else { "past the end" }
        ));
    }
    if let Some(w) = &stopped {
        diag.push(path, 0, w.clone());
    }
    if bad_chunks > 0 {
        diag.note(format!(
            "{bad_chunks} of {chunks} chunks could not be read whole (their messages are missing)"
        ));
    }
    for (id, n) in &st.orphans {
        diag.push(
            path,
            0,
            format!("{n} messages on connection {id}, which no connection record defines; skipped"),
        );
    }
    if st.messages == 0 && stopped.is_some() {
        return Err(nodata(format!(
            "no message read: {}",
            stopped.unwrap_or_default()
        )));
    }
    for t in st.topics.values_mut() {
        if let Some(why) = &t.unusable {
            diag.push(path, 0, format!("topic {}: {why}", t.summary.topic));
        }
    }
    let mut out = assemble(st.topics, &DIALECT, path, choice, opts, diag)?;
    out.summary.stopped_early = stopped;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_and_records_guard_their_lengths() {
        let mut f = Vec::new();
        f.extend_from_slice(&7u32.to_le_bytes());
        f.extend_from_slice(b"op=\x02ab");
        assert!(parse_fields(&f).is_err_and(|e| e.contains("7 bytes where 6 remain")));
        assert!(parse_fields(&[1, 0]).is_err_and(|e| e.contains("2 stray bytes")));
        assert!(parse_fields(b"\x02\0\0\0op").is_err_and(|e| e.contains("without '='")));
        let mut g = Vec::new();
        g.extend_from_slice(&4u32.to_le_bytes());
        g.extend_from_slice(b"op=\x07");
        assert_eq!(parse_fields(&g).unwrap(), vec![(&b"op"[..], &b"\x07"[..])]);
        // A record whose header claims 4 GiB: cut, no allocation.
        let mut r = u32::MAX.to_le_bytes().to_vec();
        r.extend_from_slice(&[0; 8]);
        let (recs, cut) = records(&r, 13);
        assert!(recs.is_empty());
        assert!(matches!(cut, Some(Cut::Overrun(13, _))));
        // A whole record: header g, data "xyz".
        let mut w = (g.len() as u32).to_le_bytes().to_vec();
        w.extend_from_slice(&g);
        w.extend_from_slice(&3u32.to_le_bytes());
        w.extend_from_slice(b"xyz");
        let (recs, cut) = records(&w, 0);
        assert!(cut.is_none());
        assert_eq!(
            (recs[0].op(), recs[0].data),
            (Some(OP_CONNECTION), &b"xyz"[..])
        );
    }

    #[test]
    fn message_layouts_are_checked() {
        // A NavSatFix body with one byte too many is another layout.
        let mut m = Vec::new();
        m.extend_from_slice(&[0; 12]); // seq, stamp
        m.extend_from_slice(&0u32.to_le_bytes()); // frame_id ""
        m.extend_from_slice(&[0; 3]); // status, service
        m.extend_from_slice(&[0; 24 + 72 + 1]);
        assert!(decode(MsgKind::Fix, &m).is_ok());
        m.push(0);
        assert!(
            decode(MsgKind::Fix, &m)
                .unwrap_err()
                .contains("1 bytes left")
        );
        m.truncate(20);
        assert!(decode(MsgKind::Fix, &m).unwrap_err().contains("truncated"));
        // A string longer than the body: an error, not a panic.
        let mut s = vec![0; 12];
        s.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode(MsgKind::Imu, &s).is_err());
    }
}
