//! `navsync`: the command-line tool. The library does the work; this
//! binary parses arguments, shows progress and prints results.

mod commands;
mod progress;

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
    /// Fuse IMU and GNSS files described by a KF-GINS configuration.
    Fuse(commands::fuse::Args),
    /// Score a navigation result against a reference trajectory.
    Eval(commands::eval::Args),
    /// Time the navigation core on generated data (1 h of 200 Hz IMU).
    Bench(commands::bench::Args),
    /// Simulate carrier tracking (unaided or INS-aided, fixed or adaptive
    /// bandwidth) against C/N0: jitter, bias, slips, threshold.
    Track(commands::track::Args),
    /// Make a simulated odometer speed file from a truth trajectory.
    SpeedSim(commands::speed_sim::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fuse(a) => commands::fuse::run(a),
        Command::Eval(a) => commands::eval::run(a),
        Command::Bench(a) => commands::bench::run(a),
        Command::Track(a) => commands::track::run(a),
        Command::SpeedSim(a) => commands::speed_sim::run(a),
    };
    if let Err(e) = result {
        eprintln!("navsync: error: {e:#}");
        std::process::exit(1);
    }
}
