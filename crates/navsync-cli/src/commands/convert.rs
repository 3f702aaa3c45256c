//! `navsync convert`: receiver and logger files → KF-GINS files and
//! rig-logs (the work is in `navsync_receivers::convert`).

use std::path::PathBuf;

use anyhow::Result;
use navsync_receivers::convert::{self, ConvertOptions, GnssSource, InputFormat};
use navsync_receivers::rosmsg::{AltitudeDatum, BagSummary, TopicChoice};

use super::args;
use super::print_diagnostics;

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
    /// PX4 ULog (.ulg): sensor_combined, vehicle_gps_position / sensor_gps →
    /// rig.csv on the autopilot's boot clock (then `navsync sync`);
    /// vehicle_attitude + vehicle_global_position → autopilot.nav.
    Ulog,
    /// ROS 1 bag, format 2.0 (.bag; uncompressed, bz2 or lz4 chunks):
    /// sensor_msgs/Imu, sensor_msgs/NavSatFix, nav_msgs/Odometry (→ speed.txt),
    /// geometry_msgs/TwistStamped and TwistWithCovarianceStamped.
    Rosbag,
    /// ArduPilot DataFlash .BIN log (2014 TimeMS or current TimeUS layouts):
    /// rig.csv (IMU on the boot clock, GPS fixes with their arrival boot
    /// time; `navsync sync` puts it on GPS time) and autopilot.nav (the
    /// autopilot's EKF/AHR2 estimate, for comparison).
    Dataflash,
}

/// Which height a ROS NavSatFix altitude is.
#[derive(Copy, Clone, Debug, clap::ValueEnum)]
pub enum RosAltitude {
    /// Above the WGS 84 ellipsoid, as sensor_msgs/NavSatFix defines it.
    Ellipsoid,
    /// Above mean sea level (what many drivers write): EGM96 geoid added.
    Msl,
}

impl std::convert::From<RosAltitude> for AltitudeDatum {
    fn from(a: RosAltitude) -> Self {
        match a {
            RosAltitude::Ellipsoid => AltitudeDatum::Ellipsoid,
            RosAltitude::Msl => AltitudeDatum::Msl,
        }
    }
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
    #[arg(long, default_value = "5,5,10", value_parser = args::Triplet(args::sigma(args::MAX_LENGTH_M, "m")))]
    pub default_sd: [f64; 3],
    /// Which fixes to write when a stream has both NAV-PVT and NMEA.
    #[arg(long, value_enum, default_value = "auto")]
    pub gnss_source: Source,
    /// Seconds added to IMU times (a known sensor/boot time → GPS time offset).
    #[arg(value_parser = args::symmetric(args::MAX_SPAN_S, "s"), long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub imu_time_offset_s: f64,
    /// Microseconds per ESF-RAW sensor time-tag tick (checked against GPS time in summary.json).
    #[arg(value_parser = args::real(1e-3, 1e6, "µs"), long, default_value_t = 1000.0)]
    pub esf_raw_tick_us: f64,
    /// Microseconds per ESF-MEAS time-tag tick (u-blox IMUs: 1 ms).
    #[arg(value_parser = args::real(1e-3, 1e6, "µs"), long, default_value_t = 1000.0)]
    pub esf_meas_tick_us: f64,
    /// Report IMU intervals at least this long (Tang, Zhang & Niu 2022: no 0.1 s gap).
    #[arg(value_parser = args::positive(3600.0, "s"), long, default_value_t = 0.1)]
    pub gap_s: f64,
    /// σ (deg) of NMEA HDT headings (dual-antenna receivers; HDT carries no accuracy): the receiver's datasheet heading accuracy for its baseline.
    #[arg(value_parser = args::positive(30.0, "deg"), long, default_value_t = navsync_receivers::convert::DEFAULT_HDT_SD_DEG)]
    pub hdt_sd: f64,
    /// Keep UBX 3D epochs whose gnssFixOK flag is 0 (outside the receiver's DOP/accuracy masks).
    #[arg(long)]
    pub keep_fix_not_ok: bool,
    /// Keep UBX 2D fixes (fix type 2: height held by the receiver), with its vertical accuracy.
    #[arg(long)]
    pub keep_2d: bool,
    /// Keep dead-reckoning-only epochs (fix type 1) of a u-blox sensor-fusion receiver's NAV-PVAT.
    #[arg(long)]
    pub keep_dr_only: bool,
    /// ROS bag: the sensor_msgs/Imu topic (default: the only one; ROS 1:
    /// the one with most messages).
    #[arg(long)]
    pub imu_topic: Option<String>,
    /// ROS bag: the sensor_msgs/NavSatFix topic (default: the only one).
    #[arg(long)]
    pub gnss_topic: Option<String>,
    /// ROS bag: the geometry_msgs/TwistWithCovarianceStamped velocity topic
    /// (ENU; ROS 1 also a TwistStamped in a world frame; default: the only
    /// one), matched to fixes by header.stamp.
    #[arg(long)]
    pub velocity_topic: Option<String>,
    /// ROS 1 bag: the odometer topic, nav_msgs/Odometry (twist.twist.linear.x)
    /// or a TwistStamped in the body frame (default: the only one): speed.txt.
    #[arg(long)]
    pub odom_topic: Option<String>,
    /// ROS bag: the datum of NavSatFix altitudes. The message defines
    /// ellipsoidal height; `msl` when the driver writes height above sea
    /// level (EGM96 geoid separation added). Stated in summary.json.
    #[arg(long, value_enum, default_value = "ellipsoid")]
    pub ros_altitude: RosAltitude,
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
        From::Ulog => InputFormat::Ulog,
        From::Rosbag => InputFormat::Ros1Bag,
        From::Dataflash => InputFormat::DataFlash,
    };
    let topics = TopicChoice {
        imu: a.imu_topic.clone(),
        gnss: a.gnss_topic.clone(),
        velocity: a.velocity_topic.clone(),
        odom: a.odom_topic.clone(),
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
        ros_altitude: a.ros_altitude.into(),
        ..Default::default()
    };
    opts.fix.default_sd_m = a.default_sd;
    opts.fix.keep_fix_not_ok = a.keep_fix_not_ok;
    opts.fix.keep_2d = a.keep_2d;
    opts.fix.keep_dr_only = a.keep_dr_only;
    if let Some(why) = convert::heading_problem(a.hdt_sd) {
        anyhow::bail!("--hdt-sd: {why}");
    }
    if a.default_sd.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        anyhow::bail!("--default-sd: standard deviations must be positive");
    }
    let _held = super::take_output(&a.output, "convert")?;
    let s = convert::convert_with_topics(format, &a.file, &a.output, &opts, &topics)?;
    for j in &s.time_jumps {
        eprintln!(
            "navsync: warning: byte {}: GPS time jumps by {:.0} s (from {} to {}): two logs \
             concatenated? Their fixes are mixed in gnss.txt; convert each log on its own",
            j.byte_offset, j.jump_s, j.from, j.to
        );
    }
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
        print_bag("ROS 2", b);
    }
    if let Some(b) = &s.ros1 {
        print_bag("ROS 1", b);
    }
    if let Some(d) = &s.dataflash {
        print_dataflash(d, &s);
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
    if let Some(u) = &s.ulog {
        print_ulog(u);
    } else if s.gnss_fixes > 0 && s.dataflash.is_none() {
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
    if let Some(g) = s.geoid_model.as_ref().filter(|_| s.dataflash.is_none()) {
        println!(
            "  {} heights from MSL + geoid model (GGA without geoid separation): {g}",
            s.geoid_model_heights
        );
    }
    if s.imu_samples > 0 && s.ulog.is_none() && s.dataflash.is_none() {
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
    if s.speeds > 0 {
        println!("speed.txt: {} odometer speeds", s.speeds);
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

/// What a ULog conversion read and wrote.
fn print_ulog(u: &navsync_receivers::ulog::UlogSummary) {
    let sys = ["sys_name", "ver_hw", "ver_sw"]
        .iter()
        .filter_map(|k| u.info.get(*k).map(|v| format!("{k} {v}")))
        .collect::<Vec<_>>()
        .join(", ");
    println!(
        "PX4 ULog v{}: {} topic instances{}{}",
        u.version,
        u.topics.len(),
        if sys.is_empty() {
            String::new()
        } else {
            format!(" ({sys})")
        },
        if u.dropouts > 0 {
            format!(
                "; {} logger dropouts ({} ms lost)",
                u.dropouts, u.dropout_ms
            )
        } else {
            String::new()
        }
    );
    println!(
        "rig.csv: {} sensor_combined samples (instance {}, {:.1} Hz, {}) and {} fixes from {} (instance {}), counter = boot µs",
        u.imu_samples,
        u.imu_instance,
        u.imu_rate_hz,
        u.imu_axes,
        u.fixes,
        u.gps_topic,
        u.gps_instance
    );
    for o in &u.other_instances {
        println!("  {o}");
    }
    println!(
        "autopilot.nav: {} epochs; {}",
        u.autopilot_nav_epochs, u.autopilot_nav
    );
}

/// A ROS bag's topics (used and skipped, with types and counts), its
/// altitude datum and odometer speeds, on the console.
pub fn print_bag(ros: &str, b: &BagSummary) {
    println!("{ros} bag: {} topics", b.topics.len());
    for t in &b.topics {
        println!(
            "  {:<24} {:<46} {:>8} messages{}{}",
            t.topic,
            t.schema,
            t.messages,
            t.role
                .as_ref()
                .map(|r| format!(", {} used as {r}", t.used))
                .unwrap_or_else(|| ", skipped".into()),
            t.log_time_minus_stamp
                .as_ref()
                .map(|l| format!(", log_time − stamp median {:+.4} s", l.median_s))
                .unwrap_or_default()
        );
        if let Some(n) = &t.note {
            println!("      {n}");
        }
    }
    if let Some(w) = &b.stopped_early {
        println!("  {w}");
    }
    if b.topics.iter().any(|t| t.role.as_deref() == Some("gnss")) {
        println!("  altitude: {}", b.altitude_datum);
    }
    if let Some(sp) = &b.speed {
        println!(
            "  speeds: {} from {} on {} ({:.2} … {:.2} m/s, σ {})",
            sp.speeds,
            sp.source,
            sp.topic,
            sp.min_mps,
            sp.max_mps,
            sp.median_sd_mps
                .map(|s| format!("{s:.3} m/s median from its covariance"))
                .unwrap_or_else(
                    || "not given: the sensor sheet's odometer sd_mps or 0.1 m/s".into()
                )
        );
    }
}

/// What a DataFlash conversion read and wrote.
fn print_dataflash(
    d: &navsync_receivers::dataflash::DataFlashSummary,
    s: &convert::ConvertSummary,
) {
    let p = &d.parse;
    println!(
        "DataFlash log: {} message types described, {} messages; time field {}{}",
        p.formats,
        p.messages.values().sum::<u64>(),
        d.time_field,
        if p.garbage_bytes > 0 || !p.unknown_type_messages.is_empty() || p.truncated_at.is_some() {
            format!(
                "; {} bytes outside messages, {} messages of undescribed types, {}",
                p.garbage_bytes,
                p.unknown_type_messages.values().sum::<u64>(),
                if p.truncated_at.is_some() {
                    "last message cut short"
                } else {
                    "complete"
                }
            )
        } else {
            String::new()
        }
    );
    for (k, n) in d.imu_instances.iter().chain(&d.gps_instances) {
        println!("  {k:<20} {n}");
    }
    println!(
        "rig.csv: {} IMU samples (instance {}), {} GNSS fixes (instance {}), {} IMU gaps > 1 s",
        s.imu_samples,
        d.imu_instance_used.map_or("-".into(), |i| i.to_string()),
        s.gnss_fixes,
        d.gps_instance_used.map_or("-".into(), |i| i.to_string()),
        d.imu_gaps.len()
    );
    if s.gnss_fixes > 0 {
        println!("  σ: {}", d.sigma_source);
    }
    if let (Some(ppm), Some(l)) = (d.boot_clock_error_ppm, &d.fix_latency_above_fastest_ms) {
        println!(
            "  boot clock {ppm:+.1} ppm against GPS time; fix arrival above the fastest: median {:.1} ms, max {:.1} ms",
            l.median, l.max
        );
    }
    match &d.estimate_source {
        Some(src) if d.estimate_rows > 0 => {
            println!("autopilot.nav: {} rows from {src}", d.estimate_rows)
        }
        _ => println!(
            "autopilot.nav: not written (no EKF attitude/velocity with AHR2 position, or no fixes to put it on GPS time)"
        ),
    }
}
