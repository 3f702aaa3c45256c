//! UTC ↔ GPS time with leap seconds, for receivers that report UTC (NMEA,
//! NAV-PVT dates, comma2k19's Unix times).
//!
//! GPS time has no leap seconds; GPS − UTC grows by one at each leap second
//! inserted since 1980-01-06 (18 s since 2017-01-01; IERS Bulletin C, and
//! the IS-GPS-200 ΔtLS parameter). A receiver that knows the current value
//! says so (UBX NAV-TIMEGPS `leapS` with `leapSValid`); [`LeapSeconds`]
//! prefers it and falls back to the table, which is checked against
//! hifitime's table in the tests. Dates make week numbers unambiguous, so
//! everything here is safe across GPS week rollovers (1999, 2019, 2038).

use navsync::time::{GpsTime, NS_PER_S};

/// Days from 1970-01-01 to a proleptic Gregorian date (H. Hinnant's
/// `days_from_civil`, public-domain algorithm).
pub fn days_from_civil(year: i32, month: u32, day: u32) -> i64 {
    let y = year as i64 - (month <= 2) as i64;
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = month as i64;
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + day as i64 - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Days from 1970-01-01 to the GPS epoch, 1980-01-06.
pub(crate) const GPS_EPOCH_UNIX_DAYS: i64 = 3657;

/// UTC instants (seconds since the GPS epoch, counted without leap seconds)
/// from which GPS − UTC took its next value: 1 s from 1981-07-01, …, 18 s
/// from 2017-01-01 (IERS Bulletin C).
const LEAP_STEPS: [(i32, u32, u32); 18] = [
    (1981, 7, 1),
    (1982, 7, 1),
    (1983, 7, 1),
    (1985, 7, 1),
    (1988, 1, 1),
    (1990, 1, 1),
    (1991, 1, 1),
    (1992, 7, 1),
    (1993, 7, 1),
    (1994, 7, 1),
    (1996, 1, 1),
    (1997, 7, 1),
    (1999, 1, 1),
    (2006, 1, 1),
    (2009, 1, 1),
    (2012, 7, 1),
    (2015, 7, 1),
    (2017, 1, 1),
];

/// GPS − UTC (s) from the table at a UTC instant given as seconds since the
/// GPS epoch without leap seconds. Before 1980-01-06 it is 0 (GPS did not
/// exist; callers should not ask).
pub(crate) fn table_leap_seconds(utc_s_since_gps_epoch: i64) -> i32 {
    LEAP_STEPS
        .iter()
        .filter(|&&(y, m, d)| {
            (days_from_civil(y, m, d) - GPS_EPOCH_UNIX_DAYS) * 86_400 <= utc_s_since_gps_epoch
        })
        .count() as i32
}

/// A UTC date and time of day; `sec` may be 60 during a leap second.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct UtcTime {
    pub year: i32,
    pub month: u32,
    pub day: u32,
    pub hour: u32,
    pub min: u32,
    pub sec: u32,
    /// Nanoseconds within the second, 0..1e9.
    pub nano: u32,
}

impl UtcTime {
    /// Checks the ranges (month 1..12, day valid for the month, hour < 24,
    /// min < 60, sec ≤ 60, nano < 1e9).
    pub(crate) fn is_valid(&self) -> bool {
        if !(1..=12).contains(&self.month) || self.day == 0 || self.hour >= 24 {
            return false;
        }
        let next = if self.month == 12 {
            days_from_civil(self.year + 1, 1, 1)
        } else {
            days_from_civil(self.year, self.month + 1, 1)
        };
        let len = next - days_from_civil(self.year, self.month, 1);
        (self.day as i64) <= len && self.min < 60 && self.sec <= 60 && self.nano < 1_000_000_000
    }

    /// From a date and nanoseconds since midnight.
    pub(crate) fn from_date_tod(year: i32, month: u32, day: u32, tod_ns: i64) -> Self {
        let s = tod_ns.div_euclid(NS_PER_S);
        UtcTime {
            year,
            month,
            day,
            hour: (s / 3600) as u32,
            min: ((s / 60) % 60) as u32,
            sec: (s % 60) as u32,
            nano: tod_ns.rem_euclid(NS_PER_S) as u32,
        }
    }

    /// From Unix time in nanoseconds (which, like UTC clocks, skips leap
    /// seconds).
    pub fn from_unix_ns(unix_ns: i64) -> Self {
        let days = unix_ns.div_euclid(86_400 * NS_PER_S);
        let tod = unix_ns.rem_euclid(86_400 * NS_PER_S);
        let (y, m, d) = civil_from_days(days);
        Self::from_date_tod(y, m, d, tod)
    }

    /// Seconds since the GPS epoch counted without leap seconds (a leap
    /// second 23:59:60 counts as the next day's 00:00:00) and the ns part.
    fn naive(&self) -> (i64, i64) {
        let days = days_from_civil(self.year, self.month, self.day) - GPS_EPOCH_UNIX_DAYS;
        let s = days * 86_400 + (self.hour * 3600 + self.min * 60 + self.sec) as i64;
        (s, self.nano as i64)
    }
}

/// Inverse of [`days_from_civil`] (H. Hinnant's `civil_from_days`).
pub fn civil_from_days(z: i64) -> (i32, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    ((y + (m <= 2) as i64) as i32, m, d)
}

/// Where the leap-second count comes from.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub enum LeapSource {
    /// Reported by the receiver (NAV-TIMEGPS leapS with leapSValid).
    Receiver,
    /// navsync's table (IERS Bulletin C through 2017-01-01).
    Table,
}

/// GPS − UTC as known while reading a stream: the receiver's value once it
/// has given one, the table before.
#[derive(Clone, Debug, Default)]
pub struct LeapSeconds {
    receiver: Option<i32>,
}

impl LeapSeconds {
    pub fn new() -> Self {
        Self::default()
    }

    /// Records the receiver's GPS − UTC (s).
    pub(crate) fn set_from_receiver(&mut self, leap_s: i32) {
        self.receiver = Some(leap_s);
    }

    /// GPS − UTC (s) at `utc` and where the value came from.
    pub fn at(&self, utc: &UtcTime) -> (i32, LeapSource) {
        match self.receiver {
            Some(l) => (l, LeapSource::Receiver),
            None => {
                // During 23:59:60 the old offset still holds.
                let mut probe = *utc;
                probe.sec = probe.sec.min(59);
                (table_leap_seconds(probe.naive().0), LeapSource::Table)
            }
        }
    }

    /// GPS time of a UTC instant.
    pub fn utc_to_gps(&self, utc: &UtcTime) -> (GpsTime, LeapSource) {
        let (leap, src) = self.at(utc);
        (utc_to_gps_with(utc, leap), src)
    }
}

/// GPS time of a UTC instant given GPS − UTC = `leap_s`.
pub(crate) fn utc_to_gps_with(utc: &UtcTime, leap_s: i32) -> GpsTime {
    let (s, ns) = utc.naive();
    GpsTime::from_ns((s + leap_s as i64) * NS_PER_S + ns)
}

/// GPS time of a UTC instant by the table alone.
pub fn utc_to_gps(utc: &UtcTime) -> GpsTime {
    LeapSeconds::new().utc_to_gps(utc).0
}

/// UTC (as Unix ns) of a GPS instant by the table (a GPS instant inside an
/// inserted leap second maps to the following 00:00:00).
pub fn gps_to_unix_ns(t: GpsTime) -> i64 {
    let gps_s = t.ns().div_euclid(NS_PER_S);
    // The leap count at UTC ≈ GPS − leap; iterate once to settle at steps.
    let mut leap = table_leap_seconds(gps_s) as i64;
    leap = table_leap_seconds(gps_s - leap) as i64;
    t.ns() - leap * NS_PER_S + GPS_EPOCH_UNIX_DAYS * 86_400 * NS_PER_S
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_days_round_trip() {
        for z in [-800_000i64, -1, 0, 3657, 10_957, 17_745, 25_000, 60_000] {
            let (y, m, d) = civil_from_days(z);
            assert_eq!(days_from_civil(y, m, d), z);
        }
        assert_eq!(days_from_civil(1980, 1, 6), GPS_EPOCH_UNIX_DAYS);
    }

    #[test]
    fn known_epochs() {
        // comma2k19 README: GPS = UTC + 18 s in 2018.
        let t = utc_to_gps(&UtcTime::from_unix_ns(1_533_226_488_299 * 1_000_000));
        assert_eq!(t.week(), 2012);
        assert_eq!(t.ns_of_week(), 404_106_299_000_000);
        // NEO-M8L fixture: 2024-01-30 15:31:52 − 422154 ns UTC is iTOW 228730000 ms − 422154 ns.
        let u = UtcTime {
            year: 2024,
            month: 1,
            day: 30,
            hour: 15,
            min: 31,
            sec: 51,
            nano: 999_577_846,
        };
        let g = utc_to_gps(&u);
        assert_eq!(
            (g.week(), g.ns_of_week()),
            (2299, 228_730_000_000_000 - 422_154)
        );
    }

    #[test]
    fn leap_second_2016_12_31() {
        let at = |h, m, s| {
            utc_to_gps(&UtcTime {
                year: 2016,
                month: 12,
                day: 31,
                hour: h,
                min: m,
                sec: s,
                nano: 0,
            })
        };
        let before = at(23, 59, 59);
        let during = at(23, 59, 60);
        let after = utc_to_gps(&UtcTime {
            year: 2017,
            month: 1,
            day: 1,
            hour: 0,
            min: 0,
            sec: 0,
            nano: 0,
        });
        assert_eq!(during - before, NS_PER_S);
        assert_eq!(after - during, NS_PER_S);
    }

    #[test]
    fn receiver_value_wins() {
        let mut l = LeapSeconds::new();
        let u = UtcTime::from_unix_ns(1_700_000_000 * NS_PER_S);
        assert_eq!(l.at(&u), (18, LeapSource::Table));
        l.set_from_receiver(19);
        assert_eq!(l.at(&u), (19, LeapSource::Receiver));
    }

    #[test]
    fn week_rollovers_are_plain_dates() {
        // 2019-04-06 23:59:42 UTC = GPS 2019-04-07 00:00:00 = week 2048 (10-bit rollover).
        let u = UtcTime {
            year: 2019,
            month: 4,
            day: 6,
            hour: 23,
            min: 59,
            sec: 42,
            nano: 0,
        };
        let g = utc_to_gps(&u);
        assert_eq!((g.week(), g.ns_of_week()), (2048, 0));
        assert_eq!(
            gps_to_unix_ns(g),
            days_from_civil(2019, 4, 6) * 86_400 * NS_PER_S + (86_400 - 18) * NS_PER_S
        );
    }
}
