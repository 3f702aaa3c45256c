//! The streaming GNSS/INS engine: push IMU samples and GNSS fixes, get the
//! navigation state at every IMU epoch.
//!
//! Loosely coupled, indirect-feedback (closed-loop) Kalman filter (seed 000
//! §1.2; seed 004 §1.1): the strapdown mechanization runs on every IMU
//! sample; GNSS fixes, the non-holonomic constraint and odometer speeds
//! correct it through the error-state filter, and the estimated errors are
//! fed back at once.
//!
//! A GNSS fix that falls between two IMU samples is processed at its own
//! time: the IMU interval is split there under the linear-rate assumption,
//! the first part is integrated, the fix is applied, and the remainder
//! follows. Every IMU sample uses its own interval; a gap longer than
//! `gap_factor` nominal periods is reported, never bridged silently.

use std::collections::VecDeque;

use nalgebra::Vector3;
use serde::Serialize;

use crate::error::{Diagnostics, Error};
use crate::filter::gnss::{self, GnssFix};
use crate::filter::nhc::VehicleConstraint;
use crate::filter::{
    ErrorStateFilter, ImuNoise, InitialStd, Observation, StateLayout, UpdateOutcome, feedback,
};
use crate::ins::{ImuErrors, ImuSample, Increment, Mechanization, NavState};
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
        }
    }
}

/// The solution at one IMU epoch.
#[derive(Copy, Clone, Debug)]
pub struct NavOutput {
    pub nav: NavState,
    pub imu: ImuErrors,
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
    pub nhc_updates: usize,
    pub odometer_updates: usize,
    pub gaps: usize,
    pub gap_total_s: f64,
    pub max_gap_s: f64,
    pub covariance_propagations: usize,
}

/// The streaming engine.
pub struct Fusion {
    cfg: FusionConfig,
    nav: NavState,
    imu: ImuErrors,
    mech: Mechanization,
    filter: ErrorStateFilter,
    started: bool,
    last_time: GpsTime,
    nominal_dt: f64,
    gate: Option<f64>,
    gate_vel: Option<f64>,
    consecutive_rejects: usize,
    pending: VecDeque<GnssFix>,
    last_w_ib: Vector3<f64>,
    next_nhc: GpsTime,
    next_odo: GpsTime,
    pending_speed: Option<f64>,
    odo_scale: f64,
    odo_scale_index: Option<usize>,
    stats: FusionStats,
    diag: Diagnostics,
}

impl Fusion {
    pub fn new(cfg: FusionConfig) -> Self {
        let mut layout = StateLayout::default();
        let mut extra_var = Vec::new();
        let mut odo_scale_index = None;
        if let Some(odo) = &cfg.odometer
            && let Some(sd) = odo.scale_sd
        {
            odo_scale_index = Some(layout.add("odometer_scale", 1e-10));
            extra_var.push(sd * sd);
        }
        let filter = ErrorStateFilter::new(layout, cfg.noise, &cfg.init_std, &extra_var);
        let gate = cfg
            .gate_prob
            .filter(|p| *p > 0.0 && *p < 1.0)
            .map(|p| chi2_quantile(p, 3.0));
        Fusion {
            nav: cfg.init_nav,
            imu: cfg.init_imu,
            mech: Mechanization::new(),
            filter,
            started: false,
            last_time: cfg.init_nav.time,
            nominal_dt: 1.0 / cfg.imu_rate_hz,
            gate,
            gate_vel: gate,
            consecutive_rejects: 0,
            pending: VecDeque::new(),
            last_w_ib: Vector3::zeros(),
            next_nhc: cfg.init_nav.time,
            next_odo: cfg.init_nav.time,
            pending_speed: None,
            odo_scale: 0.0,
            odo_scale_index,
            stats: FusionStats::default(),
            diag: Diagnostics::with_cap(1000),
            cfg,
        }
    }

    /// The current navigation state.
    pub fn nav(&self) -> &NavState {
        &self.nav
    }

    /// The current IMU error estimates.
    pub fn imu_errors(&self) -> &ImuErrors {
        &self.imu
    }

    pub fn stats(&self) -> &FusionStats {
        &self.stats
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
        self.odo_scale
    }

    /// Queues a GNSS fix. Fixes must arrive before the IMU samples pass
    /// their time; a fix older than the current solution is reported as
    /// late and dropped.
    pub fn push_gnss(&mut self, fix: GnssFix) {
        if self.started && fix.time <= self.nav.time {
            self.stats.gnss_fixes_late += 1;
            self.diag.note(format!(
                "GNSS fix at {} arrived after the solution passed it; dropped",
                fix.time
            ));
            return;
        }
        let pos = self.pending.partition_point(|f| f.time <= fix.time);
        self.pending.insert(pos, fix);
    }

    /// Sets the odometer speed (m/s) used at the next odometer update.
    pub fn push_speed(&mut self, speed_mps: f64) {
        self.pending_speed = Some(speed_mps);
    }

    /// Standard deviations of all states at the current time (propagates
    /// the covariance first).
    pub fn std_devs(&mut self) -> Vec<f64> {
        self.filter.propagate(&self.nav);
        (0..self.filter.n()).map(|i| self.filter.sd(i)).collect()
    }

    /// Processes one IMU sample and returns the solution at its time, or
    /// `None` for the starting sample and samples before the start.
    pub fn push_imu(&mut self, sample: &ImuSample) -> Result<Option<NavOutput>, Error> {
        if !self.started {
            // Half a nanosecond of slack: configs give start times in decimal seconds.
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
            while self.pending.front().is_some_and(|f| f.time <= sample.time) {
                self.pending.pop_front();
            }
            return Ok(None);
        }
        let dt_ns = sample.time - self.last_time;
        if dt_ns <= 0 {
            self.diag.note(format!(
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
            if fix.time > sample.time {
                break;
            }
            self.pending.pop_front();
            // Within 1 µs of the sample: apply after the full step.
            if sample.time - fix.time <= 1_000 {
                self.pending.push_front(fix);
                break;
            }
            let frac = (fix.time - start) as f64 / (sample.time - start) as f64;
            let seg_dt = (fix.time - start) as f64 * 1e-9;
            let (th1, v1) = (dtheta * frac, dvel * frac);
            dtheta -= th1;
            dvel -= v1;
            self.integrate(&th1, &v1, seg_dt);
            self.nav.time = fix.time;
            start = fix.time;
            self.stats.gnss_split_intervals += 1;
            self.gnss_update(&fix)?;
        }
        let rest_dt = (sample.time - start) as f64 * 1e-9;
        self.integrate(&dtheta, &dvel, rest_dt);
        self.nav.time = sample.time;
        self.last_time = sample.time;
        self.stats.imu_samples += 1;

        while self.pending.front().is_some_and(|f| f.time <= sample.time) {
            let fix = self.pending.pop_front().expect("front exists");
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
        self.diag.note(format!(
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

    /// Mechanizes one raw increment pair over `dt` with the current error
    /// estimates.
    fn integrate(&mut self, dtheta: &Vector3<f64>, dvel: &Vector3<f64>, dt: f64) {
        if dt <= 0.0 {
            return;
        }
        let inc: Increment = self.imu.compensate(dtheta, dvel, dt);
        self.last_w_ib = inc.dtheta / dt;
        let step = self.mech.step(&mut self.nav, &inc);
        self.filter.accumulate(&step);
    }

    fn apply(&mut self, obs: &Observation, gate: Option<f64>) -> Result<UpdateOutcome, Error> {
        self.filter.propagate(&self.nav);
        let outcome = self.filter.update(obs, gate, self.nav.time)?;
        if outcome.accepted {
            feedback(&outcome.dx, &mut self.nav, &mut self.imu);
            if let Some(i) = self.odo_scale_index {
                self.odo_scale -= outcome.dx[i];
            }
        }
        Ok(outcome)
    }

    fn gnss_update(&mut self, fix: &GnssFix) -> Result<(), Error> {
        let n = self.filter.n();
        let obs = gnss::position(&self.nav, fix, &self.cfg.antenna_lever_b, n);
        let gate = if self.consecutive_rejects >= self.cfg.max_consecutive_rejects {
            None
        } else {
            self.gate
        };
        let outcome = self.apply(&obs, gate)?;
        if !outcome.accepted {
            self.consecutive_rejects += 1;
            self.stats.gnss_fixes_rejected += 1;
            self.diag.note(format!(
                "GNSS fix at {} rejected by the innovation gate (innovation {:.3} m, NIS {:.1} > {:.1})",
                fix.time,
                Vector3::from_column_slice(&obs.z).norm(),
                outcome.nis,
                gate.unwrap_or(f64::INFINITY)
            ));
            return Ok(());
        }
        if gate.is_none() && self.gate.is_some() {
            self.stats.gate_reopened += 1;
            self.diag.note(format!(
                "GNSS fix at {} accepted without gating after {} consecutive rejections",
                fix.time, self.consecutive_rejects
            ));
        }
        self.consecutive_rejects = 0;
        self.stats.gnss_fixes_used += 1;
        if self.cfg.use_gnss_velocity
            && let Some(obs) = gnss::velocity(
                &self.nav,
                fix,
                &self.cfg.antenna_lever_b,
                &self.last_w_ib,
                n,
            )
        {
            if self.apply(&obs, self.gate_vel)?.accepted {
                self.stats.gnss_velocity_used += 1;
            } else {
                self.stats.gnss_velocity_rejected += 1;
                self.diag.note(format!(
                    "GNSS velocity at {} rejected by the innovation gate",
                    fix.time
                ));
            }
        }
        Ok(())
    }

    fn vehicle_updates(&mut self) -> Result<(), Error> {
        let n = self.filter.n();
        if let Some(nhc) = self.cfg.nhc
            && self.nav.time >= self.next_nhc
        {
            self.next_nhc = self.nav.time.add_seconds(nhc.interval_s);
            let obs = nhc.vehicle.nhc(&self.nav, &self.last_w_ib, n);
            if self.apply(&obs, None)?.accepted {
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
            if self.apply(&obs, None)?.accepted {
                self.stats.odometer_updates += 1;
            }
        }
        Ok(())
    }
}
