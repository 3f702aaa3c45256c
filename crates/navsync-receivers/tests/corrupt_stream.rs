//! A mixed NMEA + UBX stream as a u-blox receiver emits it, with 1 % of its
//! bytes corrupted (seeded) and a few runs of garbage: every intact message
//! is recovered exactly, every damaged span is reported as exactly one
//! corrupt run covering exactly its bytes, and nothing else is lost.

mod common;

use common::*;
use navsync_receivers::nmea::{NmeaMessage, encode_sentence};
use navsync_receivers::stream::{EventKind, StreamReader};
use navsync_receivers::ubx::{self, UbxMessage};
use rand::RngExt;

#[derive(Clone, Debug)]
enum Truth {
    Ubx(UbxMessage),
    Nmea(NmeaMessage),
    /// An intact frame of a type the reader does not decode.
    Other,
    Garbage,
}

struct Segment {
    offset: usize,
    len: usize,
    truth: Truth,
}

/// ~one second of output per epoch: NAV-PVT, NAV-TIMEGPS, TIM-TP, ESF-RAW
/// (10 samples × 7 sensors), ESF-MEAS, a TIM-TM2 every 5th epoch, a NAV-SAT
/// (not decoded), GGA, RMC, GST, ZDA and a GSV (not decoded); a garbage run
/// every 50th epoch.
fn generate(epochs: usize, seed: u64) -> (Vec<u8>, Vec<Segment>) {
    let mut r = rng(seed);
    let mut bytes = Vec::new();
    let mut segs = Vec::new();
    let mut push = |bytes: &mut Vec<u8>, b: &[u8], truth: Truth| {
        segs.push(Segment {
            offset: bytes.len(),
            len: b.len(),
            truth,
        });
        bytes.extend_from_slice(b);
    };
    for e in 0..epochs {
        for k in [0usize, 1, 2] {
            let m = ubx_message(&mut r, k);
            push(&mut bytes, &m.to_frame().unwrap(), Truth::Ubx(m));
        }
        let raw = UbxMessage::EsfRaw(esf_raw(&mut r, 70));
        push(&mut bytes, &raw.to_frame().unwrap(), Truth::Ubx(raw));
        let meas = ubx_message(&mut r, 4);
        push(&mut bytes, &meas.to_frame().unwrap(), Truth::Ubx(meas));
        if e % 5 == 0 {
            let m = ubx_message(&mut r, 3);
            push(&mut bytes, &m.to_frame().unwrap(), Truth::Ubx(m));
        }
        let sat: Vec<u8> = (0..8 + 12 * 20).map(|_| r.random()).collect();
        push(
            &mut bytes,
            &ubx::encode_frame(0x01, 0x35, &sat).unwrap(),
            Truth::Other,
        );
        for k in 0..4 {
            let m = nmea_message(&mut r, k);
            push(&mut bytes, m.to_sentence().as_bytes(), Truth::Nmea(m));
        }
        let gsv =
            encode_sentence("GPGSV,3,1,12,01,40,083,46,02,17,308,41,12,07,344,39,14,22,228,45");
        push(&mut bytes, gsv.as_bytes(), Truth::Other);
        if e % 50 == 25 {
            // Logger garbage, seeded with sync characters.
            let n = r.random_range(1..60);
            let g: Vec<u8> = (0..n)
                .map(|_| [0xB5, 0x62, b'$', b'*', b'\r', b'\n', r.random()][r.random_range(0..7)])
                .collect();
            push(&mut bytes, &g, Truth::Garbage);
        }
    }
    (bytes, segs)
}

/// Independent checks of a (possibly corrupted) span against its
/// protocol's checksum: a corruption the checksum cannot see (two equal
/// XOR changes in one NMEA sentence) leaves a valid frame.
fn still_valid_frame(b: &[u8], original: &[u8]) -> bool {
    if original[0] == ubx::SYNC1 {
        let n = b.len();
        b[0] == ubx::SYNC1
            && b[1] == ubx::SYNC2
            && b[4..6] == original[4..6]
            && ubx::checksum(&b[2..n - 2]) == b[n - 2..]
    } else {
        let star = original.iter().position(|&c| c == b'*').unwrap();
        let body = &b[1..star];
        let hex = std::str::from_utf8(&b[star + 1..star + 3])
            .ok()
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        b[0] == b'$'
            && b[star] == b'*'
            && body
                .iter()
                .all(|&c| (0x20..0x7F).contains(&c) && c != b'$' && c != b'*')
            && hex == Some(body.iter().fold(0, |a, &c| a ^ c))
            && b.ends_with(b"\r\n")
    }
}

#[test]
fn one_percent_corrupted_bytes() {
    let (clean, segs) = generate(400, 2024);
    let mut bytes = clean.clone();
    let mut r = rng(99);
    let mut corrupted = vec![false; bytes.len()];
    for (i, b) in bytes.iter_mut().enumerate() {
        if r.random_bool(0.01) {
            // Never a 0x20 flip: it turns a hex checksum digit into its
            // lower-case twin, which is the same checksum (not a corruption).
            let x = loop {
                let x: u8 = r.random_range(1..=255);
                if x != 0x20 {
                    break x;
                }
            };
            *b ^= x;
            corrupted[i] = true;
        }
    }
    let n_corrupted = corrupted.iter().filter(|&&c| c).count();

    // Ground truth: intact frames, frames whose corruption the checksum
    // cannot see, and the maximal runs of damaged spans between them.
    let mut expect_frames = Vec::new(); // (offset, len, truth, intact)
    let mut expect_runs: Vec<(usize, usize)> = Vec::new();
    let (mut intact_msgs, mut damaged_msgs, mut undetectable) = (0, 0, 0);
    for s in &segs {
        let damaged = corrupted[s.offset..s.offset + s.len].iter().any(|&c| c);
        let span = &bytes[s.offset..s.offset + s.len];
        let is_msg = matches!(s.truth, Truth::Ubx(_) | Truth::Nmea(_));
        let frame_ok = match s.truth {
            Truth::Garbage => false,
            _ if !damaged => true,
            _ => still_valid_frame(span, &clean[s.offset..s.offset + s.len]),
        };
        if frame_ok {
            if damaged {
                undetectable += 1;
            } else if is_msg {
                intact_msgs += 1;
            }
            expect_frames.push((s.offset, s.len, s.truth.clone(), !damaged));
        } else {
            if is_msg {
                damaged_msgs += 1;
            }
            match expect_runs.last_mut() {
                Some((o, l)) if *o + *l == s.offset => *l += s.len,
                _ => expect_runs.push((s.offset, s.len)),
            }
        }
    }

    // Read in uneven chunks, as from a serial port.
    let mut reader = StreamReader::new();
    let mut events = Vec::new();
    let mut pos = 0;
    while pos < bytes.len() {
        let n = r.random_range(1..700).min(bytes.len() - pos);
        reader.push(&bytes[pos..pos + n]);
        pos += n;
        while let Some(e) = reader.next_event() {
            events.push(e);
        }
    }
    reader.finish();
    while let Some(e) = reader.next_event() {
        events.push(e);
    }

    let runs: Vec<(usize, usize)> = events
        .iter()
        .filter(|e| matches!(e.kind, EventKind::Corrupt(_)))
        .map(|e| (e.offset as usize, e.len))
        .collect();
    let frames: Vec<_> = events
        .iter()
        .filter(|e| !matches!(e.kind, EventKind::Corrupt(_)))
        .collect();
    println!(
        "stream {} bytes, {} corrupted ({:.3} %); messages: {} intact, {} damaged, {} damaged but checksum-valid; \
         corrupt runs expected {} reported {}",
        bytes.len(),
        n_corrupted,
        100.0 * n_corrupted as f64 / bytes.len() as f64,
        intact_msgs,
        damaged_msgs,
        undetectable,
        expect_runs.len(),
        runs.len()
    );
    assert_eq!(
        runs, expect_runs,
        "every damaged span reported as exactly its bytes"
    );
    assert_eq!(
        frames.len(),
        expect_frames.len(),
        "nothing else lost, nothing invented"
    );
    let mut recovered = 0;
    for (e, (offset, len, truth, intact)) in frames.iter().zip(&expect_frames) {
        assert_eq!((e.offset as usize, e.len), (*offset, *len));
        if !intact {
            continue;
        }
        match (truth, &e.kind) {
            (Truth::Ubx(m), EventKind::Ubx(got)) => assert_eq!(got, m),
            (Truth::Nmea(m), EventKind::Nmea(got)) => {
                assert!(nmea_close(got, m), "{got:?} vs {m:?}")
            }
            (Truth::Other, EventKind::Unknown(_)) => continue,
            (t, k) => panic!("at {offset}: expected {t:?}, got {k:?}"),
        }
        recovered += 1;
    }
    assert_eq!(recovered, intact_msgs, "every intact message recovered");
    assert!(
        damaged_msgs > 500,
        "the test must exercise corruption ({damaged_msgs} damaged)"
    );
    let st = reader.stats();
    assert_eq!(st.corrupt_runs as usize, expect_runs.len());
    assert_eq!(
        st.corrupt_bytes as usize,
        expect_runs.iter().map(|r| r.1).sum::<usize>()
    );
}
