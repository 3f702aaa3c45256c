//! Counter unwrapping for any bit width (1..=64).
//!
//! A counter of `bits` bits wraps modulo 2^bits; consecutive records are
//! closer than half the wrap period, so the signed modular difference to
//! the previous value is the true advance (a wrap is an advance like any
//! other). A value that falls back by more than a small reordering
//! tolerance has not wrapped: the counter went backwards, which is
//! reported; the record is skipped unless the following records confirm
//! a new lineage (the counter was reset), which then starts a new segment.

/// What the unwrapper made of one raw value.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Unwrapped {
    /// The unwrapped counter.
    Ok(u64),
    /// A small step back (records slightly out of order): the unwrapped
    /// value, which lies before the latest one.
    Reordered(u64),
    /// The counter fell back by `ticks` without wrapping: record skipped.
    Backwards { ticks: u64 },
    /// An implausible jump forward by `ticks`: record skipped.
    JumpForward { ticks: u64 },
    /// Confirmed reset: the counter restarted; this is the first value of
    /// a new segment (no clock relation carries over).
    Reset(u64),
}

/// Unwraps a counter stream.
#[derive(Clone, Debug)]
pub(crate) struct Unwrapper {
    bits: u32,
    reorder_ticks: u64,
    max_forward_ticks: u64,
    last_raw: u64,
    last: u64,
    started: bool,
    /// A suspect lineage: (last raw value, consecutive records on it).
    suspect: Option<(u64, u32)>,
    /// Records needed to confirm a new lineage.
    confirm: u32,
    /// Wraps seen.
    pub wraps: u64,
}

impl Unwrapper {
    /// `reorder_ticks`: tolerated step back; `max_forward_ticks`: the
    /// largest plausible advance between two records (capped at half the
    /// wrap period).
    pub(crate) fn new(bits: u32, reorder_ticks: u64, max_forward_ticks: u64) -> Self {
        let half = if bits >= 64 {
            1u64 << 63
        } else {
            1u64 << (bits - 1)
        };
        Unwrapper {
            bits,
            reorder_ticks: reorder_ticks.min(half / 4),
            max_forward_ticks: max_forward_ticks.min(half - 1).max(1),
            last_raw: 0,
            last: 0,
            started: false,
            suspect: None,
            confirm: 3,
            wraps: 0,
        }
    }

    /// Signed modular difference `b − a` in `[-2^(bits-1), 2^(bits-1))`.
    fn diff(&self, a: u64, b: u64) -> i64 {
        if self.bits >= 64 {
            b.wrapping_sub(a) as i64
        } else {
            let m = 1u64 << self.bits;
            let d = b.wrapping_sub(a) & (m - 1);
            if d >= m / 2 {
                d as i64 - m as i64
            } else {
                d as i64
            }
        }
    }

    /// Unwraps one raw value.
    pub(crate) fn push(&mut self, raw: u64) -> Unwrapped {
        if !self.started {
            self.started = true;
            self.last_raw = raw;
            self.last = raw;
            return Unwrapped::Ok(raw);
        }
        let d = self.diff(self.last_raw, raw);
        if d >= 0 && (d as u64) <= self.max_forward_ticks {
            self.suspect = None;
            if raw < self.last_raw && self.bits < 64 {
                self.wraps += 1;
            }
            self.last_raw = raw;
            self.last += d as u64;
            return Unwrapped::Ok(self.last);
        }
        if d < 0 && d.unsigned_abs() <= self.reorder_ticks {
            self.suspect = None;
            return Unwrapped::Reordered(self.last - d.unsigned_abs().min(self.last));
        }
        // Suspect: does it continue an earlier suspect lineage?
        let continues = match self.suspect {
            Some((s_raw, _)) => {
                let ds = self.diff(s_raw, raw);
                ds >= -(self.reorder_ticks as i64) && ds <= self.max_forward_ticks as i64
            }
            None => false,
        };
        let count = if continues {
            self.suspect.map(|s| s.1).unwrap_or(0) + 1
        } else {
            1
        };
        self.suspect = Some((raw, count));
        if count >= self.confirm {
            self.suspect = None;
            if d > 0 {
                // A long forward gap confirmed: keep counting through it.
                self.last_raw = raw;
                self.last += d as u64;
                return Unwrapped::Ok(self.last);
            }
            // A reset: start a new segment well after the old one so that
            // unwrapped values stay increasing.
            self.last_raw = raw;
            self.last += self.max_forward_ticks;
            return Unwrapped::Reset(self.last);
        }
        if d < 0 {
            Unwrapped::Backwards {
                ticks: d.unsigned_abs(),
            }
        } else {
            Unwrapped::JumpForward { ticks: d as u64 }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwraps_any_width() {
        for bits in [8u32, 12, 16, 24, 32, 48, 64] {
            let m: u128 = 1u128 << bits;
            let step = if bits == 64 {
                1_000_000
            } else {
                (m / 7) as u64
            };
            let mut u = Unwrapper::new(bits, 0, u64::MAX);
            // A 64-bit counter never wraps in practice (584 years at 1 GHz).
            let start: u64 = if bits == 64 {
                1 << 40
            } else {
                (m - 3 * step as u128) as u64
            };
            let mut truth = start as u128;
            assert_eq!(u.push(start), Unwrapped::Ok(start));
            for _ in 0..20 {
                truth += step as u128;
                let raw = (truth % m) as u64;
                match u.push(raw) {
                    Unwrapped::Ok(v) => assert_eq!(v as u128, truth, "bits {bits}"),
                    other => panic!("bits {bits}: {other:?}"),
                }
            }
            if bits < 64 {
                assert!(u.wraps >= 2, "bits {bits}");
            }
        }
    }

    #[test]
    fn backwards_is_detected_and_a_reset_confirmed() {
        let mut u = Unwrapper::new(32, 100, 10_000_000);
        assert_eq!(u.push(5_000_000), Unwrapped::Ok(5_000_000));
        assert_eq!(u.push(5_005_000), Unwrapped::Ok(5_005_000));
        // slight reorder
        assert_eq!(u.push(5_004_950), Unwrapped::Reordered(5_004_950));
        // a single corrupt value going back: skipped, lineage kept
        assert_eq!(u.push(1_000), Unwrapped::Backwards { ticks: 5_004_000 });
        assert_eq!(u.push(5_010_000), Unwrapped::Ok(5_010_000));
        // a real reset: three records on the new lineage confirm it
        assert!(matches!(u.push(100), Unwrapped::Backwards { .. }));
        assert!(matches!(u.push(5_100), Unwrapped::Backwards { .. }));
        let Unwrapped::Reset(base) = u.push(10_100) else {
            panic!()
        };
        assert!(base > 5_010_000);
        assert_eq!(u.push(15_100), Unwrapped::Ok(base + 5_000));
    }
}
