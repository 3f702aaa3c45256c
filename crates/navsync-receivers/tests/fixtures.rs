//! Real u-blox streams (gpsd regression logs, BSD-2-Clause; see
//! tests/fixtures/README.md): concrete decoded values, exact re-encoding,
//! and time of validity in GPS time.

use navsync::time::GpsTime;
use navsync_receivers::fixes::{
    FixOptions, NmeaFixes, NmeaOutcome, TimeContext, nav_pvt_fix, nav_pvt_time,
};
use navsync_receivers::marks::QErrCorrector;
use navsync_receivers::nmea::NmeaMessage;
use navsync_receivers::stream::{Event, EventKind, StreamStats, gpsd_log_header_len, read_all};
use navsync_receivers::ubx::{EsfValue, UbxMessage};

fn load(name: &str) -> (Vec<u8>, Vec<Event>, StreamStats) {
    let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(path).unwrap();
    let h = gpsd_log_header_len(&bytes);
    let (ev, st) = read_all(&bytes[h..], h as u64);
    // Every byte after the header is in exactly one event, and every
    // decoded UBX message re-encodes to its original bytes.
    let mut next = h as u64;
    for e in &ev {
        assert_eq!(e.offset, next);
        next += e.len as u64;
        if let EventKind::Ubx(m) = &e.kind {
            let frame = &bytes[e.offset as usize..e.offset as usize + e.len];
            assert_eq!(m.to_frame().unwrap(), frame, "{name}: {e}");
        }
    }
    assert_eq!(next, bytes.len() as u64);
    (bytes, ev, st)
}

fn ubx(ev: &[Event]) -> Vec<&UbxMessage> {
    ev.iter()
        .filter_map(|e| {
            if let EventKind::Ubx(m) = &e.kind {
                Some(m)
            } else {
                None
            }
        })
        .collect()
}

#[test]
fn neo_m8l_nav_pvt_esf_meas() {
    let (_, ev, st) = load("ublox-neo-m8l-excerpt.log");
    assert_eq!(
        (
            st.ubx_messages,
            st.nmea_messages,
            st.unknown_frames,
            st.invalid_frames,
            st.corrupt_runs
        ),
        (53, 0, 69, 0, 0)
    );
    let msgs = ubx(&ev);
    let pvts: Vec<_> = msgs
        .iter()
        .filter_map(|m| {
            if let UbxMessage::NavPvt(p) = m {
                Some(p)
            } else {
                None
            }
        })
        .collect();
    let meas: Vec<_> = msgs
        .iter()
        .filter_map(|m| {
            if let UbxMessage::EsfMeas(p) = m {
                Some(p)
            } else {
                None
            }
        })
        .collect();
    assert_eq!((pvts.len(), meas.len()), (2, 49));
    let p = pvts[0];
    assert_eq!(
        (p.itow_ms, p.year, p.month, p.day, p.hour, p.min, p.sec),
        (228_730_000, 2024, 1, 30, 15, 31, 52)
    );
    assert_eq!((p.nano_ns, p.fix_type, p.num_sv), (-422_154, 4, 14));
    assert_eq!(
        (p.lat_e7, p.lon_e7, p.height_mm, p.h_acc_mm, p.v_acc_mm),
        (487_409_646, 93_117_369, 311_278, 5124, 11_540)
    );
    assert_eq!(p.vel_ned_mm_s, [-319, -285, -1031]);

    // Time of validity: iTOW refined by the UTC fraction equals
    // NAV-TIMEGPS iTOW + fTOW (−422153 ns) to 1 ns.
    let mut ctx = TimeContext::default();
    let tg: Vec<_> = msgs
        .iter()
        .filter_map(|m| {
            if let UbxMessage::NavTimeGps(t) = m {
                Some(t)
            } else {
                None
            }
        })
        .collect();
    assert_eq!(
        (tg[0].week, tg[0].leap_s, tg[0].ftow_ns),
        (2299, 18, -422_153)
    );
    ctx.push_timegps(tg[0]);
    let (t, _) = nav_pvt_time(p, &ctx).unwrap();
    assert_eq!(
        t,
        GpsTime::from_week_ns(2299, 228_730_000_000_000 - 422_154)
    );
    assert!((t.ns() - tg[0].time_ns().unwrap()).abs() <= 1);
    // Same time from the UTC date alone (no NAV-TIMEGPS: leap-second table).
    assert_eq!(nav_pvt_time(p, &TimeContext::default()).unwrap().0, t);
    let fix = nav_pvt_fix(p, &ctx).unwrap().unwrap().fix;
    assert!((fix.pos.lat_rad.to_degrees() - 48.740_964_6).abs() < 1e-12);
    assert_eq!(fix.pos_sd.x, 5.124);
    assert_eq!(fix.vel_sd.unwrap().z, 0.313);

    // First ESF-MEAS: accelerometer set (m/s² · 2⁻¹⁰), then gyro set with a
    // negative 24-bit two's-complement x rate (0xFFFF98 = −104).
    assert_eq!(meas[0].time_tag, 1_138_255);
    let v: Vec<_> = meas[0].data.iter().map(|d| d.value()).collect();
    assert_eq!(
        v,
        [
            EsfValue::Accel(0, 702.0 / 1024.0),
            EsfValue::Accel(1, 225.0 / 1024.0),
            EsfValue::Accel(2, 12_058.0 / 1024.0)
        ]
    );
    assert_eq!(
        meas[1].data[0].value(),
        EsfValue::Gyro(0, (-104.0f64 / 4096.0).to_radians())
    );
    assert_eq!(meas[1].data[3].value(), EsfValue::Temperature(31.21));
    assert_eq!(meas[1].calib_ttag, Some(1_138_250));
}

#[test]
fn m8t_timing_tim_tp_qerr() {
    let (_, ev, st) = load("u-blox-m8t-time-excerpt.log");
    // gpsd's own JSON lines at the head of the stream are not receiver
    // frames: one corrupt run of 457 bytes, reported. Read: 3 TIM-TP,
    // 3 NAV-TIMEGPS, 3 NAV-POSLLH, 3 NAV-STATUS.
    assert_eq!(
        (
            st.ubx_messages,
            st.unknown_frames,
            st.corrupt_runs,
            st.corrupt_bytes
        ),
        (12, 15, 1, 457)
    );
    assert_eq!((ev[0].offset, ev[0].len), (137, 457));
    let mut ctx = TimeContext::default();
    let mut q = QErrCorrector::new();
    let mut pulses = Vec::new();
    for m in ubx(&ev) {
        match m {
            UbxMessage::NavTimeGps(t) => ctx.push_timegps(t),
            UbxMessage::TimTp(tp) => {
                assert!(tp.utc_time_base() && tp.q_err_valid());
                pulses.push(q.push_tim_tp(tp, &ctx.leap).unwrap());
            }
            _ => {}
        }
    }
    assert_eq!(
        pulses.iter().map(|p| p.q_err_ps).collect::<Vec<_>>(),
        [-4331, 9862, 2873]
    );
    // UTC-based pulse times + 18 leap seconds: whole GPS seconds 237888.. of
    // week 2146, each one second after the previous NAV-TIMEGPS epoch.
    assert_eq!(
        pulses[1].time,
        GpsTime::from_week_ns(2146, 237_871_000_000_000 + 18_000_000_000)
    );
    assert_eq!(pulses[2].time - pulses[1].time, 1_000_000_000);
}

#[test]
fn f9p_high_precision_nmea_fixes() {
    let (_, ev, st) = load("ublox-f9p-hpnmea-excerpt.log");
    assert_eq!(
        (st.nmea_messages, st.unknown_frames, st.corrupt_runs),
        (6, 28, 0)
    );
    let ctx = TimeContext::default();
    let mut f = NmeaFixes::new(FixOptions::default());
    let mut out = Vec::new();
    for e in &ev {
        if let EventKind::Nmea(m) = &e.kind {
            if let NmeaMessage::Gga(g) = m {
                assert_eq!(
                    (g.quality, g.num_sv, g.geoid_sep_m),
                    (2, Some(12), Some(-21.35))
                );
            }
            f.push(m, &ctx, &mut out);
        }
    }
    f.finish(&ctx, &mut out);
    let fixes: Vec<_> = out
        .iter()
        .filter_map(|o| {
            if let NmeaOutcome::Fix(f) = o {
                Some(f)
            } else {
                None
            }
        })
        .collect();
    assert_eq!(fixes.len(), 3);
    // 2021-12-23 01:45:00 UTC → GPS, checked against hifitime.
    let oracle = hifitime::Epoch::from_gregorian_utc(2021, 12, 23, 1, 45, 0, 0)
        .to_gpst_duration()
        .total_nanoseconds();
    assert_eq!(fixes[0].fix.time.ns() as i128, oracle);
    assert!((fixes[2].fix.pos.h_m - (1129.989 - 21.35)).abs() < 1e-9);
    assert!((fixes[1].fix.pos.lon_rad.to_degrees() + (121.0 + 18.8446927 / 60.0)).abs() < 1e-12);
    assert!(fixes.iter().all(|f| f.default_sd)); // this log has no GST
}

#[test]
fn neo_f9v_nav_pvt() {
    let (_, ev, st) = load("ublox-neo-f9v-excerpt.log");
    // NAV-PVT, NAV-VELNED, NAV-TIMEGPS and (since the dead-reckoning
    // messages are read) NAV-ATT read.
    assert_eq!(
        (st.ubx_messages, st.unknown_frames, st.corrupt_runs),
        (4, 5, 0)
    );
    let msgs = ubx(&ev);
    let UbxMessage::NavPvt(p) = msgs[0] else {
        panic!()
    };
    assert_eq!(
        (p.itow_ms, p.fix_type, p.num_sv, p.lat_e7, p.lon_e7),
        (9_631_000, 3, 30, 440_688_183, -1_213_140_788)
    );
    let fix = nav_pvt_fix(p, &TimeContext::default()).unwrap().unwrap();
    assert_eq!(
        fix.fix.time,
        GpsTime::from_week_ns(2384, 9_631_000_000_000 - 78_138)
    );
    assert!((fix.fix.pos.h_m - 1106.009).abs() < 1e-9);
}
