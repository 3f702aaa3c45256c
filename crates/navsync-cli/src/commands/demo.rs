//! `navsync demo`: the built-in drive through simulate → sync → fuse →
//! eval, and its HTML report.

use std::collections::HashMap;
use std::path::PathBuf;

use super::args;
use anyhow::Result;
use indicatif::ProgressBar;
use navsync_report::demo::{DemoOptions, run_demo};

#[derive(clap::Args)]
pub struct Args {
    /// Output folder (report.html and every file beside it).
    #[arg(long, default_value = "navsync-demo")]
    pub output: PathBuf,
    /// Length of the drive (s) [default: 600].
    #[arg(value_parser = args::real(1.0, 86_400.0, "s"), long)]
    pub duration: Option<f64>,
    /// Seed of every random error source [default: 1].
    #[arg(value_parser = args::seed(), long)]
    pub seed: Option<u64>,
}

pub fn run(a: Args) -> Result<()> {
    let _held = super::take_output(&a.output, "demo")?;
    let opts = DemoOptions {
        output: a.output,
        duration_s: a.duration,
        seed: a.seed,
    };
    let mut bars: HashMap<String, ProgressBar> = HashMap::new();
    let outcome = run_demo(&opts, &mut |stage, f| {
        let pb = bars
            .entry(stage.to_string())
            .or_insert_with(|| crate::progress::bar(stage));
        crate::progress::set(pb, f);
        if f >= 1.0 {
            pb.finish();
        }
    })?;
    for pb in bars.values() {
        pb.finish_and_clear();
    }
    let s = &outcome.summary;
    println!(
        "navsync demo: {:.0} s {} drive ({}, seed {}) simulated, synchronized, fused and scored in {:.2} s",
        s.duration_s, s.scenario, s.imu, s.seed, s.total_time_s
    );
    print!("{}", s.table());
    println!(
        "  stages: {}",
        s.stage_times_s
            .iter()
            .map(|(k, t)| format!("{k} {t:.2} s"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("  open {}", outcome.report_path.display());
    println!("  (rebuild it: {})", outcome.report_command);
    Ok(())
}
