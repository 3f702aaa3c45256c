//! Fuzzes the PX4 ULog reader (`navsync_receivers::ulog::read`): raw bytes
//! as a file (mode byte even), or a file with a valid header, PX4's real
//! format definitions (nested types, padding) and subscriptions, followed
//! by fuzzed messages (letter, size, payload) and sync messages (mode byte
//! odd). Beyond "no panic": the whole input is consumed (every byte read,
//! skipped to a sync or reported), decoded records are in the topics the
//! file subscribed, and a topic's message count covers its records.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::Diagnostics;
use navsync_receivers::testulog::*;
use navsync_receivers::ulog;

const LETTERS: &[u8] = b"BFIMPQARDLCSO";

fn structured(rest: &[u8]) -> Vec<u8> {
    let mut w = UlogWriter::new(0);
    for d in [
        SENSOR_COMBINED,
        VEHICLE_GPS_POSITION,
        SENSOR_GPS,
        VEHICLE_ATTITUDE,
        VEHICLE_GLOBAL_POSITION,
        VEHICLE_LOCAL_POSITION,
        ESC_REPORT,
        ESC_STATUS,
    ] {
        w.format(d);
    }
    for (id, name) in [
        "sensor_combined",
        "vehicle_gps_position",
        "sensor_gps",
        "vehicle_attitude",
        "vehicle_global_position",
        "vehicle_local_position",
        "esc_status",
    ]
    .iter()
    .enumerate()
    {
        w.add(0, id as u16, name);
    }
    let mut i = 0;
    while i + 2 <= rest.len() {
        let (kind, len) = (rest[i], rest[i + 1] as usize);
        i += 2;
        let end = (i + len).min(rest.len());
        let body = &rest[i..end];
        i = end;
        match kind % 16 {
            // Data of a subscribed id, its payload fuzzed.
            0..=7 => {
                let mut b = vec![kind % 8, 0];
                b.extend_from_slice(body);
                w.msg(b'D', &b);
            }
            13 => w.sync(),
            k => w.msg(LETTERS[(k as usize + kind as usize / 16) % LETTERS.len()], body),
        }
    }
    w.buf
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let bytes = if mode % 2 == 0 {
        rest.to_vec()
    } else {
        structured(rest)
    };
    let mut diag = Diagnostics::with_cap(100);
    if let Ok(d) = ulog::read(bytes.as_slice(), Path::new("fuzz.ulg"), &mut diag) {
        assert_eq!(d.bytes, bytes.len() as u64);
        let count = |t: &str, id: u8| {
            d.topics
                .iter()
                .filter(|x| x.topic == t && x.multi_id == id)
                .map(|x| x.messages)
                .sum::<u64>()
        };
        for (id, v) in &d.imu {
            assert!(v.len() as u64 <= count(ulog::IMU_TOPIC, *id));
        }
        for ((t, id), v) in &d.gps {
            assert!(ulog::GPS_TOPICS.contains(&t.as_str()));
            assert!(v.len() as u64 <= count(t.as_str(), *id));
        }
    }
});
