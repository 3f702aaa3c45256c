//! `navsync sync`: a raw rig log to GPS-time-stamped KF-GINS files.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use navsync::Diagnostics;
use navsync::ins::ImuSample;
use navsync::io::kfgins::{TextWriter, format_gnss_line};
use navsync::io::riglog::{RigLogReader, RigRecord};
use navsync::timing::report::{TruthAccumulator, TruthTimes, format_week_sow};
use navsync::timing::{
    IncrementBuilder, Oscillator, RateRule, SyncConfig, SyncEngine, SyncMode, SyncOutput,
    SyncReport,
};

use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// The raw log (rig-log v1).
    #[arg(required_unless_present = "bench")]
    pub rig: Option<PathBuf>,
    /// Output folder for imu.txt, gnss.txt, imu_times.txt, sync_report.json.
    #[arg(long, required_unless_present = "bench")]
    pub output: Option<PathBuf>,
    /// Hardware (1PPS + counter), software (receive times) or auto.
    #[arg(long, value_enum, default_value_t = Mode::Auto)]
    pub mode: Mode,
    /// Stamp every sample from past data only (as in real time).
    #[arg(long)]
    pub causal: bool,
    /// Known output delay T_c of an IMU timed by its serial frame (s),
    /// subtracted from every IMU stamp (seed 000).
    #[arg(long, default_value_t = 0.0)]
    pub imu_output_delay: f64,
    /// The counter's oscillator: how fast holdover error bounds grow.
    #[arg(long, value_enum, default_value_t = Osc::Xo)]
    pub oscillator: Osc,
    /// Software sync: assumed latency of the fastest GNSS message (s).
    #[arg(long, default_value_t = 0.0)]
    pub gnss_min_latency: f64,
    /// Rate → increment rule: trapezoid of consecutive samples (seed 001
    /// §1.1, for instantaneous rates) or average (rate already averaged
    /// over the interval, as an averaging/decimating IMU outputs).
    #[arg(long, value_enum, default_value_t = Rule::Trapezoid)]
    pub rate_rule: Rule,
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
    #[arg(long, default_value_t = 24.0, requires = "bench")]
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
    Sw,
}

pub fn run(args: Args) -> Result<()> {
    if args.bench {
        return bench(&args);
    }
    let (Some(rig), Some(out_dir)) = (&args.rig, &args.output) else {
        bail!("sync needs RIG.csv and --output DIR");
    };
    let cfg = SyncConfig {
        mode: match args.mode {
            Mode::Auto => SyncMode::Auto,
            Mode::Hw => SyncMode::Hw,
            Mode::Sw => SyncMode::Sw,
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
    let rule = match args.rate_rule {
        Rule::Trapezoid => RateRule::Trapezoid,
        Rule::Average => RateRule::Average,
    };
    let summary = sync_file(rig, out_dir, cfg, rule, args.truth.as_deref())?;
    let wall = t0.elapsed().as_secs_f64();
    if let Some(tpl) = &args.kfgins_template {
        write_kfgins_config(tpl, out_dir, &summary.report)?;
    }
    print_summary(&summary.report, wall, out_dir);
    if !summary.read_diag.is_empty() {
        eprintln!("{} lines skipped while reading:", summary.read_diag.total);
        print_diagnostics(&summary.read_diag, 10);
    }
    if !summary.report.diagnostics.is_empty() {
        eprintln!("{} reported conditions:", summary.report.diagnostics.total);
        print_diagnostics(&summary.report.diagnostics, 10);
    }
    Ok(())
}

/// What a synchronization run produced.
pub struct SyncSummary {
    pub report: SyncReport,
    pub read_diag: Diagnostics,
    pub records: usize,
}

/// Batches passed between the reader, engine and writer threads.
const BATCH: usize = 8192;

/// Reads `rig`, synchronizes, writes the outputs into `out_dir`. The reader
/// and the writer run on their own threads; memory stays bounded by the
/// channel depth.
pub fn sync_file(
    rig: &Path,
    out_dir: &Path,
    cfg: SyncConfig,
    rule: RateRule,
    truth: Option<&Path>,
) -> Result<SyncSummary> {
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let mut read_diag = Diagnostics::default();
    let mut reader = RigLogReader::open(rig, &mut read_diag)?;
    let header = reader.header().clone();
    let kind = header.imu_kind;

    // Reader thread: parsed records in batches.
    let (rec_tx, rec_rx) = mpsc::sync_channel::<Vec<(RigRecord, usize)>>(8);
    let reader_handle = std::thread::Builder::new()
        .name("rig-reader".into())
        .spawn(move || -> Result<(Diagnostics, usize)> {
            let mut diag = read_diag;
            let mut batch = Vec::with_capacity(BATCH);
            while let Some(r) = reader.next_record(&mut diag)? {
                batch.push(r);
                if batch.len() == BATCH {
                    let full = std::mem::replace(&mut batch, Vec::with_capacity(BATCH));
                    if rec_tx.send(full).is_err() {
                        break;
                    }
                }
            }
            if !batch.is_empty() {
                let _ = rec_tx.send(batch);
            }
            Ok((diag, reader.records()))
        })?;

    // Writer thread: formatting and files.
    let (out_tx, out_rx) = mpsc::sync_channel::<Vec<SyncOutput>>(8);
    let dir = out_dir.to_path_buf();
    let truth_path = truth.map(Path::to_path_buf);
    let writer_handle = std::thread::Builder::new()
        .name("sync-writer".into())
        .spawn(move || -> Result<Option<TruthAccumulator>> {
            let mut imu_w = TextWriter::create(&dir.join("imu.txt"))?;
            let mut gnss_w = TextWriter::create(&dir.join("gnss.txt"))?;
            let mut times_w = TextWriter::create(&dir.join("imu_times.txt"))?;
            let mut truth = match &truth_path {
                Some(p) => Some((TruthTimes::open(p)?, TruthAccumulator::default())),
                None => None,
            };
            let mut inc = IncrementBuilder::with_rule(kind, rule);
            let mut buf_imu = Vec::with_capacity(1 << 20);
            let mut buf_times = Vec::with_capacity(1 << 18);
            let mut buf_gnss = Vec::with_capacity(1 << 12);
            let mut truth_short = false;
            for batch in out_rx {
                for o in batch {
                    match o {
                        SyncOutput::Imu(s) => {
                            if s.flags.unstamped {
                                buf_times.extend_from_slice(b"-1 nan\n");
                            } else {
                                format_week_sow(&mut buf_times, s.time);
                            }
                            if let Some((tt, acc)) = &mut truth {
                                match tt.next_time()? {
                                    Some(true_t) => {
                                        if !s.flags.unstamped && !s.flags.duplicate {
                                            acc.push(s.time, true_t, s.bound_s, s.flags.holdover)
                                        }
                                    }
                                    None => truth_short = true,
                                }
                            }
                            if let Some(sample) = inc.push(s.time, &s.values, &s.flags) {
                                push_imu_line(&mut buf_imu, &sample);
                            }
                        }
                        SyncOutput::Gnss(g) => {
                            format_gnss_line(&mut buf_gnss, &g.fix());
                        }
                    }
                }
                imu_w.write(&buf_imu)?;
                times_w.write(&buf_times)?;
                gnss_w.write(&buf_gnss)?;
                buf_imu.clear();
                buf_times.clear();
                buf_gnss.clear();
            }
            imu_w.finish()?;
            gnss_w.finish()?;
            times_w.finish()?;
            if truth_short {
                eprintln!("warning: the truth file has fewer lines than the log has imu records");
            }
            Ok(truth.map(|(_, acc)| acc))
        })?;

    let mut engine = SyncEngine::new(&header, cfg);
    let mut out = Vec::with_capacity(BATCH * 2);
    let mut send_err = false;
    for batch in rec_rx {
        for (rec, line) in batch {
            engine.push_into(rec, line, &mut out);
        }
        if out.len() >= BATCH {
            let full = std::mem::replace(&mut out, Vec::with_capacity(BATCH * 2));
            if out_tx.send(full).is_err() {
                send_err = true;
                break;
            }
        }
    }
    let (read_diag, records) = reader_handle
        .join()
        .map_err(|_| anyhow::anyhow!("reader thread panicked"))??;
    let finished = engine.finish();
    let (rest, mut report) = match finished {
        Ok(v) => v,
        Err(e) => {
            drop(out_tx);
            let _ = writer_handle.join();
            return Err(e.into());
        }
    };
    out.extend(rest);
    if !send_err {
        let _ = out_tx.send(out);
    }
    drop(out_tx);
    let acc = writer_handle
        .join()
        .map_err(|_| anyhow::anyhow!("writer thread panicked"))??;
    report.truth = acc.map(|a| a.finish());
    let json = serde_json::to_string_pretty(&report)?;
    let rp = out_dir.join("sync_report.json");
    std::fs::write(&rp, json).with_context(|| format!("writing {}", rp.display()))?;
    Ok(SyncSummary {
        report,
        read_diag,
        records,
    })
}

fn print_summary(r: &SyncReport, wall: f64, out_dir: &Path) {
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
            "  software sync: jitter ≈ {:.4} ms (1σ), host clock {:.2} ppm; constant offset unobservable: {}",
            sw.jitter_sd_ms,
            sw.host_clock_error_ppm.unwrap_or(f64::NAN),
            sw.unobservable
        );
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
    println!(
        "  wrote {}/imu.txt, gnss.txt, imu_times.txt, sync_report.json",
        out_dir.display()
    );
}

/// Writes DIR/kf-gins.yaml: the template with paths, rate and start time
/// replaced by this run's.
fn write_kfgins_config(template: &Path, out_dir: &Path, r: &SyncReport) -> Result<()> {
    let text = std::fs::read_to_string(template)
        .with_context(|| format!("reading {}", template.display()))?;
    let rate = r.imu.rate_hz.unwrap_or(200.0).round();
    let start = r.first_stamp.map(|w| w.sow).unwrap_or(0.0);
    let mut out = String::new();
    out.push_str("# KF-GINS configuration written by navsync sync\n");
    for line in text.lines() {
        let key = line.split(':').next().unwrap_or("").trim();
        let new = match key {
            "imupath" => Some("imupath: \"./imu.txt\"".to_string()),
            "gnsspath" => Some("gnsspath: \"./gnss.txt\"".to_string()),
            "outputpath" => Some("outputpath: \"./out\"".to_string()),
            "imudatarate" => Some(format!("imudatarate: {rate}")),
            "starttime" => Some(format!("starttime: {start:.9}")),
            _ => None,
        };
        out.push_str(new.as_deref().unwrap_or(line));
        out.push('\n');
    }
    let p = out_dir.join("kf-gins.yaml");
    std::fs::write(&p, out).with_context(|| format!("writing {}", p.display()))?;
    Ok(())
}

/// A KF-GINS IMU line, like `io::kfgins::format_imu_line` (every bit kept:
/// shortest round-trip form) but with a faster float printer.
fn push_imu_line(out: &mut Vec<u8>, s: &ImuSample) {
    s.time.write_sow(out);
    let mut b = zmij::Buffer::new();
    for v in s.dtheta.iter().chain(s.dvel.iter()) {
        out.push(b' ');
        out.extend_from_slice(b.format(*v).as_bytes());
    }
    out.push(b'\n');
}

/// CPU time of this process, all threads (s), from /proc/self/stat.
fn cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = s.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Peak resident memory of this process (kB), from /proc/self/status.
fn peak_rss_kb() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
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
    let gen_s = t0.elapsed().as_secs_f64();
    let size = std::fs::metadata(&rig)?.len();
    println!(
        "generated {:.1} h: {n_imu} imu records, {:.2} GB, in {gen_s:.1} s",
        hours,
        size as f64 / 1e9
    );
    let rss_before = peak_rss_kb().unwrap_or(0);
    let cfg = SyncConfig {
        causal: args.causal,
        source: rig.display().to_string(),
        ..Default::default()
    };
    let t1 = Instant::now();
    let cpu0 = cpu_seconds().unwrap_or(0.0);
    let out = dir.join("out");
    let res = sync_file(&rig, &out, cfg, RateRule::Trapezoid, None);
    let wall = t1.elapsed().as_secs_f64();
    let cpu = cpu_seconds().unwrap_or(0.0) - cpu0;
    let rss = peak_rss_kb().unwrap_or(0);
    let _ = std::fs::remove_dir_all(&dir);
    let summary = res?;
    println!(
        "synchronized {} records ({} imu) in {wall:.2} s ({:.2} M records/s, {:.0} MB/s of log); peak RSS {:.1} MB (before the run {:.1} MB)",
        summary.records,
        summary.report.records.imu,
        summary.records as f64 / wall / 1e6,
        size as f64 / wall / 1e6,
        rss as f64 / 1024.0,
        rss_before as f64 / 1024.0
    );
    println!(
        "  CPU time {cpu:.2} s over all threads (load average now {})",
        std::fs::read_to_string("/proc/loadavg")
            .ok()
            .and_then(|l| l.split_whitespace().next().map(str::to_string))
            .unwrap_or_default()
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
    use navsync::io::text::{push_fixed, push_u64};
    let mut w = TextWriter::create(path)?;
    let mut buf = Vec::with_capacity(1 << 20);
    buf.extend_from_slice(
        b"# rig-log v1\n# counter_hz: 1000000\n# counter_bits: 32\n# imu: rate\n# imu_rate_hz: 200\n",
    );
    let dur = hours * 3600.0;
    let f = 1e6 * (1.0 + 20e-6);
    let c0 = 4_000_000_000.0f64;
    let counter = |t: f64| -> u64 { ((c0 + t * f).floor() as u64) & 0xFFFF_FFFF };
    let imu_dt = 1.0 / (200.0 * (1.0 - 300e-6));
    let (week, sow0) = (2300u64, 100_000u64);
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
                buf.extend_from_slice(b"pps,");
                push_u64(&mut buf, counter(next_pps));
                buf.push(b'\n');
                next_pps += 1.0;
            } else {
                let s = (next_gnss - 0.08).round() as u64;
                buf.extend_from_slice(b"gnss,");
                push_u64(&mut buf, counter(next_gnss));
                buf.push(b',');
                push_u64(&mut buf, week);
                buf.push(b',');
                push_u64(&mut buf, sow0 + s);
                buf.extend_from_slice(b".000,30.444784635,114.471867431,22.1037,0.02,0.02,0.03\n");
                next_gnss += 1.0;
            }
        }
        buf.extend_from_slice(b"imu,");
        push_u64(&mut buf, counter(t_imu));
        let ph = t_imu * 0.7;
        let vals = [
            1e-3 * ph.sin(),
            -2e-3 * ph.cos(),
            5e-4,
            0.1 * ph.cos(),
            0.05,
            -9.7935 + 0.01 * ph.sin(),
        ];
        for v in vals {
            buf.push(b',');
            push_fixed(&mut buf, v, 10);
        }
        buf.push(b'\n');
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
