//! The streaming GNSS/INS engine: push IMU samples and GNSS fixes, get the
//! navigation state at every IMU epoch.
//!
//! Loosely coupled, indirect-feedback (closed-loop) Kalman filter (seed 000
//! §1.2; seed 004 §1.1): the strapdown mechanization runs on every IMU
//! sample; GNSS fixes, the non-holonomic constraint and odometer speeds
//! correct it through the error-state filter, and the estimated errors are
//! fed back at once.
//!
//! Timing is explicit everywhere:
//! - A GNSS fix that falls between two IMU samples is processed at its own
//!   time: the IMU interval is split there (linear-rate assumption), the
//!   first part is integrated, the fix applied, the remainder follows.
//! - Every IMU sample uses its own interval; a gap longer than `gap_factor`
//!   nominal periods is reported, never bridged silently.
//! - Optionally the IMU–GNSS time offset τ (GNSS time tag − true time of
//!   validity) is a filter state (seed 004 eqs 11–16: observation row
//!   [H, −v]; PSINS's delay state has the same rows): a fix tagged t is
//!   processed at t − τ̂ and its rows are −v_antenna (position) and −a
//!   (velocity). τ̂ is held while it is unobservable (standstill, constant
//!   velocity), and a coarse search ([`crate::offset_search`]) brings large
//!   offsets (±0.5 s) within the filter's linear range.
//! - Fixes that arrive late in real time (latency) are handled by one of
//!   the [`LatencyMode`]s.

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::Vector3;
use serde::Serialize;

use crate::earth::{Geodetic, LocalEarth};
use crate::error::{Diagnostics, Error};
use crate::filter::dense::{self, Mat};
use crate::filter::gnss::{self, GnssFix};
use crate::filter::nhc::VehicleConstraint;
use crate::filter::{
    ErrorStateFilter, ImuNoise, InitialStd, Observation, StateLayout, UpdateOutcome, feedback,
};
use crate::ins::{ImuErrors, ImuSample, Increment, Mechanization, NavState, StepInfo};
use crate::offset_search::{CoarseOffsetSearch, OffsetEstimate};
use crate::stats::chi2_quantile;
use crate::time::GpsTime;

/// How to treat the increments of the sample that ends a data gap.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum GapPolicy {
    /// Decide from the physics: the accelerometer increment's magnitude
    /// (≈ g·Δt for a land vehicle) tells whether it covers the whole gap or
    /// one nominal period.
    #[default]
    Auto,
    /// The increments cover one nominal period; the rates are held over the
    /// rest of the gap.
    HoldRate,
    /// The increments cover the whole gap (an accumulating IMU).
    AsIs,
}

/// How GNSS fixes that arrive after their time of validity are used.
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "mode")]
pub enum LatencyMode {
    /// Post-processing: fixes are pushed before the IMU passes them and
    /// processed exactly at their (corrected) time of validity.
    #[default]
    Offline,
    /// Real time, uncompensated: a fix is applied when it arrives as if it
    /// were valid then (what a filter without latency handling does).
    Naive,
    /// (a) Known fixed latency (PX4 EKF2 style): the filter runs `lag_s`
    /// behind real time so every fix is fused at its time of validity, and
    /// the output is predicted forward to real time by re-integrating the
    /// buffered IMU samples.
    FixedLag { lag_s: f64 },
    /// (b) Seed 002 step 5: the fix valid at t_v is used at its receipt
    /// time, moved forward by the INS change over the latency.
    Extrapolate,
    /// (c) Delayed-state update: return to the stored state at t_v, update
    /// there and propagate forward again through the buffered IMU samples.
    DelayedState { max_latency_s: f64 },
}

/// Non-holonomic constraint settings.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct NhcOptions {
    pub vehicle: VehicleConstraint,
    /// Seconds between constraint updates.
    pub interval_s: f64,
}

/// Odometer speed update settings (speeds come from the IMU file's 8th
/// column or from [`Fusion::push_speed`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct OdometerOptions {
    pub vehicle: VehicleConstraint,
    pub sd_mps: f64,
    pub interval_s: f64,
    /// Estimate an odometer scale factor with this initial σ.
    pub scale_sd: Option<f64>,
}

/// The IMU–GNSS time-offset state.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct TimeOffsetOptions {
    /// Initial estimate τ̂₀ (s): GNSS time tag − true time of validity.
    pub init_s: f64,
    /// Initial σ (s).
    pub sd_s: f64,
    /// Random-walk power spectral density (s²/s).
    pub random_walk_psd: f64,
    /// Freeze τ̂ while the motion gives it no information.
    pub hold_when_unobservable: bool,
    /// Run the coarse search over ±this range (s); 0 disables it.
    pub search_range_s: f64,
}

impl Default for TimeOffsetOptions {
    fn default() -> Self {
        TimeOffsetOptions {
            init_s: 0.0,
            sd_s: 0.2,
            random_walk_psd: 1e-12,
            hold_when_unobservable: true,
            search_range_s: 0.5,
        }
    }
}

/// Everything the engine needs to start.
#[derive(Clone, Debug)]
pub struct FusionConfig {
    /// Initial navigation state; its `time` is the start: samples before it
    /// are skipped and the first sample at or after it starts the run.
    pub init_nav: NavState,
    pub init_imu: ImuErrors,
    pub init_std: InitialStd,
    pub noise: ImuNoise,
    /// GNSS antenna position in the body frame (m, FRD).
    pub antenna_lever_b: Vector3<f64>,
    /// Nominal IMU rate (Hz), for gap detection.
    pub imu_rate_hz: f64,
    /// A step longer than this many nominal periods is a gap.
    pub gap_factor: f64,
    pub gap_policy: GapPolicy,
    /// Covariance propagation step (s); 0 propagates at every IMU sample.
    pub cov_step_s: f64,
    /// Chi-square gate probability for GNSS fixes (e.g. 0.9999); `None`
    /// disables gating.
    pub gate_prob: Option<f64>,
    /// Accept a fix anyway after this many consecutive rejections (the
    /// filter, not the fixes, is then the likely culprit).
    pub max_consecutive_rejects: usize,
    /// Use GNSS velocity when a fix carries it.
    pub use_gnss_velocity: bool,
    pub nhc: Option<NhcOptions>,
    pub odometer: Option<OdometerOptions>,
    pub time_offset: Option<TimeOffsetOptions>,
    pub latency: LatencyMode,
    /// Estimate the 12 axis misalignments of the gyro and accelerometer
    /// triads (random constants) with these initial σ (rad): gyro, accel.
    /// A MEMS IMU's ±0.05° couples a 10°/s turn into 30°/h of tilt rate,
    /// which the 21 KF-GINS states leave out (the filter is then
    /// overconfident in turns and outages).
    pub misalignment_sd_rad: Option<[f64; 2]>,
}

impl FusionConfig {
    /// Sensible defaults around an initial state and noise model.
    pub fn new(
        init_nav: NavState,
        init_std: InitialStd,
        noise: ImuNoise,
        imu_rate_hz: f64,
    ) -> Self {
        FusionConfig {
            init_nav,
            init_imu: ImuErrors::default(),
            init_std,
            noise,
            antenna_lever_b: Vector3::zeros(),
            imu_rate_hz,
            gap_factor: 2.5,
            gap_policy: GapPolicy::Auto,
            cov_step_s: 0.1,
            gate_prob: Some(0.9999),
            max_consecutive_rejects: 5,
            use_gnss_velocity: true,
            nhc: None,
            odometer: None,
            time_offset: None,
            latency: LatencyMode::Offline,
            misalignment_sd_rad: None,
        }
    }
}

/// The solution at one IMU epoch.
#[derive(Copy, Clone, Debug)]
pub struct NavOutput {
    pub nav: NavState,
    pub imu: ImuErrors,
}

/// The time-offset estimate at some epoch.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct TimeOffsetState {
    pub offset_s: f64,
    pub sd_s: f64,
    /// False while τ̂ is held (unobservable motion).
    pub observable: bool,
}

/// Counters the engine keeps.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FusionStats {
    pub imu_samples: usize,
    pub gnss_fixes_used: usize,
    pub gnss_fixes_rejected: usize,
    pub gnss_fixes_late: usize,
    pub gnss_velocity_used: usize,
    pub gnss_velocity_rejected: usize,
    pub gnss_split_intervals: usize,
    pub gate_reopened: usize,
    /// Fixes over the gate accepted because they agreed with the previous
    /// rejected fix (the INS had drifted beyond its covariance, which was
    /// inflated); see `Core::gnss_update`.
    pub gnss_fixes_accepted_consistent: usize,
    pub nhc_updates: usize,
    pub odometer_updates: usize,
    pub gaps: usize,
    pub gap_total_s: f64,
    pub max_gap_s: f64,
    pub covariance_propagations: usize,
    pub time_offset_held_updates: usize,
    pub delayed_state_replays: usize,
}

/// Exponential-moving-average kinematics of the solution, used to decide
/// whether the time offset is observable and for the velocity row −a.
#[derive(Copy, Clone, Debug, Default)]
struct Kinematics {
    acc: Vector3<f64>,
    acc_slow: Vector3<f64>,
}

impl Kinematics {
    const TAU_FAST_S: f64 = 0.05;
    const TAU_SLOW_S: f64 = 1.0;

    fn push(&mut self, step: &StepInfo) {
        if step.dt <= 0.0 {
            return;
        }
        let a = step.dv_n / step.dt;
        let kf = (step.dt / Self::TAU_FAST_S).min(1.0);
        let ks = (step.dt / Self::TAU_SLOW_S).min(1.0);
        self.acc += (a - self.acc) * kf;
        self.acc_slow += (a - self.acc_slow) * ks;
    }
}

/// A GNSS position fix the gate rejected: its innovation and noise, and the
/// NIS ratio (NIS / gate) of the first rejection of its run.
#[derive(Clone)]
struct RejectedFix {
    time: GpsTime,
    z: Vec<f64>,
    r: Mat,
    first_ratio: f64,
}

/// Fixes further apart than this (s) are not compared with each other.
const CONSISTENCY_MAX_GAP_S: f64 = 5.0;
/// A run of rejections that began with a NIS above this multiple of the
/// gate (an innovation more than twice the gate's radius) started with a
/// jump: a GNSS fault, never taken for INS drift.
const SMOOTH_START_RATIO: f64 = 4.0;
/// At most one drift acceptance in this long (s): drift beyond the model is
/// an episode (a hard turn with misaligned gyros); a disagreement that keeps
/// coming back is systematic (late time tags, a wrong lever arm) and
/// inflating P for it again and again would let biased fixes tear the
/// attitude apart. Then the gate and its reopening rule stand.
const CONSISTENCY_COOLDOWN_S: f64 = 60.0;
/// Largest covariance inflation of one drift acceptance.
const MAX_INFLATION: f64 = 100.0;

/// The filter and navigation state: everything that a delayed-state update
/// must be able to restore (cloned at each IMU epoch in that mode).
#[derive(Clone)]
struct Core {
    cfg: Arc<FusionConfig>,
    nav: NavState,
    imu: ImuErrors,
    mech: Mechanization,
    filter: ErrorStateFilter,
    started: bool,
    last_time: GpsTime,
    nominal_dt: f64,
    gate: Option<f64>,
    consecutive_rejects: usize,
    /// The last fix rejected by the gate in the current run of rejections.
    last_rejected: Option<RejectedFix>,
    /// When a fix over the gate was last accepted as INS drift.
    last_drift_accept: Option<GpsTime>,
    pending: VecDeque<GnssFix>,
    last_w_ib: Vector3<f64>,
    kin: Kinematics,
    next_nhc: GpsTime,
    next_odo: GpsTime,
    pending_speed: Option<f64>,
    odo_scale: f64,
    odo_scale_index: Option<usize>,
    tau: f64,
    tau_index: Option<usize>,
    tau_observable: bool,
    stats: FusionStats,
    /// Messages since the wrapper last drained them.
    notes: Vec<String>,
    /// Steps since the wrapper last drained them (for the coarse search):
    /// end time, velocity change, duration, antenna lever arm in NED.
    steps: Vec<(GpsTime, Vector3<f64>, f64, Vector3<f64>)>,
    record_steps: bool,
}

impl Core {
    fn new(cfg: Arc<FusionConfig>) -> Self {
        let mut layout = StateLayout::default();
        let mut extra_var = Vec::new();
        let mut odo_scale_index = None;
        if let Some(odo) = &cfg.odometer
            && let Some(sd) = odo.scale_sd
        {
            odo_scale_index = Some(layout.add("odometer_scale", 1e-10));
            extra_var.push(sd * sd);
        }
        let mut tau_index = None;
        let mut tau = 0.0;
        if let Some(to) = &cfg.time_offset {
            tau_index = Some(layout.add("time_offset", to.random_walk_psd));
            extra_var.push(to.sd_s * to.sd_s);
            tau = to.init_s;
        }
        if let Some([g, a]) = cfg.misalignment_sd_rad {
            layout.add_misalignment();
            extra_var.extend([g * g; 6]);
            extra_var.extend([a * a; 6]);
        }
        let filter = ErrorStateFilter::new(layout, cfg.noise, &cfg.init_std, &extra_var);
        let gate = cfg
            .gate_prob
            .filter(|p| *p > 0.0 && *p < 1.0)
            .map(|p| chi2_quantile(p, 3.0));
        let record_steps = cfg.time_offset.is_some_and(|t| t.search_range_s > 0.0);
        Core {
            nav: cfg.init_nav,
            imu: cfg.init_imu,
            mech: Mechanization::new(),
            filter,
            started: false,
            last_time: cfg.init_nav.time,
            nominal_dt: 1.0 / cfg.imu_rate_hz,
            gate,
            consecutive_rejects: 0,
            last_rejected: None,
            last_drift_accept: None,
            pending: VecDeque::new(),
            last_w_ib: Vector3::zeros(),
            kin: Kinematics::default(),
            next_nhc: cfg.init_nav.time,
            next_odo: cfg.init_nav.time,
            pending_speed: None,
            odo_scale: 0.0,
            odo_scale_index,
            tau,
            tau_index,
            tau_observable: false,
            stats: FusionStats::default(),
            notes: Vec::new(),
            steps: Vec::new(),
            record_steps,
            cfg,
        }
    }

    /// Number of accepted corrections so far (any change of the state by
    /// the filter).
    fn corrections(&self) -> usize {
        let s = &self.stats;
        s.gnss_fixes_used + s.gnss_velocity_used + s.nhc_updates + s.odometer_updates
    }

    /// Processing time of a fix: its tag corrected by the offset estimate.
    fn proc_time(&self, fix: &GnssFix) -> GpsTime {
        if self.tau_index.is_some() {
            fix.time.add_seconds(-self.tau)
        } else {
            fix.time
        }
    }

    fn queue(&mut self, fix: GnssFix) {
        if self.pending.iter().any(|p| p.time == fix.time) {
            return;
        }
        if self.started && self.proc_time(&fix) <= self.nav.time {
            self.stats.gnss_fixes_late += 1;
            self.notes.push(format!(
                "GNSS fix at {} arrived after the solution passed it; dropped",
                fix.time
            ));
            return;
        }
        let pos = self.pending.partition_point(|f| f.time <= fix.time);
        self.pending.insert(pos, fix);
    }

    fn push_imu(&mut self, sample: &ImuSample) -> Result<Option<NavOutput>, Error> {
        if !self.started {
            if sample.time < self.cfg.init_nav.time {
                return Ok(None);
            }
            self.started = true;
            self.nav.time = sample.time;
            self.last_time = sample.time;
            self.next_nhc = sample.time;
            self.next_odo = sample.time;
            let first = self
                .imu
                .compensate(&sample.dtheta, &sample.dvel, self.nominal_dt);
            self.mech.set_previous(first);
            while let Some(f) = self.pending.front()
                && self.proc_time(f) <= sample.time
            {
                self.pending.pop_front();
            }
            return Ok(None);
        }
        let dt_ns = sample.time - self.last_time;
        if dt_ns <= 0 {
            self.notes.push(format!(
                "IMU sample at {} is not after {}; skipped",
                sample.time, self.last_time
            ));
            return Ok(None);
        }
        let dt = dt_ns as f64 * 1e-9;
        let mut dtheta = sample.dtheta;
        let mut dvel = sample.dvel;
        if dt > self.cfg.gap_factor * self.nominal_dt {
            self.handle_gap(dt, &mut dtheta, &mut dvel);
        }
        if let Some(speed) = sample.odo_speed {
            self.pending_speed = Some(speed);
        }

        // Split the interval at every GNSS fix inside it.
        let mut start = self.last_time;
        while let Some(fix) = self.pending.front().copied() {
            let tp = self.proc_time(&fix);
            if tp > sample.time {
                break;
            }
            // Within 1 µs of the sample: apply after the full step.
            if sample.time - tp <= 1_000 {
                break;
            }
            self.pending.pop_front();
            if tp <= start {
                // τ̂ moved the fix behind the solution: apply it now.
                self.gnss_update(&fix)?;
                continue;
            }
            let frac = (tp - start) as f64 / (sample.time - start) as f64;
            let seg_dt = (tp - start) as f64 * 1e-9;
            let (th1, v1) = (dtheta * frac, dvel * frac);
            dtheta -= th1;
            dvel -= v1;
            self.integrate(&th1, &v1, seg_dt, tp);
            self.nav.time = tp;
            start = tp;
            self.stats.gnss_split_intervals += 1;
            self.gnss_update(&fix)?;
        }
        let rest_dt = (sample.time - start) as f64 * 1e-9;
        self.integrate(&dtheta, &dvel, rest_dt, sample.time);
        self.nav.time = sample.time;
        self.last_time = sample.time;
        self.stats.imu_samples += 1;

        while let Some(fix) = self.pending.front().copied()
            && self.proc_time(&fix) <= sample.time
        {
            self.pending.pop_front();
            self.gnss_update(&fix)?;
        }
        self.vehicle_updates()?;
        if self.filter.pending_dt() >= self.cfg.cov_step_s {
            self.filter.propagate(&self.nav);
            self.stats.covariance_propagations += 1;
        }
        Ok(Some(NavOutput {
            nav: self.nav,
            imu: self.imu,
        }))
    }

    fn handle_gap(&mut self, dt: f64, dtheta: &mut Vector3<f64>, dvel: &mut Vector3<f64>) {
        self.stats.gaps += 1;
        self.stats.gap_total_s += dt;
        self.stats.max_gap_s = self.stats.max_gap_s.max(dt);
        let ratio = dt / self.nominal_dt;
        let hold = match self.cfg.gap_policy {
            GapPolicy::HoldRate => true,
            GapPolicy::AsIs => false,
            GapPolicy::Auto => {
                // |Δv| ≈ |f|·T with |f| ≈ g for a land vehicle: compare the
                // covered time T with one nominal period and with the gap.
                let covered = dvel.norm() / crate::earth::GAMMA_E;
                let to_nominal = (covered / self.nominal_dt).ln().abs();
                let to_gap = (covered / dt).ln().abs();
                to_nominal < to_gap
            }
        };
        if hold {
            *dtheta *= ratio;
            *dvel *= ratio;
        }
        self.mech.reset_history();
        self.notes.push(format!(
            "IMU data gap of {:.4} s ({:.1} nominal periods) ending at {}: {}",
            dt,
            ratio,
            self.last_time.add_seconds(dt),
            if hold {
                "rates held over the gap"
            } else {
                "increments taken to cover the whole gap"
            }
        ));
    }

    /// Mechanizes one raw increment pair over `dt` ending at `t`.
    fn integrate(&mut self, dtheta: &Vector3<f64>, dvel: &Vector3<f64>, dt: f64, t: GpsTime) {
        if dt <= 0.0 {
            return;
        }
        let inc: Increment = self.imu.compensate(dtheta, dvel, dt);
        self.last_w_ib = inc.dtheta / dt;
        let step = self.mech.step(&mut self.nav, &inc);
        self.filter.accumulate(&step);
        self.kin.push(&step);
        if self.record_steps {
            let lever_n = self.nav.q_nb * self.cfg.antenna_lever_b;
            self.steps.push((t, step.dv_n, dt, lever_n));
        }
    }

    fn apply(
        &mut self,
        obs: &Observation,
        gate: Option<f64>,
        frozen: &[usize],
    ) -> Result<UpdateOutcome, Error> {
        self.filter.propagate(&self.nav);
        let outcome = self
            .filter
            .update_with_frozen(obs, gate, frozen, self.nav.time)?;
        if outcome.accepted {
            feedback(
                &outcome.dx,
                self.filter.layout(),
                &mut self.nav,
                &mut self.imu,
            );
            if let Some(i) = self.odo_scale_index {
                self.odo_scale -= outcome.dx[i];
            }
            if let Some(i) = self.tau_index {
                self.tau -= outcome.dx[i];
            }
        }
        Ok(outcome)
    }

    /// Whether the motion currently carries information on the time offset:
    /// the fix's along-track offset −v·δτ can only be told from a position
    /// error while the velocity changes (speed or direction).
    fn offset_observable(&self) -> bool {
        let speed = (self.nav.vel.x.powi(2) + self.nav.vel.y.powi(2)).sqrt();
        let acc_h = self.kin.acc_slow.norm();
        speed > 0.5 && acc_h > 0.1
    }

    fn frozen_states(&mut self) -> Vec<usize> {
        match (self.tau_index, self.cfg.time_offset) {
            (Some(i), Some(to)) => {
                self.tau_observable = self.offset_observable();
                if to.hold_when_unobservable && !self.tau_observable {
                    self.stats.time_offset_held_updates += 1;
                    vec![i]
                } else {
                    vec![]
                }
            }
            _ => vec![],
        }
    }

    fn gnss_update(&mut self, fix: &GnssFix) -> Result<(), Error> {
        let n = self.filter.n();
        let lever = self.cfg.antenna_lever_b;
        let mut obs = gnss::position(&self.nav, fix, &lever, n);
        let frozen = self.frozen_states();
        if let Some(i) = self.tau_index {
            // ∂z/∂δτ = −v of the antenna (seed 004 eq 15).
            let c = self.nav.c_nb();
            let w_nb = crate::ins::omega_nb_b(&self.nav, &self.last_w_ib);
            let v_ant = self.nav.vel + c * w_nb.cross(&lever);
            for r in 0..3 {
                obs.h.set(r, i, -v_ant[r]);
            }
        }
        let gate = if self.consecutive_rejects >= self.cfg.max_consecutive_rejects {
            None
        } else {
            self.gate
        };
        let outcome = self.apply(&obs, gate, &frozen)?;
        if !outcome.accepted
            && let Some(threshold) = gate
        {
            match self.consistent_with_last_rejected(&obs, fix.time, threshold) {
                Some(factor) => {
                    self.notes.push(format!(
                        "GNSS fix at {} over the gate (NIS {:.1} > {:.1}) accepted: it agrees with the previous rejected fix, so the INS drifted beyond its covariance; covariance inflated x{:.2}",
                        fix.time, outcome.nis, threshold, factor
                    ));
                    self.filter.inflate(factor);
                    self.apply(&obs, None, &frozen)?;
                    self.stats.gnss_fixes_accepted_consistent += 1;
                    self.last_drift_accept = Some(fix.time);
                }
                None => {
                    self.consecutive_rejects += 1;
                    self.stats.gnss_fixes_rejected += 1;
                    self.notes.push(format!(
                        "GNSS fix at {} rejected by the innovation gate (innovation {:.3} m, NIS {:.1} > {:.1})",
                        fix.time,
                        Vector3::from_column_slice(&obs.z).norm(),
                        outcome.nis,
                        threshold
                    ));
                    let first_ratio = match &self.last_rejected {
                        Some(prev) => prev.first_ratio,
                        None => outcome.nis / threshold,
                    };
                    self.last_rejected = Some(RejectedFix {
                        time: fix.time,
                        z: obs.z.clone(),
                        r: obs.r.clone(),
                        first_ratio,
                    });
                    return Ok(());
                }
            }
        }
        self.last_rejected = None;
        if gate.is_none() && self.gate.is_some() {
            self.stats.gate_reopened += 1;
            self.notes.push(format!(
                "GNSS fix at {} accepted without gating after {} consecutive rejections",
                fix.time, self.consecutive_rejects
            ));
        }
        self.consecutive_rejects = 0;
        self.stats.gnss_fixes_used += 1;
        if self.cfg.use_gnss_velocity
            && let Some(mut obs) = gnss::velocity(&self.nav, fix, &lever, &self.last_w_ib, n)
        {
            if let Some(i) = self.tau_index {
                for r in 0..3 {
                    obs.h.set(r, i, -self.kin.acc[r]);
                }
            }
            if self.apply(&obs, self.gate, &frozen)?.accepted {
                self.stats.gnss_velocity_used += 1;
            } else {
                self.stats.gnss_velocity_rejected += 1;
                self.notes.push(format!(
                    "GNSS velocity at {} rejected by the innovation gate",
                    fix.time
                ));
            }
        }
        Ok(())
    }

    /// Tells INS drift from a GNSS fault when a fix fails the gate. A fault
    /// (multipath, a wrong fix) makes the innovation jump; a filter whose
    /// model left errors out (axis misalignment, vibration, a rough
    /// nonlinearity) sees it grow smoothly past the gate while consecutive
    /// fixes keep agreeing with each other. So the fix is taken when the
    /// run of rejections began just over the gate and the difference of
    /// this innovation and the last rejected one passes the same gate with
    /// covariance S_k + R_{k−1}. Returns the covariance inflation that
    /// makes the innovation's size match its covariance
    /// (λ = (zᵀz − tr R) / tr(H P Hᵀ), the moment estimate of an adaptive
    /// fading factor, Xia et al. 1994), at least 1, at most
    /// [`MAX_INFLATION`]; none within [`CONSISTENCY_COOLDOWN_S`] of the last.
    fn consistent_with_last_rejected(
        &self,
        obs: &Observation,
        time: GpsTime,
        threshold: f64,
    ) -> Option<f64> {
        let prev = self.last_rejected.as_ref()?;
        if self
            .last_drift_accept
            .is_some_and(|t| time.seconds_since(t) < CONSISTENCY_COOLDOWN_S)
        {
            return None;
        }
        if prev.first_ratio > SMOOTH_START_RATIO
            || time.seconds_since(prev.time) > CONSISTENCY_MAX_GAP_S
            || prev.z.len() != obs.z.len()
        {
            return None;
        }
        let s = self.filter.innovation_covariance(obs);
        let mut c = s.clone();
        for (x, y) in c.data.iter_mut().zip(&prev.r.data) {
            *x += y;
        }
        let l = dense::cholesky(&c)?;
        let d: Vec<f64> = obs.z.iter().zip(&prev.z).map(|(a, b)| a - b).collect();
        let mut c_inv_d = d.clone();
        dense::cholesky_solve(&l, &mut c_inv_d);
        let chi2: f64 = d.iter().zip(&c_inv_d).map(|(a, b)| a * b).sum();
        if chi2.is_nan() || chi2 > threshold {
            return None;
        }
        let m = obs.dim();
        let z2: f64 = obs.z.iter().map(|x| x * x).sum();
        let tr_r: f64 = (0..m).map(|i| obs.r.get(i, i)).sum();
        let tr_hph: f64 = (0..m).map(|i| s.get(i, i) - obs.r.get(i, i)).sum();
        let factor = ((z2 - tr_r) / tr_hph).clamp(1.0, MAX_INFLATION);
        factor.is_finite().then_some(factor)
    }

    fn vehicle_updates(&mut self) -> Result<(), Error> {
        let n = self.filter.n();
        let frozen: Vec<usize> = self.tau_index.into_iter().collect();
        if let Some(nhc) = self.cfg.nhc
            && self.nav.time >= self.next_nhc
        {
            self.next_nhc = self.nav.time.add_seconds(nhc.interval_s);
            let obs = nhc.vehicle.nhc(&self.nav, &self.last_w_ib, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.nhc_updates += 1;
            }
        }
        if let Some(odo) = self.cfg.odometer
            && self.nav.time >= self.next_odo
            && let Some(speed) = self.pending_speed.take()
        {
            self.next_odo = self.nav.time.add_seconds(odo.interval_s);
            let scale = self.odo_scale_index.map(|i| (i, self.odo_scale));
            let obs = odo
                .vehicle
                .odometer(&self.nav, &self.last_w_ib, speed, odo.sd_mps, scale, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.odometer_updates += 1;
            }
        }
        Ok(())
    }

    /// Re-initialises τ̂ from the coarse search when the filter disagrees.
    fn adopt_coarse(&mut self, est: &OffsetEstimate) -> Option<String> {
        let i = self.tau_index?;
        let sd_f = self.filter.sd(i);
        let diff = self.tau - est.offset_s;
        if diff.abs() <= 3.0 * (sd_f * sd_f + est.sd_s * est.sd_s).sqrt() {
            return Some(format!(
                "time-offset coarse search: {:.4} s ± {:.4} s agrees with the filter ({:.4} s ± {:.4} s)",
                est.offset_s, est.sd_s, self.tau, sd_f
            ));
        }
        self.tau = est.offset_s;
        let p = self.filter.covariance_mut();
        for j in 0..p.rows {
            p.set(i, j, 0.0);
            p.set(j, i, 0.0);
        }
        let sd = est.sd_s.max(0.002);
        p.set(i, i, sd * sd);
        Some(format!(
            "time-offset coarse search: {:.4} s ± {:.4} s over {} epochs; filter re-initialised from {:.4} s",
            est.offset_s,
            est.sd_s,
            est.epochs,
            est.offset_s + diff
        ))
    }
}

/// The fixed-lag mode's output predictor: the lagged filter state carried
/// forward through the buffered samples.
#[derive(Clone)]
struct Predictor {
    nav: NavState,
    mech: Mechanization,
    last: GpsTime,
    /// The lagged filter's correction count this prediction started from.
    corrections: usize,
}

impl Predictor {
    fn step(&mut self, s: &ImuSample, imu: &ImuErrors) {
        let dt = s.time.seconds_since(self.last);
        if dt <= 0.0 {
            return;
        }
        let inc = imu.compensate(&s.dtheta, &s.dvel, dt);
        self.mech.step(&mut self.nav, &inc);
        self.nav.time = s.time;
        self.last = s.time;
    }
}

/// Interval between stored filter states in the delayed-state mode.
const SNAPSHOT_INTERVAL_NS: i64 = 50_000_000;

/// A recent solution epoch kept for real-time latency handling.
#[derive(Copy, Clone, Debug)]
struct HistoryEntry {
    time: GpsTime,
    pos: Geodetic,
    vel: Vector3<f64>,
}

/// The streaming engine.
pub struct Fusion {
    core: Core,
    search: Option<CoarseOffsetSearch>,
    search_reported: bool,
    // Real-time latency handling.
    history: VecDeque<HistoryEntry>,
    snapshots: VecDeque<Core>,
    imu_buffer: VecDeque<ImuSample>,
    /// Fixes inserted in the delayed-state window (re-queued on a restore).
    applied: VecDeque<GnssFix>,
    predictor: Option<Predictor>,
    replays: usize,
    now: GpsTime,
    diag: Diagnostics,
}

impl Fusion {
    pub fn new(cfg: FusionConfig) -> Self {
        let search = cfg
            .time_offset
            .filter(|t| t.search_range_s > 0.0)
            .map(|t| CoarseOffsetSearch::new(t.search_range_s, cfg.init_nav.vel));
        let now = cfg.init_nav.time;
        Fusion {
            core: Core::new(Arc::new(cfg)),
            search,
            search_reported: false,
            history: VecDeque::new(),
            snapshots: VecDeque::new(),
            imu_buffer: VecDeque::new(),
            applied: VecDeque::new(),
            predictor: None,
            replays: 0,
            now,
            diag: Diagnostics::with_cap(1000),
        }
    }

    fn cfg(&self) -> &FusionConfig {
        &self.core.cfg
    }

    /// The current navigation state of the filter (for [`LatencyMode::FixedLag`]
    /// this is the lagged state, not the predicted output).
    pub fn nav(&self) -> &NavState {
        &self.core.nav
    }

    /// The current IMU error estimates.
    pub fn imu_errors(&self) -> &ImuErrors {
        &self.core.imu
    }

    pub fn stats(&self) -> FusionStats {
        let mut s = self.core.stats.clone();
        s.delayed_state_replays = self.replays;
        s
    }

    /// Reported conditions (gaps, rejected or late fixes, …).
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diag
    }

    /// Takes the diagnostics collected so far.
    pub fn take_diagnostics(&mut self) -> Diagnostics {
        std::mem::replace(&mut self.diag, Diagnostics::with_cap(1000))
    }

    /// Estimated odometer scale factor (0 when not estimated).
    pub fn odometer_scale(&self) -> f64 {
        self.core.odo_scale
    }

    /// The time-offset estimate, when the state is enabled.
    pub fn time_offset(&self) -> Option<TimeOffsetState> {
        self.core.tau_index.map(|i| TimeOffsetState {
            offset_s: self.core.tau,
            sd_s: self.core.filter.sd(i),
            observable: self.core.tau_observable,
        })
    }

    /// The coarse time-offset search result, once it converged.
    pub fn coarse_offset(&self) -> Option<OffsetEstimate> {
        self.search.as_ref().and_then(|s| s.result())
    }

    /// Standard deviations of all states at the current time (propagates
    /// the covariance first).
    pub fn std_devs(&mut self) -> Vec<f64> {
        let nav = self.core.nav;
        self.core.filter.propagate(&nav);
        (0..self.core.filter.n())
            .map(|i| self.core.filter.sd(i))
            .collect()
    }

    /// Covariance of the position error δr^n (m², NED) as of the last
    /// propagation (call [`Self::std_devs`] first for the current time).
    pub fn position_covariance(&self) -> nalgebra::Matrix3<f64> {
        let p = self.core.filter.covariance();
        let i0 = crate::filter::idx::POS;
        nalgebra::Matrix3::from_fn(|r, c| p.get(i0 + r, i0 + c))
    }

    /// Sets the odometer speed (m/s) used at the next odometer update.
    pub fn push_speed(&mut self, speed_mps: f64) {
        self.core.pending_speed = Some(speed_mps);
    }

    fn drain_notes(&mut self) {
        for n in self.core.notes.drain(..) {
            self.diag.note(n);
        }
    }

    fn feed_search(&mut self) {
        let steps = std::mem::take(&mut self.core.steps);
        let Some(search) = self.search.as_mut() else {
            return;
        };
        for (t, dv, dt, lever_n) in &steps {
            search.push_step(*t, dv, *dt, lever_n);
        }
        if !self.search_reported
            && let Some(est) = search.result()
        {
            self.search_reported = true;
            self.core.record_steps = false;
            if let Some(msg) = self.core.adopt_coarse(&est) {
                self.diag.note(msg);
            }
        }
    }

    /// Pushes a GNSS fix. In [`LatencyMode::Offline`] fixes must come before
    /// the IMU samples pass their time; in the real-time modes, push each
    /// fix when it arrives (after the IMU samples up to its arrival).
    pub fn push_gnss(&mut self, fix: GnssFix) -> Result<(), Error> {
        if let Some(s) = self.search.as_mut() {
            s.push_fix(fix.time, &fix.pos, &fix.pos_sd);
        }
        match self.cfg().latency {
            LatencyMode::Offline | LatencyMode::FixedLag { .. } => self.core.queue(fix),
            LatencyMode::Naive => {
                if self.core.started {
                    let mut f = fix;
                    f.time = self.core.nav.time;
                    self.core.gnss_update(&f)?;
                } else {
                    self.core.queue(fix);
                }
            }
            LatencyMode::Extrapolate => self.extrapolated_update(fix)?,
            LatencyMode::DelayedState { .. } => self.delayed_update(fix)?,
        }
        self.drain_notes();
        Ok(())
    }

    /// Processes one IMU sample and returns the solution at its time, or
    /// `None` for the starting sample and samples before the start.
    pub fn push_imu(&mut self, sample: &ImuSample) -> Result<Option<NavOutput>, Error> {
        self.now = sample.time;
        let out = match self.cfg().latency {
            LatencyMode::FixedLag { lag_s } => self.push_imu_lagged(sample, lag_s)?,
            LatencyMode::DelayedState { max_latency_s } => {
                let out = self.core.push_imu(sample)?;
                if out.is_some() {
                    self.imu_buffer.push_back(*sample);
                    self.maybe_snapshot();
                    // Keep the states (and samples after them) that a fix up
                    // to `max_latency_s` old can need.
                    let oldest = sample.time.add_seconds(-max_latency_s);
                    while self.snapshots.len() > 1 && self.snapshots[1].nav.time <= oldest {
                        self.snapshots.pop_front();
                    }
                    let keep_from = self
                        .snapshots
                        .front()
                        .map(|s| s.nav.time)
                        .unwrap_or(sample.time);
                    while self.imu_buffer.front().is_some_and(|s| s.time <= keep_from) {
                        self.imu_buffer.pop_front();
                    }
                }
                out
            }
            _ => self.core.push_imu(sample)?,
        };
        if let Some(o) = &out
            && self.cfg().latency == LatencyMode::Extrapolate
        {
            self.history.push_back(HistoryEntry {
                time: o.nav.time,
                pos: o.nav.pos,
                vel: o.nav.vel,
            });
            let oldest = o.nav.time.add_seconds(-5.0);
            while self.history.len() > 2 && self.history[1].time <= oldest {
                self.history.pop_front();
            }
        }
        self.feed_search();
        self.drain_notes();
        Ok(out)
    }

    /// (a) The filter consumes samples `lag_s` behind; the output is its
    /// state predicted through the buffered samples.
    fn push_imu_lagged(
        &mut self,
        sample: &ImuSample,
        lag_s: f64,
    ) -> Result<Option<NavOutput>, Error> {
        self.imu_buffer.push_back(*sample);
        let horizon = sample.time.add_seconds(-lag_s);
        while let Some(s) = self.imu_buffer.front().copied()
            && s.time <= horizon
        {
            self.imu_buffer.pop_front();
            self.core.push_imu(&s)?;
        }
        if !self.core.started {
            return Ok(None);
        }
        // Output predictor: the lagged state carried through the buffered
        // samples. It is rebuilt only when the lagged filter corrected its
        // state; otherwise the newest sample is integrated onto it.
        let corrections = self.core.corrections();
        let rebuild = self
            .predictor
            .as_ref()
            .is_none_or(|p| p.corrections != corrections);
        if rebuild {
            let mut p = Predictor {
                nav: self.core.nav,
                mech: self.core.mech.clone(),
                last: self.core.last_time,
                corrections,
            };
            for s in &self.imu_buffer {
                p.step(s, &self.core.imu);
            }
            self.predictor = Some(p);
        } else if let Some(p) = self.predictor.as_mut() {
            p.step(sample, &self.core.imu);
        }
        let nav = self
            .predictor
            .as_ref()
            .map(|p| p.nav)
            .unwrap_or(self.core.nav);
        Ok(Some(NavOutput {
            nav,
            imu: self.core.imu,
        }))
    }

    /// (b) Seed 002 step 5: shift the fix by the INS change between its time
    /// of validity and now, and apply it now.
    fn extrapolated_update(&mut self, fix: GnssFix) -> Result<(), Error> {
        if !self.core.started {
            self.core.queue(fix);
            return Ok(());
        }
        let now = self.core.nav;
        let Some(then) = self.history_at(fix.time) else {
            self.core.stats.gnss_fixes_late += 1;
            self.core.notes.push(format!(
                "GNSS fix at {} is older than the kept INS history; dropped",
                fix.time
            ));
            return Ok(());
        };
        let le = LocalEarth::new(&then.pos, &then.vel);
        let d_ned = le.geodetic_delta_to_ned(
            now.pos.lat_rad - then.pos.lat_rad,
            now.pos.lon_rad - then.pos.lon_rad,
            now.pos.h_m - then.pos.h_m,
        );
        let d = LocalEarth::new(&fix.pos, &then.vel).ned_to_geodetic_delta(&d_ned);
        let mut moved = fix;
        moved.time = now.time;
        moved.pos = Geodetic::new(
            fix.pos.lat_rad + d.x,
            fix.pos.lon_rad + d.y,
            fix.pos.h_m + d.z,
        );
        moved.vel = fix.vel.map(|v| v + (now.vel - then.vel));
        self.core.gnss_update(&moved)
    }

    fn history_at(&self, t: GpsTime) -> Option<HistoryEntry> {
        let h = &self.history;
        let n = h.len();
        if n == 0 || t < h[0].time {
            return None;
        }
        if t >= h[n - 1].time {
            return Some(h[n - 1]);
        }
        let i = h.partition_point(|e| e.time <= t).clamp(1, n - 1);
        let (a, b) = (h[i - 1], h[i]);
        let u = (t - a.time) as f64 / (b.time - a.time) as f64;
        Some(HistoryEntry {
            time: t,
            pos: Geodetic::new(
                a.pos.lat_rad + (b.pos.lat_rad - a.pos.lat_rad) * u,
                a.pos.lon_rad + (b.pos.lon_rad - a.pos.lon_rad) * u,
                a.pos.h_m + (b.pos.h_m - a.pos.h_m) * u,
            ),
            vel: a.vel + (b.vel - a.vel) * u,
        })
    }

    /// Stores the filter state every [`SNAPSHOT_INTERVAL_NS`] (a delayed fix
    /// replays at most that much more than its latency).
    fn maybe_snapshot(&mut self) {
        let due = self
            .snapshots
            .back()
            .is_none_or(|s| self.core.nav.time - s.nav.time >= SNAPSHOT_INTERVAL_NS);
        if due {
            self.snapshots.push_back(self.core.clone());
        }
    }

    /// (c) Return to the stored state before the fix, insert it, and
    /// re-process the buffered IMU samples.
    fn delayed_update(&mut self, fix: GnssFix) -> Result<(), Error> {
        let tp = self.core.proc_time(&fix);
        if !self.core.started || tp > self.core.nav.time {
            self.core.queue(fix);
            self.applied.push_back(fix);
            return Ok(());
        }
        let Some(k) = self.snapshots.iter().rposition(|s| s.nav.time < tp) else {
            self.core.stats.gnss_fixes_late += 1;
            self.core.notes.push(format!(
                "GNSS fix at {} is older than the stored states; dropped (raise the maximum latency)",
                fix.time
            ));
            return Ok(());
        };
        let notes = std::mem::take(&mut self.core.notes);
        let mut core = self.snapshots[k].clone();
        core.notes = notes;
        self.replays += 1;
        // Fixes already applied after the snapshot must be applied again.
        let t_snap = core.nav.time;
        for f in &self.applied {
            if core.proc_time(f) > t_snap && !core.pending.iter().any(|p| p.time == f.time) {
                core.queue(*f);
            }
        }
        core.queue(fix);
        self.applied.push_back(fix);
        let oldest = self.snapshots[0].nav.time;
        while self
            .applied
            .front()
            .is_some_and(|f| self.core.proc_time(f) < oldest)
        {
            self.applied.pop_front();
        }
        self.snapshots.truncate(k + 1);
        let replay: Vec<ImuSample> = self
            .imu_buffer
            .iter()
            .filter(|s| s.time > t_snap)
            .copied()
            .collect();
        self.core = core;
        for s in &replay {
            self.core.push_imu(s)?;
            self.maybe_snapshot();
        }
        // The coarse search already saw these steps on the first pass.
        self.core.steps.clear();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::TurningAtRest;

    fn setup(latency: LatencyMode) -> (TurningAtRest, FusionConfig) {
        let m = TurningAtRest {
            pos: Geodetic::from_deg(30.4, 114.5, 25.0),
            yaw0_rad: 0.3,
            rate_rad_s: 0.05,
            t0: GpsTime::from_week_sow(2300, 1000.0),
        };
        let std = InitialStd {
            pos: Vector3::repeat(1.0),
            vel: Vector3::repeat(0.1),
            att: Vector3::repeat(0.01),
            gyro_bias: Vector3::repeat(1e-5),
            accel_bias: Vector3::repeat(1e-3),
            gyro_scale: Vector3::repeat(1e-4),
            accel_scale: Vector3::repeat(1e-4),
        };
        let noise = ImuNoise {
            arw: Vector3::repeat(1e-5),
            vrw: Vector3::repeat(1e-4),
            gyro_bias_sd: Vector3::repeat(1e-6),
            accel_bias_sd: Vector3::repeat(1e-5),
            gyro_scale_sd: Vector3::repeat(1e-5),
            accel_scale_sd: Vector3::repeat(1e-5),
            corr_time_s: 3600.0,
        };
        let mut nav0 = m.state(m.t0);
        nav0.pos.h_m += 0.5; // an initial error for the fixes to correct
        let mut cfg = FusionConfig::new(nav0, std, noise, 200.0);
        cfg.latency = latency;
        (m, cfg)
    }

    /// Runs 30 s with 1 Hz fixes arriving `latency_s` after validity.
    fn run(latency: LatencyMode, latency_s: f64) -> (NavState, NavState, FusionStats) {
        let (m, cfg) = setup(latency);
        let mut f = Fusion::new(cfg);
        let dt = 5_000_000;
        let mut t = m.t0;
        let mut last = None;
        let mut next_fix = m.t0.add_seconds(1.0);
        for _ in 0..(30 * 200) {
            let s = m.sample(t + -dt, t);
            let fix_arrival = next_fix.add_seconds(if latency == LatencyMode::Offline {
                -0.5
            } else {
                latency_s
            });
            if t >= fix_arrival {
                let truth = m.state(next_fix);
                f.push_gnss(GnssFix {
                    time: next_fix,
                    pos: truth.pos,
                    pos_sd: Vector3::repeat(0.02),
                    vel: None,
                    vel_sd: None,
                })
                .unwrap();
                next_fix = next_fix.add_seconds(1.0);
            }
            if let Some(o) = f.push_imu(&s).unwrap() {
                last = Some(o.nav);
            }
            t = t + dt;
        }
        let nav = last.unwrap();
        (nav, m.state(nav.time), f.stats().clone())
    }

    #[test]
    fn every_latency_mode_converges_on_a_consistent_scenario() {
        for (mode, lat) in [
            (LatencyMode::Offline, 0.0),
            (LatencyMode::Naive, 0.1),
            (LatencyMode::FixedLag { lag_s: 0.2 }, 0.1),
            (LatencyMode::Extrapolate, 0.1),
            (LatencyMode::DelayedState { max_latency_s: 0.5 }, 0.1),
        ] {
            let (nav, truth, stats) = run(mode, lat);
            let le = LocalEarth::new(&truth.pos, &truth.vel);
            let dp = le.geodetic_delta_to_ned(
                nav.pos.lat_rad - truth.pos.lat_rad,
                nav.pos.lon_rad - truth.pos.lon_rad,
                nav.pos.h_m - truth.pos.h_m,
            );
            // At rest latency costs nothing: all modes remove the 0.5 m
            // initial height error to well below the fixes' 2 cm.
            assert!(dp.norm() < 0.01, "{mode:?}: {dp}");
            assert!(stats.gnss_fixes_used >= 28, "{mode:?}: {stats:?}");
            assert_eq!(stats.gnss_fixes_late, 0, "{mode:?}");
        }
    }

    /// Runs 60 s at rest with 1 Hz fixes displaced north by `shift(t)` (m,
    /// t in s from the start); returns the final north error against the
    /// fixes' track and the statistics.
    fn run_with_shifted_fixes(shift: impl Fn(f64) -> f64) -> (f64, FusionStats) {
        let (m, cfg) = setup(LatencyMode::Offline);
        let mut f = Fusion::new(cfg);
        let dt = 5_000_000;
        let mut t = m.t0;
        let mut next_fix = m.t0.add_seconds(1.0);
        let mut last = None;
        for _ in 0..(60 * 200) {
            if t >= next_fix.add_seconds(-0.5) {
                let mut pos = m.state(next_fix).pos;
                let le = LocalEarth::new(&pos, &Vector3::zeros());
                pos.lat_rad += shift(next_fix.seconds_since(m.t0)) / le.rm_h;
                f.push_gnss(GnssFix {
                    time: next_fix,
                    pos,
                    pos_sd: Vector3::repeat(0.02),
                    vel: None,
                    vel_sd: None,
                })
                .unwrap();
                next_fix = next_fix.add_seconds(1.0);
            }
            if let Some(o) = f.push_imu(&m.sample(t + -dt, t)).unwrap() {
                last = Some(o.nav);
            }
            t = t + dt;
        }
        let nav = last.unwrap();
        let truth = m.state(nav.time);
        let le = LocalEarth::new(&truth.pos, &truth.vel);
        let north = (nav.pos.lat_rad - truth.pos.lat_rad) * le.rm_h;
        (
            north - shift(nav.time.seconds_since(m.t0)),
            f.stats().clone(),
        )
    }

    #[test]
    fn smooth_drift_past_the_gate_is_followed_and_a_jump_is_rejected() {
        // The fixes accelerate away from the INS at 0.05 m/s² from 20 s on:
        // to this overconfident filter (accelerometer bias σ 1 mm/s²) it is
        // an error its model left out, growing smoothly past the gate while
        // consecutive fixes agree. The filter must follow the fixes.
        let (err, stats) = run_with_shifted_fixes(|t| 0.025 * (t - 20.0).max(0.0).powi(2));
        // One drift episode: accepted once (the cooldown keeps a
        // disagreement that comes back from inflating P again and again).
        assert_eq!(stats.gnss_fixes_accepted_consistent, 1, "{stats:?}");
        assert!(
            stats.gnss_fixes_rejected <= 3 && stats.gate_reopened == 0,
            "{stats:?}"
        );
        assert!(err.abs() < 0.1, "north error against the fixes {err} m");
        // A 3 m jump for three epochs is a GNSS fault: all three rejected,
        // none taken for drift, and the solution stays on the true track.
        let (err, stats) =
            run_with_shifted_fixes(|t| if (30.0..33.0).contains(&t) { 3.0 } else { 0.0 });
        assert_eq!(stats.gnss_fixes_rejected, 3, "{stats:?}");
        assert_eq!(stats.gnss_fixes_accepted_consistent, 0, "{stats:?}");
        assert!(err.abs() < 0.01, "north error {err} m");
    }
}
