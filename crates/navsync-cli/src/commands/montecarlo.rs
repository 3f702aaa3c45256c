//! `navsync montecarlo`: the whole chain over many seeds, in parallel.

use std::path::PathBuf;

use anyhow::Result;
use navsync_sim::montecarlo::{self, McOptions};
use navsync_sim::scenario::{Scenario, base_layer, parse_override, set_path};
use serde_json::json;

#[derive(clap::Args)]
pub struct Args {
    /// A preset (demo), a built-in trajectory (test-track, urban, figure8,
    /// static) or a scenario TOML file.
    #[arg(long, default_value = "demo")]
    pub scenario: String,
    /// Number of runs (seeds FIRST_SEED, FIRST_SEED+1, …).
    #[arg(value_parser = super::args::count(1, 100_000), long, default_value_t = 50)]
    pub runs: usize,
    /// Runs in parallel [default: the number of cores].
    #[arg(value_parser = super::args::count(1, super::args::MAX_JOBS), long)]
    pub jobs: Option<usize>,
    /// Length of each run (s) [default: the scenario's].
    #[arg(value_parser = super::args::real(1.0, super::args::MAX_SPAN_S, "s"), long)]
    pub duration: Option<f64>,
    /// Seed of the first run.
    #[arg(value_parser = super::args::seed(), long, default_value_t = 1)]
    pub first_seed: u64,
    /// Folder for montecarlo.json (the runs' files go below it and are
    /// removed as each run ends).
    #[arg(long, default_value = "navsync-montecarlo")]
    pub output: PathBuf,
    /// Keep every run's files (sim/, synced/ under DIR/runs/run-SEED).
    #[arg(long)]
    pub keep_files: bool,
    /// Score the RTS-smoothed solution (`fuse --smooth`) instead of the
    /// forward filter's.
    #[arg(long)]
    pub smooth: bool,
    /// Any scenario setting as key=value (as `navsync simulate --set`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let _held = super::take_output(&args.output, "montecarlo")?;
    let mut layer = base_layer(&args.scenario)?;
    if let Some(d) = args.duration {
        set_path(&mut layer, "duration_s", json!(d))?;
    }
    for s in &args.set {
        let (k, v) = parse_override(s)?;
        set_path(&mut layer, &k, v)?;
    }
    let scn = Scenario::from_layer(layer)?;
    let jobs = super::args::jobs(args.jobs);
    let opts = McOptions {
        runs: args.runs,
        jobs,
        first_seed: args.first_seed,
        work_dir: args.output.join("runs"),
        keep_files: args.keep_files,
        smooth: args.smooth,
        ..McOptions::default()
    };
    let pb = crate::progress::bar("runs");
    let report = montecarlo::run(&scn, &opts, &|done, total| {
        crate::progress::set(&pb, done as f64 / total as f64)
    })?;
    pb.finish_and_clear();
    if !args.keep_files {
        let _ = std::fs::remove_dir(&opts.work_dir);
    }
    let path = montecarlo::write_json(&report, &args.output)?;
    println!(
        "navsync montecarlo: {} runs of {:.0} s ({}, seeds {}…{}) on {} threads in {:.1} s",
        report.runs,
        report.duration_s,
        args.scenario,
        args.first_seed,
        args.first_seed + report.runs as u64 - 1,
        jobs,
        report.wall_time_s
    );
    if let Some(t) = report.true_time_offset_s {
        println!("  true time offset {:.3} ms", t * 1e3);
    }
    print!("{}", report.table());
    println!("  wrote {}", path.display());
    Ok(())
}
