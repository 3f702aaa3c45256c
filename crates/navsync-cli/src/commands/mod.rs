pub mod args;
pub mod array;
pub mod batch;
pub mod bench;
pub mod clock;
pub mod convert;
pub mod demo;
pub mod eval;
pub mod export;
pub mod faults;
pub mod fuse;
pub mod imu;
pub mod init;
pub mod live;
pub mod montecarlo;
pub mod process;
pub mod report;
pub mod simulate;
pub mod speed_sim;
pub mod sync;
pub mod track;

/// A solution and the reference it is scored against (`eval`; `report`
/// has its own arguments, with the truth optional).
#[derive(clap::Args)]
pub struct Scored {
    /// Reference trajectory (11-column nav format).
    #[arg(long)]
    pub truth: std::path::PathBuf,
    /// Solution to score (11-column nav format).
    #[arg(long)]
    pub nav: std::path::PathBuf,
    /// GNSS outage windows "sow:len,sow:len" in which drift is measured.
    #[arg(long, default_value = "")]
    pub outages: String,
}

/// Prints at most `limit` diagnostics and a count of the rest.
pub fn print_diagnostics(d: &navsync::Diagnostics, limit: usize) {
    for item in d.items.iter().take(limit) {
        eprintln!("  {item}");
    }
    if d.total > limit {
        eprintln!("  … and {} more (all in summary.json)", d.total - limit);
    }
}

/// Takes `dir` as this run's output folder (created if missing): its lock
/// (a second writer refuses, naming this run), stale temporaries of
/// earlier runs removed and an earlier run's files of `command` moved into
/// `.previous/`, each said on stderr (`navsync::io::output`). Hold the
/// result until the run is done.
pub fn take_output(
    dir: &std::path::Path,
    command: &str,
) -> anyhow::Result<navsync::io::output::OutputDir> {
    let d = navsync::io::output::OutputDir::open(dir, command)?;
    for n in d.notes() {
        eprintln!("navsync: {n}");
    }
    Ok(d)
}
