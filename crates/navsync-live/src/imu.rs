//! The IMU on a serial port: the text line formats accepted, and the
//! timing of each sample from the arrival times of its lines.
//!
//! Line formats (one sample a line, fields split by any mix of spaces, tabs
//! or commas as in FORMATS.md; blank lines and `#` lines ignored):
//! - `rate`: `gx gy gz ax ay az` — gyro rad/s, then specific force m/s²,
//!   body FRD: the six value fields of a rig-log `imu` record without its
//!   counter;
//! - `increment`: `dtx dty dtz dvx dvy dvz` — rad, m/s over the interval
//!   that ends at the sample;
//! - `rate-csv`: `t gx gy gz ax ay az` — the `navsync convert --format
//!   rate-csv` line; the sensor's own time `t` is not used (the arrival time
//!   stamps the sample).
//!
//! Timing. An IMU without a sync pin is timed by its serial frames (seed
//! 000): the host stamps each line's arrival, `h_k = t_k + T_c + μ_k` with
//! the output delay `T_c` (configured, subtracted by the engine) and a
//! transmission/scheduling delay `μ_k ≥ 0`. Several lines read together
//! share one stamp, so raw arrivals would look duplicated or irregular:
//! a line read with `n` more behind it arrived at least `n` periods before
//! the read.
//! [`ArrivalTimer`] replaces each arrival by the lower envelope of
//! arrival vs sample index (seed 001 §2.2, TICSync; [`EnvelopeFit`]) fitted
//! causally over the last seconds (for the first 200 samples, with the
//! nominal period as slope): the sample clock up to the fastest delay.
//! When the envelope improves (a faster arrival than any before, a refit)
//! the stamps come down to it by at most a quarter period per sample, so
//! consecutive stamps stay 0.75–1.25 periods apart. The index comes from the line count: a corrupted sample line
//! (a bad line of about a sample line's length; one twice as long is two
//! merged samples) advances it, a short junk line does not. A sample that
//! vanishes without a trace is not inferred from timing: on a loaded host,
//! late arrivals for a while look the same (an IMU that numbers its samples
//! would tell).

use std::collections::VecDeque;

use navsync::io::riglog::ImuKind;
use navsync::io::text::{is_blank_or_comment, parse_f64, split_fields};
use navsync::timing::fit::EnvelopeFit;

/// Which line format the IMU port carries.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ImuLineFormat {
    Rate,
    Increment,
    RateCsv,
}

impl ImuLineFormat {
    /// Meaning of the six values.
    pub fn kind(self) -> ImuKind {
        match self {
            ImuLineFormat::Increment => ImuKind::Increment,
            _ => ImuKind::Rate,
        }
    }

    fn fields(self) -> usize {
        match self {
            ImuLineFormat::RateCsv => 7,
            _ => 6,
        }
    }

    /// Parses one line: `Ok(None)` for blank and comment lines.
    pub fn parse(self, line: &[u8]) -> Result<Option<[f64; 6]>, String> {
        if is_blank_or_comment(line) {
            return Ok(None);
        }
        let want = self.fields();
        let mut f: [&[u8]; 8] = [b""; 8];
        let n = split_fields(line, &mut f);
        if n != want {
            return Err(format!(
                "expected {want} fields ({}), found {n}",
                match self {
                    ImuLineFormat::Rate => "gx gy gz rad/s, ax ay az m/s²",
                    ImuLineFormat::Increment => "dθ xyz rad, dv xyz m/s",
                    ImuLineFormat::RateCsv => "t, gx gy gz rad/s, ax ay az m/s²",
                }
            ));
        }
        let first = want - 6;
        let mut v = [0.0; 6];
        for (k, x) in v.iter_mut().enumerate() {
            *x = parse_f64(f[first + k]).map_err(|e| format!("field {}: {e}", first + k + 1))?;
        }
        Ok(Some(v))
    }
}

/// Splits a byte stream into lines (LF or CR LF), bounded: a line longer
/// than `max_len` is cut off and reported as bad.
#[derive(Debug)]
pub struct LineSplitter {
    buf: Vec<u8>,
    max_len: usize,
    overflow: bool,
}

impl LineSplitter {
    pub fn new(max_len: usize) -> Self {
        LineSplitter {
            buf: Vec::with_capacity(max_len),
            max_len,
            overflow: false,
        }
    }

    /// Forgets a partial line (after a reconnect).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.overflow = false;
    }

    /// Feeds bytes; calls `line(bytes, too_long)` for every complete line.
    pub fn push(&mut self, mut bytes: &[u8], mut line: impl FnMut(&[u8], bool)) {
        while let Some(i) = memchr_lf(bytes) {
            let (head, rest) = bytes.split_at(i);
            if !self.overflow {
                let room = self.max_len.saturating_sub(self.buf.len());
                self.overflow = head.len() > room;
                self.buf.extend_from_slice(&head[..head.len().min(room)]);
            }
            let mut l = self.buf.as_slice();
            if l.last() == Some(&b'\r') {
                l = &l[..l.len() - 1];
            }
            line(l, self.overflow);
            self.buf.clear();
            self.overflow = false;
            bytes = &rest[1..];
        }
        let room = self.max_len.saturating_sub(self.buf.len());
        if bytes.len() > room {
            self.overflow = true;
        }
        self.buf.extend_from_slice(&bytes[..bytes.len().min(room)]);
    }
}

fn memchr_lf(b: &[u8]) -> Option<usize> {
    b.iter().position(|&c| c == b'\n')
}

/// Points before the envelope's slope is fitted (at 200 Hz, one second).
const MIN_FIT_POINTS: usize = 200;

/// Causal lower-envelope timing of periodic samples from their arrivals
/// (see the module notes).
#[derive(Clone, Debug)]
pub struct ArrivalTimer {
    nominal_period_ns: f64,
    window_s: f64,
    /// (index, arrival ns relative to `origin`) over the window.
    points: VecDeque<(f64, f64)>,
    origin: Option<u64>,
    next_k: i64,
    /// Lower envelope with the nominal period until a fit exists:
    /// min over samples of (arrival − index · nominal period).
    base: f64,
    fit: Option<EnvelopeFit>,
    /// The previous stamp (index, ns from origin): stamps come down to a
    /// lower envelope by at most a quarter period per sample.
    last: Option<(f64, f64)>,
    since_fit: usize,
    /// Typical length of a sample line (bytes, running mean).
    line_len: Option<f64>,
    /// Lost samples counted so far (corrupted lines).
    pub lost: u64,
    /// Times the envelope was restarted (a source reopened, or an
    /// arrival well before the envelope: the rate changed).
    pub restarts: u64,
}

impl ArrivalTimer {
    /// A timer for a nominal rate (Hz); the envelope spans `window_s`.
    pub fn new(rate_hz: f64, window_s: f64) -> Self {
        ArrivalTimer {
            nominal_period_ns: 1e9 / rate_hz,
            window_s,
            points: VecDeque::new(),
            origin: None,
            next_k: 0,
            base: f64::INFINITY,
            fit: None,
            last: None,
            since_fit: 0,
            line_len: None,
            lost: 0,
            restarts: 0,
        }
    }

    /// Starts afresh (the source was reopened: a gap of unknown length).
    pub fn restart(&mut self) {
        self.points.clear();
        self.origin = None;
        self.next_k = 0;
        self.base = f64::INFINITY;
        self.fit = None;
        self.last = None;
        self.since_fit = 0;
        self.restarts += 1;
    }

    fn period(&self) -> f64 {
        self.fit
            .as_ref()
            .map(|f| f.slope(0.0))
            .filter(|p| p.is_finite() && *p > 0.2 * self.nominal_period_ns)
            .unwrap_or(self.nominal_period_ns)
    }

    fn refit(&mut self) {
        let pts = self.points.make_contiguous();
        self.fit = EnvelopeFit::fit(pts, 1).filter(|f| f.degree() == 1);
        self.since_fit = 0;
    }

    /// A good sample line of `len` bytes (learns the typical length).
    pub fn note_line_len(&mut self, len: usize) {
        let l = len as f64;
        self.line_len = Some(match self.line_len {
            None => l,
            Some(m) => m + (l - m) / 64.0,
        });
    }

    /// A bad line of `len` bytes: how many samples it stood for (0 for
    /// junk shorter than half a sample line, or before any sample line);
    /// the index advances by that many (counted as lost).
    pub fn bad_line(&mut self, len: usize) -> u32 {
        let Some(m) = self.line_len.filter(|m| *m > 0.0) else {
            return 0;
        };
        let slots = (len as f64 / m).round().min(1000.0) as u32;
        if (len as f64) < 0.5 * m || self.origin.is_none() {
            return 0;
        }
        self.next_k += slots as i64;
        self.lost += slots as u64;
        slots
    }

    /// The sample whose line arrived at host counter `arrival_ns`, read
    /// together with `behind` more sample lines: those queued behind it, so
    /// it arrived at least that many nominal periods earlier.
    pub fn push(&mut self, arrival_ns: u64, behind: usize) -> u64 {
        let arrival_ns = arrival_ns.saturating_sub((behind as f64 * self.nominal_period_ns) as u64);
        let x = self.next_k as f64;
        self.next_k += 1;
        self.add(x, arrival_ns)
    }

    /// A sample that carries its own time tag: `x` is its sensor time in
    /// nominal periods (from any origin), `arrival_ns` the arrival of the
    /// message that held it (ESF-RAW: several samples per message).
    pub fn push_tagged(&mut self, x: f64, arrival_ns: u64) -> u64 {
        self.add(x, arrival_ns)
    }

    fn add(&mut self, x: f64, arrival_ns: u64) -> u64 {
        let origin = *self.origin.get_or_insert(arrival_ns);
        let h = arrival_ns.saturating_sub(origin) as f64;
        if let Some(f) = &self.fit
            && h - f.eval(x) < -0.5 * self.period()
        {
            // Earlier than the sample clock allows: the rate changed.
            let k = self.next_k;
            self.restart();
            self.next_k = k;
            return self.add(x, arrival_ns);
        }
        self.base = self.base.min(h - x * self.nominal_period_ns);
        self.points.push_back((x, h));
        let span = self.window_s * 1e9;
        while self.points.front().is_some_and(|&(_, h0)| h - h0 > span) {
            self.points.pop_front();
        }
        self.since_fit += 1;
        // A free slope needs a second of points (a few jittered points give
        // a poor one); refit about once a second.
        if self.points.len() >= MIN_FIT_POINTS && self.since_fit >= MIN_FIT_POINTS {
            self.refit();
        }
        let env = match &self.fit {
            Some(f) => f.eval(x),
            None => self.base + x * self.nominal_period_ns,
        };
        // Not after the arrival; but a better envelope (a faster arrival
        // than all before, a refit) lowers the stamps gradually: never
        // closer than 3/4 of a period to the previous one, which takes
        // precedence (the engine would take a closer pair for a duplicate).
        let t = match self.last {
            Some((xl, tl)) => env
                .min(h)
                .max(tl + (x - xl) * 0.75 * self.nominal_period_ns),
            None => env.min(h),
        };
        self.last = Some((x, t));
        origin + t.max(0.0).round() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_parse_and_reject() {
        let v = ImuLineFormat::Rate
            .parse(b"1e-3, -2e-3 5e-4\t0.1,0.05,-9.79")
            .unwrap()
            .unwrap();
        assert_eq!(v[5], -9.79);
        assert_eq!(ImuLineFormat::Rate.parse(b"# hello").unwrap(), None);
        assert!(
            ImuLineFormat::Rate
                .parse(b"1 2 3")
                .unwrap_err()
                .contains("expected 6")
        );
        assert!(
            ImuLineFormat::Rate
                .parse(b"1 2 3 4 5 x")
                .unwrap_err()
                .contains("field 6")
        );
        let v = ImuLineFormat::RateCsv
            .parse(b"12.5,1,2,3,4,5,6")
            .unwrap()
            .unwrap();
        assert_eq!(v, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert!(ImuLineFormat::Increment.parse(b"\xff\xfe garbage").is_err());
    }

    #[test]
    fn lines_split_across_reads_and_long_lines_are_cut() {
        let mut s = LineSplitter::new(16);
        let mut got = Vec::new();
        s.push(b"ab", |l, t| got.push((l.to_vec(), t)));
        s.push(b"c\r\nde", |l, t| got.push((l.to_vec(), t)));
        s.push(b"f\n0123456789012345678\nok\n", |l, t| {
            got.push((l.to_vec(), t))
        });
        assert_eq!(got[0], (b"abc".to_vec(), false));
        assert_eq!(got[1], (b"def".to_vec(), false));
        assert!(got[2].1);
        assert_eq!(got[3], (b"ok".to_vec(), false));
    }

    /// Arrivals of a 200 Hz IMU (+50 ppm) with delays of 0.1–1 ms, every
    /// 50th line held 12 ms (its successors wait behind it), one sample
    /// line corrupted and one junk line.
    #[test]
    fn envelope_recovers_the_sample_clock() {
        let mut t = ArrivalTimer::new(200.0, 10.0);
        let period = 5e6 * (1.0 + 50e-6);
        let t0 = 1_000_000_000u64;
        let mut worst = 0.0f64;
        let mut prev = 0u64;
        let mut last_stamp: Option<(u64, u64)> = None;
        // (k, true time, arrival); a read returns every line that arrived
        // by then: lines sharing an arrival are one read.
        let mut arrivals = Vec::new();
        for k in 0..4000u64 {
            if k == 3000 {
                continue; // its line is corrupted
            }
            let true_ns = t0 as f64 + k as f64 * period;
            let mut d = 1e5 + ((k * 7919) % 1000) as f64 * 900.0;
            if k % 50 == 0 {
                d += 12e6;
            }
            if k == 0 {
                d += 40e6; // the first lines come in one read
            }
            // bytes arrive in order: a held line holds up its successors
            let arrival = ((true_ns + d) as u64).max(prev);
            prev = arrival;
            arrivals.push((k, true_ns, arrival));
        }
        for (i, &(k, true_ns, arrival)) in arrivals.iter().enumerate() {
            if k == 3001 {
                assert_eq!(t.bad_line(118), 1); // corrupted sample line
            }
            if k == 3500 {
                assert_eq!(t.bad_line(20), 0); // junk between samples
            }
            let behind = arrivals[i + 1..]
                .iter()
                .take_while(|a| a.2 == arrival)
                .count();
            t.note_line_len(120);
            let s = t.push(arrival, behind);
            // Regular spacing from the first sample on (the engine would
            // call a closer pair a duplicate).
            if let Some((kp, sp)) = last_stamp {
                let d = (s - sp) as f64 / ((k - kp) as f64 * period);
                assert!((0.74..1.26).contains(&d), "sample {k}: spacing {d} periods");
            }
            last_stamp = Some((k, s));
            if k > 300 {
                worst = worst.max((s as f64 - (true_ns + 1e5)).abs());
            }
        }
        assert_eq!((t.lost, t.restarts), (1, 0));
        // within 50 µs of the sample clock (+ the fastest delay), against
        // delays of up to 1 ms and 12 ms holds
        assert!(worst < 5e4, "worst {worst} ns");
    }
}
