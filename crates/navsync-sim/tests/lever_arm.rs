//! The antenna lever-arm states on simulated drives (issue 34 item 1):
//! the sheet saying [0, 0, 0] while the antenna is at [0.4, −0.3, −0.8] m.
//! The drive is simulated and synchronized once (`chain::run_chain`), then
//! fused with the right sheet, the zero sheet, and the zero sheet with the
//! lever-arm states; every solution is scored against the truth.

use std::path::Path;

use navsync::error::Error;
use navsync::eval::TruthScorer;
use navsync::fusion::LeverArmSummary;
use navsync::ins::{ImuErrors, NavState};
use navsync::io::config::KfGinsConfig;
use navsync::pipeline::{self, FuseOptions, NavSink, NullSink};
use navsync::testfiles::TestDir;
use navsync_sim::Simulation;
use navsync_sim::chain::{ChainDirs, ChainOptions, run_chain};
use navsync_sim::scenario::Scenario;

const TRUE_LEVER_M: [f64; 3] = [0.4, -0.3, -0.8];

/// Horizontal RMS error of a solution against the truth.
struct Scorer {
    truth: TruthScorer,
    sum_sq: f64,
    n: usize,
}

impl NavSink for Scorer {
    fn nav(&mut self, nav: &NavState, _: &ImuErrors) -> Result<(), Error> {
        if let Some(e) = self.truth.score(nav)? {
            self.sum_sq += e.pos_ned_m.x.powi(2) + e.pos_ned_m.y.powi(2);
            self.n += 1;
        }
        Ok(())
    }
}

/// Fuses `cfg` with `opts` (no files written) and returns the horizontal
/// RMS (m) and the lever-arm summary.
fn fuse(cfg: &KfGinsConfig, opts: &FuseOptions, truth: &Path) -> (f64, Option<LeverArmSummary>) {
    let mut sink = Scorer {
        truth: TruthScorer::open(truth).unwrap(),
        sum_sq: 0.0,
        n: 0,
    };
    let opts = FuseOptions {
        dry_run: true,
        ..opts.clone()
    };
    let s = pipeline::run(cfg, &opts, &mut sink, &mut |_| {}).unwrap();
    assert!(sink.n > 1000, "{} epochs scored", sink.n);
    ((sink.sum_sq / sink.n as f64).sqrt(), s.lever_arm)
}

/// The configuration as a user with an unmeasured lever arm writes it:
/// the chain's `kf-gins.yaml` with `antlever: [0, 0, 0]`.
fn zero_lever(cfg: &KfGinsConfig) -> KfGinsConfig {
    let path = cfg.path.with_file_name("kf-gins-zero-lever.yaml");
    let text = std::fs::read_to_string(&cfg.path).unwrap();
    assert!(text.contains("antlever:"), "{text}");
    let text: String = text
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("antlever:") {
                "antlever: [0.0, 0.0, 0.0]\n".to_string()
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    std::fs::write(&path, text).unwrap();
    let mut notes = navsync::error::Diagnostics::default();
    let mut zero = KfGinsConfig::load(&path, &mut notes).unwrap();
    zero.imu_path = cfg.imu_path.clone();
    zero.gnss_path = cfg.gnss_path.clone();
    zero
}

/// Right sheet, zero sheet, zero sheet + states on `trajectory` with `imu`.
fn three_runs(trajectory: &str, imu: &str) -> (f64, f64, f64, f64, LeverArmSummary) {
    let dir = TestDir::new("lever-arm");
    let layer = serde_json::json!({
        "trajectory": trajectory,
        "duration_s": 300.0,
        "seed": 1,
        "imu": { "grade": imu },
        "gnss": { "lever_arm_m": TRUE_LEVER_M },
    });
    let scn = Scenario::from_layer(layer).unwrap();
    let sim = Simulation::new(scn.clone()).unwrap();
    let dirs = ChainDirs::under(&dir);
    let chain = ChainOptions::for_scenario(&scn);
    let run = run_chain(&sim, &dirs, &chain, &mut NullSink, &mut |_, _| {}).unwrap();
    let truth = dirs.sim.join("truth.nav");
    let right = run.config.clone();
    let zero = zero_lever(&run.config);
    let (rms_right, none) = fuse(&right, &chain.fuse, &truth);
    assert!(none.is_none(), "no lever-arm summary without the states");
    let (rms_zero, _) = fuse(&zero, &chain.fuse, &truth);
    let with_states = FuseOptions {
        lever_arm_sd_m: Some(0.5),
        ..chain.fuse.clone()
    };
    let (rms_est, lever) = fuse(&zero, &with_states, &truth);
    let (rms_right_est, l_right) = fuse(&right, &with_states, &truth);
    assert!(
        !l_right.unwrap().significant,
        "the right sheet is confirmed"
    );
    (rms_right, rms_zero, rms_est, rms_right_est, lever.unwrap())
}

/// The horizontal components are estimated within 3σ of the truth and
/// their σ says they were observed; the solution comes back to within
/// 1.5× the right sheet's, the zero sheet's is 5× worse; on the right
/// sheet the states cost under 45 %.
fn check(trajectory: &str, imu: &str) {
    let (right, zero, est, right_est, l) = three_runs(trajectory, imu);
    let msg = format!(
        "{trajectory} {imu}: horizontal RMS right {right:.3} m, zero {zero:.3} m, estimated {est:.3} m, \
         right + states {right_est:.3} m; {l:#?}"
    );
    eprintln!("{msg}");
    for (k, truth) in TRUE_LEVER_M.iter().enumerate().take(2) {
        assert!(l.observed[k], "{msg}");
        let err = (l.estimate_m[k] - truth).abs();
        assert!(err < 3.0 * l.sd_m[k], "component {k}: {msg}");
        assert!(l.sd_m[k] < 0.1, "{msg}");
    }
    assert!(
        l.significant && l.note.contains("differs from the sheet"),
        "{msg}"
    );
    // Measured (seed 1, 300 s): estimated / right 1.39 (test track) and
    // 1.29 (urban), zero / estimated 8.8 and 7.1, right + states / right
    // 1.34 and 1.27: the states cost the σ of their estimate (1.5–2 cm).
    assert!(est < 1.5 * right, "{msg}");
    assert!(zero > 5.0 * est, "{msg}");
    assert!(right_est < 1.45 * right, "{msg}");
    // The down component is a consider state: never updated, its σ kept.
    assert!(
        !l.observed[2] && l.estimate_m[2] == 0.0 && l.sd_m[2] > 0.45,
        "{msg}"
    );
}

#[test]
fn lever_arm_states_recover_a_zero_sheet_on_the_test_track_adis16465() {
    check("test-track", "adis16465");
}

#[test]
fn lever_arm_states_recover_a_zero_sheet_on_urban_icm20602() {
    check("urban", "icm20602");
}

/// A straight road at a steady speed does not observe the forward
/// component (a constant offset along the track, the time-offset state's
/// signature too): its σ stays near the initial one and the summary says
/// so (no false confidence). The right component is observed here only
/// through the truth-given initial position (σ 5 cm), and found.
#[test]
fn a_straight_road_does_not_observe_the_lever_arm() {
    let dir = TestDir::new("lever-straight");
    let layer = serde_json::json!({
        "initial_speed_mps": 15.0,
        "segments": [{ "kind": "cruise", "duration_s": 120.0 }],
        "seed": 2,
        "imu": { "grade": "adis16465" },
        "gnss": { "lever_arm_m": TRUE_LEVER_M },
    });
    let scn = Scenario::from_layer(layer).unwrap();
    let sim = Simulation::new(scn.clone()).unwrap();
    let dirs = ChainDirs::under(&dir);
    let chain = ChainOptions::for_scenario(&scn);
    let run = run_chain(&sim, &dirs, &chain, &mut NullSink, &mut |_, _| {}).unwrap();
    let zero = zero_lever(&run.config);
    let opts = FuseOptions {
        lever_arm_sd_m: Some(0.5),
        ..chain.fuse.clone()
    };
    let (_, l) = fuse(&zero, &opts, &dirs.sim.join("truth.nav"));
    let l = l.unwrap();
    assert!(!l.observed[0] && l.sd_m[0] > 0.45, "{l:#?}");
    assert!(
        l.note
            .contains("forward and down components are not observed"),
        "{l:#?}"
    );
    assert!(
        (l.estimate_m[1] - TRUE_LEVER_M[1]).abs() < 3.0 * l.sd_m[1],
        "{l:#?}"
    );
}
