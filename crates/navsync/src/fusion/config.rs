//! The engine's settings and the figures it reports: latency modes, GNSS
//! weighting, vehicle constraints, the time-offset state, statistics.

#![warn(missing_docs)]

use super::*;

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
    FixedLag {
        /// How far the filter runs behind real time (s).
        lag_s: f64,
    },
    /// (b) Seed 002 step 5: the fix valid at t_v is used at its receipt
    /// time, moved forward by the INS change over the latency.
    Extrapolate,
    /// (c) Delayed-state update: return to the stored state at t_v, update
    /// there and propagate forward again through the buffered IMU samples.
    DelayedState {
        /// Oldest fix that can still be fused (s after its time of
        /// validity): stored states and IMU samples are kept this long.
        max_latency_s: f64,
    },
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
    Gate {
        /// Gate probability, within (0, 1) (`--gate-prob`).
        prob: f64,
    },
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
    /// Whether fixes that jump from their neighbours (against the INS)
    /// get their R scaled up (step 1 of the robust update). Off by
    /// default: on the real-GNSS drive of docs/real-gnss.md it cost the
    /// MEMS IMUs up to 15 % of horizontal RMS against every fix at its σ,
    /// while gaining the navigation-grade one 5–10 %; without it robust
    /// weighting stays within 4 % of KF-GINS's rule for every IMU there.
    pub noise_scale: bool,
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
            noise_scale: false,
            prior_fixes: 4.0,
            drift_run: 3,
        }
    }
}

impl RobustWeighting {
    /// The IGG-III equivalent weight of a standardised residual.
    pub(crate) fn weight(&self, v: f64) -> f64 {
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
    /// Fused at its stated σ.
    Used,
    /// Fused with an inflated R on some axis (robust weighting).
    DownWeighted,
    /// Not fused (over the gate, or every axis beyond `k1`).
    Rejected,
    /// Accepted after a run of rejections that agreed with each other.
    DriftAccepted,
}

/// One GNSS observation as the filter saw it (for `gnss_residuals.txt`
/// and the report).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct FixRecord {
    /// GPS time tag of the fix.
    #[serde(skip)]
    pub time: GpsTime,
    /// Seconds of the GPS week.
    pub sow: f64,
    /// "position" or "velocity".
    pub kind: &'static str,
    /// Innovation, predicted minus measured (m or m/s, NED).
    pub(crate) innovation: [f64; 3],
    /// Stated standard deviations (m or m/s).
    pub sd: [f64; 3],
    /// Normalised innovation squared with the stated σ (3 degrees of freedom).
    pub nis: f64,
    /// Weight per axis (R divided by it, memory included).
    pub(crate) weight: [f64; 3],
    /// What became of it.
    pub status: FixStatus,
    /// Why (the integrity monitor's or the robust weighting's reason).
    pub reason: crate::fusion::FaultReason,
    /// Horizontal protection level after it (m): K·√(λ·largest eigenvalue
    /// of the horizontal position covariance), K = [`crate::fusion::PROTECTION_K`].
    pub hpl_m: f64,
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
    /// Checks the model's values; the message names the bad one.
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
    pub(crate) vehicle: VehicleConstraint,
    /// Seconds between constraint updates.
    pub(crate) interval_s: f64,
}

/// Odometer speed update settings (speeds come from the IMU file's 8th
/// column or from `Fusion::push_speed`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct OdometerOptions {
    pub(crate) vehicle: VehicleConstraint,
    pub(crate) sd_mps: f64,
    pub(crate) interval_s: f64,
    /// Estimate an odometer scale factor with this initial σ.
    pub(crate) scale_sd: Option<f64>,
}

/// Dual-antenna heading update settings.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HeadingOptions {
    /// Yaw of the baseline (primary → secondary antenna) in the body frame,
    /// from x towards y (rad).
    pub dual_antenna_yaw_rad: f64,
    /// σ of that yaw (rad): a Schmidt "consider" state (Schmidt 1966;
    /// Groves §3.4.3 on consider states), carried in P and never updated,
    /// so that repeated headings cannot average the constant mounting
    /// error away.
    pub dual_antenna_yaw_sd_rad: f64,
    /// The alignment took its heading from the baseline: the initial yaw
    /// error holds the mounting error (P starts with their correlation).
    pub aligned_from_baseline: bool,
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

impl TimeOffsetOptions {
    /// Largest coarse search range (±s): the search keeps a 1 ms grid
    /// over ±(range + 50 ms) (`offset_search.rs`), 10 101 cells at 5 s; an
    /// IMU–GNSS offset beyond seconds is a wrong clock (e.g. GPS vs UTC),
    /// to be fixed in the time stamps, not estimated.
    pub const MAX_SEARCH_RANGE_S: f64 = 5.0;
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
    pub(crate) init_imu: ImuErrors,
    /// Initial standard deviations of the filter states.
    pub init_std: InitialStd,
    /// The IMU's noise and error-process model (KF-GINS `imunoise`).
    pub noise: ImuNoise,
    /// GNSS antenna position in the body frame (m, FRD).
    pub(crate) antenna_lever_b: Vector3<f64>,
    /// Estimate the antenna lever arm as three error states (random
    /// constants in the body frame) with this initial σ (m); `None`: the
    /// lever arm is the fixed `antenna_lever_b` (`fusion/aid/lever_arm.rs`).
    pub lever_arm_sd_m: Option<f64>,
    /// The initial position was placed from a GNSS fix less the lever arm
    /// (an alignment): with the lever-arm states on, its error is
    /// correlated with theirs (`fusion/aid/lever_arm.rs`).
    pub(crate) init_pos_from_antenna: bool,
    /// Nominal IMU rate (Hz), for gap detection.
    pub imu_rate_hz: f64,
    /// A step longer than this many nominal periods is a gap.
    pub gap_factor: f64,
    /// How the sample that ends a gap is treated.
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
    /// Non-holonomic constraint; `None`: off.
    pub nhc: Option<NhcOptions>,
    /// Odometer/CAN speed updates; `None`: off.
    pub odometer: Option<OdometerOptions>,
    /// Dual-antenna heading updates (headings from `Fusion::push_heading`).
    pub heading: Option<HeadingOptions>,
    /// Estimate the IMU–GNSS time offset as a filter state; `None`: off.
    pub time_offset: Option<TimeOffsetOptions>,
    /// How GNSS fixes that arrive late are used.
    pub latency: LatencyMode,
    /// Estimate the 12 axis misalignments of the gyro and accelerometer
    /// triads (random constants) with these initial σ (rad): gyro, accel.
    /// A MEMS IMU's ±0.05° couples a 10°/s turn into 30°/h of tilt rate,
    /// which the 21 KF-GINS states leave out (the filter is then
    /// overconfident in turns and outages).
    pub(crate) misalignment_sd_rad: Option<[f64; 2]>,
    /// Time-correlated GNSS position error as filter states.
    pub gnss_error: Option<GnssErrorModel>,
    /// Started levelled over a standstill: the tilt error is M·δb_a
    /// ([`crate::align::levelling_tilt_coupling`]). P starts with
    /// P_φφ += M Σ_b Mᵀ and P_φb = M Σ_b (Σ_b from `init_std.accel_bias`);
    /// `init_std.att` then holds only the tilt σ that is not the bias.
    pub(crate) levelling_coupling: Option<Matrix3<f64>>,
    /// With `levelling_coupling`: σ (rad) of the accelerometer triad's axis
    /// misalignment (the datasheet's cross-axis figure) when it is not
    /// estimated. Levelling takes the misaligned axes for level, so the
    /// tilt error gains M·J(f̄ᵇ)·δm_a, J the misalignment Jacobian of the
    /// levelled specific force f̄ᵇ. With the misalignment states on, their
    /// σ is used instead and P_φm is set as well.
    pub(crate) levelling_accel_misalignment_sd_rad: f64,
    /// Detect standstills and apply zero-velocity and zero-angular-rate
    /// updates while stopped.
    pub standstill: Option<StandstillOptions>,
    /// A land vehicle whose heading is unknown at the start: find it in the
    /// run from the GNSS track (`course_heading`); `None`: off.
    pub course_heading: Option<super::course_heading::CourseHeadingOptions>,
    /// The smoother's re-judged position fixes (`crate::rejudge`), by time
    /// tag: each bypasses the fault monitor and the robust weights (rerun
    /// passes only; `None` in a first pass).
    pub(crate) gnss_decisions:
        Option<std::sync::Arc<std::collections::BTreeMap<GpsTime, GnssDecision>>>,
}

/// The smoother's verdict on one position fix, forced on the forward
/// filter's next pass (`crate::rejudge`).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum GnssDecision {
    /// Inconsistent with the smoothed solution: not fused, recorded with
    /// this reason (the monitor's, or `SmootherExcluded` for a fix the
    /// first pass used).
    Exclude(super::FaultReason),
    /// Consistent with the smoothed solution: used at its stated σ
    /// whatever the forward filter's weights, recorded with this reason
    /// (`SmootherReadmitted` for a fix the first pass excluded,
    /// `Persisted` for one it followed after a fault episode).
    Follow(super::FaultReason),
    /// Consistent with the smoothed solution and used by the first pass:
    /// used at its stated σ, without the fault monitor or the robust
    /// weights (they judged it before; a state the smoother moved must
    /// not refuse it).
    Keep,
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
            lever_arm_sd_m: None,
            init_pos_from_antenna: false,
            imu_rate_hz,
            gap_factor: 2.5,
            gap_policy: GapPolicy::Auto,
            cov_step_s: 0.1,
            gnss_weighting: GnssWeighting::default(),
            max_consecutive_rejects: 5,
            use_gnss_velocity: true,
            nhc: None,
            odometer: None,
            heading: None,
            time_offset: None,
            latency: LatencyMode::Offline,
            misalignment_sd_rad: None,
            gnss_error: None,
            levelling_coupling: None,
            levelling_accel_misalignment_sd_rad: 0.0,
            standstill: None,
            course_heading: None,
            gnss_decisions: None,
        }
    }
}

/// The solution at one IMU epoch.
#[derive(Copy, Clone, Debug)]
pub struct NavOutput {
    /// The navigation state at the epoch.
    pub nav: NavState,
    /// The IMU error estimates (biases, scale factors) at the epoch.
    pub imu: ImuErrors,
}

/// The time-offset estimate at some epoch.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct TimeOffsetState {
    /// Estimated offset τ̂ = GNSS time tag − true time of validity (s).
    pub offset_s: f64,
    /// σ of the estimate (s).
    pub sd_s: f64,
    /// False while τ̂ is held (unobservable motion).
    pub observable: bool,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The robust weighting's measure of how far the INS's position error
/// runs past its σ after gaps.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct InsOverconfidence {
    /// The σ scale in use at the end (HPHᵀ is multiplied by it where fixes
    /// are judged).
    pub scale: f64,
    /// Fixes that measured it, over the run.
    pub fixes: usize,
}

/// Counters the engine keeps.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FusionStats {
    /// IMU samples integrated.
    pub imu_samples: usize,
    /// GNSS positions fused (down-weighted and drift-accepted ones included).
    pub gnss_fixes_used: usize,
    /// GNSS positions rejected.
    pub gnss_fixes_rejected: usize,
    pub(crate) gnss_fixes_late: usize,
    /// GNSS velocities fused.
    pub gnss_velocity_used: usize,
    pub(crate) gnss_velocity_rejected: usize,
    pub(crate) gnss_split_intervals: usize,
    pub(crate) gate_reopened: usize,
    /// Fixes over the gate accepted because they agreed with the previous
    /// rejected fix (the INS had drifted beyond its covariance, which was
    /// inflated); see `Core::gnss_update`.
    pub(crate) gnss_fixes_accepted_consistent: usize,
    /// Robust weighting: fixes used with an inflated R on some axis.
    pub gnss_fixes_downweighted: usize,
    /// Robust weighting: velocities used with an inflated R on some axis.
    pub gnss_velocity_downweighted: usize,
    /// Robust weighting: the INS overconfidence scale at the end of the run
    /// (the median ratio of actual to predicted innovation of the last
    /// fixes sharper than the INS after a gap, within [1, 100]), and how
    /// many such fixes it has seen; absent when none was seen.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gnss_ins_overconfidence: Option<InsOverconfidence>,
    /// The share of the fixes' stated variance that does not change from
    /// one clean fix to the next (N, E, D; 0–1), measured by the fault
    /// monitor over the last 120 s of the run: an error the filter cannot
    /// average, which the written σ and protection levels carry
    /// (`fusion::fix_correlation`; not with Gauss–Markov error states,
    /// which model it); absent until 20 clean pairs measured it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gnss_fix_error_correlated: Option<[f64; 3]>,
    /// Fixes refused before use for non-finite values or a σ ≤ 0 or
    /// beyond [`MAX_GNSS_SD_M`] (repeated times and stale outputs are
    /// counted below).
    pub gnss_fixes_invalid: usize,
    /// Headings from the GNSS track's course fused after the heading was
    /// found there (`course_heading`), and those over the gate.
    #[serde(skip_serializing_if = "is_zero")]
    pub course_heading_updates: usize,
    /// Track-course headings over the χ² gate.
    #[serde(skip_serializing_if = "is_zero")]
    pub course_heading_rejected: usize,
    /// Fixes ignored because their time repeats an earlier fix's.
    pub gnss_fixes_duplicate: usize,
    /// Fixes ignored as stale: position repeated while the solution moved > 1 m.
    pub gnss_fixes_stale: usize,
    /// Fixes the integrity monitor excluded (jumps, runs, ramps).
    pub gnss_fixes_excluded: usize,
    /// Fixes the forward pass used and the smoother's re-judgement
    /// excluded (`crate::rejudge`; the smoothed solution only).
    pub gnss_smoother_excluded: usize,
    /// Fixes the forward pass excluded and the smoother's re-judgement
    /// used again.
    pub gnss_smoother_readmitted: usize,
    /// Forward–backward passes the smoothed solution took (1: the fixes
    /// were consistent with the first; 0: not smoothed or not judged).
    pub gnss_smoother_passes: usize,
    /// GNSS fault episodes (spikes, runs at a false level, ramps, stale
    /// outputs): `fusion::aid::integrity`.
    pub gnss_fault_episodes: Vec<crate::fusion::FaultEpisode>,
    /// A land vehicle's mounting yaw found in the motion and its σ (deg;
    /// `mount_search`), when searched.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_yaw_estimate_deg: Option<f64>,
    /// σ of that estimate (deg).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_yaw_estimate_sd_deg: Option<f64>,
    /// Non-holonomic constraint updates applied.
    pub nhc_updates: usize,
    /// Odometer speed updates applied.
    pub odometer_updates: usize,
    /// Dual-antenna heading updates used and rejected by the gate.
    #[serde(skip_serializing_if = "is_zero")]
    pub heading_updates: usize,
    /// Heading updates rejected by the gate.
    #[serde(skip_serializing_if = "is_zero")]
    pub heading_rejected: usize,
    /// Standstill: zero-velocity and zero-angular-rate updates, and the
    /// time detected still (s).
    pub zupt_updates: usize,
    /// Zero-angular-rate updates.
    pub zaru_updates: usize,
    /// Time detected still (s).
    pub standstill_s: f64,
    /// IMU data gaps (steps over `gap_factor` nominal periods).
    pub gaps: usize,
    /// Total duration of the gaps (s).
    pub gap_total_s: f64,
    /// Longest gap (s).
    pub max_gap_s: f64,
    /// Gaps with GNSS going on after which the navigation state was
    /// re-initialised from the fixes (`fusion/gap.rs`).
    pub gap_reinits: usize,
    pub(crate) covariance_propagations: usize,
    pub(crate) time_offset_held_updates: usize,
    /// Times the time-offset estimate left its search range (± the coarse
    /// search's range) and was reset to its initial value and σ.
    #[serde(skip_serializing_if = "is_zero")]
    pub time_offset_resets: usize,
    pub(crate) delayed_state_replays: usize,
}
