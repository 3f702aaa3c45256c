//! Random, valid instances of every message (seeded), for round trips and
//! generated streams.
#![allow(dead_code)]

use navsync_receivers::nmea::{Date, Gga, Gst, NmeaMessage, Rmc, Zda};
use navsync_receivers::ubx::*;
use rand::{RngExt, SeedableRng};

pub type TestRng = rand_pcg::Pcg64;

pub fn rng(seed: u64) -> TestRng {
    TestRng::seed_from_u64(seed)
}

pub fn nav_pvt(r: &mut TestRng) -> NavPvt {
    let mut p = NavPvt::decode(&[0u8; 92]).unwrap();
    p.itow_ms = r.random_range(0..604_800_000);
    p.year = r.random_range(1980..2100);
    p.month = r.random_range(1..=12);
    p.day = r.random_range(1..=28);
    p.hour = r.random_range(0..24);
    p.min = r.random_range(0..60);
    p.sec = r.random_range(0..60);
    p.valid = r.random();
    p.t_acc_ns = r.random();
    p.nano_ns = r.random_range(-1_000_000_000..1_000_000_000);
    p.fix_type = r.random_range(0..6);
    p.flags = r.random();
    p.flags2 = r.random();
    p.num_sv = r.random();
    p.lon_e7 = r.random_range(-1_800_000_000..1_800_000_000);
    p.lat_e7 = r.random_range(-900_000_000..900_000_000);
    p.height_mm = r.random();
    p.h_msl_mm = r.random();
    p.h_acc_mm = r.random();
    p.v_acc_mm = r.random();
    p.vel_ned_mm_s = r.random();
    p.g_speed_mm_s = r.random();
    p.head_mot_e5 = r.random();
    p.s_acc_mm_s = r.random();
    p.head_acc_e5 = r.random();
    p.p_dop_e2 = r.random();
    p.flags3 = r.random();
    p.reserved1 = r.random();
    p.head_veh_e5 = r.random();
    p.mag_dec_e2 = r.random();
    p.mag_acc_e2 = r.random();
    p
}

pub fn nav_timegps(r: &mut TestRng) -> NavTimeGps {
    NavTimeGps {
        itow_ms: r.random_range(0..604_800_000),
        ftow_ns: r.random_range(-500_000..=500_000),
        week: r.random_range(0..4000),
        leap_s: r.random_range(0..40),
        valid: r.random_range(0..8),
        t_acc_ns: r.random(),
    }
}

pub fn tim_tp(r: &mut TestRng) -> TimTp {
    TimTp {
        tow_ms: r.random_range(0..604_800_000),
        tow_sub_ms: r.random(),
        q_err_ps: r.random_range(-30_000..30_000),
        week: r.random_range(0..4000),
        flags: r.random(),
        ref_info: r.random(),
    }
}

pub fn tim_tm2(r: &mut TestRng) -> TimTm2 {
    TimTm2 {
        ch: r.random_range(0..2),
        flags: r.random(),
        count: r.random(),
        wn_r: r.random_range(0..4000),
        wn_f: r.random_range(0..4000),
        tow_ms_r: r.random_range(0..604_800_000),
        tow_sub_ms_r_ns: r.random_range(0..1_000_000),
        tow_ms_f: r.random_range(0..604_800_000),
        tow_sub_ms_f_ns: r.random_range(0..1_000_000),
        acc_est_ns: r.random(),
    }
}

pub fn esf_meas(r: &mut TestRng) -> EsfMeas {
    let n = r.random_range(0..=31);
    let data = (0..n)
        .map(|_| EsfData {
            data_type: r.random_range(0..64),
            field: r.random_range(0..1 << 24),
        })
        .collect();
    let calib = r.random_bool(0.5).then(|| r.random());
    let mut m = EsfMeas::new(r.random(), r.random(), data, calib);
    m.flags |= r.random_range(0..8) & !0x08; // timeMarkSent/Edge bits
    m
}

pub fn esf_raw(r: &mut TestRng, blocks: usize) -> EsfRaw {
    EsfRaw {
        reserved1: r.random(),
        blocks: (0..blocks)
            .map(|_| EsfRawBlock {
                data_type: r.random(),
                field: r.random_range(0..1 << 24),
                s_ttag: r.random(),
            })
            .collect(),
    }
}

pub fn ubx_message(r: &mut TestRng, kind: usize) -> UbxMessage {
    match kind % 6 {
        0 => UbxMessage::NavPvt(nav_pvt(r)),
        1 => UbxMessage::NavTimeGps(nav_timegps(r)),
        2 => UbxMessage::TimTp(tim_tp(r)),
        3 => UbxMessage::TimTm2(tim_tm2(r)),
        4 => UbxMessage::EsfMeas(esf_meas(r)),
        _ => {
            let n = r.random_range(0..80);
            UbxMessage::EsfRaw(esf_raw(r, n))
        }
    }
}

/// Values on the grid the sentences carry (centiseconds, 1e-7 arc-minutes,
/// mm, 2–3 decimals), so that decode(encode(x)) == x up to float parsing.
fn tod(r: &mut TestRng) -> i64 {
    r.random_range(0..8_640_000i64) * 10_000_000
}
fn lat(r: &mut TestRng) -> f64 {
    let min_e7: i64 = r.random_range(-90 * 60 * 10_000_000i64 + 1..90 * 60 * 10_000_000);
    min_e7 as f64 / 60e7
}
fn lon(r: &mut TestRng) -> f64 {
    let min_e7: i64 = r.random_range(-180 * 60 * 10_000_000i64 + 1..180 * 60 * 10_000_000);
    min_e7 as f64 / 60e7
}
fn dec(r: &mut TestRng, lo: i64, hi: i64, decimals: i32) -> f64 {
    r.random_range(lo..hi) as f64 / 10f64.powi(decimals)
}

pub fn nmea_message(r: &mut TestRng, kind: usize) -> NmeaMessage {
    let talker = ["GP", "GN", "GL"][r.random_range(0..3)].to_string();
    match kind % 4 {
        0 => NmeaMessage::Gga(Gga {
            talker,
            time_of_day_ns: Some(tod(r)),
            lat_deg: Some(lat(r)),
            lon_deg: Some(lon(r)),
            quality: r.random_range(1..=5),
            num_sv: Some(r.random_range(4..40)),
            hdop: Some(dec(r, 40, 999, 2) as f32),
            alt_msl_m: Some(dec(r, -400_000, 9_000_000, 3)),
            geoid_sep_m: Some(dec(r, -99_000, 99_000, 3)),
        }),
        1 => NmeaMessage::Rmc(Rmc {
            talker,
            time_of_day_ns: Some(tod(r)),
            date: Some(Date {
                year: r.random_range(2000..2080),
                month: r.random_range(1..=12),
                day: r.random_range(1..=28),
            }),
            valid: true,
            lat_deg: Some(lat(r)),
            lon_deg: Some(lon(r)),
            speed_knots: Some(dec(r, 0, 200_000, 3)),
            course_deg: Some(dec(r, 0, 36_000, 2)),
        }),
        2 => NmeaMessage::Gst(Gst {
            talker,
            time_of_day_ns: Some(tod(r)),
            rms_m: Some(dec(r, 1, 99_999, 3)),
            semi_major_sd_m: Some(dec(r, 1, 99_999, 3)),
            semi_minor_sd_m: Some(dec(r, 1, 99_999, 3)),
            orientation_deg: Some(dec(r, 0, 180_000, 3)),
            lat_sd_m: Some(dec(r, 1, 99_999, 3)),
            lon_sd_m: Some(dec(r, 1, 99_999, 3)),
            alt_sd_m: Some(dec(r, 1, 99_999, 3)),
        }),
        _ => NmeaMessage::Zda(Zda {
            talker,
            time_of_day_ns: Some(tod(r)),
            date: Some(Date {
                year: r.random_range(1980..2100),
                month: r.random_range(1..=12),
                day: r.random_range(1..=28),
            }),
        }),
    }
}

/// Equal up to the float parsing of the sentence (lat/lon: < 1e-9 deg from
/// 1e-7 arc-minute rounding; others exact to their decimals).
pub fn nmea_close(a: &NmeaMessage, b: &NmeaMessage) -> bool {
    let ang = |x: Option<f64>, y: Option<f64>| match (x, y) {
        (Some(x), Some(y)) => (x - y).abs() < 1e-9,
        (None, None) => true,
        _ => false,
    };
    let num = |x: Option<f64>, y: Option<f64>| match (x, y) {
        (Some(x), Some(y)) => (x - y).abs() <= 1e-9 * x.abs().max(1.0),
        (None, None) => true,
        _ => false,
    };
    match (a, b) {
        (NmeaMessage::Gga(x), NmeaMessage::Gga(y)) => {
            x.talker == y.talker
                && x.time_of_day_ns == y.time_of_day_ns
                && ang(x.lat_deg, y.lat_deg)
                && ang(x.lon_deg, y.lon_deg)
                && x.quality == y.quality
                && x.num_sv == y.num_sv
                && x.hdop == y.hdop
                && num(x.alt_msl_m, y.alt_msl_m)
                && num(x.geoid_sep_m, y.geoid_sep_m)
        }
        (NmeaMessage::Rmc(x), NmeaMessage::Rmc(y)) => {
            x.talker == y.talker
                && x.time_of_day_ns == y.time_of_day_ns
                && x.date == y.date
                && x.valid == y.valid
                && ang(x.lat_deg, y.lat_deg)
                && ang(x.lon_deg, y.lon_deg)
                && num(x.speed_knots, y.speed_knots)
                && num(x.course_deg, y.course_deg)
        }
        (NmeaMessage::Gst(x), NmeaMessage::Gst(y)) => {
            x.talker == y.talker
                && x.time_of_day_ns == y.time_of_day_ns
                && num(x.rms_m, y.rms_m)
                && num(x.semi_major_sd_m, y.semi_major_sd_m)
                && num(x.semi_minor_sd_m, y.semi_minor_sd_m)
                && num(x.orientation_deg, y.orientation_deg)
                && num(x.lat_sd_m, y.lat_sd_m)
                && num(x.lon_sd_m, y.lon_sd_m)
                && num(x.alt_sd_m, y.alt_sd_m)
        }
        (NmeaMessage::Zda(x), NmeaMessage::Zda(y)) => x == y,
        _ => false,
    }
}
