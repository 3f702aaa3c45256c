//! IMU acquisition quality (seed 001 §1): rate→increment conversion,
//! averaging/accumulating decimation, low-pass filter delay, and the
//! quality check of a recorded IMU log against the rules of seed 001 §1.5.
//!
//! Conventions (FORMATS.md §1, seed 001 §1.1): an increment sample
//! ([`crate::ins::ImuSample`]) holds the integral of the angular rate and of
//! the specific force over the interval `(t_{k−1}, t_k]` and is stamped at
//! the end of that interval, `t_k`. A rate sample ([`RateSample`]) holds
//! the rates at (or averaged over the interval ending at) its time stamp.
//!
//! Everything is streaming: push a sample, get what it completes.
//!
//! - [`convert`]: [`RateToIncrement`] (trapezoid of consecutive rates times
//!   the interval, seed 001 §1.1).
//! - [`decimate`]: [`DecRate`] (ADIS16465 `DEC_RATE`: output rate = input
//!   rate / (DEC_RATE + 1), seed 001 §1.3.1), [`IncrementDecimator`]
//!   (accumulation, or naive point decimation for comparison),
//!   [`RateDecimator`] (averaging or point), [`Conditioner`] (a log's
//!   samples in, KF-GINS increments out).
//! - [`lowpass`]: FIR/IIR descriptions, their group delay, and its
//!   compensation in the time stamps (seed 001 §1.4).
//! - [`log`]: a raw reader for `kf-gins` and `rate-csv` logs that keeps
//!   every record (bad ones reported with file and line).
//! - [`quality`]: the streaming log analysis and the seed 001 §1.5 verdict.
//! - The rate study (the lowest IMU rate that costs no accuracy, by
//!   simulated GNSS outages, seed 001 §1.3.3) is in `navsync-sim`.
//! - [`spec`]: datasheet figures of gyro and accelerometer triads and of
//!   the named IMU presets (the sensor sheet's and the simulator's).
#![warn(missing_docs)]

pub mod convert;
pub mod decimate;
pub mod log;
pub mod lowpass;
pub mod quality;
pub mod spec;

use nalgebra::Vector3;

use crate::time::GpsTime;

pub use convert::{RateRule, RateToIncrement};
pub use decimate::{
    Conditioner, ConditionerConfig, DecRate, DecimationMethod, IncrementDecimator, RateDecimator,
};
pub use log::{ImuLogFormat, ImuLogReader};
pub use lowpass::LowPassFilter;
pub use quality::{QualityAnalyzer, QualityConfig, QualityReport, Status, check_file};

/// Angular rate and specific force at one instant (or averaged over the
/// interval ending at `time`, see [`RateRule`]), body frame FRD.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RateSample {
    /// Time stamp: the instant of the rates, or the end of the interval
    /// they were averaged over.
    pub time: GpsTime,
    /// Angular rate (rad/s).
    pub gyro: Vector3<f64>,
    /// Specific force (m/s²).
    pub accel: Vector3<f64>,
}

/// Nominal interval (ns) of a rate (Hz), rounded to the nanosecond.
pub fn period_ns(rate_hz: f64) -> i64 {
    (1e9 / rate_hz).round() as i64
}
