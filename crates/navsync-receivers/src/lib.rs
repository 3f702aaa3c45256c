//! navsync-receivers: what real receivers and loggers emit, read into
//! navsync's types.
//!
//! - [`stream`]: incremental reader of mixed NMEA 0183 + u-blox UBX byte
//!   streams (push bytes, get messages; every corrupt or unknown frame
//!   reported with its offset).
//! - [`ubx`], [`nmea`]: the messages (decoders and encoders); [`rtcm3`]:
//!   RTCM 3 framing (frames recognised and skipped).
//! - [`gnsstime`]: UTC ↔ GPS time with leap seconds.
//! - [`geoid`]: EGM96 geoid separation for GGA without one.
//! - [`fixes`]: GNSS fixes at their time of validity (NAV-PVT, NMEA epochs).
//! - [`imu`]: ESF-MEAS/ESF-RAW and rate-form IMU data → increments.
//! - [`marks`]: TIM-TM2 event stamps and TIM-TP qErr PPS correction.
//! - [`ros2`]: ROS 2 bags (MCAP, CDR): `Imu`, `NavSatFix`, velocities.
//! - [`ulog`]: PX4 ULog flight logs: IMU, GPS, the autopilot's estimate.
//! - [`ros1`]: ROS 1 bags (v2.0; bz2, lz4 chunks): the same and odometry;
//!   [`rosmsg`]: the messages both share and what becomes of them.
//! - [`dataflash`]: ArduPilot DataFlash `.BIN` logs; [`autopilot`]: an
//!   autopilot log → a rig log for software synchronization.
//! - [`convert`]: file conversion to KF-GINS files and rig-logs.
//!
//! Kept out of the core `navsync` crate so that its receiver dependencies
//! (`nmea`, later serial and PPS) stay optional for library users.

pub mod autopilot;
pub mod convert;
pub mod dataflash;
pub mod detect;
pub mod fixes;
pub mod geoid;
pub mod gnsstime;
pub mod imu;
pub mod marks;
pub mod nmea;
pub mod ros1;
pub mod ros2;
pub mod rosmsg;
pub mod rtcm3;
pub mod stream;
#[cfg(feature = "test-bags")]
pub mod testbag;
#[cfg(feature = "test-bags")]
pub mod testbag1;
#[cfg(feature = "test-bags")]
pub mod testdataflash;
#[cfg(feature = "test-bags")]
pub mod testulog;
pub mod ubx;
pub mod ubx_dr;
pub mod ulog;

pub use stream::{Event, EventKind, StreamReader};
