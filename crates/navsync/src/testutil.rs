//! Analytic motions with exact IMU increments, for tests of the core.
//!
//! A vehicle at rest on the ellipsoid, level, turning about the down axis
//! at a constant rate r: C_b^n(t) = R_z(ψ0 + r t), so ω_ib^b(t) =
//! C_n^b(t) ω_ie^n + [0, 0, r] and f^b = −C_n^b g^n = [0, 0, −g]. The
//! increments over an interval have closed forms (integrals of sin/cos).

use nalgebra::Vector3;

use crate::attitude::Euler;
use crate::earth::{Geodetic, gravity, omega_ie_n};
use crate::ins::{ImuSample, NavState};
use crate::time::GpsTime;

/// A level vehicle at rest turning about the down axis at `rate_rad_s`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TurningAtRest {
    pub pos: Geodetic,
    pub(crate) yaw0_rad: f64,
    pub(crate) rate_rad_s: f64,
    pub t0: GpsTime,
}

impl TurningAtRest {
    /// The true state at `t`.
    pub(crate) fn state(&self, t: GpsTime) -> NavState {
        let yaw = self.yaw0_rad + self.rate_rad_s * t.seconds_since(self.t0);
        NavState::new(t, self.pos, Vector3::zeros(), &Euler::new(0.0, 0.0, yaw))
    }

    /// Exact increments over (t_a, t_b].
    pub(crate) fn sample(&self, ta: GpsTime, tb: GpsTime) -> ImuSample {
        let (s, c) = self.pos.lat_rad.sin_cos();
        let w = omega_ie_n(s, c);
        let g = gravity(s, self.pos.h_m);
        let dt = tb.seconds_since(ta);
        let y0 = self.yaw0_rad + self.rate_rad_s * ta.seconds_since(self.t0);
        let y1 = y0 + self.rate_rad_s * dt;
        let r = self.rate_rad_s;
        // ∫ R_z(ψ)ᵀ [w_n, 0, w_d] dt = [w_n ∫cosψ, −w_n ∫sinψ, w_d dt]
        let (int_cos, int_sin) = if r.abs() > 1e-12 {
            ((y1.sin() - y0.sin()) / r, (y0.cos() - y1.cos()) / r)
        } else {
            (y0.cos() * dt, y0.sin() * dt)
        };
        ImuSample {
            time: tb,
            dtheta: Vector3::new(w.x * int_cos, -w.x * int_sin, w.z * dt + r * dt),
            dvel: Vector3::new(0.0, 0.0, -g * dt),
            odo_speed: None,
        }
    }
}

/// The simulator's random streams (`navsync_sim::rng`), for tests of the
/// core: the same generator and seeding, so the tests draw the same data
/// as when the simulator lived in the core (rand is a dev-dependency).
pub(crate) mod rng {
    use rand::RngExt;
    use rand_distr::StandardNormal;

    /// PCG-64 MCG, as the simulator's `SimRng`.
    pub(crate) type SimRng = rand_pcg::Pcg64Mcg;

    fn splitmix64(mut z: u64) -> u64 {
        z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn fnv1a(name: &str) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in name.bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        h
    }

    /// The random stream of source `source` in a run with seed `seed`.
    pub(crate) fn stream(seed: u64, source: &str) -> SimRng {
        let lo = splitmix64(seed ^ fnv1a(source));
        let hi = splitmix64(lo ^ 0x5851_f42d_4c95_7f2d);
        let state = ((hi as u128) << 64) | lo as u128;
        SimRng::new(state | 1)
    }

    /// A standard normal draw.
    pub(crate) fn normal(rng: &mut SimRng) -> f64 {
        rng.sample(StandardNormal)
    }

    /// A uniform draw in [0, 1).
    pub(crate) fn uniform(rng: &mut SimRng) -> f64 {
        rng.random::<f64>()
    }

    /// A uniform draw in [lo, hi).
    pub(crate) fn uniform_in(rng: &mut SimRng, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * uniform(rng)
    }
}

/// The synthetic IMU of `navsync_sim::synthetic` (the same signal and
/// draws), for the quality-check tests: a static start, then gentle
/// land-vehicle-like motion, with ADIS16465-class white noise (ARW 0.15
/// deg/√h, VRW 0.04 m/s/√h) and constant biases.
pub(crate) struct SyntheticImu {
    rng: rand_pcg::Pcg64,
    dt_ns: i64,
    t0_ns: i64,
    k: i64,
    gyro_sd: f64,
    accel_sd: f64,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    static_s: f64,
}

impl SyntheticImu {
    /// `rate_hz` samples from GPS time `t0_ns`, static for `static_s` s.
    pub(crate) fn new(rate_hz: f64, t0_ns: i64, static_s: f64, seed: u64) -> Self {
        use rand::SeedableRng;
        let dt_ns = crate::imu::period_ns(rate_hz);
        let rate = 1e9 / dt_ns as f64;
        SyntheticImu {
            rng: rand_pcg::Pcg64::seed_from_u64(seed),
            dt_ns,
            t0_ns,
            k: 0,
            gyro_sd: 0.15f64.to_radians() / 60.0 * rate.sqrt(),
            accel_sd: 0.04 / 60.0 * rate.sqrt(),
            gyro_bias: Vector3::new(3e-5, -2e-5, 1e-5),
            accel_bias: Vector3::new(0.002, -0.001, 0.003),
            static_s,
        }
    }

    fn truth(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        use std::f64::consts::PI;
        let g = 9.7936;
        let m = t - self.static_s;
        if m <= 0.0 {
            return (Vector3::zeros(), Vector3::new(0.0, 0.0, -g));
        }
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
    pub(crate) fn next_rate(&mut self) -> crate::imu::RateSample {
        use rand::RngExt;
        let t_rel = (self.k * self.dt_ns) as f64 * 1e-9;
        let (w, f) = self.truth(t_rel);
        let mut n = [0.0; 6];
        for x in n.iter_mut() {
            *x = self.rng.sample::<f64, _>(rand_distr::StandardNormal);
        }
        let s = crate::imu::RateSample {
            time: GpsTime::from_ns(self.t0_ns + self.k * self.dt_ns),
            gyro: w + self.gyro_bias + Vector3::new(n[0], n[1], n[2]) * self.gyro_sd,
            accel: f + self.accel_bias + Vector3::new(n[3], n[4], n[5]) * self.accel_sd,
        };
        self.k += 1;
        s
    }
}
