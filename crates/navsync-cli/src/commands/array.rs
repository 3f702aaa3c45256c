//! `navsync array`: an IMU array with unknown relative time offsets
//! (seed 004): the units' delays relative to the first from their gyros,
//! every stream shifted onto the first unit's time with a Lagrange
//! fractional-delay filter and averaged into one virtual IMU, which is
//! fused with the time-offset state (the offset common to all units). Each
//! unit is also fused alone with its own offset state, for its score and
//! as a GNSS-only check of the delays.

use std::path::{Path, PathBuf};

use super::args;
use anyhow::{Context, Result};
use navsync::Diagnostics;
use navsync::array::RelativeDelay;
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
    /// Largest relative delay searched between two units (s).
    #[arg(value_parser = args::positive(args::MAX_OFFSET_SEARCH_S, "s"), long, default_value_t = 0.5)]
    pub max_delay: f64,
}

#[derive(Serialize)]
struct ImuRow {
    file: String,
    /// Offset of this unit's tags to GNSS time (GNSS tag − true validity
    /// on this unit's time base): the array's common offset minus the
    /// unit's delay relative to the first.
    offset_s: f64,
    offset_sd_s: f64,
    /// The unit's data are this much later than the first unit's (gyros).
    delay_relative_to_first: RelativeDelay,
    /// This unit fused alone with its own offset state.
    alone_offset_s: f64,
    alone_offset_sd_s: f64,
    score: Option<EvalReport>,
}

#[derive(Serialize)]
struct ArrayReport {
    /// The offset common to the array (first unit's tags), from the fused
    /// aligned array.
    common_offset_s: f64,
    common_offset_sd_s: f64,
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

    // 1. The units' delays relative to the first, from their gyros.
    let paths: Vec<&Path> = args.imus.iter().map(PathBuf::as_path).collect();
    let mut d = Diagnostics::default();
    let delays = navsync::array::relative_delays(&paths, period_s, args.max_delay, 0, &mut d)?;

    // 2. Each IMU alone with the GNSS and the time-offset state.
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
        rows.push(ImuRow {
            file: imu.display().to_string(),
            offset_s: f64::NAN,
            offset_sd_s: f64::NAN,
            delay_relative_to_first: delays[i],
            alone_offset_s: summary.time_offset_s.unwrap_or(0.0),
            alone_offset_sd_s: summary.time_offset_sd_s.unwrap_or(f64::NAN),
            score: score(args.truth.as_deref(), &dir.join("navresult.nav"))?,
        });
    }

    // 3. Align every stream onto the first unit's time (advance unit i by
    // its delay d_i: a delay of −d_i / T samples) and average.
    let combined = args.output.join("array_imu.txt");
    let shifts: Vec<f64> = delays.iter().map(|r| -r.delay_s / period_s).collect();
    let samples = navsync::array::combine(
        &paths,
        &shifts,
        args.fd_order as usize,
        0,
        &combined,
        &mut d,
    )?;

    // 4. Fuse the virtual IMU with the time-offset state (the offset
    // common to the array): independent units average their white noise
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
        time_offset: Some(TimeOffsetOptions::default()),
        output_gnss_time: true,
        ..FuseOptions::default()
    };
    let mut sink = KfGinsSink::create(&dir, 0)?;
    let summary = pipeline::run(&cfg, &opts, &mut sink, &mut |_| {})?;
    sink.finish()?;
    let array_score = score(args.truth.as_deref(), &dir.join("navresult.nav"))?;
    let common = summary.time_offset_s.unwrap_or(0.0);
    let common_sd = summary.time_offset_sd_s.unwrap_or(f64::NAN);
    // An IMU whose data are late by d sees GNSS fixes early: τ_i = τ_1 − d_i.
    for r in &mut rows {
        let d = r.delay_relative_to_first;
        r.offset_s = common - d.delay_s;
        r.offset_sd_s = (common_sd * common_sd + d.sd_s * d.sd_s).sqrt();
    }

    println!(
        "common offset of the array (first unit's tags − GNSS validity): {:.3} ± {:.3} ms",
        common * 1e3,
        common_sd * 1e3
    );
    println!(
        "{:<4} {:>12} {:>10} {:>14} {:>9} {:>12} {:>10} {:>12} {:>10}",
        "IMU",
        "delay (ms)",
        "σ (ms)",
        "offset (ms)",
        "σ (ms)",
        "alone (ms)",
        "σ (ms)",
        "horiz RMS m",
        "yaw RMS °"
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
            "{:<4} {:>12.3} {:>10.3} {:>14.3} {:>9.3} {:>12.3} {:>10.3} {:>12} {:>10}",
            i + 1,
            r.delay_relative_to_first.delay_s * 1e3,
            r.delay_relative_to_first.sd_s * 1e3,
            r.offset_s * 1e3,
            r.offset_sd_s * 1e3,
            r.alone_offset_s * 1e3,
            r.alone_offset_sd_s * 1e3,
            h,
            y
        );
    }
    if let Some(s) = &array_score {
        println!(
            "{:<4} {:>12} {:>10} {:>14} {:>9} {:>12} {:>10} {:>12.4} {:>10.4}",
            "all", "aligned", "", "", "", "", "", s.pos_horizontal_m.rms, s.yaw_deg.rms
        );
    }
    let report = ArrayReport {
        common_offset_s: common,
        common_offset_sd_s: common_sd,
        imus: rows,
        array_score,
        combined_imu: combined.display().to_string(),
        samples,
    };
    navsync::io::output::write_file(
        args.output.join("array.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    println!(
        "wrote {}/array.json, array_imu.txt, imu*/ and array/",
        args.output.display()
    );
    Ok(())
}
