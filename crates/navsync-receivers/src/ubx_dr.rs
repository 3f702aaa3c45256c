//! The messages of u-blox dead-reckoning (sensor-fusion) receivers that
//! navsync reads: UBX-NAV-PVAT (0x01 0x17: position, velocity, attitude
//! and time of the fused solution, 116 bytes) and UBX-NAV-ATT (0x01 0x05:
//! vehicle attitude, 32 bytes). Layouts from the u-blox interface
//! descriptions: [HPS] ZED-F9R Interface Description (HPS 1.21,
//! UBX-21035062), UBX-NAV-PVAT and UBX-NAV-ATT; [ADR] the u-blox M8 ADR /
//! NEO-M8L protocol description gives the same NAV-ATT.
//!
//! NAV-PVAT is the receiver's FUSED solution: GNSS and its own IMU (and
//! wheel ticks) through its filter; fixType 4 = GNSS + dead reckoning, 1 =
//! dead reckoning only ([HPS] UBX-NAV-PVAT fixType). Its errors are
//! correlated in time (a filter's output), see `fixes::fused_sd_factor`.

use super::ubx::{NavPvt, PayloadError, Rd, bad_len};

/// UBX-NAV-PVAT ([HPS] UBX-NAV-PVAT, version 0x00).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavPvat {
    pub itow_ms: u32,
    pub version: u8,
    /// validDate (bit 0), validTime (1), fullyResolved (2), validMag (3).
    pub valid: u8,
    pub year: u16,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub min: u8,
    pub sec: u8,
    pub reserved0: [u8; 3],
    pub t_acc_ns: u32,
    pub nano_ns: i32,
    /// 0 no fix, 1 DR only, 2 2D, 3 3D, 4 GNSS + DR, 5 time only.
    pub fix_type: u8,
    /// gnssFixOK (bit 0), diffSoln (1), vehRollValid (3), vehPitchValid
    /// (4), vehHeadingValid (5), carrSoln (6..7).
    pub flags: u8,
    pub flags2: u8,
    pub num_sv: u8,
    pub lon_e7: i32,
    pub lat_e7: i32,
    pub height_mm: i32,
    pub h_msl_mm: i32,
    pub h_acc_mm: u32,
    pub v_acc_mm: u32,
    pub vel_ned_mm_s: [i32; 3],
    pub g_speed_mm_s: i32,
    pub s_acc_mm_s: u32,
    /// Vehicle roll, pitch, heading and heading of motion (1e-5 deg).
    pub veh_roll_e5: i32,
    pub veh_pitch_e5: i32,
    pub veh_heading_e5: i32,
    pub mot_heading_e5: i32,
    /// Accuracies of roll, pitch, heading (1e-2 deg).
    pub acc_roll_e2: u16,
    pub acc_pitch_e2: u16,
    pub acc_heading_e2: u16,
    pub mag_dec_e2: i16,
    pub mag_acc_e2: u16,
    pub err_ellipse_orient_e2: u16,
    pub err_ellipse_major_mm: u32,
    pub err_ellipse_minor_mm: u32,
    pub reserved2: [u8; 8],
}

impl NavPvat {
    pub const LEN: usize = 116;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-PVAT", p.len(), "116 (version 0)"));
        }
        let r = Rd(p);
        Ok(NavPvat {
            itow_ms: r.u4(0),
            version: r.u1(4),
            valid: r.u1(5),
            year: r.u2(6),
            month: r.u1(8),
            day: r.u1(9),
            hour: r.u1(10),
            min: r.u1(11),
            sec: r.u1(12),
            reserved0: r.arr(13),
            t_acc_ns: r.u4(16),
            nano_ns: r.i4(20),
            fix_type: r.u1(24),
            flags: r.u1(25),
            flags2: r.u1(26),
            num_sv: r.u1(27),
            lon_e7: r.i4(28),
            lat_e7: r.i4(32),
            height_mm: r.i4(36),
            h_msl_mm: r.i4(40),
            h_acc_mm: r.u4(44),
            v_acc_mm: r.u4(48),
            vel_ned_mm_s: [r.i4(52), r.i4(56), r.i4(60)],
            g_speed_mm_s: r.i4(64),
            s_acc_mm_s: r.u4(68),
            veh_roll_e5: r.i4(72),
            veh_pitch_e5: r.i4(76),
            veh_heading_e5: r.i4(80),
            mot_heading_e5: r.i4(84),
            acc_roll_e2: r.u2(88),
            acc_pitch_e2: r.u2(90),
            acc_heading_e2: r.u2(92),
            mag_dec_e2: r.i2(94),
            mag_acc_e2: r.u2(96),
            err_ellipse_orient_e2: r.u2(98),
            err_ellipse_major_mm: r.u4(100),
            err_ellipse_minor_mm: r.u4(104),
            reserved2: r.arr(108),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend(self.itow_ms.to_le_bytes());
        w.extend([self.version, self.valid]);
        w.extend(self.year.to_le_bytes());
        w.extend([self.month, self.day, self.hour, self.min, self.sec]);
        w.extend(self.reserved0);
        w.extend(self.t_acc_ns.to_le_bytes());
        w.extend(self.nano_ns.to_le_bytes());
        w.extend([self.fix_type, self.flags, self.flags2, self.num_sv]);
        for v in [self.lon_e7, self.lat_e7, self.height_mm, self.h_msl_mm] {
            w.extend(v.to_le_bytes());
        }
        w.extend(self.h_acc_mm.to_le_bytes());
        w.extend(self.v_acc_mm.to_le_bytes());
        for v in self.vel_ned_mm_s {
            w.extend(v.to_le_bytes());
        }
        w.extend(self.g_speed_mm_s.to_le_bytes());
        w.extend(self.s_acc_mm_s.to_le_bytes());
        for v in [
            self.veh_roll_e5,
            self.veh_pitch_e5,
            self.veh_heading_e5,
            self.mot_heading_e5,
        ] {
            w.extend(v.to_le_bytes());
        }
        for v in [self.acc_roll_e2, self.acc_pitch_e2, self.acc_heading_e2] {
            w.extend(v.to_le_bytes());
        }
        w.extend(self.mag_dec_e2.to_le_bytes());
        w.extend(self.mag_acc_e2.to_le_bytes());
        w.extend(self.err_ellipse_orient_e2.to_le_bytes());
        w.extend(self.err_ellipse_major_mm.to_le_bytes());
        w.extend(self.err_ellipse_minor_mm.to_le_bytes());
        w.extend(self.reserved2);
        w
    }

    /// vehHeadingValid.
    pub fn veh_heading_valid(&self) -> bool {
        self.flags & 0x20 != 0
    }

    pub fn veh_heading_deg(&self) -> f64 {
        self.veh_heading_e5 as f64 * 1e-5
    }

    pub fn acc_heading_deg(&self) -> f64 {
        self.acc_heading_e2 as f64 * 1e-2
    }

    /// The same solution in NAV-PVT's form, so that one set of rules
    /// (fix type, gnssFixOK, UTC → GPS time, σ) makes fixes of both: the
    /// time, fix and position fields have the same meaning in [HPS]
    /// UBX-NAV-PVT and UBX-NAV-PVAT; flags bit 5 is headVehValid in one
    /// and vehHeadingValid in the other.
    pub fn as_nav_pvt(&self) -> NavPvt {
        NavPvt {
            itow_ms: self.itow_ms,
            year: self.year,
            month: self.month,
            day: self.day,
            hour: self.hour,
            min: self.min,
            sec: self.sec,
            valid: self.valid,
            t_acc_ns: self.t_acc_ns,
            nano_ns: self.nano_ns,
            fix_type: self.fix_type,
            flags: self.flags & 0xE3,
            flags2: self.flags2,
            num_sv: self.num_sv,
            lon_e7: self.lon_e7,
            lat_e7: self.lat_e7,
            height_mm: self.height_mm,
            h_msl_mm: self.h_msl_mm,
            h_acc_mm: self.h_acc_mm,
            v_acc_mm: self.v_acc_mm,
            vel_ned_mm_s: self.vel_ned_mm_s,
            g_speed_mm_s: self.g_speed_mm_s,
            head_mot_e5: self.mot_heading_e5,
            s_acc_mm_s: self.s_acc_mm_s,
            head_acc_e5: self.acc_heading_e2 as u32 * 1000,
            p_dop_e2: 0,
            flags3: 0,
            reserved1: [0; 5],
            head_veh_e5: self.veh_heading_e5,
            mag_dec_e2: self.mag_dec_e2,
            mag_acc_e2: self.mag_acc_e2,
        }
    }
}

/// UBX-NAV-ATT ([HPS] UBX-NAV-ATT; [ADR]): the vehicle's attitude.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NavAtt {
    pub itow_ms: u32,
    pub version: u8,
    pub reserved0: [u8; 3],
    /// Roll, pitch, heading (1e-5 deg).
    pub roll_e5: i32,
    pub pitch_e5: i32,
    pub heading_e5: i32,
    /// Their accuracies (1e-5 deg).
    pub acc_roll_e5: u32,
    pub acc_pitch_e5: u32,
    pub acc_heading_e5: u32,
}

impl NavAtt {
    pub const LEN: usize = 32;

    pub fn decode(p: &[u8]) -> Result<Self, PayloadError> {
        if p.len() != Self::LEN {
            return Err(bad_len("NAV-ATT", p.len(), "32 (version 0)"));
        }
        let r = Rd(p);
        Ok(NavAtt {
            itow_ms: r.u4(0),
            version: r.u1(4),
            reserved0: r.arr(5),
            roll_e5: r.i4(8),
            pitch_e5: r.i4(12),
            heading_e5: r.i4(16),
            acc_roll_e5: r.u4(20),
            acc_pitch_e5: r.u4(24),
            acc_heading_e5: r.u4(28),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Vec::with_capacity(Self::LEN);
        w.extend(self.itow_ms.to_le_bytes());
        w.push(self.version);
        w.extend(self.reserved0);
        for v in [self.roll_e5, self.pitch_e5, self.heading_e5] {
            w.extend(v.to_le_bytes());
        }
        for v in [self.acc_roll_e5, self.acc_pitch_e5, self.acc_heading_e5] {
            w.extend(v.to_le_bytes());
        }
        w
    }

    pub fn heading_deg(&self) -> f64 {
        self.heading_e5 as f64 * 1e-5
    }

    pub fn acc_heading_deg(&self) -> f64 {
        self.acc_heading_e5 as f64 * 1e-5
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ubx::{UbxMessage, encode_frame};

    fn pvat() -> NavPvat {
        NavPvat {
            itow_ms: 120_000,
            version: 0,
            valid: 0x07,
            year: 2026,
            month: 4,
            day: 20,
            hour: 9,
            min: 59,
            sec: 42,
            reserved0: [0; 3],
            t_acc_ns: 20,
            nano_ns: -1500,
            fix_type: 4,
            flags: 0x21 | 0x18,
            flags2: 0xE0,
            num_sv: 17,
            lon_e7: -5_712_345,
            lat_e7: 512_612_345,
            height_mm: 95_123,
            h_msl_mm: 49_876,
            h_acc_mm: 1234,
            v_acc_mm: 2345,
            vel_ned_mm_s: [4100, -250, 12],
            g_speed_mm_s: 4108,
            s_acc_mm_s: 150,
            veh_roll_e5: -123_456,
            veh_pitch_e5: 234_567,
            veh_heading_e5: 35_612_345,
            mot_heading_e5: 35_600_000,
            acc_roll_e2: 45,
            acc_pitch_e2: 46,
            acc_heading_e2: 123,
            mag_dec_e2: 0,
            mag_acc_e2: 0,
            err_ellipse_orient_e2: 9000,
            err_ellipse_major_mm: 1500,
            err_ellipse_minor_mm: 900,
            reserved2: [0; 8],
        }
    }

    #[test]
    fn nav_pvat_frame_decodes_field_by_field() {
        let p = pvat();
        let payload = p.encode();
        assert_eq!(payload.len(), NavPvat::LEN);
        // Offsets of [HPS] UBX-NAV-PVAT checked on the bytes themselves.
        assert_eq!(payload[24], 4);
        assert_eq!(&payload[32..36], &512_612_345i32.to_le_bytes());
        assert_eq!(&payload[80..84], &35_612_345i32.to_le_bytes());
        assert_eq!(&payload[92..94], &123u16.to_le_bytes());
        let frame = encode_frame(0x01, 0x17, &payload).unwrap();
        // Fletcher checksum over class, id, length, payload ([F9] §3.4).
        let (mut a, mut b) = (0u8, 0u8);
        for x in &frame[2..frame.len() - 2] {
            a = a.wrapping_add(*x);
            b = b.wrapping_add(a);
        }
        assert_eq!(frame[frame.len() - 2..], [a, b]);
        let back = UbxMessage::decode(crate::ubx::MsgId::NAV_PVAT, &payload)
            .unwrap()
            .unwrap();
        assert_eq!(back, UbxMessage::NavPvat(p.clone()));
        assert!(p.veh_heading_valid());
        assert!((p.veh_heading_deg() - 356.12345).abs() < 1e-9);
        assert!((p.acc_heading_deg() - 1.23).abs() < 1e-12);
        let n = p.as_nav_pvt();
        assert_eq!((n.lat_e7, n.h_acc_mm, n.fix_type), (512_612_345, 1234, 4));
        assert!(n.head_veh_valid() && n.gnss_fix_ok());
        assert!(NavPvat::decode(&payload[..115]).is_err());
    }

    #[test]
    fn nav_att_frame_decodes() {
        let a = NavAtt {
            itow_ms: 120_000,
            version: 0,
            reserved0: [0; 3],
            roll_e5: -150_000,
            pitch_e5: 75_000,
            heading_e5: 18_000_001,
            acc_roll_e5: 40_000,
            acc_pitch_e5: 41_000,
            acc_heading_e5: 120_000,
        };
        let payload = a.encode();
        assert_eq!(payload.len(), NavAtt::LEN);
        assert_eq!(&payload[16..20], &18_000_001i32.to_le_bytes());
        let frame = encode_frame(0x01, 0x05, &payload).unwrap();
        let mut r = crate::stream::StreamReader::new();
        r.push(&frame);
        r.finish();
        let ev = r.next_event().unwrap();
        assert!(
            matches!(&ev.kind, crate::stream::EventKind::Ubx(UbxMessage::NavAtt(m)) if *m == a),
            "{ev:?}"
        );
        assert!((a.heading_deg() - 180.00001).abs() < 1e-9);
        assert!((a.acc_heading_deg() - 1.2).abs() < 1e-12);
        assert!(NavAtt::decode(&payload[..31]).is_err());
    }
}
