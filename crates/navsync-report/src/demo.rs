//! `navsync demo`: the built-in drive through the whole chain — simulate,
//! synchronize the raw rig log, fuse with the time-offset state, score
//! against the truth — and its report, with every file beside it.
//!
//! Layout of the output folder: `sim/` (the simulator's files: truth,
//! rig.csv, …), `synced/` (imu.txt, gnss.txt, sync_report.json,
//! kf-gins.yaml), `fused/` (navresult.nav, imu_err.txt, std.txt,
//! time_offset.txt, summary.json), `eval.json` (as `navsync eval --json`),
//! `demo.json` (the summary below) and `report.html`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use navsync::Error;
use navsync::eval::EvalReport;
use navsync::pipeline::KfGinsSink;
use navsync_sim::Simulation;
use navsync_sim::chain::{ChainDirs, ChainOptions, outage_windows, run_chain, true_time_offset_s};
use navsync_sim::scenario::{Scenario, base_layer, set_path};
use serde::Serialize;

use crate::inputs::ReportInputs;

/// What to run.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    pub output: PathBuf,
    /// Length of the drive (s) [default: the preset's 600 s].
    pub duration_s: Option<f64>,
    pub seed: Option<u64>,
}

/// The demo's figures (written as `demo.json`).
#[derive(Clone, Debug, Serialize)]
pub struct DemoSummary {
    pub scenario: String,
    pub seed: u64,
    pub duration_s: f64,
    pub imu: String,
    /// IMU stamps against their true times (µs).
    pub sync_rms_us: Option<f64>,
    pub sync_max_us: Option<f64>,
    /// The longest holdover (s) and the largest stamp-error bound in it (µs).
    pub longest_holdover_s: Option<f64>,
    pub holdover_bound_us: Option<f64>,
    pub pps_rejected: u64,
    /// Measured GNSS latency (ms): min, median, max.
    pub gnss_latency_ms: [Option<f64>; 3],
    pub pos_horizontal_rms_m: f64,
    pub pos_3d_rms_m: f64,
    pub vel_3d_rms_mps: f64,
    pub att_rms_deg: [f64; 3],
    pub outages: usize,
    pub outage_rms_max_horizontal_m: Option<f64>,
    pub outage_worst_horizontal_m: Option<f64>,
    pub time_offset_ms: Option<f64>,
    pub time_offset_sd_ms: Option<f64>,
    pub time_offset_truth_ms: Option<f64>,
    /// Wall time of each stage (s) and of the whole run.
    pub stage_times_s: Vec<(String, f64)>,
    pub total_time_s: f64,
}

impl DemoSummary {
    /// The summary as a short table.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let opt = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |x| format!("{x:.d$}"));
        let mut row = |k: &str, v: String| {
            let _ = writeln!(s, "  {k:<44} {v}");
        };
        row(
            "IMU stamp error vs truth (RMS / max)",
            format!(
                "{} / {} µs",
                opt(self.sync_rms_us, 3),
                opt(self.sync_max_us, 3)
            ),
        );
        if let (Some(h), Some(b)) = (self.longest_holdover_s, self.holdover_bound_us) {
            row(
                "longest 1PPS holdover, its stamp bound",
                format!("{h:.0} s, ≤ {b:.2} µs"),
            );
        }
        row("1PPS pulses rejected", self.pps_rejected.to_string());
        let [a, m, b] = self.gnss_latency_ms;
        row(
            "GNSS latency measured (min / median / max)",
            format!("{} / {} / {} ms", opt(a, 1), opt(m, 1), opt(b, 1)),
        );
        row(
            "position RMS (horizontal / 3D)",
            format!(
                "{:.3} / {:.3} m",
                self.pos_horizontal_rms_m, self.pos_3d_rms_m
            ),
        );
        row(
            "velocity RMS (3D)",
            format!("{:.4} m/s", self.vel_3d_rms_mps),
        );
        row(
            "attitude RMS (roll / pitch / yaw)",
            format!(
                "{:.4} / {:.4} / {:.4} deg",
                self.att_rms_deg[0], self.att_rms_deg[1], self.att_rms_deg[2]
            ),
        );
        if let (Some(r), Some(w)) = (
            self.outage_rms_max_horizontal_m,
            self.outage_worst_horizontal_m,
        ) {
            row(
                &format!(
                    "GNSS-outage drift ({} outages, RMS of max horizontal)",
                    self.outages
                ),
                format!("{r:.3} m (worst {w:.3} m)"),
            );
        }
        if let (Some(o), Some(sd)) = (self.time_offset_ms, self.time_offset_sd_ms) {
            row(
                "time offset estimate (GNSS tag − validity)",
                format!(
                    "{o:.3} ± {sd:.3} ms{}",
                    self.time_offset_truth_ms
                        .map(|t| format!(" (truth {t:.3} ms)"))
                        .unwrap_or_default()
                ),
            );
        }
        s
    }
}

/// What the demo produced.
pub struct DemoOutcome {
    pub summary: DemoSummary,
    pub eval: EvalReport,
    pub report_path: PathBuf,
    /// The `navsync report` command that rebuilds the report from the files.
    pub report_command: String,
}

fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<(), Error> {
    let json = serde_json::to_string_pretty(v).map_err(|e| Error::Invalid(e.to_string()))?;
    navsync::io::output::write_file(path, json)
}

/// The demo scenario with the options applied.
pub fn demo_scenario(opts: &DemoOptions) -> Result<Scenario, Error> {
    let mut layer = base_layer("demo")?;
    if let Some(d) = opts.duration_s {
        set_path(&mut layer, "duration_s", serde_json::json!(d))?;
    }
    if let Some(s) = opts.seed {
        set_path(&mut layer, "seed", serde_json::json!(s))?;
    }
    Scenario::from_layer(layer)
}

/// Runs the demo; `progress(stage, fraction)` reports each stage.
pub fn run_demo(
    opts: &DemoOptions,
    progress: &mut dyn FnMut(&str, f64),
) -> Result<DemoOutcome, Error> {
    let started = Instant::now();
    let scn = demo_scenario(opts)?;
    let sim = Simulation::new(scn.clone())?;
    let dirs = ChainDirs::under(&opts.output);
    let chain = ChainOptions::for_scenario(&scn);
    let mut sink = KfGinsSink::create(&dirs.fused, chain.fuse.week)?;
    let run = run_chain(&sim, &dirs, &chain, &mut sink, &mut |stage, f| {
        progress(stage.name(), f)
    })?;
    sink.finish()?;
    let mut times: Vec<(String, f64)> = run
        .stage_times_s
        .iter()
        .map(|(s, t)| (s.name().to_string(), *t))
        .collect();
    write_json(&dirs.fused.join("summary.json"), &run.fuse)?;

    progress("report", 0.0);
    let t_report = Instant::now();
    let tau_true = true_time_offset_s(&scn);
    let outages = outage_windows(&scn);
    let truth = dirs.sim.join("truth.nav");
    let inputs = ReportInputs {
        title: format!(
            "navsync demo: {:.0} s test-track drive, ADIS16465 at {} Hz, hardware-synchronized logger",
            sim.duration_s(),
            scn.imu.output_rate_hz
        ),
        truth: Some(truth.clone()),
        nav: dirs.fused.join("navresult.nav"),
        sync_report: Some(dirs.synced.join("sync_report.json")),
        summary: Some(dirs.fused.join("summary.json")),
        std: Some(dirs.fused.join("std.txt")),
        imu_err: Some(dirs.fused.join("imu_err.txt")),
        imu_err_truth: Some(dirs.sim.join("imu_err_truth.txt")),
        gnss: Some(dirs.synced.join("gnss.txt")),
        time_offset: Some(dirs.fused.join("time_offset.txt")),
        gnss_residuals: Some(dirs.fused.join("gnss_residuals.txt")).filter(|p| p.is_file()),
        time_offset_truth_s: tau_true,
        outages: outages.clone(),
        ..ReportInputs::default()
    };
    let report = crate::build(&inputs)?;
    let Some(eval) = report.eval else {
        return Err(Error::Invalid(
            "the demo's report was built without its truth".into(),
        ));
    };
    let report_path = opts.output.join("report.html");
    navsync::io::output::write_file(&report_path, &report.html)?;
    write_json(&opts.output.join("eval.json"), &eval)?;
    times.push(("report".into(), t_report.elapsed().as_secs_f64()));
    progress("report", 1.0);

    let e = &eval;
    let s = &run.sync.report;
    let longest = s
        .holdover
        .iter()
        .max_by(|a, b| a.duration_s.total_cmp(&b.duration_s));
    let rejected = s.pps.as_ref().map_or(0, |p| {
        p.counts.rejected_spurious + p.counts.rejected_displaced + p.counts.rejected_duplicate
    });
    let l = &s.gnss.latency_ms;
    let summary = DemoSummary {
        scenario: "demo (test-track)".into(),
        seed: scn.seed,
        duration_s: sim.duration_s(),
        imu: format!("{} at {} Hz", scn.imu.grade, scn.imu.output_rate_hz),
        sync_rms_us: s.truth.as_ref().map(|t| t.rms_us),
        sync_max_us: s.truth.as_ref().map(|t| t.max_abs_us),
        longest_holdover_s: longest.map(|h| h.duration_s),
        holdover_bound_us: longest.map(|h| h.max_bound_us),
        pps_rejected: rejected,
        gnss_latency_ms: [l.min, l.median, l.max],
        pos_horizontal_rms_m: e.pos_horizontal_m.rms,
        pos_3d_rms_m: e.pos_3d_m.rms,
        vel_3d_rms_mps: e.vel_3d_mps.rms,
        att_rms_deg: [e.roll_deg.rms, e.pitch_deg.rms, e.yaw_deg.rms],
        outages: e.outages.len(),
        outage_rms_max_horizontal_m: e.outage_rms_max_horizontal_m,
        outage_worst_horizontal_m: e.outage_worst_horizontal_m,
        time_offset_ms: run.fuse.time_offset_s.map(|v| v * 1e3),
        time_offset_sd_ms: run.fuse.time_offset_sd_s.map(|v| v * 1e3),
        time_offset_truth_ms: tau_true.map(|v| v * 1e3),
        stage_times_s: times,
        total_time_s: started.elapsed().as_secs_f64(),
    };
    write_json(&opts.output.join("demo.json"), &summary)?;
    let d = |p: &Path| p.display().to_string();
    let report_command = format!(
        "navsync report --truth {} --nav {} --sync-report {} --std {} --imu-err {} --imu-err-truth {} --gnss {} --outages {} --time-offset-truth {} --output {}",
        d(&truth),
        d(&inputs.nav),
        d(&dirs.synced.join("sync_report.json")),
        d(&dirs.fused.join("std.txt")),
        d(&dirs.fused.join("imu_err.txt")),
        d(&dirs.sim.join("imu_err_truth.txt")),
        d(&dirs.synced.join("gnss.txt")),
        outages
            .iter()
            .map(|w| w.to_string())
            .collect::<Vec<_>>()
            .join(","),
        tau_true.unwrap_or(0.0),
        d(&report_path)
    );
    Ok(DemoOutcome {
        summary,
        eval,
        report_path,
        report_command,
    })
}
