//! Deterministic synthetic IMU signals for tests and benchmarks: a static
//! start, then gentle land-vehicle-like motion, with white noise of a given
//! angle/velocity random walk and constant biases. Not a navigation
//! simulator (that is `sim`): the signals need not be consistent with a
//! trajectory, only realistic in level, noise and spectrum for quality
//! checks.

use std::f64::consts::PI;

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64;

use navsync::imu::{RateSample, period_ns};
use navsync::time::GpsTime;

/// A synthetic IMU (see the module docs).
#[derive(Clone, Debug)]
pub struct SyntheticImu {
    rng: Pcg64,
    dt_ns: i64,
    t0_ns: i64,
    k: i64,
    /// Per-sample white-noise σ (rad/s, m/s²): random walk × √rate.
    gyro_sd: f64,
    accel_sd: f64,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    static_s: f64,
}

impl SyntheticImu {
    /// `rate_hz` samples from GPS time `t0_ns`; ADIS16465-class noise
    /// (ARW 0.15 deg/√h, VRW 0.04 m/s/√h), static for `static_s` seconds.
    pub fn new(rate_hz: f64, t0_ns: i64, static_s: f64, seed: u64) -> Self {
        let mut s = SyntheticImu {
            rng: Pcg64::seed_from_u64(seed),
            dt_ns: period_ns(rate_hz),
            t0_ns,
            k: 0,
            gyro_sd: 0.0,
            accel_sd: 0.0,
            gyro_bias: Vector3::new(3e-5, -2e-5, 1e-5),
            accel_bias: Vector3::new(0.002, -0.001, 0.003),
            static_s,
        };
        s.set_noise(0.15, 0.04);
        s
    }

    /// White noise from the angle random walk (deg/√h) and velocity random
    /// walk (m/s/√h): σ per sample = random walk [unit/√s] × √rate.
    pub fn set_noise(&mut self, arw_deg_rt_h: f64, vrw_mps_rt_h: f64) {
        let rate = 1e9 / self.dt_ns as f64;
        self.gyro_sd = arw_deg_rt_h.to_radians() / 60.0 * rate.sqrt();
        self.accel_sd = vrw_mps_rt_h / 60.0 * rate.sqrt();
    }

    /// Nominal interval (ns).
    pub fn dt_ns(&self) -> i64 {
        self.dt_ns
    }

    /// The noise-free signal at `t` seconds after the start.
    pub fn truth(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let g = 9.7936;
        let m = t - self.static_s;
        if m <= 0.0 {
            return (Vector3::zeros(), Vector3::new(0.0, 0.0, -g));
        }
        // Gentle turns, speed changes and body vibration of a car.
        let ramp = (m / 5.0).min(1.0);
        let yaw_rate = 0.15 * (2.0 * PI * 0.02 * m).sin() * ramp;
        let long_acc = 1.2 * (2.0 * PI * 0.01 * m).sin() * ramp;
        let vib = 0.05 * (2.0 * PI * 13.0 * m).sin() * ramp;
        (
            Vector3::new(0.3 * vib, 0.2 * vib, yaw_rate),
            Vector3::new(long_acc, 8.0 * yaw_rate, -g + 5.0 * vib),
        )
    }

    /// The next rate sample.
    pub fn next_rate(&mut self) -> RateSample {
        let t_rel = (self.k * self.dt_ns) as f64 * 1e-9;
        let (w, f) = self.truth(t_rel);
        let mut n = [0.0; 6];
        for x in n.iter_mut() {
            *x = self.rng.sample::<f64, _>(StandardNormal);
        }
        let s = RateSample {
            time: GpsTime::from_ns(self.t0_ns + self.k * self.dt_ns),
            gyro: w + self.gyro_bias + Vector3::new(n[0], n[1], n[2]) * self.gyro_sd,
            accel: f + self.accel_bias + Vector3::new(n[3], n[4], n[5]) * self.accel_sd,
        };
        self.k += 1;
        s
    }
}

/// Writes `duration_s` of synthetic increments (KF-GINS format, full
/// precision) at `rate_hz` to `path`, starting at GPS sow 100000; returns
/// the number of records. For benchmarks and examples.
pub fn write_increment_log(
    path: &std::path::Path,
    duration_s: f64,
    rate_hz: f64,
    static_s: f64,
    seed: u64,
) -> Result<usize, navsync::error::Error> {
    use navsync::imu::convert::{RateRule, RateToIncrement};
    use navsync::io::kfgins::{TextWriter, format_imu_line};
    let mut imu = SyntheticImu::new(rate_hz, 100_000 * navsync::time::NS_PER_S, static_s, seed);
    let mut conv = RateToIncrement::new(RateRule::Trapezoid);
    let mut out = TextWriter::create(path)?;
    let mut buf = Vec::with_capacity(1 << 20);
    let n = (duration_s * rate_hz).round() as usize;
    let mut written = 0;
    for _ in 0..=n {
        if let Some(inc) = conv.push(&imu.next_rate()) {
            format_imu_line(&mut buf, &inc);
            written += 1;
            if buf.len() > (1 << 20) - 512 {
                out.write(&buf)?;
                buf.clear();
            }
        }
    }
    out.write(&buf)?;
    out.finish()?;
    Ok(written)
}
