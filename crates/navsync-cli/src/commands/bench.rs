//! `navsync bench`: speed and memory of the navigation core.

use anyhow::Result;

#[derive(clap::Args)]
pub struct Args {
    /// Hours of 200 Hz IMU data to generate and fuse.
    #[arg(long, default_value_t = 1.0)]
    pub hours: f64,
}

pub fn run(_args: Args) -> Result<()> {
    anyhow::bail!("bench: not built yet")
}
