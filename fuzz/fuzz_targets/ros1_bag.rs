//! Fuzzes the ROS 1 bag reader (`navsync_receivers::ros1::read_bag`): raw
//! bytes as a bag file, or a bag written by `testbag1` (uncompressed, bz2
//! or lz4 chunks) whose `Imu`, `NavSatFix`, `Odometry`, `TwistStamped`,
//! `TwistWithCovarianceStamped` and one unread topic carry fuzzed message
//! bodies. Beyond "no panic": IMU samples, fixes and speeds come out
//! finite, in strictly increasing time, fixes with positive σ.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use navsync::Diagnostics;
use navsync_receivers::ros1;
use navsync_receivers::rosmsg::{AltitudeDatum, BagOptions, TopicChoice};
use navsync_receivers::testbag1::{
    Compression, FIX, IMU, Msg1, ODOM, TWIST, TWIST_COV, write_bag1,
};

const TOPICS: [(&str, (&str, &str)); 6] = [
    ("/imu", IMU),
    ("/fix", FIX),
    ("/odom", ODOM),
    ("/twist", TWIST),
    ("/vel", TWIST_COV),
    ("/rosout", ("rosgraph_msgs/Log", "acffd30cd6b6de30f120938c17c593fb")),
];

/// `rest` as (topic byte, u16 LE length mod 1024, body) triples.
fn bag(rest: &[u8], c: Compression) -> Vec<u8> {
    let mut msgs = Vec::new();
    let mut i = 0;
    let mut seq = 0i64;
    while i + 3 <= rest.len() {
        let k = rest[i] as usize % TOPICS.len();
        let len = u16::from_le_bytes([rest[i + 1], rest[i + 2]]) as usize % 1024;
        i += 3;
        let end = (i + len).min(rest.len());
        seq += 1;
        msgs.push(Msg1 {
            topic: TOPICS[k].0,
            ty: TOPICS[k].1,
            log_ns: 1_700_000_000_000_000_000 + seq * 10_000_000,
            data: rest[i..end].to_vec(),
        });
        i = end;
    }
    write_bag1(&msgs, c, 512)
}

fuzz_target!(|data: &[u8]| {
    if data.is_empty() {
        return;
    }
    let (mode, rest) = (data[0], &data[1..]);
    for (_, (ty, _)) in &TOPICS[..5] {
        let _ = ros1::decode_message(ty, rest);
    }
    let bytes = if mode & 1 == 0 {
        rest.to_vec()
    } else {
        let c = match (mode >> 1) & 3 {
            1 => Compression::Bz2,
            2 => Compression::Lz4,
            _ => Compression::None,
        };
        bag(rest, c)
    };
    let opts = BagOptions {
        default_sd_m: [5.0, 5.0, 10.0],
        altitude: if mode & 8 == 0 {
            AltitudeDatum::Ellipsoid
        } else {
            AltitudeDatum::Msl
        },
    };
    let mut d = Diagnostics::with_cap(16);
    let Ok(b) = ros1::read_bag(
        &bytes,
        Path::new("fuzz.bag"),
        &TopicChoice::default(),
        &opts,
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
    for w in b.speeds.windows(2) {
        assert!(w[1].0 > w[0].0);
    }
    assert!(b.speeds.iter().all(|s| s.1.is_finite()));
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
            assert!(v.iter().chain(s.iter()).all(|x| x.is_finite()));
            assert!(s.iter().all(|x| *x > 0.0));
        }
    }
});
