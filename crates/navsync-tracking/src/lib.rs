//! Carrier tracking with inertial Doppler aiding and an adaptive loop
//! bandwidth (seed 003: Sun, Petovello & Cannon, "Use of a reduced IMU to
//! aid a GPS receiver with adaptive tracking loops for land vehicle
//! navigation", GPS Solutions 14:319, 2010).
//!
//! - [`loop_filter`]: first- to third-order loop filters (Kaplan &
//!   Hegarty Table 5.6, bilinear integrators) whose state is frequency and
//!   frequency rate, so the bandwidth can change without jumps.
//! - [`discriminator`]: Costas and PLL discriminators, phase lock
//!   indicator, C/N0 estimator.
//! - [`oscillator`]: h0/h−1/h−2 clock model, Allan deviation, phase noise.
//! - [`dynamics`]: trajectories (trait) and line-of-sight dynamics.
//! - [`aiding`]: Doppler-aiding error processes (random ramp, held
//!   Gauss-Markov, schedules, from a filter covariance).
//! - [`design`]: the phase-error budget (thermal, oscillator, aiding,
//!   dynamics) and the adaptive bandwidth rule.
//! - [`channel`]: the receiver side of a tracking channel (streaming).
//! - [`sim`]: the correlator-level simulator, C/N0 sweeps and thresholds.

// Index loops are the clearest form for the small kernels here.
#![allow(clippy::needless_range_loop)]

pub mod aiding;
pub mod channel;
pub mod design;
pub mod discriminator;
pub mod dynamics;
pub mod loop_filter;
pub mod oscillator;
pub mod scenario;
pub mod sim;

/// GPS L1 carrier frequency (Hz).
pub(crate) const GPS_L1_HZ: f64 = 1_575.42e6;
/// Speed of light (m/s), IS-GPS-200.
pub(crate) const SPEED_OF_LIGHT: f64 = 299_792_458.0;
/// L1 carrier cycles per C/A chip (1575.42 MHz / 1.023 MHz).
pub(crate) const CARRIER_CYCLES_PER_CA_CHIP: f64 = 1540.0;
