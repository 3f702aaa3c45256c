//! The ramp-onset test of the fault monitor (issue 33): each fix against
//! the clean anchors seconds back, where the INS is sharper than the fixes'
//! own error change; an onset hands the wrapper a rollback
//! (`fusion/rollback.rs`). See the parent module's notes.

use nalgebra::Vector3;

use super::*;

/// A ramp's onset is judged against anchors at least this old (s): over
/// the last seconds a slow ramp is below any test.
pub(super) const ONSET_MIN_LAG_S: f64 = 3.5;
/// Anchors tested for a ramp's onset are at least this far apart (s):
/// neighbours test the same thing, and fixes at 10 Hz would cost 200
/// tests a fix.
pub(super) const ONSET_ANCHOR_SPACING_S: f64 = 0.9;
/// The onset test's calibration keeps, for a clean fix per anchor
/// spacing, its largest D against the older anchors, over this many
/// seconds…
pub(super) const ONSET_CAL_MEMORY_S: f64 = 600.0;
/// …and is used once it holds this many fixes spanning at least
/// [`ONSET_CAL_SPAN_S`]: the filter's σ, which the test's drift model
/// reads, is optimistic while its heading and biases settle (a clean urban
/// drive with the ADIS16465 had a false onset 74 s in, on 60 fixes).
pub(super) const ONSET_CAL_MIN: usize = 60;
/// χ²₃'s 99th percentile.
pub(super) const CHI2_3_P99: f64 = 11.345;
/// The shortest span (s) of clean fixes the onset test is calibrated on.
pub(super) const ONSET_CAL_SPAN_S: f64 = 120.0;
/// χ²₃'s 95th percentile: the onset test's threshold is scaled by the
/// measured 95th percentile of the clean fixes' D over this.
pub(super) const CHI2_3_P95: f64 = 7.815;
/// An onset's episode holds while the INS's drift variance since its
/// anchor is within this many times the fixes' error change (its σ twice
/// theirs).
pub(super) const ONSET_HOLD_RATIO: f64 = 4.0;

impl Anchor {
    /// Whether the anchor's own fix agreed with the filter: its NIS,
    /// Σ r⁺ᵢ² / (Rᵢ − (H P⁺ Hᵀ)ᵢ) (the posterior residual's form of
    /// zᵀ S⁻¹ z, per axis), within χ²₃'s 99th percentile times `scale`.
    /// A fix already off (dataset2's real fixes: 0.54 m down at a NIS of
    /// 14.5) is no level to measure a ramp from.
    pub(super) fn fits(&self, scale: f64) -> bool {
        let nis: f64 = (0..3)
            .map(|i| {
                let v = (self.r[i] - self.hph_post[i]).max(f64::MIN_POSITIVE);
                self.residual[i] * self.residual[i] / v
            })
            .sum();
        nis <= CHI2_3_P99 * scale
    }
}

impl FaultMonitor {
    /// The ramp-onset test: the fix against the clean anchors at least
    /// [`ONSET_MIN_LAG_S`] back. A ramp's steps are each within the jump
    /// test, and the filter follows them; against a fix seconds back the
    /// offset it built shows, once it is beyond the free INS's drift since
    /// (Δ and V as for a jump, the INS's growth over the longer lag). The
    /// filter's growth model is not a calibrated χ² over seconds (a MEMS
    /// INS in turns drifts past it; a receiver's multipath moves real
    /// fixes by decimetres over seconds: dataset2's clean fixes reach
    /// D = 31 against the χ²₃ 10⁻⁴ quantile 21.1), so the threshold is that
    /// quantile times the measured 95th percentile of D on clean fixes over
    /// χ²₃'s, at least 1 ([`Self::recalibrate_onset`]): a test calibrated
    /// on the fixes the monitor accepted (the same idea as the INS
    /// overconfidence λ). Until enough have been seen there is no onset
    /// test. On an onset, the anchor with the largest D becomes the
    /// episode's, the anchors since are dropped (they were on the ramp) and
    /// the wrapper rolls the filter back to that anchor
    /// ([`Judgement::Onset`]).
    pub(super) fn ramp_onset(&mut self, fix: &FixView) -> Option<Judgement> {
        let (time, hph) = (fix.time, &fix.hph);
        self.onset_pending = None;
        let mut worst: Option<(Anchor, f64, Vector3<f64>, Vector3<f64>)> = None;
        let mut last_tested: Option<GpsTime> = None;
        for a in self.onset_anchors(time) {
            if last_tested.is_some_and(|t| t.seconds_since(a.time) < ONSET_ANCHOR_SPACING_S)
                || !self.ins_is_sharper(a, fix)
            {
                continue;
            }
            last_tested = Some(a.time);
            let (delta, d, v) = self.test(a, fix);
            if worst.is_none_or(|(_, dw, _, _)| d > dw) {
                worst = Some((*a, d, delta, v));
            }
        }
        if let (Some(scale), Some((a, d, delta, v))) = (self.onset_scale, worst)
            && d > fix_test_threshold() * scale
        {
            self.anchors.retain(|b| b.seq <= a.seq);
            self.pending_pair = None;
            self.open(a, time, delta, v, hph, true);
            return Some(Judgement::Onset {
                anchor: a.time,
                offset_m: delta.norm(),
            });
        }
        // A fix beyond the test's threshold is under suspicion even while
        // the test cannot yet be used, and a fix the robust weighting then
        // refuses or takes for drift is too: neither calibrates it (a
        // ramp's own fixes, let in, raised the scale 1.0 → 3.3 in five
        // seconds and hid it on dataset2).
        self.onset_pending = worst
            .filter(|(_, d, _, _)| *d <= fix_test_threshold() * self.onset_scale.unwrap_or(1.0))
            .map(|(_, d, _, _)| (time, d));
        None
    }

    /// The onset test's calibration: the measured 95th percentile of its
    /// statistic on clean fixes over χ²₃'s (a variance ratio, at least 1),
    /// once enough clean fixes were seen (see [`Self::ramp_onset`]).
    pub(in crate::fusion) fn drift_test_scale(&self) -> Option<f64> {
        self.onset_scale
    }

    /// The time of the last clean anchor.
    pub(in crate::fusion) fn last_anchor_time(&self) -> Option<GpsTime> {
        self.anchors.back().map(|a| a.time)
    }

    /// Prepares a rollback's re-run from a state stored at or before the
    /// clean fix `anchor`: the fixes after it up to `onset` are the
    /// ramp's; those up to it are judged again as they were.
    pub(in crate::fusion) fn replay_ramp(&mut self, anchor: GpsTime, onset: GpsTime) {
        self.replay_onset = Some((anchor, onset));
    }

    /// Prepares a ramp end's re-run from a state stored at or before the
    /// clean fix `anchor`: the fixes after it and before `end` were the
    /// ramp's, and the fix at `end`, back at the anchor's level, ends it.
    pub(in crate::fusion) fn replay_ramp_end(&mut self, anchor: GpsTime, end: GpsTime) {
        self.replay_onset = Some((anchor, end));
        self.replay_return = Some(end);
    }

    /// A fix of the ramp (or of the false fix, [`Self::replay_false_fix_end`])
    /// in a rollback's re-run: the first opens the episode against the
    /// last anchor (the one rolled back to), the others continue it.
    pub(super) fn replay_ramp_fix(&mut self, fix: &FixView) -> Judgement {
        let (time, hph) = (fix.time, &fix.hph);
        if let Some(mut ep) = self.episode {
            let (delta, _, _) = self.test(&ep.anchor, fix);
            ep.last_delta = delta;
            ep.hph_last = hph.diagonal();
            ep.count(time, &delta);
            self.episode = Some(ep);
            return Judgement::Exclude(FaultReason::Run);
        }
        let opening = if self.replay_jump {
            FaultReason::Jump
        } else {
            FaultReason::Ramp
        };
        let Some(a) = self.anchors.back().copied() else {
            return Judgement::Exclude(opening);
        };
        let (delta, _, v) = self.test(&a, fix);
        self.pending_pair = None;
        self.open(a, time, delta, v, hph, !self.replay_jump);
        Judgement::Exclude(opening)
    }

    /// Whether the INS's horizontal drift since anchor `a` is within the
    /// fixes' own error change over the same time: there a test against
    /// `a` stands on the measured fix noise, not on the INS's drift model,
    /// which over seconds a MEMS INS leaves (the test-track drive with the
    /// ADIS16465, clean: 0.44 m in 7 s where its model said 0.19 m, 100 s
    /// into the drive).
    pub(super) fn ins_is_sharper(&self, a: &Anchor, fix: &FixView) -> bool {
        self.ins_within(a, fix, 1.0)
    }

    /// Whether the INS's horizontal drift variance since `a` is within
    /// `ratio` times the fixes' error-change variance.
    pub(super) fn ins_within(&self, a: &Anchor, fix: &FixView, ratio: f64) -> bool {
        let (time, hph, r, lambda) = (fix.time, &fix.hph, &fix.r, fix.lambda);
        let lag = time.seconds_since(a.time);
        let growth = self.ins_growth(a, lag, hph) * lambda;
        let fixes = self.fix_change_var(r, &a.r, lag);
        (0..2).all(|i| growth[i] <= ratio * fixes[i])
    }

    /// Whether the onset test holds a clean anchor at least
    /// [`ONSET_MIN_LAG_S`] back, within the fixes, against which the INS
    /// is the sharper reference ([`Self::ins_is_sharper`]).
    pub(in crate::fusion) fn ins_is_reference(&self, fix: &FixView) -> bool {
        if !self.onset_enabled
            || self.onset_scale.is_none()
            || self.anchors_since_reset < MIN_ANCHORS
        {
            return false;
        }
        self.onset_anchors(fix.time)
            .next()
            .is_some_and(|a| self.ins_is_sharper(a, fix))
    }

    /// The anchors an onset test at `time` may use, newest first: at least
    /// [`ONSET_MIN_LAG_S`] back, settled, not dragged, fitting the filter
    /// ([`Anchor::fits`]), and not across a gap in the fixes (a ramp is
    /// followed fix by fix, and a receiver's fixes around a gap move by
    /// metres: dataset2's real fixes, 2–3 m against anchors before a 6–7 s
    /// gap). None when the fix itself came after a gap.
    fn onset_anchors(&self, time: GpsTime) -> impl Iterator<Item = &Anchor> {
        let scale = self.onset_scale.unwrap_or(1.0);
        let gap_end = self.gap_end;
        let mut newer = self.anchors.back().map(|a| a.time);
        self.anchors
            .iter()
            .rev()
            .take(if self.fixes_continuous { usize::MAX } else { 0 })
            .take_while(move |a| {
                let within = newer.is_some_and(|n| n.seconds_since(a.time) <= JUMP_MAX_GAP_S)
                    && gap_end.is_none_or(|g| a.time >= g);
                newer = Some(a.time);
                within
            })
            .filter(move |a| {
                a.settled
                    && !a.dragged
                    && a.fits(scale)
                    && time.seconds_since(a.time) >= ONSET_MIN_LAG_S
            })
    }

    /// Sets the onset test's threshold scale from `onset_cal` (after it
    /// changed): the 95th percentile of the clean fixes' D over χ²₃'s, at
    /// least 1; `None` before [`ONSET_CAL_MIN`] fixes over
    /// [`ONSET_CAL_SPAN_S`].
    pub(super) fn recalibrate_onset(&mut self) {
        self.onset_scale = None;
        let (Some((first, _)), Some((last, _))) = (self.onset_cal.front(), self.onset_cal.back())
        else {
            return;
        };
        if self.onset_cal.len() < ONSET_CAL_MIN || last.seconds_since(*first) < ONSET_CAL_SPAN_S {
            return;
        }
        let mut d: Vec<f64> = self.onset_cal.iter().map(|(_, d)| *d).collect();
        let k = ((d.len() as f64) * 0.95) as usize;
        let k = k.min(d.len() - 1);
        let (_, p95, _) = d.select_nth_unstable_by(k, f64::total_cmp);
        self.onset_scale = Some((*p95 / CHI2_3_P95).max(1.0));
    }
}
