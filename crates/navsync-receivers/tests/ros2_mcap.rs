//! ROS 2 bags (MCAP) through `convert`: bags written with the `mcap`
//! crate's writer and the CDR encoder of `testbag` (independent of the
//! decoder under test), holding a known IMU rotation and known fixes.

use std::path::Path;

use navsync::testfiles::TestDir;
use navsync_receivers::convert::{
    ConvertOptions, ConvertSummary, InputFormat, convert_with_topics,
};
use navsync_receivers::ros2::TopicChoice;
use navsync_receivers::testbag::{FIX, IMU, Msg, TWIST, fix_msg, imu_msg, twist_msg, write_bag};

/// A directory of this test, removed when it passes.
fn tmp(name: &str) -> TestDir {
    TestDir::new(&format!("ros2-{name}"))
}

/// 2024-01-01T00:00:00Z (Monday): GPS week 2295, 86 400 s + 18 leap s.
const T0_NS: i64 = 1_704_067_200 * 1_000_000_000;
const SOW0: f64 = 86_418.0;
const YAW_RATE: f64 = 0.1; // rad/s about FLU z (a left turn)
const G: f64 = 9.80665;

/// 10 s: IMU at 100 Hz turning left at 0.1 rad/s, 1 Hz fixes (one NO_FIX)
/// with a velocity each, messages logged 4 ms after their stamps,
/// alternating little- and big-endian CDR.
fn drive(lag_ns: i64) -> Vec<Msg> {
    let mut v = Vec::new();
    for k in 0..=1000i64 {
        let t = T0_NS + k * 10_000_000;
        v.push(Msg {
            topic: "/imu/data",
            schema: IMU,
            log_ns: t + lag_ns,
            data: imu_msg(k % 2 == 0, t, [0.0, 0.0, YAW_RATE], [0.0, 0.0, G]),
        });
        if k % 100 == 50 {
            let s = k / 100;
            let status = if s == 3 { -1 } else { 0 };
            let lat = 30.5 + 1e-5 * s as f64;
            v.push(Msg {
                topic: "/fix",
                schema: FIX,
                log_ns: t + lag_ns,
                data: fix_msg(
                    s % 2 == 1,
                    t,
                    status,
                    [lat, 114.25, 25.0],
                    [0.04, 0.01, 0.09],
                ),
            });
            v.push(Msg {
                topic: "/fix_velocity",
                schema: TWIST,
                log_ns: t + lag_ns,
                data: twist_msg(true, t, [0.5, 1.1, -0.1], 0.0025),
            });
        }
    }
    v
}

/// The conversion and its output directory (removed with the test's
/// directory when dropped).
fn run(bag: &[u8], name: &str, topics: &TopicChoice) -> (Result<ConvertSummary, String>, TestDir) {
    let out = tmp(name).at("out");
    let input = out.root().join("bag.mcap");
    std::fs::write(&input, bag).unwrap();
    let r = convert_with_topics(
        InputFormat::Mcap,
        &input,
        &out,
        &ConvertOptions::default(),
        topics,
    )
    .map_err(|e| e.to_string());
    (r, out)
}

fn rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect()
}

fn messages(s: &ConvertSummary) -> Vec<String> {
    s.diagnostics.items.iter().map(|d| d.to_string()).collect()
}

#[test]
fn known_rotation_and_fixes_round_trip() {
    for (compression, name) in [
        (None, "plain"),
        (Some(mcap::Compression::Zstd), "zstd"),
        (Some(mcap::Compression::Lz4), "lz4"),
    ] {
        let bag = write_bag(&drive(4_000_000), compression);
        let (s, out) = run(&bag, name, &TopicChoice::default());
        let s = s.unwrap();
        assert!(s.diagnostics.is_empty(), "{:?}", messages(&s));
        let imu = rows(&out.join("imu.txt"));
        assert_eq!(imu.len(), 1000, "{name}");
        assert!((imu[0][0] - (SOW0 + 0.01)).abs() < 1e-9, "{}", imu[0][0]);
        // FLU yaw rate +0.1 rad/s is −0.1 about FRD z; gravity's reaction
        // (+g up in FLU) is −g along FRD z.
        let turned: f64 = imu.iter().map(|r| r[3]).sum();
        assert!((turned + YAW_RATE * 10.0).abs() < 1e-9, "{turned}");
        for r in &imu {
            assert!((r[6] + G * 0.01).abs() < 1e-9 && r[1].abs() < 1e-15 && r[5].abs() < 1e-15);
        }
        let gnss = rows(&out.join("gnss.txt"));
        assert_eq!(gnss.len(), 9, "one NO_FIX of 10 dropped");
        assert_eq!(gnss[0].len(), 13);
        assert!((gnss[0][0] - (SOW0 + 0.5)).abs() < 1e-9);
        assert!(
            (gnss[3][1] - (30.5 + 4e-5)).abs() < 1e-10,
            "fix 3 was the NO_FIX"
        );
        // vn ve vd from ENU (0.5, 1.1, −0.1); σ n e d from ENU variances.
        assert_eq!(&gnss[0][4..7], &[1.1, 0.5, 0.1]);
        assert_eq!(&gnss[0][7..10], &[0.1, 0.2, 0.3]);
        assert_eq!(&gnss[0][10..13], &[0.05, 0.05, 0.05]);
        let t = &s.fix_epochs[0];
        assert_eq!((t.epochs, t.fixes), (10, 9));
        assert_eq!(t.dropped[0].reason, "status -1 (NO_FIX)");
        let b = s.ros2.as_ref().unwrap();
        let imu_t = b.topics.iter().find(|t| t.topic == "/imu/data").unwrap();
        assert_eq!((imu_t.used, imu_t.role.as_deref()), (1001, Some("imu")));
        let lag = imu_t.log_time_minus_stamp.as_ref().unwrap();
        assert!((lag.median_s - 0.004).abs() < 1e-9, "{lag:?}");
        assert_eq!(b.fixes_with_velocity, 9);
        assert_eq!(s.no_fix_message(), None);
    }
}

#[test]
fn systematic_stamp_offset_is_reported() {
    let bag = write_bag(&drive(18_000_000_000), None);
    let (s, _) = run(&bag, "lag18", &TopicChoice::default());
    let m = messages(&s.unwrap());
    assert!(
        m.iter()
            .any(|l| l.contains("/imu/data") && l.contains("+18.000 s") && l.contains("GPS − UTC")),
        "{m:?}"
    );
}

#[test]
fn bad_messages_are_named_and_the_good_ones_kept() {
    let mut msgs = drive(4_000_000);
    // IMU messages (index = sample number): 10 NaN, 20 a repeated stamp,
    // 30 back in time, 40 cut short, 50 stamped before 1980.
    let stamp = |k: i64| T0_NS + k * 10_000_000;
    let idx = |msgs: &Vec<Msg>, k: usize| {
        msgs.iter()
            .enumerate()
            .filter(|(_, m)| m.topic == "/imu/data")
            .nth(k)
            .unwrap()
            .0
    };
    let i = idx(&msgs, 10);
    msgs[i].data = imu_msg(true, stamp(10), [f64::NAN, 0.0, YAW_RATE], [0.0, 0.0, G]);
    let i = idx(&msgs, 20);
    msgs[i].data = imu_msg(true, stamp(19), [0.0, 0.0, YAW_RATE], [0.0, 0.0, G]);
    let i = idx(&msgs, 30);
    msgs[i].data = imu_msg(true, stamp(25), [0.0, 0.0, YAW_RATE], [0.0, 0.0, G]);
    let i = idx(&msgs, 40);
    msgs[i].data.truncate(100);
    let i = idx(&msgs, 50);
    msgs[i].data = imu_msg(true, 1_000_000_000, [0.0, 0.0, YAW_RATE], [0.0, 0.0, G]);
    // A fix with a NaN latitude.
    let f = msgs.iter().position(|m| m.topic == "/fix").unwrap();
    msgs[f].data = fix_msg(
        true,
        T0_NS + 500_000_000,
        0,
        [f64::NAN, 114.0, 20.0],
        [1.0; 3],
    );
    let (s, out) = run(&write_bag(&msgs, None), "bad", &TopicChoice::default());
    let s = s.unwrap();
    let m = messages(&s);
    let expect = [
        "non-finite angular velocity",
        "duplicate epoch",
        "time goes backwards",
        "truncated",
        "before the GPS epoch",
        "latitude NaN",
    ];
    for e in expect {
        assert!(
            m.iter()
                .any(|l| l.contains(e) && l.contains("bag.mcap") && l.contains("message ")),
            "{e}: {m:?}"
        );
    }
    // The samples around each bad one are all there: 1001 − 5 messages.
    assert_eq!(rows(&out.join("imu.txt")).len(), 1001 - 5 - 1);
    assert_eq!(rows(&out.join("gnss.txt")).len(), 8);
    let dropped: Vec<_> = s.fix_epochs[0]
        .dropped
        .iter()
        .map(|d| d.reason.as_str())
        .collect();
    assert!(
        dropped.contains(&"non-finite or out-of-range position"),
        "{dropped:?}"
    );
}

#[test]
fn truncated_file_keeps_the_messages_before_the_cut() {
    let msgs = drive(4_000_000);
    let bag = write_bag(&msgs, Some(mcap::Compression::Zstd));
    let (full, full_out) = run(&bag, "whole", &TopicChoice::default());
    full.unwrap();
    let whole = rows(&full_out.join("imu.txt"));
    let cut = &bag[..bag.len() * 3 / 5];
    let (s, out) = run(cut, "cut", &TopicChoice::default());
    let s = s.unwrap();
    let m = messages(&s);
    assert!(
        m.iter().any(|l| l.contains("bag.mcap")
            && l.contains("reading stopped after message")
            && l.contains("truncated")),
        "{m:?}"
    );
    let part = rows(&out.join("imu.txt"));
    assert!(
        part.len() > 100 && part.len() < whole.len(),
        "{}",
        part.len()
    );
    assert_eq!(part[..], whole[..part.len()], "what was read is unchanged");
    // Nothing readable at all: an error naming the file.
    let (e, _) = run(&bag[..30], "stub", &TopicChoice::default());
    let e = e.unwrap_err();
    assert!(e.contains("bag.mcap") && e.contains("truncated"), "{e}");
    let (e, _) = run(
        b"not an mcap file at all, just text",
        "text",
        &TopicChoice::default(),
    );
    assert!(e.unwrap_err().contains("not an MCAP file"));
}

#[test]
fn topic_choice_and_wrong_schemas_are_errors_that_say_why() {
    let bag = write_bag(&drive(0), None);
    let wrong = TopicChoice {
        imu: Some("/fix".into()),
        ..Default::default()
    };
    let e = run(&bag, "wrong", &wrong).0.unwrap_err();
    assert!(
        e.contains("bag.mcap")
            && e.contains("/fix")
            && e.contains("schema sensor_msgs/msg/NavSatFix, not sensor_msgs/msg/Imu"),
        "{e}"
    );
    let missing = TopicChoice {
        gnss: Some("/gps".into()),
        ..Default::default()
    };
    let e = run(&bag, "missing", &missing).0.unwrap_err();
    assert!(
        e.contains("no topic /gps") && e.contains("/imu/data (sensor_msgs/msg/Imu"),
        "{e}"
    );
    // Two IMU topics: the choice is the user's.
    let mut two = drive(0);
    two.push(Msg {
        topic: "/imu2",
        schema: IMU,
        log_ns: T0_NS + 20_000_000_000,
        data: imu_msg(true, T0_NS, [0.0; 3], [0.0; 3]),
    });
    let bag2 = write_bag(&two, None);
    let e = run(&bag2, "two", &TopicChoice::default()).0.unwrap_err();
    assert!(
        e.contains("2 topics have schema sensor_msgs/msg/Imu") && e.contains("--imu-topic"),
        "{e}"
    );
    let pick = TopicChoice {
        imu: Some("/imu/data".into()),
        ..Default::default()
    };
    assert!(run(&bag2, "pick", &pick).0.is_ok());
    // No topic navsync reads.
    let other = write_bag(
        &[Msg {
            topic: "/tf",
            schema: "tf2_msgs/msg/TFMessage",
            log_ns: T0_NS,
            data: vec![0, 1, 0, 0],
        }],
        None,
    );
    let e = run(&other, "other", &TopicChoice::default()).0.unwrap_err();
    assert!(
        e.contains("no sensor_msgs/msg/Imu or sensor_msgs/msg/NavSatFix topic")
            && e.contains("/tf"),
        "{e}"
    );
}

#[test]
fn unknown_chunk_compression_is_named() {
    let mut bag = write_bag(&drive(0), Some(mcap::Compression::Zstd));
    // Rename the chunks' compression in place (same length, records whole).
    let at: Vec<usize> = (0..bag.len() - 3)
        .filter(|&i| &bag[i..i + 4] == b"zstd")
        .collect();
    assert!(!at.is_empty());
    for i in at {
        bag[i..i + 4].copy_from_slice(b"brot");
    }
    let e = run(&bag, "unknown", &TopicChoice::default()).0.unwrap_err();
    assert!(
        e.contains("bag.mcap") && e.contains("\"brot\"") && e.contains("lz4"),
        "{e}"
    );
}
