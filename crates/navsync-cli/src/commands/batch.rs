//! `navsync batch`: many drives on one machine, one drive per task, in
//! parallel (rayon); a table with one row per drive.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::args;
use anyhow::{Context, Result};
use navsync_report::drive::{DriveOptions, DriveRow, process_drive};
use rayon::prelude::*;

#[derive(clap::Args)]
pub struct Args {
    /// Drive folders: each holds rig.csv + kf-gins.yaml (a raw rig log and
    /// the configuration of its IMU and antenna, as `navsync simulate`
    /// writes), or kf-gins.yaml with IMU and GNSS files already on GPS
    /// time; truth.nav, when present, is the reference.
    #[arg(required = true)]
    pub drives: Vec<PathBuf>,
    /// Output root: one folder per drive below it, and batch.csv, batch.json.
    #[arg(long, default_value = "navsync-batch")]
    pub output: PathBuf,
    /// Drives processed at once [default: the number of cores].
    #[arg(value_parser = args::count(1, args::MAX_JOBS), long)]
    pub jobs: Option<usize>,
    /// Forward filter only (no smoothing).
    #[arg(long)]
    pub no_smooth: bool,
    /// Do not estimate the IMU–GNSS time offset.
    #[arg(long)]
    pub no_time_offset: bool,
    /// Skip each drive's report.html (the verdict is still computed).
    #[arg(long)]
    pub no_html: bool,
    /// Each drive on one core: its file reading and writing inline, not on
    /// threads of their own (same results; for schedulers that pin a core
    /// per job; threads are faster on a free machine and, measured on 2
    /// cores, still slightly faster with every core busy).
    #[arg(long)]
    pub single_core: bool,
}

/// One output folder name per drive: the folder's name, with its position
/// appended where two drives share a name (as the Python fleet does).
pub fn output_names(drives: &[PathBuf]) -> Vec<String> {
    let names: Vec<String> = drives
        .iter()
        .map(|p| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "drive".into())
        })
        .collect();
    names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            if names.iter().filter(|m| *m == n).count() > 1 {
                format!("{n}-{i}")
            } else {
                n.clone()
            }
        })
        .collect()
}

pub fn run(a: Args) -> Result<()> {
    let jobs = args::jobs(a.jobs);
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let opts = DriveOptions {
        smooth: !a.no_smooth,
        estimate_time_offset: !a.no_time_offset,
        html: !a.no_html,
    };
    let names = output_names(&a.drives);
    if a.single_core {
        navsync::stage::set_io_threads(false);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .context("starting the worker threads")?;
    let pb = crate::progress::bar("batch");
    let done = std::sync::atomic::AtomicUsize::new(0);
    let n = a.drives.len();
    let t0 = Instant::now();
    let rows: Vec<DriveRow> = pool.install(|| {
        a.drives
            .par_iter()
            .zip(names.par_iter())
            .map(|(dir, name)| {
                let row = process_drive(dir, &a.output.join(name), &opts);
                let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                crate::progress::set(&pb, k as f64 / n as f64);
                row
            })
            .collect()
    });
    pb.finish_and_clear();
    let wall = t0.elapsed().as_secs_f64();
    let csv = a.output.join("batch.csv");
    write_csv(&csv, &rows)?;
    let json = a.output.join("batch.json");
    navsync::io::output::write_file(&json, serde_json::to_string_pretty(&rows)?)
        .with_context(|| format!("writing {}", json.display()))?;
    print!("{}", table(&rows));
    let failed = rows.iter().filter(|r| !r.ok).count();
    println!(
        "navsync batch: {} drives ({} failed) in {:.2} s on {} threads; wrote {}, {}",
        rows.len(),
        failed,
        wall,
        jobs,
        csv.display(),
        json.display()
    );
    anyhow::ensure!(
        failed == 0,
        "{failed} of {} drives failed (rows above)",
        rows.len()
    );
    Ok(())
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map(|x| format!("{x:.digits$}")).unwrap_or_default()
}

/// The on-screen table.
pub fn table(rows: &[DriveRow]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<20} {:<19} {:>9} {:>9} {:>9} {:>5} {:>9} {:>5} {:>10} {:>7}  error",
        "drive",
        "verdict",
        "h RMS m",
        "3D RMS m",
        "drift m",
        "sync",
        "stamp µs",
        "lost",
        "offset ms",
        "wall s"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<20} {:<19} {:>9} {:>9} {:>9} {:>5} {:>9} {:>5} {:>10} {:>7.2}  {}",
            r.drive,
            r.verdict
                .as_deref()
                .unwrap_or(if r.ok { "" } else { "failed" }),
            opt(r.pos_horizontal_rms_m, 4),
            opt(r.pos_3d_rms_m, 4),
            opt(r.outage_drift_rms_m, 3),
            r.sync_mode.as_deref().unwrap_or(""),
            opt(r.stamp_error_rms_us, 3),
            r.imu_lost.map(|v| v.to_string()).unwrap_or_default(),
            opt(r.time_offset_ms, 3),
            r.wall_s,
            r.error.as_deref().unwrap_or("")
        );
    }
    s
}

/// batch.csv: every field of the rows, full precision, a header naming units.
fn write_csv(path: &Path, rows: &[DriveRow]) -> Result<()> {
    let mut f: Vec<u8> = Vec::new();
    let quote = |s: &str| {
        if s.contains([',', '"', '\n']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    };
    let num = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
    writeln!(
        f,
        "drive,ok,verdict,pos_horizontal_rms_m,pos_3d_rms_m,vel_horizontal_rms_mps,yaw_rms_deg,outage_drift_rms_m,\
         sync_mode,imu_lost,sync_implausible,stamp_bound_max_us,stamp_error_rms_us,time_offset_ms,time_offset_sd_ms,\
         duration_s,wall_s,kind,input_dir,output_dir,error"
    )?;
    for r in rows {
        writeln!(
            f,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            quote(&r.drive),
            r.ok,
            quote(r.verdict.as_deref().unwrap_or("")),
            num(r.pos_horizontal_rms_m),
            num(r.pos_3d_rms_m),
            num(r.vel_horizontal_rms_mps),
            num(r.yaw_rms_deg),
            num(r.outage_drift_rms_m),
            quote(r.sync_mode.as_deref().unwrap_or("")),
            r.imu_lost.map(|v| v.to_string()).unwrap_or_default(),
            r.sync_implausible
                .map(|v| v.to_string())
                .unwrap_or_default(),
            num(r.stamp_bound_max_us),
            num(r.stamp_error_rms_us),
            num(r.time_offset_ms),
            num(r.time_offset_sd_ms),
            num(r.duration_s),
            r.wall_s,
            quote(&r.kind),
            quote(&r.input_dir),
            quote(&r.output_dir),
            quote(r.error.as_deref().unwrap_or(""))
        )?;
    }
    navsync::io::output::write_file(path, f)?;
    Ok(())
}
