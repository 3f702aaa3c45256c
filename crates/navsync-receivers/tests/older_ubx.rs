//! Issue 17 (receivers): older u-blox epochs (NAV-SOL + NAV-POSLLH +
//! NAV-VELNED + NAV-STATUS by iTOW), NAV-HPPOSLLH, RTCM3 frames skipped,
//! every dropped epoch counted by reason, and the EGM96 geoid height for
//! GGA without a separation. Streams are built from real-shaped frames
//! (checksums right) and the shared gpsd logs (`../shared/data/gpsd-ublox`
//! from the repository root; BSD-2-Clause, see its README).

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use navsync::earth::{Geodetic, c_ne, geodetic_to_ecef, ned_offset};
use navsync::testfiles::TestDir;
use navsync::time::GpsTime;
use navsync_receivers::convert::{ConvertOptions, ConvertSummary, InputFormat, convert};
use navsync_receivers::fixes::{
    DropReason, FixOptions, TimeContext, UbxEpochs, UbxFixSource, UbxOutcome,
};
use navsync_receivers::geoid::Egm96Grid;
use navsync_receivers::nmea::encode_sentence;
use navsync_receivers::stream::{EventKind, gpsd_log_header_len, read_all};
use navsync_receivers::ubx::*;

/// A directory of this test, removed when it passes.
fn tmp(name: &str) -> TestDir {
    TestDir::new(&format!("rx17-{name}"))
}

fn shared_log(name: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/gpsd-ublox")
        .join(name);
    assert!(
        p.exists(),
        "{} missing: the shared data folder sits beside the repository",
        p.display()
    );
    p
}

/// The conversion and its output directory (removed with the test's
/// directory when dropped).
fn run(name: &str, bytes: &[u8], opts: &ConvertOptions) -> (ConvertSummary, TestDir) {
    let out = tmp(name).at("out");
    let input = out.root().join("in.log");
    std::fs::write(&input, bytes).unwrap();
    (convert(InputFormat::Ubx, &input, &out, opts).unwrap(), out)
}

const WEEK: i16 = 2300;
const LAT: f64 = 44.068_809_6;
const LON: f64 = -121.314_309_2;
const H: f64 = 1110.675;

fn frame(m: UbxMessage) -> Vec<u8> {
    m.to_frame().unwrap()
}

fn sol(itow_ms: u32, gps_fix: u8, flags: u8, pos: &Geodetic, vel_ned: Vector3<f64>) -> NavSol {
    let mut s = NavSol::decode(&[0; 52]).unwrap();
    s.itow_ms = itow_ms;
    s.ftow_ns = 4363;
    s.week = WEEK;
    s.gps_fix = gps_fix;
    s.flags = flags;
    let r = geodetic_to_ecef(pos);
    s.ecef_cm = [r.x, r.y, r.z].map(|v| (v * 100.0).round() as i32);
    s.p_acc_cm = 250;
    let v = c_ne(pos) * vel_ned;
    s.ecef_vel_cm_s = [v.x, v.y, v.z].map(|v| (v * 100.0).round() as i32);
    s.s_acc_cm_s = 20;
    s.num_sv = 9;
    s
}

fn posllh(itow_ms: u32) -> NavPosLlh {
    NavPosLlh {
        itow_ms,
        lon_e7: (LON * 1e7).round() as i32,
        lat_e7: (LAT * 1e7).round() as i32,
        height_mm: (H * 1e3).round() as i32,
        h_msl_mm: ((H + 21.35) * 1e3).round() as i32,
        h_acc_mm: 1200,
        v_acc_mm: 2500,
    }
}

fn velned(itow_ms: u32) -> NavVelNed {
    NavVelNed {
        itow_ms,
        vel_ned_cm_s: [100, -50, 20],
        speed_cm_s: 114,
        g_speed_cm_s: 112,
        heading_e5: 0,
        s_acc_cm_s: 30,
        c_acc_e5: 0,
    }
}

fn status(itow_ms: u32, gps_fix: u8, flags: u8) -> NavStatus {
    NavStatus {
        itow_ms,
        gps_fix,
        flags,
        fix_stat: 0,
        flags2: 0,
        ttff_ms: 30_000,
        msss_ms: 60_000,
    }
}

fn pvt(itow_ms: u32, fix_type: u8, flags: u8) -> NavPvt {
    let mut p = NavPvt::decode(&[0; 92]).unwrap();
    p.itow_ms = itow_ms;
    p.fix_type = fix_type;
    p.flags = flags;
    p.lat_e7 = (LAT * 1e7).round() as i32;
    p.lon_e7 = (LON * 1e7).round() as i32;
    p.height_mm = (H * 1e3).round() as i32;
    p.h_acc_mm = 800;
    p.v_acc_mm = 1500;
    p.s_acc_mm_s = 90;
    p
}

fn timegps(itow_ms: u32) -> NavTimeGps {
    NavTimeGps {
        itow_ms,
        ftow_ns: -1000,
        week: WEEK,
        leap_s: 18,
        valid: 7,
        t_acc_ns: 20,
    }
}

fn epochs(msgs: &[UbxMessage], opts: FixOptions) -> Vec<UbxOutcome> {
    let mut e = UbxEpochs::new(opts);
    let mut ctx = TimeContext::default();
    let mut out = Vec::new();
    for m in msgs {
        e.push(m, &ctx, &mut out);
        if let UbxMessage::NavTimeGps(t) = m {
            ctx.push_timegps(t);
        }
    }
    e.finish(&ctx, &mut out);
    out
}

#[test]
fn nav_sol_posllh_velned_status_of_one_itow_make_one_fix() {
    let pos = Geodetic::from_deg(LAT, LON, H);
    let v = Vector3::new(1.0, -0.5, 0.2);
    let itow = 420_964_000;
    let out = epochs(
        &[
            UbxMessage::NavSol(sol(itow, 3, 0x0D, &pos, v)),
            UbxMessage::NavPosLlh(posllh(itow)),
            UbxMessage::NavVelNed(velned(itow)),
            UbxMessage::NavStatus(status(itow, 3, 0x0D)),
        ],
        FixOptions::default(),
    );
    assert_eq!(out.len(), 1);
    let UbxOutcome::Fix {
        fix,
        source,
        high_precision,
    } = &out[0]
    else {
        panic!("{out:?}")
    };
    assert_eq!((*source, *high_precision), (UbxFixSource::Combined, false));
    // Epoch = NAV-SOL week + iTOW + fTOW.
    assert_eq!(
        fix.fix.time,
        GpsTime::from_week_ns(WEEK as i64, itow as i64 * 1_000_000 + 4363)
    );
    // Position exactly NAV-POSLLH's, with hAcc, hAcc, vAcc.
    assert!((fix.fix.pos.lat_rad.to_degrees() - LAT).abs() < 1e-12);
    assert!((fix.fix.pos.lon_rad.to_degrees() - LON).abs() < 1e-12);
    assert!((fix.fix.pos.h_m - H).abs() < 1e-9);
    assert_eq!(fix.fix.pos_sd, Vector3::new(1.2, 1.2, 2.5));
    // Velocity NAV-VELNED's (cm/s) with sAcc.
    assert_eq!(fix.fix.vel, Some(Vector3::new(1.0, -0.5, 0.2)));
    assert_eq!(fix.fix.vel_sd, Some(Vector3::new(0.3, 0.3, 0.3)));
}

#[test]
fn nav_sol_alone_gives_its_ecef_solution_in_geodetic_and_ned() {
    let pos = Geodetic::from_deg(LAT, LON, H);
    let v = Vector3::new(3.0, 4.0, -0.5);
    let out = epochs(
        &[UbxMessage::NavSol(sol(1000, 3, 0x0D, &pos, v))],
        FixOptions::default(),
    );
    let UbxOutcome::Fix { fix, .. } = &out[0] else {
        panic!("{out:?}")
    };
    // ECEF to the cm: the position is back within 1 cm, the velocity
    // within 1 cm/s per axis.
    assert!(ned_offset(&pos, &fix.fix.pos).norm() < 0.01);
    let dv = fix.fix.vel.unwrap() - v;
    assert!(dv.amax() < 0.01, "{dv}");
    assert_eq!(fix.fix.pos_sd, Vector3::new(2.5, 2.5, 2.5)); // pAcc
    assert_eq!(fix.fix.vel_sd, Some(Vector3::new(0.2, 0.2, 0.2)));
}

#[test]
fn without_a_nav_sol_week_the_time_comes_from_nav_timegps() {
    let itow = 5_000;
    let out = epochs(
        &[
            UbxMessage::NavPosLlh(posllh(itow)),
            UbxMessage::NavStatus(status(itow, 3, 0x0D)),
            UbxMessage::NavTimeGps(timegps(itow)),
            // Another epoch with no week known at all: NoTime.
        ],
        FixOptions::default(),
    );
    let UbxOutcome::Fix { fix, .. } = &out[0] else {
        panic!("{out:?}")
    };
    assert_eq!(
        fix.fix.time,
        GpsTime::from_week_ns(WEEK as i64, itow as i64 * 1_000_000 - 1000)
    );
    assert_eq!(fix.fix.vel, None);
    let out = epochs(
        &[
            UbxMessage::NavPosLlh(posllh(itow)),
            UbxMessage::NavStatus(status(itow, 3, 0x01)),
        ],
        FixOptions::default(),
    );
    assert!(matches!(
        &out[0],
        UbxOutcome::Dropped { reason: DropReason::NoTime, detail: Some(d), .. } if d.contains("5000 ms")
    ));
}

#[test]
fn nav_hpposllh_refines_the_nav_pvt_position() {
    let itow = 7_000;
    let mut p = pvt(itow, 3, 0x01);
    p.valid = 0; // week from NAV-TIMEGPS
    let hp = NavHpPosLlh {
        version: 0,
        reserved1: [0; 2],
        flags: 0,
        itow_ms: itow,
        lon_e7: p.lon_e7,
        lat_e7: p.lat_e7,
        height_mm: p.height_mm,
        h_msl_mm: p.height_mm + 21_350,
        lon_hp_e9: -37,
        lat_hp_e9: 42,
        height_hp_e4: 7,
        h_msl_hp_e4: 7,
        h_acc_e4: 143,
        v_acc_e4: 211,
    };
    let msgs = [
        UbxMessage::NavTimeGps(timegps(itow)),
        UbxMessage::NavPvt(p.clone()),
        UbxMessage::NavHpPosLlh(hp.clone()),
    ];
    let out = epochs(&msgs, FixOptions::default());
    let UbxOutcome::Fix {
        fix,
        source,
        high_precision,
    } = &out[0]
    else {
        panic!("{out:?}")
    };
    assert_eq!((*source, *high_precision), (UbxFixSource::NavPvt, true));
    let lat = p.lat_e7 as f64 * 1e-7 + 42e-9;
    assert!((fix.fix.pos.lat_rad.to_degrees() - lat).abs() < 1e-13);
    assert!((fix.fix.pos.lon_rad.to_degrees() - (p.lon_e7 as f64 * 1e-7 - 37e-9)).abs() < 1e-13);
    assert!((fix.fix.pos.h_m - (H + 0.0007)).abs() < 1e-9);
    assert!((fix.fix.pos_sd.x - 0.0143).abs() < 1e-12 && (fix.fix.pos_sd.z - 0.0211).abs() < 1e-12);
    // A NAV-HPPOSLLH flagged invalidLlh is not used.
    let mut bad = hp;
    bad.flags = 1;
    let out = epochs(
        &[
            msgs[0].clone(),
            msgs[1].clone(),
            UbxMessage::NavHpPosLlh(bad),
        ],
        FixOptions::default(),
    );
    assert!(matches!(
        &out[0],
        UbxOutcome::Fix { high_precision: false, fix, .. } if (fix.fix.pos.h_m - H).abs() < 1e-9
    ));
}

/// NAV-TIMEGPS + NAV-PVT epochs: 3 good, 4 gnssFixOK = 0, 2 fix type 2,
/// 1 time only; then 2 older epochs without NAV-PVT: a NAV-POSLLH alone
/// and a NAV-SOL without fix.
fn mixed_drop_stream() -> Vec<u8> {
    let mut s = b"# generated\n".to_vec();
    let kinds = [
        (3, 1),
        (3, 0),
        (2, 1),
        (3, 1),
        (3, 0),
        (5, 1),
        (3, 0),
        (2, 0),
        (3, 1),
        (3, 0),
    ];
    for (k, (fix_type, flags)) in kinds.into_iter().enumerate() {
        let itow = 100_000_000 + 1000 * k as u32;
        s.extend(frame(UbxMessage::NavTimeGps(timegps(itow))));
        let mut p = pvt(itow, fix_type, flags);
        p.valid = 0;
        s.extend(frame(UbxMessage::NavPvt(p)));
    }
    let pos = Geodetic::from_deg(LAT, LON, H);
    s.extend(frame(UbxMessage::NavPosLlh(posllh(100_010_000))));
    s.extend(frame(UbxMessage::NavSol(sol(
        100_011_000,
        0,
        0x0C,
        &pos,
        Vector3::zeros(),
    ))));
    s
}

#[test]
fn every_dropped_epoch_is_counted_by_reason_with_the_option_that_keeps_it() {
    let (s, out) = run("drops", &mixed_drop_stream(), &ConvertOptions::default());
    assert_eq!(s.gnss_fixes, 3);
    assert_eq!(s.gnss_source, "UBX NAV-PVT");
    let pvt = &s.fix_epochs[0];
    assert_eq!(
        (pvt.source.as_str(), pvt.epochs, pvt.fixes),
        ("UBX NAV-PVT", 10, 3)
    );
    let d: Vec<(&str, u64, Option<&str>)> = pvt
        .dropped
        .iter()
        .map(|d| (d.reason.as_str(), d.epochs, d.kept_by.as_deref()))
        .collect();
    assert_eq!(
        d,
        [
            ("fix type 2 (2D fix)", 2, Some("--keep-2d")),
            ("fix type 5 (time only)", 1, None),
            (
                "gnssFixOK = 0 (3D solution outside the receiver's DOP/accuracy masks)",
                4,
                Some("--keep-fix-not-ok")
            ),
        ]
    );
    let old = &s.fix_epochs[1];
    assert_eq!((old.epochs, old.fixes), (2, 0));
    assert_eq!(old.dropped[0].reason, "fix type 0 (no fix)");
    assert!(
        old.dropped[1]
            .reason
            .starts_with("position without NAV-SOL")
    );
    // summary.json carries the table.
    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(
        json.contains("\"kept_by\": \"--keep-fix-not-ok\""),
        "{json}"
    );
    assert!(s.no_fix_message().is_none());

    // The options keep what they say: 4 + 2 more (the 2D one with
    // gnssFixOK = 0 needs both).
    let mut o = ConvertOptions::default();
    o.fix.keep_fix_not_ok = true;
    let (s1, _) = run("keep1", &mixed_drop_stream(), &o);
    assert_eq!(s1.gnss_fixes, 7);
    o.fix.keep_2d = true;
    let (s2, _) = run("keep2", &mixed_drop_stream(), &o);
    assert_eq!(s2.gnss_fixes, 9);
}

#[test]
fn a_stream_without_a_fix_says_why() {
    let mut s = Vec::new();
    for k in 0..5u32 {
        let itow = 1000 * (k + 1);
        s.extend(frame(UbxMessage::NavTimeGps(timegps(itow))));
        s.extend(frame(UbxMessage::NavPvt(pvt(itow, 3, 0))));
    }
    let (sum, out) = run("nofix", &s, &ConvertOptions::default());
    assert_eq!(sum.gnss_fixes, 0);
    assert!(!out.join("gnss.txt").exists());
    let m = sum.no_fix_message().unwrap();
    assert!(m.contains("5 UBX NAV-PVT epochs: gnssFixOK = 0"), "{m}");
    assert!(m.contains("--keep-fix-not-ok"), "{m}");
    // A stream of no position message at all says that instead.
    let (sum, _) = run(
        "nopos",
        &frame(UbxMessage::NavTimeGps(timegps(1))),
        &ConvertOptions::default(),
    );
    assert!(
        sum.no_fix_message()
            .unwrap()
            .contains("no position message")
    );
}

/// RTCM 10403.x example message 1005 (reference station 2003; the frame
/// decoders reproduce in their tests), CRC-24Q 0x360B98.
const RTCM_1005: [u8; 25] = [
    0xD3, 0x00, 0x13, 0x3E, 0xD7, 0xD3, 0x02, 0x02, 0x98, 0x0E, 0xDE, 0xEF, 0x34, 0xB4, 0xBD, 0x62,
    0xAC, 0x09, 0x41, 0x98, 0x6F, 0x33, 0x36, 0x0B, 0x98,
];

#[test]
fn rtcm3_frames_on_an_f9_port_are_counted_and_skipped() {
    let mut s = Vec::new();
    for k in 0..3u32 {
        let itow = 1000 * (k + 1);
        s.extend(frame(UbxMessage::NavTimeGps(timegps(itow))));
        s.extend(frame(UbxMessage::NavPvt(pvt(itow, 3, 1))));
        s.extend(RTCM_1005);
        s.extend(navsync_receivers::rtcm3::encode_frame(&[0x43, 0x50, 0, 0, 0]).unwrap());
    }
    let (sum, _) = run("rtcm", &s, &ConvertOptions::default());
    let st = sum.stream.as_ref().unwrap();
    assert_eq!(
        (st.rtcm3_frames, st.corrupt_runs, st.corrupt_bytes),
        (6, 0, 0)
    );
    assert_eq!(sum.frames["RTCM3 1005 (not read)"], 3);
    assert_eq!(sum.frames["RTCM3 1077 (not read)"], 3);
    assert_eq!(sum.gnss_fixes, 3);
    assert!(sum.diagnostics.is_empty(), "{:?}", sum.diagnostics);
}

#[test]
fn shared_neo_m8t_log_gives_its_nav_sol_epochs_at_nav_timegps_time() {
    let path = shared_log("ublox-neo-m8t.log");
    let bytes = std::fs::read(&path).unwrap();
    let h = gpsd_log_header_len(&bytes);
    let (ev, _) = read_all(&bytes[h..], h as u64);
    let mut times = Vec::new();
    let mut sols = 0;
    for e in &ev {
        if let EventKind::Ubx(m) = &e.kind {
            // Real NAV-SOL frames re-encode bit for bit.
            let f = &bytes[e.offset as usize..e.offset as usize + e.len];
            assert_eq!(m.to_frame().unwrap(), f);
            match m {
                UbxMessage::NavTimeGps(t) => times.push(t.time_ns().unwrap()),
                UbxMessage::NavSol(_) => sols += 1,
                _ => {}
            }
        }
    }
    assert_eq!((sols, times.len()), (39, 39));
    let dir = tmp("m8t");
    let s = convert(InputFormat::Ubx, &path, &dir, &ConvertOptions::default()).unwrap();
    assert_eq!((s.gnss_fixes, s.gnss_columns), (39, 13));
    assert_eq!(s.gnss_source, "UBX NAV-SOL/POSLLH/VELNED/STATUS");
    // Each fix at its epoch: NAV-SOL week + iTOW + fTOW equals the
    // receiver's NAV-TIMEGPS of the same epoch to the ns.
    let text = std::fs::read_to_string(dir.join("gnss.txt")).unwrap();
    for (line, t) in text.lines().zip(&times) {
        let sow: f64 = line.split_whitespace().next().unwrap().parse().unwrap();
        let t = GpsTime::from_ns(*t);
        assert!((sow - t.sow()).abs() < 1.5e-9, "{sow} vs {}", t.sow());
    }
}

#[test]
fn shared_m8t_timing_log_is_time_only_and_says_so() {
    let dir = tmp("m8t-time");
    let s = convert(
        InputFormat::Ubx,
        &shared_log("u-blox-m8t-time.log"),
        &dir,
        &ConvertOptions::default(),
    )
    .unwrap();
    assert_eq!(s.gnss_fixes, 0);
    assert_eq!(s.fix_epochs[0].epochs, 151);
    assert_eq!(s.fix_epochs[0].dropped[0].reason, "fix type 5 (time only)");
    assert_eq!(s.pps, 152); // its PPS events are still written
    assert!(
        s.no_fix_message()
            .unwrap()
            .contains("151 UBX NAV-SOL/POSLLH/VELNED/STATUS epochs: fix type 5")
    );
}

/// The table: every shared gpsd log gives all its 3D epochs
/// (counted independently by scripts/ubx_fix_census.py).
#[test]
fn shared_gpsd_logs_give_every_3d_epoch() {
    for (name, format, fixes_3d) in [
        ("u-blox-m8t-time.log", InputFormat::Ubx, 0),
        ("ublox-f9p-hpnmea.log", InputFormat::Nmea, 9),
        ("ublox-neo-f9v.log", InputFormat::Ubx, 4),
        ("ublox-neo-m8l.log", InputFormat::Ubx, 19),
        ("ublox-neo-m8t.log", InputFormat::Ubx, 39),
    ] {
        let dir = tmp(name);
        let s = convert(format, &shared_log(name), &dir, &ConvertOptions::default()).unwrap();
        assert_eq!(s.gnss_fixes, fixes_3d, "{name}");
        let st = s.stream.unwrap();
        assert_eq!(st.rtcm3_frames, 0, "{name}");
    }
}

#[test]
fn gga_without_geoid_separation_gets_egm96() {
    // The F9P log's GGA say a separation of −21.350 m (the receiver's own
    // geoid model); drop that field as Quectel/Unicore/Ashtech/Telit do,
    // and the height becomes altitude + EGM96 N (−19.83 m at Bend, Oregon:
    // the two models differ by about 1.5 m there).
    let bytes = std::fs::read(shared_log("ublox-f9p-hpnmea.log")).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    let mut stripped = String::new();
    for line in text.split_inclusive('\n') {
        if line.starts_with("$GNGGA") {
            let body = &line[1..line.find('*').unwrap()];
            let mut f: Vec<&str> = body.split(',').collect();
            f[11] = "";
            stripped.push_str(&encode_sentence(&f.join(",")));
        } else {
            stripped.push_str(line);
        }
    }
    let dir = tmp("geoid");
    let orig_out = dir.join("orig");
    let a = convert(
        InputFormat::Nmea,
        &shared_log("ublox-f9p-hpnmea.log"),
        &orig_out,
        &ConvertOptions::default(),
    )
    .unwrap();
    assert_eq!((a.gnss_fixes, a.geoid_model_heights), (9, 0));
    assert!(a.geoid_model.is_none());
    let input = dir.join("no-sep.log");
    std::fs::write(&input, stripped).unwrap();
    let b_out = dir.join("model");
    let b = convert(
        InputFormat::Nmea,
        &input,
        &b_out,
        &ConvertOptions::default(),
    )
    .unwrap();
    assert_eq!((b.gnss_fixes, b.geoid_model_heights), (9, 9));
    assert!(b.geoid_model.as_ref().unwrap().starts_with("EGM96"));
    let json = std::fs::read_to_string(b_out.join("summary.json")).unwrap();
    assert!(json.contains("\"geoid_model_heights\": 9"));
    let cols = |p: &Path| -> Vec<[f64; 3]> {
        std::fs::read_to_string(p.join("gnss.txt"))
            .unwrap()
            .lines()
            .map(|l| {
                let f: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
                [f[1], f[2], f[3]]
            })
            .collect()
    };
    let mut g = Egm96Grid::new();
    for (x, y) in cols(&orig_out).iter().zip(cols(&b_out)) {
        // h = MSL altitude + EGM96 N, MSL altitude = h_receiver + 21.350.
        let n = g.separation_m(y[0], y[1]).unwrap();
        assert!((y[2] - (x[2] + 21.35 + n)).abs() < 1e-3, "{x:?} vs {y:?}");
        assert!((-20.0..-19.7).contains(&n), "{n}");
        assert!((1.0..2.0).contains(&(y[2] - x[2])));
    }
}

#[test]
fn nmea_epochs_without_a_fix_are_counted_by_reason() {
    use navsync_receivers::nmea::{Date, Gga, Rmc};
    // (quality, position given, altitude given) per 1 s epoch.
    let epochs = [
        (1, true, true),
        (0, false, true),
        (1, true, true),
        (6, true, true),
        (0, false, true),
        (4, true, false),
        (2, true, true),
    ];
    let mut s = String::new();
    for (k, (quality, pos, alt)) in epochs.into_iter().enumerate() {
        let tod = Some((3600 + k as i64) * 1_000_000_000);
        let rmc = Rmc {
            talker: "GN".into(),
            time_of_day_ns: tod,
            date: Some(Date {
                year: 2025,
                month: 3,
                day: 14,
            }),
            valid: quality > 0,
            lat_deg: None,
            lon_deg: None,
            speed_knots: None,
            course_deg: None,
        };
        let gga = Gga {
            talker: "GN".into(),
            time_of_day_ns: tod,
            lat_deg: pos.then_some(LAT),
            lon_deg: pos.then_some(LON),
            quality,
            num_sv: Some(8),
            hdop: Some(1.0),
            alt_msl_m: alt.then_some(1130.0),
            geoid_sep_m: Some(-21.35),
        };
        s.push_str(&rmc.to_sentence());
        s.push_str(&gga.to_sentence());
    }
    let dir = tmp("nmea-drops");
    let input = dir.join("in.nmea");
    std::fs::write(&input, s).unwrap();
    let sum = convert(
        InputFormat::Nmea,
        &input,
        &dir.join("out"),
        &ConvertOptions::default(),
    )
    .unwrap();
    assert_eq!(sum.gnss_fixes, 3);
    let t = &sum.fix_epochs[0];
    assert_eq!((t.source.as_str(), t.epochs, t.fixes), ("NMEA GGA", 7, 3));
    let d: Vec<(&str, u64)> = t
        .dropped
        .iter()
        .map(|d| (d.reason.as_str(), d.epochs))
        .collect();
    assert_eq!(
        d,
        [
            ("GGA fix quality 0 (invalid: no fix)", 2),
            ("GGA fix quality 6 (estimated (dead reckoning))", 1),
            (
                "GGA unusable (no time, date or altitude: each one in the problems listed)",
                1
            ),
        ]
    );
    assert!(
        sum.diagnostics
            .items
            .iter()
            .any(|i| i.message.contains("lacks the altitude"))
    );
}
