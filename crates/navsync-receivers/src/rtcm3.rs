//! RTCM 3 transport-layer framing, enough to recognise and skip the
//! correction frames a u-blox F9 port carries beside UBX and NMEA.
//!
//! RTCM Standard 10403.x (Differential GNSS Services – Version 3), §4
//! "Transport layer": preamble `0xD3`, 6 reserved bits (zero), a 10-bit
//! message length (0..1023 bytes), the message, then a 24-bit CRC-24Q
//! (polynomial 0x1864CFB, initial value 0, no final XOR) over preamble,
//! reserved bits, length and message. The first 12 bits of a message are
//! its number (DF002), e.g. 1005 (station position) or 1077 (GPS MSM7).

/// Transport-layer preamble.
pub(crate) const PREAMBLE: u8 = 0xD3;
/// Bytes around the message: preamble, 2 bytes reserved + length, 3 CRC.
pub(crate) const FRAME_OVERHEAD: usize = 6;
/// Largest message (10-bit length field).
pub(crate) const MAX_MESSAGE_LEN: usize = 1023;

/// CRC-24Q (Qualcomm) as RTCM 10403.x §4 defines it, bitwise: polynomial
/// x²⁴ + x²³ + x¹⁸ + x¹⁷ + x¹⁴ + x¹¹ + x¹⁰ + x⁷ + x⁶ + x⁵ + x⁴ + x³ + x + 1.
pub(crate) fn crc24q(bytes: &[u8]) -> u32 {
    const POLY: u32 = 0x186_4CFB;
    let mut crc = 0u32;
    for &b in bytes {
        crc ^= (b as u32) << 16;
        for _ in 0..8 {
            crc <<= 1;
            if crc & 0x100_0000 != 0 {
                crc ^= POLY;
            }
        }
    }
    crc & 0xFF_FFFF
}

/// The message number (DF002, first 12 bits) of a message, `None` when it
/// is shorter than 2 bytes.
pub(crate) fn message_number(message: &[u8]) -> Option<u16> {
    match message {
        [a, b, ..] => Some(((*a as u16) << 4) | ((*b as u16) >> 4)),
        _ => None,
    }
}

/// A whole frame around `message` (tests and simulators). Errors when the
/// message exceeds the 10-bit length.
pub fn encode_frame(message: &[u8]) -> Result<Vec<u8>, String> {
    if message.len() > MAX_MESSAGE_LEN {
        return Err(format!(
            "RTCM3 message of {} bytes exceeds the {MAX_MESSAGE_LEN}-byte limit",
            message.len()
        ));
    }
    let n = message.len();
    let mut out = Vec::with_capacity(n + FRAME_OVERHEAD);
    out.extend_from_slice(&[PREAMBLE, (n >> 8) as u8, n as u8]);
    out.extend_from_slice(message);
    let crc = crc24q(&out);
    out.extend_from_slice(&crc.to_be_bytes()[1..]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc24q_matches_the_published_table() {
        // The first entries of the CRC-24Q byte table (RTKLIB rtkcmn.c
        // tbl_CRC24Q, gpsd crc24q.c): CRC of the single byte k.
        assert_eq!(crc24q(&[0x01]), 0x86_4CFB);
        assert_eq!(crc24q(&[0x02]), 0x8A_D50D);
        assert_eq!(crc24q(&[0x03]), 0x0C_99F6);
        assert_eq!(crc24q(&[0x04]), 0x93_E6E1);
    }

    #[test]
    fn a_frame_checks_to_zero_and_names_its_message() {
        // Message 1005 starts 0x3E 0xD…: 0x3ED = 1005.
        let f = encode_frame(&[0x3E, 0xD0, 0x00, 0x03]).unwrap();
        assert_eq!(f[..3], [0xD3, 0x00, 0x04]);
        // A CRC without final XOR over data + CRC is zero.
        assert_eq!(crc24q(&f), 0);
        assert_eq!(message_number(&f[3..7]), Some(1005));
        assert_eq!(message_number(&[0x3E]), None);
        assert!(encode_frame(&[0; 1024]).is_err());
    }
}
