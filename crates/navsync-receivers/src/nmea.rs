//! NMEA 0183 sentences navsync reads: GGA (position), RMC (date, speed,
//! course), GST (position standard deviations), ZDA (date and time), HDT
//! (true heading: a dual-antenna receiver's baseline azimuth).
//!
//! The stream reader ([`crate::stream`]) finds sentences and verifies their
//! checksum (NMEA 0183 v4.10 §5.2.1: XOR of the bytes between `$` and `*`,
//! two upper-case hex digits); field parsing is done by the `nmea` crate
//! (DEPENDENCIES.md), whose values are turned here into navsync's types.
//! The encoders write the same sentences (tests, simulators, and the
//! PTY-fed live tests to come).

use chrono::{Datelike, NaiveTime, Timelike};

/// NMEA 0183 checksum: XOR of every byte between `$` and `*`.
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |c, &x| c ^ x)
}

/// `$<body>*HH\r\n` for a body such as `GPGGA,...`.
pub fn encode_sentence(body: &str) -> String {
    format!("${body}*{:02X}\r\n", checksum(body.as_bytes()))
}

/// Nanoseconds since midnight UTC.
pub(crate) type TimeOfDayNs = i64;

fn tod_ns(t: NaiveTime) -> TimeOfDayNs {
    t.num_seconds_from_midnight() as i64 * 1_000_000_000 + t.nanosecond() as i64
}

/// A calendar date (UTC).
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Date {
    pub year: i32,
    pub month: u32,
    pub day: u32,
}

/// GGA: fix data. Heights as sent: `alt_msl_m` above mean sea level and the
/// geoid separation, whose sum is the ellipsoidal height.
#[derive(Clone, Debug, PartialEq)]
pub struct Gga {
    pub talker: String,
    pub time_of_day_ns: Option<TimeOfDayNs>,
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    /// Fix quality: 0 invalid, 1 GPS, 2 DGPS, 3 PPS, 4 RTK fixed, 5 RTK
    /// float, 6 estimated, 7 manual, 8 simulation.
    pub quality: u8,
    pub num_sv: Option<u32>,
    pub hdop: Option<f32>,
    pub alt_msl_m: Option<f64>,
    pub geoid_sep_m: Option<f64>,
}

impl Gga {
    /// Ellipsoidal height (m) when both parts are present.
    #[cfg(test)]
    pub(crate) fn ellipsoidal_height_m(&self) -> Option<f64> {
        Some(self.alt_msl_m? + self.geoid_sep_m?)
    }
}

/// RMC: recommended minimum data.
#[derive(Clone, Debug, PartialEq)]
pub struct Rmc {
    pub talker: String,
    pub time_of_day_ns: Option<TimeOfDayNs>,
    pub date: Option<Date>,
    /// Status A (autonomous) or D (differential); false for V (warning).
    pub valid: bool,
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    pub speed_knots: Option<f64>,
    /// Course over ground, degrees true.
    pub course_deg: Option<f64>,
}

/// GST: pseudorange error statistics (metres).
#[derive(Clone, Debug, PartialEq)]
pub struct Gst {
    pub talker: String,
    pub time_of_day_ns: Option<TimeOfDayNs>,
    pub rms_m: Option<f64>,
    pub semi_major_sd_m: Option<f64>,
    pub semi_minor_sd_m: Option<f64>,
    pub orientation_deg: Option<f64>,
    pub lat_sd_m: Option<f64>,
    pub lon_sd_m: Option<f64>,
    pub alt_sd_m: Option<f64>,
}

/// ZDA: UTC date and time.
#[derive(Clone, Debug, PartialEq)]
pub struct Zda {
    pub talker: String,
    pub time_of_day_ns: Option<TimeOfDayNs>,
    pub date: Option<Date>,
}

/// HDT: true heading (degrees). It carries no time: it belongs to the
/// epoch whose timed sentences came before it. From a GNSS talker (GP, GN,
/// GL, GA, GB, BD, GI, GQ) it is a dual-antenna (moving-base) receiver's
/// baseline azimuth; other talkers (HE gyrocompass, IN integrated
/// navigation) are other instruments.
#[derive(Clone, Debug, PartialEq)]
pub struct Hdt {
    pub talker: String,
    pub heading_deg: Option<f64>,
}

impl Hdt {
    /// Whether the talker is a GNSS receiver (NMEA 0183 v4.11 talker IDs).
    pub fn from_gnss(&self) -> bool {
        matches!(
            self.talker.as_str(),
            "GP" | "GN" | "GL" | "GA" | "GB" | "BD" | "GI" | "GQ"
        )
    }
}

/// A decoded sentence of a type navsync reads.
#[derive(Clone, Debug, PartialEq)]
pub enum NmeaMessage {
    Gga(Gga),
    Rmc(Rmc),
    Gst(Gst),
    Zda(Zda),
    Hdt(Hdt),
}

impl NmeaMessage {
    pub fn kind(&self) -> &'static str {
        match self {
            NmeaMessage::Gga(_) => "GGA",
            NmeaMessage::Rmc(_) => "RMC",
            NmeaMessage::Gst(_) => "GST",
            NmeaMessage::Zda(_) => "ZDA",
            NmeaMessage::Hdt(_) => "HDT",
        }
    }
}

/// The sentence formatter (e.g. `GGA`) of a `$TTFFF,...` sentence, or the
/// whole address for proprietary `$P...` sentences.
pub fn formatter(sentence: &[u8]) -> &[u8] {
    let body = sentence.strip_prefix(b"$").unwrap_or(sentence);
    let addr_end = body
        .iter()
        .position(|&b| b == b',' || b == b'*')
        .unwrap_or(body.len());
    let addr = &body[..addr_end];
    if addr.first() == Some(&b'P') || addr.len() < 5 {
        addr
    } else {
        &addr[2..]
    }
}

/// Whether navsync decodes sentences with this formatter.
pub(crate) fn is_read(formatter: &[u8]) -> bool {
    matches!(formatter, b"GGA" | b"RMC" | b"GST" | b"ZDA" | b"HDT")
}

/// Decodes a checksum-verified sentence (`$` to the two checksum digits,
/// without CR LF) of a type navsync reads. `Ok(None)` for other types; an
/// error names what the `nmea` crate rejected.
pub fn decode(sentence: &str) -> Result<Option<NmeaMessage>, String> {
    let f = formatter(sentence.as_bytes());
    if !is_read(f) {
        return Ok(None);
    }
    let talker = sentence.get(1..3).unwrap_or("").to_string();
    let parsed = nmea::parse_str(sentence).map_err(|e| format!("{e:?}"))?;
    let date = |d: chrono::NaiveDate| Date {
        year: d.year(),
        month: d.month(),
        day: d.day(),
    };
    Ok(Some(match parsed {
        nmea::ParseResult::GGA(g) => NmeaMessage::Gga(Gga {
            talker,
            time_of_day_ns: g.fix_time.map(tod_ns),
            lat_deg: g.latitude,
            lon_deg: g.longitude,
            quality: g.fix_type.map(fix_quality).unwrap_or(0),
            num_sv: g.fix_satellites,
            hdop: g.hdop,
            alt_msl_m: g.altitude.map(f32_decimal),
            geoid_sep_m: g.geoid_separation.map(f32_decimal),
        }),
        nmea::ParseResult::RMC(r) => NmeaMessage::Rmc(Rmc {
            talker,
            time_of_day_ns: r.fix_time.map(tod_ns),
            date: r.fix_date.map(date),
            valid: r.status_of_fix != nmea::sentences::rmc::RmcStatusOfFix::Invalid,
            lat_deg: r.lat,
            lon_deg: r.lon,
            speed_knots: r.speed_over_ground.map(f32_decimal),
            course_deg: r.true_course.map(f32_decimal),
        }),
        nmea::ParseResult::GST(s) => NmeaMessage::Gst(Gst {
            talker,
            time_of_day_ns: s.time.map(tod_ns),
            rms_m: s.rms_sd.map(f32_decimal),
            semi_major_sd_m: s.ellipse_semi_major_sd.map(f32_decimal),
            semi_minor_sd_m: s.ellipse_semi_minor_sd.map(f32_decimal),
            orientation_deg: s.err_ellipse_orientation.map(f32_decimal),
            lat_sd_m: s.lat_sd.map(f32_decimal),
            lon_sd_m: s.long_sd.map(f32_decimal),
            alt_sd_m: s.alt_sd.map(f32_decimal),
        }),
        nmea::ParseResult::ZDA(z) => NmeaMessage::Zda(Zda {
            talker,
            time_of_day_ns: z.utc_time.map(tod_ns),
            date: z.utc_date().map(date),
        }),
        nmea::ParseResult::HDT(h) => NmeaMessage::Hdt(Hdt {
            talker,
            heading_deg: h.heading.map(f32_decimal),
        }),
        other => return Err(format!("unexpected sentence {other:?}")),
    }))
}

/// The `nmea` crate keeps these fields as `f32`; the shortest decimal that
/// reads back as the same `f32` is the number the receiver wrote (to f32's
/// 7 significant digits), so `1129.913` stays 1129.913, not 1129.9129638…
fn f32_decimal(v: f32) -> f64 {
    format!("{v}").parse().unwrap_or(v as f64)
}

fn fix_quality(f: nmea::sentences::FixType) -> u8 {
    use nmea::sentences::FixType as F;
    match f {
        F::Invalid => 0,
        F::Gps => 1,
        F::DGps => 2,
        F::Pps => 3,
        F::Rtk => 4,
        F::FloatRtk => 5,
        F::Estimated => 6,
        F::Manual => 7,
        F::Simulation => 8,
    }
}

// ---------------------------------------------------------------- encoders

fn fmt_tod(out: &mut String, tod: Option<TimeOfDayNs>) {
    use std::fmt::Write;
    if let Some(t) = tod {
        let t = t.rem_euclid(86_400_000_000_000);
        let s = t / 1_000_000_000;
        let cs = (t % 1_000_000_000) / 10_000_000;
        let _ = write!(
            out,
            "{:02}{:02}{:02}.{:02}",
            s / 3600,
            (s / 60) % 60,
            s % 60,
            cs
        );
    }
}

/// `ddmm.mmmmmmm,N` (or `dddmm…,E` for longitude), 7 decimals of minutes
/// as u-blox high-precision NMEA.
fn fmt_angle(out: &mut String, deg: Option<f64>, lon: bool) {
    use std::fmt::Write;
    match deg {
        Some(d) => {
            let a = d.abs();
            let mut whole = a.trunc();
            let mut min = (a - whole) * 60.0;
            if (min * 1e7).round() >= 60.0 * 1e7 {
                whole += 1.0;
                min = 0.0;
            }
            let hemi = match (lon, d < 0.0) {
                (false, false) => 'N',
                (false, true) => 'S',
                (true, false) => 'E',
                (true, true) => 'W',
            };
            if lon {
                let _ = write!(out, "{:03}{:010.7},{hemi}", whole as u32, min);
            } else {
                let _ = write!(out, "{:02}{:010.7},{hemi}", whole as u32, min);
            }
        }
        None => out.push(','),
    }
}

fn fmt_opt(out: &mut String, v: Option<f64>, decimals: usize) {
    use std::fmt::Write;
    if let Some(v) = v {
        let _ = write!(out, "{v:.decimals$}");
    }
}

impl Gga {
    /// The sentence (with `*HH\r\n`).
    pub fn to_sentence(&self) -> String {
        let mut b = format!("{}GGA,", self.talker);
        fmt_tod(&mut b, self.time_of_day_ns);
        b.push(',');
        fmt_angle(&mut b, self.lat_deg, false);
        b.push(',');
        fmt_angle(&mut b, self.lon_deg, true);
        b.push_str(&format!(",{},", self.quality));
        if let Some(n) = self.num_sv {
            b.push_str(&format!("{n:02}"));
        }
        b.push(',');
        fmt_opt(&mut b, self.hdop.map(|h| h as f64), 2);
        b.push(',');
        fmt_opt(&mut b, self.alt_msl_m, 3);
        b.push_str(",M,");
        fmt_opt(&mut b, self.geoid_sep_m, 3);
        b.push_str(",M,,");
        encode_sentence(&b)
    }
}

impl Rmc {
    pub fn to_sentence(&self) -> String {
        let mut b = format!("{}RMC,", self.talker);
        fmt_tod(&mut b, self.time_of_day_ns);
        b.push_str(if self.valid { ",A," } else { ",V," });
        fmt_angle(&mut b, self.lat_deg, false);
        b.push(',');
        fmt_angle(&mut b, self.lon_deg, true);
        b.push(',');
        fmt_opt(&mut b, self.speed_knots, 3);
        b.push(',');
        fmt_opt(&mut b, self.course_deg, 2);
        b.push(',');
        if let Some(d) = self.date {
            b.push_str(&format!(
                "{:02}{:02}{:02}",
                d.day,
                d.month,
                d.year.rem_euclid(100)
            ));
        }
        b.push_str(",,,");
        b.push(if self.valid { 'A' } else { 'N' });
        b.push_str(",V");
        encode_sentence(&b)
    }
}

impl Gst {
    pub fn to_sentence(&self) -> String {
        let mut b = format!("{}GST,", self.talker);
        fmt_tod(&mut b, self.time_of_day_ns);
        for v in [
            self.rms_m,
            self.semi_major_sd_m,
            self.semi_minor_sd_m,
            self.orientation_deg,
            self.lat_sd_m,
            self.lon_sd_m,
            self.alt_sd_m,
        ] {
            b.push(',');
            fmt_opt(&mut b, v, 3);
        }
        encode_sentence(&b)
    }
}

impl Zda {
    pub fn to_sentence(&self) -> String {
        let mut b = format!("{}ZDA,", self.talker);
        fmt_tod(&mut b, self.time_of_day_ns);
        match self.date {
            Some(d) => b.push_str(&format!(",{:02},{:02},{:04},00,00", d.day, d.month, d.year)),
            None => b.push_str(",,,,00,00"),
        }
        encode_sentence(&b)
    }
}

impl Hdt {
    pub fn to_sentence(&self) -> String {
        let mut b = format!("{}HDT,", self.talker);
        fmt_opt(&mut b, self.heading_deg, 2);
        b.push_str(",T");
        encode_sentence(&b)
    }
}

impl NmeaMessage {
    pub fn to_sentence(&self) -> String {
        match self {
            NmeaMessage::Gga(m) => m.to_sentence(),
            NmeaMessage::Rmc(m) => m.to_sentence(),
            NmeaMessage::Gst(m) => m.to_sentence(),
            NmeaMessage::Zda(m) => m.to_sentence(),
            NmeaMessage::Hdt(m) => m.to_sentence(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formatter_of_talker_and_proprietary_sentences() {
        assert_eq!(formatter(b"$GNGGA,1,2*00"), b"GGA");
        assert_eq!(formatter(b"$PUBX,00,1*00"), b"PUBX");
        assert_eq!(formatter(b"$GP*00"), b"GP");
    }

    #[test]
    fn f9p_high_precision_gga_decodes() {
        // From ublox-f9p-hpnmea.log (gpsd, BSD-2-Clause).
        let s = "$GNGGA,014500.00,4404.1306024,N,12118.8446777,W,2,12,0.49,1129.913,M,-21.350,M,,0278*4C";
        let Some(NmeaMessage::Gga(g)) = decode(s).unwrap() else {
            panic!()
        };
        assert_eq!(g.time_of_day_ns, Some((3600 + 45 * 60) * 1_000_000_000));
        assert!((g.lat_deg.unwrap() - (44.0 + 4.1306024 / 60.0)).abs() < 1e-12);
        assert!((g.lon_deg.unwrap() + (121.0 + 18.8446777 / 60.0)).abs() < 1e-12);
        assert_eq!(g.quality, 2);
        assert_eq!(g.alt_msl_m, Some(1129.913));
        assert_eq!(g.geoid_sep_m, Some(-21.35));
        assert!((g.ellipsoidal_height_m().unwrap() - 1108.563).abs() < 1e-9);
    }

    #[test]
    fn hdt_decodes_round_trips_and_names_its_talker() {
        // gpsd's example of an HDT from a heading sensor (HE talker).
        let Some(NmeaMessage::Hdt(he)) = decode("$HEHDT,341.8,T*21").unwrap() else {
            panic!()
        };
        assert_eq!(he.heading_deg, Some(341.8));
        assert!(!he.from_gnss());
        let h = Hdt {
            talker: "GN".into(),
            heading_deg: Some(123.45),
        };
        let line = h.to_sentence();
        assert_eq!(line, encode_sentence("GNHDT,123.45,T"));
        let back = decode(line.trim_end()).unwrap();
        assert_eq!(back, Some(NmeaMessage::Hdt(h.clone())));
        assert!(h.from_gnss());
        // No heading (a receiver without a baseline solution): empty field.
        let empty = encode_sentence("GPHDT,,T");
        let Some(NmeaMessage::Hdt(e)) = decode(empty.trim_end()).unwrap() else {
            panic!()
        };
        assert_eq!(e.heading_deg, None);
    }
}
