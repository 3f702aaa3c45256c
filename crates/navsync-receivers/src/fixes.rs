//! GNSS fixes in GPS time from receiver messages: UBX NAV-PVT, older UBX
//! epochs (NAV-SOL + NAV-POSLLH + NAV-VELNED + NAV-STATUS, gathered by
//! iTOW), or NMEA epochs (GGA position + GST standard deviations + RMC/ZDA
//! date). Every UBX epoch that gives no fix says why ([`DropReason`]).
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
use navsync::earth::{Geodetic, c_ne, ecef_to_geodetic};
use navsync::filter::gnss::GnssFix;
use navsync::time::{GpsTime, NS_PER_S, NS_PER_WEEK};

use crate::geoid::Egm96Grid;
use crate::gnsstime::{LeapSeconds, LeapSource, UtcTime};
use crate::nmea::{Date, Gga, Gst, Hdt, NmeaMessage, TimeOfDayNs};
use crate::ubx::{
    NavHpPosLlh, NavPosLlh, NavPvat, NavPvt, NavSol, NavStatus, NavTimeGps, NavVelNed, UbxMessage,
    fix_type_name,
};

/// Options for turning messages into fixes.
#[derive(Copy, Clone, Debug)]
pub struct FixOptions {
    /// Standard deviations N, E, D (m) used when the stream gives none
    /// (NMEA without GST).
    pub default_sd_m: [f64; 3],
    /// Keep UBX 3D epochs whose gnssFixOK (GPSfixOK) flag is 0: the
    /// receiver computed them but they fail its DOP/accuracy masks. Their
    /// own accuracy estimates are used as standard deviations.
    pub keep_fix_not_ok: bool,
    /// Keep UBX 2D fixes (fix type 2: height held by the receiver, not
    /// measured), with the receiver's vertical accuracy estimate.
    pub keep_2d: bool,
    /// Keep dead-reckoning-only epochs (fix type 1) of a sensor-fusion
    /// receiver: no GNSS in them, only its own IMU and wheel ticks.
    pub keep_dr_only: bool,
}

impl Default for FixOptions {
    fn default() -> Self {
        FixOptions {
            default_sd_m: [5.0, 5.0, 10.0],
            keep_fix_not_ok: false,
            keep_2d: false,
            keep_dr_only: false,
        }
    }
}

/// Why a UBX navigation epoch gave no fix.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum DropReason {
    /// Fix type other than 3 (3D) or 4 (GNSS + dead reckoning); 2 (2D)
    /// only without [`FixOptions::keep_2d`].
    FixType(u8),
    /// gnssFixOK (NAV-PVT) / GPSfixOK (NAV-SOL, NAV-STATUS) is 0.
    FixNotOk,
    /// NAV-PVT flags3 or NAV-HPPOSLLH flags: invalidLlh.
    InvalidLlh,
    /// NAV-POSLLH / NAV-VELNED without NAV-SOL or NAV-STATUS for the iTOW:
    /// nothing says whether the receiver had a fix.
    NoStatus,
    /// A fix status but no position (NAV-STATUS alone).
    NoPosition,
    /// The GPS week is unknown (no valid UTC date, NAV-SOL week or
    /// NAV-TIMEGPS yet).
    NoTime,
}

impl DropReason {
    /// What the reason means, for the summary and the screen.
    pub fn describe(&self) -> String {
        match self {
            DropReason::FixType(t) => format!("fix type {t} ({})", fix_type_name(*t)),
            DropReason::FixNotOk => {
                "gnssFixOK = 0 (3D solution outside the receiver's DOP/accuracy masks)".into()
            }
            DropReason::InvalidLlh => "invalidLlh set (position flagged invalid)".into(),
            DropReason::NoStatus => {
                "position without NAV-SOL or NAV-STATUS for its iTOW (fix status unknown)".into()
            }
            DropReason::NoPosition => "fix status without a position message".into(),
            DropReason::NoTime => {
                "GPS week unknown (no valid date, NAV-SOL week or NAV-TIMEGPS)".into()
            }
        }
    }

    /// The `navsync convert` option that keeps such epochs, if one does.
    pub fn kept_by(&self) -> Option<&'static str> {
        match self {
            DropReason::FixType(2) => Some("--keep-2d"),
            DropReason::FixType(1) => Some("--keep-dr-only"),
            DropReason::FixNotOk => Some("--keep-fix-not-ok"),
            _ => None,
        }
    }
}

/// Whether a UBX fix status gives a fix under `opts` (fix type first: it
/// is the more telling reason when both fail).
fn check_status(fix_type: u8, fix_ok: bool, opts: &FixOptions) -> Result<(), DropReason> {
    match fix_type {
        3 | 4 => {}
        2 if opts.keep_2d => {}
        // Dead reckoning only: gnssFixOK is 0 by definition.
        1 if opts.keep_dr_only => return Ok(()),
        t => return Err(DropReason::FixType(t)),
    }
    if !fix_ok && !opts.keep_fix_not_ok {
        return Err(DropReason::FixNotOk);
    }
    Ok(())
}

/// A fix and where its parts came from.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ReceiverFix {
    pub fix: GnssFix,
    pub leap: Option<LeapSource>,
    /// Standard deviations were the configured defaults.
    pub default_sd: bool,
    /// The ellipsoidal height used the EGM96 geoid model
    /// ([`crate::geoid`]): the message gave height above mean sea level
    /// without the geoid separation.
    pub(crate) geoid_from_model: bool,
}

/// The GPS week and leap seconds a stream has told so far.
#[derive(Clone, Debug, Default)]
pub struct TimeContext {
    pub leap: LeapSeconds,
    /// Last NAV-TIMEGPS with a valid week: (week, iTOW ms).
    week: Option<(i64, u32)>,
    /// Last NAV-TIMEGPS with a valid TOW: (iTOW ms, fTOW ns).
    ftow: Option<(u32, i32)>,
}

impl TimeContext {
    pub fn push_timegps(&mut self, t: &NavTimeGps) {
        if t.leap_valid() {
            self.leap.set_from_receiver(t.leap_s as i32);
        }
        if t.week_valid() && (0..=MAX_GPS_WEEK).contains(&t.week) {
            self.week = Some((t.week as i64, t.itow_ms));
        }
        if t.tow_valid() {
            self.ftow = Some((t.itow_ms, t.ftow_ns));
        }
    }

    /// fTOW (ns) of the NAV-TIMEGPS of this iTOW, 0 when there was none.
    fn ftow_for(&self, itow_ms: u32) -> i64 {
        match self.ftow {
            Some((i, f)) if i == itow_ms => f as i64,
            _ => 0,
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
    match nav_pvt_epoch(p, ctx, &FixOptions::default()) {
        Ok(f) => Ok(Some(f)),
        Err((DropReason::NoTime, Some(e))) => Err(e),
        Err(_) => Ok(None),
    }
}

/// [`nav_pvt_fix`] under `opts`, with the reason when the epoch gives no
/// fix (and, for [`DropReason::NoTime`], what was wrong with its time).
pub(crate) fn nav_pvt_epoch(
    p: &NavPvt,
    ctx: &TimeContext,
    opts: &FixOptions,
) -> Result<ReceiverFix, (DropReason, Option<String>)> {
    check_status(p.fix_type, p.gnss_fix_ok(), opts).map_err(|r| (r, None))?;
    if p.invalid_llh() {
        return Err((DropReason::InvalidLlh, None));
    }
    let (time, leap) = nav_pvt_time(p, ctx).map_err(|e| (DropReason::NoTime, Some(e)))?;
    let h = p.h_acc_m();
    let v = p.v_acc_m();
    let s = p.s_acc_mps();
    let vel = p.vel_ned_mps();
    Ok(ReceiverFix {
        fix: GnssFix {
            time,
            pos: Geodetic::from_deg(p.lat_deg(), p.lon_deg(), p.height_m()),
            pos_sd: Vector3::new(h, h, v),
            vel: Some(Vector3::new(vel[0], vel[1], vel[2])),
            vel_sd: Some(Vector3::new(s, s, s)),
        },
        leap,
        default_sd: false,
        geoid_from_model: false,
    })
}

// ------------------------------------------------------------ UBX epochs

/// Correlation time (s) assumed for the errors of a receiver's fused
/// (GNSS + dead-reckoning) solution: its filter carries an error for tens
/// of seconds (an assumption; the receivers do not state it).
pub const FUSED_CORRELATION_TIME_S: f64 = 10.0;

/// σ factor for fixes whose errors are a first-order Gauss–Markov process
/// of correlation time `tau_s` sampled every `interval_s`: with lag-one
/// correlation ρ = exp(−Δt/τ), n such fixes carry the information of
/// n·(1 − ρ)/(1 + ρ) independent ones (the AR(1) effective sample size,
/// Bretherton et al. 1999, "The effective number of spatial degrees of
/// freedom of a time-varying field", J. Climate 12), so each fix's
/// variance is scaled by (1 + ρ)/(1 − ρ) for a filter that takes them as
/// white: σ × √20 ≈ 4.5 at 1 Hz and τ = 10 s.
pub fn fused_sd_factor(interval_s: f64, tau_s: f64) -> f64 {
    let rho = (-interval_s / tau_s).exp();
    ((1.0 + rho) / (1.0 - rho)).sqrt()
}

/// Largest GPS week taken from a message (year 2171).
const MAX_GPS_WEEK: i16 = 10_000;

/// Which messages an epoch's fix came from.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum UbxFixSource {
    /// NAV-PVT (position refined by NAV-HPPOSLLH of the same iTOW).
    NavPvt,
    /// NAV-SOL / NAV-POSLLH / NAV-HPPOSLLH / NAV-VELNED / NAV-STATUS of
    /// one iTOW, where the stream has no NAV-PVT for it.
    Combined,
    /// NAV-PVAT of a dead-reckoning receiver (no NAV-PVT for the iTOW):
    /// its fused GNSS + IMU solution, σ inflated by [`fused_sd_factor`].
    NavPvat,
}

impl UbxFixSource {
    pub fn name(&self) -> &'static str {
        match self {
            UbxFixSource::NavPvt => "UBX NAV-PVT",
            UbxFixSource::Combined => "UBX NAV-SOL/POSLLH/VELNED/STATUS",
            UbxFixSource::NavPvat => {
                "UBX NAV-PVAT (the receiver's FUSED GNSS + dead-reckoning solution, σ inflated)"
            }
        }
    }
}

/// What became of one UBX navigation epoch.
#[derive(Clone, Debug, PartialEq)]
pub enum UbxOutcome {
    Fix {
        fix: ReceiverFix,
        source: UbxFixSource,
        /// The position came from NAV-HPPOSLLH.
        high_precision: bool,
    },
    Dropped {
        itow_ms: u32,
        source: UbxFixSource,
        reason: DropReason,
        /// More about it (a time inconsistency), for diagnostics.
        detail: Option<String>,
    },
}

/// The navigation messages of one iTOW.
#[derive(Clone, Debug, Default)]
struct UbxEpoch {
    itow_ms: u32,
    pvt: Option<NavPvt>,
    sol: Option<NavSol>,
    posllh: Option<NavPosLlh>,
    hp: Option<NavHpPosLlh>,
    velned: Option<NavVelNed>,
    status: Option<NavStatus>,
    pvat: Option<NavPvat>,
}

/// Gathers UBX navigation messages by iTOW into epochs and turns each into
/// a fix or a counted drop. A u-blox receiver sends all navigation
/// messages of an epoch together, each carrying the epoch's iTOW ([M8]
/// "Navigation epochs" and "iTOW timestamps"), so an epoch
/// closes when a message of another iTOW arrives (NAV-TIMEGPS included:
/// push it here before [`TimeContext::push_timegps`]), or at
/// [`UbxEpochs::finish`].
#[derive(Clone, Debug, Default)]
pub struct UbxEpochs {
    cur: Option<UbxEpoch>,
    opts: FixOptions,
    /// iTOW of the last NAV-PVAT epoch (ms), for its fix interval.
    last_pvat_itow: Option<u32>,
}

impl UbxEpochs {
    pub fn new(opts: FixOptions) -> Self {
        UbxEpochs {
            cur: None,
            opts,
            last_pvat_itow: None,
        }
    }

    /// Takes a message; epochs closed by it go to `out`. Messages without
    /// navigation content are ignored.
    pub fn push(&mut self, m: &UbxMessage, ctx: &TimeContext, out: &mut Vec<UbxOutcome>) {
        let itow = match m {
            UbxMessage::NavPvt(p) => p.itow_ms,
            UbxMessage::NavSol(p) => p.itow_ms,
            UbxMessage::NavPosLlh(p) => p.itow_ms,
            UbxMessage::NavHpPosLlh(p) => p.itow_ms,
            UbxMessage::NavVelNed(p) => p.itow_ms,
            UbxMessage::NavStatus(p) => p.itow_ms,
            UbxMessage::NavPvat(p) => p.itow_ms,
            UbxMessage::NavTimeGps(t) => {
                if self.cur.as_ref().is_some_and(|e| e.itow_ms != t.itow_ms) {
                    self.close(ctx, out);
                }
                return;
            }
            _ => return,
        };
        if self.cur.as_ref().is_some_and(|e| e.itow_ms != itow) {
            self.close(ctx, out);
        }
        let e = self.cur.get_or_insert_with(|| UbxEpoch {
            itow_ms: itow,
            ..Default::default()
        });
        match m {
            UbxMessage::NavPvt(p) => e.pvt = Some(p.clone()),
            UbxMessage::NavSol(p) => e.sol = Some(p.clone()),
            UbxMessage::NavPosLlh(p) => e.posllh = Some(p.clone()),
            UbxMessage::NavHpPosLlh(p) => e.hp = Some(p.clone()),
            UbxMessage::NavVelNed(p) => e.velned = Some(p.clone()),
            UbxMessage::NavStatus(p) => e.status = Some(p.clone()),
            UbxMessage::NavPvat(p) => e.pvat = Some(p.clone()),
            _ => {}
        }
    }

    /// Closes the open epoch.
    pub fn finish(&mut self, ctx: &TimeContext, out: &mut Vec<UbxOutcome>) {
        self.close(ctx, out);
    }

    fn close(&mut self, ctx: &TimeContext, out: &mut Vec<UbxOutcome>) {
        let Some(e) = self.cur.take() else { return };
        if e.pvt.is_none()
            && let Some(p) = &e.pvat
        {
            out.push(self.pvat_epoch(p, ctx));
            return;
        }
        let hp = e.hp.as_ref().filter(|h| !h.invalid_llh());
        if let Some(p) = &e.pvt {
            let source = UbxFixSource::NavPvt;
            out.push(match nav_pvt_epoch(p, ctx, &self.opts) {
                Ok(mut fix) => {
                    if let Some(h) = hp {
                        fix.fix.pos = Geodetic::from_deg(h.lat_deg(), h.lon_deg(), h.height_m());
                        fix.fix.pos_sd = Vector3::new(h.h_acc_m(), h.h_acc_m(), h.v_acc_m());
                    }
                    UbxOutcome::Fix {
                        fix,
                        source,
                        high_precision: hp.is_some(),
                    }
                }
                Err((reason, detail)) => UbxOutcome::Dropped {
                    itow_ms: e.itow_ms,
                    source,
                    reason,
                    detail,
                },
            });
            return;
        }
        out.push(match self.combined(&e, hp, ctx) {
            Ok((fix, high_precision)) => UbxOutcome::Fix {
                fix,
                source: UbxFixSource::Combined,
                high_precision,
            },
            Err((reason, detail)) => UbxOutcome::Dropped {
                itow_ms: e.itow_ms,
                source: UbxFixSource::Combined,
                reason,
                detail,
            },
        });
    }

    /// A NAV-PVAT epoch: NAV-PVT's rules on its fields, then the σ scaled
    /// by [`fused_sd_factor`] for the fix interval since the last one.
    fn pvat_epoch(&mut self, p: &NavPvat, ctx: &TimeContext) -> UbxOutcome {
        let interval_s = self
            .last_pvat_itow
            .map(|l| p.itow_ms.wrapping_sub(l) as f64 * 1e-3)
            .filter(|d| *d > 0.0 && *d <= 60.0)
            .unwrap_or(1.0);
        self.last_pvat_itow = Some(p.itow_ms);
        let source = UbxFixSource::NavPvat;
        match nav_pvt_epoch(&p.as_nav_pvt(), ctx, &self.opts) {
            Ok(mut fix) => {
                let k = fused_sd_factor(interval_s, FUSED_CORRELATION_TIME_S);
                fix.fix.pos_sd *= k;
                fix.fix.vel_sd = fix.fix.vel_sd.map(|v| v * k);
                UbxOutcome::Fix {
                    fix,
                    source,
                    high_precision: false,
                }
            }
            Err((reason, detail)) => UbxOutcome::Dropped {
                itow_ms: p.itow_ms,
                source,
                reason,
                detail,
            },
        }
    }

    /// A fix from the pre-NAV-PVT messages of one epoch: status from
    /// NAV-SOL (else NAV-STATUS); position from NAV-HPPOSLLH, else
    /// NAV-POSLLH (hAcc on N and E, vAcc down), else NAV-SOL's ECEF
    /// position (pAcc, a 3D accuracy, on each axis); velocity from
    /// NAV-VELNED, else NAV-SOL's ECEF velocity rotated to NED (sAcc on
    /// each axis); time iTOW + fTOW of NAV-SOL's week when WKNSET and
    /// TOWSET, else of the last NAV-TIMEGPS week.
    fn combined(
        &self,
        e: &UbxEpoch,
        hp: Option<&NavHpPosLlh>,
        ctx: &TimeContext,
    ) -> Result<(ReceiverFix, bool), (DropReason, Option<String>)> {
        let status = match (&e.sol, &e.status) {
            (Some(s), _) => Some((s.gps_fix, s.gps_fix_ok())),
            (None, Some(s)) => Some((s.gps_fix, s.gps_fix_ok())),
            (None, None) => None,
        };
        let Some((fix_type, fix_ok)) = status else {
            return Err((DropReason::NoStatus, None));
        };
        check_status(fix_type, fix_ok, &self.opts).map_err(|r| (r, None))?;
        if e.hp.is_some() && hp.is_none() && e.posllh.is_none() && e.sol.is_none() {
            return Err((DropReason::InvalidLlh, None));
        }
        let (pos, pos_sd) = if let Some(h) = hp {
            (
                Geodetic::from_deg(h.lat_deg(), h.lon_deg(), h.height_m()),
                Vector3::new(h.h_acc_m(), h.h_acc_m(), h.v_acc_m()),
            )
        } else if let Some(p) = &e.posllh {
            (
                Geodetic::from_deg(p.lat_deg(), p.lon_deg(), p.height_m()),
                Vector3::new(p.h_acc_m(), p.h_acc_m(), p.v_acc_m()),
            )
        } else if let Some(s) = &e.sol {
            let [x, y, z] = s.ecef_m();
            let a = s.p_acc_m();
            (
                ecef_to_geodetic(&Vector3::new(x, y, z)),
                Vector3::new(a, a, a),
            )
        } else {
            return Err((DropReason::NoPosition, None));
        };
        let (vel, vel_sd) = if let Some(v) = &e.velned {
            let [n, east, d] = v.vel_ned_mps();
            let a = v.s_acc_mps();
            (Some(Vector3::new(n, east, d)), Some(Vector3::new(a, a, a)))
        } else if let Some(s) = &e.sol {
            let [x, y, z] = s.ecef_vel_mps();
            let a = s.s_acc_mps();
            let ned = c_ne(&pos).transpose() * Vector3::new(x, y, z);
            (Some(ned), Some(Vector3::new(a, a, a)))
        } else {
            (None, None)
        };
        let itow_ns = e.itow_ms as i64 * 1_000_000;
        let time = match &e.sol {
            Some(s) if s.week_and_tow_valid() => {
                // GPS weeks stay far below 10000 (year 2171); larger or
                // negative weeks are corrupt and would overflow the ns.
                if !(0..=MAX_GPS_WEEK).contains(&s.week) {
                    return Err((
                        DropReason::NoTime,
                        Some(format!(
                            "NAV-SOL iTOW {} ms: week {} out of range",
                            e.itow_ms, s.week
                        )),
                    ));
                }
                GpsTime::from_week_ns(s.week as i64, itow_ns + s.ftow_ns as i64)
            }
            _ => match ctx.week_for(e.itow_ms) {
                Some(w) => GpsTime::from_week_ns(w, itow_ns + ctx.ftow_for(e.itow_ms)),
                None => {
                    return Err((
                        DropReason::NoTime,
                        Some(format!(
                            "UBX epoch iTOW {} ms: no NAV-SOL week and no NAV-TIMEGPS week yet",
                            e.itow_ms
                        )),
                    ));
                }
            },
        };
        Ok((
            ReceiverFix {
                fix: GnssFix {
                    time,
                    pos,
                    pos_sd,
                    vel,
                    vel_sd,
                },
                leap: None,
                default_sd: false,
                geoid_from_model: false,
            },
            hp.is_some(),
        ))
    }
}

/// One NMEA epoch being gathered (sentences sharing a time of day).
#[derive(Clone, Debug, Default)]
struct NmeaEpoch {
    tod: TimeOfDayNs,
    gga: Option<Gga>,
    gst: Option<Gst>,
    hdt: Option<Hdt>,
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
    /// For GGA without a geoid separation.
    geoid: Egm96Grid,
}

/// What happened to an NMEA epoch.
#[derive(Clone, Debug, PartialEq)]
pub enum NmeaOutcome {
    Fix(ReceiverFix),
    /// No usable position, and why.
    NoFix {
        tod: TimeOfDayNs,
        reason: NmeaDrop,
    },
    /// A GGA that could not be used (no time, date or altitude…), said in
    /// a sentence for the diagnostics.
    Problem(String),
    /// An epoch's HDT heading (degrees true, in [0, 360)) at the epoch's
    /// GPS time; `from_gnss`: sent by a GNSS talker (a dual-antenna
    /// baseline), see [`Hdt::from_gnss`].
    Heading {
        time: GpsTime,
        heading_deg: f64,
        talker: String,
        from_gnss: bool,
    },
    /// An HDT whose heading field is empty (no baseline solution).
    NoHeading,
    /// An HDT that could not be used, said in a sentence.
    HeadingProblem(String),
}

/// Why an NMEA epoch gave no fix although nothing was wrong with it.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum NmeaDrop {
    /// Sentences of one time (RMC, GST, ZDA) without a GGA: not a position
    /// epoch.
    NoGga,
    /// GGA fix quality other than 1..=5 (NMEA 0183 GGA field 6: 0 invalid,
    /// 6 estimated/dead reckoning, 7 manual input, 8 simulation).
    Quality(u8),
    /// GGA with a valid quality but empty latitude or longitude.
    NoPosition,
}

impl NmeaDrop {
    pub fn describe(&self) -> String {
        match self {
            NmeaDrop::NoGga => "no GGA sentence in the epoch".into(),
            NmeaDrop::Quality(q) => format!(
                "GGA fix quality {q} ({})",
                match q {
                    0 => "invalid: no fix",
                    6 => "estimated (dead reckoning)",
                    7 => "manual input",
                    8 => "simulation",
                    _ => "not a fix",
                }
            ),
            NmeaDrop::NoPosition => "GGA without latitude or longitude".into(),
        }
    }
}

impl NmeaFixes {
    pub fn new(opts: FixOptions) -> Self {
        NmeaFixes {
            opts,
            ..Default::default()
        }
    }

    pub fn push(&mut self, m: &NmeaMessage, ctx: &TimeContext, out: &mut Vec<NmeaOutcome>) {
        // HDT has no time: it joins the epoch whose timed sentences came
        // before it (receivers send an epoch's sentences together).
        if let NmeaMessage::Hdt(h) = m {
            match self.cur.as_mut() {
                Some(e) => e.hdt = Some(h.clone()),
                None => out.push(NmeaOutcome::HeadingProblem(format!(
                    "{}HDT before any timed sentence (GGA, RMC, GST or ZDA): its time is unknown; skipped",
                    h.talker
                ))),
            }
            return;
        }
        let (tod, date) = match m {
            NmeaMessage::Gga(g) => (g.time_of_day_ns, None),
            NmeaMessage::Gst(g) => (g.time_of_day_ns, None),
            NmeaMessage::Rmc(r) => (r.time_of_day_ns, r.date),
            NmeaMessage::Zda(z) => (z.time_of_day_ns, z.date),
            NmeaMessage::Hdt(_) => return,
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
            if e.hdt.is_some() {
                out.push(NmeaOutcome::HeadingProblem(format!(
                    "HDT at {} s of day: no date in the stream (needs RMC or ZDA); skipped",
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
            out.extend(epoch_heading(&u, ctx));
        }
        out.push(self.epoch_fix(&e, ctx));
        out.extend(epoch_heading(&e, ctx));
    }

    fn epoch_fix(&mut self, e: &NmeaEpoch, ctx: &TimeContext) -> NmeaOutcome {
        let no_fix = |reason| NmeaOutcome::NoFix { tod: e.tod, reason };
        let Some(g) = &e.gga else {
            return no_fix(NmeaDrop::NoGga);
        };
        if !(1..=5).contains(&g.quality) {
            return no_fix(NmeaDrop::Quality(g.quality));
        }
        let (Some(lat), Some(lon)) = (g.lat_deg, g.lon_deg) else {
            return no_fix(NmeaDrop::NoPosition);
        };
        // NMEA 0183 GGA field 9 is the antenna altitude above mean sea
        // level (geoid), field 11 the geoid separation; when a receiver
        // leaves field 11 empty, EGM96 gives it (as gpsd does).
        let (h, geoid_from_model) = match (g.alt_msl_m, g.geoid_sep_m) {
            (Some(a), Some(n)) => (a + n, false),
            (Some(a), None) => match self.geoid.separation_m(lat, lon) {
                Some(n) => (a + n, true),
                None => {
                    return NmeaOutcome::Problem(format!(
                        "GGA at {} s of day: position {lat}, {lon} outside the geoid model; skipped",
                        e.tod as f64 * 1e-9
                    ));
                }
            },
            (None, _) => {
                return NmeaOutcome::Problem(format!(
                    "GGA at {} s of day lacks the altitude: no height; skipped",
                    e.tod as f64 * 1e-9
                ));
            }
        };
        let Some(date) = e.date else {
            return NmeaOutcome::Problem(format!(
                "GGA at {} s of day: no date; skipped",
                e.tod as f64 * 1e-9
            ));
        };
        let (time, src) = match epoch_gps_time(date, e.tod, ctx) {
            Ok(t) => t,
            Err(utc) => {
                return NmeaOutcome::Problem(format!("invalid UTC date/time {utc:?}; skipped"));
            }
        };
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
            geoid_from_model,
        })
    }
}

/// The GPS time of an epoch's UTC date and time of day, and where its leap
/// seconds came from; the UTC time itself when it is not a valid one.
fn epoch_gps_time(
    date: Date,
    tod: TimeOfDayNs,
    ctx: &TimeContext,
) -> Result<(GpsTime, LeapSource), UtcTime> {
    let utc = UtcTime::from_date_tod(date.year, date.month, date.day, tod);
    if !utc.is_valid() {
        return Err(utc);
    }
    Ok(ctx.leap.utc_to_gps(&utc))
}

/// The HDT heading of a dated epoch, at the epoch's GPS time.
fn epoch_heading(e: &NmeaEpoch, ctx: &TimeContext) -> Option<NmeaOutcome> {
    let h = e.hdt.as_ref()?;
    let Some(deg) = h.heading_deg else {
        return Some(NmeaOutcome::NoHeading);
    };
    let when = e.tod as f64 * 1e-9;
    if !(deg.is_finite() && (0.0..360.0).contains(&deg)) {
        return Some(NmeaOutcome::HeadingProblem(format!(
            "{}HDT at {when} s of day: heading {deg}° outside [0, 360); skipped",
            h.talker
        )));
    }
    let (time, _) = match epoch_gps_time(e.date?, e.tod, ctx) {
        Ok(t) => t,
        Err(utc) => {
            return Some(NmeaOutcome::HeadingProblem(format!(
                "{}HDT at {when} s of day: invalid UTC date/time {utc:?}; skipped",
                h.talker
            )));
        }
    };
    Some(NmeaOutcome::Heading {
        time,
        heading_deg: deg,
        talker: h.talker.clone(),
        from_gnss: h.from_gnss(),
    })
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

    fn hdt(talker: &str, deg: Option<f64>) -> NmeaMessage {
        NmeaMessage::Hdt(Hdt {
            talker: talker.into(),
            heading_deg: deg,
        })
    }

    /// HDT joins the epoch of the timed sentences before it, takes its GPS
    /// time (dated by the RMC), and is reported when it has no epoch, no
    /// heading or a heading outside [0, 360).
    #[test]
    fn hdt_takes_its_epochs_time_and_bad_ones_are_reported() {
        let ctx = TimeContext::default();
        let mut f = NmeaFixes::new(FixOptions::default());
        let mut out = Vec::new();
        f.push(&hdt("GN", Some(10.0)), &ctx, &mut out); // no epoch yet
        let rmc = |tod_s: i64| {
            NmeaMessage::Rmc(Rmc {
                talker: "GN".into(),
                time_of_day_ns: Some(tod_s * NS_PER_S),
                date: Some(Date {
                    year: 2026,
                    month: 12,
                    day: 3,
                }),
                valid: true,
                lat_deg: None,
                lon_deg: None,
                speed_knots: None,
                course_deg: None,
            })
        };
        for (t, h) in [
            (100, Some(45.25)),
            (101, None),
            (102, Some(360.0)),
            (103, Some(359.9)),
        ] {
            f.push(&gga(t), &ctx, &mut out);
            f.push(&rmc(t), &ctx, &mut out);
            f.push(&hdt(if t == 103 { "HE" } else { "GN" }, h), &ctx, &mut out);
        }
        f.finish(&ctx, &mut out);
        let day = utc_to_gps_date(2026, 12, 3);
        let headings: Vec<_> = out
            .iter()
            .filter_map(|o| match o {
                NmeaOutcome::Heading {
                    time,
                    heading_deg,
                    from_gnss,
                    ..
                } => Some((*time, *heading_deg, *from_gnss)),
                _ => None,
            })
            .collect();
        assert_eq!(
            headings,
            vec![
                (day + 100 * NS_PER_S, 45.25, true),
                (day + 103 * NS_PER_S, 359.9, false)
            ]
        );
        let problems: Vec<_> = out
            .iter()
            .filter_map(|o| match o {
                NmeaOutcome::HeadingProblem(p) => Some(p.as_str()),
                _ => None,
            })
            .collect();
        assert_eq!(problems.len(), 2, "{problems:?}");
        assert!(problems[0].contains("before any timed sentence"));
        assert!(problems[1].contains("360") && problems[1].contains("102 s of day"));
        assert_eq!(
            out.iter()
                .filter(|o| matches!(o, NmeaOutcome::NoHeading))
                .count(),
            1
        );
        // The fixes are untouched by the headings.
        assert_eq!(
            out.iter()
                .filter(|o| matches!(o, NmeaOutcome::Fix(_)))
                .count(),
            4
        );
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
