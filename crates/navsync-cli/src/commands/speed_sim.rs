//! `navsync speed-sim`: a simulated odometer/CAN speed file from a truth
//! trajectory (for testing `navsync fuse --odometer` on simulated drives).

use std::path::PathBuf;

use anyhow::Result;
use navsync::Diagnostics;
use navsync_sim::speed::{SpeedSimOptions, simulate_speed_file};

use super::args;
use super::print_diagnostics;

#[derive(clap::Args)]
pub struct Args {
    /// Truth trajectory (11-column nav format) of the IMU centre.
    #[arg(long)]
    pub truth: PathBuf,
    /// Output speed file (`sow speed_mps`).
    #[arg(long)]
    pub out: PathBuf,
    /// Output rate (Hz).
    #[arg(value_parser = args::real(0.01, 10_000.0, "Hz"), long, default_value_t = 20.0)]
    pub rate: f64,
    /// Scale error s: reported = (1 + s)·true + noise.
    #[arg(value_parser = args::symmetric(1.0, ""), long, default_value_t = 0.01, allow_hyphen_values = true)]
    pub scale_error: f64,
    /// White noise σ (m/s).
    #[arg(value_parser = args::non_negative(args::MAX_SPEED_MPS, "m/s"), long, default_value_t = 0.05)]
    pub noise: f64,
    /// Resolution of the reported speed (m/s); 0 keeps full precision.
    #[arg(value_parser = args::non_negative(args::MAX_SPEED_MPS, "m/s"), long, default_value_t = 0.01)]
    pub resolution: f64,
    #[arg(value_parser = args::seed(), long, default_value_t = 1)]
    pub seed: u64,
}

pub fn run(a: Args) -> Result<()> {
    anyhow::ensure!(
        a.rate > 0.0 && a.noise >= 0.0 && a.resolution >= 0.0,
        "need --rate > 0, --noise ≥ 0, --resolution ≥ 0"
    );
    args::refuse_output_over_input(&a.out, &[&a.truth], "--out")?;
    let o = SpeedSimOptions {
        rate_hz: a.rate,
        scale_error: a.scale_error,
        noise_sd_mps: a.noise,
        resolution_mps: a.resolution,
        seed: a.seed,
    };
    let mut diag = Diagnostics::default();
    let n = simulate_speed_file(&a.truth, &a.out, &o, &mut diag)?;
    println!(
        "navsync speed-sim: wrote {n} speeds to {} ({} Hz, scale error {:+.3} %, noise {} m/s, resolution {} m/s)",
        a.out.display(),
        a.rate,
        100.0 * a.scale_error,
        a.noise,
        a.resolution
    );
    if !diag.is_empty() {
        eprintln!("{} truth lines skipped:", diag.total);
        print_diagnostics(&diag, 10);
    }
    Ok(())
}
