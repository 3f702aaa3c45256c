//! Numeric arguments checked when they are parsed (issue 32): every
//! number a command takes is finite and inside a stated range, and the
//! error names the flag, the value and the range. A value outside what
//! makes physical sense is refused before any work starts: 1e300 s of
//! offset search, a 1e300 Hz rate or NaN σ would otherwise allocate without
//! bound, divide by zero or run forever, or be used silently.
//!
//! The bounds below are the ranges any real rig reaches, with a margin;
//! each says why.

use std::ffi::OsStr;

use clap::builder::{RangedI64ValueParser, RangedU64ValueParser, TypedValueParser};
use clap::error::{Error, ErrorKind};

/// Longest time span (s): one GPS week. Every time in the formats is
/// seconds of week, and a simulation or a drive longer than a week is
/// not a single run.
pub const MAX_SPAN_S: f64 = 604_800.0;
/// Highest sampling rate (Hz): MEMS IMUs sample internally at up to tens of
/// kHz (an ADIS16465 at 2 kHz, ICM parts at 8–32 kHz); 1 MHz is far beyond
/// any of them and keeps every period above a microsecond (the time base
/// is 1 ns).
pub const MAX_RATE_HZ: f64 = 1.0e6;
/// Largest time offset or latency (s): a sensor's delay, a message's
/// latency or an IMU–GNSS offset is milliseconds to a second; beyond a
/// minute the clocks are wrong (e.g. GPS vs UTC: 18 s), not offset.
pub const MAX_OFFSET_S: f64 = 60.0;
/// Largest coarse search range of the IMU–GNSS time offset (±s): the
/// library's bound on the search grid's memory and the reason for it
/// (`TimeOffsetOptions::MAX_SEARCH_RANGE_S`).
pub const MAX_OFFSET_SEARCH_S: f64 = navsync::fusion::TimeOffsetOptions::MAX_SEARCH_RANGE_S;
/// Largest standard deviation or distance in metres: 1000 km, beyond
/// any GNSS solution's error (a fix with a σ over 1 km is refused by
/// the filter anyway) or any lever arm.
pub const MAX_LENGTH_M: f64 = 1.0e6;
/// Largest speed (m/s, m/s² spreads): 1000, beyond any land vehicle,
/// drone or aircraft that navsync fuses.
pub const MAX_SPEED_MPS: f64 = 1000.0;
/// Largest count of parallel jobs asked for (`--jobs`); the count used is
/// further capped at the machine's cores ([`jobs`]).
pub const MAX_JOBS: u64 = 4096;
/// Largest number of runs, repetitions or printed lines.
pub const MAX_COUNT: u64 = 1_000_000;

/// A real number in `[lo, hi]` (or `(lo, hi]`), with its unit for the
/// message. A clap value parser (`#[arg(value_parser = args::positive(…))]`).
#[derive(Clone, Copy, Debug)]
pub struct Real {
    lo: f64,
    hi: f64,
    lo_open: bool,
    unit: &'static str,
}

/// A number in `[lo, hi]` (`unit`, e.g. "s", "Hz", "deg").
pub const fn real(lo: f64, hi: f64, unit: &'static str) -> Real {
    Real {
        lo,
        hi,
        lo_open: false,
        unit,
    }
}

/// A number in `(0, hi]`: durations, rates, σ.
pub const fn positive(hi: f64, unit: &'static str) -> Real {
    Real {
        lo: 0.0,
        hi,
        lo_open: true,
        unit,
    }
}

/// A number in `[0, hi]` (0 usually meaning "off" or "every sample").
pub const fn non_negative(hi: f64, unit: &'static str) -> Real {
    real(0.0, hi, unit)
}

/// A standard deviation in `[1e-9, hi]`: a σ below a nanounit is a
/// filter trusting beyond float precision (its variance's inverse
/// overflows the gain), not a sensor.
pub const fn sigma(hi: f64, unit: &'static str) -> Real {
    real(1e-9, hi, unit)
}

/// A sampling rate in `[1 mHz, MAX_RATE_HZ]`: below 1 mHz a period no
/// longer fits the nanosecond time base's week, above see [`MAX_RATE_HZ`].
pub const fn rate() -> Real {
    real(1e-3, MAX_RATE_HZ, "Hz")
}

/// A random seed in `0..=2^53`: seeds are written to JSON
/// (scenario.json, montecarlo.json) and read by Python as doubles, exact
/// up to 2^53; consecutive seeds (`--first-seed` + run) must not wrap.
pub fn seed() -> RangedU64ValueParser<u64> {
    RangedU64ValueParser::<u64>::new().range(0..=(1u64 << 53))
}

/// A number in `[-hi, hi]`.
pub const fn symmetric(hi: f64, unit: &'static str) -> Real {
    real(-hi, hi, unit)
}

impl Real {
    /// `s` as a number inside the range, or why not.
    pub fn check(&self, s: &str) -> Result<f64, String> {
        let x: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("not a number; expected {}", self.expected()))?;
        let above_lo = if self.lo_open {
            x > self.lo
        } else {
            x >= self.lo
        };
        if x.is_finite() && above_lo && x <= self.hi {
            Ok(x)
        } else {
            Err(format!("out of range; expected {}", self.expected()))
        }
    }

    fn expected(&self) -> String {
        let open = if self.lo_open { "(" } else { "[" };
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!("a number in {open}{}, {}]{unit}", self.lo, self.hi)
    }
}

/// The clap error for `value` of `arg`: "invalid value 'V' for '--flag
/// <X>': WHY".
fn invalid(cmd: &clap::Command, arg: Option<&clap::Arg>, value: &str, why: &str) -> Error {
    let name = arg.map_or_else(|| "the value".to_string(), |a| format!("'{a}'"));
    Error::raw(
        ErrorKind::ValueValidation,
        format!("invalid value '{value}' for {name}: {why}\n"),
    )
    .with_cmd(cmd)
}

impl TypedValueParser for Real {
    type Value = f64;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<f64, Error> {
        let s = value.to_string_lossy();
        self.check(&s).map_err(|why| invalid(cmd, arg, &s, &why))
    }
}

/// Three comma-separated numbers, each in `r` (lever arms, σ per axis,
/// mounting angles).
#[derive(Clone, Copy, Debug)]
pub struct Triplet(pub Real);

impl TypedValueParser for Triplet {
    type Value = [f64; 3];

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<[f64; 3], Error> {
        let s = value.to_string_lossy();
        let parts: Vec<&str> = s.split(',').collect();
        if parts.len() != 3 {
            return Err(invalid(
                cmd,
                arg,
                &s,
                "expected three comma-separated numbers",
            ));
        }
        let mut out = [0.0; 3];
        for (o, p) in out.iter_mut().zip(&parts) {
            *o = self
                .0
                .check(p)
                .map_err(|why| invalid(cmd, arg, &s, &format!("'{}' is {why}", p.trim())))?;
        }
        Ok(out)
    }
}

/// An unsigned count in `lo..=hi` (clap's own message names the range).
pub fn count(lo: u64, hi: u64) -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::<usize>::new().range(lo..=hi)
}

/// A `u32` in `lo..=hi`.
pub fn count_u32(lo: u64, hi: u64) -> RangedU64ValueParser<u32> {
    RangedU64ValueParser::<u32>::new().range(lo..=hi)
}

/// An `i64` in `lo..=hi`.
pub fn int(lo: i64, hi: i64) -> RangedI64ValueParser<i64> {
    RangedI64ValueParser::<i64>::new().range(lo..=hi)
}

/// Threads for `--jobs N`: N capped at the machine's cores (more threads
/// than cores only contend; thousands exhaust the process), with a note on
/// stderr when capped; the cores when not given.
pub fn jobs(asked: Option<usize>) -> usize {
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    match asked {
        Some(n) if n > cores => {
            eprintln!("navsync: note: --jobs {n} capped at the {cores} cores of this machine");
            cores
        }
        Some(n) => n,
        None => cores,
    }
}

/// Refuses an output path that is one of the inputs (writing it would
/// truncate the input before it is read): `what` names the output flag.
/// Paths are compared canonicalised (an output that does not exist yet
/// is not an input); `-` (standard input) is never a file.
pub fn refuse_output_over_input(
    output: &std::path::Path,
    inputs: &[&std::path::Path],
    what: &str,
) -> anyhow::Result<()> {
    let Ok(out) = output.canonicalize() else {
        return Ok(());
    };
    for input in inputs {
        if input.as_os_str() == "-" {
            continue;
        }
        if input.canonicalize().is_ok_and(|i| i == out) {
            anyhow::bail!(
                "{what} {} would overwrite the input {}: choose another output",
                output.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Every argument of `cmd` and its subcommands that takes numbers, as
/// `path<TAB>--flag<TAB>kind` lines (kind `real`, `real3` for three
/// comma-separated numbers, `int`): what the hidden `navsync
/// __numeric-args` prints for the CLI's property test
/// (tests/numeric_args.rs), so that a flag added later is tried too.
pub fn numeric_args(cmd: &clap::Command) -> Vec<String> {
    use std::any::TypeId;
    let mut out = Vec::new();
    let mut stack = vec![(String::new(), cmd)];
    while let Some((path, c)) = stack.pop() {
        for a in c.get_arguments() {
            let Some(long) = a.get_long() else { continue };
            let id = a.get_value_parser().type_id();
            let kind = if id == TypeId::of::<f64>() {
                "real"
            } else if id == TypeId::of::<[f64; 3]>() {
                "real3"
            } else if id == TypeId::of::<[f64; 2]>() {
                "real2"
            } else if [
                TypeId::of::<u8>(),
                TypeId::of::<u32>(),
                TypeId::of::<u64>(),
                TypeId::of::<usize>(),
                TypeId::of::<i64>(),
            ]
            .iter()
            .any(|t| id == *t)
            {
                "int"
            } else {
                continue;
            };
            out.push(format!("{}\t--{long}\t{kind}", path.trim()));
        }
        for s in c.get_subcommands() {
            stack.push((format!("{path} {}", s.get_name()), s));
        }
    }
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_refuses_non_finite_and_out_of_range() {
        let r = positive(10.0, "s");
        for bad in ["NaN", "nan", "inf", "-inf", "1e300", "0", "-1", "x", "10.5"] {
            assert!(r.check(bad).is_err(), "{bad}");
        }
        assert_eq!(r.check("1e-300"), Ok(1e-300));
        assert_eq!(r.check(" 10 "), Ok(10.0));
        let e = r.check("NaN").unwrap_err();
        assert!(e.contains("(0, 10] s"), "{e}");
        let z = non_negative(1.0, "");
        assert_eq!(z.check("0"), Ok(0.0));
        assert!(z.check("-0.1").is_err());
    }

    #[test]
    fn jobs_capped_at_cores() {
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        assert_eq!(jobs(Some(100_000)), cores);
        assert_eq!(jobs(Some(1)), 1);
        assert_eq!(jobs(None), cores);
    }
}
