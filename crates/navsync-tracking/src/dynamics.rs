//! Line-of-sight dynamics for the carrier-tracking simulator: a vehicle
//! trajectory (behind the [`Trajectory`] trait) seen along the direction
//! to one satellite.
//!
//! Implementations: [`StaticTrajectory`], [`LandVehicleProfile`] (a
//! compact, smooth, seeded land-vehicle drive whose jerk stays below 1 g/s)
//! and [`SampledTrajectory`] (any sampled position/velocity track, e.g. a
//! navsync or KF-GINS navigation file or a `navsync_sim` trajectory).

use nalgebra::Vector3;
use rand::RngExt;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

use navsync::earth::{Geodetic, c_ne, geodetic_to_ecef};

/// Standard gravity (m/s²), for jerk limits stated in g/s.
pub const G0: f64 = 9.806_65;

/// Position and its first three derivatives in a local NED frame fixed at
/// the start (m, m/s, m/s², m/s³).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Kinematics {
    pub pos_m: Vector3<f64>,
    pub vel_mps: Vector3<f64>,
    pub(crate) acc_mps2: Vector3<f64>,
    pub(crate) jerk_mps3: Vector3<f64>,
}

/// A receiver trajectory with random access in time (seconds from its
/// start). Values outside `[0, duration_s]` are held at the ends.
pub trait Trajectory: Sync {
    fn kinematics(&self, t_s: f64) -> Kinematics;
    fn duration_s(&self) -> f64;
}

/// A receiver at rest.
#[derive(Copy, Clone, Debug, Default)]
pub struct StaticTrajectory;

impl Trajectory for StaticTrajectory {
    fn kinematics(&self, _t_s: f64) -> Kinematics {
        Kinematics::default()
    }
    fn duration_s(&self) -> f64 {
        f64::INFINITY
    }
}

/// A satellite seen from the receiver: unit vector to it (NED), and the
/// range rate and acceleration its own motion causes (m/s, m/s²).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SatelliteLos {
    pub unit_ned: Vector3<f64>,
    pub(crate) sat_rate_mps: f64,
    pub(crate) sat_accel_mps2: f64,
}

/// Range from the satellite to the receiver and its derivatives.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct LosState {
    pub(crate) range_m: f64,
    pub(crate) rate_mps: f64,
    pub accel_mps2: f64,
    pub(crate) jerk_mps3: f64,
}

impl SatelliteLos {
    /// From elevation and azimuth (rad); typical GPS satellite range rate
    /// and acceleration are up to ±800 m/s and ≈0.1–0.2 m/s².
    pub fn from_elevation_azimuth(
        el_rad: f64,
        az_rad: f64,
        sat_rate_mps: f64,
        sat_accel_mps2: f64,
    ) -> Self {
        SatelliteLos {
            unit_ned: Vector3::new(
                el_rad.cos() * az_rad.cos(),
                el_rad.cos() * az_rad.sin(),
                -el_rad.sin(),
            ),
            sat_rate_mps,
            sat_accel_mps2,
        }
    }

    /// The range state at `t_s` for receiver kinematics `k`: the range
    /// shrinks by u·Δp when the receiver moves towards the satellite.
    pub fn state(&self, t_s: f64, k: &Kinematics) -> LosState {
        let u = &self.unit_ned;
        LosState {
            range_m: self.sat_rate_mps * t_s + 0.5 * self.sat_accel_mps2 * t_s * t_s
                - u.dot(&k.pos_m),
            rate_mps: self.sat_rate_mps + self.sat_accel_mps2 * t_s - u.dot(&k.vel_mps),
            accel_mps2: self.sat_accel_mps2 - u.dot(&k.acc_mps2),
            jerk_mps3: -u.dot(&k.jerk_mps3),
        }
    }
}

/// Largest line-of-sight range rate, acceleration and jerk along a trajectory (scanned
/// every `step_s`), the dynamic-stress inputs of an unaided loop design.
#[derive(Copy, Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DynamicsEnvelope {
    pub(crate) rate_mps: f64,
    pub accel_mps2: f64,
    pub(crate) jerk_mps3: f64,
}

impl DynamicsEnvelope {
    pub fn scan(traj: &dyn Trajectory, los: &SatelliteLos, duration_s: f64, step_s: f64) -> Self {
        let mut env = DynamicsEnvelope::default();
        let n = (duration_s / step_s).ceil() as usize;
        for i in 0..=n {
            let t = (i as f64 * step_s).min(duration_s);
            let s = los.state(t, &traj.kinematics(t));
            env.rate_mps = env.rate_mps.max(s.rate_mps.abs());
            env.accel_mps2 = env.accel_mps2.max(s.accel_mps2.abs());
            env.jerk_mps3 = env.jerk_mps3.max(s.jerk_mps3.abs());
        }
        env
    }
}

/// A raised-cosine trapezoid pulse: rises from 0 to `amp` over `edge_s`,
/// holds for `hold_s`, falls back over `edge_s`. Its largest slope is
/// π·amp/(2·edge_s).
#[derive(Copy, Clone, Debug, PartialEq)]
struct Pulse {
    start_s: f64,
    edge_s: f64,
    hold_s: f64,
    amp: f64,
}

impl Pulse {
    fn end_s(&self) -> f64 {
        self.start_s + 2.0 * self.edge_s + self.hold_s
    }

    /// Value and time derivative at `t`.
    fn eval(&self, t: f64) -> (f64, f64) {
        let u = t - self.start_s;
        let d = self.edge_s;
        let w = std::f64::consts::PI / d;
        if u <= 0.0 || u >= 2.0 * d + self.hold_s {
            (0.0, 0.0)
        } else if u < d {
            (
                0.5 * self.amp * (1.0 - (w * u).cos()),
                0.5 * self.amp * w * (w * u).sin(),
            )
        } else if u <= d + self.hold_s {
            (self.amp, 0.0)
        } else {
            let v = u - d - self.hold_s;
            (
                0.5 * self.amp * (1.0 + (w * v).cos()),
                -0.5 * self.amp * w * (w * v).sin(),
            )
        }
    }
}

/// Parameters of the generated land-vehicle drive.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LandVehicleOptions {
    pub duration_s: f64,
    /// Jerk limit of each acceleration component (m/s³); the rotation of
    /// the acceleration vector in turns adds |a|·ψ̇ on top (kept small).
    pub axis_jerk_mps3: f64,
    /// Largest forward acceleration and braking (m/s²).
    pub max_accel_mps2: f64,
    /// Largest lateral acceleration in turns (m/s²).
    pub max_lateral_mps2: f64,
    /// Largest speed (m/s).
    pub max_speed_mps: f64,
    /// Hills: height amplitude (m) and wavelength along the road (m).
    pub hill_amp_m: f64,
    pub hill_wavelength_m: f64,
    pub seed: u64,
}

impl Default for LandVehicleOptions {
    fn default() -> Self {
        LandVehicleOptions {
            duration_s: 600.0,
            axis_jerk_mps3: 0.8 * G0,
            max_accel_mps2: 3.0,
            max_lateral_mps2: 3.5,
            max_speed_mps: 28.0,
            hill_amp_m: 3.0,
            hill_wavelength_m: 400.0,
            seed: 1,
        }
    }
}

/// A seeded land-vehicle drive: standstill, accelerations, cruising, turns
/// of 30–90°, lane changes, braking to lower speeds and to stops, over
/// sinusoidal hills. Forward and lateral accelerations are sequences of
/// raised-cosine pulses whose edges respect the jerk limit; the heading
/// rate is a_lat/v (no side slip). The path is integrated with 1 ms steps
/// and stored every 10 ms with position, velocity, acceleration and jerk;
/// queries use the quintic Hermite interpolant of position, velocity and
/// acceleration, so the position, velocity and acceleration returned are
/// exact derivatives of one another.
#[derive(Clone, Debug)]
pub struct LandVehicleProfile {
    step_s: f64,
    samples: Vec<Kinematics>,
    duration_s: f64,
}

impl LandVehicleProfile {
    pub fn new(opts: &LandVehicleOptions) -> Self {
        let (long, lat) = plan_maneuvers(opts);
        let store_every = 10usize;
        let dt = 1e-3;
        let step_s = dt * store_every as f64;
        let n = (opts.duration_s / step_s).ceil() as usize + 1;
        let mut samples = Vec::with_capacity(n);
        let k_hill = 2.0 * std::f64::consts::PI / opts.hill_wavelength_m;
        let amp = opts.hill_amp_m;
        let mut pos = Vector3::zeros();
        let mut v = 0.0f64;
        let mut psi = 0.0f64;
        let mut dist = 0.0f64;
        let (mut il, mut ia) = (0usize, 0usize);
        let eval = |pulses: &[Pulse], cursor: &mut usize, t: f64| -> (f64, f64) {
            while *cursor < pulses.len() && pulses[*cursor].end_s() < t {
                *cursor += 1;
            }
            let mut out = (0.0, 0.0);
            for p in pulses[*cursor..].iter().take_while(|p| p.start_s <= t) {
                let (a, j) = p.eval(t);
                out.0 += a;
                out.1 += j;
            }
            out
        };
        let kin = |t: f64,
                   pos: Vector3<f64>,
                   v: f64,
                   psi: f64,
                   dist: f64,
                   il: &mut usize,
                   ia: &mut usize| {
            let (ax, jx) = eval(&long, il, t);
            let (ay, jy) = if v > 0.5 {
                eval(&lat, ia, t)
            } else {
                (0.0, 0.0)
            };
            let psi_dot = if v > 0.5 { ay / v } else { 0.0 };
            let (s, c) = psi.sin_cos();
            let (sh, ch) = (k_hill * dist).sin_cos();
            // h(s) = A sin(k s); down = −h: derivatives by the chain rule.
            let vd = -amp * k_hill * ch * v;
            let ad = -(-amp * k_hill * k_hill * sh * v * v + amp * k_hill * ch * ax);
            let jd = -(-amp * k_hill.powi(3) * ch * v.powi(3)
                - 3.0 * amp * k_hill * k_hill * sh * v * ax
                + amp * k_hill * ch * jx);
            let jt = jx - psi_dot * ay;
            let jn = jy + psi_dot * ax;
            Kinematics {
                pos_m: pos,
                vel_mps: Vector3::new(v * c, v * s, vd),
                acc_mps2: Vector3::new(ax * c - ay * s, ax * s + ay * c, ad),
                jerk_mps3: Vector3::new(jt * c - jn * s, jt * s + jn * c, jd),
            }
        };
        let total_steps = (n - 1) * store_every;
        let mut k0 = kin(0.0, pos, v, psi, dist, &mut il, &mut ia);
        samples.push(k0);
        for i in 1..=total_steps {
            let t1 = i as f64 * dt;
            let t0 = t1 - dt;
            let (ax0, _) = eval(&long, &mut il, t0);
            let (ax1, _) = eval(&long, &mut il, t1);
            let v1 = (v + 0.5 * (ax0 + ax1) * dt).max(0.0);
            let rate0 = if v > 0.5 {
                eval(&lat, &mut ia, t0).0 / v
            } else {
                0.0
            };
            let rate1 = if v1 > 0.5 {
                eval(&lat, &mut ia, t1).0 / v1
            } else {
                0.0
            };
            let psi1 = psi + 0.5 * (rate0 + rate1) * dt;
            let dist1 = dist + 0.5 * (v + v1) * dt + (ax0 - ax1) * dt * dt / 12.0;
            let mut k1 = kin(t1, pos, v1, psi1, dist1, &mut il, &mut ia);
            // Hermite-corrected trapezoid: p1 = p0 + (v0+v1)dt/2 + (a0−a1)dt²/12.
            let p1 = pos
                + (k0.vel_mps + k1.vel_mps) * (0.5 * dt)
                + (k0.acc_mps2 - k1.acc_mps2) * (dt * dt / 12.0);
            // Height follows the hill shape exactly.
            let p1 = Vector3::new(p1.x, p1.y, -amp * (k_hill * dist1).sin());
            k1.pos_m = p1;
            pos = p1;
            v = v1;
            psi = psi1;
            dist = dist1;
            k0 = k1;
            if i % store_every == 0 {
                samples.push(k1);
            }
        }
        LandVehicleProfile {
            step_s,
            samples,
            duration_s: opts.duration_s,
        }
    }
}

impl Trajectory for LandVehicleProfile {
    fn kinematics(&self, t_s: f64) -> Kinematics {
        let n = self.samples.len();
        let x = (t_s / self.step_s).clamp(0.0, (n - 1) as f64);
        let i = (x.floor() as usize).min(n - 2);
        let u = x - i as f64;
        quintic_hermite(&self.samples[i], &self.samples[i + 1], self.step_s, u)
    }
    fn duration_s(&self) -> f64 {
        self.duration_s
    }
}

/// Quintic Hermite interpolation of position matching position, velocity
/// and acceleration at both ends of a step of `h` seconds, at fraction `u`.
fn quintic_hermite(a: &Kinematics, b: &Kinematics, h: f64, u: f64) -> Kinematics {
    // p(u) = Σ c_k u^k on [0, 1] with derivatives scaled by h.
    let p0 = a.pos_m;
    let v0 = a.vel_mps * h;
    let a0 = a.acc_mps2 * (h * h);
    let p1 = b.pos_m;
    let v1 = b.vel_mps * h;
    let a1 = b.acc_mps2 * (h * h);
    let c0 = p0;
    let c1 = v0;
    let c2 = a0 * 0.5;
    let c3 = (p1 - p0) * 10.0 - v0 * 6.0 - v1 * 4.0 - a0 * 1.5 + a1 * 0.5;
    let c4 = (p0 - p1) * 15.0 + v0 * 8.0 + v1 * 7.0 + a0 * 1.5 - a1;
    let c5 = (p1 - p0) * 6.0 - (v0 + v1) * 3.0 - a0 * 0.5 + a1 * 0.5;
    let pos = c0 + (c1 + (c2 + (c3 + (c4 + c5 * u) * u) * u) * u) * u;
    let vel = c1 + (c2 * 2.0 + (c3 * 3.0 + (c4 * 4.0 + c5 * 5.0 * u) * u) * u) * u;
    let acc = c2 * 2.0 + (c3 * 6.0 + (c4 * 12.0 + c5 * 20.0 * u) * u) * u;
    let jerk = c3 * 6.0 + (c4 * 24.0 + c5 * 60.0 * u) * u;
    Kinematics {
        pos_m: pos,
        vel_mps: vel / h,
        acc_mps2: acc / (h * h),
        jerk_mps3: jerk / (h * h * h),
    }
}

/// Plans the forward and lateral acceleration pulses.
fn plan_maneuvers(o: &LandVehicleOptions) -> (Vec<Pulse>, Vec<Pulse>) {
    let mut rng = Pcg64Mcg::seed_from_u64(o.seed);
    let mut long = Vec::new();
    let mut lat = Vec::new();
    let j = o.axis_jerk_mps3;
    let edge = |amp: f64| (std::f64::consts::PI * amp.abs() / (2.0 * j)).max(0.5);
    let mut t = 5.0; // standstill first
    let mut v = 0.0f64;
    // A speed change of dv with acceleration amplitude `a`: area a(H + D) = dv.
    let speed_change = |t: &mut f64, v: &mut f64, target: f64, amp: f64, long: &mut Vec<Pulse>| {
        let dv = target - *v;
        let mut a = amp.copysign(dv);
        let mut d = edge(a);
        let mut hold = dv / a - d;
        if hold < 0.0 {
            // Too small a change for this amplitude: shrink it (a·D = dv).
            a = (2.0 * j * dv.abs() / std::f64::consts::PI)
                .sqrt()
                .copysign(dv);
            d = edge(a);
            a = dv / d;
            hold = 0.0;
        }
        long.push(Pulse {
            start_s: *t,
            edge_s: d,
            hold_s: hold,
            amp: a,
        });
        *t += 2.0 * d + hold;
        *v = target;
    };
    while t < o.duration_s {
        if v < 3.0 {
            let target = rng.random_range(12.0..o.max_speed_mps.min(25.0));
            let a = rng.random_range(1.5..o.max_accel_mps2);
            speed_change(&mut t, &mut v, target, a, &mut long);
            continue;
        }
        match rng.random_range(0..6u32) {
            0 => t += rng.random_range(4.0..15.0),
            1 => {
                let target = (v + rng.random_range(3.0..8.0)).min(o.max_speed_mps);
                let a = rng.random_range(1.0..o.max_accel_mps2);
                speed_change(&mut t, &mut v, target, a, &mut long);
            }
            2 => {
                let stop = rng.random_range(0.0..1.0) < 0.3;
                let target = if stop {
                    0.0
                } else {
                    (v - rng.random_range(5.0..12.0)).max(6.0)
                };
                let a = rng.random_range(1.5..o.max_accel_mps2);
                speed_change(&mut t, &mut v, target, a, &mut long);
                if stop {
                    t += rng.random_range(2.0..6.0);
                }
            }
            3 | 4 => {
                // A turn of 30–90° at constant speed: a(H + D) = Δψ·v.
                let dpsi = rng.random_range(30f64..90.0).to_radians();
                let sign = if rng.random_range(0.0..1.0) < 0.5 {
                    -1.0
                } else {
                    1.0
                };
                // Keep |a|²/v (the rotation term of the jerk) under 1.5 m/s³.
                let amax = o.max_lateral_mps2.min((1.5 * v).sqrt());
                let mut a = rng.random_range(0.5 * amax..amax);
                let mut d = edge(a);
                let mut hold = dpsi * v / a - d;
                if hold < 0.0 {
                    a = dpsi * v / d;
                    d = edge(a);
                    hold = (dpsi * v / a - d).max(0.0);
                }
                lat.push(Pulse {
                    start_s: t,
                    edge_s: d,
                    hold_s: hold,
                    amp: sign * a,
                });
                t += 2.0 * d + hold + 1.0;
            }
            _ => {
                // A lane change: lateral pulse one way, then back.
                let a = rng.random_range(0.8..1.8f64).min((1.5 * v).sqrt());
                let d = edge(a).max(0.8);
                let hold = rng.random_range(0.0..0.6);
                let sign = if rng.random_range(0.0..1.0) < 0.5 {
                    -1.0
                } else {
                    1.0
                };
                lat.push(Pulse {
                    start_s: t,
                    edge_s: d,
                    hold_s: hold,
                    amp: sign * a,
                });
                t += 2.0 * d + hold;
                lat.push(Pulse {
                    start_s: t,
                    edge_s: d,
                    hold_s: hold,
                    amp: -sign * a,
                });
                t += 2.0 * d + hold + 1.0;
            }
        }
    }
    (long, lat)
}

/// One sample of a trajectory given in geodetic coordinates.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct GeodeticSample {
    pub t_s: f64,
    pub pos: Geodetic,
    pub vel_ned_mps: Vector3<f64>,
}

/// A sampled trajectory (positions and velocities, e.g. a navigation or
/// truth file at 10–200 Hz), interpolated by cubic Hermite splines.
/// Positions are converted to ECEF and expressed in the NED frame of the
/// first sample (a fixed frame: no flat-Earth error); velocities are
/// rotated from each sample's NED frame into that frame, so range and
/// range rate stay consistent over any distance.
#[derive(Clone, Debug)]
pub struct SampledTrajectory {
    t_s: Vec<f64>,
    pos: Vec<Vector3<f64>>,
    vel: Vec<Vector3<f64>>,
}

impl SampledTrajectory {
    /// From samples in increasing time; times are made relative to the
    /// first. Errors with fewer than two samples or non-increasing times.
    pub(crate) fn from_geodetic(samples: &[GeodeticSample]) -> Result<Self, String> {
        if samples.len() < 2 {
            return Err("a sampled trajectory needs at least two samples".into());
        }
        let first = &samples[0];
        let r0 = geodetic_to_ecef(&first.pos);
        let c_en0 = c_ne(&first.pos).transpose();
        let mut out = SampledTrajectory {
            t_s: Vec::with_capacity(samples.len()),
            pos: Vec::with_capacity(samples.len()),
            vel: Vec::with_capacity(samples.len()),
        };
        for s in samples {
            let t = s.t_s - first.t_s;
            if let Some(&last) = out.t_s.last()
                && t <= last
            {
                return Err(format!("sample times must increase (at {} s)", s.t_s));
            }
            out.t_s.push(t);
            out.pos.push(c_en0 * (geodetic_to_ecef(&s.pos) - r0));
            out.vel.push(c_en0 * (c_ne(&s.pos) * s.vel_ned_mps));
        }
        Ok(out)
    }
}

impl Trajectory for SampledTrajectory {
    fn kinematics(&self, t_s: f64) -> Kinematics {
        let n = self.t_s.len();
        let t = t_s.clamp(self.t_s[0], self.t_s[n - 1]);
        let i = self.t_s.partition_point(|&x| x <= t).clamp(1, n - 1) - 1;
        let h = self.t_s[i + 1] - self.t_s[i];
        let u = (t - self.t_s[i]) / h;
        let (p0, p1) = (self.pos[i], self.pos[i + 1]);
        let (m0, m1) = (self.vel[i] * h, self.vel[i + 1] * h);
        // Cubic Hermite: p(u) = c0 + c1 u + c2 u² + c3 u³.
        let c2 = (p1 - p0) * 3.0 - m0 * 2.0 - m1;
        let c3 = (p0 - p1) * 2.0 + m0 + m1;
        Kinematics {
            pos_m: p0 + (m0 + (c2 + c3 * u) * u) * u,
            vel_mps: (m0 + (c2 * 2.0 + c3 * 3.0 * u) * u) / h,
            acc_mps2: (c2 * 2.0 + c3 * 6.0 * u) / (h * h),
            jerk_mps3: c3 * 6.0 / (h * h * h),
        }
    }
    fn duration_s(&self) -> f64 {
        self.t_s[self.t_s.len() - 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn land_vehicle_respects_its_limits_and_is_consistent() {
        let opts = LandVehicleOptions {
            duration_s: 300.0,
            seed: 3,
            ..Default::default()
        };
        let p = LandVehicleProfile::new(&opts);
        let (mut max_jerk, mut max_acc, mut max_speed, mut turned) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut prev = p.kinematics(0.0);
        let dt = 0.001;
        for i in 1..=(300.0 / dt) as usize {
            let t = i as f64 * dt;
            let k = p.kinematics(t);
            max_jerk = max_jerk.max(k.jerk_mps3.norm());
            max_acc = max_acc.max(k.acc_mps2.norm());
            max_speed = max_speed.max(k.vel_mps.norm());
            // Velocity is the derivative of position (trapezoid, O(dt³·jerk)).
            let dp = k.pos_m - prev.pos_m;
            let want = (k.vel_mps + prev.vel_mps) * (0.5 * dt);
            assert!((dp - want).norm() < 1e-7, "t {t}: {}", (dp - want).norm());
            let dv = k.vel_mps - prev.vel_mps;
            assert!((dv - (k.acc_mps2 + prev.acc_mps2) * (0.5 * dt)).norm() < 1e-6);
            if k.vel_mps.xy().norm() > 1.0 && prev.vel_mps.xy().norm() > 1.0 {
                turned += k.vel_mps.xy().angle(&prev.vel_mps.xy());
            }
            prev = k;
        }
        // The limit: jerk ≤ 1 g/s.
        assert!(max_jerk <= G0, "max jerk {max_jerk}");
        assert!(max_jerk > 0.5 * G0, "profile too gentle: {max_jerk}");
        assert!(max_acc > 2.0 && max_acc < 5.0, "max acceleration {max_acc}");
        assert!(max_speed > 12.0 && max_speed <= opts.max_speed_mps + 0.5);
        assert!(
            turned.to_degrees() > 90.0,
            "turned only {}°",
            turned.to_degrees()
        );
    }

    #[test]
    fn sampled_trajectory_reproduces_a_straight_line_exactly() {
        // Eastward at 20 m/s on the equator: ECEF displacement along y.
        let samples: Vec<GeodeticSample> = (0..50)
            .map(|i| {
                let t = i as f64 * 0.1;
                let lon = (20.0 * t / navsync::earth::A).to_degrees();
                GeodeticSample {
                    t_s: 1000.0 + t,
                    pos: Geodetic::from_deg(0.0, lon, 0.0),
                    vel_ned_mps: Vector3::new(0.0, 20.0, 0.0),
                }
            })
            .collect();
        let tr = SampledTrajectory::from_geodetic(&samples).unwrap();
        let k = tr.kinematics(2.345);
        assert!((k.pos_m.y - 20.0 * 2.345).abs() < 1e-6, "{}", k.pos_m);
        // On a great circle the fixed start frame sees the Earth's curvature
        // as a tiny downward motion: |v_d| ≈ v²t/R.
        assert!((k.vel_mps.y - 20.0).abs() < 1e-6 && k.vel_mps.z.abs() < 1e-3);
        assert!(SampledTrajectory::from_geodetic(&samples[..1]).is_err());
        let mut bad = samples.clone();
        bad[3].t_s = bad[2].t_s;
        assert!(SampledTrajectory::from_geodetic(&bad).is_err());
    }

    #[test]
    fn line_of_sight_projects_motion() {
        let los = SatelliteLos::from_elevation_azimuth(0.0, 0.0, 100.0, 0.1);
        let k = Kinematics {
            pos_m: Vector3::new(10.0, 0.0, 0.0),
            vel_mps: Vector3::new(5.0, 3.0, 0.0),
            acc_mps2: Vector3::new(1.0, 0.0, 0.0),
            jerk_mps3: Vector3::new(2.0, 0.0, 0.0),
        };
        let s = los.state(2.0, &k);
        assert!((s.range_m - (200.0 + 0.2 - 10.0)).abs() < 1e-12);
        assert!((s.rate_mps - (100.0 + 0.2 - 5.0)).abs() < 1e-12);
        assert!((s.accel_mps2 - (0.1 - 1.0)).abs() < 1e-12);
        assert!((s.jerk_mps3 + 2.0).abs() < 1e-12);
    }
}
