//! Every listed message: encode → frame → stream reader → decode gives the
//! message back, checksums included; a changed byte is caught.

mod common;

use common::*;
use navsync_receivers::stream::{EventKind, read_all};

#[test]
fn ubx_messages_round_trip_through_the_reader() {
    let mut r = rng(11);
    for k in 0..6 * 300 {
        let m = ubx_message(&mut r, k);
        let frame = m.to_frame().unwrap();
        let (ev, st) = read_all(&frame, 0);
        assert_eq!(ev.len(), 1, "{m:?}");
        assert_eq!(ev[0].kind, EventKind::Ubx(m.clone()));
        assert_eq!(ev[0].len, frame.len());
        assert_eq!(st.ubx_messages, 1);
        // Any single changed byte breaks the Fletcher checksum ([M8] §32.4):
        // the frame is reported, never decoded.
        let i = k % frame.len();
        let mut bad = frame.clone();
        bad[i] ^= 1 + (k % 255) as u8;
        let (ev, st) = read_all(&bad, 0);
        assert!(
            ev.iter().all(|e| !matches!(e.kind, EventKind::Ubx(_))),
            "byte {i} of {m:?}"
        );
        assert_eq!(st.corrupt_bytes as usize, bad.len());
    }
}

#[test]
fn nmea_sentences_round_trip_through_the_reader() {
    let mut r = rng(12);
    for k in 0..4 * 300 {
        let m = nmea_message(&mut r, k);
        let s = m.to_sentence();
        let (ev, _) = read_all(s.as_bytes(), 0);
        assert_eq!(ev.len(), 1, "{s}");
        let EventKind::Nmea(got) = &ev[0].kind else {
            panic!("{s}: {:?}", ev[0])
        };
        assert!(nmea_close(got, &m), "{s}\n{got:?}\n{m:?}");
        // A changed byte (not a case flip of a hex digit, which is the same
        // checksum) breaks the XOR checksum or the framing.
        let i = k % s.len();
        let mut bad = s.clone().into_bytes();
        bad[i] ^= [1u8, 2, 4, 8, 16, 64, 128][k % 7];
        let (ev, st) = read_all(&bad, 0);
        assert!(
            ev.iter().all(|e| !matches!(e.kind, EventKind::Nmea(_))),
            "byte {i} of {s}"
        );
        assert_eq!(st.corrupt_bytes as usize, bad.len());
    }
}

#[test]
fn hand_checked_sentences() {
    // NMEA 0183 examples with their published checksums.
    for s in [
        "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n",
        "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A\r\n",
        "$GPZDA,201530.00,04,07,2002,00,00*60\r\n",
        "$GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031*6A\r\n",
    ] {
        let (ev, st) = read_all(s.as_bytes(), 0);
        assert_eq!((st.nmea_messages, st.corrupt_runs), (1, 0), "{s}: {ev:?}");
    }
}
