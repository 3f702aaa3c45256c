//! The shared data types at the bottom of the core: what the file formats
//! (`io`), synchronization, the mechanization and the filter pass between
//! them: an IMU record ([`ImuSample`]), the navigation state
//! ([`NavState`]), a GNSS fix ([`GnssFix`]), the IMU error parameters
//! ([`ImuErrors`]), the IMU noise model ([`ImuNoise`]) and the initial σ of
//! the error state ([`InitialStd`]). Plain data: their algorithms stay with
//! their users (`ImuErrors::compensate` and the mechanization in
//! [`crate::ins`], the observations of a fix in [`crate::filter::gnss`]);
//! the old paths (`ins::ImuSample`, `ins::NavState`,
//! `filter::gnss::GnssFix`, `filter::ImuNoise`, …) re-export them.

#![warn(missing_docs)]

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::attitude::{Euler, euler_to_quat, quat_to_euler};
use crate::earth::Geodetic;
use crate::time::GpsTime;

/// One IMU record: the increments over the interval that ends at `time`
/// (FORMATS.md §1: "each row holds the increments over the interval that
/// ends at `sow`").
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ImuSample {
    /// End of the interval (GPS time).
    pub time: GpsTime,
    /// Angle increment in the body frame (rad).
    pub dtheta: Vector3<f64>,
    /// Velocity increment (integral of specific force) in the body frame (m/s).
    pub dvel: Vector3<f64>,
    /// Odometer speed (m/s) when the IMU file carries an 8th column.
    pub odo_speed: Option<f64>,
}

/// The navigation state of the IMU centre.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct NavState {
    /// GPS time of the state.
    pub time: GpsTime,
    /// Geodetic position of the IMU centre (latitude, longitude, ellipsoidal
    /// height).
    pub pos: Geodetic,
    /// Ground velocity in NED (m/s).
    pub vel: Vector3<f64>,
    /// Attitude, body (FRD) to navigation (NED).
    pub q_nb: UnitQuaternion<f64>,
}

impl NavState {
    /// A state from position, velocity and ZYX Euler angles.
    pub fn new(time: GpsTime, pos: Geodetic, vel: Vector3<f64>, att: &Euler) -> Self {
        NavState {
            time,
            pos,
            vel,
            q_nb: euler_to_quat(att),
        }
    }

    /// ZYX Euler angles of the attitude.
    pub fn euler(&self) -> Euler {
        quat_to_euler(&self.q_nb)
    }

    /// C_b^n.
    pub fn c_nb(&self) -> Matrix3<f64> {
        *self.q_nb.to_rotation_matrix().matrix()
    }
}

/// A GNSS fix of the antenna: position (and optionally velocity) valid at
/// `time`, with standard deviations in NED.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GnssFix {
    /// Time of validity (GPS time).
    pub time: GpsTime,
    /// Geodetic position of the antenna phase centre.
    pub pos: Geodetic,
    /// Position standard deviations N, E, D (m).
    pub pos_sd: Vector3<f64>,
    /// NED velocity (m/s), when the receiver gave it.
    pub vel: Option<Vector3<f64>>,
    /// Velocity standard deviations N, E, D (m/s).
    pub vel_sd: Option<Vector3<f64>>,
}

/// IMU biases, scale factors and axis misalignments (SI: rad/s, m/s²,
/// dimensionless, rad). Measurement model (KF-GINS algorithm doc, IMU
/// error compensation, extended by the off-diagonal terms of the usual
/// 12-parameter triad model, e.g. Groves 2013 §4.4.2):
/// Δθ̃ = (I + diag(s_g) + M_g) Δθ + b_g Δt, likewise for Δv, with
/// M = [[0, m₀, m₁], [m₂, 0, m₃], [m₄, m₅, 0]].
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct ImuErrors {
    /// Gyro bias b_g (rad/s), body frame.
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer bias b_a (m/s²), body frame.
    pub accel_bias: Vector3<f64>,
    /// Gyro scale factors s_g (dimensionless), per body axis.
    pub gyro_scale: Vector3<f64>,
    /// Accelerometer scale factors s_a (dimensionless), per body axis.
    pub accel_scale: Vector3<f64>,
    /// Off-diagonal terms m₀…m₅ of M_g (rad); zero unless estimated.
    pub gyro_misalign: [f64; 6],
    /// Off-diagonal terms of M_a (rad).
    pub accel_misalign: [f64; 6],
}

/// Continuous-time IMU noise model in SI units (KF-GINS doc §3.4, q(t)):
/// white noise on rates (ARW, VRW) and first-order Gauss-Markov biases and
/// scale factors with standard deviations `*_sd` and correlation time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuNoise {
    /// Angle random walk (rad/√s).
    pub arw: Vector3<f64>,
    /// Velocity random walk (m/s/√s).
    pub vrw: Vector3<f64>,
    /// Gyro bias instability σ (rad/s).
    pub gyro_bias_sd: Vector3<f64>,
    /// Accelerometer bias instability σ (m/s²).
    pub accel_bias_sd: Vector3<f64>,
    /// Gyro scale-factor σ (dimensionless).
    pub gyro_scale_sd: Vector3<f64>,
    /// Accelerometer scale-factor σ (dimensionless).
    pub accel_scale_sd: Vector3<f64>,
    /// Gauss-Markov correlation time (s).
    pub corr_time_s: f64,
}

/// Initial standard deviations of the error state (SI units; attitude in
/// rad about N, E, D).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialStd {
    /// Position σ N, E, D (m).
    pub pos: Vector3<f64>,
    /// Velocity σ N, E, D (m/s).
    pub vel: Vector3<f64>,
    /// Attitude σ about N, E, D (rad).
    pub att: Vector3<f64>,
    /// Gyro bias σ (rad/s).
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer bias σ (m/s²).
    pub accel_bias: Vector3<f64>,
    /// Gyro scale-factor σ (dimensionless).
    pub gyro_scale: Vector3<f64>,
    /// Accelerometer scale-factor σ (dimensionless).
    pub accel_scale: Vector3<f64>,
}
