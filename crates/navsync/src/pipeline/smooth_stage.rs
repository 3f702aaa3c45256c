//! The smoothing stage of a batch run: the fixed-interval smoother over the
//! forward pass's nodes (`crate::smoother`), the fixes re-judged where the
//! fault monitor judged them (`crate::rejudge`), and the smoothed solution
//! written at the forward run's epochs.

use super::*;
use crate::fusion::fix_correlation::FixSumsTimeline;
use crate::fusion::jump_doubt::{JumpDoubt, doubt_covariance};
use crate::navigator::widen_position;

/// What the forward pass leaves for the smoother.
pub(super) struct ForwardResult<'a> {
    pub fusion: &'a mut Fusion,
    /// Every GNSS observation the forward filter weighed.
    pub records: &'a [FixRecord],
    /// The fixes handed to the filter.
    pub fixes: &'a [GnssFix],
    /// The run's first epoch.
    pub t0: GpsTime,
    /// When the run started (for the stage's times).
    pub started: Instant,
}

/// Smooths the forward pass, re-judging its fixes with the robust
/// weighting (each further pass reruns [`forward_pass`] on `input` with
/// the decisions), and writes the smoothed solution and its fix records to
/// `out`; the re-judgement's counts go to `stats`, its notes to `diag`.
pub(super) fn smooth_stage(
    input: &PassInput,
    fc: &FusionConfig,
    forward: ForwardResult,
    out: &mut dyn NavSink,
    stats: &mut FusionStats,
    diag: &mut Diagnostics,
) -> Result<SmootherSummary, Error> {
    let ForwardResult {
        fusion,
        records,
        fixes,
        t0,
        started,
    } = forward;
    let forward_s = started.elapsed().as_secs_f64();
    let temp_bytes = fusion.smoother_record().map(|r| r.1).unwrap_or(0);
    let tau_index = fusion.state_layout().index_of("time_offset");
    let undecided = fusion.undecided_jumps();
    let correlated_share = fusion.correlated_fix_share();
    // The smoother re-judges the fixes where the fault monitor judged them
    // (robust weighting): `crate::rejudge`.
    let judged = matches!(fc.gnss_weighting, GnssWeighting::Robust(_));
    let (mut smoothed, smoothed_records, rejudge) = if judged {
        let lever = fc.antenna_lever_b;
        let rerun = |decisions| {
            let mut fc2 = fc.clone();
            fc2.gnss_decisions = Some(std::sync::Arc::new(decisions));
            let mut scratch = Diagnostics::with_cap(10);
            let p = forward_pass(input, fc2, &mut NullSink, &mut scratch, &mut |_| {})?;
            Ok((p.fusion, p.stream.fix_records))
        };
        let r = crate::rejudge::smooth_rejudged(fusion, records, fixes, &lever, rerun)?;
        diag.extend(r.3);
        (r.0, r.1, Some(r.2))
    } else {
        (fusion.smooth()?, records.to_vec(), None)
    };
    if let Some(r) = &rejudge {
        stats.gnss_smoother_excluded = r.excluded;
        stats.gnss_smoother_readmitted = r.readmitted;
        stats.gnss_smoother_passes = r.passes;
    }
    if !input.opts.dry_run {
        out.fix_records(&smoothed_records)?;
    }
    let times = SmoothTimes {
        started,
        forward_s,
        temp_bytes,
    };
    let widen = Widening {
        undecided: &undecided,
        correlated: correlated_share
            .map(|share| (share, FixSumsTimeline::from_records(&smoothed_records))),
    };
    write_smoothed(
        &mut smoothed,
        tau_index,
        &widen,
        input.opts,
        out,
        Some(t0),
        times,
    )
}

/// What the smoothed σ carry beyond the smoother's covariance.
struct Widening<'a> {
    /// The jumps the data ended before the fixes decided
    /// (`fusion::jump_doubt`): no fix after them tells the smoother either.
    undecided: &'a [JumpDoubt],
    /// The fixes' error that outlasts their spacing, at the share measured
    /// at the run's end (`fusion::fix_correlation`).
    correlated: Option<(Vector3<f64>, FixSumsTimeline)>,
}

impl Widening<'_> {
    /// Widens the auxiliary line of the smoothed solution at `t`.
    fn apply(&self, aux: &mut crate::navigator::AuxLine, t: GpsTime) {
        if let Some((share, sums)) = &self.correlated
            && let Some(extra) = sums.at(t).and_then(|s| s.consider(share, &aux.1))
        {
            widen_position(aux, &extra);
        }
        if let Some(extra) = doubt_covariance(self.undecided, t) {
            widen_position(aux, &extra);
        }
    }
}

/// Times and sizes of the smoothing, for its summary.
struct SmoothTimes {
    started: Instant,
    forward_s: f64,
    temp_bytes: u64,
}

/// The smoother's backward pass, then the smoothed solution through `sink`
/// at every forward epoch (the same epochs, `--output-at` and auxiliary
/// lines as the forward run).
fn write_smoothed(
    smoothed: &mut Smoothed,
    tau_index: Option<usize>,
    widen: &Widening,
    opts: &FuseOptions,
    sink: &mut dyn NavSink,
    t0: Option<GpsTime>,
    times: SmoothTimes,
) -> Result<SmootherSummary, Error> {
    let SmoothTimes {
        started,
        forward_s,
        temp_bytes,
    } = times;
    let backward_s = started.elapsed().as_secs_f64() - forward_s;
    // The forward run's output rules (GNSS time, output-at epochs, the
    // auxiliary interval from the start sample on).
    let mut output = SolutionOutput::new(
        opts.output_gnss_time,
        Some(opts.aux_interval_s),
        output_at_interpolator(opts)?,
    );
    if let Some(t) = t0 {
        output.start(t);
    }
    let mut start_offset: Option<(f64, f64)> = None;
    smoothed.for_each(|ep| {
        let offset = tau_index.map(|i| TimeOffsetState {
            offset_s: ep.time_offset_s,
            sd_s: ep.sd[i],
            observable: true,
        });
        if start_offset.is_none() {
            start_offset = offset.map(|o| (o.offset_s, o.sd_s));
        }
        let mut aux = output
            .take_aux_due(ep.nav.time)
            .then(|| (ep.sd.clone(), ep.p_pos, offset));
        if let Some(aux) = aux.as_mut() {
            widen.apply(aux, ep.nav.time);
        }
        output.write(&ep.nav, &ep.imu, offset, sink, aux)?;
        Ok(())
    })?;
    output.finish();
    Ok(SmootherSummary {
        nodes: smoothed.node_count(),
        regularised_nodes: smoothed.failures,
        epochs: smoothed.epochs(),
        temp_bytes,
        forward_s,
        backward_s,
        output_s: started.elapsed().as_secs_f64() - forward_s - backward_s,
        time_offset_start_s: start_offset.map(|o| o.0),
        time_offset_start_sd_s: start_offset.map(|o| o.1),
    })
}
