//! `navsync simulate`: the virtual rig (trajectory, IMU, GNSS, clocks and
//! the raw logger), and `navsync simulate --bench`, its speed and memory.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use navsync_sim::scenario::{Scenario, base_layer, parse_override, set_path};
use navsync_sim::{SimReport, Simulation};
use serde_json::{Value, json};

use super::args;
use crate::progress;

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Sync {
    /// 1PPS and IMU data-ready edges latched by a counter.
    Hw,
    /// 1PPS latched; IMU timed by the start of its serial frame (no sync pin).
    Serial,
    /// No PPS: receive times only.
    Sw,
    /// 1PPS latched; IMU stamped at receipt (serial port, no sync pin).
    Hybrid,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum GnssMode {
    Rtk,
    Spp,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum RealLayout {
    /// KF-GINS C++: sow lat lon h vn ve vd sd_n sd_e sd_d sd_vn sd_ve sd_vd.
    Cpp,
    /// KF-GINS-Matlab: sow lat lon h sd_n sd_e sd_d vn ve vd sd_vn sd_ve sd_vd.
    Matlab,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Decimation {
    Average,
    Point,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Record {
    Rate,
    Increment,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Vibration {
    /// None.
    None,
    /// Road: 12 random tones in 10–60 Hz (0.2°/s, 0.5 m/s² RMS per axis).
    Road,
    /// Engine: tones at 101.5 Hz and 203 Hz (2nd/4th order at ~3000 rpm).
    Engine,
    /// Road and engine together.
    Car,
}

#[derive(clap::Args)]
pub struct Args {
    /// A built-in scenario (test-track, urban, figure8, static), a preset
    /// (demo: the `navsync demo` drive; hybrid: 1PPS captured, the IMU
    /// stamped at receipt) or a TOML file with [[segments]]
    /// and any other setting.
    #[arg(long, default_value = "urban")]
    pub scenario: String,
    /// Seed of every random error source.
    #[arg(value_parser = args::seed(), long)]
    pub seed: Option<u64>,
    /// Output folder.
    #[arg(long, required_unless_present = "bench")]
    pub output: Option<PathBuf>,
    /// Length of the run (s); built-in scenarios default to 600 s.
    #[arg(value_parser = args::real(1.0, args::MAX_SPAN_S, "s"), long)]
    pub duration: Option<f64>,
    /// Seed of the random trajectory (urban).
    #[arg(value_parser = args::seed(), long)]
    pub traj_seed: Option<u64>,
    /// IMU preset: nav, tactical, adis16465, icm20602, perfect.
    #[arg(long)]
    pub imu_grade: Option<String>,
    /// IMU output rate (Hz).
    #[arg(value_parser = args::real(1.0, 10_000.0, "Hz"), long)]
    pub imu_rate: Option<f64>,
    /// IMU internal sampling rate (Hz; a multiple of the output rate, 0 =
    /// ideal integrating IMU).
    #[arg(value_parser = args::non_negative(args::MAX_RATE_HZ, "Hz"), long)]
    pub internal_rate: Option<f64>,
    /// How the IMU decimates its internal samples.
    #[arg(long, value_enum)]
    pub decimation: Option<Decimation>,
    /// What `imu` records of rig.csv hold.
    #[arg(long, value_enum)]
    pub imu_record: Option<Record>,
    /// IMU vibration.
    #[arg(long, value_enum)]
    pub vibration: Option<Vibration>,
    /// GNSS fix rate (Hz).
    #[arg(value_parser = args::real(0.01, 100.0, "Hz"), long)]
    pub gnss_rate: Option<f64>,
    /// GNSS solution type (sets the noise).
    #[arg(long, value_enum)]
    pub gnss_mode: Option<GnssMode>,
    /// Point the KF-GINS configuration at the 13-column GNSS file.
    #[arg(long)]
    pub gnss_velocity: bool,
    /// A dual-antenna receiver: the baseline's yaw in the body frame (deg,
    /// from forward towards right) and the heading noise σ (deg), e.g.
    /// "30,0.2". A heading comes with every fix: heading.txt, and
    /// `heading` records in rig.csv.
    #[arg(long, value_name = "YAW_DEG,SD_DEG", allow_hyphen_values = true)]
    pub dual_antenna: Option<String>,
    /// GNSS outages "start:len,start:len" (s after the start).
    #[arg(long)]
    pub outages: Option<String>,
    /// PPS dropouts "start:len,…" (s after the start).
    #[arg(long)]
    pub pps_dropout: Option<String>,
    /// Logger counter frequency error (ppm).
    #[arg(value_parser = args::symmetric(1e4, "ppm"), long, allow_negative_numbers = true)]
    pub counter_ppm: Option<f64>,
    /// IMU sample-clock frequency error (ppm; −400 makes 200 Hz 199.92 Hz).
    #[arg(value_parser = args::symmetric(1e4, "ppm"), long, allow_negative_numbers = true)]
    pub imu_clock_ppm: Option<f64>,
    /// How the logger times the IMU.
    #[arg(long, value_enum)]
    pub sync: Option<Sync>,
    /// Probability that an IMU frame is lost.
    #[arg(value_parser = args::real(0.0, 0.99, ""), long)]
    pub lost_frames: Option<f64>,
    /// Follow a reference drive (a KF-GINS navigation file, e.g. a real
    /// vehicle's reference trajectory) instead of a built-in scenario: the
    /// IMU is simulated exactly along a smooth fit of it.
    #[arg(long, value_name = "NAV_FILE")]
    pub from_nav: Option<PathBuf>,
    /// With --from-nav: replay these real GNSS fixes (KF-GINS GNSS file, 7
    /// or 13 columns): each fix's real error from the reference antenna
    /// position and its stated σ are kept (set the antenna lever arm with
    /// --set gnss.lever_arm_m=[x,y,z]).
    #[arg(long, value_name = "GNSS_FILE", requires = "from_nav")]
    pub gnss_real: Option<PathBuf>,
    /// Column order of a 13-column --gnss-real file.
    #[arg(long, value_enum, default_value = "cpp", requires = "gnss_real")]
    pub gnss_real_layout: RealLayout,
    /// Any setting as key=value (TOML value), e.g.
    /// `--set imu.gyro.arw_deg_sqrt_h=0.3 --set rig.pps.jitter_s=1e-6`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Print no summary.
    #[arg(long)]
    pub quiet: bool,
    /// Benchmark: 1 h of 200 Hz IMU with 2 kHz internal sampling (default
    /// test-track scenario, ADIS16465, all files), timed, with peak memory.
    #[arg(long)]
    pub bench: bool,
}

/// Parses "a:b,c:d" into [[a, b], [c, d]].
fn windows(text: &str, what: &str) -> Result<Value> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (a, b) = part
            .split_once(':')
            .with_context(|| format!("{what}: '{part}' is not start:length"))?;
        let a: f64 = a
            .trim()
            .parse()
            .with_context(|| format!("{what}: '{a}' is not a number"))?;
        let b: f64 = b
            .trim()
            .parse()
            .with_context(|| format!("{what}: '{b}' is not a number"))?;
        if b.is_nan() || b < 0.0 {
            bail!("{what}: length {b} must be >= 0");
        }
        out.push(json!([a, b]));
    }
    Ok(Value::Array(out))
}

fn vibration_layer(v: Vibration) -> Value {
    let road =
        json!({"band_hz": [10.0, 60.0], "gyro_rms_deg_s": 0.2, "accel_rms_mps2": 0.5, "tones": 12});
    let engine = json!([
        {"freq_hz": 101.5, "gyro_amp_deg_s": [0.3, 0.3, 0.1], "accel_amp_mps2": [0.2, 0.2, 1.0]},
        {"freq_hz": 203.0, "gyro_amp_deg_s": [0.2, 0.2, 0.1], "accel_amp_mps2": [0.2, 0.2, 0.8]}
    ]);
    match v {
        Vibration::None => json!({"tones": []}),
        Vibration::Road => json!({"tones": [], "random": road}),
        Vibration::Engine => json!({"tones": engine}),
        Vibration::Car => json!({"tones": engine, "random": road}),
    }
}

/// The scenario from the arguments: file or built-in, then overrides.
pub fn scenario_from_args(a: &Args) -> Result<Scenario> {
    let mut layer = match &a.from_nav {
        None => base_layer(&a.scenario)?,
        Some(_) if a.scenario.ends_with(".toml") => base_layer(&a.scenario)?,
        Some(_) if a.scenario != "urban" => {
            bail!("--from-nav follows a reference drive: give no built-in --scenario with it")
        }
        Some(_) => json!({}),
    };
    let mut set = |k: &str, v: Value| set_path(&mut layer, k, v);
    if let Some(nav) = &a.from_nav {
        set("reference_nav", json!(nav.to_string_lossy()))?;
    }
    if let Some(g) = &a.gnss_real {
        set("gnss.real_fixes", json!(g.to_string_lossy()))?;
        set(
            "gnss.real_layout",
            json!(match a.gnss_real_layout {
                RealLayout::Cpp => "cpp",
                RealLayout::Matlab => "matlab",
            }),
        )?;
    }
    if let Some(s) = a.seed {
        set("seed", json!(s))?;
    }
    if let Some(d) = a.duration {
        set("duration_s", json!(d))?;
    }
    if let Some(s) = a.traj_seed {
        set("traj_seed", json!(s))?;
    }
    if let Some(g) = &a.imu_grade {
        set("imu.grade", json!(g))?;
    }
    if let Some(r) = a.imu_rate {
        set("imu.output_rate_hz", json!(r))?;
    }
    if let Some(r) = a.internal_rate {
        set("imu.internal_rate_hz", json!(r))?;
    }
    if let Some(d) = a.decimation {
        set(
            "imu.decimation",
            json!(match d {
                Decimation::Average => "average",
                Decimation::Point => "point",
            }),
        )?;
    }
    if let Some(r) = a.imu_record {
        set(
            "rig.imu_record",
            json!(match r {
                Record::Rate => "rate",
                Record::Increment => "increment",
            }),
        )?;
    }
    if let Some(v) = a.vibration {
        set("vibration", vibration_layer(v))?;
    }
    if let Some(r) = a.gnss_rate {
        set("gnss.rate_hz", json!(r))?;
    }
    if let Some(m) = a.gnss_mode {
        set(
            "gnss.mode",
            json!(match m {
                GnssMode::Rtk => "rtk",
                GnssMode::Spp => "spp",
            }),
        )?;
    }
    if a.gnss_velocity {
        set("gnss.velocity", json!(true))?;
    }
    if let Some(d) = &a.dual_antenna {
        let v: Vec<f64> = d
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("--dual-antenna {d:?}: {e}"))?;
        let [yaw, sd] = v[..] else {
            anyhow::bail!("--dual-antenna {d:?}: expected YAW_DEG,SD_DEG");
        };
        anyhow::ensure!(
            yaw.is_finite() && yaw.abs() <= 360.0 && sd > 0.0 && sd <= 30.0,
            "--dual-antenna {d:?}: the yaw within ±360° and the σ within (0, 30]°"
        );
        set(
            "gnss.dual_antenna",
            json!({"mount_yaw_deg": yaw, "sd_deg": sd}),
        )?;
    }
    if let Some(o) = &a.outages {
        set("gnss.outages", windows(o, "--outages")?)?;
    }
    if let Some(o) = &a.pps_dropout {
        set("rig.pps.dropouts", windows(o, "--pps-dropout")?)?;
    }
    if let Some(p) = a.counter_ppm {
        set("rig.counter.freq_error_ppm", json!(p))?;
    }
    if let Some(p) = a.imu_clock_ppm {
        set("imu.clock.freq_error_ppm", json!(p))?;
    }
    if let Some(s) = a.sync {
        set(
            "rig.sync",
            json!(match s {
                Sync::Hw => "hw",
                Sync::Serial => "serial",
                Sync::Sw => "sw",
                Sync::Hybrid => "hybrid",
            }),
        )?;
    }
    if let Some(p) = a.lost_frames {
        set("rig.imu_link.loss_prob", json!(p))?;
    }
    for s in &a.set {
        let (k, v) = parse_override(s)?;
        set(&k, v)?;
    }
    Ok(Scenario::from_layer(layer)?)
}

pub fn run(args: Args) -> Result<()> {
    if args.bench {
        return bench(&args);
    }
    let scn = scenario_from_args(&args)?;
    let out = args.output.clone().context("--output is required")?;
    let _held = super::take_output(&out, "simulate")?;
    let sim = Simulation::new(scn)?;
    let argv: Vec<String> = std::env::args().collect();
    let pb = progress::bar("simulate");
    let report = sim.run(&out, &argv, &mut |f| progress::set(&pb, f))?;
    pb.finish_and_clear();
    if !args.quiet {
        print_summary(&sim, &report, &out);
    }
    Ok(())
}

fn print_summary(sim: &Simulation, r: &SimReport, out: &Path) {
    let s = &sim.scenario;
    println!(
        "simulated {:.0} s ({}; seed {}; IMU {} at {} Hz{}; GNSS {:?} {} Hz; sync {}) in {:.2} s",
        sim.duration_s(),
        s.reference_nav
            .as_deref()
            .or(s.trajectory.as_deref())
            .unwrap_or("user segments"),
        s.seed,
        s.imu.grade,
        s.imu.output_rate_hz,
        if s.imu.internal_rate_hz > 0.0 {
            format!(" from {} Hz internal", s.imu.internal_rate_hz)
        } else {
            String::new()
        },
        s.gnss.mode,
        s.gnss.rate_hz,
        s.rig.sync.name(),
        r.runtime_s
    );
    let m = &r.motion;
    println!(
        "  motion: {:.0} m, max {:.1} m/s, yaw rate {:.1}°/s, lateral {:.2} m/s², longitudinal {:.2} m/s², height {:.1}..{:.1} m",
        m.distance_m,
        m.max_speed_mps,
        m.max_yaw_rate_deg_s,
        m.max_lateral_accel_mps2,
        m.max_long_accel_mps2,
        m.height_range_m[0],
        m.height_range_m[1]
    );
    println!(
        "  IMU: {} samples ({:.5} Hz mean), rig records {}, lost {} (+{} in gaps), duplicated {}, spikes {}",
        r.imu_samples,
        r.imu_mean_rate_hz,
        r.imu_records,
        r.imu_lost.count,
        r.imu_gap_lost,
        r.imu_duplicated.count,
        r.imu_spikes.count
    );
    println!(
        "  GNSS: {} fixes ({} withheld by outages, {} outliers), latency {:.1}–{:.1} ms; PPS {} (dropped {}, displaced {}, spurious {})",
        r.gnss_fixes,
        r.gnss_removed_by_outages,
        r.gnss_outliers.count,
        r.gnss_latency_s[0] * 1e3,
        r.gnss_latency_s[1] * 1e3,
        r.pps_pulses,
        r.pps_dropped,
        r.pps_displaced.count,
        r.pps_spurious.count
    );
    println!("  files in {}: {}", out.display(), r.files.join(", "));
    println!(
        "  next: navsync fuse --config {}",
        out.join("kf-gins.yaml").display()
    );
}

fn dir_size_mb(dir: &Path) -> f64 {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| e.metadata().ok())
                .map(|m| m.len() as f64)
                .sum::<f64>()
                / 1e6
        })
        .unwrap_or(0.0)
}

/// 1 h at 200 Hz with 2 kHz internal sampling: wall time and peak memory
/// against the goal (≤ 3 s) and the reference Python simulator (~25 s).
fn bench(args: &Args) -> Result<()> {
    let mut a = Args {
        scenario: args.scenario.clone(),
        seed: args.seed,
        output: None,
        duration: Some(args.duration.unwrap_or(3600.0)),
        traj_seed: args.traj_seed,
        imu_grade: Some(args.imu_grade.clone().unwrap_or_else(|| "adis16465".into())),
        imu_rate: args.imu_rate,
        internal_rate: args.internal_rate,
        decimation: args.decimation,
        imu_record: args.imu_record,
        vibration: args.vibration,
        gnss_rate: args.gnss_rate,
        gnss_mode: args.gnss_mode,
        gnss_velocity: args.gnss_velocity,
        dual_antenna: args.dual_antenna.clone(),
        outages: args.outages.clone(),
        pps_dropout: args.pps_dropout.clone(),
        counter_ppm: args.counter_ppm,
        imu_clock_ppm: args.imu_clock_ppm,
        sync: args.sync,
        lost_frames: args.lost_frames,
        from_nav: args.from_nav.clone(),
        gnss_real: args.gnss_real.clone(),
        gnss_real_layout: args.gnss_real_layout,
        set: args.set.clone(),
        quiet: true,
        bench: false,
    };
    if a.scenario == "urban" && !args.scenario.ends_with(".toml") {
        a.scenario = "test-track".into();
    }
    let scn = scenario_from_args(&a)?;
    let keep = args.output.is_some();
    let dir = args.output.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("navsync-simbench-{}", std::process::id()))
    });
    let sim = Simulation::new(scn)?;
    let cpu0 = crate::procstat::cpu_seconds();
    let t0 = Instant::now();
    let report = sim.run(&dir, &["navsync simulate --bench".into()], &mut |_| {})?;
    let wall = t0.elapsed().as_secs_f64();
    let cpu = crate::procstat::cpu_seconds().zip(cpu0).map(|(a, b)| a - b);
    let rss = crate::procstat::peak_rss_mb();
    let size = dir_size_mb(&dir);
    let s = &sim.scenario;
    let internal = if s.imu.internal_rate_hz > 0.0 {
        (report.imu_samples as f64 * s.imu.internal_rate_hz / s.imu.output_rate_hz) as u64
    } else {
        0
    };
    println!(
        "navsync simulate bench: {} s of {} ({} IMU, {} Hz output, {} Hz internal), sync {}",
        sim.duration_s(),
        s.trajectory.as_deref().unwrap_or("segments"),
        s.imu.grade,
        s.imu.output_rate_hz,
        s.imu.internal_rate_hz,
        s.rig.sync.name()
    );
    println!(
        "  samples: {} IMU outputs, {} internal samples, {} rig records, {} GNSS fixes; {:.0} MB written",
        report.imu_samples, internal, report.imu_records, report.gnss_fixes, size
    );
    println!(
        "  wall time: {wall:.2} s  (goal 3.0 s: {:.2}x the goal{}; reference Python simulator ~25 s: {:.1}x faster)",
        wall / 3.0,
        if wall <= 3.0 { ", met" } else { ", NOT met" },
        25.0 / wall
    );
    if let Some(c) = cpu {
        println!(
            "  CPU time: {c:.2} s (simulation and file writing run on two threads; wall ≈ CPU/2 on an idle 2-core machine)"
        );
    }
    match rss {
        Some(m) => println!("  peak memory (VmHWM): {m:.1} MB"),
        None => println!("  peak memory: unavailable (no /proc/self/status)"),
    }
    println!(
        "  throughput: {:.2} M IMU outputs/s, {:.1} M internal samples/s",
        report.imu_samples as f64 / wall / 1e6,
        internal as f64 / wall / 1e6
    );
    if !keep {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(())
}
