//! The consistency probe: a second forward pass of the same data with the
//! errors a sensor sheet usually leaves fixed estimated as states (the
//! IMU–GNSS time offset and the antenna lever arm), so that the verdict can
//! say whether the sheet's values fit the data.
//!
//! Why a second pass and not only a test of the innovations: the filter
//! absorbs a constant error into its position with its own gain, and with a
//! MEMS IMU (a large P⁻, a gain near 1) almost all of it, so the
//! innovations of the run itself hardly show a GNSS tag 10 ms late (a
//! seventh of the runs with a loss above 5× passed the innovation tests on
//! the verdict's labelled bed, docs/report.md). Estimated as a state, the
//! offset is observed through the whole drive (v·δt along the track, which
//! changes with the speed), as the filter would estimate it (Groves 2013,
//! §14.1.5: an unmodelled time-tag error; augmentation of the state with
//! the suspect parameter); the lever arm likewise through the heading
//! changes (`fusion::aid::lever_arm`, Groves 2013 §14.2.7). Estimated
//! together, a forward antenna error and a late tag (both along the track
//! at a steady speed) share what the drive cannot separate, and their σ
//! say so.
//!
//! The probe writes nothing but its figures: its solution is discarded
//! (a [`NullSink`]); the run's own files stay what the user asked for.

use serde::Serialize;

use crate::error::Error;
use crate::io::config::KfGinsConfig;
use crate::navigator::NullSink;
use crate::pipeline::{FuseOptions, run};

/// Initial σ of the probe's lever-arm states (m): a sheet's lever arm is
/// a tape measurement or a default of zero; half a metre covers a
/// mis-measured or forgotten antenna on a car (the states' default).
pub const PROBE_LEVER_ARM_SD_M: f64 = 0.5;

/// What the probe found (`probe.json` of `navsync process`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ProbeResult {
    /// The final IMU–GNSS time-offset estimate (GNSS tag − true validity,
    /// s) and its σ, when the main run did not estimate it itself.
    pub time_offset_s: Option<f64>,
    /// σ of `time_offset_s` (s).
    pub time_offset_sd_s: Option<f64>,
    /// The lever-arm states' estimate against the sheet's, when the main
    /// run did not estimate it itself.
    pub lever_arm: Option<crate::fusion::LeverArmSummary>,
    /// Wall time of the probe (s).
    pub run_time_s: f64,
    /// What was estimated and why, for the reader of the file.
    pub note: String,
}

/// Runs the probe for a run made with `opts` on `cfg`: `None` when there is
/// nothing to probe (the run estimated every probed state itself).
pub fn run_probe(cfg: &KfGinsConfig, opts: &FuseOptions) -> Result<Option<ProbeResult>, Error> {
    let probe_offset = opts.time_offset.is_none();
    let probe_lever = opts.lever_arm_sd_m.is_none();
    if !probe_offset && !probe_lever {
        return Ok(None);
    }
    let mut probe = opts.clone();
    if probe_offset {
        probe.time_offset = Some(crate::fusion::TimeOffsetOptions::default());
    }
    if probe_lever {
        probe.lever_arm_sd_m = Some(PROBE_LEVER_ARM_SD_M);
    }
    // Without the axis misalignments as states the offset's σ is about 2×
    // optimistic (docs/offset: the NEES of 50 simulated runs), and the
    // estimate takes up what they leave: estimate them too, at the
    // datasheet's σ (the same figure for the gyro triad, for want of one).
    if probe.misalignment_sd_deg.is_none()
        && let Some(m) = opts.accel_misalignment_sd_deg.filter(|m| *m > 0.0)
    {
        probe.misalignment_sd_deg = Some([m, m]);
    }
    probe.smooth = None;
    probe.output_gnss_time = false;
    probe.output_at = None;
    probe.dry_run = false;
    let summary = run(cfg, &probe, &mut NullSink, &mut |_| {})?;
    let estimated = match (probe_offset, probe_lever) {
        (true, true) => "the IMU–GNSS time offset and the antenna lever arm",
        (true, false) => "the IMU–GNSS time offset",
        _ => "the antenna lever arm",
    };
    Ok(Some(ProbeResult {
        time_offset_s: summary.time_offset_s.filter(|_| probe_offset),
        time_offset_sd_s: summary.time_offset_sd_s.filter(|_| probe_offset),
        lever_arm: summary.lever_arm.filter(|_| probe_lever),
        run_time_s: summary.run_time_s,
        note: format!(
            "a second forward pass with {estimated} (and the axis misalignments) estimated as \
             states; its solution is discarded: the verdict compares the estimates with the \
             sheet's"
        ),
    }))
}
