//! The IMU log's clock put on GPS time from the motion alone, for
//! `process` (and `convert --imu-time-offset-s auto`) when the IMU's times
//! and the fixes' GPS times do not overlap and no receive times relate the
//! two clocks: Unix (UTC) seconds put on GPS time by the leap-second
//! table first, then `navsync::clock_search` (its docs: the method and the
//! papers).

use std::path::Path;

use anyhow::{Context, Result, bail};
use navsync::Diagnostics;
use navsync::clock_search::{ClockOffset, ClockSearchOptions, search_clock_offset};
use navsync::io::kfgins::{GnssLayout, GnssReader, ImuReader};
use navsync::io::text::{LineReader, is_blank_or_comment, parse_f64, split_fields};
use navsync::time::NS_PER_WEEK;
use navsync_receivers::gnsstime::{UtcTime, utc_to_gps};

/// 1980-01-06 00:00:00 UTC, the GPS epoch, in Unix seconds (IS-GPS-200 §3.3.4).
const GPS_EPOCH_UNIX_S: f64 = 315_964_800.0;

/// Unix seconds in this range (2008-01 … 2049-03) are taken for UTC.
const UNIX_RANGE_S: std::ops::RangeInclusive<f64> = 1.2e9..=2.5e9;

/// The offset found: GPS time = the raw log's time + `offset_s`.
pub struct Found {
    pub offset_s: f64,
    pub search: ClockOffset,
    /// What was done, in words (printed and kept in process.json).
    pub notes: Vec<String>,
}

/// The first time in a rate CSV (the first field of its first data line).
fn first_time_s(raw: &Path) -> Result<f64> {
    let file = std::fs::File::open(raw).with_context(|| format!("opening {}", raw.display()))?;
    let mut lines = LineReader::new(file, raw);
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 1] = [b""];
        split_fields(line, &mut f);
        return parse_f64(f[0])
            .map_err(|e| anyhow::anyhow!("{}:{no}: field 1 (time): {e}", raw.display()));
    }
    bail!("{}: no data line", raw.display())
}

/// Finds GPS time − the raw IMU log's time. `imu_txt` is the log converted
/// with no offset (its seconds of week are the raw times modulo a week),
/// `gnss` the fixes (KF-GINS, GPS seconds of week). Raw times that look
/// like Unix seconds are taken for UTC when `try_utc` (not when they
/// already overlap the fixes: GPS seconds since 1980 look alike).
pub fn find(raw: &Path, imu_txt: &Path, gnss: &Path, try_utc: bool) -> Result<Found> {
    let week_s = NS_PER_WEEK as f64 * 1e-9;
    let raw_first = first_time_s(raw)?;
    let mut diag = Diagnostics::default();
    let mut imu = Vec::new();
    let mut r = ImuReader::open(imu_txt, 0)?;
    while let Some(s) = r.next_sample(&mut diag)? {
        imu.push(s);
    }
    let mut fixes = Vec::new();
    let mut g = GnssReader::open(gnss, 0, GnssLayout::Cpp)?;
    while let Some(f) = g.next_fix(&mut diag)? {
        fixes.push(f);
    }
    // The reader's seconds are the raw times less whole weeks.
    let weeks_off = raw_first.div_euclid(week_s);
    let mut notes = Vec::new();
    // GPS time = raw + base (+ the offset found on the shifted axis).
    let mut base = -weeks_off * week_s;
    if try_utc && UNIX_RANGE_S.contains(&raw_first) {
        let ns = (raw_first * 1e9).round() as i64;
        let utc = UtcTime::from_unix_ns(ns);
        let gps = utc_to_gps(&utc);
        let utc_base = gps.seconds() - raw_first;
        notes.push(format!(
            "the IMU log's times look like Unix (UTC) seconds (first {raw_first:.3} = {:04}-{:02}-{:02} {:02}:{:02}:{:02} UTC): \
             put on GPS time with the leap-second table (GPS − UTC = {:.0} s), GPS week {}",
            utc.year,
            utc.month,
            utc.day,
            utc.hour,
            utc.min,
            utc.sec,
            utc_base + GPS_EPOCH_UNIX_S,
            gps.week()
        ));
        // The samples moved onto GPS seconds of week (the fixes' axis).
        let shift = utc_base + weeks_off * week_s - gps.week() as f64 * week_s;
        for s in &mut imu {
            s.time = s.time.add_seconds(shift);
        }
        // GPS = raw + utc_base + c: the true week kept.
        base = utc_base;
    }
    let o = ClockSearchOptions::default();
    let t0 = std::time::Instant::now();
    let c = search_clock_offset(&imu, &fixes, &o).map_err(|e| {
        anyhow::anyhow!(
            "the IMU clock's offset to GPS time could not be found from the motion ({} against {}): {e}. \
             Drive a few turns (faster than {}°/s above {} m/s: the yaw rate is what times the IMU \
             against the GNSS course), or log the fixes' receive times on the IMU's clock (a rig log, or gpspipe \
             with host times), or give the offset (`navsync convert --from rate-csv --imu-time-offset-s S`)",
            imu_txt.display(),
            gnss.display(),
            o.turn_rate_deg_s,
            o.min_speed_mps
        )
    })?;
    let offset_s = base + c.offset_s;
    notes.push(format!(
        "IMU clock → GPS time found from the motion in {:.2} s: GPS = IMU time + {offset_s:.4} s \
         (remaining after the steps above {:+.4} ± {:.4} s; peak correlation {:.3}: yaw rate {:.3}, specific force {:.3}; \
         peak width {:.2} s; second peak {:.2} of it at {:+.1} s; {} turning of {} GNSS intervals; \
         lags searched {:.0} … {:.0} s). Method: temporal calibration by the motion both sensors see \
         (Furgale, Rehder & Siegwart, IROS 2013), started from the peak of a normalised cross-correlation \
         (Mair et al., ROBIO 2011; Knapp & Carter 1976); the filter's time-offset state refines it",
        t0.elapsed().as_secs_f64(),
        c.offset_s,
        c.sd_s,
        c.peak_corr,
        c.yaw_corr,
        c.accel_corr,
        c.width_s,
        c.second_peak_ratio,
        c.second_offset_s - c.offset_s,
        c.turn_intervals,
        c.yaw_intervals,
        c.range_s[0],
        c.range_s[1]
    ));
    Ok(Found {
        offset_s,
        search: c,
        notes,
    })
}
