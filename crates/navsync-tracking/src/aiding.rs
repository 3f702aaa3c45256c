//! Errors of the Doppler aiding that an integrated navigation solution
//! feeds to the carrier loop, and the statistics the navigation filter
//! reports about them.
//!
//! Seed 003 (Sun, Petovello & Cannon 2010, appendix) models the aiding
//! error two ways: a random ramp (a constant Doppler-rate error, eq 16) and
//! a first-order Gauss-Markov sequence held constant over each Kalman-filter
//! update period T (eqs 18–20: u_i = e^{−αT} u_{i−1} + σ_w w_i with
//! σ_w² = σ_u²(1 − e^{−2αT}) in the discrete form). [`AidingErrorProcess`]
//! simulates their sum: between two filter updates the error is the held GM
//! value plus a ramp whose rate is drawn at each update (the velocity error
//! of an INS growing between GNSS updates, reset by each update). A
//! schedule of segments lets the quality change over time (e.g. a GNSS
//! outage: no resets, a steeper ramp, a larger GM σ).

use rand::RngExt;
use rand::SeedableRng;
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use serde::Serialize;

/// What the navigation filter knows about its Doppler-aiding error.
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize)]
pub struct AidingStats {
    /// RMS of the Doppler-rate (ramp) error (Hz/s).
    pub ramp_hz_s: f64,
    /// Standard deviation σ_u of the Gauss-Markov Doppler error (Hz).
    pub gm_sd_hz: f64,
    /// Its correlation time 1/α (s).
    pub gm_tau_s: f64,
    /// Kalman-filter update period T (s): the GM value is held over it and
    /// the ramp restarts at each update.
    pub update_period_s: f64,
}

/// One segment of an aiding-error schedule, from `start_s` on.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct AidingSegment {
    pub start_s: f64,
    pub stats: AidingStats,
}

/// How the aiding error is made.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum AidingErrorConfig {
    /// Perfect aiding.
    None,
    /// A deterministic Doppler-rate error `rate_hz_s` from t = 0 on (the
    /// step of frequency derivative of seed 003 eq 16), never reset.
    ConstantRamp { rate_hz_s: f64 },
    /// Random ramp + held Gauss-Markov, with statistics changing by segment.
    Schedule(Vec<AidingSegment>),
}

impl AidingErrorConfig {
    /// A schedule with one segment.
    pub fn constant(stats: AidingStats) -> Self {
        AidingErrorConfig::Schedule(vec![AidingSegment {
            start_s: 0.0,
            stats,
        }])
    }

    /// A schedule from a navigation filter's velocity standard deviation
    /// along the line of sight, `(t_s, sd_mps)` in increasing time (e.g.
    /// from `std.txt` of `navsync fuse`): at each sample the GM σ is the
    /// σ in Hz (σ/λ), the ramp is the growth rate of σ (Hz/s, zero when it
    /// shrinks), the update period is the sample spacing, and `tau_s` is
    /// the GM correlation time.
    pub fn from_velocity_sd(series: &[(f64, f64)], wavelength_m: f64, tau_s: f64) -> Self {
        let mut segs = Vec::with_capacity(series.len());
        for (i, &(t, sd)) in series.iter().enumerate() {
            let (dt, growth) = match series.get(i + 1) {
                Some(&(t1, sd1)) => (t1 - t, ((sd1 - sd) / (t1 - t)).max(0.0)),
                None => (
                    segs.last()
                        .map(|s: &AidingSegment| s.stats.update_period_s)
                        .unwrap_or(1.0),
                    0.0,
                ),
            };
            segs.push(AidingSegment {
                start_s: t,
                stats: AidingStats {
                    ramp_hz_s: growth / wavelength_m,
                    gm_sd_hz: sd / wavelength_m,
                    gm_tau_s: tau_s,
                    update_period_s: dt.max(1e-3),
                },
            });
        }
        AidingErrorConfig::Schedule(segs)
    }

    /// The statistics in force at `t_s` (what the adaptive loop is told).
    pub fn stats_at(&self, t_s: f64) -> AidingStats {
        match self {
            AidingErrorConfig::None => AidingStats::default(),
            AidingErrorConfig::ConstantRamp { rate_hz_s } => AidingStats {
                ramp_hz_s: rate_hz_s.abs(),
                ..Default::default()
            },
            AidingErrorConfig::Schedule(segs) => {
                segment_at(segs, t_s).map(|s| s.stats).unwrap_or_default()
            }
        }
    }
}

fn segment_at(segs: &[AidingSegment], t_s: f64) -> Option<&AidingSegment> {
    let i = segs.partition_point(|s| s.start_s <= t_s);
    if i == 0 {
        segs.first()
    } else {
        segs.get(i - 1)
    }
}

/// Simulates the aiding error (Hz) at increasing times.
#[derive(Clone, Debug)]
pub struct AidingErrorProcess {
    cfg: AidingErrorConfig,
    rng: Pcg64Mcg,
    /// Unit-variance GM state (scaled by the current σ_u).
    gm_unit: f64,
    /// Unit-variance ramp draw of the current update period.
    ramp_unit: f64,
    last_update_s: f64,
    next_update_s: f64,
}

impl AidingErrorProcess {
    pub fn new(cfg: AidingErrorConfig, seed: u64) -> Self {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let gm_unit: f64 = rng.sample(StandardNormal);
        let ramp_unit: f64 = rng.sample(StandardNormal);
        AidingErrorProcess {
            cfg,
            rng,
            gm_unit,
            ramp_unit,
            last_update_s: 0.0,
            next_update_s: 0.0,
        }
    }

    pub fn config(&self) -> &AidingErrorConfig {
        &self.cfg
    }

    /// The Doppler aiding error (Hz) at `t_s`; calls must not go back in time.
    pub(crate) fn error_hz(&mut self, t_s: f64) -> f64 {
        match &self.cfg {
            AidingErrorConfig::None => 0.0,
            AidingErrorConfig::ConstantRamp { rate_hz_s } => rate_hz_s * t_s,
            AidingErrorConfig::Schedule(segs) => {
                let Some(seg) = segment_at(segs, t_s).copied() else {
                    return 0.0;
                };
                let s = seg.stats;
                let period = s.update_period_s.max(1e-3);
                while t_s >= self.next_update_s {
                    // A filter update: new GM sample (seed 003 eqs 19–20 on
                    // the unit-variance state), new ramp rate.
                    let decay = if s.gm_tau_s > 0.0 {
                        (-period / s.gm_tau_s).exp()
                    } else {
                        0.0
                    };
                    let w: f64 = self.rng.sample(StandardNormal);
                    self.gm_unit = decay * self.gm_unit + (1.0 - decay * decay).sqrt() * w;
                    self.ramp_unit = self.rng.sample(StandardNormal);
                    self.last_update_s = self.next_update_s;
                    self.next_update_s += period;
                }
                s.gm_sd_hz * self.gm_unit
                    + s.ramp_hz_s * self.ramp_unit * (t_s - self.last_update_s)
            }
        }
    }

    pub fn stats_at(&self, t_s: f64) -> AidingStats {
        self.cfg.stats_at(t_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_markov_part_has_the_configured_statistics() {
        let stats = AidingStats {
            ramp_hz_s: 0.0,
            gm_sd_hz: 0.2,
            gm_tau_s: 2.0,
            update_period_s: 0.1,
        };
        let mut p = AidingErrorProcess::new(AidingErrorConfig::constant(stats), 5);
        let mut xs = Vec::new();
        for k in 0..200_000 {
            xs.push(p.error_hz(k as f64 * 0.1 + 0.05));
        }
        let n = xs.len() as f64;
        let var = xs.iter().map(|x| x * x).sum::<f64>() / n;
        // Lag-one correlation e^{−T/τ}.
        let c1 = xs.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (n - 1.0) / var;
        // 2·10⁵ samples with correlation time 20 samples: ~5000 independent
        // values, relative σ of the variance ≈ √(2/5000) = 2 %.
        assert!((var.sqrt() / 0.2 - 1.0).abs() < 0.05, "sd {}", var.sqrt());
        assert!((c1 - (-0.05f64).exp()).abs() < 0.01, "lag-1 {c1}");
    }

    #[test]
    fn ramp_restarts_at_each_update() {
        let stats = AidingStats {
            ramp_hz_s: 1.0,
            gm_sd_hz: 0.0,
            gm_tau_s: 1.0,
            update_period_s: 1.0,
        };
        let mut p = AidingErrorProcess::new(AidingErrorConfig::constant(stats), 9);
        let a = p.error_hz(0.0);
        let b = p.error_hz(0.5);
        let c = p.error_hz(0.9);
        assert_eq!(a, 0.0);
        assert!(
            ((c - b) / 0.4 - b / 0.5).abs() < 1e-12,
            "linear within a period"
        );
        let d = p.error_hz(1.0);
        assert_eq!(d, 0.0);
        let mut fixed =
            AidingErrorProcess::new(AidingErrorConfig::ConstantRamp { rate_hz_s: 1.0 }, 1);
        assert_eq!(fixed.error_hz(2.5), 2.5);
    }

    #[test]
    fn schedule_from_velocity_sd() {
        let lambda = 0.19;
        let cfg = AidingErrorConfig::from_velocity_sd(
            &[(0.0, 0.019), (1.0, 0.019), (2.0, 0.038)],
            lambda,
            5.0,
        );
        let s0 = cfg.stats_at(0.5);
        assert!((s0.gm_sd_hz - 0.1).abs() < 1e-12 && s0.ramp_hz_s == 0.0);
        let s1 = cfg.stats_at(1.5);
        assert!((s1.ramp_hz_s - 0.1).abs() < 1e-12);
        assert!((cfg.stats_at(9.0).gm_sd_hz - 0.2).abs() < 1e-12);
    }
}
