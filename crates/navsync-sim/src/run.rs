//! Runs a scenario and writes every output file, streaming (memory does
//! not grow with the run's length).
//!
//! Files in the output folder:
//! - `imu.txt`: KF-GINS IMU increments on true GPS time (what a perfectly
//!   synchronized logger would hold; full precision);
//! - `gnss.txt` (7 columns) and `gnss_posvel.txt` (13, KF-GINS C++ order);
//! - `truth.nav`: the IMU centre's exact state at every IMU epoch (11
//!   columns with the week);
//! - `imu_err_truth.txt`: true biases and scale factors (KF-GINS IMU_ERR
//!   layout: deg/h, mGal, ppm);
//! - `kf-gins.yaml`: a KF-GINS configuration that runs as it is;
//! - `rig.csv`: the raw `rig-log v1` (FORMATS.md §2) and
//!   `imu_times_truth.txt`: the true time of each of its `imu` records;
//! - `scenario.json`: every parameter and every drawn error.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::Instant;

use nalgebra::Vector3;
use serde::Serialize;
use serde_json::json;

use super::clock::{Counter, ImuClock, Temperature};
use super::fitted::FittedMotion;
use super::gnss::{GnssEpoch, GnssSim, RealLayout, ReplayFix, replay_from_reference};
use super::imu::{ImuOutput, ImuSensor, OutputKind};
use super::rig::{
    HostReceiver, PendingRecords, PpsKind, PpsSource, RigRecord, SerialLink, SyncMode,
};
use super::rng::{self, SimRng};
use super::scenario::Scenario;
use super::trajectory::{Trajectory, TrajectoryOptions, Vibration};
use super::truth::TruthGenerator;
use navsync::earth::{Geodetic, LocalEarth};
use navsync::error::{Diagnostics, Error};
use navsync::filter::gnss::GnssFix;
use navsync::ins::{ImuErrors, ImuSample, NavState};
use navsync::io::heading::{HEADING_FILE_HEADER, HeadingObs, heading_line};
use navsync::io::kfgins::{
    GnssLayout, GnssReader, NavReader, format_gnss_line, format_imu_err_line, format_imu_line,
    format_nav_line,
};
use navsync::io::riglog::{
    ImuKind, ImuTiming, RateSampling, RigGnss, RigHeader, RigHeading, write as rig_write,
};
use navsync::io::text::{plain_number, push_u64};
use navsync::time::GpsTime;

/// At most this many entries per fault list in `scenario.json`.
const MAX_LISTED: usize = 10_000;

/// A list that keeps the first entries and counts all.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Listed<T> {
    pub count: usize,
    pub first: Vec<T>,
}

impl<T> Listed<T> {
    fn push(&mut self, v: T) {
        self.count += 1;
        if self.first.len() < MAX_LISTED {
            self.first.push(v);
        }
    }
}

/// Extremes of the motion.
#[derive(Clone, Debug, Default, Serialize)]
pub struct MotionStats {
    pub distance_m: f64,
    pub max_speed_mps: f64,
    pub max_yaw_rate_deg_s: f64,
    pub max_lateral_accel_mps2: f64,
    pub max_long_accel_mps2: f64,
    pub max_pitch_deg: f64,
    pub max_roll_deg: f64,
    pub height_range_m: [f64; 2],
}

/// What a run produced (the measured part of `scenario.json`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct SimReport {
    pub imu_samples: u64,
    pub imu_first_sow: f64,
    pub imu_last_sow: f64,
    pub imu_mean_rate_hz: f64,
    pub imu_records: u64,
    pub imu_lost: Listed<f64>,
    pub imu_gap_lost: u64,
    pub imu_duplicated: Listed<f64>,
    pub imu_spikes: Listed<f64>,
    pub gnss_epochs: u64,
    pub gnss_fixes: u64,
    pub gnss_removed_by_outages: u64,
    pub gnss_outliers: Listed<f64>,
    pub gnss_messages: u64,
    pub gnss_latency_s: [f64; 3],
    pub pps_pulses: u64,
    /// Time-marked edges written as `mark` records.
    pub marks: u64,
    pub pps_dropped: u64,
    pub pps_displaced: Listed<f64>,
    pub pps_spurious: Listed<f64>,
    pub counter_start_ticks: f64,
    pub counter_first_wrap_sow: Option<f64>,
    pub counter_freq_error_ppm_start_end: [f64; 2],
    pub imu_clock_freq_error_ppm_start_end: [f64; 2],
    pub motion: MotionStats,
    pub initial_state: InitialState,
    pub files: Vec<String>,
    pub runtime_s: f64,
}

/// The true state at the first IMU epoch (the KF-GINS configuration's).
#[derive(Clone, Debug, Default, Serialize)]
pub struct InitialState {
    pub sow: f64,
    pub pos: [f64; 3],
    pub vel: [f64; 3],
    pub att: [f64; 3],
}

/// The simulation, ready to run.
pub struct Simulation {
    pub scenario: Scenario,
    pub trajectory: Trajectory,
    segments: Vec<super::trajectory::Segment>,
    start: GpsTime,
    duration_s: f64,
    /// Real GNSS errors replayed along a reference drive.
    replay: Option<Vec<ReplayFix>>,
}

impl Simulation {
    /// Builds the trajectory (and draws the vibration) for a scenario.
    pub fn new(scenario: Scenario) -> Result<Self, Error> {
        scenario.validate()?;
        if let Some(path) = scenario.reference_nav.clone() {
            return Self::along_reference(scenario, Path::new(&path));
        }
        let (segments, duration) = scenario.segments_and_duration()?;
        let mut vib_rng = rng::stream(scenario.seed, "trajectory.vibration");
        let vibration =
            Vibration::draw(&scenario.vibration, &mut vib_rng).map_err(Error::Invalid)?;
        let origin = Geodetic::from_deg(scenario.origin[0], scenario.origin[1], scenario.origin[2]);
        let trajectory = Trajectory::from_segments(
            origin,
            &segments,
            TrajectoryOptions {
                initial_speed_mps: scenario.initial_speed_mps,
                initial_heading_rad: scenario.initial_heading_deg.to_radians(),
                duration_s: duration,
                roll_gain_rad_per_mps2: scenario.roll_gain_deg_per_mps2.to_radians(),
                vibration,
            },
        )?;
        let start = GpsTime::from_week_sow(scenario.gps_week, scenario.start_sow);
        let duration_s = trajectory.duration_s();
        Ok(Simulation {
            scenario,
            trajectory,
            segments,
            start,
            duration_s,
            replay: None,
        })
    }

    /// A simulation along a reference drive (`reference_nav`), optionally
    /// with its real GNSS fixes replayed (`gnss.real_fixes`). The start
    /// time is the reference's first epoch in the scenario's GPS week.
    fn along_reference(mut scenario: Scenario, path: &Path) -> Result<Self, Error> {
        let mut diag = Diagnostics::default();
        let records = NavReader::read_all(path, &mut diag)?;
        let motion = FittedMotion::fit(&records).map_err(|e| match e {
            Error::Invalid(m) => Error::config(path, m),
            e => e,
        })?;
        let origin = motion.origin();
        let start = GpsTime::from_week_sow(scenario.gps_week, records[0].time.sow());
        scenario.start_sow = start.sow();
        scenario.origin = [
            origin.lat_rad.to_degrees(),
            origin.lon_rad.to_degrees(),
            origin.h_m,
        ];
        let mut replay = None;
        if let Some(real) = scenario.gnss.real_fixes.clone() {
            let layout = match scenario.gnss.real_layout {
                RealLayout::Cpp => GnssLayout::Cpp,
                RealLayout::Matlab => GnssLayout::Matlab,
            };
            let mut reader = GnssReader::open(Path::new(&real), scenario.gps_week, layout)?;
            let mut fixes = Vec::new();
            while let Some(f) = reader.next_fix(&mut diag)? {
                fixes.push(f);
            }
            let lever = Vector3::from(scenario.gnss.lever_arm_m);
            let list = replay_from_reference(&motion, start, &lever, &fixes);
            if list.is_empty() {
                return Err(Error::config(
                    Path::new(&real),
                    format!(
                        "none of its {} fixes falls within the reference drive ({:.3}–{:.3} s of week)",
                        fixes.len(),
                        start.sow(),
                        start.sow() + motion.duration_s()
                    ),
                ));
            }
            replay = Some(list);
        }
        let trajectory = Trajectory::from_fitted(motion);
        let duration_s = trajectory.duration_s();
        Ok(Simulation {
            scenario,
            trajectory,
            segments: Vec::new(),
            start,
            duration_s,
            replay,
        })
    }

    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    pub fn start(&self) -> GpsTime {
        self.start
    }

    /// Runs the scenario into `dir`; `progress` gets the fraction done.
    /// `argv` is recorded in `scenario.json`.
    pub fn run(
        &self,
        dir: &Path,
        argv: &[String],
        progress: &mut dyn FnMut(f64),
    ) -> Result<SimReport, Error> {
        let wall = Instant::now();
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let scn = &self.scenario;
        let seed = scn.seed;
        let start = self.start;
        let dur = self.duration_s;
        let imu_spec = &scn.imu;
        let rig = &scn.rig;
        let t_out = 1.0 / imu_spec.output_rate_hz;

        let temp = Temperature::new(&rig.temperature).map_err(Error::Invalid)?;
        let mut imu_clock = ImuClock::new(
            &imu_spec.clock,
            t_out,
            temp.clone(),
            rng::stream(seed, "imu.clock.rw"),
        )
        .map_err(Error::Invalid)?;
        let mut sensor = ImuSensor::new(imu_spec, seed).map_err(Error::Invalid)?;
        let n_dec = sensor.decimation_factor();
        let mut truth = TruthGenerator::new(&self.trajectory, start);
        let mut gnss = GnssSim::new(
            &scn.gnss,
            TruthGenerator::new(&self.trajectory, start),
            start.add_seconds(dur),
            seed,
        );
        if let Some(list) = &self.replay {
            gnss = gnss.with_replay(list.clone());
        }
        let gnss_spec = gnss.spec().clone();
        let mut pps =
            (rig.sync != SyncMode::Sw).then(|| PpsSource::new(&rig.pps, start, dur, seed));
        // Time-marked edges: k-th at first_s + k / rate_hz.
        let mut mark_rng = rng::stream(seed, "rig.marks");
        let mut next_mark = (rig.marks.rate_hz > 0.0).then_some(0u64);
        let mut counter = Counter::new(&rig.counter, temp, rng::stream(seed, "rig.counter.rw"))
            .map_err(Error::Invalid)?;
        let mut report = SimReport {
            counter_start_ticks: counter.start_ticks(),
            counter_first_wrap_sow: counter
                .first_wrap_s(dur)
                .map(|t| start.add_seconds(t).sow()),
            ..SimReport::default()
        };
        let counter_ppm0 = counter.freq_error_ppm(0.0);
        let imu_clock_ppm0 = imu_clock.freq_error_ppm(0.0);

        let mut gnss_link = SerialLink::new(rig.gnss_link.baud, rig.gnss_link.msg_bytes);
        let mut imu_link = SerialLink::new(rig.imu_link.baud, rig.imu_link.frame_bytes);
        let mut host_imu = HostReceiver::with_law(
            rig.software.imu_latency_s,
            rig.software.imu_latency_law,
            rig.software.imu_latency_mean_s,
            rng::stream(seed, "rig.sw.imu"),
        );
        let mut host_gnss = HostReceiver::new(
            rig.software.gnss_latency_s,
            rng::stream(seed, "rig.sw.gnss"),
        );
        let mut gnss_latency_rng = rng::stream(seed, "rig.gnss.latency");
        let mut loss_rng = rng::stream(seed, "rig.imu.loss");
        let mut dup_rng = rng::stream(seed, "rig.imu.duplicate");
        let mut spike_rng = rng::stream(seed, "rig.imu.spike");
        let mut pending = PendingRecords::default();

        let record_kind = rig.imu_record.unwrap_or(imu_spec.output);
        let files = Files::create(dir, scn.output.rig_log, gnss_spec.dual_antenna.is_some())?;
        let rig_log = scn.output.rig_log;
        let (tx, rx) = sync_channel::<Vec<Out>>(4);
        let writer = std::thread::Builder::new()
            .name("simulate-writer".into())
            .spawn(move || write_files(rx, files))
            .map_err(|e| Error::io(dir, e))?;
        let mut sink = Sink {
            batch: Vec::with_capacity(BATCH),
            tx: Some(tx),
        };
        if rig_log {
            let mut h = RigHeader::new(
                rig.counter.hz,
                rig.counter.bits,
                match record_kind {
                    OutputKind::Rate => ImuKind::Rate,
                    OutputKind::Increment => ImuKind::Increment,
                },
            );
            h.imu_rate_hz = Some(imu_spec.output_rate_hz);
            h.imu_timing = Some(match rig.sync {
                SyncMode::Hw => ImuTiming::DataReady,
                SyncMode::Serial => ImuTiming::FrameStart,
                SyncMode::Sw | SyncMode::Hybrid => ImuTiming::Receive,
            });
            if record_kind == OutputKind::Rate {
                h.imu_rates = Some(if imu_spec.rates_are_interval_averages() {
                    RateSampling::IntervalAverage
                } else {
                    RateSampling::Instantaneous
                });
            }
            if rig.sync == SyncMode::Serial {
                h.imu_output_delay_s = Some(rig.imu_link.output_delay_s);
            }
            sink.push(Out::RigHeader(h.to_text()));
        }

        // imu_err_truth at whole multiples of the interval.
        let err_step_ns = (scn.output.imu_err_interval_s * 1e9).round().max(1.0) as i64;
        let mut next_err = GpsTime::from_ns(start.ns().div_euclid(err_step_ns) * err_step_ns);
        if next_err < start {
            next_err = next_err + err_step_ns;
        }

        let full_window = sensor.needs_full_window();
        let mut window = vec![[0.0f64; 6]; n_dec];
        let (_, mut t_prev) = imu_clock.current();
        let imu_t0 = t_prev;
        if n_dec > 0 {
            let r = truth.rates_at_s(t_prev);
            sensor.prime(&r.w_ib_b, &r.f_b);
        }
        let mut prev_time: Option<GpsTime> = None;
        let mut motion = MotionStats {
            height_range_m: [f64::INFINITY, f64::NEG_INFINITY],
            ..MotionStats::default()
        };
        let mut latency = [f64::INFINITY, f64::NEG_INFINITY, 0.0];
        let lookahead_s = 2.0;
        let mut last_progress = 0.0;
        let spike_scale = [
            if imu_spec.gyro.range_deg_s > 0.0 {
                imu_spec.gyro.range_deg_s.to_radians()
            } else {
                10.0
            },
            if imu_spec.accel.range_g > 0.0 {
                imu_spec.accel.range_g * super::imu::G0
            } else {
                100.0
            },
        ];

        loop {
            let t_k = imu_clock.advance();
            if t_k > dur {
                break;
            }
            let out = if n_dec == 0 {
                let (dth, dv) = truth.increment_s(t_prev, t_k);
                sensor.push_exact(&dth, &dv)
            } else {
                let step = (t_k - t_prev) / n_dec as f64;
                let first = if full_window { 1 } else { n_dec };
                for j in first..=n_dec {
                    let tj = if j == n_dec {
                        t_k
                    } else {
                        t_prev + step * j as f64
                    };
                    let r = truth.rates_at_s(tj);
                    window[j - 1] = [
                        r.w_ib_b.x, r.w_ib_b.y, r.w_ib_b.z, r.f_b.x, r.f_b.y, r.f_b.z,
                    ];
                }
                sensor.push_window(&window).map_err(Error::Invalid)?
            };
            let time = start + (t_k * 1e9).round() as i64;
            if prev_time.is_some_and(|p| time <= p) {
                return Err(Error::Invalid(format!(
                    "IMU sample times do not increase at {time} (IMU rate too high for nanosecond times?)"
                )));
            }

            // Truth at the sample.
            let p = truth.state_at(time);
            let euler = p.nav.euler();
            sink.push(Out::Truth {
                time,
                pos: p.nav.pos,
                vel: p.nav.vel,
                att_deg: euler.to_deg(),
            });
            update_motion(&mut motion, &p.nav, &p.kin.vehicle, t_k - t_prev);
            if report.imu_samples == 0 {
                report.imu_first_sow = time.sow();
                report.initial_state = InitialState {
                    sow: time.sow(),
                    pos: [
                        p.nav.pos.lat_rad.to_degrees(),
                        p.nav.pos.lon_rad.to_degrees(),
                        p.nav.pos.h_m,
                    ],
                    vel: p.nav.vel.into(),
                    att: euler.to_deg(),
                };
            }
            report.imu_samples += 1;
            report.imu_last_sow = time.sow();

            // True IMU errors at whole intervals inside (prev, time].
            while next_err <= time {
                sink.push(Out::ImuErr {
                    time: next_err,
                    errors: sensor.current_errors(),
                });
                next_err = next_err + err_step_ns;
            }

            // GNSS and PPS ahead of the IMU, into the pending records.
            while let Some(tv) = gnss.peek_time() {
                if tv.seconds_since(start) > t_k + lookahead_s {
                    break;
                }
                let Some(ep) = gnss.next_epoch() else { break };
                gnss_epoch(&ep, &mut sink, &mut report);
                if ep.in_outage {
                    continue;
                }
                let ready = ep.valid.seconds_since(start)
                    + rng::uniform_in(
                        &mut gnss_latency_rng,
                        rig.gnss_link.processing_delay_s[0],
                        rig.gnss_link.processing_delay_s[1],
                    )
                    + rng::uniform_in(&mut gnss_latency_rng, 0.0, rig.gnss_link.extra_jitter_s);
                let (_, arrived) = gnss_link.send(ready);
                let latch = if rig.sync == SyncMode::Sw {
                    host_gnss.receive(arrived)
                } else {
                    arrived
                };
                let l = latch - ep.valid.seconds_since(start);
                latency = [latency[0].min(l), latency[1].max(l), latency[2] + l];
                report.gnss_messages += 1;
                pending.push(latch, RigRecord::Gnss(Box::new(ep.fix)));
                // The heading of the same epoch: the next message, latched
                // with it (equal counters keep their order).
                if let Some(h) = ep.heading {
                    pending.push(latch, RigRecord::Heading(h));
                }
            }
            if let Some(src) = &mut pps {
                while src.peek_s().is_some_and(|t| t <= t_k + lookahead_s) {
                    let Some(e) = src.next_edge() else { break };
                    let sow = start.add_seconds(e.time_s).sow();
                    match e.kind {
                        PpsKind::Normal => {}
                        PpsKind::Displaced => report.pps_displaced.push(sow),
                        PpsKind::Spurious => report.pps_spurious.push(sow),
                    }
                    report.pps_pulses += 1;
                    pending.push(e.time_s, RigRecord::Pps);
                }
            }

            while let Some(k) = next_mark {
                let edge = rig.marks.first_s + k as f64 / rig.marks.rate_hz;
                if edge > t_k + lookahead_s {
                    break;
                }
                if edge >= dur {
                    next_mark = None;
                    break;
                }
                let gps =
                    start.add_seconds(edge + rig.marks.receiver_sd_s * rng::normal(&mut mark_rng));
                let latch = edge + rng::uniform_in(&mut mark_rng, 0.0, rig.marks.latch_delay_s);
                report.marks += 1;
                pending.push(latch, RigRecord::Mark(gps));
                next_mark = Some(k + 1);
            }

            // The logged IMU record: transport faults, then timing.
            let rel = t_k;
            let u_loss = rng::uniform(&mut loss_rng);
            let in_gap = rig
                .imu_link
                .gaps
                .iter()
                .any(|g| rel >= g[0] && rel < g[0] + g[1]);
            let lost = in_gap || u_loss < rig.imu_link.loss_prob;
            let duplicated = rng::uniform(&mut dup_rng) < rig.imu_link.duplicate_prob;
            let spike = draw_spike(&mut spike_rng, rig.imu_link.spike_prob, spike_scale);
            // The frame still occupies the serial link whether or not the
            // logger keeps it.
            let (frame_start, frame_end) = imu_link.send(rel + rig.imu_link.output_delay_s);
            if lost {
                if in_gap {
                    report.imu_gap_lost += 1;
                } else {
                    report.imu_lost.push(time.sow());
                }
            } else {
                let mut logged = out;
                if let Some((ch, value)) = spike {
                    apply_spike(&mut logged, ch, value, t_out);
                    report.imu_spikes.push(time.sow());
                }
                let latch = match rig.sync {
                    SyncMode::Hw => rel + rig.imu_link.data_ready_delay_s,
                    SyncMode::Serial => frame_start,
                    SyncMode::Sw | SyncMode::Hybrid => host_imu.receive(frame_end),
                };
                let sample = ImuSample {
                    time,
                    dtheta: logged.dtheta,
                    dvel: logged.dvel,
                    odo_speed: None,
                };
                let copies: u8 = if duplicated { 2 } else { 1 };
                if duplicated {
                    report.imu_duplicated.push(time.sow());
                }
                sink.push(Out::Imu { sample, copies });
                if rig_log {
                    flush_pending(&mut pending, latch, &mut sink, &mut counter);
                    let vals = match record_kind {
                        OutputKind::Rate => [logged.gyro_rate, logged.accel_rate],
                        OutputKind::Increment => [logged.dtheta, logged.dvel],
                    };
                    let counter = counter.latch(latch);
                    sink.push(Out::RigImu {
                        counter,
                        vals: [
                            vals[0].x, vals[0].y, vals[0].z, vals[1].x, vals[1].y, vals[1].z,
                        ],
                        copies,
                        time,
                    });
                    report.imu_records += copies as u64;
                }
            }
            prev_time = Some(time);
            t_prev = t_k;
            let frac = t_k / dur;
            if frac - last_progress >= 0.005 {
                last_progress = frac;
                progress(frac);
            }
        }
        // Records latched before the end of the run.
        if rig_log {
            flush_pending(&mut pending, dur, &mut sink, &mut counter);
        }
        // The remaining GNSS epochs (validity before the end).
        while let Some(ep) = gnss.next_epoch() {
            gnss_epoch(&ep, &mut sink, &mut report);
        }
        while next_err <= start.add_seconds(dur) {
            sink.push(Out::ImuErr {
                time: next_err,
                errors: sensor.current_errors(),
            });
            next_err = next_err + err_step_ns;
        }
        sink.finish();
        let written = writer
            .join()
            .map_err(|_| Error::Invalid("the file writer thread panicked".into()))??;
        if report.imu_samples == 0 {
            return Err(Error::Invalid(format!(
                "the run of {dur} s is shorter than one IMU period ({t_out} s)"
            )));
        }
        report.pps_dropped = pps.as_ref().map_or(0, |p| p.dropped as u64);
        report.imu_mean_rate_hz = imu_clock.mean_rate_hz(imu_t0);
        if report.gnss_messages > 0 {
            latency[2] /= report.gnss_messages as f64;
            report.gnss_latency_s = latency;
        }
        report.counter_freq_error_ppm_start_end = [counter_ppm0, counter.freq_error_ppm(dur)];
        report.imu_clock_freq_error_ppm_start_end = [imu_clock_ppm0, imu_clock.freq_error_ppm(dur)];
        if motion.height_range_m[0] > motion.height_range_m[1] {
            motion.height_range_m = [0.0; 2];
        }
        report.motion = motion;

        let config = self.kf_gins_config(&report, &gnss_spec, &sensor);
        navsync::io::output::write_file(dir.join("kf-gins.yaml"), config)?;
        report.files = written;
        report.files.push("kf-gins.yaml".into());
        report.files.push("scenario.json".into());
        report.files.sort();
        report.runtime_s = wall.elapsed().as_secs_f64();
        let doc = json!({
            "tool": "navsync simulate",
            "version": env!("CARGO_PKG_VERSION"),
            "argv": argv,
            "seed": scn.seed,
            "gps_week": scn.gps_week,
            "start_sow": scn.start_sow,
            "duration_s": dur,
            "imu_rate_hz": imu_spec.output_rate_hz,
            "models": {
                "ellipsoid": "WGS-84",
                "omega_e": navsync::earth::OMEGA_E,
                "gravity": "normal gravity (Somigliana, TR8350.2 eqs 4-1, 4-3) along the ellipsoid normal",
                "imu_output": "increments = integrals of w_ib^b / f^b over (t_k-1, t_k]; internal chain: samples at internal_rate_hz on the IMU clock, errors, saturation, optional low-pass, DEC_RATE decimation",
                "imu_error_model": "m = (I + diag(s) + M) x + b_turn_on + b_drift(t) + white; drift = flicker bank or Gauss-Markov",
                "vehicle": "velocity along body x (no side slip); roll = -k*v*yawrate; vibration: body rotation alpha(t), NED displacement",
                "imu_txt_times": "true GPS time of each IMU sample (ideal synchronisation)",
                "imu_times_truth": "true GPS time of each rig.csv imu record, in order",
            },
            "scenario": scn,
            "trajectory": {
                "segments": self.trajectory.segments(),
                "segment_specs": self.segments,
            },
            "vibration_drawn": self.trajectory.vibration().tones(),
            "imu_drawn": sensor.drawn(),
            "imu_errors_at_start_kfgins_units": kfgins_units(&sensor.current_errors()),
            "gnss_resolved": gnss_spec,
            "report": report,
        });
        let path = dir.join("scenario.json");
        let text = serde_json::to_string_pretty(&doc).map_err(|e| Error::Invalid(e.to_string()))?;
        navsync::io::output::write_file(&path, text)?;
        progress(1.0);
        Ok(report)
    }

    /// A KF-GINS configuration for the written files (paths relative to
    /// the configuration's folder; navsync resolves them there).
    fn kf_gins_config(
        &self,
        report: &SimReport,
        gnss: &super::gnss::GnssSpec,
        sensor: &ImuSensor,
    ) -> String {
        let scn = &self.scenario;
        let imu = &scn.imu;
        let o = &scn.output;
        let init = &report.initial_state;
        let pos0 = Geodetic::from_deg(init.pos[0], init.pos[1], init.pos[2]);
        let le = LocalEarth::new(&pos0, &Vector3::zeros());
        let d = le.ned_to_geodetic_delta(&Vector3::from(o.init_error_pos_m));
        let pos = [
            init.pos[0] + d.x.to_degrees(),
            init.pos[1] + d.y.to_degrees(),
            init.pos[2] + d.z,
        ];
        let vel = [0, 1, 2].map(|i| init.vel[i] + o.init_error_vel_mps[i]);
        let att = [0, 1, 2].map(|i| init.att[i] + o.init_error_att_deg[i]);
        let drawn = sensor.drawn();
        // Initial bias uncertainty: turn-on plus the drift's stationary σ.
        let drift_sd = |sds: &[f64]| sds.iter().map(|s| s * s).sum::<f64>().sqrt();
        let deg_h = 180.0 / std::f64::consts::PI * 3600.0;
        let bg = (imu.gyro.turn_on_bias_deg_h.powi(2)
            + (drift_sd(&drawn.gyro.drift_component_sd) * deg_h).powi(2))
        .sqrt()
        .max(0.01);
        let ba = (imu.accel.turn_on_bias_mgal.powi(2)
            + (drift_sd(&drawn.accel.drift_component_sd) * 1e5).powi(2))
        .sqrt()
        .max(1.0);
        let sd = gnss.std_written_m.unwrap_or([0.02, 0.02, 0.03]);
        let gnss_file = if gnss.velocity {
            "gnss_posvel.txt"
        } else {
            "gnss.txt"
        };
        let v3 =
            |v: [f64; 3], dec: usize| format!("[ {:.dec$}, {:.dec$}, {:.dec$} ]", v[0], v[1], v[2]);
        let s3 = |x: f64, dec: usize| v3([x; 3], dec);
        let mut y = String::new();
        y.push_str("# KF-GINS configuration written by navsync simulate\n");
        y.push_str(&format!(
            "# scenario={} seed={} imu-grade={} gnss-mode={:?} sync={}\n",
            scn.trajectory.as_deref().unwrap_or("segments"),
            scn.seed,
            imu.grade,
            gnss.mode,
            scn.rig.sync.name()
        ));
        y.push_str("# paths are relative to this file's folder\n");
        y.push_str("imupath: \"./imu.txt\"\n");
        y.push_str(&format!("gnsspath: \"./{gnss_file}\"\n"));
        y.push_str("outputpath: \"./out\"\n");
        y.push_str("imudatalen: 7\n");
        y.push_str(&format!(
            "imudatarate: {}\n",
            plain_number(imu.output_rate_hz)
        ));
        y.push_str(&format!("starttime: {:.9}\n", init.sow));
        y.push_str("endtime: -1\n");
        y.push_str(&format!(
            "initpos: [ {:.10}, {:.10}, {:.6} ]\n",
            pos[0], pos[1], pos[2]
        ));
        y.push_str(&format!("initvel: {}\n", v3(vel, 9)));
        y.push_str(&format!("initatt: {}\n", v3(att, 9)));
        y.push_str("initgyrbias: [ 0, 0, 0 ]\ninitaccbias: [ 0, 0, 0 ]\n");
        y.push_str("initgyrscale: [ 0, 0, 0 ]\ninitaccscale: [ 0, 0, 0 ]\n");
        let pos_sd = [0, 1, 2].map(|i| (2.5 * sd[i]).max(0.05) + o.init_error_pos_m[i].abs());
        y.push_str(&format!("initposstd: {}\n", v3(pos_sd, 6)));
        let vel_sd = [0, 1, 2].map(|i| 0.05 + o.init_error_vel_mps[i].abs());
        y.push_str(&format!("initvelstd: {}\n", v3(vel_sd, 6)));
        let att_sd = [
            0.1 + o.init_error_att_deg[0].abs(),
            0.1 + o.init_error_att_deg[1].abs(),
            0.5 + o.init_error_att_deg[2].abs(),
        ];
        y.push_str(&format!("initattstd: {}\n", v3(att_sd, 6)));
        y.push_str(&format!("initbgstd: {}\n", s3(bg, 6)));
        y.push_str(&format!("initbastd: {}\n", s3(ba, 6)));
        y.push_str(&format!(
            "initsgstd: {}\n",
            s3(imu.gyro.scale_ppm.max(10.0), 6)
        ));
        y.push_str(&format!(
            "initsastd: {}\n",
            s3(imu.accel.scale_ppm.max(10.0), 6)
        ));
        y.push_str("imunoise:\n");
        y.push_str(&format!(
            "  arw: {}\n",
            s3(imu.gyro.arw_deg_sqrt_h.max(1e-3), 6)
        ));
        y.push_str(&format!(
            "  vrw: {}\n",
            s3(imu.accel.vrw_mps_sqrt_h.max(1e-3), 6)
        ));
        y.push_str(&format!(
            "  gbstd: {}\n",
            s3(imu.gyro.bias_instability_deg_h.max(0.01), 6)
        ));
        y.push_str(&format!(
            "  abstd: {}\n",
            s3(imu.accel.bias_instability_mgal.max(1.0), 6)
        ));
        y.push_str(&format!(
            "  gsstd: {}\n",
            s3(imu.gyro.scale_ppm.max(10.0), 6)
        ));
        y.push_str(&format!(
            "  asstd: {}\n",
            s3(imu.accel.scale_ppm.max(10.0), 6)
        ));
        y.push_str("  corrtime: 1.000000\n");
        y.push_str(&format!("antlever: {}\n", v3(gnss.lever_arm_m, 6)));
        y
    }
}

fn kfgins_units(e: &ImuErrors) -> serde_json::Value {
    let deg_h = 180.0 / std::f64::consts::PI * 3600.0;
    json!({
        "gyro_bias_deg_h": (e.gyro_bias * deg_h).as_slice(),
        "accel_bias_mgal": (e.accel_bias * 1e5).as_slice(),
        "gyro_scale_ppm": (e.gyro_scale * 1e6).as_slice(),
        "accel_scale_ppm": (e.accel_scale * 1e6).as_slice(),
    })
}

fn update_motion(
    m: &mut MotionStats,
    nav: &NavState,
    v: &super::trajectory::VehicleState,
    dt: f64,
) {
    let speed = nav.vel.norm();
    m.distance_m += speed * dt;
    m.max_speed_mps = m.max_speed_mps.max(speed);
    m.max_yaw_rate_deg_s = m
        .max_yaw_rate_deg_s
        .max(v.yaw_rate_rad_s.abs().to_degrees());
    m.max_lateral_accel_mps2 = m
        .max_lateral_accel_mps2
        .max((v.speed_mps * v.yaw_rate_rad_s).abs());
    m.max_long_accel_mps2 = m.max_long_accel_mps2.max(v.accel_mps2.abs());
    m.max_pitch_deg = m.max_pitch_deg.max(v.pitch_rad.abs().to_degrees());
    m.max_roll_deg = m.max_roll_deg.max(v.roll_rad.abs().to_degrees());
    m.height_range_m = [
        m.height_range_m[0].min(nav.pos.h_m),
        m.height_range_m[1].max(nav.pos.h_m),
    ];
}

/// A spike (one corrupt value) with probability `p`: channel and value.
/// The draws are made for every record, so the spike probability changes
/// no other draw.
fn draw_spike(r: &mut SimRng, p: f64, scale: [f64; 2]) -> Option<(usize, f64)> {
    let u = rng::uniform(r);
    let ch = (rng::uniform(r) * 6.0).min(5.0) as usize;
    let v = rng::uniform_in(r, -1.0, 1.0);
    (u < p).then(|| (ch, v * scale[ch / 3]))
}

fn apply_spike(o: &mut ImuOutput, ch: usize, rate_value: f64, t_out: f64) {
    let (rate, inc) = if ch < 3 {
        (&mut o.gyro_rate[ch], &mut o.dtheta[ch])
    } else {
        (&mut o.accel_rate[ch - 3], &mut o.dvel[ch - 3])
    };
    *rate = rate_value;
    *inc = rate_value * t_out;
}

fn gnss_epoch(ep: &GnssEpoch, sink: &mut Sink, report: &mut SimReport) {
    report.gnss_epochs += 1;
    if ep.in_outage {
        report.gnss_removed_by_outages += 1;
        return;
    }
    if ep.outlier {
        report.gnss_outliers.push(ep.valid.sow());
    }
    report.gnss_fixes += 1;
    sink.push(Out::Gnss { fix: ep.fix });
    if let Some(obs) = ep.heading {
        sink.push(Out::Heading { obs });
    }
}

fn flush_pending(
    pending: &mut PendingRecords,
    before_s: f64,
    sink: &mut Sink,
    counter: &mut Counter,
) {
    while let Some((latch, rec)) = pending.pop_before(before_s) {
        let c = counter.latch(latch);
        sink.push(match rec {
            RigRecord::Pps => Out::RigPps { counter: c },
            RigRecord::Gnss(fix) => Out::RigGnss {
                counter: c,
                fix: *fix,
            },
            RigRecord::Mark(time) => Out::RigMark { counter: c, time },
            RigRecord::Heading(obs) => Out::RigHeading { counter: c, obs },
        });
    }
}

/// Records per batch handed to the writer thread.
const BATCH: usize = 4096;

/// Everything the writer thread formats, in file order.
enum Out {
    Truth {
        time: GpsTime,
        pos: Geodetic,
        vel: Vector3<f64>,
        att_deg: [f64; 3],
    },
    Imu {
        sample: ImuSample,
        copies: u8,
    },
    ImuErr {
        time: GpsTime,
        errors: ImuErrors,
    },
    Gnss {
        fix: GnssFix,
    },
    RigHeader(String),
    RigMark {
        counter: u64,
        time: GpsTime,
    },
    RigPps {
        counter: u64,
    },
    RigGnss {
        counter: u64,
        fix: GnssFix,
    },
    /// A dual-antenna heading: `heading.txt` …
    Heading {
        obs: HeadingObs,
    },
    /// … and its rig-log record.
    RigHeading {
        counter: u64,
        obs: HeadingObs,
    },
    RigImu {
        counter: u64,
        vals: [f64; 6],
        copies: u8,
        time: GpsTime,
    },
}

/// Batches records for the writer thread (formatting and writing run in
/// parallel with the simulation; the bounded channel bounds memory).
struct Sink {
    batch: Vec<Out>,
    tx: Option<SyncSender<Vec<Out>>>,
}

impl Sink {
    #[inline]
    fn push(&mut self, o: Out) {
        self.batch.push(o);
        if self.batch.len() >= BATCH {
            self.send();
        }
    }

    fn send(&mut self) {
        let b = std::mem::replace(&mut self.batch, Vec::with_capacity(BATCH));
        if let Some(tx) = &self.tx
            && tx.send(b).is_err()
        {
            // The writer stopped on an error; it reports it at join.
            self.tx = None;
        }
    }

    fn finish(mut self) {
        self.send();
        self.tx = None;
    }
}

/// A file written from a buffer that records are formatted into directly.
struct Chunked {
    /// Whole or absent under its name (`navsync::io::output`).
    file: navsync::io::output::AtomicFile,
    path: PathBuf,
    buf: Vec<u8>,
}

const CHUNK: usize = 1 << 18;

impl Chunked {
    fn create(path: PathBuf) -> Result<Self, Error> {
        let file = navsync::io::output::AtomicFile::with_capacity(&path, 0)?;
        Ok(Chunked {
            file,
            path,
            buf: Vec::with_capacity(CHUNK + 4096),
        })
    }

    #[inline]
    fn done_line(&mut self) -> Result<(), Error> {
        if self.buf.len() >= CHUNK {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), Error> {
        self.file.write(&self.buf)?;
        self.buf.clear();
        Ok(())
    }

    fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    }
}

/// The output files of a run.
struct Files {
    imu: Chunked,
    truth: Chunked,
    gnss: Chunked,
    gnss_posvel: Chunked,
    imu_err: Chunked,
    rig: Option<Chunked>,
    times: Option<Chunked>,
    heading: Option<Chunked>,
}

impl Files {
    fn create(dir: &Path, rig_log: bool, headings: bool) -> Result<Self, Error> {
        let w = |n: &str| Chunked::create(dir.join(n));
        Ok(Files {
            imu: w("imu.txt")?,
            truth: w("truth.nav")?,
            gnss: w("gnss.txt")?,
            gnss_posvel: w("gnss_posvel.txt")?,
            imu_err: w("imu_err_truth.txt")?,
            rig: if rig_log { Some(w("rig.csv")?) } else { None },
            times: if rig_log {
                Some(w("imu_times_truth.txt")?)
            } else {
                None
            },
            heading: if headings {
                let mut c = w("heading.txt")?;
                c.buf.extend_from_slice(HEADING_FILE_HEADER.as_bytes());
                Some(c)
            } else {
                None
            },
        })
    }
}

/// The writer thread: formats every record into its file.
fn write_files(rx: Receiver<Vec<Out>>, mut f: Files) -> Result<Vec<String>, Error> {
    for batch in rx {
        for o in batch {
            match o {
                Out::Truth {
                    time,
                    pos,
                    vel,
                    att_deg,
                } => {
                    format_nav_line(&mut f.truth.buf, time.week(), time, &pos, &vel, &att_deg);
                    f.truth.done_line()?;
                }
                Out::Imu { sample, copies } => {
                    for _ in 0..copies {
                        format_imu_line(&mut f.imu.buf, &sample);
                    }
                    f.imu.done_line()?;
                }
                Out::ImuErr { time, errors } => {
                    format_imu_err_line(&mut f.imu_err.buf, time, &errors);
                    f.imu_err.done_line()?;
                }
                Out::Gnss { fix } => {
                    let pos_only = GnssFix {
                        vel: None,
                        vel_sd: None,
                        ..fix
                    };
                    format_gnss_line(&mut f.gnss.buf, &pos_only);
                    format_gnss_line(&mut f.gnss_posvel.buf, &fix);
                    f.gnss.done_line()?;
                    f.gnss_posvel.done_line()?;
                }
                Out::RigHeader(h) => {
                    if let Some(r) = &mut f.rig {
                        r.buf.extend_from_slice(h.as_bytes());
                    }
                }
                Out::Heading { obs } => {
                    if let Some(h) = &mut f.heading {
                        h.buf.extend_from_slice(heading_line(&obs).as_bytes());
                        h.done_line()?;
                    }
                }
                Out::RigHeading { counter, obs } => {
                    if let Some(r) = &mut f.rig {
                        rig_write::heading(&mut r.buf, &RigHeading::from_obs(counter, &obs));
                        r.done_line()?;
                    }
                }
                Out::RigPps { counter } => {
                    if let Some(r) = &mut f.rig {
                        rig_write::pps(&mut r.buf, counter);
                        r.done_line()?;
                    }
                }
                Out::RigMark { counter, time } => {
                    if let Some(r) = &mut f.rig {
                        rig_write::mark(&mut r.buf, counter, time, &[]);
                        r.done_line()?;
                    }
                }
                Out::RigGnss { counter, fix } => {
                    if let Some(r) = &mut f.rig {
                        rig_write::gnss(
                            &mut r.buf,
                            &RigGnss {
                                counter,
                                time: fix.time,
                                lat_deg: fix.pos.lat_rad.to_degrees(),
                                lon_deg: fix.pos.lon_rad.to_degrees(),
                                h_m: fix.pos.h_m,
                                sd_m: fix.pos_sd.into(),
                            },
                        );
                        r.done_line()?;
                    }
                }
                Out::RigImu {
                    counter,
                    vals,
                    copies,
                    time,
                } => {
                    if let Some(r) = &mut f.rig {
                        let b = &mut r.buf;
                        let at = b.len();
                        rig_write::imu(b, counter, &vals);
                        if copies > 1 {
                            let line = b[at..].to_vec();
                            b.extend_from_slice(&line);
                        }
                        r.done_line()?;
                    }
                    if let Some(t) = &mut f.times {
                        for _ in 0..copies {
                            push_u64(&mut t.buf, time.week().max(0) as u64);
                            t.buf.push(b' ');
                            time.write_sow(&mut t.buf);
                            t.buf.push(b'\n');
                        }
                        t.done_line()?;
                    }
                }
            }
        }
    }
    let mut names = Vec::new();
    let mut all = vec![f.imu, f.truth, f.gnss, f.gnss_posvel, f.imu_err];
    all.extend(f.rig);
    all.extend(f.times);
    all.extend(f.heading);
    for mut c in all {
        c.flush()?;
        names.push(c.name());
        c.file.commit()?;
    }
    Ok(names)
}
