//! `navsync bench`: speed and memory of the navigation core, end to end.
//!
//! Generates `--hours` of a test-track drive (ADIS16465-class IMU at
//! 200 Hz, 1 Hz RTK GNSS) with the simulator, then runs the real user
//! command `navsync fuse --config …` on it as a child process several times
//! (read, fuse, write the 200 Hz nav file) and prints the median wall time
//! and the child's peak memory (from its summary.json). As a baseline
//! measured in the same run it times the I/O floor in this process: the
//! same files read and parsed, and one nav line per IMU sample formatted
//! and written, with no navigation at all. With `--smooth` it also times
//! `navsync fuse --smooth` (forward run, RTS backward pass, smoothed and
//! forward files written) against the forward run of the same round.
//! With `--kfgins BIN` it also times that KF-GINS binary on the same files
//! in the same rounds; without it, KF-GINS's figure is one measured
//! elsewhere and the output says so.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use super::args;
use anyhow::{Context, Result, bail, ensure};
use navsync::Diagnostics;
use navsync::ins::{ImuErrors, NavState};
use navsync::io::config::KfGinsConfig;
use navsync::io::kfgins::{GnssLayout, GnssReader, ImuReader};
use navsync::pipeline::{KfGinsSink, NavSink};
use navsync_sim::Simulation;
use navsync_sim::scenario::Scenario;
use serde_json::json;

/// KF-GINS (C++) on 1 h of 200 Hz IMU + 1 Hz GNSS, a figure measured
/// elsewhere on a machine of this class (not in this run), and the goal of
/// at least 20 times faster.
const KFGINS_WALL_S: f64 = 17.0;
const GOAL_WALL_S: f64 = 0.9;
const GOAL_PEAK_MB: f64 = 50.0;
/// Smoothing: at most this multiple of the forward run's wall time, and
/// this peak memory for 1 h.
const GOAL_SMOOTH_RATIO: f64 = 2.5;
const GOAL_SMOOTH_PEAK_MB: f64 = 300.0;

#[derive(clap::Args)]
pub struct Args {
    /// Hours of 200 Hz IMU data to generate and fuse.
    #[arg(value_parser = args::real(1e-3, 168.0, "h"), long, default_value_t = 1.0)]
    pub hours: f64,
    /// Timed runs of `navsync fuse` (the median is reported).
    #[arg(value_parser = args::count(1, 1000), long, default_value_t = 5)]
    pub runs: usize,
    /// Also time `navsync fuse --smooth` in every round.
    #[arg(long)]
    pub smooth: bool,
    /// A KF-GINS executable (i2Nav-WHU/KF-GINS, C++): timed on the same
    /// generated files in the same rounds (`BIN kf-gins.yaml`, run in the
    /// data folder). Without it the comparison quotes a figure measured
    /// elsewhere.
    #[arg(long, value_name = "BIN")]
    pub kfgins: Option<std::path::PathBuf>,
}

/// Runs KF-GINS on `config` in `dir` (its paths are relative to the working
/// directory); returns the wall time (s).
fn time_kfgins(bin: &Path, config: &Path, dir: &Path) -> Result<f64> {
    std::fs::create_dir_all(dir.join("out")).context("creating the KF-GINS output folder")?;
    let t = Instant::now();
    let child = Command::new(bin)
        .arg(config)
        .current_dir(dir)
        .output()
        .with_context(|| format!("starting {}", bin.display()))?;
    let wall = t.elapsed().as_secs_f64();
    if !child.status.success() {
        bail!(
            "{} failed ({}) on the generated data:\n{}",
            bin.display(),
            child.status,
            String::from_utf8_lossy(&child.stderr)
        );
    }
    Ok(wall)
}

/// Runs `navsync fuse` on `config` into `out` with `extra` arguments;
/// returns the wall time (s) and its summary.json.
fn time_fuse(
    exe: &Path,
    config: &Path,
    out: &Path,
    extra: &[&str],
) -> Result<(f64, serde_json::Value)> {
    let t = Instant::now();
    let child = Command::new(exe)
        .arg("fuse")
        .arg("--config")
        .arg(config)
        .arg("--output")
        .arg(out)
        .args(extra)
        .output()
        .context("starting navsync fuse")?;
    let wall = t.elapsed().as_secs_f64();
    if !child.status.success() {
        bail!(
            "navsync fuse {} failed ({}) on the generated data:\n{}",
            extra.join(" "),
            child.status,
            String::from_utf8_lossy(&child.stderr)
        );
    }
    let summary: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.join("summary.json")).context("reading summary.json")?,
    )?;
    Ok((wall, summary))
}

pub fn run(args: Args) -> Result<()> {
    ensure!(
        args.hours > 0.0 && args.hours <= 24.0,
        "--hours must be in (0, 24]"
    );
    ensure!(args.runs >= 1, "--runs must be at least 1");
    let dir = std::env::temp_dir().join(format!("navsync-bench-{}", std::process::id()));
    let result = bench_in(&dir, &args);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn bench_in(dir: &Path, args: &Args) -> Result<()> {
    let duration_s = args.hours * 3600.0;
    let layer = json!({
        "trajectory": "test-track",
        "duration_s": duration_s,
        "imu": {"grade": "adis16465", "output_rate_hz": 200.0, "internal_rate_hz": 0.0},
        "gnss": {"rate_hz": 1.0},
        "output": {"rig_log": false},
    });
    let sim = Simulation::new(Scenario::from_layer(layer)?)?;
    let t0 = Instant::now();
    let report = sim.run(dir, &["navsync bench".into()], &mut |_| {})?;
    println!(
        "navsync bench: {:.1} h test-track drive, {} IMU samples (200 Hz) and {} GNSS fixes (1 Hz), generated in {:.1} s",
        args.hours,
        report.imu_samples,
        report.gnss_fixes,
        t0.elapsed().as_secs_f64()
    );
    let config = dir.join("kf-gins.yaml");
    let exe = std::env::current_exe().context("locating the navsync executable")?;

    let mut fuse_wall = Vec::with_capacity(args.runs);
    let mut floor_wall = Vec::with_capacity(args.runs);
    let mut peak_mb = Vec::with_capacity(args.runs);
    let mut smooth_wall = Vec::with_capacity(args.runs);
    let mut smooth_peak_mb = Vec::new();
    let mut smooth_temp_mb: Option<f64> = None;
    let mut kfgins_wall = Vec::new();
    for run in 0..args.runs {
        // Alternate the two so that both see the same machine state.
        let out = dir.join(format!("out{run}"));
        let (wall, summary) = time_fuse(&exe, &config, &out, &[])?;
        fuse_wall.push(wall);
        if let Some(m) = summary.get("peak_memory_mb").and_then(|v| v.as_f64()) {
            peak_mb.push(m);
        }
        let _ = std::fs::remove_dir_all(&out);
        if args.smooth {
            let out = dir.join(format!("smooth{run}"));
            let (wall, summary) = time_fuse(&exe, &config, &out, &["--smooth"])?;
            smooth_wall.push(wall);
            if let Some(m) = summary.get("peak_memory_mb").and_then(|v| v.as_f64()) {
                smooth_peak_mb.push(m);
            }
            smooth_temp_mb = summary
                .pointer("/smoother/temp_bytes")
                .and_then(|v| v.as_f64())
                .map(|b| b / 1e6);
            let _ = std::fs::remove_dir_all(&out);
        }
        if let Some(bin) = &args.kfgins {
            kfgins_wall.push(time_kfgins(bin, &config, dir)?);
            let _ = std::fs::remove_dir_all(dir.join("out"));
        }
        let floor_out = dir.join(format!("floor{run}"));
        floor_wall.push(io_floor(&config, &floor_out)?);
        let _ = std::fs::remove_dir_all(&floor_out);
    }
    let (fuse, fuse_min, fuse_max) = median_min_max(&mut fuse_wall);
    let (floor, _, _) = median_min_max(&mut floor_wall);
    let scale = args.hours;
    println!(
        "  navsync fuse, end to end (process start, read, fuse, write the 200 Hz nav file), {} runs: median {fuse:.3} s (min {fuse_min:.3}, max {fuse_max:.3})",
        args.runs
    );
    println!(
        "  I/O floor in the same run (read and parse both files, format and write one nav line per sample, no navigation): median {floor:.3} s; fuse / floor = {:.2}",
        fuse / floor
    );
    if args.kfgins.is_some() {
        let (kf, kf_min, kf_max) = median_min_max(&mut kfgins_wall);
        println!(
            "  KF-GINS on the same files in the same run, {} runs: median {kf:.3} s (min {kf_min:.3}, max {kf_max:.3}); navsync {:.1}x faster",
            args.runs,
            kf / fuse
        );
    } else {
        println!(
            "  against KF-GINS (~{KFGINS_WALL_S:.0} s per hour, a figure measured elsewhere, not in this run; --kfgins BIN times it here): {:.1}x faster",
            KFGINS_WALL_S * scale / fuse
        );
    }
    println!(
        "  goal ≤ {:.2} s for this length: {}",
        GOAL_WALL_S * scale,
        if fuse <= GOAL_WALL_S * scale {
            "met"
        } else {
            "NOT met"
        }
    );
    match peak_mb.iter().cloned().reduce(f64::max) {
        Some(m) => println!(
            "  peak memory of navsync fuse (VmHWM, worst run): {m:.1} MB; goal ≤ {GOAL_PEAK_MB:.0} MB: {}",
            if m <= GOAL_PEAK_MB { "met" } else { "NOT met" }
        ),
        None => println!("  peak memory: unavailable (no /proc on this system)"),
    }
    if args.smooth {
        let (sm, sm_min, sm_max) = median_min_max(&mut smooth_wall);
        println!(
            "  navsync fuse --smooth, end to end (forward run, backward pass, smoothed and forward files written), {} runs: median {sm:.3} s (min {sm_min:.3}, max {sm_max:.3}); / forward = {:.2}; goal ≤ {GOAL_SMOOTH_RATIO}: {}",
            args.runs,
            sm / fuse,
            if sm / fuse <= GOAL_SMOOTH_RATIO {
                "met"
            } else {
                "NOT met"
            }
        );
        match smooth_peak_mb.iter().cloned().reduce(f64::max) {
            Some(m) => println!(
                "  peak memory of navsync fuse --smooth (VmHWM, worst run): {m:.1} MB (goal ≤ {GOAL_SMOOTH_PEAK_MB:.0} MB for 1 h: {}); temporary files {:.0} MB",
                if m <= GOAL_SMOOTH_PEAK_MB {
                    "met"
                } else {
                    "NOT met"
                },
                smooth_temp_mb.unwrap_or(f64::NAN)
            ),
            None => println!("  peak memory: unavailable (no /proc on this system)"),
        }
    }
    println!(
        "  load average now {}",
        crate::procstat::load_average().unwrap_or_else(|| "unknown".into())
    );
    Ok(())
}

/// Reads the configuration's IMU and GNSS files and writes one nav line
/// per IMU sample through the same writer as `fuse`, without navigating.
/// Returns the wall time (s).
fn io_floor(config: &Path, out: &Path) -> Result<f64> {
    let t = Instant::now();
    let mut diag = Diagnostics::default();
    let cfg = KfGinsConfig::load(config, &mut diag)?;
    let week = 0;
    let mut gnss = GnssReader::open(&cfg.gnss_path, week, GnssLayout::Cpp)?;
    let mut fixes = 0usize;
    while gnss.next_fix(&mut diag)?.is_some() {
        fixes += 1;
    }
    let mut imu = ImuReader::open(&cfg.imu_path, week)?;
    let mut sink = KfGinsSink::create(out, week)?;
    let errors = ImuErrors::default();
    let mut nav = NavState::new(
        navsync::GpsTime::from_week_ns(week, 0),
        cfg.init_pos,
        cfg.init_vel,
        &cfg.init_att,
    );
    while let Some(s) = imu.next_sample(&mut diag)? {
        nav.time = s.time;
        sink.nav(&nav, &errors)?;
    }
    sink.finish()?;
    ensure!(fixes > 0, "the generated GNSS file is empty");
    Ok(t.elapsed().as_secs_f64())
}

/// Sorts `v` and returns its median, minimum and maximum.
fn median_min_max(v: &mut [f64]) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    (median, v[0], v[n - 1])
}
