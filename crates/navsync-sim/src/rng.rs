//! Independent random streams, one per error source.
//!
//! Every source of randomness in the simulator (each sensor error, each
//! fault, each clock) draws from its own PCG generator seeded from the run
//! seed and the source's name, so that switching one fault on or off never
//! changes the draws of any other source, and a run is reproducible from
//! its seed alone.

use rand::RngExt;
use rand_distr::StandardNormal;

/// The generator used for every stream (PCG-64 MCG: fast, 128-bit state;
/// O'Neill 2014, "PCG: A Family of Simple Fast Space-Efficient
/// Statistically Good Algorithms for Random Number Generation").
pub type SimRng = rand_pcg::Pcg64Mcg;

/// SplitMix64 finaliser (Steele, Lea & Flood 2014): a bijective mix of 64
/// bits, used to spread the seed and the source hash over the state.
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// FNV-1a hash of a source name (stable across platforms and versions).
fn fnv1a(name: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in name.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The random stream of source `source` in a run with seed `seed`.
pub fn stream(seed: u64, source: &str) -> SimRng {
    let lo = splitmix64(seed ^ fnv1a(source));
    let hi = splitmix64(lo ^ 0x5851_f42d_4c95_7f2d);
    let state = ((hi as u128) << 64) | lo as u128;
    SimRng::new(state | 1)
}

/// A standard normal draw.
#[inline]
pub fn normal(rng: &mut SimRng) -> f64 {
    rng.sample(StandardNormal)
}

/// A uniform draw in [0, 1).
#[inline]
pub fn uniform(rng: &mut SimRng) -> f64 {
    rng.random::<f64>()
}

/// A uniform draw in [lo, hi).
#[inline]
pub fn uniform_in(rng: &mut SimRng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * uniform(rng)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let mut a = stream(7, "imu.gyro.white");
        let mut b = stream(7, "imu.gyro.white");
        let mut c = stream(7, "imu.accel.white");
        let mut d = stream(8, "imu.gyro.white");
        let xa: Vec<f64> = (0..4).map(|_| uniform(&mut a)).collect();
        let xb: Vec<f64> = (0..4).map(|_| uniform(&mut b)).collect();
        let xc: Vec<f64> = (0..4).map(|_| uniform(&mut c)).collect();
        let xd: Vec<f64> = (0..4).map(|_| uniform(&mut d)).collect();
        assert_eq!(xa, xb);
        assert_ne!(xa, xc);
        assert_ne!(xa, xd);
    }

    #[test]
    fn normal_draws_have_unit_variance() {
        let mut r = stream(1, "test");
        let n = 200_000;
        let (mut s, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let x = normal(&mut r);
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        // Sampling sd of the mean is 1/sqrt(n) = 0.0022; of the variance sqrt(2/n) = 0.0032.
        assert!(mean.abs() < 0.011, "{mean}");
        assert!((var - 1.0).abs() < 0.016, "{var}");
    }
}
