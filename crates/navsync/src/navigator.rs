//! The streaming composition of navsync: records in, fused solutions out.
//!
//! A [`Navigator`] owns the filter ([`crate::fusion::Fusion`]) and the glue
//! every caller used to rebuild: the GNSS fix queue (fixes delivered when
//! the IMU reaches their time, or their arrival in a real-time latency
//! mode), simulated outages, reduced-IMU pseudo-signals, odometer speeds,
//! the auxiliary output interval, `--output-at` interpolation, and the move
//! of solutions to GNSS time. With a rig-log front end
//! ([`Navigator::with_rig_sync`]) raw logger records (1PPS edges, counter
//! stamped IMU and GNSS records) go in and the synchronization engine
//! ([`crate::timing::engine::SyncEngine`]) puts them on GPS time first.
//!
//! Batch fusion of files ([`crate::pipeline::run`]), `navsync live` and
//! the simulator chain are loops over this one type.
//!
//! ```
//! use nalgebra::Vector3;
//! use navsync::attitude::Euler;
//! use navsync::earth::{Geodetic, gravity};
//! use navsync::fusion::FusionConfig;
//! use navsync::ins::{ImuSample, NavState};
//! use navsync::navigator::{Navigator, Step};
//! use navsync::navigator::NullSink;
//! use navsync::sensor::ImuFigures;
//! use navsync::GpsTime;
//!
//! // A levelled IMU at rest at 45° N, heading north; the datasheet of an
//! // ADIS16465-class IMU sets the filter's noise model.
//! let t0 = GpsTime::from_week_ns(2200, 100_000_000_000_000);
//! let pos = Geodetic::from_deg(45.0, 7.0, 300.0);
//! let imu = ImuFigures::preset("adis16465").unwrap();
//! let init = NavState::new(t0, pos, Vector3::zeros(), &Euler::default());
//! let cfg = FusionConfig::new(init, imu.initial_std(), imu.noise(), 200.0);
//! let mut nav = Navigator::new(cfg);
//! let g = gravity(pos.lat_rad.sin(), pos.h_m);
//! let mut last = None;
//! for k in 0..=400 {
//!     let s = ImuSample {
//!         time: t0.add_seconds(k as f64 * 0.005),
//!         dtheta: Vector3::zeros(),
//!         dvel: Vector3::new(0.0, 0.0, -g * 0.005),
//!         odo_speed: None,
//!     };
//!     if let Step::Solution(out) = nav.push_imu(&s, &mut NullSink).unwrap() {
//!         last = Some(out.nav);
//!     }
//! }
//! // Two seconds at rest: the solution stays within centimetres.
//! let end = last.unwrap();
//! assert!((end.pos.h_m - 300.0).abs() < 0.05 && end.vel.norm() < 0.05);
//! ```
#![warn(missing_docs)]

use std::collections::VecDeque;

use nalgebra::Matrix3;

use crate::error::{Diagnostics, Error};
use crate::filter::gnss::GnssFix;
use crate::fusion::TimeOffsetState;
use crate::fusion::{FixRecord, Fusion, FusionConfig, LatencyMode, NavOutput, Revised};
use crate::ins::{ImuErrors, ImuSample, NavState};
use crate::interp::NavInterpolator;
use crate::io::riglog::{RigHeader, RigRecord};
use crate::reduced::ReducedImu;
use crate::time::GpsTime;
use crate::time::OutageSchedule;
use crate::time::seconds_to_ns;
use crate::timing::engine::{SyncConfig, SyncEngine, SyncOutput};
use crate::timing::imu::{IncrementBuilder, RateRule};
use crate::timing::report::SyncReport;

/// Receives the solution of a stream (a file writer, a plot, a socket).
pub trait NavSink {
    /// Every IMU epoch.
    fn nav(&mut self, out: &NavState, imu: &ImuErrors) -> Result<(), Error>;
    /// At the auxiliary interval: IMU errors, all state σ (SI) and the
    /// time-offset estimate when it is a state.
    fn aux(
        &mut self,
        _time: GpsTime,
        _imu: &ImuErrors,
        _sd: &[f64],
        _offset: Option<TimeOffsetState>,
    ) -> Result<(), Error> {
        Ok(())
    }
    /// The solution interpolated at a requested epoch (`--output-at`).
    fn nav_at(&mut self, _nav: &NavState) -> Result<(), Error> {
        Ok(())
    }
    /// At the end of the run: every GNSS observation the filter weighed.
    fn fix_records(&mut self, _records: &[FixRecord]) -> Result<(), Error> {
        Ok(())
    }
    /// Right after [`Self::aux`]: the position-error covariance (m², NED),
    /// for consistency tests (NEES).
    fn position_covariance(
        &mut self,
        _time: GpsTime,
        _p_ned_m2: &nalgebra::Matrix3<f64>,
    ) -> Result<(), Error> {
        Ok(())
    }
}

/// A sink that keeps nothing (benchmarks, studies that only need a summary).
pub struct NullSink;

impl NavSink for NullSink {
    fn nav(&mut self, _: &NavState, _: &ImuErrors) -> Result<(), Error> {
        Ok(())
    }
}

/// What one IMU sample produced.
// Returned by value once per sample: boxing the solution would allocate at
// the IMU rate for no gain.
#[allow(clippy::large_enum_variant)]
#[derive(Copy, Clone, Debug)]
pub enum Step {
    /// The filter is not running yet (the first sample sets its clock).
    Starting,
    /// The solution at this sample, handed to the sink (unless GNSS-time
    /// output left it out: the stream's diagnostics count those).
    Solution(NavOutput),
    /// The sample lies after the configured end: nothing was done.
    Ended,
}

/// Counts of a stream, for a run's summary.
#[derive(Clone, Debug, Default)]
pub struct StreamCounts {
    /// First IMU epoch of the run (the first sample at or after its start).
    pub first_epoch: Option<GpsTime>,
    /// Time of the last solution.
    pub last_epoch: Option<GpsTime>,
    /// Fixes withheld by the simulated outages.
    pub fixes_withheld: usize,
    /// Fixes at or before the start time (not fused).
    pub fixes_outside: usize,
    /// Solutions written at the `output_at` epochs, and requested epochs
    /// that fell outside the data.
    pub(crate) output_at_written: usize,
    pub(crate) output_at_skipped: usize,
}

/// Raw logger records → synchronized samples, in front of the filter.
struct RigFrontEnd {
    engine: SyncEngine,
    increments: IncrementBuilder,
    out: Vec<SyncOutput>,
    line: usize,
}

/// How long [`Navigator::with_revised_output`] holds solutions back (s):
/// longer than the filter keeps the states a rollback returns to
/// (`fusion::rollback`, stored at most every 0.9 s).
const HOLD_S: f64 = crate::fusion::ROLLBACK_KEEP_S + 4.0;

/// The auxiliary line of a solution: all state σ, the position
/// covariance (m², NED) and the time offset with its σ.
pub(crate) type AuxLine = (Vec<f64>, Matrix3<f64>, Option<TimeOffsetState>);

/// Adds `extra` (m², NED) to an auxiliary line's position covariance and
/// position σ: a jump the fixes left undecided (`fusion::jump_doubt`), the
/// fixes' error that outlasts their spacing (`fusion::fix_correlation`).
pub(crate) fn widen_position(aux: &mut AuxLine, extra: &Matrix3<f64>) {
    crate::fusion::widen_position(&mut aux.0, &mut aux.1, extra);
}

/// A solution held back before it is written (see
/// [`Navigator::with_revised_output`]).
struct Held {
    nav: NavState,
    imu: ImuErrors,
    offset: Option<TimeOffsetState>,
    aux: Option<AuxLine>,
    /// The auxiliary schedule before this solution.
    next_aux_before: Option<GpsTime>,
}

/// The streaming navigator: push GNSS fixes, speeds and IMU samples (or raw
/// rig-log records); solutions come out through a [`NavSink`].
pub struct Navigator {
    fusion: Fusion,
    /// The initial state's time: the first IMU epoch is the first sample at
    /// or after it.
    start: GpsTime,
    /// Count fixes at or before `start` as outside the run and drop them
    /// (a batch run; a live start from a fix keeps that fix).
    drop_fixes_before_start: bool,
    end: Option<GpsTime>,
    /// Fixes not yet handed to the filter, in the order pushed.
    pending: VecDeque<GnssFix>,
    /// A fix is delivered once the IMU time + this reaches its time tag
    /// (ns); `None` delivers at the next IMU sample.
    fix_lead_ns: Option<i64>,
    outages: Option<OutageSchedule>,
    reduced_imu: Option<ReducedImu>,
    nominal_dt_s: f64,
    output: SolutionOutput,
    /// With [`Self::with_revised_output`]: the solutions of the last
    /// [`HOLD_S`] not yet written, oldest first.
    held: Option<VecDeque<Held>>,
    /// The navigator's own counts (the output's are read from `output`:
    /// see [`Self::counts`]).
    counts: StreamCounts,
    rig: Option<RigFrontEnd>,
}

/// How solutions reach a sink: stamped in GNSS time on request (kept
/// strictly increasing), interpolated at requested epochs, and the
/// auxiliary lines at their interval. The forward stream and the smoother's
/// output pass write through the same one.
pub(crate) struct SolutionOutput {
    output_gnss_time: bool,
    /// Interval of the auxiliary output (ns); `None`: none.
    aux_ns: Option<i64>,
    next_aux: Option<GpsTime>,
    interp: Option<NavInterpolator>,
    /// Time of the last solution handed to the sink.
    last_written: Option<GpsTime>,
    /// Interpolated epochs written.
    pub(crate) at_written: usize,
    /// Solutions left out of the GNSS-time output (τ̂ stepped back).
    pub(crate) out_of_order: usize,
}

impl SolutionOutput {
    pub(crate) fn new(
        output_gnss_time: bool,
        aux_interval_s: Option<f64>,
        interp: Option<NavInterpolator>,
    ) -> Self {
        SolutionOutput {
            output_gnss_time,
            aux_ns: aux_interval_s.map(seconds_to_ns),
            next_aux: None,
            interp,
            last_written: None,
            at_written: 0,
            out_of_order: 0,
        }
    }

    /// The first epoch: the auxiliary schedule counts from it.
    pub(crate) fn start(&mut self, t: GpsTime) {
        self.next_aux = self.aux_ns.map(|_| t);
    }

    /// Whether an auxiliary line is due with the solution at `t` (advancing
    /// the schedule when it is).
    pub(crate) fn take_aux_due(&mut self, t: GpsTime) -> bool {
        let Some(na) = self.next_aux else {
            return false;
        };
        if t < na {
            return false;
        }
        self.next_aux = Some(match self.aux_ns {
            Some(ns) if ns > 0 => na + ns,
            _ => t,
        });
        true
    }

    /// One solution at IMU time `nav.time` with the time offset `offset`,
    /// and its auxiliary line when one is due ([`Self::take_aux_due`]):
    /// all state σ, the position covariance and the time offset with its
    /// σ. `false`: left out (GNSS time stepped back).
    pub(crate) fn write(
        &mut self,
        nav: &NavState,
        imu: &ImuErrors,
        offset: Option<TimeOffsetState>,
        sink: &mut dyn NavSink,
        aux: Option<AuxLine>,
    ) -> Result<bool, Error> {
        // Solutions are on the IMU's time base; on request, move them to
        // GNSS time with the offset estimate (GNSS time = IMU time + τ̂).
        let mut nav_out = *nav;
        if self.output_gnss_time
            && let Some(o) = offset
        {
            nav_out.time = nav_out.time.add_seconds(o.offset_s);
            // A step of τ̂ larger than the sample interval would send the
            // output back in time: such solutions are left out, so the
            // written solution stays strictly increasing.
            if self.last_written.is_some_and(|t| nav_out.time <= t) {
                self.out_of_order += 1;
                return Ok(false);
            }
        }
        self.last_written = Some(nav_out.time);
        sink.nav(&nav_out, imu)?;
        if let Some(ip) = self.interp.as_mut() {
            for at in ip.push(&nav_out) {
                self.at_written += 1;
                sink.nav_at(&at)?;
            }
        }
        if let Some((sd, p_pos, offset)) = aux {
            sink.aux(nav.time, imu, &sd, offset)?;
            sink.position_covariance(nav.time, &p_pos)?;
        }
        Ok(true)
    }

    /// The end of the stream: the interpolator's pending epochs are
    /// dropped; returns how many requested epochs were not written.
    pub(crate) fn finish(&mut self) -> usize {
        match self.interp.as_mut() {
            Some(ip) => {
                ip.finish();
                ip.skipped
            }
            None => 0,
        }
    }
}

impl Navigator {
    /// A navigator over a filter configuration: fixes are fused at the next
    /// IMU sample, auxiliary output every 0.1 s, no outages.
    pub fn new(cfg: FusionConfig) -> Self {
        let start = cfg.init_nav.time;
        let nominal_dt_s = 1.0 / cfg.imu_rate_hz.max(1e-9);
        Navigator {
            fusion: Fusion::new(cfg),
            start,
            drop_fixes_before_start: false,
            end: None,
            pending: VecDeque::new(),
            fix_lead_ns: None,
            outages: None,
            reduced_imu: None,
            nominal_dt_s,
            output: SolutionOutput::new(false, Some(0.1), None),
            held: None,
            counts: StreamCounts::default(),
            rig: None,
        }
    }

    /// A batch run: fixes at or before the initial state's time are
    /// outside the run (counted, not fused), and each fix is handed to the
    /// filter once the IMU time + `lead_s` reaches its tag (offline, a lead
    /// lets the filter and the time-offset search see fixes early; in a
    /// real-time latency mode a negative lead delivers each at its arrival).
    pub fn for_batch(mut self, lead_s: f64) -> Self {
        self.drop_fixes_before_start = true;
        self.fix_lead_ns = Some(seconds_to_ns(lead_s));
        self
    }

    /// Offline: solutions reach the sink `HOLD_S` (59 s) late, so that when the
    /// filter returns to a stored state and runs again (a ramp's onset or end or
    /// a stale run found, `fusion::rollback`) the re-run's solutions are
    /// written in place of those it replaces: the written forward solution
    /// is then the filter's on the fixes it kept, not one led off by the
    /// fault until it was found. The solutions [`Self::push_imu`] returns
    /// are not held (a streaming caller gets each at once, and the re-run's
    /// last in place of the current one). No effect without rollbacks
    /// (the real-time latency modes).
    pub fn with_revised_output(mut self) -> Self {
        self.fusion.keep_revisions();
        if self.fusion.keeps_revisions() {
            self.held = Some(VecDeque::new());
        }
        self
    }

    /// Reduced IMU: absent sensors replaced by pseudo-signals.
    pub fn with_reduced_imu(mut self, reduced: Option<ReducedImu>) -> Self {
        self.reduced_imu = reduced;
        self
    }

    /// Stamp the solutions in GNSS time (IMU time + τ̂) instead of the IMU's
    /// time base; they stay strictly increasing.
    pub fn with_gnss_time_output(mut self, on: bool) -> Self {
        self.output.output_gnss_time = on;
        self
    }

    /// Auxiliary output ([`NavSink::aux`]: IMU errors, σ, time offset) at
    /// this interval (s; 0 at every epoch), or none.
    pub fn with_aux_interval(mut self, interval_s: Option<f64>) -> Self {
        self.output.aux_ns = interval_s.map(seconds_to_ns);
        self
    }

    /// Stop at this time: later IMU samples return [`Step::Ended`].
    pub fn with_end(mut self, end: Option<GpsTime>) -> Self {
        self.end = end;
        self
    }

    /// Withhold the fixes inside these outage windows (counted from the
    /// first IMU epoch).
    pub fn with_outages(mut self, outages: Option<OutageSchedule>) -> Self {
        self.outages = outages;
        self
    }

    /// Write the solution interpolated at the interpolator's requested
    /// epochs as well ([`NavSink::nav_at`]).
    pub fn with_interpolator(mut self, interp: Option<NavInterpolator>) -> Self {
        self.output.interp = interp;
        self
    }

    /// Put raw rig-log records through the synchronization engine first
    /// ([`Self::push_record`]); rates become increments by the header's
    /// rule (`RateRule::for_header`). A rig log delivers each fix when
    /// its last byte arrived, after the IMU passed its time of validity: an
    /// offline filter becomes a delayed-state one (the update at the fix's
    /// time, then forward again over the buffered samples; exact, like
    /// offline) with up to 1 s of latency.
    pub fn with_rig_sync(mut self, header: &RigHeader, sync: SyncConfig) -> Self {
        if self.fusion.config().latency == LatencyMode::Offline {
            let mut cfg = self.fusion.config().clone();
            cfg.latency = LatencyMode::DelayedState { max_latency_s: 1.0 };
            self.fusion = Fusion::new(cfg);
        }
        self.rig = Some(RigFrontEnd {
            increments: IncrementBuilder::with_rule(header.imu_kind, RateRule::for_header(header)),
            engine: SyncEngine::new(header, sync),
            out: Vec::new(),
            line: 0,
        });
        self
    }

    /// The filter (state, σ, statistics).
    pub fn fusion(&self) -> &Fusion {
        &self.fusion
    }

    /// The filter, mutably (smoother set-up, diagnostics).
    pub fn fusion_mut(&mut self) -> &mut Fusion {
        &mut self.fusion
    }

    /// The filter, after the stream.
    pub fn into_fusion(self) -> Fusion {
        self.fusion
    }

    /// What the stream counted so far (the output's counters are read
    /// from the output itself).
    pub fn counts(&self) -> StreamCounts {
        StreamCounts {
            output_at_written: self.output.at_written,
            ..self.counts.clone()
        }
    }

    /// Fixes waiting for the IMU to reach them.
    #[cfg(test)]
    pub(crate) fn pending_fixes(&self) -> usize {
        self.pending.len()
    }

    /// A GNSS fix (at its time of validity). It is fused when the IMU
    /// reaches it (offline) or its arrival (real-time latency modes).
    pub fn push_gnss(&mut self, fix: GnssFix) {
        self.pending.push_back(fix);
    }

    /// A dual-antenna heading, used at the first IMU sample at or after
    /// its time.
    pub fn push_heading(&mut self, h: crate::io::heading::HeadingObs) {
        self.fusion.push_heading(h);
    }

    /// An odometer/CAN speed (m/s) valid at the next IMU sample.
    pub fn push_speed(&mut self, speed_mps: f64) {
        self.fusion.push_speed(speed_mps);
    }

    /// Hands the fixes this IMU time reaches to the filter.
    fn deliver_fixes(&mut self, imu_time: GpsTime) -> Result<(), Error> {
        while let Some(fix) = self.pending.front().copied() {
            if let Some(lead) = self.fix_lead_ns
                && fix.time > imu_time + lead
            {
                break;
            }
            self.pending.pop_front();
            // Outages are measured from the first IMU epoch, which is the
            // first sample at or after the start time.
            let t_ref = self.counts.first_epoch.unwrap_or(imu_time);
            if self.drop_fixes_before_start && fix.time <= self.start {
                self.counts.fixes_outside += 1;
            } else if let Some(o) = self.outages
                && o.contains(t_ref, fix.time)
            {
                self.counts.fixes_withheld += 1;
            } else {
                self.fusion.push_gnss(fix)?;
            }
        }
        Ok(())
    }

    /// One IMU sample: fixes it reaches are fused first, then the sample is
    /// mechanized; the solution goes to `sink` (and the auxiliary lines at
    /// their interval, the interpolated epochs it passes).
    pub fn push_imu(&mut self, sample: &ImuSample, sink: &mut dyn NavSink) -> Result<Step, Error> {
        if let Some(e) = self.end
            && sample.time > e
        {
            return Ok(Step::Ended);
        }
        self.deliver_fixes(sample.time)?;
        let mut s = *sample;
        if let Some(r) = &self.reduced_imu {
            let dt = s.time.seconds_since(self.fusion.nav().time);
            let dt = if dt > 0.0 && dt < 1.0 {
                dt
            } else {
                self.nominal_dt_s
            };
            r.fill(&mut s, self.fusion.nav(), self.fusion.imu_errors(), dt);
        }
        let Some(out) = self.fusion.push_imu(&s)? else {
            if self.counts.first_epoch.is_none() && s.time >= self.start {
                self.counts.first_epoch = Some(s.time);
                self.output.start(s.time);
            }
            return Ok(Step::Starting);
        };
        self.counts.last_epoch = Some(out.nav.time);
        let fusion = &mut self.fusion;
        let offset = fusion.time_offset();
        let next_aux_before = self.output.next_aux;
        let aux_due = self.output.take_aux_due(out.nav.time);
        let aux = aux_due.then(|| {
            let (sd, cov) = fusion.written_figures();
            (sd, cov, fusion.time_offset())
        });
        let Some(held) = self.held.as_mut() else {
            self.output.write(&out.nav, &out.imu, offset, sink, aux)?;
            return Ok(Step::Solution(out));
        };
        held.push_back(Held {
            nav: out.nav,
            imu: out.imu,
            offset,
            aux,
            next_aux_before,
        });
        let out = match self.fusion.take_revision() {
            Some(revised) => self.revise(revised).unwrap_or(out),
            None => out,
        };
        self.write_held(sink, Some(out.nav.time.add_seconds(-HOLD_S)))?;
        Ok(Step::Solution(out))
    }

    /// Replaces the held solutions from the first revised one's time on by
    /// the revised ones (their auxiliary lines on the same schedule);
    /// returns the last. Revised solutions older than every held one are
    /// dropped (they were written: a rollback further back than
    /// [`HOLD_S`]).
    fn revise(&mut self, revised: Vec<Revised>) -> Option<NavOutput> {
        let held = self.held.as_mut()?;
        let first = revised.first()?.out.nav.time;
        let oldest = held.front().map(|h| h.nav.time);
        if let Some(k) = held.iter().position(|h| h.nav.time >= first) {
            self.output.next_aux = held[k].next_aux_before;
            held.truncate(k);
        }
        let last = revised.last().map(|r| r.out);
        for r in revised {
            if oldest.is_some_and(|t| r.out.nav.time < t) {
                continue;
            }
            let next_aux_before = self.output.next_aux;
            let aux_due = self.output.take_aux_due(r.out.nav.time);
            held.push_back(Held {
                nav: r.out.nav,
                imu: r.out.imu,
                offset: r.offset,
                aux: aux_due.then_some((r.sd, r.position_covariance, r.offset)),
                next_aux_before,
            });
        }
        last
    }

    /// Writes the held solutions older than `before` (all with `None`).
    fn write_held(&mut self, sink: &mut dyn NavSink, before: Option<GpsTime>) -> Result<(), Error> {
        let Some(held) = self.held.as_mut() else {
            return Ok(());
        };
        while let Some(h) = held.front()
            && before.is_none_or(|t| h.nav.time < t)
        {
            let Some(mut h) = held.pop_front() else {
                break;
            };
            if let (Some(aux), Some(doubt)) =
                (h.aux.as_mut(), self.fusion.doubt_covariance(h.nav.time))
            {
                widen_position(aux, &doubt);
            }
            self.output.write(&h.nav, &h.imu, h.offset, sink, h.aux)?;
        }
        Ok(())
    }

    /// One raw rig-log record (needs [`Self::with_rig_sync`]): stamped by
    /// the synchronization engine, rates turned into increments, then fused
    /// as [`Self::push_gnss`] and [`Self::push_imu`] do. Returns the
    /// solutions it produced (the engine may release several samples at
    /// once, or none while it waits for the next 1PPS edge).
    pub fn push_record(
        &mut self,
        record: RigRecord,
        sink: &mut dyn NavSink,
    ) -> Result<Vec<NavOutput>, Error> {
        let Some(mut rig) = self.rig.take() else {
            return Err(Error::Invalid(
                "raw records need the synchronization front end (Navigator::with_rig_sync)".into(),
            ));
        };
        rig.line += 1;
        let mut out = std::mem::take(&mut rig.out);
        rig.engine.push_into(record, rig.line, &mut out);
        let r = self.consume_synced(&mut out, &mut rig.increments, sink);
        rig.out = out;
        self.rig = Some(rig);
        r
    }

    fn consume_synced(
        &mut self,
        out: &mut Vec<SyncOutput>,
        increments: &mut IncrementBuilder,
        sink: &mut dyn NavSink,
    ) -> Result<Vec<NavOutput>, Error> {
        let mut solutions = Vec::new();
        for o in out.drain(..) {
            match o {
                SyncOutput::Gnss(g) => self.push_gnss(g.fix()),
                // A receiver's vehicle heading only seeds an alignment.
                SyncOutput::Heading(h) => {
                    if h.source == crate::io::heading::HeadingSource::Baseline {
                        self.push_heading(h);
                    }
                }
                SyncOutput::Imu(s) => {
                    let Some(sample) = increments.push(s.time, &s.values, &s.flags) else {
                        continue;
                    };
                    if let Step::Solution(n) = self.push_imu(&sample, sink)? {
                        solutions.push(n);
                    }
                }
            }
        }
        Ok(solutions)
    }

    /// Ends the stream: the synchronization engine releases what it held,
    /// the interpolator its last epochs, and `sink` receives every GNSS
    /// observation the filter weighed.
    pub fn finish(&mut self, sink: &mut dyn NavSink) -> Result<StreamEnd, Error> {
        let mut sync_report = None;
        let mut diagnostics = Diagnostics::with_cap(1000);
        if let Some(rig) = self.rig.take() {
            let RigFrontEnd {
                engine,
                mut increments,
                ..
            } = rig;
            let (mut out, report) = engine.finish()?;
            self.consume_synced(&mut out, &mut increments, sink)?;
            sync_report = Some(report);
        }
        self.write_held(sink, None)?;
        self.counts.output_at_skipped = self.output.finish();
        diagnostics.extend(self.fusion.take_diagnostics());
        if self.output.out_of_order > 0 {
            diagnostics.note(format!(
                "{} solutions left out of the GNSS-time output: the time-offset estimate stepped back by more than a sample interval",
                self.output.out_of_order
            ));
        }
        let fix_records = self.fusion.take_fix_log();
        sink.fix_records(&fix_records)?;
        Ok(StreamEnd {
            counts: self.counts(),
            fix_records,
            sync_report,
            diagnostics,
        })
    }
}

/// What a finished stream hands back.
#[derive(Debug)]
pub struct StreamEnd {
    /// Epochs and fix counts of the run, for its summary.
    pub counts: StreamCounts,
    /// Every GNSS observation the filter weighed.
    pub fix_records: Vec<FixRecord>,
    /// The synchronization engine's report, with a rig-log front end.
    pub sync_report: Option<SyncReport>,
    /// The filter's notes (and the engine's are in its report).
    pub diagnostics: Diagnostics,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::Euler;
    use crate::earth::{Geodetic, gravity};
    use crate::ins::NavState;
    use crate::sensor::ImuFigures;
    use nalgebra::Vector3;

    fn at_rest(start: GpsTime) -> (Navigator, Geodetic, f64) {
        let pos = Geodetic::from_deg(30.0, 114.0, 20.0);
        let imu = ImuFigures::preset("adis16465").expect("preset");
        let init = NavState::new(start, pos, Vector3::zeros(), &Euler::default());
        let cfg = FusionConfig::new(init, imu.initial_std(), imu.noise(), 200.0);
        (
            Navigator::new(cfg),
            pos,
            gravity(pos.lat_rad.sin(), pos.h_m),
        )
    }

    fn sample(t: GpsTime, g: f64) -> ImuSample {
        ImuSample {
            time: t,
            dtheta: Vector3::zeros(),
            dvel: Vector3::new(0.0, 0.0, -g * 0.005),
            odo_speed: None,
        }
    }

    #[test]
    fn fixes_wait_for_the_imu_and_outages_withhold_them() {
        let t0 = GpsTime::from_week_sow(2300, 1000.0);
        let (nav, pos, g) = at_rest(t0);
        let mut nav = nav.with_outages(Some(OutageSchedule {
            period_s: 10.0,
            len_s: 1.0,
            first_s: 1.0,
        }));
        nav.fix_lead_ns = Some(0);
        // Five fixes pushed at once, ahead of the IMU (a file read ahead).
        for k in 1..=5 {
            nav.push_gnss(GnssFix {
                time: t0.add_seconds(k as f64),
                pos,
                pos_sd: Vector3::repeat(0.05),
                vel: None,
                vel_sd: None,
            });
        }
        let mut held = Vec::new();
        for k in 0..=1000 {
            let s = sample(t0.add_seconds(k as f64 * 0.005), g);
            nav.push_imu(&s, &mut NullSink).expect("push");
            if k % 200 == 100 {
                held.push(nav.pending_fixes());
            }
        }
        // At 0.5 s all five wait; one more leaves at each second.
        assert_eq!(held, vec![5, 4, 3, 2, 1]);
        // The fix at +1 s falls in the outage [+1 s, +2 s): withheld.
        assert_eq!(nav.counts().fixes_withheld, 1);
        let end = nav.finish(&mut NullSink).expect("finish");
        assert_eq!(end.fix_records.len(), 4, "fixes fused");
        assert_eq!(end.counts.first_epoch, Some(t0));
        assert_eq!(end.counts.last_epoch, Some(t0.add_seconds(5.0)));
    }

    #[test]
    fn samples_after_the_end_are_refused() {
        let t0 = GpsTime::from_week_sow(2300, 1000.0);
        let (nav, _, g) = at_rest(t0);
        let mut nav = nav.with_end(Some(t0.add_seconds(1.0)));
        let mut steps = Vec::new();
        for k in [0, 1, 200, 201] {
            let s = sample(t0.add_seconds(k as f64 * 0.005), g);
            steps.push(nav.push_imu(&s, &mut NullSink).expect("push"));
        }
        assert!(matches!(steps[0], Step::Starting));
        assert!(matches!(steps[1], Step::Solution(_)));
        assert!(matches!(steps[2], Step::Solution(_)));
        assert!(matches!(steps[3], Step::Ended));
    }

    #[test]
    fn raw_records_need_the_sync_front_end() {
        let (mut nav, _, _) = at_rest(GpsTime::from_week_sow(2300, 1000.0));
        let err = nav
            .push_record(RigRecord::Pps { counter: 1 }, &mut NullSink)
            .expect_err("no front end");
        assert!(err.to_string().contains("with_rig_sync"), "{err}");
    }
}
