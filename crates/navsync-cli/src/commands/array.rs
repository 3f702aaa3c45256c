//! `navsync array`: an IMU array with unknown relative time offsets
//! (seed 004): estimate each IMU's offset, shift every stream onto GNSS
//! time with a Lagrange fractional-delay filter, average into one virtual
//! IMU and fuse it.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use navsync::Diagnostics;
use navsync::eval::{self, EvalReport};
use navsync::fusion::TimeOffsetOptions;
use navsync::io::config::KfGinsConfig;
use navsync::pipeline::{self, FuseOptions, KfGinsSink};
use serde::Serialize;

#[derive(clap::Args)]
pub struct Args {
    /// IMU files (KF-GINS increments on one sample grid); two or more.
    #[arg(long = "imu", required = true, num_args = 1)]
    pub imus: Vec<PathBuf>,
    /// GNSS file (KF-GINS, 7 or 13 columns), correctly timed.
    #[arg(long)]
    pub gnss: PathBuf,
    /// KF-GINS configuration giving the initial state, noise and lever arm
    /// of one IMU (its imupath/gnsspath are replaced).
    #[arg(long)]
    pub config: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "navsync-array")]
    pub output: PathBuf,
    /// Reference trajectory to score every single IMU and the array.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Order of the Lagrange fractional-delay filter (1–7).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u8).range(1..=7))]
    pub fd_order: u8,
}

#[derive(Serialize)]
struct ImuRow {
    file: String,
    offset_s: f64,
    offset_sd_s: f64,
    offset_relative_to_first_s: f64,
    score: Option<EvalReport>,
}

#[derive(Serialize)]
struct ArrayReport {
    imus: Vec<ImuRow>,
    array_score: Option<EvalReport>,
    combined_imu: String,
    samples: usize,
}

fn score(truth: Option<&Path>, nav: &Path) -> Result<Option<EvalReport>> {
    let Some(t) = truth else {
        return Ok(None);
    };
    let mut d = Diagnostics::default();
    Ok(Some(eval::eval_files(t, nav, &[], &mut d)?))
}

pub fn run(args: Args) -> Result<()> {
    anyhow::ensure!(
        args.imus.len() >= 2,
        "an array needs at least two --imu files"
    );
    let mut diag = Diagnostics::default();
    let base = KfGinsConfig::load(&args.config, &mut diag)?;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let period_s = 1.0 / base.imu_rate_hz;

    // 1. Each IMU with the GNSS and the time-offset state.
    let mut rows = Vec::new();
    for (i, imu) in args.imus.iter().enumerate() {
        let mut cfg = base.clone();
        cfg.imu_path = imu.clone();
        cfg.gnss_path = args.gnss.clone();
        let dir = args.output.join(format!("imu{}", i + 1));
        let opts = FuseOptions {
            output_dir: Some(dir.clone()),
            time_offset: Some(TimeOffsetOptions::default()),
            // Scored on GNSS time, like the aligned array.
            output_gnss_time: true,
            ..FuseOptions::default()
        };
        let mut sink = KfGinsSink::create(&dir, 0)?;
        let summary = pipeline::run(&cfg, &opts, &mut sink, &mut |_| {})?;
        sink.finish()?;
        let (o, sd) = (
            summary.time_offset_s.unwrap_or(0.0),
            summary.time_offset_sd_s.unwrap_or(f64::NAN),
        );
        rows.push(ImuRow {
            file: imu.display().to_string(),
            offset_s: o,
            offset_sd_s: sd,
            offset_relative_to_first_s: 0.0,
            score: score(args.truth.as_deref(), &dir.join("navresult.nav"))?,
        });
    }
    let first = rows[0].offset_s;
    for r in &mut rows {
        r.offset_relative_to_first_s = r.offset_s - first;
    }

    // 2. Align every stream onto GNSS time and average (delay = τ_i / T).
    let combined = args.output.join("array_imu.txt");
    let paths: Vec<&Path> = args.imus.iter().map(PathBuf::as_path).collect();
    let delays: Vec<f64> = rows.iter().map(|r| r.offset_s / period_s).collect();
    let mut d = Diagnostics::default();
    let samples = navsync::array::combine(
        &paths,
        &delays,
        args.fd_order as usize,
        0,
        &combined,
        &mut d,
    )?;

    // 3. Fuse the virtual IMU: independent units average their white noise
    // and instabilities down by 1/√N.
    let n = args.imus.len() as f64;
    let mut cfg = base.clone();
    cfg.imu_path = combined.clone();
    cfg.gnss_path = args.gnss.clone();
    let k = 1.0 / n.sqrt();
    cfg.noise.arw *= k;
    cfg.noise.vrw *= k;
    cfg.noise.gyro_bias_sd *= k;
    cfg.noise.accel_bias_sd *= k;
    cfg.noise.gyro_scale_sd *= k;
    cfg.noise.accel_scale_sd *= k;
    cfg.init_std.gyro_bias *= k;
    cfg.init_std.accel_bias *= k;
    cfg.init_std.gyro_scale *= k;
    cfg.init_std.accel_scale *= k;
    let dir = args.output.join("array");
    let opts = FuseOptions {
        output_dir: Some(dir.clone()),
        ..FuseOptions::default()
    };
    let mut sink = KfGinsSink::create(&dir, 0)?;
    pipeline::run(&cfg, &opts, &mut sink, &mut |_| {})?;
    sink.finish()?;
    let array_score = score(args.truth.as_deref(), &dir.join("navresult.nav"))?;

    println!(
        "{:<4} {:>14} {:>10} {:>16} {:>12} {:>10}",
        "IMU", "offset (ms)", "σ (ms)", "vs IMU 1 (ms)", "horiz RMS m", "yaw RMS °"
    );
    for (i, r) in rows.iter().enumerate() {
        let (h, y) = r
            .score
            .as_ref()
            .map(|s| {
                (
                    format!("{:.4}", s.pos_horizontal_m.rms),
                    format!("{:.4}", s.yaw_deg.rms),
                )
            })
            .unwrap_or_default();
        println!(
            "{:<4} {:>14.3} {:>10.3} {:>16.3} {:>12} {:>10}",
            i + 1,
            r.offset_s * 1e3,
            r.offset_sd_s * 1e3,
            r.offset_relative_to_first_s * 1e3,
            h,
            y
        );
    }
    if let Some(s) = &array_score {
        println!(
            "{:<4} {:>14} {:>10} {:>16} {:>12.4} {:>10.4}",
            "all", "aligned", "", "", s.pos_horizontal_m.rms, s.yaw_deg.rms
        );
    }
    let report = ArrayReport {
        imus: rows,
        array_score,
        combined_imu: combined.display().to_string(),
        samples,
    };
    std::fs::write(
        args.output.join("array.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    println!(
        "wrote {}/array.json, array_imu.txt, imu*/ and array/",
        args.output.display()
    );
    Ok(())
}
