//! `navsync convert`: receiver and logger files → KF-GINS files and
//! rig-logs (the work is in `navsync_receivers::convert`).

use std::path::PathBuf;

use anyhow::Result;
use navsync_receivers::convert::{self, ConvertOptions, GnssSource, InputFormat};
use navsync_receivers::ros2::TopicChoice;

use super::{parse_triplet, print_diagnostics};

#[derive(Copy, Clone, Debug, clap::ValueEnum)]
pub enum From {
    /// u-blox stream: UBX (NAV-PVT, or NAV-SOL/POSLLH/HPPOSLLH/VELNED/STATUS
    /// epochs; NAV-RELPOSNED headings; NAV-TIMEGPS, TIM-TP, TIM-TM2,
    /// ESF-MEAS, ESF-RAW), possibly mixed with NMEA and RTCM3 (skipped);
    /// gpsd `#` header lines skipped.
    Ubx,
    /// NMEA 0183 stream (GGA, RMC, GST, ZDA; HDT headings), possibly mixed
    /// with UBX.
    Nmea,
    /// Rate-form IMU CSV: time s, gyro x y z rad/s, accel x y z m/s².
    RateCsv,
    /// comma2k19 gnss_ublox.csv (boot time, lat, lon, speed, UTC ms, alt, bearing).
    CommaGnss,
    /// ROS 2 bag as .mcap (uncompressed, zstd or lz4 chunks): sensor_msgs/Imu,
    /// sensor_msgs/NavSatFix, geometry_msgs/TwistWithCovarianceStamped (CDR).
    Mcap,
}

#[derive(Copy, Clone, Debug, clap::ValueEnum)]
pub enum Source {
    Auto,
    Ubx,
    Nmea,
}

#[derive(clap::Args)]
pub struct Args {
    /// Input format.
    #[arg(long, value_enum)]
    pub from: From,
    /// Input file; `-` reads standard input (`gpspipe -R -n 1000 | navsync convert --from ubx - --output DIR`).
    pub file: PathBuf,
    /// Output directory (created if needed).
    #[arg(long)]
    pub output: PathBuf,
    /// Standard deviations N,E,D (m) for fixes that carry none (NMEA without GST, comma2k19).
    #[arg(long, default_value = "5,5,10", value_parser = parse_triplet)]
    pub default_sd: [f64; 3],
    /// Which fixes to write when a stream has both NAV-PVT and NMEA.
    #[arg(long, value_enum, default_value = "auto")]
    pub gnss_source: Source,
    /// Seconds added to IMU times (a known sensor/boot time → GPS time offset).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub imu_time_offset_s: f64,
    /// Microseconds per ESF-RAW sensor time-tag tick (checked against GPS time in summary.json).
    #[arg(long, default_value_t = 1000.0)]
    pub esf_raw_tick_us: f64,
    /// Microseconds per ESF-MEAS time-tag tick (u-blox IMUs: 1 ms).
    #[arg(long, default_value_t = 1000.0)]
    pub esf_meas_tick_us: f64,
    /// Report IMU intervals at least this long (Tang, Zhang & Niu 2022: no 0.1 s gap).
    #[arg(long, default_value_t = 0.1)]
    pub gap_s: f64,
    /// σ (deg) of NMEA HDT headings (dual-antenna receivers; HDT carries no accuracy): the receiver's datasheet heading accuracy for its baseline.
    #[arg(long, default_value_t = navsync_receivers::convert::DEFAULT_HDT_SD_DEG)]
    pub hdt_sd: f64,
    /// Keep UBX 3D epochs whose gnssFixOK flag is 0 (outside the receiver's DOP/accuracy masks).
    #[arg(long)]
    pub keep_fix_not_ok: bool,
    /// Keep UBX 2D fixes (fix type 2: height held by the receiver), with its vertical accuracy.
    #[arg(long)]
    pub keep_2d: bool,
    /// ROS 2 bag: the sensor_msgs/msg/Imu topic (default: the only one).
    #[arg(long)]
    pub imu_topic: Option<String>,
    /// ROS 2 bag: the sensor_msgs/msg/NavSatFix topic (default: the only one).
    #[arg(long)]
    pub gnss_topic: Option<String>,
    /// ROS 2 bag: the geometry_msgs/msg/TwistWithCovarianceStamped velocity
    /// topic (ENU; default: the only one), matched to fixes by header.stamp.
    #[arg(long)]
    pub velocity_topic: Option<String>,
    /// Succeed even when a receiver stream gives no fix (e.g. a timing log converted for its PPS events).
    #[arg(long)]
    pub allow_no_fix: bool,
}

pub fn run(a: Args) -> Result<()> {
    let format = match a.from {
        From::Ubx => InputFormat::Ubx,
        From::Nmea => InputFormat::Nmea,
        From::RateCsv => InputFormat::RateCsv,
        From::CommaGnss => InputFormat::CommaGnss,
        From::Mcap => InputFormat::Mcap,
    };
    let topics = TopicChoice {
        imu: a.imu_topic.clone(),
        gnss: a.gnss_topic.clone(),
        velocity: a.velocity_topic.clone(),
    };
    let mut opts = ConvertOptions {
        gnss_source: match a.gnss_source {
            Source::Auto => GnssSource::Auto,
            Source::Ubx => GnssSource::Ubx,
            Source::Nmea => GnssSource::Nmea,
        },
        esf_meas_tick_s: a.esf_meas_tick_us * 1e-6,
        esf_raw_tick_s: a.esf_raw_tick_us * 1e-6,
        imu_time_offset_s: a.imu_time_offset_s,
        gap_threshold_s: a.gap_s,
        hdt_sd_deg: a.hdt_sd,
        ..Default::default()
    };
    opts.fix.default_sd_m = a.default_sd;
    opts.fix.keep_fix_not_ok = a.keep_fix_not_ok;
    opts.fix.keep_2d = a.keep_2d;
    if let Some(why) = convert::heading_problem(a.hdt_sd) {
        anyhow::bail!("--hdt-sd: {why}");
    }
    if a.default_sd.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        anyhow::bail!("--default-sd: standard deviations must be positive");
    }
    let _held = super::take_output(&a.output, "convert")?;
    let s = convert::convert_with_topics(format, &a.file, &a.output, &opts, &topics)?;
    if let Some(st) = &s.stream {
        println!(
            "stream: {} bytes after a {}-byte header; {} UBX + {} NMEA messages read, {} other intact frames ({} RTCM3), {} invalid, {} corrupt runs ({} bytes)",
            st.bytes,
            s.header_bytes,
            st.ubx_messages,
            st.nmea_messages,
            st.unknown_frames,
            st.rtcm3_frames,
            st.invalid_frames,
            st.corrupt_runs,
            st.corrupt_bytes
        );
        for (k, n) in &s.frames {
            println!("  {k:<28} {n}");
        }
    }
    if let Some(b) = &s.ros2 {
        println!("ROS 2 bag: {} topics", b.topics.len());
        for t in &b.topics {
            println!(
                "  {:<24} {:<46} {:>8} messages{}{}",
                t.topic,
                t.schema,
                t.messages,
                t.role
                    .as_ref()
                    .map(|r| format!(", {} used as {r}", t.used))
                    .unwrap_or_default(),
                t.log_time_minus_stamp
                    .as_ref()
                    .map(|l| format!(", log_time − stamp median {:+.4} s", l.median_s))
                    .unwrap_or_default()
            );
        }
        if let Some(w) = &b.stopped_early {
            println!("  {w}");
        }
    }
    for t in &s.fix_epochs {
        println!(
            "{}: {} epochs, {} gave a fix, {} dropped",
            t.source,
            t.epochs,
            t.fixes,
            t.epochs - t.fixes
        );
        for d in &t.dropped {
            println!(
                "  {:>7}  {}{}",
                d.epochs,
                d.reason,
                d.kept_by
                    .as_ref()
                    .map(|o| format!("  [kept with {o}]"))
                    .unwrap_or_default()
            );
        }
    }
    if s.ubx_high_precision_positions > 0 {
        println!(
            "  {} positions from NAV-HPPOSLLH",
            s.ubx_high_precision_positions
        );
    }
    if s.gnss_fixes > 0 {
        println!(
            "gnss.txt: {} fixes, {} columns, from {}{}{}",
            s.gnss_fixes,
            s.gnss_columns,
            s.gnss_source,
            s.leap_source
                .map(|l| format!(", leap seconds from {l:?}"))
                .unwrap_or_default(),
            if s.gnss_default_sd > 0 {
                format!(", {} with default std", s.gnss_default_sd)
            } else {
                String::new()
            }
        );
    }
    if let Some(g) = &s.geoid_model {
        println!(
            "  {} heights from MSL + geoid model (GGA without geoid separation): {g}",
            s.geoid_model_heights
        );
    }
    if s.imu_samples > 0 {
        println!(
            "imu.txt: {} increments on {}; {} gaps ≥ {} s",
            s.imu_samples, s.imu_time_axis, s.imu_gaps, a.gap_s
        );
        if let Some(c) = &s.sensor_clock
            && let Some(r) = c.ticks_per_gps_second
        {
            println!(
                "  sensor clock: {r:.1} ticks per GPS second ± {:.0} % over {:.0} s (configured {:.1})",
                100.0 * c.relative_uncertainty,
                c.gps_span_s,
                c.configured_ticks_per_second
            );
        }
    }
    if s.headings > 0 || !s.heading_drops.is_empty() {
        println!("heading.txt: {} receiver headings", s.headings);
        for (why, n) in &s.heading_drops {
            println!("  {n} skipped: {why}");
        }
    }
    if s.pps + s.mark_edges > 0 {
        println!(
            "events.rig: {} PPS ({} without qErr), {} time-mark edges, {} strobes",
            s.pps, s.pps_without_qerr, s.mark_edges, s.strobes
        );
    }
    if !s.diagnostics.is_empty() {
        eprintln!("{} problems reported:", s.diagnostics.total);
        print_diagnostics(&s.diagnostics, 10);
    }
    println!("wrote {}", s.files.join(", "));
    if let Some(m) = s.no_fix_message() {
        if a.allow_no_fix {
            eprintln!("navsync: note: {m}");
        } else {
            anyhow::bail!("{m} (--allow-no-fix accepts a stream without fixes)");
        }
    }
    Ok(())
}
