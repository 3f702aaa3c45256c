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
//!   velocity), and a coarse search (`crate::offset_search`) brings large
//!   offsets (±0.5 s) within the filter's linear range.
//! - Fixes that arrive late in real time (latency) are handled by one of
//!   the [`LatencyMode`]s.
//!
//! Files: this one holds the engine ([`Fusion`]) and its filter core
//! (mechanization, gaps, covariance propagation); `aid/` the aid sources,
//! one file each behind one trait, their common update path and the
//! delayed-measurement buffer (the design of PX4 EKF2's `aid_sources/`,
//! see `aid/mod.rs`); `latency.rs` the real-time latency modes, policies
//! over that buffer; `config.rs` the settings and statistics.

#![warn(missing_docs)]

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::earth::{Geodetic, LocalEarth};
use crate::error::{Diagnostics, Error};
use crate::filter::dense::{self, Mat};
use crate::filter::gnss::GnssFix;
use crate::filter::nhc::VehicleConstraint;
use crate::filter::standstill::{self, StandstillDetector, StandstillOptions, StillWindow};
use crate::filter::{
    ErrorStateFilter, ImuNoise, InitialStd, Observation, SmootherNode, StateLayout, UpdateOutcome,
    feedback,
};
use crate::ins::{ImuErrors, ImuSample, Increment, Mechanization, NavState, StepInfo};
use crate::offset_search::{CoarseOffsetSearch, OffsetEstimate};
use crate::smoother::{NodeNominal, Recorder, Smoothed};
use crate::stats::chi2_quantile;
use crate::time::GpsTime;

mod aid;
mod config;
pub mod course_heading;
pub(crate) mod fix_correlation;
mod gap;
pub(crate) mod jump_doubt;
mod latency;
mod rollback;
#[cfg(test)]
mod tests;

pub use aid::gnss::MAX_GNSS_SD_M;
use aid::gnss::invalid_fix;
pub use aid::integrity::{
    EpisodeClass, EpisodeEnd, FaultEpisode, FaultReason, MAX_EPISODE_S, PROTECTION_K,
};
pub(crate) use aid::integrity::{FIX_CHANGE_FLOOR_M, fix_test_threshold};
pub use aid::lever_arm::{
    LEVER_OBSERVED_FRACTION, LEVER_SIGNIFICANT_SIGMAS, LeverArmState, LeverArmSummary,
};
use aid::time_offset::Kinematics;
use aid::{AidSources, DelayBuffer, Timed};
pub use config::*;
use latency::{HistoryEntry, Predictor};
pub(crate) use rollback::{KEEP_S as ROLLBACK_KEEP_S, Revised};

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
    /// The aid sources and their control state.
    aid: AidSources,
    /// Per-observation records since the wrapper last drained them.
    fix_log: Vec<FixRecord>,
    /// The delayed-measurement buffer: fixes waiting for the solution to
    /// reach their processing time.
    pending: DelayBuffer<GnssFix>,
    last_w_ib: Vector3<f64>,
    /// The initial heading is unknown (σ > 90°): yaw is never updated.
    heading_unknown: bool,
    /// Finds the heading from the GNSS track while it is unknown.
    course_heading: Option<course_heading::CourseHeading>,
    /// The heading found from the track, once found.
    heading_acquired: Option<course_heading::HeadingAcquired>,
    kin: Kinematics,
    odo_scale: f64,
    odo_scale_index: Option<usize>,
    /// The dual-antenna mounting yaw's consider state.
    heading_mount_index: Option<usize>,
    tau: f64,
    tau_index: Option<usize>,
    /// The antenna lever arm in use (body, m): the configuration's, or
    /// its estimate when the lever-arm states (first index) are on.
    lever_b: Vector3<f64>,
    lever_index: Option<usize>,
    /// Estimated correlated GNSS position error (NED, m) and its first
    /// state index.
    gnss_bias: Vector3<f64>,
    gnss_bias_index: Option<usize>,
    /// The fixes' error that outlasts their spacing, for the written σ
    /// (`fix_correlation`).
    fix_correlation: fix_correlation::FixCorrelation,
    tau_observable: bool,
    stats: FusionStats,
    /// Messages since the wrapper last drained them.
    notes: Vec<String>,
    /// Steps since the wrapper last drained them (for the coarse search):
    /// end time, velocity change, duration, antenna lever arm in NED.
    steps: Vec<(GpsTime, Vector3<f64>, f64, Vector3<f64>)>,
    record_steps: bool,
    /// Smoother: the node interval (s) when nodes are recorded, and the
    /// nodes completed since the wrapper last drained them.
    node_interval_s: Option<f64>,
    nodes: Vec<(SmootherNode, NodeNominal)>,
    /// A fault found after its first fixes were used: what to take back
    /// (`rollback.rs`).
    rollback_to: Option<rollback::Rollback>,
    /// A fix that jumped from the clean level, for the wrapper to judge
    /// against the INS run free from seconds back (`rollback.rs`).
    jump_check: Option<rollback::JumpCheck>,
    /// A fix that jumped again inside a fault episode (`jump_doubt.rs`).
    jump_in_episode: Option<jump_doubt::JumpInEpisode>,
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
        let mut gnss_bias_index = None;
        if let Some(m) = &cfg.gnss_error {
            const NAMES: [&str; 3] = ["gnss_error_n", "gnss_error_e", "gnss_error_d"];
            for (i, name) in NAMES.into_iter().enumerate() {
                let k = layout.add_gauss_markov(name, m.gm_sd_m[i], m.corr_time_s);
                gnss_bias_index.get_or_insert(k);
                extra_var.push(m.gm_sd_m[i] * m.gm_sd_m[i]);
            }
        }
        // The dual-antenna mounting yaw error: a random constant, held.
        let mut heading_mount_index = None;
        if let Some(h) = &cfg.heading
            && h.dual_antenna_yaw_sd_rad > 0.0
        {
            heading_mount_index = Some(layout.add("dual_antenna_yaw", 0.0));
            extra_var.push(h.dual_antenna_yaw_sd_rad * h.dual_antenna_yaw_sd_rad);
        }
        let mut lever_index = None;
        if let Some(sd) = cfg.lever_arm_sd_m {
            const NAMES: [&str; 3] = ["lever_arm_x", "lever_arm_y", "lever_arm_z"];
            for name in NAMES {
                let k = layout.add(name, aid::lever_arm::LEVER_ARM_PSD);
                lever_index.get_or_insert(k);
                extra_var.push(sd * sd);
            }
        }
        let mut filter = ErrorStateFilter::new(layout, cfg.noise, &cfg.init_std, &extra_var);
        // Aligned from the baseline, ψ̂ = az − α̂ with α = α̂ + ε: the yaw
        // error δψ = ψ̂ − ψ = noise + ε, i.e. φ_D = −δψ = −noise + δx_ε
        // (δx_ε = ε̂ − ε = −ε), so cov(φ_D, δx_ε) = σ_ε².
        if let (Some(i), Some(h)) = (heading_mount_index, &cfg.heading)
            && h.aligned_from_baseline
        {
            let v = h.dual_antenna_yaw_sd_rad * h.dual_antenna_yaw_sd_rad;
            let p = filter.covariance_mut();
            p.set(crate::filter::idx::ATT + 2, i, v);
            p.set(i, crate::filter::idx::ATT + 2, v);
        }
        if let Some(m) = cfg.levelling_coupling {
            use crate::filter::idx;
            // Accelerometer axis misalignment enters the velocity error as
            // −C·J(Δv)·δm_a beside the bias's −C·Δt·δb_a (filter/model.rs),
            // so at levelling it is an apparent bias J(f̄ᵇ)·δm_a, with
            // f̄ᵇ = C_bn (0, 0, −g) at rest.
            let f_b =
                cfg.init_nav.c_nb().transpose() * Vector3::new(0.0, 0.0, -crate::earth::GAMMA_E);
            let j = crate::filter::misalign_jacobian(&f_b);
            // The states (first accelerometer index, σ) when estimated.
            let states = filter
                .layout()
                .misalign
                .zip(cfg.misalignment_sd_rad)
                .map(|(first, [_, sd])| (first + 6, sd));
            let sigma_b = Matrix3::from_diagonal(
                &cfg.init_std
                    .accel_bias
                    .component_mul(&cfg.init_std.accel_bias),
            );
            // The tilt error is M·δb_a + M·J·δm_a: the misalignment part
            // correlated with its states when estimated, else tilt noise
            // only (tried: folding it into the bias states' σ did worse on
            // the test-track table of docs/alignment.md).
            let mj = m * j;
            let sd = states.map_or(cfg.levelling_accel_misalignment_sd_rad, |(_, sd)| sd);
            let p = filter.covariance_mut();
            let p_att = p.block3(idx::ATT, idx::ATT)
                + m * sigma_b * m.transpose()
                + mj * mj.transpose() * (sd * sd);
            let p_att_ba = m * sigma_b;
            p.set_block3(idx::ATT, idx::ATT, &p_att);
            p.set_block3(idx::ATT, idx::BA, &p_att_ba);
            p.set_block3(idx::BA, idx::ATT, &p_att_ba.transpose());
            if let Some((first, _)) = states {
                for r in 0..3 {
                    for c in 0..6 {
                        let v = mj[(r, c)] * sd * sd;
                        p.set(idx::ATT + r, first + c, v);
                        p.set(first + c, idx::ATT + r, v);
                    }
                }
            }
        }
        if let (Some(i), Some(sd), true) =
            (lever_index, cfg.lever_arm_sd_m, cfg.init_pos_from_antenna)
        {
            aid::lever_arm::correlate_initial_position(&mut filter, &cfg.init_nav, i, sd);
        }
        let record_steps = cfg.time_offset.is_some_and(|t| t.search_range_s > 0.0);
        Core {
            nav: cfg.init_nav,
            imu: cfg.init_imu,
            mech: Mechanization::new(),
            filter,
            started: false,
            last_time: cfg.init_nav.time,
            nominal_dt: 1.0 / cfg.imu_rate_hz,
            aid: AidSources::new(&cfg),
            fix_log: Vec::new(),
            pending: DelayBuffer::default(),
            last_w_ib: Vector3::zeros(),
            heading_unknown: cfg.init_std.att.z > std::f64::consts::FRAC_PI_2,
            course_heading: cfg.course_heading.map(course_heading::CourseHeading::new),
            heading_acquired: None,
            kin: Kinematics::default(),
            odo_scale: 0.0,
            odo_scale_index,
            heading_mount_index,
            tau,
            tau_index,
            lever_b: cfg.antenna_lever_b,
            lever_index,
            gnss_bias: Vector3::zeros(),
            gnss_bias_index,
            fix_correlation: Default::default(),
            tau_observable: false,
            stats: FusionStats::default(),
            notes: Vec::new(),
            steps: Vec::new(),
            record_steps,
            node_interval_s: None,
            nodes: Vec::new(),
            rollback_to: None,
            jump_check: None,
            jump_in_episode: None,
            cfg,
        }
    }

    /// Propagates the covariance to now and collects any smoother nodes
    /// this completed, with the nominal state they were corrected to.
    fn propagate(&mut self) {
        self.filter.propagate(&self.nav);
        self.collect_nodes();
    }

    fn collect_nodes(&mut self) {
        if self.node_interval_s.is_none() {
            return;
        }
        let nominal = NodeNominal {
            imu: self.imu,
            time_offset_s: self.tau,
            odometer_scale: self.odo_scale,
            yaw_held: self.heading_unknown,
        };
        for node in self.filter.take_nodes() {
            self.nodes.push((node, nominal));
        }
    }

    /// Number of accepted corrections so far (any change of the state by
    /// the filter).
    fn corrections(&self) -> usize {
        self.aid.corrections()
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
        if self.pending.contains_time(fix.time)
            || self.aid.gnss.last_fix.is_some_and(|(t, _)| t == fix.time)
        {
            self.stats.gnss_fixes_duplicate += 1;
            self.notes.push(format!(
                "GNSS fix at {} repeats the time of an earlier fix; ignored",
                fix.time
            ));
            return;
        }
        if let Some(why) = invalid_fix(&fix) {
            self.stats.gnss_fixes_invalid += 1;
            self.notes
                .push(format!("GNSS fix at {} ignored: {why}", fix.time));
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
        self.pending.insert(fix);
    }

    fn push_imu(&mut self, sample: &ImuSample) -> Result<Option<NavOutput>, Error> {
        if !self.started {
            if sample.time < self.cfg.init_nav.time {
                return Ok(None);
            }
            self.started = true;
            // A start between samples (an alignment epoch): carry the
            // position to the first sample at the initial velocity.
            let lag = sample.time.seconds_since(self.nav.time);
            if lag > 0.0 && lag < 1.0 {
                let le = LocalEarth::new(&self.nav.pos, &self.nav.vel);
                let d = le.ned_to_geodetic_delta(&(self.nav.vel * lag));
                self.nav.pos.lat_rad += d.x;
                self.nav.pos.lon_rad += d.y;
                self.nav.pos.h_m += d.z;
            }
            if let Some(dt) = self.node_interval_s {
                self.filter.record_nodes(sample.time, dt);
                self.collect_nodes();
            }
            self.nav.time = sample.time;
            self.last_time = sample.time;
            self.aid.start(sample.time);
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
            if dt >= gap::REINIT_GAP_S && self.reinit_after_gap(sample.time, dt) {
                self.nav.time = sample.time;
                self.last_time = sample.time;
                self.stats.imu_samples += 1;
                if let Some(why) = state_problem(&self.nav) {
                    return Err(breakdown(sample, why));
                }
                return Ok(Some(NavOutput {
                    nav: self.nav,
                    imu: self.imu,
                }));
            }
            self.handle_gap(dt, &mut dtheta, &mut dvel);
        }
        if let Some(speed) = sample.odo_speed {
            self.aid.odometer.speed_mps = Some(speed);
        }

        // Split the interval at every GNSS fix inside it (the buffer's
        // measurements are fused at their own time).
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

        self.fuse_due()?;
        if self.filter.pending_dt() >= self.cfg.cov_step_s {
            self.propagate();
            self.stats.covariance_propagations += 1;
            if let Some(why) = self.filter.variance_problem() {
                return Err(breakdown(sample, why));
            }
        }
        if let Some(why) = state_problem(&self.nav) {
            return Err(breakdown(sample, why));
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
        self.aid.standstill.reset();
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
        if self.aid.standstill.detector.is_some() {
            let speed = self.nav.vel.x.hypot(self.nav.vel.y);
            let f_n = self.nav.q_nb * (inc.dvel / dt);
            self.aid
                .standstill
                .detect(&f_n, &self.last_w_ib, &self.imu.gyro_bias, dt, speed);
        }
        if let Some(free) = self.aid.gnss.free_ins.as_mut() {
            free.step(dtheta, dvel, dt);
        }
        let step = self.mech.step(&mut self.nav, &inc);
        self.filter.accumulate(&step);
        self.kin.push(&step);
        if self.record_steps {
            let lever_n = self.nav.q_nb * self.lever_b;
            self.steps.push((t, step.dv_n, dt, lever_n));
        }
    }
}

/// The streaming engine.
pub struct Fusion {
    core: Core,
    search: Option<CoarseOffsetSearch>,
    search_reported: bool,
    // Real-time latency handling (`latency.rs`).
    /// Extrapolation: the recent solutions.
    history: DelayBuffer<HistoryEntry>,
    /// Delayed state: the stored filter cores.
    snapshots: DelayBuffer<Core>,
    /// Fixed lag and delayed state: the IMU samples after the filter's
    /// horizon.
    imu_buffer: DelayBuffer<ImuSample>,
    /// Delayed state: the fixes received within the stored window, in
    /// arrival order (re-queued on a restore).
    applied: DelayBuffer<GnssFix>,
    /// Delayed state: the dual-antenna headings received within the
    /// stored window, each with when the filter was last given it
    /// ([`latency::given_order`]), given again on a restore to a state
    /// stored before that.
    headings_received: std::collections::VecDeque<(i128, crate::io::heading::HeadingObs)>,
    /// Fixed lag and delayed state: odometer speeds, each with the time of
    /// the buffered IMU sample it was given before (fed to the lagged
    /// filter, or given again in a re-run, just ahead of that sample).
    speeds_given: std::collections::VecDeque<(GpsTime, f64)>,
    /// A speed given after the last IMU sample, to be recorded with the
    /// next one.
    speed_for_next: Option<f64>,
    predictor: Option<Predictor>,
    replays: usize,
    now: GpsTime,
    diag: Diagnostics,
    /// Every GNSS observation the filter weighed, in time order.
    fix_log: Vec<FixRecord>,
    /// The forward run's record for the smoother, when enabled.
    recorder: Option<Recorder>,
    /// Rollback (`rollback.rs`): the states stored after clean fixes.
    rollback_states: std::collections::VecDeque<rollback::Stored>,
    /// Rollback: a ramp's end held as a hypothesis.
    held_ramp_end: Option<rollback::HeldRampEnd>,
    /// Jumps the fixes have not decided, for the σ written.
    jump_doubts: Vec<jump_doubt::JumpDoubt>,
    /// With [`Self::keep_revisions`]: the last rollback's re-run solutions
    /// not yet taken.
    revisions: Option<Vec<rollback::Revised>>,
}

impl Fusion {
    /// A filter over this configuration, waiting for its first IMU sample.
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
            history: DelayBuffer::default(),
            snapshots: DelayBuffer::default(),
            imu_buffer: DelayBuffer::default(),
            applied: DelayBuffer::default(),
            headings_received: std::collections::VecDeque::new(),
            speeds_given: std::collections::VecDeque::new(),
            speed_for_next: None,
            predictor: None,
            replays: 0,
            now,
            diag: Diagnostics::with_cap(1000),
            fix_log: Vec::new(),
            recorder: None,
            rollback_states: std::collections::VecDeque::new(),
            held_ramp_end: None,
            jump_doubts: Vec::new(),
            revisions: None,
        }
        .with_onset_test()
    }

    /// Records the forward run for fixed-interval smoothing
    /// ([`crate::smoother`]), in temporary files in `dir`, with a node at
    /// every correction epoch and at least every `node_interval_s`. Call
    /// before the first sample; then [`Self::smooth`] at the end.
    /// Smoothing is post-processing: it needs [`LatencyMode::Offline`].
    pub(crate) fn enable_smoother(
        &mut self,
        dir: &std::path::Path,
        node_interval_s: f64,
    ) -> Result<(), Error> {
        if self.cfg().latency != LatencyMode::Offline {
            return Err(Error::Invalid(
                "smoothing is post-processing: it needs the offline latency mode (fixes at their time of validity)".into(),
            ));
        }
        if !(node_interval_s.is_finite() && node_interval_s > 0.0) {
            return Err(Error::Invalid(format!(
                "smoother node interval must be positive, got {node_interval_s}"
            )));
        }
        if self.core.started {
            return Err(Error::Invalid(
                "the smoother must be enabled before the first IMU sample".into(),
            ));
        }
        self.recorder = Some(Recorder::create(dir, self.core.filter.n())?);
        self.core.node_interval_s = Some(node_interval_s);
        Ok(())
    }

    fn store_nodes(&mut self) -> Result<(), Error> {
        if let Some(rec) = self.recorder.as_mut() {
            for (node, nominal) in self.core.nodes.drain(..) {
                rec.push_node(&node, &nominal)?;
            }
        }
        Ok(())
    }

    /// Ends the forward run and runs the smoother's backward pass: the
    /// smoothed solution at every epoch the forward run returned.
    pub fn smooth(&mut self) -> Result<Smoothed, Error> {
        let nav = self.core.nav;
        self.core.filter.finish_nodes(&nav);
        self.core.collect_nodes();
        self.store_nodes()?;
        let layout = self.core.filter.layout().clone();
        let rec = self
            .recorder
            .take()
            .ok_or_else(|| Error::Invalid("the smoother was not enabled".into()))?;
        let mut smoothed = rec.smooth(layout)?;
        smoothed.yaw_turn = self.core.heading_acquired;
        Ok(smoothed)
    }

    /// The heading found in the run from the GNSS track, if it was.
    pub fn heading_acquired(&self) -> Option<course_heading::HeadingAcquired> {
        self.core.heading_acquired
    }

    /// The error-state layout (state names and indices).
    pub(crate) fn state_layout(&self) -> &StateLayout {
        self.core.filter.layout()
    }

    /// Nodes and bytes the smoother has recorded so far.
    pub(crate) fn smoother_record(&self) -> Option<(usize, u64)> {
        self.recorder.as_ref().map(|r| (r.node_count(), r.bytes()))
    }

    /// Takes the GNSS observation records collected so far, their
    /// protection levels widened by the jumps the fixes left undecided
    /// (`jump_doubt.rs`).
    pub(crate) fn take_fix_log(&mut self) -> Vec<FixRecord> {
        let mut log = std::mem::take(&mut self.fix_log);
        self.widen_protection_levels(&mut log);
        log
    }

    /// The configuration the filter runs with.
    pub fn config(&self) -> &FusionConfig {
        self.cfg()
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
    pub(crate) fn imu_errors(&self) -> &ImuErrors {
        &self.core.imu
    }

    /// Counts of what the filter did so far.
    pub fn stats(&self) -> FusionStats {
        let mut s = self.core.stats.clone();
        self.core.aid.counters(&mut s);
        s.delayed_state_replays = self.replays;
        s
    }

    /// Reported conditions (gaps, rejected or late fixes, …).
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diag
    }

    /// Takes the diagnostics collected so far.
    pub(crate) fn take_diagnostics(&mut self) -> Diagnostics {
        self.note_unresolved_ramp_end();
        self.note_jump_doubts();
        std::mem::replace(&mut self.diag, Diagnostics::with_cap(1000))
    }

    /// Estimated odometer scale factor (0 when not estimated).
    pub(crate) fn odometer_scale(&self) -> f64 {
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

    /// The antenna lever-arm estimate, when its states are on.
    pub fn lever_arm(&self) -> Option<LeverArmState> {
        self.core.lever_arm_state()
    }

    /// The coarse time-offset search result, once it converged.
    pub(crate) fn coarse_offset(&self) -> Option<OffsetEstimate> {
        self.search.as_ref().and_then(|s| s.result())
    }

    /// Standard deviations of all states at the current time (propagates
    /// the covariance first).
    pub fn std_devs(&mut self) -> Vec<f64> {
        self.core.propagate();
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

    /// The σ of every state and the position covariance (m², NED) as
    /// written beside a solution: the filter's, the position's widened by
    /// the fixes' error that outlasts their spacing (`fix_correlation`).
    /// Propagates the covariance first.
    pub fn written_figures(&mut self) -> (Vec<f64>, nalgebra::Matrix3<f64>) {
        self.core.propagate();
        self.figures_as_propagated()
    }

    /// [`Self::written_figures`] as of the last covariance propagation.
    pub(crate) fn figures_as_propagated(&self) -> (Vec<f64>, nalgebra::Matrix3<f64>) {
        let f = &self.core.filter;
        let mut sd: Vec<f64> = (0..f.n()).map(|i| f.sd(i)).collect();
        let mut cov = self.position_covariance();
        if let Some(extra) = self.correlated_fix_covariance(&cov) {
            widen_position(&mut sd, &mut cov, &extra);
        }
        (sd, cov)
    }

    /// What a written position covariance `p_pos` (m², NED) adds for the
    /// fixes' error that outlasts their spacing (`fix_correlation`).
    pub(crate) fn correlated_fix_covariance(
        &self,
        p_pos: &nalgebra::Matrix3<f64>,
    ) -> Option<nalgebra::Matrix3<f64>> {
        self.core.fix_correlation.covariance(p_pos)
    }

    /// The correlated share of the fixes' stated variance as measured now
    /// (per axis), for the smoothed σ (`fix_correlation`).
    pub(crate) fn correlated_fix_share(&self) -> Option<Vector3<f64>> {
        self.core.aid.gnss.unmodelled_fix_share(self.cfg())
    }

    /// A dual-antenna heading, used at the first IMU epoch at or after its
    /// time (with `FusionConfig::heading`).
    pub(crate) fn push_heading(&mut self, h: crate::io::heading::HeadingObs) {
        if self.cfg().heading.is_none() {
            return;
        }
        self.core.aid.heading.give(h);
        if let LatencyMode::DelayedState { .. } = self.cfg().latency {
            let order = latency::given_order(self.core.nav.time, true);
            self.headings_received.push_back((order, h));
            self.forget_old_headings();
        }
    }

    /// Sets the odometer speed (m/s) used at the next odometer update. A
    /// filter running a lag behind gets it with the next sample, when it
    /// reaches that sample; a delayed-state filter gets it now and again
    /// in every re-run through that sample.
    pub(crate) fn push_speed(&mut self, speed_mps: f64) {
        match self.cfg().latency {
            LatencyMode::FixedLag { .. } => self.speed_for_next = Some(speed_mps),
            LatencyMode::DelayedState { .. } => {
                self.core.aid.odometer.speed_mps = Some(speed_mps);
                self.speed_for_next = Some(speed_mps);
            }
            _ => self.core.aid.odometer.speed_mps = Some(speed_mps),
        }
    }

    fn drain_notes(&mut self) {
        for n in self.core.notes.drain(..) {
            self.diag.note(n);
        }
        // A delayed-state replay weighs fixes again: the new record
        // replaces the old one of the same time and kind.
        for r in self.core.fix_log.drain(..) {
            while let Some(last) = self.fix_log.last()
                && (last.time > r.time || (last.time == r.time && last.kind == r.kind))
            {
                self.fix_log.pop();
            }
            self.fix_log.push(r);
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
            LatencyMode::Offline | LatencyMode::FixedLag { .. } => {
                // Kept for a rollback's re-run (`rollback.rs`).
                if self.core.aid.gnss.monitor.onset_enabled {
                    self.applied.push_back(fix);
                }
                self.core.queue(fix)
            }
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
        self.store_nodes()
    }

    /// Processes one IMU sample and returns the solution at its time, or
    /// `None` for the starting sample and samples before the start.
    pub fn push_imu(&mut self, sample: &ImuSample) -> Result<Option<NavOutput>, Error> {
        self.now = sample.time;
        let out = match self.cfg().latency {
            LatencyMode::FixedLag { lag_s } => self.push_imu_lagged(sample, lag_s)?,
            LatencyMode::DelayedState { max_latency_s } => {
                self.push_imu_delayed_state(sample, max_latency_s)?
            }
            LatencyMode::Extrapolate => {
                let out = self.core.push_imu(sample)?;
                if let Some(o) = &out {
                    self.record_history(o);
                }
                out
            }
            LatencyMode::Offline | LatencyMode::Naive => self.core.push_imu(sample)?,
        };
        self.feed_search();
        self.drain_notes();
        self.store_nodes()?;
        if let (Some(rec), Some(o)) = (self.recorder.as_mut(), &out) {
            rec.push_nav(&o.nav)?;
        }
        if out.is_some() {
            self.after_sample(sample)?;
        }
        Ok(out)
    }
}

/// Why the navigation state is broken, if it is: a value not finite, a
/// latitude beyond ±90°, a height beyond −100 km … 10 000 km or a speed
/// above 10 km/s (far outside the input limits of `crate::io::plausible`:
/// a state there has diverged).
fn state_problem(nav: &NavState) -> Option<String> {
    let p = &nav.pos;
    let finite = p.lat_rad.is_finite()
        && p.lon_rad.is_finite()
        && p.h_m.is_finite()
        && nav.vel.iter().all(|v| v.is_finite())
        && nav.q_nb.coords.iter().all(|v| v.is_finite());
    if !finite {
        return Some("position, velocity or attitude is not finite".into());
    }
    if p.lat_rad.abs() > std::f64::consts::FRAC_PI_2 || !(-1e5..=1e7).contains(&p.h_m) {
        return Some(format!(
            "position latitude {:e}° height {:e} m is off the earth",
            p.lat_rad.to_degrees(),
            p.h_m
        ));
    }
    let v = nav.vel.norm();
    (v > 1e4).then(|| format!("speed {v:e} m/s"))
}

/// The error for a breakdown while processing `sample`, naming the record.
fn breakdown(sample: &ImuSample, why: String) -> Error {
    Error::Diverged {
        time: sample.time,
        msg: format!(
            "{why}, after the IMU record at sow {:.6} (dtheta {:e} {:e} {:e} rad, dvel {:e} {:e} {:e} m/s); \
             stopped rather than write it: check that record and the ones before it; if they are ordinary, \
             the filter's model drove it off: IMU figures far better than the data's (another IMU's sheet) \
             or fixes whose σ are stated far too small",
            sample.time.sow(),
            sample.dtheta.x,
            sample.dtheta.y,
            sample.dtheta.z,
            sample.dvel.x,
            sample.dvel.y,
            sample.dvel.z
        ),
    }
}

/// Adds `extra` (m², NED) to a written position covariance `cov` and to the
/// position σ in the state σ `sd`.
pub(crate) fn widen_position(
    sd: &mut [f64],
    cov: &mut nalgebra::Matrix3<f64>,
    extra: &nalgebra::Matrix3<f64>,
) {
    *cov += extra;
    let pos = crate::filter::idx::POS;
    for i in 0..3 {
        if let Some(s) = sd.get_mut(pos + i) {
            *s = (*s * *s + extra[(i, i)]).sqrt();
        }
    }
}
