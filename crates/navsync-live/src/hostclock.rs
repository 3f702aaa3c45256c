//! The one host clock every arrival is stamped with, and CPU time.
//!
//! Stamps are `CLOCK_MONOTONIC_RAW` in nanoseconds: never stepped nor
//! slewed by NTP, so [`navsync::timing::SyncEngine`] can model it as a
//! free-running 64-bit counter at 1 GHz whose frequency error and drift the
//! 1PPS edges reveal (seed 001 §2.1). Kernel PPS timestamps are
//! `CLOCK_REALTIME` (RFC 2783 `pps_fetch`, Linux `pps_get_ts`); they are
//! moved onto this clock with [`realtime_to_raw`].

/// Nominal rate of the host counter (Hz).
pub const COUNTER_HZ: f64 = 1e9;

// time_t and c_long are 32 bits on some targets: the conversions are not no-ops everywhere.
#[allow(clippy::useless_conversion)]
fn now(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; clock_gettime only writes it.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
    if rc != 0 {
        return 0;
    }
    i64::from(ts.tv_sec) * 1_000_000_000 + i64::from(ts.tv_nsec)
}

/// The host counter now: `CLOCK_MONOTONIC_RAW` (ns).
#[inline]
pub fn now_ns() -> u64 {
    now(libc::CLOCK_MONOTONIC_RAW).max(0) as u64
}

/// `CLOCK_REALTIME` now (ns since 1970).
pub fn realtime_ns() -> i64 {
    now(libc::CLOCK_REALTIME)
}

/// Converts a `CLOCK_REALTIME` stamp (ns) taken moments ago to the host
/// counter: the offset REALTIME − MONOTONIC_RAW is read now, between two
/// raw readings (midpoint). The offset changes only by NTP slewing
/// (≤ 500 ppm) or a step: a stamp milliseconds old is converted to within
/// nanoseconds, and a stepped clock shows as a displaced pulse, which the
/// clock model rejects.
pub fn realtime_to_raw(real_ns: i64) -> u64 {
    let r1 = now(libc::CLOCK_MONOTONIC_RAW);
    let re = now(libc::CLOCK_REALTIME);
    let r2 = now(libc::CLOCK_MONOTONIC_RAW);
    let offset = re - (r1 + (r2 - r1) / 2);
    (real_ns - offset).max(0) as u64
}

/// CPU time of this process, all threads (s), from `getrusage`
/// (user + system, µs resolution).
pub fn cpu_seconds() -> f64 {
    // SAFETY: an all-zero rusage is a valid value; getrusage only writes it.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `ru` is valid and writable.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) } != 0 {
        return f64::NAN;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(ru.ru_utime) + tv(ru.ru_stime)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_clock_advances_and_realtime_converts() {
        let a = now_ns();
        let real = realtime_ns();
        let b = now_ns();
        let raw = realtime_to_raw(real);
        assert!(b >= a);
        // The converted stamp lies between the raw readings (± slew, µs).
        assert!(raw + 50_000 >= a && raw <= b + 50_000, "{a} {raw} {b}");
        assert!(cpu_seconds() >= 0.0);
    }
}
