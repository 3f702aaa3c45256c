//! ROS 1 bags through `convert`: bags written by `testbag1` (from the
//! format's specification, independent of the reader) with uncompressed,
//! bz2 and lz4 chunks, the real Husky bag, and damaged bags.

use std::path::Path;

use navsync::testfiles::TestDir;
use navsync_receivers::convert::{
    ConvertOptions, ConvertSummary, InputFormat, convert_with_topics,
};
use navsync_receivers::geoid::Egm96Grid;
use navsync_receivers::rosmsg::{AltitudeDatum, TopicChoice};
use navsync_receivers::testbag1::{
    Compression, FIX, IMU, Msg1, ODOM, TWIST, TWIST_COV, fix_msg, imu_msg, odom_msg, twist_cov_msg,
    twist_msg, write_bag1,
};

fn tmp(name: &str) -> TestDir {
    TestDir::new(&format!("ros1-{name}"))
}

/// 2024-01-01T00:00:00Z (Monday): GPS week 2295, 86 400 s + 18 leap s.
const T0_NS: i64 = 1_704_067_200 * 1_000_000_000;
const SOW0: f64 = 86_418.0;
const YAW_RATE: f64 = 0.1; // rad/s about FLU z (a left turn)
const G: f64 = 9.80665;
const LAG_NS: i64 = 4_000_000;

/// 10 s: IMU at 100 Hz turning left, 1 Hz fixes (the fourth NO_FIX) each
/// with an ENU velocity, odometry at 10 Hz (2 + 0.1·k m/s, σ 0.05 m/s),
/// and a topic navsync does not read; recorded 4 ms after the stamps.
fn drive() -> Vec<Msg1> {
    let mut v = Vec::new();
    for k in 0..=1000i64 {
        let t = T0_NS + k * 10_000_000;
        v.push(Msg1 {
            topic: "/imu/data",
            ty: IMU,
            log_ns: t + LAG_NS,
            data: imu_msg(t, [0.0, 0.0, YAW_RATE], [0.0, 0.0, G]),
        });
        if k % 10 == 5 {
            v.push(Msg1 {
                topic: "/odom",
                ty: ODOM,
                log_ns: t + LAG_NS,
                data: odom_msg(t, "base_link", 2.0 + 0.01 * k as f64, 0.0025),
            });
        }
        if k % 100 == 50 {
            let s = k / 100;
            let lat = 30.5 + 1e-5 * s as f64;
            v.push(Msg1 {
                topic: "/fix",
                ty: FIX,
                log_ns: t + LAG_NS,
                data: fix_msg(
                    t,
                    if s == 3 { -1 } else { 1 },
                    [lat, 114.25, 25.0],
                    [0.04, 0.01, 0.09],
                ),
            });
            v.push(Msg1 {
                topic: "/fix_velocity",
                ty: TWIST_COV,
                log_ns: t + LAG_NS,
                data: twist_cov_msg(t, [0.5, 1.1, -0.1], 0.0025),
            });
            v.push(Msg1 {
                topic: "/rosout",
                ty: ("rosgraph_msgs/Log", "acffd30cd6b6de30f120938c17c593fb"),
                log_ns: t + LAG_NS,
                data: vec![1, 2, 3],
            });
        }
    }
    v
}

fn run_with(
    bag: &[u8],
    name: &str,
    topics: &TopicChoice,
    opts: &ConvertOptions,
) -> (Result<ConvertSummary, String>, TestDir) {
    let out = tmp(name).at("out");
    let input = out.root().join("drive.bag");
    std::fs::write(&input, bag).unwrap();
    let r = convert_with_topics(InputFormat::Ros1Bag, &input, &out, opts, topics)
        .map_err(|e| e.to_string());
    (r, out)
}

fn run(bag: &[u8], name: &str) -> (Result<ConvertSummary, String>, TestDir) {
    run_with(
        bag,
        name,
        &TopicChoice::default(),
        &ConvertOptions::default(),
    )
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
fn every_compression_round_trips_values_times_frames_and_sigma() {
    for c in [Compression::None, Compression::Bz2, Compression::Lz4] {
        let name = c.name();
        let bag = write_bag1(&drive(), c, 4096);
        let (s, out) = run(&bag, name);
        let s = s.unwrap();
        assert!(s.diagnostics.is_empty(), "{name}: {:?}", messages(&s));
        let imu = rows(&out.join("imu.txt"));
        assert_eq!(imu.len(), 1000, "{name}");
        assert!((imu[0][0] - (SOW0 + 0.01)).abs() < 1e-9, "{}", imu[0][0]);
        // FLU yaw rate +0.1 rad/s is −0.1 about FRD z; +g up in FLU is −g
        // along FRD z.
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
        assert_eq!(gnss[0][3], 25.0, "ellipsoidal by default");
        // vn ve vd from ENU (0.5, 1.1, −0.1); σ n e d from ENU variances.
        assert_eq!(&gnss[0][4..7], &[1.1, 0.5, 0.1]);
        assert_eq!(&gnss[0][7..10], &[0.1, 0.2, 0.3]);
        assert_eq!(&gnss[0][10..13], &[0.05, 0.05, 0.05]);
        assert_eq!(s.fix_epochs[0].dropped[0].reason, "status -1 (NO_FIX)");
        // Odometry: 100 speeds, linear.x at its stamp.
        let sp = rows(&out.join("speed.txt"));
        assert_eq!(sp.len(), 100);
        assert!((sp[0][0] - (SOW0 + 0.05)).abs() < 1e-9 && (sp[0][1] - 2.05).abs() < 1e-12);
        assert!((sp[99][0] - (SOW0 + 9.95)).abs() < 1e-9 && (sp[99][1] - 11.95).abs() < 1e-12);
        let b = s.ros1.as_ref().unwrap();
        let sps = b.speed.as_ref().unwrap();
        assert_eq!(sps.median_sd_mps, Some(0.05));
        assert!(sps.source.contains("\"base_link\""), "{}", sps.source);
        let role = |t: &str| {
            let t = b.topics.iter().find(|x| x.topic == t).unwrap();
            (t.role.clone(), t.used, t.messages)
        };
        assert_eq!(role("/imu/data"), (Some("imu".into()), 1001, 1001));
        assert_eq!(role("/fix"), (Some("gnss".into()), 9, 10));
        assert_eq!(role("/odom"), (Some("speed".into()), 100, 100));
        assert_eq!(role("/fix_velocity"), (Some("velocity".into()), 9, 10));
        assert_eq!(role("/rosout"), (None, 0, 10));
        let lag = b.topics[1].log_time_minus_stamp.as_ref().unwrap();
        assert!((lag.median_s - 0.004).abs() < 1e-9, "{lag:?}");
        assert!(b.altitude_datum.starts_with("ellipsoid"));
        assert_eq!(s.no_fix_message(), None);
    }
}

#[test]
fn msl_altitudes_get_the_egm96_separation() {
    let bag = write_bag1(&drive(), Compression::Bz2, 1 << 20);
    let opts = ConvertOptions {
        ros_altitude: AltitudeDatum::Msl,
        ..Default::default()
    };
    let (s, out) = run_with(&bag, "msl", &TopicChoice::default(), &opts);
    let s = s.unwrap();
    let gnss = rows(&out.join("gnss.txt"));
    let n = Egm96Grid::new().separation_m(30.5, 114.25).unwrap();
    // Hubei: the geoid lies some metres from the ellipsoid.
    assert!(n.abs() > 5.0, "{n}");
    assert!(
        (gnss[0][3] - (25.0 + n)).abs() < 1e-3,
        "{} vs {}",
        gnss[0][3],
        25.0 + n
    );
    let b = s.ros1.unwrap();
    assert!(b.altitude_datum.starts_with("msl") && b.altitude_datum.contains("EGM96"));
    assert_eq!(s.geoid_model_heights, 9);
}

#[test]
fn twist_stamped_is_a_speed_in_the_body_frame_and_a_velocity_in_a_world_frame() {
    let mut msgs: Vec<Msg1> = drive()
        .into_iter()
        .filter(|m| m.topic != "/odom" && m.topic != "/fix_velocity")
        .collect();
    let fixes: Vec<i64> = (0..10)
        .map(|s| T0_NS + (s * 100 + 50) * 10_000_000)
        .collect();
    for &t in &fixes {
        msgs.push(Msg1 {
            topic: "/cmd_vel_stamped",
            ty: TWIST,
            log_ns: t + LAG_NS,
            data: twist_msg(t, "base_link", [1.5, 0.0, 0.0]),
        });
        msgs.push(Msg1 {
            topic: "/gps/vel",
            ty: TWIST,
            log_ns: t + LAG_NS,
            data: twist_msg(t, "odom", [0.5, 1.1, -0.1]),
        });
    }
    msgs.sort_by_key(|m| m.log_ns);
    let (s, out) = run(&write_bag1(&msgs, Compression::Lz4, 4096), "twist");
    let s = s.unwrap();
    let sp = rows(&out.join("speed.txt"));
    assert_eq!(sp.len(), 10);
    let notes = messages(&s);
    assert!(sp.iter().all(|r| r[1] == 1.5));
    let b = s.ros1.unwrap();
    assert!(b.speed.unwrap().source.contains("body frame"));
    assert!(
        notes
            .iter()
            .any(|l| l.contains("9 of 9 fixes have a velocity") && l.contains("0 of them")),
        "{notes:?}"
    );
    // A TwistStamped velocity has no covariance: the fixes keep positions
    // only (KF-GINS velocity columns need a σ), and that is said (above).
    let role = b.topics.iter().find(|t| t.topic == "/gps/vel").unwrap();
    assert_eq!(role.role.as_deref(), Some("velocity"));
    assert_eq!(rows(&out.join("gnss.txt"))[0].len(), 7);
}

#[test]
fn the_real_husky_bag() {
    let bag = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-logs/husky-ros1-bag/test1.bag");
    let out = tmp("husky").at("out");
    let s = convert_with_topics(
        InputFormat::Ros1Bag,
        &bag,
        &out,
        &ConvertOptions::default(),
        &TopicChoice::default(),
    )
    .unwrap();
    assert!(s.diagnostics.is_empty(), "{:?}", messages(&s));
    let b = s.ros1.as_ref().unwrap();
    let count = |t: &str| b.topics.iter().find(|x| x.topic == t).unwrap().messages;
    assert_eq!(count("/imu/data"), 11_865);
    assert_eq!(count("/fix"), 989);
    assert_eq!(count("/husky_velocity_controller/odom"), 3_952);
    assert_eq!(s.gnss_fixes, 989);
    assert_eq!(s.imu_samples, 11_864);
    assert_eq!(s.speeds, 3_952);
    // Unix 1432235498 s (2015-05-21, GPS − UTC = 16 s): week 1845,
    // 414 714 s; 395.3 s long.
    let gnss = rows(&out.join("gnss.txt"));
    let imu = rows(&out.join("imu.txt"));
    assert!(
        (414_714.0..414_715.0).contains(&gnss[0][0]),
        "{}",
        gnss[0][0]
    );
    let span = imu[imu.len() - 1][0] - imu[0][0];
    assert!((span - 395.3).abs() < 0.5, "{span}");
    // σ from the diagonal covariance: 0.8–1.7 m horizontal (median
    // 0.8–0.9 m), the vertical twice that.
    let mut h: Vec<f64> = gnss.iter().map(|r| r[4]).collect();
    h.sort_by(f64::total_cmp);
    assert!((0.8..=0.9).contains(&h[h.len() / 2]), "{}", h[h.len() / 2]);
    assert!(
        gnss.iter().all(|r| r[4] == r[5]
            && (r[6] - 2.0 * r[4]).abs() < 1e-9
            && (0.7..1.8).contains(&r[4]))
    );
    // At rest the accelerometer reads about (−0.22, 9.79, 0.08) FLU: y up,
    // so the FRD y column holds −g·dt (median over the first 10 s).
    let mut ay: Vec<f64> = imu[1..300]
        .iter()
        .zip(&imu[..299])
        .map(|(r, p)| r[5] / (r[0] - p[0]))
        .collect();
    ay.sort_by(f64::total_cmp);
    assert!((ay[ay.len() / 2] + 9.8).abs() < 0.1, "{}", ay[ay.len() / 2]);
    let sp = rows(&out.join("speed.txt"));
    assert!(sp.iter().all(|r| r[1] > -0.05 && r[1] < 1.8));
}

/// The file offsets of a bag's chunk records.
fn chunk_offsets(bag: &[u8]) -> Vec<usize> {
    let mut v = Vec::new();
    let mut pos = 13;
    while pos + 4 <= bag.len() {
        let hl = u32::from_le_bytes(bag[pos..pos + 4].try_into().unwrap()) as usize;
        let h = &bag[pos + 4..pos + 4 + hl];
        let dl = u32::from_le_bytes(bag[pos + 4 + hl..pos + 8 + hl].try_into().unwrap()) as usize;
        if h.windows(4).any(|w| w == b"op=\x05") {
            v.push(pos);
        }
        pos += 8 + hl + dl;
    }
    v
}

#[test]
fn truncated_bag_keeps_the_whole_records_and_says_it_was_cut() {
    let bag = write_bag1(&drive(), Compression::Bz2, 4096);
    let (full, full_out) = run(&bag, "whole");
    full.unwrap();
    let whole = rows(&full_out.join("imu.txt"));
    let cut = &bag[..bag.len() * 3 / 5];
    let (s, out) = run(cut, "cut");
    let s = s.unwrap();
    let why = s.ros1.as_ref().unwrap().stopped_early.clone().unwrap();
    assert!(why.contains("cut"), "{why}");
    assert!(
        messages(&s)
            .iter()
            .any(|m| m.contains("drive.bag") && m.contains("cut")),
        "{:?}",
        messages(&s)
    );
    let part = rows(&out.join("imu.txt"));
    assert!(
        part.len() > 100 && part.len() < whole.len(),
        "{}",
        part.len()
    );
    assert_eq!(part[..], whole[..part.len()], "what was read is unchanged");
    // Cut inside the bag header: nothing to read, an error naming the file.
    let (e, _) = run(&bag[..40], "stub");
    let e = e.unwrap_err();
    assert!(e.contains("drive.bag") && e.contains("cut"), "{e}");
    let (e, _) = run(b"#ROSBAG V1.2\nold", "v1");
    assert!(e.unwrap_err().contains("format 1.x"));
    let (e, _) = run(b"not a bag", "text");
    assert!(e.unwrap_err().contains("not a ROS 1 bag"));
}

#[test]
fn a_corrupt_chunk_is_reported_and_skipped() {
    // bz2 (CRC) and lz4 (frame checksum) detect damage; an uncompressed
    // ROS 1 chunk has no checksum, so damaged values there cannot be seen.
    for c in [Compression::Bz2, Compression::Lz4] {
        let mut bag = write_bag1(&drive(), c, 4096);
        let chunks = chunk_offsets(&bag);
        assert!(chunks.len() > 5);
        // Garble the middle of the third chunk's data.
        let at = chunks[2] + (chunks[3] - chunks[2]) / 2;
        for b in &mut bag[at..at + 40] {
            *b ^= 0x5a;
        }
        let (s, out) = run(&bag, c.name());
        let s = s.unwrap();
        let m = messages(&s);
        assert!(
            m.iter()
                .any(|l| l.contains("drive.bag")
                    && l.contains(&format!("chunk at byte {}", chunks[2]))),
            "{}: {m:?}",
            c.name()
        );
        let n = rows(&out.join("imu.txt")).len();
        assert!(n > 500 && n < 1000, "{}: {n}", c.name());
    }
}

#[test]
fn an_unknown_layout_of_a_known_type_skips_its_topic() {
    let mut msgs = drive();
    for m in msgs.iter_mut().filter(|m| m.topic == "/odom") {
        m.ty = (ODOM.0, "0123456789abcdef0123456789abcdef");
    }
    // And IMU messages one byte too long: each reported and skipped.
    for m in msgs.iter_mut().filter(|m| m.topic == "/imu/data").take(3) {
        m.data.push(0);
    }
    let (s, out) = run(&write_bag1(&msgs, Compression::None, 4096), "layout");
    let s = s.unwrap();
    let m = messages(&s);
    assert!(
        m.iter()
            .any(|l| l.contains("/odom") && l.contains("md5sum 0123")),
        "{m:?}"
    );
    assert_eq!(
        m.iter().filter(|l| l.contains("1 bytes left")).count(),
        3,
        "{m:?}"
    );
    assert!(!out.join("speed.txt").exists());
    let b = s.ros1.unwrap();
    let odom = b.topics.iter().find(|t| t.topic == "/odom").unwrap();
    assert!(odom.role.is_none() && odom.note.as_deref().unwrap().contains("another layout"));
    assert_eq!(rows(&out.join("imu.txt")).len(), 1001 - 3 - 1);
    // Asked for by name, it is an error that says why.
    let choice = TopicChoice {
        odom: Some("/odom".into()),
        ..Default::default()
    };
    let (e, _) = run_with(
        &write_bag1(&msgs, Compression::None, 4096),
        "layout-named",
        &choice,
        &ConvertOptions::default(),
    );
    assert!(e.unwrap_err().contains("another layout"));
}

#[test]
fn bags_with_only_imu_or_only_fixes() {
    let imu_only: Vec<Msg1> = drive()
        .into_iter()
        .filter(|m| m.topic == "/imu/data")
        .collect();
    let (s, out) = run(&write_bag1(&imu_only, Compression::Lz4, 4096), "imu-only");
    let s = s.unwrap();
    assert_eq!((s.gnss_fixes, s.imu_samples), (0, 1000));
    assert!(!out.join("gnss.txt").exists());
    // An IMU log, not a failed receiver log.
    assert_eq!(s.no_fix_message(), None);
    let fix_only: Vec<Msg1> = drive().into_iter().filter(|m| m.topic == "/fix").collect();
    let (s, out) = run(&write_bag1(&fix_only, Compression::Bz2, 4096), "fix-only");
    let s = s.unwrap();
    assert_eq!((s.gnss_fixes, s.imu_samples), (9, 0));
    assert!(!out.join("imu.txt").exists());
    // Neither: an error listing what the bag holds.
    let other: Vec<Msg1> = drive()
        .into_iter()
        .filter(|m| m.topic == "/rosout")
        .collect();
    let (e, _) = run(&write_bag1(&other, Compression::None, 4096), "neither");
    let e = e.unwrap_err();
    assert!(e.contains("/rosout (rosgraph_msgs/Log"), "{e}");
}

#[test]
fn the_largest_imu_topic_is_chosen() {
    let mut msgs = drive();
    for k in 0..10 {
        let t = T0_NS + k * 1_000_000_000;
        msgs.push(Msg1 {
            topic: "/imu/slow",
            ty: IMU,
            log_ns: t,
            data: imu_msg(t, [0.0; 3], [0.0, 0.0, G]),
        });
    }
    msgs.sort_by_key(|m| m.log_ns);
    let (s, out) = run(&write_bag1(&msgs, Compression::Bz2, 4096), "two-imus");
    let s = s.unwrap();
    assert_eq!(rows(&out.join("imu.txt")).len(), 1000);
    let slow = s.ros1.unwrap();
    let slow = slow.topics.iter().find(|t| t.topic == "/imu/slow").unwrap();
    assert!(slow.role.is_none() && slow.note.as_deref().unwrap().contains("--imu-topic"));
}
