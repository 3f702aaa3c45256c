//! Fuzzes the ROS 2 bag reader (`navsync_receivers::ros2::read_bag`): raw
//! bytes as an MCAP file, or a bag written with the `mcap` crate (plain,
//! zstd or lz4 chunks) whose `Imu`, `NavSatFix` and `TwistWithCovarianceStamped`
//! payloads are fuzzed CDR bodies behind a valid encapsulation header.
//! Beyond "no panic": IMU samples and fixes come out finite, in strictly
//! increasing time, with positive σ.
#![no_main]

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::Diagnostics;
use navsync_receivers::ros2::{self, TopicChoice};

const SCHEMAS: [&str; 4] = [
    ros2::IMU_SCHEMA,
    ros2::NAVSATFIX_SCHEMA,
    ros2::TWIST_SCHEMA,
    "std_msgs/msg/String",
];

/// `rest` as (kind, length, payload) triples on four topics.
fn bag(rest: &[u8], compression: Option<mcap::Compression>) -> Option<Vec<u8>> {
    let mut w = mcap::WriteOptions::new()
        .compression(compression)
        .chunk_size(Some(512))
        .create(Cursor::new(Vec::new()))
        .ok()?;
    let mut ids = Vec::new();
    for (k, s) in SCHEMAS.iter().enumerate() {
        let sid = w.add_schema(s, "ros2msg", b"").ok()?;
        ids.push(
            w.add_channel(sid, &format!("/t{k}"), "cdr", &BTreeMap::new())
                .ok()?,
        );
    }
    let mut i = 0;
    let mut seq = 0u32;
    while i + 2 <= rest.len() {
        let (kind, len) = (rest[i], rest[i + 1] as usize * 2);
        i += 2;
        let end = (i + len).min(rest.len());
        let mut data = vec![0, (kind >> 2) & 1, 0, 0];
        data.extend_from_slice(&rest[i..end]);
        i = end;
        seq += 1;
        let h = mcap::records::MessageHeader {
            channel_id: ids[kind as usize % ids.len()],
            sequence: seq,
            log_time: 1_700_000_000_000_000_000 + seq as u64 * 10_000_000,
            publish_time: 0,
        };
        w.write_to_known_channel(&h, &data).ok()?;
    }
    w.finish().ok()?;
    Some(w.into_inner().into_inner())
}

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let (mode, rest) = (data[0], &data[1..]);
    let _ = ros2::Imu::decode(rest);
    let _ = ros2::NavSatFix::decode(rest);
    let _ = ros2::TwistStamped::decode(rest);
    let bytes = if mode & 1 == 0 {
        rest.to_vec()
    } else {
        let compression = match (mode >> 1) & 3 {
            1 => Some(mcap::Compression::Zstd),
            2 => Some(mcap::Compression::Lz4),
            _ => None,
        };
        match bag(rest, compression) {
            Some(b) => b,
            None => return,
        }
    };
    let mut d = Diagnostics::with_cap(16);
    let Ok(b) = ros2::read_bag(
        &bytes,
        Path::new("fuzz.mcap"),
        &TopicChoice::default(),
        [5.0, 5.0, 10.0],
        &mut d,
    ) else {
        return;
    };
    for w in b.imu.windows(2) {
        assert!(w[1].time > w[0].time);
    }
    for s in &b.imu {
        assert!(
            s.gyro_radps
                .iter()
                .chain(s.accel_mps2.iter())
                .all(|v| v.is_finite())
        );
    }
    for w in b.fixes.windows(2) {
        assert!(w[1].fix.time > w[0].fix.time);
    }
    for f in &b.fixes {
        let f = f.fix;
        assert!(f.pos.lat_rad.is_finite() && f.pos.lon_rad.is_finite() && f.pos.h_m.is_finite());
        assert!(
            f.pos_sd.iter().all(|s| s.is_finite() && *s > 0.0),
            "{:?}",
            f.pos_sd
        );
        if let (Some(v), Some(s)) = (f.vel, f.vel_sd) {
            assert!(
                v.iter()
                    .chain(s.iter())
                    .all(|x| x.is_finite() && x.abs() < f64::MAX)
            );
            assert!(s.iter().all(|x| *x > 0.0));
        }
    }
});
