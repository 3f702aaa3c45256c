//! Studies that drive the navsync library with its simulator
//! (`navsync::sim`): the whole chain on one scenario, Monte Carlo over
//! seeds, and the IMU rate study. The simulator itself still lives in the
//! core crate (its IMU presets feed the sensor sheet); ARCHITECTURE.md has
//! the plan.
//!
//! - [`chain`]: simulate → sync → fuse → eval on one scenario (the demo's
//!   and Monte Carlo's run).
//! - [`montecarlo`]: the chain over many seeds in parallel: accuracy,
//!   sync and time-offset errors, NEES consistency.
//! - [`rate_study`]: GNSS-outage drift against IMU rate (Tang, Zhang & Niu
//!   2022 §1.3.3).

pub mod chain;
pub mod montecarlo;
pub mod rate_study;
