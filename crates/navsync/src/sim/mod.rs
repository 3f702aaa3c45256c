//! The virtual rig: trajectories, exact truth, IMU, GNSS and clock models,
//! and the raw logs a real rig would record (`navsync simulate`).

pub mod clock;
pub mod imu;
pub mod rng;
pub mod trajectory;
pub mod truth;

pub use imu::{ImuSensor, ImuSpec};
pub use trajectory::{Segment, Trajectory, TrajectoryOptions};
pub use truth::{TruthGenerator, TruthPoint};
