//! Time synchronization: raw logger records (`rig-log v1`) to GPS time.
//!
//! Streaming-first: [`SyncEngine::push`] takes records in arrival order and
//! returns GPS-stamped IMU samples and GNSS fixes, immediately in causal
//! (real-time) mode, after a bounded lookahead in post-processing mode;
//! [`SyncEngine::finish`] flushes and returns the [`SyncReport`].
//!
//! * Hardware sync (seed 001 §2.1, seed 002): the local counter is
//!   unwrapped (`unwrap`), each 1PPS edge labelled with its GPS second
//!   from the GNSS messages, and a robust windowed regression maps the
//!   counter to GPS time ([`clock`]), with holdover and relock.
//! * Software sync (seed 001 §2.2): lower envelopes of receive times
//!   ([`swsync`], [`fit::EnvelopeFit`]).
//! * IMU timing ([`imu`]): lost/duplicated samples, samples per second,
//!   true rate, rate → increment conversion; the output delay T_c of an
//!   IMU without sync pin is subtracted (seed 000).

#![warn(missing_docs)]

pub mod clock;
pub mod engine;
pub mod file;
pub mod fit;
pub mod imu;
pub mod report;
pub mod sampleclock;
pub mod swsync;
pub(crate) mod unwrap;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod testsim;

pub use clock::{LockState, Oscillator};
pub use engine::{SyncConfig, SyncEngine, SyncMode, SyncOutput};
pub use imu::{IncrementBuilder, RateRule};
pub use report::SyncReport;
pub use swsync::SwConfig;
