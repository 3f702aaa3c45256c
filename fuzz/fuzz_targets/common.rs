//! Shared checks: the reader accounts for every byte exactly once, in order,
//! and every decoded message re-encodes to the very bytes it came from;
//! the decoded UBX navigation messages go through the epoch combiner (no
//! panic on any content).

use navsync_receivers::fixes::{FixOptions, TimeContext, UbxEpochs};
use navsync_receivers::stream::{EventKind, StreamReader};
use navsync_receivers::ubx::UbxMessage;

/// Feeds `bytes` in chunks whose sizes come from `sizes`, then checks the
/// event invariants.
pub fn check_stream(bytes: &[u8], sizes: &[u8]) {
    let mut r = StreamReader::new();
    let mut events = Vec::new();
    let mut pos = 0;
    let mut k = 0;
    while pos < bytes.len() {
        let n = (sizes.get(k).copied().unwrap_or(255) as usize % 64 + 1).min(bytes.len() - pos);
        r.push(&bytes[pos..pos + n]);
        pos += n;
        k += 1;
        while let Some(e) = r.next_event() {
            events.push(e);
        }
    }
    r.finish();
    while let Some(e) = r.next_event() {
        events.push(e);
    }
    let mut epochs = UbxEpochs::new(FixOptions::default());
    let mut ctx = TimeContext::default();
    let mut outcomes = Vec::new();
    let mut expect = 0u64;
    for e in &events {
        if let EventKind::Ubx(m) = &e.kind {
            epochs.push(m, &ctx, &mut outcomes);
            if let UbxMessage::NavTimeGps(t) = m {
                ctx.push_timegps(t);
            }
        }
        assert_eq!(e.offset, expect, "events must tile the stream");
        assert!(e.len > 0);
        let frame = &bytes[e.offset as usize..e.offset as usize + e.len];
        match &e.kind {
            EventKind::Ubx(m) => assert_eq!(m.to_frame().unwrap(), frame, "UBX re-encode"),
            EventKind::Nmea(_) => assert_eq!(frame[0], b'$'),
            _ => {}
        }
        expect += e.len as u64;
    }
    assert_eq!(expect, bytes.len() as u64, "every byte accounted for");
    epochs.finish(&ctx, &mut outcomes);
    let st = r.stats();
    assert_eq!(st.bytes, bytes.len() as u64);
}
