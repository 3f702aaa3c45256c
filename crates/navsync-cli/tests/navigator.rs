//! The streaming navigator fed raw rig-log records one at a time (as a
//! live logger would deliver them) against the batch chain on the same
//! simulated drive: causal synchronization and a delayed-state filter
//! must navigate as well as files synchronized and fused offline.

mod common;

use common::{bin, run, temp_dir};
use navsync::error::Diagnostics;
use navsync::eval::{EpochError, TruthScorer};
use navsync::ins::{ImuErrors, NavState};
use navsync::io::config::KfGinsConfig;
use navsync::io::riglog::{RigLogReader, RigRecord};
use navsync::navigator::NavSink;
use navsync::navigator::Navigator;
use navsync::pipeline::{FuseOptions, fusion_config};
use navsync::timing::{SyncConfig, SyncMode};
use navsync::{Error, GpsTime};

/// Scores every solution against the truth as it comes.
struct Scoring {
    scorer: TruthScorer,
    sum_h2: f64,
    n: usize,
    last: Option<GpsTime>,
    backwards: usize,
}

impl NavSink for Scoring {
    fn nav(&mut self, nav: &NavState, _: &ImuErrors) -> Result<(), Error> {
        if self.last.is_some_and(|t| nav.time <= t) {
            self.backwards += 1;
            return Ok(());
        }
        self.last = Some(nav.time);
        if let Some(EpochError { pos_ned_m, .. }) = self.scorer.score(nav)? {
            self.sum_h2 += pos_ned_m.x.powi(2) + pos_ned_m.y.powi(2);
            self.n += 1;
        }
        Ok(())
    }
}

#[test]
fn streamed_rig_records_navigate_like_the_batch_chain() {
    let dir = temp_dir("demo");
    let (ok, out, err) = run(bin().args(["demo", "--output"]).arg(&dir));
    assert!(ok, "demo failed: {out}\n{err}");
    let batch: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval.json")).unwrap()).unwrap();
    let batch_rms = batch["pos_horizontal_m"]["rms"].as_f64().unwrap();
    let rig = dir.join("sim/rig.csv");
    let mut diag = Diagnostics::with_cap(100);
    let cfg = KfGinsConfig::load(&dir.join("synced/kf-gins.yaml"), &mut diag).unwrap();
    let mut week = None;
    let mut scan = RigLogReader::open(&rig, &mut diag).unwrap();
    while let Some((r, _)) = scan.next_record(&mut diag).unwrap() {
        if let RigRecord::Gnss(g) = r {
            week = Some(g.time.week());
            break;
        }
    }
    // The batch chain's fusion settings for this scenario (time-offset,
    // misalignment and correlated-GNSS-error states).
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("sim/scenario.json")).unwrap())
            .unwrap();
    let scenario: navsync_sim::scenario::Scenario =
        serde_json::from_value(written["scenario"].clone()).unwrap();
    let opts: FuseOptions = navsync_sim::chain::ChainOptions::for_scenario(&scenario).fuse;
    assert_eq!(Some(opts.week), week);
    let mut reader = RigLogReader::open(&rig, &mut diag).unwrap();
    let sync = SyncConfig {
        mode: SyncMode::Auto,
        causal: true,
        ..SyncConfig::default()
    };
    let mut nav = Navigator::new(fusion_config(&cfg, &opts)).with_rig_sync(reader.header(), sync);
    let mut sink = Scoring {
        scorer: TruthScorer::open(&dir.join("sim/truth.nav")).unwrap(),
        sum_h2: 0.0,
        n: 0,
        last: None,
        backwards: 0,
    };
    let (mut records, mut imu_records) = (0usize, 0usize);
    while let Some((r, _)) = reader.next_record(&mut diag).unwrap() {
        records += 1;
        imu_records += usize::from(matches!(r, RigRecord::Imu { .. }));
        nav.push_record(r, &mut sink).unwrap();
    }
    let end = nav.finish(&mut sink).unwrap();
    let rms = (sink.sum_h2 / sink.n as f64).sqrt();
    eprintln!(
        "{records} records, {} solutions scored, {} fixes weighed, horizontal RMS {rms:.3} m, {} backwards",
        sink.n,
        end.fix_records.len(),
        sink.backwards
    );
    assert!(end.sync_report.is_some(), "the engine's report");
    assert_eq!(sink.backwards, 0, "solutions out of time order");
    // Every IMU record gives a scored solution but the first two (rates
    // need two samples; the filter starts at the first increment) and the
    // few the simulator spoilt.
    assert!(
        sink.n + 10 >= imu_records,
        "{} solutions of {imu_records}",
        sink.n
    );
    // The drive has 600 fixes less two 30 s outages: all weighed.
    assert!(
        end.fix_records.len() >= 530,
        "{} fixes",
        end.fix_records.len()
    );
    // Causal stamps (µs) and a delayed-state update (exact) lose nothing
    // that matters against offline synchronization and fusion: measured
    // 0.260 m against 0.259 m.
    assert!(
        rms <= 1.1 * batch_rms,
        "streamed {rms:.3} m vs batch {batch_rms:.3} m"
    );
    // The receiver's 10 ms late tags are found in the stream too.
    let tau = nav.fusion().time_offset().expect("time-offset state");
    assert!(
        (tau.offset_s - 0.010).abs() < 3.0 * tau.sd_s.max(5e-4),
        "τ {:.4} ± {:.4} s",
        tau.offset_s,
        tau.sd_s
    );
}

#[test]
fn gnss_time_output_never_steps_back() {
    // On GNSS time the solution is stamped IMU time + τ̂; the coarse search
    // and early updates move τ̂ by more than the 5 ms sample interval (the
    // demo's run did, twice), and the written file must stay in order.
    let dir = temp_dir("gnss-time");
    let (ok, out, err) = run(bin().args(["demo", "--output"]).arg(&dir));
    assert!(ok, "demo failed: {out}\n{err}");
    let fused = dir.join("gnss-time");
    let (ok, out, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(dir.join("synced/kf-gins.yaml"))
        .args([
            "--estimate-time-offset",
            "--time-offset-search",
            "0.5",
            "--time-base",
            "gnss",
            "--output",
        ])
        .arg(&fused));
    assert!(ok, "fuse failed: {out}\n{err}");
    let text = std::fs::read_to_string(fused.join("navresult.nav")).unwrap();
    let times: Vec<f64> = text
        .lines()
        .filter_map(|l| l.split_whitespace().nth(1)?.parse().ok())
        .collect();
    assert!(times.len() > 100_000, "{} solutions", times.len());
    let back = times.windows(2).filter(|w| w[1] <= w[0]).count();
    assert_eq!(back, 0, "solutions not after their predecessor");
}
