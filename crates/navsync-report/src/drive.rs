//! One drive of a fleet, end to end: synchronize its rig log, fuse (and
//! smooth), score against its truth when it has one, judge it and write
//! its report. `navsync batch` and the Python package's `fleet` both run
//! this, so a drive gives the same row from either.
//!
//! A drive is a folder holding either
//! - `rig.csv` (a raw rig log) and `kf-gins.yaml` (the KF-GINS
//!   configuration whose IMU error model and lever arm apply; its file paths
//!   are replaced by the synchronized files) — what `navsync simulate`
//!   writes; or
//! - `kf-gins.yaml` alone, whose IMU and GNSS files are already on GPS time.
//!
//! and optionally `truth.nav` (the reference) and `imu_times_truth.txt`
//! (the true IMU stamps, to score the synchronization).

use std::path::{Path, PathBuf};
use std::time::Instant;

use navsync::fusion::TimeOffsetOptions;
use navsync::io::config::KfGinsConfig;
use navsync::pipeline::{self, FuseOptions, KfGinsSink};
use navsync::timing::SyncConfig;
use navsync::timing::file::{sync_file, write_kfgins_config};
use navsync::{Diagnostics, Error};
use serde::Serialize;

use crate::ReportInputs;

/// How each drive is processed.
#[derive(Clone, Debug)]
pub struct DriveOptions {
    /// Forward–backward smoothing after the forward filter.
    pub smooth: bool,
    /// Estimate the IMU–GNSS time offset as a filter state.
    pub estimate_time_offset: bool,
    /// Write `report.html` (the verdict is computed either way).
    pub html: bool,
}

impl Default for DriveOptions {
    fn default() -> Self {
        DriveOptions {
            smooth: true,
            estimate_time_offset: true,
            html: true,
        }
    }
}

/// One drive's row: what it gave, or why it failed.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DriveRow {
    /// The drive folder's name.
    pub drive: String,
    pub input_dir: String,
    pub output_dir: String,
    /// "rig" (synchronized here) or "kf-gins" (already on GPS time).
    pub kind: String,
    pub ok: bool,
    pub error: Option<String>,
    pub duration_s: Option<f64>,
    /// Position errors against `truth.nav` (RMS), when the drive has one.
    pub pos_horizontal_rms_m: Option<f64>,
    pub pos_3d_rms_m: Option<f64>,
    pub vel_horizontal_rms_mps: Option<f64>,
    pub yaw_rms_deg: Option<f64>,
    /// RMS over GNSS outages of the maximum horizontal drift in each.
    pub outage_drift_rms_m: Option<f64>,
    /// Synchronization: mode used, IMU records lost, implausible figures,
    /// largest stamp error bound, and the stamp error against the true
    /// stamps when known.
    pub sync_mode: Option<String>,
    pub imu_lost: Option<u64>,
    pub sync_implausible: Option<usize>,
    pub stamp_bound_max_us: Option<f64>,
    pub stamp_error_rms_us: Option<f64>,
    /// IMU–GNSS time offset estimated by the filter (ms) and its σ.
    pub time_offset_ms: Option<f64>,
    pub time_offset_sd_ms: Option<f64>,
    /// The report's verdict: good, usable with caution, or poor.
    pub verdict: Option<String>,
    /// Wall time of the whole drive (s).
    pub wall_s: f64,
}

/// Processes the drive in `input` into `output` (created; files of an
/// earlier run of the same drive are overwritten, so a retried task gives
/// the same folder). Never fails: a failure is the row's `error`.
pub fn process_drive(input: &Path, output: &Path, opts: &DriveOptions) -> DriveRow {
    let t0 = Instant::now();
    let mut row = DriveRow {
        drive: input
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| input.display().to_string()),
        input_dir: input.display().to_string(),
        output_dir: output.display().to_string(),
        ..DriveRow::default()
    };
    if let Err(e) = run(input, output, opts, &mut row) {
        row.error = Some(e.to_string());
    } else {
        row.ok = true;
    }
    row.wall_s = t0.elapsed().as_secs_f64();
    let json = output.join("drive.json");
    if let (true, Ok(text)) = (output.is_dir(), serde_json::to_string_pretty(&row)) {
        // A row that cannot be saved is still returned.
        let _ = navsync::io::output::write_file(json, text);
    }
    row
}

fn run(input: &Path, output: &Path, opts: &DriveOptions, row: &mut DriveRow) -> Result<(), Error> {
    let template = input.join("kf-gins.yaml");
    if !input.is_dir() {
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: "not a folder".into(),
        });
    }
    if !template.is_file() {
        return Err(Error::NoData {
            path: input.to_path_buf(),
            msg: "no kf-gins.yaml (a drive is rig.csv + kf-gins.yaml, or kf-gins.yaml with its IMU and GNSS files)".into(),
        });
    }
    // One writer per drive folder (navsync::io::output).
    let _held = navsync::io::output::OutputDir::open(output, "batch")?;
    let rig = input.join("rig.csv");
    let mut notes = Diagnostics::default();
    let mut sync_report: Option<PathBuf> = None;
    let cfg = if rig.is_file() {
        row.kind = "rig".into();
        let synced = output.join("synced");
        let stamps_truth = input.join("imu_times_truth.txt");
        let s = sync_file(
            &rig,
            &synced,
            SyncConfig {
                source: rig.display().to_string(),
                ..SyncConfig::default()
            },
            None,
            stamps_truth.is_file().then_some(stamps_truth.as_path()),
        )?;
        write_kfgins_config(&template, &synced, &s.report)?;
        let r = &s.report;
        row.sync_mode = Some(r.mode.clone());
        row.imu_lost = Some(r.imu.lost);
        row.sync_implausible = Some(r.implausible.len());
        row.stamp_bound_max_us = r.stamp_bound_us.max;
        row.stamp_error_rms_us = r.truth.as_ref().map(|t| t.rms_us);
        sync_report = Some(synced.join("sync_report.json"));
        let mut cfg = KfGinsConfig::load(&synced.join("kf-gins.yaml"), &mut notes)?;
        cfg.imu_path = synced.join("imu.txt");
        cfg.gnss_path = synced.join("gnss.txt");
        cfg
    } else {
        row.kind = "kf-gins".into();
        KfGinsConfig::load(&template, &mut notes)?
    };
    let fused = output.join("fused");
    let fopts = FuseOptions {
        output_dir: Some(fused.clone()),
        time_offset: opts
            .estimate_time_offset
            .then_some(TimeOffsetOptions::default()),
        smooth: opts.smooth.then_some(pipeline::SmoothOptions::default()),
        ..FuseOptions::default()
    };
    fopts.validate()?;
    let summary = fuse(&cfg, &fopts, &fused)?;
    row.duration_s = Some(summary.duration_s);
    row.time_offset_ms = summary.time_offset_s.map(|o| o * 1e3);
    row.time_offset_sd_ms = summary.time_offset_sd_s.map(|o| o * 1e3);
    let truth = input.join("truth.nav");
    let inputs = ReportInputs {
        title: format!("navsync batch: {}", row.drive),
        truth: truth.is_file().then_some(truth),
        nav: fused.join("navresult.nav"),
        sync_report,
        gnss: Some(cfg.gnss_path.clone()),
        ..ReportInputs::default()
    }
    .with_siblings_of_nav();
    let report = crate::build(&inputs)?;
    if let Some(e) = &report.eval {
        row.pos_horizontal_rms_m = Some(e.pos_horizontal_m.rms);
        row.pos_3d_rms_m = Some(e.pos_3d_m.rms);
        row.vel_horizontal_rms_mps = Some(e.vel_horizontal_mps.rms);
        row.yaw_rms_deg = Some(e.yaw_deg.rms);
        row.outage_drift_rms_m = e.outage_rms_max_horizontal_m;
        let path = output.join("eval.json");
        let json = serde_json::to_string_pretty(e).map_err(|e| Error::Invalid(e.to_string()))?;
        navsync::io::output::write_file(&path, json)?;
    }
    row.verdict = Some(report.verdict.grade.words().to_string());
    if opts.html {
        let path = output.join("report.html");
        navsync::io::output::write_file(&path, &report.html)?;
    }
    Ok(())
}

/// The fusion into `dir` with `summary.json`, as `navsync fuse` writes it
/// (the smoothed solution in `dir`, the forward one in `dir/forward`).
pub fn fuse(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    dir: &Path,
) -> Result<pipeline::FuseSummary, Error> {
    let mut sink = KfGinsSink::create(dir, opts.week)?;
    let summary = if opts.smooth.is_some() {
        let mut forward = KfGinsSink::create(&dir.join("forward"), opts.week)?;
        let mut fwd_opts = opts.clone();
        fwd_opts.output_dir = Some(dir.to_path_buf());
        let s = pipeline::run_smoothed(cfg, &fwd_opts, &mut forward, &mut sink, &mut |_| {})?;
        forward.finish()?;
        s
    } else {
        pipeline::run(cfg, opts, &mut sink, &mut |_| {})?
    };
    sink.finish()?;
    let path = dir.join("summary.json");
    let json = serde_json::to_string_pretty(&summary).map_err(|e| Error::Invalid(e.to_string()))?;
    navsync::io::output::write_file(&path, json)?;
    Ok(summary)
}
