//! The GNSS receiver port: bytes with their arrival stamps in, fixes with
//! the host time their last byte arrived out (seed 002: the serial latency
//! runs from the fix's epoch to the last byte).
//!
//! Reuses the receivers crate: [`StreamReader`] (mixed NMEA + UBX),
//! [`nav_pvt_fix`] and [`NmeaFixes`]. UBX NAV-PVT fixes are complete when
//! their frame is; an NMEA epoch (GGA + GST + RMC/ZDA sharing a time of day)
//! is known complete only when the next epoch's first sentence arrives, so
//! its receive time is that of its own last sentence, one epoch before it
//! is delivered. Once the port has given a NAV-PVT fix, NMEA fixes are
//! ignored (the same epochs twice).
//!
//! Dual-antenna headings (moving-base UBX NAV-RELPOSNED, or NMEA HDT from
//! a GNSS talker with the σ of [`GnssDecoder::set_hdt_sd_deg`]) come out
//! at their epoch's GPS time, by the same rules as `convert`'s heading.txt;
//! the first heading dropped for each reason is noted, the rest counted.
//!
//! With [`GnssDecoder::enable_esf`], the port's UBX ESF-RAW (or, without
//! it, ESF-MEAS) data of a receiver's own IMU come out as rate samples on
//! the sensor time-tag axis with the arrival of their message
//! ([`EsfImu`] pairs the gyro and accelerometer triads; values in the
//! sensor's axes as sent).

use std::collections::BTreeSet;

use navsync::filter::gnss::GnssFix;
use navsync::io::heading::HeadingObs;
use navsync::time::GpsTime;
use navsync_receivers::convert::{hdt_heading, relposned_heading};
use navsync_receivers::fixes::{FixOptions, NmeaFixes, NmeaOutcome, TimeContext, nav_pvt_fix};
use navsync_receivers::imu::{EsfImu, RateSample};
use navsync_receivers::stream::{EventKind, StreamReader};
use navsync_receivers::ubx::UbxMessage;

/// A fix and the host counter (ns) at which its last byte arrived.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct ReceivedFix {
    pub fix: GnssFix,
    pub received_ns: u64,
}

/// An IMU sample from ESF messages and the arrival of its message.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct EsfSample {
    /// Sensor time (time tag × tick, ns from the sensor's origin).
    pub sensor_ns: i64,
    /// Gyro rad/s then specific force m/s², sensor axes.
    pub values: [f64; 6],
    pub arrival_ns: u64,
}

/// What a push produced.
#[derive(Clone, Debug, Default)]
pub(crate) struct Decoded {
    pub fixes: Vec<ReceivedFix>,
    pub imu: Vec<EsfSample>,
    /// Dual-antenna (baseline) headings and the host counter (ns) at which
    /// their last byte arrived.
    pub headings: Vec<(HeadingObs, u64)>,
    /// Problems: corrupt runs, invalid frames, unusable epochs.
    pub notes: Vec<String>,
}

/// ESF decoding state: ESF-RAW once seen (full rate), else ESF-MEAS.
struct Esf {
    raw: EsfImu,
    meas: EsfImu,
    raw_seen: bool,
    rates: Vec<RateSample>,
}

/// Incremental decoder of one receiver port.
pub(crate) struct GnssDecoder {
    reader: StreamReader,
    ctx: TimeContext,
    nmea: NmeaFixes,
    nmea_out: Vec<NmeaOutcome>,
    /// Arrival of the latest NMEA sentence (the open epoch's last so far).
    last_nmea_ns: Option<u64>,
    seen_pvt: bool,
    esf: Option<Esf>,
    /// GPS time of the latest fix (NAV-RELPOSNED's week).
    last_fix_time: Option<GpsTime>,
    /// σ given to HDT headings (deg): HDT carries none.
    hdt_sd_deg: f64,
    /// Reasons a heading was dropped for, already noted once.
    heading_drop_reasons: BTreeSet<String>,
    /// Fixes delivered.
    pub fixes: u64,
    /// Headings delivered and dropped.
    pub headings: u64,
    pub heading_drops: u64,
}

/// σ of an HDT heading when none is set (deg), as `convert --hdt-sd`.
pub(crate) const DEFAULT_HDT_SD_DEG: f64 = 0.5;

impl Default for GnssDecoder {
    fn default() -> Self {
        Self::new(FixOptions::default())
    }
}

impl GnssDecoder {
    pub(crate) fn new(opts: FixOptions) -> Self {
        GnssDecoder {
            reader: StreamReader::new(),
            ctx: TimeContext::default(),
            nmea: NmeaFixes::new(opts),
            nmea_out: Vec::new(),
            last_nmea_ns: None,
            seen_pvt: false,
            esf: None,
            last_fix_time: None,
            hdt_sd_deg: DEFAULT_HDT_SD_DEG,
            heading_drop_reasons: BTreeSet::new(),
            fixes: 0,
            headings: 0,
            heading_drops: 0,
        }
    }

    /// The σ of HDT headings (deg), checked by the caller with
    /// [`navsync_receivers::convert::heading_problem`] (as `convert --hdt-sd`).
    pub(crate) fn set_hdt_sd_deg(&mut self, sd_deg: f64) {
        self.hdt_sd_deg = sd_deg;
    }

    /// A heading not used: noted the first time for its reason.
    fn drop_heading(&mut self, reason: String, notes: &mut Vec<String>) {
        self.heading_drops += 1;
        if self.heading_drop_reasons.insert(reason.clone()) {
            notes.push(format!(
                "{reason}: heading not used (further ones for this reason only counted)"
            ));
        }
    }

    /// Also decode ESF-RAW/ESF-MEAS IMU data; `tick_s` is the sensor
    /// time-tag tick (u-blox: 1 ms for ESF-MEAS; check ESF-RAW's).
    pub(crate) fn enable_esf(&mut self, tick_s: f64) {
        self.esf = Some(Esf {
            raw: EsfImu::new(tick_s),
            meas: EsfImu::new(tick_s),
            raw_seen: false,
            rates: Vec::new(),
        });
    }

    /// Forgets a partial frame (after a reconnect); keeps the time context.
    pub(crate) fn reset_stream(&mut self) {
        self.reader = StreamReader::new();
    }

    /// Bytes that arrived at host counter `arrival_ns`; what they complete
    /// is appended to `out`.
    pub(crate) fn push(&mut self, bytes: &[u8], arrival_ns: u64, out: &mut Decoded) {
        self.reader.push(bytes);
        let notes = &mut out.notes;
        while let Some(ev) = self.reader.next_event() {
            match &ev.kind {
                EventKind::Ubx(UbxMessage::EsfRaw(m)) if self.esf.is_some() => {
                    if let Some(e) = self.esf.as_mut() {
                        e.raw_seen = true;
                        e.raw.push_raw(m, &mut e.rates);
                    }
                }
                EventKind::Ubx(UbxMessage::EsfMeas(m)) if self.esf.is_some() => {
                    if let Some(e) = self.esf.as_mut()
                        && !e.raw_seen
                    {
                        e.meas.push_meas(m, &mut e.rates);
                    }
                }
                EventKind::Ubx(UbxMessage::NavTimeGps(t)) => self.ctx.push_timegps(t),
                EventKind::Ubx(UbxMessage::NavPvt(p)) => match nav_pvt_fix(p, &self.ctx) {
                    Ok(Some(f)) => {
                        self.seen_pvt = true;
                        self.fixes += 1;
                        self.last_fix_time = Some(f.fix.time);
                        out.fixes.push(ReceivedFix {
                            fix: f.fix,
                            received_ns: arrival_ns,
                        });
                    }
                    Ok(None) => {}
                    Err(e) => notes.push(format!("{e}; fix skipped")),
                },
                EventKind::Ubx(UbxMessage::NavRelPosNed(r)) => {
                    match relposned_heading(r, self.last_fix_time) {
                        Ok(h) => {
                            self.headings += 1;
                            out.headings.push((h, arrival_ns));
                        }
                        Err(why) => self.drop_heading(format!("NAV-RELPOSNED: {why}"), notes),
                    }
                }
                EventKind::Ubx(_) | EventKind::Unknown(_) => {}
                EventKind::Nmea(m) => {
                    let epoch_end = self.last_nmea_ns.unwrap_or(arrival_ns);
                    self.last_nmea_ns = Some(arrival_ns);
                    let mut outcomes = std::mem::take(&mut self.nmea_out);
                    self.nmea.push(m, &self.ctx, &mut outcomes);
                    for o in outcomes.drain(..) {
                        match o {
                            NmeaOutcome::Fix(f) if !self.seen_pvt => {
                                self.fixes += 1;
                                self.last_fix_time = Some(f.fix.time);
                                out.fixes.push(ReceivedFix {
                                    fix: f.fix,
                                    received_ns: epoch_end,
                                });
                            }
                            NmeaOutcome::Fix(_) | NmeaOutcome::NoFix { .. } => {}
                            NmeaOutcome::Heading {
                                time,
                                heading_deg,
                                talker,
                                from_gnss,
                            } => match hdt_heading(
                                time,
                                heading_deg,
                                &talker,
                                from_gnss,
                                self.hdt_sd_deg,
                            ) {
                                Ok(h) => {
                                    self.headings += 1;
                                    out.headings.push((h, arrival_ns));
                                }
                                Err(why) => self.drop_heading(why, notes),
                            },
                            NmeaOutcome::NoHeading => self.drop_heading(
                                "HDT with an empty heading (no baseline solution)".into(),
                                notes,
                            ),
                            NmeaOutcome::HeadingProblem(p) => {
                                self.heading_drops += 1;
                                notes.push(p);
                            }
                            NmeaOutcome::Problem(p) => notes.push(p),
                        }
                    }
                    self.nmea_out = outcomes;
                }
                EventKind::Invalid { .. } | EventKind::Corrupt(_) => notes.push(ev.to_string()),
            }
        }
        if let Some(e) = self.esf.as_mut() {
            for r in e.rates.drain(..) {
                let (g, a) = (r.gyro_radps, r.accel_mps2);
                out.imu.push(EsfSample {
                    sensor_ns: r.time.ns(),
                    values: [g.x, g.y, g.z, a.x, a.y, a.z],
                    arrival_ns,
                });
            }
        }
    }
}
