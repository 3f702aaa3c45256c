//! IMU datasheet figures: the gyro and accelerometer triads' errors in
//! datasheet units ([`GyroSpec`], [`AccelSpec`]) and those of the named
//! IMU presets ([`preset_triads`]). The sensor sheet fills what a user
//! leaves out from them ([`crate::sensor`]); the simulator
//! (`navsync-sim`) builds its IMU models on them (its `ImuSpec` adds the
//! internal chain and the sample clock).
#![warn(missing_docs)]

use serde::{Deserialize, Serialize};

/// Standard gravity (m/s² per g).
pub const G0: f64 = 9.806_65;

/// Correlation time of the presets' bias drift (s) (a first-order
/// Gauss–Markov model's, as KF-GINS's `corrtime`).
pub const PRESET_BIAS_CORR_TIME_S: f64 = 3600.0;

/// Gyro triad errors in datasheet units (1σ values; 0 switches a term off).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GyroSpec {
    /// Angle random walk (deg/√h): white rate noise density.
    pub arw_deg_sqrt_h: f64,
    /// In-run bias instability (deg/h), the flicker floor of the Allan
    /// deviation (IEEE Std 952); a bias drift, not a constant.
    pub bias_instability_deg_h: f64,
    /// Turn-on (run-to-run) bias σ (deg/h), constant within a run.
    pub turn_on_bias_deg_h: f64,
    /// Scale-factor error σ (ppm).
    pub scale_ppm: f64,
    /// Axis misalignment σ (deg), off-diagonal terms.
    pub misalignment_deg: f64,
    /// Saturation (deg/s), 0 = none.
    pub range_deg_s: f64,
    /// Quantization step of the rate output (deg/s), 0 = none.
    pub rate_lsb_deg_s: f64,
    /// Quantization step of the angle increment (deg), 0 = none.
    pub delta_lsb_deg: f64,
}

impl Default for GyroSpec {
    fn default() -> Self {
        GyroSpec {
            arw_deg_sqrt_h: 0.0,
            bias_instability_deg_h: 0.0,
            turn_on_bias_deg_h: 0.0,
            scale_ppm: 0.0,
            misalignment_deg: 0.0,
            range_deg_s: 0.0,
            rate_lsb_deg_s: 0.0,
            delta_lsb_deg: 0.0,
        }
    }
}

/// Accelerometer triad errors in datasheet units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AccelSpec {
    /// Velocity random walk (m/s/√h): white specific-force noise density.
    pub vrw_mps_sqrt_h: f64,
    /// In-run bias instability (mGal; 1 mGal = 1e-5 m/s² ≈ 1 µg), the
    /// flicker floor of the Allan deviation (IEEE Std 952).
    pub bias_instability_mgal: f64,
    /// Turn-on (run-to-run) bias σ (mGal), constant within a run.
    pub turn_on_bias_mgal: f64,
    /// Scale-factor error σ (ppm).
    pub scale_ppm: f64,
    /// Axis misalignment σ (deg), off-diagonal terms; levelling takes it
    /// for tilt.
    pub misalignment_deg: f64,
    /// Saturation (g), 0 = none.
    pub range_g: f64,
    /// Quantization step of the specific-force output (m/s²), 0 = none.
    pub rate_lsb_mps2: f64,
    /// Quantization step of the velocity increment (m/s), 0 = none.
    pub delta_lsb_mps: f64,
}

impl Default for AccelSpec {
    fn default() -> Self {
        AccelSpec {
            vrw_mps_sqrt_h: 0.0,
            bias_instability_mgal: 0.0,
            turn_on_bias_mgal: 0.0,
            scale_ppm: 0.0,
            misalignment_deg: 0.0,
            range_g: 0.0,
            rate_lsb_mps2: 0.0,
            delta_lsb_mps: 0.0,
        }
    }
}

/// The gyro and accelerometer figures of a named preset (`None` for an
/// unknown name):
/// - `nav`: navigation grade, Leador-A15 class (i2Nav reference IMU):
///   ARW 0.003°/√h, gyro bias instability 0.027°/h, VRW 0.03 m/s/√h,
///   accelerometer bias instability 15 mGal;
/// - `tactical`: Honeywell HG1700 class: ARW 0.125°/√h, 1°/h, VRW 0.04
///   m/s/√h (65 µg/√Hz), 50 mGal, 1 mg turn-on;
/// - `adis16465`: ADIS16465-1 datasheet: ARW 0.15°/√h, 2°/h in-run,
///   ±0.05° misalignment, ±125°/s, ±8 g, 3.6 µg in-run; VRW 0.04 m/s/√h
///   and turn-on/scale as the shared reference simulator's `adis16465`
///   grade;
/// - `icm20602`: InvenSense ICM-20602 datasheet: gyro noise 0.004°/s/√Hz
///   (ARW 0.24°/√h), accel 100 µg/√Hz (VRW 0.059 m/s/√h), ±250°/s and
///   ±4 g at 16 bits (LSB 1/131 °/s, 1/8192 g), ±1 % sensitivity, ±2 %
///   cross-axis; bias instability 10°/h (i2Nav awesome-gins-datasets);
/// - `perfect`: no errors.
pub fn preset_triads(name: &str) -> Option<(GyroSpec, AccelSpec)> {
    Some(match name {
        "nav" => (
            GyroSpec {
                arw_deg_sqrt_h: 0.003,
                bias_instability_deg_h: 0.027,
                turn_on_bias_deg_h: 0.02,
                scale_ppm: 10.0,
                misalignment_deg: 0.002,
                range_deg_s: 400.0,
                ..Default::default()
            },
            AccelSpec {
                vrw_mps_sqrt_h: 0.03,
                bias_instability_mgal: 15.0,
                turn_on_bias_mgal: 50.0,
                scale_ppm: 20.0,
                misalignment_deg: 0.002,
                range_g: 20.0,
                ..Default::default()
            },
        ),
        "tactical" => (
            GyroSpec {
                arw_deg_sqrt_h: 0.125,
                bias_instability_deg_h: 1.0,
                turn_on_bias_deg_h: 3.0,
                scale_ppm: 150.0,
                misalignment_deg: 0.01,
                range_deg_s: 1000.0,
                ..Default::default()
            },
            AccelSpec {
                vrw_mps_sqrt_h: 0.04,
                bias_instability_mgal: 50.0,
                turn_on_bias_mgal: 1000.0,
                scale_ppm: 300.0,
                misalignment_deg: 0.01,
                range_g: 50.0,
                ..Default::default()
            },
        ),
        "adis16465" => (
            GyroSpec {
                arw_deg_sqrt_h: 0.15,
                bias_instability_deg_h: 2.0,
                turn_on_bias_deg_h: 10.0,
                scale_ppm: 500.0,
                misalignment_deg: 0.05,
                range_deg_s: 125.0,
                // 32-bit outputs: 0.00625°/s/2^16 and 360°/2^31.
                rate_lsb_deg_s: 0.00625 / 65536.0,
                delta_lsb_deg: 360.0 / 2_147_483_648.0,
            },
            AccelSpec {
                vrw_mps_sqrt_h: 0.04,
                bias_instability_mgal: 3.6 * 0.980_665, // 3.6 µg
                turn_on_bias_mgal: 100.0,
                scale_ppm: 500.0,
                misalignment_deg: 0.05,
                range_g: 8.0,
                // 1.25 mg/2^16 and 100 m/s/2^31.
                rate_lsb_mps2: 1.25e-3 * G0 / 65536.0,
                delta_lsb_mps: 100.0 / 2_147_483_648.0,
            },
        ),
        "icm20602" => (
            GyroSpec {
                arw_deg_sqrt_h: 0.24,
                bias_instability_deg_h: 10.0,
                turn_on_bias_deg_h: 360.0,
                scale_ppm: 5000.0,
                misalignment_deg: 0.3,
                range_deg_s: 250.0,
                rate_lsb_deg_s: 1.0 / 131.0,
                ..Default::default()
            },
            AccelSpec {
                vrw_mps_sqrt_h: 0.059,
                bias_instability_mgal: 100.0,
                turn_on_bias_mgal: 3000.0,
                scale_ppm: 5000.0,
                misalignment_deg: 0.3,
                range_g: 4.0,
                rate_lsb_mps2: G0 / 8192.0,
                ..Default::default()
            },
        ),
        "perfect" => (GyroSpec::default(), AccelSpec::default()),
        _ => return None,
    })
}
