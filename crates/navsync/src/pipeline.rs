//! Batch fusion of KF-GINS files: a loop over the streaming engine
//! ([`crate::fusion::Fusion`]) that reads the IMU file on one thread,
//! fuses on the calling thread and writes the 200 Hz navigation file on a
//! third, holding only a few blocks of each file in memory.

#![warn(missing_docs)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Vector3;
use serde::Serialize;

use crate::attitude::Euler;
use crate::error::{Diagnostics, Error};
use crate::filter::gnss::GnssFix;
use crate::filter::nhc::VehicleConstraint;
use crate::fusion::{
    FixRecord, FixStatus, Fusion, FusionConfig, FusionStats, GapPolicy, GnssErrorModel,
    GnssWeighting, LatencyMode, NhcOptions, TimeOffsetOptions, TimeOffsetState,
};
use crate::ins::{ImuErrors, ImuSample, NavState};
use crate::interp::NavInterpolator;
use crate::io::config::KfGinsConfig;
use crate::io::kfgins::{
    GnssLayout, GnssReader, ImuReader, TextWriter, format_imu_err_line, format_nav_line,
    format_std_line,
};
use crate::navigator::{Navigator, SolutionOutput, Step, StreamCounts};
use crate::smoother::Smoothed;
use crate::stage::{Consumer, Drain, Producer, Source, fill_batch};
use crate::time::GpsTime;

mod align_stage;
mod smooth_stage;
use align_stage::align_stage;
use smooth_stage::{ForwardResult, smooth_stage};

/// Largest accelerometer cross-axis misalignment σ accepted (deg): the
/// levelling term is linear in it (a datasheet gives a fraction of a
/// degree), and beyond a few degrees the triad is mis-mounted, not
/// misaligned.
pub(crate) const MAX_ACCEL_MISALIGNMENT_DEG: f64 = 10.0;

/// Largest initial σ of the lever-arm states (m): an antenna is metres
/// from the IMU at most, and the states are linearised (small errors).
pub const MAX_LEVER_ARM_SD_M: f64 = 10.0;

pub use crate::reduced::NhcSettings;
pub use crate::time::OutageSchedule;

/// Options of a batch run beyond the KF-GINS configuration.
#[derive(Clone, Debug, Serialize)]
pub struct FuseOptions {
    /// Output folder (defaults to the config's `outputpath`).
    pub output_dir: Option<PathBuf>,
    /// Simulated GNSS outages (`--outage-period/-len/-first`); `None`: no outage.
    pub outages: Option<OutageSchedule>,
    /// Non-holonomic constraint (`--nhc`); `None`: not applied.
    pub nhc: Option<NhcSettings>,
    /// The IMU's mounting in the vehicle (roll, pitch, yaw; deg;
    /// docs/real-logs.md, Mounting): the vehicle frame of the NHC and the
    /// odometer (C_b^v) and the yaw between the IMU's heading and the
    /// course in the alignment (`--mount`, the sheet's `mount_deg`).
    pub mount_deg: [f64; 3],
    /// 13-column GNSS files in the KF-GINS-Matlab column order (σ before
    /// velocity) instead of the C++ one (`--gnss-layout matlab`).
    pub gnss_layout_matlab: bool,
    /// GNSS file format (KF-GINS text or RTKLIB `.pos`).
    pub gnss_format: crate::io::rtklib::GnssFormat,
    /// RTKLIB: keep solutions with quality flag Q ≤ this (1 fix … 6 PPP).
    pub rtklib_max_q: u8,
    /// Floor for GNSS standard deviations (m, m/s) instead of skipping.
    pub gnss_sd_floor: Option<f64>,
    /// Covariance propagation step (s); 0 propagates at every IMU sample.
    pub cov_step_s: f64,
    /// How fixes that disagree with the INS are weighted (`--gnss-weighting`).
    pub gnss_weighting: GnssWeighting,
    /// How the sample that ends an IMU data gap is treated (`--gap-policy`).
    pub gap_policy: GapPolicy,
    /// A step longer than this many nominal IMU periods is a gap (> 1).
    pub gap_factor: f64,
    /// Interval of the `imu_err.txt` and `std.txt` lines (s); 0 writes them
    /// at every IMU epoch like KF-GINS.
    pub aux_interval_s: f64,
    /// Use GNSS velocities when the file carries them (`--no-gnss-velocity`
    /// clears it).
    pub use_gnss_velocity: bool,
    /// GPS week of the data (KF-GINS files carry none; 0 as KF-GINS writes).
    pub week: i64,
    /// Write no output files (for benchmarks and studies).
    pub dry_run: bool,
    /// Estimate the IMU–GNSS time offset as a filter state.
    pub time_offset: Option<TimeOffsetOptions>,
    /// How fixes are used; with a real-time mode, each fix is delivered to
    /// the engine `gnss_latency_s` after its time tag, as it would arrive.
    pub latency: LatencyMode,
    /// Emulated GNSS latency for the real-time modes (s, ≥ 0; 0 offline).
    pub gnss_latency_s: f64,
    /// Also write the solution interpolated at these epochs (one per line:
    /// `sow` or `week sow`) with (2n+1)-order Lagrange (seed 000 eq 1).
    pub output_at: Option<PathBuf>,
    /// n of the (2n+1)-order interpolation (0 linear, 1 cubic, …).
    pub output_at_n: usize,
    /// With the time-offset state: stamp the solution in GNSS time (IMU
    /// time + τ̂) rather than on the IMU's own time base.
    pub output_gnss_time: bool,
    /// Reduced IMU: absent sensors replaced by pseudo-signals (seed 003).
    pub reduced_imu: Option<crate::reduced::ReducedImu>,
    /// Odometer/CAN speed updates from a speed file.
    pub odometer: Option<crate::reduced::OdometerSettings>,
    /// Estimate the gyro and accelerometer axis misalignments with these
    /// initial σ (deg): 12 more states (see `FusionConfig`).
    pub misalignment_sd_deg: Option<[f64; 2]>,
    /// Estimate the antenna lever arm as three states with this initial σ
    /// (m; `--estimate-lever-arm`, the sheet's `estimate_lever_arm`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lever_arm_sd_m: Option<f64>,
    /// The accelerometer axis misalignment from the datasheet (σ, deg;
    /// cross-axis sensitivity in % × 0.573). When the run levels itself,
    /// the levelled tilt carries it (`FusionConfig::
    /// levelling_accel_misalignment_sd_rad`); with `misalignment_sd_deg`
    /// the states' σ is used instead.
    pub accel_misalignment_sd_deg: Option<f64>,
    /// The receiver's time-correlated position error as filter states.
    pub gnss_error: Option<GnssErrorModel>,
    /// Fixed-interval (RTS) smoothing of the whole run.
    pub smooth: Option<SmoothOptions>,
    /// Find the initial attitude (and position, velocity) from the data
    /// instead of the configuration's `initatt` ([`crate::align`]); always
    /// done when the configuration has no `initatt`.
    pub align: Option<crate::align::AlignOptions>,
    /// Detect standstills and apply zero-velocity and zero-angular-rate
    /// updates while stopped ([`crate::filter::standstill`]).
    pub standstill: Option<crate::filter::standstill::StandstillOptions>,
    /// Receiver headings (a heading file: dual-antenna baseline, receiver
    /// vehicle heading) for the alignment.
    pub heading: Option<HeadingOptions>,
}

/// A heading file and how its dual-antenna baseline sits in the body.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeadingOptions {
    /// `sow heading_deg sd_deg [baseline|vehicle]` ([`crate::io::heading`]).
    pub path: PathBuf,
    /// Yaw of the baseline (primary → secondary antenna) in the body frame,
    /// from x towards y (deg).
    pub dual_antenna_yaw_deg: f64,
    /// σ of that yaw (deg).
    pub dual_antenna_yaw_sd_deg: f64,
}

/// Settings of the forward–backward smoother ([`crate::smoother`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SmoothOptions {
    /// Longest interval between smoother nodes without corrections (s):
    /// the solution between nodes is corrected by interpolation.
    pub node_interval_s: f64,
}

impl Default for SmoothOptions {
    fn default() -> Self {
        SmoothOptions {
            node_interval_s: 1.0,
        }
    }
}

/// What the smoother did (in `summary.json`).
#[derive(Clone, Debug, Serialize)]
pub struct SmootherSummary {
    /// Smoother nodes (see [`SmoothOptions::node_interval_s`]).
    pub nodes: usize,
    /// Nodes whose predicted covariance had to be regularised.
    pub regularised_nodes: usize,
    /// Forward epochs stored (the epochs smoothed).
    pub epochs: usize,
    /// Size of the temporary files (bytes).
    pub temp_bytes: u64,
    /// Wall time of the forward pass (s).
    pub forward_s: f64,
    /// Wall time of the backward pass (s).
    pub backward_s: f64,
    /// Wall time of writing the smoothed output (s).
    pub output_s: f64,
    /// The smoothed time offset at the start and its σ (s), when estimated.
    pub time_offset_start_s: Option<f64>,
    /// σ of that offset (s).
    pub time_offset_start_sd_s: Option<f64>,
}

impl Default for FuseOptions {
    fn default() -> Self {
        FuseOptions {
            output_dir: None,
            outages: None,
            nhc: None,
            mount_deg: [0.0; 3],
            gnss_layout_matlab: false,
            gnss_format: crate::io::rtklib::GnssFormat::Kfgins,
            rtklib_max_q: crate::io::rtklib::RTKLIB_MAX_Q,
            gnss_sd_floor: None,
            cov_step_s: 0.1,
            gnss_weighting: GnssWeighting::default(),
            gap_policy: GapPolicy::Auto,
            gap_factor: 2.5,
            aux_interval_s: 0.1,
            use_gnss_velocity: true,
            week: 0,
            dry_run: false,
            time_offset: None,
            latency: LatencyMode::Offline,
            gnss_latency_s: 0.0,
            output_at: None,
            output_at_n: 1,
            output_gnss_time: false,
            reduced_imu: None,
            odometer: None,
            misalignment_sd_deg: None,
            lever_arm_sd_m: None,
            accel_misalignment_sd_deg: None,
            gnss_error: None,
            smooth: None,
            align: None,
            standstill: None,
            heading: None,
        }
    }
}

impl FuseOptions {
    /// Checks the settings that the engine cannot take as they are.
    pub fn validate(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Invalid(m));
        if let Some(o) = &self.outages {
            o.validate().map_err(Error::Invalid)?;
        }
        if !(self.gnss_latency_s.is_finite() && self.gnss_latency_s >= 0.0) {
            return bad(format!(
                "GNSS latency {} s must be >= 0",
                self.gnss_latency_s
            ));
        }
        if self.gnss_latency_s > 0.0 && self.latency == LatencyMode::Offline {
            return bad(
                "a GNSS latency needs a real-time latency mode (naive, fixed, extrapolate or delayed)"
                    .into(),
            );
        }
        if let Some(t) = &self.time_offset
            && !(t.sd_s.is_finite() && t.sd_s > 0.0 && t.init_s.is_finite())
        {
            return bad(format!(
                "time-offset σ {} s must be positive (initial value {} s finite)",
                t.sd_s, t.init_s
            ));
        }
        if let Some(t) = &self.time_offset
            && !(t.search_range_s.is_finite()
                && (0.0..=TimeOffsetOptions::MAX_SEARCH_RANGE_S).contains(&t.search_range_s))
        {
            return bad(format!(
                "time-offset search range ±{} s: expected 0 (off) to {} s",
                t.search_range_s,
                TimeOffsetOptions::MAX_SEARCH_RANGE_S
            ));
        }
        if let Some(h) = &self.heading
            && !(h.dual_antenna_yaw_deg.is_finite()
                && h.dual_antenna_yaw_sd_deg.is_finite()
                && h.dual_antenna_yaw_sd_deg >= 0.0)
        {
            return bad(format!(
                "dual-antenna yaw {}° must be finite and its σ {}° not negative",
                h.dual_antenna_yaw_deg, h.dual_antenna_yaw_sd_deg
            ));
        }
        if let Some(o) = &self.odometer
            && !(o.sd_mps > 0.0 && o.interval_s >= 0.0 && o.scale_sd.is_none_or(|s| s > 0.0))
        {
            return bad(format!(
                "odometer σ {} m/s must be positive, its interval {} s and scale-factor σ not negative",
                o.sd_mps, o.interval_s
            ));
        }
        if let Some(r) = &self.reduced_imu {
            let n = &r.noise;
            if !(n.rate_sd > 0.0
                && n.rate_corr_s > 0.0
                && n.vertical_accel_sd > 0.0
                && n.vertical_accel_corr_s > 0.0)
            {
                return bad("pseudo-signal noise settings must be positive".into());
            }
        }
        if self.output_at_n > crate::interp::MAX_INTERP_N {
            return bad(format!(
                "interpolation n {} is too large: at most {} (a {}-order polynomial)",
                self.output_at_n,
                crate::interp::MAX_INTERP_N,
                2 * crate::interp::MAX_INTERP_N + 1
            ));
        }
        if !(self.cov_step_s.is_finite() && self.cov_step_s >= 0.0) {
            return bad(format!(
                "covariance step {} s must be >= 0",
                self.cov_step_s
            ));
        }
        if !(self.gap_factor.is_finite() && self.gap_factor > 1.0) {
            return bad(format!("gap factor {} must exceed 1", self.gap_factor));
        }
        if !(self.aux_interval_s.is_finite() && self.aux_interval_s >= 0.0) {
            return bad(format!(
                "auxiliary interval {} s must be >= 0",
                self.aux_interval_s
            ));
        }
        match self.gnss_weighting {
            GnssWeighting::Gate { prob } if !(prob > 0.0 && prob < 1.0) => {
                return bad(format!("gate probability {prob} must be within (0, 1)"));
            }
            GnssWeighting::Robust(rw) => rw.validate().map_err(Error::Invalid)?,
            _ => {}
        }
        if let Some(m) = &self.gnss_error {
            m.validate().map_err(Error::Invalid)?;
        }
        if let Some(sd) = self.lever_arm_sd_m
            && !(sd.is_finite() && sd > 0.0 && sd <= MAX_LEVER_ARM_SD_M)
        {
            return bad(format!(
                "lever-arm σ {sd} m must be within (0, {MAX_LEVER_ARM_SD_M}] m"
            ));
        }
        if let Some(d) = self.accel_misalignment_sd_deg
            && !(d.is_finite() && (0.0..=MAX_ACCEL_MISALIGNMENT_DEG).contains(&d))
        {
            return bad(format!(
                "accelerometer misalignment σ {d}° must be within 0–{MAX_ACCEL_MISALIGNMENT_DEG}°"
            ));
        }
        if let Some(a) = &self.align
            && !(a.min_speed_mps.is_finite()
                && a.min_speed_mps > a.still_speed_mps
                && a.still_speed_mps > 0.0)
        {
            return bad(format!(
                "alignment speed must be above the standstill speed ({} m/s), got {} m/s",
                a.still_speed_mps, a.min_speed_mps
            ));
        }
        if let Some(st) = &self.standstill {
            st.validate().map_err(Error::Invalid)?;
        }
        if let Some(sm) = &self.smooth {
            if self.latency != LatencyMode::Offline {
                return bad(
                    "smoothing is post-processing: it needs the offline latency mode".into(),
                );
            }
            if !(sm.node_interval_s.is_finite() && sm.node_interval_s > 0.0) {
                return bad(format!(
                    "smoother node interval must be positive, got {}",
                    sm.node_interval_s
                ));
            }
        }
        Ok(())
    }
}

/// What a run did (written as `summary.json`).
#[derive(Clone, Debug, Serialize)]
pub struct FuseSummary {
    /// Always `navsync`.
    pub tool: &'static str,
    /// The crate version that wrote the summary.
    pub version: &'static str,
    /// Path of the KF-GINS configuration file.
    pub config: String,
    /// Path of the IMU file.
    pub imu_file: String,
    /// Path of the GNSS file.
    pub gnss_file: String,
    /// Folder the outputs were written to.
    pub output_dir: String,
    /// Seconds of GPS week of the first IMU epoch of the run.
    pub start_sow: f64,
    /// Seconds of GPS week of the last solution.
    pub end_sow: f64,
    /// From the first IMU epoch to the last solution (s).
    pub duration_s: f64,
    pub(crate) imu_records_read: usize,
    pub(crate) imu_lines_skipped: usize,
    pub(crate) gnss_fixes_read: usize,
    pub(crate) gnss_lines_skipped: usize,
    /// Fixes not fused because a simulated outage covered them.
    pub gnss_fixes_withheld_by_outages: usize,
    pub(crate) gnss_fixes_outside_run: usize,
    /// Outage windows as `sow:len` (the `navsync eval --outages` argument).
    pub outages: String,
    /// Final time-offset estimate (GNSS tag − true validity time), when estimated.
    pub time_offset_s: Option<f64>,
    /// σ of that estimate (s).
    pub time_offset_sd_s: Option<f64>,
    /// The coarse search's estimate, when it converged.
    pub time_offset_coarse_s: Option<f64>,
    /// Epochs written by `--output-at`, and requested epochs outside the data.
    pub output_at_written: usize,
    /// Requested epochs outside the data (not written).
    pub output_at_skipped: usize,
    /// The engine's counters.
    pub stats: FusionStats,
    pub(crate) final_gyro_bias_deg_h: [f64; 3],
    pub(crate) final_accel_bias_mgal: [f64; 3],
    pub(crate) final_gyro_scale_ppm: [f64; 3],
    pub(crate) final_accel_scale_ppm: [f64; 3],
    /// Estimated odometer scale factor (when odometer updates ran).
    pub final_odometer_scale: Option<f64>,
    /// Estimated axis misalignments m₀…m₅ of the gyro and accelerometer
    /// triads (deg), when estimated.
    pub final_gyro_misalign_deg: Option<[f64; 6]>,
    /// Same for the accelerometer triad (deg).
    pub final_accel_misalign_deg: Option<[f64; 6]>,
    /// GNSS observations that were not used at their stated σ (all of
    /// them are in `gnss_residuals.txt`).
    pub gnss_weighting: WeightingReport,
    /// The smoother's figures, when it ran.
    pub smoother: Option<SmootherSummary>,
    /// The initial alignment, when the run aligned itself.
    pub alignment: Option<crate::align::Alignment>,
    /// The heading found later in the run from the GNSS track, when the
    /// alignment could not find it (`fusion::course_heading`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_acquired: Option<crate::fusion::course_heading::HeadingAcquired>,
    /// A land vehicle's mounting yaw found in the motion and what the run
    /// did with it (`mount_search`), when the run aligned itself.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_yaw: Option<crate::mount_search::MountYawDecision>,
    /// The configuration's IMU error model (the datasheet figures a report
    /// compares the estimates with).
    pub imu_model: ImuModelSummary,
    /// The configuration's antenna lever arm, IMU to antenna, FRD (m;
    /// KF-GINS `antlever`): the report's verdict warns of a zero one.
    pub antenna_lever_m: [f64; 3],
    /// The lever-arm states' estimate against it, when they ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lever_arm: Option<crate::fusion::LeverArmSummary>,
    /// The options of the run.
    pub options: FuseOptions,
    /// Wall time of the run (s).
    pub run_time_s: f64,
    /// Warnings and skipped lines of the run.
    pub diagnostics: Diagnostics,
}

/// The configured IMU error model in the configuration's units (KF-GINS
/// `imunoise`, `initgyrbias`/`initaccbias`, `initbgstd`/`initbastd`).
#[derive(Clone, Debug, Serialize)]
pub struct ImuModelSummary {
    /// Bias instability: steady-state σ of the Gauss–Markov biases.
    pub gyro_bias_sd_deg_h: [f64; 3],
    /// Accelerometer bias instability (mGal).
    pub accel_bias_sd_mgal: [f64; 3],
    /// Gyro scale-factor σ (ppm).
    pub gyro_scale_sd_ppm: [f64; 3],
    /// Accelerometer scale-factor σ (ppm).
    pub accel_scale_sd_ppm: [f64; 3],
    /// Angular random walk (deg/√h).
    pub arw_deg_sqrt_h: [f64; 3],
    /// Velocity random walk (m/s/√h).
    pub vrw_mps_sqrt_h: [f64; 3],
    /// Gauss–Markov correlation time (s).
    pub corr_time_s: f64,
    /// Initial biases and their σ.
    pub init_gyro_bias_deg_h: [f64; 3],
    /// Initial accelerometer bias (mGal).
    pub init_accel_bias_mgal: [f64; 3],
    /// Initial gyro bias σ (deg/h).
    pub init_gyro_bias_sd_deg_h: [f64; 3],
    /// Initial accelerometer bias σ (mGal).
    pub init_accel_bias_sd_mgal: [f64; 3],
}

impl ImuModelSummary {
    /// The IMU model of a configuration.
    pub fn of(cfg: &KfGinsConfig) -> Self {
        const DEG_H: f64 = std::f64::consts::PI / 180.0 / 3600.0;
        const MGAL: f64 = 1e-5;
        const PPM: f64 = 1e-6;
        let v = |x: &Vector3<f64>, unit: f64| [x.x / unit, x.y / unit, x.z / unit];
        let n = &cfg.noise;
        ImuModelSummary {
            gyro_bias_sd_deg_h: v(&n.gyro_bias_sd, DEG_H),
            accel_bias_sd_mgal: v(&n.accel_bias_sd, MGAL),
            gyro_scale_sd_ppm: v(&n.gyro_scale_sd, PPM),
            accel_scale_sd_ppm: v(&n.accel_scale_sd, PPM),
            arw_deg_sqrt_h: v(&n.arw, std::f64::consts::PI / 180.0 / 60.0),
            vrw_mps_sqrt_h: v(&n.vrw, 1.0 / 60.0),
            corr_time_s: n.corr_time_s,
            init_gyro_bias_deg_h: v(&cfg.init_imu.gyro_bias, DEG_H),
            init_accel_bias_mgal: v(&cfg.init_imu.accel_bias, MGAL),
            init_gyro_bias_sd_deg_h: v(&cfg.init_std.gyro_bias, DEG_H),
            init_accel_bias_sd_mgal: v(&cfg.init_std.accel_bias, MGAL),
        }
    }
}

/// The GNSS observations the filter down-weighted or rejected.
#[derive(Clone, Debug, Default, Serialize)]
pub struct WeightingReport {
    pub(crate) observations: usize,
    pub(crate) down_weighted: Vec<WeightedFix>,
    /// Observations rejected (not fused).
    pub rejected: Vec<WeightedFix>,
}

/// One down-weighted or rejected observation: its NIS at the stated σ and
/// its smallest axis weight.
#[derive(Clone, Debug, Serialize)]
pub struct WeightedFix {
    /// Seconds of GPS week of the observation.
    pub sow: f64,
    /// `position` or `velocity`.
    pub kind: &'static str,
    /// Normalised innovation squared at the stated σ (3 degrees of freedom).
    pub nis: f64,
    pub(crate) min_weight: f64,
}

impl WeightingReport {
    pub(crate) fn from_records(records: &[FixRecord]) -> Self {
        let mut r = WeightingReport {
            observations: records.len(),
            ..WeightingReport::default()
        };
        for f in records {
            let w = WeightedFix {
                sow: f.sow,
                kind: f.kind,
                nis: f.nis,
                min_weight: f.weight.iter().copied().fold(f64::INFINITY, f64::min),
            };
            match f.status {
                FixStatus::Used => {}
                FixStatus::Rejected => r.rejected.push(w),
                FixStatus::DownWeighted | FixStatus::DriftAccepted => r.down_weighted.push(w),
            }
        }
        r
    }
}

/// An IMU found tilted beyond this (deg) at the start, with the NHC on and
/// no mounting roll or pitch given, is taken as mounted so.
pub const MOUNT_TILT_FROM_GRAVITY_DEG: f64 = 20.0;

/// Builds the engine configuration from a KF-GINS configuration.
pub fn fusion_config(cfg: &KfGinsConfig, opts: &FuseOptions) -> FusionConfig {
    let start = GpsTime::from_week_ns(opts.week, crate::time::seconds_to_ns(cfg.start_sow));
    let nav = NavState::new(start, cfg.init_pos, cfg.init_vel, &cfg.init_att);
    let mut fc = FusionConfig::new(nav, cfg.init_std, cfg.noise, cfg.imu_rate_hz);
    fc.init_imu = cfg.init_imu;
    fc.antenna_lever_b = cfg.antenna_lever;
    fc.cov_step_s = opts.cov_step_s;
    fc.gnss_weighting = opts.gnss_weighting;
    fc.gap_policy = opts.gap_policy;
    fc.gap_factor = opts.gap_factor;
    fc.use_gnss_velocity = opts.use_gnss_velocity;
    fc.time_offset = opts.time_offset;
    fc.latency = opts.latency;
    fc.nhc = opts.nhc.map(|s| NhcOptions {
        vehicle: VehicleConstraint::new(
            &Euler::from_deg(opts.mount_deg[0], opts.mount_deg[1], opts.mount_deg[2]),
            Vector3::from(s.lever_m),
            s.sd_mps,
        ),
        interval_s: s.interval_s,
    });
    if let Some(r) = &opts.reduced_imu {
        r.adjust_noise(&mut fc.noise, &mut fc.init_std);
    }
    fc.odometer = opts
        .odometer
        .as_ref()
        .map(|o| crate::reduced::odometer_options(o, opts.nhc.as_ref(), opts.mount_deg));
    fc.misalignment_sd_rad = opts.misalignment_sd_deg.map(|d| d.map(f64::to_radians));
    fc.lever_arm_sd_m = opts.lever_arm_sd_m;
    fc.gnss_error = opts.gnss_error;
    fc.standstill = opts.standstill;
    fc
}

pub use crate::navigator::{NavSink, NullSink};

/// States handed to the navigation writer thread at a time.
const NAV_BATCH: usize = 4096;

/// Writes `navresult.nav` (through a writer thread), `imu_err.txt` and
/// `std.txt` in KF-GINS layouts.
pub struct KfGinsSink {
    week: i64,
    batch: Vec<NavState>,
    writer: Option<Drain<NavLines>>,
    imu_err: TextWriter,
    std: TextWriter,
    offset: Option<TextWriter>,
    nav_at: Option<TextWriter>,
    dir: PathBuf,
    line: Vec<u8>,
}

impl KfGinsSink {
    /// Creates the three files in `dir` (created if missing).
    pub fn create(dir: &Path, week: i64) -> Result<Self, Error> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        // The writer stage converts attitudes to Euler angles, formats and
        // writes: the fusion thread only hands over batches of states.
        let writer = Drain::start(
            NavLines {
                nav: TextWriter::create(&dir.join("navresult.nav"))?,
                week,
                text: Vec::with_capacity(NAV_BATCH * 160),
            },
            "nav-writer",
        )?;
        Ok(KfGinsSink {
            week,
            batch: Vec::with_capacity(NAV_BATCH),
            writer: Some(writer),
            imu_err: TextWriter::create(&dir.join("imu_err.txt"))?,
            std: TextWriter::create(&dir.join("std.txt"))?,
            offset: None,
            nav_at: None,
            dir: dir.to_path_buf(),
            line: Vec::with_capacity(512),
        })
    }

    fn flush_block(&mut self) -> Result<(), Error> {
        if self.batch.is_empty() {
            return Ok(());
        }
        let block = std::mem::replace(&mut self.batch, Vec::with_capacity(NAV_BATCH));
        match self.writer.as_mut().map(|w| w.send(block)) {
            Some(Err(e)) => {
                self.writer = None;
                Err(e)
            }
            _ => Ok(()),
        }
    }

    fn join(&mut self) -> Result<(), Error> {
        match self.writer.take() {
            Some(w) => w.finish(),
            None => Ok(()),
        }
    }

    /// Flushes and closes every file.
    pub fn finish(mut self) -> Result<(), Error> {
        self.flush_block()?;
        self.join()?;
        let KfGinsSink {
            imu_err,
            std,
            offset,
            nav_at,
            ..
        } = self;
        if let Some(w) = offset {
            w.finish()?;
        }
        if let Some(w) = nav_at {
            w.finish()?;
        }
        imu_err.finish()?;
        std.finish()
    }
}

/// `navresult.nav` as a writer stage.
struct NavLines {
    nav: TextWriter,
    week: i64,
    text: Vec<u8>,
}

impl Consumer for NavLines {
    type Item = NavState;
    type Output = ();
    fn consume(&mut self, batch: Vec<NavState>) -> Result<(), Error> {
        self.text.clear();
        for s in &batch {
            format_nav_line(
                &mut self.text,
                self.week,
                s.time,
                &s.pos,
                &s.vel,
                &s.euler().to_deg(),
            );
        }
        self.nav.write(&self.text)
    }
    fn finish(self) -> Result<(), Error> {
        self.nav.finish()
    }
}

impl NavSink for KfGinsSink {
    /// `gnss_residuals.txt`: one line per GNSS observation (docs/FORMATS.md).
    fn fix_records(&mut self, records: &[FixRecord]) -> Result<(), Error> {
        let mut w = TextWriter::create(&self.dir.join("gnss_residuals.txt"))?;
        let mut text = String::from(
            "# navsync GNSS residuals: sow kind innov_n innov_e innov_d sd_n sd_e sd_d nis w_n w_e w_d status reason hpl_m\n# innovation = predicted - measured (m or m/s, NED); w = weight (R divided by it); reason: jump, ramp, run, stale, persisted, outlier, smoother-excluded, smoother-readmitted or -; hpl_m: horizontal protection level K*sigma after the fix, K = 6\n",
        );
        for r in records {
            use std::fmt::Write as _;
            let st = match r.status {
                FixStatus::Used => "used",
                FixStatus::DownWeighted => "down-weighted",
                FixStatus::Rejected => "rejected",
                FixStatus::DriftAccepted => "drift-accepted",
            };
            let _ = writeln!(
                text,
                "{:.3} {} {:.4} {:.4} {:.4} {:.4} {:.4} {:.4} {:.3} {:.4e} {:.4e} {:.4e} {} {} {:.3}",
                r.sow,
                r.kind,
                r.innovation[0],
                r.innovation[1],
                r.innovation[2],
                r.sd[0],
                r.sd[1],
                r.sd[2],
                r.nis,
                r.weight[0],
                r.weight[1],
                r.weight[2],
                st,
                r.reason.word(),
                r.hpl_m
            );
        }
        w.write(text.as_bytes())?;
        w.finish()
    }

    fn nav(&mut self, nav: &NavState, _imu: &ImuErrors) -> Result<(), Error> {
        self.batch.push(*nav);
        if self.batch.len() >= NAV_BATCH {
            self.flush_block()?;
        }
        Ok(())
    }

    fn aux(
        &mut self,
        time: GpsTime,
        imu: &ImuErrors,
        sd: &[f64],
        offset: Option<TimeOffsetState>,
    ) -> Result<(), Error> {
        self.line.clear();
        format_imu_err_line(&mut self.line, time, imu);
        self.imu_err.write(&self.line)?;
        self.line.clear();
        format_std_line(&mut self.line, time, sd);
        self.std.write(&self.line)?;
        if let Some(o) = offset {
            if self.offset.is_none() {
                let mut w = TextWriter::create(&self.dir.join("time_offset.txt"))?;
                w.write(b"# sow offset_s sd_s observable  (offset = GNSS time tag - true time of validity)\n")?;
                self.offset = Some(w);
            }
            self.line.clear();
            time.write_sow(&mut self.line);
            use std::io::Write as _;
            let _ = writeln!(
                self.line,
                " {:.7} {:.7} {}",
                o.offset_s,
                o.sd_s,
                u8::from(o.observable)
            );
            if let Some(w) = self.offset.as_mut() {
                w.write(&self.line)?;
            }
        }
        Ok(())
    }

    fn nav_at(&mut self, nav: &NavState) -> Result<(), Error> {
        if self.nav_at.is_none() {
            self.nav_at = Some(TextWriter::create(&self.dir.join("navresult_at.nav"))?);
        }
        self.line.clear();
        format_nav_line(
            &mut self.line,
            self.week,
            nav.time,
            &nav.pos,
            &nav.vel,
            &nav.euler().to_deg(),
        );
        match self.nav_at.as_mut() {
            Some(w) => w.write(&self.line),
            None => Ok(()),
        }
    }
}

const BATCH: usize = 4096;

/// The IMU file of a run as a reader stage.
struct ImuBatches {
    reader: ImuReader,
    diag: Diagnostics,
}

impl Producer for ImuBatches {
    type Item = ImuSample;
    /// Records read and the notes on skipped lines.
    type Output = (usize, Diagnostics);
    fn next_batch(&mut self) -> Result<Option<Vec<ImuSample>>, Error> {
        fill_batch(BATCH, || self.reader.next_sample(&mut self.diag))
    }
    fn finish(self) -> Result<(usize, Diagnostics), Error> {
        Ok((self.reader.count(), self.diag))
    }
}

/// The GNSS file of a run, in the format the options name.
enum GnssInput {
    Kfgins(Box<GnssReader>),
    Rtklib(Box<crate::io::rtklib::PosReader>),
}

impl GnssInput {
    fn open(path: &Path, opts: &FuseOptions) -> Result<Self, Error> {
        use crate::io::rtklib::{GnssFormat, PosReader};
        Ok(match opts.gnss_format {
            GnssFormat::Kfgins => {
                let layout = if opts.gnss_layout_matlab {
                    GnssLayout::Matlab
                } else {
                    GnssLayout::Cpp
                };
                let mut r = GnssReader::open(path, opts.week, layout)?;
                r.sd_floor = opts.gnss_sd_floor;
                GnssInput::Kfgins(Box::new(r))
            }
            GnssFormat::Rtklib => {
                let mut r = PosReader::open(path, opts.week)?;
                r.sd_floor = opts.gnss_sd_floor;
                r.max_q = opts.rtklib_max_q;
                GnssInput::Rtklib(Box::new(r))
            }
        })
    }

    fn next_fix(&mut self, diag: &mut Diagnostics) -> Result<Option<GnssFix>, Error> {
        match self {
            GnssInput::Kfgins(r) => r.next_fix(diag),
            GnssInput::Rtklib(r) => r.next_fix(diag),
        }
    }
}

/// Runs the fusion of a KF-GINS configuration into `sink`. `progress` is
/// called with the fraction done (0..1) now and then. With
/// [`FuseOptions::smooth`], `sink` receives the smoothed solution (use
/// [`run_smoothed`] to keep the forward one too).
pub fn run(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    sink: &mut dyn NavSink,
    progress: &mut dyn FnMut(f64),
) -> Result<FuseSummary, Error> {
    if opts.smooth.is_some() {
        run_inner(cfg, opts, &mut NullSink, Some(sink), progress)
    } else {
        run_inner(cfg, opts, sink, None, progress)
    }
}

/// As [`run`] with smoothing: the forward solution goes to `forward`, the
/// smoothed one to `smoothed` (same files, same epochs).
pub fn run_smoothed(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    forward: &mut dyn NavSink,
    smoothed: &mut dyn NavSink,
    progress: &mut dyn FnMut(f64),
) -> Result<FuseSummary, Error> {
    let mut o = opts.clone();
    o.smooth.get_or_insert_with(SmoothOptions::default);
    run_inner(cfg, &o, forward, Some(smoothed), progress)
}

fn run_inner(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    sink: &mut dyn NavSink,
    smoothed_sink: Option<&mut dyn NavSink>,
    progress: &mut dyn FnMut(f64),
) -> Result<FuseSummary, Error> {
    opts.validate()?;
    let started = Instant::now();
    let mut diag = Diagnostics::with_cap(1000);
    let mut fc = fusion_config(cfg, opts);
    // Heading-file problems are kept apart from the GNSS file's count.
    let mut heading_diag = Diagnostics::with_cap(1000);
    let (headings, baselines) = heading_inputs(opts, &mut fc, &mut heading_diag)?;
    let (alignment, mount_yaw, align_used) = if opts.align.is_some() || !cfg.init_state_given {
        let (a, m, ao) = align_stage(cfg, opts, &mut fc, &headings, &mut diag)?;
        (Some(a), m, Some(ao))
    } else {
        (None, None, opts.align)
    };
    let fc = fc;
    let start = fc.init_nav.time;
    let end = cfg
        .end_sow
        .map(|e| GpsTime::from_week_ns(opts.week, crate::time::seconds_to_ns(e)));
    let smoothing = match (opts.smooth, smoothed_sink) {
        (Some(sm), Some(s)) => Some((s, sm.node_interval_s)),
        _ => None,
    };
    let smooth_dir = opts
        .output_dir
        .clone()
        .unwrap_or_else(|| cfg.output_path.clone());
    let pass_input = PassInput {
        cfg,
        opts,
        end,
        baselines: &baselines,
        smoother: smoothing.as_ref().map(|s| (smooth_dir.as_path(), s.1)),
    };
    let pass = forward_pass(&pass_input, fc.clone(), sink, &mut diag, progress)?;
    let ForwardPass {
        mut fusion,
        stream,
        imu_count,
        imu_diag,
        fixes_read,
        fixes,
    } = pass;
    let StreamCounts {
        first_epoch,
        last_epoch,
        fixes_withheld: withheld,
        fixes_outside: outside,
        output_at_written: at_written,
        output_at_skipped,
        ..
    } = stream.counts;
    let Some(t0) = first_epoch else {
        return Err(Error::NoData {
            path: cfg.imu_path.clone(),
            msg: format!("no IMU record at or after starttime {}", cfg.start_sow),
        });
    };
    let last_time = last_epoch.unwrap_or(start);
    progress(1.0);

    let gnss_skipped = diag.total;
    let imu_skipped = imu_diag.total;
    let mut all = imu_diag;
    all.extend(diag);
    all.extend(heading_diag);
    all.extend(stream.diagnostics);
    let records = stream.fix_records;
    let mut stats = fusion.stats();
    let smoother = match smoothing {
        Some((out, _)) => {
            let forward = ForwardResult {
                fusion: &mut fusion,
                records: &records,
                fixes: &fixes,
                t0,
                started,
            };
            Some(smooth_stage(
                &pass_input,
                &fc,
                forward,
                out,
                &mut stats,
                &mut all,
            )?)
        }
        None => None,
    };
    let imu = *fusion.imu_errors();
    let deg_h = 180.0 / std::f64::consts::PI * 3600.0;
    let outages = opts
        .outages
        .map(|o| outage_windows(&o, t0, last_time))
        .unwrap_or_default();
    Ok(FuseSummary {
        tool: "navsync",
        version: env!("CARGO_PKG_VERSION"),
        config: cfg.path.display().to_string(),
        imu_file: cfg.imu_path.display().to_string(),
        gnss_file: cfg.gnss_path.display().to_string(),
        output_dir: opts
            .output_dir
            .clone()
            .unwrap_or_else(|| cfg.output_path.clone())
            .display()
            .to_string(),
        start_sow: t0.sow(),
        end_sow: last_time.sow(),
        duration_s: last_time.seconds_since(t0),
        imu_records_read: imu_count,
        imu_lines_skipped: imu_skipped,
        gnss_fixes_read: fixes_read,
        gnss_lines_skipped: gnss_skipped,
        gnss_fixes_withheld_by_outages: withheld,
        gnss_fixes_outside_run: outside,
        outages,
        time_offset_s: fusion.time_offset().map(|o| o.offset_s),
        time_offset_sd_s: fusion.time_offset().map(|o| o.sd_s),
        time_offset_coarse_s: fusion.coarse_offset().map(|o| o.offset_s),
        output_at_written: at_written,
        output_at_skipped,
        stats: {
            let e = mount_yaw.as_ref().map(|d| &d.estimate);
            stats.mount_yaw_estimate_deg = e.and_then(|e| e.yaw_deg);
            stats.mount_yaw_estimate_sd_deg = e.and_then(|e| e.sd_deg);
            stats
        },
        final_gyro_bias_deg_h: (imu.gyro_bias * deg_h).into(),
        final_accel_bias_mgal: (imu.accel_bias * 1e5).into(),
        final_gyro_scale_ppm: (imu.gyro_scale * 1e6).into(),
        final_accel_scale_ppm: (imu.accel_scale * 1e6).into(),
        final_odometer_scale: opts
            .odometer
            .as_ref()
            .filter(|o| o.scale_sd.is_some())
            .map(|_| fusion.odometer_scale()),
        final_gyro_misalign_deg: opts
            .misalignment_sd_deg
            .map(|_| imu.gyro_misalign.map(f64::to_degrees)),
        final_accel_misalign_deg: opts
            .misalignment_sd_deg
            .map(|_| imu.accel_misalign.map(f64::to_degrees)),
        gnss_weighting: WeightingReport::from_records(&records),
        smoother,
        alignment,
        heading_acquired: fusion.heading_acquired(),
        mount_yaw,
        imu_model: ImuModelSummary::of(cfg),
        antenna_lever_m: cfg.antenna_lever.into(),
        lever_arm: fusion
            .lever_arm()
            .map(|l| l.against_sheet(cfg.antenna_lever.into())),
        // The alignment's options as used: the sheet's lever arm and
        // mounting yaw, not the defaults they replaced.
        options: FuseOptions {
            align: align_used,
            ..opts.clone()
        },
        run_time_s: started.elapsed().as_secs_f64(),
        diagnostics: all,
    })
}

/// The heading file's observations (all of them: a receiver's vehicle
/// heading seeds the alignment) and the dual-antenna baselines among them,
/// with `fc.heading` set when there are any; the file's problems go to
/// `diag`. Dual-antenna headings are measurements through the drive; a
/// receiver's vehicle heading is its own filtered estimate, and fusing it
/// would count its errors as new information again and again.
fn heading_inputs(
    opts: &FuseOptions,
    fc: &mut FusionConfig,
    diag: &mut Diagnostics,
) -> Result<
    (
        Vec<crate::io::heading::HeadingObs>,
        Vec<crate::io::heading::HeadingObs>,
    ),
    Error,
> {
    let Some(h) = &opts.heading else {
        return Ok((Vec::new(), Vec::new()));
    };
    let headings = crate::io::heading::read_headings(&h.path, opts.week, diag)?;
    let baselines: Vec<_> = headings
        .iter()
        .filter(|o| o.source == crate::io::heading::HeadingSource::Baseline)
        .copied()
        .collect();
    if !baselines.is_empty() {
        fc.heading = Some(crate::fusion::HeadingOptions {
            dual_antenna_yaw_rad: h.dual_antenna_yaw_deg.to_radians(),
            dual_antenna_yaw_sd_rad: h.dual_antenna_yaw_sd_deg.to_radians(),
            aligned_from_baseline: false,
        });
    }
    Ok((headings, baselines))
}

/// The simulated outages' windows within the run, as summary.json's
/// `outages` ("sow:len,…", what `navsync eval --outages` takes).
fn outage_windows(schedule: &OutageSchedule, t0: GpsTime, last: GpsTime) -> String {
    schedule
        .windows(t0, last)
        .iter()
        .map(|w| w.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// What a forward pass needs besides its filter configuration.
struct PassInput<'a> {
    cfg: &'a KfGinsConfig,
    opts: &'a FuseOptions,
    end: Option<GpsTime>,
    baselines: &'a [crate::io::heading::HeadingObs],
    /// The smoother's temporary folder and node interval, when smoothing.
    smoother: Option<(&'a Path, f64)>,
}

/// One forward pass's result.
struct ForwardPass {
    fusion: Fusion,
    stream: crate::navigator::StreamEnd,
    imu_count: usize,
    imu_diag: Diagnostics,
    fixes_read: usize,
    /// The fixes handed to the filter, for the smoother's re-judgement
    /// (kept only when smoothing).
    fixes: Vec<GnssFix>,
}

/// One forward pass over the run's files: the IMU, the GNSS fixes, the
/// odometer speeds and dual-antenna headings through the navigator into
/// `sink`, recorded for the smoother when it is on.
fn forward_pass(
    input: &PassInput,
    fc: FusionConfig,
    sink: &mut dyn NavSink,
    diag: &mut Diagnostics,
    progress: &mut dyn FnMut(f64),
) -> Result<ForwardPass, Error> {
    let PassInput {
        cfg,
        opts,
        end,
        baselines,
        smoother,
    } = *input;
    let start = fc.init_nav.time;
    // The files are written whole at the end: a rollback's re-run may
    // replace the solutions of the last seconds (a streaming caller of
    // `batch_navigator` gets each solution as it comes).
    let mut navigator = batch_navigator(fc, opts)?
        .with_end(end)
        .with_revised_output();
    if let Some((dir, interval_s)) = smoother {
        navigator.fusion_mut().enable_smoother(dir, interval_s)?;
    }
    let mut fixes = Vec::new();
    // Fixes are read from the file as far ahead of the IMU as the
    // navigator delivers them (it holds them until then).
    let lead_ns = crate::time::seconds_to_ns(fix_lead_s(opts));

    let mut gnss = GnssInput::open(&cfg.gnss_path, opts)?;
    let mut next_fix: Option<GnssFix> = gnss.next_fix(diag)?;
    let mut speeds = match &opts.odometer {
        Some(o) => Some(crate::reduced::SpeedStream::open(
            &o.path,
            opts.week,
            o.max_gap_s,
        )?),
        None => None,
    };

    // IMU reader stage: batches of parsed samples.
    let mut imu_batches = Source::start(
        ImuBatches {
            reader: ImuReader::open(&cfg.imu_path, opts.week)?,
            diag: Diagnostics::with_cap(1000),
        },
        "imu-reader",
    )?;

    let mut next_heading = baselines.partition_point(|h| h.time < start);
    let mut fixes_read = usize::from(next_fix.is_some());
    let span = end.map(|e| e.seconds_since(start)).unwrap_or(f64::NAN);
    let mut last_progress = Instant::now();
    let mut result: Result<(), Error> = Ok(());
    'outer: loop {
        let batch = match imu_batches.next_batch() {
            Ok(Some(b)) => b,
            Ok(None) => break,
            Err(e) => {
                result = Err(e);
                break;
            }
        };
        for s in &batch {
            while let Some(fix) = next_fix
                && fix.time <= s.time + lead_ns
            {
                if smoother.is_some() {
                    fixes.push(fix);
                }
                navigator.push_gnss(fix);
                next_fix = gnss.next_fix(diag)?;
                fixes_read += usize::from(next_fix.is_some());
            }
            if let Some(sp) = speeds.as_mut()
                && let Some(v) = sp.at(s.time, diag)?
            {
                navigator.push_speed(v);
            }
            while let Some(h) = baselines.get(next_heading)
                && h.time <= s.time
            {
                navigator.push_heading(*h);
                next_heading += 1;
            }
            match navigator.push_imu(s, sink) {
                Ok(Step::Ended) => break 'outer,
                Ok(_) => {}
                Err(e) => {
                    result = Err(e);
                    break 'outer;
                }
            }
        }
        if last_progress.elapsed().as_millis() > 100 {
            last_progress = Instant::now();
            let last = navigator.counts().last_epoch.unwrap_or(start);
            let frac = if span.is_finite() && span > 0.0 {
                last.seconds_since(start) / span
            } else {
                f64::NAN
            };
            progress(frac);
        }
    }
    let read = imu_batches.finish();
    result?;
    let (imu_count, imu_diag) = read?;
    // Count the remaining fixes (and their bad lines) for the summary.
    while next_fix.is_some() {
        next_fix = gnss.next_fix(diag)?;
        fixes_read += usize::from(next_fix.is_some());
    }
    if let GnssInput::Rtklib(r) = &gnss
        && let Some(note) = r.q_summary()
    {
        diag.note(note);
    }
    let stream = if opts.dry_run {
        navigator.finish(&mut NullSink)?
    } else {
        navigator.finish(sink)?
    };
    Ok(ForwardPass {
        fusion: navigator.into_fusion(),
        stream,
        imu_count,
        imu_diag,
        fixes_read,
        fixes,
    })
}

/// The streaming navigator set up as a batch run's options say (outages,
/// reduced IMU, auxiliary interval, `output_at` epochs read from their file,
/// GNSS-time output, and the fix lead of the latency mode).
pub fn batch_navigator(cfg: FusionConfig, opts: &FuseOptions) -> Result<Navigator, Error> {
    opts.validate()?;
    Ok(Navigator::new(cfg)
        .for_batch(fix_lead_s(opts))
        .with_outages(opts.outages)
        .with_reduced_imu(opts.reduced_imu)
        .with_gnss_time_output(opts.output_gnss_time)
        .with_aux_interval(Some(opts.aux_interval_s))
        .with_interpolator(output_at_interpolator(opts)?))
}

/// How far ahead of the IMU a fix is handed to the filter (s): offline,
/// fixes are queued ahead (the filter processes each at its corrected
/// time, and the time-offset search needs them early); in a real-time mode
/// each is delivered at its arrival, `gnss_latency_s` after its time tag.
pub(crate) fn fix_lead_s(opts: &FuseOptions) -> f64 {
    if !matches!(opts.latency, LatencyMode::Offline) {
        -opts.gnss_latency_s
    } else {
        1.0 + opts
            .time_offset
            .map(|t| t.search_range_s.max(3.0 * t.sd_s))
            .unwrap_or(0.0)
    }
}

/// The `--output-at` interpolator with the requested epochs, if any.
fn output_at_interpolator(opts: &FuseOptions) -> Result<Option<NavInterpolator>, Error> {
    let Some(p) = &opts.output_at else {
        return Ok(None);
    };
    let mut ip = NavInterpolator::new(opts.output_at_n);
    for t in crate::io::kfgins::read_times(p, opts.week)? {
        ip.request(t);
    }
    Ok(Some(ip))
}
