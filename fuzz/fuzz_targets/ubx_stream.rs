//! Fuzzes the mixed-stream reader with UBX-heavy input: raw bytes, and
//! checksum-correct frames of the thirteen decoded messages (so the payload
//! decoders and the NAV epoch combiner are reached) and CRC-correct RTCM3
//! frames, spliced with raw bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_receivers::rtcm3;
use navsync_receivers::ubx::encode_frame;

#[path = "common.rs"]
mod common;

const IDS: [(u8, u8); 15] = [
    (0x01, 0x07),
    (0x01, 0x06),
    (0x01, 0x02),
    (0x01, 0x14),
    (0x01, 0x12),
    (0x01, 0x03),
    (0x01, 0x20),
    (0x0D, 0x01),
    (0x0D, 0x03),
    (0x10, 0x02),
    (0x10, 0x03),
    (0x01, 0x35),
    (0x28, 0x00),
    // Dead-reckoning receivers: NAV-PVAT, NAV-ATT.
    (0x01, 0x17),
    (0x01, 0x05),
];

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let (mode, rest) = (data[0], &data[1..]);
    let mut stream = Vec::new();
    if mode & 1 == 0 {
        stream.extend_from_slice(rest);
    } else {
        // [selector, len, payload…, garbage_len, garbage…]*
        let mut i = 0;
        while i + 2 <= rest.len() {
            let sel = rest[i] as usize % (IDS.len() + 1);
            let len = (rest[i + 1] as usize).min(rest.len() - i - 2);
            let payload = &rest[i + 2..i + 2 + len];
            match IDS.get(sel) {
                Some(&(class, id)) => stream.extend(encode_frame(class, id, payload).unwrap()),
                None => stream.extend(rtcm3::encode_frame(payload).unwrap()),
            }
            i += 2 + len;
            if let Some(&g) = rest.get(i) {
                let g = (g as usize % 8).min(rest.len() - i - 1);
                stream.extend_from_slice(&rest[i + 1..i + 1 + g]);
                i += 1 + g;
            }
        }
    }
    common::check_stream(&stream, data);
});
