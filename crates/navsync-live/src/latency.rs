//! Arrival → solution latency: a fixed histogram (1 µs bins up to 50 ms),
//! constant memory however long the run.

use serde::Serialize;

const BIN_NS: u64 = 1_000;
const BINS: usize = 50_000;

/// Latency statistics of a run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LatencySummary {
    pub count: u64,
    pub median_us: Option<f64>,
    pub p99_us: Option<f64>,
    pub max_us: Option<f64>,
    /// Samples above the histogram's range (50 ms).
    pub over_50ms: u64,
}

/// The histogram.
#[derive(Clone, Debug)]
pub(crate) struct LatencyHistogram {
    bins: Vec<u32>,
    over: u64,
    n: u64,
    max_ns: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    pub(crate) fn new() -> Self {
        LatencyHistogram {
            bins: vec![0; BINS],
            over: 0,
            n: 0,
            max_ns: 0,
        }
    }

    pub(crate) fn push(&mut self, ns: u64) {
        self.n += 1;
        self.max_ns = self.max_ns.max(ns);
        match self.bins.get_mut((ns / BIN_NS) as usize) {
            Some(b) => *b = b.saturating_add(1),
            None => self.over += 1,
        }
    }

    /// The `q` quantile (bin centre, µs); `None` when empty or beyond range.
    pub(crate) fn quantile_us(&self, q: f64) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        let target = ((self.n as f64 * q).ceil() as u64).clamp(1, self.n);
        let mut acc = 0u64;
        for (i, &c) in self.bins.iter().enumerate() {
            acc += c as u64;
            if acc >= target {
                return Some((i as f64 + 0.5) * BIN_NS as f64 * 1e-3);
            }
        }
        None
    }

    pub(crate) fn summary(&self) -> LatencySummary {
        LatencySummary {
            count: self.n,
            median_us: self.quantile_us(0.5),
            p99_us: self.quantile_us(0.99),
            max_us: (self.n > 0).then_some(self.max_ns as f64 * 1e-3),
            over_50ms: self.over,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_known_set() {
        let mut h = LatencyHistogram::new();
        for k in 1..=1000u64 {
            h.push(k * 10_000); // 10 µs … 10 ms
        }
        h.push(60_000_000);
        let s = h.summary();
        assert_eq!(s.count, 1001);
        assert!((s.median_us.unwrap() - 5010.5).abs() < 11.0, "{s:?}");
        assert!((s.p99_us.unwrap() - 9920.5).abs() < 20.0, "{s:?}");
        assert_eq!(s.max_us, Some(60_000.0));
        assert_eq!(s.over_50ms, 1);
    }
}
