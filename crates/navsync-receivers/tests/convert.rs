//! `convert` end to end on generated inputs whose truth is known, read back
//! with navsync's own KF-GINS readers.

use navsync::Diagnostics;
use navsync::io::kfgins::{GnssLayout, GnssReader, ImuReader};
use navsync::testfiles::TestDir;
use navsync::time::{GpsTime, NS_PER_S};
use navsync_receivers::convert::{ConvertOptions, InputFormat, convert};
use navsync_receivers::gnsstime::utc_to_gps;
use navsync_receivers::ubx::*;

/// A directory of this test, removed when it passes.
fn tmp(name: &str) -> TestDir {
    TestDir::new(&format!("rx-{name}"))
}

const WEEK: i64 = 2300;
const TOW0_S: i64 = 100_000;

/// 20 s of a dead-reckoning receiver at rest-ish: NAV-TIMEGPS + NAV-PVT at
/// 1 Hz, ESF-RAW at 100 Hz (gyro z 10 deg/s, accel z −9.8 m/s²), TIM-TP
/// with a known qErr, a camera strobe on EXTINT0 each second.
/// A NAV-TIMEGPS frame at `itow_ms` of the test week (valid, 18 leap s).
fn nav_time_gps_frame(itow_ms: u32) -> Vec<u8> {
    let tg = NavTimeGps {
        itow_ms,
        ftow_ns: 0,
        week: WEEK as i16,
        leap_s: 18,
        valid: 7,
        t_acc_ns: 20,
    };
    UbxMessage::NavTimeGps(tg).to_frame().unwrap()
}

fn receiver_stream() -> Vec<u8> {
    let mut s = b"# generated test stream\n".to_vec();
    for k in 0..20i64 {
        let itow = ((TOW0_S + k) * 1000) as u32;
        s.extend(nav_time_gps_frame(itow));
        let mut p = NavPvt::decode(&[0; 92]).unwrap();
        p.itow_ms = itow;
        p.valid = 0x04; // date/time not valid: week from NAV-TIMEGPS
        p.fix_type = 3;
        p.flags = 1;
        p.lat_e7 = 300_000_000 + k as i32;
        p.lon_e7 = 1_140_000_000;
        p.height_mm = 20_000;
        p.h_acc_mm = 1500;
        p.v_acc_mm = 3000;
        p.s_acc_mm_s = 100;
        p.vel_ned_mm_s = [1000, 0, 0];
        s.extend(UbxMessage::NavPvt(p).to_frame().unwrap());
        let tp = TimTp {
            tow_ms: itow + 1000,
            tow_sub_ms: 0,
            q_err_ps: -12_000,
            week: WEEK as u16,
            flags: 0,
            ref_info: 0,
        };
        s.extend(UbxMessage::TimTp(tp).to_frame().unwrap());
        let tm = TimTm2 {
            ch: 0,
            flags: 0x80 | 0x40 | 0x08 | 0x04,
            count: k as u16,
            wn_r: WEEK as u16,
            wn_f: WEEK as u16,
            tow_ms_r: itow + 500,
            tow_sub_ms_r_ns: 0,
            tow_ms_f: itow + 504,
            tow_sub_ms_f_ns: 0,
            acc_est_ns: 21,
        };
        s.extend(UbxMessage::TimTm2(tm).to_frame().unwrap());
        for j in 0..100u32 {
            let tag = k as u32 * 1000 + j * 10; // 10 ms steps, tick 1 ms
            let mut blocks = Vec::new();
            for (t, v) in [
                (esf_type::GYRO_X, 0i32),
                (esf_type::GYRO_Y, 0),
                (esf_type::GYRO_Z, 40_960),
                (esf_type::ACC_X, 0),
                (esf_type::ACC_Y, 0),
                (esf_type::ACC_Z, -10_035),
            ] {
                blocks.push(EsfRawBlock {
                    data_type: t,
                    field: (v as u32) & 0xFF_FFFF,
                    s_ttag: tag + 1_000_000,
                });
            }
            s.extend(
                UbxMessage::EsfRaw(EsfRaw {
                    reserved1: [0; 4],
                    blocks,
                })
                .to_frame()
                .unwrap(),
            );
        }
    }
    s.extend(b"\x00\xB5\x62garbage");
    s
}

#[test]
fn ubx_stream_to_kfgins_and_rig_log() {
    let dir = tmp("ubx");
    let input = dir.join("in.ubx");
    std::fs::write(&input, receiver_stream()).unwrap();
    let out = dir.join("out");
    let s = convert(InputFormat::Ubx, &input, &out, &ConvertOptions::default()).unwrap();
    assert_eq!(s.header_bytes, 24);
    let st = s.stream.as_ref().unwrap();
    assert_eq!(
        (st.ubx_messages, st.corrupt_runs, st.corrupt_bytes),
        (20 * 104, 1, 10)
    );
    assert_eq!(
        (s.gnss_fixes, s.gnss_columns, s.pps, s.mark_edges, s.strobes),
        (20, 13, 20, 40, 20)
    );

    let mut d = Diagnostics::default();
    let mut g = GnssReader::open(&out.join("gnss.txt"), WEEK, GnssLayout::Cpp).unwrap();
    let mut k = 0;
    while let Some(f) = g.next_fix(&mut d).unwrap() {
        assert_eq!(f.time, GpsTime::from_week_ns(WEEK, (TOW0_S + k) * NS_PER_S));
        assert!((f.pos.lat_rad.to_degrees() - (30.0 + k as f64 * 1e-7)).abs() < 1e-10);
        assert_eq!((f.pos_sd.x, f.pos_sd.z, f.vel.unwrap().x), (1.5, 3.0, 1.0));
        k += 1;
    }
    assert_eq!(k, 20);

    // 100 Hz increments: gyro z = 40960 · 2⁻¹² deg/s = 10 deg/s → 0.1 deg per
    // 10 ms; accel z = −10035 · 2⁻¹⁰ m/s² → ×0.01 s.
    let mut imu = ImuReader::open(&out.join("imu.txt"), 0).unwrap();
    let mut n = 0;
    while let Some(x) = imu.next_sample(&mut d).unwrap() {
        assert!((x.dtheta.z - 0.1f64.to_radians()).abs() < 1e-15);
        assert!((x.dvel.z + 10_035.0 / 1024.0 * 0.01).abs() < 1e-14);
        n += 1;
    }
    assert_eq!(n, 1999);
    assert_eq!(s.imu_gaps, 0);
    assert!(d.is_empty(), "{:?}", d.items);

    // Rig-log: pps at pulse − qErr (12 ns late here), marks in GPS ns.
    let rig = std::fs::read_to_string(out.join("events.rig")).unwrap();
    assert!(rig.starts_with("# rig-log v1\n# counter_hz: 1000000000\n# counter_bits: 64\n"));
    let first_pulse = GpsTime::from_week_ns(WEEK, (TOW0_S + 1) * NS_PER_S).ns();
    assert!(rig.contains(&format!("\npps,{}\n", first_pulse + 12)));
    let first_mark = GpsTime::from_week_ns(WEEK, TOW0_S * NS_PER_S + 500_000_000).ns();
    let mark_line = |ns: i64, rising: u8| {
        let t = GpsTime::from_ns(ns);
        let mut l = format!("\nmark,{ns},{},", t.week()).into_bytes();
        t.write_sow(&mut l);
        format!("{},0,{rising},0,21\n", String::from_utf8(l).unwrap())
    };
    assert!(rig.contains(&mark_line(first_mark, 1)), "{rig}");
    assert!(rig.contains(&mark_line(first_mark + 4_000_000, 0)), "{rig}");
    // The rig-log reader takes the file: marks carry their GPS time.
    let mut diag = navsync::Diagnostics::default();
    let mut r =
        navsync::io::riglog::RigLogReader::open(&out.join("events.rig"), &mut diag).unwrap();
    let mut marks = 0;
    while let Some((rec, _)) = r.next_record(&mut diag).unwrap() {
        if let navsync::io::riglog::RigRecord::Mark { counter, time } = rec {
            assert_eq!(counter as i64, time.ns());
            marks += 1;
        }
    }
    assert!(marks >= 2 && diag.is_empty(), "{marks} marks, {diag:?}");
}

#[test]
fn rate_csv_bad_lines_gaps_and_trapezoid() {
    let dir = tmp("rate");
    let input = dir.join("imu.csv");
    std::fs::write(
        &input,
        "# t, gyro, accel\n\
         10.00,0,0,0.1,0,0,-9.8\n\
         10.01,0,0,0.3,0,0,-9.8\n\
         10.02,0,0,abc,0,0,-9.8\n\
         10.02,0,0,0.5\n\
         10.005,0,0,0.5,0,0,-9.8\n\
         10.20,0,0,0.5,0,0,-9.8\n",
    )
    .unwrap();
    let out = dir.join("out");
    let opts = ConvertOptions {
        imu_time_offset_s: 100.0,
        ..Default::default()
    };
    let s = convert(InputFormat::RateCsv, &input, &out, &opts).unwrap();
    assert_eq!((s.imu_samples, s.imu_gaps), (2, 1));
    let lines: Vec<String> = s.diagnostics.items.iter().map(|d| d.to_string()).collect();
    assert!(
        lines[0].ends_with(":4: field 4: not a number; line skipped")
            || lines[0].contains(":4: field 4"),
        "{lines:?}"
    );
    assert!(lines[1].contains(":5: expected 7 fields"), "{lines:?}");
    assert!(lines.iter().any(|l| l.contains("not after")), "{lines:?}");
    assert!(
        lines.iter().any(|l| l.contains("IMU gap of 0.1900 s")),
        "{lines:?}"
    );
    let mut d = Diagnostics::default();
    let mut imu = ImuReader::open(&out.join("imu.txt"), 0).unwrap();
    let a = imu.next_sample(&mut d).unwrap().unwrap();
    assert_eq!(a.time, GpsTime::from_ns(110_010_000_000));
    assert!((a.dtheta.z - 0.5 * (0.1 + 0.3) * 0.01).abs() < 1e-15); // seed 001 §1.1
}

#[test]
fn comma_gnss_to_gps_time_with_receipts() {
    let dir = tmp("comma");
    let input = dir.join("gnss_ublox.csv");
    std::fs::write(
        &input,
        "# t_boot_s_received,lat_deg,lon_deg,speed_mps,utc_unix_ms,alt_m,bearing_deg\n\
         46408.654976041,37.720997700,-122.472305300,7.823,1533226488299,33.3700,2.13561\n\
         46408.744466041,37.721005000,-122.472305000,7.993,1533226488399,33.3520,2.27721\n\
         46408.8,999,0,0,1533226488499,0,0\n",
    )
    .unwrap();
    let out = dir.join("out");
    let s = convert(
        InputFormat::CommaGnss,
        &input,
        &out,
        &ConvertOptions::default(),
    )
    .unwrap();
    assert_eq!(
        (s.gnss_fixes, s.gnss_columns, s.diagnostics.total),
        (2, 7, 1)
    );
    let gnss = std::fs::read_to_string(out.join("gnss.txt")).unwrap();
    // 2018-08-02 16:14:48.299 UTC + 18 s = GPS week 2012, 404106.299 s.
    assert!(
        gnss.starts_with("404106.299000000 37.72099770000 -122.47230530000 33.3700 "),
        "{gnss}"
    );
    let t = utc_to_gps(&navsync_receivers::gnsstime::UtcTime::from_unix_ns(
        1_533_226_488_299_000_000,
    ));
    assert_eq!((t.week(), t.ns_of_week()), (2012, 404_106_299_000_000));
    let rec = std::fs::read_to_string(out.join("gnss_receipt.txt")).unwrap();
    assert!(
        rec.contains("\n2012 404106.299000000 46408.654976041\n"),
        "{rec}"
    );
}

#[test]
fn empty_and_missing_inputs_are_clear_errors() {
    let dir = tmp("bad");
    let input = dir.join("empty.ubx");
    std::fs::write(&input, "# only a header\n").unwrap();
    let e = convert(
        InputFormat::Ubx,
        &input,
        &dir.join("o"),
        &ConvertOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("no bytes after the header"), "{e}");
    let e = convert(
        InputFormat::RateCsv,
        &dir.join("missing.csv"),
        &dir.join("o"),
        &ConvertOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("missing.csv"), "{e}");
}

/// 10 s of a moving-base receiver: NAV-TIMEGPS, NAV-PVT and NAV-RELPOSNED
/// at 1 Hz, heading 10° + k° with accHeading 0.2°, except epoch 3 without
/// relPosHeadingValid, epoch 5 without gnssFixOK, epoch 7 with an absurd
/// accHeading of 180° and epoch 8 with accHeading 0. The good epochs go to
/// heading.txt; each bad one is a diagnostic naming its byte offset and
/// reason; the fixes are all written.
#[test]
fn nav_relposned_to_heading_file_with_bad_epochs_reported() {
    let mut s = Vec::new();
    let mut offsets = Vec::new();
    for k in 0..10i64 {
        let itow = ((TOW0_S + k) * 1000) as u32;
        s.extend(nav_time_gps_frame(itow));
        let mut p = NavPvt::decode(&[0; 92]).unwrap();
        p.itow_ms = itow;
        p.valid = 0x04;
        p.fix_type = 3;
        p.flags = 1;
        p.lat_e7 = 300_000_000;
        p.lon_e7 = 1_140_000_000;
        p.height_mm = 20_000;
        p.h_acc_mm = 20;
        p.v_acc_mm = 30;
        s.extend(UbxMessage::NavPvt(p).to_frame().unwrap());
        let mut r = NavRelPosNed::decode(&[0; 64]).unwrap();
        r.version = 1;
        r.itow_ms = itow;
        r.rel_pos_length_cm = 100;
        r.rel_pos_heading_e5 = ((10 + k) * 100_000) as i32;
        r.acc_heading_e5 = 20_000;
        r.flags = 0x001 | 0x004 | (2 << 3) | 0x020 | 0x100;
        match k {
            3 => r.flags &= !0x100,
            5 => r.flags &= !0x001,
            7 => r.acc_heading_e5 = 18_000_000,
            8 => r.acc_heading_e5 = 0,
            _ => {}
        }
        offsets.push(s.len());
        s.extend(UbxMessage::NavRelPosNed(r).to_frame().unwrap());
    }
    let dir = tmp("relposned");
    let input = dir.join("in.ubx");
    std::fs::write(&input, &s).unwrap();
    let out = dir.join("out");
    let sum = convert(InputFormat::Ubx, &input, &out, &ConvertOptions::default()).unwrap();
    assert_eq!(sum.gnss_fixes, 10);
    assert_eq!(sum.headings, 6);
    assert_eq!(sum.frames.get("UBX NAV-RELPOSNED"), Some(&10));
    let mut d = Diagnostics::default();
    let h = navsync::io::heading::read_headings(&out.join("heading.txt"), WEEK, &mut d).unwrap();
    assert!(d.is_empty(), "{:?}", d.items);
    let kept: Vec<i64> = h
        .iter()
        .map(|o| {
            (o.time
                .seconds_since(GpsTime::from_week_ns(WEEK, TOW0_S * NS_PER_S))) as i64
        })
        .collect();
    assert_eq!(kept, [0, 1, 2, 4, 6, 9]);
    for (o, k) in h.iter().zip(&kept) {
        assert!((o.heading_rad.to_degrees() - (10 + k) as f64).abs() < 1e-6);
        assert!((o.sd_rad.to_degrees() - 0.2).abs() < 1e-6);
        assert_eq!(o.source, navsync::io::heading::HeadingSource::Baseline);
    }
    let msgs: Vec<&str> = sum
        .diagnostics
        .items
        .iter()
        .map(|d| d.message.as_str())
        .filter(|m| m.contains("NAV-RELPOSNED"))
        .collect();
    assert_eq!(msgs.len(), 4, "{msgs:?}");
    for (m, (k, why)) in msgs.iter().zip([
        (3, "relPosHeadingValid not set"),
        (5, "gnssFixOK not set"),
        (7, "180.00°"),
        (8, "0.00°"),
    ]) {
        assert!(
            m.starts_with(&format!("byte {}:", offsets[k])) && m.contains(why),
            "{m}"
        );
    }
}

/// 8 s of a dual-antenna NMEA receiver (a Unicore- or Septentrio-like
/// stream: GGA, RMC, then HDT each second), heading 200° + k°. Epoch 2's
/// HDT is empty (no baseline solution), epoch 4's comes from a gyrocompass
/// talker (HE), epoch 6's is 400°. The good ones go to heading.txt at
/// their epoch's GPS time, as baseline headings with `hdt_sd_deg`; the rest
/// are tallied, the 400° one also a diagnostic; the fixes are all written.
#[test]
fn nmea_hdt_to_heading_file_at_its_epochs_time() {
    use navsync_receivers::nmea::{Date, Gga, Hdt, Rmc, encode_sentence};
    let date = Date {
        year: 2026,
        month: 12,
        day: 3,
    };
    let mut text = String::new();
    // A stray HDT before any epoch: its time is unknown.
    text.push_str(&encode_sentence("GNHDT,1.00,T"));
    let tod0_s = 3600 * 10;
    for k in 0..8i64 {
        let tod = Some((tod0_s + k) * NS_PER_S);
        text.push_str(
            &Gga {
                talker: "GN".into(),
                time_of_day_ns: tod,
                lat_deg: Some(30.5),
                lon_deg: Some(114.3),
                quality: 4,
                num_sv: Some(20),
                hdop: Some(0.6),
                alt_msl_m: Some(20.0),
                geoid_sep_m: Some(-10.0),
            }
            .to_sentence(),
        );
        text.push_str(
            &Rmc {
                talker: "GN".into(),
                time_of_day_ns: tod,
                date: Some(date),
                valid: true,
                lat_deg: Some(30.5),
                lon_deg: Some(114.3),
                speed_knots: Some(0.0),
                course_deg: None,
            }
            .to_sentence(),
        );
        let heading = match k {
            2 => None,
            6 => Some(400.0),
            _ => Some(200.0 + k as f64),
        };
        let talker = if k == 4 { "HE" } else { "GN" };
        text.push_str(
            &Hdt {
                talker: talker.into(),
                heading_deg: heading,
            }
            .to_sentence(),
        );
    }
    let dir = tmp("nmea-hdt");
    let input = dir.join("in.nmea");
    std::fs::write(&input, &text).unwrap();
    let out = dir.join("out");
    let opts = ConvertOptions {
        hdt_sd_deg: 0.3,
        ..Default::default()
    };
    let sum = convert(InputFormat::Nmea, &input, &out, &opts).unwrap();
    assert_eq!(sum.gnss_fixes, 8);
    assert_eq!(sum.headings, 5);
    let t0 = utc_to_gps(&navsync_receivers::gnsstime::UtcTime {
        year: 2026,
        month: 12,
        day: 3,
        hour: 10,
        min: 0,
        sec: 0,
        nano: 0,
    });
    let mut d = Diagnostics::default();
    let h =
        navsync::io::heading::read_headings(&out.join("heading.txt"), t0.week(), &mut d).unwrap();
    assert!(d.is_empty(), "{:?}", d.items);
    let kept: Vec<i64> = h
        .iter()
        .map(|o| o.time.seconds_since(t0).round() as i64)
        .collect();
    assert_eq!(kept, [0, 1, 3, 5, 7]);
    for (o, k) in h.iter().zip(&kept) {
        assert!((o.heading_rad.to_degrees() - (200 + k) as f64).abs() < 1e-6);
        assert!((o.sd_rad.to_degrees() - 0.3).abs() < 1e-9);
        assert_eq!(o.source, navsync::io::heading::HeadingSource::Baseline);
    }
    let tallied: u64 = sum.heading_drops.values().sum();
    assert_eq!(tallied, 4, "{:?}", sum.heading_drops);
    assert!(sum.heading_drops.keys().any(|k| k.contains("talker HE")));
    assert!(
        sum.heading_drops
            .keys()
            .any(|k| k.contains("empty heading"))
    );
    let msgs: Vec<&str> = sum
        .diagnostics
        .items
        .iter()
        .map(|d| d.message.as_str())
        .filter(|m| m.contains("HDT"))
        .collect();
    assert_eq!(msgs.len(), 2, "{msgs:?}");
    assert!(msgs.iter().any(|m| m.contains("before any timed sentence")));
    assert!(
        msgs.iter()
            .any(|m| m.contains("400") && m.contains("36006 s of day"))
    );
}

/// The real NEO-M8L log (gpsd regression data, an ADR receiver): every
/// NAV-PVT has headVehValid, and headVeh repeats headMot to a few 1e-5° at
/// ground speeds of a few cm/s to a few m/s with a headAcc of ≈ 5°. So its
/// vehicle heading is the heading of motion there, meaningless at rest:
/// the alignment takes a vehicle heading only above its minimum speed.
#[test]
fn neo_m8l_head_veh_repeats_head_mot() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/gpsd-ublox/ublox-neo-m8l.log");
    if !path.is_file() {
        eprintln!("skipped: {} not found", path.display());
        return;
    }
    let out = tmp("m8l-heading");
    let sum = convert(InputFormat::Ubx, &path, &out, &ConvertOptions::default()).unwrap();
    assert_eq!(sum.frames.get("UBX NAV-PVT"), Some(&19));
    assert_eq!(sum.headings, 19);
    let mut d = Diagnostics::default();
    let h = navsync::io::heading::read_headings(&out.join("heading.txt"), 0, &mut d).unwrap();
    assert!(
        h.iter()
            .all(|o| o.source == navsync::io::heading::HeadingSource::Vehicle)
    );
    assert!(
        h.iter()
            .all(|o| (4.0..6.0).contains(&o.sd_rad.to_degrees()))
    );
    // headVeh against headMot, straight from the stream.
    let bytes = std::fs::read(&path).unwrap();
    let mut n = 0;
    let mut i = 0;
    while let Some(j) = bytes[i..]
        .windows(4)
        .position(|w| w == [0xB5, 0x62, 0x01, 0x07])
    {
        let at = i + j + 6;
        if let Some(p) = bytes.get(at..at + 92)
            && let Ok(p) = NavPvt::decode(p)
        {
            assert!(p.flags & 0x20 != 0, "headVehValid");
            // The two differ in the last digits only (the receiver's
            // rounding): at most 1e-4°, against a headAcc of ≈ 5°.
            assert!((p.head_veh_e5 - p.head_mot_e5).abs() <= 10, "{p:?}");
            n += 1;
        }
        i = at;
    }
    assert_eq!(n, 19);
}
