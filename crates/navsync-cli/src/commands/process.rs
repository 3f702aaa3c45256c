//! `navsync process`: a whole drive in one command. The raw logs (one rig
//! log, or a receiver log and an IMU log) are recognised by their content
//! and put on GPS time (`sync` or `convert`), the sensor sheet becomes the
//! filter configuration (no initial state: the run aligns itself), then
//! align → fuse → smooth, and the report. Layout of DIR:
//!
//! - `sync/` (rig log) or `convert/gnss/`, `convert/imu/`: GPS-time KF-GINS files;
//! - `fuse/`: navresult.nav, std.txt, imu_err.txt, summary.json (smoothed;
//!   the forward filter's in `fuse/forward/`);
//! - `report.html`; `process.json`: what each stage did.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use navsync::Diagnostics;
use navsync::align::{AlignMethod, AlignOptions};
use navsync::fusion::TimeOffsetOptions;
use navsync::io::text::{LineReader, is_blank_or_comment, parse_f64, split_fields};
use navsync::pipeline::{FuseOptions, NhcSettings, SmoothOptions};
use navsync::sensor::{DriveFiles, SensorSheet};
use navsync::timing::file::sync_file;
use navsync::timing::{SyncConfig, SyncMode};
use navsync_receivers::convert::{self, ConvertOptions, InputFormat};
use navsync_receivers::detect::{FileKind, detect};
use navsync_report::ReportInputs;
use serde_json::json;

use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// The raw logs: one rig log (rig-log v1), or a receiver log (u-blox
    /// UBX, NMEA, comma2k19 gnss_ublox.csv) and an IMU log (rate CSV:
    /// time s, gyro x y z rad/s, accel x y z m/s²), or a ROS 2 .mcap bag.
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
    /// A reference trajectory (11-column nav format): the report scores
    /// against it and the errors are printed at the end.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Alignment: take the heading from GNSS velocity from this speed on (m/s).
    #[arg(long, default_value_t = 3.0)]
    pub align_min_speed: f64,
    /// Go on when `sync` finds the rig log implausible.
    #[arg(long)]
    pub force: bool,
}

/// The inputs, by kind.
struct Inputs {
    rig: Option<PathBuf>,
    gnss: Option<(PathBuf, FileKind)>,
    imu: Option<(PathBuf, FileKind)>,
}

fn classify(raw: &[PathBuf]) -> Result<Inputs> {
    let mut inp = Inputs {
        rig: None,
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
            FileKind::RigLog => {
                if let Some(o) = &inp.rig {
                    return Err(slot_taken("rig", o));
                }
                inp.rig = Some(p.clone());
            }
            FileKind::Mcap => {
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
    /// Receiver headings `convert` wrote (dual-antenna NAV-RELPOSNED or NMEA HDT,
    /// NAV-PVT headVeh), for the alignment.
    heading: Option<PathBuf>,
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
        // The log's `heading` records, when it has any.
        heading: Some(dir.join("heading.txt")).filter(|p| p.is_file()),
    })
}

fn format_of(kind: FileKind) -> Option<InputFormat> {
    Some(match kind {
        FileKind::Ubx => InputFormat::Ubx,
        FileKind::Nmea => InputFormat::Nmea,
        FileKind::Mcap => InputFormat::Mcap,
        FileKind::CommaGnss => InputFormat::CommaGnss,
        FileKind::RateCsv => InputFormat::RateCsv,
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
    if s.gnss_fixes > 0 {
        println!(
            "  {}: {} fixes ({} columns) from {}",
            dir.join("gnss.txt").display(),
            s.gnss_fixes,
            s.gnss_columns,
            s.gnss_source
        );
    }
    if s.imu_samples > 0 {
        println!(
            "  {}: {} increments on {}, {} gaps",
            dir.join("imu.txt").display(),
            s.imu_samples,
            s.imu_time_axis,
            s.imu_gaps
        );
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

fn convert_stage(inp: &Inputs, sheet: &SensorSheet, out: &Path) -> Result<Data> {
    let (Some((g, gk)), Some((i, ik))) = (&inp.gnss, &inp.imu) else {
        bail!("a receiver log and an IMU log are needed");
    };
    let dir = out.join("convert");
    println!("[1/4] convert → {}", dir.display());
    let mut opts = ConvertOptions::default();
    opts.fix.default_sd_m = sheet.gnss_default_sd_m;
    opts.hdt_sd_deg = sheet.hdt_sd_deg;
    let mut notes = Vec::new();
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
    if !overlap {
        let receipt = receipt.as_ref().filter(|_| matches!(ik, FileKind::RateCsv));
        let Some(receipt) = receipt else {
            bail!(
                "the IMU log's times ({:.3} … {:.3} s) and the GNSS fixes' GPS times of week ({:.3} … {:.3} s) \
                 do not overlap: the IMU log is not on GPS time, and no receive times relate the two clocks. \
                 Put the IMU on GPS time (`navsync convert --from rate-csv --imu-time-offset-s S`), or log both \
                 streams with one clock in a rig log",
                is.first_sow,
                is.last_sow,
                gs.first_sow,
                gs.last_sow
            );
        };
        let c0 = receipt_envelope(receipt)?;
        let note = format!(
            "IMU times are not GPS time: shifted by {c0:.6} s, the lower envelope of the fixes' \
             (GPS time of validity − receipt time) in {}; the remaining constant offset is estimated by the filter",
            receipt.display()
        );
        println!("  {note}");
        notes.push(note);
        let o = ConvertOptions {
            imu_time_offset_s: c0,
            ..opts
        };
        convert_one(i, *ik, &imu_dir, &o)?;
        imu = imu_dir.join("imu.txt");
        software_timed = true;
    }
    Ok(Data {
        imu,
        gnss,
        week: 0,
        sync_report: None,
        software_timed,
        notes,
        heading: Some(dir.join("gnss").join("heading.txt")).filter(|p| p.is_file()),
    })
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
    Ok(())
}

pub fn run(a: Args) -> Result<()> {
    // The sheet first: a typo should not cost a sync.
    let sheet = SensorSheet::load(&a.sensor)?;
    let fig = sheet.imu_figures(&a.sensor)?;
    let _held = super::take_output(&a.output, "process")?;
    println!("navsync process: inputs");
    let inp = classify(&a.raw)?;
    let data = match &inp.rig {
        Some(rig) => sync_stage(rig, &a.output, a.force)?,
        None => convert_stage(&inp, &sheet, &a.output)?,
    };

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
    let cfg = sheet.kfgins_config(&a.sensor, &drive)?;
    // Without 1PPS the filter estimates the remaining constant offset.
    let estimate_offset = sheet
        .time_offset
        .as_ref()
        .map(|t| t.estimate)
        .unwrap_or(data.software_timed);
    let opts = FuseOptions {
        output_dir: Some(fuse_dir.clone()),
        week: data.week,
        nhc: sheet.nhc.then_some(NhcSettings {
            mount_deg: sheet.mount_deg,
            ..NhcSettings::default()
        }),
        odometer: sheet
            .odometer
            .as_ref()
            .map(|o| navsync::reduced::OdometerSettings {
                sd_mps: o.sd_mps,
                lever_m: Some(o.lever_m),
                ..navsync::reduced::OdometerSettings::new(o.file.clone())
            }),
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
        align: Some(AlignOptions {
            min_speed_mps: a.align_min_speed,
            // Heading from the course is the vehicle's: turned by the
            // IMU's mounting yaw.
            mount_yaw_rad: sheet.mount_deg[2].to_radians(),
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

    let mut warnings = Vec::new();
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
        "notes": data.notes,
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
