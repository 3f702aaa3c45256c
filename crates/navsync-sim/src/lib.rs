//! The navsync simulator and the studies on it.
//!
//! The virtual rig: trajectories, exact truth, IMU, GNSS and clock models,
//! and the raw logs a real rig would record (`navsync simulate`).
//! Library use: [`Scenario`] (what to simulate) → [`Simulation::new`] →
//! [`Simulation::run`] (writes the files); or the streaming pieces:
//! [`TruthGenerator`] (exact truth and increments at any times),
//! [`ImuSensor`] (IMU errors and internal chain), [`gnss::GnssSim`],
//! [`clock`] (oscillators, counters), [`rig`] (PPS, serial links).
//!
//! - [`trajectory`], [`fitted`]: vehicle motion (segments, a fit to a
//!   reference solution); [`truth`]: exact states and increments;
//! - [`imu`], [`gnss`], [`clock`], [`rig`]: the sensor and rig models
//!   (the IMU presets' datasheet figures come from the core,
//!   `navsync::imu::spec`); [`rng`]: one random stream per error source;
//! - [`faults`]: GNSS receiver faults injected into any GNSS file, labelled;
//! - [`scenario`], [`run`]: what to simulate and the run that writes the
//!   files; [`speed`]: an odometer file from a truth file;
//!   [`synthetic`]: deterministic IMU test signals (benchmarks);
//!
//! and the studies that drive the library with it:
//!
//! - [`chain`]: simulate → sync → fuse → eval on one scenario (the demo's
//!   and Monte Carlo's run).
//! - [`montecarlo`]: the chain over many seeds in parallel: accuracy,
//!   sync and time-offset errors, NEES consistency.
//! - [`rate_study`]: GNSS-outage drift against IMU rate (Tang, Zhang & Niu
//!   2022 §1.3.3).

// Index loops are the clearest form for the small matrix kernels here.
#![allow(clippy::needless_range_loop)]

pub mod clock;
pub mod faults;
pub mod fitted;
pub mod gnss;
pub mod imu;
pub mod rig;
pub mod rng;
pub mod run;
pub mod scenario;
pub mod speed;
pub mod synthetic;
pub mod trajectory;
pub mod truth;

pub mod chain;
pub mod montecarlo;
pub mod rate_study;

pub use imu::{ImuSensor, ImuSpec};
pub use run::{SimReport, Simulation};
pub use scenario::Scenario;
pub use trajectory::{Segment, Trajectory, TrajectoryOptions};
pub use truth::{TruthGenerator, TruthPoint};
