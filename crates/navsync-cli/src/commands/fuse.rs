//! `navsync fuse`: KF-GINS-compatible batch fusion.

use std::path::PathBuf;

use anyhow::{Context, Result};
use navsync::Diagnostics;
use navsync::fusion::{
    GapPolicy, GnssErrorModel, GnssWeighting, LatencyMode, RobustWeighting, TimeOffsetOptions,
};
use navsync::io::config::KfGinsConfig;
use navsync::io::rtklib::GnssFormat;
use navsync::pipeline::{self, FuseOptions, KfGinsSink, NhcSettings, OutageSchedule};

use super::args;
use super::print_diagnostics;

/// How a dual-antenna baseline sits in the body: `fuse --heading FILE`
/// and `live --heading` (both need `--heading`).
#[derive(clap::Args, Debug, Clone)]
pub struct DualAntennaArgs {
    /// Yaw of the dual-antenna baseline (primary → secondary antenna) in
    /// the body frame, from x towards y (deg; 0: along body x).
    #[arg(
        value_parser = args::symmetric(360.0, "deg"),
        long,
        default_value_t = 0.0,
        requires = "heading",
        allow_hyphen_values = true
    )]
    pub dual_antenna_yaw: f64,
    /// σ of that mounting yaw (deg), added to the receiver's heading σ.
    #[arg(value_parser = args::non_negative(180.0, "deg"), long, default_value_t = 0.5, requires = "heading")]
    pub dual_antenna_yaw_sd: f64,
}

impl DualAntennaArgs {
    /// The filter's heading-update settings, checked as the pipeline
    /// checks a heading file's (finite yaw, σ not negative).
    pub fn fusion_options(&self) -> Result<navsync::fusion::HeadingOptions> {
        let (yaw, sd) = (self.dual_antenna_yaw, self.dual_antenna_yaw_sd);
        anyhow::ensure!(
            yaw.is_finite() && sd.is_finite() && sd >= 0.0,
            "--dual-antenna-yaw {yaw}° must be finite and --dual-antenna-yaw-sd {sd}° not negative"
        );
        Ok(navsync::fusion::HeadingOptions {
            dual_antenna_yaw_rad: yaw.to_radians(),
            dual_antenna_yaw_sd_rad: sd.to_radians(),
            aligned_from_baseline: false,
        })
    }
}

#[derive(clap::Args)]
pub struct Args {
    /// KF-GINS YAML configuration (read unchanged).
    #[arg(long)]
    pub config: PathBuf,
    /// Output folder [default: the config's outputpath].
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Apply the non-holonomic constraint (zero lateral and vertical
    /// velocity in the vehicle frame).
    #[arg(long)]
    pub nhc: bool,
    /// NHC standard deviation (m/s).
    #[arg(value_parser = args::sigma(args::MAX_SPEED_MPS, "m/s"), long, default_value_t = 0.1, requires = "nhc")]
    pub nhc_sd: f64,
    /// Seconds between NHC updates.
    #[arg(value_parser = args::positive(3600.0, "s"), long, default_value_t = 0.2, requires = "nhc")]
    pub nhc_interval: f64,
    /// IMU mounting angles in the vehicle: roll,pitch,yaw (deg; positive yaw turns the IMU's x axis
    /// to the vehicle's right, docs/real-logs.md). The vehicle frame of the NHC and the odometer, and
    /// the yaw between the IMU's heading and the course in the alignment.
    #[arg(long, value_parser = args::Triplet(args::symmetric(360.0, "deg")), default_value = "0,0,0")]
    pub mount: [f64; 3],
    /// Lever arm from the IMU to the NHC point (rear-axle centre), body FRD (m).
    #[arg(long, value_parser = args::Triplet(args::symmetric(1000.0, "m")), default_value = "0,0,0", requires = "nhc")]
    pub nhc_lever: [f64; 3],
    /// Simulated GNSS outages: one every PERIOD seconds…
    #[arg(value_parser = args::real(1.0, args::MAX_SPAN_S, "s"), long, requires_all = ["outage_len", "outage_first"])]
    pub outage_period: Option<f64>,
    /// …lasting LEN seconds…
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long)]
    pub outage_len: Option<f64>,
    /// …the first FIRST seconds after the first IMU epoch.
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long)]
    pub outage_first: Option<f64>,
    /// Post-process forward and backward: Rauch–Tung–Striebel smoothing of
    /// every filter state over the whole run. The smoothed solution goes to
    /// the output folder, the forward one to its `forward/` subfolder.
    #[arg(long)]
    pub smooth: bool,
    /// Longest interval between smoother nodes without corrections (s);
    /// between nodes the smoothed correction is interpolated.
    #[arg(value_parser = args::positive(3600.0, "s"), long, default_value_t = 1.0, requires = "smooth")]
    pub smooth_node_interval: f64,
    /// Find the initial attitude, position and velocity from the data
    /// (static levelling, heading from GNSS course once moving) instead of
    /// the configuration's initpos/initvel/initatt. Done anyway when the
    /// configuration has no initatt.
    #[arg(long)]
    pub align: bool,
    /// Alignment: take the heading from GNSS velocity from this speed on (m/s).
    #[arg(value_parser = args::positive(100.0, "m/s"), long, default_value_t = 3.0)]
    pub align_min_speed: f64,
    /// Receiver headings for the alignment (`sow heading_deg sd_deg
    /// [baseline|vehicle]`, docs/FORMATS.md; `navsync convert` writes
    /// heading.txt from UBX NAV-RELPOSNED and NAV-PVT headVeh): a
    /// dual-antenna heading aligns at a standstill, without motion.
    #[arg(long)]
    pub heading: Option<PathBuf>,
    #[command(flatten)]
    pub dual_antenna: DualAntennaArgs,
    /// Detect standstills (IMU quiet and the solution slower than 0.5 m/s)
    /// and apply zero-velocity and zero-angular-rate updates while stopped:
    /// keeps heading and biases alive at traffic lights.
    #[arg(long)]
    pub zupt: bool,
    /// Standstill: RMS spread of the specific force over 1 s below which the
    /// IMU counts as still (m/s²); raise it for an IMU on a vibrating mount.
    #[arg(value_parser = args::positive(100.0, "m/s²"), long, default_value_t = 0.15)]
    pub zupt_accel_spread: f64,
    /// Column order of 13-column GNSS files.
    #[arg(long, value_enum, default_value_t = Layout::Cpp)]
    pub gnss_layout: Layout,
    /// GNSS file format: kfgins (7/13 columns), rtklib (.pos, llh or xyz,
    /// GPST), or auto = rtklib for a `.pos` file, else kfgins (the choice is printed).
    #[arg(long, value_enum, default_value_t = GnssFileFormat::Auto)]
    pub gnss_format: GnssFileFormat,
    /// RTKLIB: keep solutions with quality flag Q ≤ this (1 fix, 2 float,
    /// 3 SBAS, 4 DGPS, 5 single, 6 PPP); the default keeps all, weighted by
    /// their σ; 2 keeps RTK fix and float only.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u8).range(1..=6))]
    pub rtklib_max_q: u8,
    /// Replace GNSS standard deviations below this (m) instead of skipping the fix.
    #[arg(value_parser = args::positive(1000.0, "m"), long)]
    pub gnss_sd_floor: Option<f64>,
    /// Ignore GNSS velocities in 13-column files (KF-GINS ignores them).
    #[arg(long)]
    pub no_gnss_velocity: bool,
    /// How GNSS fixes that disagree with the INS are weighted: robust
    /// (fixes that disagree with the INS beyond its demonstrated spread are
    /// down-weighted per axis, IGG-III, and gross faults rejected; real
    /// fixes need it), gate (a chi-square gate, the first version's rule)
    /// or off (every fix at its stated σ, as KF-GINS).
    #[arg(long, value_enum, default_value_t = Weighting::Robust)]
    pub gnss_weighting: Weighting,
    /// Gate probability of --gnss-weighting gate (implies it).
    #[arg(value_parser = args::real(0.5, 0.999_999, ""), long, conflicts_with = "no_gate")]
    pub gate_prob: Option<f64>,
    /// Every fix at its stated σ: same as --gnss-weighting off.
    #[arg(long)]
    pub no_gate: bool,
    /// The receiver's time-correlated position error as 3 Gauss–Markov
    /// filter states: its σ per NED axis (m), e.g. 0.01,0.01,0.015 for RTK
    /// (with --gnss-gm-time). The stated σ is then taken as the total.
    #[arg(long, value_name = "N,E,D", requires = "gnss_gm_time",
          value_parser = args::Triplet(args::sigma(args::MAX_LENGTH_M, "m")))]
    pub gnss_gm_sd: Option<[f64; 3]>,
    /// Correlation time of that error (s), e.g. 60 for RTK, 300 for SPP.
    #[arg(value_parser = args::real(1e-3, 1e6, "s"), long, value_name = "S", requires = "gnss_gm_sd")]
    pub gnss_gm_time: Option<f64>,
    /// Robust weighting: standardised innovation below which a fix keeps
    /// its σ…
    #[arg(value_parser = args::positive(100.0, ""), long, default_value_t = RobustWeighting::default().k0)]
    pub robust_k0: f64,
    /// …and beyond which an axis is rejected.
    #[arg(value_parser = args::positive(100.0, ""), long, default_value_t = RobustWeighting::default().k1)]
    pub robust_k1: f64,
    /// Robust weighting: correlation time (s) over which a down-weighting
    /// is remembered (0: every fix on its own).
    #[arg(value_parser = args::non_negative(args::MAX_SPAN_S, "s"), long, default_value_t = RobustWeighting::default().memory_s)]
    pub robust_memory: f64,
    /// Robust weighting: scale up R for fixes that jump from the previous
    /// fix by more than their σ allow (measured against the INS). Off by
    /// default: on a real drive it cost MEMS IMUs up to 15 % and gained a
    /// navigation-grade one 5–10 % (docs/real-gnss.md).
    #[arg(long, action = clap::ArgAction::Set, default_value_t = RobustWeighting::default().noise_scale)]
    pub robust_noise_scale: bool,
    /// Covariance propagation step (s); 0 = every IMU sample.
    #[arg(value_parser = args::non_negative(3600.0, "s"), long, default_value_t = 0.1)]
    pub cov_step: f64,
    /// How to treat the sample after an IMU data gap.
    #[arg(long, value_enum, default_value_t = Gap::Auto)]
    pub gap_policy: Gap,
    /// Interval of imu_err.txt and std.txt lines (s); 0 = every IMU epoch.
    #[arg(value_parser = args::non_negative(3600.0, "s"), long, default_value_t = 0.1)]
    pub aux_interval: f64,
    /// GPS week written into navresult.nav (KF-GINS writes 0).
    #[arg(value_parser = args::int(0, 9999), long, default_value_t = 0)]
    pub week: i64,
    /// Estimate the IMU–GNSS time offset (GNSS time tag − true time of
    /// validity) as a filter state; written to time_offset.txt and summary.json.
    #[arg(long)]
    pub estimate_time_offset: bool,
    /// Initial time-offset estimate (s).
    #[arg(value_parser = args::symmetric(args::MAX_OFFSET_SEARCH_S, "s"), long, default_value_t = 0.0, requires = "estimate_time_offset")]
    pub time_offset_init: f64,
    /// Initial time-offset σ (s).
    #[arg(value_parser = args::sigma(args::MAX_OFFSET_SEARCH_S, "s"), long, default_value_t = 0.2, requires = "estimate_time_offset")]
    pub time_offset_sd: f64,
    /// Coarse search range ±S (s) before the filter refines; 0 disables it.
    #[arg(value_parser = args::non_negative(args::MAX_OFFSET_SEARCH_S, "s"), long, default_value_t = 0.5, requires = "estimate_time_offset")]
    pub time_offset_search: f64,
    /// Let the time offset move even while the motion makes it unobservable.
    #[arg(long, requires = "estimate_time_offset")]
    pub no_time_offset_hold: bool,
    /// Time base of the written solution: the IMU's stamps (default), or
    /// GNSS time (IMU stamps + estimated offset) when the GNSS clock is the
    /// trusted one.
    #[arg(long, value_enum, default_value_t = TimeBase::Imu, requires = "estimate_time_offset")]
    pub time_base: TimeBase,
    /// Real-time latency handling: fixes reach the filter --gnss-latency
    /// seconds after their time tag, and are used by this method.
    #[arg(long, value_enum, default_value_t = Latency::Offline)]
    pub latency_mode: Latency,
    /// Emulated GNSS latency for the real-time modes (s).
    #[arg(value_parser = args::non_negative(args::MAX_OFFSET_S, "s"), long, default_value_t = 0.0)]
    pub gnss_latency: f64,
    /// Fusion lag of `--latency-mode fixed` (s) [default: --gnss-latency].
    #[arg(value_parser = args::non_negative(args::MAX_OFFSET_S, "s"), long)]
    pub fixed_lag: Option<f64>,
    /// Also write the solution at these epochs (one `sow` or `week sow` per
    /// line) to navresult_at.nav, by (2n+1)-order Lagrange interpolation.
    #[arg(long)]
    pub output_at: Option<PathBuf>,
    /// n of the (2n+1)-order interpolation (0 linear, 1 cubic, …).
    #[arg(value_parser = args::count(0, navsync::interp::MAX_INTERP_N as u64), long, default_value_t = 1)]
    pub interp_n: usize,
    /// Inertial sensors present: full, 1g2a (vertical gyro, forward and
    /// lateral accelerometers) or 1g3a; absent ones become pseudo-signals.
    #[arg(long, default_value = "full")]
    pub imu_config: navsync::reduced::ImuConfig,
    /// Roll/pitch rates a pseudo gyro must cover (deg/s, 1σ) and their
    /// correlation time (s).
    #[arg(value_parser = args::sigma(1000.0, "deg/s"), long, default_value_t = 0.5)]
    pub pseudo_rate_sd: f64,
    #[arg(value_parser = args::real(1e-3, 1e6, "s"), long, default_value_t = 1.0)]
    pub pseudo_rate_corr: f64,
    /// Vertical acceleration a pseudo accelerometer must cover (m/s², 1σ)
    /// and its correlation time (s).
    #[arg(value_parser = args::sigma(1000.0, "m/s²"), long, default_value_t = 0.2)]
    pub pseudo_accel_sd: f64,
    #[arg(value_parser = args::real(1e-3, 1e6, "s"), long, default_value_t = 0.5)]
    pub pseudo_accel_corr: f64,
    /// Odometer/CAN speed file: `sow speed_mps` per line (GPS seconds of
    /// week, m/s; any separators; `#` comments).
    #[arg(long)]
    pub odometer: Option<PathBuf>,
    /// Odometer speed standard deviation (m/s).
    #[arg(value_parser = args::sigma(args::MAX_SPEED_MPS, "m/s"), long, default_value_t = 0.1, requires = "odometer")]
    pub odo_sd: f64,
    /// Seconds between odometer updates.
    #[arg(value_parser = args::positive(3600.0, "s"), long, default_value_t = 0.1, requires = "odometer")]
    pub odo_interval: f64,
    /// Initial σ of the odometer scale factor (0: no scale-factor state).
    #[arg(value_parser = args::non_negative(1.0, ""), long, default_value_t = 0.01, requires = "odometer")]
    pub odo_scale_sd: f64,
    /// Lever arm from the IMU to the odometer point, body FRD (m)
    /// [default: the NHC lever arm].
    #[arg(long, value_parser = args::Triplet(args::symmetric(1000.0, "m")), requires = "odometer")]
    pub odo_lever: Option<[f64; 3]>,
    /// Estimate the gyro and accelerometer axis misalignments (12 more
    /// states) with this initial σ (deg), or GYRO,ACCEL: e.g. 0.05 for an
    /// ADIS16465's datasheet figure. Off by default (KF-GINS's 21 states).
    #[arg(long, value_parser = parse_sd_pair, value_name = "SD_DEG[,SD_DEG]")]
    pub misalignment: Option<[f64; 2]>,
    /// The accelerometer axis misalignment from the datasheet (σ, deg; a
    /// cross-axis sensitivity of 1 % is 0.57°), when the run levels itself
    /// (no initatt, or --align): levelling takes the misaligned axes for
    /// level, so the tilt's σ includes it. Not estimated (see
    /// --misalignment). E.g. 0.3 for an ICM-20602, 0.05 for an ADIS16465.
    #[arg(value_parser = args::non_negative(10.0, "deg"), long, value_name = "SD_DEG")]
    pub accel_misalignment: Option<f64>,
    /// Estimate the GNSS antenna lever arm (3 more states, random
    /// constants in the body frame, from `antlever` with σ --lever-arm-sd):
    /// observable through heading changes; summary.json says how well.
    #[arg(long)]
    pub estimate_lever_arm: bool,
    /// Initial σ of the lever-arm states (m).
    #[arg(value_parser = args::positive(navsync::pipeline::MAX_LEVER_ARM_SD_M, "m"), long, default_value_t = 0.5, requires = "estimate_lever_arm", value_name = "SD_M")]
    pub lever_arm_sd: f64,
}

/// "a" or "a,b" (degrees, in [1e-9, 10]: an axis misalignment of a MEMS
/// IMU is at most about a degree) into [a, a] or [a, b].
fn parse_sd_pair(s: &str) -> Result<[f64; 2], String> {
    let range = args::sigma(10.0, "deg");
    let v = s
        .split(',')
        .map(|x| {
            range
                .check(x)
                .map_err(|why| format!("'{}' is {why}", x.trim()))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    match v.as_slice() {
        [a] => Ok([*a, *a]),
        [a, b] => Ok([*a, *b]),
        _ => Err(format!("'{s}': expected SD or GYRO_SD,ACCEL_SD")),
    }
}

#[derive(Copy, Clone, PartialEq, clap::ValueEnum)]
pub enum TimeBase {
    Imu,
    Gnss,
}

#[derive(Copy, Clone, PartialEq, clap::ValueEnum)]
pub enum Latency {
    /// Post-processing: each fix is used at its time of validity.
    Offline,
    /// Used on arrival as if valid then (no compensation).
    Naive,
    /// (a) Filter runs a fixed lag behind real time; output predicted forward.
    Fixed,
    /// (b) Fix moved forward by the INS change over the latency (the patent "A
    /// time synchronization method for a GPS/SINS integrated navigation
    /// system").
    Extrapolate,
    /// (c) Delayed-state update: update in the past, propagate forward again.
    Delayed,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Weighting {
    /// IGG-III down-weighting per axis, judged against the INS's
    /// demonstrated spread (and, with --robust-noise-scale true, the
    /// fixes' jumps from their neighbours).
    Robust,
    /// Chi-square gate (probability 0.9999 unless --gate-prob).
    Gate,
    /// Every fix at its stated σ (KF-GINS).
    Off,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Layout {
    /// sow lat lon h vn ve vd sd_n sd_e sd_d sd_vn sd_ve sd_vd (KF-GINS C++)
    Cpp,
    /// sow lat lon h sd_n sd_e sd_d vn ve vd sd_vn sd_ve sd_vd (KF-GINS-Matlab)
    Matlab,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum GnssFileFormat {
    Auto,
    Kfgins,
    Rtklib,
}

#[derive(Copy, Clone, clap::ValueEnum)]
pub enum Gap {
    Auto,
    HoldRate,
    AsIs,
}

impl Args {
    pub fn options(&self) -> Result<FuseOptions> {
        let outages = match (self.outage_period, self.outage_len, self.outage_first) {
            // Values checked by FuseOptions::validate.
            (Some(period_s), Some(len_s), Some(first_s)) => Some(OutageSchedule {
                period_s,
                len_s,
                first_s,
            }),
            (None, None, None) => None,
            _ => anyhow::bail!("--outage-period, --outage-len and --outage-first go together"),
        };
        let gnss_error = match (self.gnss_gm_sd, self.gnss_gm_time) {
            (Some(sd), Some(tau)) => {
                let m = GnssErrorModel {
                    gm_sd_m: sd,
                    corr_time_s: tau,
                };
                Some(m)
            }
            _ => None,
        };
        let gnss_weighting = if self.no_gate {
            GnssWeighting::Off
        } else if let Some(prob) = self.gate_prob {
            GnssWeighting::Gate { prob }
        } else {
            match self.gnss_weighting {
                Weighting::Off => GnssWeighting::Off,
                Weighting::Gate => GnssWeighting::Gate { prob: 0.9999 },
                Weighting::Robust => {
                    let rw = RobustWeighting {
                        k0: self.robust_k0,
                        k1: self.robust_k1,
                        memory_s: self.robust_memory,
                        noise_scale: self.robust_noise_scale,
                        ..RobustWeighting::default()
                    };
                    GnssWeighting::Robust(rw)
                }
            }
        };
        // Values are checked by FuseOptions::validate (the library's one
        // check, for library callers too).
        Ok(FuseOptions {
            output_dir: self.output.clone(),
            outages,
            nhc: self.nhc.then_some(NhcSettings {
                lever_m: self.nhc_lever,
                sd_mps: self.nhc_sd,
                interval_s: self.nhc_interval,
            }),
            mount_deg: self.mount,
            gnss_layout_matlab: matches!(self.gnss_layout, Layout::Matlab),
            gnss_format: match self.gnss_format {
                GnssFileFormat::Rtklib => GnssFormat::Rtklib,
                // Auto is resolved in `run`, where the GNSS path is known.
                GnssFileFormat::Kfgins | GnssFileFormat::Auto => GnssFormat::Kfgins,
            },
            rtklib_max_q: self.rtklib_max_q,
            gnss_sd_floor: self.gnss_sd_floor,
            cov_step_s: self.cov_step,
            gnss_weighting,
            gap_policy: match self.gap_policy {
                Gap::Auto => GapPolicy::Auto,
                Gap::HoldRate => GapPolicy::HoldRate,
                Gap::AsIs => GapPolicy::AsIs,
            },
            gap_factor: 2.5,
            aux_interval_s: self.aux_interval,
            use_gnss_velocity: !self.no_gnss_velocity,
            week: self.week,
            dry_run: false,
            time_offset: self.estimate_time_offset.then_some(TimeOffsetOptions {
                init_s: self.time_offset_init,
                sd_s: self.time_offset_sd,
                random_walk_psd: 1e-12,
                hold_when_unobservable: !self.no_time_offset_hold,
                search_range_s: self.time_offset_search,
            }),
            latency: match self.latency_mode {
                Latency::Offline => LatencyMode::Offline,
                Latency::Naive => LatencyMode::Naive,
                Latency::Fixed => LatencyMode::FixedLag {
                    lag_s: self.fixed_lag.unwrap_or(self.gnss_latency),
                },
                Latency::Extrapolate => LatencyMode::Extrapolate,
                Latency::Delayed => LatencyMode::DelayedState {
                    max_latency_s: (2.0 * self.gnss_latency).max(1.0),
                },
            },
            gnss_latency_s: self.gnss_latency,
            output_at: self.output_at.clone(),
            output_at_n: self.interp_n,
            output_gnss_time: self.time_base == TimeBase::Gnss,
            reduced_imu: (self.imu_config != navsync::reduced::ImuConfig::Full).then(|| {
                navsync::reduced::ReducedImu {
                    config: self.imu_config,
                    noise: navsync::reduced::PseudoSignalNoise {
                        rate_sd: self.pseudo_rate_sd.to_radians(),
                        rate_corr_s: self.pseudo_rate_corr,
                        vertical_accel_sd: self.pseudo_accel_sd,
                        vertical_accel_corr_s: self.pseudo_accel_corr,
                    },
                }
            }),
            odometer: self
                .odometer
                .clone()
                .map(|path| navsync::reduced::OdometerSettings {
                    sd_mps: self.odo_sd,
                    interval_s: self.odo_interval,
                    scale_sd: (self.odo_scale_sd > 0.0).then_some(self.odo_scale_sd),
                    lever_m: self.odo_lever,
                    ..navsync::reduced::OdometerSettings::new(path)
                }),
            misalignment_sd_deg: self.misalignment,
            lever_arm_sd_m: self.estimate_lever_arm.then_some(self.lever_arm_sd),
            accel_misalignment_sd_deg: self.accel_misalignment,
            gnss_error,
            align: self.align.then_some(navsync::align::AlignOptions {
                min_speed_mps: self.align_min_speed,
                ..Default::default()
            }),
            heading: self.heading.clone().map(|path| pipeline::HeadingOptions {
                path,
                dual_antenna_yaw_deg: self.dual_antenna.dual_antenna_yaw,
                dual_antenna_yaw_sd_deg: self.dual_antenna.dual_antenna_yaw_sd,
            }),
            standstill: self
                .zupt
                .then_some(navsync::filter::standstill::StandstillOptions {
                    accel_spread_mps2: self.zupt_accel_spread,
                    ..Default::default()
                }),
            smooth: self.smooth.then_some(pipeline::SmoothOptions {
                node_interval_s: self.smooth_node_interval,
            }),
        })
    }
}

pub fn run(args: Args) -> Result<()> {
    let mut diag = Diagnostics::default();
    let cfg = KfGinsConfig::load(&args.config, &mut diag)?;
    if let Some(w) = navsync::sensor::zero_lever_warning(cfg.antenna_lever_m(), &args.config) {
        eprintln!("navsync fuse: WARNING: {w}");
    }
    let mut opts = args.options()?;
    opts.validate()?;
    let by_extension = cfg
        .gnss_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("pos"));
    if matches!(args.gnss_format, GnssFileFormat::Auto) && by_extension {
        opts.gnss_format = GnssFormat::Rtklib;
    }
    if opts.gnss_format == GnssFormat::Rtklib {
        println!(
            "GNSS file {} read as RTKLIB .pos{}",
            cfg.gnss_path.display(),
            if matches!(args.gnss_format, GnssFileFormat::Auto) {
                " (by its extension; --gnss-format kfgins reads it as KF-GINS text)"
            } else {
                ""
            }
        );
    }
    let out_dir = opts
        .output_dir
        .clone()
        .unwrap_or_else(|| cfg.output_path.clone());
    if !diag.is_empty() {
        eprintln!("configuration notes:");
        print_diagnostics(&diag, 20);
    }
    let _held = super::take_output(&out_dir, "fuse")?;
    execute(&cfg, &opts, &out_dir)?;
    Ok(())
}

/// Runs the fusion of `cfg` into `out_dir` (the smoothed solution there and
/// the forward one in `forward/` with [`FuseOptions::smooth`]), writes
/// summary.json and prints what was done (also `navsync process`'s fuse stage).
pub fn execute(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    out_dir: &std::path::Path,
) -> Result<pipeline::FuseSummary> {
    let pb = crate::progress::bar("fuse");
    let mut sink = KfGinsSink::create(out_dir, opts.week)?;
    let summary = if opts.smooth.is_some() {
        let fwd_dir = out_dir.join("forward");
        let mut forward = KfGinsSink::create(&fwd_dir, opts.week)?;
        let mut fwd_opts = opts.clone();
        fwd_opts.output_dir = Some(out_dir.to_path_buf());
        let summary = pipeline::run_smoothed(cfg, &fwd_opts, &mut forward, &mut sink, &mut |f| {
            crate::progress::set(&pb, f)
        })?;
        forward.finish()?;
        summary
    } else {
        pipeline::run(cfg, opts, &mut sink, &mut |f| crate::progress::set(&pb, f))?
    };
    sink.finish()?;
    pb.finish_and_clear();
    let mut json = serde_json::to_value(&summary)?;
    // The process's peak memory, for users and `navsync bench`.
    if let (Some(m), Some(obj)) = (crate::procstat::peak_rss_mb(), json.as_object_mut()) {
        obj.insert("peak_memory_mb".into(), m.into());
    }
    // The files this run wrote (relative to the folder): an earlier run's
    // others are in `.previous/` (navsync::io::output).
    let mut files = navsync::io::output::written_under(out_dir);
    files.push("summary.json".into());
    if let Some(obj) = json.as_object_mut() {
        obj.insert("files".into(), files.into());
    }
    let json = serde_json::to_string_pretty(&json)?;
    let summary_path = out_dir.join("summary.json");
    navsync::io::output::write_file(&summary_path, json)
        .with_context(|| format!("writing {}", summary_path.display()))?;

    let s = &summary.stats;
    println!(
        "navsync fuse: {:.1} s of data ({} IMU samples) in {:.3} s",
        summary.duration_s, s.imu_samples, summary.run_time_s
    );
    println!(
        "  GNSS fixes: {} used ({} down-weighted), {} rejected, {} withheld (outages), {} velocity updates ({} down-weighted)",
        s.gnss_fixes_used,
        s.gnss_fixes_downweighted,
        s.gnss_fixes_rejected,
        summary.gnss_fixes_withheld_by_outages,
        s.gnss_velocity_used,
        s.gnss_velocity_downweighted
    );
    if let Some(o) = s.gnss_ins_overconfidence {
        println!(
            "  INS σ scale where fixes are judged: {:.2} (from {} fixes after gaps)",
            o.scale, o.fixes
        );
    }
    let refused = s.gnss_fixes_invalid + s.gnss_fixes_duplicate + s.gnss_fixes_stale;
    if refused > 0 {
        println!(
            "  GNSS fixes refused before use: {} invalid, {} with a repeated time, {} stale (see the notes)",
            s.gnss_fixes_invalid, s.gnss_fixes_duplicate, s.gnss_fixes_stale
        );
    }
    if opts.nhc.is_some() {
        println!("  NHC updates: {}", s.nhc_updates);
    }
    if let Some(r) = &opts.reduced_imu {
        println!(
            "  IMU configuration {} (absent sensors replaced by pseudo-signals)",
            r.config
        );
    }
    if opts.odometer.is_some() {
        print!("  odometer updates: {}", s.odometer_updates);
        match summary.final_odometer_scale {
            Some(k) => println!(", estimated scale error {:+.3} %", 100.0 * k),
            None => println!(),
        }
    }
    if opts.heading.is_some() {
        println!(
            "  dual-antenna heading updates: {} ({} rejected by the gate)",
            s.heading_updates, s.heading_rejected
        );
    }
    if s.gaps > 0 {
        println!(
            "  IMU gaps: {} ({:.3} s in all, longest {:.3} s)",
            s.gaps, s.gap_total_s, s.max_gap_s
        );
    }
    if let (Some(o), Some(sd)) = (summary.time_offset_s, summary.time_offset_sd_s) {
        println!(
            "  time offset (GNSS tag − validity): {:.3} ms ± {:.3} ms (coarse search: {})",
            o * 1e3,
            sd * 1e3,
            summary
                .time_offset_coarse_s
                .map(|c| format!("{:.1} ms", c * 1e3))
                .unwrap_or_else(|| "not converged".into())
        );
    }
    if let Some(l) = &summary.lever_arm {
        println!("  {}", l.note);
    }
    if opts.output_at.is_some() {
        println!(
            "  navresult_at.nav: {} epochs ({} outside the data)",
            summary.output_at_written, summary.output_at_skipped
        );
    }
    if !summary.outages.is_empty() {
        println!(
            "  outages (for `navsync eval --outages`): {}",
            summary.outages
        );
    }
    if let Some(a) = &summary.alignment {
        println!("  alignment: {}", a.note);
    }
    if let Some(sm) = &summary.smoother {
        println!(
            "  smoother: {} nodes, forward {:.2} s, backward {:.2} s, output {:.2} s, {:.1} MB of temporary files{}",
            sm.nodes,
            sm.forward_s,
            sm.backward_s,
            sm.output_s,
            sm.temp_bytes as f64 / 1e6,
            if sm.regularised_nodes > 0 {
                format!(" ({} nodes regularised)", sm.regularised_nodes)
            } else {
                String::new()
            }
        );
        if let (Some(o), Some(sd)) = (sm.time_offset_start_s, sm.time_offset_start_sd_s) {
            println!(
                "  smoothed time offset at the start: {:.3} ms ± {:.3} ms",
                o * 1e3,
                sd * 1e3
            );
        }
        println!(
            "  wrote {0}/navresult.nav, imu_err.txt, std.txt (smoothed), {0}/forward/ (forward), summary.json",
            out_dir.display()
        );
    } else {
        println!(
            "  wrote {}/navresult.nav, imu_err.txt, std.txt, summary.json",
            out_dir.display()
        );
    }
    if summary.diagnostics.total > 0 {
        eprintln!("{} reported conditions:", summary.diagnostics.total);
        print_diagnostics(&summary.diagnostics, 10);
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::parse_sd_pair;

    #[test]
    fn misalignment_sigmas_parse_or_say_why_not() {
        assert_eq!(parse_sd_pair("0.05"), Ok([0.05, 0.05]));
        assert_eq!(parse_sd_pair("0.05, 0.1"), Ok([0.05, 0.1]));
        for (bad, why) in [
            ("x", "'x' is not a number"),
            ("0.1,0.2,0.3", "expected SD or GYRO_SD,ACCEL_SD"),
            ("0", "out of range; expected a number in"),
            ("-0.1", "out of range; expected a number in"),
            ("nan", "out of range; expected a number in"),
        ] {
            let e = parse_sd_pair(bad).unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }
}
