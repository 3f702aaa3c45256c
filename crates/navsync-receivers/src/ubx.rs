//! u-blox UBX binary protocol: frame checksum and encoder, and the messages
//! navsync reads (NAV-PVT, NAV-TIMEGPS, TIM-TP, TIM-TM2, ESF-MEAS, ESF-RAW,
//! and the older navigation set NAV-SOL, NAV-POSLLH, NAV-VELNED,
//! NAV-STATUS, plus the F9 high-precision NAV-HPPOSLLH and the moving-base
//! NAV-RELPOSNED of a dual-antenna heading setup; the dead-reckoning
//! receivers' NAV-PVAT and NAV-ATT are in [`crate::ubx_dr`]).
//!
//! Written from the u-blox interface descriptions rather than with the
//! `ublox` crate: 0.10.0 panics in `TimTm2Flags::time_base()` for the GNSS
//! and UTC time bases, decodes ESF-MEAS sensor values as sign-magnitude
//! (they are 24-bit two's complement: the real NEO-M8L fixture shows
//! `0xfffffc` for −4 · 2⁻¹⁰ m/s²), and has no encoders for received messages.
//! References, cited per message below:
//! - [M8] u-blox 8 / u-blox M8 Receiver Description including Protocol
//!   Specification, UBX-13003221 (R20+): §32.2 frame structure, §32.4
//!   checksum, UBX-NAV-PVT, UBX-NAV-TIMEGPS, UBX-TIM-TP, UBX-TIM-TM2,
//!   UBX-ESF-MEAS, UBX-ESF-RAW.
//! - [F9] ZED-F9P Interface Description, UBX-18010854 (R08): §3.4 UBX frame
//!   structure, §5.17.1 UBX-TIM-TM2, §5.17.2 UBX-TIM-TP (same layouts).
//! - [M8] also gives NAV-SOL, NAV-POSLLH, NAV-VELNED and NAV-STATUS (the
//!   same layouts as the u-blox 6 Receiver Description, GPS.G6-SW-10018,
//!   for LEA-6/NEO-6 and earlier).
//! - [F9] §5.14 UBX-NAV-HPPOSLLH (protocol ≥ 27): invalidLlh in `flags`.
//! - [F9] UBX-NAV-RELPOSNED (0x01 0x3C), version 0x01, 64 bytes: the
//!   relative position of the rover antenna from the (moving) base,
//!   relPosHeading and accHeading; also ZED-F9P Integration Manual
//!   UBX-18010802, "Moving base" (heading of the base→rover vector).
//! - [F9K] ZED-F9K Integration Manual, §3.2.6 Table 11: ESF data types and
//!   their scaling.
//!
//! Every decoder checks the payload length first and reads fixed offsets; no
//! decoder can panic on any input (fuzzed, see `fuzz/`). Every message keeps
//! all of its bytes, reserved ones included, so `encode(decode(frame))`
//! reproduces a real frame bit for bit.

pub use crate::ubx_dr::{NavAtt, NavPvat};
use std::fmt;

/// First UBX sync character ([M8] §32.2).
pub const SYNC1: u8 = 0xB5;
/// Second UBX sync character ([M8] §32.2).
pub const SYNC2: u8 = 0x62;
/// Bytes around the payload: 2 sync, class, id, 2 length, 2 checksum.
pub(crate) const FRAME_OVERHEAD: usize = 8;

/// 8-bit Fletcher checksum over class, id, length and payload ([M8] §32.4,
/// RFC 1145): `CK_A += b; CK_B += CK_A` modulo 256.
pub fn checksum(bytes: &[u8]) -> [u8; 2] {
    let (mut a, mut b) = (0u8, 0u8);
    for &x in bytes {
        a = a.wrapping_add(x);
        b = b.wrapping_add(a);
    }
    [a, b]
}

/// A whole UBX frame (sync, class, id, little-endian length, payload,
/// checksum). Errors when the payload exceeds the 16-bit length field.
pub fn encode_frame(class: u8, id: u8, payload: &[u8]) -> Result<Vec<u8>, PayloadError> {
    let len = u16::try_from(payload.len()).map_err(|_| PayloadError {
        what: format!(
            "payload of {} bytes exceeds the 65535-byte UBX limit",
            payload.len()
        ),
    })?;
    let mut out = Vec::with_capacity(payload.len() + FRAME_OVERHEAD);
    out.extend_from_slice(&[SYNC1, SYNC2, class, id]);
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(payload);
    let ck = checksum(&out[2..]);
    out.extend_from_slice(&ck);
    Ok(out)
}

/// A payload that does not fit its message's layout.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PayloadError {
    pub what: String,
}

impl fmt::Display for PayloadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.what)
    }
}

impl std::error::Error for PayloadError {}

pub(crate) fn bad_len(name: &str, len: usize, expected: &str) -> PayloadError {
    PayloadError {
        what: format!("{name} payload is {len} bytes, expected {expected}"),
    }
}

/// Little-endian field reader over a payload whose length was checked.
pub(crate) struct Rd<'a>(pub(crate) &'a [u8]);

impl Rd<'_> {
    pub(crate) fn u1(&self, o: usize) -> u8 {
        self.0[o]
    }
    pub(crate) fn i1(&self, o: usize) -> i8 {
        self.0[o] as i8
    }
    pub(crate) fn u2(&self, o: usize) -> u16 {
        u16::from_le_bytes([self.0[o], self.0[o + 1]])
    }
    pub(crate) fn i2(&self, o: usize) -> i16 {
        self.u2(o) as i16
    }
    pub(crate) fn u4(&self, o: usize) -> u32 {
        u32::from_le_bytes([self.0[o], self.0[o + 1], self.0[o + 2], self.0[o + 3]])
    }
    pub(crate) fn i4(&self, o: usize) -> i32 {
        self.u4(o) as i32
    }
    pub(crate) fn arr<const N: usize>(&self, o: usize) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&self.0[o..o + N]);
        a
    }
}

/// Class and id of a UBX message.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MsgId {
    pub class: u8,
    pub id: u8,
}

impl MsgId {
    pub(crate) const NAV_PVT: MsgId = MsgId {
        class: 0x01,
        id: 0x07,
    };
    pub(crate) const NAV_POSLLH: MsgId = MsgId {
        class: 0x01,
        id: 0x02,
    };
    pub(crate) const NAV_STATUS: MsgId = MsgId {
        class: 0x01,
        id: 0x03,
    };
    pub(crate) const NAV_SOL: MsgId = MsgId {
        class: 0x01,
        id: 0x06,
    };
    pub(crate) const NAV_HPPOSLLH: MsgId = MsgId {
        class: 0x01,
        id: 0x14,
    };
    pub(crate) const NAV_VELNED: MsgId = MsgId {
        class: 0x01,
        id: 0x12,
    };
    pub(crate) const NAV_RELPOSNED: MsgId = MsgId {
        class: 0x01,
        id: 0x3C,
    };
    pub(crate) const NAV_PVAT: MsgId = MsgId {
        class: 0x01,
        id: 0x17,
    };
    pub(crate) const NAV_ATT: MsgId = MsgId {
        class: 0x01,
        id: 0x05,
    };
    pub(crate) const NAV_TIMEGPS: MsgId = MsgId {
        class: 0x01,
        id: 0x20,
    };
    pub(crate) const TIM_TP: MsgId = MsgId {
        class: 0x0D,
        id: 0x01,
    };
    pub(crate) const TIM_TM2: MsgId = MsgId {
        class: 0x0D,
        id: 0x03,
    };
    pub(crate) const ESF_MEAS: MsgId = MsgId {
        class: 0x10,
        id: 0x02,
    };
    pub(crate) const ESF_RAW: MsgId = MsgId {
        class: 0x10,
        id: 0x03,
    };

    /// The u-blox name when navsync knows it (for reports), else `None`.
    pub fn name(self) -> Option<&'static str> {
        Some(match (self.class, self.id) {
            (0x01, 0x01) => "NAV-POSECEF",
            (0x01, 0x02) => "NAV-POSLLH",
            (0x01, 0x03) => "NAV-STATUS",
            (0x01, 0x04) => "NAV-DOP",
            (0x01, 0x05) => "NAV-ATT",
            (0x01, 0x06) => "NAV-SOL",
            (0x01, 0x07) => "NAV-PVT",
            (0x01, 0x11) => "NAV-VELECEF",
            (0x01, 0x14) => "NAV-HPPOSLLH",
            (0x01, 0x17) => "NAV-PVAT",
            (0x01, 0x12) => "NAV-VELNED",
            (0x01, 0x20) => "NAV-TIMEGPS",
            (0x01, 0x21) => "NAV-TIMEUTC",
            (0x01, 0x22) => "NAV-CLOCK",
            (0x01, 0x26) => "NAV-TIMELS",
            (0x01, 0x35) => "NAV-SAT",
            (0x01, 0x3C) => "NAV-RELPOSNED",
            (0x01, 0x3D) => "NAV-EELL",
            (0x01, 0x61) => "NAV-EOE",
            (0x02, 0x13) => "RXM-SFRBX",
            (0x02, 0x15) => "RXM-RAWX",
            (0x05, 0x00) => "ACK-NAK",
            (0x05, 0x01) => "ACK-ACK",
            (0x0A, 0x04) => "MON-VER",
            (0x0D, 0x01) => "TIM-TP",
            (0x0D, 0x03) => "TIM-TM2",
            (0x0D, 0x04) => "TIM-SVIN",
            (0x10, 0x02) => "ESF-MEAS",
            (0x10, 0x03) => "ESF-RAW",
            (0x10, 0x10) => "ESF-STATUS",
            (0x10, 0x14) => "ESF-ALG",
            (0x10, 0x15) => "ESF-INS",
            (0x28, 0x00) => "HNR-PVT",
            (0x28, 0x01) => "HNR-ATT",
            (0x28, 0x02) => "HNR-INS",
            _ => return None,
        })
    }
}

impl fmt::Display for MsgId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "UBX {n}"),
            None => write!(f, "UBX 0x{:02X} 0x{:02X}", self.class, self.id),
        }
    }
}

// ---------------------------------------------------------------- NAV-PVT

/// UBX-NAV-PVT (0x01 0x07), navigation position/velocity/time solution,
/// 92-byte payload ([M8] UBX-NAV-PVT; [F9] same layout, `flags3` at 78).
/// Raw integer fields as sent; accessors give SI units.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavPvt {
    /// GPS time of week of the navigation epoch (ms).
    pub itow_ms: u32,
    pub year: u16,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub min: u8,
    pub sec: u8,
    /// validDate (bit 0), validTime (1), fullyResolved (2), validMag (3).
    pub valid: u8,
    /// Time accuracy estimate (ns).
    pub t_acc_ns: u32,
    /// Fraction of the UTC second (ns, −1e9..1e9): UTC = date/time + nano.
    pub nano_ns: i32,
    /// 0 no fix, 1 DR only, 2 2D, 3 3D, 4 GNSS+DR, 5 time only.
    pub fix_type: u8,
    /// gnssFixOK (bit 0), diffSoln (1), psmState (2..4), headVehValid (5),
    /// carrSoln (6..7).
    pub flags: u8,
    /// confirmedAvai (5), confirmedDate (6), confirmedTime (7).
    pub flags2: u8,
    pub num_sv: u8,
    /// Longitude (1e-7 deg).
    pub lon_e7: i32,
    /// Latitude (1e-7 deg).
    pub lat_e7: i32,
    /// Height above the ellipsoid (mm).
    pub height_mm: i32,
    /// Height above mean sea level (mm).
    pub h_msl_mm: i32,
    /// Horizontal and vertical accuracy estimates (mm).
    pub h_acc_mm: u32,
    pub v_acc_mm: u32,
    /// NED velocity (mm/s).
    pub vel_ned_mm_s: [i32; 3],
    /// Ground speed (mm/s).
    pub g_speed_mm_s: i32,
    /// Heading of motion (1e-5 deg).
    pub head_mot_e5: i32,
    /// Speed accuracy estimate (mm/s).
    pub s_acc_mm_s: u32,
    /// Heading accuracy estimate (1e-5 deg).
    pub head_acc_e5: u32,
    /// Position DOP (0.01).
    pub p_dop_e2: u16,
    /// invalidLlh (bit 0), lastCorrectionAge (1..4) on protocol ≥ 27.
    pub flags3: u8,
    pub reserved1: [u8; 5],
    /// Heading of vehicle (1e-5 deg).
    pub head_veh_e5: i32,
    /// Magnetic declination and its accuracy (0.01 deg).
    pub mag_dec_e2: i16,
    pub mag_acc_e2: u16,
}

impl NavPvt {
    pub const LEN: usize = 92;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-PVT", p.len(), "92 (u-blox 8/9)"));
        }
        let r = Rd(p);
        Ok(NavPvt {
            itow_ms: r.u4(0),
            year: r.u2(4),
            month: r.u1(6),
            day: r.u1(7),
            hour: r.u1(8),
            min: r.u1(9),
            sec: r.u1(10),
            valid: r.u1(11),
            t_acc_ns: r.u4(12),
            nano_ns: r.i4(16),
            fix_type: r.u1(20),
            flags: r.u1(21),
            flags2: r.u1(22),
            num_sv: r.u1(23),
            lon_e7: r.i4(24),
            lat_e7: r.i4(28),
            height_mm: r.i4(32),
            h_msl_mm: r.i4(36),
            h_acc_mm: r.u4(40),
            v_acc_mm: r.u4(44),
            vel_ned_mm_s: [r.i4(48), r.i4(52), r.i4(56)],
            g_speed_mm_s: r.i4(60),
            head_mot_e5: r.i4(64),
            s_acc_mm_s: r.u4(68),
            head_acc_e5: r.u4(72),
            p_dop_e2: r.u2(76),
            flags3: r.u1(78),
            reserved1: r.arr(79),
            head_veh_e5: r.i4(84),
            mag_dec_e2: r.i2(88),
            mag_acc_e2: r.u2(90),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        w.extend_from_slice(&self.year.to_le_bytes());
        w.extend_from_slice(&[
            self.month, self.day, self.hour, self.min, self.sec, self.valid,
        ]);
        w.extend_from_slice(&self.t_acc_ns.to_le_bytes());
        w.extend_from_slice(&self.nano_ns.to_le_bytes());
        w.extend_from_slice(&[self.fix_type, self.flags, self.flags2, self.num_sv]);
        for v in [self.lon_e7, self.lat_e7, self.height_mm, self.h_msl_mm] {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.h_acc_mm.to_le_bytes());
        w.extend_from_slice(&self.v_acc_mm.to_le_bytes());
        for v in self.vel_ned_mm_s {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.g_speed_mm_s.to_le_bytes());
        w.extend_from_slice(&self.head_mot_e5.to_le_bytes());
        w.extend_from_slice(&self.s_acc_mm_s.to_le_bytes());
        w.extend_from_slice(&self.head_acc_e5.to_le_bytes());
        w.extend_from_slice(&self.p_dop_e2.to_le_bytes());
        w.push(self.flags3);
        w.extend_from_slice(&self.reserved1);
        w.extend_from_slice(&self.head_veh_e5.to_le_bytes());
        w.extend_from_slice(&self.mag_dec_e2.to_le_bytes());
        w.extend_from_slice(&self.mag_acc_e2.to_le_bytes());
        w
    }

    pub(crate) fn valid_date(&self) -> bool {
        self.valid & 0x01 != 0
    }
    pub(crate) fn valid_time(&self) -> bool {
        self.valid & 0x02 != 0
    }
    /// gnssFixOK: a valid fix within the DOP and accuracy masks.
    pub(crate) fn gnss_fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }
    /// headVehValid: headVeh is the vehicle's heading (dead-reckoning
    /// receivers); otherwise it repeats the heading of motion.
    pub fn head_veh_valid(&self) -> bool {
        self.flags & 0x20 != 0
    }
    /// invalidLlh (protocol ≥ 27): lon, lat, height and hMSL are invalid.
    pub(crate) fn invalid_llh(&self) -> bool {
        self.flags3 & 0x01 != 0
    }
    pub fn lat_deg(&self) -> f64 {
        self.lat_e7 as f64 * 1e-7
    }
    pub fn lon_deg(&self) -> f64 {
        self.lon_e7 as f64 * 1e-7
    }
    pub(crate) fn height_m(&self) -> f64 {
        self.height_mm as f64 * 1e-3
    }
    pub fn vel_ned_mps(&self) -> [f64; 3] {
        self.vel_ned_mm_s.map(|v| v as f64 * 1e-3)
    }
    pub(crate) fn h_acc_m(&self) -> f64 {
        self.h_acc_mm as f64 * 1e-3
    }
    pub(crate) fn v_acc_m(&self) -> f64 {
        self.v_acc_mm as f64 * 1e-3
    }
    pub(crate) fn s_acc_mps(&self) -> f64 {
        self.s_acc_mm_s as f64 * 1e-3
    }
}

// ------------------------------------------- NAV-SOL, NAV-POSLLH, NAV-VELNED

/// Fix type as NAV-PVT, NAV-SOL and NAV-STATUS report it ([M8]
/// UBX-NAV-PVT fixType, UBX-NAV-SOL gpsFix, UBX-NAV-STATUS gpsFix).
pub(crate) fn fix_type_name(fix_type: u8) -> &'static str {
    match fix_type {
        0 => "no fix",
        1 => "dead reckoning only",
        2 => "2D fix",
        3 => "3D fix",
        4 => "GNSS + dead reckoning",
        5 => "time only",
        _ => "reserved fix type",
    }
}

/// UBX-NAV-SOL (0x01 0x06), navigation solution in ECEF, 52 bytes ([M8]
/// UBX-NAV-SOL; u-blox 6 NAV-SOL). Superseded by NAV-PVT but still the
/// only full solution message of LEA-4/5/6 receivers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavSol {
    pub itow_ms: u32,
    /// Fraction of iTOW (ns, −500000..500000): epoch = iTOW + fTOW.
    pub ftow_ns: i32,
    /// GPS week of the epoch.
    pub week: i16,
    /// 0 no fix, 1 DR only, 2 2D, 3 3D, 4 GPS + DR, 5 time only.
    pub gps_fix: u8,
    /// GPSfixOK (bit 0), DiffSoln (1), WKNSET (2), TOWSET (3).
    pub flags: u8,
    /// ECEF position (cm).
    pub ecef_cm: [i32; 3],
    /// 3D position accuracy estimate (cm).
    pub p_acc_cm: u32,
    /// ECEF velocity (cm/s).
    pub ecef_vel_cm_s: [i32; 3],
    /// Speed accuracy estimate (cm/s).
    pub s_acc_cm_s: u32,
    /// Position DOP (0.01).
    pub p_dop_e2: u16,
    pub reserved1: u8,
    pub num_sv: u8,
    pub(crate) reserved2: [u8; 4],
}

impl NavSol {
    pub const LEN: usize = 52;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-SOL", p.len(), "52"));
        }
        let r = Rd(p);
        Ok(NavSol {
            itow_ms: r.u4(0),
            ftow_ns: r.i4(4),
            week: r.i2(8),
            gps_fix: r.u1(10),
            flags: r.u1(11),
            ecef_cm: [r.i4(12), r.i4(16), r.i4(20)],
            p_acc_cm: r.u4(24),
            ecef_vel_cm_s: [r.i4(28), r.i4(32), r.i4(36)],
            s_acc_cm_s: r.u4(40),
            p_dop_e2: r.u2(44),
            reserved1: r.u1(46),
            num_sv: r.u1(47),
            reserved2: r.arr(48),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        w.extend_from_slice(&self.ftow_ns.to_le_bytes());
        w.extend_from_slice(&self.week.to_le_bytes());
        w.extend_from_slice(&[self.gps_fix, self.flags]);
        for v in self.ecef_cm {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.p_acc_cm.to_le_bytes());
        for v in self.ecef_vel_cm_s {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.s_acc_cm_s.to_le_bytes());
        w.extend_from_slice(&self.p_dop_e2.to_le_bytes());
        w.extend_from_slice(&[self.reserved1, self.num_sv]);
        w.extend_from_slice(&self.reserved2);
        w
    }

    /// GPSfixOK: a valid fix within the DOP and accuracy masks.
    pub(crate) fn gps_fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }
    /// WKNSET and TOWSET: week and time of week are valid.
    pub(crate) fn week_and_tow_valid(&self) -> bool {
        self.flags & 0x0C == 0x0C
    }
    pub(crate) fn ecef_m(&self) -> [f64; 3] {
        self.ecef_cm.map(|v| v as f64 * 1e-2)
    }
    pub(crate) fn ecef_vel_mps(&self) -> [f64; 3] {
        self.ecef_vel_cm_s.map(|v| v as f64 * 1e-2)
    }
    pub(crate) fn p_acc_m(&self) -> f64 {
        self.p_acc_cm as f64 * 1e-2
    }
    pub(crate) fn s_acc_mps(&self) -> f64 {
        self.s_acc_cm_s as f64 * 1e-2
    }
}

/// UBX-NAV-POSLLH (0x01 0x02), geodetic position, 28 bytes ([M8]
/// UBX-NAV-POSLLH).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavPosLlh {
    pub itow_ms: u32,
    /// Longitude and latitude (1e-7 deg).
    pub lon_e7: i32,
    pub lat_e7: i32,
    /// Height above the ellipsoid and above mean sea level (mm).
    pub height_mm: i32,
    pub h_msl_mm: i32,
    /// Horizontal and vertical accuracy estimates (mm).
    pub h_acc_mm: u32,
    pub v_acc_mm: u32,
}

impl NavPosLlh {
    pub const LEN: usize = 28;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-POSLLH", p.len(), "28"));
        }
        let r = Rd(p);
        Ok(NavPosLlh {
            itow_ms: r.u4(0),
            lon_e7: r.i4(4),
            lat_e7: r.i4(8),
            height_mm: r.i4(12),
            h_msl_mm: r.i4(16),
            h_acc_mm: r.u4(20),
            v_acc_mm: r.u4(24),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        for v in [self.lon_e7, self.lat_e7, self.height_mm, self.h_msl_mm] {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.h_acc_mm.to_le_bytes());
        w.extend_from_slice(&self.v_acc_mm.to_le_bytes());
        w
    }

    pub fn lat_deg(&self) -> f64 {
        self.lat_e7 as f64 * 1e-7
    }
    pub fn lon_deg(&self) -> f64 {
        self.lon_e7 as f64 * 1e-7
    }
    pub(crate) fn height_m(&self) -> f64 {
        self.height_mm as f64 * 1e-3
    }
    pub(crate) fn h_acc_m(&self) -> f64 {
        self.h_acc_mm as f64 * 1e-3
    }
    pub(crate) fn v_acc_m(&self) -> f64 {
        self.v_acc_mm as f64 * 1e-3
    }
}

/// UBX-NAV-HPPOSLLH (0x01 0x14), high-precision geodetic position, 36
/// bytes ([F9] §5.14; [M8] for the HPG firmware): each coordinate is the
/// 1e-7 deg (or mm) field plus a high-precision part of 1e-9 deg (or
/// 0.1 mm); accuracies in 0.1 mm.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavHpPosLlh {
    pub version: u8,
    pub reserved1: [u8; 2],
    /// invalidLlh (bit 0).
    pub flags: u8,
    pub itow_ms: u32,
    pub lon_e7: i32,
    pub lat_e7: i32,
    pub height_mm: i32,
    pub h_msl_mm: i32,
    /// High-precision parts: lon, lat (1e-9 deg), height, hMSL (0.1 mm).
    pub lon_hp_e9: i8,
    pub lat_hp_e9: i8,
    pub height_hp_e4: i8,
    pub h_msl_hp_e4: i8,
    /// Horizontal and vertical accuracy estimates (0.1 mm).
    pub h_acc_e4: u32,
    pub v_acc_e4: u32,
}

impl NavHpPosLlh {
    pub const LEN: usize = 36;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-HPPOSLLH", p.len(), "36"));
        }
        let r = Rd(p);
        Ok(NavHpPosLlh {
            version: r.u1(0),
            reserved1: r.arr(1),
            flags: r.u1(3),
            itow_ms: r.u4(4),
            lon_e7: r.i4(8),
            lat_e7: r.i4(12),
            height_mm: r.i4(16),
            h_msl_mm: r.i4(20),
            lon_hp_e9: r.i1(24),
            lat_hp_e9: r.i1(25),
            height_hp_e4: r.i1(26),
            h_msl_hp_e4: r.i1(27),
            h_acc_e4: r.u4(28),
            v_acc_e4: r.u4(32),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.push(self.version);
        w.extend_from_slice(&self.reserved1);
        w.push(self.flags);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        for v in [self.lon_e7, self.lat_e7, self.height_mm, self.h_msl_mm] {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&[
            self.lon_hp_e9 as u8,
            self.lat_hp_e9 as u8,
            self.height_hp_e4 as u8,
            self.h_msl_hp_e4 as u8,
        ]);
        w.extend_from_slice(&self.h_acc_e4.to_le_bytes());
        w.extend_from_slice(&self.v_acc_e4.to_le_bytes());
        w
    }

    /// invalidLlh: lon, lat, height and hMSL are invalid.
    pub(crate) fn invalid_llh(&self) -> bool {
        self.flags & 0x01 != 0
    }
    /// lat + latHp (deg): 1e-7 deg + 1e-9 deg parts.
    pub fn lat_deg(&self) -> f64 {
        self.lat_e7 as f64 * 1e-7 + self.lat_hp_e9 as f64 * 1e-9
    }
    pub fn lon_deg(&self) -> f64 {
        self.lon_e7 as f64 * 1e-7 + self.lon_hp_e9 as f64 * 1e-9
    }
    /// height + heightHp (m): mm + 0.1 mm parts.
    pub(crate) fn height_m(&self) -> f64 {
        self.height_mm as f64 * 1e-3 + self.height_hp_e4 as f64 * 1e-4
    }
    pub(crate) fn h_acc_m(&self) -> f64 {
        self.h_acc_e4 as f64 * 1e-4
    }
    pub(crate) fn v_acc_m(&self) -> f64 {
        self.v_acc_e4 as f64 * 1e-4
    }
}

/// UBX-NAV-VELNED (0x01 0x12), velocity in NED, 36 bytes ([M8]
/// UBX-NAV-VELNED).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavVelNed {
    pub itow_ms: u32,
    /// NED velocity (cm/s).
    pub vel_ned_cm_s: [i32; 3],
    /// 3D speed and ground speed (cm/s).
    pub speed_cm_s: u32,
    pub g_speed_cm_s: u32,
    /// Heading of motion (1e-5 deg).
    pub heading_e5: i32,
    /// Speed accuracy estimate (cm/s).
    pub s_acc_cm_s: u32,
    /// Course accuracy estimate (1e-5 deg).
    pub c_acc_e5: u32,
}

impl NavVelNed {
    pub const LEN: usize = 36;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-VELNED", p.len(), "36"));
        }
        let r = Rd(p);
        Ok(NavVelNed {
            itow_ms: r.u4(0),
            vel_ned_cm_s: [r.i4(4), r.i4(8), r.i4(12)],
            speed_cm_s: r.u4(16),
            g_speed_cm_s: r.u4(20),
            heading_e5: r.i4(24),
            s_acc_cm_s: r.u4(28),
            c_acc_e5: r.u4(32),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        for v in self.vel_ned_cm_s {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.speed_cm_s.to_le_bytes());
        w.extend_from_slice(&self.g_speed_cm_s.to_le_bytes());
        w.extend_from_slice(&self.heading_e5.to_le_bytes());
        w.extend_from_slice(&self.s_acc_cm_s.to_le_bytes());
        w.extend_from_slice(&self.c_acc_e5.to_le_bytes());
        w
    }

    pub fn vel_ned_mps(&self) -> [f64; 3] {
        self.vel_ned_cm_s.map(|v| v as f64 * 1e-2)
    }
    pub(crate) fn s_acc_mps(&self) -> f64 {
        self.s_acc_cm_s as f64 * 1e-2
    }
}

/// UBX-NAV-STATUS (0x01 0x03), receiver navigation status, 16 bytes ([M8]
/// UBX-NAV-STATUS).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavStatus {
    pub itow_ms: u32,
    /// Fix type, as NAV-SOL gpsFix.
    pub gps_fix: u8,
    /// gpsFixOk (bit 0), diffSoln (1), wknSet (2), towSet (3).
    pub flags: u8,
    /// dgpsIStat (bit 0), mapMatching (6..7).
    pub fix_stat: u8,
    /// psmState (0..1), spoofDetState (3..4), carrSoln (6..7).
    pub flags2: u8,
    /// Time to first fix and time since startup (ms).
    pub ttff_ms: u32,
    pub msss_ms: u32,
}

impl NavStatus {
    pub const LEN: usize = 16;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-STATUS", p.len(), "16"));
        }
        let r = Rd(p);
        Ok(NavStatus {
            itow_ms: r.u4(0),
            gps_fix: r.u1(4),
            flags: r.u1(5),
            fix_stat: r.u1(6),
            flags2: r.u1(7),
            ttff_ms: r.u4(8),
            msss_ms: r.u4(12),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        w.extend_from_slice(&[self.gps_fix, self.flags, self.fix_stat, self.flags2]);
        w.extend_from_slice(&self.ttff_ms.to_le_bytes());
        w.extend_from_slice(&self.msss_ms.to_le_bytes());
        w
    }

    pub(crate) fn gps_fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }
}

// ------------------------------------------------------------ NAV-TIMEGPS

/// UBX-NAV-TIMEGPS (0x01 0x20), GPS time solution, 16 bytes ([M8]
/// UBX-NAV-TIMEGPS). Precise GPS time of the epoch = week, iTOW + fTOW.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavTimeGps {
    pub itow_ms: u32,
    /// Fraction of iTOW (ns, −500000..500000).
    pub ftow_ns: i32,
    /// GPS week (full, not modulo 1024).
    pub week: i16,
    /// GPS − UTC leap seconds (s).
    pub leap_s: i8,
    /// towValid (bit 0), weekValid (1), leapSValid (2).
    pub valid: u8,
    pub t_acc_ns: u32,
}

impl NavTimeGps {
    pub const LEN: usize = 16;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-TIMEGPS", p.len(), "16"));
        }
        let r = Rd(p);
        Ok(NavTimeGps {
            itow_ms: r.u4(0),
            ftow_ns: r.i4(4),
            week: r.i2(8),
            leap_s: r.i1(10),
            valid: r.u1(11),
            t_acc_ns: r.u4(12),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        w.extend_from_slice(&self.ftow_ns.to_le_bytes());
        w.extend_from_slice(&self.week.to_le_bytes());
        w.push(self.leap_s as u8);
        w.push(self.valid);
        w.extend_from_slice(&self.t_acc_ns.to_le_bytes());
        w
    }

    pub(crate) fn tow_valid(&self) -> bool {
        self.valid & 0x01 != 0
    }
    pub(crate) fn week_valid(&self) -> bool {
        self.valid & 0x02 != 0
    }
    pub(crate) fn leap_valid(&self) -> bool {
        self.valid & 0x04 != 0
    }
    /// GPS time of the epoch (ns since the GPS epoch) when week and TOW are
    /// valid.
    pub fn time_ns(&self) -> Option<i64> {
        (self.tow_valid() && self.week_valid()).then(|| {
            self.week as i64 * navsync::time::NS_PER_WEEK
                + self.itow_ms as i64 * 1_000_000
                + self.ftow_ns as i64
        })
    }
}

// ----------------------------------------------------------------- TIM-TP

/// UBX-TIM-TP (0x0D 0x01), time of the *next* time pulse and its
/// quantization error, 16 bytes ([M8] UBX-TIM-TP; [F9] §5.17.2).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TimTp {
    /// Time pulse time of week in the time base (ms).
    pub tow_ms: u32,
    /// Sub-millisecond part (ms · 2⁻³²).
    pub tow_sub_ms: u32,
    /// Quantization error of the time pulse (ps).
    pub q_err_ps: i32,
    /// Week number in the time base.
    pub week: u16,
    /// timeBase (bit 0: 0 GNSS, 1 UTC), utc (1), raim (2..3),
    /// qErrInvalid (4).
    pub flags: u8,
    /// timeRefGnss (bits 0..3), utcStandard (4..7).
    pub ref_info: u8,
}

impl TimTp {
    pub const LEN: usize = 16;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("TIM-TP", p.len(), "16"));
        }
        let r = Rd(p);
        Ok(TimTp {
            tow_ms: r.u4(0),
            tow_sub_ms: r.u4(4),
            q_err_ps: r.i4(8),
            week: r.u2(12),
            flags: r.u1(14),
            ref_info: r.u1(15),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend_from_slice(&self.tow_ms.to_le_bytes());
        w.extend_from_slice(&self.tow_sub_ms.to_le_bytes());
        w.extend_from_slice(&self.q_err_ps.to_le_bytes());
        w.extend_from_slice(&self.week.to_le_bytes());
        w.push(self.flags);
        w.push(self.ref_info);
        w
    }

    /// True when the pulse time is UTC rather than GNSS time.
    pub fn utc_time_base(&self) -> bool {
        self.flags & 0x01 != 0
    }
    /// qErrInvalid clear (newer firmware sets it when qErr is unusable).
    pub fn q_err_valid(&self) -> bool {
        self.flags & 0x10 == 0
    }
    /// Pulse time in its time base, ns since that scale's week 0 (rounded:
    /// towSubMS has 2⁻³² ms resolution).
    pub(crate) fn pulse_time_ns(&self) -> i64 {
        let sub_ns = ((self.tow_sub_ms as u64 * 1_000_000 + (1 << 31)) >> 32) as i64;
        self.week as i64 * navsync::time::NS_PER_WEEK + self.tow_ms as i64 * 1_000_000 + sub_ns
    }
}

// ---------------------------------------------------------------- TIM-TM2

/// Time base of a TIM-TM2 time mark ([F9] §5.17.1 flags bits 3..4).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum TimeBase {
    Receiver,
    Gnss,
    Utc,
    /// Value 3, not defined by the protocol.
    Reserved,
}

/// UBX-TIM-TM2 (0x0D 0x03), time of the last rising and falling edges on an
/// EXTINT pin, 28 bytes ([M8] UBX-TIM-TM2; [F9] §5.17.1).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TimTm2 {
    /// EXTINT channel.
    pub ch: u8,
    /// mode (bit 0), run (1), newFallingEdge (2), timeBase (3..4), utc (5),
    /// time valid (6), newRisingEdge (7).
    pub flags: u8,
    /// Rising-edge counter.
    pub count: u16,
    pub wn_r: u16,
    pub wn_f: u16,
    pub tow_ms_r: u32,
    /// Millisecond fraction of the rising edge (ns).
    pub tow_sub_ms_r_ns: u32,
    pub tow_ms_f: u32,
    pub tow_sub_ms_f_ns: u32,
    /// Accuracy estimate (ns).
    pub acc_est_ns: u32,
}

impl TimTm2 {
    pub const LEN: usize = 28;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("TIM-TM2", p.len(), "28"));
        }
        let r = Rd(p);
        Ok(TimTm2 {
            ch: r.u1(0),
            flags: r.u1(1),
            count: r.u2(2),
            wn_r: r.u2(4),
            wn_f: r.u2(6),
            tow_ms_r: r.u4(8),
            tow_sub_ms_r_ns: r.u4(12),
            tow_ms_f: r.u4(16),
            tow_sub_ms_f_ns: r.u4(20),
            acc_est_ns: r.u4(24),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.push(self.ch);
        w.push(self.flags);
        w.extend_from_slice(&self.count.to_le_bytes());
        w.extend_from_slice(&self.wn_r.to_le_bytes());
        w.extend_from_slice(&self.wn_f.to_le_bytes());
        for v in [
            self.tow_ms_r,
            self.tow_sub_ms_r_ns,
            self.tow_ms_f,
            self.tow_sub_ms_f_ns,
            self.acc_est_ns,
        ] {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w
    }

    /// The time base, read from flags bits 3..4 (the bits `ublox` 0.10.0
    /// misreads).
    pub fn time_base(&self) -> TimeBase {
        match (self.flags >> 3) & 0x03 {
            0 => TimeBase::Receiver,
            1 => TimeBase::Gnss,
            2 => TimeBase::Utc,
            _ => TimeBase::Reserved,
        }
    }
    pub(crate) fn new_rising_edge(&self) -> bool {
        self.flags & 0x80 != 0
    }
    pub(crate) fn new_falling_edge(&self) -> bool {
        self.flags & 0x04 != 0
    }
    /// Time valid (a valid GNSS fix).
    pub(crate) fn time_valid(&self) -> bool {
        self.flags & 0x40 != 0
    }
    /// Rising edge, ns since week 0 of the time base.
    pub(crate) fn rising_ns(&self) -> i64 {
        edge_ns(self.wn_r, self.tow_ms_r, self.tow_sub_ms_r_ns)
    }
    /// Falling edge, ns since week 0 of the time base.
    pub(crate) fn falling_ns(&self) -> i64 {
        edge_ns(self.wn_f, self.tow_ms_f, self.tow_sub_ms_f_ns)
    }
}

fn edge_ns(week: u16, tow_ms: u32, sub_ns: u32) -> i64 {
    week as i64 * navsync::time::NS_PER_WEEK + tow_ms as i64 * 1_000_000 + sub_ns as i64
}

// --------------------------------------------------------- ESF data words

/// ESF sensor data types and scaling ([F9K] §3.2.6 Table 11; [M8] ESF-MEAS
/// "data types").
pub mod esf_type {
    pub const GYRO_Z: u8 = 5;
    pub const WHEEL_TICK_FL: u8 = 6;
    pub const WHEEL_TICK_FR: u8 = 7;
    pub const WHEEL_TICK_RL: u8 = 8;
    pub const WHEEL_TICK_RR: u8 = 9;
    pub const SPEED_TICK: u8 = 10;
    pub const SPEED: u8 = 11;
    pub const GYRO_TEMP: u8 = 12;
    pub const GYRO_Y: u8 = 13;
    pub const GYRO_X: u8 = 14;
    pub const ACC_X: u8 = 16;
    pub const ACC_Y: u8 = 17;
    pub const ACC_Z: u8 = 18;
    /// A 6-axis IMU sample's types in the usual order: gyro x, y, z, then
    /// accelerometer x, y, z.
    pub const IMU6: [u8; 6] = [GYRO_X, GYRO_Y, GYRO_Z, ACC_X, ACC_Y, ACC_Z];
}

/// The physical quantity of an ESF sample, in SI units.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum EsfValue {
    /// Angular rate about sensor axis 0 = x, 1 = y, 2 = z (rad/s).
    Gyro(usize, f64),
    /// Specific force along sensor axis 0 = x, 1 = y, 2 = z (m/s²).
    Accel(usize, f64),
    /// Gyroscope temperature (°C).
    Temperature(f64),
    /// Speed (m/s).
    Speed(f64),
    /// Wheel or speed ticks (type 6..10): count and backward flag.
    Ticks {
        data_type: u8,
        count: u32,
        backward: bool,
    },
    /// A type navsync does not interpret (the raw 24 bits).
    Other { data_type: u8, raw: u32 },
}

/// Decodes a 24-bit ESF data field of `data_type`: signed types are 24-bit
/// two's complement; tick types are 23-bit counts plus a direction bit
/// ([F9K] Table 11). Gyro deg/s · 2⁻¹², accel m/s² · 2⁻¹⁰, temperature
/// °C · 1e-2, speed m/s · 1e-3.
pub fn esf_value(data_type: u8, field24: u32) -> EsfValue {
    let signed = (((field24 & 0x00FF_FFFF) << 8) as i32 >> 8) as f64;
    let gyro = |s: f64| (s / 4096.0).to_radians();
    match data_type {
        esf_type::GYRO_X => EsfValue::Gyro(0, gyro(signed)),
        esf_type::GYRO_Y => EsfValue::Gyro(1, gyro(signed)),
        esf_type::GYRO_Z => EsfValue::Gyro(2, gyro(signed)),
        esf_type::ACC_X => EsfValue::Accel(0, signed / 1024.0),
        esf_type::ACC_Y => EsfValue::Accel(1, signed / 1024.0),
        esf_type::ACC_Z => EsfValue::Accel(2, signed / 1024.0),
        esf_type::GYRO_TEMP => EsfValue::Temperature(signed * 1e-2),
        esf_type::SPEED => EsfValue::Speed(signed * 1e-3),
        6..=10 => EsfValue::Ticks {
            data_type,
            count: field24 & 0x007F_FFFF,
            backward: field24 & 0x0080_0000 != 0,
        },
        _ => EsfValue::Other {
            data_type,
            raw: field24 & 0x00FF_FFFF,
        },
    }
}

/// One ESF data word: type and 24-bit field.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct EsfData {
    pub data_type: u8,
    /// The 24-bit field as sent (see [`esf_value`]).
    pub field: u32,
}

impl EsfData {
    pub fn value(&self) -> EsfValue {
        esf_value(self.data_type, self.field)
    }
}

// --------------------------------------------------------------- ESF-MEAS

/// UBX-ESF-MEAS (0x10 0x02), external sensor fusion measurements: one time
/// tag for a set of data words ([M8] UBX-ESF-MEAS).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EsfMeas {
    /// Sensor time tag (ms on u-blox IMUs: [F9K]/ZED-F9R integration manual
    /// §3.2.5.2.3, default SEN_TTAG_FACT 1000 µs).
    pub time_tag: u32,
    /// timeMarkSent (bits 0..1), timeMarkEdge (2), calibTtagValid (3),
    /// numMeas (11..15); other bits kept as sent.
    pub flags: u16,
    /// Data provider id.
    pub id: u16,
    /// Data words; the 6-bit type is bits 24..29 of each word.
    pub data: Vec<EsfData>,
    /// The two bits above the type (30..31), kept for exact re-encoding.
    pub(crate) data_high_bits: Vec<u8>,
    /// Receiver local time calibrated (ms), when calibTtagValid.
    pub calib_ttag: Option<u32>,
}

impl EsfMeas {
    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() < 8 {
            return Err(bad_len("ESF-MEAS", p.len(), "at least 8"));
        }
        let r = Rd(p);
        let flags = r.u2(4);
        let n = (flags >> 11) as usize;
        let calib = flags & 0x08 != 0;
        let expected = 8 + 4 * n + if calib { 4 } else { 0 };
        if p.len() != expected {
            return Err(bad_len(
                "ESF-MEAS",
                p.len(),
                &format!("{expected} (numMeas {n}, calibTtagValid {calib})"),
            ));
        }
        let mut data = Vec::with_capacity(n);
        let mut high = Vec::with_capacity(n);
        for k in 0..n {
            let w = r.u4(8 + 4 * k);
            data.push(EsfData {
                data_type: ((w >> 24) & 0x3F) as u8,
                field: w & 0x00FF_FFFF,
            });
            high.push((w >> 30) as u8);
        }
        Ok(EsfMeas {
            time_tag: r.u4(0),
            flags,
            id: r.u2(6),
            data,
            data_high_bits: high,
            calib_ttag: calib.then(|| r.u4(8 + 4 * n)),
        })
    }

    /// The payload. `flags` is sent as stored; numMeas and calibTtagValid
    /// must agree with `data` and `calib_ttag` (use [`EsfMeas::new`]).
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(12 + 4 * self.data.len());
        w.extend_from_slice(&self.time_tag.to_le_bytes());
        w.extend_from_slice(&self.flags.to_le_bytes());
        w.extend_from_slice(&self.id.to_le_bytes());
        for (k, d) in self.data.iter().enumerate() {
            let high = self.data_high_bits.get(k).copied().unwrap_or(0) as u32;
            let word = (high << 30) | ((d.data_type as u32 & 0x3F) << 24) | (d.field & 0x00FF_FFFF);
            w.extend_from_slice(&word.to_le_bytes());
        }
        if let Some(c) = self.calib_ttag {
            w.extend_from_slice(&c.to_le_bytes());
        }
        w
    }

    /// A consistent message (flags built from `data` and `calib_ttag`; at
    /// most 31 data words, the width of numMeas).
    pub fn new(time_tag: u32, id: u16, data: Vec<EsfData>, calib_ttag: Option<u32>) -> Self {
        let mut data = data;
        data.truncate(31);
        let flags = ((data.len() as u16) << 11) | if calib_ttag.is_some() { 0x08 } else { 0 };
        let n = data.len();
        EsfMeas {
            time_tag,
            flags,
            id,
            data,
            data_high_bits: vec![0; n],
            calib_ttag,
        }
    }
}

// ---------------------------------------------------------------- ESF-RAW

/// One ESF-RAW block: a data word and its own sensor time tag.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct EsfRawBlock {
    /// The full 8-bit type (bits 24..31).
    pub data_type: u8,
    /// The raw 24-bit field (sign-extend with [`esf_value`]).
    pub field: u32,
    /// Sensor time tag of this sample (sensor ticks).
    pub s_ttag: u32,
}

impl EsfRawBlock {
    pub fn value(&self) -> EsfValue {
        esf_value(self.data_type, self.field)
    }
}

/// UBX-ESF-RAW (0x10 0x03), raw sensor measurements ([M8] UBX-ESF-RAW:
/// 4 reserved bytes, then blocks of data X4 + sTtag U4).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EsfRaw {
    pub reserved1: [u8; 4],
    pub blocks: Vec<EsfRawBlock>,
}

impl EsfRaw {
    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() < 4 || !(p.len() - 4).is_multiple_of(8) {
            return Err(bad_len("ESF-RAW", p.len(), "4 + 8·N"));
        }
        let r = Rd(p);
        let n = (p.len() - 4) / 8;
        let blocks = (0..n)
            .map(|k| {
                let w = r.u4(4 + 8 * k);
                EsfRawBlock {
                    data_type: (w >> 24) as u8,
                    field: w & 0x00FF_FFFF,
                    s_ttag: r.u4(8 + 8 * k),
                }
            })
            .collect();
        Ok(EsfRaw {
            reserved1: r.arr(0),
            blocks,
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(4 + 8 * self.blocks.len());
        w.extend_from_slice(&self.reserved1);
        for b in &self.blocks {
            let word = ((b.data_type as u32) << 24) | (b.field & 0x00FF_FFFF);
            w.extend_from_slice(&word.to_le_bytes());
            w.extend_from_slice(&b.s_ttag.to_le_bytes());
        }
        w
    }
}

// ---------------------------------------------------------- NAV-RELPOSNED

/// UBX-NAV-RELPOSNED (0x01 0x3C), version 0x01, 64-byte payload ([F9]
/// UBX-NAV-RELPOSNED): the rover antenna's position relative to the base
/// (in a moving-base setup, the second antenna of the vehicle relative to
/// the first), with the heading of that baseline. The u-blox 8 (M8P)
/// version 0x00 is 40 bytes and has no heading: it is not read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavRelPosNed {
    /// Message version (0x01).
    pub version: u8,
    pub reserved0: u8,
    pub ref_station_id: u16,
    pub itow_ms: u32,
    /// Base→rover vector N, E, D and its length (cm).
    pub rel_pos_ned_cm: [i32; 3],
    pub rel_pos_length_cm: i32,
    /// Heading of the base→rover vector, clockwise from north (1e-5 deg).
    pub rel_pos_heading_e5: i32,
    pub reserved1: [u8; 4],
    /// High-precision parts of N, E, D and length (0.1 mm, −99..99).
    pub rel_pos_hp_ned: [i8; 3],
    pub rel_pos_hp_length: i8,
    /// Accuracy of N, E, D and length (0.1 mm).
    pub acc_ned: [u32; 3],
    pub acc_length: u32,
    /// Accuracy of the heading (1e-5 deg).
    pub acc_heading_e5: u32,
    pub reserved2: [u8; 4],
    /// gnssFixOK (bit 0), diffSoln (1), relPosValid (2), carrSoln (3..4:
    /// 0 none, 1 float, 2 fixed), isMoving (5), refPosMiss (6), refObsMiss
    /// (7), relPosHeadingValid (8), relPosNormalized (9).
    pub flags: u32,
}

impl NavRelPosNed {
    pub const LEN: usize = 64;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len(
                "NAV-RELPOSNED",
                p.len(),
                "64 (version 1, u-blox 9; the 40-byte version 0 has no heading)",
            ));
        }
        let r = Rd(p);
        Ok(NavRelPosNed {
            version: r.u1(0),
            reserved0: r.u1(1),
            ref_station_id: r.u2(2),
            itow_ms: r.u4(4),
            rel_pos_ned_cm: [r.i4(8), r.i4(12), r.i4(16)],
            rel_pos_length_cm: r.i4(20),
            rel_pos_heading_e5: r.i4(24),
            reserved1: r.arr(28),
            rel_pos_hp_ned: [r.i1(32), r.i1(33), r.i1(34)],
            rel_pos_hp_length: r.i1(35),
            acc_ned: [r.u4(36), r.u4(40), r.u4(44)],
            acc_length: r.u4(48),
            acc_heading_e5: r.u4(52),
            reserved2: r.arr(56),
            flags: r.u4(60),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.push(self.version);
        w.push(self.reserved0);
        w.extend_from_slice(&self.ref_station_id.to_le_bytes());
        w.extend_from_slice(&self.itow_ms.to_le_bytes());
        for v in self.rel_pos_ned_cm {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.rel_pos_length_cm.to_le_bytes());
        w.extend_from_slice(&self.rel_pos_heading_e5.to_le_bytes());
        w.extend_from_slice(&self.reserved1);
        for v in self.rel_pos_hp_ned {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.rel_pos_hp_length.to_le_bytes());
        for v in self.acc_ned {
            w.extend_from_slice(&v.to_le_bytes());
        }
        w.extend_from_slice(&self.acc_length.to_le_bytes());
        w.extend_from_slice(&self.acc_heading_e5.to_le_bytes());
        w.extend_from_slice(&self.reserved2);
        w.extend_from_slice(&self.flags.to_le_bytes());
        w
    }

    pub fn gnss_fix_ok(&self) -> bool {
        self.flags & 0x001 != 0
    }
    pub fn rel_pos_valid(&self) -> bool {
        self.flags & 0x004 != 0
    }
    /// carrSoln: 0 no carrier-phase solution, 1 float, 2 fixed.
    pub fn carr_soln(&self) -> u8 {
        ((self.flags >> 3) & 0x3) as u8
    }
    pub fn rel_pos_heading_valid(&self) -> bool {
        self.flags & 0x100 != 0
    }
    /// Heading of the base→rover baseline (deg, clockwise from north).
    pub fn heading_deg(&self) -> f64 {
        self.rel_pos_heading_e5 as f64 * 1e-5
    }
    pub fn acc_heading_deg(&self) -> f64 {
        self.acc_heading_e5 as f64 * 1e-5
    }
    /// Baseline length (m), high-precision part included.
    pub fn length_m(&self) -> f64 {
        self.rel_pos_length_cm as f64 * 1e-2 + self.rel_pos_hp_length as f64 * 1e-4
    }
}

// ---------------------------------------------------------------- dispatch

/// A decoded UBX message of a type navsync reads.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum UbxMessage {
    NavPvt(NavPvt),
    NavSol(NavSol),
    NavPosLlh(NavPosLlh),
    NavHpPosLlh(NavHpPosLlh),
    NavVelNed(NavVelNed),
    NavRelPosNed(NavRelPosNed),
    NavStatus(NavStatus),
    NavTimeGps(NavTimeGps),
    TimTp(TimTp),
    TimTm2(TimTm2),
    EsfMeas(EsfMeas),
    EsfRaw(EsfRaw),
    /// Dead-reckoning receivers ([`crate::ubx_dr`]).
    NavPvat(NavPvat),
    NavAtt(NavAtt),
}

impl UbxMessage {
    /// Decodes a payload of a known message; `Ok(None)` for a type navsync
    /// does not read (an intact frame of another type).
    pub fn decode(id: MsgId, payload: &[u8]) -> Result<Option<UbxMessage>, PayloadError> {
        Ok(Some(match id {
            MsgId::NAV_PVT => UbxMessage::NavPvt(NavPvt::decode(payload)?),
            MsgId::NAV_SOL => UbxMessage::NavSol(NavSol::decode(payload)?),
            MsgId::NAV_POSLLH => UbxMessage::NavPosLlh(NavPosLlh::decode(payload)?),
            MsgId::NAV_HPPOSLLH => UbxMessage::NavHpPosLlh(NavHpPosLlh::decode(payload)?),
            MsgId::NAV_VELNED => UbxMessage::NavVelNed(NavVelNed::decode(payload)?),
            MsgId::NAV_RELPOSNED => UbxMessage::NavRelPosNed(NavRelPosNed::decode(payload)?),
            MsgId::NAV_STATUS => UbxMessage::NavStatus(NavStatus::decode(payload)?),
            MsgId::NAV_TIMEGPS => UbxMessage::NavTimeGps(NavTimeGps::decode(payload)?),
            MsgId::TIM_TP => UbxMessage::TimTp(TimTp::decode(payload)?),
            MsgId::TIM_TM2 => UbxMessage::TimTm2(TimTm2::decode(payload)?),
            MsgId::ESF_MEAS => UbxMessage::EsfMeas(EsfMeas::decode(payload)?),
            MsgId::ESF_RAW => UbxMessage::EsfRaw(EsfRaw::decode(payload)?),
            MsgId::NAV_PVAT => UbxMessage::NavPvat(NavPvat::decode(payload)?),
            MsgId::NAV_ATT => UbxMessage::NavAtt(NavAtt::decode(payload)?),
            _ => return Ok(None),
        }))
    }

    pub fn id(&self) -> MsgId {
        match self {
            UbxMessage::NavPvt(_) => MsgId::NAV_PVT,
            UbxMessage::NavSol(_) => MsgId::NAV_SOL,
            UbxMessage::NavPosLlh(_) => MsgId::NAV_POSLLH,
            UbxMessage::NavHpPosLlh(_) => MsgId::NAV_HPPOSLLH,
            UbxMessage::NavVelNed(_) => MsgId::NAV_VELNED,
            UbxMessage::NavRelPosNed(_) => MsgId::NAV_RELPOSNED,
            UbxMessage::NavStatus(_) => MsgId::NAV_STATUS,
            UbxMessage::NavTimeGps(_) => MsgId::NAV_TIMEGPS,
            UbxMessage::TimTp(_) => MsgId::TIM_TP,
            UbxMessage::TimTm2(_) => MsgId::TIM_TM2,
            UbxMessage::EsfMeas(_) => MsgId::ESF_MEAS,
            UbxMessage::EsfRaw(_) => MsgId::ESF_RAW,
            UbxMessage::NavPvat(_) => MsgId::NAV_PVAT,
            UbxMessage::NavAtt(_) => MsgId::NAV_ATT,
        }
    }

    pub fn payload(&self) -> Vec<u8> {
        match self {
            UbxMessage::NavPvt(m) => m.encode(),
            UbxMessage::NavSol(m) => m.encode(),
            UbxMessage::NavPosLlh(m) => m.encode(),
            UbxMessage::NavHpPosLlh(m) => m.encode(),
            UbxMessage::NavVelNed(m) => m.encode(),
            UbxMessage::NavRelPosNed(m) => m.encode(),
            UbxMessage::NavStatus(m) => m.encode(),
            UbxMessage::NavTimeGps(m) => m.encode(),
            UbxMessage::TimTp(m) => m.encode(),
            UbxMessage::TimTm2(m) => m.encode(),
            UbxMessage::EsfMeas(m) => m.encode(),
            UbxMessage::EsfRaw(m) => m.encode(),
            UbxMessage::NavPvat(m) => m.encode(),
            UbxMessage::NavAtt(m) => m.encode(),
        }
    }

    /// The whole frame, checksum included.
    pub fn to_frame(&self) -> Result<Vec<u8>, PayloadError> {
        let id = self.id();
        encode_frame(id.class, id.id, &self.payload())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_of_a_known_poll_frame() {
        // [M8] §32.4 example family: the MON-VER poll is B5 62 0A 04 00 00 0E 34.
        assert_eq!(
            encode_frame(0x0A, 0x04, &[]).unwrap(),
            [0xB5, 0x62, 0x0A, 0x04, 0, 0, 0x0E, 0x34]
        );
    }

    #[test]
    fn esf_values_are_twos_complement() {
        // -4 · 2^-10 m/s² as the NEO-M8L sends it
        assert_eq!(
            esf_value(esf_type::ACC_Y, 0xFF_FFFC),
            EsfValue::Accel(1, -4.0 / 1024.0)
        );
        // +1 deg/s on z
        match esf_value(esf_type::GYRO_Z, 4096) {
            EsfValue::Gyro(2, w) => assert!((w - 1f64.to_radians()).abs() < 1e-15),
            v => panic!("{v:?}"),
        }
        assert_eq!(
            esf_value(esf_type::WHEEL_TICK_RL, 0x80_0005),
            EsfValue::Ticks {
                data_type: 8,
                count: 5,
                backward: true
            }
        );
    }

    #[test]
    fn wrong_lengths_are_errors_not_panics() {
        for n in 0..120 {
            let p = vec![0xFFu8; n];
            for id in [
                MsgId::NAV_PVT,
                MsgId::NAV_SOL,
                MsgId::NAV_POSLLH,
                MsgId::NAV_HPPOSLLH,
                MsgId::NAV_VELNED,
                MsgId::NAV_RELPOSNED,
                MsgId::NAV_STATUS,
                MsgId::NAV_TIMEGPS,
                MsgId::TIM_TP,
                MsgId::TIM_TM2,
                MsgId::ESF_MEAS,
                MsgId::ESF_RAW,
            ] {
                let _ = UbxMessage::decode(id, &p);
            }
        }
        assert!(NavPvt::decode(&[0; 84]).is_err());
        assert!(EsfRaw::decode(&[0; 13]).is_err());
        assert!(EsfRaw::decode(&[0; 12]).is_ok());
        assert!(NavRelPosNed::decode(&[0; 40]).is_err());
    }

    /// NAV-RELPOSNED write → frame → parse gives the message back, and the
    /// accessors scale as [F9] UBX-NAV-RELPOSNED says (1e-5 deg, cm + 0.1 mm).
    #[test]
    fn nav_relposned_round_trip() {
        let m = NavRelPosNed {
            version: 1,
            reserved0: 0,
            ref_station_id: 7,
            itow_ms: 345_678_900,
            rel_pos_ned_cm: [-52, 85, -3],
            rel_pos_length_cm: 99,
            rel_pos_heading_e5: 12_150_000,
            reserved1: [0; 4],
            rel_pos_hp_ned: [-12, 34, 5],
            rel_pos_hp_length: -42,
            acc_ned: [40, 40, 80],
            acc_length: 50,
            acc_heading_e5: 20_000,
            reserved2: [0; 4],
            flags: 0x001 | 0x004 | (2 << 3) | 0x020 | 0x100,
        };
        let frame = UbxMessage::NavRelPosNed(m.clone()).to_frame().unwrap();
        assert_eq!(frame.len(), NavRelPosNed::LEN + FRAME_OVERHEAD);
        assert_eq!((frame[2], frame[3]), (0x01, 0x3C));
        let back = UbxMessage::decode(MsgId::NAV_RELPOSNED, &frame[6..frame.len() - 2])
            .unwrap()
            .unwrap();
        assert_eq!(back, UbxMessage::NavRelPosNed(m.clone()));
        assert!((m.heading_deg() - 121.5).abs() < 1e-12);
        assert!((m.acc_heading_deg() - 0.2).abs() < 1e-12);
        assert!((m.length_m() - (0.99 - 0.0042)).abs() < 1e-12);
        assert!(m.gnss_fix_ok() && m.rel_pos_valid() && m.rel_pos_heading_valid());
        assert_eq!(m.carr_soln(), 2);
        assert_eq!(MsgId::NAV_RELPOSNED.name(), Some("NAV-RELPOSNED"));
    }

    #[test]
    fn tim_tm2_time_base_bits() {
        let mut m = TimTm2::decode(&[0; 28]).unwrap();
        for (bits, tb) in [
            (0u8, TimeBase::Receiver),
            (1, TimeBase::Gnss),
            (2, TimeBase::Utc),
            (3, TimeBase::Reserved),
        ] {
            m.flags = bits << 3 | 0x80;
            assert_eq!(m.time_base(), tb);
            assert!(m.new_rising_edge() && !m.new_falling_edge());
        }
    }
}
