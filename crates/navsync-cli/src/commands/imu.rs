//! `navsync imu`: IMU acquisition quality (seed 001 §1) — check a log
//! against the seed's rules, convert rates to KF-GINS increments with
//! averaging decimation, and find the lowest IMU rate that costs no
//! accuracy.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use navsync::Diagnostics;
use navsync::imu::decimate::{InputKind, InputSample};
use navsync::imu::log::{ImuLogFormat, ImuLogReader, Order, TimeOrder};
use navsync::imu::quality::{self, QualityConfig, QualityReport, Status};
use navsync::imu::{
    Conditioner, ConditionerConfig, DecRate, DecimationMethod, LowPassFilter, RateRule, RateSample,
};
use navsync::ins::ImuSample;
use navsync::io::kfgins::{TextWriter, format_imu_line};
use navsync::time::GpsTime;

use super::args;
use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: Sub,
}

#[derive(clap::Subcommand)]
pub enum Sub {
    /// Check an IMU log against the acquisition criteria of Tang, Zhang &
    /// Niu, "MEMS IMU raw data acquisition and time synchronization
    /// pitfalls" (i2Nav, 2022) §1.5: gaps, loss, bad data, precision,
    /// filter, noise.
    Check(CheckArgs),
    /// Convert rates (or increments) to KF-GINS increments, with
    /// averaging decimation.
    Convert(ConvertArgs),
    /// Decimate a KF-GINS configuration's IMU to several rates and compare
    /// the GNSS-outage drift (Tang, Zhang & Niu 2022 §1.3.3).
    RateStudy(RateStudyArgs),
    /// Time `imu check` on generated data (default 1 h at 200 Hz).
    Bench(BenchArgs),
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Format {
    /// sow dθx dθy dθz dvx dvy dvz [odo] (increments, rad and m/s)
    KfGins,
    /// time gx gy gz ax ay az (rates, rad/s and m/s²)
    RateCsv,
}

impl From<Format> for ImuLogFormat {
    fn from(f: Format) -> Self {
        match f {
            Format::KfGins => ImuLogFormat::KfGins,
            Format::RateCsv => ImuLogFormat::RateCsv,
        }
    }
}

#[derive(clap::Args)]
pub struct CheckArgs {
    /// The IMU log.
    pub file: PathBuf,
    /// Its format [default: detected from the values].
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// Also write the full report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Nominal output rate (Hz) [default: from the first intervals].
    #[arg(value_parser = args::rate(), long)]
    pub rate: Option<f64>,
    /// The IMU's internal (raw) sampling rate, if known (Hz).
    #[arg(value_parser = args::rate(), long)]
    pub raw_rate: Option<f64>,
    /// Gyro full scale (deg/s): samples at it are saturated.
    #[arg(value_parser = args::positive(1e5, "deg/s"), long)]
    pub gyro_range: Option<f64>,
    /// Accelerometer full scale (g).
    #[arg(value_parser = args::positive(1000.0, "g"), long)]
    pub accel_range: Option<f64>,
    /// The low-pass filter the IMU applied (TOML, see `imu convert --help`).
    #[arg(long)]
    pub lowpass: Option<PathBuf>,
    /// Longest acceptable gap (s).
    #[arg(value_parser = args::positive(3600.0, "s"), long, default_value_t = 0.1)]
    pub max_gap: f64,
    /// Findings to print (all are in the JSON).
    #[arg(value_parser = args::count(0, args::MAX_COUNT), long, default_value_t = 12)]
    pub show: usize,
    /// Exit with status 2 when the verdict is FAIL (for scripts and CI).
    #[arg(long)]
    pub strict: bool,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum From_ {
    /// Rates sampled at their time stamps (trapezoid).
    Rate,
    /// Rates averaged over the interval ending at their stamps (rectangle).
    RateAverage,
    /// Increments (passed through).
    Increment,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Method {
    /// Average rates / accumulate increments (Tang, Zhang & Niu 2022 §1.3).
    Average,
    /// Keep one sample per window (aliases; for comparison only).
    Point,
}

#[derive(clap::Args)]
pub struct ConvertArgs {
    /// Input log.
    pub input: PathBuf,
    /// Output KF-GINS IMU file (increments, full precision).
    pub output: PathBuf,
    /// What the input holds [default: from --format, or detected].
    #[arg(long, value_enum)]
    pub from: Option<From_>,
    /// Input format [default: detected].
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// Decimate by N = DEC_RATE + 1.
    #[arg(value_parser = args::count_u32(1, 10_000), long, default_value_t = 1)]
    pub decimate: u32,
    #[arg(long, value_enum, default_value_t = Method::Average)]
    pub method: Method,
    /// Nominal input rate (Hz) [default: from the first intervals].
    #[arg(value_parser = args::rate(), long)]
    pub rate: Option<f64>,
    /// Count windows (device DEC_RATE semantics) instead of ending them on
    /// multiples of the output period.
    #[arg(long)]
    pub no_align: bool,
    /// Seconds added to every time stamp (e.g. boot time → GPS sow).
    #[arg(value_parser = args::symmetric(args::MAX_SPAN_S, "s"), long, default_value_t = 0.0)]
    pub time_offset: f64,
    /// Low-pass filter the IMU applied: its group delay is removed from
    /// the time stamps. TOML: `sample_rate_hz = 2000`, then `kind = "fir"`
    /// with `taps = [...]`, `kind = "iir"` with `b`/`a`, `kind =
    /// "moving-average"`/`"bartlett"` with `n`, or `kind = "first-order"`
    /// with `cutoff_hz`.
    #[arg(long)]
    pub lowpass: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct RateStudyArgs {
    /// KF-GINS configuration whose IMU file is decimated.
    #[arg(long)]
    pub config: PathBuf,
    /// Output rates (Hz), each an integer divisor of the input rate.
    #[arg(value_parser = args::rate(), long, value_delimiter = ',', default_value = "200,100,50,25,10")]
    pub rates: Vec<f64>,
    /// Reference trajectory (11-column nav format).
    #[arg(long)]
    pub truth: PathBuf,
    #[arg(long, value_enum, default_value_t = Method::Average)]
    pub method: Method,
    /// Outage protocol: every PERIOD s, LEN s long, the first FIRST s in.
    #[arg(value_parser = args::real(1.0, args::MAX_SPAN_S, "s"), long, default_value_t = 180.0)]
    pub outage_period: f64,
    #[arg(value_parser = args::positive(args::MAX_SPAN_S, "s"), long, default_value_t = 60.0)]
    pub outage_len: f64,
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long, default_value_t = 120.0)]
    pub outage_first: f64,
    /// Apply the non-holonomic constraint in every run.
    #[arg(long)]
    pub nhc: bool,
    /// Folder for the decimated files [default: a temporary folder, removed].
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Also write the table as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct BenchArgs {
    #[arg(value_parser = args::real(1e-3, 168.0, "h"), long, default_value_t = 1.0)]
    pub hours: f64,
    #[arg(value_parser = args::rate(), long, default_value_t = 200.0)]
    pub rate: f64,
    /// Keep the generated file here (else a temporary file, removed).
    #[arg(long)]
    pub keep: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        Sub::Check(a) => check(a),
        Sub::Convert(a) => convert(a),
        Sub::RateStudy(a) => rate_study(a),
        Sub::Bench(a) => bench(a),
    }
}

/// The `--lowpass` filter description (TOML), if one is given.
fn load_lowpass(path: Option<&Path>) -> Result<Option<LowPassFilter>> {
    Ok(path
        .map(|p| LowPassFilter::load_with(p, |t| toml::from_str(t)))
        .transpose()?)
}

fn check(a: CheckArgs) -> Result<()> {
    if let Some(p) = &a.json {
        let mut inputs = vec![a.file.as_path()];
        inputs.extend(a.lowpass.as_deref());
        super::args::refuse_output_over_input(p, &inputs, "--json")?;
    }
    let started = Instant::now();
    let lowpass = load_lowpass(a.lowpass.as_deref())?;
    let cfg = QualityConfig {
        nominal_rate_hz: a.rate,
        raw_rate_hz: a.raw_rate,
        gyro_range_rad_s: a.gyro_range.map(f64::to_radians),
        accel_range_mps2: a.accel_range.map(|g| g * 9.80665),
        lowpass,
        max_gap_s: a.max_gap,
        ..Default::default()
    };
    let mut diag = Diagnostics::default();
    let report = quality::check_file(&a.file, a.format.map(Into::into), cfg, &mut diag)?;
    let elapsed = started.elapsed().as_secs_f64();
    print!("{}", format_check(&report, a.show));
    println!("(checked in {elapsed:.3} s)");
    if let Some(p) = &a.json {
        navsync::io::output::write_file(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if a.strict && report.verdict == Status::Fail {
        std::process::exit(2);
    }
    Ok(())
}

/// The verdict table.
pub fn format_check(r: &QualityReport, show: usize) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "navsync imu check: {} ({}, {} records, {:.2} s, {:.3} Hz)",
        r.file, r.format, r.records, r.duration_s, r.true_rate_hz
    );
    let _ = writeln!(
        s,
        "criteria: Tang, Zhang & Niu, \"MEMS IMU raw data acquisition and time synchronization pitfalls\" (i2Nav, 2022)"
    );
    let _ = writeln!(
        s,
        "{:<5} {:<13} {:<60} {:<26} measured",
        "", "section", "criterion", "limit"
    );
    for c in &r.criteria {
        let _ = writeln!(
            s,
            "{:<5} {:<13} {:<60} {:<26} {}",
            c.status.label(),
            c.section,
            c.rule,
            c.limit,
            c.measured
        );
    }
    let _ = writeln!(s, "verdict: {}", r.verdict.label());
    for n in &r.notes {
        let _ = writeln!(s, "note: {n}");
    }
    if let Some(lp) = &r.lowpass {
        let _ = writeln!(s, "warning: {}", lp.warning);
    }
    if !r.events.is_empty() {
        let total: usize = [
            r.counts.malformed_lines,
            r.counts.gaps,
            r.counts.duplicates,
            r.counts.out_of_order,
            r.counts.stale_records,
            r.counts.stuck_segments,
            r.counts.saturation_events,
            r.counts.spikes,
        ]
        .iter()
        .sum();
        let _ = writeln!(s, "findings ({total}; first {}):", show.min(r.events.len()));
        for e in r.events.iter().take(show) {
            let _ = writeln!(
                s,
                "  line {:>8}  {:<12} {}{}",
                e.line,
                format!("{:?}", e.kind).to_lowercase(),
                e.channel.map(|c| format!("{c}: ")).unwrap_or_default(),
                e.detail
            );
        }
    }
    s
}

fn convert(a: ConvertArgs) -> Result<()> {
    let started = Instant::now();
    anyhow::ensure!(a.decimate >= 1, "--decimate must be at least 1");
    let mut diag = Diagnostics::with_cap(1000);
    let format = match (a.format, a.from) {
        (Some(f), _) => Some(f.into()),
        (None, Some(From_::Increment)) => Some(ImuLogFormat::KfGins),
        (None, Some(_)) => Some(ImuLogFormat::RateCsv),
        (None, None) => None,
    };
    super::args::refuse_output_over_input(&a.output, &[&a.input], "the output")?;
    if let Some(lp) = &a.lowpass {
        super::args::refuse_output_over_input(&a.output, &[lp], "the output")?;
    }
    let mut reader = ImuLogReader::open(&a.input, format)?;
    // Read ahead to learn the format and the nominal rate.
    let mut head = Vec::new();
    while head.len() < 64 {
        match reader.next_record(&mut diag)? {
            Some(r) => head.push(r),
            None => break,
        }
    }
    let fmt = reader
        .format()
        .ok_or_else(|| anyhow::anyhow!("{}: no IMU records", a.input.display()))?;
    let input = match (a.from, fmt) {
        (Some(From_::Rate), _) => InputKind::Rate(RateRule::Trapezoid),
        (Some(From_::RateAverage), _) => InputKind::Rate(RateRule::Average),
        (Some(From_::Increment), _) => InputKind::Increment,
        (None, ImuLogFormat::RateCsv) => InputKind::Rate(RateRule::Trapezoid),
        (None, ImuLogFormat::KfGins) => InputKind::Increment,
    };
    anyhow::ensure!(
        (input == InputKind::Increment) == (fmt == ImuLogFormat::KfGins),
        "--from does not match the {} format of {}",
        fmt.name(),
        a.input.display()
    );
    let input_rate = match a.rate {
        Some(r) => r,
        None => {
            let mut dts: Vec<f64> = head
                .windows(2)
                .map(|w| (w[1].time_ns - w[0].time_ns) as f64 * 1e-9)
                .filter(|&d| d > 0.0)
                .collect();
            anyhow::ensure!(
                !dts.is_empty(),
                "{}: too few records to find the rate",
                a.input.display()
            );
            // Mean of the intervals that are not gaps: a clock that stamps
            // in coarse ticks has a median off the true rate.
            let med = navsync::stats::quantile(&mut dts, 0.5);
            let regular: Vec<f64> = dts.into_iter().filter(|&d| d < 1.5 * med).collect();
            regular.len() as f64 / regular.iter().sum::<f64>()
        }
    };
    let lowpass = load_lowpass(a.lowpass.as_deref())?;
    let delay_s = lowpass
        .as_ref()
        .map(|f| f.delay_compensation_s())
        .unwrap_or(0.0);
    if let Some(f) = &lowpass {
        eprintln!("warning: {}", f.warning(&f.group_delay(10.0)));
    }
    let cfg = ConditionerConfig {
        input,
        dec: DecRate::from_factor(a.decimate)?,
        method: match a.method {
            Method::Average => DecimationMethod::Average,
            Method::Point => DecimationMethod::Point,
        },
        input_rate_hz: Some(input_rate),
        // Windows end on multiples of the output period only for a round
        // input rate (a grid of 19.17 ms means nothing).
        align_to_grid: !a.no_align && is_round_rate(input_rate),
        delay_compensation_s: delay_s,
        ..Default::default()
    };
    let mut cond = Conditioner::new(cfg)?;
    let mut out = TextWriter::create(&a.output)?;
    let mut buf = Vec::with_capacity(1 << 20);
    let mut written = 0usize;
    let mut order = TimeOrder::default();
    let offset_ns = (a.time_offset * 1e9).round() as i64;
    let (mut dups, mut back) = (0usize, 0usize);
    let mut io_err: Option<navsync::Error> = None;
    {
        let mut emit = |s: ImuSample| {
            format_imu_line(&mut buf, &s);
            written += 1;
            if buf.len() > (1 << 20) - 512 {
                if let Err(e) = out.write(&buf) {
                    io_err.get_or_insert(e);
                }
                buf.clear();
            }
        };
        let mut pending = head.into_iter();
        loop {
            let rec = match pending.next() {
                Some(r) => r,
                None => match reader.next_record(&mut diag)? {
                    Some(r) => r,
                    None => break,
                },
            };
            match order.check(&a.input, &rec)? {
                Order::Next => {}
                Order::Duplicate => {
                    dups += 1;
                    diag.push(&a.input, rec.line, "duplicate time stamp; record skipped");
                    continue;
                }
                Order::Backwards => {
                    back += 1;
                    diag.push(&a.input, rec.line, "time goes backwards; record skipped");
                    continue;
                }
            }
            let time = GpsTime::from_ns(rec.time_ns + offset_ns);
            let v = rec.values;
            let s = match input {
                InputKind::Increment => InputSample::Increment(ImuSample {
                    time,
                    dtheta: [v[0], v[1], v[2]].into(),
                    dvel: [v[3], v[4], v[5]].into(),
                    odo_speed: rec.odo,
                }),
                InputKind::Rate(_) => InputSample::Rate(RateSample {
                    time,
                    gyro: [v[0], v[1], v[2]].into(),
                    accel: [v[3], v[4], v[5]].into(),
                }),
            };
            cond.push(&s, &mut emit);
        }
        cond.finish(&mut emit);
    }
    if let Some(e) = io_err {
        return Err(e.into());
    }
    out.write(&buf)?;
    out.finish()?;
    let st = cond.decimator_stats();
    println!(
        "navsync imu convert: {} ({}, {:.3} Hz) -> {} ({} increments at {:.3} Hz, {} method) in {:.3} s",
        a.input.display(),
        fmt.name(),
        input_rate,
        a.output.display(),
        written,
        input_rate / a.decimate as f64,
        match a.method {
            Method::Average => "average",
            Method::Point => "point",
        },
        started.elapsed().as_secs_f64()
    );
    if st.gaps > 0 || st.partial_windows > 0 {
        println!(
            "  input gaps: {}; output windows cut short or long: {}",
            st.gaps, st.partial_windows
        );
    }
    if let Some(c) = cond.convert_stats()
        && c.gaps_not_bridged > 0
    {
        println!(
            "  gaps over 0.1 s not integrated across: {}",
            c.gaps_not_bridged
        );
    }
    if delay_s != 0.0 {
        println!(
            "  time stamps shifted back by {:.3} ms (filter delay)",
            delay_s * 1e3
        );
    }
    if dups + back > 0 {
        println!("  skipped: {dups} duplicate and {back} backward time stamps");
    }
    if !diag.is_empty() {
        eprintln!("{} lines reported:", diag.total);
        print_diagnostics(&diag, 10);
    }
    Ok(())
}

/// A rate within 0.1 % of a whole number of Hz (or of 1/n Hz).
fn is_round_rate(hz: f64) -> bool {
    let r = if hz >= 1.0 { hz } else { 1.0 / hz };
    (r - r.round()).abs() < 1e-3 * r
}

fn rate_study(a: RateStudyArgs) -> Result<()> {
    use navsync::io::config::KfGinsConfig;
    use navsync::pipeline::{FuseOptions, NhcSettings, OutageSchedule};
    use navsync_sim::rate_study::{RateStudyOptions, rate_study as study};
    anyhow::ensure!(!a.rates.is_empty(), "--rates is empty");
    let outages = OutageSchedule {
        period_s: a.outage_period,
        len_s: a.outage_len,
        first_s: a.outage_first,
    };
    outages.validate().map_err(anyhow::Error::msg)?;
    let mut diag = Diagnostics::default();
    let cfg = KfGinsConfig::load(&a.config, &mut diag)?;
    if !diag.is_empty() {
        eprintln!("configuration notes:");
        print_diagnostics(&diag, 10);
    }
    let (work_dir, temp) = match &a.work_dir {
        Some(d) => (d.clone(), false),
        None => (
            std::env::temp_dir().join(format!("navsync-rate-study-{}", std::process::id())),
            true,
        ),
    };
    let opts = RateStudyOptions {
        rates_hz: a.rates.clone(),
        method: match a.method {
            Method::Average => DecimationMethod::Average,
            Method::Point => DecimationMethod::Point,
        },
        outages,
        truth: a.truth.clone(),
        fuse: FuseOptions {
            nhc: a.nhc.then(NhcSettings::default),
            ..Default::default()
        },
        work_dir: work_dir.clone(),
        keep_files: !temp,
    };
    let pb = crate::progress::bar("rates");
    let n = a.rates.len() as f64;
    let result = study(&cfg, &opts, &mut |k, f| {
        crate::progress::set(&pb, (k as f64 + f) / n)
    });
    pb.finish_and_clear();
    if temp {
        let _ = std::fs::remove_dir_all(&work_dir);
    }
    let rows = result?;
    println!(
        "navsync imu rate-study: {} ({} Hz input), {} decimation, GNSS outages {} s every {} s from +{} s",
        a.config.display(),
        cfg.imu_rate_hz,
        match a.method {
            Method::Average => "averaging",
            Method::Point => "point",
        },
        a.outage_len,
        a.outage_period,
        a.outage_first
    );
    println!(
        "{:>9} {:>8} {:>9} {:>7} {:>14} {:>11} {:>11} {:>13} {:>9} {:>7}",
        "rate Hz",
        "DEC_RATE",
        "samples",
        "outages",
        "RMS max hor m",
        "worst hor m",
        "RMS max 3D",
        "hor RMS all m",
        "yaw RMS",
        "time s"
    );
    let base = rows[0].rms_max_horizontal_m;
    for r in &rows {
        println!(
            "{:>9} {:>8} {:>9} {:>7} {:>14.3} {:>11.3} {:>11.3} {:>13.4} {:>9.4} {:>7.2}   {:+.1} %",
            r.rate_hz,
            r.dec_rate,
            r.imu_samples,
            r.outages,
            r.rms_max_horizontal_m,
            r.worst_horizontal_m,
            r.rms_max_3d_m,
            r.horizontal_rms_m,
            r.yaw_rms_deg,
            r.run_time_s,
            (r.rms_max_horizontal_m / base - 1.0) * 100.0
        );
    }
    println!("(last column: drift change against the first rate)");
    if let Some(p) = &a.json {
        navsync::io::output::write_file(p, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

fn bench(a: BenchArgs) -> Result<()> {
    use navsync::io::text::{LineReader, split_fields};
    let path = match &a.keep {
        Some(p) => p.clone(),
        None => std::env::temp_dir().join(format!("navsync-imu-bench-{}.txt", std::process::id())),
    };
    let t = Instant::now();
    let n = navsync_sim::synthetic::write_increment_log(&path, a.hours * 3600.0, a.rate, 300.0, 1)?;
    let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    println!(
        "generated {n} records ({:.1} h at {} Hz, {:.1} MB) in {:.2} s: {}",
        a.hours,
        a.rate,
        size as f64 / 1e6,
        t.elapsed().as_secs_f64(),
        path.display()
    );
    // Baseline: read every line and split its fields, nothing else.
    let t = Instant::now();
    let mut r = LineReader::open(&path)?;
    let mut fields = 0usize;
    while let Some((line, _)) = r.next_line()? {
        let mut f: [&[u8]; 12] = [b""; 12];
        fields += split_fields(line, &mut f);
    }
    let base = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut diag = Diagnostics::default();
    let report = quality::check_file(&path, None, QualityConfig::default(), &mut diag)?;
    let check_s = t.elapsed().as_secs_f64();
    println!("read + split lines (baseline): {base:.3} s ({fields} fields)");
    println!(
        "imu check:                     {check_s:.3} s = {:.1} x baseline, {:.0} ns/record; verdict {}",
        check_s / base,
        check_s / n as f64 * 1e9,
        report.verdict.label()
    );
    if a.keep.is_none() {
        let _ = std::fs::remove_file(&path);
    }
    Ok(())
}
