//! GNSS fixes in GPS time from receiver messages: UBX NAV-PVT, or NMEA
//! epochs (GGA position + GST standard deviations + RMC/ZDA date).
//!
//! Time of validity is the message's own epoch, never its arrival:
//! - NAV-PVT: iTOW is GPS time of week rounded to the ms; the exact epoch
//!   is iTOW + δ where δ (|δ| < 0.5 ms, = NAV-TIMEGPS fTOW) is the
//!   difference of the UTC fraction of second (`nano`, [M8] UBX-NAV-PVT)
//!   and iTOW's, since GPS − UTC is a whole number of seconds. The week
//!   comes from the UTC date (+ leap seconds) when valid, else from the
//!   last NAV-TIMEGPS week: dates and full week numbers make it safe across
//!   10-bit week rollovers.
//! - NMEA: UTC date + time of day → GPS with the receiver's leap seconds
//!   when the stream gave them (NAV-TIMEGPS), else the table.

use nalgebra::Vector3;
use navsync::earth::Geodetic;
use navsync::filter::gnss::GnssFix;
use navsync::time::{GpsTime, NS_PER_S, NS_PER_WEEK};

use crate::gnsstime::{LeapSeconds, LeapSource, UtcTime};
use crate::nmea::{Date, Gga, Gst, NmeaMessage, TimeOfDayNs};
use crate::ubx::{NavPvt, NavTimeGps};

/// Options for turning messages into fixes.
#[derive(Copy, Clone, Debug)]
pub struct FixOptions {
    /// Standard deviations N, E, D (m) used when the stream gives none
    /// (NMEA without GST).
    pub default_sd_m: [f64; 3],
}

impl Default for FixOptions {
    fn default() -> Self {
        FixOptions {
            default_sd_m: [5.0, 5.0, 10.0],
        }
    }
}

/// A fix and where its parts came from.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ReceiverFix {
    pub fix: GnssFix,
    pub leap: Option<LeapSource>,
    /// Standard deviations were the configured defaults.
    pub default_sd: bool,
}

/// The GPS week and leap seconds a stream has told so far.
#[derive(Clone, Debug, Default)]
pub struct TimeContext {
    pub leap: LeapSeconds,
    /// Last NAV-TIMEGPS with a valid week: (week, iTOW ms).
    week: Option<(i64, u32)>,
}

impl TimeContext {
    pub fn push_timegps(&mut self, t: &NavTimeGps) {
        if t.leap_valid() {
            self.leap.set_from_receiver(t.leap_s as i32);
        }
        if t.week_valid() {
            self.week = Some((t.week as i64, t.itow_ms));
        }
    }

    /// Week of an iTOW from the last NAV-TIMEGPS, one week on when iTOW
    /// fell back by more than half a week (a rollover since).
    fn week_for(&self, itow_ms: u32) -> Option<i64> {
        let (w, last) = self.week?;
        let back = last as i64 - itow_ms as i64;
        Some(if back > NS_PER_WEEK / 2_000_000 {
            w + 1
        } else {
            w
        })
    }
}

/// GPS time of a NAV-PVT epoch (see the module notes), or why not.
pub fn nav_pvt_time(
    p: &NavPvt,
    ctx: &TimeContext,
) -> Result<(GpsTime, Option<LeapSource>), String> {
    let itow_ns = p.itow_ms as i64 * 1_000_000;
    let delta = if p.valid_time() {
        let utc_frac = (p.nano_ns as i64).rem_euclid(NS_PER_S);
        let itow_frac = itow_ns.rem_euclid(NS_PER_S);
        (utc_frac - itow_frac + NS_PER_S / 2).rem_euclid(NS_PER_S) - NS_PER_S / 2
    } else {
        0
    };
    let utc = (p.valid_date() && p.valid_time()).then_some({
        // date/time fields are rounded; nano corrects them (may be < 0).
        UtcTime {
            year: p.year as i32,
            month: p.month as u32,
            day: p.day as u32,
            hour: p.hour as u32,
            min: p.min as u32,
            sec: p.sec as u32,
            nano: 0,
        }
    });
    if let Some(u) = utc.filter(|u| u.is_valid()) {
        let (t0, src) = ctx.leap.utc_to_gps(&u);
        let approx = t0 + p.nano_ns as i64;
        // The week that puts iTOW + δ nearest the UTC-derived time.
        let tow = itow_ns + delta;
        let w = (approx.ns() - tow + NS_PER_WEEK / 2).div_euclid(NS_PER_WEEK);
        let t = GpsTime::from_week_ns(w, tow);
        if (t - approx).abs() > 2 * NS_PER_S {
            return Err(format!(
                "NAV-PVT iTOW {} ms disagrees with its UTC time by {:.3} s",
                p.itow_ms,
                (t - approx) as f64 * 1e-9
            ));
        }
        return Ok((t, Some(src)));
    }
    match ctx.week_for(p.itow_ms) {
        Some(w) => Ok((GpsTime::from_week_ns(w, itow_ns + delta), None)),
        None => Err(format!(
            "NAV-PVT iTOW {} ms: no valid UTC date and no NAV-TIMEGPS week yet",
            p.itow_ms
        )),
    }
}

/// A fix from NAV-PVT when it holds a usable 3D solution: gnssFixOK, fix
/// type 3 (3D) or 4 (GNSS + dead reckoning), valid position. Standard
/// deviations: hAcc on north and east and vAcc down, sAcc on each velocity
/// axis (u-blox gives accuracy estimates, not covariances; using hAcc per
/// axis is the conservative reading, as the ROS u-blox drivers do).
pub fn nav_pvt_fix(p: &NavPvt, ctx: &TimeContext) -> Result<Option<ReceiverFix>, String> {
    if !p.gnss_fix_ok() || !matches!(p.fix_type, 3 | 4) || p.invalid_llh() {
        return Ok(None);
    }
    let (time, leap) = nav_pvt_time(p, ctx)?;
    let h = p.h_acc_m();
    let v = p.v_acc_m();
    let s = p.s_acc_mps();
    let vel = p.vel_ned_mps();
    Ok(Some(ReceiverFix {
        fix: GnssFix {
            time,
            pos: Geodetic::from_deg(p.lat_deg(), p.lon_deg(), p.height_m()),
            pos_sd: Vector3::new(h, h, v),
            vel: Some(Vector3::new(vel[0], vel[1], vel[2])),
            vel_sd: Some(Vector3::new(s, s, s)),
        },
        leap,
        default_sd: false,
    }))
}

/// One NMEA epoch being gathered (sentences sharing a time of day).
#[derive(Clone, Debug, Default)]
struct NmeaEpoch {
    tod: TimeOfDayNs,
    gga: Option<Gga>,
    gst: Option<Gst>,
    date: Option<Date>,
}

/// Gathers NMEA sentences into epochs and turns each into a fix.
#[derive(Clone, Debug, Default)]
pub struct NmeaFixes {
    cur: Option<NmeaEpoch>,
    /// Last dated epoch: (date, time of day), to carry the date forward
    /// across midnight.
    last_dated: Option<(Date, TimeOfDayNs)>,
    /// Epochs seen before any date.
    undated: Vec<NmeaEpoch>,
    opts: FixOptions,
}

/// What happened to an NMEA epoch.
#[derive(Clone, Debug, PartialEq)]
pub enum NmeaOutcome {
    Fix(ReceiverFix),
    /// No usable position (quality 0, empty fields, no GGA).
    NoFix {
        tod: TimeOfDayNs,
    },
    Problem(String),
}

impl NmeaFixes {
    pub fn new(opts: FixOptions) -> Self {
        NmeaFixes {
            opts,
            ..Default::default()
        }
    }

    pub fn push(&mut self, m: &NmeaMessage, ctx: &TimeContext, out: &mut Vec<NmeaOutcome>) {
        let (tod, date) = match m {
            NmeaMessage::Gga(g) => (g.time_of_day_ns, None),
            NmeaMessage::Gst(g) => (g.time_of_day_ns, None),
            NmeaMessage::Rmc(r) => (r.time_of_day_ns, r.date),
            NmeaMessage::Zda(z) => (z.time_of_day_ns, z.date),
        };
        let Some(tod) = tod else {
            if let NmeaMessage::Gga(_) = m {
                out.push(NmeaOutcome::Problem("GGA without time: skipped".into()));
            }
            return;
        };
        if self.cur.as_ref().is_some_and(|e| e.tod != tod) {
            self.close(ctx, out);
        }
        let e = self.cur.get_or_insert_with(|| NmeaEpoch {
            tod,
            ..Default::default()
        });
        match m {
            NmeaMessage::Gga(g) => e.gga = Some(g.clone()),
            NmeaMessage::Gst(g) => e.gst = Some(g.clone()),
            _ => {}
        }
        if date.is_some() {
            e.date = date;
        }
    }

    /// Closes the open epoch and reports epochs that never got a date.
    pub fn finish(&mut self, ctx: &TimeContext, out: &mut Vec<NmeaOutcome>) {
        self.close(ctx, out);
        for e in self.undated.drain(..) {
            if e.gga.is_some() {
                out.push(NmeaOutcome::Problem(format!(
                    "GGA at {} s of day: no date in the stream (needs RMC or ZDA); skipped",
                    e.tod as f64 * 1e-9
                )));
            }
        }
    }

    fn close(&mut self, ctx: &TimeContext, out: &mut Vec<NmeaOutcome>) {
        let Some(mut e) = self.cur.take() else { return };
        if e.date.is_none() {
            e.date = self.last_dated.map(|(d, t)| {
                if e.tod < t - 12 * 3600 * NS_PER_S {
                    next_day(d)
                } else {
                    d
                }
            });
        }
        let Some(date) = e.date else {
            self.undated.push(e);
            return;
        };
        self.last_dated = Some((date, e.tod));
        // Epochs before the first date: same day, or the day before when
        // their time of day is later (they preceded midnight).
        for u in std::mem::take(&mut self.undated) {
            let mut u = u;
            u.date = Some(if u.tod > e.tod { prev_day(date) } else { date });
            out.push(self.epoch_fix(&u, ctx));
        }
        out.push(self.epoch_fix(&e, ctx));
    }

    fn epoch_fix(&self, e: &NmeaEpoch, ctx: &TimeContext) -> NmeaOutcome {
        let Some(g) = &e.gga else {
            return NmeaOutcome::NoFix { tod: e.tod };
        };
        let (Some(lat), Some(lon)) = (g.lat_deg, g.lon_deg) else {
            return NmeaOutcome::NoFix { tod: e.tod };
        };
        if !g.has_fix() {
            return NmeaOutcome::NoFix { tod: e.tod };
        }
        let Some(h) = g.ellipsoidal_height_m() else {
            return NmeaOutcome::Problem(format!(
                "GGA at {} s of day lacks altitude or geoid separation: no ellipsoidal height; skipped",
                e.tod as f64 * 1e-9
            ));
        };
        let Some(date) = e.date else {
            return NmeaOutcome::NoFix { tod: e.tod };
        };
        let utc = UtcTime::from_date_tod(date.year, date.month, date.day, e.tod);
        if !utc.is_valid() {
            return NmeaOutcome::Problem(format!("invalid UTC date/time {utc:?}; skipped"));
        }
        let (time, src) = ctx.leap.utc_to_gps(&utc);
        let gst_sd = e.gst.as_ref().and_then(|s| {
            let v = [s.lat_sd_m?, s.lon_sd_m?, s.alt_sd_m?];
            v.iter().all(|x| x.is_finite() && *x > 0.0).then_some(v)
        });
        let (sd, default_sd) = match gst_sd {
            Some(v) => (v, false),
            None => (self.opts.default_sd_m, true),
        };
        NmeaOutcome::Fix(ReceiverFix {
            fix: GnssFix {
                time,
                pos: Geodetic::from_deg(lat, lon, h),
                pos_sd: Vector3::new(sd[0], sd[1], sd[2]),
                vel: None,
                vel_sd: None,
            },
            leap: Some(src),
            default_sd,
        })
    }
}

fn next_day(d: Date) -> Date {
    let z = crate::gnsstime::days_from_civil(d.year, d.month, d.day) + 1;
    let (year, month, day) = crate::gnsstime::civil_from_days(z);
    Date { year, month, day }
}

fn prev_day(d: Date) -> Date {
    let z = crate::gnsstime::days_from_civil(d.year, d.month, d.day) - 1;
    let (year, month, day) = crate::gnsstime::civil_from_days(z);
    Date { year, month, day }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nmea::{Rmc, Zda};

    fn gga(tod_s: i64) -> NmeaMessage {
        NmeaMessage::Gga(Gga {
            talker: "GN".into(),
            time_of_day_ns: Some(tod_s * NS_PER_S),
            lat_deg: Some(44.0),
            lon_deg: Some(-121.0),
            quality: 1,
            num_sv: Some(10),
            hdop: Some(0.8),
            alt_msl_m: Some(1000.0),
            geoid_sep_m: Some(-20.0),
        })
    }

    #[test]
    fn nmea_epochs_cross_midnight_and_back_date_early_gga() {
        let ctx = TimeContext::default();
        let mut f = NmeaFixes::new(FixOptions::default());
        let mut out = Vec::new();
        f.push(&gga(86_399), &ctx, &mut out); // before any date
        let rmc = NmeaMessage::Rmc(Rmc {
            talker: "GN".into(),
            time_of_day_ns: Some(5 * NS_PER_S),
            date: Some(Date {
                year: 2021,
                month: 12,
                day: 23,
            }),
            valid: true,
            lat_deg: None,
            lon_deg: None,
            speed_knots: None,
            course_deg: None,
        });
        f.push(&rmc, &ctx, &mut out);
        f.push(&gga(5), &ctx, &mut out);
        f.push(&gga(6), &ctx, &mut out);
        f.finish(&ctx, &mut out);
        let fixes: Vec<_> = out
            .iter()
            .filter_map(|o| {
                if let NmeaOutcome::Fix(f) = o {
                    Some(f.fix.time)
                } else {
                    None
                }
            })
            .collect();
        assert_eq!(fixes.len(), 3);
        let day = utc_to_gps_date(2021, 12, 23);
        assert_eq!(fixes[0], day + (-NS_PER_S)); // 23:59:59 on the 22nd
        assert_eq!(fixes[1], day + 5 * NS_PER_S);
        assert_eq!(fixes[2], day + 6 * NS_PER_S);
        let _ = Zda {
            talker: String::new(),
            time_of_day_ns: None,
            date: None,
        };
    }

    fn utc_to_gps_date(y: i32, m: u32, d: u32) -> GpsTime {
        crate::gnsstime::utc_to_gps(&UtcTime {
            year: y,
            month: m,
            day: d,
            hour: 0,
            min: 0,
            sec: 0,
            nano: 0,
        })
    }
}
