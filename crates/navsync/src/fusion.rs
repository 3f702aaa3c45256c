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

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::earth::{Geodetic, LocalEarth};
use crate::error::{Diagnostics, Error};
use crate::filter::dense::{self, Mat};
use crate::filter::gnss::{self, GnssFix};
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

/// How GNSS fixes that disagree with the INS prediction are weighted.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "mode")]
pub enum GnssWeighting {
    /// Every fix at its stated σ (what KF-GINS does).
    Off,
    /// Chi-square gate at probability `prob`: a fix over it is rejected,
    /// unless it agrees with the previous rejected fix (taken as INS drift:
    /// P is inflated), and after `max_consecutive_rejects` rejections the
    /// next fix is accepted without gating.
    Gate { prob: f64 },
    /// Robust down-weighting (the default); see [`RobustWeighting`].
    Robust(RobustWeighting),
}

impl Default for GnssWeighting {
    fn default() -> Self {
        GnssWeighting::Robust(RobustWeighting::default())
    }
}

/// Robust GNSS weighting. Real GNSS errors come in episodes (multipath,
/// float solutions) in which they exceed the receiver's stated σ several
/// times, correlated over seconds. Two mechanisms (see
/// `Core::robust_apply`):
///
/// - The scale of each axis's noise is estimated by variational Bayes
///   from the jump between consecutive fixes (measured against the INS,
///   whose drift cancels), forgetting with the correlation time
///   `memory_s`; it never drops below the stated σ.
/// - Gross errors: an IGG-III equivalent-weight function on each NED axis
///   of the standardised innovation v_i = z_i/√S_ii (Yang, Song & Xu,
///   "Robust estimator for correlated observations based on bifactor
///   equivalent weights", Journal of Geodesy 76, 2002; its use in a
///   Kalman filter: Yang, He & Xu, "Adaptively robust filtering for
///   kinematic geodetic positioning", Journal of Geodesy 75, 2001):
///
///   w = 1 for |v| ≤ k0; w = (k0/|v|)·((k1 − |v|)/(k1 − k0))² for
///   k0 < |v| ≤ k1; w = 0 beyond k1, and R_ii is divided by w.
///
/// A fix rejected on every axis is counted as rejected; only a run of at
/// least `drift_run` rejected fixes that agree with each other (the INS
/// drifted beyond its covariance, as after a long outage) inflates P.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct RobustWeighting {
    /// Below this |v| a fix keeps its stated σ (4: 6e-5 of honest
    /// Gaussian residuals per axis are touched; real MEMS filters are
    /// often 2–3× overconfident through GNSS gaps, and a lower k0 then
    /// blames good fixes for the INS's drift).
    pub k0: f64,
    /// Beyond this |v| an axis is rejected.
    pub k1: f64,
    /// Correlation time of the noise-scale estimate (s): how long a
    /// degraded episode is remembered. 0 (the default) judges each fix by
    /// its jump from the previous one alone: on the real drive tried, any
    /// memory also discounted the good fixes that end an episode.
    pub memory_s: f64,
    /// Weight of the prior (scale 1: the stated σ) in equivalent fixes.
    pub prior_fixes: f64,
    /// Consecutive rejected fixes, agreeing with each other, that are
    /// taken as INS drift.
    pub drift_run: usize,
}

impl Default for RobustWeighting {
    fn default() -> Self {
        RobustWeighting {
            k0: 4.0,
            k1: 10.0,
            memory_s: 0.0,
            prior_fixes: 4.0,
            drift_run: 3,
        }
    }
}

impl RobustWeighting {
    /// The IGG-III equivalent weight of a standardised residual.
    pub fn weight(&self, v: f64) -> f64 {
        let a = v.abs();
        if a <= self.k0 {
            1.0
        } else if a <= self.k1 {
            let r = (self.k1 - a) / (self.k1 - self.k0);
            self.k0 / a * r * r
        } else {
            0.0
        }
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.k0 > 0.0 && self.k1 > self.k0 && self.k1.is_finite()) {
            return Err(format!(
                "robust GNSS weighting needs 0 < k0 < k1 (k0 {}, k1 {})",
                self.k0, self.k1
            ));
        }
        let finite = self.memory_s.is_finite() && self.prior_fixes.is_finite();
        if !finite || self.memory_s < 0.0 || self.prior_fixes < 1.0 || self.drift_run < 2 {
            return Err(
                "robust GNSS memory must be >= 0 s, the prior >= 1 fix and the drift run >= 2 fixes"
                    .into(),
            );
        }
        Ok(())
    }
}

/// What happened to one GNSS observation (position or velocity of a fix).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FixStatus {
    Used,
    DownWeighted,
    Rejected,
    /// Accepted after a run of rejections that agreed with each other.
    DriftAccepted,
}

/// One GNSS observation as the filter saw it (for `gnss_residuals.txt`
/// and the report).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct FixRecord {
    #[serde(skip)]
    pub time: GpsTime,
    /// Seconds of the GPS week.
    pub sow: f64,
    /// "position" or "velocity".
    pub kind: &'static str,
    /// Innovation, predicted minus measured (m or m/s, NED).
    pub innovation: [f64; 3],
    /// Stated standard deviations (m or m/s).
    pub sd: [f64; 3],
    /// Normalised innovation squared with the stated σ (3 degrees of freedom).
    pub nis: f64,
    /// Weight per axis (R divided by it, memory included).
    pub weight: [f64; 3],
    pub status: FixStatus,
}

/// A receiver's time-correlated position error (multipath, atmosphere,
/// ambiguity residuals) modelled as three first-order Gauss–Markov filter
/// states b (NED): the fix is r_ant + b + white noise, and R keeps only
/// the white part, R_white = max(R_stated − σ_GM², (0.3 σ_stated)²): the
/// stated σ is taken as the total. Without it, a filter that averages
/// many fixes believes it beat an error that does not average down.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct GnssErrorModel {
    /// Steady-state σ of the correlated error per NED axis (m).
    pub gm_sd_m: [f64; 3],
    /// Its correlation time (s).
    pub corr_time_s: f64,
}

impl GnssErrorModel {
    pub fn validate(&self) -> Result<(), String> {
        if self.gm_sd_m.iter().any(|s| !(s.is_finite() && *s > 0.0))
            || !(self.corr_time_s.is_finite() && self.corr_time_s > 0.0)
        {
            return Err(format!(
                "the correlated GNSS error needs positive σ and correlation time (σ {:?} m, τ {} s)",
                self.gm_sd_m, self.corr_time_s
            ));
        }
        Ok(())
    }
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
    /// How disagreeing GNSS fixes are weighted.
    pub gnss_weighting: GnssWeighting,
    /// Gate mode: accept a fix anyway after this many consecutive
    /// rejections (the filter, not the fixes, is then the likely culprit).
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
    /// Time-correlated GNSS position error as filter states.
    pub gnss_error: Option<GnssErrorModel>,
    /// Started levelled over a standstill: the tilt error is M·δb_a
    /// ([`crate::align::levelling_tilt_coupling`]). P starts with
    /// P_φφ += M Σ_b Mᵀ and P_φb = M Σ_b (Σ_b from `init_std.accel_bias`);
    /// `init_std.att` then holds only the tilt σ that is not the bias.
    pub levelling_coupling: Option<Matrix3<f64>>,
    /// Detect standstills and apply zero-velocity and zero-angular-rate
    /// updates while stopped.
    pub standstill: Option<StandstillOptions>,
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
            gnss_weighting: GnssWeighting::default(),
            max_consecutive_rejects: 5,
            use_gnss_velocity: true,
            nhc: None,
            odometer: None,
            time_offset: None,
            latency: LatencyMode::Offline,
            misalignment_sd_rad: None,
            gnss_error: None,
            levelling_coupling: None,
            standstill: None,
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
    /// Robust weighting: fixes used with an inflated R on some axis.
    pub gnss_fixes_downweighted: usize,
    pub gnss_velocity_downweighted: usize,
    /// Fixes refused before use: non-finite values, σ ≤ 0 or beyond
    /// [`MAX_GNSS_SD_M`], a time already seen, or a position repeated
    /// while the vehicle moved (a stale receiver output).
    pub gnss_fixes_invalid: usize,
    pub gnss_fixes_duplicate: usize,
    pub gnss_fixes_stale: usize,
    pub nhc_updates: usize,
    pub odometer_updates: usize,
    /// Standstill: zero-velocity and zero-angular-rate updates, and the
    /// time detected still (s).
    pub zupt_updates: usize,
    pub zaru_updates: usize,
    pub standstill_s: f64,
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

/// Largest stated GNSS σ (m or m/s) taken at face value: beyond it a fix
/// carries no usable information and is refused with a diagnostic.
pub const MAX_GNSS_SD_M: f64 = 1000.0;

/// Why a fix cannot be used at all, if so: non-finite values, σ that are
/// not positive, or σ beyond [`MAX_GNSS_SD_M`].
fn invalid_fix(fix: &GnssFix) -> Option<String> {
    let p = &fix.pos;
    if !(p.lat_rad.is_finite() && p.lon_rad.is_finite() && p.h_m.is_finite()) {
        return Some("its position is not a number".into());
    }
    if p.lat_rad.abs() > std::f64::consts::FRAC_PI_2 || p.h_m.abs() > 1e6 {
        return Some(format!(
            "its position ({:.6}°, {:.1} m) is off the Earth",
            p.lat_rad.to_degrees(),
            p.h_m
        ));
    }
    let check = |sd: &Vector3<f64>, what: &str, unit: &str| -> Option<String> {
        if sd.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Some(format!(
                "its {what} standard deviations {:?} {unit} must be positive numbers",
                sd.as_slice()
            ));
        }
        if sd.max() > MAX_GNSS_SD_M {
            return Some(format!(
                "its {what} standard deviation {:.3e} {unit} exceeds {MAX_GNSS_SD_M} {unit}: no usable information",
                sd.max()
            ));
        }
        None
    };
    if let Some(w) = check(&fix.pos_sd, "position", "m") {
        return Some(w);
    }
    if let Some(v) = &fix.vel {
        if v.iter().any(|x| !x.is_finite()) {
            return Some("its velocity is not a number".into());
        }
        match &fix.vel_sd {
            Some(sd) => return check(sd, "velocity", "m/s"),
            None => return Some("it has a velocity without standard deviations".into()),
        }
    }
    None
}

/// Consecutive fixes further apart than this (s) are not differenced:
/// the INS is then no longer a sharp relative reference.
const PAIR_MAX_GAP_S: f64 = 2.5;

/// A used fix's posterior residual (robust weighting), for the next
/// fix's differenced innovation.
#[derive(Copy, Clone, Debug)]
struct ResidualMemo {
    time: GpsTime,
    /// z⁺ = predicted (after the update) − measured.
    residual: Vector3<f64>,
    /// Diagonal of H P⁺ Hᵀ.
    hph_post: Vector3<f64>,
    /// Diagonal of the stated R.
    r_stated: Vector3<f64>,
}
/// A fix whose R grew by more than ×2 on some axis is reported as
/// down-weighted.
const DOWN_WEIGHTED_BELOW: f64 = 0.5;

/// zᵀ S⁻¹ z, or `None` when S is not positive definite.
fn nis_of(s: &Mat, z: &[f64]) -> Option<f64> {
    let l = dense::cholesky(s)?;
    let mut x = z.to_vec();
    dense::cholesky_solve(&l, &mut x);
    let v: f64 = z.iter().zip(&x).map(|(a, b)| a * b).sum();
    v.is_finite().then_some(v)
}

impl RejectedFix {
    /// Whether `obs` (innovation covariance `s`) agrees with this earlier
    /// fix: the difference of the innovations passes the χ² `threshold`
    /// with covariance S_k + R_{k−1}.
    fn agrees_with(&self, obs: &Observation, s: &Mat, threshold: f64) -> bool {
        if self.z.len() != obs.z.len() {
            return false;
        }
        let mut c = s.clone();
        for (x, y) in c.data.iter_mut().zip(&self.r.data) {
            *x += y;
        }
        let d: Vec<f64> = obs.z.iter().zip(&self.z).map(|(a, b)| a - b).collect();
        nis_of(&c, &d).is_some_and(|chi2| chi2 <= threshold)
    }
}

/// The covariance inflation that makes an innovation's size match its
/// covariance, λ = (zᵀz − tr R) / tr(H P Hᵀ) (the moment estimate of an
/// adaptive fading factor, Xia et al. 1994), within [1, MAX_INFLATION].
fn moment_inflation(obs: &Observation, s: &Mat) -> Option<f64> {
    let m = obs.dim();
    let z2: f64 = obs.z.iter().map(|x| x * x).sum();
    let tr_r: f64 = (0..m).map(|i| obs.r.get(i, i)).sum();
    let tr_hph: f64 = (0..m).map(|i| s.get(i, i) - obs.r.get(i, i)).sum();
    let factor = ((z2 - tr_r) / tr_hph).clamp(1.0, MAX_INFLATION);
    factor.is_finite().then_some(factor)
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
/// Robust weighting: a run of this many rejected fixes that agree with
/// each other is taken as INS drift however it began (a fault that stays
/// consistent that long cannot be told from drift; KF-GINS would have
/// followed it from the start).
const LONG_DRIFT_RUN: usize = 10;
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
    /// Robust weighting: the run of fixes rejected on every axis.
    rejected_run: Vec<RejectedFix>,
    /// Robust weighting: the inverse-gamma posterior (α, β) of the noise
    /// scale of each axis of position and velocity, and when it was set.
    noise_scale: [([(f64, f64); 3], GpsTime); 2],
    /// Robust weighting: the last fix's posterior residual, per slot.
    last_residual: [Option<ResidualMemo>; 2],
    /// The last fix used (time and position), to spot repeated ones.
    last_fix: Option<(GpsTime, Geodetic, Geodetic)>,
    /// Per-observation records since the wrapper last drained them.
    fix_log: Vec<FixRecord>,
    pending: VecDeque<GnssFix>,
    last_w_ib: Vector3<f64>,
    /// Standstill detection, and the still window awaiting its updates.
    still_detector: Option<StandstillDetector>,
    still_window: Option<StillWindow>,
    /// The initial heading is unknown (σ > 90°): yaw is never updated.
    heading_unknown: bool,
    kin: Kinematics,
    next_nhc: GpsTime,
    next_odo: GpsTime,
    pending_speed: Option<f64>,
    odo_scale: f64,
    odo_scale_index: Option<usize>,
    tau: f64,
    tau_index: Option<usize>,
    /// Estimated correlated GNSS position error (NED, m) and its first
    /// state index.
    gnss_bias: Vector3<f64>,
    gnss_bias_index: Option<usize>,
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
        let mut filter = ErrorStateFilter::new(layout, cfg.noise, &cfg.init_std, &extra_var);
        if let Some(m) = cfg.levelling_coupling {
            use crate::filter::idx;
            let sigma_b = Matrix3::from_diagonal(
                &cfg.init_std
                    .accel_bias
                    .component_mul(&cfg.init_std.accel_bias),
            );
            let p = filter.covariance_mut();
            let p_att = p.block3(idx::ATT, idx::ATT) + m * sigma_b * m.transpose();
            let p_att_ba = m * sigma_b;
            p.set_block3(idx::ATT, idx::ATT, &p_att);
            p.set_block3(idx::ATT, idx::BA, &p_att_ba);
            p.set_block3(idx::BA, idx::ATT, &p_att_ba.transpose());
        }
        let gate = match cfg.gnss_weighting {
            GnssWeighting::Gate { prob } if prob > 0.0 && prob < 1.0 => {
                Some(chi2_quantile(prob, 3.0))
            }
            _ => None,
        };
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
            rejected_run: Vec::new(),
            noise_scale: [(
                [(0.0, 0.0); 3].map(|_| {
                    let p = match cfg.gnss_weighting {
                        GnssWeighting::Robust(rw) => 0.5 * rw.prior_fixes,
                        _ => 1.0,
                    };
                    (p, p)
                }),
                cfg.init_nav.time,
            ); 2],
            last_residual: [None; 2],
            last_fix: None,
            fix_log: Vec::new(),
            pending: VecDeque::new(),
            last_w_ib: Vector3::zeros(),
            still_detector: cfg.standstill.map(StandstillDetector::new),
            still_window: None,
            heading_unknown: cfg.init_std.att.z > std::f64::consts::FRAC_PI_2,
            kin: Kinematics::default(),
            next_nhc: cfg.init_nav.time,
            next_odo: cfg.init_nav.time,
            pending_speed: None,
            odo_scale: 0.0,
            odo_scale_index,
            tau,
            tau_index,
            gnss_bias: Vector3::zeros(),
            gnss_bias_index,
            tau_observable: false,
            stats: FusionStats::default(),
            notes: Vec::new(),
            steps: Vec::new(),
            record_steps,
            node_interval_s: None,
            nodes: Vec::new(),
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
        };
        for node in self.filter.take_nodes() {
            self.nodes.push((node, nominal));
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
        if self.pending.iter().any(|p| p.time == fix.time)
            || self.last_fix.is_some_and(|(t, _, _)| t == fix.time)
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
        let pos = self.pending.partition_point(|f| f.time <= fix.time);
        self.pending.insert(pos, fix);
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
            self.propagate();
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
        if let Some(d) = self.still_detector.as_mut() {
            d.reset();
        }
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
        if let Some(d) = self.still_detector.as_mut() {
            let speed = self.nav.vel.x.hypot(self.nav.vel.y);
            let window_s = d.options().window_s;
            let f_n = self.nav.q_nb * (inc.dvel / dt);
            match d.push(&f_n, &self.last_w_ib, &self.imu.gyro_bias, dt, speed) {
                Some(Some(w)) => {
                    self.still_window = Some(w);
                    self.stats.standstill_s += window_s;
                }
                Some(None) => self.still_window = None,
                None => {}
            }
        }
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
        self.propagate();
        // An unknown heading (σ beyond 90°: a vehicle that never moved) is
        // held: a small-angle error model linearised at a wrong heading
        // would let the lever arm or gyrocompassing terms "observe" it.
        let held_yaw;
        let frozen = if self.heading_unknown {
            held_yaw = [frozen, &[crate::filter::idx::ATT + 2]].concat();
            &held_yaw[..]
        } else {
            frozen
        };
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
            if let Some(i) = self.gnss_bias_index {
                for k in 0..3 {
                    self.gnss_bias[k] -= outcome.dx[i + k];
                }
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

    /// The position observation of a fix, with the time-offset column.
    fn position_obs(&self, fix: &GnssFix) -> Observation {
        let lever = self.cfg.antenna_lever_b;
        let mut obs = gnss::position(&self.nav, fix, &lever, self.filter.n());
        if let (Some(i), Some(m)) = (self.gnss_bias_index, &self.cfg.gnss_error) {
            // Predicted fix r̂_ant + b̂: z gains +b̂, ∂z/∂δb = I; R keeps the
            // white part of the stated σ.
            for k in 0..3 {
                obs.z[k] += self.gnss_bias[k];
                obs.h.set(k, i + k, 1.0);
                let r = obs.r.get(k, k);
                let gm2 = m.gm_sd_m[k] * m.gm_sd_m[k];
                obs.r.set(k, k, (r - gm2).max(0.09 * r));
            }
        }
        if let Some(i) = self.tau_index {
            // ∂z/∂δτ = −v of the antenna (seed 004 eq 15).
            let c = self.nav.c_nb();
            let w_nb = crate::ins::omega_nb_b(&self.nav, &self.last_w_ib);
            let v_ant = self.nav.vel + c * w_nb.cross(&lever);
            for r in 0..3 {
                obs.h.set(r, i, -v_ant[r]);
            }
        }
        obs
    }

    /// The velocity observation of a fix (when it has one), with the
    /// time-offset column.
    fn velocity_obs(&self, fix: &GnssFix) -> Option<Observation> {
        let lever = self.cfg.antenna_lever_b;
        let mut obs = gnss::velocity(&self.nav, fix, &lever, &self.last_w_ib, self.filter.n())?;
        if let Some(i) = self.tau_index {
            for r in 0..3 {
                obs.h.set(r, i, -self.kin.acc[r]);
            }
        }
        Some(obs)
    }

    fn gnss_update(&mut self, fix: &GnssFix) -> Result<(), Error> {
        if self.is_stale(fix) {
            return Ok(());
        }
        match self.cfg.gnss_weighting {
            GnssWeighting::Robust(rw) => self.robust_gnss_update(fix, &rw)?,
            GnssWeighting::Off | GnssWeighting::Gate { .. } => self.gated_gnss_update(fix)?,
        }
        self.last_fix = Some((fix.time, fix.pos, self.nav.pos));
        Ok(())
    }

    /// A fix whose position repeats the previous fix's to the last bit
    /// while the solution moved more than 1 m: a receiver repeating a stale
    /// output. Reported and skipped.
    fn is_stale(&mut self, fix: &GnssFix) -> bool {
        let Some((_, prev_pos, prev_nav)) = self.last_fix else {
            return false;
        };
        if prev_pos != fix.pos {
            return false;
        }
        let le = LocalEarth::new(&self.nav.pos, &self.nav.vel);
        let moved = le
            .geodetic_delta_to_ned(
                self.nav.pos.lat_rad - prev_nav.lat_rad,
                self.nav.pos.lon_rad - prev_nav.lon_rad,
                self.nav.pos.h_m - prev_nav.h_m,
            )
            .norm();
        if moved <= 1.0 {
            return false;
        }
        self.stats.gnss_fixes_stale += 1;
        self.notes.push(format!(
            "GNSS fix at {} repeats the previous fix's position while the solution moved {moved:.1} m: a stale receiver output; ignored",
            fix.time
        ));
        true
    }

    /// The first round's rule: χ² gate, drift acceptance, reopening.
    fn gated_gnss_update(&mut self, fix: &GnssFix) -> Result<(), Error> {
        let obs = self.position_obs(fix);
        let frozen = self.frozen_states();
        let gate = if self.consecutive_rejects >= self.cfg.max_consecutive_rejects {
            None
        } else {
            self.gate
        };
        let outcome = self.apply(&obs, gate, &frozen)?;
        let mut record = FixRecord {
            time: fix.time,
            sow: fix.time.sow(),
            kind: "position",
            innovation: [obs.z[0], obs.z[1], obs.z[2]],
            sd: [0, 1, 2].map(|i| obs.r.get(i, i).sqrt()),
            nis: outcome.nis,
            weight: [1.0; 3],
            status: FixStatus::Used,
        };
        if !outcome.accepted
            && let Some(threshold) = gate
        {
            let verdict = self.consistent_with_last_rejected(&obs, fix.time, threshold);
            record.status = match verdict {
                Some(_) => FixStatus::DriftAccepted,
                None => {
                    record.weight = [0.0; 3];
                    FixStatus::Rejected
                }
            };
            self.fix_log.push(record);
            match verdict {
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
        if outcome.accepted {
            self.fix_log.push(record);
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
            && let Some(obs) = self.velocity_obs(fix)
        {
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

    /// Robust GNSS update ([`RobustWeighting`]): position, then velocity.
    fn robust_gnss_update(&mut self, fix: &GnssFix, rw: &RobustWeighting) -> Result<(), Error> {
        let frozen = self.frozen_states();
        let obs = self.position_obs(fix);
        let status = self.robust_apply(obs, 0, fix.time, rw, &frozen)?;
        match status {
            FixStatus::Rejected => {
                self.stats.gnss_fixes_rejected += 1;
                return Ok(());
            }
            FixStatus::DownWeighted => self.stats.gnss_fixes_downweighted += 1,
            FixStatus::DriftAccepted => self.stats.gnss_fixes_accepted_consistent += 1,
            FixStatus::Used => {}
        }
        self.stats.gnss_fixes_used += 1;
        if self.cfg.use_gnss_velocity
            && let Some(obs) = self.velocity_obs(fix)
        {
            match self.robust_apply(obs, 1, fix.time, rw, &frozen)? {
                FixStatus::Rejected => {
                    self.stats.gnss_velocity_rejected += 1;
                    return Ok(());
                }
                FixStatus::DownWeighted => self.stats.gnss_velocity_downweighted += 1,
                _ => {}
            }
            self.stats.gnss_velocity_used += 1;
        }
        Ok(())
    }

    /// Weights one 3-axis GNSS observation (`slot` 0 position, 1 velocity)
    /// and applies it unless every axis is rejected.
    ///
    /// 1. Noise scale. Over a second the INS is a far better relative
    ///    reference than a degraded fix, so the change between this
    ///    innovation and the previous fix's posterior residual,
    ///    Δz = z_k − z⁺_{k−1} = (δr_k − δr⁺_{k−1}) − (e_k − e_{k−1}),
    ///    measures the fixes' own errors e while a smooth INS drift cancels
    ///    (an estimate from the innovations alone would take a drifting INS
    ///    for bad fixes, discount them and drift further). Per axis,
    ///    u = Δz² / ((HPHᵀ)_k − (HP⁺Hᵀ)_{k−1} + R_k + R_{k−1}) (stated R),
    ///    whose mean is 1 for fixes as good as stated, feeds an
    ///    inverse-gamma posterior IG(α, β) of the scale s (R = s·R_stated):
    ///    α ← α + ½, β ← β + ½u (Särkkä & Nummenmaa, "Recursive noise
    ///    adaptive Kalman filtering by variational Bayesian approximations",
    ///    IEEE TAC 54(3), 2009, eqs 14–18, on differenced innovations), with
    ///    forgetting toward the prior IG(ν₀/2, ν₀/2) by exp(−Δt/τ), and
    ///    ŝ = max(1, β/α): no fix is trusted more than it claims.
    /// 2. Gross errors: the IGG-III weight w_i of v_i = z_i/√(HPHᵀ + ŝR)_ii.
    /// 3. The update with R' = diag(ŝ_i R_i / w_i).
    fn robust_apply(
        &mut self,
        mut obs: Observation,
        slot: usize,
        time: GpsTime,
        rw: &RobustWeighting,
        frozen: &[usize],
    ) -> Result<FixStatus, Error> {
        self.propagate();
        let r_stated = Vector3::new(obs.r.get(0, 0), obs.r.get(1, 1), obs.r.get(2, 2));
        let sd = [0, 1, 2].map(|i| r_stated[i].sqrt());
        let s_stated = self.filter.innovation_covariance(&obs);
        let nis = nis_of(&s_stated, &obs.z).unwrap_or(f64::INFINITY);
        let mut hph =
            Matrix3::from_fn(|r, c| s_stated.get(r, c)) - Matrix3::from_diagonal(&r_stated);
        let z = Vector3::new(obs.z[0], obs.z[1], obs.z[2]);

        // 1. Forgetting toward the prior, then the differenced innovation.
        let prior = 0.5 * rw.prior_fixes;
        let (mut post, last) = self.noise_scale[slot];
        let rho = if rw.memory_s > 0.0 {
            (-time.seconds_since(last).max(0.0) / rw.memory_s).exp()
        } else {
            0.0
        };
        for (a, b) in post.iter_mut() {
            *a = prior + (*a - prior) * rho;
            *b = prior + (*b - prior) * rho;
        }
        let mut jump_sq = [0.0; 3];
        if let Some(prev) = self.last_residual[slot]
            && time.seconds_since(prev.time) <= PAIR_MAX_GAP_S
        {
            for i in 0..3 {
                let var =
                    (hph[(i, i)] - prev.hph_post[i]).max(0.0) + r_stated[i] + prev.r_stated[i];
                let d = z[i] - prev.residual[i];
                jump_sq[i] = d * d / var;
                // A jump too large for any noise scale is a gross error,
                // left to step 2 (it must not inflate the scale for long).
                let u = jump_sq[i].min(rw.k1 * rw.k1);
                post[i].0 += 0.5;
                post[i].1 += 0.5 * u;
            }
        }
        let scale = post.map(|(a, b)| (b / a).max(1.0));

        // 2. Gross errors: beyond k1 on any axis, the whole fix is wrong
        //    (a receiver's faults are not confined to one axis).
        let mut w = [1.0; 3];
        for i in 0..3 {
            let s_ii = hph[(i, i)] + scale[i] * r_stated[i];
            w[i] = rw.weight(z[i] / s_ii.max(f64::MIN_POSITIVE).sqrt());
        }
        if w.contains(&0.0) {
            w = [0.0; 3];
        }
        let kind = if slot == 0 { "position" } else { "velocity" };
        let mut record = FixRecord {
            time,
            sow: time.sow(),
            kind,
            innovation: [z[0], z[1], z[2]],
            sd,
            nis,
            weight: [0.0; 3],
            status: FixStatus::Used,
        };
        self.noise_scale[slot] = (post, time);
        // A disagreement that persists smoothly (down-weighted or rejected
        // fixes that agree with each other) is the INS drifting.
        let mut drift = false;
        if slot == 0 {
            if w.iter().any(|w| *w < 1.0) {
                drift = self.robust_drift_check(&obs, &s_stated, time, rw)?;
            } else {
                self.rejected_run.clear();
            }
        }
        if drift {
            record.status = FixStatus::DriftAccepted;
            w = [1.0; 3];
            let s = self.filter.innovation_covariance(&obs);
            hph = Matrix3::from_fn(|r, c| s.get(r, c)) - Matrix3::from_diagonal(&r_stated);
        } else if w.iter().all(|w| *w == 0.0) {
            record.status = FixStatus::Rejected;
            self.fix_log.push(record);
            self.notes.push(format!(
                "GNSS {kind} at {time} rejected by robust weighting (innovation {:.3}, NIS {:.1}; beyond {} σ)",
                z.norm(),
                nis,
                rw.k1
            ));
            return Ok(FixStatus::Rejected);
        }

        // 3. The update.
        let mut r_eff = r_stated;
        for i in 0..3 {
            r_eff[i] = if w[i] > 0.0 {
                scale[i] * r_stated[i] / w[i]
            } else {
                r_stated[i] * 1e12
            };
            record.weight[i] = (r_stated[i] / r_eff[i]).min(1.0);
            obs.r.set(i, i, r_eff[i]);
        }
        if record.status == FixStatus::Used
            && record.weight.iter().any(|w| *w < DOWN_WEIGHTED_BELOW)
        {
            record.status = FixStatus::DownWeighted;
        }
        self.apply(&obs, None, frozen)?;
        // Posterior residual z⁺ = R' S⁻¹ z and H P⁺ Hᵀ = HPHᵀ S⁻¹ R'.
        let r_mat = Matrix3::from_diagonal(&r_eff);
        self.last_residual[slot] = (hph + r_mat).try_inverse().map(|s_inv| {
            let hp_post = hph * s_inv * r_mat;
            ResidualMemo {
                time,
                residual: r_mat * s_inv * z,
                hph_post: Vector3::new(hp_post[(0, 0)], hp_post[(1, 1)], hp_post[(2, 2)]),
                r_stated,
            }
        });
        self.fix_log.push(record);
        Ok(record.status)
    }

    /// After a position fix that was down-weighted or rejected: when the last
    /// `drift_run` such fixes agree with each other (consecutive
    /// innovations differ by no more than their covariances allow) and the
    /// run began just past k1 (at most 2·k1: a fault jumps), or when
    /// [`LONG_DRIFT_RUN`] of them agree, the INS drifted beyond its
    /// covariance, as after a long outage, and P is
    /// inflated by the moment estimate λ = (zᵀz − tr R)/tr(HPHᵀ) (an
    /// adaptive fading factor, Xia et al. 1994), capped at
    /// [`MAX_INFLATION`], at most once per [`CONSISTENCY_COOLDOWN_S`].
    /// Returns whether P was inflated.
    fn robust_drift_check(
        &mut self,
        obs: &Observation,
        s: &Mat,
        time: GpsTime,
        rw: &RobustWeighting,
    ) -> Result<bool, Error> {
        let threshold = chi2_quantile(0.9999, obs.dim() as f64);
        if let Some(prev) = self.rejected_run.last() {
            let agrees = time.seconds_since(prev.time) <= CONSISTENCY_MAX_GAP_S
                && prev.agrees_with(obs, s, threshold);
            if !agrees {
                self.rejected_run.clear();
            }
        }
        // How far past k1 the worst axis is (squared, as the gate's ratio).
        let ratio = (0..obs.dim())
            .map(|i| obs.z[i] * obs.z[i] / s.get(i, i))
            .fold(0.0, f64::max)
            / (rw.k1 * rw.k1);
        self.rejected_run.push(RejectedFix {
            time,
            z: obs.z.clone(),
            r: obs.r.clone(),
            first_ratio: ratio,
        });
        let cooled = self
            .last_drift_accept
            .is_none_or(|t| time.seconds_since(t) >= CONSISTENCY_COOLDOWN_S);
        // A drifting INS crosses k1 gradually; a fault jumps far past it.
        let smooth_start = self.rejected_run[0].first_ratio <= SMOOTH_START_RATIO;
        let run = self.rejected_run.len();
        if !cooled || !((run >= rw.drift_run && smooth_start) || run >= LONG_DRIFT_RUN) {
            return Ok(false);
        }
        let Some(factor) = moment_inflation(obs, s) else {
            return Ok(false);
        };
        self.notes.push(format!(
            "GNSS fix at {time}: {} consecutive disagreeing fixes agree with each other, so the INS drifted beyond its covariance; covariance inflated x{factor:.2}",
            self.rejected_run.len()
        ));
        self.filter.inflate(factor);
        self.last_drift_accept = Some(time);
        self.rejected_run.clear();
        Ok(true)
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
        {
            return None;
        }
        let s = self.filter.innovation_covariance(obs);
        if !prev.agrees_with(obs, &s, threshold) {
            return None;
        }
        moment_inflation(obs, &s)
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
        if let (Some(opts), Some(w)) = (self.cfg.standstill, self.still_window.take()) {
            let obs = standstill::zupt(&self.nav, opts.zupt_sd_mps, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.zupt_updates += 1;
            }
            let obs =
                standstill::zaru(&self.nav, &self.imu.gyro_bias, &w, opts.zaru_floor_rad_s, n);
            if self.apply(&obs, None, &frozen)?.accepted {
                self.stats.zaru_updates += 1;
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
        let mut dx = vec![0.0; self.filter.n()];
        dx[i] = self.tau - est.offset_s;
        self.filter.record_correction(self.nav.time, &dx);
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
    /// Every GNSS observation the filter weighed, in time order.
    fix_log: Vec<FixRecord>,
    /// The forward run's record for the smoother, when enabled.
    recorder: Option<Recorder>,
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
            fix_log: Vec::new(),
            recorder: None,
        }
    }

    /// Records the forward run for fixed-interval smoothing
    /// ([`crate::smoother`]), in temporary files in `dir`, with a node at
    /// every correction epoch and at least every `node_interval_s`. Call
    /// before the first sample; then [`Self::smooth`] at the end.
    /// Smoothing is post-processing: it needs [`LatencyMode::Offline`].
    pub fn enable_smoother(
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
        rec.smooth(layout)
    }

    /// The error-state layout (state names and indices).
    pub fn state_layout(&self) -> &StateLayout {
        self.core.filter.layout()
    }

    /// Nodes and bytes the smoother has recorded so far.
    pub fn smoother_record(&self) -> Option<(usize, u64)> {
        self.recorder.as_ref().map(|r| (r.node_count(), r.bytes()))
    }

    /// The GNSS observations weighed so far (robust weighting): time,
    /// innovation, NIS, weights and what became of each.
    pub fn fix_log(&self) -> &[FixRecord] {
        &self.fix_log
    }

    /// Takes the GNSS observation records collected so far.
    pub fn take_fix_log(&mut self) -> Vec<FixRecord> {
        std::mem::take(&mut self.fix_log)
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

    /// Sets the odometer speed (m/s) used at the next odometer update.
    pub fn push_speed(&mut self, speed_mps: f64) {
        self.core.pending_speed = Some(speed_mps);
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
        self.store_nodes()
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
        self.store_nodes()?;
        if let (Some(rec), Some(o)) = (self.recorder.as_mut(), &out) {
            rec.push_nav(&o.nav)?;
        }
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
        run_shifted(GnssWeighting::Gate { prob: 0.9999 }, shift)
    }

    fn run_shifted(weighting: GnssWeighting, shift: impl Fn(f64) -> f64) -> (f64, FusionStats) {
        let (m, mut cfg) = setup(LatencyMode::Offline);
        cfg.gnss_weighting = weighting;
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

    /// Robust weighting (the default): the same two cases as the gate.
    #[test]
    fn robust_weighting_follows_smooth_drift_and_rejects_a_jump() {
        let robust = GnssWeighting::default();
        let (err, stats) = run_shifted(robust, |t| 0.025 * (t - 20.0).max(0.0).powi(2));
        assert!(
            err.abs() < 0.1,
            "north error against the fixes {err} m; {stats:?}"
        );
        // A 3 m jump for three epochs: three fixes that agree with each
        // other, but the run began with a jump, so it is a fault.
        let (err, stats) = run_shifted(
            robust,
            |t| {
                if (30.0..33.0).contains(&t) { 3.0 } else { 0.0 }
            },
        );
        assert_eq!(stats.gnss_fixes_rejected, 3, "{stats:?}");
        assert_eq!(stats.gnss_fixes_accepted_consistent, 0, "{stats:?}");
        assert!(err.abs() < 0.01, "north error {err} m");
        // Moderately bad fixes (0.3 m jumps, 15 stated σ) for ten epochs
        // are used, down-weighted, and move the solution by less than their
        // error.
        let (err, stats) = run_shifted(robust, |t| {
            if (30.0..40.0).contains(&t) {
                if (t as i64) % 2 == 0 { 0.3 } else { -0.3 }
            } else {
                0.0
            }
        });
        assert!(stats.gnss_fixes_downweighted >= 5, "{stats:?}");
        assert!(err.abs() < 0.01, "north error {err} m");
    }

    /// A straight drive at 10 m/s with 1 Hz fixes of 2 cm, among which
    /// bad ones: every bad fix is reported, none stops the run, and the
    /// solution stays on the true track.
    #[test]
    fn bad_fixes_are_reported_and_leave_the_state_intact() {
        use crate::sim::trajectory::{Segment, Trajectory, TrajectoryOptions};
        use crate::sim::truth::TruthGenerator;
        let traj = Trajectory::from_segments(
            Geodetic::from_deg(30.4, 114.5, 25.0),
            &[Segment::Cruise {
                duration_s: Some(80.0),
                distance_m: None,
            }],
            TrajectoryOptions {
                initial_speed_mps: 10.0,
                initial_heading_rad: 0.4,
                ..Default::default()
            },
        )
        .unwrap();
        let t0 = GpsTime::from_week_sow(2300, 1000.0);
        let mut truth = TruthGenerator::new(&traj, t0);
        let (_, cfg0) = setup(LatencyMode::Offline);
        let mut cfg = FusionConfig::new(truth.state_at(t0).nav, cfg0.init_std, cfg0.noise, 200.0);
        cfg.init_std.pos = Vector3::repeat(0.05);
        let mut f = Fusion::new(cfg);
        let good = |truth: &mut TruthGenerator, t: GpsTime| GnssFix {
            time: t,
            pos: truth.state_at(t).nav.pos,
            pos_sd: Vector3::repeat(0.02),
            vel: None,
            vel_sd: None,
        };
        let mut worst: f64 = 0.0;
        let mut stale = None;
        for k in 1..=200 * 80 {
            let t = t0.add_seconds(k as f64 * 0.005);
            if k % 200 == 100 {
                let sec = k / 200 + 1;
                let tf = t0.add_seconds(sec as f64);
                let mut fix = good(&mut truth, tf);
                match sec {
                    10 => fix.pos_sd = Vector3::new(0.0, 0.02, 0.02),
                    12 => fix.pos.h_m = f64::NAN,
                    14 => fix.pos_sd = Vector3::repeat(1e6),
                    16 => fix.pos.lat_rad += 10_000.0 / 6.4e6,
                    18 => {
                        // A burst of 20 identical fixes (same time).
                        for _ in 0..19 {
                            f.push_gnss(fix).unwrap();
                        }
                    }
                    // A receiver repeating its 30 s fix for 5 s while moving.
                    30 => stale = Some(fix.pos),
                    31..=35 => fix.pos = stale.unwrap(),
                    _ => {}
                }
                f.push_gnss(fix).unwrap();
            }
            let (nav, sample) = truth.next(t);
            if let Some(o) = f.push_imu(&sample).unwrap() {
                let le = LocalEarth::new(&nav.pos, &nav.vel);
                let d = le.geodetic_delta_to_ned(
                    o.nav.pos.lat_rad - nav.pos.lat_rad,
                    o.nav.pos.lon_rad - nav.pos.lon_rad,
                    o.nav.pos.h_m - nav.pos.h_m,
                );
                if k > 200 {
                    worst = worst.max(d.norm());
                }
            }
        }
        let st = f.stats();
        assert_eq!(st.gnss_fixes_invalid, 3, "{st:?}");
        assert_eq!(st.gnss_fixes_duplicate, 19, "{st:?}");
        assert_eq!(st.gnss_fixes_stale, 5, "{st:?}");
        assert_eq!(st.gnss_fixes_rejected, 1, "{st:?}");
        let notes: Vec<String> = f
            .diagnostics()
            .items
            .iter()
            .map(|d| d.to_string())
            .collect();
        let has = |s: &str| notes.iter().any(|n| n.contains(s));
        assert!(has("must be positive numbers"), "{notes:?}");
        assert!(has("not a number"), "{notes:?}");
        assert!(has("no usable information"), "{notes:?}");
        assert!(has("rejected by robust weighting"), "{notes:?}");
        assert!(has("repeats the time"), "{notes:?}");
        assert!(has("stale receiver output"), "{notes:?}");
        assert!(worst < 0.1, "worst position error {worst} m");
    }
}
