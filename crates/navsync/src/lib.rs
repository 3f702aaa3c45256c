//! navsync: GNSS/INS integrated navigation in which time synchronization is
//! first-class.
//!
//! The library is streaming-first: every stage takes one sample at a time
//! and returns what it can. [`navigator::Navigator`] composes them: raw
//! rig-log records or synchronized IMU samples and GNSS fixes go in, fused
//! solutions come out through a [`pipeline::NavSink`]; batch processing of
//! files ([`pipeline::run`]) and `navsync live` are loops over it. See the
//! crate's `examples/` (`stream_rig_log`, `batch`).
//!
//! Conventions: SI units inside; body frame FRD, navigation frame NED;
//! `q_nb`/`c_nb` rotate body to navigation; GPS time as integer nanoseconds
//! ([`time::GpsTime`]).

#![warn(missing_docs)]
// Index loops are the clearest form for the small matrix kernels here.
#![allow(clippy::needless_range_loop)]

pub mod align;
pub mod allan;
pub mod array;
pub mod attitude;
pub mod clock_search;
pub mod earth;
pub mod error;
pub mod eval;
pub mod filter;
pub mod fusion;
pub mod imu;
pub mod ins;
pub mod interp;
pub mod io;
pub mod mount_search;
pub mod navigator;
// Number formatting without allocation (under time and io::text).
mod numfmt;
pub(crate) mod offset_search;
pub mod pipeline;
pub mod probe;
pub mod reduced;
mod rejudge;
pub mod sensor;
pub mod smoother;
pub mod stage;
pub mod stats;
#[doc(hidden)]
pub mod testfiles;
#[cfg(test)]
mod testutil;
pub mod time;
pub mod timing;
pub mod types;
// Enums written as words, one table both ways.
mod words;

pub use error::{Diagnostic, Diagnostics, Error, Result};
pub use time::{GpsTime, OutageWindow};
