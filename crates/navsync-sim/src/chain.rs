//! The whole chain on a simulated drive, the path a user's data takes:
//! simulate (`navsync simulate`) → synchronize the raw rig log (`navsync
//! sync`) → fuse with the time-offset state (`navsync fuse
//! --estimate-time-offset`). The demo and the Monte Carlo runs are loops
//! over [`run_chain`]; scoring is [`navsync::eval`]'s.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::imu::OutputKind;
use crate::rig::SyncMode as RigSync;
use crate::scenario::Scenario;
use crate::{SimReport, Simulation};
use navsync::error::{Diagnostics, Error};
use navsync::fusion::{GnssErrorModel, TimeOffsetOptions};
use navsync::io::config::KfGinsConfig;
use navsync::pipeline::{self, FuseOptions, FuseSummary, NavSink};
use navsync::time::{GpsTime, OutageWindow};
use navsync::timing::file::{SyncSummary, sync_file, write_kfgins_config};
use navsync::timing::{RateRule, SyncConfig, SyncMode};

/// Where each stage writes.
#[derive(Clone, Debug)]
pub struct ChainDirs {
    /// The simulator's files (truth, rig.csv, …).
    pub sim: PathBuf,
    /// The synchronized KF-GINS files and `sync_report.json`.
    pub synced: PathBuf,
    /// The fusion's files (when the sink writes any).
    pub fused: PathBuf,
}

impl ChainDirs {
    /// `root/sim`, `root/synced`, `root/fused`.
    pub fn under(root: &Path) -> Self {
        ChainDirs {
            sim: root.join("sim"),
            synced: root.join("synced"),
            fused: root.join("fused"),
        }
    }
}

/// How the chain synchronizes and fuses.
#[derive(Clone, Debug)]
pub struct ChainOptions {
    pub sync: SyncConfig,
    pub rate_rule: RateRule,
    pub fuse: FuseOptions,
}

impl ChainOptions {
    /// What a user who knows the rig would choose: hardware sync when the
    /// rig has PPS (T_c subtracted for a serial-timed IMU, seed 000), the
    /// average rule for rates from an averaging IMU (seed 001 §1.3.1), and
    /// fusion with the time-offset state (and the misalignment states for
    /// an IMU whose datasheet gives a misalignment, and the receiver's
    /// time-correlated error as filter states), in the scenario's GPS week.
    pub fn for_scenario(scn: &Scenario) -> Self {
        let rig = &scn.rig;
        let sync = SyncConfig {
            mode: match rig.sync {
                RigSync::Sw => SyncMode::Sw,
                RigSync::Hybrid => SyncMode::Hybrid,
                RigSync::Hw | RigSync::Serial => SyncMode::Hw,
            },
            // The simulated rig's T_c (the log's header carries it too).
            imu_output_delay_s: (rig.sync == RigSync::Serial)
                .then_some(rig.imu_link.output_delay_s),
            ..SyncConfig::default()
        };
        let averaged = scn.imu.rates_are_interval_averages();
        let rates = rig.imu_record.unwrap_or(scn.imu.output) == OutputKind::Rate;
        let rate_rule = if rates && !averaged {
            RateRule::Trapezoid
        } else {
            RateRule::Average
        };
        // The datasheet's axis misalignment, when the IMU has one, as
        // the initial σ of the misalignment states.
        let (mg, ma) = (
            scn.imu.gyro.misalignment_deg,
            scn.imu.accel.misalignment_deg,
        );
        // The receiver's correlated error, as its error model gives it.
        let gnss = scn.gnss.resolved();
        let gnss_error = match (gnss.gm_sd_m, gnss.gm_corr_time_s) {
            (Some(sd), Some(tau)) if sd.iter().all(|s| *s > 0.0) && tau > 0.0 => {
                Some(GnssErrorModel {
                    gm_sd_m: sd,
                    corr_time_s: tau,
                })
            }
            _ => None,
        };
        let fuse = FuseOptions {
            time_offset: Some(TimeOffsetOptions::default()),
            week: scn.gps_week,
            misalignment_sd_deg: (mg > 0.0 && ma > 0.0).then_some([mg, ma]),
            gnss_error,
            ..FuseOptions::default()
        };
        ChainOptions {
            sync,
            rate_rule,
            fuse,
        }
    }
}

/// The true IMU–GNSS time offset the filter should find (s, GNSS time tag
/// − true validity, on the synchronized IMU time base): the receiver's tag
/// offset less what the IMU stamps are late by (the data-ready delay).
/// `None` for software sync, where a constant offset is unobservable.
pub fn true_time_offset_s(scn: &Scenario) -> Option<f64> {
    match scn.rig.sync {
        RigSync::Hw => Some(scn.gnss.time_offset_s - scn.rig.imu_link.data_ready_delay_s),
        RigSync::Serial => Some(scn.gnss.time_offset_s),
        RigSync::Sw | RigSync::Hybrid => None,
    }
}

/// The scenario's GNSS outages.
pub fn outage_windows(scn: &Scenario) -> Vec<OutageWindow> {
    let start = GpsTime::from_week_sow(scn.gps_week, scn.start_sow);
    scn.gnss
        .outages
        .iter()
        .map(|w| OutageWindow::new(start.add_seconds(w[0]), w[1]))
        .collect()
}

/// The stages, for progress reports.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Stage {
    Simulate,
    Sync,
    Fuse,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Simulate => "simulate",
            Stage::Sync => "sync",
            Stage::Fuse => "fuse",
        }
    }
}

/// What each stage reported.
pub struct ChainRun {
    pub sim: SimReport,
    pub sync: SyncSummary,
    pub fuse: FuseSummary,
    /// The configuration the fusion ran with (`synced/kf-gins.yaml`).
    pub config: KfGinsConfig,
    /// Wall time of each stage (s).
    pub stage_times_s: Vec<(Stage, f64)>,
}

/// Runs the chain on `sim` into `dirs`; the solution goes to `sink`.
/// `progress` gets each stage and its fraction done.
pub fn run_chain(
    sim: &Simulation,
    dirs: &ChainDirs,
    opts: &ChainOptions,
    sink: &mut dyn NavSink,
    progress: &mut dyn FnMut(Stage, f64),
) -> Result<ChainRun, Error> {
    let argv = vec![format!("navsync chain (seed {})", sim.scenario.seed)];
    let mut times = Vec::with_capacity(3);
    let t = Instant::now();
    let sim_report = sim.run(&dirs.sim, &argv, &mut |f| progress(Stage::Simulate, f))?;
    times.push((Stage::Simulate, t.elapsed().as_secs_f64()));
    progress(Stage::Sync, 0.0);
    let t = Instant::now();
    let rig = dirs.sim.join("rig.csv");
    let sync_cfg = SyncConfig {
        source: rig.display().to_string(),
        ..opts.sync.clone()
    };
    let sync = sync_file(
        &rig,
        &dirs.synced,
        sync_cfg,
        Some(opts.rate_rule),
        Some(&dirs.sim.join("imu_times_truth.txt")),
    )?;
    write_kfgins_config(&dirs.sim.join("kf-gins.yaml"), &dirs.synced, &sync.report)?;
    progress(Stage::Sync, 1.0);
    times.push((Stage::Sync, t.elapsed().as_secs_f64()));
    let t = Instant::now();
    // The file's relative paths are resolved next to it (notes only).
    let mut notes = Diagnostics::default();
    let mut config = KfGinsConfig::load(&dirs.synced.join("kf-gins.yaml"), &mut notes)?;
    config.imu_path = dirs.synced.join("imu.txt");
    config.gnss_path = dirs.synced.join("gnss.txt");
    let fuse_opts = FuseOptions {
        output_dir: Some(dirs.fused.clone()),
        ..opts.fuse.clone()
    };
    let fuse = pipeline::run(&config, &fuse_opts, sink, &mut |f| progress(Stage::Fuse, f))?;
    times.push((Stage::Fuse, t.elapsed().as_secs_f64()));
    Ok(ChainRun {
        sim: sim_report,
        sync,
        fuse,
        config,
        stage_times_s: times,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imu::Decimation;
    use crate::scenario::base_layer;

    #[test]
    fn options_follow_the_rig() {
        let mut scn = Scenario::from_layer(base_layer("demo").unwrap()).unwrap();
        let o = ChainOptions::for_scenario(&scn);
        // ADIS16465: rates averaged over the interval by DEC_RATE.
        assert_eq!(o.rate_rule, RateRule::Average);
        assert_eq!(o.sync.mode, SyncMode::Hw);
        assert!(o.fuse.time_offset.is_some());
        assert_eq!(o.fuse.week, scn.gps_week);
        assert_eq!(true_time_offset_s(&scn), Some(0.010));
        let w = outage_windows(&scn);
        assert_eq!(w.len(), 2);
        assert_eq!(w[0].start.sow(), scn.start_sow + 240.0);
        scn.imu.decimation = Decimation::Point;
        assert_eq!(
            ChainOptions::for_scenario(&scn).rate_rule,
            RateRule::Trapezoid
        );
        scn.rig.sync = RigSync::Serial;
        let o = ChainOptions::for_scenario(&scn);
        assert_eq!(
            o.sync.imu_output_delay_s,
            Some(scn.rig.imu_link.output_delay_s)
        );
        scn.rig.sync = RigSync::Sw;
        assert_eq!(ChainOptions::for_scenario(&scn).sync.mode, SyncMode::Sw);
        assert_eq!(true_time_offset_s(&scn), None);
    }
}
