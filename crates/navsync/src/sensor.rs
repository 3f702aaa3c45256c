//! The sensor sheet (`sensor.yaml`): what a user knows about their rig —
//! the IMU's datasheet figures (or a named preset), the GNSS antenna lever
//! arm, the IMU's mounting in the vehicle, an optional odometer — and
//! nothing about the drive itself. `navsync init` writes a commented
//! template ([`template`]); `navsync process` reads it ([`SensorSheet::load`])
//! and turns it, with the data's own start time and rate, into the
//! KF-GINS-style configuration of the filter ([`SensorSheet::kfgins_config`])
//! whose initial state is then found by alignment ([`crate::align`]).
//!
//! Units are in the key names (datasheet units: deg/√h, m/s/√h, deg/h,
//! mGal, ppm), as on an IMU datasheet; they are converted to SI here, the
//! same way KF-GINS converts its `imunoise` block (`kf_gins.cpp`,
//! `loadConfig`).

#![warn(missing_docs)]

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::attitude::Euler;
use crate::earth::Geodetic;
use crate::error::Error;
use crate::filter::{ImuNoise, InitialStd};
use crate::imu::spec::{PRESET_BIAS_CORR_TIME_S, preset_triads};
use crate::ins::ImuErrors;
use crate::io::config::KfGinsConfig;

const DEG: f64 = std::f64::consts::PI / 180.0;

/// The IMU presets a sheet may name (those of `navsync simulate`).
pub(crate) const PRESETS: &[&str] = &["adis16465", "icm20602", "tactical", "nav"];

/// The IMU block keys and what each holds (for messages and the template).
pub(crate) const IMU_KEYS: &[(&str, &str)] = &[
    ("preset", "a named IMU whose figures fill the keys left out"),
    (
        "rate_hz",
        "IMU output rate (Hz); measured from the data if left out",
    ),
    ("arw_deg_sqrt_h", "gyro angle random walk (deg/√h)"),
    (
        "vrw_mps_sqrt_h",
        "accelerometer velocity random walk (m/s/√h)",
    ),
    (
        "gyro_bias_instability_deg_h",
        "gyro in-run bias instability (deg/h)",
    ),
    (
        "accel_bias_instability_mgal",
        "accelerometer in-run bias instability (mGal; 1 mGal = 1e-5 m/s² ≈ 1 µg)",
    ),
    ("gyro_turn_on_bias_deg_h", "gyro turn-on bias σ (deg/h)"),
    (
        "accel_turn_on_bias_mgal",
        "accelerometer turn-on bias σ (mGal)",
    ),
    ("gyro_scale_ppm", "gyro scale-factor error σ (ppm)"),
    (
        "accel_scale_ppm",
        "accelerometer scale-factor error σ (ppm)",
    ),
    (
        "bias_corr_time_s",
        "correlation time of the bias instability (s)",
    ),
    (
        "accel_misalignment_deg",
        "accelerometer axis misalignment σ (deg; cross-axis sensitivity 1 % ≈ 0.57°): levelling takes it for tilt; 0 if left out",
    ),
];

/// The range each IMU figure must lie in, in the order of
/// `ImuFigures::as_pairs`. The upper bounds are far beyond any IMU (the
/// worst consumer MEMS parts, e.g. an ICM-20602 at 0.24 deg/√h and
/// 1 % scale error, sit 2–4 orders of magnitude below): a figure above
/// one is a unit slip or a typo (1e308), and would overflow the filter's
/// covariance. The correlation time's floor of 1 s keeps the
/// Gauss–Markov driving noise (2σ²/T) finite.
const IMU_FIGURE_RANGE: [(f64, f64); 10] = [
    (0.0, 1e3),                                         // arw_deg_sqrt_h
    (0.0, 1e2),                                         // vrw_mps_sqrt_h
    (0.0, 1e5),                                         // gyro_bias_instability_deg_h (≈ 28 deg/s)
    (0.0, 1e6),                                         // accel_bias_instability_mgal (≈ 1 g)
    (0.0, 1e5),                                         // gyro_turn_on_bias_deg_h
    (0.0, 1e6),                                         // accel_turn_on_bias_mgal
    (0.0, 1e5),                                         // gyro_scale_ppm (10 %)
    (0.0, 1e5),                                         // accel_scale_ppm
    (1.0, 1e7),                                         // bias_corr_time_s (≈ 4 months)
    (0.0, crate::pipeline::MAX_ACCEL_MISALIGNMENT_DEG), // accel_misalignment_deg
];

/// The range [`IMU_FIGURE_RANGE`] gives the figure `key` (a key of the
/// sheet's `imu` block), for other readers of datasheet figures (the
/// KF-GINS configuration's `imunoise`).
pub(crate) fn figure_range(key: &str) -> (f64, f64) {
    let keys = IMU_KEYS[2..].iter().map(|(k, _)| *k);
    keys.zip(IMU_FIGURE_RANGE)
        .find(|(k, _)| *k == key)
        .map_or((0.0, f64::MAX), |(_, r)| r)
}

/// The IMU rate range (Hz) a sheet may give.
const RATE_RANGE_HZ: (f64, f64) = (1.0, 1e5);
/// Largest odometer speed σ (m/s) and time-offset σ (s) a sheet may give.
const MAX_ODO_SD_MPS: f64 = 100.0;
const MAX_TIME_OFFSET_SD_S: f64 = 10.0;

/// The IMU as the sheet gives it: every figure optional here, so that a
/// preset can fill what is left out; [`SensorSheet::imu_figures`] says
/// which is missing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuSheet {
    /// A named IMU (one of `adis16465`, `icm20602`, `tactical`, `nav`) whose
    /// figures fill the keys left out.
    pub preset: Option<String>,
    /// IMU output rate (Hz); measured from the data when `None`.
    pub rate_hz: Option<f64>,
    /// Gyro angle random walk (deg/√h).
    pub arw_deg_sqrt_h: Option<f64>,
    /// Accelerometer velocity random walk (m/s/√h).
    pub vrw_mps_sqrt_h: Option<f64>,
    /// Gyro in-run bias instability (deg/h).
    pub gyro_bias_instability_deg_h: Option<f64>,
    /// Accelerometer in-run bias instability (mGal; 1 mGal = 1e-5 m/s²).
    pub accel_bias_instability_mgal: Option<f64>,
    /// Gyro turn-on bias σ (deg/h).
    pub gyro_turn_on_bias_deg_h: Option<f64>,
    /// Accelerometer turn-on bias σ (mGal).
    pub accel_turn_on_bias_mgal: Option<f64>,
    /// Gyro scale-factor error σ (ppm).
    pub gyro_scale_ppm: Option<f64>,
    /// Accelerometer scale-factor error σ (ppm).
    pub accel_scale_ppm: Option<f64>,
    /// Correlation time of the bias instability (s); 3600 s when `None` and no
    /// preset gives it.
    pub bias_corr_time_s: Option<f64>,
    /// Accelerometer axis misalignment σ (deg; cross-axis sensitivity 1 % ≈
    /// 0.57°); 0 when `None` and no preset gives it.
    pub accel_misalignment_deg: Option<f64>,
}

/// The IMU's figures, all present (datasheet units).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImuFigures {
    /// Gyro angle random walk (deg/√h).
    pub arw_deg_sqrt_h: f64,
    /// Accelerometer velocity random walk (m/s/√h).
    pub vrw_mps_sqrt_h: f64,
    /// Gyro in-run bias instability (deg/h).
    pub gyro_bias_instability_deg_h: f64,
    /// Accelerometer in-run bias instability (mGal).
    pub accel_bias_instability_mgal: f64,
    /// Gyro turn-on bias σ (deg/h).
    pub gyro_turn_on_bias_deg_h: f64,
    /// Accelerometer turn-on bias σ (mGal).
    pub accel_turn_on_bias_mgal: f64,
    /// Gyro scale-factor error σ (ppm).
    pub gyro_scale_ppm: f64,
    /// Accelerometer scale-factor error σ (ppm).
    pub accel_scale_ppm: f64,
    /// Correlation time of the bias instability (s).
    pub bias_corr_time_s: f64,
    /// Accelerometer axis misalignment σ (deg).
    pub accel_misalignment_deg: f64,
}

impl ImuFigures {
    /// A preset's figures (the datasheet figures of [`crate::imu::spec`],
    /// which the simulator's presets use too).
    pub fn preset(name: &str) -> Option<ImuFigures> {
        if !PRESETS.contains(&name) {
            return None;
        }
        let (gyro, accel) = preset_triads(name)?;
        Some(ImuFigures {
            arw_deg_sqrt_h: gyro.arw_deg_sqrt_h,
            vrw_mps_sqrt_h: accel.vrw_mps_sqrt_h,
            gyro_bias_instability_deg_h: gyro.bias_instability_deg_h,
            accel_bias_instability_mgal: accel.bias_instability_mgal,
            gyro_turn_on_bias_deg_h: gyro.turn_on_bias_deg_h,
            accel_turn_on_bias_mgal: accel.turn_on_bias_mgal,
            gyro_scale_ppm: gyro.scale_ppm,
            accel_scale_ppm: accel.scale_ppm,
            bias_corr_time_s: PRESET_BIAS_CORR_TIME_S,
            accel_misalignment_deg: accel.misalignment_deg,
        })
    }

    fn as_pairs(&self) -> [(&'static str, f64); 10] {
        [
            ("arw_deg_sqrt_h", self.arw_deg_sqrt_h),
            ("vrw_mps_sqrt_h", self.vrw_mps_sqrt_h),
            (
                "gyro_bias_instability_deg_h",
                self.gyro_bias_instability_deg_h,
            ),
            (
                "accel_bias_instability_mgal",
                self.accel_bias_instability_mgal,
            ),
            ("gyro_turn_on_bias_deg_h", self.gyro_turn_on_bias_deg_h),
            ("accel_turn_on_bias_mgal", self.accel_turn_on_bias_mgal),
            ("gyro_scale_ppm", self.gyro_scale_ppm),
            ("accel_scale_ppm", self.accel_scale_ppm),
            ("bias_corr_time_s", self.bias_corr_time_s),
            ("accel_misalignment_deg", self.accel_misalignment_deg),
        ]
    }

    /// The filter's process noise (SI), as KF-GINS converts its `imunoise`
    /// block; floors keep a "perfect" figure from making the filter
    /// over-confident (as `navsync simulate`'s configuration does).
    pub fn noise(&self) -> ImuNoise {
        ImuNoise {
            arw: Vector3::repeat(self.arw_deg_sqrt_h.max(1e-3) * DEG / 60.0),
            vrw: Vector3::repeat(self.vrw_mps_sqrt_h.max(1e-3) / 60.0),
            gyro_bias_sd: Vector3::repeat(
                self.gyro_bias_instability_deg_h.max(0.01) * DEG / 3600.0,
            ),
            accel_bias_sd: Vector3::repeat(self.accel_bias_instability_mgal.max(1.0) * 1e-5),
            gyro_scale_sd: Vector3::repeat(self.gyro_scale_ppm.max(10.0) * 1e-6),
            accel_scale_sd: Vector3::repeat(self.accel_scale_ppm.max(10.0) * 1e-6),
            corr_time_s: self.bias_corr_time_s,
        }
    }

    /// Initial σ of the IMU error states: the turn-on bias and the
    /// instability together (root sum of squares), the scale factors.
    pub fn initial_std(&self) -> InitialStd {
        let bg = self
            .gyro_turn_on_bias_deg_h
            .hypot(self.gyro_bias_instability_deg_h)
            .max(0.01);
        let ba = self
            .accel_turn_on_bias_mgal
            .hypot(self.accel_bias_instability_mgal)
            .max(1.0);
        InitialStd {
            // Position, velocity and attitude σ come from the alignment.
            pos: Vector3::repeat(1.0),
            vel: Vector3::repeat(0.1),
            att: Vector3::repeat(DEG),
            gyro_bias: Vector3::repeat(bg * DEG / 3600.0),
            accel_bias: Vector3::repeat(ba * 1e-5),
            gyro_scale: Vector3::repeat(self.gyro_scale_ppm.max(10.0) * 1e-6),
            accel_scale: Vector3::repeat(self.accel_scale_ppm.max(10.0) * 1e-6),
        }
    }
}

/// Wheel or CAN speed input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometerSheet {
    /// Speed file: `sow speed_mps` per line, GPS seconds of week; relative
    /// paths are relative to the sheet's folder.
    pub file: PathBuf,
    /// Speed σ (m/s).
    #[serde(default = "default_odo_sd")]
    pub sd_mps: f64,
    /// Lever arm from the IMU to the wheel contact point, IMU axes (m).
    #[serde(default)]
    pub lever_m: [f64; 3],
}

fn default_odo_sd() -> f64 {
    0.1
}

/// IMU–GNSS time-offset estimation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeOffsetSheet {
    /// Estimate the offset as a filter state.
    pub estimate: bool,
    /// Initial σ of the offset (s).
    #[serde(default = "default_offset_sd")]
    pub sd_s: f64,
}

fn default_offset_sd() -> f64 {
    0.2
}

/// A sensor sheet as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSheet {
    /// The IMU's figures (`imu:` block).
    pub imu: ImuSheet,
    /// Lever arm from the IMU to the GNSS antenna phase centre, IMU axes
    /// [forward, right, down] (m).
    pub antenna_lever_m: [f64; 3],
    /// Estimate the antenna lever arm as filter states (from
    /// `antenna_lever_m`, with σ `antenna_lever_sd_m`): worth it when the
    /// lever arm is unmeasured and the drive turns.
    #[serde(default)]
    pub estimate_lever_arm: bool,
    /// Initial σ of the lever-arm states (m).
    #[serde(default = "default_lever_sd")]
    pub antenna_lever_sd_m: f64,
    /// IMU-to-vehicle mounting [roll, pitch, yaw] (deg): the IMU's attitude
    /// in the vehicle's axes (forward, right, down), ZYX Euler angles like a
    /// solution's roll, pitch, yaw, so the IMU's yaw is the vehicle's
    /// heading + yaw. Positive yaw turns the IMU's x axis from forward to
    /// the right (clockwise from above), positive roll its y axis down,
    /// positive pitch its x axis up; 0 when x forward, y right, z down.
    /// Used by the NHC and the odometer (C_b^v, `filter::nhc`) and the
    /// alignment's course.
    #[serde(default)]
    pub mount_deg: [f64; 3],
    /// Apply the non-holonomic constraint (land vehicle; needs `mount_deg`).
    #[serde(default)]
    pub nhc: bool,
    /// Wheel or CAN speed updates; `None`: none.
    #[serde(default)]
    pub odometer: Option<OdometerSheet>,
    /// Estimate the IMU–GNSS time offset; `None`: not estimated.
    #[serde(default)]
    pub time_offset: Option<TimeOffsetSheet>,
    /// σ [north, east, down] (m) given to fixes that carry none (NMEA without
    /// GST).
    #[serde(default = "default_gnss_sd")]
    pub gnss_default_sd_m: [f64; 3],
    /// Dual-antenna heading: the yaw of the baseline (primary → secondary
    /// antenna) in the IMU's axes, from x towards y (deg), and its σ.
    #[serde(default)]
    pub dual_antenna_yaw_deg: f64,
    /// σ of `dual_antenna_yaw_deg` (deg).
    #[serde(default = "default_dual_antenna_yaw_sd")]
    pub dual_antenna_yaw_sd_deg: f64,
    /// σ given to NMEA HDT headings (deg), which carry none: the
    /// receiver's datasheet heading accuracy for the baseline's length.
    #[serde(default = "default_hdt_sd")]
    pub hdt_sd_deg: f64,
}

fn default_lever_sd() -> f64 {
    0.5
}

fn default_gnss_sd() -> [f64; 3] {
    [5.0, 5.0, 10.0]
}

fn default_dual_antenna_yaw_sd() -> f64 {
    0.5
}

fn default_hdt_sd() -> f64 {
    0.5
}

impl SensorSheet {
    /// Reads and checks a sheet; relative paths in it (the odometer file)
    /// become relative to the sheet's folder.
    pub fn load(path: &Path) -> Result<SensorSheet, Error> {
        let text = crate::io::text::read_config_text(path)?;
        let mut s = Self::parse(&text, path)?;
        if let (Some(o), Some(dir)) = (&mut s.odometer, path.parent())
            && o.file.is_relative()
        {
            o.file = dir.join(&o.file);
        }
        Ok(s)
    }

    /// Parses and checks YAML text; `path` names it in messages.
    pub fn parse(text: &str, path: &Path) -> Result<SensorSheet, Error> {
        let sheet: SensorSheet = serde_saphyr::from_str(text).map_err(|e| yaml_error(path, &e))?;
        sheet.validate(path)?;
        Ok(sheet)
    }

    /// The IMU figures: the preset's, overridden by any figure given; an
    /// error names the keys still missing.
    pub fn imu_figures(&self, path: &Path) -> Result<ImuFigures, Error> {
        let i = &self.imu;
        let base = match &i.preset {
            Some(p) => Some(ImuFigures::preset(p).ok_or_else(|| {
                Error::config(
                    path,
                    format!(
                        "key 'imu.preset': unknown IMU '{p}'; expected one of {}",
                        PRESETS.join(", ")
                    ),
                )
            })?),
            None => None,
        };
        let given = [
            i.arw_deg_sqrt_h,
            i.vrw_mps_sqrt_h,
            i.gyro_bias_instability_deg_h,
            i.accel_bias_instability_mgal,
            i.gyro_turn_on_bias_deg_h,
            i.accel_turn_on_bias_mgal,
            i.gyro_scale_ppm,
            i.accel_scale_ppm,
            i.bias_corr_time_s,
            i.accel_misalignment_deg,
        ];
        let base_vals = base.map(|b| b.as_pairs().map(|p| p.1));
        let mut v = [0.0; 10];
        let mut missing = Vec::new();
        for k in 0..10 {
            match (given[k], base_vals) {
                (Some(x), _) => v[k] = x,
                (None, Some(b)) => v[k] = b[k],
                // The correlation time has a usual value; the others are
                // the IMU's own.
                (None, None) if k == 8 => v[k] = 3600.0,
                // Axes taken as orthogonal.
                (None, None) if k == 9 => v[k] = 0.0,
                (None, None) => missing.push(IMU_KEYS[k + 2]),
            }
        }
        if !missing.is_empty() {
            let list: Vec<String> = missing
                .iter()
                .map(|(k, what)| format!("'imu.{k}' ({what})"))
                .collect();
            return Err(Error::config(
                path,
                format!(
                    "missing key{} {}: give {}, or 'imu.preset' (one of {}) to fill {}",
                    if list.len() > 1 { "s" } else { "" },
                    list.join(", "),
                    if list.len() > 1 { "them" } else { "it" },
                    PRESETS.join(", "),
                    if list.len() > 1 { "them" } else { "it" },
                ),
            ));
        }
        let f = ImuFigures {
            arw_deg_sqrt_h: v[0],
            vrw_mps_sqrt_h: v[1],
            gyro_bias_instability_deg_h: v[2],
            accel_bias_instability_mgal: v[3],
            gyro_turn_on_bias_deg_h: v[4],
            accel_turn_on_bias_mgal: v[5],
            gyro_scale_ppm: v[6],
            accel_scale_ppm: v[7],
            bias_corr_time_s: v[8],
            accel_misalignment_deg: v[9],
        };
        for ((k, x), (lo, hi)) in f.as_pairs().into_iter().zip(IMU_FIGURE_RANGE) {
            // NaN fails the range test too (`.nan` and `.inf` are YAML numbers).
            if !(lo..=hi).contains(&x) {
                let why = if k == "accel_misalignment_deg" {
                    " (a datasheet's cross-axis misalignment is a fraction of a degree)"
                } else {
                    " (beyond any IMU: check the key's unit)"
                };
                return Err(Error::config(
                    path,
                    format!("key 'imu.{k}' must be within [{lo}, {hi}]{why}, got {x}"),
                ));
            }
        }
        Ok(f)
    }

    /// Checks every value (the IMU figures included).
    pub fn validate(&self, path: &Path) -> Result<(), Error> {
        self.imu_figures(path)?;
        let bad = |k: &str, m: String| Err(Error::config(path, format!("key '{k}' {m}")));
        let (lo, hi) = RATE_RANGE_HZ;
        if let Some(r) = self.imu.rate_hz
            && !(lo..=hi).contains(&r)
        {
            return bad(
                "imu.rate_hz",
                format!("must be within [{lo}, {hi}] Hz, got {r}"),
            );
        }
        for (k, v, lim) in [
            ("antenna_lever_m", self.antenna_lever_m, 100.0),
            ("mount_deg", self.mount_deg, 180.0),
            ("gnss_default_sd_m", self.gnss_default_sd_m, 1e4),
        ] {
            if v.iter().any(|x| !(x.is_finite() && x.abs() <= lim)) {
                return bad(k, format!("must hold 3 numbers within ±{lim}, got {v:?}"));
            }
        }
        let max_sd = crate::pipeline::MAX_LEVER_ARM_SD_M;
        if !(self.antenna_lever_sd_m > 0.0 && self.antenna_lever_sd_m <= max_sd) {
            return bad(
                "antenna_lever_sd_m",
                format!(
                    "must be within (0, {max_sd}] m, got {}",
                    self.antenna_lever_sd_m
                ),
            );
        }
        if !(self.dual_antenna_yaw_deg.is_finite() && self.dual_antenna_yaw_deg.abs() <= 360.0) {
            return bad(
                "dual_antenna_yaw_deg",
                format!("must be within ±360°, got {}", self.dual_antenna_yaw_deg),
            );
        }
        if !(self.dual_antenna_yaw_sd_deg.is_finite()
            && (0.0..=30.0).contains(&self.dual_antenna_yaw_sd_deg))
        {
            return bad(
                "dual_antenna_yaw_sd_deg",
                format!("must be within 0…30°, got {}", self.dual_antenna_yaw_sd_deg),
            );
        }
        if !crate::io::heading::usable_sd(self.hdt_sd_deg) {
            return bad(
                "hdt_sd_deg",
                format!(
                    "must be within (0, {}]°, got {}",
                    crate::io::heading::MAX_HEADING_SD_DEG,
                    self.hdt_sd_deg
                ),
            );
        }
        if self.gnss_default_sd_m.iter().any(|x| *x <= 0.0) {
            return bad(
                "gnss_default_sd_m",
                format!("must be positive, got {:?}", self.gnss_default_sd_m),
            );
        }
        if let Some(o) = &self.odometer {
            if !(o.sd_mps > 0.0 && o.sd_mps <= MAX_ODO_SD_MPS) {
                return bad(
                    "odometer.sd_mps",
                    format!("must be within (0, {MAX_ODO_SD_MPS}] m/s, got {}", o.sd_mps),
                );
            }
            if o.lever_m
                .iter()
                .any(|x| !(x.is_finite() && x.abs() <= 100.0))
            {
                return bad(
                    "odometer.lever_m",
                    format!("must hold 3 numbers within ±100 m, got {:?}", o.lever_m),
                );
            }
        }
        if let Some(t) = &self.time_offset
            && !(t.sd_s > 0.0 && t.sd_s <= MAX_TIME_OFFSET_SD_S)
        {
            return bad(
                "time_offset.sd_s",
                format!(
                    "must be within (0, {MAX_TIME_OFFSET_SD_S}] s, got {}",
                    t.sd_s
                ),
            );
        }
        Ok(())
    }

    /// A warning when the sheet's `imu.rate_hz` differs from the rate
    /// measured on the data (its median interval) by more than
    /// [`RATE_MISMATCH`]: the filter would take the sheet's rate (its gap
    /// detection and noise per sample), though the data say otherwise.
    pub fn rate_mismatch(&self, sheet_path: &Path, data: &DriveFiles) -> Option<String> {
        let (given, measured) = (self.imu.rate_hz?, data.imu_rate_hz?);
        ((given - measured).abs() > RATE_MISMATCH * measured).then(|| {
            format!(
                "{}: imu.rate_hz is {given} Hz but the data's median interval gives {measured:.1} Hz \
                 ({} differs by more than {:.0} %): the sheet's rate is used; correct it or remove \
                 the key to use the measured rate",
                sheet_path.display(),
                data.imu.display(),
                RATE_MISMATCH * 100.0
            )
        })
    }

    /// The filter configuration for a drive: the sheet's IMU and lever arm,
    /// the data's files, rate and start time; no initial state (the run
    /// aligns itself: `init_state_given` is false).
    pub fn kfgins_config(
        &self,
        sheet_path: &Path,
        data: &DriveFiles,
    ) -> Result<KfGinsConfig, Error> {
        let fig = self.imu_figures(sheet_path)?;
        let imu_rate_hz = self.imu.rate_hz.or(data.imu_rate_hz).ok_or_else(|| {
            Error::config(
                sheet_path,
                "the IMU rate could not be measured from the data: give 'imu.rate_hz' (Hz)",
            )
        })?;
        Ok(KfGinsConfig {
            path: sheet_path.to_path_buf(),
            imu_path: data.imu.clone(),
            gnss_path: data.gnss.clone(),
            output_path: data.output.clone(),
            imu_rate_hz,
            start_sow: data.start_sow,
            end_sow: None,
            init_pos: Geodetic::from_deg(0.0, 0.0, 0.0),
            init_vel: Vector3::zeros(),
            init_att: Euler::from_deg(0.0, 0.0, 0.0),
            init_state_given: false,
            init_imu: ImuErrors::default(),
            init_std: fig.initial_std(),
            noise: fig.noise(),
            antenna_lever: Vector3::from(self.antenna_lever_m),
        })
    }
}

/// A warning for a zero antenna lever arm in `source` (a sensor sheet's
/// `antenna_lever_m`, a KF-GINS `antlever`): the default left unmeasured,
/// as a rule, and every centimetre of it goes into the position.
pub fn zero_lever_warning(lever_m: [f64; 3], source: &Path) -> Option<String> {
    lever_m.iter().all(|x| *x == 0.0).then(|| {
        format!(
            "{}: the antenna lever arm is [0, 0, 0]: unmeasured? Its error goes straight into the \
             position (a 0.5 m offset is a 0.5 m error); measure the IMU-to-antenna offset \
             (forward, right, down) and enter it, or let the filter estimate it on a drive with \
             turns (sheet: estimate_lever_arm: true; process/fuse --estimate-lever-arm)",
            source.display()
        )
    })
}

/// Relative difference between a sheet's IMU rate and the measured one
/// beyond which [`SensorSheet::rate_mismatch`] warns: a clock error is
/// ppm to a few %, a wrong rate (50 Hz for 200 Hz) is a factor.
pub const RATE_MISMATCH: f64 = 0.10;

/// The KF-GINS files of one drive and what is known of them.
#[derive(Clone, Debug)]
pub struct DriveFiles {
    /// IMU increments (KF-GINS, 7 columns).
    pub imu: PathBuf,
    /// GNSS fixes (KF-GINS, 7 or 13 columns).
    pub gnss: PathBuf,
    /// Output folder of the fusion.
    pub output: PathBuf,
    /// IMU rate measured from the data (Hz).
    pub imu_rate_hz: Option<f64>,
    /// First IMU epoch (GPS seconds of week).
    pub start_sow: f64,
}

/// A YAML error as "the file, line N: what; expected keys …".
fn yaml_error(path: &Path, e: &serde_saphyr::Error) -> Error {
    let line = e.location().map(|l| l.line()).filter(|l| *l > 0);
    // The first line of the rendered message is the message itself (a
    // source snippet may follow).
    let text = e.to_string();
    let msg = text.lines().next().unwrap_or("invalid YAML").trim();
    let mut msg = msg.trim_start_matches("error: ").replace('`', "'");
    // The location is given as the line number: drop its repetition.
    if msg.starts_with("line ")
        && let Some(i) = msg.find(": ")
    {
        msg = msg[i + 2..].to_string();
    }
    // A missing key has no line of its own (the location is the end of
    // its mapping).
    let line = line.filter(|_| !msg.contains("missing field"));
    let hint = if msg.contains("unknown field") {
        ""
    } else if msg.contains("missing field") {
        if msg.contains("'imu'") || msg.contains("'antenna_lever_m'") {
            " (a sensor sheet needs 'imu' and 'antenna_lever_m'; `navsync init` writes one)"
        } else {
            ""
        }
    } else {
        " (`navsync init` writes a commented template)"
    };
    match line {
        Some(l) => Error::Parse {
            path: path.to_path_buf(),
            line: l as usize,
            msg: format!("{msg}{hint}"),
        },
        None => Error::config(path, format!("{msg}{hint}")),
    }
}

/// The commented template `navsync init` writes, with the figures of
/// `preset` filled in (all keys active, so that the user edits numbers,
/// not comments).
pub fn template(preset: &str) -> Result<String, Error> {
    let f = ImuFigures::preset(preset).ok_or_else(|| {
        Error::Invalid(format!(
            "unknown IMU preset '{preset}': expected one of {}",
            PRESETS.join(", ")
        ))
    })?;
    let mut y = String::new();
    y.push_str(&format!(
        "# navsync sensor sheet (written by `navsync init --preset {preset}`).\n\
         # What you know about your rig; nothing about the drive. Used by\n\
         #   navsync process RAW... --sensor THIS_FILE --output DIR\n\
         # Axes: IMU body frame forward-right-down (FRD). Units are in the key names.\n\
         \n\
         # The IMU. Either name a preset and delete the figures below\n\
         # (presets: {}), or give every figure from your IMU's datasheet;\n\
         # figures given override the preset's.\n\
         imu:\n\
         \x20 # preset: {preset}\n\
         \x20 # IMU output rate (Hz). Left out: measured from the data.\n\
         \x20 # rate_hz: 200\n",
        PRESETS.join(", ")
    ));
    let comment = |k: &str| -> &str {
        IMU_KEYS
            .iter()
            .find(|p| p.0 == k)
            .map(|p| p.1)
            .unwrap_or("")
    };
    for (k, v) in f.as_pairs() {
        y.push_str(&format!("  # {}\n  {k}: {}\n", comment(k), fmt_num(v)));
    }
    y.push_str(
        "\n# Lever arm from the IMU to the GNSS antenna phase centre, in the IMU's\n\
         # axes [forward, right, down] (m). An antenna above the IMU has a negative\n\
         # down component. Measure it to a few cm: errors go straight into position.\n\
         antenna_lever_m: [0.0, 0.0, 0.0]\n\
         # Unmeasured? Estimate it as filter states from the value above with this\n\
         # σ (m): the horizontal components need turns, the vertical one is hardly\n\
         # observable on a road (process says how well each was found).\n\
         # estimate_lever_arm: true\n\
         # antenna_lever_sd_m: 0.5\n\
         \n\
         # Land vehicle: apply the non-holonomic constraint (no sideways or vertical\n\
         # velocity of the vehicle). Needs the IMU's mounting angles below.\n\
         nhc: false\n\
         # IMU-to-vehicle mounting [roll, pitch, yaw] (deg): the IMU's attitude in the\n\
         # vehicle's axes (forward, right, down), as a solution's roll/pitch/yaw: the\n\
         # IMU's yaw is the vehicle's heading + yaw. Positive yaw turns the IMU's x\n\
         # axis from forward to the right (clockwise seen from above), positive roll\n\
         # turns its y axis down, positive pitch its x axis up. Examples: x forward,\n\
         # z down: [0, 0, 0]; x to the right: [0, 0, 90]; x backward: [0, 0, 180];\n\
         # on its side, x forward and y down (a ROS/FLU IMU with its y axis up):\n\
         # [90, 0, 0]; upside down, x forward: [180, 0, 0]. Used by the NHC, the\n\
         # odometer and the alignment's course. With nhc or an odometer and roll and\n\
         # pitch 0 here, an IMU found tilted by more than 20° at rest is taken as\n\
         # mounted so (roll and pitch from gravity; process says so).\n\
         mount_deg: [0.0, 0.0, 0.0]\n\
         \n\
         # Optional wheel or CAN speed: a file of `sow speed_mps` lines (GPS seconds\n\
         # of week, m/s; relative to this sheet's folder), its σ (m/s) and the lever\n\
         # arm from the IMU to the wheel contact point [forward, right, down] (m).\n\
         # odometer:\n\
         #   file: speed.txt\n\
         #   sd_mps: 0.1\n\
         #   lever_m: [0.0, 0.0, 0.0]\n\
         \n\
         # Optional: estimate the IMU-GNSS time offset (GNSS time tag minus true time\n\
         # of validity) as a filter state, with this initial σ (s). Worth it with\n\
         # software time stamps (no 1PPS), e.g. an IMU and a receiver on USB.\n\
         # time_offset:\n\
         #   estimate: true\n\
         #   sd_s: 0.2\n\
         \n\
         # σ [north, east, down] (m) given to fixes that carry none (NMEA without GST).\n\
         gnss_default_sd_m: [5.0, 5.0, 10.0]\n\
         \n\
         # Dual-antenna heading (u-blox moving base: log UBX NAV-RELPOSNED): the yaw\n\
         # of the baseline from the primary to the secondary antenna in the IMU's axes,\n\
         # from forward towards right (deg; 0: the second antenna straight ahead of\n\
         # the first, 90: to its right), and how well it is known (σ, deg). Unused\n\
         # without dual-antenna headings in the receiver log.\n\
         dual_antenna_yaw_deg: 0.0\n\
         dual_antenna_yaw_sd_deg: 0.5\n\
         # NMEA HDT (Unicore, Septentrio, Hemisphere dual-antenna receivers) carries no\n\
         # accuracy: the σ (deg) its headings get; take the receiver's datasheet\n\
         # heading accuracy for your baseline's length.\n\
         hdt_sd_deg: 0.5\n",
    );
    Ok(y)
}

/// Shortest round-trip form of a number (so a template parses back to the
/// very values it was written from).
fn fmt_num(x: f64) -> String {
    let s = format!("{x:?}");
    if s.contains('.') || s.contains('e') {
        s
    } else {
        format!("{s}.0")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn template_round_trips_to_the_preset() {
        for p in PRESETS {
            let t = template(p).unwrap();
            let s = SensorSheet::parse(&t, Path::new("sensor.yaml")).unwrap();
            let f = s.imu_figures(Path::new("sensor.yaml")).unwrap();
            assert_eq!(f, ImuFigures::preset(p).unwrap(), "{p}");
            assert_eq!(s.antenna_lever_m, [0.0; 3]);
            assert!(
                zero_lever_warning(s.antenna_lever_m, Path::new("s.yaml"))
                    .is_some_and(|w| w.contains("s.yaml") && w.contains("[0, 0, 0]"))
            );
            assert!(zero_lever_warning([0.0, 0.0, -0.01], Path::new("s.yaml")).is_none());
            assert!(!s.nhc && s.odometer.is_none() && s.time_offset.is_none());
        }
        // The preset alone gives the same figures.
        let s = SensorSheet::parse(
            "imu:\n  preset: icm20602\nantenna_lever_m: [0.1, 0, -0.5]\n",
            Path::new("s.yaml"),
        )
        .unwrap();
        let f = s.imu_figures(Path::new("s.yaml")).unwrap();
        assert_eq!(f, ImuFigures::preset("icm20602").unwrap());
        // ICM-20602 datasheet ARW 0.24°/√h → rad/√s.
        assert!((f.noise().arw.x - 0.24 * DEG / 60.0).abs() < 1e-15);
    }

    #[test]
    fn misspelled_key_names_file_line_and_expected_keys() {
        let t = template("adis16465")
            .unwrap()
            .replace("antenna_lever_m:", "antena_lever_m:");
        let e = SensorSheet::parse(&t, Path::new("my/sensor.yaml"))
            .unwrap_err()
            .to_string();
        let line = t
            .lines()
            .position(|l| l.starts_with("antena_lever_m"))
            .unwrap()
            + 1;
        assert!(e.contains("my/sensor.yaml"), "{e}");
        assert!(e.contains("'antena_lever_m'"), "{e}");
        assert!(e.contains(&format!(":{line}:")), "line {line}: {e}");
        assert!(
            e.contains("antenna_lever_m") && e.contains("mount_deg"),
            "{e}"
        );

        let t = template("adis16465")
            .unwrap()
            .replace("  vrw_mps_sqrt_h:", "  vrw_mps_sqrth:");
        let e = SensorSheet::parse(&t, Path::new("s.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'vrw_mps_sqrth'") && e.contains("vrw_mps_sqrt_h"),
            "{e}"
        );
    }

    #[test]
    fn missing_keys_are_named() {
        let e = SensorSheet::parse("imu:\n  preset: nav\n", Path::new("s.yaml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.yaml") && e.contains("antenna_lever_m"), "{e}");

        // No preset: every figure is needed, and the missing one is named.
        let t = template("adis16465")
            .unwrap()
            .lines()
            .filter(|l| !l.trim_start().starts_with("vrw_mps_sqrt_h"))
            .collect::<Vec<_>>()
            .join("\n");
        let e = SensorSheet::parse(&t, Path::new("s.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.yaml") && e.contains("missing key 'imu.vrw_mps_sqrt_h'"),
            "{e}"
        );
        let e = SensorSheet::parse(
            "imu:\n  preset: adis1646\nantenna_lever_m: [0, 0, 0]\n",
            Path::new("s.yaml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("unknown IMU 'adis1646'"), "{e}");
        let e = SensorSheet::parse(
            "imu:\n  preset: nav\n  rate_hz: -5\nantenna_lever_m: [0, 0, 0]\n",
            Path::new("s.yaml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("'imu.rate_hz' must be within [1, 100000] Hz, got -5"),
            "{e}"
        );
    }

    /// The accelerometer misalignment is optional without a preset (axes
    /// taken as orthogonal) and must not be negative.
    #[test]
    fn accel_misalignment_defaults_to_zero_and_is_checked() {
        let figures = |t: &str| {
            SensorSheet::parse(t, Path::new("s.yaml"))
                .and_then(|s| s.imu_figures(Path::new("s.yaml")))
                .map_err(|e| e.to_string())
        };
        let no_preset = template("icm20602")
            .unwrap()
            .lines()
            .filter(|l| !l.trim_start().starts_with("accel_misalignment_deg"))
            .collect::<Vec<_>>()
            .join("\n");
        assert_eq!(figures(&no_preset).unwrap().accel_misalignment_deg, 0.0);
        let negative = template("icm20602").unwrap().replace(
            "accel_misalignment_deg: 0.3",
            "accel_misalignment_deg: -0.3",
        );
        let e = figures(&negative).unwrap_err();
        assert!(
            e.contains("s.yaml") && e.contains("'imu.accel_misalignment_deg'"),
            "{e}"
        );
        let too_large = template("icm20602")
            .unwrap()
            .replace("accel_misalignment_deg: 0.3", "accel_misalignment_deg: 30");
        let e = figures(&too_large).unwrap_err();
        assert!(
            e.contains("s.yaml")
                && e.contains("'imu.accel_misalignment_deg' must be within [0, 10]"),
            "{e}"
        );
    }

    /// An absurd figure (1e308, YAML's `.inf` and `.nan`, a negative) is an
    /// error naming its key, never a filter whose covariance overflows.
    #[test]
    fn absurd_figures_are_errors_naming_the_key() {
        let t = template("adis16465").unwrap();
        let set = |key: &str, v: &str| -> String {
            let mut found = false;
            let out = t
                .lines()
                .map(|l| match l.split_once(':') {
                    Some((k, _)) if k.trim() == key && !k.trim_start().starts_with('#') => {
                        found = true;
                        format!("{k}: {v}\n")
                    }
                    _ => format!("{l}\n"),
                })
                .collect();
            assert!(found, "{key} not in the template");
            out
        };
        let keys = IMU_KEYS[2..]
            .iter()
            .map(|(k, _)| (*k, format!("'imu.{k}'")));
        for (key, named) in keys {
            for v in ["1e308", ".inf", "-.inf", ".nan", "-1"] {
                let e = SensorSheet::parse(&set(key, v), Path::new("s.yaml"))
                    .unwrap_err()
                    .to_string();
                assert!(
                    e.contains("s.yaml") && e.contains(&named),
                    "{key} = {v}: {e}"
                );
            }
        }
        // Keys outside the figures, added to the template.
        for (extra, named) in [
            ("imu:\n  rate_hz: 1e308\n", "'imu.rate_hz'"),
            ("imu:\n  rate_hz: .inf\n", "'imu.rate_hz'"),
            ("imu:\n  rate_hz: 1e-300\n", "'imu.rate_hz'"),
            (
                "odometer:\n  file: o.txt\n  sd_mps: 1e308\n",
                "'odometer.sd_mps'",
            ),
            (
                "odometer:\n  file: o.txt\n  sd_mps: .nan\n",
                "'odometer.sd_mps'",
            ),
            (
                "time_offset:\n  estimate: true\n  sd_s: 1e308\n",
                "'time_offset.sd_s'",
            ),
            ("gnss_default_sd_m: [1, 1, 1e308]\n", "'gnss_default_sd_m'"),
            ("antenna_lever_m: [.nan, 0, 0]\n", "'antenna_lever_m'"),
            ("antenna_lever_sd_m: 0\n", "'antenna_lever_sd_m'"),
            ("antenna_lever_sd_m: 50\n", "'antenna_lever_sd_m'"),
        ] {
            let (block, _) = extra.split_once(':').unwrap();
            let text = if block == "imu" {
                t.replace("imu:\n", extra)
            } else {
                let kept: String = t
                    .lines()
                    .filter(|l| !l.starts_with(&format!("{block}:")))
                    .map(|l| format!("{l}\n"))
                    .collect();
                kept + extra
            };
            let e = SensorSheet::parse(&text, Path::new("s.yaml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("s.yaml") && e.contains(named), "{extra}: {e}");
        }
        // The limits leave every preset, and a plausible rate, valid.
        let ok = t.replace("imu:\n", "imu:\n  rate_hz: 2000\n");
        assert_eq!(
            SensorSheet::parse(&ok, Path::new("s.yaml"))
                .unwrap()
                .imu
                .rate_hz,
            Some(2000.0)
        );
    }

    /// The HDT heading σ defaults to 0.5° and is checked like a heading σ.
    #[test]
    fn hdt_sd_defaults_and_is_checked() {
        let parse = |t: &str| SensorSheet::parse(t, Path::new("s.yaml")).map_err(|e| e.to_string());
        let t = template("adis16465").unwrap();
        let without: String = t
            .lines()
            .filter(|l| !l.starts_with("hdt_sd_deg"))
            .map(|l| format!("{l}\n"))
            .collect();
        assert_eq!(parse(&without).unwrap().hdt_sd_deg, 0.5);
        assert_eq!(
            parse(&t.replace("hdt_sd_deg: 0.5", "hdt_sd_deg: 0.2"))
                .unwrap()
                .hdt_sd_deg,
            0.2
        );
        for bad in ["0", "-1", "45", ".nan"] {
            let e =
                parse(&t.replace("hdt_sd_deg: 0.5", &format!("hdt_sd_deg: {bad}"))).unwrap_err();
            assert!(
                e.contains("s.yaml") && e.contains("'hdt_sd_deg' must be within (0, 30]"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn config_has_no_initial_state_and_si_noise() {
        let s = SensorSheet::parse(&template("adis16465").unwrap(), Path::new("s.yaml")).unwrap();
        let d = DriveFiles {
            imu: "imu.txt".into(),
            gnss: "gnss.txt".into(),
            output: "out".into(),
            imu_rate_hz: Some(200.0),
            start_sow: 100.0,
        };
        let c = s.kfgins_config(Path::new("s.yaml"), &d).unwrap();
        assert!(!c.init_state_given);
        assert_eq!(c.imu_rate_hz, 200.0);
        assert_eq!(c.start_sow, 100.0);
        // 2 deg/h bias instability → rad/s.
        assert!((c.noise.gyro_bias_sd.x - 2.0 * DEG / 3600.0).abs() < 1e-18);
        // Initial gyro bias σ: turn-on 10 deg/h with 2 deg/h in-run.
        assert!((c.init_std.gyro_bias.x - 104f64.sqrt() * DEG / 3600.0).abs() < 1e-15);
    }
}
