//! `navsync process`: a whole drive in one command. The raw logs (one rig
//! log, or a receiver log and an IMU log) are recognised by their content
//! and put on GPS time (`sync` or `convert`), the sensor sheet becomes the
//! filter configuration (no initial state: the run aligns itself), then
//! align → fuse → smooth, and the report. Layout of DIR:
//!
//! - `sync/` (rig log) or `convert/gnss/`, `convert/imu/`: GPS-time KF-GINS files;
//!   an autopilot log is converted into `convert/rig.csv` first, then `sync/`;
//! - `fuse/`: navresult.nav, std.txt, imu_err.txt, summary.json (smoothed;
//!   the forward filter's in `fuse/forward/`);
//! - `report.html`; `process.json`: what each stage did.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use navsync::Diagnostics;
use navsync::align::{AlignMethod, AlignOptions};
use navsync::fusion::TimeOffsetOptions;
use navsync::io::config::KfGinsConfig;
use navsync::io::text::{LineReader, is_blank_or_comment, parse_f64, split_fields};
use navsync::pipeline::{FuseOptions, NhcSettings, SmoothOptions};
use navsync::sensor::{DriveFiles, SensorSheet};
use navsync::timing::file::sync_file;
use navsync::timing::{SyncConfig, SyncMode};
use navsync_receivers::convert::{self, ConvertOptions, InputFormat};
use navsync_receivers::detect::{FileKind, detect};
use navsync_report::ReportInputs;
use serde_json::json;

use super::args;
use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// The raw logs: one rig log (rig-log v1), or a receiver log (u-blox
    /// UBX, NMEA, comma2k19 gnss_ublox.csv) and an IMU log (rate CSV:
    /// time s, gyro x y z rad/s, accel x y z m/s²), or a ROS 2 .mcap bag,
    /// or a ROS 1 .bag (its odometry → the odometer when the sheet has
    /// none), or an autopilot log (ArduPilot DataFlash .BIN, PX4 ULog).
    /// Recognised by content.
    #[arg(required = true, value_name = "RAW")]
    pub raw: Vec<PathBuf>,
    /// The sensor sheet (`navsync init` writes one).
    #[arg(long)]
    pub sensor: PathBuf,
    /// Output folder (created).
    #[arg(long)]
    pub output: PathBuf,
    /// Forward filter only (no forward–backward smoothing).
    #[arg(long)]
    pub no_smooth: bool,
    /// Skip the consistency probe (a second forward pass with the
    /// IMU–GNSS time offset and the antenna lever arm estimated as states,
    /// whose estimates the report's verdict compares with the sheet;
    /// fuse/probe.json).
    #[arg(long)]
    pub no_probe: bool,
    /// A reference trajectory (11-column nav format): the report scores
    /// against it and the errors are printed at the end.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Alignment: take the heading from GNSS velocity from this speed on (m/s).
    #[arg(value_parser = args::positive(100.0, "m/s"), long, default_value_t = 3.0)]
    pub align_min_speed: f64,
    /// Go on when `sync` finds the rig log implausible.
    #[arg(long)]
    pub force: bool,
    /// ROS bag: the datum of NavSatFix altitudes (`msl`: EGM96 geoid added).
    #[arg(long, value_enum, default_value = "ellipsoid")]
    pub ros_altitude: super::convert::RosAltitude,
    /// Estimate the GNSS antenna lever arm as filter states (as the sheet's
    /// `estimate_lever_arm: true`; σ from `antenna_lever_sd_m`).
    #[arg(long)]
    pub estimate_lever_arm: bool,
}

/// The inputs, by kind.
struct Inputs {
    rig: Option<PathBuf>,
    /// An autopilot log (IMU and fix arrivals on its boot clock): converted
    /// into `convert/rig.csv`, then synchronized like a rig log.
    autopilot: Option<PathBuf>,
    gnss: Option<(PathBuf, FileKind)>,
    imu: Option<(PathBuf, FileKind)>,
}

fn classify(raw: &[PathBuf]) -> Result<Inputs> {
    let mut inp = Inputs {
        rig: None,
        autopilot: None,
        gnss: None,
        imu: None,
    };
    for p in raw {
        let kind = detect(p)?;
        println!("  {}: {}", p.display(), kind.describe());
        let slot_taken = |what: &str, other: &Path| -> anyhow::Error {
            anyhow::anyhow!(
                "two {what} logs given ({} and {}): give one rig log, or one receiver log and one IMU log",
                other.display(),
                p.display()
            )
        };
        match kind {
            // An autopilot log holds IMU and GNSS on one clock, as a rig log.
            FileKind::RigLog => {
                if let Some(o) = &inp.rig {
                    return Err(slot_taken("rig", o));
                }
                inp.rig = Some(p.clone());
            }
            k if k.is_autopilot_log() => {
                if let Some(o) = &inp.autopilot {
                    return Err(slot_taken("autopilot", o));
                }
                inp.autopilot = Some(p.clone());
            }
            FileKind::Mcap | FileKind::Ros1Bag => {
                if let Some((o, _)) = inp.gnss.as_ref().or(inp.imu.as_ref()) {
                    return Err(slot_taken("GNSS/IMU", o));
                }
                inp.gnss = Some((p.clone(), kind));
                inp.imu = Some((p.clone(), kind));
            }
            k if k.has_gnss() => {
                if let Some((o, _)) = &inp.gnss {
                    return Err(slot_taken("GNSS", o));
                }
                inp.gnss = Some((p.clone(), kind));
            }
            _ => {
                if let Some((o, _)) = &inp.imu {
                    return Err(slot_taken("IMU", o));
                }
                inp.imu = Some((p.clone(), kind));
            }
        }
    }
    if let Some(r) = &inp.autopilot {
        if inp.rig.is_some() || inp.gnss.is_some() || inp.imu.is_some() {
            bail!(
                "{} is an autopilot log, which holds IMU and GNSS already: give it alone",
                r.display()
            );
        }
        return Ok(inp);
    }
    if let Some(r) = &inp.rig {
        if inp.gnss.is_some() || inp.imu.is_some() {
            bail!(
                "{} is a rig log, which holds IMU and GNSS already: give it alone",
                r.display()
            );
        }
        return Ok(inp);
    }
    match (&inp.gnss, &inp.imu) {
        (None, _) => bail!(
            "no GNSS log among the inputs: navsync process needs GNSS positions to align and fuse \
             (an IMU alone drifts); give a receiver log (UBX, NMEA, comma2k19 CSV) or a rig log"
        ),
        (Some((g, FileKind::Ubx)), None)
            if navsync_receivers::detect::ubx_fused_without_imu(g).unwrap_or(false) =>
        {
            bail!(
                "{} holds a u-blox dead-reckoning receiver's FUSED solution (NAV-PVAT: GNSS + the \
                 receiver's own IMU, already filtered) and no raw IMU data (no ESF-RAW/ESF-MEAS): \
                 navsync process needs the IMU samples to run its own INS. Use \
                 `navsync convert --from ubx` for its fixes and headings, or log ESF-RAW too",
                g.display()
            )
        }
        (Some((g, _)), None) => bail!(
            "no IMU log among the inputs (only {}): give the IMU log too (rate CSV: time, gyro x y z rad/s, accel x y z m/s²)",
            g.display()
        ),
        _ => Ok(inp),
    }
}

/// First and last epoch (sow), count and median interval of a KF-GINS file.
#[derive(Clone, Copy, Debug)]
struct Span {
    first_sow: f64,
    last_sow: f64,
    count: usize,
    median_dt_s: f64,
}

fn span_of(path: &Path) -> Result<Span> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut lines = LineReader::new(file, path);
    let mut first = None;
    let mut last = f64::NAN;
    let mut count = 0;
    let mut dts = Vec::new();
    while let Some((line, _)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 1] = [b""];
        split_fields(line, &mut f);
        let Ok(t) = parse_f64(f[0]) else { continue };
        if first.is_none() {
            first = Some(t);
        } else if dts.len() < 5000 {
            dts.push(t - last);
        }
        last = t;
        count += 1;
    }
    dts.sort_by(f64::total_cmp);
    Ok(Span {
        first_sow: first.unwrap_or(f64::NAN),
        last_sow: last,
        count,
        median_dt_s: dts.get(dts.len() / 2).copied().unwrap_or(f64::NAN),
    })
}

/// What the data stages produced.
struct Data {
    imu: PathBuf,
    gnss: PathBuf,
    week: i64,
    sync_report: Option<PathBuf>,
    /// The IMU's clock → GPS time relation was found from receive times
    /// only: a constant offset remains for the filter to estimate.
    software_timed: bool,
    notes: Vec<String>,
    /// Odometer speeds a ROS 1 bag gave (`speed.txt`) and their median σ.
    speed: Option<(PathBuf, Option<f64>)>,
    /// Receiver headings `convert` wrote (dual-antenna NAV-RELPOSNED or NMEA HDT,
    /// NAV-PVT headVeh), for the alignment.
    heading: Option<PathBuf>,
    /// The IMU clock's offset found from the motion (`clock_search`).
    clock_search: Option<navsync::clock_search::ClockOffset>,
}

fn sync_stage(rig: &Path, out: &Path, force: bool) -> Result<Data> {
    let dir = out.join("sync");
    println!("[1/4] sync: {} → {}", rig.display(), dir.display());
    let cfg = SyncConfig {
        mode: SyncMode::Auto,
        source: rig.display().to_string(),
        ..Default::default()
    };
    let t0 = std::time::Instant::now();
    let s = sync_file(rig, &dir, cfg, None, None)?;
    super::sync::print_summary(&s.report, t0.elapsed().as_secs_f64());
    super::sync::print_wrote(&dir);
    if !s.read_diag.is_empty() {
        eprintln!("{} lines skipped while reading:", s.read_diag.total);
        print_diagnostics(&s.read_diag, 5);
    }
    if !s.report.implausible.is_empty() {
        for b in &s.report.implausible {
            eprintln!(
                "  implausible: {} (likely cause: {}; fix: {})",
                b.what, b.cause, b.fix
            );
        }
        if !force {
            bail!(
                "implausible rig log {} (see {}/sync_report.json): its stamps are not to be trusted; --force goes on anyway",
                rig.display(),
                dir.display()
            );
        }
    }
    if s.report.gnss.stamped == 0 {
        bail!(
            "no GNSS fix in {} ({} gnss records): navsync process needs GNSS positions to align and fuse \
             (an IMU alone drifts); check that the receiver's fixes are logged as `gnss,…` records",
            rig.display(),
            s.report.records.gnss
        );
    }
    let software_timed = s.report.software.is_some() || s.report.hybrid.is_some();
    Ok(Data {
        imu: dir.join("imu.txt"),
        gnss: dir.join("gnss.txt"),
        week: s.report.first_stamp.map(|w| w.week).unwrap_or(0),
        sync_report: Some(dir.join("sync_report.json")),
        software_timed,
        notes: Vec::new(),
        speed: None,
        // The log's `heading` records, when it has any.
        heading: Some(dir.join("heading.txt")).filter(|p| p.is_file()),
        clock_search: None,
    })
}

fn format_of(kind: FileKind) -> Option<InputFormat> {
    Some(match kind {
        FileKind::Ubx => InputFormat::Ubx,
        FileKind::Nmea => InputFormat::Nmea,
        FileKind::Mcap => InputFormat::Mcap,
        FileKind::Ros1Bag => InputFormat::Ros1Bag,
        FileKind::CommaGnss => InputFormat::CommaGnss,
        FileKind::RateCsv => InputFormat::RateCsv,
        FileKind::Ulog => InputFormat::Ulog,
        FileKind::DataFlash => InputFormat::DataFlash,
        FileKind::RigLog | FileKind::KfginsImu | FileKind::KfginsGnss => return None,
    })
}

fn convert_one(
    path: &Path,
    kind: FileKind,
    dir: &Path,
    opts: &ConvertOptions,
) -> Result<convert::ConvertSummary> {
    let Some(format) = format_of(kind) else {
        bail!(
            "{}: {} needs no conversion",
            path.display(),
            kind.describe()
        );
    };
    let s = convert::convert(format, path, dir, opts)?;
    if let Some(u) = &s.ulog {
        println!(
            "  {}: {} IMU samples ({:.1} Hz) on the boot clock, {} GPS fixes from {}; autopilot.nav: {} epochs",
            dir.join("rig.csv").display(),
            u.imu_samples,
            u.imu_rate_hz,
            u.fixes,
            u.gps_topic,
            u.autopilot_nav_epochs
        );
    } else if s.dataflash.is_some() {
        println!(
            "  {}: {} IMU samples ({}), {} fixes ({}); {}/summary.json",
            dir.join("rig.csv").display(),
            s.imu_samples,
            s.imu_time_axis,
            s.gnss_fixes,
            s.gnss_source,
            dir.display()
        );
    } else if s.gnss_fixes > 0 {
        println!(
            "  {}: {} fixes ({} columns) from {}",
            dir.join("gnss.txt").display(),
            s.gnss_fixes,
            s.gnss_columns,
            s.gnss_source
        );
    }
    if s.imu_samples > 0 && s.ulog.is_none() && s.dataflash.is_none() {
        println!(
            "  {}: {} increments on {}, {} gaps",
            dir.join("imu.txt").display(),
            s.imu_samples,
            s.imu_time_axis,
            s.imu_gaps
        );
    }
    if let Some(b) = &s.ros1 {
        super::convert::print_bag("ROS 1", b);
    }
    if !s.diagnostics.is_empty() {
        eprintln!(
            "  {} problems reported (all in {}/summary.json):",
            s.diagnostics.total,
            dir.display()
        );
        print_diagnostics(&s.diagnostics, 5);
    }
    Ok(s)
}

/// An autopilot log → `DIR/convert/rig.csv` (IMU on the boot clock, fixes
/// with their GPS time and arrival boot time) → [`sync_stage`] (software
/// synchronization puts the IMU on GPS time).
fn autopilot_stage(log: &Path, sheet: &SensorSheet, out: &Path, force: bool) -> Result<Data> {
    let kind = detect(log)?;
    let dir = out.join("convert");
    println!("[1/4] convert: {} → {}", log.display(), dir.display());
    let mut opts = ConvertOptions::default();
    opts.fix.default_sd_m = sheet.gnss_default_sd_m;
    let s = convert_one(log, kind, &dir, &opts)?;
    if s.gnss_fixes == 0 {
        let why = s.no_fix_message().unwrap_or_else(|| {
            format!(
                "no GNSS fix in {}: the log holds no GPS messages (IMU only; {}/rig.csv has no gnss records)",
                log.display(),
                dir.display()
            )
        });
        bail!("{why}: navsync process needs GNSS positions to align and fuse");
    }
    sync_stage(&dir.join("rig.csv"), out, force)
}

fn convert_stage(
    inp: &Inputs,
    sheet: &SensorSheet,
    out: &Path,
    ros_altitude: navsync_receivers::rosmsg::AltitudeDatum,
) -> Result<Data> {
    let (Some((g, gk)), Some((i, ik))) = (&inp.gnss, &inp.imu) else {
        bail!("a receiver log and an IMU log are needed");
    };
    let dir = out.join("convert");
    println!("[1/4] convert → {}", dir.display());
    let mut opts = ConvertOptions::default();
    opts.fix.default_sd_m = sheet.gnss_default_sd_m;
    opts.hdt_sd_deg = sheet.hdt_sd_deg;
    opts.ros_altitude = ros_altitude;
    let mut notes = Vec::new();
    let mut week = 0;
    let mut speed = None;
    let (gnss, receipt) = if *gk == FileKind::KfginsGnss {
        (g.clone(), None)
    } else {
        let d = dir.join("gnss");
        // A heading file of an earlier run in this folder is not this log's.
        let _ = std::fs::remove_file(d.join("heading.txt"));
        let s = convert_one(g, *gk, &d, &opts)?;
        if let Some(m) = s.no_fix_message() {
            bail!("{m}: navsync process needs GNSS positions to align and fuse");
        }
        // The fixes' GPS week (gnss.txt holds seconds of week only).
        week = s.gps_week.unwrap_or(0);
        let bag = s.ros1.as_ref().or(s.ros2.as_ref());
        if let Some(b) = bag
            && s.gnss_fixes == 0
        {
            let topics: Vec<String> = b
                .topics
                .iter()
                .map(|t| format!("{} ({})", t.topic, t.schema))
                .collect();
            bail!(
                "no GNSS in {}: the bag has no NavSatFix topic (topics: {}); navsync process needs GNSS \
                 positions to align and fuse (an IMU alone drifts)",
                g.display(),
                topics.join(", ")
            );
        }
        if let Some(b) = bag {
            notes.push(format!("NavSatFix altitude datum: {}", b.altitude_datum));
        }
        if s.speeds > 0 {
            let sd = bag
                .and_then(|b| b.speed.as_ref())
                .and_then(|p| p.median_sd_mps);
            speed = Some((d.join("speed.txt"), sd));
        }
        let r = d.join("gnss_receipt.txt");
        (d.join("gnss.txt"), r.is_file().then_some(r))
    };
    let imu_dir = dir.join(if ik == gk { "gnss" } else { "imu" });
    let mut imu = if *ik == FileKind::KfginsImu {
        i.clone()
    } else if ik == gk {
        imu_dir.join("imu.txt")
    } else {
        convert_one(i, *ik, &imu_dir, &opts)?;
        imu_dir.join("imu.txt")
    };
    // The IMU must be on GPS time. A logger that stamps both streams on
    // its own clock at receipt (comma2k19: boot time) gives, for each fix,
    // its time of validity and its receipt time: GPS = local + c, and since
    // latency is never negative, c ≥ max(valid − receipt) = c0, equality
    // for the fastest message (Tang, Zhang, Niu, "MEMS IMU raw data
    // acquisition and time synchronization pitfalls", 2022, software sync).
    // What remains (fastest latency − the IMU's own delay) is a constant
    // offset for the filter's time-offset state.
    let gs = span_of(&gnss)?;
    let is = span_of(&imu)?;
    let overlap = is.first_sow < gs.last_sow && gs.first_sow < is.last_sow;
    let mut software_timed = false;
    let mut clock_search = None;
    let receipt = receipt.as_ref().filter(|_| matches!(ik, FileKind::RateCsv));
    let offset_s = match receipt {
        Some(receipt) if !overlap => {
            let c0 = receipt_envelope(receipt)?;
            let note = format!(
                "IMU times are not GPS time: shifted by {c0:.6} s, the lower envelope of the fixes' \
                 (GPS time of validity − receipt time) in {}; the remaining constant offset is estimated by the filter",
                receipt.display()
            );
            println!("  {note}");
            notes.push(note);
            Some(c0)
        }
        // A rate CSV's clock is the logging host's: nothing relates it to
        // GPS time, so the offset comes from the motion; when the times
        // overlap the fixes', the motion checks them.
        None if *ik == FileKind::RateCsv => {
            println!(
                "  IMU log {:.3} … {:.3} s, fixes' GPS times of week {:.3} … {:.3} s, no receive times: {}",
                is.first_sow,
                is.last_sow,
                gs.first_sow,
                gs.last_sow,
                if overlap {
                    "checking the IMU's clock against the motion"
                } else {
                    "no overlap, the offset from the motion"
                }
            );
            clock_offset(i, &imu, &gnss, overlap, &mut notes, &mut clock_search)?
        }
        _ if !overlap => bail!(
            "the IMU log's times ({:.3} … {:.3} s) and the GNSS fixes' GPS times of week ({:.3} … {:.3} s) \
             do not overlap: the IMU log is not on GPS time, and no receive times relate the two clocks. \
             Put the IMU on GPS time (`navsync convert --from rate-csv --imu-time-offset-s S`), or log both \
             streams with one clock in a rig log",
            is.first_sow,
            is.last_sow,
            gs.first_sow,
            gs.last_sow
        ),
        _ => None,
    };
    if let Some(offset_s) = offset_s {
        let o = ConvertOptions {
            imu_time_offset_s: offset_s,
            ..opts
        };
        convert_one(i, *ik, &imu_dir, &o)?;
        imu = imu_dir.join("imu.txt");
        software_timed = true;
    }
    Ok(Data {
        imu,
        gnss,
        week,
        sync_report: None,
        software_timed,
        notes,
        speed,
        heading: Some(dir.join("gnss").join("heading.txt")).filter(|p| p.is_file()),
        clock_search,
    })
}

/// The smallest σ (m/s) a wheel odometer's speed is given: quantisation of
/// the wheel ticks and slip leave a few cm/s on any real vehicle.
const BAG_ODOMETER_SD_FLOOR_MPS: f64 = 0.05;

/// The odometer: the sensor sheet's, else the speeds a ROS 1 bag gave, at
/// their covariance's median σ but never below [`BAG_ODOMETER_SD_FLOOR_MPS`]:
/// a ROS driver's twist covariance is a tuning constant, not a measured σ
/// (the Husky's says 0.032 m/s while its skid-steer wheels read at most
/// 1.02 m/s where GNSS saw 1.7; at that σ the forward solution ran 9.9 m
/// RMS from the fixes, at 0.05 m/s 1.7 m). Without a covariance, the
/// sheet's default 0.1 m/s.
fn odometer_settings(
    sheet: &SensorSheet,
    data: &Data,
) -> Option<navsync::reduced::OdometerSettings> {
    if let Some(o) = &sheet.odometer {
        return Some(navsync::reduced::OdometerSettings {
            sd_mps: o.sd_mps,
            lever_m: Some(o.lever_m),
            ..navsync::reduced::OdometerSettings::new(o.file.clone())
        });
    }
    let (path, sd) = data.speed.as_ref()?;
    let mut o = navsync::reduced::OdometerSettings::new(path.clone());
    if let Some(sd) = sd.filter(|s| s.is_finite() && *s > 0.0) {
        o.sd_mps = sd.max(BAG_ODOMETER_SD_FLOOR_MPS);
    }
    Some(o)
}

/// The IMU clock's offset from the motion (`clock::find`): `Some` when
/// the IMU is to be shifted. Times that overlap the fixes' stay when the
/// offset found is zero within max(3σ, 10 ms), and stay with a warning
/// note when the motion cannot tell; without overlap, no offset is an
/// error that says what to do.
fn clock_offset(
    raw: &Path,
    imu: &Path,
    gnss: &Path,
    overlap: bool,
    notes: &mut Vec<String>,
    search: &mut Option<navsync::clock_search::ClockOffset>,
) -> Result<Option<f64>> {
    match super::clock::find(raw, imu, gnss, !overlap) {
        Ok(found) => {
            for n in &found.notes {
                println!("  {n}");
            }
            notes.extend(found.notes);
            *search = Some(found.search.clone());
            let zero = found.offset_s.abs() <= (3.0 * found.search.sd_s).max(0.010);
            if overlap && zero {
                let n = format!(
                    "the IMU's times are GPS time within {:.4} s (offset found {:+.4} s): kept",
                    (3.0 * found.search.sd_s).max(0.010),
                    found.offset_s
                );
                println!("  {n}");
                notes.push(n);
                return Ok(None);
            }
            Ok(Some(found.offset_s))
        }
        Err(e) if overlap => {
            let n = format!(
                "the IMU's times overlap the fixes' and are taken for GPS time, unchecked: {e:#}"
            );
            eprintln!("navsync process: warning: {n}");
            notes.push(n);
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// c0 = max over fixes of (GPS sow of validity − receipt time), from a
/// `gnss_receipt.txt` (`week sow receipt_s` lines).
fn receipt_envelope(path: &Path) -> Result<f64> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut lines = LineReader::new(file, path);
    let mut c0 = f64::NEG_INFINITY;
    while let Some((line, no)) = lines.next_line()? {
        if is_blank_or_comment(line) {
            continue;
        }
        let mut f: [&[u8]; 3] = [b""; 3];
        if split_fields(line, &mut f) < 3 {
            bail!("{}:{no}: expected 'week sow receipt_s'", path.display());
        }
        let (Ok(sow), Ok(rx)) = (parse_f64(f[1]), parse_f64(f[2])) else {
            bail!(
                "{}:{no}: expected numbers 'week sow receipt_s'",
                path.display()
            );
        };
        c0 = c0.max(sow - rx);
    }
    anyhow::ensure!(c0.is_finite(), "{}: no receipt times", path.display());
    Ok(c0)
}

/// The report stage: one HTML page of the run, scored against `truth`
/// when given, judged from the filter's own statistics otherwise.
/// The consistency probe (`navsync::probe`): its figures go to
/// fuse/probe.json, where the report's verdict finds them. A probe that
/// fails (its filter broke down) does not fail the run: that it failed is
/// what probe.json then says.
fn probe_stage(cfg: &KfGinsConfig, opts: &FuseOptions, fuse_dir: &Path) -> Result<()> {
    let record = match navsync::probe::run_probe(cfg, opts) {
        Ok(None) => return Ok(()),
        Ok(Some(p)) => {
            if let (Some(o), Some(sd)) = (p.time_offset_s, p.time_offset_sd_s) {
                println!(
                    "  consistency probe ({:.1} s): with the time offset estimated as a state, GNSS tags look {:+.1} ms ± {:.1} ms late (the sheet assumes none)",
                    p.run_time_s,
                    o * 1e3,
                    sd * 1e3
                );
            }
            if let Some(l) = &p.lever_arm {
                println!("  consistency probe: {}", l.note);
            }
            serde_json::to_value(&p)?
        }
        Err(e) => {
            eprintln!("navsync process: warning: the consistency probe failed: {e}");
            json!({ "failed": e.to_string() })
        }
    };
    let path = fuse_dir.join("probe.json");
    navsync::io::output::write_file(&path, serde_json::to_string_pretty(&record)?)
        .with_context(|| format!("writing {}", path.display()))
}

fn write_report(
    fuse_dir: &Path,
    truth: Option<&Path>,
    sync_report: Option<&Path>,
    gnss: &Path,
    html: &Path,
) -> Result<()> {
    let inputs = ReportInputs {
        title: "navsync process".into(),
        truth: truth.map(Path::to_path_buf),
        nav: fuse_dir.join("navresult.nav"),
        sync_report: sync_report.map(Path::to_path_buf),
        gnss: Some(gnss.to_path_buf()),
        ..ReportInputs::default()
    }
    .with_siblings_of_nav();
    let report = navsync_report::build(&inputs)?;
    navsync::io::output::write_file(html, &report.html)
        .with_context(|| format!("writing {}", html.display()))?;
    let scored = match &report.eval {
        Some(e) => format!("{} epochs scored", e.epochs_compared),
        None => "no reference".into(),
    };
    println!(
        "  wrote {} ({:.0} kB, {scored}); verdict: {}",
        html.display(),
        report.html.len() as f64 / 1e3,
        report.verdict.grade.words()
    );
    for c in &report.verdict.causes {
        println!("  likely cause: {c}");
    }
    Ok(())
}

pub fn run(a: Args) -> Result<()> {
    // The sheet first: a typo should not cost a sync.
    let sheet = SensorSheet::load(&a.sensor)?;
    let fig = sheet.imu_figures(&a.sensor)?;
    let lever_warning = navsync::sensor::zero_lever_warning(sheet.antenna_lever_m, &a.sensor);
    if let Some(w) = &lever_warning {
        eprintln!("navsync process: WARNING: {w}");
    }
    let _held = super::take_output(&a.output, "process")?;
    println!("navsync process: inputs");
    let inp = classify(&a.raw)?;
    let data = match (&inp.rig, &inp.autopilot) {
        (Some(rig), _) => sync_stage(rig, &a.output, a.force)?,
        (None, Some(log)) => autopilot_stage(log, &sheet, &a.output, a.force)?,
        (None, None) => convert_stage(&inp, &sheet, &a.output, a.ros_altitude.into())?,
    };
    let mut notes = data.notes.clone();

    let imu_span = span_of(&data.imu)?;
    let gnss_span = span_of(&data.gnss)?;
    if gnss_span.count == 0 {
        bail!(
            "no GNSS fix in {}: navsync process needs GNSS positions to align and fuse",
            data.gnss.display()
        );
    }
    anyhow::ensure!(
        imu_span.count >= 2,
        "{}: fewer than two IMU samples",
        data.imu.display()
    );
    let fuse_dir = a.output.join("fuse");
    let drive = DriveFiles {
        imu: data.imu.clone(),
        gnss: data.gnss.clone(),
        output: fuse_dir.clone(),
        imu_rate_hz: (imu_span.median_dt_s > 0.0).then(|| 1.0 / imu_span.median_dt_s),
        start_sow: imu_span.first_sow,
    };
    let rate_warning = sheet.rate_mismatch(&a.sensor, &drive);
    if let Some(w) = &rate_warning {
        eprintln!("navsync process: WARNING: {w}");
    }
    let cfg = sheet.kfgins_config(&a.sensor, &drive)?;
    // Without 1PPS the filter estimates the remaining constant offset.
    let estimate_offset = sheet
        .time_offset
        .as_ref()
        .map(|t| t.estimate)
        .unwrap_or(data.software_timed);
    let estimate_lever = sheet.estimate_lever_arm || a.estimate_lever_arm;
    let odometer = odometer_settings(&sheet, &data);
    if odometer.is_some() && sheet.odometer.is_none() {
        let n = format!(
            "the bag's odometry ({}) is used as the odometer (the sensor sheet has no `odometer`), \
             σ {:.3} m/s{}, lever arm: the NHC's",
            data.speed
                .as_ref()
                .map(|s| s.0.display().to_string())
                .unwrap_or_default(),
            odometer.as_ref().map(|o| o.sd_mps).unwrap_or_default(),
            if data.speed.as_ref().is_some_and(|s| s.1.is_some()) {
                " (its covariance's, floored at 0.05 m/s)"
            } else {
                " (the bag gives none: the sheet default)"
            }
        );
        println!("  {n}");
        notes.push(n);
    }
    let opts = FuseOptions {
        output_dir: Some(fuse_dir.clone()),
        week: data.week,
        nhc: sheet.nhc.then_some(NhcSettings::default()),
        mount_deg: sheet.mount_deg,
        odometer: odometer.clone(),
        time_offset: estimate_offset.then(|| TimeOffsetOptions {
            init_s: 0.0,
            sd_s: sheet.time_offset.as_ref().map(|t| t.sd_s).unwrap_or(0.2),
            random_walk_psd: 1e-12,
            hold_when_unobservable: true,
            search_range_s: 0.5,
        }),
        // The solution on GPS time (IMU stamps + the estimated offset):
        // the GNSS receiver's clock is the trusted one.
        output_gnss_time: estimate_offset,
        // Heading from the course is the vehicle's: the alignment turns it
        // by `mount_deg`'s yaw.
        align: Some(AlignOptions {
            min_speed_mps: a.align_min_speed,
            ..AlignOptions::default()
        }),
        heading: data
            .heading
            .clone()
            .map(|path| navsync::pipeline::HeadingOptions {
                path,
                dual_antenna_yaw_deg: sheet.dual_antenna_yaw_deg,
                dual_antenna_yaw_sd_deg: sheet.dual_antenna_yaw_sd_deg,
            }),
        smooth: (!a.no_smooth).then_some(SmoothOptions::default()),
        // Zero-velocity and zero-angular-rate updates at stops.
        standstill: Some(navsync::filter::standstill::StandstillOptions::default()),
        accel_misalignment_sd_deg: Some(fig.accel_misalignment_deg),
        lever_arm_sd_m: estimate_lever.then_some(sheet.antenna_lever_sd_m),
        // The lever-arm states absorb what else turns with the heading: the
        // axis misalignment (docs/lever-arm.md) is estimated with them.
        misalignment_sd_deg: (estimate_lever && fig.accel_misalignment_deg > 0.0)
            .then_some([fig.accel_misalignment_deg; 2]),
        ..FuseOptions::default()
    };
    opts.validate()?;
    println!(
        "[2/4] align + fuse{}: {} IMU samples at {:.1} Hz, {} GNSS fixes → {}",
        if a.no_smooth { "" } else { " + smooth" },
        imu_span.count,
        cfg.imu_rate_hz,
        gnss_span.count,
        fuse_dir.display()
    );
    let summary = super::fuse::execute(&cfg, &opts, &fuse_dir)?;
    if let Some(l) = &summary.lever_arm {
        notes.push(l.note.clone());
    }
    if !a.no_probe {
        probe_stage(&cfg, &opts, &fuse_dir)?;
    }

    let mut warnings: Vec<String> = lever_warning.into_iter().chain(rate_warning).collect();
    // The mounting yaw found in the motion (land vehicles): taken, or the
    // sheet's contradicted.
    if let Some(m) = &summary.mount_yaw
        && !m.message.is_empty()
    {
        if m.disagrees {
            eprintln!("navsync process: WARNING: {}", m.message);
            warnings.push(m.message.clone());
        } else {
            // Printed with the run's diagnostics already.
            notes.push(m.message.clone());
        }
    }
    if let Some(al) = &summary.alignment
        && al.method == AlignMethod::NoMotion
    {
        let w = format!(
            "the vehicle never moved faster than {:.1} m/s: heading is unobservable (a MEMS gyro cannot sense \
             the earth's rotation). The solution is written levelled, with heading 0° and a heading σ of {:.0}° \
             (fuse/std.txt): its positions follow GNSS, its heading means nothing. Drive a few seconds \
             above {:.1} m/s (--align-min-speed) to fix the heading",
            a.align_min_speed,
            al.att_sd_rad[2].to_degrees(),
            a.align_min_speed
        );
        eprintln!("navsync process: WARNING: {w}");
        warnings.push(w);
        // The filter holds the unknown heading (its σ stays at the
        // alignment's 180° in fuse/std.txt).
    }

    println!("[3/4] report");
    let html = a.output.join("report.html");
    let report_written = match write_report(
        &fuse_dir,
        a.truth.as_deref(),
        data.sync_report.as_deref(),
        &data.gnss,
        &html,
    ) {
        Ok(()) => true,
        Err(e) => {
            let w = format!("report.html not written: {e:#}");
            eprintln!("navsync process: warning: {w}");
            warnings.push(w);
            false
        }
    };

    let mut eval_json = serde_json::Value::Null;
    if let Some(truth) = &a.truth {
        println!("[4/4] against the reference {}", truth.display());
        let mut diag = Diagnostics::default();
        let nav = fuse_dir.join("navresult.nav");
        let r = navsync::eval::eval_files(truth, &nav, &[], &mut diag)?;
        print!("{}", super::eval::format_report(&r));
        let fwd = fuse_dir.join("forward").join("navresult.nav");
        if fwd.is_file() {
            let f = navsync::eval::eval_files(truth, &fwd, &[], &mut diag)?;
            println!("forward filter against the smoothed solution:");
            print!("{}", super::eval::format_comparison(&f, &r));
        }
        eval_json = serde_json::to_value(&r)?;
    } else {
        println!("[4/4] no reference (--truth): nothing to score");
    }

    let record = json!({
        "tool": "navsync process",
        "version": env!("CARGO_PKG_VERSION"),
        "inputs": a.raw.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "sensor_sheet": a.sensor.display().to_string(),
        "imu_figures": fig,
        "imu": data.imu.display().to_string(),
        "gnss": data.gnss.display().to_string(),
        "sync_report": data.sync_report.as_ref().map(|p| p.display().to_string()),
        "imu_rate_hz": cfg.imu_rate_hz,
        "time_offset_estimated": estimate_offset,
        "smoothed": !a.no_smooth,
        "fuse_summary": fuse_dir.join("summary.json").display().to_string(),
        "alignment": summary.alignment,
        "report": report_written.then(|| html.display().to_string()),
        "eval": eval_json,
        "notes": notes,
        "imu_clock_search": data.clock_search,
        "warnings": warnings,
    });
    let p = a.output.join("process.json");
    navsync::io::output::write_file(&p, serde_json::to_string_pretty(&record)?)
        .with_context(|| format!("writing {}", p.display()))?;
    println!(
        "navsync process: done: {}/fuse/navresult.nav{}, process.json",
        a.output.display(),
        if report_written { ", report.html" } else { "" }
    );
    Ok(())
}
