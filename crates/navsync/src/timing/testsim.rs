//! A compact synthetic rig for the timing tests (the full simulator is
//! `navsync-sim`'s; this one keeps the core's tests free of it): a local
//! counter driven by true time with a frequency error, a temperature ramp
//! and a frequency random walk, wrapping at its bit width; PPS edges with
//! jitter, dropouts, displaced and spurious pulses; GNSS messages with
//! latency and jitter; an IMU on its own clock with lost and duplicated
//! samples; receive jitter for software sync.
//! Records come out in arrival order with the true time of each IMU record.

use crate::io::riglog::{ImuKind, RigGnss, RigHeader, RigRecord};
use crate::time::{GpsTime, NS_PER_S};

/// Deterministic generator (SplitMix64 → uniform, Box–Muller → normal).
pub(crate) struct Rng(u64);

impl Rng {
    pub(super) fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub(super) fn u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub(super) fn uniform(&mut self) -> f64 {
        (self.u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub(super) fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.uniform()
    }
    pub(super) fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    pub(super) fn chance(&mut self, p: f64) -> bool {
        self.uniform() < p
    }
}

/// Scenario parameters (SI units; times relative to the start second).
#[derive(Clone, Debug)]
pub(super) struct Scenario {
    pub seed: u64,
    pub duration_s: f64,
    pub counter_hz: f64,
    pub counter_bits: u32,
    /// Counter value at t = 0 (ticks, may be fractional).
    pub(crate) counter_start: f64,
    pub(crate) freq_error_ppm: f64,
    /// Temperature ramp (°C/min) from t = ramp_start_s, and the counter's
    /// temperature coefficient (ppm/°C).
    pub(crate) ramp_c_per_min: f64,
    pub(crate) ramp_start_s: f64,
    pub(crate) tempco_ppm_per_c: f64,
    /// Fractional-frequency random walk: σ of the change over 1 s.
    pub(crate) freq_rw_per_sqrt_s: f64,
    pub pps: bool,
    pub(crate) pps_jitter_s: f64,
    /// (start, length) of PPS dropouts (s).
    pub(crate) pps_dropouts: Vec<(f64, f64)>,
    pub(crate) displaced_fraction: f64,
    pub(crate) spurious_fraction: f64,
    /// GNSS latency: uniform base in this range plus jitter.
    pub(crate) gnss_latency_s: (f64, f64),
    /// Uniform jitter added on top (s).
    pub(crate) gnss_jitter_uniform_s: f64,
    /// Gaussian jitter σ added on top (clipped so latency ≥ 5 ms).
    pub(crate) gnss_jitter_normal_s: f64,
    pub imu_rate_hz: f64,
    pub(crate) imu_ppm: f64,
    pub(crate) imu_kind: ImuKind,
    pub(crate) imu_lost_fraction: f64,
    pub(crate) imu_dup_fraction: f64,
    /// Software sync: IMU output delay T_c and uniform receive jitter.
    pub imu_output_delay_s: f64,
    pub(crate) receive_jitter_s: Option<(f64, f64)>,
    /// GPS second of t = 0.
    pub(crate) start_second: i64,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            seed: 1,
            duration_s: 300.0,
            counter_hz: 1e6,
            counter_bits: 32,
            counter_start: 4_294_000_000.5,
            freq_error_ppm: 37.0,
            ramp_c_per_min: 0.0,
            ramp_start_s: 0.0,
            tempco_ppm_per_c: 0.5,
            freq_rw_per_sqrt_s: 1e-11,
            pps: true,
            pps_jitter_s: 1e-7,
            pps_dropouts: Vec::new(),
            displaced_fraction: 0.0,
            spurious_fraction: 0.0,
            gnss_latency_s: (0.07, 0.1),
            gnss_jitter_uniform_s: 0.0,
            gnss_jitter_normal_s: 0.0,
            imu_rate_hz: 200.0,
            imu_ppm: -400.0,
            imu_kind: ImuKind::Rate,
            imu_lost_fraction: 0.0,
            imu_dup_fraction: 0.0,
            imu_output_delay_s: 0.0,
            receive_jitter_s: None,
            start_second: 2300 * 604_800 + 100_000,
        }
    }
}

/// What was injected, for the assertions.
#[derive(Clone, Debug, Default)]
pub(super) struct Truth {
    /// True GPS time of every `imu` record, in record order.
    pub imu_times: Vec<GpsTime>,
    /// Unwrapped-phase-free: (raw counter, true second) of good pulses.
    pub(crate) good_pulses: Vec<(u64, i64)>,
    /// Raw counters of displaced or spurious pulses.
    pub(crate) bad_pulses: Vec<u64>,
    pub imu_lost: u64,
    pub(crate) imu_dup: u64,
}

/// A generated log.
pub(crate) struct Generated {
    pub header: RigHeader,
    pub records: Vec<RigRecord>,
    pub truth: Truth,
}

struct Counter {
    hz: f64,
    bits: u32,
    /// Phase (ticks) at each whole second and the fractional frequency there.
    phase: Vec<f64>,
    y: Vec<f64>,
}

impl Counter {
    fn new(s: &Scenario, rng: &mut Rng) -> Self {
        let n = s.duration_s.ceil() as usize + 3;
        let mut y = Vec::with_capacity(n);
        let mut w = 0.0;
        for k in 0..n {
            let t = k as f64;
            let dt_c = s.ramp_c_per_min / 60.0 * (t - s.ramp_start_s).max(0.0);
            y.push((s.freq_error_ppm + s.tempco_ppm_per_c * dt_c) * 1e-6 + w);
            w += s.freq_rw_per_sqrt_s * rng.normal();
        }
        let mut phase = Vec::with_capacity(n);
        let mut p = s.counter_start;
        for k in 0..n {
            phase.push(p);
            if k + 1 < n {
                p += s.counter_hz * (1.0 + 0.5 * (y[k] + y[k + 1]));
            }
        }
        Counter {
            hz: s.counter_hz,
            bits: s.counter_bits,
            phase,
            y,
        }
    }

    /// Raw (wrapped) counter latched at true time `t` (floor of the phase).
    fn at(&self, t: f64) -> u64 {
        let t = t.max(0.0);
        let k = (t.floor() as usize).min(self.phase.len() - 2);
        let u = t - k as f64;
        let y0 = self.y[k];
        let y1 = self.y[k + 1];
        let ph = self.phase[k] + self.hz * (u + y0 * u + 0.5 * (y1 - y0) * u * u);
        let v = ph.floor().max(0.0) as u128;
        if self.bits >= 64 {
            v as u64
        } else {
            (v % (1u128 << self.bits)) as u64
        }
    }
}

fn gps(s: &Scenario, t: f64) -> GpsTime {
    let whole = t.floor();
    GpsTime::from_ns(
        (s.start_second + whole as i64) * NS_PER_S + ((t - whole) * 1e9).round() as i64,
    )
}

/// Generates the log of scenario `s`.
pub(super) fn generate(s: &Scenario) -> Generated {
    let mut rng_clock = Rng::new(s.seed);
    let mut rng_pps = Rng::new(s.seed.wrapping_add(11));
    let mut rng_gnss = Rng::new(s.seed.wrapping_add(22));
    let mut rng_imu = Rng::new(s.seed.wrapping_add(33));
    let mut rng_rx = Rng::new(s.seed.wrapping_add(44));
    let counter = Counter::new(s, &mut rng_clock);
    let mut truth = Truth::default();
    // (arrival true time, order key, record, imu true time)
    let mut ev: Vec<(f64, u64, RigRecord, Option<GpsTime>)> = Vec::new();
    let mut key = 0u64;
    let mut push = |ev: &mut Vec<_>, t: f64, r: RigRecord, it: Option<GpsTime>| {
        ev.push((t, key, r, it));
        key += 1;
    };
    if s.pps {
        let mut n = 1.0;
        while n < s.duration_s {
            let dropped = s.pps_dropouts.iter().any(|&(a, l)| n >= a && n < a + l);
            if !dropped {
                let mut t = n + s.pps_jitter_s * rng_pps.normal();
                let displaced = rng_pps.chance(s.displaced_fraction);
                if displaced {
                    let d = rng_pps.range(1e-4, 1e-3);
                    t += if rng_pps.chance(0.5) { d } else { -d };
                }
                let c = counter.at(t);
                if displaced {
                    truth.bad_pulses.push(c);
                } else {
                    truth.good_pulses.push((c, s.start_second + n as i64));
                }
                push(&mut ev, t, RigRecord::Pps { counter: c }, None);
                if rng_pps.chance(s.spurious_fraction) {
                    let ts = n + rng_pps.range(0.02, 0.98);
                    let cs = counter.at(ts);
                    truth.bad_pulses.push(cs);
                    push(&mut ev, ts, RigRecord::Pps { counter: cs }, None);
                }
            }
            n += 1.0;
        }
    }
    // GNSS at 1 Hz, valid at whole seconds.
    let mut m = 1.0;
    while m < s.duration_s {
        let mut lat = rng_gnss.range(s.gnss_latency_s.0, s.gnss_latency_s.1)
            + s.gnss_jitter_uniform_s * rng_gnss.uniform();
        if s.gnss_jitter_normal_s > 0.0 {
            lat = (lat + s.gnss_jitter_normal_s * rng_gnss.normal()).max(0.005);
        }
        if let Some((a, b)) = s.receive_jitter_s {
            lat += rng_rx.range(a, b);
        }
        let t_rx = m + lat;
        let g = RigGnss {
            counter: counter.at(t_rx),
            time: gps(s, m),
            lat_deg: 30.0,
            lon_deg: 114.0,
            h_m: 20.0,
            sd_m: [0.02, 0.02, 0.03],
        };
        push(&mut ev, t_rx, RigRecord::Gnss(g), None);
        m += 1.0;
    }
    // IMU on its own clock.
    let period = 1.0 / (s.imu_rate_hz * (1.0 + s.imu_ppm * 1e-6));
    let mut k = 0u64;
    let t_first = 0.0123;
    let mut last_rx = 0.0f64;
    loop {
        let t = t_first + k as f64 * period;
        if t >= s.duration_s || s.imu_rate_hz <= 0.0 {
            break;
        }
        k += 1;
        if rng_imu.chance(s.imu_lost_fraction) {
            truth.imu_lost += 1;
            continue;
        }
        let ph = 0.8 * t;
        let values = [
            1e-2 * ph.sin(),
            2e-3 * ph.cos(),
            5e-3,
            0.2 * ph.cos(),
            0.1,
            -9.79 + 0.01 * (3.0 * t).sin(),
        ];
        let (latch_t, arrive_t) = match s.receive_jitter_s {
            Some((a, b)) => {
                // serial frames arrive in order
                let rx = (t + s.imu_output_delay_s + rng_rx.range(a, b)).max(last_rx + 1e-5);
                last_rx = rx;
                (rx, rx)
            }
            None => (t + s.imu_output_delay_s, t + s.imu_output_delay_s + 1e-4),
        };
        let c = counter.at(latch_t);
        let rec = RigRecord::Imu { counter: c, values };
        push(&mut ev, arrive_t, rec, Some(gps(s, t)));
        if rng_imu.chance(s.imu_dup_fraction) {
            truth.imu_dup += 1;
            push(&mut ev, arrive_t + 1e-6, rec, Some(gps(s, t)));
        }
    }
    ev.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut records = Vec::with_capacity(ev.len());
    for (_, _, r, it) in ev {
        if let Some(t) = it {
            truth.imu_times.push(t);
        }
        records.push(r);
    }
    Generated {
        header: RigHeader {
            counter_hz: s.counter_hz,
            counter_bits: s.counter_bits,
            imu_kind: s.imu_kind,
            imu_rate_hz: Some(s.imu_rate_hz),
            imu_timing: None,
            imu_output_delay_s: None,
            imu_rates: None,
            extra: Vec::new(),
        },
        records,
        truth,
    }
}
