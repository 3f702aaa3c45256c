//! The virtual rig: trajectories, exact truth, IMU, GNSS and clock models,
//! and the raw logs a real rig would record (`navsync simulate`).
//!
//! Library use: [`Scenario`] (what to simulate) → [`Simulation::new`] →
//! [`Simulation::run`] (writes the files); or the streaming pieces:
//! [`TruthGenerator`] (exact truth and increments at any times),
//! [`ImuSensor`] (IMU errors and internal chain), [`gnss::GnssSim`],
//! [`clock`] (oscillators, counters), [`rig`] (PPS, serial links).

pub mod clock;
pub mod fitted;
pub mod gnss;
pub mod imu;
pub mod rig;
pub mod rng;
pub mod run;
pub mod scenario;
pub mod speed;
pub mod trajectory;
pub mod truth;

pub use imu::{ImuSensor, ImuSpec};
pub use run::{SimReport, Simulation};
pub use scenario::Scenario;
pub use trajectory::{Segment, Trajectory, TrajectoryOptions};
pub use truth::{TruthGenerator, TruthPoint};
