//! The live loop on pseudo-terminals at real rate (a few seconds each):
//! no sample lost, a solution, holdover when PPS is removed and relock when
//! it returns; NMEA fixes; an unplugged IMU reopened; missing devices.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use navsync::fusion::NavOutput;
use navsync::testfiles::TestDir;
use navsync::timing::LockState;
use navsync_live::live::{NavInfo, SourceId};
use navsync_live::replay::GnssKind;
use navsync_live::selftest::{self, SelftestConfig, builtin_fusion};
use navsync_live::{LiveConfig, LiveSink, LiveStatus, PortConfig, PpsInput};

/// A directory of this test, removed when it passes.
fn tmp(name: &str) -> TestDir {
    TestDir::new(&format!("live-{name}"))
}

#[test]
fn ubx_with_a_pps_gap_loses_nothing_holds_over_and_relocks() {
    // Lock needs 4 pulses; PPS removed from 5 s to 8 s; relock at the
    // second pulse back.
    let mut cfg = SelftestConfig::new(10.5, 5.2, 3.0);
    cfg.replay.imu_garbage_every = Some(400);
    let dir = tmp("ubx");
    cfg.output = Some(dir.join("out"));
    let r = selftest::run(&cfg, &dir).unwrap();
    // The solution at IMU rate in KF-GINS files.
    let nav = std::fs::read_to_string(dir.join("out/navresult.nav")).unwrap();
    let rows: Vec<&str> = nav.lines().collect();
    assert_eq!(rows.len() as u64, r.solutions);
    assert!(
        rows.iter().all(|l| l.split_whitespace().count() == 11),
        "{}",
        rows[0]
    );
    assert!(rows[0].starts_with("2400 "), "{}", rows[0]);
    let std_lines = std::fs::read_to_string(dir.join("out/std.txt")).unwrap();
    assert!((4..=8).contains(&std_lines.lines().count()), "{std_lines}");
    let c = &r.live.counts;
    assert!(r.imu_written >= 2090, "{r:#?}");
    assert_eq!(r.imu_received, r.imu_written, "{:#?}", r.live.first_notes);
    assert_eq!(r.samples_lost, 0, "{:#?}", r.live.counts);
    assert_eq!(c.imu_bad_lines, r.imu_written / 400);
    assert!(r.solutions > r.imu_written / 3, "{}", r.solutions);
    assert!(c.gnss_fused >= 50, "{c:?}");
    assert_eq!(r.holdover_at_s.len(), 1, "{:?}", r.live.state_changes);
    // Holdover 1.5 s after the last pulse (5 s), relock at the second
    // pulse back (9 s) or the one after.
    assert!(
        (6.0..7.5).contains(&r.holdover_at_s[0]),
        "{:?}",
        r.holdover_at_s
    );
    let relock = r.relocked_at_s.last().copied().unwrap_or(0.0);
    assert!((8.5..10.5).contains(&relock), "{:?}", r.live.state_changes);
    assert!(
        r.stamp_errors.holdover_compared > 100,
        "{:?}",
        r.stamp_errors
    );
    // PTY arrival jitter is removed by the envelope: stamps within 0.5 ms.
    assert!(r.stamp_errors.max_abs_us < 500.0, "{:?}", r.stamp_errors);
    assert!(r.max_pos_error_m < 5.0, "{}", r.max_pos_error_m);
    let sync = r.live.sync.as_ref().unwrap();
    assert_eq!(sync.holdover.len(), 1);
    assert!(
        r.latency_median_us.unwrap() < 5_000.0,
        "{:?}",
        r.latency_median_us
    );
}

#[test]
fn nmea_fixes_and_an_unplugged_imu_port() {
    let mut cfg = SelftestConfig::new(8.0, 0.0, 0.0);
    cfg.replay.gnss = GnssKind::Nmea;
    cfg.replay.imu_unplug = Some((5.2, 1.0));
    let dir = tmp("nmea");
    let r = selftest::run(&cfg, &dir).unwrap();
    let c = &r.live.counts;
    assert!(c.reopens >= 1, "{:#?}", r.live.first_notes);
    assert!(
        r.live.first_notes.iter().any(|n| n.contains("device gone")),
        "{:#?}",
        r.live.first_notes
    );
    // Every line written was received and stamped; the unplugged second
    // shows as a gap the engine reports.
    assert_eq!(r.imu_received, r.imu_written);
    assert_eq!(c.imu_stamped, r.imu_written);
    assert!((150..=260).contains(&c.imu_lost), "{c:?}");
    assert!(c.gnss_fused >= 25, "{c:?}");
    assert!(r.solutions > 250, "{}", r.solutions);
    assert!(r.max_pos_error_m < 5.0, "{}", r.max_pos_error_m);
}

#[test]
fn esf_raw_imu_on_the_receiver_port() {
    let mut cfg = SelftestConfig::new(7.0, 0.0, 0.0);
    cfg.replay.imu_esf = true;
    let dir = tmp("esf");
    let r = selftest::run(&cfg, &dir).unwrap();
    let c = &r.live.counts;
    // The replay writes 5 samples a message; the last message may still
    // be in flight: at most one message short.
    assert!(r.imu_written >= 1395, "{r:#?}");
    assert!(
        c.imu_stamped + 5 >= r.imu_written,
        "{c:?} of {}",
        r.imu_written
    );
    assert_eq!(c.imu_lost, 0, "{c:?}");
    assert!(r.solutions > 250, "{}", r.solutions);
    // Messages carry 25 ms of samples; the tags and the envelope put every
    // sample back on its own time.
    assert!(r.stamp_errors.max_abs_us < 500.0, "{:?}", r.stamp_errors);
    assert!(r.max_pos_error_m < 5.0, "{}", r.max_pos_error_m);
}

/// The self-test's filter facing `yaw_deg` (the truth faces north) with
/// yaw σ `yaw_sd_deg`, fusing a baseline at `mount_deg` in the body.
fn heading_fusion(
    cfg: &SelftestConfig,
    yaw_deg: f64,
    yaw_sd_deg: f64,
    mount_deg: f64,
) -> navsync::fusion::FusionConfig {
    let mut f = builtin_fusion(&cfg.replay);
    let n = &f.init_nav;
    f.init_nav = navsync::ins::NavState::new(
        n.time,
        n.pos,
        n.vel,
        &navsync::attitude::Euler::from_deg(0.0, 0.0, yaw_deg),
    );
    f.init_std.att.z = yaw_sd_deg.to_radians();
    f.heading = Some(navsync::fusion::HeadingOptions {
        dual_antenna_yaw_rad: mount_deg.to_radians(),
        dual_antenna_yaw_sd_rad: 0.5f64.to_radians(),
        aligned_from_baseline: false,
    });
    f
}

/// Every heading given to the filter is fused or rejected once (the last
/// may still wait for its IMU sample), through the delayed-state restores
/// of every fix.
fn assert_each_heading_counted_once(c: &navsync_live::live::LiveCounts) {
    let given = c.gnss_headings - c.headings_before_start - c.headings_stale;
    let done = c.headings_fused + c.headings_rejected;
    assert!(done <= given && done + 1 >= given, "{c:?}");
}

#[test]
fn dual_antenna_headings_correct_the_yaw_live() {
    // A standing MEMS IMU cannot find its heading in 8 s (Earth rate is
    // far below its bias): the yaw that starts 6° off comes right only
    // through the NAV-RELPOSNED headings (baseline 30° right of forward).
    let mut cfg = SelftestConfig::new(9.0, 0.0, 0.0);
    cfg.replay.dual_antenna = Some((30.0, 0.3));
    cfg.fusion = Some(heading_fusion(&cfg, 6.0, 10.0, 30.0));
    let dir = tmp("relposned");
    cfg.record = Some(dir.join("rig.csv"));
    let r = selftest::run(&cfg, &dir).unwrap();
    let c = &r.live.counts;
    // The recording keeps every heading on its GPS time, and `sync` puts
    // them in heading.txt beside gnss.txt.
    assert_eq!(r.live.recorded.as_ref().unwrap().headings, c.gnss_headings);
    let synced = navsync::timing::file::sync_file(
        &dir.join("rig.csv"),
        &dir.join("sync"),
        navsync::timing::SyncConfig::default(),
        None,
        None,
    )
    .unwrap();
    assert_eq!(synced.report.records.headings, c.gnss_headings);
    let mut diag = navsync::error::Diagnostics::default();
    let headings =
        navsync::io::heading::read_headings(&dir.join("sync/heading.txt"), 2400, &mut diag)
            .unwrap();
    assert_eq!(headings.len() as u64, c.gnss_headings, "{diag:?}");
    assert!(
        headings
            .iter()
            .all(|h| (h.heading_rad.to_degrees() - 30.0).abs() < 2.0
                && h.time.ns() % 100_000_000 == 0),
        "{:?}",
        &headings[..3]
    );
    // The fusion starts when the clock locks (4 pulses); from then on the
    // heading of every fused fix's epoch is fused too.
    assert!(c.gnss_headings >= 80, "{c:?}");
    assert!(c.gnss_fused >= 35, "{c:?}");
    assert!(
        c.headings_fused + 2 >= c.gnss_fused,
        "{c:?} {:#?}",
        r.live.first_notes
    );
    assert_eq!(c.headings_stale, 0, "{c:?}");
    assert_each_heading_counted_once(c);
    let yaw = r.final_att_deg.unwrap()[2];
    eprintln!(
        "FINAL yaw {yaw} sd {:?} {:?}",
        r.final_yaw_sd_deg, r.live.counts
    );
    assert!(yaw.abs() < 0.5, "yaw {yaw}° (started at 6°)");
    let sd = r.final_yaw_sd_deg.unwrap();
    assert!(sd < 1.0, "yaw σ {sd}°");
}

#[test]
fn hdt_headings_give_the_initial_yaw_when_it_is_unknown() {
    // The configuration's yaw is unknown (σ 180°, value 100° off): the
    // first HDT heading (baseline 90° right of forward) gives it.
    let mut cfg = SelftestConfig::new(7.0, 0.0, 0.0);
    cfg.replay.gnss = GnssKind::Nmea;
    cfg.replay.dual_antenna = Some((90.0, 0.3));
    cfg.hdt_sd_deg = 0.4;
    cfg.fusion = Some(heading_fusion(&cfg, 100.0, 180.0, 90.0));
    let dir = tmp("hdt");
    let r = selftest::run(&cfg, &dir).unwrap();
    let c = &r.live.counts;
    assert!(
        r.live
            .first_notes
            .iter()
            .any(|n| n.contains("from the dual-antenna baseline")),
        "{:#?}",
        r.live.first_notes
    );
    assert!(c.headings_fused >= 20, "{c:?}");
    assert!(c.headings_before_start >= 10, "{c:?}");
    assert_each_heading_counted_once(c);
    let yaw = r.final_att_deg.unwrap()[2];
    eprintln!(
        "FINAL yaw {yaw} sd {:?} {:?}",
        r.final_yaw_sd_deg, r.live.counts
    );
    assert!(yaw.abs() < 0.5, "yaw {yaw}°");
    let sd = r.final_yaw_sd_deg.unwrap();
    assert!(sd < 1.0, "yaw σ {sd}°");
    // A σ of HDT headings that is no σ is refused before anything opens.
    let mut lc = LiveConfig::new(
        PortConfig {
            path: dir.join("none"),
            baud: 115200,
        },
        Some(PortConfig {
            path: dir.join("none-imu"),
            baud: 115200,
        }),
        PpsInput::None,
        builtin_fusion(&cfg.replay),
    );
    lc.hdt_sd_deg = f64::NAN;
    let e = navsync_live::run(lc, &AtomicBool::new(false), &mut Collect::default()).unwrap_err();
    assert!(e.to_string().contains("--hdt-sd"), "{e}");
}

#[derive(Default)]
struct Collect {
    notes: Vec<String>,
    statuses: Vec<LiveStatus>,
}

impl LiveSink for Collect {
    fn nav(&mut self, _: &NavOutput, _: &NavInfo) -> Result<(), navsync::Error> {
        Ok(())
    }
    fn status(&mut self, s: &LiveStatus) {
        self.statuses.push(s.clone());
    }
    fn note(&mut self, source: SourceId, msg: &str) {
        self.notes.push(format!("{source}: {msg}"));
    }
}

#[test]
fn missing_devices_are_reported_and_retried_and_bad_bauds_refused() {
    let fusion = builtin_fusion(&Default::default());
    let port = |p: &str| PortConfig {
        path: PathBuf::from(p),
        baud: 115200,
    };
    let mut cfg = LiveConfig::new(
        port("/dev/navsync-no-gnss"),
        Some(port("/dev/navsync-no-imu")),
        PpsInput::Kernel(PathBuf::from("/dev/navsync-no-pps")),
        fusion.clone(),
    );
    cfg.duration = Some(Duration::from_millis(1200));
    cfg.reopen_interval = Duration::from_millis(300);
    cfg.status_interval = Duration::from_millis(500);
    let mut sink = Collect::default();
    let stop = AtomicBool::new(false);
    let r = navsync_live::run(cfg, &stop, &mut sink).unwrap();
    for what in [
        "imu: /dev/navsync-no-imu",
        "gnss: /dev/navsync-no-gnss",
        "pps: /dev/navsync-no-pps",
    ] {
        assert!(
            sink.notes
                .iter()
                .any(|n| n.starts_with(what) && n.contains("cannot open")),
            "{what}: {:#?}",
            sink.notes
        );
    }
    // Reported once per outage, not at every retry.
    assert_eq!(sink.notes.len(), 3, "{:#?}", sink.notes);
    assert!(!sink.statuses.is_empty());
    assert!(
        sink.statuses
            .iter()
            .all(|s| !s.imu_up && s.state == LockState::Acquiring)
    );
    assert_eq!(r.counts.solutions, 0);

    let mut bad = LiveConfig::new(
        port("/dev/null"),
        Some(port("/dev/null")),
        PpsInput::None,
        fusion.clone(),
    );
    if let Some(p) = bad.imu.as_mut() {
        p.baud = 12345;
    }
    let e = navsync_live::run(bad, &stop, &mut sink)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("--imu-baud") && e.contains("12345"), "{e}");
    let none = LiveConfig::new(port("/dev/null"), None, PpsInput::None, fusion);
    let e = navsync_live::run(none, &stop, &mut sink)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("no IMU"), "{e}");
}
