//! Autopilot logs → a rig log: an autopilot stamps its IMU samples and the
//! arrival of each GNSS fix on one boot clock, and the fix carries its own
//! GPS time. That is a rig log without 1PPS (FORMATS.md §2): counter = boot
//! time in µs, `imu` records at the samples' boot times, `gnss` records at
//! the fixes' arrival boot times. `navsync sync` then puts the IMU on GPS
//! time by software synchronization (lower envelopes of the two streams;
//! Harrison & Newman, "TICSync", ICRA 2011; Tang, Zhang & Niu, "MEMS IMU
//! raw data acquisition and time synchronization pitfalls", 2022 §2.2).
//!
//! The autopilot's own estimate goes to `autopilot.nav` (FORMATS.md §1, 11
//! columns) on GPS time by the boot → GPS relation of the fixes
//! ([`BootToGps`]; the fastest fix latency taken as 0, as `sync` assumes),
//! for comparison only.

use std::io::Read;
use std::path::Path;

use nalgebra::Vector3;
use navsync::earth::Geodetic;
use navsync::error::Error;
use navsync::io::kfgins::{TextWriter, format_nav_line};
use navsync::io::riglog::{
    ImuKind, ImuTiming, RateSampling, RigGnss, RigHeader, write as rig_write,
};
use navsync::time::GpsTime;

use crate::convert::{ConvertOptions, ConvertSummary, DropTally, EpochTally};
use crate::dataflash::{BootEstimate, BootFix, BootImu, MinMedMax, read_dataflash};

/// The header of a rig log from an autopilot: a 64-bit µs boot counter,
/// IMU rates sampled at the counter's instant (`data-ready`: a sample
/// time, not a serial receipt), no 1PPS.
pub fn rig_header() -> RigHeader {
    let mut h = RigHeader::new(1e6, 64, ImuKind::Rate);
    h.imu_timing = Some(ImuTiming::DataReady);
    h.imu_rates = Some(RateSampling::Instantaneous);
    h
}

/// Writes `imu` and `fixes` as a rig log, records merged in boot-time
/// order (IMU first at equal times).
pub fn write_rig_log(path: &Path, imu: &[BootImu], fixes: &[BootFix]) -> Result<(), Error> {
    let mut w = TextWriter::create(path)?;
    w.write(rig_header().to_text().as_bytes())?;
    let mut buf = Vec::with_capacity(1 << 16);
    let (mut i, mut g) = (0, 0);
    while i < imu.len() || g < fixes.len() {
        let take_imu = match (imu.get(i), fixes.get(g)) {
            (Some(a), Some(f)) => a.boot_us <= f.arrival_us,
            (Some(_), None) => true,
            _ => false,
        };
        if take_imu {
            rig_write::imu(&mut buf, imu[i].boot_us, &imu[i].values);
            i += 1;
        } else {
            let f = &fixes[g];
            rig_write::gnss(
                &mut buf,
                &RigGnss {
                    counter: f.arrival_us,
                    time: f.time,
                    lat_deg: f.lat_deg,
                    lon_deg: f.lon_deg,
                    h_m: f.h_m,
                    sd_m: f.sd_m,
                },
            );
            g += 1;
        }
        if buf.len() > (1 << 16) - 512 {
            w.write(&buf)?;
            buf.clear();
        }
    }
    w.write(&buf)?;
    w.finish()
}

/// Boot time → GPS time from the fixes: with x the arrival boot time and
/// y = x − (GPS − first fix) (s), the line y = a + b·x + min(residual): the
/// rate b by least squares, the offset at the fastest fix (taken as
/// arriving at once, as `sync` assumes). Not an envelope fit for the rate:
/// arrival times are quantised to the autopilot's scheduler slots (20 ms
/// on 16.BIN), and an envelope leans on the few early slots (−200 ppm
/// there instead of the 25 ppm a line through all fixes gives).
#[derive(Clone, Debug)]
pub struct BootToGps {
    boot0_us: u64,
    gps0: GpsTime,
    /// y = a + b·x at the fastest fix.
    a_s: f64,
    b: f64,
    /// Latencies of the fixes above the fastest (s), sorted.
    excess_s: Vec<f64>,
}

impl BootToGps {
    /// The relation of `fixes`; `None` with fewer than two or no spread
    /// of arrival times.
    pub fn from_fixes(fixes: &[BootFix]) -> Option<Self> {
        let f0 = fixes.first()?;
        if fixes.len() < 2 {
            return None;
        }
        let pts: Vec<(f64, f64)> = fixes
            .iter()
            .map(|f| {
                let x = (f.arrival_us as f64 - f0.arrival_us as f64) * 1e-6;
                (x, x - f.time.seconds_since(f0.time))
            })
            .collect();
        let n = pts.len() as f64;
        let (mx, my) = pts
            .iter()
            .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
        let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        // Arrival times over ~3 years apart are not one boot: no relation.
        if sxx.is_nan() || sxx <= 0.0 || pts.iter().any(|p| p.0.abs() > 1e8 || p.1.abs() > 1e8) {
            return None;
        }
        let b = sxy / sxx;
        let a = my - b * mx;
        let mut excess_s: Vec<f64> = pts.iter().map(|&(x, y)| y - (a + b * x)).collect();
        excess_s.sort_by(f64::total_cmp);
        let lo = excess_s[0];
        excess_s.iter_mut().for_each(|e| *e -= lo);
        (a.is_finite() && b.is_finite() && b.abs() < 1e-3).then_some(BootToGps {
            boot0_us: f0.arrival_us,
            gps0: f0.time,
            a_s: a + lo,
            b,
            excess_s,
        })
    }

    /// GPS time of boot time `boot_us`.
    pub fn gps(&self, boot_us: u64) -> GpsTime {
        let x = (boot_us as f64 - self.boot0_us as f64) * 1e-6;
        self.gps0.add_seconds(x - (self.a_s + self.b * x))
    }

    /// The boot clock's rate error against GPS time (ppm; positive: the
    /// boot clock runs fast).
    pub fn clock_error_ppm(&self) -> f64 {
        // dGPS/dboot = 1 − b.
        (1.0 / (1.0 - self.b) - 1.0) * 1e6
    }

    /// Fix latency above the fastest (ms).
    pub fn excess_ms(&self) -> MinMedMax {
        let e = &self.excess_s;
        MinMedMax {
            min: e.first().copied().unwrap_or(0.0) * 1e3,
            median: e.get(e.len() / 2).copied().unwrap_or(0.0) * 1e3,
            max: e.last().copied().unwrap_or(0.0) * 1e3,
        }
    }
}

/// Writes the estimate rows within the fixes' span (± 10 s) as an
/// 11-column nav file on GPS time; returns the rows written.
pub fn write_estimate_nav(
    path: &Path,
    rows: &[BootEstimate],
    map: &BootToGps,
    span_us: (u64, u64),
) -> Result<usize, Error> {
    let mut w = TextWriter::create(path)?;
    let mut line = Vec::with_capacity(200);
    let mut n = 0;
    let (lo, hi) = (
        span_us.0.saturating_sub(10_000_000),
        span_us.1.saturating_add(10_000_000),
    );
    for r in rows.iter().filter(|r| (lo..=hi).contains(&r.boot_us)) {
        let t = map.gps(r.boot_us);
        line.clear();
        format_nav_line(
            &mut line,
            t.week(),
            t,
            &Geodetic {
                lat_rad: r.lat_deg.to_radians(),
                lon_rad: r.lon_deg.to_radians(),
                h_m: r.h_m,
            },
            &Vector3::from(r.vel_ned_mps),
            &r.att_deg,
        );
        w.write(&line)?;
        n += 1;
    }
    w.finish()?;
    Ok(n)
}

/// `navsync convert --from dataflash`: `rig.csv` (IMU on the boot clock,
/// fixes with GPS time and arrival boot time), `autopilot.nav` (the
/// autopilot's estimate on GPS time), the summary's counts.
pub(crate) fn convert_dataflash(
    mut reader: Box<dyn Read>,
    input: &Path,
    out_dir: &Path,
    opts: &ConvertOptions,
    s: &mut ConvertSummary,
) -> Result<(), Error> {
    let mut bytes = Vec::new();
    reader
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(input, e))?;
    let read = read_dataflash(&bytes, input, opts.fix.default_sd_m, &mut s.diagnostics);
    drop(bytes);
    let mut d = read.summary;
    s.frames = d.parse.messages.clone();
    if read.imu.is_empty() {
        let found: Vec<String> = d.parse.messages.keys().cloned().collect();
        return Err(Error::config(
            input,
            format!(
                "no IMU samples in this DataFlash log (expected IMU, IMU2 or IMU3 messages with GyrX…AccZ); \
                 its messages: {}",
                if found.is_empty() {
                    "none".into()
                } else {
                    found.join(", ")
                }
            ),
        ));
    }
    s.imu_samples = read.imu.len();
    s.imu_time_axis = format!(
        "the boot clock, {}; rig.csv counter in µs, put on GPS time by `navsync sync`",
        d.time_field
    );
    s.imu_gaps = d.imu_gaps.len();
    for g in &d.imu_gaps {
        s.diagnostics.push(
            input,
            0,
            format!(
                "IMU logging gap of {:.3} s after boot time {:.3} s",
                g.length_s, g.after_boot_s
            ),
        );
    }
    let gps_messages: u64 = d
        .gps_instances
        .iter()
        .filter(|(k, _)| k.ends_with("messages"))
        .map(|(_, v)| v)
        .sum();
    if gps_messages > 0 {
        s.fix_epochs.push(EpochTally {
            source: format!("DataFlash GPS[{}]", d.gps_instance_used.unwrap_or_default()),
            epochs: d
                .gps_instance_used
                .and_then(|i| d.gps_instances.get(&format!("GPS[{i}] messages")).copied())
                .unwrap_or(0),
            fixes: read.fixes.len() as u64,
            dropped: d
                .gps_drops
                .iter()
                .map(|(reason, &epochs)| DropTally {
                    reason: reason.clone(),
                    epochs,
                    kept_by: None,
                })
                .collect(),
        });
    }
    s.gnss_fixes = read.fixes.len();
    s.gnss_default_sd = read.fixes.iter().filter(|f| f.default_sd).count();
    if !read.fixes.is_empty() {
        s.gnss_columns = 7;
        s.gnss_source = format!("DataFlash GPS (MSL heights + EGM96), σ: {}", d.sigma_source);
        s.geoid_model_heights = read.fixes.len();
        s.geoid_model = Some(crate::geoid::EGM96_SOURCE.into());
    }
    let rig = out_dir.join("rig.csv");
    write_rig_log(&rig, &read.imu, &read.fixes)?;
    s.files.push(rig.display().to_string());
    if let Some(map) = BootToGps::from_fixes(&read.fixes) {
        d.boot_clock_error_ppm = Some(map.clock_error_ppm());
        d.fix_latency_above_fastest_ms = Some(map.excess_ms());
        if !read.estimate.is_empty() {
            let span = (
                read.fixes[0].arrival_us,
                read.fixes[read.fixes.len() - 1].arrival_us,
            );
            let nav = out_dir.join("autopilot.nav");
            d.estimate_rows = write_estimate_nav(&nav, &read.estimate, &map, span)?;
            s.files.push(nav.display().to_string());
        }
    } else {
        d.estimate_source = None;
        d.estimate_rows = 0;
    }
    if gps_messages == 0 {
        s.diagnostics.push(
            input,
            0,
            "no GPS messages in the log: rig.csv holds the IMU only (no GPS time, no fixes)",
        );
    }
    s.dataflash = Some(d);
    Ok(())
}
