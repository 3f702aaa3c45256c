//! navsync's leap-second table and UTC → GPS conversion against hifitime
//! (an independent implementation with its own IERS table).

mod common;

use hifitime::Epoch;
use navsync_receivers::gnsstime::{UtcTime, days_from_civil, gps_to_unix_ns, utc_to_gps};
use rand::RngExt;

fn oracle(u: &UtcTime) -> i128 {
    Epoch::from_gregorian_utc(
        u.year,
        u.month as u8,
        u.day as u8,
        u.hour as u8,
        u.min as u8,
        u.sec as u8,
        u.nano,
    )
    .to_gpst_duration()
    .total_nanoseconds()
}

#[test]
fn every_leap_second_boundary_matches_hifitime() {
    for year in 1981..=2030 {
        for month in [1u32, 7] {
            let midnight = days_from_civil(year, month, 1) * 86_400 * 1_000_000_000;
            for ds in [-2i64, -1, 0, 1] {
                let u = UtcTime::from_unix_ns(midnight + ds * 1_000_000_000 + 123_456_789);
                assert_eq!(utc_to_gps(&u).ns() as i128, oracle(&u), "{u:?}");
            }
        }
    }
}

#[test]
fn random_instants_match_hifitime_and_invert() {
    let mut r = common::rng(5);
    let start = days_from_civil(1980, 1, 7) * 86_400;
    let end = days_from_civil(2035, 1, 1) * 86_400;
    for _ in 0..20_000 {
        let unix_ns = r.random_range(start..end) * 1_000_000_000 + r.random_range(0..1_000_000_000);
        let u = UtcTime::from_unix_ns(unix_ns);
        let g = utc_to_gps(&u);
        assert_eq!(g.ns() as i128, oracle(&u), "{u:?}");
        assert_eq!(gps_to_unix_ns(g), unix_ns);
    }
}
