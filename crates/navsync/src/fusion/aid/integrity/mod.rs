//! GNSS fault detection and exclusion by episodes (issue 33).
//!
//! A receiver's faults come in episodes: a spike (one wild fix), a false
//! RTK fix (a wrong ambiguity: a constant offset of decimetres to metres
//! for seconds, at a σ of centimetres), a ramp (multipath building up), a
//! stale output. Judged one at a time against the INS, a run of faulty
//! fixes that agree with each other looks like INS drift, and the filter
//! is talked into it. Over seconds, though, the INS's *displacement* is
//! far sharper than its absolute position: the change of the innovation
//! between two fixes measures the change of the fixes' own error.
//!
//! The monitor keeps the last clean fixes (anchors: their posterior
//! residual r⁺ and the state's σ then) and the GNSS corrections applied
//! since (a ledger). For a new fix k and an anchor A,
//!
//!   Δ = z_k − C_A(t_k) − r⁺_A = d − (e_k − e_A),
//!
//! z the innovation (predicted − measured), C_A the position change the
//! GNSS updates since A made to the prediction (their position and
//! velocity corrections carried to t_k), d the free INS's drift since A
//! and e a fix's error: a test on the fixes' time-differenced errors in
//! the spirit of the time-differenced receiver autonomous integrity
//! monitoring of carrier-phase users (e.g. Joerger & Pervan, "Kalman
//! filter-based integrity monitoring against sensor faults", J. Guidance,
//! Control and Dynamics 36(2), 2013, for the idea of testing against the
//! INS over a window). Its covariance is V = λ·G(Δt) + F(Δt), F the
//! variance of the fixes' error change (R_k + R_A for independent errors;
//! less for a receiver whose error is smooth in time, as measured on clean
//! fix pairs: `fix_change_var`), G the
//! free INS's position error growth since A from the state's σ at A
//! (short-term INS error propagation, Titterton & Weston, "Strapdown
//! Inertial Navigation Technology", 2nd ed., §12.3: δr ≈ δv·t +
//! ½(g·δθ + δf)·t² + VRW·t^{3/2}/√3, plus the heading error times the
//! distance travelled, a gyro bias's tilt and heading drift) or the
//! filter's own predicted growth H P Hᵀ − (H P⁺ Hᵀ)_A if larger; with no
//! GNSS update since A, that growth alone (it holds the correlation of
//! tilt and bias that the σ-model leaves out); λ ≥ 1 the INS overconfidence the robust
//! weighting measured on clean fixes. D = Δᵀ V⁻¹ Δ is tested against the
//! χ²₃ quantile at [`FALSE_ALARM_PROB`]:
//!
//! against the last anchor: a *jump* (spikes, the onset of a false fix).
//! A ramp's steps are each too small to see. Against the anchors seconds
//! back a ramp's *onset* shows ([`FaultMonitor::ramp_onset`]) where the
//! INS's drift since is within the fixes' own error change (a navigation-
//! grade INS; over the seconds a ramp takes, a free MEMS INS drifts as a
//! ramp does, and its growth model, from the state's σ, took its own drift
//! for ramps on clean drives): the wrapper then returns to the filter's
//! state after that anchor and runs again without the ramp's fixes
//! (`fusion/rollback.rs`). While the INS is such a reference the robust
//! weighting may not take disagreeing fixes for INS drift. Otherwise a
//! ramp's end is recognised, as a jump back to where the fixes were
//! seconds before: a jump within
//! the INS's drift since an anchor seconds back and much closer to it
//! than to the last, or any jump within that drift once the fixes since
//! had dragged the INS (a fix the robust weighting used because it judged
//! the INS drifted: the fixes before the jump are then the suspects).
//!
//! A detection opens an episode: "the fixes moved to a new level", held as
//! a hypothesis. Each later fix is tested against the episode's anchor:
//! while it fails, the fix is excluded (a *run*);
//! when it passes, either the fixes came back (the episode ends; an
//! episode of one fix was a *spike*) or the INS's own predicted drift has
//! grown to cover the offset (accepted after persisting: the INS can no
//! longer tell), or its drift since the episode began, measured on the
//! episode's fixes, passed the level it judges. Fixes whose offset
//! wanders beyond the INS's growth show an INS that drifts: the fixes
//! are followed again, if the INS, at the
//! rate it drifts from them, could have built the offset (a ramp's size,
//! not a false fix of metres). A fix that jumps from the episode's last
//! one by more than the offset so far, away from the INS, is a new fault
//! inside it (a *jump*: a spike during a false fix), no evidence of
//! drift. An onset's episode holds while the INS's drift since its anchor
//! stays within [`ONSET_HOLD_RATIO`] times the fixes' error change. An
//! episode longer than [`MAX_EPISODE_S`] is one the IMU cannot
//! bridge: the fixes are followed again and the run says so. A persisted
//! level that a later jump undoes (the two jumps' sum within their test)
//! was a false fix, found at its end ([`followed`]).
//! Nothing under suspicion feeds the robust weighting's scales.

use std::collections::VecDeque;

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::stats::chi2_quantile;
use crate::time::GpsTime;

mod followed;
pub(in crate::fusion) use followed::PersistedLevel;
mod onset;
use onset::{ONSET_ANCHOR_SPACING_S, ONSET_CAL_MEMORY_S, ONSET_HOLD_RATIO};

/// False-alarm probability of one test of one clean fix (χ², 3 degrees
/// of freedom).
pub const FALSE_ALARM_PROB: f64 = 1e-4;

/// The threshold of that test: χ²₃'s quantile at 1 − [`FALSE_ALARM_PROB`]
/// (21.1), shared by the monitor and the smoother's re-judgement.
pub(crate) fn fix_test_threshold() -> f64 {
    // Computed once: a bisection over the incomplete gamma function, and
    // the monitor asks for it several times a fix (a fifth of a run's
    // time with 10 Hz fixes).
    static THRESHOLD: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *THRESHOLD.get_or_init(|| chi2_quantile(1.0 - FALSE_ALARM_PROB, 3.0))
}
/// A ramp's end is judged against an anchor (or, in `rollback.rs`, a
/// stored state) at least this old (s): over the last seconds a ramp is
/// below any test.
pub(in crate::fusion) const RAMP_END_MIN_LAG_S: f64 = 3.0;
/// A fix more than this (s) after the last clean one is not tested for a
/// jump.
const JUMP_MAX_GAP_S: f64 = 2.5;
/// Clean fixes in a row needed before the INS is a reference for faults.
const MIN_ANCHORS: usize = 5;
/// …and the span (s) they must cover before the onset test measures a ramp
/// from them ([`Anchor::settled`]): the velocity an episode led off is put
/// right by the fixes over seconds, not over a count of fixes (five fixes
/// span 5 s at 1 Hz but 0.4 s at 10 Hz, where a ramp the filter had
/// followed left a 9 cm/s velocity error that the onset test, against an
/// anchor 0.5 s after the episode, took for a new ramp: 10 s of clean
/// fixes excluded on the 10 Hz ADIS16465 drive).
const SETTLE_SPAN_S: f64 = 4.5;
/// A jump is a ramp's end when the fix is this much closer to the level
/// of the fixes seconds before than to the last one.
const RAMP_END_CLOSER: f64 = 0.5;
/// A jump is compared with an older anchor's level only when it is at
/// least this many of that anchor's σ (Σ Δᵢ²/Vᵢ, V its test's variance):
/// below it the anchor cannot tell the two levels apart.
const RAMP_END_MIN_RESOLUTION: f64 = 1.0;
/// Anchors and ledger entries older than this (s) are dropped.
const MEMORY_S: f64 = 20.0;
/// An INS found drifting in an episode could have built an offset of its
/// drift rate there times the episode and the memory before it, times
/// this: the rate is measured over a few seconds of fixes, and a ramp may
/// have led the INS off for longer than the memory (on the bed, 1 cost
/// correct ramp ends and 2 did not).
const DRIFT_BUILD_MARGIN: f64 = 2.0;
/// An episode longer than this (s) is more than the IMU is trusted to
/// bridge: the fixes are followed again, and the run says so.
pub const MAX_EPISODE_S: f64 = 60.0;
/// The factor K of the horizontal protection level K·σ: 6.0, the SBAS
/// precision-approach factor K_H,PA (RTCA DO-229). Only as good as the
/// filter's covariance (with the measured overconfidence λ applied).
pub const PROTECTION_K: f64 = 6.0;
/// Floor (m, per axis) of the change of a fix's error between two fixes:
/// a receiver's stated σ leaves out its multipath, which even in RTK moves
/// the fixes by centimetres over seconds (dataset2's real fixes: biases of
/// 5–10 cm lasting ~10 s at a stated 1 cm). With it the tests see offsets
/// from about 0.3 m (4.6 σ of the difference of two fixes), the size the
/// issue calls visible.
pub(crate) const FIX_CHANGE_FLOOR_M: f64 = 0.05;
/// How long (s) the clean fix pairs that measure the receiver's error
/// change are kept.
const FIX_CHANGE_MEMORY_S: f64 = 120.0;
/// Clean fix pairs needed before their error change is used instead of
/// the stated σ.
const FIX_CHANGE_MIN_PAIRS: usize = 20;
/// Margin on the measured variance of the fixes' error change: their
/// changes are heavier-tailed than a Gaussian's (comma2k19's u-blox: the
/// 99th percentile of the 1 s change is 2.5 times its RMS), so the test
/// allows twice the measured σ.
const FIX_CHANGE_MARGIN: f64 = 4.0;
/// How often (s) the share of the fixes' error that changes from fix to
/// fix is measured again: a statistic of the last [`FIX_CHANGE_MEMORY_S`],
/// whose six medians added a quarter to a 10 Hz run's time when taken at
/// every fix.
const FIX_SHARE_EVERY_S: f64 = 5.0;
/// Two fixes' stated σ within this ratio are the same solution quality.
const FIX_SAME_SD_RATIO: f64 = 1.1;
/// Median of χ²₁: the variance of a Gaussian is the median of its squares
/// divided by this.
const CHI2_1_MEDIAN: f64 = 0.454_936;
/// Standard gravity (m/s²) for the tilt term of the growth.
const G_MPS2: f64 = 9.8;

/// Why a fix was judged as it was (the `reason` column of
/// `gnss_residuals.txt`).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FaultReason {
    /// Nothing to say.
    #[default]
    None,
    /// It jumped from the last clean fix by more than the INS allows.
    Jump,
    /// It continues an episode opened by a jump or a ramp's onset.
    Run,
    /// Its offset from the INS grew, since a clean fix seconds before,
    /// beyond what the INS can drift: a ramp's onset. The filter returned
    /// to its state after that fix and ran again without the fixes since.
    Ramp,
    /// It repeats the previous fix's position while the vehicle moved.
    Stale,
    /// It continues an episode that lasted until the INS could no longer
    /// tell its offset (the run's notes say why), or longer than the IMU
    /// can bridge: used.
    Persisted,
    /// Beyond the robust weighting's outlier bound (a single wild value).
    Outlier,
    /// Used forward, excluded by the smoother's re-judgement: inconsistent
    /// with the smoothed solution of the other fixes (`crate::rejudge`).
    SmootherExcluded,
    /// Excluded forward, used again after the smoother's re-judgement:
    /// consistent with the smoothed solution (`crate::rejudge`).
    SmootherReadmitted,
}

impl FaultReason {
    /// The word in `gnss_residuals.txt` (`-` for none).
    pub fn word(self) -> &'static str {
        match self {
            FaultReason::None => "-",
            FaultReason::Jump => "jump",
            FaultReason::Run => "run",
            FaultReason::Ramp => "ramp",
            FaultReason::Stale => "stale",
            FaultReason::Persisted => "persisted",
            FaultReason::Outlier => "outlier",
            FaultReason::SmootherExcluded => "smoother-excluded",
            FaultReason::SmootherReadmitted => "smoother-readmitted",
        }
    }
}

/// How a fault episode is classed once closed.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EpisodeClass {
    /// One fix, then back.
    Spike,
    /// Several fixes at a new level (a false fix), then back.
    Run,
    /// A slow drift away.
    Ramp,
    /// Repeated stale outputs.
    Stale,
}

/// How an episode ended.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EpisodeEnd {
    /// The fixes came back to the INS.
    Returned,
    /// The INS could no longer tell the offset (its predicted drift grew
    /// to cover it, or its drift since the episode began passed it); fixes
    /// used again.
    Persisted,
    /// Longer than [`MAX_EPISODE_S`]: more than the IMU can bridge; the
    /// fixes are followed again and the solution in the episode is uncertain.
    Unbridged,
    /// The run ended inside it.
    Open,
}

/// One fault episode (summary.json `integrity.episodes`, the report's
/// timeline).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct FaultEpisode {
    /// GPS seconds of week of its first excluded fix.
    pub start_sow: f64,
    /// GPS seconds of week of its last excluded fix.
    pub end_sow: f64,
    /// Fixes excluded in it.
    pub fixes: usize,
    /// What it was.
    pub class: EpisodeClass,
    /// How it ended.
    pub end: EpisodeEnd,
    /// Largest estimated fault offset (m, 3-D).
    pub max_offset_m: f64,
}

/// A position fix as the monitor judges it: its time, innovation z
/// (predicted − measured, NED, m), the prediction's H P Hᵀ, its stated R
/// (diagonal) and the INS overconfidence λ.
#[derive(Clone, Copy, Debug)]
pub(in crate::fusion) struct FixView {
    time: GpsTime,
    z: Vector3<f64>,
    hph: Matrix3<f64>,
    r: Vector3<f64>,
    lambda: f64,
}

impl FixView {
    pub(in crate::fusion) fn new(
        time: GpsTime,
        z: Vector3<f64>,
        hph: Matrix3<f64>,
        r: Vector3<f64>,
        lambda: f64,
    ) -> Self {
        FixView {
            time,
            z,
            hph,
            r,
            lambda,
        }
    }
}

/// A clean fix that later ones are judged against.
#[derive(Copy, Clone, Debug)]
struct Anchor {
    time: GpsTime,
    /// Used only because the robust weighting judged that the INS had
    /// drifted (disagreeing fixes that agreed with each other), while the
    /// INS was a reference: the fixes were pulling the state away, most
    /// often along a ramp.
    dragged: bool,
    /// Added after [`MIN_ANCHORS`] clean fixes over [`SETTLE_SPAN_S`]
    /// since the start or a reset:
    /// the INS was a reference again. The first clean fixes after an
    /// episode the fixes outlasted follow an INS whose velocity the
    /// episode had led off (its position alone was put back): against
    /// them, the clean fixes after drift like a ramp's onset (a ramp
    /// followed for 23 s on the 1 Hz ADIS16465 drive, then 7 clean fixes
    /// excluded as one).
    settled: bool,
    /// Ledger sequence number after its own position update.
    seq: u64,
    /// Posterior residual r⁺ (predicted after the update − measured, NED).
    residual: Vector3<f64>,
    /// Diagonal of H P⁺ Hᵀ after its update.
    hph_post: Vector3<f64>,
    /// Its stated R (diagonal).
    r: Vector3<f64>,
    /// The state's σ then: velocity (NED, m/s), tilt (rad), yaw (rad),
    /// accelerometer bias (m/s²), horizontal speed (m/s).
    vel_sd: Vector3<f64>,
    tilt_sd: f64,
    yaw_sd: f64,
    accel_bias_sd: f64,
    gyro_bias_sd: f64,
    speed_mps: f64,
}

/// A GNSS correction applied to the state: the change of the predicted
/// position (NED, m) and velocity (m/s).
#[derive(Copy, Clone, Debug)]
struct Correction {
    time: GpsTime,
    seq: u64,
    dpos: Vector3<f64>,
    dvel: Vector3<f64>,
}

/// An open episode.
#[derive(Copy, Clone, Debug)]
struct Episode {
    anchor: Anchor,
    start: GpsTime,
    last: GpsTime,
    fixes: usize,
    /// Δ of its first fix: the fault's level, and the variance per axis
    /// its test divided by.
    level: Vector3<f64>,
    level_var: Vector3<f64>,
    /// Diagonal of H P Hᵀ at its first fix.
    hph_start: Vector3<f64>,
    /// Δ and the diagonal of H P Hᵀ at its last fix that continued it (a
    /// fix that jumped from it is a new fault inside the episode).
    last_delta: Vector3<f64>,
    hph_last: Vector3<f64>,
    max_offset_m: f64,
    /// Opened by a ramp's onset (the fixes drift away; not a level).
    onset: bool,
    /// Whether the last fix judged in it held the level: as sharp as the
    /// anchor (its stated σ the same) and with the one before (the change
    /// of their offsets from the INS within the test)
    /// (`followed::PersistedLevel`).
    steady: bool,
}

impl Episode {
    /// One more excluded fix at `time`, `delta` from the INS.
    fn count(&mut self, time: GpsTime, delta: &Vector3<f64>) {
        self.fixes += 1;
        self.last = time;
        self.max_offset_m = self.max_offset_m.max(delta.norm());
    }
}

/// Why an episode's fixes are followed again ([`Judgement::Persisted`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(in crate::fusion) enum PersistedBy {
    /// The INS's predicted drift since the episode's anchor covers the
    /// fixes' offset.
    DriftCovers,
    /// A ramp's onset: the INS's predicted drift since the anchor outgrew
    /// the fixes' own error change ([`ONSET_HOLD_RATIO`]), so it can no
    /// longer tell a ramp from its own drift.
    OnsetUnresolved,
    /// The fixes' offset wandered past the INS's predicted growth at a
    /// rate that could have built it: the INS drifts.
    InsDrifts,
    /// The INS's drift since the episode began, measured on its fixes
    /// (`drift_m`, horizontal), passed the level it judged (`level_m`).
    InsDriftedPastLevel { drift_m: f64, level_m: f64 },
    /// Longer than [`MAX_EPISODE_S`]: more than the IMU can bridge.
    Unbridged,
}

/// What the monitor says of a fix.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(in crate::fusion) enum Judgement {
    /// Consistent: weigh it as usual.
    Clean,
    /// Excluded, for this reason.
    Exclude(FaultReason),
    /// An episode ended with the fixes still off the old level, the INS
    /// no longer able to tell (or longer than the IMU can bridge): use it,
    /// marked persisted, `by` the reason.
    Persisted {
        by: PersistedBy,
        /// The fix's offset from the state the INS carried (m, NED): the
        /// position variance grows by its square.
        offset: Vector3<f64>,
    },
    /// A jump back to where the fixes were seconds before: the fixes just
    /// before it had drifted away (a ramp the filter followed). Used, with
    /// the position variance grown by the square of `offset`.
    RampEnd { offset: Vector3<f64> },
    /// A jump back that undid the jump opening an episode the fixes were
    /// followed out of: the level followed was a false fix, which began
    /// after the clean fix at `anchor` ([`followed`]); `offset` the fix's
    /// jump. Weighed as any fix is; offline the wrapper returns to the
    /// state after `anchor` and runs again without the fixes since.
    FalseFixEnd {
        anchor: GpsTime,
        offset: Vector3<f64>,
    },
    /// A ramp's onset: excluded, and the fixes since the clean fix at
    /// `anchor` were on the ramp. The filter returns to its state after
    /// that fix and runs again to this one without them (a rollback by
    /// the wrapper, `crate::fusion::rollback`); `offset_m` the fix's offset
    /// from the INS carried from the anchor (3-D).
    Onset { anchor: GpsTime, offset_m: f64 },
}

/// The state's σ at a clean fix, as the monitor needs them.
#[derive(Copy, Clone, Debug, Default)]
pub(in crate::fusion) struct StateSpread {
    pub vel_sd: Vector3<f64>,
    pub tilt_sd: f64,
    pub yaw_sd: f64,
    pub accel_bias_sd: f64,
    pub gyro_bias_sd: f64,
    pub speed_mps: f64,
}

/// A clean fix pair's change of error: Δ² over the pair's stated R + R'
/// (`share`), the variance the INS's drift and the anchor's σ put in Δ over
/// R + R' (`ins_share`), per axis, and the time between the fixes squared
/// (s²; `share` over it is the change per second²).
#[derive(Clone, Copy, Debug)]
struct FixPair {
    time: GpsTime,
    dt2: f64,
    share: Vector3<f64>,
    ins_share: Vector3<f64>,
}

impl FixPair {
    /// Δ² over R + R' per second², on axis `i`.
    fn per_s2(&self, i: usize) -> f64 {
        self.share[i] / self.dt2
    }
}

/// The last fix judged clean against the anchor before it, until it becomes
/// an anchor itself: its Δ, the time between (s), their stated R + R' and
/// the INS's part of Δ's variance (λ·G + H P⁺ Hᵀ of the anchor).
#[derive(Clone, Copy, Debug)]
struct PendingPair {
    time: GpsTime,
    delta: Vector3<f64>,
    dt: f64,
    stated: Vector3<f64>,
    ins_var: Vector3<f64>,
}

/// The episode monitor of the GNSS source.
#[derive(Clone, Debug, Default)]
pub(in crate::fusion) struct FaultMonitor {
    anchors: VecDeque<Anchor>,
    ledger: VecDeque<Correction>,
    seq: u64,
    episode: Option<Episode>,
    /// Closed episodes, in time order.
    pub(in crate::fusion) episodes: Vec<FaultEpisode>,
    /// Accelerometer velocity random walk (m/s/√s), for the growth.
    pub(in crate::fusion) vrw: f64,
    /// Anchors added since the start, a reset or an episode the INS could
    /// not resolve (then the INS is not yet a reference).
    anchors_since_reset: usize,
    /// The first of them.
    first_anchor_since_reset: Option<GpsTime>,
    /// Clean fix pairs' change of error, the last [`FIX_CHANGE_MEMORY_S`].
    fix_change: VecDeque<FixPair>,
    /// Their robust rate (1/s², per axis) once there are
    /// [`FIX_CHANGE_MIN_PAIRS`]: the share of the stated variance by which
    /// the fixes' error changes per second².
    fix_change_rate: Option<Vector3<f64>>,
    /// The share of the stated variance by which the fixes' error changes
    /// from one fix to the next (per axis, robust, the INS's predicted
    /// part taken out, not capped): the part of the error the filter can
    /// average away; and when it was measured (at most once every
    /// [`FIX_SHARE_EVERY_S`]).
    fix_white_share: Option<(GpsTime, Vector3<f64>)>,
    /// The last fix judged clean against the previous anchor, of the same
    /// stated σ; a pair once it becomes an anchor itself.
    pending_pair: Option<PendingPair>,
    /// D of clean fixes against older anchors (the onset test's), the
    /// last [`ONSET_CAL_MEMORY_S`].
    onset_cal: VecDeque<(GpsTime, f64)>,
    /// This fix's largest D in the onset test, until it is found clean
    /// (an anchor not drift-accepted): only then does it calibrate.
    onset_pending: Option<(GpsTime, f64)>,
    /// The onset test's threshold scale from `onset_cal`
    /// ([`Self::recalibrate_onset`]); `None` until it is calibrated.
    onset_scale: Option<f64>,
    /// The onset test runs only where a rollback can follow it (set by
    /// the wrapper: offline, no heading or odometer input to replay).
    pub(in crate::fusion) onset_enabled: bool,
    /// In a rollback's re-run: the fixes after the first time (the
    /// anchor's) up to the second (the onset's) are the ramp's, excluded
    /// as one episode from the anchor.
    replay_onset: Option<(GpsTime, GpsTime)>,
    /// In a ramp end's re-run: the fix that jumped back, which ends the
    /// replayed episode (the fixes before it from `replay_onset`'s anchor
    /// were the ramp's).
    replay_return: Option<GpsTime>,
    /// The replayed episode opened with a jump (a false fix found at its
    /// end), not a ramp's onset.
    replay_jump: bool,
    /// The last episode the fixes were followed out of, while its end may
    /// still come ([`followed`]).
    followed: Option<followed::Followed>,
    /// A jump's episode that persisted, for the wrapper to follow its
    /// level from the jump on ([`followed::PersistedLevel`]; taken by
    /// [`Self::take_persisted_level`]).
    persisted_level: Option<followed::PersistedLevel>,
    /// In such a re-run: the jump whose level is followed at once.
    replay_level: Option<followed::PersistedLevel>,
    /// The clean anchor of the last ramp onset whose episode persisted
    /// (the fixes followed again, the INS no longer the sharper): a jump
    /// after it may be the ramp's end (`fusion/rollback.rs`).
    pub(in crate::fusion) onset_followed: Option<GpsTime>,
    /// The fix judged last jumped from the clean level (a spike, a false
    /// fix's onset, or a ramp's end): the wrapper may judge it against
    /// the INS run free from seconds back ([`Self::take_jump`]).
    jumped: bool,
    /// The fix judged last jumped again inside an episode (a new fault
    /// in it, or a ramp's end after its onset): the episode's start
    /// ([`Self::take_jump_in_episode`]).
    jumped_in_episode: Option<GpsTime>,
    /// The last fix judged, and whether the one judged now came within
    /// [`JUMP_MAX_GAP_S`] of it.
    last_judged: Option<GpsTime>,
    fixes_continuous: bool,
    /// The first fix after the last gap in the fixes: no onset test
    /// reaches back past it.
    gap_end: Option<GpsTime>,
}

/// What an update's correction `dx` moved the position (at `pos`) and
/// the velocity (at `vel`) by (error-state convention: the state moves by
/// −dx); none when `dx` is shorter.
pub(in crate::fusion) fn state_change(
    dx: &[f64],
    pos: usize,
    vel: usize,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if dx.len() < pos.max(vel) + 3 {
        return None;
    }
    Some((
        -Vector3::new(dx[pos], dx[pos + 1], dx[pos + 2]),
        -Vector3::new(dx[vel], dx[vel + 1], dx[vel + 2]),
    ))
}

impl FaultMonitor {
    pub(in crate::fusion) fn new(vrw: f64) -> Self {
        FaultMonitor {
            vrw,
            ..Default::default()
        }
    }

    /// Forgets everything judged against (after a re-initialisation, or a
    /// covariance inflation: the INS is no longer the reference it was).
    pub(in crate::fusion) fn reset(&mut self) {
        self.restart_anchors();
        self.ledger.clear();
        // A level followed before it is no reference for a jump after it.
        self.followed = None;
        self.onset_followed = None;
        self.persisted_level = None;
        if let Some(ep) = self.episode.take() {
            self.close(ep, EpisodeEnd::Returned);
        }
    }

    /// Forgets the anchors, and counts the clean fixes that make the INS
    /// a reference again from none ([`Anchor::settled`]).
    fn restart_anchors(&mut self) {
        self.anchors.clear();
        self.anchors_since_reset = 0;
        self.first_anchor_since_reset = None;
    }

    /// Records a GNSS correction `dx` (error-state convention: the state
    /// moves by −dx) with position at `pos` and velocity at `vel`.
    pub(in crate::fusion) fn record_correction(
        &mut self,
        time: GpsTime,
        dx: &[f64],
        pos: usize,
        vel: usize,
    ) {
        let Some((dpos, dvel)) = state_change(dx, pos, vel) else {
            return;
        };
        self.seq += 1;
        self.ledger.push_back(Correction {
            time,
            seq: self.seq,
            dpos,
            dvel,
        });
    }

    /// Remembers a clean, used fix as an anchor (after its position
    /// update, before its velocity update); `drift_accepted`: used only
    /// because the robust weighting judged the INS drifted. (While the INS
    /// is not yet a reference, after a start or an unresolved episode,
    /// that is the INS catching up, not being dragged.)
    pub(in crate::fusion) fn add_anchor(
        &mut self,
        time: GpsTime,
        residual: Vector3<f64>,
        hph_post: Vector3<f64>,
        r: Vector3<f64>,
        spread: StateSpread,
        drift_accepted: bool,
    ) {
        let dragged = drift_accepted && self.anchors_since_reset >= MIN_ANCHORS;
        if let Some(pair) = self.pending_pair.take()
            && pair.time == time
            && !drift_accepted
        {
            self.note_fix_change(&pair);
        }
        // One calibration value per anchor spacing: fixes at 10 Hz test
        // nearly the same thing ten times a second, and each value costs
        // a recalibration.
        if let Some((t, d)) = self.onset_pending.take()
            && t == time
            && !drift_accepted
            && self
                .onset_cal
                .back()
                .is_none_or(|(last, _)| time.seconds_since(*last) >= ONSET_ANCHOR_SPACING_S)
        {
            self.onset_cal.push_back((time, d));
            while self
                .onset_cal
                .front()
                .is_some_and(|(t, _)| time.seconds_since(*t) > ONSET_CAL_MEMORY_S)
            {
                self.onset_cal.pop_front();
            }
            self.recalibrate_onset();
        }
        let first = *self.first_anchor_since_reset.get_or_insert(time);
        let settled =
            self.anchors_since_reset >= MIN_ANCHORS && time.seconds_since(first) >= SETTLE_SPAN_S;
        self.anchors_since_reset += 1;
        self.anchors.push_back(Anchor {
            time,
            dragged,
            settled,
            seq: self.seq,
            residual,
            hph_post,
            r,
            vel_sd: spread.vel_sd,
            tilt_sd: spread.tilt_sd,
            yaw_sd: spread.yaw_sd,
            accel_bias_sd: spread.accel_bias_sd,
            gyro_bias_sd: spread.gyro_bias_sd,
            speed_mps: spread.speed_mps,
        });
        while self
            .anchors
            .front()
            .is_some_and(|a| time.seconds_since(a.time) > MEMORY_S)
            && self.anchors.len() > 1
        {
            self.anchors.pop_front();
        }
        if let Some(oldest) = self.anchors.front().map(|a| a.seq) {
            while self.ledger.front().is_some_and(|c| c.seq <= oldest) {
                self.ledger.pop_front();
            }
        }
    }

    /// The change GNSS updates after `a` made to the predicted position at
    /// `time` (their position corrections, and velocity corrections
    /// carried over the time since).
    fn ledger_since(&self, a: &Anchor, time: GpsTime) -> Vector3<f64> {
        self.ledger
            .iter()
            .filter(|k| k.seq > a.seq)
            .map(|k| k.dpos + k.dvel * time.seconds_since(k.time).max(0.0))
            .sum()
    }

    /// The free INS's position error variance grown since `a` (diagonal,
    /// NED), Titterton & Weston §12.3.
    fn growth(&self, a: &Anchor, dt: f64) -> Vector3<f64> {
        let dt = dt.max(0.0);
        let t2 = dt * dt;
        let quartic = 0.25 * t2 * t2;
        let tilt = G_MPS2 * a.tilt_sd;
        // A gyro bias tilts the platform (g·b·t³/6) and turns the heading
        // (v·b·t²/2).
        let tilt_drift = G_MPS2 * a.gyro_bias_sd * dt * t2 / 6.0;
        let heading = a.speed_mps * dt * a.yaw_sd + 0.5 * a.speed_mps * a.gyro_bias_sd * t2;
        let vrw = self.vrw * self.vrw * dt * t2 / 3.0;
        let ab = a.accel_bias_sd * a.accel_bias_sd * quartic;
        let h = |i: usize| {
            a.vel_sd[i] * a.vel_sd[i] * t2
                + (tilt * tilt) * quartic
                + ab
                + vrw
                + tilt_drift * tilt_drift
                + 0.5 * heading * heading
        };
        Vector3::new(h(0), h(1), a.vel_sd[2] * a.vel_sd[2] * t2 + ab + vrw)
    }

    /// Δ, D and the variance per axis D divides by, of a fix against
    /// anchor `a`.
    fn test(&self, a: &Anchor, fix: &FixView) -> (Vector3<f64>, f64, Vector3<f64>) {
        let (time, z, hph, r, lambda) = (fix.time, &fix.z, &fix.hph, &fix.r, fix.lambda);
        let dt = time.seconds_since(a.time);
        let c = self.ledger_since(a, time);
        let delta = z - c - a.residual;
        let g = self.ins_growth(a, dt, hph);
        let fixes = self.fix_change_var(r, &a.r, dt);
        let v = Vector3::from_fn(|i, _| {
            (lambda * g[i] + a.hph_post[i] + fixes[i]).max(f64::MIN_POSITIVE)
        });
        let d: f64 = (0..3).map(|i| delta[i] * delta[i] / v[i]).sum();
        (delta, d, v)
    }

    /// The INS's position error variance grown since anchor `a`, `dt` s
    /// back, per axis (m², before the overconfidence λ); `hph` the
    /// predicted H P Hᵀ now.
    fn ins_growth(&self, a: &Anchor, dt: f64, hph: &Matrix3<f64>) -> Vector3<f64> {
        // With no GNSS update since A, the filter's H P Hᵀ grew from A's
        // alone: that is the free INS's growth under its own model, the
        // tilt and the accelerometer bias with their correlation (which
        // `growth`, from σ alone, leaves out: for a MEMS IMU whose bias
        // the fixes have not separated from the tilt it overstates the
        // drift several times, and let a 9 m false fix pass as drift after
        // 7 s). After updates, H P Hᵀ no longer holds it: the model's
        // growth from A's σ, or the filter's if larger.
        // (The ledger is in the order of its sequence numbers.)
        let free = self.ledger.back().is_none_or(|k| k.seq <= a.seq);
        let mut g = if free {
            Vector3::zeros()
        } else {
            self.growth(a, dt)
        };
        for i in 0..3 {
            g[i] = g[i].max(hph[(i, i)] - a.hph_post[i]);
        }
        g
    }

    /// The variance (m², per axis) of the change of the fixes' error over
    /// `dt` s between a fix of stated R `r` and one of `r_then`. Two
    /// independent draws would give r + r_then, but a receiver's error is
    /// correlated in time: over a second, a standalone or DGNSS fix at a
    /// stated 2 m moves by centimetres to decimetres, and a 12 m jump
    /// passes a test built on the stated σ (4.2 σ of the difference).
    /// So the change is measured on clean fix pairs (Δ of a fix against
    /// the anchor just before it, INS drift included, so the measure errs
    /// large), as a share ρ² of their stated R + R' per second²: the
    /// errors are smooth, and their change grows about linearly with the
    /// time between over the seconds a jump test spans (comma2k19's u-blox
    /// against the reference: RMS 0.014, 0.10, 0.18, 0.38 m over 0.1, 1,
    /// 2, 5 s), and a receiver's worse fixes (float, DGNSS) move by more
    /// than its best. The variance is (r + r_then)·min(1,
    /// [`FIX_CHANGE_MARGIN`]·ρ²·dt²), at least the floor of
    /// [`FIX_CHANGE_FLOOR_M`] per fix: a time-differenced test of the fixes
    /// (Joerger & Pervan 2013) with their differenced noise measured
    /// rather than assumed white. RTK fixes whose multipath moves them by
    /// more than their stated σ keep the stated variance and the floor.
    /// Only between fixes of the same stated σ (within
    /// [`FIX_SAME_SD_RATIO`]): a receiver whose σ changes has changed its
    /// solution (satellites lost or gained, a fix type), and its error
    /// may then move by all it states (the ArduCopter log's last second,
    /// σ 0.8 → 2.1 m and the fix 1.8 m down).
    fn fix_change_var(&self, r: &Vector3<f64>, r_then: &Vector3<f64>, dt: f64) -> Vector3<f64> {
        let floor = 2.0 * FIX_CHANGE_FLOOR_M * FIX_CHANGE_FLOOR_M;
        Vector3::from_fn(|i, _| {
            let share = self
                .fix_change_rate
                .filter(|_| same_sd(r[i], r_then[i]))
                .map_or(1.0, |q| (FIX_CHANGE_MARGIN * q[i] * dt * dt).min(1.0));
            ((r[i] + r_then[i]) * share).max(floor)
        })
    }

    /// Keeps a clean pair's change of error and updates the measured rate
    /// (per axis, the median of Δ²/(stated·dt²) over [`CHI2_1_MEDIAN`]) and
    /// the white share (the median of Δ²/stated over it, less the INS's
    /// part).
    fn note_fix_change(&mut self, pair: &PendingPair) {
        let PendingPair {
            time,
            delta,
            dt,
            stated,
            ins_var,
        } = *pair;
        let new = FixPair {
            time,
            dt2: dt * dt,
            share: Vector3::from_fn(|i, _| delta[i] * delta[i] / stated[i]),
            ins_share: ins_var.component_div(&stated),
        };
        let finite = (0..3).all(|i| {
            new.per_s2(i).is_finite() && new.share[i].is_finite() && new.ins_share[i].is_finite()
        });
        if !finite {
            return;
        }
        self.fix_change.push_back(new);
        while self
            .fix_change
            .front()
            .is_some_and(|p| time.seconds_since(p.time) > FIX_CHANGE_MEMORY_S)
        {
            self.fix_change.pop_front();
        }
        if self.fix_change.len() < FIX_CHANGE_MIN_PAIRS {
            self.fix_change_rate = None;
            self.fix_white_share = None;
            return;
        }
        let mut axis: Vec<f64> = Vec::with_capacity(self.fix_change.len());
        let pairs = &self.fix_change;
        self.fix_change_rate = Some(Vector3::from_fn(|i, _| {
            variance_of(pairs, &mut axis, |p| p.per_s2(i))
        }));
        if self
            .fix_white_share
            .is_some_and(|(t, _)| time.seconds_since(t) < FIX_SHARE_EVERY_S)
        {
            return;
        }
        // Var Δ = the INS's part + the fixes' change: the latter's share is
        // Δ²'s less the INS's (each robust; the INS's is a variance, not a
        // square, hence the χ²₁ median put back).
        let white = Vector3::from_fn(|i, _| {
            variance_of(pairs, &mut axis, |p| p.share[i])
                - CHI2_1_MEDIAN * variance_of(pairs, &mut axis, |p| p.ins_share[i])
        });
        self.fix_white_share = Some((time, white));
    }

    /// The share of the fixes' stated variance that does not change from
    /// one clean fix to the next (per axis, 0–1): an error correlated over
    /// longer than the fixes' spacing, which a filter taking the fixes as
    /// independent cannot average away (`fusion::fix_correlation`). `None`
    /// until [`FIX_CHANGE_MIN_PAIRS`] clean pairs measured it. The pairs'
    /// Δ carries the INS's drift between them too, taken out at its
    /// predicted variance: where the INS drifts less than its model says
    /// (or the fixes change less than their σ), the share errs large, the
    /// safe side.
    pub(in crate::fusion) fn correlated_fix_share(&self) -> Option<Vector3<f64>> {
        self.fix_white_share
            .map(|(_, w)| w.map(|w| (1.0 - w).clamp(0.0, 1.0)))
    }

    /// Judges a position fix: innovation `z`, predicted H P Hᵀ `hph`,
    /// stated R diagonal `r`, the INS overconfidence `lambda` (≥ 1).
    pub(in crate::fusion) fn judge(
        &mut self,
        time: GpsTime,
        z: &Vector3<f64>,
        hph: &Matrix3<f64>,
        r: &Vector3<f64>,
        lambda: f64,
    ) -> Judgement {
        let fix = FixView::new(time, *z, *hph, *r, lambda.max(1.0));
        let judgement = self.judge_fix(&fix);
        self.follow_replayed_level(time, judgement)
    }

    /// [`Self::judge`] of the fix as the monitor sees it.
    fn judge_fix(&mut self, fix: &FixView) -> Judgement {
        let (time, hph, r) = (fix.time, &fix.hph, &fix.r);
        self.fixes_continuous = self
            .last_judged
            .is_some_and(|t| time.seconds_since(t) <= JUMP_MAX_GAP_S);
        if !self.fixes_continuous {
            self.gap_end = Some(time);
        }
        self.last_judged = Some(time);
        if let Some(end) = self.replay_return
            && time >= end
        {
            self.replay_return = None;
            self.replay_onset = None;
            self.replay_jump = false;
            if let Some(ep) = self.episode.take() {
                self.close(ep, EpisodeEnd::Returned);
                // Back from a false fix or a ramp: weighed as any fix back
                // at the clean level is, by the free INS's own predicted
                // drift. Its position variance grown to fit the offset
                // (as the monitor's own ramp end does) cut the smoother's
                // bridge there: a 23 s ramp's, 0.015 → 0.047 m smoothed
                // on the 10 Hz ADIS16465 drive (bed seed 5), forward
                // within millimetres either way.
                // The INS coasted through the episode, as through a gap:
                // it is a reference again only once anchors settle after
                // it ([`Anchor::settled`]).
                self.restart_anchors();
                return Judgement::Clean;
            }
        }
        if let Some((anchor, until)) = self.replay_onset {
            if time > anchor && time <= until {
                return self.replay_ramp_fix(fix);
            }
            if time > until {
                self.replay_onset = None;
            }
        }
        if let Some(ep) = self.episode {
            return self.judge_in_episode(ep, fix);
        }
        if let Some(end) = self.false_fix_end(fix) {
            return end;
        }
        let threshold = fix_test_threshold();
        // The INS becomes a reference again only after a few clean fixes
        // in a row (at the start, after a re-initialisation or an episode
        // it could not resolve): an INS that just left its model would
        // otherwise flip between excluding and following.
        if self.anchors_since_reset < MIN_ANCHORS {
            return Judgement::Clean;
        }
        let Some(last) = self.anchors.back().copied() else {
            return Judgement::Clean;
        };
        // Over a gap the INS is no longer a sharp relative reference (a
        // MEMS INS drifts past its σ through gaps): the robust weighting
        // judges such a fix alone.
        if time.seconds_since(last.time) > JUMP_MAX_GAP_S {
            // …unless the fixes since were there but refused by the robust
            // weighting (a ramp past its gate): the onset test still
            // reaches back to the clean fixes before them.
            if self.onset_enabled
                && let Some(onset) = self.ramp_onset(fix)
            {
                return onset;
            }
            return Judgement::Clean;
        }
        let (delta, d, v) = self.test(&last, fix);
        if d > threshold {
            self.jumped = true;
            // Back to the level of the fixes seconds before? Then those
            // since drifted away (a ramp the filter followed) and this one
            // is the good one. It must be much closer to the old level than
            // to the last (a false fix's onset is as far from both)...
            // unless the fixes since had dragged the INS (the robust
            // weighting took their pull for INS drift): then the last
            // level is the suspect one, and the INS's own distance from
            // the old level is no longer a measure of it (a MEMS INS
            // dragged along a ramp drifts metres from an anchor 20 s back;
            // measured on the bed, such jumps were all ramp ends).
            let dragged = self.anchors.iter().any(|a| a.dragged);
            //
            // "Closer" means something only where the old anchor can tell
            // the two levels apart: the jump at least its σ there. An INS
            // whose drift since the anchor is metres wide places any fix
            // near the old level (comma2k19 with the IMU alone: a 30 m
            // spike, against an anchor 20 s back at σ 151 m, was followed
            // as a ramp's end).
            if let Some((old, d_old, delta_old, v_old)) = self.back_to_older(fix, &last)
                && d_old <= threshold
                && (dragged
                    || (delta_old.norm() < RAMP_END_CLOSER * delta.norm()
                        && (0..3).map(|i| delta[i] * delta[i] / v_old[i]).sum::<f64>()
                            >= RAMP_END_MIN_RESOLUTION))
            {
                self.episodes.push(FaultEpisode {
                    start_sow: old.sow(),
                    end_sow: time.sow(),
                    fixes: 0,
                    class: EpisodeClass::Ramp,
                    end: EpisodeEnd::Returned,
                    max_offset_m: delta.norm(),
                });
                self.anchors.clear();
                // Should a later jump undo this one, it was a false fix's
                // onset, not a ramp's end.
                self.followed = Some(followed::Followed {
                    anchor: last.time,
                    start: time,
                    followed_from: time,
                    level: delta,
                    level_var: v,
                    min_held: followed::LEVEL_HELD_MIN_FIXES,
                });
                return Judgement::RampEnd { offset: delta };
            }
            self.open(last, time, delta, v, hph, false);
            return Judgement::Exclude(FaultReason::Jump);
        }
        if self.onset_enabled
            && let Some(onset) = self.ramp_onset(fix)
        {
            return onset;
        }
        // A pair measures the receiver's error change only between fixes of
        // the same stated σ (see `fix_change_var`).
        if (0..3).all(|i| same_sd(r[i], last.r[i])) {
            let dt = time.seconds_since(last.time);
            self.pending_pair = Some(PendingPair {
                time,
                delta,
                dt,
                stated: r + last.r,
                ins_var: v - self.fix_change_var(r, &last.r, dt),
            });
        }
        Judgement::Clean
    }

    /// Judges a fix inside the open episode `ep` (see the module's notes):
    /// back at the clean level, the INS no longer able to tell, the fixes
    /// followed again, a new fault inside it, or the episode continued.
    fn judge_in_episode(&mut self, mut ep: Episode, fix: &FixView) -> Judgement {
        let (time, hph, r, lambda) = (fix.time, &fix.hph, &fix.r, fix.lambda);
        // An onset's episode is judged with the onset test's calibrated
        // threshold: its anchor is seconds back.
        let threshold = if ep.onset {
            fix_test_threshold() * self.onset_scale.unwrap_or(1.0)
        } else {
            fix_test_threshold()
        };
        let (delta, d, _) = self.test(&ep.anchor, fix);
        let hph_diag = hph.diagonal();
        let step = delta - ep.last_delta;
        let step_fixes = self.fix_change_var(r, &ep.anchor.r, time.seconds_since(ep.last));
        let d_step = offset_change_statistic(&step, &hph_diag, &ep.hph_last, &step_fixes, lambda);
        ep.steady = d_step <= threshold && (0..3).all(|i| same_sd(r[i], ep.anchor.r[i]));
        // An onset's episode holds only while the INS is the sharper
        // reference, as when the onset was found: once its drift since the
        // anchor outgrows the fixes' own error change, it can no longer
        // tell a ramp from its own drift (a MEMS INS held 50 s from a fix
        // on a ramp's start coasted 20 m off on the test-track drive), and
        // the fixes are followed again.
        if ep.onset && !self.ins_within(&ep.anchor, fix, ONSET_HOLD_RATIO) {
            return self.end_unresolved(ep, PersistedBy::OnsetUnresolved, time, delta);
        }
        if d <= threshold {
            // Back at the clean level, or the INS can no longer tell.
            let returned = delta.norm() <= (delta - ep.level).norm();
            self.episode = None;
            if returned {
                self.close(ep, EpisodeEnd::Returned);
                return Judgement::Clean;
            }
            return self.end_unresolved(ep, PersistedBy::DriftCovers, time, delta);
        }
        // A fix that jumped from the episode's last one by more than the
        // whole offset so far, and not back toward the INS (the fault
        // ending while the INS drifted), is a new fault inside the episode
        // (a spike during a false fix; an INS that drifts fast, even
        // quadratically, moves the offset by less than it already is):
        // excluded, and no evidence on the INS's drift (taken for
        // drift, a 45 m spike 29 s into an episode was followed). The
        // next fix is compared with it: one that holds the new level
        // is judged as the episode's fixes are.
        let horizontal = |v: &Vector3<f64>| v[0].hypot(v[1]);
        // A jump that undoes the one that opened the episode is the fixes
        // coming back, however far the INS drifted from them meanwhile
        // (an ICM-20602 run free for 10 s: 0.97 m past its λ-scaled
        // growth, and the clean fixes after a 1.5 m false fix were
        // excluded for 17 s more, 1.025 m RMS against the oracle's
        // 0.098 m): [`followed`]'s test on the episode's two edges.
        if !ep.onset && d_step > threshold {
            let step_var = Vector3::from_fn(|i, _| {
                lambda * (hph_diag[i] - ep.hph_last[i]).max(0.0) + step_fixes[i]
            });
            if followed::undoes(&step, &step_var, &ep.level, &ep.level_var) {
                self.episode = None;
                self.close(ep, EpisodeEnd::Returned);
                return Judgement::Clean;
            }
        }
        let new_fault = d_step > threshold
            && horizontal(&step) > horizontal(&ep.last_delta)
            && horizontal(&delta) >= RAMP_END_CLOSER * horizontal(&ep.last_delta);
        ep.last_delta = delta;
        ep.hph_last = hph_diag;
        if new_fault {
            ep.count(time, &delta);
            self.episode = Some(ep);
            self.jumped_in_episode = Some(ep.start);
            return Judgement::Exclude(FaultReason::Jump);
        }
        // A false fix holds its level; fixes whose offset from the INS
        // wanders beyond what the INS's growth since the episode began
        // allows show an INS that drifts (one the fixes before had led
        // off, e.g. along a ramp): it is no reference, follow the
        // fixes... if it could have drifted that far. At the rate it
        // drifts from the fixes in the episode, over the episode and
        // the memory before it, the INS builds an offset of a ramp's
        // size; not one of metres more (a false fix early in a drive,
        // whose INS drifts faster than its model but by decimetres).
        let moved = delta - ep.level;
        // The fixes since the episode's first are off by a constant (a
        // false fix) or right (a ramp's end): either way the change of
        // their offset from the INS is the INS's own drift since. Once
        // that is more than the level it judges, the INS is no nearer
        // the truth than the fixes it refuses, whatever its model says:
        // coasting on it costs more than following them, and a false
        // fix's end, a jump back, is still watched for ([`followed`]).
        // (An ICM-20602 led along a ramp, at its end, refused the fixes
        // back 1.5 m away for 19 s while it drifted to 4.3 m off, within
        // its predicted growth.)
        if !ep.onset && horizontal(&moved) > horizontal(&ep.level) {
            let by = PersistedBy::InsDriftedPastLevel {
                drift_m: horizontal(&moved),
                level_m: horizontal(&ep.level),
            };
            return self.end_unresolved(ep, by, time, delta);
        }
        let level_fixes = self.fix_change_var(r, &ep.anchor.r, time.seconds_since(ep.start));
        let d_level =
            offset_change_statistic(&moved, &hph_diag, &ep.hph_start, &level_fixes, lambda);
        let episode_s = time.seconds_since(ep.start).max(1.0);
        let could_build_m =
            DRIFT_BUILD_MARGIN * horizontal(&moved) / episode_s * (episode_s + MEMORY_S);
        // (An onset's episode is a drift away by its nature, and the onset
        // test has already weighed it against the INS's drift.)
        if !ep.onset && d_level > threshold && horizontal(&delta) <= could_build_m {
            return self.end_unresolved(ep, PersistedBy::InsDrifts, time, delta);
        }
        if time.seconds_since(ep.start) > MAX_EPISODE_S {
            self.ledger.clear();
            return self.end_unresolved(ep, PersistedBy::Unbridged, time, delta);
        }
        ep.count(time, &delta);
        self.episode = Some(ep);
        Judgement::Exclude(FaultReason::Run)
    }

    /// Whether the fix judged last jumped from the clean level (cleared
    /// by the call).
    pub(in crate::fusion) fn take_jump(&mut self) -> bool {
        std::mem::take(&mut self.jumped)
    }

    /// The start of the episode the fix judged last jumped inside, if it
    /// did (cleared by the call).
    pub(in crate::fusion) fn take_jump_in_episode(&mut self) -> Option<GpsTime> {
        self.jumped_in_episode.take()
    }

    /// The oldest anchor at least [`RAMP_END_MIN_LAG_S`] before `time` (and
    /// older than `last`), with D of the fix against it, its Δ and the
    /// test's variance per axis.
    fn back_to_older(
        &self,
        fix: &FixView,
        last: &Anchor,
    ) -> Option<(GpsTime, f64, Vector3<f64>, Vector3<f64>)> {
        let time = fix.time;
        let a = self
            .anchors
            .iter()
            .find(|a| a.seq < last.seq && time.seconds_since(a.time) >= RAMP_END_MIN_LAG_S)?;
        let (delta, d, v) = self.test(a, fix);
        Some((a.time, d, delta, v))
    }

    /// Ends `ep` with the fixes followed again from the one at `time`
    /// (`by` why: persisted or unbridged): the INS is no reference until
    /// clean fixes rebuild it. A persisted level that a later jump undoes
    /// was a false fix ([`followed`]).
    fn end_unresolved(
        &mut self,
        ep: Episode,
        by: PersistedBy,
        time: GpsTime,
        delta: Vector3<f64>,
    ) -> Judgement {
        let end = if by == PersistedBy::Unbridged {
            EpisodeEnd::Unbridged
        } else {
            EpisodeEnd::Persisted
        };
        self.episode = None;
        self.close(ep, end);
        if end == EpisodeEnd::Persisted {
            if ep.onset {
                self.onset_followed = Some(ep.anchor.time);
            } else {
                self.followed = Some(followed::Followed::from_episode(&ep, time));
                self.persisted_level = followed::PersistedLevel::of(self, &ep, by);
            }
        }
        self.restart_anchors();
        Judgement::Persisted { by, offset: delta }
    }

    fn open(
        &mut self,
        anchor: Anchor,
        time: GpsTime,
        delta: Vector3<f64>,
        delta_var: Vector3<f64>,
        hph: &Matrix3<f64>,
        onset: bool,
    ) {
        let hph_diag = hph.diagonal();
        self.episode = Some(Episode {
            hph_start: hph_diag,
            anchor,
            start: time,
            last: time,
            fixes: 1,
            level: delta,
            level_var: delta_var,
            last_delta: delta,
            hph_last: hph_diag,
            max_offset_m: delta.norm(),
            onset,
            steady: true,
        });
    }

    fn close(&mut self, ep: Episode, end: EpisodeEnd) {
        let class = if ep.onset {
            EpisodeClass::Ramp
        } else if ep.fixes == 1 {
            EpisodeClass::Spike
        } else {
            EpisodeClass::Run
        };
        self.episodes.push(FaultEpisode {
            start_sow: ep.start.sow(),
            end_sow: ep.last.sow(),
            fixes: ep.fixes,
            class,
            end,
            max_offset_m: ep.max_offset_m,
        });
    }

    /// Records a stale fix (a one-fix episode of its own class, or one
    /// more in the stale episode just before).
    pub(in crate::fusion) fn note_stale(&mut self, time: GpsTime) {
        if let Some(last) = self.episodes.last_mut()
            && last.class == EpisodeClass::Stale
            && time.sow() - last.end_sow <= 2.5
            && time.sow() >= last.end_sow
        {
            last.end_sow = time.sow();
            last.fixes += 1;
            return;
        }
        self.episodes.push(FaultEpisode {
            start_sow: time.sow(),
            end_sow: time.sow(),
            fixes: 1,
            class: EpisodeClass::Stale,
            end: EpisodeEnd::Returned,
            max_offset_m: 0.0,
        });
    }

    /// The closed episodes and the open one (marked open).
    pub(in crate::fusion) fn all_episodes(&self) -> Vec<FaultEpisode> {
        let mut v = self.episodes.clone();
        if let Some(ep) = self.episode {
            let mut m = self.clone();
            m.episodes.clear();
            m.close(ep, EpisodeEnd::Open);
            v.extend(m.episodes);
        }
        v.sort_by(|a, b| a.start_sow.total_cmp(&b.start_sow));
        v
    }
}

/// The median of `pick` over `pairs` divided by χ²₁'s median: the
/// variance of a Gaussian whose squares `pick` gives, robustly (`axis` is
/// scratch space).
fn variance_of(
    pairs: &VecDeque<FixPair>,
    axis: &mut Vec<f64>,
    pick: impl Fn(&FixPair) -> f64,
) -> f64 {
    axis.clear();
    axis.extend(pairs.iter().map(pick));
    let mid = axis.len() / 2;
    let (_, median, _) = axis.select_nth_unstable_by(mid, f64::total_cmp);
    *median / CHI2_1_MEDIAN
}

/// Whether two stated variances are of the same σ, within
/// [`FIX_SAME_SD_RATIO`].
fn same_sd(var_a: f64, var_b: f64) -> bool {
    let ratio2 = FIX_SAME_SD_RATIO * FIX_SAME_SD_RATIO;
    var_a <= ratio2 * var_b && var_b <= ratio2 * var_a
}

/// D of a change of a fix's offset from the INS (`change`, NED) against
/// the INS's growth since (H P Hᵀ's diagonal now and then, times the
/// overconfidence `lambda`) and the variance of the fixes' error change
/// over the time between (`fixes`, [`FaultMonitor::fix_change_var`]):
/// Σ change_i² / (λ·g_i + fixes_i).
fn offset_change_statistic(
    change: &Vector3<f64>,
    hph_now: &Vector3<f64>,
    hph_then: &Vector3<f64>,
    fixes: &Vector3<f64>,
    lambda: f64,
) -> f64 {
    (0..3)
        .map(|i| {
            let growth = (hph_now[i] - hph_then[i]).max(0.0);
            change[i] * change[i] / (lambda * growth + fixes[i])
        })
        .sum()
}

#[cfg(test)]
mod tests;
