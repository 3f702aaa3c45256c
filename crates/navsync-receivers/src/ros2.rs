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
//! - The messages and what becomes of them are shared with ROS 1 bags
//!   ([`crate::rosmsg`]); this module is the MCAP container and CDR.

use std::collections::BTreeMap;
use std::path::Path;

use navsync::error::{Diagnostics, Error};

pub use crate::rosmsg::{
    AltitudeDatum, BagData, BagFix, BagOptions, BagSummary, Header, Imu, NavSatFix, StampLag,
    TopicChoice, TopicSummary, TwistStamped,
};
use crate::rosmsg::{Decoded, Dialect, Item, MsgKind, Topic, Wire, assemble};
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
    /// A CDR string: uint32 length counting the NUL, the bytes, the NUL.
    pub(crate) fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        let b = self.take(n, 1)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Ok(String::from_utf8_lossy(b).into_owned())
    }
}

/// A CDR body as the shared message reader.
impl Wire for Cdr<'_> {
    fn u8(&mut self) -> Result<u8, String> {
        Cdr::u8(self)
    }
    fn u16(&mut self) -> Result<u16, String> {
        Cdr::u16(self)
    }
    fn u32(&mut self) -> Result<u32, String> {
        Cdr::u32(self)
    }
    fn f64(&mut self) -> Result<f64, String> {
        Cdr::f64(self)
    }
    fn string(&mut self) -> Result<String, String> {
        Cdr::string(self)
    }
    /// `std_msgs/msg/Header`: `builtin_interfaces/Time` (int32 sec,
    /// uint32 nanosec), string frame_id.
    fn header(&mut self) -> Result<Header, String> {
        Ok(Header {
            sec: self.i32()? as i64,
            nanosec: self.u32()?,
            frame_id: self.string()?,
        })
    }
}

impl Imu {
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        Imu::read(&mut Cdr::new(data)?)
    }
}

impl NavSatFix {
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        NavSatFix::read(&mut Cdr::new(data)?)
    }
}

impl TwistStamped {
    /// `geometry_msgs/msg/TwistWithCovarianceStamped`.
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        TwistStamped::read(&mut Cdr::new(data)?, true)
    }
}

const DIALECT: Dialect = Dialect {
    name: "ROS 2",
    imu: IMU_SCHEMA,
    fix: NAVSATFIX_SCHEMA,
    velocity: TWIST_SCHEMA,
    speed: "nav_msgs/msg/Odometry (not read from ROS 2 bags yet)",
    imu_most_messages: false,
};

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
    let opts = BagOptions {
        default_sd_m: opts_default_sd,
        altitude: AltitudeDatum::Ellipsoid,
    };
    read_bag_with(bytes, path, choice, &opts, diag)
}

/// [`read_bag`] with every option.
pub fn read_bag_with(
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
        let t = topics.entry(ch.topic.clone()).or_insert_with(|| {
            let kind = match schema.as_str() {
                IMU_SCHEMA => Some(MsgKind::Imu),
                NAVSATFIX_SCHEMA => Some(MsgKind::Fix),
                TWIST_SCHEMA => Some(MsgKind::TwistCov),
                _ => None,
            };
            let unusable = (kind.is_some() && ch.message_encoding != "cdr").then(|| {
                format!(
                    "message encoding {}; navsync reads ROS 2 CDR (`cdr`)",
                    ch.message_encoding
                )
            });
            Topic {
                summary: TopicSummary {
                    topic: ch.topic.clone(),
                    schema: schema.clone(),
                    message_encoding: ch.message_encoding.clone(),
                    ..Default::default()
                },
                kind,
                unusable,
                items: Vec::new(),
            }
        });
        t.summary.messages += 1;
        if ch.message_encoding != "cdr" {
            continue;
        }
        let msg = match t.kind {
            Some(MsgKind::Imu) => Imu::decode(&m.data).map(Decoded::Imu),
            Some(MsgKind::Fix) => NavSatFix::decode(&m.data).map(Decoded::Fix),
            Some(MsgKind::TwistCov) => TwistStamped::decode(&m.data).map(Decoded::Twist),
            _ => continue,
        };
        t.items.push(Item {
            number,
            log_time: m.log_time,
            msg,
        });
    }
    let mut out = assemble(topics, &DIALECT, path, choice, opts, diag)?;
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
        let h = c.header().unwrap();
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
}
