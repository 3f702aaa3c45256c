//! `navsync sync`: a raw rig log to GPS-time-stamped KF-GINS files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use navsync::io::kfgins::TextWriter;
use navsync::timing::file::{sync_file, write_kfgins_config};
use navsync::timing::{Oscillator, RateRule, SyncConfig, SyncMode, SyncReport};

use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// The raw log (rig-log v1).
    #[arg(required_unless_present = "bench")]
    pub rig: Option<PathBuf>,
    /// Output folder for imu.txt, gnss.txt, imu_times.txt, sync_report.json.
    #[arg(long, required_unless_present = "bench")]
    pub output: Option<PathBuf>,
    /// Hardware (1PPS + counter captures), hybrid (1PPS + counter for GPS
    /// time, IMU counters are receive times: an IMU on a serial port
    /// without sync pin), software (receive times only) or auto (hybrid
    /// when the header says `imu_timing: receive` or the imu intervals
    /// jitter far beyond the counter tick).
    #[arg(long, value_enum, default_value_t = Mode::Auto)]
    pub mode: Mode,
    /// Write the outputs and exit 0 even when the log's figures are
    /// implausible (loss, duplicates or irregular intervals over 1 %, a
    /// rate far from nominal).
    #[arg(long)]
    pub force: bool,
    /// Stamp every sample from past data only (as in real time).
    #[arg(long)]
    pub causal: bool,
    /// Known output delay T_c of an IMU timed by its serial frame (s),
    /// subtracted from every IMU stamp (Liu et al., "Data synchronization
    /// in IMU/GPS integrated measurement system of vehicle motion
    /// parameters"); in hybrid mode the fastest transport latency, which
    /// receive times cannot observe [default: the log header's
    /// `imu_output_delay_s`, else 0].
    #[arg(value_parser = args::non_negative(10.0, "s"), long)]
    pub imu_output_delay: Option<f64>,
    /// The counter's oscillator: how fast holdover error bounds grow.
    #[arg(long, value_enum, default_value_t = Osc::Xo)]
    pub oscillator: Osc,
    /// Software sync: assumed latency of the fastest GNSS message (s).
    #[arg(value_parser = args::non_negative(args::MAX_OFFSET_S, "s"), long, default_value_t = 0.0)]
    pub gnss_min_latency: f64,
    /// Rate → increment rule: trapezoid of consecutive samples (Tang, Zhang
    /// & Niu 2022 §1.1, for instantaneous rates) or average (rate already averaged
    /// over the interval, as an averaging/decimating IMU outputs)
    /// [default: the log header's `imu_rates`, else trapezoid].
    #[arg(long, value_enum)]
    pub rate_rule: Option<Rule>,
    /// True GPS time of each imu record ("week sow" lines): print the
    /// stamp errors and add them to the report.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Write DIR/kf-gins.yaml for `navsync fuse`, copying initial state and
    /// noise from this KF-GINS configuration.
    #[arg(long)]
    pub kfgins_template: Option<PathBuf>,
    /// Benchmark: generate a rig log of --hours at 200 Hz in a temporary
    /// file, synchronize it, print wall time and peak memory.
    #[arg(long)]
    pub bench: bool,
    /// Hours of data for --bench.
    #[arg(value_parser = args::real(1e-3, 168.0, "h"), long, default_value_t = 24.0, requires = "bench")]
    pub hours: f64,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Osc {
    /// Plain crystal: a 1 °C/min ramp may start at any time (≈ 30 µs after 60 s).
    Xo,
    /// Temperature-compensated crystal.
    Tcxo,
    /// Oven-controlled crystal.
    Ocxo,
}

impl From<Osc> for Oscillator {
    fn from(o: Osc) -> Self {
        match o {
            Osc::Xo => Oscillator::Xo,
            Osc::Tcxo => Oscillator::Tcxo,
            Osc::Ocxo => Oscillator::Ocxo,
        }
    }
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Rule {
    Trapezoid,
    Average,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Mode {
    Auto,
    Hw,
    Hybrid,
    Sw,
}

pub fn run(args: Args) -> Result<()> {
    if args.bench {
        return bench(&args);
    }
    let (Some(rig), Some(out_dir)) = (&args.rig, &args.output) else {
        bail!("sync needs RIG.csv and --output DIR");
    };
    let _held = super::take_output(out_dir, "sync")?;
    let cfg = SyncConfig {
        mode: match args.mode {
            Mode::Auto => SyncMode::Auto,
            Mode::Hw => SyncMode::Hw,
            Mode::Sw => SyncMode::Sw,
            Mode::Hybrid => SyncMode::Hybrid,
        },
        causal: args.causal,
        imu_output_delay_s: args.imu_output_delay,
        oscillator: args.oscillator.into(),
        sw: navsync::timing::SwConfig {
            gnss_min_latency_s: args.gnss_min_latency,
            ..Default::default()
        },
        source: rig.display().to_string(),
        ..Default::default()
    };
    let t0 = Instant::now();
    let rule = args.rate_rule.map(|r| match r {
        Rule::Trapezoid => RateRule::Trapezoid,
        Rule::Average => RateRule::Average,
    });
    let summary = sync_file(rig, out_dir, cfg, rule, args.truth.as_deref())?;
    let wall = t0.elapsed().as_secs_f64();
    if let Some(tpl) = &args.kfgins_template {
        write_kfgins_config(tpl, out_dir, &summary.report)?;
    }
    print_summary(&summary.report, wall);
    if !summary.read_diag.is_empty() {
        eprintln!("{} lines skipped while reading:", summary.read_diag.total);
        print_diagnostics(&summary.read_diag, 10);
    }
    if !summary.report.diagnostics.is_empty() {
        eprintln!("{} reported conditions:", summary.report.diagnostics.total);
        print_diagnostics(&summary.report.diagnostics, 10);
    }
    let bad = &summary.report.implausible;
    if bad.is_empty() {
        print_wrote(out_dir);
    } else {
        eprintln!();
        eprintln!(
            "navsync sync: IMPLAUSIBLE LOG {}: the stamps are not to be trusted",
            rig.display()
        );
        for b in bad {
            eprintln!("  - {}", b.what);
        }
        let mut causes: Vec<&Implausible> = Vec::new();
        for b in bad {
            if !causes.iter().any(|c| c.cause == b.cause) {
                causes.push(b);
            }
        }
        for c in causes {
            eprintln!("  likely cause: {}", c.cause);
            eprintln!("  fix: {}", c.fix);
        }
        if args.force {
            eprintln!("  --force: outputs written anyway");
            print_wrote(out_dir);
        } else {
            // No silent garbage: the time-stamped files are withdrawn; the
            // report stays for diagnosis.
            for f in [
                "imu.txt",
                "gnss.txt",
                "imu_times.txt",
                "heading.txt",
                "kf-gins.yaml",
            ] {
                let p = out_dir.join(f);
                if p.exists() {
                    let _ = std::fs::remove_file(&p);
                }
            }
            bail!(
                "implausible log {} ({} findings; see {}/sync_report.json): imu.txt, gnss.txt and imu_times.txt removed; --force keeps them",
                rig.display(),
                bad.len(),
                out_dir.display()
            );
        }
    }
    Ok(())
}

use super::args;
use navsync::timing::report::Implausible;

pub fn print_summary(r: &SyncReport, wall: f64) {
    let mode = if r.causal {
        "causal"
    } else {
        "post-processing"
    };
    println!(
        "navsync sync: {} sync ({mode}) of {} imu, {} pps, {} gnss records in {wall:.2} s",
        r.mode, r.records.imu, r.records.pps, r.records.gnss
    );
    if let Some(f) = &r.counter.freq_error_ppm {
        println!(
            "  counter: {:.3} ppm (range {:.3} … {:.3}), {} wraps",
            f.mean, f.min, f.max, r.counter.wraps
        );
    }
    if let Some(p) = &r.pps {
        let c = &p.counts;
        println!(
            "  pps: {} received, {} accepted; rejected {} displaced, {} spurious, {} duplicate, {} unconfirmed, {} at acquisition; innovation RMS {:.3} µs",
            c.received,
            c.accepted,
            c.rejected_displaced,
            c.rejected_spurious,
            c.rejected_duplicate,
            c.rejected_unconfirmed,
            c.rejected_acquisition,
            p.innovation_rms_us.unwrap_or(f64::NAN)
        );
    }
    for s in &r.lock_timeline {
        println!(
            "  {:<10} {} {:.3} … {:.3}",
            s.state, s.start.week, s.start.sow, s.end.sow
        );
    }
    for g in r.imu.logging_gaps.iter().take(10) {
        println!(
            "  imu logging gap: {:.1} s after {} {:.3} ({} samples missing; not counted as random loss)",
            g.length_s, g.start.week, g.start.sow, g.samples_missing
        );
    }
    for h in &r.holdover {
        println!(
            "  holdover {:.3} … {:.3} ({:.1} s), bound up to {:.2} µs",
            h.start.sow, h.end.sow, h.duration_s, h.max_bound_us
        );
    }
    let i = &r.imu;
    println!(
        "  imu: rate {:.6} Hz (nominal {}), lost {}, duplicated {}, irregular {}, unstamped {}; per GPS second {:?}",
        i.rate_hz.unwrap_or(f64::NAN),
        i.nominal_rate_hz
            .map(|v| format!("{v}"))
            .unwrap_or("-".into()),
        i.lost,
        i.duplicated,
        i.irregular_intervals,
        i.unstamped,
        i.samples_per_gps_second
    );
    let l = &r.gnss.latency_ms;
    println!(
        "  gnss: {} fixes, latency min/median/max {:.1}/{:.1}/{:.1} ms",
        r.gnss.stamped,
        l.min.unwrap_or(f64::NAN),
        l.median.unwrap_or(f64::NAN),
        l.max.unwrap_or(f64::NAN)
    );
    if let Some(sw) = &r.software {
        println!(
            "  software sync: {}; constant offset unobservable: {}",
            sw.describe(),
            sw.unobservable
        );
    }
    if let Some(h) = &r.hybrid {
        println!("  hybrid sync: {}", h.describe());
        println!("  constant offset unobservable: {}", h.unobservable);
    }
    if let Some(m) = &r.marks {
        println!("  receiver time marks: {}", m.describe());
    }
    println!(
        "  stamp bound: mean {:.3} µs, max {:.3} µs",
        r.stamp_bound_us.mean.unwrap_or(f64::NAN),
        r.stamp_bound_us.max.unwrap_or(f64::NAN)
    );
    if let Some(t) = &r.truth {
        println!(
            "  vs truth: {} stamps, RMS {:.3} µs, max {:.3} µs, mean {:.3} µs, sd {:.3} µs, within bound {:.2} %, largest step {:.3} µs",
            t.compared,
            t.rms_us,
            t.max_abs_us,
            t.mean_us,
            t.sd_us,
            100.0 * t.within_bound,
            t.max_step_us
        );
        if t.holdover_compared > 0 {
            println!(
                "  vs truth in holdover: {} stamps, RMS {:.3} µs, max {:.3} µs, within bound {:.2} %",
                t.holdover_compared,
                t.holdover_rms_us,
                t.holdover_max_abs_us,
                100.0 * t.holdover_within_bound
            );
        }
    }
}

/// The files `sync` leaves (printed once they are known to stay).
pub fn print_wrote(out_dir: &Path) {
    let heading = if out_dir.join("heading.txt").is_file() {
        ", heading.txt"
    } else {
        ""
    };
    println!(
        "  wrote {}/imu.txt, gnss.txt, imu_times.txt{heading}, sync_report.json",
        out_dir.display()
    );
}

/// `--bench`: a generated hardware-sync log of `hours` at 200 Hz.
fn bench(args: &Args) -> Result<()> {
    let hours = args.hours;
    anyhow::ensure!(hours > 0.0 && hours <= 168.0, "--hours must be in (0, 168]");
    let dir = std::env::temp_dir().join(format!("navsync-sync-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let rig = dir.join("rig.csv");
    let t0 = Instant::now();
    let n_imu = write_bench_log(&rig, hours)?;
    // The generated log goes to disk before the clock starts: its
    // write-back must not be charged to the synchronization.
    std::fs::File::open(&rig)
        .and_then(|f| f.sync_all())
        .with_context(|| format!("flushing {}", rig.display()))?;
    let gen_s = t0.elapsed().as_secs_f64();
    let size = std::fs::metadata(&rig)?.len();
    println!(
        "generated {:.1} h: {n_imu} imu records, {:.2} GB, in {gen_s:.1} s",
        hours,
        size as f64 / 1e9
    );
    let rss_before = crate::procstat::peak_rss_mb().unwrap_or(0.0);
    let cfg = SyncConfig {
        causal: args.causal,
        source: rig.display().to_string(),
        ..Default::default()
    };
    let t1 = Instant::now();
    let cpu0 = crate::procstat::cpu_seconds().unwrap_or(0.0);
    let out = dir.join("out");
    let res = sync_file(&rig, &out, cfg, Some(RateRule::Trapezoid), None);
    let wall = t1.elapsed().as_secs_f64();
    let cpu = crate::procstat::cpu_seconds().unwrap_or(0.0) - cpu0;
    let rss = crate::procstat::peak_rss_mb().unwrap_or(0.0);
    let _ = std::fs::remove_dir_all(&dir);
    let summary = res?;
    println!(
        "synchronized {} records ({} imu) in {wall:.2} s ({:.2} M records/s, {:.0} MB/s of log); peak RSS {:.1} MB (before the run {:.1} MB)",
        summary.records,
        summary.report.records.imu,
        summary.records as f64 / wall / 1e6,
        size as f64 / wall / 1e6,
        rss,
        rss_before
    );
    println!(
        "  CPU time {cpu:.2} s over all threads (load average now {})",
        crate::procstat::load_average().unwrap_or_default()
    );
    println!(
        "  imu rate {:.4} Hz, lost {}, pps accepted {} of {}",
        summary.report.imu.rate_hz.unwrap_or(f64::NAN),
        summary.report.imu.lost,
        summary
            .report
            .pps
            .as_ref()
            .map(|p| p.counts.accepted)
            .unwrap_or(0),
        summary.report.records.pps
    );
    Ok(())
}

/// Writes a hardware-sync rig log: 1 MHz 32-bit counter (+20 ppm), PPS,
/// 1 Hz GNSS 80 ms late, a 200 Hz IMU (−300 ppm) with small varying rates.
fn write_bench_log(path: &Path, hours: f64) -> Result<u64> {
    use navsync::io::riglog::{ImuKind, RigGnss, RigHeader, write};
    use navsync::time::GpsTime;
    let mut w = TextWriter::create(path)?;
    let mut buf = Vec::with_capacity(1 << 20);
    let mut header = RigHeader::new(1e6, 32, ImuKind::Rate);
    header.imu_rate_hz = Some(200.0);
    buf.extend_from_slice(header.to_text().as_bytes());
    let dur = hours * 3600.0;
    let f = 1e6 * (1.0 + 20e-6);
    let c0 = 4_000_000_000.0f64;
    let counter = |t: f64| -> u64 { ((c0 + t * f).floor() as u64) & 0xFFFF_FFFF };
    let imu_dt = 1.0 / (200.0 * (1.0 - 300e-6));
    let (week, sow0) = (2300i64, 100_000.0f64);
    let mut k = 0u64;
    let mut next_pps = 1.0;
    let mut next_gnss = 1.08;
    loop {
        let t_imu = 0.003 + k as f64 * imu_dt;
        if t_imu > dur {
            break;
        }
        // events in time order
        while next_pps <= t_imu || next_gnss <= t_imu {
            if next_pps <= next_gnss {
                write::pps(&mut buf, counter(next_pps));
                next_pps += 1.0;
            } else {
                let s = (next_gnss - 0.08f64).round();
                let fix = RigGnss {
                    counter: counter(next_gnss),
                    time: GpsTime::from_week_sow(week, sow0 + s),
                    lat_deg: 30.444784635,
                    lon_deg: 114.471867431,
                    h_m: 22.1037,
                    sd_m: [0.02, 0.02, 0.03],
                };
                write::gnss(&mut buf, &fix);
                next_gnss += 1.0;
            }
        }
        let ph = t_imu * 0.7;
        // Values to 1e-10, as a logger prints them.
        let vals = [
            1e-3 * ph.sin(),
            -2e-3 * ph.cos(),
            5e-4,
            0.1 * ph.cos(),
            0.05,
            -9.7935 + 0.01 * ph.sin(),
        ]
        .map(|v| (v * 1e10).round() / 1e10);
        write::imu(&mut buf, counter(t_imu), &vals);
        k += 1;
        if buf.len() > (1 << 20) - 256 {
            w.write(&buf)?;
            buf.clear();
        }
    }
    w.write(&buf)?;
    w.finish()?;
    Ok(k)
}
