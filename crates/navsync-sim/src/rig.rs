//! The acquisition rig: how the logger times what it records.
//!
//! - `hw` (seed 001 §2.1): the logger latches its counter at each 1PPS edge
//!   and at each IMU data-ready edge; GNSS messages are stamped when their
//!   last byte arrives.
//! - `serial` (seed 000 §1.2): the IMU has no sync pin; the counter is
//!   latched at the start of each IMU serial frame, which leaves the IMU a
//!   known output delay T_c after its sample.
//! - `sw` (seed 001 §2.2): no PPS at all; every record carries the host's
//!   receive time (serial transfer plus a positive software latency).
//! - `hybrid`: the commonest logger: 1PPS latched on the host counter,
//!   GNSS messages stamped at their last byte as in `hw`, but the IMU on a
//!   serial port without sync pin, its records stamped at receipt (FIFO,
//!   latency law of `software`).
//!
//! Serial links are FIFO: a frame starts when it is ready and the previous
//! frame has left (10 bits per byte, 8N1).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use serde::{Deserialize, Serialize};

use super::clock::{CounterSpec, TemperatureSpec};
use super::imu::OutputKind;
use super::rng::{self, SimRng};
use navsync::filter::gnss::GnssFix;
use navsync::time::GpsTime;

/// How IMU samples are timed by the logger.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SyncMode {
    /// 1PPS and IMU data-ready edges latched by the counter.
    #[default]
    Hw,
    /// 1PPS latched; the IMU timed by the start of its serial frame.
    Serial,
    /// No PPS; receive times only.
    Sw,
    /// 1PPS latched; the IMU stamped at receipt by the host.
    Hybrid,
}

impl SyncMode {
    pub fn name(self) -> &'static str {
        match self {
            SyncMode::Hw => "hw",
            SyncMode::Serial => "serial",
            SyncMode::Sw => "sw",
            SyncMode::Hybrid => "hybrid",
        }
    }
}

/// 1PPS edges and their faults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpsSpec {
    /// Edge jitter, 1σ (s).
    pub jitter_s: f64,
    /// No pulses in these windows: `[start_s, length_s]` after the start.
    pub dropouts: Vec<[f64; 2]>,
    /// Fraction of pulses displaced…
    pub displaced_fraction: f64,
    /// …by a magnitude uniform in this range (s), either sign.
    pub displaced_range_s: [f64; 2],
    /// Spurious extra pulses per hour (Poisson).
    pub spurious_per_hour: f64,
}

impl Default for PpsSpec {
    fn default() -> Self {
        PpsSpec {
            jitter_s: 1e-7,
            dropouts: Vec::new(),
            displaced_fraction: 0.0,
            displaced_range_s: [1e-4, 1e-3],
            spurious_per_hour: 0.0,
        }
    }
}

/// The GNSS receiver's serial link.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssLinkSpec {
    pub baud: f64,
    pub msg_bytes: u32,
    /// Receiver processing time from validity to the first byte, uniform (s).
    pub processing_delay_s: [f64; 2],
    /// Extra latency, uniform in [0, extra_jitter_s] (s).
    pub extra_jitter_s: f64,
}

impl Default for GnssLinkSpec {
    fn default() -> Self {
        GnssLinkSpec {
            baud: 38400.0,
            msg_bytes: 150,
            processing_delay_s: [0.03, 0.06],
            extra_jitter_s: 0.0,
        }
    }
}

/// The IMU's data path to the logger and its faults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuLinkSpec {
    /// Data-ready edge after the sample (s) (`hw`).
    pub data_ready_delay_s: f64,
    /// T_c: start of the serial frame after the sample (s) (`serial`, `sw`).
    pub output_delay_s: f64,
    pub baud: f64,
    pub frame_bytes: u32,
    /// Probability that a frame is lost.
    pub loss_prob: f64,
    /// Every frame lost in these windows: `[start_s, length_s]`.
    pub gaps: Vec<[f64; 2]>,
    /// Probability that a record is written twice.
    pub duplicate_prob: f64,
    /// Probability that a record carries one corrupt value (a spike).
    pub spike_prob: f64,
}

impl Default for ImuLinkSpec {
    fn default() -> Self {
        ImuLinkSpec {
            data_ready_delay_s: 0.0,
            output_delay_s: 0.001,
            baud: 460_800.0,
            frame_bytes: 40,
            loss_prob: 0.0,
            gaps: Vec::new(),
            duplicate_prob: 0.0,
            spike_prob: 0.0,
        }
    }
}

/// How a host receive latency is drawn.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LatencyLaw {
    /// Uniform in `[min, max]`.
    #[default]
    Uniform,
    /// `min` plus an exponential excess of mean `imu_latency_mean_s`
    /// (a scheduler's tail).
    Exponential,
}

/// Host receive latencies (positive only) for software sync, and for the
/// IMU of the `hybrid` rig (s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SoftwareSpec {
    pub imu_latency_s: [f64; 2],
    pub gnss_latency_s: [f64; 2],
    /// Law of the IMU latency.
    pub imu_latency_law: LatencyLaw,
    /// Mean excess over `imu_latency_s[0]` of the exponential law (s).
    pub imu_latency_mean_s: f64,
}

impl Default for SoftwareSpec {
    fn default() -> Self {
        SoftwareSpec {
            imu_latency_s: [0.001, 0.010],
            gnss_latency_s: [0.001, 0.010],
            imu_latency_law: LatencyLaw::Uniform,
            imu_latency_mean_s: 0.002,
        }
    }
}

/// External events time-marked by the receiver (u-blox TIM-TM2 on
/// EXTINT: a camera strobe, an IMU sync pulse divided down), the same edge
/// latched by the logger's counter: `mark` records.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MarkSpec {
    /// Edges per second (0: none).
    pub rate_hz: f64,
    /// The first edge, seconds after the start.
    pub first_s: f64,
    /// The receiver's time-mark error, white (s, 1σ; TIM-TM2 ~20 ns).
    pub receiver_sd_s: f64,
    /// The logger's latch error, uniform in [0, this] (s): an input
    /// capture is exact to a tick; a host's GPIO interrupt is not.
    pub latch_delay_s: f64,
}

impl Default for MarkSpec {
    fn default() -> Self {
        MarkSpec {
            rate_hz: 0.0,
            first_s: 0.5123,
            receiver_sd_s: 2e-8,
            latch_delay_s: 0.0,
        }
    }
}

/// The whole rig.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RigSpec {
    pub sync: SyncMode,
    /// What the `imu` records hold; default: what the IMU outputs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub imu_record: Option<OutputKind>,
    pub counter: CounterSpec,
    pub temperature: TemperatureSpec,
    pub pps: PpsSpec,
    pub gnss_link: GnssLinkSpec,
    pub imu_link: ImuLinkSpec,
    pub software: SoftwareSpec,
    pub marks: MarkSpec,
}

fn check_range(r: [f64; 2], what: &str) -> Result<(), String> {
    if !(r[0].is_finite() && r[1].is_finite() && r[0] >= 0.0 && r[1] >= r[0]) {
        return Err(format!(
            "{what} {r:?} must be [min, max] with 0 <= min <= max"
        ));
    }
    Ok(())
}

fn is_positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

fn is_non_negative(x: f64) -> bool {
    x.is_finite() && x >= 0.0
}

fn check_prob(p: f64, what: &str) -> Result<(), String> {
    if !(0.0..=1.0).contains(&p) {
        return Err(format!("{what} {p} must be a probability within [0, 1]"));
    }
    Ok(())
}

impl RigSpec {
    pub fn validate(&self, imu_period_s: f64) -> Result<(), String> {
        let p = &self.pps;
        if !(p.jitter_s >= 0.0 && p.spurious_per_hour >= 0.0) {
            return Err("pps jitter_s and spurious_per_hour must be >= 0".into());
        }
        check_prob(p.displaced_fraction, "pps displaced_fraction")?;
        check_range(p.displaced_range_s, "pps displaced_range_s")?;
        let g = &self.gnss_link;
        if !is_positive(g.baud) || g.msg_bytes == 0 || !is_non_negative(g.extra_jitter_s) {
            return Err("gnss_link needs baud > 0, msg_bytes > 0, extra_jitter_s >= 0".into());
        }
        check_range(g.processing_delay_s, "gnss_link processing_delay_s")?;
        let i = &self.imu_link;
        if !is_positive(i.baud) || i.frame_bytes == 0 {
            return Err("imu_link needs baud > 0 and frame_bytes > 0".into());
        }
        if !(i.data_ready_delay_s >= 0.0 && i.output_delay_s >= 0.0) {
            return Err("imu_link delays must be >= 0".into());
        }
        check_prob(i.loss_prob, "imu_link loss_prob")?;
        check_prob(i.duplicate_prob, "imu_link duplicate_prob")?;
        check_prob(i.spike_prob, "imu_link spike_prob")?;
        let frame_s = i.frame_bytes as f64 * 10.0 / i.baud;
        if self.sync != SyncMode::Hw && frame_s >= imu_period_s {
            return Err(format!(
                "an IMU frame of {} bytes at {} baud takes {:.3} ms, longer than the IMU period {:.3} ms",
                i.frame_bytes,
                i.baud,
                frame_s * 1e3,
                imu_period_s * 1e3
            ));
        }
        let m = &self.marks;
        if !(is_non_negative(m.rate_hz)
            && m.rate_hz <= 1000.0
            && is_non_negative(m.first_s)
            && is_non_negative(m.receiver_sd_s)
            && is_non_negative(m.latch_delay_s))
        {
            return Err(
                "marks need 0 <= rate_hz <= 1000 and first_s, receiver_sd_s, latch_delay_s >= 0"
                    .into(),
            );
        }
        check_range(self.software.imu_latency_s, "software imu_latency_s")?;
        if !is_non_negative(self.software.imu_latency_mean_s) {
            return Err("software imu_latency_mean_s must be >= 0".into());
        }
        check_range(self.software.gnss_latency_s, "software gnss_latency_s")?;
        Ok(())
    }
}

/// A record waiting to be written, ordered by the time its counter is latched.
#[derive(Clone, Debug)]
pub enum RigRecord {
    Pps,
    Gnss(Box<GnssFix>),
    /// A time-marked edge and the receiver's GPS time of it.
    Mark(GpsTime),
    /// A dual-antenna heading, sent right after its epoch's fix.
    Heading(navsync::io::heading::HeadingObs),
}

#[derive(Debug)]
struct Pending {
    latch_s: f64,
    seq: u64,
    rec: RigRecord,
}

impl PartialEq for Pending {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Pending {
    /// Reversed, so that the heap pops the earliest latch first.
    fn cmp(&self, o: &Self) -> Ordering {
        o.latch_s
            .total_cmp(&self.latch_s)
            .then(o.seq.cmp(&self.seq))
    }
}

/// PPS and GNSS records waiting for their latch time.
#[derive(Debug, Default)]
pub struct PendingRecords {
    heap: BinaryHeap<Pending>,
    seq: u64,
}

impl PendingRecords {
    pub fn push(&mut self, latch_s: f64, rec: RigRecord) {
        self.seq += 1;
        self.heap.push(Pending {
            latch_s,
            seq: self.seq,
            rec,
        });
    }

    /// The earliest record latched before `t`, if any.
    pub fn pop_before(&mut self, t: f64) -> Option<(f64, RigRecord)> {
        if self.heap.peek().is_some_and(|p| p.latch_s < t) {
            self.heap.pop().map(|p| (p.latch_s, p.rec))
        } else {
            None
        }
    }

    pub fn len(&self) -> usize {
        self.heap.len()
    }

    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

/// What happened to one PPS pulse.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PpsKind {
    Normal,
    Displaced,
    Spurious,
}

/// One PPS edge.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PpsEdge {
    /// True time of the edge (s after the start).
    pub time_s: f64,
    pub kind: PpsKind,
}

/// 1PPS edges at whole GPS seconds (and spurious ones), with jitter,
/// displacements and dropouts.
pub struct PpsSource {
    spec: PpsSpec,
    start: GpsTime,
    end_s: f64,
    next_second: i64,
    next_spurious_s: f64,
    jitter: SimRng,
    displace: SimRng,
    spurious: SimRng,
    /// Nominal seconds withheld by dropouts.
    pub dropped: usize,
}

impl PpsSource {
    pub fn new(spec: &PpsSpec, start: GpsTime, end_s: f64, seed: u64) -> Self {
        let first = start.ns().div_euclid(1_000_000_000) + 1;
        let mut spurious = rng::stream(seed, "rig.pps.spurious");
        let next_spurious_s = Self::draw_gap(&mut spurious, spec.spurious_per_hour);
        PpsSource {
            spec: spec.clone(),
            start,
            end_s,
            next_second: first,
            next_spurious_s,
            jitter: rng::stream(seed, "rig.pps.jitter"),
            displace: rng::stream(seed, "rig.pps.displace"),
            spurious,
            dropped: 0,
        }
    }

    fn draw_gap(r: &mut SimRng, per_hour: f64) -> f64 {
        if per_hour <= 0.0 {
            return f64::INFINITY;
        }
        let u = rng::uniform(r);
        -(1.0 - u).ln() * 3600.0 / per_hour
    }

    /// Nominal time (s after the start) of the next pulse or spurious edge.
    pub fn peek_s(&self) -> Option<f64> {
        let sec = GpsTime::from_ns(self.next_second * 1_000_000_000).seconds_since(self.start);
        let t = sec.min(self.next_spurious_s);
        (t < self.end_s).then_some(t)
    }

    /// The next edge in nominal order (dropped pulses are skipped; their
    /// draws are still made, so dropouts change no other pulse).
    pub fn next_edge(&mut self) -> Option<PpsEdge> {
        loop {
            let sec = GpsTime::from_ns(self.next_second * 1_000_000_000).seconds_since(self.start);
            if self.next_spurious_s < sec {
                let t = self.next_spurious_s;
                if t >= self.end_s {
                    return None;
                }
                let gap = Self::draw_gap(&mut self.spurious, self.spec.spurious_per_hour);
                self.next_spurious_s += gap;
                return Some(PpsEdge {
                    time_s: t,
                    kind: PpsKind::Spurious,
                });
            }
            if sec >= self.end_s {
                return None;
            }
            self.next_second += 1;
            let jitter = self.spec.jitter_s * rng::normal(&mut self.jitter);
            let u = rng::uniform(&mut self.displace);
            let mag = rng::uniform_in(
                &mut self.displace,
                self.spec.displaced_range_s[0],
                self.spec.displaced_range_s[1],
            );
            let sign = if rng::uniform(&mut self.displace) < 0.5 {
                -1.0
            } else {
                1.0
            };
            if self
                .spec
                .dropouts
                .iter()
                .any(|d| sec >= d[0] && sec < d[0] + d[1])
            {
                self.dropped += 1;
                continue;
            }
            let displaced = u < self.spec.displaced_fraction;
            return Some(PpsEdge {
                time_s: sec + jitter + if displaced { sign * mag } else { 0.0 },
                kind: if displaced {
                    PpsKind::Displaced
                } else {
                    PpsKind::Normal
                },
            });
        }
    }
}

/// A FIFO serial link: a message ready at `t` starts when the previous one
/// has left and takes `bytes·10/baud`.
#[derive(Clone, Debug)]
pub struct SerialLink {
    tx_s: f64,
    busy_until: f64,
}

impl SerialLink {
    pub fn new(baud: f64, bytes: u32) -> Self {
        SerialLink {
            tx_s: bytes as f64 * 10.0 / baud,
            busy_until: f64::NEG_INFINITY,
        }
    }

    /// Transmission time of one message (s).
    pub fn tx_s(&self) -> f64 {
        self.tx_s
    }

    /// (first byte, last byte) times of a message ready at `ready_s`.
    pub fn send(&mut self, ready_s: f64) -> (f64, f64) {
        let start = ready_s.max(self.busy_until);
        self.busy_until = start + self.tx_s;
        (start, self.busy_until)
    }
}

/// Host receive times: transfer end plus a positive latency, never before
/// the previous receive (the host reads a port in order).
#[derive(Clone, Debug)]
pub struct HostReceiver {
    range: [f64; 2],
    law: LatencyLaw,
    mean_s: f64,
    rng: SimRng,
    last: f64,
}

impl HostReceiver {
    /// Uniform latencies in `range`.
    pub fn new(range: [f64; 2], rng: SimRng) -> Self {
        Self::with_law(range, LatencyLaw::Uniform, 0.0, rng)
    }

    /// Latencies by `law` (`mean_s`: the exponential's mean excess).
    pub fn with_law(range: [f64; 2], law: LatencyLaw, mean_s: f64, rng: SimRng) -> Self {
        HostReceiver {
            range,
            law,
            mean_s,
            rng,
            last: f64::NEG_INFINITY,
        }
    }

    pub fn receive(&mut self, arrived_s: f64) -> f64 {
        let lat = match self.law {
            LatencyLaw::Uniform => rng::uniform_in(&mut self.rng, self.range[0], self.range[1]),
            LatencyLaw::Exponential => {
                self.range[0] - self.mean_s * (1.0 - rng::uniform(&mut self.rng)).ln()
            }
        };
        let rx = (arrived_s + lat).max(self.last);
        self.last = rx;
        rx
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pps_pulses_at_whole_seconds_with_faults() {
        let start = GpsTime::from_week_sow(2300, 100000.25);
        let spec = PpsSpec {
            jitter_s: 0.0,
            dropouts: vec![[10.0, 5.0]],
            displaced_fraction: 0.1,
            displaced_range_s: [1e-4, 1e-3],
            spurious_per_hour: 360.0,
        };
        let mut p = PpsSource::new(&spec, start, 3600.0, 1);
        let mut normal = 0;
        let mut displaced = 0;
        let mut spurious = 0;
        let mut last = f64::NEG_INFINITY;
        while let Some(e) = p.next_edge() {
            match e.kind {
                PpsKind::Normal => {
                    normal += 1;
                    // Whole GPS seconds: start is at .25 s.
                    assert!(((e.time_s + 0.25) - (e.time_s + 0.25).round()).abs() < 1e-9);
                    assert!(!(e.time_s >= 10.0 && e.time_s < 15.0));
                }
                PpsKind::Displaced => {
                    displaced += 1;
                    let off = (e.time_s + 0.25) - (e.time_s + 0.25).round();
                    assert!((1e-4..=1e-3).contains(&off.abs()), "{off}");
                }
                PpsKind::Spurious => spurious += 1,
            }
            // Nominal order within a millisecond.
            assert!(e.time_s > last - 2e-3);
            last = e.time_s;
        }
        // 3600 seconds in (start, start+3600): 3600 nominal, 5 dropped.
        assert_eq!(normal + displaced, 3595);
        assert_eq!(p.dropped, 5);
        assert!((250..470).contains(&displaced), "{displaced}");
        // Poisson(360): sd 19.
        assert!((280..440).contains(&spurious), "{spurious}");
        // Dropouts and displacements change no other pulse: the same seed
        // without faults gives the same jitter-free whole seconds.
        let mut q = PpsSource::new(
            &PpsSpec {
                jitter_s: 0.0,
                ..PpsSpec::default()
            },
            start,
            20.0,
            1,
        );
        assert!((q.next_edge().unwrap().time_s - 0.75).abs() < 1e-12);
    }

    #[test]
    fn serial_link_is_fifo() {
        let mut s = SerialLink::new(38400.0, 150);
        assert!((s.tx_s() - 0.0390625).abs() < 1e-15);
        let (a0, a1) = s.send(1.0);
        assert_eq!((a0, a1), (1.0, 1.0390625));
        // A message ready during the previous transfer waits for it.
        let (b0, _) = s.send(1.01);
        assert_eq!(b0, a1);
        let mut h = HostReceiver::new([0.001, 0.010], rng::stream(1, "h"));
        let mut last = 0.0;
        for k in 0..1000 {
            let rx = h.receive(k as f64 * 0.001);
            assert!(rx >= last && rx >= k as f64 * 0.001 + 0.001);
            last = rx;
        }
    }

    #[test]
    fn pending_records_pop_in_latch_order() {
        let mut p = PendingRecords::default();
        p.push(3.0, RigRecord::Pps);
        p.push(1.0, RigRecord::Pps);
        p.push(2.0, RigRecord::Pps);
        assert!(p.pop_before(0.5).is_none());
        assert_eq!(p.pop_before(10.0).unwrap().0, 1.0);
        assert_eq!(p.pop_before(10.0).unwrap().0, 2.0);
        assert_eq!(p.len(), 1);
    }

    #[test]
    fn rig_validation_explains() {
        let mut r = RigSpec {
            sync: SyncMode::Serial,
            ..RigSpec::default()
        };
        r.imu_link.baud = 9600.0;
        let e = r.validate(0.005).unwrap_err();
        assert!(e.contains("longer than the IMU period"), "{e}");
        r.imu_link.baud = 460_800.0;
        r.imu_link.loss_prob = 2.0;
        assert!(r.validate(0.005).unwrap_err().contains("loss_prob"));
    }
}
