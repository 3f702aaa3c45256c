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
//! Timing. An IMU without a sync pin is timed by its serial frames
//! (Liu et al., "Data synchronization in IMU/GPS integrated measurement
//! system of vehicle motion parameters"): the host stamps each line's
//! arrival, `h_k = t_k + T_c + μ_k` with the output delay `T_c`
//! (configured, subtracted by the engine) and a transmission/scheduling
//! delay `μ_k ≥ 0`. The engine's hybrid sync turns these receive times
//! into sample instants with the core's sample clock
//! ([`navsync::timing::sampleclock`]: the lower envelope of receive time
//! vs sample index, Harrison & Newman, "TICSync", ICRA 2011). What only
//! the reader knows goes with each sample ([`LineFeed`]):
//! - several lines read together share one stamp: how many sample lines
//!   came after each in its read goes with it (the sample clock takes it
//!   as received that many periods earlier);
//! - a corrupted sample line (a bad line of about a sample line's length;
//!   one twice as long is two merged samples) is a sample known lost; a
//!   short junk line is not;
//! - a reopened port starts a new segment of the sample clock.
//!
//! ESF samples (UBX ESF-RAW) carry their sensor time tags: [`TagTimer`]
//! maps them to the host counter by the lower envelope of message arrival
//! vs tag (the sample clock numbers samples by their arrivals; it does not
//! take given indices).

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

/// What the reader knows about one serial sample line, for the engine.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) struct LineSample {
    /// Sample lines read after it together (they share the read's stamp).
    pub behind: u32,
    /// Samples known lost just before it (corrupted lines).
    pub lost_before: u32,
    /// First sample since the port was reopened.
    pub restart: bool,
}

/// What the reader of a serial IMU port knows about its lines (see the
/// module notes); the timing itself is the engine's.
#[derive(Clone, Debug)]
pub(crate) struct LineFeed {
    /// Typical length of a sample line (bytes, running mean).
    line_len: Option<f64>,
    /// A sample line came since the port was (re)opened.
    seen_sample: bool,
    reopened: bool,
    lost_pending: u32,
}

impl LineFeed {
    pub(crate) fn new() -> Self {
        LineFeed {
            line_len: None,
            seen_sample: false,
            reopened: false,
            lost_pending: 0,
        }
    }

    /// The port was reopened (a gap of unknown length).
    pub(crate) fn reopen(&mut self) {
        self.reopened = true;
        self.seen_sample = false;
        self.lost_pending = 0;
    }

    /// A bad line of `len` bytes: how many samples it stood for (0 for
    /// junk shorter than half a sample line, or before any sample line
    /// since the port opened); they go with the next sample as known lost.
    pub(crate) fn bad_line(&mut self, len: usize) -> u32 {
        let Some(m) = self.line_len.filter(|m| *m > 0.0) else {
            return 0;
        };
        if (len as f64) < 0.5 * m || !self.seen_sample {
            return 0;
        }
        let slots = (len as f64 / m).round().min(1000.0) as u32;
        self.lost_pending = self.lost_pending.saturating_add(slots);
        slots
    }

    /// A good sample line of `len` bytes read together with `behind` more
    /// sample lines after it.
    pub(crate) fn sample(&mut self, len: usize, behind: usize) -> LineSample {
        let l = len as f64;
        self.line_len = Some(match self.line_len {
            None => l,
            Some(m) => m + (l - m) / 64.0,
        });
        self.seen_sample = true;
        LineSample {
            behind: behind.min(u32::MAX as usize) as u32,
            lost_before: std::mem::take(&mut self.lost_pending),
            restart: std::mem::take(&mut self.reopened),
        }
    }
}

/// Points before the envelope's slope is fitted (at 200 Hz, one second).
const MIN_FIT_POINTS: usize = 200;

/// Causal lower-envelope timing of time-tagged samples from the arrivals
/// of the messages that held them (ESF-RAW): the envelope of arrival vs
/// tag over the last seconds (for the first 200 samples, with the nominal
/// period as slope). When the envelope improves (a faster arrival than any
/// before, a refit) the stamps come down to it by at most a quarter period
/// per sample, so consecutive stamps stay at least 0.75 periods apart.
#[derive(Clone, Debug)]
pub(crate) struct TagTimer {
    nominal_period_ns: f64,
    window_s: f64,
    /// (tag in periods, arrival ns relative to `origin`) over the window.
    points: VecDeque<(f64, f64)>,
    origin: Option<u64>,
    /// Lower envelope with the nominal period until a fit exists:
    /// min over samples of (arrival − tag · nominal period).
    base: f64,
    fit: Option<EnvelopeFit>,
    /// The previous stamp (tag, ns from origin).
    last: Option<(f64, f64)>,
    since_fit: usize,
    /// Times the envelope was restarted (a source reopened, or an
    /// arrival well before the envelope: the rate changed).
    pub(crate) restarts: u64,
}

impl TagTimer {
    /// A timer for a nominal rate (Hz); the envelope spans `window_s`.
    pub(crate) fn new(rate_hz: f64, window_s: f64) -> Self {
        TagTimer {
            nominal_period_ns: 1e9 / rate_hz,
            window_s,
            points: VecDeque::new(),
            origin: None,
            base: f64::INFINITY,
            fit: None,
            last: None,
            since_fit: 0,
            restarts: 0,
        }
    }

    /// Starts afresh (the source was reopened: a gap of unknown length).
    pub(crate) fn restart(&mut self) {
        self.points.clear();
        self.origin = None;
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

    /// The sample whose sensor time is `x` nominal periods (from any
    /// origin), held by a message that arrived at host counter `arrival_ns`.
    pub(crate) fn push_tagged(&mut self, x: f64, arrival_ns: u64) -> u64 {
        let origin = *self.origin.get_or_insert(arrival_ns);
        let h = arrival_ns.saturating_sub(origin) as f64;
        if let Some(f) = &self.fit
            && h - f.eval(x) < -0.5 * self.period()
        {
            // Earlier than the sample clock allows: the rate changed.
            self.restart();
            return self.push_tagged(x, arrival_ns);
        }
        self.base = self.base.min(h - x * self.nominal_period_ns);
        self.points.push_back((x, h));
        let span = self.window_s * 1e9;
        while self.points.front().is_some_and(|&(_, h0)| h - h0 > span) {
            self.points.pop_front();
        }
        self.since_fit += 1;
        // A free slope needs a second of points; refit about once a second.
        if self.points.len() >= MIN_FIT_POINTS && self.since_fit >= MIN_FIT_POINTS {
            let pts = self.points.make_contiguous();
            self.fit = EnvelopeFit::fit(pts, 1).filter(|f| f.degree() == 1);
            self.since_fit = 0;
        }
        let env = match &self.fit {
            Some(f) => f.eval(x),
            None => self.base + x * self.nominal_period_ns,
        };
        // Not after the arrival; a better envelope lowers the stamps
        // gradually (never closer than 3/4 of a period to the previous
        // one, which the engine would take for a duplicate).
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

    use navsync::io::riglog::{ImuTiming, RigGnss, RigHeader, RigRecord};
    use navsync::time::GpsTime;
    use navsync::timing::{SyncConfig, SyncEngine, SyncMode, SyncOutput};

    /// A line on the simulated IMU port.
    #[derive(Copy, Clone, Debug)]
    enum Line {
        /// Sample `k` taken at host ns `s`.
        Sample { k: u64, s: f64 },
        /// A corrupted sample line (as long as a good one).
        Corrupt,
        /// Short junk.
        Junk,
    }

    const T0: u64 = 1_000_000_000;
    const LINE_LEN: usize = 120;

    /// What came out of the live path: per sample k (stamp − truth ns,
    /// lost before it, emitted by the push of its own record), and the
    /// total lost.
    struct SimOut {
        err_ns: Vec<(u64, f64)>,
        lost_at: Vec<(u64, u32)>,
        late: Vec<u64>,
        stamped: usize,
    }

    /// Feeds `lines` (with their arrival times; lines sharing one are one
    /// read; `reopen_before` lines come after a reopened port) through
    /// [`LineFeed`] and a causal hybrid [`SyncEngine`] with a 50 ms
    /// lookahead, as the live loop does, with 1PPS and 10 Hz fixes 60 ms
    /// after each edge; host counter = GPS time + `T0`. `fastest` is the
    /// fastest delay (the constant receive times cannot see).
    fn run_live_path(lines: &[(Line, u64)], reopen_before: Option<usize>, fastest: f64) -> SimOut {
        let mut h = RigHeader::new(1e9, 64, navsync::io::riglog::ImuKind::Rate);
        h.imu_rate_hz = Some(200.0);
        h.imu_timing = Some(ImuTiming::Receive);
        let mut e = SyncEngine::new(
            &h,
            SyncConfig {
                mode: SyncMode::Hybrid,
                causal: true,
                reorder_tolerance_s: 1.5,
                hybrid_lookahead_s: Some(0.05),
                ..Default::default()
            },
        );
        let gps0 = GpsTime::from_week_sow(2400, 300_000.0);
        let gps = |host: f64| gps0.add_seconds((host - T0 as f64) * 1e-9);
        let end = lines.last().map_or(T0, |l| l.1);
        // Delivery order: (delivered at, record, sample k, what the reader knew).
        let mut ev: Vec<(u64, RigRecord, Option<u64>, Option<LineSample>)> = Vec::new();
        for n in 0..=((end - T0) / 1_000_000_000) {
            let c = T0 + n * 1_000_000_000;
            ev.push((c, RigRecord::Pps { counter: c }, None, None));
            for m in 0..10u64 {
                let valid = c + m * 100_000_000;
                let g = RigGnss {
                    counter: valid + 60_000_000,
                    time: gps(valid as f64),
                    lat_deg: 30.5,
                    lon_deg: 114.3,
                    h_m: 25.0,
                    sd_m: [1.0; 3],
                };
                ev.push((valid + 60_000_000, RigRecord::Gnss(g), None, None));
            }
        }
        let mut feed = LineFeed::new();
        let mut i = 0;
        while i < lines.len() {
            let arrival = lines[i].1;
            let j = i + lines[i..].iter().take_while(|l| l.1 == arrival).count();
            let read = &lines[i..j];
            let mut behind = read
                .iter()
                .filter(|l| matches!(l.0, Line::Sample { .. }))
                .count();
            for (o, (l, _)) in read.iter().enumerate() {
                if reopen_before == Some(i + o) {
                    feed.reopen();
                }
                match *l {
                    Line::Sample { k, .. } => {
                        behind -= 1;
                        let s = feed.sample(LINE_LEN, behind);
                        let values = [k as f64 * 1e-6, 0.0, 0.0, 0.0, 0.0, -9.8];
                        let rec = RigRecord::Imu {
                            counter: arrival,
                            values,
                        };
                        ev.push((arrival, rec, Some(k), Some(s)));
                    }
                    Line::Corrupt => assert_eq!(feed.bad_line(LINE_LEN), 1),
                    Line::Junk => assert_eq!(feed.bad_line(20), 0),
                }
            }
            i = j;
        }
        ev.sort_by_key(|e| e.0); // stable: a read's lines stay in order
        let truth: std::collections::HashMap<u64, f64> = lines
            .iter()
            .filter_map(|l| match l.0 {
                Line::Sample { k, s } => Some((k, s)),
                _ => None,
            })
            .collect();
        let mut seq_k = Vec::new();
        let mut o = SimOut {
            err_ns: Vec::new(),
            lost_at: Vec::new(),
            late: Vec::new(),
            stamped: 0,
        };
        let take = |outs: Vec<SyncOutput>, own: Option<u64>, seq_k: &Vec<u64>, o: &mut SimOut| {
            for x in outs {
                if let SyncOutput::Imu(s) = x {
                    assert!(!s.flags.unstamped);
                    let k = seq_k[s.seq as usize];
                    o.stamped += 1;
                    if s.flags.lost_before > 0 {
                        o.lost_at.push((k, s.flags.lost_before));
                    }
                    if own.is_some_and(|own| own != k) {
                        o.late.push(k);
                    }
                    let t = truth[&k] + fastest;
                    o.err_ns.push((k, (s.time - gps(t)) as f64));
                }
            }
        };
        for (_, rec, k, hint) in ev {
            if let Some(k) = k {
                seq_k.push(k);
            }
            if let Some(h) = hint {
                feed_engine(&mut e, h);
            }
            let locked = e.lock_state() == navsync::timing::LockState::Locked;
            let outs = e.push(rec);
            take(outs, k.filter(|_| locked), &seq_k, &mut o);
        }
        let (outs, _) = e.finish().unwrap();
        take(outs, None, &seq_k, &mut o);
        o
    }

    /// What the live loop tells the engine before a line's record.
    fn feed_engine(e: &mut SyncEngine, h: LineSample) {
        crate::live::hint_engine(e, h);
    }

    /// Arrival of sample `k` at `s` ns: 0.1–1.0 ms of delay spread over
    /// every 1000 samples, every 50th line held 12 ms (its successors
    /// wait behind it: bytes arrive in order).
    fn delay_ns(k: u64) -> f64 {
        let mut d = 1e5 + ((k * 7919) % 1000) as f64 * 900.0;
        if k.is_multiple_of(50) {
            d += 12e6;
        }
        d
    }

    /// The live path times serial lines with the core's sample clock: a
    /// 200 Hz IMU (+50 ppm), delays of 0.1–1 ms, 12 ms holds, lines read
    /// together, a corrupted sample line, a line that vanished without a
    /// trace, a junk line, and a reader stalled for 20 lines (one read, no
    /// loss). Both losses are found where they are, the
    /// stamps follow the sample clock, and lines on time are stamped by the
    /// push of their own record (no lookahead wait).
    #[test]
    fn serial_lines_are_timed_by_the_core_sample_clock() {
        let period = 5e6 * (1.0 + 50e-6);
        let mut lines = Vec::new();
        let mut prev = 0u64;
        for k in 0..4000u64 {
            let s = T0 as f64 + 0.2e9 + k as f64 * period;
            let mut arrival = ((s + delay_ns(k)) as u64).max(prev);
            if (2000..2020).contains(&k) {
                // The reader stalled 100 ms: 20 lines in one read, the
                // last 4.5 ms (0.9 periods) after its instant.
                arrival = (T0 as f64 + 0.2e9 + 2019.0 * period + 4.5e6) as u64;
            }
            prev = arrival;
            match k {
                3000 => lines.push((Line::Corrupt, arrival)),
                3500 => {} // vanished
                _ => lines.push((Line::Sample { k, s }, arrival)),
            }
            if k == 2500 {
                lines.push((Line::Junk, arrival));
            }
        }
        let o = run_live_path(&lines, None, 1e5);
        assert_eq!(o.stamped, 3998);
        assert_eq!(o.lost_at, vec![(3001, 1), (3501, 1)]);
        // An envelope through n points a second whose delays spread over
        // D = 0.9 ms lies within about D/n = 4.5 µs of the fastest delay;
        // 10·D/n leaves room for the fit's ends. From 1 s after lock (4 s).
        let bound = 10.0 * 0.9e6 / 200.0;
        let worst = o
            .err_ns
            .iter()
            .filter(|(k, _)| *k > 1000)
            .map(|(_, e)| e.abs())
            .fold(0.0, f64::max);
        assert!(worst < bound, "worst {worst} ns > {bound}");
        // Only the stalled read (late against the line: released by the
        // next line on time) and the sample after the vanished line (a
        // period late: 50 ms of reads, 10 samples) waited, with those
        // queued behind them.
        assert!(
            o.late.contains(&2000) && o.late.contains(&3501),
            "{:?}",
            o.late
        );
        assert!(
            o.late
                .iter()
                .all(|k| (2000..2022).contains(k) || (3501..3513).contains(k)),
            "{:?}",
            o.late
        );
    }

    /// A reopened port: the IMU comes back 1 s later on another phase. A
    /// new segment of the sample clock: the gap counted as lost samples
    /// (its length in periods), and the new phase found.
    #[test]
    fn a_reopened_port_starts_a_new_segment() {
        let period = 5e6 * (1.0 + 50e-6);
        let mut lines = Vec::new();
        let mut prev = 0u64;
        let mut reopen = None;
        for k in 0..3400u64 {
            // Samples 1600–1799 are not sent; from 1800 on, 0.37 of a
            // period later than the old phase.
            if (1600..1800).contains(&k) {
                continue;
            }
            let shift = if k >= 1800 { 0.37 * period } else { 0.0 };
            let s = T0 as f64 + 0.2e9 + k as f64 * period + shift;
            let arrival = ((s + delay_ns(k)) as u64).max(prev);
            prev = arrival;
            if k == 1800 {
                reopen = Some(lines.len());
            }
            lines.push((Line::Sample { k, s }, arrival));
        }
        let o = run_live_path(&lines, reopen, 1e5);
        assert_eq!(o.stamped, 3200);
        assert_eq!(o.lost_at.len(), 1, "{:?}", o.lost_at);
        let (k, n) = o.lost_at[0];
        assert_eq!(k, 1800);
        assert!((200..=201).contains(&n), "{n} lost");
        // The new phase from 1 s after the reopen, as within a segment; the
        // first second runs on fewer points.
        let bound = 10.0 * 0.9e6 / 200.0;
        let worst = o
            .err_ns
            .iter()
            .filter(|(k, _)| *k > 2000)
            .map(|(_, e)| e.abs())
            .fold(0.0, f64::max);
        assert!(worst < bound, "worst {worst} ns > {bound}");
    }
}
