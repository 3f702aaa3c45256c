//! Fuzzes the mixed-stream reader with NMEA-heavy input: raw bytes, and
//! checksum-correct GGA/RMC/GST/ZDA sentences with fuzzed fields (so the
//! `nmea` crate's parsers are reached) spliced with raw bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_receivers::nmea::encode_sentence;

#[path = "common.rs"]
mod common;

const ADDR: [&str; 6] = ["GPGGA", "GNRMC", "GPGST", "GNZDA", "GPGSV", "PUBX"];
const ALPHABET: &[u8] = b"0123456789.,-+NSEWAVDMK";

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let (mode, rest) = (data[0], &data[1..]);
    let mut stream = Vec::new();
    if mode & 1 == 0 {
        stream.extend_from_slice(rest);
    } else {
        // [selector, len, field bytes…, garbage_len, garbage…]*
        let mut i = 0;
        while i + 2 <= rest.len() {
            let addr = ADDR[rest[i] as usize % ADDR.len()];
            let len = (rest[i + 1] as usize % 96).min(rest.len() - i - 2);
            let body: String = rest[i + 2..i + 2 + len]
                .iter()
                .map(|&b| {
                    if mode & 2 == 0 {
                        ALPHABET[b as usize % ALPHABET.len()] as char
                    } else {
                        (0x20 + b % 0x5F) as char
                    }
                })
                .filter(|&c| c != '*' && c != '$')
                .collect();
            stream.extend_from_slice(encode_sentence(&format!("{addr},{body}")).as_bytes());
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
