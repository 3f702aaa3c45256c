//! Incremental reader of a mixed NMEA 0183 + UBX byte stream, as a u-blox
//! receiver emits it on one port.
//!
//! Push bytes as they arrive ([`StreamReader::push`]), take events
//! ([`StreamReader::next_event`]); at the end of a file call
//! [`StreamReader::finish`]. The same reader serves a file (one push of the
//! whole file, or blocks) and a live serial port (one push per `read`).
//!
//! Every byte of the stream ends up in exactly one event: a decoded message,
//! an intact frame of a type navsync does not read ([`EventKind::Unknown`],
//! RTCM 3 correction frames among them: [`FrameId::Rtcm3`]),
//! an intact frame whose content is wrong for its type
//! ([`EventKind::Invalid`]), or a run of bytes that belong to no intact
//! frame ([`EventKind::Corrupt`], with its offset, length and what was
//! wrong with the first frame candidate in it). So nothing is lost
//! silently and every corruption is reported.
//!
//! Resynchronization: a frame candidate starts at a UBX sync pair `B5 62`,
//! at `$`, or at an RTCM 3 preamble `D3` whose 6 reserved bits are zero. A
//! candidate whose checksum (UBX Fletcher-8, [M8] §32.4; NMEA XOR, NMEA 0183
//! §5.2.1; RTCM 3 CRC-24Q, RTCM 10403.x §4) or structure fails is abandoned and scanning resumes at
//! its *second* byte, so an intact frame that a corrupted one seemed to
//! cover (a corrupted length field) is still found.

use std::collections::VecDeque;
use std::fmt;

use crate::nmea::{self, NmeaMessage};
use crate::rtcm3;
use crate::ubx::{self, MsgId, UbxMessage};

/// Limits that bound how long a candidate can make the reader wait.
#[derive(Copy, Clone, Debug)]
pub(crate) struct ReaderLimits {
    /// Largest UBX payload accepted (bytes). u-blox output messages stay
    /// below ~8.2 kB (RXM-RAWX: 16 + 32·255); a longer length field is
    /// treated as corruption.
    pub(crate) max_ubx_payload: usize,
    /// Longest NMEA sentence accepted, `$` to LF (NMEA 0183 says 82;
    /// receivers exceed it, e.g. u-blox PUBX).
    pub(crate) max_nmea_len: usize,
}

impl Default for ReaderLimits {
    fn default() -> Self {
        ReaderLimits {
            max_ubx_payload: 8192,
            max_nmea_len: 256,
        }
    }
}

/// The type of an intact frame.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FrameId {
    Ubx(MsgId),
    /// NMEA address field, e.g. `GNGSV` or `PUBX`.
    Nmea(String),
    /// RTCM 3 frame and its message number (`None`: shorter than 2 bytes).
    Rtcm3(Option<u16>),
}

impl fmt::Display for FrameId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameId::Ubx(id) => write!(f, "{id}"),
            FrameId::Nmea(a) => write!(f, "NMEA {a}"),
            FrameId::Rtcm3(Some(n)) => write!(f, "RTCM3 {n}"),
            FrameId::Rtcm3(None) => write!(f, "RTCM3 (empty)"),
        }
    }
}

/// Why a frame candidate was abandoned.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SkipReason {
    /// Bytes that start no frame.
    Stray,
    UbxChecksum {
        id: MsgId,
        payload_len: usize,
        computed: [u8; 2],
        found: [u8; 2],
    },
    UbxTooLong {
        id: MsgId,
        payload_len: usize,
    },
    NmeaChecksum {
        address: String,
        computed: u8,
        found: u8,
    },
    /// A byte that cannot be inside a sentence.
    NmeaBadByte {
        byte: u8,
    },
    NmeaNoChecksum,
    NmeaBadChecksumDigits,
    NmeaNoTerminator,
    NmeaTooLong,
    Rtcm3Crc {
        message_len: usize,
        computed: u32,
        found: u32,
    },
    /// The stream ended inside a frame candidate.
    Truncated,
}

impl fmt::Display for SkipReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SkipReason::Stray => write!(f, "bytes outside any frame"),
            SkipReason::UbxChecksum {
                id,
                payload_len,
                computed,
                found,
            } => write!(
                f,
                "{id} frame ({payload_len}-byte payload): checksum {:02X} {:02X}, computed {:02X} {:02X}",
                found[0], found[1], computed[0], computed[1]
            ),
            SkipReason::UbxTooLong { id, payload_len } => write!(
                f,
                "{id} header claims a {payload_len}-byte payload, above the limit"
            ),
            SkipReason::NmeaChecksum {
                address,
                computed,
                found,
            } => write!(
                f,
                "NMEA {address} sentence: checksum {found:02X}, computed {computed:02X}"
            ),
            SkipReason::NmeaBadByte { byte } => {
                write!(f, "NMEA sentence holds byte 0x{byte:02X}")
            }
            SkipReason::NmeaNoChecksum => write!(f, "NMEA sentence ends without a checksum"),
            SkipReason::NmeaBadChecksumDigits => {
                write!(f, "NMEA checksum is not two hex digits")
            }
            SkipReason::NmeaNoTerminator => write!(f, "NMEA sentence not ended by CR LF"),
            SkipReason::NmeaTooLong => write!(f, "NMEA sentence longer than the limit"),
            SkipReason::Rtcm3Crc {
                message_len,
                computed,
                found,
            } => write!(
                f,
                "RTCM3 frame ({message_len}-byte message): CRC-24Q {found:06X}, computed {computed:06X}"
            ),
            SkipReason::Truncated => write!(f, "stream ends inside a frame"),
        }
    }
}

/// A run of bytes belonging to no intact frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Corruption {
    /// What was wrong with the first candidate (or [`SkipReason::Stray`]).
    pub first: SkipReason,
    /// Frame candidates abandoned inside the run.
    pub candidates: u32,
}

/// What a span of the stream turned out to be.
#[derive(Clone, Debug, PartialEq)]
pub enum EventKind {
    Ubx(UbxMessage),
    Nmea(NmeaMessage),
    /// An intact frame of a type navsync does not read.
    Unknown(FrameId),
    /// An intact frame (checksum right) whose content is invalid.
    Invalid {
        frame: FrameId,
        what: String,
    },
    /// Bytes in no intact frame.
    Corrupt(Corruption),
}

/// One span of the stream: `len` bytes from absolute byte `offset`.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    pub offset: u64,
    pub len: usize,
    pub kind: EventKind,
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.kind {
            EventKind::Ubx(m) => write!(f, "byte {}: {}", self.offset, m.id()),
            EventKind::Nmea(m) => write!(f, "byte {}: NMEA {}", self.offset, m.kind()),
            EventKind::Unknown(id) => write!(f, "byte {}: {id} (not read)", self.offset),
            EventKind::Invalid { frame, what } => {
                write!(f, "byte {}: {frame} frame invalid: {what}", self.offset)
            }
            EventKind::Corrupt(c) => {
                write!(
                    f,
                    "bytes {}..{} skipped: {}",
                    self.offset,
                    self.offset + self.len as u64,
                    c.first
                )?;
                if c.candidates > 1 {
                    write!(f, " (+{} more bad candidates)", c.candidates - 1)?;
                }
                Ok(())
            }
        }
    }
}

/// Counts over everything read so far.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct StreamStats {
    pub bytes: u64,
    pub ubx_messages: u64,
    pub nmea_messages: u64,
    /// Intact frames of types navsync does not read (RTCM 3 included).
    pub unknown_frames: u64,
    /// RTCM 3 frames (CRC-24Q right), skipped.
    pub rtcm3_frames: u64,
    pub invalid_frames: u64,
    pub corrupt_runs: u64,
    pub corrupt_bytes: u64,
}

/// Outcome of looking at the candidate at the current position.
enum Step {
    /// Need more bytes to decide.
    Wait,
    /// Not a frame: skip one byte for this reason.
    Skip(SkipReason),
    /// An intact frame of this many bytes.
    Frame(usize, EventKind),
}

/// The incremental mixed-stream reader.
pub struct StreamReader {
    buf: Vec<u8>,
    /// Index in `buf` of the first byte not yet accounted for.
    pos: usize,
    /// Absolute offset of `buf[0]`.
    base: u64,
    pending: Option<(u64, usize, Corruption)>,
    events: VecDeque<Event>,
    limits: ReaderLimits,
    eof: bool,
    stats: StreamStats,
}

impl Default for StreamReader {
    fn default() -> Self {
        Self::new()
    }
}

impl StreamReader {
    pub fn new() -> Self {
        Self::with_limits(ReaderLimits::default())
    }

    pub(crate) fn with_limits(limits: ReaderLimits) -> Self {
        StreamReader {
            buf: Vec::new(),
            pos: 0,
            base: 0,
            pending: None,
            events: VecDeque::new(),
            limits,
            eof: false,
            stats: StreamStats::default(),
        }
    }

    /// Offsets in events start at `offset` (e.g. after a file's header).
    pub(crate) fn starting_at(mut self, offset: u64) -> Self {
        self.base = offset;
        self
    }

    /// Appends bytes from the stream and parses what is complete.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.pos > 0 && self.pos * 2 >= self.buf.len() {
            self.buf.drain(..self.pos);
            self.base += self.pos as u64;
            self.pos = 0;
        }
        self.buf.extend_from_slice(bytes);
        self.stats.bytes += bytes.len() as u64;
        self.process();
    }

    /// Marks the end of the stream: what is left becomes a corrupt run
    /// (a truncated frame).
    pub fn finish(&mut self) {
        self.eof = true;
        self.process();
        self.flush_pending();
    }

    /// The next event, in stream order.
    pub fn next_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    pub fn stats(&self) -> &StreamStats {
        &self.stats
    }

    /// Bytes held waiting for the rest of a frame.
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn process(&mut self) {
        while self.pos < self.buf.len() {
            match self.step() {
                Step::Wait => {
                    if self.eof {
                        self.skip(SkipReason::Truncated);
                    } else {
                        return;
                    }
                }
                Step::Skip(reason) => self.skip(reason),
                Step::Frame(len, kind) => {
                    self.flush_pending();
                    match &kind {
                        EventKind::Ubx(_) => self.stats.ubx_messages += 1,
                        EventKind::Nmea(_) => self.stats.nmea_messages += 1,
                        EventKind::Unknown(id) => {
                            self.stats.unknown_frames += 1;
                            if let FrameId::Rtcm3(_) = id {
                                self.stats.rtcm3_frames += 1;
                            }
                        }
                        EventKind::Invalid { .. } => self.stats.invalid_frames += 1,
                        EventKind::Corrupt(_) => {}
                    }
                    self.events.push_back(Event {
                        offset: self.base + self.pos as u64,
                        len,
                        kind,
                    });
                    self.pos += len;
                }
            }
        }
    }

    fn skip(&mut self, reason: SkipReason) {
        let offset = self.base + self.pos as u64;
        let is_candidate = reason != SkipReason::Stray;
        match &mut self.pending {
            Some((_, len, c)) => {
                *len += 1;
                if is_candidate {
                    if c.candidates == 0 {
                        c.first = reason;
                    }
                    c.candidates += 1;
                }
            }
            None => {
                self.pending = Some((
                    offset,
                    1,
                    Corruption {
                        first: reason,
                        candidates: is_candidate as u32,
                    },
                ))
            }
        }
        self.pos += 1;
    }

    fn flush_pending(&mut self) {
        if let Some((offset, len, c)) = self.pending.take() {
            self.stats.corrupt_runs += 1;
            self.stats.corrupt_bytes += len as u64;
            self.events.push_back(Event {
                offset,
                len,
                kind: EventKind::Corrupt(c),
            });
        }
    }

    fn step(&self) -> Step {
        let b = &self.buf[self.pos..];
        match b[0] {
            ubx::SYNC1 => self.step_ubx(b),
            b'$' => self.step_nmea(b),
            rtcm3::PREAMBLE => self.step_rtcm3(b),
            _ => Step::Skip(SkipReason::Stray),
        }
    }

    /// RTCM 10403.x §4 transport frame: `D3`, 6 zero bits, 10-bit length,
    /// message, CRC-24Q. Recognised and skipped (navsync reads no RTCM).
    fn step_rtcm3(&self, b: &[u8]) -> Step {
        if b.len() < 3 {
            return Step::Wait;
        }
        if b[1] & 0xFC != 0 {
            return Step::Skip(SkipReason::Stray);
        }
        let message_len = (((b[1] & 0x03) as usize) << 8) | b[2] as usize;
        let total = message_len + rtcm3::FRAME_OVERHEAD;
        if b.len() < total {
            return Step::Wait;
        }
        let computed = rtcm3::crc24q(&b[..3 + message_len]);
        let c = &b[3 + message_len..total];
        let found = u32::from_be_bytes([0, c[0], c[1], c[2]]);
        if computed != found {
            return Step::Skip(SkipReason::Rtcm3Crc {
                message_len,
                computed,
                found,
            });
        }
        let number = rtcm3::message_number(&b[3..3 + message_len]);
        Step::Frame(total, EventKind::Unknown(FrameId::Rtcm3(number)))
    }

    fn step_ubx(&self, b: &[u8]) -> Step {
        if b.len() < 2 {
            return Step::Wait;
        }
        if b[1] != ubx::SYNC2 {
            return Step::Skip(SkipReason::Stray);
        }
        if b.len() < 6 {
            return Step::Wait;
        }
        let id = MsgId {
            class: b[2],
            id: b[3],
        };
        let payload_len = u16::from_le_bytes([b[4], b[5]]) as usize;
        if payload_len > self.limits.max_ubx_payload {
            return Step::Skip(SkipReason::UbxTooLong { id, payload_len });
        }
        let total = payload_len + ubx::FRAME_OVERHEAD;
        if b.len() < total {
            return Step::Wait;
        }
        let computed = ubx::checksum(&b[2..6 + payload_len]);
        let found = [b[6 + payload_len], b[7 + payload_len]];
        if computed != found {
            return Step::Skip(SkipReason::UbxChecksum {
                id,
                payload_len,
                computed,
                found,
            });
        }
        let payload = &b[6..6 + payload_len];
        let kind = match UbxMessage::decode(id, payload) {
            Ok(Some(m)) => EventKind::Ubx(m),
            Ok(None) => EventKind::Unknown(FrameId::Ubx(id)),
            Err(e) => EventKind::Invalid {
                frame: FrameId::Ubx(id),
                what: e.what,
            },
        };
        Step::Frame(total, kind)
    }

    fn step_nmea(&self, b: &[u8]) -> Step {
        // `$`, printable characters up to `*`, two hex digits, CR LF (or LF).
        let limit = self.limits.max_nmea_len.min(b.len());
        let mut star = None;
        for (k, &c) in b.iter().enumerate().take(limit).skip(1) {
            match c {
                b'*' => {
                    star = Some(k);
                    break;
                }
                b'\r' | b'\n' => return Step::Skip(SkipReason::NmeaNoChecksum),
                b'$' | 0..=0x1F | 0x7F..=0xFF => {
                    return Step::Skip(SkipReason::NmeaBadByte { byte: c });
                }
                _ => {}
            }
        }
        let Some(star) = star else {
            return if b.len() >= self.limits.max_nmea_len {
                Step::Skip(SkipReason::NmeaTooLong)
            } else {
                Step::Wait
            };
        };
        if b.len() < star + 4 {
            return Step::Wait;
        }
        let hex = |c: u8| (c as char).to_digit(16);
        let (Some(h), Some(l)) = (hex(b[star + 1]), hex(b[star + 2])) else {
            return Step::Skip(SkipReason::NmeaBadChecksumDigits);
        };
        let found = (h * 16 + l) as u8;
        let computed = nmea::checksum(&b[1..star]);
        let address_end = b[1..star]
            .iter()
            .position(|&c| c == b',')
            .map_or(star, |p| p + 1);
        let address = || String::from_utf8_lossy(&b[1..address_end]).into_owned();
        if found != computed {
            return Step::Skip(SkipReason::NmeaChecksum {
                address: address(),
                computed,
                found,
            });
        }
        let total = match (b[star + 3], b.get(star + 4)) {
            (b'\n', _) => star + 4,
            (b'\r', Some(b'\n')) => star + 5,
            (b'\r', None) => return Step::Wait,
            _ => return Step::Skip(SkipReason::NmeaNoTerminator),
        };
        if total > self.limits.max_nmea_len {
            return Step::Skip(SkipReason::NmeaTooLong);
        }
        // Printable ASCII only, so this is valid UTF-8.
        let sentence = std::str::from_utf8(&b[..star + 3]).unwrap_or("");
        let kind = match nmea::decode(sentence) {
            Ok(Some(m)) => EventKind::Nmea(m),
            Ok(None) => EventKind::Unknown(FrameId::Nmea(address())),
            Err(what) => EventKind::Invalid {
                frame: FrameId::Nmea(address()),
                what,
            },
        };
        Step::Frame(total, kind)
    }
}

/// Length of a gpsd test log's header: the `#` comment lines at the start
/// (the raw stream follows). Only leading lines count: a `#` byte later on
/// is stream data.
pub fn gpsd_log_header_len(bytes: &[u8]) -> usize {
    let mut pos = 0;
    while bytes.get(pos) == Some(&b'#') {
        match bytes[pos..].iter().position(|&c| c == b'\n') {
            Some(nl) => pos += nl + 1,
            None => return bytes.len(),
        }
    }
    pos
}

/// Reads a whole byte slice: all events, in order.
pub fn read_all(bytes: &[u8], start_offset: u64) -> (Vec<Event>, StreamStats) {
    let mut r = StreamReader::new().starting_at(start_offset);
    r.push(bytes);
    r.finish();
    let mut out = Vec::new();
    while let Some(e) = r.next_event() {
        out.push(e);
    }
    (out, r.stats().clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tp_frame(q: i32) -> Vec<u8> {
        UbxMessage::TimTp(ubx::TimTp {
            tow_ms: 1000,
            tow_sub_ms: 0,
            q_err_ps: q,
            week: 2300,
            flags: 0,
            ref_info: 0,
        })
        .to_frame()
        .unwrap()
    }

    #[test]
    fn byte_by_byte_equals_one_push() {
        let mut s = Vec::new();
        s.extend(tp_frame(5));
        s.extend(b"junk");
        s.extend(nmea::encode_sentence("GPTXT,01,01,02,hello").as_bytes());
        s.extend(tp_frame(-7));
        let (all, _) = read_all(&s, 0);
        let mut r = StreamReader::new();
        for b in &s {
            r.push(std::slice::from_ref(b));
        }
        r.finish();
        let mut one = Vec::new();
        while let Some(e) = r.next_event() {
            one.push(e);
        }
        assert_eq!(all, one);
        assert_eq!(all.len(), 4);
        assert!(matches!(all[1].kind, EventKind::Corrupt(_)));
        assert_eq!((all[1].offset, all[1].len), (24, 4));
        assert!(matches!(all[2].kind, EventKind::Unknown(FrameId::Nmea(ref a)) if a == "GPTXT"));
    }

    #[test]
    fn corrupted_length_does_not_hide_following_frames() {
        let mut a = tp_frame(1);
        a[4] = 0xFF; // length 0x00FF: swallows the next frame as "payload"
        let b = tp_frame(2);
        let mut s = a.clone();
        s.extend(&b);
        s.extend(vec![0u8; 300]);
        let (ev, _) = read_all(&s, 0);
        let msgs: Vec<_> = ev
            .iter()
            .filter(|e| matches!(e.kind, EventKind::Ubx(_)))
            .collect();
        assert_eq!(msgs.len(), 1);
        assert_eq!(msgs[0].offset, a.len() as u64);
    }

    #[test]
    fn truncated_tail_is_reported() {
        let f = tp_frame(3);
        let (ev, st) = read_all(&f[..10], 100);
        assert_eq!(ev.len(), 1);
        assert_eq!(ev[0].offset, 100);
        assert_eq!(ev[0].len, 10);
        assert!(matches!(&ev[0].kind, EventKind::Corrupt(c) if c.first == SkipReason::Truncated));
        assert_eq!(st.corrupt_bytes, 10);
    }

    #[test]
    fn rtcm3_frames_are_recognised_and_skipped() {
        let rtcm = rtcm3::encode_frame(&[0x43, 0x50, 1, 2, 3, 4, 5]).unwrap(); // 1077
        let mut bad = rtcm.clone();
        bad[5] ^= 0x10;
        let mut s = tp_frame(1);
        s.extend(&rtcm);
        s.extend(&bad);
        s.extend(tp_frame(2));
        let (ev, st) = read_all(&s, 0);
        assert_eq!(ev.len(), 4, "{ev:?}");
        assert_eq!(ev[1].kind, EventKind::Unknown(FrameId::Rtcm3(Some(1077))));
        assert_eq!(ev[1].len, rtcm.len());
        // The damaged copy is one corrupt run naming the CRC.
        assert!(
            matches!(&ev[2].kind, EventKind::Corrupt(c) if matches!(c.first, SkipReason::Rtcm3Crc { message_len: 7, .. }))
        );
        assert_eq!(ev[2].len, bad.len());
        assert!(matches!(ev[3].kind, EventKind::Ubx(_)));
        assert_eq!(
            (st.rtcm3_frames, st.unknown_frames, st.corrupt_runs),
            (1, 1, 1)
        );
        // A D3 byte whose reserved bits are set starts no candidate.
        let (ev, _) = read_all(&[0xD3, 0xFF, 0x00], 0);
        assert!(matches!(&ev[0].kind, EventKind::Corrupt(c) if c.first == SkipReason::Stray));
    }

    #[test]
    fn header_length_stops_at_the_first_stream_byte() {
        assert_eq!(gpsd_log_header_len(b"# a\n# b\n\xB5b"), 8);
        assert_eq!(gpsd_log_header_len(b"$GP"), 0);
    }
}
