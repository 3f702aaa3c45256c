//! Aid source: GNSS position and velocity fixes. The observation models
//! (antenna lever arm: KF-GINS algorithm document, `filter/gnss.rs`; the
//! Gauss–Markov error states; τ's columns from `time_offset.rs`), validity
//! checks, the χ² gate with its reopening rule, robust (IGG-III / Huber)
//! down-weighting and the drift acceptance after an outage.
//!
//! Position and velocity are one source: a fix's velocity row is fused
//! only after its position was used, with the same held states.

use super::integrity::{
    FaultMonitor, FaultReason, FixView, Judgement, PROTECTION_K, PersistedBy, StateSpread,
};
use super::*;
use crate::filter::idx;
use crate::fusion::jump_doubt::JumpInEpisode;
use crate::fusion::rollback::{JumpCheck, Rollback};
use std::collections::VecDeque;

mod free_ins;
mod stale;

pub(in crate::fusion) use free_ins::{
    FreeIns, fix_difference_3sd_m, free_drift_sd_m, free_drift_variance,
};
use stale::RepeatStart;

/// A GNSS position fix the gate rejected (or robust weighting rejected or
/// down-weighted): its innovation and noise, and the NIS ratio (NIS /
/// gate) of the first rejection of its run.
#[derive(Clone)]
struct RejectedFix {
    time: GpsTime,
    /// Innovation; for a fix that was used down-weighted, what was left of
    /// it after the update (z⁺ = R' S⁻¹ z).
    z: Vec<f64>,
    r: Mat,
    first_ratio: f64,
}

/// Largest stated GNSS σ (m or m/s) taken at face value: beyond it a fix
/// carries no usable information and is refused with a diagnostic.
pub const MAX_GNSS_SD_M: f64 = 1000.0;

/// Why a fix cannot be used at all, if so: non-finite values, σ that are
/// not positive, or σ beyond [`MAX_GNSS_SD_M`].
pub(in crate::fusion) fn invalid_fix(fix: &GnssFix) -> Option<String> {
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

/// Whether `obs` (time `time`, innovation covariance `s`) continues the
/// straight line through the two earlier fixes' innovations `a` and `b`:
/// the INS's velocity drifted (its position error grows linearly), which
/// consecutive innovations that agree with each other cannot show. The
/// difference from the extrapolation z_b + α(z_b − z_a),
/// α = (t − t_b)/(t_b − t_a), passes the χ² `threshold` with covariance
/// S + (1+α)² R_b + α² R_a.
fn extrapolation_agrees(
    a: &RejectedFix,
    b: &RejectedFix,
    obs: &Observation,
    time: GpsTime,
    s: &Mat,
    threshold: f64,
) -> bool {
    let span = b.time.seconds_since(a.time);
    if a.z.len() != obs.z.len() || b.z.len() != obs.z.len() || span <= 0.0 {
        return false;
    }
    let alpha = time.seconds_since(b.time) / span;
    let mut c = s.clone();
    for ((x, rb), ra) in c.data.iter_mut().zip(&b.r.data).zip(&a.r.data) {
        *x += (1.0 + alpha).powi(2) * rb + alpha * alpha * ra;
    }
    let d: Vec<f64> = (0..obs.z.len())
        .map(|i| obs.z[i] - (b.z[i] + alpha * (b.z[i] - a.z[i])))
        .collect();
    nis_of(&c, &d).is_some_and(|chi2| chi2 <= threshold)
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
/// Robust weighting: this many fixes in a row (none more than
/// [`CONSISTENCY_MAX_GAP_S`] apart) down-weighted or rejected, agreeing
/// with each other or not, are taken as an INS that left its model (a
/// drift that accelerates, a wrong initial attitude or error model),
/// even within the cooldown: a GNSS fault that long is one KF-GINS would
/// have followed from the start, while an INS left alone against a stream
/// of good fixes drifts without bound.
const PERSISTENT_DISAGREEMENT: usize = 10;
/// Fixes whose overconfidence ratios are kept; their median is the
/// robust weighting's INS σ scale.
const OVERCONFIDENCE_WINDOW: usize = 15;
/// Ratios needed before the overconfidence scale is used.
const MIN_OVERCONFIDENCE_FIXES: usize = 3;
/// Largest covariance inflation of one drift acceptance.
const MAX_INFLATION: f64 = 100.0;

/// Control state of the GNSS source: the gate and its run of
/// rejections, the robust weighting's noise scales and residuals, the
/// last fix used.
#[derive(Clone, Default)]
pub(in crate::fusion) struct GnssSource {
    /// The χ² gate (3 degrees of freedom) when gating is on.
    gate: Option<f64>,
    consecutive_rejects: usize,
    /// The last fix rejected by the gate in the current run of rejections.
    last_rejected: Option<RejectedFix>,
    /// When a fix over the gate was last accepted as INS drift.
    last_drift_accept: Option<GpsTime>,
    /// Robust weighting: the run of fixes rejected on every axis.
    rejected_run: Vec<RejectedFix>,
    /// Robust weighting: the INS's overconfidence as seen by the last
    /// [`OVERCONFIDENCE_WINDOW`] fixes sharper than it after a gap.
    overconfidence: VecDeque<f64>,
    /// Robust weighting: consecutive down-weighted or rejected fixes,
    /// whether they agree or not, and the last one's time.
    disagreeing_streak: (usize, Option<GpsTime>),
    /// Robust weighting: the inverse-gamma posterior (α, β) of the noise
    /// scale of each axis of position and velocity, and when it was set.
    noise_scale: [([(f64, f64); 3], GpsTime); 2],
    /// Robust weighting: the last fix's posterior residual, per slot.
    last_residual: [Option<ResidualMemo>; 2],
    /// The last fix used (time, fix position), to spot repeated ones.
    pub(in crate::fusion) last_fix: Option<(GpsTime, Geodetic)>,
    /// Repeats of the position first written at this fix that were used
    /// (a stale run found after them is rolled back, `rollback.rs`).
    repeats_used: usize,
    /// A rollback's re-run: the repeats of the position first written at
    /// the first time, up to the second (the one found stale), are stale.
    /// (Set before the re-run writes that position again: kept until the
    /// next rollback.)
    /// After it, repeats are judged again: a receiver in static hold at
    /// rest under an INS with another IMU's figures was found stale after
    /// 3 s, and refusing the rest of its 7 s hold left the INS free at rest
    /// (0.20 m RMS over those seconds against 0.034 m).
    replay_stale: Option<(GpsTime, GpsTime)>,
    /// A rollback's re-run: the fix at this time began a run of fixes the
    /// robust weighting later took for INS drift; it is taken so at once.
    pub(in crate::fusion) replay_drift_accept: Option<GpsTime>,
    /// When the last fix's position was first written, the solution then
    /// and the INS's spread then: a repeat is judged by the motion since
    /// (see `is_stale`).
    repeat_since: Option<RepeatStart>,
    /// The corrections GNSS updates made since `repeat_since` (NED, m and
    /// m/s): Σ δp, Σ δv and Σ δv·(t − t_since), so that at T they moved
    /// the solution by Σ δp + Σ δv·(T − t_since) − Σ δv·(t − t_since).
    repeat_corrections: [Vector3<f64>; 3],
    /// From the first repeat of the last position on: the INS running free
    /// since that position was first written (see `judge_run_end`).
    pub(in crate::fusion) free_ins: Option<FreeIns>,
    /// The smallest nonzero change between consecutive fix positions seen
    /// so far, per axis (m, NED): the resolution the receiver writes at,
    /// or coarser (see `is_stale`).
    position_step_m: [Option<f64>; 3],
    pub(in crate::fusion) counts: GnssCounts,
    /// The fault-episode monitor (robust weighting).
    pub(in crate::fusion) monitor: FaultMonitor,
    /// A fix the monitor vouched for: used whatever the robust weights say.
    forced: Option<FaultReason>,
    /// When the last position fix was received (used or not).
    last_received: Option<GpsTime>,
}

/// What became of the fixes this source weighed.
#[derive(Clone, Copy, Default)]
pub(in crate::fusion) struct GnssCounts {
    pub(in crate::fusion) fixes_used: usize,
    fixes_rejected: usize,
    fixes_downweighted: usize,
    fixes_accepted_consistent: usize,
    pub(in crate::fusion) velocity_used: usize,
    velocity_rejected: usize,
    velocity_downweighted: usize,
    gate_reopened: usize,
    stale: usize,
    /// Fixes the integrity monitor excluded.
    excluded: usize,
    /// Fixes that measured the INS overconfidence.
    overconfidence_fixes: usize,
}

impl GnssSource {
    /// The share of the fixes' error that outlasts their spacing which the
    /// written σ carry (`fusion::fix_correlation`): the monitor's, none
    /// where Gauss–Markov error states model it (`FusionConfig::gnss_error`).
    pub(in crate::fusion) fn unmodelled_fix_share(
        &self,
        cfg: &FusionConfig,
    ) -> Option<Vector3<f64>> {
        let share = self.monitor.correlated_fix_share();
        share.filter(|_| cfg.gnss_error.is_none())
    }

    pub(in crate::fusion) fn new(cfg: &FusionConfig) -> Self {
        let gate = match cfg.gnss_weighting {
            GnssWeighting::Gate { prob } if prob > 0.0 && prob < 1.0 => {
                Some(chi2_quantile(prob, 3.0))
            }
            _ => None,
        };
        let prior = match cfg.gnss_weighting {
            GnssWeighting::Robust(rw) => 0.5 * rw.prior_fixes,
            _ => 1.0,
        };
        GnssSource {
            gate,
            noise_scale: [([(prior, prior); 3], cfg.init_nav.time); 2],
            monitor: FaultMonitor::new(cfg.noise.vrw.max()),
            ..Default::default()
        }
    }
}

impl AidSource for GnssSource {
    /// A fix in the delayed buffer whose processing time the solution
    /// reached.
    fn due(&self, core: &Core) -> bool {
        core.pending
            .front()
            .is_some_and(|f| core.proc_time(f) <= core.nav.time)
    }

    fn fuse(&mut self, core: &mut Core) -> Result<(), Error> {
        // τ̂ moves with each fix: the processing time is taken anew.
        while self.due(core) {
            if let Some(fix) = core.pending.pop_front() {
                self.fuse_fix(core, &fix)?;
            }
        }
        Ok(())
    }

    fn counters(&self, stats: &mut FusionStats) {
        let c = &self.counts;
        stats.gnss_fixes_used = c.fixes_used;
        stats.gnss_fixes_rejected = c.fixes_rejected;
        stats.gnss_fixes_downweighted = c.fixes_downweighted;
        stats.gnss_fixes_accepted_consistent = c.fixes_accepted_consistent;
        stats.gnss_velocity_used = c.velocity_used;
        stats.gnss_velocity_rejected = c.velocity_rejected;
        stats.gnss_velocity_downweighted = c.velocity_downweighted;
        stats.gate_reopened = c.gate_reopened;
        stats.gnss_fixes_stale = c.stale;
        stats.gnss_fixes_excluded = c.excluded;
        stats.gnss_fault_episodes = self.monitor.all_episodes();
        stats.gnss_fix_error_correlated = self.monitor.correlated_fix_share().map(|c| c.into());
        stats.gnss_ins_overconfidence =
            (c.overconfidence_fixes > 0).then(|| crate::fusion::InsOverconfidence {
                scale: self.overconfidence_scale(),
                fixes: c.overconfidence_fixes,
            });
    }
}

impl GnssSource {
    /// The position observation of a fix, with the time-offset column.
    fn position_obs(core: &Core, fix: &GnssFix) -> Observation {
        let lever = core.lever_b;
        let mut obs = crate::filter::gnss::position(&core.nav, fix, &lever, core.filter.n());
        if let (Some(i), Some(m)) = (core.gnss_bias_index, &core.cfg.gnss_error) {
            // Predicted fix r̂_ant + b̂: z gains +b̂, ∂z/∂δb = I; R keeps the
            // white part of the stated σ.
            for k in 0..3 {
                obs.z[k] += core.gnss_bias[k];
                obs.h.set(k, i + k, 1.0);
                let r = obs.r.get(k, k);
                let gm2 = m.gm_sd_m[k] * m.gm_sd_m[k];
                obs.r.set(k, k, (r - gm2).max(0.09 * r));
            }
        }
        core.offset_column_position(&mut obs);
        core.lever_column_position(&mut obs);
        obs
    }

    /// The velocity observation of a fix (when it has one), with the
    /// time-offset column.
    fn velocity_obs(core: &Core, fix: &GnssFix) -> Option<Observation> {
        let lever = core.lever_b;
        let mut obs = crate::filter::gnss::velocity(
            &core.nav,
            fix,
            &lever,
            &core.last_w_ib,
            core.filter.n(),
        )?;
        core.offset_column_velocity(&mut obs);
        core.lever_column_velocity(&mut obs);
        Some(obs)
    }

    /// Fuses one fix now (control: staleness, then the configured
    /// weighting), and remembers it.
    pub(in crate::fusion) fn fuse_fix(
        &mut self,
        core: &mut Core,
        fix: &GnssFix,
    ) -> Result<(), Error> {
        if self.is_stale(core, fix) {
            return Ok(());
        }
        let repeat = self.last_fix.is_some_and(|(_, p)| p == fix.pos);
        if !repeat {
            self.judge_run_end(core, fix);
        } else if self.free_ins.is_none() && self.monitor.onset_enabled {
            // No update since the first write: the solution now is the INS
            // run free from it. (Only where a rollback can follow.)
            self.free_ins = Some(FreeIns::from_core(core));
        }
        let used_before = self.counts.fixes_used;
        match core.cfg.gnss_weighting {
            GnssWeighting::Robust(rw) => self.robust_gnss_update(core, fix, &rw)?,
            GnssWeighting::Off | GnssWeighting::Gate { .. } => self.gated_gnss_update(core, fix)?,
        }
        if repeat && self.counts.fixes_used > used_before {
            self.repeats_used += 1;
        }
        self.note_position_step(core, fix);
        if self.last_fix.is_none_or(|(_, p)| p != fix.pos) {
            self.repeat_since = Some(RepeatStart {
                time: fix.time,
                nav_pos: core.nav.pos,
                drift_var_coeffs: free_drift_variance(core),
            });
            self.repeat_corrections = [Vector3::zeros(); 3];
            self.repeats_used = 0;
            self.free_ins = None;
        }
        self.last_fix = Some((fix.time, fix.pos));
        Ok(())
    }

    /// The first round's rule: χ² gate, drift acceptance, reopening.
    fn gated_gnss_update(&mut self, core: &mut Core, fix: &GnssFix) -> Result<(), Error> {
        let obs = Self::position_obs(core, fix);
        let frozen = core.frozen_states();
        let gate = if self.consecutive_rejects >= core.cfg.max_consecutive_rejects {
            None
        } else {
            self.gate
        };
        let outcome = core.apply(&obs, gate, &frozen)?;
        if outcome.accepted {
            self.note_correction(fix.time, &outcome.dx);
        }
        let mut record = FixRecord {
            time: fix.time,
            sow: fix.time.sow(),
            kind: "position",
            innovation: [obs.z[0], obs.z[1], obs.z[2]],
            sd: [0, 1, 2].map(|i| obs.r.get(i, i).sqrt()),
            nis: outcome.nis,
            weight: [1.0; 3],
            status: FixStatus::Used,
            reason: FaultReason::None,
            hpl_m: protection_level(core, 1.0),
        };
        if !outcome.accepted
            && let Some(threshold) = gate
        {
            let verdict = self.consistent_with_last_rejected(core, &obs, fix.time, threshold);
            record.status = match verdict {
                Some(_) => FixStatus::DriftAccepted,
                None => {
                    record.weight = [0.0; 3];
                    FixStatus::Rejected
                }
            };
            core.fix_log.push(record);
            match verdict {
                Some(factor) => {
                    core.notes.push(format!(
                        "GNSS fix at {} over the gate (NIS {:.1} > {:.1}) accepted: it agrees with the previous rejected fix, so the INS drifted beyond its covariance; covariance inflated x{:.2}",
                        fix.time, outcome.nis, threshold, factor
                    ));
                    core.filter.inflate(factor);
                    let outcome = core.apply(&obs, None, &frozen)?;
                    self.note_correction(fix.time, &outcome.dx);
                    self.counts.fixes_accepted_consistent += 1;
                    self.last_drift_accept = Some(fix.time);
                }
                None => {
                    self.consecutive_rejects += 1;
                    self.counts.fixes_rejected += 1;
                    core.notes.push(format!(
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
            core.fix_log.push(record);
        }
        self.last_rejected = None;
        if gate.is_none() && self.gate.is_some() {
            self.counts.gate_reopened += 1;
            core.notes.push(format!(
                "GNSS fix at {} accepted without gating after {} consecutive rejections",
                fix.time, self.consecutive_rejects
            ));
        }
        self.consecutive_rejects = 0;
        self.counts.fixes_used += 1;
        if core.cfg.use_gnss_velocity
            && let Some(obs) = Self::velocity_obs(core, fix)
        {
            let outcome = core.apply(&obs, self.gate, &frozen)?;
            if outcome.accepted {
                self.note_correction(fix.time, &outcome.dx);
                self.counts.velocity_used += 1;
            } else {
                self.counts.velocity_rejected += 1;
                core.notes.push(format!(
                    "GNSS velocity at {} rejected by the innovation gate",
                    fix.time
                ));
            }
        }
        Ok(())
    }

    /// Robust GNSS update ([`RobustWeighting`]): position, then velocity.
    fn robust_gnss_update(
        &mut self,
        core: &mut Core,
        fix: &GnssFix,
        rw: &RobustWeighting,
    ) -> Result<(), Error> {
        let frozen = core.frozen_states();
        let obs = Self::position_obs(core, fix);
        let decision = core
            .cfg
            .gnss_decisions
            .as_ref()
            .and_then(|d| d.get(&fix.time).copied());
        let excluded = match decision {
            Some(d) => self.apply_decision(core, &obs, fix.time, d),
            None => self.judge_integrity(core, &obs, fix.time)?,
        };
        let innovation = Vector3::new(obs.z[0], obs.z[1], obs.z[2]);
        if let Some(episode_start) = self.monitor.take_jump_in_episode()
            && self.monitor.onset_enabled
            && core.rollback_to.is_none()
        {
            core.jump_in_episode = Some(JumpInEpisode {
                time: fix.time,
                at: core.nav.time,
                innovation,
                episode_start,
            });
        }
        if self.monitor.take_jump() && self.monitor.onset_enabled && core.rollback_to.is_none() {
            core.jump_check = Some(JumpCheck {
                time: fix.time,
                at: core.nav.time,
                pos: fix.pos,
                pos_sd: fix.pos_sd,
                innovation,
                excluded,
            });
        }
        if excluded {
            self.last_received = Some(fix.time);
            return Ok(());
        }
        let monitor_vouched = self.forced.is_some();
        let status = self.robust_apply(core, obs, 0, fix.time, rw, &frozen)?;
        self.forced = None;
        self.last_received = Some(fix.time);
        if matches!(status, FixStatus::Used | FixStatus::DriftAccepted)
            && let Some(memo) = self.last_residual[0].filter(|m| m.time == fix.time)
        {
            let spread = state_spread(core);
            self.monitor.add_anchor(
                fix.time,
                memo.residual,
                memo.hph_post,
                memo.r_stated,
                spread,
                // The robust weighting's own "the INS drifted": the fixes
                // had been pulling the state away.
                status == FixStatus::DriftAccepted && !monitor_vouched,
            );
        }
        match status {
            FixStatus::Rejected => {
                self.counts.fixes_rejected += 1;
                return Ok(());
            }
            FixStatus::DownWeighted => self.counts.fixes_downweighted += 1,
            FixStatus::DriftAccepted => self.counts.fixes_accepted_consistent += 1,
            FixStatus::Used => {}
        }
        self.counts.fixes_used += 1;
        if core.cfg.use_gnss_velocity
            && let Some(obs) = Self::velocity_obs(core, fix)
        {
            match self.robust_apply(core, obs, 1, fix.time, rw, &frozen)? {
                FixStatus::Rejected => {
                    self.counts.velocity_rejected += 1;
                    return Ok(());
                }
                FixStatus::DownWeighted => self.counts.velocity_downweighted += 1,
                _ => {}
            }
            self.counts.velocity_used += 1;
        }
        Ok(())
    }

    /// Weights one 3-axis GNSS observation (`slot` 0 position, 1 velocity)
    /// and applies it unless every axis is rejected.
    ///
    /// 1. Noise scale (when `RobustWeighting::noise_scale`, else 1). Over
    ///    a second the INS is a far better relative reference than a
    ///    degraded fix, so the change between this
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
        core: &mut Core,
        mut obs: Observation,
        slot: usize,
        time: GpsTime,
        rw: &RobustWeighting,
        frozen: &[usize],
    ) -> Result<FixStatus, Error> {
        core.propagate();
        let r_stated = Vector3::new(obs.r.get(0, 0), obs.r.get(1, 1), obs.r.get(2, 2));
        let sd = [0, 1, 2].map(|i| r_stated[i].sqrt());
        let s_stated = core.filter.innovation_covariance(&obs);
        let nis = nis_of(&s_stated, &obs.z).unwrap_or(f64::INFINITY);
        let mut hph =
            Matrix3::from_fn(|r, c| s_stated.get(r, c)) - Matrix3::from_diagonal(&r_stated);
        let z = Vector3::new(obs.z[0], obs.z[1], obs.z[2]);
        let ins_scale = if slot == 0 {
            self.ins_overconfidence(time, &z, &hph, &r_stated)
        } else {
            1.0
        };

        // 1. The noise scale of the fixes' stated σ: forgetting toward the
        //    prior, then the differenced innovation.
        let scale = if rw.noise_scale {
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
            if let Some(prev) = self.last_residual[slot]
                && time.seconds_since(prev.time) <= PAIR_MAX_GAP_S
            {
                for i in 0..3 {
                    let var = ins_scale * (hph[(i, i)] - prev.hph_post[i]).max(0.0)
                        + r_stated[i]
                        + prev.r_stated[i];
                    let d = z[i] - prev.residual[i];
                    // A jump too large for any noise scale is a gross error,
                    // left to step 2 (it must not inflate the scale for long).
                    let u = (d * d / var).min(rw.k1 * rw.k1);
                    post[i].0 += 0.5;
                    post[i].1 += 0.5 * u;
                }
            }
            self.noise_scale[slot] = (post, time);
            post.map(|(a, b)| (b / a).max(1.0))
        } else {
            [1.0; 3]
        };

        // 2. Gross errors: beyond k1 on any axis, the whole fix is wrong
        //    (a receiver's faults are not confined to one axis).
        let mut w = [1.0; 3];
        for i in 0..3 {
            let s_ii = ins_scale * hph[(i, i)] + scale[i] * r_stated[i];
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
            reason: self.forced.unwrap_or_default(),
            hpl_m: 0.0,
        };
        // A disagreement that persists smoothly (down-weighted or rejected
        // fixes that agree with each other) is the INS drifting.
        let mut drift = false;
        if slot == 0 && self.forced.is_some() {
            drift = true;
        } else if slot == 0 {
            if self.replay_drift_accept.is_some_and(|t| time >= t) {
                self.replay_drift_accept = None;
                // Its level persisted (until taken for drift), as a
                // monitor's episode does: the smoother's re-judgement
                // weighs it as the end of a fault the filter followed.
                if w.iter().any(|w| *w < 1.0)
                    && self.accept_drift(core, &obs, &s_stated, time, "the run of fixes it began was taken for INS drift (above); taken so from it on")
                {
                    drift = true;
                    record.reason = FaultReason::Persisted;
                }
            } else if w.iter().any(|w| *w < 1.0) {
                drift = self.robust_drift_check(core, &obs, &s_stated, time, rw)?;
            } else {
                self.rejected_run.clear();
                self.disagreeing_streak = (0, None);
            }
        }
        if drift
            && matches!(
                self.forced,
                Some(FaultReason::SmootherReadmitted | FaultReason::None)
            )
        {
            // The smoother's verdict, not a drift: used at its stated σ.
            w = [1.0; 3];
        } else if drift {
            record.status = FixStatus::DriftAccepted;
            w = [1.0; 3];
            let s = core.filter.innovation_covariance(&obs);
            hph = Matrix3::from_fn(|r, c| s.get(r, c)) - Matrix3::from_diagonal(&r_stated);
        } else if w.iter().all(|w| *w == 0.0) {
            record.status = FixStatus::Rejected;
            record.reason = FaultReason::Outlier;
            record.hpl_m = protection_level(core, ins_scale);
            core.fix_log.push(record);
            core.notes.push(format!(
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
        let outcome = core.apply(&obs, None, frozen)?;
        if outcome.accepted {
            self.monitor
                .record_correction(time, &outcome.dx, idx::POS, idx::VEL);
            self.note_correction(time, &outcome.dx);
            if slot == 0 {
                let share = self.unmodelled_fix_share(&core.cfg);
                core.fix_correlation.note_fused(time, r_stated, share);
            }
        }
        record.hpl_m = protection_level(core, ins_scale);
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
        // A down-weighted fix of the drift run moved the state: the next
        // fix is compared with what is left of this one's innovation.
        if slot == 0
            && record.status == FixStatus::DownWeighted
            && let (Some(last), Some(memo)) = (self.rejected_run.last_mut(), self.last_residual[0])
            && last.time == time
        {
            last.z = memo.residual.iter().copied().collect();
        }
        core.fix_log.push(record);
        Ok(record.status)
    }

    /// Excludes a position fix for `reason`: counted and recorded (its
    /// record returned).
    fn exclude(
        &mut self,
        core: &mut Core,
        obs: &Observation,
        s: &Mat,
        time: GpsTime,
        reason: FaultReason,
        lambda: f64,
    ) -> FixRecord {
        self.counts.excluded += 1;
        self.counts.fixes_rejected += 1;
        let record = excluded_record(core, obs, s, time, reason, lambda);
        core.fix_log.push(record);
        record
    }

    /// Puts a position fix before the fault monitor
    /// ([`super::integrity`]). Returns true when the fix was excluded
    /// (recorded and counted here); a fix the monitor vouches for after an
    /// episode is marked to be used whatever its weights, with P inflated
    /// so that its innovation fits.
    fn judge_integrity(
        &mut self,
        core: &mut Core,
        obs: &Observation,
        time: GpsTime,
    ) -> Result<bool, Error> {
        core.propagate();
        let s = core.filter.innovation_covariance(obs);
        let (r, hph) = stated_parts(obs, &s);
        let z = Vector3::new(obs.z[0], obs.z[1], obs.z[2]);
        let lambda = self.overconfidence_scale();
        match self.monitor.judge(time, &z, &hph, &r, lambda) {
            Judgement::Clean => Ok(false),
            Judgement::Exclude(reason) => {
                let record = self.exclude(core, obs, &s, time, reason, lambda);
                core.notes.push(format!(
                    "GNSS fix at {time} excluded by the integrity monitor ({}: innovation {:.3} m, NIS {:.1})",
                    reason.word(),
                    z.norm(),
                    record.nis
                ));
                Ok(true)
            }
            Judgement::Onset { anchor, offset_m } => {
                // Excluded here; the wrapper returns to the state after
                // `anchor` and runs again without the ramp's fixes.
                self.exclude(core, obs, &s, time, FaultReason::Ramp, lambda);
                core.rollback_to = Some(Rollback::Ramp {
                    anchor,
                    onset: time,
                });
                core.notes.push(format!(
                    "GNSS fix at {time} excluded by the integrity monitor (ramp: {offset_m:.3} m from the INS carried from the clean fix at {anchor}, beyond its drift since); the filter returns to its state after that fix and runs again without the fixes since"
                ));
                Ok(true)
            }
            Judgement::RampEnd { offset } => {
                grow_position_variance(core, &offset);
                core.notes.push(format!(
                    "GNSS fix at {time} jumped {:.3} m back to where the fixes were seconds before: those since drifted away (a ramp the filter followed); used, position variance grown to fit",
                    offset.norm()
                ));
                self.forced = Some(FaultReason::Persisted);
                Ok(false)
            }
            // Weighed as any fix is: in real time the filter stands on the
            // false level, and a fix forced in there (position variance
            // grown to fit) was measured to pull it onto whichever level
            // came back, good or not (fixes flipping ±0.3 m every second:
            // 0.020 m off where weighing keeps it within 0.01 m).
            // Offline the re-run from before the episode replaces it.
            Judgement::FalseFixEnd { anchor, offset } => {
                if self.monitor.onset_enabled {
                    core.rollback_to = Some(Rollback::FalseFixEnded { anchor, end: time });
                }
                core.notes.push(format!(
                    "GNSS fix at {time} jumped {:.3} m back, undoing the jump that opened the episode after the clean fix at {anchor}: the level followed since was a false fix{}",
                    offset.norm(),
                    if self.monitor.onset_enabled {
                        "; the filter returns to its state after that clean fix and runs again without the fixes since"
                    } else {
                        ""
                    }
                ));
                Ok(false)
            }
            Judgement::Persisted { by, offset } => {
                grow_position_variance(core, &offset);
                let why = match by {
                    PersistedBy::Unbridged => format!(
                        "a fault episode lasted longer than the IMU can bridge ({} s); the fixes are followed again and the solution in the episode is uncertain",
                        super::integrity::MAX_EPISODE_S
                    ),
                    PersistedBy::DriftCovers => "the fixes stayed at their new level until the INS's predicted drift covered it; used again (covariance inflated to fit)".to_string(),
                    PersistedBy::OnsetUnresolved => "the fixes drifted on from the INS after a ramp's onset until its predicted drift outgrew their own error change, so it can no longer tell a ramp from its own drift; used again (covariance inflated to fit)".to_string(),
                    PersistedBy::InsDrifts => "the fixes' offset from the INS wandered past its predicted growth, at a rate that could have built the offset: the INS drifts; used again (covariance inflated to fit)".to_string(),
                    PersistedBy::InsDriftedPastLevel { drift_m, level_m } => format!(
                        "the INS drifted {drift_m:.3} m from the fixes since the episode began, more than the {level_m:.3} m level it judged: it is no nearer the truth than they are; used again (covariance inflated to fit)"
                    ),
                };
                let rerun = match self.monitor.take_persisted_level() {
                    Some(level) if core.rollback_to.is_none() => {
                        core.rollback_to = Some(Rollback::LevelPersisted(level));
                        format!(
                            "; the level held since the jump at {}: the filter returns to its state before it and runs again following the fixes from it",
                            level.jump
                        )
                    }
                    _ => String::new(),
                };
                core.notes.push(format!("GNSS fix at {time}: {why}{rerun}"));
                self.forced = Some(FaultReason::Persisted);
                Ok(false)
            }
        }
    }

    /// Applies the smoother's verdict on a position fix in place of the
    /// monitor's (`crate::rejudge`). Returns true when the fix is excluded
    /// (recorded and counted here); any other is marked to be used at its
    /// stated σ whatever its weights, the covariance untouched (inflating
    /// it, as after a persisted episode, would cut the smoother's bridge
    /// over the fixes excluded before it: measured worse on the bed).
    fn apply_decision(
        &mut self,
        core: &mut Core,
        obs: &Observation,
        time: GpsTime,
        decision: GnssDecision,
    ) -> bool {
        match decision {
            GnssDecision::Keep => {
                self.forced = Some(FaultReason::None);
                false
            }
            GnssDecision::Follow(reason) => {
                self.forced = Some(reason);
                false
            }
            GnssDecision::Exclude(reason) => {
                core.propagate();
                let s = core.filter.innovation_covariance(obs);
                let lambda = self.overconfidence_scale();
                self.exclude(core, obs, &s, time, reason, lambda);
                true
            }
        }
    }

    /// The median of the kept overconfidence ratios, within
    /// [1, MAX_INFLATION]; 1 before [`MIN_OVERCONFIDENCE_FIXES`] of them
    /// (the median of two is the larger: one bad fix would set it).
    pub(in crate::fusion) fn overconfidence_scale(&self) -> f64 {
        if self.overconfidence.len() < MIN_OVERCONFIDENCE_FIXES {
            return 1.0;
        }
        let mut q: Vec<f64> = self.overconfidence.iter().copied().collect();
        q.sort_by(f64::total_cmp);
        q[q.len() / 2].clamp(1.0, MAX_INFLATION)
    }

    /// The robust weighting's scale λ of the INS's predicted spread HPHᵀ:
    /// how much larger than predicted its errors have been. A MEMS filter
    /// whose model leaves errors out (flicker, misalignment, a vibrating
    /// mount) drifts through GNSS gaps at several times its σ, and would
    /// then take good fixes for bad ones. The first fix after a gap of more
    /// than [`PAIR_MAX_GAP_S`] that is sharper than the INS (tr R < tr HPHᵀ)
    /// measures it: q = (zᵀz − tr R)/tr(HPHᵀ), the moment estimate of an
    /// adaptive fading factor (Xia, Rao, Ying & Shen, "Adaptive fading
    /// Kalman filter with an application", Automatica 30(8), 1994), whose
    /// mean is 1 for a consistent filter. λ is the median q of the last
    /// [`OVERCONFIDENCE_WINDOW`] such fixes, within [1, MAX_INFLATION]; it
    /// scales HPHᵀ only where fixes are judged (noise scale and IGG-III
    /// weights), never in the update itself. Returns λ for this fix, from
    /// the fixes before it.
    fn ins_overconfidence(
        &mut self,
        time: GpsTime,
        z: &Vector3<f64>,
        hph: &Matrix3<f64>,
        r_stated: &Vector3<f64>,
    ) -> f64 {
        let lambda = self.overconfidence_scale();
        // A gap in the fixes received, not one the fault monitor made by
        // excluding fixes (the INS may have been led off by them).
        let after_gap = self
            .last_received
            .is_none_or(|prev| time.seconds_since(prev) > PAIR_MAX_GAP_S);
        let tr_r = r_stated.sum();
        let tr_hph = hph.trace();
        if after_gap && tr_r < tr_hph && tr_hph > 0.0 {
            let q = (z.norm_squared() - tr_r) / tr_hph;
            if q.is_finite() {
                if self.overconfidence.len() == OVERCONFIDENCE_WINDOW {
                    self.overconfidence.pop_front();
                }
                self.overconfidence.push_back(q.max(0.0));
                self.counts.overconfidence_fixes += 1;
            }
        }
        lambda
    }

    /// After a position fix that was down-weighted or rejected: when the last
    /// `drift_run` such fixes agree with each other (each innovation
    /// differs from the previous fix's, or from the straight line through
    /// the two before, by no more than their covariances allow; a
    /// down-weighted fix counts by its posterior residual, since it moved
    /// the state) and the run began just past k1 (at most 2·k1: a fault
    /// jumps), or when [`LONG_DRIFT_RUN`] of them agree, the INS drifted
    /// beyond its covariance, as after a long outage, and P is inflated by
    /// the moment estimate λ = (zᵀz − tr R)/tr(HPHᵀ) (an adaptive fading
    /// factor, Xia et al. 1994), capped at [`MAX_INFLATION`], at most once
    /// per [`CONSISTENCY_COOLDOWN_S`] — unless
    /// [`PERSISTENT_DISAGREEMENT`] fixes in a row disagree with the INS.
    /// Returns whether P was inflated.
    fn robust_drift_check(
        &mut self,
        core: &mut Core,
        obs: &Observation,
        s: &Mat,
        time: GpsTime,
        rw: &RobustWeighting,
    ) -> Result<bool, Error> {
        let threshold = chi2_quantile(0.9999, obs.dim() as f64);
        // "The INS drifted" only where it could have: not while the fault
        // monitor holds a clean fix seconds back against which the INS's
        // drift is within the fixes' own error change (a navigation-grade
        // INS drifts millimetres in seconds; three fixes that moved 0.2 m
        // together are a ramp, which the monitor's onset test then finds).
        if obs.dim() == 3 {
            let (r, hph) = stated_parts(obs, s);
            let lambda = self.overconfidence_scale();
            let z = Vector3::new(obs.z[0], obs.z[1], obs.z[2]);
            let fix = FixView::new(time, z, hph, r, lambda);
            if self.monitor.ins_is_reference(&fix) {
                return Ok(false);
            }
        }
        if let Some(prev) = self.rejected_run.last() {
            let n = self.rejected_run.len();
            let trend = n >= 2
                && extrapolation_agrees(&self.rejected_run[n - 2], prev, obs, time, s, threshold);
            let agrees = time.seconds_since(prev.time) <= CONSISTENCY_MAX_GAP_S
                && (prev.agrees_with(obs, s, threshold) || trend);
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
        let (streak, last) = self.disagreeing_streak;
        let streak = if last.is_some_and(|t| time.seconds_since(t) <= CONSISTENCY_MAX_GAP_S) {
            streak + 1
        } else {
            1
        };
        self.disagreeing_streak = (streak, Some(time));
        let persistent = streak >= PERSISTENT_DISAGREEMENT;
        let cooled = persistent
            || self
                .last_drift_accept
                .is_none_or(|t| time.seconds_since(t) >= CONSISTENCY_COOLDOWN_S);
        // A drifting INS crosses k1 gradually; a fault jumps far past it.
        let smooth_start = self.rejected_run[0].first_ratio <= SMOOTH_START_RATIO;
        let run = self.rejected_run.len();
        let agreeing_run = (run >= rw.drift_run && smooth_start) || run >= LONG_DRIFT_RUN;
        if !cooled || !(agreeing_run || persistent) {
            return Ok(false);
        }
        let why = if agreeing_run {
            format!(
                "{run} consecutive disagreeing fixes agree with each other, so the INS drifted beyond its covariance"
            )
        } else {
            format!("{streak} consecutive fixes disagreed with the INS, so it left its error model")
        };
        // A run that began with a jump and agreed throughout is a level the
        // fixes moved to at its first fix, refused until now: offline the
        // filter returns to before it and takes it from there
        // (`fusion/rollback.rs`). (The 1 Hz ADIS16465 drive, held-out seed
        // 8: the good fixes back at a ramp's end, refused 9 s while the
        // INS coasted 2.1–3.4 m off at a protection level of 0.3–1.6 m.)
        let first = &self.rejected_run[0];
        let rerun = (self.monitor.onset_enabled
            && core.rollback_to.is_none()
            && agreeing_run
            && first.first_ratio > SMOOTH_START_RATIO)
            .then_some(first.time);
        let why = match rerun {
            Some(first) => format!(
                "{why}; the run began at {first} with a jump, so the filter returns to its state before it and runs again taking the fixes from it"
            ),
            None => why,
        };
        let accepted = self.accept_drift(core, obs, s, time, &why);
        if let (true, Some(first)) = (accepted, rerun) {
            core.rollback_to = Some(Rollback::DriftRunAccepted { first });
        }
        Ok(accepted)
    }

    /// Takes the fix at `time` for INS drift (`why`): P inflated by the
    /// moment estimate ([`moment_inflation`]); false where there is none.
    fn accept_drift(
        &mut self,
        core: &mut Core,
        obs: &Observation,
        s: &Mat,
        time: GpsTime,
        why: &str,
    ) -> bool {
        let Some(factor) = moment_inflation(obs, s) else {
            return false;
        };
        core.notes.push(format!(
            "GNSS fix at {time}: {why}; covariance inflated x{factor:.2}"
        ));
        core.filter.inflate(factor);
        self.last_drift_accept = Some(time);
        self.rejected_run.clear();
        self.disagreeing_streak = (0, None);
        true
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
        core: &Core,
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
        let s = core.filter.innovation_covariance(obs);
        if !prev.agrees_with(obs, &s, threshold) {
            return None;
        }
        moment_inflation(obs, &s)
    }
}

/// The horizontal protection level (m): K·√μ, μ the larger eigenvalue of
/// the horizontal position covariance scaled by λ, with the fixes' error
/// that outlasts their spacing added (`fusion::fix_correlation`); K =
/// [`PROTECTION_K`].
fn protection_level(core: &Core, lambda: f64) -> f64 {
    let p = core.filter.covariance();
    let lambda = lambda.max(1.0);
    let p_pos = Matrix3::from_fn(|r, c| lambda * p.get(idx::POS + r, idx::POS + c));
    // The fixes' error that outlasts their spacing (`fix_correlation`).
    let p_pos = p_pos + core.fix_correlation.covariance(&p_pos).unwrap_or_default();
    let (a, b, d) = (p_pos[(0, 0)], p_pos[(0, 1)], p_pos[(1, 1)]);
    let mu = 0.5 * (a + d) + (0.25 * (a - d) * (a - d) + b * b).sqrt();
    PROTECTION_K * mu.max(0.0).sqrt()
}

/// The record of a position fix not fused (stale, or excluded by the fault
/// monitor): innovation covariance `s`, the INS overconfidence `lambda`.
fn excluded_record(
    core: &Core,
    obs: &Observation,
    s: &Mat,
    time: GpsTime,
    reason: FaultReason,
    lambda: f64,
) -> FixRecord {
    FixRecord {
        time,
        sow: time.sow(),
        kind: "position",
        innovation: [obs.z[0], obs.z[1], obs.z[2]],
        sd: [0, 1, 2].map(|i| obs.r.get(i, i).sqrt()),
        nis: nis_of(s, &obs.z).unwrap_or(f64::INFINITY),
        weight: [0.0; 3],
        status: FixStatus::Rejected,
        reason,
        hpl_m: protection_level(core, lambda),
    }
}

/// Grows the position variance by the square of `offset` (NED, m): the
/// INS's position is off by about that much, while its velocity and
/// attitude keep what they knew.
fn grow_position_variance(core: &mut Core, offset: &Vector3<f64>) {
    let p = core.filter.covariance_mut();
    for i in 0..3 {
        let k = idx::POS + i;
        p.set(k, k, p.get(k, k) + offset[i] * offset[i]);
    }
}

/// A 3-D position observation's stated R (diagonal) and H P Hᵀ, from its
/// innovation covariance `s` = H P Hᵀ + R.
fn stated_parts(obs: &Observation, s: &Mat) -> (Vector3<f64>, Matrix3<f64>) {
    let r = Vector3::new(obs.r.get(0, 0), obs.r.get(1, 1), obs.r.get(2, 2));
    let hph = Matrix3::from_fn(|i, j| s.get(i, j)) - Matrix3::from_diagonal(&r);
    (r, hph)
}

/// The state's σ the fault monitor's growth model needs, now.
fn state_spread(core: &Core) -> StateSpread {
    let f = &core.filter;
    StateSpread {
        vel_sd: Vector3::new(f.sd(idx::VEL), f.sd(idx::VEL + 1), f.sd(idx::VEL + 2)),
        tilt_sd: f.sd(idx::ATT).max(f.sd(idx::ATT + 1)),
        // An unknown yaw (held) is not a heading error to grow with.
        yaw_sd: f.sd(idx::ATT + 2).min(std::f64::consts::PI),
        accel_bias_sd: f.sd(idx::BA).max(f.sd(idx::BA + 1)).max(f.sd(idx::BA + 2)),
        gyro_bias_sd: f.sd(idx::BG).max(f.sd(idx::BG + 1)).max(f.sd(idx::BG + 2)),
        speed_mps: core.nav.vel.xy().norm(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// The free INS's displacement-error variance from a known covariance
    /// (the fusion tests' initial σ: velocity 0.1 m/s, tilt 0.01 rad,
    /// accelerometer bias 1 mm/s², uncorrelated): level and heading north,
    /// f = (0, 0, −g), so a tilt φ gives an acceleration error
    /// (g φ_E, −g φ_N, 0) and a bias δb_a gives −δb_a; its position error
    /// does not enter a displacement. With the tilt and the bias
    /// correlated as a standstill leaves them (g φ_E = δb_a,x), their
    /// errors cancel on that axis.
    #[test]
    fn free_drift_variance_is_the_second_order_error_growth() {
        let (_, cfg) = crate::fusion::tests::setup(LatencyMode::Offline);
        let mut core = Core::new(Arc::new(cfg));
        core.nav.q_nb = nalgebra::UnitQuaternion::identity();
        let g = crate::earth::gravity(core.nav.pos.lat_rad.sin(), core.nav.pos.h_m);
        let (sd_v, sd_att, sd_ba) = (0.1, 0.01, 1e-3);
        let c = free_drift_variance(&core);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1e-12);
        assert_eq!(c[1], 0.0, "{c:?}");
        assert!(close(c[0], 3.0 * sd_v * sd_v), "{c:?}");
        let accel_var = 2.0 * (g * sd_att).powi(2) + 3.0 * sd_ba * sd_ba;
        assert!(close(c[2], accel_var / 4.0), "{c:?}");
        // Tilt east and the x bias tied: σ_b = g σ_φ, correlation 1.
        let p = core.filter.covariance_mut();
        p.set(idx::BA, idx::BA, (g * sd_att).powi(2));
        p.set(idx::ATT + 1, idx::BA, g * sd_att * sd_att);
        p.set(idx::BA, idx::ATT + 1, g * sd_att * sd_att);
        let c = free_drift_variance(&core);
        let accel_var = (g * sd_att).powi(2) + 2.0 * sd_ba * sd_ba;
        assert!(close(c[2], accel_var / 4.0), "{c:?}");
    }

    /// The INS overconfidence scale: the median moment ratio of fixes
    /// sharper than the INS after a gap, from the fixes before.
    #[test]
    fn overconfidence_is_the_median_ratio_of_sharp_fixes_after_gaps() {
        let mut g = GnssSource::default();
        let t0 = GpsTime::from_week_sow(2300, 1000.0);
        let hph = Matrix3::from_diagonal(&Vector3::repeat(0.01));
        let r = Vector3::repeat(0.0001);
        // zᵀz − tr R = q · tr HPHᵀ (HPHᵀ 0.01 m² per axis, R 1 cm²), for
        // q = 4, 9, 1.
        let fix = |q: f64| Vector3::repeat(((q * 0.03 + 0.0003) / 3.0).sqrt());
        assert_eq!(g.ins_overconfidence(t0, &fix(4.0), &hph, &r), 1.0);
        // Fewer than three ratios set nothing (one bad fix would).
        let lambda = g.ins_overconfidence(t0.add_seconds(10.0), &fix(9.0), &hph, &r);
        assert_eq!(lambda, 1.0);
        let lambda = g.ins_overconfidence(t0.add_seconds(20.0), &fix(1.0), &hph, &r);
        assert_eq!(lambda, 1.0, "median of 4, 9 is not used");
        let lambda = g.ins_overconfidence(t0.add_seconds(30.0), &fix(1.0), &hph, &r);
        assert!((lambda - 4.0).abs() < 1e-9, "median of 4, 9, 1: {lambda}");
        // A fix less sharp than the INS measures nothing; a consistent
        // filter (q below 1) never makes the INS look sharper than it says.
        let dull = Vector3::repeat(1.0);
        g.ins_overconfidence(t0.add_seconds(40.0), &dull, &hph, &dull);
        assert_eq!(g.overconfidence.len(), 4);
        for k in 0..OVERCONFIDENCE_WINDOW {
            g.ins_overconfidence(t0.add_seconds(50.0 + 10.0 * k as f64), &fix(0.2), &hph, &r);
        }
        assert_eq!(g.overconfidence.len(), OVERCONFIDENCE_WINDOW);
        assert_eq!(
            g.ins_overconfidence(t0.add_seconds(500.0), &fix(0.2), &hph, &r),
            1.0
        );
        // A fix a second after a used one measures nothing: the INS had no
        // gap to drift through.
        let before = g.overconfidence.clone();
        g.last_received = Some(t0.add_seconds(599.0));
        g.ins_overconfidence(t0.add_seconds(600.0), &fix(50.0), &hph, &r);
        assert_eq!(g.overconfidence, before);

        // The summary reports the scale in use and every fix that measured
        // it (4 + 15 + 1 = 20), not only those still in the window.
        let mut stats = FusionStats::default();
        g.counters(&mut stats);
        let o = stats.gnss_ins_overconfidence.expect("measured");
        assert_eq!(o.fixes, 20);
        assert_eq!(o.scale, 1.0);
        let mut stats = FusionStats::default();
        GnssSource::default().counters(&mut stats);
        assert!(stats.gnss_ins_overconfidence.is_none());
    }
}
