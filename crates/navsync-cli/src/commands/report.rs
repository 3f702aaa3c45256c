//! `navsync report`: one self-contained HTML page of a run.

use std::path::PathBuf;

use anyhow::{Context, Result};
use navsync::eval::parse_outages;
use navsync_report::ReportInputs;

use super::args;
use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// Reference trajectory (11-column nav format). Without it the page
    /// judges the run from the filter's own statistics (verdict, GNSS
    /// innovations and NIS, σ, IMU biases against the configuration, gaps).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// The solution (11-column nav format); the files `navsync fuse` writes
    /// beside it (std.txt, imu_err.txt, summary.json, …) are picked up.
    #[arg(long)]
    pub nav: PathBuf,
    /// GNSS outage windows "sow:len,sow:len" (by default those in
    /// summary.json); with --truth, the drift in them is measured.
    #[arg(long, default_value = "")]
    pub outages: String,
    /// sync_report.json of `navsync sync`: timeline and latency histogram.
    #[arg(long)]
    pub sync_report: Option<PathBuf>,
    /// summary.json of `navsync fuse`.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    /// std.txt (KF-GINS layout): the filter's ±3σ bounds.
    #[arg(long)]
    pub std: Option<PathBuf>,
    /// imu_err.txt (KF-GINS layout): IMU error estimates.
    #[arg(long)]
    pub imu_err: Option<PathBuf>,
    /// The true IMU errors (the simulator's imu_err_truth.txt).
    #[arg(long)]
    pub imu_err_truth: Option<PathBuf>,
    /// GNSS fixes (7 or 13 columns) for the trajectory plot and the gaps
    /// table.
    #[arg(long)]
    pub gnss: Option<PathBuf>,
    /// time_offset.txt of `navsync fuse --estimate-time-offset`.
    #[arg(long)]
    pub time_offset: Option<PathBuf>,
    /// The true time offset (s), drawn beside the estimate.
    #[arg(value_parser = args::symmetric(args::MAX_OFFSET_S, "s"), long, allow_negative_numbers = true)]
    pub time_offset_truth: Option<f64>,
    /// Page title.
    #[arg(long, default_value = "navsync report")]
    pub title: String,
    /// The HTML file to write.
    #[arg(long)]
    pub output: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    let inputs = [
        Some(&a.nav),
        a.truth.as_ref(),
        a.sync_report.as_ref(),
        a.summary.as_ref(),
        a.std.as_ref(),
        a.imu_err.as_ref(),
        a.imu_err_truth.as_ref(),
        a.gnss.as_ref(),
        a.time_offset.as_ref(),
    ];
    let inputs: Vec<&std::path::Path> = inputs.into_iter().flatten().map(|p| p.as_path()).collect();
    args::refuse_output_over_input(&a.output, &inputs, "--output")?;
    let inputs = ReportInputs {
        title: a.title,
        truth: a.truth,
        nav: a.nav,
        sync_report: a.sync_report,
        summary: a.summary,
        std: a.std,
        imu_err: a.imu_err,
        imu_err_truth: a.imu_err_truth,
        gnss: a.gnss,
        time_offset: a.time_offset,
        gnss_residuals: None,
        time_offset_truth_s: a.time_offset_truth,
        outages: parse_outages(&a.outages, 0)?,
        ..ReportInputs::default()
    }
    .with_siblings_of_nav();
    let report = navsync_report::build(&inputs)?;
    navsync::io::output::write_file(&a.output, &report.html)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let scored = match &report.eval {
        Some(e) => format!("{} epochs scored, ", e.epochs_compared),
        None => "no truth, ".into(),
    };
    println!(
        "navsync report: {scored}verdict: {}; wrote {} ({:.0} kB)",
        report.verdict.grade.words(),
        a.output.display(),
        report.html.len() as f64 / 1e3
    );
    for c in &report.verdict.causes {
        println!("  likely cause: {c}");
    }
    if let Some(c) = report
        .verdict
        .checks
        .iter()
        .find(|c| c.name == "solution file")
    {
        eprintln!("navsync report: {}", c.finding);
    }
    if !report.diagnostics.is_empty() {
        eprintln!("{} lines skipped:", report.diagnostics.total);
        print_diagnostics(&report.diagnostics, 10);
    }
    Ok(())
}
