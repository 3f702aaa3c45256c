//! `navsync`: the command-line tool. The library does the work; this
//! binary parses arguments, shows progress and prints results.

mod commands;
mod procstat;
mod progress;
mod signals;

use clap::{Parser, Subcommand};

/// GNSS/INS integrated navigation with first-class time synchronization.
#[derive(Parser)]
#[command(name = "navsync", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write a commented sensor sheet (sensor.yaml) for `navsync process`:
    /// IMU figures, antenna lever arm, mounting, odometer.
    Init(commands::init::Args),
    /// A whole drive in one command: raw logs (a rig log, or a receiver log
    /// and an IMU log) + sensor sheet → sync/convert, align, fuse, smooth,
    /// report, in one folder.
    Process(commands::process::Args),
    /// The whole chain on a built-in drive (simulate → sync → fuse → eval)
    /// and its HTML report: navsync-demo/report.html.
    Demo(commands::demo::Args),
    /// One self-contained HTML report of a run: a quality verdict, GNSS
    /// innovations and NIS, the filter's σ, IMU biases against the
    /// configuration, gaps and predicted drift, time offset,
    /// synchronization; with --truth also the errors with ±3σ and metrics
    /// (std.txt, imu_err.txt, time_offset.txt, summary.json,
    /// gnss_residuals.txt beside --nav are used unless given).
    Report(commands::report::Args),
    /// Fuse IMU and GNSS files described by a KF-GINS configuration.
    Fuse(Box<commands::fuse::Args>),
    /// Score a navigation result against a reference trajectory.
    Eval(commands::eval::Args),
    /// Export a navigation solution to GPX, KML, GeoJSON, CSV or TUM (with
    /// the σ of std.txt beside it).
    Export(commands::export::Args),
    /// Convert receiver logs (UBX, NMEA) and rate-form IMU CSVs to KF-GINS files and rig-logs.
    Convert(commands::convert::Args),
    /// Put a raw rig log (rig-log v1) on GPS time: KF-GINS files and a report.
    Sync(commands::sync::Args),
    /// Time the navigation core on generated data (1 h of 200 Hz IMU).
    Bench(commands::bench::Args),
    /// Fuse an IMU array with unknown relative time offsets (Wang, Guan & Ding,
    /// "Research on time synchronization in a loosely coupled IMU-array
    /// navigation system", 2019).
    Array(commands::array::Args),
    /// Simulate carrier tracking (unaided or INS-aided, fixed or adaptive
    /// bandwidth) against C/N0: jitter, bias, slips, threshold.
    Track(commands::track::Args),
    /// Make a simulated odometer speed file from a truth trajectory.
    SpeedSim(commands::speed_sim::Args),
    /// IMU acquisition quality: check a log, convert and decimate, rate study.
    Imu(commands::imu::Args),
    /// Simulate a drive: exact truth, IMU, GNSS, clocks and a raw rig log.
    Simulate(commands::simulate::Args),
    /// Inject GNSS receiver faults (spikes, false RTK fixes, ramps, stale
    /// repeats) into a GNSS file, with one label per faulty fix.
    Faults(commands::faults::Args),
    /// Simulate → sync → fuse → eval over many seeds in parallel: accuracy
    /// percentiles and the filter's consistency (NEES).
    Montecarlo(commands::montecarlo::Args),
    /// Many drives at once, one per task (sync → fuse → smooth → eval →
    /// verdict): a folder per drive and a table with a row per drive.
    Batch(commands::batch::Args),
    /// Live on Linux: GNSS and IMU serial ports + kernel PPS, synchronized
    /// and fused in real time (--selftest: measured on pseudo-terminals).
    Live(commands::live::Args),
    /// The numeric arguments of every command (for the CLI's tests).
    #[command(name = "__numeric-args", hide = true)]
    NumericArgs,
}

fn main() {
    let cli = Cli::parse();
    signals::install();
    let result = match cli.command {
        Command::Init(a) => commands::init::run(a),
        Command::Process(a) => commands::process::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::Report(a) => commands::report::run(a),
        Command::Fuse(a) => commands::fuse::run(*a),
        Command::Eval(a) => commands::eval::run(a),
        Command::Export(a) => commands::export::run(a),
        Command::Convert(a) => commands::convert::run(a),
        Command::Bench(a) => commands::bench::run(a),
        Command::Array(a) => commands::array::run(a),
        Command::Sync(a) => commands::sync::run(a),
        Command::Track(a) => commands::track::run(a),
        Command::SpeedSim(a) => commands::speed_sim::run(a),
        Command::Imu(a) => commands::imu::run(a),
        Command::Simulate(a) => commands::simulate::run(a),
        Command::Faults(a) => commands::faults::run(a),
        Command::Montecarlo(a) => commands::montecarlo::run(a),
        Command::Batch(a) => commands::batch::run(a),
        Command::Live(a) => commands::live::run(a),
        Command::NumericArgs => {
            use clap::CommandFactory;
            for line in commands::args::numeric_args(&Cli::command()) {
                println!("{line}");
            }
            Ok(())
        }
    };
    if let Err(e) = result {
        eprintln!("navsync: error: {}", chain_once(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined by ": ", each cause once: a cause
/// whose text its parent already shows (`navsync::Error::Io` prints its
/// io::Error, which is also its source) is not repeated.
fn chain_once(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}
