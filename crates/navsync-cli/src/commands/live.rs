//! `navsync live`: serial GNSS + IMU and kernel PPS, synchronized and fused
//! in real time (the work is in the `navsync-live` library, Linux only; on
//! other systems the command says so and exits non-zero).

use std::path::PathBuf;

use anyhow::Result;
#[cfg(target_os = "linux")]
use {
    anyhow::{Context, bail},
    navsync::Diagnostics,
    navsync::fusion::NavOutput,
    navsync::io::config::KfGinsConfig,
    navsync::pipeline::{FuseOptions, fusion_config},
    navsync_live::files::FileSink,
    navsync_live::imu::ImuLineFormat,
    navsync_live::live::{NavInfo, SourceId, stop_on_ctrl_c},
    navsync_live::selftest::{self, SelftestConfig},
    navsync_live::{LiveConfig, LiveSink, LiveStatus, PortConfig, PpsInput, status_line},
    std::time::{Duration, Instant},
};

use super::args;
#[cfg(target_os = "linux")]
use super::print_diagnostics;
use super::sync::Osc;

// Read only by the Linux implementation.
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
#[derive(clap::Args)]
pub struct Args {
    /// GNSS receiver serial port (UBX NAV-PVT or NMEA GGA+GST+RMC/ZDA).
    #[arg(long, required_unless_present = "selftest")]
    pub gnss: Option<PathBuf>,
    #[arg(long, default_value_t = 115200)]
    pub gnss_baud: u32,
    /// IMU serial port (one text line per sample, see --imu-format; not
    /// with `--imu-format ubx-esf`).
    #[arg(long)]
    pub imu: Option<PathBuf>,
    #[arg(long, default_value_t = 115200)]
    pub imu_baud: u32,
    /// IMU line format: `rate` = gx gy gz (rad/s) ax ay az (m/s²), FRD;
    /// `increment` = dθ (rad) dv (m/s); `rate-csv` = t then the six rates
    /// (t not used); `ubx-esf` = no IMU port: the receiver's ESF-RAW (or
    /// ESF-MEAS) messages on the GNSS port, values in the sensor's axes.
    #[arg(long, value_enum, default_value_t = Format::Rate)]
    pub imu_format: Format,
    /// `ubx-esf`: seconds per ESF time-tag tick.
    #[arg(value_parser = args::real(1e-9, 1.0, "s"), long, default_value_t = 1e-3)]
    pub esf_tick: f64,
    /// Nominal IMU rate (Hz) [default: the config's imudatarate].
    #[arg(value_parser = args::rate(), long)]
    pub imu_rate: Option<f64>,
    /// Known IMU output delay T_c (s), subtracted from its stamps (Liu et
    /// al., "Data synchronization in IMU/GPS integrated measurement system
    /// of vehicle motion parameters").
    #[arg(value_parser = args::non_negative(10.0, "s"), long, default_value_t = 0.0)]
    pub imu_output_delay: f64,
    /// Receive time (s) the IMU's sample clock waits after a late line
    /// before deciding whether samples were lost before it; lines on time
    /// are stamped at once. Shorter: late lines' solutions come sooner, but
    /// a latency excursion longer than this is taken for a loss.
    #[arg(value_parser = args::positive(60.0, "s"), long, default_value_t = navsync_live::live::DEFAULT_IMU_LOOKAHEAD_S)]
    pub imu_lookahead: f64,
    /// Kernel PPS device (RFC 2783), e.g. /dev/pps0. Without it, the
    /// clock is synchronized from receive times only.
    #[arg(long)]
    pub pps: Option<PathBuf>,
    /// The host clock's oscillator: how fast holdover bounds grow.
    #[arg(long, value_enum, default_value_t = Osc::Xo)]
    pub oscillator: Osc,
    /// KF-GINS YAML configuration: noise, initial attitude and σ, lever arm
    /// (the initial position comes from the first GNSS fix; paths and
    /// start/end times are not used).
    #[arg(long, required_unless_present = "selftest")]
    pub config: Option<PathBuf>,
    /// Write DIR/navresult.nav (KF-GINS, every IMU epoch), imu_err.txt and
    /// std.txt (once a second) and live_report.json (the self-test: the
    /// first three).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Without --output: solution lines printed per second.
    #[arg(value_parser = args::real(1e-3, 1000.0, "Hz"), long, default_value_t = 1.0)]
    pub print_rate: f64,
    /// Status line interval (s).
    #[arg(value_parser = args::real(1e-3, 3600.0, "s"), long, default_value_t = 1.0)]
    pub status_interval: f64,
    /// Stop after this many seconds (default: Ctrl-C).
    #[arg(value_parser = args::positive(args::MAX_SPAN_S, "s"), long)]
    pub duration: Option<f64>,
    /// Record every IMU line, GNSS fix and PPS edge received, on the host
    /// counter, as a rig log for `navsync sync` (written to the OS every
    /// 0.25 s; an existing file is refused).
    #[arg(long, value_name = "RIG.csv")]
    pub record: Option<PathBuf>,
    /// Record the receiver's bytes as read from its port (raw.ubx,
    /// raw.nmea) for `navsync convert`.
    #[arg(long, value_name = "FILE")]
    pub record_gnss: Option<PathBuf>,
    /// Fuse the receiver's dual-antenna headings (moving-base UBX
    /// NAV-RELPOSNED, or NMEA HDT). With the configuration's initial yaw
    /// σ above 90°, the first heading also gives the initial yaw.
    #[arg(long)]
    pub heading: bool,
    #[command(flatten)]
    pub dual_antenna: super::fuse::DualAntennaArgs,
    /// σ of NMEA HDT headings (deg; HDT carries none), as `convert --hdt-sd`.
    #[arg(value_parser = args::positive(30.0, "deg"), long, default_value_t = 0.5, requires = "heading")]
    pub hdt_sd: f64,
    /// Measure the live loop on pseudo-terminals at real rate (200 Hz IMU,
    /// 10 Hz GNSS, injected PPS with a gap): lost samples, latency, CPU.
    #[arg(long)]
    pub selftest: bool,
    /// Self-test length (minutes).
    #[arg(value_parser = args::real(0.1, 10_080.0, "min"), long, default_value_t = 10.0, requires = "selftest")]
    pub minutes: f64,
    /// Self-test: PPS removed this many seconds into the run…
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long, default_value_t = 240.0, requires = "selftest")]
    pub pps_gap_start: f64,
    /// …for this long (s); 0 keeps it.
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long, default_value_t = 60.0, requires = "selftest")]
    pub pps_gap: f64,
    /// Self-test GNSS messages.
    #[arg(long, value_enum, default_value_t = Gnss::Ubx, requires = "selftest")]
    pub selftest_gnss: Gnss,
    /// Self-test: the IMU in ESF-RAW messages on the GNSS port.
    #[arg(long, requires = "selftest")]
    pub selftest_esf: bool,
    /// Self-test: write the report here (JSON).
    #[arg(long, requires = "selftest")]
    pub json: Option<PathBuf>,
}

// Read only by the Linux implementation.
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Format {
    Rate,
    Increment,
    RateCsv,
    UbxEsf,
}

// Read only by the Linux implementation.
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Gnss {
    Ubx,
    Nmea,
}

/// Prints the status and the solution at a limited rate; writes every
/// epoch to navresult.nav with --output.
#[cfg(target_os = "linux")]
struct CliSink {
    file: Option<FileSink>,
    print_every: Option<Duration>,
    next_print: Instant,
}

#[cfg(target_os = "linux")]
impl LiveSink for CliSink {
    fn nav(&mut self, out: &NavOutput, _info: &NavInfo) -> Result<(), navsync::Error> {
        if let Some(f) = self.file.as_mut() {
            f.nav(out)?;
        } else if let Some(every) = self.print_every
            && Instant::now() >= self.next_print
        {
            self.next_print = Instant::now() + every;
            let n = &out.nav;
            let a = n.euler().to_deg();
            println!(
                "{} {:.3} {:.9} {:.9} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3}",
                n.time.week(),
                n.time.sow(),
                n.pos.lat_rad.to_degrees(),
                n.pos.lon_rad.to_degrees(),
                n.pos.h_m,
                n.vel.x,
                n.vel.y,
                n.vel.z,
                a[0],
                a[1],
                a[2]
            );
        }
        Ok(())
    }

    fn aux(&mut self, out: &NavOutput, sd: &[f64]) -> Result<(), navsync::Error> {
        match self.file.as_mut() {
            Some(f) => f.aux(out, sd),
            None => Ok(()),
        }
    }

    fn status(&mut self, s: &LiveStatus) {
        println!("{}", status_line(s));
    }

    fn note(&mut self, source: SourceId, msg: &str) {
        eprintln!("navsync live: {source}: {msg}");
    }
}

/// `navsync live` needs Linux (termios serial ports, the RFC 2783 PPS API).
#[cfg(not(target_os = "linux"))]
pub fn run(_args: Args) -> Result<()> {
    anyhow::bail!(
        "navsync live works on Linux only (serial ports through termios, 1PPS through the kernel PPS API, RFC 2783); this build is for {}",
        std::env::consts::OS
    )
}

#[cfg(target_os = "linux")]
pub fn run(args: Args) -> Result<()> {
    if args.selftest {
        return run_selftest(&args);
    }
    let (Some(gnss), Some(config)) = (&args.gnss, &args.config) else {
        bail!(
            "live needs --gnss PORT, --imu PORT (or --imu-format ubx-esf) and --config kf-gins.yaml"
        );
    };
    let esf = matches!(args.imu_format, Format::UbxEsf);
    let imu = match (&args.imu, esf) {
        (Some(p), false) => Some(PortConfig {
            path: p.clone(),
            baud: args.imu_baud,
        }),
        (None, true) => None,
        (None, false) => bail!("live needs --imu PORT (or --imu-format ubx-esf)"),
        (Some(_), true) => bail!("--imu-format ubx-esf reads the IMU on the GNSS port: drop --imu"),
    };
    let mut diag = Diagnostics::default();
    let kf = KfGinsConfig::load(config, &mut diag)?;
    // Its data paths are not used live: notes about them are beside the point.
    diag.items
        .retain(|d| !d.message.contains("working directory"));
    diag.total = diag.items.len();
    if !diag.is_empty() {
        print_diagnostics(&diag, 10);
    }
    let mut fusion = fusion_config(&kf, &FuseOptions::default());
    if args.heading {
        fusion.heading = Some(args.dual_antenna.fusion_options()?);
    }
    let pps = match &args.pps {
        Some(p) => PpsInput::Kernel(p.clone()),
        None => {
            eprintln!("navsync live: no --pps: synchronizing from receive times only (tens of ms)");
            PpsInput::None
        }
    };
    let mut cfg = LiveConfig::new(
        PortConfig {
            path: gnss.clone(),
            baud: args.gnss_baud,
        },
        imu,
        pps,
        fusion,
    );
    cfg.imu_format = match args.imu_format {
        Format::Increment => ImuLineFormat::Increment,
        Format::RateCsv => ImuLineFormat::RateCsv,
        Format::Rate | Format::UbxEsf => ImuLineFormat::Rate,
    };
    cfg.esf_tick_s = esf.then_some(args.esf_tick);
    cfg.imu_rate_hz = args.imu_rate.unwrap_or(kf.imu_rate_hz);
    cfg.imu_output_delay_s = args.imu_output_delay;
    anyhow::ensure!(
        args.imu_lookahead.is_finite() && args.imu_lookahead >= 0.0,
        "--imu-lookahead {} must be a non-negative number of seconds",
        args.imu_lookahead
    );
    cfg.imu_lookahead_s = args.imu_lookahead;
    cfg.oscillator = args.oscillator.into();
    anyhow::ensure!(
        args.status_interval > 0.0,
        "--status-interval must be positive"
    );
    cfg.status_interval = Duration::from_secs_f64(args.status_interval);
    if let Some(d) = args.duration {
        anyhow::ensure!(d > 0.0, "--duration must be positive");
        cfg.duration = Some(Duration::from_secs_f64(d));
    }
    cfg.hdt_sd_deg = args.hdt_sd;
    cfg.record = args.record.clone();
    cfg.record_gnss = args.record_gnss.clone();
    let _held = match &args.output {
        Some(dir) => Some(super::take_output(dir, "live")?),
        None => None,
    };
    let mut sink = CliSink {
        file: args.output.as_deref().map(FileSink::new),
        print_every: (args.print_rate > 0.0)
            .then(|| Duration::from_secs_f64(1.0 / args.print_rate)),
        next_print: Instant::now(),
    };
    let stop = stop_on_ctrl_c();
    let report = navsync_live::run(cfg, stop, &mut sink)?;
    if let Some(f) = sink.file.take() {
        f.finish()?;
    }
    let c = &report.counts;
    println!(
        "navsync live: {:.1} s, imu {} lines ({} bad, {} lost), {} solutions, gnss {} fixes, pps {} edges; latency median {} µs, p99 {} µs, max {} µs; CPU {:.2} % of one core",
        report.duration_s,
        c.imu_lines,
        c.imu_bad_lines,
        c.imu_lost,
        c.solutions,
        c.gnss_fixes,
        c.pps_edges,
        us(report.latency.median_us),
        us(report.latency.p99_us),
        us(report.latency.max_us),
        report.cpu_percent
    );
    if c.gnss_headings > 0 {
        println!(
            "  dual-antenna headings: {} received, {} fused, {} rejected by the gate, {} too old",
            c.gnss_headings, c.headings_fused, c.headings_rejected, c.headings_stale
        );
    }
    print_recorded(&report.recorded, &args);
    if let Some(dir) = &args.output {
        let p = dir.join("live_report.json");
        navsync::io::output::write_file(&p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!(
            "  wrote {}/navresult.nav, imu_err.txt, std.txt, live_report.json",
            dir.display()
        );
    }
    Ok(())
}

#[cfg(target_os = "linux")]
fn print_recorded(r: &Option<navsync_live::record::RecordCounts>, args: &Args) {
    let Some(r) = r else { return };
    if let Some(p) = &args.record {
        println!(
            "  recorded {} imu, {} gnss, {} pps records to {} ({} bytes{})",
            r.imu,
            r.gnss,
            r.pps,
            p.display(),
            r.rig_bytes,
            if r.late > 0 {
                format!("; {} came late, after later records", r.late)
            } else {
                String::new()
            }
        );
    }
    if let Some(p) = &args.record_gnss {
        println!(
            "  recorded {} receiver bytes to {}",
            r.raw_gnss_bytes,
            p.display()
        );
    }
}

#[cfg(target_os = "linux")]
fn us(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.0}")).unwrap_or_else(|| "-".into())
}

#[cfg(target_os = "linux")]
fn run_selftest(args: &Args) -> Result<()> {
    anyhow::ensure!(
        args.minutes > 0.0 && args.minutes <= 24.0 * 60.0,
        "--minutes must be in (0, 1440]"
    );
    let dur = args.minutes * 60.0;
    let mut cfg = SelftestConfig::new(dur, args.pps_gap_start, args.pps_gap);
    cfg.replay.gnss = match args.selftest_gnss {
        Gnss::Ubx => navsync_live::replay::GnssKind::Ubx,
        Gnss::Nmea => navsync_live::replay::GnssKind::Nmea,
    };
    cfg.replay.imu_esf = args.selftest_esf;
    cfg.verbose = true;
    anyhow::ensure!(
        args.imu_lookahead.is_finite() && args.imu_lookahead >= 0.0,
        "--imu-lookahead {} must be a non-negative number of seconds",
        args.imu_lookahead
    );
    cfg.imu_lookahead_s = args.imu_lookahead;
    cfg.record = args.record.clone();
    cfg.record_gnss = args.record_gnss.clone();
    cfg.output = args.output.clone();
    if let Some(d) = &args.output {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let dir = std::env::temp_dir().join(format!("navsync-live-selftest-{}", std::process::id()));
    println!(
        "navsync live --selftest: {:.1} min on PTYs in {} (200 Hz IMU, 10 Hz GNSS, PPS removed at {} s for {} s)",
        args.minutes,
        dir.display(),
        args.pps_gap_start,
        args.pps_gap
    );
    let r = selftest::run(&cfg, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    let r = r?;
    println!(
        "samples: written {}, received {}, stamped {}, lost {}; solutions {}",
        r.imu_written, r.imu_received, r.imu_stamped, r.samples_lost, r.solutions
    );
    println!(
        "latency arrival → solution: median {} µs, p99 {} µs, max {} µs",
        us(r.latency_median_us),
        us(r.latency_p99_us),
        us(r.latency_max_us)
    );
    println!(
        "CPU: {:.2} % of one core ({:.2} s live threads over {:.1} s; replay writer {:.2} s excluded)",
        r.cpu_percent, r.cpu_s, r.duration_s, r.replay_cpu_s
    );
    println!(
        "PPS: {} edges injected, gap {:?}; holdover entered at {:?} s, locked at {:?} s",
        r.pps_injected, r.pps_gap, r.holdover_at_s, r.relocked_at_s
    );
    if let Some(s) = &r.live.sync {
        for (h, span) in s.holdover.iter().zip(&r.holdover_spans_s) {
            println!(
                "  holdover stamps from {:.2} s to {:.2} s of GPS time ({:.1} s, {} samples), stamp bound up to {:.1} µs",
                span.0, span.1, h.duration_s, h.samples, h.max_bound_us
            );
        }
        if let Some(p) = &s.pps {
            println!(
                "  pulses: {} received, {} accepted; innovation RMS {:.2} µs; counter {:.3} ppm",
                p.counts.received,
                p.counts.accepted,
                p.innovation_rms_us.unwrap_or(f64::NAN),
                s.counter
                    .freq_error_ppm
                    .as_ref()
                    .map(|f| f.mean)
                    .unwrap_or(f64::NAN)
            );
        }
    }
    let e = &r.stamp_errors;
    println!(
        "stamps vs truth: {} compared, RMS {:.1} µs, max {:.1} µs; in holdover {} compared, max {:.1} µs",
        e.compared, e.rms_us, e.max_abs_us, e.holdover_compared, e.holdover_max_abs_us
    );
    println!(
        "gnss: {} epochs written, {} fixes received, {} fused; position within {:.2} m; replay writer late by up to {:.2} ms",
        r.gnss_epochs_written,
        r.gnss_fixes_received,
        r.gnss_fixes_fused,
        r.max_pos_error_m,
        r.replay_max_late_ms
    );
    print_recorded(&r.live.recorded, args);
    if let Some(p) = &args.json {
        navsync::io::output::write_file(p, serde_json::to_string_pretty(&r)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("wrote {}", p.display());
    }
    Ok(())
}
