//! The live loop: sources → stamps → synchronization engine → fusion.
//!
//! ```text
//!  IMU port thread ──┐  (lines stamped on arrival: crate::imu)
//!  GNSS port thread ─┼─► bounded channel ─► engine thread: SyncEngine (causal,
//!  PPS thread ───────┘  (host counter ns)     hybrid sync) → IncrementBuilder
//!                                             → Fusion (delayed-state GNSS) → sink
//! ```
//!
//! Every stamp is the host counter ([`crate::hostclock`]): the engine sees
//! a rig log whose counter is `CLOCK_MONOTONIC_RAW` at 1 GHz, 64 bits, and
//! maps it to GPS time from the 1PPS edges labelled by the GNSS fixes
//! (Tang, Zhang & Niu 2022 §2.1), with holdover while pulses are missing and relock when
//! they return (seed 002, embodiment step 2: without 1PPS the sample clock
//! runs on the system clock and is realigned at the next pulses;
//! [`navsync::timing::clock`]). The serial IMU's lines are receive times:
//! the engine's hybrid sync finds the IMU's own sample clock in them
//! ([`navsync::timing::sampleclock`], the same code as `navsync sync`), with
//! a short lookahead (`imu_lookahead_s`) so that solutions are not held
//! back; ESF samples are stamped by their time tags ([`crate::imu`]) and
//! synchronized as hardware captures. Without a PPS source it runs
//! software synchronization from receive times (Tang, Zhang & Niu 2022 §2.2). GNSS fixes reach the
//! filter at their arrival, a latency after their epoch (seed 002 step 4),
//! and are fused at their time of validity by the delayed-state update
//! ([`LatencyMode::DelayedState`], instead of seed 002 step 5's
//! extrapolation).
//!
//! Robustness: a port that cannot be opened or vanishes is reported and
//! reopened every `reopen_interval`; the loop keeps going with what
//! remains. Memory is bounded: the channel holds at most `CHANNEL_DEPTH`
//! records, and an engine that stamps nothing for `max_unstamped_s` (no
//! PPS lock and no GNSS) is restarted, its waiting samples counted as
//! dropped.

use std::collections::VecDeque;
use std::io;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use navsync::filter::gnss::GnssFix;
use navsync::fusion::{FusionConfig, LatencyMode, NavOutput};
use navsync::io::heading::HeadingObs;
use navsync::io::riglog::{ImuTiming, RigGnss, RigHeader, RigHeading, RigRecord};
use navsync::navigator::{Navigator, Step};
use navsync::pipeline::NullSink;
use navsync::time::GpsTime;
use navsync::timing::{
    IncrementBuilder, LockState, Oscillator, SyncConfig, SyncEngine, SyncMode, SyncOutput,
    SyncReport,
};
use serde::Serialize;

use crate::gnss::{Decoded, GnssDecoder, ReceivedFix};
use crate::hostclock::{self, COUNTER_HZ};
use crate::imu::{ImuLineFormat, LineFeed, LineSample, LineSplitter, TagTimer};
use crate::latency::LatencyHistogram;
use crate::pps::{KernelPps, PpsEdge, PpsSource};
use crate::record::{RecordCounts, Recorder};
use crate::serial::SerialPort;

/// Headings kept before the fusion starts (a minute at 10 Hz): the fix it
/// starts from can be seconds old when the clock has just locked.
const EARLY_HEADINGS: usize = 600;

/// Records waiting between the source threads and the engine (≈ 20 s of a
/// 200 Hz IMU): a stalled engine blocks the readers, whose kernel buffers
/// then fill; memory does not grow.
pub const CHANNEL_DEPTH: usize = 4096;

/// Default of [`LiveConfig::imu_lookahead_s`]: three times a USB-serial
/// adapter's 16 ms latency timer, 10 samples at 200 Hz.
pub const DEFAULT_IMU_LOOKAHEAD_S: f64 = 0.05;

/// A serial port and its speed.
#[derive(Clone, Debug)]
pub struct PortConfig {
    pub path: PathBuf,
    pub baud: u32,
}

/// Where 1PPS edges come from.
pub enum PpsInput {
    /// None: software synchronization from receive times.
    None,
    /// A kernel PPS device, reopened when it fails.
    Kernel(PathBuf),
    /// Any other source (tests, replays).
    Source(Box<dyn PpsSource>),
}

/// Settings of a live run.
pub struct LiveConfig {
    pub gnss: PortConfig,
    /// The IMU's own port (text lines of `imu_format`); `None` when the
    /// IMU data come in ESF messages on the GNSS port (`esf_tick_s`).
    pub imu: Option<PortConfig>,
    pub imu_format: ImuLineFormat,
    /// Read the receiver's UBX ESF-RAW/ESF-MEAS IMU data on the GNSS port,
    /// with this sensor time-tag tick (s).
    pub esf_tick_s: Option<f64>,
    pub pps: PpsInput,
    /// Filter settings (from the KF-GINS configuration). Its initial
    /// position and time are replaced by the first stamped GNSS fix when
    /// `init_from_gnss`; the latency mode is set to the delayed-state
    /// update over `max_gnss_latency_s`.
    pub fusion: FusionConfig,
    pub init_from_gnss: bool,
    /// Nominal IMU rate (Hz).
    pub imu_rate_hz: f64,
    /// The IMU's output delay T_c (s), subtracted from its stamps (seed 000).
    pub imu_output_delay_s: f64,
    /// Receive time the sample clock waits after a late IMU line before it
    /// decides whether samples were lost before it (s); lines on time are
    /// stamped at once. Longer: fewer latency excursions taken for losses;
    /// shorter: late lines' solutions come sooner.
    pub imu_lookahead_s: f64,
    pub oscillator: Oscillator,
    /// Oldest fix the filter can still fuse at its time of validity (s);
    /// older dual-antenna headings are not fused either.
    pub max_gnss_latency_s: f64,
    /// σ of NMEA HDT headings (deg; HDT carries none). Headings are fused
    /// when `fusion.heading` is set.
    pub hdt_sd_deg: f64,
    /// How often a missing device is tried again.
    pub reopen_interval: Duration,
    /// How often [`LiveSink::status`] is called.
    pub status_interval: Duration,
    /// Restart the engine when it has stamped nothing for this long (s).
    pub max_unstamped_s: f64,
    /// Stop after this long (None: until `stop` is set).
    pub duration: Option<Duration>,
    /// Record every received record here as a rig log ([`crate::record`]).
    pub record: Option<PathBuf>,
    /// Record the receiver's raw bytes here.
    pub record_gnss: Option<PathBuf>,
}

impl LiveConfig {
    /// Defaults around ports, a PPS input and filter settings.
    pub fn new(
        gnss: PortConfig,
        imu: Option<PortConfig>,
        pps: PpsInput,
        fusion: FusionConfig,
    ) -> Self {
        let imu_rate_hz = fusion.imu_rate_hz;
        LiveConfig {
            gnss,
            imu,
            imu_format: ImuLineFormat::Rate,
            esf_tick_s: None,
            pps,
            fusion,
            init_from_gnss: true,
            imu_rate_hz,
            imu_output_delay_s: 0.0,
            imu_lookahead_s: DEFAULT_IMU_LOOKAHEAD_S,
            oscillator: Oscillator::Xo,
            max_gnss_latency_s: 1.5,
            hdt_sd_deg: crate::gnss::DEFAULT_HDT_SD_DEG,
            reopen_interval: Duration::from_secs(1),
            status_interval: Duration::from_secs(1),
            max_unstamped_s: 60.0,
            duration: None,
            record: None,
            record_gnss: None,
        }
    }
}

/// Which source a message is about.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceId {
    Imu,
    Gnss,
    Pps,
    Engine,
}

impl std::fmt::Display for SourceId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SourceId::Imu => "imu",
            SourceId::Gnss => "gnss",
            SourceId::Pps => "pps",
            SourceId::Engine => "engine",
        })
    }
}

/// What the source threads send to the engine thread.
enum Input {
    Imu {
        /// When the read returned (latency is measured from it).
        arrival_ns: u64,
        /// The engine's counter: `arrival_ns` for a line, the tag's
        /// stamp for an ESF sample.
        counter: u64,
        values: [f64; 6],
        /// What the line's reader knew (serial lines).
        line: Option<LineSample>,
    },
    Gnss(ReceivedFix),
    /// A dual-antenna heading from the receiver, and the host counter (ns)
    /// at which its last byte arrived.
    Heading(HeadingObs, u64),
    /// Bytes read from the receiver's port (only when they are recorded).
    GnssRaw(Vec<u8>),
    Pps(PpsEdge),
    /// An IMU line that is not a sample.
    BadImuLine(String),
    /// Something to report; `up` tells a port's new state when it changed.
    Note {
        source: SourceId,
        msg: String,
        up: Option<bool>,
    },
    /// A source thread ended.
    Done,
}

/// Per-epoch information given with each solution.
#[derive(Copy, Clone, Debug)]
pub struct NavInfo {
    /// Index of the IMU line among those received (0-based).
    pub seq: u64,
    /// Host counter when the line arrived (ns).
    pub arrival_ns: u64,
    /// Stamp error bound (s).
    pub bound_s: f64,
    pub holdover: bool,
    /// Arrival → solution (ns).
    pub latency_ns: u64,
}

/// Counters of a live run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LiveCounts {
    pub imu_lines: u64,
    pub imu_bad_lines: u64,
    /// Lost as the arrival timer or the engine found (gaps in the sample train).
    pub imu_lost: u64,
    pub imu_stamped: u64,
    pub imu_unstamped: u64,
    /// Samples dropped by engine restarts (no time reference for too long).
    pub imu_dropped_no_time: u64,
    pub solutions: u64,
    pub gnss_fixes: u64,
    /// Fixes the filter used (fused at their time of validity).
    pub gnss_fused: u64,
    pub gnss_problems: u64,
    /// Dual-antenna headings received, fused, rejected by the filter's
    /// gate, too old to fuse (older than the latency limit), and received
    /// before the fusion started (kept for its initial yaw).
    pub gnss_headings: u64,
    pub headings_fused: u64,
    pub headings_rejected: u64,
    pub headings_stale: u64,
    pub headings_before_start: u64,
    pub pps_edges: u64,
    pub pps_missed: u64,
    pub reopens: u64,
    pub engine_restarts: u64,
}

/// A lock-state change, at seconds since the start (host clock).
#[derive(Clone, Debug, Serialize)]
pub struct StateChange {
    pub at_s: f64,
    pub state: LockState,
}

/// The status handed to [`LiveSink::status`] now and then.
#[derive(Clone, Debug, Serialize)]
pub struct LiveStatus {
    pub elapsed_s: f64,
    pub state: LockState,
    pub mode: &'static str,
    pub imu_up: bool,
    pub gnss_up: bool,
    pub pps_up: bool,
    pub counts: LiveCounts,
    /// Latest solution time and position (lat, lon deg, h m).
    #[serde(skip)]
    pub time: Option<GpsTime>,
    pub pos: Option<[f64; 3]>,
    pub vel: Option<[f64; 3]>,
    pub att_deg: Option<[f64; 3]>,
    pub latency_median_us: Option<f64>,
    pub latency_max_us: Option<f64>,
    pub bound_us: Option<f64>,
}

/// What the run did.
#[derive(Clone, Debug, Serialize)]
pub struct LiveReport {
    pub duration_s: f64,
    pub counts: LiveCounts,
    pub latency: crate::latency::LatencySummary,
    /// CPU time of the whole process over the run (s) and as % of one core.
    pub cpu_s: f64,
    pub cpu_percent: f64,
    pub state_changes: Vec<StateChange>,
    /// The engine's report (holdover spans, lock timeline, pulses, IMU, GNSS latency).
    pub sync: Option<SyncReport>,
    pub sync_error: Option<String>,
    pub notes_total: u64,
    pub first_notes: Vec<String>,
    /// What `--record` and `--record-gnss` wrote.
    pub recorded: Option<RecordCounts>,
}

/// Receives the solution and the status.
pub trait LiveSink {
    /// Every IMU epoch's solution.
    fn nav(&mut self, out: &NavOutput, info: &NavInfo) -> Result<(), navsync::Error>;
    /// Once a second of solution time: the IMU error estimates and every
    /// state's σ (SI), as KF-GINS writes `imu_err.txt` and `std.txt`.
    fn aux(&mut self, _out: &NavOutput, _sd: &[f64]) -> Result<(), navsync::Error> {
        Ok(())
    }
    /// Every `status_interval`.
    fn status(&mut self, s: &LiveStatus);
    /// A reported condition (ports opened or lost, corrupt data, …).
    fn note(&mut self, source: SourceId, msg: &str);
}

/// Set by the SIGINT handler ([`stop_on_ctrl_c`]).
static CTRL_C: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    CTRL_C.store(true, Ordering::SeqCst);
}

/// Makes Ctrl-C end a live run cleanly; returns the flag to pass to [`run`].
pub fn stop_on_ctrl_c() -> &'static AtomicBool {
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_sigint as *const () as libc::sighandler_t);
    }
    &CTRL_C
}

fn note(tx: &SyncSender<Input>, source: SourceId, msg: String, up: Option<bool>) -> bool {
    tx.send(Input::Note { source, msg, up }).is_ok()
}

/// Opens `port` until it opens or `stop`; reports the first failure of a
/// series.
fn open_port(
    port: &PortConfig,
    source: SourceId,
    tx: &SyncSender<Input>,
    stop: &AtomicBool,
    retry: Duration,
) -> Option<SerialPort> {
    let mut reported = false;
    while !stop.load(Ordering::Relaxed) {
        match SerialPort::open(&port.path, port.baud) {
            Ok(p) => {
                let how = if p.is_tty {
                    format!("{} baud", port.baud)
                } else {
                    "not a terminal: read as it is".into()
                };
                if !note(
                    tx,
                    source,
                    format!("{} opened ({how})", port.path.display()),
                    Some(true),
                ) {
                    return None;
                }
                return Some(p);
            }
            Err(e) => {
                if !reported {
                    reported = true;
                    let msg = format!("{e}; retrying every {:.1} s", retry.as_secs_f64());
                    if !note(tx, source, msg, Some(false)) {
                        return None;
                    }
                }
                sleep_unless(stop, retry);
            }
        }
    }
    None
}

fn sleep_unless(stop: &AtomicBool, d: Duration) {
    let end = Instant::now() + d;
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if now >= end {
            break;
        }
        std::thread::sleep((end - now).min(Duration::from_millis(50)));
    }
}

const READ_TIMEOUT: Duration = Duration::from_millis(200);

/// Reads a port until `stop`, reopening it when it fails; `on_bytes`
/// handles every read with its arrival stamp, `on_reopen` is called after
/// a reconnect.
fn port_loop(
    port: PortConfig,
    source: SourceId,
    tx: SyncSender<Input>,
    stop: Arc<AtomicBool>,
    retry: Duration,
    mut on_bytes: impl FnMut(&[u8], u64, &SyncSender<Input>) -> bool,
    mut on_reopen: impl FnMut(),
) {
    let mut buf = vec![0u8; 4096];
    let mut first = true;
    'outer: while let Some(mut p) = open_port(&port, source, &tx, &stop, retry) {
        if !first {
            on_reopen();
        }
        first = false;
        let mut quiet = Duration::ZERO;
        let mut quiet_reported = false;
        while !stop.load(Ordering::Relaxed) {
            match p.read_timeout(&mut buf, READ_TIMEOUT) {
                Ok(0) => {
                    quiet += READ_TIMEOUT;
                    if quiet >= Duration::from_secs(5) && !quiet_reported {
                        quiet_reported = true;
                        let msg = format!("{}: no data for 5 s", port.path.display());
                        if !note(&tx, source, msg, None) {
                            break 'outer;
                        }
                    }
                }
                Ok(n) => {
                    let stamp = hostclock::now_ns();
                    if quiet_reported {
                        let msg = format!("{}: data again", port.path.display());
                        if !note(&tx, source, msg, None) {
                            break 'outer;
                        }
                    }
                    quiet = Duration::ZERO;
                    quiet_reported = false;
                    if !on_bytes(&buf[..n], stamp, &tx) {
                        break 'outer;
                    }
                }
                Err(e) => {
                    let msg = format!("{e}; reopening");
                    if !note(&tx, source, msg, Some(false)) {
                        break 'outer;
                    }
                    sleep_unless(&stop, retry);
                    continue 'outer;
                }
            }
        }
        break;
    }
    let _ = tx.send(Input::Done);
}

fn spawn_imu(
    cfg: &LiveConfig,
    port: PortConfig,
    tx: SyncSender<Input>,
    stop: Arc<AtomicBool>,
) -> io::Result<JoinHandle<()>> {
    let fmt = cfg.imu_format;
    let retry = cfg.reopen_interval;
    std::thread::Builder::new()
        .name("live-imu".into())
        .spawn(move || {
            let feed = std::cell::RefCell::new(LineFeed::new());
            let split = std::cell::RefCell::new(LineSplitter::new(512));
            port_loop(
                port,
                SourceId::Imu,
                tx,
                stop,
                retry,
                |bytes, stamp, tx| {
                    // The lines of one read, in order: Ok(values, length) or
                    // Err(message, length).
                    let mut items: Vec<(Result<[f64; 6], String>, usize)> = Vec::new();
                    split.borrow_mut().push(bytes, |line, too_long| {
                        let parsed = if too_long {
                            Err("line longer than 512 bytes".to_string())
                        } else {
                            fmt.parse(line)
                        };
                        match parsed {
                            Ok(Some(v)) => items.push((Ok(v), line.len())),
                            Ok(None) => {}
                            Err(e) => {
                                let shown = String::from_utf8_lossy(&line[..line.len().min(60)]);
                                items.push((
                                    Err(format!("bad IMU line '{shown}': {e}")),
                                    line.len(),
                                ));
                            }
                        }
                    });
                    let mut t = feed.borrow_mut();
                    let mut behind = items.iter().filter(|i| i.0.is_ok()).count();
                    let mut ok = true;
                    for (item, len) in items {
                        match item {
                            Ok(values) => {
                                behind = behind.saturating_sub(1);
                                let s = t.sample(len, behind);
                                ok &= tx
                                    .send(Input::Imu {
                                        arrival_ns: stamp,
                                        counter: stamp,
                                        values,
                                        line: Some(s),
                                    })
                                    .is_ok();
                            }
                            Err(msg) => {
                                let what = match t.bad_line(len) {
                                    0 => "skipped".to_string(),
                                    n => format!("counted as {n} lost sample(s)"),
                                };
                                ok &= tx.send(Input::BadImuLine(format!("{msg}; {what}"))).is_ok();
                            }
                        }
                    }
                    ok
                },
                || {
                    feed.borrow_mut().reopen();
                    split.borrow_mut().reset();
                },
            );
        })
}

fn spawn_gnss(
    cfg: &LiveConfig,
    tx: SyncSender<Input>,
    stop: Arc<AtomicBool>,
) -> io::Result<JoinHandle<()>> {
    let port = cfg.gnss.clone();
    let retry = cfg.reopen_interval;
    let esf = cfg.esf_tick_s;
    let period_ns = 1e9 / cfg.imu_rate_hz;
    let rate = cfg.imu_rate_hz;
    let keep_raw = cfg.record_gnss.is_some();
    let hdt_sd_deg = cfg.hdt_sd_deg;
    std::thread::Builder::new()
        .name("live-gnss".into())
        .spawn(move || {
            let mut d = GnssDecoder::default();
            // Checked by `run` before the thread starts.
            d.set_hdt_sd_deg(hdt_sd_deg);
            if let Some(tick) = esf {
                d.enable_esf(tick);
            }
            let dec = std::cell::RefCell::new(d);
            // ESF samples: timed by their tags against message arrivals.
            let timer = std::cell::RefCell::new((TagTimer::new(rate, 10.0), None::<i64>));
            let mut out = Decoded::default();
            port_loop(
                port,
                SourceId::Gnss,
                tx,
                stop,
                retry,
                |bytes, stamp, tx| {
                    let mut ok = !keep_raw || tx.send(Input::GnssRaw(bytes.to_vec())).is_ok();
                    dec.borrow_mut().push(bytes, stamp, &mut out);
                    let (t, tag0) = &mut *timer.borrow_mut();
                    for e in out.imu.drain(..) {
                        let t0 = *tag0.get_or_insert(e.sensor_ns);
                        let x = (e.sensor_ns - t0) as f64 / period_ns;
                        let sample_ns = t.push_tagged(x, e.arrival_ns);
                        ok &= tx
                            .send(Input::Imu {
                                arrival_ns: e.arrival_ns,
                                counter: sample_ns,
                                values: e.values,
                                line: None,
                            })
                            .is_ok();
                    }
                    for f in out.fixes.drain(..) {
                        ok &= tx.send(Input::Gnss(f)).is_ok();
                    }
                    for (h, received_ns) in out.headings.drain(..) {
                        ok &= tx.send(Input::Heading(h, received_ns)).is_ok();
                    }
                    for msg in out.notes.drain(..) {
                        ok &= note(tx, SourceId::Gnss, msg, None);
                    }
                    ok
                },
                || {
                    dec.borrow_mut().reset_stream();
                    let (t, tag0) = &mut *timer.borrow_mut();
                    t.restart();
                    *tag0 = None;
                },
            );
        })
}

fn spawn_pps(
    input: PpsInput,
    retry: Duration,
    tx: SyncSender<Input>,
    stop: Arc<AtomicBool>,
) -> io::Result<Option<JoinHandle<()>>> {
    let (path, mut given) = match input {
        PpsInput::None => return Ok(None),
        PpsInput::Kernel(p) => (Some(p), None),
        PpsInput::Source(s) => (None, Some(s)),
    };
    let h = std::thread::Builder::new()
        .name("live-pps".into())
        .spawn(move || {
            let mut reported = false;
            'outer: while !stop.load(Ordering::Relaxed) {
                let mut src: Box<dyn PpsSource> = match (given.take(), &path) {
                    (Some(s), _) => s,
                    (None, Some(p)) => match KernelPps::open(p) {
                        Ok(s) => {
                            reported = false;
                            if !note(
                                &tx,
                                SourceId::Pps,
                                format!("{} opened", p.display()),
                                Some(true),
                            ) {
                                break;
                            }
                            Box::new(s)
                        }
                        Err(e) => {
                            if !reported {
                                reported = true;
                                let msg =
                                    format!("{e}; retrying every {:.1} s", retry.as_secs_f64());
                                if !note(&tx, SourceId::Pps, msg, Some(false)) {
                                    break;
                                }
                            }
                            sleep_unless(&stop, retry);
                            continue;
                        }
                    },
                    (None, None) => break,
                };
                let mut quiet = 0u32;
                while !stop.load(Ordering::Relaxed) {
                    match src.next_edge(Duration::from_millis(500)) {
                        Ok(Some(e)) => {
                            if quiet >= 10 {
                                let msg = format!("{}: edges again", src.name());
                                if !note(&tx, SourceId::Pps, msg, None) {
                                    break 'outer;
                                }
                            }
                            quiet = 0;
                            if tx.send(Input::Pps(e)).is_err() {
                                break 'outer;
                            }
                        }
                        Ok(None) => {
                            quiet += 1;
                            // 5 s: holdover has begun; say why once.
                            if quiet == 10 {
                                let msg = format!(
                                    "{}: no edge for 5 s (no signal, or assert capture not enabled)",
                                    src.name()
                                );
                                if !note(&tx, SourceId::Pps, msg, None) {
                                    break 'outer;
                                }
                            }
                        }
                        Err(e) => {
                            let msg = format!("{e}; reopening");
                            if !note(&tx, SourceId::Pps, msg, Some(false)) {
                                break 'outer;
                            }
                            sleep_unless(&stop, retry);
                            continue 'outer;
                        }
                    }
                }
            }
            let _ = tx.send(Input::Done);
        })?;
    Ok(Some(h))
}

/// Tells the engine what the reader knew about the next line's record.
pub(crate) fn hint_engine(e: &mut SyncEngine, l: LineSample) {
    if l.lost_before > 0 {
        e.note_imu_lost(l.lost_before);
    }
    if l.restart {
        e.note_imu_restart();
    }
    e.note_imu_read_behind(l.behind);
}

/// Meaning of the IMU values (ESF data are rates).
fn imu_kind(cfg: &LiveConfig) -> navsync::io::riglog::ImuKind {
    match cfg.esf_tick_s {
        Some(_) => navsync::io::riglog::ImuKind::Rate,
        None => cfg.imu_format.kind(),
    }
}

/// Engine-side state of a run.
struct Core {
    header: RigHeader,
    sync_cfg: SyncConfig,
    engine: SyncEngine,
    inc: IncrementBuilder,
    fusion_cfg: FusionConfig,
    init_from_gnss: bool,
    /// The fusion stream, once it has an initial state.
    navigator: Option<Navigator>,
    /// Latest IMU stamp out of the engine.
    last_imu_time: Option<GpsTime>,
    max_gnss_latency_s: f64,
    /// (engine seq, arrival ns) of IMU lines not yet stamped.
    arrivals: VecDeque<(u64, u64)>,
    imu_seq: u64,
    /// IMU records pushed since the engine last stamped one.
    waiting: u64,
    max_waiting: u64,
    /// Recent fixes by validity time (the engine's record has no velocity).
    recent_fixes: VecDeque<GnssFix>,
    /// The latest dual-antenna headings before the fusion started (at most
    /// [`EARLY_HEADINGS`]): its initial yaw when the configuration's is
    /// unknown.
    early_headings: VecDeque<HeadingObs>,
    /// Headings arrived while heading updates are off (noted once).
    headings_unused_noted: bool,
    out: Vec<SyncOutput>,
    counts: LiveCounts,
    latency: LatencyHistogram,
    last: Option<(NavOutput, NavInfo)>,
    /// GPS second of the last [`LiveSink::aux`] call.
    aux_second: Option<i64>,
    state: LockState,
    changes: Vec<StateChange>,
    t0: u64,
    notes_total: u64,
    first_notes: Vec<String>,
    recorder: Option<Recorder>,
}

/// The header of a `--record` rig log: the host counter, and what its
/// `imu` counters are.
pub fn record_header(cfg: &LiveConfig) -> RigHeader {
    let mut h = RigHeader::new(COUNTER_HZ, 64, imu_kind(cfg));
    h.imu_rate_hz = Some(cfg.imu_rate_hz);
    // Lines: their arrival (hybrid sync finds the sample clock again). ESF:
    // the sensor's time tags put on the host counter, sample instants up
    // to the fastest message delay, as live stamps them.
    h.imu_timing = Some(if cfg.esf_tick_s.is_some() {
        ImuTiming::DataReady
    } else {
        ImuTiming::Receive
    });
    h.imu_output_delay_s = Some(cfg.imu_output_delay_s);
    h
}

fn record_comments(cfg: &LiveConfig) -> Vec<&'static str> {
    let mut c = vec![
        "recorded by navsync live, counter = the host's CLOCK_MONOTONIC_RAW in ns",
        "gnss and heading counters are the arrival of their last byte",
    ];
    c.push(if cfg.esf_tick_s.is_some() {
        "imu counters are the ESF time tags mapped to the host counter by the arrival envelope"
    } else {
        "imu counters are the arrival of each line (lines of one read share it)"
    });
    if matches!(cfg.pps, PpsInput::None) {
        c.push("no 1PPS input");
    }
    c
}

impl Core {
    fn new(cfg: &LiveConfig) -> Self {
        let header = record_header(cfg);
        let hw = !matches!(cfg.pps, PpsInput::None);
        let sync_cfg = SyncConfig {
            // Serial lines are receive times: hybrid sync (the IMU's sample
            // clock on 1PPS time); ESF samples are sample instants already.
            mode: match (hw, cfg.esf_tick_s.is_some()) {
                (false, _) => SyncMode::Sw,
                (true, true) => SyncMode::Hw,
                (true, false) => SyncMode::Hybrid,
            },
            hybrid_lookahead_s: Some(cfg.imu_lookahead_s),
            causal: true,
            imu_output_delay_s: Some(cfg.imu_output_delay_s),
            oscillator: cfg.oscillator,
            // NMEA fixes are delivered one epoch after their last byte.
            reorder_tolerance_s: 1.5,
            source: "live".into(),
            ..Default::default()
        };
        let mut fusion_cfg = cfg.fusion.clone();
        fusion_cfg.latency = LatencyMode::DelayedState {
            max_latency_s: cfg.max_gnss_latency_s,
        };
        fusion_cfg.imu_rate_hz = cfg.imu_rate_hz;
        Core {
            engine: SyncEngine::new(&header, sync_cfg.clone()),
            header,
            sync_cfg,
            inc: IncrementBuilder::new(imu_kind(cfg)),
            init_from_gnss: cfg.init_from_gnss,
            navigator: (!cfg.init_from_gnss)
                .then(|| Navigator::new(fusion_cfg.clone()).with_aux_interval(None)),
            last_imu_time: None,
            max_gnss_latency_s: cfg.max_gnss_latency_s,
            fusion_cfg,
            arrivals: VecDeque::new(),
            imu_seq: 0,
            waiting: 0,
            max_waiting: (cfg.max_unstamped_s * cfg.imu_rate_hz).max(1000.0) as u64,
            recent_fixes: VecDeque::new(),
            early_headings: VecDeque::new(),
            headings_unused_noted: false,
            out: Vec::new(),
            counts: LiveCounts::default(),
            latency: LatencyHistogram::new(),
            last: None,
            aux_second: None,
            state: LockState::Acquiring,
            changes: Vec::new(),
            t0: hostclock::now_ns(),
            notes_total: 0,
            first_notes: Vec::new(),
            recorder: None,
        }
    }

    fn record(&mut self, r: RigRecord) {
        if let Some(rec) = self.recorder.as_mut() {
            rec.record(r);
        }
    }

    fn elapsed_s(&self) -> f64 {
        hostclock::now_ns().saturating_sub(self.t0) as f64 * 1e-9
    }

    fn note(&mut self, sink: &mut dyn LiveSink, source: SourceId, msg: &str) {
        self.notes_total += 1;
        if self.first_notes.len() < 200 {
            self.first_notes
                .push(format!("{:.3} s {source}: {msg}", self.elapsed_s()));
        }
        sink.note(source, msg);
    }

    fn push(&mut self, rec: RigRecord, sink: &mut dyn LiveSink) -> Result<(), navsync::Error> {
        if let RigRecord::Imu { .. } = rec {
            self.waiting += 1;
        }
        let mut out = std::mem::take(&mut self.out);
        self.engine.push_into(rec, 0, &mut out);
        let r = self.consume(&mut out, sink);
        self.out = out;
        let st = self.engine.lock_state();
        if st != self.state {
            self.state = st;
            let at_s = self.elapsed_s();
            self.changes.push(StateChange { at_s, state: st });
            let msg = format!("clock {st:?}").to_lowercase();
            self.note(sink, SourceId::Engine, &msg);
        }
        if self.waiting > self.max_waiting {
            self.restart_engine(sink);
        }
        r
    }

    fn restart_engine(&mut self, sink: &mut dyn LiveSink) {
        let dropped = self.arrivals.len() as u64;
        self.counts.imu_dropped_no_time += dropped;
        self.counts.engine_restarts += 1;
        self.arrivals.clear();
        self.waiting = 0;
        self.imu_seq = 0;
        self.engine = SyncEngine::new(&self.header, self.sync_cfg.clone());
        self.inc = IncrementBuilder::new(self.header.imu_kind);
        let msg = format!(
            "no time reference (PPS lock or GNSS) for {} IMU samples: {dropped} dropped, synchronization restarted",
            self.max_waiting
        );
        self.note(sink, SourceId::Engine, &msg);
    }

    fn consume(
        &mut self,
        out: &mut Vec<SyncOutput>,
        sink: &mut dyn LiveSink,
    ) -> Result<(), navsync::Error> {
        for o in out.drain(..) {
            match o {
                SyncOutput::Imu(s) => {
                    self.waiting = 0;
                    let mut arrival = 0;
                    while let Some(&(seq, a)) = self.arrivals.front()
                        && seq <= s.seq
                    {
                        self.arrivals.pop_front();
                        arrival = a;
                    }
                    self.counts.imu_lost += s.flags.lost_before as u64;
                    if s.flags.unstamped {
                        self.counts.imu_unstamped += 1;
                        continue;
                    }
                    self.counts.imu_stamped += 1;
                    self.last_imu_time = Some(s.time);
                    let Some(sample) = self.inc.push(s.time, &s.values, &s.flags) else {
                        continue;
                    };
                    let Some(f) = self.navigator.as_mut() else {
                        continue;
                    };
                    // Live output goes to the live sink below, with the
                    // sample's arrival and bound.
                    let Step::Solution(nav) = f.push_imu(&sample, &mut NullSink)? else {
                        continue;
                    };
                    let stats = f.fusion().stats();
                    self.counts.gnss_fused = stats.gnss_fixes_used as u64;
                    self.counts.headings_fused = stats.heading_updates as u64;
                    self.counts.headings_rejected = stats.heading_rejected as u64;
                    let lat = hostclock::now_ns().saturating_sub(arrival);
                    self.latency.push(lat);
                    self.counts.solutions += 1;
                    let info = NavInfo {
                        seq: s.seq,
                        arrival_ns: arrival,
                        bound_s: s.bound_s,
                        holdover: s.flags.holdover,
                        latency_ns: lat,
                    };
                    sink.nav(&nav, &info)?;
                    let sec = nav.nav.time.ns().div_euclid(navsync::time::NS_PER_S);
                    if self.aux_second != Some(sec) {
                        self.aux_second = Some(sec);
                        let (sd, _) = f.fusion_mut().written_figures();
                        sink.aux(&nav, &sd)?;
                    }
                    self.last = Some((nav, info));
                }
                // Headings reach the filter from the port directly
                // ([`Core::heading`]); the engine is given none.
                SyncOutput::Heading(_) => {}
                SyncOutput::Gnss(g) => {
                    let mut fix = g.fix();
                    if let Some(full) = self.recent_fixes.iter().find(|f| f.time == g.time) {
                        fix = *full;
                    }
                    // Fixes stamped in a backlog (the clock just locked) are
                    // too old to start from or to fuse.
                    let stale = self
                        .last_imu_time
                        .is_some_and(|t| t.seconds_since(g.received) > self.max_gnss_latency_s);
                    if self.navigator.is_none() && stale {
                        continue;
                    }
                    if self.navigator.is_none() && self.init_from_gnss {
                        let mut fc = self.fusion_cfg.clone();
                        fc.init_nav.time = fix.time;
                        fc.init_nav.pos = fix.pos;
                        if let Some(v) = fix.vel {
                            fc.init_nav.vel = v;
                        }
                        let yaw_note = self.yaw_from_first_heading(&mut fc, fix.time);
                        self.navigator = Some(Navigator::new(fc).with_aux_interval(None));
                        let msg = format!(
                            "fusion started at {} from the GNSS fix ({:.7}°, {:.7}°, {:.2} m){yaw_note}",
                            fix.time,
                            fix.pos.lat_rad.to_degrees(),
                            fix.pos.lon_rad.to_degrees(),
                            fix.pos.h_m
                        );
                        self.note(sink, SourceId::Engine, &msg);
                    }
                    if let Some(f) = self.navigator.as_mut() {
                        // Fused at the next IMU sample, which counts it.
                        f.push_gnss(fix);
                    }
                }
            }
        }
        Ok(())
    }

    /// A dual-antenna heading: fused at its time when heading updates are
    /// on and it is not older than the latency limit; before the fusion
    /// starts, kept for the initial yaw.
    fn heading(&mut self, h: HeadingObs, sink: &mut dyn LiveSink) {
        self.counts.gnss_headings += 1;
        if self.fusion_cfg.heading.is_none() {
            if !self.headings_unused_noted {
                self.headings_unused_noted = true;
                let msg = "the receiver sends dual-antenna headings, but heading updates are off (--heading turns them on)";
                self.note(sink, SourceId::Gnss, msg);
            }
            return;
        }
        let stale = self
            .last_imu_time
            .is_some_and(|t| t.seconds_since(h.time) > self.max_gnss_latency_s);
        match self.navigator.as_mut() {
            _ if stale => self.counts.headings_stale += 1,
            Some(f) => f.push_heading(h),
            None => {
                self.counts.headings_before_start += 1;
                if self.early_headings.len() == EARLY_HEADINGS {
                    self.early_headings.pop_front();
                }
                self.early_headings.push_back(h);
            }
        }
    }

    /// With heading updates on and the configuration's initial yaw unknown
    /// (σ > 90°), the initial yaw from the heading nearest `start` in time
    /// (within 1 s): the body yaw of the baseline azimuth at the configured roll
    /// and pitch, σ = heading σ ⊕ mounting σ. Returns what it did, for the
    /// start note.
    fn yaw_from_first_heading(&self, fc: &mut FusionConfig, start: GpsTime) -> String {
        let off = |h: &HeadingObs| h.time.seconds_since(start).abs();
        let nearest = self
            .early_headings
            .iter()
            .min_by(|a, b| off(a).total_cmp(&off(b)))
            .copied();
        let (Some(opts), Some(h)) = (fc.heading.as_mut(), nearest) else {
            return String::new();
        };
        if fc.init_std.att.z <= std::f64::consts::FRAC_PI_2 || off(&h) > 1.0 {
            return String::new();
        }
        let [roll, pitch, _] = fc.init_nav.euler().to_deg().map(f64::to_radians);
        let yaw = navsync::align::yaw_from_baseline(
            h.heading_rad,
            roll,
            pitch,
            opts.dual_antenna_yaw_rad,
        );
        let sd = h.sd_rad.hypot(opts.dual_antenna_yaw_sd_rad);
        fc.init_nav = navsync::types::NavState::new(
            fc.init_nav.time,
            fc.init_nav.pos,
            fc.init_nav.vel,
            &navsync::attitude::Euler::new(roll, pitch, yaw),
        );
        fc.init_std.att.z = sd;
        opts.aligned_from_baseline = true;
        format!(
            ", heading {:.2}° ± {:.2}° from the dual-antenna baseline",
            yaw.to_degrees().rem_euclid(360.0),
            sd.to_degrees()
        )
    }

    fn status(&self, imu_up: bool, gnss_up: bool, pps_up: bool) -> LiveStatus {
        let (time, pos, vel, att, bound) = match &self.last {
            Some((n, i)) => (
                Some(n.nav.time),
                Some([
                    n.nav.pos.lat_rad.to_degrees(),
                    n.nav.pos.lon_rad.to_degrees(),
                    n.nav.pos.h_m,
                ]),
                Some([n.nav.vel.x, n.nav.vel.y, n.nav.vel.z]),
                Some(n.nav.euler().to_deg()),
                Some(i.bound_s * 1e6),
            ),
            None => (None, None, None, None, None),
        };
        let s = self.latency.summary();
        LiveStatus {
            elapsed_s: self.elapsed_s(),
            state: self.state,
            mode: if self.sync_cfg.mode != SyncMode::Sw {
                "pps"
            } else {
                "receive-time"
            },
            imu_up,
            gnss_up,
            pps_up,
            counts: self.counts.clone(),
            time,
            pos,
            vel,
            att_deg: att,
            latency_median_us: s.median_us,
            latency_max_us: s.max_us,
            bound_us: bound,
        }
    }
}

/// Runs live until `stop` is set or the configured duration ends.
pub fn run(cfg: LiveConfig, stop: &AtomicBool, sink: &mut dyn LiveSink) -> io::Result<LiveReport> {
    let bad = |msg: String| io::Error::new(io::ErrorKind::InvalidInput, msg);
    match (&cfg.imu, cfg.esf_tick_s) {
        (Some(p), None) => {
            crate::serial::check_baud(p.baud).map_err(|e| bad(format!("--imu-baud: {e}")))?
        }
        (None, Some(t)) if t.is_finite() && t > 0.0 => {}
        (None, Some(t)) => return Err(bad(format!("ESF time-tag tick {t} s is not positive"))),
        (Some(_), Some(_)) => {
            return Err(bad(
                "the IMU is either on its own port or in ESF messages on the GNSS port, not both"
                    .into(),
            ));
        }
        (None, None) => {
            return Err(bad(
                "no IMU: give its port, or read ESF messages on the GNSS port".into(),
            ));
        }
    }
    crate::serial::check_baud(cfg.gnss.baud)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("--gnss-baud: {e}")))?;
    if let Some(why) = navsync_receivers::convert::heading_problem(cfg.hdt_sd_deg) {
        return Err(bad(format!("--hdt-sd: HDT heading σ: {why}")));
    }
    if !(cfg.imu_rate_hz.is_finite() && cfg.imu_rate_hz > 0.0) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("IMU rate {} Hz is not positive", cfg.imu_rate_hz),
        ));
    }
    let recorder = if cfg.record.is_some() || cfg.record_gnss.is_some() {
        let comments = record_comments(&cfg);
        Some(Recorder::create(
            cfg.record.as_deref(),
            cfg.record_gnss.as_deref(),
            &record_header(&cfg),
            &comments,
        )?)
    } else {
        None
    };
    let started = Instant::now();
    let cpu0 = hostclock::cpu_seconds();
    let (tx, rx) = mpsc::sync_channel::<Input>(CHANNEL_DEPTH);
    let halt = Arc::new(AtomicBool::new(false));
    let mut core = Core::new(&cfg);
    core.recorder = recorder;
    let retry = cfg.reopen_interval;
    let has_pps = !matches!(cfg.pps, PpsInput::None);
    let mut handles = vec![spawn_gnss(&cfg, tx.clone(), halt.clone())?];
    if let Some(p) = cfg.imu.clone() {
        handles.push(spawn_imu(&cfg, p, tx.clone(), halt.clone())?);
    }
    let sources = handles.len() + usize::from(has_pps);
    let status_every = cfg.status_interval;
    let duration = cfg.duration;
    if let Some(h) = spawn_pps(cfg.pps, retry, tx.clone(), halt.clone())? {
        handles.push(h);
    }
    drop(tx);
    let result = engine_loop(
        &mut core,
        &rx,
        stop,
        sink,
        started,
        duration,
        status_every,
        sources,
    );
    halt.store(true, Ordering::SeqCst);
    drop(rx);
    for h in handles {
        let _ = h.join();
    }
    // What the engine took in is written even when the run failed.
    let fin = core.recorder.as_mut().map(|r| r.finish());
    result?;
    fin.transpose()?;
    let recorded = core.recorder.as_ref().map(|r| r.counts.clone());
    let duration_s = started.elapsed().as_secs_f64();
    let cpu_s = hostclock::cpu_seconds() - cpu0;
    let Core {
        engine,
        counts,
        latency,
        changes,
        notes_total,
        first_notes,
        ..
    } = core;
    let (sync, sync_error) = match engine.finish() {
        Ok((_, r)) => (Some(r), None),
        Err(e) => (None, Some(e.to_string())),
    };
    Ok(LiveReport {
        duration_s,
        counts,
        latency: latency.summary(),
        cpu_s,
        cpu_percent: 100.0 * cpu_s / duration_s.max(1e-9),
        state_changes: changes,
        sync,
        sync_error,
        notes_total,
        first_notes,
        recorded,
    })
}

#[allow(clippy::too_many_arguments)]
fn engine_loop(
    core: &mut Core,
    rx: &Receiver<Input>,
    stop: &AtomicBool,
    sink: &mut dyn LiveSink,
    started: Instant,
    duration: Option<Duration>,
    status_every: Duration,
    sources: usize,
) -> io::Result<()> {
    let (mut imu_up, mut gnss_up, mut pps_up) = (false, false, false);
    let mut next_status = Instant::now() + status_every;
    let mut done = 0;
    let to_io = |e: navsync::Error| io::Error::other(e.to_string());
    loop {
        if stop.load(Ordering::Relaxed) || duration.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
        let wait = next_status.saturating_duration_since(Instant::now());
        match rx.recv_timeout(wait.min(Duration::from_millis(100))) {
            Ok(Input::Imu {
                arrival_ns,
                counter,
                values,
                line,
            }) => {
                imu_up = true;
                core.counts.imu_lines += 1;
                core.arrivals.push_back((core.imu_seq, arrival_ns));
                core.imu_seq += 1;
                let rec = RigRecord::Imu { counter, values };
                core.record(rec);
                if let Some(l) = line {
                    hint_engine(&mut core.engine, l);
                }
                core.push(rec, sink).map_err(to_io)?;
            }
            Ok(Input::Gnss(f)) => {
                core.counts.gnss_fixes += 1;
                core.recent_fixes.push_back(f.fix);
                if core.recent_fixes.len() > 64 {
                    core.recent_fixes.pop_front();
                }
                let (lat, lon) = (
                    f.fix.pos.lat_rad.to_degrees(),
                    f.fix.pos.lon_rad.to_degrees(),
                );
                let rec = RigRecord::Gnss(RigGnss {
                    counter: f.received_ns,
                    time: f.fix.time,
                    lat_deg: lat,
                    lon_deg: lon,
                    h_m: f.fix.pos.h_m,
                    sd_m: [f.fix.pos_sd.x, f.fix.pos_sd.y, f.fix.pos_sd.z],
                });
                core.record(rec);
                core.push(rec, sink).map_err(to_io)?;
            }
            Ok(Input::Heading(h, received_ns)) => {
                // Recorded on its GPS time (`sync` passes it through to
                // heading.txt); the filter takes it from here.
                core.record(RigRecord::Heading(RigHeading::from_obs(received_ns, &h)));
                core.heading(h, sink);
            }
            Ok(Input::GnssRaw(bytes)) => {
                if let Some(r) = core.recorder.as_mut() {
                    r.raw_gnss(&bytes);
                }
            }
            Ok(Input::Pps(e)) => {
                pps_up = true;
                core.counts.pps_edges += 1;
                core.counts.pps_missed += e.missed;
                let rec = RigRecord::Pps { counter: e.host_ns };
                core.record(rec);
                core.push(rec, sink).map_err(to_io)?;
            }
            Ok(Input::Note { source, msg, up }) => {
                if let Some(u) = up {
                    let flag = match source {
                        SourceId::Imu => &mut imu_up,
                        SourceId::Gnss => &mut gnss_up,
                        _ => &mut pps_up,
                    };
                    if u && !*flag && core.counts.imu_lines + core.counts.gnss_fixes > 0 {
                        core.counts.reopens += 1;
                    }
                    *flag = u;
                }
                if source == SourceId::Gnss && up.is_none() {
                    core.counts.gnss_problems += 1;
                }
                core.note(sink, source, &msg);
            }
            Ok(Input::BadImuLine(msg)) => {
                core.counts.imu_bad_lines += 1;
                // Garbage floods are counted; the first lines are shown.
                if core.counts.imu_bad_lines <= 20 {
                    core.note(sink, SourceId::Imu, &msg);
                }
            }
            Ok(Input::Done) => {
                done += 1;
                if done == sources {
                    break;
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if let Some(r) = core.recorder.as_mut() {
            r.tick(hostclock::now_ns())?;
        }
        if Instant::now() >= next_status {
            next_status += status_every;
            sink.status(&core.status(imu_up, gnss_up, pps_up));
        }
    }
    sink.status(&core.status(imu_up, gnss_up, pps_up));
    Ok(())
}
